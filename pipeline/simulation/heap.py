"""Dropping a random heap of boxes into a bin and letting it come to rest (paper Sec. 4.3).

World frame: z up, origin at the centre of the bin floor's top surface; metres, seconds.
The bin's inner walls are at x = ±inner_length_x/2 and y = ±inner_width_y/2; its floor
spans z ∈ [−floor_thickness, 0] and stands on the ground (top at z = −floor_thickness).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pybullet as p

from pipeline.camera.geometry import rotation_matrices
from pipeline.simulation.cartons import draw_carton


@dataclass
class BoxPose:
    """One box at rest.

    Attributes:
        type_index: index into the box set's ``types``; ``len(types)`` for a carton drawn from
            ``boxes.cartons``.
        size: (3,) edge lengths along the box's own x, y, z axes, metres.
        position: (3,) centre in the world frame, metres.
        quat_xyzw: (4,) orientation in the world frame, unit quaternion (x, y, z, w).
        body_id: pybullet body unique id in the current simulation.
        mass: kg.
    """

    type_index: int
    size: np.ndarray
    position: np.ndarray
    quat_xyzw: np.ndarray
    body_id: int
    mass: float = 0.0


@dataclass
class HeapResult:
    """The heap after settling: boxes still in the bin, and what it took to get there."""

    boxes: list[BoxPose]
    num_dropped: int
    num_removed: int  # boxes that came to rest outside the bin and were removed
    settle_steps: int  # physics steps from the first drop until rest was declared
    settled: bool  # False when max_settle_steps was reached first


def random_quaternion(rng: np.random.Generator) -> np.ndarray:
    """A uniformly distributed unit quaternion (x, y, z, w) with w ≥ 0."""
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    return q if q[3] >= 0 else -q


_UNIT_CORNERS = np.array(
    [[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], np.float64
)


def box_corners(client: int, body_ids: list[int], half_extents: np.ndarray) -> np.ndarray:
    """(n, 8, 3) world positions of the corners of boxes ``body_ids`` now, metres.

    ``half_extents``: (n, 3) half edge lengths of each box along its own axes.
    """
    states = [p.getBasePositionAndOrientation(b, physicsClientId=client) for b in body_ids]
    pos = np.array([s[0] for s in states], np.float64).reshape(-1, 3)
    R = rotation_matrices(np.array([s[1] for s in states], np.float64).reshape(-1, 4))
    local = _UNIT_CORNERS[None] * np.asarray(half_extents, np.float64)[:, None, :]  # (n, 8, 3)
    return np.einsum("nij,nkj->nki", R, local) + pos[:, None, :]


def _half_extents(client: int, body_ids: list[int]) -> np.ndarray:
    """(n, 3) half extents of each body's (box) collision shape, metres."""
    return (
        np.array(
            [p.getCollisionShapeData(b, -1, physicsClientId=client)[0][3] for b in body_ids],
            np.float64,
        ).reshape(-1, 3)
        / 2.0
    )


def settle(
    client: int,
    body_ids: list[int],
    physics_cfg,
    max_steps: int,
    half_extents: np.ndarray | None = None,
) -> tuple[int, bool]:
    """Step until the boxes ``body_ids`` are at rest: over the last ``rest_window_steps``, no
    corner of any box has been farther than ``rest_corner_displacement`` from where it is now
    (corners sampled every ``rest_check_interval_steps`` steps; corners, not centres, so that a
    box turning about its centre is not at rest).

    A displacement over a window, not a speed at an instant: a box that is slowly tipping over or
    creeping passes a speed threshold at the moment it is checked, but not a displacement
    test over a quarter of a second.

    ``half_extents``: (n, 3) half edge lengths of the box whose corners are watched, per body
    (default: each body's box collision shape); for bodies that are not boxes, any box fixed to
    them (``pipeline.simulation.object_heap`` passes each object's bounding box).

    Returns (steps taken, whether rest was reached within ``max_steps``).
    """
    every = int(physics_cfg.rest_check_interval_steps)
    window = max(1, int(np.ceil(int(physics_cfg.rest_window_steps) / every)))  # checks
    eps2 = float(physics_cfg.rest_corner_displacement) ** 2
    if not body_ids:
        return 0, True
    half = (
        _half_extents(client, body_ids)
        if half_extents is None
        else np.asarray(half_extents, np.float64).reshape(-1, 3)
    )
    history = [box_corners(client, body_ids, half)]
    steps = 0
    while steps < max_steps:
        for _ in range(every):
            p.stepSimulation(physicsClientId=client)
        steps += every
        now = box_corners(client, body_ids, half)
        history.append(now)
        if len(history) > window + 1:
            history.pop(0)
        if (
            len(history) == window + 1
            and max(float(((past - now) ** 2).sum(-1).max()) for past in history[:-1]) < eps2
        ):
            return steps, True
    return steps, False


def corner_drift(client: int, body_ids: list[int], steps: int) -> np.ndarray:
    """Step the simulation ``steps`` times; return each box's largest corner displacement over
    them, (n,) metres. The check that a heap declared at rest is at rest."""
    half = _half_extents(client, body_ids)
    before = box_corners(client, body_ids, half)
    for _ in range(steps):
        p.stepSimulation(physicsClientId=client)
    return np.linalg.norm(box_corners(client, body_ids, half) - before, axis=-1).max(-1)


def drop_area(bin_cfg, physics_cfg) -> tuple[float, float]:
    """Half extents (hx, hy) in metres of the area bodies are dropped over: the bin's inner walls
    (world x = ±inner_length_x / 2, y = ±inner_width_y / 2) less ``physics.drop_margin``; a drop
    position is drawn uniformly from [-hx, hx] × [-hy, hy]."""
    margin = float(physics_cfg.drop_margin)
    return bin_cfg.inner_length_x / 2 - margin, bin_cfg.inner_width_y / 2 - margin


def inside_bin(position: np.ndarray, bin_cfg) -> bool:
    """Whether a body's centre ``position`` (world frame, m; the bin floor's top at z = 0) lies
    inside the bin's inner walls, from just below the floor to 0.1 m above the walls' tops."""
    return (
        abs(position[0]) < bin_cfg.inner_length_x / 2
        and abs(position[1]) < bin_cfg.inner_width_y / 2
        and -0.005 < position[2] < bin_cfg.wall_height + 0.1
    )


def _box_shapes(client: int, size: np.ndarray) -> tuple[int, int]:
    """(collision shape, visual shape) of a box with edge lengths ``size`` (3,), metres."""
    half = (np.asarray(size, np.float64) / 2).tolist()
    return (
        p.createCollisionShape(p.GEOM_BOX, halfExtents=half, physicsClientId=client),
        p.createVisualShape(
            p.GEOM_BOX, halfExtents=half, rgbaColor=[0.8, 0.6, 0.4, 1], physicsClientId=client
        ),
    )


def jittered_size(size: np.ndarray, size_jitter: float, rng: np.random.Generator) -> np.ndarray:
    """A box type's edge lengths (3,), each scaled by its own factor drawn uniformly from
    [1 − size_jitter, 1 + size_jitter]. ``size_jitter`` = 0 returns ``size`` and draws nothing,
    so heaps without jitter use the same random stream as before jitter existed."""
    size = np.asarray(size, np.float64)
    if size_jitter == 0:
        return size.copy()
    if not 0 <= size_jitter < 1:
        raise ValueError(f"size_jitter must be in [0, 1), got {size_jitter}")
    return size * rng.uniform(1.0 - size_jitter, 1.0 + size_jitter, 3)


def drop_heap(
    client: int,
    rng: np.random.Generator,
    boxes_cfg,
    bin_cfg,
    physics_cfg,
    size_jitter: float = 0.0,
    cartons: bool = False,
) -> HeapResult:
    """Drop a random number of random boxes one by one ("trickle"), settle, remove escapees.

    Random draws, in this order: the count, then per box its type, x, y and orientation, and,
    when ``size_jitter`` > 0, its three edge scale factors (``jittered_size``). With ``cartons``
    (``boxes.cartons`` must be set) each box is a carton of that distribution instead
    (``pipeline.simulation.cartons.draw_carton``; type index ``len(types)``), its draws in place
    of the type's; ``size_jitter`` does not apply.
    """
    if cartons and boxes_cfg.cartons is None:
        raise ValueError(
            "cartons were asked for but boxes.cartons is not set: use boxes=cartons "
            "or leave the split out of generate.carton_splits"
        )
    n = int(rng.integers(boxes_cfg.min_count, boxes_cfg.max_count + 1))
    sizes = [np.asarray(t.size, dtype=np.float64) for t in boxes_cfg.types]
    shapes = [_box_shapes(client, size) for size in sizes]
    hx, hy = drop_area(bin_cfg, physics_cfg)
    bodies: list[tuple[int, int]] = []  # (body id, type index)
    body_size: dict[int, np.ndarray] = {}
    body_mass: dict[int, float] = {}
    steps = 0
    for i in range(n):
        if cartons:
            carton = draw_carton(boxes_cfg.cartons, rng)
            k, size, mass = len(sizes), carton.size, carton.mass
        else:
            k = int(rng.integers(len(sizes)))
        x, y = rng.uniform(-hx, hx), rng.uniform(-hy, hy)
        q = random_quaternion(rng)
        if not cartons:  # drawn after the pose, as before cartons existed
            size = jittered_size(sizes[k], size_jitter, rng)
            mass = boxes_cfg.density * float(np.prod(size))
        shape = shapes[k] if not cartons and size_jitter == 0 else _box_shapes(client, size)
        body = p.createMultiBody(
            mass,
            shape[0],
            shape[1],
            basePosition=[x, y, physics_cfg.drop_height_above_bin_floor],
            baseOrientation=q.tolist(),
            physicsClientId=client,
        )
        p.changeDynamics(
            body,
            -1,
            lateralFriction=boxes_cfg.lateral_friction,
            frictionAnchor=int(bool(physics_cfg.friction_anchor)),
            physicsClientId=client,
        )
        bodies.append((body, k))
        body_size[body] = size
        body_mass[body] = float(mass)
        if i < n - 1:
            for _ in range(physics_cfg.drop_interval_steps):
                p.stepSimulation(physicsClientId=client)
            steps += physics_cfg.drop_interval_steps
    ids = [b for b, _ in bodies]
    settle_steps, settled = settle(client, ids, physics_cfg, physics_cfg.max_settle_steps)
    steps += settle_steps

    removed = 0
    for body, _ in list(bodies):
        pos, _ = p.getBasePositionAndOrientation(body, physicsClientId=client)
        if not inside_bin(np.asarray(pos), bin_cfg):
            p.removeBody(body, physicsClientId=client)
            bodies = [(b, k) for b, k in bodies if b != body]
            removed += 1
    if removed and bodies:
        # Removing a box can unsettle a neighbour leaning on it: settle again.
        extra, settled_again = settle(
            client, [b for b, _ in bodies], physics_cfg, physics_cfg.max_settle_steps
        )
        steps += extra
        settled = settled and settled_again

    out = []
    for body, k in bodies:
        pos, quat = p.getBasePositionAndOrientation(body, physicsClientId=client)
        out.append(
            BoxPose(
                type_index=k,
                size=body_size[body].copy(),
                position=np.asarray(pos),
                quat_xyzw=np.asarray(quat),
                body_id=body,
                mass=body_mass[body],
            )
        )
    return HeapResult(
        boxes=out, num_dropped=n, num_removed=removed, settle_steps=steps, settled=settled
    )
