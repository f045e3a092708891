"""Choosing what the robot executes: the run-time check gates every target, retries differ.

Hand-worked on one box lying flat in the middle of the bin (its top face at the image centre
is reachable with both cups) and on a pixel of the bin floor 2 cm from the +y wall. The robot
side (``pipeline.controller.picker.RobotController``) plans on the world's observation only:
its check knows the heap from the home depth image. The servo of a patterned grasp tracks the
centre of the surface the descriptor grows at its pixel, so that is what the check tests: for
the floor pixel, the floor around the box, whose centre is the bin centre, under the box: the
hand would be inside the box (its columns in the heap model), a rejection.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pybullet as p
import pytest
from conftest import default_config

from pipeline.camera.geometry import project, world_to_camera
from pipeline.controller.planning import Grasp


class Scripted:
    """A planner that returns the last list appended to ``plans`` (none: no grasp)."""

    def __init__(self):
        self.plans = []

    def plan(self, observation, rng):
        return self.plans[-1] if self.plans else []


def _runner(cfg, name="test"):
    """The world (a cell) and the robot side (a controller with a scripted planner)."""
    from pipeline.controller.picker import RobotController
    from pipeline.robot.model import Robot, robot_config
    from pipeline.world.cell import PickCell
    from pipeline.world.trial import TrialRunner

    cell = PickCell(cfg, lambda: Robot(robot_config(cfg)))
    planner = Scripted()
    runner = TrialRunner(cfg, cell, RobotController(cfg, planner, name), name)
    runner.plans = planner.plans  # what the planner returns next: append a list of grasps
    return runner


def _one_box_runner(smoke_cfg, name: str, size: list[float]):
    """A runner whose cell holds one box of ``size`` (m) flat at the bin centre, at rest."""
    cfg = smoke_cfg(
        "evaluate",
        "evaluate.boxes_per_trial=1",
        f"eval_boxes.types=[{{name: {name}, size: {list(size)}}}]",
    )
    r = _runner(cfg)
    cell = r.cell
    cell.reset(np.random.default_rng(0), 1)
    (body,) = list(cell.boxes)
    p.resetBasePositionAndOrientation(
        body, [0, 0, size[2] / 2], [0, 0, 0, 1], physicsClientId=cell.client
    )
    cell.settle()
    return r


def _close(r):
    r.cell.close()
    r.robot_side.close()


@pytest.fixture
def runner(smoke_cfg):
    r = _one_box_runner(smoke_cfg, "medium", [0.145, 0.092, 0.052])
    yield r
    _close(r)


@pytest.fixture
def cube_runner(smoke_cfg):
    r = _one_box_runner(smoke_cfg, "cube", [0.06, 0.06, 0.07])
    yield r
    _close(r)


def _home(runner):
    """The home observation of the world as it is now."""
    runner.cell.robot.set_joints(runner.cell.robot.home_q())
    return runner.cell.observe()


def _grasp(obs, point_world, pattern="B", **kw):
    u, v = project(world_to_camera(np.asarray(point_world, float), obs.T_world_cam), obs.intrinsics)
    return Grasp(float(u), float(v), pattern, **kw)


def _check(runner, obs, grasp, pattern):
    """The run-time check of ``grasp`` with ``pattern`` on the home ``obs``: (check, reason)."""
    ctrl = runner.robot_side
    ctrl.checker.update(obs)
    feats, _ = ctrl.home_surface(obs, grasp, [grasp])
    return ctrl.checker.check(
        obs, feats, feats.center_cam, pattern, (grasp.u, grasp.v), hand_fit=True
    )


def _select(runner, obs, grasps):
    return runner.robot_side.select(obs, grasps)


def test_a_reachable_target_is_chosen_and_a_rejected_one_never(runner):
    (body,) = list(runner.cell.boxes)
    obs = _home(runner)
    good = _grasp(obs, [0, 0, 0.052])  # the box's top face centre
    bad = _grasp(obs, [0.1, 0.13, 0.0])
    assert runner.target_of(good.u, good.v) == body  # the world's books
    assert _check(runner, obs, good, "B")[0] is not None
    assert _check(runner, obs, bad, "B")[0] is None
    # G_opt is the rejected one: the next candidate is executed, never G_opt
    chosen = _select(runner, obs, [bad, good]).plan
    assert (chosen.grasp, chosen.pattern) == (good, "B")
    # nothing passes: no grasp (the trial ends), G_opt is not run anyway
    result = _select(runner, obs, [bad, bad])
    assert result.plan is None
    # the floor point's surface is the floor around the box, centred under it: the hand there
    # is in the box's columns, with B and with each single cup of the fallback
    assert sum(result.rejected.values()) == 2 * 3
    assert set(result.rejected) <= {"collision", "path_collision"}
    runner.plans.append([bad])
    runner.cell.reset = lambda rng, count: None  # the trial keeps this heap
    trial = runner.run_trial(0, np.random.default_rng(0), np.random.default_rng(1))
    assert trial.end == "no_grasp" and trial.attempts == []
    # the labels on that image hold a grasp the check passes (the box's top face): the planner's
    # perception lost the box, not execution (evaluate.label_no_grasp)
    assert trial.no_grasp["label_candidates"] == 1 and trial.no_grasp["label_executable"]
    assert {k: trial.no_grasp[k] for k in ("boxes_left", "candidates", "checked")} == {
        "boxes_left": 1,
        "candidates": 1,
        "checked": 1,
    }
    assert trial.final_home == {}  # kept only with the trace (evaluate.log_trials)
    runner.plans.append([bad])
    traced = runner.run_trial(
        0, np.random.default_rng(0), np.random.default_rng(1), keep_trace=True
    )
    home = traced.final_home
    assert home["depth_m"].shape == obs.depth_m.shape
    np.testing.assert_allclose(home["T_world_cam"], obs.T_world_cam, atol=1e-3)  # home, by IK
    np.testing.assert_allclose(home["candidates_px"], [[bad.u, bad.v]])
    (left,) = home["boxes_left"]
    assert left["body"] == body and left["type"] == runner.cell.boxes[body]["type"]
    np.testing.assert_allclose(left["position"], runner.cell.box_pose(body)[0])


def test_the_preferred_clearance_never_rejects_what_the_check_accepts(runner):
    """The check's first pass asks ``evaluate.preferred_bin_clearance`` from the bin on the
    servo's path, the second the labels' clearance. The box lies at the bin centre, 0.1 m and
    more from every wall: its top face passes the first pass (10 mm) with the same hand axis
    and path as the plain check. A clearance no path has (1 m) fails the first pass at every
    rotation, and the plain check still accepts the grasp."""
    obs = _home(runner)
    good = _grasp(obs, [0, 0, 0.052])
    checker = runner.robot_side.checker
    assert runner.cfg.evaluate.preferred_bin_clearance == pytest.approx(0.01)
    assert checker.comfort == pytest.approx(0.01)
    comfortable, _ = _check(runner, obs, good, "B")
    checker.comfort = None
    plain, _ = _check(runner, obs, good, "B")
    np.testing.assert_allclose(comfortable.x_world, plain.x_world)
    assert len(comfortable.path) == len(plain.path)
    checker.comfort = 1.0
    unreachable, _ = _check(runner, obs, good, "B")
    np.testing.assert_allclose(unreachable.x_world, plain.x_world)


def test_each_rotation_is_predicted_once_over_both_clearances(runner, monkeypatch):
    """B tries the hand turned by 0 and 180° (``hand.rotations_deg``). With a first-pass
    clearance no path has (1 m) both rotations fail it on the bin, and the second pass accepts
    0°: two servo predictions in all (not 2 + 1), and three motion checks (two at 1 m, one at
    the labels' clearance)."""
    import pipeline.labelling.grasp_check as gc

    calls = {"predict": 0, "motion": 0}

    def counting(name, fn):
        def wrapped(*a, **k):
            calls[name] += 1
            return fn(*a, **k)

        return wrapped

    monkeypatch.setattr(gc, "servo_motion", counting("predict", gc.servo_motion))
    monkeypatch.setattr(gc, "check_motion", counting("motion", gc.check_motion))
    obs = _home(runner)
    good = _grasp(obs, [0, 0, 0.052])
    monkeypatch.setattr(runner.robot_side.checker, "comfort", 1.0)
    check, reason = _check(runner, obs, good, "B")
    assert reason is None and check is not None
    assert calls == {"predict": 2, "motion": 3}


def _fail(runner, obs, grasp, pattern, outcome="dropped"):
    """The robot remembers a failed plan of ``grasp`` with ``pattern`` on ``obs``."""
    from pipeline.controller.picker import Plan

    ctrl = runner.robot_side
    ctrl.remember_failure(Plan(grasp, pattern, obs, ctrl.point_world(obs, grasp)), outcome)


def _move(runner, body, position):
    p.resetBasePositionAndOrientation(
        body, position, [0, 0, 0, 1], physicsClientId=runner.cell.client
    )


def test_a_retry_after_a_failure_differs(runner):
    """A failed plan (pattern B at the top's centre P) is skipped while the heap looks the same;
    the fallback's L is a new plan; without the fallback nothing is left; the box moved by 1 cm
    (its edges change about 2 x 9.2 cm x 1 cm of depth, > 5 cm²) makes B a new plan; with
    retry_policy=repeat B is chosen again on the old image."""
    (body,) = list(runner.cell.boxes)
    obs = _home(runner)
    g = _grasp(obs, [0, 0, 0.052])
    _fail(runner, obs, g, "B")
    result = _select(runner, obs, [g])
    assert result.plan.pattern == "L" and result.rejected == {"repeat": 1}  # the fallback
    runner.cfg.evaluate.single_cup_fallback = False
    result = _select(runner, obs, [g])
    assert result.plan is None and result.rejected == {"repeat": 1}
    _move(runner, body, [0.01, 0, 0.026])
    moved = _home(runner)
    assert _select(runner, moved, [_grasp(moved, [0.01, 0, 0.052])]).plan.pattern == "B"
    runner.cfg.evaluate.retry_policy = "repeat"
    runner.robot_side.memory.policy = "repeat"
    assert _select(runner, obs, [g]).plan.pattern == "B"


def _add_cube(runner, xy):
    """A 6 cm cube resting on the bin floor at ``xy`` (world, m), one of the cell's boxes."""
    cell = runner.cell
    shape = p.createCollisionShape(p.GEOM_BOX, halfExtents=[0.03] * 3, physicsClientId=cell.client)
    visual = p.createVisualShape(p.GEOM_BOX, halfExtents=[0.03] * 3, physicsClientId=cell.client)
    body = p.createMultiBody(
        0.1, shape, visual, basePosition=[xy[0], xy[1], 0.03], physicsClientId=cell.client
    )
    cell.boxes[body] = {"type": "cube", "size": np.array([0.06, 0.06, 0.06]), "mass": 0.1}
    return body


def test_a_failure_at_the_point_skips_every_pattern_there(runner):
    """After a lost target or a seal that did not form (``evaluate.retry_point_outcomes``), the
    point failed, not the pattern: B, L and R there are all repeats while the heap is
    unchanged; 5 cm away is a new plan. After a drop only the dropped pattern is."""
    obs = _home(runner)
    g = _grasp(obs, [0, 0, 0.052])
    memory = runner.robot_side.memory
    P = runner.robot_side.point_world(obs, g)
    assert list(runner.cfg.evaluate.retry_point_outcomes) == ["lost_target", "no_seal"]
    for outcome in ("lost_target", "no_seal"):
        memory.clear()
        _fail(runner, obs, g, "B", outcome)
        assert all(memory.repeats(obs, P, pat) for pat in ("B", "L", "R"))
        assert not memory.repeats(obs, P + [0.05, 0, 0], "L")
    memory.clear()
    _fail(runner, obs, g, "B", "dropped")
    assert memory.repeats(obs, P, "B") and not memory.repeats(obs, P, "L")


def test_a_retry_is_new_once_the_heap_around_it_changes(runner):
    """The failed plan on the medium box at the bin centre (P = its top face centre) stays
    skipped while the depth around it is as it was; a cube whose centre is 0.10 m from P
    (< retry_neighbour_m = 0.15 m) moving 1 cm, or being picked, makes it a new plan; a cube
    0.22 m away (its nearest side 0.19 m from P) does not count."""
    obs0 = _home(runner)
    g = _grasp(obs0, [0, 0, 0.052])
    memory = runner.robot_side.memory
    P = runner.robot_side.point_world(obs0, g)
    near = _add_cube(runner, [0.0, 0.1])
    far = _add_cube(runner, [0.22, 0.0])
    obs = _home(runner)
    _fail(runner, obs, g, "B")
    assert memory.repeats(_home(runner), P, "B")
    runner.cell.remove_box(far)  # picked, but out of reach of the failed plan
    assert memory.repeats(_home(runner), P, "B")
    _move(runner, near, [0.0, 0.11, 0.03])
    assert not memory.repeats(_home(runner), P, "B")  # the neighbour moved by 1 cm
    _move(runner, near, [0.0, 0.1, 0.03])
    assert memory.repeats(_home(runner), P, "B")  # back where it was
    runner.cell.remove_box(near)  # the neighbour was picked
    assert not memory.repeats(_home(runner), P, "B")


def test_single_point_tries_the_other_cup(runner):
    """A Dex-Net-style point (no pattern) gets ``dexnet_pattern`` (L) first, then R; when L was
    the failed plan, R is next."""
    obs = _home(runner)
    point_cam = world_to_camera(np.array([0, 0, 0.052]), obs.T_world_cam)
    g = _grasp(obs, [0, 0, 0.052], pattern=None, point_cam=point_cam)
    assert runner.robot_side.patterns(g) == ["L", "R"]
    plan = _select(runner, obs, [g]).plan
    assert plan.pattern == "L"
    np.testing.assert_allclose(plan.fixed_point_world, [0, 0, 0.052], atol=1e-6)
    _fail(runner, obs, g, "L", "collision")
    assert _select(runner, obs, [g]).plan.pattern == "R"
    # one cup dropped the box there: the other single cup is skipped too
    # (evaluate.retry_drop_single_cup)
    runner.robot_side.memory.clear()
    _fail(runner, obs, g, "L", "dropped")
    assert _select(runner, obs, [g]).plan is None


def test_a_b_that_does_not_fit_is_tried_with_one_cup(cube_runner):
    """The cube's 60 x 60 mm top face: B's cup discs (9 mm radius at ±35 mm) reach 44 mm from
    the centre, past the 30 mm half-width, so the hand-fit gate rejects B; one cup on the
    centre (9 mm <= 30 mm, area 3600 mm² >= 1.2 x 254 mm²) fits. With the single-cup fallback
    the B candidate is executed with L, and after a failed L with R; without it, nothing passes
    and the only rejection is B's fit."""
    runner = cube_runner
    obs = _home(runner)
    g = _grasp(obs, [0, 0, 0.07])
    assert runner.cfg.evaluate.single_cup_fallback  # the default
    assert runner.robot_side.patterns(g) == ["B", "L", "R"]
    result = _select(runner, obs, [g])
    assert result.plan.pattern == "L" and result.rejected == {"hand_fit": 1}
    _fail(runner, obs, g, "L", "collision")
    assert _select(runner, obs, [g]).plan.pattern == "R"
    # an L or R candidate has no fallback
    assert runner.robot_side.patterns(Grasp(g.u, g.v, "L")) == ["L"]
    runner.cfg.evaluate.single_cup_fallback = False
    runner.robot_side.memory.clear()
    result = _select(runner, obs, [g])
    assert result.plan is None and result.rejected == {"hand_fit": 1}


def test_a_b_falls_back_to_one_cup_last_when_asked(cube_runner):
    """``evaluate.single_cup_fallback_order``. The cube's B does not fit (above) and a second
    candidate, an L at the same point, does. at_once: the B candidate is executed with L before
    the second candidate is looked at; last: the second candidate's own L comes first, and the
    B's single cups only after every candidate's own pattern."""
    runner = cube_runner
    obs = _home(runner)
    b = _grasp(obs, [0, 0, 0.07])
    single = Grasp(b.u, b.v, "L")
    point = Grasp(b.u, b.v, None)  # a single suction point: both cups are its own
    side = runner.robot_side
    assert runner.cfg.evaluate.single_cup_fallback_order == "at_once"  # the default
    assert side.order([b, single, point]) == [
        (0, "B"),
        (0, "L"),
        (0, "R"),
        (1, "L"),
        (2, "L"),
        (2, "R"),
    ]
    plan = _select(runner, obs, [b, single]).plan
    assert plan.grasp is b and plan.pattern == "L"
    runner.cfg.evaluate.single_cup_fallback_order = "last"
    assert side.order([b, single, point]) == [
        (0, "B"),
        (1, "L"),
        (2, "L"),
        (2, "R"),
        (0, "L"),
        (0, "R"),
    ]
    plan = _select(runner, obs, [b, single]).plan
    assert plan.grasp is single and plan.pattern == "L"
    result = _select(runner, obs, [b])  # the B alone still falls back
    assert result.plan.grasp is b and result.plan.pattern == "L"
    runner.cfg.evaluate.single_cup_fallback = False  # no fallback: the order has none to move
    assert side.order([b, single]) == [(0, "B"), (1, "L")]


def test_two_cups_first_where_they_fit(runner, cube_runner):
    """``evaluate.two_cups_first``. On the medium box's top face (145 x 92 mm) both cups fit:
    an L of the fallback tier is executed as B under ``second_tier`` and ``all``, a first-tier L
    only under ``all``. On the cube's 60 mm face B does not fit ("hand_fit"): the L is executed
    as it is. The order keeps the upgrade with its own grasp when a B's single cups go last."""
    obs = _home(runner)
    side = runner.robot_side
    first = _grasp(obs, [0, 0, 0.052], "L")
    tier2 = _grasp(obs, [0, 0, 0.052], "L", second_tier=True)
    b = _grasp(obs, [0, 0, 0.052], "B")
    assert runner.cfg.evaluate.two_cups_first == "none"  # the stage default
    assert side.patterns(tier2) == ["L"]
    assert _select(runner, obs, [tier2]).plan.pattern == "L"
    runner.cfg.evaluate.two_cups_first = "second_tier"
    assert side.patterns(tier2) == ["B", "L"] and side.patterns(first) == ["L"]
    assert _select(runner, obs, [tier2]).plan.pattern == "B"
    assert _select(runner, obs, [first]).plan.pattern == "L"
    runner.cfg.evaluate.single_cup_fallback_order = "last"
    assert side.order([b, tier2]) == [(0, "B"), (1, "B"), (1, "L"), (0, "L"), (0, "R")]
    runner.cfg.evaluate.two_cups_first = "all"
    assert side.patterns(first) == ["B", "L"]
    assert _select(runner, obs, [first]).plan.pattern == "B"

    cube = cube_runner
    cube.cfg.evaluate.two_cups_first = "all"
    obs = _home(cube)
    single = _grasp(obs, [0, 0, 0.07], "L")
    assert _check(cube, obs, single, "B")[1] == "hand_fit"
    result = _select(cube, obs, [single])
    assert result.plan.pattern == "L" and result.rejected.get("hand_fit") == 1


def test_b_turned_by_a_quarter_where_its_cups_fit_the_other_way(smoke_cfg):
    """``evaluate.b_quarter_turn``. A 170 x 60 mm top face lying along the world's x axis: the
    paper's rule makes that axis the hand's X, so B's cups (88 mm apart on the hand's Y) would
    straddle the 60 mm side and do not fit ("hand_fit"). Off: the B falls back to one cup (L).
    On: B with the hand turned by 90° follows B itself, before the single cups; its X is the
    face's short axis (world y), and the servo then picks the bar with both cups."""
    from pipeline.controller.check import pattern_fits

    r = _one_box_runner(smoke_cfg, "bar", [0.17, 0.06, 0.05])
    try:
        obs = _home(r)
        b = _grasp(obs, [0, 0, 0.05], "B")
        side = r.robot_side
        feats, _ = side.home_surface(obs, b, [b])
        assert not pattern_fits(feats, "B", r.cfg.hand)
        assert pattern_fits(feats, "B", r.cfg.hand, quarter_turn=True)
        assert r.cfg.evaluate.b_quarter_turn is False  # the stage default
        assert side.order([b]) == [(0, "B"), (0, "L"), (0, "R")]
        assert _select(r, obs, [b]).plan.pattern == "L"
        r.cfg.evaluate.b_quarter_turn = True
        assert side.order([b]) == [(0, "B"), (0, "B90"), (0, "L"), (0, "R")]
        result = _select(r, obs, [b])
        assert result.plan.pattern == "B" and result.rejected == {"hand_fit": 1}
        # the hand's X: the face's short axis as the descriptor measures it from depth
        np.testing.assert_allclose(np.abs(result.plan.x_world), [0, 1, 0], atol=1e-3)
        attempt = r.attempt(result.plan, obs, 0, 0, None)
        assert (attempt.pattern, attempt.outcome) == ("B", "success")
    finally:
        _close(r)


def test_an_unknown_two_cups_first_is_refused(smoke_cfg):
    from pipeline.controller.picker import RobotController

    cfg = smoke_cfg("evaluate", "evaluate.two_cups_first=always")
    with pytest.raises(ValueError, match="two_cups_first is 'always': choose from"):
        RobotController(cfg, planner=None, name="test")


def test_an_unknown_fallback_order_is_refused(smoke_cfg):
    from pipeline.controller.picker import RobotController

    cfg = smoke_cfg("evaluate", "evaluate.single_cup_fallback_order=later")
    with pytest.raises(ValueError, match="single_cup_fallback_order is 'later': choose from"):
        RobotController(cfg, planner=None, name="test")


def test_dexnet_alternatives_follow_the_best_by_quality():
    """``grasps_of``: the best, then the final set's others by score (ties in sampling order),
    skipping -inf and the best's pixel and repeated pixels."""
    from pipeline.dexnet.cem import CEMIteration, CEMResult
    from pipeline.dexnet.planner import grasps_of
    from pipeline.dexnet.sampling import Candidates

    uv = np.array([[10, 10], [20, 20], [30, 30], [20, 20], [40, 40]])
    n = len(uv)
    c = Candidates(
        uv=uv,
        point=np.zeros((n, 3)),
        axis=np.tile([0, 0, 1.0], (n, 1)),
        depth=np.ones(n),
        angle=np.zeros(n),
    )
    scores = np.array([0.9, 0.5, 0.7, 0.5, -np.inf])
    result = CEMResult(
        best=c.take([0]), best_score=0.9, iterations=[CEMIteration(c, scores, np.array([0]))]
    )
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
        normal_cam=np.array([0.0, 0.0, -1.0]),
        long_axis_cam=np.array([1.0, 0, 0]),
        short_axis_cam=np.array([0, 1.0, 0]),
        warped_long=np.array([1.0, 0, 0]),
        warped_short=np.array([0, 1.0, 0]),
    )


def _first_goal(runner, centre, feats, pattern, T_home):
    """``pipeline.robot.approach.first_goal`` as the robot's servo calls it at its first step
    (the hand's X by the paper's rule)."""
    from pipeline.controller.check import paper_x_axis
    from pipeline.robot.approach import first_goal

    ctrl = runner.robot_side
    return first_goal(
        ctrl.servo_cfg,
        runner.cfg,
        T_home,
        centre,
        feats.normal_cam,
        paper_x_axis(feats),
        pattern,
        runner.cell.intrinsics,
    )


def test_lifted_goal_by_hand(runner):
    """Home camera looking straight down at a level face 0.5 m away. The grasp pose for B is
    0.15 m above the centre (seen at (0, 0, 0.15)); lifted by 0.30 − 0.15 = 0.15 m it sees the
    centre at (0, 0, 0.30). For L the camera sits 35 mm to the side, so the centre is seen at
    y = −0.035 m, at either height. The pre-grasp on the normal is the full 0.30 m (the camera
    and cups are far from the walls)."""
    T_home = runner.cell.robot.home_camera_pose()
    centre, feats = _level_face()
    runner.cfg.motion.approach = "lift"
    cfg, d = _first_goal(runner, centre, feats, "B", T_home)
    assert d == pytest.approx(0.30)
    assert cfg.target_point == pytest.approx((0.0, 0.0, 0.30), abs=1e-9)
    cfg, d = _first_goal(runner, centre, feats, "L", T_home)
    assert cfg.target_point == pytest.approx((0.0, -0.035, 0.30), abs=1e-9)
    runner.cfg.motion.approach = "pregrasp"
    cfg, d = _first_goal(runner, centre, feats, "B", T_home)
    assert d == pytest.approx(0.30) and cfg.standoff == pytest.approx(0.30)
    runner.cfg.motion.approach = "direct"
    cfg, d = _first_goal(runner, centre, feats, "B", T_home)
    assert d == pytest.approx(0.15) and cfg is runner.robot_side.servo_cfg


def test_first_goal_is_a_via_point(runner):
    """The lift's and the pre-grasp's goals take motion.via_tolerance_scale (k) times the servo's
    tolerances; d* keeps its own. k = 2: 0.01 -> 0.02 (x, y, log Z), 1 deg -> 2 deg."""
    T_home = runner.cell.robot.home_camera_pose()
    centre, feats = _level_face()
    final = runner.robot_side.servo_cfg
    runner.cfg.motion.via_tolerance_scale = 2.0
    for approach in ("lift", "pregrasp"):
        runner.cfg.motion.approach = approach
        cfg, _ = _first_goal(runner, centre, feats, "B", T_home)
        assert (cfg.tolerance_xy, cfg.tolerance_log_z, cfg.tolerance_rot_deg) == pytest.approx(
            (2 * final.tolerance_xy, 2 * final.tolerance_log_z, 2 * final.tolerance_rot_deg)
        )
    runner.cfg.motion.via_tolerance_scale = 0.5
    with pytest.raises(ValueError, match="via_tolerance_scale"):
        _first_goal(runner, centre, feats, "B", T_home)


def test_lift_is_cut_to_keep_a_steep_face_in_view(runner):
    """A face tilted 60° about the camera x axis: lifting the grasp pose straight up moves the
    centre sideways in the goal's view by about h·sin 60°, so the full 0.15 m lift would put it
    outside the central 70 % of the image; the lift is cut until it is inside."""
    T_home = runner.cell.robot.home_camera_pose()
    t = np.radians(60)
    normal = np.array([0.0, np.sin(t), -np.cos(t)])  # towards the camera (normal · centre < 0)
    feats = SimpleNamespace(
        normal_cam=normal,
        long_axis_cam=np.array([1.0, 0, 0]),
        short_axis_cam=np.cross(normal, [1.0, 0, 0]),
        warped_long=np.array([1.0, 0, 0]),
        warped_short=np.array([0, 1.0, 0]),
    )
    runner.cfg.motion.approach = "lift"
    cfg, d = _first_goal(runner, np.array([0.0, 0.0, 0.5]), feats, "B", T_home)
    assert 0.15 < d < 0.30
    x, y, z = cfg.target_point
    intr = runner.cell.intrinsics
    assert abs(y / z) <= 0.7 * intr.cy / intr.fy and abs(x / z) <= 0.7 * intr.cx / intr.fx


@pytest.fixture
def two_boxes(smoke_cfg):
    """Two medium boxes (145 × 92 × 52 mm) lying flat side by side, touching along y = 0: their
    top faces are coplanar at z = 52 mm, centred at (0, ±0.046, 0.052)."""
    cfg = smoke_cfg(
        "evaluate",
        "evaluate.boxes_per_trial=2",
        "eval_boxes.types=[{name: medium, size: [0.145, 0.092, 0.052]}]",
    )
    r = _runner(cfg)
    r.cell.reset(np.random.default_rng(0), 2)
    for body, y in zip(r.cell.boxes, (-0.046, 0.046)):
        p.resetBasePositionAndOrientation(
            body, [0, y, 0.026], [0, 0, 0, 1], physicsClientId=r.cell.client
        )
    yield r
    _close(r)


def test_coplanar_faces_of_two_boxes_are_split_between_the_planners_points(two_boxes):
    """The descriptor grows both top faces into one 145 × 184 mm region centred on the seam
    (y = 0); with the other face's point 92 mm away (> face_split_m) in that region, the
    surface the check tests and the servo tracks is the chosen face: centre (0, −0.046, 0.052)."""
    runner = two_boxes
    ctrl = runner.robot_side
    a, b = list(runner.cell.boxes)
    obs = _home(runner)
    ga, gb = _grasp(obs, [0, -0.046, 0.052]), _grasp(obs, [0, 0.046, 0.052])
    assert runner.target_of(ga.u, ga.v) == a and runner.target_of(gb.u, gb.v) == b

    def world(point_cam):
        T = obs.T_world_cam
        return T[:3, :3] @ point_cam + T[:3, 3]

    alone, sites = ctrl.home_surface(obs, ga, [ga])
    assert sites is None  # no other point: the whole region
    assert abs(world(alone.center_cam)[1]) < 0.003  # its centre is on the seam
    assert alone.short_length == pytest.approx(0.145, abs=0.004)
    assert alone.long_length == pytest.approx(0.184, abs=0.004)
    part, sites = ctrl.home_surface(obs, ga, [ga, gb])
    assert sites.shape == (2, 3)
    np.testing.assert_allclose(sites, [[0, -0.046, 0.052], [0, 0.046, 0.052]], atol=0.002)
    np.testing.assert_allclose(world(part.center_cam), [0, -0.046, 0.052], atol=0.003)
    assert part.long_length == pytest.approx(0.145, abs=0.004)
    assert part.short_length == pytest.approx(0.092, abs=0.004)
    # the choice carries the sites to the attempt
    plan = _select(runner, obs, [ga, gb]).plan
    assert plan.grasp is ga and plan.sites_world.shape == (2, 3)
    # a point of the same face (3 cm away, < face_split_m) splits nothing; nor does 0 (off)
    near = _grasp(obs, [0.03, -0.046, 0.052])
    assert ctrl.home_surface(obs, ga, [ga, near])[1] is None
    runner.cfg.evaluate.face_split_m = 0.0
    assert ctrl.home_surface(obs, ga, [ga, gb])[1] is None


def test_pattern_fits_by_the_hand_level_rule(smoke_cfg):
    """A 145 × 52 mm face (a medium box on its side). Cups: 18 mm discs (radius 9 mm, no
    margin at run time), B's at ±35 mm along the hand's Y. X along the long axis: half-lengths
    72.5 mm (X) and 26 mm (Y), B's cups reach 35 + 9 = 44 mm > 26 mm: no B; one cup on the
    centre (9 mm) fits: L, R. X along the short axis: Y half-length 72.5 mm ≥ 44 mm and
    9 mm ≤ 26 mm: B fits. A 90 × 90 mm face: 44 mm ≤ 45 mm, B fits (the labels' 2 mm margin
    would say no). Area: B needs 1.2 × 2 × π 9² mm² = 610.7 mm², one cup 305.4 mm²."""
    from pipeline.controller.check import pattern_fits

    hand = smoke_cfg("evaluate").hand
    face = dict(long_length=0.145, short_length=0.052, area=0.145 * 0.052)
    x_long = SimpleNamespace(
        **face, warped_long=np.array([1.0, 0, 0]), warped_short=np.array([0, 1.0, 0])
    )
    x_short = SimpleNamespace(
        **face, warped_long=np.array([0, 1.0, 0]), warped_short=np.array([1.0, 0, 0])
    )
    assert not pattern_fits(x_long, "B", hand)
    assert pattern_fits(x_long, "L", hand) and pattern_fits(x_long, "R", hand)
    assert pattern_fits(x_short, "B", hand)
    square = SimpleNamespace(
        long_length=0.09,
        short_length=0.09,
        area=0.0081,
        warped_long=np.array([1.0, 0, 0]),
        warped_short=np.array([0, 1.0, 0]),
    )
    assert pattern_fits(square, "B", hand)
    assert not pattern_fits(SimpleNamespace(**{**vars(square), "short_length": 0.087}), "B", hand)
    # a 25 mm square: one cup fits (9 mm ≤ 12.5 mm) if the area is at least 305.4 mm²
    small = dict(
        long_length=0.025,
        short_length=0.025,
        warped_long=np.array([1.0, 0, 0]),
        warped_short=np.array([0, 1.0, 0]),
    )
    assert pattern_fits(SimpleNamespace(**small, area=0.000625), "L", hand)
    assert not pattern_fits(SimpleNamespace(**small, area=0.0003), "L", hand)
    assert not pattern_fits(SimpleNamespace(**small, area=0.000625), "B", hand)


def test_the_labels_are_asked_only_when_wanted(smoke_cfg):
    """``evaluate.label_no_grasp=false``: a "no grasp" end records the planner's figures alone;
    the oracle's own trials are never asked (it is the labels)."""
    r = _one_box_runner(smoke_cfg, "medium", [0.145, 0.092, 0.052])
    try:
        r.cell.reset = lambda rng, count: None
        r.cfg.evaluate.label_no_grasp = False
        off = r.run_trial(0, np.random.default_rng(0), np.random.default_rng(1))
        assert off.end == "no_grasp" and "label_executable" not in off.no_grasp
        r.cfg.evaluate.label_no_grasp = True
        r.name = "oracle"
        res = r.run_trial(0, np.random.default_rng(0), np.random.default_rng(1))
        assert res.end == "no_grasp" and "label_executable" not in res.no_grasp
    finally:
        _close(r)
