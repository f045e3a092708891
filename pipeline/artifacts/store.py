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


def resolve_artifact(data_root: Path, stage: str, version: str = "latest", *,
                     verify: bool = False, key: str | None = None) -> Path:
    """Folder of a complete artifact, by version key or ``"latest"``; a clear error otherwise.

    Args:
        verify: also re-hash its files against the manifest (``check_artifact``): what a stage
            does before reading an upstream artifact (about 0.15 s for the 80 MB generation
            artifact of ``default``, with the files in the page cache).
        key: the config key that asked for ``version`` (``"label.generate_version"``), named in
            the error message with the fix.

    Raises:
        ArtifactError: no such complete artifact (the message lists the available versions and
            the fix), or with ``verify`` a file that does not match the manifest.
    """
    stage_dir = Path(data_root) / stage
    version = str(version)
    asked = f"{key}={version}" if key else f"version '{version}'"
    who = f"[{key.split('.')[0]}] " if key else ""
    if not version or version.startswith(".") or "/" in version or "\\" in version:
        raise ArtifactError(f"{who}{asked}: '{version}' is not a version name: give a version "
                            "key or 'latest'.")
    folder = stage_dir / version
    if (folder / MANIFEST).is_file():
        folder = folder.resolve()
        return check_artifact(folder, key) if verify else folder
    known = available_versions(data_root, stage)
    if known:
        hint = f"available versions: {', '.join(known)}"
        fix = (f"pass {key}=<one of those> or {key}=latest" if key
               else "give one of those or 'latest'")
        fix += f", or run `make {stage}` (`python -m pipeline.{stage}`) to create it"
    else:
        hint = "none exist yet"
        fix = f"run `make {stage}` (or `python -m pipeline.{stage}`) first"
    raise ArtifactError(
        f"{who}{asked}: no complete '{stage}' artifact named '{version}' under {stage_dir} "
        f"({hint}). Fix: {fix}."
    )


def artifact_file(folder: Path, rel: str) -> Path:
    """``folder / rel`` for a file name read from an artifact (manifest.json, index.json,
    labels.json, ...), after checking that it stays inside the artifact folder.

    Raises:
        ArtifactError: ``rel`` is not a relative path, climbs out with ``..``, or leads outside
            ``folder`` through a symbolic link.
    """
    folder = Path(folder)
    bad = None
    if not isinstance(rel, str) or not rel or "\x00" in rel or "\\" in rel:
        bad = "is not a relative file name"
    elif rel.startswith("/") or (len(rel) > 1 and rel[1] == ":"):
        bad = "is an absolute path"
    elif ".." in rel.split("/"):
        bad = "climbs out of the artifact folder with '..'"
    else:
        root = folder.resolve()
        path = (folder / rel).resolve()
        if root not in path.parents:
            bad = "leads outside the artifact folder (through a symbolic link)"
    if bad is not None:
        stage = folder.resolve().parent.name
        raise ArtifactError(
            f"{folder}: the file name {rel!r} it lists {bad}; the artifact is corrupted or was "
            f"tampered with. Fix: recompute it (the {stage} stage with {stage}.force=true), or "
            "run `make verify` to list every problem.")
    return folder / rel


def check_artifact(folder: Path, key: str | None = None) -> Path:
    """``folder`` if its files match its manifest (``verify_artifact``); else ArtifactError
    naming the artifact, the bad files and the fix. ``key``: the config key that chose it."""
    problems = verify_artifact(folder)
    if not problems:
        return folder
    stage = Path(folder).resolve().parent.name
    shown = "; ".join(problems[:5])
    if len(problems) > 5:
        shown += f"; and {len(problems) - 5} more"
    who = f"[{key.split('.')[0]}] " if key else ""
    via = f" ({key})" if key else ""
    raise ArtifactError(
        f"{who}the '{stage}' artifact {folder}{via} does not match its manifest: {shown}. "
        f"Fix: recompute it (rerun the {stage} stage with the same settings and "
        f"{stage}.force=true), or run `make verify` to list every problem."
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
    files = manifest.get("files") if isinstance(manifest, dict) else None
    if not isinstance(files, dict):
        return [f"{MANIFEST}: has no 'files' table"]
    for rel, meta in sorted(files.items()):
        try:
            path = artifact_file(root, rel)
        except ArtifactError:
            problems.append(f"{rel}: path points outside the artifact folder")
            continue
        if not path.is_file():
            problems.append(f"{rel}: missing")
            continue
        try:
            size, sha = int(meta["bytes"]), str(meta["sha256"])
        except (KeyError, TypeError, ValueError):
            problems.append(f"{rel}: the manifest's entry lacks bytes / sha256")
            continue
        if path.stat().st_size != size:
            problems.append(f"{rel}: changed ({path.stat().st_size} bytes, the manifest says "
                            f"{size})")
        elif sha256_file(path) != sha:
            problems.append(f"{rel}: changed (sha256 differs from the manifest)")
    listed = set(files)
    for path in sorted(p for p in folder.rglob("*") if p.is_file()):
        rel = path.relative_to(folder).as_posix()
        if rel != MANIFEST and rel not in listed:
            problems.append(f"{rel}: not listed in the manifest")
    return problems
