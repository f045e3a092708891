"""The robot's model of the heap, from one depth image: columns on a grid over the bin.

The run-time check (``pipeline.controller.check``) must keep the arm and hand clear of boxes it
cannot see whole. A camera above the bin sees the heap's upper surface only; what lies under it
is unknown, so everything under an observed point is taken as occupied, down to the bin floor:

0. A pixel whose depth agrees, within ``flying_tolerance_m``, with fewer than
   ``flying_min_neighbours`` of its 8 neighbours is dropped as a flying pixel: the mixed depth a
   real camera returns where a pixel straddles an edge (a box's top and the floor behind it),
   which floats in mid-air between them and would stand as a column beside the box. Surfaces
   and straight edges keep their pixels (an edge pixel has 5 neighbours on its own face), an
   isolated value does not. A dropped pixel is no depth (step 3 covers its cell if nothing else
   does). Ideal depth has no mixed pixels; ``flying_tolerance_m`` 0 turns the step off.
1. Every pixel with depth is back-projected (``Observation.T_world_cam``) into the world frame.
   Points the static cell model explains are dropped: within ``bin_tolerance_m`` of the bin
   floor (z = 0) or of an inner wall, or outside the bin's inner walls (the rim, the walls'
   tops, the floor around the bin).
2. A grid of ``cell_m`` cells covers the bin's inner area; a cell's height is the highest point
   that falls in it, 0 where its points are all on the floor.
3. A cell with no point at all (a sensor's hole, a shadow beside a tall box) takes the highest
   of its known neighbours, repeatedly, until every cell has a height: unknown space is taken
   as occupied as high as what surrounds it.

A column covers its whole cell, so the model is conservative by up to a cell sideways, and it
never misses what the camera saw.

**Contact** (:class:`HeapCollider`): the robot's links are sampled as points on their collision
surfaces every ``cell_m`` at most (:class:`LinkSurface`, from the robot model's own primitive
shapes). A link is within ``margin`` of the heap when one of its points lies inside a column
grown by the margin: sideways by ``ceil(margin / cell_m)`` cells, upwards by ``margin``. The grown
columns are at least ``cell_m`` + 2 × margin wide, wider than the points' spacing, so no column
slips between two points of a face it enters. A link whose bounding box lies above the grown
heights under it is not sampled at all.

**The grasped surface.** The cups are meant to touch the surface they grasp: for a candidate,
the cells holding pixels of the surface the descriptor finds at it (its region) take the height
of their other points only (0 when they have none) while that candidate is checked
(:meth:`HeapModel.heights_without`). What the descriptor finds is what the servo will track; no
instance mask is used. On a noisy sensor's depth the region can stop short of the face, and the
face's other pixels, raised by the noise, stood as columns under the cups (1 cm above the face at
the grasp pose, with a 5 mm margin): with ``surface_tolerance_m`` > 0 the surface left out is the
region and every pixel connected to it through points within that distance of its plane
(:func:`plane_surface`).

Frames: world (z up, origin at the centre of the bin floor's top surface); grid rows along +y,
columns along +x, cell (0, 0) at the bin's (−x, −y) corner. Metres.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import cv2
import numpy as np
import pybullet as p

from pipeline.controller.observation import Observation


@dataclass(frozen=True)
class HeapModelConfig:
    """How the heap model is built (``evaluate.heap_model``; metres)."""

    cell_m: float  # grid cell side; the robot's surface points are this far apart at most
    bin_tolerance_m: float  # points this near the bin's floor or inner walls are the bin
    flying_tolerance_m: float  # step 0: neighbours within this depth agree (0: step off)
    flying_min_neighbours: int  # step 0: a pixel needs this many agreeing neighbours of 8
    surface_tolerance_m: float = 0.0  # the grasped surface's plane: points this near it (0: off)


@dataclass
class HeightMap:
    """The heap's height over the bin (module docstring).

    Attributes:
        heights: (ny, nx) metres above the bin floor (0: floor), every cell filled.
        observed: (ny, nx) bool, the cells that held at least one point of the image.
        cell_m: cell side, metres.
        origin: (2,) world (x, y) of cell (0, 0)'s corner.
        pixel_cell: (H, W) int, the flat cell index of each pixel's point (−1: no depth, the
            bin's or outside the grid).
        pixel_z: (H, W) float, each pixel's point's height above the floor (0 where
            ``pixel_cell`` is −1 or the point is on the floor).
    """

    heights: np.ndarray
    observed: np.ndarray
    cell_m: float
    origin: np.ndarray
    pixel_cell: np.ndarray
    pixel_z: np.ndarray

    @property
    def shape(self) -> tuple[int, int]:
        return self.heights.shape

    def cell_of(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(rows, cols) of world points ``xy`` (n, 2), clipped into the grid."""
        ij = np.floor((np.asarray(xy, np.float64) - self.origin) / self.cell_m).astype(int)
        ny, nx = self.shape
        return np.clip(ij[:, 1], 0, ny - 1), np.clip(ij[:, 0], 0, nx - 1)

    def centres(self) -> np.ndarray:
        """(ny, nx, 2) world (x, y) of every cell's centre."""
        ny, nx = self.shape
        x = self.origin[0] + (np.arange(nx) + 0.5) * self.cell_m
        y = self.origin[1] + (np.arange(ny) + 0.5) * self.cell_m
        return np.stack(np.meshgrid(x, y), axis=-1)


def agreeing_neighbours(depth: np.ndarray, tolerance: float) -> np.ndarray:
    """(H, W) int: how many of each pixel's 8 neighbours hold depth within ``tolerance`` (m)
    of its own (the image border replicated outwards; a pixel without depth has none)."""
    d = np.where(np.isfinite(depth) & (depth > 0), depth, 0.0)
    h, w = d.shape
    pad = np.pad(d, 1, mode="edge")
    count = np.zeros((h, w), np.int32)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            if dy or dx:
                nb = pad[1 + dy : 1 + dy + h, 1 + dx : 1 + dx + w]
                count += (nb > 0) & (np.abs(nb - d) <= tolerance)
    return np.where(d > 0, count, 0)


def drop_flying_pixels(depth: np.ndarray, cfg: HeapModelConfig) -> np.ndarray:
    """``depth`` (H, W, m) with its flying pixels set to 0 (no depth): module docstring, step 0."""
    if float(cfg.flying_tolerance_m) <= 0:
        return depth
    keep = agreeing_neighbours(depth, float(cfg.flying_tolerance_m)) >= int(
        cfg.flying_min_neighbours
    )
    return np.where(keep, depth, 0.0)


@functools.lru_cache(maxsize=4)
def _ray_factors(intr, h: int, w: int) -> tuple[np.ndarray, np.ndarray]:
    """((1, W) (u − cx) / fx, (H, 1) (v − cy) / fy): a pixel's camera x and y per metre of
    depth (``pipeline.camera.geometry.backproject_pixels``'s factors), once per camera."""
    ax = (np.arange(w, dtype=np.float64) - intr.cx) / intr.fx
    ay = (np.arange(h, dtype=np.float64) - intr.cy) / intr.fy
    for a in (ax, ay):
        a.flags.writeable = False
    return ax[None, :], ay[:, None]


def camera_points(obs: Observation) -> tuple[tuple[np.ndarray, np.ndarray, np.ndarray], np.ndarray]:
    """((x, y, z), valid): the camera-frame coordinates (H, W) each of every pixel's point,
    metres, and the (H, W) bool of pixels with depth (the others are at the camera's centre)."""
    depth = np.asarray(obs.depth_m, np.float64)
    h, w = depth.shape
    valid = np.isfinite(depth) & (depth > 0)
    ax, ay = _ray_factors(obs.intrinsics, h, w)
    z = np.where(valid, depth, 0.0)
    return (ax * z, ay * z, z), valid


def world_points(obs: Observation) -> tuple[tuple[np.ndarray, np.ndarray, np.ndarray], np.ndarray]:
    """((x, y, z), valid): the world coordinates (H, W) each of every pixel's point, and the
    (H, W) bool of pixels with depth (the others are at the camera's centre)."""
    (x, y, z), valid = camera_points(obs)
    R, t = obs.T_world_cam[:3, :3], obs.T_world_cam[:3, 3]
    world = tuple(x * R[i, 0] + y * R[i, 1] + z * R[i, 2] + t[i] for i in range(3))
    return world, valid


def build_heightmap(obs: Observation, bin_cfg, cfg: HeapModelConfig) -> HeightMap:
    """The height map of the heap in ``obs`` (module docstring, steps 0–3). ``bin_cfg``: the
    static bin (``conf/bin/``: ``inner_length_x``, ``inner_width_y``)."""
    hx, hy = float(bin_cfg.inner_length_x) / 2, float(bin_cfg.inner_width_y) / 2
    cell, tol = float(cfg.cell_m), float(cfg.bin_tolerance_m)
    nx, ny = int(np.ceil(2 * hx / cell - 1e-9)), int(np.ceil(2 * hy / cell - 1e-9))
    origin = np.array([-hx, -hy])
    (x, y, z), valid = world_points(obs)
    valid &= drop_flying_pixels(np.asarray(obs.depth_m, np.float64), cfg) > 0
    inside = valid & (np.abs(x) < hx) & (np.abs(y) < hy)
    on_bin = (np.abs(x) > hx - tol) | (np.abs(y) > hy - tol)  # the inner walls' band
    use = inside & ~on_bin
    col = np.clip(np.floor((x - origin[0]) / cell).astype(int), 0, nx - 1)
    row = np.clip(np.floor((y - origin[1]) / cell).astype(int), 0, ny - 1)
    flat = np.where(use, row * nx + col, -1)
    above = use & (z > tol)
    pixel_z = np.where(above, z, 0.0)
    heights = np.zeros(ny * nx)
    np.maximum.at(heights, flat[above], z[above])
    observed = np.bincount(flat[use], minlength=ny * nx) > 0
    heights = fill_unknown(heights.reshape(ny, nx), observed.reshape(ny, nx))
    return HeightMap(heights, observed.reshape(ny, nx), cell, origin, flat, pixel_z)


def fill_unknown(heights: np.ndarray, known: np.ndarray) -> np.ndarray:
    """``heights`` (ny, nx) with every cell not ``known`` given the highest height of its known
    8-neighbours, in rings from the known cells inwards (a cell filled in one ring counts as
    known for the next); all cells unknown: zeros."""
    h = np.where(known, heights, -np.inf)
    known = known.copy()
    if not known.any():
        return np.zeros_like(heights)
    while not known.all():
        padded = np.pad(h, 1, constant_values=-np.inf)
        ny, nx = h.shape
        best = np.max(
            [
                padded[1 + dy : 1 + dy + ny, 1 + dx : 1 + dx + nx]
                for dy in (-1, 0, 1)
                for dx in (-1, 0, 1)
            ],
            axis=0,
        )
        new = ~known & np.isfinite(best)
        h = np.where(new, best, h)
        known = known | new
    return h


def plane_surface(
    obs: Observation,
    region: np.ndarray,
    centre_cam: np.ndarray,
    normal_cam: np.ndarray,
    tolerance_m: float,
) -> np.ndarray:
    """(H, W) bool: ``region`` and every pixel connected to it (8-neighbours) through pixels
    whose point lies within ``tolerance_m`` of the surface's plane (through ``centre_cam``,
    normal ``normal_cam``; home camera frame, metres): the rest of the grasped face where the
    descriptor's region, grown on a noisy sensor's depth, stopped short of it."""
    (x, y, z), valid = camera_points(obs)
    n = np.asarray(normal_cam, np.float64)
    n = n / np.linalg.norm(n)
    dist = x * n[0] + y * n[1] + z * n[2] - float(n @ np.asarray(centre_cam))
    near = (valid & (np.abs(dist) <= tolerance_m)) | region
    _, labels = cv2.connectedComponents(near.astype(np.uint8), connectivity=8)
    touched = np.unique(labels[region])
    return np.isin(labels, touched[touched > 0])


class HeapModel:
    """The height map of the latest home observation, and its variants without a surface."""

    def __init__(self, bin_cfg, cfg: HeapModelConfig) -> None:
        self.bin_cfg, self.cfg = bin_cfg, cfg
        self.map: HeightMap | None = None

    def update(self, obs: Observation) -> HeightMap:
        """The height map of ``obs`` (the home image of a new plan)."""
        self.map = build_heightmap(obs, self.bin_cfg, self.cfg)
        return self.map

    def heights_without(self, region: np.ndarray | None) -> np.ndarray:
        """The map's heights (ny, nx) with the pixels of ``region`` ((H, W) bool, the grasped
        surface; None: none) left out: each cell holding a region pixel takes the highest of its
        other points above the floor (0 when none)."""
        m = self.map
        if m is None:
            raise RuntimeError("HeapModel.update(observation) must come before a check")
        if region is None:
            return m.heights
        cells = np.unique(m.pixel_cell[region & (m.pixel_cell >= 0)])
        heights = m.heights.copy().ravel()
        if len(cells) == 0:
            return heights.reshape(m.shape)
        keep = (m.pixel_cell >= 0) & ~region & np.isin(m.pixel_cell, cells)
        redo = np.zeros_like(heights)
        np.maximum.at(redo, m.pixel_cell[keep], m.pixel_z[keep])
        heights[cells] = redo[cells]
        return heights.reshape(m.shape)


class HeapCollider:
    """Which world points lie within ``margin`` of the heap's columns ``heights``."""

    def __init__(
        self, heights: np.ndarray, origin: np.ndarray, cell_m: float, margin: float
    ) -> None:
        """``heights``: (ny, nx) metres above the floor; ``origin``: (2,) world (x, y) of cell
        (0, 0)'s corner; ``margin``: metres."""
        k = int(math.ceil(margin / cell_m - 1e-9))
        h = np.where(heights > 0, heights + margin, -np.inf)
        padded = np.pad(h, k, constant_values=-np.inf)
        ny, nx = h.shape
        self.grown = np.max(
            [
                padded[k + dy : k + dy + ny, k + dx : k + dx + nx]
                for dy in range(-k, k + 1)
                for dx in range(-k, k + 1)
            ],
            axis=0,
        )
        self.origin, self.cell, self.k = np.asarray(origin, np.float64), float(cell_m), k
        self.top = float(self.grown.max()) if np.isfinite(self.grown).any() else -np.inf

    def _cells(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(rows, cols, inside) of world points (n, 2): ``inside`` false off the grid."""
        ij = np.floor((xy - self.origin) / self.cell).astype(int)
        ny, nx = self.grown.shape
        inside = (ij[:, 0] >= 0) & (ij[:, 0] < nx) & (ij[:, 1] >= 0) & (ij[:, 1] < ny)
        return np.clip(ij[:, 1], 0, ny - 1), np.clip(ij[:, 0], 0, nx - 1), inside

    def may_touch(self, lo, hi) -> bool:
        """Whether a box from ``lo`` to ``hi`` (world (3,) corners) may reach a grown column:
        false when its bottom lies above every grown height under its footprint."""
        if lo[2] >= self.top:
            return False
        rows, cols, _ = self._cells(np.array([[lo[0], lo[1]], [hi[0], hi[1]]]))
        under = self.grown[rows[0] : rows[1] + 1, cols[0] : cols[1] + 1]
        return under.size > 0 and lo[2] < float(under.max())

    def hits(self, points: np.ndarray) -> bool:
        """Whether one of ``points`` (n, 3) world lies inside a grown column."""
        rows, cols, inside = self._cells(points[:, :2])
        return bool(np.any(inside & (points[:, 2] < self.grown[rows, cols])))


class LinkSurface:
    """Points on each link's collision surface, every ``spacing`` metres at most, in the
    link's centre-of-mass frame (pybullet's frame for its collision shapes): boxes and
    cylinders, the primitives of the project's robot (``pipeline.robot.urdf_builder``)."""

    def __init__(self, robot, spacing: float) -> None:
        self.points: dict[int, np.ndarray] = {}
        for link in robot._links:
            if link == -1:
                continue  # the fixed base stands where it stands (Robot.in_collision)
            pts = []
            for shape in p.getCollisionShapeData(robot.body_id, link, physicsClientId=robot.client):
                geom, dims, pos, orn = shape[2], shape[3], shape[5], shape[6]
                local = surface_points(geom, dims, spacing)
                R = np.asarray(p.getMatrixFromQuaternion(orn)).reshape(3, 3)
                pts.append(local @ R.T + np.asarray(pos))
            if pts:
                self.points[link] = np.vstack(pts)


def surface_points(geom: int, dims, spacing: float) -> np.ndarray:
    """Points (n, 3) every ``spacing`` at most on a primitive's surface, its own frame:
    ``GEOM_BOX`` (dims: full sizes) or ``GEOM_CYLINDER`` (dims: length, radius; axis z)."""
    if geom == p.GEOM_BOX:
        half = np.asarray(dims[:3], np.float64) / 2
        axes = [np.linspace(-h, h, max(2, int(math.ceil(2 * h / spacing)) + 1)) for h in half]
        g = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
        on_face = np.any(np.isclose(np.abs(g), half), axis=1)
        return g[on_face]
    if geom == p.GEOM_CYLINDER:
        length, radius = float(dims[0]), float(dims[1])
        zs = np.linspace(-length / 2, length / 2, max(2, int(math.ceil(length / spacing)) + 1))
        radii = np.linspace(radius, 0.0, max(2, int(math.ceil(radius / spacing)) + 1))
        rings = []
        for r in radii:  # concentric rings of each cap, the outer one also the side's
            n = max(1, int(math.ceil(2 * math.pi * r / spacing)))
            t = np.linspace(0, 2 * math.pi, n, endpoint=False)
            rings.append(np.stack([r * np.cos(t), r * np.sin(t)], axis=1))
        side = np.vstack([np.c_[rings[0], np.full(len(rings[0]), z)] for z in zs])
        disc = np.vstack(rings)
        caps = np.vstack([np.c_[disc, np.full(len(disc), z)] for z in (zs[0], zs[-1])])
        return np.vstack([side, caps])
    raise ValueError(
        f"the heap model samples boxes and cylinders only, not pybullet geometry "
        f"type {geom}: give the robot's collision shapes as primitives"
    )
