"""Configuration: every value has one home (conf/), composed configs are complete, and algorithm
settings are built from their sections without field-by-field copies."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
from omegaconf import MISSING, OmegaConf

from pipeline.config import physical, schema, stage_sections
from pipeline.config.build import from_section
from pipeline.runtime.cli import CONF_DIR, compose, compose_uncached

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


# Value overrides of every kind (a scalar, a list, null, an interpolation, an added key, a deleted
# key) beside config-group choices, as tests, benchmarks and the studies compose them.
SAME_WAY = [
    ["experiment=smoke"],
    ["experiment=smoke", "paths.root=/tmp/a", "generate.num_scenes=4", "logging.progress=false"],
    ["experiment=default", "sensor=sr300", "paths.root=/tmp/b", "servo.normal_smoothing=2"],
    ["experiment=smoke", "evaluate.planners=[dcnn,oracle]", "hand.rotations_deg=[0]"],
    ["experiment=smoke", "evaluate.dcnn_fallback_ratio=null", "evaluate.train_version=${seed}"],
    ["experiment=smoke", "+extra_key=1", "+extra_two=2", "~extra_two", "executor=ray"],
    ["paths.root=/tmp/c", "experiment=paper", "depth_filter=fill_median"],
]
# Bad overrides: both ways raise the same error.
BAD = [
    ["experiment=smoke", "generate.num_scene=3"],  # a typo in a key
    ["experiment=smoke", "generate.num_scenes=many"],  # a wrong type
    ["experiment=smoke", "camera.fx=[1,2]"],
    ["experiment=smok"],  # an unknown option of a group
    ["experiment=smoke", "+seed=2"],  # adding a key that exists
    ["experiment=smoke", "~no_such_key"],
]


@pytest.mark.parametrize("root", ["generate", "ablation"])
def test_compose_is_hydras_composition(root):
    """``compose`` keeps the group choices' composition and applies value overrides to a copy:
    the same config, flags and node types as Hydra's whole composition. The override lists
    share group choices, so most of them take the kept composition."""
    for overrides in SAME_WAY:
        want = compose_uncached(root, overrides)
        got = compose(root, overrides)
        assert OmegaConf.to_yaml(got) == OmegaConf.to_yaml(want), (root, overrides)
        assert OmegaConf.is_struct(got) and OmegaConf.is_struct(want)
        assert OmegaConf.get_type(got.paths, "root") is OmegaConf.get_type(want.paths, "root")


@pytest.mark.parametrize("overrides", BAD, ids=lambda o: o[-1])
def test_compose_raises_hydras_errors(overrides):
    with pytest.raises(Exception) as want:
        compose_uncached("evaluate", overrides)
    with pytest.raises(want.type) as got:
        compose("evaluate", overrides)
    assert str(got.value) == str(want.value)


def test_composed_copies_are_independent():
    a = compose("generate", ["experiment=smoke"])
    a.generate.num_scenes = 12345
    assert compose("generate", ["experiment=smoke"]).generate.num_scenes != 12345
