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
    return subprocess.run([str(LINT), "--config", str(root / "pyproject.toml"), "--no-cache"],
                          cwd=root, capture_output=True, text=True, timeout=120,
                          env={"PYTHONPATH": str(root), "PATH": "/usr/bin:/bin"})


def test_the_contracts_hold():
    out = _lint(REPO)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "0 broken" in out.stdout


def test_a_controller_module_importing_the_world_breaks_the_fence(tmp_path):
    """A copy of the package where the observation module imports the world cell, as a
    robot-side shortcut to the truth would: the contract is broken, and lint-imports says so."""
    shutil.copytree(REPO / "pipeline", tmp_path / "pipeline",
                    ignore=shutil.ignore_patterns("__pycache__", "*.urdf", "urdf"))
    shutil.copy(REPO / "pyproject.toml", tmp_path / "pyproject.toml")
    victim = tmp_path / "pipeline" / "controller" / "retry.py"
    victim.write_text(victim.read_text() + "\n\ndef _peek():\n"
                      "    from pipeline.world.cell import PickCell  # the truth\n"
                      "    return PickCell\n")
    out = _lint(tmp_path)
    assert out.returncode == 1, out.stdout + out.stderr
    assert "robot side imports nothing of the simulated world" in out.stdout
    assert "BROKEN" in out.stdout and "pipeline.controller.retry -> pipeline.world.cell" \
        in out.stdout
