"""The numpy expressions of the descriptor's compiled loops (``pipeline/servo/region_kernels.py``;
``docs/performance.md``, "Compiled loops"), as ``pipeline.servo.region`` computed them before,
kept for ``make bench`` (which runs the closed loop with both) and for the tests that check both
give the same bits. Same arguments, frames, units and returns as the loops they mirror."""

from __future__ import annotations

import numpy as np

from pipeline.servo.region import eq12_mask, eq14_terms


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
    normal smoothing): ``region.eq12_mask``, ``region.eq14_terms``, then Eq. 13."""
    h, w = Z.shape
    on_plane = eq12_mask(X, Y, Z, valid, nx, ny, nz, d_hat, eps)
    rules = np.zeros((h, w), dtype=bool)
    if h < 3 or w < 3:
        return on_plane, rules
    cx, cy, cz, defined, towards, length2 = eq14_terms(X, Y, Z, valid, xn, yn)
    dot = cx * nx
    dot += cy * ny
    dot += cz * nz
    dot = np.where(towards > 0, -dot, dot)
    ok = (dot > 0) & (dot * dot > (k * k) * length2)
    rules[1:-1, 1:-1] = ok & defined
    rules &= on_plane
    return on_plane, rules
