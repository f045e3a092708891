"""The reference DCNN planning path: ``Planner.plan`` as written before it was made faster
(``docs/performance.md``, "Planning time"), kept for ``make bench`` (which times it beside
``Planner.plan`` in the same run) and for the tests that check both give the same candidates.

It computes the same thing as ``Planner.plan``, the slow way: the network's 2 × 2 max-pools as
``torch.nn.functional.max_pool2d`` (which also finds the indices a backward pass would need),
the network's output decoded cell by cell, the image back-projected once per tier of
candidates, and each candidate's surface normal computed on its own
(``pipeline.planner.ranking.surface_normal``).
"""

from __future__ import annotations

import copy

import numpy as np
import torch
from torch import nn

from pipeline.camera.geometry import Intrinsics, backproject
from pipeline.grasping.types import GraspClass
from pipeline.planner.decode import GraspPrediction
from pipeline.planner.network import split_output
from pipeline.planner.normalisation import Normalisation
from pipeline.planner.planner import Planner
from pipeline.planner.ranking import (
    GraspCandidate,
    RankingConfig,
    depth_at,
    grasp_candidate,
    order_candidates,
    surface_normal,
)


def decode_output(
    raw: torch.Tensor, threshold: float = 0.0, image_size: int = 416
) -> list[GraspPrediction]:
    """``pipeline.planner.decode.decode_output``, one cell at a time."""
    offset, logits = split_output(raw.detach()[None].float())
    offset, probs = offset[0].cpu().numpy(), torch.sigmoid(logits[0]).cpu().numpy()
    grid = offset.shape[0]
    cell_px = image_size / grid
    best = probs.argmax(-1)
    best_p = probs.max(-1)
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
    """``pipeline.planner.decode.second_chance``, one cell at a time."""
    out = []
    for p in preds:
        if p.grasp_class != GraspClass.NG and p.probability > threshold:
            continue
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


def normalise_depth(depth_m: np.ndarray, norm: Normalisation) -> np.ndarray:
    """``pipeline.planner.normalisation.normalise_depth``, with its copy to float32."""
    depth_m = np.asarray(depth_m, np.float32)
    x = (depth_m - np.float32(norm.d_ground)) / np.float32(norm.depth_scale)
    return np.where(depth_m > 0, x, np.float32(norm.missing_depth_value)).astype(np.float32)


def inclination(normal_cam: np.ndarray) -> float:
    """``pipeline.planner.ranking.inclination``, with ``np.linalg.norm`` and ``np.clip``."""
    n = np.asarray(normal_cam, np.float64)
    return float(np.arccos(np.clip(-n[2] / np.linalg.norm(n), -1.0, 1.0)))


def rank_grasps(
    predictions: list[GraspPrediction],
    depth_m: np.ndarray,
    intrinsics: Intrinsics,
    cfg: RankingConfig,
    points_cam: np.ndarray | None = None,
) -> list[GraspCandidate]:
    """``pipeline.planner.ranking.rank_grasps``, one candidate at a time (``points_cam`` is
    not used: it back-projects the image itself)."""
    depth_m = np.asarray(depth_m, np.float32)
    points = backproject(depth_m, intrinsics)
    H, W = depth_m.shape
    h = cfg.normal_half_window
    out = []
    for pred in predictions:
        if pred.probability <= cfg.threshold or pred.grasp_class == GraspClass.NG:
            continue
        u = int(np.clip(round(pred.u), 0, W - 1))
        v = int(np.clip(round(pred.v), 0, H - 1))
        depth = depth_at(depth_m, u, v, h)
        normal = None if depth is None else surface_normal(points, u, v, h, cfg.max_depth_jump)
        if normal is None:
            continue
        out.append(grasp_candidate(pred, depth, normal, inclination(normal), cfg))
    return order_candidates(out, cfg)


def _has_data(depth_m: np.ndarray, u: float, v: float) -> bool:
    H, W = depth_m.shape
    return bool(depth_m[int(np.clip(round(v), 0, H - 1)), int(np.clip(round(u), 0, W - 1))] > 0)


class ReferencePlanner(Planner):
    """``planner``'s network, normalisation, ranking config and depth filter, planned by
    ``Planner.plan``'s steps with the reference parts: the network with ``nn.MaxPool2d``, the
    normalisation with its copy, decoding and the second tier one cell at a time, ranking one
    candidate at a time (``rank_grasps`` below). ``plan`` takes and returns what
    ``Planner.plan`` does; ``last_reason`` likewise."""

    def __init__(self, planner: Planner) -> None:
        self.__dict__.update(planner.__dict__)
        self.net = copy.deepcopy(planner.net).eval()
        for module in self.net.modules():  # every 2 x 2 pool back to nn.MaxPool2d
            for name, child in module.named_children():
                if isinstance(child, nn.MaxPool2d):
                    setattr(module, name, nn.MaxPool2d(child.kernel_size, child.stride))
        self.last_reason = ""

    @torch.no_grad()
    def predict(self, depth_m: np.ndarray) -> torch.Tensor:
        depth_m = self._check(depth_m)
        batch = depth_m.reshape(-1, 1, self.size, self.size)
        x = torch.from_numpy(normalise_depth(batch, self.norm)).to(self.device)
        return self.net(x).float().cpu()

    # the reference parts, in the places ``Planner.plan`` calls its parts from
    decode_cells = staticmethod(decode_output)
    fallback_tier = staticmethod(second_chance)
    rank_tier = staticmethod(rank_grasps)
