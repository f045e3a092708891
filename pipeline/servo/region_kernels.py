"""Two loops of the surface descriptor's region growing, compiled by Numba.

``pipeline.servo.region`` runs once per control step of the servo. Two of its steps were numpy
expressions whose temporaries cost more than their arithmetic: Eq. 12 over the whole image
(``on_plane_mask``: five image-sized arrays) and the tracked plane's slab counts
(``slab_counts``: an N × N array for the N ≈ 441 points of the 21 × 21 window). Each loop here
performs the numpy expression's floating-point operations per element in the same order and
precision (no fused multiply-add, no reassociation: Numba's default, ``fastmath`` off), so its
result is bit for bit the numpy one's; ``tests/test_region_kernels.py`` checks both against the
numpy expressions. Compiled code is cached beside this file (``cache=True``).
Frames and units: ``pipeline.servo.region``'s (camera frame, metres; pixels (u, v)).
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def on_plane_mask(Z, xn, yn, nx, ny, nz, d_hat, eps):
    """(H, W) bool: Eq. 12, ``Z > 0`` and |n̂ · P + D̂| < ε1 with P = Z (xn, yn, 1).

    Args:
        Z: (H, W) float32 z-depth, m (0 = no data). xn: (W,), yn: (H,) float32 normalised
            image coordinates of the columns / rows.
        nx, ny, nz, d_hat, eps: float32 plane normal, offset and ε1.

    Per pixel, as numpy computes ``Z * ((nx * xn)[None, :] + (ny * yn + nz)[:, None])``, then
    ``+ d_hat``: s = nx·xn[u] + (ny·yn[v] + nz), dist = Z·s + D̂, all float32.
    """
    H, W = Z.shape
    out = np.empty((H, W), np.bool_)
    for v in range(H):
        row = ny * yn[v] + nz
        for u in range(W):
            z = Z[v, u]
            dist = z * (nx * xn[u] + row) + d_hat
            out[v, u] = (z > 0) & (abs(dist) < eps)
    return out


@njit(cache=True, nogil=True)
def slab_counts(d, tol):
    """(N,) int64: for each i, how many j have |d[j] − d[i]| < ``tol`` (float64 offsets ``d``
    (N,) of the window points along the tracked normal, m), as numpy's
    ``(np.abs(d[None, :] - d[:, None]) < tol).sum(axis=1)``."""
    n = d.shape[0]
    counts = np.zeros(n, np.int64)
    for i in range(n):
        di = d[i]
        c = 0
        for j in range(n):
            if abs(d[j] - di) < tol:
                c += 1
        counts[i] = c
    return counts


@njit(cache=True, nogil=True)
def plane_rules_unsmoothed(X, Y, Z, valid, xn, yn, nx, ny, nz, d_hat, eps, k):
    """``pipeline.servo.region.plane_rules`` without normal smoothing: (Eq. 12 mask, Eqs. 12
    & 13 mask), both (h, w) bool, of a crop; the operations of its numpy expressions per pixel.

    Args:
        X, Y, Z: (h, w) float32 back-projected coordinates, m (Z = 0 where no data); valid:
            (h, w) bool. xn: (w,), yn: (h,) float32. nx, ny, nz, d_hat, eps: float32 plane and
            ε1; k: float32 1 − ε2 / 2.
    """
    h, w = Z.shape
    on_plane = np.empty((h, w), np.bool_)
    for r in range(h):
        for c in range(w):
            dist = X[r, c] * nx
            dist = dist + Y[r, c] * ny
            dist = dist + Z[r, c] * nz
            dist = dist + d_hat
            on_plane[r, c] = valid[r, c] & (abs(dist) < eps)
    rules = np.zeros((h, w), np.bool_)
    if h < 3 or w < 3:
        return on_plane, rules
    kk = k * k
    for r in range(1, h - 1):
        yi = yn[r]
        for c in range(1, w - 1):
            xi = xn[c]
            du = Z[r, c + 1] - Z[r, c - 1]
            dv = Z[r + 1, c] - Z[r - 1, c]
            A = X[r, c + 1] - X[r, c - 1]
            B = Y[r + 1, c] - Y[r - 1, c]
            cx = du * (yi * dv - B)
            cy = dv * (xi * du - A)
            cz = A * B - (xi * yi) * (du * dv)
            defined = (
                valid[r, c] & valid[r, c + 1] & valid[r, c - 1] & valid[r + 1, c] & valid[r - 1, c]
            )
            towards = cx * xi
            towards = towards + cy * yi
            towards = towards + cz
            length2 = cx * cx
            length2 = length2 + cy * cy
            length2 = length2 + cz * cz
            dot = cx * nx
            dot = dot + cy * ny
            dot = dot + cz * nz
            if towards > 0:
                dot = -dot
            ok = (dot > 0) & (dot * dot > kk * length2)
            rules[r, c] = ok & defined & on_plane[r, c]
    return on_plane, rules
