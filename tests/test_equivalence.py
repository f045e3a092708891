"""Two versions of a stage that hold the same data, and the report's upstream matches."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from pipeline.artifacts import ArtifactError
from pipeline.artifacts.equivalence import same_data
from pipeline.report.upstream import Match


def _version(stage_dir: Path, name: str, files: dict) -> None:
    (stage_dir / name).mkdir(parents=True)
    (stage_dir / name / "manifest.json").write_text(json.dumps({"files": files}))


def _f(sha: str, n: int = 10) -> dict:
    return {"bytes": n, "sha256": sha}


@pytest.fixture
def gen(tmp_path: Path) -> Path:
    """data/generate with a: scenes + logs; b: the same scenes, other logs; c: one scene differs;
    d: the same scenes and one more file; e: logs only."""
    d = tmp_path / "generate"
    scenes = {"index.json": _f("11"), "scenes/train-00000.npz": _f("22", 100)}
    _version(d, "a", {**scenes, "log.rrd": _f("33"), "log.mcap": _f("44")})
    _version(d, "b", {**scenes, "log.rrd": _f("55"), "log.mcap": _f("66")})
    _version(d, "c", {**scenes, "scenes/train-00000.npz": _f("23", 100), "log.rrd": _f("33")})
    _version(d, "d", {**scenes, "scenes/val-00000.npz": _f("77")})
    _version(d, "e", {"log.rrd": _f("33"), "log.mcap": _f("44")})
    _version(d, "f", {"log.rrd": _f("88")})
    return d


def test_versions_with_the_same_data_but_other_logs_are_the_same(gen: Path) -> None:
    assert same_data(gen, "a", "b") and same_data(gen, "b", "a")
    assert not same_data(gen, "a", "c")  # one scene's hash differs
    assert not same_data(gen, "a", "d")  # one file more
    assert not same_data(gen, "e", "f")  # nothing but logs: no data to compare
    assert not same_data(gen, "a", "missing")
    assert same_data(gen, "missing", "missing")  # the same name is the same version


def test_a_match_accepts_an_identical_upstream_only_when_told_where_it_lives(gen: Path) -> None:
    message = lambda name, theirs: f"{name} was made from {theirs}"  # noqa: E731
    Match("generate", "a", message, stage_dir=gen).check("L", {"generate": "b"})
    with pytest.raises(ArtifactError, match="L was made from c"):
        Match("generate", "a", message, stage_dir=gen).check("L", {"generate": "c"})
    with pytest.raises(ArtifactError, match="L was made from b"):
        Match("generate", "a", message).check("L", {"generate": "b"})  # strict without stage_dir
