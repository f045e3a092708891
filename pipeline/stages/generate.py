"""The generation stage (paper Sec. 4.3, Fig. 4a): depth images of random box heaps.

``generate(cfg)`` is a pure function of the config: it drops a random heap into the bin for
every scene of every split, renders the overhead depth image and instance mask, and writes the
versioned artifact described in ``pipeline.dataset.scenes``. Each scene depends only on its seed
(base seed, split, index), and shards are fixed by ``generate.scenes_per_shard``, so the
artifact is byte-identical whatever ``generate.workers`` is.

Interrupted runs resume (``pipeline.artifacts.store``): a rerun of the same version keeps the
shard files a killed run finished (rebuilding their summaries from the files) and simulates the
rest; ``camera.json``, ``index.json`` and the logs are written again. The artifact equals an
uninterrupted run's (the manifest's ``timings`` and ``created`` aside).

Command line::

    python -m pipeline.stages.generate experiment=smoke generate.num_scenes=200 generate.workers=2
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from omegaconf import DictConfig, OmegaConf

from pipeline.artifacts import stage_config
from pipeline.artifacts.store import StageRun
from pipeline.camera.geometry import (
    Intrinsics,
    camera_pose_above_bin,
    pose_matrix,
    quat_from_matrix,
)
from pipeline.camera.randomise import check_randomisation, draw_sensor, randomisation_rng
from pipeline.camera.render import check_renderer
from pipeline.camera.sensor import apply_sensor_model
from pipeline.dataset.scenes import SPLIT_CODES, SPLITS, SceneDataset
from pipeline.dataset.storage import read_npz, shard_index, write_npz
from pipeline.runtime.cli import stage_command
from pipeline.runtime.executor import log_quota, map_shards, resolve_workers
from pipeline.runtime.stage_artifacts import run_stage_from_config
from pipeline.simulation.cartons import check_cartons
from pipeline.simulation.scene import connect, scene_rng, simulate_scene
from pipeline.tracking import StageLog, default_blueprint

STAGE = "generate"
SECTIONS = ("seed", "camera", "bin", "boxes", "physics", "sensor", "generate")
NOT_AFFECTING_RESULT = ("generate.workers", "generate.force")


@dataclass(frozen=True)
class ShardTask:
    split: str
    shard: int
    first: int  # first scene index (within the split)
    count: int
    path: str  # output file


@dataclass
class ShardSummary:
    task: ShardTask
    num_boxes: np.ndarray
    num_removed: np.ndarray
    settle_steps: np.ndarray
    settled: np.ndarray
    seconds: float


def split_sizes(gcfg) -> dict[str, int]:
    sizes = {"train": gcfg.num_scenes, "val": gcfg.num_val_scenes, "test": gcfg.num_test_scenes}
    for split, n in sizes.items():
        if n < 0:
            raise ValueError(f"number of {split} scenes must be >= 0, got {n}")
    return sizes


def plan_shards(gcfg, out_dir: Path) -> list[ShardTask]:
    """Fixed shards of ``scenes_per_shard`` consecutive scenes per split."""
    if gcfg.scenes_per_shard < 1:
        raise ValueError(f"generate.scenes_per_shard must be >= 1, got {gcfg.scenes_per_shard}")
    tasks = []
    for split, n in split_sizes(gcfg).items():
        for k in range(math.ceil(n / gcfg.scenes_per_shard)):
            first = k * gcfg.scenes_per_shard
            count = min(gcfg.scenes_per_shard, n - first)
            tasks.append(
                ShardTask(split, k, first, count, str(out_dir / "scenes" / f"{split}-{k:05d}.npz"))
            )
    return tasks


_CLIENT: int | None = None
_CFG = None


def _init_worker(cfg_obj) -> None:
    global _CLIENT, _CFG
    _CLIENT = connect()
    _CFG = cfg_obj


def generate_shard(task: ShardTask) -> ShardSummary:
    """Simulate and store one shard's scenes (runs in a worker process)."""
    cfg = _CFG
    t0 = time.perf_counter()
    T_world_cam = camera_pose_above_bin(cfg.camera.height_above_bin_floor)
    T_cam_world = np.linalg.inv(T_world_cam)
    unit = cfg.generate.depth_unit
    max_depth = 65535 * unit
    cols: dict[str, list] = {
        k: []
        for k in (
            "depth",
            "depth_clean",
            "mask",
            "scene_index",
            "seed",
            "num_boxes",
            "num_dropped",
            "num_removed",
            "settle_steps",
            "settled",
            "box_type",
            "box_size",
            "box_mass",
            "box_T_world",
            "box_T_cam",
        )
    }
    rand = cfg.generate.camera_randomisation
    randomised = bool(rand.enabled) and task.split in rand.splits
    keep_clean = stores_clean_depth(cfg)
    intr = Intrinsics.from_config(cfg.camera)
    cartons = cfg.boxes.cartons is not None and task.split in cfg.generate.carton_splits
    jitter = (
        cfg.generate.size_jitter
        if task.split in cfg.generate.size_jitter_splits and not cartons
        else 0.0
    )
    for index in range(task.first, task.first + task.count):
        seed = (cfg.seed, SPLIT_CODES[task.split], index)
        scene = simulate_scene(_CLIENT, cfg, scene_rng(*seed), size_jitter=jitter, cartons=cartons)
        depth = scene.depth_m
        if randomised:
            r_rng = randomisation_rng(*seed)
            sensor = draw_sensor(rand, r_rng)
            if sensor is not None:
                depth = apply_sensor_model(scene.depth_clean_m, sensor, r_rng, intr)
        if float(depth.max(initial=0.0)) > max_depth:
            raise ValueError(
                f"depth beyond {max_depth:.2f} m cannot be stored with "
                f"generate.depth_unit={unit}; increase the unit"
            )
        cols["depth"].append(np.round(depth / unit).astype(np.uint16))
        if keep_clean:  # the ideal depth too: labels and clean-input baselines
            cols["depth_clean"].append(np.round(scene.depth_clean_m / unit).astype(np.uint16))
        cols["mask"].append(scene.mask)
        cols["scene_index"].append(index)
        cols["seed"].append(seed)
        cols["num_boxes"].append(len(scene.boxes))
        cols["num_dropped"].append(scene.num_dropped)
        cols["num_removed"].append(scene.num_removed)
        cols["settle_steps"].append(scene.settle_steps)
        cols["settled"].append(scene.settled)
        for box in scene.boxes:
            T_world_box = pose_matrix(box.position, box.quat_xyzw)
            cols["box_type"].append(box.type_index)
            cols["box_size"].append(box.size)
            cols["box_mass"].append(box.mass)
            cols["box_T_world"].append(T_world_box)
            cols["box_T_cam"].append(T_cam_world @ T_world_box)
    H, W = cfg.camera.height, cfg.camera.width
    arrays = {
        "depth": np.stack(cols["depth"]).astype(np.uint16),
        "mask": np.stack(cols["mask"]).astype(np.uint8),
        "scene_index": np.asarray(cols["scene_index"], dtype=np.int64),
        "seed": np.asarray(cols["seed"], dtype=np.int64).reshape(-1, 3),
        "num_boxes": np.asarray(cols["num_boxes"], dtype=np.int32),
        "num_dropped": np.asarray(cols["num_dropped"], dtype=np.int32),
        "num_removed": np.asarray(cols["num_removed"], dtype=np.int32),
        "settle_steps": np.asarray(cols["settle_steps"], dtype=np.int32),
        "settled": np.asarray(cols["settled"], dtype=bool),
        "box_type": np.asarray(cols["box_type"], dtype=np.int16),
        "box_size": np.asarray(cols["box_size"], dtype=np.float64).reshape(-1, 3),
        "box_mass": np.asarray(cols["box_mass"], dtype=np.float64),
        "box_T_world": np.asarray(cols["box_T_world"], dtype=np.float64).reshape(-1, 4, 4),
        "box_T_cam": np.asarray(cols["box_T_cam"], dtype=np.float64).reshape(-1, 4, 4),
    }
    if keep_clean:
        arrays["depth_clean"] = np.stack(cols["depth_clean"]).astype(np.uint16)
    assert arrays["depth"].shape == (task.count, H, W)
    Path(task.path).parent.mkdir(parents=True, exist_ok=True)
    write_npz(Path(task.path), arrays)
    return ShardSummary(
        task,
        arrays["num_boxes"],
        arrays["num_removed"],
        arrays["settle_steps"],
        arrays["settled"],
        time.perf_counter() - t0,
    )


def shard_from_file(task: ShardTask) -> ShardSummary | None:
    """The summary of a shard an interrupted run already wrote (None if the file is missing,
    unreadable or not this task's scenes): what ``generate_shard`` returned, from the file."""
    path = Path(task.path)
    if not path.is_file():
        return None
    try:
        arrays = read_npz(path)  # reads every member: a damaged file fails its CRC check
        ok = np.array_equal(arrays["scene_index"], np.arange(task.first, task.first + task.count))
        summary = ShardSummary(
            task,
            arrays["num_boxes"],
            arrays["num_removed"],
            arrays["settle_steps"],
            arrays["settled"],
            0.0,
        )
    except Exception:
        return None
    return summary if ok else None


def run_shards(tasks: list[ShardTask], cfg_obj, workers: int, progress: bool = True):
    """Yield each shard's summary in task order, computed by ``workers`` processes."""
    return map_shards(
        generate_shard,
        tasks,
        init=_init_worker,
        initargs=(cfg_obj,),
        workers=workers,
        desc=STAGE,
        progress=progress,
        executor=cfg_obj.executor,
    )


def _log_static(log: StageLog, cfg_obj) -> None:
    b = cfg_obj.bin
    t, ft = b.wall_thickness, b.floor_thickness
    lx, ly, h = b.inner_length_x, b.inner_width_y, b.wall_height
    centers = [
        [0, 0, -ft / 2],
        [-(lx + t) / 2, 0, (h - ft) / 2],
        [(lx + t) / 2, 0, (h - ft) / 2],
        [0, -(ly + t) / 2, (h - ft) / 2],
        [0, (ly + t) / 2, (h - ft) / 2],
    ]
    sizes = [
        [lx + 2 * t, ly + 2 * t, ft],
        [t, ly + 2 * t, h + ft],
        [t, ly + 2 * t, h + ft],
        [lx, t, h + ft],
        [lx, t, h + ft],
    ]
    log.log_boxes(
        "world/bin",
        np.asarray(centers, float),
        np.asarray(sizes, float),
        np.tile([0.0, 0.0, 0.0, 1.0], (5, 1)),
        labels=["floor"] + ["wall"] * 4,
        static=True,
    )


def _log_scene(log: StageLog, scene, log_index: int, dt: float) -> None:
    log.set_time(
        sequences={"scene": log_index},
        durations_s={"sim_time": scene.settle_steps * dt},
        clock_ns=log_index * 1_000_000_000,
    )
    log.log_camera("world/camera", scene.intrinsics, scene.T_world_cam)
    log.log_depth("world/camera/depth", scene.depth_m)
    log.log_segmentation("world/camera/mask", scene.mask)
    centers = np.array([b.T_world_box[:3, 3] for b in scene.boxes]).reshape(-1, 3)
    sizes = np.array([b.size for b in scene.boxes]).reshape(-1, 3)
    quats = np.array([quat_from_matrix(b.T_world_box[:3, :3]) for b in scene.boxes]).reshape(-1, 4)
    log.log_boxes(
        "world/boxes",
        centers,
        sizes,
        quats,
        labels=[f"{b.instance}:{b.type_name}" for b in scene.boxes],
    )
    log.log_scalar("metrics/boxes_per_scene", float(len(scene.boxes)))
    log.log_text(
        "log",
        f"{scene.split} scene {scene.index}: {len(scene.boxes)} boxes at rest "
        f"after {scene.settle_steps} steps (seed {scene.seed})",
    )


def _metrics(summaries: list[ShardSummary], sizes: dict[str, int], max_count: int) -> dict:
    out: dict = {"scenes": dict(sizes), "splits": {}}
    for split in SPLITS:
        ss = [s for s in summaries if s.task.split == split]
        if not ss:
            out["splits"][split] = {"scenes": 0}
            continue
        nb = np.concatenate([s.num_boxes for s in ss])
        steps = np.concatenate([s.settle_steps for s in ss])
        out["splits"][split] = {
            "scenes": int(len(nb)),
            "boxes": int(nb.sum()),
            "boxes_per_scene_mean": round(float(nb.mean()), 3),
            "boxes_per_scene_histogram": np.bincount(nb, minlength=max_count + 1).tolist(),
            "boxes_removed_outside_bin": int(np.concatenate([s.num_removed for s in ss]).sum()),
            "scenes_not_settled": int((~np.concatenate([s.settled for s in ss])).sum()),
            "settle_steps_median": float(np.median(steps)),
            "settle_steps_p90": float(np.percentile(steps, 90)),
        }
    return out


def stores_clean_depth(cfg) -> bool:
    """Whether the shards also hold the ideal ``depth_clean``: a sensor model or camera
    randomisation makes ``depth`` differ from it."""
    return bool(cfg.sensor.enabled) or bool(cfg.generate.camera_randomisation.enabled)


def box_types_meta(cfg) -> list[dict]:
    """camera.json's ``box_types``: the set's types, then ``carton`` (no fixed size) when the
    boxes of some split come from ``boxes.cartons`` (their type index is ``len(types)``)."""
    types = OmegaConf.to_container(cfg.boxes.types, resolve=True)
    if cfg.boxes.cartons is not None and list(cfg.generate.carton_splits):
        types.append({"name": "carton", "size": None})
    return types


def check_size_jitter(gcfg) -> None:
    """``generate.size_jitter`` in [0, 1) and ``generate.size_jitter_splits`` names splits."""
    if not 0 <= float(gcfg.size_jitter) < 1:
        raise ValueError(
            f"generate.size_jitter must be in [0, 1) (a fraction of each edge), got "
            f"{gcfg.size_jitter}; 0 keeps the box types' exact sizes"
        )
    check_splits("generate.size_jitter_splits", gcfg.size_jitter_splits)


def check_splits(key: str, names) -> None:
    """``names`` (the config's ``key``) are all splits of ``SPLITS``."""
    unknown = sorted(set(names) - set(SPLITS))
    if unknown:
        raise ValueError(f"{key} has {unknown}: choose from {list(SPLITS)}")


def generate(cfg: DictConfig) -> Path:
    """Run the generation stage; returns the artifact folder (reused if it already exists)."""
    config = stage_config(cfg, SECTIONS, NOT_AFFECTING_RESULT)
    cfg_obj = OmegaConf.to_object(cfg)  # plain dataclasses: fast, picklable for the workers
    sizes = split_sizes(cfg_obj.generate)
    if not cfg_obj.boxes.types:
        raise ValueError("boxes.types is empty: the box set needs at least one box type")
    check_size_jitter(cfg_obj.generate)
    check_splits("generate.carton_splits", cfg_obj.generate.carton_splits)
    if cfg_obj.boxes.cartons is not None:
        check_cartons(cfg_obj.boxes.cartons)
    check_splits(
        "generate.camera_randomisation.splits", cfg_obj.generate.camera_randomisation.splits
    )
    check_randomisation(cfg_obj.generate.camera_randomisation)
    check_renderer(cfg_obj.camera.renderer)
    workers = resolve_workers(cfg_obj.generate.workers, cfg_obj.executor)

    def body(run: StageRun) -> None:
        tasks = plan_shards(cfg_obj.generate, run.work_dir)
        # an interrupted run's finished shards are kept; everything else is redone
        done: dict[ShardTask, ShardSummary] = run.finished_shards(
            tasks, [t.path for t in tasks], shard_from_file, lambda t: t.path
        )

        _write_meta(run, cfg, cfg_obj, tasks)

        t0 = time.perf_counter()
        todo = [t for t in tasks if t not in done]
        done.update(zip(todo, list(run_shards(todo, cfg_obj, workers, cfg_obj.logging.progress))))
        summaries = [done[t] for t in tasks]
        run.timings["simulate_s"] = round(time.perf_counter() - t0, 3)
        run.timings["workers"] = workers
        n_simulated = sum(t.count for t in todo)
        run.timings["scenes_per_s"] = round(n_simulated / max(run.timings["simulate_s"], 1e-9), 3)
        if run.resumed:
            run.timings["shards_resumed"] = len(tasks) - len(todo)

        t1 = time.perf_counter()
        quota = log_quota(sizes, cfg_obj.logging.max_logged_scenes)
        with StageLog.for_stage(run.work_dir, STAGE, run.version, default_blueprint()) as log:
            _log_static(log, cfg_obj)
            log_index = 0
            for split in SPLITS:
                ds = SceneDataset(run.work_dir, split)
                for i in range(quota[split]):
                    _log_scene(log, ds[i], log_index, cfg_obj.physics.time_step)
                    log_index += 1
        run.timings["log_s"] = round(time.perf_counter() - t1, 3)
        run.metrics.update(_metrics(summaries, sizes, cfg_obj.boxes.max_count))
        run.metrics["logged_scenes"] = log_index

    return run_stage_from_config(cfg, STAGE, config, {}, body, resumable=True)


def _write_meta(run: StageRun, cfg: DictConfig, cfg_obj, tasks: list[ShardTask]) -> None:
    """``camera.json`` (intrinsics, camera pose, depth unit, renderer, sensor, frames, bin, box
    types) and ``index.json`` (the shards of each split)."""
    intr = Intrinsics.from_config(cfg_obj.camera)
    T_world_cam = camera_pose_above_bin(cfg_obj.camera.height_above_bin_floor)
    (run.work_dir / "camera.json").write_text(
        json.dumps(
            {
                "intrinsics": intr.as_dict(),
                "T_world_cam": T_world_cam.tolist(),
                "depth_unit": cfg_obj.generate.depth_unit,
                "renderer": cfg_obj.camera.renderer,  # how the ideal depth was rendered
                # the sensor model of `depth`; with one, shards also hold the ideal
                # `depth_clean`
                "sensor": OmegaConf.to_container(cfg.sensor, resolve=True),
                "frames": {
                    "camera": "OpenCV: x right, y down, z forward; metres",
                    "world": "z up; origin at the centre of the bin floor's top surface",
                },
                "bin": OmegaConf.to_container(cfg.bin, resolve=True),
                "box_types": box_types_meta(cfg),
            },
            indent=2,
        )
        + "\n"
    )
    index = {"splits": shard_index(tasks, run.work_dir, SPLITS, lambda t: t.path)}
    (run.work_dir / "index.json").write_text(json.dumps(index, indent=2) + "\n")


main = stage_command("generate", generate)


if __name__ == "__main__":
    main()
