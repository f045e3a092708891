"""Table 1 of the paper: precision of the DCNN's predictions on the test split.

Definition (the paper gives none; this is ours, also printed in the report):

* **Predictions.** Every cell of every test image gives one prediction: its point g (pixels),
  its class argmax_c p(c) and its confidence S = max_c p(c) (Eq. 3). Cells whose class is NG are
  not predictions (the planner never outputs NG points). No threshold: the ranking by S does
  the selecting.
* **Ground truth.** The labelled grasp points of class R, L or B of the image (all of them,
  including those the one-point-per-cell rule dropped from the training targets).
* **Correct.** Within one image, predictions are matched in descending S: a prediction is
  correct when a ground-truth point of the *same class* lies within ``radius_px`` pixels and
  has not been matched by a higher-ranked prediction (the nearest such point is taken).
* **Top 1**: the fraction of images whose highest-S prediction is correct (averaged over test
  images that have at least one prediction). **Top k %**: all predictions of all test images
  pooled and sorted by S; the precision of the first ceil(k/100 · M) of the M predictions.
* **Precision–recall curve**: along the pooled ranking, precision = correct / taken and recall
  = correct / (number of ground-truth points).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pipeline.labelling.types import GraspClass

TOP_FRACTIONS = (0.01, 0.05, 0.10)
PAPER_TABLE1 = {"top1": 0.8310, "top1pct": 0.8025, "top5pct": 0.6722, "top10pct": 0.5564}


@dataclass
class ImagePredictions:
    """One image's predictions and truth. ``uv`` (K, 2) px, ``classes`` (K,) int, ``scores``
    (K,) float confidence; ``gt_uv`` (G, 2) px, ``gt_classes`` (G,) int (NG rows are ignored)."""

    uv: np.ndarray
    classes: np.ndarray
    scores: np.ndarray
    gt_uv: np.ndarray
    gt_classes: np.ndarray


def match_image(pred: ImagePredictions, radius_px: float) -> np.ndarray:
    """(K,) bool: which predictions are correct, matched greedily in descending score."""
    uv = np.asarray(pred.uv, np.float64).reshape(-1, 2)
    classes = np.asarray(pred.classes).reshape(-1)
    scores = np.asarray(pred.scores, np.float64).reshape(-1)
    keep = np.asarray(pred.gt_classes).reshape(-1) != GraspClass.NG
    gt_uv = np.asarray(pred.gt_uv, np.float64).reshape(-1, 2)[keep]
    gt_cls = np.asarray(pred.gt_classes).reshape(-1)[keep]
    used = np.zeros(len(gt_uv), bool)
    correct = np.zeros(len(uv), bool)
    for k in np.argsort(-scores, kind="stable"):
        if classes[k] == GraspClass.NG:
            continue
        dist = np.linalg.norm(gt_uv - uv[k], axis=1)
        ok = (~used) & (gt_cls == classes[k]) & (dist <= radius_px)
        if ok.any():
            j = int(np.argmin(np.where(ok, dist, np.inf)))
            used[j] = True
            correct[k] = True
    return correct


def precision_table(images: list[ImagePredictions], radius_px: float) -> dict:
    """Table 1 and the precision–recall curve (see the module docstring).

    Returns:
        dict with ``top1``, ``top1pct``, ``top5pct``, ``top10pct`` (fractions in [0, 1], None
        when there is nothing to rank), ``num_predictions``, ``num_ground_truth``, ``num_images``,
        and ``pr_curve``: {"precision", "recall", "score"} arrays along the pooled ranking.
    """
    all_scores, all_correct, top1 = [], [], []
    num_gt = 0
    for img in images:
        classes = np.asarray(img.classes).reshape(-1)
        scores = np.asarray(img.scores, np.float64).reshape(-1)
        correct = match_image(img, radius_px)
        num_gt += int(np.sum(np.asarray(img.gt_classes) != GraspClass.NG))
        is_pred = classes != GraspClass.NG
        if is_pred.any():
            best = np.nonzero(is_pred)[0][np.argmax(scores[is_pred])]
            top1.append(bool(correct[best]))
        all_scores.append(scores[is_pred])
        all_correct.append(correct[is_pred])
    scores = np.concatenate(all_scores) if all_scores else np.zeros(0)
    correct = np.concatenate(all_correct) if all_correct else np.zeros(0, bool)
    order = np.argsort(-scores, kind="stable")
    scores, correct = scores[order], correct[order]
    hits = np.cumsum(correct)
    taken = np.arange(1, len(correct) + 1)
    out = {"top1": float(np.mean(top1)) if top1 else None,
           "num_predictions": int(len(correct)), "num_ground_truth": num_gt,
           "num_images": len(images), "radius_px": float(radius_px)}
    for frac in TOP_FRACTIONS:
        n = math.ceil(frac * len(correct))
        out[f"top{round(frac * 100)}pct"] = float(hits[n - 1] / n) if n else None
    out["pr_curve"] = {"precision": hits / np.maximum(taken, 1),
                       "recall": hits / max(num_gt, 1), "score": scores}
    return out


def downsample_curve(curve: dict, points: int = 200) -> dict:
    """``points`` evenly spaced samples (by rank) of a PR curve, as lists for JSON."""
    n = len(curve["precision"])
    if n == 0:
        return {k: [] for k in curve}
    idx = np.unique(np.linspace(0, n - 1, min(points, n)).round().astype(int))
    return {k: [round(float(v), 6) for v in np.asarray(curve[k])[idx]] for k in curve}
