"""Surface feature descriptor (paper Sec. 5.1, Fig. 7): region growing from a seed pixel.

Given a depth image and a seed pixel g (the planner's g_opt at the home pose, afterwards the
previous iteration's g'), find the planar surface g lies on and return its centre g', normal
n, axes n_l, n_s and their warped-perspective versions ñ_l, ñ_s for 2.5D visual servoing
(Sec. 5.2, Eq. 24).

Frames and units: camera frame OpenCV (x right, y down, z forward), metres; pixels (u, v) with
u the column, v the row, (0, 0) the centre of the top-left pixel; ``depth_m`` is an (H, W)
float z-depth in metres, 0 (or non-finite) = no data; it goes through
``pipeline.camera.depth_input.check_depth_image`` (NaN, ±inf, ≤ 0 and implausible depths are no
data; a wrong shape or a non-float dtype is a ``ValueError``). Every normal is reported pointing
*towards* the camera (n · P < 0), as everywhere in the project.

The paper's rules, with P(u, v) the back-projection of pixel (u, v) (``camera.backproject``):

    n̂ · P(u, v) + D̂ = 0                                          (11)  plane of the seed window
    |n_p · P(u, v) + D̂| < ε1                                      (12)  distance rule
    ‖n_p − n̂‖² < ε2                                                (13)  normal rule
    n_p = (P(u+1, v) − P(u−1, v)) × (P(u, v+1) − P(u, v−1))        (14)  per-pixel normal

Algorithm and the choices made where the paper is vague:

1. **Seed plane (Eq. 11).** The plane is fitted to the valid points (depth > 0) of the
   ``window`` × ``window`` (21 × 21) window centred on the rounded seed, clipped to the image;
   at least 10 points are needed. The fit is the least-squares plane (the smallest singular
   vector of the centred points; computed as the scatter matrix's eigenvector, which is the
   same thing, by ``grasping.surfaces.fit_plane``). Additions, so that a window that
   overlaps another surface (a seed near an edge; a box side face is only ~20 px tall) still
   gives the seed's plane: (a) ``window_hypotheses`` (default 50) RANSAC planes through three
   random window points (fixed-seed generator: reproducible) are scored by their window points
   within ε1; the best of those that hold the seed point (within ε1) — of all of them if none
   does, e.g. when the seed is a depth spike — selects the points that are fitted; (b)
   ``window_refits``
   (default 2) least-squares refits on the window points within ε1 of the previous fit. When
   the whole window lies on one plane this is exactly the paper's SVD of all its points;
   ``window_hypotheses=0, window_refits=0`` is the paper's fit in every case.
   ``SurfaceFeatures.plane`` is (n̂, D̂) of this fit, n̂ towards the camera (so D̂ = −n̂ · P > 0).
2. **Per-pixel normals (Eq. 14)** by central differences of the back-projected image (the exact
   cross product, rewritten with fewer image-sized operations, see ``plane_rules``), normalised and
   flipped towards the camera (Eq. 14's cross product itself points away from the camera for a
   visible surface, see ``planner.ranking``). n_p is undefined on the image border and where
   the pixel or one of its four neighbours has no data; such pixels fail Eq. 13.
   (``planner.ranking.surface_normal`` computes the same n_p but averaged over a window at one
   pixel; here it is needed at every pixel.) **Noise:** with the project's SR300 sensor model
   (σ ≈ 0.9 mm at 0.5 m) the central differences span only ~2.4 mm, so a single n_p is tens of
   degrees off and Eq. 13 rejects almost every pixel ("region_too_small" on a 0.2 × 0.12 m
   face). ``normal_smoothing`` = k > 0 replaces each unit n_p by the renormalised mean of the
   defined unit n_p in its (2k + 1)² neighbourhood. Measured on sr300-noised depth with
   k = 1–2: a 25°-tilted face and boxes beside a 2 cm step are recovered (normal < 0.1° off,
   centre < 0.3 px off, no foreign pixels); at a 20° crease the region takes ~3 pixel columns
   of the other face (centre ~3 px off). Default 0 = the paper, exact on noise-free depth
   (the project's default ``sensor=ideal``); set it for noisy depth.
3. **Rules.** Eq. 12 is implemented as |n̂ · P + D̂| < ε1, the distance to the fitted plane:
   the paper writes n_p, which reads as a typo — D̂ is the offset of n̂'s plane, and n_p · P + D̂
   is not a distance to anything. Eq. 13 is used as written with unit normals:
   ‖n_p − n̂‖² = 2 − 2 n_p · n̂ < ε2 (ε2 = 0.05 ≈ 12.8°).
4. **Region growing** = the ``connectivity``-connected component (4 by default) of the
   pixels satisfying both rules that contains the seed pixel. If the seed pixel itself fails
   the rules (e.g. it lies on an edge, where Eq. 14 mixes two faces), the component holding the
   rule-satisfying pixel nearest to the seed inside the seed window is taken (ties: the first
   in row-major order); if there is none: no surface (``"no_region_at_seed"``).
5. **Rim** (addition): a pixel on a surface's boundary has its Eq. 14 stencil across the edge,
   so its n_p is corrupted and the rules alone would drop a one-pixel rim all around the region
   (lengths ~2 px short; with ``normal_smoothing`` = k a (k + 1)-pixel rim). The region is
   grown by ``rim + normal_smoothing`` pixels (8-neighbour steps, so the corners come back
   too) through pixels that satisfy Eq. 12 only. At a depth step (a box on or beside a lower
   one) the other surface fails Eq. 12 and is not added; at a crease between two faces at the
   same height the region takes the other face's pixels next to the crease that lie within ε1
   of the plane (on ideal depth with k = 0: at most two pixel columns for a 20° crease; Eq. 13
   itself lets through the column whose stencil straddles the crease). ``rim=0``: the paper's
   rules only, no growth. With ``sites_cam`` (addition, the closed loop's face split), the
   region then keeps only the Voronoi cell of the first site (``split_region``): coplanar faces
   of two boxes side by side at the same height have no seam in ideal depth and grow into one
   region. A region with fewer than ``min_pixels`` pixels (after the rim and the split) is no
   surface (``"region_too_small"``).
6. **Surface geometry.** If ``refine`` (default), the plane is refitted by least squares on all
   the region's points, and ``normal_cam`` is that plane's normal; otherwise n̂. The centre,
   axes and lengths are computed exactly as for the labels (``grasping.surfaces.region_surface``):
   the rays through the region's pixel centres are intersected with the plane and the
   minimum-area rectangle of those points gives the centre (the centre of the visible region,
   on the plane, not the centroid of the points), the long / short axes and L_l, L_s (which
   can be up to one pixel footprint shorter than the region, the samples being pixel centres).
   ``center_px`` = g' is the centre projected into the image. Axis signs as in the labels:
   ``long_axis_cam`` has camera-x ≥ 0, ``short = normal × long``.
7. **Warped perspective** as in hand-level labelling (``grasping.hand.warped_axes``): R0 is the
   minimal rotation with R0 Z = −n; ñ = R0ᵀ n_axis, i.e. the axis rotated by the minimal
   rotation taking −n onto the camera's +Z. ñ lies in the camera X-Y plane; its z component
   (~1e-16 after the rotation) is set to exactly 0 and it is renormalised. For a level surface
   (n = −Z) R0 = I and ñ equals the axis.

**Cost.** Everything is vectorised (no per-pixel Python loop). Only Eq. 12 is evaluated on
the whole image; Eqs. 13–14 and region growing run on the bounding box of the Eq. 12
components that meet the seed window (found by flood fills), grown by the stencil and rim
margins: the region lies inside it, so the result is the same as on the whole image. Measured
(median of 20 calls, 416 × 416, fx = fy = 411.7, cx = cy = 207.5, a 0.2 × 0.12 m face tilted
25° at 0.5 m on a background; one core of a loaded 2-core machine): ~3.8 ms with the defaults,
~3.0 ms with the paper-only settings, ~4.4 ms with ``normal_smoothing=2`` on noisy depth; a
plane filling the whole image ~20 ms (Eq. 14 and the rectangle on every pixel).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.camera.depth_input import check_depth_image
from pipeline.camera.geometry import Intrinsics
from pipeline.config.build import from_section
from pipeline.grasping.hand import warped_axes
from pipeline.grasping.surfaces import fit_plane, region_surface
from pipeline.grasping.types import FaceFrame
from pipeline.servo.region import (
    NoSurface,
    PlaneCrop,
    SeedWindow,
    crop_points,
    grown_region,
    seed_pixel,
    window_plane,
)

NO_SURFACE_REASONS = (
    "seed_outside_image",
    "no_depth_at_seed",
    "too_few_window_points",
    "no_region_at_seed",
    "region_too_small",
    "edge_on",
    "surface_changed",
)


@dataclass
class DescriptorConfig:
    """Settings of ``describe_surface`` (lengths in metres): keys of the ``servo`` section
    (``conf/servo/``), built by :func:`descriptor_config`.

    Attributes:
        window: side of the square seed window for the plane fit of Eq. 11, pixels (odd).
        eps_distance: ε1 of Eq. 12, the largest distance to the fitted plane.
        eps_normal: ε2 of Eq. 13, the largest ‖n_p − n̂‖² of unit normals (0.05 ≈ 12.8°).
        min_pixels: fewest pixels of a region; a smaller one is no surface.
        connectivity: 4 or 8, pixel connectivity of region growing (the rim always grows by
            8-neighbour steps).
        window_hypotheses: RANSAC planes tried to pick the window points on the seed's surface
            before the fit of Eq. 11 (0 = fit all the window's points, as the paper).
        window_refits: least-squares refits of the window plane on the window points within
            ``eps_distance`` of the previous fit (0 = the paper's single fit).
        rim: pixels by which the region is grown through pixels satisfying Eq. 12 only, to get
            back the boundary pixels whose Eq. 14 normal straddles the edge (0 = off). The
            growth is ``rim + normal_smoothing`` pixels.
        normal_smoothing: k; if > 0, each unit n_p is replaced by the renormalised mean of the
            defined unit n_p of its (2k + 1)² neighbourhood before Eq. 13 (0 = Eq. 14 per pixel,
            as the paper). Needed on noisy depth (see the module docstring).
        refine: refit the plane by least squares on the whole region (``normal_cam``, centre
            and axes then use that plane; ``plane`` stays the window fit).
        window_tolerance_depth: with ``window_hypotheses``, the RANSAC inlier tolerance of the
            window planes is ε1 · min(1, Z_seed / this) (0 = ε1 at every depth). A window of
            fixed pixel size shrinks on the surface as the camera approaches: at 0.16 m a
            21 × 21 window spans 8 mm, and a plane steeper than the face can then hold most of
            its points within ε1 = 4 mm.
        seed_repair: a seed pixel without data takes the depth of the nearest window pixel
            with data (a sensor's hole; False: "no_depth_at_seed"), the plane through the
            3 × 3 median depth when the seed pixel is more than ε1 from it (a crack), and the
            nearest component of at least ``min_pixels`` when the seed's own is smaller
            (False: the seed's depth and component as they are, the nearest rule pixel only
            when the seed fails the rules).
        track_normal_deg: with an expected normal (``describe_surface(expected_normal_cam=)``,
            the tracked surface's normal carried from the previous frame), the window plane
            takes that orientation (``tracked_plane``), and a surface found farther than this
            angle from it is "surface_changed" (0 = off, the paper: the plane at the seed,
            whatever it is).
        track_offset_m: with an expected normal and an expected point
            (``describe_surface(expected_point_cam=)``, a point of the tracked surface carried
            into this frame), only window slabs within this distance (m) of the tracked plane
            compete (``tracked_plane``; None = the normal only).
    """

    window: int
    eps_distance: float
    eps_normal: float
    min_pixels: int
    connectivity: int
    window_hypotheses: int
    window_refits: int
    rim: int
    normal_smoothing: int
    refine: bool
    window_tolerance_depth: float  # m; > 0: window RANSAC tolerance ε1·min(1, Z/this)
    seed_repair: bool
    track_normal_deg: float  # > 0: stay on the surface whose normal is expected
    track_offset_m: float | None  # m; with an expected point: stay on the tracked plane too


def descriptor_config(cfg) -> DescriptorConfig:
    """The descriptor of a composed config (``cfg.servo``)."""
    return from_section(DescriptorConfig, cfg.servo)


@dataclass
class SurfaceFeatures(FaceFrame):
    """The descriptor's output for one surface: a :class:`~pipeline.grasping.types.FaceFrame`
    (g' = ``center_px``, the centre on the refined plane, its normal, axes, L_l, L_s of the
    region's rectangle and the region's area) and:

    Attributes:
        warped_long, warped_short: (3,) ñ_l, ñ_s: the axes rotated by the minimal rotation that
            takes −normal onto the camera's +Z; z component 0, unit.
        plane: (4,) (n̂, D̂) of Eq. 11 (the window fit), n̂ towards the camera, n̂ · P + D̂ = 0.
        num_pixels: pixels of the region.
        region: (H, W) bool mask of the region.
    """

    warped_long: np.ndarray
    warped_short: np.ndarray
    plane: np.ndarray
    num_pixels: int
    region: np.ndarray


def describe_surface(
    depth_m: np.ndarray,
    intrinsics: Intrinsics,
    seed_uv,
    cfg: DescriptorConfig,
    expected_normal_cam: np.ndarray | None = None,
    sites_cam: np.ndarray | None = None,
    expected_point_cam: np.ndarray | None = None,
) -> tuple[SurfaceFeatures | None, str]:
    """Surface features of the planar surface at ``seed_uv`` (paper Sec. 5.1; see the module
    docstring for the algorithm).

    Args:
        depth_m: (H, W) float z-depth, metres; NaN, ±inf, ≤ 0 and implausible depths are no
            data (``pipeline.camera.depth_input.check_depth_image``).
        intrinsics: of ``depth_m`` (its size must match).
        seed_uv: (2,) seed pixel g = (u, v), rounded to the nearest pixel.
        cfg: settings.
        expected_normal_cam: (3,) optional, the normal the surface should have in this camera
            frame (the tracked surface's, moved by the camera's motion); used with
            ``cfg.track_normal_deg``.
        sites_cam: (k, 3) optional points, camera frame, metres, the first the tracked face's
            (not the paper's; ``split_region``): with k ≥ 2 the grown region keeps only the
            pixels nearer to the first site than to every other, before the plane and the
            rectangle are fitted. The closed loop passes the planner's points of other faces
            that lie in the region, where coplanar faces of two boxes grew into one region.
        expected_point_cam: (3,) optional, a point of the tracked surface in this camera frame,
            metres; the surface's plane may be at most ``cfg.track_offset_m`` from it along the
            expected normal (not the paper; with ``expected_normal_cam``: ``tracked_plane``).

    Returns:
        (features, "") when a surface is found, else (None, reason) with reason one of
        ``NO_SURFACE_REASONS``: ``"seed_outside_image"`` (also a NaN/inf seed),
        ``"no_depth_at_seed"`` (with ``seed_repair``: no data in the whole window),
        ``"too_few_window_points"``,
        ``"no_region_at_seed"``, ``"region_too_small"``, ``"edge_on"`` (a region pixel's ray
        misses the plane), ``"surface_changed"`` (its normal is more than
        ``cfg.track_normal_deg`` from ``expected_normal_cam``).

    Raises:
        ValueError: a depth image of the wrong shape (not the intrinsics' (H, W)), ndim or
            dtype (``DepthImageError``, e.g. a raw uint16 image: convert it to metres first), a
            seed that is not two numbers, or a bad ``cfg.connectivity``.

    Cost: ~4 ms for a 416 × 416 image with a box face of ~15 000 pixels, ~20 ms when the face
    fills the image (see the module docstring).
    """
    if cfg.connectivity not in (4, 8):
        raise ValueError(f"connectivity must be 4 or 8, not {cfg.connectivity}")
    H, W = intrinsics.height, intrinsics.width
    # float32 metres, 0 = no data (NaN, ±inf, ≤ 0, implausible): a fresh array.
    Z = check_depth_image(depth_m, (H, W), name="depth_m")
    # Back-projection P = Z (xn, yn, 1), as camera.backproject; X = Z xn and Y = Z yn are only
    # formed where needed (the window, the crop).
    xn = (np.arange(W, dtype=np.float32) - np.float32(intrinsics.cx)) / np.float32(intrinsics.fx)
    yn = (np.arange(H, dtype=np.float32) - np.float32(intrinsics.cy)) / np.float32(intrinsics.fy)
    expected = None
    if expected_normal_cam is not None and cfg.track_normal_deg > 0:
        expected = np.asarray(expected_normal_cam, np.float64)
        expected = expected / np.linalg.norm(expected)
    try:
        u, v = seed_pixel(seed_uv, W, H)
        window = SeedWindow.of(Z, xn, yn, u, v, cfg)
        # (1) Eq. 11: plane of the seed window.
        n_hat, c_hat = window_plane(
            window.points, window.seed_point, cfg, expected, expected_point_cam
        )
        crop = PlaneCrop.of(Z, xn, yn, n_hat, -c_hat, window, cfg)
        idx, grown = grown_region(crop, window, sites_cam, cfg)
        return _features(idx, grown, crop, n_hat, c_hat, xn, yn, intrinsics, expected, cfg), ""
    except NoSurface as e:
        return None, e.reason


def _features(
    idx: np.ndarray,
    grown: np.ndarray,
    crop: PlaneCrop,
    n_hat: np.ndarray,
    c_hat: float,
    xn: np.ndarray,
    yn: np.ndarray,
    intrinsics: Intrinsics,
    expected: np.ndarray | None,
    cfg: DescriptorConfig,
) -> SurfaceFeatures:
    """(6) The region's plane and rectangle, (7) the warped perspective."""
    H, W = intrinsics.height, intrinsics.width
    rv, ru = np.divmod(idx, crop.c1 - crop.c0)
    rv += crop.r0
    ru += crop.c0
    region = np.zeros((H, W), dtype=bool)
    region[crop.r0 : crop.r1, crop.c0 : crop.c1] = grown.view(bool)
    if cfg.refine:
        n, c, e1, e2 = fit_plane(crop_points(crop, idx))
    else:
        n, c = n_hat, c_hat
        e1 = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(n, e1)
    surface = region_surface(
        0,
        ru,
        rv,
        xn[ru].astype(np.float64),
        yn[rv].astype(np.float64),
        n,
        float(c),
        e1,
        e2,
        intrinsics,
        {},
    )
    if surface is None:
        raise NoSurface("edge_on")
    if expected is not None and abs(float(np.asarray(surface.normal_cam) @ expected)) < np.cos(
        np.radians(cfg.track_normal_deg)
    ):
        raise NoSurface("surface_changed")
    _, w_long, w_short = warped_axes(surface)
    w_long, w_short = (
        np.array([w[0], w[1], 0.0]) / np.hypot(w[0], w[1]) for w in (w_long, w_short)
    )
    d_hat = -c_hat  # n̂ · P + D̂ = 0 with n̂ towards the camera
    return SurfaceFeatures(
        center_px=np.asarray(surface.center_px, dtype=np.float64),
        center_cam=np.asarray(surface.center_cam, dtype=np.float64),
        normal_cam=np.asarray(surface.normal_cam, dtype=np.float64),
        long_axis_cam=surface.long_axis_cam,
        short_axis_cam=surface.short_axis_cam,
        long_length=surface.long_length,
        short_length=surface.short_length,
        warped_long=w_long,
        warped_short=w_short,
        plane=np.array([n_hat[0], n_hat[1], n_hat[2], d_hat]),
        num_pixels=int(len(rv)),
        area=surface.area,
        region=region,
    )
