"""The Dex-Net-style planner's training labels on the box heaps (paper Sec. 8.1.1): candidates
sampled as the policy samples them, labelled by the suction contact model (``contact``) on the
scene's true boxes, written one shard of scenes at a time (resumable)."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pipeline.artifacts import artifact_file
from pipeline.camera.geometry import gravity_in_camera
from pipeline.dataset.scenes import SPLIT_CODES, SPLITS, Scene, SceneDataset
from pipeline.dataset.storage import read_npz, write_npz
from pipeline.dexnet.contact import (
    LABELLED_CANDIDATE_FIELDS,
    REASONS,
    BoxScene,
    evaluate_contacts,
    robust_quality,
)
from pipeline.dexnet.planner import sampler_config, workspace
from pipeline.dexnet.sampling import point_cloud_image, sample_candidates
from pipeline.grasping.suction import suction_model_config

LABEL_SEED = 5  # candidate sampling and robustness for a scene: (seed, LABEL_SEED, split, index)


# One row per labelled candidate in candidates/<split>-<shard>.npz:
CANDIDATE_FIELDS = {
    "scene_index": "(M,) int64 scene index within the split",
    **LABELLED_CANDIDATE_FIELDS,
}


def label_scene_candidates(scene: Scene, cfg, count: int) -> dict[str, np.ndarray]:
    """Sample ``count`` candidates on one scene as the policy would and label them."""
    rng = np.random.default_rng([int(cfg.seed), LABEL_SEED, SPLIT_CODES[scene.split], scene.index])
    ws = workspace(cfg, scene.T_world_cam)
    mask = ws.object_mask(scene.depth_m, scene.intrinsics)
    cloud = point_cloud_image(
        scene.depth_m, scene.intrinsics, sampler_config(cfg), object_mask=mask
    )
    cands = sample_candidates(cloud, count, rng, sampler_config(cfg))
    model = suction_model_config(cfg, float(cfg.boxes.density))
    g = gravity_in_camera(scene.T_world_cam)
    # candidates come from what the sensor saw; their labels from the ideal depth (the geometry)
    truth = BoxScene(scene.depth_clean_m, scene.mask, scene.intrinsics, g, scene.boxes)
    if len(cands):
        quality = robust_quality(cands.point, cands.axis, truth, model, rng=rng)
        reason = evaluate_contacts(cands.point, cands.axis, truth, model).reason
    else:
        quality, reason = np.zeros(0), np.zeros(0, np.int8)
    return {
        "scene_index": np.full(len(cands), scene.index, np.int64),
        "uv": cands.uv.astype(np.int64).reshape(-1, 2),
        "point": cands.point.reshape(-1, 3),
        "axis": cands.axis.reshape(-1, 3),
        "depth": cands.depth.astype(np.float64),
        "angle": cands.angle.astype(np.float64),
        "quality": np.asarray(quality, np.float64),
        "label": np.asarray(quality, np.float64) >= model.quality_threshold,
        "reason": np.asarray(reason, np.int8),
    }


@dataclass
class CandidateTask:
    split: str
    first: int
    count: int
    out_path: str


_STATE: dict = {}


def init_worker(cfg_obj, gen_dir: str) -> None:
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
    return label_summary(task, arrays)


def label_summary(task: CandidateTask, arrays: dict) -> dict:
    return {
        "split": task.split,
        "scenes": task.count,
        "candidates": int(len(arrays["label"])),
        "positives": int(arrays["label"].sum()),
        "reasons": np.bincount(arrays["reason"].astype(np.int64), minlength=len(REASONS)).tolist(),
    }


def label_shard_from_file(task: CandidateTask) -> dict | None:
    """The summary of a candidate shard an interrupted run already wrote (None: redo it)."""
    if not Path(task.out_path).is_file():
        return None
    try:
        arrays = read_npz(Path(task.out_path))
        idx = arrays["scene_index"]
        ok = set(arrays) == set(CANDIDATE_FIELDS) and bool(
            np.all((idx >= task.first) & (idx < task.first + task.count))
        )
        return label_summary(task, arrays) if ok else None
    except Exception:
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
            tasks.append(
                CandidateTask(split, shard["first"], count, str(out_dir / "candidates" / name))
            )
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
