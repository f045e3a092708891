"""The robot-level check of a grasp (paper Sec. 4.3, Fig. 4e): can the whole robot take it?

For a hand-level B, L or R, the target camera pose (``pipeline.robot.target_camera_pose``)
must be reached by inverse kinematics (checked by forward kinematics), within joint limits,
with the arm and hand clear of the ground, the bin and the obstacles the caller gives. The box
being grasped is not an obstacle (the cups are meant to touch it).

At the paper's target pose (camera d* = 0.15 m from the surface) the cup lips hover 10 mm above
the surface (``pipeline.robot.urdf_builder.CUP_TIP_Z``), so a neighbouring face level with the
target does not count as a collision; one that stands higher under the hand does.

With ``robot.path_check`` (an extension), the motion the robot will execute is checked too: the
2.5D VS from home through the approach's first goal (``motion.approach``) to the target pose,
predicted on the surface with the closed loop's own control law and joint update
(``pipeline.servo.predict``), sampled at most 1 cm and 2° apart (``pipeline.robot.path``); a
motion that fails gives the reasons "path_timeout", "path_joint_limits", "path_lost" or
"path_collision".

One function, :func:`check_grasp`, serves both sides: the labelling stage checks against the
heap's true boxes (``pipeline.labelling.robot_check.RobotChecker``), the closed loop against its
own model of the heap from the depth image (``pipeline.controller.check``).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from pipeline.robot.approach import first_goal
from pipeline.robot.model import Robot
from pipeline.robot.path import check_motion, path_config
from pipeline.robot.target_pose import hand_rotations, rotate_about, target_camera_pose
from pipeline.robot.urdf_builder import CUP_TIP_Z
from pipeline.servo.control import servo_config
from pipeline.servo.predict import servo_motion


class GraspCheck(NamedTuple):
    """Outcome of :func:`check_grasp`.

    Attributes:
        reason: None when the robot can take the grasp, else the failed check: "ik",
            "joint_limits", "collision" (the grasp pose), "press" (the final press along the
            camera's axis touches the bin), "path_timeout", "path_joint_limits", "path_lost"
            (the predicted servo) or "path_collision".
        x_world: (3,) the hand's X axis in the world of the rotation that passed (else None).
        path: the predicted servo's camera poses (4, 4) from home, one per control period, of
            the rotation that passed (None without ``robot.path_check``).
    """

    reason: str | None
    x_world: np.ndarray | None
    path: list | None


def check_grasp(
    robot: Robot,
    cfg,
    hand_cfg,
    T_world_cam: np.ndarray,
    centre_cam: np.ndarray,
    normal_cam: np.ndarray,
    long_cam: np.ndarray,
    short_cam: np.ndarray,
    x_axis_cam: np.ndarray,
    pattern: str,
    intrinsics,
    obstacle_ids,
    ignore_body_ids,
    bin_ids=(),
    bin_clearances: Sequence[float | None] = (None,),
) -> GraspCheck:
    """The robot-level check of a grasp seen from the home camera ``T_world_cam`` (4, 4).

    For each hand rotation about the normal (``hand_cfg.rotations_deg``, in order): the target
    camera pose (the active cup on ``centre_cam``, d* along ``normal_cam``, camera X along
    ``x_axis_cam`` turned by the rotation; home camera frame, metres) must be reached by IK
    from home, in the joint limits, clear of ``obstacle_ids`` except ``ignore_body_ids``
    (:meth:`Robot.solve_ik`), and the final press from it along the camera's axis must end
    clear of the bin with every link but the cups (:func:`press_reason`). With
    ``robot.path_check``, so must the motion to it: the 2.5D
    VS from home through ``motion.approach``'s first goal to that pose, predicted on the exact
    surface (``centre_cam``, ``normal_cam``, axes ``long_cam``, ``short_cam``;
    :func:`pipeline.servo.predict.servo_motion`), must converge within ``servo.timeout_s``
    without running into the joint limits, and every sample of its motion
    (:func:`pipeline.robot.path.check_motion`) must be collision-free, keeping a clearance more
    from the bodies of ``bin_ids``.

    ``bin_clearances``: the clearances (m; None: ``robot.path.bin_clearance``) tried in turn,
    each over every rotation; the first (clearance, rotation) that passes is the answer. Only
    the motion check depends on the clearance, so each rotation's IK, press and predicted
    motion are worked out once, and a motion that failed on an obstacle other than the bin
    (which no smaller clearance changes) is not checked again.

    ``robot`` is a loaded :class:`pipeline.robot.Robot` in a client whose ``obstacle_ids`` are
    what the caller knows of the surroundings: the labelling stage passes the heap's true boxes,
    the closed loop a heap model built from its depth image
    (``pipeline.controller.heap_model``).

    Returns:
        :class:`GraspCheck` of the first clearance and rotation that pass, else the failed
        check of the first rotation at the last clearance. The robot is left at home.
    """
    base_path_cfg = path_config(cfg)
    home = robot.home_q()
    surface_cam = (centre_cam, normal_cam, long_cam, short_cam)
    bodies = (obstacle_ids, ignore_body_ids, bin_ids)
    rotations = hand_rotations(pattern, hand_cfg.rotations_deg)
    # per rotation: (grasp pose, the reason before the motion check or None, the motion)
    found: dict[int, tuple] = {}
    # per rotation: the reason of a motion check that failed on the obstacles, not the bin
    blocked: dict[int, str] = {}
    first = None
    try:
        for clearance in bin_clearances:
            path_cfg = base_path_cfg
            if path_cfg is not None and clearance is not None:
                path_cfg = dataclasses.replace(path_cfg, bin_clearance=float(clearance))
            first = None
            for i, rot in enumerate(rotations):
                if i not in found:
                    x_rot = rotate_about(x_axis_cam, normal_cam, rot)
                    found[i] = _pose_and_motion(
                        robot, cfg, hand_cfg, home, T_world_cam, surface_cam, x_rot, pattern,
                        intrinsics, path_cfg is not None, bodies,
                    )  # fmt: skip
                grasp, reason, motion = found[i]
                poses = None if motion is None else motion.poses
                if reason is None and path_cfg is not None:
                    reason = blocked.get(i)
                    if reason is None:
                        path = check_motion(robot, motion.q, motion.poses, path_cfg, *bodies)
                        if not path.ok:
                            reason = "path_" + path.reason
                            if not path.padded:
                                blocked[i] = reason
                if reason is None:
                    return GraspCheck(None, grasp[:3, 0].copy(), poses)
                first = first or reason
    finally:
        robot.set_joints(home)
    return GraspCheck(first, None, None)


def _pose_and_motion(
    robot, cfg, hand_cfg, home, T_world_cam, surface_cam, x_rot, pattern, intrinsics, with_path,
    bodies,
):  # fmt: skip
    """For one hand rotation of :func:`check_grasp`, the hand's X ``x_rot`` (home camera
    frame): (the target camera pose (4, 4) world, None or the failed check before the motion
    check: "ik", "joint_limits", "collision", "press", or "path_" + the servo prediction's
    reason; the predicted motion, :class:`pipeline.servo.predict.ServoMotion`, or None when
    not predicted)."""
    obstacle_ids, ignore_body_ids, bin_ids = bodies
    centre_cam, normal_cam = surface_cam[0], surface_cam[1]
    grasp = T_world_cam @ target_camera_pose(
        centre_cam,
        normal_cam,
        x_rot,
        pattern,
        standoff=float(hand_cfg.standoff),
        cup_offset=float(hand_cfg.cup_offset),
    )
    res = robot.solve_ik(
        grasp, seed_q=home, obstacle_ids=obstacle_ids, ignore_body_ids=ignore_body_ids
    )
    reason, motion = res.reason, None
    if reason is None:
        reason = press_reason(robot, grasp, res.q, hand_cfg, cfg, bin_ids)
    if reason is None and with_path:
        motion = _predicted_motion(
            robot, cfg, home, T_world_cam, surface_cam, x_rot, grasp[:3, 0], pattern, intrinsics
        )
        if motion.reason is not None:
            reason = "path_" + motion.reason
    return grasp, reason, motion


def press_reason(
    robot, grasp: np.ndarray, q_grasp: np.ndarray, hand_cfg, cfg, bin_ids
) -> str | None:
    """None when the final press (from the grasp pose ``grasp``, (4, 4) world, along the camera's
    axis until the lips touch the surface and press ``motion.press_depth``) ends clear of the
    bin ``bin_ids`` with every link but the cups, which are meant to touch; else "press". The
    closed loop judges that approach so (a protective stop), and a grasp pose that clears a wall
    by the margin can still reach it along a tilted axis."""
    travel = float(hand_cfg.standoff) - CUP_TIP_Z + float(cfg.motion.press_depth)
    pressed = grasp.copy()
    pressed[:3, 3] += travel * grasp[:3, 2]
    res = robot.solve_ik(pressed, seed_q=q_grasp, obstacle_ids=())
    if res.reason is not None:
        return "press"
    hits = [
        c
        for c in robot.in_collision(res.q, list(bin_ids), self_collision=False)
        if not c.robot_link.startswith("cup")
    ]
    return "press" if hits else None


def _predicted_motion(
    robot: Robot,
    cfg,
    home: np.ndarray,
    T_world_cam: np.ndarray,
    surface_cam: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    x_cam: np.ndarray,
    x_world: np.ndarray,
    pattern: str,
    intrinsics,
):
    """The servo from home, predicted on the exact surface
    (:class:`pipeline.servo.predict.ServoMotion`: its joints, camera poses and reason, None when
    it converges). ``surface_cam``: :func:`check_grasp`'s (centre, normal, long axis, short
    axis), (3,) each, home camera frame, m; ``x_cam`` (home camera frame) and ``x_world`` the
    hand's X axis of the rotation checked."""
    centre_cam, normal_cam, long_cam, short_cam = surface_cam
    servo = servo_config(cfg)
    goal, _ = first_goal(
        servo, cfg, T_world_cam, centre_cam, normal_cam, x_cam, pattern, intrinsics
    )
    goals = [servo] if goal is servo else [goal, servo]
    dt = 1.0 / float(cfg.servo.control_rate_hz)
    R, t = T_world_cam[:3, :3], T_world_cam[:3, 3]
    return servo_motion(
        robot,
        home,
        R @ centre_cam + t,
        R @ normal_cam,
        R @ long_cam,
        R @ short_cam,
        pattern,
        goals,
        dt,
        int(math.ceil(float(cfg.servo.timeout_s) / dt)),
        float(cfg.servo.joint_damping),
        float(cfg.motion.max_joint_speed),
        x_world,
    )
