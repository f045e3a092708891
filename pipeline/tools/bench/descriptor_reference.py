"""The numpy expressions of the descriptor's compiled loops (``pipeline/servo/region_kernels.py``;
``docs/performance.md``, "Compiled loops"), as ``pipeline.servo.region`` computed them before,
kept for ``make bench`` (which runs the closed loop with both) and for the tests that check both
give the same bits. Same arguments, frames, units and returns as the loops they mirror."""

from __future__ import annotations

import numpy as np


def on_plane_mask(Z, xn, yn, nx, ny, nz, d_hat, eps):
    """The numpy expression ``on_plane_mask`` replaced (``PlaneCrop.of``)."""
    dist = Z * ((nx * xn)[None, :] + (ny * yn + nz)[:, None])
    dist += d_hat
    return (Z > 0) & (np.abs(dist) < eps)


def slab_counts(d, tol):
    """The numpy expression ``slab_counts`` replaced (``tracked_plane``)."""
    return (np.abs(d[None, :] - d[:, None]) < tol).sum(axis=1)


def plane_rules_unsmoothed(X, Y, Z, valid, xn, yn, nx, ny, nz, d_hat, eps, k):
    """The numpy expressions ``plane_rules_unsmoothed`` replaced (``plane_rules`` without
    normal smoothing)."""
    h, w = Z.shape
    dist = X * nx
    dist += Y * ny
    dist += Z * nz
    dist += d_hat
    on_plane = valid & (np.abs(dist) < eps)
    rules = np.zeros((h, w), dtype=bool)
    if h < 3 or w < 3:
        return on_plane, rules
    xi, yi = xn[None, 1:-1], yn[1:-1, None]
    du = Z[1:-1, 2:] - Z[1:-1, :-2]
    dv = Z[2:, 1:-1] - Z[:-2, 1:-1]
    A = X[1:-1, 2:] - X[1:-1, :-2]
    B = Y[2:, 1:-1] - Y[:-2, 1:-1]
    cx = du * (yi * dv - B)
    cy = dv * (xi * du - A)
    cz = A * B - (xi * yi) * (du * dv)
    defined = (
        valid[1:-1, 1:-1] & valid[1:-1, 2:] & valid[1:-1, :-2] & valid[2:, 1:-1] & valid[:-2, 1:-1]
    )
    towards = cx * xi
    towards += cy * yi
    towards += cz
    length2 = cx * cx
    length2 += cy * cy
    length2 += cz * cz
    dot = cx * nx
    dot += cy * ny
    dot += cz * nz
    dot = np.where(towards > 0, -dot, dot)
    ok = (dot > 0) & (dot * dot > (k * k) * length2)
    rules[1:-1, 1:-1] = ok & defined
    rules &= on_plane
    return on_plane, rules
