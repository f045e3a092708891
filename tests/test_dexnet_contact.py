"""The Dex-Net-style suction contact model (pipeline.dexnet.contact) on hand-built scenes.

Camera: 120 x 120 px, fx = fy = 150, principal point (59.5, 59.5); one pixel is 3.3 mm at 0.5 m.
"Looking down" scenes: gravity along camera +z, boxes lie on a floor 0.55 m away, box tops at
z = 0.5 m. "Looking sideways" scenes: gravity along camera +y (image down), the box faces the
camera at z = 0.5 m in front of a wall at 1 m. Depth and mask are ray-cast per pixel by
``_render`` below, independently of the code under test.

Defaults used in the hand computations: cup radius r = 9 mm, vacuum V = 12.7 N, mu = 0.5,
compliance 3 mm, g = 9.81, density 400 kg/m^3; so the limits at zero pull are shear
mu V = 6.35 N, torsion r mu V = 0.05715 N m, bending r V = 0.1143 N m.
"""

from __future__ import annotations

from dataclasses import replace
from types import SimpleNamespace as NS

import numpy as np
import pytest
from conftest import default_config

from pipeline.camera.geometry import Intrinsics
from pipeline.dexnet.contact import REASONS, BoxScene, evaluate_contacts, robust_quality
from pipeline.grasping.suction import SuctionModelConfig

INTR = Intrinsics(120, 120, 150.0, 150.0, 59.5, 59.5)
CFG = default_config(SuctionModelConfig)
DOWN = np.array([0.0, 0.0, 1.0])  # gravity, camera looking down
SIDEWAYS = np.array([0.0, 1.0, 0.0])  # gravity, camera looking horizontally
Z_AXIS = np.array([0.0, 0.0, 1.0])
TOP = 0.5  # z of the faces facing the camera
FLOOR = 0.55
BIG = (0.145, 0.092, 0.05)  # half extents 72.5 x 46 mm in the image plane


def _box(size, centre, yaw_deg: float = 0.0) -> NS:
    """A box with the given edge lengths (m), centre (camera frame, m), rotated about camera z."""
    c, s = np.cos(np.radians(yaw_deg)), np.sin(np.radians(yaw_deg))
    T = np.eye(4)
    T[:3, :3] = [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]
    T[:3, 3] = centre
    return NS(size=np.asarray(size, dtype=float), T_cam_box=T)


def _on_floor(size, x: float = 0.0, y: float = 0.0, yaw_deg: float = 0.0) -> NS:
    """A box resting on the floor (camera looking down): its top at z = FLOOR - height."""
    return _box(size, (x, y, FLOOR - size[2] / 2), yaw_deg)


def _render(boxes, background_z: float) -> tuple[np.ndarray, np.ndarray]:
    """Noise-free z-depth (m) and instance mask of the boxes in front of a plane at background_z
    (mask 0 there): each pixel's ray is intersected with each box (slab method, box frame)."""
    u, v = np.meshgrid(np.arange(INTR.width, dtype=float), np.arange(INTR.height, dtype=float))
    rays = np.stack([(u - INTR.cx) / INTR.fx, (v - INTR.cy) / INTR.fy, np.ones_like(u)], -1)
    depth = np.full(u.shape, background_z)
    mask = np.zeros(u.shape, dtype=np.uint8)
    for k, box in enumerate(boxes, start=1):
        R, t = box.T_cam_box[:3, :3], box.T_cam_box[:3, 3]
        origin, dirs, half = -t @ R, rays @ R, box.size / 2
        with np.errstate(divide="ignore", invalid="ignore"):
            lo, hi = (-half - origin) / dirs, (half - origin) / dirs
        enter = np.nanmax(np.minimum(lo, hi), axis=-1)  # ray z = 1: parameter = z-depth
        leave = np.nanmin(np.maximum(lo, hi), axis=-1)
        hit = (enter <= leave) & (enter > 0) & (enter < depth)
        depth[hit], mask[hit] = enter[hit], k
    return depth.astype(np.float32), mask


def _evaluate(boxes, points, axes=None, gravity=DOWN, background_z=FLOOR, cfg=CFG):
    depth, mask = _render(boxes, background_z)
    points = np.atleast_2d(np.asarray(points, dtype=float))
    axes = np.tile(Z_AXIS, (len(points), 1)) if axes is None else np.atleast_2d(axes)
    return evaluate_contacts(points, axes, BoxScene(depth, mask, INTR, gravity, boxes), cfg)


def _reasons(result) -> list[str]:
    return [REASONS[c] for c in result.reason]


def test_centre_of_large_flat_face_seals_and_holds():
    # Rim at 9 mm from the centre, well inside the 72.5 x 46 mm half extents; all rim heights
    # equal (level face); m = 400 x 0.145 x 0.092 x 0.05 = 0.2668 kg, weight 2.617 N along a:
    # f_N = 12.7 - 2.617 = 10.08 N > 0, no shear, c - x = (0, 0, 0.025) parallel to F: no torque.
    res = _evaluate([_on_floor(BIG)], [0.0, 0.0, TOP])
    assert res.seal.tolist() == [True] and res.wrench_ok.tolist() == [True]
    assert _reasons(res) == ["ok"] and res.instance.tolist() == [1]
    for field in (res.seal, res.wrench_ok, res.reason, res.instance):
        assert field.shape == (1,)


@pytest.mark.parametrize(
    "point, case",
    [
        ((0.0705, 0.0, TOP), "2 mm inside the +x edge: the rim reaches x = 79.5 mm > 72.5 mm"),
        ((0.0705, 0.044, TOP), "2 mm inside the corner in x and y"),
    ],
)
def test_edges_and_corners_do_not_seal(point, case):
    res = _evaluate([_on_floor(BIG)], point)
    assert res.seal.tolist() == [False] and res.wrench_ok.tolist() == [False], case
    assert _reasons(res) == ["off_face"], case
    assert res.instance.tolist() == [1], case


def test_face_smaller_than_cup_does_not_seal():
    # 15 x 15 mm face: half extent 7.5 mm < 9 mm rim radius, every rim line misses the box.
    res = _evaluate([_on_floor((0.015, 0.015, 0.05))], [0.0, 0.0, TOP])
    assert res.seal.tolist() == [False] and _reasons(res) == ["off_face"]


def test_bin_floor_is_not_on_a_box():
    # (0.12, 0, 0.55) is on the floor, 47.5 mm beyond the box's +x edge; the line along +z
    # meets no box.
    res = _evaluate([_on_floor(BIG)], [0.12, 0.0, FLOOR])
    assert _reasons(res) == ["not_on_box"] and res.instance.tolist() == [0]
    assert not res.seal[0] and not res.wrench_ok[0]
    empty = _evaluate([], [0.0, 0.0, TOP])
    assert _reasons(empty) == ["not_on_box"]


@pytest.mark.parametrize(
    "tilt_deg, expected",
    [
        (5.0, "ok"),  # spread 2 r tan 5 deg = 1.57 mm <= 3 mm
        (30.0, "uneven"),  # spread 2 r tan 30 deg = 10.39 mm > 3 mm
    ],
)
def test_tilted_approach_on_a_level_face(tilt_deg, expected):
    t = np.radians(tilt_deg)
    axis = [np.sin(t), 0.0, np.cos(t)]
    res = _evaluate([_on_floor(BIG)], [0.0, 0.0, TOP], axes=axis)
    assert _reasons(res) == [expected]
    assert res.seal[0] == (expected == "ok")


def test_box_lying_on_the_seal_area_occludes_it():
    # A 30 x 30 x 4 mm box lies on the big box's top, over x in [5, 35] mm. The centre line
    # (x = 0) misses it, so the big box is the target; the rim point (9, 0, 500) mm projects to
    # u = 59.5 + 150 x 0.009 / 0.5 = 62.2 -> pixel 62, whose ray meets the thin box at
    # x = 2.5 / 150 x 0.496 = 8.3 mm: mask 2 there, not the target's 1.
    boxes = [_on_floor(BIG), _box((0.03, 0.03, 0.004), (0.020, 0.0, TOP - 0.002))]
    res = _evaluate(boxes, [0.0, 0.0, TOP])
    assert _reasons(res) == ["occluded"] and res.instance.tolist() == [1]
    assert not res.seal[0] and not res.wrench_ok[0]
    # On the thin box itself (the first box along the line): its 15 mm half extents hold the
    # rim, nothing lies on it, and it weighs 400 x 3.6e-6 = 1.4 g.
    top = _evaluate(boxes, [0.020, 0.0, TOP - 0.004])
    assert _reasons(top) == ["ok"] and top.instance.tolist() == [2]


def test_rotated_box_uses_its_own_frame():
    # The big box turned 30 deg about the optical axis. 2 mm inside its own +x edge the rim
    # leaves the face; in image-aligned terms that point (61.1, 35.3) mm and the rim around it
    # would still lie inside +-72.5 x +-46 mm, so this needs the box frame. 15 mm inside: seals,
    # but 57.5 mm from the COM the weight's torque 0.0575 x 2.617 = 0.1505 N m exceeds the
    # bending limit r f_N = 0.009 x 10.08 = 0.0907 N m (level-face grasps on this 0.27 kg box
    # hold only within 0.0907 / 2.617 = 34.7 mm of the centre). 30 mm from the centre: holds.
    box = _on_floor(BIG, yaw_deg=30.0)
    x_axis = box.T_cam_box[:3, 0]
    points = [[0.0, 0.0, TOP] + d * x_axis for d in (0.0575, 0.0705, 0.030)]
    res = _evaluate([box], points)
    assert res.seal.tolist() == [True, False, True]
    assert _reasons(res) == ["bending", "off_face", "ok"]


def test_heavy_box_pulls_off():
    # Density 4000: m = 4000 x 0.145 x 0.092 x 0.05 = 2.668 kg, weight 26.17 N along the axis:
    # f_N = 12.7 - 26.17 = -13.47 N < 0.
    res = _evaluate([_on_floor(BIG)], [0.0, 0.0, TOP], cfg=replace(CFG, density=4000.0))
    assert res.seal.tolist() == [True] and res.wrench_ok.tolist() == [False]
    assert _reasons(res) == ["pull"]


def test_side_face_far_from_the_com_bends():
    # Camera looking sideways at the 60 x 60 mm end of a 60 x 60 x 200 mm box (COM 0.1 m behind
    # the face). m = 400 x 7.2e-4 = 0.288 kg, F = (0, 2.825, 0) N, perpendicular to a = +z:
    # f_pull = 0, f_N = 12.7 N; shear 2.825 <= 6.35 N.
    # tau = (c - x) x F = (0, 0, 0.1) x (0, 2.825, 0) = (-0.2825, 0, 0) N m:
    # torsion tau . a = 0; bending 0.2825 > r f_N = 0.1143 N m.
    box = _box((0.06, 0.06, 0.20), (0.0, 0.0, TOP + 0.10))
    res = _evaluate([box], [0.0, 0.0, TOP], gravity=SIDEWAYS, background_z=1.0)
    assert res.seal.tolist() == [True] and _reasons(res) == ["bending"]


def test_side_face_shear_and_torsion():
    # A 200 x 60 x 10 mm plate facing the sideways camera (COM 5 mm behind the face).
    plate = _box((0.20, 0.06, 0.01), (0.0, 0.0, TOP + 0.005))
    # Density 2000: m = 0.24 kg, F = (0, 2.354, 0) N; shear 2.354 <= 6.35 N. Grasped 80 mm off
    # centre along x: tau = (-0.08, 0, 0.005) x F = (-0.0118, 0, -0.1883) N m;
    # torsion |tau . a| = 0.1883 > r mu f_N = 0.05715 N m.
    res = _evaluate(
        [plate],
        [0.08, 0.0, TOP],
        gravity=SIDEWAYS,
        background_z=1.0,
        cfg=replace(CFG, density=2000.0),
    )
    assert _reasons(res) == ["torsion"]
    # Density 6000, at the centre: F = 7.063 N across the axis > mu f_N = 6.35 N.
    res = _evaluate(
        [plate],
        [0.0, 0.0, TOP],
        gravity=SIDEWAYS,
        background_z=1.0,
        cfg=replace(CFG, density=6000.0),
    )
    assert _reasons(res) == ["shear"]


def test_wrench_ok_implies_seal_on_a_batch():
    boxes = [_on_floor(BIG), _box((0.03, 0.03, 0.004), (0.020, 0.0, TOP - 0.002))]
    points = [
        [0.0, 0.0, TOP],
        [0.0705, 0.0, TOP],
        [0.12, 0.0, FLOOR],
        [-0.03, 0.0, TOP],
        [0.020, 0.0, TOP - 0.004],
    ]
    res = _evaluate(boxes, points)
    assert _reasons(res) == ["occluded", "off_face", "not_on_box", "ok", "ok"]
    assert res.instance.tolist() == [1, 1, 0, 1, 2]
    assert not np.any(res.wrench_ok & ~res.seal)


def test_robust_quality():
    boxes = [_on_floor(BIG)]
    depth, mask = _render(boxes, FLOOR)
    # Centre of the face: shifts of ~2 mm keep the rim on it; a tilt seals up to
    # atan(3 / 18) = 9.5 deg, exceeded by |N(0, 5 deg)| with probability 5.9 %, so q ~ 0.94.
    # 1 mm inside the edge the rim overhangs by 8 mm = 4 sigma of the shift: q ~ 0.
    points = np.array([[0.0, 0.0, TOP], [0.0715, 0.0, TOP], [0.12, 0.0, FLOOR]])
    axes = np.tile(Z_AXIS, (3, 1))
    scene = BoxScene(depth, mask, INTR, DOWN, boxes)

    def quality(seed: int) -> np.ndarray:
        return robust_quality(points, axes, scene, CFG, np.random.default_rng(seed))

    q = quality(0)
    assert q.shape == (3,) and np.all((q >= 0.0) & (q <= 1.0))
    assert q[0] >= 0.8 and q[1] <= 0.1 and q[2] == 0.0
    np.testing.assert_array_equal(q, quality(0))
    assert robust_quality(points[:0], axes[:0], scene, CFG, np.random.default_rng(0)).shape == (0,)
