"""Measured performance figures (``make bench``); prints, never asserts.

Rendering (``--only render``): ms per frame of the ray-cast renderer and of TinyRenderer on the
same frames in one run, the rest check (heaps of 20 boxes that move in one more second, settle
steps), generation scenes/s and the closed loop with each renderer. Generation throughput with 1
and 2 worker processes and the ratio of the stage's per-process rate to a bare pybullet loop doing
the same work (same cell, same trickle drop and rest test, same renderer) measured in the same run.
Labelling throughput with 1 and 2 workers on the generated scenes, and its split between surface
detection and robot checks. Planning time per image of the DCNN (default and paper widths) and of
the Dex-Net-style planner (GQ-CNN and planarity), GQ-CNN training throughput. The closed loop: the
surface descriptor's time per frame, the control loop's rate, simulated seconds per wall second and
the wall time of a 3-box trial. The executors (``executor=local|ray``, ``--only executors``):
overhead per trivial task, Ray's start-up, and generation + labelling throughput with 1 and 2
workers under each. Training memory (``--only training``): peak resident memory of loading an
experiment's splits, reading one epoch of batches from disk and a few training steps of its
network, against what the depth would take held in memory. The sensor model and depth preprocessing
(``--only sensor``): time per image of the SR300 model, hole filling and the median, and what they
do to the depth of the bench's heaps (pixels without data, error against the ideal depth). The DCNN
on a CUDA GPU (``--only gpu``, ``pipeline/bench_gpu.py``): planning time, training images/s and
agreement with the CPU.

    python -m pipeline.bench [--scenes 60] [--only GROUP] [--experiment paper] [--root <root>]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import tempfile
import time
from pathlib import Path

import numpy as np
import pybullet as p


def bare_loop(num_scenes: int, cfg, seed: int) -> float:
    """Scenes per second of a minimal settle + render loop (no storage, no logging).

    It draws the same heaps as the stage (same seeds, same order of random draws), drops them
    the same way, applies the same rest test (``pipeline.simulation.heap.settle``) and renders
    one frame with the configured renderer (``camera.renderer``), so the ratio of the two rates
    is the stage's overhead.
    """
    from pipeline.camera.geometry import Intrinsics, camera_pose_above_bin
    from pipeline.camera.render import render_depth
    from pipeline.simulation.heap import settle

    client = p.connect(p.DIRECT)
    intr = Intrinsics.from_config(cfg.camera)
    T_cam = camera_pose_above_bin(cfg.camera.height_above_bin_floor)
    sizes = [np.asarray(t.size) for t in cfg.boxes.types]
    b, ph = cfg.bin, cfg.physics
    lx, ly, h, t, ft = (b.inner_length_x, b.inner_width_y, b.wall_height, b.wall_thickness,
                        b.floor_thickness)
    parts = [([lx / 2 + t, ly / 2 + t, ft / 2], [0, 0, -ft / 2]),
             ([t / 2, ly / 2 + t, (h + ft) / 2], [-(lx + t) / 2, 0, (h - ft) / 2]),
             ([t / 2, ly / 2 + t, (h + ft) / 2], [(lx + t) / 2, 0, (h - ft) / 2]),
             ([lx / 2, t / 2, (h + ft) / 2], [0, -(ly + t) / 2, (h - ft) / 2]),
             ([lx / 2, t / 2, (h + ft) / 2], [0, (ly + t) / 2, (h - ft) / 2])]
    hx, hy = lx / 2 - ph.drop_margin, ly / 2 - ph.drop_margin
    anchor = int(bool(ph.friction_anchor))
    t0 = time.perf_counter()
    for i in range(num_scenes):
        rng = np.random.default_rng([seed, 0, i])
        p.resetSimulation(physicsClientId=client)
        p.setGravity(0, 0, ph.gravity, physicsClientId=client)
        p.setPhysicsEngineParameter(fixedTimeStep=ph.time_step,
                                    numSolverIterations=ph.solver_iterations,
                                    physicsClientId=client)
        # Ground: the same invisible 2 m slab as the stage (drawing it costs ~40 ms a frame).
        ground = p.createCollisionShape(p.GEOM_BOX, halfExtents=[1, 1, 0.01],
                                        physicsClientId=client)
        plane = p.createMultiBody(0, ground, basePosition=[0, 0, -ft - 0.01],
                                  physicsClientId=client)
        p.changeVisualShape(plane, -1, rgbaColor=[1, 1, 1, 0], physicsClientId=client)
        static = []
        for half, pos in parts:
            col = p.createCollisionShape(p.GEOM_BOX, halfExtents=half, physicsClientId=client)
            vis = p.createVisualShape(p.GEOM_BOX, halfExtents=half, physicsClientId=client)
            static.append(p.createMultiBody(0, col, vis, basePosition=pos,
                                            physicsClientId=client))
        for body in [plane] + static:
            p.changeDynamics(body, -1, frictionAnchor=anchor, physicsClientId=client)
        bodies = []
        n = int(rng.integers(cfg.boxes.min_count, cfg.boxes.max_count + 1))
        for j in range(n):
            s = sizes[int(rng.integers(len(sizes)))]
            x, y = rng.uniform(-hx, hx), rng.uniform(-hy, hy)
            q = rng.normal(size=4)
            col = p.createCollisionShape(p.GEOM_BOX, halfExtents=(s / 2).tolist(),
                                         physicsClientId=client)
            vis = p.createVisualShape(p.GEOM_BOX, halfExtents=(s / 2).tolist(),
                                      physicsClientId=client)
            bodies.append(p.createMultiBody(cfg.boxes.density * float(np.prod(s)), col, vis,
                                            basePosition=[x, y, ph.drop_height_above_bin_floor],
                                            baseOrientation=(q / np.linalg.norm(q)).tolist(),
                                            physicsClientId=client))
            p.changeDynamics(bodies[-1], -1, frictionAnchor=anchor, physicsClientId=client)
            if j < n - 1:
                for _ in range(ph.drop_interval_steps):
                    p.stepSimulation(physicsClientId=client)
        settle(client, bodies, ph, ph.max_settle_steps)
        render_depth(client, intr, T_cam, cfg.camera.near, cfg.camera.far,
                     ground=(-ft, plane), renderer=cfg.camera.renderer, bodies=static + bodies)
    rate = num_scenes / (time.perf_counter() - t0)
    p.disconnect(client)
    return rate


def render_figures(cfg, num_heaps: int = 6, repeats: int = 5) -> dict[str, float]:
    """Both renderers on the same frames, interleaved in one run: ``num_heaps`` heaps of 20
    boxes, each seen from the generation camera and from two closed-loop-like close-up poses
    (``closeup_poses``). Median ms per 416 × 416 depth + mask frame of each and their ratio."""
    from pipeline.camera.geometry import Intrinsics, camera_pose_above_bin
    from pipeline.camera.render import render_depth
    from pipeline.cell.bin import build_cell
    from pipeline.simulation.heap import drop_heap
    from pipeline.simulation.views import closeup_poses

    client = p.connect(p.DIRECT)
    intr = Intrinsics.from_config(cfg.camera)
    boxes = dataclasses.replace(cfg.boxes, min_count=20, max_count=20)
    times: dict[str, list[float]] = {"tinyrenderer": [], "raycast": []}
    for i in range(num_heaps):
        cell = build_cell(client, cfg.bin, cfg.physics)
        heap = drop_heap(client, np.random.default_rng([BENCH_SEED, 5, i]), boxes, cfg.bin,
                         cfg.physics)
        poses = [camera_pose_above_bin(cfg.camera.height_above_bin_floor)] + closeup_poses(
            heap.boxes, np.random.default_rng([BENCH_SEED, 6, i]), (0.15, 0.3))
        for T in poses:
            for _ in range(repeats):
                for name in times:
                    t0 = time.perf_counter()
                    render_depth(client, intr, T, cfg.camera.near, cfg.camera.far,
                                 ground=(-cfg.bin.floor_thickness, cell[0]), renderer=name)
                    times[name].append(time.perf_counter() - t0)
    p.disconnect(client)
    out = {f"render_{k}_ms_per_frame": 1000 * float(np.median(v)) for k, v in times.items()}
    out["render_raycast_speedup"] = (out["render_tinyrenderer_ms_per_frame"]
                                     / out["render_raycast_ms_per_frame"])
    n = len(times["raycast"]) // repeats
    print(f"render: {out['render_raycast_ms_per_frame']:.1f} ms per frame, "
          f"{out['render_raycast_speedup']:.1f}x TinyRenderer (same heaps, same run; "
          f"TinyRenderer {out['render_tinyrenderer_ms_per_frame']:.1f} ms; {n} frames of "
          f"{num_heaps} 20-box heaps, overhead and close-up poses, 416x416 depth + mask)")
    return out


def rest_figures(cfg, num_heaps: int = 24) -> dict[str, float]:
    """Heaps of 20 boxes dropped as the generation stage drops them: settle steps, and how many
    heaps still have a box corner moving more than 2 mm in one more simulated second (the
    check of ``tests/test_generate.py::test_heaps_of_20_really_at_rest``, same seeds)."""
    from pipeline.cell.bin import build_cell
    from pipeline.simulation.heap import corner_drift, drop_heap

    client = p.connect(p.DIRECT)
    boxes = dataclasses.replace(cfg.boxes, min_count=20, max_count=20)
    steps, drift, capped = [], [], 0
    one_second = int(round(1.0 / cfg.physics.time_step))
    for i in range(num_heaps):
        build_cell(client, cfg.bin, cfg.physics)
        heap = drop_heap(client, rest_check_rng(i), boxes, cfg.bin, cfg.physics)
        steps.append(heap.settle_steps)
        capped += not heap.settled
        drift.append(float(corner_drift(client, [b.body_id for b in heap.boxes],
                                        one_second).max()))
    p.disconnect(client)
    moving = int(sum(d > 0.002 for d in drift))
    out = {"rest_heaps": num_heaps, "rest_heaps_moving_over_2mm": moving,
           "rest_worst_drift_mm": 1000 * max(drift), "rest_settle_steps_median":
           float(np.median(steps)), "rest_settle_steps_max": float(max(steps)),
           "rest_heaps_at_step_cap": capped}
    print(f"heaps at rest: {num_heaps - moving} of {num_heaps} heaps of 20 boxes move no corner "
          f"more than 2 mm in one more second (worst {out['rest_worst_drift_mm']:.2f} mm); "
          f"settle steps median {out['rest_settle_steps_median']:.0f}, max "
          f"{out['rest_settle_steps_max']:.0f}; {capped} at the step cap")
    return out


def rest_check_rng(index: int) -> np.random.Generator:
    """The heaps of the rest check (bench and slow test): seeds (BENCH_SEED, 7, index)."""
    return np.random.default_rng([BENCH_SEED, 7, index])


BENCH_SEED = 12345


def stage_rates(num_scenes: int, root: str, executors: tuple[str, ...] = ("local",),
                workers_list: tuple[int, ...] = (1, 2), extra: tuple[str, ...] = (),
                label: bool = True) -> dict[str, float]:
    """Scenes per second of ``pipeline.generate`` and ``pipeline.label`` with 1 and 2 workers
    (simulation + storage; labelling = surfaces + hand + robot checks), from their manifests.
    Keys ``generate_2w_scenes_per_s`` (local executor), ``generate_ray_2w_scenes_per_s`` (ray:
    run with Ray already started, so its start-up is not counted)."""
    from pipeline.artifacts.store import load_manifest
    from pipeline.cli import compose
    from pipeline.generate import generate
    from pipeline.label import label as label_stage

    def cfg(stage: str, workers: int, sub: str, executor: str = "local"):
        return compose(stage, [f"executor={executor}",
            "experiment=smoke", f"paths.root={root}/{sub}", f"generate.num_scenes={num_scenes}",
            "generate.num_val_scenes=0", "generate.num_test_scenes=0",
            "generate.scenes_per_shard=10", f"generate.workers={workers}",
            f"label.workers={workers}", "logging.max_logged_scenes=0", "logging.progress=false",
            f"seed={BENCH_SEED}", *extra,
        ])

    out = {}
    for executor, workers in [(e, w) for e in executors for w in workers_list]:
        key = f"{workers}w" if executor == "local" else f"{executor}_{workers}w"
        gen = load_manifest(generate(cfg("generate", workers, key, executor)))
        out[f"generate_{key}_scenes_per_s"] = gen["timings"]["scenes_per_s"]
        if not label:
            continue
        lab = load_manifest(label_stage(cfg("label", workers, key, executor)))
        out[f"label_{key}_scenes_per_s"] = lab["timings"]["scenes_per_s"]
        if workers == 1 and executor == "local":
            out["label_surfaces_ms_per_scene"] = 1000 * lab["timings"]["surface_detection_s_per_scene"]
            out["label_robot_ms_per_scene"] = 1000 * lab["timings"]["robot_checks_s_per_scene"]
    return out


def _noop_init() -> None:
    """Worker set-up of the executor overhead benchmark: nothing."""


def _noop_task(x: int) -> int:
    """The trivial task of the executor overhead benchmark."""
    return x


def executor_overhead(executor_cfg, workers: int, num_tasks: int = 200) -> tuple[float, float]:
    """(seconds to the first result: worker start-up, ms per task after it) of ``map_shards``
    running ``num_tasks`` trivial tasks on ``workers`` workers of ``executor_cfg``."""
    from pipeline.executor import map_shards

    t0 = time.perf_counter()
    first = None
    for _ in map_shards(_noop_task, list(range(num_tasks)), init=_noop_init, initargs=(),
                        workers=workers, desc="overhead", progress=False, size=lambda t: 1,
                        executor=executor_cfg):
        first = first or time.perf_counter()
    end = time.perf_counter()
    return first - t0, 1000 * (end - first) / (num_tasks - 1)


def executor_figures(num_scenes: int, num_tasks: int = 200) -> dict[str, float]:
    """The executors: per trivial task overhead and worker start-up, local and Ray, 1 and 2
    workers; Ray's start-up (a private 2-CPU instance); generation and labelling throughput with
    1 and 2 workers under both (``stage_rates``)."""
    from pipeline.cli import compose
    from pipeline.executor import import_ray, start_ray

    out: dict[str, float] = {}
    local, ray_cfg = (compose("generate", [f"executor={name}"]).executor for name in ("local", "ray"))
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
    print(f"executor overhead, {num_tasks} trivial tasks (ms per task after the first; "
          "seconds to the first result):")
    for ex in ("local", "ray"):
        for workers in (1, 2):
            print(f"  {ex + ',':<6} {workers} worker(s):                "
                  f"{out[f'{ex}_{workers}w_ms_per_task']:.3f} ms/task, "
                  f"{out[f'{ex}_{workers}w_start_s']:.2f} s start")
    print(f"Ray start-up (private 2-CPU instance):  {out['ray_startup_s']:.2f} s "
          "(once per stage run; not in the rates below)")
    for stage, name in (("generate", "generation"), ("label", "labelling")):
        for ex in ("local", "ray"):
            for workers in (1, 2):
                key = f"{workers}w" if ex == "local" else f"{ex}_{workers}w"
                label = f"{name} stage, {ex}, {workers} worker(s):"
                print(f"{label:<40}{out[f'{stage}_{key}_scenes_per_s']:.2f} scenes/s")
    return out


def bench_scenes(cfg, num_images: int) -> list:
    """``num_images`` simulated heaps of the bench's fixed seed (test split code 2)."""
    from pipeline.simulation.scene import connect, scene_rng, simulate_scene

    client = connect()
    try:
        return [simulate_scene(client, cfg, scene_rng(BENCH_SEED, 2, i))
                for i in range(num_images)]
    finally:
        p.disconnect(client)


def planning_times(cfg, num_images: int = 8, repeats: int = 3) -> dict[str, float]:
    """Median planning time per image (network + decoding + ranking with the closed loop's
    second tier, CPU, 2 threads; the ``default`` network on 1 thread too). For the ``default``
    network: the trained planner of ``models/train/latest`` when it exists (so the number of
    ranked candidates is real), otherwise an untrained one of the same width.
    For the ``paper`` network (width 1.0): network + decoding + ranking, untrained weights.
    """
    import torch

    from pipeline.artifacts.fingerprint import REPO_ROOT
    from pipeline.cli import compose
    from pipeline.planner.normalisation import Normalisation
    from pipeline.planner.network import GraspNet, network_config
    from pipeline.planner.planner import Planner, fallback_threshold, ranking_config
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
            net = GraspNet(network_config(full))
            rk = ranking_config(full, min(full.train.threshold_grid))
            planner = Planner(net, Normalisation(rk.d_ground, 0.1, 0.5), rk)
            label = "untrained"
        # the default network also on one thread: the paper's planning-time comparison point
        floor = fallback_threshold(full, planner.ranking.threshold)
        for threads in ((2, 1) if name == "default" else (2,)):
            torch.set_num_threads(threads)
            planner.plan(scenes[0].depth_m, intr, fallback_threshold=floor)  # warm-up
            times, counts = [], []
            for _ in range(1 if name == "paper" else repeats):
                for sc in scenes[: 3 if name == "paper" else num_images]:
                    t0 = time.perf_counter()
                    counts.append(len(planner.plan(sc.depth_m, intr, fallback_threshold=floor)))
                    times.append(time.perf_counter() - t0)
            key = f"plan_{name}" + ("" if threads == 2 else f"_{threads}thread")
            out[f"{key}_ms"] = 1000 * float(np.median(times))
            out[f"{key}_candidates"] = float(np.mean(counts))
            target = " (target <= 34 ms: the paper's, on a GTX 1080)" \
                if name == "default" and threads == 1 else ""
            print(f"planning, {name} network (width {full.model.width}, {label}), {threads} "
                  f"thread{'s' if threads > 1 else ''}: {out[f'{key}_ms']:.1f} ms/image, "
                  f"{np.mean(counts):.1f} candidates ranked{target}")
        torch.set_num_threads(2)
    return out


def _rss_mb() -> float:
    """This process's resident memory now, MB (Linux ``/proc/self/status``)."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def _training_memory_child(experiment: str, root: str | None, steps: int, loader_workers: int,
                           width: float | None) -> dict:
    """Runs in a fresh process (``training_memory``): the training stage's data path over
    the experiment's latest label artifact, then ``steps`` optimisation steps of its network."""
    import resource

    import torch

    from pipeline.artifacts import load_manifest, resolve_artifact
    from pipeline.cli import compose, data_root
    from pipeline.dataset.labels import LabelSet
    from pipeline.planner.data import GraspDataset, make_loader
    from pipeline.planner.distributed import DistContext
    from pipeline.planner.loss import grasp_loss, loss_config
    from pipeline.planner.data import epoch_batches
    from pipeline.planner.normalisation import normalisation
    from pipeline.planner.network import GraspNet, network_config

    overrides = [f"experiment={experiment}"] + ([f"paths.root={root}"] if root else [])
    overrides += [f"model.width={width}"] if width is not None else []
    cfg = compose("train", overrides)
    label_dir = resolve_artifact(data_root(cfg), "label", "latest")
    gen_dir = resolve_artifact(data_root(cfg), "generate",
                               load_manifest(label_dir)["upstream"]["generate"])
    torch.set_num_threads(int(cfg.train.num_threads))
    out = {"rss_start_mb": _rss_mb()}
    net_cfg, norm = network_config(cfg), normalisation(cfg)
    cache = data_root(cfg) / ".cache" / "depth" / gen_dir.name
    t0 = time.perf_counter()
    sets = {s: GraspDataset(gen_dir, LabelSet(label_dir, s), s, norm, net_cfg.grid, cfg.hand,
                            cache_dir=cache) for s in ("train", "val", "test")}
    out["load_s"] = time.perf_counter() - t0
    out["rss_after_load_mb"] = _rss_mb()
    train = sets["train"]
    h, w = train.depth.shape
    out["images"] = sum(len(d) for d in sets.values())
    out["in_memory_depth_mb"] = out["images"] * h * w * 2 / 2**20
    batch = int(cfg.train.batch_size)
    batches, _ = epoch_batches(len(train), batch, int(cfg.seed), 0, "none", DistContext())
    t0 = time.perf_counter()
    for x, _targets in make_loader(train, batches, loader_workers):
        pass
    out["epoch_decode_s"] = time.perf_counter() - t0
    out["decode_images_per_s"] = len(train) / out["epoch_decode_s"]
    out["rss_after_epoch_of_data_mb"] = _rss_mb()
    torch.manual_seed(0)
    net = GraspNet(net_cfg)
    opt = torch.optim.Adam(net.parameters(), lr=1e-4)
    loss_cfg = loss_config(cfg)
    net.train()
    t0 = time.perf_counter()
    for x, targets in make_loader(train, batches[:steps], loader_workers):
        loss = grasp_loss(net(x), targets, loss_cfg)["total"]
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
    out["train_images_per_s"] = steps * batch / (time.perf_counter() - t0)
    out["width"] = net_cfg.width
    out["peak_rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    out["peak_rss_loader_worker_mb"] = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
    return out


def training_memory(experiment: str = "paper", root: str | None = None, steps: int = 4,
                    loader_workers: int = 1, width: float | None = None) -> dict:
    """Peak memory of training at an experiment's scale (its latest label artifact under
    ``root``), measured in a fresh process: load the splits (label rows in memory, depth
    streamed from the on-disk cache), read one epoch of training batches through the
    DataLoader, then ``steps`` optimisation steps of the experiment's network (batch 16).
    Also the size the depth of all splits would take in memory."""
    import subprocess
    import sys

    code = ("import json, sys; from pipeline.bench import _training_memory_child; "
            "print('RESULT ' + json.dumps(_training_memory_child(*json.loads(sys.argv[1]))))")
    args = json.dumps([experiment, root, steps, loader_workers, width])
    proc = subprocess.run([sys.executable, "-c", code, args], capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"training memory benchmark failed:\n{proc.stderr[-2000:]}")
    line = next(ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT "))
    return json.loads(line[len("RESULT "):])


def training_images_per_s(cfg, width: float, batch: int = 16, steps: int = 4,
                          channels_last: bool = False) -> float:
    """Training throughput (forward + focal loss + backward + Adam step), CPU, 2 threads, on
    random depth-like inputs with 10 random grasp points per image, in the contiguous or the
    channels-last memory layout (``train.channels_last``); ``cfg``'s network at ``width``."""
    import torch

    from pipeline.bench_gpu import random_training_batch
    from pipeline.planner.loss import grasp_loss, loss_config
    from pipeline.planner.network import GraspNet, network_config

    torch.set_num_threads(2)
    torch.manual_seed(0)
    layout = torch.channels_last if channels_last else torch.contiguous_format
    net_cfg = dataclasses.replace(network_config(cfg), width=width)
    net = GraspNet(net_cfg).train().to(memory_format=layout)
    opt = torch.optim.Adam(net.parameters(), lr=1e-4)
    x, targets = random_training_batch(batch, net_cfg.input_size, net_cfg.grid)
    x = x.to(memory_format=layout)
    times = []
    for _ in range(steps + 1):  # the first step warms up
        t0 = time.perf_counter()
        opt.zero_grad()
        grasp_loss(net(x), targets, loss_config(cfg))["total"].backward()
        opt.step()
        times.append(time.perf_counter() - t0)
    return batch / float(np.median(times[1:]))


def dexnet_figures(cfg, num_images: int = 6) -> dict[str, float]:
    """Dex-Net-style planner: median planning time per image of each variant (the GQ-CNN of
    ``data/baseline/latest`` when it exists, else untrained weights of the same size), and the
    GQ-CNN's training throughput (crops/s, batch 64)."""
    import torch

    from pipeline.artifacts.fingerprint import REPO_ROOT
    from pipeline.cli import compose
    from pipeline.dexnet.gqcnn import GQCNN
    from pipeline.dexnet.planner import (
        DexNetPlanner, cem_config, crop_config, gqcnn_config, planarity_config, sampler_config,
        workspace,
    )
    torch.set_num_threads(2)
    full = compose("baseline", ["experiment=default"])
    scenes = bench_scenes(cfg, num_images)
    intr = intrinsics_of(cfg)
    out: dict[str, float] = {}
    trained = REPO_ROOT / "data" / "baseline" / "latest" / "gqcnn.pt"
    for variant in ("gqcnn", "planarity"):
        if variant == "gqcnn" and trained.is_file():
            planner, label = DexNetPlanner.from_config(full, "gqcnn", scenes[0].T_world_cam,
                                                       trained.parent), "trained"
        else:
            torch.manual_seed(0)
            net = GQCNN(gqcnn_config(full)) if variant == "gqcnn" else None
            planner = DexNetPlanner(variant, workspace(full, scenes[0].T_world_cam),
                                    sampler_config(full), cem_config(full),
                                    planarity_config(full), crop_config(full), net)
            label = "untrained" if variant == "gqcnn" else "analytic"
        planner.plan(scenes[0].depth_m, intr)  # warm-up
        times = []
        for sc in scenes:
            t0 = time.perf_counter()
            planner.plan(sc.depth_m, intr)
            times.append(time.perf_counter() - t0)
        out[f"plan_dexnet_{variant}_ms"] = 1000 * float(np.median(times))
        print(f"planning, Dex-Net-style {variant} + CEM ({label}): "
              f"{out[f'plan_dexnet_{variant}_ms']:.1f} ms/image")
    net = GQCNN(gqcnn_config(full)).train()
    opt = torch.optim.Adam(net.parameters(), lr=1e-3)
    size = int(full.dexnet.crop.size)
    x, pose = torch.randn(64, 1, size, size), torch.randn(64, 2)
    y = (torch.rand(64) > 0.5).float()
    times = []
    for _ in range(6):
        t0 = time.perf_counter()
        opt.zero_grad()
        torch.nn.functional.binary_cross_entropy_with_logits(net(x, pose), y).backward()
        opt.step()
        times.append(time.perf_counter() - t0)
    out["gqcnn_train_crops_per_s"] = 64 / float(np.median(times[1:]))
    print(f"GQ-CNN training, batch 64: {out['gqcnn_train_crops_per_s']:.0f} crops/s")
    return out


def closed_loop_figures(cfg_name: str = "evaluate", renderer: str | None = None,
                        descriptor: bool = True, boxes: int = 3) -> dict[str, float]:
    """Closed loop: the descriptor's time per 416 x 416 frame, and one trial of ``boxes`` driven by
    the training-free Dex-Net-style planarity planner (no artifact needed): control-loop rate
    (wall), simulated seconds per wall second, wall time of the trial, and where a control step's
    wall time goes (median ms per call of each part). ``renderer``: ``camera.renderer`` (None:
    the configured one); keys carry its name when given."""
    import torch

    from pipeline.cli import compose
    from pipeline.controller.planning import DexNetStylePlanner
    from pipeline.servo.descriptor import describe_surface
    from pipeline.world.trial import make_runner

    torch.set_num_threads(1)
    extra = [f"camera.renderer={renderer}"] if renderer else []
    cfg = compose(cfg_name, ["experiment=default", f"evaluate.boxes_per_trial={boxes}",
                             "evaluate.dexnet_variant=planarity", *extra])
    runner = make_runner(cfg, "dexnet", lambda cell: DexNetStylePlanner(
        cfg, "planarity", cell.robot.home_camera_pose(), None))
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
    result = runner.run_trial(0, np.random.default_rng([BENCH_SEED, 31, 0]),
                              np.random.default_rng([BENCH_SEED, 37, 0]))
    wall = time.perf_counter() - t0
    cell.close()
    runner.robot_side.close()
    tm = {**runner.timings, **runner.robot_side.timings}
    sfx = f"_{renderer}" if renderer else ""
    steps = tm["control_step_s"]
    out[f"control_loop_hz{sfx}"] = 1.0 / float(np.median(steps)) if steps else float("nan")
    out[f"sim_s_per_wall_s{sfx}"] = result.sim_s / wall
    out[f"trial_{boxes}_boxes_wall_s{sfx}"] = wall
    parts = {"render": "render_s", "descriptor": "descriptor_s",
             "control law + Jacobian + joint update": "control_law_s", "physics": "physics_s",
             "collision check": "collision_s"}
    ms = {k: 1000 * float(np.median(tm[v])) if tm[v] else 0.0 for k, v in parts.items()}
    for k, v in parts.items():
        out[f"step_{v[:-2]}_ms{sfx}"] = ms[k]
    name = renderer or str(cfg.camera.renderer)
    print(f"closed loop ({name}): control loop {out[f'control_loop_hz{sfx}']:.1f} Hz (wall), "
          f"{out[f'sim_s_per_wall_s{sfx}']:.2f} simulated s per wall s; one {boxes}-box trial "
          f"{wall:.1f} s wall ({result.picked}/{result.boxes} picked in {len(result.attempts)} "
          f"attempts, {result.sim_s:.1f} s simulated)")
    print(f"  control step {1000 * float(np.median(steps)) if steps else float('nan'):.1f} ms "
          "(median): " + ", ".join(f"{k} {v:.1f} ms" for k, v in ms.items()))
    return out


def render_group(cfg, num_scenes: int) -> dict[str, float]:
    """``--only render``: both renderers on the same frames, the rest check, generation scenes/s
    (stage, 1 worker, and the bare loop) and the closed loop with each renderer (one trial of
    the evaluation's size, the planarity planner, one process)."""
    from pipeline.cli import compose

    out = render_figures(cfg)
    out.update(rest_figures(cfg))
    # best of two alternating runs of each: on a shared 2-core machine single runs of a few
    # seconds scatter by about ±15 %
    for rep in range(2):
        for name in ("tinyrenderer", "raycast"):
            rc = dataclasses.replace(cfg, camera=dataclasses.replace(cfg.camera, renderer=name))
            with tempfile.TemporaryDirectory() as root:
                rates = stage_rates(num_scenes, root, workers_list=(1,),
                                    extra=(f"camera.renderer={name}",), label=False)
            for key, rate in ((f"generate_1w_scenes_per_s_{name}",
                               rates["generate_1w_scenes_per_s"]),
                              (f"bare_loop_scenes_per_s_{name}",
                               bare_loop(num_scenes, rc, BENCH_SEED))):
                out[key] = max(out.get(key, 0.0), rate)
    for name in ("tinyrenderer", "raycast"):
        out[f"stage_vs_bare_{name}"] = (out[f"generate_1w_scenes_per_s_{name}"]
                                        / out[f"bare_loop_scenes_per_s_{name}"])
        print(f"generation ({name}), 1 worker, best of 2: "
              f"{out[f'generate_1w_scenes_per_s_{name}']:.2f} scenes/s; bare loop "
              f"{out[f'bare_loop_scenes_per_s_{name}']:.2f} scenes/s; stage / bare "
              f"{out[f'stage_vs_bare_{name}']:.2f} (target >= 0.90)")
    out["generate_raycast_speedup"] = (out["generate_1w_scenes_per_s_raycast"]
                                       / out["generate_1w_scenes_per_s_tinyrenderer"])
    print(f"generation speed-up of the ray-cast renderer: {out['generate_raycast_speedup']:.2f}x")
    boxes = int(compose("evaluate", ["experiment=default"]).evaluate.boxes_per_trial)
    for name in ("tinyrenderer", "raycast"):
        out.update(closed_loop_figures(renderer=name, descriptor=False, boxes=boxes))
    out["closed_loop_raycast_speedup"] = (out["sim_s_per_wall_s_raycast"]
                                          / out["sim_s_per_wall_s_tinyrenderer"])
    print(f"closed-loop speed-up of the ray-cast renderer: "
          f"{out['closed_loop_raycast_speedup']:.2f}x (target: >= 2 simulated s per wall s)")
    return out


def sensor_figures(num_images: int = 20, repeats: int = 3) -> dict[str, float]:
    """The SR300 model and the depth filters on the bench's heaps: ms per 416 × 416 image
    (median over images × repeats), the fraction of pixels without data where the ideal depth
    has data, and the error against the ideal depth (median |e| and the 90th percentile of
    |e|, mm, over the pixels with data)."""
    from omegaconf import OmegaConf

    from pipeline.camera.depth_filter import fill_holes, median_filter, preprocess_depth
    from pipeline.camera.sensor import apply_sensor_model
    from pipeline.cli import compose

    cfg = OmegaConf.to_object(compose("generate", ["experiment=default", "sensor=sr300"]))
    filters = {name: OmegaConf.to_object(compose("evaluate", [f"depth_filter={name}"])
                                         ).depth_filter for name in ("fill", "fill_median")}
    intr = intrinsics_of(cfg)
    scenes = bench_scenes(cfg, num_images)
    times: dict[str, list[float]] = {"sensor": [], "fill": [], "median5": []}
    stats: dict[str, list[np.ndarray]] = {"sensor": [], "fill": [], "fill_median": []}
    lost: dict[str, list[float]] = {k: [] for k in stats}
    for k, sc in enumerate(scenes):
        ideal = sc.depth_clean_m
        for r in range(repeats):
            rng = np.random.default_rng([BENCH_SEED, k, r])
            t0 = time.perf_counter()
            noisy = apply_sensor_model(ideal, cfg.sensor, rng, intr)
            t1 = time.perf_counter()
            filled = fill_holes(noisy, filters["fill"].fill_holes_px)
            t2 = time.perf_counter()
            median_filter(filled, filters["fill_median"].median_px)
            t3 = time.perf_counter()
            times["sensor"].append(t1 - t0)
            times["fill"].append(t2 - t1)
            times["median5"].append(t3 - t2)
        images = {"sensor": noisy, "fill": preprocess_depth(noisy, filters["fill"]),
                  "fill_median": preprocess_depth(noisy, filters["fill_median"])}
        for name, img in images.items():
            has = ideal > 0
            lost[name].append(float(np.mean((img == 0) & has)))
            ok = has & (img > 0)
            stats[name].append(np.abs(img[ok] - ideal[ok]))
    out = {f"{k}_ms_per_image": 1000 * float(np.median(v)) for k, v in times.items()}
    for name in stats:
        err = np.concatenate(stats[name])
        out[f"{name}_missing_fraction"] = float(np.mean(lost[name]))
        out[f"{name}_median_abs_error_mm"] = 1000 * float(np.median(err))
        out[f"{name}_p90_abs_error_mm"] = 1000 * float(np.percentile(err, 90))
    print(f"SR300 model and depth filters, {num_images} default heaps x {repeats} noise draws "
          "(416 x 416):")
    print(f"  time per image: sensor model {out['sensor_ms_per_image']:.1f} ms, hole filling "
          f"{out['fill_ms_per_image']:.1f} ms, 5x5 median {out['median5_ms_per_image']:.1f} ms")
    for name in stats:
        print(f"  {name:12s} pixels without data {100 * out[f'{name}_missing_fraction']:5.1f} %, "
              f"|error| median {out[f'{name}_median_abs_error_mm']:.2f} mm, "
              f"90th percentile {out[f'{name}_p90_abs_error_mm']:.2f} mm")
    return out


def intrinsics_of(cfg):
    from pipeline.camera.geometry import Intrinsics
    return Intrinsics.from_config(cfg.camera)


def main(argv: list[str] | None = None) -> int:
    from omegaconf import OmegaConf

    from pipeline.cli import compose

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", type=int, default=60, help="scenes per throughput run")
    parser.add_argument("--only", choices=("all", "stages", "render", "planners", "closed-loop",
                                           "executors", "training", "sensor", "ood", "gpu"),
                        default="all", help="run one group of figures")
    parser.add_argument("--experiment", default="paper",
                        help="--only training: whose latest label artifact to load (paper)")
    parser.add_argument("--root", default=None,
                        help="--only training: paths.root holding that artifact (the repository)")
    args = parser.parse_args(argv)
    cfg = OmegaConf.to_object(compose("generate", ["experiment=smoke"]))
    os.environ.setdefault("LP_NUM_THREADS", "1")

    results = {}
    if args.only == "training":
        mem = training_memory(args.experiment, args.root)
        print(f"training memory, `{args.experiment}` data ({mem['images']} images, "
              f"network width {mem['width']}):")
        print(f"  process at start (imports):          {mem['rss_start_mb']:.0f} MB")
        print(f"  after loading the splits:            {mem['rss_after_load_mb']:.0f} MB "
              f"({mem['load_s']:.1f} s; the depth in memory would take "
              f"{mem['in_memory_depth_mb']:.0f} MB)")
        print(f"  after one epoch of batches read:     {mem['rss_after_epoch_of_data_mb']:.0f} MB "
              f"({mem['decode_images_per_s']:.0f} images/s decoded, 1 loader worker)")
        print(f"  peak, with training steps (batch 16): {mem['peak_rss_mb']:.0f} MB "
              f"(loader worker peak {mem['peak_rss_loader_worker_mb']:.0f} MB; "
              f"{mem['train_images_per_s']:.2f} images/s)")
        print(json.dumps({k: round(v, 3) if isinstance(v, float) else v for k, v in mem.items()}))
        return 0
    if args.only in ("ood", "gpu"):  # the baseline's out-of-domain heaps; the DCNN on CUDA
        from pipeline import bench_gpu, bench_ood
        return (bench_ood.main(["--scenes", str(min(args.scenes, 8))]) if args.only == "ood"
                else bench_gpu.main([]))
    if args.only in ("render", "executors"):
        results.update(render_group(cfg, args.scenes) if args.only == "render"
                       else executor_figures(args.scenes))
        print(json.dumps({k: round(v, 3) for k, v in results.items()}))
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
        print(json.dumps({k: round(v, 3) for k, v in results.items()}))
        return 0
    results.update(render_figures(cfg))
    results.update(rest_figures(cfg))
    results["bare_loop_scenes_per_s"] = bare_loop(args.scenes, cfg, BENCH_SEED)
    print(f"bare pybullet loop, 1 process:          {results['bare_loop_scenes_per_s']:.2f} scenes/s")
    with tempfile.TemporaryDirectory() as root:
        results.update(stage_rates(args.scenes, root))
    for workers in (1, 2):
        print(f"generation stage, {workers} worker(s):        "
              f"{results[f'generate_{workers}w_scenes_per_s']:.2f} scenes/s")
    one, two = results["generate_1w_scenes_per_s"], results["generate_2w_scenes_per_s"]
    results["stage_vs_bare_per_process"] = one / results["bare_loop_scenes_per_s"]
    results["speedup_2w"] = two / one
    print(f"stage / bare loop, per process:         {results['stage_vs_bare_per_process']:.2f} "
          "(target >= 0.90)")
    print(f"speed-up with 2 workers:                {results['speedup_2w']:.2f}x (target >= 1.6x)")
    for workers in (1, 2):
        print(f"labelling stage, {workers} worker(s):         "
              f"{results[f'label_{workers}w_scenes_per_s']:.2f} scenes/s")
    print(f"labelling per scene, 1 process:         "
          f"{results['label_surfaces_ms_per_scene']:.1f} ms surfaces + "
          f"{results['label_robot_ms_per_scene']:.1f} ms robot checks")
    results.update(planning_times(cfg))
    width = float(compose("train", ["experiment=default"]).model.width)
    # the default network in both layouts, and the one twice as wide, in the same run
    for key, w, last in (("default", width, False), ("default_channels_last", width, True),
                         ("wide_channels_last", 2 * width, True)):
        results[f"train_{key}_images_per_s"] = training_images_per_s(cfg, w, channels_last=last)
    contiguous, channels_last, wide = (results[f"train_{k}_images_per_s"] for k in
                                       ("default", "default_channels_last", "wide_channels_last"))
    print(f"training, default network (width {width}), batch 16: {contiguous:.1f} images/s "
          f"contiguous, {channels_last:.1f} images/s channels_last "
          f"({channels_last / contiguous:.2f}x, same run); width {2 * width}, channels_last: "
          f"{wide:.1f} images/s ({wide / channels_last:.2f}x the default's)")
    results["label_vs_generate_1w"] = results["label_1w_scenes_per_s"] / one
    print(f"labelling / generation, per process:    {results['label_vs_generate_1w']:.2f} "
          "(target >= 1: labelling is not the bottleneck)")
    if args.only == "all":
        results.update(dexnet_figures(cfg))
        results.update(closed_loop_figures())
    print(json.dumps({k: round(v, 3) for k, v in results.items()}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
