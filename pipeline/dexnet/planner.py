"""The Dex-Net-style suction planner: depth image → one suction grasp, by the cross-entropy method.

    planner = DexNetPlanner.from_config(cfg, "gqcnn", model_dir=Path("data/baseline/latest"))
    grasps = planner.plan(depth_m, intrinsics)      # [] or [SuctionGrasp]: G_opt = grasps[0]

The same call as the project's planner (``pipeline.planner.Planner.plan``): a depth image in
metres and the intrinsics in, ranked candidates out (here at most one: the CEM's argmax). A
``SuctionGrasp`` has ``u``, ``v``, ``score``, ``depth`` and ``normal_cam`` like the project's
``GraspCandidate``; its ``grasp_class`` is ``None``: Dex-Net plans for a single cup and has no
grasp patterns.

Steps (gqcnn's ``CrossEntropyRobustGraspingPolicy`` with a suction sampler):

1. **Segmask** (Dex-Net plans on a mask of the objects, from background subtraction): pixels
   with depth whose back-projected point lies inside the bin's inner walls and at least
   ``dexnet.object_margin`` above the bin floor. Needs the camera pose ``T_world_cam`` (the home
   pose) and the bin geometry.
2. **Point-cloud image and normals** (``pipeline.dexnet.sampling``).
3. **CEM** over suction candidates (``pipeline.dexnet.cem``) scored by one quality:
   ``gqcnn`` (the trained GQ-CNN, ``pipeline.dexnet.gqcnn``) or ``planarity`` (the analytic disc
   approach planarity, ``pipeline.dexnet.quality``; no training).

**Bad input** (as the project's planner): the depth image goes through
``pipeline.camera.depth_input.check_depth_image`` (shape from the intrinsics): a wrong shape,
ndim or dtype (e.g. a raw uint16 image) raises its ``DepthImageError`` (a ``ValueError``);
NaN, ±inf, ≤ 0 and implausible depths become 0 = no data, which is never sampled. ``plan``
returns ``[]`` (no grasp) when there is nothing to grasp, and ``planner.last_reason`` says why
(``NO_GRASP_REASONS``): ``"no_valid_depth"`` (no pixel has data), ``"no_object_pixels"`` (no
pixel with data inside the bin above ``object_margin``: an empty bin), ``"no_candidates"`` (object
pixels, but none acceptable: too few with a full Sobel window, all in the border or too steep).
``last_reason`` is ``""`` after a plan with a grasp. ``load_gqcnn`` raises
``pipeline.planner.planner.ModelFileError`` (a ``ValueError``) naming the file and the fix for
a file that is not a GQ-CNN of this version (truncated, garbage, other keys or shapes).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pipeline.camera.depth_input import check_depth_image
from pipeline.camera.geometry import Intrinsics, backproject_pixels, ground_distance
from pipeline.config.build import from_section
from pipeline.dexnet.cem import CEMConfig, CEMResult, cross_entropy_method
from pipeline.dexnet.gqcnn import (
    GQCNN,
    CropConfig,
    GQCNNConfig,
    candidate_inputs,
    crop_source,
    predict_quality,
)
from pipeline.dexnet.quality import PlanarityConfig, disc_planarity
from pipeline.dexnet.sampling import Candidates, PointCloudImage, SamplerConfig, point_cloud_image
from pipeline.planner.planner import (
    build_from_blob,
    config_from_blob,
    find_model_file,
    read_model_file,
)

VARIANTS = ("gqcnn", "planarity")
MODEL_FILE = "gqcnn.pt"
# The baseline stage's planners (``baseline.variants``, ``evaluate.dexnet_variant``): the quality
# each scores with and, for a trained one, its file in the baseline artifact. ``gqcnn``: trained
# on the box heaps; ``gqcnn_ood``: the same network trained on heaps of other objects.
OOD_MODEL_FILE = "gqcnn_ood.pt"
BASELINE_VARIANTS = {
    "gqcnn": ("gqcnn", MODEL_FILE),
    "gqcnn_ood": ("gqcnn", OOD_MODEL_FILE),
    "planarity": ("planarity", None),
}
MODEL_KEYS = ("network", "crop", "state_dict")
REBUILD_FIX = (
    "re-run the baseline stage with `make baseline` (`python -m pipeline.stages.baseline`), "
    "or pass a data/baseline/<version> folder made by this version of the pipeline"
)

# ``DexNetPlanner.last_reason`` after a plan without a grasp (see the module docstring).
NO_VALID_DEPTH = "no_valid_depth"
NO_OBJECT_PIXELS = "no_object_pixels"
NO_CANDIDATES = "no_candidates"
NO_GRASP_REASONS = (NO_VALID_DEPTH, NO_OBJECT_PIXELS, NO_CANDIDATES)


@dataclass
class SuctionGrasp:
    """One suction grasp. ``u``, ``v``: pixels; ``score``: the quality (GQ-CNN probability or
    planarity) in [0, 1]; ``depth``: metres; ``point_cam``: (3,) contact point, camera frame;
    ``normal_cam``: (3,) unit surface normal towards the camera; ``axis_cam`` = −normal: the
    approach axis; ``angle``: rad between the axis and the optical axis."""

    u: float
    v: float
    score: float
    depth: float
    point_cam: np.ndarray
    normal_cam: np.ndarray
    axis_cam: np.ndarray
    angle: float
    grasp_class: None = None


@dataclass(frozen=True)
class Workspace:
    """The bin interior, for the segmask: inner half-extents (m) and the camera pose."""

    half_x: float
    half_y: float
    object_margin: float
    T_world_cam: np.ndarray  # (4, 4) camera pose in the world frame at planning time

    def object_mask(self, depth_m: np.ndarray, intrinsics: Intrinsics) -> np.ndarray:
        """(H, W) bool: pixels with data inside the bin and above its floor (world z = 0)."""
        h, w = depth_m.shape
        u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
        z = depth_m.astype(np.float64)
        pts = backproject_pixels(np.stack([u, v], axis=-1), z, intrinsics)
        R, t = self.T_world_cam[:3, :3], self.T_world_cam[:3, 3]
        world = pts @ R.T + t
        return (
            (z > 0)
            & (np.abs(world[..., 0]) < self.half_x)
            & (np.abs(world[..., 1]) < self.half_y)
            & (world[..., 2] > self.object_margin)
        )


def sampler_config(cfg) -> SamplerConfig:
    """The candidate sampler of a composed config (``conf/dexnet/``)."""
    return from_section(SamplerConfig, cfg.dexnet)


def cem_config(cfg) -> CEMConfig:
    """The cross-entropy method of a composed config (``conf/dexnet/``)."""
    return from_section(CEMConfig, cfg.dexnet)


def crop_config(cfg) -> CropConfig:
    """The GQ-CNN's crop and pose input of a composed config (``dexnet.crop``), with D_ground
    (``pipeline.camera.geometry.ground_distance``)."""
    return from_section(CropConfig, cfg.dexnet.crop, d_ground=ground_distance(cfg.camera, cfg.bin))


def gqcnn_config(cfg) -> GQCNNConfig:
    """The GQ-CNN's architecture of a composed config (``conf/dexnet/``)."""
    return from_section(GQCNNConfig, cfg.dexnet, crop_size=int(cfg.dexnet.crop.size))


def planarity_config(cfg) -> PlanarityConfig:
    """The analytic disc-planarity quality of a composed config (``dexnet.planarity``), with
    the cup radius ``hand.cup_diameter`` / 2."""
    return from_section(
        PlanarityConfig, cfg.dexnet.planarity, cup_radius=float(cfg.hand.cup_diameter) / 2.0
    )


def workspace(cfg, T_world_cam: np.ndarray) -> Workspace:
    b = cfg.bin
    return Workspace(
        half_x=float(b.inner_length_x) / 2.0,
        half_y=float(b.inner_width_y) / 2.0,
        object_margin=float(cfg.dexnet.object_margin),
        T_world_cam=np.asarray(T_world_cam, np.float64),
    )


def load_gqcnn(model_dir: Path | str) -> tuple[GQCNN, CropConfig]:
    """The GQ-CNN and its crop config from a baseline artifact folder (or a ``gqcnn.pt``)."""
    path = find_model_file(model_dir, MODEL_FILE, "baseline", "data/baseline", "baseline")
    blob = read_model_file(
        path, MODEL_KEYS, "GQ-CNN (gqcnn.pt of `python -m pipeline.stages.baseline`)", REBUILD_FIX
    )
    net = build_from_blob(
        path, REBUILD_FIX, lambda: GQCNN(GQCNNConfig(**blob["network"])), blob["state_dict"]
    )
    crop = config_from_blob(path, REBUILD_FIX, "crop", lambda: CropConfig(**blob["crop"]))
    return net.eval(), crop


class DexNetPlanner:
    """Segmask → normals → CEM with one quality function → the best suction grasp."""

    def __init__(
        self,
        variant: str,
        workspace: Workspace,
        sampler: SamplerConfig,
        cem: CEMConfig,
        planarity: PlanarityConfig,
        crop: CropConfig | None = None,
        net: GQCNN | None = None,
        seed: int = 0,
    ) -> None:
        if variant not in VARIANTS:
            raise ValueError(f"unknown Dex-Net variant {variant!r}: choose one of {VARIANTS}")
        if variant == "gqcnn" and (net is None or crop is None):
            raise ValueError(
                "the gqcnn variant needs a trained GQ-CNN: pass model_dir=<baseline "
                "artifact> (made by `python -m pipeline.stages.baseline`)"
            )
        self.variant, self.workspace = variant, workspace
        self.sampler, self.cem, self.planarity = sampler, cem, planarity
        self.crop, self.net = crop, net
        self.seed = seed
        self._calls = 0
        self.last_reason = ""  # why the last plan/run_cem found no grasp (NO_GRASP_REASONS)

    @classmethod
    def from_config(
        cls, cfg, variant: str, T_world_cam: np.ndarray, model_dir: Path | str | None = None
    ) -> DexNetPlanner:
        net = crop = None
        if variant == "gqcnn":
            if model_dir is None:
                raise ValueError("the gqcnn variant needs model_dir=<baseline artifact folder>")
            net, crop = load_gqcnn(model_dir)
        return cls(
            variant,
            workspace(cfg, T_world_cam),
            sampler_config(cfg),
            cem_config(cfg),
            planarity_config(cfg),
            crop,
            net,
            seed=int(cfg.seed),
        )

    @classmethod
    def for_variant(
        cls, cfg, variant: str, T_world_cam: np.ndarray, baseline_dir: Path | str | None = None
    ) -> DexNetPlanner:
        """The planner of a ``BASELINE_VARIANTS`` name, its GQ-CNN (if any) read from the
        baseline artifact folder ``baseline_dir``."""
        if variant not in BASELINE_VARIANTS:
            raise ValueError(
                f"unknown Dex-Net-style planner {variant!r}: choose one of "
                f"{', '.join(BASELINE_VARIANTS)}"
            )
        quality, model_file = BASELINE_VARIANTS[variant]
        if model_file is None:
            return cls.from_config(cfg, quality, T_world_cam)
        if baseline_dir is None:
            raise ValueError(f"the {variant} planner needs baseline_dir=<baseline artifact folder>")
        return cls.from_config(cfg, quality, T_world_cam, Path(baseline_dir) / model_file)

    def score(
        self,
        depth_m: np.ndarray,
        cloud: PointCloudImage,
        cands: Candidates,
        source: np.ndarray | None = None,
    ) -> np.ndarray:
        """Quality of each candidate: (N,) in [0, 1]. ``source``: ``crop_source(depth_m)``, kept
        by the caller that scores several sets on one image (computed here otherwise)."""
        if len(cands) == 0:
            return np.zeros(0)
        if self.variant == "planarity":
            return disc_planarity(cloud, cands, self.planarity)
        crops, poses = candidate_inputs(depth_m, cands, self.crop, source)
        return predict_quality(self.net, crops, poses)

    def run_cem(
        self, depth_m: np.ndarray, intrinsics: Intrinsics, rng: np.random.Generator
    ) -> CEMResult:
        """The whole CEM run (every iteration's candidates and scores, for logging).

        Bad depth values are no data, a bad shape/dtype raises a ``ValueError`` (module
        docstring); without a candidate the result's ``best`` is empty and ``self.last_reason``
        says why."""
        return self._run_cem(self._check(depth_m, intrinsics), intrinsics, rng)

    def _check(self, depth_m: np.ndarray, intrinsics: Intrinsics) -> np.ndarray:
        return check_depth_image(depth_m, (intrinsics.height, intrinsics.width), name="depth_m")

    def _run_cem(
        self, depth_m: np.ndarray, intrinsics: Intrinsics, rng: np.random.Generator
    ) -> CEMResult:
        none = CEMResult(best=Candidates.empty(), best_score=-np.inf)
        self.last_reason = ""
        if not (depth_m > 0).any():
            self.last_reason = NO_VALID_DEPTH
            return none
        mask = self.workspace.object_mask(depth_m, intrinsics)
        if not mask.any():
            self.last_reason = NO_OBJECT_PIXELS
            return none
        cloud = point_cloud_image(depth_m, intrinsics, self.sampler, object_mask=mask)
        source = crop_source(depth_m) if self.variant == "gqcnn" else None  # once per image
        result = cross_entropy_method(
            cloud, lambda c: self.score(depth_m, cloud, c, source), self.cem, self.sampler, rng
        )
        if len(result.best) == 0:
            self.last_reason = NO_CANDIDATES
        return result

    def plan(
        self,
        depth_m: np.ndarray,
        intrinsics: Intrinsics,
        rng: np.random.Generator | None = None,
        max_grasps: int = 1,
    ) -> list[SuctionGrasp]:
        """One (H, W) depth image, metres → ``[best grasp, ...]``, or ``[]`` when no candidate
        exists (the reason in ``self.last_reason``). With ``max_grasps`` > 1, after the best come
        the other candidates of CEM's final set, best quality first, one per pixel: the
        alternatives the closed loop falls back on when the robot cannot take the best.

        ``rng`` defaults to a generator seeded by (seed, number of earlier calls), so a planner
        replays the same sequence of plans. A rejected image (``ValueError``) is not counted.
        """
        depth_m = self._check(depth_m, intrinsics)
        if rng is None:
            rng = np.random.default_rng([self.seed, self._calls])
        self._calls += 1
        result = self._run_cem(depth_m, intrinsics, rng)
        return grasps_of(result, max_grasps)


def _grasp(c: Candidates, i: int, score: float) -> SuctionGrasp:
    axis = c.axis[i]
    return SuctionGrasp(
        u=float(c.uv[i, 0]),
        v=float(c.uv[i, 1]),
        score=float(score),
        depth=float(c.depth[i]),
        point_cam=c.point[i].copy(),
        normal_cam=-axis,
        axis_cam=axis.copy(),
        angle=float(c.angle[i]),
    )


def grasps_of(result: CEMResult, max_grasps: int = 1) -> list[SuctionGrasp]:
    """The best grasp, then up to ``max_grasps`` − 1 others of the final scored set (finite
    scores, best first, ties in sampling order; one per pixel, the best's pixel excluded)."""
    if len(result.best) == 0:
        return []
    out = [_grasp(result.best, 0, result.best_score)]
    if max_grasps <= 1 or not result.iterations:
        return out
    final = result.iterations[-1]
    seen = {(int(result.best.uv[0, 0]), int(result.best.uv[0, 1]))}
    for i in np.argsort(-final.scores, kind="stable"):
        if len(out) >= max_grasps or not np.isfinite(final.scores[i]):
            break
        key = (int(final.candidates.uv[i, 0]), int(final.candidates.uv[i, 1]))
        if key not in seen:
            seen.add(key)
            out.append(_grasp(final.candidates, int(i), final.scores[i]))
    return out
