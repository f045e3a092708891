"""The architecture contracts of pyproject.toml ([tool.importlinter]) hold, and would catch a
robot-side module that imports the simulated world."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
LINT = Path(sys.executable).with_name("lint-imports")


def _lint(root: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [str(LINT), "--config", str(root / "pyproject.toml"), "--no-cache"],
        cwd=root,
        capture_output=True,
        text=True,
        timeout=120,
        env={"PYTHONPATH": str(root), "PATH": "/usr/bin:/bin"},
    )


def test_the_contracts_hold():
    out = _lint(REPO)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "0 broken" in out.stdout


def test_a_controller_module_importing_the_world_breaks_the_fence(tmp_path):
    """A copy of the package where the observation module imports the world cell, as a
    robot-side shortcut to the truth would: the contract is broken, and lint-imports says so."""
    shutil.copytree(
        REPO / "pipeline",
        tmp_path / "pipeline",
        ignore=shutil.ignore_patterns("__pycache__", "*.urdf", "urdf"),
    )
    shutil.copy(REPO / "pyproject.toml", tmp_path / "pyproject.toml")
    victim = tmp_path / "pipeline" / "controller" / "retry.py"
    victim.write_text(
        victim.read_text() + "\n\ndef _peek():\n"
        "    from pipeline.world.cell import PickCell  # the truth\n"
        "    return PickCell\n"
    )
    out = _lint(tmp_path)
    assert out.returncode == 1, out.stdout + out.stderr
    assert "robot side imports nothing of the simulated world" in out.stdout
    assert (
        "BROKEN" in out.stdout and "pipeline.controller.retry -> pipeline.world.cell" in out.stdout
    )


def test_an_upward_import_breaks_the_layers(tmp_path):
    """A copy of the package where the camera (a bottom layer) imports a stage: the layers
    contract is broken, and lint-imports names the import."""
    shutil.copytree(
        REPO / "pipeline",
        tmp_path / "pipeline",
        ignore=shutil.ignore_patterns("__pycache__", "*.urdf", "urdf"),
    )
    shutil.copy(REPO / "pyproject.toml", tmp_path / "pyproject.toml")
    victim = tmp_path / "pipeline" / "camera" / "geometry.py"
    victim.write_text(
        victim.read_text() + "\n\ndef _up():\n    from pipeline.stages import train\n\n"
        "    return train\n"
    )
    out = _lint(tmp_path)
    assert out.returncode == 1, out.stdout + out.stderr
    assert "Imports point down the layers" in out.stdout and "BROKEN" in out.stdout
    assert "pipeline.camera.geometry -> pipeline.stages.train" in out.stdout


def test_ruff_lint_and_format_are_clean():
    ruff = Path(sys.executable).with_name("ruff")
    for args in (["check", "."], ["format", "--check", "."]):
        out = subprocess.run(
            [str(ruff), *args], cwd=REPO, capture_output=True, text=True, timeout=120
        )
        assert out.returncode == 0, f"ruff {' '.join(args)}:\n{out.stdout}{out.stderr}"


MAX_MODULE_LINES, MAX_FUNCTION_LINES = 600, 100


def test_rooms_a_person_can_hold_in_mind():
    """No module of the package over 600 lines and no function over 100 (decorators included)."""
    import ast

    too_long = []
    for path in sorted((REPO / "pipeline").rglob("*.py")):
        text = path.read_text()
        rel = path.relative_to(REPO)
        if len(text.splitlines()) > MAX_MODULE_LINES:
            too_long.append(f"{rel}: {len(text.splitlines())} lines")
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                start = min([node.lineno] + [d.lineno for d in node.decorator_list])
                if node.end_lineno - start + 1 > MAX_FUNCTION_LINES:
                    too_long.append(f"{rel}:{node.lineno} {node.name}")
    assert too_long == [], too_long
