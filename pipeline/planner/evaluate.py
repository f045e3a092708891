"""Table 1 of the paper: precision of the DCNN's predictions on the test split.

Definition (the paper gives none; this is ours, also printed in the report):

* **Predictions.** Every cell of an image whose confidence S = max_c p(c) exceeds th (Eq. 3; the
  model's calibrated th, ``pipeline.planner.calibration``) gives one prediction: its point g
  (pixels), its class argmax_c p(c) and S. Cells whose class is NG are not predictions (the
  planner never outputs NG points).
* **Ground truth.** The labelled grasp points of class R, L or B of the image (all of them,
  including those the one-point-per-cell rule dropped from the training targets).
* **Correct.** Within one image, predictions are matched in descending S: a prediction is
  correct when a ground-truth point of the *same class* lies within ``radius_px`` pixels and
  has not been matched by a higher-ranked prediction (the nearest such point is taken).
* **Scored images.** Every test image with at least one graspable ground-truth point. An image
  where the planner proposes nothing is a miss, never skipped.
* **Top 1**: the share of scored images whose highest-S prediction is correct.
* **Top k % (pooled)**: all predictions of all test images pooled and sorted by S; the precision
  of the first ceil(k/100 · M) of the M predictions.
* **Top k % (per image)**: within each scored image, the precision of its first
  ceil(k/100 · M_i) predictions; the mean over scored images, an image with no prediction
  counting 0.
* **Old definition** (kept as one labelled row, ``legacy``): no threshold (every non-NG cell a
  prediction), top 1 averaged over the images that have a prediction, whatever their truth.
* **Precision–recall curve**: along the pooled ranking of every non-NG cell (no threshold),
  precision = correct / taken and recall = correct / (number of ground-truth points).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pipeline.grasping.types import GraspClass

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


def _pooled_top(scores: np.ndarray, correct: np.ndarray) -> dict:
    """Top k % (k of ``TOP_FRACTIONS``) of a pooled ranking; None when it is empty."""
    order = np.argsort(-scores, kind="stable")
    hits = np.cumsum(correct[order])
    out = {}
    for frac in TOP_FRACTIONS:
        n = math.ceil(frac * len(correct))
        out[f"top{round(frac * 100)}pct"] = float(hits[n - 1] / n) if n else None
    return out


def precision_table(
    images: list[ImagePredictions], radius_px: float, threshold: float | None = None
) -> dict:
    """Table 1 and the precision–recall curve (see the module docstring).

    Args:
        images: every cell's prediction of each test image (any score).
        radius_px: the matching radius.
        threshold: th of Eq. 3; predictions with S <= th are dropped. None: no threshold.

    Returns:
        dict with ``top1``, ``top1pct``, ``top5pct``, ``top10pct`` (fractions in [0, 1], None
        when there is nothing to score), ``per_image`` (the per-image top k %), ``legacy`` (the
        old definitions: no threshold, top 1 over images with a prediction), ``threshold``,
        ``num_predictions`` (above th), ``num_ground_truth``, ``num_images``, ``scored_images``,
        ``no_prediction_images`` (scored images with nothing above th), and ``pr_curve``:
        {"precision", "recall", "score"} arrays along the pooled ranking of every non-NG cell.
    """
    th = -math.inf if threshold is None else float(threshold)
    all_scores, all_correct, above_flags = [], [], []
    top1, legacy_top1, per_image = [], [], {f: [] for f in TOP_FRACTIONS}
    num_gt = no_prediction = 0
    for img in images:
        classes = np.asarray(img.classes).reshape(-1)
        scores = np.asarray(img.scores, np.float64).reshape(-1)
        gt_count = int(np.sum(np.asarray(img.gt_classes) != GraspClass.NG))
        num_gt += gt_count
        is_pred = classes != GraspClass.NG
        # Matching among every prediction and among those above th gives the same flags for the
        # ones above th: greedy matching in descending S never looks at lower scores first.
        correct = match_image(img, radius_px)
        if is_pred.any():
            best = np.nonzero(is_pred)[0][np.argmax(scores[is_pred])]
            legacy_top1.append(bool(correct[best]))
        above = is_pred & (scores > th)
        all_scores.append(scores[is_pred])
        all_correct.append(correct[is_pred])
        above_flags.append(above[is_pred])
        if gt_count == 0:
            continue
        if not above.any():
            no_prediction += 1
            top1.append(False)
            for frac in TOP_FRACTIONS:
                per_image[frac].append(0.0)
            continue
        idx = np.nonzero(above)[0]
        ranked = idx[np.argsort(-scores[idx], kind="stable")]
        top1.append(bool(correct[ranked[0]]))
        for frac in TOP_FRACTIONS:
            n = math.ceil(frac * len(ranked))
            per_image[frac].append(float(np.mean(correct[ranked[:n]])))
    scores = np.concatenate(all_scores) if all_scores else np.zeros(0)
    correct = np.concatenate(all_correct) if all_correct else np.zeros(0, bool)
    above = np.concatenate(above_flags) if above_flags else np.zeros(0, bool)
    out = {
        "threshold": None if threshold is None else float(threshold),
        "top1": float(np.mean(top1)) if top1 else None,
        **_pooled_top(scores[above], correct[above]),
        "per_image": {
            f"top{round(f * 100)}pct": (float(np.mean(v)) if v else None)
            for f, v in per_image.items()
        },
        "legacy": {
            "top1": float(np.mean(legacy_top1)) if legacy_top1 else None,
            **_pooled_top(scores, correct),
        },
        "num_predictions": int(above.sum()),
        "num_ground_truth": num_gt,
        "num_images": len(images),
        "scored_images": len(top1),
        "no_prediction_images": no_prediction,
        "radius_px": float(radius_px),
    }
    order = np.argsort(-scores, kind="stable")
    hits = np.cumsum(correct[order])
    taken = np.arange(1, len(correct) + 1)
    out["pr_curve"] = {
        "precision": hits / np.maximum(taken, 1),
        "recall": hits / max(num_gt, 1),
        "score": scores[order],
    }
    return out


def downsample_curve(curve: dict, points: int = 200) -> dict:
    """``points`` evenly spaced samples (by rank) of a PR curve, as lists for JSON."""
    n = len(curve["precision"])
    if n == 0:
        return {k: [] for k in curve}
    idx = np.unique(np.linspace(0, n - 1, min(points, n)).round().astype(int))
    return {k: [round(float(v), 6) for v in np.asarray(curve[k])[idx]] for k in curve}
