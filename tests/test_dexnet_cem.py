"""Cross-entropy method policy (gqcnn CrossEntropyRobustGraspingPolicy) on a synthetic level plane.

Camera: 200 x 200 px, fx = fy = 200, cx = cy = 99.5; level plane at 0.5 m. With the default
68-px border the acceptable pixels are u, v in [68, 131] (64 x 64).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from conftest import default_config

import pipeline.dexnet.cem as cem_mod
from pipeline.camera.geometry import Intrinsics
from pipeline.dexnet.cem import CEMConfig, cross_entropy_method
from pipeline.dexnet.sampling import SamplerConfig, point_cloud_image

INTR = Intrinsics(200, 200, 200.0, 200.0, 99.5, 99.5)
TARGET = np.array([120, 80])
CEM, SAMPLER = default_config(CEMConfig), default_config(SamplerConfig)  # conf/dexnet/


@pytest.fixture(scope="module")
def cloud():
    return point_cloud_image(np.full((200, 200), 0.5), INTR, SAMPLER)


def peak(cands):
    """Higher is better: minus the pixel distance to (u, v) = (120, 80)."""
    return -np.linalg.norm(cands.uv - TARGET, axis=1)


@pytest.fixture
def components(monkeypatch):
    """Record the n_components of every GaussianMixture the CEM builds."""
    seen = []
    base = cem_mod.GaussianMixture

    class Recording(base):
        def fit(self, X, y=None):
            seen.append((self.n_components, len(X)))
            return super().fit(X, y)

    monkeypatch.setattr(cem_mod, "GaussianMixture", Recording)
    return seen


def test_default_sizes(cloud, components):
    # 200 seeds -> ceil(0.25 * 200) = 50 elites, ceil(0.4 * 50) = 20 components -> 50 samples
    # -> ceil(0.25 * 50) = 13 elites, ceil(0.4 * 13) = 6 components -> 50 -> 13 -> final 50.
    res = cross_entropy_method(cloud, peak, CEM, SAMPLER, np.random.default_rng(0))
    assert [len(it.candidates) for it in res.iterations] == [200, 50, 50, 50]
    assert [len(it.scores) for it in res.iterations] == [200, 50, 50, 50]
    assert [len(it.elite_idx) for it in res.iterations] == [50, 13, 13, 1]
    assert components == [(20, 50), (6, 13), (6, 13)]
    assert res.num_scored == 350
    assert len(res.best) == 1
    # The final "elite" is the argmax, and it is the returned best.
    final = res.iterations[-1]
    assert final.scores[final.elite_idx[0]] == res.best_score == final.scores.max()
    # Elites are the top scores, best first.
    it0 = res.iterations[0]
    assert np.all(it0.scores[it0.elite_idx] >= np.sort(it0.scores)[-50])
    assert np.all(np.diff(it0.scores[it0.elite_idx]) <= 0)


def test_changed_parameters(cloud, components):
    # 40 seeds -> ceil(0.5 * 40) = 20 elites, ceil(0.1 * 20) = 2 components -> 15 samples
    # -> ceil(0.5 * 15) = 8 elites, ceil(0.1 * 8) = 1 component -> 15 -> final 15.
    cfg = dataclasses.replace(
        CEM,
        num_seed_samples=40,
        num_gmm_samples=15,
        num_iters=2,
        gmm_refit_p=0.5,
        gmm_component_frac=0.1,
    )
    res = cross_entropy_method(cloud, peak, cfg, SAMPLER, np.random.default_rng(1))
    assert [len(it.candidates) for it in res.iterations] == [40, 15, 15]
    assert [len(it.elite_idx) for it in res.iterations] == [20, 8, 1]
    assert components == [(2, 20), (1, 8)]
    assert res.num_scored == 70


def test_zero_iterations_returns_argmax_of_seeds(cloud, components):
    res = cross_entropy_method(
        cloud, peak, dataclasses.replace(CEM, num_iters=0), SAMPLER, np.random.default_rng(2)
    )
    assert [len(it.candidates) for it in res.iterations] == [200]
    assert components == []
    assert res.best_score == res.iterations[0].scores.max()


def test_components_never_exceed_elites(cloud, components):
    # frac 1.0 with 3 elites -> 3 components (not more than the 3 points).
    cfg = dataclasses.replace(
        CEM,
        num_seed_samples=10,
        num_gmm_samples=10,
        num_iters=1,
        gmm_refit_p=0.25,
        gmm_component_frac=1.0,
    )
    res = cross_entropy_method(cloud, peak, cfg, SAMPLER, np.random.default_rng(3))
    assert components == [(3, 3)]
    assert [len(it.candidates) for it in res.iterations] == [10, 10]


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_best_lands_near_the_peak(cloud, seed):
    res = cross_entropy_method(cloud, peak, CEM, SAMPLER, np.random.default_rng(seed))
    # Dex-Net returns the argmax of the *final* set of 50, so "a few pixels", not exactly 0
    # (over 60 seeds: median 2 px, worst 4.5 px) ...
    assert np.linalg.norm(res.best.uv[0] - TARGET) <= 5.0
    # ... but the sets do concentrate: median distance ~35 px for the seeds, ~4 px at the end.
    med = [np.median(-it.scores) for it in res.iterations]
    assert med[-1] < 0.25 * med[0]
    np.testing.assert_allclose(res.best.axis[0], [0, 0, 1], atol=1e-9)
    # Every scored candidate was acceptable: inside the border and valid.
    for it in res.iterations:
        uv = it.candidates.uv
        assert uv.min() >= 68 and uv.max() <= 131
        assert cloud.valid[uv[:, 1], uv[:, 0]].all()


def test_deterministic_for_same_seed(cloud):
    a = cross_entropy_method(cloud, peak, CEM, SAMPLER, np.random.default_rng(42))
    b = cross_entropy_method(cloud, peak, CEM, SAMPLER, np.random.default_rng(42))
    assert len(a.iterations) == len(b.iterations)
    for ia, ib in zip(a.iterations, b.iterations):
        np.testing.assert_array_equal(ia.candidates.uv, ib.candidates.uv)
        np.testing.assert_array_equal(ia.elite_idx, ib.elite_idx)
    np.testing.assert_array_equal(a.best.uv, b.best.uv)
    c = cross_entropy_method(cloud, peak, CEM, SAMPLER, np.random.default_rng(43))
    assert not np.array_equal(a.iterations[1].candidates.uv, c.iterations[1].candidates.uv)


def test_ties_broken_by_order_and_nan_is_worst(cloud):
    # Constant scores: elites are the first ceil(0.25 N) candidates (stable sort).
    res = cross_entropy_method(
        cloud,
        lambda c: np.zeros(len(c)),
        dataclasses.replace(CEM, num_iters=1),
        SAMPLER,
        np.random.default_rng(4),
    )
    np.testing.assert_array_equal(res.iterations[0].elite_idx, np.arange(50))

    def nan_but_peak(c):
        s = peak(c)
        s[::2] = np.nan
        return s

    res = cross_entropy_method(cloud, nan_but_peak, CEM, SAMPLER, np.random.default_rng(5))
    assert np.isfinite(res.best_score)
    for it in res.iterations:
        assert np.all(np.isfinite(it.scores[it.elite_idx]))


def test_empty_valid_mask_gives_empty_result():
    empty = point_cloud_image(
        np.full((200, 200), 0.5), INTR, SAMPLER, object_mask=np.zeros((200, 200), bool)
    )
    calls = []
    res = cross_entropy_method(
        empty, lambda c: calls.append(len(c)) or peak(c), CEM, SAMPLER, np.random.default_rng(6)
    )
    assert len(res.best) == 0 and res.best_score == -math.inf
    assert res.iterations == [] and res.num_scored == 0 and calls == []


def test_tiny_region_and_duplicate_elites(cloud):
    # A 2 x 2 object: 4 seeds, GMM samples outside it are rejected and resampled; elites repeat
    # pixels (fewer distinct points than components) without warnings escaping.
    mask = np.zeros((200, 200), bool)
    mask[100:102, 100:102] = True
    small = point_cloud_image(np.full((200, 200), 0.5), INTR, SAMPLER, object_mask=mask)
    res = cross_entropy_method(small, peak, CEM, SAMPLER, np.random.default_rng(7))
    assert len(res.iterations[0].candidates) == 4
    for it in res.iterations:
        assert mask[it.candidates.uv[:, 1], it.candidates.uv[:, 0]].all()
    assert tuple(res.best.uv[0]) == (101, 100)  # nearest of the 4 pixels to (120, 80)


def test_score_fn_shape_is_checked(cloud):
    with pytest.raises(ValueError):
        cross_entropy_method(cloud, lambda c: np.zeros(3), CEM, SAMPLER, np.random.default_rng(8))
