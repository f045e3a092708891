"""Network output → grasp point predictions G_i = [g_i, S_i] (paper Eqs. 1–3)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from pipeline.grasping.types import GraspClass
from pipeline.planner.network import split_output


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
    out = []
    for jv, ju in zip(*np.nonzero(best_p > threshold)):
        out.append(
            GraspPrediction(
                u=float((ju + offset[jv, ju, 0]) * cell_px),
                v=float((jv + offset[jv, ju, 1]) * cell_px),
                grasp_class=GraspClass(int(best[jv, ju])),
                probability=float(best_p[jv, ju]),
                class_probs=probs[jv, ju].copy(),
            )
        )
    return out


def second_chance(
    preds: list[GraspPrediction], threshold: float, fallback_threshold: float
) -> list[GraspPrediction]:
    """The cells that Eq. 3 at ``threshold`` drops (their most probable class is NG, or its
    probability is at most ``threshold``) but whose most probable class other than NG has a
    probability above ``fallback_threshold``, each as that class with that probability.

    ``preds``: ``decode_output`` at ``fallback_threshold`` or lower (each cell's
    ``class_probs`` are read; a cell below ``fallback_threshold`` in every class gives
    nothing). The closed loop's fallback tier (``Planner.plan``), not the paper."""
    out = []
    for p in preds:
        if p.grasp_class != GraspClass.NG and p.probability > threshold:
            continue  # Eq. 3 keeps it
        probs = np.asarray(p.class_probs, np.float64).copy()
        probs[int(GraspClass.NG)] = -np.inf
        best = int(probs.argmax())
        if probs[best] > fallback_threshold:
            out.append(
                GraspPrediction(
                    u=p.u,
                    v=p.v,
                    grasp_class=GraspClass(best),
                    probability=float(probs[best]),
                    class_probs=p.class_probs,
                )
            )
    return out
