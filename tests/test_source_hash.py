"""A stage's version covers the source it depends on (its import closure), not all of pipeline/."""

from pipeline.artifacts.fingerprint import import_closure, source_hash


def test_generation_depends_on_the_simulator_not_on_the_planners():
    closure = import_closure("pipeline.generate")
    assert {"pipeline.generate", "pipeline.simulation.heap", "pipeline.camera.render",
            "pipeline.dataset.storage"} <= set(closure)
    assert not any(m.startswith(("pipeline.planner", "pipeline.dexnet", "pipeline.labelling"))
                   for m in closure)


def test_imports_inside_functions_count():
    # pipeline.label imports the robot checker inside a function (lazily).
    assert "pipeline.labelling.robot_check" in import_closure("pipeline.label")


def test_stage_hashes_differ_and_are_stable():
    hashes = {s: source_hash(s) for s in ("generate", "label", "train", "baseline", "report")}
    assert len(set(hashes.values())) == len(hashes)
    assert source_hash("generate") == hashes["generate"]
    assert source_hash() not in hashes.values()  # the whole package
