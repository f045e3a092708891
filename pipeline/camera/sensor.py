"""An optional depth-sensor model applied to ideal rendered depth (``conf/sensor/*.yaml``)."""

from __future__ import annotations

import numpy as np


def apply_sensor_model(depth_m: np.ndarray, sensor_cfg, rng: np.random.Generator) -> np.ndarray:
    """Noisy copy of an ideal depth image.

    Args:
        depth_m: (H, W) float32 ideal z-depth, metres.
        sensor_cfg: a ``SensorConfig``; returns ``depth_m`` unchanged when not enabled.
        rng: the scene's generator (draws: noise, then dropout), so output is reproducible.

    Returns:
        (H, W) float32 depth in metres, 0 where the sensor returns no data.
    """
    if not sensor_cfg.enabled:
        return depth_m
    z = depth_m.astype(np.float64)
    out = z + rng.normal(size=z.shape) * sensor_cfg.noise_sigma_at_1m * z * z
    if sensor_cfg.edge_dropout_prob > 0:
        jump = np.zeros(z.shape, dtype=bool)
        dv = np.abs(np.diff(z, axis=0)) > sensor_cfg.edge_jump
        du = np.abs(np.diff(z, axis=1)) > sensor_cfg.edge_jump
        jump[1:, :] |= dv
        jump[:-1, :] |= dv
        jump[:, 1:] |= du
        jump[:, :-1] |= du
        drop = jump & (rng.random(z.shape) < sensor_cfg.edge_dropout_prob)
        out[drop] = 0.0
    if sensor_cfg.quantisation_step > 0:
        out = np.round(out / sensor_cfg.quantisation_step) * sensor_cfg.quantisation_step
    return np.clip(out, 0.0, None).astype(np.float32)
