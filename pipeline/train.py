"""The training stage (paper Sec. 4.1, Sec. 6): the grasp-point DCNN on a label artifact.

    python -m pipeline.train experiment=smoke [train.label_version=<version>] [train.epochs=2]

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

Several processes: ``torchrun --nproc_per_node=N -m pipeline.train`` (``make train NPROC=N``)
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
import math
import os
import pickle
import re
import sys
import time
from pathlib import Path

import hydra
import numpy as np
import torch
from omegaconf import DictConfig, OmegaConf
from tqdm import tqdm

from pipeline.artifacts import compute_version, load_manifest, resolve_artifact, run_stage, stage_config
from pipeline.artifacts.csvfile import write_rows
from pipeline.artifacts.store import ArtifactError, StageRun
from pipeline.camera.geometry import backproject
from pipeline.cli import CONF_DIR, data_root, stage_main
from pipeline.dataset.labels import LabelSet
from pipeline.labelling.types import CLASS_COLORS, GraspClass
from pipeline.planner.augment import FLIPS
from pipeline.planner.calibration import choose_threshold, threshold_curve
from pipeline.planner import distributed
from pipeline.planner.data import GraspDataset, epoch_batches, make_loader
from pipeline.planner.normalisation import normalisation
from pipeline.planner.evaluate import downsample_curve
from pipeline.planner.loss import LossConfig, grasp_loss, loss_config
from pipeline.planner.network import GraspNet, count_flops, count_parameters, network_config
from pipeline.planner.numerics import set_training_numerics
from pipeline.planner.planner import MODEL_FILE, Planner, pick_device, ranking_config
from pipeline.planner.schedule import learning_rate, schedule_config
from pipeline.planner.scoring import EVAL_BATCH, ranked_images, table1
from pipeline.tracking import StageLog

STAGE = "train"
SECTIONS = ("seed", "model", "train", "camera", "bin", "hand")
NOT_AFFECTING_RESULT = ("train.label_version", "train.force", "train.device", "train.log_samples",
                        "train.loader_workers")
CHECKPOINT = "checkpoint.pt"
BEST = "best.pt"  # in the resume folder: the weights of the epoch with the lowest val loss
RESUME_PREFIX = ".resume-"


def _interned(obj):
    """``obj`` with every dict key string interned. Pickle shares equal strings by identity, so
    otherwise a checkpoint's bytes would depend on whether its optimiser state and history were
    built in this process or loaded from a checkpoint (a resumed run)."""
    if isinstance(obj, dict):
        return {sys.intern(k) if type(k) is str else k: _interned(v) for k, v in obj.items()}
    if isinstance(obj, list):
        return [_interned(v) for v in obj]
    return obj


def _save_atomic(obj, path: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".part")
    torch.save(_interned(obj), tmp)
    os.replace(tmp, path)


def _cpu_state(module_or_opt) -> dict:
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


def _log_history(log: StageLog, history: dict, steps_per_epoch: int) -> None:
    for step, (t, c, k) in enumerate(zip(history["step_total"], history["step_coord"],
                                         history["step_class"])):
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


def _log_samples(log: StageLog, planner: Planner, data: GraspDataset, count: int,
                 start_ns: int) -> None:
    """Test images with the planner's ranked candidates (coloured by class) and the truth."""
    for k in range(min(count, len(data))):
        depth = data.depth_m(k)
        log.set_time(sequences={"sample": k}, clock_ns=start_ns + k * 1_000_000_000)
        log.log_depth("samples/camera/depth", depth)
        points = backproject(depth, data.intrinsics)  # (H, W, 3) camera frame

        def at(uv):
            uv = np.asarray(uv, np.float64).reshape(-1, 2)
            u = np.clip(np.round(uv[:, 0]).astype(int), 0, depth.shape[1] - 1)
            v = np.clip(np.round(uv[:, 1]).astype(int), 0, depth.shape[0] - 1)
            return points[v, u].astype(np.float32)

        cands = planner.plan(depth, data.intrinsics)
        colors = np.array([CLASS_COLORS[c.grasp_class] for c in cands], np.uint8).reshape(-1, 3)
        log.log_points("samples/camera/predicted", at([[c.u, c.v] for c in cands]), colors)
        rows = data.rows[k]
        gt_colors = np.array([CLASS_COLORS[GraspClass(int(c))] for c in rows["grasp_class"]],
                             np.uint8).reshape(-1, 3)
        log.log_points("samples/camera/ground_truth", at(rows["uv"]), gt_colors)
        best = (f"G_opt = ({cands[0].u:.0f}, {cands[0].v:.0f}) {cands[0].grasp_class.name} "
                f"J = {cands[0].score:.3f}") if cands else "no candidate"
        log.log_text("log", f"test image {k}: {len(cands)} candidates; {best}")


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


def _load_resume(ckpt_path: Path, net, opt, epochs: int) -> tuple[dict | None, int]:
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
            "(train.force=true alone does not: it still resumes from this file).")

    try:
        ckpt = torch.load(ckpt_path, map_location="cpu", weights_only=True)
    except Exception as e:  # truncated, empty, not a torch file, or refused by weights_only
        text = str(e).split("WeightsUnpickler error:")[-1]
        lines = [line.strip() for line in text.splitlines() if line.strip()] or [""]
        blocked = re.search(r"GLOBAL\s+([\w.]+)", text)
        if isinstance(e, pickle.UnpicklingError) and blocked:
            raise refuse("it holds pickled objects other than tensors and plain data, which "
                         f"torch.load(weights_only=True) refuses to load (it asks for "
                         f"{blocked.group(1)})") from None
        raise refuse(f"it is not a readable torch checkpoint (truncated or not written by "
                     f"torch.save: {type(e).__name__}: {lines[0].split('. ')[0][:160]})") from None
    keys = ("model", "optimizer", "epoch", "history")
    if not isinstance(ckpt, dict) or not all(k in ckpt for k in keys) \
            or not isinstance(ckpt["epoch"], int):
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


def train(cfg: DictConfig) -> Path | None:
    """Train the DCNN on a label artifact; returns the training artifact folder.

    Under ``torchrun`` (``pipeline.planner.distributed``) every rank trains on its part of each
    batch; rank 0 alone validates, checkpoints and writes the artifact, and the other ranks
    return None.
    """
    ctx = distributed.from_env()
    label_dir = resolve_artifact(data_root(cfg), "label", cfg.train.label_version, verify=True,
                                 key="train.label_version")
    gen_version = (load_manifest(label_dir).get("upstream") or {}).get("generate")
    try:
        gen_dir = resolve_artifact(data_root(cfg), "generate", str(gen_version), verify=True)
    except ArtifactError as e:
        raise ArtifactError(
            f"[train] the label artifact {label_dir.name} (train.label_version) was made from the "
            f"generation artifact {gen_version}: {e} Or pick another label artifact with "
            "train.label_version=<version>.") from None
    if cfg.train.augment_flip not in FLIPS:
        raise ValueError(f"train.augment_flip={cfg.train.augment_flip!r}; choose one of {FLIPS}")
    device = pick_device(cfg.train.device)
    config = stage_config(cfg, SECTIONS, NOT_AFFECTING_RESULT)
    config["train"]["device_type"] = device.type
    if ctx.active:  # data-parallel results differ slightly from one process's (see distributed)
        config["train"]["world_size"] = ctx.world_size
    upstream = {"label": label_dir.name, "generate": gen_dir.name}
    version = compute_version(STAGE, config, upstream)
    schedule = schedule_config(cfg)  # validated before it names the resume folder
    resume_config = copy.deepcopy(config)
    # Neither the epoch budget, the stopping rule nor th changes an epoch's weights (the epoch
    # budget does when the rate follows a schedule over the whole run).
    for key in (("epochs",) if schedule.name == "constant" else ()) + (
            "patience", "threshold", "threshold_grid"):
        resume_config["train"].pop(key)
    resume_dir = Path(cfg.paths.models) / STAGE / (RESUME_PREFIX + compute_version(
        STAGE + "-resume", resume_config, upstream, code_of=STAGE))
    ckpt_path, best_path = resume_dir / CHECKPOINT, resume_dir / BEST
    cache_dir = data_root(cfg) / ".cache" / "depth" / gen_dir.name
    seed, tc = int(cfg.seed), cfg.train
    progress = bool(cfg.logging.progress) and ctx.is_main
    net_cfg, norm = network_config(cfg), normalisation(cfg)
    loss_cfg = loss_config(cfg)
    batch = int(tc.batch_size)
    # channels_last: the same arithmetic in another memory layout (faster convolutions on CPU).
    memory_format = torch.channels_last if bool(tc.channels_last) else torch.contiguous_format
    if batch < ctx.world_size:
        raise ValueError(f"train.batch_size={batch} is smaller than the {ctx.world_size} "
                         "processes: each needs at least one image of every batch")

    def dataset(split: str) -> GraspDataset:
        return GraspDataset(gen_dir, LabelSet(label_dir, split), split, norm, net_cfg.grid,
                            cfg.hand, int(tc.max_train_images) if split == "train" else 0,
                            cache_dir=cache_dir)

    def setup():
        """Deterministic torch state, the network and Adam: the same on every rank."""
        set_training_numerics(device.type)
        torch.set_num_threads(max(1, int(tc.num_threads) // ctx.local_world_size))
        torch.manual_seed(seed)
        net = GraspNet(net_cfg).to(run_device, memory_format=memory_format)
        opt = torch.optim.Adam(net.parameters(), lr=schedule.lr,  # set before every step
                               betas=tuple(float(b) for b in tc.betas))
        return net, opt

    def fit(net, opt, train_set: GraspDataset, history: dict, start_epoch: int,
            end_of_epoch) -> tuple[int, float]:
        """Epochs ``start_epoch..epochs-1``; ``end_of_epoch(epoch)`` after each (rank 0)."""
        model = net
        if ctx.active:
            if run_device.type == "cuda":
                model = torch.nn.SyncBatchNorm.convert_sync_batchnorm(model)
            model = torch.nn.parallel.DistributedDataParallel(
                model, device_ids=[run_device.index] if run_device.type == "cuda" else None)
        images_done, train_s = 0, 0.0
        n = len(train_set)
        total_steps = int(tc.epochs) * math.ceil(n / batch)  # one per global batch
        for epoch in range(start_epoch, int(tc.epochs)):
            if distributed.broadcast(ctx, should_stop(history["val_loss"], int(tc.patience))
                                     if ctx.is_main else None):
                break
            batches, weights = epoch_batches(n, batch, seed, epoch, tc.augment_flip, ctx)
            loader = make_loader(train_set, batches, int(tc.loader_workers))
            model.train()
            t_epoch = time.perf_counter()
            running = 0.0
            bar = tqdm(zip(loader, weights), total=len(batches), unit="batch",
                       desc=f"train epoch {epoch + 1}/{tc.epochs}", disable=not progress)
            for s, ((x, targets), weight) in enumerate(bar):
                for group in opt.param_groups:
                    group["lr"] = learning_rate(epoch * len(batches) + s, total_steps, schedule)
                loss = grasp_loss(model(x.to(run_device, memory_format=memory_format)), targets,
                                  loss_cfg)
                if not torch.isfinite(loss["total"]):
                    raise FloatingPointError(f"loss is {float(loss['total'])} at epoch {epoch + 1}"
                                             f" step {s}; lower train.lr or check the labels")
                opt.zero_grad(set_to_none=True)
                (loss["total"] * weight if ctx.active else loss["total"]).backward()
                opt.step()
                values = distributed.all_mean(
                    ctx, [float(loss[k].detach()) for k in ("total", "coord", "class")], weight,
                    run_device)
                for key, v in zip(("step_total", "step_coord", "step_class"), values):
                    history[key].append(v)
                running += values[0] * min(batch, n - s * batch)
                bar.set_postfix(loss=f"{values[0]:.4f}")
            bar.close()
            train_s += time.perf_counter() - t_epoch
            images_done += n
            history["train_loss"].append(running / n)
            end_of_epoch(epoch)
        return images_done, train_s

    run_device = distributed.init(ctx, device)
    try:
        if not ctx.is_main:
            start_epoch = distributed.broadcast(ctx, None)
            if start_epoch is None:  # rank 0 found the artifact or failed before training
                return None
            net, opt = setup()
            history, loaded = (_load_resume(ckpt_path, net, opt, int(tc.epochs))
                               if start_epoch else (None, 0))
            if loaded != start_epoch:
                raise FileNotFoundError(
                    f"rank {ctx.rank} cannot read the checkpoint {ckpt_path} that rank 0 resumes "
                    f"from at epoch {start_epoch}: paths.models must be one filesystem shared by "
                    "every node")
            distributed.barrier(ctx)  # rank 0 has built the depth cache
            fit(net, opt, dataset("train"), history or _new_history(), start_epoch,
                lambda epoch: None)
            return None

        started = False

        def body(run: StageRun) -> None:
            nonlocal started
            net, opt = setup()
            history, start_epoch = _load_resume(ckpt_path, net, opt, int(tc.epochs))
            history = history or _new_history()
            if start_epoch:
                print(f"train: resuming from {ckpt_path} at epoch {start_epoch}")
            started = True
            distributed.broadcast(ctx, start_epoch)
            t0 = time.perf_counter()
            sets = {split: dataset(split) for split in ("train", "val", "test")}
            run.timings["load_s"] = round(time.perf_counter() - t0, 3)
            distributed.barrier(ctx)
            train_set = sets["train"]
            if len(train_set) == 0:
                raise ValueError("the label artifact has no training images")

            def end_of_epoch(epoch: int) -> None:
                history["val_loss"].append(evaluate_loss(net, sets["val"], loss_cfg, run_device))
                if best_epoch(history["val_loss"]) == epoch + 1:  # before the checkpoint: a
                    # resume re-runs an epoch whose checkpoint is missing, and rewrites this
                    _save_atomic({"model": _cpu_state(net), "epoch": epoch + 1}, best_path)
                _save_atomic({"model": _cpu_state(net), "optimizer": _cpu_state(opt),
                              # Without paths and logging: where a run writes and how it logs
                              # do not change the model, and the file must not depend on them.
                              "config": {k: v for k, v in OmegaConf.to_container(cfg, resolve=True)
                                         .items() if k not in ("paths", "logging")},
                              "epoch": epoch + 1, "history": history,
                              "metrics": {"train_loss": history["train_loss"][-1],
                                          "val_loss": history["val_loss"][-1]}}, ckpt_path)
                print(f"train: epoch {epoch + 1}/{tc.epochs} train loss "
                      f"{history['train_loss'][-1]:.4f} val loss {history['val_loss'][-1]:.4f}")

            images_done, train_s = fit(net, opt, train_set, history, start_epoch, end_of_epoch)
            _finish(run, net, sets, history, images_done, train_s, start_epoch)

        def _finish(run: StageRun, net, sets, history, images_done, train_s, start_epoch) -> None:
            steps_per_epoch = math.ceil(len(sets["train"]) / batch)
            # The model is the epoch with the lowest validation loss (validation-based stopping).
            chosen = best_epoch(history["val_loss"]) or len(history["train_loss"])
            if chosen != len(history["train_loss"]):
                best = torch.load(best_path, map_location="cpu", weights_only=True) \
                    if best_path.is_file() else {}
                if best.get("epoch") != chosen:
                    raise ArtifactError(
                        f"[train] {best_path} does not hold epoch {chosen}, the epoch with the "
                        f"lowest validation loss: delete {resume_dir} and train again")
                net.load_state_dict(best["model"])
            # th of Eq. 3: calibrated on the validation split, or fixed by train.threshold.
            grid = sorted(float(t) for t in tc.threshold_grid)
            if not grid:
                raise ValueError("train.threshold_grid is empty: list the th values to calibrate "
                                 "over, e.g. train.threshold_grid=[0.1,0.2,0.3]")
            planner = Planner(net, norm, ranking_config(cfg, grid[0]), run_device)
            t1 = time.perf_counter()
            th_curve = threshold_curve(ranked_images(planner, sets["val"], progress,
                                                      desc="train: calibrating th on val"), grid,
                                       float(tc.match_radius_px))
            threshold = (choose_threshold(th_curve) if tc.threshold is None
                         else float(tc.threshold))
            run.timings["calibration_s"] = round(time.perf_counter() - t1, 3)
            planner.ranking = ranking_config(cfg, threshold)
            write_rows(run.work_dir / "threshold_curve.csv",
                       [{k: (round(v, 6) if isinstance(v, float) else v) for k, v in r.items()}
                        for r in th_curve])
            model_blob = {"state_dict": _cpu_state(net), "network": dataclasses.asdict(net_cfg),
                          "normalisation": norm.as_dict(),
                          "ranking": dataclasses.asdict(planner.ranking),
                          "classes": [c.name for c in GraspClass]}
            torch.save(model_blob, run.work_dir / MODEL_FILE)
            if ckpt_path.is_file():
                (run.work_dir / CHECKPOINT).write_bytes(ckpt_path.read_bytes())
            print(f"train: th = {threshold:g} "
                  f"({'calibrated on val' if tc.threshold is None else 'train.threshold'})")

            t1 = time.perf_counter()
            result = table1(planner, sets["test"], float(tc.match_radius_px))
            run.timings["test_eval_s"] = round(time.perf_counter() - t1, 3)
            curve = result.pop("pr_curve")
            with open(run.work_dir / "pr_curve.csv", "w", newline="") as f:
                w = csv.writer(f)
                w.writerow(["rank", "score", "precision", "recall"])
                for r, (sc, p, rc) in enumerate(zip(curve["score"], curve["precision"],
                                                    curve["recall"]), 1):
                    w.writerow([r, f"{sc:.6f}", f"{p:.6f}", f"{rc:.6f}"])

            lost = sum(d.lost_points for d in sets.values())
            total = sum(d.total_points for d in sets.values())
            run.metrics.update({
                "network": {"width": net_cfg.width, "parameters": count_parameters(net),
                            "macs_per_image": count_flops(net),
                            "gmacs_per_image": round(count_flops(net) / 1e9, 4)},
                "images": {s: len(d) for s, d in sets.items()},
                "one_point_per_cell": {
                    "lost_points": int(lost), "total_points": int(total),
                    "lost_fraction": round(lost / max(total, 1), 6),
                    "per_split": {s: {"lost": d.lost_points, "total": d.total_points}
                                  for s, d in sets.items()}},
                "epochs": len(history["train_loss"]),
                "max_epochs": int(tc.epochs),
                "best_epoch": chosen,
                "stopped_early": len(history["train_loss"]) < int(tc.epochs),
                "train_loss_per_epoch": [round(v, 6) for v in history["train_loss"]],
                "val_loss_per_epoch": [round(v, 6) if math.isfinite(v) else None
                                       for v in history["val_loss"]],
                "threshold": {"value": threshold,
                              "rule": "calibrated" if tc.threshold is None else "fixed",
                              "curve": [{k: (round(v, 6) if isinstance(v, float) else v)
                                         for k, v in r.items()} for r in th_curve]},
                "table1": result,
                "table1_definition": "see pipeline/planner/evaluate.py (module docstring)",
                "pr_curve": downsample_curve(curve),
                "device": device.type,
            })
            run.timings.update({
                "train_s": round(train_s, 3), "epochs_run_here": len(history["train_loss"]) - start_epoch,
                "processes": ctx.world_size, "loader_workers": int(tc.loader_workers),
                "train_images_per_s": round(images_done / train_s, 3) if train_s else None})

            with StageLog(run.work_dir, app_id=f"binpick-{STAGE}", recording_id=run.version) as log:
                _log_history(log, history, steps_per_epoch)
                end_ns = (len(history["step_total"]) + 1) * 1_000_000
                log.set_time(sequences={"epoch": len(history["train_loss"])}, clock_ns=end_ns)
                for key in ("top1", "top1pct", "top5pct", "top10pct"):
                    if result[key] is not None:
                        log.log_scalar(f"test/table1/{key}", result[key])
                _log_samples(log, planner, sets["test"], int(tc.log_samples),
                             end_ns + 1_000_000_000)

        try:
            return run_stage(Path(cfg.paths.models), STAGE, version, config, upstream, body,
                             seed=seed, force=bool(tc.force))
        finally:
            if not started:
                distributed.broadcast(ctx, None)
    finally:
        distributed.shutdown(ctx)


def _new_history() -> dict:
    return {k: [] for k in ("train_loss", "val_loss", "step_total", "step_coord", "step_class")}


@hydra.main(config_path=CONF_DIR, config_name="train", version_base="1.3")
def main(cfg: DictConfig) -> None:
    stage_main(train)(cfg)


if __name__ == "__main__":
    main()
