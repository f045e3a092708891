"""The noisy pipeline and the robustness study (pipeline/stages/robustness.py).

The study's comparisons rest on three properties checked here: the noisy generation holds the
clean generation's heaps (its ``depth_clean`` equals the clean run's ``depth`` byte for byte),
labels come from the ideal depth (so both pipelines' labels are identical), and the closed
loop draws the sensor's noise from a stream of its own (same heaps, same plans' draws).
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from omegaconf import OmegaConf

from pipeline.dataset import SceneDataset
from pipeline.dataset.storage import read_npz
from pipeline.runtime.cli import compose
from pipeline.stages.robustness import depth_getter


@pytest.fixture(scope="module")
def pipelines(smoke_pipeline, smoke_pipelines):
    """{"clean" | "noisy": (generation folder, label folder)}: the session's smoke pipeline and
    the same heaps rendered through the SR300 model."""
    noisy = smoke_pipelines("sensor=sr300", stages=("generate", "label"))
    return {
        kind: (root.artifact("generate"), root.artifact("label"))
        for kind, root in (("clean", smoke_pipeline), ("noisy", noisy))
    }


def test_noisy_generation_holds_the_clean_heaps(pipelines):
    (gen_c, _), (gen_n, _) = pipelines["clean"], pipelines["noisy"]
    assert gen_c.name != gen_n.name
    cam_c = json.loads((gen_c / "camera.json").read_text())
    cam_n = json.loads((gen_n / "camera.json").read_text())
    assert cam_c["sensor"]["enabled"] is False and cam_n["sensor"]["name"] == "sr300"
    for split in ("train", "val", "test"):
        a, b = SceneDataset(gen_c, split), SceneDataset(gen_n, split)
        assert len(a) == len(b)
        for i in range(len(a)):
            sa, sb = a[i], b[i]
            # the clean run has no second column: depth_clean_m is its depth itself
            assert sa.depth_clean_m is sa.depth_m
            np.testing.assert_array_equal(sb.depth_clean_m, sa.depth_m)
            np.testing.assert_array_equal(sb.mask, sa.mask)
            assert [bx.type_index for bx in sb.boxes] == [bx.type_index for bx in sa.boxes]
            np.testing.assert_array_equal(
                np.stack([bx.T_world_box for bx in sb.boxes]),
                np.stack([bx.T_world_box for bx in sa.boxes]),
            )
            # the sensor's depth: holes where the ideal depth had data, noise elsewhere
            lost = (sb.depth_m == 0) & (sa.depth_m > 0)
            assert 0.01 < lost.mean() < 0.5
            both = (sb.depth_m > 0) & (sa.depth_m > 0)
            err = (sb.depth_m - sa.depth_m)[both]
            assert 0.0005 < float(np.std(err)) < 0.01  # ~1.5 mm (conf/sensor/sr300.yaml)
    shard = read_npz(next((gen_c / "scenes").glob("*.npz")))
    assert "depth_clean" not in shard  # only stored with a sensor model


def test_labels_come_from_the_ideal_depth(pipelines):
    (_, lab_c), (_, lab_n) = pipelines["clean"], pipelines["noisy"]
    files_c = sorted((lab_c / "labels").glob("*.npz"))
    files_n = sorted((lab_n / "labels").glob("*.npz"))
    assert [f.name for f in files_c] == [f.name for f in files_n] and files_c
    for fc, fn in zip(files_c, files_n):
        a, b = read_npz(fc), read_npz(fn)
        assert sorted(a) == sorted(b)
        for k in a:
            np.testing.assert_array_equal(a[k], b[k], err_msg=f"{fn.name}: {k}")


def test_depth_getter_inputs(pipelines):
    gen_n, _ = pipelines["noisy"]
    scene = SceneDataset(gen_n, "test")[0]
    assert depth_getter("ideal")(scene) is scene.depth_clean_m
    assert depth_getter("sensor")(scene) is scene.depth_m
    filled = depth_getter("sensor+fill")(scene)
    assert (filled == 0).sum() < (scene.depth_m == 0).sum()
    assert np.array_equal(filled[scene.depth_m > 0], scene.depth_m[scene.depth_m > 0])
    for bad, hint in (
        ("noisy", "ideal, sensor or sensor"),
        ("sensor+blur", "choose from"),
        ("ideal+fill", "ideal, sensor or sensor"),
    ):
        with pytest.raises(ValueError, match=hint):
            depth_getter(bad)


def test_bad_variant_model_is_refused_before_any_work(tmp_path):
    from pipeline.stages.robustness import robustness

    cfg = compose("robustness", ["experiment=smoke", f"paths.root={tmp_path}"])
    cfg.robustness.policies[1].model = "dirty"
    with pytest.raises(ValueError, match="use clean .* or noisy"):
        robustness(cfg, ["experiment=smoke", f"paths.root={tmp_path}"])
    assert not (tmp_path / "data").exists()


def test_closed_loop_sensor_stream_keeps_the_heaps():
    """With sensor=sr300 the evaluation's heaps are the noise-free run's: the sensor draws
    from its own stream (seed, 41, trial), not from the heap's or the plans' generators."""
    from pipeline.world.trial import HEAP_STREAMS

    HEAP_SEED = HEAP_STREAMS["dev"][0]
    from pipeline.robot.model import Robot, robot_config
    from pipeline.world.cell import PickCell

    poses = {}
    for sensor in ("ideal", "sr300"):
        cfg = OmegaConf.to_object(compose("evaluate", ["experiment=smoke", f"sensor={sensor}"]))
        cell = PickCell(cfg, lambda cfg=cfg: Robot(robot_config(cfg)))
        cell.reset(np.random.default_rng([0, HEAP_SEED, 0]), 3)
        cell.sensor_rng = np.random.default_rng([0, 41, 0])
        frame = cell.render()
        poses[sensor] = sorted(cell.boxes)
        if sensor == "sr300":
            assert (frame.depth_m == 0).mean() > 0.01  # holes: the model is applied
            cell.sensor_rng = None
            with pytest.raises(ValueError, match="sensor_rng"):
                cell.render()
        else:
            assert (frame.depth_m > 0).all()
    assert poses["ideal"] == poses["sr300"]


@pytest.mark.slow
def test_smoke_study_end_to_end(smoke_pipeline, tmp_path):
    """The whole study at smoke scale, two closed-loop variants and two policies: the clean
    pipeline read as `make reproduce` leaves it, the noisy one built; tables, artifacts reused
    across variants, upstream versions."""
    from conftest import smoke_overrides

    from pipeline.artifacts import ArtifactError
    from pipeline.stages.baseline import baseline
    from pipeline.stages.robustness import robustness

    empty = smoke_overrides(tmp_path / "empty")
    with pytest.raises(ArtifactError, match="robustness.train_version"):
        robustness(compose("robustness", empty), empty)  # nothing trained yet
    assert not (tmp_path / "empty" / "data").exists()  # refused before any work
    smoke = smoke_pipeline.copy(tmp_path / "root")
    base = smoke_overrides(smoke.root, "baseline.epochs=1")
    baseline(compose("baseline", base))  # as make reproduce runs it before the study
    cfg = compose("robustness", base)
    rc = cfg.robustness
    rc.closed_loop = [rc.closed_loop[0], rc.closed_loop[3]]  # clean_ideal, noisy_sensor
    rc.policies = [rc.policies[0], rc.policies[2]]  # paper (= clean_ideal), area_check
    rc.table1_inputs = ["ideal", "sensor", "sensor+fill_median"]
    rc.table2_inputs = ["ideal", "sensor"]
    latest = {s: smoke.artifact(s) for s in ("generate", "label", "train", "baseline")}
    out = robustness(cfg, base)
    # the study reads the clean pipeline and leaves every `latest` where it was
    assert {s: smoke.artifact(s) for s in latest} == latest
    study = json.loads((out / "robustness.json").read_text())
    assert [(r["model"], r["input"]) for r in study["table1"]] == [
        (m, i) for m in ("clean", "noisy") for i in ("ideal", "sensor", "sensor+fill_median")
    ]
    planners = {r["planner"] for r in study["table2"]}
    assert {"dcnn_clean", "dcnn_noisy", "gqcnn"} <= planners
    cl = {r["variant"]: r for r in study["closed_loop"]}
    assert list(cl) == ["clean_ideal", "noisy_sensor", "paper", "area_check"]
    # the paper policy is the clean_ideal run itself: the same evaluation artifact, reused
    assert cl["paper"]["evaluate_version"] == cl["clean_ideal"]["evaluate_version"]
    assert cl["noisy_sensor"]["evaluate_version"] != cl["clean_ideal"]["evaluate_version"]
    manifest = json.loads((out / "manifest.json").read_text())
    up = manifest["upstream"]
    for key in (
        "generate_clean",
        "generate_noisy",
        "label_clean",
        "label_noisy",
        "train_clean",
        "train_noisy",
        "baseline",
        "evaluate_clean_ideal",
        "evaluate_noisy_sensor",
    ):
        assert key in up, key
    for key, stage in (
        ("generate_clean", "generate"),
        ("label_clean", "label"),
        ("train_clean", "train"),
        ("baseline", "baseline"),
    ):
        assert up[key] == latest[stage].name, key
    for name in ("table1.csv", "table2.csv", "closed_loop.csv", "log.rrd", "log.mcap"):
        assert (out / name).is_file()
    # a rerun reuses everything: the same artifact, no stage run again
    assert robustness(cfg, base) == out


def test_noisy_model_needs_the_noisy_network(tmp_path):
    from pipeline.stages.robustness import robustness

    base = ["experiment=smoke", f"paths.root={tmp_path}", "robustness.noisy_network=false"]
    cfg = compose("robustness", base)
    assert any(str(v.model) == "noisy" for v in cfg.robustness.closed_loop)
    with pytest.raises(ValueError, match="noisy_network is false"):
        robustness(cfg, base)
    assert not (tmp_path / "data").exists()


@pytest.mark.slow
def test_one_network_study(smoke_pipeline, tmp_path):
    """robustness.noisy_network=false: no second network; the noisy generation holds the test
    split only; Tables 1 and 2 and every closed-loop row measure the network under test."""
    from conftest import smoke_overrides

    from pipeline.artifacts import load_manifest
    from pipeline.stages.baseline import baseline
    from pipeline.stages.robustness import robustness

    smoke = smoke_pipeline.copy(tmp_path / "root")
    base = smoke_overrides(smoke.root, "baseline.epochs=1", "robustness.noisy_network=false")
    baseline(compose("baseline", base))
    cfg = compose("robustness", base)
    rc = cfg.robustness
    rc.closed_loop = [rc.closed_loop[0], rc.closed_loop[2]]  # clean_ideal, clean_sensor
    rc.policies = [rc.policies[0]]
    rc.table1_inputs = ["ideal", "sensor"]
    rc.table2_inputs = ["sensor"]
    out = robustness(cfg, base)
    study = json.loads((out / "robustness.json").read_text())
    up = load_manifest(out)["upstream"]
    assert "train_noisy" not in up
    gen = load_manifest(smoke.root / "data" / "generate" / up["generate_noisy"])
    assert gen["config"]["generate"]["num_scenes"] == 0
    assert gen["config"]["sensor"]["name"] == "sr300"
    assert {r["model"] for r in study["table1"]} == {"clean"}
    assert {r["planner"] for r in study["table2"]} >= {"dcnn_clean"}
    assert "dcnn_noisy" not in {r["planner"] for r in study["table2"]}
    assert [r["variant"] for r in study["closed_loop"]] == ["clean_ideal", "clean_sensor", "paper"]
