"""A trained GQ-CNN's outputs in the baseline artifact: its model file, the one
:func:`pipeline.dexnet.planner.load_gqcnn` reads, and its figures for the manifest.

The inputs of a split are ``(crops, poses, labels)``: crops (M, 1, S, S) float16, poses (M, 2)
float32 and labels (M,) bool, as ``pipeline.dexnet.training`` builds and trains on them.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import torch

from pipeline.dexnet.gqcnn import GQCNN, CropConfig, count_parameters
from pipeline.dexnet.training import evaluate_gqcnn

# (crops (M, 1, S, S) float16, poses (M, 2) float32, labels (M,) bool) of one split.
Inputs = tuple[np.ndarray, np.ndarray, np.ndarray]


def save_gqcnn(net: GQCNN, crop: CropConfig, path: Path) -> None:
    """Write ``net`` to ``path`` (``gqcnn.pt``, ``gqcnn_ood.pt``): its network and crop configs
    as dicts and its weights (``pipeline.dexnet.planner.MODEL_KEYS``), all that
    ``torch.load(weights_only=True)`` reads back."""
    torch.save(
        {
            "network": dataclasses.asdict(net.cfg),
            "crop": dataclasses.asdict(crop),
            "state_dict": net.state_dict(),
        },
        path,
    )


def training_timings(name: str, history: dict) -> dict[str, float]:
    """``<name>_train_s`` (seconds, 3 decimals) and ``<name>_samples_per_s`` (1 decimal) of a
    ``train_gqcnn`` history; ``name``: the variant (``gqcnn``, ``gqcnn_ood``)."""
    return {
        f"{name}_train_s": round(history["train_s"], 3),
        f"{name}_samples_per_s": round(history["samples_per_s"], 1),
    }


def training_metrics(net: GQCNN, history: dict, train: Inputs, tests: dict[str, Inputs]) -> dict:
    """The manifest's entry of a trained GQ-CNN, figures to 6 decimals: its parameter count, the
    number of training samples, the training loss and validation figures of each epoch
    (``history``), and ``evaluate_gqcnn`` on each of ``tests`` under its name."""
    return {
        "parameters": count_parameters(net),
        "train_samples": int(len(train[2])),
        "train_loss": [round(x, 6) for x in history["train_loss"]],
        "val": [_rounded(e) for e in history["val"]],
        **{name: _rounded(evaluate_gqcnn(net, *inputs)) for name, inputs in tests.items()},
    }


def _rounded(figures: dict[str, float]) -> dict[str, float]:
    return {k: round(v, 6) for k, v in figures.items()}
