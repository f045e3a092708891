"""Simulator knowledge for the robot: the "truth" heap model of the ablation, and nothing else.

``evaluate.collision_model: truth`` (the ablation row ``simulator_knowledge``; never the
default) gives the robot's run-time check the heap's true boxes instead of its model from depth
(``pipeline.controller.heap_model``): every box at its true pose, the hidden ones under the
visible surface included, as static bodies in the check's own client, and the box under the
candidate pixel (from the simulator's body-id image) left out as the grasped one. A real cell
has none of this; the row shows what the knowledge is worth. It plugs into the robot side
through ``pipeline.controller.check.CollisionModel``, so the controller never imports the world.
"""

from __future__ import annotations

import contextlib

import pybullet as p

from pipeline.controller.observation import Observation
from pipeline.simulation.scene import collision_box


class TruthHeap:
    """A ``CollisionModel`` of the world cell's true boxes (module docstring)."""

    def __init__(self, client: int, cell) -> None:
        """``client``: the robot side's check client; ``cell``: the world
        (``pipeline.world.cell.PickCell``)."""
        self.client, self.cell = client, cell
        self.mirror: dict[int, int] = {}  # world body → body in the check's client

    def clear(self) -> None:
        for b in self.mirror.values():
            p.removeBody(b, physicsClientId=self.client)
        self.mirror = {}

    def update(self, obs: Observation) -> None:
        from pipeline.camera.geometry import pose_matrix

        self.clear()
        for body, info in self.cell.boxes.items():
            T = pose_matrix(*self.cell.box_pose(body))
            self.mirror[body] = collision_box(self.client, info["size"], T)

    @contextlib.contextmanager
    def excluding(self, obs: Observation, uv, region, plane=None):
        ids = self.cell.last_frame.body_ids
        r, c = int(round(uv[1])), int(round(uv[0]))
        target = int(ids[r, c]) if 0 <= r < ids.shape[0] and 0 <= c < ids.shape[1] else -1
        ignore = [self.mirror[target]] if target in self.mirror else []
        yield list(self.mirror.values()), ignore
