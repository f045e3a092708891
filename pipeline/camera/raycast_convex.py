"""Exact depth and instance masks of a world of convex solids by vectorised ray casting.

``pipeline.camera.raycast`` draws boxes by the slab test. A convex solid is an intersection of
half-spaces ``n_f . x <= d_f`` (one per face plane), and the slab test is the case of three
pairs of parallel planes; this module draws any convex solid the same way, so that heaps of the
random objects of ``pipeline.simulation.objects`` (cylinders drawn as 64-gons, prisms, convex
hulls) are rendered as exactly as the box heaps. A box is the convex solid of its six faces.

For a ray x(t) = t r, r = (xn, yn, 1) (t is the z-depth), each plane bounds t: where
``n_f . r < 0`` the ray enters the half-space at ``t = d_f / (n_f . r)`` (a lower bound), where
``n_f . r > 0`` it leaves it there (an upper bound), and where ``n_f . r = 0`` it is inside the
half-space for every t when ``d_f >= 0``, for none otherwise. The ray is inside the solid over
[max of the lower bounds, min of the upper bounds] when that interval is not empty.
Conventions (pixel centres, near-plane clipping, ``far`` and body id -1 where nothing is seen,
pybullet body unique ids) are ``pipeline.camera.raycast``'s; each solid is tested only over the
bounding rectangle of its projected vertices.

What a pybullet body is drawn as (``convex_from_pybullet``): a ``GEOM_BOX`` shape its box; a
``GEOM_MESH`` shape the convex hull of its collision vertices (``p.getMeshData``), which is the
solid pybullet simulates and the one ``pipeline.dexnet.contact_mesh.RayScene`` casts the contact
model's lines against, so the image and the labels see the same geometry (to rounding).
Frames: camera (OpenCV: x right, y down, z forward), world (z up); metres.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pybullet as p
from scipy.spatial import ConvexHull

from pipeline.camera.geometry import Intrinsics, pose_matrix
from pipeline.camera.raycast import UnsupportedGeometry, all_bodies, ray_grid
from pipeline.camera.raycast_kernels import half_spaces_into


@dataclass(frozen=True)
class ConvexShape:
    """One convex solid to draw, in the world frame.

    Attributes:
        body_id: the id written into the mask where this solid is the nearest surface.
        normals: (F, 3) float64 unit outward normals of its face planes, world frame.
        offsets: (F,) float64 plane offsets: the solid is ``{x : normals @ x <= offsets}``, m.
        vertices: (V, 3) float64 its vertices, world frame, m (for the image footprint).
    """

    body_id: int
    normals: np.ndarray
    offsets: np.ndarray
    vertices: np.ndarray


def convex_shape(body_id: int, vertices_world: np.ndarray) -> ConvexShape:
    """The ``ConvexShape`` of the convex hull of (V, 3) world points (scipy's Qhull, which
    ``trimesh.convex.convex_hull`` also uses); coplanar facets merged into one plane."""
    pts = np.asarray(vertices_world, np.float64).reshape(-1, 3)
    hull = ConvexHull(pts)
    eq = hull.equations  # (F, 4): n . x + e <= 0 inside, |n| = 1, one row per triangle
    # a 64-gon cap is 62 coplanar triangles: keep one plane of each group
    _, first = np.unique(np.round(eq, 9), axis=0, return_index=True)
    eq = eq[np.sort(first)]
    return ConvexShape(int(body_id), eq[:, :3].copy(), -eq[:, 3], pts[hull.vertices])


_CORNERS = np.array(
    [[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], np.float64
)


def box_shape(body_id: int, T_world_box: np.ndarray, half_extents: np.ndarray) -> ConvexShape:
    """The ``ConvexShape`` of a box: centre and axes ``T_world_box`` (4, 4), half edge lengths
    ``half_extents`` (3,), m. Its planes are ``+-R[:, i] . x <= +-R[:, i] . c + h_i``."""
    R, c = np.asarray(T_world_box, np.float64)[:3, :3], np.asarray(T_world_box, np.float64)[:3, 3]
    h = np.asarray(half_extents, np.float64).reshape(3)
    normals = np.concatenate([R.T, -R.T])  # rows: +x, +y, +z, -x, -y, -z box axes
    offsets = np.concatenate([R.T @ c + h, -(R.T @ c) + h])
    return ConvexShape(int(body_id), normals, offsets, (_CORNERS * h) @ R.T + c)


def convex_from_pybullet(client: int, body_ids=None) -> list[ConvexShape]:
    """The visible convex solids of ``body_ids`` (all bodies of the client when None), posed now.

    A body whose visual shapes are all fully transparent (alpha 0, as the project's ground slab)
    or that has none is skipped, as the rasteriser skips it. Its collision shapes are drawn:
    boxes (``GEOM_BOX``, placed by their local frames) and convex meshes (``GEOM_MESH``, whose
    ``p.getMeshData`` vertices are in the base frame).

    Raises:
        UnsupportedGeometry: a listed body has links or another kind of collision shape.
    """
    if body_ids is None:
        body_ids = all_bodies(client)
    out = []
    for body in body_ids:
        visual = p.getVisualShapeData(body, physicsClientId=client)
        if not visual or all(s[7][3] <= 0.0 for s in visual):
            continue
        if p.getNumJoints(body, physicsClientId=client) > 0:
            raise UnsupportedGeometry(
                f"body {body} has links: the convex ray-cast renderer "
                "draws single rigid bodies only"
            )
        pos, quat = p.getBasePositionAndOrientation(body, physicsClientId=client)
        T_base = pose_matrix(np.asarray(pos), np.asarray(quat))
        for k, s in enumerate(p.getCollisionShapeData(body, -1, physicsClientId=client)):
            geom, dims, local_pos, local_orn = s[2], s[3], s[5], s[6]
            if geom == p.GEOM_BOX:  # its six planes directly (no hull to compute)
                T = T_base @ pose_matrix(np.asarray(local_pos), np.asarray(local_orn))
                out.append(box_shape(int(body), T, np.asarray(dims, np.float64) / 2.0))
                continue
            if geom == p.GEOM_MESH:
                _, local = p.getMeshData(body, -1, collisionShapeIndex=k, physicsClientId=client)
                T = T_base
            else:
                raise UnsupportedGeometry(
                    f"body {body} has a collision shape of pybullet geometry type {geom}: the "
                    "convex ray-cast renderer draws boxes and convex meshes only"
                )
            world = np.asarray(local, np.float64) @ T[:3, :3].T + T[:3, 3]
            out.append(convex_shape(int(body), world))
    return out


def posed_solids(
    shapes: list[ConvexShape], intr: Intrinsics, T_world_cam: np.ndarray, near: float, far: float
):
    """Each solid of ``shapes`` that can be seen, in the camera frame: yields ``(shape, n_c,
    d_c, (u0, u1, v0, v1))``, its planes ``n_c . x_cam <= d_c`` ((F, 3), (F,); m) and the pixel
    rectangle [u0, u1) × [v0, v1) of its projected vertices (the whole image when a vertex is
    behind the camera). Shared by ``raycast_convex`` and its numpy path."""
    H, W = intr.height, intr.width
    T_cam_world = np.linalg.inv(np.asarray(T_world_cam, np.float64))
    R_cw, t_cw = T_cam_world[:3, :3], T_cam_world[:3, 3]
    for shape in shapes:
        n_c = shape.normals @ R_cw.T  # (F, 3) camera frame
        d_c = shape.offsets + n_c @ t_cw  # n.(R x + t) form: n_c . x_cam <= d_c
        pts = shape.vertices @ R_cw.T + t_cw  # (V, 3) camera frame
        z = pts[:, 2]
        if z.max() < near or z.min() > far:
            continue
        if z.min() <= 1e-9:
            yield shape, n_c, d_c, (0, W, 0, H)
            continue
        u = intr.fx * pts[:, 0] / z + intr.cx
        v = intr.fy * pts[:, 1] / z + intr.cy
        u0, u1 = max(0, int(np.ceil(u.min()))), min(W, int(np.floor(u.max())) + 1)
        v0, v1 = max(0, int(np.ceil(v.min()))), min(H, int(np.floor(v.max())) + 1)
        if u0 < u1 and v0 < v1:
            yield shape, n_c, d_c, (u0, u1, v0, v1)


def raycast_convex(
    shapes: list[ConvexShape], intr: Intrinsics, T_world_cam: np.ndarray, near: float, far: float
) -> tuple[np.ndarray, np.ndarray]:
    """Z-depth and body ids of the nearest convex surface through every pixel centre: as
    ``raycast.raycast_boxes`` (the same arguments, frames, units and returns) for the solids of
    ``convex_from_pybullet``, −1 where no solid is seen.

    The arithmetic per pixel and plane is in float64 (a solid has tens of planes, not three,
    and a thin sliver between two nearly parallel planes must not open up by rounding).
    """
    grid = ray_grid(intr)
    H, W = intr.height, intr.width
    depth = np.full((H, W), np.inf, np.float64)
    ids = np.full((H, W), -1, np.int32)
    for shape, n_c, d_c, (u0, u1, v0, v1) in posed_solids(shapes, intr, T_world_cam, near, far):
        half_spaces_into(
            depth, ids, grid.xn64, grid.yn64, u0, u1, v0, v1, n_c, d_c, near, far, shape.body_id
        )  # the loop over the footprint's pixels and the planes, compiled
    depth[ids < 0] = far
    return depth.astype(np.float32), ids


def render_convex_depth(
    client: int,
    intr: Intrinsics,
    T_world_cam: np.ndarray,
    near: float,
    far: float,
    *,
    ground: tuple[float, int] | None = None,
    bodies=None,
):
    """``pipeline.camera.render.render_depth``'s ``"raycast"`` path for a world of convex
    bodies (boxes and convex meshes): a ``DepthFrame`` of the bodies ``bodies`` (default every
    body of the client), with the analytic ground ``(z, body_id)`` filled in where nothing is
    seen (``raycast.fill_ground``)."""
    from pipeline.camera.raycast import fill_ground
    from pipeline.camera.render import DepthFrame

    depth, ids = raycast_convex(convex_from_pybullet(client, bodies), intr, T_world_cam, near, far)
    if ground is not None:
        fill_ground(depth, ids, intr, T_world_cam, ground[0], ground[1], far)
    return DepthFrame(depth_m=depth, body_ids=ids)
