"""The unseen-size test set (pipeline/stages/unseen.py): no training size among its boxes, bad input
refused before any work, and a smoke run end to end (seen rows from the manifests, unseen rows
measured, ``latest`` left where it was, the report's section)."""

from __future__ import annotations

import json

import pytest

from pipeline.runtime.cli import compose


def _base(tmp_path):
    return [
        "experiment=smoke",
        f"paths.root={tmp_path}",
        "logging.progress=false",
        "generate.num_scenes=4",
        "generate.num_val_scenes=2",
        "generate.num_test_scenes=2",
        "generate.scenes_per_shard=4",
        "label.robot_checks=false",
        "baseline.epochs=1",
    ]


def test_unseen_boxes_are_none_of_the_training_sizes():
    cfg = compose("generate", ["boxes=unseen"])
    train = compose("generate", []).boxes
    seen = {tuple(sorted(b.size)) for b in train.types}
    unseen = [tuple(sorted(b.size)) for b in cfg.boxes.types]
    assert len(unseen) >= 7 and not seen & set(unseen)
    names = [b.name for b in cfg.boxes.types]
    assert len(set(names)) == len(names)


def test_bad_input_is_refused_before_any_work(tmp_path):
    from pipeline.stages.unseen import unseen

    with pytest.raises(ValueError, match="conf/boxes"):
        unseen(compose("unseen", _base(tmp_path) + ["unseen.boxes=nowhere"]))
    with pytest.raises(ValueError, match="test_scenes"):
        unseen(compose("unseen", _base(tmp_path) + ["unseen.test_scenes=0"]))
    with pytest.raises(ValueError, match="conf/eval_boxes"):
        unseen(compose("unseen", _base(tmp_path) + ["unseen.closed_loop_boxes=nowhere"]))
    with pytest.raises(ValueError, match="closed_loop_trials"):
        unseen(compose("unseen", _base(tmp_path) + ["unseen.closed_loop_trials=-1"]))
    assert not (tmp_path / "data").exists()


def test_closed_loop_boxes_are_the_unseen_sizes():
    """eval_boxes=unseen holds the unseen set's sizes, 12 to a heap."""
    cfg = compose("evaluate", ["eval_boxes=unseen"])
    unseen = compose("generate", ["boxes=unseen"]).boxes
    assert [list(b.size) for b in cfg.eval_boxes.types] == [list(b.size) for b in unseen.types]
    assert cfg.eval_boxes.min_count == cfg.eval_boxes.max_count == 12


@pytest.mark.slow
def test_smoke_unseen_end_to_end(smoke_pipeline, tmp_path):
    from conftest import smoke_overrides

    from pipeline.artifacts import ArtifactError, load_manifest
    from pipeline.report import report
    from pipeline.report.unseen import UNSEEN_SECTION
    from pipeline.stages.baseline import baseline
    from pipeline.stages.evaluate import evaluate
    from pipeline.stages.unseen import unseen

    # the session's generate -> label -> train; nothing trained yet in an empty root
    with pytest.raises(ArtifactError, match="unseen.train_version"):
        unseen(compose("unseen", _base(tmp_path / "empty")), _base(tmp_path / "empty"))
    assert not (tmp_path / "empty" / "data").exists()  # refused before any work
    smoke = smoke_pipeline.copy(tmp_path / "root")
    root = smoke.root
    base = smoke_overrides(root, "baseline.epochs=1")
    baseline(compose("baseline", base))  # as make reproduce runs it before unseen
    table3 = evaluate(compose("evaluate", base)).name  # likewise
    cfg = compose("unseen", base)
    seen_gen = smoke.artifact("generate").name
    out = unseen(cfg, base)
    data = json.loads((out / "unseen.json").read_text())
    manifest = load_manifest(out)
    up = manifest["upstream"]
    # the unseen heaps: a test split only, of the unseen boxes
    gen_u = load_manifest(root / "data" / "generate" / up["generate_unseen"])
    assert gen_u["config"]["boxes"]["name"] == "unseen"
    assert gen_u["config"]["generate"]["num_scenes"] == 0
    # ``latest`` names the ordinary (seen-size) pipeline, not the unseen heaps
    assert smoke.artifact("generate").name == seen_gen
    assert up["train"] == smoke.artifact("train").name
    assert up["baseline"] == smoke.artifact("baseline").name
    # Table 1: the seen row is the train manifest's, the unseen row is measured at the same th
    t1 = {r["set"]: r for r in data["table1"]}
    train_t1 = load_manifest(root / "models" / "train" / up["train"])["metrics"]["table1"]
    assert t1["seen"]["top1"] == (None if train_t1["top1"] is None else round(train_t1["top1"], 6))
    assert t1["unseen"]["threshold"] == train_t1["threshold"]
    assert t1["unseen"]["scored_images"] <= 2
    # Table 2: every planner on both sets
    sets = {(r["set"], r["planner"]) for r in data["table2"]}
    assert {p for s, p in sets if s == "seen"} == {p for s, p in sets if s == "unseen"}
    assert all(r["images"] <= 2 for r in data["table2"] if r["set"] == "unseen")
    for name in (
        "table1.csv",
        "table2.csv",
        "closed_loop.csv",
        "drops_by_mass.csv",
        "log.rrd",
        "log.mcap",
    ):
        assert (out / name).is_file()
    # the closed loop: every planner on heaps of the unseen boxes, drawn from the test stream
    ev = load_manifest(root / "data" / "evaluate" / up["evaluate_unseen"])
    assert ev["config"]["eval_boxes"]["name"] == "unseen"
    assert ev["config"]["evaluate"]["split"] == "test"
    assert [r["planner"] for r in data["closed_loop"]] == ev["config"]["evaluate"]["planners"]
    keys = ("planner", "boxes", "picked", "attempts", "successes", "end_no_grasp")
    assert [{k: r[k] for k in keys} for r in data["closed_loop"]] == [
        {k: r[k] for k in keys} for r in ev["metrics"]["table3"]
    ]
    assert up["evaluate_unseen"] != table3  # other heaps: another evaluation
    assert (root / "data" / "evaluate" / "latest").resolve().name == table3
    assert unseen(cfg, base) == out  # reused
    report(compose("report", base))
    readme = (root / "reports" / "README.md").read_text()
    assert f"## {UNSEEN_SECTION}" in readme and out.name in readme
    assert (root / "reports" / "tables" / "unseen_table2.csv").is_file()
    assert (root / "reports" / "tables" / "unseen_closed_loop.csv").is_file()
