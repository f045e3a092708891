"""Grasp planners behind one interface: an observation in, ranked grasps out.

Every planner of the closed loop, built in or a user's plug-in, is an object with

    plan(observation: Observation, rng: numpy.random.Generator) -> Sequence[Grasp]

returning grasps best first (``[]``: no grasp). ``rng`` is the trial's planning stream (a
planner that draws samples, as Dex-Net's CEM does, takes them from it, so runs repeat); others
ignore it. The robot then executes the best-ranked grasp that passes its run-time check
(``pipeline.controller.picker``).

**Built in** (``evaluate.planners``): ``dcnn`` (the trained network, :class:`DCNNPlanner`),
``dexnet`` and ``dexnet_ood`` (the Dex-Net-style planners, :class:`DexNetStylePlanner`) and
``oracle`` (the labels on the home image; ground truth, so it lives with the world:
``pipeline.world.oracle``).

**Plug-ins.** Any other entry of ``evaluate.planners`` names a user's planner: either
``package.module:Class`` (importable from the working directory or the environment) or the name
of an entry point in the group ``binpick.planners`` (``[project.entry-points."binpick.planners"]``
of the user's ``pyproject.toml``, value ``package.module:Class``). The class is called with the
composed configuration (``Class(cfg)``) and its ``plan`` must follow the interface above; every
answer is checked (:func:`checked_grasps`). docs/planners.md has a complete example.
"""

from __future__ import annotations

import importlib
import inspect
import math
from collections.abc import Sequence
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from pipeline.controller.observation import Observation

PATTERNS = ("L", "R", "B")  # the two-cup hand's grasp patterns (paper Fig. 6)
ENTRY_POINT_GROUP = "binpick.planners"
BUILT_IN = ("dcnn", "dexnet", "dexnet_ood", "oracle")


@dataclass
class Grasp:
    """One grasp candidate in the observation's image: the project's candidate type.

    Attributes:
        u, v: the grasp point, pixels (u right, v down) of ``Observation.depth_m``.
        pattern: "L", "R" or "B" (which cups: the servo then centres them on the surface the
            descriptor finds at the point, paper Sec. 5), or None for a single suction point
            held fixed (Dex-Net's kind: the robot serves it with ``evaluate.dexnet_pattern``'s
            cup, then the other, and the servo keeps the cup on this very point).
        score: the planner's own score (for logs; the order of the list is the ranking).
        point_cam: (3,) the suction point in the camera frame, metres, for a fixed point
            (pattern None); None: the depth at (u, v) back-projected.
        second_tier: the DCNN's fallback tier (``evaluate.dcnn_fallback_ratio``), for the
            report.
    """

    u: float
    v: float
    pattern: str | None
    score: float = 0.0
    point_cam: np.ndarray | None = None
    second_tier: bool = False


class GraspPlanner(Protocol):
    """The planner interface (module docstring)."""

    def plan(self, observation: Observation, rng: np.random.Generator) -> Sequence[Grasp]: ...


class PlannerError(ValueError):
    """A plug-in planner that cannot be loaded or breaks the interface."""


def checked_grasps(grasps: Any, observation: Observation, name: str) -> list[Grasp]:
    """``grasps`` as a list, after checking that it is what ``plan`` promises: a sequence of
    :class:`Grasp` with finite pixels inside the image, a pattern of ``PATTERNS`` or None, and a
    ``point_cam`` of three finite numbers in front of the camera when given. Raises
    :class:`PlannerError` naming the planner ``name``, the offending item and the fix."""
    fix = "return a list of pipeline.controller.planning.Grasp, best first ([] for no grasp)"
    if grasps is None or isinstance(grasps, (str, bytes, dict)) or not hasattr(grasps, "__len__"):
        raise PlannerError(
            f"planner {name!r}: plan() returned {type(grasps).__name__}, not a "
            f"sequence of Grasp: {fix}"
        )
    out = list(grasps)
    h, w = observation.intrinsics.height, observation.intrinsics.width
    for i, g in enumerate(out):
        if not isinstance(g, Grasp):
            raise PlannerError(
                f"planner {name!r}: item {i} of plan()'s answer is a "
                f"{type(g).__name__}, not a Grasp: {fix}"
            )
        if not (math.isfinite(float(g.u)) and math.isfinite(float(g.v))):
            raise PlannerError(
                f"planner {name!r}: grasp {i} has a non-finite pixel "
                f"({g.u}, {g.v}): give the grasp point in pixels of the image"
            )
        if not (-0.5 <= float(g.u) < w - 0.5 and -0.5 <= float(g.v) < h - 0.5):
            raise PlannerError(
                f"planner {name!r}: grasp {i} at pixel ({g.u:.1f}, {g.v:.1f}) "
                f"lies outside the {w} x {h} image: u must be in [0, {w - 1}] "
                f"and v in [0, {h - 1}]"
            )
        if g.pattern is not None and g.pattern not in PATTERNS:
            raise PlannerError(
                f"planner {name!r}: grasp {i} has pattern {g.pattern!r}: use "
                f"one of {PATTERNS}, or None for a single suction point"
            )
        if g.point_cam is not None:
            pt = np.asarray(g.point_cam, np.float64)
            if pt.shape != (3,) or not np.all(np.isfinite(pt)) or pt[2] <= 0:
                raise PlannerError(
                    f"planner {name!r}: grasp {i} has point_cam {g.point_cam!r}:"
                    " give three finite numbers (camera frame, metres, z > 0) "
                    "or None"
                )
    return out


# ------------------------------------------------------------------------------ built-in
class DCNNPlanner:
    """The trained DCNN (``pipeline.planner.planner.Planner``, paper Secs. 4.1–4.2): Eq. 3's
    candidates above th ranked by Eq. 7, then, with ``evaluate.dcnn_fallback_ratio``, the
    second tier; each as its class's pattern."""

    def __init__(self, cfg, train_dir: Path | str) -> None:
        from pipeline.planner.planner import Planner, fallback_threshold, ranking_config

        self.net = Planner.load(train_dir, device="cpu")
        th = cfg.evaluate.dcnn_threshold
        # the composed train.ranking (policy included), with the model's th unless overridden
        self.net.ranking = ranking_config(
            cfg, self.net.ranking.threshold if th is None else float(th)
        )
        self.floor = fallback_threshold(cfg, self.net.ranking.threshold)  # the second tier's

    def plan(self, observation: Observation, rng: np.random.Generator) -> list[Grasp]:
        cands = self.net.plan(
            observation.depth_m, observation.intrinsics, fallback_threshold=self.floor
        )
        return [
            Grasp(
                u=float(c.u),
                v=float(c.v),
                pattern=c.grasp_class.name,
                score=float(c.score),
                second_tier=bool(c.second_tier),
            )
            for c in cands
        ]


class DexNetStylePlanner:
    """A Dex-Net-style planner (GQ-CNN or planarity + CEM, ``pipeline.dexnet.planner``, paper
    Sec. 8.1.1): its best CEM grasp, then, when the run-time check is on, the rest of CEM's
    final set by quality (at most ``evaluate.max_candidates_checked``); single suction points
    (pattern None)."""

    def __init__(
        self, cfg, variant: str, T_home: np.ndarray, baseline_dir: Path | str | None
    ) -> None:
        from pipeline.dexnet.planner import DexNetPlanner

        self.dex = DexNetPlanner.for_variant(cfg, variant, T_home, baseline_dir)
        self.k = (
            int(cfg.evaluate.max_candidates_checked) if bool(cfg.evaluate.check_reachability) else 1
        )

    def plan(self, observation: Observation, rng: np.random.Generator) -> list[Grasp]:
        grasps = self.dex.plan(
            observation.depth_m, observation.intrinsics, rng=rng, max_grasps=self.k
        )
        return [
            Grasp(
                u=float(g.u),
                v=float(g.v),
                pattern=None,
                score=float(g.score),
                point_cam=np.asarray(g.point_cam, np.float64),
            )
            for g in grasps
        ]


# ------------------------------------------------------------------------------ plug-ins
def plugin_target(name: str) -> str:
    """``package.module:Class`` of a plug-in name: the name itself when it holds a ':', else
    the value of its entry point in ``binpick.planners``. Raises :class:`PlannerError` for a
    name that is neither."""
    if ":" in name:
        return name
    found = [ep for ep in metadata.entry_points(group=ENTRY_POINT_GROUP) if ep.name == name]
    if not found:
        known = sorted(ep.name for ep in metadata.entry_points(group=ENTRY_POINT_GROUP))
        raise PlannerError(
            f"unknown planner {name!r}: evaluate.planners takes {', '.join(BUILT_IN)}, a "
            f"plug-in as package.module:Class, or an entry point of the group "
            f"{ENTRY_POINT_GROUP!r} (installed: {', '.join(known) or 'none'})"
        )
    return found[0].value


def load_plugin(name: str, cfg) -> GraspPlanner:
    """The user's planner ``name`` (``package.module:Class`` or an entry point name) built as
    ``Class(cfg)``; raises :class:`PlannerError` when the module cannot be imported, lacks the
    class, the class cannot be built, or what it builds has no ``plan(observation, rng)``."""
    target = plugin_target(name)
    module_name, _, attr = target.partition(":")
    if not module_name or not attr:
        raise PlannerError(
            f"planner {name!r}: write a plug-in as package.module:Class, got {target!r}"
        )
    try:
        module = importlib.import_module(module_name)
    except Exception as exc:  # ImportError, or the module's own error while importing
        raise PlannerError(
            f"planner {name!r}: cannot import module {module_name!r} "
            f"({type(exc).__name__}: {exc}); run from the folder that holds it "
            "or install its package into .venv"
        ) from exc
    factory = module
    for part in attr.split("."):
        if not hasattr(factory, part):
            raise PlannerError(
                f"planner {name!r}: module {module_name!r} has no {attr!r}; "
                "name the planner class after the ':'"
            )
        factory = getattr(factory, part)
    if not callable(factory):
        raise PlannerError(
            f"planner {name!r}: {target} is a {type(factory).__name__}, not a "
            "class: name the planner class after the ':'"
        )
    try:
        planner = factory(cfg)
    except Exception as exc:
        raise PlannerError(
            f"planner {name!r}: {target}(cfg) failed ({type(exc).__name__}: "
            f"{exc}); its class is called with the composed configuration"
        ) from exc
    method = getattr(planner, "plan", None)
    if not callable(method):
        raise PlannerError(
            f"planner {name!r}: {target} has no plan() method; give it "
            "plan(self, observation, rng) returning a list of Grasp"
        )
    try:
        inspect.signature(method).bind(None, None)
    except TypeError:
        raise PlannerError(
            f"planner {name!r}: {target}.plan{inspect.signature(method)} does "
            "not take (observation, rng); give it plan(self, observation, rng)"
        ) from None
    return planner
