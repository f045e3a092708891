"""Choosing what the robot executes: the run-time check gates every target, retries differ.

Hand-worked on one box lying flat in the middle of the bin (its top face at the image centre
is reachable with both cups) and on a pixel of the bin floor 2 cm from the +y wall. The servo
of a DCNN candidate tracks the centre of the surface the descriptor grows at its pixel, so that
is what the check tests: for the floor pixel, the floor around the box, whose centre is the bin
centre, under the box: the hand would be inside the box, a rejection.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pybullet as p
import pytest

from conftest import default_config
from pipeline.camera.geometry import project, world_to_camera
from pipeline.labelling.types import GraspClass


def _one_box_runner(smoke_cfg, name: str, size: list[float]):
    """A PickRunner whose cell holds one box of ``size`` (m) flat at the bin centre, at rest."""
    from pipeline.robot.model import robot_config
    from pipeline.world.cell import PickCell
    from pipeline.world.trial import PickRunner
    from pipeline.robot.model import Robot

    cfg = smoke_cfg("evaluate", "evaluate.boxes_per_trial=1",
                    f"eval_boxes.types=[{{name: {name}, size: {list(size)}}}]")
    cell = PickCell(cfg, lambda: Robot(robot_config(cfg)))
    calls = []
    r = PickRunner(cfg, cell, lambda d, i, rng: calls[-1] if calls else [], "test")
    r.plans = calls  # what the planner returns next: append a list of candidates
    cell.reset(np.random.default_rng(0), 1)
    (body,) = list(cell.boxes)
    p.resetBasePositionAndOrientation(body, [0, 0, size[2] / 2], [0, 0, 0, 1],
                                      physicsClientId=cell.client)
    cell.settle()
    return r


@pytest.fixture
def runner(smoke_cfg):
    r = _one_box_runner(smoke_cfg, "medium", [0.145, 0.092, 0.052])
    yield r
    r.cell.close()


@pytest.fixture
def cube_runner(smoke_cfg):
    r = _one_box_runner(smoke_cfg, "cube", [0.06, 0.06, 0.07])
    yield r
    r.cell.close()


def _pixel_of(runner, point_world):
    frame = runner.cell.render()
    u, v = project(world_to_camera(np.asarray(point_world), frame.T_world_cam),
                   runner.cell.intrinsics)
    return frame, float(u), float(v)


def test_a_reachable_target_is_chosen_and_a_rejected_one_never(runner):
    (body,) = list(runner.cell.boxes)
    frame, u, v = _pixel_of(runner, [0, 0, 0.052])  # the box's top face centre
    good = SimpleNamespace(u=u, v=v, grasp_class=GraspClass.B)
    _, wu, wv = _pixel_of(runner, [0.1, 0.13, 0.0])
    bad = SimpleNamespace(u=wu, v=wv, grasp_class=GraspClass.B)
    assert runner._target_of(frame, good)[0] == body
    assert runner._reachable(frame, good, "B", body) is not None
    assert runner._reachable(frame, bad, "B", -1) is None
    # G_opt is the rejected one: the next candidate is executed, never G_opt
    assert runner.select(frame, [bad, good], [])[:2] == (good, "B")
    # nothing passes: no grasp (the trial ends), G_opt is not run anyway
    rejected = {}
    assert runner.select(frame, [bad, bad], [], rejected) is None
    # the point on the bin floor near a corner: the hand at that pose is in the walls, with B
    # and with each single cup of the fallback (evaluate.single_cup_fallback)
    assert rejected == {"collision": 2 * 3}
    runner.plans.append([bad])
    runner.cell.reset = lambda rng, count: None  # the trial keeps this heap
    result = runner.run_trial(0, np.random.default_rng(0), np.random.default_rng(1))
    assert result.end == "no_grasp" and result.attempts == []
    # the labels on that image hold a grasp the check passes (the box's top face): the planner's
    # perception lost the box, not execution (evaluate.label_no_grasp)
    assert result.no_grasp == {"boxes_left": 1, "candidates": 1, "checked": 1,
                               "rejected": {"collision": 3}, "label_candidates": 1,
                               "label_executable": True}
    assert result.final_home == {}  # kept only with the trace (evaluate.log_trials)
    runner.plans.append([bad])
    traced = runner.run_trial(0, np.random.default_rng(0), np.random.default_rng(1),
                              keep_trace=True)
    home = traced.final_home
    assert home["depth_m"].shape == frame.depth_m.shape
    np.testing.assert_allclose(home["T_world_cam"], frame.T_world_cam, atol=1e-3)  # home, by IK
    np.testing.assert_allclose(home["candidates_px"], [[wu, wv]])
    (left,) = home["boxes_left"]
    assert left["body"] == body and left["type"] == runner.cell.boxes[body]["type"]
    np.testing.assert_allclose(left["position"], runner.cell.box_pose(body)[0])


def test_the_preferred_clearance_never_rejects_what_the_check_accepts(runner):
    """The check's first pass asks ``evaluate.preferred_bin_clearance`` from the bin on the
    servo's path, the second the labels' clearance. The box lies at the bin centre, 0.1 m and
    more from every wall: its top face passes the first pass (10 mm) with the same hand axis
    and path as the plain check. A clearance no path has (1 m) fails the first pass at every
    rotation, and the plain check still accepts the grasp."""
    from pipeline.world.trial import _with_bin_clearance

    (body,) = list(runner.cell.boxes)
    frame, u, v = _pixel_of(runner, [0, 0, 0.052])
    good = SimpleNamespace(u=u, v=v, grasp_class=GraspClass.B)
    assert runner.cfg.evaluate.preferred_bin_clearance == pytest.approx(0.01)
    assert runner._comfort_cfg.robot.path.bin_clearance == pytest.approx(0.01)
    assert runner.cfg.robot.path.bin_clearance == 0.0  # the caller's config is not changed
    comfortable = runner._reachable(frame, good, "B", body)
    runner._comfort_cfg = None
    plain = runner._reachable(frame, good, "B", body)
    np.testing.assert_allclose(comfortable.x_world, plain.x_world)
    assert len(comfortable.path) == len(plain.path)
    runner._comfort_cfg = _with_bin_clearance(runner.cfg, 1.0)
    unreachable = runner._reachable(frame, good, "B", body)
    np.testing.assert_allclose(unreachable.x_world, plain.x_world)


def test_a_retry_after_a_failure_differs(runner):
    """A failed plan (box b, pattern B, point P) is skipped while b has not moved; a different
    pattern, a point 5 cm away, or the box moved by 1 cm or turned by 10° make it a new plan."""
    (body,) = list(runner.cell.boxes)
    pos, quat = runner.cell.box_pose(body)
    P = np.array([0.0, 0.0, 0.052])
    failed = [runner.failure_record(body, "B", P)]
    assert failed[0]["neighbours"] == {}  # the box is alone in the bin
    assert runner._repeats_failure(body, "B", P + [0.01, 0, 0], failed)  # 1 cm: same plan
    assert not runner._repeats_failure(body, "L", P, failed)
    assert not runner._repeats_failure(body, "B", P + [0.05, 0, 0], failed)
    moved = [dict(failed[0], position=pos + [0.01, 0, 0])]
    assert not runner._repeats_failure(body, "B", P, moved)
    half = np.radians(10) / 2
    turned = [dict(failed[0], quat=np.array([0, 0, np.sin(half), np.cos(half)]))]
    assert not runner._repeats_failure(body, "B", P, turned)
    # the same candidate is skipped by select; with retry_policy=repeat it is chosen again
    frame, u, v = _pixel_of(runner, P)
    cand = SimpleNamespace(u=u, v=v, grasp_class=GraspClass.B)
    rejected = {}
    assert runner.select(frame, [cand], failed, rejected)[:2] == (cand, "L")  # the fallback
    assert rejected == {"repeat": 1}
    runner.cfg.evaluate.single_cup_fallback = False
    rejected = {}
    assert runner.select(frame, [cand], failed, rejected) is None
    assert rejected == {"repeat": 1}
    runner.cfg.evaluate.retry_policy = "repeat"
    assert runner.select(frame, [cand], failed)[:2] == (cand, "B")


def _add_cube(runner, xy):
    """A 6 cm cube resting on the bin floor at ``xy`` (world, m), one of the cell's boxes."""
    cell = runner.cell
    shape = p.createCollisionShape(p.GEOM_BOX, halfExtents=[0.03] * 3, physicsClientId=cell.client)
    body = p.createMultiBody(0.1, shape, basePosition=[xy[0], xy[1], 0.03],
                             physicsClientId=cell.client)
    cell.boxes[body] = {"type": "cube", "size": [0.06, 0.06, 0.06]}
    return body


def test_a_failure_at_the_point_skips_every_pattern_there(runner):
    """After a lost target or a seal that did not form (``evaluate.retry_point_outcomes``), the
    point failed, not the pattern: B, L and R there are all repeats while the heap is
    unchanged; 5 cm away is a new plan. After a drop only the dropped pattern is."""
    (body,) = list(runner.cell.boxes)
    P = np.array([0.0, 0.0, 0.052])
    assert list(runner.cfg.evaluate.retry_point_outcomes) == ["lost_target", "no_seal"]
    for outcome in ("lost_target", "no_seal"):
        failed = [{**runner.failure_record(body, "B", P), "outcome": outcome}]
        assert all(runner._repeats_failure(body, pat, P, failed) for pat in ("B", "L", "R"))
        assert not runner._repeats_failure(body, "L", P + [0.05, 0, 0], failed)
    failed = [{**runner.failure_record(body, "B", P), "outcome": "dropped"}]
    assert runner._repeats_failure(body, "B", P, failed)
    assert not runner._repeats_failure(body, "L", P, failed)


def test_a_retry_is_new_once_the_heap_around_it_changes(runner):
    """The failed plan on the medium box at the bin centre (P = its top face centre) stays
    skipped while its surroundings are as they were; a cube whose centre was 0.10 m from P
    (< retry_neighbour_m = 0.15 m) being picked, or moving 1 cm, makes it a new plan; a cube
    0.17 m away (> 0.15 m) does not count, unless it comes nearer."""
    (body,) = list(runner.cell.boxes)
    P = np.array([0.0, 0.0, 0.052])
    near = _add_cube(runner, [0.0, 0.1])  # |(0, 0.1, 0.03) - P| = 0.102 m
    far = _add_cube(runner, [0.17, 0.0])  # |(0.17, 0, 0.03) - P| = 0.171 m
    failed = [runner.failure_record(body, "B", P)]
    assert set(failed[0]["neighbours"]) == {near}
    assert runner._repeats_failure(body, "B", P, failed)
    runner.cell.remove_box(far)  # picked, but out of reach of the failed plan
    assert runner._repeats_failure(body, "B", P, failed)
    p.resetBasePositionAndOrientation(near, [0.0, 0.11, 0.03], [0, 0, 0, 1],
                                      physicsClientId=runner.cell.client)
    assert not runner._repeats_failure(body, "B", P, failed)  # the neighbour moved by 1 cm
    p.resetBasePositionAndOrientation(near, [0.0, 0.1, 0.03], [0, 0, 0, 1],
                                      physicsClientId=runner.cell.client)
    assert runner._repeats_failure(body, "B", P, failed)  # back where it was
    runner.cell.remove_box(near)  # the neighbour was picked
    assert not runner._repeats_failure(body, "B", P, failed)
    # a failure recorded with nothing near; then a box slides within 0.15 m: a new plan
    failed = [runner.failure_record(body, "B", P)]
    assert runner._repeats_failure(body, "B", P, failed)
    _add_cube(runner, [0.12, 0.0])  # 0.121 m from P
    assert not runner._repeats_failure(body, "B", P, failed)


def test_single_point_tries_the_other_cup(runner):
    """A Dex-Net-style point (no class) gets ``dexnet_pattern`` (L) first, then R; when L was
    the failed plan, R is next."""
    (body,) = list(runner.cell.boxes)
    frame, u, v = _pixel_of(runner, [0, 0, 0.052])
    point_cam = world_to_camera(np.array([0, 0, 0.052]), frame.T_world_cam)
    cand = SimpleNamespace(u=u, v=v, grasp_class=None, point_cam=point_cam)
    assert runner._patterns(cand) == ["L", "R"]
    assert runner.select(frame, [cand], [])[:2] == (cand, "L")
    failed = [runner.failure_record(body, "L", np.array([0, 0, 0.052]))]
    assert runner.select(frame, [cand], failed)[:2] == (cand, "R")


def test_a_b_that_does_not_fit_is_tried_with_one_cup(cube_runner):
    """The cube's 60 x 60 mm top face: B's cup discs (9 mm radius at ±35 mm) reach 44 mm from
    the centre, past the 30 mm half-width, so the hand-fit gate rejects B; one cup on the
    centre (9 mm <= 30 mm, area 3600 mm² >= 1.2 x 254 mm²) fits. With the single-cup fallback
    the B candidate is executed with L, and after a failed L with R; without it, nothing passes
    and the only rejection is B's fit."""
    runner = cube_runner
    (body,) = list(runner.cell.boxes)
    frame, u, v = _pixel_of(runner, [0, 0, 0.07])
    cand = SimpleNamespace(u=u, v=v, grasp_class=GraspClass.B)
    assert runner.cfg.evaluate.single_cup_fallback  # the default
    assert runner._patterns(cand) == ["B", "L", "R"]
    rejected = {}
    assert runner.select(frame, [cand], [], rejected)[:2] == (cand, "L")
    assert rejected == {"hand_fit": 1}
    failed = [runner.failure_record(body, "L", np.array([0, 0, 0.07]))]
    assert runner.select(frame, [cand], failed)[:2] == (cand, "R")
    # an L or R candidate has no fallback
    assert runner._patterns(SimpleNamespace(u=u, v=v, grasp_class=GraspClass.L)) == ["L"]
    runner.cfg.evaluate.single_cup_fallback = False
    rejected = {}
    assert runner.select(frame, [cand], [], rejected) is None
    assert rejected == {"hand_fit": 1}


def test_dexnet_alternatives_follow_the_best_by_quality():
    """``grasps_of``: the best, then the final set's others by score (ties in sampling order),
    skipping -inf and the best's pixel and repeated pixels."""
    from pipeline.dexnet.cem import CEMIteration, CEMResult
    from pipeline.dexnet.planner import grasps_of
    from pipeline.dexnet.sampling import Candidates

    uv = np.array([[10, 10], [20, 20], [30, 30], [20, 20], [40, 40]])
    n = len(uv)
    c = Candidates(uv=uv, point=np.zeros((n, 3)), axis=np.tile([0, 0, 1.0], (n, 1)),
                   depth=np.ones(n), angle=np.zeros(n))
    scores = np.array([0.9, 0.5, 0.7, 0.5, -np.inf])
    result = CEMResult(best=c.take([0]), best_score=0.9,
                       iterations=[CEMIteration(c, scores, np.array([0]))])
    assert [(g.u, g.v) for g in grasps_of(result)] == [(10, 10)]
    got = [(g.u, g.v, g.score) for g in grasps_of(result, 10)]
    assert got == [(10, 10, 0.9), (30, 30, 0.7), (20, 20, 0.5)]


def test_hand_rotations_by_hand():
    """B keeps only 0 and 180 (a quarter turn puts the cup line across the fitted axis); one cup
    keeps every angle; X turned 90° about +Z is +Y, and the normal's component is removed."""
    from pipeline.robot.target_pose import hand_rotations, rotate_about

    assert hand_rotations("B", [0, 180, 90, 270]) == [0.0, 180.0]
    assert hand_rotations("L", [0, 180, 90, -90]) == [0.0, 180.0, 90.0, 270.0]
    assert hand_rotations("B", [90]) == [0.0]
    assert rotate_about([1, 0, 0.3], [0, 0, 1], 90) == pytest.approx([0, 1, 0], abs=1e-12)
    assert rotate_about([1, 0, 0], [0, 0, 1], 180) == pytest.approx([-1, 0, 0], abs=1e-12)


def test_servo_turns_to_a_reference_axis_by_hand():
    """A level surface straight ahead (normal −Z), its long axis along camera X. Without a
    reference the rotation error is 0; with the hand's X wanted at −X (a half turn) the error is
    π about Z; wanted at +Y, −π/2 about Z... i.e. atan2(−a_y, a_x) with a = +Y: −π/2."""
    from pipeline.servo.control import ServoConfig, servo_velocity

    args = ([0, 0, 0.3], [0, 0, -1], [1, 0, 0], [0, 1, 0], "B", default_config(ServoConfig), 1 / 30)
    assert servo_velocity(*args).error[3:] == pytest.approx([0, 0, 0], abs=1e-12)
    half = servo_velocity(*args, reference_x=[-1, 0, 0]).error[3:]
    assert abs(half[2]) == pytest.approx(np.pi) and half[:2] == pytest.approx([0, 0])
    quarter = servo_velocity(*args, reference_x=[0, 1, 0]).error[3:]
    assert quarter == pytest.approx([0, 0, -np.pi / 2])


def _level_face(z=0.5):
    """A level face straight ahead of the home camera: centre (0, 0, z), normal towards it."""
    return np.array([0.0, 0.0, z]), SimpleNamespace(
        normal_cam=np.array([0.0, 0.0, -1.0]), long_axis_cam=np.array([1.0, 0, 0]),
        short_axis_cam=np.array([0, 1.0, 0]), warped_long=np.array([1.0, 0, 0]),
        warped_short=np.array([0, 1.0, 0]))


def test_lifted_goal_by_hand(runner):
    """Home camera looking straight down at a level face 0.5 m away. The grasp pose for B is
    0.15 m above the centre (seen at (0, 0, 0.15)); lifted by 0.30 − 0.15 = 0.15 m it sees the
    centre at (0, 0, 0.30). For L the camera sits 35 mm to the side, so the centre is seen at
    y = −0.035 m, at either height. The pre-grasp on the normal is the full 0.30 m (the camera
    and cups are far from the walls)."""
    T_home = runner.cell.robot.home_camera_pose()
    centre, feats = _level_face()
    runner.cfg.motion.approach = "lift"
    cfg, d = runner._first_goal(centre, feats, None, "B", T_home)
    assert d == pytest.approx(0.30)
    assert cfg.target_point == pytest.approx((0.0, 0.0, 0.30), abs=1e-9)
    cfg, d = runner._first_goal(centre, feats, None, "L", T_home)
    assert cfg.target_point == pytest.approx((0.0, -0.035, 0.30), abs=1e-9)
    runner.cfg.motion.approach = "pregrasp"
    cfg, d = runner._first_goal(centre, feats, None, "B", T_home)
    assert d == pytest.approx(0.30) and cfg.standoff == pytest.approx(0.30)
    runner.cfg.motion.approach = "direct"
    cfg, d = runner._first_goal(centre, feats, None, "B", T_home)
    assert d == pytest.approx(0.15) and cfg is runner.servo_cfg


def test_lift_is_cut_to_keep_a_steep_face_in_view(runner):
    """A face tilted 60° about the camera x axis: lifting the grasp pose straight up moves the
    centre sideways in the goal's view by about h·sin 60°, so the full 0.15 m lift would put it
    outside the central 70 % of the image; the lift is cut until it is inside."""
    T_home = runner.cell.robot.home_camera_pose()
    t = np.radians(60)
    normal = np.array([0.0, np.sin(t), -np.cos(t)])  # towards the camera (normal · centre < 0)
    feats = SimpleNamespace(normal_cam=normal, long_axis_cam=np.array([1.0, 0, 0]),
                            short_axis_cam=np.cross(normal, [1.0, 0, 0]),
                            warped_long=np.array([1.0, 0, 0]), warped_short=np.array([0, 1.0, 0]))
    runner.cfg.motion.approach = "lift"
    cfg, d = runner._first_goal(np.array([0.0, 0.0, 0.5]), feats, None, "B", T_home)
    assert 0.15 < d < 0.30
    x, y, z = cfg.target_point
    intr = runner.cell.intrinsics
    assert abs(y / z) <= 0.7 * intr.cy / intr.fy and abs(x / z) <= 0.7 * intr.cx / intr.fx


@pytest.fixture
def two_boxes(smoke_cfg):
    """Two medium boxes (145 × 92 × 52 mm) lying flat side by side, touching along y = 0: their
    top faces are coplanar at z = 52 mm, centred at (0, ±0.046, 0.052)."""
    from pipeline.robot.model import robot_config
    from pipeline.world.cell import PickCell
    from pipeline.world.trial import PickRunner
    from pipeline.robot.model import Robot

    cfg = smoke_cfg("evaluate", "evaluate.boxes_per_trial=2",
                    "eval_boxes.types=[{name: medium, size: [0.145, 0.092, 0.052]}]")
    cell = PickCell(cfg, lambda: Robot(robot_config(cfg)))
    r = PickRunner(cfg, cell, lambda d, i, rng: [], "test")
    cell.reset(np.random.default_rng(0), 2)
    for body, y in zip(cell.boxes, (-0.046, 0.046)):
        p.resetBasePositionAndOrientation(body, [0, y, 0.026], [0, 0, 0, 1],
                                          physicsClientId=cell.client)
    yield r
    cell.close()


def test_coplanar_faces_of_two_boxes_are_split_between_the_planners_points(two_boxes):
    """The descriptor grows both top faces into one 145 × 184 mm region centred on the seam
    (y = 0); with the other face's point 92 mm away (> face_split_m) in that region, the
    surface the check tests and the servo tracks is the chosen face: centre (0, −0.046, 0.052)."""
    runner = two_boxes
    a, b = list(runner.cell.boxes)
    frame, ua, va = _pixel_of(runner, [0, -0.046, 0.052])
    _, ub, vb = _pixel_of(runner, [0, 0.046, 0.052])
    cand_a = SimpleNamespace(u=ua, v=va, grasp_class=GraspClass.B)
    cand_b = SimpleNamespace(u=ub, v=vb, grasp_class=GraspClass.B)
    assert runner._target_of(frame, cand_a)[0] == a and runner._target_of(frame, cand_b)[0] == b

    def world(point_cam):
        T = frame.T_world_cam
        return T[:3, :3] @ point_cam + T[:3, 3]

    alone, sites = runner._home_surface(frame, cand_a, [cand_a])
    assert sites is None  # no other point: the whole region
    assert abs(world(alone.center_cam)[1]) < 0.003  # its centre is on the seam
    assert alone.short_length == pytest.approx(0.145, abs=0.004)
    assert alone.long_length == pytest.approx(0.184, abs=0.004)
    part, sites = runner._home_surface(frame, cand_a, [cand_a, cand_b])
    assert sites.shape == (2, 3)
    np.testing.assert_allclose(sites, [[0, -0.046, 0.052], [0, 0.046, 0.052]], atol=0.002)
    np.testing.assert_allclose(world(part.center_cam), [0, -0.046, 0.052], atol=0.003)
    assert part.long_length == pytest.approx(0.145, abs=0.004)
    assert part.short_length == pytest.approx(0.092, abs=0.004)
    # the choice carries the sites to the attempt
    chosen = runner.select(frame, [cand_a, cand_b], [])
    assert chosen[0] is cand_a and chosen[4].shape == (2, 3)
    # a point of the same face (3 cm away, < face_split_m) splits nothing; nor does 0 (off)
    _, uc, vc = _pixel_of(runner, [0.03, -0.046, 0.052])
    near = SimpleNamespace(u=uc, v=vc, grasp_class=GraspClass.B)
    assert runner._home_surface(frame, cand_a, [cand_a, near])[1] is None
    runner.cfg.evaluate.face_split_m = 0.0
    assert runner._home_surface(frame, cand_a, [cand_a, cand_b])[1] is None


def test_pattern_fits_by_the_hand_level_rule(smoke_cfg):
    """A 145 × 52 mm face (a medium box on its side). Cups: 18 mm discs (radius 9 mm, no
    margin at run time), B's at ±35 mm along the hand's Y. X along the long axis: half-lengths
    72.5 mm (X) and 26 mm (Y), B's cups reach 35 + 9 = 44 mm > 26 mm: no B; one cup on the
    centre (9 mm) fits: L, R. X along the short axis: Y half-length 72.5 mm ≥ 44 mm and
    9 mm ≤ 26 mm: B fits. A 90 × 90 mm face: 44 mm ≤ 45 mm, B fits (the labels' 2 mm margin
    would say no). Area: B needs 1.2 × 2 × π 9² mm² = 610.7 mm², one cup 305.4 mm²."""
    from pipeline.world.trial import pattern_fits

    hand = smoke_cfg("evaluate").hand
    face = dict(long_length=0.145, short_length=0.052, area=0.145 * 0.052)
    x_long = SimpleNamespace(**face, warped_long=np.array([1.0, 0, 0]),
                             warped_short=np.array([0, 1.0, 0]))
    x_short = SimpleNamespace(**face, warped_long=np.array([0, 1.0, 0]),
                              warped_short=np.array([1.0, 0, 0]))
    assert not pattern_fits(x_long, "B", hand)
    assert pattern_fits(x_long, "L", hand) and pattern_fits(x_long, "R", hand)
    assert pattern_fits(x_short, "B", hand)
    square = SimpleNamespace(long_length=0.09, short_length=0.09, area=0.0081,
                             warped_long=np.array([1.0, 0, 0]), warped_short=np.array([0, 1.0, 0]))
    assert pattern_fits(square, "B", hand)
    assert not pattern_fits(SimpleNamespace(**{**vars(square), "short_length": 0.087}), "B", hand)
    # a 25 mm square: one cup fits (9 mm ≤ 12.5 mm) if the area is at least 305.4 mm²
    small = dict(long_length=0.025, short_length=0.025, warped_long=np.array([1.0, 0, 0]),
                 warped_short=np.array([0, 1.0, 0]))
    assert pattern_fits(SimpleNamespace(**small, area=0.000625), "L", hand)
    assert not pattern_fits(SimpleNamespace(**small, area=0.0003), "L", hand)
    assert not pattern_fits(SimpleNamespace(**small, area=0.000625), "B", hand)


def test_the_labels_are_asked_only_when_wanted(smoke_cfg):
    """``evaluate.label_no_grasp=false``: a "no grasp" end records the planner's figures alone;
    the oracle's own trials are never asked (it is the labels)."""
    from pipeline.world.trial import PickRunner

    r = _one_box_runner(smoke_cfg, "medium", [0.145, 0.092, 0.052])
    try:
        r.cell.reset = lambda rng, count: None
        r.cfg.evaluate.label_no_grasp = False
        off = r.run_trial(0, np.random.default_rng(0), np.random.default_rng(1))
        assert off.end == "no_grasp" and "label_executable" not in off.no_grasp
        r.cfg.evaluate.label_no_grasp = True
        oracle = PickRunner(r.cfg, r.cell, lambda d, i, rng: [], "oracle")
        res = oracle.run_trial(0, np.random.default_rng(0), np.random.default_rng(1))
        assert res.end == "no_grasp" and "label_executable" not in res.no_grasp
    finally:
        r.cell.close()
