"""The robot-level check of a motion, not only of its end pose (paper Sec. 4.3, "collision
status with the surroundings"; docs/closed_loop.md).

A motion is the joint vectors of consecutive control periods (``pipeline.servo.predict``).
Between two of them the joints move linearly (what one period of the closed loop's Euler step
does); each step is cut into the fewest equal parts in which the camera moves at most
``step_m`` and turns at most ``step_deg``, and the robot must touch neither the bin nor another
box at every part: a sampled check of the swept motion.

Frames: world (z up); joints (7,) radians; metres, degrees.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from pipeline.camera.geometry import norm3
from pipeline.config.build import from_section


@dataclass(frozen=True)
class PathCheckConfig:
    """How finely a motion is sampled and how far it keeps from the bin: ``robot.path``, built
    by :func:`path_config`."""

    step_m: float  # largest camera translation between samples, metres
    step_deg: float  # largest camera rotation between samples, degrees
    # extra clearance from the padded bodies (the bin), on top of robot.collision_margin, for
    # a servo that strays from the predicted path (evaluate records how far, per attempt)
    bin_clearance: float


def path_config(cfg) -> PathCheckConfig | None:
    """The path check's settings, ``cfg.robot.path`` (None when ``robot.path_check`` is off)."""
    return from_section(PathCheckConfig, cfg.robot.path) if bool(cfg.robot.path_check) else None


@dataclass
class PathResult:
    """Outcome of :func:`check_motion`.

    Attributes:
        ok: every sample passed.
        reason: None when ok, else "collision".
        index: the control period whose step failed (the number of steps when ok).
        samples: how many joint vectors were checked.
        collisions: the contacts at the failing sample.
        padded: the contacts are with the padded bodies (the bin, at the clearance), not with
            the other obstacles or the robot itself: a smaller clearance may pass.
    """

    ok: bool
    reason: str | None
    index: int
    samples: int
    collisions: list = field(default_factory=list)
    padded: bool = False


def _angle_deg(R_a: np.ndarray, R_b: np.ndarray) -> float:
    c = (np.trace(R_a.T @ R_b) - 1.0) / 2.0
    return math.degrees(math.acos(min(1.0, max(-1.0, c))))


def substeps(T_a: np.ndarray, T_b: np.ndarray, step_m: float, step_deg: float) -> int:
    """The fewest equal parts of the step from camera pose ``T_a`` to ``T_b`` (4, 4) in which
    the camera moves at most ``step_m`` and turns at most ``step_deg`` (at least 1)."""
    dist = norm3((T_b[:3, 3] - T_a[:3, 3]).tolist())
    return max(
        1,
        int(math.ceil(max(dist / step_m, _angle_deg(T_a[:3, :3], T_b[:3, :3]) / step_deg) - 1e-9)),
    )


def check_motion(
    robot,
    q: np.ndarray,
    poses: Sequence[np.ndarray],
    cfg: PathCheckConfig,
    obstacle_ids: Sequence[int],
    ignore_body_ids: Sequence[int] = (),
    padded_ids: Sequence[int] = (),
) -> PathResult:
    """Check the motion through joints ``q`` (n, 7) whose camera poses are ``poses`` (n of
    (4, 4), world): each step from ``q[i]`` to ``q[i + 1]`` is cut into :func:`substeps`
    parts and the robot at every part's end must be clear of ``obstacle_ids`` (less
    ``ignore_body_ids``; those of ``padded_ids``, the bin, by ``robot.collision_margin`` +
    ``cfg.bin_clearance``) and of itself. The start ``q[0]`` is not checked (the robot is
    there already). The robot is left at the last joints checked."""
    q = np.asarray(q, np.float64)
    padded = list(dict.fromkeys(padded_ids))
    plain = [o for o in obstacle_ids if o not in padded]
    margin = robot.cfg.collision_margin + cfg.bin_clearance
    count = 0
    with robot.obstacles_still():  # only the robot moves here
        for i in range(len(q) - 1):
            n = substeps(poses[i], poses[i + 1], cfg.step_m, cfg.step_deg)
            for k in range(1, n + 1):
                qk = q[i] + (k / n) * (q[i + 1] - q[i])
                count += 1
                hits = robot.in_collision(qk, plain, ignore_body_ids)
                if hits:
                    return PathResult(False, "collision", i, count, list(hits))
                if padded:  # the robot is at qk already
                    hits = robot.in_collision(
                        None, padded, ignore_body_ids, margin=margin, self_collision=False
                    )
                    if hits:
                        return PathResult(False, "collision", i, count, list(hits), padded=True)
    return PathResult(True, None, len(q) - 1, count)


def distance_to_path(points: np.ndarray, path: np.ndarray) -> np.ndarray:
    """Distance (n,) of each of ``points`` (n, 3) from the polyline through ``path`` (m, 3),
    metres (a single point when m = 1)."""
    points, path = np.asarray(points, np.float64), np.asarray(path, np.float64)
    if len(path) == 1:
        return np.linalg.norm(points - path[0], axis=1)
    a, b = path[:-1], path[1:]  # (m-1, 3) segments
    ab = b - a
    t = np.einsum("nmk,mk->nm", points[:, None, :] - a[None], ab) / np.maximum(
        np.einsum("mk,mk->m", ab, ab), 1e-18
    )
    closest = a[None] + np.clip(t, 0.0, 1.0)[..., None] * ab[None]
    return np.linalg.norm(points[:, None, :] - closest, axis=2).min(axis=1)
