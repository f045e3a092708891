"""Training section: the paper's Table 1 (precision of the DCNN's predictions, Sec. 7) and the
validation curve that calibrated the threshold th (Eq. 3), from the train artifact
(``models/train/<version>``, ``report.train_version``; optional). It must have been trained on
the label artifact the report reads.

Tables ``table1_precision`` (precision top 1 / top 1 % / 5 % / 10 %, the paper's and ours),
``threshold_calibration`` and ``training_curve`` (the losses per epoch); figure ``pr_curve.png``
(the DCNN's precision–recall curve on the
test split). Training timings are not copied.
"""

from __future__ import annotations

from pathlib import Path

from pipeline.artifacts import ArtifactError
from pipeline.planner.evaluate import PAPER_TABLE1
from pipeline.report.figures import figure_pr_curve
from pipeline.report.section import Context, Section
from pipeline.report.tables import Table
from pipeline.report.upstream import ArtifactInfo, Match, resolve_upstream

TABLE1_SECTION = "Table 1 — precision of the DCNN's predictions (paper Sec. 7)"
TRAIN_NOT_RUN = "Training: not run yet (`make train`)."
PR_FIGURE = "figures/pr_curve.png"
# (manifest key, column header) of Table 1; the paper's values are pipeline.planner.evaluate's.
TABLE1_COLUMNS = (
    ("top1", "Top 1"),
    ("top1pct", "Top 1 %"),
    ("top5pct", "Top 5 %"),
    ("top10pct", "Top 10 %"),
)


class TrainInfo(ArtifactInfo):
    """The train artifact: folder and manifest (``metrics.table1``, ``pr_curve``, ``network``,
    and ``threshold`` when th was calibrated)."""

    @classmethod
    def load(cls, folder: Path, manifest: dict) -> TrainInfo:
        """Raises ``ArtifactError`` when the manifest lacks Table 1."""
        try:
            metrics = manifest["metrics"]
            complete = (
                all(key in metrics["table1"] for key, _ in TABLE1_COLUMNS)
                and {"precision", "recall"} <= set(metrics["pr_curve"])
                and {"width", "parameters", "macs_per_image"} <= set(metrics["network"])
            )
        except (KeyError, TypeError):
            complete = False
        if not complete:
            raise ArtifactError(
                f"{folder.name}/manifest.json (train) lacks metrics.table1 / pr_curve / network: "
                "the train artifact predates the report's Table 1; recompute it with `make train` "
                "(train.force=true)."
            )
        return cls(folder, manifest)


def resolve_train(models: Path, version: str, label_version: str | None) -> TrainInfo | None:
    """The training artifact to report, or None when ``version`` is "latest" and none exists.

    Raises ``ArtifactError`` when a named version does not exist, when the artifact was trained
    on another label artifact than ``label_version``, or when its manifest lacks Table 1.
    """
    used = label_version if label_version is not None else "none (no label artifact)"
    return resolve_upstream(
        models,
        "train",
        version,
        TrainInfo.load,
        [
            Match(
                "label",
                label_version,
                lambda name, theirs: (
                    f"train artifact {name} was trained on label artifact {theirs}, but the "
                    f"report reads label artifact {used}: pass matching versions "
                    f"(report.label_version={theirs} report.train_version={name}), or rerun "
                    f"`make train` (train.label_version={label_version}) and then the report."
                ),
            )
        ],
    )


def table1_table(trained: TrainInfo) -> Table:
    """Table 1: the paper's precision and ours (percent; CSV with 4 decimals): the pooled and
    per-image figures at the calibrated th, and the old definitions in one labelled row."""
    ours = trained.metrics["table1"]

    def pct(v):
        return None if v is None else 100.0 * float(v)

    th = ours.get("threshold")
    at = f"th = {float(th):g}" if th is not None else "no threshold"
    headers = ["", *(h for _, h in TABLE1_COLUMNS)]
    rows = [
        ["paper", *(100.0 * PAPER_TABLE1[k] for k, _ in TABLE1_COLUMNS)],
        [f"this reproduction, pooled top k % ({at})", *(pct(ours[k]) for k, _ in TABLE1_COLUMNS)],
    ]
    if "per_image" in ours:
        rows.append(
            [
                f"this reproduction, per-image top k % ({at})",
                pct(ours["top1"]),
                *(pct(ours["per_image"].get(k)) for k, _ in TABLE1_COLUMNS[1:]),
            ]
        )
    if "legacy" in ours:
        rows.append(
            [
                "old definition (no threshold; top 1 over images with a prediction)",
                *(pct(ours["legacy"].get(k)) for k, _ in TABLE1_COLUMNS),
            ]
        )
    n = len(TABLE1_COLUMNS)
    return Table(
        "table1_precision",
        headers,
        rows,
        [""] + ["{:.2f} %"] * n,
        csv_formats=[""] + ["{:.4f}"] * n,
    )


def threshold_table(trained: TrainInfo) -> Table | None:
    """The validation curve that chose th (``pipeline.planner.calibration``), percent."""
    info = trained.metrics.get("threshold")
    if not info or not info.get("curve"):
        return None
    rows = [
        [
            r["threshold"],
            *(
                None if r[k] is None else 100.0 * r[k]
                for k in ("gopt_accuracy", "no_candidate", "precision", "recall", "f1")
            ),
        ]
        for r in info["curve"]
    ]
    return Table(
        "threshold_calibration",
        ["th", "G_opt correct", "no candidate", "precision", "recall", "F1"],
        rows,
        ["{:g}"] + ["{:.2f} %"] * 5,
        csv_formats=["{:g}"] + ["{:.4f}"] * 5,
    )


def training_curve_table(trained: TrainInfo) -> Table | None:
    """The loss per epoch (training and validation focal loss, Eqs. 4–6, per image), the epoch
    the model is marked; None for an artifact without per-epoch losses."""
    m = trained.metrics
    train, val = m.get("train_loss_per_epoch"), m.get("val_loss_per_epoch")
    if not train or val is None:
        return None
    best = m.get("best_epoch")
    rows = [
        [e, tl, vl, "model" if e == best else ""] for e, (tl, vl) in enumerate(zip(train, val), 1)
    ]
    headers, formats = ["epoch", "train loss", "val loss", ""], ["{}", "{:.4f}", "{:.4f}", ""]
    csv_formats = ["{}", "{:.6f}", "{:.6f}", ""]
    return Table("training_curve", headers, rows, formats, csv_formats=csv_formats)


def render_train(trained: TrainInfo, tables: dict[str, Table], figure: str | None) -> list[str]:
    """README lines of the Table 1 section (``figure``: the PR-curve figure, if drawn)."""
    out: list[str] = []
    m = trained.metrics
    t1 = m["table1"]
    net = m["network"]
    cfg = trained.manifest.get("config", {})
    radius = t1.get("radius_px", (cfg.get("train") or {}).get("match_radius_px"))
    images = m.get("images") or {}
    epochs = m.get("epochs", (cfg.get("train") or {}).get("epochs"))
    flip = (cfg.get("train") or {}).get("augment_flip", "none")
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
        how = (
            "calibrated on the validation split"
            if thr.get("rule") == "calibrated"
            else "fixed by `train.threshold`"
        )
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
        f"{images.get('train')} training images"
        + (f" (each mirrored at random: `train.augment_flip={flip}`)" if flip != "none" else "")
        + f" for {epochs} epoch"
        f"{'' if epochs == 1 else 's'}"
        + (
            f" of at most {m['max_epochs']} (validation-based stopping, patience "
            f"{(cfg.get('train') or {}).get('patience')}); the model is epoch {m['best_epoch']}, "
            "the one with the lowest validation loss."
            if "best_epoch" in m
            else "."
        ),
        "",
    ]
    if "training_curve" in tables:
        out += [
            "Loss per epoch (focal loss per image; the model is the epoch marked):",
            "",
            tables["training_curve"].markdown(),
        ]
    out += [
        "CSV versions: [tables/table1_precision.csv](tables/table1_precision.csv), "
        "[tables/threshold_calibration.csv](tables/threshold_calibration.csv)"
        + (
            ", [tables/training_curve.csv](tables/training_curve.csv)"
            if "training_curve" in tables
            else ""
        )
        + "."
        + (f" Precision–recall curve: [{figure}]({figure})." if figure else ""),
        "",
    ]
    return out


class TrainingSection(Section):
    name = "train"
    not_run = TRAIN_NOT_RUN
    paper_table = "Table 1 of the paper (precision of the DCNN model's predictions)"
    heading = TABLE1_SECTION

    def resolve(self, ctx: Context) -> TrainInfo | None:
        return resolve_train(ctx.models, ctx.requested("train"), ctx.version("label"))

    def tables(self, info: TrainInfo, ctx: Context) -> list[Table]:
        return [
            t
            for t in (table1_table(info), threshold_table(info), training_curve_table(info))
            if t is not None
        ]

    def figures(self, info: TrainInfo, ctx: Context, folder: Path) -> dict[str, str]:
        figure_pr_curve(info.metrics["pr_curve"], folder / PR_FIGURE)
        return {
            PR_FIGURE: (
                "Precision–recall curve of the DCNN on the test split: all predictions pooled "
                "and ranked by confidence (from the train manifest; Table 1's definition)."
            )
        }

    def body(self, info: TrainInfo, tables: dict[str, Table], figures: dict[str, str]) -> list[str]:
        return render_train(info, tables, PR_FIGURE if PR_FIGURE in figures else None)
