"""Robot-level labelling (paper Sec. 4.3, Fig. 4e): can the whole robot take this grasp?

For a hand-level B, L or R, the target camera pose (``pipeline.robot.target_camera_pose``)
must be reached by inverse kinematics (checked by forward kinematics), within joint limits,
with the arm and hand clear of the ground, the bin and the other boxes. The box being grasped
is not an obstacle (the cups are meant to touch it).

At the paper's target pose (camera d* = 0.15 m from the surface) the cup lips hover 10 mm above
the surface (``pipeline.robot.urdf_builder.CUP_TIP_Z``), so a neighbouring face level with the
target does not count as a collision; one that stands higher under the hand does.

With ``robot.path_check`` (an extension), the motion the robot will execute is checked too: the
2.5D VS from home through the approach's first goal (``motion.approach``) to the target pose,
predicted on the surface with the closed loop's own control law and joint update
(``pipeline.servo.predict``), sampled at most 1 cm and 2° apart (``pipeline.robot.path``); a
motion that fails gives the reasons "path_timeout", "path_joint_limits", "path_lost" or
"path_collision". The same function, :func:`check_grasp`, is the closed loop's run-time check.
"""

from __future__ import annotations

import math
from typing import NamedTuple, Optional

import numpy as np
import pybullet as p

from pipeline.camera.geometry import quat_from_matrix
from pipeline.config.build import from_section
from pipeline.dataset.scenes import Scene
from pipeline.labelling.hand import HandLabel
from pipeline.labelling.types import Surface
from pipeline.robot.approach import first_goal
from pipeline.robot.model import Robot, RobotConfig
from pipeline.robot.path import PathCheckConfig, check_motion
from pipeline.robot.target_pose import hand_rotations, rotate_about, target_camera_pose
from pipeline.robot.urdf_builder import URDF_PATH
from pipeline.servo.control import servo_config
from pipeline.servo.predict import servo_motion
from pipeline.simulation.heap import build_cell


def robot_config(cfg) -> RobotConfig:
    """The ``RobotConfig`` of a composed config (``cfg.robot``; the URDF is the project's)."""
    return from_section(RobotConfig, cfg.robot, urdf_path=str(URDF_PATH),
                        base_position=tuple(cfg.robot.base_position))


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
        self.bin_ids = list(cell[1:])  # bin floor and walls (not the ground)
        self.T_world_cam = scene.T_world_cam
        self._scene = scene

    def check(self, surface: Surface, hand: HandLabel, hand_cfg) -> str | None:
        """None when the robot can take the grasp with one of the hand's rotations about the
        normal (``hand.rotations_deg``, in order; 0 = the paper's axis), else the failed check
        of the paper's rotation (:func:`check_grasp`)."""
        return check_grasp(self.robot, self.cfg, hand_cfg, self.T_world_cam, surface.center_cam,
                           surface.normal_cam, surface.long_axis_cam, surface.short_axis_cam,
                           hand.x_axis_cam, hand.grasp_class.name, self._scene.intrinsics,
                           self.obstacles, [self.box_bodies[surface.instance]],
                           self.bin_ids).reason


class GraspCheck(NamedTuple):
    """Outcome of :func:`check_grasp`.

    Attributes:
        reason: None when the robot can take the grasp, else the failed check: "ik",
            "joint_limits", "collision" (the grasp pose), "path_timeout",
            "path_joint_limits", "path_lost" (the predicted servo) or "path_collision".
        x_world: (3,) the hand's X axis in the world of the rotation that passed (else None).
        path: the predicted servo's camera poses (4, 4) from home, one per control period, of
            the rotation that passed (None without ``robot.path_check``).
    """

    reason: Optional[str]
    x_world: Optional[np.ndarray]
    path: Optional[list]


def path_config(cfg) -> PathCheckConfig | None:
    """The path check's settings, ``cfg.robot.path`` (None when ``robot.path_check`` is off)."""
    return from_section(PathCheckConfig, cfg.robot.path) if bool(cfg.robot.path_check) else None


def check_grasp(robot: Robot, cfg, hand_cfg, T_world_cam: np.ndarray, centre_cam: np.ndarray,
                normal_cam: np.ndarray, long_cam: np.ndarray, short_cam: np.ndarray,
                x_axis_cam: np.ndarray, pattern: str, intrinsics, obstacle_ids, ignore_body_ids,
                bin_ids=()) -> GraspCheck:
    """The robot-level check of a grasp seen from the home camera ``T_world_cam`` (4, 4).

    For each hand rotation about the normal (``hand_cfg.rotations_deg``, in order): the target
    camera pose (the active cup on ``centre_cam``, d* along ``normal_cam``, camera X along
    ``x_axis_cam`` turned by the rotation; home camera frame, metres) must be reached by IK
    from home, in the joint limits, clear of ``obstacle_ids`` except ``ignore_body_ids``
    (:meth:`Robot.solve_ik`). With ``robot.path_check``, so must the motion to it: the 2.5D
    VS from home through ``motion.approach``'s first goal to that pose, predicted on the exact
    surface (``centre_cam``, ``normal_cam``, axes ``long_cam``, ``short_cam``;
    :func:`pipeline.servo.predict.servo_motion`), must converge within ``servo.timeout_s``
    without running into the joint limits, and every sample of its motion
    (:func:`pipeline.robot.path.check_motion`) must be collision-free, keeping
    ``robot.path.bin_clearance`` more from the bodies of ``bin_ids``.

    Returns:
        :class:`GraspCheck` of the first rotation that passes, else the failed check of the
        first rotation. The robot is left at home.
    """
    path_cfg = path_config(cfg)
    home = robot.home_q()
    first = None
    try:
        for rot in hand_rotations(pattern, hand_cfg.rotations_deg):
            x_rot = rotate_about(x_axis_cam, normal_cam, rot)
            grasp = T_world_cam @ target_camera_pose(
                centre_cam, normal_cam, x_rot, pattern, standoff=float(hand_cfg.standoff),
                cup_offset=float(hand_cfg.cup_offset))
            res = robot.solve_ik(grasp, seed_q=home, obstacle_ids=obstacle_ids,
                                 ignore_body_ids=ignore_body_ids)
            reason, poses = res.reason, None
            if reason is None and path_cfg is not None:
                reason, poses = _path_reason(robot, cfg, home, T_world_cam, centre_cam,
                                             normal_cam, long_cam, short_cam, x_rot,
                                             grasp[:3, 0], pattern, intrinsics, path_cfg,
                                             obstacle_ids, ignore_body_ids, bin_ids)
            if reason is None:
                return GraspCheck(None, grasp[:3, 0].copy(), poses)
            first = first or reason
    finally:
        robot.set_joints(home)
    return GraspCheck(first, None, None)


def _path_reason(robot, cfg, home, T_world_cam, centre_cam, normal_cam, long_cam, short_cam,
                 x_cam, x_world, pattern, intrinsics, path_cfg, obstacle_ids, ignore_body_ids,
                 bin_ids):
    """(None when the servo from home, predicted on the exact surface, converges and its motion
    passes, else "path_" + the servo's or the motion check's reason; the predicted camera
    poses)."""
    servo = servo_config(cfg)
    goal, _ = first_goal(servo, cfg, T_world_cam, centre_cam, normal_cam, x_cam, pattern,
                         intrinsics)
    goals = [servo] if goal is servo else [goal, servo]
    dt = 1.0 / float(cfg.servo.control_rate_hz)
    R, t = T_world_cam[:3, :3], T_world_cam[:3, 3]
    motion = servo_motion(robot, home, R @ centre_cam + t, R @ normal_cam, R @ long_cam,
                          R @ short_cam, pattern, goals, dt,
                          int(math.ceil(float(cfg.servo.timeout_s) / dt)),
                          float(cfg.servo.joint_damping), float(cfg.motion.max_joint_speed),
                          x_world)
    if motion.reason is not None:
        return "path_" + motion.reason, motion.poses
    path = check_motion(robot, motion.q, motion.poses, path_cfg, obstacle_ids,
                        ignore_body_ids, bin_ids)
    return (None if path.ok else "path_" + path.reason), motion.poses
