"""Suction candidate sampling on a depth image, after gqcnn's ``DepthImageSuctionPointSampler``
(``gqcnn/grasping/grasp_sampler.py``) and autolab_core's ``PointCloudImage.normal_cloud_im``.

Frames and units (see ``pipeline.camera.geometry``):
    pixel  (u, v): u = column (right), v = row (down); (0, 0) is the centre of the top-left pixel.
    camera (x, y, z): OpenCV convention, x right, y down, z forward along the optical axis; metres.
    depth images: (H, W) float z-depth in metres; 0 (or non-finite) = no data.

A suction candidate is a pixel (u, v), the camera-frame point seen there, and an approach axis
``axis = -normal`` that points *into* the surface (away from the camera, so ``axis_z > 0`` on a
surface facing the camera). Its approach angle is the angle between ``axis`` and the optical
axis ``+z``.

Edge pixels (decision): like gqcnn, there is no separate depth-edge detector. Pixels whose Sobel
window touches a pixel without data are invalid. Pixels whose Sobel window spans a depth step get
a normal tilted towards the step; steps taller than about ``2 * pixel pitch * tan(30 deg)``
(≈ 3 mm at 0.5 m with fx = 200, ≈ 1.5 mm at 0.625 m with the SR300's fx = 411.7) tilt it past the
30° limit, so those pixels are rejected by the approach-angle test. Lower steps pass as gently
tilted surfaces, exactly as in Dex-Net; the quality function (e.g.
``quality.disc_planarity``) has to penalise them.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from pipeline.camera.geometry import Intrinsics


@dataclass
class SamplerConfig:
    """Parameters of gqcnn's ``DepthImageSuctionPointSampler`` (Dex-Net 4.0 suction config):
    ``conf/dexnet/``, built by ``pipeline.dexnet.planner.sampler_config``.

    Attributes:
        border_px: reject candidates closer than this many pixels to the image border, i.e. keep
            only ``border_px <= u <= W - 1 - border_px`` and likewise for v (68 = sqrt(2) x half
            of a 96-px GQ-CNN crop, so a crop rotated by any angle stays inside the image).
        max_approach_angle_deg: reject candidates whose approach axis is more than this many
            degrees from the optical axis.
        max_tries: number of pixels drawn (without replacement) before giving up.
        sobel_ksize: aperture of the ``cv2.Sobel`` derivatives used for the normals.
    """

    border_px: int
    max_approach_angle_deg: float
    max_tries: int
    sobel_ksize: int


@dataclass
class PointCloudImage:
    """Per-pixel geometry of one depth image, computed once by :func:`point_cloud_image`.

    Attributes:
        points: (H, W, 3) float64 camera-frame points in metres; (0, 0, 0) where there is no data.
        normals: (H, W, 3) float64 unit surface normals pointing towards the camera
            (``n . p < 0``); (0, 0, 0) where undefined (no data in the Sobel window, or a
            degenerate cross product).
        valid: (H, W) bool; depth > 0, the whole Sobel window has data, a finite non-zero normal,
            and (if one was given) inside the caller's object mask.
        depth: (H, W) float64 z-depth in metres, 0 where there is no data.
        intrinsics: the camera intrinsics the points were back-projected with (needed by the
            quality functions to size pixel windows); ``None`` only for hand-built images.
    """

    points: np.ndarray
    normals: np.ndarray
    valid: np.ndarray
    depth: np.ndarray
    intrinsics: Intrinsics | None = field(default=None)

    @property
    def shape(self) -> tuple[int, int]:
        """(H, W) of the image."""
        return self.depth.shape


def point_cloud_image(
    depth_m: np.ndarray,
    intrinsics: Intrinsics,
    cfg: SamplerConfig,
    object_mask: np.ndarray | None = None,
) -> PointCloudImage:
    """Back-project a depth image and estimate per-pixel normals, as autolab_core's
    ``CameraIntrinsics.deproject_to_image`` + ``PointCloudImage.normal_cloud_im``.

    The normal at a pixel is ``normalize(gx x gy)`` with ``gx``/``gy`` the ``cv2.Sobel``
    derivatives (aperture ``cfg.sobel_ksize``) of the XYZ image along u and v, flipped so that it
    faces the camera. Pixels whose Sobel window touches a pixel without data (or leaves the image)
    are invalid, so no normal is ever computed from the zeros of missing data.

    Unlike gqcnn, which zeroes the depth outside the segmentation mask before computing normals,
    the normals here are computed from the full depth image and the mask only restricts ``valid``:
    pixels on the rim of the mask keep their true surface normal.

    Args:
        depth_m: (H, W) z-depth in metres; 0 or non-finite = no data.
        intrinsics: pinhole intrinsics of the (W x H) image.
        cfg: sampler parameters (only ``sobel_ksize`` is used).
        object_mask: optional (H, W) bool/int mask; non-zero = pixels that may be candidates.

    Returns:
        The :class:`PointCloudImage`.
    """
    depth = np.asarray(depth_m, dtype=np.float64)
    H, W = intrinsics.height, intrinsics.width
    if depth.shape != (H, W):
        raise ValueError(
            f"depth image has shape {depth.shape}, expected (H, W) = ({H}, {W}) "
            "from the camera intrinsics"
        )
    has_data = np.isfinite(depth) & (depth > 0)
    depth = np.where(has_data, depth, 0.0)

    # Back-projection in float64 (same convention as geometry.backproject, which is float32).
    xr = ((np.arange(W, dtype=np.float64) - intrinsics.cx) / intrinsics.fx)[None, :]
    yr = ((np.arange(H, dtype=np.float64) - intrinsics.cy) / intrinsics.fy)[:, None]
    X, Y, Z = xr * depth, yr * depth, depth

    # Sobel derivatives of the XYZ image along u (gx) and v (gy), one channel at a time, and
    # n = gx x gy written out (much faster than np.cross on (H, W, 3)).
    k = int(cfg.sobel_ksize)
    gxX, gxY, gxZ = (cv2.Sobel(c, cv2.CV_64F, 1, 0, ksize=k) for c in (X, Y, Z))
    gyX, gyY, gyZ = (cv2.Sobel(c, cv2.CV_64F, 0, 1, ksize=k) for c in (X, Y, Z))
    nx = gxY * gyZ - gxZ * gyY
    ny = gxZ * gyX - gxX * gyZ
    nz = gxX * gyY - gxY * gyX
    norm = np.sqrt(nx * nx + ny * ny + nz * nz)
    # Face the camera: n . p < 0 (p is the pixel's ray direction up to a positive scale, so the
    # ray (xr, yr, 1) decides the side even where the depth is 0).
    side = nx * xr + ny * yr + nz
    flip = (side > 0) | ((side == 0) & (nz > 0))

    # Every pixel of the Sobel window (kernel side k; 3 for ksize 1) must have data and lie inside
    # the image: erode the data mask, treating everything outside the image as no data.
    side_px = max(k, 3)
    window_ok = cv2.erode(
        has_data.astype(np.uint8),
        np.ones((side_px, side_px), np.uint8),
        borderType=cv2.BORDER_CONSTANT,
        borderValue=0,
    ).astype(bool)
    good = window_ok & np.isfinite(norm) & (norm > 0)
    scale = np.zeros_like(norm)
    scale[good] = np.where(flip[good], -1.0, 1.0) / norm[good]
    normals = np.stack([nx * scale, ny * scale, nz * scale], axis=-1)
    points = np.stack([X, Y, np.broadcast_to(Z, X.shape)], axis=-1)
    valid = good
    if object_mask is not None:
        mask = np.asarray(object_mask)
        if mask.shape != (H, W):
            raise ValueError(f"object mask has shape {mask.shape}, expected ({H}, {W})")
        valid = valid & (mask != 0)
    return PointCloudImage(
        points=points, normals=normals, valid=valid, depth=depth, intrinsics=intrinsics
    )


@dataclass
class Candidates:
    """N suction candidates (gqcnn's ``SuctionPoint2D``, as a struct of arrays).

    Attributes:
        uv: (N, 2) int64 pixel (u, v).
        point: (N, 3) float64 camera-frame contact point, metres.
        axis: (N, 3) float64 unit approach axis = -normal (into the object, away from the camera).
        depth: (N,) float64 z of the point, metres.
        angle: (N,) float64 angle between ``axis`` and the optical axis +z, radians.
    """

    uv: np.ndarray
    point: np.ndarray
    axis: np.ndarray
    depth: np.ndarray
    angle: np.ndarray

    def __len__(self) -> int:
        return int(self.uv.shape[0])

    def take(self, idx) -> Candidates:
        """The candidates selected by ``idx`` (integer indices or an (N,) bool mask)."""
        idx = np.asarray(idx)
        if idx.dtype != bool:
            idx = idx.astype(np.int64).reshape(-1)
        return Candidates(
            uv=self.uv[idx],
            point=self.point[idx],
            axis=self.axis[idx],
            depth=self.depth[idx],
            angle=self.angle[idx],
        )

    @staticmethod
    def empty() -> Candidates:
        """Zero candidates with correctly shaped arrays."""
        return Candidates(
            uv=np.zeros((0, 2), np.int64),
            point=np.zeros((0, 3)),
            axis=np.zeros((0, 3)),
            depth=np.zeros(0),
            angle=np.zeros(0),
        )

    @staticmethod
    def concat(parts: list[Candidates]) -> Candidates:
        """Concatenate candidate sets in order; an empty list gives :meth:`empty`."""
        parts = [p for p in parts if len(p)]
        if not parts:
            return Candidates.empty()
        return Candidates(
            uv=np.concatenate([p.uv for p in parts]),
            point=np.concatenate([p.point for p in parts]),
            axis=np.concatenate([p.axis for p in parts]),
            depth=np.concatenate([p.depth for p in parts]),
            angle=np.concatenate([p.angle for p in parts]),
        )


def candidates_at(cloud: PointCloudImage, uv, cfg: SamplerConfig) -> tuple[Candidates, np.ndarray]:
    """Candidates at given pixels, with gqcnn's acceptance tests.

    Depth and approach axis are read from the image at each pixel, as gqcnn does for both the
    sampler's draws and the cross-entropy method's GMM samples.

    Args:
        cloud: the image's :class:`PointCloudImage`.
        uv: (N, 2) pixel (u, v); integers (non-integer values are rounded to the nearest pixel).
        cfg: sampler parameters (``border_px``, ``max_approach_angle_deg``).

    Returns:
        ``(cands, ok)``: ``ok`` is an (N,) bool array, true where the pixel is inside the image,
        ``border_px <= u <= W-1-border_px`` and ``border_px <= v <= H-1-border_px``, valid in
        ``cloud``, and the approach angle is <= ``max_approach_angle_deg``; ``cands`` holds the
        ``ok.sum()`` accepted candidates, in input order.
    """
    uv = np.asarray(uv)
    if uv.size == 0:
        return Candidates.empty(), np.zeros(0, bool)
    uv = uv.reshape(-1, 2)
    if not np.issubdtype(uv.dtype, np.integer):
        uv = np.rint(np.where(np.isfinite(uv), uv, -1))
    uv = uv.astype(np.int64)
    H, W = cloud.shape
    b = int(cfg.border_px)
    u, v = uv[:, 0], uv[:, 1]
    ok = (u >= b) & (u <= W - 1 - b) & (v >= b) & (v <= H - 1 - b)
    ok &= (u >= 0) & (u < W) & (v >= 0) & (v < H)  # also when border_px < 0
    ui, vi = np.where(ok, u, 0), np.where(ok, v, 0)
    ok &= cloud.valid[vi, ui]
    axis = -cloud.normals[vi, ui]
    angle = np.arccos(np.clip(axis[:, 2], -1.0, 1.0))
    ok &= angle <= np.deg2rad(cfg.max_approach_angle_deg)
    cands = Candidates(
        uv=uv[ok],
        point=cloud.points[vi[ok], ui[ok]],
        axis=axis[ok],
        depth=cloud.depth[vi[ok], ui[ok]],
        angle=angle[ok],
    )
    return cands, ok


def sample_candidates(
    cloud: PointCloudImage, num: int, rng: np.random.Generator, cfg: SamplerConfig
) -> Candidates:
    """Draw suction candidates as gqcnn's ``DepthImageSuctionPointSampler._sample_suction_points``.

    Pixels are drawn uniformly *without replacement* from the valid pixels, at most
    ``min(cfg.max_tries, number of valid pixels)`` of them; each draw is kept if
    :func:`candidates_at` accepts it, and drawing stops once ``num`` are kept. The draws are made
    at once and checked in vectorised batches, in draw order; the result is the same as gqcnn's
    one-at-a-time loop.

    Returns:
        Up to ``num`` distinct candidates, in draw order. **May return fewer** (possibly none)
        when the tries run out: few valid pixels, or most of them in the border or too steep.
    """
    num = int(num)
    if num <= 0:
        return Candidates.empty()
    vs, us = np.nonzero(cloud.valid)
    n_valid = us.size
    n_tries = min(int(cfg.max_tries), n_valid)
    if n_tries <= 0:
        return Candidates.empty()
    pick = rng.choice(n_valid, size=n_tries, replace=False)
    # Evaluate the draws in batches, in draw order, and stop once `num` are accepted.
    batch = max(4 * num, 1024)
    parts: list[Candidates] = []
    kept = 0
    for start in range(0, n_tries, batch):
        sel = pick[start : start + batch]
        uv = np.stack([us[sel], vs[sel]], axis=1).astype(np.int64)
        cands, _ok = candidates_at(cloud, uv, cfg)
        cands = cands.take(np.arange(min(num - kept, len(cands))))
        parts.append(cands)
        kept += len(cands)
        if kept >= num:
            break
    return Candidates.concat(parts)
