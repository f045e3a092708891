"""The report stage: gather the latest artifacts into ``reports/`` (tables, figures, README).

``report(cfg)`` is a pure function of the config and its upstream artifacts. For now it reports
the generated dataset, when a label artifact exists its grasp-point labels, and when a train
artifact exists the paper's Table 1 (Tables 2–3 follow once the baseline and evaluation stages
exist). It writes the
versioned artifact ``data/report/<version>/``::

    manifest.json                 what produced it (see pipeline.artifacts)
    README.md                     the report (Markdown; links are relative to this folder)
    tables/dataset_splits.csv     per split: scenes, boxes, removed boxes, settle steps
    tables/box_types.csv          per box type: boxes, mean visible area in the mask
    tables/label_classes.csv      per split and level (hand / robot): grasp points per class
    tables/label_ng_reasons.csv   per NG reason: grasp points per split
    tables/surface_accuracy.csv   per split: detected surfaces vs. the simulator's true faces
    figures/sample_depth.png      ``report.num_sample_images`` test depth images + instance masks
    figures/boxes_per_scene.png   histogram of boxes per scene, all splits
    figures/labels_sample.png     test depth images with their grasp points coloured by class
    tables/table1_precision.csv   Table 1: precision top 1 / top 1 % / 5 % / 10 %, paper and ours
    tables/threshold_calibration.csv  the validation curve that chose th (Eq. 3)
    figures/pr_curve.png          the DCNN's precision–recall curve on the test split
    tables/unseen_table1.csv, unseen_table2.csv  Tables 1 and 2 on unseen box sizes
    tables/robustness_*.csv       the robustness study (sensor model, Tables 1–2 per input,
                                  closed-loop variants, Sec. 8.4's policies, failures)
    figures/robustness_depth.png  ideal, sensor-model and filtered depth of one test image
    log.rrd, log.mcap             Rerun and MCAP logs of the tables (one text entry each)

The three ``label_*``/``surface_*`` tables and ``labels_sample.png`` exist only when there is a
label artifact (``report.label_version``, default the latest one); without one the README says
that labelling has not run. A label artifact made from another generation artifact than
``report.generate_version`` is an error. The labelling throughput (scenes/s) is run-dependent,
so it stays in the label manifest's ``timings`` and is not copied here.

``table1_precision.csv`` and ``pr_curve.png`` exist only when there is a train artifact
(``report.train_version``, default the latest one under ``paths.models``); it must have been
trained on the label artifact the report reads. Training timings are not copied either.

The ``robustness_*`` tables exist only when there is a robustness artifact
(``report.robustness_version``, default the latest one; ``pipeline.robustness``), read from its
``robustness.json``. Its depth figure draws the first test image of the study's noisy
generation artifact (its ``artifacts.generate_noisy``) when that artifact is under
``data/generate/``; the figure's filter (``conf/depth_filter/fill_median.yaml``) and whether the
generation artifact was found are part of the report's version key
(``config.robustness_figure``).

and then publishes README.md, figures/ and tables/ into ``paths.reports`` (``<root>/reports/``),
replacing those files one by one and leaving other files there alone.

Every file in the artifact is a function of the version key alone (no wall-clock times, no
absolute paths; PNGs are written without the "Software" metadata), so two runs into different
roots give byte-identical files (``log.rrd`` aside, see ``pipeline.tracking``).
The figures are drawn by ``pipeline.report_figures``.

Command line::

    python -m pipeline.report experiment=smoke
    python -m pipeline.report experiment=smoke report.generate_version=<version> report.force=true
    python -m pipeline.report experiment=smoke report.generate_version=<g> report.label_version=<l>
"""

from __future__ import annotations

import csv
import io
import json
import os
import re
import shutil
import uuid
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import hydra
import numpy as np
from omegaconf import DictConfig, OmegaConf

from pipeline.artifacts import (
    ArtifactError,
    available_versions,
    check_artifact,
    compute_version,
    load_manifest,
    resolve_artifact,
    run_stage,
    stage_config,
)
from pipeline.artifacts.store import StageRun
from pipeline.cli import CONF_DIR, data_root, stage_main
from pipeline.dataset.scenes import SPLITS, SceneDataset
from pipeline.dataset.storage import read_npz
from pipeline.label import NG_REASONS, LabelSet
from pipeline.labelling.types import GraspClass
from pipeline.report_figures import (  # noqa: F401 (FIG_DPI, PNG_METADATA, _outline: API)
    CLASS_MEANING,
    FIG_DPI,
    PNG_METADATA,
    _outline,
    figure_boxes_per_scene,
    figure_labels_sample,
    figure_planner_points,
    figure_pr_curve,
    figure_servo_convergence,
    figure_table2_curve,
    figure_sample_depth,
    figure_sensor_depth,
)
from pipeline.planner.evaluate import PAPER_TABLE1
from pipeline.tracking import StageLog

STAGE = "report"
SECTIONS = ("report",)
# The upstream versions cover which artifacts are read.
NOT_AFFECTING_RESULT = ("report.force", "report.generate_version", "report.label_version",
                        "report.train_version", "report.baseline_version",
                        "report.evaluate_version", "report.robustness_version",
                        "report.ablation_version", "report.unseen_version")
# Files whose content is measured wall-clock time: the same artifacts give other numbers on
# another run, so `make repro-check` skips them (they are listed in metrics.volatile_files).
VOLATILE_FILES = ("tables/planning_time.csv", "tables/table3_timing.csv")

PUBLISHED = ("README.md", "figures", "tables")
NONE = "—"  # shown in Markdown where a value does not exist (e.g. an empty split)


# ---------------------------------------------------------------------- tables
@dataclass
class Table:
    """A table written both as Markdown (formatted) and as CSV (plain values)."""

    name: str  # CSV file stem
    headers: list[str]
    rows: list[list[Any]]  # None = no value (empty split, no boxes of a type)
    formats: list[str] = field(default_factory=list)  # per column, e.g. "{:.2f}"; "" = str()
    csv_formats: list[str] | None = None  # the CSV's, when not ``formats`` ("" = full precision)
    text_columns: int = 1  # leading columns aligned left in Markdown

    def _cell(self, value: Any, col: int, missing: str, formats: list[str]) -> str:
        if value is None:
            return missing
        fmt = formats[col] if col < len(formats) else ""
        return fmt.format(value) if fmt else str(value)

    def csv_text(self) -> str:
        formats = self.formats if self.csv_formats is None else self.csv_formats
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        w.writerow(self.headers)
        for row in self.rows:
            w.writerow([self._cell(v, i, "", formats) for i, v in enumerate(row)])
        return buf.getvalue()

    def markdown(self) -> str:
        align = ["---" if i < self.text_columns else "---:" for i in range(len(self.headers))]
        lines = ["| " + " | ".join(self.headers) + " |", "|" + "|".join(align) + "|"]
        for row in self.rows:
            lines.append("| " + " | ".join(self._cell(v, i, NONE, self.formats)
                                           for i, v in enumerate(row)) + " |")
        return "\n".join(lines) + "\n"


@dataclass
class DatasetStats:
    """What the report reads from the scenes themselves (via ``SceneDataset``)."""

    scenes: dict[str, int]
    boxes: dict[str, int]
    not_settled: dict[str, int]
    settle_steps: dict[str, np.ndarray]  # per split, one value per scene
    type_names: list[str]
    type_sizes: list[list[float]]  # metres
    type_boxes: np.ndarray  # (T,) boxes of each type, all splits
    type_visible_px: np.ndarray  # (T,) summed visible pixels of those boxes
    image_size: tuple[int, int]  # (W, H)


def dataset_stats(gen_dir: Path) -> DatasetStats:
    """Count boxes per type and their visible mask pixels over every scene of every split."""
    meta = SceneDataset(gen_dir, "train")
    types = meta.box_types
    n_types = len(types)
    type_boxes = np.zeros(n_types, dtype=np.int64)
    type_px = np.zeros(n_types, dtype=np.int64)
    scenes, boxes, not_settled, steps = {}, {}, {}, {}
    image_size = (int(meta.intrinsics.width), int(meta.intrinsics.height))
    for split in SPLITS:
        ds = SceneDataset(gen_dir, split)
        scenes[split] = len(ds)
        boxes[split] = 0
        not_settled[split] = 0
        split_steps = []
        for scene in ds:
            n = len(scene.boxes)
            boxes[split] += n
            not_settled[split] += int(not scene.settled)
            split_steps.append(scene.settle_steps)
            if n == 0:
                continue
            px = np.bincount(scene.mask.ravel(), minlength=n + 1)[1:n + 1]
            kinds = np.array([b.type_index for b in scene.boxes], dtype=np.int64)
            np.add.at(type_boxes, kinds, 1)
            np.add.at(type_px, kinds, px)
        steps[split] = np.asarray(split_steps, dtype=np.int64)
    return DatasetStats(scenes, boxes, not_settled, steps,
                        [t["name"] for t in types], [list(t["size"]) for t in types],
                        type_boxes, type_px, image_size)


def _split_metrics(gen_manifest: dict, gen_dir: Path) -> dict[str, dict]:
    try:
        splits = gen_manifest["metrics"]["splits"]
        return {s: splits[s] for s in SPLITS}
    except (KeyError, TypeError):
        raise ArtifactError(
            f"{gen_dir}/manifest.json has no metrics.splits.<{'|'.join(SPLITS)}>: the generation "
            "artifact predates the report stage; recompute it with `make generate` "
            "(generate.force=true)."
        ) from None


def _check_consistent(splits: dict[str, dict], stats: DatasetStats, gen_dir: Path) -> None:
    """The manifest's metrics must describe the scenes actually stored."""
    problems = []
    for s in SPLITS:
        m = splits[s]
        if m.get("scenes", 0) != stats.scenes[s]:
            problems.append(f"{s}: manifest says {m.get('scenes')} scenes, files hold {stats.scenes[s]}")
        if stats.scenes[s] and m.get("boxes") != stats.boxes[s]:
            problems.append(f"{s}: manifest says {m.get('boxes')} boxes, files hold {stats.boxes[s]}")
    if problems:
        raise ArtifactError(f"generation artifact {gen_dir} is inconsistent ("
                            + "; ".join(problems) + "); run `make verify`, then recompute it.")


def _step_unit(time_step: float) -> str:
    """``"1/240 s"`` for a time step of 1/240 s, else e.g. ``"0.005 s"``."""
    inv = 1.0 / time_step
    return f"1/{round(inv)} s" if abs(inv - round(inv)) < 1e-6 else f"{time_step:g} s"


def splits_table(splits: dict[str, dict], stats: DatasetStats, time_step: float) -> Table:
    unit = _step_unit(time_step)
    headers = ["split", "scenes", "boxes", "mean boxes per scene",
               "boxes removed (left the bin)", "scenes at the step cap",
               f"median settle steps ({unit})", f"p90 settle steps ({unit})"]
    rows = []
    for s in SPLITS:
        m = splits[s]
        if not m.get("scenes"):
            rows.append([s, 0, 0, None, None, None, None, None])
            continue
        rows.append([s, m["scenes"], m["boxes"], m["boxes_per_scene_mean"],
                     m["boxes_removed_outside_bin"], m["scenes_not_settled"],
                     m["settle_steps_median"], m["settle_steps_p90"]])
    n = sum(stats.scenes.values())
    nb = sum(stats.boxes.values())
    all_steps = np.concatenate([stats.settle_steps[s] for s in SPLITS])
    if n:
        removed = sum(splits[s].get("boxes_removed_outside_bin", 0) for s in SPLITS)
        rows.append(["all", n, nb, round(nb / n, 3), removed, sum(stats.not_settled.values()),
                     float(np.median(all_steps)), float(np.percentile(all_steps, 90))])
    else:
        rows.append(["all", 0, 0, None, None, None, None, None])
    return Table("dataset_splits", headers, rows,
                 ["", "", "", "{:.2f}", "", "", "{:.0f}", "{:.0f}"])


def box_types_table(stats: DatasetStats) -> Table:
    W, H = stats.image_size
    headers = ["box type", "edge lengths (mm)", "boxes", "share of boxes (%)",
               f"mean visible area (px of {W}x{H})"]
    total = int(stats.type_boxes.sum())
    rows = []
    for k, name in enumerate(stats.type_names):
        n = int(stats.type_boxes[k])
        dims = " x ".join(f"{1000 * v:g}" for v in stats.type_sizes[k])
        rows.append([name, dims, n,
                     round(100.0 * n / total, 1) if total else None,
                     round(float(stats.type_visible_px[k]) / n, 1) if n else None])
    return Table("box_types", headers, rows, ["", "", "", "{:.1f}", "{:.1f}"])


# ---------------------------------------------------------------------- labels
LABEL_SECTION = "Labels (paper Sec. 4.3, Figs. 4–6)"
LABEL_NOT_RUN = "Labelling: not run yet (`make label`)."
# Where each NG reason is decided (pipeline.label): the hand level looks at the surface alone,
# the robot level at the whole robot in the scene.
NG_REASON_LEVEL = {"too_small": "hand", "center_occluded": "hand", "ik": "robot",
                   "joint_limits": "robot", "collision": "robot", "path_collision": "robot",
                   "path_joint_limits": "robot", "path_timeout": "robot", "path_lost": "robot"}
NG_REASON_MEANING = {
    "too_small": "the cups do not fit on the visible surface",
    "center_occluded": "the centre of the visible region lies on another box",
    "ik": "inverse kinematics does not reach the target camera pose",
    "joint_limits": "it is reached only outside the joint limits",
    "collision": "it is reached only with the arm or hand touching the bin or another box",
    "path_collision": "the pose is clear, but the servo's motion from home touches the bin, "
                      "another box or the robot itself",
    "path_joint_limits": "the servo from home, predicted on the exact surface, runs into the "
                         "joint limits",
    "path_timeout": "the servo from home, predicted on the exact surface, does not converge "
                    "in time",
    "path_lost": "the servo from home, predicted on the exact surface, loses sight of it",
}
# (manifest key, column header, Markdown format) of the surface-accuracy table.
ACCURACY_COLUMNS = (
    ("images", "images", ""), ("found", "found", ""), ("missed", "missed", ""),
    ("spurious", "spurious", ""), ("precision", "precision", "{:.3f}"),
    ("recall", "recall", "{:.3f}"),
    ("center_err_px_median", "centre error median (px)", "{:.3f}"),
    ("center_err_px_p90", "centre error p90 (px)", "{:.3f}"),
    ("center_err_mm_median", "centre error median (mm)", "{:.3f}"),
    ("center_err_mm_p90", "centre error p90 (mm)", "{:.3f}"),
    ("normal_err_deg_median", "normal error median (deg)", "{:.3f}"),
    ("normal_err_deg_p90", "normal error p90 (deg)", "{:.3f}"),
)


@dataclass
class LabelInfo:
    """The label artifact the report reads: its folder, manifest and per-split metrics."""

    folder: Path
    manifest: dict
    splits: dict[str, dict]  # manifest metrics.splits.<split>
    accuracy: dict  # manifest metrics.surface_accuracy (all splits)

    @property
    def version(self) -> str:
        return self.folder.name


def _optional_artifact(root: Path, stage: str, version: str) -> Path | None:
    """An upstream the report can do without: None when ``version`` is "latest" and no
    ``stage`` artifact exists yet; a named version that does not exist is an error."""
    try:
        folder = resolve_artifact(root, stage, version, key=f"report.{stage}_version")
    except ArtifactError:
        if version == "latest" and not available_versions(root, stage):
            return None
        raise
    return check_artifact(folder, f"report.{stage}_version")  # files match the manifest


def resolve_labels(root: Path, version: str, gen_version: str) -> LabelInfo | None:
    """The label artifact to report, or None when ``version`` is "latest" and none exists.

    Raises ``ArtifactError`` when a named version does not exist, when the artifact was made from
    another generation artifact than ``gen_version``, or when its manifest lacks the metrics.
    """
    folder = _optional_artifact(root, "label", version)
    if folder is None:
        return None
    manifest = load_manifest(folder)
    label_gen = (manifest.get("upstream") or {}).get("generate")
    if label_gen != gen_version:
        raise ArtifactError(
            f"label artifact {folder.name} was made from generation artifact {label_gen}, but the "
            f"report reads generation artifact {gen_version}: pass matching versions "
            f"(report.generate_version={label_gen} report.label_version={folder.name}), or rerun "
            f"`make label` (label.generate_version={gen_version}) and then the report.")
    keys = ("scenes", "grasp_points", "classes", "hand_level_classes", "ng_reasons",
            "surface_accuracy")
    try:
        metrics = manifest["metrics"]
        splits = {s: metrics["splits"][s] for s in SPLITS}
        accuracy = metrics["surface_accuracy"]
        complete = all(key in m for m in splits.values() for key in keys)
    except (KeyError, TypeError):
        complete = False
    if not complete:
        raise ArtifactError(
            f"{folder.name}/manifest.json (label) lacks metrics.splits.<split>.classes / "
            "hand_level_classes / ng_reasons / surface_accuracy or metrics.surface_accuracy: the "
            "label artifact predates the report's label section; recompute it with `make label` "
            "(label.force=true).")
    return LabelInfo(folder, manifest, splits, accuracy)


def check_labels(labels: LabelInfo, stats: DatasetStats) -> None:
    """The label files must hold one entry per generated scene and the manifest's class counts."""
    problems = []
    try:
        for s in SPLITS:
            ls = LabelSet(labels.folder, s)
            if len(ls) != stats.scenes[s]:
                problems.append(f"{s}: {len(ls)} labelled scenes, {stats.scenes[s]} generated")
                continue
            counts = np.zeros(len(GraspClass), dtype=np.int64)
            for i in range(len(ls)):
                counts += np.bincount(ls[i]["grasp_class"], minlength=len(GraspClass))
            expected = [int(labels.splits[s]["classes"].get(c.name, 0)) for c in GraspClass]
            if counts.tolist() != expected:
                problems.append(f"{s}: label files hold classes {counts.tolist()} (R, L, B, NG), "
                                f"the manifest says {expected}")
    except (OSError, KeyError, ValueError) as e:
        problems.append(f"unreadable label files ({type(e).__name__}: {e})")
    if problems:
        raise ArtifactError(f"label artifact {labels.version} is inconsistent ("
                            + "; ".join(problems) + "); run `make verify`, then recompute it.")


def _pct(n: int, total: int) -> float | None:
    """Percentage, unrounded (the tables round it once, when formatting)."""
    return 100.0 * n / total if total else None


def label_classes_table(labels: LabelInfo) -> Table:
    """Per split (and all) and level: grasp points of each class, with percentages."""
    headers = ["split", "level", "scenes", "grasp points", "grasp points per scene"]
    for c in GraspClass:
        headers += [c.name, f"{c.name} (%)"]
    rows = []
    totals = {"hand_level_classes": np.zeros(len(GraspClass), np.int64),
              "classes": np.zeros(len(GraspClass), np.int64)}
    n_scenes = 0
    for split in [*SPLITS, "all"]:
        if split != "all":
            n_scenes += int(labels.splits[split]["scenes"])
        scenes = n_scenes if split == "all" else int(labels.splits[split]["scenes"])
        for key, level in (("hand_level_classes", "hand"), ("classes", "robot")):
            if split == "all":
                counts = totals[key]
            else:
                counts = np.array([int(labels.splits[split][key].get(c.name, 0))
                                   for c in GraspClass], np.int64)
                totals[key] += counts
            total = int(counts.sum())
            row = [split, level, scenes, total, total / scenes if scenes else None]
            for c in GraspClass:
                row += [int(counts[c]), _pct(int(counts[c]), total)]
            rows.append(row)
    formats = ["", "", "", "", "{:.1f}"] + ["", "{:.1f}"] * len(GraspClass)
    csv_formats = ["", "", "", "", "{:.3f}"] + ["", "{:.2f}"] * len(GraspClass)
    return Table("label_classes", headers, rows, formats, csv_formats, text_columns=2)


def label_ng_reasons_table(labels: LabelInfo) -> Table:
    """Per NG reason: grasp points of each split, all splits, share of all NG points."""
    names = [r for r in NG_REASONS if r]
    names += sorted({r for m in labels.splits.values() for r in m["ng_reasons"]} - set(names))
    headers = ["NG reason", "level", *SPLITS, "all", "share of NG (%)"]
    per = {r: [int(labels.splits[s]["ng_reasons"].get(r, 0)) for s in SPLITS] for r in names}
    ng_total = sum(sum(v) for v in per.values())
    rows = [[r, NG_REASON_LEVEL.get(r, NONE), *per[r], sum(per[r]), _pct(sum(per[r]), ng_total)]
            for r in names]
    split_totals = [sum(per[r][k] for r in names) for k in range(len(SPLITS))]
    rows.append(["total", "", *split_totals, ng_total, 100.0 if ng_total else None])
    formats = [""] * (len(headers) - 1) + ["{:.1f}"]
    csv_formats = [""] * (len(headers) - 1) + ["{:.2f}"]
    return Table("label_ng_reasons", headers, rows, formats, csv_formats, text_columns=2)


def surface_accuracy_table(labels: LabelInfo) -> Table:
    """Per split (and all): detected surfaces matched against the simulator's true faces."""
    headers = ["split"] + [h for _, h, _ in ACCURACY_COLUMNS]
    rows = []
    for split in [*SPLITS, "all"]:
        acc = labels.accuracy if split == "all" else labels.splits[split]["surface_accuracy"]
        rows.append([split] + [acc.get(key) for key, _, _ in ACCURACY_COLUMNS])
    formats = [""] + [f for _, _, f in ACCURACY_COLUMNS]
    return Table("surface_accuracy", headers, rows, formats, csv_formats=[""] * len(headers))


def render_labels(labels: LabelInfo | None, tables: dict[str, Table],
                  figure: str | None) -> list[str]:
    """README lines of the labels section (``figure``: the sample-labels figure, if drawn)."""
    out = [f"## {LABEL_SECTION}", ""]
    if labels is None:
        return out + [LABEL_NOT_RUN, ""]
    cfg = labels.manifest.get("config", {})
    robot_checks = (cfg.get("label") or {}).get("robot_checks", True)
    surf = cfg.get("surfaces") or {}
    classes = ", ".join(f"{c.name} ({CLASS_MEANING[c]})" for c in GraspClass)
    out += [
        f"Grasp points and their classes from label artifact `{labels.version}`, from its "
        "manifest's metrics. Every visible planar face found by RANSAC gives one grasp point "
        f"(its centre); its class is one of {classes}.",
        "",
        "### Grasp points per class",
        "",
        "*hand*: the hand-level class from the surface alone (Figs. 5, 6); *robot*: the final "
        "class after the robot-level check (Fig. 4e), which turns B, L and R into NG when the "
        "robot cannot take the grasp"
        + ("" if robot_checks else " (not run: `label.robot_checks=false`, so both levels agree)")
        + ". Percentages are of the row's grasp points.",
        "",
        tables["label_classes"].markdown(),
        "### NG reasons",
        "",
        "Grasp points labelled NG, by the check that failed: "
        + "; ".join(f"*{r}* ({NG_REASON_LEVEL[r]} level): {m}"
                    for r, m in NG_REASON_MEANING.items()) + ".",
        "",
        tables["label_ng_reasons"].markdown(),
        "### Surface detection accuracy",
        "",
        "Detected surfaces against the true visible faces computed from the simulator's box "
        "poses" + (f" (faces with at least {surf['truth_min_visible_px']} visible pixels; a "
                   f"match has the same box, centres within "
                   f"{1000 * float(surf['match_max_center_dist']):g} mm and normals within "
                   f"{float(surf['match_max_normal_deg']):g}°)"
                   if {"truth_min_visible_px", "match_max_center_dist",
                       "match_max_normal_deg"} <= set(surf) else "")
        + ". *Found*: matched true faces; *missed*: true faces without a detection; "
        "*spurious*: detections without a true face. Errors are over the matched pairs: "
        "the grasp point's distance in the image (px) and in 3-D (mm), and the angle between "
        "the normals.",
        "",
        tables["surface_accuracy"].markdown(),
        "### Throughput",
        "",
        "Labelling speed (scenes per second; seconds per scene for surface detection and for "
        "the robot-level checks) depends on the machine and the run, so it is not copied into "
        "this report, whose files depend on the artifact versions alone: see the label "
        f"manifest's timings (`scenes_per_s`, `surface_detection_s_per_scene`, "
        f"`robot_checks_s_per_scene` in `data/label/{labels.version}/manifest.json`).",
        "",
        "CSV versions: [tables/label_classes.csv](tables/label_classes.csv), "
        "[tables/label_ng_reasons.csv](tables/label_ng_reasons.csv), "
        "[tables/surface_accuracy.csv](tables/surface_accuracy.csv)."
        + (f" Sample labels: [{figure}]({figure})." if figure else ""),
        "",
    ]
    return out


# ---------------------------------------------------------------------- training (Table 1)
TABLE1_SECTION = "Table 1 — precision of the DCNN's predictions (paper Sec. 7)"
TRAIN_NOT_RUN = "Training: not run yet (`make train`)."
# (manifest key, column header) of Table 1; the paper's values are pipeline.planner.evaluate's.
TABLE1_COLUMNS = (("top1", "Top 1"), ("top1pct", "Top 1 %"), ("top5pct", "Top 5 %"),
                  ("top10pct", "Top 10 %"))


@dataclass
class ArtifactInfo:
    """An upstream artifact the report reads (train, baseline, evaluate): folder and manifest."""

    folder: Path
    manifest: dict

    @property
    def version(self) -> str:
        return self.folder.name

    @property
    def metrics(self) -> dict:
        return self.manifest["metrics"]


TrainInfo = BaselineInfo = EvaluateInfo = ArtifactInfo  # names that say which one is meant


def resolve_train(models: Path, version: str, label_version: str | None) -> TrainInfo | None:
    """The training artifact to report, or None when ``version`` is "latest" and none exists.

    Raises ``ArtifactError`` when a named version does not exist, when the artifact was trained
    on another label artifact than ``label_version``, or when its manifest lacks Table 1.
    """
    folder = _optional_artifact(models, "train", version)
    if folder is None:
        return None
    manifest = load_manifest(folder)
    train_label = (manifest.get("upstream") or {}).get("label")
    if train_label != label_version:
        used = label_version if label_version is not None else "none (no label artifact)"
        raise ArtifactError(
            f"train artifact {folder.name} was trained on label artifact {train_label}, but the "
            f"report reads label artifact {used}: pass matching versions "
            f"(report.label_version={train_label} report.train_version={folder.name}), or rerun "
            f"`make train` (train.label_version={label_version}) and then the report.")
    try:
        metrics = manifest["metrics"]
        complete = (all(key in metrics["table1"] for key, _ in TABLE1_COLUMNS)
                    and {"precision", "recall"} <= set(metrics["pr_curve"])
                    and {"width", "parameters", "macs_per_image"} <= set(metrics["network"]))
    except (KeyError, TypeError):
        complete = False
    if not complete:
        raise ArtifactError(
            f"{folder.name}/manifest.json (train) lacks metrics.table1 / pr_curve / network: the "
            "train artifact predates the report's Table 1; recompute it with `make train` "
            "(train.force=true).")
    return TrainInfo(folder, manifest)


def table1_table(trained: TrainInfo) -> Table:
    """Table 1: the paper's precision and ours (percent; CSV with 4 decimals): the pooled and
    per-image figures at the calibrated th, and the old definitions in one labelled row."""
    ours = trained.metrics["table1"]

    def pct(v):
        return None if v is None else 100.0 * float(v)

    th = ours.get("threshold")
    at = f"th = {float(th):g}" if th is not None else "no threshold"
    headers = ["", *(h for _, h in TABLE1_COLUMNS)]
    rows = [["paper", *(100.0 * PAPER_TABLE1[k] for k, _ in TABLE1_COLUMNS)],
            [f"this reproduction, pooled top k % ({at})",
             *(pct(ours[k]) for k, _ in TABLE1_COLUMNS)]]
    if "per_image" in ours:
        rows.append([f"this reproduction, per-image top k % ({at})", pct(ours["top1"]),
                     *(pct(ours["per_image"].get(k)) for k, _ in TABLE1_COLUMNS[1:])])
    if "legacy" in ours:
        rows.append(["old definition (no threshold; top 1 over images with a prediction)",
                     *(pct(ours["legacy"].get(k)) for k, _ in TABLE1_COLUMNS)])
    n = len(TABLE1_COLUMNS)
    return Table("table1_precision", headers, rows, [""] + ["{:.2f} %"] * n,
                 csv_formats=[""] + ["{:.4f}"] * n)


def threshold_table(trained: TrainInfo) -> Table | None:
    """The validation curve that chose th (``pipeline.planner.calibration``), percent."""
    info = trained.metrics.get("threshold")
    if not info or not info.get("curve"):
        return None
    rows = [[r["threshold"], *(None if r[k] is None else 100.0 * r[k]
                               for k in ("gopt_accuracy", "no_candidate", "precision", "recall",
                                         "f1"))] for r in info["curve"]]
    return Table("threshold_calibration",
                 ["th", "G_opt correct", "no candidate", "precision", "recall", "F1"], rows,
                 ["{:g}"] + ["{:.2f} %"] * 5, csv_formats=["{:g}"] + ["{:.4f}"] * 5)


def render_train(trained: TrainInfo | None, tables: dict[str, Table],
                 figure: str | None) -> list[str]:
    """README lines of the Table 1 section (``figure``: the PR-curve figure, if drawn)."""
    out = [f"## {TABLE1_SECTION}", ""]
    if trained is None:
        return out + [TRAIN_NOT_RUN, ""]
    m = trained.metrics
    t1 = m["table1"]
    net = m["network"]
    cfg = trained.manifest.get("config", {})
    radius = t1.get("radius_px", (cfg.get("train") or {}).get("match_radius_px"))
    images = m.get("images") or {}
    epochs = m.get("epochs", (cfg.get("train") or {}).get("epochs"))
    out += [
        f"Precision (%) of the DCNN of train artifact `{trained.version}` on the test split "
        f"({t1.get('num_images', images.get('test'))} images, "
        f"{t1.get('num_predictions')} ranked predictions, "
        f"{t1.get('num_ground_truth')} ground-truth grasp points), from its manifest's metrics; "
        "the paper's row is copied from its Table 1 for comparison.",
        "",
        tables["table1_precision"].markdown(),
        "*Precision* (the paper gives no definition; this is ours, "
        "`pipeline/planner/evaluate.py`): every cell of a test image whose confidence "
        "S = max p(c) exceeds th gives one prediction (its grasp point and its class argmax "
        "p(c)); cells whose class is NG are not predictions, and ground-truth points of class NG "
        "are ignored. Within an image, predictions are matched in descending S: one is correct "
        f"when a not yet matched ground-truth grasp point of the *same class* (R, L or B) lies "
        f"within {float(radius):g} pixels. *Top 1*: the share of the "
        f"{t1.get('scored_images', '')} test images that have a graspable ground-truth point "
        "whose highest-S prediction is correct; an image with no prediction above th "
        f"({t1.get('no_prediction_images', '—')} of them) is a miss. *Top k % (pooled)*: all "
        "predictions of all test images pooled and sorted by S; the precision of the first "
        "ceil(k/100 · M) of the M predictions. *Top k % (per image)*: the same within each "
        "scored image, averaged over them (no prediction: 0). The old definition's row has no "
        "threshold and averages top 1 over the images that have any prediction.",
        "",
    ]
    thr = trained.metrics.get("threshold")
    if thr and "threshold_calibration" in tables:
        how = ("calibrated on the validation split" if thr.get("rule") == "calibrated"
               else "fixed by `train.threshold`")
        out += [
            f"**Threshold th = {float(thr['value']):g}** ({how}; `pipeline/planner/"
            "calibration.py`): the grid value with the largest F1 of the planner's detections "
            "above th on the validation split (matched to label points of the same class within "
            f"{float(radius):g} px, as in Table 1; precision and recall pooled over the split); "
            "ties go to the lowest th. The same th is stored in the model and used by Table 2, "
            "the closed loop and the robustness study. The validation curve (*G_opt correct*: "
            "the share of validation images with a graspable point whose first Eq. 7 candidate "
            "has a label point of its class that near; *no candidate*: nothing above th):",
            "",
            tables["threshold_calibration"].markdown(),
        ]
    out += [
        f"Network: width multiplier {float(net['width']):g}, {int(net['parameters']):,} "
        f"parameters, {int(net['macs_per_image']):,} multiply-accumulates per image "
        f"({2 * int(net['macs_per_image']) / 1e9:.3f} GFLOPs, convolutions only). Trained on "
        f"{images.get('train')} training images for {epochs} epoch"
        f"{'' if epochs == 1 else 's'}" + (
            f" of at most {m['max_epochs']} (validation-based stopping, patience "
            f"{(cfg.get('train') or {}).get('patience')}); the model is epoch {m['best_epoch']}, "
            "the one with the lowest validation loss." if "best_epoch" in m else "."),
        "",
        "CSV versions: [tables/table1_precision.csv](tables/table1_precision.csv), "
        "[tables/threshold_calibration.csv](tables/threshold_calibration.csv)."
        + (f" Precision–recall curve: [{figure}]({figure})." if figure else ""),
        "",
    ]
    return out


# ---------------------------------------------------------------------- Table 2 (baseline)
TABLE2_SECTION = "Table 2: grasp points near surface centres, ours vs. Dex-Net (Sec. 8.1.1)"
BASELINE_NOT_RUN = "Dex-Net-style comparison: not run yet (`make baseline`)."


def resolve_baseline(root: Path, version: str, gen_version: str,
                     train_version: str | None) -> BaselineInfo | None:
    """The baseline artifact to report, or None when ``version`` is "latest" and none exists.

    Raises ``ArtifactError`` when a named version does not exist, when it was made from another
    generation artifact, when its DCNN row comes from another train artifact than the report's,
    or when its manifest lacks Table 2.
    """
    folder = _optional_artifact(root, "baseline", version)
    if folder is None:
        return None
    manifest = load_manifest(folder)
    up = manifest.get("upstream") or {}
    if up.get("generate") != gen_version:
        raise ArtifactError(
            f"baseline artifact {folder.name} was made from generation artifact "
            f"{up.get('generate')}, but the report reads {gen_version}: pass matching versions "
            f"(report.baseline_version=...), or rerun `make baseline` and then the report.")
    if up.get("train") is not None and train_version is not None and up["train"] != train_version:
        raise ArtifactError(
            f"baseline artifact {folder.name} compared the DCNN of train artifact {up['train']}, "
            f"but the report reads train artifact {train_version}: rerun `make baseline` "
            f"(baseline.train_version={train_version}) and then the report.")
    try:
        complete = bool(manifest["metrics"]["table2"]["rows"]) and (folder / "chosen.npz").is_file()
    except (KeyError, TypeError):
        complete = False
    if not complete:
        raise ArtifactError(f"{folder.name}/manifest.json (baseline) lacks metrics.table2; "
                            "recompute it with `make baseline` (baseline.force=true).")
    return BaselineInfo(folder, manifest)


def table2_table(info: BaselineInfo) -> Table:
    """Table 2: the paper's rows and ours, share of images within the radius (percent)."""
    t2 = info.metrics["table2"]
    radius = float(t2["radius_px"])
    key = f"within_{radius:g}px"
    paper = t2["paper"]["within_30px"]
    old = f"{key}_inclusive"
    headers = ["", "planner", f"less than {radius:g} px", "images", "no grasp",
               f"less than {radius:g} px where a grasp was found", "median distance (px)",
               f"old definition: at most {radius:g} px"]
    rows = [["paper", "Dex-Net 4.0", 100.0 * paper["dexnet4"], None, None, None, None, None],
            ["paper", "ours (DCNN)", 100.0 * paper["ours"], None, None, None, None, None]]
    for r in t2["rows"]:
        images, missing = int(r["images"]), int(r["no_grasp"])
        found = images - missing
        rows.append(["this reproduction", r["name"], 100.0 * float(r[key]), images, missing,
                     100.0 * float(r[key]) * images / found if found else None,
                     r["median_distance_px"],
                     100.0 * float(r[old]) if old in r else None])
    return Table("table2_centre_distance", headers, rows,
                 ["", "", "{:.2f} %", "{}", "{}", "{:.2f} %", "{:.1f}", "{:.2f} %"],
                 csv_formats=["", "", "{:.4f}", "{}", "{}", "{:.4f}", "{:.3f}", "{:.4f}"],
                 text_columns=2)


def planning_time_table(info: BaselineInfo) -> Table:
    """Planning time per image of each planner, as measured in the baseline run (volatile)."""
    times = info.manifest.get("timings", {}).get("planning_ms_per_image", {})
    names = {r["planner"]: r["name"] for r in info.metrics["table2"]["rows"]}
    rows = [[names.get(k, k), v.get("mean"), v.get("median"), v.get("p90")]
            for k, v in times.items() if v]
    return Table("planning_time", ["planner", "mean (ms)", "median (ms)", "90th pct. (ms)"],
                 rows, ["", "{:.1f}", "{:.1f}", "{:.1f}"], csv_formats=["", "", "", ""])


def render_baseline(info: BaselineInfo | None, tables: dict[str, Table],
                    figures: dict[str, str]) -> list[str]:
    out = [f"## {TABLE2_SECTION}", ""]
    if info is None:
        return out + [BASELINE_NOT_RUN, ""]
    m = info.metrics
    cfg = info.manifest.get("config", {})
    g = m.get("gqcnn", {})
    labels = m.get("candidate_labels", {}).get("train", {})
    test = g.get("test", {})
    radius = float(m["table2"]["radius_px"])
    out += [
        f"Share of test images whose *optimal* grasp point lies less than {radius:g} pixels from "
        f"the centre of a true visible box face (baseline artifact `{info.version}`), as the "
        "paper defines it; the last column keeps the earlier definition (at most "
        f"{radius:g} px). The DCNN plans at its calibrated th (Table 1). The truth is "
        "the simulator's box geometry (`true_visible_faces`), not the labelling stage; an image "
        "where a planner finds no grasp counts as a miss; every planner sees the same images. "
        "The paper's rows are copied from its Table 2.",
        "",
        tables["table2_centre_distance"].markdown(),
        "**What the baseline is.** Dex-Net's weights and data cannot be downloaded here, so the "
        "comparison planner is rebuilt from Dex-Net's published method and trained on this "
        "project's heaps (`pipeline/dexnet/`): suction candidates sampled on the depth image "
        "(Sobel normals, 68-px border, 30° approach limit), the cross-entropy method with "
        "Dex-Net 4.0's suction parameters (200 seeds, 50 samples × 3 iterations, elite fraction "
        "0.25, Gaussian mixtures), and two quality functions: a GQ-CNN trained on candidates "
        "labelled by a suction contact model on the true geometry (seal of an 18-mm cup, "
        "weight as a wrench about the cup, robustness over perturbations: Dex-Net 3.0 style), "
        "and the training-free disc planarity. It plans one suction point for a single cup. "
        "Unlike Dex-Net 4.0 it is trained on about "
        f"{labels.get('candidates', 0):,} labelled candidates of these box heaps (Dex-Net 4.0: "
        "millions of grasps on thousands of object meshes) and its network is small "
        f"({g.get('parameters', 0):,} parameters).",
        "",
        f"GQ-CNN on the test split's labelled candidates: accuracy "
        f"{100 * test.get('accuracy', float('nan')):.1f} %, precision "
        f"{100 * test.get('precision', float('nan')):.1f} %, recall "
        f"{100 * test.get('recall', float('nan')):.1f} % (positives "
        f"{100 * test.get('positive_rate', float('nan')):.1f} %); "
        f"{(cfg.get('baseline') or {}).get('epochs')} epochs on "
        f"{g.get('train_samples', 0):,} candidates.",
        "",
        "Planning time per image of each planner, measured in the same run on this machine's "
        "CPU: [tables/planning_time.csv](tables/planning_time.csv) (wall-clock, so it is not "
        "part of the reproducibility check).",
        "",
        "CSV version: [tables/table2_centre_distance.csv](tables/table2_centre_distance.csv).",
        "",
    ]
    return out


# ---------------------------------------------------------------------- Table 3 (closed loop)
TABLE3_SECTION = "Table 3: closed-loop bin-picking (Secs. 5, 6)"
EVALUATE_NOT_RUN = "Closed-loop evaluation: not run yet (`make evaluate`)."
PLANNER_LABELS = {"dcnn": "ours: DCNN + descriptor + 2.5D VS (2 cups)",
                  "dexnet": "Dex-Net-style GQ-CNN + CEM, same robot (1 cup)",
                  "oracle": "oracle: the labelling stage's labels on the home image (ground "
                            "truth; the ceiling of execution, not a planner)"}
FAILURE_MEANING = {
    "no_seal": "a cup's rim did not lie on one face of one box (edge, corner, small face, "
               "tilt beyond the cup's compliance)",
    "dropped": "sealed, but the active cups cannot hold the box's weight and torque",
    "collision": "the arm or hand touched the bin (a protective stop; other boxes are pushed "
                 "aside under physics unless evaluate.stop_on_box_contact)",
    "joint_limits": "the servo ran into joint limits",
    "timeout": "the servo did not converge in time",
    "lost_target": "the descriptor found no surface at the tracked point",
}


def resolve_evaluate(root: Path, version: str) -> EvaluateInfo | None:
    """The evaluation artifact to report, or None when ``version`` is "latest" and none exists."""
    folder = _optional_artifact(root, "evaluate", version)
    if folder is None:
        return None
    manifest = load_manifest(folder)
    if not (manifest.get("metrics") or {}).get("table3"):
        raise ArtifactError(f"{folder.name}/manifest.json (evaluate) lacks metrics.table3; "
                            "recompute it with `make evaluate` (evaluate.force=true).")
    return EvaluateInfo(folder, manifest)


def table3_table(info: EvaluateInfo) -> Table:
    """Table 3: the paper's rows and ours (success rate; PPH of the robot's simulated motion)."""
    headers = ["", "system", "hand", "success rate", "attempts", "boxes picked",
               "boxes picked (%)", "mean PPH (motion only)"]
    rows = []
    for r in info.metrics["paper_table3"]:
        rows.append(["paper", r["system"], r["hand"], r["success"], None, None, None,
                     r["pph"] if r["pph"] is not None else None])
    for r in info.metrics["table3"]:
        rows.append(["this reproduction", PLANNER_LABELS.get(r["planner"], r["planner"]),
                     "suction (1 cup)" if r["planner"] == "dexnet" else "suction (2 cups)",
                     _times(r["success_rate"]), int(r["attempts"]),
                     f"{int(r['picked'])}/{int(r['boxes'])}",
                     _pct(int(r["picked"]), int(r["boxes"])), r["pph_motion"]])
    return Table("table3_success", headers, rows,
                 ["", "", "", "{:.1f} %", "{}", "{}", "{:.1f} %", "{}"],
                 csv_formats=["", "", "", "{:.1f}", "{}", "{}", "{:.1f}", "{}"],
                 text_columns=3)


def failures_table(info: EvaluateInfo) -> Table:
    from pipeline.picking.trial import OUTCOMES, TRIAL_ENDS

    kinds = OUTCOMES[1:]
    headers = ["planner", *kinds, "success on another box", *(f"trials ended: {e}" for e in TRIAL_ENDS)]
    rows = [[r["planner"], *(int(r[f"fail_{k}"]) for k in kinds), int(r["wrong_target"]),
             *(int(r[f"end_{e}"]) for e in TRIAL_ENDS)] for r in info.metrics["table3"]]
    return Table("table3_failures", headers, rows)


def table3_timing_table(info: EvaluateInfo) -> Table:
    """Measured wall-clock figures of the evaluation run (volatile)."""
    t = (info.manifest.get("timings") or {}).get("planners", {})
    headers = ["planner", "planning time median (ms; planner + run-time check)",
               "PPH incl. planning", "descriptor (ms/frame)", "control loop (Hz, wall)", "sim s per wall s",
               "trial wall time (s)"]
    rows = [[PLANNER_LABELS.get(k, k), v.get("planning_ms_median"), v.get("pph_with_planning"),
             v.get("descriptor_ms_median"), v.get("control_loop_hz"), v.get("sim_s_per_wall_s"),
             v.get("trial_wall_s_mean")] for k, v in t.items()]
    return Table("table3_timing", headers, rows)


def path_deviation_table(info: EvaluateInfo) -> Table:
    """How far the executed servo came from the path the run-time check predicted."""
    headers = ["planner", "attempts", "median (mm)", "largest (mm)"]
    rows = [[PLANNER_LABELS.get(r["planner"], r["planner"]), int(r["attempts"]),
             _num(r.get("path_deviation_mm_median")), _num(r.get("path_deviation_mm_max"))]
            for r in info.metrics["table3"]]
    return Table("table3_path_deviation", headers, rows, ["", "{}", "{:.1f}", "{:.1f}"])


def render_evaluate(info: EvaluateInfo | None, tables: dict[str, Table]) -> list[str]:
    out = [f"## {TABLE3_SECTION}", ""]
    if info is None:
        return out + [EVALUATE_NOT_RUN, ""]
    cfg = info.manifest.get("config", {})
    ev = cfg.get("evaluate") or {}
    motion = cfg.get("motion") or {}
    out += [
        f"Pick-and-place trials in pybullet (evaluation artifact `{info.version}`): "
        f"{ev.get('num_trials')} trials of {ev.get('boxes_per_trial')} boxes per planner, the "
        "same heaps (same seeds) for every planner, boxes of `eval_boxes` (the three training "
        "sizes and four unseen ones). Success rate = successful grasps / attempts. PPH = "
        "successful picks per hour of *simulated* robot time: servoing at "
        f"{(cfg.get('servo') or {}).get('control_rate_hz')} Hz, the approach, suction, lift, "
        f"and joint moves to the conveyor and back at {motion.get('max_joint_speed')} rad/s "
        f"and {motion.get('max_joint_accel')} rad/s²; the measured planning time is added in "
        "[tables/table3_timing.csv](tables/table3_timing.csv) (wall-clock, not part of the "
        "reproducibility check). The paper's rows are copied from its Table 3.",
        "",
        tables["table3_success"].markdown(),
        "Failures by kind (attempts) and how the trials ended:",
        "",
        tables["table3_failures"].markdown(),
        *[f"- *{k}*: {v}" for k, v in FAILURE_MEANING.items()],
        "",
        "The run-time check predicts the servo's camera path from home on the surface it "
        "checks (`robot.path_check`, docs/closed_loop.md). The farthest the executed camera came "
        "from that prediction, per attempt:",
        "",
        tables["table3_path_deviation"].markdown(),
        "CSV versions: [tables/table3_success.csv](tables/table3_success.csv), "
        "[tables/table3_failures.csv](tables/table3_failures.csv), "
        "[tables/table3_path_deviation.csv](tables/table3_path_deviation.csv).",
        "",
    ]
    return out


# ---------------------------------------------------------------------- ablation
ABLATION_SECTION = "Ablation: what each execution extension contributes"
ABLATION_NOT_RUN = "Ablation: not run yet (`make ablation`)."
ABLATION_MEANING = {
    "all_on": "every extension on (the defaults)",
    "no_gate": "no run-time check: the best-ranked candidate is executed unchecked",
    "no_path_check": "the check tests the grasp pose only, not the servo's path to it",
    "approach_direct": "the paper's servo straight from home to d*",
    "approach_pregrasp": "a pre-grasp on the surface normal instead of the lift",
    "retry_repeat": "no memory of failed plans",
    "paper_descriptor": "the paper's descriptor (fixed window tolerance, seed as it is, no "
                        "tracking of the surface's normal)",
    "paper_rotation": "the paper's axis rule only (no hand turned by 180° or 90°)",
    "all_off": "all of the above off: the paper's execution",
}


def resolve_ablation(root: Path, version: str):
    """(folder, rows) of the ablation artifact to report, or None when there is none."""
    folder = _optional_artifact(root, "ablation", version)
    if folder is None:
        return None
    rows = (load_manifest(folder).get("metrics") or {}).get("ablation")
    if not isinstance(rows, list):
        raise ArtifactError(f"{folder.name}/manifest.json (ablation) lacks metrics.ablation; "
                            "recompute it with `make ablation` (ablation.force=true).")
    return folder, rows


def ablation_table(rows: list[dict]) -> Table:
    headers = ["planner", "variant", "overrides", "success rate", "attempts", "boxes picked",
               "boxes picked (%)", "PPH (motion)", "no seal", "dropped", "collision",
               "lost target", "timeout", "trials ended: no grasp"]
    out = [[r["planner"], r["variant"], r["overrides"], _times(r.get("success_rate")),
            _int(r.get("attempts")), f"{_int(r.get('picked'))}/{_int(r.get('boxes'))}",
            _pct(int(r["picked"]), int(r["boxes"])), _num(r.get("pph_motion")),
            _int(r.get("fail_no_seal")), _int(r.get("fail_dropped")),
            _int(r.get("fail_collision")), _int(r.get("fail_lost_target")),
            _int(r.get("fail_timeout")), _int(r.get("end_no_grasp"))] for r in rows]
    return Table("ablation", headers, out,
                 ["", "", "", "{:.1f} %", "{}", "{}", "{:.1f} %", "{}", "{}", "{}", "{}", "{}",
                  "{}", "{}"], text_columns=3)


def render_ablation(ablation, tables: dict[str, Table]) -> list[str]:
    out = [f"## {ABLATION_SECTION}", ""]
    if ablation is None:
        return out + [ABLATION_NOT_RUN, ""]
    folder, rows = ablation
    trials = sorted({int(r["boxes"]) for r in rows})
    out += [
        f"Ablation artifact `{folder.name}` (`python -m pipeline.ablation`): each extension "
        "of the closed loop turned off on its own, then all at once, on the same heaps as "
        "Table 3 (one evaluation artifact per row, named in the CSV). For the oracle the labels "
        "and the run-time check follow the same switches, so its rows show what the extension "
        "does to execution alone; the DCNN keeps the network trained on the default labels, "
        "and a variant changes its execution only. Boxes per planner and variant: "
        f"{', '.join(str(t) for t in trials)}.",
        "",
        tables["ablation"].markdown(),
        *[f"- *{k}*: {v}" for k, v in ABLATION_MEANING.items()],
        "",
        "CSV version: [tables/ablation.csv](tables/ablation.csv).",
        "",
    ]
    return out


# ---------------------------------------------------------------------- unseen box sizes
UNSEEN_SECTION = "Unseen box sizes: Tables 1 and 2 on boxes not seen in training"
UNSEEN_NOT_RUN = "Unseen box sizes: not run yet (`make unseen`)."


def resolve_unseen(root: Path, version: str):
    """(folder, metrics) of the unseen-size artifact to report, or None when there is none."""
    folder = _optional_artifact(root, "unseen", version)
    if folder is None:
        return None
    metrics = load_manifest(folder).get("metrics") or {}
    if not all(isinstance(metrics.get(k), list) for k in ("table1", "table2", "boxes")):
        raise ArtifactError(f"{folder.name}/manifest.json (unseen) lacks metrics.table1 / "
                            "table2 / boxes; recompute it with `make unseen` "
                            "(unseen.force=true).")
    return folder, metrics


def unseen_table1(metrics: dict) -> Table:
    """Table 1 of the trained network on the seen- and the unseen-size test split (percent)."""
    keys = ("top1", "top1pct", "top5pct", "top10pct", "per_image_top1pct",
            "per_image_top5pct", "per_image_top10pct")
    headers = ["box sizes", "th", "Top 1", "Top 1 % (pooled)", "Top 5 % (pooled)",
               "Top 10 % (pooled)", "Top 1 % (per image)", "Top 5 % (per image)",
               "Top 10 % (per image)", "scored images", "no prediction"]
    rows = [[r["set"], _num(r.get("threshold")), *(_times(r.get(k)) for k in keys),
             _int(r.get("scored_images")), _int(r.get("no_prediction_images"))]
            for r in metrics["table1"]]
    return Table("unseen_table1", headers, rows,
                 ["", "{:g}"] + ["{:.2f} %"] * len(keys) + ["{}", "{}"], text_columns=1)


def unseen_table2(metrics: dict) -> Table:
    """Table 2 of every planner on the seen- and the unseen-size test split (percent)."""
    key, radius = _within_key(metrics["table2"])
    headers = ["box sizes", "planner", f"less than {radius} px", "images", "no grasp",
               "median distance (px)"]
    rows = [[r["set"], r.get("name", r["planner"]), _times(r.get(key)), _int(r.get("images")),
             _int(r.get("no_grasp")), _num(r.get("median_distance_px"))]
            for r in metrics["table2"]]
    return Table("unseen_table2", headers, rows,
                 ["", "", "{:.2f} %", "{}", "{}", "{:.1f}"], text_columns=2)


def render_unseen(unseen, tables: dict[str, Table]) -> list[str]:
    out = [f"## {UNSEEN_SECTION}", ""]
    if unseen is None:
        return out + [UNSEEN_NOT_RUN, ""]
    folder, metrics = unseen
    sizes = ", ".join(f"{b['name']} {' x '.join(f'{1000 * x:g}' for x in b['size'])} mm"
                      for b in metrics["boxes"])
    out += [
        f"Unseen-size artifact `{folder.name}` (`python -m pipeline.unseen`): the trained "
        "network and the Dex-Net-style planners, all trained on the three training sizes, on a "
        f"test split of heaps of other boxes ({sizes}), beside the same tables on the training "
        "sizes' test split (*seen*, from the train and baseline artifacts). Definitions as in "
        "Tables 1 and 2 above; the network plans at its calibrated th.",
        "",
        tables["unseen_table1"].markdown(),
        tables["unseen_table2"].markdown(),
        "CSV versions: [tables/unseen_table1.csv](tables/unseen_table1.csv), "
        "[tables/unseen_table2.csv](tables/unseen_table2.csv).",
        "",
    ]
    return out


# ---------------------------------------------------------------------- robustness (Secs. 8.4-8.5)
ROBUSTNESS_SECTION = "Robustness: sensor noise and the failure cases (Secs. 8.4, 8.5)"
ROBUSTNESS_NOT_RUN = ("Robustness study: not run yet (`make robustness`, i.e. "
                      "`python -m pipeline.robustness`).")
ROBUSTNESS_KEYS = ("table1", "table2", "closed_loop", "sensor", "artifacts")
ROBUSTNESS_FIGURE = "figures/robustness_depth.png"
ROBUSTNESS_FIGURE_FILTER = "fill_median"  # conf/depth_filter/<name>.yaml, the figure's 3rd panel
MODEL_LABELS = {"clean": "clean-trained", "noisy": "noisy-trained"}
ROBUSTNESS_PLANNERS = {"dcnn_clean": "ours (DCNN), clean-trained",
                       "dcnn_noisy": "ours (DCNN), noisy-trained",
                       "gqcnn": "Dex-Net-style GQ-CNN + CEM",
                       "planarity": "Dex-Net-style planarity + CEM"}
REFERENCE_POLICY = "paper"  # the policy rows are compared with this variant
SENSOR_MEANING = {  # pipeline.camera.sensor's parameters (SensorConfig); metres and degrees
    "name": "the sensor model (`conf/sensor/<name>.yaml`)",
    "enabled": "whether the model is applied (false: ideal depth)",
    "noise_sigma_0": "σ0 (m) of the axial noise "
                     "σ(z, θ) = σ0 + σ2·z² + σθ/√z · θ²/(π/2 − θ)²",
    "noise_sigma_2": "σ2 (m per m²): the noise growing with the square of depth",
    "noise_sigma_theta": "σθ (m·√m): the noise growing at grazing incidence θ",
    "projector_baseline": "projector–camera distance along x (m): projector shadows beside "
                          "depth steps",
    "dropout_angle_start_deg": "incidence angle (°) where steep-surface dropout starts",
    "dropout_angle_deg": "incidence angle (°) from which steep-surface dropout is certain",
    "min_range": "no data nearer than this (m)",
    "max_range": "no data farther than this (m)",
    "edge_jump": "a depth step between 4-neighbours (m)",
    "edge_dropout_prob": "chance that a pixel at such a step has no data",
    "quantisation_step": "depth unit (m)",
}


@dataclass
class RobustnessInfo(ArtifactInfo):
    """The robustness artifact: folder, manifest and its ``robustness.json`` (``data``)."""

    data: dict = field(default_factory=dict)


def _num(value: Any) -> float | None:
    """A table value as a float; None for a missing or not-a-number value (shown as —)."""
    if value is None or isinstance(value, bool):
        return None
    try:
        x = float(value)
    except (TypeError, ValueError):
        return None
    return x if np.isfinite(x) else None


def _int(value: Any) -> int | None:
    x = _num(value)
    return None if x is None else int(round(x))


def _times(value: Any, factor: float = 100.0) -> float | None:
    x = _num(value)
    return None if x is None else factor * x


def resolve_robustness(root: Path, version: str) -> RobustnessInfo | None:
    """The robustness artifact to report, or None when ``version`` is "latest" and none exists.

    Raises ``ArtifactError`` when a named version does not exist or when its ``robustness.json``
    lacks the tables, the sensor model or the artifact versions.
    """
    folder = _optional_artifact(root, "robustness", version)
    if folder is None:
        return None
    manifest = load_manifest(folder)
    try:
        # Python's json reads the NaN the study writes for undefined rates.
        data = json.loads((folder / "robustness.json").read_text())
        complete = (isinstance(data, dict) and set(ROBUSTNESS_KEYS) <= set(data)
                    and all(isinstance(data[k], list) for k in ROBUSTNESS_KEYS[:3])
                    and all(isinstance(data[k], dict) for k in ROBUSTNESS_KEYS[3:]))
    except (OSError, ValueError):
        complete = False
    if not complete:
        raise ArtifactError(
            f"{folder.name}/robustness.json (robustness) is missing or lacks "
            f"{' / '.join(ROBUSTNESS_KEYS)}: recompute it with `make robustness` "
            "(robustness.force=true).")
    return RobustnessInfo(folder, manifest, data)


def robustness_generation(root: Path, info: RobustnessInfo) -> Path | None:
    """The study's noisy generation artifact (drawn in the depth figure), None when it is not
    under ``root``; an artifact whose files do not match its manifest is an error."""
    version = info.data["artifacts"].get("generate_noisy")
    if not version:
        return None
    folder = Path(root) / "generate" / str(version)
    if not (folder / "manifest.json").is_file():
        return None
    return check_artifact(folder.resolve(), "report.robustness_version")


def _filter_config(name: str) -> DictConfig:
    return OmegaConf.load(Path(CONF_DIR) / "depth_filter" / f"{name}.yaml")


def robustness_table1_table(info: RobustnessInfo) -> Table:
    """Table 1 of each network on each input (percent; CSV with 4 decimals)."""
    headers = ["network", "input", *(h for _, h in TABLE1_COLUMNS), "predictions", "images"]
    rows = [[MODEL_LABELS.get(str(r.get("model")), str(r.get("model"))), str(r.get("input")),
             *(_times(r.get(k)) for k, _ in TABLE1_COLUMNS), _int(r.get("predictions")),
             _int(r.get("images"))] for r in info.data["table1"]]
    n = len(TABLE1_COLUMNS)
    return Table("robustness_table1", headers, rows, ["", ""] + ["{:.2f} %"] * n + ["{}", "{}"],
                 csv_formats=["", ""] + ["{:.4f}"] * n + ["{}", "{}"], text_columns=2)


def _within_key(rows: list[dict]) -> tuple[str, str]:
    """The Table 2 rows' ``within_<r>px`` key and its radius as text (``"30"``)."""
    for r in rows:
        for k in r:
            m = re.fullmatch(r"within_(.+)px", k)
            if m:
                return k, m.group(1)
    return "within_30px", "30"


def robustness_table2_table(info: RobustnessInfo) -> Table:
    """Table 2 of each planner on each input: share of images within the radius (percent)."""
    rows_in = info.data["table2"]
    key, radius = _within_key(rows_in)
    headers = ["planner", "input", "images", f"within {radius} px", "no grasp",
               "median distance (px)"]
    rows = [[ROBUSTNESS_PLANNERS.get(str(r.get("planner")), str(r.get("planner"))),
             str(r.get("input")), _int(r.get("images")), _times(r.get(key)),
             _int(r.get("no_grasp")), _num(r.get("median_distance_px"))] for r in rows_in]
    return Table("robustness_table2", headers, rows,
                 ["", "", "{}", "{:.2f} %", "{}", "{:.1f}"],
                 csv_formats=["", "", "{}", "{:.4f}", "{}", "{:.3f}"], text_columns=2)


def _ratio(num: Any, den: Any) -> str | None:
    a, b = _int(num), _int(den)
    return None if a is None or b is None else f"{a}/{b}"


def _closed_loop_row(r: dict) -> list[Any]:
    return [str(r.get("variant")), MODEL_LABELS.get(str(r.get("model")), str(r.get("model"))),
            str(r.get("overrides") or "-"), _times(r.get("success_rate")),
            _ratio(r.get("successes"), r.get("attempts")),
            _ratio(r.get("picked"), r.get("boxes")),
            _num(r.get("pph_motion"))]


CLOSED_LOOP_HEADERS = ["variant", "network", "overrides", "success rate",
                       "successes / attempts", "picked / boxes", "PPH (motion only)"]


def robustness_closed_loop_table(info: RobustnessInfo) -> Table:
    """The closed-loop variants of the sensor study (group ``sensor``)."""
    rows = [_closed_loop_row(r) for r in info.data["closed_loop"] if r.get("group") == "sensor"]
    return Table("robustness_closed_loop", CLOSED_LOOP_HEADERS, rows,
                 ["", "", "", "{:.1f} %", "", "", "{:.1f}"],
                 csv_formats=["", "", "", "{:.4f}", "", "", "{:.1f}"], text_columns=3)


def robustness_policies_table(info: RobustnessInfo) -> Table:
    """Sec. 8.4's policies (group ``policy``), with the change in success rate (percentage
    points) and PPH against the ``paper`` row; that row itself shows none."""
    policy = [r for r in info.data["closed_loop"] if r.get("group") == "policy"]
    ref = next((r for r in policy if r.get("variant") == REFERENCE_POLICY), None)
    ref_rate = _times(ref.get("success_rate")) if ref is not None else None
    ref_pph = _num(ref.get("pph_motion")) if ref is not None else None
    rows = []
    for r in policy:
        row = _closed_loop_row(r)
        rate, pph = row[3], row[6]
        own = r is ref
        row += [None if own or rate is None or ref_rate is None else rate - ref_rate,
                None if own or pph is None or ref_pph is None else pph - ref_pph]
        rows.append(row)
    headers = CLOSED_LOOP_HEADERS + [f"success rate vs. {REFERENCE_POLICY} (pp)",
                                     f"PPH vs. {REFERENCE_POLICY}"]
    return Table("robustness_policies", headers, rows,
                 ["", "", "", "{:.1f} %", "", "", "{:.1f}", "{:+.1f}", "{:+.1f}"],
                 csv_formats=["", "", "", "{:.4f}", "", "", "{:.1f}", "{:.4f}", "{:.1f}"],
                 text_columns=3)


def robustness_failures_table(info: RobustnessInfo) -> Table:
    """Failed attempts by kind of every closed-loop variant (the ``fail_*`` columns)."""
    rows_in = info.data["closed_loop"]
    kinds = list(dict.fromkeys(k for r in rows_in for k in r if k.startswith("fail_")))
    rows = [[str(r.get("group")), str(r.get("variant")), *(_int(r.get(k)) for k in kinds)]
            for r in rows_in]
    return Table("robustness_failures", ["group", "variant", *(k[5:] for k in kinds)], rows,
                 text_columns=2)


def _param_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return f"{value:g}"
    return str(value)


def robustness_sensor_table(info: RobustnessInfo) -> Table:
    """The sensor model's parameters, as the study recorded them."""
    rows = [[k, _param_value(v), SENSOR_MEANING.get(k)] for k, v in info.data["sensor"].items()]
    return Table("robustness_sensor_model", ["parameter", "value", "meaning"], rows,
                 text_columns=3)


def _input_meaning(name: str) -> str:
    if name == "ideal":
        return "*ideal*: the renderer's depth"
    if name == "sensor":
        return "*sensor*: the sensor model's depth"
    head, _, filt = name.partition("+")
    if head == "sensor" and filt:
        return (f"*{name}*: the sensor model's depth after `conf/depth_filter/{filt}.yaml` "
                "(`pipeline/camera/depth_filter.py`)")
    return f"*{name}*"


def render_robustness(info: RobustnessInfo | None, tables: dict[str, Table],
                      figure: str | None, figure_note: str | None = None) -> list[str]:
    """README lines of the robustness section (``figure``: the depth figure, if drawn;
    ``figure_note``: why it was not)."""
    out = [f"## {ROBUSTNESS_SECTION}", ""]
    if info is None:
        return out + [ROBUSTNESS_NOT_RUN, ""]
    data = info.data
    cfg = (info.manifest.get("config") or {}).get("robustness") or {}
    sensor = data["sensor"].get("name", cfg.get("sensor"))
    arts = data["artifacts"]
    inputs = list(dict.fromkeys(str(r.get("input")) for r in data["table1"] + data["table2"]))
    images = sorted({_int(r.get("images")) for r in data["table1"]} - {None})
    trials = cfg.get("closed_loop_trials")
    out += [
        f"Robustness artifact `{info.version}` (`python -m pipeline.robustness`): the method on "
        f"depth from the `{sensor}` sensor model instead of the ideal rendered depth, with a "
        "network trained on ideal depth (*clean-trained*, train artifact "
        f"`{arts.get('train_clean')}`) and one trained on the sensor's depth (*noisy-trained*, "
        f"`{arts.get('train_noisy')}`). Tables 1 and 2 are measured on the test split of the "
        f"noisy generation artifact `{arts.get('generate_noisy')}`"
        + (f" ({', '.join(str(n) for n in images)} images)" if images else "")
        + ", the same heaps as the clean one; the labels come from the ideal depth, so they "
        "are the same for every input. Inputs: " + "; ".join(_input_meaning(n) for n in inputs)
        + ". The closed-loop variants are ordinary evaluation artifacts of the DCNN planner"
        + (f" ({trials} trial{'' if trials == 1 else 's'} each)" if trials is not None else "")
        + ", all on the same heaps and seeds; they differ only in the overrides shown.",
        "",
        "### Sensor model",
        "",
        f"The parameters of `conf/sensor/{sensor}.yaml` as the study used them "
        "(`pipeline/camera/sensor.py`).",
        "",
        tables["robustness_sensor_model"].markdown(),
    ]
    if figure:
        out += ["The first test image's ideal depth, its depth from this model and that depth "
                f"after `depth_filter={ROBUSTNESS_FIGURE_FILTER}`: [{figure}]({figure}).", ""]
    elif figure_note:
        out += [figure_note, ""]
    out += [
        "### Sensor noise: Table 1",
        "",
        "Precision (%) of each network's predictions per input (Table 1's definition, "
        f"\"{TABLE1_SECTION}\").",
        "",
        tables["robustness_table1"].markdown(),
        "### Sensor noise: Table 2",
        "",
        "Share of test images whose optimal grasp point lies within the radius of a true "
        "surface centre, per planner and input (Table 2's measure, "
        f"\"{TABLE2_SECTION}\"; an image without a grasp counts as a miss).",
        "",
        tables["robustness_table2"].markdown(),
        "### Sensor noise: closed loop",
        "",
        "Success rate = successful grasps / attempts; PPH = successful picks per hour of "
        "simulated robot motion (as in Table 3).",
        "",
        tables["robustness_closed_loop"].markdown(),
        "### Sec. 8.4 failure cases: closed loop",
        "",
        "The paper's proposed fixes of its failure cases on ideal depth, each against the "
        f"paper's policy (the `{REFERENCE_POLICY}` row): differences in success rate are "
        "percentage points, in PPH picks per hour.",
        "",
        tables["robustness_policies"].markdown(),
        "Failed attempts by kind (see Table 3's list):",
        "",
        tables["robustness_failures"].markdown(),
        "CSV versions: "
        + ", ".join(f"[tables/{n}.csv](tables/{n}.csv)" for n in (
            "robustness_sensor_model", "robustness_table1", "robustness_table2",
            "robustness_closed_loop", "robustness_policies", "robustness_failures")) + ".",
        "",
    ]
    return out


# ---------------------------------------------------------------------- README
def _commit(manifest: dict) -> str:
    code = manifest.get("code", {})
    commit = code.get("commit")
    if not commit:
        return "unknown"
    return f"`{commit[:10]}`" + (" (+ uncommitted changes)" if code.get("dirty") else "")


def render_readme(version: str, upstream: dict[str, tuple[str, dict]], tables: dict[str, Table],
                  figures: dict[str, str], gen_cfg: dict, stats: DatasetStats,
                  labels: LabelInfo | None = None, trained: TrainInfo | None = None,
                  baseline: BaselineInfo | None = None,
                  evaluated: EvaluateInfo | None = None,
                  robustness: RobustnessInfo | None = None,
                  robustness_note: str | None = None, ablation=None, unseen=None) -> str:
    phys = gen_cfg.get("physics", {})
    dt = float(phys.get("time_step", 1 / 240))
    cap = phys.get("max_settle_steps")
    W, H = stats.image_size
    out = [
        "# Bin-picking reproduction: report",
        "",
        f"Report artifact `{version}`, built by `python -m pipeline.report` (`make report`) from the "
        "artifacts below. Every number here is computed from those artifacts; nothing is copied "
        "from the paper.",
        "",
        "## Artifacts used",
        "",
        "| stage | version | git commit |",
        "|---|---|---|",
    ]
    for stage, (ver, manifest) in upstream.items():
        out.append(f"| {stage} | `{ver}` | {_commit(manifest)} |")
    if labels is None:
        out.append(f"| label | not run yet (`make label`) | {NONE} |")
    if trained is None:
        out.append(f"| train | not run yet (`make train`) | {NONE} |")
    if baseline is None:
        out.append(f"| baseline | not run yet (`make baseline`) | {NONE} |")
    if evaluated is None:
        out.append(f"| evaluate | not run yet (`make evaluate`) | {NONE} |")
    if robustness is None:
        out.append(f"| robustness | not run yet (`make robustness`) | {NONE} |")
    if ablation is None:
        out.append(f"| ablation | not run yet (`make ablation`) | {NONE} |")
    if unseen is None:
        out.append(f"| unseen | not run yet (`make unseen`) | {NONE} |")
    out += [
        "",
        "Each artifact lives in `data/<stage>/<version>/`; its `manifest.json` holds the full "
        "config, package versions, creation time and file hashes (`make verify` re-checks them).",
        "",
        "## Dataset",
        "",
        "Generated heaps (paper Sec. 4.3), from the generation manifest's metrics.",
        "",
        tables["dataset_splits"].markdown(),
        f"*Boxes* are the boxes at rest in the bin (ground truth). *Boxes removed* came to rest "
        f"outside the bin and were deleted before rendering. *Scenes at the step cap* did not "
        f"come to rest within `physics.max_settle_steps` = {cap} steps "
        f"({cap * dt:.1f} s). Settle steps are physics steps of {_step_unit(dt)} "
        "from the first drop until the heap is at rest." if cap is not None else
        "*Boxes* are the boxes at rest in the bin (ground truth).",
        "",
        "### Box types",
        "",
        f"All splits, counted from the scenes. The visible area is the number of pixels of the "
        f"box in the {W}x{H} instance mask (0 for a fully hidden box).",
        "",
        tables["box_types"].markdown(),
        "CSV versions: [tables/dataset_splits.csv](tables/dataset_splits.csv), "
        "[tables/box_types.csv](tables/box_types.csv).",
        "",
    ]
    label_figure = "figures/labels_sample.png"
    out += render_labels(labels, tables, label_figure if label_figure in figures else None)
    pr_figure = "figures/pr_curve.png"
    out += render_train(trained, tables, pr_figure if pr_figure in figures else None)
    out += render_baseline(baseline, tables, figures)
    out += render_unseen(unseen, tables)
    out += render_evaluate(evaluated, tables)
    out += render_ablation(ablation, tables)
    out += render_robustness(robustness, tables,
                             ROBUSTNESS_FIGURE if ROBUSTNESS_FIGURE in figures else None,
                             robustness_note)
    out += ["## Figures", ""]
    for rel, caption in figures.items():
        out += [f"![{caption}]({rel})", "", f"*{caption}*", ""]
    out += [
        "## Paper tables",
        "",
        ("Table 1 of the paper (precision of the DCNN model's predictions) is reported above, "
         f"in \"{TABLE1_SECTION}\". " if trained is not None else
         "Table 1 of the paper (precision of the DCNN model's predictions) will appear above "
         "once the training stage has run (`make train`). ")
        + ("Table 2 (optimal grasp points within 30 pixels of a surface centre, ours vs. "
           f"Dex-Net) is reported above, in \"{TABLE2_SECTION}\". " if baseline is not None else
           "Table 2 (ours vs. Dex-Net) will appear above once the baseline stage has run "
           "(`make baseline`). ")
        + ("Table 3 (bin-picking success rate and speed) is reported above, in "
           f"\"{TABLE3_SECTION}\"." if evaluated is not None else
           "Table 3 (bin-picking success rate and speed) will appear above once the "
           "closed-loop evaluation has run (`make evaluate`)."),
        "",
    ]
    return "\n".join(out)


# ---------------------------------------------------------------------- publishing
def publish(artifact_dir: Path, reports_dir: Path) -> list[Path]:
    """Copy README.md, figures/ and tables/ of the artifact into ``reports_dir``.

    The files are first copied into a temporary sibling folder of ``reports_dir`` (same file
    system), then moved over the old ones with ``os.replace`` (README.md last), so a reader never
    sees a half-written file. Files in ``reports_dir`` that the artifact does not hold are kept.
    """
    artifact_dir, reports_dir = Path(artifact_dir), Path(reports_dir)
    rels = []
    for name in PUBLISHED:
        src = artifact_dir / name
        if src.is_file():
            rels.append(Path(name))
        elif src.is_dir():
            rels += sorted(p.relative_to(artifact_dir) for p in src.rglob("*") if p.is_file())
    rels.sort(key=lambda p: (p == Path("README.md"), p.as_posix()))  # README.md last
    reports_dir.mkdir(parents=True, exist_ok=True)
    tmp = reports_dir.parent / f".tmp-{reports_dir.name}-{uuid.uuid4().hex[:8]}"
    tmp.mkdir()
    try:
        for rel in rels:
            (tmp / rel).parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(artifact_dir / rel, tmp / rel)
        for rel in rels:
            (reports_dir / rel).parent.mkdir(parents=True, exist_ok=True)
            os.replace(tmp / rel, reports_dir / rel)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return [reports_dir / rel for rel in rels]


# ---------------------------------------------------------------------- the stage
def report(cfg: DictConfig) -> Path:
    """Run the report stage; returns the artifact folder (reused if it already exists).

    Raises ``ArtifactError`` (from ``resolve_artifact``) when there is no generation artifact,
    and from ``resolve_labels`` when the label artifact does not match it (no label artifact at
    all is fine: the report then leaves the labels out).
    """
    root = data_root(cfg)
    gen_dir = resolve_artifact(root, "generate", cfg.report.generate_version, verify=True,
                               key="report.generate_version")
    gen_version = gen_dir.name
    gen_manifest = load_manifest(gen_dir)
    splits = _split_metrics(gen_manifest, gen_dir)
    num_samples = int(cfg.report.num_sample_images)
    if num_samples < 0:
        raise ValueError(f"report.num_sample_images must be >= 0, got {num_samples}")
    labels = resolve_labels(root, str(cfg.report.label_version), gen_version)
    trained = resolve_train(Path(cfg.paths.models), str(cfg.report.train_version),
                            labels.version if labels is not None else None)
    baseline = resolve_baseline(root, str(cfg.report.baseline_version), gen_version,
                                trained.version if trained is not None else None)
    evaluated = resolve_evaluate(root, str(cfg.report.evaluate_version))
    robustness = resolve_robustness(root, str(cfg.report.robustness_version))
    ablated = resolve_ablation(root, str(cfg.report.ablation_version))
    unseen = resolve_unseen(root, str(cfg.report.unseen_version))
    robust_gen = robustness_generation(root, robustness) if robustness is not None else None
    config = stage_config(cfg, SECTIONS, NOT_AFFECTING_RESULT)
    if robustness is not None:
        # What the depth figure reads besides the artifacts: the filter's parameters, and
        # whether the study's noisy generation artifact is there to draw from.
        filter_cfg = _filter_config(ROBUSTNESS_FIGURE_FILTER)
        config["robustness_figure"] = {
            "generate": robust_gen.name if robust_gen is not None else None,
            "depth_filter": OmegaConf.to_container(filter_cfg, resolve=True)}
    upstream = {"generate": gen_version}
    if labels is not None:
        upstream["label"] = labels.version
    if trained is not None:
        upstream["train"] = trained.version
    if baseline is not None:
        upstream["baseline"] = baseline.version
    if evaluated is not None:
        upstream["evaluate"] = evaluated.version
    if robustness is not None:
        upstream["robustness"] = robustness.version
    if ablated is not None:
        upstream["ablation"] = ablated[0].name
    if unseen is not None:
        upstream["unseen"] = unseen[0].name
    version = compute_version(STAGE, config, upstream)
    gen_cfg = gen_manifest.get("config", {})

    def body(run: StageRun) -> None:
        stats = dataset_stats(gen_dir)
        _check_consistent(splits, stats, gen_dir)
        dt = float(gen_cfg.get("physics", {}).get("time_step", 1 / 240))
        max_count = int(gen_cfg.get("boxes", {}).get(
            "max_count", max(len(m.get("boxes_per_scene_histogram", [0])) for m in splits.values()) - 1))
        tables = {t.name: t for t in (splits_table(splits, stats, dt), box_types_table(stats))}
        if labels is not None:
            check_labels(labels, stats)
            for t in (label_classes_table(labels), label_ng_reasons_table(labels),
                      surface_accuracy_table(labels)):
                tables[t.name] = t
        if trained is not None:
            for t in (table1_table(trained), threshold_table(trained)):
                if t is not None:
                    tables[t.name] = t
        if baseline is not None:
            for t in (table2_table(baseline), planning_time_table(baseline)):
                tables[t.name] = t
        if evaluated is not None:
            for t in (table3_table(evaluated), failures_table(evaluated),
                      table3_timing_table(evaluated), path_deviation_table(evaluated)):
                tables[t.name] = t
        if ablated is not None:
            tables["ablation"] = ablation_table(ablated[1])
        if unseen is not None:
            for t in (unseen_table1(unseen[1]), unseen_table2(unseen[1])):
                tables[t.name] = t
        if robustness is not None:
            for t in (robustness_sensor_table(robustness), robustness_table1_table(robustness),
                      robustness_table2_table(robustness),
                      robustness_closed_loop_table(robustness),
                      robustness_policies_table(robustness),
                      robustness_failures_table(robustness)):
                tables[t.name] = t
        for t in tables.values():
            path = run.work_dir / "tables" / f"{t.name}.csv"
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(t.csv_text())

        figures: dict[str, str] = {}
        if num_samples > 0:
            split, drawn = figure_sample_depth(gen_dir, num_samples,
                                               run.work_dir / "figures" / "sample_depth.png")
            figures["figures/sample_depth.png"] = (
                f"{drawn} depth images of the {split} split (colour: depth in metres; grey: no "
                "data; white: box outlines) with their instance masks." if drawn
                else "No scenes to draw.")
        figure_boxes_per_scene(splits, max_count, run.work_dir / "figures" / "boxes_per_scene.png")
        figures["figures/boxes_per_scene.png"] = (
            "Boxes at rest per scene, all splits stacked (from the generation manifest).")
        if labels is not None and num_samples > 0:
            split, drawn = figure_labels_sample(gen_dir, labels.folder, num_samples,
                                                run.work_dir / "figures" / "labels_sample.png")
            figures["figures/labels_sample.png"] = (
                f"Grasp points of {drawn} depth images of the {split} split, coloured by their "
                "class after the robot-level check (R red, L green, B blue, NG grey; paper "
                "Fig. 4f)." if drawn else "No labelled scenes to draw.")
        if trained is not None:
            figure_pr_curve(trained.metrics["pr_curve"], run.work_dir / "figures" / "pr_curve.png")
            figures["figures/pr_curve.png"] = (
                "Precision–recall curve of the DCNN on the test split: all predictions pooled "
                "and ranked by confidence (from the train manifest; Table 1's definition).")

        if baseline is not None:
            chosen = read_npz(baseline.folder / "chosen.npz")
            planners = [r["planner"] for r in baseline.metrics["table2"]["rows"]]
            curve = np.loadtxt(baseline.folder / "table2_curve.csv", delimiter=",", skiprows=1,
                               ndmin=2)
            figure_table2_curve(curve[:, 0], {p: curve[:, 1 + k] for k, p in enumerate(planners)},
                                run.work_dir / "figures" / "table2_curve.png",
                                baseline.metrics["table2"]["paper"]["within_30px"],
                                float(baseline.metrics["table2"]["paper"]["radius_px"]))
            figures["figures/table2_curve.png"] = (
                "Share of test images whose optimal grasp point lies within r pixels of a true "
                "surface centre, per planner (Table 2 at r = 30 px; stars: the paper's values).")
            if num_samples > 0:
                drawn = figure_planner_points(gen_dir, chosen, planners, num_samples,
                                              run.work_dir / "figures" / "fig10_planners.png")
                figures["figures/fig10_planners.png"] = (
                    f"{drawn} test depth images with each planner's optimal grasp point and the "
                    "true surface centres (white +), like the paper's Fig. 10.")

        if evaluated is not None:
            conv = evaluated.folder / "servo_convergence.csv"
            figure_servo_convergence(conv, run.work_dir / "figures" / "servo_convergence.png")
            figures["figures/servo_convergence.png"] = (
                "Visual-servoing error over simulated time for the attempts of the logged "
                "trials: translation error |p_e − p_e*| (normalised) and rotation error |uθ|.")

        robustness_note = None
        if robustness is not None:
            gen_noisy = robustness.data["artifacts"].get("generate_noisy")
            sensor = robustness.data["sensor"].get("name", "sensor")
            drawn = None
            if robust_gen is not None:
                drawn = figure_sensor_depth(robust_gen, filter_cfg, ROBUSTNESS_FIGURE_FILTER,
                                            str(sensor), run.work_dir / ROBUSTNESS_FIGURE)
            if drawn is not None:
                figures[ROBUSTNESS_FIGURE] = (
                    f"Test image #{drawn} of generation artifact `{gen_noisy}` (the robustness "
                    f"study's noisy generation): the ideal depth, the `{sensor}` model's depth "
                    f"and that depth after `depth_filter={ROBUSTNESS_FIGURE_FILTER}` (magenta: "
                    "no data; one colour scale).")
            else:
                (run.work_dir / ROBUSTNESS_FIGURE).unlink(missing_ok=True)
                robustness_note = (
                    f"No depth figure: the study's noisy generation artifact `{gen_noisy}` "
                    + ("has no test images." if robust_gen is not None else
                       "is not under `data/generate/` (rerun `make robustness`, which "
                       "recreates it, then the report)."))

        used = {"generate": (gen_version, gen_manifest)}
        if labels is not None:
            used["label"] = (labels.version, labels.manifest)
        if trained is not None:
            used["train"] = (trained.version, trained.manifest)
        if baseline is not None:
            used["baseline"] = (baseline.version, baseline.manifest)
        if evaluated is not None:
            used["evaluate"] = (evaluated.version, evaluated.manifest)
        if robustness is not None:
            used["robustness"] = (robustness.version, robustness.manifest)
        if ablated is not None:
            used["ablation"] = (ablated[0].name, load_manifest(ablated[0]))
        if unseen is not None:
            used["unseen"] = (unseen[0].name, load_manifest(unseen[0]))
        readme = render_readme(run.version, used, tables, figures, gen_cfg, stats, labels,
                               trained, baseline, evaluated, robustness, robustness_note,
                               ablated, unseen)
        (run.work_dir / "README.md").write_text(readme)

        with StageLog(run.work_dir, app_id=f"binpick-{STAGE}", recording_id=run.version) as log:
            step = 0
            for t in tables.values():
                if f"tables/{t.name}.csv" in VOLATILE_FILES:
                    continue  # wall-clock figures: they would make the logs differ between runs
                log.set_time(sequences={"step": step}, clock_ns=step)
                log.log_text(f"report/tables/{t.name}", f"tables/{t.name}.csv\n{t.csv_text()}")
                step += 1
            log.set_time(sequences={"step": step}, clock_ns=step)
            log.log_text("report/figures", "figures: " + ", ".join(figures))
            step += 1
            log.set_time(sequences={"step": step}, clock_ns=step)
            log.log_text("report/readme", readme)

        run.metrics.update({
            "generate_version": gen_version,
            "label_version": labels.version if labels is not None else None,
            "train_version": trained.version if trained is not None else None,
            "baseline_version": baseline.version if baseline is not None else None,
            "evaluate_version": evaluated.version if evaluated is not None else None,
            "robustness_version": robustness.version if robustness is not None else None,
            "unseen_version": unseen[0].name if unseen is not None else None,
            "volatile_files": sorted(f for f in VOLATILE_FILES if (run.work_dir / f).is_file()),
            "scenes": dict(stats.scenes),
            "boxes": dict(stats.boxes),
            "grasp_points": ({s: int(labels.splits[s]["grasp_points"]) for s in SPLITS}
                             if labels is not None else None),
            "tables": sorted(f"tables/{name}.csv" for name in tables),
            "figures": sorted(figures),
        })

    out = run_stage(root, STAGE, version, config, upstream, body, force=bool(cfg.report.force))
    published = publish(out, Path(cfg.paths.reports))
    print(f"[{STAGE}] published {len(published)} files to {cfg.paths.reports}")
    return out


@hydra.main(config_path=CONF_DIR, config_name="report", version_base="1.3")
def main(cfg: DictConfig) -> None:
    stage_main(report)(cfg)


if __name__ == "__main__":
    main()
