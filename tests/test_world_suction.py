"""Suction in pybullet (pipeline.world.suction): seal test, hold test, the vacuum constraint.

World (pybullet DIRECT, gravity −9.81 m/s² along world z): a static ground slab with its top at
z = 0 and the robot at its home pose (camera 0.625 m above the origin, looking straight down).
There the lips are at z = 0.485, cup_left at world y = +0.035 and cup_right at y = −0.035
(camera y = world −y), both at x = 0; the tests read them from ``link_pose`` rather than
assuming them. Boxes are placed under the cups, floating (nothing is stepped unless a test says
so), their top face 1 mm below the lips. The box: 0.092 (world x) × 0.145 (world y) × 0.052 m,
volume 6.9368e-4 m³; at 400 kg/m³ its mass is 0.27747 kg and its weight W = 2.722 N.

Model defaults (SuctionModelConfig): r = 9 mm, V = 12.7 N per cup, mu = 0.5, compliance 3 mm,
K = 16 rim points; the hand's cup offset d = 0.035 m.
"""

from __future__ import annotations

import math
import time
from dataclasses import replace

import numpy as np
import pybullet as p
import pytest
from conftest import default_config

from pipeline.camera.geometry import Intrinsics
from pipeline.dexnet.contact import REASONS, BoxScene, evaluate_contacts
from pipeline.grasping.suction import SuctionModelConfig, hold_test
from pipeline.robot.model import Robot, RobotConfig
from pipeline.robot.urdf_builder import CUP_OFFSET
from pipeline.world.suction import SuctionGripper, seal_test

CFG = default_config(SuctionModelConfig)
SIZE = np.array([0.092, 0.145, 0.052])  # world x, y, z edge lengths, m
VOLUME = float(np.prod(SIZE))  # 6.9368e-4 m^3
G = np.array([0.0, 0.0, -9.81])
GAP = 0.001  # lip above the top face


@pytest.fixture(scope="module")
def world():
    client = p.connect(p.DIRECT)
    p.setGravity(0, 0, -9.81, physicsClientId=client)
    col = p.createCollisionShape(p.GEOM_BOX, halfExtents=[1.0, 1.0, 0.01], physicsClientId=client)
    ground = p.createMultiBody(0.0, col, basePosition=[0, 0, -0.01], physicsClientId=client)
    robot = Robot(default_config(RobotConfig))
    robot.load(client)
    home = robot.home_q()
    yield client, robot, ground, home
    p.disconnect(client)


class Scene:
    """The world at the home pose, plus the boxes a test adds (removed afterwards)."""

    def __init__(self, client, robot, ground, home):
        self.client, self.robot, self.ground, self.home = client, robot, ground, home
        robot.set_joints(home)
        self.left = robot.link_pose("cup_left")[:3, 3]
        self.right = robot.link_pose("cup_right")[:3, 3]
        self.mid = (self.left + self.right) / 2
        self.bodies: list[int] = []

    def box(
        self,
        dx=0.0,
        dy=0.0,
        density=400.0,
        size=SIZE,
        centre=None,
        gap=GAP,
        tilt_x_deg=0.0,
        mass=None,
    ):
        """A box under the cups' midpoint shifted by (dx, dy), its top ``gap`` below the lips;
        returns (body, mass)."""
        size = np.asarray(size, dtype=float)
        if centre is None:
            centre = self.mid + [dx, dy, -gap - size[2] / 2]
        mass = density * float(np.prod(size)) if mass is None else mass
        col = p.createCollisionShape(
            p.GEOM_BOX, halfExtents=(size / 2).tolist(), physicsClientId=self.client
        )
        orn = p.getQuaternionFromEuler([math.radians(tilt_x_deg), 0, 0])
        body = p.createMultiBody(
            mass, col, basePosition=list(centre), baseOrientation=orn, physicsClientId=self.client
        )
        p.changeDynamics(body, -1, lateralFriction=0.5, physicsClientId=self.client)
        self.bodies.append(body)
        return body, mass

    def seal(self, pattern, boxes, **kw):
        return seal_test(self.client, self.robot, pattern, CFG, set(boxes), **kw)


@pytest.fixture
def scene(world):
    s = Scene(*world)
    t0 = time.perf_counter()
    yield s
    assert time.perf_counter() - t0 < 2.0
    for b in s.bodies:
        p.removeBody(b, physicsClientId=s.client)
    s.robot.set_joints(s.home)
    _hold_joints(s.robot, s.home)


def _hold_joints(robot, q) -> None:
    """Joint motors hold ``q`` (position control, 500 N m) while the simulation steps."""
    p.setJointMotorControlArray(
        robot.body_id,
        robot.joint_indices,
        p.POSITION_CONTROL,
        targetPositions=list(q),
        forces=[500.0] * len(q),
        physicsClientId=robot.client,
    )


def test_home_cup_geometry(scene):
    # The frames the other tests build on: lips 0.14 m ahead of the camera, ±0.035 m across.
    assert np.allclose(scene.left, [0.0, 0.035, 0.485], atol=1e-4)
    assert np.allclose(scene.right, [0.0, -0.035, 0.485], atol=1e-4)


def test_both_cups_on_the_middle_of_a_large_face_seal_and_hold(scene):
    box, mass = scene.box()
    res = scene.seal("B", [box])
    assert res.sealed and res.reason == "ok" and res.body == box
    # Contact points straight under the lips on the top face (1 mm below them); axis world −z.
    assert np.allclose(
        res.contact_points, [scene.left - [0, 0, GAP], scene.right - [0, 0, GAP]], atol=1e-4
    )
    assert np.allclose(res.axis, [0, 0, -1], atol=1e-6)
    assert np.allclose(res.heights, GAP, atol=1e-4)  # every rim point 1 mm ahead
    # Hold: W = 2.722 N, f_N = 2 V - W = 22.68 N; the COM is straight below the centroid, so no
    # shear, torsion or bending: margin = 2 V / W - 1 = 25.4 / 2.722 - 1 = 8.33.
    hold = hold_test(
        mass,
        p.getBasePositionAndOrientation(box, physicsClientId=scene.client)[0],
        res.contact_points,
        res.axis,
        G,
        CFG,
        CUP_OFFSET,
    )
    assert hold.ok and hold.reason == "ok"
    assert hold.margin == pytest.approx(25.4 / (mass * 9.81) - 1, rel=1e-6)
    gripper = SuctionGripper(scene.client, scene.robot, CFG, CUP_OFFSET)
    out = gripper.try_grasp("B", {box: mass})
    assert out.sealed and out.held and out.body == box and gripper.holding == box
    gripper.release()
    assert gripper.holding is None


def test_rays_pass_through_the_cups_own_pad(scene):
    # Why seal_test collects every hit: the rim rays start 10 mm behind the lip, exactly on the
    # mantle of the cup's pad cylinder (radius r = 9 mm), and Bullet reports the cup for some
    # of them at fraction 0. A plain closest-hit batch would therefore see the robot there.
    T = scene.robot.link_pose("cup_left")
    ang = 2 * np.pi * np.arange(CFG.ring_points) / CFG.ring_points
    rim = T[:3, 3] + CFG.cup_radius * (
        np.cos(ang)[:, None] * T[:3, 0] + np.sin(ang)[:, None] * T[:3, 1]
    )
    box, _ = scene.box()
    plain = p.rayTestBatch(
        (rim - 0.01 * T[:3, 2]).tolist(),
        (rim + 0.02 * T[:3, 2]).tolist(),
        physicsClientId=scene.client,
    )
    assert any(r[0] == scene.robot.body_id for r in plain)
    res = scene.seal("L", [box])
    assert res.sealed and np.allclose(res.heights, GAP, atol=1e-4)


def test_ignored_body_is_passed_through(scene):
    # A 2 mm sheet lying on the box top, 6 mm narrower than the cup: the cup is off_face on it,
    # but with the sheet ignored the rays reach the box below and it seals (heights 3 mm).
    box, _ = scene.box(gap=0.003)
    sheet, _ = scene.box(size=(0.012, 0.012, 0.002), centre=scene.left - [0, 0, 0.002], mass=0.0)
    assert scene.seal("L", [box]).reason == "off_face"
    res = scene.seal("L", [box], ignore=(sheet,))
    assert res.sealed and res.body == box and np.allclose(res.heights, 0.003, atol=1e-4)


def test_cup_over_an_edge_is_off_face(scene):
    # Box shifted along world −y until its +y edge is 3 mm past the left cup's centre
    # (y_edge = 0.035 + 0.003 = 0.038): the left rim (radius 9 mm) hangs 6 mm over the edge,
    # the right cup (y = −0.035) is 62 mm inside the −y edge at −0.107.
    box, _ = scene.box(dy=(scene.left[1] + 0.003 - SIZE[1] / 2) - scene.mid[1])
    for pattern, sealed, reason in (
        ("B", False, "off_face"),
        ("L", False, "off_face"),
        ("R", True, "ok"),
    ):
        res = scene.seal(pattern, [box])
        assert (res.sealed, res.reason) == (sealed, reason), pattern


def test_no_box_under_the_cups_is_no_contact(scene):
    # The ground is 0.485 m below the lips, far beyond the 0.02 m reach.
    res = scene.seal("B", [])
    assert not res.sealed and res.reason == "no_contact" and res.body is None
    assert np.isnan(res.contact_points).all()


def test_box_smaller_than_the_cup_does_not_seal(scene):
    # A 12 mm cube centred under the left cup: its centre ray hits, but the rim (radius 9 mm)
    # reaches past the cube's 6 mm half width, so the rim rays miss.
    small, _ = scene.box(size=(0.012, 0.012, 0.012), centre=scene.left - [0, 0, GAP + 0.006])
    res = scene.seal("L", [small])
    assert not res.sealed and res.reason == "off_face" and res.body == small


def test_non_box_body_is_bin(scene):
    # A static slab that is not in box_bodies: the seal geometry is fine, but not on a box.
    slab, _ = scene.box(mass=0.0)
    res = scene.seal("B", [])
    assert not res.sealed and res.reason == "bin" and res.body == slab


def test_tilted_face_is_uneven_for_two_cups_only(scene):
    # Box tilted 5 deg about world x (across the cup line, world y): the rim heights change by
    # tan 5 deg = 0.0875 m per m along y. One cup's rim spans 18 mm: spread 1.57 mm <= 3 mm.
    # Both cups' rims span 2 (0.035 + 0.009) = 88 mm: spread 7.7 mm > 3 mm (the rigid hand).
    box, _ = scene.box(tilt_x_deg=5.0, gap=0.005)
    res_l, res_b = scene.seal("L", [box]), scene.seal("B", [box])
    assert res_l.sealed and np.ptp(res_l.heights) == pytest.approx(
        0.018 * math.tan(math.radians(5)), abs=2e-4
    )
    assert not res_b.sealed and res_b.reason == "uneven"
    assert np.ptp(res_b.heights) == pytest.approx(0.088 * math.tan(math.radians(5)), abs=2e-4)


def test_heavy_box_pulls_off(scene):
    # 4000 kg/m^3: m = 2.7747 kg, W = 27.22 N > 2 V = 25.4 N, so f_N = -1.82 N < 0: "pull".
    box, mass = scene.box(density=4000.0)
    gripper = SuctionGripper(scene.client, scene.robot, CFG, CUP_OFFSET)
    out = gripper.try_grasp("B", {box: mass})
    assert out.sealed and not out.held and out.reason == "pull"
    assert out.hold.margin == pytest.approx(25.4 / (mass * 9.81) - 1, rel=1e-6)  # -0.067
    assert gripper.holding is None


def test_single_cup_far_from_the_com_bends_but_two_cups_hold(scene):
    # 1600 kg/m^3: m = 1.10989 kg, W = 10.888 N. Box centre shifted to y = -0.025 (its +y edge
    # at 0.0475, 3.5 mm beyond the left rim).
    # L at y = +0.035: lever 0.060 m, bending torque 0.060 W = 0.6533 N m against
    #   r f_N = 0.009 (12.7 - 10.888) = 0.01631 N m -> "bending" (pull, shear, torsion pass).
    # B: centroid y = 0, COM 0.025 m along the cup line: torque about the in-plane axis
    #   across the cup line 0.025 W = 0.2722 N m against f_N (r + d) = (25.4 - 10.888)
    #   (0.009 + 0.035) = 14.512 x 0.044 = 0.6385 N m -> holds (bending margin
    #   0.6385 / 0.2722 - 1 = 1.346; the pull margin 25.4 / 10.888 - 1 = 1.333 is smaller). With a
    #   single-cup lever r it would be 0.1306 N m < 0.2722: the two-cup lever is what holds it.
    box, mass = scene.box(dy=-0.025 - scene.mid[1], density=1600.0)
    assert mass == pytest.approx(1.10989, abs=1e-4)
    gripper = SuctionGripper(scene.client, scene.robot, CFG, CUP_OFFSET)
    out_l = gripper.try_grasp("L", {box: mass})
    assert out_l.sealed and not out_l.held and out_l.reason == "bending"
    assert out_l.hold.margin == pytest.approx(0.01631 / 0.6533 - 1, abs=1e-3)
    out_b = gripper.try_grasp("B", {box: mass})
    assert out_b.held and out_b.reason == "ok"
    assert out_b.hold.margin == pytest.approx(25.4 / 10.888 - 1, abs=1e-3)
    gripper.release()
    com = p.getBasePositionAndOrientation(box, physicsClientId=scene.client)[0]
    no_lever = hold_test(mass, com, out_b.seal.contact_points, out_b.seal.axis, G, CFG, 0.0)
    assert not no_lever.ok and no_lever.reason == "bending"


def test_two_cup_torsion_uses_the_friction_couple():
    # Cups at (0, +-0.035, 0), axis -z, m = 1 kg, "gravity" (1, 0, -9.81) m/s^2 (a horizontal
    # pull of 1 N besides the weight), COM at c = (0, 0.03, -0.001).
    # Two cups: pull 9.81 N, f_N = 25.4 - 9.81 = 15.59 N; shear 1 N <= mu f_N = 7.795 N;
    # tau = c x F = (0.03 x -9.81, -0.001 x 1, -0.03 x 1) = (-0.2943, -0.001, -0.03) N m;
    # torsion |tau . a| = 0.03 <= mu f_N d = 0.5 x 15.59 x 0.035 = 0.2728 N m; bending: about
    # the cup line (y) 0.001 N m (lever r), across it 0.2943 N m (lever r + d = 0.044):
    # hypot(0.001 / 0.009, 0.2943 / 0.044) = 6.69 N <= f_N = 15.59 N -> ok.
    # One cup at the same centroid: f_N = 12.7 - 9.81 = 2.89 N, shear 1 <= 1.445 N, torsion
    # 0.03 > r mu f_N = 0.009 x 0.5 x 2.89 = 0.0130 N m -> "torsion".
    g = [1.0, 0.0, -9.81]
    pts = np.array([[0, 0.035, 0], [0, -0.035, 0]])
    res = hold_test(1.0, [0, 0.03, -0.001], pts, [0, 0, -1], g, CFG, 0.035)
    assert res.ok
    assert res.margin == pytest.approx(
        min(25.4 / 9.81, 7.795 / 1.0, 0.2728 / 0.03, 15.59 / 6.69) - 1, rel=2e-3
    )
    one = hold_test(1.0, [0, 0.03, -0.001], [[0, 0, 0]], [0, 0, -1], g, CFG, 0.035)
    assert not one.ok and one.reason == "torsion"


def _pose(body, client) -> np.ndarray:
    pos, orn = p.getBasePositionAndOrientation(body, physicsClientId=client)
    T = np.eye(4)
    T[:3, :3] = np.reshape(p.getMatrixFromQuaternion(orn), (3, 3))
    T[:3, 3] = pos
    return T


def _render_top(box_centre, size, top, floor, intr):
    """Depth and mask of one axis-aligned box seen straight down (camera frame): its top face
    at z = top over its footprint, the floor elsewhere (side faces are not drawn, so only
    points away from the edges are used)."""
    u, v = np.meshgrid(np.arange(intr.width, dtype=float), np.arange(intr.height, dtype=float))
    x = (u - intr.cx) / intr.fx * top
    y = (v - intr.cy) / intr.fy * top
    inside = (np.abs(x - box_centre[0]) <= size[0] / 2) & (np.abs(y - box_centre[1]) <= size[1] / 2)
    return (np.where(inside, top, floor).astype(np.float32), inside.astype(np.uint8))


@pytest.mark.parametrize(
    "density, gravity_dir, expected",
    [
        (
            800.0,
            (0.0, 0.0, 1.0),
            ["ok", "ok", "bending", "bending", "bending", "ok", "bending", "bending"],
        ),
        (400.0, (0.9, 0.3, 0.3), ["ok", "ok", "ok", "ok", "torsion", "ok", "torsion", "ok"]),
        (1600.0, (0.25, -0.2, 0.95), ["shear"] * 8),
    ],
)
def test_one_cup_reproduces_the_dexnet_contact_rule(density, gravity_dir, expected):
    # Camera frame, looking down at a 0.145 x 0.092 x 0.05 box with its top at z = 0.5; eight
    # contact points on the top face, all >= 7 mm inside its edges (contact.py's image checks
    # pass). Straight-down gravity, 800 kg/m^3: m = 0.5336 kg, W = 5.2346 N, f_N = 12.7 -
    # 5.2346 = 7.465 N, bending limit r f_N = 0.06719 N m, so a contact more than
    # 0.06719 / 5.2346 = 12.8 mm from the COM's vertical bends: (0, 0), (0.01, 0) and
    # (0.005, -0.008) (9.4 mm) hold, the others bend. Tilted gravity brings torsion (a
    # sideways pull with an in-plane lever) and, on the 1600 kg/m^3 box (W = 10.47 N), shear:
    # its sideways weight 10.47 x 0.319 = 3.34 N > mu f_N = 0.5 (12.7 - 10.47 x 0.948) = 1.39 N.
    cfg = replace(CFG, density=density)
    size = np.array([0.145, 0.092, 0.05])
    top, floor = 0.5, 0.55
    centre = np.array([0.0, 0.0, top + size[2] / 2])
    intr = Intrinsics(60, 60, 75.0, 75.0, 29.5, 29.5)
    depth, mask = _render_top(centre, size, top, floor, intr)
    pts = np.array(
        [
            [0, 0],
            [0.01, 0],
            [0.02, 0],
            [0, 0.02],
            [-0.04, 0.015],
            [0.005, -0.008],
            [0, -0.03],
            [0.05, 0],
        ]
    )
    pts = np.column_stack([pts, np.full(len(pts), top)])
    axis = np.array([0.0, 0.0, 1.0])
    T = np.eye(4)
    T[:3, 3] = centre
    boxes = [type("B", (), {"size": size, "T_cam_box": T})()]
    ref = evaluate_contacts(
        pts,
        np.tile(axis, (len(pts), 1)),
        BoxScene(depth, mask, intr, np.array(gravity_dir), boxes),
        cfg,
    )
    assert ref.seal.all()
    g = cfg.gravity * np.asarray(gravity_dir) / np.linalg.norm(gravity_dir)
    mass = cfg.density * float(np.prod(size))
    got = [hold_test(mass, centre, pt, axis, g, cfg, CUP_OFFSET) for pt in pts]
    assert [h.reason for h in got] == [REASONS[c] for c in ref.reason] == expected
    assert [h.ok for h in got] == ref.wrench_ok.tolist()


def test_attached_box_stays_and_falls_after_release(scene):
    # B on the 0.277 kg box, hanging in the air under the hand: the constraint (maxForce
    # 2 V = 25.4 N) carries W = 2.72 N, so after 120 steps (0.5 s) it has not moved; released,
    # it falls the 0.43 m to the ground (free fall covers 1.2 m in 0.5 s).
    box, mass = scene.box()
    _hold_joints(scene.robot, scene.home)  # the arm holds still while the simulation steps
    z0 = p.getBasePositionAndOrientation(box, physicsClientId=scene.client)[0][2]
    gripper = SuctionGripper(scene.client, scene.robot, CFG, CUP_OFFSET)
    out = gripper.try_grasp("B", {box: mass})
    assert out.held
    with pytest.raises(RuntimeError):
        gripper.try_grasp("B", {box: mass})
    for _ in range(120):
        p.stepSimulation(physicsClientId=scene.client)
    assert p.getBasePositionAndOrientation(box, physicsClientId=scene.client)[0][
        2
    ] == pytest.approx(z0, abs=1e-3)
    # The box follows the hand: turn joint 1 by 0.05 rad (the lips swing 0.42 x 0.05 = 21 mm
    # sideways) and hold it there with the joint motors; the box keeps its pose in the cup frame.
    T_cup_box = np.linalg.inv(scene.robot.link_pose("cup_left")) @ _pose(box, scene.client)
    q = scene.home.copy()
    q[0] += 0.05
    _hold_joints(scene.robot, q)
    for _ in range(120):
        p.stepSimulation(physicsClientId=scene.client)
    moved = scene.robot.link_pose("cup_left")
    assert np.linalg.norm(moved[:3, 3] - scene.left) > 0.015
    assert np.allclose(np.linalg.inv(moved) @ _pose(box, scene.client), T_cup_box, atol=2e-3)
    gripper.release()
    z0 = p.getBasePositionAndOrientation(box, physicsClientId=scene.client)[0][2]
    for _ in range(120):
        p.stepSimulation(physicsClientId=scene.client)
    z1 = p.getBasePositionAndOrientation(box, physicsClientId=scene.client)[0][2]
    assert z1 < z0 - 0.3 and z1 == pytest.approx(SIZE[2] / 2, abs=0.01)
