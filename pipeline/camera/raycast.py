"""Exact depth and instance masks of a world of boxes by vectorised ray casting.

The project's simulated world is made of cuboids only: the bin's floor and walls and the boxes
of the heap (the robot is never in the camera's view when it renders). For such a world the
z-depth of a pixel is the entry distance of its ray into the nearest box, which the slab test
gives exactly, pixel by pixel. Each box is tested only over its projected footprint: the
bounding rectangle of its eight corners in the image. The box is set up here in numpy; the loop
over its footprint's pixels is compiled (``pipeline.camera.raycast_kernels``: the operations of
the numpy path kept in ``pipeline/tools/bench/render_reference.py``, with the same result bit
for bit).

Conventions (the same as ``pipeline.camera.render``'s TinyRenderer path):
    - Rays pass through OpenCV pixel centres: pixel (u, v) looks along the camera-frame
      direction ((u − cx)/fx, (v − cy)/fy, 1), so the ray parameter is the z-depth itself.
    - The near plane clips: a surface nearer than ``near`` is not seen, and the ray sees what lies
      beyond it (for a box cut by the plane, the inside of its far faces). Nothing beyond
      ``far`` is seen; a pixel that sees nothing has depth ``far`` and body id −1, before the
      analytic ground fills it. (pybullet's rasteriser drops every triangle with a vertex in
      front of the near plane instead; ``docs/simulation.md``.)
    - Body ids are pybullet body unique ids, as in the rasteriser's segmentation mask.
Frames: camera (OpenCV: x right, y down, z forward), world (z up); metres.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pybullet as p

from pipeline.camera.geometry import Intrinsics, pose_matrix
from pipeline.camera.raycast_kernels import ground_into, slab_box_into


@dataclass(frozen=True)
class BoxShape:
    """One cuboid to draw.

    Attributes:
        body_id: the id written into the mask where this box is the nearest surface.
        T_world_box: (4, 4) pose of the box centre in the world frame.
        half_extents: (3,) half edge lengths along the box's own x, y, z axes, metres.
    """

    body_id: int
    T_world_box: np.ndarray
    half_extents: np.ndarray


class UnsupportedGeometry(ValueError):
    """A visible shape that is not a box: the ray-cast renderer cannot draw it."""


def all_bodies(client: int) -> list[int]:
    """The unique ids of every body in the pybullet client, in the client's order."""
    return [
        p.getBodyUniqueId(i, physicsClientId=client)
        for i in range(p.getNumBodies(physicsClientId=client))
    ]


def boxes_from_pybullet(client: int, body_ids=None, cache: dict | None = None) -> list[BoxShape]:
    """The visible box shapes of ``body_ids`` (all bodies of the client when None), posed now.

    Shapes drawn fully transparent (alpha 0, as the project's ground slab) are skipped, as the
    rasteriser skips them. Only base links are read: every body of the project's cell is a
    single rigid box.

    ``cache``: a dict the caller keeps for one world whose bodies keep their shapes (the closed
    loop's cell, emptied when it builds a new world): each body's visible boxes in its own
    frame are read from pybullet once and kept there, so a frame reads only the bodies' poses.
    The shapes are the same either way.

    Raises:
        UnsupportedGeometry: a listed body has a visible shape that is not a box, or links.
    """
    if body_ids is None:
        body_ids = all_bodies(client)
    out = []
    for body in body_ids:
        local = None if cache is None else cache.get(body)
        if local is None:
            local = _local_boxes(client, body)
            if cache is not None:
                cache[body] = local
        if not local:
            continue
        pos, quat = p.getBasePositionAndOrientation(body, physicsClientId=client)
        T_body = pose_matrix(pos, quat)
        for T_local, half in local:
            out.append(BoxShape(int(body), T_body @ T_local, half))
    return out


def _local_boxes(client: int, body: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """The visible boxes of ``body``: (4, 4) pose in the body frame and (3,) half extents, m."""
    out = []
    for s in p.getVisualShapeData(body, physicsClientId=client):
        link, geom, dims, local_pos, local_orn, rgba = s[1], s[2], s[3], s[5], s[6], s[7]
        if rgba[3] <= 0.0:
            continue
        if geom != p.GEOM_BOX or link != -1:
            raise UnsupportedGeometry(
                f"body {body} has a visible {'link' if link != -1 else 'base'} shape of "
                f"pybullet geometry type {geom}: the ray-cast renderer draws base boxes "
                "only. Leave that body out of `bodies`, or use camera.renderer=tinyrenderer"
            )
        out.append((pose_matrix(local_pos, local_orn), np.asarray(dims, np.float64) / 2.0))
    return out


class RayGrid:
    """The normalised ray direction of every pixel centre of one camera, computed once.

    ``xn[u] = (u − cx)/fx`` and ``yn[v] = (v − cy)/fy`` (float32; ``xn64``, ``yn64`` in float64),
    so the camera-frame ray of pixel (u, v) is (xn[u], yn[v], 1).
    """

    def __init__(self, intr: Intrinsics) -> None:
        self.intr = intr
        self.xn64 = (np.arange(intr.width, dtype=np.float64) - intr.cx) / intr.fx
        self.yn64 = (np.arange(intr.height, dtype=np.float64) - intr.cy) / intr.fy
        self.xn, self.yn = self.xn64.astype(np.float32), self.yn64.astype(np.float32)


_GRIDS: dict[Intrinsics, RayGrid] = {}


def ray_grid(intr: Intrinsics) -> RayGrid:
    """The cached ``RayGrid`` of ``intr``."""
    grid = _GRIDS.get(intr)
    if grid is None:
        grid = _GRIDS[intr] = RayGrid(intr)
    return grid


_CORNERS = np.array(
    [[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], np.float64
)


def _footprint(
    R_cb: np.ndarray, c: np.ndarray, half: np.ndarray, intr: Intrinsics, near: float, far: float
) -> tuple[int, int, int, int] | None:
    """Pixel rectangle [u0, u1) × [v0, v1) that holds every pixel centre whose ray can meet the
    box (camera-frame centre ``c``, axes ``R_cb``), or None when the box is out of view."""
    pts = (_CORNERS * half) @ R_cb.T + c  # (8, 3) corners in the camera frame
    z = pts[:, 2]
    if z.max() < near or z.min() > far:
        return None
    W, H = intr.width, intr.height
    if z.min() <= 1e-9:  # a corner behind the camera: its projection is unbounded
        return 0, W, 0, H
    u = intr.fx * pts[:, 0] / z + intr.cx
    v = intr.fy * pts[:, 1] / z + intr.cy
    u0, u1 = max(0, int(np.ceil(u.min()))), min(W, int(np.floor(u.max())) + 1)
    v0, v1 = max(0, int(np.ceil(v.min()))), min(H, int(np.floor(v.max())) + 1)
    if u0 >= u1 or v0 >= v1:
        return None
    return u0, u1, v0, v1


def posed_boxes(
    boxes: list[BoxShape], intr: Intrinsics, T_world_cam: np.ndarray, near: float, far: float
):
    """Each box of ``boxes`` that can be seen, in the camera frame: yields ``(box, R_cb, c,
    (u0, u1, v0, v1))``, its axes (3, 3) and centre (3,) in the camera frame (m) and its
    footprint (``_footprint``). Shared by ``raycast_boxes`` and its numpy path."""
    T_cam_world = np.linalg.inv(T_world_cam)
    R_cw, t_cw = T_cam_world[:3, :3], T_cam_world[:3, 3]
    for box in boxes:
        R_cb = R_cw @ box.T_world_box[:3, :3]
        c = R_cw @ box.T_world_box[:3, 3] + t_cw
        fp = _footprint(R_cb, c, box.half_extents, intr, near, far)
        if fp is not None:
            yield box, R_cb, c, fp


def raycast_boxes(
    boxes: list[BoxShape], intr: Intrinsics, T_world_cam: np.ndarray, near: float, far: float
) -> tuple[np.ndarray, np.ndarray]:
    """Z-depth and body ids of the nearest box surface through every pixel centre.

    Args:
        boxes: the cuboids to draw (``boxes_from_pybullet``).
        intr: camera intrinsics; T_world_cam: (4, 4) camera pose, OpenCV axes.
        near, far: the visible depth range, metres.

    Returns:
        depth: (H, W) float32 z-depth in metres, ``far`` where no box is seen.
        body_ids: (H, W) int32 body id of the seen box, −1 where none.

    For a ray x(t) = t·r with r = (xn, yn, 1) (t is the z-depth), in the box frame
    o + t·d with o = −R_cbᵀc and d = R_cbᵀr, the slab of axis i is crossed over
    t ∈ [m_i − w_i, m_i + w_i] with m_i = −o_i/d_i and w_i = h_i/|d_i|; the ray is inside the box
    over [max_i(m_i − w_i), min_i(m_i + w_i)] when that interval is not empty. Seen is its entry
    if the entry is at least ``near``, else its exit: the near plane is a clipping plane that cuts
    the box open, and the ray sees the inside of its far faces. (pybullet's rasteriser differs
    here: it drops every triangle that has a vertex in front of the near plane.)
    """
    grid = ray_grid(intr)
    H, W = intr.height, intr.width
    f32 = np.float32
    depth = np.full((H, W), np.inf, np.float32)
    ids = np.full((H, W), -1, np.int32)
    for box, R_cb, c, (u0, u1, v0, v1) in posed_boxes(boxes, intr, T_world_cam, near, far):
        # d_i = a·xn + b·yn + k; the per-pixel arithmetic in float32 (3× faster; its rounding,
        # ~1e-7 m, is far below the depth's own float32 resolution); the loop over the
        # footprint's pixels is compiled (raycast_kernels.slab_box_into)
        slab_box_into(
            depth,
            ids,
            grid.xn,
            grid.yn,
            u0,
            u1,
            v0,
            v1,
            R_cb.T.astype(f32),  # row i: (a, b, k) of axis i
            (R_cb.T @ c).astype(f32),  # −o
            np.asarray(box.half_extents, f32),
            f32(near),
            f32(far),
            box.body_id,
        )
    np.copyto(depth, f32(far), where=ids < 0)
    return depth, ids


def fill_ground(
    depth: np.ndarray,
    body_ids: np.ndarray,
    intr: Intrinsics,
    T_world_cam: np.ndarray,
    ground_z: float,
    ground_id: int,
    far: float,
) -> None:
    """In place: where ``body_ids`` is −1, the z-depth of the horizontal plane world
    z = ``ground_z`` and ``ground_id``, for rays that meet it in front of the camera nearer than
    ``far``.

    A pixel's world ray is t + z·R r with r = (xn, yn, 1), so it meets the plane at the z-depth
    z = (ground_z − t_z) / (R[2] · r).
    """
    grid = ray_grid(intr)
    R, t = T_world_cam[:3, :3], T_world_cam[:3, 3]
    ground_into(
        depth,
        body_ids,
        grid.xn64,
        grid.yn64,
        float(R[2, 0]),
        float(R[2, 1]),
        float(R[2, 2]),
        float(ground_z - t[2]),
        int(ground_id),
        float(far),
    )
