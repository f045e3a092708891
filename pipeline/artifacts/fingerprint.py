"""What produced an artifact: source hash, git state, package versions, file hashes."""

from __future__ import annotations

import hashlib
import subprocess
import sys
from functools import lru_cache
from importlib import metadata
from pathlib import Path

PACKAGE_ROOT = Path(__file__).resolve().parents[1]  # .../pipeline
REPO_ROOT = PACKAGE_ROOT.parent

# Packages whose version can change a stage's numbers; all are pinned in pyproject.toml.
KEY_PACKAGES = (
    "numpy",
    "pybullet",
    "torch",
    "open3d-cpu",
    "opencv-python-headless",
    "rerun-sdk",
    "mcap",
    "foxglove-sdk",
    "hydra-core",
    "matplotlib",
    "omegaconf",
)


def sha256_file(path: Path, chunk: int = 1 << 20) -> str:
    """Hex sha256 of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while block := f.read(chunk):
            h.update(block)
    return h.hexdigest()


@lru_cache(maxsize=1)
def source_hash() -> str:
    """sha256 over every ``pipeline/**/*.py`` file (relative path and bytes), sorted by path."""
    h = hashlib.sha256()
    for path in sorted(PACKAGE_ROOT.rglob("*.py")):
        if "__pycache__" in path.parts:
            continue
        h.update(path.relative_to(PACKAGE_ROOT).as_posix().encode())
        h.update(b"\0")
        h.update(path.read_bytes())
        h.update(b"\0")
    return h.hexdigest()


@lru_cache(maxsize=1)
def package_versions() -> dict[str, str]:
    """Installed versions of :data:`KEY_PACKAGES` and of Python itself."""
    versions = {"python": ".".join(map(str, sys.version_info[:3]))}
    for name in KEY_PACKAGES:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = "not-installed"
    return versions


@lru_cache(maxsize=1)
def git_state() -> dict[str, object]:
    """``{"commit": sha or None, "dirty": bool or None}`` of the repository holding the code."""

    def git(*args: str) -> str | None:
        try:
            out = subprocess.run(
                ["git", "-C", str(REPO_ROOT), *args],
                capture_output=True, text=True, timeout=10, check=True,
            )
        except (OSError, subprocess.SubprocessError):
            return None
        return out.stdout.strip()

    commit = git("rev-parse", "HEAD")
    if commit is None:
        return {"commit": None, "dirty": None}
    status = git("status", "--porcelain", "--untracked-files=no", "--", "pipeline", "conf")
    return {"commit": commit, "dirty": bool(status)}
