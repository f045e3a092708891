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
import dataclasses

import numpy as np
import torch
from torch import nn

from pipeline.camera.depth_filter import preprocess_depth
from pipeline.camera.geometry import Intrinsics, backproject
from pipeline.grasping.types import GraspClass
from pipeline.planner.decode import GraspPrediction
from pipeline.planner.network import split_output
from pipeline.planner.normalisation import Normalisation
from pipeline.planner.planner import NO_PREDICTION, NO_RANKABLE_CANDIDATE, NO_VALID_DEPTH, Planner
from pipeline.planner.ranking import (
    GraspCandidate,
    RankingConfig,
    graspability,
    order_candidates,
    surface_normal,
)


class ReferencePlanner:
    """``planner``'s network, normalisation, ranking config and depth filter, planned the
    reference way. ``plan`` takes and returns what ``Planner.plan`` does; ``last_reason``
    likewise."""

    def __init__(self, planner: Planner) -> None:
        self.planner = planner
        self.net = copy.deepcopy(planner.net).eval()
        for module in self.net.modules():  # every 2 x 2 pool back to nn.MaxPool2d
            for name, child in module.named_children():
                if isinstance(child, nn.MaxPool2d):
                    setattr(module, name, nn.MaxPool2d(child.kernel_size, child.stride))
        self.last_reason = ""

    @torch.no_grad()
    def predict(self, depth_m: np.ndarray) -> torch.Tensor:
        p = self.planner
        depth_m = p._check(depth_m)
        batch = depth_m.reshape(-1, 1, p.size, p.size)
        x = torch.from_numpy(normalise_depth(batch, p.norm)).to(p.device)
        return self.net(x).float().cpu()

    def plan(
        self, depth_m: np.ndarray, intrinsics: Intrinsics, fallback_threshold: float | None = None
    ) -> list[GraspCandidate]:
        p = self.planner
        depth_m = preprocess_depth(p._check(depth_m, batch=False), p.depth_filter)
        if (intrinsics.height, intrinsics.width) != depth_m.shape:
            raise ValueError("intrinsics and depth image differ in size")
        self.last_reason = ""
        if not (depth_m > 0).any():
            self.last_reason = NO_VALID_DEPTH
            return []
        raw = self.predict(depth_m)[0]
        th = p.ranking.threshold
        second = fallback_threshold is not None and float(fallback_threshold) < th
        floor = float(fallback_threshold) if second else th
        preds = decode_output(raw, threshold=floor, image_size=p.size)
        preds = [q for q in preds if np.isfinite(q.u) and np.isfinite(q.v)]
        first = [q for q in preds if q.probability > th and q.grasp_class != GraspClass.NG]
        tiers = [(first, p.ranking)]
        if second:
            tiers.append(
                (second_chance(preds, th, floor), dataclasses.replace(p.ranking, threshold=floor))
            )
        if not any(preds for preds, _ in tiers):
            self.last_reason = NO_PREDICTION
            return []
        ranked = [
            dataclasses.replace(c, second_tier=tier > 0)
            for tier, (preds, ranking) in enumerate(tiers)
            for c in rank_grasps(preds, depth_m, intrinsics, ranking)
            if _has_data(depth_m, c.u, c.v)
        ]
        if not ranked:
            self.last_reason = NO_RANKABLE_CANDIDATE
        return ranked


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
) -> list[GraspCandidate]:
    """``pipeline.planner.ranking.rank_grasps``, one candidate at a time."""
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
        depth = float(depth_m[v, u])
        if depth <= 0:
            window = depth_m[max(v - h, 0) : v + h + 1, max(u - h, 0) : u + h + 1]
            if not (window > 0).any():
                continue
            depth = float(np.median(window[window > 0]))
        normal = surface_normal(points, u, v, h, cfg.max_depth_jump)
        if normal is None:
            continue
        phi = inclination(normal)
        score, j_distance, j_inclination = graspability(depth, phi, cfg.d_ground, cfg.phi_switch)
        out.append(
            GraspCandidate(
                u=float(pred.u),
                v=float(pred.v),
                grasp_class=GraspClass(pred.grasp_class),
                probability=float(pred.probability),
                score=score,
                phi=phi,
                depth=depth,
                normal_cam=normal.astype(np.float32),
                j_distance=j_distance,
                j_inclination=j_inclination,
            )
        )
    return order_candidates(out, cfg)


def _has_data(depth_m: np.ndarray, u: float, v: float) -> bool:
    H, W = depth_m.shape
    return bool(depth_m[int(np.clip(round(v), 0, H - 1)), int(np.clip(round(u), 0, W - 1))] > 0)
