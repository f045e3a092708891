"""The camera's target pose for a grasp (paper Sec. 4.3 "Robot-level labeling", Eqs. 17–18).

Frames: everything here is in one camera frame ``cam0`` (in practice the camera at the robot's
home pose), OpenCV axes (x right, y down, z forward), metres.

Cup convention (see ``pipeline.robot.urdf_builder``): the LEFT cup's centre is at target-camera
y = −``cup_offset``, the RIGHT cup's at y = +``cup_offset``, both with their axes along camera z.
"""

from __future__ import annotations

import numpy as np

from pipeline.camera.geometry import cross3

# Signed camera-y of the cup that must sit over the surface centre, per pattern, in units of
# cup_offset. B: the surface centre lies on the optical axis, between the cups.
_CUP_Y_SIGN = {"L": -1.0, "R": 1.0, "B": 0.0}


def _pattern_name(pattern) -> str:
    name = getattr(pattern, "name", pattern)  # accepts "L" or GraspClass.L
    if name not in _CUP_Y_SIGN:
        raise ValueError(
            f"grasp pattern must be one of L, R, B (got {pattern!r}); NG has no target pose"
        )
    return name


def target_camera_pose(
    center_cam: np.ndarray,
    normal_cam: np.ndarray,
    x_axis_cam: np.ndarray,
    pattern,
    standoff: float = 0.15,
    cup_offset: float = 0.035,
) -> np.ndarray:
    """``T_cam0_cam_target``: where the camera must be to grasp a surface with ``pattern``.

    Camera z is the anti-normal (looking straight at the surface), camera x is ``x_axis_cam``
    made orthogonal to the normal, camera y = z × x. The optical centre is ``standoff`` from the
    surface centre along the normal, then shifted along the target camera's y so that the active
    cup's centre line (parallel to camera z) passes through the surface centre:

    * "B": no shift — the surface centre is on the optical axis, between the cups;
    * "L": the left cup (camera y = −cup_offset) must be over the centre, so the optical centre
      moves by +cup_offset along the target y (the centre is then seen at y = −cup_offset,
      as in the paper's Eq. 17–18 with off = −0.035 for L);
    * "R": by −cup_offset.

    Args:
        center_cam: (3,) surface centre in ``cam0``, metres.
        normal_cam: (3,) surface normal in ``cam0``, pointing out of the surface towards the
            approaching camera (so ``normal_cam @ center_cam < 0`` for a surface ``cam0`` sees).
        x_axis_cam: (3,) in-plane direction the target camera's x should follow (the surface
            axis chosen by hand-level labelling); need not be unit or exactly in the plane.
        pattern: "L", "R" or "B" (or an enum member with that ``name``).
        standoff: d*, optical centre to surface along the normal, metres.
        cup_offset: cup centre to optical centre along camera y, metres.

    Returns:
        (4, 4) float64 pose of the target camera in ``cam0``.
    """
    sign = _CUP_Y_SIGN[_pattern_name(pattern)]
    c = np.asarray(center_cam, dtype=np.float64).reshape(3)
    n = np.asarray(normal_cam, dtype=np.float64).reshape(3)
    a = np.asarray(x_axis_cam, dtype=np.float64).reshape(3)
    n_norm = np.linalg.norm(n)
    if n_norm < 1e-9:
        raise ValueError("normal_cam has zero length")
    n = n / n_norm
    if n @ c > 0:
        raise ValueError(
            f"normal_cam {n} points away from the camera for a surface at {c}: "
            "pass the normal that faces the camera (normal @ center < 0)"
        )
    z = -n
    x = a - (a @ z) * z
    if np.linalg.norm(x) < 1e-6:
        raise ValueError("x_axis_cam is parallel to the normal; give an in-plane direction")
    x /= np.linalg.norm(x)
    y = np.array(cross3(z.tolist(), x.tolist()))  # np.cross(z, x)
    T = np.eye(4)
    T[:3, :3] = np.column_stack([x, y, z])
    T[:3, 3] = c + standoff * n - sign * cup_offset * y
    return T


def hand_rotations(pattern, rotations_deg) -> list[float]:
    """The hand rotations about the surface normal to try for ``pattern``, in order (degrees,
    0 = the paper's axis choice). Both cups on (B) allows only 0 and 180: a quarter turn would
    put the cup line across the axis the fit was checked along. One cup (L, R) allows any: the
    active cup stays on the surface centre, only the idle cup and the hand move."""
    name = _pattern_name(pattern)
    out = [float(r) % 360.0 for r in rotations_deg]
    if name == "B":
        out = [r for r in out if r in (0.0, 180.0)]
    return out or [0.0]


def rotate_about(axis: np.ndarray, normal: np.ndarray, degrees: float) -> np.ndarray:
    """``axis`` (3,) turned by ``degrees`` about the unit ``normal`` (right-handed, Rodrigues),
    after removing its component along the normal."""
    n = np.asarray(normal, np.float64) / np.linalg.norm(normal)
    a = np.asarray(axis, np.float64)
    a = a - (a @ n) * n
    t = np.radians(degrees)
    return np.cos(t) * a + np.sin(t) * np.array(cross3(n.tolist(), a.tolist()))  # n × a
