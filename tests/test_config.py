"""Configuration: every value has one home (conf/), composed configs are complete, and algorithm
settings are built from their sections without field-by-field copies."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
from omegaconf import MISSING, OmegaConf

from pipeline.config import physical, schema, stage_sections
from pipeline.config.build import from_section
from pipeline.runtime.cli import CONF_DIR, compose

ROOTS = (
    "generate",
    "label",
    "train",
    "baseline",
    "evaluate",
    "unseen",
    "ablation",
    "robustness",
    "report",
)


@dataclasses.dataclass
class Settings:
    window: int
    eps: float
    name: str = "x"


def test_from_section_by_hand():
    node = OmegaConf.create({"window": 21, "eps": 0.004, "name": "a", "other": 1})
    assert from_section(Settings, node) == Settings(21, 0.004, "a")  # "other" is ignored
    assert from_section(Settings, {"window": 5, "eps": 0.1, "name": "b"}) == Settings(5, 0.1, "b")
    assert from_section(Settings, Settings(3, 0.5, "c"), eps=0.25) == Settings(3, 0.25, "c")
    # the dataclass default does not stand in for a value missing from the section
    with pytest.raises(KeyError, match="Settings.name"):
        from_section(Settings, {"window": 5, "eps": 0.1})
    with pytest.raises(TypeError, match="no field"):
        from_section(Settings, node, colour="red")


def test_schema_fields_have_no_defaults():
    """The schema gives types only: a value written there as well as in conf/ could differ."""
    modules = (schema, physical, stage_sections)
    classes = {
        cls
        for module in modules
        for cls in vars(module).values()
        if isinstance(cls, type)
        and dataclasses.is_dataclass(cls)
        and cls.__module__ == module.__name__
    }
    assert len(classes) > 30  # every section of the schema is checked
    for cls in classes:
        for f in dataclasses.fields(cls):
            nested = f.default_factory is not dataclasses.MISSING and dataclasses.is_dataclass(
                f.default_factory
            )
            assert f.default is MISSING or nested, f"{cls.__name__}.{f.name} has a default"


@pytest.mark.parametrize("root", ROOTS)
def test_every_stage_config_is_complete(root):
    runs = [[f"experiment={e}"] for e in ("smoke", "default", "paper")] + [
        ["experiment=smoke", extra] for extra in ("sensor=sr300", "executor=ray", "planner=dcnn")
    ]
    for overrides in runs:
        assert OmegaConf.missing_keys(compose(root, overrides)) == set(), (root, overrides)


def test_executor_options_are_the_executors_only():
    """The Ray settings are included by both executors, not an executor of their own."""
    from hydra.errors import MissingConfigException

    options = sorted(p.stem for p in (Path(CONF_DIR) / "executor").glob("*.yaml"))
    assert options == ["local", "ray"]
    with pytest.raises(MissingConfigException, match="local"):
        compose("generate", ["experiment=smoke", "executor=ray_settings"])
