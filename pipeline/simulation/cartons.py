"""A distribution of warehouse cartons for training heaps (``boxes.cartons``; docs/generation.md,
"Carton distribution").

Each carton is drawn, independently, as:

1. the long edge ``L ~ U(long_edge)``; the middle edge ``M = L · U(middle_ratio)``; the short
   edge ``S = M · U(short_ratio)``; a carton with an edge below ``min_edge`` is drawn again;
2. a carton whose sorted edges all lie within ``held_out_margin`` (relative) of those of one of
   the ``held_out`` sizes is drawn again, so that those sizes stay outside the training
   distribution (the unseen-size sets are measured on them);
3. its density ``ρ ~ U(density)``, capped so that the mass ``ρ·L·M·S`` stays within
   ``max_mass`` (the hand's payload); a carton too heavy at the lowest density is drawn again
   from step 1.

The edges are returned in a random order along the box's own axes (the heap drops every box
in a random orientation anyway). Metres, kilograms, kg/m³.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

# Rejection sampling gives up after this many draws (a distribution whose every carton is held
# out or too heavy is a configuration error).
MAX_DRAWS = 1000


@dataclass(frozen=True)
class Carton:
    """One drawn carton: ``size`` (3,) edge lengths along the box's own axes (m), ``mass`` (kg)."""

    size: np.ndarray
    mass: float

    @property
    def density(self) -> float:
        return self.mass / float(np.prod(self.size))


def _sorted_desc(size) -> np.ndarray:
    return np.sort(np.asarray(size, np.float64))[::-1]


def is_held_out(size, held_out: Sequence[Sequence[float]], margin: float) -> bool:
    """Whether every sorted edge of ``size`` lies within ``margin`` (relative to the held-out
    edge) of the sorted edges of one of the ``held_out`` sizes (metres)."""
    s = _sorted_desc(size)
    for h in held_out:
        h = _sorted_desc(h)
        if np.all(np.abs(s - h) <= margin * h):
            return True
    return False


def check_cartons(cfg) -> None:
    """Raise ``ValueError`` naming the key when ``boxes.cartons`` cannot be sampled."""
    for key in ("long_edge", "middle_ratio", "short_ratio", "density"):
        lo, hi = (float(x) for x in getattr(cfg, key))
        if not 0 < lo <= hi:
            raise ValueError(f"boxes.cartons.{key} = [{lo}, {hi}] must be a range 0 < low <= high")
    for key in ("middle_ratio", "short_ratio"):
        if float(getattr(cfg, key)[1]) > 1:
            raise ValueError(
                f"boxes.cartons.{key} must not exceed 1 (edges are drawn long to short)"
            )
    if float(cfg.max_mass) <= 0:
        raise ValueError("boxes.cartons.max_mass must be > 0 kg (the hand's payload)")
    if float(cfg.held_out_margin) < 0:
        raise ValueError("boxes.cartons.held_out_margin must be >= 0")


def heaviest_mass(cfg, size) -> float:
    """kg: the heaviest carton of edges ``size`` (3,) m that the distribution ``cfg``
    (``boxes.cartons``) draws: the highest density, capped at ``max_mass`` (module docstring,
    step 3)."""
    return min(float(cfg.density[1]) * float(np.prod(size)), float(cfg.max_mass))


def draw_carton(cfg, rng: np.random.Generator) -> Carton:
    """One carton of the distribution ``cfg`` (``boxes.cartons``; module docstring).

    Random draws, per attempt: L, the two ratios, the axis order, then the density."""
    lo_d, hi_d = (float(x) for x in cfg.density)
    min_edge, max_mass = float(cfg.min_edge), float(cfg.max_mass)
    for _ in range(MAX_DRAWS):
        L = rng.uniform(*cfg.long_edge)
        M = L * rng.uniform(*cfg.middle_ratio)
        S = M * rng.uniform(*cfg.short_ratio)
        size = np.array([L, M, S])[rng.permutation(3)]
        if S < min_edge or is_held_out(size, cfg.held_out, float(cfg.held_out_margin)):
            continue
        volume = L * M * S
        hi = min(hi_d, max_mass / volume)
        if hi < lo_d:
            continue
        return Carton(size=size, mass=float(rng.uniform(lo_d, hi) * volume))
    raise ValueError(
        f"boxes.cartons: no carton drawn in {MAX_DRAWS} tries: every draw was "
        f"held out, below min_edge or heavier than max_mass; widen the ranges"
    )
