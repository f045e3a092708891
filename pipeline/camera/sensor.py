"""A depth-sensor model for an SR300-class coded-light camera (``conf/sensor/*.yaml``).

The renderer gives ideal z-depth. ``apply_sensor_model`` turns it into what a structured-light
camera returns, in four steps (parameters and their sources: ``conf/sensor/sr300.yaml`` and the
"The sensor model" in docs/robustness.md):

1. **Surface normal and incidence angle** θ of every pixel, from the ideal depth
   (``incidence_angles``): the angle between the viewing ray and the surface normal.
2. **Missing data** (depth 0):

   * *projector shadow* (``projector_shadow``): the pattern projector sits ``projector_baseline``
     metres beside the IR camera along the camera's x axis. A point the projector cannot see
     gets no depth: beside every depth step, a band of f·b·(1/z_near − 1/z_far) pixels on the
     far surface, on the side away from the projector;
   * *steep surfaces*: the reflected pattern is too weak and too stretched to decode: a pixel
     is lost with a probability rising linearly from 0 at θ = ``dropout_angle_start_deg`` to 1
     at θ = ``dropout_angle_deg``;
   * *out of range*: ideal depth outside [``min_range``, ``max_range``];
   * *mixed pixels at depth steps*: a pixel whose depth differs from a 4-neighbour by more
     than ``edge_jump`` is lost with probability ``edge_dropout_prob``;
   * *holes* (``hole_mask``): square blobs of ``hole_size_px`` pixels anywhere in the image,
     covering about ``hole_rate`` of it (dark or specular spots; 0 = none).
3. **Axial noise**, Gaussian with standard deviation (Nguyen, Izadi & Lovell 2012's form)

       σ(z, θ) = noise_sigma_0 + noise_sigma_2 · z² + noise_sigma_theta / √z · θ² / (π/2 − θ)²

   (metres, z in metres, θ in radians): growing with the square of depth (triangulation)
   and sharply at grazing incidence.
4. **Calibration error**: depth × (1 + ``depth_scale_error``) + ``depth_bias`` (0 and 0 in
   the SR300 profile; the randomised training depth draws both).
5. **Quantisation** to the sensor's depth unit (``quantisation_step``).

Not modelled: lateral (pixel-position) noise, multi-path and interference between cameras,
temporal noise (one image per scene), the firmware's own smoothing.

Random draws, in this order from the caller's generator: the noise (H·W normals), the
steep-surface uniforms (H·W, only when ``dropout_angle_deg < 90``), then the edge-dropout
uniforms (H·W, only when ``edge_dropout_prob > 0``), then the hole blobs' uniforms
(⌈H/s⌉·⌈W/s⌉ for blob side s, only when ``hole_rate > 0``). A disabled model returns the
input itself and draws nothing.
"""

from __future__ import annotations

import numpy as np

from pipeline.camera.geometry import Intrinsics
from pipeline.camera.sensor_kernels import incidence_cos_into


def incidence_angles(depth_m: np.ndarray, intr: Intrinsics) -> np.ndarray:
    """Angle between each pixel's viewing ray and its surface normal.

    The normal is the cross product of the camera-frame tangents along u and v; each tangent is
    the one-sided difference towards the neighbour with the smaller depth step, so a pixel at
    a depth step takes the tangent of its own surface. The per-pixel loop is compiled
    (``pipeline/camera/sensor_kernels.py``; its numpy form, bit for bit the same, is
    ``pipeline/tools/bench/sensor_reference.py``).

    Args:
        depth_m: (H, W) ideal z-depth, metres (0 = no data).
        intr: the image's intrinsics.

    Returns:
        (H, W) float64 radians in [0, π/2]; 0 where the pixel or both neighbours lack data.
    """
    z = np.ascontiguousarray(depth_m, np.float64)
    H, W = z.shape
    xn = (np.arange(W, dtype=np.float64) - intr.cx) / intr.fx
    yn = (np.arange(H, dtype=np.float64) - intr.cy) / intr.fy
    cos = np.empty((H, W), dtype=np.float64)
    incidence_cos_into(z, xn, yn, cos)
    ok = cos >= 0
    theta = np.arccos(np.clip(np.where(ok, cos, 0.0), 0.0, 1.0))
    return np.where(ok, theta, 0.0)


def projector_shadow(depth_m: np.ndarray, intr: Intrinsics, baseline_m: float) -> np.ndarray:
    """Pixels the pattern projector cannot see (structured light's shadows).

    The projector is at (``baseline_m``, 0, 0) in the camera frame (negative: at −x), looking
    along z. A camera pixel (u, v) at depth z meets the projector's column
    u_p = u − f_x·b/z on the same row; a point is hidden from the projector when a point
    closer to it on that row maps to a projector column at or past its own. For b > 0 that is
    u_p(u) > min_{u' > u} u_p(u'); for b < 0 the mirror image.

    Args:
        depth_m: (H, W) ideal z-depth, metres (0 = no data: neither casts nor receives shadow).
        intr: the image's intrinsics.
        baseline_m: projector offset along the camera's x axis, metres (0 = no shadows).

    Returns:
        (H, W) bool, True where the pixel is in the projector's shadow.
    """
    z = np.asarray(depth_m, np.float64)
    if baseline_m == 0:
        return np.zeros(z.shape, dtype=bool)
    fb = intr.fx * abs(baseline_m)
    cols = np.arange(z.shape[1], dtype=np.float64)[None, :]
    valid = z > 0
    if baseline_m > 0:
        up = np.where(valid, cols - fb / np.where(valid, z, 1.0), np.inf)
        # smallest projector column strictly to the right of each pixel
        right_min = np.minimum.accumulate(up[:, ::-1], axis=1)[:, ::-1]
        ahead = np.concatenate([right_min[:, 1:], np.full((z.shape[0], 1), np.inf)], axis=1)
        # 0.5 px: a plane tilted away from the projector by less than that per pixel is lit
        return valid & (up > ahead + 0.5)
    up = np.where(valid, cols + fb / np.where(valid, z, 1.0), -np.inf)
    left_max = np.maximum.accumulate(up, axis=1)
    behind = np.concatenate([np.full((z.shape[0], 1), -np.inf), left_max[:, :-1]], axis=1)
    return valid & (up < behind - 0.5)


def depth_steps(depth_m: np.ndarray, jump_m: float) -> np.ndarray:
    """(H, W) bool: pixels whose depth differs from a 4-neighbour by more than ``jump_m``."""
    z = np.asarray(depth_m, np.float64)
    step = np.zeros(z.shape, dtype=bool)
    dv = np.abs(np.diff(z, axis=0)) > jump_m
    du = np.abs(np.diff(z, axis=1)) > jump_m
    step[1:, :] |= dv
    step[:-1, :] |= dv
    step[:, 1:] |= du
    step[:, :-1] |= du
    return step


def steep_dropout(theta: np.ndarray, sensor_cfg, rng: np.random.Generator) -> np.ndarray:
    """(H, W) bool: pixels lost for their incidence angle ``theta`` (radians): probability 0 up
    to ``dropout_angle_start_deg``, rising linearly to 1 at ``dropout_angle_deg``. Draws H·W
    uniforms unless ``dropout_angle_deg`` is 90 or more (off)."""
    hi = float(sensor_cfg.dropout_angle_deg)
    if hi >= 90:
        return np.zeros(theta.shape, dtype=bool)
    lo = min(float(sensor_cfg.dropout_angle_start_deg), hi)
    deg = np.rad2deg(theta)
    prob = np.clip((deg - lo) / max(hi - lo, 1e-9), 0.0, 1.0)
    prob = np.where(deg >= hi, 1.0, prob)
    return rng.random(theta.shape) < prob


def hole_mask(
    shape: tuple[int, int], rate: float, size_px: int, rng: np.random.Generator
) -> np.ndarray:
    """(H, W) bool: the image cut into ``size_px`` × ``size_px`` blocks, each lost with
    probability ``rate`` (so about ``rate`` of the image is lost, in square blobs)."""
    if size_px < 1:
        raise ValueError(f"sensor hole_size_px must be >= 1, got {size_px}")
    H, W = shape
    blocks = rng.random((-(-H // size_px), -(-W // size_px))) < rate
    return np.repeat(np.repeat(blocks, size_px, axis=0), size_px, axis=1)[:H, :W]


def noise_sigma(z: np.ndarray, theta: np.ndarray, sensor_cfg) -> np.ndarray:
    """σ(z, θ) of the module docstring, metres. ``z`` metres, ``theta`` radians (< π/2).

    The angle term grows without bound as θ → π/2 (1 m at 89° for σθ = 0.1 mm): with
    ``noise_sigma_theta > 0`` keep the steep-surface dropout on (``dropout_angle_deg`` < 90),
    as ``conf/sensor/sr300.yaml`` does (no pixel beyond 78° keeps data)."""
    z = np.asarray(z, np.float64)
    theta = np.minimum(np.asarray(theta, np.float64), np.pi / 2 - 1e-3)
    sigma = float(sensor_cfg.noise_sigma_0) + float(sensor_cfg.noise_sigma_2) * z * z
    k = float(sensor_cfg.noise_sigma_theta)
    if k:
        sigma = sigma + k / np.sqrt(np.maximum(z, 1e-6)) * theta**2 / (np.pi / 2 - theta) ** 2
    return sigma


def apply_sensor_model(
    depth_m: np.ndarray, sensor_cfg, rng: np.random.Generator, intr: Intrinsics
) -> np.ndarray:
    """What the sensor returns for an ideal depth image (module docstring).

    Args:
        depth_m: (H, W) float32 ideal z-depth, metres (0 = no data).
        sensor_cfg: a ``SensorConfig``; returns ``depth_m`` itself when not enabled.
        rng: the scene's generator (draws: noise, steep-surface, then edge dropout; see the
            module docstring), so the output is reproducible.
        intr: the image's intrinsics (normals and projector shadows need them).

    Returns:
        (H, W) float32 depth in metres, 0 where the sensor returns no data.
    """
    if not sensor_cfg.enabled:
        return depth_m
    z = np.asarray(depth_m, np.float64)
    if z.shape != (intr.height, intr.width):
        raise ValueError(
            f"depth image has shape {z.shape}, expected (H, W) = "
            f"({intr.height}, {intr.width}) from the camera intrinsics"
        )
    valid = z > 0
    theta = incidence_angles(z, intr)
    out = z + rng.normal(size=z.shape) * noise_sigma(z, theta, sensor_cfg)
    lost = ~valid | (z < float(sensor_cfg.min_range)) | (z > float(sensor_cfg.max_range))
    lost |= projector_shadow(z, intr, float(sensor_cfg.projector_baseline))
    lost |= steep_dropout(theta, sensor_cfg, rng)
    if float(sensor_cfg.edge_dropout_prob) > 0:
        lost |= depth_steps(z, float(sensor_cfg.edge_jump)) & (
            rng.random(z.shape) < float(sensor_cfg.edge_dropout_prob)
        )
    if float(sensor_cfg.hole_rate) > 0:
        lost |= hole_mask(z.shape, float(sensor_cfg.hole_rate), int(sensor_cfg.hole_size_px), rng)
    out = out * (1.0 + float(sensor_cfg.depth_scale_error)) + float(sensor_cfg.depth_bias)
    step = float(sensor_cfg.quantisation_step)
    if step > 0:
        out = np.round(out / step) * step
    out[lost] = 0.0
    return np.clip(out, 0.0, None).astype(np.float32)
