"""Region growing of the surface feature descriptor (paper Sec. 5.1, Eqs. 11–14): the seed
window's plane, the per-pixel rules, the grown region and its rim.

``pipeline.servo.descriptor`` composes these steps; its module docstring gives the algorithm
(steps 1–5) and the choices made where the paper is vague. Frames and units as there: camera
frame OpenCV (x right, y down, z forward), metres; pixels (u, v), u the column, v the row.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import cv2
import numpy as np

from pipeline.grasping.surfaces import fit_plane
from pipeline.servo.region_kernels import on_plane_mask, plane_rules_unsmoothed, slab_counts

if TYPE_CHECKING:
    from pipeline.servo.descriptor import DescriptorConfig

MIN_WINDOW_POINTS = 10
# The reasons ``describe_surface`` gives for finding no surface (see its docstring).


def plane_rules(
    X: np.ndarray,
    Y: np.ndarray,
    Z: np.ndarray,
    valid: np.ndarray,
    xn: np.ndarray,
    yn: np.ndarray,
    n_hat: np.ndarray,
    d_hat: float,
    cfg: DescriptorConfig,
) -> tuple[np.ndarray, np.ndarray]:
    """(Eq. 12 mask, Eqs. 12 & 13 mask), both (h, w) bool, of an image (or a crop of one).

    Args:
        X, Y, Z: (h, w) float32 back-projected coordinates (Z = 0 where no data).
        valid: (h, w) bool, depth available.
        xn, yn: (w,), (h,) float32 normalised image coordinates of the columns / rows.
        n_hat, d_hat: the plane of Eq. 11, n̂ towards the camera.

    Eq. 14 with P = Z (xn, yn, 1): along a row yn is constant and along a column xn is, so
    with du = Z(u+1) − Z(u−1), dv = Z(v+1) − Z(v−1), A = X(u+1) − X(u−1), B = Y(v+1) − Y(v−1):
    a = P(u+1) − P(u−1) = (A, yn du, du), b = P(v+1) − P(v−1) = (xn dv, B, dv) and
    a × b = (du (yn dv − B), dv (xn du − A), A B − xn yn du dv) — the exact cross product with
    fewer image-sized operations. n_p is flipped towards the camera where (a × b) · P > 0, and
    Eq. 13, 2 − 2 n_p · n̂ < ε2, is tested as s (c · n̂) > (1 − ε2 / 2) |c| (s the flip sign).
    """
    h, w = Z.shape
    nx, ny, nz = (np.float32(x) for x in n_hat)
    k = np.float32(1.0 - cfg.eps_normal / 2.0)
    if cfg.normal_smoothing <= 0:  # eq12_mask, eq14_terms and Eq. 13, per pixel, compiled
        return plane_rules_unsmoothed(
            X, Y, Z, valid, xn, yn, nx, ny, nz, np.float32(d_hat), np.float32(cfg.eps_distance), k
        )
    on_plane = eq12_mask(
        X, Y, Z, valid, nx, ny, nz, np.float32(d_hat), np.float32(cfg.eps_distance)
    )
    rules = np.zeros((h, w), dtype=bool)
    if h < 3 or w < 3:
        return on_plane, rules
    cx, cy, cz, defined, towards, length2 = eq14_terms(X, Y, Z, valid, xn, yn)
    # Unit n_p towards the camera (0 where undefined), box-averaged, renormalised.
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = np.where(defined & (length2 > 0), np.float32(1.0) / np.sqrt(length2), np.float32(0.0))
    inv = np.where(towards > 0, -inv, inv)
    size = (2 * cfg.normal_smoothing + 1,) * 2
    mx, my, mz = (cv2.blur(c * inv, size, borderType=cv2.BORDER_CONSTANT) for c in (cx, cy, cz))
    dot = mx * nx
    dot += my * ny
    dot += mz * nz
    norm2 = mx * mx
    norm2 += my * my
    norm2 += mz * mz
    ok = (dot > 0) & (dot * dot > (k * k) * norm2)
    rules[1:-1, 1:-1] = ok & defined
    rules &= on_plane
    return on_plane, rules


def eq12_mask(X, Y, Z, valid, nx, ny, nz, d_hat, eps) -> np.ndarray:
    """(h, w) bool, Eq. 12 on (h, w) float32 coordinates: ``valid`` and |n̂ · P + D̂| < ε1
    (float32 scalars ``nx``, ``ny``, ``nz``, ``d_hat``, ``eps``; m)."""
    dist = X * nx
    dist += Y * ny
    dist += Z * nz
    dist += d_hat
    return valid & (np.abs(dist) < eps)


def eq14_terms(X, Y, Z, valid, xn, yn) -> tuple[np.ndarray, ...]:
    """Eq. 14 on the (h − 2, w − 2) interior of (h, w) float32 coordinates (h, w ≥ 3), as
    ``plane_rules`` derives it: the cross product's components ``cx``, ``cy``, ``cz`` (away
    from the camera for a visible surface), ``defined`` (the pixel and its four neighbours have
    depth), ``towards`` = (c · P) / Z and ``length2`` = |c|²."""
    xi, yi = xn[None, 1:-1], yn[1:-1, None]
    du = Z[1:-1, 2:] - Z[1:-1, :-2]
    dv = Z[2:, 1:-1] - Z[:-2, 1:-1]
    A = X[1:-1, 2:] - X[1:-1, :-2]
    B = Y[2:, 1:-1] - Y[:-2, 1:-1]
    cx = du * (yi * dv - B)
    cy = dv * (xi * du - A)
    cz = A * B - (xi * yi) * (du * dv)
    defined = (
        valid[1:-1, 1:-1] & valid[1:-1, 2:] & valid[1:-1, :-2] & valid[2:, 1:-1] & valid[:-2, 1:-1]
    )
    towards = cx * xi
    towards += cy * yi
    towards += cz
    length2 = cx * cx
    length2 += cy * cy
    length2 += cz * cz
    return cx, cy, cz, defined, towards, length2


def window_plane(
    win: np.ndarray,
    seed_point: np.ndarray,
    cfg: DescriptorConfig,
    expected: np.ndarray | None = None,
    expected_point: np.ndarray | None = None,
) -> tuple[np.ndarray, float]:
    """Eq. 11: the plane (n̂ towards the camera, c = n̂ · P) of the (N, 3) window points, N ≥ 10.

    With ``cfg.window_hypotheses`` > 0 the points are first restricted to the seed's surface
    (RANSAC): planes through three random window points (a fixed-seed generator, so the result
    is reproducible) are scored by their points within ε1; among the planes that hold the seed
    point (within ε1), or among all if none does (the seed is an outlier, e.g. a depth spike),
    the one with most points is kept, and its points are fitted. Then ``cfg.window_refits``
    least-squares refits on the points within ε1. With ``cfg.window_tolerance_depth`` the
    hypotheses' tolerance shrinks with the seed's depth (see ``DescriptorConfig``). With an
    ``expected`` unit normal (3,) and ``cfg.track_normal_deg``: :func:`tracked_plane` (with
    ``expected_point``, if given).
    """
    if expected is not None and cfg.track_normal_deg > 0:
        return tracked_plane(win, seed_point, cfg, expected, expected_point)
    used = np.ones(len(win), dtype=bool)
    if cfg.window_hypotheses > 0:
        rng = np.random.default_rng(0)
        pick = rng.integers(0, len(win), size=(cfg.window_hypotheses, 3))
        p0 = win[pick[:, 0]]
        a, b = win[pick[:, 1]] - p0, win[pick[:, 2]] - p0
        n = np.cross(a, b)
        length = np.linalg.norm(n, axis=1)
        # Well-conditioned triangles only: the two edges at p0 at least ~6° apart.
        ok = (length > 0) & (length > 0.1 * np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1))
        if ok.any():
            n, p0 = n[ok] / length[ok, None], p0[ok]
            offset = np.einsum("ki,ki->k", n, p0)
            tol = hypothesis_tolerance(seed_point, cfg)
            inliers = np.abs(win @ n.T - offset) < tol  # (N, K)
            counts = inliers.sum(axis=0)
            holds_seed = np.abs(n @ seed_point - offset) < tol
            if holds_seed.any():
                counts = np.where(holds_seed, counts, -1)
            best = int(np.argmax(counts))
            if counts[best] >= MIN_WINDOW_POINTS:
                used = inliers[:, best]
    n_hat, c_hat, _, _ = fit_plane(win[used])
    for _ in range(cfg.window_refits):
        inl = np.abs(win @ n_hat - c_hat) < cfg.eps_distance
        if inl.sum() < MIN_WINDOW_POINTS or np.array_equal(inl, used):
            break
        used = inl
        n_hat, c_hat, _, _ = fit_plane(win[used])
    return n_hat, c_hat


def hypothesis_tolerance(seed_point: np.ndarray, cfg: DescriptorConfig) -> float:
    """The window planes' inlier tolerance: ε1, times min(1, Z_seed / window_tolerance_depth)
    when that is set (metres)."""
    tol = cfg.eps_distance
    if cfg.window_tolerance_depth > 0:
        tol *= min(1.0, float(seed_point[2]) / cfg.window_tolerance_depth)
    return tol


def tracked_plane(
    win: np.ndarray,
    seed_point: np.ndarray,
    cfg: DescriptorConfig,
    expected: np.ndarray,
    expected_point: np.ndarray | None = None,
) -> tuple[np.ndarray, float]:
    """The window plane while tracking a surface of known normal ``expected`` (3,, unit): the
    plane of that normal through the window point that most window points lie within the
    hypotheses' tolerance of (the largest slab of the tracked orientation), its offset the mean
    of those points'. A seed carried to the next frame can sit on the edge or the next face of
    a box; the window's own best plane is then one across both faces, and the region grown
    from it is the wrong face or nothing. The region found from this plane is refitted
    (``cfg.refine``), so the surface's normal is measured afresh in every frame.

    With ``expected_point`` (3,), a point of the tracked surface carried into this frame, and
    ``cfg.track_offset_m`` set: only the slabs within that distance of the tracked plane count.
    Parallel planes share the normal: the top of a cube and the bin floor 7 cm below it both
    face the camera, and a window mostly on the floor made the servo follow the floor. When no
    window point is that near, the plane is the tracked one (the region grows from it, or
    nothing grows: the target is lost)."""
    n = np.asarray(expected, np.float64)
    n = n if n @ seed_point < 0 else -n  # towards the camera, as fit_plane's
    tol = hypothesis_tolerance(seed_point, cfg)
    d = win @ n
    counts = slab_counts(d, tol)  # (N,) per candidate offset: the points within tol of it
    if expected_point is not None and cfg.track_offset_m is not None:
        tracked = float(n @ np.asarray(expected_point, np.float64))
        near = np.abs(d - tracked) < float(cfg.track_offset_m)
        if not near.any():
            return n, tracked
        counts = np.where(near, counts, -1)
    used = np.abs(d - d[int(np.argmax(counts))]) < tol
    return n, float(d[used].mean())


def split_region(points: np.ndarray, sites: np.ndarray) -> np.ndarray:
    """(n,) bool: which of the region's ``points`` (n, 3) are nearer to ``sites[0]`` than to
    every other site of ``sites`` (k, 3) (its Voronoi cell; ties stay). Same frame and unit for
    both. Two equal faces side by side with a site at each centre split at their seam."""
    d2 = ((points[:, None, :] - sites[None, :, :]) ** 2).sum(-1)  # (n, k)
    return d2[:, 0] <= d2[:, 1:].min(axis=1)


class NoSurface(Exception):
    """No surface at the seed; ``reason`` is one of ``NO_SURFACE_REASONS``."""

    def __init__(self, reason: str):
        super().__init__(reason)
        self.reason = reason


def seed_pixel(seed_uv, W: int, H: int) -> tuple[int, int]:
    """The seed's pixel (u, v), rounded; ``NoSurface`` outside the image, ValueError when the
    seed is not two numbers."""
    try:
        seed = np.asarray(seed_uv, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        seed = np.zeros(0)
    if seed.shape != (2,):
        raise ValueError(f"seed_uv must be a pixel (u, v), got {seed_uv!r}")
    if not (np.isfinite(seed).all() and -1 <= seed[0] <= W and -1 <= seed[1] <= H):
        raise NoSurface("seed_outside_image")
    u = int(round(float(seed[0])))
    v = int(round(float(seed[1])))
    if not (0 <= u < W and 0 <= v < H):
        raise NoSurface("seed_outside_image")
    return u, v


@dataclass
class SeedWindow:
    """The seed pixel (u, v), its window [v0, v1) × [u0, u1), the window's points (N, 3)
    (camera frame, metres) and the seed's point (3,)."""

    u: int
    v: int
    v0: int
    v1: int
    u0: int
    u1: int
    points: np.ndarray
    seed_point: np.ndarray
    valid: np.ndarray  # (H, W) bool: pixels with depth

    @classmethod
    def of(
        cls, Z: np.ndarray, xn: np.ndarray, yn: np.ndarray, u: int, v: int, cfg: DescriptorConfig
    ) -> SeedWindow:
        H, W = Z.shape
        valid = Z > 0
        if not valid[v, u] and not cfg.seed_repair:
            raise NoSurface("no_depth_at_seed")
        h = cfg.window // 2
        v0, v1, u0, u1 = max(v - h, 0), min(v + h + 1, H), max(u - h, 0), min(u + h + 1, W)
        wv, wu = np.nonzero(valid[v0:v1, u0:u1])
        if not valid[v, u] and len(wv) == 0:
            raise NoSurface("no_depth_at_seed")
        if len(wv) < MIN_WINDOW_POINTS:
            raise NoSurface("too_few_window_points")
        wv, wu = wv + v0, wu + u0
        zw = Z[wv, wu].astype(np.float64)
        win = np.stack([zw * xn[wu], zw * yn[wv], zw], axis=1)
        # The seed's depth: the median of its 3 × 3 neighbourhood when the seed pixel is more
        # than ε1 from it (a one-pixel crack between two boxes, or a spike): the window plane
        # must be the surface around the seed, not the crack's. A seed pixel without data (a
        # sensor's hole) takes the depth of the nearest window pixel that has one, with
        # seed_repair; the region then grows from the nearest rule pixel (``grown_region``).
        z_seed = float(Z[v, u])
        if z_seed <= 0:
            k = int(np.argmin((wv - v) ** 2 + (wu - u) ** 2))  # the first of equally near ones
            z_seed = float(Z[wv[k], wu[k]])
        around = Z[max(v - 1, 0) : v + 2, max(u - 1, 0) : u + 2]
        around = around[around > 0]
        z_around = float(np.median(around)) if around.size else z_seed
        if cfg.seed_repair and abs(z_seed - z_around) > cfg.eps_distance:
            z_seed = z_around
        seed_point = z_seed * np.array([xn[u], yn[v], 1.0], dtype=np.float64)
        return cls(u, v, v0, v1, u0, u1, win, seed_point, valid)


@dataclass
class PlaneCrop:
    """(2)–(3) Eqs. 12–14 on the crop [r0, r1) × [c0, c1) that can hold the region: its points'
    coordinates ``Xc``, ``Yc``, ``Zc`` (camera frame, metres), the Eq. 12 pixels ``on_plane``
    and the pixels that pass every rule, ``rules`` (all (r1 − r0, c1 − c0))."""

    r0: int
    r1: int
    c0: int
    c1: int
    Xc: np.ndarray
    Yc: np.ndarray
    Zc: np.ndarray
    on_plane: np.ndarray
    rules: np.ndarray
    grow: int

    @classmethod
    def of(
        cls,
        Z: np.ndarray,
        xn: np.ndarray,
        yn: np.ndarray,
        n_hat: np.ndarray,
        d_hat: float,
        window: SeedWindow,
        cfg: DescriptorConfig,
    ) -> PlaneCrop:
        """The region is one connected set of Eq. 12 pixels meeting the window (plus a rim), so
        the bounding box of the Eq. 12 components that meet the window, grown by the rim and
        the one-pixel stencil of Eq. 14, gives exactly the same result as the whole image."""
        H, W = Z.shape
        v0, v1, u0, u1 = window.v0, window.v1, window.u0, window.u1
        nx, ny, nz = (np.float32(a) for a in n_hat)
        # Eq. 12 over the image: Z > 0 (window.valid) and |n̂ · P + D̂| < ε1 (compiled loop)
        on_plane = on_plane_mask(
            Z, xn, yn, nx, ny, nz, np.float32(d_hat), np.float32(cfg.eps_distance)
        )
        # Flood fill (mask only) from the window's Eq. 12 pixels, one fill per component.
        image = on_plane.view(np.uint8)
        filled = np.zeros((H + 2, W + 2), dtype=np.uint8)
        flags = cfg.connectivity | cv2.FLOODFILL_MASK_ONLY | (1 << 8)
        boxes = []
        window_on_plane = on_plane[v0:v1, u0:u1]
        window_filled = filled[v0 + 1 : v1 + 1, u0 + 1 : u1 + 1]  # a view: sees the fills
        while True:  # one pass per component
            left = np.flatnonzero(window_on_plane & (window_filled == 0))
            if len(left) == 0:
                break
            y, x = divmod(int(left[0]), u1 - u0)
            boxes.append(cv2.floodFill(image, filled, (x + u0, y + v0), 1, 0, 0, flags)[3])
        if not boxes:
            raise NoSurface("no_region_at_seed")
        grow = cfg.rim + cfg.normal_smoothing if cfg.rim > 0 else 0
        margin = 1 + grow + cfg.normal_smoothing
        box = np.array(boxes)  # (x, y, width, height) per component
        c0 = max(int(box[:, 0].min()) - margin, 0)
        r0 = max(int(box[:, 1].min()) - margin, 0)
        c1 = min(int((box[:, 0] + box[:, 2]).max()) + margin, W)
        r1 = min(int((box[:, 1] + box[:, 3]).max()) + margin, H)
        Zc = Z[r0:r1, c0:c1]
        Xc = Zc * xn[None, c0:c1]
        Yc = Zc * yn[r0:r1, None]
        on_plane_c, rules = plane_rules(
            Xc, Yc, Zc, window.valid[r0:r1, c0:c1], xn[c0:c1], yn[r0:r1], n_hat, d_hat, cfg
        )
        return cls(r0, r1, c0, c1, Xc, Yc, Zc, on_plane_c, rules, grow)


def grown_region(
    crop: PlaneCrop, window: SeedWindow, sites_cam: np.ndarray | None, cfg: DescriptorConfig
) -> tuple[np.ndarray, np.ndarray]:
    """(4) Region growing and (5) the rim: (the region's flat indices in the crop, row-major,
    as ``region_surface`` needs; the region as a (r1 − r0, c1 − c0) uint8 mask)."""
    r0, r1, c0, c1 = crop.r0, crop.r1, crop.c0, crop.c1
    u, v = window.u, window.v
    # (4) The connected component of the rule pixels at the seed.
    _, labels = cv2.connectedComponents(crop.rules.view(np.uint8), connectivity=cfg.connectivity)
    label = int(labels[v - r0, u - c0]) if (r0 <= v < r1 and c0 <= u < c1) else 0
    sizes = np.bincount(labels.ravel())
    if label == 0 or (cfg.seed_repair and sizes[label] < cfg.min_pixels):
        # the seed fails the rules, or its component is no surface (a one-pixel depth outlier
        # at the seed passes Eq. 13 itself while its four neighbours fail it): the nearest rule
        # pixel in the window ...
        a0, a1 = max(window.v0, r0), min(window.v1, r1)
        b0, b1 = max(window.u0, c0), min(window.u1, c1)
        wl = labels[a0 - r0 : a1 - r0, b0 - c0 : b1 - c0]
        lv, lu = np.nonzero(wl)
        if len(lv) == 0:
            raise NoSurface("no_region_at_seed")
        # ... of a component of at least min_pixels when the window meets one
        big = sizes[wl[lv, lu]] >= cfg.min_pixels
        if cfg.seed_repair and big.any():
            lv, lu = lv[big], lu[big]
        k = int(np.argmin((lv + a0 - v) ** 2 + (lu + b0 - u) ** 2))
        label = int(wl[lv[k], lu[k]])
    grown = (labels == label).view(np.uint8)

    # (5) Rim: boundary pixels satisfying Eq. 12 only. A 3 × 3 (8-neighbour) growth whatever
    # the connectivity: a rectangle's corner pixel touches the rule pixels only diagonally.
    kernel = np.ones((3, 3), np.uint8)
    for _ in range(crop.grow):
        grown = cv2.dilate(grown, kernel) & crop.on_plane.view(np.uint8)
    idx = np.flatnonzero(grown)  # row-major, as region_surface needs
    if sites_cam is not None and len(sites_cam) > 1:
        keep = split_region(crop_points(crop, idx), np.asarray(sites_cam, np.float64))
        idx = idx[keep]
        grown = np.zeros_like(grown)
        grown.ravel()[idx] = 1
    if len(idx) < cfg.min_pixels:
        raise NoSurface("region_too_small")
    return idx, grown


def crop_points(crop: PlaneCrop, idx: np.ndarray) -> np.ndarray:
    """(N, 3) float64 camera-frame points of the crop's flat indices ``idx``."""
    return np.stack(
        [crop.Xc.ravel()[idx], crop.Yc.ravel()[idx], crop.Zc.ravel()[idx]], axis=1
    ).astype(np.float64)
