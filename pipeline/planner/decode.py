"""Network output → grasp point predictions G_i = [g_i, S_i] (paper Eqs. 1–3)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from pipeline.grasping.types import GraspClass
from pipeline.planner.network import split_output

_CLASSES = tuple(GraspClass)  # GraspClass by output channel (its value)


@dataclass
class GraspPrediction:
    """One cell's prediction. ``u``, ``v``: pixels; ``probability`` = max_c p(c) (S_i of Eq. 3);
    ``class_probs``: (C,) per-class sigmoid probabilities in ``GraspClass`` order."""

    u: float
    v: float
    grasp_class: GraspClass
    probability: float
    class_probs: np.ndarray


def decode_output(
    raw: torch.Tensor, threshold: float = 0.0, image_size: int = 416
) -> list[GraspPrediction]:
    """One image's output (2 + C, N, N) → the cells whose max class probability > ``threshold``
    (Eq. 3), in row-major cell order. NG points are kept (ranking drops them)."""
    if raw.ndim != 3:
        raise ValueError(f"expected one image's output (2 + C, N, N), got {tuple(raw.shape)}")
    offset, logits = split_output(raw.detach()[None].float())  # (1, N, N, 2), (1, N, N, C)
    offset, probs = offset[0].cpu().numpy(), torch.sigmoid(logits[0]).cpu().numpy()
    grid = offset.shape[0]
    cell_px = image_size / grid
    best = probs.argmax(-1)  # (N, N)
    best_p = probs.max(-1)  # (N, N)
    jv, ju = np.nonzero(best_p > threshold)  # row-major cell order
    # all kept cells at once: the cell index (int64) plus its float32 offset is float64, as it
    # is for one cell's numpy scalars
    us = ((ju + offset[jv, ju, 0]) * cell_px).tolist()
    vs = ((jv + offset[jv, ju, 1]) * cell_px).tolist()
    classes = [_CLASSES[c] for c in best[jv, ju].tolist()]
    kept = best_p[jv, ju].tolist()  # float32 → float, exactly
    cell_probs = probs[jv, ju]  # (K, C), a copy
    return [
        GraspPrediction(u, v, c, p, cell_probs[k].copy())
        for k, (u, v, c, p) in enumerate(zip(us, vs, classes, kept))
    ]


def second_chance(
    preds: list[GraspPrediction], threshold: float, fallback_threshold: float
) -> list[GraspPrediction]:
    """The cells that Eq. 3 at ``threshold`` drops (their most probable class is NG, or its
    probability is at most ``threshold``) but whose most probable class other than NG has a
    probability above ``fallback_threshold``, each as that class with that probability.

    ``preds``: ``decode_output`` at ``fallback_threshold`` or lower (each cell's
    ``class_probs`` are read; a cell below ``fallback_threshold`` in every class gives
    nothing). The closed loop's fallback tier (``Planner.plan``), not the paper."""
    rest = [p for p in preds if not (p.grasp_class != GraspClass.NG and p.probability > threshold)]
    if not rest:  # Eq. 3 keeps every cell
        return []
    probs = np.stack([np.asarray(p.class_probs) for p in rest]).astype(np.float64)  # (K, C)
    probs[:, int(GraspClass.NG)] = -np.inf
    best = probs.argmax(axis=1)  # the most probable class other than NG, the first of equals
    best_p = probs[np.arange(len(rest)), best]
    return [
        GraspPrediction(
            u=p.u, v=p.v, grasp_class=GraspClass(c), probability=q, class_probs=p.class_probs
        )
        for p, c, q in zip(rest, best.tolist(), best_p.tolist())
        if q > fallback_threshold
    ]
