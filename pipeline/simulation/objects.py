"""Random rigid objects other than boxes, for training a suction planner out of domain.

Dex-Net 4.0 trained its GQ-CNN on heaps of objects unlike the test objects. This module makes
such objects: convex solids of three families, in random sizes comparable to the project's
boxes (edges of about 2 to 15 cm, ``conf/boxes/paper.yaml``), built with trimesh, and puts them
into a pybullet scene as dynamic bodies.

Families (``ObjectSetSpec.families``):

- ``cylinder``: a circular solid, radius r, length h along its own z axis, its circle drawn as a
  regular polygon of ``cylinder_sections`` sides (``trimesh.creation.cylinder``; volume
  ``(n/2) r^2 sin(2 pi/n) h``, 0.16 % under ``pi r^2 h`` for n = 64).
- ``prism``: a right prism of length h along its own z axis over a convex polygon of 3 to 8
  sides: regular (vertices on a circle at equal angles) or irregular (vertices on a circle at
  jittered angles, then the polygon squeezed along one axis, which keeps it convex). Volume:
  polygon area x h.
- ``hull``: an irregular convex solid, the convex hull (``trimesh.convex.convex_hull``, which
  uses scipy's Qhull) of random points drawn in the shell between 0.6 and 1.0 of an ellipsoid
  with random semi-axes (a shell rather than the whole ellipsoid keeps the hull from coming out
  much smaller than the ellipsoid).

Object frame: every ``ObjectShape`` is expressed in its own frame, whose origin is the solid's
centre of mass (uniform density) and whose axes are its principal axes of inertia, so that the
inertia tensor is diagonal there (cylinders and regular prisms are already in such a frame;
irregular prisms and hulls are rotated into it). Units: metres, cubic metres, kilograms.

In pybullet (``create_body``) the body's base frame is the object frame: the inertial frame is
the identity (origin = centre of mass), so ``p.getBasePositionAndOrientation`` returns the pose
of the object frame and the position of the centre of mass. The collision shape is the convex
hull of the vertices (``GEOM_MESH`` from vertices, which pybullet always treats as convex, with
its default 1 mm collision margin); the visual shape is the same triangle mesh, which pybullet's
TinyRenderer draws. The exact inertia (trimesh's, times the density) replaces pybullet's, which
it would otherwise take from the bounding box.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pybullet as p
import trimesh

FAMILIES = ("cylinder", "prism", "hull")


@dataclass
class ObjectSetSpec:
    """Shape families and size ranges of a set of random objects (metres).

    Every ``(low, high)`` range is sampled uniformly; integer ranges are inclusive.

    Attributes:
        families: the families to draw from (``FAMILIES``), each equally likely.
        cylinder_radius: radius of a cylinder, m.
        cylinder_length: length of a cylinder along its axis, m.
        cylinder_sections: sides of the polygon that draws a cylinder's circle.
        prism_sides: number of sides of a prism's base polygon (3 = triangle ... 8 = octagon).
        prism_radius: radius of the circle the base polygon's vertices lie on, m.
        prism_length: length of a prism along its axis, m.
        prism_regular_share: probability that a prism's base is a regular polygon.
        prism_jitter: an irregular base's vertex angles are ``2 pi (k + j) / n`` with ``j``
            uniform in ``[-prism_jitter, prism_jitter]`` (< 0.5 keeps the vertices in order).
        prism_squeeze: an irregular base is then scaled along a random in-plane direction by a
            factor drawn from this range.
        hull_semi_axis: each semi-axis of a hull's ellipsoid, m.
        hull_points: number of random points whose convex hull is the solid.
    """

    families: tuple[str, ...] = FAMILIES
    cylinder_radius: tuple[float, float] = (0.015, 0.05)
    cylinder_length: tuple[float, float] = (0.02, 0.15)
    cylinder_sections: int = 64
    prism_sides: tuple[int, int] = (3, 8)
    prism_radius: tuple[float, float] = (0.02, 0.06)
    prism_length: tuple[float, float] = (0.02, 0.15)
    prism_regular_share: float = 0.5
    prism_jitter: float = 0.3
    prism_squeeze: tuple[float, float] = (0.5, 1.0)
    hull_semi_axis: tuple[float, float] = (0.015, 0.075)
    hull_points: tuple[int, int] = (8, 40)


@dataclass
class ObjectShape:
    """One convex rigid object in its own frame (origin at the centre of mass, principal axes).

    Attributes:
        family: ``"cylinder"``, ``"prism"`` or ``"hull"``.
        vertices: (V, 3) float64 vertex positions in the object frame, m.
        faces: (F, 3) int64 vertex indices of the triangles, counter-clockwise seen from outside
            (outward normals).
        volume: m^3.
        extents: (3,) edge lengths of the axis-aligned bounding box in the object frame, m.
        inertia: (3,) principal moments of inertia about the centre of mass per unit density
            (the diagonal of the inertia tensor in the object frame), m^5; times the density in
            kg/m^3 they are kg m^2.
    """

    family: str
    vertices: np.ndarray
    faces: np.ndarray
    volume: float
    extents: np.ndarray
    inertia: np.ndarray

    def mesh(self) -> trimesh.Trimesh:
        """The shape as a trimesh (a copy; processing off, so vertices and faces stay as they
        are)."""
        return trimesh.Trimesh(self.vertices.copy(), self.faces.copy(), process=False)


def _nearest_axes(axes: np.ndarray) -> np.ndarray:
    """The principal axes ``axes`` ((3, 3), one per column, any order and sign) reordered and
    signed to be as close as possible to the current x, y, z axes, as a rotation (det +1): an
    axis that is principal already (a prism's z) stays where it is."""
    perms = ((0, 1, 2), (0, 2, 1), (1, 0, 2), (1, 2, 0), (2, 0, 1), (2, 1, 0))
    best = max(perms, key=lambda q: float(np.abs(axes[[0, 1, 2], list(q)]).sum()))
    out = axes[:, list(best)].copy()
    out *= np.where(np.diag(out) < 0.0, -1.0, 1.0)[None, :]
    if np.linalg.det(out) < 0.0:
        k = int(np.argmin(np.abs(np.diag(out))))
        out[:, k] *= -1.0
    return out


def _object_shape(family: str, mesh: trimesh.Trimesh) -> ObjectShape:
    """The ``ObjectShape`` of a closed convex mesh, moved so that its centre of mass is the
    origin and turned so that its principal axes of inertia are the frame's axes (when the
    inertia tensor is not diagonal already: a rotation is only applied where needed, so that a
    cylinder keeps its axis along z)."""
    if not mesh.is_watertight or mesh.volume <= 0.0:
        raise ValueError(f"a {family} mesh must be closed with outward faces")
    vertices = np.asarray(mesh.vertices, np.float64) - np.asarray(mesh.center_mass, np.float64)
    mesh = trimesh.Trimesh(vertices, np.asarray(mesh.faces), process=False)
    inertia = np.asarray(mesh.moment_inertia, np.float64)  # about the COM, unit density
    off_diagonal = np.abs(inertia - np.diag(np.diag(inertia))).max()
    if off_diagonal > 1e-9 * np.trace(inertia):
        axes = _nearest_axes(np.linalg.eigh(inertia)[1])
        vertices = vertices @ axes  # coordinates along the principal axes
        mesh = trimesh.Trimesh(vertices, np.asarray(mesh.faces), process=False)
        vertices = vertices - np.asarray(mesh.center_mass, np.float64)  # rounding only
        mesh = trimesh.Trimesh(vertices, np.asarray(mesh.faces), process=False)
        inertia = np.asarray(mesh.moment_inertia, np.float64)
    return ObjectShape(
        family=family,
        vertices=np.asarray(mesh.vertices, np.float64).copy(),
        faces=np.asarray(mesh.faces, np.int64).copy(),
        volume=float(mesh.volume),
        extents=np.asarray(mesh.extents, np.float64).copy(),
        inertia=np.diag(inertia).copy(),
    )


def cylinder(radius: float, length: float, sections: int = 64) -> ObjectShape:
    """A cylinder of ``radius`` and ``length`` (m) along the object z axis; its circle is a
    regular polygon of ``sections`` sides inscribed in the circle, with a vertex on +x."""
    mesh = trimesh.creation.cylinder(
        radius=float(radius), height=float(length), sections=int(sections)
    )
    return _object_shape("cylinder", mesh)


def prism(polygon_xy: np.ndarray, length: float) -> ObjectShape:
    """A right prism of ``length`` (m) along the object z axis over the convex polygon
    ``polygon_xy`` ((n, 2) vertices in order, m); moved so that its centre of mass is the
    origin (and turned about z onto its principal axes when the polygon is irregular)."""
    xy = np.asarray(polygon_xy, np.float64).reshape(-1, 2)
    if len(xy) < 3:
        raise ValueError(f"a prism needs a polygon of at least 3 vertices, not {len(xy)}")
    h = float(length) / 2.0
    points = np.concatenate(
        [np.column_stack([xy, np.full(len(xy), -h)]), np.column_stack([xy, np.full(len(xy), h)])]
    )
    return _object_shape("prism", trimesh.convex.convex_hull(points))


def convex_solid(points: np.ndarray) -> ObjectShape:
    """The convex hull of (n, 3) points (m), as an object of family ``hull``."""
    return _object_shape("hull", trimesh.convex.convex_hull(np.asarray(points, np.float64)))


def regular_polygon(sides: int, radius: float) -> np.ndarray:
    """(sides, 2) vertices of a regular polygon inscribed in a circle of ``radius`` (m) about
    the origin, counter-clockwise from +x. Its area is ``(sides/2) radius^2 sin(2 pi/sides)``."""
    angles = 2.0 * np.pi * np.arange(int(sides)) / int(sides)
    return float(radius) * np.column_stack([np.cos(angles), np.sin(angles)])


def _uniform(rng: np.random.Generator, bounds) -> float:
    low, high = (float(b) for b in bounds)
    if high < low:
        raise ValueError(f"range {bounds} has high < low")
    return float(rng.uniform(low, high))


def _integer(rng: np.random.Generator, bounds) -> int:
    low, high = (int(b) for b in bounds)
    if high < low:
        raise ValueError(f"range {bounds} has high < low")
    return int(rng.integers(low, high + 1))


def sample_object(rng: np.random.Generator, spec: ObjectSetSpec) -> ObjectShape:
    """One random object of ``spec``'s families and sizes.

    Random draws, in this order: the family; then for a cylinder its radius and length; for a
    prism its number of sides, radius, length, whether it is regular and, if not, its vertex
    angle jitters, squeeze direction and squeeze factor; for a hull its three semi-axes, number
    of points, their directions and their radii. The same generator state gives the same object.
    """
    families = tuple(spec.families)
    unknown = sorted(set(families) - set(FAMILIES))
    if not families or unknown:
        raise ValueError(f"families must be a non-empty selection of {FAMILIES}, not {families}")
    family = families[int(rng.integers(len(families)))]
    if family == "cylinder":
        radius = _uniform(rng, spec.cylinder_radius)
        length = _uniform(rng, spec.cylinder_length)
        return cylinder(radius, length, spec.cylinder_sections)
    if family == "prism":
        sides = _integer(rng, spec.prism_sides)
        if sides < 3:
            raise ValueError(f"prism_sides must be >= 3, not {spec.prism_sides}")
        radius = _uniform(rng, spec.prism_radius)
        length = _uniform(rng, spec.prism_length)
        if rng.uniform() < spec.prism_regular_share:
            return prism(regular_polygon(sides, radius), length)
        jitter = rng.uniform(-spec.prism_jitter, spec.prism_jitter, size=sides)
        angles = 2.0 * np.pi * (np.arange(sides) + jitter) / sides
        xy = radius * np.column_stack([np.cos(angles), np.sin(angles)])
        phi = rng.uniform(0.0, np.pi)
        squeeze = _uniform(rng, spec.prism_squeeze)
        u = np.array([np.cos(phi), np.sin(phi)])
        xy = xy + (squeeze - 1.0) * np.outer(xy @ u, u)  # scale along u, keep across u
        return prism(xy, length)
    semi = np.array([_uniform(rng, spec.hull_semi_axis) for _ in range(3)])
    count = _integer(rng, spec.hull_points)
    if count < 4:
        raise ValueError(f"hull_points must be >= 4, not {spec.hull_points}")
    directions = rng.normal(size=(count, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    radii = rng.uniform(0.6, 1.0, size=(count, 1))
    return convex_solid(directions * radii * semi)


def create_body(
    client: int,
    shape: ObjectShape,
    density: float,
    friction: float,
    position,
    orientation,
    *,
    friction_anchor: bool = False,
    rgba=(0.8, 0.6, 0.4, 1.0),
) -> int:
    """Put ``shape`` into the pybullet simulation ``client`` as a dynamic rigid body.

    Mimics ``pipeline.simulation.heap``'s boxes: mass ``density x volume``, lateral friction
    ``friction`` and friction anchor set with ``p.changeDynamics``, pybullet's default
    restitution (0), the boxes' colour. In addition the inertia is the exact one
    (``density x shape.inertia``, principal moments along the object axes).

    Args:
        client: pybullet physics client id.
        shape: the object, in its frame (origin = centre of mass).
        density: kg/m^3.
        friction: lateral (Coulomb) friction coefficient.
        position: (3,) world position of the object frame's origin (the centre of mass), m.
        orientation: (4,) world orientation of the object frame, unit quaternion (x, y, z, w).
        friction_anchor: pybullet's friction anchor (``physics.friction_anchor`` for heaps).
        rgba: colour of the visual shape.

    Returns:
        The body's unique id. Its base (and inertial) frame is the object frame.
    """
    vertices = np.asarray(shape.vertices, np.float64)
    col = p.createCollisionShape(p.GEOM_MESH, vertices=vertices.tolist(), physicsClientId=client)
    vis = p.createVisualShape(
        p.GEOM_MESH,
        vertices=vertices.tolist(),
        indices=np.asarray(shape.faces, np.int64).reshape(-1).tolist(),
        rgbaColor=list(rgba),
        physicsClientId=client,
    )
    mass = float(density) * float(shape.volume)
    body = p.createMultiBody(
        mass,
        col,
        vis,
        basePosition=list(map(float, position)),
        baseOrientation=list(map(float, orientation)),
        baseInertialFramePosition=[0.0, 0.0, 0.0],
        baseInertialFrameOrientation=[0.0, 0.0, 0.0, 1.0],
        physicsClientId=client,
    )
    p.changeDynamics(
        body,
        -1,
        lateralFriction=float(friction),
        frictionAnchor=int(bool(friction_anchor)),
        localInertiaDiagonal=(float(density) * np.asarray(shape.inertia)).tolist(),
        physicsClientId=client,
    )
    return body
