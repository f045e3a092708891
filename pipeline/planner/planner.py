"""The grasp planner (paper Fig. 2, red loop): depth image → ranked grasp candidates.

    planner = Planner.load("models/train/latest")
    candidates = planner.plan(depth_m, intrinsics)   # G_opt = candidates[0]

``model.pt`` (written by ``pipeline.stages.train``) holds the weights, the network config, the depth
normalisation and the ranking config (th, D_ground), so a planner needs nothing else.

**Bad input.** The depth image goes through ``pipeline.camera.depth_input.check_depth_image``:
a wrong shape, ndim or dtype (e.g. a raw uint16 image) raises its ``DepthImageError`` (a
``ValueError``) naming the fix; NaN, ±inf, ≤ 0 and implausible depths become 0 = no data. A
candidate is only ever returned at a pixel with data: ``plan`` drops the candidates whose
nearest pixel has none (``rank_grasps`` alone would give them the window's median depth). When
``plan`` returns no candidate, ``planner.last_reason`` says why (``NO_GRASP_REASONS``); it is
``""`` after a plan with candidates.

**Bad model files.** ``Planner.load`` raises ``ModelFileError`` (a ``ValueError``) naming the
file, what was expected and the fix, for a file that is not a readable checkpoint (truncated,
garbage), lacks one of ``MODEL_KEYS``, or holds weights that do not fit the network its config
describes (missing or unexpected tensors, other shapes, e.g. another width). It always loads
with ``weights_only=True``.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from pathlib import Path
from typing import TypeVar

import numpy as np
import torch

from pipeline.camera.depth_filter import preprocess_depth
from pipeline.camera.depth_input import check_depth_image
from pipeline.camera.geometry import Intrinsics, backproject, ground_distance
from pipeline.config.build import from_section
from pipeline.grasping.types import GraspClass
from pipeline.planner.decode import decode_output, second_chance
from pipeline.planner.network import GraspNet, NetworkConfig
from pipeline.planner.normalisation import Normalisation, normalise_depth
from pipeline.planner.ranking import GraspCandidate, RankingConfig, rank_grasps

T = TypeVar("T")

MODEL_FILE = "model.pt"
MODEL_KEYS = ("state_dict", "network", "normalisation", "ranking")
RETRAIN_FIX = (
    "retrain with `make train` (`python -m pipeline.stages.train`), or pass a "
    "models/train/<version> folder made by this version of the pipeline"
)

# ``Planner.last_reason`` after a plan that returned no candidate.
NO_VALID_DEPTH = "no_valid_depth"  # no pixel of the image has data (all NaN/inf/<= 0, ...)
NO_PREDICTION = "no_prediction"  # no cell above the threshold th with a class other than NG
NO_RANKABLE_CANDIDATE = "no_rankable_candidate"  # every prediction lacked depth or a normal
NO_GRASP_REASONS = (NO_VALID_DEPTH, NO_PREDICTION, NO_RANKABLE_CANDIDATE)


class ModelFileError(ValueError):
    """A model file that this version of the pipeline cannot load."""


def find_model_file(
    model_dir: Path | str, file_name: str, kind: str, folder: str, stage: str
) -> Path:
    """The model file ``file_name`` in the artifact folder ``model_dir``, or ``model_dir`` itself
    when it is not a folder. ``FileNotFoundError`` when there is no such file, naming what to
    give: a ``kind`` artifact folder (``folder``/<version>) made by ``pipeline.stages.<stage>``."""
    path = Path(model_dir)
    path = path / file_name if path.is_dir() else path
    if not path.is_file():
        raise FileNotFoundError(
            f"{path} not found: give a {kind} artifact folder "
            f"({folder}/<version>) made by `python -m pipeline.stages.{stage}`"
        )
    return path


def read_model_file(path: Path, keys: tuple[str, ...], what: str, fix: str) -> dict:
    """``torch.load(path, weights_only=True)`` of a dict holding ``keys``, else a
    ``ModelFileError`` naming the file, ``what`` it should be and the ``fix``."""
    try:
        blob = torch.load(path, map_location="cpu", weights_only=True)
    except OSError:
        raise
    except Exception as exc:  # truncated zip, garbage, a pickle of other objects, ...
        # torch's first sentence only (its advice is about weights_only=False: not wanted here).
        first = (str(exc).strip().splitlines() or [""])[0].split(". ")[0][:160]
        first = first or "the file ends too early"
        raise ModelFileError(
            f"{path} is not a readable {what} ({type(exc).__name__}: {first}); "
            f"the file may be truncated or not a model at all: {fix}"
        ) from None
    if not isinstance(blob, dict):
        raise ModelFileError(
            f"{path} holds a {type(blob).__name__}, not a {what} (a dict with "
            f"keys {', '.join(keys)}): {fix}"
        )
    missing = [k for k in keys if k not in blob]
    if missing:
        raise ModelFileError(
            f"{path} is not a {what}: it lacks {', '.join(missing)} (has "
            f"{', '.join(map(str, blob)) or 'nothing'}; expected {', '.join(keys)}"
            f"): {fix}"
        )
    return blob


def config_from_blob(path: Path, fix: str, what: str, build: Callable[[], T]) -> T:
    """``build()`` the ``what`` config(s) a model file holds beside its network (e.g.
    ``CropConfig(**blob["crop"])``); a ``TypeError`` there (fields this version does not know,
    or lacks) is a ``ModelFileError`` naming the file, ``what`` and the ``fix``."""
    try:
        return build()
    except TypeError as exc:
        raise ModelFileError(
            f"{path}: its {what} config does not fit this version of the pipeline ({exc}): {fix}"
        ) from None


def build_from_blob(
    path: Path, fix: str, build: Callable[[], torch.nn.Module], state_dict
) -> torch.nn.Module:
    """``build()`` the network a model file's config describes and load ``state_dict`` into it,
    checking first that the file's tensors are exactly the network's (names and shapes), so a
    mismatch is a ``ModelFileError`` that lists it rather than torch's long RuntimeError."""
    try:
        net = build()
    except (TypeError, ValueError, KeyError) as exc:
        raise ModelFileError(
            f"{path}: its network config does not describe a network of this "
            f"version of the pipeline ({type(exc).__name__}: {exc}): "
            f"{fix}"
        ) from None
    if not isinstance(state_dict, dict) or not all(
        isinstance(v, torch.Tensor) for v in state_dict.values()
    ):
        raise ModelFileError(f"{path}: state_dict is not a dict of tensors: {fix}")
    want = net.state_dict()
    missing = [k for k in want if k not in state_dict]
    unexpected = [k for k in state_dict if k not in want]
    shapes = [
        f"{k}: file {tuple(state_dict[k].shape)}, network {tuple(want[k].shape)}"
        for k in want
        if k in state_dict and state_dict[k].shape != want[k].shape
    ]
    problems = []
    if missing:
        problems.append(f"{len(missing)} tensor(s) missing (e.g. {', '.join(missing[:3])})")
    if unexpected:
        problems.append(
            f"{len(unexpected)} unexpected tensor(s) (e.g. {', '.join(unexpected[:3])})"
        )
    if shapes:
        problems.append(f"{len(shapes)} tensor(s) of another shape (e.g. {'; '.join(shapes[:2])})")
    if problems:
        cfg = getattr(net, "cfg", None)
        raise ModelFileError(
            f"{path}: its weights do not fit the network its config describes "
            f"({cfg}): {', '.join(problems)}; the file comes from an "
            f"incompatible network or another version: {fix}"
        )
    try:
        net.load_state_dict(state_dict)
    except RuntimeError as exc:  # e.g. dtypes torch cannot copy
        raise ModelFileError(
            f"{path}: its weights cannot be loaded ({str(exc)[:200]}): {fix}"
        ) from None
    return net


def pick_device(requested: str = "auto") -> torch.device:
    if requested == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if requested == "cuda" and not torch.cuda.is_available():
        raise ValueError("device=cuda asked for but torch sees no CUDA device; use device=cpu")
    return torch.device(requested)


class Planner:
    """A trained network plus decoding (Eq. 3) and ranking (Eqs. 7–10)."""

    # The parts ``plan`` runs after the network: one image's raw output → its cells above a
    # threshold; the second tier's predictions; one tier's candidates, scored and sorted. (The
    # bench's reference planner puts its own implementations here.)
    decode_cells = staticmethod(decode_output)  # (raw, threshold, image_size)
    fallback_tier = staticmethod(second_chance)  # (predictions, threshold, fallback_threshold)
    rank_tier = staticmethod(rank_grasps)  # (predictions, depth_m, intrinsics, cfg, points_cam)

    def __init__(
        self,
        net: GraspNet,
        norm: Normalisation,
        ranking: RankingConfig,
        device: str | torch.device = "cpu",
    ) -> None:
        self.device = pick_device(device) if isinstance(device, str) else device
        self.net = net.to(self.device).eval()
        self.norm, self.ranking = norm, ranking
        self.size = net.cfg.input_size
        self.last_reason = ""  # why the last ``plan`` returned [] (NO_GRASP_REASONS), else ""
        # depth preprocessing in ``plan`` (a ``DepthFilterConfig``; None = none)
        self.depth_filter = None

    @classmethod
    def load(cls, model_dir: Path | str, device: str = "cpu") -> Planner:
        """From a training artifact folder (or a ``model.pt`` path)."""
        path = find_model_file(model_dir, MODEL_FILE, "training", "models/train", "train")
        what = "grasp planner model (model.pt of `python -m pipeline.stages.train`)"
        blob = read_model_file(path, MODEL_KEYS, what, RETRAIN_FIX)
        net = build_from_blob(
            path,
            RETRAIN_FIX,
            lambda: GraspNet(NetworkConfig(**blob["network"])),
            blob["state_dict"],
        )
        norm, ranking = config_from_blob(
            path,
            RETRAIN_FIX,
            "normalisation/ranking",
            lambda: (Normalisation(**blob["normalisation"]), RankingConfig(**blob["ranking"])),
        )
        return cls(net, norm, ranking, device)

    def _check(self, depth_m: np.ndarray, batch: bool = True) -> np.ndarray:
        """``check_depth_image``: (…, S, S) (or (S, S) without ``batch``) → float32 metres,
        0 = no data (NaN, inf, ≤ 0, implausible depths)."""
        return check_depth_image(
            depth_m,
            (self.size, self.size),
            allow_batch=batch,
            name="depth_m",
            shape_source="the network's input size",
        )

    @torch.no_grad()
    def predict(self, depth_m: np.ndarray) -> torch.Tensor:
        """(B, H, W) or (H, W) depth, metres, 0 = no data → raw output (B, 2 + C, N, N), CPU.

        Bad values are sanitised and bad shapes/dtypes rejected as in ``plan``; an empty batch
        (0, H, W) gives an empty (0, 2 + C, N, N) output."""
        depth_m = self._check(depth_m)
        batch = depth_m.reshape(-1, 1, self.size, self.size)
        if batch.shape[0] == 0:
            cfg = self.net.cfg
            return torch.zeros((0, 2 + cfg.num_classes, cfg.grid, cfg.grid))
        x = torch.from_numpy(normalise_depth(batch, self.norm)).to(self.device)
        return self.net(x).float().cpu()

    def plan(
        self, depth_m: np.ndarray, intrinsics: Intrinsics, fallback_threshold: float | None = None
    ) -> list[GraspCandidate]:
        """One (H, W) depth image, metres → candidates sorted by J (Eq. 7), G_opt first.

        ``fallback_threshold`` (not the paper; ``evaluate.dcnn_fallback_ratio`` in the closed
        loop): when given and below th, the candidates of Eq. 3 are followed by a second tier,
        sorted
        by J among themselves: the cells Eq. 3 drops whose most probable class other than NG
        has a probability above it (``decode.second_chance``), as that class. A caller that
        executes the first candidate a check accepts thus reaches the second tier only when
        no candidate of Eq. 3 passes. None (default): Eq. 3 alone, as in Tables 1 and 2.

        NaN, ±inf, ≤ 0 and implausible depths are no data (``check_depth_image``); a wrong
        shape (also one that differs from ``intrinsics``), ndim or a non-float dtype raises a
        ``ValueError``. Then ``self.depth_filter``'s preprocessing, if set (hole filling,
        median; ``pipeline.camera.depth_filter``). Every candidate's nearest pixel has data.
        ``[]`` = no grasp, with the reason in ``self.last_reason``: ``"no_valid_depth"`` (the
        image has no data at all: the network is not run), ``"no_prediction"`` (no cell above
        th that is not NG, e.g. an empty bin), ``"no_rankable_candidate"`` (every prediction
        lacked data or a normal).
        """
        depth_m = preprocess_depth(self._check(depth_m, batch=False), self.depth_filter)
        if (intrinsics.height, intrinsics.width) != depth_m.shape:
            raise ValueError(
                f"intrinsics are for {intrinsics.width} x {intrinsics.height} "
                f"images, the depth image is {depth_m.shape[1]} x "
                f"{depth_m.shape[0]}: pass the intrinsics of this image"
            )
        self.last_reason = ""
        if not (depth_m > 0).any():
            self.last_reason = NO_VALID_DEPTH
            return []
        raw = self.predict(depth_m)[0]
        th = self.ranking.threshold
        second = fallback_threshold is not None and float(fallback_threshold) < th
        floor = float(fallback_threshold) if second else th
        preds = self.decode_cells(raw, floor, self.size)
        # A (pathological) non-finite offset has no pixel: drop it before rounding.
        preds = [p for p in preds if math.isfinite(p.u) and math.isfinite(p.v)]
        first = [p for p in preds if p.probability > th and p.grasp_class != GraspClass.NG]
        tiers = [(first, self.ranking)]
        if second:
            tiers.append(
                (
                    self.fallback_tier(preds, th, floor),
                    dataclasses.replace(self.ranking, threshold=floor),
                )
            )
        if not any(preds for preds, _ in tiers):
            self.last_reason = NO_PREDICTION
            return []
        points = backproject(depth_m, intrinsics)  # once for both tiers
        ranked = []
        for tier, (preds, ranking) in enumerate(tiers):
            for c in self.rank_tier(preds, depth_m, intrinsics, ranking, points):
                if _has_data(depth_m, c.u, c.v):
                    c.second_tier = tier > 0  # a new candidate of rank_grasps: set in place
                    ranked.append(c)
        if not ranked:
            self.last_reason = NO_RANKABLE_CANDIDATE
        return ranked


def _has_data(depth_m: np.ndarray, u: float, v: float) -> bool:
    """Whether the pixel nearest (u, v) (as ``rank_grasps`` picks it) has depth data."""
    H, W = depth_m.shape
    return bool(depth_m[min(max(round(v), 0), H - 1), min(max(round(u), 0), W - 1)] > 0)


def ranking_config(cfg, threshold: float) -> RankingConfig:
    """The ranking config of a pipeline config (``train.ranking``, its angles in degrees) with
    th = ``threshold`` (the training stage's calibrated or fixed value,
    ``pipeline.planner.calibration``) and D_ground (``pipeline.camera.geometry.ground_distance``,
    Eq. 9)."""
    r = cfg.train.ranking
    return from_section(
        RankingConfig,
        r,
        d_ground=ground_distance(cfg.camera, cfg.bin),
        threshold=float(threshold),
        phi_switch=math.radians(float(r.phi_switch_deg)),
        inclination_tie=math.radians(float(r.inclination_tie_deg)),
    )


def fallback_threshold(cfg, threshold: float) -> float | None:
    """The floor of ``Planner.plan``'s second tier in the closed loop:
    ``evaluate.dcnn_fallback_ratio`` × th (``threshold``); None when the ratio is null (off)."""
    ratio = cfg.evaluate.dcnn_fallback_ratio
    return None if ratio is None else float(ratio) * float(threshold)


def ranking_dict(r: RankingConfig) -> dict:
    return dataclasses.asdict(r)
