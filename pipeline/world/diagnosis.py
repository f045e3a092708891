"""Why a trial ended "no grasp" (docs/closed_loop.md, "Why a trial ended 'no grasp'").

Two records of the home image a trial ended on, made after the trial has ended; neither changes
what the robot does:

- ``labels_at_no_grasp``: whether the labelling stage's labels on that image hold a grasp that
  passes the same selection (``evaluate.label_no_grasp``): perception or execution lost the
  boxes left;
- ``final_home_record``: the image, the planner's candidates and the boxes left, for the logs
  (``TrialResult.final_home``).
"""

from __future__ import annotations

import numpy as np

from pipeline.world.cell import PickCell


def labels_at_no_grasp(runner, obs) -> dict:
    """For a ``TrialRunner``'s "no grasp" end on the home observation ``obs``: the labelling
    stage's graspable points on the same image (the oracle's grasps, ``pipeline.world.oracle``,
    after the robot's area check) and whether one of them passes the robot's own selection
    (``RobotController.select``: the run-time check, with the trial's retry memory).

    Returns ``{"label_candidates": int, "label_executable": bool}``; ``label_executable`` true:
    the labels hold a grasp the robot would have executed, so the planner's perception lost the
    boxes; false: execution could not take any labelled point either. The oracle planner is made
    once per runner (``runner.oracle``); the wall times the check adds to the robot side's
    timings are dropped."""
    if runner.oracle is None:
        from pipeline.world.oracle import OraclePlanner

        runner.oracle = OraclePlanner(runner.cfg, runner.cell)
    ctrl = runner.robot_side
    lengths = {k: len(v) for k, v in ctrl.timings.items()}
    seen = ctrl.perceive(obs)
    labels = ctrl.large_enough(seen, runner.oracle.plan(obs, None))
    executable = bool(labels) and ctrl.select(seen, labels).plan is not None
    for k, n in lengths.items():  # the diagnosis is not the planner's or the servo's time
        del ctrl.timings[k][n:]
    return {"label_candidates": len(labels), "label_executable": executable}


def final_home_record(cell: PickCell, obs, cands: list) -> dict:
    """``TrialResult.final_home`` of the home observation ``obs`` with the planner's grasps
    ``cands``: ``depth_m`` (H, W) float32 metres, 0 = no data; ``T_world_cam`` (4, 4);
    ``candidates_px`` (K, 2) the grasps' (u, v), pixels; ``boxes_left``: one {"body", "type",
    "position"} per box in the bin (position: (3,) world frame, metres)."""
    boxes = []
    for body in cell.boxes_in_bin():
        boxes.append(
            {
                "body": int(body),
                "type": str(cell.boxes[body]["type"]),
                "position": np.asarray(cell.box_pose(body)[0], np.float64),
            }
        )
    uv = np.array([[float(c.u), float(c.v)] for c in cands], np.float64).reshape(-1, 2)
    return {
        "depth_m": np.asarray(obs.depth_m, np.float32),
        "T_world_cam": np.asarray(obs.T_world_cam, np.float64),
        "candidates_px": uv,
        "boxes_left": boxes,
    }
