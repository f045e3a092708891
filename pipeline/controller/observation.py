"""What the robot gets from its cell at one instant: the one type that crosses the fence.

A real cell's computer receives a depth image from its camera, knows the camera's intrinsics
from calibration, computes the camera's pose from its joint encoders and its own kinematic
model, and reads its joint state. :class:`Observation` holds exactly that. The simulated world
(``pipeline.world.cell.PickCell.observe``) fills one per camera frame; planners
(``pipeline.controller.planning``) and every decision of the robot side take nothing else, apart
from the static cell model (``pipeline.cell``, ``pipeline.robot``) and the configuration.

Frames: the world frame is z up, origin at the centre of the bin floor's top surface; the camera
frame is OpenCV's (x right, y down, z forward). Units: metres, radians.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.camera.geometry import Intrinsics


@dataclass(frozen=True)
class Observation:
    """One camera frame and the robot's state when it was taken.

    Attributes:
        depth_m: (H, W) float32 z-depth along the optical axis, metres, as the camera delivers
            it (ideal, or through the sensor model ``sensor=``); 0 = no data.
        intrinsics: the camera's pinhole intrinsics ((H, W) = the image's size).
        T_world_cam: (4, 4) camera pose in the world frame, from the joint state by the robot's
            forward kinematics.
        joints: (7,) joint angles, radians (xArm6 joints 1–6, then the hand tilt).
    """

    depth_m: np.ndarray
    intrinsics: Intrinsics
    T_world_cam: np.ndarray
    joints: np.ndarray

    def __post_init__(self) -> None:
        d = np.asarray(self.depth_m)
        if d.ndim != 2 or d.shape != (self.intrinsics.height, self.intrinsics.width):
            raise ValueError(
                f"Observation.depth_m has shape {d.shape}; the intrinsics are for "
                f"({self.intrinsics.height}, {self.intrinsics.width}) images: pass "
                "the depth image the intrinsics describe"
            )
        if np.asarray(self.T_world_cam).shape != (4, 4):
            raise ValueError(
                f"Observation.T_world_cam must be a (4, 4) pose, got shape "
                f"{np.asarray(self.T_world_cam).shape}"
            )
