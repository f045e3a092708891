"""Camera randomisation for training depth (``generate.camera_randomisation``; docs/generation.md,
"Camera randomisation").

One network for every depth camera: in the randomised splits a scene keeps its ideal depth with
probability ``ideal_fraction``; otherwise a sensor model (``pipeline.camera.sensor``) is drawn,
every parameter uniformly from its [low, high] range (``hole_size_px`` an integer in its range,
``dropout_angle_deg`` = start + span, below 90° so that grazing pixels, whose noise grows without
bound, are always lost), and the ideal depth goes through it.

The draws come from a generator of their own per scene (``randomisation_rng``), so that the
heaps, and the sensor= model's own draws, are the same with and without randomisation.
"""

from __future__ import annotations

import numpy as np

from pipeline.config.physical import SensorConfig

# The generator key of the randomisation stream (scene seeds are (seed, split code, index)).
STREAM_KEY = 977

_RANGES = (
    "noise_sigma_0",
    "noise_sigma_2",
    "noise_sigma_theta",
    "projector_baseline",
    "edge_dropout_prob",
    "quantisation_step",
    "hole_rate",
    "depth_bias",
    "depth_scale_error",
)


def randomisation_rng(seed: int, split_code: int, index: int) -> np.random.Generator:
    """The scene's randomisation generator: a pure function of (seed, split, index)."""
    return np.random.default_rng([int(seed), int(split_code), int(index), STREAM_KEY])


def check_randomisation(cfg) -> None:
    """Raise ``ValueError`` naming the key when ``generate.camera_randomisation``'s values are
    invalid (its split names are the generation stage's to check)."""
    if not 0 <= float(cfg.ideal_fraction) <= 1:
        raise ValueError("generate.camera_randomisation.ideal_fraction must be in [0, 1]")
    if cfg.dropout_angle_start_deg[1] + cfg.dropout_angle_span_deg[1] >= 90:
        raise ValueError(
            "generate.camera_randomisation: dropout_angle_start_deg + "
            "dropout_angle_span_deg must stay below 90 (grazing pixels must be lost: "
            "their noise grows without bound)"
        )
    for key in (*_RANGES, "dropout_angle_start_deg", "dropout_angle_span_deg", "hole_size_px"):
        lo, hi = getattr(cfg, key)
        if lo > hi:
            raise ValueError(f"generate.camera_randomisation.{key} = [{lo}, {hi}]: low > high")
    if cfg.hole_size_px[0] < 1:
        raise ValueError("generate.camera_randomisation.hole_size_px must be >= 1")


def draw_sensor(cfg, rng: np.random.Generator) -> SensorConfig | None:
    """None (keep the ideal depth) with probability ``cfg.ideal_fraction``, else a sensor model
    drawn from ``cfg``'s ranges. Draws: one uniform, then (when a model is drawn) one per
    parameter in ``_RANGES`` order, the dropout start and span, the hole size."""
    if rng.random() < float(cfg.ideal_fraction):
        return None
    v = {k: float(rng.uniform(*getattr(cfg, k))) for k in _RANGES}
    start = float(rng.uniform(*cfg.dropout_angle_start_deg))
    span = float(rng.uniform(*cfg.dropout_angle_span_deg))
    hole = int(rng.integers(int(cfg.hole_size_px[0]), int(cfg.hole_size_px[1]) + 1))
    return SensorConfig(
        name="randomised",
        enabled=True,
        dropout_angle_start_deg=start,
        dropout_angle_deg=start + span,
        hole_size_px=hole,
        min_range=float(cfg.min_range),
        max_range=float(cfg.max_range),
        edge_jump=float(cfg.edge_jump),
        **v,
    )
