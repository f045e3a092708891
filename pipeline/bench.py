"""Measured performance figures (``make bench``); prints, never asserts.

Generation throughput with 1 and 2 worker processes, the render time per frame, and the ratio
of the stage's per-process rate to a bare pybullet loop doing the same work (same cell, same
trickle drop and rest test, same TinyRenderer frame) measured in the same run.

    python -m pipeline.bench [--scenes 60] [--render-frames 30]
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path

import numpy as np
import pybullet as p


def bare_loop(num_scenes: int, cfg) -> float:
    """Scenes per second of a minimal settle + render loop (no storage, no logging)."""
    client = p.connect(p.DIRECT)
    W = H = 416
    view = p.computeViewMatrix([0, 0, 0.625], [0, 0, 0], [0, 1, 0])
    proj = p.computeProjectionMatrixFOV(53.6, 1.0, 0.1, 2.0)
    sizes = [np.asarray(t.size) for t in cfg.boxes.types]
    t0 = time.perf_counter()
    for i in range(num_scenes):
        rng = np.random.default_rng([cfg.seed, 9, i])
        p.resetSimulation(physicsClientId=client)
        p.setGravity(0, 0, -9.81, physicsClientId=client)
        p.setPhysicsEngineParameter(fixedTimeStep=1 / 240, numSolverIterations=50,
                                    physicsClientId=client)
        ground = p.createCollisionShape(p.GEOM_PLANE, physicsClientId=client)
        p.createMultiBody(0, ground, basePosition=[0, 0, -0.02], physicsClientId=client)
        lx, ly, h, t = 0.40, 0.30, 0.15, 0.01
        parts = [([lx / 2 + t, ly / 2 + t, 0.01], [0, 0, -0.01]),
                 ([t / 2, ly / 2 + t, h / 2], [-(lx + t) / 2, 0, h / 2 - 0.02]),
                 ([t / 2, ly / 2 + t, h / 2], [(lx + t) / 2, 0, h / 2 - 0.02]),
                 ([lx / 2, t / 2, h / 2], [0, -(ly + t) / 2, h / 2 - 0.02]),
                 ([lx / 2, t / 2, h / 2], [0, (ly + t) / 2, h / 2 - 0.02])]
        for half, pos in parts:
            col = p.createCollisionShape(p.GEOM_BOX, halfExtents=half, physicsClientId=client)
            vis = p.createVisualShape(p.GEOM_BOX, halfExtents=half, physicsClientId=client)
            p.createMultiBody(0, col, vis, basePosition=pos, physicsClientId=client)
        bodies = []
        for j in range(int(rng.integers(0, 21))):
            s = sizes[int(rng.integers(len(sizes)))]
            col = p.createCollisionShape(p.GEOM_BOX, halfExtents=(s / 2).tolist(),
                                         physicsClientId=client)
            vis = p.createVisualShape(p.GEOM_BOX, halfExtents=(s / 2).tolist(),
                                      physicsClientId=client)
            q = rng.normal(size=4)
            bodies.append(p.createMultiBody(400 * float(np.prod(s)), col, vis,
                                            basePosition=[rng.uniform(-0.17, 0.17),
                                                          rng.uniform(-0.12, 0.12), 0.625],
                                            baseOrientation=(q / np.linalg.norm(q)).tolist(),
                                            physicsClientId=client))
            for _ in range(20):
                p.stepSimulation(physicsClientId=client)
        calm, steps = 0, 0
        while calm < 5 and steps < 3000:
            for _ in range(10):
                p.stepSimulation(physicsClientId=client)
            steps += 10
            still = all(np.linalg.norm(p.getBaseVelocity(b, physicsClientId=client)[0]) < 0.005
                        and np.linalg.norm(p.getBaseVelocity(b, physicsClientId=client)[1]) < 0.05
                        for b in bodies)
            calm = calm + 1 if still else 0
        _, _, _, depth, seg = p.getCameraImage(W, H, view, proj, renderer=p.ER_TINY_RENDERER,
                                               physicsClientId=client)
        d = np.asarray(depth, np.float32).reshape(H, W)
        _ = 2.0 * 0.1 / (2.0 - 1.9 * d)
    rate = num_scenes / (time.perf_counter() - t0)
    p.disconnect(client)
    return rate


def render_time_ms(frames: int, cfg) -> float:
    """Median wall time of one 416 × 416 depth + mask frame of a settled 20-box heap."""
    from pipeline.camera.geometry import Intrinsics, camera_pose_above_bin
    from pipeline.camera.render import render_depth
    from pipeline.simulation.heap import build_cell, drop_heap

    client = p.connect(p.DIRECT)
    cell = build_cell(client, cfg.bin, cfg.physics)
    boxes = cfg.boxes
    boxes.min_count = boxes.max_count = 20
    drop_heap(client, np.random.default_rng(0), boxes, cfg.bin, cfg.physics)
    intr = Intrinsics.from_config(cfg.camera)
    T = camera_pose_above_bin(cfg.camera.height_above_bin_floor)
    times = []
    for _ in range(frames):
        t0 = time.perf_counter()
        render_depth(client, intr, T, cfg.camera.near, cfg.camera.far,
                     ground=(-cfg.bin.floor_thickness, cell[0]))
        times.append(time.perf_counter() - t0)
    p.disconnect(client)
    return 1000 * float(np.median(times))


def stage_rate(num_scenes: int, workers: int) -> float:
    """Scenes per second of ``pipeline.generate`` itself (simulation + storage), from its manifest."""
    from pipeline.artifacts.store import load_manifest
    from pipeline.generate import generate
    from pipeline.cli import compose

    with tempfile.TemporaryDirectory() as root:
        cfg = compose("generate", [
            "experiment=smoke", f"paths.root={root}", f"generate.num_scenes={num_scenes}",
            "generate.num_val_scenes=0", "generate.num_test_scenes=0",
            "generate.scenes_per_shard=10", f"generate.workers={workers}",
            "logging.max_logged_scenes=0", "logging.progress=false", "seed=12345",
        ])
        folder = generate(cfg)
        return float(load_manifest(folder)["timings"]["scenes_per_s"])


def main(argv: list[str] | None = None) -> int:
    from omegaconf import OmegaConf

    from pipeline.cli import compose

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", type=int, default=60, help="scenes per throughput run")
    parser.add_argument("--render-frames", type=int, default=30)
    args = parser.parse_args(argv)
    cfg = OmegaConf.to_object(compose("generate", ["experiment=smoke"]))
    os.environ.setdefault("LP_NUM_THREADS", "1")

    results = {}
    results["render_ms_per_frame"] = render_time_ms(args.render_frames, cfg)
    print(f"render, 416x416 depth + mask, 20 boxes: {results['render_ms_per_frame']:.1f} ms/frame")
    results["bare_loop_scenes_per_s"] = bare_loop(args.scenes, cfg)
    print(f"bare pybullet loop, 1 process:          {results['bare_loop_scenes_per_s']:.2f} scenes/s")
    for workers in (1, 2):
        rate = stage_rate(args.scenes, workers)
        results[f"generate_{workers}w_scenes_per_s"] = rate
        print(f"generation stage, {workers} worker(s):        {rate:.2f} scenes/s")
    one, two = results["generate_1w_scenes_per_s"], results["generate_2w_scenes_per_s"]
    results["stage_vs_bare_per_process"] = one / results["bare_loop_scenes_per_s"]
    results["speedup_2w"] = two / one
    print(f"stage / bare loop, per process:         {results['stage_vs_bare_per_process']:.2f} "
          "(target >= 0.90)")
    print(f"speed-up with 2 workers:                {results['speedup_2w']:.2f}x (target >= 1.6x)")
    print(json.dumps({k: round(v, 3) for k, v in results.items()}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
