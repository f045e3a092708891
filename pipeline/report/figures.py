"""Figures of the report stage (``pipeline.report``), drawn with matplotlib's Agg backend.

Every figure is a function of its inputs alone: fixed size and dpi, no wall-clock text, and PNGs
written without the "Software" metadata, so the same artifacts give byte-identical files.
"""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import numpy as np
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator

from pipeline.dataset.labels import LabelSet
from pipeline.dataset.scenes import SPLITS, SceneDataset
from pipeline.grasping.types import CLASS_COLORS, GraspClass

FIG_DPI = 100
# PNG text chunks: matplotlib writes "Software: matplotlib version ..." unless told not to.
PNG_METADATA = {"Software": None}
NO_DATA = "#5c3a21"  # depth pixels without a value, in the labels figure (brown)
SENSOR_NO_DATA = "#e4007c"  # depth pixels without a value, in the sensor-depth figure (magenta)
CLASS_MEANING = {
    GraspClass.R: "right cup",
    GraspClass.L: "left cup",
    GraspClass.B: "both cups",
    GraspClass.NG: "not graspable",
}


def _save(fig: Figure, path: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=FIG_DPI, format="png", metadata=PNG_METADATA)


def outline(mask: np.ndarray) -> np.ndarray:
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


def _depth_range(scenes) -> tuple[float, float]:
    """(min, max) of the scenes' valid depths in metres, for one shared colour scale."""
    valid = np.concatenate([s.depth_m[s.depth_m > 0] for s in scenes])
    vmin, vmax = (float(valid.min()), float(valid.max())) if valid.size else (0.0, 1.0)
    return vmin, (vmax if vmax > vmin else vmin + 1e-3)


def _empty_figure(text: str, path: Path) -> None:
    """A small figure that says why there is nothing to draw."""
    fig = Figure(figsize=(6.0, 2.0), dpi=FIG_DPI)
    fig.text(0.5, 0.5, text, ha="center", va="center")
    _save(fig, path)


def _depth_grid(scenes) -> tuple[Figure, list]:
    """A figure of the scenes' depth images, three a row on one grey scale (light = near,
    ``NO_DATA`` where there is no depth), each axes' limits the image's pixels; returns the
    figure and one axes a scene, in order."""
    vmin, vmax = _depth_range(scenes)
    per_row = min(3, len(scenes))
    rows = math.ceil(len(scenes) / per_row)
    fig = Figure(figsize=(3.3 * per_row, 3.3 * rows + 0.9), dpi=FIG_DPI, layout="constrained")
    axes = fig.subplots(rows, per_row, squeeze=False).ravel()
    cmap = matplotlib.colormaps["gray_r"].with_extremes(bad=NO_DATA)  # near = light
    for ax in axes:
        ax.set_axis_off()
    for ax, scene in zip(axes, scenes):
        H, W = scene.depth_m.shape
        depth = np.where(scene.depth_m > 0, scene.depth_m, np.nan)
        ax.imshow(depth, cmap=cmap, vmin=vmin, vmax=vmax, interpolation="nearest")
        ax.set_xlim(-0.5, W - 0.5)
        ax.set_ylim(H - 0.5, -0.5)
    return fig, list(axes[: len(scenes)])


def _marker_handle(marker: str, colour, label: str, size: float):
    """A legend entry of one marker (black edge) and no line."""
    from matplotlib.lines import Line2D

    return Line2D(
        [],
        [],
        linestyle="",
        marker=marker,
        markersize=size,
        color=colour,
        label=label,
        markeredgecolor="black",
    )


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
        _empty_figure("no scenes in the generation artifact", path)
        return split, 0
    scenes = [ds[i] for i in range(n)]
    vmin, vmax = _depth_range(scenes)
    pairs_per_row = min(3, n)
    rows = math.ceil(n / pairs_per_row)
    fig = Figure(
        figsize=(4.4 * pairs_per_row + 1.2, 2.4 * rows + 0.5), dpi=FIG_DPI, layout="constrained"
    )
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
        edge = outline(scene.mask)
        overlay = np.zeros(edge.shape + (4,))
        overlay[edge] = (1.0, 1.0, 1.0, 0.9)
        ax_d.imshow(overlay, interpolation="nearest")
        ax_d.set_title(f"{split} #{scene.index}: {len(scene.boxes)} boxes", fontsize=8)
        ax_m.imshow(_mask_rgb(scene.mask), interpolation="nearest")
        ax_m.set_title("instance mask", fontsize=8)
    cb = fig.colorbar(im, ax=axes.ravel().tolist(), shrink=0.9)
    cb.set_label("depth (m)")
    fig.suptitle(
        f"Sample depth images ({split} split; grey = no data, white = box outlines)", fontsize=9
    )
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
        h[: min(len(hist), max_count + 1)] = hist[: max_count + 1]
        ax.bar(
            x,
            h,
            bottom=bottom,
            color=colour,
            label=f"{split} ({splits[split]['scenes']})",
            width=0.85,
        )
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


def figure_labels_sample(
    gen_dir: Path, label_dir: Path, num: int, path: Path
) -> tuple[str | None, int]:
    """Depth images with their grasp points coloured by final class (like the paper's Fig. 4f).

    Draws the first ``num`` scenes of the test split (else train, else val) with the labels of
    the label artifact ``label_dir``; returns (split, images drawn).
    """
    split = sample_split(gen_dir)
    n = min(num, len(SceneDataset(gen_dir, split))) if split else 0
    if n == 0:
        _empty_figure("no labelled scenes", path)
        return split, 0
    ds, ls = SceneDataset(gen_dir, split), LabelSet(label_dir, split)
    scenes = [ds[i] for i in range(n)]
    fig, axes = _depth_grid(scenes)
    colours = {c: tuple(v / 255 for v in CLASS_COLORS[c]) for c in GraspClass}
    totals = np.zeros(len(GraspClass), dtype=np.int64)
    for i, (ax, scene) in enumerate(zip(axes, scenes)):
        rows_i = ls[i]
        uv, cls = rows_i["uv"], rows_i["grasp_class"].astype(np.int64)
        totals += np.bincount(cls, minlength=len(GraspClass))
        for c in GraspClass:
            sel = cls == c
            if sel.any():
                ax.scatter(
                    uv[sel, 0],
                    uv[sel, 1],
                    s=26,
                    color=colours[c],
                    edgecolors="black",
                    linewidths=0.6,
                    zorder=3,
                )
        ax.set_title(f"{split} #{scene.index}: {len(cls)} grasp points", fontsize=8)
    handles = [
        _marker_handle("o", colours[c], f"{c.name}: {CLASS_MEANING[c]} ({totals[c]})", 7)
        for c in GraspClass
    ]
    fig.legend(
        handles=handles,
        loc="outside lower center",
        ncols=len(handles),
        fontsize=8,
        title="class after the robot-level check (grasp points drawn)",
        title_fontsize=8,
    )
    fig.suptitle(
        f"Grasp points on {split} depth images (light = near, dark = far, brown = no data)",
        fontsize=9,
    )
    _save(fig, path)
    return split, n


def figure_pr_curve(curve: dict, path: Path, paper: dict | None = None) -> None:
    """Precision–recall curve of the DCNN on the test split (the train manifest's
    ``metrics.pr_curve``: precision and recall along the pooled ranking by confidence)."""
    fig = Figure(figsize=(5.2, 4.0), dpi=FIG_DPI, layout="constrained")
    ax = fig.subplots()
    precision = np.asarray(curve.get("precision") or [], np.float64)
    recall = np.asarray(curve.get("recall") or [], np.float64)
    if len(precision):
        ax.plot(recall, precision, color="tab:blue", lw=1.5, label="this reproduction")
    else:
        ax.text(0.5, 0.5, "no predictions", transform=ax.transAxes, ha="center")
    ax.set_xlim(0.0, 1.0)
    ax.set_ylim(0.0, 1.02)
    ax.set_xlabel("recall")
    ax.set_ylabel("precision")
    ax.grid(True, alpha=0.3)
    if len(precision):
        ax.legend(fontsize=8, loc="upper right")
    ax.set_title("Precision–recall of the DCNN (test split)", fontsize=10)
    _save(fig, path)


PLANNER_STYLE = {  # Table 2 / Fig. 10 planners: (colour, marker, legend label)
    "dcnn": ("tab:blue", "o", "ours (DCNN)"),
    "gqcnn": ("tab:red", "X", "Dex-Net-style GQ-CNN + CEM (box heaps)"),
    "gqcnn_ood": ("tab:purple", "P", "Dex-Net-style GQ-CNN + CEM (non-box objects)"),
    "planarity": ("tab:orange", "s", "Dex-Net-style planarity + CEM"),
}


def figure_table2_curve(
    radii: np.ndarray,
    rates: dict[str, np.ndarray],
    path: Path,
    paper: dict[str, float],
    paper_radius: float,
) -> None:
    """Share of test images whose optimal grasp point lies within r px of a true surface centre,
    per planner, over r (the baseline's ``table2_curve.csv``), with the paper's 30-px values."""
    fig = Figure(figsize=(5.6, 4.0), dpi=FIG_DPI, layout="constrained")
    ax = fig.subplots()
    for name, rate in rates.items():
        colour, marker, label = PLANNER_STYLE.get(name, ("black", ".", name))
        ax.plot(radii, 100.0 * np.asarray(rate), color=colour, lw=1.5, label=label)
    paper_style = {
        "ours": ("tab:blue", "paper: ours"),
        "dexnet4": ("tab:red", "paper: Dex-Net 4.0"),
    }
    for key, value in paper.items():
        colour, label = paper_style.get(key, ("black", f"paper: {key}"))
        ax.scatter(
            [paper_radius],
            [100.0 * value],
            color=colour,
            marker="*",
            s=120,
            edgecolors="black",
            linewidths=0.6,
            zorder=4,
            label=label,
        )
    ax.axvline(paper_radius, color="grey", lw=0.8, ls="--")
    ax.set_xlim(
        float(radii.min()) if len(radii) else 0.0, float(radii.max()) if len(radii) else 1.0
    )
    ax.set_ylim(0.0, 101.0)
    ax.set_xlabel("radius r (pixels)")
    ax.set_ylabel("optimal points within r of a true surface centre (%)")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7, loc="lower right")
    ax.set_title("Table 2 over the radius (test split)", fontsize=10)
    _save(fig, path)


def figure_planner_points(
    gen_dir: Path, chosen: dict[str, np.ndarray], planners: list[str], num: int, path: Path
) -> int:
    """Fig. 10-like: test depth images with every planner's optimal grasp point and the true
    surface centres (white crosses). ``chosen``: the baseline's ``chosen.npz``. Returns the
    number of images drawn."""
    ds = SceneDataset(gen_dir, "test")
    n = min(num, len(chosen["scene_index"]), len(ds))
    if n == 0:
        _empty_figure("no test images", path)
        return 0
    scenes = [ds[int(chosen["scene_index"][i])] for i in range(n)]
    starts = np.concatenate([[0], np.cumsum(chosen["num_centres"])])
    fig, axes = _depth_grid(scenes)
    for i, (ax, scene) in enumerate(zip(axes, scenes)):
        centres = chosen["centres"][starts[i] : starts[i + 1]]
        ax.scatter(centres[:, 0], centres[:, 1], marker="+", s=30, color="white", lw=1.0, zorder=3)
        for name in planners:
            uv = chosen[f"{name}_uv"][i]
            if np.all(np.isfinite(uv)):
                colour, marker, _ = PLANNER_STYLE.get(name, ("black", ".", name))
                ax.scatter(
                    [uv[0]],
                    [uv[1]],
                    marker=marker,
                    s=70,
                    color=colour,
                    edgecolors="black",
                    linewidths=0.7,
                    zorder=4,
                )
        ax.set_title(f"test #{scene.index}", fontsize=8)
    handles = [_marker_handle("+", "black", "true surface centres", 8)]
    for p in planners:
        colour, marker, label = PLANNER_STYLE.get(p, ("black", ".", p))
        handles.append(_marker_handle(marker, colour, label, 8))
    fig.legend(handles=handles, loc="outside lower center", ncols=len(handles), fontsize=8)
    fig.suptitle("Optimal grasp points of each planner (paper Fig. 10; light = near)", fontsize=9)
    _save(fig, path)
    return n


def figure_servo_convergence(csv_path: Path, path: Path) -> None:
    """The servo error over simulated time, one line per attempt of the logged trials (the
    evaluation's ``servo_convergence.csv``)."""
    import csv

    with open(csv_path) as f:
        rows = list(csv.DictReader(f))
    fig = Figure(figsize=(9.0, 3.6), dpi=FIG_DPI, layout="constrained")
    ax_t, ax_r = fig.subplots(1, 2)
    groups: dict[tuple, list[dict]] = {}
    for r in rows:
        groups.setdefault((r["planner"], r["trial"], r["attempt"]), []).append(r)
    colours = {"dcnn": "tab:blue", "dexnet": "tab:red", "dexnet_ood": "tab:orange"}
    seen = set()
    for (planner, _, _), rs in groups.items():
        t = [float(r["t_s"]) for r in rs]
        label = None if planner in seen else planner
        seen.add(planner)
        ax_t.plot(
            t,
            [float(r["translation_error"]) for r in rs],
            color=colours.get(planner, "k"),
            lw=0.8,
            alpha=0.7,
            label=label,
        )
        ax_r.plot(
            t,
            [float(r["rotation_error_deg"]) for r in rs],
            color=colours.get(planner, "k"),
            lw=0.8,
            alpha=0.7,
        )
    for ax, name in ((ax_t, "|p_e − p_e*| (normalised)"), (ax_r, "|uθ| (degrees)")):
        ax.set_yscale("log")
        ax.set_xlabel("simulated time (s)")
        ax.set_ylabel(name)
        ax.grid(True, alpha=0.3)
    if not rows:
        ax_t.text(0.5, 0.5, "no logged attempts", transform=ax_t.transAxes, ha="center")
    elif seen:
        ax_t.legend(fontsize=8)
    fig.suptitle("2.5D visual-servoing convergence (logged trials)", fontsize=10)
    _save(fig, path)


def figure_sensor_depth(
    gen_dir: Path, filter_cfg, filter_name: str, sensor_name: str, path: Path
) -> int | None:
    """The first test image of a generation artifact made with a sensor model, in three panels:
    the ideal depth (``Scene.depth_clean_m``), the sensor's depth (``Scene.depth_m``) and that
    depth after the preprocessing ``filter_cfg`` (``pipeline.camera.depth_filter``; its name
    ``filter_name`` is shown). One colour scale (the ideal depth's range); pixels without data
    (0) in magenta. Returns the scene index drawn, None when the test split is empty."""
    from pipeline.camera.depth_filter import preprocess_depth

    ds = SceneDataset(gen_dir, "test")
    if len(ds) == 0:
        _empty_figure("no test images", path)
        return None
    scene = ds[0]
    panels = (
        ("ideal depth", scene.depth_clean_m),
        (f"{sensor_name} model", scene.depth_m),
        (f"{sensor_name} model + {filter_name}", preprocess_depth(scene.depth_m, filter_cfg)),
    )
    valid = scene.depth_clean_m[scene.depth_clean_m > 0]
    vmin, vmax = (float(valid.min()), float(valid.max())) if valid.size else (0.0, 1.0)
    vmax = vmax if vmax > vmin else vmin + 1e-3
    fig = Figure(figsize=(11.0, 3.6), dpi=FIG_DPI, layout="constrained")
    axes = fig.subplots(1, 3)
    cmap = matplotlib.colormaps["viridis"].with_extremes(bad=SENSOR_NO_DATA)
    im = None
    for ax, (title, depth) in zip(axes, panels):
        depth = np.asarray(depth, np.float32)
        missing = float(np.mean(depth <= 0))
        im = ax.imshow(
            np.where(depth > 0, depth, np.nan),
            cmap=cmap,
            vmin=vmin,
            vmax=vmax,
            interpolation="nearest",
        )
        ax.set_title(f"{title}: {100.0 * missing:.1f} % of pixels without data", fontsize=8)
        ax.set_axis_off()
    cb = fig.colorbar(im, ax=list(axes), shrink=0.9)
    cb.set_label("depth (m)")
    fig.suptitle(
        f"Ideal vs. sensor-model depth, test #{scene.index} (magenta = no data; one colour scale)",
        fontsize=9,
    )
    _save(fig, path)
    return scene.index
