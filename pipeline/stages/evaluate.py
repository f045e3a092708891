"""The closed-loop evaluation stage (paper Secs. 5, 6, Table 3): picking every box out of a bin.

    python -m pipeline.stages.evaluate experiment=smoke [planner=dcnn|dexnet|dexnet_ood|oracle|all]

For every planner in ``evaluate.planners`` (``dcnn``: the training artifact
``evaluate.train_version``; ``dexnet``: the baseline artifact ``evaluate.baseline_version``,
variant ``evaluate.dexnet_variant``; ``dexnet_ood``: the same artifact's GQ-CNN trained on
non-box objects, variant ``gqcnn_ood``; ``oracle``: the labels on the home image; any other
entry: a user's plug-in planner, ``package.module:Class`` or an entry point name,
``pipeline.controller.planning``) and every trial, the same heap of
``evaluate.boxes_per_trial`` boxes of ``eval_boxes`` is dropped into the bin and the robot
picks until the trial ends (``pipeline.world.trial``). The heaps come from the stream of
``evaluate.split``: ``dev`` (development, the ablation) or ``test`` (the report's Table 3;
never used to choose anything); trial t of split s has the heap seed (seed, HEAP_SEEDS[s], t).
Trials run in parallel processes; the artifact does not depend on the number of workers. An
interrupted run resumes: a rerun keeps the trials it finished and runs the others
(``_finished_trials``; docs/artifacts.md).

The robot decides from its observations alone (``pipeline.controller``): every depth image it
takes (at home and in every servo step) goes through the ``sensor`` model (default ``ideal``:
none; ``sensor=sr300``: noise, holes and quantisation, drawn from a stream of its own, so the
heaps and the plans' draws are those of the noise-free run), and the robot side applies the
``depth_filter`` preprocessing (default ``none``). With noisy depth set
``servo.normal_smoothing`` (the descriptor's per-pixel normals need it; see
``pipeline.servo.descriptor``). ``evaluate.collision_model=truth`` gives the robot's run-time
check the heap's true boxes instead (simulator knowledge: an ablation row, never a headline).

Artifact (``data/evaluate/<version>/``)::

    trials.json             every trial and every attempt: outcome, pattern, G_opt, servo steps,
                            simulated seconds, final servo error (no wall-clock times)
    table3.csv              per planner: trials, boxes, attempts, successes, success rate,
                            failures by kind, picks on another box, simulated seconds, PPH of
                            the robot's motion alone
    servo_convergence.csv   the servo error over time of the logged trials' attempts
    drops_by_mass.csv       per planner, box type (by mass) and pattern: attempts that held the
                            box at first, and how many dropped it, with the drop rate's Wilson
                            95 % interval (``pipeline.world.books.drops_by_mass``)
    log.rrd, log.mcap       the logged trials step by step: camera pose, home depth images,
                            G_opt and g′, the reconstructed surface, the servo error

Measured wall-clock figures (planning time per image, PPH including the planning time, the
descriptor's time per frame, the control loop's rate, simulated seconds per wall second) go
into the manifest's ``timings``, not into the files.
"""

from __future__ import annotations

import dataclasses
import json
import os
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from omegaconf import DictConfig, OmegaConf

from pipeline.artifacts import stage_config
from pipeline.artifacts.csvfile import write_rows
from pipeline.artifacts.store import StageRun
from pipeline.camera.render import check_renderer
from pipeline.controller.check import COLLISION_MODELS
from pipeline.controller.planning import BUILT_IN, load_plugin, plugin_target
from pipeline.controller.retry import RETRY_POLICIES
from pipeline.robot.approach import check_approach
from pipeline.runtime.cli import stage_command
from pipeline.runtime.executor import map_shards, resolve_workers
from pipeline.runtime.stage_artifacts import run_stage_from_config, upstream_artifact
from pipeline.tracking import StageLog
from pipeline.world.books import convergence_rows, drops_by_mass, summarise
from pipeline.world.trial import HEAP_STREAMS, OUTCOMES, TrialResult, TrialRunner, make_runner

STAGE = "evaluate"
# train.ranking: the oracle ranks with it (the DCNN with its model's, part of the train version)
SECTIONS = (
    "seed",
    "camera",
    "sensor",
    "depth_filter",
    "bin",
    "physics",
    "hand",
    "robot",
    "suction",
    "dexnet",
    "motion",
    "servo",
    "eval_boxes",
    "evaluate",
    "train.ranking",
)
NOT_AFFECTING_RESULT = (
    "evaluate.train_version",
    "evaluate.baseline_version",
    "evaluate.workers",
    "evaluate.force",
    "evaluate.log_trials",
    "evaluate.num_threads",
)
PLANNERS = BUILT_IN  # and plug-ins (pipeline.controller.planning)
# The Dex-Net-style planners: the baseline variant each drives the robot with (None: the one
# ``evaluate.dexnet_variant`` names). ``dexnet_ood``: the GQ-CNN trained on non-box objects.
DEXNET_PLANNERS = {"dexnet": None, "dexnet_ood": "gqcnn_ood"}


def dexnet_variant(cfg, name: str) -> str:
    """The baseline variant (``pipeline.dexnet.planner.BASELINE_VARIANTS``) of Dex-Net-style
    planner ``name``."""
    return DEXNET_PLANNERS[name] or str(cfg.evaluate.dexnet_variant)


PAPER_TABLE3 = [  # paper Table 3, as reported
    {
        "system": "Dex-Net 3.0",
        "hand": "suction (1 cup)",
        "success": 98.0,
        "planning_s": 3.0,
        "pph": None,
    },
    {
        "system": "Dex-Net 4.0",
        "hand": "suction (1 cup) + gripper",
        "success": 97.0,
        "planning_s": None,
        "pph": "over 300",
    },
    {
        "system": "Zeng et al.",
        "hand": "suction + gripper",
        "success": 58.3,
        "planning_s": 0.06,
        "pph": None,
    },
    {
        "system": "Le et al.",
        "hand": "suction (1 cup)",
        "success": 99.6,
        "planning_s": 0.862,
        "pph": None,
    },
    {
        "system": "Ours (paper)",
        "hand": "suction (2 cups)",
        "success": 97.5,
        "planning_s": 0.034,
        "pph": "over 1000",
    },
]


@dataclass
class TrialTask:
    planner: str
    trial: int
    count: int = 1  # scenes for the progress bar


_STATE: dict = {}


def _init_worker(cfg_obj, train_dir: str | None, baseline_dir: str | None) -> None:
    import torch

    _STATE.clear()
    _STATE.update(cfg=cfg_obj, train_dir=train_dir, baseline_dir=baseline_dir, runners={})
    torch.set_num_threads(int(cfg_obj.evaluate.num_threads))


def make_planner(
    cfg, name: str, train_dir: str | None, baseline_dir: str | None, T_home, cell=None
):
    """The ``plan(observation, rng)`` planner (``pipeline.controller.planning``) called
    ``name``: a built-in one, or a plug-in. ``oracle`` reads the world ``cell``'s truth
    (``pipeline.world.oracle``)."""
    from pipeline.controller.planning import DCNNPlanner, DexNetStylePlanner

    if name == "dcnn":
        return DCNNPlanner(cfg, train_dir)
    if name in DEXNET_PLANNERS:
        return DexNetStylePlanner(cfg, dexnet_variant(cfg, name), T_home, baseline_dir)
    if name == "oracle":
        from pipeline.world.oracle import OraclePlanner

        return OraclePlanner(cfg, cell)
    return load_plugin(name, cfg)


def _runner(name: str) -> TrialRunner:
    if name not in _STATE["runners"]:
        cfg = _STATE["cfg"]
        _STATE["runners"][name] = make_runner(
            cfg,
            name,
            lambda cell: make_planner(
                cfg,
                name,
                _STATE["train_dir"],
                _STATE["baseline_dir"],
                cell.robot.home_camera_pose(),
                cell,
            ),
        )
    return _STATE["runners"][name]


def run_task(task: TrialTask) -> tuple[TrialResult, dict]:
    cfg = _STATE["cfg"]
    runner = _runner(task.planner)
    clocks = {**runner.timings, **runner.robot_side.timings}
    for v in clocks.values():
        v.clear()
    seed = int(cfg.seed)
    keep = task.trial < int(cfg.evaluate.log_trials)
    heap, plan, sensor = HEAP_STREAMS[str(cfg.evaluate.split)]
    t0 = time.perf_counter()
    result = runner.run_trial(
        task.trial,
        np.random.default_rng([seed, heap, task.trial]),
        np.random.default_rng([seed, plan, task.trial]),
        keep,
        rng_sensor=np.random.default_rng([seed, sensor, task.trial]),
    )
    wall = time.perf_counter() - t0
    timings = {k: list(v) for k, v in clocks.items()}
    timings["wall_s"] = wall
    return result, timings


# ------------------------------------------------------------------------------ logs
def log_trials(log: StageLog, results: list[TrialResult], intr) -> None:
    """Every logged trial, control step by control step (timeline ``control_step``; the log
    time is simulated time at 30 Hz): the robot's link origins, the camera's pose, g′ and the
    reconstructed surface in the camera frame, the servo errors; per attempt the home depth
    image (half resolution, under a camera of half-resolution intrinsics) with G_opt; for a
    trial that ended "no grasp", its last home image (``_log_final_home``)."""
    from types import SimpleNamespace

    from pipeline.camera.geometry import backproject_pixels, quat_from_axes

    half = SimpleNamespace(
        width=intr.width // 2,
        height=intr.height // 2,
        fx=intr.fx / 2,
        fy=intr.fy / 2,
        cx=(intr.cx + 0.5) / 2 - 0.5,
        cy=(intr.cy + 0.5) / 2 - 0.5,
    )
    tick = 0
    for r in results:
        if not r.trace and not r.final_home:
            continue
        prefix = f"trials/{r.planner}/trial_{r.trial}"
        for s in r.trace:
            log.set_time(sequences={"control_step": tick}, clock_ns=int(round(tick * 1e9 / 30.0)))
            tick += 1
            log.log_points(
                f"{prefix}/robot/links",
                s["links"],
                np.full((len(s["links"]), 3), 200, np.uint8),
                frame_id="world",
            )
            log.log_camera(f"{prefix}/camera", intr, s["T_world_cam"])
            if s["depth"] is not None:
                d = s["depth"][::2, ::2]
                log.log_camera(
                    f"{prefix}/home_camera", half, s["T_world_cam"], frame_id="home_camera"
                )
                log.log_depth(f"{prefix}/home_camera/depth", d, frame_id="home_camera")
                u, v = s["g_opt"]
                z = float(s["depth"][int(round(v)), int(round(u))])
                g = backproject_pixels(np.array([[u, v]]), np.array([z]), intr)
                log.log_points(
                    f"{prefix}/home_camera/g_opt",
                    g,
                    np.array([[255, 40, 40]], np.uint8),
                    frame_id="home_camera",
                )
            f = s["surface"]
            log.log_points(
                f"{prefix}/camera/g_prime",
                f.center_cam.reshape(1, 3),
                np.array([[255, 220, 0]], np.uint8),
            )
            q = quat_from_axes(f.long_axis_cam, f.short_axis_cam, f.normal_cam)
            log.log_boxes(
                f"{prefix}/camera/surface",
                f.center_cam.reshape(1, 3),
                np.array([[f.long_length, f.short_length, 0.001]]),
                q.reshape(1, 4),
                labels=[f"attempt {s['attempt']}"],
                frame_id="camera",
            )
            e = s["error"]
            log.log_scalar(f"{prefix}/servo/translation_error", float(np.linalg.norm(e[:3])))
            log.log_scalar(
                f"{prefix}/servo/rotation_error_deg", float(np.degrees(np.linalg.norm(e[3:])))
            )
        for a in r.attempts:
            log.log_text(
                "log",
                f"{r.planner} trial {r.trial} attempt {a.index}: {a.pattern} at "
                f"({a.g_opt[0]:.0f}, {a.g_opt[1]:.0f}) → {a.outcome} "
                f"({a.servo_steps} servo steps, {a.sim_s:.2f} s simulated)",
            )
        if r.final_home:
            log.set_time(sequences={"control_step": tick}, clock_ns=int(round(tick * 1e9 / 30.0)))
            tick += 1
            _log_final_home(log, r, intr, prefix)


def _log_final_home(log: StageLog, r: TrialResult, intr, prefix: str) -> None:
    """The home image on which trial ``r`` ended "no grasp", at full resolution (so the planner
    can be run on it again from the log): ``<prefix>/no_grasp`` (camera; MCAP frame
    ``no_grasp_camera``), its ``depth``, the boxes left (world frame) and the planner's
    candidates (each rejected by the run-time check; none: the planner proposed nothing)."""
    from pipeline.camera.geometry import backproject_pixels

    f = r.final_home
    log.log_camera(f"{prefix}/no_grasp", intr, f["T_world_cam"], frame_id="no_grasp_camera")
    log.log_depth(f"{prefix}/no_grasp/depth", f["depth_m"], frame_id="no_grasp_camera")
    boxes = f["boxes_left"]
    if boxes:
        log.log_points(
            f"{prefix}/no_grasp/boxes_left",
            np.array([b["position"] for b in boxes], np.float64),
            np.tile(np.array([[255, 140, 0]], np.uint8), (len(boxes), 1)),
            frame_id="world",
        )
    uv = f["candidates_px"]
    if len(uv):
        d = f["depth_m"]
        rows = np.clip(np.round(uv[:, 1]).astype(int), 0, d.shape[0] - 1)
        cols = np.clip(np.round(uv[:, 0]).astype(int), 0, d.shape[1] - 1)
        pts = backproject_pixels(uv, d[rows, cols], intr)
        log.log_points(
            f"{prefix}/no_grasp/candidates",
            pts,
            np.tile(np.array([[255, 40, 40]], np.uint8), (len(uv), 1)),
            frame_id="no_grasp_camera",
        )
    left = (
        ", ".join(
            f"{b['type']} at ({b['position'][0]:+.3f}, {b['position'][1]:+.3f}, "
            f"{b['position'][2]:+.3f}) m"
            for b in boxes
        )
        or "none"
    )
    ng = r.no_grasp
    log.log_text(
        "log",
        f"{r.planner} trial {r.trial} ended no grasp: {ng.get('candidates', 0)} "
        f"candidates, rejected {ng.get('rejected', {})}; boxes left: {left}",
        level="WARN",
    )


# ------------------------------------------------------------------------------ the stage
def plugin_source_hash(name: str) -> str:
    """sha256 (16 hex digits) of the file of plug-in ``name``'s module ("" when it has none):
    editing a plug-in gives its evaluation a new version."""
    import hashlib
    import importlib

    module = importlib.import_module(plugin_target(name).partition(":")[0])
    path = getattr(module, "__file__", None)
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()[:16] if path else ""


def _check_choice(what: str, value: str, choices: tuple[str, ...]) -> None:
    """A ValueError "<what> 'value': choose from (...)" unless ``value`` is one of ``choices``."""
    if value not in choices:
        raise ValueError(f"{what} {value!r}: choose from {choices}")


def _check_config(cfg: DictConfig, planners: list[str]) -> dict[str, str]:
    """Refuse a bad evaluation config before any trial; the plug-ins' source hashes by name."""
    if len(set(planners)) != len(planners):
        raise ValueError(f"evaluate.planners names a planner twice: {planners}")
    _check_choice("evaluate.split is", str(cfg.evaluate.split), tuple(HEAP_STREAMS))
    _check_choice(
        "evaluate.collision_model is", str(cfg.evaluate.collision_model), COLLISION_MODELS
    )
    plugins = {}
    for name in (n for n in planners if n not in PLANNERS):
        load_plugin(name, cfg)  # a bad plug-in fails here, with its reason, before any trial
        plugins[name] = plugin_source_hash(name)
    if int(cfg.evaluate.num_trials) < 1:
        raise ValueError(f"evaluate.num_trials must be >= 1, got {cfg.evaluate.num_trials}")
    check_renderer(str(cfg.camera.renderer))
    _check_choice("evaluate.retry_policy is", str(cfg.evaluate.retry_policy), RETRY_POLICIES)
    for outcome in cfg.evaluate.retry_point_outcomes:
        _check_choice("evaluate.retry_point_outcomes has", str(outcome), OUTCOMES[1:])
    check_approach(str(cfg.motion.approach))
    return plugins


def _planner_artifacts(cfg: DictConfig, planners: list[str]) -> tuple[Path | None, Path | None]:
    """(the trained DCNN, the baseline artifact) the planners need, verified; None where none
    is needed."""
    from pipeline.dexnet.planner import BASELINE_VARIANTS

    train_dir = baseline_dir = None
    if "dcnn" in planners:
        train_dir = upstream_artifact(
            cfg, "train", "evaluate.train_version", root=Path(cfg.paths.models)
        )
    if "dexnet" in planners and str(cfg.evaluate.dexnet_variant) not in BASELINE_VARIANTS:
        raise ValueError(
            f"evaluate.dexnet_variant={cfg.evaluate.dexnet_variant}: choose from "
            f"{', '.join(BASELINE_VARIANTS)}"
        )
    for name in (n for n in planners if n in DEXNET_PLANNERS):
        variant = dexnet_variant(cfg, name)
        model_file = BASELINE_VARIANTS[variant][1]
        if model_file is None:  # training-free (planarity)
            continue
        if baseline_dir is None:
            baseline_dir = upstream_artifact(cfg, "baseline", "evaluate.baseline_version")
        if not (baseline_dir / model_file).is_file():
            raise ValueError(
                f"baseline artifact {baseline_dir.name} has no {model_file} (its "
                f"baseline.variants left {variant} out, needed by planner "
                f"{name}): run `make baseline` with {variant} in "
                "baseline.variants, or pass another evaluate.baseline_version"
            )
    return train_dir, baseline_dir


def evaluate(cfg: DictConfig) -> Path:
    """Run the closed-loop trials; returns the evaluation artifact folder."""
    planners = [str(p) for p in cfg.evaluate.planners]
    plugins = _check_config(cfg, planners)
    train_dir, baseline_dir = _planner_artifacts(cfg, planners)
    upstream = {}
    if train_dir is not None:
        upstream["train"] = train_dir.name
    if baseline_dir is not None:
        upstream["baseline"] = baseline_dir.name
    for name, digest in plugins.items():  # a plug-in's source is part of the version
        upstream[f"plugin:{name}"] = digest
    config = stage_config(cfg, SECTIONS, NOT_AFFECTING_RESULT)
    cfg_obj = OmegaConf.to_object(cfg)
    workers = resolve_workers(cfg_obj.evaluate.workers, cfg_obj.executor)

    def body(run: StageRun) -> None:
        tasks = [
            TrialTask(name, t) for name in planners for t in range(int(cfg.evaluate.num_trials))
        ]
        # an interrupted run's finished trials are kept; the rest are run
        done = _finished_trials(run, tasks)
        todo = [i for i in range(len(tasks)) if i not in done]
        t0 = time.perf_counter()
        trials = map_shards(
            run_task,
            [tasks[i] for i in todo],
            init=_init_worker,
            initargs=(
                cfg_obj,
                str(train_dir) if train_dir else None,
                str(baseline_dir) if baseline_dir else None,
            ),
            workers=min(workers, len(todo)),
            desc=STAGE,
            progress=bool(cfg_obj.logging.progress),
            executor=cfg_obj.executor,
        )
        for i, pair in zip(todo, trials, strict=True):
            _keep_trial(run, i, pair)
            done[i] = pair
        wall = time.perf_counter() - t0
        out = [done[i] for i in range(len(tasks))]
        results = [r for r, _ in out]
        _write_results(run, cfg, results)
        timings: dict = {"wall_s": round(wall, 2), "workers": workers, "planners": {}}
        if run.resumed:
            timings["trials_resumed"] = len(tasks) - len(todo)
        for name in planners:
            timings["planners"][name] = _planner_timings([m for m in out if m[0].planner == name])
        run.timings.update(timings)
        from pipeline.camera.geometry import Intrinsics

        with StageLog.for_stage(run.work_dir, STAGE, run.version) as log:
            log_trials(log, results, Intrinsics.from_config(cfg.camera))

    return run_stage_from_config(cfg, STAGE, config, upstream, body, resumable=True)


# ------------------------------------------------------------------------------ resuming
# A finished trial's result and timings, one JSON file per trial in the run's resume folder
# (``StageRun.state_dir``, never part of the artifact), so that a rerun of an interrupted
# evaluation runs only the trials it had not finished. A logged trial (the first
# ``evaluate.log_trials`` of each planner) is not kept: its step-by-step log data is run again.
TRIALS_DIR = "trials"


def _trial_file(run: StageRun, index: int) -> Path:
    """Where task ``index`` (in the stage's task order) keeps its finished trial."""
    return run.state_dir / TRIALS_DIR / f"{index:06d}.json"


def _keep_trial(run: StageRun, index: int, pair: tuple[TrialResult, dict]) -> None:
    """Write task ``index``'s finished (result, timings) atomically, unless it is logged."""
    result, timings = pair
    if result.has_log_data:
        return
    path = _trial_file(run, index)
    path.parent.mkdir(parents=True, exist_ok=True)
    part = path.with_suffix(".part")
    part.write_text(json.dumps({"result": result.to_record(), "timings": timings}))
    os.replace(part, path)


def _finished_trials(run: StageRun, tasks: list[TrialTask]) -> dict[int, tuple]:
    """The trials an interrupted run of this version finished: {task index: (result,
    timings)}. Everything else in the work folder is deleted, and so is a trial file that
    cannot be read or names another trial. Empty unless ``run.resumed``."""
    if not run.resumed:
        return {}
    files = [_trial_file(run, i) for i in range(len(tasks))]
    run.keep_only(files)
    done = {}
    for i, (task, path) in enumerate(zip(tasks, files, strict=True)):
        if not path.is_file():
            continue
        try:
            record = json.loads(path.read_text())
            result = TrialResult.from_record(record["result"])
            timings = dict(record["timings"])
            if (result.planner, result.trial) != (task.planner, task.trial):
                raise ValueError(f"{path.name} holds another trial")
        except (ValueError, KeyError, TypeError):  # json.JSONDecodeError is a ValueError
            path.unlink()
            continue
        done[i] = (result, timings)
    print(f"[{STAGE}] resuming: {len(done)} of {len(tasks)} trials already run")
    return done


def _write_results(run: StageRun, cfg: DictConfig, results: list) -> None:
    """``trials.json`` (every attempt), Table 3, the drops by mass and the servo's convergence."""
    trials = [
        {
            "planner": r.planner,
            "trial": r.trial,
            "boxes": r.boxes,
            "picked": r.picked,
            "end": r.end,
            "sim_s": round(r.sim_s, 4),
            **({"no_grasp": r.no_grasp} if r.no_grasp else {}),
            "attempts": [
                {k: v for k, v in dataclasses.asdict(a).items() if k != "planning_s"}
                for a in r.attempts
            ],
        }
        for r in results
    ]
    (run.work_dir / "trials.json").write_text(json.dumps(trials, indent=1) + "\n")
    rows = summarise(results)
    write_rows(run.work_dir / "table3.csv", rows, empty_header=("planner",))
    drops = drops_by_mass(trials, cfg.eval_boxes)
    write_rows(run.work_dir / "drops_by_mass.csv", drops, empty_header=("planner",))
    run.metrics["drops_by_mass"] = drops
    write_rows(
        run.work_dir / "servo_convergence.csv", convergence_rows(results), empty_header=("planner",)
    )
    run.metrics["table3"] = rows
    run.metrics["paper_table3"] = PAPER_TABLE3


def _planner_timings(mine: list) -> dict:
    """One planner's timings from its (result, timing) pairs: planning time, PPH with planning,
    the descriptor's time, the control loop's rate, simulated seconds per wall second."""
    plan = [a.planning_s for r, _ in mine for a in r.attempts]
    sim = sum(r.sim_s for r, _ in mine)
    succ = sum(r.picked for r, _ in mine)
    desc = [x for _, t in mine for x in t["descriptor_s"]]
    step = [x for _, t in mine for x in t["control_step_s"]]
    total_plan = sum(r.planning_s for r, _ in mine)
    walls = [t["wall_s"] for _, t in mine]
    return {
        "planning_ms_median": round(1000 * float(np.median(plan)), 2) if plan else None,
        "planning_ms_mean": round(1000 * float(np.mean(plan)), 2) if plan else None,
        "pph_with_planning": round(3600.0 * succ / (sim + total_plan), 1)
        if sim + total_plan > 0
        else None,
        "descriptor_ms_median": round(1000 * float(np.median(desc)), 3) if desc else None,
        "control_loop_hz": round(1.0 / float(np.median(step)), 2) if step else None,
        "sim_s_per_wall_s": round(sim / max(sum(walls), 1e-9), 3),
        "trial_wall_s_mean": round(float(np.mean(walls)), 2) if walls else None,
    }


main = stage_command("evaluate", evaluate)


if __name__ == "__main__":
    main()
