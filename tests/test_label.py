"""The labelling stage end to end on a tiny generated dataset."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import smoke_overrides

from pipeline.artifacts import load_manifest, verify_artifact
from pipeline.dataset import SceneDataset
from pipeline.dataset.labels import LabelSet
from pipeline.grasping.types import NG_REASONS, GraspClass
from pipeline.runtime.cli import compose
from pipeline.stages.generate import generate
from pipeline.stages.label import label
from pipeline.tracking import mcap_message_counts, rrd_entity_paths


def _cfg(stage, root, *extra):
    return compose(stage, smoke_overrides(root, *extra))


@pytest.fixture(scope="module")
def labelled(smoke_pipeline):
    """The session's smoke pipeline: (root, generation folder, label folder). Read-only."""
    return (
        smoke_pipeline.root,
        smoke_pipeline.artifact("generate"),
        smoke_pipeline.artifact("label"),
    )


def test_label_artifact(labelled):
    root, gen, folder = labelled
    manifest = load_manifest(folder)
    assert manifest["upstream"] == {"generate": gen.name}
    assert verify_artifact(folder) == []
    total = 0
    for split in ("train", "val", "test"):
        ds, labels = SceneDataset(gen, split), LabelSet(folder, split)
        assert len(labels) == len(ds)
        split_counts = np.zeros(4, int)
        for i in range(len(ds)):
            scene, rows = ds[i], labels[i]
            n = len(rows["instance"])
            total += n
            split_counts += np.bincount(rows["grasp_class"], minlength=4)
            assert (rows["scene_index"] == i).all()
            # Every grasp point lies on its own box in the instance mask.
            u, v = np.round(rows["uv"]).astype(int).T
            assert ((0 <= u) & (u < 416) & (0 <= v) & (v < 416)).all()
            # Graspable points lie on their own box in the instance mask; the others are NG.
            on_box = scene.mask[v, u] == rows["instance"]
            off = ~on_box & (rows["hand_class"] != GraspClass.NG)
            assert not off.any()
            # NG exactly when a reason is recorded; hand-level NG is "too_small",
            # "center_occluded" or "hold" (the hold check, hand.hold_check).
            assert ((rows["grasp_class"] == GraspClass.NG) == (rows["ng_reason"] > 0)).all()
            hand_ng = rows["hand_class"] == GraspClass.NG
            assert np.isin(
                rows["ng_reason"][hand_ng],
                [NG_REASONS.index(r) for r in ("too_small", "center_occluded", "hold")],
            ).all()
            # The robot check keeps the hand-level class or turns it NG, except that a B it
            # blocks becomes L or R where one cup passes (label.single_cup_fallback).
            kept = rows["grasp_class"] != GraspClass.NG
            same = rows["grasp_class"] == rows["hand_class"]
            one_cup = (rows["hand_class"] == GraspClass.B) & np.isin(
                rows["grasp_class"], [GraspClass.L, GraspClass.R]
            )
            assert (same | one_cup)[kept].all()
            # Normals face the camera and are unit length.
            assert (np.einsum("ij,ij->i", rows["normal_cam"], rows["center_cam"]) < 0).all()
            assert np.allclose(np.linalg.norm(rows["normal_cam"], axis=1), 1, atol=1e-5)
        metrics = manifest["metrics"]["splits"][split]
        assert [metrics["classes"][c.name] for c in GraspClass] == split_counts.tolist()
    assert total > 20
    acc = manifest["metrics"]["surface_accuracy"]
    assert acc["recall"] >= 0.95 and acc["precision"] >= 0.95
    assert acc["center_err_px_median"] < 3.0 and acc["normal_err_deg_median"] < 3.0


def test_label_logs(labelled):
    _, gen, folder = labelled
    entities = rrd_entity_paths(folder / "log.rrd")
    assert {
        "/world/camera/depth",
        "/world/camera/grasp_points",
        "/world/camera/surfaces",
        "/world/robot/links",
        "/world/robot/target_camera",
    } <= entities
    scenes = sum(len(SceneDataset(gen, s)) for s in ("train", "val", "test"))
    logged = min(scenes, compose("label", ["experiment=smoke"]).logging.max_logged_scenes)
    counts = mcap_message_counts(folder / "log.mcap")
    assert (
        counts["/world/camera/depth"] == logged and counts["/world/camera/grasp_points"] == logged
    )


def test_label_same_whatever_the_workers(smoke_pipeline, labelled, tmp_path):
    _, _, folder = labelled
    root = smoke_pipeline.copy(tmp_path / "root", tops=("data",)).root
    other = label(_cfg("label", root, "label.workers=2", "label.force=true"))
    assert other.name == folder.name
    a = load_manifest(folder)["files"]
    assert verify_artifact(other) == []
    # Same version, recomputed with two workers: every label file identical.
    b = load_manifest(other)["files"]
    assert {k: v for k, v in a.items() if k != "log.rrd"} == {
        k: v for k, v in b.items() if k != "log.rrd"
    }


def test_without_robot_checks_hand_classes_stand(smoke_pipeline, tmp_path):
    root = smoke_pipeline.copy(tmp_path / "root", tops=("data",)).root
    folder = label(_cfg("label", root, "label.robot_checks=false"))
    rows = LabelSet(folder, "train")[0]
    assert (rows["grasp_class"] == rows["hand_class"]).all()


def test_hand_config_matches_the_robot_urdf():
    from pipeline.robot import urdf_builder

    cfg = compose("label", ["experiment=smoke"])
    assert cfg.hand.cup_diameter == urdf_builder.CUP_DIAMETER
    assert cfg.hand.cup_offset == urdf_builder.CUP_OFFSET
    assert cfg.robot.home_camera_height == cfg.camera.height_above_bin_floor


def test_label_without_generation_says_what_to_do(tmp_path):
    from pipeline.artifacts.store import ArtifactError

    with pytest.raises(ArtifactError, match="make generate"):
        label(_cfg("label", tmp_path))


def test_robot_checks_use_the_generated_bin(tmp_path):
    """Labels must check collisions against the bin the scenes were generated in, even when the
    label command's own config names another bin."""
    import pybullet as p
    from omegaconf import OmegaConf

    from pipeline.labelling.robot_check import RobotChecker

    gen = generate(_cfg("generate", tmp_path, "bin.wall_height=0.10"))
    ds = SceneDataset(gen, "train")
    assert ds.bin.wall_height == pytest.approx(0.10)
    checker = RobotChecker(OmegaConf.to_object(compose("label", ["experiment=smoke"])))
    checker.set_scene(ds[0], ds.bin)
    wall = checker.obstacles[2]  # build_cell order: ground, floor, walls
    top = p.getAABB(wall, physicsClientId=checker.client)[1][2]
    assert top == pytest.approx(0.10, abs=0.002)
