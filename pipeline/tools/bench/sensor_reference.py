"""The numpy expression of the sensor model's compiled loop (``pipeline/camera/sensor_kernels.py``),
as ``pipeline.camera.sensor.incidence_angles`` computed it before, kept for ``make bench`` (which
times both) and for the test that checks both give the same bits. Same arguments, frames, units
and return as ``incidence_angles``."""

from __future__ import annotations

import numpy as np

from pipeline.camera.geometry import Intrinsics


def incidence_angles(depth_m: np.ndarray, intr: Intrinsics) -> np.ndarray:
    """Angle between each pixel's viewing ray and its surface normal.

    The normal is the cross product of the camera-frame tangents along u and v; each tangent is
    the one-sided difference towards the neighbour with the smaller depth step, so a pixel at
    a depth step takes the tangent of its own surface.

    Args:
        depth_m: (H, W) ideal z-depth, metres (0 = no data).
        intr: the image's intrinsics.

    Returns:
        (H, W) float64 radians in [0, π/2]; 0 where the pixel or both neighbours lack data.
    """
    z = np.asarray(depth_m, np.float64)
    H, W = z.shape
    u = (np.arange(W, dtype=np.float64)[None, :] - intr.cx) / intr.fx
    v = (np.arange(H, dtype=np.float64)[:, None] - intr.cy) / intr.fy
    P = np.stack([u * z, v * z, z], axis=-1)  # (H, W, 3) camera frame

    def tangent(axis: int) -> np.ndarray:
        """(H, W, 3) tangent along image axis ``axis`` (0 = v, 1 = u)."""
        lo = [slice(None)] * 2
        hi = [slice(None)] * 2
        lo[axis], hi[axis] = slice(0, -1), slice(1, None)
        lo, hi = tuple(lo), tuple(hi)
        d = P[hi] - P[lo]
        both = (z[hi] > 0) & (z[lo] > 0)
        fwd, bwd = np.zeros_like(P), np.zeros_like(P)
        dzf, dzb = np.full(z.shape, np.inf), np.full(z.shape, np.inf)
        fwd[lo], bwd[hi] = d, d
        dzf[lo] = np.where(both, np.abs(d[..., 2]), np.inf)
        dzb[hi] = np.where(both, np.abs(d[..., 2]), np.inf)
        t = np.where((dzf <= dzb)[..., None], fwd, bwd)
        return np.where(np.isfinite(np.minimum(dzf, dzb))[..., None], t, 0.0)

    n = np.cross(tangent(1), tangent(0))
    norm_n = np.linalg.norm(n, axis=-1)
    norm_p = np.linalg.norm(P, axis=-1)
    ok = (z > 0) & (norm_n > 0) & (norm_p > 0)
    cos = np.zeros_like(z)
    cos[ok] = np.abs((n[ok] * P[ok]).sum(-1)) / (norm_n[ok] * norm_p[ok])
    theta = np.arccos(np.clip(cos, 0.0, 1.0))
    return np.where(ok, theta, 0.0)
