"""The Dex-Net-style planner's faster paths give the results of the plain ones, to the bit.

* :func:`pipeline.dexnet.gqcnn.extract_crops` (crops written in place, heights relative to the
  candidates computed for all crops at once, the NaN-holed source image shared across the CEM's
  scoring rounds) against the crop-by-crop implementation it replaced, kept here.
* The whole plan (every CEM iteration's candidates and scores, the grasp) with the mixtures
  fitted on one BLAS and OpenMP thread (``cem.GMM_THREADS = 1``), the shared crop source and
  the GQ-CNN's pooling by ``MaxPool2x2``'s inference path, against the libraries' own thread
  setting, the reference crops and ``max_pool2d``, on synthetic heaps.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest
import torch
from conftest import default_config

import pipeline.dexnet.cem as cem_mod
import pipeline.dexnet.planner as planner_mod
from pipeline.camera.geometry import Intrinsics, camera_pose_above_bin
from pipeline.dexnet.cem import CEMConfig
from pipeline.dexnet.gqcnn import (
    GQCNN,
    CropConfig,
    GQCNNConfig,
    candidate_inputs,
    crop_angle,
    crop_source,
    extract_crops,
    pose_input,
)
from pipeline.dexnet.planner import DexNetPlanner, Workspace
from pipeline.dexnet.quality import PlanarityConfig
from pipeline.dexnet.sampling import SamplerConfig
from pipeline.planner.network import MaxPool2x2

FLOOR = 0.625  # camera height above the bin floor (conf/camera/sr300.yaml)
INTR = Intrinsics(200, 200, 200.0, 200.0, 99.5, 99.5)
CROP = default_config(CropConfig, d_ground=FLOOR + 0.02)  # conf/dexnet/: 64-px window, 32-px crop


def reference_extract_crops(depth_m, uv, depth, axes_cam, cfg):
    """The crop-by-crop implementation that :func:`extract_crops` replaced."""
    depth_m = np.asarray(depth_m, np.float32)
    uv = np.asarray(uv, np.float64).reshape(-1, 2)
    n, s = len(uv), cfg.size
    out = np.empty((n, 1, s, s), np.float32)
    if n == 0:
        return out
    source = np.where(depth_m > 0, depth_m, np.nan).astype(np.float32)
    scale = s / cfg.window_px
    angles = np.degrees(crop_angle(axes_cam))
    centre = float(s // 2)
    for i in range(n):
        u, v = uv[i]
        m = cv2.getRotationMatrix2D((float(u), float(v)), float(angles[i]), scale)
        m[0, 2] += centre - u
        m[1, 2] += centre - v
        crop = cv2.warpAffine(
            source,
            m,
            (s, s),
            flags=cv2.INTER_NEAREST,
            borderMode=cv2.BORDER_CONSTANT,
            borderValue=float("nan"),
        )
        rel = (crop - float(depth[i])) / cfg.depth_scale
        out[i, 0] = np.where(np.isfinite(rel), rel, cfg.missing_value)
    return out


def heap(seed: int, h: int = 200, w: int = 200) -> np.ndarray:
    """A bin floor at FLOOR with a few boxes (flat or tilted tops) and holes of no data."""
    rng = np.random.default_rng(seed)
    depth = np.full((h, w), FLOOR)
    vv, uu = np.mgrid[0:h, 0:w]
    for _ in range(6):
        u0, v0 = rng.integers(40, w - 80), rng.integers(40, h - 80)
        du, dv = rng.integers(20, 60, size=2)
        top = FLOOR - rng.uniform(0.03, 0.15) + rng.uniform(-4e-4, 4e-4) * (uu - u0)
        box = (uu >= u0) & (uu < u0 + du) & (vv >= v0) & (vv < v0 + dv)
        depth = np.where(box, np.minimum(depth, top), depth)
    depth[rng.random((h, w)) < 0.02] = 0.0
    return depth


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_extract_crops_equals_the_crop_by_crop_reference(seed):
    rng = np.random.default_rng(seed)
    depth = heap(seed).astype(np.float32)
    n = 300
    uv = rng.integers(-10, 210, size=(n, 2))  # some near and outside the image
    cand_depth = rng.uniform(0.4, 0.7, n)
    axes = rng.normal(size=(n, 3))
    axes[: n // 4, :2] = 0.0  # along the optical axis: no rotation
    axes[n // 4 : n // 2, 1] = 0.0  # exact multiples of 90 degrees
    axes[n // 4 : n // 2, 0] *= rng.choice([-1.0, 1.0], n // 4) / np.abs(axes[n // 4 : n // 2, 0])
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    ref = reference_extract_crops(depth, uv, cand_depth, axes, CROP)
    new = extract_crops(depth, uv, cand_depth, axes, CROP)
    shared = extract_crops(depth, uv, cand_depth, axes, CROP, source=crop_source(depth))
    assert ref.dtype == new.dtype == shared.dtype == np.float32
    assert np.array_equal(ref, new)
    assert np.array_equal(ref, shared)
    assert extract_crops(depth, uv[:0], cand_depth[:0], axes[:0], CROP).shape == (0, 1, 32, 32)


def _planners() -> list[DexNetPlanner]:
    ws = Workspace(0.3, 0.3, 0.005, camera_pose_above_bin(FLOOR))
    args = (ws, default_config(SamplerConfig), default_config(CEMConfig))
    torch.manual_seed(0)
    net = GQCNN(GQCNNConfig(crop_size=CROP.size, width=16, fc=128)).eval()
    return [
        DexNetPlanner("planarity", *args, default_config(PlanarityConfig)),
        DexNetPlanner("gqcnn", *args, default_config(PlanarityConfig), CROP, net),
    ]


def _reference_inputs(depth_m, cands, cfg, source=None):
    return reference_extract_crops(depth_m, cands.uv, cands.depth, cands.axis, cfg), pose_input(
        cands, cfg
    )


def test_plans_equal_the_plain_path(monkeypatch):
    images = [heap(seed) for seed in (3, 4)]
    runs = {}
    for name in ("plain", "fast"):
        with monkeypatch.context() as m:
            if name == "plain":
                m.setattr(cem_mod, "GMM_THREADS", None)
                m.setattr(planner_mod, "candidate_inputs", _reference_inputs)
                m.setattr(MaxPool2x2, "forward", torch.nn.MaxPool2d.forward)
            else:
                assert cem_mod.GMM_THREADS == 1
                assert planner_mod.candidate_inputs is candidate_inputs
            runs[name] = [
                p.run_cem(d, INTR, np.random.default_rng([7, i]))
                for p in _planners()
                for i, d in enumerate(images)
            ]
    for plain, fast in zip(runs["plain"], runs["fast"], strict=True):
        assert len(plain.best) == 1
        assert len(plain.iterations) == len(fast.iterations) == 4
        for a, b in zip(plain.iterations, fast.iterations, strict=True):
            assert np.array_equal(a.candidates.uv, b.candidates.uv)
            assert np.array_equal(a.candidates.axis, b.candidates.axis)
            assert np.array_equal(a.scores, b.scores)
            assert np.array_equal(a.elite_idx, b.elite_idx)
        assert np.array_equal(plain.best.uv, fast.best.uv)
        assert plain.best_score == fast.best_score
        assert plain.num_scored == fast.num_scored
