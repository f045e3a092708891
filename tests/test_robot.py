"""The robot model: URDF, FK, the home pose, target camera poses, IK and its checks."""

from __future__ import annotations

import time
from enum import Enum

import numpy as np
import pybullet as p
import pytest
from conftest import conf_section, default_config

from pipeline.camera.geometry import camera_pose_above_bin
from pipeline.cell.bin import build_cell
from pipeline.robot.model import Robot, RobotConfig, rotation_angle_deg
from pipeline.robot.target_pose import target_camera_pose
from pipeline.robot.urdf_builder import (
    CUP_DIAMETER,
    CUP_OFFSET,
    CUP_TIP_Z,
    URDF_PATH,
    build_urdf_xml,
)

POS_TOL, ROT_TOL = 0.002, 1.0
DOWN = np.array([[1.0, 0, 0], [0, -1, 0], [0, 0, -1]])  # camera axes looking straight down


@pytest.fixture(scope="module")
def cell():
    """A pybullet client with the paper's bin and the robot beside it."""
    client = p.connect(p.DIRECT)
    bin_cfg = conf_section("bin")
    bodies = build_cell(client, bin_cfg, conf_section("physics"))
    robot = Robot(default_config(RobotConfig))
    robot.load(client, ground_z=-bin_cfg.floor_thickness)
    yield client, robot, bodies
    p.disconnect(client)


def _static_box(client, center, half_extents) -> int:
    col = p.createCollisionShape(p.GEOM_BOX, halfExtents=half_extents, physicsClientId=client)
    return p.createMultiBody(0.0, col, basePosition=center, physicsClientId=client)


def _pose(R, t) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, t
    return T


def _assert_reaches(robot, q, T_target):
    T = robot.camera_pose(q)
    assert np.linalg.norm(T[:3, 3] - T_target[:3, 3]) <= POS_TOL
    assert rotation_angle_deg(T[:3, :3], T_target[:3, :3]) <= ROT_TOL


# ----------------------------------------------------------------------------- URDF and FK
def test_urdf_file_is_the_builders_output():
    assert URDF_PATH.read_text() == build_urdf_xml(), (
        "urdf/binpick_robot.urdf is stale: regenerate it with "
        "pipeline.robot.urdf_builder.write_urdf()"
    )


def test_urdf_loads_with_seven_movable_joints(cell):
    _, robot, _ = cell
    assert robot.joint_names == [f"joint{i}" for i in range(1, 8)]
    assert robot.joint_limits.shape == (7, 2)
    assert np.all(robot.joint_limits[:, 0] < robot.joint_limits[:, 1])
    np.testing.assert_allclose(robot.joint_limits[1], [-2.059, 2.0944])  # xArm6 joint 2
    np.testing.assert_allclose(robot.joint_limits[6], [-np.pi / 2, np.pi / 2])  # hand tilt
    for name in ("camera", "cup_left", "cup_right", "hand", "link6"):
        assert name in robot.link_index


def test_cups_sit_either_side_of_the_camera(cell):
    """Left cup at camera y = −0.035, right at +0.035, lips 0.14 ahead, 18 mm across."""
    client, robot, _ = cell
    q = robot.home_q() + np.array([0.3, 0.2, -0.3, 0.5, 0.4, -0.7, 0.6])  # any pose
    T_world_cam = robot.camera_pose(q)
    for name, y in (("cup_left", -CUP_OFFSET), ("cup_right", CUP_OFFSET)):
        T_cam_cup = np.linalg.inv(T_world_cam) @ robot.link_pose(name)
        np.testing.assert_allclose(T_cam_cup[:3, 3], [0.0, y, CUP_TIP_Z], atol=1e-6)
        np.testing.assert_allclose(T_cam_cup[:3, :3], np.eye(3), atol=1e-6)
        radii = [
            s[3][1]
            for s in p.getCollisionShapeData(
                robot.body_id, robot.link_index[name], physicsClientId=client
            )
        ]
        assert max(radii) == pytest.approx(CUP_DIAMETER / 2)
    assert (CUP_OFFSET, CUP_DIAMETER) == (0.035, 0.018)  # paper Fig. 1b


def test_home_pose_matches_the_overhead_camera(cell):
    _, robot, bodies = cell
    q = robot.home_q()
    _assert_reaches(robot, q, camera_pose_above_bin(0.625))
    assert robot.within_limits(q)
    assert q[6] == 0.0  # the hand is straight at home
    assert robot.in_collision(q, bodies) == []


# ----------------------------------------------------------------------------- target pose
def test_target_pose_horizontal_surface_both_cups():
    c, n = np.array([0.02, -0.01, 0.5]), np.array([0.0, 0.0, -1.0])
    T = target_camera_pose(c, n, np.array([1.0, 0.0, 0.0]), "B")
    np.testing.assert_allclose(T[:3, :3], np.eye(3), atol=1e-12)  # looking along the anti-normal
    np.testing.assert_allclose(T[:3, 3], [0.02, -0.01, 0.35], atol=1e-12)  # 0.15 m above
    # The axis is projected into the plane and normalised.
    T2 = target_camera_pose(c, n, np.array([2.0, 0.0, 0.5]), "B")
    np.testing.assert_allclose(T2, T, atol=1e-12)
    # Camera x along the other surface axis: x = (0, 1, 0), y = z × x = (−1, 0, 0).
    T3 = target_camera_pose(c, n, np.array([0.0, 1.0, 0.0]), "B")
    np.testing.assert_allclose(T3[:3, :3], [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-12)
    np.testing.assert_allclose(T3[:3, 3], [0.02, -0.01, 0.35], atol=1e-12)


def test_target_pose_left_and_right_put_that_cup_over_the_centre():
    c, n, x = np.array([0.02, -0.01, 0.5]), np.array([0.0, 0.0, -1.0]), np.array([1.0, 0, 0])
    T_left = target_camera_pose(c, n, x, "L")
    T_right = target_camera_pose(c, n, x, "R")
    # L: the camera moves +0.035 along its y so the left cup (y = −0.035) is over the centre.
    np.testing.assert_allclose(T_left[:3, 3], [0.02, 0.025, 0.35], atol=1e-12)
    np.testing.assert_allclose(T_right[:3, 3], [0.02, -0.045, 0.35], atol=1e-12)
    # Seen from the target pose, the centre is on the active cup's axis, 0.15 m ahead.
    np.testing.assert_allclose(
        (np.linalg.inv(T_left) @ np.r_[c, 1])[:3], [0, -0.035, 0.15], atol=1e-12
    )
    np.testing.assert_allclose(
        (np.linalg.inv(T_right) @ np.r_[c, 1])[:3], [0, 0.035, 0.15], atol=1e-12
    )


def test_target_pose_tilted_surface():
    """Surface turned 30° about camera x: n = (0, −1/2, −√3/2)."""
    c = np.array([0.0, 0.05, 0.45])
    n = np.array([0.0, -0.5, -np.sqrt(3) / 2])
    T = target_camera_pose(c, n, np.array([1.0, 0.0, 0.0]), "B")
    np.testing.assert_allclose(T[:3, 0], [1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(T[:3, 1], [0, np.sqrt(3) / 2, -0.5], atol=1e-12)  # z × x
    np.testing.assert_allclose(T[:3, 2], [0, 0.5, np.sqrt(3) / 2], atol=1e-12)
    np.testing.assert_allclose(T[:3, 3], c + 0.15 * n, atol=1e-12)
    T_left = target_camera_pose(c, n, np.array([1.0, 0.0, 0.0]), "L")
    np.testing.assert_allclose(T_left[:3, 3], c + 0.15 * n + 0.035 * T[:3, 1], atol=1e-12)
    np.testing.assert_allclose(
        (np.linalg.inv(T_left) @ np.r_[c, 1])[:3], [0, -0.035, 0.15], atol=1e-12
    )


def test_target_pose_rejects_bad_input():
    c, n, x = np.array([0, 0, 0.5]), np.array([0, 0, -1.0]), np.array([1.0, 0, 0])
    with pytest.raises(ValueError, match="NG"):
        target_camera_pose(c, n, x, "NG")
    with pytest.raises(ValueError, match="faces the camera"):
        target_camera_pose(c, -n, x, "B")
    with pytest.raises(ValueError, match="parallel"):
        target_camera_pose(c, n, n, "B")
    Pattern = Enum("Pattern", "R L B NG")  # any enum whose member names are the patterns
    np.testing.assert_allclose(
        target_camera_pose(c, n, x, Pattern.L), target_camera_pose(c, n, x, "L")
    )


# ----------------------------------------------------------------------------- IK
def _floor_target(pattern, x=0.0, y=0.0, axis=(1.0, 0.0, 0.0)):
    """World T of the camera grasping a horizontal surface at (x, y, 0) with ``pattern``."""
    T0 = camera_pose_above_bin(0.625)
    c_cam = (np.linalg.inv(T0) @ np.array([x, y, 0.0, 1.0]))[:3]
    n_cam = T0[:3, :3].T @ np.array([0.0, 0.0, 1.0])
    a_cam = T0[:3, :3].T @ np.asarray(axis)
    return T0 @ target_camera_pose(c_cam, n_cam, a_cam, pattern)


def test_ik_reaches_the_bin_floor_centre(cell):
    _, robot, bodies = cell
    T = _floor_target("B")
    np.testing.assert_allclose(T, _pose(DOWN, [0, 0, 0.15]), atol=1e-12)
    res = robot.solve_ik(T, obstacle_ids=bodies)
    assert res.ok and res.reason is None, res
    assert res.position_error_m <= POS_TOL and res.orientation_error_deg <= ROT_TOL
    assert robot.within_limits(res.q)
    _assert_reaches(robot, res.q, T)


def test_ik_too_far_is_an_ik_failure(cell):
    _, robot, bodies = cell
    res = robot.solve_ik(_pose(DOWN, [2.0, 0.0, 0.3]), obstacle_ids=bodies)
    assert not res.ok and res.reason == "ik"
    assert res.position_error_m > 1.0


def test_hand_inside_the_bin_wall_is_a_collision(cell):
    """Camera 0.15 m above the floor 10 mm from the +x wall: the 0.11 m camera bar hits it."""
    _, robot, bodies = cell
    T = _floor_target("B", x=0.19)
    assert robot.solve_ik(T).ok  # reachable without obstacles
    res = robot.solve_ik(T, obstacle_ids=bodies)
    assert not res.ok and res.reason == "collision"
    wall_plus_x = bodies[3]
    assert ("camera", wall_plus_x) in res.collisions


def test_box_in_the_way_is_a_collision_unless_ignored(cell):
    client, robot, bodies = cell
    T = _floor_target("L", x=0.05, y=0.02)
    box = _static_box(client, [0.05, 0.02 + 0.035, 0.04], [0.03, 0.03, 0.04])  # under the cups
    try:
        res = robot.solve_ik(T, obstacle_ids=[*bodies, box])
        assert not res.ok and res.reason == "collision"
        assert {c.robot_link for c in res.collisions} & {"cup_left", "cup_right"}
        # The target box touched by the cups can be excluded.
        assert robot.solve_ik(T, obstacle_ids=[*bodies, box], ignore_body_ids=[box]).ok
        # A box whose top is the grasped surface: lips 10 mm above it, outside the 5 mm margin.
        T_top = _floor_target("B", x=0.05, y=0.02)
        T_top[2, 3] += 0.08
        assert robot.solve_ik(T_top, obstacle_ids=[*bodies, box]).ok
    finally:
        p.removeBody(box, physicsClientId=client)


def test_box_against_the_arm_is_a_collision(cell):
    client, robot, bodies = cell
    q = robot.home_q()
    robot.set_joints(q)
    (lo, hi) = np.asarray(
        p.getAABB(robot.body_id, robot.link_index["link2"], physicsClientId=client)
    )
    box = _static_box(client, ((lo + hi) / 2).tolist(), [0.01, 0.01, 0.01])  # inside the upper arm
    try:
        assert ("link2", box) in robot.in_collision(q, [*bodies, box])
        assert robot.in_collision(q, [*bodies, box], ignore_body_ids=[box]) == []
    finally:
        p.removeBody(box, physicsClientId=client)


def test_pose_reachable_only_outside_the_joint_limits(cell):
    """Camera 0.4 m below and just in front of the base flange, no obstacles.

    Found by search: the arm reaches it only with the shoulder (joint 2) beyond its +2.094 rad
    limit; 500 random in-limit seeds found no in-limits solution.
    """
    _, robot, _ = cell
    q_outside = np.array([5.125, 2.628, -3.001, 0.55, 1.52, -5.069, -0.557])
    assert q_outside[1] > robot.joint_limits[1, 1]
    T = robot.camera_pose(q_outside)
    res = robot.solve_ik(T)
    assert not res.ok and res.reason == "joint_limits"
    assert res.position_error_m <= POS_TOL and not robot.within_limits(res.q)


@pytest.mark.parametrize("pattern", ["B", "L", "R"])
def test_straight_down_grasps_over_the_bin(cell, pattern):
    """Kinematically the whole floor is reachable; with the bin, the cells clear of the walls."""
    _, robot, bodies = cell
    times = []
    for x in np.linspace(-0.17, 0.17, 5):
        for y in np.linspace(-0.12, 0.12, 5):
            T = _floor_target(pattern, x, y)
            t0 = time.perf_counter()
            free = robot.solve_ik(T)
            times.append(time.perf_counter() - t0)
            assert free.ok, (x, y, free)
            inner = abs(x) < 0.1 and abs(y) < 0.1
            if inner:
                assert robot.solve_ik(T, obstacle_ids=bodies).ok, (x, y)
    # A few ms per IK + checks (measured about 1 ms); generous for slow CI machines.
    assert np.mean(times) < 0.02


def test_many_obstacles_give_the_contacts_of_few():
    """Above 32 obstacles ``in_collision`` takes the engine's broadphase: on 60 small boxes
    (a 6 x 10 grid of 2 cm cubes 1 cm apart, 0.3 m under the home camera) the contacts of
    every pose of a descent are those found by asking 30 at a time (the exact box test)."""
    client = p.connect(p.DIRECT)
    try:
        bin_cfg = conf_section("bin")
        build_cell(client, bin_cfg, conf_section("physics"))
        robot = Robot(default_config(RobotConfig))
        robot.load(client, ground_z=-bin_cfg.floor_thickness)
        cubes = [
            _static_box(client, [-0.05 + 0.03 * i, -0.15 + 0.03 * j, 0.01], [0.01, 0.01, 0.01])
            for i in range(6)
            for j in range(10)
        ]
        home = robot.home_camera_pose()
        hits_seen = 0
        for depth in np.linspace(0.55, 0.63, 9):
            T = home.copy()
            T[2, 3] = home[2, 3] - depth + 0.02  # the camera down to ~2 cm above the cubes' tops
            res = robot.solve_ik(T, seed_q=robot.home_q())
            many = sorted(robot.in_collision(res.q, cubes))
            few = sorted(
                robot.in_collision(res.q, cubes[:30]) + robot.in_collision(res.q, cubes[30:])
            )
            few = sorted(c for c in few if c.other_body != robot.body_id)
            many = sorted(c for c in many if c.other_body != robot.body_id)
            assert many == few
            hits_seen += len(many)
        assert hits_seen > 0  # the descent does reach the cubes
    finally:
        p.disconnect(client)


def _every_pair(robot, q, obstacles, ignore=(), margin=None, self_collision=True):
    """``Robot.in_collision`` as it tests boxes without shortcuts: every obstacle's box read
    from the engine, every (obstacle, link) pair and every self-collision pair by the box
    test, then the engine's closest points."""
    robot.set_joints(q)
    cid, rid = robot.client, robot.body_id
    margin = robot.cfg.collision_margin if margin is None else margin
    m_self = robot.cfg.self_collision_margin
    boxes = {j: p.getAABB(rid, j, physicsClientId=cid) for j in robot._links}

    def near(a, b, m):
        return all(a[0][k] <= b[1][k] + m and b[0][k] <= a[1][k] + m for k in range(3))

    found = []
    for body in [b for b in dict.fromkeys(obstacles) if b not in {*ignore, rid}]:
        other = p.getAABB(body, physicsClientId=cid)
        for link in robot._links[1:]:  # not the fixed base (-1)
            if near(boxes[link], other, margin) and p.getClosestPoints(
                rid, body, margin, linkIndexA=link, physicsClientId=cid
            ):
                found.append((robot.link_name[link], body))
    for a, b in robot.self_collision_pairs if self_collision else ():
        if near(boxes[a], boxes[b], m_self) and p.getClosestPoints(
            rid, rid, m_self, linkIndexA=a, linkIndexB=b, physicsClientId=cid
        ):
            found.append((robot.link_name[a], rid))
    return found


def test_collision_shortcuts_give_the_contacts_of_every_pair(cell):
    """``in_collision`` skips the links of an obstacle clear of the box around all links, and
    inside ``obstacles_still`` reads the obstacles' boxes once: on random joints near boxes in
    the bin, the same contacts, in the same order, as testing every pair."""
    client, robot, bodies = cell
    rng = np.random.default_rng(3)
    boxes = [
        _static_box(client, [rng.uniform(-0.25, 0.25), rng.uniform(-0.2, 0.2), 0.05], [0.05] * 3)
        for _ in range(8)
    ]
    obstacles = [*bodies, *boxes]
    lo, hi = robot.joint_limits[:, 0], robot.joint_limits[:, 1]
    home = robot.home_q()
    try:
        contacts = 0
        for i in range(120):
            q = np.clip(home + rng.normal(0, 0.6, len(home)), lo, hi)
            kwargs = {"margin": 0.02, "self_collision": False} if i % 3 == 2 else {}
            ignore = boxes[:1] if i % 2 else []
            expected = _every_pair(robot, q, obstacles, ignore, **kwargs)
            assert robot.in_collision(q, obstacles, ignore, **kwargs) == expected
            with robot.obstacles_still():
                assert robot.in_collision(q, obstacles, ignore, **kwargs) == expected
                assert robot.in_collision(q, obstacles, ignore, **kwargs) == expected
            contacts += bool(expected)
        assert 5 <= contacts <= 115  # both outcomes are tested
    finally:
        robot.set_joints(home)
        for b in boxes:
            p.removeBody(b, physicsClientId=client)


def test_ik_seeds_try_home_once(cell):
    """``Robot._seeds``: the given seed, the home pose unless the seed is it (the same seed
    gives the same answer), then the ``ik_restarts`` perturbations of home."""
    _, robot, _ = cell
    restarts = robot.cfg.ik_restarts
    home = robot.home_q()
    from_home = list(robot._seeds(home))
    from_other = list(robot._seeds(home + 0.1))
    assert len(from_home) == 1 + restarts
    assert len(from_other) == 2 + restarts
    np.testing.assert_array_equal(from_other[1], home)
    for a, b in zip(from_home[1:], from_other[2:]):
        np.testing.assert_array_equal(a, b)
    assert len(list(robot._seeds(None))) == 1 + restarts
