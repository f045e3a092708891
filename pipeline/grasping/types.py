"""Data passed between surface detection, hand-level and robot-level labelling.

Frames: camera (OpenCV: x right, y down, z forward; metres); pixel (u, v).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import IntEnum

import numpy as np


class GraspClass(IntEnum):
    """The DCNN's four classes (paper Eq. 3). The order is the network's output order."""

    R = 0  # right cup on
    L = 1  # left cup on
    B = 2  # both cups on
    NG = 3  # not graspable


# Why a surface is NG: index into this tuple in the label rows' ``ng_reason`` ('' = graspable).
# The hand-level reasons (too_small, center_occluded) first, then the robot-level checks, then
# the hold check (``hand.hold_check``) and the final press's check (``press``), each appended
# so that the earlier codes keep their values.
NG_REASONS = (
    "",
    "too_small",
    "center_occluded",
    "ik",
    "joint_limits",
    "collision",
    "path_collision",
    "path_joint_limits",
    "path_timeout",
    "path_lost",
    "hold",
    "press",
)
# Display colour (RGB) of each class in logs and figures.
CLASS_COLORS = {
    GraspClass.R: (230, 60, 60),
    GraspClass.L: (60, 200, 60),
    GraspClass.B: (60, 120, 255),
    GraspClass.NG: (150, 150, 150),
}


@dataclass
class FaceFrame:
    """The frame of one visible planar face in the camera frame (OpenCV axes, metres).

    The fields the labelling stage's :class:`Surface` (from the instance mask) and the run-time
    descriptor's ``pipeline.servo.descriptor.SurfaceFeatures`` (from depth alone) share.

    Attributes:
        center_px: (2,) the centre projected to pixel coordinates (u, v): the grasp point g.
        center_cam: (3,) centre of the visible region of the face, in the face's plane, metres.
        normal_cam: (3,) unit normal, pointing towards the camera (``normal_cam @ center_cam < 0``).
        long_axis_cam: (3,) unit vector in the plane along the longer side of the visible region.
        short_axis_cam: (3,) unit vector in the plane along the shorter side
            (``short = normal × long``, a right-handed frame (long, short, normal)).
        long_length: L_l, length of the visible region along ``long_axis_cam``, metres.
        short_length: L_s, along ``short_axis_cam``, metres.
        area: visible area of the face in its plane, m² (the sum of the pixels' footprints).
    """

    center_px: np.ndarray
    center_cam: np.ndarray
    normal_cam: np.ndarray
    long_axis_cam: np.ndarray
    short_axis_cam: np.ndarray
    long_length: float
    short_length: float
    area: float


@dataclass
class Surface(FaceFrame):
    """One visible planar face of a box, as seen in one depth image (a :class:`FaceFrame`).

    Attributes:
        instance: the box's value in the scene's instance mask (1-based).
        num_points: inlier points of the plane fit.
        extra: per-surface facts added by later steps (free-form).
    """

    instance: int
    num_points: int
    extra: dict = field(default_factory=dict)
