"""Open a stage's latest Rerun log in the viewer: ``python -m pipeline.tools.view generate``.

Without a display (no ``$DISPLAY`` / ``$WAYLAND_DISPLAY``) it prints the command to run on a
machine that has one, and the path of the MCAP file for Foxglove.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
from pathlib import Path

from pipeline.artifacts.fingerprint import REPO_ROOT
from pipeline.artifacts.store import ArtifactError, resolve_artifact

MODEL_STAGES = ("train",)  # artifacts under paths.models


def rerun_executable() -> str:
    local = Path(sys.executable).with_name("rerun")
    return str(local) if local.exists() else (shutil.which("rerun") or "rerun")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("stage", help="stage name, e.g. generate")
    parser.add_argument("version", nargs="?", default="latest")
    parser.add_argument(
        "--root", type=Path, default=Path(os.environ.get("BINPICK_ROOT", REPO_ROOT))
    )
    args = parser.parse_args(argv)
    top = args.root / ("models" if args.stage in MODEL_STAGES else "data")
    try:
        folder = resolve_artifact(top, args.stage, args.version)
    except ArtifactError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    rrd, mcap = folder / "log.rrd", folder / "log.mcap"
    if not rrd.is_file():
        print(f"error: {folder} has no log.rrd", file=sys.stderr)
        return 2
    cmd = [rerun_executable(), str(rrd)]
    if not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        print("No display here. On a machine with one, run:")
        print("  " + " ".join(cmd))
        print(f"The same data for Foxglove: {mcap}")
        return 0
    return subprocess.call(cmd)


if __name__ == "__main__":
    sys.exit(main())
