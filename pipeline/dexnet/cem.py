"""Cross-entropy method suction policy, after gqcnn's ``CrossEntropyRobustGraspingPolicy``
(``gqcnn/grasping/policy/policy.py``) with the Dex-Net 4.0 suction parameters.

The search runs over 2-D pixel positions (u, v) of a depth image (u = column, v = row); at each
pixel the contact point, depth and approach axis are read from the image
(:func:`pipeline.dexnet.sampling.candidates_at`), as gqcnn does for suction.
"""

from __future__ import annotations

import contextlib
import functools
import math
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from sklearn.exceptions import ConvergenceWarning
from sklearn.mixture import GaussianMixture
from threadpoolctl import ThreadpoolController

from pipeline.dexnet.sampling import (
    Candidates,
    PointCloudImage,
    SamplerConfig,
    candidates_at,
    sample_candidates,
)


@dataclass
class CEMConfig:
    """gqcnn ``CrossEntropyRobustGraspingPolicy`` parameters (Dex-Net 4.0 suction config):
    ``conf/dexnet/``, built by ``pipeline.dexnet.planner.cem_config``.

    Attributes:
        num_seed_samples: candidates drawn by the sampler to start (Dex-Net 3.0 used 250).
        num_gmm_samples: candidates drawn from the Gaussian mixture at each iteration.
        num_iters: number of refit iterations.
        gmm_refit_p: share of the scored candidates kept as elites, ``ceil(p * N)``.
        gmm_component_frac: mixture components per elite, ``max(ceil(frac * n_elite), 1)``.
        gmm_reg_covar: ``reg_covar`` of the mixture (added to the covariance diagonals, in
            standardised units).
        max_resamples: at most this many rounds of ``num_gmm_samples`` draws per iteration to
            collect ``num_gmm_samples`` acceptable candidates.
    """

    num_seed_samples: int
    num_gmm_samples: int
    num_iters: int
    gmm_refit_p: float
    gmm_component_frac: float
    gmm_reg_covar: float
    max_resamples: int


@dataclass
class CEMIteration:
    """One scored candidate set.

    Attributes:
        candidates: the N candidates scored.
        scores: (N,) float64 scores (NaN replaced by -inf).
        elite_idx: indices into ``candidates``: the ``ceil(gmm_refit_p * N)`` elites (best first)
            for a refit iteration; for the final set, the single argmax. (If the loop stops early,
            the last entry is a refit iteration with its elites; the result is its argmax.)
    """

    candidates: Candidates
    scores: np.ndarray
    elite_idx: np.ndarray


@dataclass
class CEMResult:
    """Outcome of :func:`cross_entropy_method`.

    Attributes:
        best: the chosen candidate (length 1), or empty when no candidate could be sampled.
        best_score: its score; ``-inf`` when ``best`` is empty.
        iterations: every scored set in order, the final one included (for logging).
        num_scored: total number of candidates passed to the score function.
    """

    best: Candidates
    best_score: float
    iterations: list[CEMIteration] = field(default_factory=list)
    num_scored: int = 0


# Threads of the BLAS and OpenMP libraries while a mixture is fitted and sampled (None: the
# libraries' own setting). The mixtures are tiny (2-D, the elites: 50 points with conf/dexnet/):
# their many small Cholesky factorisations and triangular solves (OpenBLAS) and the k-means that
# starts them (scikit-learn's OpenMP loop, one chunk of up to 256 points) run on one thread
# whatever the setting, but with more threads configured every call still wakes and synchronises
# a thread pool, which on a busy machine (parallel trial workers) costs milliseconds per call:
# most of a plan's time.
# One thread changes no result (tests/test_dexnet_speed.py checks whole plans against None).
GMM_THREADS: int | None = 1


@functools.cache
def _controller() -> ThreadpoolController:
    """The process's thread-pool controller, built on first use (it inspects the libraries)."""
    return ThreadpoolController()


def _thread_limit():
    """Context manager: BLAS and OpenMP limited to ``GMM_THREADS`` threads (no-op for None);
    the previous settings come back on exit."""
    if GMM_THREADS is None:
        return contextlib.nullcontext()
    return _controller().limit(limits=GMM_THREADS)


def _score(score_fn: Callable[[Candidates], np.ndarray], cands: Candidates) -> np.ndarray:
    s = np.asarray(score_fn(cands), dtype=np.float64).reshape(-1)
    if s.shape != (len(cands),):
        raise ValueError(f"score_fn returned {s.shape[0]} scores for {len(cands)} candidates")
    return np.where(np.isnan(s), -np.inf, s)


def _refit_and_sample(
    cloud: PointCloudImage,
    elite_uv: np.ndarray,
    n_elite: int,
    cfg: CEMConfig,
    sampler_cfg: SamplerConfig,
    rng: np.random.Generator,
) -> list[Candidates]:
    """Step 2 of :func:`cross_entropy_method` after the elites: fit the mixture to the elites'
    standardised pixels (N, 2) and draw acceptable candidates until ``num_gmm_samples`` are
    collected or ``max_resamples`` rounds pass; the collected parts (none: nothing accepted)."""
    elite_uv = elite_uv.astype(np.float64)
    mean = elite_uv.mean(axis=0)
    std = elite_uv.std(axis=0)
    std[std < 1e-6] = 1e-6
    x = (elite_uv - mean) / std
    if len(x) < 2:  # GaussianMixture needs >= 2 samples; a repeat changes nothing
        x = np.repeat(x, 2, axis=0)
    n_comp = min(max(math.ceil(cfg.gmm_component_frac * n_elite), 1), n_elite)
    state = np.random.RandomState(int(rng.integers(0, 2**31 - 1)))
    gmm = GaussianMixture(
        n_components=n_comp,
        reg_covar=cfg.gmm_reg_covar,
        weights_init=np.full(n_comp, 1.0 / n_comp),
        random_state=state,
    )
    parts: list[Candidates] = []
    collected = 0
    with warnings.catch_warnings(), _thread_limit():
        warnings.simplefilter("ignore", ConvergenceWarning)
        gmm.fit(x)
        for _r in range(max(cfg.max_resamples, 1)):
            draws, _ = gmm.sample(n_samples=cfg.num_gmm_samples)
            draws = draws[state.permutation(len(draws))]
            uv = np.rint(draws * std + mean)
            new, _ok = candidates_at(cloud, uv, sampler_cfg)
            need = cfg.num_gmm_samples - collected
            if len(new):
                new = new.take(np.arange(min(need, len(new))))
                parts.append(new)
                collected += len(new)
            if collected >= cfg.num_gmm_samples:
                break
    return parts


def cross_entropy_method(
    cloud: PointCloudImage,
    score_fn: Callable[[Candidates], np.ndarray],
    cfg: CEMConfig,
    sampler_cfg: SamplerConfig,
    rng: np.random.Generator | None = None,
) -> CEMResult:
    """Pick the best suction candidate with gqcnn's cross-entropy method.

    1. Draw ``num_seed_samples`` candidates with :func:`sample_candidates`.
    2. ``num_iters`` times: score the set; elites = the top ``ceil(gmm_refit_p * N)`` (stable sort
       on -score, so ties go to the earlier candidate); standardise the elites' (u, v) (mean,
       std; a zero std is replaced by 1e-6 as in gqcnn); fit a ``GaussianMixture`` with
       ``min(max(ceil(gmm_component_frac * n_elite), 1), n_elite)`` components, uniform initial
       weights (as gqcnn) and ``reg_covar = gmm_reg_covar``; draw ``num_gmm_samples`` positions,
       un-standardise, round to the nearest pixel and keep those :func:`candidates_at` accepts
       (inside the image and border, valid/masked, approach angle within the limit); repeat for
       up to ``max_resamples`` rounds until ``num_gmm_samples`` are collected (extra ones are
       dropped). The collected set replaces the current one.
    3. Score the final set and return its argmax (first one on ties).

    Sizes with conf/dexnet/dexnet4.yaml's values: 200 scored -> 50 elites -> 50 -> 13 -> 50 -> 13
    -> final 50.

    Randomness: everything comes from ``rng``. Each mixture gets
    ``random_state = np.random.RandomState(s)`` with an int ``s`` drawn from ``rng``: a
    ``RandomState`` *instance* rather than the int itself, because ``GaussianMixture.sample``
    re-seeds from an int on every call, which would make every resampling round repeat the same
    draws. Each round's draws are shuffled with the same state (``sample`` returns them grouped
    by component, and truncation would otherwise favour the first components). The result is
    deterministic for a given ``rng`` state.

    Edge cases: no seed candidates -> ``best`` empty, ``best_score = -inf`` (no grasp). If a
    refit iteration collects no acceptable candidate at all (rare: the elites themselves are
    acceptable pixels), the loop stops and the argmax of the last scored set is returned.
    ``ConvergenceWarning`` from scikit-learn (e.g. fewer distinct elites than components) is
    silenced inside this function only.

    Args:
        cloud: the depth image's :class:`PointCloudImage` (its ``valid`` carries the object mask).
        score_fn: maps N :class:`Candidates` to (N,) scores, higher is better (NaN counts as -inf).
        cfg: CEM parameters.
        sampler_cfg: acceptance parameters for seeds and GMM samples.
        rng: random generator; defaults to ``np.random.default_rng()`` (non-deterministic).

    Returns:
        The :class:`CEMResult`.
    """
    rng = rng if rng is not None else np.random.default_rng()

    cands = sample_candidates(cloud, cfg.num_seed_samples, rng, sampler_cfg)
    if len(cands) == 0:
        return CEMResult(best=Candidates.empty(), best_score=-math.inf, iterations=[], num_scored=0)

    iterations: list[CEMIteration] = []
    num_scored = 0
    final: CEMIteration | None = None
    for _ in range(cfg.num_iters):
        scores = _score(score_fn, cands)
        num_scored += len(cands)
        n = len(cands)
        n_elite = min(max(math.ceil(cfg.gmm_refit_p * n), 1), n)
        elite_idx = np.argsort(-scores, kind="stable")[:n_elite]
        it = CEMIteration(candidates=cands, scores=scores, elite_idx=elite_idx)
        iterations.append(it)

        parts = _refit_and_sample(cloud, cands.uv[elite_idx], n_elite, cfg, sampler_cfg, rng)
        if not parts:
            final = it
            break
        cands = Candidates.concat(parts)

    if final is None:
        scores = _score(score_fn, cands)
        num_scored += len(cands)
        best_i = int(np.argmax(scores))
        final = CEMIteration(
            candidates=cands, scores=scores, elite_idx=np.array([best_i], np.int64)
        )
        iterations.append(final)
    else:
        best_i = int(np.argmax(final.scores))
    return CEMResult(
        best=final.candidates.take([best_i]),
        best_score=float(final.scores[best_i]),
        iterations=iterations,
        num_scored=num_scored,
    )
