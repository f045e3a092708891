"""The robot side decides from observations alone: the heap model, the retry memory and the
planner interface, by hand, on depth images drawn without a simulated world."""

from __future__ import annotations

import dataclasses
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from pipeline.camera.geometry import Intrinsics, camera_pose_above_bin, pose_matrix
from pipeline.camera.raycast import BoxShape, raycast_boxes
from pipeline.controller.heap_model import (
    HeapCollider,
    HeapModel,
    HeapModelConfig,
    agreeing_neighbours,
    build_heightmap,
    fill_unknown,
    plane_surface,
)
from pipeline.controller.observation import Observation
from pipeline.controller.planning import Grasp, PlannerError, checked_grasps, load_plugin

REPO = Path(__file__).resolve().parents[1]
INTR = Intrinsics(416, 416, 411.7, 411.7, 207.5, 207.5)
HOME = camera_pose_above_bin(0.625)
BIN = SimpleNamespace(inner_length_x=0.40, inner_width_y=0.30)
HEAP = HeapModelConfig(
    cell_m=0.005, bin_tolerance_m=0.004, flying_tolerance_m=0.01, flying_min_neighbours=4
)


def observe(boxes, T=HOME) -> Observation:
    """The home camera's depth of the bin floor (z = 0, 1 m around) and ``boxes``, each
    ((x, y, z) centre, (a, b, c) size), axis-aligned: a depth image drawn by ray casting alone."""
    shapes = [BoxShape(0, pose_matrix([0, 0, -0.01], [0, 0, 0, 1]), np.array([1.0, 1.0, 0.01]))]
    for k, (c, size) in enumerate(boxes, start=1):
        shapes.append(BoxShape(k, pose_matrix(c, [0, 0, 0, 1]), np.asarray(size) / 2))
    depth, _ = raycast_boxes(shapes, INTR, T, 0.1, 2.0)
    return Observation(depth.astype(np.float32), INTR, T, np.zeros(7))


# ------------------------------------------------------------------------------ heap model
def test_unknown_cells_take_their_highest_known_neighbour():
    """A 3 x 4 map known only at (0, 0) = 1 and (2, 3) = 5. First ring: (0, 1), (1, 0), (1, 1)
    touch (0, 0) only and take 1; (1, 2), (1, 3), (2, 2) take 5. Second ring: (0, 2), (0, 3)
    and (2, 1) touch a 5 and take it, (2, 0) touches only 1s."""
    h = np.zeros((3, 4))
    h[0, 0], h[2, 3] = 1.0, 5.0
    known = np.zeros((3, 4), bool)
    known[0, 0] = known[2, 3] = True
    filled = fill_unknown(h, known)
    np.testing.assert_array_equal(filled, [[1, 1, 5, 5], [1, 1, 5, 5], [1, 5, 5, 5]])
    assert (fill_unknown(h, np.zeros_like(known)) == 0).all()


def test_heightmap_of_a_box_by_hand():
    """A 145 x 92 x 52 mm box at (0.05, −0.03): the cells inside its top read 52 mm (the
    camera sees the top; its sides lean away from the camera at the image centre), the floor
    0; the cells under the walls' 4 mm band hold no point of the image's walls (none drawn),
    and every cell is filled."""
    obs = observe([((0.05, -0.03, 0.026), (0.145, 0.092, 0.052))])
    m = build_heightmap(obs, BIN, HEAP)
    assert m.shape == (60, 80)
    centres = m.centres()
    inside = (np.abs(centres[..., 0] - 0.05) < 0.0725 - 0.005) & (
        np.abs(centres[..., 1] + 0.03) < 0.046 - 0.005
    )
    outside = (np.abs(centres[..., 0] - 0.05) > 0.0725 + 0.005) | (
        np.abs(centres[..., 1] + 0.03) > 0.046 + 0.005
    )
    np.testing.assert_allclose(m.heights[inside], 0.052, atol=1e-4)
    assert (m.heights[outside] == 0).all()
    assert inside.sum() > 200 and outside.sum() > 3000


def test_agreeing_neighbours_by_hand():
    """A 4 x 4 plane at 0.60 m, a step to 0.50 m in its right column, a spike of 0.55 m at
    (1, 1), rows and columns beyond the border replicating the image's own. The spike agrees
    with none of its 8 neighbours (all 5 cm away); (1, 0) on the plane with all but the spike
    (its 3 left neighbours are the border's copies of column 0)."""
    d = np.full((4, 4), 0.60)
    d[:, 3] = 0.50
    d[1, 1] = 0.55
    n = agreeing_neighbours(d, 0.01)
    assert n[1, 1] == 0
    assert n[1, 0] == 7
    # (0, 2): neighbours (-1, 1..3) replicate row 0 = 0.60, 0.60, 0.50; (0, 1) 0.60, (0, 3)
    # 0.50; (1, 1) the spike, (1, 2) 0.60, (1, 3) 0.50: agreeing 0.60s = 4
    assert n[0, 2] == 4
    # the step column: (2, 3) has (1, 3), (3, 3) and the 3 replicated to its right: 5
    assert n[2, 3] == 5
    d[3, 0] = 0.0  # no depth: no agreement, and it agrees with nobody
    assert agreeing_neighbours(d, 0.01)[3, 0] == 0
    # (2, 0) loses (3, 0) and its copy beyond the left border, (3, -1): 7 - 2
    assert n[2, 0] == 7 and agreeing_neighbours(d, 0.01)[2, 0] == 5


def test_flying_pixels_beside_a_box_are_dropped_not_its_faces():
    """Mixed pixels along one edge of the box of the test above (depths halfway between its top
    and the floor, alternating a little as a real camera's do) would stand as columns beside it;
    the flying-pixel step drops them, and leaves the ideal image's model as it was."""
    box = [((0.05, -0.03, 0.026), (0.145, 0.092, 0.052))]
    obs = observe(box)
    clean = build_heightmap(obs, BIN, HEAP)
    off = HeapModelConfig(0.005, 0.004, 0.0, 4)
    np.testing.assert_array_equal(clean.heights, build_heightmap(obs, BIN, off).heights)
    depth = obs.depth_m.copy()
    top, floor = float(depth.min()), float(depth.max())
    rows = np.nonzero((depth[:, :-1] < top + 1e-3) & (depth[:, 1:] > floor - 0.02))
    assert len(rows[0]) > 20  # the box's right edge, one pixel per image row
    u = rows[1] + 1  # the first floor pixel right of the top
    depth[rows[0], u] = top + (floor - top) * np.where(rows[0] % 2, 0.3, 0.6)
    mixed = dataclasses.replace(obs, depth_m=depth)
    assert build_heightmap(mixed, BIN, off).heights.max() > 0.052 - 1e-4  # columns: as high
    raised = build_heightmap(mixed, BIN, off).heights > clean.heights + 0.005
    assert raised.sum() >= 5  # cells beside the edge stand up without the step
    np.testing.assert_array_equal(build_heightmap(mixed, BIN, HEAP).heights, clean.heights)


def test_the_grasped_surface_is_left_out():
    """The box's top as the grasped region: its cells fall to the floor (its edge cells too:
    their other points are the floor's), and the cube's stay; half the top (x < 0) as the
    region leaves the other half standing."""
    obs = observe(
        [((0.0, 0.0, 0.026), (0.145, 0.092, 0.052)), ((0.12, 0.09, 0.05), (0.06, 0.06, 0.10))]
    )
    model = HeapModel(BIN, HEAP)
    m = model.update(obs)
    top = np.abs(obs.depth_m - (0.625 - 0.052)) < 1e-4
    without = model.heights_without(top)
    rows, cols = m.cell_of(np.array([[0.0, 0.0], [0.12, 0.09], [0.05, 0.0], [-0.05, 0.0]]))
    assert m.heights[rows[0], cols[0]] == pytest.approx(0.052, abs=1e-4)
    assert without[rows[0], cols[0]] == 0.0  # the top's cell: nothing else in it
    assert without[rows[1], cols[1]] == pytest.approx(0.10, abs=1e-4)  # the cube stays
    assert (without[m.heights == pytest.approx(0.052, abs=1e-4)] == 0).all()
    half = model.heights_without(top & (np.arange(416)[None, :] < 207))
    assert half[rows[2], cols[2]] == pytest.approx(0.052, abs=1e-4)  # x = +0.05: kept
    assert half[rows[3], cols[3]] == 0.0  # x = −0.05: left out
    assert model.heights_without(None) is m.heights


def test_the_rest_of_the_grasped_face_joins_its_region_through_its_plane():
    """``plane_surface``: the medium box's top (z = 0.052, 0.625 m below the home camera, so
    0.573 m from it along the camera's axis, normal (0, 0, -1) in the camera frame) with half
    of it as the region. With a 5 mm tolerance the other half joins (its points lie on the
    plane), a patch raised by 3 mm (a sensor's noise) joins too, and the cube's top 48 mm higher
    and the floor 52 mm lower do not, nor a patch of the face raised by 8 mm (a real obstacle's
    height above it). With a 2 mm tolerance the 3 mm patch stays out too. The model without
    that surface drops the cells of the region's other half, which the region alone keeps."""
    obs = observe(
        [((0.0, 0.0, 0.026), (0.145, 0.092, 0.052)), ((0.12, 0.09, 0.05), (0.06, 0.06, 0.10))]
    )
    depth = obs.depth_m.copy()
    top = np.abs(depth - 0.573) < 1e-4
    cols = np.arange(416)[None, :]
    raised_3mm = top & (np.arange(416)[:, None] < 195) & (cols > 240) & (cols < 250)
    raised_8mm = top & (np.arange(416)[:, None] > 220) & (cols > 240) & (cols < 250)
    depth[raised_3mm] -= 0.003
    depth[raised_8mm] -= 0.008
    obs = dataclasses.replace(obs, depth_m=depth)
    region = top & (cols < 207)
    centre, normal = np.array([0.0, 0.0, 0.573]), np.array([0.0, 0.0, -1.0])
    surface = plane_surface(obs, region, centre, normal, 0.005)
    assert surface[top & ~raised_8mm].all()  # the whole face, the 3 mm patch included
    assert not surface[raised_8mm].any()
    assert not surface[~top].any()  # neither the cube, nor the floor, nor the face's sides
    tight = plane_surface(obs, region, centre, normal, 0.002)
    assert (tight == (top & ~raised_3mm & ~raised_8mm)).all()
    model = HeapModel(BIN, HEAP)
    m = model.update(obs)
    rows, cols_ = m.cell_of(np.array([[0.05, 0.0]]))
    assert model.heights_without(region)[rows[0], cols_[0]] == pytest.approx(0.052, abs=1e-4)
    assert model.heights_without(surface)[rows[0], cols_[0]] == 0.0


def test_collider_by_hand():
    """One 5 mm cell 50 mm high at cell (2, 3) of a 6 x 8 grid from (0, 0), margin 5 mm: the
    column grows by one cell each way (x 10–25 mm, y 5–20 mm) and 5 mm up (55 mm)."""
    h = np.zeros((6, 8))
    h[2, 3] = 0.05
    c = HeapCollider(h, np.zeros(2), 0.005, 0.005)
    assert c.hits(np.array([[0.0175, 0.0125, 0.054]]))  # over the cell, inside the margin
    assert not c.hits(np.array([[0.0175, 0.0125, 0.056]]))  # above it
    assert c.hits(np.array([[0.011, 0.006, 0.01]]))  # beside it, within one grown cell
    assert not c.hits(np.array([[0.0255, 0.0125, 0.01]]))  # two cells off in x
    assert not c.hits(np.array([[-0.01, 0.0125, 0.0]]))  # off the grid: the bin's business
    assert c.may_touch((0.0, 0.0, 0.05), (0.02, 0.02, 0.1))
    assert not c.may_touch((0.0, 0.0, 0.056), (0.02, 0.02, 0.1))  # above every grown column
    assert not c.may_touch((0.03, 0.0, 0.0), (0.04, 0.03, 0.1))  # beside them


def test_surface_points_of_the_primitives_by_hand():
    """A 20 x 10 x 10 mm box sampled every 5 mm: a 5 x 3 x 3 lattice less its one interior
    point, all on the faces; a cylinder of radius 9 mm and length 25 mm: every point on its
    side (r = 9 mm) or on a cap (z = ±12.5 mm), within the radius, and no two neighbours on its
    rim more than 5 mm apart."""
    import pybullet as p

    from pipeline.controller.heap_model import surface_points

    box = surface_points(p.GEOM_BOX, [0.02, 0.01, 0.01], 0.005)
    assert len(box) == 5 * 3 * 3 - 3  # 45 lattice points, the 3 inner ones (x = −5, 0, 5 mm) off
    assert np.all(np.isclose(np.abs(box), [0.01, 0.005, 0.005]).any(axis=1))
    cyl = surface_points(p.GEOM_CYLINDER, [0.025, 0.009], 0.005)
    r = np.hypot(cyl[:, 0], cyl[:, 1])
    assert np.all(np.isclose(r, 0.009) | np.isclose(np.abs(cyl[:, 2]), 0.0125))
    assert r.max() <= 0.009 + 1e-12
    rim = cyl[np.isclose(cyl[:, 2], 0.0125) & np.isclose(r, 0.009)]
    ang = np.sort(np.arctan2(rim[:, 1], rim[:, 0]))
    assert np.max(np.diff(np.r_[ang, ang[0] + 2 * np.pi])) * 0.009 <= 0.005 + 1e-9


# ------------------------------------------------------------------------------ retry memory
def _memory(**kw):
    from pipeline.controller.retry import RetryMemory

    ev = SimpleNamespace(
        retry_policy="skip_failed",
        retry_same_point_m=0.03,
        retry_neighbour_m=0.15,
        retry_depth_change_m=0.005,
        retry_changed_area_m2=0.0005,
        retry_point_outcomes=["no_seal"],
        retry_drop_single_cup=True,
        retry_no_seal_two_cups=True,
    )
    return RetryMemory(SimpleNamespace(**{**vars(ev), **kw}))


def test_the_retry_memory_sees_the_heap_change_by_hand():
    """A failed B at the top of a box at the bin centre (P = (0, 0, 0.052)). On the same image
    it is a repeat, L there is not (a drop fails the pattern), a point 5 cm away is not. A
    6 cm cube set down with its centre 0.10 m from P changes about 40.6 cm²: its top, 36 cm²
    (at 0.565 m it spans 60 mm / (0.565 / 411.7) = 43.7 px, 43.7² px × (0.565 / 411.7)² m²),
    and its side facing the camera's axis, seen between 0.07 / 0.565 × 411.7 = 51.0 px and
    0.07 / 0.625 × 411.7 = 46.1 px from the image centre: 4.9 px × 43.7 px at about 0.6 m,
    214 px × (0.6 / 411.7)² m² = 4.6 cm². A new plan.
    The same box 0.20 m from P (> retry_neighbour_m) changes nothing near P."""
    box = ((0.0, 0.0, 0.026), (0.145, 0.092, 0.052))
    then = observe([box])
    P = np.array([0.0, 0.0, 0.052])
    mem = _memory()
    mem.remember(then, P, "B", "dropped")
    assert mem.repeats(then, P + [0.01, 0, 0], "B")
    assert not mem.repeats(then, P, "L")
    assert not mem.repeats(then, P + [0.05, 0, 0], "B")
    near = observe([box, ((0.0, 0.1, 0.03), (0.06, 0.06, 0.06))])
    area = mem.changed_area(mem.failed[0], near)
    assert area == pytest.approx(0.00406, rel=0.05)
    assert not mem.repeats(near, P, "B")
    far = observe([box, ((0.0, -0.2, 0.03), (0.06, 0.06, 0.06))])
    assert mem.changed_area(mem.failed[0], far) == 0.0
    assert mem.repeats(far, P, "B")
    # after a seal that did not form, every pattern at the point is a repeat
    mem.remember(then, P, "B", "no_seal")
    assert mem.repeats(then, P, "L") and mem.repeats(then, P, "R")
    assert not _memory(retry_policy="repeat").repeats(then, P, "B")


def test_a_one_pixel_flicker_at_depth_steps_is_no_change():
    """The box's outline one pixel wider in the new image (a sensor's flicker at a depth step:
    every step grows by a pixel, the 3 x 3 minimum of the depth): its 474 mm perimeter, about
    346 px at 1.37 mm a pixel, changes about 6.5 cm² of depth by the box's 52 mm, more than the
    5 cm² threshold, but as a band one pixel thin: no change, and the failed plan stays a repeat.
    """
    import cv2

    box = ((0.0, 0.0, 0.026), (0.145, 0.092, 0.052))
    then = observe([box])
    P = np.array([0.0, 0.0, 0.052])
    mem = _memory()
    mem.remember(then, P, "B", "collision")
    grown = cv2.erode(then.depth_m, np.ones((3, 3), np.uint8))
    flicker = Observation(grown, then.intrinsics, then.T_world_cam, then.joints)
    band = (np.abs(grown - then.depth_m) > 0.005).sum() * (0.573 / 411.7) ** 2
    assert band > 0.0005  # the band alone is over the threshold
    assert mem.changed_area(mem.failed[0], flicker) == 0.0
    assert mem.repeats(flicker, P, "B")


def test_a_box_one_cup_dropped_keeps_its_single_cups_skipped():
    """An L dropped the box at P: on the same image L and R near P are repeats, B is not; once
    a neighbour 10 cm away has moved in (36 cm² changed), L and R at P stay skipped (the box is
    as heavy as it was), a point 5 cm away is new; with the rule off, L is a new plan then."""
    box = ((0.0, 0.0, 0.026), (0.145, 0.092, 0.052))
    then = observe([box])
    changed = observe([box, ((0.0, 0.1, 0.03), (0.06, 0.06, 0.06))])
    P = np.array([0.0, 0.0, 0.052])
    for rule, after in ((True, True), (False, False)):
        mem = _memory(retry_drop_single_cup=rule)
        mem.remember(then, P, "L", "dropped")
        assert mem.repeats(then, P, "L") and mem.repeats(then, P, "R") == rule
        assert not mem.repeats(then, P, "B")
        assert mem.repeats(changed, P + [0.01, 0, 0], "L") == after
        assert mem.repeats(changed, P, "R") == after
        assert not mem.repeats(changed, P + [0.05, 0, 0], "L")


def test_two_cups_without_a_seal_keep_b_skipped():
    """B found no seal at P: on the same image every pattern near P is a repeat (no_seal is a
    point outcome); once a neighbour 10 cm away has moved in (36 cm² changed), B at P stays
    skipped (the surface has not grown), L and R are new plans, a B 5 cm away is new; with the
    rule off, B is a new plan then too."""
    box = ((0.0, 0.0, 0.026), (0.145, 0.092, 0.052))
    then = observe([box])
    changed = observe([box, ((0.0, 0.1, 0.03), (0.06, 0.06, 0.06))])
    P = np.array([0.0, 0.0, 0.052])
    for rule in (True, False):
        mem = _memory(retry_no_seal_two_cups=rule)
        mem.remember(then, P, "B", "no_seal")
        assert all(mem.repeats(then, P, k) for k in "BLR")
        assert mem.repeats(changed, P + [0.01, 0, 0], "B") == rule
        assert not mem.repeats(changed, P, "L") and not mem.repeats(changed, P, "R")
        assert not mem.repeats(changed, P + [0.05, 0, 0], "B")
    mem = _memory()
    mem.remember(then, P, "L", "no_seal")  # one cup without a seal: the plain rule
    assert not mem.repeats(changed, P, "L")


# ------------------------------------------------------------------------------ decisions
def test_the_robot_decides_from_observations_with_no_world():
    """In a fresh interpreter: a depth image drawn by ray casting (a medium box at the bin
    centre, a 14 cm tall cube beside the point of a second grasp), a scripted planner, the
    robot side's plan. The grasp on the floor beside the tall cube is rejected (the hand would
    be in the cube: the heap model has it) and the box's top is planned with both cups at its
    centre; no module of the simulated world was ever imported."""
    script = f"""
import sys, numpy as np
sys.path.insert(0, {str(REPO / "tests")!r})
from test_controller import observe, INTR
from pipeline.runtime.cli import compose
from pipeline.controller.picker import RobotController
from pipeline.controller.planning import Grasp
from pipeline.camera.geometry import project, world_to_camera
cfg = compose("evaluate", ["experiment=smoke"])
obs = observe([((0.0, 0.0, 0.026), (0.145, 0.092, 0.052)),
               ((-0.14, 0.08, 0.07), (0.06, 0.06, 0.14))])
def px(p):
    u, v = project(world_to_camera(np.asarray(p, float), obs.T_world_cam), INTR)
    return float(u), float(v)
floor, top = px([-0.14, 0.115, 0.0]), px([0.0, 0.0, 0.052])
class Scripted:
    def plan(self, observation, rng):
        return [Grasp(*floor, pattern="L"), Grasp(*top, pattern="B")]
robot = RobotController(cfg, Scripted(), "scripted")
result = robot.plan(obs, np.random.default_rng(0))
plan = result.plan
print("PATTERN", plan.pattern, "POINT", np.round(plan.point_world, 3).tolist())
print("REJECTED", sorted(result.rejected))
leaked = sorted(m for m in sys.modules if m.startswith(("pipeline.world", "pipeline.simulation",
                "pipeline.dataset", "pipeline.camera.sensor", "pipeline.labelling.scene")))
print("LEAKED", leaked)
"""
    out = subprocess.run(
        [sys.executable, "-c", script], cwd=REPO, capture_output=True, text=True, timeout=300
    )
    assert out.returncode == 0, out.stderr[-3000:]
    lines = {line.split()[0]: line for line in out.stdout.splitlines() if line[:1].isupper()}
    assert lines["PATTERN"].startswith("PATTERN B POINT [0.0, 0.0, 0.052]")
    assert "collision" in lines["REJECTED"] or "path_collision" in lines["REJECTED"]
    assert lines["LEAKED"] == "LEAKED []"


# ------------------------------------------------------------------------------ plug-ins
def test_bad_planner_answers_are_named():
    obs = observe([])
    good = [Grasp(10.0, 20.0, "B"), Grasp(3.0, 4.0, None, point_cam=np.array([0, 0, 0.5]))]
    assert checked_grasps(good, obs, "p") == good
    assert checked_grasps((), obs, "p") == []
    for bad, words in [
        (None, "NoneType, not a sequence"),
        ([(10, 20)], "item 0 of plan()'s answer is a tuple, not a Grasp"),
        ([Grasp(500.0, 20.0, "B")], "lies outside the 416 x 416 image"),
        ([Grasp(float("nan"), 20.0, "B")], "non-finite pixel"),
        ([Grasp(10.0, 20.0, "X")], "pattern 'X'"),
        ([Grasp(1.0, 2.0, None, point_cam=np.array([0, 0, -1.0]))], "point_cam"),
    ]:
        with pytest.raises(PlannerError, match=words.replace("(", r"\(").replace(")", r"\)")):
            checked_grasps(bad, obs, "p")


def test_bad_plugins_are_named(tmp_path, monkeypatch):
    (tmp_path / "my_planners.py").write_text(
        "class NoPlan:\n    def __init__(self, cfg): pass\n"
        "class WrongArgs:\n    def __init__(self, cfg): pass\n    def plan(self, obs): return []\n"
        "class Broken:\n    def __init__(self, cfg): raise RuntimeError('no model file')\n"
        "class Good:\n    def __init__(self, cfg): self.cfg = cfg\n"
        "    def plan(self, observation, rng): return []\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    assert load_plugin("my_planners:Good", "cfg").cfg == "cfg"
    cases = [
        ("no_such_module:P", "cannot import module 'no_such_module'"),
        ("my_planners:Missing", "has no 'Missing'"),
        ("my_planners:NoPlan", "has no plan\\(\\) method"),
        ("my_planners:WrongArgs", "does not take \\(observation, rng\\)"),
        ("my_planners:Broken", "failed \\(RuntimeError: no model file\\)"),
        ("nothing_registered", "unknown planner 'nothing_registered'"),
    ]
    for name, words in cases:
        with pytest.raises(PlannerError, match=words):
            load_plugin(name, "cfg")


def test_the_example_plugin_proposes_box_tops_highest_first():
    """docs/examples/centroid_planner.py on a medium box (top at 52 mm) and a tall cube (top at
    140 mm): the cube's top first, with one cup (60 mm < 2 x 44 mm), then the box's top with
    both (92 mm ≥ 88 mm), each at its centre; nothing on the floor."""
    from pipeline.runtime.cli import compose

    sys.path.insert(0, str(REPO))
    try:
        planner = load_plugin(
            "docs.examples.centroid_planner:CentroidPlanner",
            compose("evaluate", ["experiment=smoke"]),
        )
    finally:
        sys.path.remove(str(REPO))
    obs = observe(
        [((0.0, 0.0, 0.026), (0.145, 0.092, 0.052)), ((-0.14, 0.08, 0.07), (0.06, 0.06, 0.14))]
    )
    grasps = checked_grasps(planner.plan(obs, np.random.default_rng(0)), obs, "centroid")
    assert [g.pattern for g in grasps] == ["L", "B"]
    assert [round(g.score, 3) for g in grasps] == [0.14, 0.052]
    from pipeline.camera.geometry import project, world_to_camera

    for g, centre in zip(grasps, ([-0.14, 0.08, 0.14], [0.0, 0.0, 0.052])):
        u, v = project(world_to_camera(np.asarray(centre), HOME), INTR)
        assert abs(g.u - u) <= 1.5 and abs(g.v - v) <= 1.5
