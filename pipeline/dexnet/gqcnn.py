"""The grasp-quality CNN (GQ-CNN) of the Dex-Net-style baseline, and its input crops.

Input, as in gqcnn's suction networks (Dex-Net 3.0/4.0):

* **Crop**: a ``window_px`` × ``window_px`` window of the depth image (64 px, about 8 cm on the
  boxes) centred on the candidate pixel (u, v), rotated about that pixel so that the image
  projection of the approach axis points along +u (gqcnn aligns the crop with the grasp axis),
  resized to ``size`` × ``size`` (32 px: Dex-Net 3.0's suction input size; nearest-neighbour, the
  candidate becomes crop pixel (S/2, S/2)). Values are heights relative to the candidate:
  ``(depth − candidate depth) / depth_scale``; pixels with no data (depth 0, or outside the
  image) read ``missing_value``. Shape (N, 1, S, S) float32.
* **Pose**: ``[(candidate depth − D_ground) / pose_depth_scale, approach angle (rad)]``: Dex-Net
  4.0's suction pose input (depth and the angle between approach axis and optical axis).
  Shape (N, 2) float32.

Network: three conv blocks (conv, ReLU, 2×2 max-pool, the DCNN's ``MaxPool2x2``, whose
inference path skips the indices a backward pass needs; a 5×5 then two 3×3 kernels; ``width``,
2·``width``, 4·``width`` channels), a fully connected layer of ``fc`` units on the flattened
image features, the pose through its own ``fc // 4`` units, both concatenated into ``fc`` units
and one output logit: the predicted probability that the suction grasp is robust (robust
quality ≥ the contact model's threshold, ``pipeline.dexnet.contact``). Far smaller than Dex-Net
4.0's network (about 0.16 M parameters at width 16, 2.8 M multiply-accumulates per crop, vs.
about 18 M parameters): it is trained from scratch on a CPU, and the CEM scores 350 crops per
image.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
import torch
from torch import nn

from pipeline.dexnet.sampling import Candidates
from pipeline.planner.network import MaxPool2x2


@dataclass(frozen=True)
class CropConfig:
    """How a candidate's crop and pose input are made (see the module docstring): ``dexnet.crop``
    with ``d_ground`` given by the caller, built by ``pipeline.dexnet.planner.crop_config``."""

    window_px: int
    size: int
    depth_scale: float  # m
    missing_value: float
    pose_depth_scale: float  # m
    # m, camera to ground at the home pose (as the DCNN's D_ground,
    # ``pipeline.camera.geometry.ground_distance``): derived, not a key of ``dexnet.crop``
    d_ground: float


@dataclass(frozen=True)
class GQCNNConfig:
    """The GQ-CNN's architecture (see the module docstring): ``dexnet.width`` and ``dexnet.fc``,
    with ``crop_size`` = ``dexnet.crop.size``, built by ``pipeline.dexnet.planner.gqcnn_config``."""

    crop_size: int
    width: int
    fc: int


def crop_angle(axes_cam: np.ndarray) -> np.ndarray:
    """(N, 3) approach axes (camera frame) → (N,) image-plane angle of their projection, rad.

    The angle of (a_x, a_y) from +u towards +v; 0 for an axis along the optical axis (no in-plane
    component: the crop is not rotated).
    """
    axes = np.asarray(axes_cam, np.float64).reshape(-1, 3)
    planar = np.hypot(axes[:, 0], axes[:, 1])
    return np.where(planar > 1e-6, np.arctan2(axes[:, 1], axes[:, 0]), 0.0)


def crop_source(depth_m: np.ndarray) -> np.ndarray:
    """The image the crops are cut from: (H, W) float32 depth, NaN where there is no data.

    Computed once per depth image (:func:`extract_crops` takes it as ``source``, so the CEM's
    scoring rounds on one image share it)."""
    depth_m = np.asarray(depth_m, np.float32)
    return np.where(depth_m > 0, depth_m, np.nan).astype(np.float32)


def extract_crops(
    depth_m: np.ndarray,
    uv: np.ndarray,
    depth: np.ndarray,
    axes_cam: np.ndarray,
    cfg: CropConfig,
    source: np.ndarray | None = None,
) -> np.ndarray:
    """Crops centred on candidates, rotated to their axes: (N, 1, S, S) float32.

    Args:
        depth_m: (H, W) depth image, metres, 0 = no data.
        uv: (N, 2) candidate pixels (u, v).
        depth: (N,) candidate depths, metres.
        axes_cam: (N, 3) approach axes in the camera frame.
        source: ``crop_source(depth_m)`` when the caller already has it (else computed here).
    """
    uv = np.asarray(uv, np.float64).reshape(-1, 2)
    n, s = len(uv), cfg.size
    if n == 0:
        return np.empty((n, 1, s, s), np.float32)
    # Missing data and the outside of the image read as NaN, replaced after the warp; the warp
    # is nearest-neighbour so that a hole never blends into a valid depth.
    if source is None:
        source = crop_source(depth_m)
    scale = s / cfg.window_px
    angles = np.degrees(crop_angle(axes_cam))
    centre = float(s // 2)  # the candidate lands on a pixel centre: crop pixel (S/2, S/2)
    crops = np.empty((n, s, s), np.float32)
    for i in range(n):
        u, v = uv[i]
        # Rotate the image by the axis angle about (u, v) so the axis points along +u, scale it
        # and move (u, v) to the crop centre: M maps source pixels to crop pixels.
        m = cv2.getRotationMatrix2D((float(u), float(v)), float(angles[i]), scale)
        m[0, 2] += centre - u
        m[1, 2] += centre - v
        cv2.warpAffine(
            source,
            m,
            (s, s),
            dst=crops[i],
            flags=cv2.INTER_NEAREST,
            borderMode=cv2.BORDER_CONSTANT,
            borderValue=float("nan"),
        )
    # Heights relative to each candidate, all crops at once (float32, as crop by crop).
    rel = (
        crops - np.asarray(depth, np.float64).astype(np.float32)[:, None, None]
    ) / cfg.depth_scale
    out = np.empty((n, 1, s, s), np.float32)
    out[:, 0] = np.where(np.isfinite(rel), rel, cfg.missing_value)
    return out


def pose_input(cands: Candidates, cfg: CropConfig) -> np.ndarray:
    """(N, 2) float32: normalised candidate depth and approach angle (rad)."""
    return np.stack(
        [(cands.depth - cfg.d_ground) / cfg.pose_depth_scale, cands.angle], axis=1
    ).astype(np.float32)


def candidate_inputs(
    depth_m: np.ndarray, cands: Candidates, cfg: CropConfig, source: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Crops (N, 1, S, S) and poses (N, 2) of candidates on one depth image (``source``: its
    ``crop_source``, if the caller keeps it)."""
    crops = extract_crops(depth_m, cands.uv, cands.depth, cands.axis, cfg, source)
    return crops, pose_input(cands, cfg)


class GQCNN(nn.Module):
    """Crop (B, 1, S, S) + pose (B, 2) → logit (B,) of a robust suction grasp."""

    def __init__(self, cfg: GQCNNConfig) -> None:
        super().__init__()
        self.cfg = cfg
        w = cfg.width
        layers: list[nn.Module] = []
        c_in = 1
        for c_out, k in ((w, 5), (2 * w, 3), (4 * w, 3)):
            layers += [
                nn.Conv2d(c_in, c_out, k, padding=k // 2),
                nn.ReLU(inplace=True),
                MaxPool2x2(),
            ]
            c_in = c_out
        self.features = nn.Sequential(*layers)
        side = cfg.crop_size // 8
        if side < 1:
            raise ValueError(f"crop_size {cfg.crop_size} is too small: at least 8 px")
        self.image_fc = nn.Sequential(
            nn.Flatten(), nn.Linear(c_in * side * side, cfg.fc), nn.ReLU(inplace=True)
        )
        self.pose_fc = nn.Sequential(nn.Linear(2, cfg.fc // 4), nn.ReLU(inplace=True))
        self.head = nn.Sequential(
            nn.Linear(cfg.fc + cfg.fc // 4, cfg.fc), nn.ReLU(inplace=True), nn.Linear(cfg.fc, 1)
        )

    def forward(self, crops: torch.Tensor, poses: torch.Tensor) -> torch.Tensor:
        x = self.image_fc(self.features(crops))
        return self.head(torch.cat([x, self.pose_fc(poses)], dim=1)).squeeze(1)


@torch.inference_mode()
def predict_quality(
    net: GQCNN, crops: np.ndarray, poses: np.ndarray, batch: int = 256
) -> np.ndarray:
    """Probability of a robust grasp for each candidate: (N,) float64 in [0, 1]."""
    net.eval()
    out = np.empty(len(crops), np.float64)
    for start in range(0, len(crops), batch):
        c = torch.from_numpy(np.ascontiguousarray(crops[start : start + batch]))
        p = torch.from_numpy(np.ascontiguousarray(poses[start : start + batch]))
        out[start : start + batch] = torch.sigmoid(net(c, p)).double().numpy()
    return out


def count_parameters(net: nn.Module) -> int:
    return int(sum(p.numel() for p in net.parameters()))


def border_for_window(window_px: int) -> int:
    """The border within which a rotated crop would leave the image: ceil(√2 · window / 2)."""
    return int(math.ceil(math.sqrt(2.0) * window_px / 2.0))
