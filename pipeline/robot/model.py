"""The 7-DoF picking robot in pybullet: forward/inverse kinematics and collision checks.

Frames: world (z up, origin at the centre of the bin floor's top surface, metres); the camera
link's frame is the OpenCV optical frame (x right, y down, z forward), so ``T_world_cam`` from
:meth:`Robot.camera_pose` is directly comparable with ``pipeline.camera.geometry`` poses.
Joint vectors ``q`` are (7,) float64 radians in the order of :attr:`Robot.joint_names`
(xArm6 joints 1–6, then the hand tilt ``joint7``).
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
import pybullet as p

from pipeline.camera.geometry import camera_pose_above_bin, pose_matrix, quat_from_matrix
from pipeline.config.build import from_section


@dataclass
class RobotConfig:
    """Where the robot stands and how IK and collision checks are done. Metres, degrees.

    The arm stands on a 0.12 m pedestal beside the bin's −x wall, its zero pose reaching
    towards +x (Fig. 1a: arm beside the bin). Chosen by a sweep of base x ∈ {−0.35, −0.42,
    −0.50} and z ∈ {−0.02, 0.1, 0.2, 0.3}: on the ground the home pose is out of reach; at
    (−0.42, 0, 0.10) every straight-down grasp pose (B, L, R; standoff 0.15 m) over the bin
    floor is kinematically reachable, and 97 % of a set of raised and 35–50° tilted surfaces.

    The values are the ``robot`` section (``conf/robot/``), with the project's URDF
    (``urdf_builder.URDF_PATH``) given by the caller, built by
    :func:`robot_config`.
    """

    urdf_path: str  # the robot's URDF file (not a key of the ``robot`` section)
    base_position: tuple  # bottom centre of the arm's base, world frame
    base_yaw_deg: float  # 0: the arm's zero pose reaches towards +x
    pedestal_half_size_xy: float  # drawn under the base when load() gets a ground height
    home_camera_height: float  # = camera.height_above_bin_floor (paper Sec. 4.3)
    ik_max_iterations: int  # per pybullet call; 20 (pybullet's default) leaves cm errors
    ik_residual_threshold: float  # m, pybullet's early exit
    ik_joint_damping: float  # DLS damping; pybullet's default 0.1 converges slowly
    ik_hand_damping: float  # joint7: damped harder so the hand tilts only when it helps
    ik_refinements: int  # pybullet calls per seed, each from the last (clamped) answer
    ik_restarts: int  # extra seeds (perturbations of home) after the first seeds fail
    ik_restart_noise_rad: float  # std-dev of the seed perturbations
    position_tolerance: float  # m, FK check of an IK answer
    orientation_tolerance_deg: float
    collision_margin: float  # m, closer than this to an obstacle counts as a collision
    self_collision_margin: float  # m, for robot link pairs ≥ 3 joints apart


@dataclass
class IKResult:
    """Outcome of :meth:`Robot.solve_ik`.

    Attributes:
        ok: a collision-free, in-limits joint vector reaching the target within tolerance.
        q: (7,) the best joint vector found (also when not ok), radians.
        position_error_m: FK camera position error of ``q``, metres.
        orientation_error_deg: FK camera orientation error of ``q``, degrees.
        reason: None when ok, else the furthest check that failed over all seeds:
            "ik" (no seed converged), "joint_limits" (converged only outside the limits) or
            "collision" (converged in limits only in collision).
        collisions: what ``q`` touches when reason is "collision".
    """

    ok: bool
    q: np.ndarray
    position_error_m: float
    orientation_error_deg: float
    reason: str | None
    collisions: list = field(default_factory=list)


class Contact(NamedTuple):
    """A robot link closer than the margin to another body (the robot itself for self-contact)."""

    robot_link: str
    other_body: int


_REASON_RANK = {"ik": 0, "joint_limits": 1, "collision": 2}
# Above this many obstacles, ``Robot.in_collision`` asks the engine's broadphase which bodies
# are near each link instead of testing every body's box (same contacts, found faster).
_BROADPHASE_MIN_OBSTACLES = 32
# Links rigidly fixed to the camera frame: at an IK answer their pose is the target's.
_CAMERA_RIGID = ("camera", "cup_left", "cup_right")


def rotation_angle_deg(R_a: np.ndarray, R_b: np.ndarray) -> float:
    """Angle of the rotation between two (3, 3) rotation matrices, degrees."""
    R = R_a.T @ R_b
    # atan2 of the sine (skew part) and cosine (trace) stays accurate near 0 and π.
    s = 0.5 * math.sqrt(
        (R[2, 1] - R[1, 2]) ** 2 + (R[0, 2] - R[2, 0]) ** 2 + (R[1, 0] - R[0, 1]) ** 2
    )
    c = (np.trace(R) - 1.0) / 2.0
    return math.degrees(math.atan2(s, c))


def _overlap(box_a, box_b, margin: float) -> bool:
    """Whether two AABBs ((min x, y, z), (max x, y, z)) come closer than ``margin``."""
    (a0, a1), (b0, b1) = box_a, box_b
    return (
        a0[0] <= b1[0] + margin
        and b0[0] <= a1[0] + margin
        and a0[1] <= b1[1] + margin
        and b0[1] <= a1[1] + margin
        and a0[2] <= b1[2] + margin
        and b0[2] <= a1[2] + margin
    )


class Robot:
    """xArm6 + hand tilt + camera + two cups (``urdf/binpick_robot.urdf``) in one pybullet client.

    Usage::

        robot = Robot(robot_config(cfg)); robot.load(client)
        res = robot.solve_ik(T_world_cam, obstacle_ids=bin_and_box_ids)
        if res.ok: robot.set_joints(res.q)

    FK, IK and collision checks teleport the robot (``resetJointState``); do not call them on a
    robot that a running physics simulation is driving unless that is intended.
    """

    def __init__(self, cfg: RobotConfig):
        self.cfg = cfg
        self.client: int | None = None
        self.body_id: int | None = None
        self.pedestal_id: int | None = None
        self._home_q: np.ndarray | None = None
        self._restart_offsets: np.ndarray | None = None
        self._still_boxes: dict | None = None  # obstacles' boxes inside obstacles_still()
        self.joint_names: list[str] = []  # filled by load(): joint1 … joint6, joint7 (hand)
        self.joint_limits = np.zeros((0, 2))  # (7, 2) [lower, upper] radians, after load()

    # ----------------------------------------------------------------------------- loading
    def load(self, client: int, ground_z: float | None = None) -> int:
        """Add the robot (fixed base) to ``client`` and return its body id.

        ``pipeline.cell.bin.build_cell`` resets the simulation, which removes the robot:
        load it after building the cell, and again after every reset.

        Args:
            client: pybullet physics client id.
            ground_z: world z of the ground's top; when given, a static pedestal box is added
                from there up to the base (its id is ``pedestal_id``; it is not an obstacle).
        """
        cfg = self.cfg
        self.client = client
        base_q = p.getQuaternionFromEuler([0, 0, math.radians(cfg.base_yaw_deg)])
        self.body_id = p.loadURDF(
            cfg.urdf_path,
            basePosition=list(cfg.base_position),
            baseOrientation=base_q,
            useFixedBase=True,
            flags=p.URDF_USE_IMPLICIT_CYLINDER,
            physicsClientId=client,
        )
        if ground_z is not None and cfg.base_position[2] - ground_z > 1e-4:
            half = cfg.pedestal_half_size_xy
            hz = (cfg.base_position[2] - ground_z) / 2.0
            col = p.createCollisionShape(
                p.GEOM_BOX, halfExtents=[half, half, hz], physicsClientId=client
            )
            vis = p.createVisualShape(
                p.GEOM_BOX,
                halfExtents=[half, half, hz],
                rgbaColor=[0.5, 0.5, 0.5, 1],
                physicsClientId=client,
            )
            self.pedestal_id = p.createMultiBody(
                0.0,
                col,
                vis,
                basePosition=[cfg.base_position[0], cfg.base_position[1], ground_z + hz],
                physicsClientId=client,
            )
        self._read_structure()
        return self.body_id

    def _read_structure(self) -> None:
        self.link_index: dict[str, int] = {"link_base": -1}
        self.parent_link: dict[int, int] = {}
        movable, lower, upper = [], [], []
        for j in range(p.getNumJoints(self.body_id, physicsClientId=self.client)):
            info = p.getJointInfo(self.body_id, j, physicsClientId=self.client)
            self.link_index[info[12].decode()] = j
            self.parent_link[j] = info[16]
            if info[2] == p.JOINT_REVOLUTE:
                movable.append(j)
                lower.append(info[8])
                upper.append(info[9])
        self.joint_indices = movable  # pybullet joint index of each entry of q
        self.joint_names = [
            p.getJointInfo(self.body_id, j, physicsClientId=self.client)[1].decode()
            for j in movable
        ]
        self.joint_limits = np.array([lower, upper]).T  # (7, 2) radians
        self.camera_link = self.link_index["camera"]
        self.link_name = {v: k for k, v in self.link_index.items()}
        # Movable joints between a link and the base, for the self-collision pair rule.
        depth = {-1: 0}
        for j in sorted(self.parent_link):
            depth[j] = depth[self.parent_link[j]] + (1 if j in movable else 0)
        links = sorted(depth)
        self._links = links  # -1 (base) and every link index
        # Pairs ≥ 3 movable joints apart on this serial chain can actually meet; closer pairs
        # share a joint housing and always touch in the primitive geometry.
        self.self_collision_pairs = [
            (a, b)
            for i, a in enumerate(links)
            for b in links[i + 1 :]
            if abs(depth[a] - depth[b]) >= 3
        ]
        span = self.joint_limits[:, 1] - self.joint_limits[:, 0]
        # Joints whose range spans a full turn: an answer outside the limits is wrapped by 2π.
        self._wraps = span >= 2 * math.pi - 1e-9
        # joint7 (the hand tilt) is the last movable joint.
        self._ik_damping = [self.cfg.ik_joint_damping] * (len(movable) - 1) + [
            self.cfg.ik_hand_damping
        ]

    def _require_loaded(self) -> None:
        if self.body_id is None:
            raise RuntimeError("Robot.load(client) must be called before using the robot")

    # ----------------------------------------------------------------------------- kinematics
    def set_joints(self, q: Sequence[float]) -> None:
        """Teleport the joints to ``q`` (7,), radians (zero velocity)."""
        self._require_loaded()
        values = np.asarray(q, dtype=np.float64).reshape(-1).tolist()
        p.resetJointStatesMultiDof(
            self.body_id, self.joint_indices, [[v] for v in values], physicsClientId=self.client
        )

    def joints(self) -> np.ndarray:
        """The current joint vector (7,), radians."""
        self._require_loaded()
        return np.array(
            [
                s[0]
                for s in p.getJointStates(
                    self.body_id, self.joint_indices, physicsClientId=self.client
                )
            ]
        )

    def link_pose(self, name: str, q: Sequence[float] | None = None) -> np.ndarray:
        """``T_world_link`` (4, 4) of URDF link ``name`` by FK; sets the joints to ``q`` first."""
        self._require_loaded()
        if q is not None:
            self.set_joints(q)
        idx = self.link_index[name]
        if idx == -1:
            pos, orn = p.getBasePositionAndOrientation(self.body_id, physicsClientId=self.client)
        else:
            st = p.getLinkState(
                self.body_id, idx, computeForwardKinematics=True, physicsClientId=self.client
            )
            pos, orn = st[4], st[5]
        return pose_matrix(np.asarray(pos), np.asarray(orn))

    def camera_pose(self, q: Sequence[float] | None = None) -> np.ndarray:
        """``T_world_cam`` (4, 4), OpenCV optical frame, by FK; sets the joints to ``q`` first."""
        return self.link_pose("camera", q)

    def within_limits(self, q: Sequence[float], tol: float = 1e-6) -> bool:
        """Whether every joint of ``q`` (7,) lies within its limits (± ``tol`` rad)."""
        q = np.asarray(q)
        return bool(
            np.all(q >= self.joint_limits[:, 0] - tol)
            and np.all(q <= self.joint_limits[:, 1] + tol)
        )

    def _wrap_into_limits(self, q: np.ndarray) -> np.ndarray:
        """Full-turn joints moved by multiples of 2π into their limits (same pose)."""
        q = q.copy()
        lo, hi = self.joint_limits[:, 0], self.joint_limits[:, 1]
        for i in np.flatnonzero(self._wraps):
            while q[i] > hi[i]:
                q[i] -= 2 * math.pi
            while q[i] < lo[i]:
                q[i] += 2 * math.pi
        return q

    def _pose_error(self, T_target: np.ndarray, link: int) -> tuple[float, float]:
        T = self.link_pose(self.link_name[link])
        return (
            float(np.linalg.norm(T[:3, 3] - T_target[:3, 3])),
            rotation_angle_deg(T[:3, :3], T_target[:3, :3]),
        )

    def _ik_from(self, seed: np.ndarray, T_target: np.ndarray, link: int | None = None):
        """Damped-least-squares IK from ``seed`` on ``link`` (default: the camera), FK-checked.

        pybullet's null-space variant (lower/upper limits + rest poses) stalls about 1 mm short
        of the target, so the plain variant is used: it converges to < 1e-6 m in well under a
        millisecond and stays near the seed's branch, but ignores the joint limits. An answer
        that reaches the target outside the limits is clamped into them and solved again (up
        to ``ik_refinements`` calls), which often slides it to an in-limits solution.
        Returns (position error m, orientation error deg, q) of the best iterate: in limits
        and within tolerance first, then within tolerance, then the smallest error.
        """
        cfg = self.cfg
        link = self.camera_link if link is None else link
        pos = T_target[:3, 3].tolist()
        orn = quat_from_matrix(T_target[:3, :3]).tolist()
        lo, hi = self.joint_limits[:, 0], self.joint_limits[:, 1]
        q = np.asarray(seed, dtype=np.float64)
        best, best_key = (math.inf, math.inf, q), (2, math.inf)
        for _ in range(cfg.ik_refinements):
            self.set_joints(q)
            q = np.array(
                p.calculateInverseKinematics(
                    self.body_id,
                    link,
                    pos,
                    orn,
                    jointDamping=self._ik_damping,
                    maxNumIterations=cfg.ik_max_iterations,
                    residualThreshold=cfg.ik_residual_threshold,
                    physicsClientId=self.client,
                )
            )
            q = self._wrap_into_limits(q)
            self.set_joints(q)
            pos_err, rot_err = self._pose_error(T_target, link)
            reached = pos_err <= cfg.position_tolerance and rot_err <= cfg.orientation_tolerance_deg
            in_limits = self.within_limits(q)
            key = (0 if reached and in_limits else 1 if reached else 2, pos_err + 1e-3 * rot_err)
            if key < best_key:
                best, best_key = (pos_err, rot_err, q), key
            if key[0] == 0:
                break
            if reached:
                q = np.clip(q, lo, hi)
        return best

    def _seeds(self, seed_q: Sequence[float] | None):
        """``seed_q`` (if given), the home pose (unless ``seed_q`` is it), then ``ik_restarts``
        fixed perturbations of the home pose.

        A generator, so a target solved from the first seed costs nothing extra. The
        perturbations come from a fixed generator: the same target always gets the same seeds
        (reproducible labels).
        """
        home = self.home_q()
        seed = None if seed_q is None else np.asarray(seed_q, dtype=np.float64)
        if seed is not None:
            yield seed
        if seed is None or not np.array_equal(seed, home):  # a seed twice: the same answer
            yield home
        if self._restart_offsets is None:
            rng = np.random.default_rng(0)
            self._restart_offsets = rng.normal(
                0.0, self.cfg.ik_restart_noise_rad, (self.cfg.ik_restarts, len(home))
            )
        lo, hi = self.joint_limits[:, 0], self.joint_limits[:, 1]
        for offset in self._restart_offsets:
            yield np.clip(home + offset, lo, hi)

    def solve_ik(
        self,
        T_world_cam_target: np.ndarray,
        seed_q: Sequence[float] | None = None,
        obstacle_ids: Sequence[int] = (),
        ignore_body_ids: Sequence[int] = (),
    ) -> IKResult:
        """Joint angles that put the camera at ``T_world_cam_target`` (4, 4; OpenCV frame).

        Per seed (``seed_q``, then the home pose, then perturbations of it): pybullet IK on the
        camera link, FK check (``position_tolerance``, ``orientation_tolerance_deg``) → else
        "ik"; joint limits → else "joint_limits"; :meth:`in_collision` against
        ``obstacle_ids`` (minus ``ignore_body_ids``) and the robot itself → else "collision".
        The first seed that passes all three wins. The robot is left at the returned ``q``.
        """
        self._require_loaded()
        T_target = np.asarray(T_world_cam_target, dtype=np.float64)
        return self._solve(T_target, self._seeds(seed_q), obstacle_ids, ignore_body_ids)

    def _solve(self, T_target, seeds, obstacle_ids, ignore_body_ids) -> IKResult:
        cfg = self.cfg
        best: IKResult | None = None
        for seed in seeds:
            pos_err, rot_err, q = self._ik_from(seed, T_target)
            if pos_err > cfg.position_tolerance or rot_err > cfg.orientation_tolerance_deg:
                res = IKResult(False, q, pos_err, rot_err, "ik")
            elif not self.within_limits(q):
                res = IKResult(False, q, pos_err, rot_err, "joint_limits")
            else:
                hits = self.in_collision(q, obstacle_ids, ignore_body_ids)
                res = IKResult(not hits, q, pos_err, rot_err, "collision" if hits else None, hits)
            if res.ok:
                return res
            if (
                best is None
                or _REASON_RANK[res.reason] > _REASON_RANK[best.reason]
                or (
                    res.reason == best.reason == "ik"
                    and res.position_error_m < best.position_error_m
                )
            ):
                best = res
            if res.reason == "collision" and any(
                c.robot_link in _CAMERA_RIGID and c.other_body != self.body_id
                for c in res.collisions
            ):
                break  # the camera and cups sit at the target whatever q is: no seed helps
        self.set_joints(best.q)
        return best

    # ----------------------------------------------------------------------------- collisions
    def in_collision(
        self,
        q: Sequence[float] | None,
        obstacle_body_ids: Sequence[int],
        ignore_body_ids: Sequence[int] = (),
        margin: float | None = None,
        self_collision: bool = True,
    ) -> list[Contact]:
        """Robot links within the margin of an obstacle, or of each other, at ``q``.

        Args:
            q: (7,) joint vector (None: the current joints). The robot is left at ``q``.
            obstacle_body_ids: single-link bodies to keep clear of (ground, bin parts, boxes);
                their base AABB is the broad-phase filter.
            ignore_body_ids: bodies to skip, e.g. the target box the cups are meant to touch.
            margin: the obstacles' margin (None: ``collision_margin``), metres.
            self_collision: also check the robot against itself.

        Returns:
            One :class:`Contact` per (robot link, other body) pair closer than
            ``collision_margin`` (obstacles) or ``self_collision_margin`` (robot link pairs ≥ 3
            joints apart; ``other_body`` is then the robot's own id). Empty: collision-free.
            The fixed base link is not checked against obstacles (it stands where it stands).
        """
        self._require_loaded()
        if q is not None:
            self.set_joints(q)
        cid, rid = self.client, self.body_id
        margin = self.cfg.collision_margin if margin is None else float(margin)
        self_margin = self.cfg.self_collision_margin
        # Axis-aligned boxes first: getClosestPoints only for pairs whose boxes (grown by the
        # margin) overlap. This cuts the check from ~0.2 ms to a few hundredths. With many
        # obstacles (a heap model of hundreds of columns, pipeline.controller.heap_model) the
        # engine's own broadphase names the bodies near each link; its boxes are the bodies'
        # grown by the contact threshold, so it passes every pair the exact test passes.
        boxes = {j: p.getAABB(rid, j, physicsClientId=cid) for j in self._links}
        ignore = set(ignore_body_ids) | {rid}
        found: list[Contact] = []
        wanted = [b for b in dict.fromkeys(obstacle_body_ids) if b not in ignore]
        tested = [j for j in self._links if j != -1]  # the fixed base is not tested
        near_link, around = None, None
        if len(wanted) > _BROADPHASE_MIN_OBSTACLES:
            pool = set(wanted)
            near_link = {}
            for link in self._links:
                lo, hi = boxes[link]
                hits = (
                    p.getOverlappingObjects(
                        [v - margin for v in lo], [v + margin for v in hi], physicsClientId=cid
                    )
                    or ()
                )
                near_link[link] = {b for b, _ in hits if b in pool}
        elif wanted and tested:
            # The box around all tested links: an obstacle clear of it is clear of every link
            # (min ≤ each link's min, max ≥ each link's max, and x + margin grows with x), so
            # the test of each link is skipped for it.
            lows, highs = [boxes[j][0] for j in tested], [boxes[j][1] for j in tested]
            around = (tuple(map(min, *lows)), tuple(map(max, *highs)))
        for body in wanted:
            if near_link is None:
                if around is None:
                    break  # no link to test
                other = self._obstacle_box(body)
                if not _overlap(around, other, margin):
                    continue
            for link in tested:
                if near_link is not None:
                    if body not in near_link[link]:
                        continue
                elif not _overlap(boxes[link], other, margin):
                    continue
                if p.getClosestPoints(rid, body, margin, linkIndexA=link, physicsClientId=cid):
                    found.append(Contact(self.link_name[link], body))
        for a, b in self.self_collision_pairs if self_collision else ():
            if _overlap(boxes[a], boxes[b], self_margin) and p.getClosestPoints(
                rid, rid, self_margin, linkIndexA=a, linkIndexB=b, physicsClientId=cid
            ):
                found.append(Contact(self.link_name[a], rid))
        return found

    def _obstacle_box(self, body: int):
        """``p.getAABB(body)``; inside :meth:`obstacles_still`, read from the engine once."""
        still = self._still_boxes
        if still is None:
            return p.getAABB(body, physicsClientId=self.client)
        box = still.get(body)
        if box is None:
            box = still[body] = p.getAABB(body, physicsClientId=self.client)
        return box

    @contextlib.contextmanager
    def obstacles_still(self):
        """A block in which only this robot moves: :meth:`in_collision` reads each obstacle's
        box from the engine once instead of at every call (the same boxes, so the same
        contacts). For the many checks along one motion (``pipeline.robot.path``)."""
        if self._still_boxes is not None:  # nested: the outer block keeps the boxes
            yield
            return
        self._still_boxes = {}
        try:
            yield
        finally:
            self._still_boxes = None

    # ----------------------------------------------------------------------------- home
    def home_camera_pose(self) -> np.ndarray:
        """``T_world_cam`` at home: ``home_camera_height`` above the bin centre, looking down."""
        return camera_pose_above_bin(self.cfg.home_camera_height)

    def home_q(self) -> np.ndarray:
        """(7,) joints of the home pose, solved once and cached.

        The hand is kept straight (tilt 0) at home: the 6-DoF arm alone puts the flange where
        the straight hand's camera is at :meth:`home_camera_pose`, starting from a hand-picked
        elbow-up, flange-down pose; the answer is then FK-checked on the camera.
        """
        self._require_loaded()
        if self._home_q is None:
            nominal = np.array([0.0, -0.3, -1.0, 0.0, 1.3, 0.0, 0.0])
            T_cam = self.home_camera_pose()
            self.set_joints(nominal)
            T_flange_cam = np.linalg.inv(self.link_pose("link6")) @ self.camera_pose()
            T_flange = T_cam @ np.linalg.inv(T_flange_cam)
            _, _, q = self._ik_from(nominal, T_flange, link=self.link_index["link6"])
            q[-1] = 0.0  # joint7 does not move the flange; keep it exactly straight
            self.set_joints(q)
            pos_err, rot_err = self._pose_error(T_cam, self.camera_link)
            hits = self.in_collision(q, ())
            if (
                pos_err > self.cfg.position_tolerance
                or rot_err > self.cfg.orientation_tolerance_deg
                or not self.within_limits(q)
                or hits
            ):
                raise RuntimeError(
                    f"the home camera pose is not reachable from base {self.cfg.base_position}: "
                    f"errors {pos_err:.4f} m / {rot_err:.2f} deg, joints {np.round(q, 3)}, "
                    f"self-contacts {hits}; move RobotConfig.base_position"
                )
            self._home_q = q.copy()
        return self._home_q.copy()


def robot_config(cfg) -> RobotConfig:
    """The ``RobotConfig`` of a composed config (``cfg.robot``; the URDF is the project's).

    Raises ValueError when ``cfg.hand``'s cups differ from the URDF's: the robot model (what
    the checks and the simulated hand use) and the hand config must describe one hand.
    """
    from pipeline.robot import urdf_builder

    built = (urdf_builder.CUP_DIAMETER, urdf_builder.CUP_OFFSET)
    if not np.allclose(built, (cfg.hand.cup_diameter, cfg.hand.cup_offset)):
        raise ValueError(
            f"hand config (cup_diameter={cfg.hand.cup_diameter}, cup_offset="
            f"{cfg.hand.cup_offset}) differs from the robot URDF's cups {built}: change "
            "pipeline/robot/urdf_builder.py to match and run `python -m "
            "pipeline.robot.urdf_builder`, or keep conf/hand/two_cup.yaml as it is"
        )
    return from_section(
        RobotConfig,
        cfg.robot,
        urdf_path=str(urdf_builder.URDF_PATH),
        base_position=tuple(cfg.robot.base_position),
    )
