"""Random non-box objects (pipeline.simulation.objects): meshes worked out by hand, sampling,
and pybullet bodies."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pybullet as p
import pytest

from pipeline.simulation.objects import (
    FAMILIES,
    ObjectSetSpec,
    create_body,
    cylinder,
    prism,
    regular_polygon,
    sample_object,
)


def test_cylinder_volume_and_inertia_by_hand():
    # r = 30 mm, h = 100 mm, drawn as a 64-gon: the polygon's area is (n/2) r^2 sin(2 pi/n)
    # = 32 x 9e-4 x sin(5.625 deg) = 2.8229e-3 m^2 (pi r^2 = 2.8274e-3: 0.16 % more), so
    # V = 2.8229e-4 m^3.
    r, h, n = 0.03, 0.10, 64
    shape = cylinder(r, h, sections=n)
    polygon_area = n / 2 * r**2 * np.sin(2 * np.pi / n)
    assert shape.volume == pytest.approx(polygon_area * h, rel=1e-12)
    assert shape.volume == pytest.approx(np.pi * r**2 * h, rel=(2 * np.pi / n) ** 2 / 6 * 1.01)
    assert shape.family == "cylinder"
    np.testing.assert_allclose(shape.extents, [2 * r, 2 * r, h], atol=1e-12)
    # Inertia per unit density about the centre. A regular n-gon of circumradius r and area A
    # has the polar moment J = A r^2 (1 + 2 cos^2(pi/n)) / 6, and J / 2 about any diameter; so
    # I_zz = V r^2 (1 + 2 cos^2(pi/n)) / 6 and I_xx = I_yy = I_zz / 2 + V h^2 / 12.
    V = polygon_area * h
    izz = V * r**2 * (1 + 2 * np.cos(np.pi / n) ** 2) / 6
    np.testing.assert_allclose(shape.inertia, [izz / 2 + V * h**2 / 12] * 2 + [izz], rtol=1e-9)
    # The solid circular cylinder's, V r^2 / 2 and V (3 r^2 + h^2) / 12, are within 0.4 %.
    Vc = np.pi * r**2 * h
    np.testing.assert_allclose(
        shape.inertia, [Vc * (3 * r**2 + h**2) / 12] * 2 + [Vc * r**2 / 2], rtol=4e-3
    )


def test_prism_volumes_by_hand():
    # Right triangle with legs 30 and 40 mm: area 0.5 x 0.03 x 0.04 = 6e-4 m^2; x 0.1 m.
    tri = prism([[0.0, 0.0], [0.03, 0.0], [0.0, 0.04]], 0.10)
    assert tri.volume == pytest.approx(6e-5, rel=1e-12)
    # Its centre of mass (the triangle's centroid, (10, 13.3) mm) is moved to the origin.
    assert np.abs(tri.mesh().center_mass).max() < 1e-9
    # Regular hexagon of circumradius 30 mm: area 3 x 0.03^2 x sin 60 deg = 2.3383e-3 m^2; x 50 mm
    hexagon = prism(regular_polygon(6, 0.03), 0.05)
    assert hexagon.volume == pytest.approx(3 * 0.03**2 * np.sin(np.pi / 3) * 0.05, rel=1e-12)
    # Vertex to vertex 60 mm along x, flat to flat 2 x 30 cos 30 deg = 51.96 mm along y.
    np.testing.assert_allclose(hexagon.extents, [0.06, 0.06 * np.cos(np.pi / 6), 0.05], atol=1e-12)


def test_sampled_objects_are_closed_convex_and_centred():
    rng = np.random.default_rng(7)
    spec = ObjectSetSpec()
    shapes = [sample_object(rng, spec) for _ in range(30)]
    assert {s.family for s in shapes} == set(FAMILIES)
    for s in shapes:
        mesh = s.mesh()
        assert mesh.is_watertight and mesh.is_convex, s.family
        assert np.linalg.norm(mesh.center_mass) < 1e-9, s.family
        assert s.volume == pytest.approx(mesh.volume, rel=1e-12) and s.volume > 0
        # Principal axes: the inertia tensor is diagonal in the object frame.
        tensor = mesh.moment_inertia
        assert np.abs(tensor - np.diag(np.diag(tensor))).max() < 1e-9 * np.trace(tensor)
        np.testing.assert_allclose(s.inertia, np.diag(tensor), rtol=1e-9)
        np.testing.assert_allclose(s.extents, np.ptp(s.vertices, axis=0), atol=1e-15)
        # Comparable to the boxes: no edge of the bounding box over 15 cm, the largest over 1 cm.
        assert s.extents.max() <= 0.15 + 1e-9 and s.extents.max() >= 0.01, s.family
        assert s.vertices.shape[1] == 3 and s.faces.shape[1] == 3
    # An irregular prism keeps its axis along z: its length is one of the drawn lengths.
    prisms = [s for s in shapes if s.family == "prism"]
    for s in prisms:
        assert spec.prism_length[0] <= s.extents[2] <= spec.prism_length[1]


def test_same_seed_same_object():
    spec = ObjectSetSpec()
    for seed in range(6):
        a = sample_object(np.random.default_rng(seed), spec)
        b = sample_object(np.random.default_rng(seed), spec)
        assert a.family == b.family
        np.testing.assert_array_equal(a.vertices, b.vertices)
        np.testing.assert_array_equal(a.faces, b.faces)
    one = replace(spec, families=("hull",))
    a, b = (sample_object(np.random.default_rng(s), one) for s in (0, 1))
    assert a.vertices.shape != b.vertices.shape or not np.array_equal(a.vertices, b.vertices)
    with pytest.raises(ValueError):
        sample_object(np.random.default_rng(0), replace(spec, families=("box",)))


def test_body_falls_onto_a_plane_and_rests(client):
    p.setGravity(0, 0, -9.81, physicsClientId=client)
    p.setPhysicsEngineParameter(fixedTimeStep=1 / 240, physicsClientId=client)
    plane = p.createCollisionShape(p.GEOM_BOX, halfExtents=[1.0, 1.0, 0.01], physicsClientId=client)
    ground = p.createMultiBody(0.0, plane, -1, basePosition=[0, 0, -0.01], physicsClientId=client)
    p.changeDynamics(ground, -1, lateralFriction=0.5, physicsClientId=client)
    rng = np.random.default_rng(3)
    spec = ObjectSetSpec(families=("hull",))
    shape = sample_object(rng, spec)
    density = 400.0
    body = create_body(
        client, shape, density, 0.5, [0.0, 0.0, 0.2], p.getQuaternionFromEuler([0.3, 0.2, 0.1])
    )
    info = p.getDynamicsInfo(body, -1, physicsClientId=client)
    assert info[0] == pytest.approx(density * shape.volume, rel=1e-12)
    assert info[1] == pytest.approx(0.5)
    np.testing.assert_allclose(info[2], density * shape.inertia, rtol=1e-9)
    assert info[3] == (0.0, 0.0, 0.0)  # inertial frame = object frame: the COM is the origin
    for _ in range(720):  # 3 s
        p.stepSimulation(physicsClientId=client)
    before = np.array(p.getBasePositionAndOrientation(body, physicsClientId=client)[0])
    for _ in range(120):  # 0.5 s more
        p.stepSimulation(physicsClientId=client)
    after = np.array(p.getBasePositionAndOrientation(body, physicsClientId=client)[0])
    lin, ang = p.getBaseVelocity(body, physicsClientId=client)
    assert np.linalg.norm(after - before) < 1e-4
    assert np.linalg.norm(lin) < 1e-3 and np.linalg.norm(ang) < 1e-2
    # Resting on the plane: its lowest vertex (world frame) within the 1 mm collision margin
    # (and contact slop) above z = 0, and the COM above it.
    R = np.array(
        p.getMatrixFromQuaternion(p.getBasePositionAndOrientation(body, physicsClientId=client)[1])
    ).reshape(3, 3)
    lowest = (shape.vertices @ R.T + after)[:, 2].min()
    assert -1e-3 < lowest < 2.5e-3
    assert after[2] > lowest


def test_body_is_drawn_by_the_renderer(client):
    shape = cylinder(0.03, 0.08)
    body = create_body(client, shape, 400.0, 0.5, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0])
    view = p.computeViewMatrix([0, 0, 0.5], [0, 0, 0], [0, 1, 0])
    proj = p.computeProjectionMatrixFOV(40.0, 1.0, 0.1, 2.0)
    _, _, _, _, seg = p.getCameraImage(
        32, 32, view, proj, renderer=p.ER_TINY_RENDERER, physicsClientId=client
    )
    seg = np.asarray(seg).reshape(32, 32)
    # The 60 mm disc, 0.46 m from the camera, with a 40 deg field of view over 32 pixels:
    # 2 x 0.46 tan 20 deg / 32 = 10.5 mm a pixel, a disc 5.7 pixels across: about 26 pixels.
    assert seg[16, 16] == body and 15 < (seg == body).sum() < 40
