"""The report's run-time table (pipeline/report/run_time.py), on hand-made manifests."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from pipeline.report.run_time import by_stage, made_from, run_time_rows, run_time_table


def _artifact(top: Path, stage: str, version: str, seconds: float | None, **upstream: str):
    folder = top / stage / version
    folder.mkdir(parents=True)
    timings = {} if seconds is None else {"total_s": seconds}
    (folder / "manifest.json").write_text(
        json.dumps({"stage": stage, "version": version, "timings": timings, "upstream": upstream})
    )


@pytest.fixture
def roots(tmp_path):
    """generate g1 (60 s) -> label l1 (120 s) -> train t1 (600 s, in models/); evaluate e1 and
    e2 (30 s, 90 s) of t1; an ablation of e1 and e2 (6 s); a study that names t1, e2 and a
    removed artifact; a second generation g2 nobody names."""
    data, models = tmp_path / "data", tmp_path / "models"
    _artifact(data, "generate", "g1", 60.0)
    _artifact(data, "generate", "g2", 1000.0)
    _artifact(data, "label", "l1", 120.0, generate="g1")
    _artifact(models, "train", "t1", 600.0, label="l1", generate="g1")
    _artifact(data, "evaluate", "e1", 30.0, train="t1")
    _artifact(data, "evaluate", "e2", 90.0, train="t1")
    _artifact(data, "ablation", "a1", 6.0, **{"dcnn/all_on": "e1", "dcnn/no_gate": "e2"})
    _artifact(data, "robustness", "r1", None, train_clean="t1", evaluate_x="e2", gone="zz")
    return data, models


def test_every_artifact_counts_once(roots):
    found = made_from(roots, ["e1", "a1", "r1", "none"])
    assert sorted(found) == ["a1", "e1", "e2", "g1", "l1", "r1", "t1"]  # not g2, zz, none
    rows = {r["stage"]: r for r in run_time_rows(found)}
    assert [r["stage"] for r in run_time_rows(found)] == [
        "generate",
        "label",
        "train",
        "evaluate",
        "ablation",
        "robustness",
        "total",
    ]
    assert (rows["evaluate"]["artifacts"], rows["evaluate"]["seconds"]) == (2, 120.0)
    assert rows["robustness"] == {
        "stage": "robustness",
        "artifacts": 1,
        "seconds": 0.0,
        "untimed": 1,
    }
    # 60 + 120 + 600 + 30 + 90 + 6 s, by hand
    assert rows["total"] == {"stage": "total", "artifacts": 7, "seconds": 906.0, "untimed": 1}


def test_each_artifact_counts_for_the_first_stage_that_reaches_it(roots):
    # the report reads train t1, evaluate e1, ablation a1 and robustness r1: g1 and l1 count for
    # train (no generate or label is reported), e2 for the ablation (it reaches e2 before the
    # robustness study does), r1 alone for the robustness study
    found = by_stage(roots, {"robustness": "r1", "ablation": "a1", "evaluate": "e1", "train": "t1"})
    assert {v: m["stage"] for v, m in found.items()} == {
        "t1": "train",
        "l1": "train",
        "g1": "train",
        "e1": "evaluate",
        "a1": "ablation",
        "e2": "ablation",
        "r1": "robustness",
    }
    rows = {r["stage"]: r["seconds"] for r in run_time_rows(found)}
    assert rows == {
        "train": 780.0,
        "evaluate": 30.0,
        "ablation": 96.0,
        "robustness": 0.0,
        "total": 906.0,
    }


def test_table_in_minutes_with_share_and_budget(roots):
    table = run_time_table(roots, {"label": "l1", "generate": "g1"}, {"generate": 2, "train": 9})
    # g1 60 s and l1 120 s of 180 s; the total's budget sums the stages' that have one
    assert table.rows == [
        ["generate", 1, 1.0, 100 / 3, 2, 0],
        ["label", 1, 2.0, 200 / 3, None, 0],
        ["total", 2, 3.0, 100.0, 2, 0],
    ]
    assert table.csv_text().splitlines()[-1] == "total,2,3.00,100.0,2,0"
    assert run_time_table(roots, {"generate": "g1"}).rows[-1][4] is None  # no budget at all
    assert run_time_table(roots, {}).rows == []
