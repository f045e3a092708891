"""The generation stage: reproducibility, versioning, atomicity, logs, the loader."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pybullet as p
import pytest
from hydra.errors import ConfigCompositionException
from omegaconf import OmegaConf

from pipeline.artifacts import compute_version, load_manifest, stage_config, verify_artifact
from pipeline.artifacts.store import ArtifactError, resolve_artifact
from pipeline.camera.geometry import backproject
from pipeline.dataset import SceneDataset
from pipeline.runtime.cli import compose
from pipeline.simulation.heap import corner_drift, settle
from pipeline.simulation.scene import connect, scene_rng, simulate_scene
from pipeline.stages.generate import NOT_AFFECTING_RESULT, SECTIONS, generate
from pipeline.tracking import mcap_message_counts, rrd_entity_paths

TINY = (
    "generate.num_scenes=3",
    "generate.num_val_scenes=1",
    "generate.num_test_scenes=1",
    "generate.scenes_per_shard=2",
)


@pytest.fixture(scope="module")
def client():
    c = connect()
    yield c
    p.disconnect(c)


@pytest.fixture(scope="module")
def sim_cfg():
    return OmegaConf.to_object(compose("generate", ["experiment=smoke"]))


def test_same_seed_same_scene(client, sim_cfg):
    a = simulate_scene(client, sim_cfg, scene_rng(0, 0, 7))
    simulate_scene(client, sim_cfg, scene_rng(0, 0, 8))  # disturb the client's state
    b = simulate_scene(client, sim_cfg, scene_rng(0, 0, 7))
    assert np.array_equal(a.depth_m, b.depth_m)
    assert np.array_equal(a.mask, b.mask)
    c = simulate_scene(client, sim_cfg, scene_rng(0, 1, 7))  # same index, other split
    assert not np.array_equal(a.depth_m, c.depth_m)


def test_heap_really_at_rest(client, sim_cfg):
    """After the rest criterion fires, another second of simulation moves no box corner > 2 mm."""
    for index in range(3):
        scene = simulate_scene(client, sim_cfg, scene_rng(5, 0, index))
        drift = corner_drift(client, [b.body_id for b in scene.boxes], 240)
        assert scene.settled
        assert (drift < 0.002).all(), drift


@pytest.mark.slow
def test_heaps_of_20_really_at_rest(client, sim_cfg):
    """24 heaps of 20 boxes (the bench's rest check, same seeds): after the rest criterion
    fires, one more simulated second moves no corner of any box by more than 2 mm."""
    from pipeline.cell.bin import build_cell
    from pipeline.simulation.heap import drop_heap
    from pipeline.tools.bench.common import rest_check_rng

    boxes = dataclasses.replace(sim_cfg.boxes, min_count=20, max_count=20)
    one_second = int(round(1.0 / sim_cfg.physics.time_step))
    worst = {}
    for i in range(24):
        build_cell(client, sim_cfg.bin, sim_cfg.physics)
        heap = drop_heap(client, rest_check_rng(i), boxes, sim_cfg.bin, sim_cfg.physics)
        assert heap.settled, f"heap {i} hit the step cap"
        worst[i] = float(corner_drift(client, [b.body_id for b in heap.boxes], one_second).max())
    moving = {i: round(1000 * d, 2) for i, d in worst.items() if d > 0.002}
    assert not moving, f"heaps whose corners moved more than 2 mm (mm): {moving}"


def test_settle_declares_rest_by_displacement_over_a_window(client, sim_cfg):
    """A box floating still (no gravity) is at rest after exactly one window; the same box
    drifting at a constant 4 mm/s, slower than the old 5 mm/s speed threshold, never is.

    Hand-worked: the window is 60 steps = 6 checks of 10 steps, and every corner must have stayed
    within 0.5 mm of where it is now at each of them, so a still box is at rest at step 60. At
    4 mm/s a corner moves 4 / 240 × 60 = 1 mm per window, twice the tolerance.
    """
    from pipeline.cell.bin import build_cell

    build_cell(client, sim_cfg.bin, sim_cfg.physics)
    p.setGravity(0, 0, 0, physicsClientId=client)
    col = p.createCollisionShape(p.GEOM_BOX, halfExtents=[0.05, 0.04, 0.03], physicsClientId=client)
    box = p.createMultiBody(1.0, col, basePosition=[0, 0, 0.1], physicsClientId=client)
    p.changeDynamics(box, -1, linearDamping=0.0, angularDamping=0.0, physicsClientId=client)
    steps, at_rest = settle(client, [box], sim_cfg.physics, 3000)
    assert (steps, at_rest) == (60, True)
    p.resetBaseVelocity(box, [0.004, 0, 0], [0, 0, 0], physicsClientId=client)
    steps, at_rest = settle(client, [box], sim_cfg.physics, 600)
    assert (steps, at_rest) == (600, False)


def test_boxes_in_bin_and_visible(client, sim_cfg):
    scene = simulate_scene(client, sim_cfg, scene_rng(0, 0, 3))
    assert scene.num_dropped == len(scene.boxes) + scene.num_removed
    for box in scene.boxes:
        assert abs(box.position[0]) < 0.2 and abs(box.position[1]) < 0.15
        assert 0 < box.position[2] < 0.3
    # Every box's pixels lie above the bin floor (depth < 0.625 m).
    assert (scene.depth_m[scene.mask > 0] < 0.625).all()


def test_version_key(sim_cfg, tmp_path):
    base = compose("generate", ["experiment=smoke"])

    def key(*overrides):
        cfg = compose("generate", ["experiment=smoke", *overrides])
        return compute_version("generate", stage_config(cfg, SECTIONS, NOT_AFFECTING_RESULT), {})

    k0 = key()
    assert k0 == compute_version("generate", stage_config(base, SECTIONS, NOT_AFFECTING_RESULT), {})
    # Settings that cannot change the artifact leave the key alone.
    assert key("generate.workers=7") == k0
    assert key(f"paths.root={tmp_path}") == k0
    assert key("logging.max_logged_scenes=3", "logging.progress=false") == k0
    assert key("generate.force=true") == k0
    assert key("report.num_sample_images=2") == k0
    # Anything that changes the data changes it.
    assert key("generate.num_scenes=17") != k0
    assert key("seed=1") != k0
    assert key("camera.fx=400") != k0
    assert key("sensor=sr300") != k0
    assert key("physics.solver_iterations=60") != k0
    # And so do the upstream versions.
    cfg = compose("generate", ["experiment=smoke"])
    assert compute_version("generate", stage_config(cfg, SECTIONS), {"x": "1"}) != compute_version(
        "generate", stage_config(cfg, SECTIONS), {"x": "2"}
    )


@pytest.mark.parametrize(
    "override",
    [
        "generate.num_scene=3",  # typo in a key
        "generate.num_scenes=many",  # wrong type
        "camera.fx=[1,2]",
        "experiment=smok",  # unknown experiment
    ],
)
def test_config_typo_rejected(override):
    with pytest.raises(ConfigCompositionException):
        compose("generate", ["experiment=smoke", override])


def test_artifact_and_loader(smoke_cfg, tmp_path):
    cfg = smoke_cfg("generate", *TINY, "generate.workers=1")
    folder = generate(cfg)
    assert folder == (tmp_path / "data" / "generate" / folder.name)
    assert (tmp_path / "data" / "generate" / "latest").resolve() == folder.resolve()
    manifest = load_manifest(folder)
    for key in (
        "stage",
        "version",
        "created",
        "config",
        "upstream",
        "code",
        "packages",
        "platform",
        "seed",
        "files",
        "metrics",
        "timings",
    ):
        assert key in manifest
    assert set(manifest["platform"]) == {"machine", "cpu", "system", "libc"}
    assert manifest["version"] == folder.name
    assert set(manifest["files"]) >= {
        "camera.json",
        "index.json",
        "log.rrd",
        "log.mcap",
        "scenes/train-00000.npz",
        "scenes/train-00001.npz",
        "scenes/val-00000.npz",
        "scenes/test-00000.npz",
    }
    assert verify_artifact(folder) == []

    ds = SceneDataset(folder, "train")
    assert len(ds) == 3 and len(SceneDataset(folder, "val")) == 1
    total = 0
    for i, scene in enumerate(ds):
        assert scene.index == i and scene.seed == (0, 0, i)
        assert scene.depth_m.shape == (416, 416) and scene.depth_m.dtype == np.float32
        assert scene.mask.max() == len(scene.boxes)
        total += len(scene.boxes)
        for box in scene.boxes:
            # The stored camera-frame pose is the world pose seen from the camera.
            assert np.allclose(np.linalg.inv(scene.T_world_cam) @ box.T_world_box, box.T_cam_box)
            # Every visible pixel of the box back-projects inside the box (to 2 mm).
            pix = scene.mask == box.instance
            if not pix.any():
                continue
            pts = backproject(scene.depth_m, scene.intrinsics)[pix]
            local = (pts - box.T_cam_box[:3, 3]) @ box.T_cam_box[:3, :3]
            assert (np.abs(local) <= box.size / 2 + 0.002).all()
    assert total == manifest["metrics"]["splits"]["train"]["boxes"]

    # Train and validation boxes are jittered (generate.size_jitter_splits); test boxes are not.
    j = cfg.generate.size_jitter
    assert j > 0 and list(cfg.generate.size_jitter_splits) == ["train", "val"]
    types = [np.asarray(t.size) for t in cfg.boxes.types]
    for split in ("train", "val", "test"):
        for scene in SceneDataset(folder, split):
            for box in scene.boxes:
                ratio = box.size / types[box.type_index]
                if split == "test":
                    assert np.array_equal(box.size, types[box.type_index])
                else:
                    assert ((1 - j <= ratio) & (ratio <= 1 + j)).all() and (ratio != 1).all()

    # Logs: read back entities and message counts.
    entities = rrd_entity_paths(folder / "log.rrd")
    assert {
        "/world/camera",
        "/world/camera/depth",
        "/world/camera/mask",
        "/world/boxes",
        "/world/bin",
    } <= entities
    counts = mcap_message_counts(folder / "log.mcap")
    assert counts["/world/camera/depth"] == 5 and counts["/world/camera/mask"] == 5
    assert counts["/world/boxes"] == 5 and counts["/world/bin"] == 1


def test_rerun_reuses_and_force_recomputes(smoke_cfg, capsys):
    cfg = smoke_cfg("generate", *TINY, "generate.workers=1")
    first = generate(cfg)
    created = load_manifest(first)["created"]
    assert generate(cfg) == first
    assert "reusing" in capsys.readouterr().out
    assert load_manifest(first)["created"] == created
    forced = generate(smoke_cfg("generate", *TINY, "generate.workers=1", "generate.force=true"))
    assert forced == first and verify_artifact(forced) == []


def test_same_artifact_whatever_the_workers(tmp_path):
    def files(workers: int) -> dict:
        cfg = compose(
            "generate",
            [
                "experiment=smoke",
                *TINY,
                f"paths.root={tmp_path / str(workers)}",
                f"generate.workers={workers}",
                "logging.progress=false",
            ],
        )
        m = load_manifest(generate(cfg))
        return {k: v for k, v in m["files"].items() if k != "log.rrd"}

    assert files(1) == files(2)


def test_exception_leaves_no_artifact(smoke_cfg, tmp_path, monkeypatch):
    import pipeline.stages.generate as gen

    def boom(*args, **kwargs):
        raise RuntimeError("simulated crash")

    monkeypatch.setattr(gen, "_log_static", boom)
    with pytest.raises(RuntimeError, match="simulated crash"):
        generate(smoke_cfg("generate", *TINY, "generate.workers=1"))
    stage_dir = tmp_path / "data" / "generate"
    assert [p.name for p in stage_dir.iterdir()] == []  # no version folder, no latest, no tmp
    with pytest.raises(ArtifactError, match="make generate"):
        resolve_artifact(tmp_path / "data", "generate", "latest")


def test_verify_catches_changes(smoke_cfg):
    folder = generate(smoke_cfg("generate", *TINY, "generate.workers=1"))
    shard = folder / "scenes" / "val-00000.npz"
    data = bytearray(shard.read_bytes())
    data[100] ^= 0xFF
    shard.write_bytes(bytes(data))
    (folder / "camera.json").unlink()
    problems = verify_artifact(folder)
    assert any("val-00000.npz: changed" in m for m in problems)
    assert any("camera.json: missing" in m for m in problems)


def test_splits_never_share_seeds(smoke_cfg):
    folder = generate(smoke_cfg("generate", *TINY, "generate.workers=1"))
    seeds = [
        SceneDataset(folder, s)[i].seed
        for s in ("train", "val", "test")
        for i in range(len(SceneDataset(folder, s)))
    ]
    assert len(set(seeds)) == len(seeds)
    assert json.loads((folder / "camera.json").read_text())["depth_unit"] == 1e-4


def test_jittered_size_draws_per_edge_and_nothing_at_zero():
    from pipeline.simulation.heap import jittered_size

    size = np.array([0.1, 0.2, 0.4])
    rng = np.random.default_rng(3)
    expect = size * np.random.default_rng(3).uniform(0.8, 1.2, 3)
    assert np.allclose(jittered_size(size, 0.2, rng), expect)
    rng = np.random.default_rng(3)
    assert np.array_equal(jittered_size(size, 0.0, rng), size)
    assert rng.uniform() == np.random.default_rng(3).uniform()  # no draw was taken
    with pytest.raises(ValueError, match="size_jitter"):
        jittered_size(size, 1.0, rng)


def test_jittered_heap_bodies_have_their_drawn_size_and_mass(client, sim_cfg):
    from pipeline.cell.bin import build_cell
    from pipeline.simulation.heap import drop_heap

    build_cell(client, sim_cfg.bin, sim_cfg.physics)
    heap = drop_heap(
        client,
        np.random.default_rng(11),
        sim_cfg.boxes,
        sim_cfg.bin,
        sim_cfg.physics,
        size_jitter=0.2,
    )
    assert heap.boxes
    for box in heap.boxes:
        base = np.asarray(sim_cfg.boxes.types[box.type_index].size)
        assert ((box.size >= 0.8 * base) & (box.size <= 1.2 * base)).all()
        shape = p.getCollisionShapeData(box.body_id, -1, physicsClientId=client)[0]
        assert np.allclose(shape[3], box.size, atol=1e-6)  # GEOM_BOX dimensions: full extents
        mass = p.getDynamicsInfo(box.body_id, -1, physicsClientId=client)[0]
        assert mass == pytest.approx(sim_cfg.boxes.density * np.prod(box.size))


def test_unseen_sizes_stay_outside_every_jittered_training_type():
    """At ``generate.size_jitter`` no box of the unseen-size test set or of the closed-loop trials
    that is not a training type can be drawn from a training type in any orientation: for every
    permutation of its edges some edge lies outside [1 - j, 1 + j] × the type's edge."""
    import itertools

    cfg = OmegaConf.to_object(compose("generate", ["experiment=paper"]))
    j = cfg.generate.size_jitter
    train = [np.asarray(t.size) for t in cfg.boxes.types]
    others = [
        np.asarray(t.size)
        for t in OmegaConf.to_object(
            compose("generate", ["experiment=paper", "boxes=unseen"])
        ).boxes.types
    ]
    others += [
        np.asarray(t.size)
        for t in cfg.eval_boxes.types
        if not any(np.array_equal(t.size, s) for s in train)
    ]
    assert len(others) == 11
    for size in others:
        for base in train:
            for perm in itertools.permutations(size):
                ratio = np.asarray(perm) / base
                assert not ((1 - j <= ratio) & (ratio <= 1 + j)).all(), (size, base)
