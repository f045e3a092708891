"""Pixels of a stored scene's depth image → camera-frame points (for logs and figures)."""

from __future__ import annotations

import numpy as np


def pixels_to_points(scene, uv: np.ndarray) -> np.ndarray:
    """(N, 2) pixels → (N, 3) float32 camera-frame (OpenCV) points at the scene's ideal depth,
    metres: each pixel rounded to the nearest one inside the (H, W) image.

    ``scene``: a ``pipeline.dataset.scenes.Scene`` (``depth_clean_m`` (H, W) metres,
    ``intrinsics``)."""
    uv = np.asarray(uv, np.float64).reshape(-1, 2)
    h, w = scene.depth_clean_m.shape
    u = np.clip(np.round(uv[:, 0]).astype(int), 0, w - 1)
    v = np.clip(np.round(uv[:, 1]).astype(int), 0, h - 1)
    z = scene.depth_clean_m[v, u].astype(np.float64)
    k = scene.intrinsics
    return np.stack([(uv[:, 0] - k.cx) / k.fx * z, (uv[:, 1] - k.cy) / k.fy * z, z], axis=1).astype(
        np.float32
    )
