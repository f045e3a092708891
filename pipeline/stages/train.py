"""The training stage (paper Sec. 4.1, Sec. 6): the grasp-point DCNN on a label artifact.

    python -m pipeline.stages.train experiment=smoke [train.label_version=<version>] \
        [train.epochs=2]

Upstream: the label artifact (``train.label_version``, default latest) and the generation
artifact it names. Output: ``models/train/<version>/`` with

* ``model.pt``: the weights of the epoch with the lowest validation loss, network config, depth
  normalisation and ranking config (th, D_ground): what ``pipeline.planner.Planner.load``
  reads; ``torch.load(weights_only=True)``.
* ``checkpoint.pt``: the last checkpoint (weights, Adam state, config, epoch, history).
* ``threshold_curve.csv``: th of Eq. 3 against the validation split's figures, from which th is
  chosen (``pipeline.planner.calibration``) unless ``train.threshold`` fixes it.
* ``pr_curve.csv``: the precision–recall curve on the test split (``planner.evaluate``).
* ``log.rrd`` / ``log.mcap``: loss per step (``step`` timeline) and per epoch (``epoch``
  timeline), validation loss, Table 1, and sample test predictions on their depth images.
* manifest metrics: parameters, FLOPs (MACs), points lost to the one-point-per-cell rule,
  train/val loss per epoch, Table 1, a downsampled PR curve, training images/s.

Optimiser (Sec. 6): Adam, lr 1e-4, betas (0.9, 0.999), batch 16; loss (Eqs. 4–6): λ = 1,
α = 0.25, γ = 2. Stopping: ``train.epochs`` is a budget; training stops once ``train.patience``
epochs pass without a lower validation loss, and the model is the epoch with the lowest one
(its weights kept in the resume folder's ``best.pt``). Depth normalisation:
``pipeline.planner.data``. Augmentation: each training image mirrored at random in u, v, both
or neither (``train.augment_flip``, see ``pipeline.planner.augment``).

Determinism: weights are initialised from ``torch.manual_seed(seed)``; the data order and flips
of epoch e come from a generator seeded by (seed, e); CPU threads are fixed
(``train.num_threads``) and ``torch.use_deterministic_algorithms(True)``. Two CPU runs with the
same config write byte-identical ``model.pt``. On CUDA, max-pool backward has no deterministic
kernel, so GPU runs are repeatable only approximately (the device is part of the version).

Data: depth streams from disk (``pipeline.planner.data.DepthShards``: the generation shards,
decompressed once into ``<data>/.cache/depth/<generate version>/``) through a DataLoader with
``train.loader_workers`` decoding processes; only the label rows are held in memory, so the
``paper`` scale trains in the memory of the ``smoke`` one. The loader does not change the result.

Several processes: ``torchrun --nproc_per_node=N -m pipeline.stages.train`` (``make train NPROC=N``)
trains data-parallel (``pipeline.planner.distributed``): the same global batches split across
the processes; ``world_size`` enters the version because the result differs slightly.

Resuming: after every epoch the checkpoint is written to ``models/train/.resume-<key>/``, key =
the version without ``train.epochs``; a run that finds it continues from its epoch, so a killed
run loses at most one epoch and ``train.epochs=<more>`` extends a finished run. Because the
epoch's data order depends only on (seed, epoch) and the per-step losses live in the checkpoint,
a resumed run writes the same ``model.pt`` and logs as an uninterrupted one. The folder is kept
after success (delete it to start over).
"""

from __future__ import annotations

import copy
import csv
import dataclasses
import functools
import math
import time
from pathlib import Path

import numpy as np
import torch
from omegaconf import DictConfig, OmegaConf

from pipeline.artifacts import (
    compute_version,
    load_manifest,
    resolve_artifact,
    run_stage,
    stage_config,
)
from pipeline.artifacts.csvfile import write_rows
from pipeline.artifacts.store import ArtifactError, StageRun
from pipeline.camera.geometry import backproject
from pipeline.dataset.labels import LabelSet
from pipeline.grasping.types import CLASS_COLORS, GraspClass
from pipeline.planner import distributed
from pipeline.planner.augment import FLIPS
from pipeline.planner.calibration import choose_threshold, threshold_curve
from pipeline.planner.data import GraspDataset
from pipeline.planner.evaluate import downsample_curve
from pipeline.planner.fit import (
    Trainer,
    best_epoch,
    cpu_state,
    evaluate_loss,
    load_resume,
    new_history,
    save_atomic,
    save_checkpoint,
)
from pipeline.planner.loss import loss_config
from pipeline.planner.network import count_flops, count_parameters, network_config
from pipeline.planner.normalisation import normalisation
from pipeline.planner.planner import MODEL_FILE, Planner, pick_device, ranking_config
from pipeline.planner.schedule import schedule_config
from pipeline.planner.scoring import ranked_images, table1
from pipeline.runtime.cli import data_root, stage_command
from pipeline.runtime.stage_artifacts import upstream_artifact
from pipeline.tracking import StageLog

STAGE = "train"
SECTIONS = ("seed", "model", "train", "camera", "bin", "hand")
NOT_AFFECTING_RESULT = (
    "train.label_version",
    "train.force",
    "train.device",
    "train.log_samples",
    "train.loader_workers",
)
CHECKPOINT = "checkpoint.pt"
BEST = "best.pt"  # in the resume folder: the weights of the epoch with the lowest val loss
RESUME_PREFIX = ".resume-"


def _log_history(log: StageLog, history: dict, steps_per_epoch: int) -> None:
    for step, (t, c, k) in enumerate(
        zip(history["step_total"], history["step_coord"], history["step_class"])
    ):
        log.set_time(sequences={"step": step}, clock_ns=step * 1_000_000)
        log.log_scalar("train/step/loss", t)
        log.log_scalar("train/step/coord", c)
        log.log_scalar("train/step/class", k)
    for e, (tr, va) in enumerate(zip(history["train_loss"], history["val_loss"])):
        step = (e + 1) * steps_per_epoch
        log.set_time(sequences={"epoch": e + 1, "step": step}, clock_ns=step * 1_000_000)
        log.log_scalar("train/epoch/loss", tr)
        if math.isfinite(va):
            log.log_scalar("val/epoch/loss", va)


def _points_at(points: np.ndarray, uv) -> np.ndarray:
    """(N, 3) float32 camera-frame points of ``points`` (H, W, 3) at the pixels ``uv`` (N, 2),
    rounded and clipped to the image."""
    uv = np.asarray(uv, np.float64).reshape(-1, 2)
    u = np.clip(np.round(uv[:, 0]).astype(int), 0, points.shape[1] - 1)
    v = np.clip(np.round(uv[:, 1]).astype(int), 0, points.shape[0] - 1)
    return points[v, u].astype(np.float32)


def _log_samples(
    log: StageLog, planner: Planner, data: GraspDataset, count: int, start_ns: int
) -> None:
    """Test images with the planner's ranked candidates (coloured by class) and the truth."""
    for k in range(min(count, len(data))):
        depth = data.depth_m(k)
        log.set_time(sequences={"sample": k}, clock_ns=start_ns + k * 1_000_000_000)
        log.log_depth("samples/camera/depth", depth)
        points = backproject(depth, data.intrinsics)  # (H, W, 3) camera frame
        at = functools.partial(_points_at, points)
        cands = planner.plan(depth, data.intrinsics)
        colors = np.array([CLASS_COLORS[c.grasp_class] for c in cands], np.uint8).reshape(-1, 3)
        log.log_points("samples/camera/predicted", at([[c.u, c.v] for c in cands]), colors)
        rows = data.rows[k]
        gt_colors = np.array(
            [CLASS_COLORS[GraspClass(int(c))] for c in rows["grasp_class"]], np.uint8
        ).reshape(-1, 3)
        log.log_points("samples/camera/ground_truth", at(rows["uv"]), gt_colors)
        best = (
            (
                f"G_opt = ({cands[0].u:.0f}, {cands[0].v:.0f}) {cands[0].grasp_class.name} "
                f"J = {cands[0].score:.3f}"
            )
            if cands
            else "no candidate"
        )
        log.log_text("log", f"test image {k}: {len(cands)} candidates; {best}")


def _inputs(cfg: DictConfig) -> tuple[Path, Path]:
    """(label artifact, the generation artifact it was made from), both verified."""
    label_dir = upstream_artifact(cfg, "label", "train.label_version")
    gen_version = (load_manifest(label_dir).get("upstream") or {}).get("generate")
    try:
        gen_dir = resolve_artifact(data_root(cfg), "generate", str(gen_version), verify=True)
    except ArtifactError as e:
        raise ArtifactError(
            f"[train] the label artifact {label_dir.name} (train.label_version) was made from the "
            f"generation artifact {gen_version}: {e} Or pick another label artifact with "
            "train.label_version=<version>."
        ) from None
    if cfg.train.augment_flip not in FLIPS:
        raise ValueError(f"train.augment_flip={cfg.train.augment_flip!r}; choose one of {FLIPS}")
    return label_dir, gen_dir


def _resume_dir(cfg: DictConfig, config: dict, upstream: dict, schedule) -> Path:
    """``models/train/.resume-<key>``: the key is the version without what does not change an
    epoch's weights: the stopping rule and th, and the epoch budget (which does change them
    when the rate follows a schedule over the whole run)."""
    resume_config = copy.deepcopy(config)
    for key in (("epochs",) if schedule.name == "constant" else ()) + (
        "patience",
        "threshold",
        "threshold_grid",
    ):
        resume_config["train"].pop(key)
    return (
        Path(cfg.paths.models)
        / STAGE
        / (
            RESUME_PREFIX
            + compute_version(STAGE + "-resume", resume_config, upstream, code_of=STAGE)
        )
    )


def train(cfg: DictConfig) -> Path | None:
    """Train the DCNN on a label artifact; returns the training artifact folder.

    Under ``torchrun`` (``pipeline.planner.distributed``) every rank trains on its part of each
    batch; rank 0 alone validates, checkpoints and writes the artifact, and the other ranks
    return None.
    """
    ctx = distributed.from_env()
    label_dir, gen_dir = _inputs(cfg)
    device = pick_device(cfg.train.device)
    config = stage_config(cfg, SECTIONS, NOT_AFFECTING_RESULT)
    config["train"]["device_type"] = device.type
    if ctx.active:  # data-parallel results differ slightly from one process's (see distributed)
        config["train"]["world_size"] = ctx.world_size
    upstream = {"label": label_dir.name, "generate": gen_dir.name}
    version = compute_version(STAGE, config, upstream)
    schedule = schedule_config(cfg)  # validated before it names the resume folder
    tc = cfg.train
    batch = int(tc.batch_size)
    if batch < ctx.world_size:
        raise ValueError(
            f"train.batch_size={batch} is smaller than the {ctx.world_size} "
            "processes: each needs at least one image of every batch"
        )
    trainer = Trainer(
        ctx=ctx,
        device=distributed.init(ctx, device),
        net_cfg=network_config(cfg),
        loss_cfg=loss_config(cfg),
        schedule=schedule,
        batch=batch,
        epochs=int(tc.epochs),
        patience=int(tc.patience),
        seed=int(cfg.seed),
        augment_flip=str(tc.augment_flip),
        loader_workers=int(tc.loader_workers),
        num_threads=int(tc.num_threads),
        betas=tuple(float(b) for b in tc.betas),
        channels_last=bool(tc.channels_last),
        progress=bool(cfg.logging.progress) and ctx.is_main,
    )
    job = _TrainingRun(
        cfg, trainer, label_dir, gen_dir, _resume_dir(cfg, config, upstream, schedule)
    )
    try:
        if not ctx.is_main:
            job.follow()
            return None
        try:
            return run_stage(
                Path(cfg.paths.models),
                STAGE,
                version,
                config,
                upstream,
                job.body,
                seed=trainer.seed,
                force=bool(tc.force),
            )
        finally:
            if not job.started:
                distributed.broadcast(ctx, None)
    finally:
        distributed.shutdown(ctx)


class _TrainingRun:
    """One run of the stage: the datasets, the resume folder, training and the artifact."""

    def __init__(
        self, cfg: DictConfig, trainer: Trainer, label_dir: Path, gen_dir: Path, resume_dir: Path
    ):
        self.cfg, self.tc, self.trainer = cfg, cfg.train, trainer
        self.label_dir, self.gen_dir, self.resume_dir = label_dir, gen_dir, resume_dir
        self.ckpt_path, self.best_path = resume_dir / CHECKPOINT, resume_dir / BEST
        self.cache_dir = data_root(cfg) / ".cache" / "depth" / gen_dir.name
        self.norm = normalisation(cfg)
        self.checkpoint_config = {
            k: v
            for k, v in OmegaConf.to_container(cfg, resolve=True).items()
            if k not in ("paths", "logging")
        }
        self.started = False

    def dataset(self, split: str) -> GraspDataset:
        tc = self.tc
        return GraspDataset(
            self.gen_dir,
            LabelSet(self.label_dir, split),
            split,
            self.norm,
            self.trainer.net_cfg.grid,
            self.cfg.hand,
            int(tc.max_train_images) if split == "train" else 0,
            cache_dir=self.cache_dir,
        )

    def follow(self) -> None:
        """A rank other than 0: train on its part of every batch, from rank 0's start epoch."""
        ctx = self.trainer.ctx
        start_epoch = distributed.broadcast(ctx, None)
        if start_epoch is None:  # rank 0 found the artifact or failed before training
            return
        net, opt = self.trainer.build()
        history, loaded = (
            load_resume(self.ckpt_path, net, opt, self.trainer.epochs) if start_epoch else (None, 0)
        )
        if loaded != start_epoch:
            raise FileNotFoundError(
                f"rank {ctx.rank} cannot read the checkpoint {self.ckpt_path} that rank 0 "
                f"resumes from at epoch {start_epoch}: paths.models must be one filesystem "
                "shared by every node"
            )
        distributed.barrier(ctx)  # rank 0 has built the depth cache
        self.trainer.fit(
            net,
            opt,
            self.dataset("train"),
            history or new_history(),
            start_epoch,
            lambda epoch: None,
        )

    def body(self, run: StageRun) -> None:
        """Rank 0: resume or start, train, then write the artifact into ``run.work_dir``."""
        trainer, ctx = self.trainer, self.trainer.ctx
        net, opt = trainer.build()
        history, start_epoch = load_resume(self.ckpt_path, net, opt, trainer.epochs)
        history = history or new_history()
        if start_epoch:
            print(f"train: resuming from {self.ckpt_path} at epoch {start_epoch}")
        self.started = True
        distributed.broadcast(ctx, start_epoch)
        t0 = time.perf_counter()
        sets = {split: self.dataset(split) for split in ("train", "val", "test")}
        run.timings["load_s"] = round(time.perf_counter() - t0, 3)
        distributed.barrier(ctx)
        if len(sets["train"]) == 0:
            raise ValueError("the label artifact has no training images")

        def end_of_epoch(epoch: int) -> None:
            history["val_loss"].append(
                evaluate_loss(net, sets["val"], trainer.loss_cfg, trainer.device)
            )
            if best_epoch(history["val_loss"]) == epoch + 1:  # before the checkpoint: a
                # resume re-runs an epoch whose checkpoint is missing, and rewrites this
                save_atomic({"model": cpu_state(net), "epoch": epoch + 1}, self.best_path)
            save_checkpoint(self.ckpt_path, net, opt, self.checkpoint_config, epoch, history)
            print(
                f"train: epoch {epoch + 1}/{trainer.epochs} train loss "
                f"{history['train_loss'][-1]:.4f} val loss {history['val_loss'][-1]:.4f}"
            )

        images_done, train_s = trainer.fit(
            net, opt, sets["train"], history, start_epoch, end_of_epoch
        )
        chosen = self._best_weights(net, history)
        planner, threshold, th_curve = self._calibrate(run, net, sets["val"])
        self._write_model(run, net, planner, threshold, th_curve)
        result, curve = self._table1(run, planner, sets["test"])
        run.metrics.update(
            _metrics(
                net,
                trainer,
                sets,
                history,
                chosen,
                threshold,
                self.tc.threshold is None,
                th_curve,
                result,
                curve,
            )
        )
        run.timings.update(
            {
                "train_s": round(train_s, 3),
                "epochs_run_here": len(history["train_loss"]) - start_epoch,
                "processes": ctx.world_size,
                "loader_workers": trainer.loader_workers,
                "train_images_per_s": round(images_done / train_s, 3) if train_s else None,
            }
        )
        with StageLog.for_stage(run.work_dir, STAGE, run.version) as log:
            _log_history(log, history, math.ceil(len(sets["train"]) / trainer.batch))
            end_ns = (len(history["step_total"]) + 1) * 1_000_000
            log.set_time(sequences={"epoch": len(history["train_loss"])}, clock_ns=end_ns)
            for key in ("top1", "top1pct", "top5pct", "top10pct"):
                if result[key] is not None:
                    log.log_scalar(f"test/table1/{key}", result[key])
            _log_samples(
                log, planner, sets["test"], int(self.tc.log_samples), end_ns + 1_000_000_000
            )

    def _best_weights(self, net, history: dict) -> int:
        """Load the epoch with the lowest validation loss (validation-based stopping); its
        1-based number."""
        chosen = best_epoch(history["val_loss"]) or len(history["train_loss"])
        if chosen != len(history["train_loss"]):
            best = (
                torch.load(self.best_path, map_location="cpu", weights_only=True)
                if self.best_path.is_file()
                else {}
            )
            if best.get("epoch") != chosen:
                raise ArtifactError(
                    f"[train] {self.best_path} does not hold epoch {chosen}, the epoch with the "
                    f"lowest validation loss: delete {self.resume_dir} and train again"
                )
            net.load_state_dict(best["model"])
        return chosen

    def _calibrate(self, run: StageRun, net, val: GraspDataset) -> tuple[Planner, float, list]:
        """th of Eq. 3: calibrated on the validation split, or fixed by train.threshold; the
        planner ranks with it."""
        grid = sorted(float(t) for t in self.tc.threshold_grid)
        if not grid:
            raise ValueError(
                "train.threshold_grid is empty: list the th values to calibrate "
                "over, e.g. train.threshold_grid=[0.1,0.2,0.3]"
            )
        planner = Planner(net, self.norm, ranking_config(self.cfg, grid[0]), self.trainer.device)
        t1 = time.perf_counter()
        th_curve = threshold_curve(
            ranked_images(planner, val, self.trainer.progress, desc="train: calibrating th on val"),
            grid,
            float(self.tc.match_radius_px),
        )
        threshold = (
            choose_threshold(th_curve) if self.tc.threshold is None else float(self.tc.threshold)
        )
        run.timings["calibration_s"] = round(time.perf_counter() - t1, 3)
        planner.ranking = ranking_config(self.cfg, threshold)
        return planner, threshold, th_curve

    def _write_model(
        self, run: StageRun, net, planner: Planner, threshold: float, th_curve: list
    ) -> None:
        """``threshold_curve.csv``, ``model.pt`` and the last checkpoint into the artifact."""
        write_rows(run.work_dir / "threshold_curve.csv", _rounded(th_curve))
        model_blob = {
            "state_dict": cpu_state(net),
            "network": dataclasses.asdict(self.trainer.net_cfg),
            "normalisation": self.norm.as_dict(),
            "ranking": dataclasses.asdict(planner.ranking),
            "classes": [c.name for c in GraspClass],
        }
        torch.save(model_blob, run.work_dir / MODEL_FILE)
        if self.ckpt_path.is_file():
            (run.work_dir / CHECKPOINT).write_bytes(self.ckpt_path.read_bytes())
        print(
            f"train: th = {threshold:g} "
            f"({'calibrated on val' if self.tc.threshold is None else 'train.threshold'})"
        )

    def _table1(self, run: StageRun, planner: Planner, test: GraspDataset) -> tuple[dict, dict]:
        """Table 1 on the test split and ``pr_curve.csv``; (the table's figures, the curve)."""
        t1 = time.perf_counter()
        result = table1(planner, test, float(self.tc.match_radius_px))
        run.timings["test_eval_s"] = round(time.perf_counter() - t1, 3)
        curve = result.pop("pr_curve")
        with open(run.work_dir / "pr_curve.csv", "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["rank", "score", "precision", "recall"])
            for r, (sc, p, rc) in enumerate(
                zip(curve["score"], curve["precision"], curve["recall"]), 1
            ):
                w.writerow([r, f"{sc:.6f}", f"{p:.6f}", f"{rc:.6f}"])
        return result, curve


def _rounded(rows: list[dict]) -> list[dict]:
    return [{k: (round(v, 6) if isinstance(v, float) else v) for k, v in r.items()} for r in rows]


def _metrics(
    net,
    trainer: Trainer,
    sets: dict,
    history: dict,
    chosen: int,
    threshold: float,
    calibrated: bool,
    th_curve: list,
    result: dict,
    curve: dict,
) -> dict:
    """The manifest's metrics: the network's size, the data, the losses, th and Table 1."""
    lost = sum(d.lost_points for d in sets.values())
    total = sum(d.total_points for d in sets.values())
    return {
        "network": {
            "width": trainer.net_cfg.width,
            "parameters": count_parameters(net),
            "macs_per_image": count_flops(net),
            "gmacs_per_image": round(count_flops(net) / 1e9, 4),
        },
        "images": {s: len(d) for s, d in sets.items()},
        "one_point_per_cell": {
            "lost_points": int(lost),
            "total_points": int(total),
            "lost_fraction": round(lost / max(total, 1), 6),
            "per_split": {
                s: {"lost": d.lost_points, "total": d.total_points} for s, d in sets.items()
            },
        },
        "epochs": len(history["train_loss"]),
        "max_epochs": trainer.epochs,
        "best_epoch": chosen,
        "stopped_early": len(history["train_loss"]) < trainer.epochs,
        "train_loss_per_epoch": [round(v, 6) for v in history["train_loss"]],
        "val_loss_per_epoch": [
            round(v, 6) if math.isfinite(v) else None for v in history["val_loss"]
        ],
        "threshold": {
            "value": threshold,
            "rule": "calibrated" if calibrated else "fixed",
            "curve": _rounded(th_curve),
        },
        "table1": result,
        "table1_definition": "see pipeline/planner/evaluate.py (module docstring)",
        "pr_curve": downsample_curve(curve),
        "device": trainer.device.type,
    }


main = stage_command("train", train)


if __name__ == "__main__":
    main()
