"""The training stage, the planner, the flip augmentation and the Table 1 precision."""

from __future__ import annotations

import shutil

import numpy as np
import pytest
import torch
from conftest import conf_section, smoke_overrides

from pipeline.artifacts import load_manifest, verify_artifact
from pipeline.artifacts.fingerprint import sha256_file
from pipeline.camera.geometry import Intrinsics
from pipeline.config.physical import HandConfig
from pipeline.grasping.hand import hand_label
from pipeline.grasping.types import GraspClass, Surface
from pipeline.planner.augment import flip_image, flip_rows
from pipeline.planner.evaluate import ImagePredictions, match_image, precision_table
from pipeline.planner.planner import Planner
from pipeline.runtime.cli import compose
from pipeline.stages.train import RESUME_PREFIX, train
from pipeline.tracking import rrd_entity_paths, rrd_timelines

R, L, B, NG = (int(c) for c in GraspClass)


def _cfg(stage, root, *extra):
    return compose(stage, smoke_overrides(root, *extra))


@pytest.fixture(scope="module")
def labelled_root(smoke_pipeline):
    """The session's smoke pipeline (read-only: training on it again reuses its artifact)."""
    return smoke_pipeline.root


def _fresh_models(root, name):
    """A scratch copy of the data with its own models/ folder (beside ``root``)."""
    other = root.parent / f"{root.name}-{name}"
    if other.exists():
        shutil.rmtree(other)
    shutil.copytree(root / "data", other / "data", symlinks=True)
    return other


def test_train_end_to_end_and_deterministic(labelled_root):
    folder = train(_cfg("train", labelled_root))
    assert verify_artifact(folder) == []
    manifest = load_manifest(folder)
    assert set(manifest["upstream"]) == {"label", "generate"}
    m = manifest["metrics"]
    assert m["network"]["parameters"] > 0 and m["network"]["macs_per_image"] > 0
    assert 0 <= m["one_point_per_cell"]["lost_fraction"] < 1
    assert len(m["train_loss_per_epoch"]) == 1 and np.isfinite(m["train_loss_per_epoch"][0])
    assert {"top1", "top1pct", "top5pct", "top10pct"} <= set(m["table1"])
    assert (folder / "pr_curve.csv").is_file()
    blob = torch.load(folder / "model.pt", weights_only=True)
    assert blob["network"]["width"] == 0.0625
    ckpt = torch.load(folder / "checkpoint.pt", weights_only=True)
    assert ckpt["epoch"] == 1 and "optimizer" in ckpt
    assert {
        "/train/step/loss",
        "/train/epoch/loss",
        "/samples/camera/depth",
        "/samples/camera/predicted",
    } <= rrd_entity_paths(folder / "log.rrd")
    assert {"step", "epoch"} <= rrd_timelines(folder / "log.rrd")

    # Same config, fresh models folder (no resume checkpoint): byte-identical weights.
    other = _fresh_models(labelled_root, "train-repeat")
    again = train(_cfg("train", other))
    assert again.name == folder.name
    assert sha256_file(again / "model.pt") == sha256_file(folder / "model.pt")


def test_resume_matches_uninterrupted(labelled_root):
    resumed_root = _fresh_models(labelled_root, "train-resume")
    train(_cfg("train", resumed_root, "train.epochs=1"))
    assert list((resumed_root / "models" / "train").glob(RESUME_PREFIX + "*/checkpoint.pt"))
    resumed = train(_cfg("train", resumed_root, "train.epochs=2"))  # continues from epoch 1
    fresh_root = _fresh_models(labelled_root, "train-fresh")
    fresh = train(_cfg("train", fresh_root, "train.epochs=2"))
    assert resumed.name == fresh.name
    assert sha256_file(resumed / "model.pt") == sha256_file(fresh / "model.pt")
    assert (
        load_manifest(resumed)["metrics"]["train_loss_per_epoch"]
        == load_manifest(fresh)["metrics"]["train_loss_per_epoch"]
    )
    assert load_manifest(resumed)["timings"]["epochs_run_here"] == 1


ONECYCLE = ("train.schedule.name=onecycle", "train.patience=0")


def test_a_bad_schedule_is_refused_before_any_folder(labelled_root):
    root = _fresh_models(labelled_root, "bad-schedule")
    with pytest.raises(ValueError, match="train.schedule.name='cyclic'"):
        train(_cfg("train", root, "train.schedule.name=cyclic"))
    assert not (root / "models").exists()  # no resume folder named by the bad name


def test_onecycle_resumes_on_the_same_curve(labelled_root, monkeypatch):
    fresh = train(
        _cfg("train", _fresh_models(labelled_root, "oc-fresh"), "train.epochs=2", *ONECYCLE)
    )
    # A run killed after its first epoch (the checkpoint of epoch 1 written) ...
    root = _fresh_models(labelled_root, "oc-killed")
    real = __import__("pipeline.planner.fit", fromlist=["should_stop"]).should_stop

    def crash_after_one(val_loss, patience):
        if len(val_loss) == 1:
            raise KeyboardInterrupt
        return real(val_loss, patience)

    monkeypatch.setattr("pipeline.planner.fit.should_stop", crash_after_one)
    with pytest.raises(KeyboardInterrupt):
        train(_cfg("train", root, "train.epochs=2", *ONECYCLE))
    monkeypatch.setattr("pipeline.planner.fit.should_stop", real)
    # ... continues on the same learning-rate curve and writes the same weights
    resumed = train(_cfg("train", root, "train.epochs=2", *ONECYCLE))
    assert load_manifest(resumed)["timings"]["epochs_run_here"] == 1
    assert sha256_file(resumed / "model.pt") == sha256_file(fresh / "model.pt")
    # The curve depends on the epoch budget: a 1-epoch run is not resumed by a 2-epoch one.
    other = _fresh_models(labelled_root, "oc-budget")
    train(_cfg("train", other, "train.epochs=1", *ONECYCLE))
    again = train(_cfg("train", other, "train.epochs=2", *ONECYCLE))
    assert load_manifest(again)["timings"]["epochs_run_here"] == 2
    assert sha256_file(again / "model.pt") == sha256_file(fresh / "model.pt")


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA GPU")
def test_train_on_cuda(labelled_root):
    """The smoke training on a GPU: its own version (the device type is part of the key), a
    verified artifact whose model plans on the CPU, and a finite loss."""
    root = _fresh_models(labelled_root, "train-cuda")
    folder = train(_cfg("train", root, "train.device=cuda"))
    assert verify_artifact(folder) == []
    manifest = load_manifest(folder)
    assert manifest["config"]["train"]["device_type"] == "cuda"
    assert folder.name != train(_cfg("train", labelled_root)).name  # the CPU artifact
    assert np.isfinite(manifest["metrics"]["train_loss_per_epoch"]).all()
    planner = Planner.load(folder, device="cpu")
    assert planner.predict(np.full((1, 416, 416), 0.6, np.float32)).shape == (1, 6, 13, 13)


def test_planner_load_and_plan(labelled_root):
    from pipeline.dataset import SceneDataset

    folder = train(_cfg("train", labelled_root))  # reuses the artifact
    planner = Planner.load(folder)
    gen = sorted(
        p
        for p in (labelled_root / "data" / "generate").iterdir()
        if not p.name.startswith((".", "latest"))
    )[0]
    scene = SceneDataset(gen, "test")[0]
    planner.ranking.threshold = 0.0  # an untrained smoke net is never confident
    cands = planner.plan(scene.depth_m, scene.intrinsics)
    assert all(c.grasp_class != GraspClass.NG for c in cands)
    scores = [c.score for c in cands]
    assert scores == sorted(scores, reverse=True)
    raw = planner.predict(np.stack([scene.depth_m, scene.depth_m]))
    assert raw.shape == (2, 6, 13, 13)
    with pytest.raises(ValueError, match="416"):
        planner.plan(scene.depth_m[:400], scene.intrinsics)
    with pytest.raises(ValueError, match="dtype"):
        planner.plan((scene.depth_m * 1e4).astype(np.uint16), scene.intrinsics)


# ----------------------------------------------------------------------------- flips

INTR = Intrinsics(416, 416, 411.7, 411.7, 207.5, 207.5)


def _face(tilt_deg: float, mirror=(1.0, 1.0, 1.0)) -> Surface:
    """A 0.06 × 0.03 m face (one cup fits, two do not), long axis along camera x, normal tilted
    by ``tilt_deg`` about camera x, optionally mirrored."""
    m = np.asarray(mirror)
    t = np.radians(tilt_deg)
    n = np.array([0.0, -np.sin(t), -np.cos(t)]) * m
    long = np.array([1.0, 0.0, 0.0]) * m
    c = np.array([0.02, 0.01, 0.5]) * m
    return Surface(
        instance=1,
        center_cam=c,
        normal_cam=n,
        long_axis_cam=long,
        short_axis_cam=np.cross(n, long),
        long_length=0.06,
        short_length=0.03,
        center_px=np.array([224.0, 216.0]),
        num_points=500,
        area=0.0018,
    )


def _rows(surface: Surface, hand: HandConfig) -> dict:
    h = hand_label(surface, hand)
    return {
        "uv": surface.center_px[None].astype(np.float32),
        "center_cam": surface.center_cam[None].astype(np.float32),
        "normal_cam": surface.normal_cam[None].astype(np.float32),
        "x_axis_cam": h.x_axis_cam[None].astype(np.float32),
        "grasp_class": np.array([int(h.grasp_class)], np.int8),
    }


def test_flip_labels_hand_cases():
    hand = conf_section("hand")
    tilted = _rows(_face(-20.0), hand)  # the R camera centre is ~2.4 cm higher
    assert tilted["grasp_class"][0] == R
    v = flip_rows(tilted, "v", INTR, hand)
    assert v["grasp_class"][0] == L  # a vertical mirror swaps the cups
    assert np.allclose(v["uv"][0], [224.0, 415.0 - 216.0])
    # ... and agrees with labelling the mirrored face from scratch
    assert hand_label(_face(-20.0, (1, -1, 1)), hand).grasp_class == GraspClass.L
    # A horizontal mirror keeps L and R (module docstring of pipeline.planner.augment).
    u = flip_rows(tilted, "u", INTR, hand)
    assert u["grasp_class"][0] == R
    assert hand_label(_face(-20.0, (-1, 1, 1)), hand).grasp_class == GraspClass.R
    assert np.allclose(u["uv"][0], [415.0 - 224.0, 216.0])
    # A level face is a tie (|z_L − z_R| < tie_tolerance) → L, and stays L under any flip.
    level = _rows(_face(0.0), hand)
    assert level["grasp_class"][0] == L
    for flip in ("u", "v", "uv"):
        assert flip_rows(level, flip, INTR, hand)["grasp_class"][0] == L
    # B and NG are kept.
    other = dict(tilted, grasp_class=np.array([B], np.int8))
    assert flip_rows(other, "v", INTR, hand)["grasp_class"][0] == B
    img = np.arange(6.0).reshape(2, 3)
    assert (flip_image(img, "u") == img[:, ::-1]).all()
    assert (flip_image(img, "v") == img[::-1]).all()
    with pytest.raises(ValueError, match="principal point"):
        flip_rows(tilted, "u", Intrinsics(416, 416, 411.7, 411.7, 200.0, 207.5), hand)


# ----------------------------------------------------------------------------- Table 1


def test_precision_hand_made():
    # Image A: gt L at (100, 100), R at (300, 300).
    #   p1 L (105, 100) 0.9  → correct (5 px from the L)
    #   p2 L (102, 100) 0.8  → wrong (that L is already matched)
    #   p3 R (300, 320) 0.7  → wrong (20 px > 16 px)
    #   p4 NG (300, 300) 0.95 → not a prediction
    # Image B: gt B at (50, 50).
    #   p5 B (60, 50) 0.6    → correct
    a = ImagePredictions(
        uv=np.array([[105, 100], [102, 100], [300, 320], [300, 300]]),
        classes=np.array([L, L, R, NG]),
        scores=np.array([0.9, 0.8, 0.7, 0.95]),
        gt_uv=np.array([[100, 100], [300, 300]]),
        gt_classes=np.array([L, R]),
    )
    b = ImagePredictions(
        uv=np.array([[60, 50]]),
        classes=np.array([B]),
        scores=np.array([0.6]),
        gt_uv=np.array([[50, 50]]),
        gt_classes=np.array([B]),
    )
    assert match_image(a, 16.0).tolist() == [True, False, False, False]
    t = precision_table([a, b], 16.0)
    # Pooled ranking (4 predictions): 0.9 ✓, 0.8 ✗, 0.7 ✗, 0.6 ✓.
    assert t["num_predictions"] == 4 and t["num_ground_truth"] == 3
    assert t["top1"] == 1.0  # both images' best prediction is correct
    # ceil(1 % · 4) = ceil(5 % · 4) = ceil(10 % · 4) = 1 prediction: the 0.9 one, correct.
    assert t["top1pct"] == t["top5pct"] == t["top10pct"] == 1.0
    assert np.allclose(t["pr_curve"]["precision"], [1, 1 / 2, 1 / 3, 2 / 4])
    assert np.allclose(t["pr_curve"]["recall"], [1 / 3, 1 / 3, 1 / 3, 2 / 3])
    # A wrong class at the right place is wrong.
    c = ImagePredictions(
        uv=np.array([[100, 100]]),
        classes=np.array([R]),
        scores=np.array([0.9]),
        gt_uv=np.array([[100, 100]]),
        gt_classes=np.array([L]),
    )
    assert precision_table([c], 16.0)["top1"] == 0.0
