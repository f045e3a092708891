"""Table 2 (paper Sec. 8.1.1, Fig. 10): the DCNN and the Dex-Net-style planners on the same
test images, each optimal grasp point's distance to the nearest true surface centre.

The baseline stage computes the published Table 2 with it; the unseen-size and robustness
studies run it on their own heaps and depth. The distance measure itself is
``pipeline.planner.centre_distance``; the Dex-Net-style planner is ``pipeline.dexnet.planner``.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from pipeline.dataset.scenes import SceneDataset
from pipeline.dexnet.planner import DexNetPlanner
from pipeline.labelling.surface_truth import true_visible_faces
from pipeline.planner.centre_distance import nearest_centre_distance, within_curve, within_rate

OURS = "dcnn"  # the DCNN planner (a training artifact)
OOD = "gqcnn_ood"  # the GQ-CNN trained on heaps of other objects (``objects``, ``baseline.ood``)
PLANNER_NAMES = {
    OURS: "Ours (DCNN, two cups)",
    "gqcnn": "Dex-Net-style GQ-CNN + CEM, trained on the box heaps",
    OOD: "Dex-Net-style GQ-CNN + CEM, trained on non-box objects",
    "planarity": "Dex-Net-style planarity + CEM",
}
EVAL_SEED = 11  # the CEM's generator for test image i: (seed, EVAL_SEED, i)


def make_planners(cfg, gen: SceneDataset, model_dir: Path, train_dir: Path | None) -> dict:
    """name → plan(depth_m, intrinsics, index) → list of candidates (G_opt first)."""
    planners: dict = {}
    if train_dir is not None:
        from pipeline.planner.planner import Planner

        dcnn = Planner.load(train_dir, device="cpu")
        planners[OURS] = lambda depth, intr, i: dcnn.plan(depth, intr)
    for variant in cfg.baseline.variants:
        dex = DexNetPlanner.for_variant(cfg, variant, gen.T_world_cam, model_dir)

        def plan(depth, intr, i, dex=dex):
            return dex.plan(depth, intr, rng=np.random.default_rng([int(cfg.seed), EVAL_SEED, i]))

        planners[variant] = plan
    return planners


def evaluate_table2(
    cfg,
    gen_dir: Path,
    model_dir: Path,
    train_dir: Path | None,
    progress: bool,
    planners: dict | None = None,
    depth_of=None,
) -> dict:
    """Every planner on the same test images: chosen points, distances, planning times.

    ``planners``: name → plan(depth_m, intrinsics, index) (default ``make_planners``);
    ``depth_of(scene)``: the (H, W) depth the planners see (default ``scene.depth_m``, what the
    sensor returned). The true face centres always come from the ideal depth.
    """
    from tqdm import tqdm

    gen = SceneDataset(gen_dir, "test")
    n = (
        len(gen)
        if int(cfg.baseline.max_eval_images) <= 0
        else min(len(gen), int(cfg.baseline.max_eval_images))
    )
    if planners is None:
        planners = make_planners(cfg, gen, model_dir, train_dir)
    if depth_of is None:

        def depth_of(scene):
            return scene.depth_m

    min_px = int(cfg.surfaces.truth_min_visible_px)
    out = {
        "scene_index": np.arange(n, dtype=np.int64),
        "num_centres": np.zeros(n, np.int64),
        "centres": [],
    }
    times = {name: [] for name in planners}
    for name in planners:
        out[f"{name}_uv"] = np.full((n, 2), np.nan)
        out[f"{name}_score"] = np.full(n, np.nan)
        out[f"{name}_dist"] = np.full(n, np.nan)
    for i in tqdm(range(n), desc="table 2", unit="image", disable=not progress):
        scene = gen[i]
        faces = true_visible_faces(
            scene.depth_clean_m, scene.mask, scene.intrinsics, scene.boxes, min_visible_px=min_px
        )
        depth = depth_of(scene)
        centres = np.array([f.center_px for f in faces], np.float64).reshape(-1, 2)
        out["num_centres"][i] = len(centres)
        out["centres"].append(centres)
        for name, plan in planners.items():
            t0 = time.perf_counter()
            cands = plan(depth, scene.intrinsics, i)
            times[name].append(time.perf_counter() - t0)
            uv = np.array([cands[0].u, cands[0].v]) if cands else None
            if uv is not None:
                out[f"{name}_uv"][i] = uv
                out[f"{name}_score"][i] = cands[0].score
            out[f"{name}_dist"][i] = nearest_centre_distance(uv, centres)
    out["times"] = times
    out["planners"] = list(planners)
    return out


def table2_rows(result: dict, radius_px: float, radii: np.ndarray) -> tuple[list, list]:
    rows, curve = [], []
    for name in result["planners"]:
        d = result[f"{name}_dist"]
        scored = ~np.isnan(d)
        finite = d[np.isfinite(d)]
        rows.append(
            {
                "planner": name,
                "name": PLANNER_NAMES.get(name, name),
                "images": int(scored.sum()),
                "no_grasp": int(np.sum(np.isinf(d))),
                f"within_{radius_px:g}px": round(within_rate(d, radius_px), 6),
                f"within_{radius_px:g}px_inclusive": round(
                    within_rate(d, radius_px, inclusive=True), 6
                ),
                "median_distance_px": round(float(np.median(finite)), 3)
                if len(finite)
                else float("nan"),
            }
        )
    for r in radii:
        curve.append(
            [int(r)]
            + [
                round(float(within_curve(result[f"{name}_dist"], np.array([r]))[0]), 6)
                for name in result["planners"]
            ]
        )
    return rows, curve
