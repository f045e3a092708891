"""Labels section (paper Sec. 4.3, Figs. 4–6): the grasp points and their classes, from the label
artifact (``data/label/<version>``, ``report.label_version``; optional). It must have been made
from the generation artifact the report reads.

Tables ``label_classes`` (per split and level, hand / robot: grasp points per class),
``label_ng_reasons`` (per NG reason: grasp points per split) and ``surface_accuracy`` (per
split: detected surfaces against the simulator's true faces); figure ``labels_sample.png``. The
labelling throughput (scenes/s) is run-dependent, so it stays in the label manifest's ``timings``
and is not copied.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.artifacts import ArtifactError
from pipeline.dataset.labels import LabelSet
from pipeline.dataset.scenes import SPLITS
from pipeline.grasping.types import NG_REASONS, GraspClass
from pipeline.report.dataset import DatasetStats
from pipeline.report.figures import CLASS_MEANING, figure_labels_sample
from pipeline.report.section import Context, Section
from pipeline.report.tables import NONE, Table, pct
from pipeline.report.upstream import ArtifactInfo, Match, resolve_upstream

LABEL_SECTION = "Labels (paper Sec. 4.3, Figs. 4–6)"
LABEL_NOT_RUN = "Labelling: not run yet (`make label`)."
LABEL_FIGURE = "figures/labels_sample.png"
# Where each NG reason is decided (pipeline.stages.label): the hand level looks at the surface
# alone,
# the robot level at the whole robot in the scene.
NG_REASON_LEVEL = {
    "too_small": "hand",
    "center_occluded": "hand",
    "ik": "robot",
    "joint_limits": "robot",
    "collision": "robot",
    "path_collision": "robot",
    "path_joint_limits": "robot",
    "path_timeout": "robot",
    "path_lost": "robot",
    "hold": "hand",
    "press": "robot",
}
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
    "hold": "the cups fit, but would not hold the box's weight (hold test; hand.hold_check)",
    "press": "the pose is clear, but the final press along the camera's axis brings the hand "
    "or the arm onto the bin",
}
# (manifest key, column header, Markdown format) of the surface-accuracy table.
# The counts, precision and recall, then each error's median and 90th percentile.
ACCURACY_COLUMNS = (
    *((key, key, "") for key in ("images", "found", "missed", "spurious")),
    *((key, key, "{:.3f}") for key in ("precision", "recall")),
    *(
        (f"{key}_{stat}", f"{name} {stat} ({unit})", "{:.3f}")
        for key, name, unit in (
            ("center_err_px", "centre error", "px"),
            ("center_err_mm", "centre error", "mm"),
            ("normal_err_deg", "normal error", "deg"),
        )
        for stat in ("median", "p90")
    ),
)
SPLIT_KEYS = (
    "scenes",
    "grasp_points",
    "classes",
    "hand_level_classes",
    "ng_reasons",
    "surface_accuracy",
)


@dataclass
class LabelInfo(ArtifactInfo):
    """The label artifact the report reads: its folder, manifest and per-split metrics."""

    splits: dict[str, dict]  # manifest metrics.splits.<split>
    accuracy: dict  # manifest metrics.surface_accuracy (all splits)

    @classmethod
    def load(cls, folder: Path, manifest: dict) -> LabelInfo:
        """Raises ``ArtifactError`` when the manifest lacks the metrics the section reports."""
        try:
            metrics = manifest["metrics"]
            splits = {s: metrics["splits"][s] for s in SPLITS}
            accuracy = metrics["surface_accuracy"]
            complete = all(key in m for m in splits.values() for key in SPLIT_KEYS)
        except (KeyError, TypeError):
            complete = False
        if not complete:
            raise ArtifactError(
                f"{folder.name}/manifest.json (label) lacks metrics.splits.<split>.classes / "
                "hand_level_classes / ng_reasons / surface_accuracy or metrics.surface_accuracy: "
                "the label artifact predates the report's label section; recompute it with "
                "`make label` (label.force=true)."
            )
        return cls(folder, manifest, splits, accuracy)


def resolve_labels(root: Path, version: str, gen_version: str) -> LabelInfo | None:
    """The label artifact to report, or None when ``version`` is "latest" and none exists.

    Raises ``ArtifactError`` when a named version does not exist, when the artifact was made from
    another generation artifact than ``gen_version`` (or one with the same data), or when its
    manifest lacks the metrics.
    """
    return resolve_upstream(
        root,
        "label",
        version,
        LabelInfo.load,
        [
            Match(
                "generate",
                gen_version,
                lambda name, theirs: (
                    f"label artifact {name} was made from generation artifact {theirs}, but the "
                    f"report reads generation artifact {gen_version}: pass matching versions "
                    f"(report.generate_version={theirs} report.label_version={name}), or rerun "
                    f"`make label` (label.generate_version={gen_version}) and then the report."
                ),
                stage_dir=root / "generate",
            )
        ],
    )


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
                problems.append(
                    f"{s}: label files hold classes {counts.tolist()} (R, L, B, NG), "
                    f"the manifest says {expected}"
                )
    except (OSError, KeyError, ValueError) as e:
        problems.append(f"unreadable label files ({type(e).__name__}: {e})")
    if problems:
        raise ArtifactError(
            f"label artifact {labels.version} is inconsistent ("
            + "; ".join(problems)
            + "); run `make verify`, then recompute it."
        )


def label_classes_table(labels: LabelInfo) -> Table:
    """Per split (and all) and level: grasp points of each class, with percentages."""
    headers = ["split", "level", "scenes", "grasp points", "grasp points per scene"]
    for c in GraspClass:
        headers += [c.name, f"{c.name} (%)"]
    rows = []
    totals = {
        "hand_level_classes": np.zeros(len(GraspClass), np.int64),
        "classes": np.zeros(len(GraspClass), np.int64),
    }
    n_scenes = 0
    for split in [*SPLITS, "all"]:
        if split != "all":
            n_scenes += int(labels.splits[split]["scenes"])
        scenes = n_scenes if split == "all" else int(labels.splits[split]["scenes"])
        for key, level in (("hand_level_classes", "hand"), ("classes", "robot")):
            if split == "all":
                counts = totals[key]
            else:
                counts = np.array(
                    [int(labels.splits[split][key].get(c.name, 0)) for c in GraspClass], np.int64
                )
                totals[key] += counts
            total = int(counts.sum())
            row = [split, level, scenes, total, total / scenes if scenes else None]
            for c in GraspClass:
                row += [int(counts[c]), pct(int(counts[c]), total)]
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
    rows = [
        [r, NG_REASON_LEVEL.get(r, NONE), *per[r], sum(per[r]), pct(sum(per[r]), ng_total)]
        for r in names
    ]
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


def render_labels(labels: LabelInfo, tables: dict[str, Table], figure: str | None) -> list[str]:
    """README lines of the labels section (``figure``: the sample-labels figure, if drawn)."""
    out: list[str] = []
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
        + "; ".join(
            f"*{r}* ({NG_REASON_LEVEL[r]} level): {m}" for r, m in NG_REASON_MEANING.items()
        )
        + ".",
        "",
        tables["label_ng_reasons"].markdown(),
        "### Surface detection accuracy",
        "",
        "Detected surfaces against the true visible faces computed from the simulator's box "
        "poses"
        + (
            f" (faces with at least {surf['truth_min_visible_px']} visible pixels; a "
            f"match has the same box, centres within "
            f"{1000 * float(surf['match_max_center_dist']):g} mm and normals within "
            f"{float(surf['match_max_normal_deg']):g}°)"
            if {"truth_min_visible_px", "match_max_center_dist", "match_max_normal_deg"}
            <= set(surf)
            else ""
        )
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


class LabelsSection(Section):
    name, heading, not_run = "label", LABEL_SECTION, LABEL_NOT_RUN

    def resolve(self, ctx: Context) -> LabelInfo | None:
        return resolve_labels(ctx.root, ctx.requested("label"), ctx.version("generate"))

    def tables(self, info: LabelInfo, ctx: Context) -> list[Table]:
        check_labels(info, ctx.found["generate"].stats)
        return [
            label_classes_table(info),
            label_ng_reasons_table(info),
            surface_accuracy_table(info),
        ]

    def figures(self, info: LabelInfo, ctx: Context, folder: Path) -> dict[str, str]:
        if ctx.num_samples <= 0:
            return {}
        split, drawn = figure_labels_sample(
            ctx.found["generate"].folder, info.folder, ctx.num_samples, folder / LABEL_FIGURE
        )
        return {
            LABEL_FIGURE: (
                f"Grasp points of {drawn} depth images of the {split} split, coloured by their "
                "class after the robot-level check (R red, L green, B blue, NG grey; paper "
                "Fig. 4f)."
                if drawn
                else "No labelled scenes to draw."
            )
        }

    def body(self, info: LabelInfo, tables: dict[str, Table], figures: dict[str, str]) -> list[str]:
        return render_labels(info, tables, LABEL_FIGURE if LABEL_FIGURE in figures else None)

    def metrics(self, info: LabelInfo | None) -> dict[str, Any]:
        return {
            "label_version": info.version if info is not None else None,
            "grasp_points": (
                {s: int(info.splits[s]["grasp_points"]) for s in SPLITS}
                if info is not None
                else None
            ),
        }
