"""The planning path's faster parts give exactly what they replaced: the 2 × 2 max-pool without
autograd, decoding all cells at once, the surface normals of many candidates at once, and
``Planner.plan`` as a whole against the reference path (``pipeline/tools/bench/
planning_reference.py``, the bench's comparison point) on the bench's images."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch
import torch.nn.functional as F
from conftest import default_config

from pipeline.camera.geometry import Intrinsics, backproject
from pipeline.grasping.types import GraspClass
from pipeline.planner.decode import decode_output, second_chance
from pipeline.planner.network import MaxPool2x2
from pipeline.planner.ranking import RankingConfig, surface_normal, surface_normals
from pipeline.tools.bench import planning_reference as reference

SR300 = Intrinsics(416, 416, 411.7, 411.7, 207.5, 207.5)


@pytest.fixture(autouse=True)
def one_thread():
    """One torch thread, as the bench's comparison runs (and quicker on a busy 2-core CPU)."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


def same(a, b) -> bool:
    """Bit for bit: arrays (dtype and bytes), else type and value."""
    if isinstance(a, np.ndarray):
        return isinstance(b, np.ndarray) and a.dtype == b.dtype and a.tobytes() == b.tobytes()
    return type(a) is type(b) and a == b


def same_list(xs, ys) -> bool:
    """Two lists of dataclasses (or None) with the same fields, bit for bit, in the same order."""
    if len(xs) != len(ys):
        return False
    for x, y in zip(xs, ys):
        if x is None or y is None:
            if not (x is None and y is None):
                return False
            continue
        if isinstance(x, np.ndarray):
            if not same(x, y):
                return False
            continue
        for f in dataclasses.fields(x):
            if not same(getattr(x, f.name), getattr(y, f.name)):
                return False
    return True


def test_max_pool_2x2_by_hand_and_with_nan():
    x = torch.tensor([[1.0, 5.0, -1.0, -2.0], [3.0, 2.0, -3.0, -4.0]])[None, None]
    x = torch.cat([x, x.flip(-2)], -2)  # (1, 1, 4, 4)
    pool = MaxPool2x2()
    with torch.no_grad():
        assert pool(x).tolist() == [[[[5.0, -1.0], [5.0, -1.0]]]]
        y = torch.randn(2, 3, 8, 6)
        y[0, 1, 3, 2] = float("nan")  # a NaN spreads to its window in both
        y[1, 2, 4:6, 0:2] = 0.5  # a tied window
        got, want = pool(y), F.max_pool2d(y, 2, 2)
    assert torch.equal(got.isnan(), want.isnan()) and got.isnan().sum() == 1
    assert torch.equal(torch.nan_to_num(got), torch.nan_to_num(want))


def test_max_pool_2x2_with_autograd_is_max_pool2d():
    """Under autograd the gradient of a tied window goes to one element, as nn.MaxPool2d's."""
    x = torch.full((1, 1, 4, 4), 2.0, requires_grad=True)
    MaxPool2x2()(x).sum().backward()
    assert x.grad.sum() == 4 and set(x.grad.unique().tolist()) == {0.0, 1.0}


def test_decode_and_second_chance_match_the_reference():
    """All cells at once = one cell at a time, on random outputs (many cells on each side of
    the thresholds, NG best in some)."""
    gen = torch.Generator().manual_seed(3)
    for _ in range(5):
        raw = torch.randn(6, 13, 13, generator=gen) * 3
        for threshold in (-1.0, 0.0, 0.3, 0.9):
            got = decode_output(raw, threshold=threshold)
            want = reference.decode_output(raw, threshold=threshold)
            assert len(got) > 0 or threshold == 0.9
            assert same_list(got, want)
            assert same_list(second_chance(got, 0.6, 0.3), reference.second_chance(want, 0.6, 0.3))


def test_surface_normals_match_surface_normal_one_by_one():
    """On a depth image of tilted boxes with holes and steps, at pixels all over it (its
    borders, holes and edges included): the same normals, bit for bit, or None where
    ``surface_normal`` gives None."""
    rng = np.random.default_rng(0)
    v, u = np.mgrid[0:416, 0:416].astype(np.float32)
    depth = 0.6 + 0.0004 * u - 0.0002 * v  # a tilted floor
    for _ in range(12):  # boxes: tilted tops, depth steps to the floor
        u0, v0 = rng.integers(0, 380, 2)
        w, h = rng.integers(20, 80, 2)
        gu, gv = rng.normal(0, 0.002, 2)
        top = rng.uniform(0.4, 0.55) + gu * (u - u0) + gv * (v - v0)
        box = (u >= u0) & (u < u0 + w) & (v >= v0) & (v < v0 + h)
        depth = np.where(box, top, depth)
    depth = depth + rng.normal(0, 0.0005, depth.shape)  # noise: no two normals alike
    depth[rng.random(depth.shape) < 0.03] = 0.0  # scattered missing pixels
    depth[100:130, 200:240] = 0.0  # a hole larger than a window
    depth = depth.astype(np.float32)
    points = backproject(depth, SR300)
    us = np.concatenate([rng.integers(0, 416, 400), [0, 1, 3, 4, 415, 412, 411, 215, 220]])
    vs = np.concatenate([rng.integers(0, 416, 400), [0, 2, 3, 4, 415, 413, 411, 115, 120]])
    for h, jump in ((3, 0.02), (1, 0.005), (0, 0.02)):
        want = [surface_normal(points, int(a), int(b), h, jump) for a, b in zip(us, vs)]
        got = surface_normals(points, us.tolist(), vs.tolist(), h, jump)
        assert same_list(got, want)
        assert sum(n is None for n in want) > 0 and sum(n is not None for n in want) > 300
    assert surface_normals(points, [], [], 3, 0.02) == []


@pytest.fixture(scope="module")
def bench_images():
    from omegaconf import OmegaConf

    from pipeline.runtime.cli import compose
    from pipeline.tools.bench.common import bench_scenes, intrinsics_of

    cfg = OmegaConf.to_object(compose("generate", ["experiment=smoke"]))
    return [sc.depth_m for sc in bench_scenes(cfg, 8)], intrinsics_of(cfg)


class DepthDrivenOutput(torch.nn.Module):
    """A stand-in for a trained network: ``net``'s offsets, class logits from each cell's mean
    height in the normalised depth (higher cells graspable, lower ones NG) plus fixed noise, so
    that some cells pass th, some only the second tier's floor, and some neither."""

    def __init__(self, net, cut: float):
        super().__init__()
        self.inner, self.cfg, self.cut = net, net.cfg, cut
        self.noise = torch.randn(1, 4, 13, 13, generator=torch.Generator().manual_seed(0))

    def forward(self, x):
        raw = self.inner(x).clone()
        height = -F.avg_pool2d(x, 32)  # (B, 1, 13, 13)
        raw[:, 2:] = 12 * (height - self.cut) + self.noise
        raw[:, 2 + int(GraspClass.NG)] = -12 * (height[:, 0] - self.cut) + self.noise[:, 3]
        return raw


def test_plan_matches_the_reference_on_the_bench_images(bench_images):
    """``Planner.plan`` (second tier on, as the closed loop plans) and the reference path give
    the same candidates, every field bit for bit, in the same order, on the bench's 8 images:
    with the untrained ``default`` network (its raw output equal too), with every cell a
    candidate (class bias 0) and with depth-driven outputs (tens of candidates per image, both
    tiers)."""
    from pipeline.planner.planner import fallback_threshold
    from pipeline.runtime.cli import compose
    from pipeline.tools.bench.planning import untrained_planner

    images, intr = bench_images
    full = compose("train", ["experiment=default"])
    planner = untrained_planner(full)
    floor = fallback_threshold(full, planner.ranking.threshold)
    ref = reference.ReferencePlanner(planner)
    assert torch.equal(planner.predict(np.stack(images)), ref.predict(np.stack(images)))
    with torch.no_grad():
        planner.net.out.bias[2:] = 0.0
    every = reference.ReferencePlanner(planner)
    net = planner.net
    planner.net = DepthDrivenOutput(net, 1.0).eval()
    driven = reference.ReferencePlanner(planner)
    counts = []
    for ref_plan, network in ((every, net), (driven, planner.net)):
        planner.net = network
        for depth in images:
            got = planner.plan(depth, intr, fallback_threshold=floor)
            want = ref_plan.plan(depth, intr, fallback_threshold=floor)
            assert same_list(got, want) and planner.last_reason == ref_plan.last_reason
            counts.append((len(got), sum(c.second_tier for c in got)))
    every_counts, driven_counts = counts[:8], counts[8:]
    assert all(n == 169 and 0 < n2 < n for n, n2 in every_counts)
    assert all(20 < n < 169 for n, _ in driven_counts) and sum(n2 for _, n2 in driven_counts) > 0


def test_bench_comparison_figures(bench_images):
    from pipeline.runtime.cli import compose
    from pipeline.tools.bench.planning import compare_plans, untrained_planner

    images, intr = bench_images

    class Scene:
        def __init__(self, depth):
            self.depth_m = depth

    planner = untrained_planner(compose("train", ["experiment=default"]))
    with torch.no_grad():
        planner.net.out.bias[2:] = 0.0
    out = compare_plans(planner, [Scene(d) for d in images[:2]], intr, 0.025, 1, "k")
    assert set(out) == {"k_ms", "k_reference_ms", "k_ratio", "k_candidates", "k_same_candidates"}
    assert out["k_same_candidates"] == 1.0 and out["k_candidates"] == 169.0
    assert out["k_ratio"] == pytest.approx(out["k_ms"] / out["k_reference_ms"])


def test_rank_grasps_with_given_points_is_the_same():
    cfg = default_config(RankingConfig, d_ground=0.645, threshold=0.5)
    depth = np.full((416, 416), 0.6, np.float32)
    depth[100:200, 100:200] = 0.5
    preds = [
        reference.GraspPrediction(u, v, GraspClass.B, 0.9, np.full(4, 0.9, np.float32))
        for u, v in ((150.0, 150.0), (99.6, 150.2), (300.0, 20.0), (0.0, 415.0))
    ]
    from pipeline.planner.ranking import rank_grasps

    want = reference.rank_grasps(preds, depth, SR300, cfg)
    assert len(want) == 4
    assert same_list(rank_grasps(preds, depth, SR300, cfg), want)
    assert same_list(rank_grasps(preds, depth, SR300, cfg, backproject(depth, SR300)), want)
