"""Table 2's metric, on distances worked out by hand."""

import math

import numpy as np

from pipeline.planner.centre_distance import nearest_centre_distance, within_curve, within_rate


def test_nearest_centre_is_the_closest_one():
    centres = np.array([[100.0, 100.0], [130.0, 140.0]])
    # (127, 136) → (130, 140): a 3-4-5 triangle, 5 px; the other centre is 44.7 px away.
    assert nearest_centre_distance(np.array([127.0, 136.0]), centres) == 5.0


def test_no_grasp_is_a_miss_and_no_centre_is_not_scored():
    assert nearest_centre_distance(None, np.array([[1.0, 2.0]])) == math.inf
    assert math.isnan(nearest_centre_distance(np.array([1.0, 2.0]), np.zeros((0, 2))))


def test_within_rate_counts_misses_and_skips_unscored_images():
    d = np.array([3.0, 29.9, 30.0, 31.0, math.inf, math.nan])
    # Scored: 5 images (nan skipped); less than 30 px (the paper's words): 3.0 and 29.9 → 2 / 5.
    assert within_rate(d, 30.0) == 0.4
    # The earlier definition, at most 30 px, also counts the 30.0 → 3 / 5.
    assert within_rate(d, 30.0, inclusive=True) == 0.6
    assert list(within_curve(d, np.array([5, 30, 50]))) == [0.2, 0.4, 0.8]
