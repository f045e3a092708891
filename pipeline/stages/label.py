"""The labelling stage (paper Sec. 4.3, Figs. 4b–4f, 5, 6): grasp points and their classes.

For every generated depth image:

1. **Surfaces** (Fig. 4b–c): the point cloud is split into per-object clusters with the
   simulator's instance mask (standing in for the paper's PCL box-filter crop), and every visible
   planar face is found by repeated RANSAC plane fits (``pipeline.grasping.surfaces``). Each
   surface gives a grasp point g = its centre in pixels, a normal, long/short axes and lengths.
2. **Hand level** (Figs. 5, 6): B, L, R or NG from the surface alone
   (``pipeline.grasping.hand``); also NG ("center_occluded") when the centre of the visible
   region falls on another box lying across the face (about 4 % of surfaces), and NG ("hold")
   when the pattern's cups would not hold the box's weight (``hand.hold_check``, an extension
   of the paper's rule: ``pipeline.labelling.scene``).
3. **Robot level** (Fig. 4e): for B, L and R, the robot (``pipeline.robot``) must reach the
   target camera pose (inverse kinematics checked by forward kinematics), within joint limits,
   without the arm or hand touching the bin or other boxes; otherwise NG with the failed check.

Labels are computed from the ideal depth (``Scene.depth_clean_m``): when the generation artifact
has a sensor model (``sensor=sr300``), the network is trained on the noisy images with the labels
of the true geometry.

Detected surfaces are also matched against the true visible faces computed from the
simulator's box poses; the accuracy goes into the manifest.

Artifact (``data/label/<version>/``): ``labels/<split>-<shard>.npz`` aligned with the
generation shards, one row per grasp point (see ``pipeline.dataset.labels.LABEL_FIELDS``), plus
``log.rrd``/``log.mcap``.
Interrupted runs resume (``pipeline.artifacts.store``): a rerun keeps the label shards a killed
run finished, rebuilding their summaries from the files and from each shard's accuracy records
(kept in the work folder's ``.resume/``, not in the artifact), and labels the rest.

    python -m pipeline.stages.label experiment=smoke \
        [label.generate_version=<version>] [label.robot_checks=false]
"""

from __future__ import annotations

import dataclasses
import json
import os
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from omegaconf import DictConfig, OmegaConf

from pipeline.artifacts import artifact_file, stage_config
from pipeline.artifacts.store import StageRun
from pipeline.camera.geometry import quat_from_axes
from pipeline.dataset.labels import LABEL_FIELDS, LabelSet
from pipeline.dataset.scenes import SPLITS, Scene, SceneDataset
from pipeline.dataset.storage import read_npz, shard_index, write_npz
from pipeline.grasping.types import CLASS_COLORS, NG_REASONS, GraspClass
from pipeline.labelling.scene import label_scene
from pipeline.labelling.surface_truth import aggregate
from pipeline.runtime.cli import stage_command
from pipeline.runtime.executor import log_quota, map_shards, resolve_workers
from pipeline.runtime.stage_artifacts import run_stage_from_config, upstream_artifact
from pipeline.tracking import StageLog, default_blueprint

STAGE = "label"
# boxes, physics, suction: the hold check (hand.hold_check) weighs the boxes against the cups
SECTIONS = ("hand", "surfaces", "label", "robot", "motion", "servo", "boxes", "physics", "suction")
NOT_AFFECTING_RESULT = ("label.workers", "label.force", "label.generate_version")


@dataclass(frozen=True)
class LabelTask:
    split: str
    gen_file: str  # generation shard (relative to the generation artifact)
    first: int
    count: int
    out_path: str
    state_path: str = ""  # resume data: the shard's accuracy records (not in the artifact)


@dataclass
class LabelSummary:
    task: LabelTask
    matches: list = field(default_factory=list)
    hand_counts: np.ndarray = field(default_factory=lambda: np.zeros(4, np.int64))
    final_counts: np.ndarray = field(default_factory=lambda: np.zeros(4, np.int64))
    reasons: dict = field(default_factory=dict)
    surface_s: float = 0.0
    robot_s: float = 0.0


_STATE: dict = {}

HOLD_MASSES = ("own", "heaviest")


def check_hold_mass(cfg) -> str:
    """``label.hold_mass``, validated: ``own`` or ``heaviest`` (the latter needs the carton
    distribution, ``boxes=cartons``)."""
    mode = str(cfg.label.hold_mass)
    if mode not in HOLD_MASSES:
        raise ValueError(f"label.hold_mass is {mode!r}: choose from {HOLD_MASSES}")
    if mode == "heaviest" and getattr(cfg.boxes, "cartons", None) is None:
        raise ValueError(
            "label.hold_mass=heaviest weighs a carton as the heaviest of its size "
            "in boxes.cartons, and this box set has none: use boxes=cartons, or "
            "label.hold_mass=own"
        )
    return mode


def weighed_for_hold(scene, cfg):
    """``scene`` with each drawn carton's mass as the hold check weighs it (``label.hold_mass``:
    its own, or the heaviest of its size that ``boxes.cartons`` draws); boxes without a drawn
    mass (a fixed set, weighed at its density) are left as they are."""
    if check_hold_mass(cfg) == "own":
        return scene
    from pipeline.simulation.cartons import heaviest_mass

    boxes = [
        b
        if b.mass is None
        else dataclasses.replace(b, mass=heaviest_mass(cfg.boxes.cartons, b.size))
        for b in scene.boxes
    ]
    return dataclasses.replace(scene, boxes=boxes)


def _init_worker(cfg_obj, gen_dir: str) -> None:
    _STATE.clear()
    _STATE["cfg"] = cfg_obj
    _STATE["gen_dir"] = Path(gen_dir)
    if cfg_obj.label.robot_checks:
        from pipeline.labelling.robot_check import RobotChecker

        _STATE["robot"] = RobotChecker(cfg_obj)


def label_shard(task: LabelTask) -> LabelSummary:
    cfg = _STATE["cfg"]
    ds = SceneDataset(_STATE["gen_dir"], task.split)
    summary = LabelSummary(task)
    cols: dict[str, list] = {}
    per_scene = []
    for index in range(task.first, task.first + task.count):
        scene = weighed_for_hold(ds[index], cfg)
        rows, match, ts, tr = label_scene(
            scene, cfg, _STATE.get("robot"), ds.bin, density=float(cfg.boxes.density)
        )
        summary.surface_s += ts
        summary.robot_s += tr
        summary.matches.append(match)
        rows["scene_index"] = np.full(len(rows["instance"]), index, np.int64)
        for k, v in rows.items():
            cols.setdefault(k, []).append(v)
        per_scene.append(len(rows["instance"]))
        _count_classes(summary, rows)
    arrays = {k: np.concatenate(v) for k, v in cols.items()}
    arrays["points_per_scene"] = np.asarray(per_scene, np.int32)
    if task.state_path:  # before the shard: a shard file that exists has its records
        state = Path(task.state_path)
        state.parent.mkdir(parents=True, exist_ok=True)
        tmp = state.with_name(state.name + ".part")
        tmp.write_text(json.dumps({"matches": summary.matches}, default=_plain))
        os.replace(tmp, state)
    Path(task.out_path).parent.mkdir(parents=True, exist_ok=True)
    write_npz(Path(task.out_path), arrays)
    return summary


def _count_classes(summary: LabelSummary, rows: dict[str, np.ndarray]) -> None:
    """Add grasp points' hand-level and final classes and NG reasons to ``summary``."""
    summary.hand_counts += np.bincount(rows["hand_class"], minlength=4)
    summary.final_counts += np.bincount(rows["grasp_class"], minlength=4)
    for code in rows["ng_reason"]:
        if code:
            name = NG_REASONS[code]
            summary.reasons[name] = summary.reasons.get(name, 0) + 1


def _plain(value):
    """JSON for numpy scalars in accuracy records (floats round-trip exactly through JSON)."""
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f"{type(value).__name__} is not JSON serialisable")


def shard_from_file(task: LabelTask) -> LabelSummary | None:
    """The summary of a shard an interrupted run already wrote, from its label file and its
    accuracy records (``task.state_path``): what ``label_shard`` returned, timings aside. None
    when either is missing, unreadable or not this task's scenes."""
    out, state = Path(task.out_path), Path(task.state_path) if task.state_path else None
    if state is None or not out.is_file() or not state.is_file():
        return None
    try:
        arrays = read_npz(out)  # reads every member: a damaged file fails its CRC check
        matches = json.loads(state.read_text())["matches"]
        per_scene = arrays["points_per_scene"]
        scenes = np.repeat(np.arange(task.first, task.first + task.count), per_scene)
        if (
            len(matches) != task.count
            or len(per_scene) != task.count
            or not np.array_equal(arrays["scene_index"], scenes)
        ):
            return None
        summary = LabelSummary(task, matches=matches)
        _count_classes(summary, arrays)
    except Exception:
        return None
    return summary


def plan_tasks(gen_dir: Path, out_dir: Path, state_dir: Path | None = None) -> list[LabelTask]:
    """One task per generation shard, writing ``out_dir/labels/<name>`` (and, with
    ``state_dir``, its resume data ``state_dir/labels/<name>.json``)."""
    index = json.loads((gen_dir / "index.json").read_text())
    tasks = []
    for split in SPLITS:
        for shard in index["splits"][split]:
            name = artifact_file(gen_dir, shard["file"]).name  # ArtifactError if outside
            state = str(state_dir / "labels" / f"{name}.json") if state_dir is not None else ""
            tasks.append(
                LabelTask(
                    split,
                    shard["file"],
                    shard["first"],
                    shard["count"],
                    str(out_dir / "labels" / name),
                    state,
                )
            )
    return tasks


def run_tasks(tasks, cfg_obj, gen_dir: Path, workers: int, progress: bool):
    """Yield each shard's summary in task order, computed by ``workers`` processes."""
    return map_shards(
        label_shard,
        tasks,
        init=_init_worker,
        initargs=(cfg_obj, str(gen_dir)),
        workers=workers,
        desc=STAGE,
        progress=progress,
        executor=cfg_obj.executor,
    )


ROBOT_SAMPLE_SCENES = 10  # logged scenes that also show the robot at a target pose


def _log_robot_sample(log: StageLog, scene: Scene, rows: dict, robot, bin_cfg) -> None:
    """The robot at the target pose of the scene's first graspable point (Fig. 4e): its link
    origins as a skeleton of points and the target camera as a frustum."""
    from pipeline.robot.target_pose import target_camera_pose

    graspable = np.nonzero(rows["grasp_class"] != GraspClass.NG)[0]
    if len(graspable) == 0:
        log.log_points("world/robot/links", np.zeros((0, 3), np.float32), frame_id="world")
        return
    i = int(graspable[0])
    robot.set_scene(scene, bin_cfg)
    T = scene.T_world_cam @ target_camera_pose(
        rows["center_cam"][i].astype(np.float64),
        rows["normal_cam"][i].astype(np.float64),
        rows["x_axis_cam"][i].astype(np.float64),
        GraspClass(int(rows["grasp_class"][i])).name,
        standoff=robot.cfg.hand.standoff,
        cup_offset=robot.cfg.hand.cup_offset,
    )
    result = robot.robot.solve_ik(
        T,
        seed_q=robot.robot.home_q(),
        obstacle_ids=robot.obstacles,
        ignore_body_ids=[robot.box_bodies[int(rows["instance"][i])]],
    )
    names = sorted(robot.robot.link_index, key=robot.robot.link_index.get)
    links = np.array([robot.robot.link_pose(n, result.q)[:3, 3] for n in names], np.float32)
    log.log_points("world/robot/links", links, frame_id="world")
    log.log_camera("world/robot/target_camera", scene.intrinsics, T, frame_id="target_camera")


def _log_scene(
    log: StageLog, scene: Scene, rows: dict, log_index: int, robot=None, bin_cfg=None
) -> None:
    log.set_time(sequences={"scene": log_index}, clock_ns=log_index * 1_000_000_000)
    log.log_camera("world/camera", scene.intrinsics, scene.T_world_cam)
    log.log_depth("world/camera/depth", scene.depth_m)
    classes = [GraspClass(int(c)) for c in rows["grasp_class"]]
    colors = np.array([CLASS_COLORS[c] for c in classes], np.uint8).reshape(-1, 3)
    log.log_points("world/camera/grasp_points", rows["center_cam"].reshape(-1, 3), colors)
    n = len(classes)
    quats = np.array(
        [
            quat_from_axes(
                rows["long_axis_cam"][i], rows["short_axis_cam"][i], rows["normal_cam"][i]
            )
            for i in range(n)
        ]
    ).reshape(-1, 4)
    sizes = np.column_stack([rows["lengths"], np.full(n, 0.001)]).reshape(-1, 3)
    log.log_boxes(
        "world/camera/surfaces",
        rows["center_cam"].reshape(-1, 3),
        sizes,
        quats,
        labels=[c.name for c in classes],
        frame_id="camera",
    )
    if robot is not None:
        _log_robot_sample(log, scene, rows, robot, bin_cfg)
    counts = np.bincount(rows["grasp_class"], minlength=4)
    log.log_text(
        "log",
        f"{scene.split} scene {scene.index}: {n} grasp points; "
        + ", ".join(f"{c.name} {counts[c]}" for c in GraspClass),
    )


def label(cfg: DictConfig) -> Path:
    """Run the labelling stage on a generation artifact; returns the label artifact folder."""
    check_hold_mass(cfg)
    gen_dir = upstream_artifact(cfg, "generate", "label.generate_version")
    upstream = {"generate": gen_dir.name}
    config = stage_config(cfg, SECTIONS, NOT_AFFECTING_RESULT)
    cfg_obj = OmegaConf.to_object(cfg)
    workers = resolve_workers(cfg_obj.label.workers, cfg_obj.executor)

    def body(run: StageRun) -> None:
        tasks = plan_tasks(gen_dir, run.work_dir, run.state_dir)
        # an interrupted run's finished shards are kept; everything else is redone
        done: dict[LabelTask, LabelSummary] = run.finished_shards(
            tasks,
            [p for t in tasks for p in (t.out_path, t.state_path)],
            shard_from_file,
            lambda t: t.out_path,
        )
        _write_index(run, tasks)
        t0 = time.perf_counter()
        todo = [t for t in tasks if t not in done]
        done.update(
            zip(todo, list(run_tasks(todo, cfg_obj, gen_dir, workers, cfg_obj.logging.progress)))
        )
        summaries = [done[t] for t in tasks]
        elapsed = time.perf_counter() - t0
        n_scenes = sum(t.count for t in todo)  # labelled by this run
        run.timings.update(
            {
                "label_s": round(elapsed, 3),
                "workers": workers,
                "scenes_per_s": round(n_scenes / max(elapsed, 1e-9), 3),
                "surface_detection_s_per_scene": round(
                    sum(s.surface_s for s in summaries) / max(n_scenes, 1), 5
                ),
                "robot_checks_s_per_scene": round(
                    sum(s.robot_s for s in summaries) / max(n_scenes, 1), 5
                ),
            }
        )
        if run.resumed:
            run.timings["shards_resumed"] = len(tasks) - len(todo)
        metrics = _label_metrics(summaries)
        run.metrics.update(metrics)

        sizes = {split: metrics["splits"][split]["scenes"] for split in SPLITS}
        run.metrics["logged_scenes"] = _log_scenes(run, cfg_obj, gen_dir, sizes)

    return run_stage_from_config(cfg, STAGE, config, upstream, body, resumable=True)


def _write_index(run: StageRun, tasks: list[LabelTask]) -> None:
    """``labels.json``: the shards of each split, the row fields, the classes and NG reasons."""
    meta = {
        "splits": shard_index(tasks, run.work_dir, SPLITS, lambda t: t.out_path),
        "fields": LABEL_FIELDS,
        "classes": [c.name for c in GraspClass],
        "ng_reasons": list(NG_REASONS),
    }
    (run.work_dir / "labels.json").write_text(json.dumps(meta, indent=2) + "\n")


def _label_metrics(summaries: list[LabelSummary]) -> dict:
    """The manifest's label metrics: per split the classes at hand and robot level, the NG
    reasons and the surface detection's accuracy; the accuracy over every split."""
    metrics: dict = {"splits": {}}
    for split in SPLITS:
        ss = [s for s in summaries if s.task.split == split]
        hand = sum((s.hand_counts for s in ss), np.zeros(4, np.int64))
        final = sum((s.final_counts for s in ss), np.zeros(4, np.int64))
        reasons: dict = {}
        for s in ss:
            for k, v in s.reasons.items():
                reasons[k] = reasons.get(k, 0) + v
        metrics["splits"][split] = {
            "scenes": int(sum(s.task.count for s in ss)),
            "grasp_points": int(final.sum()),
            "hand_level_classes": {c.name: int(hand[c]) for c in GraspClass},
            "classes": {c.name: int(final[c]) for c in GraspClass},
            "ng_reasons": dict(sorted(reasons.items())),
            "surface_accuracy": aggregate([m for s in ss for m in s.matches]),
        }
    metrics["surface_accuracy"] = aggregate([m for s in summaries for m in s.matches])
    return metrics


def _log_scenes(run: StageRun, cfg_obj, gen_dir: Path, sizes: dict[str, int]) -> int:
    """Log the first scenes of each split (``logging.max_logged_scenes`` in all) with their
    labels, and the robot's check of the first ones; the number logged."""
    quota = log_quota(sizes, cfg_obj.logging.max_logged_scenes)
    checker = None
    if cfg_obj.label.robot_checks:
        from pipeline.labelling.robot_check import RobotChecker

        checker = RobotChecker(cfg_obj)
    with StageLog.for_stage(run.work_dir, STAGE, run.version, default_blueprint()) as log:
        log_index = 0
        for split in SPLITS:
            ds, labels = SceneDataset(gen_dir, split), LabelSet(run.work_dir, split)
            for i in range(quota[split]):
                sample = checker if log_index < ROBOT_SAMPLE_SCENES else None
                _log_scene(log, ds[i], labels[i], log_index, sample, ds.bin)
                log_index += 1
    return log_index


main = stage_command("label", label)


if __name__ == "__main__":
    main()
