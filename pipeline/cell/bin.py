"""The ground and the bin as static pybullet bodies (the cell's known geometry).

World frame: z up, origin at the centre of the bin floor's top surface; metres. The bin's inner
walls are at x = ±inner_length_x/2 and y = ±inner_width_y/2; its floor spans
z ∈ [−floor_thickness, 0] and stands on the ground (top at z = −floor_thickness); the walls rise
to z = wall_height.
"""

from __future__ import annotations

import pybullet as p


def _static_box(client: int, half_extents, position, rgba, friction: float, anchor: bool) -> int:
    col = p.createCollisionShape(p.GEOM_BOX, halfExtents=half_extents, physicsClientId=client)
    vis = p.createVisualShape(
        p.GEOM_BOX, halfExtents=half_extents, rgbaColor=rgba, physicsClientId=client
    )
    body = p.createMultiBody(0.0, col, vis, basePosition=position, physicsClientId=client)
    p.changeDynamics(
        body, -1, lateralFriction=friction, frictionAnchor=int(anchor), physicsClientId=client
    )
    return body


def build_cell(client: int, bin_cfg, physics_cfg) -> list[int]:
    """Reset the simulation and build the ground and the bin.

    Returns their body ids: ``[ground, bin floor, wall −x, wall +x, wall −y, wall +y]``.
    The ground's top surface is at world z = −floor_thickness.
    """
    p.resetSimulation(physicsClientId=client)
    p.setGravity(0, 0, physics_cfg.gravity, physicsClientId=client)
    p.setPhysicsEngineParameter(
        fixedTimeStep=physics_cfg.time_step,
        numSolverIterations=physics_cfg.solver_iterations,
        deterministicOverlappingPairs=1,
        physicsClientId=client,
    )
    t, ft = bin_cfg.wall_thickness, bin_cfg.floor_thickness
    lx, ly, h = bin_cfg.inner_length_x, bin_cfg.inner_width_y, bin_cfg.wall_height
    fr, anchor = bin_cfg.lateral_friction, bool(physics_cfg.friction_anchor)
    blue = [0.2, 0.3, 0.8, 1]
    bodies = [
        # Ground: a collision slab, drawn invisible; the renderer fills its depth analytically
        # (see pipeline.camera.render.render_depth(ground=...)).
        _static_box(client, [1.0, 1.0, 0.01], [0, 0, -ft - 0.01], [1, 1, 1, 0], fr, anchor),
        _static_box(client, [lx / 2 + t, ly / 2 + t, ft / 2], [0, 0, -ft / 2], blue, fr, anchor),
    ]
    wall_z = (h - ft) / 2.0  # walls run from the ground up to h above the bin floor
    half_h = (h + ft) / 2.0
    for sx in (-1, 1):
        bodies.append(
            _static_box(
                client,
                [t / 2, ly / 2 + t, half_h],
                [sx * (lx / 2 + t / 2), 0, wall_z],
                blue,
                fr,
                anchor,
            )
        )
    for sy in (-1, 1):
        bodies.append(
            _static_box(
                client,
                [lx / 2, t / 2, half_h],
                [0, sy * (ly / 2 + t / 2), wall_z],
                blue,
                fr,
                anchor,
            )
        )
    return bodies
