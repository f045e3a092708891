"""Grasp point score ranking (paper Sec. 4.2, Eqs. 7–10).

    J_i = J_distance     if φ < π/6,  else J_inclination                           (7)
    φ = arccos(n^Z / |n|)                                                         (8)
    J_distance = 1 − I(g^u, g^v) / D_ground                                       (9)
    J_inclination = 1 − 2 φ / π                                                  (10)

**Normal and φ.** The normal at g is Eq. 14's n_p = (P(u+1,v) − P(u−1,v)) × (P(u,v+1) −
P(u,v−1)) on the back-projected depth image (camera frame, OpenCV), each n_p normalised and
averaged over a (2h+1)² window around g, skipping pixels with no data or with a depth jump (an
object edge) to a neighbour. For a surface facing the camera Eq. 14's cross product points
*away* from it (+z for a level surface: x-right × y-down = z-forward), which is what makes Eq. 8
give φ = 0 for a level surface. ``GraspCandidate.normal_cam`` is reported pointing *towards* the
camera (n · P < 0, like the labels' ``normal_cam``), so with that n, φ = arccos(−n_z / |n|): the
angle between −n (Eq. 14's orientation) and the camera's +Z axis. A level surface facing the
camera has φ = 0, a surface seen edge-on φ = π/2.

**Depth I(g).** The depth of the pixel nearest g; if it has no data, the median valid depth of
the window. A candidate with no valid depth or normal in its window is dropped.

**Policies** (``RankingConfig.policy``):

- ``"paper"``: sort by J (Eq. 7), ties by class probability. Any surface inclined by 30°–60°
  (J_inclination ≥ 1/3) outranks every level one (J_distance is 0.07–0.3 in the bin), and among
  inclined surfaces height plays no part.
- ``"height_tiebreak"`` (the fix the paper proposes in Sec. 8.4 for Fig. 11, where a lower box
  with a slightly smaller inclination was picked instead of the upper one): take the candidates
  in the paper's order; when the best remaining one is inclined (φ ≥ π/6), every remaining
  candidate whose φ differs from its φ by less than ``inclination_tie`` competes with it on
  height, and the highest (largest J_distance) goes next. Repeat on the rest.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from pipeline.camera.geometry import Intrinsics, backproject
from pipeline.grasping.types import GraspClass
from pipeline.planner.decode import GraspPrediction


@dataclass
class RankingConfig:
    """How candidates are ranked: ``train.ranking`` (angles there in degrees), with D_ground
    (``pipeline.camera.geometry.ground_distance``) and th (the training stage's calibrated or
    fixed value) given by the caller; built by ``pipeline.planner.planner.ranking_config`` and
    stored with the model (Tables 1 and 2). The closed loop builds it again from the evaluate
    stage's composed ``train.ranking``, with the model's th."""

    d_ground: float  # D_ground, camera-to-ground distance at the home pose, metres (Eq. 9)
    threshold: float  # th of Eq. 3 (the paper gives no value)
    phi_switch: float  # Eq. 7's switch from J_distance to J_inclination, rad
    normal_half_window: int  # h: the normal is averaged over (2h + 1)² pixels
    max_depth_jump: float  # m; a larger depth step to a neighbour marks an edge
    policy: str  # "paper" | "height_tiebreak" (module docstring)
    inclination_tie: float  # rad; "height_tiebreak": inclinations this close tie


POLICIES = ("paper", "height_tiebreak")


@dataclass
class GraspCandidate:
    """A scored grasp point. ``u``, ``v``: pixels; ``score``: J of Eq. 7; ``phi``: rad;
    ``depth``: I(g), metres; ``normal_cam``: (3,) unit normal, camera frame, towards the camera;
    ``j_distance``, ``j_inclination``: Eqs. 9 and 10 (both shown in the paper's Fig. 9);
    ``second_tier``: proposed by the fallback tier of ``Planner.plan``, not by Eq. 3."""

    u: float
    v: float
    grasp_class: GraspClass
    probability: float
    score: float
    phi: float
    depth: float
    normal_cam: np.ndarray
    j_distance: float
    j_inclination: float
    second_tier: bool = False  # the closed loop's fallback tier (``Planner.plan``), not Eq. 3's


def window_normals(
    P: np.ndarray, max_depth_jump: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The pixels of windows ``P`` (..., h + 2, w + 2, 3) float64 (camera frame, metres; each
    window with the one-pixel ring its central differences read) → their points (..., h, w, 3),
    the central-difference normals n = (right − left) × (down − up) (..., h, w, 3; Eq. 14: away
    from the camera), their lengths (..., h, w) and which pixels are used (..., h, w): the pixel
    and its four neighbours have depth, none differs from the pixel by more than
    ``max_depth_jump`` (m), and n is not zero."""
    centre = P[..., 1:-1, 1:-1, :]
    left, right = P[..., 1:-1, :-2, :], P[..., 1:-1, 2:, :]
    up, down = P[..., :-2, 1:-1, :], P[..., 2:, 1:-1, :]
    n = np.cross(right - left, down - up)
    z = [a[..., 2] for a in (centre, left, right, up, down)]
    valid = np.all([zi > 0 for zi in z], axis=0)
    for zi in z[1:]:
        valid &= np.abs(zi - z[0]) <= max_depth_jump
    length = np.linalg.norm(n, axis=-1)
    valid &= length > 0
    return centre, n, length, valid


def surface_normal(
    points_cam: np.ndarray, u: int, v: int, half_window: int, max_depth_jump: float
) -> np.ndarray | None:
    """Unit normal (3,) at pixel (u, v), pointing towards the camera, or None if no pixel of the
    window is usable.

    Args:
        points_cam: (H, W, 3) back-projected depth image, camera frame, metres (z = 0: no data).
        u, v: integer pixel.
    """
    H, W, _ = points_cam.shape
    # The window plus the one-pixel ring its central differences read.
    v0, v1 = max(v - half_window, 1), min(v + half_window, H - 2)
    u0, u1 = max(u - half_window, 1), min(u + half_window, W - 2)
    if v0 > v1 or u0 > u1:
        return None
    P = points_cam[v0 - 1 : v1 + 2, u0 - 1 : u1 + 2].astype(np.float64)  # (h+2, w+2, 3)
    centre, n, length, valid = window_normals(P, max_depth_jump)
    if not valid.any():
        return None
    mean = (n[valid] / length[valid, None]).mean(0)
    norm = np.linalg.norm(mean)
    if norm == 0:
        return None
    mean /= norm
    ray = points_cam[v, u] if points_cam[v, u, 2] > 0 else centre[valid][0]
    return -mean if mean @ ray > 0 else mean  # towards the camera


def surface_normals(
    points_cam: np.ndarray,
    us: Sequence[int],
    vs: Sequence[int],
    half_window: int,
    max_depth_jump: float,
) -> list[np.ndarray | None]:
    """``surface_normal`` at each pixel (us[i], vs[i]), the same values: the windows that lie
    inside the image's one-pixel border are computed together (the same float64 operations per
    pixel, the window's unit normals summed in the same row-major order), those that reach the
    border one by one."""
    H, W, _ = points_cam.shape
    h = half_window
    us, vs = np.asarray(us, np.intp).reshape(-1), np.asarray(vs, np.intp).reshape(-1)
    out: list[np.ndarray | None] = [None] * len(us)
    inside = (vs - h >= 1) & (vs + h <= H - 2) & (us - h >= 1) & (us + h <= W - 2)
    for i in np.flatnonzero(~inside):
        out[i] = surface_normal(points_cam, int(us[i]), int(vs[i]), h, max_depth_jump)
    idx = np.flatnonzero(inside)
    if len(idx) == 0:
        return out
    # (K, 2h + 3, 2h + 3, 3): each window plus the one-pixel ring its central differences read
    ring = np.arange(-h - 1, h + 2)
    rows, cols = vs[idx, None] + ring, us[idx, None] + ring
    P = points_cam[rows[:, :, None], cols[:, None, :]].astype(np.float64)
    centre, n, length, valid = window_normals(P, max_depth_jump)  # (K, w, w, ...)
    # −0.0 where a pixel is not used: x + (−0.0) = x for every x, signed zeros included, so the
    # sum is that of the used pixels alone, in the same order
    unit = np.full(n.shape, -0.0)
    np.divide(n, length[..., None], out=unit, where=valid[..., None])
    k, w = len(idx), 2 * h + 1
    total = unit.reshape(k, w * w, 3).sum(axis=1)
    count = valid.reshape(k, w * w).sum(axis=1)
    means = np.divide(total, count[:, None], out=np.zeros_like(total), where=count[:, None] > 0)
    first = valid.reshape(k, w * w).argmax(axis=1)  # the first used pixel, row-major
    centres = centre.reshape(k, w * w, 3)
    rays = points_cam[vs[idx], us[idx]]  # (K, 3) float32
    for j, i in enumerate(idx):
        if count[j] == 0:
            continue
        # np.linalg.norm of a vector is sqrt(mean · mean) (a BLAS dot): the same dot here
        sq = means[j].dot(means[j])
        if sq == 0:
            continue
        mean = means[j] / math.sqrt(sq)
        ray = rays[j] if rays[j, 2] > 0 else centres[j, first[j]]
        out[i] = -mean if mean @ ray > 0 else mean  # towards the camera
    return out


def inclination(normal_cam: np.ndarray) -> float:
    """φ of Eq. 8 (rad) for a normal pointing towards the camera: the angle between −n and +Z."""
    n = np.asarray(normal_cam, np.float64)
    # np.linalg.norm(n) of a vector is sqrt(n · n); both square roots are correctly rounded
    cos = -n[2] / math.sqrt(n.dot(n))
    return float(np.arccos(min(max(cos, -1.0), 1.0)))  # np.clip's value, without its overhead


def graspability(
    depth: float, phi: float, d_ground: float, phi_switch: float
) -> tuple[float, float, float]:
    """Eqs. 7, 9, 10 → (J, J_distance, J_inclination)."""
    j_distance = 1.0 - depth / d_ground
    j_inclination = 1.0 - 2.0 * phi / math.pi
    return (j_distance if phi < phi_switch else j_inclination), j_distance, j_inclination


def depth_at(depth_m: np.ndarray, u: int, v: int, half_window: int) -> float | None:
    """I(g) at pixel (u, v) of ``depth_m`` (H, W) (m, 0 = no data): its depth, else the median
    of the data in the window of ``half_window`` pixels around it; None where it has none."""
    depth = float(depth_m[v, u])
    if depth > 0:
        return depth
    h = half_window
    window = depth_m[max(v - h, 0) : v + h + 1, max(u - h, 0) : u + h + 1]
    if not (window > 0).any():
        return None
    return float(np.median(window[window > 0]))


def rank_grasps(
    predictions: Sequence[GraspPrediction],
    depth_m: np.ndarray,
    intrinsics: Intrinsics,
    cfg: RankingConfig,
    points_cam: np.ndarray | None = None,
) -> list[GraspCandidate]:
    """Score and sort one image's predictions; G_opt is the first candidate.

    Keeps predictions with ``probability > cfg.threshold`` (Eq. 3) whose class is not NG.

    Args:
        predictions: ``decode.decode_output`` output (any threshold).
        depth_m: (H, W) float32 z-depth, metres, 0 = no data.
        intrinsics: of ``depth_m``.
        points_cam: ``backproject(depth_m, intrinsics)`` when the caller has it already
            (``Planner.plan`` ranks two tiers on one image); None: computed here.

    Returns:
        candidates sorted by J descending (ties: higher probability first).
    """
    depth_m = np.asarray(depth_m, np.float32)
    if points_cam is None:
        points_cam = backproject(depth_m, intrinsics)  # (H, W, 3) camera frame
    H, W = depth_m.shape
    h = cfg.normal_half_window
    kept = []  # (prediction, u, v, depth I(g)) of those with a depth
    for pred in predictions:
        if pred.probability <= cfg.threshold or pred.grasp_class == GraspClass.NG:
            continue
        u = min(max(round(pred.u), 0), W - 1)  # the pixel nearest g
        v = min(max(round(pred.v), 0), H - 1)
        depth = depth_at(depth_m, u, v, h)
        if depth is not None:
            kept.append((pred, u, v, depth))
    normals = surface_normals(
        points_cam, [k[1] for k in kept], [k[2] for k in kept], h, cfg.max_depth_jump
    )
    out = []
    for (pred, _, _, depth), normal in zip(kept, normals):
        if normal is None:
            continue
        out.append(grasp_candidate(pred, depth, normal, inclination(normal), cfg))
    return order_candidates(out, cfg)


def grasp_candidate(
    pred: GraspPrediction, depth: float, normal: np.ndarray, phi: float, cfg: RankingConfig
) -> GraspCandidate:
    """The candidate of prediction ``pred`` at depth I(g) ``depth`` (m) with the unit
    ``normal`` (3,) (camera frame, towards the camera) of inclination ``phi`` (rad, Eq. 8),
    scored by Eqs. 7, 9 and 10."""
    score, j_distance, j_inclination = graspability(depth, phi, cfg.d_ground, cfg.phi_switch)
    return GraspCandidate(
        u=float(pred.u),
        v=float(pred.v),
        grasp_class=GraspClass(pred.grasp_class),
        probability=float(pred.probability),
        score=score,
        phi=phi,
        depth=depth,
        normal_cam=normal.astype(np.float32),
        j_distance=j_distance,
        j_inclination=j_inclination,
    )


def order_candidates(cands: Sequence[GraspCandidate], cfg: RankingConfig) -> list[GraspCandidate]:
    """The candidates in the order of ``cfg.policy`` (module docstring); G_opt first."""
    if cfg.policy not in POLICIES:
        raise ValueError(f"unknown ranking policy {cfg.policy!r}; choose one of {POLICIES}")
    ranked = sorted(cands, key=lambda c: (-c.score, -c.probability))
    if cfg.policy == "paper":
        return ranked
    out = []
    while ranked:
        best = ranked[0]
        if best.phi >= cfg.phi_switch:
            ties = [c for c in ranked if abs(c.phi - best.phi) < cfg.inclination_tie]
            best = max(ties, key=lambda c: (c.j_distance, c.probability))  # first of equals
        out.append(best)
        ranked = [c for c in ranked if c is not best]
    return out
