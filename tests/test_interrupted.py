"""Interrupted work: a stage killed with SIGKILL at any moment, then run again, finishes with the
artifact an uninterrupted run writes, and nothing half-written is ever visible in between.

Each stage runs as a subprocess through its command line (``python -m pipeline.<stage>``), is
killed (``Popen.kill``) once the file system shows it reached a point (its work folder exists,
N shard files are written, the log is being written, a training checkpoint appears), and is run
again to completion. The result is compared with an uninterrupted reference run in another
``paths.root`` (in the test's process, with the same overrides): same version, same files
(``pipeline.tools.repro_check.compare_artifacts``, Rerun logs by content) and the same manifest
apart from ``created`` and ``timings``.

The default run keeps one kill per stage; ``-m slow`` adds kills at more points.
"""

from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import sys
import textwrap
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from pipeline.artifacts.fingerprint import REPO_ROOT, stage_module
from pipeline.artifacts.locking import LOCK_PREFIX, TMP_PREFIX
from pipeline.artifacts.store import (
    MANIFEST,
    STATE_DIR,
    ArtifactError,
    ArtifactWriter,
    load_manifest,
    resolve_artifact,
    run_stage,
    verify_artifact,
)
from pipeline.runtime.cli import run_named_stage
from pipeline.tools.repro_check import compare_artifacts

OVERRIDES = (
    "experiment=smoke",
    "logging.progress=false",
    "generate.num_scenes=6",
    "generate.num_val_scenes=2",
    "generate.num_test_scenes=2",
    "generate.scenes_per_shard=2",
    "label.robot_checks=false",
    "label.workers=1",
    "train.epochs=3",
)
SHARDS = 5  # 3 train + 1 val + 1 test shards of 2 scenes
TOP = {"generate": "data", "label": "data", "train": "models"}
VOLATILE = ("created", "timings")


def _overrides(root: Path, workers: int = 1) -> list[str]:
    return [f"paths.root={root}", *OVERRIDES, f"generate.workers={workers}"]


def _cmd(stage: str, root: Path, workers: int = 1) -> list[str]:
    return [sys.executable, "-m", stage_module(stage), *_overrides(root, workers)]


def _env() -> dict:
    return {**os.environ, "PYTHONUNBUFFERED": "1"}


def _run(stage: str, root: Path) -> str:
    """Run ``stage`` to completion; its output."""
    res = subprocess.run(
        _cmd(stage, root), cwd=REPO_ROOT, env=_env(), capture_output=True, text=True, timeout=300
    )
    out = res.stdout + res.stderr
    assert res.returncode == 0, f"{stage} failed:\n{out[-3000:]}"
    return out


def _stage_dir(root: Path, stage: str) -> Path:
    return root / TOP[stage] / stage


def _work_dir(root: Path, stage: str, version: str) -> Path:
    return _stage_dir(root, stage) / f"{TMP_PREFIX}{version}"


def _kill_when(
    stage: str,
    root: Path,
    ready: Callable[[], bool],
    timeout: float = 240.0,
    workers: int = 1,
    sig: int = signal.SIGKILL,
):
    """Start ``stage``, send it ``sig`` (SIGKILL) as soon as ``ready()``; fails if it ended
    before."""
    log = root / f"{stage}-killed.log"
    with open(log, "a") as out:
        # SIGINT at its default in the stage, whatever this process inherited: a shell starts a
        # background job with SIGINT ignored, and Python then never raises KeyboardInterrupt
        proc = subprocess.Popen(
            _cmd(stage, root, workers),
            cwd=REPO_ROOT,
            env=_env(),
            stdout=out,
            stderr=subprocess.STDOUT,
            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
        )
    try:
        deadline = time.monotonic() + timeout
        while not ready():
            if proc.poll() is not None:
                pytest.fail(
                    f"{stage} ended (exit {proc.returncode}) before the kill point:\n"
                    + log.read_text()[-3000:]
                )
            assert time.monotonic() < deadline, f"{stage} never reached the kill point"
            time.sleep(0.01)
        assert proc.poll() is None, f"{stage} ended before it could be killed"
        proc.send_signal(sig)
        proc.wait(timeout=60)
    finally:
        proc.kill()
        proc.wait()


def _shards(root: Path, stage: str, version: str) -> list[Path]:
    sub = {"generate": "scenes", "label": "labels"}[stage]
    return sorted((_work_dir(root, stage, version) / sub).glob("*.npz"))


def _assert_nothing_visible(root: Path, stage: str, version: str) -> None:
    """After the kill: no artifact folder, ``latest`` absent or complete, readers refuse the
    work folder."""
    stage_dir = _stage_dir(root, stage)
    assert not (stage_dir / version).exists()
    latest = stage_dir / "latest"
    assert not os.path.lexists(latest) or (latest / MANIFEST).is_file()
    for name in (version, "latest", f"{TMP_PREFIX}{version}"):
        with pytest.raises(ArtifactError):
            resolve_artifact(root / TOP[stage], stage, name)


def _assert_same_as(reference: Path, folder: Path, stage: str) -> None:
    assert folder.name == reference.name
    assert verify_artifact(folder) == []
    assert compare_artifacts(stage, reference, folder) == []
    a, b = load_manifest(reference), load_manifest(folder)
    for m in (a, b):
        for key in VOLATILE:
            m.pop(key)
        # Rerun logs are not byte-stable; compare_artifacts compared them by content.
        m["files"] = {k: v for k, v in m["files"].items() if not k.endswith(".rrd")}
    assert a == b
    # Nothing of the interrupted runs is left beside the artifact.
    stage_dir = folder.parent
    left = [p.name for p in stage_dir.iterdir() if p.name.startswith((TMP_PREFIX, LOCK_PREFIX))]
    assert left == []


def _resumed_shards(out: str, stage: str) -> int:
    m = re.search(rf"\[{stage}\] resuming: (\d+) of {SHARDS} shards already written", out)
    assert m, out[-3000:]
    return int(m.group(1))


@pytest.fixture(scope="module")
def reference(tmp_path_factory) -> dict[str, Path]:
    """Uninterrupted runs of the three stages, in this process, with the overrides of their
    command line (``_cmd``)."""
    root = tmp_path_factory.mktemp("reference")
    folders = {}
    for stage in ("generate", "label", "train"):
        folders[stage] = run_named_stage(stage, _overrides(root), "reference")
    return folders


def _root_with(tmp_path: Path, reference: dict[str, Path], *stages: str) -> Path:
    """A fresh ``paths.root`` holding copies of the reference artifacts of ``stages``."""
    root = tmp_path / "run"
    root.mkdir()
    for stage in stages:
        src = reference[stage]
        dst = _stage_dir(root, stage)
        dst.mkdir(parents=True)
        shutil.copytree(src, dst / src.name)
        os.symlink(src.name, dst / "latest")
    return root


_EPOCHS: dict = {}


def _ckpt_epoch(root: Path) -> int:
    """The epoch of the training resume checkpoint (0 when none); read again only when the
    file was replaced (polled often: the stage must not be slowed down)."""
    import torch

    found = list((root / "models" / "train").glob(".resume-*/checkpoint.pt"))
    if not found:
        return 0
    try:
        st = found[0].stat()
        key = (str(found[0]), st.st_ino, st.st_mtime_ns, st.st_size)
        if key not in _EPOCHS:
            _EPOCHS[key] = int(torch.load(found[0], map_location="cpu", weights_only=True)["epoch"])
        return _EPOCHS[key]
    except Exception:
        return 0


# ----------------------------------------------------------------------------- generation


def _check_generate(
    tmp_path,
    reference,
    kill_points: list[Callable[[Path, str], bool]],
    workers: int = 1,
    sig: int = signal.SIGKILL,
):
    version = reference["generate"].name
    root = _root_with(tmp_path, reference)
    seen = 0
    for ready in kill_points:
        _kill_when(
            "generate", root, lambda ready=ready: ready(root, version), workers=workers, sig=sig
        )
        seen = len(_shards(root, "generate", version))  # complete: written atomically
        _assert_nothing_visible(root, "generate", version)
        if workers > 1:  # the pool's workers died with the stage: nothing more is written
            files = sorted(p.name for p in _work_dir(root, "generate", version).rglob("*"))
            time.sleep(1.0)
            assert sorted(p.name for p in _work_dir(root, "generate", version).rglob("*")) == files
    out = _run("generate", root)
    assert _resumed_shards(out, "generate") == seen
    _assert_same_as(reference["generate"], resolve_artifact(root / "data", "generate"), "generate")


def _n_shards(n: int):
    return lambda root, version: len(_shards(root, "generate", version)) >= n


def _work_exists(stage: str):
    return lambda root, version: _work_dir(root, stage, version).is_dir()


def _logging(stage: str):
    return lambda root, version: (_work_dir(root, stage, version) / "log.rrd").is_file()


def test_generate_killed_after_a_shard_resumes(tmp_path, reference):
    _check_generate(tmp_path, reference, [_n_shards(1)])


@pytest.mark.slow
def test_generate_with_worker_processes_killed(tmp_path, reference):
    # The killed stage's pool workers must not outlive it (they would keep writing into the
    # work folder and hold its lock): the rerun starts at once and resumes.
    _check_generate(tmp_path, reference, [_n_shards(2)], workers=2)


@pytest.mark.slow
def test_generate_interrupted_with_ctrl_c_resumes(tmp_path, reference):
    # SIGINT: KeyboardInterrupt keeps the work folder as a kill does.
    _check_generate(tmp_path, reference, [_n_shards(2)], sig=signal.SIGINT)


@pytest.mark.slow
def test_generate_killed_again_and_again(tmp_path, reference):
    # Right after it took its work folder, after 3 of 5 shards, while writing its log.
    _check_generate(
        tmp_path, reference, [_work_exists("generate"), _n_shards(3), _logging("generate")]
    )


# ----------------------------------------------------------------------------- labelling


def _check_label(tmp_path, reference, kill_points):
    version = reference["label"].name
    root = _root_with(tmp_path, reference, "generate")
    seen = 0
    for ready in kill_points:
        _kill_when("label", root, lambda ready=ready: ready(root, version))
        seen = len(_shards(root, "label", version))
        _assert_nothing_visible(root, "label", version)
    out = _run("label", root)
    assert _resumed_shards(out, "label") == seen
    _assert_same_as(reference["label"], resolve_artifact(root / "data", "label"), "label")


def _n_labels(n: int):
    return lambda root, version: len(_shards(root, "label", version)) >= n


def test_label_killed_after_a_shard_resumes(tmp_path, reference):
    _check_label(tmp_path, reference, [_n_labels(1)])


@pytest.mark.slow
def test_label_killed_again_and_again(tmp_path, reference):
    _check_label(tmp_path, reference, [_work_exists("label"), _n_labels(3), _logging("label")])


# ----------------------------------------------------------------------------- training


def _check_train(tmp_path, reference, kill_points):
    version = reference["train"].name
    root = _root_with(tmp_path, reference, "generate", "label")
    for ready in kill_points:
        _kill_when("train", root, lambda ready=ready: ready(root, version))
        _assert_nothing_visible(root, "train", version)
    out = _run("train", root)
    epoch = _ckpt_epoch(root)
    assert epoch == 3
    _assert_same_as(reference["train"], resolve_artifact(root / "models", "train"), "train")
    return out


def _epoch(n: int):
    return lambda root, version: _ckpt_epoch(root) >= n


def test_train_killed_after_an_epoch_resumes(tmp_path, reference):
    out = _check_train(tmp_path, reference, [_epoch(1)])
    assert re.search(r"resuming from .* at epoch [123]\b", out)


@pytest.mark.slow
def test_train_killed_again_and_again(tmp_path, reference):
    # Right after it took its work folder, after epoch 2, after the last epoch (while it
    # evaluates and writes the artifact's files).
    _check_train(tmp_path, reference, [_work_exists("train"), _epoch(2), _epoch(3)])


# ----------------------------------------------------------------------------- the store


def test_resumable_work_folder_kept_force_empties_it(tmp_path):
    def partial(run):
        assert not run.resumed
        (run.work_dir / "done.txt").write_text("finished shard")
        (run.state_dir).mkdir()
        (run.state_dir / "records.json").write_text("{}")
        (run.work_dir / "half.txt.part").write_text("half")
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_stage(tmp_path, "s", "v1", {}, {}, partial, resumable=True, say=lambda _: None)
    work = tmp_path / "s" / f"{TMP_PREFIX}v1"
    assert (work / "done.txt").is_file()
    with pytest.raises(ArtifactError, match="not a version name"):
        resolve_artifact(tmp_path, "s", work.name)

    def resume(run):
        assert run.resumed
        kept = run.keep_only([run.work_dir / "done.txt", run.state_dir / "records.json"])
        assert sorted(p.name for p in kept) == ["done.txt", "records.json"]
        assert not (run.work_dir / "half.txt.part").exists()

    folder = run_stage(tmp_path, "s", "v1", {}, {}, resume, resumable=True, say=lambda _: None)
    assert sorted(load_manifest(folder)["files"]) == ["done.txt"]  # no resume data
    assert not (folder / STATE_DIR).exists() and verify_artifact(folder) == []
    assert sorted(p.name for p in (tmp_path / "s").iterdir()) == ["latest", "v1"]

    with pytest.raises(KeyboardInterrupt):
        run_stage(tmp_path, "s", "v2", {}, {}, partial, resumable=True, say=lambda _: None)

    def fresh(run):
        assert not run.resumed and list(run.work_dir.iterdir()) == []
        (run.work_dir / "new.txt").write_text("x")

    folder = run_stage(
        tmp_path, "s", "v2", {}, {}, fresh, resumable=True, force=True, say=lambda _: None
    )
    assert sorted(load_manifest(folder)["files"]) == ["new.txt"]

    # An error (not an interruption) leaves nothing behind, as for any stage.
    with pytest.raises(KeyboardInterrupt):
        run_stage(tmp_path, "s", "v3", {}, {}, partial, resumable=True, say=lambda _: None)

    def failing(run):
        assert run.resumed
        raise RuntimeError("disk on fire")

    with pytest.raises(RuntimeError):
        run_stage(tmp_path, "s", "v3", {}, {}, failing, resumable=True, say=lambda _: None)
    assert sorted(p.name for p in (tmp_path / "s").iterdir()) == ["latest", "v1", "v2"]


def test_a_second_writer_of_the_same_version_is_refused(tmp_path):
    with ArtifactWriter(tmp_path, "s", "v1", {}, {}) as run:
        (run.work_dir / "a.txt").write_text("x")
        with pytest.raises(
            ArtifactError,
            match=rf"another run of s v1 is writing .*pid "
            rf"{os.getpid()}",
        ):
            run_stage(tmp_path, "s", "v1", {}, {}, lambda r: None, say=lambda _: None)
        # Another version is not blocked.
        run_stage(tmp_path, "s", "v2", {}, {}, lambda r: None, say=lambda _: None)
    assert (tmp_path / "s" / "v1" / "a.txt").is_file()


def test_killed_writer_releases_its_lock_and_workers(tmp_path):
    """The lock of a killed run is free again, and the worker processes it forked die with it
    (else they would keep writing into the work folder and keep the lock)."""
    script = textwrap.dedent(f"""
        import multiprocessing as mp, os, time
        from pipeline.artifacts.store import ArtifactWriter

        def sleep(_):
            time.sleep(600)

        with ArtifactWriter({str(tmp_path)!r}, "s", "v1", {{}}, {{}}, resumable=True) as run:
            pool = mp.get_context("fork").Pool(1)
            pool.map_async(sleep, [0])
            print(" ".join(str(p.pid) for p in pool._pool), flush=True)
            time.sleep(600)
    """)
    proc = subprocess.Popen(
        [sys.executable, "-c", script], cwd=REPO_ROOT, env=_env(), stdout=subprocess.PIPE, text=True
    )
    try:
        workers = [int(p) for p in proc.stdout.readline().split()]
        assert workers
    finally:
        proc.kill()
        proc.wait()
    deadline = time.monotonic() + 10
    while any(Path(f"/proc/{pid}").exists() and "Z" not in _state(pid) for pid in workers):
        assert time.monotonic() < deadline, "the killed run's worker is still alive"
        time.sleep(0.05)
    folder = run_stage(
        tmp_path, "s", "v1", {}, {}, lambda run: None, resumable=True, say=lambda _: None
    )
    assert verify_artifact(folder) == []


def _state(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return "Z"
