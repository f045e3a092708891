"""The sensor model's compiled loop (``pipeline/camera/sensor_kernels.py``) gives the numpy
expression it replaced (``pipeline/tools/bench/sensor_reference.py``) bit for bit: incidence
angles on synthetic frames with tilted faces, depth steps, exact ties between the two
neighbours' steps, no-data pixels and noise, on the degenerate sizes, and on heap frames from
above and from the servo's close-up poses; and the whole SR300 model on those heap frames."""

from __future__ import annotations

import dataclasses

import numpy as np
import pybullet as p
from omegaconf import OmegaConf

from pipeline.camera.geometry import Intrinsics, camera_pose_above_bin
from pipeline.camera.render import render_depth
from pipeline.camera.sensor import apply_sensor_model, incidence_angles
from pipeline.cell.bin import build_cell
from pipeline.runtime.cli import compose
from pipeline.simulation.heap import drop_heap
from pipeline.simulation.views import closeup_poses
from pipeline.tools.bench import sensor_reference


def same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


def synthetic_frame(rng: np.random.Generator, h: int, w: int) -> np.ndarray:
    """(h, w) float64 depth, metres: a floor at 0.9 m under tilted rectangles, 2 % of the
    pixels without data, float32-rounded as a renderer delivers it."""
    z = np.full((h, w), 0.9)
    for _ in range(12):
        r0, c0 = rng.integers(0, max(h - 4, 1)), rng.integers(0, max(w - 4, 1))
        bh, bw = rng.integers(3, max(h // 2, 4)), rng.integers(3, max(w // 2, 4))
        gy, gx = rng.normal(0, 0.3, 2)
        rr, cc = np.mgrid[0:bh, 0:bw]
        face = 0.6 + rng.uniform(0, 0.2) + gx * cc / 500 + gy * rr / 500
        sub = z[r0 : r0 + bh, c0 : c0 + bw]
        sub[:] = np.minimum(sub, face[: sub.shape[0], : sub.shape[1]])
    z[rng.random(z.shape) < 0.02] = 0.0
    return z.astype(np.float32).astype(np.float64)


def test_incidence_angles_bit_for_bit_on_synthetic_frames():
    intr = Intrinsics(64, 48, 500.0, 500.0, 31.5, 23.5)
    rng = np.random.default_rng(3)
    for k in range(8):
        z = synthetic_frame(rng, intr.height, intr.width)
        if k % 2:
            z = z + rng.normal(0, 2e-4, z.shape) * (z > 0)
        assert same_bits(incidence_angles(z, intr), sensor_reference.incidence_angles(z, intr))
    # Exact ties: a staircase whose forward and backward steps are equal everywhere, and a
    # plane (equal steps of zero), each with a no-data column and row.
    stairs = 0.6 + 0.001 * (np.arange(intr.width)[None, :] + np.arange(intr.height)[:, None])
    flat = np.full((intr.height, intr.width), 0.7)
    for z in (stairs, flat):
        z = z.copy()
        z[:, 10] = 0.0
        z[7, :] = 0.0
        assert same_bits(incidence_angles(z, intr), sensor_reference.incidence_angles(z, intr))
    for h, w in ((1, 1), (1, 7), (7, 1), (2, 2)):
        small = Intrinsics(w, h, 500.0, 500.0, (w - 1) / 2, (h - 1) / 2)
        z = np.full((h, w), 0.8)
        assert same_bits(incidence_angles(z, small), sensor_reference.incidence_angles(z, small))


def test_sensor_model_bit_for_bit_on_heap_frames(monkeypatch):
    """Heaps of 20 boxes from above and from close-up poses: the incidence angles and the whole
    SR300 model (same generator seed) the same bits with the compiled loop and the numpy one."""
    from pipeline.camera import sensor

    cfg = OmegaConf.to_object(compose("evaluate", ["experiment=smoke", "sensor=sr300"]))
    intr = Intrinsics.from_config(cfg.camera)
    boxes = dataclasses.replace(cfg.boxes, min_count=20)
    client = p.connect(p.DIRECT)
    frames = []
    try:
        for i in range(2):
            p.resetSimulation(physicsClientId=client)
            cell = build_cell(client, cfg.bin, cfg.physics)
            heap = drop_heap(client, np.random.default_rng([7, 0, i]), boxes, cfg.bin, cfg.physics)
            poses = [camera_pose_above_bin(cfg.camera.height_above_bin_floor)]
            poses += closeup_poses(heap.boxes, np.random.default_rng([7, 1, i]), (0.15, 0.3))[:3]
            for T in poses:
                frame = render_depth(
                    client,
                    intr,
                    T,
                    cfg.camera.near,
                    cfg.camera.far,
                    ground=(-cfg.bin.floor_thickness, cell[0]),
                    renderer="raycast",
                )
                frames.append(frame.depth_m)
    finally:
        p.disconnect(client)
    assert len(frames) >= 4
    compiled = [
        (
            incidence_angles(z, intr),
            apply_sensor_model(z, cfg.sensor, np.random.default_rng(k), intr),
        )
        for k, z in enumerate(frames)
    ]
    monkeypatch.setattr(sensor, "incidence_angles", sensor_reference.incidence_angles)
    for k, z in enumerate(frames):
        theta, noisy = compiled[k]
        assert same_bits(theta, sensor_reference.incidence_angles(z, intr))
        assert same_bits(
            noisy, sensor.apply_sensor_model(z, cfg.sensor, np.random.default_rng(k), intr)
        )
