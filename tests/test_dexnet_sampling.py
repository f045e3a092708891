"""Dex-Net suction sampling (gqcnn DepthImageSuctionPointSampler) and disc planarity, on synthetic
depth images whose answers are worked out by hand.

Camera for every test: 200 x 200 px, fx = fy = 200, cx = cy = 99.5 (the optical axis passes
between the four central pixels). At z = 0.5 m one pixel spans 0.5 / 200 = 2.5 mm.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from conftest import default_config

from pipeline.camera.geometry import Intrinsics
from pipeline.dexnet.quality import PlanarityConfig, disc_planarity
from pipeline.dexnet.sampling import (
    Candidates,
    SamplerConfig,
    candidates_at,
    point_cloud_image,
    sample_candidates,
)

INTR = Intrinsics(200, 200, 200.0, 200.0, 99.5, 99.5)
SAMPLER, PLANARITY = default_config(SamplerConfig), default_config(PlanarityConfig)  # conf/
Z0 = 0.5


def level_plane(z=Z0):
    return np.full((200, 200), z)


def tilted_plane(deg, z0=Z0):
    """Plane z - tan(deg) * y = z0 (rotated `deg` about camera x), seen along each pixel's ray:
    with y = (v - cy) / fy * z, z = z0 / (1 - tan(deg) * (v - cy) / fy). Its camera-facing normal
    is (0, sin, -cos), so the approach axis is (0, -sin, cos) and the angle to +z is `deg`."""
    v = np.arange(200, dtype=np.float64)[:, None]
    z = z0 / (1.0 - np.tan(np.deg2rad(deg)) * (v - INTR.cy) / INTR.fy)
    return np.broadcast_to(z, (200, 200)).copy()


def step(height=0.02, col=100):
    """Floor at 0.5 m for u < col, a surface `height` closer to the camera for u >= col."""
    d = level_plane()
    d[:, col:] = Z0 - height
    return d


def test_level_plane_normals_axis_angle():
    cloud = point_cloud_image(level_plane(), INTR, SAMPLER)
    # Interior pixels: normal (0, 0, -1) faces the camera; the 1-px rim is invalid (the 3x3 Sobel
    # window leaves the image).
    assert cloud.valid[1:-1, 1:-1].all()
    assert not cloud.valid[0].any() and not cloud.valid[:, -1].any()
    np.testing.assert_allclose(
        cloud.normals[1:-1, 1:-1], np.broadcast_to([0, 0, -1.0], (198, 198, 3)), atol=1e-12
    )
    # Pixel (u, v) = (100, 100) is half a pixel right/below the axis: x = y = 0.5 / 200 * 0.5.
    np.testing.assert_allclose(cloud.points[100, 100], [0.00125, 0.00125, 0.5])
    cands = sample_candidates(cloud, 50, np.random.default_rng(0), SAMPLER)
    assert len(cands) == 50
    np.testing.assert_allclose(cands.axis, np.broadcast_to([0, 0, 1.0], (50, 3)), atol=1e-12)
    np.testing.assert_allclose(cands.angle, 0.0, atol=1e-6)
    np.testing.assert_allclose(cands.depth, 0.5)
    assert cands.uv.dtype == np.int64 and cands.uv.shape == (50, 2)


def test_tilted_plane_20_degrees():
    cloud = point_cloud_image(tilted_plane(20.0), INTR, SAMPLER)
    cands = sample_candidates(cloud, 100, np.random.default_rng(1), SAMPLER)
    assert len(cands) == 100
    np.testing.assert_allclose(np.rad2deg(cands.angle), 20.0, atol=0.5)
    s, c = np.sin(np.deg2rad(20)), np.cos(np.deg2rad(20))
    np.testing.assert_allclose(cands.axis, np.broadcast_to([0, -s, c], (100, 3)), atol=1e-6)
    # n . p < 0 everywhere: normals face the camera.
    assert np.all(np.einsum("ij,ij->i", -cands.axis, cands.point) < 0)


def test_tilted_plane_40_degrees_gives_nothing():
    cloud = point_cloud_image(tilted_plane(40.0), INTR, SAMPLER)
    assert cloud.valid[1:-1, 1:-1].all()  # valid, but too steep for suction
    assert len(sample_candidates(cloud, 50, np.random.default_rng(2), SAMPLER)) == 0
    # ...unless the limit is raised past 40 degrees.
    cands = sample_candidates(
        cloud,
        10,
        np.random.default_rng(2),
        dataclasses.replace(SAMPLER, max_approach_angle_deg=45.0),
    )
    assert len(cands) == 10
    np.testing.assert_allclose(np.rad2deg(cands.angle), 40.0, atol=0.5)


@pytest.mark.parametrize("border", [68, 20, 0])
def test_sampled_pixels_respect_border_and_validity(border):
    cfg = dataclasses.replace(SAMPLER, border_px=border)
    cloud = point_cloud_image(level_plane(), INTR, cfg)
    cands = sample_candidates(cloud, 500, np.random.default_rng(3), cfg)
    assert len(cands) == 500
    u, v = cands.uv[:, 0], cands.uv[:, 1]
    # Distance to the first and last pixel centres is >= border on every side.
    assert u.min() >= border and v.min() >= border
    assert u.max() <= 199 - border and v.max() <= 199 - border
    assert cloud.valid[v, u].all()
    assert len(np.unique(cands.uv, axis=0)) == 500  # drawn without replacement, as gqcnn


def test_holes_and_their_rim_never_sampled():
    d = level_plane()
    d[90:110, 90:110] = 0.0  # a 20 x 20 px hole in the middle
    d[120, 70] = np.nan  # non-finite depth also counts as no data
    cloud = point_cloud_image(d, INTR, SAMPLER)
    # Pixels whose 3x3 Sobel window touches the hole are invalid: rows/cols 89..110.
    assert not cloud.valid[89:111, 89:111].any()
    assert cloud.valid[88, 100] and cloud.valid[111, 100]
    assert not cloud.valid[119:122, 69:72].any()
    np.testing.assert_array_equal(cloud.points[95, 95], 0.0)
    np.testing.assert_array_equal(cloud.normals[95, 95], 0.0)
    cands = sample_candidates(
        cloud, 2000, np.random.default_rng(4), dataclasses.replace(SAMPLER, border_px=0)
    )
    u, v = cands.uv[:, 0], cands.uv[:, 1]
    assert len(cands) == 2000
    assert np.all(d[v, u] > 0)
    assert not np.any((u >= 89) & (u <= 110) & (v >= 89) & (v <= 110))


def test_step_edge_pixels_rejected_by_the_angle_limit():
    # Decision (see sampling.py): no separate edge detector, as in gqcnn. On a 2 cm step at
    # u = 100, the Sobel windows of columns 99 and 100 span the step: gx ~ (4.95 mm, 0, -20 mm),
    # so the normal tilts atan(20 / 4.95) ~ 76 deg from the optical axis -> rejected (> 30 deg).
    # Columns 98 and 101 see only one level -> axis (0, 0, 1), accepted.
    cloud = point_cloud_image(step(0.02), INTR, SAMPLER)
    uv = np.array([[u, 100] for u in range(97, 103)])
    cands, ok = candidates_at(cloud, uv, SAMPLER)
    np.testing.assert_array_equal(ok, [True, True, False, False, True, True])
    np.testing.assert_allclose(cands.angle, 0.0, atol=1e-9)
    np.testing.assert_allclose(cands.depth, [0.5, 0.5, 0.48, 0.48])
    tilt = np.rad2deg(np.arccos(-cloud.normals[100, 99:101, 2]))
    assert np.all(tilt > 70)
    samples = sample_candidates(
        cloud, 2000, np.random.default_rng(5), dataclasses.replace(SAMPLER, border_px=0)
    )
    assert len(samples) == 2000
    assert not np.isin(samples.uv[:, 0], [99, 100]).any()


def test_low_step_passes_the_angle_limit_like_dexnet():
    # Documented limit of the Sobel normal: a 1 mm step tilts the edge normals only by
    # atan(1 / ~5) ~ 11 deg, so they pass the 30 deg test (Dex-Net does the same); the quality
    # function has to catch it.
    cloud = point_cloud_image(step(0.001), INTR, SAMPLER)
    _, ok = candidates_at(cloud, np.array([[99, 100], [100, 100]]), SAMPLER)
    assert ok.all()


def test_candidates_at_ok_flags():
    d = tilted_plane(0.0)
    d[110:140, 140:199] = tilted_plane(40.0)[110:140, 140:199]  # a steep patch
    d[70, 80] = 0.0  # a one-pixel hole
    mask = np.ones((200, 200), bool)
    mask[120, 100] = False
    cfg = dataclasses.replace(SAMPLER, border_px=20)
    cloud = point_cloud_image(d, INTR, cfg, object_mask=mask)
    uv = np.array(
        [
            [100, 100],  # fine
            [-1, 100],  # outside the image
            [100, 200],  # outside the image
            [19, 100],  # in the border (u < 20)
            [20, 100],  # exactly on the border distance: accepted
            [179, 100],  # 199 - 179 = 20: accepted
            [180, 100],  # 199 - 180 = 19: in the border
            [80, 70],  # the hole
            [81, 71],  # Sobel window touches the hole -> invalid
            [160, 120],  # steep patch (40 deg)
            [100, 120],  # outside the object mask
        ]
    )
    cands, ok = candidates_at(cloud, uv, cfg)
    np.testing.assert_array_equal(ok, [1, 0, 0, 0, 1, 1, 0, 0, 0, 0, 0])
    np.testing.assert_array_equal(cands.uv, uv[ok])
    assert len(cands) == 3
    # Float pixels are rounded to the nearest pixel.
    c2, ok2 = candidates_at(cloud, np.array([[99.6, 100.4]]), cfg)
    assert ok2.all() and tuple(c2.uv[0]) == (100, 100)
    c3, ok3 = candidates_at(cloud, np.zeros((0, 2), np.int64), cfg)
    assert len(c3) == 0 and ok3.shape == (0,)


def test_object_mask_restricts_sampling_and_few_valid_pixels_give_fewer():
    mask = np.zeros((200, 200), bool)
    mask[100:103, 90:93] = True  # 9 pixels
    cloud = point_cloud_image(level_plane(), INTR, SAMPLER, object_mask=mask)
    assert cloud.valid.sum() == 9
    cands = sample_candidates(cloud, 50, np.random.default_rng(6), SAMPLER)
    assert len(cands) == 9  # fewer than asked: tries run out
    assert mask[cands.uv[:, 1], cands.uv[:, 0]].all()
    empty = point_cloud_image(level_plane(), INTR, SAMPLER, object_mask=np.zeros((200, 200), bool))
    assert len(sample_candidates(empty, 50, np.random.default_rng(6), SAMPLER)) == 0


def test_max_tries_caps_the_draws():
    # With border 68 only 64 x 64 of the 198 x 198 valid pixels are acceptable (~10 %): 20 tries
    # accept ~2, never more than 20.
    cloud = point_cloud_image(level_plane(), INTR, SAMPLER)
    cands = sample_candidates(
        cloud, 50, np.random.default_rng(7), dataclasses.replace(SAMPLER, max_tries=20)
    )
    assert len(cands) <= 20 and len(cands) < 50


def test_sampling_is_deterministic():
    cloud = point_cloud_image(level_plane(), INTR, SAMPLER)
    a = sample_candidates(cloud, 100, np.random.default_rng(8), SAMPLER)
    b = sample_candidates(cloud, 100, np.random.default_rng(8), SAMPLER)
    np.testing.assert_array_equal(a.uv, b.uv)


def test_candidates_take_concat_empty():
    cloud = point_cloud_image(level_plane(), INTR, SAMPLER)
    c = sample_candidates(cloud, 5, np.random.default_rng(9), SAMPLER)
    t = c.take([4, 0])
    np.testing.assert_array_equal(t.uv, c.uv[[4, 0]])
    assert len(c.take(np.array([True, False, True, False, False]))) == 2
    cc = Candidates.concat([c, Candidates.empty(), t])
    assert len(cc) == 7 and cc.point.shape == (7, 3)
    assert len(Candidates.concat([])) == 0 and Candidates.empty().uv.shape == (0, 2)


# ---------------------------------------------------------------------------------- planarity


def _cand(cloud, u, v, axis=(0.0, 0.0, 1.0)):
    """A hand-built candidate at pixel (u, v) with the given axis (even where the pixel itself is
    a hole: its point is then the level plane's point, z = 0.5)."""
    z = Z0
    p = [(u - INTR.cx) / INTR.fx * z, (v - INTR.cy) / INTR.fy * z, z]
    a = np.asarray(axis, float)
    return Candidates(
        uv=np.array([[u, v]]),
        point=np.array([p]),
        axis=a[None] / np.linalg.norm(a),
        depth=np.array([z]),
        angle=np.array([np.arccos(a[2] / np.linalg.norm(a))]),
    )


def test_disc_planarity_flat_and_tilted_planes():
    for deg in (0.0, 20.0):
        cloud = point_cloud_image(tilted_plane(deg), INTR, SAMPLER)
        cands = sample_candidates(cloud, 50, np.random.default_rng(10), SAMPLER)
        q = disc_planarity(cloud, cands, PLANARITY)
        assert q.shape == (50,)
        np.testing.assert_allclose(q, 1.0, atol=1e-6)


def test_disc_planarity_step_edge():
    # 2 cm step at u = 100. The disc (r = 9 mm, 3.6 px at 0.5 m) around u = 97 (floor) reaches
    # the upper surface at u = 100: its points there lie 7.45 mm to the side (< 9 mm) and 20 mm
    # above the approach plane -> mean squared residual >> sigma^2 = 1 mm^2 -> q ~ exp(-80).
    cloud = point_cloud_image(step(0.02), INTR, SAMPLER)
    cands, ok = candidates_at(
        cloud,
        np.array([[97, 100], [102, 100], [60, 100], [140, 100]]),
        dataclasses.replace(SAMPLER, border_px=0),
    )
    assert ok.all()
    q = disc_planarity(cloud, cands, PLANARITY)
    assert q[0] < 0.1 and q[1] < 0.1
    np.testing.assert_allclose(q[2:], 1.0, atol=1e-6)  # far from the edge: flat


def test_disc_planarity_holes():
    # Disc of radius 3.6 px around (100, 100) on the level plane: its footprint holds the 37
    # pixels with du^2 + dv^2 <= 3.6^2 (7 + 2*7 + 2*5 + 2*3). A 5 x 5 hole removes 25 of them:
    # coverage 12/37 = 0.32 < 0.8 -> q = 0. A single missing pixel leaves 36/37 -> q = 1.
    d = level_plane()
    d[98:103, 98:103] = 0.0
    cloud = point_cloud_image(d, INTR, SAMPLER)
    assert disc_planarity(cloud, _cand(cloud, 100, 100), PLANARITY)[0] == 0.0
    d1 = level_plane()
    d1[101, 101] = 0.0
    cloud1 = point_cloud_image(d1, INTR, SAMPLER)
    np.testing.assert_allclose(
        disc_planarity(cloud1, _cand(cloud1, 100, 100), PLANARITY), 1.0, atol=1e-9
    )
    # Stricter coverage requirement turns that into 0 as well.
    assert (
        disc_planarity(
            cloud1, _cand(cloud1, 100, 100), dataclasses.replace(PLANARITY, min_coverage=0.99)
        )[0]
        == 0.0
    )


def test_disc_planarity_wrong_axis_is_penalised():
    # On the level plane, an axis tilted 20 deg gives residuals up to 9 mm * tan(20) = 3.3 mm.
    cloud = point_cloud_image(level_plane(), INTR, SAMPLER)
    s, c = np.sin(np.deg2rad(20)), np.cos(np.deg2rad(20))
    q = disc_planarity(cloud, _cand(cloud, 100, 100, axis=(0.0, -s, c)), PLANARITY)
    assert q[0] < 0.1
    assert disc_planarity(cloud, Candidates.empty(), PLANARITY).shape == (0,)
