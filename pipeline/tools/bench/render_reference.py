"""The ray casters' numpy path: ``pipeline.camera.raycast.raycast_boxes`` and ``fill_ground``
and ``pipeline.camera.raycast_convex.raycast_convex`` as written before their per-pixel loops were
compiled (``pipeline/camera/raycast_kernels.py``; ``docs/performance.md``, "Rendering"), kept
for ``make bench`` (which times both in the same run) and for the tests that check both give the
same depth and body ids, bit for bit.

Each solid is set up as the renderers set it up (``posed_boxes``, ``posed_solids``); its
footprint is then computed with whole-footprint numpy arrays, one temporary per operation.
Same arguments, frames, units and returns as the functions they mirror.
"""

from __future__ import annotations

import numpy as np

from pipeline.camera.raycast import BoxShape, posed_boxes, ray_grid
from pipeline.camera.raycast_convex import ConvexShape, posed_solids


def raycast_boxes(
    boxes: list[BoxShape], intr, T_world_cam: np.ndarray, near: float, far: float
) -> tuple[np.ndarray, np.ndarray]:
    """``pipeline.camera.raycast.raycast_boxes`` with numpy arrays per footprint."""
    grid = ray_grid(intr)
    H, W = intr.height, intr.width
    f32 = np.float32
    depth = np.full((H, W), np.inf, np.float32)
    ids = np.full((H, W), -1, np.int32)
    with np.errstate(divide="ignore", invalid="ignore"):
        for box, R_cb, c, (u0, u1, v0, v1) in posed_boxes(boxes, intr, T_world_cam, near, far):
            xn, yn = grid.xn[None, u0:u1], grid.yn[v0:v1, None]
            o = -(R_cb.T @ c)
            t_in = t_out = None
            for i in range(3):
                # d_i = a·xn + b·yn + k; the per-pixel arithmetic in float32 (3× faster; its
                # rounding, ~1e-7 m, is far below the depth's own float32 resolution)
                a, b, k = f32(R_cb[0, i]), f32(R_cb[1, i]), f32(R_cb[2, i])
                inv = f32(1.0) / (a * xn + (b * yn + k))
                m = f32(-o[i]) * inv
                w = f32(box.half_extents[i]) * np.abs(inv)
                lo, hi = m - w, m + w
                if t_in is None:
                    t_in, t_out = lo, hi
                else:
                    # fmax/fmin: a ray parallel to a slab on its boundary gives 0/0 = nan
                    t_in, t_out = np.fmax(t_in, lo), np.fmin(t_out, hi)
            t_seen = np.where(t_in >= f32(near), t_in, t_out)
            block = depth[v0:v1, u0:u1]
            hit = (t_in <= t_out) & (t_seen >= f32(near)) & (t_seen <= f32(far)) & (t_seen < block)
            np.copyto(block, t_seen, where=hit)  # (masks are coherent: copyto beats indexing)
            np.copyto(ids[v0:v1, u0:u1], box.body_id, where=hit)
    np.copyto(depth, f32(far), where=ids < 0)
    return depth, ids


def raycast_convex(
    shapes: list[ConvexShape], intr, T_world_cam: np.ndarray, near: float, far: float
) -> tuple[np.ndarray, np.ndarray]:
    """``pipeline.camera.raycast_convex.raycast_convex`` with numpy arrays per footprint."""
    grid = ray_grid(intr)
    H, W = intr.height, intr.width
    depth = np.full((H, W), np.inf, np.float64)
    ids = np.full((H, W), -1, np.int32)
    with np.errstate(divide="ignore", invalid="ignore"):
        for shape, n_c, d_c, (u0, u1, v0, v1) in posed_solids(shapes, intr, T_world_cam, near, far):
            xn, yn = grid.xn64[None, u0:u1], grid.yn64[v0:v1, None]
            shape_hw = (v1 - v0, u1 - u0)
            t_in = np.full(shape_hw, -np.inf)
            t_out = np.full(shape_hw, np.inf)
            denom, t = np.empty(shape_hw), np.empty(shape_hw)
            for (a, b, k), d in zip(n_c, d_c):
                np.add(a * xn, b * yn + k, out=denom)  # n_f . r per pixel
                np.divide(d, denom, out=t)
                np.fmax(t_in, t, out=t_in, where=denom < 0.0)  # entering: a lower bound
                np.fmin(t_out, t, out=t_out, where=denom > 0.0)  # leaving: an upper bound
                if d < 0.0:  # a ray parallel to this plane and outside it is never inside
                    t_out[denom == 0.0] = -np.inf
            t_seen = np.where(t_in >= near, t_in, t_out)
            block = depth[v0:v1, u0:u1]
            hit = (t_in <= t_out) & (t_seen >= near) & (t_seen <= far) & (t_seen < block)
            np.copyto(block, t_seen, where=hit)
            np.copyto(ids[v0:v1, u0:u1], shape.body_id, where=hit)
    depth[ids < 0] = far
    return depth.astype(np.float32), ids


def fill_ground(
    depth: np.ndarray,
    body_ids: np.ndarray,
    intr,
    T_world_cam: np.ndarray,
    ground_z: float,
    ground_id: int,
    far: float,
) -> None:
    """``pipeline.camera.raycast.fill_ground`` with numpy arrays over the whole image."""
    grid = ray_grid(intr)
    R, t = T_world_cam[:3, :3], T_world_cam[:3, 3]
    dz = R[2, 0] * grid.xn64[None, :] + (R[2, 1] * grid.yn64[:, None] + R[2, 2])
    with np.errstate(divide="ignore", invalid="ignore"):
        z = (ground_z - t[2]) / dz
    hit = (body_ids < 0) & (z > 0) & (z < far)
    np.copyto(depth, z, where=hit, casting="same_kind")
    np.copyto(body_ids, ground_id, where=hit)
