"""Shared fixtures: the real Hydra config with test overrides, rooted in a scratch folder."""

from __future__ import annotations

from pathlib import Path

import pybullet as p
import pytest

from pipeline.cli import compose


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
