"""The network input's depth normalisation (``normalise_depth``): the network sees

    x = (depth − D_ground) / depth_scale        where the depth has data (depth > 0)
    x = missing_depth_value                      where it has none (depth = 0)

with D_ground = camera height above the bin floor + floor thickness (the camera–ground
distance of Eq. 9). With depth_scale = 0.1 m the bin floor is at ≈ −0.2 and a box top 0.1 m
above the floor at ≈ −1.2; no data (0.5) sits apart from every real depth (all < D_ground).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.camera.geometry import ground_distance


@dataclass(frozen=True)
class Normalisation:
    """Depth → network input (module docstring). Metres."""

    d_ground: float
    depth_scale: float
    missing_depth_value: float

    def as_dict(self) -> dict:
        return {
            "d_ground": self.d_ground,
            "depth_scale": self.depth_scale,
            "missing_depth_value": self.missing_depth_value,
        }


def normalisation(cfg) -> Normalisation:
    """The network input's normalisation from a composed config: D_ground
    (``pipeline.camera.geometry.ground_distance``), ``train.depth_scale`` and
    ``train.missing_depth_value``."""
    return Normalisation(
        ground_distance(cfg.camera, cfg.bin),
        float(cfg.train.depth_scale),
        float(cfg.train.missing_depth_value),
    )


def normalise_depth(depth_m: np.ndarray, norm: Normalisation) -> np.ndarray:
    """(..., H, W) float32 depth, metres (0 = no data) → float32 network input, same shape."""
    depth_m = np.asarray(depth_m, np.float32)
    x = (depth_m - np.float32(norm.d_ground)) / np.float32(norm.depth_scale)
    return np.where(depth_m > 0, x, np.float32(norm.missing_depth_value)).astype(
        np.float32, copy=False
    )
