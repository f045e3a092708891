"""The oracle planner: its candidates are the labelling stage's graspable labels of the home
image, ranked by Eq. 7."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest


def test_oracle_candidates_equal_the_labels(smoke_cfg):
    from pipeline.grasping.types import GraspClass
    from pipeline.labelling.robot_check import RobotChecker
    from pipeline.labelling.scene import label_scene
    from pipeline.robot.model import Robot, robot_config
    from pipeline.world.cell import PickCell
    from pipeline.world.oracle import OraclePlanner

    cfg = smoke_cfg("evaluate", "evaluate.boxes_per_trial=8")
    cell = PickCell(cfg, lambda: Robot(robot_config(cfg)))
    try:
        cell.reset(np.random.default_rng([5, 31, 0]), 8)
        obs = cell.observe()
        frame = cell.last_frame
        oracle = OraclePlanner(cfg, cell)
        cands = oracle.plan(obs, None)
        scene = oracle.scene(frame, cell.intrinsics)
        rows, _, _, _ = label_scene(
            scene, cfg, RobotChecker(cfg), cfg.bin, density=float(cfg.eval_boxes.density)
        )
    finally:
        cell.close()
    ok = rows["grasp_class"] != int(GraspClass.NG)
    labels = {
        (round(float(u), 3), round(float(v), 3), int(c))
        for (u, v), c in zip(rows["uv"][ok], rows["grasp_class"][ok])
    }
    got = {(round(c.u, 3), round(c.v, 3), int(GraspClass[c.pattern])) for c in cands}
    assert len(labels) >= 3
    assert got == labels
    scores = [c.score for c in cands]
    assert scores == sorted(scores, reverse=True)  # Eq. 7, best first
    # it plans on the latest observation only
    with pytest.raises(ValueError, match="latest observation"):
        oracle.plan(dataclasses.replace(obs, T_world_cam=np.eye(4)), None)
    # the scene it labels holds the heap: every box in the mask is a box of the cell
    assert set(np.unique(scene.mask)) - {0} <= set(range(1, len(scene.boxes) + 1))
