"""Pinhole geometry in the OpenCV convention.

Frames:
    pixel  (u, v): u to the right, v down; (0, 0) is the centre of the top-left pixel.
    camera (x, y, z): x right, y down, z forward along the optical axis; metres.
    world  (x, y, z): z up; origin at the centre of the bin floor's top surface; metres.

Poses are 4 × 4 homogeneous matrices ``T_a_b`` mapping points in frame b to frame a.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole intrinsics of a ``width`` × ``height`` image, in pixels."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float

    @classmethod
    def from_config(cls, cam) -> Intrinsics:
        return cls(
            int(cam.width),
            int(cam.height),
            float(cam.fx),
            float(cam.fy),
            float(cam.cx),
            float(cam.cy),
        )

    @property
    def K(self) -> np.ndarray:
        """3 × 3 camera matrix, float64."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def as_dict(self) -> dict[str, float]:
        return {
            "width": self.width,
            "height": self.height,
            "fx": self.fx,
            "fy": self.fy,
            "cx": self.cx,
            "cy": self.cy,
        }


def backproject(depth_m: np.ndarray, intr: Intrinsics) -> np.ndarray:
    """Depth image to a camera-frame point per pixel.

    Args:
        depth_m: (H, W) z-depth along the optical axis in metres (0 = no data).
        intr: camera intrinsics.

    Returns:
        (H, W, 3) float32 points in the camera frame, metres; pixels without data give (0, 0, 0).
    """
    if depth_m.shape != (intr.height, intr.width):
        raise ValueError(
            f"depth image has shape {depth_m.shape}, expected (H, W) = "
            f"({intr.height}, {intr.width}) from the camera intrinsics"
        )
    z = depth_m.astype(np.float32)
    u = np.arange(intr.width, dtype=np.float32)[None, :]
    v = np.arange(intr.height, dtype=np.float32)[:, None]
    x = (u - intr.cx) / intr.fx * z
    y = (v - intr.cy) / intr.fy * z
    return np.stack([x, y, z], axis=-1)


def backproject_pixels(uv: np.ndarray, z: np.ndarray, intr: Intrinsics) -> np.ndarray:
    """Pixels (..., 2) as (u, v) at z-depths (...) in metres to camera-frame points (..., 3),
    float64 metres: the inverse of ``project`` (``backproject`` does a whole image)."""
    uv = np.asarray(uv, dtype=np.float64)
    z = np.asarray(z, dtype=np.float64)
    return np.stack(
        [(uv[..., 0] - intr.cx) / intr.fx * z, (uv[..., 1] - intr.cy) / intr.fy * z, z], axis=-1
    )


def project(points_cam: np.ndarray, intr: Intrinsics) -> np.ndarray:
    """Camera-frame points (..., 3) in metres to pixel coordinates (..., 2) as (u, v)."""
    p = np.asarray(points_cam, dtype=np.float64)
    u = intr.fx * p[..., 0] / p[..., 2] + intr.cx
    v = intr.fy * p[..., 1] / p[..., 2] + intr.cy
    return np.stack([u, v], axis=-1)


def ground_distance(camera_cfg, bin_cfg) -> float:
    """D_ground (Eq. 9; the DCNN's and the GQ-CNN's input normalisation): the distance from
    the camera at the home pose to the ground plane, metres: its height above the bin floor
    (``camera.height_above_bin_floor``) plus the floor's thickness (``bin.floor_thickness``)."""
    return float(camera_cfg.height_above_bin_floor) + float(bin_cfg.floor_thickness)


def camera_pose_above_bin(height: float) -> np.ndarray:
    """``T_world_cam`` of a camera ``height`` metres above the world origin, looking down.

    Camera x is world +x, camera y is world −y (image down = towards −y), camera z is world −z.
    """
    T = np.eye(4)
    T[:3, :3] = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]])
    T[:3, 3] = [0.0, 0.0, height]
    return T


def world_to_camera(points_world: np.ndarray, T_world_cam: np.ndarray) -> np.ndarray:
    """World-frame points (..., 3) to the camera frame (..., 3)."""
    T_cam_world = np.linalg.inv(T_world_cam)
    p = np.asarray(points_world, dtype=np.float64)
    return p @ T_cam_world[:3, :3].T + T_cam_world[:3, 3]


def rotation_matrices(quats_xyzw: np.ndarray) -> np.ndarray:
    """(..., 4) unit quaternions (x, y, z, w) → (..., 3, 3) rotation matrices, float64."""
    q = np.asarray(quats_xyzw, dtype=np.float64)
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
            np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
            np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )


def pose_matrix(position: np.ndarray, quat_xyzw: np.ndarray) -> np.ndarray:
    """4 × 4 pose from a position (3,) and a unit quaternion (x, y, z, w).

    The rotation is :func:`rotation_matrices`' formula on Python floats (one pose is too small
    for numpy's per-call overhead to pay): the same products and sums in the same order, so the
    same bits."""
    x, y, z, w = np.asarray(quat_xyzw, dtype=np.float64).reshape(4).tolist()
    px, py, pz = np.asarray(position, dtype=np.float64).reshape(3).tolist()
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w), px],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w), py],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y), pz],
            [0.0, 0.0, 0.0, 1.0],
        ]
    )


def quat_from_matrix(R: np.ndarray) -> np.ndarray:
    """(3, 3) rotation matrix → unit quaternion (x, y, z, w), Shepperd's method.

    Divides by the largest of 4w², 4x², 4y², 4z², so it stays exact for half-turns (w = 0),
    where shortcuts that take the signs of x, y, z from the skew part lose them.
    """
    R = np.asarray(R, dtype=np.float64)
    t = R[0, 0] + R[1, 1] + R[2, 2]
    k = int(np.argmax([t, R[0, 0], R[1, 1], R[2, 2]]))
    if k == 0:
        s = 2.0 * np.sqrt(1.0 + t)
        q = [(R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s, s / 4]
    elif k == 1:
        s = 2.0 * np.sqrt(1.0 + R[0, 0] - R[1, 1] - R[2, 2])
        q = [s / 4, (R[0, 1] + R[1, 0]) / s, (R[0, 2] + R[2, 0]) / s, (R[2, 1] - R[1, 2]) / s]
    elif k == 2:
        s = 2.0 * np.sqrt(1.0 - R[0, 0] + R[1, 1] - R[2, 2])
        q = [(R[0, 1] + R[1, 0]) / s, s / 4, (R[1, 2] + R[2, 1]) / s, (R[0, 2] - R[2, 0]) / s]
    else:
        s = 2.0 * np.sqrt(1.0 - R[0, 0] - R[1, 1] + R[2, 2])
        q = [(R[0, 2] + R[2, 0]) / s, (R[1, 2] + R[2, 1]) / s, s / 4, (R[1, 0] - R[0, 1]) / s]
    q = np.asarray(q)
    return q / np.linalg.norm(q)


def quat_from_axes(x, y, z) -> np.ndarray:
    """Unit quaternion (x, y, z, w) of the frame with axes x, y, z (each (3,), in the parent
    frame): the nearest rotation (SVD), its third axis flipped if the axes are left-handed."""
    R = np.column_stack([x, y, z]).astype(np.float64)
    u, _, vt = np.linalg.svd(R)
    R = u @ vt
    if np.linalg.det(R) < 0:
        R[:, 2] *= -1
    return quat_from_matrix(R)


def gravity_in_camera(T_world_cam: np.ndarray) -> np.ndarray:
    """World gravity direction (0, 0, -1) in the camera frame of pose ``T_world_cam`` (4, 4):
    (3,) unit vector."""
    return np.asarray(T_world_cam, np.float64)[:3, :3].T @ np.array([0.0, 0.0, -1.0])


# Small vectors on Python floats. The servo's control law, its predicted motion and the robot's
# checks work on (3,) vectors and (3, 3) rotations thousands of times per scene, where numpy's
# per-call overhead outweighs the arithmetic. Each helper gives the float64 bits of the numpy
# expression it stands for (tests/test_small_vectors.py compares them on random vectors): the
# same products and sums in the same order, without fused multiply-adds; numpy's dot products
# (``a @ b``, ``np.linalg.norm``, ``R.T @ v``) add their terms in index order to a sum that
# starts at +0.0, which the helpers do too (an all −0 sum is +0 in both).


def cross3(a, b) -> tuple[float, float, float]:
    """``np.cross(a, b)`` of two 3-vectors of floats, as a tuple."""
    a0, a1, a2 = a
    b0, b1, b2 = b
    return (a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0)


def dot3(a, b) -> float:
    """``a @ b`` of two 3-vectors of floats (numpy's dot: terms in order, from +0.0)."""
    return 0.0 + a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def norm3(a) -> float:
    """``np.linalg.norm(a)`` of a 3-vector of floats: the square root of ``a @ a``."""
    return math.sqrt(0.0 + a[0] * a[0] + a[1] * a[1] + a[2] * a[2])


def rotate_back(R, v) -> tuple[float, float, float]:
    """``R.T @ v`` (3,) of a rotation ``R`` given as 3 rows of 3 floats (``R.tolist()``) and a
    3-vector of floats: the world-to-frame rotation of a pose's ``R_world_frame``."""
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = R
    v0, v1, v2 = v
    return (
        0.0 + r00 * v0 + r10 * v1 + r20 * v2,
        0.0 + r01 * v0 + r11 * v1 + r21 * v2,
        0.0 + r02 * v0 + r12 * v1 + r22 * v2,
    )
