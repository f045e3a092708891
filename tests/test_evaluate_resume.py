"""An interrupted evaluation resumes: the trials it finished are kept (one JSON record each in the
work folder's resume data) and only the rest are run, and the artifact equals an uninterrupted
run's. A trial's record reads back to the same result, field for field."""

from __future__ import annotations

import json

import pytest

import pipeline.stages.evaluate as evaluate_mod
from pipeline.artifacts.locking import TMP_PREFIX
from pipeline.artifacts.store import STATE_DIR, load_manifest
from pipeline.runtime.cli import compose
from pipeline.tools.repro_check import compare_artifacts
from pipeline.world.trial import Attempt, TrialResult

VOLATILE = ("created", "timings")


def _cfg(root, *extra):
    """Two trials of one box each with the analytic Dex-Net-style planner (no trained model),
    in one process, none of them logged: both are kept when finished."""
    return compose(
        "evaluate",
        [
            "experiment=smoke",
            f"paths.root={root}",
            "logging.progress=false",
            "planner=dexnet",
            "evaluate.dexnet_variant=planarity",
            "evaluate.boxes_per_trial=1",
            "evaluate.max_attempts_per_trial=2",
            "evaluate.num_trials=2",
            "evaluate.workers=1",
            *extra,
        ],
    )


def _interrupted_at_second_trial(root, monkeypatch, *extra):
    """Run the evaluation in ``root``, interrupted (Ctrl-C) while its second trial runs; the
    work folder it leaves."""
    run_task = evaluate_mod.run_task

    def interrupt_second(task):
        if task.trial == 1:
            raise KeyboardInterrupt
        return run_task(task)

    with monkeypatch.context() as m:
        m.setattr(evaluate_mod, "run_task", interrupt_second)
        with pytest.raises(KeyboardInterrupt):
            evaluate_mod.evaluate(_cfg(root, *extra))
    (work,) = (root / "data" / "evaluate").glob(f"{TMP_PREFIX}*")
    return work


def test_trial_record_reads_back_to_the_same_result():
    a = Attempt(3, 0, "dcnn", "B", [10.5, 20.25], target_body=7, target_type="medium")
    a.outcome, a.final_error, a.path_deviation_m = "dropped", [0.001, float("nan")], None
    r = TrialResult(3, "dcnn", 12, 11, "no_grasp", [a], no_grasp={"rejected": {"ik": 2}})
    back = TrialResult.from_record(json.loads(json.dumps(r.to_record())))
    assert repr(back) == repr(r)  # NaN compares unequal to itself; its repr does not
    logged = TrialResult(0, "dcnn", 12, 12, "bin_empty", [], trace=[{"step": 0}])
    with pytest.raises(ValueError, match="log data"):
        logged.to_record()


def test_interrupted_evaluation_resumes_to_the_same_artifact(tmp_path, monkeypatch, capsys):
    reference = evaluate_mod.evaluate(_cfg(tmp_path / "reference", "evaluate.log_trials=0"))

    # Interrupted (Ctrl-C) while the second trial runs: the first is kept, then a rerun
    # runs the second only.
    root = tmp_path / "resumed"
    run_task = evaluate_mod.run_task
    work = _interrupted_at_second_trial(root, monkeypatch, "evaluate.log_trials=0")
    assert [p.name for p in (work / STATE_DIR / "trials").iterdir()] == ["000000.json"]

    ran = []
    monkeypatch.setattr(evaluate_mod, "run_task", lambda task: ran.append(task) or run_task(task))
    capsys.readouterr()
    resumed = evaluate_mod.evaluate(_cfg(root, "evaluate.log_trials=0"))
    assert "resuming: 1 of 2 trials already run" in capsys.readouterr().out
    assert [(t.planner, t.trial) for t in ran] == [("dexnet", 1)]
    assert resumed.name == reference.name
    assert compare_artifacts("evaluate", reference, resumed) == []
    a, b = load_manifest(reference), load_manifest(resumed)
    assert b["timings"]["trials_resumed"] == 1
    for m in (a, b):
        for key in VOLATILE:
            m.pop(key)
        # Rerun logs are not byte-stable; compare_artifacts compared them by content.
        m["files"] = {k: v for k, v in m["files"].items() if not k.endswith(".rrd")}
    assert a == b
    assert not (resumed / STATE_DIR).exists()
    assert [p.name for p in resumed.parent.iterdir() if p.name.startswith(TMP_PREFIX)] == []


def test_unreadable_or_logged_trials_are_run_again(tmp_path, monkeypatch, capsys):
    """A trial record that is cut short is run again, and so is a logged trial, whose log
    data is not kept."""
    root = tmp_path / "root"
    run_task = evaluate_mod.run_task
    work = _interrupted_at_second_trial(root, monkeypatch, "evaluate.log_trials=1")
    assert not (work / STATE_DIR / "trials").exists()  # trial 0 was logged: not kept

    # A record cut short (as if written by other means: the stage writes them atomically).
    (work / STATE_DIR / "trials").mkdir(parents=True)
    (work / STATE_DIR / "trials" / "000001.json").write_text('{"result": {"trial"')
    ran = []
    monkeypatch.setattr(evaluate_mod, "run_task", lambda task: ran.append(task) or run_task(task))
    capsys.readouterr()
    out = evaluate_mod.evaluate(_cfg(root, "evaluate.log_trials=1"))
    assert "resuming: 0 of 2 trials already run" in capsys.readouterr().out
    assert [t.trial for t in ran] == [0, 1]
    assert len(json.loads((out / "trials.json").read_text())) == 2
