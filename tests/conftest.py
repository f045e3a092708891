"""Shared fixtures: the real Hydra config with test overrides, rooted in a scratch folder, and
one smoke pipeline (generation, labels, a trained network) built once per test session."""

from __future__ import annotations

import shutil
from dataclasses import dataclass
from pathlib import Path

import pybullet as p
import pytest

from pipeline.cli import compose

# The session's smoke pipeline: 4 training, 1 validation and 2 test heaps in shards of 2, one
# worker per stage (a CPU training of conf/experiment/smoke.yaml's one epoch is deterministic).
SMOKE_SCENES = ("generate.num_scenes=4", "generate.num_val_scenes=1", "generate.num_test_scenes=2",
                "generate.scenes_per_shard=2", "generate.workers=1", "label.workers=1",
                "train.device=cpu")


def conf_section(name: str, *overrides: str):
    """The ``name`` section of the composed configuration (``conf/``, the smoke experiment) as its
    schema dataclass, e.g. ``conf_section("hand")`` → ``HandConfig``: the values live in YAML
    only, so tests take them from there."""
    from omegaconf import OmegaConf

    return OmegaConf.to_object(compose("generate", ["experiment=smoke", *overrides])[name])


def smoke_overrides(root: Path, *extra: str) -> list[str]:
    """Overrides of a smoke config rooted in ``root`` with the session pipeline's scene counts."""
    return ["experiment=smoke", f"paths.root={root}", "logging.progress=false", *SMOKE_SCENES,
            *extra]


@dataclass(frozen=True)
class SmokeRoot:
    """A ``paths.root`` holding smoke artifacts: ``data/generate``, ``data/label``,
    ``models/train``. The session's one is shared: a test that writes to it (a new artifact, a
    damaged file) works on ``copy(...)`` instead."""

    root: Path

    def cfg(self, stage: str, *extra: str):
        """The composed config of ``stage`` rooted here, with the session's scene counts."""
        return compose(stage, smoke_overrides(self.root, *extra))

    def copy(self, dest: Path, tops: tuple[str, ...] = ("data", "models")) -> "SmokeRoot":
        """A scratch copy of the top folders ``tops`` in ``dest`` (replaced if it exists)."""
        if dest.exists():
            shutil.rmtree(dest)
        for top in tops:
            if (self.root / top).exists():
                shutil.copytree(self.root / top, dest / top, symlinks=True)
        dest.mkdir(parents=True, exist_ok=True)
        return SmokeRoot(dest)

    def artifact(self, stage: str) -> Path:
        """The folder ``latest`` of ``stage`` points to."""
        top = "models" if stage == "train" else "data"
        return (self.root / top / stage / "latest").resolve()


@pytest.fixture(scope="session")
def smoke_pipeline(tmp_path_factory) -> SmokeRoot:
    """Generation, labels (with the robot-level checks) and a trained smoke network, built once
    per session. Read-only: copy it (``SmokeRoot.copy``) to change anything."""
    from pipeline.generate import generate
    from pipeline.label import label
    from pipeline.train import train

    smoke = SmokeRoot(tmp_path_factory.mktemp("smoke_pipeline"))
    generate(smoke.cfg("generate"))
    label(smoke.cfg("label"))
    train(smoke.cfg("train"))
    return smoke


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
        return p.createMultiBody(0, col, vis, basePosition=position, baseOrientation=quat,
                                 physicsClientId=client)

    return make


@pytest.fixture
def smoke_cfg(tmp_path: Path):
    """A factory: ``smoke_cfg("generate", "generate.num_scenes=2")`` → config rooted in tmp_path."""

    def make(config_name: str = "generate", *overrides: str):
        return compose(config_name, [
            "experiment=smoke", f"paths.root={tmp_path}", "logging.progress=false",
            *overrides,
        ])

    return make
