"""One scene's grasp-point labels (paper Sec. 4.3): surfaces, hand level, robot level.

``label_scene`` is what the labelling stage runs per scene and what the oracle planner runs on
the closed loop's home image; its rows are ``pipeline.dataset.labels.LABEL_FIELDS``.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from pipeline.config.build import from_section
from pipeline.dataset.scenes import Scene
from pipeline.labelling.hand import hand_label
from pipeline.labelling.surfaces import (
    SurfaceDetectionConfig, detect_surfaces, match_surfaces, true_visible_faces,
)
from pipeline.labelling.types import NG_REASONS, GraspClass


def surface_config(cfg) -> SurfaceDetectionConfig:
    """The surface detection settings of a composed config's ``surfaces`` group."""
    return from_section(SurfaceDetectionConfig, cfg.surfaces)


def label_scene(scene: Scene, cfg, robot=None, bin_cfg=None
                ) -> tuple[dict[str, np.ndarray], dict, float, float]:
    """Grasp points of one scene: (rows, accuracy match record, surface seconds, robot seconds).

    ``bin_cfg``: the bin the scene was generated in (robot-level collision checks).
    """
    t0 = time.perf_counter()
    # Labels come from the ideal depth (the simulator's geometry): with a sensor model the
    # network sees noisy depth with holes but learns where the true surfaces are.
    depth = scene.depth_clean_m
    surfaces = detect_surfaces(depth, scene.mask, scene.intrinsics, surface_config(cfg))
    truth = true_visible_faces(depth, scene.mask, scene.intrinsics, scene.boxes,
                               cfg.surfaces.truth_min_visible_px)
    match = match_surfaces(surfaces, truth, cfg.surfaces.match_max_center_dist,
                           cfg.surfaces.match_max_normal_deg)
    t1 = time.perf_counter()
    rows = []
    if robot is not None and surfaces:
        robot.set_scene(scene, bin_cfg)
    H, W = scene.mask.shape
    for s in surfaces:
        hl = hand_label(s, cfg.hand)
        u, v = np.clip(np.round(s.center_px).astype(int), 0, [W - 1, H - 1])
        if hl.grasp_class != GraspClass.NG and scene.mask[v, u] != s.instance:
            # The centre of the visible region falls on another box (a box lying across this
            # face): a cup placed there would not touch this surface.
            hl = dataclasses.replace(hl, grasp_class=GraspClass.NG, reason="center_occluded")
        final, reason = hl.grasp_class, hl.reason or ""
        if robot is not None and final != GraspClass.NG:
            reason = robot.check(s, hl, cfg.hand) or ""
            if reason:
                final = GraspClass.NG
        rows.append((s, hl, final, reason))
    t2 = time.perf_counter()

    def arr(fn, dtype, shape=()):
        return np.asarray([fn(r) for r in rows], dtype=dtype).reshape((len(rows), *shape))

    out = {
        "instance": arr(lambda r: r[0].instance, np.int16),
        "uv": arr(lambda r: r[0].center_px, np.float32, (2,)),
        "center_cam": arr(lambda r: r[0].center_cam, np.float32, (3,)),
        "normal_cam": arr(lambda r: r[0].normal_cam, np.float32, (3,)),
        "long_axis_cam": arr(lambda r: r[0].long_axis_cam, np.float32, (3,)),
        "short_axis_cam": arr(lambda r: r[0].short_axis_cam, np.float32, (3,)),
        "lengths": arr(lambda r: (r[0].long_length, r[0].short_length), np.float32, (2,)),
        "area": arr(lambda r: r[0].area, np.float32),
        "x_axis_cam": arr(lambda r: r[1].x_axis_cam, np.float32, (3,)),
        "theta_deg": arr(lambda r: (r[1].theta1_deg, r[1].theta2_deg), np.float32, (2,)),
        "hand_class": arr(lambda r: int(r[1].grasp_class), np.int8),
        "grasp_class": arr(lambda r: int(r[2]), np.int8),
        "ng_reason": arr(lambda r: NG_REASONS.index(r[3]), np.int8),
        "num_points": arr(lambda r: r[0].num_points, np.int32),
    }
    return out, match, t1 - t0, t2 - t1
