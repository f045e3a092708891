"""A trained planner run over a labelled split: Table 1 and the ranked candidates that calibrate
th (``pipeline.planner.calibration``). Used by training, the unseen-box study and the
robustness study.
"""

from __future__ import annotations

import numpy as np
import torch
from tqdm import tqdm

from pipeline.planner.data import GraspDataset
from pipeline.planner.decode import decode_output
from pipeline.planner.evaluate import ImagePredictions, precision_table
from pipeline.planner.planner import Planner

EVAL_BATCH = 16  # images per forward pass


@torch.no_grad()
def table1(planner: Planner, data: GraspDataset, radius_px: float, depth_of=None) -> dict:
    """Table 1 on a split at the planner's th (``planner.evaluate``; the old definitions too).

    ``depth_of(i)``: the (H, W) depth image, metres, the network sees for image i (default:
    ``data.depth_m``, the generation artifact's ``depth``); the ground truth is ``data.rows``.
    """
    depth_of = data.depth_m if depth_of is None else depth_of
    images = []
    for start in range(0, len(data), EVAL_BATCH):
        idx = list(range(start, min(start + EVAL_BATCH, len(data))))
        raw = planner.predict(np.stack([depth_of(i) for i in idx]))
        for k, i in enumerate(idx):
            preds = decode_output(raw[k], threshold=-1.0, image_size=planner.size)
            images.append(image_predictions(preds, data.rows[i]))
    return precision_table(images, radius_px, threshold=planner.ranking.threshold)


@torch.no_grad()
def ranked_images(
    planner: Planner, data: GraspDataset, progress: bool = False, desc: str = "planning"
) -> list[ImagePredictions]:
    """Every image of a split planned at the planner's th: its candidates in Eq. 7's order and
    its label points (``pipeline.planner.calibration``). ``desc``: the progress bar's label."""
    return [
        image_predictions(planner.plan(data.depth_m(i), data.intrinsics), data.rows[i])
        for i in tqdm(range(len(data)), desc=desc, unit="image", disable=not progress)
    ]


def image_predictions(points, rows: dict) -> ImagePredictions:
    """One image's predicted points (objects with ``u``, ``v``, ``grasp_class`` and
    ``probability``: decoded cells or ranked candidates, in their order) beside its label rows
    (``uv`` (M, 2) pixels, ``grasp_class`` (M,))."""
    return ImagePredictions(
        uv=np.array([[p.u, p.v] for p in points], np.float64).reshape(-1, 2),
        classes=np.array([int(p.grasp_class) for p in points], np.int64),
        scores=np.array([p.probability for p in points], np.float64),
        gt_uv=rows["uv"],
        gt_classes=rows["grasp_class"],
    )
