"""Calibrating th on the validation split, the strict Table 1 and validation-based stopping,
against answers worked out by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pipeline.grasping.types import GraspClass
from pipeline.planner.calibration import choose_threshold, gopt_correct, threshold_curve
from pipeline.planner.evaluate import ImagePredictions, precision_table
from pipeline.planner.fit import best_epoch, should_stop

R, L, B, NG = (int(c) for c in GraspClass)


def _img(uv, classes, probs, gt_uv, gt_classes):
    return ImagePredictions(
        np.array(uv, float).reshape(-1, 2),
        np.array(classes, int),
        np.array(probs, float),
        np.array(gt_uv, float).reshape(-1, 2),
        np.array(gt_classes, int),
    )


# Three validation images, candidates already in Eq. 7's order.
#   A: gt L at (100, 100). Candidates: R (300, 300) p 0.2 (wrong place), L (104, 100) p 0.6.
#      G_opt: th < 0.2 → the R (wrong); 0.2 <= th < 0.6 → the L (right); th >= 0.6 → none.
#   B: gt B at (50, 50). Candidates: B (55, 50) p 0.3.
#      th < 0.3 → right; th >= 0.3 → none (a miss).
#   C: only an NG label point: not scored, whatever it proposes.
A = _img([[300, 300], [104, 100]], [R, L], [0.2, 0.6], [[100, 100]], [L])
B_ = _img([[55, 50]], [B], [0.3], [[50, 50]], [B])
C = _img([[10, 10]], [L], [0.9], [[10, 10]], [NG])


def test_gopt_correct_by_hand():
    assert gopt_correct(A, 0.1, 16.0) is False  # the R at (300, 300) comes first
    assert gopt_correct(A, 0.2, 16.0) is True  # p > th: the R (0.2) is dropped at th = 0.2
    assert gopt_correct(A, 0.6, 16.0) is False  # nothing above th: a miss
    assert gopt_correct(B_, 0.25, 16.0) is True
    assert gopt_correct(B_, 0.25, 4.0) is False  # 5 px away
    assert gopt_correct(C, 0.1, 16.0) is None
    # The right place with the wrong class is wrong.
    wrong_class = _img([[100, 100]], [R], [0.9], [[100, 100]], [L])
    assert gopt_correct(wrong_class, 0.1, 16.0) is False


def test_threshold_curve_and_choice_by_hand():
    curve = threshold_curve([A, B_, C], [0.1, 0.25, 0.5, 0.7], 16.0)
    # G_opt over the scored images A and B: th 0.1: A wrong, B right → 1/2; 0.25: both right →
    # 1; 0.5: A right, B none → 1/2; 0.7: neither → 0.
    assert [r["gopt_accuracy"] for r in curve] == [0.5, 1.0, 0.5, 0.0]
    assert [r["no_candidate"] for r in curve] == [0.0, 0.0, 0.5, 1.0]
    assert all(r["scored_images"] == 2 for r in curve)
    # Detections on every image (C's L at 0.9 has no graspable truth: always wrong); 2 graspable
    # label points (A's L, B's B).
    #   th 0.1: A R ✗, A L ✓, B ✓, C ✗ → P 2/4, R 2/2, F1 2/3
    #   th 0.25: A L ✓, B ✓, C ✗ → P 2/3, R 1, F1 0.8
    #   th 0.5: A L ✓, C ✗ → P 1/2, R 1/2, F1 1/2
    #   th 0.7: C ✗ → P 0, R 0, F1 0
    assert [r["precision"] for r in curve] == pytest.approx([0.5, 2 / 3, 0.5, 0.0])
    assert [r["recall"] for r in curve] == pytest.approx([1.0, 1.0, 0.5, 0.0])
    assert [r["f1"] for r in curve] == pytest.approx([2 / 3, 0.8, 0.5, 0.0])
    assert choose_threshold(curve) == 0.25
    # Equal F1: the lowest th wins.
    tie = [dict(r, f1=0.5) for r in curve]
    assert choose_threshold(tie) == 0.1
    # Nothing above th anywhere: precision has no denominator.
    assert threshold_curve([A], [0.9], 16.0)[0]["precision"] is None


def test_choice_needs_a_scored_image():
    with pytest.raises(ValueError, match="num_val_scenes"):
        choose_threshold(threshold_curve([C], [0.1, 0.5], 16.0))


def _pred(uv, classes, scores, gt_uv, gt_classes):
    return ImagePredictions(
        np.array(uv, float).reshape(-1, 2),
        np.array(classes, int),
        np.array(scores, float),
        np.array(gt_uv, float).reshape(-1, 2),
        np.array(gt_classes, int),
    )


def test_table1_strict_definitions_by_hand():
    # Image P: gt L (100, 100), R (300, 300). Predictions: L (105, 100) 0.9 ✓, L (102, 100) 0.4
    #   ✗ (that L is taken), R (300, 305) 0.3 ✓.
    # Image Q: gt B (50, 50). Prediction: B (60, 50) 0.2 ✓ (below th = 0.25).
    # Image S: gt NG only. Prediction: L (10, 10) 0.95 ✗ (no graspable truth; not scored).
    p = _pred(
        [[105, 100], [102, 100], [300, 305]],
        [L, L, R],
        [0.9, 0.4, 0.3],
        [[100, 100], [300, 300]],
        [L, R],
    )
    q = _pred([[60, 50]], [B], [0.2], [[50, 50]], [B])
    s = _pred([[10, 10]], [L], [0.95], [[10, 10]], [NG])
    t = precision_table([p, q, s], 16.0, threshold=0.25)
    # Scored images: P and Q; Q has nothing above th → a miss. Top 1 = 1/2.
    assert t["scored_images"] == 2 and t["no_prediction_images"] == 1
    assert t["top1"] == 0.5
    # Pooled above th: 0.95 ✗ (S), 0.9 ✓, 0.4 ✗, 0.3 ✓ → M = 4; ceil(1 %·4) = 1: the 0.95 ✗.
    assert t["num_predictions"] == 4
    assert t["top1pct"] == t["top5pct"] == t["top10pct"] == 0.0
    # Per image: P has 3 above th, ceil(k·3) = 1 for k ≤ 10 % → its 0.9 ✓ → 1; Q → 0. Mean 1/2.
    assert t["per_image"] == {"top1pct": 0.5, "top5pct": 0.5, "top10pct": 0.5}
    # The old definition: no threshold, top 1 over images with a prediction (P ✓, Q ✓, S ✗).
    assert t["legacy"]["top1"] == pytest.approx(2 / 3)
    # Old pooled ranking of all 5: 0.95 ✗ first.
    assert t["legacy"]["top1pct"] == 0.0
    # Without a threshold the strict top 1 still skips S but counts Q: both right → 1.
    assert precision_table([p, q, s], 16.0)["top1"] == 1.0


def test_stopping_rule_by_hand():
    assert best_epoch([0.5, 0.4, 0.45, 0.4]) == 2  # the first of equal losses
    assert best_epoch([math.nan, math.nan]) is None
    assert not should_stop([0.5, 0.4, 0.45], 2)  # 1 epoch since the best
    assert should_stop([0.5, 0.4, 0.45, 0.41], 2)  # 2 epochs since the best
    assert not should_stop([0.5, 0.4, 0.45, 0.41], 0)  # 0: never
    assert not should_stop([math.nan] * 5, 1)  # no validation images: never
