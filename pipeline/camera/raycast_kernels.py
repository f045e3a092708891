"""The ray casters' per-pixel loops, compiled by Numba.

``pipeline.camera.raycast`` (boxes, the slab test in float32) and
``pipeline.camera.raycast_convex`` (convex solids, half-spaces in float64) set up each solid in
the camera frame and find its footprint in the image in numpy; the loop over the footprint's
pixels runs here. Each kernel performs, pixel by pixel, exactly the floating-point operations of
the numpy expressions it replaced, in the same order and the same precision (no fused
multiply-add, no reassociation: Numba's default, ``fastmath`` off), so its depth and body ids are
bit for bit the numpy path's; ``tests/test_raycast_kernels.py`` checks that against the numpy
path (``pipeline/tools/bench/render_reference.py``) on heaps and closed-loop frames. What the
loops gain is the work between the operations: numpy makes a temporary array of the whole
footprint for each of some thirty operations per box, the loop keeps one pixel in registers.

``error_model="numpy"``: a division by zero gives ±inf or nan as in numpy (a ray parallel to a
face), instead of raising. Compiled code is cached beside this file (``cache=True``), so only
the first process after a change compiles it (about a second).
Frames and conventions: those of ``pipeline.camera.raycast``; depth in metres.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True, error_model="numpy")
def slab_box_into(depth, ids, xn, yn, u0, u1, v0, v1, abk, mo, half, near, far, body_id):
    """In place: draw one box into ``depth`` (H, W) float32 and ``ids`` (H, W) int32 over the
    footprint [u0, u1) × [v0, v1), where it is nearer than what is there.

    Args:
        xn: (W,) float32 ``(u − cx)/fx``; yn: (H,) float32 ``(v − cy)/fy``.
        abk: (3, 3) float32, row i = (a, b, k) of the box axis i: the ray direction in the box
            frame is d_i = a·xn + b·yn + k.
        mo: (3,) float32 −o_i, the camera centre's negated box-frame coordinates, m.
        half: (3,) float32 half edge lengths, m. near, far: float32 visible range, m.

    Per pixel, as ``raycast.raycast_boxes`` documents: inv_i = 1/d_i, the slab of axis i is
    crossed over [m_i − w_i, m_i + w_i] with m_i = −o_i·inv_i and w_i = h_i·|inv_i|; entry and
    exit are their max and min (nan-ignoring, as ``np.fmax``/``np.fmin``), seen is the entry if
    it is at least ``near``, else the exit.
    """
    one = np.float32(1.0)
    a0, a1, a2 = abk[0, 0], abk[1, 0], abk[2, 0]
    m0, m1, m2 = mo[0], mo[1], mo[2]
    h0, h1, h2 = half[0], half[1], half[2]
    n = u1 - u0
    t_in_row = np.empty(n, np.float32)
    t_out_row = np.empty(n, np.float32)
    for v in range(v0, v1):
        y = yn[v]
        k0 = abk[0, 1] * y + abk[0, 2]
        k1 = abk[1, 1] * y + abk[1, 2]
        k2 = abk[2, 1] * y + abk[2, 2]
        # the slabs: branch-free, so that the compiler runs several pixels at once (SIMD)
        for j in range(n):
            x = xn[u0 + j]
            inv = one / (a0 * x + k0)
            m = m0 * inv
            w = h0 * abs(inv)
            t_in = m - w
            t_out = m + w
            inv = one / (a1 * x + k1)
            m = m1 * inv
            w = h1 * abs(inv)
            t_in = _fmax(t_in, m - w)
            t_out = _fmin(t_out, m + w)
            inv = one / (a2 * x + k2)
            m = m2 * inv
            w = h2 * abs(inv)
            t_in_row[j] = _fmax(t_in, m - w)
            t_out_row[j] = _fmin(t_out, m + w)
        drow = depth[v]
        irow = ids[v]
        for j in range(n):
            t_in = t_in_row[j]
            t_out = t_out_row[j]
            t_seen = t_in if t_in >= near else t_out
            if t_in <= t_out and t_seen >= near and t_seen <= far and t_seen < drow[u0 + j]:
                drow[u0 + j] = t_seen
                irow[u0 + j] = body_id


@njit(cache=True, nogil=True, error_model="numpy")
def half_spaces_into(depth, ids, xn, yn, u0, u1, v0, v1, n_c, d_c, near, far, body_id):
    """In place: draw one convex solid ``{x : n_c @ x <= d_c}`` (camera frame; ``n_c`` (F, 3),
    ``d_c`` (F,), float64) into ``depth`` (H, W) float64 and ``ids`` (H, W) int32 over the
    footprint [u0, u1) × [v0, v1), where it is nearer than what is there.

    ``xn`` (W,), ``yn`` (H,) float64 normalised ray coordinates. Per pixel and plane, as
    ``raycast_convex.raycast_convex`` documents: denom = n_f · r, t = d_f / denom; denom < 0
    raises the entry to t, denom > 0 lowers the exit to t (nan-ignoring), denom = 0 with
    d_f < 0 closes the interval (exit −inf).
    """
    for v in range(v0, v1):
        y = yn[v]
        for u in range(u0, u1):
            x = xn[u]
            t_in = -np.inf
            t_out = np.inf
            for f in range(n_c.shape[0]):
                denom = n_c[f, 0] * x + (n_c[f, 1] * y + n_c[f, 2])
                t = d_c[f] / denom
                if denom < 0.0:
                    t_in = _fmax(t_in, t)
                elif denom > 0.0:
                    t_out = _fmin(t_out, t)
                elif d_c[f] < 0.0 and denom == 0.0:
                    t_out = -np.inf
            t_seen = t_in if t_in >= near else t_out
            if t_in <= t_out and t_seen >= near and t_seen <= far and t_seen < depth[v, u]:
                depth[v, u] = t_seen
                ids[v, u] = body_id


@njit(cache=True, nogil=True, error_model="numpy")
def ground_into(depth, ids, xn, yn, r20, r21, r22, height, ground_id, far):
    """In place: where ``ids`` (H, W) int32 is −1, the z-depth of the horizontal plane whose
    height above the camera along world z is ``height`` (m, ground z − camera z) into ``depth``
    (H, W) float32 and ``ground_id`` into ``ids``, for rays that meet it in front of the camera
    nearer than ``far``.

    ``xn`` (W,), ``yn`` (H,) float64; (r20, r21, r22) the camera rotation's last row: a pixel's
    world ray rises dz = r20·xn + (r21·yn + r22) per metre of depth, so z = height / dz
    (float64, stored as the nearest float32).
    """
    for v in range(ids.shape[0]):
        ky = r21 * yn[v] + r22
        for u in range(ids.shape[1]):
            if ids[v, u] < 0:
                z = height / (r20 * xn[u] + ky)
                if z > 0.0 and z < far:
                    depth[v, u] = np.float32(z)
                    ids[v, u] = ground_id


@njit(cache=True, inline="always")
def _fmax(a, b):
    """``np.fmax`` of two scalars: the larger; a nan loses to a number."""
    if a != a:
        return b
    if b != b:
        return a
    return a if a >= b else b


@njit(cache=True, inline="always")
def _fmin(a, b):
    """``np.fmin`` of two scalars: the smaller; a nan loses to a number (``-fmax(-a, -b)``,
    which keeps the sign of a zero as ``np.fmin`` does)."""
    return -_fmax(-a, -b)
