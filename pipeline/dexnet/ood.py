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

from pipeline.camera.geometry import (
    Intrinsics, camera_pose_above_bin, gravity_in_camera,
)
from pipeline.camera.raycast_convex import render_convex_depth
from pipeline.camera.render import check_renderer, render_depth
from pipeline.camera.sensor import apply_sensor_model
from pipeline.dexnet.contact import suction_model_config
from pipeline.dexnet.contact_mesh import RayScene, evaluate_contacts_mesh, robust_quality_mesh
from pipeline.dexnet.gqcnn import candidate_inputs
from pipeline.dexnet.planner import crop_config, sampler_config, workspace
from pipeline.dexnet.sampling import Candidates, point_cloud_image, sample_candidates
from pipeline.simulation.heap import build_cell
from pipeline.simulation.object_heap import ObjectHeap, drop_object_heap

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


def _stored(depth_m: np.ndarray, unit: float) -> np.ndarray:
    """Depth as a generation shard stores and returns it: rounded to ``unit`` (uint16), m."""
    return (np.round(np.asarray(depth_m, np.float64) / unit).astype(np.uint16)
            .astype(np.float32) * np.float32(unit))


def object_heap_scene(client: int, cfg, rng: np.random.Generator, count: int) -> ObjectHeapScene:
    """Build, render, sample and label one object heap in the pybullet client ``client`` (reset).

    ``cfg``: a composed config (``objects``, ``bin``, ``physics``, ``camera``, ``sensor``,
    ``generate.depth_unit``, ``dexnet``, ``suction``, ``hand``); ``count``: the candidates to
    sample (fewer when the heap offers fewer acceptable pixels). Draws from ``rng``, in order:
    the heap, the sensor model, the candidates, the perturbations of the robust quality.
    """
    renderer = str(cfg.camera.renderer)
    check_renderer(renderer)
    cell = build_cell(client, cfg.bin, cfg.physics)
    heap = drop_object_heap(client, rng, cfg.objects, cfg.bin, cfg.physics)
    intr = Intrinsics.from_config(cfg.camera)
    T_world_cam = camera_pose_above_bin(cfg.camera.height_above_bin_floor)
    ids = [o.body_id for o in heap.objects]
    ground = (-float(cfg.bin.floor_thickness), cell[0])
    if renderer == "raycast":
        frame = render_convex_depth(client, intr, T_world_cam, cfg.camera.near, cfg.camera.far,
                                    ground=ground, bodies=cell[1:] + ids)
    else:
        frame = render_depth(client, intr, T_world_cam, cfg.camera.near, cfg.camera.far,
                             ground=ground, renderer=renderer)
    lut = np.zeros(int(frame.body_ids.max(initial=-1)) + 2, dtype=np.uint8)
    for k, body in enumerate(ids, start=1):
        if body + 1 < len(lut):
            lut[body + 1] = k
    mask = lut[frame.body_ids + 1]
    unit = float(cfg.generate.depth_unit)
    depth = _stored(apply_sensor_model(frame.depth_m, cfg.sensor, rng, intr), unit)
    depth_clean = _stored(frame.depth_m, unit)

    sampler = sampler_config(cfg)
    object_mask = workspace(cfg, T_world_cam).object_mask(depth, intr)
    cloud = point_cloud_image(depth, intr, sampler, object_mask=object_mask)
    cands = sample_candidates(cloud, int(count), rng, sampler)
    model = suction_model_config(cfg, float(cfg.objects.density))
    if len(cands) and ids:
        g = gravity_in_camera(T_world_cam)
        args = (depth_clean, mask, intr, T_world_cam, client, ids, g, model)
        with RayScene(client) as rays:
            quality = robust_quality_mesh(cands.point, cands.axis, *args, rng, rays=rays)
            reason = evaluate_contacts_mesh(cands.point, cands.axis, *args, rays=rays).reason
    else:
        quality, reason = np.zeros(len(cands)), np.zeros(len(cands), np.int8)
    crop = crop_config(cfg)
    crops, poses = candidate_inputs(depth, cands, crop)
    crops = np.asarray(crops, np.float16).reshape(len(cands), 1, crop.size, crop.size)
    quality = np.asarray(quality, np.float64)
    return ObjectHeapScene(depth_m=depth, depth_clean_m=depth_clean, mask=mask, intrinsics=intr,
                           T_world_cam=T_world_cam, heap=heap, candidates=cands,
                           quality=quality, label=quality >= model.quality_threshold,
                           reason=np.asarray(reason, np.int8), crops=crops,
                           poses=np.asarray(poses, np.float32).reshape(len(cands), 2))


def connect() -> int:
    """A headless pybullet client for ``object_heap_scene``."""
    return p.connect(p.DIRECT)
