"""2.5D visual servoing (paper Sec. 5.2, Eqs. 15–28): the control law and the camera Jacobian.

Camera frame: OpenCV (x right, y down, z forward), metres, radians. The surface normals passed
to the law point towards the camera (project convention).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pybullet as p
import pytest
from conftest import default_config

from pipeline.robot.model import Robot, RobotConfig
from pipeline.robot.target_pose import target_camera_pose
from pipeline.servo.control import (
    ServoConfig,
    clamp_twist,
    current_features,
    interaction_matrix,
    rotation_error,
    servo_velocity,
    target_features,
    warp_axis,
)
from pipeline.servo.jacobian import camera_jacobian, integrate, joint_velocities

DT = 1.0 / 30.0
D_STAR = 0.15
X_AXIS, Y_AXIS = np.array([1.0, 0, 0]), np.array([0, 1.0, 0])
FACING = np.array([0, 0, -1.0])  # a fronto-parallel surface's normal, towards the camera
SERVO = default_config(ServoConfig)  # conf/servo/paper.yaml, d* and cup offset from conf/hand/


# ----------------------------------------------------------------------------- so(3) helpers
def _skew(w):
    return np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])


def _exp(w):
    """Rodrigues: rotation matrix of the rotation vector w."""
    th = np.linalg.norm(w)
    if th < 1e-15:
        return np.eye(3)
    K = _skew(w / th)
    return np.eye(3) + math.sin(th) * K + (1 - math.cos(th)) * K @ K


def _log(R):
    """Rotation vector of R (angles < π)."""
    c = np.clip((np.trace(R) - 1) / 2, -1, 1)
    v = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]]) / 2
    s = np.linalg.norm(v)
    th = math.atan2(s, c)
    return v * (th / s) if s > 1e-15 else v


def _in_plane(deg):
    a = math.radians(deg)
    return np.array([math.cos(a), math.sin(a), 0.0])


# ----------------------------------------------------------------------------- features
def test_target_features_follow_eq_17_18():
    cfg = SERVO
    # p_e* = [0, off/d*, log d*], off = -0.035 (L), 0 (B), +0.035 (R).
    for pattern, off in (("L", -0.035), ("B", 0.0), ("R", 0.035)):
        np.testing.assert_allclose(
            target_features(pattern, cfg), [0, off / 0.15, math.log(0.15)], atol=1e-15
        )
    np.testing.assert_allclose(current_features([0.03, -0.06, 0.3]), [0.1, -0.2, math.log(0.3)])


def test_target_features_match_the_target_camera_pose():
    # At target_camera_pose(...) the surface centre must have exactly the features p_e*.
    c, n = np.array([0.1, -0.05, 0.5]), np.array([0.2, -0.1, -1.0])
    for pattern in "LBR":
        T = target_camera_pose(c, n, X_AXIS, pattern)
        c_t = T[:3, :3].T @ (c - T[:3, 3])
        np.testing.assert_allclose(
            current_features(c_t), target_features(pattern, SERVO), atol=1e-12
        )


# ----------------------------------------------------------------------------- control law
@pytest.mark.parametrize("pattern,off", [("L", -0.035), ("B", 0.0), ("R", 0.035)])
def test_zero_velocity_at_the_target(pattern, off):
    cmd = servo_velocity([0, off, D_STAR], FACING, X_AXIS, Y_AXIS, pattern, SERVO, DT)
    np.testing.assert_allclose(cmd.error, 0, atol=1e-12)
    np.testing.assert_allclose(cmd.velocity, 0, atol=1e-12)
    assert cmd.converged


def test_lateral_offset_moves_the_camera_towards_the_centre():
    # Centre (0.02, 0, 0.15), B: x = 0.02/0.15, y = 0, log Z = log d*, uθ = 0, so
    # e = [0.1333, 0, 0, 0, 0, 0]. With L_v⁻¹ = [[-1, 0, -x], [0, -1, -y], [0, 0, -1]]:
    # V = -λ' Z L_v⁻¹ e_p = -λ' 0.15 [-0.1333, 0, 0] = [λ' 0.02, 0, 0] = X λ',
    # λ' = 0.4 / (1/30) = 12 per second → V = (0.24, 0, 0) m/s, Ω = 0 (under the speed limits).
    cmd = servo_velocity([0.02, 0, D_STAR], FACING, X_AXIS, Y_AXIS, "B", SERVO, DT)
    np.testing.assert_allclose(cmd.velocity, [0.24, 0, 0, 0, 0, 0], atol=1e-12)
    assert cmd.velocity[0] > 0 and not cmd.converged
    assert cmd.scale == 1.0


def test_far_centre_moves_the_camera_forward():
    # Centre (0, 0, 0.30), B: e = [0, 0, log 2, 0, 0, 0]; V = -λ Z L_v⁻¹ e_p = (0, 0, λ 0.3 log 2).
    # Continuous gain λ = 0.4/s: V_z = 0.4 · 0.3 · 0.6931 = 0.08318 m/s.
    cfg = dataclasses.replace(SERVO, gain_per_step=False)
    cmd = servo_velocity([0, 0, 0.30], FACING, X_AXIS, Y_AXIS, "B", cfg)
    np.testing.assert_allclose(cmd.velocity, [0, 0, 0.4 * 0.3 * math.log(2), 0, 0, 0], atol=1e-12)
    assert cmd.velocity[2] > 0


def test_rotation_is_compensated_by_translation():
    # Centre on the axis at d*, B, surface tilted α = 10° about camera y (away normal
    # n = (sin α, 0, cos α)): uθ = (0, -α, 0) and, at x = y = 0, L_w uθ = (α, 0, 0), so
    # Ω = -λ uθ = (0, λα, 0) and V = -λ Z L_v⁻¹ (0 - L_w uθ) = (-λ Z α, 0, 0):
    # rotating about +y moves the centre to -x in the image (Ṗ = -Ω × P = (-λαZ, 0, 0)),
    # which V_x = -λαZ cancels.
    a = math.radians(10)
    n_towards = -np.array([math.sin(a), 0, math.cos(a)])
    cfg = dataclasses.replace(SERVO, gain_per_step=False)
    cmd = servo_velocity([0, 0, D_STAR], n_towards, X_AXIS, Y_AXIS, "B", cfg)
    np.testing.assert_allclose(cmd.velocity, [-0.4 * D_STAR * a, 0, 0, 0, 0.4 * a, 0], atol=1e-12)


def test_gain_per_step_needs_dt():
    with pytest.raises(ValueError):
        servo_velocity([0, 0, 0.2], FACING, X_AXIS, Y_AXIS, "B", SERVO)
    with pytest.raises(ValueError):
        servo_velocity([0, 0, 0.2], FACING, X_AXIS, Y_AXIS, "NG", SERVO, DT)


# ----------------------------------------------------------------------------- u theta
def test_u_theta_of_a_tilted_normal():
    # Away normal n = R_y(10°) z = (sin 10°, 0, cos 10°); n × n_Z = (0, -sin 10°, 0), so the
    # unit axis is -y and uθ = (0, -10° in rad, 0). Ω = -λ uθ is about +y, which turns the
    # camera's z towards +x, i.e. towards n.
    a = math.radians(10)
    n = np.array([math.sin(a), 0, math.cos(a)])
    u = rotation_error(-n, X_AXIS, Y_AXIS)
    np.testing.assert_allclose(u, [0, -a, 0], atol=1e-12)
    z_after = _exp(-0.1 * u) @ np.array([0, 0, 1.0])
    assert z_after @ n > math.cos(a)


def test_u_theta_of_a_rotated_long_axis():
    # ñ_l at 30° about Z from X: ñ_l × n_X = (0, 0, -sin 30°) → uθ = (0, 0, -30° in rad).
    # Ω = -λ uθ is about +z, turning X (towards +y) onto the axis.
    a = math.radians(30)
    u = rotation_error(FACING, _in_plane(30), _in_plane(120))
    np.testing.assert_allclose(u, [0, 0, -a], atol=1e-12)
    x_after = _exp(-0.1 * u) @ X_AXIS
    assert x_after @ _in_plane(30) > math.cos(a)


def test_u_theta_treats_axes_as_lines():
    # A long axis pointing at 170° is the line at -10° (350°): same error, uθ_z = +10° in rad
    # (the short axis at 80° / 260° is farther from X, 80°).
    ref = rotation_error(FACING, _in_plane(350), _in_plane(80))
    np.testing.assert_allclose(ref, [0, 0, math.radians(10)], atol=1e-12)
    np.testing.assert_allclose(
        rotation_error(FACING, _in_plane(170), _in_plane(260)), ref, atol=1e-12
    )
    # The short axis wins when its line is nearer: long at 60°, short at 150° (= -30°) → +30°.
    np.testing.assert_allclose(
        rotation_error(FACING, _in_plane(60), _in_plane(150)), [0, 0, math.radians(30)], atol=1e-12
    )
    # Lengths do not matter.
    np.testing.assert_allclose(
        rotation_error(FACING, 3 * _in_plane(350), 0.2 * _in_plane(80)), ref, atol=1e-12
    )


def test_warp_axis_brings_in_surface_axes_to_the_image_plane():
    # Surface tilted 20° about camera y: its in-plane axis (cos 20°, 0, -sin 20°) (⊥ the away
    # normal (sin 20°, 0, cos 20°)) warps to X; the other in-plane axis, y, stays y.
    a = math.radians(20)
    n_towards = -np.array([math.sin(a), 0, math.cos(a)])
    np.testing.assert_allclose(
        warp_axis([math.cos(a), 0, -math.sin(a)], n_towards), X_AXIS, atol=1e-12
    )
    np.testing.assert_allclose(warp_axis(Y_AXIS, n_towards), Y_AXIS, atol=1e-12)
    np.testing.assert_allclose(warp_axis(_in_plane(40), FACING), _in_plane(40), atol=1e-12)


# ----------------------------------------------------------------------------- M and clamp
def test_interaction_matrix_and_its_inverse_at_the_centre():
    # x = y = 0, Z = d* (ρ = 1): L_v = -I, L_w = [[0, -1, 0], [1, 0, 0], [0, 0, 0]],
    # M = [[-I/d*, L_w], [0, I]] and M⁻¹ = [[-d* I, d* L_w], [0, I]]
    # (check: (-I/d*)(d* L_w) + L_w = 0).
    L_w = np.array([[0, -1.0, 0], [1, 0, 0], [0, 0, 0]])
    M = interaction_matrix([0, 0, math.log(D_STAR)], D_STAR, SERVO)
    M_expected = np.block([[-np.eye(3) / D_STAR, L_w], [np.zeros((3, 3)), np.eye(3)]])
    np.testing.assert_allclose(M, M_expected, atol=1e-12)
    M_inv = np.block([[-D_STAR * np.eye(3), D_STAR * L_w], [np.zeros((3, 3)), np.eye(3)]])
    np.testing.assert_allclose(np.linalg.inv(M), M_inv, atol=1e-12)


def test_speed_clamp_keeps_the_direction():
    cfg = SERVO
    # Centre (0, 0, 0.30), B, per-step gain: V_z = 12 · 0.3 · log 2 = 2.495 m/s > 0.5.
    cmd = servo_velocity([0, 0, 0.30], FACING, X_AXIS, Y_AXIS, "B", cfg, DT)
    assert cmd.raw_velocity[2] == pytest.approx(12 * 0.3 * math.log(2))
    assert cmd.linear_speed == pytest.approx(0.5)
    np.testing.assert_allclose(cmd.velocity, cmd.raw_velocity * cmd.scale)
    # Uniform clamp: one factor for V and Ω (their ratio is kept).
    twist = np.array([1.0, -2.0, 0.5, 0.3, 3.0, -1.0])
    out, s = clamp_twist(twist, cfg)
    np.testing.assert_allclose(out, twist * s)
    assert s == pytest.approx(min(0.5 / np.linalg.norm(twist[:3]), 1.5 / np.linalg.norm(twist[3:])))
    # Separate clamp: each part at its limit, each keeping its direction.
    out, _ = clamp_twist(twist, dataclasses.replace(SERVO, uniform_clamp=False))
    assert np.linalg.norm(out[:3]) == pytest.approx(0.5)
    assert np.linalg.norm(out[3:]) == pytest.approx(1.5)
    np.testing.assert_allclose(np.cross(out[:3], twist[:3]), 0, atol=1e-12)
    np.testing.assert_allclose(np.cross(out[3:], twist[3:]), 0, atol=1e-12)
    assert out[:3] @ twist[:3] > 0 and out[3:] @ twist[3:] > 0


# ----------------------------------------------------------------------------- closed loop
def test_kinematic_camera_converges():
    """A free-flying camera integrating the commanded twist reaches the L target pose."""
    cfg = SERVO
    c_w = np.array([0.05, -0.02, 0.1])  # surface centre, world
    n_w = np.array([0.0, 0.0, 1.0])  # surface normal towards the camera (facing up)
    long_w = np.array([math.cos(0.4), math.sin(0.4), 0.0])
    short_w = np.cross(n_w, long_w)
    # Start: centre on the optical axis 0.35 m away (0.2 m beyond d*), the optical axis 15°
    # off the normal, camera x 20° off the long axis (about the normal).
    z0 = _exp(np.radians(15) * np.array([1.0, 0.3, 0]) / np.hypot(1, 0.3)) @ -n_w
    x0 = _exp(-n_w * math.radians(20)) @ long_w
    x0 = x0 - (x0 @ z0) * z0
    x0 /= np.linalg.norm(x0)
    R = np.column_stack([x0, np.cross(z0, x0), z0])
    t = c_w - 0.35 * z0
    errors, converged_at = [], None
    for k in range(60):
        center = R.T @ (c_w - t)
        normal = R.T @ n_w
        cmd = servo_velocity(
            center,
            normal,
            warp_axis(R.T @ long_w, normal),
            warp_axis(R.T @ short_w, normal),
            "L",
            cfg,
            DT,
        )
        errors.append(np.linalg.norm(cmd.error))
        if cmd.converged:
            converged_at = k
            break
        t = t + R @ cmd.velocity[:3] * DT
        R = R @ _exp(cmd.velocity[3:] * DT)
    print(f"converged after {converged_at} steps; |e|: {np.round(errors, 4).tolist()}")
    assert converged_at is not None and converged_at <= 40, (converged_at, errors[-3:])
    assert all(b <= a + 1e-9 for a, b in zip(errors, errors[1:])), errors
    # The target pose seen from the final camera is (nearly) the identity.
    T_goal = target_camera_pose(R.T @ (c_w - t), R.T @ n_w, X_AXIS, "L")
    assert np.linalg.norm(T_goal[:3, 3]) < 0.003
    assert np.degrees(np.linalg.norm(_log(T_goal[:3, :3]))) < 1.5
    assert abs(R[:, 0] @ long_w) > math.cos(math.radians(1.5))  # X along the long axis


# ----------------------------------------------------------------------------- Jacobian
@pytest.fixture(scope="module")
def robot():
    client = p.connect(p.DIRECT)
    r = Robot(default_config(RobotConfig))
    r.load(client)
    yield r
    p.disconnect(client)


def _fd_jacobian(robot, q, eps=3e-3):
    """Central differences of camera_pose(q), in the camera frame at q.

    pybullet reports link poses in single precision (~6e-8 m at 0.7 m), so eps must be large:
    3e-3 rad keeps the rounding (~1e-5) and the truncation (~eps² ≈ 1e-5) both well under 1e-4.
    """
    R0 = robot.camera_pose(q)[:3, :3]
    J = np.zeros((6, len(q)))
    for i in range(len(q)):
        dq = np.zeros(len(q))
        dq[i] = eps
        Tp, Tm = robot.camera_pose(q + dq), robot.camera_pose(q - dq)
        J[:3, i] = R0.T @ (Tp[:3, 3] - Tm[:3, 3]) / (2 * eps)
        J[3:, i] = _log(Tm[:3, :3].T @ Tp[:3, :3]) / (2 * eps)
    return J


def test_camera_jacobian_matches_finite_differences(robot):
    home = robot.home_q()
    q_rand = np.clip(
        home + np.random.default_rng(0).normal(0, 0.4, 7),
        robot.joint_limits[:, 0],
        robot.joint_limits[:, 1],
    )
    for q in (home, q_rand):
        J = camera_jacobian(robot, q)
        assert J.shape == (6, 7)
        np.testing.assert_allclose(J, _fd_jacobian(robot, q), atol=1e-4)


def test_joint_step_moves_the_camera_by_the_twist(robot):
    q0 = robot.home_q()
    T0 = robot.camera_pose(q0)
    twist = np.array([0.05, -0.02, 0.1, 0.1, -0.2, 0.3])
    dt = 0.01
    qdot = joint_velocities(camera_jacobian(robot, q0), twist)
    q1, clamped = integrate(robot, q0, qdot, dt, max_joint_speed=3.0)
    assert not clamped
    T1 = robot.camera_pose(q1)
    # Displacement in the start camera frame ≈ V dt (1.1 mm); rotation ≈ Ω dt (3.7 mrad);
    # the Euler step's second-order error is ~|Ω dt| · |V dt| ≈ 4e-6 m.
    np.testing.assert_allclose(T0[:3, :3].T @ (T1[:3, 3] - T0[:3, 3]), twist[:3] * dt, atol=2e-5)
    np.testing.assert_allclose(_log(T0[:3, :3].T @ T1[:3, :3]), twist[3:] * dt, atol=5e-5)


def test_integrate_limits_speed_and_range(robot):
    q0 = robot.home_q()
    qdot = np.array([4.0, -1.0, 0, 0, 0, 0, 2.0])
    q1, clamped = integrate(robot, q0, qdot, 0.1, max_joint_speed=2.0)
    assert clamped
    np.testing.assert_allclose(q1 - q0, qdot * 0.5 * 0.1)  # scaled as a whole by 2/4
    hi = robot.joint_limits[:, 1]
    q_edge = q0.copy()
    q_edge[1] = hi[1] - 1e-3
    q2, clamped = integrate(robot, q_edge, np.eye(7)[1], 0.1, max_joint_speed=2.0)
    assert clamped and q2[1] == hi[1]
