"""Dataset section: the generated heaps (paper Sec. 4.3), from the generation artifact
(``data/generate/<version>``, ``report.generate_version``; the one section that is not optional).

Tables ``dataset_splits`` (per split: scenes, boxes, removed boxes, settle steps, from the
manifest's metrics) and ``box_types`` (per box type: boxes and mean visible area in the instance
mask, counted from the scenes); figures ``sample_depth.png`` and ``boxes_per_scene.png``.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.artifacts import ArtifactError, load_manifest, resolve_artifact
from pipeline.dataset.scenes import SPLITS, SceneDataset
from pipeline.report.figures import figure_boxes_per_scene, figure_sample_depth
from pipeline.report.section import Context, Section
from pipeline.report.tables import Table
from pipeline.report.upstream import ArtifactInfo


@dataclass
class DatasetStats:
    """What the report reads from the scenes themselves (via ``SceneDataset``)."""

    scenes: dict[str, int]
    boxes: dict[str, int]
    not_settled: dict[str, int]
    settle_steps: dict[str, np.ndarray]  # per split, one value per scene
    type_names: list[str]
    type_sizes: list[list[float] | None]  # metres; None: drawn per box (boxes.cartons)
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
            px = np.bincount(scene.mask.ravel(), minlength=n + 1)[1 : n + 1]
            kinds = np.array([b.type_index for b in scene.boxes], dtype=np.int64)
            np.add.at(type_boxes, kinds, 1)
            np.add.at(type_px, kinds, px)
        steps[split] = np.asarray(split_steps, dtype=np.int64)
    return DatasetStats(
        scenes,
        boxes,
        not_settled,
        steps,
        [t["name"] for t in types],
        [list(t["size"]) if t.get("size") is not None else None for t in types],
        type_boxes,
        type_px,
        image_size,
    )


def split_metrics(gen_manifest: dict, gen_dir: Path) -> dict[str, dict]:
    """The generation manifest's ``metrics.splits.<split>``; an older manifest is an error."""
    try:
        splits = gen_manifest["metrics"]["splits"]
        return {s: splits[s] for s in SPLITS}
    except (KeyError, TypeError):
        raise ArtifactError(
            f"{gen_dir}/manifest.json has no metrics.splits.<{'|'.join(SPLITS)}>: the generation "
            "artifact predates the report stage; recompute it with `make generate` "
            "(generate.force=true)."
        ) from None


def check_consistent(splits: dict[str, dict], stats: DatasetStats, gen_dir: Path) -> None:
    """The manifest's metrics must describe the scenes actually stored."""
    problems = []
    for s in SPLITS:
        m = splits[s]
        if m.get("scenes", 0) != stats.scenes[s]:
            problems.append(
                f"{s}: manifest says {m.get('scenes')} scenes, files hold {stats.scenes[s]}"
            )
        if stats.scenes[s] and m.get("boxes") != stats.boxes[s]:
            problems.append(
                f"{s}: manifest says {m.get('boxes')} boxes, files hold {stats.boxes[s]}"
            )
    if problems:
        raise ArtifactError(
            f"generation artifact {gen_dir} is inconsistent ("
            + "; ".join(problems)
            + "); run `make verify`, then recompute it."
        )


@dataclass
class DatasetInfo(ArtifactInfo):
    """The generation artifact: folder, manifest and its per-split metrics."""

    splits: dict[str, dict]  # manifest metrics.splits.<split>

    @property
    def config(self) -> dict:
        """The generation config (``physics``, ``boxes``, ...), from the manifest."""
        return self.manifest.get("config", {})

    @cached_property
    def stats(self) -> DatasetStats:
        """The counts over every scene (read once, when first asked for, inside the report's
        build); raises ``ArtifactError`` when they disagree with the manifest's metrics."""
        stats = dataset_stats(self.folder)
        check_consistent(self.splits, stats, self.folder)
        return stats


def step_unit(time_step: float) -> str:
    """``"1/240 s"`` for a time step of 1/240 s, else e.g. ``"0.005 s"``."""
    inv = 1.0 / time_step
    return f"1/{round(inv)} s" if abs(inv - round(inv)) < 1e-6 else f"{time_step:g} s"


def splits_table(splits: dict[str, dict], stats: DatasetStats, time_step: float) -> Table:
    unit = step_unit(time_step)
    headers = [
        "split",
        "scenes",
        "boxes",
        "mean boxes per scene",
        "boxes removed (left the bin)",
        "scenes at the step cap",
        f"median settle steps ({unit})",
        f"p90 settle steps ({unit})",
    ]
    rows = []
    for s in SPLITS:
        m = splits[s]
        if not m.get("scenes"):
            rows.append([s, 0, 0, None, None, None, None, None])
            continue
        rows.append(
            [
                s,
                m["scenes"],
                m["boxes"],
                m["boxes_per_scene_mean"],
                m["boxes_removed_outside_bin"],
                m["scenes_not_settled"],
                m["settle_steps_median"],
                m["settle_steps_p90"],
            ]
        )
    n = sum(stats.scenes.values())
    nb = sum(stats.boxes.values())
    all_steps = np.concatenate([stats.settle_steps[s] for s in SPLITS])
    if n:
        removed = sum(splits[s].get("boxes_removed_outside_bin", 0) for s in SPLITS)
        rows.append(
            [
                "all",
                n,
                nb,
                round(nb / n, 3),
                removed,
                sum(stats.not_settled.values()),
                float(np.median(all_steps)),
                float(np.percentile(all_steps, 90)),
            ]
        )
    else:
        rows.append(["all", 0, 0, None, None, None, None, None])
    return Table(
        "dataset_splits", headers, rows, ["", "", "", "{:.2f}", "", "", "{:.0f}", "{:.0f}"]
    )


def box_types_table(stats: DatasetStats) -> Table:
    W, H = stats.image_size
    headers = [
        "box type",
        "edge lengths (mm)",
        "boxes",
        "share of boxes (%)",
        f"mean visible area (px of {W}x{H})",
    ]
    total = int(stats.type_boxes.sum())
    rows = []
    for k, name in enumerate(stats.type_names):
        n = int(stats.type_boxes[k])
        dims = (
            "drawn per box (boxes.cartons)"
            if stats.type_sizes[k] is None
            else " x ".join(f"{1000 * v:g}" for v in stats.type_sizes[k])
        )
        rows.append(
            [
                name,
                dims,
                n,
                round(100.0 * n / total, 1) if total else None,
                round(float(stats.type_visible_px[k]) / n, 1) if n else None,
            ]
        )
    return Table("box_types", headers, rows, ["", "", "", "{:.1f}", "{:.1f}"])


def time_step(gen_cfg: dict) -> float:
    """The physics time step of the generation (s)."""
    return float(gen_cfg.get("physics", {}).get("time_step", 1 / 240))


def render_dataset(info: DatasetInfo, tables: dict[str, Table]) -> list[str]:
    """README lines of the dataset section."""
    phys = info.config.get("physics", {})
    dt = time_step(info.config)
    cap = phys.get("max_settle_steps")
    W, H = info.stats.image_size
    gen = info.config.get("generate", {})
    jitter = float(gen.get("size_jitter", 0.0))
    cartons = (info.config.get("boxes") or {}).get("cartons")
    carton_note = (
        f" The {' and '.join(gen.get('carton_splits', []))} heaps' boxes are cartons drawn per "
        "box from the carton distribution (`boxes.cartons`, docs/generation.md), type "
        "*carton*; the size jitter applies to the other splits' types."
        if cartons
        else ""
    )
    jitter_note = (
        f"Edge lengths are the types' nominal sizes. Not the paper's: in the "
        f"{' and '.join(gen.get('size_jitter_splits', []))} heaps each box's three edges are "
        f"scaled by factors drawn from U({1 - jitter:g}, {1 + jitter:g}) "
        f"(`generate.size_jitter`, docs/generation.md); the other "
        f"splits hold the exact sizes."
        if jitter > 0
        else "Every box has its type's exact size (`generate.size_jitter` = 0, the paper's three "
        "sizes)."
    ) + carton_note
    return [
        "## Dataset",
        "",
        "Generated heaps (paper Sec. 4.3), from the generation manifest's metrics.",
        "",
        tables["dataset_splits"].markdown(),
        f"*Boxes* are the boxes at rest in the bin (ground truth). *Boxes removed* came to rest "
        f"outside the bin and were deleted before rendering. *Scenes at the step cap* did not "
        f"come to rest within `physics.max_settle_steps` = {cap} steps "
        f"({cap * dt:.1f} s). Settle steps are physics steps of {step_unit(dt)} "
        "from the first drop until the heap is at rest."
        if cap is not None
        else "*Boxes* are the boxes at rest in the bin (ground truth).",
        "",
        "### Box types",
        "",
        f"All splits, counted from the scenes. The visible area is the number of pixels of the "
        f"box in the {W}x{H} instance mask (0 for a fully hidden box). {jitter_note}",
        "",
        tables["box_types"].markdown(),
        "CSV versions: [tables/dataset_splits.csv](tables/dataset_splits.csv), "
        "[tables/box_types.csv](tables/box_types.csv).",
        "",
    ]


class DatasetSection(Section):
    name = "generate"

    def resolve(self, ctx: Context) -> DatasetInfo:
        """The generation artifact (verified); raises ``ArtifactError`` when there is none. Also
        checks ``report.num_sample_images``."""
        folder = resolve_artifact(
            ctx.root,
            "generate",
            ctx.requested("generate"),
            verify=True,
            key="report.generate_version",
        )
        manifest = load_manifest(folder)
        info = DatasetInfo(folder, manifest, split_metrics(manifest, folder))
        if ctx.num_samples < 0:
            raise ValueError(f"report.num_sample_images must be >= 0, got {ctx.num_samples}")
        return info

    def tables(self, info: DatasetInfo, ctx: Context) -> list[Table]:
        return [
            splits_table(info.splits, info.stats, time_step(info.config)),
            box_types_table(info.stats),
        ]

    def figures(self, info: DatasetInfo, ctx: Context, folder: Path) -> dict[str, str]:
        figures = {}
        if ctx.num_samples > 0:
            split, drawn = figure_sample_depth(
                info.folder, ctx.num_samples, folder / "figures" / "sample_depth.png"
            )
            figures["figures/sample_depth.png"] = (
                f"{drawn} depth images of the {split} split (colour: depth in metres; grey: no "
                "data; white: box outlines) with their instance masks."
                if drawn
                else "No scenes to draw."
            )
        max_count = int(
            info.config.get("boxes", {}).get(
                "max_count",
                max(len(m.get("boxes_per_scene_histogram", [0])) for m in info.splits.values()) - 1,
            )
        )
        figure_boxes_per_scene(info.splits, max_count, folder / "figures" / "boxes_per_scene.png")
        figures["figures/boxes_per_scene.png"] = (
            "Boxes at rest per scene, all splits stacked (from the generation manifest)."
        )
        return figures

    def markdown(
        self, info: DatasetInfo, tables: dict[str, Table], figures: dict[str, str]
    ) -> list[str]:
        return render_dataset(info, tables)

    def metrics(self, info: DatasetInfo) -> dict[str, Any]:
        return {
            "generate_version": info.version,
            "scenes": dict(info.stats.scenes),
            "boxes": dict(info.stats.boxes),
        }
