"""How the robot approaches a grasp pose: the servo's first goal before the grasp pose.

The closed loop servos from home to a first goal, then on to the grasp pose (the camera at d*
from the surface, ``target_pose.target_camera_pose``); the labelling stage and the run-time
check follow the same servo (``pipeline.servo.predict``, ``pipeline.robot.path``).
``motion.approach`` chooses the first goal (docs/closed_loop.md):

* ``lift``: the grasp pose raised straight up (world z) by ``lift_height``;
* ``pregrasp``: a point on the surface normal, ``pregrasp_standoff`` from the surface;
* ``direct``: none (the paper: straight to d*).

Frames: ``cam0`` is the camera that saw the surface (the home camera), OpenCV axes; ``T_world_cam``
is its pose in the world (z up). Metres.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from pipeline.robot.target_pose import target_camera_pose
from pipeline.robot.urdf_builder import CUP_TIP_Z

APPROACHES = ("lift", "pregrasp", "direct")


def check_approach(name: str) -> str:
    """``name`` if it is a known approach, else a ValueError naming the choices."""
    if name not in APPROACHES:
        raise ValueError(f"motion.approach must be one of {', '.join(APPROACHES)} (got {name!r})")
    return name


def lift_height(
    T_cam0_goal: np.ndarray,
    centre_cam: np.ndarray,
    up_cam: np.ndarray,
    limit_x: float,
    limit_y: float,
    max_lift: float,
    step: float = 0.01,
) -> tuple[float, np.ndarray | None]:
    """The "lift" approach's first goal: the grasp pose ``T_cam0_goal`` (4, 4, in cam0) raised
    by the largest of ``max_lift`` down to 0 (``step`` decrements) at which the surface centre,
    seen from the raised camera, stays within ``|x/z| <= limit_x`` and ``|y/z| <= limit_y`` (a
    steep face slides sideways in the view as the camera rises; a centre pushed out of the
    image is a lost target).

    Args:
        T_cam0_goal: (4, 4) grasp camera pose in cam0.
        centre_cam: (3,) surface centre in cam0, metres.
        up_cam: (3,) unit world up (+z) expressed in cam0.
        limit_x, limit_y: tangent limits of the allowed part of the image.
        max_lift: metres.

    Returns:
        (lift h in metres, the centre's position (3,) in the raised camera's frame), or
        (0.0, None) when no lift keeps the centre in view.
    """
    R = T_cam0_goal[:3, :3]
    for h in np.arange(max_lift, 0.0, -step):
        point = R.T @ (centre_cam - (T_cam0_goal[:3, 3] + h * up_cam))
        if (
            point[2] > 0
            and abs(point[0] / point[2]) <= limit_x
            and abs(point[1] / point[2]) <= limit_y
        ):
            return float(h), point
    return 0.0, None


def pregrasp_standoff(
    T_world_cam: np.ndarray,
    centre_cam: np.ndarray,
    normal_cam: np.ndarray,
    x_axis_cam: np.ndarray,
    pattern: str,
    standoff: float,
    cup_offset: float,
    max_standoff: float,
    half_x: float,
    half_y: float,
) -> float:
    """The "pregrasp" approach's distance from the surface along its normal: the largest of
    ``max_standoff`` down to ``standoff`` (d*) in 1 cm steps at which the camera and both cup
    lips lie within ``|x| <= half_x``, ``|y| <= half_y`` in the world (the walls' vertical
    planes less a margin), so the descent along the normal cannot sweep a wall; d* when none
    does (the direct approach)."""
    points = np.array(
        [[0, 0, 0], [0, -cup_offset, CUP_TIP_Z], [0, cup_offset, CUP_TIP_Z]], np.float64
    )
    for d in np.arange(max_standoff, standoff, -0.01):
        try:
            T = T_world_cam @ target_camera_pose(
                centre_cam,
                normal_cam,
                x_axis_cam,
                pattern,
                standoff=float(d),
                cup_offset=cup_offset,
            )
        except ValueError:
            return standoff
        w = points @ T[:3, :3].T + T[:3, 3]
        if (np.abs(w[:, 0]) <= half_x).all() and (np.abs(w[:, 1]) <= half_y).all():
            return float(d)
    return standoff


def first_goal(
    servo_cfg,
    cfg,
    T_world_cam: np.ndarray,
    centre_cam: np.ndarray,
    normal_cam: np.ndarray,
    x_axis_cam: np.ndarray,
    pattern: str,
    intrinsics,
):
    """(the servo configuration of the approach's first goal, its distance from the surface)
    for ``cfg.motion.approach``, given the servo's own configuration ``servo_cfg``
    (``pipeline.servo.control.servo_config``) and a surface seen from the home camera
    ``T_world_cam`` (centre, normal towards the camera, the hand's X; cam0 frame, metres):

    * lift: the grasp pose raised straight up (world z) by :func:`lift_height`, orientation
      unchanged; the goal is the centre's desired position in the raised camera
      (``ServoConfig.target_point``). From there the servo descends (nearly) vertically;
    * pregrasp: d* replaced by :func:`pregrasp_standoff` along the normal;
    * direct, or a lift or pre-grasp that shrank to nothing: ``servo_cfg`` itself (d*).

    A first goal other than ``servo_cfg`` is a via point: its tolerances are
    ``motion.via_tolerance_scale`` times ``servo_cfg``'s.
    """
    hand, m, b = cfg.hand, cfg.motion, cfg.bin
    d_star, off = float(hand.standoff), float(hand.cup_offset)
    approach = check_approach(str(m.approach))
    if approach == "pregrasp":
        margin = float(m.pregrasp_wall_margin)
        d = pregrasp_standoff(
            T_world_cam,
            centre_cam,
            normal_cam,
            x_axis_cam,
            pattern,
            d_star,
            off,
            float(m.pregrasp_standoff),
            float(b.inner_length_x) / 2 - margin,
            float(b.inner_width_y) / 2 - margin,
        )
        if d <= d_star:
            return servo_cfg, d_star
        return _via(dataclasses.replace(servo_cfg, standoff=d), m), d
    if approach == "lift":
        T = target_camera_pose(
            centre_cam, normal_cam, x_axis_cam, pattern, standoff=d_star, cup_offset=off
        )
        up_cam = T_world_cam[:3, :3].T @ np.array([0.0, 0.0, 1.0])
        h, point = lift_height(
            T,
            np.asarray(centre_cam, np.float64),
            up_cam,
            *image_limits(intrinsics, float(m.pregrasp_image_fraction)),
            float(m.pregrasp_standoff) - d_star,
        )
        if point is not None:
            return _via(
                dataclasses.replace(servo_cfg, target_point=tuple(float(x) for x in point)), m
            ), d_star + h
    return servo_cfg, d_star


def _via(goal, motion_cfg):
    """``goal`` as a via point: its tolerances times ``motion.via_tolerance_scale``."""
    k = float(motion_cfg.via_tolerance_scale)
    if k < 1:
        raise ValueError(
            f"motion.via_tolerance_scale must be >= 1 (a via point is no tighter "
            f"than the goal), got {k}"
        )
    return dataclasses.replace(
        goal,
        tolerance_xy=goal.tolerance_xy * k,
        tolerance_log_z=goal.tolerance_log_z * k,
        tolerance_rot_deg=goal.tolerance_rot_deg * k,
    )


def image_limits(intrinsics, fraction: float) -> tuple[float, float]:
    """Tangent limits (x/z, y/z) of the central ``fraction`` of the half field of view."""
    return (fraction * intrinsics.cx / intrinsics.fx, fraction * intrinsics.cy / intrinsics.fy)
