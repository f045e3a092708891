"""Dropping a random heap of non-box objects into the bin, by the box heaps' physics.

The out-of-domain training set of the Dex-Net-style baseline (docs/baseline.md) is heaps of the
random convex objects of ``pipeline.simulation.objects`` (cylinders, prisms, convex hulls) in
the same bin, dropped, settled and cleaned up exactly as ``pipeline.simulation.heap`` does it for
boxes: the same cell (``pipeline.cell.bin.build_cell``), drop height, drop cadence, margin
from the walls, rest criterion (``heap.settle``, watching the corners of each object's bounding
box in its own frame) and removal of objects that came to rest outside the bin. The one
difference is the caller's: ``pipeline.dexnet.ood`` settles them at ``objects.solver_iterations``
(docs/simulation.md, "Solver iterations").

World frame: z up, origin at the centre of the bin floor's top surface; metres, seconds
(``pipeline.simulation.heap``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pybullet as p

from pipeline.config.build import from_section
from pipeline.simulation.heap import drop_area, inside_bin, random_quaternion, settle
from pipeline.simulation.objects import ObjectSetSpec, ObjectShape, create_body, sample_object


@dataclass
class ObjectPose:
    """One object at rest.

    Attributes:
        shape: the object in its own frame (origin = centre of mass).
        position: (3,) centre of mass in the world frame, m.
        quat_xyzw: (4,) orientation of the object frame in the world frame (x, y, z, w).
        body_id: pybullet body unique id in the current simulation.
    """

    shape: ObjectShape
    position: np.ndarray
    quat_xyzw: np.ndarray
    body_id: int


@dataclass
class ObjectHeap:
    """The heap after settling (``heap.HeapResult``'s fields, for objects)."""

    objects: list[ObjectPose]
    num_dropped: int
    num_removed: int
    settle_steps: int
    settled: bool


def object_spec(objects_cfg) -> ObjectSetSpec:
    """The ``ObjectSetSpec`` of the ``objects`` config section (``conf/objects/``), each field
    from the key of the same name."""
    return from_section(ObjectSetSpec, objects_cfg)


def drop_object_heap(
    client: int, rng: np.random.Generator, objects_cfg, bin_cfg, physics_cfg
) -> ObjectHeap:
    """Drop a random number of random objects one by one, settle, remove escapees, settle again.

    ``objects_cfg``: the ``objects`` section (``conf/objects/``: the shape spec, ``min_count``,
    ``max_count``, ``density``, ``lateral_friction``); the cell must have been built
    (``pipeline.cell.bin.build_cell``). Random draws, in this order: the count, then per object its
    shape
    (``objects.sample_object``), x, y and orientation.
    """
    spec = object_spec(objects_cfg)
    lo, hi = int(objects_cfg.min_count), int(objects_cfg.max_count)
    if not 0 <= lo <= hi:
        raise ValueError(
            f"objects.min_count and max_count must satisfy 0 <= min <= max, got {lo} and {hi}"
        )
    n = int(rng.integers(lo, hi + 1))
    hx, hy = drop_area(bin_cfg, physics_cfg)
    bodies: dict[int, ObjectShape] = {}
    steps = 0
    for i in range(n):
        shape = sample_object(rng, spec)
        x, y = rng.uniform(-hx, hx), rng.uniform(-hy, hy)
        q = random_quaternion(rng)
        body = create_body(
            client,
            shape,
            float(objects_cfg.density),
            float(objects_cfg.lateral_friction),
            [x, y, physics_cfg.drop_height_above_bin_floor],
            q,
            friction_anchor=bool(physics_cfg.friction_anchor),
        )
        bodies[body] = shape
        if i < n - 1:
            for _ in range(physics_cfg.drop_interval_steps):
                p.stepSimulation(physicsClientId=client)
            steps += physics_cfg.drop_interval_steps

    def half(ids):
        return np.array([bodies[b].extents / 2.0 for b in ids]).reshape(-1, 3)

    ids = list(bodies)
    settle_steps, settled = settle(
        client, ids, physics_cfg, physics_cfg.max_settle_steps, half(ids)
    )
    steps += settle_steps
    removed = 0
    for body in ids:
        pos, _ = p.getBasePositionAndOrientation(body, physicsClientId=client)
        if not inside_bin(np.asarray(pos), bin_cfg):
            p.removeBody(body, physicsClientId=client)
            del bodies[body]
            removed += 1
    if removed and bodies:  # removing one can unsettle a neighbour leaning on it
        ids = list(bodies)
        extra, settled_again = settle(
            client, ids, physics_cfg, physics_cfg.max_settle_steps, half(ids)
        )
        steps += extra
        settled = settled and settled_again
    out = []
    for body, shape in bodies.items():
        pos, quat = p.getBasePositionAndOrientation(body, physicsClientId=client)
        out.append(ObjectPose(shape, np.asarray(pos), np.asarray(quat), body))
    return ObjectHeap(
        objects=out, num_dropped=n, num_removed=removed, settle_steps=steps, settled=settled
    )
