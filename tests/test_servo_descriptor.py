"""Surface feature descriptor (paper Sec. 5.1), on synthetic depth images of planar rectangles.

Camera: the SR300 model of the project, 416 × 416, fx = fy = 411.7 px, principal point
(207.5, 207.5); OpenCV frame (x right, y down, z forward), metres. A pixel (u, v) sees the ray
r = ((u − 207.5) / 411.7, (v − 207.5) / 411.7, 1), and a depth z the point z · r.
At z = 0.5 m one pixel is 0.5 / 411.7 = 1.21 mm.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from conftest import default_config
from omegaconf import OmegaConf

from pipeline.camera.geometry import Intrinsics, project
from pipeline.camera.sensor import apply_sensor_model
from pipeline.servo.descriptor import DescriptorConfig, describe_surface

SR300 = Intrinsics(416, 416, 411.7, 411.7, 207.5, 207.5)
SENSOR_SR300_YAML = Path(__file__).resolve().parents[1] / "conf" / "sensor" / "sr300.yaml"
FLOOR_Z = 0.6
C25, S25 = np.cos(np.radians(25)), np.sin(np.radians(25))
C20, S20 = np.cos(np.radians(20)), np.sin(np.radians(20))


def descriptor(**overrides) -> DescriptorConfig:
    """``conf/servo/``'s descriptor with the window-depth tolerance and the normal tracking off
    (0, as the paper) unless ``overrides`` set them: each test turns on what it tests."""
    off = {"window_tolerance_depth": 0.0, "track_normal_deg": 0.0}
    return default_config(DescriptorConfig, **{**off, **overrides})


def rect(center, axis_a, axis_b, half_a, half_b):
    """A planar rectangle: centre, two orthonormal in-plane axes and half-lengths along them."""
    return (
        np.asarray(center, float),
        np.asarray(axis_a, float),
        np.asarray(axis_b, float),
        half_a,
        half_b,
    )


def render(rects, floor_z=FLOOR_Z, intr=SR300):
    """(depth (H, W) float32, [hit mask per rectangle]): nearest rectangle per ray, else a level
    floor at ``floor_z`` (None: no data)."""
    u = np.arange(intr.width)[None, :]
    v = np.arange(intr.height)[:, None]
    r = np.stack(
        np.broadcast_arrays((u - intr.cx) / intr.fx, (v - intr.cy) / intr.fy, np.ones((1, 1))),
        axis=-1,
    )  # (H, W, 3)
    depth = np.full((intr.height, intr.width), np.inf if floor_z is None else floor_z)
    hits = []
    for c, a, b, ha, hb in rects:
        n = np.cross(a, b)
        z = (n @ c) / (r @ n)  # ray-plane intersection; r_z = 1 so this is the z-depth
        rel = z[..., None] * r - c
        hit = (np.abs(rel @ a) <= ha) & (np.abs(rel @ b) <= hb) & (z > 0)
        hits.append(hit)
        depth = np.where(hit & (z < depth), z, depth)
    depth[~np.isfinite(depth)] = 0.0
    return depth.astype(np.float32), hits


def angle_deg(a, b):
    return float(np.degrees(np.arccos(np.clip(abs(np.dot(a, b)), -1.0, 1.0))))


# Two level boxes side by side (top faces only): A (higher) over x ∈ [−0.10, 0], y ∈ [−0.05,
# 0.05] at z = 0.50; B over x ∈ [0, 0.10] at z = 0.52, 2 cm lower.
# A's pixels: (u − 207.5) · 0.5 / 411.7 ∈ [−0.10, 0] → u − 207.5 ∈ [−82.34, 0] → u = 126..207,
# 82 columns; v − 207.5 ∈ [−41.17, 41.17] → v = 167..248, 82 rows: 82 × 82 = 6724 pixels.
BOX_A = rect([-0.05, 0.0, 0.50], [1, 0, 0], [0, 1, 0], 0.05, 0.05)
BOX_B_STEP = rect([0.05, 0.0, 0.52], [1, 0, 0], [0, 1, 0], 0.05, 0.05)
A_PIXELS = 82 * 82


def test_tilted_rectangle_normal_centre_axes_lengths():
    # A 0.20 × 0.12 m rectangle centred at (0.03, −0.02, 0.5), tilted 25° about camera x: long
    # axis (1, 0, 0), short side along (0, cos 25°, sin 25°) (going down the image it recedes);
    # normal towards the camera (0, sin 25°, −cos 25°) = (0, 0.4226, −0.9063).
    centre = np.array([0.03, -0.02, 0.5])
    scene = [rect(centre, [1, 0, 0], [0, C25, S25], 0.10, 0.06)]
    depth, _ = render(scene)
    # Centre in pixels: u = 207.5 + 411.7 · 0.03 / 0.5 = 232.202, v = 207.5 − 16.468 = 191.032.
    g_true = np.array([232.202, 191.032])
    np.testing.assert_allclose(project(centre, SR300), g_true, atol=1e-3)
    seed = (g_true[0] + 40, g_true[1] + 20)  # off-centre: g' is refined to the centre
    f, reason = describe_surface(depth, SR300, seed, descriptor())
    assert reason == "" and f is not None
    n_true = np.array([0.0, S25, -C25])
    assert np.degrees(np.arccos(np.clip(f.normal_cam @ n_true, -1, 1))) < 0.5  # signed: towards
    assert f.normal_cam @ f.center_cam < 0
    assert np.degrees(np.arccos(np.clip(f.plane[:3] @ n_true, -1, 1))) < 0.5
    # Eq. 11's D̂: n̂ · P + D̂ = 0 at the centre → D̂ = −n·c = 0.02 · 0.4226 + 0.5 · 0.9063 = 0.4616.
    assert f.plane[3] == pytest.approx(-n_true @ centre, abs=1e-3)
    assert np.linalg.norm(f.center_px - g_true) < 1.0
    assert np.linalg.norm(f.center_cam - centre) < 0.002
    assert angle_deg(f.long_axis_cam, [1, 0, 0]) < 0.5
    assert angle_deg(f.short_axis_cam, [0, C25, S25]) < 0.5
    # Pixel footprint ≈ 1.2–1.4 mm; the rectangle of pixel centres is up to one footprint short.
    assert f.long_length == pytest.approx(0.20, abs=0.003)
    assert f.short_length == pytest.approx(0.12, abs=0.003)
    # Warped perspective: R0 with R0 Z = −n is the rotation by +25° about x; R0ᵀ keeps
    # (1, 0, 0) and takes the short axis ±(0, cos 25°, sin 25°) to ±(0, 1, 0).
    assert angle_deg(f.warped_long, [1, 0, 0]) < 0.5
    assert angle_deg(f.warped_short, [0, 1, 0]) < 0.5
    for w in (f.warped_long, f.warped_short):
        assert w[2] == 0.0 and np.linalg.norm(w) == pytest.approx(1.0, abs=1e-12)
    # The paper's settings only (plain window SVD, no rim, no refit; 8-connected): same plane,
    # same centre; the region loses its one-pixel rim, so the lengths are ~2 px (2.5 mm) shorter.
    paper = descriptor(window_hypotheses=0, window_refits=0, rim=0, refine=False, connectivity=8)
    fp, _ = describe_surface(depth, SR300, seed, paper)
    assert np.degrees(np.arccos(np.clip(fp.normal_cam @ n_true, -1, 1))) < 0.5
    np.testing.assert_allclose(fp.normal_cam, fp.plane[:3])
    assert np.linalg.norm(fp.center_px - g_true) < 1.0
    assert 0.0 < f.long_length - fp.long_length < 0.004


def test_plane_filling_the_image():
    # The 25° plane of the previous test through (0, 0, 0.5), filling the whole image (no floor).
    # Every pixel is on it: the border rows / columns have no Eq. 14 normal (no neighbour) and
    # come back through the rim, so the region is all 416 × 416 = 173056 pixels.
    depth, _ = render([rect([0, 0, 0.5], [1, 0, 0], [0, C25, S25], 1.0, 1.0)], floor_z=None)
    assert depth.min() > 0
    f, reason = describe_surface(depth, SR300, (300, 100), descriptor())
    assert reason == "" and f.num_pixels == 416 * 416
    assert np.degrees(np.arccos(np.clip(f.normal_cam @ [0, S25, -C25], -1, 1))) < 0.01
    # The image's footprint is symmetric about the plane's x = 0 line, so the centre projects
    # to u = 207.5 (v is not the image centre: the plane recedes downwards).
    assert f.center_px[0] == pytest.approx(207.5, abs=0.5)


def test_noisy_depth_needs_normal_smoothing():
    # The project's SR300 sensor model (conf/sensor/sr300.yaml, pipeline/camera/sensor.py):
    # σ = σ0 + σ2 z² + σθ/√z · θ²/(π/2 − θ)² = 0.5 + 2 · 0.25 = 1.0 mm at 0.5 m plus the angle
    # term (θ = 16–32° on this face: +0.02–0.04 mm), half the pixels at depth jumps dropped,
    # projector shadow on the floor left of the face, 1/8 mm quantisation. Eq. 14's central
    # differences span 2 pixels = 2.4 mm, so a single n_p is tens of degrees off and Eq. 13
    # (≈ 12.8°) rejects nearly everything; averaging n_p over 5 × 5 pixels recovers the face.
    # Measured with rng seeds 0–4 (thresholds unchanged from the old σ = 0.0035 z² model):
    # paper descriptor region_too_small every time; smoothed normal 0.007–0.035° off, centre
    # 0.23 px off, 0.980–0.983 of the face's pixels (the rest lost at its rim).
    sr300 = OmegaConf.load(SENSOR_SR300_YAML)
    centre = np.array([0.03, -0.02, 0.5])
    ideal, hits = render([rect(centre, [1, 0, 0], [0, C25, S25], 0.10, 0.06)])
    depth = apply_sensor_model(ideal, sr300, np.random.default_rng(0), SR300)
    seed = (272, 211)
    assert describe_surface(depth, SR300, seed, descriptor()) == (None, "region_too_small")
    f, reason = describe_surface(depth, SR300, seed, descriptor(normal_smoothing=2))
    assert reason == ""
    assert np.degrees(np.arccos(np.clip(f.normal_cam @ [0, S25, -C25], -1, 1))) < 0.5
    assert np.linalg.norm(f.center_px - project(centre, SR300)) < 1.0
    assert not (f.region & ~hits[0]).any()
    assert f.num_pixels > 0.95 * hits[0].sum()  # only dropped / noisy rim pixels are missing


def test_region_stops_at_depth_step_between_touching_boxes():
    depth, hits = render([BOX_A, BOX_B_STEP])
    assert hits[0].sum() == A_PIXELS
    f, reason = describe_surface(depth, SR300, (160, 200), descriptor())
    assert reason == ""
    # Every pixel of A and nothing else: the step (2 cm ≫ ε1 = 4 mm) fails Eq. 12; A's own rim
    # pixels (their Eq. 14 stencil reaches over the step) come back through the rim rule.
    np.testing.assert_array_equal(f.region, hits[0])
    assert f.num_pixels == A_PIXELS
    # Centre (−0.05, 0, 0.5) → u = 207.5 − 411.7 · 0.1 = 166.33, v = 207.5.
    assert np.linalg.norm(f.center_px - [166.33, 207.5]) < 1.0
    np.testing.assert_allclose(f.normal_cam, [0, 0, -1], atol=1e-6)
    # Level square 0.1 × 0.1: lengths one footprint (1.2 mm) short at most.
    assert 0.0975 < f.short_length <= f.long_length < 0.1005
    # Level surface: the warped perspective is the identity.
    np.testing.assert_allclose(f.warped_long, f.long_axis_cam, atol=1e-9)
    np.testing.assert_allclose(f.warped_short, f.short_axis_cam, atol=1e-9)
    assert f.warped_long[2] == 0.0 and f.warped_short[2] == 0.0

    # The paper's rules alone (rim = 0) lose A's one-pixel rim: the top and bottom rows and the
    # left column border the floor (10 cm lower), the right column borders B: 80 × 80 = 6400.
    f0, _ = describe_surface(depth, SR300, (160, 200), descriptor(rim=0))
    assert f0.num_pixels == 80 * 80
    assert np.linalg.norm(f0.center_px - [166.33, 207.5]) < 1.0


def test_seed_on_edge_takes_nearest_region():
    depth, hits = render([BOX_A, BOX_B_STEP])
    # u = 207 is A's last column: its Eq. 14 normal straddles the step, so the seed pixel fails
    # Eq. 13; the nearest rule pixel (u = 206) is in A's region.
    f, reason = describe_surface(depth, SR300, (207, 200), descriptor())
    assert reason == ""
    np.testing.assert_array_equal(f.region, hits[0])


def test_seed_on_depth_spike():
    # A 1 cm spike at the seed pixel of A: RANSAC finds no plane holding the seed, so the window
    # plane is A's; the seed fails Eq. 12 and the region is the component of the nearest rule
    # pixel: all of A but the spike (its four neighbours' n_p are corrupted by it, they are on
    # A's plane and come back through the rim): 6724 − 1 pixels.
    depth, hits = render([BOX_A, BOX_B_STEP])
    depth[200, 160] = 0.49
    f, reason = describe_surface(depth, SR300, (160, 200), descriptor())
    assert reason == "" and f.num_pixels == A_PIXELS - 1
    assert not f.region[200, 160]
    np.testing.assert_allclose(f.normal_cam, [0, 0, -1], atol=1e-6)


def test_a_seed_in_a_sensor_hole_keeps_the_face_around_it():
    # An 11 x 11 hole (no data, as an SR300 leaves) centred on the seed in A's face: with
    # seed_repair the seed takes the depth of the nearest window pixel with data (5 px away, on
    # A), the window plane is A's, the seed pixel has no data and so fails the rules, and the
    # region is the component of the nearest rule pixel: all of A but the hole's 121 pixels
    # (their neighbours' n_p lack a stencil pixel; they are on A's plane and come back through
    # the rim), with A's normal.
    depth, hits = render([BOX_A, BOX_B_STEP])
    depth[195:206, 155:166] = 0.0
    f, reason = describe_surface(depth, SR300, (160, 200), descriptor())
    assert reason == "" and f.num_pixels == A_PIXELS - 121
    hole = np.zeros_like(hits[0])
    hole[195:206, 155:166] = True
    np.testing.assert_array_equal(f.region, hits[0] & ~hole)
    np.testing.assert_allclose(f.normal_cam, [0, 0, -1], atol=1e-6)


def test_region_stops_at_crease_between_level_and_tilted_box():
    # B touches A along x = 0 at the same height and goes down at 20°: points
    # (t cos 20°, y, 0.5 + t sin 20°), t ∈ [0, 0.10]; normal towards the camera (sin 20°, 0, −cos
    # 20°).
    box_b = rect([0.05 * C20, 0.0, 0.5 + 0.05 * S20], [C20, 0, S20], [0, 1, 0], 0.05, 0.05)
    depth, hits = render([BOX_A, box_b])
    assert hits[0].sum() == A_PIXELS
    f, reason = describe_surface(depth, SR300, (160, 200), descriptor())
    assert reason == ""
    assert np.all(f.region[hits[0]])  # all of A
    # Beyond A, at most two of B's columns (u = 208, 209): u = 208's stencil straddles the crease
    # (n_p ~10° off, within ε2), and the rim adds one more column within ε1 of A's plane.
    extra = f.region & ~hits[0]
    assert extra.sum() <= 2 * 82
    assert not extra[:, 210:].any()
    # B's pixels at t > 1 cm lie more than 4 mm below A's plane and 20° off: nothing far in.
    assert angle_deg(f.normal_cam, [0, 0, 1]) < 0.5
    assert np.linalg.norm(f.center_px - [166.33, 207.5]) < 1.5
    # Seeded on B instead: B's region, B's normal.
    f_b, _ = describe_surface(depth, SR300, (260, 200), descriptor())
    assert not f_b.region[:, :206].any()
    assert np.degrees(np.arccos(f_b.normal_cam @ [S20, 0, -C20])) < 0.5


def test_failures_have_reasons():
    depth, _ = render([BOX_A, BOX_B_STEP])
    assert describe_surface(depth, SR300, (500, 10), descriptor()) == (None, "seed_outside_image")
    holed = depth.copy()
    holed[195:206, 155:166] = 0.0  # an 11 x 11 hole around the seed
    assert describe_surface(holed, SR300, (160, 200), descriptor(seed_repair=False)) == (
        None,
        "no_depth_at_seed",
    )
    holed[185:216, 145:176] = 0.0  # a hole larger than the 21 x 21 window: nothing to repair
    assert describe_surface(holed, SR300, (160, 200), descriptor()) == (None, "no_depth_at_seed")
    # Region of 6724 pixels < min_pixels.
    assert describe_surface(depth, SR300, (160, 200), descriptor(min_pixels=7000)) == (
        None,
        "region_too_small",
    )
    # A 6 × 6-pixel patch in an image without data elsewhere: the window holds its 36 points
    # (≥ 10), so the plane is fitted; n_p exists only at the inner 4 × 4, the rim brings back
    # the rest: 36 pixels < 50.
    patch = np.zeros_like(depth)
    patch[100:106, 100:106] = 0.5
    assert describe_surface(patch, SR300, (102, 102), descriptor()) == (None, "region_too_small")
    # 3 × 3 = 9 window points < 10.
    patch[:] = 0.0
    patch[100:103, 100:103] = 0.5
    assert describe_surface(patch, SR300, (101, 101), descriptor()) == (
        None,
        "too_few_window_points",
    )


def _step_image():
    """A level face at 0.5 m over u ∈ [150, 250), v ∈ [150, 250) (100 × 100 px), the floor 13 cm
    below it (0.63 m) everywhere else; SR300-like intrinsics."""
    from pipeline.camera.geometry import Intrinsics

    intr = Intrinsics(416, 416, 411.7, 411.7, 207.5, 207.5)
    depth = np.full((416, 416), 0.63, np.float32)
    depth[150:250, 150:250] = 0.5
    return depth, intr


def test_seed_near_a_face_edge_over_a_13cm_step_keeps_its_face():
    """Seeds 1–3 px inside the face's edge: the 21 × 21 window holds face and floor, and the
    descriptor still returns the face: normal (0, 0, −1), region = the face's 100 × 100 px
    (area 100² px × (0.5/411.7 m)² = 0.01475 m²), centre (199.5, 199.5)."""
    from pipeline.servo.descriptor import describe_surface

    depth, intr = _step_image()
    for seed in ((151, 199), (152, 199), (153, 199), (248, 200), (200, 248)):
        feats, reason = describe_surface(depth, intr, seed, descriptor())
        assert feats is not None, (seed, reason)
        assert feats.normal_cam == pytest.approx([0, 0, -1], abs=1e-3)
        assert feats.center_px == pytest.approx([199.5, 199.5], abs=0.5)
        assert feats.area == pytest.approx(100**2 * (0.5 / 411.7) ** 2, rel=0.03)


def test_a_one_pixel_outlier_at_the_seed_keeps_the_face():
    """The seed pixel itself 0.6 mm off the face (a one-pixel depth outlier): it passes Eqs. 12
    and 13 (its own Eq. 14 normal is exact) while its four neighbours fail Eq. 13, so it is a
    component of one pixel; the region is the face around it (the paper's rule alone gives
    "region_too_small")."""
    from pipeline.servo.descriptor import describe_surface

    depth, intr = _step_image()
    depth[200, 200] = 0.5006
    feats, reason = describe_surface(depth, intr, (200, 200), descriptor())
    assert feats is not None, reason
    assert feats.area == pytest.approx(100**2 * (0.5 / 411.7) ** 2, rel=0.03)


def test_window_tolerance_shrinks_with_depth_close_to_the_face():
    """The camera 0.157 m from a level face (the servo's last frames); below-right of the seed a
    steep face falls away (+2.3 mm of depth per row). The 21 × 21 window spans 8 mm on the face,
    so with a fixed ε1 = 4 mm a steep RANSAC plane holds most window points and the region grown
    from it is empty; with the tolerance scaled by Z / 0.6 m (1.05 mm) the level face wins:
    normal (0, 0, −1)."""
    from pipeline.camera.geometry import Intrinsics

    intr = Intrinsics(416, 416, 411.7, 411.7, 207.5, 207.5)
    depth = np.full((416, 416), 0.157, np.float32)
    v, u = np.mgrid[0:416, 0:416]
    corner = (v >= 122) & (u >= 209)
    depth[corner] = (0.1585 + 0.0023 * (v - 122))[corner]
    feats, reason = describe_surface(depth, intr, (208, 121), descriptor())
    assert feats is None and reason == "region_too_small"  # the paper's fixed ε1
    feats, reason = describe_surface(
        depth, intr, (208, 121), descriptor(window_tolerance_depth=0.6)
    )
    assert feats is not None, reason
    assert feats.normal_cam == pytest.approx([0, 0, -1], abs=1e-3)


def test_a_seed_on_a_one_pixel_crack_keeps_the_face_around_it():
    """Two boxes side by side, their tops level at 0.5 m, a one-pixel gap between them (column
    u = 200) that sees 2 cm deeper: a seed on the gap takes the surface around it (the median of
    its 3 × 3 neighbourhood), not the gap's plane, and grows the nearest box top: the left one,
    u ∈ [150, 200) × v ∈ [150, 250), 50 × 100 px, centre (174.5, 199.5). (The seed's own depth
    alone gives "no_region_at_seed".)"""
    depth, intr = _step_image()
    depth[150:250, 200] = 0.52
    feats, reason = describe_surface(depth, intr, (200, 200), descriptor())
    assert feats is not None, reason
    assert feats.normal_cam == pytest.approx([0, 0, -1], abs=1e-3)
    assert feats.center_px == pytest.approx([174.5, 199.5], abs=0.5)
    assert feats.area == pytest.approx(50 * 100 * (0.5 / 411.7) ** 2, rel=0.03)


def test_a_tracked_seed_that_slid_onto_the_next_face_keeps_the_tracked_face():
    """Level box A (x from −0.10 to 0 m, z = 0.5) and box B touching it along x = 0 and going
    down at 45° (normal towards the camera (sin 45°, 0, −cos 45°)). A seed on B 7 px past the
    crease gives B. Tracking A (its normal, −Z, expected, ``track_normal_deg`` = 20): the window
    plane is A's orientation through the largest slab of window points (A's own plane), and
    the region is all of A, its normal A's. A surface found too far from the expected normal is
    "surface_changed", not a new target."""
    c45 = s45 = np.sqrt(0.5)
    box_b = rect([0.05 * c45, 0.0, 0.5 + 0.05 * s45], [c45, 0, s45], [0, 1, 0], 0.05, 0.05)
    depth, hits = render([BOX_A, box_b])
    seed = (215, 200)
    f, _ = describe_surface(depth, SR300, seed, descriptor())
    # B, and of A at most the rim's two columns (as at the 20° crease above)
    assert angle_deg(f.normal_cam, [s45, 0, -c45]) < 0.5 and f.region[hits[0]].sum() <= 2 * 82
    cfg = descriptor(track_normal_deg=20.0)
    f, reason = describe_surface(depth, SR300, seed, cfg, expected_normal_cam=[0, 0, -1])
    assert reason == "" and angle_deg(f.normal_cam, [0, 0, 1]) < 0.5
    assert np.all(f.region[hits[0]])
    # A normal expected 12° off A's (within Eq. 13's ε2 = 0.05, about 12.8°): A's region still
    # grows from that orientation, but its refitted normal is 12° from the expected one, more
    # than a tracking tolerance of 10°: "surface_changed". 50° off: nothing grows at all.
    t = np.radians(12)
    off = np.array([np.sin(t), 0.0, -np.cos(t)])
    assert describe_surface(
        depth, SR300, seed, descriptor(track_normal_deg=10.0), expected_normal_cam=off
    ) == (None, "surface_changed")
    t = np.radians(50)
    assert describe_surface(
        depth, SR300, seed, cfg, expected_normal_cam=[0, np.sin(t), -np.cos(t)]
    ) == (None, "no_region_at_seed")
    # tracking off (the paper): the expected normal is ignored
    f, _ = describe_surface(depth, SR300, seed, descriptor(), expected_normal_cam=[0, 0, -1])
    assert angle_deg(f.normal_cam, [s45, 0, -c45]) < 0.5


def test_split_region_is_the_voronoi_cell_of_the_first_site():
    # Points on the x axis at 0, 1, 2, 3, 4 cm (in cm: exact in floating point); sites at 1 cm
    # (first) and 3 cm: the bisector is x = 2 cm, equidistant, and stays with the first site.
    pts = np.array([[0.0, 0, 0], [1.0, 0, 0], [2.0, 0, 0], [3.0, 0, 0], [4.0, 0, 0]])
    from pipeline.servo.region import split_region

    keep = split_region(pts, np.array([[1.0, 0, 0], [3.0, 0, 0]]))
    assert keep.tolist() == [True, True, True, False, False]
    # a third site at −0.5 cm takes the point at 0 (0.5 cm from it, 1 cm from the first site)
    keep = split_region(pts, np.array([[1.0, 0, 0], [3.0, 0, 0], [-0.5, 0, 0]]))
    assert keep.tolist() == [False, True, True, False, False]


def test_two_coplanar_faces_side_by_side_split_at_their_seam():
    """Two level 0.10 × 0.10 m faces at z = 0.50 touching along x = 0 (no seam in the depth):
    the region grown at A's centre holds both (0.20 × 0.10 m, centre on the seam, x = 0); with
    sites at both face centres it is A alone: centre (−0.05, 0, 0.5), both lengths 0.10 m, the
    82 × 82 pixels of BOX_A (see above) give or take the column on the seam (x = 0 is the
    pixel centre of column u = 207.5, between columns 207 and 208)."""
    box_b = rect([0.05, 0.0, 0.50], [1, 0, 0], [0, 1, 0], 0.05, 0.05)
    depth, _ = render([BOX_A, box_b])
    centre_a = np.array([-0.05, 0.0, 0.50])
    seed = project(centre_a, SR300)
    whole, reason = describe_surface(depth, SR300, seed, descriptor())
    assert reason == ""
    assert abs(whole.center_cam[0]) < 0.002 and whole.long_length == pytest.approx(0.2, abs=0.003)
    sites = np.array([centre_a, [0.05, 0.0, 0.50]])
    part, reason = describe_surface(depth, SR300, seed, descriptor(), sites_cam=sites)
    assert reason == ""
    np.testing.assert_allclose(part.center_cam, centre_a, atol=0.0015)
    assert part.long_length == pytest.approx(0.10, abs=0.003)
    assert part.short_length == pytest.approx(0.10, abs=0.003)
    assert abs(part.num_pixels - A_PIXELS) <= 82
    assert not part.region[:, 208:].any()  # nothing of B's side of the seam
    # one site only (or none) is the whole region
    one, _ = describe_surface(depth, SR300, seed, descriptor(), sites_cam=sites[:1])
    assert one.num_pixels == whole.num_pixels


def test_tracking_keeps_the_plane_not_only_its_orientation():
    """A window whose points lie on two parallel planes facing the camera, 140 on the bin floor
    at z = 0.50 m and 60 on a cube's top at z = 0.43 m. Tracking the orientation alone
    (normal (0, 0, -1)) takes the larger slab, the floor: offset n · P = -0.50. With a point of
    the tracked top carried into the frame (z = 0.431) and 1 cm of tolerance, the plane is the
    top's (-0.43); with the tracked plane 3 cm from either slab, it is the tracked plane itself."""
    from pipeline.servo.region import tracked_plane

    cfg = default_config(DescriptorConfig)
    rng = np.random.default_rng(0)
    floor = np.c_[rng.uniform(-0.02, 0.02, (140, 2)), np.full(140, 0.50)]
    top = np.c_[rng.uniform(-0.02, 0.02, (60, 2)), np.full(60, 0.43)]
    win = np.vstack([floor, top])
    seed = np.array([0.0, 0.0, 0.43])
    n_down = np.array([0.0, 0.0, -1.0])
    n, c = tracked_plane(win, seed, cfg, n_down)
    assert n == pytest.approx(n_down) and c == pytest.approx(-0.50)
    cfg = dataclasses.replace(cfg, track_offset_m=0.01)
    n, c = tracked_plane(win, seed, cfg, n_down, np.array([0.01, 0.0, 0.431]))
    assert c == pytest.approx(-0.43)
    n, c = tracked_plane(win, seed, cfg, n_down, np.array([0.0, 0.0, 0.46]))
    assert c == pytest.approx(-0.46)
