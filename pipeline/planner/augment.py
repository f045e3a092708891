"""Mirror augmentation of a depth image and its grasp-point labels.

A mirrored depth image is the image of the mirrored heap, so its labels are the labelling
rules applied to the mirrored surfaces. Mirroring changes only the L/R choice
(``pipeline.grasping.hand``): B and NG are decided by surface sizes, which a mirror keeps.

Which flips swap L and R. The hand's X is aligned with a surface axis rotated the *smaller* way
onto camera X, its Y (the line of the two cups) is Z × X, and L/R is chosen by comparing the
heights (camera z) of the two target camera centres, z_{L,R} = z_0 ± cup_offset · y_z, i.e. by
the sign of y_z, the z component of the hand's Y axis (R when z_R < z_L − tie_tolerance).

* Horizontal flip (u → W − 1 − u, camera x → −x, M = diag(−1, 1, 1)): the smaller rotation onto
  X flips its sense, so the new X is −M x; Z' = M z; Y' = Z' × X' = M y (det M = −1 twice).
  y_z is unchanged: **a horizontal flip keeps L and R.** (The cups lie along the hand's Y, which
  the hand turns to stay close to camera Y; mirroring X does not exchange them.)
* Vertical flip (v → H − 1 − v, y → −y, M = diag(1, −1, 1)): the rotation onto X also flips its
  sense but X' = M x (its x component is kept), Y' = Z' × X' = −M y, so y_z changes sign:
  **a vertical flip swaps L and R**, except for a tie (|z_L − z_R| < tie_tolerance, labelled L),
  which stays a tie and so stays L.

Rather than hard-code the swap, ``flip_rows`` mirrors the stored geometry (``center_cam``,
``normal_cam``, ``x_axis_cam``) and re-applies the height rule to every L/R row, so both flips
and ties come out of the same code as the labelling stage (``hand.camera_centre``'s
``target_camera_pose``).

Caveat: the robot-level check (IK, joint limits, collisions) is not mirror-symmetric (the robot
stands on one side of the bin). A flipped image keeps each point's graspable/NG decision, which
is exact for the hand level and an approximation for the robot level. It is on by default
(``train.augment_flip: uv``) because it lowers the validation loss, which is measured on
unflipped images with the true robot-level labels (docs/training.md).

Mirroring a pixel about the image centre is the camera mirror only if the principal point is
the image centre (cx = (W − 1)/2, cy = (H − 1)/2); ``flip_rows`` checks it.
"""

from __future__ import annotations

import numpy as np

from pipeline.camera.geometry import Intrinsics
from pipeline.grasping.types import GraspClass
from pipeline.robot.target_pose import target_camera_pose

FLIPS = ("none", "u", "v", "uv")
_AXIS = {"u": 0, "v": 1}  # pixel axis u ↔ camera x, v ↔ camera y


def lr_choice(
    center_cam: np.ndarray,
    normal_cam: np.ndarray,
    x_axis_cam: np.ndarray,
    standoff: float,
    cup_offset: float,
    tie_tolerance: float,
) -> GraspClass:
    """The hand-level rule between L and R (``hand.hand_label`` step 4): R when its camera
    centre is higher (smaller z) by more than ``tie_tolerance``, else L (ties go to L)."""
    z_l, z_r = (
        target_camera_pose(
            center_cam, normal_cam, x_axis_cam, p, standoff=standoff, cup_offset=cup_offset
        )[2, 3]
        for p in ("L", "R")
    )
    return GraspClass.R if z_r < z_l - tie_tolerance else GraspClass.L


def _mirror_x_axis(x_axis: np.ndarray, normal: np.ndarray, axis: int) -> np.ndarray:
    """The hand X the labelling rule picks for the mirrored surface: the mirrored axis, signed
    like ``hand.hand_label`` does (the warped view's x component ≥ 0)."""
    from pipeline.grasping.hand import rotation_between

    m = np.ones(3)
    m[axis] = -1.0
    a, n = x_axis * m, normal * m
    R0 = rotation_between(np.array([0.0, 0.0, 1.0]), -n)
    return a if (R0.T @ a)[0] >= 0 else -a


def flip_rows(
    rows: dict[str, np.ndarray], flip: str, intrinsics: Intrinsics, hand
) -> dict[str, np.ndarray]:
    """One image's label rows mirrored by ``flip`` ("u", "v", "uv" or "none").

    Args:
        rows: ``LabelSet`` rows; reads ``uv`` (P, 2) px, ``center_cam``, ``normal_cam``,
            ``x_axis_cam`` (P, 3) camera frame, ``grasp_class`` (P,).
        intrinsics: the image's; its principal point must be the image centre.
        hand: ``HandConfig`` (standoff, cup_offset, tie_tolerance) used for the labels.

    Returns:
        a new dict with those keys transformed (other keys copied); ``grasp_class`` L/R re-decided
        by ``lr_choice`` on the mirrored geometry.
    """
    if flip not in FLIPS:
        raise ValueError(f"unknown flip {flip!r}; choose one of {FLIPS}")
    out = {k: np.array(v, copy=True) for k, v in rows.items()}
    if flip == "none":
        return out
    size = (intrinsics.width, intrinsics.height)
    principal = (intrinsics.cx, intrinsics.cy)
    for name in flip:
        axis = _AXIS[name]
        if abs(principal[axis] - (size[axis] - 1) / 2) > 1e-6:
            raise ValueError(
                f"a {name}-flip mirrors the camera only when the principal point is "
                f"the image centre; got c = {principal[axis]} for size {size[axis]}"
            )
        out["uv"][:, axis] = (size[axis] - 1) - out["uv"][:, axis]
        for i in range(len(out["uv"])):
            out["x_axis_cam"][i] = _mirror_x_axis(
                out["x_axis_cam"][i].astype(np.float64),
                out["normal_cam"][i].astype(np.float64),
                axis,
            )
        out["center_cam"][:, axis] *= -1
        out["normal_cam"][:, axis] *= -1
    cls = out["grasp_class"]
    for i in np.nonzero((cls == GraspClass.L) | (cls == GraspClass.R))[0]:
        cls[i] = lr_choice(
            out["center_cam"][i].astype(np.float64),
            out["normal_cam"][i].astype(np.float64),
            out["x_axis_cam"][i].astype(np.float64),
            hand.standoff,
            hand.cup_offset,
            hand.tie_tolerance,
        )
    return out


def flip_image(image: np.ndarray, flip: str) -> np.ndarray:
    """Mirror an (..., H, W) image: "u" reverses W, "v" reverses H."""
    if flip not in FLIPS:
        raise ValueError(f"unknown flip {flip!r}; choose one of {FLIPS}")
    if "u" in flip:
        image = image[..., ::-1]
    if "v" in flip:
        image = image[..., ::-1, :]
    return np.ascontiguousarray(image)
