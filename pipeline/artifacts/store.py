"""Atomic, versioned artifact folders and their manifests.

Write protocol (``ArtifactWriter``):

1. The stage writes every file into ``<stage_dir>/.tmp-<version>-<random>/``.
2. When the stage function returns, ``manifest.json`` is written there last, with the sha256 and
   size of every file.
3. The folder is renamed to ``<stage_dir>/<version>/`` (a single ``rename``; with ``force=true``
   the old folder is first moved aside and deleted only after the rename succeeded).
4. ``<stage_dir>/latest`` is re-pointed (symlink written under a temporary name, then renamed).

A crash or exception at any point leaves at most a ``.tmp-*`` folder, which is never read and
is removed by the next run of the stage. A folder without ``manifest.json`` is not an artifact.
"""

from __future__ import annotations

import datetime as _dt
import json
import os
import shutil
import time
import uuid
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping

from pipeline.artifacts.fingerprint import git_state, package_versions, sha256_file, source_hash

MANIFEST = "manifest.json"
LATEST = "latest"
TMP_PREFIX = ".tmp-"


class ArtifactError(RuntimeError):
    """A missing, incomplete or corrupted artifact; the message says what to do."""


@dataclass
class StageRun:
    """What a stage function receives: where to write and where to record results.

    Attributes:
        stage: stage name (``"generate"``, ...).
        version: the artifact's version key.
        work_dir: temporary folder to write every output file into.
        final_dir: where the artifact will live once complete (do not write there).
        metrics: filled by the stage; stored in the manifest.
        timings: seconds per phase, filled by the stage; stored in the manifest.
    """

    stage: str
    version: str
    work_dir: Path
    final_dir: Path
    config: dict[str, Any]
    upstream: dict[str, str]
    seed: int | None
    metrics: dict[str, Any] = field(default_factory=dict)
    timings: dict[str, float] = field(default_factory=dict)


def _now_iso() -> str:
    return _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")


def _hash_files(folder: Path) -> dict[str, dict[str, Any]]:
    files = {}
    for path in sorted(p for p in folder.rglob("*") if p.is_file()):
        rel = path.relative_to(folder).as_posix()
        if rel == MANIFEST:
            continue
        files[rel] = {"sha256": sha256_file(path), "bytes": path.stat().st_size}
    return files


def _point_latest(stage_dir: Path, version: str) -> None:
    tmp = stage_dir / f"{TMP_PREFIX}latest-{uuid.uuid4().hex[:8]}"
    os.symlink(version, tmp)
    os.replace(tmp, stage_dir / LATEST)


def _remove_stale_tmp(stage_dir: Path, max_age_s: float = 0.0) -> None:
    """Remove temporary folders left by interrupted runs (older than ``max_age_s``)."""
    now = time.time()
    for path in stage_dir.glob(f"{TMP_PREFIX}*"):
        try:
            if now - path.lstat().st_mtime < max_age_s:
                continue
            if path.is_dir() and not path.is_symlink():
                shutil.rmtree(path, ignore_errors=True)
            else:
                path.unlink(missing_ok=True)
        except FileNotFoundError:
            pass


class ArtifactWriter:
    """Create one artifact atomically. See the module docstring for the protocol."""

    def __init__(
        self,
        data_root: Path,
        stage: str,
        version: str,
        config: Mapping[str, Any],
        upstream: Mapping[str, str],
        seed: int | None = None,
    ) -> None:
        self.stage_dir = Path(data_root) / stage
        self.run = StageRun(
            stage=stage,
            version=version,
            work_dir=self.stage_dir / f"{TMP_PREFIX}{version}-{uuid.uuid4().hex[:8]}",
            final_dir=self.stage_dir / version,
            config=dict(config),
            upstream=dict(upstream),
            seed=seed,
        )

    def exists(self) -> bool:
        return (self.run.final_dir / MANIFEST).is_file()

    def __enter__(self) -> StageRun:
        self.stage_dir.mkdir(parents=True, exist_ok=True)
        # Only folders older than an hour: a concurrent run of the same stage may be writing.
        _remove_stale_tmp(self.stage_dir, max_age_s=3600.0)
        self.run.work_dir.mkdir()
        self._t0 = time.perf_counter()
        return self.run

    def __exit__(self, exc_type, exc, tb) -> bool:
        if exc_type is not None:
            shutil.rmtree(self.run.work_dir, ignore_errors=True)
            return False
        try:
            self._finish()
        except BaseException:
            shutil.rmtree(self.run.work_dir, ignore_errors=True)
            raise
        return False

    def _finish(self) -> None:
        run = self.run
        run.timings.setdefault("total_s", round(time.perf_counter() - self._t0, 3))
        manifest = {
            "stage": run.stage,
            "version": run.version,
            "created": _now_iso(),
            "config": run.config,
            "upstream": run.upstream,
            "code": {**git_state(), "source_hash": source_hash(run.stage)},
            "packages": package_versions(),
            "seed": run.seed,
            "files": _hash_files(run.work_dir),
            "metrics": run.metrics,
            "timings": run.timings,
        }
        tmp_manifest = run.work_dir / (MANIFEST + ".part")
        tmp_manifest.write_text(json.dumps(manifest, indent=2, sort_keys=True) + "\n")
        os.replace(tmp_manifest, run.work_dir / MANIFEST)
        _fsync_tree(run.work_dir)
        old = None
        if run.final_dir.exists():
            old = self.stage_dir / f"{TMP_PREFIX}old-{run.version}-{uuid.uuid4().hex[:8]}"
            os.replace(run.final_dir, old)
        os.replace(run.work_dir, run.final_dir)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
        _point_latest(self.stage_dir, run.version)


def _fsync_tree(folder: Path) -> None:
    for path in folder.rglob("*"):
        if path.is_file():
            fd = os.open(path, os.O_RDONLY)
            try:
                os.fsync(fd)
            finally:
                os.close(fd)


def run_stage(
    data_root: Path,
    stage: str,
    version: str,
    config: Mapping[str, Any],
    upstream: Mapping[str, str],
    body: Callable[[StageRun], None],
    *,
    seed: int | None = None,
    force: bool = False,
    say: Callable[[str], None] = print,
) -> Path:
    """Produce the artifact ``<data_root>/<stage>/<version>`` with ``body`` unless it exists.

    Returns the artifact folder. An existing, complete artifact is reused (and ``latest`` is
    pointed at it) unless ``force`` is true.
    """
    writer = ArtifactWriter(data_root, stage, version, config, upstream, seed)
    if writer.exists() and not force:
        _point_latest(writer.stage_dir, version)
        say(f"[{stage}] version {version} already exists at {writer.run.final_dir}: reusing it "
            f"(pass {stage}.force=true to recompute).")
        return writer.run.final_dir
    with writer as run:
        body(run)
    say(f"[{stage}] wrote version {version} to {run.final_dir}")
    return run.final_dir


def available_versions(data_root: Path, stage: str) -> list[str]:
    stage_dir = Path(data_root) / stage
    if not stage_dir.is_dir():
        return []
    return sorted(
        p.name for p in stage_dir.iterdir()
        if p.is_dir() and not p.is_symlink() and not p.name.startswith(".")
        and (p / MANIFEST).is_file()
    )


def resolve_artifact(data_root: Path, stage: str, version: str = "latest") -> Path:
    """Folder of a complete artifact, by version key or ``"latest"``; a clear error otherwise."""
    stage_dir = Path(data_root) / stage
    if not version or version.startswith(".") or "/" in version or "\\" in version:
        raise ArtifactError(f"'{version}' is not a version name: give a version key or 'latest'.")
    folder = stage_dir / version
    if (folder / MANIFEST).is_file():
        return folder.resolve()
    known = available_versions(data_root, stage)
    hint = (f"available versions: {', '.join(known)}" if known
            else f"none exist yet: run `make {stage}` (or `python -m pipeline.{stage}`) first")
    raise ArtifactError(
        f"No complete '{stage}' artifact named '{version}' under {stage_dir} ({hint})."
    )


def load_manifest(folder: Path) -> dict[str, Any]:
    path = Path(folder) / MANIFEST
    try:
        return json.loads(path.read_text())
    except FileNotFoundError:
        raise ArtifactError(f"{folder} has no {MANIFEST}: it is not a complete artifact.") from None
    except json.JSONDecodeError as e:
        raise ArtifactError(f"{path} is not valid JSON ({e}); recompute the stage with force=true.") from None


def verify_artifact(folder: Path) -> list[str]:
    """Re-hash an artifact's files against its manifest; returns a list of problems (empty = ok)."""
    folder = Path(folder)
    try:
        manifest = load_manifest(folder)
    except ArtifactError as e:
        return [str(e)]
    problems = []
    root = folder.resolve()
    for rel, meta in sorted(manifest.get("files", {}).items()):
        path = (folder / rel).resolve()
        if root not in path.parents:
            problems.append(f"{rel}: path points outside the artifact folder")
            continue
        if not path.is_file():
            problems.append(f"{rel}: missing")
            continue
        if path.stat().st_size != meta["bytes"] or sha256_file(path) != meta["sha256"]:
            problems.append(f"{rel}: changed (sha256 or size differs from the manifest)")
    listed = set(manifest.get("files", {}))
    for path in sorted(p for p in folder.rglob("*") if p.is_file()):
        rel = path.relative_to(folder).as_posix()
        if rel != MANIFEST and rel not in listed:
            problems.append(f"{rel}: not listed in the manifest")
    return problems
