"""The ray casters' compiled per-pixel loops (``pipeline/camera/raycast_kernels.py``) give the
numpy path's depth and body ids bit for bit (``pipeline/tools/bench/render_reference.py``): on
box heaps seen from the generation camera and from close-up poses on box faces (the servo's
views, the near plane cutting boxes open among them), on heaps of the baseline's convex objects
(64-gon cylinders, prisms, hulls), on a camera whose rays run exactly parallel to box faces
(division by zero: ±inf and nan), and with a box reaching behind the camera."""

from __future__ import annotations

import dataclasses

import numpy as np
import pybullet as p
import pytest
from omegaconf import OmegaConf

from pipeline.camera.geometry import Intrinsics, camera_pose_above_bin
from pipeline.camera.raycast import BoxShape, boxes_from_pybullet, fill_ground, raycast_boxes
from pipeline.camera.raycast_convex import box_shape, convex_from_pybullet, raycast_convex
from pipeline.cell.bin import build_cell
from pipeline.runtime.cli import compose
from pipeline.simulation.heap import drop_heap
from pipeline.simulation.objects import ObjectSetSpec, create_body, sample_object
from pipeline.simulation.views import closeup_poses
from pipeline.tools.bench import render_reference as reference

SR300 = Intrinsics(416, 416, 411.7, 411.7, 207.5, 207.5)


def same(a: np.ndarray, b: np.ndarray) -> bool:
    """Same dtype, shape and bytes (nan-safe, and -0.0 differs from 0.0)."""
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


def both_ways(render, reference_render, shapes, intr, poses, near=0.1, far=2.0) -> int:
    """Render every pose both ways; assert the same bits and that something was seen (a pose
    5 cm from a face can see nothing: everything within the near plane); return the frames."""
    seen = 0
    for T in poses:
        depth, ids = render(shapes, intr, T, near, far)
        ref_depth, ref_ids = reference_render(shapes, intr, T, near, far)
        assert same(depth, ref_depth) and same(ids, ref_ids), "the kernel differs from numpy"
        seen += int((ids >= 0).sum())
    assert seen > 0
    return len(poses)


@pytest.fixture(scope="module")
def generate_cfg():
    return OmegaConf.to_object(compose("generate", ["experiment=smoke"]))


def test_box_heaps_bit_for_bit(generate_cfg):
    """4 heaps of 20 boxes from the generation camera and three close-ups each (0.15 m, the
    servo's d*, 0.2 m and 0.3 m, tilted with the faces), then 0.05 m, inside the near plane."""
    cfg = generate_cfg
    boxes = dataclasses.replace(cfg.boxes, min_count=20)
    client = p.connect(p.DIRECT)
    frames = 0
    try:
        for i in range(4):
            p.resetSimulation(physicsClientId=client)
            build_cell(client, cfg.bin, cfg.physics)
            heap = drop_heap(client, np.random.default_rng([7, 0, i]), boxes, cfg.bin, cfg.physics)
            poses = [camera_pose_above_bin(cfg.camera.height_above_bin_floor)]
            poses += closeup_poses(heap.boxes, np.random.default_rng([7, 1, i]), (0.15, 0.2, 0.3))
            poses += closeup_poses(heap.boxes, np.random.default_rng([7, 2, i]), (0.05,))
            frames += both_ways(
                raycast_boxes, reference.raycast_boxes, boxes_from_pybullet(client), SR300, poses
            )
            # the same boxes as convex solids: the float64 half-space kernel
            shapes = convex_from_pybullet(client)
            frames += both_ways(raycast_convex, reference.raycast_convex, shapes, SR300, poses[:2])
    finally:
        p.disconnect(client)
    assert frames >= 20


def test_convex_object_heaps_bit_for_bit():
    """Heaps of the baseline's out-of-domain objects (cylinders as 64-gons, prisms, hulls)
    dropped on a plane, from above and tilted."""
    spec = ObjectSetSpec()
    client = p.connect(p.DIRECT)
    try:
        p.setGravity(0, 0, -9.81, physicsClientId=client)
        plane = p.createCollisionShape(
            p.GEOM_BOX, halfExtents=[0.5, 0.5, 0.01], physicsClientId=client
        )
        p.createMultiBody(0, plane, basePosition=[0, 0, -0.01], physicsClientId=client)
        rng = np.random.default_rng(11)
        for k in range(8):
            shape = sample_object(rng, spec)
            pos = [rng.uniform(-0.08, 0.08), rng.uniform(-0.08, 0.08), 0.1 + 0.05 * k]
            create_body(
                client, shape, 300.0, 0.5, pos, p.getQuaternionFromEuler(rng.uniform(0, 3, 3))
            )
        for _ in range(240):
            p.stepSimulation(physicsClientId=client)
        shapes = convex_from_pybullet(client)
        top = camera_pose_above_bin(0.55)
        tilted = top.copy()
        c, s = np.cos(0.3), np.sin(0.3)
        tilted[:3, :3] = top[:3, :3] @ np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
        intr = Intrinsics(160, 160, 160.0, 160.0, 79.5, 79.5)
        assert both_ways(raycast_convex, reference.raycast_convex, shapes, intr, [top, tilted]) == 2
    finally:
        p.disconnect(client)


def test_rays_parallel_to_faces_and_a_box_behind_the_camera():
    """An axis-aligned box seen straight down by a camera whose principal point is a pixel
    centre: the centre column's and row's rays run exactly parallel to four faces (d_i = 0:
    1/0 = inf, 0·inf = nan); a second box reaches behind the camera (the whole image is its
    footprint) and is cut open by the near plane."""
    intr = Intrinsics(9, 9, 4.0, 4.0, 4.0, 4.0)
    down = camera_pose_above_bin(1.0)
    aligned = np.eye(4)
    behind = np.eye(4)
    behind[:3, 3] = [0.3, 0.0, 1.0]  # the camera's height: half of it behind the camera
    boxes = [
        BoxShape(3, aligned, np.array([0.1, 0.1, 0.1])),
        BoxShape(4, behind, np.array([0.1, 0.4, 0.2])),
    ]
    both_ways(raycast_boxes, reference.raycast_boxes, boxes, intr, [down])
    shapes = [box_shape(b.body_id, b.T_world_box, b.half_extents) for b in boxes]
    both_ways(raycast_convex, reference.raycast_convex, shapes, intr, [down])
    depth, ids = raycast_boxes(boxes[:1], intr, down, 0.1, 2.0)
    assert ids[4, 4] == 3 and depth[4, 4] == np.float32(0.9)  # the top face, 0.9 m away


def test_ground_bit_for_bit():
    """The analytic ground under a box, from above, tilted, and tilted so far that part of the
    image looks above the horizon (rays that never meet the plane), at two heights (the lower
    one partly beyond ``far``)."""
    intr = Intrinsics(64, 48, 40.0, 40.0, 31.5, 23.5)
    box = [BoxShape(3, np.eye(4), np.array([0.1, 0.1, 0.1]))]
    top = camera_pose_above_bin(1.0)
    kinds = set()
    for tilt in (0.0, 0.4, 1.3):
        T = top.copy()
        c, s = np.cos(tilt), np.sin(tilt)
        T[:3, :3] = top[:3, :3] @ np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
        for ground_z in (-0.02, -1.5):
            depth, ids = raycast_boxes(box, intr, T, 0.1, 2.0)
            ref_depth, ref_ids = depth.copy(), ids.copy()
            fill_ground(depth, ids, intr, T, ground_z, 7, 2.0)
            reference.fill_ground(ref_depth, ref_ids, intr, T, ground_z, 7, 2.0)
            assert same(depth, ref_depth) and same(ids, ref_ids)
            kinds |= set(np.unique(ids).tolist())
    assert kinds == {-1, 3, 7}  # ground, box and nothing (beyond far, above the horizon)


def test_scalar_fmin_fmax_are_numpys():
    """The loops' scalar ``_fmin`` / ``_fmax`` give ``np.fmin`` / ``np.fmax`` for every pair of
    nan, signed zeros, infinities and numbers, the sign of a zero included."""
    from pipeline.camera.raycast_kernels import _fmax, _fmin

    values = [np.nan, 0.0, -0.0, 1.5, -2.25, np.inf, -np.inf, 1e-300, 3.0]
    for mine, numpys in ((_fmin, np.fmin), (_fmax, np.fmax)):
        for a in values:
            for b in values:
                want, got = numpys(a, b), mine(a, b)
                assert same(np.float64(want), np.float64(got)), (numpys.__name__, a, b, got)
