"""The closed loop: move times by hand, one short pick in the smoke config, the stage's artifact."""

import json
import math

import numpy as np
import pytest

from pipeline.picking.trial import move_time


def test_move_time_trapezoid_and_triangle():
    # 2 rad at 3 rad/s and 10 rad/s²: cruise reached (2 ≥ 3²/10 = 0.9): 2/3 + 3/10 = 0.9667 s.
    assert math.isclose(move_time(np.array([0.5, -2.0]), 3.0, 10.0), 2 / 3 + 0.3)
    # 0.4 rad: never reaches 3 rad/s; triangle 2·sqrt(0.4/10) = 0.4 s.
    assert math.isclose(move_time(np.array([0.4]), 3.0, 10.0), 0.4)
    assert move_time(np.zeros(7), 3.0, 10.0) == 0.0


class _Oracle:
    """Plans the centre of the most visible box's top face with both cups (B)."""

    def __init__(self, cell):
        self.cell = cell

    def __call__(self, depth, intr, rng):
        from types import SimpleNamespace

        from pipeline.labelling.types import GraspClass

        frame = self.cell.render()
        ids, counts = np.unique(frame.body_ids[np.isin(frame.body_ids, list(self.cell.boxes))],
                                return_counts=True)
        if len(ids) == 0:
            return []
        v, u = np.nonzero(frame.body_ids == ids[np.argmax(counts)])
        return [SimpleNamespace(u=float(np.median(u)), v=float(np.median(v)),
                                grasp_class=GraspClass.B)]


def test_one_short_pick_succeeds(smoke_cfg):
    from pipeline.labelling.robot_check import robot_config
    from pipeline.picking.cell import PickCell
    from pipeline.picking.trial import PickRunner
    from pipeline.robot.model import Robot

    cfg = smoke_cfg("evaluate", "evaluate.boxes_per_trial=1", "eval_boxes=warehouse",
                    "eval_boxes.types=[{name: medium, size: [0.145, 0.092, 0.052]}]")
    cell = PickCell(cfg, lambda: Robot(robot_config(cfg)))
    try:
        runner = PickRunner(cfg, cell, _Oracle(cell), "oracle")
        result = runner.run_trial(0, np.random.default_rng(0), np.random.default_rng(1),
                                  keep_trace=True)
    finally:
        cell.close()
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
    from pipeline.evaluate import evaluate

    cfg = smoke_cfg("evaluate", "planner=dexnet", "evaluate.dexnet_variant=planarity",
                    "evaluate.boxes_per_trial=1", "evaluate.max_attempts_per_trial=2",
                    "evaluate.workers=1")
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
    from pipeline.evaluate import evaluate

    cfg = smoke_cfg("evaluate", "evaluate.planners=[dcnn,magic]")
    with pytest.raises(ValueError, match="magic"):
        evaluate(cfg)
