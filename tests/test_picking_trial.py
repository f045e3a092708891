"""The closed loop: move times by hand, one short pick in the smoke config, the stage's artifact."""

import json
import math

import numpy as np
import pytest

from pipeline.controller.motion import move_time


def test_move_time_trapezoid_and_triangle():
    # 2 rad at 3 rad/s and 10 rad/s²: cruise reached (2 ≥ 3²/10 = 0.9): 2/3 + 3/10 = 0.9667 s.
    assert math.isclose(move_time(np.array([0.5, -2.0]), 3.0, 10.0), 2 / 3 + 0.3)
    # 0.4 rad: never reaches 3 rad/s; triangle 2·sqrt(0.4/10) = 0.4 s.
    assert math.isclose(move_time(np.array([0.4]), 3.0, 10.0), 0.4)
    assert move_time(np.zeros(7), 3.0, 10.0) == 0.0


class _Oracle:
    """Plans the centre of the most visible box's top face with both cups (B), from the
    world's body ids (a test's oracle)."""

    def __init__(self, cell):
        self.cell = cell

    def plan(self, observation, rng):
        from pipeline.controller.planning import Grasp

        ids = self.cell.last_frame.body_ids
        seen, counts = np.unique(ids[np.isin(ids, list(self.cell.boxes))], return_counts=True)
        if len(seen) == 0:
            return []
        v, u = np.nonzero(ids == seen[np.argmax(counts)])
        return [Grasp(float(np.median(u)), float(np.median(v)), "B")]


def test_one_short_pick_succeeds(smoke_cfg):
    from pipeline.controller.picker import RobotController
    from pipeline.robot.model import Robot, robot_config
    from pipeline.world.cell import PickCell
    from pipeline.world.trial import TrialRunner

    cfg = smoke_cfg(
        "evaluate",
        "evaluate.boxes_per_trial=1",
        "eval_boxes=warehouse",
        "eval_boxes.types=[{name: medium, size: [0.145, 0.092, 0.052]}]",
    )
    cell = PickCell(cfg, lambda: Robot(robot_config(cfg)))
    robot_side = RobotController(cfg, _Oracle(cell), "oracle")
    try:
        runner = TrialRunner(cfg, cell, robot_side, "oracle")
        result = runner.run_trial(
            0, np.random.default_rng(0), np.random.default_rng(1), keep_trace=True
        )
    finally:
        cell.close()
        robot_side.close()
    assert result.boxes == 1
    assert [a.outcome for a in result.attempts] == ["success"], result.attempts
    assert result.end == "bin_empty" and result.picked == 1
    a = result.attempts[0]
    assert a.pattern == "B" and a.servo_steps > 5 and a.motion_s > 1.0
    # The servo error shrinks from the home pose to convergence.
    errors = [np.linalg.norm(s["error"][:3]) for s in result.trace]
    assert errors[-1] < 0.2 * errors[0]


def test_evaluate_stage_writes_table3(smoke_cfg):
    from pipeline.artifacts import load_manifest, verify_artifact
    from pipeline.stages.evaluate import evaluate

    cfg = smoke_cfg(
        "evaluate",
        "planner=dexnet",
        "evaluate.dexnet_variant=planarity",
        "evaluate.boxes_per_trial=1",
        "evaluate.max_attempts_per_trial=2",
        "evaluate.workers=1",
    )
    out = evaluate(cfg)
    assert verify_artifact(out) == []
    m = load_manifest(out)
    (row,) = m["metrics"]["table3"]
    assert row["planner"] == "dexnet" and row["trials"] == 1 and row["boxes"] == 1
    assert row["attempts"] >= 1
    trials = json.loads((out / "trials.json").read_text())
    assert len(trials) == 1 and "planning_s" not in trials[0]["attempts"][0]
    assert "dexnet" in m["timings"]["planners"]
    assert (out / "log.rrd").is_file() and (out / "log.mcap").is_file()
    # Rerunning reuses the artifact.
    assert evaluate(cfg) == out


def test_evaluate_rejects_unknown_planner(smoke_cfg):
    from pipeline.stages.evaluate import evaluate

    cfg = smoke_cfg("evaluate", "evaluate.planners=[dcnn,magic]")
    with pytest.raises(ValueError, match="unknown planner 'magic'"):
        evaluate(cfg)
    with pytest.raises(ValueError, match="evaluate.split is 'train'"):
        evaluate(smoke_cfg("evaluate", "evaluate.split=train"))
    with pytest.raises(ValueError, match="evaluate.collision_model is 'oracle'"):
        evaluate(smoke_cfg("evaluate", "evaluate.collision_model=oracle"))


def test_the_splits_draw_disjoint_heaps():
    """dev keeps the seed keys of every earlier evaluation (31, 37, 41); test's are others, so
    trial t of test is never trial t of dev."""
    from pipeline.world.trial import HEAP_STREAMS

    assert HEAP_STREAMS["dev"] == (31, 37, 41)
    assert not set(HEAP_STREAMS["dev"]) & set(HEAP_STREAMS["test"])


def test_the_example_plugin_runs_a_short_closed_loop(smoke_cfg, monkeypatch):
    """docs/examples/centroid_planner.py as a new user runs it: named in evaluate.planners,
    imported from the repository's root; it picks in the smoke trial and its row is Table 3's."""
    from pathlib import Path

    from pipeline.stages.evaluate import evaluate

    root = Path(__file__).resolve().parents[1]
    monkeypatch.chdir(root)
    monkeypatch.syspath_prepend(str(root))
    name = "docs.examples.centroid_planner:CentroidPlanner"
    out = evaluate(smoke_cfg("evaluate", f"evaluate.planners=[{name}]", "evaluate.workers=1"))
    (row,) = json.loads((out / "manifest.json").read_text())["metrics"]["table3"]
    assert row["planner"] == name and row["attempts"] >= 1 and row["picked"] >= 1


def test_a_no_grasp_end_logs_its_home_image(tmp_path):
    """The last home image of a trial that ended "no grasp" is in the MCAP log at full
    resolution, with the boxes left (world frame) and the candidates back-projected: a candidate
    at the principal point, 0.5 m away, is the point (0, 0, 0.5) of the camera frame."""
    from mcap.reader import make_reader
    from mcap_protobuf.decoder import DecoderFactory

    from pipeline.camera.geometry import Intrinsics
    from pipeline.stages.evaluate import log_trials
    from pipeline.tracking import StageLog
    from pipeline.world.trial import TrialResult

    intr = Intrinsics(width=8, height=6, fx=10.0, fy=10.0, cx=3.5, cy=2.5)
    depth = np.full((6, 8), 0.5, np.float32)
    home = {
        "depth_m": depth,
        "T_world_cam": np.eye(4),
        "candidates_px": np.array([[3.5, 2.5]]),
        "boxes_left": [{"body": 7, "type": "cube", "position": np.array([0.1, -0.2, 0.03])}],
    }
    result = TrialResult(
        trial=3,
        planner="dcnn",
        boxes=12,
        picked=11,
        end="no_grasp",
        attempts=[],
        no_grasp={"boxes_left": 1, "candidates": 1, "checked": 1, "rejected": {"collision": 1}},
        final_home=home,
    )
    with StageLog(tmp_path, "evaluate", "rec") as log:
        log_trials(log, [result], intr)
    prefix = "/trials/dcnn/trial_3/no_grasp"
    with open(tmp_path / "log.mcap", "rb") as f:
        msgs = {
            ch.topic: dec
            for _, ch, _, dec in make_reader(
                f, decoder_factories=[DecoderFactory()]
            ).iter_decoded_messages()
        }
    img = msgs[f"{prefix}/depth"]
    assert (img.width, img.height, img.frame_id) == (8, 6, "no_grasp_camera")
    np.testing.assert_array_equal(np.frombuffer(img.data, "<f4").reshape(6, 8), depth)
    boxes = np.frombuffer(msgs[f"{prefix}/boxes_left"].data, [("xyz", "<f4", 3), ("c", "u1", 4)])
    np.testing.assert_allclose(boxes["xyz"], [[0.1, -0.2, 0.03]], atol=1e-7)
    cands = np.frombuffer(msgs[f"{prefix}/candidates"].data, [("xyz", "<f4", 3), ("c", "u1", 4)])
    np.testing.assert_allclose(cands["xyz"], [[0.0, 0.0, 0.5]], atol=1e-7)
    assert msgs[f"{prefix}/candidates"].frame_id == "no_grasp_camera"
    text = msgs["/log"].message
    assert "trial 3 ended no grasp: 1 candidates" in text and "cube at (+0.100, -0.200" in text
