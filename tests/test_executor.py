"""The executor (``executor=local|ray``): same artifacts either way, results in task order,
a task's exception raised in the driver with its message."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import conf_section
from hydra.errors import ConfigCompositionException

from pipeline.runtime.cli import compose
from pipeline.runtime.executor import RAY_INSTALL_HINT, import_ray, map_shards, start_ray
from pipeline.stages.generate import generate
from pipeline.stages.label import label
from pipeline.tools.repro_check import compare_artifacts

ray = pytest.importorskip("ray")

# 4 generation / labelling shards (train 2 + val 1 + test 1), 2 logged scenes.
TINY = (
    "generate.num_scenes=3",
    "generate.num_val_scenes=1",
    "generate.num_test_scenes=1",
    "generate.scenes_per_shard=2",
    "logging.max_logged_scenes=2",
    "logging.progress=false",
)
# One local worker against two Ray workers; one local worker against two local ones is
# test_generate.py's and test_label.py's "same whatever the workers".
RUNS = (("local", 1), ("ray", 2))
RAY = conf_section("executor", "executor=ray")


def _cfg(stage: str, root: Path, executor: str, workers: int, *extra: str):
    return compose(
        stage,
        [
            "experiment=smoke",
            f"paths.root={root}",
            *TINY,
            f"executor={executor}",
            f"generate.workers={workers}",
            f"label.workers={workers}",
            *extra,
        ],
    )


# Trivial tasks. Module-level, so Ray pickles them by reference: the fixture below puts this
# folder on the workers' PYTHONPATH, as a cluster needs the package importable on every node.
_STATE: dict = {}


def _init(offset: int) -> None:
    _STATE["offset"] = offset


def _square(x: int) -> tuple[int, int]:
    if x < 0:
        raise ValueError(f"task {x} is negative")
    return x * x + _STATE["offset"], os.getpid()


@pytest.fixture(scope="module")
def ray_instance():
    """One private 2-CPU Ray instance for the module; map_shards reuses it, never stops it."""
    with pytest.MonkeyPatch.context() as mp:
        mp.delenv("RAY_ADDRESS", raising=False)
        path = [str(Path(__file__).parent)] + [p for p in [os.environ.get("PYTHONPATH")] if p]
        mp.setenv("PYTHONPATH", os.pathsep.join(path))
        started = start_ray(RAY, 2)
        yield ray
        if started:
            ray.shutdown()


@pytest.fixture(scope="module")
def artifacts(tmp_path_factory, request):
    """{(executor, workers): (generation folder, label folder)}; the local run first."""
    out = {}
    for executor, workers in RUNS:
        if executor == "ray":
            request.getfixturevalue("ray_instance")
        root = tmp_path_factory.mktemp(f"{executor}{workers}")
        gen = generate(_cfg("generate", root, executor, workers))
        out[executor, workers] = (gen, label(_cfg("label", root, executor, workers)))
    return out


@pytest.mark.parametrize("stage", ["generate", "label"])
def test_same_artifact_whatever_the_executor(artifacts, stage):
    k = 0 if stage == "generate" else 1
    base = artifacts["local", 1][k]
    for run in RUNS[1:]:
        other = artifacts[run][k]
        assert other.name == base.name  # same version
        assert compare_artifacts(stage, base, other) == [], run  # same files, same bytes/rows


def test_ray_results_in_task_order(ray_instance):
    tasks = list(range(12))
    out = list(
        map_shards(
            _square,
            tasks,
            init=_init,
            initargs=(7,),
            workers=2,
            desc="t",
            progress=False,
            size=lambda t: 1,
            executor=RAY,
        )
    )
    assert [r for r, _ in out] == [x * x + 7 for x in tasks]
    pids = {pid for _, pid in out}
    assert len(pids) == 2 and os.getpid() not in pids  # two Ray worker processes
    assert ray_instance.is_initialized()  # not stopped: this call did not start it


def test_ray_task_error_surfaces_with_its_message(ray_instance):
    with pytest.raises(ValueError, match="task -2 is negative") as info:
        list(
            map_shards(
                _square,
                [1, -2, 3],
                init=_init,
                initargs=(0,),
                workers=2,
                desc="t",
                progress=False,
                size=lambda t: 1,
                executor=RAY,
            )
        )
    assert "Ray worker" in "".join(getattr(info.value, "__notes__", []))


def test_ray_task_error_fails_the_stage(artifacts, tmp_path, monkeypatch):
    """A labelling worker that cannot read its shard: the stage raises the worker's error and
    leaves no label artifact, no work folder. (The driver's check of the upstream artifact
    against its manifest would catch the missing shard first: it is switched off here.)"""
    gen = artifacts["ray", 2][0]
    copy = tmp_path / "data" / "generate" / gen.name
    shutil.copytree(gen, copy)
    shard = sorted(copy.rglob("*.npz"))[-1]
    shard.unlink()
    monkeypatch.setattr("pipeline.artifacts.store.verify_artifact", lambda folder: [])
    with pytest.raises(FileNotFoundError, match=shard.name):
        label(_cfg("label", tmp_path, "ray", 2, f"label.generate_version={gen.name}"))
    label_dir = tmp_path / "data" / "label"
    assert not label_dir.exists() or list(label_dir.iterdir()) == []


def test_ray_from_the_command_line(artifacts, tmp_path):
    """``python -m pipeline.stages.label executor=ray``: the stage's functions live in ``__main__``
    there; the workers must still run them with shared module state. Same artifact as in-process."""
    gen, lab = artifacts["local", 1]
    shutil.copytree(gen, tmp_path / "data" / "generate" / gen.name)
    env = {k: v for k, v in os.environ.items() if k != "RAY_ADDRESS"}
    subprocess.run(
        [
            sys.executable,
            "-m",
            "pipeline.stages.label",
            "experiment=smoke",
            *TINY,
            f"paths.root={tmp_path}",
            "executor=ray",
            "label.workers=2",
            f"label.generate_version={gen.name}",
        ],
        check=True,
        env=env,
        cwd=Path(__file__).parents[1],
    )
    other = tmp_path / "data" / "label" / lab.name
    assert compare_artifacts("label", lab, other) == []


def test_missing_ray_says_how_to_install(monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)  # `import ray` raises ImportError
    with pytest.raises(ImportError, match=r"pip install -e '\.\[ray\]'") as info:
        import_ray()
    assert str(info.value) == RAY_INSTALL_HINT


def test_executor_choice_is_checked():
    assert compose("generate", ["experiment=smoke"]).executor.name == "local"
    assert compose("label", ["experiment=smoke", "executor=ray"]).executor.name == "ray"
    with pytest.raises(ConfigCompositionException, match="executor"):
        compose("generate", ["experiment=smoke", "executor=nope"])
