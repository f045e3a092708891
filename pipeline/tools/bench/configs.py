"""``make bench ARGS="--only config"``: the time of one config composition, Hydra's whole one
against ``compose``'s copy of the kept group composition (docs/configuration.md)."""

from __future__ import annotations

import time

from pipeline.runtime.cli import compose, compose_uncached


def compose_figures(repeats: int = 5) -> dict[str, float]:
    """ms per composition of the evaluate stage's smoke config with a new ``paths.root`` each
    time (as tests compose): Hydra's whole composition and ``compose``, interleaved, with their
    ratio."""
    compose("evaluate", ["experiment=smoke"])  # keep the group composition, as after first use
    times: dict[str, list[float]] = {"compose_uncached_ms": [], "compose_ms": []}
    for i in range(repeats):
        for name, fn in (("compose_uncached_ms", compose_uncached), ("compose_ms", compose)):
            t0 = time.perf_counter()
            fn("evaluate", ["experiment=smoke", f"paths.root=/tmp/bench-{i}", "seed=3"])
            times[name].append(1e3 * (time.perf_counter() - t0))
    out = {name: sorted(v)[len(v) // 2] for name, v in times.items()}
    out["compose_speedup"] = out["compose_uncached_ms"] / out["compose_ms"]
    print(
        f"config composition: Hydra's whole {out['compose_uncached_ms']:.0f} ms, compose "
        f"{out['compose_ms']:.0f} ms ({out['compose_speedup']:.1f}x; median of {repeats})"
    )
    return out
