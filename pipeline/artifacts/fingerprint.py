"""What produced an artifact: source hash, git state, package versions, file hashes."""

from __future__ import annotations

import ast
import hashlib
import subprocess
import sys
from functools import cache, lru_cache
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
    "scikit-learn",
)


def sha256_file(path: Path, chunk: int = 1 << 20) -> str:
    """Hex sha256 of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while block := f.read(chunk):
            h.update(block)
    return h.hexdigest()


# Plumbing that cannot change a stage's numbers: the resolved config is hashed itself (so the
# schema and the CLI need not be), the artifact code writes manifests, not results, and the
# executor only decides where shards run (same artifact locally and on Ray: test_executor.py).
PLUMBING = ("pipeline.runtime", "pipeline.config", "pipeline.artifacts")


def stage_module(stage: str) -> str:
    """The module of a stage: ``pipeline.stages.<stage>``, or ``pipeline.<stage>`` for a stage
    that is a package of its own (``report``)."""
    if (PACKAGE_ROOT / "stages" / f"{stage}.py").is_file():
        return f"pipeline.stages.{stage}"
    return f"pipeline.{stage}"


def _module_path(name: str) -> Path | None:
    """File of module ``pipeline.a.b`` (``a/b.py`` or ``a/b/__init__.py``), None if none."""
    rel = Path(*name.split(".")[1:])
    if not rel.parts:  # the package itself (``from pipeline import x``)
        path = PACKAGE_ROOT / "__init__.py"
        return path if path.is_file() else None
    for path in (PACKAGE_ROOT / rel.with_suffix(".py"), PACKAGE_ROOT / rel / "__init__.py"):
        if path.is_file():
            return path
    return None


def _imports(path: Path, name: str) -> set[str]:
    """``pipeline.*`` modules imported anywhere in a file (module level or inside functions)."""
    tree = ast.parse(path.read_bytes(), filename=str(path))
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")
                parts = parts[: len(parts) - (node.level - 1)]
                base = ".".join(parts + ([base] if base else []))
            found.add(base)
            found.update(f"{base}.{a.name}" for a in node.names)  # submodules, if any
    return {m for m in found if m == "pipeline" or m.startswith("pipeline.")}


@cache
def import_closure(module: str) -> tuple[str, ...]:
    """Every ``pipeline`` module that ``module`` imports, transitively, itself included, and
    the packages (``__init__``) on the way; sorted. Found by parsing the source (``ast``), so
    imports inside functions count too."""
    seen: set[str] = set()
    todo = [module]
    while todo:
        name = todo.pop()
        if name in seen:
            continue
        path = _module_path(name)
        if path is None:
            continue  # a name imported from a module, not a module itself
        seen.add(name)
        parts = name.split(".")
        todo += [".".join(parts[:k]) for k in range(2, len(parts))]  # parent packages
        todo += sorted(_imports(path, name))
    return tuple(sorted(seen))


@cache
def source_hash(stage: str | None = None) -> str:
    """sha256 over the source a stage's result depends on (relative path and bytes, sorted).

    With ``stage``: the files of ``import_closure(stage_module(stage))`` except the
    :data:`PLUMBING` modules, plus the data files (non-Python, e.g. the robot's URDF) kept in
    the sub-folders of the packages in that closure. So editing the training code leaves the
    generation artifact's version alone. Without ``stage``, or for a stage with no module of its
    own: every ``pipeline/**/*.py`` file.
    """
    if stage is None or _module_path(stage_module(stage)) is None:
        files = [p for p in PACKAGE_ROOT.rglob("*.py") if "__pycache__" not in p.parts]
    else:
        modules = [
            m
            for m in import_closure(stage_module(stage))
            if not any(m == p or m.startswith(p + ".") for p in PLUMBING)
        ]
        files = [_module_path(m) for m in modules]
        for m in modules:
            path = _module_path(m)
            if path.name == "__init__.py" and m != "pipeline":
                files += [
                    p
                    for p in path.parent.rglob("*")
                    if p.is_file()
                    and p.suffix not in (".py", ".pyc")
                    and "__pycache__" not in p.parts
                    and p.parent != path.parent
                ]
    h = hashlib.sha256()
    for path in sorted(set(files)):
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
def platform_info() -> dict[str, str]:
    """The machine an artifact was made on: architecture, CPU model (``/proc/cpuinfo``'s first
    ``model name``, "" where there is none), operating system and C library. Not part of any
    version: the same code and config name the same artifact everywhere, but floating-point
    results (and with them the chaotic physics of a heap) can differ between CPUs
    (docs/artifacts.md, "Across machines"), and this says which machine made which bytes."""
    import platform

    cpu = ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    libc = " ".join(platform.libc_ver()).strip()
    return {
        "machine": platform.machine(),
        "cpu": cpu or platform.processor(),
        "system": f"{platform.system()} {platform.release()}",
        "libc": libc,
    }


@lru_cache(maxsize=1)
def git_state() -> dict[str, object]:
    """``{"commit": sha or None, "dirty": bool or None}`` of the repository holding the code."""

    def git(*args: str) -> str | None:
        try:
            out = subprocess.run(
                ["git", "-C", str(REPO_ROOT), *args],
                capture_output=True,
                text=True,
                timeout=10,
                check=True,
            )
        except (OSError, subprocess.SubprocessError):
            return None
        return out.stdout.strip()

    commit = git("rev-parse", "HEAD")
    if commit is None:
        return {"commit": None, "dirty": None}
    status = git("status", "--porcelain", "--untracked-files=no", "--", "pipeline", "conf")
    return {"commit": commit, "dirty": bool(status)}
