"""Calibrating th of Eq. 3 on the validation split: one threshold for every use of the model.

The paper gives no value for th. With the focal loss (α = 0.25, Eqs. 4–6) the network's class
probabilities are low, so a fixed th = 0.5 leaves many images without any candidate. The
training stage therefore chooses th on the *validation* split by this rule and stores it in
``model.pt``; Table 1, Table 2, the closed loop and the robustness study all read it from there.

**Rule.** For each th on ``grid`` (ascending), every candidate the planner returns on a
validation image (a cell with S = max_c p(c) > th, a class other than NG and depth data at its
point) is a detection. Detections are matched to the
image's label points as in Table 1 (``pipeline.planner.evaluate.match_image``: in descending S,
a detection is correct when a not yet matched label point of the *same class* lies within
``radius_px`` pixels). Pooled over every validation image (one without a graspable label point
contributes only wrong detections), precision = correct / detections and
recall = correct / graspable (R, L or B) label points. th is the grid value with the largest
F1 = 2 P R / (P + R); among equal F1 the lowest th.

F1 weighs the two ways a threshold fails the planner: too low, the list is full of wrong points
(precision); too high, the planner proposes nothing for faces that are graspable (recall, and
images with no candidate at all).

The curve stored beside the choice also gives, for each th, the share of images with no
candidate and the share whose optimal grasp point G_opt (the first candidate of Eq. 7's
ranking among the detections, ``pipeline.planner.ranking``) has a label point of its class
within ``radius_px`` (an image with nothing above th counting as a miss), over the validation
images that have a graspable label point.

**Why G_opt at th is a prefix scan.** With the paper's ranking policy a candidate's J (Eq. 7)
does not depend on the other candidates, so the ranked list at a higher th is the ranked list at
the grid's lowest th with the candidates at or below th removed, in the same order. G_opt at th
is therefore the first candidate of the lowest-th ranking whose probability exceeds th, and one
ranking per image serves the whole grid.
"""

from __future__ import annotations

import numpy as np

from pipeline.grasping.types import GraspClass
from pipeline.planner.evaluate import ImagePredictions, match_image

# An image here is an ``ImagePredictions`` whose rows are the planner's candidates at the grid's
# lowest th in Eq. 7's order, ``scores`` being each candidate's S = max_c p(c)
# (``pipeline.planner.scoring.ranked_images``).


def has_graspable(gt_classes: np.ndarray) -> bool:
    """Whether an image has at least one graspable (R, L or B) label point."""
    return bool(np.any(np.asarray(gt_classes).reshape(-1) != GraspClass.NG))


def gopt_correct(img: ImagePredictions, threshold: float, radius_px: float) -> bool | None:
    """Whether G_opt at ``threshold`` is correct (module docstring); None when the image has no
    graspable label point (not scored). No candidate above th: False."""
    if not has_graspable(img.gt_classes):
        return None
    probs = np.asarray(img.scores, np.float64).reshape(-1)
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


def threshold_curve(
    images: list[ImagePredictions], grid: list[float], radius_px: float
) -> list[dict]:
    """One row per th of ``grid``: ``threshold``, ``gopt_accuracy`` (share of scored images whose
    G_opt is correct), ``no_candidate`` (share of scored images with nothing above th),
    ``precision``, ``recall``, ``f1`` (pooled detections above th on every image),
    ``scored_images`` (images with a graspable label point); None where
    a share has no denominator (no scored image, nothing above th)."""
    scored = [img for img in images if has_graspable(img.gt_classes)]
    num_gt = sum(int(np.sum(np.asarray(img.gt_classes) != GraspClass.NG)) for img in images)
    rows = []
    for th in grid:
        th = float(th)
        correct = [gopt_correct(img, th, radius_px) for img in scored]
        empty = [not np.any(np.asarray(img.scores) > th) for img in scored]
        hits = taken = 0
        for img in images:
            probs = np.asarray(img.scores, np.float64).reshape(-1)
            sel = probs > th
            if not sel.any():
                continue
            matched = match_image(
                ImagePredictions(
                    uv=np.asarray(img.uv, np.float64).reshape(-1, 2)[sel],
                    classes=np.asarray(img.classes).reshape(-1)[sel],
                    scores=probs[sel],
                    gt_uv=img.gt_uv,
                    gt_classes=img.gt_classes,
                ),
                radius_px,
            )
            hits += int(matched.sum())
            taken += int(sel.sum())
        precision = hits / taken if taken else None
        recall = hits / num_gt if num_gt else None
        f1 = (
            2 * precision * recall / (precision + recall)
            if precision is not None and recall is not None and precision + recall > 0
            else 0.0
        )
        n = len(scored)
        rows.append(
            {
                "threshold": th,
                "gopt_accuracy": float(np.mean(correct)) if n else None,
                "no_candidate": float(np.mean(empty)) if n else None,
                "precision": precision,
                "recall": recall,
                "f1": f1,
                "scored_images": n,
            }
        )
    return rows


def choose_threshold(curve: list[dict]) -> float:
    """th of the row with the largest ``f1``; among equal ones the lowest th."""
    if not any(r["recall"] is not None for r in curve):
        raise ValueError(
            "threshold calibration has no validation image with a graspable label "
            "point: generate more validation scenes (generate.num_val_scenes)"
        )
    best = max(r["f1"] for r in curve)
    return min(r["threshold"] for r in curve if r["f1"] == best)
