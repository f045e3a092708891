"""The grasp planner (paper Fig. 2, red loop): depth image → ranked grasp candidates.

    planner = Planner.load("models/train/latest")
    candidates = planner.plan(depth_m, intrinsics)   # G_opt = candidates[0]

``model.pt`` (written by ``pipeline.train``) holds the weights, the network config, the depth
normalisation and the ranking config (th, D_ground), so a planner needs nothing else.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import torch

from pipeline.camera.geometry import Intrinsics
from pipeline.planner.data import Normalisation, normalise_depth
from pipeline.planner.decode import decode_output
from pipeline.planner.network import GraspNet, NetworkConfig
from pipeline.planner.ranking import GraspCandidate, RankingConfig, rank_grasps

MODEL_FILE = "model.pt"


def pick_device(requested: str = "auto") -> torch.device:
    if requested == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if requested == "cuda" and not torch.cuda.is_available():
        raise ValueError("device=cuda asked for but torch sees no CUDA device; use device=cpu")
    return torch.device(requested)


class Planner:
    """A trained network plus decoding (Eq. 3) and ranking (Eqs. 7–10)."""

    def __init__(self, net: GraspNet, norm: Normalisation, ranking: RankingConfig,
                 device: str | torch.device = "cpu") -> None:
        self.device = pick_device(device) if isinstance(device, str) else device
        self.net = net.to(self.device).eval()
        self.norm, self.ranking = norm, ranking
        self.size = net.cfg.input_size

    @classmethod
    def load(cls, model_dir: Path | str, device: str = "cpu") -> "Planner":
        """From a training artifact folder (or a ``model.pt`` path)."""
        path = Path(model_dir)
        path = path / MODEL_FILE if path.is_dir() else path
        if not path.is_file():
            raise FileNotFoundError(f"{path} not found: give a training artifact folder "
                                    "(models/train/<version>) made by `python -m pipeline.train`")
        blob = torch.load(path, map_location="cpu", weights_only=True)
        net = GraspNet(NetworkConfig(**blob["network"]))
        net.load_state_dict(blob["state_dict"])
        return cls(net, Normalisation(**blob["normalisation"]), RankingConfig(**blob["ranking"]),
                   device)

    def _check(self, depth_m: np.ndarray) -> np.ndarray:
        depth_m = np.asarray(depth_m)
        if depth_m.dtype not in (np.float32, np.float64):
            raise ValueError(f"depth must be float32/float64 metres, got dtype {depth_m.dtype} "
                             "(convert a uint16 image with its depth unit first)")
        if depth_m.ndim < 2 or depth_m.shape[-2:] != (self.size, self.size):
            raise ValueError(f"depth must be (…, {self.size}, {self.size}) metres, got "
                             f"{depth_m.shape}")
        return depth_m.astype(np.float32)

    @torch.no_grad()
    def predict(self, depth_m: np.ndarray) -> torch.Tensor:
        """(B, H, W) or (H, W) depth, metres, 0 = no data → raw output (B, 2 + C, N, N), CPU."""
        depth_m = self._check(depth_m)
        batch = depth_m.reshape(-1, 1, self.size, self.size)
        x = torch.from_numpy(normalise_depth(batch, self.norm)).to(self.device)
        return self.net(x).float().cpu()

    def plan(self, depth_m: np.ndarray, intrinsics: Intrinsics) -> list[GraspCandidate]:
        """One (H, W) depth image, metres → candidates sorted by J (Eq. 7), G_opt first."""
        depth_m = self._check(depth_m)
        if depth_m.ndim != 2:
            raise ValueError(f"plan takes one (H, W) image, got {depth_m.shape}; use predict "
                             "for batches")
        raw = self.predict(depth_m)[0]
        preds = decode_output(raw, threshold=self.ranking.threshold, image_size=self.size)
        return rank_grasps(preds, depth_m, intrinsics, self.ranking)


def ranking_config(cfg) -> RankingConfig:
    """The ranking config of a pipeline config: th from ``train.threshold``, D_ground = camera
    height above the bin floor + floor thickness (the camera–ground distance, Eq. 9)."""
    return RankingConfig(d_ground=float(cfg.camera.height_above_bin_floor + cfg.bin.floor_thickness),
                         threshold=float(cfg.train.threshold))


def ranking_dict(r: RankingConfig) -> dict:
    return dataclasses.asdict(r)
