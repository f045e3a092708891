"""One scene's grasp-point labels (paper Sec. 4.3): surfaces, hand level, robot level.

``label_scene`` is what the labelling stage runs per scene and what the oracle planner runs on
the closed loop's home image; its rows are ``pipeline.dataset.labels.LABEL_FIELDS``.

Hold check (``hand.hold_check``, not in the paper): a B, L or R whose cups fit on the face is
NG ("hold") when the closed loop's hold test (``pipeline.grasping.suction.hold_test``: pull,
shear, torsion, bending) says the cups would not carry the box's weight. The cups sit where the
pattern puts them (L, R: one cup on the surface centre; B: the centre ± ``cup_offset`` along the
hand's Y), the approach axis is the anti-normal, the box's mass is density × volume and its
centre of mass its centre (the simulator's boxes are uniform), and gravity is the world's −z
seen in the camera frame. The paper's rule (Fig. 6e) only checks that one cup fits, so a
medium box on a tilted face, whose centre of mass lies far to the side of the one cup, is
labelled L or R and dropped.
"""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np

from pipeline.config.build import from_section
from pipeline.dataset.scenes import Box, Scene
from pipeline.grasping.hand import HandLabel, camera_centre, hand_label
from pipeline.grasping.suction import SuctionModelConfig, box_mass, suction_model_config
from pipeline.grasping.surfaces import SurfaceDetectionConfig, detect_surfaces
from pipeline.grasping.types import NG_REASONS, GraspClass, Surface
from pipeline.labelling.surface_truth import match_surfaces, true_visible_faces


def surface_config(cfg) -> SurfaceDetectionConfig:
    """The surface detection settings of a composed config's ``surfaces`` group."""
    return from_section(SurfaceDetectionConfig, cfg.surfaces)


def pattern_holds(
    surface: Surface,
    hl: HandLabel,
    box: Box,
    T_world_cam: np.ndarray,
    suction: SuctionModelConfig,
    cup_offset: float,
    landing_tolerance: float = 0.0,
) -> bool:
    """Whether ``hl``'s pattern, its cups placed on ``surface`` as the pattern puts them, holds
    ``box``'s weight by ``pipeline.grasping.suction.hold_test`` (module docstring). With
    ``landing_tolerance`` > 0 (``hand.hold_landing_tolerance``, m) it must also hold with all its
    cups shifted together by that distance in each of 8 directions in the surface's plane: ± the
    hand's X, ± its Y, and the four diagonals (:func:`landing_shifts`).

    Frames: ``surface`` and ``box.T_cam_box`` in the camera frame, ``T_world_cam`` the camera's
    pose in the world (z up); metres. ``suction``: cup radius, vacuum force, friction, gravity
    (m/s²) and the boxes' density (kg/m³), which gives the mass of a box without its own
    ``mass`` (kg).
    """
    from pipeline.grasping.suction import hold_test

    n = np.asarray(surface.normal_cam, np.float64)
    c = np.asarray(surface.center_cam, np.float64)
    x = np.asarray(hl.x_axis_cam, np.float64)
    y = np.cross(-n, x)  # hand y = z × x, z = −n
    y /= np.linalg.norm(y)
    if hl.grasp_class == GraspClass.B:
        points = np.stack([c - cup_offset * y, c + cup_offset * y])
    else:
        points = c[None]
    gravity_cam = T_world_cam[:3, :3].T @ np.array([0.0, 0.0, -suction.gravity])
    mass = box_mass(box, suction.density)
    return all(
        hold_test(
            mass, box.T_cam_box[:3, 3], points + shift, -n, gravity_cam, suction, cup_offset
        ).ok
        for shift in landing_shifts(x, y, landing_tolerance)
    )


def landing_shifts(x: np.ndarray, y: np.ndarray, tolerance: float) -> np.ndarray:
    """(k, 3): the cups' shifts the hold check tries: none first, then with ``tolerance`` > 0
    the 8 shifts of length ``tolerance`` along ±``x``, ±``y`` and the diagonals (unit vectors
    in the surface's plane, camera frame; metres)."""
    shifts = [np.zeros(3)]
    if tolerance > 0:
        for a in range(8):
            t = math.radians(45.0 * a)
            shifts.append(tolerance * (math.cos(t) * x + math.sin(t) * y))
    return np.asarray(shifts)


def single_cup_order(surface: Surface, hl: HandLabel, hand_cfg) -> tuple[GraspClass, ...]:
    """The single-cup patterns a hand-level B falls back on, in the hand-level rule's order
    (``pipeline.grasping.hand``, step 4: the pattern whose camera centre is higher first, L
    within ``tie_tolerance``); () for a class other than B."""
    if hl.grasp_class != GraspClass.B:
        return ()
    z_l, z_r = (
        camera_centre(surface, hl.x_axis_cam, c, hand_cfg)[2] for c in (GraspClass.L, GraspClass.R)
    )
    if z_r < z_l - hand_cfg.tie_tolerance:
        return GraspClass.R, GraspClass.L
    return GraspClass.L, GraspClass.R


def robot_level_class(hl: HandLabel, check, holds, fallback=()) -> tuple[GraspClass, str]:
    """(the robot-level class, the NG reason or ""): ``hl``'s class when ``check(hl)`` (the
    robot-level check: None or an NG reason) passes; else the first of ``fallback`` (single-cup
    classes, ``single_cup_order``) whose label ``holds`` the box (``holds(label)``) and passes
    ``check``; else NG with the first check's reason."""
    first = check(hl)
    if not first:
        return hl.grasp_class, ""
    for cls in fallback:
        one = dataclasses.replace(hl, grasp_class=cls)
        if holds(one) and not check(one):
            return cls, ""
    return GraspClass.NG, first


def label_scene(
    scene: Scene, cfg, robot=None, bin_cfg=None, density: float | None = None
) -> tuple[dict[str, np.ndarray], dict, float, float]:
    """Grasp points of one scene: (rows, accuracy match record, surface seconds, robot seconds).

    ``bin_cfg``: the bin the scene was generated in (robot-level collision checks).
    ``density``: the boxes' density, kg/m³, for the hold check (``boxes.density`` for generated
    heaps, ``eval_boxes.density`` in the closed loop); needed when ``hand.hold_check`` is on.
    """
    suction = None
    if cfg.hand.hold_check:
        if density is None:
            raise ValueError(
                "label_scene: hand.hold_check is on but no box density was given; "
                "pass density= (boxes.density for generated heaps, "
                "eval_boxes.density in the closed loop) or set "
                "hand.hold_check=false"
            )
        suction = suction_model_config(cfg, density)
    t0 = time.perf_counter()
    # Labels come from the ideal depth (the simulator's geometry): with a sensor model the
    # network sees noisy depth with holes but learns where the true surfaces are.
    depth = scene.depth_clean_m
    surfaces = detect_surfaces(depth, scene.mask, scene.intrinsics, surface_config(cfg))
    truth = true_visible_faces(
        depth, scene.mask, scene.intrinsics, scene.boxes, cfg.surfaces.truth_min_visible_px
    )
    match = match_surfaces(
        surfaces, truth, cfg.surfaces.match_max_center_dist, cfg.surfaces.match_max_normal_deg
    )
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
        if (
            suction is not None
            and hl.grasp_class != GraspClass.NG
            and not pattern_holds(
                s,
                hl,
                scene.boxes[s.instance - 1],
                scene.T_world_cam,
                suction,
                float(cfg.hand.cup_offset),
                float(cfg.hand.hold_landing_tolerance),
            )
        ):
            hl = dataclasses.replace(hl, grasp_class=GraspClass.NG, reason="hold")
        final, reason = hl.grasp_class, hl.reason or ""
        if robot is not None and final != GraspClass.NG:
            box = scene.boxes[s.instance - 1]
            final, reason = robot_level_class(
                hl,
                lambda h, s=s: robot.check(s, h, cfg.hand),
                lambda h, s=s, box=box: (
                    suction is None
                    or pattern_holds(
                        s,
                        h,
                        box,
                        scene.T_world_cam,
                        suction,
                        float(cfg.hand.cup_offset),
                        float(cfg.hand.hold_landing_tolerance),
                    )
                ),
                single_cup_order(s, hl, cfg.hand) if bool(cfg.label.single_cup_fallback) else (),
            )
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
