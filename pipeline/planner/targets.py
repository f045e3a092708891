"""Grid targets for the DCNN (paper Sec. 4.1, Eq. 5): one image's grasp points ↔ N × N cells.

Pixel frame: (u, v) continuous image coordinates, u right, v down; the image spans
[0, S) × [0, S) with S = ``image_size`` (pixel k's centre is at k, as in
``pipeline.camera.geometry.backproject``). Cell (row j_v, column j_u) covers
u ∈ [32 j_u, 32 (j_u + 1)), v ∈ [32 j_v, 32 (j_v + 1)) for S = 416, N = 13.

Offsets are in cell units: the fraction of a cell, in [0, 1), from the cell's top-left corner.

**One point per cell.** A cell can hold only one ground-truth point. When several fall in one
cell, the kept point is chosen by, in order:

1. graspable (R, L, B) before NG: the planner outputs graspable points only, so losing an NG
   point costs less than losing a graspable one;
2. the point closest to the cell centre (the other points are nearer a neighbouring cell, where
   the network's (0, 1) offsets reach least well);
3. the lower input index (deterministic ties).

The others are dropped and counted in ``lost``.
"""

from __future__ import annotations

import numpy as np
import torch

from pipeline.grasping.types import GraspClass

EMPTY = -1  # ``cls`` and ``kept_index`` value of a cell without a ground-truth point
# Points this far (pixels) outside the image are an error; nearer ones are clamped into it
# (a projected surface centre can sit a fraction of a pixel past the border).
OUTSIDE_TOLERANCE_PX = 1.0
_BELOW_ONE = np.nextafter(np.float32(1.0), np.float32(0.0))  # largest float32 < 1


def encode(uv: np.ndarray, classes: np.ndarray, grid: int = 13, image_size: int = 416) -> dict:
    """Grasp points of one image → grid targets.

    Args:
        uv: (P, 2) float grasp points (u, v), pixels.
        classes: (P,) int grasp classes (``GraspClass`` values).
        grid: N, cells per side.
        image_size: S, pixels per side (a multiple of ``grid``).

    Returns:
        dict with
        ``obj`` (N, N) bool: the cell holds a ground-truth point (1^GP of Eq. 5);
        ``offset`` (N, N, 2) float32 (u, v) offset in cell units in [0, 1) (0 where empty);
        ``cls`` (N, N) int64 class of the kept point, ``EMPTY`` (−1) where empty;
        ``kept_index`` (N, N) int64 index into ``uv`` of the kept point, −1 where empty;
        ``lost`` int: points dropped by the one-per-cell rule.
    """
    uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
    classes = np.asarray(classes).reshape(-1).astype(np.int64)
    if len(uv) != len(classes):
        raise ValueError(f"uv has {len(uv)} points but classes has {len(classes)}")
    if image_size % grid:
        raise ValueError(f"image_size {image_size} is not a multiple of grid {grid}")
    if not np.all(np.isfinite(uv)):
        raise ValueError("uv holds NaN or infinite grasp points; fix the labels")
    bad = (uv < -OUTSIDE_TOLERANCE_PX) | (uv > image_size + OUTSIDE_TOLERANCE_PX)
    if bad.any():
        raise ValueError(
            f"grasp points {uv[bad.any(1)].tolist()} lie outside the "
            f"{image_size}×{image_size} image; were the labels made for "
            "another image size?"
        )
    if np.any((classes < 0) | (classes >= len(GraspClass))):
        raise ValueError(f"classes must be in 0..{len(GraspClass) - 1}, got {np.unique(classes)}")

    cell_px = image_size / grid
    pos = np.clip(uv / cell_px, 0.0, grid * (1 - 1e-9))  # (P, 2) in cell units, in [0, N)
    cell = np.floor(pos).astype(np.int64)  # (P, 2) (j_u, j_v)
    frac = np.minimum(pos - cell, _BELOW_ONE)  # (P, 2) in [0, 1)

    obj = np.zeros((grid, grid), bool)
    offset = np.zeros((grid, grid, 2), np.float32)
    cls = np.full((grid, grid), EMPTY, np.int64)
    kept = np.full((grid, grid), -1, np.int64)
    # Sort by the rule's keys; the first point to reach a cell keeps it.
    ng = classes == GraspClass.NG
    dist_to_centre = np.linalg.norm(frac - 0.5, axis=1)
    order = np.lexsort((np.arange(len(uv)), dist_to_centre, ng))  # last key is primary
    for i in order:
        ju, jv = cell[i]
        if obj[jv, ju]:
            continue
        obj[jv, ju] = True
        offset[jv, ju] = frac[i]
        cls[jv, ju] = classes[i]
        kept[jv, ju] = i
    return {
        "obj": obj,
        "offset": offset,
        "cls": cls,
        "kept_index": kept,
        "lost": int(len(uv) - obj.sum()),
    }


def decode_points(
    obj: np.ndarray, offset: np.ndarray, cls: np.ndarray, image_size: int = 416
) -> tuple[np.ndarray, np.ndarray]:
    """Inverse of ``encode``: the cells with ``obj`` → points in row-major cell order.

    Args:
        obj: (N, N) bool; offset: (N, N, 2) (u, v) in cell units; cls: (N, N) int.

    Returns:
        uv (K, 2) float32 pixels (u, v), classes (K,) int64.
    """
    obj = np.asarray(obj, bool)
    grid = obj.shape[0]
    jv, ju = np.nonzero(obj)  # row-major
    cell_px = image_size / grid
    off = np.asarray(offset, np.float64)[jv, ju]  # (K, 2)
    uv = np.stack([ju + off[:, 0], jv + off[:, 1]], axis=1) * cell_px
    return uv.astype(np.float32), np.asarray(cls)[jv, ju].astype(np.int64)


def stack_targets(targets: list[dict]) -> dict[str, torch.Tensor]:
    """``encode`` outputs of B images → a batch for ``pipeline.planner.loss.grasp_loss``:
    obj (B, N, N) bool, offset (B, N, N, 2) float32, cls (B, N, N) int64."""
    return {
        "obj": torch.from_numpy(np.stack([t["obj"] for t in targets])),
        "offset": torch.from_numpy(np.stack([t["offset"] for t in targets])),
        "cls": torch.from_numpy(np.stack([t["cls"] for t in targets])),
    }
