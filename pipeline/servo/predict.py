"""The motion the 2.5D visual servoing will make, predicted without rendering.

The closed loop servos on what the descriptor measures in each new depth image and moves the
joints by the camera Jacobian's damped pseudo-inverse (Eq. 28). For a surface whose centre,
normal and axes are known in the world, the same loop can be run on the exact features instead:
each period the features are computed from the camera pose (forward kinematics), the control
law (:func:`pipeline.servo.control.servo_velocity`) gives the twist, and the joints follow it
exactly as in the closed loop (:mod:`pipeline.servo.jacobian`: same damping, same joint-speed
clamp, same limits). This is the motion the robot will execute up to the descriptor's
measurement noise, joint path included: the 7-joint robot is redundant for the camera pose, so a
motion found by inverse kinematics along the same camera path could differ from the servo's.
2.5D VS does not move the camera along a straight line; on the evaluation's heaps the path from
home bows out by centimetres.

Frames: world (z up); camera poses (4, 4) in the OpenCV optical frame; metres, radians, seconds.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from pipeline.camera.geometry import rotate_back
from pipeline.servo.control import ServoConfig, servo_velocity, warp, warp_rotation
from pipeline.servo.jacobian import camera_jacobian, integrate, joint_velocities

# Consecutive clamped periods after which the closed loop gives up ("joint_limits").
LIMIT_PERIODS = 10


@dataclass
class ServoMotion:
    """Outcome of :func:`servo_motion`.

    Attributes:
        q: (n, 7) joints at each control period, the first being the start, radians.
        poses: n camera poses (4, 4), world, at those joints.
        reason: None when the last goal was reached, else "timeout" (not within the allowed
            periods), "joint_limits" (clamped by the speed or joint limits for
            ``LIMIT_PERIODS`` periods running) or "lost" (the surface centre went behind the
            camera).
    """

    q: np.ndarray
    poses: list
    reason: str | None


def servo_motion(
    robot,
    q_start: np.ndarray,
    centre_w: np.ndarray,
    normal_w: np.ndarray,
    long_w: np.ndarray,
    short_w: np.ndarray,
    pattern: str,
    goals: Sequence[ServoConfig],
    dt: float,
    max_steps: int,
    joint_damping: float,
    max_joint_speed: float,
    reference_x_w: np.ndarray | None = None,
) -> ServoMotion:
    """The servo from joints ``q_start`` (7,) to the last of ``goals``, on exact features.

    Args:
        robot: a loaded ``pipeline.robot.Robot`` (its joints are moved; left at the last q).
        centre_w, normal_w, long_w, short_w: (3,) the surface centre, its normal (towards the
            starting camera) and its in-plane axes, world frame.
        pattern: "L", "R" or "B".
        goals: the servo configurations in order (the approach's first goal, then d*); the
            next one takes over in the period its predecessor converges, as in the closed loop.
        dt: the control period, seconds.
        max_steps: periods before the servo gives up (``servo.timeout_s / dt``).
        joint_damping: μ of the damped pseudo-inverse (``servo.joint_damping``).
        max_joint_speed: rad/s (``motion.max_joint_speed``).
        reference_x_w: (3,) optional, where the hand's X should point (world).
    """
    # The surface, world frame, as floats: each period rotates it into the camera frame with
    # pipeline.camera.geometry's rotate_back, the bits of R.T @ v.
    centre_w, normal_w, long_w, short_w = (
        np.asarray(v, np.float64).reshape(3).tolist() for v in (centre_w, normal_w, long_w, short_w)
    )
    if reference_x_w is not None:
        reference_x_w = np.asarray(reference_x_w, np.float64).reshape(3).tolist()
    q = np.asarray(q_start, np.float64)
    qs, poses = [q], []
    goal, limit_hits = 0, 0
    for step in range(max_steps + 1):
        T = robot.camera_pose(q)
        poses.append(T)
        rows = T[:3].tolist()
        R = [row[:3] for row in rows]
        centre = rotate_back(
            R, (centre_w[0] - rows[0][3], centre_w[1] - rows[1][3], centre_w[2] - rows[2][3])
        )
        if centre[2] <= 1e-3:
            return ServoMotion(np.array(qs), poses, "lost")
        normal = rotate_back(R, normal_w)
        warp_by = warp_rotation(normal)  # one rotation for both axes
        wl, ws = warp(rotate_back(R, long_w), warp_by), warp(rotate_back(R, short_w), warp_by)
        ref = None if reference_x_w is None else rotate_back(R, reference_x_w)
        cmd = servo_velocity(centre, normal, wl, ws, pattern, goals[goal], dt, reference_x=ref)
        if cmd.converged and goal < len(goals) - 1:
            goal += 1
            cmd = servo_velocity(centre, normal, wl, ws, pattern, goals[goal], dt, reference_x=ref)
        if cmd.converged:
            return ServoMotion(np.array(qs), poses, None)
        if step == max_steps:
            break
        # the robot stands at q since camera_pose(q) above: its pose is T
        qdot = joint_velocities(camera_jacobian(robot, q, T), cmd.velocity, joint_damping)
        q, clamped = integrate(robot, q, qdot, dt, max_joint_speed)
        qs.append(q)
        limit_hits = limit_hits + 1 if clamped else 0
        if limit_hits >= LIMIT_PERIODS:
            poses.append(robot.camera_pose(q))
            return ServoMotion(np.array(qs), poses, "joint_limits")
    return ServoMotion(np.array(qs), poses, "timeout")
