"""Camera poses that look at a heap the way the closed loop's hand camera does.

World frame: z up, origin at the centre of the bin floor's top surface; metres. Camera poses are
``T_world_cam`` with OpenCV axes (x right, y down, z forward).
"""

from __future__ import annotations

import numpy as np

from pipeline.camera.geometry import pose_matrix
from pipeline.simulation.heap import BoxPose


def closeup_poses(
    boxes: list[BoxPose], rng: np.random.Generator, distances: tuple[float, ...] = (0.15, 0.3)
) -> list[np.ndarray]:
    """One pose per distance: the camera on the normal of a box face, looking straight at it.

    For each distance a box is drawn uniformly from ``boxes``; its face whose outward normal is
    nearest world +z is the target, and the camera sits ``distance`` metres from that face's
    centre along the normal (0.15 m is the servo's d*, paper Sec. 5.2), rotated about the
    normal by a uniform angle: the final poses of the 2.5D visual servoing, tilted as the faces
    are. Draws per distance: the box index, then the angle.
    """
    poses = []
    for d in distances:
        box = boxes[int(rng.integers(len(boxes)))]
        R = pose_matrix(box.position, box.quat_xyzw)[:3, :3]
        axis = int(np.argmax(np.abs(R[2])))
        n = R[:, axis] * np.sign(R[2, axis])  # the face normal nearest world +z
        centre = np.asarray(box.position) + n * box.size[axis] / 2.0
        z = -n
        a = R[:, (axis + 1) % 3]  # an in-plane axis of the face, turned by a random angle
        b = np.cross(z, a)
        phi = rng.uniform(0.0, 2.0 * np.pi)
        x = np.cos(phi) * a + np.sin(phi) * b
        T = np.eye(4)
        T[:3, :3] = np.column_stack([x, np.cross(z, x), z])
        T[:3, 3] = centre + d * n
        poses.append(T)
    return poses
