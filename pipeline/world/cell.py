"""The simulated picking cell of the closed-loop evaluation (paper Fig. 1a, Sec. 6): the world.

One headless pybullet world holds the ground, the bin (``pipeline.simulation.heap``), the robot
with its two-cup hand and eye-in-hand depth camera (``pipeline.robot``), and a heap of boxes
dropped into the bin. World frame: z up, origin at the centre of the bin floor's top surface;
metres, kilograms, seconds. Camera frame: OpenCV (x right, y down, z forward).

The robot is position-controlled: its joints are set every control step (``Robot.set_joints``)
and the boxes follow the physics. A held box hangs on a constraint (``pipeline.world.suction``).
The camera renders only the bin and the boxes (a real hand's cups are outside the camera's view
of the surface): the ray-cast renderer is given just those bodies; for pybullet's rasteriser
the robot is moved out of the way for the duration of a render.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pybullet as p

from pipeline.camera.geometry import Intrinsics
from pipeline.camera.render import render_depth
from pipeline.camera.sensor import apply_sensor_model
from pipeline.cell.bin import build_cell
from pipeline.controller.observation import Observation
from pipeline.simulation.heap import drop_heap, settle

_PARKED = [0.0, 0.0, -50.0]  # where the robot waits while the camera renders


@dataclass
class Frame:
    """One camera image with the world's truth. ``depth_m``: (H, W) float32 metres, 0 = no
    data, as the sensor returns it (what the robot gets); ``body_ids``: (H, W) int32 pybullet
    body per pixel (−1 none); ``T_world_cam``: (4, 4) camera pose; ``depth_clean_m``: the
    renderer's ideal depth."""

    depth_m: np.ndarray
    body_ids: np.ndarray
    T_world_cam: np.ndarray
    depth_clean_m: np.ndarray | None = None


class PickCell:
    """Bin, heap and robot in one pybullet client; rendering from the hand camera."""

    def __init__(self, cfg, robot_factory) -> None:
        """``robot_factory()`` returns an unloaded ``pipeline.robot.Robot``."""
        self.cfg = cfg
        self.client = p.connect(p.DIRECT)
        self.intrinsics = Intrinsics.from_config(cfg.camera)
        self.robot = robot_factory()
        self.boxes: dict[int, dict] = {}  # body id → {"mass", "size", "type"}
        self.cell_ids: list[int] = []
        self.sensor_rng: np.random.Generator | None = None  # draws of cfg.sensor's model
        self.last_frame: Frame | None = None  # the truth behind the latest observation
        self.box_shapes: dict = {}  # the ray cast's shapes of this world's bodies (render)

    def reset(self, rng: np.random.Generator, count: int) -> None:
        """New world: the cell, ``count`` boxes of ``eval_boxes`` dropped and settled, the robot
        at home."""
        cfg = self.cfg
        self.box_shapes = {}
        self.cell_ids = build_cell(self.client, cfg.bin, cfg.physics)
        boxes_cfg = _with_count(cfg.eval_boxes, count)
        heap = drop_heap(self.client, rng, boxes_cfg, cfg.bin, cfg.physics)
        self.boxes = {}
        for b in heap.boxes:
            mass = float(p.getDynamicsInfo(b.body_id, -1, physicsClientId=self.client)[0])
            self.boxes[b.body_id] = {
                "mass": mass,
                "size": np.asarray(b.size, np.float64),
                "type": boxes_cfg.types[b.type_index].name,
            }
        self.robot.load(self.client, ground_z=-cfg.bin.floor_thickness)
        self.robot.set_joints(self.robot.home_q())

    @property
    def obstacles(self) -> list[int]:
        """Bodies the robot must not touch (bin parts and boxes; not the ground)."""
        return list(self.cell_ids[1:]) + list(self.boxes)

    def render(self, T_world_cam: np.ndarray | None = None) -> Frame:
        """Depth and body ids from the hand camera (or from ``T_world_cam``)."""
        cid, rid, cam = self.client, self.robot.body_id, self.cfg.camera
        T = self.robot.camera_pose() if T_world_cam is None else T_world_cam
        ground = (-self.cfg.bin.floor_thickness, self.cell_ids[0])
        if cam.renderer == "raycast":  # draws the bin and the boxes only: no need to park
            frame = render_depth(
                cid,
                self.intrinsics,
                T,
                cam.near,
                cam.far,
                ground=ground,
                renderer="raycast",
                bodies=self.obstacles,
                box_cache=self.box_shapes,
            )
        else:
            pos, orn = p.getBasePositionAndOrientation(rid, physicsClientId=cid)
            p.resetBasePositionAndOrientation(rid, _PARKED, orn, physicsClientId=cid)
            try:
                frame = render_depth(
                    cid, self.intrinsics, T, cam.near, cam.far, ground=ground, renderer=cam.renderer
                )
            finally:
                p.resetBasePositionAndOrientation(rid, pos, orn, physicsClientId=cid)
        depth = frame.depth_m
        if self.cfg.sensor.enabled:  # what the camera returns (pipeline.camera.sensor)
            if self.sensor_rng is None:
                raise ValueError(
                    "PickCell.sensor_rng is not set: a sensor model needs a "
                    "generator (PickRunner.run_trial's rng_sensor)"
                )
            depth = apply_sensor_model(depth, self.cfg.sensor, self.sensor_rng, self.intrinsics)
        return Frame(depth, frame.body_ids, T, frame.depth_m)

    def observe(self) -> Observation:
        """What the robot gets from the hand camera now (``pipeline.controller.observation``):
        the sensor's depth, the intrinsics, the camera pose and the joint state. The truth
        behind it (body ids, ideal depth) stays here, in ``last_frame``."""
        frame = self.render()
        self.last_frame = frame
        return Observation(frame.depth_m, self.intrinsics, frame.T_world_cam, self.robot.joints())

    def step(self, seconds: float) -> None:
        """Advance the physics by ``seconds`` (rounded to whole time steps, at least one)."""
        n = max(1, int(round(seconds / self.cfg.physics.time_step)))
        for _ in range(n):
            p.stepSimulation(physicsClientId=self.client)

    def settle(self) -> None:
        if self.boxes:
            settle(
                self.client, list(self.boxes), self.cfg.physics, self.cfg.physics.max_settle_steps
            )

    def remove_box(self, body: int) -> None:
        p.removeBody(body, physicsClientId=self.client)
        self.boxes.pop(body, None)
        self.box_shapes.pop(body, None)

    def boxes_in_bin(self) -> list[int]:
        """Boxes whose centre is inside the bin's walls (others fell out: removed)."""
        b = self.cfg.bin
        inside = []
        for body in list(self.boxes):
            pos, _ = p.getBasePositionAndOrientation(body, physicsClientId=self.client)
            if (
                abs(pos[0]) < b.inner_length_x / 2
                and abs(pos[1]) < b.inner_width_y / 2
                and pos[2] > -0.05
            ):
                inside.append(body)
            else:
                self.remove_box(body)
        return inside

    def box_pose(self, body: int) -> tuple[np.ndarray, np.ndarray]:
        pos, quat = p.getBasePositionAndOrientation(body, physicsClientId=self.client)
        return np.asarray(pos), np.asarray(quat)

    def close(self) -> None:
        if p.isConnected(self.client):
            p.disconnect(self.client)


def _with_count(boxes_cfg, count: int):
    """The box set with min_count = max_count = ``count``."""
    from types import SimpleNamespace

    return SimpleNamespace(
        types=list(boxes_cfg.types),
        density=float(boxes_cfg.density),
        lateral_friction=float(boxes_cfg.lateral_friction),
        min_count=int(count),
        max_count=int(count),
        name=boxes_cfg.name,
    )
