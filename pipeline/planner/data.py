"""Training data: depth images of a generation artifact with the grid targets of its labels.

Depth normalisation (``normalise_depth``): the network sees

    x = (depth − D_ground) / depth_scale        where the depth has data (depth > 0)
    x = missing_depth_value                      where it has none (depth = 0)

with D_ground = camera height above the bin floor + floor thickness (the camera–ground
distance of Eq. 9). With depth_scale = 0.1 m the bin floor is at ≈ −0.2 and a box top 0.1 m
above the floor at ≈ −1.2; no data (0.5) sits apart from every real depth (all < D_ground).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from pipeline.dataset.scenes import SceneDataset
from pipeline.planner.augment import flip_image, flip_rows
from pipeline.planner.targets import encode, stack_targets


@dataclass(frozen=True)
class Normalisation:
    """Depth → network input (module docstring). Metres."""

    d_ground: float
    depth_scale: float
    missing_depth_value: float

    def as_dict(self) -> dict:
        return {"d_ground": self.d_ground, "depth_scale": self.depth_scale,
                "missing_depth_value": self.missing_depth_value}


def normalise_depth(depth_m: np.ndarray, norm: Normalisation) -> np.ndarray:
    """(..., H, W) float32 depth, metres (0 = no data) → float32 network input, same shape."""
    depth_m = np.asarray(depth_m, np.float32)
    x = (depth_m - np.float32(norm.d_ground)) / np.float32(norm.depth_scale)
    return np.where(depth_m > 0, x, np.float32(norm.missing_depth_value)).astype(np.float32)


class GraspDataset:
    """One split held in memory: depth as uint16 in the generation's depth unit (2 bytes a
    pixel: 2,400 images ≈ 0.8 GB) and each image's label rows.

    ``batch(indices, flips)`` → (x (B, 1, H, W) float32, targets for ``grasp_loss``).
    ``lost_points`` / ``total_points``: points dropped by the one-point-per-cell rule.
    """

    def __init__(self, gen_dir: Path, labels, split: str, norm: Normalisation, grid: int,
                 hand_cfg=None, limit: int = 0) -> None:
        ds = SceneDataset(gen_dir, split)
        n = len(ds) if limit <= 0 else min(limit, len(ds))
        if len(labels) < n:
            raise ValueError(f"the label artifact has {len(labels)} {split} images, the "
                             f"generation artifact {len(ds)}: they do not belong together")
        self.intrinsics = ds.intrinsics
        self.depth_unit = ds.depth_unit
        self.norm, self.grid, self.hand_cfg = norm, grid, hand_cfg
        size = (ds.intrinsics.height, ds.intrinsics.width)
        self.depth_raw = np.zeros((n, *size), np.uint16)
        self.rows = []
        self.lost_points = self.total_points = 0
        for i in range(n):
            self.depth_raw[i] = np.round(ds[i].depth_m / self.depth_unit).astype(np.uint16)
            rows = labels[i]
            self.rows.append(rows)
            enc = encode(rows["uv"], rows["grasp_class"], grid, size[1])
            self.lost_points += enc["lost"]
            self.total_points += len(rows["uv"])

    def __len__(self) -> int:
        return len(self.rows)

    def depth_m(self, i: int) -> np.ndarray:
        """(H, W) float32 metres, 0 = no data."""
        return self.depth_raw[i].astype(np.float32) * np.float32(self.depth_unit)

    def batch(self, indices, flips=None) -> tuple[torch.Tensor, dict]:
        xs, targets = [], []
        for k, i in enumerate(indices):
            depth, rows = self.depth_m(int(i)), self.rows[int(i)]
            flip = flips[k] if flips is not None else "none"
            if flip != "none":
                depth = flip_image(depth, flip)
                rows = flip_rows(rows, flip, self.intrinsics, self.hand_cfg)
            xs.append(normalise_depth(depth, self.norm))
            targets.append(encode(rows["uv"], rows["grasp_class"], self.grid, depth.shape[1]))
        return torch.from_numpy(np.stack(xs)[:, None]), stack_targets(targets)
