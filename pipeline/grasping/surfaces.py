"""Visible planar surfaces of boxes in a depth image: detection, ground truth, scoring.

Paper Sec. 4.3, Figs. 4b–4c: the depth image becomes a point cloud, the cloud is split into one
cluster per object, RANSAC finds the planar surfaces of each cluster, and each surface's centre
and normal are computed; the centre projected to pixel coordinates is the grasp point g.

Frames: camera (OpenCV: x right, y down, z forward; metres) and pixel (u, v), as in
``pipeline.camera.geometry``. A plane is stored as a unit normal ``n`` and offset ``c`` with
``n · X = c`` for camera-frame points X; normals point towards the camera, so ``c < 0``.

The visible region of a surface is a set of pixels. Its rectangle is computed from the rays
through those pixel centres, intersected with the surface's plane (so depth noise does not
widen it): ``cv2.minAreaRect`` of the intersection points in the plane's 2-D coordinates. The
rectangle's centre is the surface centre (the centre of the visible region, not the centroid
of its points), its sides give L_l and L_s. Because the samples are pixel centres, the
rectangle can be up to one pixel footprint (about 1.5 mm at 0.6 m) shorter than the region
along an image-aligned side; the centre has no such bias. Detection and ground truth use the
same computation, so they are comparable.

Axis signs: ``long_axis_cam`` has a camera-x component ≥ 0 (it points right in the image; when
that component is 0, its y component is ≥ 0, pointing down), and ``short_axis_cam = normal ×
long``, so (long, short, normal) is right-handed. For a square face the long side is whichever
side the samples make longer.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from pipeline.camera.geometry import Intrinsics, cross3, project
from pipeline.grasping.types import Surface

# RANSAC stops once an all-inlier hypothesis has been drawn with this probability (open3d's
# default for segment_plane).
RANSAC_PROBABILITY = 0.99999999
_RANSAC_CHUNK = 50

# Face names in box-frame axis order, (axis, sign): "+x" is the face whose outward normal is +x.
FACES = (
    ("+x", 0, 1.0),
    ("-x", 0, -1.0),
    ("+y", 1, 1.0),
    ("-y", 1, -1.0),
    ("+z", 2, 1.0),
    ("-z", 2, -1.0),
)


@dataclass
class SurfaceDetectionConfig:
    """Settings of ``detect_surfaces`` (lengths in metres): keys of the ``surfaces`` section
    (``conf/surfaces/``), built by ``pipeline.labelling.scene.surface_config``.

    Attributes:
        distance_threshold: RANSAC inlier distance to the plane, and the distance within which a
            cluster point is assigned to a found plane.
        ransac_n: points per RANSAC hypothesis.
        num_iterations: RANSAC hypotheses per plane.
        min_inliers: fewest pixels a surface's connected region may have.
        search_min_inliers: the plane search goes on while this many points are left and ends
            at a plane with fewer inliers. Lower than ``min_inliers`` because the planes found
            first take the pixels of later faces that lie within ``distance_threshold`` of them
            (along shared edges: a side face seen at a grazing angle can lose a whole pixel
            column, a third of its pixels); the final nearest-plane assignment gives them back.
        max_surfaces_per_object: planes searched per object cluster (a box shows at most 3 faces).
        seed: base seed of RANSAC; each object's searches are seeded from (seed, instance), so
            a result does not depend on the order or number of earlier calls.
        ransac_backend: "numpy" (``conf/surfaces/ransac.yaml``'s) or "open3d". Both draw
            ``num_iterations`` hypotheses of ``ransac_n`` points and keep the one with most
            inliers. open3d 0.20's ``segment_plane`` evaluates hypotheses on several threads
            that share one random generator and stop early on a shared counter, so even after
            ``o3d.utility.random.seed`` its answer varies run to run (measured: 2 different
            planes in 50 identical calls on one box's points; after refinement 1–5 of ~400
            surfaces differ between processes on noisy depth). The numpy version draws its
            hypotheses from a seeded ``np.random.Generator`` and is bitwise reproducible.
        ransac_max_points: RANSAC runs on a random subsample of at most this many points; the
            plane is then refined on all points (the final geometry never uses the sample).
        refine_iterations: at most this many least-squares refits (inliers → plane → inliers)
            after RANSAC; stops earlier when the inliers no longer change.
        connectivity: 4 or 8, pixel connectivity of the visible region; 4 keeps regions that touch
            only diagonally apart.
    """

    distance_threshold: float
    ransac_n: int
    num_iterations: int
    min_inliers: int
    search_min_inliers: int
    max_surfaces_per_object: int
    seed: int
    ransac_backend: str
    ransac_max_points: int
    refine_iterations: int
    connectivity: int


# --------------------------------------------------------------------------------------------
# Shared geometry


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product of two 3-vectors (``np.cross`` costs ~100 µs of overhead per call)."""
    return np.array(cross3(a.tolist(), b.tolist()))


def fit_plane(points: np.ndarray) -> tuple[np.ndarray, float, np.ndarray, np.ndarray]:
    """Least-squares plane of (N, 3) points: (unit normal, offset c, in-plane axes e1, e2).

    The normal is the direction of least variance (the scatter matrix's eigenvector of the
    smallest eigenvalue, as the SVD of the centred points would give); it is oriented towards
    the camera (origin), i.e. ``c = n · centroid < 0``. e1 is the direction of most variance.
    """
    # OpenCV: scatter matrix and mean in one call, then its eigenvectors (rows, by decreasing
    # eigenvalue); about 3x faster than numpy here.
    scatter, mean = cv2.calcCovarMatrix(points, None, cv2.COVAR_NORMAL | cv2.COVAR_ROWS)
    _, _, vecs = cv2.eigen(scatter)
    centroid = mean[0]
    n = vecs[2]
    if n @ centroid > 0:
        n = -n
    return n, float(n @ centroid), vecs[0], _cross(n, vecs[0])


def _orient_long_axis(long_axis: np.ndarray) -> np.ndarray:
    """Sign convention: camera x component ≥ 0 (points right in the image); if it is 0, y ≥ 0."""
    if abs(long_axis[0]) > 1e-9:
        return long_axis if long_axis[0] > 0 else -long_axis
    return long_axis if long_axis[1] >= 0 else -long_axis


def region_surface(
    instance: int,
    us: np.ndarray,
    vs: np.ndarray,
    xn: np.ndarray,
    yn: np.ndarray,
    normal: np.ndarray,
    offset: float,
    e1: np.ndarray,
    e2: np.ndarray,
    intr: Intrinsics,
    extra: dict,
) -> Surface | None:
    """The Surface of a pixel region on the plane ``normal · X = offset`` (camera frame).

    Args:
        us, vs: (N,) the region's pixels, in row-major order (as ``np.nonzero`` gives them).
        xn, yn: (N,) their normalised image coordinates (u − cx) / fx, (v − cy) / fy.
        normal, offset: the plane, normal towards the camera (so ``offset < 0``).
        e1, e2: (3,) orthonormal axes spanning the plane.

    Returns None if a pixel's ray misses the plane (the region is seen edge-on).
    """
    n_dot_r = normal[0] * xn + normal[1] * yn + normal[2]  # n · (x/z, y/z, 1), < 0 in front
    if offset >= 0 or n_dot_r.max() > -1e-9:
        return None
    # Pixel → plane is a projective map (all points in front of the camera), which keeps convex
    # hulls: only the hull pixels are needed for the rectangle, and the hull's vertices are among
    # each image row's first and last pixels.
    new_row = np.flatnonzero(vs[1:] != vs[:-1])
    cand = np.concatenate(([0], new_row + 1, new_row, [len(us) - 1]))
    hull = cv2.convexHull(
        np.stack([us[cand], vs[cand]], axis=1).astype(np.int32), returnPoints=False
    )
    h = cand[hull.ravel()]
    z = offset / n_dot_r[h]  # depth of the hull pixels' rays on the plane
    pts = np.stack([xn[h] * z, yn[h] * z, z], axis=1)  # (K, 3)
    origin = pts[0]
    # Plane coordinates in millimetres: float32 for OpenCV without losing precision.
    rel = (pts - origin) * 1000.0
    q = np.stack([rel @ e1, rel @ e2], axis=1).astype(np.float32)
    rect = cv2.minAreaRect(q)
    (x0, y0), (x1, y1), (x2, y2), _ = cv2.boxPoints(rect).tolist()  # corners, mm
    side_a, side_b = (x1 - x0, y1 - y0), (x2 - x1, y2 - y1)
    len_a, len_b = float(np.hypot(*side_a)), float(np.hypot(*side_b))
    if len_a >= len_b:
        long_2d, long_len, short_len = side_a, len_a, len_b
    else:
        long_2d, long_len, short_len = side_b, len_b, len_a
    if long_len > 0:
        long_axis = (long_2d[0] * e1 + long_2d[1] * e2) / long_len
    else:  # a single pixel: any in-plane direction
        long_axis = e1.copy()
    long_axis = _orient_long_axis(long_axis)
    short_axis = _cross(normal, long_axis)
    centre = origin + (rect[0][0] / 1000.0) * e1 + (rect[0][1] / 1000.0) * e2
    # Footprint of one pixel on the plane: z² / (fx fy |n · r|) with r = (x/z, y/z, 1) and
    # z = offset / (n · r), i.e. offset² / (fx fy |n · r|³).
    s = -n_dot_r
    area = float(offset * offset * np.sum(1.0 / (s * s * s)) / (intr.fx * intr.fy))
    return Surface(
        instance=int(instance),
        center_cam=centre,
        normal_cam=np.array(normal, dtype=np.float64),
        long_axis_cam=long_axis,
        short_axis_cam=short_axis,
        long_length=long_len / 1000.0,
        short_length=short_len / 1000.0,
        center_px=project(centre, intr),
        num_points=int(len(us)),
        area=area,
        extra=extra,
    )


class RegionFinder:
    """Largest connected region of a subset of one instance's pixels, on the instance's
    bounding box (cheaper than the whole image)."""

    def __init__(self, us: np.ndarray, vs: np.ndarray, connectivity: int) -> None:
        self.u0, self.v0 = int(us.min()), int(vs.min())
        self.shape = (int(vs.max()) - self.v0 + 1, int(us.max()) - self.u0 + 1)
        self.connectivity = connectivity

    def largest(self, us: np.ndarray, vs: np.ndarray) -> tuple[np.ndarray | None, int]:
        """(selection of the pixels in the largest region, or None if they are all one region;
        number of regions)."""
        img = np.zeros(self.shape, dtype=np.uint8)
        rows, cols = vs - self.v0, us - self.u0
        img[rows, cols] = 1
        count, labels, stats, _ = cv2.connectedComponentsWithStats(
            img, connectivity=self.connectivity
        )
        if count <= 2:  # background + one region
            return None, count - 1
        best = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))  # ties: lowest label
        return labels[rows, cols] == best, count - 1


def check_images(depth_m: np.ndarray, mask: np.ndarray, intr: Intrinsics) -> None:
    shape = (intr.height, intr.width)
    if depth_m.shape != shape or mask.shape != shape:
        raise ValueError(
            f"depth {depth_m.shape} and mask {mask.shape} must both be (H, W) = "
            f"{shape}, the camera intrinsics' image size"
        )


def instance_pixels(depth_m: np.ndarray, mask: np.ndarray, intr: Intrinsics):
    """For each instance id > 0 with valid depth, in id order, yield ``(instance, us, vs, xn,
    yn, points)``: its pixels in row-major order, their normalised image coordinates
    (u − cx) / fx and (v − cy) / fy, and their (N, 3) camera-frame points."""
    valid = (mask > 0) & (depth_m > 0) & np.isfinite(depth_m)
    vs, us = np.nonzero(valid)
    if len(us) == 0:
        return
    ids = mask[vs, us]
    order = np.argsort(ids, kind="stable")
    ids, us, vs = ids[order], us[order], vs[order]
    z = depth_m[vs, us].astype(np.float64)
    starts = np.flatnonzero(np.r_[True, ids[1:] != ids[:-1]])
    ends = np.r_[starts[1:], len(ids)]
    xn_all = (us - intr.cx) / intr.fx
    yn_all = (vs - intr.cy) / intr.fy
    for s, e in zip(starts, ends):
        points = np.stack([xn_all[s:e] * z[s:e], yn_all[s:e] * z[s:e], z[s:e]], axis=1)
        yield int(ids[s]), us[s:e], vs[s:e], xn_all[s:e], yn_all[s:e], points


# --------------------------------------------------------------------------------------------
# Detection


def _ransac_numpy(
    sample: np.ndarray, cfg: SurfaceDetectionConfig, rng: np.random.Generator
) -> tuple[np.ndarray, float] | None:
    """Best plane (n, c) of up to ``num_iterations`` random ``ransac_n``-point hypotheses on the
    (M, 3) ``sample``: the one with most inliers (the first drawn among equals; the
    least-squares refinement that follows makes equals equivalent).

    Like open3d, stops once enough hypotheses were tried to have drawn an all-inlier one with
    probability ``RANSAC_PROBABILITY`` given the best inlier fraction w so far, i.e. after
    log(1 − p) / log(1 − w^n) of them; they are scored in chunks of ``_RANSAC_CHUNK``.
    All hypotheses are drawn first, so where it stops does not change what is drawn.
    """
    m, k, r = len(sample), cfg.num_iterations, cfg.ransac_n
    draws = rng.integers(0, m, size=(k, r))
    origin = sample[0]
    # Scoring in float32 about the sample's first point (errors ~1e-8 m, far below the
    # threshold): float64 matrix products with an inner size of 3 are ~7x slower here.
    local = (sample - origin).T.astype(np.float32)  # (3, M)
    best_count, best = 0, None
    for start in range(0, k, _RANSAC_CHUNK):
        picks = sample[draws[start : start + _RANSAC_CHUNK]] - origin  # (C, r, 3)
        if r == 3:
            u, v = picks[:, 1] - picks[:, 0], picks[:, 2] - picks[:, 0]
            normals = np.stack(
                [
                    u[:, 1] * v[:, 2] - u[:, 2] * v[:, 1],
                    u[:, 2] * v[:, 0] - u[:, 0] * v[:, 2],
                    u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0],
                ],
                axis=1,
            )
        else:
            centred = picks - picks.mean(axis=1, keepdims=True)
            normals = np.linalg.eigh(np.einsum("kri,krj->kij", centred, centred))[1][:, :, 0]
        length = np.sqrt(np.einsum("ki,ki->k", normals, normals))
        ok = length > 1e-12  # repeated or collinear picks give no plane
        if ok.any():
            normals = normals[ok] / length[ok, None]
            offsets = np.einsum("ki,ki->k", normals, picks[ok, 0])  # relative to origin
            dist = np.abs(
                normals.astype(np.float32) @ local - offsets.astype(np.float32)[:, None]
            )  # (C', M)
            counts = np.count_nonzero(dist < cfg.distance_threshold, axis=1)
            j = int(np.argmax(counts))
            if counts[j] > best_count:
                best_count = int(counts[j])
                best = (normals[j], float(offsets[j] + normals[j] @ origin))
        if best_count >= m:
            break
        if best_count > 0:
            needed = np.log(1.0 - RANSAC_PROBABILITY) / np.log(1.0 - (best_count / m) ** r)
            if start + _RANSAC_CHUNK >= needed:
                break
    return best


def _ransac_open3d(
    sample: np.ndarray, cfg: SurfaceDetectionConfig, seed: int
) -> tuple[np.ndarray, float] | None:
    """open3d's ``segment_plane`` on the sample (not reproducible run to run, see the config)."""
    from pipeline.runtime.cli import import_with_fix  # its error says how to install libusb-1.0

    o3d = import_with_fix("open3d")  # imported here: ~1.5 s, and only this backend needs it

    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(sample))
    o3d.utility.random.seed(seed)
    model, _ = cloud.segment_plane(
        distance_threshold=cfg.distance_threshold,
        ransac_n=cfg.ransac_n,
        num_iterations=cfg.num_iterations,
    )
    n = np.asarray(model[:3], dtype=np.float64)
    scale = float(np.linalg.norm(n))
    if not np.isfinite(scale) or scale == 0:
        return None
    return n / scale, -float(model[3]) / scale


@dataclass
class _Plane:
    """A plane ``normal · X = offset`` found in a cluster, and its inliers (bool per point).
    ``axes`` is the (e1, e2) of ``fit_plane`` when the plane is exactly the least-squares fit of
    ``inliers`` (refinement converged), else None."""

    normal: np.ndarray
    offset: float
    inliers: np.ndarray
    axes: tuple[np.ndarray, np.ndarray] | None


def _find_planes(points: np.ndarray, cfg: SurfaceDetectionConfig, instance: int) -> list[_Plane]:
    """Sequential RANSAC on one cluster's (N, 3) points: up to ``max_surfaces_per_object``."""
    if cfg.ransac_backend not in ("numpy", "open3d"):
        raise ValueError(f"ransac_backend must be 'numpy' or 'open3d', not {cfg.ransac_backend!r}")
    if cfg.ransac_n < 3:
        raise ValueError(f"ransac_n must be at least 3 (points per plane), not {cfg.ransac_n}")
    thr = cfg.distance_threshold
    remaining = np.ones(len(points), dtype=bool)
    left = len(points)
    planes: list[_Plane] = []
    rng = np.random.default_rng([int(cfg.seed), instance])  # depends only on (seed, instance)
    while len(planes) < cfg.max_surfaces_per_object and left >= cfg.search_min_inliers:
        rest = np.flatnonzero(remaining)
        # A random subsample, not a strided one: a stride in row-major order aliases with thin
        # image strips (a side face seen at a grazing angle is 2–3 pixels wide, each pixel
        # column at its own depth), which favours planes through single pixel columns.
        if left > cfg.ransac_max_points:
            sample = points[rest[rng.choice(left, cfg.ransac_max_points, replace=False)]]
        else:
            sample = points[rest]
        # Shortcut: if every remaining point lies within the threshold of their least-squares
        # plane (one face left, e.g. a box lying flat), RANSAC and its refinement would end at
        # that same plane and inlier set; skip them. Tried on the sample first (cheaper).
        n, c, _, _ = fit_plane(sample)
        if np.abs(sample @ n - c).max() < thr:
            rest_points = points.take(rest, axis=0)
            n, c, e1, e2 = fit_plane(rest_points)
            if np.abs(rest_points @ n - c).max() < thr:
                planes.append(_Plane(n, c, remaining.copy(), (e1, e2)))
                break
        if cfg.ransac_backend == "numpy":
            plane = _ransac_numpy(sample, cfg, rng)
        else:
            plane = _ransac_open3d(
                sample, cfg, int(cfg.seed) * 1_000_003 + instance * 101 + len(planes)
            )
        if plane is None:
            break
        n, c = plane
        axes = None
        inliers = remaining & (np.abs(points @ n - c) < thr)
        count = int(inliers.sum())
        # Least-squares refinement on all remaining points of the cluster, to a fixed point.
        for _ in range(cfg.refine_iterations):
            if count < 3:
                break
            n, c, e1, e2 = fit_plane(points.take(np.flatnonzero(inliers), axis=0))
            new = remaining & (np.abs(points @ n - c) < thr)
            new_count = int(new.sum())
            if new_count == count and np.array_equal(new, inliers):
                axes = (e1, e2)
                break
            inliers, count = new, new_count
        if count < cfg.search_min_inliers:
            break
        planes.append(_Plane(n, c, inliers, axes))
        remaining &= ~inliers
        left -= count
    return planes


def detect_surfaces(
    depth_m: np.ndarray, mask: np.ndarray, intrinsics: Intrinsics, cfg: SurfaceDetectionConfig
) -> list[Surface]:
    """Planar surfaces of every object in a depth image (paper Figs. 4b–4c).

    Segmentation: the points are grouped by the simulator's instance mask, one cluster per box.
    The paper crops the cloud with PCL's box filter instead; the mask is the exact version of
    that crop that a simulator gives for free (no tuning of crop boxes, no leaks between
    touching boxes), which keeps label errors down to the surface fit itself.

    Per cluster: RANSAC on a random subsample (a seeded numpy implementation by default, or
    open3d's ``segment_plane``, see ``SurfaceDetectionConfig.ransac_backend``), least-squares
    refits on all the cluster's points until the inliers stop changing, removal of the inliers;
    repeated until fewer than ``search_min_inliers`` points remain or ``max_surfaces_per_object``
    planes are found (when all remaining points already lie on one plane, that plane is taken
    without RANSAC). Each cluster
    point is then assigned to its nearest plane (if within ``distance_threshold``), so that
    pixels next to an edge go to the face they lie on rather than to the plane found first.
    A plane's surface is its largest connected region of pixels (coplanar patches separated by an
    occluder are not merged; the smaller patches are dropped), refitted by least squares; the
    rectangle of that region gives centre, axes and lengths (see the module docstring).

    Args:
        depth_m: (H, W) float z-depth, metres; 0 = no data.
        mask: (H, W) integer instance mask, 0 = not an object.
        intrinsics: the camera's intrinsics.
        cfg: settings.

    Returns:
        Surfaces ordered by instance, then by decreasing pixel count. ``num_points`` is the
        region's pixel count; ``area`` sums each region pixel's footprint on the plane (m²).
        ``extra`` holds ``rmse_m`` (plane fit residual of the region), ``plane_pixels`` (pixels
        assigned to the plane before keeping the largest region) and ``regions``. Deterministic:
        the same inputs give the same output.
    """
    check_images(depth_m, mask, intrinsics)
    if cfg.connectivity not in (4, 8):
        raise ValueError(f"connectivity must be 4 or 8, not {cfg.connectivity}")
    thr = cfg.distance_threshold
    surfaces: list[Surface] = []
    for instance, us, vs, xn, yn, points in instance_pixels(depth_m, mask, intrinsics):
        if len(us) < cfg.min_inliers:
            continue
        planes = _find_planes(points, cfg, instance)
        if not planes:
            continue
        # Each point goes to its nearest plane, if within the threshold: pixels next to an edge
        # go to the face they lie on, not to the plane that was found first.
        residual = np.stack([np.abs(points @ pl.normal - pl.offset) for pl in planes], axis=1)
        nearest = np.argmin(residual, axis=1)  # (N,)
        assigned = residual[np.arange(len(points)), nearest] < thr
        regions = RegionFinder(us, vs, cfg.connectivity)
        found = []
        for j, plane in enumerate(planes):
            sel = assigned & (nearest == j)
            idx = np.flatnonzero(sel)
            plane_pixels = len(idx)
            if plane_pixels < cfg.min_inliers:
                continue
            keep, num_regions = regions.largest(us[idx], vs[idx])
            if keep is not None:
                idx = idx[keep]
                if len(idx) < cfg.min_inliers:
                    continue
            region_points = points.take(idx, axis=0)
            if (
                keep is None
                and plane.axes is not None
                and plane_pixels == plane.inliers.sum()
                and np.array_equal(sel, plane.inliers)
            ):
                # The region is exactly the refinement's inlier set: the same least-squares fit.
                n, c, (e1, e2) = plane.normal, plane.offset, plane.axes
            else:
                n, c, e1, e2 = fit_plane(region_points)
            rmse = float(np.sqrt(np.mean((region_points @ n - c) ** 2)))
            pixels = (us[idx], vs[idx], xn[idx], yn[idx])
            extra = {"rmse_m": rmse, "plane_pixels": plane_pixels, "regions": num_regions}
            surface = region_surface(instance, *pixels, n, c, e1, e2, intrinsics, extra)
            if surface is not None:
                found.append(surface)
        found.sort(key=lambda s: -s.num_points)
        surfaces.extend(found)
    return surfaces


# --------------------------------------------------------------------------------------------
# Ground truth


# --------------------------------------------------------------------------------------------
# Scoring
