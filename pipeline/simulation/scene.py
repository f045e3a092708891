"""One synthetic scene: a heap dropped into the bin, at rest, seen by the overhead camera."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pybullet as p

from pipeline.camera.geometry import (
    Intrinsics,
    camera_pose_above_bin,
    pose_matrix,
    quat_from_matrix,
)
from pipeline.camera.render import render_depth
from pipeline.camera.sensor import apply_sensor_model
from pipeline.cell.bin import build_cell
from pipeline.simulation.heap import BoxPose, drop_heap


@dataclass
class SimulatedScene:
    """A rendered heap.

    Attributes:
        depth_m: (H, W) float32 z-depth, metres, as the sensor returns it (0 = no data; with
            ``sensor=ideal`` the ideal depth, which has data everywhere).
        depth_clean_m: (H, W) float32 ideal z-depth, metres (the renderer's; the same array as
            ``depth_m`` when the sensor model is off).
        mask: (H, W) uint8: 0 = not a box, k = ``boxes[k-1]``.
        boxes: boxes at rest inside the bin, in drop order.
        T_world_cam: (4, 4) camera pose (OpenCV axes) in the world frame.
        num_dropped, num_removed, settle_steps, settled: see ``HeapResult``.
    """

    depth_m: np.ndarray
    depth_clean_m: np.ndarray
    mask: np.ndarray
    boxes: list[BoxPose]
    T_world_cam: np.ndarray
    num_dropped: int
    num_removed: int
    settle_steps: int
    settled: bool


def instance_mask(body_ids: np.ndarray, objects: list[int]) -> np.ndarray:
    """The (H, W) uint8 instance mask of a rendered (H, W) body-id image ``body_ids`` (-1 = no
    body): k where the pixel shows ``objects[k-1]``, 0 for everything else."""
    lut = np.zeros(int(body_ids.max(initial=-1)) + 2, dtype=np.uint8)
    for k, body in enumerate(objects, start=1):
        if body + 1 < len(lut):
            lut[body + 1] = k
    return lut[body_ids + 1]


def scene_rng(base_seed: int, split_code: int, index: int) -> np.random.Generator:
    """The scene's generator: a pure function of (base seed, split, index).

    Distinct (split, index) pairs give distinct seed sequences, so splits never share a seed.
    """
    return np.random.default_rng([int(base_seed), int(split_code), int(index)])


def simulate_scene(
    client: int, cfg, rng: np.random.Generator, size_jitter: float = 0.0, cartons: bool = False
) -> SimulatedScene:
    """Build the cell, drop a heap, let it rest, render depth and the instance mask.

    ``cfg`` needs the sections ``camera``, ``bin``, ``boxes``, ``physics`` and ``sensor``;
    ``size_jitter``: ``drop_heap``'s per-edge size scale range (0 = the types' exact sizes);
    ``cartons``: the boxes are drawn from ``boxes.cartons`` (``drop_heap``).
    """
    cell = build_cell(client, cfg.bin, cfg.physics)
    heap = drop_heap(client, rng, cfg.boxes, cfg.bin, cfg.physics, size_jitter, cartons)
    intr = Intrinsics.from_config(cfg.camera)
    T_world_cam = camera_pose_above_bin(cfg.camera.height_above_bin_floor)
    frame = render_depth(
        client,
        intr,
        T_world_cam,
        cfg.camera.near,
        cfg.camera.far,
        ground=(-cfg.bin.floor_thickness, cell[0]),
        renderer=cfg.camera.renderer,
        bodies=cell[1:] + [b.body_id for b in heap.boxes],
    )
    mask = instance_mask(frame.body_ids, [b.body_id for b in heap.boxes])
    depth = apply_sensor_model(frame.depth_m, cfg.sensor, rng, intr)
    return SimulatedScene(
        depth_m=depth,
        depth_clean_m=frame.depth_m,
        mask=mask,
        boxes=heap.boxes,
        T_world_cam=T_world_cam,
        num_dropped=heap.num_dropped,
        num_removed=heap.num_removed,
        settle_steps=heap.settle_steps,
        settled=heap.settled,
    )


def box_pose_world(box: BoxPose) -> np.ndarray:
    """(4, 4) pose of the box centre in the world frame."""
    return pose_matrix(box.position, box.quat_xyzw)


def collision_box(client: int, size, T_world_box: np.ndarray) -> int:
    """A static box with a collision shape and no visual one: edges ``size`` (x, y, z) in
    metres, centred at the pose ``T_world_box`` ((4, 4), world frame). Returns its body id."""
    half = (np.asarray(size) / 2).tolist()
    shape = p.createCollisionShape(p.GEOM_BOX, halfExtents=half, physicsClientId=client)
    return p.createMultiBody(
        0.0,
        shape,
        -1,
        basePosition=T_world_box[:3, 3].tolist(),
        baseOrientation=quat_from_matrix(T_world_box[:3, :3]).tolist(),
        physicsClientId=client,
    )


def connect() -> int:
    """A headless pybullet client."""
    return p.connect(p.DIRECT)
