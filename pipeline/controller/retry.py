"""The retry memory: after a failed attempt, the same plan is not tried again unchanged.

With ``evaluate.retry_policy: skip_failed`` a candidate repeats a failure, and is skipped, when
its grasp point lies within ``retry_same_point_m`` of a failed attempt's point (world frame),
with the same pattern (any pattern when the failure's outcome is one of
``evaluate.retry_point_outcomes``: the surface at the point failed, not the pattern), while the
heap around that point has not changed since the failed plan was made.

**Changed**, from depth alone: the home images of the failed plan and of now (the home pose is
one joint state, so the two images are pixel-aligned; another camera pose counts as a change)
are median-filtered (5 × 5, so that a sensor's noise and single flying pixels do not count),
and the pixels whose point lies within ``retry_neighbour_m`` of the failed point (horizontal
distance, world frame) and whose depth differs by more than ``retry_depth_change_m`` are
summed as area (each pixel's footprint z² / (f_x f_y)), leaving out changes thinner than
3 pixels (a morphological opening of the changed pixels): on a sensor's depth the boundary of
every depth step flickers by a pixel or two between images, and along the edges of a whole
heap that alone exceeded the threshold, so the heap always looked changed and a failed plan was
retried unchanged. The heap changed near the point when that area reaches
``retry_changed_area_m2``: a box picked, fallen, pushed or arrived there. A 5 mm slide of a
10 cm box edge changes about 2 × 0.1 × 0.005 = 10 cm² (its leading and trailing edges, each
about 3.4 pixels wide at 0.6 m); the default 5 cm² is half of that.

**A box one cup could not hold** (``evaluate.retry_drop_single_cup``): after a single cup
(L or R) dropped a box, single-cup plans within ``retry_same_point_m`` of that point stay
skipped for the rest of the trial even when the heap has changed: a drop moves the box, so the
heap always looks changed, but the box has not become lighter. Two cups (B) there remain a new
plan.

**Two cups that found no seal** (``evaluate.retry_no_seal_two_cups``): after B found no seal,
B plans within ``retry_same_point_m`` of that point stay skipped for the rest of the trial even
when the heap has changed: the surface is no wider for a box moved beside it (two cups that
overhang a face too narrow for them, or straddle a seam). One cup (L or R) there is a new plan
as soon as the heap has changed, and on the same image the point's other patterns are skipped
as ``retry_point_outcomes`` says.

``retry_policy: repeat``: no memory (identical plans are retried until the trial's failure
limit ends it).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from pipeline.controller.heap_model import world_points
from pipeline.controller.observation import Observation

RETRY_POLICIES = ("skip_failed", "repeat")
_SAME_POSE_M, _SAME_POSE_DEG = 1e-4, 0.01  # home images this close are pixel-aligned


@dataclass
class FailedPlan:
    """A failed attempt as the robot remembers it: its grasp ``point`` (3,) world, metres, the
    ``pattern``, the ``outcome`` the robot observed, and the home image it was planned on
    (``depth_m`` median-filtered, (H, W), metres; ``T_world_cam`` (4, 4))."""

    point: np.ndarray
    pattern: str
    outcome: str
    depth_m: np.ndarray
    T_world_cam: np.ndarray


def smoothed(depth_m: np.ndarray) -> np.ndarray:
    """(H, W) float32 depth, 5 × 5 median-filtered (0 = no data stays a value of the filter)."""
    return cv2.medianBlur(np.ascontiguousarray(depth_m, np.float32), 5)


class RetryMemory:
    """The failed plans of one trial (module docstring)."""

    def __init__(self, ev) -> None:
        """``ev``: the ``evaluate`` section."""
        self.policy = str(ev.retry_policy)
        if self.policy not in RETRY_POLICIES:
            raise ValueError(
                f"evaluate.retry_policy is {self.policy!r}: choose from {RETRY_POLICIES}"
            )
        self.same_point_m = float(ev.retry_same_point_m)
        self.radius_m = float(ev.retry_neighbour_m)
        self.depth_change_m = float(ev.retry_depth_change_m)
        self.area_m2 = float(ev.retry_changed_area_m2)
        self.point_outcomes = {str(o) for o in ev.retry_point_outcomes}
        self.drop_single_cup = bool(ev.retry_drop_single_cup)
        self.no_seal_two_cups = bool(ev.retry_no_seal_two_cups)
        self.failed: list[FailedPlan] = []
        self._now: tuple[int, np.ndarray] | None = None  # (id of the obs, its smoothed depth)

    def clear(self) -> None:
        self.failed = []

    def remember(
        self, plan_obs: Observation, point_world: np.ndarray, pattern: str, outcome: str
    ) -> None:
        """A failed attempt planned on ``plan_obs`` at ``point_world`` with ``pattern``."""
        self.failed.append(
            FailedPlan(
                np.asarray(point_world, np.float64),
                pattern,
                outcome,
                smoothed(plan_obs.depth_m),
                np.asarray(plan_obs.T_world_cam, np.float64),
            )
        )

    def _smoothed_now(self, obs: Observation) -> np.ndarray:
        if self._now is None or self._now[0] != id(obs):
            self._now = (id(obs), smoothed(obs.depth_m))
        return self._now[1]

    def changed_area(self, f: FailedPlan, obs: Observation) -> float:
        """m², the area near ``f.point`` whose depth changed since ``f`` was planned (inf when
        the home camera moved)."""
        dt = np.linalg.norm(obs.T_world_cam[:3, 3] - f.T_world_cam[:3, 3])
        c = (np.trace(obs.T_world_cam[:3, :3].T @ f.T_world_cam[:3, :3]) - 1) / 2
        if dt > _SAME_POSE_M or np.degrees(np.arccos(np.clip(c, -1, 1))) > _SAME_POSE_DEG:
            return float("inf")
        now, then = self._smoothed_now(obs), f.depth_m
        (x, y, _), _ = world_points(obs)
        near = np.hypot(x - f.point[0], y - f.point[1]) <= self.radius_m
        both = (now > 0) & (then > 0) & near
        changed = both & (np.abs(now - then) > self.depth_change_m)
        # a change thinner than 3 pixels is a sensor's flicker at depth steps, not a moved box
        changed = cv2.morphologyEx(
            changed.astype(np.uint8), cv2.MORPH_OPEN, np.ones((3, 3), np.uint8)
        ).astype(bool)
        intr = obs.intrinsics
        return float(np.sum(now[changed].astype(np.float64) ** 2) / (intr.fx * intr.fy))

    def repeats(self, obs: Observation, point_world: np.ndarray | None, pattern: str) -> bool:
        """Whether a grasp at ``point_world`` (None: unknown, never a repeat) with ``pattern``,
        planned on ``obs``, repeats a failed plan in an unchanged heap."""
        if self.policy == "repeat" or point_world is None:
            return False
        for f in self.failed:
            if np.linalg.norm(point_world - f.point) > self.same_point_m:
                continue
            if (
                self.drop_single_cup
                and f.outcome == "dropped"
                and f.pattern != "B"
                and pattern != "B"
            ):
                return True  # one cup did not hold this box: the heap's changes do not matter
            if (
                self.no_seal_two_cups
                and f.outcome == "no_seal"
                and f.pattern == "B"
                and pattern == "B"
            ):
                return True  # two cups found no seal on this surface: it has not grown
            same_plan = f.pattern == pattern or f.outcome in self.point_outcomes
            if same_plan and self.changed_area(f, obs) < self.area_m2:
                return True
        return False
