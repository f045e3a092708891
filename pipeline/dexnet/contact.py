"""Suction contact model that labels candidate suction grasps in simulation (Dex-Net 3.0 style).

In simulation each box's true geometry, pose, mass and centre of mass are known, so a candidate
suction grasp (a contact point and an approach axis) can be labelled analytically, as Dex-Net
labels its training grasps. The model has one cup: a rim of ``ring_points`` points on a circle
of radius ``cup_radius``. Dex-Net 3.0's model of the cup as a ring of springs that must stay
within their rest lengths is replaced by the rules below, which are exact for boxes (flat faces).

Frames and units: camera frame (OpenCV: x right, y down, z forward), metres, newtons; pixels
(u, v) with (0, 0) the centre of the top-left pixel (``pipeline.camera.geometry``). Boxes have
``size`` (3,) edge lengths along their own x, y, z and ``T_cam_box`` (4, 4), the pose of the
box centre in the camera frame; the mask value of ``boxes[k-1]`` is k. Faces are numbered in the
order of ``pipeline.grasping.surfaces.FACES``: +x, -x, +y, -y, +z, -z (outward box-frame normal).

Line casting: a point's line starts ``START_OFFSET`` = 0.05 m back along the approach axis a
(``x - 0.05 a``) and runs forward (+a). It is intersected with a box by the slab method in the
box's frame. A line hits a box only if it enters the box at or after its start (a start inside
a box is no hit); the face it enters through is the hit face, its distance from the start along
a is the hit's height.

Rules, checked in this order; the first that fails gives the candidate's ``reason``:

1. ``not_on_box``: the target box is the first box the centre line (from ``p``) hits, and its hit
   face is the centre's face. No box hit (bin floor, bin walls, free space): no seal.
2. ``off_face``: the rim's K points lie on the circle of radius ``cup_radius`` around ``p`` in the
   plane perpendicular to a. Each rim point's line is cast against the target box only. A rim
   line that misses it or hits another face than the centre's: no seal (edges, corners, faces
   smaller than the cup).
   ``uneven``: if the rim hits' heights spread more than ``compliance`` (max - min), the cup's
   lip cannot conform and there is no seal (a tilted approach: the spread on a flat face is
   2 r tan(tilt)).
3. ``occluded``: each rim hit point, and the centre's hit point, is projected into the image and
   looked up at the nearest pixel. If it falls outside the image, or the mask there is not the
   target's instance, or the depth there differs from the point's z by more than
   ``visibility_tolerance`` (no data counts as a difference), something else lies on the seal
   area (another box on top) and there is no seal. Checking the centre too (beyond the rim) also
   rejects an object smaller than the cup lying inside the ring.
4. Wrench resistance (sealed grasps only): the only external load is the box's weight, held
   statically. Mass ``m = density x volume``, centre of mass c = the box centre, weight
   ``F = m g gravity_cam``. With the contact point x (the centre's hit point on the face):

   - ``pull``: pull-off ``f_pull = F . a`` (positive when the weight pulls the box off the
     cup), normal force ``f_N = vacuum_force - f_pull``; ``f_N < 0`` fails.
   - ``shear``: the tangential load ``|F - (F . a) a| <= friction f_N`` (friction cone).
   - ``torsion``: the weight's torque about the contact, ``tau = (c - x) x F``, about the axis:
     ``|tau . a| <= cup_radius friction f_N`` (friction over the contact ring).
   - ``bending``: the torque perpendicular to the axis ``|tau - (tau . a) a| <= cup_radius f_N``
     (the vacuum holding the rim down acts on a lever of one cup radius).

   This is Dex-Net 3.0's soft suction contact wrench set (friction, torsion, bending and the
   vacuum limit on the normal force) with isotropic limits (norms instead of Dex-Net's
   per-component box with its sqrt(3) and sqrt(2) factors) and with the bending limit taken as
   rim lever x normal force rather than their fitted elastic constant pi r kappa.

Robust quality (``robust_quality``) follows Dex-Net: the share of randomly perturbed grasps that
both seal and resist the wrench; Dex-Net 4.0 labels a grasp positive at >= 0.5
(``quality_threshold``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from pipeline.camera.geometry import Intrinsics
from pipeline.grasping.suction import SuctionModelConfig, box_mass

# Reason codes of ContactResult.reason: REASONS[code] is its name.
REASONS = (
    "ok",
    "not_on_box",
    "off_face",
    "uneven",
    "occluded",
    "pull",
    "shear",
    "torsion",
    "bending",
)

# The columns of a labelled suction candidate (the baseline's candidate shards, in-domain and out
# of domain; a scene index column precedes them):
LABELLED_CANDIDATE_FIELDS = {
    "uv": "(M, 2) int64 pixel (u, v)",
    "point": "(M, 3) float64 contact point, camera frame, m",
    "axis": "(M, 3) float64 approach axis (into the object), camera frame",
    "depth": "(M,) float64 m",
    "angle": "(M,) float64 rad from the optical axis",
    "quality": "(M,) float64 robust quality in [0, 1]",
    "label": "(M,) bool quality >= suction.quality_threshold",
    "reason": "(M,) int8 unperturbed contact outcome, index into reasons",
}
# Lines are cast from this far back along the approach axis, metres.
START_OFFSET = 0.05


@dataclass
class ContactResult:
    """Labels of N candidate suction grasps; every array has shape (N,).

    Attributes:
        seal: bool, the cup seals on the target face (rules 1-3).
        wrench_ok: bool, sealed and the seal holds the box's weight (rule 4); False where
            ``seal`` is False.
        reason: int8 code of the first rule that failed, ``REASONS[code]`` its name
            (0 = "ok": sealed and the wrench is resisted).
        instance: int, mask instance of the target box (``boxes[instance - 1]``), 0 = none.
    """

    seal: np.ndarray
    wrench_ok: np.ndarray
    reason: np.ndarray
    instance: np.ndarray


@dataclass(frozen=True, eq=False)
class ContactScene:
    """What suction grasps are labelled against, camera frame (OpenCV axes), metres: the image
    that rule 3 checks the contacts against and gravity's direction for rule 4. ``BoxScene``
    adds the boxes (``evaluate_contacts``), ``contact_mesh.BodyScene`` the pybullet bodies
    (``contact_mesh.evaluate_contacts_mesh``).

    Attributes:
        depth_m: (H, W) z-depth in metres, 0 = no data (noise-free depth for exact labels).
        mask: (H, W) instance mask: 0 = nothing graspable, k = the k-th object of the scene
            (``BoxScene.boxes[k-1]``, ``BodyScene.graspable[k-1]``).
        intrinsics: the camera's intrinsics; the image size must match depth and mask.
        gravity_cam: (3,) direction of gravity in the camera frame; normalised where used.
    """

    depth_m: np.ndarray
    mask: np.ndarray
    intrinsics: Intrinsics
    gravity_cam: np.ndarray


@dataclass(frozen=True, eq=False)
class BoxScene(ContactScene):
    """A ``ContactScene`` of boxes, for ``evaluate_contacts``: the mask value of ``boxes[k-1]``
    is k.

    Attributes:
        boxes: sequence of objects with ``size`` (3,) edge lengths in metres, optionally
            ``mass`` (kg; None or absent: ``cfg.density`` x volume), and ``T_cam_box``
            (4, 4) box-centre pose in the camera frame (e.g. ``pipeline.dataset.scenes.Box``).
    """

    boxes: Sequence


def _slab(origins: np.ndarray, dirs: np.ndarray, half: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Lines ``origins + s dirs`` (s >= 0) against boxes centred at the origin, in the box frame.

    Args:
        origins, dirs: (..., 3) line starts and directions in the box frame, broadcastable.
        half: (..., 3) half edge lengths, broadcastable.

    Returns:
        s: (...) where the line enters the box (inf where it does not hit at s >= 0).
        face: (...) int index of the entry face in ``FACES`` order (2 axis + (dir > 0)); only
            meaningful where s is finite.
    """
    # A direction component of exactly 0 becomes a tiny one: the slab is then (-inf, inf) for
    # starts inside it and empty (a huge entry) for starts outside it.
    d = np.where(np.abs(dirs) < 1e-12, np.where(dirs < 0, -1e-12, 1e-12), dirs)
    t1 = (-half - origins) / d
    t2 = (half - origins) / d
    near = np.minimum(t1, t2)
    far = np.maximum(t1, t2)
    axis = np.argmax(near, axis=-1)
    s_in = np.take_along_axis(near, axis[..., None], axis=-1)[..., 0]
    s_out = far.min(axis=-1)
    hit = (s_in <= s_out) & (s_in >= 0.0)
    d_axis = np.take_along_axis(np.broadcast_to(d, near.shape), axis[..., None], axis=-1)[..., 0]
    face = 2 * axis + (d_axis > 0)
    return np.where(hit, s_in, np.inf), face


def perpendicular_basis(axes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit vectors e1, e2, each (N, 3), with (e1, e2, a) a right-handed orthonormal frame for
    each unit axis a of the (N, 3) ``axes``."""
    helper = np.zeros_like(axes)
    use_y = np.abs(axes[:, 0]) > 0.9
    helper[~use_y, 0] = 1.0
    helper[use_y, 1] = 1.0
    e1 = np.cross(axes, helper)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    return e1, np.cross(axes, e1)


def unit_rows(x: np.ndarray, name: str) -> np.ndarray:
    """``x`` (..., 3) with each row scaled to unit length; ValueError naming ``name`` for a zero
    row."""
    norm = np.linalg.norm(x, axis=-1, keepdims=True)
    if np.any(norm < 1e-9):
        raise ValueError(f"{name} has a zero-length vector")
    return x / norm


def checked_inputs(
    points_cam, axes_cam, scene: ContactScene, cfg: SuctionModelConfig
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The contact models' inputs checked: (points (N, 3), unit axes (N, 3), unit gravity (3,)),
    camera frame. Raises ``ValueError`` for unequal point and axis counts, a depth image or mask
    that is not the intrinsics' (H, W), fewer than 3 rim points, or a zero axis or gravity."""
    p = np.asarray(points_cam, dtype=np.float64).reshape(-1, 3)
    a = unit_rows(np.asarray(axes_cam, dtype=np.float64).reshape(-1, 3), "axes_cam")
    if len(a) != len(p):
        raise ValueError(f"{len(p)} points but {len(a)} axes")
    depth_m, mask = scene.depth_m, scene.mask
    shape = (scene.intrinsics.height, scene.intrinsics.width)
    if depth_m.shape != shape or mask.shape != shape:
        raise ValueError(
            f"depth {depth_m.shape} and mask {mask.shape} must both be (H, W) = "
            f"{shape}, the camera intrinsics' image size"
        )
    if cfg.ring_points < 3:
        raise ValueError(f"ring_points must be >= 3, not {cfg.ring_points}")
    g_dir = unit_rows(np.asarray(scene.gravity_cam, dtype=np.float64).reshape(3), "gravity_cam")
    return p, a, g_dir


def empty_result(n: int) -> ContactResult:
    """N candidates on nothing: no seal, no wrench, reason "not_on_box", instance 0."""
    return ContactResult(
        np.zeros(n, dtype=bool),
        np.zeros(n, dtype=bool),
        np.full(n, REASONS.index("not_on_box"), dtype=np.int8),
        np.zeros(n, dtype=np.int64),
    )


def rim_ring(axes: np.ndarray, cfg: SuctionModelConfig) -> np.ndarray:
    """(M, K, 3) offsets of the cup rim's K = ``ring_points`` points from the centre line, on a
    circle of ``cup_radius`` perpendicular to each unit axis of ``axes`` (M, 3), evenly spaced
    from the first ``perpendicular_basis`` vector."""
    e1, e2 = perpendicular_basis(axes)
    angles = 2.0 * np.pi * np.arange(cfg.ring_points) / cfg.ring_points
    return cfg.cup_radius * (
        np.cos(angles)[None, :, None] * e1[:, None, :]
        + np.sin(angles)[None, :, None] * e2[:, None, :]
    )


def occluded_contacts(
    points: np.ndarray, instance: np.ndarray, scene: ContactScene, cfg: SuctionModelConfig
) -> np.ndarray:
    """Rule 3: (M,) whether any of each candidate's contact points (M, P, 3) (rim hits and the
    centre's, camera frame) is not what the camera of ``scene`` sees there: outside the image or
    behind it, another instance in its mask than ``instance`` (M,), or a depth more than
    ``visibility_tolerance`` away."""
    depth_m, mask, intrinsics = scene.depth_m, scene.mask, scene.intrinsics
    z = points[..., 2]
    in_front = z > 1e-9
    z_safe = np.where(in_front, z, 1.0)
    u = np.rint(intrinsics.fx * points[..., 0] / z_safe + intrinsics.cx)
    v = np.rint(intrinsics.fy * points[..., 1] / z_safe + intrinsics.cy)
    inside = in_front & (u >= 0) & (u < intrinsics.width) & (v >= 0) & (v < intrinsics.height)
    ui = np.where(inside, u, 0).astype(np.intp)
    vi = np.where(inside, v, 0).astype(np.intp)
    seen = (
        inside
        & (mask[vi, ui] == instance[:, None])
        & (np.abs(depth_m[vi, ui] - z) <= cfg.visibility_tolerance)
    )
    return ~np.all(seen, axis=1)


def wrench_failures(
    mass: np.ndarray,
    com: np.ndarray,
    contact: np.ndarray,
    axes: np.ndarray,
    g_dir: np.ndarray,
    cfg: SuctionModelConfig,
) -> list[np.ndarray]:
    """Rule 4: the object's weight against the soft contact's wrench limits, per candidate.
    ``mass`` (M,) kg, ``com`` and ``contact`` (M, 3) and ``axes`` (M, 3) unit, ``g_dir`` (3,)
    unit, one frame. Returns the (M,) failures [pull, shear, torsion, bending]."""
    F = (mass * cfg.gravity)[:, None] * g_dir  # (M, 3)
    f_pull = np.einsum("mi,mi->m", F, axes)
    f_n = cfg.vacuum_force - f_pull
    shear = np.linalg.norm(F - f_pull[:, None] * axes, axis=1)
    tau = np.cross(com - contact, F)
    tau_axial = np.einsum("mi,mi->m", tau, axes)
    bend = np.linalg.norm(tau - tau_axial[:, None] * axes, axis=1)
    r, mu = cfg.cup_radius, cfg.friction
    return [f_n < 0.0, shear > mu * f_n, np.abs(tau_axial) > r * mu * f_n, bend > r * f_n]


def record_rules(
    out: ContactResult,
    on: np.ndarray,
    instance: np.ndarray,
    off_face: np.ndarray,
    uneven: np.ndarray,
    occluded: np.ndarray,
    wrench: list[np.ndarray],
) -> ContactResult:
    """Write the candidates ``on``'s rule outcomes into ``out``: the first failed rule is the
    reason (off_face, uneven, occluded, then pull, shear, torsion, bending), a seal is no
    rule-2/3 failure, wrench_ok a seal and no rule-4 failure."""
    conditions = [off_face, uneven, occluded, *wrench]
    names = ["off_face", "uneven", "occluded", "pull", "shear", "torsion", "bending"]
    sealed = ~off_face & ~uneven & ~occluded
    out.reason[on] = np.select(conditions, [REASONS.index(k) for k in names], REASONS.index("ok"))
    out.instance[on] = instance
    out.seal[on] = sealed
    out.wrench_ok[on] = sealed & ~np.any(wrench, axis=0)
    return out


def evaluate_contacts(
    points_cam: np.ndarray, axes_cam: np.ndarray, scene: BoxScene, cfg: SuctionModelConfig
) -> ContactResult:
    """Seal and wrench resistance of N suction grasps, by the rules of the module docstring.

    Args:
        points_cam: (N, 3) contact points in the camera frame, metres.
        axes_cam: (N, 3) approach axes in the camera frame, pointing into the object (away from
            the camera); normalised here.
        scene: the image (depth, instance mask, intrinsics), the true boxes and gravity's
            direction, camera frame.
        cfg: model settings.

    Returns:
        A ContactResult of (N,) arrays.
    """
    p, a, g_dir = checked_inputs(points_cam, axes_cam, scene, cfg)
    boxes = scene.boxes
    n = len(p)
    out = empty_result(n)
    if n == 0 or len(boxes) == 0:
        return out

    T = np.stack([np.asarray(b.T_cam_box, dtype=np.float64) for b in boxes])  # (B, 4, 4)
    R, centre = T[:, :3, :3], T[:, :3, 3]  # box axes as columns; box centres
    size = np.stack([np.asarray(b.size, dtype=np.float64) for b in boxes])  # (B, 3)
    half = size / 2.0

    # Rule 1: the centre line against every box; the first entered is the target.
    start = p - START_OFFSET * a
    o_local = np.einsum("nbj,bji->nbi", start[:, None, :] - centre[None], R)  # (N, B, 3)
    d_local = np.einsum("nj,bji->nbi", a, R)
    s_all, face_all = _slab(o_local, d_local, half[None])
    target = np.argmin(s_all, axis=1)
    rows = np.arange(n)
    s0 = s_all[rows, target]
    on = np.flatnonzero(np.isfinite(s0))
    if len(on) == 0:
        return out
    b, a_on, start_on = target[on], a[on], start[on]
    face0 = face_all[on, b]
    hit0 = start_on + s0[on, None] * a_on  # (M, 3) contact point on the face

    # Rule 2: the rim's lines against the target box only.
    rim_start = start_on[:, None, :] + rim_ring(a_on, cfg)  # (M, K, 3)
    Rb = R[b]
    rim_o = np.einsum("mkj,mji->mki", rim_start - centre[b][:, None, :], Rb)
    rim_d = np.einsum("mj,mji->mi", a_on, Rb)[:, None, :]
    s_rim, face_rim = _slab(rim_o, rim_d, half[b][:, None, :])  # (M, K)
    off_face = ~np.all(np.isfinite(s_rim) & (face_rim == face0[:, None]), axis=1)
    s_rim = np.where(np.isfinite(s_rim), s_rim, 0.0)  # off_face rows are decided already
    uneven = np.ptp(s_rim, axis=1) > cfg.compliance

    # Rule 3: the rim's hits and the centre's hit must be what the camera sees there.
    pts = np.concatenate(
        [rim_start + s_rim[..., None] * a_on[:, None, :], hit0[:, None, :]], axis=1
    )  # (M, K + 1, 3)
    occluded = occluded_contacts(pts, b + 1, scene, cfg)

    # Rule 4: the box's weight against the soft contact's wrench limits.
    mass = np.array([box_mass(x, cfg.density) for x in boxes])[b]  # (M,)
    wrench = wrench_failures(mass, centre[b], hit0, a_on, g_dir, cfg)
    return record_rules(out, on, b + 1, off_face, uneven, occluded, wrench)


def robust_quality(
    points_cam: np.ndarray,
    axes_cam: np.ndarray,
    scene: BoxScene,
    cfg: SuctionModelConfig,
    rng: np.random.Generator,
) -> np.ndarray:
    """Robust quality of N suction grasps: the share of perturbed grasps that seal and resist.

    Each candidate gets ``cfg.perturbations`` perturbed grasps. The contact point is shifted in
    the plane perpendicular to the (unperturbed) axis by N(0, sigma_position) along each of two
    orthonormal in-plane directions; the axis is tilted by an angle |N(0, sigma_axis_deg)|
    towards a uniformly random in-plane direction. Every perturbed grasp is labelled by
    ``evaluate_contacts`` (one vectorised call over candidates x perturbations).

    Args:
        points_cam, axes_cam, scene, cfg: as for ``evaluate_contacts``.
        rng: source of the perturbations; the same generator state gives the same result.

    Returns:
        (N,) float64 in [0, 1]; a candidate is a positive label where it is
        >= ``cfg.quality_threshold``.
    """
    points, axes = perturbed_grasps(points_cam, axes_cam, cfg, rng)
    if len(points) == 0:
        return np.zeros(0)
    result = evaluate_contacts(points.reshape(-1, 3), axes.reshape(-1, 3), scene, cfg)
    return result.wrench_ok.reshape(points.shape[:2]).mean(axis=1)


def perturbed_grasps(
    points_cam: np.ndarray, axes_cam: np.ndarray, cfg: SuctionModelConfig, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """``cfg.perturbations`` = P perturbed copies of each of N grasps (``robust_quality``'s
    model): points (N, P, 3) and unit axes (N, P, 3), camera frame. Drawn from ``rng`` in this
    order: in-plane shifts (N, P, 2) of N(0, sigma_position), tilts (N, P) of
    |N(0, sigma_axis_deg)|, tilt directions (N, P) uniform in [0, 2 pi)."""
    p = np.asarray(points_cam, dtype=np.float64).reshape(-1, 3)
    a = unit_rows(np.asarray(axes_cam, dtype=np.float64).reshape(-1, 3), "axes_cam")
    n, k = len(p), cfg.perturbations
    if k < 1:
        raise ValueError(f"perturbations must be >= 1, not {k}")
    if n == 0:
        return np.zeros((0, k, 3)), np.zeros((0, k, 3))
    shift = rng.normal(0.0, cfg.sigma_position, size=(n, k, 2))
    tilt = np.abs(rng.normal(0.0, np.radians(cfg.sigma_axis_deg), size=(n, k)))
    phi = rng.uniform(0.0, 2.0 * np.pi, size=(n, k))
    e1, e2 = perpendicular_basis(a)
    e1, e2, a3 = e1[:, None, :], e2[:, None, :], a[:, None, :]
    points = p[:, None, :] + shift[..., :1] * e1 + shift[..., 1:] * e2
    towards = np.cos(phi)[..., None] * e1 + np.sin(phi)[..., None] * e2
    axes = np.cos(tilt)[..., None] * a3 + np.sin(tilt)[..., None] * towards
    return points, axes
