"""The report stage: gather the latest artifacts into ``reports/`` (tables, figures, README).

``report(cfg)`` is a pure function of the config and its upstream artifacts. For now it reports
the generated dataset (the paper's Tables 1–3 follow once the training, baseline and evaluation
stages exist). It writes the versioned artifact ``data/report/<version>/``::

    manifest.json                 what produced it (see pipeline.artifacts)
    README.md                     the report (Markdown; links are relative to this folder)
    tables/dataset_splits.csv     per split: scenes, boxes, removed boxes, settle steps
    tables/box_types.csv          per box type: boxes, mean visible area in the mask
    figures/sample_depth.png      ``report.num_sample_images`` test depth images + instance masks
    figures/boxes_per_scene.png   histogram of boxes per scene, all splits
    log.rrd, log.mcap             Rerun and MCAP logs of the tables (one text entry each)

and then publishes README.md, figures/ and tables/ into ``paths.reports`` (``<root>/reports/``),
replacing those files one by one and leaving other files there alone.

Every file in the artifact is a function of the version key alone (no wall-clock times, no
absolute paths; PNGs are written without the "Software" metadata), so two runs into different
roots give byte-identical files (``log.rrd`` aside, see ``pipeline.tracking``).

Command line::

    python -m pipeline.report experiment=smoke
    python -m pipeline.report experiment=smoke report.generate_version=<version> report.force=true
"""

from __future__ import annotations

import csv
import io
import math
import os
import shutil
import uuid
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import hydra
import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.ticker import MaxNLocator  # noqa: E402
from omegaconf import DictConfig  # noqa: E402

from pipeline.artifacts import (  # noqa: E402
    ArtifactError,
    compute_version,
    load_manifest,
    resolve_artifact,
    run_stage,
    stage_config,
)
from pipeline.artifacts.store import StageRun  # noqa: E402
from pipeline.cli import CONF_DIR, data_root, stage_main  # noqa: E402
from pipeline.dataset.scenes import SPLITS, SceneDataset  # noqa: E402
from pipeline.tracking import StageLog  # noqa: E402

STAGE = "report"
SECTIONS = ("report",)
NOT_AFFECTING_RESULT = ("report.force", "report.generate_version")  # upstream version covers it

PUBLISHED = ("README.md", "figures", "tables")
FIG_DPI = 100
# PNG text chunks: matplotlib writes "Software: matplotlib version ..." unless told not to.
PNG_METADATA = {"Software": None}
NONE = "—"  # shown in Markdown where a value does not exist (e.g. an empty split)


# ---------------------------------------------------------------------- tables
@dataclass
class Table:
    """A table written both as Markdown (formatted) and as CSV (plain values)."""

    name: str  # CSV file stem
    headers: list[str]
    rows: list[list[Any]]  # None = no value (empty split, no boxes of a type)
    formats: list[str] = field(default_factory=list)  # per column, e.g. "{:.2f}"; "" = str()

    def _cell(self, value: Any, col: int, missing: str) -> str:
        if value is None:
            return missing
        fmt = self.formats[col] if col < len(self.formats) else ""
        return fmt.format(value) if fmt else str(value)

    def csv_text(self) -> str:
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        w.writerow(self.headers)
        for row in self.rows:
            w.writerow([self._cell(v, i, "") for i, v in enumerate(row)])
        return buf.getvalue()

    def markdown(self) -> str:
        lines = ["| " + " | ".join(self.headers) + " |",
                 "|" + "|".join("---" if i == 0 else "---:" for i in range(len(self.headers))) + "|"]
        for row in self.rows:
            lines.append("| " + " | ".join(self._cell(v, i, NONE) for i, v in enumerate(row)) + " |")
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


# ---------------------------------------------------------------------- figures
def _save(fig: Figure, path: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=FIG_DPI, format="png", metadata=PNG_METADATA)


def _outline(mask: np.ndarray) -> np.ndarray:
    """Box pixels next to a pixel of another mask value (a one-pixel outline inside each box)."""
    m = mask.astype(np.int32)
    edge = np.zeros(m.shape, dtype=bool)
    dx = m[:, 1:] != m[:, :-1]
    dy = m[1:, :] != m[:-1, :]
    edge[:, 1:] |= dx
    edge[:, :-1] |= dx
    edge[1:, :] |= dy
    edge[:-1, :] |= dy
    return edge & (m > 0)


def _mask_rgb(mask: np.ndarray) -> np.ndarray:
    """Instance mask as RGB: background black, instances from a fixed 20-colour palette."""
    from matplotlib import colormaps

    palette = colormaps["tab20"](np.arange(20))[:, :3]
    lut = np.zeros((256, 3))
    lut[1:] = palette[(np.arange(255)) % 20]
    return lut[mask]


def sample_split(gen_dir: Path) -> str | None:
    """The split the sample figure draws from: test, else train, else val (None = no scenes)."""
    for split in ("test", "train", "val"):
        if len(SceneDataset(gen_dir, split)):
            return split
    return None


def figure_sample_depth(gen_dir: Path, num: int, path: Path) -> tuple[str | None, int]:
    """Grid of (depth with mask outlines | instance mask) pairs; returns (split, images drawn)."""
    split = sample_split(gen_dir)
    ds = SceneDataset(gen_dir, split) if split else None
    n = min(num, len(ds)) if ds is not None else 0
    if n == 0:
        fig = Figure(figsize=(6.0, 2.0), dpi=FIG_DPI)
        fig.text(0.5, 0.5, "no scenes in the generation artifact", ha="center", va="center")
        _save(fig, path)
        return split, 0
    scenes = [ds[i] for i in range(n)]
    valid = np.concatenate([s.depth_m[s.depth_m > 0] for s in scenes])
    vmin, vmax = (float(valid.min()), float(valid.max())) if valid.size else (0.0, 1.0)
    if vmax <= vmin:
        vmax = vmin + 1e-3
    pairs_per_row = min(3, n)
    rows = math.ceil(n / pairs_per_row)
    fig = Figure(figsize=(4.4 * pairs_per_row + 1.2, 2.4 * rows + 0.5), dpi=FIG_DPI,
                 layout="constrained")
    axes = fig.subplots(rows, 2 * pairs_per_row, squeeze=False)
    cmap = matplotlib.colormaps["viridis"].with_extremes(bad="0.75")
    im = None
    for ax in axes.ravel():
        ax.set_axis_off()
    for i, scene in enumerate(scenes):
        r, c = divmod(i, pairs_per_row)
        ax_d, ax_m = axes[r, 2 * c], axes[r, 2 * c + 1]
        depth = np.where(scene.depth_m > 0, scene.depth_m, np.nan)
        im = ax_d.imshow(depth, cmap=cmap, vmin=vmin, vmax=vmax, interpolation="nearest")
        edge = _outline(scene.mask)
        overlay = np.zeros(edge.shape + (4,))
        overlay[edge] = (1.0, 1.0, 1.0, 0.9)
        ax_d.imshow(overlay, interpolation="nearest")
        ax_d.set_title(f"{split} #{scene.index}: {len(scene.boxes)} boxes", fontsize=8)
        ax_m.imshow(_mask_rgb(scene.mask), interpolation="nearest")
        ax_m.set_title("instance mask", fontsize=8)
    cb = fig.colorbar(im, ax=axes.ravel().tolist(), shrink=0.9)
    cb.set_label("depth (m)")
    fig.suptitle(f"Sample depth images ({split} split; grey = no data, white = box outlines)",
                 fontsize=9)
    _save(fig, path)
    return split, n


def figure_boxes_per_scene(splits: dict[str, dict], max_count: int, path: Path) -> None:
    """Stacked histogram of boxes per scene, from the manifest's per-split histograms."""
    fig = Figure(figsize=(6.4, 3.6), dpi=FIG_DPI, layout="constrained")
    ax = fig.subplots()
    x = np.arange(max_count + 1)
    bottom = np.zeros(max_count + 1)
    drawn = False
    for split, colour in zip(SPLITS, ("tab:blue", "tab:orange", "tab:green")):
        hist = splits[split].get("boxes_per_scene_histogram")
        if not hist:
            continue
        h = np.zeros(max_count + 1)
        h[:min(len(hist), max_count + 1)] = hist[:max_count + 1]
        ax.bar(x, h, bottom=bottom, color=colour, label=f"{split} ({splits[split]['scenes']})",
               width=0.85)
        bottom += h
        drawn = True
    ax.set_xlabel("boxes at rest in the bin per scene")
    ax.set_ylabel("scenes")
    ax.yaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_xticks(x[::2] if max_count > 10 else x)
    ax.set_xlim(-0.6, max_count + 0.6)
    if drawn:
        ax.legend(title="split (scenes)", fontsize=8)
    else:
        ax.text(0.5, 0.5, "no scenes", transform=ax.transAxes, ha="center")
    ax.set_title("Boxes per scene (all splits, stacked)", fontsize=10)
    _save(fig, path)


# ---------------------------------------------------------------------- README
def _commit(manifest: dict) -> str:
    code = manifest.get("code", {})
    commit = code.get("commit")
    if not commit:
        return "unknown"
    return f"`{commit[:10]}`" + (" (+ uncommitted changes)" if code.get("dirty") else "")


def render_readme(version: str, upstream: dict[str, tuple[str, dict]], tables: dict[str, Table],
                  figures: dict[str, str], gen_cfg: dict, stats: DatasetStats) -> str:
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
        "## Figures",
        "",
    ]
    for rel, caption in figures.items():
        out += [f"![{caption}]({rel})", "", f"*{caption}*", ""]
    out += [
        "## Paper tables",
        "",
        "Tables 1–3 of the paper (1: precision of the DCNN model's predictions; 2: percentage of "
        "grasp points within 30 pixels of a surface centre, ours vs. Dex-Net; 3: bin-picking "
        "success rate and speed) will appear here when the training, baseline and evaluation "
        "stages exist. No numbers are reported for them yet.",
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

    Raises ``ArtifactError`` (from ``resolve_artifact``) when there is no generation artifact.
    """
    root = data_root(cfg)
    gen_dir = resolve_artifact(root, "generate", cfg.report.generate_version)
    gen_version = gen_dir.name
    gen_manifest = load_manifest(gen_dir)
    splits = _split_metrics(gen_manifest, gen_dir)
    num_samples = int(cfg.report.num_sample_images)
    if num_samples < 0:
        raise ValueError(f"report.num_sample_images must be >= 0, got {num_samples}")
    config = stage_config(cfg, SECTIONS, NOT_AFFECTING_RESULT)
    upstream = {"generate": gen_version}
    version = compute_version(STAGE, config, upstream)
    gen_cfg = gen_manifest.get("config", {})

    def body(run: StageRun) -> None:
        stats = dataset_stats(gen_dir)
        _check_consistent(splits, stats, gen_dir)
        dt = float(gen_cfg.get("physics", {}).get("time_step", 1 / 240))
        max_count = int(gen_cfg.get("boxes", {}).get(
            "max_count", max(len(m.get("boxes_per_scene_histogram", [0])) for m in splits.values()) - 1))
        tables = {t.name: t for t in (splits_table(splits, stats, dt), box_types_table(stats))}
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

        readme = render_readme(run.version, {"generate": (gen_version, gen_manifest)}, tables,
                               figures, gen_cfg, stats)
        (run.work_dir / "README.md").write_text(readme)

        with StageLog(run.work_dir, app_id=f"binpick-{STAGE}", recording_id=run.version) as log:
            step = 0
            for t in tables.values():
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
            "scenes": dict(stats.scenes),
            "boxes": dict(stats.boxes),
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
