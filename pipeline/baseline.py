"""The Dex-Net-style comparison stage (paper Sec. 6, 8.1.1, Table 2, Fig. 10).

    python -m pipeline.baseline experiment=smoke [baseline.train_version=<version>|none]

Dex-Net's weights and datasets cannot be downloaded here, so the comparison planner is built
the way Dex-Net 3.0/4.0 build theirs, on this project's own simulated heaps
(``pipeline.dexnet``; docs/baseline.md):

1. **Candidate labels** (scene-parallel, like labelling): on every train / val / test scene of
   the generation artifact, ``baseline.candidates_per_scene`` suction candidates are sampled
   on the depth image as the policy samples them, and each gets the robust quality of the
   suction contact model computed from the simulator's true box geometry, mass and centre of
   mass (``pipeline.dexnet.contact``). Quality ≥ ``suction.quality_threshold``: a positive.
2. **GQ-CNN** (``pipeline.dexnet.gqcnn``): trained on the train split's candidates (crop +
   pose → robust or not), Adam, binary cross-entropy; validation loss and accuracy per epoch.
2b. **Out of domain** (variant ``gqcnn_ood``, Dex-Net 4.0's way): heaps of random convex
   non-box objects (``conf/objects/``, ``baseline.ood``) built, rendered, sampled and labelled
   by ``pipeline.dexnet.ood`` (the mesh contact model on the live bodies), and the same GQ-CNN
   trained on them (``gqcnn_ood.pt``), then planning on the same box test images.
3. **Table 2** on the test split (``pipeline.dexnet.table2``): the project's DCNN planner (the training artifact
   ``baseline.train_version``) and each variant in ``baseline.variants`` (``gqcnn``: the CEM
   scored by the GQ-CNN; ``planarity``: the CEM scored by the analytic disc planarity) plan on
   the same images; each optimal point's distance to the nearest true surface centre
   (``pipeline.planner.centre_distance``), the share within 30 px and the curve over 5–50 px,
   and the planning time per image of every planner, measured in the same run.

Artifact (``data/baseline/<version>/``)::

    candidates/<split>-<shard>.npz   labelled candidates, aligned with the generation shards
    ood/<split>-<shard>.npz          gqcnn_ood: labelled candidates on object heaps, with crops
    gqcnn.pt, gqcnn_ood.pt           GQ-CNN weights + network and crop config (weights_only)
    table2.csv, table2_curve.csv     Table 2 and its curve (no timings: they are in the manifest)
    chosen.npz                       per test image: every planner's point, score and distance
    log.rrd, log.mcap                training curves, labelled candidates, test images with
                                     every planner's point, the CEM's iterations and the truth
"""

from __future__ import annotations

import csv
import dataclasses
import json
import math
import time
from dataclasses import dataclass
from pathlib import Path

import hydra
import numpy as np
import torch
from omegaconf import DictConfig, OmegaConf

from pipeline.artifacts import (
    artifact_file, check_artifact, compute_version, load_manifest, resolve_artifact, run_stage,
    stage_config,
)
from pipeline.artifacts.store import ArtifactError, StageRun
from pipeline.camera.geometry import gravity_in_camera
from pipeline.cli import CONF_DIR, data_root, stage_main
from pipeline.dataset.pixels import pixels_to_points
from pipeline.dataset.scenes import SPLIT_CODES, SPLITS, Scene, SceneDataset
from pipeline.dataset.storage import read_npz, write_npz
from pipeline.dexnet.contact import (
    LABELLED_CANDIDATE_FIELDS, REASONS, evaluate_contacts, robust_quality, suction_model_config)
from pipeline.dexnet.gqcnn import GQCNN, candidate_inputs, count_parameters, predict_quality
from pipeline.dexnet.ood import (
    OOD_FIELDS, check_ood_config, init_ood_worker, load_ood, ood_shard, ood_shard_from_file,
    plan_ood_tasks,
)
from pipeline.dexnet.planner import (
    BASELINE_VARIANTS, MODEL_FILE, OOD_MODEL_FILE, DexNetPlanner, crop_config, gqcnn_config,
    sampler_config, workspace,
)
from pipeline.dexnet.sampling import Candidates, point_cloud_image, sample_candidates
from pipeline.dexnet.table2 import EVAL_SEED, OOD, OURS, evaluate_table2, table2_rows
from pipeline.executor import map_shards, resolve_workers
from pipeline.planner.centre_distance import PAPER_RADIUS_PX, PAPER_TABLE2
from pipeline.tracking import StageLog

STAGE = "baseline"
SECTIONS = ("seed", "camera", "bin", "boxes", "physics", "hand", "surfaces", "suction", "dexnet",
            "baseline")
NOT_AFFECTING_RESULT = ("baseline.generate_version", "baseline.train_version",
                        "baseline.workers", "baseline.force", "baseline.log_samples")
PLANNER_COLORS = {OURS: (60, 120, 255), "gqcnn": (255, 80, 40), OOD: (200, 40, 200),
                  "planarity": (255, 200, 0)}
# What each trained variant learned from, in the manifest's Table 2 rows.
TRAINED_ON = {"gqcnn": "box heaps (this project's generation artifact)",
              OOD: "heaps of random convex non-box objects (conf/objects/)",
              "planarity": "nothing (analytic)"}
LABEL_SEED = 5  # candidate sampling and robustness for a scene: (seed, LABEL_SEED, split, index)

# One row per labelled candidate in candidates/<split>-<shard>.npz:
CANDIDATE_FIELDS = {"scene_index": "(M,) int64 scene index within the split",
                    **LABELLED_CANDIDATE_FIELDS}


# --------------------------------------------------------------------------------------------
# Candidate labels


def label_scene_candidates(scene: Scene, cfg, count: int) -> dict[str, np.ndarray]:
    """Sample ``count`` candidates on one scene as the policy would and label them."""
    rng = np.random.default_rng([int(cfg.seed), LABEL_SEED, SPLIT_CODES[scene.split], scene.index])
    ws = workspace(cfg, scene.T_world_cam)
    mask = ws.object_mask(scene.depth_m, scene.intrinsics)
    cloud = point_cloud_image(scene.depth_m, scene.intrinsics, sampler_config(cfg),
                              object_mask=mask)
    cands = sample_candidates(cloud, count, rng, sampler_config(cfg))
    model = suction_model_config(cfg, float(cfg.boxes.density))
    g = gravity_in_camera(scene.T_world_cam)
    # candidates come from what the sensor saw; their labels from the ideal depth (the geometry)
    args = (scene.depth_clean_m, scene.mask, scene.intrinsics, scene.boxes, g, model)
    if len(cands):
        quality = robust_quality(cands.point, cands.axis, *args, rng=rng)
        reason = evaluate_contacts(cands.point, cands.axis, *args).reason
    else:
        quality, reason = np.zeros(0), np.zeros(0, np.int8)
    return {"scene_index": np.full(len(cands), scene.index, np.int64),
            "uv": cands.uv.astype(np.int64).reshape(-1, 2),
            "point": cands.point.reshape(-1, 3), "axis": cands.axis.reshape(-1, 3),
            "depth": cands.depth.astype(np.float64), "angle": cands.angle.astype(np.float64),
            "quality": np.asarray(quality, np.float64),
            "label": np.asarray(quality, np.float64) >= model.quality_threshold,
            "reason": np.asarray(reason, np.int8)}


@dataclass
class CandidateTask:
    split: str
    first: int
    count: int
    out_path: str


_STATE: dict = {}


def _init_worker(cfg_obj, gen_dir: str) -> None:
    _STATE.clear()
    _STATE.update(cfg=cfg_obj, gen_dir=Path(gen_dir))


def label_shard(task: CandidateTask) -> dict:
    """Label one shard's scenes; writes the shard file, returns counts for the manifest."""
    cfg = _STATE["cfg"]
    ds = SceneDataset(_STATE["gen_dir"], task.split)
    cols: dict[str, list] = {}
    for index in range(task.first, task.first + task.count):
        rows = label_scene_candidates(ds[index], cfg, int(cfg.baseline.candidates_per_scene))
        for k, v in rows.items():
            cols.setdefault(k, []).append(v)
    arrays = {k: np.concatenate(v) for k, v in cols.items()}
    Path(task.out_path).parent.mkdir(parents=True, exist_ok=True)
    write_npz(Path(task.out_path), arrays)
    return _label_summary(task, arrays)


def _label_summary(task: CandidateTask, arrays: dict) -> dict:
    return {"split": task.split, "scenes": task.count, "candidates": int(len(arrays["label"])),
            "positives": int(arrays["label"].sum()),
            "reasons": np.bincount(arrays["reason"].astype(np.int64),
                                   minlength=len(REASONS)).tolist()}


def label_shard_from_file(task: CandidateTask) -> dict | None:
    """The summary of a candidate shard an interrupted run already wrote (None: redo it)."""
    if not Path(task.out_path).is_file():
        return None
    try:
        arrays = read_npz(Path(task.out_path))
        idx = arrays["scene_index"]
        ok = set(arrays) == set(CANDIDATE_FIELDS) and bool(
            np.all((idx >= task.first) & (idx < task.first + task.count)))
        return _label_summary(task, arrays) if ok else None
    except Exception:  # noqa: BLE001 - any unusable file is simply computed again
        return None


def plan_tasks(gen_dir: Path, out_dir: Path, max_train_scenes: int) -> list[CandidateTask]:
    index = json.loads((gen_dir / "index.json").read_text())
    tasks = []
    for split in SPLITS:
        budget = max_train_scenes if (split == "train" and max_train_scenes > 0) else None
        for shard in index["splits"][split]:
            count = shard["count"] if budget is None else min(shard["count"], budget)
            if count <= 0:
                break
            name = artifact_file(gen_dir, shard["file"]).name  # ArtifactError if outside
            tasks.append(CandidateTask(split, shard["first"], count,
                                       str(out_dir / "candidates" / name)))
            if budget is not None:
                budget -= count
    return tasks


def load_candidates(folder: Path, split: str) -> dict[str, np.ndarray]:
    """Every labelled candidate of a split, concatenated over its shards."""
    meta = json.loads((folder / "candidates.json").read_text())
    parts = [read_npz(artifact_file(folder, f)) for f in meta["splits"][split]]
    if not parts:
        return {}
    return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}


# --------------------------------------------------------------------------------------------
# GQ-CNN training


def _as_candidates(rows: dict, idx: np.ndarray) -> Candidates:
    return Candidates(uv=rows["uv"][idx], point=rows["point"][idx], axis=rows["axis"][idx],
                      depth=rows["depth"][idx], angle=rows["angle"][idx])


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
        c, p = candidate_inputs(depth, _as_candidates(rows, group), crop)
        crops[group], poses[group] = c.astype(np.float16), p
    return crops, poses


def _evaluate(net: GQCNN, crops, poses, labels) -> dict:
    if len(labels) == 0:
        return {"loss": float("nan"), "accuracy": float("nan")}
    q = predict_quality(net, crops.astype(np.float32), poses)
    eps = 1e-7
    y = labels.astype(np.float64)
    loss = -np.mean(y * np.log(q + eps) + (1 - y) * np.log(1 - q + eps))
    pred = q >= 0.5
    tp = int(np.sum(pred & labels))
    return {"loss": float(loss), "accuracy": float(np.mean(pred == labels)),
            "precision": float(tp / max(int(pred.sum()), 1)),
            "recall": float(tp / max(int(labels.sum()), 1)),
            "positive_rate": float(np.mean(labels))}


def train_gqcnn(cfg, train_inputs, val_inputs, progress: bool,
                name: str = "gqcnn") -> tuple[GQCNN, dict]:
    """Adam on binary cross-entropy; data order of epoch e from (seed, e). Returns net, history.
    ``name``: the variant, for the progress bar."""
    from tqdm import tqdm

    b = cfg.baseline
    torch.manual_seed(int(cfg.seed))
    torch.set_num_threads(int(b.num_threads))
    torch.use_deterministic_algorithms(True)
    net = GQCNN(gqcnn_config(cfg))
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
        for start in tqdm(steps, desc=f"{STAGE} {name} epoch {epoch + 1}/{b.epochs}", unit="batch",
                          disable=not progress, leave=False):
            idx = np.sort(order[start:start + int(b.batch_size)])
            x = torch.from_numpy(crops[idx].astype(np.float32))
            p = torch.from_numpy(poses[idx])
            y = torch.from_numpy(labels[idx].astype(np.float32))
            loss = torch.nn.functional.binary_cross_entropy_with_logits(net(x, p), y)
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            history["step_loss"].append(loss.item())
            total += history["step_loss"][-1] * len(idx)
        history["train_loss"].append(total / max(n, 1))
        history["val"].append(_evaluate(net, *val_inputs))
    history["train_s"] = time.perf_counter() - t0
    history["samples_per_s"] = int(b.epochs) * n / max(history["train_s"], 1e-9)
    return net.eval(), history


def _write_csv(path: Path, header: list[str], rows: list[list]) -> None:
    with open(path, "w", newline="") as f:
        w = csv.writer(f, lineterminator="\n")
        w.writerow(header)
        w.writerows(rows)


# --------------------------------------------------------------------------------------------
# Logs


def _quality_colors(q: np.ndarray) -> np.ndarray:
    q = np.clip(np.asarray(q, np.float64), 0.0, 1.0)
    return np.stack([255 * (1 - q), 255 * q, np.full_like(q, 40)], axis=1).astype(np.uint8)


def _log_candidates(log: StageLog, gen_dir: Path, folder: Path, count: int) -> None:
    """A few train scenes with their labelled candidates coloured by quality (red 0 → green 1)."""
    rows = load_candidates(folder, "train")
    if not rows:
        return
    ds = SceneDataset(gen_dir, "train")
    for i in range(min(count, len(ds))):
        scene = ds[i]
        sel = rows["scene_index"] == i
        log.set_time(sequences={"labelled_scene": i}, clock_ns=i * 1_000_000_000)
        log.log_camera("labels/camera", scene.intrinsics, scene.T_world_cam)
        log.log_depth("labels/camera/depth", scene.depth_m)
        log.log_points("labels/camera/candidates", rows["point"][sel],
                       _quality_colors(rows["quality"][sel]))
        reasons = np.bincount(rows["reason"][sel].astype(np.int64), minlength=len(REASONS))
        log.log_text("log", f"train scene {i}: {int(sel.sum())} candidates, "
                            f"{int(rows['label'][sel].sum())} robust; contact outcomes: "
                            + ", ".join(f"{REASONS[k]} {c}" for k, c in enumerate(reasons) if c))


def _log_history(log: StageLog, history: dict, steps_per_epoch: int) -> None:
    for step, loss in enumerate(history["step_loss"]):
        log.set_time(sequences={"step": step}, clock_ns=step * 1_000_000)
        log.log_scalar("gqcnn/step/loss", loss)
    for e, (tr, val) in enumerate(zip(history["train_loss"], history["val"])):
        step = (e + 1) * steps_per_epoch
        log.set_time(sequences={"epoch": e + 1, "step": step}, clock_ns=step * 1_000_000)
        log.log_scalar("gqcnn/epoch/train_loss", tr)
        for k in ("loss", "accuracy"):
            if math.isfinite(val[k]):
                log.log_scalar(f"gqcnn/epoch/val_{k}", val[k])


def _log_table2_samples(log: StageLog, cfg, gen_dir: Path, model_dir: Path, result: dict,
                        count: int) -> None:
    """Test images with every planner's point, the true centres and the CEM's iterations."""
    gen = SceneDataset(gen_dir, "test")
    dex = None
    if "gqcnn" in result["planners"]:
        dex = DexNetPlanner.from_config(cfg, "gqcnn", gen.T_world_cam, model_dir)
    for i in range(min(count, len(result["scene_index"]))):
        scene = gen[i]
        log.set_time(sequences={"test_image": i}, clock_ns=(10_000 + i) * 1_000_000_000)
        log.log_camera("table2/camera", scene.intrinsics, scene.T_world_cam)
        log.log_depth("table2/camera/depth", scene.depth_m)
        pts = pixels_to_points(scene, result["centres"][i])
        log.log_points("table2/camera/true_centres", pts,
                       np.full((len(pts), 3), 255, np.uint8))
        parts = []
        for name in result["planners"]:
            uv = result[f"{name}_uv"][i]
            if np.all(np.isfinite(uv)):
                p = pixels_to_points(scene, uv.reshape(1, 2))
                log.log_points(f"table2/camera/{name}", p,
                               np.array([PLANNER_COLORS[name]], np.uint8))
            parts.append(f"{name} {result[f'{name}_dist'][i]:.1f} px")
        if dex is not None:
            cem = dex.run_cem(scene.depth_m, scene.intrinsics,
                              np.random.default_rng([int(cfg.seed), EVAL_SEED, i]))
            for k, it in enumerate(cem.iterations):
                log.log_points(f"table2/camera/cem/iteration_{k}", it.candidates.point,
                               _quality_colors(it.scores))
        log.log_text("log", f"test image {i}: distance to the nearest true centre: "
                            + ", ".join(parts))


# --------------------------------------------------------------------------------------------
# The stage


def _write_index(run: StageRun, name: str, splits, fields: dict, tasks: list, path_of) -> None:
    """``<name>`` in the artifact: each split's shard files (``path_of(task)``, relative to the
    artifact), the fields of their rows and the contact model's reason codes."""
    index = {"splits": {s: [] for s in splits}, "fields": fields, "reasons": list(REASONS)}
    for t in tasks:
        index["splits"][t.split].append(Path(path_of(t)).relative_to(run.work_dir).as_posix())
    (run.work_dir / name).write_text(json.dumps(index, indent=2) + "\n")


def _make_ood_data(run: StageRun, cfg_obj, gen_dir: Path, tasks: list, done: dict,
                   workers: int, progress: bool) -> None:
    """The object heaps' labelled candidates (``ood/<split>-<shard>.npz``, ``ood.json``), with
    the generation artifact's sensor model and depth unit; their counts into the manifest."""
    from types import SimpleNamespace

    meta = SceneDataset(gen_dir, "test")
    sensor = SimpleNamespace(**meta.sensor)  # the box heaps' sensor (camera.json)
    _write_index(run, "ood.json", ("train", "val"), OOD_FIELDS, tasks, lambda t: t.path)
    t0 = time.perf_counter()
    todo = [t for t in tasks if t.path not in done]
    done.update(zip([t.path for t in todo], map_shards(
        ood_shard, todo, init=init_ood_worker, initargs=(cfg_obj, sensor, meta.depth_unit),
        workers=workers, desc=f"{STAGE} object heaps", progress=progress,
        executor=cfg_obj.executor)))
    seconds = time.perf_counter() - t0
    run.timings.update({"ood_s": round(seconds, 3), "ood_scenes_per_s": round(
        sum(t.count for t in todo) / max(seconds, 1e-9), 3)})
    out = {}
    for split in ("train", "val"):
        ss = [done[t.path] for t in tasks if t.split == split]
        reasons = np.sum([s["reasons"] for s in ss], axis=0) if ss else np.zeros(len(REASONS))
        out[split] = {k: sum(s[k] for s in ss)
                      for k in ("scenes", "objects", "not_settled", "candidates", "positives")}
        out[split]["contact_outcomes"] = {REASONS[k]: int(c) for k, c in enumerate(reasons)}
    run.metrics["ood_candidate_labels"] = out


def _train_ood(run: StageRun, cfg, tasks: list, box_test: tuple, progress: bool) -> None:
    """The GQ-CNN of ``gqcnn``, trained as it is on the object heaps' candidates instead
    (``gqcnn_ood.pt``); validated on the object heaps, tested on the box test split's."""
    crop = crop_config(cfg)
    inputs = {}
    for split in ("train", "val"):
        rows = load_ood([Path(t.path) for t in tasks if t.split == split])
        inputs[split] = (rows.get("crop", np.zeros((0, 1, crop.size, crop.size), np.float16)),
                         rows.get("pose", np.zeros((0, 2), np.float32)),
                         rows.get("label", np.zeros(0, bool)).astype(bool))
    if len(inputs["train"][2]) == 0:
        raise ValueError("no candidates on the object heaps: check baseline.ood.num_scenes and "
                         "objects.min_count (conf/objects/)")
    net, history = train_gqcnn(cfg, inputs["train"], inputs["val"], progress, name=OOD)
    torch.save({"network": dataclasses.asdict(net.cfg), "crop": dataclasses.asdict(crop),
                "state_dict": net.state_dict()}, run.work_dir / OOD_MODEL_FILE)
    run.timings.update({"gqcnn_ood_train_s": round(history["train_s"], 3),
                        "gqcnn_ood_samples_per_s": round(history["samples_per_s"], 1)})
    run.metrics[OOD] = {
        "parameters": count_parameters(net), "train_samples": int(len(inputs["train"][2])),
        "train_loss": [round(x, 6) for x in history["train_loss"]],
        "val": [{k: round(v, 6) for k, v in e.items()} for e in history["val"]],
        "box_test": {k: round(v, 6) for k, v in _evaluate(net, *box_test).items()}}


def _train_artifact(cfg) -> Path | None:
    """The project's planner for Table 2, or None (``train_version=none``, or no artifact and
    ``latest`` asked for)."""
    version = str(cfg.baseline.train_version)
    if version.lower() == "none":
        return None
    models = Path(cfg.paths.models)
    try:
        folder = resolve_artifact(models, "train", version, key="baseline.train_version")
    except ArtifactError:
        if version != "latest":
            raise
        print("[baseline] no training artifact yet: Table 2 leaves the project's planner out "
              "(run `make train` first, or pass baseline.train_version=none to silence this).")
        return None
    return check_artifact(folder, "baseline.train_version")  # files match the manifest


def baseline(cfg: DictConfig) -> Path:
    """Label candidates, train the GQ-CNN, evaluate Table 2; returns the artifact folder."""
    for variant in cfg.baseline.variants:
        if variant not in BASELINE_VARIANTS:
            raise ValueError(f"baseline.variants has {variant!r}: choose from "
                             f"{', '.join(BASELINE_VARIANTS)}")
    with_ood = OOD in cfg.baseline.variants
    if with_ood:
        check_ood_config(cfg)
    gen_dir = resolve_artifact(data_root(cfg), STAGE_UPSTREAM, cfg.baseline.generate_version,
                               verify=True, key="baseline.generate_version")
    train_dir = _train_artifact(cfg)
    upstream = {"generate": gen_dir.name}
    if train_dir is not None:
        upstream["train"] = train_dir.name
        trained_on = load_manifest(train_dir)["upstream"].get("label")
        if trained_on is not None:
            upstream["train_label"] = trained_on
    # the object heaps' settings are part of the version only when their variant is run
    sections = SECTIONS + (("objects",) if with_ood else ())
    ignore = NOT_AFFECTING_RESULT + (() if with_ood else ("baseline.ood",))
    config = stage_config(cfg, sections, ignore)
    version = compute_version(STAGE, config, upstream=upstream)
    cfg_obj = OmegaConf.to_object(cfg)
    workers = resolve_workers(cfg_obj.baseline.workers, cfg_obj.executor)
    progress = bool(cfg_obj.logging.progress)

    def body(run: StageRun) -> None:
        tasks = plan_tasks(gen_dir, run.work_dir, int(cfg.baseline.max_train_scenes))
        ood_tasks = plan_ood_tasks(cfg.baseline.ood, run.work_dir / "ood") if with_ood else []
        # an interrupted run's finished shards (both kinds) are kept; everything else is redone
        readers = {t.out_path: (label_shard_from_file, t) for t in tasks}
        readers.update({t.path: (ood_shard_from_file, t) for t in ood_tasks})
        done = run.finished_shards(list(readers), list(readers),
                                   lambda path: readers[path][0](readers[path][1]),
                                   lambda path: path)
        if run.resumed:
            run.timings["shards_resumed"] = len(done)
        _write_index(run, "candidates.json", SPLITS, CANDIDATE_FIELDS, tasks,
                     lambda t: t.out_path)
        t0 = time.perf_counter()
        todo = [t for t in tasks if t.out_path not in done]
        done.update(zip([t.out_path for t in todo], map_shards(
            label_shard, todo, init=_init_worker, initargs=(cfg_obj, str(gen_dir)),
            workers=workers, desc=f"{STAGE} labels", progress=progress,
            executor=cfg_obj.executor)))
        summaries = [done[t.out_path] for t in tasks]
        label_s = time.perf_counter() - t0
        n_scenes = sum(t.count for t in todo)
        run.timings.update({"label_s": round(label_s, 3), "label_workers": workers,
                            "label_scenes_per_s": round(n_scenes / max(label_s, 1e-9), 3)})
        labels_metrics = {}
        for split in SPLITS:
            ss = [s for s in summaries if s["split"] == split]
            reasons = np.sum([s["reasons"] for s in ss], axis=0) if ss else np.zeros(len(REASONS))
            cands = sum(s["candidates"] for s in ss)
            labels_metrics[split] = {
                "scenes": sum(s["scenes"] for s in ss), "candidates": cands,
                "positives": sum(s["positives"] for s in ss),
                "contact_outcomes": {REASONS[k]: int(c) for k, c in enumerate(reasons)}}
        run.metrics["candidate_labels"] = labels_metrics
        if with_ood:
            _make_ood_data(run, cfg_obj, gen_dir, ood_tasks, done, workers, progress)

        crop = crop_config(cfg)
        inputs = {}
        for split in ("train", "val", "test"):
            rows = load_candidates(run.work_dir, split)
            c, p = build_inputs(gen_dir, split, rows, crop)
            inputs[split] = (c, p, rows.get("label", np.zeros(0, bool)).astype(bool))
        if len(inputs["train"][2]) == 0:
            raise ValueError("no candidates in the train split: the generation artifact has no "
                             "boxes to sample on (check generate.num_scenes and boxes.max_count)")
        net, history = train_gqcnn(cfg, inputs["train"], inputs["val"], progress)
        torch.save({"network": dataclasses.asdict(net.cfg), "crop": dataclasses.asdict(crop),
                    "state_dict": net.state_dict()}, run.work_dir / MODEL_FILE)
        run.timings.update({"gqcnn_train_s": round(history["train_s"], 3),
                            "gqcnn_samples_per_s": round(history["samples_per_s"], 1)})
        run.metrics["gqcnn"] = {
            "parameters": count_parameters(net),
            "train_samples": int(len(inputs["train"][2])),
            "train_loss": [round(x, 6) for x in history["train_loss"]],
            "val": [{k: round(v, 6) for k, v in e.items()} for e in history["val"]],
            "test": {k: round(v, 6) for k, v in _evaluate(net, *inputs["test"]).items()}}
        if with_ood:
            _train_ood(run, cfg, ood_tasks, inputs["test"], progress)
        del inputs

        result = evaluate_table2(cfg, gen_dir, run.work_dir, train_dir, progress)
        radius = float(cfg.baseline.table2_radius_px)
        radii = np.arange(int(cfg.baseline.curve_min_px), int(cfg.baseline.curve_max_px) + 1)
        rows, curve = table2_rows(result, radius, radii)
        _write_csv(run.work_dir / "table2.csv", list(rows[0]) if rows else ["planner"],
                   [list(r.values()) for r in rows])
        _write_csv(run.work_dir / "table2_curve.csv", ["radius_px", *result["planners"]], curve)
        chosen = {k: v for k, v in result.items()
                  if isinstance(v, np.ndarray)}
        chosen["centres"] = (np.concatenate(result["centres"]) if result["centres"]
                             else np.zeros((0, 2)))
        write_npz(run.work_dir / "chosen.npz", chosen)
        run.metrics["table2"] = {"radius_px": radius, "rows": rows,
                                 "trained_on": {k: TRAINED_ON[k] for k in cfg.baseline.variants},
                                 "paper": {"within_30px": PAPER_TABLE2,
                                           "radius_px": PAPER_RADIUS_PX}}
        run.timings["planning_ms_per_image"] = {
            name: {"mean": round(1000 * float(np.mean(t)), 2),
                   "median": round(1000 * float(np.median(t)), 2),
                   "p90": round(1000 * float(np.percentile(t, 90)), 2)} if t else {}
            for name, t in result["times"].items()}
        run.timings["torch_threads"] = torch.get_num_threads()

        with StageLog(run.work_dir, app_id=f"binpick-{STAGE}", recording_id=run.version) as log:
            steps = math.ceil(len(history["step_loss"]) / max(int(cfg.baseline.epochs), 1))
            _log_history(log, history, steps)
            _log_candidates(log, gen_dir, run.work_dir, int(cfg.baseline.log_samples))
            _log_table2_samples(log, cfg, gen_dir, run.work_dir, result,
                                int(cfg.baseline.log_samples))

    return run_stage(data_root(cfg), STAGE, version, config, upstream, body,
                     seed=cfg_obj.seed, force=cfg_obj.baseline.force, resumable=True)


STAGE_UPSTREAM = "generate"


@hydra.main(config_path=CONF_DIR, config_name="baseline", version_base="1.3")
def main(cfg: DictConfig) -> None:
    stage_main(baseline)(cfg)


if __name__ == "__main__":
    main()
