"""The robustness study (paper Secs. 8.4, 8.5): sensor noise, depth preprocessing, failure cases.

    python -m pipeline.stages.robustness [experiment=default] [robustness.closed_loop_trials=...]

The paper trains and tests on noise-free simulated depth. This stage measures what a real
SR300-class camera's depth (``conf/sensor/sr300.yaml``: noise growing with depth and incidence,
projector shadows, steep-surface and edge dropout, 1/8 mm quantisation) does to the method, and
the paper's proposed fixes of its failure cases (Sec. 8.4). With the command's own overrides:

* it reads the **clean** pipeline: the network trained on ideal depth
  (``robustness.train_version``), the label and generation artifacts it was trained on, and the
  baseline artifact that compared it (``robustness.baseline_version``: the Dex-Net-style
  GQ-CNNs; both ``latest`` by default, as ``make reproduce`` leaves them);
* it runs, or reuses when their versions exist, the **noisy** pipeline:
  ``generate sensor=<robustness.sensor>`` (same heaps, same seeds; the shards hold the sensor's
  depth and the ideal depth) → ``label`` (labels from the ideal depth, so identical to the clean
  labels) → ``train`` (the network sees noisy depth). Without ``robustness.noisy_network`` no
  second network is trained: the noisy generation holds the test split only, and every row
  measures the network under test (``robustness.train_version``; model ``clean`` in the
  variants), which then must serve every camera (``generate.camera_randomisation``);

then measures, on the noisy generation's test split (the same heaps as the clean one):

* **Table 1** (``pipeline.planner.evaluate``) for the network under test and the
  sensor-trained one, with each input of ``robustness.table1_inputs``: ``ideal`` depth, the
  sensor's depth, and the sensor's depth after each ``depth_filter`` preprocessing;
* **Table 2** (``pipeline.stages.baseline``'s measure: G_opt within 30 px of a true face centre) for
  both networks and the Dex-Net-style planners, with the inputs of ``robustness.table2_inputs``;
* the **closed loop** (``pipeline.stages.evaluate``, DCNN only) for each variant of
  ``robustness.closed_loop`` (which model; ``sensor``, ``depth_filter``, descriptor overrides)
  and of ``robustness.policies`` (Sec. 8.4's ranking tie-break and surface-area check), all on
  the same seeds. Each variant is an ordinary evaluation artifact, reused when it exists.

Artifact (``data/robustness/<version>/``)::

    table1.csv         model, input, Top 1, Top 1 %, Top 5 %, Top 10 %, predictions
    table2.csv         planner, input, images, no grasp, within 30 px, median distance
    closed_loop.csv    group (sensor | policy), variant, model, overrides, success rate,
                       attempts, successes, boxes picked, PPH (robot motion), evaluate version
    robustness.json    all of it, with the versions of every artifact used
    log.rrd, log.mcap  sample test images: ideal, sensor, filtered depth; each network's G_opt

The manifest's ``upstream`` names every artifact the study used. The study leaves every stage's
``latest`` where it was (``Pipelines.keep_latest``): after ``make reproduce``, ``latest`` still
names the default pipeline's artifacts.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from omegaconf import DictConfig, OmegaConf

from pipeline.artifacts import load_manifest, resolve_artifact, stage_config
from pipeline.artifacts.csvfile import write_rows
from pipeline.artifacts.jsonfile import json_safe, write_json
from pipeline.artifacts.stages import compared_pair
from pipeline.artifacts.store import StageRun
from pipeline.runtime.cli import (
    compose,
    conf_file,
    data_root,
    run_named_stage,
    scale_overrides,
    stage_command,
)
from pipeline.runtime.stage_artifacts import run_stage_from_config
from pipeline.tracking import StageLog
from pipeline.world.books import RATE_KEYS, finite

STAGE = "robustness"
SECTIONS = ("seed", "robustness")
NOT_AFFECTING_RESULT = (
    "robustness.force",  # the versions are upstream
    "robustness.train_version",
    "robustness.baseline_version",
)
IDEAL, SENSOR = "ideal", "sensor"  # Table inputs; "sensor+<filter>": sensor depth, then a filter


class Pipelines:
    """Runs (or reuses) the stages the study needs, each with ``base`` overrides + its own.

    Every stage run re-points its stage's ``latest``; ``keep_latest`` puts back the pointers as
    they were before the study, so that ``latest`` still names the ``make reproduce`` pipeline
    (the report's default) and not the noisy pipeline or the last closed-loop variant."""

    STAGES = ("generate", "label", "train", "baseline", "evaluate")

    def __init__(self, base: list[str], sensor: str, data: Path, models: Path) -> None:
        self.base, self.sensor = list(base), sensor
        self.versions: dict[str, str] = {}
        self.dirs: dict[str, Path] = {}
        self.stage_dirs = {s: (models if s == "train" else data) / s for s in self.STAGES}

    def keep_latest(self):
        """Restore each stage's ``latest`` (where it existed) when the block ends."""
        from pipeline.artifacts.pointers import keep_latest

        return keep_latest(self.stage_dirs.values())

    def _run(self, key: str, stage: str, extra: list[str]) -> Path:
        out = run_named_stage(stage, self.base + extra, f"{STAGE}: {key}")
        self.versions[key], self.dirs[key] = out.name, out
        return out

    def _use(self, key: str, folder: Path) -> None:
        self.versions[key], self.dirs[key] = folder.name, folder

    def build(self, train_version: str, baseline_version: str, noisy_network: bool) -> None:
        """The clean pipeline as it is (``compared_pair``; its train artifact's upstream label
        and generation artifacts), then the noisy pipeline, run or reused: with
        ``noisy_network`` a full one, trained; without, the test split's heaps and labels."""
        pair = compared_pair(
            self.stage_dirs["baseline"].parent,
            self.stage_dirs["train"].parent,
            train_version,
            baseline_version,
            STAGE,
        )
        self._use("train_clean", pair["train"])
        self._use("baseline", pair["baseline"])
        up = load_manifest(pair["train"]).get("upstream") or {}
        for stage in ("label", "generate"):
            self._use(
                f"{stage}_clean",
                resolve_artifact(  # the train artifact's upstream
                    self.stage_dirs[stage].parent, stage, str(up.get(stage)), verify=True
                ),
            )
        test_only = [] if noisy_network else ["generate.num_scenes=0", "generate.num_val_scenes=0"]
        gen = self._run("generate_noisy", "generate", [f"sensor={self.sensor}", *test_only])
        lab = self._run("label_noisy", "label", [f"label.generate_version={gen.name}"])
        if noisy_network:
            self._run("train_noisy", "train", [f"train.label_version={lab.name}"])

    @property
    def models(self) -> tuple[str, ...]:
        """The networks of the study: ``clean`` (the one under test), and ``noisy`` when one was
        trained on the sensor's depth."""
        return ("clean", "noisy") if "train_noisy" in self.versions else ("clean",)

    def evaluate(
        self, name: str, model: str, overrides: list[str], trials: int, split: str
    ) -> Path:
        return self._run(
            f"evaluate_{name}",
            "evaluate",
            [
                "planner=dcnn",
                f"evaluate.train_version={self.versions['train_' + model]}",
                f"evaluate.num_trials={trials}",
                f"evaluate.split={split}",
                *overrides,
            ],
        )


# ------------------------------------------------------------------------------ Tables 1 and 2
def _filter_cfg(name: str):
    """The ``conf/depth_filter/<name>.yaml`` config."""
    path = conf_file("depth_filter", name)
    if not path.is_file():
        choices = sorted(p.stem for p in path.parent.glob("*.yaml"))
        raise ValueError(
            f"unknown depth filter {name!r} in a robustness input: choose from "
            f"{choices} (input names: ideal, sensor, sensor+<filter>)"
        )
    return OmegaConf.load(path)


def depth_getter(input_name: str):
    """``scene → (H, W) depth`` for a Table input name: ``ideal``, ``sensor`` or
    ``sensor+<depth_filter>``."""
    from pipeline.camera.depth_filter import preprocess_depth

    if input_name == IDEAL:
        return lambda scene: scene.depth_clean_m
    if input_name == SENSOR:
        return lambda scene: scene.depth_m
    head, _, filt = input_name.partition("+")
    if head != SENSOR or not filt:
        raise ValueError(
            f"robustness input {input_name!r}: use ideal, sensor or "
            "sensor+<depth_filter> (e.g. sensor+fill)"
        )
    fc = _filter_cfg(filt)
    return lambda scene: preprocess_depth(scene.depth_m, fc)


def table1_rows(
    p: Pipelines, inputs: list[str], radius_px: float, max_images: int, progress: bool
) -> list[dict]:
    """Table 1 of each network on each input (the noisy generation's test split)."""
    from tqdm import tqdm

    from pipeline.dataset.labels import LabelSet
    from pipeline.dataset.scenes import SceneDataset
    from pipeline.planner.data import GraspDataset
    from pipeline.planner.planner import Planner
    from pipeline.planner.scoring import table1

    gen_dir, label_dir = p.dirs["generate_noisy"], p.dirs["label_noisy"]
    scenes = SceneDataset(gen_dir, "test")
    rows = []
    for model in p.models:
        planner = Planner.load(p.dirs[f"train_{model}"])
        data = GraspDataset(
            gen_dir,
            LabelSet(label_dir, "test"),
            "test",
            planner.norm,
            planner.net.cfg.grid,
            limit=max_images,
        )
        for name in tqdm(
            inputs, desc=f"{STAGE} table 1 ({model}-trained)", unit="input", disable=not progress
        ):
            get = depth_getter(name)
            res = table1(planner, data, radius_px, depth_of=lambda i, get=get: get(scenes[i]))
            rows.append(
                {
                    "model": model,
                    "input": name,
                    **{
                        k: (round(res[k], 6) if res[k] is not None else None)
                        for k in ("top1", "top1pct", "top5pct", "top10pct")
                    },
                    "predictions": res["num_predictions"],
                    "images": res["num_images"],
                }
            )
    return rows


def table2_rows(
    p: Pipelines, inputs: list[str], max_images: int, progress: bool
) -> tuple[list[dict], dict]:
    """Table 2 of both networks and the Dex-Net-style planners on each input."""
    from pipeline.dataset.scenes import SceneDataset
    from pipeline.dexnet import table2
    from pipeline.planner.planner import Planner

    cfg = compose("baseline", p.base + [f"baseline.max_eval_images={max_images}"])
    gen_dir = p.dirs["generate_noisy"]
    gen = SceneDataset(gen_dir, "test")
    planners = table2.make_planners(cfg, gen, p.dirs["baseline"], None)
    nets = {m: Planner.load(p.dirs[f"train_{m}"]) for m in p.models}
    ours = {
        f"dcnn_{m}": (lambda depth, intr, i, net=net: net.plan(depth, intr))
        for m, net in nets.items()
    }
    planners = {**ours, **planners}
    radius = float(cfg.baseline.table2_radius_px)
    rows, picks = [], {}
    for name in inputs:
        res = table2.evaluate_table2(
            cfg,
            gen_dir,
            p.dirs["baseline"],
            None,
            progress,
            planners=planners,
            depth_of=depth_getter(name),
        )
        picks[name] = {k: res[f"{k}_uv"] for k in res["planners"]}
        for r in table2.table2_rows(res, radius, np.array([radius]))[0]:
            rows.append(
                {
                    "planner": r["planner"],
                    "input": name,
                    **{k: v for k, v in r.items() if k not in ("planner", "name")},
                }
            )
    return rows, picks


# ------------------------------------------------------------------------------ closed loop
CLOSED_LOOP_KEYS = (*RATE_KEYS, "no_attempt_reason")


def closed_loop_rows(p: Pipelines, group: str, variants, trials: dict[str, int]) -> list[dict]:
    """One evaluation per variant (reused when its version exists) and its Table 3 row;
    ``trials``: per split (``dev``, ``test``)."""
    from pipeline.world.trial import HEAP_STREAMS

    rows = []
    for v in variants:
        split = str(v.split)
        if split not in HEAP_STREAMS:
            raise ValueError(
                f"robustness variant {v.name}: split {split!r}, choose from {tuple(HEAP_STREAMS)}"
            )
        overrides = [str(o) for o in v.overrides]
        out = p.evaluate(str(v.name), str(v.model), overrides, trials[split], split)
        t3 = json.loads((out / "manifest.json").read_text())["metrics"]["table3"]
        row = next(r for r in t3 if r["planner"] == "dcnn")
        rows.append(
            {
                "group": group,
                "variant": str(v.name),
                "model": str(v.model),
                "split": split,
                "trials": row.get("trials"),
                "overrides": " ".join(overrides) or "-",
                **{k: finite(row.get(k)) for k in CLOSED_LOOP_KEYS},
                **{k: v for k, v in row.items() if k.startswith(("fail_", "end_"))},
                "evaluate_version": out.name,
            }
        )
    return rows


def _log(log: StageLog, p: Pipelines, picks: dict, count: int, tables: dict) -> None:
    """Sample test images (ideal, sensor, filtered) with each planner's G_opt, and the tables."""
    from pipeline.dataset.pixels import pixels_to_points
    from pipeline.dataset.scenes import SceneDataset

    scenes = SceneDataset(p.dirs["generate_noisy"], "test")
    colors = {
        "dcnn_clean": [40, 200, 40],
        "dcnn_noisy": [230, 160, 20],
        "gqcnn": [200, 40, 40],
        "planarity": [120, 120, 255],
    }
    for i in range(min(count, len(scenes))):
        scene = scenes[i]
        log.set_time(sequences={"test_image": i}, clock_ns=i * 1_000_000_000)
        for name in picks:
            ent = f"{name.replace('+', '_')}/camera"
            log.log_camera(ent, scene.intrinsics, scene.T_world_cam)
            log.log_depth(f"{ent}/depth", depth_getter(name)(scene))
            for planner, uv in picks[name].items():
                if i < len(uv) and np.isfinite(uv[i]).all():
                    log.log_points(
                        f"{ent}/g_opt/{planner}",
                        pixels_to_points(scene, uv[i]),
                        np.asarray([colors.get(planner, [255, 255, 255])], np.uint8),
                    )
        lost = float(np.mean((scene.depth_m == 0) & (scene.depth_clean_m > 0)))
        log.log_scalar("sensor/missing_fraction", lost)
        log.log_text("log", f"test image {i}: {100 * lost:.1f} % of pixels without data")
    for row in tables["table1"]:
        log.log_text("log", "table 1: " + json.dumps(row))
    for row in tables["closed_loop"]:
        log.log_text("log", "closed loop: " + json.dumps(row))


# ------------------------------------------------------------------------------ the stage
def robustness(cfg: DictConfig, overrides: list[str] | None = None) -> Path:
    """Run the study; returns its artifact folder. ``overrides``: passed to every stage it
    runs (the command line's own, by default none)."""
    rc = cfg.robustness
    base = scale_overrides(cfg, overrides)
    p = Pipelines(base, str(rc.sensor), data_root(cfg), Path(cfg.paths.models))
    progress = bool(cfg.logging.progress)
    radius = float(compose("train", base).train.match_radius_px)
    t1_inputs = [str(x) for x in rc.table1_inputs]
    t2_inputs = [str(x) for x in rc.table2_inputs]
    for name in set(t1_inputs + t2_inputs):
        depth_getter(name)  # a bad input name fails before any long work
    from pipeline.world.trial import HEAP_STREAMS

    for v in list(rc.closed_loop) + list(rc.policies):
        if str(v.model) not in ("clean", "noisy"):
            raise ValueError(
                f"robustness variant {v.name!r} has model={v.model!r}: use clean "
                "(the network under test) or noisy (trained on the sensor's depth, "
                "with robustness.noisy_network)"
            )
        if str(v.model) == "noisy" and not bool(rc.noisy_network):
            raise ValueError(
                f"robustness variant {v.name!r} uses model=noisy but "
                "robustness.noisy_network is false (no second network is trained): "
                "use model=clean, or set robustness.noisy_network=true"
            )
        if str(v.split) not in HEAP_STREAMS:
            raise ValueError(
                f"robustness variant {v.name!r} has split={v.split!r}: use dev "
                f"({rc.closed_loop_trials} trials) or test (the evaluation's "
                f"{cfg.evaluate.num_trials} test heaps)"
            )
    # dev variants: the study's own count; test: the evaluation's (Table 3's heaps)
    trials = {"dev": int(rc.closed_loop_trials), "test": int(cfg.evaluate.num_trials)}
    with p.keep_latest():
        p.build(str(rc.train_version), str(rc.baseline_version), bool(rc.noisy_network))
        cl = closed_loop_rows(p, "sensor", rc.closed_loop, trials)
        cl += closed_loop_rows(p, "policy", rc.policies, trials)
    upstream = dict(sorted(p.versions.items()))
    config = stage_config(cfg, SECTIONS, NOT_AFFECTING_RESULT)
    # the preprocessing behind each sensor+<filter> input is read from conf/depth_filter/
    filters = {
        n.partition("+")[2]: OmegaConf.to_container(_filter_cfg(n.partition("+")[2]))
        for n in sorted(set(t1_inputs + t2_inputs))
        if "+" in n
    }
    config["robustness"]["depth_filters"] = filters

    def body(run: StageRun) -> None:
        t1 = table1_rows(p, t1_inputs, radius, int(rc.max_images), progress)
        t2, picks = table2_rows(p, t2_inputs, int(rc.max_images), progress)
        write_rows(run.work_dir / "table1.csv", t1)
        write_rows(run.work_dir / "table2.csv", t2)
        write_rows(run.work_dir / "closed_loop.csv", cl)
        tables = {
            "table1": t1,
            "table2": t2,
            "closed_loop": cl,
            "sensor": OmegaConf.to_container(
                compose("generate", base + [f"sensor={rc.sensor}"]).sensor, resolve=True
            ),
            "depth_filters": filters,
            "artifacts": upstream,
        }
        tables = json_safe(tables)
        write_json(run.work_dir / "robustness.json", tables)
        run.metrics.update({k: tables[k] for k in ("table1", "table2", "closed_loop")})
        with StageLog.for_stage(run.work_dir, STAGE, run.version) as log:
            _log(log, p, picks, int(rc.log_images), tables)

    return run_stage_from_config(cfg, STAGE, config, upstream, body)


main = stage_command("robustness", robustness, study=True)


if __name__ == "__main__":
    main()
