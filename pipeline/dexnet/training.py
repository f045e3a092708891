"""Training the GQ-CNN on labelled candidates: the network's inputs (crops and poses) and Adam on
binary cross-entropy, the data order of epoch e from (seed, e)."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import torch

from pipeline.dataset.scenes import SceneDataset
from pipeline.dexnet.gqcnn import GQCNN, candidate_inputs, predict_quality
from pipeline.dexnet.planner import gqcnn_config
from pipeline.dexnet.sampling import Candidates


def as_candidates(rows: dict, idx: np.ndarray) -> Candidates:
    return Candidates(
        uv=rows["uv"][idx],
        point=rows["point"][idx],
        axis=rows["axis"][idx],
        depth=rows["depth"][idx],
        angle=rows["angle"][idx],
    )


def build_inputs(gen_dir: Path, split: str, rows: dict, crop) -> tuple[np.ndarray, np.ndarray]:
    """Crops (M, 1, S, S) float16 and poses (M, 2) float32 of a split's candidates, in row order."""
    m = len(rows.get("label", []))
    crops = np.empty((m, 1, crop.size, crop.size), np.float16)
    poses = np.empty((m, 2), np.float32)
    if m == 0:
        return crops, poses
    ds = SceneDataset(gen_dir, split)
    order = np.argsort(rows["scene_index"], kind="stable")
    bounds = np.flatnonzero(np.diff(rows["scene_index"][order])) + 1
    for group in np.split(order, bounds):
        depth = ds[int(rows["scene_index"][group[0]])].depth_m
        c, p = candidate_inputs(depth, as_candidates(rows, group), crop)
        crops[group], poses[group] = c.astype(np.float16), p
    return crops, poses


def evaluate_gqcnn(net: GQCNN, crops, poses, labels) -> dict:
    if len(labels) == 0:
        return {"loss": float("nan"), "accuracy": float("nan")}
    q = predict_quality(net, crops.astype(np.float32), poses)
    eps = 1e-7
    y = labels.astype(np.float64)
    loss = -np.mean(y * np.log(q + eps) + (1 - y) * np.log(1 - q + eps))
    pred = q >= 0.5
    tp = int(np.sum(pred & labels))
    return {
        "loss": float(loss),
        "accuracy": float(np.mean(pred == labels)),
        "precision": float(tp / max(int(pred.sum()), 1)),
        "recall": float(tp / max(int(labels.sum()), 1)),
        "positive_rate": float(np.mean(labels)),
    }


def train_gqcnn(
    cfg, train_inputs, val_inputs, progress: bool, name: str = "gqcnn"
) -> tuple[GQCNN, dict]:
    """Adam on binary cross-entropy; data order of epoch e from (seed, e). Returns net, history.
    ``name``: the variant, for the progress bar."""
    from tqdm import tqdm

    b = cfg.baseline
    torch.manual_seed(int(cfg.seed))
    torch.set_num_threads(int(b.num_threads))
    torch.use_deterministic_algorithms(True)
    layout = torch.channels_last if bool(b.channels_last) else torch.contiguous_format
    net = GQCNN(gqcnn_config(cfg)).to(memory_format=layout)
    opt = torch.optim.Adam(net.parameters(), lr=float(b.lr), weight_decay=float(b.weight_decay))
    crops, poses, labels = train_inputs
    n = len(labels)
    history: dict = {"step_loss": [], "train_loss": [], "val": []}
    t0 = time.perf_counter()
    for epoch in range(int(b.epochs)):
        net.train()
        gen = torch.Generator().manual_seed(int(cfg.seed) * 1_000_003 + epoch)
        order = torch.randperm(n, generator=gen).numpy()
        total = 0.0
        steps = range(0, n, int(b.batch_size))
        for start in tqdm(
            steps,
            desc=f"baseline {name} epoch {epoch + 1}/{b.epochs}",
            unit="batch",
            disable=not progress,
            leave=False,
        ):
            idx = np.sort(order[start : start + int(b.batch_size)])
            x = torch.from_numpy(crops[idx].astype(np.float32)).contiguous(memory_format=layout)
            p = torch.from_numpy(poses[idx])
            y = torch.from_numpy(labels[idx].astype(np.float32))
            loss = torch.nn.functional.binary_cross_entropy_with_logits(net(x, p), y)
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            history["step_loss"].append(loss.item())
            total += history["step_loss"][-1] * len(idx)
        history["train_loss"].append(total / max(n, 1))
        history["val"].append(evaluate_gqcnn(net, *val_inputs))
    history["train_s"] = time.perf_counter() - t0
    history["samples_per_s"] = int(b.epochs) * n / max(history["train_s"], 1e-9)
    # the standard layout, as the stored network is loaded (the same weights, so the same
    # outputs in memory as from disk)
    return net.to(memory_format=torch.contiguous_format).eval(), history
