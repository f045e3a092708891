"""Robot-level labelling (paper Sec. 4.3, Fig. 4e): can the whole robot take this grasp?

The labelling stage asks the robot's own check (:func:`pipeline.labelling.grasp_check.check_grasp`:
IK, joint limits, no contact at the target pose and, with ``robot.path_check``, along the
servo's predicted motion) with the heap's true boxes as the obstacles: the labels are made in
simulation, where the truth is known (the paper's robot-level labels). The box being grasped is
not an obstacle (the cups are meant to touch it).
"""

from __future__ import annotations

import pybullet as p

from pipeline.cell.bin import build_cell
from pipeline.dataset.scenes import Scene
from pipeline.grasping.hand import HandLabel
from pipeline.grasping.types import Surface
from pipeline.labelling.grasp_check import check_grasp
from pipeline.robot.model import Robot, robot_config
from pipeline.simulation.scene import collision_box


class RobotChecker:
    """Holds a headless pybullet world with the robot, rebuilt for each scene."""

    def __init__(self, cfg) -> None:
        self.cfg = cfg
        self.client = p.connect(p.DIRECT)
        self.robot = Robot(robot_config(cfg))
        self._scene = None

    def set_scene(self, scene: Scene, bin_cfg=None) -> None:
        """Rebuild the cell with the scene's boxes as static obstacles at their true poses.

        ``bin_cfg``: the bin the scene was generated with (``SceneDataset.bin``); defaults to
        the pipeline config's ``bin``.
        """
        cfg = self.cfg
        bin_cfg = bin_cfg or cfg.bin
        cell = build_cell(self.client, bin_cfg, cfg.physics)
        self.box_bodies: dict[int, int] = {}
        for box in scene.boxes:
            self.box_bodies[box.instance] = collision_box(self.client, box.size, box.T_world_box)
        self.robot.load(self.client, ground_z=-bin_cfg.floor_thickness)
        self.obstacles = list(cell) + list(self.box_bodies.values())
        self.bin_ids = list(cell[1:])  # bin floor and walls (not the ground)
        self.T_world_cam = scene.T_world_cam
        self._scene = scene

    def check(self, surface: Surface, hand: HandLabel, hand_cfg) -> str | None:
        """None when the robot can take the grasp with one of the hand's rotations about the
        normal (``hand.rotations_deg``, in order; 0 = the paper's axis), else the failed check
        of the paper's rotation (:func:`check_grasp`)."""
        return check_grasp(
            self.robot,
            self.cfg,
            hand_cfg,
            self.T_world_cam,
            surface.center_cam,
            surface.normal_cam,
            surface.long_axis_cam,
            surface.short_axis_cam,
            hand.x_axis_cam,
            hand.grasp_class.name,
            self._scene.intrinsics,
            self.obstacles,
            [self.box_bodies[surface.instance]],
            self.bin_ids,
        ).reason
