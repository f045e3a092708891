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

from pipeline.world.cell import Frame, PickCell


def labels_at_no_grasp(runner, frame: Frame, failed: list[dict]) -> dict:
    """For a ``PickRunner``'s "no grasp" end: the labelling stage's graspable points on the
    same home ``frame`` (the oracle's candidates, ``pipeline.world.oracle``, after the area
    check ``runner.large_enough``) and whether one of them passes the same selection
    (``runner.select``: the run-time check with the trial's retry memory ``failed``).

    Returns ``{"label_candidates": int, "label_executable": bool}``; ``label_executable`` true:
    the labels hold a grasp the robot would have executed, so the planner's perception lost the
    boxes; false: execution could not take any labelled point either. The oracle planner is made
    once per runner (``runner.oracle``); the wall times the check adds to ``runner.timings`` are
    dropped."""
    if runner.oracle is None:
        from pipeline.world.oracle import OraclePlanner

        runner.oracle = OraclePlanner(runner.cfg, runner.cell)
    lengths = {k: len(v) for k, v in runner.timings.items()}
    labels = runner.large_enough(frame, runner.oracle(frame.depth_m, runner.cell.intrinsics,
                                                      None, frame=frame))
    executable = bool(labels) and runner.select(frame, labels, failed) is not None
    for k, n in lengths.items():  # the diagnosis is not the planner's or the servo's time
        del runner.timings[k][n:]
    return {"label_candidates": len(labels), "label_executable": executable}


def final_home_record(cell: PickCell, frame: Frame, cands: list) -> dict:
    """``TrialResult.final_home`` of the home image ``frame`` with the planner's ``cands``:
    ``depth_m`` (H, W) float32 metres, 0 = no data; ``T_world_cam`` (4, 4); ``candidates_px``
    (K, 2) the candidates' (u, v), pixels; ``boxes_left``: one {"body", "type", "position"}
    per box in the bin (position: (3,) world frame, metres)."""
    boxes = []
    for body in cell.boxes_in_bin():
        boxes.append({"body": int(body), "type": str(cell.boxes[body]["type"]),
                      "position": np.asarray(cell.box_pose(body)[0], np.float64)})
    uv = np.array([[float(c.u), float(c.v)] for c in cands], np.float64).reshape(-1, 2)
    return {"depth_m": np.asarray(frame.depth_m, np.float32),
            "T_world_cam": np.asarray(frame.T_world_cam, np.float64),
            "candidates_px": uv, "boxes_left": boxes}
