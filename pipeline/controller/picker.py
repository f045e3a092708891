"""The robot's decisions at home: plan, choose, check (paper Fig. 2's red loop, and the run-time
check this project adds).

:class:`RobotController` is the robot side of the closed loop. It owns the planner, the
run-time check (``pipeline.controller.check``: its own robot model, the bin and the heap model
from depth), the retry memory (``pipeline.controller.retry``) and the servo and moves
(``pipeline.controller.motion``); it takes :class:`~pipeline.controller.observation.Observation`
objects and gives back plans and joint commands. It never sees the simulated world.

**A plan** (:meth:`RobotController.plan`) from the home observation:

1. the planner's ranked grasps (``plan(observation, rng)``, checked against the interface);
2. with ``evaluate.min_area_ratio`` > 0 (paper Sec. 8.4), the grasps with a pattern whose
   surface (the descriptor's region at the point) covers less than that ratio times the active
   cups' area are dropped;
3. the first ``evaluate.max_candidates_checked`` grasps in rank order, each with its patterns
   in order of preference (the planner's; with ``evaluate.single_cup_fallback`` a B is
   followed by L, then R, right after it or, with ``evaluate.single_cup_fallback_order:
   last``, after every grasp's own pattern; with ``evaluate.two_cups_first``, an L or R (of the
   second tier, or any) is tried with both cups first, then with its own cup; with
   ``evaluate.b_quarter_turn``, every B is followed by B with the hand turned by 90°, its cups
   along the other axis of the surface; a single suction point is served by
   ``evaluate.dexnet_pattern``'s cup, then the other): skipped when it repeats a failed plan
   (the retry memory); with ``evaluate.check_reachability`` (default) executed only when the
   descriptor finds a surface at it and the run-time check passes. The first that does is the
   plan; none: no grasp.

The surface checked is the one the servo will track: with ``evaluate.face_split_m`` > 0, a
region grown at home from a patterned grasp that also holds another grasp of the planner's
farther than ``face_split_m`` from it is split between those points (coplanar faces of two
boxes side by side).

The planning time (planner, area check, selection and check) is measured in wall-clock seconds.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, field

import numpy as np

from pipeline.camera.geometry import backproject_pixels
from pipeline.controller.check import RunTimeCheck
from pipeline.controller.motion import Kinematics, Mover, Servo
from pipeline.controller.observation import Observation
from pipeline.controller.planning import Grasp, checked_grasps
from pipeline.controller.retry import RetryMemory

FALLBACK_ORDERS = ("at_once", "last")  # evaluate.single_cup_fallback_order
TWO_CUPS_FIRST = ("none", "second_tier", "all")  # evaluate.two_cups_first
QUARTER_B = "B90"  # in the selection's order: B, the hand turned by 90° (evaluate.b_quarter_turn)


@dataclass
class Plan:
    """The grasp the robot will execute.

    Attributes:
        grasp: the planner's grasp.
        pattern: "L", "R" or "B", the cups to use.
        obs: the home observation it was planned on.
        point_world: (3,) the grasp point in the world (the depth at the pixel back-projected,
            or the planner's own point), metres; None when the pixel has no depth.
        x_world: (3,) the hand's X axis the check chose (None: the paper's rule, unchecked).
        predicted: the check's predicted camera poses of the servo ((4, 4) each), or None.
        sites_world: (k, 3) the face-split sites (the grasp's point first), or None.
        fixed_point_world: (3,) a single suction point held fixed by the servo (Dex-Net), or
            None (the servo tracks the surface centre).
        planning_s: wall-clock seconds of the planning that made it.
    """

    grasp: Grasp
    pattern: str
    obs: Observation
    point_world: np.ndarray | None
    x_world: np.ndarray | None = None
    predicted: list | None = None
    sites_world: np.ndarray | None = None
    fixed_point_world: np.ndarray | None = None
    planning_s: float = 0.0


@dataclass
class PlanResult:
    """What :meth:`RobotController.plan` found: ``plan`` (None: no grasp), the planner's
    ``candidates`` (after the area check), how many were ``checked``, the (grasp, pattern)
    pairs ``rejected`` per reason (the check's NG reason, "descriptor" when it found no surface,
    "hand_fit", "repeat" for a retry of a failed plan), and ``planning_s``."""

    plan: Plan | None
    candidates: list
    checked: int
    rejected: dict = field(default_factory=dict)
    planning_s: float = 0.0


class RobotController:
    """The robot side (module docstring).

    ``planner``: an object with ``plan(observation, rng)`` (``pipeline.controller.planning``);
    ``name``: its name in errors; ``collision_model``: the run-time check's heap knowledge
    (None: the observed heap; ``pipeline.controller.check.RunTimeCheck``)."""

    def __init__(self, cfg, planner, name: str, collision_model=None) -> None:
        from pipeline.servo.control import servo_config
        from pipeline.servo.descriptor import descriptor_config

        self.cfg, self.planner, self.name = cfg, planner, name
        order = str(cfg.evaluate.single_cup_fallback_order)
        if order not in FALLBACK_ORDERS:
            raise ValueError(
                f"evaluate.single_cup_fallback_order is {order!r}: choose from {FALLBACK_ORDERS}"
            )
        upgrade = str(cfg.evaluate.two_cups_first)
        if upgrade not in TWO_CUPS_FIRST:
            raise ValueError(
                f"evaluate.two_cups_first is {upgrade!r}: choose from {TWO_CUPS_FIRST}"
            )
        self.checker = RunTimeCheck(cfg, collision_model)
        self.robot = self.checker.robot
        self.kin = Kinematics(cfg, self.robot)
        self.mover = Mover(cfg, self.kin)
        self.descriptor_cfg = descriptor_config(cfg)
        self.servo_cfg = servo_config(cfg)
        self.memory = RetryMemory(cfg.evaluate)
        self.timings: dict[str, list[float]] = {"descriptor_s": [], "control_law_s": []}

    # ------------------------------------------------------------------ trial
    def new_trial(self) -> None:
        """Forget the failed plans (a new heap)."""
        self.memory.clear()

    def home_q(self) -> np.ndarray:
        return self.robot.home_q()

    def remember_failure(self, plan: Plan, outcome: str) -> None:
        """``plan`` failed with ``outcome`` (what the robot observed): the retry memory."""
        if plan.point_world is not None:
            self.memory.remember(plan.obs, plan.point_world, plan.pattern, outcome)

    # ------------------------------------------------------------------ helpers
    def patterns(self, grasp: Grasp) -> list[str]:
        """The patterns a grasp may be executed with, in order of preference (module
        docstring, step 3)."""
        out = self._patterns(grasp)
        if bool(self.cfg.evaluate.b_quarter_turn):
            out = [q for p in out for q in ((p, QUARTER_B) if p == "B" else (p,))]
        return out

    def _patterns(self, grasp: Grasp) -> list[str]:
        """:meth:`patterns` without B's quarter turn."""
        if grasp.pattern is not None:
            if grasp.pattern == "B" and bool(self.cfg.evaluate.single_cup_fallback):
                return ["B", "L", "R"]
            upgrade = str(self.cfg.evaluate.two_cups_first)
            if upgrade == "all" or (upgrade == "second_tier" and grasp.second_tier):
                return ["B", grasp.pattern]  # both cups first where they fit
            return [grasp.pattern]
        preferred = str(self.cfg.evaluate.dexnet_pattern)
        if preferred == "B":
            return ["B"]
        return [preferred, {"L": "R", "R": "L"}[preferred]]

    @staticmethod
    def point_cam(obs: Observation, grasp: Grasp) -> np.ndarray | None:
        """The grasp's point in the observation's camera (its own ``point_cam`` when it has
        one, else the depth at its pixel back-projected), metres; None when the pixel has no
        depth or lies outside the image."""
        if grasp.point_cam is not None:
            return np.asarray(grasp.point_cam, np.float64)
        intr = obs.intrinsics
        u, v = int(round(grasp.u)), int(round(grasp.v))
        if not (0 <= v < intr.height and 0 <= u < intr.width):
            return None
        z = float(obs.depth_m[v, u])
        if not z > 0:
            return None
        return backproject_pixels(np.array([grasp.u, grasp.v]), z, intr)

    def point_world(self, obs: Observation, grasp: Grasp) -> np.ndarray | None:
        p = self.point_cam(obs, grasp)
        if p is None:
            return None
        T = obs.T_world_cam
        return T[:3, :3] @ p + T[:3, 3]

    def describe(self, obs: Observation, grasp: Grasp, sites_cam=None):
        """The descriptor's surface at the grasp on ``obs`` (or None) and its reason."""
        from pipeline.servo.descriptor import describe_surface

        t0 = time.perf_counter()
        out = describe_surface(
            obs.depth_m,
            obs.intrinsics,
            np.array([grasp.u, grasp.v], np.float64),
            self.descriptor_cfg,
            sites_cam=sites_cam,
        )
        self.timings["descriptor_s"].append(time.perf_counter() - t0)
        return out

    def large_enough(self, obs: Observation, grasps: list[Grasp]) -> list[Grasp]:
        """With ``evaluate.min_area_ratio`` > 0 (paper Sec. 8.4's safety constraint), the
        patterned grasps among the first ``max_candidates_checked`` whose surface covers at
        least that ratio times the active cups' area (one cup for L and R, two for B); the
        others are dropped. Single suction points are kept as they are."""
        ratio = float(self.cfg.evaluate.min_area_ratio)
        if ratio <= 0 or not grasps:
            return grasps
        cup = math.pi * (float(self.cfg.hand.cup_diameter) / 2) ** 2
        kept = []
        for g in grasps[: int(self.cfg.evaluate.max_candidates_checked)]:
            if g.pattern is None:
                kept.append(g)
                continue
            feats, _ = self.describe(obs, g)
            cups = 2 if g.pattern == "B" else 1
            if feats is not None and feats.area >= ratio * cups * cup:
                kept.append(g)
        return kept

    def home_surface(self, obs: Observation, grasp: Grasp, grasps: list[Grasp]):
        """(the descriptor's surface at the grasp on the home image or None, the face-split
        sites in the world or None): the sites are the grasp's point, then the point of every
        other grasp of ``grasps`` in the region the descriptor grows at it and farther than
        ``evaluate.face_split_m`` from its point; None when there is no such point, the split
        is off, or the grasp is a single suction point."""
        feats, _ = self.describe(obs, grasp)
        split_m = float(self.cfg.evaluate.face_split_m)
        point = self.point_cam(obs, grasp)
        if split_m <= 0 or grasp.pattern is None or feats is None or point is None:
            return feats, None
        sites = [point]
        for other in grasps:
            u, v = int(round(other.u)), int(round(other.v))
            if (
                other is grasp
                or not (0 <= v < feats.region.shape[0] and 0 <= u < feats.region.shape[1])
                or not feats.region[v, u]
            ):
                continue
            q = self.point_cam(obs, other)
            if q is not None and np.linalg.norm(q - point) > split_m:
                sites.append(q)
        if len(sites) < 2:
            return feats, None
        feats, _ = self.describe(obs, grasp, sites_cam=np.asarray(sites))
        T = obs.T_world_cam
        return feats, np.asarray(sites) @ T[:3, :3].T + T[:3, 3]

    def perceive(self, obs: Observation) -> Observation:
        """``obs`` with its depth preprocessed by ``depth_filter`` (``none``: as it is; hole
        filling and median filters, ``pipeline.camera.depth_filter``): what planning and the
        servo read."""
        from pipeline.camera.depth_filter import preprocess_depth

        if str(self.cfg.depth_filter.name) == "none":
            return obs
        return dataclasses.replace(
            obs, depth_m=preprocess_depth(obs.depth_m, self.cfg.depth_filter)
        )

    # ------------------------------------------------------------------ planning
    def propose(self, obs: Observation, rng: np.random.Generator) -> list[Grasp]:
        """The planner's grasps on ``obs``, checked against the interface."""
        return checked_grasps(self.planner.plan(obs, rng), obs, self.name)

    def plan(self, obs: Observation, rng: np.random.Generator) -> PlanResult:
        """Plan at home on ``obs`` (module docstring)."""
        t0 = time.perf_counter()
        obs = self.perceive(obs)
        grasps = self.large_enough(obs, self.propose(obs, rng))
        result = self.select(obs, grasps)
        result.planning_s = time.perf_counter() - t0
        if result.plan is not None:
            result.plan.planning_s = result.planning_s
        return result

    def select(self, obs: Observation, grasps: list[Grasp]) -> PlanResult:
        """The plan among ``grasps`` on the home ``obs`` (module docstring, step 3)."""
        ev = self.cfg.evaluate
        gate = bool(ev.check_reachability)
        rejected: dict[str, int] = {}
        limit = int(ev.max_candidates_checked)
        out = PlanResult(None, grasps, min(len(grasps), limit), rejected)
        if gate and grasps:
            self.checker.update(obs)
        points: dict[int, np.ndarray | None] = {}  # per grasp, its point in the world, once
        surfaces: dict[int, tuple] = {}  # per grasp, found once when first needed: (feats, sites)
        for i, entry in self.order(grasps[:limit]):
            grasp = grasps[i]
            quarter = entry == QUARTER_B  # B with the hand turned by 90°: only a check can turn it
            pattern = "B" if quarter else entry
            if quarter and not gate:
                continue
            if i not in points:
                points[i] = self.point_world(obs, grasp)
            point = points[i]
            fixed = None if grasp.pattern is not None or grasp.point_cam is None else point
            if self.memory.repeats(obs, point, pattern):
                rejected["repeat"] = rejected.get("repeat", 0) + 1
                continue
            if i not in surfaces:
                surfaces[i] = self.home_surface(obs, grasp, grasps)
            feats, sites = surfaces[i]
            if not gate:
                out.plan = Plan(
                    grasp, pattern, obs, point, sites_world=sites, fixed_point_world=fixed
                )
                return out
            if feats is None:
                rejected["descriptor"] = rejected.get("descriptor", 0) + 1
                continue
            centre = feats.center_cam if fixed is None else self.point_cam(obs, grasp)
            check, reason = self.checker.check(
                obs,
                feats,
                centre,
                pattern,
                (grasp.u, grasp.v),
                hand_fit=bool(ev.check_hand_fit) and grasp.pattern is not None,
                quarter_turn=quarter,
            )
            if check is not None:
                out.plan = Plan(grasp, pattern, obs, point, check.x_world, check.path, sites, fixed)
                return out
            rejected[reason] = rejected.get(reason, 0) + 1
        return out

    def order(self, grasps: list[Grasp]) -> list[tuple[int, str]]:
        """The (index into ``grasps``, pattern) pairs the selection tries, in order (module
        docstring, step 3): each grasp's patterns (:meth:`patterns`) right after one another,
        or, with ``evaluate.single_cup_fallback_order: last``, a B's single cups after every
        grasp's own pattern, in the grasps' order."""
        pairs = [(i, p) for i, g in enumerate(grasps) for p in self.patterns(g)]
        if str(self.cfg.evaluate.single_cup_fallback_order) == "at_once":
            return pairs
        own, fallback = [], []
        for i, p in pairs:
            (fallback if grasps[i].pattern == "B" and p in ("L", "R") else own).append((i, p))
        return own + fallback

    # ------------------------------------------------------------------ execution
    def servo(self, plan: Plan) -> Servo:
        """The visual servo that executes ``plan`` (``pipeline.controller.motion.Servo``)."""
        return Servo(
            self.cfg,
            self.kin,
            self.descriptor_cfg,
            self.servo_cfg,
            plan,
            self.perceive,
            self.timings,
        )

    def close(self) -> None:
        self.checker.close()
