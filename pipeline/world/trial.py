"""Pick-and-place trials in the simulated cell (paper Secs. 5, 6; Fig. 2's two loops): the world
runs them, the robot side decides.

Each side's part of one **attempt** (``TrialRunner.attempt``):

1. **Plan at home** (red loop of Fig. 2): the world puts the robot at home and hands the robot
   side one observation (``PickCell.observe``); the robot plans, chooses and checks
   (``pipeline.controller.picker.RobotController.plan``). The world records, for the books
   only, which box lies under the chosen pixel (``Attempt.target_body``).
2. **Servo** (blue loop): each control period the world hands over a new observation, the
   robot's servo (``pipeline.controller.motion.Servo``) answers with a joint command, and the
   world sets the joints and runs the physics for the period. Touching the bin stops the robot
   (``collision``, a protective stop); touching boxes pushes them, under physics, unless
   ``evaluate.stop_on_box_contact``. Ten clamped steps in a row are ``joint_limits``; no
   convergence within ``servo.timeout_s`` is a ``timeout``; the descriptor losing the
   surface is ``lost_target``.
3. **Approach** along the camera axis until the lips press (joint commands from the robot,
   executed by the world, which judges contact with the bin or other boxes); **suction**: the
   world's gripper tests the seal and the hold of the active cups (``pipeline.world.suction``;
   ``no_seal``, ``dropped``); **lift** by ``motion.lift_height`` (the box must come up:
   else ``dropped``); **place**: a point-to-point move to the conveyor, release, and back
   home. ``wrong_target`` flags a success on another box than the one under G_opt at home.

**Time.** Simulated seconds: the servo's control periods, the approach and lift at their
speeds, the suction on/off times, and point-to-point moves (trapezoidal joint profiles at
``motion.max_joint_speed`` / ``max_joint_accel``) to the conveyor and back home. The measured
planning time is kept apart, so that pieces per hour can be given with and without it.

A **trial** (``run_trial``, paper Sec. 6): ``evaluate.boxes_per_trial`` boxes dropped into the
bin; attempts until the bin is empty, the robot finds no grasp at home, one box has failed
``evaluate.max_failures_per_target`` times (the protocol's rule, counted by the world), or
``evaluate.max_attempts_per_trial`` attempts. After a failure the robot remembers the failed
plan and the outcome it observed (its retry memory, ``pipeline.controller.retry``).
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field
from types import SimpleNamespace

import numpy as np
import pybullet as p

from pipeline.world.cell import PickCell
from pipeline.world.diagnosis import final_home_record, labels_at_no_grasp

OUTCOMES = ("success", "no_seal", "dropped", "collision", "joint_limits", "timeout", "lost_target")
TRIAL_ENDS = ("bin_empty", "no_grasp", "max_failures", "max_attempts")
# The closed loop's seed streams, per split (``evaluate.split``): the (heap, plan, sensor) keys
# of the generators (seed, key, trial). dev keeps the keys every earlier evaluation used (the
# heaps development looked at); test's are new, and nothing is chosen on them.
HEAP_STREAMS = {"dev": (31, 37, 41), "test": (131, 137, 141)}


@dataclass
class Attempt:
    """One grasp attempt's record (JSON-ready fields)."""

    trial: int
    index: int
    planner: str
    pattern: str  # the cups executed: "L", "R" or "B"
    g_opt: list  # [u, v] at home
    target_body: int  # body under G_opt at home (−1: none); the world's books only
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
    pregrasp_standoff: float = 0.0  # m, the first goal's distance along the normal
    lost_reason: str = ""  # the descriptor's reason when the target was lost
    face_split: bool = False  # the servo's region was split at other planner points (face_split_m)
    second_tier: bool = False  # a DCNN candidate of the fallback tier (dcnn_fallback_ratio)
    # the planner's pattern ("L", "R", "B"; "" for a single suction point): it differs from
    # ``pattern`` when the execution fell back from a B to one cup (evaluate.single_cup_fallback)
    # or chose the cup for a single point (evaluate.dexnet_pattern)
    planned_pattern: str = ""
    # m: farthest the executed camera came from the servo path the run-time check predicted
    # (robot.path_check; None without a prediction)
    path_deviation_m: float | None = None

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
    # pairs per reason (the run-time check's NG reason, "descriptor" when it found no surface,
    # "hand_fit", "repeat" for a retry of a failed plan); with evaluate.label_no_grasp, for a
    # planner other than the oracle, ``label_candidates`` and ``label_executable``
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

    @property
    def has_log_data(self) -> bool:
        """The trial kept what the logs draw (``trace``, ``final_home``): a logged trial."""
        return bool(self.trace or self.final_home)

    def to_record(self) -> dict:
        """The result as JSON-ready data, every field but the log data (``trace``,
        ``final_home``), ``planning_s`` of each attempt included; ``from_record`` reads it
        back. Raises ``ValueError`` for a trial with log data, which the record would lose."""
        if self.has_log_data:
            raise ValueError(f"trial {self.trial} of {self.planner} holds log data")
        return {
            "trial": self.trial,
            "planner": self.planner,
            "boxes": self.boxes,
            "picked": self.picked,
            "end": self.end,
            "attempts": [dataclasses.asdict(a) for a in self.attempts],
            "no_grasp": self.no_grasp,
        }

    @classmethod
    def from_record(cls, record: dict) -> TrialResult:
        """The result ``to_record`` wrote (raises ``KeyError`` or ``TypeError`` on another)."""
        fields = ("trial", "planner", "boxes", "picked", "end", "no_grasp")
        return cls(
            **{k: record[k] for k in fields}, attempts=[Attempt(**a) for a in record["attempts"]]
        )


def _surface_for_log(feats) -> SimpleNamespace:
    """What the logs draw of the descriptor's surface (centre, axes, normal, lengths; camera
    frame, metres), without its (H, W) region mask: a trial keeps one per control step."""
    return SimpleNamespace(
        **{
            k: np.asarray(getattr(feats, k)).copy()
            for k in ("center_cam", "normal_cam", "long_axis_cam", "short_axis_cam")
        },
        long_length=float(feats.long_length),
        short_length=float(feats.short_length),
    )


def _link_origins(robot) -> np.ndarray:
    """(L, 3) world positions of the robot's link frames (base first), for the logs."""
    states = p.getLinkStates(
        robot.body_id,
        list(range(p.getNumJoints(robot.body_id, physicsClientId=robot.client))),
        physicsClientId=robot.client,
    )
    base = p.getBasePositionAndOrientation(robot.body_id, physicsClientId=robot.client)[0]
    return np.array([base] + [s[4] for s in states], np.float64)


class TrialRunner:
    """Runs attempts and trials: the world (a ``PickCell``) and the robot side (a
    ``pipeline.controller.picker.RobotController`` with one planner)."""

    def __init__(self, cfg, cell: PickCell, controller, planner_name: str) -> None:
        from pipeline.grasping.suction import suction_model_config
        from pipeline.world.suction import SuctionGripper

        self.cfg, self.cell, self.robot_side, self.name = cfg, cell, controller, planner_name
        self.dt = 1.0 / float(cfg.servo.control_rate_hz)
        self.suction_cfg = suction_model_config(cfg, float(cfg.eval_boxes.density))
        self.gripper_factory = lambda: SuctionGripper(
            cell.client, cell.robot, self.suction_cfg, float(cfg.hand.cup_offset)
        )
        self.oracle = None  # the labels' planner of ``diagnosis.labels_at_no_grasp``, when needed
        # wall time of the parts of a control step (seconds, one entry per call)
        self.timings: dict[str, list[float]] = {
            "control_step_s": [],
            "render_s": [],
            "physics_s": [],
            "collision_s": [],
        }

    # ------------------------------------------------------------------ the world's steps
    def observe(self):
        t0 = time.perf_counter()
        obs = self.cell.observe()
        self.timings["render_s"].append(time.perf_counter() - t0)
        return obs

    def execute(self, q: np.ndarray) -> None:
        """The robot's joint command for one control period: joints set, physics run."""
        self.cell.robot.set_joints(q)
        t0 = time.perf_counter()
        self.cell.step(self.dt)
        self.timings["physics_s"].append(time.perf_counter() - t0)

    def target_of(self, u: float, v: float) -> int:
        """The box under pixel (u, v) of the latest observation (−1: none): the books."""
        ids = self.cell.last_frame.body_ids
        r, c = int(round(v)), int(round(u))
        if not (0 <= r < ids.shape[0] and 0 <= c < ids.shape[1]):
            return -1
        body = int(ids[r, c])
        return body if body in self.cell.boxes else -1

    def _stop_bodies(self) -> list[int]:
        """What stops the robot on contact: the bin (a protective stop); also the boxes when
        ``evaluate.stop_on_box_contact`` (otherwise the hand pushes them, under physics)."""
        if bool(self.cfg.evaluate.stop_on_box_contact):
            return self.cell.obstacles
        return list(self.cell.cell_ids[1:])

    def collisions(self, target: int) -> list[str]:
        """What the robot touches now among ``_stop_bodies`` (``describe``d; empty: nothing)."""
        ignore = [target] if target >= 0 else []
        t0 = time.perf_counter()
        contacts = self.cell.robot.in_collision(None, self._stop_bodies(), ignore_body_ids=ignore)
        self.timings["collision_s"].append(time.perf_counter() - t0)
        return self.describe(contacts)

    def describe(self, contacts) -> list[str]:
        """Contacts as "robot link:bin|box|self" strings (sorted, unique)."""
        bin_ids, rid = set(self.cell.cell_ids), self.cell.robot.body_id

        def what(body: int) -> str:
            return "self" if body == rid else "bin" if body in bin_ids else "box"

        return sorted({f"{c.robot_link}:{what(c.other_body)}" for c in contacts})

    def go_home(self, att: Attempt) -> Attempt:
        robot = self.cell.robot
        att.motion_s += self.robot_side.mover.move_time(robot.joints(), robot.home_q())
        robot.set_joints(robot.home_q())
        self.cell.settle()
        return att

    # ------------------------------------------------------------------ one attempt
    def attempt(self, plan, home_obs, trial: int, index: int, trace: list | None) -> Attempt:
        """Execute ``plan`` (planned on the raw home observation ``home_obs``)."""
        from pipeline.robot.path import distance_to_path

        cell, robot = self.cell, self.cell.robot
        g = plan.grasp
        target = self.target_of(g.u, g.v)
        att = Attempt(
            trial=trial,
            index=index,
            planner=self.name,
            pattern=plan.pattern,
            g_opt=[float(g.u), float(g.v)],
            target_body=target,
            target_type=cell.boxes[target]["type"] if target >= 0 else "",
            planning_s=plan.planning_s,
            face_split=plan.sites_world is not None,
            second_tier=bool(g.second_tier),
            planned_pattern=g.pattern or "",
        )
        servo = self.robot_side.servo(plan)
        executed = [robot.camera_pose()[:3, 3]]
        steps_max = int(np.ceil(float(self.cfg.servo.timeout_s) / self.dt))
        limit_hits, converged, obs = 0, False, home_obs
        for step in range(steps_max + 1):
            t0 = time.perf_counter()
            if step > 0:
                obs = self.observe()
            s = servo.step(obs)
            if s.status == "lost":
                att.outcome, att.lost_reason = "lost_target", s.reason
                break
            if step == 0:
                att.pregrasp_standoff = servo.pregrasp_standoff
            if trace is not None:
                trace.append(
                    {
                        "attempt": index,
                        "step": step,
                        "t": att.servo_s,
                        "T_world_cam": obs.T_world_cam.copy(),
                        "links": _link_origins(robot),
                        "g_opt": np.array([g.u, g.v], np.float64) if step == 0 else None,
                        "depth": obs.depth_m if step == 0 else None,
                        "g": s.g_px,
                        "error": np.asarray(s.cmd.error).copy(),
                        "surface": _surface_for_log(s.feats),
                    }
                )
            att.final_error = [float(x) for x in np.abs(s.cmd.error[:3])] + [
                float(np.degrees(np.linalg.norm(s.cmd.error[3:])))
            ]
            if s.status == "converged":
                converged = True
                break
            if step == steps_max:
                break
            self.execute(s.q)
            executed.append(robot.camera_pose()[:3, 3])
            att.servo_steps += 1
            att.servo_s += self.dt
            self.timings["control_step_s"].append(time.perf_counter() - t0)
            limit_hits = limit_hits + 1 if s.clamped else 0
            if limit_hits >= 10:
                att.outcome = "joint_limits"
                break
            contacts = self.collisions(target)
            if contacts:
                att.outcome, att.collided, att.phase = "collision", contacts, "servo"
                break
        if plan.predicted is not None:
            att.path_deviation_m = float(
                distance_to_path(
                    np.array(executed), np.array([T[:3, 3] for T in plan.predicted])
                ).max()
            )
        if att.outcome:
            return self.go_home(att)
        if not converged:
            att.outcome = "timeout"
            return self.go_home(att)
        return self.grasp_and_place(att, target)

    def grasp_and_place(self, att: Attempt, target: int) -> Attempt:
        cfg, cell, robot = self.cfg, self.cell, self.cell.robot
        m, mover = cfg.motion, self.robot_side.mover
        for q in mover.approach(robot.joints()):
            self.execute(q)
            att.motion_s += self.dt
        hit = [
            c
            for c in robot.in_collision(None, self._stop_bodies())
            if c.other_body != target and not c.robot_link.startswith("cup")
        ]
        if hit:
            att.outcome, att.collided, att.phase = "collision", self.describe(hit), "approach"
            return self.go_home(att)
        gripper = self.gripper_factory()
        outcome = gripper.try_grasp(att.pattern, {b: d["mass"] for b, d in cell.boxes.items()})
        att.seal_reason = outcome.reason
        att.motion_s += float(m.suction_on_s)
        if not outcome.sealed:
            att.outcome = "no_seal"
            return self.go_home(att)
        if not outcome.held:
            att.outcome = "dropped"
            return self.go_home(att)
        body = int(outcome.body)
        att.grasped_body = body
        att.wrong_target = body != target
        z0 = cell.box_pose(body)[0][2]
        for q in mover.lift(robot.joints()):
            self.execute(q)
            att.motion_s += self.dt
        if cell.box_pose(body)[0][2] - z0 < 0.5 * float(m.lift_height):
            gripper.release()
            att.outcome = "dropped"
            return self.go_home(att)
        # Carry to the conveyor, release, return home (point-to-point; the box leaves the cell).
        q_place, q = mover.place_joints(), robot.joints()
        att.motion_s += mover.move_time(q, q_place) + float(m.suction_off_s)
        gripper.release()
        cell.remove_box(body)
        att.motion_s += mover.move_time(q_place, robot.home_q())
        robot.set_joints(robot.home_q())
        cell.settle()
        att.outcome = "success"
        return att

    # ------------------------------------------------------------------ one trial
    def run_trial(
        self,
        trial: int,
        rng_heap: np.random.Generator,
        rng_plan: np.random.Generator,
        keep_trace: bool = False,
        rng_sensor: np.random.Generator | None = None,
    ) -> TrialResult:
        """One trial. ``rng_sensor``: the sensor model's draws (``cfg.sensor``), a stream of its
        own so that the heaps and the plans' draws are the same with and without noise."""
        ev, ctrl = self.cfg.evaluate, self.robot_side
        self.cell.reset(rng_heap, int(ev.boxes_per_trial))
        self.cell.sensor_rng = rng_sensor
        ctrl.new_trial()
        boxes = len(self.cell.boxes)
        attempts: list[Attempt] = []
        failures: dict[int, int] = {}
        trace: list[dict] | None = [] if keep_trace else None
        end, no_grasp, final_home = "max_attempts", {}, {}
        for index in range(int(ev.max_attempts_per_trial)):
            if not self.cell.boxes_in_bin():
                end = "bin_empty"
                break
            self.cell.robot.set_joints(self.cell.robot.home_q())
            obs = self.observe()
            result = ctrl.plan(obs, rng_plan)
            if result.plan is None:
                end = "no_grasp"
                no_grasp = {
                    "boxes_left": len(self.cell.boxes_in_bin()),
                    "candidates": len(result.candidates),
                    "checked": result.checked,
                    "rejected": dict(sorted(result.rejected.items())),
                }
                if self.name != "oracle" and bool(ev.label_no_grasp):
                    no_grasp.update(labels_at_no_grasp(self, obs))
                if trace is not None:
                    final_home = final_home_record(self.cell, obs, result.candidates)
                break
            att = self.attempt(result.plan, obs, trial, index, trace)
            attempts.append(att)
            if att.outcome != "success":
                ctrl.remember_failure(result.plan, att.outcome)
                failures[att.target_body] = failures.get(att.target_body, 0) + 1
                if failures[att.target_body] >= int(ev.max_failures_per_target):
                    end = "max_failures"
                    break
        else:
            if not self.cell.boxes_in_bin():
                end = "bin_empty"
        picked = sum(a.outcome == "success" for a in attempts)
        return TrialResult(
            trial=trial,
            planner=self.name,
            boxes=boxes,
            picked=picked,
            end=end,
            attempts=attempts,
            trace=trace or [],
            no_grasp=no_grasp,
            final_home=final_home,
        )


def make_runner(cfg, name: str, make_planner) -> TrialRunner:
    """A ``TrialRunner`` for planner ``name``: a new world cell, the planner
    ``make_planner(cell)`` (only the oracle uses the cell: it plans from its truth), and the
    robot side with the run-time check's heap knowledge of ``evaluate.collision_model``
    (``observed``: its depth images; ``truth``: ``pipeline.world.knowledge.TruthHeap``)."""
    from pipeline.controller.picker import RobotController
    from pipeline.robot.model import Robot, robot_config

    cell = PickCell(cfg, lambda: Robot(robot_config(cfg)))
    knowledge = None
    if str(cfg.evaluate.collision_model) == "truth":
        from pipeline.world.knowledge import TruthHeap

        def knowledge(client):
            return TruthHeap(client, cell)

    controller = RobotController(cfg, make_planner(cell), name, knowledge)
    return TrialRunner(cfg, cell, controller, name)
