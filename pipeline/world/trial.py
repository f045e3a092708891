"""Pick-and-place trials in the simulated cell (paper Secs. 5, 6; Fig. 2's two loops).

One **attempt** (``PickRunner.attempt``):

1. **Plan at home** (red loop of Fig. 2): one depth image at the home pose → the planner →
   G_opt (pixel) and its pattern S_opt (L, R or B; the Dex-Net-style planner has one suction
   point, served by the ``evaluate.dexnet_pattern`` cup, or by the other one when the robot
   cannot reach the first without touching the bin or a box: the labelling stage's
   robot-level check). With ``evaluate.check_reachability`` (default) the DCNN's G_opt is the
   best-ranked candidate whose target pose passes that same check (IK, joint limits, no
   contact with the bin or other boxes); the paper takes the top candidate, and its labels
   carry the robot-level check only through training. The planning time is measured (the
   check's time is not included).
2. **Servo** (blue loop): every control period (``servo.control_rate_hz``) a new depth image →
   the surface feature descriptor seeded at the previous g′ (G_opt at first; the previous g′
   is carried into the new image by the camera's known motion, since the image moves tens of
   pixels between frames) → features →
   the 2.5D visual-servoing law (Eq. 23) → joint velocities through the damped pseudo-inverse
   of the camera Jacobian (Eq. 28), limited to ``motion.max_joint_speed`` → integrated for one
   period while the physics runs. Converged when the error is within the tolerances; a
   timeout after ``servo.timeout_s`` simulated seconds. For the Dex-Net-style planner the
   servo target is its own suction point (tracked in the world; the descriptor supplies the
   surface normal and axes), not the surface centre: Dex-Net does not refine its point.
3. **Approach** along the camera axis from d* until the lips touch and press
   (``motion.press_depth``); **suction**: the seal test and the hold test of the active cups
   (``pipeline.world.suction``); **lift** ``motion.lift_height`` with the box hanging on its
   constraint; **place**: a point-to-point move to the conveyor pose, release, and back home.

Outcomes of an attempt: ``success``, or the failure ``no_seal``, ``dropped`` (sealed but the
cups cannot hold the box, or it came off during the lift), ``collision`` (the arm or hand
touched the bin while servoing or approaching: a protective stop; touching other boxes pushes
them, under physics, unless ``evaluate.stop_on_box_contact``), ``joint_limits`` (the servo ran
into joint limits and could not continue), ``timeout``, ``lost_target`` (the descriptor found
no surface at the seed). ``wrong_target`` flags a success on another box than the one under
G_opt at home.

**Time.** Simulated seconds: the servo's control periods, the approach and lift at their
speeds, the suction on/off times, and point-to-point moves (trapezoidal joint profiles at
``motion.max_joint_speed`` / ``max_joint_accel``) to the conveyor and back home. The measured
planning time is kept apart, so that pieces per hour can be given with and without it.

A **trial** (``run_trial``, paper Sec. 6): ``evaluate.boxes_per_trial`` boxes dropped into the
bin; attempts until the bin is empty, the planner finds no grasp at home, one box has failed
``evaluate.max_failures_per_target`` times, or ``evaluate.max_attempts_per_trial`` attempts.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Optional

import numpy as np
import pybullet as p

from pipeline.camera.geometry import Intrinsics, backproject_pixels, world_to_camera
from pipeline.world.cell import Frame, PickCell
from pipeline.world.diagnosis import final_home_record, labels_at_no_grasp

OUTCOMES = ("success", "no_seal", "dropped", "collision", "joint_limits", "timeout",
            "lost_target")
TRIAL_ENDS = ("bin_empty", "no_grasp", "max_failures", "max_attempts")
RETRY_POLICIES = ("skip_failed", "repeat")


@dataclass
class Attempt:
    """One grasp attempt's record (JSON-ready fields)."""

    trial: int
    index: int
    planner: str
    pattern: str
    g_opt: list  # [u, v] at home
    target_body: int  # body under G_opt at home (−1: none)
    target_type: str
    outcome: str = ""
    grasped_body: int = -1
    wrong_target: bool = False
    servo_steps: int = 0
    servo_s: float = 0.0
    motion_s: float = 0.0  # approach, suction, lift, place and return, simulated
    planning_s: float = 0.0  # measured wall-clock: the planner and the run-time check
    final_error: list = field(default_factory=list)  # |p_e − p_e*| (3) and |uθ| (deg)
    seal_reason: str = ""
    collided: list = field(default_factory=list)  # "robot link:bin|box" pairs of a collision
    phase: str = ""  # where a collision happened: "servo" or "approach"
    pregrasp_standoff: float = 0.0  # m, the pre-grasp's distance along the normal (0: none)
    lost_reason: str = ""  # the descriptor's reason when the target was lost
    face_split: bool = False  # the servo's region was split at other planner points (face_split_m)
    second_tier: bool = False  # a DCNN candidate of the fallback tier (dcnn_fallback_ratio)
    # m: farthest the executed camera came from the servo path the run-time check predicted
    # (robot.path_check; None without a prediction)
    path_deviation_m: Optional[float] = None

    @property
    def sim_s(self) -> float:
        return self.servo_s + self.motion_s


@dataclass
class TrialResult:
    trial: int
    planner: str
    boxes: int
    picked: int
    end: str
    attempts: list[Attempt]
    trace: list[dict] = field(default_factory=list)  # per control step, for the logs
    # end "no_grasp": why. ``candidates``: the planner's candidates at home (after the area
    # check), ``checked``: how many the selection looked at, ``rejected``: (candidate, pattern)
    # pairs per reason (the robot check's NG reason, "descriptor" when it found no surface,
    # "repeat" for a retry of a failed plan); with evaluate.label_no_grasp, for a planner
    # other than the oracle, ``label_candidates`` and ``label_executable``
    # (``pipeline.world.diagnosis.labels_at_no_grasp``). Empty for other ends.
    no_grasp: dict = field(default_factory=dict)
    # end "no_grasp" of a trial with a kept trace: the home image the planner found nothing on,
    # for the logs (``pipeline.world.diagnosis.final_home_record``); else empty.
    final_home: dict = field(default_factory=dict)

    @property
    def sim_s(self) -> float:
        return float(sum(a.sim_s for a in self.attempts))

    @property
    def planning_s(self) -> float:
        return float(sum(a.planning_s for a in self.attempts))


def _project(T_world_cam: np.ndarray, point_world: np.ndarray, intr: Intrinsics,
             fallback) -> np.ndarray:
    """Pixel (u, v) of a world point in a camera; ``fallback`` when it is behind the camera."""
    T_cam_world = np.linalg.inv(T_world_cam)
    c = T_cam_world[:3, :3] @ point_world + T_cam_world[:3, 3]
    if c[2] <= 1e-6:
        return np.asarray(fallback, np.float64)
    return np.array([intr.fx * c[0] / c[2] + intr.cx, intr.fy * c[1] / c[2] + intr.cy])


def _link_origins(robot) -> np.ndarray:
    """(L, 3) world positions of the robot's link frames (base first), for the logs."""
    states = p.getLinkStates(robot.body_id, list(range(p.getNumJoints(
        robot.body_id, physicsClientId=robot.client))), physicsClientId=robot.client)
    base = p.getBasePositionAndOrientation(robot.body_id, physicsClientId=robot.client)[0]
    return np.array([base] + [s[4] for s in states], np.float64)


def paper_x_axis(feats) -> np.ndarray:
    """The hand's X by the paper's rule (camera frame): the surface axis whose warped view is
    nearer the image X, signed towards +X."""
    axes = [(feats.long_axis_cam, feats.warped_long), (feats.short_axis_cam, feats.warped_short)]
    axis, warped = axes[int(np.argmax([abs(w[0]) for _, w in axes]))]  # larger |cos|: nearer X
    return np.asarray(axis if warped[0] >= 0 else -axis, np.float64)


def pattern_fits(feats, pattern: str, hand_cfg) -> bool:
    """Whether ``pattern``'s active cups lie on the descriptor's surface ``feats``: the
    labelling stage's hand-level rule (``pipeline.labelling.hand.cup_fits``: each cup disc
    inside the surface rectangle, the area at least ``min_area_ratio`` × the active cups' area)
    without the labels' safety margin (a disc just inside the rectangle seals), with the hand's
    X by the paper's rule (``paper_x_axis``) and the cups on its Y, at ±``cup_offset`` for B and
    the one active cup on the centre for L and R. Turning the hand by 90°
    (``hand.rotations_deg``) leaves a single cup's fit unchanged, and B takes only 0 and 180°,
    so the paper's axis decides."""
    from types import SimpleNamespace

    from pipeline.labelling.hand import cup_fits

    x_is_long = abs(feats.warped_long[0]) >= abs(feats.warped_short[0])  # as paper_x_axis
    half_x, half_y = (feats.long_length / 2, feats.short_length / 2) if x_is_long else \
        (feats.short_length / 2, feats.long_length / 2)
    cups = 2 if pattern == "B" else 1
    cup_area = math.pi * (float(hand_cfg.cup_diameter) / 2) ** 2
    discs = SimpleNamespace(cup_diameter=float(hand_cfg.cup_diameter), margin=0.0)
    return cup_fits(half_x, half_y, float(hand_cfg.cup_offset) if cups == 2 else 0.0, discs) \
        and feats.area >= float(hand_cfg.min_area_ratio) * cups * cup_area


def move_time(dq: np.ndarray, max_speed: float, max_accel: float) -> float:
    """Duration (s) of a synchronised point-to-point move: the slowest joint's trapezoidal
    (or triangular, for short moves) profile at ``max_speed`` (rad/s) and ``max_accel``."""
    d = float(np.max(np.abs(dq))) if len(dq) else 0.0
    if d <= 0.0:
        return 0.0
    if d >= max_speed ** 2 / max_accel:
        return d / max_speed + max_speed / max_accel
    return 2.0 * math.sqrt(d / max_accel)


class PickRunner:
    """Runs attempts and trials in a ``PickCell`` with one planner.

    ``planner(depth_m, intrinsics, rng)`` returns ranked candidates (objects with ``u``, ``v``,
    ``grasp_class`` (a ``GraspClass`` or None), ``point_cam`` optional).
    """

    def __init__(self, cfg, cell: PickCell, planner, planner_name: str) -> None:
        from pipeline.world.suction import SuctionGripper
        from pipeline.dexnet.contact import suction_model_config
        from pipeline.servo.control import servo_config
        from pipeline.servo.descriptor import descriptor_config

        self.cfg, self.cell, self.planner, self.name = cfg, cell, planner, planner_name
        self.dt = 1.0 / float(cfg.servo.control_rate_hz)
        self.descriptor_cfg = descriptor_config(cfg)
        self.servo_cfg = servo_config(cfg)
        self.suction_cfg = suction_model_config(cfg, float(cfg.eval_boxes.density))
        self.gripper_factory = lambda: SuctionGripper(cell.client, cell.robot, self.suction_cfg,
                                                      float(cfg.hand.cup_offset))
        self._place_q: np.ndarray | None = None
        pref = cfg.evaluate.preferred_bin_clearance
        # the bin clearance of the run-time check's first pass (``_check``), None: no first pass
        self._comfort = None if pref is None or not bool(cfg.robot.path_check) \
            else max(float(pref), float(cfg.robot.path.bin_clearance))
        self.oracle = None  # the labels' planner of ``diagnosis.labels_at_no_grasp``, when needed
        # wall time of the parts of a control step (seconds, one entry per call)
        self.timings: dict[str, list[float]] = {
            "descriptor_s": [], "control_step_s": [], "render_s": [], "control_law_s": [],
            "jacobian_s": [], "physics_s": [], "collision_s": []}

    # ------------------------------------------------------------------ helpers
    def _patterns(self, cand) -> list[str]:
        """The patterns a candidate may be executed with, in order of preference: the DCNN's
        (or oracle's) S_opt, and with ``evaluate.single_cup_fallback`` a B followed by L, then
        R (one cup on the surface centre: a face that two cups nearly fit, one cup fits); for
        a single suction point (Dex-Net), ``evaluate.dexnet_pattern`` then the other cup."""
        cls = getattr(cand, "grasp_class", None)
        if cls is not None:
            if cls.name == "B" and bool(self.cfg.evaluate.single_cup_fallback):
                return ["B", "L", "R"]
            return [cls.name]
        preferred = str(self.cfg.evaluate.dexnet_pattern)
        if preferred == "B":
            return ["B"]
        return [preferred, {"L": "R", "R": "L"}[preferred]]

    def large_enough(self, frame: Frame, cands: list) -> list:
        """With ``evaluate.min_area_ratio`` > 0 (paper Sec. 8.4's safety constraint), the DCNN's
        candidates among the first ``max_candidates_checked`` whose surface (the descriptor's
        region grown at the point) covers at least that ratio times the active cups' area
        (one cup for L and R, two for B); the others are dropped."""
        ratio = float(self.cfg.evaluate.min_area_ratio)
        if ratio <= 0 or not cands or getattr(cands[0], "grasp_class", None) is None:
            return cands
        from pipeline.servo.descriptor import describe_surface

        cup = math.pi * (float(self.cfg.hand.cup_diameter) / 2) ** 2
        kept = []
        for cand in cands[: int(self.cfg.evaluate.max_candidates_checked)]:
            feats, _ = describe_surface(frame.depth_m, self.cell.intrinsics,
                                        np.array([cand.u, cand.v], np.float64),
                                        self.descriptor_cfg)
            cups = 2 if cand.grasp_class.name == "B" else 1
            if feats is not None and feats.area >= ratio * cups * cup:
                kept.append(cand)
        return kept

    def _point_cam(self, frame: Frame, cand) -> np.ndarray | None:
        """The candidate's point in the frame's camera (its own ``point_cam`` when it has one,
        else the depth at its pixel back-projected), metres; None when the pixel has no depth
        or lies outside the image."""
        point = getattr(cand, "point_cam", None)
        if point is not None:
            return np.asarray(point, np.float64)
        intr = self.cell.intrinsics
        u, v = int(round(cand.u)), int(round(cand.v))
        if not (0 <= v < intr.height and 0 <= u < intr.width):
            return None
        z = float(frame.depth_m[v, u])
        if z <= 0:
            return None
        return backproject_pixels(np.array([cand.u, cand.v]), z, intr)

    @staticmethod
    def _fixed_point(cand) -> np.ndarray | None:
        """The point (3,) in the home camera that the servo holds fixed: a single suction
        point's own (Dex-Net's ``point_cam``); None for a DCNN or oracle candidate, whose servo
        tracks the centre of the surface the descriptor finds in each frame."""
        if getattr(cand, "grasp_class", None) is None and getattr(cand, "point_cam", None) \
                is not None:
            return np.asarray(cand.point_cam, np.float64)
        return None

    def _target_of(self, frame: Frame, cand) -> tuple[int, np.ndarray | None]:
        """(the box under the candidate at home, −1 for none; its point in the world frame, or
        None when the pixel has no depth)."""
        intr = self.cell.intrinsics
        u, v = int(round(cand.u)), int(round(cand.v))
        if not (0 <= v < intr.height and 0 <= u < intr.width):
            return -1, None
        target = int(frame.body_ids[v, u])
        target = target if target in self.cell.boxes else -1
        point = self._point_cam(frame, cand)
        if point is None:
            return target, None
        T = frame.T_world_cam
        return target, T[:3, :3] @ point + T[:3, 3]

    def select(self, frame: Frame, cands: list, failed: list[dict],
               rejected: dict[str, int] | None = None):
        """The grasp to execute: ``(candidate, pattern, hand X axis in the world or None for the
        paper's rule, the check's predicted camera poses or None, the face-split sites in the
        world or None (``_home_surface``))`` of the best-ranked candidate, among the
        first ``evaluate.max_candidates_checked``, that is not a repeat of a failed attempt
        (``_repeats_failure``) and, with ``evaluate.check_reachability``, passes the robot-level
        check with that pattern; None when no candidate does (the trial ends with "no grasp").

        A candidate the check rejects is never executed (the check: ``_reachable``).
        ``rejected``: if given, counts the rejected (candidate, pattern) pairs per reason."""
        gate = bool(self.cfg.evaluate.check_reachability)
        rejected = {} if rejected is None else rejected

        def reject(reason: str) -> None:
            rejected[reason] = rejected.get(reason, 0) + 1

        for cand in cands[: int(self.cfg.evaluate.max_candidates_checked)]:
            target, point = self._target_of(frame, cand)
            for pattern in self._patterns(cand):
                if self._repeats_failure(target, pattern, point, failed):
                    reject("repeat")
                    continue
                if not gate:
                    return cand, pattern, None, None, self._home_surface(frame, cand, cands)[1]
                check, reason, sites = self._check(frame, cand, pattern, target, cands)
                if check is not None:
                    return cand, pattern, check.x_world, check.path, sites
                reject(reason)
        return None

    def failure_record(self, target: int, pattern: str, point: np.ndarray) -> dict:
        """What ``_repeats_failure`` remembers of a failed plan: the box ``target`` (-1: none),
        the ``pattern``, the target ``point`` (world, m), the box's pose (world position, xyzw
        quaternion) and the poses of the other boxes whose centre lies within
        ``evaluate.retry_neighbour_m`` of the point (``neighbours``: body → (position, quat))."""
        pose = self.cell.box_pose(target) if target >= 0 else (np.zeros(3), np.zeros(4))
        return {"body": target, "pattern": pattern, "point": np.asarray(point, float),
                "position": pose[0], "quat": pose[1],
                "neighbours": {b: self.cell.box_pose(b) for b in self._near(point, target)}}

    def _near(self, point: np.ndarray, target: int) -> list[int]:
        """The boxes other than ``target`` whose centre is within ``retry_neighbour_m`` of
        ``point`` (world, m)."""
        r = float(self.cfg.evaluate.retry_neighbour_m)
        return [b for b in self.cell.boxes
                if b != target and np.linalg.norm(self.cell.box_pose(b)[0] - point) < r]

    def _moved(self, body: int, pose: tuple[np.ndarray, np.ndarray]) -> bool:
        """Whether ``body`` is gone or has moved at least ``retry_moved_m`` or turned at least
        ``retry_moved_deg`` since it was at ``pose`` (world position, xyzw quaternion)."""
        ev = self.cfg.evaluate
        if body not in self.cell.boxes:
            return True
        pos, quat = self.cell.box_pose(body)
        moved = np.linalg.norm(pos - pose[0])
        turn = 2.0 * math.degrees(math.acos(min(1.0, abs(float(np.dot(quat, pose[1]))))))
        return moved >= float(ev.retry_moved_m) or turn >= float(ev.retry_moved_deg)

    def _repeats_failure(self, target: int, pattern: str, point: np.ndarray | None,
                         failed: list[dict]) -> bool:
        """With ``evaluate.retry_policy: skip_failed``: the same box, with the same pattern (any
        pattern when the failure's ``outcome`` is one of ``evaluate.retry_point_outcomes``: the
        surface at the point failed, not the pattern), within
        ``retry_same_point_m`` of a failed attempt's point (``failure_record``), while the heap
        around it has not changed: that box has moved less than ``retry_moved_m`` and turned
        less than ``retry_moved_deg`` since the failure, and so has every box whose centre was
        within ``retry_neighbour_m`` of the point then (none has been picked or fallen out), and
        no other box has come that near. The same plan in the same surroundings would fail
        again; once a neighbour is gone or has moved, the plan is a new one."""
        ev = self.cfg.evaluate
        if str(ev.retry_policy) == "repeat" or point is None:
            return False
        any_pattern = {str(o) for o in ev.retry_point_outcomes}
        for f in failed:
            same_plan = f["pattern"] == pattern or f.get("outcome") in any_pattern
            if f["body"] != target or not same_plan or \
                    np.linalg.norm(point - f["point"]) > float(ev.retry_same_point_m):
                continue
            if target < 0 or target not in self.cell.boxes:
                return True
            if self._moved(target, (f["position"], f["quat"])):
                continue
            around = f["neighbours"]
            if any(self._moved(b, pose) for b, pose in around.items()) or \
                    set(self._near(f["point"], target)) - set(around):
                continue
            return True
        return False

    def _reachable(self, frame: Frame, cand, pattern: str, target: int, cands=()):
        """The passing ``GraspCheck`` of ``_check``, or None when it rejects the candidate."""
        return self._check(frame, cand, pattern, target, cands)[0]

    def _home_surface(self, frame: Frame, cand, cands):
        """(the descriptor's surface at the candidate in the home frame or None, the face-split
        sites or None).

        The sites (k, 3), world frame (``evaluate.face_split_m``;
        ``pipeline.servo.descriptor.split_region``): the candidate's point first, then the point
        of every other candidate of ``cands`` (the planner's at home) that lies in the region
        the descriptor grows at the candidate and farther than ``face_split_m`` from its point:
        a region holding points of two faces holds two faces, and the surface returned is the
        candidate's part of it. None when there is no such point, the split is off, or the
        candidate is a single suction point (Dex-Net)."""
        from pipeline.servo.descriptor import describe_surface

        seed = np.array([cand.u, cand.v], np.float64)
        feats, _ = describe_surface(frame.depth_m, self.cell.intrinsics, seed,
                                    self.descriptor_cfg)
        split_m = float(self.cfg.evaluate.face_split_m)
        point = self._point_cam(frame, cand)
        if split_m <= 0 or self._fixed_point(cand) is not None or feats is None or point is None:
            return feats, None
        sites = [point]
        for other in cands:
            u, v = int(round(other.u)), int(round(other.v))
            if other is cand or not (0 <= v < feats.region.shape[0]
                                     and 0 <= u < feats.region.shape[1]) \
                    or not feats.region[v, u]:
                continue
            q = self._point_cam(frame, other)
            if q is not None and np.linalg.norm(q - point) > split_m:
                sites.append(q)
        if len(sites) < 2:
            return feats, None
        feats, _ = describe_surface(frame.depth_m, self.cell.intrinsics, seed,
                                    self.descriptor_cfg, sites_cam=np.asarray(sites))
        T = frame.T_world_cam
        return feats, np.asarray(sites) @ T[:3, :3].T + T[:3, 3]

    def _check(self, frame: Frame, cand, pattern: str, target: int, cands=()):
        """The robot-level check of the labelling stage for a grasp at the candidate
        (``pipeline.labelling.robot_check.check_grasp``: the grasp pose and, with
        ``robot.path_check``, the servo's predicted motion from home to it): the descriptor must
        find the surface at the point (a failure is a rejection); camera X along the surface
        axis nearer the image X, turned about the normal by the first of ``hand.rotations_deg``
        that works. With ``evaluate.preferred_bin_clearance`` (not the paper), the rotations are
        first tried with that much clearance from the bin on the servo's path, then, when none
        has it, with ``robot.path.bin_clearance``: a hand turn that keeps the idle cup away from
        a wall is preferred to the paper's turn that grazes it, and nothing the plain check
        accepts is rejected.

        The surface is the one the servo will track: split at the other candidates of ``cands``
        (``_home_surface``).

        Returns (the passing ``GraspCheck`` (the hand's X axis in the world, the predicted camera
        poses), None, the face-split sites or None), or (None, the reason, None) when the check
        rejects the candidate: the check's NG reason, "descriptor" when the descriptor finds
        no surface at the point, or, with ``evaluate.check_hand_fit``, "hand_fit" when the
        pattern's cups do not fit on that surface (``pattern_fits``; DCNN and oracle
        candidates)."""
        from pipeline.controller.grasp_check import check_grasp

        feats, sites = self._home_surface(frame, cand, cands)
        if feats is None:
            return None, "descriptor", None
        if bool(self.cfg.evaluate.check_hand_fit) and getattr(cand, "grasp_class", None) \
                is not None and not pattern_fits(feats, pattern, self.cfg.hand):
            return None, "hand_fit", None
        # where the servo will put the active cup: the planner's own point (Dex-Net), else the
        # centre of the surface the descriptor finds at the candidate (what the servo tracks)
        fixed = self._fixed_point(cand)
        centre = feats.center_cam if fixed is None else fixed
        for clearance in ([self._comfort] if self._comfort is not None else []) + [None]:
            check = check_grasp(self.cell.robot, self.cfg, self.cfg.hand, frame.T_world_cam,
                                centre,
                                feats.normal_cam, feats.long_axis_cam, feats.short_axis_cam,
                                paper_x_axis(feats), pattern, self.cell.intrinsics,
                                self.cell.obstacles, [target] if target >= 0 else [],
                                self.cell.cell_ids[1:], bin_clearance=clearance)
            if check.reason is None:
                return check, None, sites
        return None, str(check.reason), None

    def _first_goal(self, centre_cam: np.ndarray, feats, ref_cam, pattern: str,
                    T_world_cam: np.ndarray):
        """(servo config of ``motion.approach``'s first goal, its distance from the surface):
        ``pipeline.robot.approach.first_goal`` for the descriptor's surface at home, the hand's
        X along ``ref_cam`` (None: the paper's axis)."""
        from pipeline.robot.approach import first_goal

        if ref_cam is None:
            ref_cam = paper_x_axis(feats)
        return first_goal(self.servo_cfg, self.cfg, T_world_cam, centre_cam, feats.normal_cam,
                          ref_cam, pattern, self.cell.intrinsics)

    def _render(self) -> Frame:
        t0 = time.perf_counter()
        frame = self.cell.render()
        self.timings["render_s"].append(time.perf_counter() - t0)
        return frame

    def _move_twist(self, q: np.ndarray, twist_cam: np.ndarray) -> tuple[np.ndarray, bool]:
        """One control period of a camera twist (camera frame) → new joints; physics steps."""
        from pipeline.servo.jacobian import camera_jacobian, integrate, joint_velocities

        robot = self.cell.robot
        t0 = time.perf_counter()
        J = camera_jacobian(robot, q)
        qdot = joint_velocities(J, twist_cam, float(self.cfg.servo.joint_damping))
        q_next, clamped = integrate(robot, q, qdot, self.dt, float(self.cfg.motion.max_joint_speed))
        robot.set_joints(q_next)
        t1 = time.perf_counter()
        self.cell.step(self.dt)
        self.timings["jacobian_s"].append(t1 - t0)
        self.timings["physics_s"].append(time.perf_counter() - t1)
        return q_next, clamped

    def _stop_bodies(self) -> list[int]:
        """What stops the robot on contact: the bin (a protective stop); also the boxes when
        ``evaluate.stop_on_box_contact`` (otherwise the hand pushes them, under physics)."""
        if bool(self.cfg.evaluate.stop_on_box_contact):
            return self.cell.obstacles
        return list(self.cell.cell_ids[1:])

    def _collisions(self, target: int) -> list[str]:
        """What the robot touches now among ``_stop_bodies`` (``_describe``d; empty: nothing)."""
        ignore = [target] if target >= 0 else []
        t0 = time.perf_counter()
        contacts = self.cell.robot.in_collision(None, self._stop_bodies(), ignore_body_ids=ignore)
        self.timings["collision_s"].append(time.perf_counter() - t0)
        return self._describe(contacts)

    def _describe(self, contacts) -> list[str]:
        """Contacts as "robot link:bin|box|self" strings (sorted, unique), for the failure
        records ("self": the robot touches itself)."""
        bin_ids, rid = set(self.cell.cell_ids), self.cell.robot.body_id

        def what(body: int) -> str:
            return "self" if body == rid else "bin" if body in bin_ids else "box"

        return sorted({f"{c.robot_link}:{what(c.other_body)}" for c in contacts})

    def _place_joints(self) -> np.ndarray:
        """Joints of the conveyor pose (camera at ``motion.place_position`` looking down)."""
        if self._place_q is None:
            robot = self.cell.robot
            T = robot.home_camera_pose().copy()
            T[:3, 3] = np.asarray(self.cfg.motion.place_position, np.float64)
            q_home = robot.home_q()
            res = robot.solve_ik(T, seed_q=q_home, obstacle_ids=[])
            if not res.ok:
                raise RuntimeError(f"the conveyor pose {list(T[:3, 3])} is out of the robot's "
                                   f"reach ({res.reason}): change motion.place_position")
            self._place_q = res.q
            robot.set_joints(q_home)
        return self._place_q

    # ------------------------------------------------------------------ one attempt
    def plan_at_home(self, rng: np.random.Generator):
        robot = self.cell.robot
        robot.set_joints(robot.home_q())
        frame = self._render()
        t0 = time.perf_counter()
        extra = {"frame": frame} if getattr(self.planner, "wants_frame", False) else {}
        cands = self.planner(frame.depth_m, self.cell.intrinsics, rng, **extra)
        return frame, cands, time.perf_counter() - t0

    def attempt(self, frame: Frame, cand, planning_s: float, trial: int, index: int,
                trace: list | None, pattern: str | None = None,
                x_world: np.ndarray | None = None, predicted: list | None = None,
                sites_world: np.ndarray | None = None) -> Attempt:
        """One attempt at ``cand`` with ``pattern`` (default: its first in ``_patterns``);
        ``x_world``: where the hand's X should point (world frame; None: the paper's rule);
        ``predicted``: the run-time check's camera poses of this servo, from which the
        attempt's ``path_deviation_m`` is measured (None: not recorded); ``sites_world``:
        (k, 3) the face-split sites (``_home_surface``), or None for the whole region."""
        from pipeline.servo.control import servo_velocity
        from pipeline.servo.descriptor import describe_surface

        cfg, cell, robot = self.cfg, self.cell, self.cell.robot
        intr: Intrinsics = cell.intrinsics
        target, _ = self._target_of(frame, cand)
        pattern = pattern or self._patterns(cand)[0]
        att = Attempt(trial=trial, index=index, planner=self.name, pattern=pattern,
                      g_opt=[float(cand.u), float(cand.v)], target_body=target,
                      target_type=cell.boxes[target]["type"] if target >= 0 else "",
                      planning_s=planning_s, face_split=sites_world is not None,
                      second_tier=bool(getattr(cand, "second_tier", False)))
        # Dex-Net: the servo target is its own point, fixed in the world.
        fixed_point_world = None
        fixed = self._fixed_point(cand)
        if fixed is not None:
            T = frame.T_world_cam
            fixed_point_world = T[:3, :3] @ fixed + T[:3, 3]

        q = robot.joints()
        executed = [robot.camera_pose()[:3, 3]]
        seed = np.array([cand.u, cand.v], np.float64)
        normal_world = None  # the tracked surface's normal (world), from the previous frame
        g_world = None  # and its centre g′ (world)
        limit_hits = 0
        steps_max = int(math.ceil(float(cfg.servo.timeout_s) / self.dt))
        converged = False
        servo_cfg = self.servo_cfg  # the approach's first goal, then d* (step 0 sets it)
        for step in range(steps_max + 1):
            t0 = time.perf_counter()
            if step > 0:
                frame = self._render()
            td = time.perf_counter()
            # the tracked surface's normal, carried into this frame by the camera's motion
            expected = None if normal_world is None else frame.T_world_cam[:3, :3].T @ normal_world
            # and a point of it (the previous g′): the plane itself, not only its orientation
            on_plane = None if g_world is None else \
                world_to_camera(g_world[None], frame.T_world_cam)[0]
            feats, reason = describe_surface(frame.depth_m, intr, seed, self.descriptor_cfg,
                                             expected_normal_cam=expected,
                                             sites_cam=None if sites_world is None else
                                             world_to_camera(sites_world, frame.T_world_cam),
                                             expected_point_cam=on_plane)
            self.timings["descriptor_s"].append(time.perf_counter() - td)
            if feats is None:
                att.outcome, att.lost_reason = "lost_target", str(reason)
                break
            T_cam_world = np.linalg.inv(frame.T_world_cam)
            if fixed_point_world is not None:
                centre = T_cam_world[:3, :3] @ fixed_point_world + T_cam_world[:3, 3]
                if centre[2] <= 1e-3:
                    att.outcome = "lost_target"
                    break
                seed = np.array([intr.fx * centre[0] / centre[2] + intr.cx,
                                 intr.fy * centre[1] / centre[2] + intr.cy])
            else:
                centre = feats.center_cam
                seed = None  # g′ of this frame, carried to the next (below)
            g_world = frame.T_world_cam[:3, :3] @ np.asarray(feats.center_cam) + \
                frame.T_world_cam[:3, 3]
            normal_world = frame.T_world_cam[:3, :3] @ np.asarray(feats.normal_cam)
            tc = time.perf_counter()
            ref = None if x_world is None else T_cam_world[:3, :3] @ x_world
            if step == 0:
                servo_cfg, att.pregrasp_standoff = self._first_goal(
                    np.asarray(centre), feats, ref, pattern, frame.T_world_cam)
            cmd = servo_velocity(centre, feats.normal_cam, feats.warped_long, feats.warped_short,
                                 pattern, servo_cfg, self.dt, reference_x=ref)
            self.timings["control_law_s"].append(time.perf_counter() - tc)
            if trace is not None:
                trace.append({"attempt": index, "step": step, "t": att.servo_s,
                              "T_world_cam": frame.T_world_cam.copy(),
                              "links": _link_origins(robot),
                              "g_opt": np.array([cand.u, cand.v], np.float64) if step == 0
                              else None,
                              "depth": frame.depth_m if step == 0 else None,
                              "g": np.asarray(feats.center_px, np.float64).copy(),
                              "error": np.asarray(cmd.error).copy(),
                              "surface": feats})
            att.final_error = [float(x) for x in np.abs(cmd.error[:3])] + [
                float(np.degrees(np.linalg.norm(cmd.error[3:])))]
            if cmd.converged and servo_cfg is not self.servo_cfg:
                servo_cfg = self.servo_cfg  # at the first goal (lift, pre-grasp): on to d*
                cmd = servo_velocity(centre, feats.normal_cam, feats.warped_long,
                                     feats.warped_short, pattern, servo_cfg, self.dt,
                                     reference_x=ref)
            if cmd.converged:
                converged = True
                break
            if step == steps_max:
                break
            q, clamped = self._move_twist(q, np.asarray(cmd.velocity, np.float64))
            T_moved = robot.camera_pose()
            executed.append(T_moved[:3, 3])
            if fixed_point_world is None:
                # The next seed is this g′, moved into the next image by the camera's own motion
                # (forward kinematics): the paper seeds with the previous g′; at 30 Hz and up to
                # 0.5 m/s the image moves tens of pixels between frames.
                seed = _project(T_moved, g_world, intr, feats.center_px)
            att.servo_steps += 1
            att.servo_s += self.dt
            self.timings["control_step_s"].append(time.perf_counter() - t0)
            limit_hits = limit_hits + 1 if clamped else 0
            if limit_hits >= 10:
                att.outcome = "joint_limits"
                break
            contacts = self._collisions(target)
            if contacts:
                att.outcome, att.collided, att.phase = "collision", contacts, "servo"
                break
        if predicted is not None:
            from pipeline.robot.path import distance_to_path

            att.path_deviation_m = float(distance_to_path(
                np.array(executed), np.array([T[:3, 3] for T in predicted])).max())
        if att.outcome:
            return self._go_home(att)
        if not converged:
            att.outcome = "timeout"
            return self._go_home(att)
        return self._grasp_and_place(att, q, pattern, target)

    def _grasp_and_place(self, att: Attempt, q: np.ndarray, pattern: str, target: int) -> Attempt:
        cfg, cell, robot = self.cfg, self.cell, self.cell.robot
        m = cfg.motion
        # Approach along the camera axis: from d* to the lips touching, then the press.
        from pipeline.robot.urdf_builder import CUP_TIP_Z

        travel = float(cfg.hand.standoff) - CUP_TIP_Z + float(m.press_depth)
        steps = max(1, int(math.ceil(travel / (float(m.approach_speed) * self.dt))))
        v = travel / (steps * self.dt)
        for _ in range(steps):
            q, _ = self._move_twist(q, np.array([0.0, 0.0, v, 0.0, 0.0, 0.0]))
            att.motion_s += self.dt
        hit = [c for c in robot.in_collision(None, self._stop_bodies())
               if c.other_body != target and not c.robot_link.startswith("cup")]
        if hit:
            att.outcome, att.collided, att.phase = "collision", self._describe(hit), "approach"
            return self._go_home(att)
        gripper = self.gripper_factory()
        outcome = gripper.try_grasp(pattern, {b: d["mass"] for b, d in cell.boxes.items()})
        att.seal_reason = outcome.reason
        att.motion_s += float(m.suction_on_s)
        if not outcome.sealed:
            att.outcome = "no_seal"
            return self._go_home(att)
        if not outcome.held:
            att.outcome = "dropped"
            return self._go_home(att)
        body = int(outcome.body)
        att.grasped_body = body
        att.wrong_target = body != target
        # Lift straight up (world z) with the box hanging on the constraint.
        R_cam_world = robot.camera_pose()[:3, :3].T
        lift_v = R_cam_world @ np.array([0.0, 0.0, float(m.lift_speed)])
        steps = max(1, int(math.ceil(float(m.lift_height) / (float(m.lift_speed) * self.dt))))
        z0 = cell.box_pose(body)[0][2]
        for _ in range(steps):
            q, _ = self._move_twist(q, np.concatenate([lift_v, np.zeros(3)]))
            att.motion_s += self.dt
        lifted = cell.box_pose(body)[0][2] - z0
        if lifted < 0.5 * float(m.lift_height):
            gripper.release()
            att.outcome = "dropped"
            return self._go_home(att)
        # Carry to the conveyor, release, return home (point-to-point; the box leaves the cell).
        q_place = self._place_joints()
        speed, accel = float(m.max_joint_speed), float(m.max_joint_accel)
        att.motion_s += move_time(q_place - q, speed, accel) + float(m.suction_off_s)
        gripper.release()
        cell.remove_box(body)
        att.motion_s += move_time(robot.home_q() - q_place, speed, accel)
        robot.set_joints(robot.home_q())
        cell.settle()
        att.outcome = "success"
        return att

    def _go_home(self, att: Attempt) -> Attempt:
        robot = self.cell.robot
        q = robot.joints()
        att.motion_s += move_time(robot.home_q() - q, float(self.cfg.motion.max_joint_speed),
                                  float(self.cfg.motion.max_joint_accel))
        robot.set_joints(robot.home_q())
        self.cell.settle()
        return att

    # ------------------------------------------------------------------ one trial
    def run_trial(self, trial: int, rng_heap: np.random.Generator, rng_plan: np.random.Generator,
                  keep_trace: bool = False,
                  rng_sensor: np.random.Generator | None = None) -> TrialResult:
        """One trial. ``rng_sensor``: the sensor model's draws (``cfg.sensor``), a stream of its
        own so that the heaps and the plans' draws are the same with and without noise."""
        ev = self.cfg.evaluate
        self.cell.reset(rng_heap, int(ev.boxes_per_trial))
        self.cell.sensor_rng = rng_sensor
        boxes = len(self.cell.boxes)
        attempts: list[Attempt] = []
        failures: dict[int, int] = {}
        failed: list[dict] = []  # the failed attempts' plans (``_repeats_failure``)
        trace: list[dict] | None = [] if keep_trace else None
        end = "max_attempts"
        no_grasp: dict = {}
        final_home: dict = {}
        for index in range(int(ev.max_attempts_per_trial)):
            if not self.cell.boxes_in_bin():
                end = "bin_empty"
                break
            frame, cands, planning_s = self.plan_at_home(rng_plan)
            t0 = time.perf_counter()
            cands = self.large_enough(frame, cands)
            rejected: dict[str, int] = {}
            chosen = self.select(frame, cands, failed, rejected) if cands else None
            planning_s += time.perf_counter() - t0  # the run-time check is planning time too
            if chosen is None:
                end = "no_grasp"
                no_grasp = {"boxes_left": len(self.cell.boxes_in_bin()),
                            "candidates": len(cands),
                            "checked": min(len(cands), int(ev.max_candidates_checked)),
                            "rejected": dict(sorted(rejected.items()))}
                if self.name != "oracle" and bool(ev.label_no_grasp):
                    no_grasp.update(labels_at_no_grasp(self, frame, failed))
                if trace is not None:
                    final_home = final_home_record(self.cell, frame, cands)
                break
            cand, pattern, x_world, predicted, sites = chosen
            target, point = self._target_of(frame, cand)
            record = self.failure_record(target, pattern, point) if point is not None else None
            att = self.attempt(frame, cand, planning_s, trial, index, trace, pattern, x_world,
                               predicted, sites)
            attempts.append(att)
            if att.outcome != "success":
                if record is not None:
                    failed.append({**record, "outcome": att.outcome})
                failures[att.target_body] = failures.get(att.target_body, 0) + 1
                if failures[att.target_body] >= int(ev.max_failures_per_target):
                    end = "max_failures"
                    break
        else:
            if not self.cell.boxes_in_bin():
                end = "bin_empty"
        picked = sum(a.outcome == "success" for a in attempts)
        return TrialResult(trial=trial, planner=self.name, boxes=boxes, picked=picked, end=end,
                           attempts=attempts, trace=trace or [], no_grasp=no_grasp,
                           final_home=final_home)
