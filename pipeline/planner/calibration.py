"""Calibrating th of Eq. 3 on the validation split: one threshold for every use of the model.

The paper gives no value for th. With the focal loss (α = 0.25, Eqs. 4–6) the network's class
probabilities are low, so a fixed th = 0.5 leaves many images without any candidate. The
training stage therefore chooses th on the *validation* split by this rule and stores it in
``model.pt``; Table 1, Table 2, the closed loop and the robustness study all read it from there.

**Rule.** For each th on ``grid`` (ascending), the planner's optimal grasp point G_opt (the first
candidate of Eq. 7's ranking among the cells with S = max_c p(c) > th and a class other than NG,
``pipeline.planner.ranking``) is scored on every validation image that has at least one
graspable (R, L or B) label point:

* **correct**: a label point of the *same class* lies within ``radius_px`` pixels of G_opt;
* an image where nothing clears th is a miss.

th is the grid value with the largest share of correct G_opt; among equal shares the lowest th
(it keeps more candidates for the closed loop's run-time check to walk). This is the quantity
the planner exists for: the grasp it proposes first, on images where a grasp exists.

The curve stored beside the choice also gives, for each th, the share of images with no
candidate and the pooled precision, recall and F1 of all detections above th (matched as in
Table 1, ``pipeline.planner.evaluate.match_image``).

**Why G_opt at th is a prefix scan.** With the paper's ranking policy a candidate's J (Eq. 7)
does not depend on the other candidates, so the ranked list at a higher th is the ranked list at
the grid's lowest th with the candidates at or below th removed, in the same order. G_opt at th
is therefore the first candidate of the lowest-th ranking whose probability exceeds th, and one
ranking per image serves the whole grid.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.labelling.types import GraspClass
from pipeline.planner.evaluate import ImagePredictions, match_image


@dataclass
class RankedImage:
    """One validation image: the planner's candidates at the grid's lowest th, in Eq. 7's order.

    ``uv`` (K, 2) px, ``classes`` (K,) int, ``probabilities`` (K,) S of each candidate;
    ``gt_uv`` (G, 2) px and ``gt_classes`` (G,) int: the image's label points (NG ignored).
    """

    uv: np.ndarray
    classes: np.ndarray
    probabilities: np.ndarray
    gt_uv: np.ndarray
    gt_classes: np.ndarray


def has_graspable(gt_classes: np.ndarray) -> bool:
    """Whether an image has at least one graspable (R, L or B) label point."""
    return bool(np.any(np.asarray(gt_classes).reshape(-1) != GraspClass.NG))


def gopt_correct(img: RankedImage, threshold: float, radius_px: float) -> bool | None:
    """Whether G_opt at ``threshold`` is correct (module docstring); None when the image has no
    graspable label point (not scored). No candidate above th: False."""
    if not has_graspable(img.gt_classes):
        return None
    probs = np.asarray(img.probabilities, np.float64).reshape(-1)
    above = np.nonzero(probs > threshold)[0]
    if len(above) == 0:
        return False
    k = int(above[0])
    keep = np.asarray(img.gt_classes).reshape(-1) != GraspClass.NG
    gt_uv = np.asarray(img.gt_uv, np.float64).reshape(-1, 2)[keep]
    gt_cls = np.asarray(img.gt_classes).reshape(-1)[keep]
    uv = np.asarray(img.uv, np.float64).reshape(-1, 2)[k]
    near = np.linalg.norm(gt_uv - uv, axis=1) <= radius_px
    return bool(np.any(near & (gt_cls == int(np.asarray(img.classes).reshape(-1)[k]))))


def threshold_curve(images: list[RankedImage], grid: list[float], radius_px: float) -> list[dict]:
    """One row per th of ``grid``: ``threshold``, ``gopt_accuracy`` (share of scored images whose
    G_opt is correct), ``no_candidate`` (share of scored images with nothing above th),
    ``precision``, ``recall``, ``f1`` (pooled detections above th), ``scored_images``; None where
    a share has no denominator (no scored image, nothing above th)."""
    scored = [img for img in images if has_graspable(img.gt_classes)]
    num_gt = sum(int(np.sum(np.asarray(img.gt_classes) != GraspClass.NG)) for img in scored)
    rows = []
    for th in grid:
        th = float(th)
        correct = [gopt_correct(img, th, radius_px) for img in scored]
        empty = [not np.any(np.asarray(img.probabilities) > th) for img in scored]
        hits = taken = 0
        for img in scored:
            probs = np.asarray(img.probabilities, np.float64).reshape(-1)
            sel = probs > th
            if not sel.any():
                continue
            matched = match_image(ImagePredictions(
                uv=np.asarray(img.uv, np.float64).reshape(-1, 2)[sel],
                classes=np.asarray(img.classes).reshape(-1)[sel], scores=probs[sel],
                gt_uv=img.gt_uv, gt_classes=img.gt_classes), radius_px)
            hits += int(matched.sum())
            taken += int(sel.sum())
        precision = hits / taken if taken else None
        recall = hits / num_gt if num_gt else None
        f1 = (2 * precision * recall / (precision + recall)
              if precision is not None and recall is not None and precision + recall > 0
              else 0.0)
        n = len(scored)
        rows.append({"threshold": th,
                     "gopt_accuracy": float(np.mean(correct)) if n else None,
                     "no_candidate": float(np.mean(empty)) if n else None,
                     "precision": precision, "recall": recall, "f1": f1, "scored_images": n})
    return rows


def choose_threshold(curve: list[dict]) -> float:
    """th of the row with the largest ``gopt_accuracy``; among equal ones the lowest th."""
    valid = [r for r in curve if r["gopt_accuracy"] is not None]
    if not valid:
        raise ValueError("threshold calibration has no validation image with a graspable label "
                         "point: generate more validation scenes (generate.num_val_scenes)")
    best = max(r["gopt_accuracy"] for r in valid)
    return min(r["threshold"] for r in valid if r["gopt_accuracy"] == best)
