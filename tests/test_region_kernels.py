"""The descriptor's compiled loops (``pipeline/servo/region_kernels.py``) give the numpy
expressions they replaced bit for bit: Eq. 12's mask over an image, Eqs. 12–14 on a crop
(without normal smoothing) and the tracked plane's slab counts, on random inputs with no-data
pixels, exact ties and offsets exactly ``tol`` apart, and ``describe_surface`` as a whole on
heap frames from the servo's close-up poses with the numpy expressions
(``pipeline/tools/bench/descriptor_reference.py``) put back."""

from __future__ import annotations

import dataclasses

import numpy as np
import pybullet as p
import pytest
from omegaconf import OmegaConf

from pipeline.camera.geometry import Intrinsics, camera_pose_above_bin
from pipeline.camera.render import render_depth
from pipeline.cell.bin import build_cell
from pipeline.runtime.cli import compose
from pipeline.servo import region
from pipeline.servo.descriptor import describe_surface
from pipeline.servo.region_kernels import on_plane_mask, plane_rules_unsmoothed, slab_counts
from pipeline.simulation.heap import drop_heap
from pipeline.simulation.views import closeup_poses
from pipeline.tools.bench import descriptor_reference as reference

f32 = np.float32


def test_plane_rules_bit_for_bit():
    """Crops of a tilted plane with noise, holes and a step, and the degenerate sizes (fewer
    than 3 rows or columns: no rules)."""
    rng = np.random.default_rng(5)
    passed = 0
    for h, w in ((40, 56), (2, 9), (9, 2), (3, 3)):
        xn = ((np.arange(w, dtype=f32) - f32(20.5)) / f32(60.0)).astype(f32)
        yn = ((np.arange(h, dtype=f32) - f32(15.5)) / f32(60.0)).astype(f32)
        for _ in range(10):
            n = rng.normal(size=3)
            n[2] = -abs(n[2]) - 1.0  # towards the camera
            n /= np.linalg.norm(n)
            nx, ny, nz = (f32(a) for a in n)
            d = rng.uniform(0.3, 0.6)
            # depth of the plane n . P + d = 0 along each ray, plus noise, a step and holes
            Z = (-d / (nx * xn[None, :] + ny * yn[:, None] + nz)).astype(f32)
            Z += rng.normal(0.0, 0.001, (h, w)).astype(f32)
            Z[:, w // 2 :] += f32(0.02) * (rng.random() < 0.5)
            Z[rng.random((h, w)) < 0.05] = 0.0
            X, Y = Z * xn[None, :], Z * yn[:, None]
            valid = Z > 0
            eps, k = f32(rng.uniform(0.002, 0.01)), f32(1.0 - 0.05 / 2.0)
            got = plane_rules_unsmoothed(X, Y, Z, valid, xn, yn, nx, ny, nz, f32(d), eps, k)
            want = reference.plane_rules_unsmoothed(
                X, Y, Z, valid, xn, yn, nx, ny, nz, f32(d), eps, k
            )
            for a, b in zip(got, want):
                assert a.dtype == b.dtype and np.array_equal(a, b)
            passed += int(got[1].sum())
    assert passed > 0  # some pixels pass every rule


def test_on_plane_mask_bit_for_bit():
    rng = np.random.default_rng(3)
    H, W = 48, 64
    xn = ((np.arange(W, dtype=f32) - f32(31.5)) / f32(40.0)).astype(f32)
    yn = ((np.arange(H, dtype=f32) - f32(23.5)) / f32(40.0)).astype(f32)
    for _ in range(20):
        n = rng.normal(size=3)
        n /= np.linalg.norm(n)
        nx, ny, nz = (f32(a) for a in n)
        Z = rng.uniform(0.2, 0.8, (H, W)).astype(f32)
        Z[rng.random((H, W)) < 0.1] = 0.0
        # points on the plane n . P + d = 0 through a pixel's point, so many are near it
        d_hat = f32(-(nx * xn[10] + ny * yn[20] + nz) * Z[20, 10])
        eps = f32(rng.uniform(0.001, 0.05))
        got = on_plane_mask(Z, xn, yn, nx, ny, nz, d_hat, eps)
        want = reference.on_plane_mask(Z, xn, yn, nx, ny, nz, d_hat, eps)
        assert got.dtype == want.dtype and np.array_equal(got, want)
        assert got.any() and not got.all()


def test_slab_counts_bit_for_bit_with_ties_at_tol():
    rng = np.random.default_rng(4)
    tol = 0.004
    for n in (1, 10, 441):
        d = rng.normal(0.5, 0.01, n)
        d[: n // 3] = np.round(d[: n // 3] / tol) * tol  # offsets a multiple of tol apart
        got, want = slab_counts(d, tol), reference.slab_counts(d, tol)
        assert got.dtype == want.dtype and np.array_equal(got, want)
    # by hand: 0 and 0.003 are within 0.004, 0.004 from 0 is not (strict <)
    assert slab_counts(np.array([0.0, 0.003, 0.004, 0.01]), 0.004).tolist() == [2, 3, 2, 1]


@pytest.fixture()
def numpy_region(monkeypatch):
    """``pipeline.servo.region`` with the numpy expressions in place of the compiled loops."""

    def put_back():
        monkeypatch.setattr(region, "on_plane_mask", reference.on_plane_mask)
        monkeypatch.setattr(region, "slab_counts", reference.slab_counts)
        monkeypatch.setattr(region, "plane_rules_unsmoothed", reference.plane_rules_unsmoothed)

    return put_back


def test_describe_surface_unchanged_on_heap_frames(numpy_region):
    """Heaps of 20 boxes seen from the servo's close-up poses (and from above), each box face
    at the image centre described twice per frame: from scratch and while tracking its normal
    and plane (``tracked_plane``): every feature the same bits with the compiled loops and with
    the numpy expressions."""
    cfg = OmegaConf.to_object(compose("evaluate", ["experiment=smoke"]))
    dcfg = cfg_descriptor()
    intr = Intrinsics.from_config(cfg.camera)
    boxes = dataclasses.replace(cfg.boxes, min_count=20)
    client = p.connect(p.DIRECT)
    frames = []
    try:
        for i in range(3):
            p.resetSimulation(physicsClientId=client)
            cell = build_cell(client, cfg.bin, cfg.physics)
            heap = drop_heap(client, np.random.default_rng([9, 0, i]), boxes, cfg.bin, cfg.physics)
            poses = [camera_pose_above_bin(cfg.camera.height_above_bin_floor)]
            poses += closeup_poses(heap.boxes, np.random.default_rng([9, 1, i]), (0.15, 0.3))
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

    def describe_all():
        out = []
        for depth in frames:
            seed = (intr.width / 2, intr.height / 2)
            first, reason = describe_surface(depth, intr, seed, dcfg)
            out.append((first, reason))
            if first is not None:
                tracked = describe_surface(
                    depth,
                    intr,
                    seed,
                    dcfg,
                    expected_normal_cam=first.normal_cam,
                    expected_point_cam=first.center_cam,
                )
                out.append(tracked)
        return out

    compiled = describe_all()
    numpy_region()
    reference = describe_all()
    assert len(compiled) == len(reference) >= 12
    assert sum(f is not None for f, _ in compiled) >= 6
    for (a, ra), (b, rb) in zip(compiled, reference):
        assert ra == rb and (a is None) == (b is None)
        if a is None:
            continue
        for field in dataclasses.fields(a):
            x, y = getattr(a, field.name), getattr(b, field.name)
            if isinstance(x, np.ndarray):
                assert x.dtype == y.dtype and x.tobytes() == y.tobytes(), field.name
            else:
                assert x == y, field.name


def cfg_descriptor():
    """The descriptor settings the closed loop uses (conf/servo/)."""
    from conftest import default_config

    from pipeline.servo.descriptor import DescriptorConfig

    return default_config(DescriptorConfig)
