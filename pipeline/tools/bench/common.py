"""What the benchmarks share: their seed, the camera of a config, the scenes they plan on."""

from __future__ import annotations

import numpy as np
import pybullet as p

BENCH_SEED = 12345


def rest_check_rng(index: int) -> np.random.Generator:
    """The heaps of the rest check (bench and slow test): seeds (BENCH_SEED, 7, index)."""
    return np.random.default_rng([BENCH_SEED, 7, index])


def intrinsics_of(cfg):
    from pipeline.camera.geometry import Intrinsics

    return Intrinsics.from_config(cfg.camera)


def bench_scenes(cfg, num_images: int) -> list:
    """``num_images`` simulated heaps of the bench's fixed seed (test split code 2)."""
    from pipeline.simulation.scene import connect, scene_rng, simulate_scene

    client = connect()
    try:
        return [simulate_scene(client, cfg, scene_rng(BENCH_SEED, 2, i)) for i in range(num_images)]
    finally:
        p.disconnect(client)
