"""Deterministic storage, the sensor model, artifact-store edge cases."""

from __future__ import annotations

import json
import os
from types import SimpleNamespace as NS

import numpy as np
import pytest

from pipeline.artifacts.store import (
    ArtifactError, ArtifactWriter, load_manifest, resolve_artifact, run_stage, verify_artifact,
)
from pipeline.camera.sensor import apply_sensor_model
from pipeline.dataset.storage import read_npz, write_npz


def test_npz_bytes_depend_on_content_only(tmp_path):
    arrays = {"b": np.arange(10, dtype=np.uint16), "a": np.eye(3)}
    write_npz(tmp_path / "1.npz", arrays)
    os.utime(tmp_path / "1.npz", (0, 0))
    write_npz(tmp_path / "2.npz", dict(reversed(list(arrays.items()))))
    assert (tmp_path / "1.npz").read_bytes() == (tmp_path / "2.npz").read_bytes()
    back = read_npz(tmp_path / "1.npz")
    assert np.array_equal(back["b"], arrays["b"]) and back["b"].dtype == np.uint16
    assert not list(tmp_path.glob("*.part"))


SR300 = NS(enabled=True, noise_sigma_at_1m=0.0035, edge_jump=0.01, edge_dropout_prob=0.5,
           quantisation_step=0.0)


def test_sensor_off_is_identity():
    depth = np.full((8, 8), 0.6, np.float32)
    assert apply_sensor_model(depth, NS(enabled=False), np.random.default_rng(0)) is depth


def test_sensor_noise_grows_with_depth_squared():
    rng = np.random.default_rng(0)
    cfg = NS(**{**vars(SR300), "edge_dropout_prob": 0.0})
    for z in (0.5, 1.0):
        depth = np.full((200, 200), z, np.float32)
        noisy = apply_sensor_model(depth, cfg, rng)
        # sigma = 0.0035 * z^2: 0.875 mm at 0.5 m, 3.5 mm at 1 m (to 3 % with 40,000 samples).
        assert np.std(noisy - z) == pytest.approx(0.0035 * z * z, rel=0.03)


def test_sensor_drops_only_edge_pixels_and_quantises():
    depth = np.full((10, 10), 0.6, np.float32)
    depth[:, 5:] = 0.55  # a 5 cm step between columns 4 and 5
    cfg = NS(enabled=True, noise_sigma_at_1m=0.0, edge_jump=0.01, edge_dropout_prob=1.0,
             quantisation_step=0.001)
    out = apply_sensor_model(depth, cfg, np.random.default_rng(0))
    assert (out[:, 4:6] == 0).all()  # both sides of the step are lost
    assert np.allclose(out[:, :4], 0.6) and np.allclose(out[:, 6:], 0.55)
    depth[0, 0] = 0.60049
    out = apply_sensor_model(depth, cfg, np.random.default_rng(0))
    assert out[0, 0] == pytest.approx(0.600)


def test_writer_failure_cleans_up_and_keeps_old(tmp_path):
    def body(run):
        (run.work_dir / "a.txt").write_text("first")

    folder = run_stage(tmp_path, "s", "v1", {}, {}, body, say=lambda _: None)
    assert (folder / "a.txt").read_text() == "first"

    def failing(run):
        (run.work_dir / "a.txt").write_text("second")
        raise RuntimeError("disk on fire")

    with pytest.raises(RuntimeError):
        run_stage(tmp_path, "s", "v1", {}, {}, failing, force=True, say=lambda _: None)
    # The finished artifact is untouched; no temporary folder remains.
    assert (folder / "a.txt").read_text() == "first"
    assert verify_artifact(folder) == []
    assert sorted(p.name for p in (tmp_path / "s").iterdir()) == ["latest", "v1"]


def test_stale_tmp_folders_are_never_artifacts(tmp_path):
    stale = tmp_path / "s" / ".tmp-v9-dead"
    stale.mkdir(parents=True)
    (stale / "manifest.json").write_text("{}")
    with pytest.raises(ArtifactError, match="none exist yet"):
        resolve_artifact(tmp_path, "s", "latest")
    with pytest.raises(ArtifactError, match="not a version name"):
        resolve_artifact(tmp_path, "s", ".tmp-v9-dead")


def test_verify_rejects_paths_outside_the_artifact(tmp_path):
    with ArtifactWriter(tmp_path, "s", "v1", {}, {}) as run:
        (run.work_dir / "a.txt").write_text("x")
    folder = tmp_path / "s" / "v1"
    manifest = load_manifest(folder)
    manifest["files"]["../../etc/passwd"] = {"sha256": "0", "bytes": 1}
    (folder / "manifest.json").write_text(json.dumps(manifest))
    assert any("outside" in p for p in verify_artifact(folder))
    (folder / "manifest.json").write_text("{not json")
    assert any("not valid JSON" in p for p in verify_artifact(folder))
