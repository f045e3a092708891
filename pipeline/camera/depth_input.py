"""Validation of depth images at the entry points (planners, descriptor).

    depth_m = check_depth_image(depth_m, (intrinsics.height, intrinsics.width))

Every entry point that takes a depth image (``pipeline.planner.Planner.plan``/``predict``,
``pipeline.dexnet.planner.DexNetPlanner.plan``/``run_cem``,
``pipeline.servo.descriptor.describe_surface``) calls :func:`check_depth_image` first, before
any numpy/torch/OpenCV/scikit-learn work, so that a bad image fails here with a message that
names the problem and the fix, or is turned into the project's one representation of depth:

* an (H, W) (or, where a batch is allowed, (..., H, W)) **float32 z-depth in metres**,
* **0.0 = no data** at a pixel (the convention of the renderer, the sensor model, the labels
  and the network's input normalisation).

**Errors** (:class:`DepthImageError`, a ``ValueError``), raised for what cannot be repaired
without guessing:

* not array-like (``None``, a ragged nested list, a string, ...);
* the wrong number of dimensions (1-D, 3-D such as an (H, W, 1) or RGB-D stack, 0-D), or the
  wrong shape (the expected one comes from the intrinsics or the network's input size; an
  empty 0 × 0 image is a wrong shape);
* a dtype that is not a real floating-point type: integers (``uint16`` is how sensors and the
  generation artifact store depth: convert with ``depth_m = raw * depth_unit``; an integer
  image is never silently taken as metres, since millimetres read as metres would put every
  surface 1000× too far), ``bool`` (a mask, not depth), complex, object, strings, datetimes.

**Sanitising** (never an error): a pixel whose value is not a plausible depth becomes 0.0 =
no data. Plausible = finite and within [``MIN_DEPTH_M``, ``MAX_DEPTH_M``] = [0.05, 10] m:

* NaN and ±inf: sensors (and librealsense/ROS drivers) report missing data as 0 or NaN, and
  inf appears after a division by a zero disparity;
* 0 and negative values: a point in front of the camera has z > 0, so z ≤ 0 is physically
  impossible and can only mean "no measurement" (0 is the usual code) or corrupt data;
* z < 5 cm or z > 10 m: outside what any depth camera for bin picking measures (the SR300's
  range is about 0.2–1.5 m; the simulated camera's near/far planes are 0.1/2 m, so no
  rendered depth is affected). Such values are corrupt, and they would break the maths
  downstream: the network's input normalisation overflows float32 for huge depths, and the
  Dex-Net disc-planarity window grows as 1/depth (a few pixels at 0.5 m, thousands at 1 mm,
  i.e. gigabytes of memory).

The caller's array is never modified (a float32 copy is returned). Whether an image with no
valid pixel at all is an error is the caller's decision: the planners return "no grasp" and
the descriptor ``(None, "no_depth_at_seed")`` for it.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

MIN_DEPTH_M = 0.05
MAX_DEPTH_M = 10.0

CONVERT_HINT = (
    "convert a raw sensor image with its depth unit first: "
    "depth_m = raw.astype(np.float32) * depth_unit (e.g. depth_unit = 0.001 for "
    "millimetres; the generation artifact stores it as depth_unit)"
)


class DepthImageError(ValueError):
    """A depth image that cannot be used as it is (shape, dtype, not an array)."""


def check_depth_image(
    depth,
    expected_shape: Sequence[int] | None = None,
    *,
    name: str = "depth",
    allow_batch: bool = False,
    shape_source: str = "the camera intrinsics",
    min_depth: float = MIN_DEPTH_M,
    max_depth: float = MAX_DEPTH_M,
) -> np.ndarray:
    """Validate and sanitise a depth image (see the module docstring for the policy).

    Args:
        depth: the image: an array-like of z-depths in metres.
        expected_shape: (H, W) it must have (from the intrinsics or the network), or None to
            accept any non-empty 2-D image.
        name: what to call it in messages.
        allow_batch: accept (..., H, W) (a batch of images) instead of exactly (H, W).
        shape_source: where ``expected_shape`` comes from, for the message.
        min_depth, max_depth: the plausible range, metres; values outside it are no data.

    Returns:
        A new float32 array of the same shape: metres, 0.0 where the input had no plausible
        depth (non-finite, ≤ 0, outside [min_depth, max_depth]).

    Raises:
        DepthImageError (a ValueError): not array-like, wrong ndim or shape, non-float dtype.
    """
    if isinstance(depth, np.ma.MaskedArray):  # masked pixels are no data
        mask = np.ma.getmaskarray(depth)
        depth = depth.data
    else:
        mask = None
    try:
        arr = np.asarray(depth)
    except Exception as exc:  # ragged lists, tensors on a GPU, objects without __array__
        raise DepthImageError(
            f"{name} must be an array of z-depths in metres, got "
            f"{type(depth).__name__} that numpy cannot read as one array "
            f"({exc}); pass an (H, W) float32 numpy array"
        ) from None
    kind = arr.dtype.kind
    if kind != "f":
        what = {
            "u": "an unsigned integer",
            "i": "an integer",
            "b": "a boolean (a mask?)",
            "c": "a complex",
            "O": "an object",
            "U": "a string",
            "S": "a bytes",
            "M": "a datetime",
            "m": "a timedelta",
            "V": "a structured",
        }.get(kind, "a")
        if kind == "O" and arr.ndim == 0:
            raise DepthImageError(
                f"{name} must be an array of z-depths in metres, got "
                f"{type(depth).__name__}; pass an (H, W) float32 numpy array"
            )
        hint = CONVERT_HINT if kind in "uib" else "pass real z-depths in metres"
        raise DepthImageError(
            f"{name} must be float32/float64 metres, got {what} dtype ({arr.dtype}); {hint}"
        )
    want = "(H, W)" if expected_shape is None else f"{tuple(int(s) for s in expected_shape)}"
    if allow_batch:
        want = f"(..., {want[1:]}" if expected_shape is not None else "(..., H, W)"
    if arr.ndim < 2 or (arr.ndim != 2 and not allow_batch):
        extra = (
            " (a multi-channel image? pass the depth channel alone)"
            if arr.ndim == 3 and not allow_batch
            else ""
        )
        raise DepthImageError(
            f"{name} must be a {want} image of z-depths in metres, got "
            f"{arr.ndim}-D shape {arr.shape}{extra}"
        )
    if expected_shape is not None:
        if tuple(arr.shape[-2:]) != tuple(int(s) for s in expected_shape):
            raise DepthImageError(
                f"{name} has shape {arr.shape}, expected {want} (from "
                f"{shape_source}); pass the image the intrinsics describe, or "
                "resize/crop it and its intrinsics together"
            )
    elif arr.shape[-1] == 0 or arr.shape[-2] == 0:
        raise DepthImageError(f"{name} is empty (shape {arr.shape}): no pixels to plan on")
    with np.errstate(over="ignore", invalid="ignore"):
        out = arr.astype(np.float32, copy=True)  # beyond float32's range → ±inf → no data
        good = np.isfinite(out) & (out >= np.float32(min_depth)) & (out <= np.float32(max_depth))
    if mask is not None:
        good &= ~np.broadcast_to(mask, out.shape)
    out[~good] = 0.0
    return out
