"""Shared fixtures: the real Hydra config with test overrides, rooted in a scratch folder."""

from __future__ import annotations

from pathlib import Path

import pytest

from pipeline.cli import compose


@pytest.fixture
def smoke_cfg(tmp_path: Path):
    """A factory: ``smoke_cfg("generate", "generate.num_scenes=2")`` → config rooted in tmp_path."""

    def make(config_name: str = "generate", *overrides: str):
        return compose(config_name, [
            "experiment=smoke", f"paths.root={tmp_path}", "logging.progress=false",
            *overrides,
        ])

    return make
