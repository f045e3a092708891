"""Measured figures of the out-of-domain training heaps of the Dex-Net-style baseline.

    python -m pipeline.tools.bench_ood [--experiment default] [--scenes 8]

Prints, on object heaps of ``conf/objects/`` in one process: ms per 416 x 416 frame of the
three ways to render them (the half-space ray cast ``pipeline.camera.raycast_convex``,
TinyRenderer, and ``p.rayTestBatch`` against ``contact_mesh.RayScene``'s triangle-mesh mirror),
how far TinyRenderer's image is from the exact one, and the seconds per labelled heap
(``pipeline.dexnet.ood.object_heap_scene``), with the projected time of the heaps of
``baseline.ood`` at the experiment's scale on one process (docs/baseline.md).
"""

from __future__ import annotations

import argparse
import time
from types import SimpleNamespace

import numpy as np
import pybullet as p

from pipeline.camera.geometry import Intrinsics, camera_pose_above_bin
from pipeline.camera.raycast_convex import convex_from_pybullet, raycast_convex
from pipeline.camera.render import render_depth
from pipeline.cell.bin import build_cell
from pipeline.dexnet.contact_mesh import RayScene
from pipeline.dexnet.ood import connect, object_heap_scene, object_scene_rng
from pipeline.runtime.cli import compose
from pipeline.simulation.object_heap import drop_object_heap


def _ray_test_batch(client: int, intr: Intrinsics, T: np.ndarray, near: float, far: float):
    """Depth by ``p.rayTestBatch`` on a ``RayScene`` mirror of every body: (H, W) z-depth."""
    with RayScene(client) as rays:
        u, v = np.meshgrid(np.arange(intr.width), np.arange(intr.height))
        r = (
            np.stack(
                [(u - intr.cx) / intr.fx, (v - intr.cy) / intr.fy, np.ones(u.shape)], -1
            ).reshape(-1, 3)
            @ T[:3, :3].T
        )
        starts, ends = T[:3, 3] + near * r, T[:3, 3] + far * r
        hits = []
        for i in range(0, len(r), 8192):
            hits += p.rayTestBatch(
                starts[i : i + 8192], ends[i : i + 8192], numThreads=1, physicsClientId=rays.client
            )
    frac = np.array([h[2] for h in hits])
    return (near + frac * (far - near)).reshape(intr.height, intr.width)


def render_figures(cfg, heaps: int) -> dict[str, float]:
    intr = Intrinsics.from_config(cfg.camera)
    T = camera_pose_above_bin(cfg.camera.height_above_bin_floor)
    near, far = float(cfg.camera.near), float(cfg.camera.far)
    c = connect()
    times = {"raycast_convex_ms": [], "tinyrenderer_ms": [], "ray_test_batch_ms": []}
    gaps, mismatched = [], []
    try:
        for i in range(heaps):
            cell = build_cell(c, cfg.bin, cfg.physics)
            heap = drop_object_heap(
                c, object_scene_rng(int(cfg.seed), 9, i), cfg.objects, cfg.bin, cfg.physics
            )
            bodies = cell[1:] + [o.body_id for o in heap.objects]
            t0 = time.perf_counter()
            depth, ids = raycast_convex(convex_from_pybullet(c, bodies), intr, T, near, far)
            t1 = time.perf_counter()
            frame = render_depth(c, intr, T, near, far, renderer="tinyrenderer")
            t2 = time.perf_counter()
            _ray_test_batch(c, intr, T, near, far)
            t3 = time.perf_counter()
            for k, dt in zip(times, (t1 - t0, t2 - t1, t3 - t2)):
                times[k].append(1000 * dt)
            seen = ids >= 0
            same = seen & (frame.body_ids == ids)
            mismatched.append(1.0 - same.sum() / max(seen.sum(), 1))
            gaps.append(np.percentile(np.abs(frame.depth_m[same] - depth[same]), 99))
    finally:
        p.disconnect(c)
    out = {k: round(float(np.median(v)), 1) for k, v in times.items()}
    out["tinyrenderer_p99_depth_gap_m"] = float(np.max(gaps))
    out["tinyrenderer_other_body_share"] = float(np.max(mismatched))
    return out


def scene_figures(cfg, scenes: int) -> dict[str, float]:
    sensor = SimpleNamespace(enabled=False)
    count = int(cfg.baseline.ood.candidates_per_scene)
    c = connect()
    try:
        t0 = time.perf_counter()
        for i in range(scenes):
            object_heap_scene(c, cfg, object_scene_rng(int(cfg.seed), 0, i), count, sensor, 1e-4)
        per = (time.perf_counter() - t0) / max(scenes, 1)
    finally:
        p.disconnect(c)
    total = int(cfg.baseline.ood.num_scenes) + int(cfg.baseline.ood.num_val_scenes)
    return {
        "s_per_labelled_heap": round(per, 3),
        "heaps": total,
        "projected_h_one_process": round(total * per / 3600.0, 2),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--experiment", default="default")
    parser.add_argument("--scenes", type=int, default=8)
    args = parser.parse_args(argv)
    cfg = compose("baseline", [f"experiment={args.experiment}"])
    for k, v in {
        **render_figures(cfg, max(1, args.scenes // 2)),
        **scene_figures(cfg, args.scenes),
    }.items():
        print(f"{k}: {v}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
