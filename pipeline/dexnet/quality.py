"""Analytic, training-free suction quality from the depth image alone, after gqcnn's disc approach
planarity (``DiscApproachPlanarityFunction`` in ``gqcnn/grasping/grasp_quality_function.py``).

Frames and units as in ``pipeline.dexnet.sampling``: camera frame (OpenCV, metres), pixel (u, v).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.dexnet.sampling import Candidates, PointCloudImage


@dataclass
class PlanarityConfig:
    """Parameters of :func:`disc_planarity`: ``dexnet.planarity`` with the cup radius
    ``hand.cup_diameter`` / 2, built by ``pipeline.dexnet.planner.planarity_config``.

    Attributes:
        cup_radius: suction cup radius in metres; the disc the seal needs.
        sigma: residual scale in metres: ``q = exp(-mean(residual^2) / sigma^2)``.
        min_coverage: share of the disc's expected pixels that must have depth data, else
            ``q = 0`` (holes break the seal).
    """

    cup_radius: float
    sigma: float
    min_coverage: float


def disc_planarity(cloud: PointCloudImage, cands: Candidates, cfg: PlanarityConfig) -> np.ndarray:
    """Disc approach planarity of suction candidates, in [0, 1].

    For a candidate with contact point ``c`` and unit approach axis ``a`` (camera frame), the
    approach plane passes through ``c`` with normal ``a``. Over the pixel window that covers the
    disc (half-size ``h = ceil(cup_radius * max(fx, fy) / depth) + 1`` pixels, centred on the
    candidate's pixel):

    * the *disc points* are the observed points ``p`` whose distance from ``c`` measured in the
      approach plane, ``|(p - c) - ((p - c) . a) a|``, is at most ``cup_radius``; their residual is
      the distance to the plane, ``|(p - c) . a|``;
    * the *expected pixels* are those whose viewing ray meets the approach plane within
      ``cup_radius`` of ``c`` (the disc's footprint in the image); coverage = share of them that
      have depth data. Pixels outside the image count as missing.

    ``q = exp(-mean(residual^2) / sigma^2)`` if coverage >= ``min_coverage``, else 0. A disc that
    crosses a depth edge gets residuals of the step height, hence q ~ 0; a hole gives q = 0. All
    depth data counts, not only the object mask's pixels: the cup touches whatever is there.

    Vectorised over the candidates that share a window size (few groups in practice).

    Args:
        cloud: the image's :class:`PointCloudImage` (must carry its ``intrinsics``).
        cands: N candidates.
        cfg: parameters.

    Returns:
        (N,) float64 quality in [0, 1]; 0 for candidates with non-positive depth.
    """
    n = len(cands)
    q = np.zeros(n)
    if n == 0:
        return q
    intr = cloud.intrinsics
    if intr is None:
        raise ValueError("disc_planarity needs cloud.intrinsics (build it with point_cloud_image)")
    H, W = cloud.shape
    r = float(cfg.cup_radius)
    f = max(intr.fx, intr.fy)
    c_all = np.asarray(cands.point, np.float64)
    a_all = np.asarray(cands.axis, np.float64)
    a_all = a_all / np.maximum(np.linalg.norm(a_all, axis=1, keepdims=True), 1e-12)
    z = np.asarray(cands.depth, np.float64)
    ok = np.isfinite(z) & (z > 0) & np.all(np.isfinite(c_all), axis=1)
    half = np.zeros(n, np.int64)
    half[ok] = np.ceil(r * f / z[ok]).astype(np.int64) + 1

    for h in np.unique(half[ok]):
        idx = np.nonzero(ok & (half == h))[0]
        off = np.arange(-h, h + 1)
        du, dv = np.meshgrid(off, off)  # (S, S)
        u = cands.uv[idx, 0][:, None] + du.reshape(1, -1)  # (K, S*S)
        v = cands.uv[idx, 1][:, None] + dv.reshape(1, -1)
        inside = (u >= 0) & (u < W) & (v >= 0) & (v < H)
        ui, vi = np.clip(u, 0, W - 1), np.clip(v, 0, H - 1)
        has = inside & (cloud.depth[vi, ui] > 0)
        p = cloud.points[vi, ui]  # (K, M, 3)
        c = c_all[idx][:, None, :]
        a = a_all[idx][:, None, :]

        # Observed disc points and their distances to the approach plane.
        d = p - c
        along = np.einsum("kmc,kmc->km", d, a)
        lateral2 = np.einsum("kmc,kmc->km", d, d) - along**2
        in_disc = has & (lateral2 <= r * r)
        cnt = in_disc.sum(axis=1)
        msr = np.where(in_disc, along**2, 0.0).sum(axis=1) / np.maximum(cnt, 1)

        # Expected footprint: rays through the window pixels meet the plane within r of c.
        rays = np.stack(
            [(u - intr.cx) / intr.fx, (v - intr.cy) / intr.fy, np.ones(u.shape)], axis=-1
        )  # (K, M, 3)
        denom = np.einsum("kmc,kmc->km", rays, a)
        num = np.einsum("kc,kc->k", c_all[idx], a_all[idx])[:, None]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = num / denom
        hit = rays * t[..., None]
        expected = (denom > 1e-9) & (t > 0) & (np.sum((hit - c) ** 2, axis=-1) <= r * r)
        n_exp = expected.sum(axis=1)
        cover = (expected & has).sum(axis=1) / np.maximum(n_exp, 1)

        qg = np.exp(-msr / cfg.sigma**2)
        qg[(n_exp == 0) | (cnt == 0) | (cover < cfg.min_coverage)] = 0.0
        q[idx] = qg
    return q
