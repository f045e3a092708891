"""Out-of-domain training data for the Dex-Net-style GQ-CNN: labelled candidates on heaps of
objects other than boxes (Dex-Net 4.0 trained on thousands of object meshes unlike its test
objects; docs/baseline.md).

One scene (``object_heap_scene``): the cell of ``pipeline.simulation.heap`` with a heap of the
random convex objects of ``conf/objects/`` dropped and settled by the box heaps' physics
(``pipeline.simulation.object_heap``), seen by the same camera from the same pose, rendered
exactly (``camera.renderer=raycast``: ``pipeline.camera.raycast_convex``; ``tinyrenderer``:
pybullet's rasteriser), passed through the same sensor model and stored-depth rounding
(``generate.depth_unit``) as a generated box heap; then suction candidates sampled on the
sensor's depth exactly as the in-domain candidates are (segmask, ``pipeline.dexnet.sampling``)
and each labelled, while the pybullet scene is live, by the mesh contact model
(``pipeline.dexnet.contact_mesh``) on the ideal depth and the true bodies: the same rules,
settings and robust quality as the box contact model, with each object's own mass and centre of
mass. The GQ-CNN inputs (crop, pose) are cut here too, from the depth the planner would see,
since the scene's images are not kept.

Frames: candidates and images in the camera frame (OpenCV: x right, y down, z forward), the
heap in the world frame (z up, origin at the centre of the bin floor's top); metres.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pybullet as p

from pipeline.camera.geometry import Intrinsics, camera_pose_above_bin, gravity_in_camera
from pipeline.camera.raycast_convex import render_convex_depth
from pipeline.camera.render import check_renderer, render_depth
from pipeline.camera.sensor import apply_sensor_model
from pipeline.cell.bin import build_cell
from pipeline.dexnet.contact import LABELLED_CANDIDATE_FIELDS
from pipeline.dexnet.contact_mesh import (
    BodyScene,
    RayScene,
    evaluate_contacts_mesh,
    robust_quality_mesh,
)
from pipeline.dexnet.gqcnn import candidate_inputs
from pipeline.dexnet.planner import crop_config, sampler_config, workspace
from pipeline.dexnet.sampling import Candidates, point_cloud_image, sample_candidates
from pipeline.grasping.suction import suction_model_config
from pipeline.simulation.object_heap import ObjectHeap, drop_object_heap
from pipeline.simulation.scene import instance_mask

# An object heap's generator is seeded by (seed, OOD_SEED, split code, index): four numbers, so
# it never equals a box heap's (seed, split code, index) (pipeline.simulation.scene.scene_rng).
OOD_SEED = 7


def object_scene_rng(seed: int, split_code: int, index: int) -> np.random.Generator:
    """The generator of object heap ``index`` of a split: every draw of the scene (heap, sensor,
    candidates, perturbations) comes from it."""
    return np.random.default_rng([int(seed), OOD_SEED, int(split_code), int(index)])


@dataclass
class ObjectHeapScene:
    """One labelled object heap.

    Attributes:
        depth_m: (H, W) float32 z-depth the planner sees (sensor model, then rounding to
            ``generate.depth_unit``), m; 0 = no data.
        depth_clean_m: (H, W) float32 ideal z-depth, rounded the same way, m.
        mask: (H, W) uint8 instance mask: 0 = not an object, k = ``heap.objects[k-1]``.
        intrinsics: the camera's; T_world_cam: (4, 4) its pose (OpenCV axes), world frame.
        heap: the objects at rest (their pybullet bodies are gone once the client is reset).
        candidates: (M,) suction candidates sampled on ``depth_m``, camera frame.
        quality: (M,) float64 robust quality in [0, 1] (``robust_quality_mesh``).
        label: (M,) bool ``quality >= suction.quality_threshold``.
        reason: (M,) int8 unperturbed contact outcome, index into ``contact.REASONS``.
        crops: (M, 1, S, S) float16 GQ-CNN crops of ``depth_m``; poses: (M, 2) float32.
    """

    depth_m: np.ndarray
    depth_clean_m: np.ndarray
    mask: np.ndarray
    intrinsics: Intrinsics
    T_world_cam: np.ndarray
    heap: ObjectHeap
    candidates: Candidates
    quality: np.ndarray
    label: np.ndarray
    reason: np.ndarray
    crops: np.ndarray
    poses: np.ndarray


def label_candidates(
    client: int,
    graspable: list[int],
    cands: Candidates,
    depth_clean_m: np.ndarray,
    mask: np.ndarray,
    intrinsics: Intrinsics,
    T_world_cam: np.ndarray,
    model,
    rng: np.random.Generator,
) -> tuple[np.ndarray, np.ndarray]:
    """Robust quality and unperturbed contact outcome of candidates on the live bodies of
    ``client`` (``contact_mesh``; one ``RayScene`` mirror for both), gravity along world -z.

    Args:
        client: the pybullet client, posed as in the image; graspable: its object body ids,
            in mask order (mask value k = ``graspable[k-1]``).
        cands: (M,) candidates, camera frame; depth_clean_m, mask: (H, W) ideal depth (m) and
            instance mask of the image; intrinsics, T_world_cam: the camera's.
        model: the ``SuctionModelConfig``; rng: source of the perturbations.

    Returns:
        quality: (M,) float64 in [0, 1]; reason: (M,) int8 index into ``contact.REASONS``.
    """
    if len(cands) == 0 or not graspable:
        return np.zeros(len(cands)), np.zeros(len(cands), np.int8)
    g = gravity_in_camera(T_world_cam)
    truth = BodyScene(depth_clean_m, mask, intrinsics, g, T_world_cam, client, list(graspable))
    with RayScene(client) as rays:
        quality = robust_quality_mesh(cands.point, cands.axis, truth, model, rng, rays=rays)
        reason = evaluate_contacts_mesh(cands.point, cands.axis, truth, model, rays=rays).reason
    return np.asarray(quality, np.float64), np.asarray(reason, np.int8)


def _stored(depth_m: np.ndarray, unit: float) -> np.ndarray:
    """Depth as a generation shard stores and returns it: rounded to ``unit`` (uint16), m."""
    return np.round(np.asarray(depth_m, np.float64) / unit).astype(np.uint16).astype(
        np.float32
    ) * np.float32(unit)


def object_heap_scene(
    client: int, cfg, rng: np.random.Generator, count: int, sensor_cfg, depth_unit: float
) -> ObjectHeapScene:
    """Build, render, sample and label one object heap in the pybullet client ``client`` (reset).

    Args:
        client: a pybullet client (``connect``); its simulation is reset here.
        cfg: a composed config (sections ``objects``, ``bin``, ``physics``, ``camera``,
            ``dexnet``, ``suction``, ``hand``).
        rng: the scene's generator (``object_scene_rng``). Draws, in order: the heap, the sensor
            model, the candidates, the perturbations of the robust quality.
        count: the candidates to sample (fewer when the heap offers fewer acceptable pixels).
        sensor_cfg, depth_unit: the sensor model (a ``SensorConfig``, or any object with its
            attributes) and stored-depth unit (m) of the box heaps the planner is tested on (a
            generation artifact's ``camera.json``), so both training sets see the same sensor.
    """
    renderer = str(cfg.camera.renderer)
    check_renderer(renderer)
    cell = build_cell(client, cfg.bin, cfg.physics)
    # the object heaps' own solver iterations (conf/objects/: few small contacts settle at fewer)
    p.setPhysicsEngineParameter(
        numSolverIterations=int(cfg.objects.solver_iterations), physicsClientId=client
    )
    heap = drop_object_heap(client, rng, cfg.objects, cfg.bin, cfg.physics)
    intr = Intrinsics.from_config(cfg.camera)
    T_world_cam = camera_pose_above_bin(cfg.camera.height_above_bin_floor)
    ids = [o.body_id for o in heap.objects]
    ground = (-float(cfg.bin.floor_thickness), cell[0])
    view = (client, intr, T_world_cam, cfg.camera.near, cfg.camera.far)
    if renderer == "raycast":
        frame = render_convex_depth(*view, ground=ground, bodies=cell[1:] + ids)
    else:
        frame = render_depth(*view, ground=ground, renderer=renderer)
    mask = instance_mask(frame.body_ids, ids)
    unit = float(depth_unit)
    depth = _stored(apply_sensor_model(frame.depth_m, sensor_cfg, rng, intr), unit)
    depth_clean = _stored(frame.depth_m, unit)

    sampler = sampler_config(cfg)
    object_mask = workspace(cfg, T_world_cam).object_mask(depth, intr)
    cloud = point_cloud_image(depth, intr, sampler, object_mask=object_mask)
    cands = sample_candidates(cloud, int(count), rng, sampler)
    model = suction_model_config(cfg, float(cfg.objects.density))
    quality, reason = label_candidates(
        client, ids, cands, depth_clean, mask, intr, T_world_cam, model, rng
    )
    crop = crop_config(cfg)
    crops, poses = candidate_inputs(depth, cands, crop)
    crops = np.asarray(crops, np.float16).reshape(len(cands), 1, crop.size, crop.size)
    quality = np.asarray(quality, np.float64)
    return ObjectHeapScene(
        depth_m=depth,
        depth_clean_m=depth_clean,
        mask=mask,
        intrinsics=intr,
        T_world_cam=T_world_cam,
        heap=heap,
        candidates=cands,
        quality=quality,
        label=quality >= model.quality_threshold,
        reason=np.asarray(reason, np.int8),
        crops=crops,
        poses=np.asarray(poses, np.float32).reshape(len(cands), 2),
    )


# --------------------------------------------------------------------------------------------
# Shards of labelled object heaps (the baseline stage's ``ood/<split>-<shard>.npz``)

# One row per labelled candidate in a shard file (scene-level: ``heap_*``):
OOD_FIELDS = {
    "scene_index": "(M,) int64 object heap index within the split",
    **LABELLED_CANDIDATE_FIELDS,
    "crop": "(M, 1, S, S) float16 GQ-CNN crop (dexnet.crop) of the depth the planner sees",
    "pose": "(M, 2) float32 GQ-CNN pose input (depth, approach angle)",
    "heap_objects": "(N,) int32 objects at rest per heap of the shard",
    "heap_settled": "(N,) bool whether the heap came to rest within physics.max_settle_steps",
}
SPLIT_CODES = {"train": 0, "val": 1}  # the object heaps have no test split: Table 2 is on boxes


@dataclass(frozen=True)
class OODTask:
    """Object heaps ``first`` .. ``first + count - 1`` of ``split``, written to ``path``."""

    split: str
    first: int
    count: int
    path: str


def plan_ood_tasks(ood_cfg, folder) -> list[OODTask]:
    """Shards of ``ood_cfg.scenes_per_shard`` heaps for the train and val splits
    (``baseline.ood``), their files ``<folder>/<split>-<shard>.npz``."""
    from pathlib import Path

    per = int(ood_cfg.scenes_per_shard)
    tasks = []
    for split, n in (("train", int(ood_cfg.num_scenes)), ("val", int(ood_cfg.num_val_scenes))):
        for k, first in enumerate(range(0, n, per)):
            tasks.append(
                OODTask(
                    split, first, min(per, n - first), str(Path(folder) / f"{split}-{k:05d}.npz")
                )
            )
    return tasks


def check_ood_config(cfg) -> None:
    """Refuse a ``baseline.ood`` / ``objects`` config that cannot make a training set, before any
    work, saying which key to change."""
    from pipeline.simulation.object_heap import object_spec
    from pipeline.simulation.objects import FAMILIES

    ood = cfg.baseline.ood
    for key in ("num_scenes", "scenes_per_shard", "candidates_per_scene"):
        if int(ood[key]) < 1:
            raise ValueError(
                f"baseline.ood.{key} must be >= 1 for the gqcnn_ood variant, got "
                f"{ood[key]} (or leave gqcnn_ood out of baseline.variants)"
            )
    if int(ood.num_val_scenes) < 0:
        raise ValueError(f"baseline.ood.num_val_scenes must be >= 0, got {ood.num_val_scenes}")
    spec = object_spec(cfg.objects)
    unknown = sorted(set(spec.families) - set(FAMILIES))
    if not list(spec.families) or unknown:
        raise ValueError(
            f"objects.families must be a non-empty selection of {list(FAMILIES)}, "
            f"got {list(spec.families)} (conf/objects/)"
        )
    lo, hi = int(cfg.objects.min_count), int(cfg.objects.max_count)
    if not 1 <= lo <= hi:
        raise ValueError(
            f"objects.min_count and max_count must satisfy 1 <= min <= max (an "
            f"empty heap has nothing to learn from), got {lo} and {hi}"
        )


def shard_summary(split: str, arrays: dict, num_reasons: int) -> dict:
    """Counts of one shard for the stage's manifest."""
    return {
        "split": split,
        "scenes": int(len(arrays["heap_objects"])),
        "objects": int(arrays["heap_objects"].sum()),
        "not_settled": int((~arrays["heap_settled"].astype(bool)).sum()),
        "candidates": int(len(arrays["label"])),
        "positives": int(arrays["label"].sum()),
        "reasons": np.bincount(arrays["reason"].astype(np.int64), minlength=num_reasons).tolist(),
    }


_STATE: dict = {}


def init_ood_worker(cfg_obj, sensor_cfg, depth_unit: float) -> None:
    """Per process: the config, the box heaps' sensor and depth unit, a pybullet client."""
    if _STATE.get("client") is not None:
        p.disconnect(physicsClientId=_STATE["client"])
    _STATE.clear()
    _STATE.update(cfg=cfg_obj, sensor=sensor_cfg, unit=float(depth_unit), client=connect())


def ood_shard(task: OODTask) -> dict:
    """Build and label the heaps of one shard; writes its file, returns ``shard_summary``."""
    from pathlib import Path

    from pipeline.dataset.storage import write_npz
    from pipeline.dexnet.contact import REASONS

    cfg = _STATE["cfg"]
    count = int(cfg.baseline.ood.candidates_per_scene)
    cols: dict[str, list] = {k: [] for k in OOD_FIELDS}
    for index in range(task.first, task.first + task.count):
        rng = object_scene_rng(int(cfg.seed), SPLIT_CODES[task.split], index)
        scene = object_heap_scene(
            _STATE["client"], cfg, rng, count, _STATE["sensor"], _STATE["unit"]
        )
        c = scene.candidates
        m = len(c)
        cols["scene_index"].append(np.full(m, index, np.int64))
        cols["uv"].append(c.uv.astype(np.int64).reshape(-1, 2))
        cols["point"].append(c.point.reshape(-1, 3))
        cols["axis"].append(c.axis.reshape(-1, 3))
        cols["depth"].append(c.depth.astype(np.float64))
        cols["angle"].append(c.angle.astype(np.float64))
        cols["quality"].append(scene.quality)
        cols["label"].append(scene.label)
        cols["reason"].append(scene.reason)
        cols["crop"].append(scene.crops)
        cols["pose"].append(scene.poses)
        cols["heap_objects"].append(np.array([len(scene.heap.objects)], np.int32))
        cols["heap_settled"].append(np.array([scene.heap.settled], bool))
    arrays = {k: np.concatenate(v) for k, v in cols.items()}
    Path(task.path).parent.mkdir(parents=True, exist_ok=True)
    write_npz(Path(task.path), arrays)
    return shard_summary(task.split, arrays, len(REASONS))


def ood_shard_from_file(task: OODTask) -> dict | None:
    """The summary of a shard an interrupted run already wrote, or None when the file is
    missing, unreadable or not this task's heaps (it is then computed again)."""
    from pathlib import Path

    from pipeline.dataset.storage import read_npz
    from pipeline.dexnet.contact import REASONS

    if not Path(task.path).is_file():
        return None
    try:
        arrays = read_npz(Path(task.path))
        ok = (
            set(arrays) == set(OOD_FIELDS)
            and len(arrays["heap_objects"]) == task.count
            and np.all(
                (arrays["scene_index"] >= task.first)
                & (arrays["scene_index"] < task.first + task.count)
            )
        )
        return shard_summary(task.split, arrays, len(REASONS)) if ok else None
    except Exception:
        return None


def load_ood(paths) -> dict[str, np.ndarray]:
    """Every row of the shard files ``paths``, concatenated ({} when there is none)."""
    from pipeline.dataset.storage import read_npz

    parts = [read_npz(path) for path in paths]
    if not parts:
        return {}
    return {k: np.concatenate([part[k] for part in parts]) for k in parts[0]}


def connect() -> int:
    """A headless pybullet client for ``object_heap_scene``."""
    return p.connect(p.DIRECT)
