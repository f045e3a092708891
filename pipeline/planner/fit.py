"""The DCNN's training loop (paper Sec. 6): epochs, validation loss, checkpoints, resuming.

The training stage (``pipeline.stages.train``) resolves its inputs and writes the artifact; this
module trains. :class:`Trainer` holds what every step needs (the rank's context, the device,
the network and loss configs, the schedule, the batch size and seed) and runs the epochs:
:meth:`Trainer.fit` stops by ``should_stop`` (validation-based stopping) and calls back after
every epoch, where rank 0 validates and checkpoints (:func:`save_checkpoint`).

Determinism: an epoch's data order and flips come from (seed, epoch) (``planner.data``), the
learning rate is a pure function of the global step (``planner.schedule``), and checkpoints are
written with their dict keys interned, so a resumed run writes the same bytes as an
uninterrupted one.
"""

from __future__ import annotations

import math
import os
import pickle
import re
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import torch
from tqdm import tqdm

from pipeline.artifacts.store import ArtifactError
from pipeline.planner import distributed
from pipeline.planner.data import GraspDataset, epoch_batches, make_loader
from pipeline.planner.loss import LossConfig, grasp_loss
from pipeline.planner.network import GraspNet, NetworkConfig
from pipeline.planner.numerics import set_training_numerics
from pipeline.planner.schedule import ScheduleConfig, learning_rate
from pipeline.planner.scoring import EVAL_BATCH

HISTORY_KEYS = ("train_loss", "val_loss", "step_total", "step_coord", "step_class")


def new_history() -> dict:
    """Empty loss history: per epoch (train_loss, val_loss) and per step (step_*)."""
    return {k: [] for k in HISTORY_KEYS}


def _interned(obj):
    """``obj`` with every dict key string interned. Pickle shares equal strings by identity, so
    otherwise a checkpoint's bytes would depend on whether its optimiser state and history were
    built in this process or loaded from a checkpoint (a resumed run)."""
    if isinstance(obj, dict):
        return {sys.intern(k) if type(k) is str else k: _interned(v) for k, v in obj.items()}
    if isinstance(obj, list):
        return [_interned(v) for v in obj]
    return obj


def save_atomic(obj, path: Path) -> None:
    """``torch.save`` to ``path`` through a ``.part`` file and a rename (no half-written file)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".part")
    torch.save(_interned(obj), tmp)
    os.replace(tmp, path)


def cpu_state(module_or_opt) -> dict:
    """A module's or optimiser's state dict with every tensor copied to the CPU."""
    state = module_or_opt.state_dict()

    def to_cpu(v):
        if isinstance(v, torch.Tensor):
            return v.detach().cpu().clone()
        if isinstance(v, dict):
            return {k: to_cpu(x) for k, x in v.items()}
        if isinstance(v, list):
            return [to_cpu(x) for x in v]
        return v

    return to_cpu(state)


@torch.no_grad()
def evaluate_loss(net, data: GraspDataset, loss_cfg: LossConfig, device) -> float:
    """Mean per-image loss over a split (eval mode)."""
    if len(data) == 0:
        return float("nan")
    net.eval()
    total = 0.0
    for start in range(0, len(data), EVAL_BATCH):
        idx = list(range(start, min(start + EVAL_BATCH, len(data))))
        x, targets = data.batch(idx)
        loss = grasp_loss(net(x.to(device)), targets, loss_cfg)
        total += float(loss["total"]) * len(idx)
    return total / len(data)


def best_epoch(val_loss: list[float]) -> int | None:
    """1-based epoch of the lowest validation loss (the first of equal ones); None when there is
    none (no validation images: every loss is NaN)."""
    finite = [(v, e) for e, v in enumerate(val_loss, 1) if math.isfinite(v)]
    return min(finite)[1] if finite else None


def should_stop(val_loss: list[float], patience: int) -> bool:
    """Validation-based stopping: ``patience`` epochs have passed without a lower validation loss
    than the best one. ``patience`` 0: never (train every epoch of ``train.epochs``)."""
    best = best_epoch(val_loss)
    return patience > 0 and best is not None and len(val_loss) - best >= patience


def load_resume(ckpt_path: Path, net, opt, epochs: int) -> tuple[dict | None, int]:
    """(history, epoch) of a resumable checkpoint, loaded into ``net`` and ``opt``; else (None, 0).

    No file, or one past ``epochs``: (None, 0), training starts at epoch 0. A file that cannot be
    used (truncated, not a torch checkpoint, pickled objects other than tensors and plain data,
    which ``torch.load(weights_only=True)`` refuses to unpickle, or the weights or optimiser
    state of another network) raises ``ArtifactError`` naming the file and the fix (delete its
    ``.resume-*`` folder), rather than being ignored: training from scratch would silently
    overwrite it, and such a file was not written by this stage. ``train.force=true`` does not
    help: it recomputes the artifact but still resumes from the checkpoint.
    """
    if not ckpt_path.is_file():
        return None, 0

    def refuse(reason: str) -> ArtifactError:
        return ArtifactError(
            f"[train] cannot resume from {ckpt_path}: {reason}. Fix: delete the folder "
            f"{ckpt_path.parent} (`rm -r {ckpt_path.parent}`) to train from epoch 0 "
            "(train.force=true alone does not: it still resumes from this file)."
        )

    try:
        ckpt = torch.load(ckpt_path, map_location="cpu", weights_only=True)
    except Exception as e:  # truncated, empty, not a torch file, or refused by weights_only
        text = str(e).split("WeightsUnpickler error:")[-1]
        lines = [line.strip() for line in text.splitlines() if line.strip()] or [""]
        blocked = re.search(r"GLOBAL\s+([\w.]+)", text)
        if isinstance(e, pickle.UnpicklingError) and blocked:
            raise refuse(
                "it holds pickled objects other than tensors and plain data, which "
                f"torch.load(weights_only=True) refuses to load (it asks for "
                f"{blocked.group(1)})"
            ) from None
        raise refuse(
            f"it is not a readable torch checkpoint (truncated or not written by "
            f"torch.save: {type(e).__name__}: {lines[0].split('. ')[0][:160]})"
        ) from None
    keys = ("model", "optimizer", "epoch", "history")
    if (
        not isinstance(ckpt, dict)
        or not all(k in ckpt for k in keys)
        or not isinstance(ckpt["epoch"], int)
    ):
        raise refuse(f"it is not a training checkpoint (expected a dict with {', '.join(keys)})")
    if ckpt["epoch"] > epochs:
        return None, 0
    try:
        net.load_state_dict(ckpt["model"])
        opt.load_state_dict(ckpt["optimizer"])
    except (RuntimeError, ValueError, KeyError, TypeError, AttributeError) as e:
        detail = " ".join(line.strip() for line in str(e).splitlines()[:2])[:240]
        raise refuse(f"its weights or optimiser state are of another network ({detail})") from None
    return ckpt["history"], int(ckpt["epoch"])


@dataclass
class Trainer:
    """What every training step needs; the same on every rank of a data-parallel run.

    Attributes:
        ctx: the rank's place in a data-parallel run (``planner.distributed``).
        device: where the network runs (after ``distributed.init``).
        net_cfg, loss_cfg, schedule: the network, the loss (Eqs. 4-6) and the learning rate.
        batch: the global batch, images (split across the ranks).
        epochs: the epoch budget; patience: validation-based stopping (0: never stop early).
        seed: weights from ``torch.manual_seed(seed)``, data order from (seed, epoch).
        augment_flip: the mirror augmentation (``planner.augment.FLIPS``).
        loader_workers, num_threads: decoding processes and torch threads (per node).
        betas: Adam's betas.
        channels_last: the same arithmetic in another memory layout (faster on CPU).
        progress: show a progress bar per epoch.
    """

    ctx: distributed.DistContext
    device: torch.device
    net_cfg: NetworkConfig
    loss_cfg: LossConfig
    schedule: ScheduleConfig
    batch: int
    epochs: int
    patience: int
    seed: int
    augment_flip: str
    loader_workers: int
    num_threads: int
    betas: tuple[float, float]
    channels_last: bool
    progress: bool

    @property
    def memory_format(self) -> torch.memory_format:
        return torch.channels_last if self.channels_last else torch.contiguous_format

    def build(self) -> tuple[GraspNet, torch.optim.Adam]:
        """Deterministic torch state, the network and Adam: the same on every rank."""
        set_training_numerics(self.device.type)
        torch.set_num_threads(max(1, self.num_threads // self.ctx.local_world_size))
        torch.manual_seed(self.seed)
        net = GraspNet(self.net_cfg).to(self.device, memory_format=self.memory_format)
        opt = torch.optim.Adam(
            net.parameters(),
            lr=self.schedule.lr,  # set before every step
            betas=self.betas,
        )
        return net, opt

    def _parallel(self, net: GraspNet) -> torch.nn.Module:
        """The network as the ranks train it (DDP when there are several)."""
        if not self.ctx.active:
            return net
        if self.device.type == "cuda":
            net = torch.nn.SyncBatchNorm.convert_sync_batchnorm(net)
        return torch.nn.parallel.DistributedDataParallel(
            net, device_ids=[self.device.index] if self.device.type == "cuda" else None
        )

    def fit(
        self,
        net: GraspNet,
        opt,
        train_set: GraspDataset,
        history: dict,
        start_epoch: int,
        end_of_epoch: Callable[[int], None],
    ) -> tuple[int, float]:
        """Epochs ``start_epoch..epochs-1``; ``end_of_epoch(epoch)`` after each (rank 0 validates
        and checkpoints there). Returns (images trained on here, training seconds)."""
        model = self._parallel(net)
        images_done, train_s = 0, 0.0
        total_steps = self.epochs * math.ceil(len(train_set) / self.batch)  # one per global batch
        for epoch in range(start_epoch, self.epochs):
            stop = should_stop(history["val_loss"], self.patience) if self.ctx.is_main else None
            if distributed.broadcast(self.ctx, stop):
                break
            t_epoch = time.perf_counter()
            history["train_loss"].append(
                self.train_epoch(model, opt, train_set, history, epoch, total_steps)
            )
            train_s += time.perf_counter() - t_epoch
            images_done += len(train_set)
            end_of_epoch(epoch)
        return images_done, train_s

    def train_epoch(
        self,
        model: torch.nn.Module,
        opt,
        train_set: GraspDataset,
        history: dict,
        epoch: int,
        total_steps: int,
    ) -> float:
        """One pass over the training set; appends the per-step losses to ``history`` and
        returns the epoch's mean training loss per image."""
        n = len(train_set)
        batches, weights = epoch_batches(
            n, self.batch, self.seed, epoch, self.augment_flip, self.ctx
        )
        loader = make_loader(train_set, batches, self.loader_workers)
        model.train()
        running = 0.0
        bar = tqdm(
            zip(loader, weights),
            total=len(batches),
            unit="batch",
            desc=f"train epoch {epoch + 1}/{self.epochs}",
            disable=not self.progress,
        )
        for s, ((x, targets), weight) in enumerate(bar):
            for group in opt.param_groups:
                group["lr"] = learning_rate(epoch * len(batches) + s, total_steps, self.schedule)
            loss = grasp_loss(
                model(x.to(self.device, memory_format=self.memory_format)), targets, self.loss_cfg
            )
            if not torch.isfinite(loss["total"]):
                raise FloatingPointError(
                    f"loss is {float(loss['total'])} at epoch {epoch + 1} "
                    f"step {s}; lower train.lr or check the labels"
                )
            opt.zero_grad(set_to_none=True)
            (loss["total"] * weight if self.ctx.active else loss["total"]).backward()
            opt.step()
            values = distributed.all_mean(
                self.ctx,
                [float(loss[k].detach()) for k in ("total", "coord", "class")],
                weight,
                self.device,
            )
            for key, v in zip(("step_total", "step_coord", "step_class"), values):
                history[key].append(v)
            running += values[0] * min(self.batch, n - s * self.batch)
            bar.set_postfix(loss=f"{values[0]:.4f}")
        bar.close()
        return running / n


def save_checkpoint(path: Path, net, opt, config: dict, epoch: int, history: dict) -> None:
    """The resumable checkpoint after ``epoch`` (0-based): weights, Adam state, the run's config
    (without paths and logging: where a run writes and how it logs do not change the model, and
    the file must not depend on them), the epoch count, the history and the last losses."""
    save_atomic(
        {
            "model": cpu_state(net),
            "optimizer": cpu_state(opt),
            "config": config,
            "epoch": epoch + 1,
            "history": history,
            "metrics": {
                "train_loss": history["train_loss"][-1],
                "val_loss": history["val_loss"][-1],
            },
        },
        path,
    )
