"""The suction contact model on pybullet bodies (pipeline.dexnet.contact_mesh), against the
box-only analytic model (pipeline.dexnet.contact) and on cylinders worked out by hand.

World: z up, a static floor slab with its top at z = 0 (no visual shape: the renderer fills its
depth analytically). "Looking down" camera: ``camera_pose_above_bin(0.55)``, 0.55 m above the
floor (camera x = world x, camera y = world -y, camera z = world -z; gravity along camera +z).
Box scenes are rendered exactly by ``pipeline.camera.raycast``, cylinder scenes by pybullet's
TinyRenderer (``pipeline.camera.render``), which also draws ``objects.create_body``'s mesh.

Defaults used in the hand computations: cup radius r = 9 mm, vacuum V = 12.7 N, mu = 0.5,
compliance c = 3 mm, g = 9.81, density 400 kg/m^3; so the limits at zero pull are shear
mu V = 6.35 N, torsion r mu V = 0.05715 N m, bending r V = 0.1143 N m.
"""

from __future__ import annotations

from types import SimpleNamespace as NS

import numpy as np
import pybullet as p
import pytest
from conftest import default_config

from pipeline.camera.geometry import Intrinsics, backproject, camera_pose_above_bin, pose_matrix
from pipeline.camera.render import render_depth
from pipeline.dexnet.contact import REASONS, BoxScene, evaluate_contacts, robust_quality
from pipeline.dexnet.contact_mesh import (
    MAX_NORMAL_ANGLE_DEG,
    BodyScene,
    RayScene,
    evaluate_contacts_mesh,
    robust_quality_mesh,
)
from pipeline.grasping.suction import SuctionModelConfig
from pipeline.simulation.objects import create_body, cylinder

CFG = default_config(SuctionModelConfig)
DENSITY = 400.0
DOWN = np.array([0.0, 0.0, 1.0])  # gravity in the looking-down camera's frame
T_DOWN = camera_pose_above_bin(0.55)
# 240 x 240 px, 1.67 mm a pixel at 0.5 m: fine enough that the 3 mm visibility tolerance holds
# on the leaning box's face (normal 51 deg from the line of sight: 1.25 x half a pixel = 1 mm).
INTR_BOX = Intrinsics(240, 240, 300.0, 300.0, 119.5, 119.5)
# 160 x 160 px, 1.2 mm a pixel at 0.47 m (the cylinder scenes).
INTR_CYL = Intrinsics(160, 160, 400.0, 400.0, 79.5, 79.5)


def _reasons(result) -> list[str]:
    return [REASONS[c] for c in result.reason]


def _floor(client: int) -> int:
    col = p.createCollisionShape(p.GEOM_BOX, halfExtents=[1.0, 1.0, 0.01], physicsClientId=client)
    return p.createMultiBody(0.0, col, -1, basePosition=[0, 0, -0.01], physicsClientId=client)


def _box(client: int, size, position, quat=(0.0, 0.0, 0.0, 1.0), inertial_offset=(0, 0, 0)):
    """A dynamic box as ``pipeline.simulation.heap`` makes them (GEOM_BOX, density x volume)."""
    half = (np.asarray(size, float) / 2).tolist()
    col = p.createCollisionShape(p.GEOM_BOX, halfExtents=half, physicsClientId=client)
    vis = p.createVisualShape(p.GEOM_BOX, halfExtents=half, physicsClientId=client)
    return p.createMultiBody(
        DENSITY * float(np.prod(size)),
        col,
        vis,
        basePosition=position,
        baseOrientation=quat,
        baseInertialFramePosition=list(inertial_offset),
        physicsClientId=client,
    )


def _images(client, intr, T_world_cam, floor, bodies, renderer):
    """Depth and instance mask (k for ``bodies[k-1]``) of the scene."""
    frame = render_depth(
        client,
        intr,
        T_world_cam,
        0.1,
        2.0,
        renderer=renderer,
        ground=(0.0, floor),
        bodies=bodies if renderer == "raycast" else None,
    )
    lut = np.zeros(max(int(frame.body_ids.max()), max(bodies)) + 2, np.uint8)
    for k, body in enumerate(bodies, start=1):
        lut[body + 1] = k
    return frame.depth_m, lut[frame.body_ids + 1]


# --- (a) boxes: the same labels as the analytic model -----------------------------------------

BIG, THIN, CUBE = (0.145, 0.092, 0.05), (0.03, 0.03, 0.004), (0.06, 0.06, 0.07)
TILT = np.radians(30.0)  # the cube leans 30 deg about world x


@pytest.fixture
def box_scene(client):
    """BIG flat on the floor at the origin (top at z = 0.05, camera z 0.5); THIN lying on it at
    (-40, 20) mm (over x in [-55, -25], y in [5, 35] mm); CUBE at (0, -100) mm, turned 30 deg
    about world x, so that its +y face (normal (0, cos 30, sin 30), 60 deg from vertical) faces
    up and towards the camera."""
    floor = _floor(client)
    bodies = [
        _box(client, BIG, [0, 0, 0.025]),
        _box(client, THIN, [-0.04, 0.02, 0.052]),
        _box(client, CUBE, [0.0, -0.1, 0.06], p.getQuaternionFromEuler([TILT, 0, 0])),
    ]
    depth, mask = _images(client, INTR_BOX, T_DOWN, floor, bodies, "raycast")
    T_cam_world = np.linalg.inv(T_DOWN)
    boxes = []
    for body, size in zip(bodies, (BIG, THIN, CUBE)):
        pos, quat = p.getBasePositionAndOrientation(body, physicsClientId=client)
        boxes.append(NS(size=np.array(size), T_cam_box=T_cam_world @ pose_matrix(pos, quat)))
    return NS(client=client, bodies=bodies, boxes=boxes, depth=depth, mask=mask)


def _cam(points_world) -> np.ndarray:
    T = np.linalg.inv(T_DOWN)
    return np.asarray(points_world, float) @ T[:3, :3].T + T[:3, 3]


def _cam_dir(dirs_world) -> np.ndarray:
    return np.asarray(dirs_world, float) @ np.linalg.inv(T_DOWN)[:3, :3].T


def _both(scene, points_cam, axes_cam, **kw):
    boxes = BoxScene(scene.depth, scene.mask, INTR_BOX, DOWN, scene.boxes)
    analytic = evaluate_contacts(points_cam, axes_cam, boxes, CFG)
    bodies = BodyScene(scene.depth, scene.mask, INTR_BOX, DOWN, T_DOWN, scene.client, scene.bodies)
    mesh = evaluate_contacts_mesh(points_cam, axes_cam, bodies, CFG, **kw)
    return analytic, mesh


_S5, _C5 = np.sin(np.radians(5.0)), np.cos(np.radians(5.0))
_N_CUBE_Y = np.array([0.0, np.cos(TILT), np.sin(TILT)])  # the cube's +y face normal (world)
_CUBE_Y_FACE = np.array([0.0, -0.1, 0.06]) + 0.03 * _N_CUBE_Y

# (world point, world approach axis, expected reason, expected instance, why)
NAMED = [
    (
        (0.0, 0.0, 0.05),
        (0, 0, -1),
        "ok",
        1,
        "centre of BIG's top: rim 9 mm inside 72.5 x 46 mm; m = 400 x 6.67e-4 = 0.2668 kg, weight "
        "2.617 N along a, f_N = 10.08 N; COM straight below: no torque",
    ),
    (
        (0.0705, 0.0, 0.05),
        (0, 0, -1),
        "off_face",
        1,
        "2 mm inside BIG's +x edge: the rim reaches x = 79.5 mm > 72.5 mm and misses the box",
    ),
    (
        (0.0575, 0.0, 0.05),
        (0, 0, -1),
        "bending",
        1,
        "57.5 mm from the COM: torque 0.0575 x 2.617 = 0.150 N m > r f_N = 0.0907 N m",
    ),
    (
        (0.0, 0.01, 0.05),
        (np.sin(TILT), 0, -np.cos(TILT)),
        "uneven",
        1,
        "approach tilted 30 deg on the level face: spread 2 r tan 30 deg = 10.4 mm > 3 mm",
    ),
    (
        (0.12, 0.0, 0.0),
        (0, 0, -1),
        "not_on_box",
        0,
        "the floor, 47.5 mm beyond BIG's +x edge: the first body hit is not graspable",
    ),
    (
        (-0.04, 0.0, 0.05),
        (0, 0, -1),
        "occluded",
        1,
        "on BIG 5 mm beside THIN: the centre line misses THIN, the rim point at y = 9 mm is seen "
        "through pixel v = rint(119.5 - 300 x 0.009 / 0.5) = 114, whose ray meets THIN's top at "
        "y = 5.5 / 300 x 0.496 = 9.1 mm: mask 2 there, not 1",
    ),
    (
        (-0.04, 0.02, 0.054),
        (0, 0, -1),
        "ok",
        2,
        "on THIN (the first body along the line): 15 mm half extents hold the rim; 1.4 g",
    ),
    (
        tuple(_CUBE_Y_FACE),
        tuple(-_N_CUBE_Y),
        "ok",
        3,
        "centre of CUBE's +y face (60 x 70 mm), approach along -n: m = 400 x 2.52e-4 = 0.1008 kg, "
        "W = 0.989 N; pull W cos 60 = 0.494 N, f_N = 12.21 N; shear W sin 60 = 0.856 <= 6.10 N; "
        "COM 30 mm behind the face: torque 0.03 W sin 60 = 0.0257 N m, all of it bending, "
        "<= r f_N = 0.110 N m",
    ),
    (
        (0.0725 - 0.00895, 0.0, 0.05),
        (-_S5, 0, -_C5),
        "off_face",
        1,
        "the rim crosses BIG's +x edge and lands on the +x face: see test_normal_rule_at_an_edge",
    ),
]


def test_named_candidates_on_boxes_match_the_analytic_model(box_scene):
    points = _cam([c[0] for c in NAMED])
    axes = _cam_dir([c[1] for c in NAMED])
    analytic, mesh = _both(box_scene, points, axes)
    expected = [c[2] for c in NAMED]
    assert _reasons(analytic) == expected
    assert _reasons(mesh) == expected
    assert mesh.instance.tolist() == [c[3] for c in NAMED] == analytic.instance.tolist()
    np.testing.assert_array_equal(mesh.seal, analytic.seal)
    np.testing.assert_array_equal(mesh.wrench_ok, analytic.wrench_ok)


def test_normal_rule_at_an_edge(box_scene):
    # Axis tilted 5 deg towards -x, centre 8.95 mm inside BIG's +x edge (x = 72.5 mm). The
    # ring point across the axis towards +x (ring index 8 of 16: the basis of a = (-s, 0, c) in
    # the camera frame has e2 = (-c, 0, -s)) lies r / cos 5 deg = 9.034 mm beyond the centre
    # where its line meets the top's plane: 0.084 mm past the edge. The line goes on down and
    # towards -x and enters the +x face 0.084 / tan 5 deg = 0.96 mm below the top: a hit on the
    # target, 90 deg off the top's normal. Its height along a is 0.084 / sin 5 deg = 0.96 mm more
    # than where it crossed the top's plane, r tan 5 deg = 0.79 mm above the centre's, so it is
    # +0.18 mm; the others lie within +-0.79 mm: spread 1.57 mm < 3 mm. Only the normal rule
    # (90 deg > 45 deg) tells the other face, as the analytic model's face index does.
    point = _cam([(0.0725 - 0.00895, 0.0, 0.05)])
    axis = _cam_dir([(-_S5, 0.0, -_C5)])
    analytic, mesh = _both(box_scene, point, axis)
    assert _reasons(analytic) == ["off_face"] and _reasons(mesh) == ["off_face"]
    _, lax = _both(box_scene, point, axis, max_normal_angle_deg=180.0)
    assert _reasons(lax)[0] not in ("off_face", "uneven")
    assert MAX_NORMAL_ANGLE_DEG == 45.0


def test_random_candidates_on_boxes_match_the_analytic_model(box_scene):
    # 300 points on the boxes and 100 anywhere (floor included), from the depth image, with
    # approach axes up to 20 deg off the camera ray: every reason and instance must agree.
    rng = np.random.default_rng(0)
    on = np.argwhere(box_scene.mask > 0)
    pix = np.concatenate([on[rng.choice(len(on), 300)], rng.integers(0, 240, size=(100, 2))])
    points = backproject(box_scene.depth, INTR_BOX)[pix[:, 0], pix[:, 1]].astype(np.float64)
    ray = points / np.linalg.norm(points, axis=1, keepdims=True)
    e1 = np.cross(ray, [1.0, 0.0, 0.0])
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    e2 = np.cross(ray, e1)
    tilt = rng.uniform(0.0, np.radians(20.0), len(ray))[:, None]
    phi = rng.uniform(0.0, 2 * np.pi, len(ray))[:, None]
    axes = np.cos(tilt) * ray + np.sin(tilt) * (np.cos(phi) * e1 + np.sin(phi) * e2)
    analytic, mesh = _both(box_scene, points, axes)
    np.testing.assert_array_equal(mesh.reason, analytic.reason)
    np.testing.assert_array_equal(mesh.instance, analytic.instance)
    assert len(set(_reasons(mesh))) >= 5  # the sample exercises most rules


def test_robust_quality_matches_the_analytic_model(box_scene):
    points = _cam([c[0] for c in NAMED])
    axes = _cam_dir([c[1] for c in NAMED])
    s = box_scene
    boxes = BoxScene(s.depth, s.mask, INTR_BOX, DOWN, s.boxes)
    q = robust_quality(points, axes, boxes, CFG, np.random.default_rng(5))
    bodies = BodyScene(s.depth, s.mask, INTR_BOX, DOWN, T_DOWN, s.client, s.bodies)
    with RayScene(s.client) as rays:
        qm = robust_quality_mesh(points, axes, bodies, CFG, np.random.default_rng(5), rays=rays)
        again = robust_quality_mesh(points, axes, bodies, CFG, np.random.default_rng(5), rays=rays)
    np.testing.assert_array_equal(qm, q)  # the same perturbations, labelled alike
    np.testing.assert_array_equal(qm, again)
    assert qm[0] >= 0.8 and qm[1] <= 0.1 and qm[4] == 0.0  # centre, edge, floor


def test_targets_and_a_reused_ray_scene(box_scene):
    s = box_scene
    points = _cam([(0.0, 0.0, 0.05), (-0.04, 0.02, 0.054)])
    axes = _cam_dir([(0, 0, -1), (0, 0, -1)])
    args = (BodyScene(s.depth, s.mask, INTR_BOX, DOWN, T_DOWN, s.client, s.bodies), CFG)
    free = evaluate_contacts_mesh(points, axes, *args)
    with RayScene(s.client) as rays:
        reused = evaluate_contacts_mesh(points, axes, *args, rays=rays)
        right = evaluate_contacts_mesh(
            points, axes, *args, rays=rays, targets=[s.bodies[0], s.bodies[1]]
        )
        wrong = evaluate_contacts_mesh(
            points, axes, *args, rays=rays, targets=[s.bodies[1], s.bodies[0]]
        )
    assert _reasons(free) == _reasons(reused) == _reasons(right) == ["ok", "ok"]
    # Meant for THIN, but the centre line first meets BIG (and the other way round).
    assert _reasons(wrong) == ["not_on_box", "not_on_box"] and wrong.instance.tolist() == [0, 0]
    with pytest.raises(ValueError):
        evaluate_contacts_mesh(points, axes, *args, targets=[999, 999])
    empty = evaluate_contacts_mesh(points[:0], axes[:0], *args)
    assert empty.reason.shape == (0,)


def test_ray_scene_is_exact_and_skips_a_start_inside(box_scene):
    s = box_scene
    with RayScene(s.client) as rays:
        # Straight down onto BIG's top (z = 0.05) from 0.2 m above.
        body, dist, normal = rays.cast([[0.01, 0.02, 0.25]], [[0.0, 0.0, -1.0]])
        assert body.tolist() == [s.bodies[0]] and abs(dist[0] - 0.2) < 1e-12
        np.testing.assert_allclose(normal[0], [0, 0, 1], atol=1e-12)
        # From inside BIG (z = 0.02): BIG's exit is skipped, the floor (z = 0) is next.
        body, dist, _ = rays.cast([[0.01, 0.02, 0.02]], [[0.0, 0.0, -1.0]])
        assert body[0] not in s.bodies and abs(dist[0] - 0.02) < 1e-5
        # Against THIN only, a line down through BIG misses.
        body, dist, _ = rays.cast([[0.05, 0.0, 0.25]], [[0.0, 0.0, -1.0]], want=[s.bodies[1]])
        assert body.tolist() == [-1] and np.isinf(dist[0])


def test_ray_scene_places_shapes_with_offset_frames(client):
    # A 64-gon cylinder (r = 30 mm, 100 mm long along z) whose collision frame is 20 mm up
    # from the link frame, and whose inertial frame is 50 mm along +x: link frame at
    # (0, 0, 0.5), so the cylinder spans z in [0.47, 0.57] about the axis x = y = 0.
    shape = cylinder(0.03, 0.10)
    col = p.createCollisionShape(
        p.GEOM_MESH,
        vertices=shape.vertices.tolist(),
        collisionFramePosition=[0.0, 0.0, 0.02],
        physicsClientId=client,
    )
    tube = p.createMultiBody(
        1.0,
        col,
        -1,
        basePosition=[0, 0, 0.5],
        baseInertialFramePosition=[0.05, 0, 0],
        physicsClientId=client,
    )
    # A 40 mm cube, collision frame 10 mm along +x, inertial frame 20 mm along +y: link frame at
    # (0.5, 0, 0.5), cube centred at (0.51, 0, 0.5), top at z = 0.52, x in [0.49, 0.53].
    col = p.createCollisionShape(
        p.GEOM_BOX,
        halfExtents=[0.02] * 3,
        collisionFramePosition=[0.01, 0, 0],
        physicsClientId=client,
    )
    cube = p.createMultiBody(
        1.0,
        col,
        -1,
        basePosition=[0.5, 0, 0.5],
        baseInertialFramePosition=[0, 0.02, 0],
        physicsClientId=client,
    )
    down = [[0.0, 0.0, -1.0]] * 4
    with RayScene(client) as rays:
        body, dist, _ = rays.cast(
            [[0, 0, 1.0], [0.525, 0, 1.0], [0.535, 0, 1.0], [0.06, 0, 1.0]], down
        )
        body_x, dist_x, _ = rays.cast([[0.2, 0.0, 0.5]], [[-1.0, 0.0, 0.0]])
    assert body.tolist() == [tube, cube, -1, -1]
    np.testing.assert_allclose(dist[:2], [1.0 - 0.57, 1.0 - 0.52], atol=1e-12)
    assert body_x.tolist() == [tube] and abs(dist_x[0] - (0.2 - 0.03)) < 1e-12  # a vertex on +x


def test_centre_of_mass_is_the_inertial_frame(client):
    # BIG with its inertial frame (hence its COM) 40 mm off its centre along +x. pybullet places
    # the box where the link frame says, and reports the inertial frame as the base pose; the
    # top's centre then holds 0.04 x 2.617 = 0.105 N m > r f_N = 0.0907 N m: bending.
    floor = _floor(client)
    big = _box(client, BIG, [0, 0, 0.025], inertial_offset=(0.04, 0.0, 0.0))
    np.testing.assert_allclose(
        p.getBasePositionAndOrientation(big, physicsClientId=client)[0], [0.04, 0.0, 0.025]
    )
    depth, mask = _images(client, INTR_BOX, T_DOWN, floor, [big], "raycast")
    res = evaluate_contacts_mesh(
        _cam([(0.0, 0.0, 0.05)]),
        _cam_dir([(0, 0, -1)]),
        BodyScene(depth, mask, INTR_BOX, DOWN, T_DOWN, client, [big]),
        CFG,
    )
    assert _reasons(res) == ["bending"] and res.seal.tolist() == [True]


# --- (b), (c) a cylinder lying on its side ------------------------------------------------------

SECTIONS = 64


def _lying_cylinder(client, radius: float, length: float):
    """A cylinder along world y on the floor, a flat of its 64-gon on top and at the bottom
    (turned by half a side about its axis): the top is the flat at 2 a above the floor, with
    a = R cos(pi/64) the polygon's apothem; the COM at height a."""
    floor = _floor(client)
    apothem = radius * np.cos(np.pi / SECTIONS)
    quat = p.multiplyTransforms(
        [0, 0, 0],
        p.getQuaternionFromEuler([-np.pi / 2, 0, 0]),
        [0, 0, 0],
        p.getQuaternionFromEuler([0, 0, np.pi / SECTIONS]),
    )[1]
    body = create_body(
        client, cylinder(radius, length, SECTIONS), DENSITY, 0.5, [0.0, 0.0, apothem], quat
    )
    return floor, body, apothem


@pytest.mark.parametrize(
    "radius, expected",
    [
        # Sag across the axis R - sqrt(R^2 - r^2), normal turn asin(r/R) at the rim's sides:
        (0.040, "ok"),  # 40 - sqrt(1600 - 81) = 1.03 mm <= 3 mm; 13.0 deg <= 45 deg
        (0.014, "uneven"),  # 14 - sqrt(196 - 81) = 3.28 mm > 3 mm; 40.0 deg <= 45 deg
        (0.010, "off_face"),  # 10 - sqrt(100 - 81) = 5.64 mm, but first 64.2 deg > 45 deg
    ],
)
def test_cup_on_the_top_line_of_a_lying_cylinder(client, radius, expected):
    r = CFG.cup_radius
    sag = radius - np.sqrt(radius**2 - r**2)
    assert (sag > CFG.compliance) == (expected != "ok")
    floor, body, apothem = _lying_cylinder(client, radius, 0.14)
    depth, mask = _images(client, INTR_CYL, T_DOWN, floor, [body], "tinyrenderer")
    # Cup at the top line above the COM, straight down. With the polygon's flats 5.6 deg wide
    # the rim's sides hit flats turned by 39.4 deg (R = 14 mm), not 40.0 deg, and the sag
    # differs from the circle's by under 0.02 mm.
    point = _cam([(0.0, 0.0, 2 * apothem)])
    res = evaluate_contacts_mesh(
        point,
        _cam_dir([(0, 0, -1)]),
        BodyScene(depth, mask, INTR_CYL, DOWN, T_DOWN, client, [body]),
        CFG,
    )
    assert _reasons(res) == [expected] and res.instance.tolist() == [1]
    assert res.seal.tolist() == [expected == "ok"]


def test_heavy_cylinder_held_far_from_its_com_bends(client):
    # R = 40 mm, L = 140 mm: m = 400 x (32 R^2 sin(2 pi/64)) x 0.14 = 0.2810 kg, W = 2.757 N
    # along the axis: f_N = 12.7 - 2.757 = 9.943 N, no shear. On the top line d from the COM
    # along the cylinder: c - x = (0, -d, -a) (world), F = (0, 0, -W): tau = (d W, 0, 0), across
    # a: no torsion, bending d W against r f_N = 0.0895 N m:
    # d = 50 mm: 0.138 N m > 0.0895: bending; d = 20 mm: 0.0551 N m: holds.
    floor, body, apothem = _lying_cylinder(client, 0.04, 0.14)
    assert p.getDynamicsInfo(body, -1, physicsClientId=client)[0] == pytest.approx(0.2810, abs=1e-4)
    depth, mask = _images(client, INTR_CYL, T_DOWN, floor, [body], "tinyrenderer")
    points = _cam([(0.0, d, 2 * apothem) for d in (0.05, 0.02, 0.0)])
    res = evaluate_contacts_mesh(
        points,
        _cam_dir([(0, 0, -1)] * 3),
        BodyScene(depth, mask, INTR_CYL, DOWN, T_DOWN, client, [body]),
        CFG,
    )
    assert _reasons(res) == ["bending", "ok", "ok"]
    assert res.seal.tolist() == [True, True, True]


def test_end_face_held_off_the_axis_twists(client):
    # The same cylinder seen from the side: camera 0.43 m from its +y end face (y = 70 mm),
    # looking along world -y (camera x = world -x, camera y = world -z: gravity along camera +y).
    # The cup on the flat end face, approach along -y. F = (0, 0, -W), W = 2.757 N, across the
    # axis: no pull, f_N = 12.7 N, shear W <= 6.35 N.
    # x = (25 mm, 70 mm, a) off the axis: c - x = (-0.025, -0.07, 0),
    # tau = (c - x) x F = (0.07 W, -0.025 W, 0); about a = (0, -1, 0): 0.025 W = 0.0689 N m
    # > r mu f_N = 0.05715 N m: torsion (checked before bending, 0.193 N m).
    # x on the axis: tau = (0.07 W, 0, 0): no torsion, bending 0.193 N m > r f_N = 0.1143 N m.
    floor, body, apothem = _lying_cylinder(client, 0.04, 0.14)
    T = np.eye(4)
    T[:3, :3] = np.column_stack([[-1.0, 0, 0], [0, 0, -1.0], [0, -1.0, 0]])
    T[:3, 3] = [0.0, 0.5, apothem]
    depth, mask = _images(client, INTR_CYL, T, floor, [body], "tinyrenderer")
    T_cam_world = np.linalg.inv(T)
    points = np.array([[0.025, 0.07, apothem], [0.0, 0.07, apothem]])
    points = points @ T_cam_world[:3, :3].T + T_cam_world[:3, 3]
    gravity = T_cam_world[:3, :3] @ [0.0, 0.0, -1.0]
    np.testing.assert_allclose(gravity, [0, 1, 0], atol=1e-12)
    res = evaluate_contacts_mesh(
        points,
        np.tile([0.0, 0.0, 1.0], (2, 1)),
        BodyScene(depth, mask, INTR_CYL, gravity, T, client, [body]),
        CFG,
    )
    assert _reasons(res) == ["torsion", "bending"]
    assert res.seal.tolist() == [True, True]
