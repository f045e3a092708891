"""The executors' figures: overhead per trivial task, Ray's start-up, stage throughput under
each."""

from __future__ import annotations

import tempfile
import time

from pipeline.tools.bench.simulation import stage_rates


def _noop_init() -> None:
    """Worker set-up of the executor overhead benchmark: nothing."""


def _noop_task(x: int) -> int:
    """The trivial task of the executor overhead benchmark."""
    return x


def executor_overhead(executor_cfg, workers: int, num_tasks: int = 200) -> tuple[float, float]:
    """(seconds to the first result: worker start-up, ms per task after it) of ``map_shards``
    running ``num_tasks`` trivial tasks on ``workers`` workers of ``executor_cfg``."""
    from pipeline.runtime.executor import map_shards

    t0 = time.perf_counter()
    first = None
    for _ in map_shards(
        _noop_task,
        list(range(num_tasks)),
        init=_noop_init,
        initargs=(),
        workers=workers,
        desc="overhead",
        progress=False,
        size=lambda t: 1,
        executor=executor_cfg,
    ):
        first = first or time.perf_counter()
    end = time.perf_counter()
    return first - t0, 1000 * (end - first) / (num_tasks - 1)


def executor_figures(num_scenes: int, num_tasks: int = 200) -> dict[str, float]:
    """The executors: per trivial task overhead and worker start-up, local and Ray, 1 and 2
    workers; Ray's start-up (a private 2-CPU instance); generation and labelling throughput with
    1 and 2 workers under both (``stage_rates``)."""
    from pipeline.runtime.cli import compose
    from pipeline.runtime.executor import import_ray, start_ray

    out: dict[str, float] = {}
    local, ray_cfg = (
        compose("generate", [f"executor={name}"]).executor for name in ("local", "ray")
    )
    ray_cfg.address = None  # a private instance, whatever RAY_ADDRESS says
    for workers in (1, 2):
        start, per_task = executor_overhead(local, workers, num_tasks)
        out[f"local_{workers}w_ms_per_task"], out[f"local_{workers}w_start_s"] = per_task, start
    with tempfile.TemporaryDirectory() as root:
        out.update(stage_rates(num_scenes, root, ("local",)))
        ray = import_ray()
        t0 = time.perf_counter()
        started = start_ray(ray_cfg, 2)
        out["ray_startup_s"] = time.perf_counter() - t0
        try:
            for workers in (1, 2):
                start, per_task = executor_overhead(ray_cfg, workers, num_tasks)
                out[f"ray_{workers}w_ms_per_task"], out[f"ray_{workers}w_start_s"] = per_task, start
            out.update(stage_rates(num_scenes, root, ("ray",)))
        finally:
            if started:
                ray.shutdown()
    print(
        f"executor overhead, {num_tasks} trivial tasks (ms per task after the first; "
        "seconds to the first result):"
    )
    for ex in ("local", "ray"):
        for workers in (1, 2):
            print(
                f"  {ex + ',':<6} {workers} worker(s):                "
                f"{out[f'{ex}_{workers}w_ms_per_task']:.3f} ms/task, "
                f"{out[f'{ex}_{workers}w_start_s']:.2f} s start"
            )
    print(
        f"Ray start-up (private 2-CPU instance):  {out['ray_startup_s']:.2f} s "
        "(once per stage run; not in the rates below)"
    )
    for stage, name in (("generate", "generation"), ("label", "labelling")):
        for ex in ("local", "ray"):
            for workers in (1, 2):
                key = f"{workers}w" if ex == "local" else f"{ex}_{workers}w"
                label = f"{name} stage, {ex}, {workers} worker(s):"
                print(f"{label:<40}{out[f'{stage}_{key}_scenes_per_s']:.2f} scenes/s")
    return out
