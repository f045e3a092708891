"""Hand-level labels (paper Figs. 5, 6) on surfaces worked out by hand."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from conftest import conf_section

from pipeline.grasping.hand import camera_centre, hand_label, rotation_between
from pipeline.grasping.types import GraspClass, Surface
from pipeline.robot.target_pose import target_camera_pose

CFG = conf_section(
    "hand"
)  # conf/hand/two_cup.yaml: cups: r = 9 mm, offset 35 mm, margin 2 mm, area ratio 1.2


def surface(long_axis, normal, L_l, L_s, center=(0.0, 0.0, 0.6)):
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    long_dir = np.asarray(long_axis, float) / np.linalg.norm(long_axis)
    s = np.cross(n, long_dir)
    return Surface(
        instance=1,
        center_cam=np.asarray(center, float),
        normal_cam=n,
        long_axis_cam=long_dir,
        short_axis_cam=s,
        long_length=L_l,
        short_length=L_s,
        center_px=np.zeros(2),
        num_points=1000,
        area=L_l * L_s,
    )


def test_rotation_between():
    for a, b in [((0, 0, 1), (0, 0.5, -0.866)), ((1, 0, 0), (0, 1, 0)), ((0, 0, 1), (0, 0, -1))]:
        a, b = np.array(a, float), np.array(b, float) / np.linalg.norm(b)
        R = rotation_between(a, b)
        assert R @ a == pytest.approx(b, abs=1e-9)
        assert R @ R.T == pytest.approx(np.eye(3), abs=1e-9)
        assert np.linalg.det(R) == pytest.approx(1.0)


def test_flat_face_long_along_x_takes_one_cup():
    # 0.12 × 0.075 m top face, long side along image X: θ1 = 0°, θ2 = 90°, so X is aligned with
    # the long side and the cups run across the 0.075 m side. Both cups need
    # 0.035 + 0.009 + 0.002 = 0.046 m > 0.0375 m of half-width: no B. One cup needs
    # 0.011 m ≤ 0.0375 m: fits. Level surface: O_cam heights tie → L.
    lab = hand_label(surface([1, 0, 0], [0, 0, -1], 0.12, 0.075), CFG)
    assert (lab.theta1_deg, lab.theta2_deg) == pytest.approx((0.0, 90.0))
    assert lab.aligned == "long" and lab.grasp_class == GraspClass.L
    assert lab.x_axis_cam == pytest.approx([1, 0, 0])


def test_flat_face_long_along_y_takes_both_cups():
    # The same face turned 90°: θ1 = 90°, θ2 = 0°, X aligned with the short side; the cups run
    # along the 0.12 m side: 0.046 ≤ 0.06 and 0.011 ≤ 0.0375 → B.
    lab = hand_label(surface([0, 1, 0], [0, 0, -1], 0.12, 0.075), CFG)
    assert lab.aligned == "short" and lab.grasp_class == GraspClass.B
    # Short axis = n × l = (0,0,−1) × (0,1,0) = (1, 0, 0): already along +X.
    assert lab.x_axis_cam == pytest.approx([1, 0, 0])


def test_axis_at_30_degrees():
    # Long axis at 30° to X in a level face: θ1 = 30°, θ2 = 60° → align the long side.
    a = np.radians(30)
    lab = hand_label(surface([np.cos(a), np.sin(a), 0], [0, 0, -1], 0.145, 0.100), CFG)
    assert (lab.theta1_deg, lab.theta2_deg) == pytest.approx((30.0, 60.0))
    assert lab.aligned == "long"
    # Half-width along Y: 0.046 ≤ 0.050 → B.
    assert lab.grasp_class == GraspClass.B
    # 0.088 m wide: 0.046 > 0.044 → one cup only.
    narrow = hand_label(surface([np.cos(a), np.sin(a), 0], [0, 0, -1], 0.145, 0.088), CFG)
    assert narrow.grasp_class == GraspClass.L


def test_face_too_small_is_ng():
    # 0.05 × 0.02 m: one cup needs 0.011 m of half-width, the face has 0.010 m → NG.
    lab = hand_label(surface([1, 0, 0], [0, 0, -1], 0.05, 0.02), CFG)
    assert lab.grasp_class == GraspClass.NG and lab.reason == "too_small"


def test_area_ratio_rejects_a_face_barely_larger_than_a_cup():
    # 0.023 × 0.0135 m: a cup fits geometrically? half-widths 0.0115, 0.00675 < 0.011 → no.
    # 0.024 × 0.024: fits (0.012 ≥ 0.011); area 5.76e-4 ≥ 1.2 × 2.545e-4 = 3.05e-4 → L.
    assert hand_label(surface([1, 0, 0], [0, 0, -1], 0.024, 0.024), CFG).grasp_class == GraspClass.L
    strict = dataclasses.replace(CFG, min_area_ratio=2.5)  # 2.5 × 2.545e-4 = 6.36e-4 > 5.76e-4 → NG
    assert (
        hand_label(surface([1, 0, 0], [0, 0, -1], 0.024, 0.024), strict).grasp_class
        == GraspClass.NG
    )


def test_tilted_face_picks_the_higher_camera():
    # Face tilted 30° about camera X, facing up in the image: n = (0, −0.5, −0.866), centre at
    # z = 0.55 m, long side along X, 0.06 m wide → one cup. Target Z = −n, X = (1, 0, 0),
    # Y = Z × X = (0, 0.866, −0.5). O_B = c + 0.15 n = (0, −0.075, 0.42010).
    # L: O_B + 0.035 Y = (0, −0.04469, 0.40260); R: O_B − 0.035 Y = (0, −0.10531, 0.43760).
    # L's camera is higher (smaller z in the home camera frame) → L.
    s = surface([1, 0, 0], [0, -0.5, -np.sqrt(3) / 2], 0.12, 0.06, center=(0, 0, 0.55))
    assert camera_centre(s, np.array([1.0, 0, 0]), GraspClass.L, CFG) == pytest.approx(
        [0, -0.044689, 0.402596], abs=1e-6
    )
    assert camera_centre(s, np.array([1.0, 0, 0]), GraspClass.R, CFG) == pytest.approx(
        [0, -0.105311, 0.437596], abs=1e-6
    )
    assert hand_label(s, CFG).grasp_class == GraspClass.L
    # Tilted the other way, R's camera is the higher one.
    s2 = surface([1, 0, 0], [0, 0.5, -np.sqrt(3) / 2], 0.12, 0.06, center=(0, 0, 0.55))
    assert hand_label(s2, CFG).grasp_class == GraspClass.R


def test_target_axes_right_handed():
    R = target_camera_pose(
        np.array([0, 0, 0.55]), np.array([0, -0.5, -np.sqrt(3) / 2]), np.array([1.0, 0, 0]), "B"
    )[:3, :3]
    assert R[:, 2] == pytest.approx([0, 0.5, np.sqrt(3) / 2])
    assert R[:, 1] == pytest.approx([0, np.sqrt(3) / 2, -0.5])
    assert np.linalg.det(R) == pytest.approx(1.0)


# --- Hold check (hand.hold_check): the labels' pattern must hold the box's weight -------------
# A medium box (0.145 × 0.092 × 0.052 m, 400 kg/m³: m = 0.27747 kg, m g = 2.7220 N at
# g = 9.81) shows its 0.092 × 0.052 m end face, the face normal tilted by t from the camera's
# -z about the camera's x. The camera looks straight down (T_world_cam: x, -y, -z), so gravity
# in the camera frame is (0, 0, +g). One cup (L) on the face centre c; the centre of mass lies
# 0.145 / 2 = 0.0725 m behind it, along -n. With n = (0, sin t, -cos t):
#   pull f = m g cos t, f_N = V - f = 12.7 - 2.722 cos t (N);
#   tau = (com - c) × F = -0.0725 n × (0, 0, m g) = -0.0725 m g (sin t, 0, 0): no torsion
#   (tau . a = 0), bending |tau| / r = 0.0725 × 2.722 sin t / 0.009 = 21.93 sin t (N).
#   t = 20°: 7.50 N ≤ f_N = 10.14 N → holds; t = 35°: 12.58 N > f_N = 10.47 N → drops.
def _tilted_end_face(tilt_deg):
    from pipeline.dataset.scenes import Box

    t = np.radians(tilt_deg)
    n = np.array([0.0, np.sin(t), -np.cos(t)])
    c = np.array([0.0, 0.0, 0.5])
    surf = surface([1, 0, 0], n, 0.092, 0.052, center=c)
    T_cam_box = np.eye(4)
    T_cam_box[:3, 3] = c - 0.0725 * n
    box = Box(
        instance=1,
        type_index=1,
        type_name="medium",
        size=np.array([0.145, 0.092, 0.052]),
        T_world_box=np.eye(4),
        T_cam_box=T_cam_box,
    )
    T_world_cam = np.diag([1.0, -1.0, -1.0, 1.0])
    T_world_cam[2, 3] = 0.625
    return surf, box, T_world_cam


@pytest.mark.parametrize("tilt_deg, holds", [(0.0, True), (20.0, True), (35.0, False)])
def test_hold_check_one_cup_on_a_tilted_end_face(tilt_deg, holds):
    from conftest import composed

    from pipeline.grasping.suction import suction_model_config
    from pipeline.labelling.scene import pattern_holds

    suction = suction_model_config(composed(), 400.0)
    assert (suction.vacuum_force, suction.cup_radius, suction.gravity) == pytest.approx(
        (12.7, 0.009, 9.81)
    )
    surf, box, T_world_cam = _tilted_end_face(tilt_deg)
    lab = dataclasses.replace(hand_label(surf, CFG), grasp_class=GraspClass.L)
    assert pattern_holds(surf, lab, box, T_world_cam, suction, CFG.cup_offset) is holds
    # the same face of a lighter box (100 kg/m³: m g = 0.6805 N) holds at 35° too: bending
    # 0.0725 × 0.6805 × 0.5736 / 0.009 = 3.14 N ≤ f_N = 12.7 - 0.6805 × 0.8192 = 12.14 N
    light = suction_model_config(composed(), 100.0)
    assert pattern_holds(surf, lab, box, T_world_cam, light, CFG.cup_offset)


@pytest.mark.parametrize("tolerance, holds", [(0.0, True), (0.032, True), (0.034, False)])
def test_hold_check_with_the_cup_landing_off_its_point(tolerance, holds):
    """``hand.hold_landing_tolerance``: one cup on the level end face of a medium box (400
    kg/m³: m = 400 × 0.145 × 0.092 × 0.052 = 0.27747 kg, m g = 2.7220 N), shifted sideways by
    d. Level, the weight is along the axis: no shear, no torsion; f_N = 12.7 − 2.7220 =
    9.9780 N and bending = d m g / r ≤ f_N holds up to d = 9.9780 × 0.009 / 2.7220 = 33.0 mm,
    in every direction of the plane (the diagonals too)."""
    from conftest import composed

    from pipeline.grasping.suction import suction_model_config
    from pipeline.labelling.scene import pattern_holds

    suction = suction_model_config(composed(), 400.0)
    surf, box, T_world_cam = _tilted_end_face(0.0)
    lab = dataclasses.replace(hand_label(surf, CFG), grasp_class=GraspClass.L)
    ok = pattern_holds(surf, lab, box, T_world_cam, suction, CFG.cup_offset, tolerance)
    assert ok is holds


def test_landing_shifts_by_hand():
    """None first, then 8 shifts of the tolerance's length, 45° apart in the x-y plane."""
    from pipeline.labelling.scene import landing_shifts

    x, y = np.array([1.0, 0, 0]), np.array([0, 1.0, 0])
    assert landing_shifts(x, y, 0.0).tolist() == [[0.0, 0.0, 0.0]]
    s = landing_shifts(x, y, 0.01)
    assert s.shape == (9, 3)
    np.testing.assert_allclose(s[0], 0.0)
    np.testing.assert_allclose(np.linalg.norm(s[1:], axis=1), 0.01)
    np.testing.assert_allclose(s[1], [0.01, 0, 0], atol=1e-15)
    np.testing.assert_allclose(s[2], [0.01 / np.sqrt(2), 0.01 / np.sqrt(2), 0], atol=1e-15)
    np.testing.assert_allclose(s[3], [0, 0.01, 0], atol=1e-15)
    np.testing.assert_allclose(s[5], [-0.01, 0, 0], atol=1e-15)


def test_a_blocked_b_falls_back_on_one_cup_by_hand():
    """``robot_level_class``: B passes → B; B blocked ("collision") with L passing → L; L
    failing its hold test and R passing → R; both blocked → NG with B's reason; no fallback
    → NG. ``single_cup_order``: on a face tilted 20° about the camera's x axis (its +y side
    nearer the camera), the hand's Y runs along the tilt, so one camera sits higher: that
    pattern comes first; a level face ties and L comes first; an L has no fallback."""
    from pipeline.grasping.hand import HandLabel
    from pipeline.labelling.scene import robot_level_class, single_cup_order

    b = HandLabel(GraspClass.B, np.array([1.0, 0, 0]), 0.0, 90.0, "long")
    L, R = GraspClass.L, GraspClass.R

    def check(blocked):
        return lambda h: "collision" if h.grasp_class in blocked else None

    def holds(failing=()):
        return lambda h: h.grasp_class not in failing

    assert robot_level_class(b, check(()), holds(), (L, R)) == (GraspClass.B, "")
    assert robot_level_class(b, check({GraspClass.B}), holds(), (L, R)) == (L, "")
    assert robot_level_class(b, check({GraspClass.B}), holds({L}), (L, R)) == (R, "")
    assert robot_level_class(b, check({GraspClass.B, L, R}), holds(), (L, R)) == (
        GraspClass.NG,
        "collision",
    )
    assert robot_level_class(b, check({GraspClass.B}), holds(), ()) == (GraspClass.NG, "collision")
    hand = CFG
    level = surface((1.0, 0, 0), (0, 0, -1.0), 0.145, 0.092)
    lab = hand_label(level, hand)
    assert lab.grasp_class == GraspClass.B and single_cup_order(level, lab, hand) == (L, R)
    t = np.radians(20)
    tilted = surface((1.0, 0, 0), (0, np.sin(t), -np.cos(t)), 0.145, 0.092)
    lab = hand_label(tilted, hand)
    z_l, z_r = (camera_centre(tilted, lab.x_axis_cam, c, hand)[2] for c in (L, R))
    assert abs(z_l - z_r) > hand.tie_tolerance
    assert single_cup_order(tilted, lab, hand) == ((R, L) if z_r < z_l else (L, R))
    assert single_cup_order(level, dataclasses.replace(lab, grasp_class=L), hand) == ()
