"""Suction that can fail like a real one, in pybullet: seal test, hold test, vacuum constraint.

The hand (``pipeline.robot.urdf_builder``) carries two cups, ``cup_left`` (camera y = −0.035 m)
and ``cup_right`` (camera y = +0.035 m), lips at camera z = 0.14 m, 0.018 m across. A grasp
pattern switches on one or both (:data:`PATTERN_CUPS`: "L", "R", "B"). The rules reuse
``pipeline.dexnet.contact``'s :class:`SuctionModelConfig` (cup radius r, vacuum force V per cup,
friction mu, compliance, ring points K) and its single-cup rules, so that the closed loop and
the Dex-Net-style labels agree; with one cup every rule below is contact.py's rule.

Frames and units: pybullet world frame (z up), metres, kilograms, newtons, seconds. A cup's
frame (``Robot.link_pose``) has its origin at the centre of the lip disc and its axes parallel
to the camera's OpenCV frame (x right, y down, z forward), so the cup's z axis is the approach
axis a, pointing from the cup into the object.

Seal test (:func:`seal_test`), at the robot's current joint state, nothing is moved:

* Per active cup, K + 1 rays along a: one from the lip's centre and K from points on the rim
  (radius r, angles 2 pi j / K from the cup's x axis, as contact.py's ring). Each runs from
  ``BACKOFF`` = 0.01 m behind the lip to ``reach`` ahead of it, so a surface the lip already
  touches or presses into (by up to 10 mm) is found too. A hit's height h is its distance
  along a from the lip plane (negative: the lip is pressed into the surface).
* Rays from behind the lip start inside the cup's own collision cylinder (the pad, radius r,
  25 mm long behind the lip). Bullet does not report a ray that starts inside a convex shape,
  except near its surface (within the collision margin): the rim rays start exactly on the
  pad's mantle, and 5 of 16 report the cup at fraction 0 (measured, pybullet 3.2.7; the centre
  ray never does). ``rayTestBatch`` takes no
  body to ignore and returns its ``reportHitNumber``-th hit in no particular order (a box hit
  at fraction 0.37 came before the cup's at 0.0), so each batch is cast with
  ``reportHitNumber`` = 0, 1, 2, … until no ray has another hit, and per ray the nearest hit on
  a body other than the robot and the ``ignore`` bodies is kept. The robot's collision
  filters are left alone.
* Reasons, checked in this order (the first that applies is the result's ``reason``):

  - ``no_contact``: some active cup's rays hit nothing within [−BACKOFF, reach] of its lip;
  - ``off_face``: some ray of an active cup missed while others hit, or the rays hit different
    bodies, or a hit normal is more than ``normal_tolerance_deg`` (10°) from the first cup's
    centre normal (an edge, a corner, a face smaller than the cup, two boxes, a lip partly
    over a gap);
  - ``uneven``: the rim heights of all active cups spread (max − min) more than
    ``compliance``. With one cup this is contact.py's rule; with two, the hand is rigid, so
    both lips must conform to the face at once (a face tilted by t about the axis across the
    cup line spreads the rims' heights by 2 (cup_offset + r) tan t: 3 mm at t = 1.95°, while
    one cup's rim spreads by 2 r tan t: 3 mm at t = 9.5°);
  - ``bin``: the cups seal on one face of a body that is not a box (bin floor, wall, ground);
  - ``ok``: sealed on a box.

Hold test: :func:`pipeline.grasping.suction.hold_test` (the cup model every user shares).

Gripper (:class:`SuctionGripper`): ``try_grasp`` runs the seal test, then the hold test with
the box's mass (given) and centre of mass (``getBasePositionAndOrientation``: pybullet's base
position is its inertial frame's origin, the COM), and on success welds the box to the hand
with a ``JOINT_FIXED`` constraint at their current relative pose (parent: the active cup's link
for L/R, the camera link for B), ``maxForce`` = k V: a load the vacuum could not hold tears the
box off. Collisions between the held box and the active cups are switched off while it is held
(the lip sits on or in the face; the solver must not fight the weld) and back on by
``release``.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
import pybullet as p

from pipeline.grasping.suction import HoldResult, SuctionModelConfig, hold_test

PATTERN_CUPS = {"L": ("cup_left",), "R": ("cup_right",), "B": ("cup_left", "cup_right")}
BACKOFF = 0.01  # rays start this far behind the lip, m
NORMAL_TOLERANCE_DEG = 10.0  # hit normals within this of each other count as one face
MAX_HITS_PER_RAY = 16  # reportHitNumber levels tried before giving up (never reached in practice)
_FRACTION_EPSILON = 1e-9  # rayTestBatch merges hits closer than this (fraction of the ray)


@dataclass
class SealResult:
    """Outcome of :func:`seal_test`.

    Attributes:
        sealed: every active cup seals on one face of one box (``reason == "ok"``).
        body: the pybullet body all active cups' rays hit (None if none, or different bodies).
        reason: "ok", "no_contact", "off_face", "uneven" or "bin" (module docstring).
        contact_points: (k, 3) world points under each active cup's centre (the centre ray's
            hit; NaN where it hit nothing), metres.
        axis: (3,) unit world approach axis (camera z).
        heights: (k, K) rim heights along the axis from each lip, metres (NaN: missed).
    """

    sealed: bool
    body: int | None
    reason: str
    contact_points: np.ndarray
    axis: np.ndarray
    heights: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))


@dataclass
class GraspOutcome:
    """Outcome of :meth:`SuctionGripper.try_grasp`.

    Attributes:
        sealed: the seal test passed.
        held: sealed, the hold test passed and the box is now attached.
        body: the body the cups sealed on (also when it is not held), else None.
        reason: "ok", a seal reason or a hold reason.
        seal: the seal test's result.
        hold: the hold test's result (None when there was no seal).
    """

    sealed: bool
    held: bool
    body: int | None
    reason: str
    seal: SealResult
    hold: HoldResult | None = None


def _cups(pattern: str) -> tuple[str, ...]:
    try:
        return PATTERN_CUPS[pattern]
    except KeyError:
        raise ValueError(
            f"unknown grasp pattern {pattern!r}; expected one of {sorted(PATTERN_CUPS)}"
        ) from None


def _cast_nearest(client: int, starts: np.ndarray, ends: np.ndarray, skip: set[int]):
    """Nearest hit of each ray on a body not in ``skip``.

    ``rayTestBatch`` has no ignore list and returns the ``reportHitNumber``-th hit in no fixed
    order, so every hit of every ray is collected (levels 0, 1, … until no ray has one more).

    Returns (body (n,) int, -1 = no hit; fraction (n,) in [0, 1], inf = no hit; point (n, 3);
    normal (n, 3)).
    """
    n = len(starts)
    body = np.full(n, -1, dtype=np.int64)
    frac = np.full(n, np.inf)
    point = np.full((n, 3), np.nan)
    normal = np.full((n, 3), np.nan)
    active = np.arange(n)
    for level in range(MAX_HITS_PER_RAY):
        if len(active) == 0:
            break
        res = p.rayTestBatch(
            starts[active].tolist(),
            ends[active].tolist(),
            reportHitNumber=level,
            fractionEpsilon=_FRACTION_EPSILON,
            physicsClientId=client,
        )
        still = []
        for i, r in zip(active, res):
            if r[0] == -1:
                continue
            still.append(i)
            if r[0] in skip or r[2] >= frac[i]:
                continue
            body[i], frac[i], point[i], normal[i] = r[0], r[2], r[3], r[4]
        active = np.asarray(still, dtype=np.int64)
    return body, frac, point, normal


def seal_test(
    client: int,
    robot,
    pattern: str,
    model_cfg: SuctionModelConfig,
    box_bodies: Iterable[int],
    reach: float = 0.02,
    ignore: Sequence[int] = (),
    normal_tolerance_deg: float = NORMAL_TOLERANCE_DEG,
) -> SealResult:
    """Whether the active cups of ``pattern`` seal where the robot's hand is now.

    Args:
        client: pybullet client id.
        robot: a loaded :class:`pipeline.robot.Robot` (its current joint state is used).
        pattern: "L", "R" or "B".
        model_cfg: cup radius, ring points and compliance.
        box_bodies: body ids that count as boxes (others give "bin").
        reach: how far ahead of the lip a surface still counts, m.
        ignore: bodies the rays pass through (besides the robot, always passed through).
        normal_tolerance_deg: hit normals within this angle count as one face.

    Returns:
        A :class:`SealResult` (rules in the module docstring).
    """
    cups = _cups(pattern)
    if model_cfg.ring_points < 3:
        raise ValueError(f"ring_points must be >= 3, not {model_cfg.ring_points}")
    K = model_cfg.ring_points
    angles = 2.0 * np.pi * np.arange(K) / K
    local = np.zeros((K + 1, 2))  # centre, then the rim, in the cup's (x, y)
    local[1:, 0] = model_cfg.cup_radius * np.cos(angles)
    local[1:, 1] = model_cfg.cup_radius * np.sin(angles)
    starts, ends, lips, axes = [], [], [], []
    for cup in cups:
        T = robot.link_pose(cup)
        lip, ex, ey, a = T[:3, 3], T[:3, 0], T[:3, 1], T[:3, 2]
        pts = lip + local[:, :1] * ex + local[:, 1:] * ey
        starts.append(pts - BACKOFF * a)
        ends.append(pts + reach * a)
        lips.append(lip)
        axes.append(a)
    axis = robot.camera_pose()[:3, 2].copy()
    k = len(cups)
    body, frac, point, normal = _cast_nearest(
        client, np.concatenate(starts), np.concatenate(ends), {robot.body_id, *ignore}
    )
    body = body.reshape(k, K + 1)
    hit = body >= 0
    heights = frac.reshape(k, K + 1) * (BACKOFF + reach) - BACKOFF  # inf where missed
    point = point.reshape(k, K + 1, 3)
    normal = normal.reshape(k, K + 1, 3)
    contact_points = point[:, 0, :].copy()
    rim_heights = np.where(hit[:, 1:], heights[:, 1:], np.nan)

    def result(reason: str, on: int | None) -> SealResult:
        return SealResult(reason == "ok", on, reason, contact_points, axis, rim_heights)

    if not np.all(hit.any(axis=1)):
        return result("no_contact", None)
    bodies = set(body[hit].tolist())
    on = bodies.pop() if len(bodies) == 1 else None
    if not hit.all() or on is None:
        return result("off_face", on)
    ref = normal[0, 0]
    cos = normal.reshape(-1, 3) @ ref / np.linalg.norm(normal.reshape(-1, 3), axis=1)
    if np.any(cos < math.cos(math.radians(normal_tolerance_deg))):
        return result("off_face", on)
    if np.ptp(heights[:, 1:]) > model_cfg.compliance:
        return result("uneven", on)
    if on not in set(box_bodies):
        return result("bin", on)
    return result("ok", on)


class SuctionGripper:
    """Attach / release a box with a fixed constraint whose maxForce stands for the vacuum.

    Usage::

        gripper = SuctionGripper(client, robot, suction_model_config(cfg, density),
                                 cup_offset=float(cfg.hand.cup_offset))
        out = gripper.try_grasp("B", {box_id: box_mass})
        if out.held: ...  # move the robot; the box follows
        gripper.release()
    """

    def __init__(
        self,
        client: int,
        robot,
        model_cfg: SuctionModelConfig,
        cup_offset: float,
        reach: float = 0.02,
        gravity_world: Sequence[float] | None = None,
    ):
        """``gravity_world``: gravity acceleration for the hold test, m/s²; None reads the
        engine's (``getPhysicsEngineParameters``) at each grasp."""
        self.client = client
        self.robot = robot
        self.model_cfg = model_cfg
        self.cup_offset = float(cup_offset)
        self.reach = float(reach)
        self.gravity_world = None if gravity_world is None else np.asarray(gravity_world, float)
        self._holding: int | None = None
        self._constraint: int | None = None
        self._cup_links: list[int] = []

    @property
    def holding(self) -> int | None:
        """The body id of the held box, or None."""
        return self._holding

    def _gravity(self) -> np.ndarray:
        if self.gravity_world is not None:
            return self.gravity_world
        prm = p.getPhysicsEngineParameters(physicsClientId=self.client)
        return np.array(
            [prm["gravityAccelerationX"], prm["gravityAccelerationY"], prm["gravityAccelerationZ"]]
        )

    def try_grasp(
        self, pattern: str, box_bodies: Mapping[int, float], ignore: Sequence[int] = ()
    ) -> GraspOutcome:
        """Seal test, hold test, and on success attach the box (see the module docstring).

        Args:
            pattern: "L", "R" or "B".
            box_bodies: body id → mass (kg) of every box (a seal on any other body is "bin").
            ignore: bodies the seal test's rays pass through.
        """
        if self._holding is not None:
            raise RuntimeError(f"already holding body {self._holding}; release() first")
        cid = self.client
        cups = _cups(pattern)
        seal = seal_test(
            cid,
            self.robot,
            pattern,
            self.model_cfg,
            box_bodies.keys(),
            reach=self.reach,
            ignore=ignore,
        )
        if not seal.sealed:
            return GraspOutcome(False, False, seal.body, seal.reason, seal)
        body = seal.body
        com, _ = p.getBasePositionAndOrientation(body, physicsClientId=cid)
        hold = hold_test(
            box_bodies[body],
            com,
            seal.contact_points,
            seal.axis,
            self._gravity(),
            self.model_cfg,
            self.cup_offset,
        )
        if not hold.ok:
            return GraspOutcome(True, False, body, hold.reason, seal, hold)

        rid = self.robot.body_id
        parent = self.robot.link_index[cups[0] if len(cups) == 1 else "camera"]
        # Constraint frames are relative to each link's inertial (COM) frame.
        st = p.getLinkState(rid, parent, computeForwardKinematics=True, physicsClientId=cid)
        box_pos, box_orn = p.getBasePositionAndOrientation(body, physicsClientId=cid)
        inv_pos, inv_orn = p.invertTransform(st[0], st[1])
        rel_pos, rel_orn = p.multiplyTransforms(inv_pos, inv_orn, box_pos, box_orn)
        cons = p.createConstraint(
            rid,
            parent,
            body,
            -1,
            p.JOINT_FIXED,
            [0, 0, 0],
            parentFramePosition=rel_pos,
            childFramePosition=[0, 0, 0],
            parentFrameOrientation=rel_orn,
            childFrameOrientation=[0, 0, 0, 1],
            physicsClientId=cid,
        )
        p.changeConstraint(
            cons, maxForce=len(cups) * self.model_cfg.vacuum_force, physicsClientId=cid
        )
        self._cup_links = [self.robot.link_index[c] for c in cups]
        for link in self._cup_links:
            p.setCollisionFilterPair(rid, body, link, -1, 0, physicsClientId=cid)
        self._constraint, self._holding = cons, body
        return GraspOutcome(True, True, body, "ok", seal, hold)

    def release(self) -> None:
        """Switch the vacuum off: remove the constraint (no-op when nothing is held)."""
        if self._holding is None:
            return
        cid, rid = self.client, self.robot.body_id
        p.removeConstraint(self._constraint, physicsClientId=cid)
        for link in self._cup_links:
            p.setCollisionFilterPair(rid, self._holding, link, -1, 1, physicsClientId=cid)
        self._holding, self._constraint, self._cup_links = None, None, []
