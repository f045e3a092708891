"""The structured-light depth-sensor model (pipeline/camera/sensor.py), on hand-worked cases.

Synthetic numpy depth images only (no renderer). Conventions: OpenCV camera frame (x right,
y down, z forward), metres; pixel (u, v) sees the ray r = ((u − cx)/fx, (v − cy)/fy, 1) and a
depth z the point z · r.
"""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace as NS

import numpy as np
import pytest
from omegaconf import OmegaConf

from pipeline.camera.geometry import Intrinsics
from pipeline.camera.sensor import (
    apply_sensor_model,
    depth_steps,
    incidence_angles,
    noise_sigma,
    projector_shadow,
    steep_dropout,
)

CONF_SENSOR = Path(__file__).resolve().parents[1] / "conf" / "sensor"


def sensor_cfg(name: str = "sr300", **overrides) -> NS:
    """``conf/sensor/<name>.yaml`` as a namespace, with ``overrides`` (existing fields only)."""
    cfg = OmegaConf.to_container(OmegaConf.load(CONF_SENSOR / f"{name}.yaml"))
    assert set(cfg) >= set(overrides), "override of a field the sensor config lacks"
    return NS(**{**cfg, **overrides})


# Every missing-data mechanism off: only noise and quantisation remain.
NO_DROPOUT = dict(
    projector_baseline=0.0,
    dropout_angle_deg=90.0,
    edge_dropout_prob=0.0,
    min_range=0.0,
    max_range=100.0,
)


def test_sr300_yaml_has_every_schema_field():
    from dataclasses import fields

    from pipeline.config.physical import SensorConfig

    names = {f.name for f in fields(SensorConfig)}
    for yaml in ("sr300", "ideal", "d435"):
        assert set(OmegaConf.load(CONF_SENSOR / f"{yaml}.yaml")) == names


# --- incidence_angles ------------------------------------------------------------------------

# 41 × 41 with the principal point on pixel (20, 20): its ray is the optical axis (0, 0, 1).
CENTRED = Intrinsics(41, 41, 400.0, 400.0, 20.0, 20.0)


def test_incidence_fronto_parallel_plane():
    z = np.full((41, 41), 0.6)
    theta = np.degrees(incidence_angles(z, CENTRED))
    # Normal (0, 0, −1) ∥ the optical axis: θ = 0 at the principal point. Elsewhere θ is the
    # ray's angle to the axis: at (u, v) = (40, 20), atan(20 / 400) = 2.862°; at the corner
    # (0, 0), atan(√(20² + 20²) / 400) = atan(0.070711) = 4.044°.
    assert theta[20, 20] == pytest.approx(0.0, abs=1e-4)
    assert theta[20, 40] == pytest.approx(2.862, abs=1e-3)
    assert theta[0, 0] == pytest.approx(4.044, abs=1e-3)


def test_incidence_plane_tilted_30_degrees_about_x():
    # Plane through (0, 0, 0.6) with normal n = (0, sin 30°, −cos 30°) (it recedes down the
    # image). Ray z · (0, y, 1) meets it where z (y sin 30° − cos 30°) = −0.6 cos 30°:
    #     z(v) = 0.6 / (1 − tan 30° · y),  y = (v − 20) / 400, the same along each row.
    # In the y–z plane −n points 30° towards −y from +z and the ray atan(y) towards +y, so along
    # column u = 20 θ = 30° + atan(y): 30° at the principal point, 30° + atan(0.05) = 32.862°
    # at v = 40, 30° − 2.862° = 27.138° at v = 0. A plane's finite differences lie in the
    # plane, so the estimated normal is exact (float32 input: to ~1e-5 rad).
    y = (np.arange(41)[:, None] - 20.0) / 400.0
    z = np.broadcast_to(0.6 / (1.0 - np.tan(np.radians(30)) * y), (41, 41)).astype(np.float32)
    theta = np.degrees(incidence_angles(z, CENTRED))
    assert theta[20, 20] == pytest.approx(30.0, abs=0.01)
    assert theta[40, 20] == pytest.approx(32.862, abs=0.01)
    assert theta[0, 20] == pytest.approx(27.138, abs=0.01)
    assert theta.dtype == np.float64 and theta.shape == (41, 41)


def test_incidence_no_data_gives_zero():
    y = (np.arange(41)[:, None] - 20.0) / 400.0
    clean = np.broadcast_to(0.6 / (1.0 - np.tan(np.radians(30)) * y), (41, 41))
    z = clean.copy()  # the tilted plane of the test above
    z[10, 10] = 0.0  # a one-pixel hole
    z[30:, 30:] = 0.0
    z[35, 35] = 0.6  # an isolated pixel: no neighbour with data in either direction
    theta = incidence_angles(z, CENTRED)
    assert theta[10, 10] == 0.0 and (theta[30:, 30:] == 0.0).all()
    # The hole's four neighbours take the one-sided tangent away from it, which lies in the
    # same plane: the same angle as without the hole.
    ref = incidence_angles(clean, CENTRED)
    for p in ((9, 10), (11, 10), (10, 9), (10, 11)):
        assert theta[p] == pytest.approx(ref[p], abs=1e-9)


# Box scene: a 60 × 20 image, floor at 0.7 m, a box top at 0.5 m over rows 5–14, columns 20–39.
BOX_INTR = Intrinsics(60, 20, 400.0, 400.0, 29.5, 9.5)


def box_scene() -> np.ndarray:
    z = np.full((20, 60), 0.7, np.float32)
    z[5:15, 20:40] = 0.5
    return z


def test_incidence_at_depth_step_takes_own_surface():
    # Both surfaces are fronto-parallel, so θ is each ray's angle to the axis. Row 9 (v − cy =
    # −0.5): box pixel u = 20 (u − cx = −9.5): atan(√(9.5² + 0.5²) / 400) = atan(0.023782) =
    # 1.3624°; floor pixel u = 19: atan(√(10.5² + 0.5²) / 400) = atan(0.026280) = 1.5054°.
    # A central difference across the 20 cm step would give nearly 90° instead.
    theta = np.degrees(incidence_angles(box_scene(), BOX_INTR))
    assert theta[9, 20] == pytest.approx(1.3624, abs=1e-3)
    assert theta[9, 19] == pytest.approx(1.5054, abs=1e-3)
    assert theta.max() < 5.0


# --- projector_shadow ------------------------------------------------------------------------


def test_projector_shadow_left_of_box_for_positive_baseline():
    # Projector at +x, b = 0.025, fx = 400: fx · b = 10 px. Projector column u_p = u − 10 / z:
    # floor u − 14.286, box u − 20. A floor pixel left of the box is dark when its u_p exceeds
    # the smallest u_p to its right (+0.5 px tolerance), the box's left column: 20 − 20 = 0:
    #     u − 14.286 > 0.5  ⇔  u ≥ 15  →  columns 15–19, 5 px
    # (band width fx·b·(1/0.5 − 1/0.7) = 10 · 0.5714 = 5.71 px, on integer columns 5), only on
    # the box's rows 5–14. Right of the box the floor's u_p (40 − 14.3 = 25.7 on) exceeds the
    # box's (≤ 19): lit. The box top and the floor far away: u_p increases along the row: lit.
    shadow = projector_shadow(box_scene(), BOX_INTR, 0.025)
    expected = np.zeros((20, 60), bool)
    expected[5:15, 15:20] = True
    np.testing.assert_array_equal(shadow, expected)


def test_projector_shadow_mirrors_for_negative_baseline():
    # Projector at −x: u_p = u + 10 / z; the floor right of the box is dark where
    # u + 14.286 < (39 + 20) − 0.5 ⇔ u ≤ 44 → columns 40–44, the mirror image of 15–19.
    z = box_scene()
    shadow = projector_shadow(z, BOX_INTR, -0.025)
    expected = np.zeros((20, 60), bool)
    expected[5:15, 40:45] = True
    np.testing.assert_array_equal(shadow, expected)
    # Mirror the scene (column c → 59 − c, and cx = 29.5 → 29.5): b < 0 is b > 0 mirrored.
    np.testing.assert_array_equal(projector_shadow(z[:, ::-1], BOX_INTR, 0.025), shadow[:, ::-1])


def test_projector_shadow_zero_baseline_and_no_data():
    z = box_scene()
    assert not projector_shadow(z, BOX_INTR, 0.0).any()
    # A flat plane: u_p strictly increasing along every row: no shadow.
    assert not projector_shadow(np.full((20, 60), 0.6), BOX_INTR, 0.05).any()
    # No-data pixels neither receive (column 17 in the band) nor cast (a 0 box column 20
    # leaves the box's next column 21, u_p = 1, as the caster: u − 14.286 > 1.5 ⇔ u ≥ 16).
    z[:, 17] = 0.0
    z[:, 20] = 0.0
    shadow = projector_shadow(z, BOX_INTR, 0.025)
    expected = np.zeros((20, 60), bool)
    expected[5:15, [16, 18, 19]] = True
    np.testing.assert_array_equal(shadow, expected)


def test_projector_shadow_in_apply_sensor_model():
    # The SR300 config with noise and edge dropout off (θ ≤ 5° here, far below 60°): the band
    # of test_projector_shadow_left_of_box_for_positive_baseline is 0, the rest ideal depth
    # (0.7 and 0.5 are multiples of 1/8 mm: 5600 and 4000 steps).
    cfg = sensor_cfg(
        noise_sigma_0=0.0, noise_sigma_2=0.0, noise_sigma_theta=0.0, edge_dropout_prob=0.0
    )
    z = box_scene()
    out = apply_sensor_model(z, cfg, np.random.default_rng(0), BOX_INTR)
    expected = z.copy()
    expected[5:15, 15:20] = 0.0
    np.testing.assert_array_equal(out, expected)


# --- noise_sigma -----------------------------------------------------------------------------


def test_noise_sigma_formula():
    cfg = sensor_cfg()  # σ0 = 0.0005, σ2 = 0.002, σθ = 0.0001
    z = np.array([0.5, 1.0, 0.5, 1.0, 0.25])
    theta = np.array([0.0, 0.0, np.pi / 3, np.pi / 3, np.pi / 4])
    # θ = 0: σ0 + σ2 z² = 0.0005 + 0.002 · 0.25 = 0.0010; 0.0005 + 0.002 = 0.0025.
    # θ = 60°: θ² / (π/2 − θ)² = (π/3)² / (π/6)² = 4, so + 4 σθ / √z:
    #   z = 0.5: 0.0010 + 0.0004 / 0.70711 = 0.0010 + 0.00056569 = 0.00156569;
    #   z = 1.0: 0.0025 + 0.0004 = 0.0029.
    # θ = 45°: ratio (π/4)² / (π/4)² = 1; z = 0.25: 0.0005 + 0.000125 + 0.0001 / 0.5 = 0.000825.
    expected = [0.0010, 0.0025, 0.00156569, 0.0029, 0.000825]
    np.testing.assert_allclose(noise_sigma(z, theta, cfg), expected, rtol=1e-5)


def test_noise_sigma_without_angle_term_and_at_grazing():
    cfg = sensor_cfg(noise_sigma_theta=0.0)
    # σθ = 0: the angle does not matter.
    np.testing.assert_allclose(
        noise_sigma(np.array([0.6, 0.6]), np.array([0.0, 1.5]), cfg),
        [0.0005 + 0.002 * 0.36] * 2,
        rtol=1e-12,
    )
    # θ = π/2 is clamped to π/2 − 1e-3: finite.
    s = noise_sigma(np.array([0.6]), np.array([np.pi / 2]), sensor_cfg())
    assert np.isfinite(s).all()


# --- steep_dropout ---------------------------------------------------------------------------


def test_steep_dropout_probability_ramp():
    # SR300: p = 0 up to 60°, (θ − 60) / 18 between, 1 from 78°: 64.5° → 0.25, 69° → 0.5,
    # 73.5° → 0.75. 20,000 pixels per angle: the fraction's standard error ≤ √(0.25/20000) =
    # 0.0035; tolerance 0.02.
    cfg = sensor_cfg()
    rng = np.random.default_rng(1)
    for deg, p in (
        (0.0, 0.0),
        (45.0, 0.0),
        (60.0, 0.0),
        (64.5, 0.25),
        (69.0, 0.5),
        (73.5, 0.75),
        (78.0, 1.0),
        (85.0, 1.0),
        (89.9, 1.0),
    ):
        lost = steep_dropout(np.full((200, 100), np.radians(deg)), cfg, rng)
        assert lost.dtype == bool and lost.shape == (200, 100)
        if p in (0.0, 1.0):
            assert lost.mean() == p, deg
        else:
            assert lost.mean() == pytest.approx(p, abs=0.02), deg


def test_steep_dropout_off_draws_nothing():
    rng = np.random.default_rng(2)
    state = rng.bit_generator.state
    theta = np.full((10, 10), np.radians(89.0))
    for off in (90.0, 120.0):
        lost = steep_dropout(theta, sensor_cfg(dropout_angle_deg=off), rng)
        assert not lost.any()
    assert rng.bit_generator.state == state


def test_steep_dropout_hard_threshold():
    # start = end = 70°: a step, nothing below, everything from 70° (start > end: the same).
    theta = np.radians(np.array([[69.0, 69.99, 70.0, 70.01, 80.0]]))
    for start in (70.0, 75.0):
        cfg = sensor_cfg(dropout_angle_start_deg=start, dropout_angle_deg=70.0)
        lost = steep_dropout(theta, cfg, np.random.default_rng(0))
        np.testing.assert_array_equal(lost, [[False, False, True, True, True]])


# --- depth_steps -----------------------------------------------------------------------------


def test_depth_steps_hand_case():
    # A 5 × 5 plane at 0.6 m with a 2 cm bump at (2, 2): the bump and its four 4-neighbours
    # differ by 0.02 > 0.01; the diagonal pixels touch it only diagonally: not steps.
    z = np.full((5, 5), 0.6)
    z[2, 2] = 0.62
    expected = np.zeros((5, 5), bool)
    expected[2, 2] = expected[1, 2] = expected[3, 2] = expected[2, 1] = expected[2, 3] = True
    np.testing.assert_array_equal(depth_steps(z, 0.01), expected)
    assert not depth_steps(z, 0.03).any()  # 2 cm is no step for a 3 cm threshold
    # A vertical step between columns 1 and 2 marks both columns, every row.
    z = np.full((3, 4), 0.6)
    z[:, 2:] = 0.55
    np.testing.assert_array_equal(depth_steps(z, 0.01), np.tile([False, True, True, False], (3, 1)))
    # No data (0) next to data is a step (0.6 m ≫ 1 cm).
    z = np.full((3, 3), 0.6)
    z[0, 0] = 0.0
    np.testing.assert_array_equal(
        depth_steps(z, 0.01), [[True, True, False], [True, False, False], [False, False, False]]
    )


def test_edge_dropout_probability():
    # Box scene, no shadow: the step pixels are the box's rim (1 px on each side of each
    # edge); with edge_dropout_prob = 1 all of them are lost, with 0.5 about half.
    z = box_scene()
    steps = depth_steps(z, 0.01)
    cfg = sensor_cfg(
        noise_sigma_0=0.0,
        noise_sigma_2=0.0,
        noise_sigma_theta=0.0,
        projector_baseline=0.0,
        edge_dropout_prob=1.0,
    )
    out = apply_sensor_model(z, cfg, np.random.default_rng(0), BOX_INTR)
    np.testing.assert_array_equal(out == 0, steps)
    cfg.edge_dropout_prob = 0.5
    fractions = [
        (apply_sensor_model(z, cfg, np.random.default_rng(s), BOX_INTR)[steps] == 0).mean()
        for s in range(20)
    ]
    assert not (apply_sensor_model(z, cfg, np.random.default_rng(0), BOX_INTR)[~steps] == 0).any()
    # 20 × 116 step pixels: standard error √(0.25 / 2320) = 0.010; tolerance 0.04.
    assert np.mean(fractions) == pytest.approx(0.5, abs=0.04)


# --- quantisation and range ------------------------------------------------------------------


def test_quantisation_to_multiples_of_the_step():
    # Columns of constant depth from 0.1 to 2.0 m; SR300 noise and 1/8 mm steps, range
    # [0.2, 1.5] m judged on the ideal depth: the columns at 0.1, 0.19, 1.51, 2.0 m are lost,
    # 0.2 and 1.5 (the limits) kept.
    depths = np.array([0.1, 0.19, 0.2, 0.6, 1.0, 1.5, 1.51, 2.0], np.float32)
    z = np.tile(depths, (50, 1))
    intr = Intrinsics(8, 50, 4000.0, 4000.0, 3.5, 24.5)
    # Neighbouring columns differ by up to 0.5 m over a fraction of a millimetre, so their
    # incidence angles are near 90°: steep dropout and the angle term off here.
    cfg = sensor_cfg(
        projector_baseline=0.0,
        edge_dropout_prob=0.0,
        dropout_angle_deg=90.0,
        noise_sigma_theta=0.0,
        min_range=0.2,
        max_range=1.5,
    )
    out = apply_sensor_model(z, cfg, np.random.default_rng(3), intr)
    assert out.dtype == np.float32
    kept = np.array([False, False, True, True, True, True, False, False])
    assert (out[:, ~kept] == 0).all()
    assert (out[:, kept] > 0).all()
    # Every returned value is an integer number of 0.125 mm steps (float32: to ~3e-4 step).
    steps = out[out > 0].astype(np.float64) / 0.000125
    assert np.abs(steps - np.round(steps)).max() < 1e-3
    # ... and noisy: many distinct values per column.
    assert len(np.unique(out[:, 3])) > 10
    # Noise-free: 0.60049 / 0.000125 = 4803.92 → 4804 steps = 0.6005 m.
    quiet = sensor_cfg(noise_sigma_0=0.0, noise_sigma_2=0.0, noise_sigma_theta=0.0, **NO_DROPOUT)
    one = apply_sensor_model(
        np.array([[0.60049]], np.float32),
        quiet,
        np.random.default_rng(0),
        Intrinsics(1, 1, 400.0, 400.0, 0.0, 0.0),
    )
    assert one[0, 0] == np.float32(0.6005)


def test_no_quantisation_when_step_is_zero():
    cfg = sensor_cfg(
        noise_sigma_0=0.0,
        noise_sigma_2=0.0,
        noise_sigma_theta=0.0,
        quantisation_step=0.0,
        **NO_DROPOUT,
    )
    z = np.full((4, 4), 0.60049, np.float32)
    out = apply_sensor_model(
        z, cfg, np.random.default_rng(0), Intrinsics(4, 4, 400.0, 400.0, 1.5, 1.5)
    )
    np.testing.assert_array_equal(out, z)


# --- reproducibility and draw order ----------------------------------------------------------


def test_same_seed_same_output():
    cfg = sensor_cfg()
    z = box_scene()
    a = apply_sensor_model(z, cfg, np.random.default_rng(7), BOX_INTR)
    b = apply_sensor_model(z, cfg, np.random.default_rng(7), BOX_INTR)
    c = apply_sensor_model(z, cfg, np.random.default_rng(8), BOX_INTR)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)
    np.testing.assert_array_equal(z, box_scene())  # input untouched


def test_noise_is_the_first_draw():
    # All dropout off and σθ = 0: the output is exactly
    #     round((z + g · (σ0 + σ2 z²)) / step) · step,  g = the generator's first H·W normals,
    # and the generator has drawn nothing else.
    cfg = sensor_cfg(noise_sigma_theta=0.0, **NO_DROPOUT)
    z = box_scene()
    rng = np.random.default_rng(11)
    out = apply_sensor_model(z, cfg, rng, BOX_INTR)
    twin = np.random.default_rng(11)
    g = twin.normal(size=z.shape)
    z64 = z.astype(np.float64)
    expected = np.round((z64 + g * (0.0005 + 0.002 * z64 * z64)) / 0.000125) * 0.000125
    np.testing.assert_allclose(out, expected.astype(np.float32), rtol=0, atol=1e-7)
    assert rng.bit_generator.state == twin.bit_generator.state


def test_draw_order_noise_steep_edge():
    # Everything on: H·W normals (noise), then H·W uniforms (steep surfaces), then H·W uniforms
    # (edge dropout). Steep dropout from 0° to 4° so that the near-fronto-parallel box scene
    # (θ ≤ atan(√(29.5² + 9.5²) / 400) = 4.43°) loses some pixels to it: p = θ / 4°.
    cfg = sensor_cfg(dropout_angle_start_deg=0.0, dropout_angle_deg=4.0)
    z = box_scene()
    rng = np.random.default_rng(5)
    out = apply_sensor_model(z, cfg, rng, BOX_INTR)
    twin = np.random.default_rng(5)
    g = twin.normal(size=z.shape)
    s = twin.random(z.shape)
    e = twin.random(z.shape)
    assert rng.bit_generator.state == twin.bit_generator.state
    z64 = z.astype(np.float64)
    theta = incidence_angles(z64, BOX_INTR)
    noisy = np.round((z64 + g * noise_sigma(z64, theta, cfg)) / 0.000125) * 0.000125
    p_steep = np.clip(np.degrees(theta) / 4.0, 0.0, 1.0)
    lost = (
        projector_shadow(z64, BOX_INTR, 0.025)
        | (s < p_steep)
        | (depth_steps(z64, 0.01) & (e < 0.5))
    )
    assert 0 < (s < p_steep).sum() < z.size  # the steep draw matters here
    expected = np.where(lost, 0.0, noisy).astype(np.float32)
    np.testing.assert_allclose(out, expected, rtol=0, atol=1e-7)


# --- holes, calibration error, randomised models ------------------------------------------------


def test_hole_mask_blocks_by_hand():
    """A 5 × 7 image in 2-pixel blocks: 3 × 4 blocks, each lost when its uniform < rate. rate 0:
    nothing; rate 1: everything; blocks are whole 2 × 2 squares, cut at the image's edge."""
    from pipeline.camera.sensor import hole_mask

    assert not hole_mask((5, 7), 0.0, 2, np.random.default_rng(0)).any()
    assert hole_mask((5, 7), 1.0, 2, np.random.default_rng(0)).all()
    rng = np.random.default_rng(3)
    blocks = np.random.default_rng(3).random((3, 4)) < 0.5
    m = hole_mask((5, 7), 0.5, 2, rng)
    assert m.shape == (5, 7)
    assert np.array_equal(m, np.kron(blocks, np.ones((2, 2), bool))[:5, :7].astype(bool))
    with pytest.raises(ValueError, match="hole_size_px"):
        hole_mask((5, 7), 0.5, 0, rng)


def test_bias_and_scale_error_by_hand():
    """No noise or dropout: a flat 0.5 m image comes back as 0.5 × (1 + 0.01) + 0.002 = 0.507 m;
    pixels without data stay 0."""
    z = np.full((41, 41), 0.5, np.float32)
    z[0, 0] = 0.0
    cfg = sensor_cfg(
        **NO_DROPOUT,
        noise_sigma_0=0.0,
        noise_sigma_2=0.0,
        noise_sigma_theta=0.0,
        quantisation_step=0.0,
        depth_bias=0.002,
        depth_scale_error=0.01,
    )
    out = apply_sensor_model(z, cfg, np.random.default_rng(0), CENTRED)
    assert out[0, 0] == 0.0
    assert np.allclose(out[1:, 1:], 0.507, atol=1e-6)


def test_randomised_sensors_stay_in_their_ranges():
    from pipeline.camera.randomise import check_randomisation, draw_sensor
    from pipeline.runtime.cli import compose

    rand = OmegaConf.to_object(
        compose("generate", ["experiment=smoke"])
    ).generate.camera_randomisation
    check_randomisation(rand)
    rng = np.random.default_rng(0)
    drawn = [draw_sensor(rand, rng) for _ in range(400)]
    models = [d for d in drawn if d is not None]
    assert (
        0.5 * (1 - rand.ideal_fraction) < len(models) / len(drawn) < 1.5 * (1 - rand.ideal_fraction)
    )
    for m in models:
        assert m.enabled and m.dropout_angle_deg < 90
        for key in (
            "noise_sigma_0",
            "noise_sigma_2",
            "hole_rate",
            "depth_bias",
            "depth_scale_error",
            "projector_baseline",
            "edge_dropout_prob",
        ):
            lo, hi = getattr(rand, key)
            assert lo <= getattr(m, key) <= hi
        assert rand.hole_size_px[0] <= m.hole_size_px <= rand.hole_size_px[1]
    # every camera profile lies inside the ranges
    for name in ("sr300", "d435"):
        sr = sensor_cfg(name)
        for key in (
            "noise_sigma_0",
            "noise_sigma_2",
            "noise_sigma_theta",
            "projector_baseline",
            "edge_dropout_prob",
            "quantisation_step",
            "hole_rate",
            "depth_bias",
            "depth_scale_error",
            "dropout_angle_start_deg",
        ):
            lo, hi = getattr(rand, key)
            assert lo <= getattr(sr, key) <= hi, (name, key)
        # the angle where dropout is certain lies in the drawn range (the SR300's 18 deg ramp is
        # wider than any drawn one, docs/generation.md)
        lo = rand.dropout_angle_start_deg[0] + rand.dropout_angle_span_deg[0]
        hi = rand.dropout_angle_start_deg[1] + rand.dropout_angle_span_deg[1]
        assert lo <= sr.dropout_angle_deg <= hi, name
        if sr.hole_rate > 0:
            assert rand.hole_size_px[0] <= sr.hole_size_px <= rand.hole_size_px[1]
    import dataclasses

    with pytest.raises(ValueError, match="below 90"):
        check_randomisation(dataclasses.replace(rand, dropout_angle_span_deg=[5.0, 40.0]))
    from pipeline.stages.generate import check_splits

    with pytest.raises(ValueError, match="camera_randomisation.splits"):
        check_splits("generate.camera_randomisation.splits", ["training"])
