"""Hand-level grasp-pattern labelling (paper Sec. 4.3, Figs. 5 and 6).

For one visible surface, decide how a two-cup suction hand would take it, from the surface
alone (no robot, no neighbours):

1. Warped perspective (Fig. 6b): the minimal rotation ``R0`` that turns the camera's Z axis onto
   the surface's anti-normal ``−n`` makes the surface face the camera; the surface axes seen in
   that view are ``ñ_l = R0ᵀ n_l`` and ``ñ_s = R0ᵀ n_s``.
2. Rotation pattern (Fig. 6c): θ1 = ∠(ñ_l, X), θ2 = ∠(ñ_s, X), each folded into [0°, 90°]
   because an axis has no sign. The hand's X is aligned with the axis of the smaller angle (the
   smaller rotation); the other axis then runs along the hand's Y, the line of the two cups.
3. Both cups (Fig. 6d): the cups are discs of radius r = d_cup/2 at ±0.035 m along the hand's Y
   from the surface centre. ``B`` if both discs, grown by ``margin``, lie inside the visible
   rectangle (L_l × L_s, centred on the surface centre) and the area is at least
   ``min_area_ratio`` × the two cups' area.
4. One cup (Fig. 6e): with L or R, the chosen cup sits on the surface centre and the camera is
   offset by 0.035 m along Y. One cup fits if its disc grown by ``margin`` lies inside the
   rectangle and the area is at least ``min_area_ratio`` × one cup's area. Between L and R the
   pattern whose camera centre O_cam is higher (closer to the home camera along its Z, i.e.
   smaller z in the home camera frame) is safer and chosen; within ``tie_tolerance`` the surface
   is level across the hand and L is chosen.
5. Otherwise ``NG``.

Note on the paper's wording: Fig. 6d checks "the length of the aligned axis"; with the cups on
the hand's Y axis (Fig. 1b; Eq. 17 offsets along Y), the physically relevant length is the one
along Y, i.e. the surface axis *not* aligned with X. We implement the geometric test above,
which is exact for either reading of the figure.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.config.physical import HandConfig
from pipeline.grasping.types import GraspClass, Surface
from pipeline.robot.target_pose import target_camera_pose


@dataclass
class HandLabel:
    """The hand-level decision for one surface.

    Attributes:
        grasp_class: B, L, R or NG.
        x_axis_cam: (3,) unit vector in the surface plane that the hand's X is aligned with
            (camera frame, signed so that the rotation from the home pose is smallest).
        theta1_deg, theta2_deg: ∠(ñ_l, X) and ∠(ñ_s, X) in the warped view, degrees.
        aligned: "long" or "short", the surface axis aligned with the hand's X.
        reason: why NG (``"too_small"``), else None.
    """

    grasp_class: GraspClass
    x_axis_cam: np.ndarray
    theta1_deg: float
    theta2_deg: float
    aligned: str
    reason: str | None = None


def rotation_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The minimal rotation matrix R with R a = b for unit vectors a, b."""
    a = a / np.linalg.norm(a)
    b = b / np.linalg.norm(b)
    v = np.cross(a, b)
    c = float(a @ b)
    if c < -1 + 1e-12:  # opposite: rotate 180° about any axis orthogonal to a
        axis = np.cross(a, [1.0, 0.0, 0.0])
        if np.linalg.norm(axis) < 1e-6:
            axis = np.cross(a, [0.0, 1.0, 0.0])
        axis /= np.linalg.norm(axis)
        return 2 * np.outer(axis, axis) - np.eye(3)
    vx = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + vx + vx @ vx / (1 + c)


def warped_axes(surface: Surface) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(R0, ñ_l, ñ_s): the warped-perspective rotation and the surface axes seen through it."""
    R0 = rotation_between(np.array([0.0, 0.0, 1.0]), -surface.normal_cam)
    return R0, R0.T @ surface.long_axis_cam, R0.T @ surface.short_axis_cam


def _axis_angle_to_x(axis: np.ndarray) -> float:
    """Angle in degrees between an (unsigned) in-plane axis and X, folded into [0, 90]."""
    xy = axis[:2] / max(np.linalg.norm(axis[:2]), 1e-12)
    return float(np.degrees(np.arccos(min(1.0, abs(xy[0])))))


def cup_fits(half_x: float, half_y: float, cup_y: float, cfg: HandConfig) -> bool:
    """Whether a cup disc centred at (0, cup_y) in the hand-aligned surface frame, grown by the
    margin, lies inside the rectangle |x| ≤ half_x, |y| ≤ half_y."""
    r = cfg.cup_diameter / 2 + cfg.margin
    return r <= half_x and abs(cup_y) + r <= half_y


def hand_label(surface: Surface, cfg: HandConfig) -> HandLabel:
    """Label one surface B, L, R or NG by the rules in the module docstring."""
    R0, n_l, n_s = warped_axes(surface)
    theta1, theta2 = _axis_angle_to_x(n_l), _axis_angle_to_x(n_s)
    if theta1 <= theta2:
        aligned, axis_w, axis_cam = "long", n_l, surface.long_axis_cam
        half_x, half_y = surface.long_length / 2, surface.short_length / 2
    else:
        aligned, axis_w, axis_cam = "short", n_s, surface.short_axis_cam
        half_x, half_y = surface.short_length / 2, surface.long_length / 2
    sign = 1.0 if axis_w[0] >= 0 else -1.0  # the smaller of the two rotations onto X
    x_axis = sign * axis_cam
    cup_area = np.pi * (cfg.cup_diameter / 2) ** 2

    def label(cls, reason=None):
        return HandLabel(cls, x_axis, theta1, theta2, aligned, reason)

    if (
        cup_fits(half_x, half_y, cfg.cup_offset, cfg)
        and surface.area >= cfg.min_area_ratio * 2 * cup_area
    ):
        return label(GraspClass.B)
    if not (cup_fits(half_x, half_y, 0.0, cfg) and surface.area >= cfg.min_area_ratio * cup_area):
        return label(GraspClass.NG, "too_small")
    z_l, z_r = (camera_centre(surface, x_axis, p, cfg)[2] for p in (GraspClass.L, GraspClass.R))
    if z_r < z_l - cfg.tie_tolerance:
        return label(GraspClass.R)
    return label(GraspClass.L)


def camera_centre(
    surface: Surface, x_axis_cam: np.ndarray, pattern: GraspClass, cfg: HandConfig
) -> np.ndarray:
    """O_cam of the pattern's target pose, in the current camera frame (paper Sec. 4.3):
    ``standoff`` along the normal from the centre, shifted so that the pattern's cup is over
    the centre (``pipeline.robot.target_camera_pose``)."""
    T = target_camera_pose(
        surface.center_cam,
        surface.normal_cam,
        x_axis_cam,
        pattern,
        standoff=cfg.standoff,
        cup_offset=cfg.cup_offset,
    )
    return T[:3, 3]
