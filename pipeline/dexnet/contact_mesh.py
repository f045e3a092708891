"""Suction contact model for any convex rigid bodies of a pybullet scene (Dex-Net 3.0 style).

``pipeline.dexnet.contact`` labels candidate suction grasps exactly, but only on boxes: it casts
its lines by the slab method. This module applies the same rules, with the same reason codes
(``contact.REASONS``), settings (``pipeline.grasping.suction.SuctionModelConfig``) and result
(``contact.ContactResult``), to the bodies of a pybullet scene, such as the cylinders, prisms
and convex hulls of ``pipeline.simulation.objects``, by casting its lines with
``p.rayTestBatch``. Read ``contact``'s docstring first; only what differs is spelt out here.

Frames and units: candidates, the depth image, the mask and gravity are in the camera frame
(OpenCV: x right, y down, z forward), as in ``contact``; ``T_world_cam`` (4, 4) moves the lines
into the world frame of the pybullet scene, whose hits are moved back. Metres, newtons,
kilograms. Bodies are named by their pybullet unique ids; ``graspable`` lists the bodies that
can be grasped, and the mask value of ``graspable[k-1]`` is k (``ContactResult.instance``).

Line casting (``RayScene``): a point's line starts ``START_OFFSET`` = 0.05 m back along the
approach axis a and runs ``LINE_LENGTH`` = 10 m forward. Lines are not cast against the live
bodies: Bullet intersects a ray with a convex hull shape (``GEOM_MESH`` from vertices, the only
mesh a dynamic body can have) by an iterative convex cast that, measured on a 64-sided cylinder
of 30 mm radius, places hits 1 to 5 mm off the surface (its 1 mm collision margin and its
convergence tolerance) with normals up to 10 degrees off: as large as the 3 mm compliance
itself. ``RayScene`` therefore mirrors the scene, posed as it is now, into a private DIRECT
client of static triangle meshes (the convex hull of each body's collision vertices, a box's 12
triangles), which Bullet intersects exactly (to rounding, ~1e-16 m); ``p.rayTestBatch`` is run
there. A body's base pose in pybullet is that of its inertial frame; a box shape is placed
relative to it by its local frame (``p.getCollisionShapeData``), a mesh's vertices
(``p.getMeshData``) are given in it (both checked in the tests). Supported: base links
of ``GEOM_BOX`` and (convex) ``GEOM_MESH`` shapes; a body with links, or another shape, raises
``ValueError``. As in ``contact``, a line hits a body only where it enters it at or after its
start: the bodies that contain a line's start (half-space test against each copy's faces) are
left out of its cast with Bullet's collision filter groups (a body touching such a body, as a
box resting on another, is still hit where it begins), and a line cast "against the target
only" leaves out every other body the same way.

Rules, checked in this order; the first that fails gives the candidate's ``reason``:

1. ``not_on_box``: the first body the centre line (from ``p``) hits must be graspable (with
   ``targets``: must be the candidate's target body). Hitting anything else (bin floor, bin
   walls, the ground) or nothing: no seal. (Unlike ``contact``, which knows only boxes, a
   non-graspable body in front of the target, such as a bin wall, also fails this rule.)
2. ``off_face``: each of the K rim points' lines (``contact``'s ring, same basis) is cast
   against the target only. A rim line that misses it, or hits it where the surface normal
   differs from the centre hit's by more than ``max_normal_angle_deg`` (default
   ``MAX_NORMAL_ANGLE_DEG`` = 45 degrees): no seal. This is ``contact``'s "another face": on a
   box every other face is 90 degrees away, so both models agree; on a cylinder's or prism's
   edge it is the wrap onto a face that turns away (a regular prism's edges turn by 360/n
   degrees: 120 to 45 for n = 3 to 8; at 45 degrees and below, ``uneven`` decides). The angle
   must exceed the normal angle at which a curved surface's sag alone breaks the seal, so that
   curvature is judged by ``uneven``: across a cylinder of radius R the rim's normals turn by
   asin(r/R) while it sags R - sqrt(R^2 - r^2); the sag reaches the compliance c at
   asin(r/R) = 2 atan(c/r) = 36.9 degrees (r = 9 mm, c = 3 mm), so a 30 degree limit would
   reject curved grasps that seal.
   ``uneven``: the rim hits' heights along a (distances from the start plane) spread more than
   ``compliance``.
3. ``occluded``: exactly as ``contact`` (each rim hit and the centre hit looked up in the image;
   the mask there must be the target's instance and the depth within ``visibility_tolerance``).
4. Wrench, with ``contact``'s formulas (pull, shear, torsion, bending), but the body's own mass
   (``p.getDynamicsInfo``; ``cfg.density`` is not used) and its centre of mass: the position
   ``p.getBasePositionAndOrientation`` returns, which in pybullet is the origin of the base's
   inertial frame, i.e. the centre of mass (for ``objects.create_body`` and ``heap``'s boxes
   the inertial frame is the identity, so it is also the mesh origin / box centre).

``robust_quality_mesh`` perturbs the grasps exactly as ``contact.robust_quality`` does (the same
draws from ``rng`` in the same order) and labels them with ``evaluate_contacts_mesh``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pybullet as p
import trimesh

from pipeline.camera.geometry import pose_matrix
from pipeline.dexnet.contact import (  # noqa: F401  (REASONS etc. re-exported for callers)
    REASONS,
    START_OFFSET,
    ContactResult,
    ContactScene,
    checked_inputs,
    empty_result,
    occluded_contacts,
    perturbed_grasps,
    record_rules,
    rim_ring,
    wrench_failures,
)
from pipeline.grasping.suction import SuctionModelConfig

# Largest angle between a rim hit's surface normal and the centre hit's that still seals.
MAX_NORMAL_ANGLE_DEG = 45.0
# Lines run this far forward from their start, metres.
LINE_LENGTH = 10.0
# Collision filter groups of the copies: every copy is in _ANY; the bodies a cast singles out
# (to cast against them only, or to leave them out) are moved to _PICKED for that cast.
_ANY, _PICKED = 1, 2
# Rays per p.rayTestBatch call (pybullet's limit is 16384).
RAY_BATCH = 8192


@dataclass(frozen=True, eq=False)
class BodyScene(ContactScene):
    """A ``ContactScene`` of pybullet bodies, for ``evaluate_contacts_mesh``: the mask value of
    ``graspable[k-1]`` is k.

    Attributes:
        T_world_cam: (4, 4) camera pose (OpenCV axes) in the world frame of ``client``.
        client: the pybullet client holding the bodies, posed as in the image.
        graspable: body ids of the graspable objects, in mask order.
    """

    T_world_cam: np.ndarray
    client: int
    graspable: Sequence[int]


class RayScene:
    """Exact line casting against a static copy of some bodies of a pybullet scene.

    The copy lives in its own DIRECT client, made of static triangle meshes posed as the source
    bodies are at construction (later motion of the source is not seen). Call ``close`` (or use
    it as a context manager) to free that client.

    Args:
        client: the source pybullet client.
        body_ids: the bodies to copy (default: every body of ``client``).
    """

    def __init__(self, client: int, body_ids: Sequence[int] | None = None) -> None:
        if body_ids is None:
            body_ids = [
                p.getBodyUniqueId(i, physicsClientId=client)
                for i in range(p.getNumBodies(physicsClientId=client))
            ]
        self.source = client
        self.client = p.connect(p.DIRECT)
        self._owner: dict[int, int] = {}  # copy body id -> source body id
        # source body id -> per convex shape: face normals (F, 3), offsets (F,), bounds (2, 3)
        self._planes: dict[int, list[tuple[np.ndarray, np.ndarray, np.ndarray]]] = {}
        try:
            for body in body_ids:
                self._copy(int(body))
        except BaseException:
            self.close()
            raise
        self._owner_lut = np.full(max(self._owner, default=-1) + 2, -1, np.int64)
        for copy, body in self._owner.items():
            self._owner_lut[copy + 1] = body

    def _copy(self, body: int) -> None:
        src = self.source
        if p.getNumJoints(body, physicsClientId=src) > 0:
            raise ValueError(f"body {body} has links: RayScene copies single rigid bodies only")
        pos, quat = p.getBasePositionAndOrientation(body, physicsClientId=src)
        T_base = pose_matrix(np.asarray(pos), np.asarray(quat))  # inertial frame in the world
        self._planes[body] = []
        for k, shape in enumerate(p.getCollisionShapeData(body, -1, physicsClientId=src)):
            geom, dims, local_pos, local_orn = shape[2], shape[3], shape[5], shape[6]
            if geom == p.GEOM_BOX:  # dims: edge lengths; placed by the shape's local frame
                mesh = trimesh.creation.box(extents=np.asarray(dims, np.float64))
                T = T_base @ pose_matrix(np.asarray(local_pos), np.asarray(local_orn))
            elif geom == p.GEOM_MESH:  # getMeshData's vertices are in the base frame already
                _, verts = p.getMeshData(body, -1, collisionShapeIndex=k, physicsClientId=src)
                mesh = trimesh.convex.convex_hull(np.asarray(verts, np.float64))
                T = T_base
            else:
                raise ValueError(
                    f"body {body} has a collision shape of pybullet geometry type "
                    f"{geom}: RayScene copies boxes and convex meshes only"
                )
            world = np.asarray(mesh.vertices, np.float64) @ T[:3, :3].T + T[:3, 3]
            faces = np.asarray(mesh.faces, np.int64)
            col = p.createCollisionShape(
                p.GEOM_MESH,
                vertices=world.tolist(),
                indices=faces.reshape(-1).tolist(),
                flags=p.GEOM_FORCE_CONCAVE_TRIMESH,
                physicsClientId=self.client,
            )
            copy = p.createMultiBody(0.0, col, -1, physicsClientId=self.client)
            p.setCollisionFilterGroupMask(copy, -1, _ANY, -1, physicsClientId=self.client)
            self._owner[copy] = body
            hull = trimesh.Trimesh(world, faces, process=False)
            normals = np.asarray(hull.face_normals, np.float64)
            offsets = np.einsum("fi,fi->f", normals, world[faces[:, 0]])
            self._planes[body].append((normals, offsets, np.stack([world.min(0), world.max(0)])))

    @property
    def bodies(self) -> list[int]:
        """The source body ids copied."""
        return list(self._planes)

    def contains(self, body: int, points: np.ndarray) -> np.ndarray:
        """(R,) bool: which of the (R, 3) world points lie strictly inside ``body`` (inside one
        of its convex collision shapes)."""
        x = np.asarray(points, np.float64).reshape(-1, 3)
        inside = np.zeros(len(x), bool)
        for normals, offsets, bounds in self._planes.get(int(body), []):
            near = np.flatnonzero(np.all((x > bounds[0]) & (x < bounds[1]), axis=1))
            if len(near):
                inside[near] |= (x[near] @ normals.T - offsets).max(axis=1) < 0.0
        return inside

    def _batch(self, starts: np.ndarray, ends: np.ndarray, mask: int):
        """First hits of the lines ``starts`` -> ``ends`` ((R, 3) world) among the copies whose
        group is in ``mask``: source body id (-1: none), hit point and normal, (R,), (R, 3)."""
        out = []
        for i in range(0, len(starts), RAY_BATCH):
            out += p.rayTestBatch(
                np.ascontiguousarray(starts[i : i + RAY_BATCH]),
                np.ascontiguousarray(ends[i : i + RAY_BATCH]),
                numThreads=1,
                collisionFilterMask=mask,
                physicsClientId=self.client,
            )
        copy = np.array([h[0] for h in out], np.int64)
        point = np.array([h[3] for h in out], np.float64).reshape(-1, 3)
        normal = np.array([h[4] for h in out], np.float64).reshape(-1, 3)
        return self._owner_lut[copy + 1], point, normal

    def _picked(self, bodies, starts: np.ndarray, ends: np.ndarray, mask: int):
        """``_batch`` with the copies of ``bodies`` in group ``_PICKED`` (the rest in ``_ANY``)."""
        copies = [c for c, b in self._owner.items() if b in bodies]
        for c in copies:
            p.setCollisionFilterGroupMask(c, -1, _PICKED, -1, physicsClientId=self.client)
        try:
            return self._batch(starts, ends, mask)
        finally:
            for c in copies:
                p.setCollisionFilterGroupMask(c, -1, _ANY, -1, physicsClientId=self.client)

    def cast(
        self, starts: np.ndarray, dirs: np.ndarray, want: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The first hit of each line ``starts + s dirs`` (0 <= s <= ``LINE_LENGTH``) on a body
        that does not contain the line's start; where ``want`` is given, on that body only.

        Args:
            starts: (R, 3) line starts in the world frame, m.
            dirs: (R, 3) unit directions in the world frame.
            want: optional (R,) body id each line is cast against (the others are ignored).

        Returns:
            body: (R,) int64 source body id hit, -1 where none.
            s: (R,) float64 distance of the hit from the start along the line, m (inf: none).
            normal: (R, 3) unit outward surface normal at the hit (world frame), 0 where none.
        """
        starts = np.asarray(starts, np.float64).reshape(-1, 3)
        dirs = np.asarray(dirs, np.float64).reshape(-1, 3)
        n = len(starts)
        body = np.full(n, -1, np.int64)
        s = np.full(n, np.inf)
        normal = np.zeros((n, 3))
        ends = starts + LINE_LENGTH * dirs

        def keep(rows, hit_body, point, hit_normal):
            hit = hit_body >= 0
            rows = rows[hit]
            body[rows] = hit_body[hit]
            s[rows] = np.einsum("ri,ri->r", point[hit] - starts[rows], dirs[rows])
            normal[rows] = hit_normal[hit]

        if want is None:
            order = self.bodies
            inside = np.stack([self.contains(b, starts) for b in order], axis=1)  # (R, B)
            free = ~inside.any(axis=1)
            rows = np.flatnonzero(free)
            if len(rows):
                keep(rows, *self._batch(starts[rows], ends[rows], _ANY | _PICKED))
            if not free.all():
                sets, which = np.unique(inside[~free], axis=0, return_inverse=True)
                trapped = np.flatnonzero(~free)
                for j, row in enumerate(sets):
                    rows = trapped[which.reshape(-1) == j]
                    left_out = {b for b, out in zip(order, row) if out}
                    keep(rows, *self._picked(left_out, starts[rows], ends[rows], _ANY))
            return body, s, normal
        want = np.asarray(want, np.int64).reshape(-1)
        if len(want) != n:
            raise ValueError(f"{n} lines but {len(want)} wanted bodies")
        for b in np.unique(want):
            if int(b) not in self._planes:
                raise ValueError(f"body {int(b)} is not in this RayScene")
            rows = np.flatnonzero(want == b)
            rows = rows[~self.contains(b, starts[rows])]  # a start inside: no hit
            if len(rows):
                keep(rows, *self._picked({int(b)}, starts[rows], ends[rows], _PICKED))
        return body, s, normal

    def close(self) -> None:
        """Disconnect the copy's client (idempotent)."""
        if self.client is not None and self.client >= 0:
            p.disconnect(physicsClientId=self.client)
        self.client = None

    def __enter__(self) -> RayScene:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def evaluate_contacts_mesh(
    points_cam: np.ndarray,
    axes_cam: np.ndarray,
    scene: BodyScene,
    cfg: SuctionModelConfig,
    *,
    targets: np.ndarray | None = None,
    rays: RayScene | None = None,
    max_normal_angle_deg: float = MAX_NORMAL_ANGLE_DEG,
) -> ContactResult:
    """Seal and wrench resistance of N suction grasps on pybullet bodies, by the rules of the
    module docstring.

    Args:
        points_cam: (N, 3) contact points in the camera frame, m.
        axes_cam: (N, 3) approach axes in the camera frame, pointing into the object; normalised
            here.
        scene: the image (depth, instance mask, intrinsics), the camera's pose in the world of
            the pybullet client, the graspable bodies and gravity's direction.
        cfg: model settings (``density`` is not used: each body has its own mass).
        targets: optional (N,) body id each candidate is meant for (each one of
            ``scene.graspable``); None: the first body the centre line hits is the target when
            it is graspable.
        rays: a ``RayScene`` of ``scene.client`` to reuse (it must hold every body a line may
            meet); None: one of all the client's bodies is made and closed here.
        max_normal_angle_deg: rule 2's largest rim normal deviation, degrees.

    Returns:
        A ContactResult of (N,) arrays; ``instance`` is k for ``scene.graspable[k-1]``, 0 = none.
    """
    pts, a, g_dir = checked_inputs(points_cam, axes_cam, scene, cfg)
    graspable = [int(b) for b in scene.graspable]
    n = len(pts)
    if targets is not None:
        targets = np.asarray(targets, np.int64).reshape(-1)
        if len(targets) != n:
            raise ValueError(f"{n} points but {len(targets)} targets")
        if not np.all(np.isin(targets, graspable)):
            raise ValueError("every target must be one of the graspable bodies")
    out = empty_result(n)
    if n == 0 or not graspable:
        return out
    own = rays is None
    if own:
        rays = RayScene(scene.client)
    try:
        return _evaluate(
            pts, a, scene, graspable, g_dir, cfg, targets, rays, max_normal_angle_deg, out
        )
    finally:
        if own:
            rays.close()


def _evaluate(
    pts,
    a,
    scene: BodyScene,
    graspable,
    g_dir,
    cfg,
    targets,
    rays: RayScene,
    max_angle_deg: float,
    out: ContactResult,
) -> ContactResult:
    T_wc = np.asarray(scene.T_world_cam, np.float64)
    R_wc, t_wc = T_wc[:3, :3], T_wc[:3, 3]
    client = scene.client

    # Rule 1: the centre line's first hit, against every body.
    start = pts - START_OFFSET * a
    body0, s0, normal0 = rays.cast(start @ R_wc.T + t_wc, a @ R_wc.T)
    ok = np.isin(body0, graspable) if targets is None else body0 == targets
    on = np.flatnonzero(ok)
    if len(on) == 0:
        return out
    tgt, a_on, start_on = body0[on], a[on], start[on]
    hit0 = start_on + s0[on, None] * a_on  # (M, 3) contact point, camera frame
    m, k = len(on), cfg.ring_points

    # Rule 2: the rim's lines against the target only.
    rim_start = start_on[:, None, :] + rim_ring(a_on, cfg)  # (M, K, 3)
    rim_body, s_rim, rim_normal = rays.cast(
        rim_start.reshape(-1, 3) @ R_wc.T + t_wc,
        np.repeat(a_on @ R_wc.T, k, axis=0),
        want=np.repeat(tgt, k),
    )
    rim_body, s_rim = rim_body.reshape(m, k), s_rim.reshape(m, k)
    cos_dev = np.einsum("mki,mi->mk", rim_normal.reshape(m, k, 3), normal0[on])
    same_face = cos_dev >= np.cos(np.radians(max_angle_deg))
    off_face = ~np.all((rim_body == tgt[:, None]) & same_face, axis=1)
    s_rim = np.where(np.isfinite(s_rim), s_rim, 0.0)  # off_face rows are decided already
    uneven = np.ptp(s_rim, axis=1) > cfg.compliance

    # Rule 3: the rim's hits and the centre's hit must be what the camera sees there.
    inst = np.array([graspable.index(int(b)) + 1 for b in tgt], np.int64)
    pts3 = np.concatenate(
        [rim_start + s_rim[..., None] * a_on[:, None, :], hit0[:, None, :]], axis=1
    )  # (M, K + 1, 3)
    occluded = occluded_contacts(pts3, inst, scene, cfg)

    # Rule 4: the body's weight against the soft contact's wrench limits.
    mass = np.array([p.getDynamicsInfo(int(b), -1, physicsClientId=client)[0] for b in tgt])
    com_w = np.array(
        [p.getBasePositionAndOrientation(int(b), physicsClientId=client)[0] for b in tgt],
        np.float64,
    ).reshape(-1, 3)
    com = (com_w - t_wc) @ R_wc  # camera frame
    wrench = wrench_failures(mass, com, hit0, a_on, g_dir, cfg)
    return record_rules(out, on, inst, off_face, uneven, occluded, wrench)


def robust_quality_mesh(
    points_cam: np.ndarray,
    axes_cam: np.ndarray,
    scene: BodyScene,
    cfg: SuctionModelConfig,
    rng: np.random.Generator,
    *,
    targets: np.ndarray | None = None,
    rays: RayScene | None = None,
    max_normal_angle_deg: float = MAX_NORMAL_ANGLE_DEG,
) -> np.ndarray:
    """Robust quality of N suction grasps on pybullet bodies: the share of perturbed grasps that
    seal and resist (Dex-Net 3.0).

    The perturbations are ``contact.perturbed_grasps``, as in ``contact.robust_quality``, so for
    the same generator state both functions perturb the same grasps the same way. All perturbed
    grasps are labelled by one call of
    ``evaluate_contacts_mesh``; a candidate's perturbations keep its target.

    Args:
        points_cam, axes_cam, scene, cfg, targets, rays, max_normal_angle_deg: as for
            ``evaluate_contacts_mesh``.
        rng: source of the perturbations; the same generator state gives the same result.

    Returns:
        (N,) float64 in [0, 1]; a positive label where >= ``cfg.quality_threshold``.
    """
    points, axes = perturbed_grasps(points_cam, axes_cam, cfg, rng)
    n, k = points.shape[:2]
    if n == 0:
        return np.zeros(0)
    if targets is not None:
        targets = np.repeat(np.asarray(targets, np.int64).reshape(-1), k)
    result = evaluate_contacts_mesh(
        points.reshape(-1, 3),
        axes.reshape(-1, 3),
        scene,
        cfg,
        targets=targets,
        rays=rays,
        max_normal_angle_deg=max_normal_angle_deg,
    )
    return result.wrench_ok.reshape(n, k).mean(axis=1)
