"""The depth camera: intrinsics, poses, rendering in pybullet, back-projection."""

from pipeline.camera.geometry import (  # noqa: F401
    Intrinsics,
    backproject,
    camera_pose_above_bin,
    project,
    world_to_camera,
)
