"""The sensor model's per-pixel loop, compiled by Numba: each pixel's incidence cosine.

``pipeline.camera.sensor.incidence_angles`` needs, for every pixel of a 416 × 416 frame, two
one-sided tangents, their cross product and the angle to the viewing ray. As numpy expressions
that is some twenty whole-image (H, W, 3) temporaries per frame, and in the closed loop through
a sensor model it was most of a trial's time (the servo renders and degrades a frame at every
control step). The loop below keeps one pixel in registers. It performs, pixel by pixel, the
floating-point operations of the numpy expressions it replaced, in the same order and in float64
(no fused multiply-add, no reassociation: Numba's default, ``fastmath`` off), so its result is
bit for bit theirs; ``tests/test_sensor_kernels.py`` checks that against the numpy path
(``pipeline/tools/bench/sensor_reference.py``).

``error_model="numpy"``: no exception on a division (none can divide by zero here: the cosine
is only formed where both norms are positive). Compiled code is cached beside this file
(``cache=True``). Frames and conventions: those of ``pipeline.camera.sensor``.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True, error_model="numpy")
def incidence_cos_into(z, xn, yn, cos):
    """In place: ``cos`` (H, W) float64 gets |cos θ| of each pixel's incidence angle, or −1
    where it has none (no depth, or no tangent with data along u or v, so a zero normal).

    Args:
        z: (H, W) float64 z-depth, metres (0 = no data).
        xn: (W,) float64 ``(u − cx)/fx``; yn: (H,) float64 ``(v − cy)/fy``: the camera-frame
            point of pixel (u, v) is P = (xn[u]·z, yn[v]·z, z).
        cos: (H, W) float64, written.

    Per pixel, as ``sensor.incidence_angles`` documents: along u and along v the tangent is the
    difference to the forward or the backward neighbour, whichever has the smaller depth step
    among those where both pixels have data (forward on a tie), and zero where neither has;
    n = t_u × t_v; cos θ = |n · P| / (|n| |P|). The sums of three terms run left to right, as
    numpy's reductions over the last axis of length 3 do.
    """
    H, W = z.shape
    inf = np.inf
    for r in range(H):
        yr = yn[r]
        for c in range(W):
            zc = z[r, c]
            p0 = xn[c] * zc
            p1 = yr * zc
            p2 = zc
            # tangent along u (image columns)
            f0 = 0.0
            f1 = 0.0
            f2 = 0.0
            dzf = inf
            if c + 1 < W:
                z1 = z[r, c + 1]
                f0 = xn[c + 1] * z1 - p0
                f1 = yr * z1 - p1
                f2 = z1 - p2
                if zc > 0 and z1 > 0:
                    dzf = abs(f2)
            b0 = 0.0
            b1 = 0.0
            b2 = 0.0
            dzb = inf
            if c > 0:
                z1 = z[r, c - 1]
                b0 = p0 - xn[c - 1] * z1
                b1 = p1 - yr * z1
                b2 = p2 - z1
                if zc > 0 and z1 > 0:
                    dzb = abs(b2)
            if dzf <= dzb:
                a0, a1, a2 = f0, f1, f2
            else:
                a0, a1, a2 = b0, b1, b2
            if not min(dzf, dzb) < inf:
                a0, a1, a2 = 0.0, 0.0, 0.0
            # tangent along v (image rows)
            f0 = 0.0
            f1 = 0.0
            f2 = 0.0
            dzf = inf
            if r + 1 < H:
                z1 = z[r + 1, c]
                f0 = xn[c] * z1 - p0
                f1 = yn[r + 1] * z1 - p1
                f2 = z1 - p2
                if zc > 0 and z1 > 0:
                    dzf = abs(f2)
            b0 = 0.0
            b1 = 0.0
            b2 = 0.0
            dzb = inf
            if r > 0:
                z1 = z[r - 1, c]
                b0 = p0 - xn[c] * z1
                b1 = p1 - yn[r - 1] * z1
                b2 = p2 - z1
                if zc > 0 and z1 > 0:
                    dzb = abs(b2)
            if dzf <= dzb:
                v0, v1, v2 = f0, f1, f2
            else:
                v0, v1, v2 = b0, b1, b2
            if not min(dzf, dzb) < inf:
                v0, v1, v2 = 0.0, 0.0, 0.0
            n0 = a1 * v2 - a2 * v1
            n1 = a2 * v0 - a0 * v2
            n2 = a0 * v1 - a1 * v0
            norm_n = np.sqrt((n0 * n0 + n1 * n1) + n2 * n2)
            norm_p = np.sqrt((p0 * p0 + p1 * p1) + p2 * p2)
            if zc > 0 and norm_n > 0 and norm_p > 0:
                cos[r, c] = abs((n0 * p0 + n1 * p1) + n2 * p2) / (norm_n * norm_p)
            else:
                cos[r, c] = -1.0
