"""Planning and closed-loop figures: the DCNN and Dex-Net-style planners per image, the servo
loop."""

from __future__ import annotations

import contextlib
import time

import numpy as np

from pipeline.tools.bench.common import BENCH_SEED, bench_scenes, intrinsics_of


def planning_times(cfg, num_images: int = 8, repeats: int = 3) -> dict[str, float]:
    """Median planning time per image (network + decoding + ranking with the closed loop's
    second tier, CPU, 2 threads; the ``default`` network on 1 thread too). For the ``default``
    network: the trained planner of ``models/train/latest`` when it exists (so the number of
    ranked candidates is real), otherwise an untrained one of the same width.
    For the ``paper`` network (width 1.0): network + decoding + ranking, untrained weights.

    On 1 thread, ``Planner.plan`` is timed beside the reference path it replaced
    (``planning_reference``), interleaved image by image in the same run, with their ratio and
    whether they gave the same candidates (1.0: every field of every candidate, in the same
    order); and so again for the ``default`` network with every cell a candidate (the
    untrained network with its class logits' bias at 0: every probability near 0.5, above th),
    the most decoding and ranking a plan can take.
    """
    import torch

    from pipeline.artifacts.fingerprint import REPO_ROOT
    from pipeline.planner.planner import Planner, fallback_threshold
    from pipeline.runtime.cli import compose

    torch.set_num_threads(2)
    scenes = bench_scenes(cfg, num_images)
    intr = intrinsics_of(cfg)
    out: dict[str, float] = {}
    trained = REPO_ROOT / "models" / "train" / "latest" / "model.pt"
    for name in ("default", "paper"):
        full = compose("train", [f"experiment={name}"])
        if name == "default" and trained.is_file():
            planner, label = Planner.load(trained.parent), "trained"
        else:
            planner, label = untrained_planner(full), "untrained"
        floor = fallback_threshold(full, planner.ranking.threshold)
        for threads in (2, 1) if name == "default" else (2,):
            torch.set_num_threads(threads)
            if threads == 1:  # the default network on one thread: the paper's comparison point
                out.update(
                    compare_plans(planner, scenes, intr, floor, repeats, "plan_default_1thread")
                )
                _print_comparison(out, "plan_default_1thread", full.model.width, label)
                continue
            planner.plan(scenes[0].depth_m, intr, fallback_threshold=floor)  # warm-up
            times, counts = [], []
            for _ in range(1 if name == "paper" else repeats):
                for sc in scenes[: 3 if name == "paper" else num_images]:
                    t0 = time.perf_counter()
                    counts.append(len(planner.plan(sc.depth_m, intr, fallback_threshold=floor)))
                    times.append(time.perf_counter() - t0)
            key = f"plan_{name}"
            out[f"{key}_ms"] = 1000 * float(np.median(times))
            out[f"{key}_candidates"] = float(np.mean(counts))
            print(
                f"planning, {name} network (width {full.model.width}, {label}), {threads} "
                f"threads: {out[f'{key}_ms']:.1f} ms/image, "
                f"{np.mean(counts):.1f} candidates ranked"
            )
        if name == "default":  # every cell a candidate, on one thread
            torch.set_num_threads(1)
            busy = untrained_planner(full)
            with torch.no_grad():
                busy.net.out.bias[2:] = 0.0
            key = "plan_every_cell_1thread"
            busy_floor = fallback_threshold(full, busy.ranking.threshold)
            out.update(compare_plans(busy, scenes, intr, busy_floor, repeats, key))
            _print_comparison(out, key, full.model.width, "untrained, every cell a candidate")
        torch.set_num_threads(2)
    return out


def untrained_planner(full):
    """A planner with an untrained network of ``full``'s width (``torch.manual_seed(0)``), the
    depth normalisation of training and the ranking config at the smallest th of
    ``train.threshold_grid``."""
    import torch

    from pipeline.planner.network import GraspNet, network_config
    from pipeline.planner.normalisation import Normalisation
    from pipeline.planner.planner import Planner, ranking_config

    torch.manual_seed(0)
    net = GraspNet(network_config(full))
    rk = ranking_config(full, min(full.train.threshold_grid))
    return Planner(net, Normalisation(rk.d_ground, 0.1, 0.5), rk)


def compare_plans(planner, scenes, intr, floor, repeats: int, key: str) -> dict[str, float]:
    """``planner.plan`` and the reference path on the same planner (``planning_reference``),
    interleaved image by image on the current torch threads: ``{key}_ms`` (``Planner.plan``'s
    median ms per image), ``{key}_reference_ms``, ``{key}_ratio`` (the first / the second),
    ``{key}_candidates`` (mean per image) and ``{key}_same_candidates`` (1.0 when every plan
    gave the same candidates, every field, in the same order; else 0.0)."""
    import dataclasses

    from pipeline.tools.bench.planning_reference import ReferencePlanner

    reference = ReferencePlanner(planner)
    paths = {"": planner.plan, "_reference": reference.plan}
    for plan in paths.values():  # warm-up
        plan(scenes[0].depth_m, intr, fallback_threshold=floor)
    times: dict[str, list[float]] = {k: [] for k in paths}
    counts, same = [], True
    for _ in range(repeats):
        for sc in scenes:
            got = {}
            for k, plan in paths.items():
                t0 = time.perf_counter()
                got[k] = plan(sc.depth_m, intr, fallback_threshold=floor)
                times[k].append(time.perf_counter() - t0)
            counts.append(len(got[""]))
            a, b = ([dataclasses.astuple(c) for c in got[k]] for k in paths)
            same &= len(a) == len(b) and all(
                all(_same(x, y) for x, y in zip(ca, cb)) for ca, cb in zip(a, b)
            )
    out = {f"{key}{k}_ms": 1000 * float(np.median(t)) for k, t in times.items()}
    out[f"{key}_ratio"] = out[f"{key}_ms"] / out[f"{key}_reference_ms"]
    out[f"{key}_candidates"] = float(np.mean(counts))
    out[f"{key}_same_candidates"] = float(same)
    return out


def _same(x, y) -> bool:
    """The same value, bit for bit for arrays (dtype too), by ``==`` and type otherwise."""
    if isinstance(x, np.ndarray):
        return isinstance(y, np.ndarray) and x.dtype == y.dtype and x.tobytes() == y.tobytes()
    return type(x) is type(y) and x == y


def _print_comparison(out: dict[str, float], key: str, width: float, label: str) -> None:
    target = " (target <= 34 ms: the paper's, on a GTX 1080)" if "default" in key else ""
    print(
        f"planning, default network (width {width}, {label}), 1 thread: "
        f"{out[f'{key}_ms']:.1f} ms/image{target}, reference path "
        f"{out[f'{key}_reference_ms']:.1f} ms/image (same run), ratio "
        f"{out[f'{key}_ratio']:.2f}; {out[f'{key}_candidates']:.1f} candidates ranked, "
        f"same candidates as the reference: {'yes' if out[f'{key}_same_candidates'] else 'NO'}"
    )


def dexnet_figures(cfg, num_images: int = 6) -> dict[str, float]:
    """Dex-Net-style planner: median planning time per image of each variant (the GQ-CNN of
    ``data/baseline/latest`` when it exists, else untrained weights of the same size), the same
    with the CEM's mixtures on the BLAS and OpenMP libraries' own thread setting instead of
    ``pipeline.dexnet.cem.GMM_THREADS`` (``_gmm_threads_default_ms``) and the same with the
    GQ-CNN pooling by ``max_pool2d`` instead of ``MaxPool2x2``'s inference path
    (``_max_pool2d_ms``), interleaved with the first, same draws; and
    ``gqcnn_training_figures``."""
    import torch

    from pipeline.artifacts.fingerprint import REPO_ROOT
    from pipeline.dexnet import cem
    from pipeline.dexnet.gqcnn import GQCNN
    from pipeline.dexnet.planner import (
        DexNetPlanner,
        cem_config,
        crop_config,
        gqcnn_config,
        planarity_config,
        sampler_config,
        workspace,
    )
    from pipeline.planner.network import MaxPool2x2
    from pipeline.runtime.cli import compose

    torch.set_num_threads(2)
    full = compose("baseline", ["experiment=default"])
    scenes = bench_scenes(cfg, num_images)
    intr = intrinsics_of(cfg)
    out: dict[str, float] = {}
    trained = REPO_ROOT / "data" / "baseline" / "latest" / "gqcnn.pt"
    for variant in ("gqcnn", "planarity"):
        if variant == "gqcnn" and trained.is_file():
            planner, label = (
                DexNetPlanner.from_config(full, "gqcnn", scenes[0].T_world_cam, trained.parent),
                "trained",
            )
        else:
            torch.manual_seed(0)
            net = GQCNN(gqcnn_config(full)) if variant == "gqcnn" else None
            planner = DexNetPlanner(
                variant,
                workspace(full, scenes[0].T_world_cam),
                sampler_config(full),
                cem_config(full),
                planarity_config(full),
                crop_config(full),
                net,
            )
            label = "untrained" if variant == "gqcnn" else "analytic"
        planner.plan(scenes[0].depth_m, intr)  # warm-up
        # The CEM's mixtures on cem.GMM_THREADS threads (as planned) and, for comparison, on the
        # BLAS and OpenMP libraries' own thread setting: interleaved, same draws.
        # The GQ-CNN's pooling by max_pool2d instead of MaxPool2x2's inference path: the same
        # values (tests/test_dexnet_speed.py), the path before it.
        planned, fast_pool = cem.GMM_THREADS, MaxPool2x2.forward
        times: dict[str, list[float]] = {"planned": [], "default": []}
        if variant == "gqcnn":
            times["max_pool2d"] = []
        try:
            for k, sc in enumerate(scenes):
                for name in list(times)[:: 1 if k % 2 == 0 else -1]:
                    cem.GMM_THREADS = None if name == "default" else planned
                    MaxPool2x2.forward = (
                        torch.nn.MaxPool2d.forward if name == "max_pool2d" else fast_pool
                    )
                    t0 = time.perf_counter()
                    planner.plan(sc.depth_m, intr, rng=np.random.default_rng([BENCH_SEED, 41, k]))
                    times[name].append(time.perf_counter() - t0)
        finally:
            cem.GMM_THREADS, MaxPool2x2.forward = planned, fast_pool
        key = f"plan_dexnet_{variant}"
        out[f"{key}_ms"] = 1000 * float(np.median(times["planned"]))
        out[f"{key}_gmm_threads_default_ms"] = 1000 * float(np.median(times["default"]))
        pooling = ""
        if "max_pool2d" in times:
            out[f"{key}_max_pool2d_ms"] = 1000 * float(np.median(times["max_pool2d"]))
            pooling = f"; GQ-CNN pooling by max_pool2d: {out[f'{key}_max_pool2d_ms']:.1f} ms/image"
        print(
            f"planning, Dex-Net-style {variant} + CEM ({label}): {out[f'{key}_ms']:.1f} ms/image "
            f"(mixtures on the libraries' own threads: "
            f"{out[f'{key}_gmm_threads_default_ms']:.1f} ms/image{pooling})"
        )
    out.update(gqcnn_training_figures(full))
    return out


def gqcnn_training_figures(full) -> dict[str, float]:
    """The GQ-CNN's training throughput (crops/s, batch 64, the ``baseline`` config ``full``'s
    network) in both memory layouts, alternating, and in the layout the baseline uses."""
    import torch

    from pipeline.dexnet.gqcnn import GQCNN
    from pipeline.dexnet.planner import gqcnn_config

    out: dict[str, float] = {}
    size = int(full.dexnet.crop.size)
    x, pose = torch.randn(64, 1, size, size), torch.randn(64, 2)
    y = (torch.rand(64) > 0.5).float()
    layouts = {"contiguous": torch.contiguous_format, "channels_last": torch.channels_last}
    steps, times = {}, {name: [] for name in layouts}
    for name, layout in layouts.items():
        torch.manual_seed(0)
        net = GQCNN(gqcnn_config(full)).train().to(memory_format=layout)
        opt = torch.optim.Adam(net.parameters(), lr=1e-3)
        steps[name] = (net, opt, x.contiguous(memory_format=layout))
    for _ in range(8):  # the layouts alternate; the first step of each is left out
        for name, (net, opt, xl) in steps.items():
            t0 = time.perf_counter()
            opt.zero_grad()
            torch.nn.functional.binary_cross_entropy_with_logits(net(xl, pose), y).backward()
            opt.step()
            times[name].append(time.perf_counter() - t0)
    for name in layouts:
        out[f"gqcnn_train_crops_per_s_{name}"] = 64 / float(np.median(times[name][1:]))
    used = "channels_last" if full.baseline.channels_last else "contiguous"
    out["gqcnn_train_crops_per_s"] = out[f"gqcnn_train_crops_per_s_{used}"]
    print(
        f"GQ-CNN training, batch 64: {out['gqcnn_train_crops_per_s_channels_last']:.0f} crops/s "
        f"channels-last, {out['gqcnn_train_crops_per_s_contiguous']:.0f} contiguous "
        f"(baseline.channels_last: {bool(full.baseline.channels_last)})"
    )
    return out


def closed_loop_figures(
    cfg_name: str = "evaluate",
    renderer: str | None = None,
    descriptor: bool = True,
    boxes: int = 3,
    quiet: bool = False,
) -> dict[str, float]:
    """Closed loop: the descriptor's time per 416 x 416 frame, and one trial of ``boxes`` driven by
    the training-free Dex-Net-style planarity planner (no artifact needed): control-loop rate
    (wall), simulated seconds per wall second, wall time of the trial, and where a control step's
    wall time goes (median ms per call of each part). ``renderer``: ``camera.renderer`` (None:
    the configured one); keys carry its name when given."""
    import torch

    from pipeline.controller.planning import DexNetStylePlanner
    from pipeline.runtime.cli import compose
    from pipeline.servo.descriptor import describe_surface
    from pipeline.world.trial import make_runner

    torch.set_num_threads(1)
    extra = [f"camera.renderer={renderer}"] if renderer else []
    cfg = compose(
        cfg_name,
        [
            "experiment=default",
            f"evaluate.boxes_per_trial={boxes}",
            "evaluate.dexnet_variant=planarity",
            *extra,
        ],
    )
    runner = make_runner(
        cfg,
        "dexnet",
        lambda cell: DexNetStylePlanner(cfg, "planarity", cell.robot.home_camera_pose(), None),
    )
    cell = runner.cell
    out: dict[str, float] = {}
    if descriptor:
        cell.reset(np.random.default_rng([BENCH_SEED, 31, 0]), boxes)
        frame = cell.render()
        ys, xs = np.nonzero(np.isin(frame.body_ids, list(cell.boxes)))
        seed = np.array([xs[len(xs) // 2], ys[len(ys) // 2]], np.float64)
        dcfg = runner.robot_side.descriptor_cfg  # conf/servo/, as the closed loop uses it
        times = []
        for _ in range(20):
            t0 = time.perf_counter()
            describe_surface(frame.depth_m, cell.intrinsics, seed, dcfg)
            times.append(time.perf_counter() - t0)
        out["descriptor_ms_per_frame"] = 1000 * float(np.median(times))
        print(f"surface descriptor, 416x416 frame: {out['descriptor_ms_per_frame']:.1f} ms")
    t0 = time.perf_counter()
    result = runner.run_trial(
        0, np.random.default_rng([BENCH_SEED, 31, 0]), np.random.default_rng([BENCH_SEED, 37, 0])
    )
    wall = time.perf_counter() - t0
    cell.close()
    runner.robot_side.close()
    tm = {**runner.timings, **runner.robot_side.timings}
    sfx = f"_{renderer}" if renderer else ""
    steps = tm["control_step_s"]
    out[f"control_loop_hz{sfx}"] = 1.0 / float(np.median(steps)) if steps else float("nan")
    out[f"sim_s_per_wall_s{sfx}"] = result.sim_s / wall
    out[f"trial_{boxes}_boxes_wall_s{sfx}"] = wall
    if quiet:
        out["sim_s"] = result.sim_s
        return out
    parts = {
        "render": "render_s",
        "descriptor": "descriptor_s",
        "control law + Jacobian + joint update": "control_law_s",
        "physics": "physics_s",
        "collision check": "collision_s",
    }
    ms = {k: 1000 * float(np.median(tm[v])) if tm[v] else 0.0 for k, v in parts.items()}
    for k, v in parts.items():
        out[f"step_{v[:-2]}_ms{sfx}"] = ms[k]
    name = renderer or str(cfg.camera.renderer)
    print(
        f"closed loop ({name}): control loop {out[f'control_loop_hz{sfx}']:.1f} Hz (wall), "
        f"{out[f'sim_s_per_wall_s{sfx}']:.2f} simulated s per wall s; one {boxes}-box trial "
        f"{wall:.1f} s wall ({result.picked}/{result.boxes} picked in {len(result.attempts)} "
        f"attempts, {result.sim_s:.1f} s simulated)"
    )
    print(
        f"  control step {1000 * float(np.median(steps)) if steps else float('nan'):.1f} ms "
        "(median): " + ", ".join(f"{k} {v:.1f} ms" for k, v in ms.items())
    )
    return out


@contextlib.contextmanager
def numpy_loops():
    """The closed loop with the numpy paths in place of the compiled loops: the ray cast and the
    ground (``render_reference``) and the descriptor's Eq. 12 mask, rules and slab counts
    (``descriptor_reference``). Same results, bit for bit
    (``tests/test_raycast_kernels.py``, ``tests/test_region_kernels.py``)."""
    from unittest import mock

    from pipeline.tools.bench import descriptor_reference, render_reference

    with (
        mock.patch("pipeline.camera.render.raycast_boxes", render_reference.raycast_boxes),
        mock.patch("pipeline.camera.render.fill_ground", render_reference.fill_ground),
        mock.patch("pipeline.servo.region.on_plane_mask", descriptor_reference.on_plane_mask),
        mock.patch("pipeline.servo.region.slab_counts", descriptor_reference.slab_counts),
        mock.patch(
            "pipeline.servo.region.plane_rules_unsmoothed",
            descriptor_reference.plane_rules_unsmoothed,
        ),
    ):
        yield


def compiled_loop_figures(boxes: int = 3, repeats: int = 2) -> dict[str, float]:
    """The closed loop's trial of ``closed_loop_figures`` with the compiled loops and with their
    numpy paths (``numpy_loops``), alternating, ``repeats`` times each in one run: the best wall
    time of each, their ratio, and whether every trial took the same simulated time (it must:
    the loops change no bit)."""
    walls: dict[str, list[float]] = {"compiled": [], "numpy": []}
    sims: dict[str, set] = {"compiled": set(), "numpy": set()}
    for _ in range(repeats):
        for name in walls:
            with numpy_loops() if name == "numpy" else contextlib.nullcontext():
                fig = closed_loop_figures(descriptor=False, boxes=boxes, quiet=True)
            walls[name].append(fig[f"trial_{boxes}_boxes_wall_s"])
            sims[name].add(round(fig["sim_s"], 9))
    out = {f"trial_{boxes}_boxes_wall_s_{k}": min(v) for k, v in walls.items()}
    out["closed_loop_compiled_speedup"] = (
        out[f"trial_{boxes}_boxes_wall_s_numpy"] / out[f"trial_{boxes}_boxes_wall_s_compiled"]
    )
    same = len(sims["compiled"] | sims["numpy"]) == 1
    out["closed_loop_compiled_same_trial"] = float(same)
    print(
        f"closed loop, compiled loops vs their numpy paths (one {boxes}-box trial, best of "
        f"{repeats} each, alternating): {out[f'trial_{boxes}_boxes_wall_s_compiled']:.2f} s vs "
        f"{out[f'trial_{boxes}_boxes_wall_s_numpy']:.2f} s wall, "
        f"{out['closed_loop_compiled_speedup']:.2f}x; same simulated time: {same}"
    )
    return out
