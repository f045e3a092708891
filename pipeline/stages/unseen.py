"""Unseen box sizes: Tables 1 and 2 on heaps of boxes the network never saw in training.

    python -m pipeline.stages.unseen [experiment=default] [unseen.boxes=unseen]

The paper trains on three box sizes (Sec. 4.3) and claims the planner generalises to the 12 box
types of its experiments (Fig. 8). This stage measures that claim on the planner's own tables.
With the command's own overrides:

* it reads the trained network (``unseen.train_version``) and the baseline artifact that
  compared it (``unseen.baseline_version``; both ``latest`` by default, as ``make reproduce``
  leaves them): the network and the Dex-Net-style GQ-CNNs, trained on the training heaps' boxes
  (the in-domain one) or on other objects;
* it runs (or reuses) ``generate boxes=<unseen.boxes>`` with a test split only
(``unseen.test_scenes`` heaps; no
  training or validation scenes) and its ``label`` artifact;

then measures on that unseen-size test split:

* **Table 1** (``pipeline.planner.evaluate``, the model's calibrated th) of the trained network;
* **Table 2** (``pipeline.stages.baseline``'s measure: G_opt less than 30 px from a true face
centre) of
  the trained network and the Dex-Net-style planners;
* **the closed loop** (``pipeline.stages.evaluate``, unless ``unseen.closed_loop_trials`` is 0):
every
  planner of ``evaluate.planners`` (the DCNN, the Dex-Net-style planners, the oracle) on
  ``unseen.closed_loop_trials`` heaps of 12 boxes of the unseen sizes
  (``eval_boxes=<unseen.closed_loop_boxes>``), the test split, observation-only execution:
  Table 3's rows (success and boxes picked with their Wilson intervals, trial ends, failure
  reasons) and how often each pattern dropped a box, by box mass.

The seen-size figures (the same tables on the paper's sizes' test split) are read from the
train and baseline manifests, so the report shows both side by side.

Artifact (``data/unseen/<version>/``)::

    table1.csv         set (seen | unseen), Top 1, Top 1 %, Top 5 %, Top 10 % (pooled and per
                       image), predictions, scored images, images with no prediction
    table2.csv         set, planner, images, no grasp, within 30 px, median distance
    closed_loop.csv    the closed loop's rows per planner (the evaluation's table3.csv)
    drops_by_mass.csv  per planner, box type (by mass) and pattern: held, dropped, drop rate
    unseen.json        all of it, with the versions of every artifact used
    log.rrd, log.mcap  sample unseen-size test images with each planner's G_opt

The unseen-size generation, label and evaluation artifacts never become ``latest``: it keeps
naming the ordinary pipeline's (``keep_latest``).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from omegaconf import DictConfig

from pipeline.artifacts import load_manifest, stage_config
from pipeline.artifacts.csvfile import write_rows
from pipeline.artifacts.jsonfile import json_safe, write_json
from pipeline.artifacts.pointers import keep_latest
from pipeline.artifacts.stages import compared_pair
from pipeline.artifacts.store import StageRun
from pipeline.runtime import cli
from pipeline.runtime.stage_artifacts import run_stage_from_config
from pipeline.tracking import StageLog

STAGE = "unseen"
SECTIONS = ("seed", "unseen")
NOT_AFFECTING_RESULT = (
    "unseen.force",
    "unseen.log_images",  # the versions are upstream
    "unseen.train_version",
    "unseen.baseline_version",
)
TABLE1_KEYS = ("top1", "top1pct", "top5pct", "top10pct")
PLANNER_COLORS = {
    "dcnn": (40, 200, 40),
    "gqcnn": (200, 40, 40),
    "gqcnn_ood": (240, 150, 40),
    "planarity": (120, 120, 255),
}


def build(base: list[str], uc, data: Path, models: Path) -> dict[str, Path]:
    """Run (or reuse) every artifact the study needs; name → folder."""
    if int(uc.test_scenes) < 1:
        raise ValueError(
            f"unseen.test_scenes={uc.test_scenes}: the unseen-size test split "
            "needs at least one heap"
        )
    boxes_file = cli.conf_file("boxes", uc.boxes)
    if not boxes_file.is_file():
        choices = sorted(p.stem for p in boxes_file.parent.glob("*.yaml"))
        raise ValueError(
            f"unseen.boxes={uc.boxes!r} is not a file of conf/boxes/: choose one of {choices}"
        )
    if int(uc.closed_loop_trials) < 0:
        raise ValueError(
            f"unseen.closed_loop_trials={uc.closed_loop_trials}: give a number of "
            "trials, or 0 for no closed loop"
        )
    loop_file = cli.conf_file("eval_boxes", uc.closed_loop_boxes)
    if int(uc.closed_loop_trials) > 0 and not loop_file.is_file():
        choices = sorted(p.stem for p in loop_file.parent.glob("*.yaml"))
        raise ValueError(
            f"unseen.closed_loop_boxes={uc.closed_loop_boxes!r} is not a file of "
            f"conf/eval_boxes/: choose one of {choices}"
        )
    # The planners under test: the trained network and the baseline artifact that compared it
    # (``make train``, ``make baseline``; ``latest`` unless named), as the evaluate stage reads
    # them.
    dirs = compared_pair(data, models, uc.train_version, uc.baseline_version, STAGE)

    def run(key: str, stage: str, extra: list[str]) -> Path:
        dirs[key] = cli.run_named_stage(stage, base + extra, f"{STAGE}: {key}")
        return dirs[key]

    # The unseen heaps, which must not become ``latest``.
    with keep_latest([data / "generate", data / "label", data / "evaluate"]):
        gen_u = run(
            "generate_unseen",
            "generate",
            [
                f"boxes={uc.boxes}",
                "generate.num_scenes=0",
                "generate.num_val_scenes=0",
                f"generate.num_test_scenes={int(uc.test_scenes)}",
            ],
        )
        run("label_unseen", "label", [f"label.generate_version={gen_u.name}"])
        if int(uc.closed_loop_trials) > 0:
            run(
                "evaluate_unseen",
                "evaluate",
                [
                    f"eval_boxes={uc.closed_loop_boxes}",
                    "evaluate.split=test",
                    f"evaluate.num_trials={int(uc.closed_loop_trials)}",
                    f"evaluate.train_version={dirs['train'].name}",
                    f"evaluate.baseline_version={dirs['baseline'].name}",
                ],
            )
    return dirs


def table1_row(name: str, res: dict) -> dict:
    """One Table 1 row (fractions, 6 decimals) of a ``precision_table`` result."""

    def r6(v):
        return None if v is None else round(float(v), 6)

    return {
        "set": name,
        **{k: r6(res.get(k)) for k in TABLE1_KEYS},
        **{f"per_image_{k}": r6((res.get("per_image") or {}).get(k)) for k in TABLE1_KEYS[1:]},
        "threshold": res.get("threshold"),
        "predictions": res.get("num_predictions"),
        "scored_images": res.get("scored_images"),
        "no_prediction_images": res.get("no_prediction_images"),
    }


def unseen_tables(cfg, dirs: dict[str, Path], progress: bool) -> tuple[list, list, dict]:
    """Table 1 and Table 2 rows (seen from the manifests, unseen measured here) and each
    planner's G_opt on the unseen test images."""
    from pipeline.dataset.labels import LabelSet
    from pipeline.dexnet.table2 import evaluate_table2, table2_rows
    from pipeline.planner.data import GraspDataset
    from pipeline.planner.planner import Planner
    from pipeline.planner.scoring import table1

    base = cli.scale_overrides(cfg, None)
    radius_t1 = float(cli.compose("train", base).train.match_radius_px)
    planner = Planner.load(dirs["train"])
    data = GraspDataset(
        dirs["generate_unseen"],
        LabelSet(dirs["label_unseen"], "test"),
        "test",
        planner.norm,
        planner.net.cfg.grid,
    )
    seen_t1 = load_manifest(dirs["train"])["metrics"]["table1"]
    t1 = [table1_row("seen", seen_t1), table1_row("unseen", table1(planner, data, radius_t1))]

    bcfg = cli.compose("baseline", base)
    radius = float(bcfg.baseline.table2_radius_px)
    res = evaluate_table2(bcfg, dirs["generate_unseen"], dirs["baseline"], dirs["train"], progress)
    seen_rows = load_manifest(dirs["baseline"])["metrics"]["table2"]["rows"]
    t2 = [{"set": "seen", **r} for r in seen_rows]
    t2 += [{"set": "unseen", **r} for r in table2_rows(res, radius, np.array([radius]))[0]]
    picks = {k: res[f"{k}_uv"] for k in res["planners"]}
    return t1, t2, picks


def closed_loop_rows(folder: Path | None) -> tuple[list, list]:
    """(Table 3's rows, the drops by mass) of the unseen-size evaluation artifact, from its
    manifest; ([], []) without one."""
    if folder is None:
        return [], []
    metrics = load_manifest(folder)["metrics"]
    return list(metrics["table3"]), list(metrics.get("drops_by_mass", []))


def _log(log: StageLog, gen_dir: Path, picks: dict, count: int, tables: dict) -> None:
    """Sample unseen-size test images with each planner's G_opt, and the tables."""
    from pipeline.dataset.pixels import pixels_to_points
    from pipeline.dataset.scenes import SceneDataset

    scenes = SceneDataset(gen_dir, "test")
    for i in range(min(count, len(scenes))):
        scene = scenes[i]
        log.set_time(sequences={"test_image": i}, clock_ns=i * 1_000_000_000)
        log.log_camera("unseen/camera", scene.intrinsics, scene.T_world_cam)
        log.log_depth("unseen/camera/depth", scene.depth_clean_m)
        for planner, uv in picks.items():
            if i < len(uv) and np.isfinite(uv[i]).all():
                color = np.asarray([PLANNER_COLORS.get(planner, (255, 255, 255))], np.uint8)
                log.log_points(
                    f"unseen/camera/g_opt/{planner}", pixels_to_points(scene, uv[i]), color
                )
        log.log_text("log", f"unseen test image {i}: {len(scene.boxes)} boxes")
    for key in ("table1", "table2"):
        for row in tables[key]:
            log.log_text("log", f"{key}: " + json.dumps(row))


def unseen(cfg: DictConfig, overrides: list[str] | None = None) -> Path:
    """Run the unseen-size study; returns its artifact folder. ``overrides``: passed to every
    stage it runs (the command line's own, by default none)."""
    uc = cfg.unseen
    base = cli.scale_overrides(cfg, overrides)
    dirs = build(base, uc, cli.data_root(cfg), Path(cfg.paths.models))
    upstream = {k: v.name for k, v in sorted(dirs.items())}
    config = stage_config(cfg, SECTIONS, NOT_AFFECTING_RESULT)

    def body(run: StageRun) -> None:
        t1, t2, picks = unseen_tables(cfg, dirs, bool(cfg.logging.progress))
        write_rows(run.work_dir / "table1.csv", t1)
        write_rows(run.work_dir / "table2.csv", t2)
        boxes = cli.compose("generate", base + [f"boxes={uc.boxes}"]).boxes
        loop, drops = closed_loop_rows(dirs.get("evaluate_unseen"))
        if "evaluate_unseen" in dirs:
            write_rows(run.work_dir / "closed_loop.csv", loop, empty_header=("planner",))
            write_rows(run.work_dir / "drops_by_mass.csv", drops, empty_header=("planner",))
        tables = json_safe(
            {
                "table1": t1,
                "table2": t2,
                "artifacts": upstream,
                "boxes": [
                    {"name": str(b.name), "size": [float(x) for x in b.size]} for b in boxes.types
                ],
                "closed_loop": loop,
                "drops_by_mass": drops,
            }
        )
        write_json(run.work_dir / "unseen.json", tables)
        run.metrics.update(
            {k: tables[k] for k in ("table1", "table2", "boxes", "closed_loop", "drops_by_mass")}
        )
        with StageLog.for_stage(run.work_dir, STAGE, run.version) as log:
            _log(log, dirs["generate_unseen"], picks, int(uc.log_images), tables)

    return run_stage_from_config(cfg, STAGE, config, upstream, body)


main = cli.stage_command("unseen", unseen, study=True)


if __name__ == "__main__":
    main()
