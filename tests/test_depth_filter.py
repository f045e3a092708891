"""Depth preprocessing before planning (pipeline/camera/depth_filter.py), on hand-worked cases.

Synthetic (H, W) float32 depth images in metres, 0 = no data. Hole filling is a 3 × 3 maximum
over the pixels with data, applied to the holes only, ``iterations`` = n times, accepted only
from a hole's far side: a fill value must be within 1 cm of the farthest depth with data within
2n + 1 pixels. Inside one surface each pass closes one pixel of a hole from every side; between
a near and a far surface, one pixel per pass from the far side only.
"""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace as NS

import numpy as np
import pytest
from omegaconf import OmegaConf

from pipeline.camera.depth_filter import fill_holes, median_filter, preprocess_depth

CONF_FILTER = Path(__file__).resolve().parents[1] / "conf" / "depth_filter"


def filter_cfg(name: str):
    return OmegaConf.load(CONF_FILTER / f"{name}.yaml")


def band_hole(
    width_px: int,
    left: float = 0.6,
    right: float = 0.6,
    rows: int = 5,
    start: int = 3,
    cols: int = 20,
) -> np.ndarray:
    """``rows`` × ``cols`` image: ``left`` depth, then a hole ``width_px`` columns wide from
    column ``start`` across every row, then ``right`` depth."""
    z = np.full((rows, cols), left, np.float32)
    z[:, start + width_px :] = right
    z[:, start : start + width_px] = 0.0
    return z


# --- fill_holes ------------------------------------------------------------------------------


def test_single_pixel_hole_in_a_flat_image():
    z = np.full((5, 5), 0.6, np.float32)
    z[2, 2] = 0.0
    out = fill_holes(z, 1)
    np.testing.assert_array_equal(out, np.full((5, 5), 0.6, np.float32))
    assert out.dtype == np.float32
    assert z[2, 2] == 0.0  # the input is not modified


def test_hole_between_near_and_far_takes_the_far_depth():
    # A 1-px hole (column 3) between the near surface (0.5 m, columns 0–2) and the far one
    # (0.7 m, columns 4–): its 3 × 3 neighbours with data are 0.5 and 0.7; it takes 0.7.
    z = band_hole(1, left=0.5, right=0.7)
    out = fill_holes(z, 1)
    assert (out[:, 3] == np.float32(0.7)).all()
    np.testing.assert_array_equal(out[:, :3], z[:, :3])
    np.testing.assert_array_equal(out[:, 4:], z[:, 4:])
    # A 1-px hole in a single row (a gap inside a wider image): the same.
    z = np.full((5, 7), 0.7, np.float32)
    z[:, :3] = 0.5
    z[2, 3] = 0.0  # its neighbours: 0.5 on the left, 0.7 elsewhere
    assert fill_holes(z, 1)[2, 3] == np.float32(0.7)


def test_wide_hole_between_near_and_far_fills_from_the_far_side():
    # A 5-px hole (columns 3–7) between 0.5 (left) and 0.7 (right), n = 3 passes: every hole
    # pixel has the 0.7 surface within 2n + 1 = 7 px, so 0.5 (20 cm nearer) is never taken.
    # Pass 1 fills column 7 (0.7), pass 2 column 6, pass 3 column 5; columns 3–4 stay 0.
    z = band_hole(5, left=0.5, right=0.7)
    out = fill_holes(z, 3)
    np.testing.assert_array_equal(out[0, 3:8], np.array([0, 0, 0.7, 0.7, 0.7], np.float32))
    # 5 passes close it, all at the far depth.
    assert (fill_holes(z, 5)[:, 3:8] == np.float32(0.7)).all()
    # A 2-px hole: pass 1 fills column 4 from the right, pass 2 column 3.
    np.testing.assert_array_equal(
        fill_holes(band_hole(2, left=0.5, right=0.7), 1)[0, 3:5], np.array([0, 0.7], np.float32)
    )
    np.testing.assert_array_equal(
        fill_holes(band_hole(2, left=0.5, right=0.7), 2)[0, 3:5], np.array([0.7, 0.7], np.float32)
    )


def test_projector_shadow_band_is_filled_from_the_far_side():
    # The shadow band of tests/test_sensor_model.py (fx = 400, b = 0.025, box top 0.5 m over a
    # 0.7 m floor: 5 px on the floor beside the box). Here the box is on the left (the mirror
    # image, b < 0): columns 0–2 at 0.5, shadow columns 3–7, floor from column 8. With
    # conf/depth_filter/fill.yaml's 4 passes, columns 4–7 take the floor's depth and column 3
    # (next to the box) stays without data: the box never grows into its shadow.
    z = band_hole(5, left=0.5, right=0.7)
    out = fill_holes(z, int(filter_cfg("fill").fill_holes_px))
    assert (out[:, 4:8] == np.float32(0.7)).all() and (out[:, 3] == 0).all()
    assert (fill_holes(z, 5)[:, 3:8] == np.float32(0.7)).all()


@pytest.mark.parametrize("width, passes", [(1, 1), (2, 1), (3, 2), (4, 2), (7, 4), (8, 4), (9, 5)])
def test_passes_needed_to_close_a_hole(width, passes):
    # A hole spanning every row, bounded on both sides: each pass closes one column from each
    # side, so a k-px hole needs ceil(k / 2) passes; one pass fewer leaves the middle
    # k − 2 (passes − 1) columns: 1 px when k is odd, 2 px when k is even.
    z = band_hole(width)
    assert -(-width // 2) == passes
    assert (fill_holes(z, passes) == np.float32(0.6)).all()
    left = fill_holes(z, passes - 1)
    assert (left == 0).sum(axis=1).tolist() == [width - 2 * (passes - 1)] * z.shape[0]
    # The remaining hole is the middle of the band.
    first = 3 + passes - 1
    assert (left[:, first : first + width - 2 * (passes - 1)] == 0).all()


def test_four_passes_close_eight_pixels_but_not_nine():
    # conf/depth_filter/fill.yaml: 4 passes "close holes up to about 8 px wide".
    assert int(filter_cfg("fill").fill_holes_px) == 4
    assert (fill_holes(band_hole(8), 4) > 0).all()
    out = fill_holes(band_hole(9), 4)
    # Columns 3–11 were the hole: 3–6 and 8–11 filled, column 7 (the middle) still 0.
    assert (out == 0).sum() == 5 and (out[:, 7] == 0).all()


def test_square_hole_and_hole_at_the_border():
    # A 6 × 6 hole inside a 12 × 12 plane closes from all four sides (and the corners, through
    # the diagonal neighbours): 3 passes close it, 2 leave the central 2 × 2.
    z = np.full((12, 12), 0.6, np.float32)
    z[3:9, 3:9] = 0.0
    assert (fill_holes(z, 3) > 0).all()
    left = fill_holes(z, 2)
    assert (left == 0).sum() == 4 and (left[5:7, 5:7] == 0).all()
    # A hole at the image border has data on one side only: k px need k passes.
    z = np.full((4, 10), 0.6, np.float32)
    z[:, :4] = 0.0
    assert (fill_holes(z, 2)[:, :2] == 0).all() and (fill_holes(z, 2)[:, 2:] > 0).all()
    assert (fill_holes(z, 4) > 0).all()


def test_fill_leaves_data_alone_and_empty_images_empty():
    rng = np.random.default_rng(0)
    z = (0.6 + 0.01 * rng.standard_normal((20, 20))).astype(np.float32)
    z[rng.random((20, 20)) < 0.2] = 0.0
    before = z.copy()
    out = fill_holes(z, 2)
    np.testing.assert_array_equal(out[before > 0], before[before > 0])
    np.testing.assert_array_equal(z, before)  # not in place
    assert out is not z
    empty = np.zeros((6, 6), np.float32)
    assert (fill_holes(empty, 5) == 0).all()
    copy = fill_holes(z, 0)
    assert copy is not z and np.array_equal(copy, z)


# --- median_filter ---------------------------------------------------------------------------


@pytest.mark.parametrize("ksize", [3, 5])
def test_median_removes_a_spike_and_keeps_a_step(ksize):
    # A 5 cm spike on a flat plane at 0.6 m: 1 of 9 (or 25) window values: the median is 0.6.
    z = np.full((9, 9), 0.6, np.float32)
    z[4, 4] = 0.55
    np.testing.assert_array_equal(median_filter(z, ksize), np.full((9, 9), 0.6, np.float32))
    assert z[4, 4] == np.float32(0.55)  # not in place
    # A step between columns 4 (0.5) and 5 (0.7): a window on column 4 holds 2 (3 × 3) or 3
    # (5 × 5) columns of 0.5 against 1 or 2 of 0.7: its median is 0.5; mirrored on column 5.
    z = np.full((9, 10), 0.7, np.float32)
    z[:, :5] = 0.5
    np.testing.assert_array_equal(median_filter(z, ksize), z)


def test_median_reduces_noise():
    # σ = 1 mm white noise on a plane: a 5 × 5 median's std is about √(π/2) σ / 5 ≈ 0.25 σ
    # (the sample median's efficiency); ask for less than half.
    rng = np.random.default_rng(1)
    z = (0.6 + 0.001 * rng.standard_normal((60, 60))).astype(np.float32)
    out = median_filter(z, 5)[5:-5, 5:-5]
    assert np.std(out) < 0.5 * np.std(z)
    assert abs(float(np.mean(out)) - 0.6) < 2e-4


def test_median_keeps_zero_where_there_was_no_data():
    # A 1-px hole in a plane: the median of its window is 0.6, but it had no data: stays 0.
    z = np.full((7, 7), 0.6, np.float32)
    z[3, 3] = 0.0
    out = median_filter(z, 3)
    assert out[3, 3] == 0.0
    np.testing.assert_array_equal(out[z > 0], z[z > 0])


def test_median_keeps_data_next_to_holes():
    # Data only in the top-left 4 × 4 of a 9 × 9 image. The corner pixel (3, 3) has 4 pixels
    # with data in its 3 × 3 window and 5 without: the median over the window is 0.
    z = np.zeros((9, 9), np.float32)
    z[:4, :4] = 0.6
    out = median_filter(z, 3)
    np.testing.assert_array_equal(out > 0, z > 0)


@pytest.mark.parametrize("ksize", [0, 1, 2, 4, 7])
def test_median_size_other_than_3_or_5_raises(ksize):
    z = np.full((6, 6), 0.6, np.float32)
    with pytest.raises(ValueError, match="3 or 5"):
        median_filter(z, ksize)
    if ksize > 0:  # through the config; 0 is "off" there
        with pytest.raises(ValueError, match=rf"median_px={ksize}: use 0 \(off\), 3 or 5"):
            preprocess_depth(z, NS(fill_holes_px=0, median_px=ksize))


# --- preprocess_depth ------------------------------------------------------------------------


def test_preprocess_off_returns_the_input_itself():
    z = band_hole(3)
    assert preprocess_depth(z, None) is z
    assert preprocess_depth(z, filter_cfg("none")) is z
    assert preprocess_depth(z, NS(fill_holes_px=0, median_px=0)) is z


def test_preprocess_fill_then_median():
    rng = np.random.default_rng(2)
    z = (0.6 + 0.001 * rng.standard_normal((30, 30))).astype(np.float32)
    z[:, 10:13] = 0.0  # a 3-px shadow band: 2 passes close it
    z[20, 20] = 0.65  # a spike
    before = z.copy()
    fill = preprocess_depth(z, filter_cfg("fill"))  # 4 passes, no median
    np.testing.assert_array_equal(fill, fill_holes(z, 4))
    assert (fill > 0).all() and fill[20, 20] == np.float32(0.65)
    both = preprocess_depth(z, filter_cfg("fill_median"))  # then a 5 × 5 median
    np.testing.assert_array_equal(both, median_filter(fill_holes(z, 4), 5))
    assert (both > 0).all() and abs(float(both[20, 20]) - 0.6) < 0.003
    only_median = preprocess_depth(z, NS(fill_holes_px=0, median_px=3))
    assert (only_median[:, 10:13] == 0).all()  # no filling: the band stays empty
    np.testing.assert_array_equal(z, before)  # the input is not modified
    for out in (fill, both, only_median):
        assert out.dtype == np.float32 and out is not z


def test_preprocess_float64_input_gives_float32():
    z = band_hole(2).astype(np.float64)
    out = preprocess_depth(z, filter_cfg("fill_median"))
    assert out.dtype == np.float32 and (out == np.float32(0.6)).all()
    assert (z[:, 3:5] == 0).all()
