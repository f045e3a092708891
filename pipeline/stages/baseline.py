"""The Dex-Net-style comparison stage (paper Sec. 6, 8.1.1, Table 2, Fig. 10).

    python -m pipeline.stages.baseline experiment=smoke [baseline.train_version=<version>|none]

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
3. **Table 2** on the test split (``pipeline.dexnet.table2``): the project's DCNN planner (the
training artifact
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
import json
import math
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import torch
from omegaconf import DictConfig, OmegaConf

from pipeline.artifacts import check_artifact, load_manifest, resolve_artifact, stage_config
from pipeline.artifacts.store import ArtifactError, StageRun
from pipeline.dataset.pixels import pixels_to_points
from pipeline.dataset.scenes import SPLITS, SceneDataset
from pipeline.dataset.storage import write_npz
from pipeline.dexnet.contact import REASONS
from pipeline.dexnet.labels import (
    CANDIDATE_FIELDS,
    init_worker,
    label_shard,
    label_shard_from_file,
    load_candidates,
    plan_tasks,
)
from pipeline.dexnet.ood import (
    OOD_FIELDS,
    check_ood_config,
    init_ood_worker,
    load_ood,
    ood_shard,
    ood_shard_from_file,
    plan_ood_tasks,
)
from pipeline.dexnet.planner import (
    BASELINE_VARIANTS,
    MODEL_FILE,
    OOD_MODEL_FILE,
    DexNetPlanner,
    crop_config,
)
from pipeline.dexnet.table2 import EVAL_SEED, OOD, OURS, evaluate_table2, table2_rows
from pipeline.dexnet.trained import save_gqcnn, training_metrics, training_timings
from pipeline.dexnet.training import build_inputs, train_gqcnn
from pipeline.planner.centre_distance import PAPER_RADIUS_PX, PAPER_TABLE2
from pipeline.runtime.cli import stage_command
from pipeline.runtime.executor import map_shards, resolve_workers
from pipeline.runtime.stage_artifacts import run_stage_from_config, upstream_artifact
from pipeline.tracking import StageLog

STAGE = "baseline"
SECTIONS = (
    "seed",
    "camera",
    "bin",
    "boxes",
    "physics",
    "hand",
    "surfaces",
    "suction",
    "dexnet",
    "baseline",
)
NOT_AFFECTING_RESULT = (
    "baseline.generate_version",
    "baseline.train_version",
    "baseline.workers",
    "baseline.force",
    "baseline.log_samples",
)
PLANNER_COLORS = {
    OURS: (60, 120, 255),
    "gqcnn": (255, 80, 40),
    OOD: (200, 40, 200),
    "planarity": (255, 200, 0),
}
# What each trained variant learned from, in the manifest's Table 2 rows.
TRAINED_ON = {
    "gqcnn": "box heaps (this project's generation artifact)",
    OOD: "heaps of random convex non-box objects (conf/objects/)",
    "planarity": "nothing (analytic)",
}

# --------------------------------------------------------------------------------------------
# GQ-CNN training


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
        log.log_points(
            "labels/camera/candidates", rows["point"][sel], _quality_colors(rows["quality"][sel])
        )
        reasons = np.bincount(rows["reason"][sel].astype(np.int64), minlength=len(REASONS))
        log.log_text(
            "log",
            f"train scene {i}: {int(sel.sum())} candidates, "
            f"{int(rows['label'][sel].sum())} robust; contact outcomes: "
            + ", ".join(f"{REASONS[k]} {c}" for k, c in enumerate(reasons) if c),
        )


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


def _log_table2_samples(
    log: StageLog, cfg, gen_dir: Path, model_dir: Path, result: dict, count: int
) -> None:
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
        log.log_points("table2/camera/true_centres", pts, np.full((len(pts), 3), 255, np.uint8))
        parts = []
        for name in result["planners"]:
            uv = result[f"{name}_uv"][i]
            if np.all(np.isfinite(uv)):
                p = pixels_to_points(scene, uv.reshape(1, 2))
                log.log_points(
                    f"table2/camera/{name}", p, np.array([PLANNER_COLORS[name]], np.uint8)
                )
            parts.append(f"{name} {result[f'{name}_dist'][i]:.1f} px")
        if dex is not None:
            cem = dex.run_cem(
                scene.depth_m,
                scene.intrinsics,
                np.random.default_rng([int(cfg.seed), EVAL_SEED, i]),
            )
            for k, it in enumerate(cem.iterations):
                log.log_points(
                    f"table2/camera/cem/iteration_{k}",
                    it.candidates.point,
                    _quality_colors(it.scores),
                )
        log.log_text(
            "log", f"test image {i}: distance to the nearest true centre: " + ", ".join(parts)
        )


# --------------------------------------------------------------------------------------------
# The stage


def _write_index(run: StageRun, name: str, splits, fields: dict, tasks: list, path_of) -> None:
    """``<name>`` in the artifact: each split's shard files (``path_of(task)``, relative to the
    artifact), the fields of their rows and the contact model's reason codes."""
    index = {"splits": {s: [] for s in splits}, "fields": fields, "reasons": list(REASONS)}
    for t in tasks:
        index["splits"][t.split].append(Path(path_of(t)).relative_to(run.work_dir).as_posix())
    (run.work_dir / name).write_text(json.dumps(index, indent=2) + "\n")


def _run_shards(
    done: dict,
    tasks: list,
    path_of: Callable[[Any], str],
    job: tuple,
    cfg_obj,
    workers: int,
    progress: bool,
) -> tuple[int, float]:
    """Run the shards of ``tasks`` whose file (``path_of(task)``) is not in ``done`` and put
    their summaries there, by file. ``job``: the shard function, the workers' initialiser, its
    arguments and the progress bar's name (``map_shards``, on ``workers`` processes of the
    ``executor``). Returns the scenes run and the seconds they took."""
    t0 = time.perf_counter()
    todo = [t for t in tasks if path_of(t) not in done]
    fn, init, initargs, desc = job
    shards = map_shards(
        fn,
        todo,
        init=init,
        initargs=initargs,
        workers=workers,
        desc=desc,
        progress=progress,
        executor=cfg_obj.executor,
    )
    done.update(zip([path_of(t) for t in todo], shards))
    return sum(t.count for t in todo), time.perf_counter() - t0


def _make_ood_data(
    run: StageRun, cfg_obj, gen_dir: Path, tasks: list, done: dict, workers: int, progress: bool
) -> None:
    """The object heaps' labelled candidates (``ood/<split>-<shard>.npz``, ``ood.json``), with
    the generation artifact's sensor model and depth unit; their counts into the manifest."""
    from types import SimpleNamespace

    meta = SceneDataset(gen_dir, "test")
    sensor = SimpleNamespace(**meta.sensor)  # the box heaps' sensor (camera.json)
    _write_index(run, "ood.json", ("train", "val"), OOD_FIELDS, tasks, lambda t: t.path)
    job = (ood_shard, init_ood_worker, (cfg_obj, sensor, meta.depth_unit), f"{STAGE} object heaps")
    scenes, seconds = _run_shards(done, tasks, lambda t: t.path, job, cfg_obj, workers, progress)
    run.timings.update(
        {"ood_s": round(seconds, 3), "ood_scenes_per_s": round(scenes / max(seconds, 1e-9), 3)}
    )
    out = {}
    for split in ("train", "val"):
        ss = [done[t.path] for t in tasks if t.split == split]
        reasons = np.sum([s["reasons"] for s in ss], axis=0) if ss else np.zeros(len(REASONS))
        out[split] = {
            k: sum(s[k] for s in ss)
            for k in ("scenes", "objects", "not_settled", "candidates", "positives")
        }
        out[split]["contact_outcomes"] = {REASONS[k]: int(c) for k, c in enumerate(reasons)}
    run.metrics["ood_candidate_labels"] = out


def _train_ood(run: StageRun, cfg, tasks: list, box_test: tuple, progress: bool) -> None:
    """The GQ-CNN of ``gqcnn``, trained as it is on the object heaps' candidates instead
    (``gqcnn_ood.pt``); validated on the object heaps, tested on the box test split's."""
    crop = crop_config(cfg)
    inputs = {}
    for split in ("train", "val"):
        rows = load_ood([Path(t.path) for t in tasks if t.split == split])
        inputs[split] = (
            rows.get("crop", np.zeros((0, 1, crop.size, crop.size), np.float16)),
            rows.get("pose", np.zeros((0, 2), np.float32)),
            rows.get("label", np.zeros(0, bool)).astype(bool),
        )
    if len(inputs["train"][2]) == 0:
        raise ValueError(
            "no candidates on the object heaps: check baseline.ood.num_scenes and "
            "objects.min_count (conf/objects/)"
        )
    net, history = train_gqcnn(cfg, inputs["train"], inputs["val"], progress, name=OOD)
    save_gqcnn(net, crop, run.work_dir / OOD_MODEL_FILE)
    run.timings.update(training_timings(OOD, history))
    run.metrics[OOD] = training_metrics(net, history, inputs["train"], {"box_test": box_test})


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
        print(
            "[baseline] no training artifact yet: Table 2 leaves the project's planner out "
            "(run `make train` first, or pass baseline.train_version=none to silence this)."
        )
        return None
    return check_artifact(folder, "baseline.train_version")  # files match the manifest


def baseline(cfg: DictConfig) -> Path:
    """Label candidates, train the GQ-CNN, evaluate Table 2; returns the artifact folder."""
    for variant in cfg.baseline.variants:
        if variant not in BASELINE_VARIANTS:
            raise ValueError(
                f"baseline.variants has {variant!r}: choose from {', '.join(BASELINE_VARIANTS)}"
            )
    with_ood = OOD in cfg.baseline.variants
    if with_ood:
        check_ood_config(cfg)
    gen_dir = upstream_artifact(cfg, STAGE_UPSTREAM, "baseline.generate_version")
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
    cfg_obj = OmegaConf.to_object(cfg)
    workers = resolve_workers(cfg_obj.baseline.workers, cfg_obj.executor)
    progress = bool(cfg_obj.logging.progress)

    def body(run: StageRun) -> None:
        ood_tasks = plan_ood_tasks(cfg.baseline.ood, run.work_dir / "ood") if with_ood else []
        done = _label_candidates(run, cfg_obj, gen_dir, ood_tasks, workers, progress)
        if with_ood:
            _make_ood_data(run, cfg_obj, gen_dir, ood_tasks, done, workers, progress)
        history = _train_box_gqcnn(run, cfg, gen_dir, ood_tasks if with_ood else None, progress)
        result = _table2(run, cfg, gen_dir, train_dir, progress)
        with StageLog.for_stage(run.work_dir, STAGE, run.version) as log:
            steps = math.ceil(len(history["step_loss"]) / max(int(cfg.baseline.epochs), 1))
            _log_history(log, history, steps)
            _log_candidates(log, gen_dir, run.work_dir, int(cfg.baseline.log_samples))
            _log_table2_samples(
                log, cfg, gen_dir, run.work_dir, result, int(cfg.baseline.log_samples)
            )

    return run_stage_from_config(cfg, STAGE, config, upstream, body, resumable=True)


def _label_candidates(
    run: StageRun, cfg_obj, gen_dir: Path, ood_tasks: list, workers: int, progress: bool
) -> dict:
    """Sample and label the box heaps' candidates (shards kept across an interrupted run);
    every finished shard's summary by its path, the object heaps' shards included."""
    tasks = plan_tasks(gen_dir, run.work_dir, int(cfg_obj.baseline.max_train_scenes))
    # an interrupted run's finished shards (both kinds) are kept; everything else is redone
    readers = {t.out_path: (label_shard_from_file, t) for t in tasks}
    readers.update({t.path: (ood_shard_from_file, t) for t in ood_tasks})
    done = run.finished_shards(
        list(readers),
        list(readers),
        lambda path: readers[path][0](readers[path][1]),
        lambda path: path,
    )
    if run.resumed:
        run.timings["shards_resumed"] = len(done)
    _write_index(run, "candidates.json", SPLITS, CANDIDATE_FIELDS, tasks, lambda t: t.out_path)
    job = (label_shard, init_worker, (cfg_obj, str(gen_dir)), f"{STAGE} labels")
    scenes, seconds = _run_shards(
        done, tasks, lambda t: t.out_path, job, cfg_obj, workers, progress
    )
    summaries = [done[t.out_path] for t in tasks]
    run.timings.update(
        {
            "label_s": round(seconds, 3),
            "label_workers": workers,
            "label_scenes_per_s": round(scenes / max(seconds, 1e-9), 3),
        }
    )
    labels_metrics = {}
    for split in SPLITS:
        ss = [s for s in summaries if s["split"] == split]
        reasons = np.sum([s["reasons"] for s in ss], axis=0) if ss else np.zeros(len(REASONS))
        labels_metrics[split] = {
            "scenes": sum(s["scenes"] for s in ss),
            "candidates": sum(s["candidates"] for s in ss),
            "positives": sum(s["positives"] for s in ss),
            "contact_outcomes": {REASONS[k]: int(c) for k, c in enumerate(reasons)},
        }
    run.metrics["candidate_labels"] = labels_metrics
    return done


def _train_box_gqcnn(
    run: StageRun, cfg: DictConfig, gen_dir: Path, ood_tasks: list | None, progress: bool
) -> dict:
    """Train the GQ-CNN on the box heaps' candidates (and, with ``ood_tasks``, the one on the
    object heaps); writes ``gqcnn.pt`` and the metrics; the box network's training history."""
    crop = crop_config(cfg)
    inputs = {}
    for split in ("train", "val", "test"):
        rows = load_candidates(run.work_dir, split)
        c, p = build_inputs(gen_dir, split, rows, crop)
        inputs[split] = (c, p, rows.get("label", np.zeros(0, bool)).astype(bool))
    if len(inputs["train"][2]) == 0:
        raise ValueError(
            "no candidates in the train split: the generation artifact has no "
            "boxes to sample on (check generate.num_scenes and boxes.max_count)"
        )
    net, history = train_gqcnn(cfg, inputs["train"], inputs["val"], progress)
    save_gqcnn(net, crop, run.work_dir / MODEL_FILE)
    run.timings.update(training_timings("gqcnn", history))
    run.metrics["gqcnn"] = training_metrics(net, history, inputs["train"], {"test": inputs["test"]})
    if ood_tasks is not None:
        _train_ood(run, cfg, ood_tasks, inputs["test"], progress)
    return history


def _table2(
    run: StageRun, cfg: DictConfig, gen_dir: Path, train_dir: Path | None, progress: bool
) -> dict:
    """Table 2: every planner on the same test images; ``table2.csv``, its curve, the chosen
    points and the planning times."""
    result = evaluate_table2(cfg, gen_dir, run.work_dir, train_dir, progress)
    radius = float(cfg.baseline.table2_radius_px)
    radii = np.arange(int(cfg.baseline.curve_min_px), int(cfg.baseline.curve_max_px) + 1)
    rows, curve = table2_rows(result, radius, radii)
    _write_csv(
        run.work_dir / "table2.csv",
        list(rows[0]) if rows else ["planner"],
        [list(r.values()) for r in rows],
    )
    _write_csv(run.work_dir / "table2_curve.csv", ["radius_px", *result["planners"]], curve)
    chosen = {k: v for k, v in result.items() if isinstance(v, np.ndarray)}
    chosen["centres"] = np.concatenate(result["centres"]) if result["centres"] else np.zeros((0, 2))
    write_npz(run.work_dir / "chosen.npz", chosen)
    run.metrics["table2"] = {
        "radius_px": radius,
        "rows": rows,
        "trained_on": {k: TRAINED_ON[k] for k in cfg.baseline.variants},
        "paper": {"within_30px": PAPER_TABLE2, "radius_px": PAPER_RADIUS_PX},
    }
    run.timings["planning_ms_per_image"] = {
        name: {
            "mean": round(1000 * float(np.mean(t)), 2),
            "median": round(1000 * float(np.median(t)), 2),
            "p90": round(1000 * float(np.percentile(t, 90)), 2),
        }
        if t
        else {}
        for name, t in result["times"].items()
    }
    run.timings["torch_threads"] = torch.get_num_threads()
    return result


STAGE_UPSTREAM = "generate"


main = stage_command("baseline", baseline)


if __name__ == "__main__":
    main()
