"""Robot-level labelling (paper Sec. 4.3, Fig. 4e): can the whole robot take this grasp?

For a hand-level B, L or R, the target camera pose (``pipeline.robot.target_camera_pose``)
must be reached by inverse kinematics (checked by forward kinematics), within joint limits,
with the arm and hand clear of the ground, the bin and the other boxes. The box being grasped
is not an obstacle (the cups are meant to touch it).

At the paper's target pose (camera d* = 0.15 m from the surface) the cup lips hover 10 mm above
the surface (``pipeline.robot.urdf_builder.CUP_TIP_Z``), so a neighbouring face level with the
target does not count as a collision; one that stands higher under the hand does.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pybullet as p

from pipeline.camera.geometry import quat_from_matrix
from pipeline.dataset.scenes import Scene
from pipeline.labelling.hand import HandLabel
from pipeline.labelling.types import Surface
from pipeline.robot.model import Robot, RobotConfig
from pipeline.robot.target_pose import hand_rotations, rotate_about, target_camera_pose
from pipeline.simulation.heap import build_cell


def robot_config(cfg) -> RobotConfig:
    """The ``RobotConfig`` for a pipeline config (``cfg.robot`` overrides the defaults)."""
    robot_cfg = getattr(cfg, "robot", None)
    if robot_cfg is None:
        return RobotConfig()
    values = {f.name: getattr(robot_cfg, f.name) for f in dataclasses.fields(RobotConfig)
              if hasattr(robot_cfg, f.name)}
    if "base_position" in values:
        values["base_position"] = tuple(values["base_position"])
    return RobotConfig(**values)


class RobotChecker:
    """Holds a headless pybullet world with the robot, rebuilt for each scene."""

    def __init__(self, cfg) -> None:
        from pipeline.robot import urdf_builder

        built = (urdf_builder.CUP_DIAMETER, urdf_builder.CUP_OFFSET)
        if not np.allclose(built, (cfg.hand.cup_diameter, cfg.hand.cup_offset)):
            raise ValueError(
                f"hand config (cup_diameter={cfg.hand.cup_diameter}, cup_offset="
                f"{cfg.hand.cup_offset}) differs from the robot URDF's cups {built}: change "
                "pipeline/robot/urdf_builder.py to match and run `python -m "
                "pipeline.robot.urdf_builder`, or keep conf/hand/two_cup.yaml as it is")
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
            half = (np.asarray(box.size) / 2).tolist()
            col = p.createCollisionShape(p.GEOM_BOX, halfExtents=half, physicsClientId=self.client)
            T = box.T_world_box
            body = p.createMultiBody(0.0, col, -1, basePosition=T[:3, 3].tolist(),
                                     baseOrientation=quat_from_matrix(T[:3, :3]).tolist(),
                                     physicsClientId=self.client)
            self.box_bodies[box.instance] = body
        self.robot.load(self.client, ground_z=-bin_cfg.floor_thickness)
        self.obstacles = list(cell) + list(self.box_bodies.values())
        self.T_world_cam = scene.T_world_cam
        self._scene = scene

    def check(self, surface: Surface, hand: HandLabel, hand_cfg) -> str | None:
        """None when the robot can take the grasp with one of the hand's rotations about the
        normal (``hand.rotations_deg``, in order; 0 = the paper's axis), else the failed check
        of the paper's rotation: "ik", "joint_limits" or "collision"."""
        first = None
        for rot in hand_rotations(hand.grasp_class.name, hand_cfg.rotations_deg):
            x_axis = rotate_about(hand.x_axis_cam, surface.normal_cam, rot)
            T_cam0_target = target_camera_pose(
                surface.center_cam, surface.normal_cam, x_axis, hand.grasp_class.name,
                standoff=hand_cfg.standoff,
                cup_offset=hand_cfg.cup_offset)
            result = self.robot.solve_ik(self.T_world_cam @ T_cam0_target,
                                         seed_q=self.robot.home_q(),
                                         obstacle_ids=self.obstacles,
                                         ignore_body_ids=[self.box_bodies[surface.instance]])
            if result.reason is None:
                return None
            first = first or result.reason
        return first
