"""``make bench``: run one group of figures, or all of them, and print them (never asserts)."""

from __future__ import annotations

import argparse
import json
import os
import tempfile

from pipeline.runtime.cli import compose
from pipeline.tools.bench.common import BENCH_SEED
from pipeline.tools.bench.configs import compose_figures
from pipeline.tools.bench.executors import executor_figures
from pipeline.tools.bench.planning import (
    closed_loop_figures,
    compiled_loop_figures,
    dexnet_figures,
    planning_times,
)
from pipeline.tools.bench.simulation import (
    bare_loop,
    render_figures,
    render_group,
    rest_figures,
    sensor_figures,
    stage_rates,
)
from pipeline.tools.bench.training import training_images_per_s, training_memory


def main(argv: list[str] | None = None) -> int:
    from omegaconf import OmegaConf

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", type=int, default=60, help="scenes per throughput run")
    parser.add_argument(
        "--only",
        choices=(
            "all",
            "stages",
            "render",
            "planners",
            "closed-loop",
            "executors",
            "training",
            "sensor",
            "ood",
            "gpu",
            "config",
        ),
        default="all",
        help="run one group of figures",
    )
    parser.add_argument(
        "--experiment",
        default="paper",
        help="--only training: whose latest label artifact to load (paper)",
    )
    parser.add_argument(
        "--root",
        default=None,
        help="--only training: paths.root holding that artifact (the repository)",
    )
    args = parser.parse_args(argv)
    cfg = OmegaConf.to_object(compose("generate", ["experiment=smoke"]))
    os.environ.setdefault("LP_NUM_THREADS", "1")

    results = {}
    if args.only == "training":
        _print_training_memory(args.experiment, args.root)
        return 0
    if args.only in ("ood", "gpu"):  # the baseline's out-of-domain heaps; the DCNN on CUDA
        from pipeline.tools import bench_gpu, bench_ood

        return (
            bench_ood.main(["--scenes", str(min(args.scenes, 8))])
            if args.only == "ood"
            else bench_gpu.main([])
        )
    if args.only in ("render", "executors"):
        results.update(
            render_group(cfg, args.scenes)
            if args.only == "render"
            else executor_figures(args.scenes)
        )
        print(json.dumps({k: round(v, 3) for k, v in results.items()}))
        return 0
    if args.only == "config":
        print(json.dumps({k: round(v, 3) for k, v in compose_figures().items()}))
        return 0
    if args.only == "sensor":
        results.update(sensor_figures())
        print(json.dumps({k: round(v, 4) for k, v in results.items()}))
        return 0
    if args.only in ("planners", "closed-loop"):
        if args.only == "planners":
            results.update(planning_times(cfg))
            results.update(dexnet_figures(cfg))
        else:
            results.update(closed_loop_figures())
            results.update(compiled_loop_figures())
        print(json.dumps({k: round(v, 3) for k, v in results.items()}))
        return 0
    results.update(_stage_and_training_figures(cfg, args.scenes))
    if args.only == "all":
        results.update(compose_figures())
        results.update(dexnet_figures(cfg))
        results.update(closed_loop_figures())
    print(json.dumps({k: round(v, 3) for k, v in results.items()}))
    return 0


def _print_training_memory(experiment: str, root: str | None) -> None:
    """``--only training``: memory of loading and training on ``experiment``'s latest labels."""
    mem = training_memory(experiment, root)
    print(
        f"training memory, `{experiment}` data ({mem['images']} images, "
        f"network width {mem['width']}):"
    )
    print(f"  process at start (imports):          {mem['rss_start_mb']:.0f} MB")
    print(
        f"  after loading the splits:            {mem['rss_after_load_mb']:.0f} MB "
        f"({mem['load_s']:.1f} s; the depth in memory would take "
        f"{mem['in_memory_depth_mb']:.0f} MB)"
    )
    print(
        f"  after one epoch of batches read:     {mem['rss_after_epoch_of_data_mb']:.0f} MB "
        f"({mem['decode_images_per_s']:.0f} images/s decoded, 1 loader worker)"
    )
    print(
        f"  peak, with training steps (batch 16): {mem['peak_rss_mb']:.0f} MB "
        f"(loader worker peak {mem['peak_rss_loader_worker_mb']:.0f} MB; "
        f"{mem['train_images_per_s']:.2f} images/s)"
    )
    print(json.dumps({k: round(v, 3) if isinstance(v, float) else v for k, v in mem.items()}))


def _stage_and_training_figures(cfg, num_scenes: int) -> dict[str, float]:
    """The default group: rendering, the rest check, generation and labelling throughput against
    a bare pybullet loop, planning time and training images/s; printed as measured."""
    results = {}
    results.update(render_figures(cfg))
    results.update(rest_figures(cfg))
    results["bare_loop_scenes_per_s"] = bare_loop(num_scenes, cfg, BENCH_SEED)
    print(
        f"bare pybullet loop, 1 process:          {results['bare_loop_scenes_per_s']:.2f} scenes/s"
    )
    with tempfile.TemporaryDirectory() as root:
        results.update(stage_rates(num_scenes, root))
    for workers in (1, 2):
        print(
            f"generation stage, {workers} worker(s):        "
            f"{results[f'generate_{workers}w_scenes_per_s']:.2f} scenes/s"
        )
    one, two = results["generate_1w_scenes_per_s"], results["generate_2w_scenes_per_s"]
    results["stage_vs_bare_per_process"] = one / results["bare_loop_scenes_per_s"]
    results["speedup_2w"] = two / one
    print(
        f"stage / bare loop, per process:         {results['stage_vs_bare_per_process']:.2f} "
        "(target >= 0.90)"
    )
    print(f"speed-up with 2 workers:                {results['speedup_2w']:.2f}x (target >= 1.6x)")
    for workers in (1, 2):
        print(
            f"labelling stage, {workers} worker(s):         "
            f"{results[f'label_{workers}w_scenes_per_s']:.2f} scenes/s"
        )
    print(
        f"labelling per scene, 1 process:         "
        f"{results['label_surfaces_ms_per_scene']:.1f} ms surfaces + "
        f"{results['label_robot_ms_per_scene']:.1f} ms robot checks"
    )
    results.update(planning_times(cfg))
    width = float(compose("train", ["experiment=default"]).model.width)
    # the default network in both layouts, and the one twice as wide, in the same run
    for key, w, last in (
        ("default", width, False),
        ("default_channels_last", width, True),
        ("wide_channels_last", 2 * width, True),
    ):
        results[f"train_{key}_images_per_s"] = training_images_per_s(cfg, w, channels_last=last)
    contiguous, channels_last, wide = (
        results[f"train_{k}_images_per_s"]
        for k in ("default", "default_channels_last", "wide_channels_last")
    )
    print(
        f"training, default network (width {width}), batch 16: {contiguous:.1f} images/s "
        f"contiguous, {channels_last:.1f} images/s channels_last "
        f"({channels_last / contiguous:.2f}x, same run); width {2 * width}, channels_last: "
        f"{wide:.1f} images/s ({wide / channels_last:.2f}x the default's)"
    )
    results["label_vs_generate_1w"] = results["label_1w_scenes_per_s"] / one
    print(
        f"labelling / generation, per process:    {results['label_vs_generate_1w']:.2f} "
        "(target >= 1: labelling is not the bottleneck)"
    )
    return results
