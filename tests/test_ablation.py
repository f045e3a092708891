"""The execution ablation (pipeline/stages/ablation.py): one evaluation per variant, gathered; the
evaluation's ``latest`` left where it was; bad input refused before any work."""

from __future__ import annotations

import json

import pytest
from conftest import smoke_overrides

from pipeline.runtime.cli import compose


def test_bad_planner_and_repeated_names_are_refused_before_any_work(smoke_cfg, tmp_path):
    from pipeline.stages.ablation import ablation

    with pytest.raises(ValueError, match="ablation.planners"):
        ablation(smoke_cfg("ablation", "ablation.planners=[robot]"))
    cfg = smoke_cfg("ablation")
    cfg.ablation.variants = [cfg.ablation.variants[0], cfg.ablation.variants[0]]
    with pytest.raises(ValueError, match="repeated names"):
        ablation(cfg)
    with pytest.raises(ValueError, match="variant_planners.no_gate has 'robot'"):
        ablation(smoke_cfg("ablation", "+ablation.variant_planners.no_gate=[robot]"))
    assert not (tmp_path / "data").exists()


@pytest.mark.slow
def test_smoke_ablation_end_to_end(tmp_path):
    """Two variants of the oracle at smoke scale: one evaluation artifact each, rows in config
    order with their overrides, the evaluation's ``latest`` unchanged, and a rerun reuses it
    all; the report shows the section."""
    from pipeline.stages.ablation import ablation
    from pipeline.stages.evaluate import evaluate

    base = smoke_overrides(tmp_path)  # the oracle needs no upstream artifact
    dev = evaluate(compose("evaluate", base + ["planner=oracle", "evaluate.split=dev"]))
    first = evaluate(compose("evaluate", base + ["planner=oracle"]))  # as make reproduce leaves it
    cfg = compose("ablation", base)
    # by default an execution variant runs for the DCNN alone, all_on also for the oracle
    assert list(cfg.ablation.planners) == ["dcnn"]
    assert list(cfg.ablation.variant_planners.all_on) == ["oracle", "dcnn"]
    cfg.ablation.planners = ["oracle"]  # the DCNN needs a network
    # all_on for the oracle alone; no_fallback_tier for no planner: no row
    cfg.ablation.variant_planners = {"all_on": ["oracle"], "no_fallback_tier": []}
    by_name = {str(v.name): v for v in cfg.ablation.variants}
    cfg.ablation.variants = [
        by_name["all_on"],
        by_name["no_fallback_tier"],
        by_name["no_path_check"],
    ]
    out = ablation(cfg, base)
    latest = tmp_path / "data" / "evaluate" / "latest"
    assert latest.resolve() == first.resolve()
    rows = json.loads((out / "ablation.json").read_text())
    assert [(r["planner"], r["variant"], r["overrides"]) for r in rows] == [
        ("oracle", "all_on", "-"),
        ("oracle", "no_path_check", "robot.path_check=false"),
    ]
    # all_on is the default evaluation on the dev heaps (the ablation never runs on test): the
    # same artifact, reused; the test evaluation is another
    assert rows[0]["evaluate_version"] == dev.name != first.name
    assert rows[1]["evaluate_version"] != first.name
    for name in ("ablation.csv", "log.rrd", "log.mcap"):
        assert (out / name).is_file()
    assert ablation(cfg, base) == out
