"""Deterministic storage, the sensor model, artifact-store edge cases."""

from __future__ import annotations

import json
import os
from pathlib import Path
from types import SimpleNamespace as NS

import numpy as np
import pytest
from omegaconf import OmegaConf

from pipeline.artifacts.store import (
    ArtifactError,
    ArtifactWriter,
    load_manifest,
    resolve_artifact,
    run_stage,
    verify_artifact,
)
from pipeline.camera.geometry import Intrinsics
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


CONF_SENSOR = Path(__file__).resolve().parents[1] / "conf" / "sensor"


def sensor_cfg(name: str, **overrides) -> NS:
    """``conf/sensor/<name>.yaml`` as a namespace, with ``overrides``."""
    cfg = OmegaConf.to_container(OmegaConf.load(CONF_SENSOR / f"{name}.yaml"))
    assert set(cfg) >= set(overrides), "override of a field the sensor config lacks"
    return NS(**{**cfg, **overrides})


# Nearly telecentric: fx = 4000 px, so a 200 × 200 image's rays are within
# atan(√2 · 100 / 4000) = 2.0° of the optical axis and θ ≤ 2° on a fronto-parallel plane.
NARROW = Intrinsics(200, 200, 4000.0, 4000.0, 99.5, 99.5)


def test_sensor_off_is_identity():
    depth = np.full((8, 8), 0.6, np.float32)
    intr = Intrinsics(8, 8, 400.0, 400.0, 3.5, 3.5)
    rng = np.random.default_rng(0)
    state = rng.bit_generator.state
    assert apply_sensor_model(depth, sensor_cfg("ideal"), rng, intr) is depth
    assert apply_sensor_model(depth, NS(enabled=False), rng, intr) is depth
    assert rng.bit_generator.state == state  # nothing drawn


def test_sensor_noise_grows_with_depth_squared():
    # SR300 noise with every dropout off. On a fronto-parallel plane θ ≤ 2°, so the angle term
    # σθ/√z · θ²/(π/2 − θ)² ≤ 1e-4 / √0.5 · 0.035² / 1.536² = 7e-8 m: negligible. So
    # σ = σ0 + σ2 z² = 0.0005 + 0.002 · 0.25 = 1.0 mm at 0.5 m, 0.0005 + 0.002 = 2.5 mm at 1 m.
    # The 1/8 mm quantisation adds step/√12 = 0.036 mm in quadrature: +0.07 % at 0.5 m.
    # 40,000 samples give the std to 1/√(2 · 40000) = 0.35 %; tolerance 3 %.
    cfg = sensor_cfg("sr300", edge_dropout_prob=0.0, dropout_angle_deg=90.0)
    rng = np.random.default_rng(0)
    stds = {}
    for z, sigma in ((0.5, 0.0010), (1.0, 0.0025)):
        depth = np.full((200, 200), z, np.float32)
        noisy = apply_sensor_model(depth, cfg, rng, NARROW)
        assert (noisy > 0).all()  # flat plane in range: no shadow, no dropout
        stds[z] = float(np.std(noisy.astype(np.float64) - z))
        assert stds[z] == pytest.approx(sigma, rel=0.03)
        assert float(np.mean(noisy.astype(np.float64) - z)) == pytest.approx(0.0, abs=3e-5)
    # Not linear in z: doubling z multiplies σ by 2.5, not 2.
    assert stds[1.0] / stds[0.5] == pytest.approx(2.5, rel=0.05)


def test_sensor_drops_only_edge_pixels_and_quantises():
    depth = np.full((10, 10), 0.6, np.float32)
    depth[:, 5:] = 0.55  # a 5 cm step between columns 4 and 5
    cfg = sensor_cfg(
        "sr300",
        noise_sigma_0=0.0,
        noise_sigma_2=0.0,
        noise_sigma_theta=0.0,
        projector_baseline=0.0,
        dropout_angle_deg=90.0,
        edge_dropout_prob=1.0,
        quantisation_step=0.001,
    )
    intr = Intrinsics(10, 10, 400.0, 400.0, 4.5, 4.5)
    out = apply_sensor_model(depth, cfg, np.random.default_rng(0), intr)
    assert out.dtype == np.float32 and out.shape == depth.shape
    assert (out[:, 4:6] == 0).all()  # both sides of the step are lost
    assert np.allclose(out[:, :4], 0.6) and np.allclose(out[:, 6:], 0.55)
    depth[0, 0] = 0.60049  # 0.49 mm off its neighbours: no step; rounds to 0.600
    out = apply_sensor_model(depth, cfg, np.random.default_rng(0), intr)
    assert out[0, 0] == pytest.approx(0.600)
    assert out[0, 1] == pytest.approx(0.600)


def test_sensor_rejects_image_of_wrong_shape():
    depth = np.full((10, 12), 0.6, np.float32)
    with pytest.raises(ValueError, match="expected"):
        apply_sensor_model(
            depth,
            sensor_cfg("sr300"),
            np.random.default_rng(0),
            Intrinsics(12, 12, 400.0, 400.0, 5.5, 5.5),
        )


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
