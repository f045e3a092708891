"""Whether two versions of a stage hold the same data.

A version hashes a stage's config, its upstream versions and the source of the code it runs, so a
code change that leaves a stage's output as it was (a refactor, a new option off by default)
still gives it a new version. ``same_data`` tells such versions apart from ones whose data
differ: every file of the two manifests but the logs (``log.rrd``, ``log.mcap``: they carry time
stamps and recording ids) has the same name, size and sha256. The manifests' hashes are trusted
here; ``check_artifact`` / ``make verify`` re-hash the files against them.
"""

from __future__ import annotations

from pathlib import Path

from pipeline.artifacts.store import ArtifactError, load_manifest
from pipeline.tracking.stage_log import MCAP_NAME, RRD_NAME

LOG_FILES = (RRD_NAME, MCAP_NAME)


def data_files(manifest: dict) -> dict:
    """A manifest's ``files`` (name → {bytes, sha256}) without the logs."""
    return {k: v for k, v in (manifest.get("files") or {}).items() if k not in LOG_FILES}


def same_data(stage_dir: Path, a: str, b: str) -> bool:
    """Whether versions ``a`` and ``b`` under ``stage_dir`` (e.g. ``data/generate``) are both
    complete artifacts whose files other than the logs are identical (and not none)."""
    if a == b:
        return True
    try:
        fa = data_files(load_manifest(Path(stage_dir) / a))
        fb = data_files(load_manifest(Path(stage_dir) / b))
    except ArtifactError:
        return False
    return bool(fa) and fa == fb
