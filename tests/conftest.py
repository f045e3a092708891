"""Shared fixtures: the real Hydra config with test overrides, rooted in a scratch folder, and
one smoke pipeline (generation, labels, a trained network) built once per test session."""

from __future__ import annotations

import os

# Test workers share two cores, and the tests that train or run stage subprocesses start OpenMP
# threads of their own: an idle OpenMP thread sleeps instead of spinning on a core another
# worker needs (set before torch loads its OpenMP runtime, which reads it once; subprocesses
# inherit it).
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import dataclasses
import functools
import hashlib
import shutil
from dataclasses import dataclass
from pathlib import Path

import pybullet as p
import pytest
from filelock import FileLock

from pipeline.runtime.cli import compose

# The session's smoke pipeline: 4 training, 1 validation and 2 test heaps in shards of 2, one
# worker per stage (a CPU training of conf/experiment/smoke.yaml's one epoch is deterministic).
SMOKE_SCENES = (
    "generate.num_scenes=4",
    "generate.num_val_scenes=1",
    "generate.num_test_scenes=2",
    "generate.scenes_per_shard=2",
    "generate.workers=1",
    "label.workers=1",
    "train.device=cpu",
)


@functools.cache
def composed(*overrides: str):
    """The composed configuration (``conf/``, the smoke experiment) with ``overrides``, composed
    once per test session and set of overrides (read-only: do not change it)."""
    return compose("generate", ["experiment=smoke", *overrides])


def conf_section(name: str, *overrides: str):
    """The ``name`` section of the composed configuration (``conf/``, the smoke experiment) as its
    schema dataclass, e.g. ``conf_section("hand")`` → ``HandConfig``: the values live in YAML
    only, so tests take them from there."""
    from omegaconf import OmegaConf

    return OmegaConf.to_object(composed(*overrides)[name])


def _config_builders() -> dict:
    """Each algorithm settings class → (the pipeline's builder of it from a composed config, the
    fields a caller gives it). One table, so tests build their settings as the stages do."""
    from pipeline.dexnet.cem import CEMConfig
    from pipeline.dexnet.gqcnn import CropConfig, GQCNNConfig
    from pipeline.dexnet.planner import (
        cem_config,
        crop_config,
        gqcnn_config,
        planarity_config,
        sampler_config,
    )
    from pipeline.dexnet.quality import PlanarityConfig
    from pipeline.dexnet.sampling import SamplerConfig
    from pipeline.grasping.suction import SuctionModelConfig, suction_model_config
    from pipeline.grasping.surfaces import SurfaceDetectionConfig
    from pipeline.labelling.scene import surface_config
    from pipeline.planner.loss import LossConfig, loss_config
    from pipeline.planner.network import NetworkConfig, network_config
    from pipeline.planner.planner import ranking_config
    from pipeline.planner.ranking import RankingConfig
    from pipeline.robot.model import RobotConfig, robot_config
    from pipeline.robot.path import PathCheckConfig, path_config
    from pipeline.servo.control import ServoConfig, servo_config
    from pipeline.servo.descriptor import DescriptorConfig, descriptor_config

    return {
        CEMConfig: (cem_config, ()),
        # the heaps' boxes (``boxes.density``), as the labelling and baseline stages use it
        SuctionModelConfig: (lambda c: suction_model_config(c, float(c.boxes.density)), ()),
        CropConfig: (crop_config, ()),
        GQCNNConfig: (gqcnn_config, ()),
        PlanarityConfig: (planarity_config, ()),
        SamplerConfig: (sampler_config, ()),
        SurfaceDetectionConfig: (surface_config, ()),
        LossConfig: (loss_config, ()),
        NetworkConfig: (network_config, ()),
        # th is the training stage's calibrated value: the test gives it
        RankingConfig: (ranking_config, ("threshold",)),
        RobotConfig: (robot_config, ()),
        PathCheckConfig: (path_config, ()),
        ServoConfig: (servo_config, ()),
        DescriptorConfig: (descriptor_config, ()),
    }


def default_config(cls, **overrides):
    """The ``cls`` settings (e.g. ``SamplerConfig``) the pipeline builds from the composed
    configuration (``composed()``), with the fields in ``overrides`` replaced: the values live in
    ``conf/`` only, so tests take them from there. Fields the caller gives the pipeline's builder
    (``RankingConfig``'s ``threshold``) must be in ``overrides``."""
    builders = _config_builders()
    if cls not in builders:
        raise TypeError(
            f"default_config knows no builder for {cls!r}: add it to "
            "tests/conftest.py's _config_builders"
        )
    build, given = builders[cls]
    missing = [name for name in given if name not in overrides]
    if missing:
        raise TypeError(
            f"default_config({cls.__name__}) needs {missing} in its overrides: "
            "the pipeline's builder takes them from its caller"
        )
    obj = build(composed(), **{name: overrides.pop(name) for name in given})
    if obj is None:
        raise ValueError(
            f"the composed config builds no {cls.__name__} (e.g. robot.path_check is false)"
        )
    return dataclasses.replace(obj, **overrides)


def smoke_overrides(root: Path, *extra: str) -> list[str]:
    """Overrides of a smoke config rooted in ``root`` with the session pipeline's scene counts."""
    return [
        "experiment=smoke",
        f"paths.root={root}",
        "logging.progress=false",
        *SMOKE_SCENES,
        *extra,
    ]


@dataclass(frozen=True)
class SmokeRoot:
    """A ``paths.root`` holding smoke artifacts: ``data/generate``, ``data/label``,
    ``models/train``. The session's one is shared: a test that writes to it (a new artifact, a
    damaged file) works on ``copy(...)`` instead."""

    root: Path
    extra: tuple[str, ...] = ()  # overrides it was built with, beyond the session's

    def cfg(self, stage: str, *extra: str):
        """The composed config of ``stage`` rooted here, with the session's scene counts, the
        overrides it was built with and ``extra``."""
        return compose(stage, smoke_overrides(self.root, *self.extra, *extra))

    def copy(self, dest: Path, tops: tuple[str, ...] = ("data", "models")) -> SmokeRoot:
        """A scratch copy of the top folders ``tops`` in ``dest`` (replaced if it exists)."""
        if dest.exists():
            shutil.rmtree(dest)
        for top in tops:
            if (self.root / top).exists():
                shutil.copytree(self.root / top, dest / top, symlinks=True)
        dest.mkdir(parents=True, exist_ok=True)
        return SmokeRoot(dest, self.extra)

    def artifact(self, stage: str) -> Path:
        """The folder ``latest`` of ``stage`` points to."""
        top = "models" if stage == "train" else "data"
        return (self.root / top / stage / "latest").resolve()


PIPELINE_STAGES = ("generate", "label", "train")


def build_smoke_root(
    root: Path, *extra: str, stages: tuple[str, ...] = PIPELINE_STAGES
) -> SmokeRoot:
    """Run ``stages`` (in order, each reading the previous one's ``latest``) in ``root`` with
    the session's smoke overrides plus ``extra``."""
    from pipeline.stages.generate import generate
    from pipeline.stages.label import label
    from pipeline.stages.train import train

    run = {"generate": generate, "label": label, "train": train}
    smoke = SmokeRoot(root, tuple(extra))
    for stage in stages:
        run[stage](smoke.cfg(stage))
    return smoke


@pytest.fixture(scope="session")
def smoke_pipelines(tmp_path_factory):
    """A factory: ``smoke_pipelines("sensor=sr300", stages=("generate", "label"))`` → the
    ``SmokeRoot`` of the session's smoke pipeline with those extra overrides (later overrides
    win), built once per session and set of overrides (under pytest-xdist, once for all the
    workers). Read-only, like ``smoke_pipeline``."""
    built: dict = {}
    shared = _shared_tmp(tmp_path_factory)

    def get(*extra: str, stages: tuple[str, ...] = PIPELINE_STAGES) -> SmokeRoot:
        key = (extra, tuple(stages))
        if key not in built:
            if shared is None:
                root = tmp_path_factory.mktemp("smoke_pipeline")
                built[key] = build_smoke_root(root, *extra, stages=stages)
            else:
                built[key] = _built_once_for_all_workers(shared, key)
        return built[key]

    return get


def _built_once_for_all_workers(shared: Path, key: tuple) -> SmokeRoot:
    """``build_smoke_root`` of ``key`` = (extra overrides, stages) in ``shared``: the first
    pytest-xdist worker to ask builds it under a file lock, the others wait and read it."""
    extra, stages = key
    name = hashlib.sha256(repr(key).encode()).hexdigest()[:16]
    root, done = shared / f"smoke_pipeline_{name}", shared / f"smoke_pipeline_{name}.done"
    with FileLock(str(root) + ".lock"):
        if not done.exists():
            if root.exists():  # a worker that failed half-way
                shutil.rmtree(root)
            build_smoke_root(root, *extra, stages=stages)
            done.touch()
    return SmokeRoot(root, tuple(extra))


def _shared_tmp(tmp_path_factory) -> Path | None:
    """The folder every pytest-xdist worker of this run shares (the parent of the workers' own
    temporary folders), or None in a run without workers."""
    if os.environ.get("PYTEST_XDIST_WORKER") is None:
        return None
    return tmp_path_factory.getbasetemp().parent


@pytest.fixture(scope="session")
def smoke_pipeline(smoke_pipelines) -> SmokeRoot:
    """Generation, labels (with the robot-level checks) and a trained smoke network, built once
    per session. Read-only: copy it (``SmokeRoot.copy``) to change anything."""
    return smoke_pipelines()


@pytest.fixture
def client():
    """A headless pybullet client of its own, disconnected after the test."""
    c = p.connect(p.DIRECT)
    yield c
    p.disconnect(c)


@pytest.fixture
def static_box():
    """A factory: ``static_box(client, half_extents, position, quat=(0, 0, 0, 1))`` → the body id
    of a visible static box (metres, world frame)."""

    def make(client, half, position, quat=(0, 0, 0, 1)):
        col = p.createCollisionShape(p.GEOM_BOX, halfExtents=half, physicsClientId=client)
        vis = p.createVisualShape(p.GEOM_BOX, halfExtents=half, physicsClientId=client)
        return p.createMultiBody(
            0, col, vis, basePosition=position, baseOrientation=quat, physicsClientId=client
        )

    return make


@pytest.fixture
def smoke_cfg(tmp_path: Path):
    """A factory: ``smoke_cfg("generate", "generate.num_scenes=2")`` → config rooted in tmp_path."""

    def make(config_name: str = "generate", *overrides: str):
        return compose(
            config_name,
            ["experiment=smoke", f"paths.root={tmp_path}", "logging.progress=false", *overrides],
        )

    return make
