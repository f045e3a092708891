"""The paper's failure cases (Sec. 8.4) as options: the height tie-break among inclined surfaces
and the surface-area safety check, against answers worked out by hand."""

from __future__ import annotations

import dataclasses
import math
from types import SimpleNamespace

import numpy as np
import pytest
from conftest import default_config

from pipeline.camera.geometry import Intrinsics
from pipeline.controller.observation import Observation
from pipeline.controller.planning import Grasp
from pipeline.grasping.types import GraspClass
from pipeline.planner.ranking import GraspCandidate, RankingConfig, graspability, order_candidates
from pipeline.servo.descriptor import DescriptorConfig

D_GROUND = 0.645


def cand(name: str, phi_deg: float, depth: float, prob: float = 0.9) -> GraspCandidate:
    phi = math.radians(phi_deg)
    score, jd, ji = graspability(depth, phi, D_GROUND, PAPER.phi_switch)
    c = GraspCandidate(
        u=0.0,
        v=0.0,
        grasp_class=GraspClass.L,
        probability=prob,
        score=score,
        phi=phi,
        depth=depth,
        normal_cam=np.zeros(3, np.float32),
        j_distance=jd,
        j_inclination=ji,
    )
    c.name = name
    return c


def names(cands):
    return [c.name for c in cands]


PAPER = default_config(RankingConfig, d_ground=D_GROUND, threshold=0.5, policy="paper")
TIE = dataclasses.replace(PAPER, policy="height_tiebreak", inclination_tie=math.radians(10))


def test_fig11_upper_box_goes_first_with_the_tie_break():
    # Fig. 11: the upper box's face (35°, 0.45 m away) and a lower box's face (32°, 0.55 m).
    # Eq. 7: J_inclination = 1 − 2φ/π = 0.611 (upper) < 0.644 (lower): the paper takes the lower.
    upper, lower = cand("upper", 35, 0.45), cand("lower", 32, 0.55)
    assert upper.score == pytest.approx(0.6111, abs=1e-4)
    assert lower.score == pytest.approx(0.6444, abs=1e-4)
    assert names(order_candidates([upper, lower], PAPER)) == ["lower", "upper"]
    # |35° − 32°| < 10°: compare heights; J_distance = 1 − 0.45/0.645 = 0.302 > 0.147.
    assert names(order_candidates([upper, lower], TIE)) == ["upper", "lower"]


def test_inclinations_far_apart_keep_the_paper_order():
    upper, lower = cand("upper", 45, 0.45), cand("lower", 32, 0.55)  # 13° apart ≥ 10°
    assert names(order_candidates([upper, lower], TIE)) == ["lower", "upper"]


def test_level_best_is_unchanged_and_ties_chain_greedily():
    # The best is level (φ < 30°): J is already J_distance, the tie-break does not apply.
    a, b = cand("a", 10, 0.50), cand("b", 12, 0.40)
    assert (
        names(order_candidates([a, b], TIE)) == names(order_candidates([a, b], PAPER)) == ["b", "a"]
    )
    # Inclined best (31°) and a level face 6° flatter but higher: they tie, the higher goes first;
    # then the 50° face, far from both, keeps its place in the paper's order.
    x, y, z = cand("x", 31, 0.55), cand("y", 25, 0.42), cand("z", 50, 0.30)
    assert names(order_candidates([x, y, z], PAPER)) == ["x", "z", "y"]
    assert names(order_candidates([x, y, z], TIE)) == ["y", "x", "z"]


def test_unknown_policy_is_a_clear_error():
    with pytest.raises(ValueError, match="height_tiebreak"):
        order_candidates([cand("a", 10, 0.5)], dataclasses.replace(PAPER, policy="tallest"))


def _controller(ratio: float, cup_diameter: float = 0.030):
    """The robot side's area check alone (``RobotController.large_enough``), without its
    robot or its check."""
    from pipeline.controller.picker import RobotController

    ctrl = RobotController.__new__(RobotController)
    ctrl.cfg = SimpleNamespace(
        evaluate=SimpleNamespace(min_area_ratio=ratio, max_candidates_checked=10),
        hand=SimpleNamespace(cup_diameter=cup_diameter),
    )
    ctrl.descriptor_cfg = default_config(
        DescriptorConfig, window_tolerance_depth=0.0, track_normal_deg=0.0
    )
    ctrl.timings = {"descriptor_s": []}
    return ctrl


def test_area_check_drops_surfaces_barely_larger_than_the_cup():
    """A floor 0.60 m away and two box tops 0.10 m higher, 0.5 m from the camera, where a pixel
    spans 0.5 / 411.7 m = 1.2145 mm: 22 × 22 px (7.14 cm²) and 30 × 30 px (13.27 cm²). With a
    30-mm cup (7.07 cm²), 1.2 × the cup is 8.48 cm²: the small top is larger than the cup but
    fails the check; for B (two cups) the big top needs 16.96 cm² and fails too."""
    intr = Intrinsics(width=160, height=160, fx=411.7, fy=411.7, cx=79.5, cy=79.5)
    depth = np.full((160, 160), 0.60, np.float32)
    depth[20:42, 20:42] = 0.50
    depth[80:110, 80:110] = 0.50
    obs = Observation(depth, intr, np.eye(4), np.zeros(7))
    small, big, big_b = (
        Grasp(30.5, 30.5, "L", score=1.0),
        Grasp(94.5, 94.5, "L", score=2.0),
        Grasp(94.5, 94.5, "B", score=3.0),
    )
    cands = [small, big, big_b]

    def kept(ctrl):
        return [
            {1.0: "small", 2.0: "big", 3.0: "big_b"}[g.score] for g in ctrl.large_enough(obs, cands)
        ]

    assert _controller(0.0).large_enough(obs, cands) == cands  # off: unchanged
    assert kept(_controller(1.0)) == ["small", "big"]
    assert kept(_controller(1.2)) == ["big"]
    # 18-mm cups (2.54 cm²): 1.2 × two cups = 6.1 cm², every top passes
    assert _controller(1.2, 0.018).large_enough(obs, cands) == cands
