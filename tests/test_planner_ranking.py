"""Grasp point score ranking (paper Sec. 4.2, Eqs. 7–10) on planes at known depths and tilts.

Camera: SR300-like, fx = fy = 411.7 px, principal point (207.5, 207.5); D_ground = 0.645 m.
A plane through (0, 0, z0) tilted by θ about the camera's y axis has the normal
(sin θ, 0, −cos θ) towards the camera and depth z = z0 / (1 − tan θ · (u − cx) / fx),
so φ = θ.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import default_config

from pipeline.camera.geometry import Intrinsics
from pipeline.grasping.types import GraspClass
from pipeline.planner import GraspPrediction, RankingConfig, graspability, rank_grasps

SR300 = Intrinsics(416, 416, 411.7, 411.7, 207.5, 207.5)
CFG = default_config(RankingConfig, d_ground=0.645, threshold=0.5)


def plane(z0: float, tilt_deg: float = 0.0) -> np.ndarray:
    """(416, 416) float32 depth of a plane tilted ``tilt_deg`` about the camera y axis."""
    a = (np.arange(416) - SR300.cx) / SR300.fx  # (W,) x / z per column
    z = z0 / (1 - math.tan(math.radians(tilt_deg)) * a)
    return np.broadcast_to(z[None, :], (416, 416)).astype(np.float32).copy()


def pred(u, v, cls=GraspClass.B, p=0.9) -> GraspPrediction:
    return GraspPrediction(
        u=u, v=v, grasp_class=GraspClass(cls), probability=p, class_probs=np.full(4, p, np.float32)
    )


def test_level_plane_uses_distance():
    [c] = rank_grasps([pred(200.0, 210.0)], plane(0.5), SR300, CFG)
    assert c.phi == pytest.approx(0.0, abs=1e-3)
    np.testing.assert_allclose(c.normal_cam, [0, 0, -1], atol=1e-4)  # towards the camera
    assert c.depth == pytest.approx(0.5)
    assert c.score == pytest.approx(0.224806, abs=1e-6)  # 1 − 0.5 / 0.645
    assert c.j_distance == c.score and c.j_inclination == pytest.approx(1.0, abs=1e-3)


def test_45_degree_plane_uses_inclination():
    [c] = rank_grasps([pred(200.0, 210.0)], plane(0.5, 45), SR300, CFG)
    assert c.phi == pytest.approx(math.pi / 4, abs=1e-4)
    s = math.sqrt(0.5)
    np.testing.assert_allclose(c.normal_cam, [s, 0, -s], atol=1e-4)
    assert c.score == pytest.approx(0.5, abs=1e-4)  # 1 − 2 (π/4) / π


def test_switch_at_30_degrees():
    # 29° < π/6: J_distance = 1 − I(g) / D_ground with I(g) read at the pixel.
    depth = plane(0.5, 29)
    [c] = rank_grasps([pred(200.0, 210.0)], depth, SR300, CFG)
    assert c.phi == pytest.approx(math.radians(29), abs=1e-4)
    assert c.score == pytest.approx(1 - depth[210, 200] / 0.645, abs=1e-6)
    # 31° ≥ π/6: J_inclination = 1 − 2 · 31 / 180 = 0.655556.
    [c] = rank_grasps([pred(200.0, 210.0)], plane(0.5, 31), SR300, CFG)
    assert c.score == pytest.approx(0.655556, abs=1e-4)
    # boundary: inclination
    assert graspability(0.5, math.pi / 6, 0.645, CFG.phi_switch)[0] == pytest.approx(1 - 2 / 6)


def test_ordering_on_four_bands():
    depth = np.concatenate(
        [plane(0.6)[:104], plane(0.4)[104:208], plane(0.5, 45)[208:312], plane(0.5, 60)[312:]]
    )
    preds = [
        pred(200.0, 50.0, GraspClass.B),
        pred(200.0, 150.0, GraspClass.L),
        pred(200.0, 260.0, GraspClass.R),
        pred(200.0, 360.0, GraspClass.B),
    ]
    ranked = rank_grasps(preds, depth, SR300, CFG)
    # J: level 0.6 → 1 − 0.6/0.645 = 0.069767; level 0.4 → 0.379845;
    #    45° → 1 − 2 (π/4)/π = 0.5; 60° → 1 − 2 (π/3)/π = 0.333333.
    assert [c.v for c in ranked] == [260.0, 150.0, 360.0, 50.0]
    np.testing.assert_allclose(
        [c.score for c in ranked], [0.5, 0.379845, 1 / 3, 0.069767], atol=1e-4
    )
    assert ranked[0].grasp_class == GraspClass.R  # G_opt


def test_ng_and_low_probability_are_removed():
    preds = [
        pred(100.0, 100.0, GraspClass.NG, 0.99),
        pred(150.0, 100.0, GraspClass.B, 0.5),
        pred(200.0, 100.0, GraspClass.L, 0.3),
        pred(250.0, 100.0, GraspClass.R, 0.51),
    ]
    ranked = rank_grasps(preds, plane(0.5), SR300, CFG)
    assert [(c.u, c.grasp_class) for c in ranked] == [(250.0, GraspClass.R)]  # S > th, strictly


def test_missing_depth_and_edges():
    depth = plane(0.5)
    depth[:, 210:] = 0.45  # a 5 cm step at u = 210
    depth[100:140, 100:140] = 0.0  # a hole
    depth[300, 300] = 0.0  # a single dead pixel
    ranked = rank_grasps(
        [pred(120.0, 120.0), pred(300.0, 300.0), pred(208.0, 300.0)], depth, SR300, CFG
    )
    by_u = {c.u: c for c in ranked}
    assert 120.0 not in by_u  # no data in its window: dropped
    assert by_u[300.0].depth == pytest.approx(0.45)  # median of the window
    # 2 px from the step: the pixels whose differences straddle it are skipped, so still level.
    assert by_u[208.0].phi == pytest.approx(0.0, abs=1e-3)
    assert by_u[208.0].score == pytest.approx(1 - 0.5 / 0.645, abs=1e-6)
