"""Bad inputs give one clear error and touch nothing: a missing or mistyped upstream version, a
truncated or altered artifact file, file names that lead outside an artifact, an unusable resume
checkpoint, a missing system library. Each is tried through the stage's command line (exit
status 2, one ``error:`` line naming the problem and the fix, no traceback) or, for the many
version keys, in-process; every file under ``data/`` and ``models/`` is the same afterwards."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import torch
from conftest import default_config, smoke_overrides

from pipeline.artifacts import (
    ArtifactError,
    artifact_file,
    load_manifest,
    resolve_artifact,
    verify_artifact,
)
from pipeline.artifacts.fingerprint import sha256_file, stage_module
from pipeline.dataset.labels import LabelSet
from pipeline.dataset.scenes import SceneDataset
from pipeline.runtime.cli import MissingLibraryError, compose, import_with_fix, stage_main
from pipeline.stages.label import label
from pipeline.stages.train import train

REPO = Path(__file__).resolve().parents[1]
STAGES = ("label", "train", "baseline", "evaluate", "report")


def _overrides(root: Path, *extra: str) -> list[str]:
    return smoke_overrides(root, *extra)


def _cfg(stage: str, root: Path, *extra: str):
    return compose(stage, _overrides(root, *extra))


def _stage_fn(stage: str):
    import importlib

    return getattr(importlib.import_module(stage_module(stage)), stage)


@pytest.fixture(scope="module")
def built(smoke_pipeline) -> Path:
    """The session's smoke generation, label and train artifacts (and the train stage's resume
    checkpoint). Every test here checks that it is left exactly as it was."""
    return smoke_pipeline.root


@pytest.fixture
def root(built: Path, tmp_path: Path) -> Path:
    """A scratch copy of ``built`` that a test may damage."""
    copy = tmp_path / "root"
    for top in ("data", "models"):
        shutil.copytree(built / top, copy / top, symlinks=True)
    return copy


def snapshot(root: Path) -> dict[str, str]:
    """Every folder, link and file (with its sha256) under root/data and root/models."""
    out = {}
    for top in ("data", "models"):
        for path in sorted((root / top).rglob("*")):
            rel = path.relative_to(root).as_posix()
            if path.is_symlink():
                out[rel] = "-> " + os.readlink(path)
            elif path.is_dir():
                out[rel] = "dir"
            else:
                out[rel] = sha256_file(path)
    return out


def run_cli(stage: str, root: Path, *extra: str, prelude: str = "") -> subprocess.CompletedProcess:
    """``python -m pipeline.<stage> <overrides>``; ``prelude``: Python run first, in-process."""
    args = _overrides(root, *extra)
    if prelude:
        cmd = [
            sys.executable,
            "-c",
            f"import runpy, sys; {prelude}; sys.argv[0] = '{stage_module(stage)}'; "
            f"runpy.run_module('{stage_module(stage)}', run_name='__main__', alter_sys=True)",
            *args,
        ]
    else:
        cmd = [sys.executable, "-m", stage_module(stage), *args]
    return subprocess.run(cmd, capture_output=True, text=True, cwd=REPO, timeout=300)


def assert_clean_failure(proc: subprocess.CompletedProcess, *expected: str) -> str:
    """Exit status 2, one ``error:`` line holding every ``expected`` string, no traceback."""
    assert proc.returncode == 2, proc.stderr[-3000:]
    assert "Traceback" not in proc.stderr, proc.stderr[-3000:]
    errors = [line for line in proc.stderr.splitlines() if line.startswith("error: ")]
    assert len(errors) == 1, proc.stderr[-3000:]
    for text in expected:
        assert text in errors[0], errors[0]
    return errors[0]


def _gen_dir(root: Path) -> Path:
    return (root / "data" / "generate" / "latest").resolve()


def _label_dir(root: Path) -> Path:
    return (root / "data" / "label" / "latest").resolve()


def _resume_checkpoint(root: Path) -> Path:
    (folder,) = (root / "models" / "train").glob(".resume-*")
    return folder / "checkpoint.pt"


def _rehash(folder: Path, rel: str) -> None:
    """Update the manifest's entry for ``rel``: an alteration that verification cannot see."""
    manifest = load_manifest(folder)
    path = folder / rel
    manifest["files"][rel] = {"sha256": sha256_file(path), "bytes": path.stat().st_size}
    (folder / "manifest.json").write_text(json.dumps(manifest, indent=2, sort_keys=True) + "\n")


# ---------------------------------------------------------------- missing or mistyped versions
VERSION_KEYS = [
    "label.generate_version",
    "train.label_version",
    "baseline.generate_version",
    "baseline.train_version",
    "evaluate.train_version",
    "evaluate.baseline_version",
    "report.generate_version",
    "report.label_version",
    "report.train_version",
    "report.baseline_version",
    "report.evaluate_version",
    "report.robustness_version",
    "report.ablation_version",
    "report.unseen_version",
]


def test_every_version_key_is_covered() -> None:
    found = set()
    for stage in STAGES:
        section = compose(stage, ["experiment=smoke"])[stage]
        found |= {f"{stage}.{k}" for k in section if k.endswith("_version")}
    assert found == set(VERSION_KEYS)


@pytest.mark.parametrize("key", VERSION_KEYS)
def test_unknown_version_is_a_clear_error(built: Path, key: str, capsys) -> None:
    stage, name = key.split(".")
    upstream = name.removesuffix("_version")
    before = snapshot(built)
    cfg = _cfg(stage, built, f"{key}=deadbeef00000000")
    with pytest.raises(SystemExit) as info:
        stage_main(_stage_fn(stage))(cfg)
    assert info.value.code == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(
        f"error: [{stage}] {key}=deadbeef00000000: no complete '{upstream}' "
        "artifact named 'deadbeef00000000'"
    ), err
    assert "\n" not in err and "Fix:" in err
    top = "models" if upstream == "train" else "data"
    known = (
        sorted(p.name for p in (built / top / upstream).glob("[!.]*") if not p.is_symlink())
        if (built / top / upstream).is_dir()
        else []
    )
    if known:
        assert f"available versions: {', '.join(known)}" in err and f"pass {key}=" in err
    else:
        assert "none exist yet" in err and f"make {upstream}" in err
    assert snapshot(built) == before


@pytest.mark.parametrize(
    "stage,key",
    [
        ("label", "label.generate_version"),
        ("train", "train.label_version"),
        ("evaluate", "evaluate.train_version"),
        ("report", "report.train_version"),
    ],
)
def test_unknown_version_from_the_command_line(built: Path, stage: str, key: str) -> None:
    before = snapshot(built)
    proc = run_cli(stage, built, f"{key}=nope")
    assert_clean_failure(proc, f"[{stage}]", f"{key}=nope", "available versions:", "Fix:")
    assert snapshot(built) == before


def test_not_a_version_name(built: Path) -> None:
    with pytest.raises(ArtifactError, match="not a version name"):
        label(_cfg("label", built, "label.generate_version=../generate/latest"))


# ---------------------------------------------------------------- altered artifact files
def test_truncated_generation_shard(root: Path) -> None:
    gen = _gen_dir(root)
    shard = gen / "scenes" / "train-00000.npz"
    shard.write_bytes(shard.read_bytes()[:1000])
    before = snapshot(root)
    proc = run_cli("label", root, "label.force=true")
    assert_clean_failure(
        proc,
        "[label]",
        str(gen),
        "scenes/train-00000.npz: changed",
        "generate.force=true",
        "make verify",
    )
    # every other stage that reads it says the same
    for stage, extra in (
        ("train", "train.force=true"),
        ("baseline", "baseline.train_version=none"),
        ("report", "report.force=true"),
    ):
        with pytest.raises(ArtifactError, match="train-00000.npz: changed") as info:
            _stage_fn(stage)(_cfg(stage, root, extra))
        assert "generate.force=true" in str(info.value)
    assert snapshot(root) == before


def test_altered_labels_file(root: Path) -> None:
    lab = _label_dir(root)
    shard = sorted((lab / "labels").glob("*.npz"))[0]
    data = bytearray(shard.read_bytes())
    data[len(data) // 2] ^= 0x01
    shard.write_bytes(bytes(data))
    before = snapshot(root)
    proc = run_cli("train", root, "train.force=true")
    assert_clean_failure(
        proc,
        "[train]",
        str(lab),
        f"labels/{shard.name}: changed",
        "label.force=true",
        "make verify",
    )
    with pytest.raises(ArtifactError, match=f"labels/{shard.name}: changed"):
        _stage_fn("report")(_cfg("report", root))
    assert snapshot(root) == before


def test_verification_cost_is_small(built: Path) -> None:
    """Stages re-hash upstream artifacts on every run; a tiny one costs next to nothing."""
    import time

    t0 = time.perf_counter()
    assert resolve_artifact(built / "data", "generate", verify=True) == _gen_dir(built)
    assert time.perf_counter() - t0 < 2.0


# ---------------------------------------------------------------- file names leading outside
def test_artifact_file_refuses_names_outside(tmp_path: Path) -> None:
    folder = tmp_path / "stage" / "v1"
    (folder / "sub").mkdir(parents=True)
    (tmp_path / "secret.txt").write_text("x")
    os.symlink(tmp_path / "secret.txt", folder / "sub" / "link.npz")
    os.symlink("../..", folder / "up")
    assert artifact_file(folder, "sub/a.npz") == folder / "sub" / "a.npz"
    for bad in (
        "/etc/passwd",
        "../secret.txt",
        "sub/../../secret.txt",
        "sub/link.npz",
        "up/secret.txt",
        "",
        "C:/x",
        "sub\\..\\..\\secret.txt",
    ):
        with pytest.raises(ArtifactError, match="outside|absolute|not a relative|'\\.\\.'"):
            artifact_file(folder, bad)


def test_readers_refuse_shard_names_outside(root: Path) -> None:
    gen, lab = _gen_dir(root), _label_dir(root)
    index = json.loads((gen / "index.json").read_text())
    index["splits"]["train"][0]["file"] = "../../../../etc/passwd"
    (gen / "index.json").write_text(json.dumps(index))
    with pytest.raises(ArtifactError, match="climbs out of the artifact folder"):
        SceneDataset(gen, "train")
    meta = json.loads((lab / "labels.json").read_text())
    meta["splits"]["val"][0]["file"] = str(gen / "scenes" / "val-00000.npz")  # absolute
    (lab / "labels.json").write_text(json.dumps(meta))
    with pytest.raises(ArtifactError, match="absolute path"):
        LabelSet(lab, "val")
    # a shard replaced by a link to an identical file elsewhere: same bytes, still refused
    shard = gen / "scenes" / "test-00000.npz"
    outside = root / "elsewhere.npz"
    shutil.move(shard, outside)
    os.symlink(outside, shard)
    assert any("test-00000.npz: path points outside" in p for p in verify_artifact(gen))
    with pytest.raises(ArtifactError, match="symbolic link"):
        SceneDataset(gen, "test")


def test_index_pointing_outside_from_the_command_line(root: Path) -> None:
    """index.json altered and the manifest re-hashed to match: verification passes, the file
    name is still refused."""
    gen = _gen_dir(root)
    index = json.loads((gen / "index.json").read_text())
    index["splits"]["train"][0]["file"] = "../../label/latest/labels.json"
    (gen / "index.json").write_text(json.dumps(index))
    _rehash(gen, "index.json")
    assert verify_artifact(gen) == []
    before = snapshot(root)
    proc = run_cli("label", root, "label.force=true")
    assert_clean_failure(proc, "../../label/latest/labels.json", "climbs out", "force=true")
    assert snapshot(root) == before


# ---------------------------------------------------------------- the resume checkpoint
class _Exploit:
    """Unpickling this creates the file ``path``."""

    def __init__(self, path: Path) -> None:
        self.path = str(path)

    def __reduce__(self):
        return (open, (self.path, "w"))


def test_malicious_checkpoint_is_refused(root: Path, tmp_path: Path) -> None:
    marker = tmp_path / "unpickled-marker"
    ckpt = _resume_checkpoint(root)
    torch.save({"model": _Exploit(marker), "optimizer": {}, "epoch": 1, "history": {}}, ckpt)
    before = snapshot(root)
    proc = run_cli("train", root, "train.force=true")
    assert_clean_failure(
        proc, f"cannot resume from {ckpt}", "weights_only=True", f"delete the folder {ckpt.parent}"
    )
    assert not marker.exists()
    assert snapshot(root) == before


def _other_network_checkpoint(path: Path) -> None:
    from pipeline.planner.network import GraspNet, NetworkConfig

    ckpt = torch.load(path, weights_only=True)
    ckpt["model"] = GraspNet(default_config(NetworkConfig, width=0.125)).state_dict()
    torch.save(ckpt, path)


@pytest.mark.parametrize(
    "damage,expected",
    [
        (lambda p: p.write_bytes(p.read_bytes()[: p.stat().st_size // 2]), "not a readable torch"),
        (lambda p: p.write_text("not a checkpoint\n"), "not a readable torch"),
        (lambda p: torch.save([1, 2, 3], p), "not a training checkpoint"),
        (_other_network_checkpoint, "of another network"),
    ],
    ids=["truncated", "text", "list", "other-network"],
)
def test_unusable_checkpoint_is_refused(root: Path, damage, expected: str, capsys) -> None:
    ckpt = _resume_checkpoint(root)
    damage(ckpt)
    before = snapshot(root)
    with pytest.raises(SystemExit) as info:
        stage_main(train)(_cfg("train", root, "train.force=true"))
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert f"cannot resume from {ckpt}" in err and expected in err
    assert f"delete the folder {ckpt.parent}" in err
    assert snapshot(root) == before


# ---------------------------------------------------------------- a missing system library
def test_missing_open3d_says_how_to_install(monkeypatch) -> None:
    monkeypatch.setitem(sys.modules, "open3d", None)  # `import open3d` raises ImportError
    with pytest.raises(MissingLibraryError, match="apt-get install libusb-1.0-0") as info:
        import_with_fix("open3d")
    assert isinstance(info.value, ImportError) and "scripts/setup.sh" in str(info.value)

    def no_libusb(name):
        raise OSError("libusb-1.0.so.0: cannot open shared object file: No such file or directory")

    monkeypatch.setattr("importlib.import_module", no_libusb)
    with pytest.raises(MissingLibraryError, match="libusb-1.0.so.0: cannot open"):
        import_with_fix("open3d")


def test_missing_open3d_from_the_command_line(root: Path) -> None:
    before = snapshot(root)
    proc = run_cli(
        "label", root, "surfaces.ransac_backend=open3d", prelude="sys.modules['open3d'] = None"
    )
    assert_clean_failure(
        proc,
        "cannot import open3d",
        "libusb-1.0",
        "sudo apt-get install libusb-1.0-0",
        "scripts/setup.sh",
    )
    assert snapshot(root) == before
