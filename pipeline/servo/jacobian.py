"""From the camera twist to joint motion (paper Eq. 28).

``q_r = ∫ J_c⁻¹ [V; Ω] dt``, with ``J_c`` the robot Jacobian expressed in the camera frame and
``J_c⁻¹`` its (damped) pseudo-inverse.

Frames and units: the twist ``[V; Ω]`` (6,) is the camera frame's origin velocity (m/s) and its
angular velocity (rad/s), both expressed in the camera frame (OpenCV optical frame, the
``camera`` link of :class:`pipeline.robot.model.Robot`); joint vectors are (n,) radians (n = 7:
xArm6 joints 1–6 and the hand tilt ``joint7``, in the order of ``robot.joint_indices``).
"""

from __future__ import annotations

import numpy as np
import pybullet as p


def camera_jacobian(robot, q, T_world_cam: np.ndarray | None = None) -> np.ndarray:
    """``J_c`` (6, n): joint velocities → camera-frame twist ``[V; Ω]`` at joints ``q``.

    pybullet's ``calculateJacobian`` on ``robot.camera_link`` gives the world-frame linear
    velocity of a point of the link and the link's world-frame angular velocity. Its
    ``localPosition`` is relative to the link's centre of mass, so the camera frame's origin is
    passed as ``−R_inertialᵀ p_inertial`` (zero for the current URDF, where the camera link's
    inertial origin is its frame). ``objPositions`` are the positions of all movable joints (the
    robot's 7 revolute joints, in joint-index order = the order of ``q``); velocities and
    accelerations are zero. Both 3-row blocks are then rotated into the camera frame by
    ``R_cam_world = R_world_camᵀ``. The robot is left at ``q``.

    ``T_world_cam``: the camera pose (4, 4) at ``q`` when the caller has it and the robot
    stands at ``q`` already (``robot.camera_pose(q)`` was the last thing to move it); None: it
    is computed here (forward kinematics, which puts the robot at ``q``).
    """
    robot._require_loaded()
    q = np.asarray(q, dtype=np.float64).reshape(-1)
    if q.shape != (len(robot.joint_indices),):
        raise ValueError(f"q must have {len(robot.joint_indices)} entries, got {q.shape}")
    if T_world_cam is None:
        T_world_cam = robot.camera_pose(q)  # sets the joints to q (FK)
    st = p.getLinkState(robot.body_id, robot.camera_link, physicsClientId=robot.client)
    p_in, quat_in = np.asarray(st[2]), st[3]  # inertial frame in the URDF link frame
    R_in = np.asarray(p.getMatrixFromQuaternion(quat_in)).reshape(3, 3)
    local = (-R_in.T @ p_in).tolist()  # the link frame's origin in centre-of-mass coordinates
    zeros = [0.0] * len(q)
    lin, ang = p.calculateJacobian(
        robot.body_id,
        robot.camera_link,
        local,
        q.tolist(),
        zeros,
        zeros,
        physicsClientId=robot.client,
    )
    J_world = np.vstack([np.asarray(lin), np.asarray(ang)])
    if J_world.shape != (6, len(q)):
        raise RuntimeError(
            f"unexpected Jacobian shape {J_world.shape} (fixed-base robot with "
            f"{len(q)} movable joints expected)"
        )
    R_cw = T_world_cam[:3, :3].T
    return np.vstack([R_cw @ J_world[:3], R_cw @ J_world[3:]])


def joint_velocities(J_cam, twist_cam, damping: float = 1e-3) -> np.ndarray:
    """``q̇`` (n,) realising the camera twist (6,) through the damped pseudo-inverse.

    ``q̇ = Jᵀ (J Jᵀ + μ² I₆)⁻¹ [V; Ω]`` with ``μ = damping`` (damped least squares: the
    minimum-norm solution for a full-rank redundant J, bounded near singularities; μ = 0 is the
    Moore–Penrose pseudo-inverse of Eq. 28). Mixed units (m/s and rad/s rows) are taken as they
    are, as in Eq. 28.
    """
    J = np.asarray(J_cam, dtype=np.float64)
    t = np.asarray(twist_cam, dtype=np.float64).reshape(6)
    if J.shape[0] != 6:
        raise ValueError(f"J_cam must be (6, n), got {J.shape}")
    A = J @ J.T + (damping**2) * np.eye(6)
    return J.T @ np.linalg.solve(A, t)


def integrate(robot, q, qdot, dt: float, max_joint_speed: float) -> tuple[np.ndarray, bool]:
    """One Euler step of Eq. 28: ``(q + q̇ dt, clamped)``.

    ``q̇`` is first scaled down as a whole (direction kept) so no joint exceeds
    ``max_joint_speed`` (rad/s); the result is clipped to ``robot.joint_limits``. ``clamped`` is
    True when either the speed scaling or the limit clipping changed the step. The robot itself
    is not moved.
    """
    q = np.asarray(q, dtype=np.float64).reshape(-1)
    qdot = np.asarray(qdot, dtype=np.float64).reshape(-1)
    clamped = False
    peak = float(np.max(np.abs(qdot))) if qdot.size else 0.0
    if peak > max_joint_speed:
        qdot = qdot * (max_joint_speed / peak)
        clamped = True
    q_next = q + qdot * dt
    lo, hi = robot.joint_limits[:, 0], robot.joint_limits[:, 1]
    q_clip = np.clip(q_next, lo, hi)
    if np.any(q_clip != q_next):
        clamped = True
    return q_clip, clamped
