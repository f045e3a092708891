"""Camera geometry and rendering, checked against answers worked out by hand."""

from __future__ import annotations

from types import SimpleNamespace as NS

import numpy as np
import pybullet as p
import pytest

from pipeline.camera.geometry import (
    Intrinsics,
    backproject,
    backproject_pixels,
    camera_pose_above_bin,
    pose_matrix,
    project,
    world_to_camera,
)
from pipeline.camera.render import render_depth
from pipeline.cell.bin import build_cell

SR300 = Intrinsics(416, 416, 411.7, 411.7, 207.5, 207.5)
CAM_HEIGHT = 0.625
BIN = NS(
    inner_length_x=0.40,
    inner_width_y=0.30,
    wall_height=0.15,
    wall_thickness=0.01,
    floor_thickness=0.02,
    lateral_friction=0.5,
)
PHYS = NS(gravity=-9.81, time_step=1 / 240, solver_iterations=50, friction_anchor=True)


def test_project_backproject_by_hand():
    # A point 0.1 m right of and 0.05 m below the optical axis at z = 0.5 m:
    # u = 411.7 * 0.1 / 0.5 + 207.5 = 289.84, v = 411.7 * 0.05 / 0.5 + 207.5 = 248.67.
    uv = project(np.array([0.1, 0.05, 0.5]), SR300)
    assert uv == pytest.approx([289.84, 248.67], abs=1e-9)
    depth = np.full((416, 416), 0.5, dtype=np.float32)
    pts = backproject(depth, SR300)
    assert pts.shape == (416, 416, 3)
    # Pixel (u=0, v=415): x = (0 - 207.5) / 411.7 * 0.5, y = (415 - 207.5) / 411.7 * 0.5.
    assert pts[415, 0] == pytest.approx([-0.252004, 0.252004, 0.5], abs=1e-6)


def test_backproject_pixels_by_hand():
    """The same point as above back from its pixel (289.84, 248.67) at z = 0.5 m, and a batch
    of two: the principal point at 1 m is (0, 0, 1); pixel (0, 415) at 0.5 m as above."""
    assert backproject_pixels([289.84, 248.67], 0.5, SR300) == pytest.approx([0.1, 0.05, 0.5])
    pts = backproject_pixels(np.array([[207.5, 207.5], [0.0, 415.0]]), np.array([1.0, 0.5]), SR300)
    assert pts.shape == (2, 3)
    np.testing.assert_allclose(pts, [[0, 0, 1], [-0.252004, 0.252004, 0.5]], atol=1e-6)


def test_backproject_rejects_wrong_shape():
    with pytest.raises(ValueError, match="expected"):
        backproject(np.zeros((10, 10), np.float32), SR300)


def test_camera_pose_looks_down():
    T = camera_pose_above_bin(CAM_HEIGHT)
    # The world origin (bin floor centre) is straight ahead, 0.625 m along the optical axis.
    assert world_to_camera(np.zeros(3), T) == pytest.approx([0, 0, CAM_HEIGHT])
    # World +x is image right, world +y is image up.
    assert world_to_camera(np.array([0.1, 0.2, 0]), T) == pytest.approx([0.1, -0.2, CAM_HEIGHT])


RENDERERS = ["tinyrenderer", "raycast"]


@pytest.mark.parametrize("renderer", RENDERERS)
def test_floor_and_ground_depth(client, renderer):
    build_cell(client, BIN, PHYS)
    ground = p.getBodyUniqueId(0, physicsClientId=client)
    frame = render_depth(
        client,
        SR300,
        camera_pose_above_bin(CAM_HEIGHT),
        0.1,
        2.0,
        ground=(-BIN.floor_thickness, ground),
        renderer=renderer,
    )
    # Bin floor straight below: 0.625 m to 1 mm (the requirement; in fact ~1e-6 m).
    assert abs(frame.depth_m[208, 208] - 0.625) < 1e-3
    # Image corner sees the ground, 20 mm below the bin floor (filled analytically).
    assert frame.depth_m[0, 0] == pytest.approx(0.645, abs=1e-5)
    assert frame.body_ids[0, 0] == ground


@pytest.mark.parametrize("renderer", RENDERERS)
def test_box_top_height_and_corner_pixel(client, renderer, static_box):
    """A 0.12 × 0.075 × 0.023 m box lying flat on the floor at (0.03, −0.02)."""
    build_cell(client, BIN, PHYS)
    half = [0.06, 0.0375, 0.0115]
    box = static_box(client, half, [0.03, -0.02, 0.0115])
    T = camera_pose_above_bin(CAM_HEIGHT)
    frame = render_depth(client, SR300, T, 0.1, 2.0, renderer=renderer)
    mask = frame.body_ids == box
    # Box top at 0.023 m above the floor: depth 0.625 - 0.023 = 0.602 m.
    assert np.median(frame.depth_m[mask]) == pytest.approx(0.602, abs=1e-4)
    # Corner (x = 0.09, y = 0.0175, z = 0.023) → camera (0.09, −0.0175, 0.602) →
    # u = 411.7 * 0.09 / 0.602 + 207.5 = 269.05, v = 411.7 * −0.0175 / 0.602 + 207.5 = 195.53.
    corner = project(world_to_camera(np.array([0.09, 0.0175, 0.023]), T), SR300)
    assert corner == pytest.approx([269.05, 195.53], abs=0.01)
    us, vs = np.nonzero(mask.T)
    # Pixel centres inside the box top: u in [186.98, 269.05] → 187..269; v in [195.53, 246.82].
    assert (us.min(), us.max(), vs.min(), vs.max()) == (187, 269, 196, 246)
    # The depth back-projects to the box top: the 3-D point at pixel (269, 196) is the corner
    # minus less than one pixel.
    pts = backproject(frame.depth_m, SR300)
    assert pts[196, 269] == pytest.approx(
        world_to_camera(np.array([0.09, 0.0175, 0.023]), T), abs=2e-3
    )


@pytest.mark.parametrize("renderer", RENDERERS)
@pytest.mark.parametrize("axis", ["x", "y"])
def test_raster_samples_pixel_centres(client, axis, renderer, static_box):
    """Render a plane tilted 25° and solve, per pixel, which ray the renderer sampled.

    For a plane n·X = d in the camera frame, the depth z at normalised image coordinates
    (x_n, y_n) satisfies n·(x_n, y_n, 1) = d / z, so one coordinate follows from z when the
    other is known. The sampled ray must pass through the pixel centre (sub-pixel accuracy).
    """
    T = camera_pose_above_bin(CAM_HEIGHT)
    angle = np.deg2rad(25)
    quat = p.getQuaternionFromEuler([angle, 0, 0] if axis == "x" else [0, angle, 0])
    centre = np.array([0.0, 0.0, 0.1])
    static_box(client, [0.5, 0.5, 0.01], centre.tolist(), quat)
    frame = render_depth(client, SR300, T, 0.1, 2.0, renderer=renderer)
    R = pose_matrix(centre, np.asarray(quat))[:3, :3]
    n_cam = np.linalg.inv(T)[:3, :3] @ R[:, 2]
    d = n_cam @ world_to_camera(centre + 0.01 * R[:, 2], T)
    z = frame.depth_m.astype(np.float64)
    v, u = np.mgrid[0:416, 0:416]
    if axis == "y":  # tilt about world y: depth varies along u
        yn = (v - SR300.cy) / SR300.fy
        sampled = ((d / z - n_cam[2] - n_cam[1] * yn) / n_cam[0]) * SR300.fx + SR300.cx
        err = sampled - u
    else:
        xn = (u - SR300.cx) / SR300.fx
        sampled = ((d / z - n_cam[2] - n_cam[0] * xn) / n_cam[1]) * SR300.fy + SR300.cy
        err = sampled - v
    assert np.abs(np.median(err[100:300, 100:300])) < 0.02


@pytest.mark.parametrize(
    "axis,angle",
    [((0, 0, 1), 90), ((1, 1, 0), 180), ((1, -2, 3), 180), ((0, 1, 0), 179.9), ((2, 1, -1), 37)],
)
def test_quat_from_matrix_including_half_turns(axis, angle):
    from pipeline.camera.geometry import quat_from_matrix

    a = np.asarray(axis, float) / np.linalg.norm(axis)
    h = np.radians(angle) / 2
    q_true = np.r_[a * np.sin(h), np.cos(h)]  # (x, y, z, w) by the axis-angle formula
    R = pose_matrix(np.zeros(3), q_true)[:3, :3]
    q = quat_from_matrix(R)
    assert min(np.abs(q - q_true).max(), np.abs(q + q_true).max()) < 1e-9
