"""A stage's version covers the source it depends on (its import closure), not all of pipeline/."""

from pipeline.artifacts.fingerprint import import_closure, source_hash, stage_module


def test_generation_depends_on_the_simulator_not_on_the_planners():
    closure = import_closure("pipeline.stages.generate")
    assert {
        "pipeline.stages.generate",
        "pipeline.simulation.heap",
        "pipeline.camera.render",
        "pipeline.dataset.storage",
    } <= set(closure)
    assert not any(
        m.startswith(("pipeline.planner", "pipeline.dexnet", "pipeline.labelling")) for m in closure
    )


def test_imports_inside_functions_count():
    # pipeline.stages.label imports the robot checker inside a function (lazily).
    assert "pipeline.labelling.robot_check" in import_closure("pipeline.stages.label")


STAGES = ("generate", "label", "train", "baseline", "evaluate", "unseen", "ablation", "robustness")


def test_no_stage_module_is_a_library():
    """A stage's version depends on the code it runs: no stage imports another stage's module,
    except the ablation, which runs the evaluate stage itself once per variant."""
    runs_as_stage = {("ablation", "evaluate")}
    for stage in STAGES:
        imported = {
            m.rpartition(".")[2]
            for m in import_closure(stage_module(stage))
            if m.startswith("pipeline.stages.")
        } & set(STAGES) - {stage}
        assert {(stage, other) for other in imported} <= runs_as_stage, (stage, imported)


def test_stage_hashes_differ_and_are_stable():
    hashes = {s: source_hash(s) for s in ("generate", "label", "train", "baseline", "report")}
    assert len(set(hashes.values())) == len(hashes)
    assert source_hash("generate") == hashes["generate"]
    assert source_hash() not in hashes.values()  # the whole package


def test_executor_is_plumbing(tmp_path, monkeypatch):
    """Where shards run (pipeline.runtime.executor) does not change a result: not in the source
    hash."""
    import shutil

    from pipeline.artifacts import fingerprint

    root = tmp_path / "pipeline"
    shutil.copytree(fingerprint.PACKAGE_ROOT, root, ignore=shutil.ignore_patterns("__pycache__"))
    monkeypatch.setattr(fingerprint, "PACKAGE_ROOT", root)

    def hashes():
        fingerprint.import_closure.cache_clear()
        fingerprint.source_hash.cache_clear()
        return {s: source_hash(s) for s in ("generate", "label")}

    try:
        assert "pipeline.runtime.executor" in import_closure("pipeline.stages.generate")
        before = hashes()
        with open(root / "runtime" / "executor.py", "a") as f:
            f.write("\n# an edit\n")
        assert hashes() == before
        with open(root / "stages" / "generate.py", "a") as f:
            f.write("\n# an edit\n")
        assert hashes()["generate"] != before["generate"]
    finally:
        monkeypatch.undo()
        fingerprint.import_closure.cache_clear()
        fingerprint.source_hash.cache_clear()
