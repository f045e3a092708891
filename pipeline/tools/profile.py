"""Where a stage's time goes: run it under py-spy and print the share of each part of the method.

    python -m pipeline.tools.profile label experiment=smoke            # make profile STAGE=label
    python -m pipeline.tools.profile evaluate --rate 50 evaluate.num_trials=4
    python -m pipeline.tools.profile --summarise data/profile/label.txt  # an earlier sample

The stage runs as ``python -m pipeline.stages.<stage> <overrides>`` under ``py-spy record``
(``--subprocesses``: the worker processes are sampled too; ``--nonblocking``: the stage is never
paused), which writes every sample's Python stack to ``<out>/<stage>.txt`` (py-spy's "raw"
format: one line per distinct stack, ``frame;frame;... count``). The summary gives each sample
to the first part of the method, in the order of :data:`PARTS`, whose modules stand on its
stack (so the servo's motion prediction inside the labels' robot check counts as "servo", and
torch's backward pass inside training as "backward"). Time spent
in C (pybullet's stepSimulation, torch's kernels, Open3D's RANSAC) is charged to the Python
frame that called it. A sample is one process at one instant: with two workers busy, a
stage's wall second holds about two seconds of samples.

The figures are measured on the machine that runs the command; nothing is written besides the
sample file. ``docs/performance.md`` says which part of each stage could go faster and how.
"""

from __future__ import annotations

import argparse
import collections
import re
import shutil
import subprocess
import sys
from pathlib import Path

from pipeline.artifacts.fingerprint import REPO_ROOT, stage_module

# (part of the method, the frames that belong to it): a frame is "<function> (<file>:<line>)",
# matched by ``re.search``. A sample belongs to the first part in this order that any frame of
# its stack matches, so the order goes from the specific to the general: torch's backward pass
# inside training is "backward", the servo's motion prediction inside the labels' robot check
# is "servo", and the robot's decisions inside a closed-loop trial are not "physics".
PARTS: tuple[tuple[str, str], ...] = (
    ("backward", r"_engine_run_backward|torch/autograd"),
    ("forward", r"torch/nn/|torch/_ops|torch/functional"),
    ("optimiser", r"torch/optim/"),
    ("data loading", r"pipeline/planner/(data|augment|targets|normalisation)\.py|torch/utils/data"),
    ("rendering", r"pipeline/camera/(render|raycast|raycast_convex|raycast_kernels)\.py"),
    ("sensor model", r"pipeline/camera/(sensor|randomise|depth_filter)\.py"),
    ("servo", r"pipeline/servo/"),
    ("robot checks (IK, collisions)", r"pipeline/robot/|pipeline/labelling/grasp_check\.py"),
    ("surfaces (RANSAC, regions)", r"pipeline/grasping/surfaces\.py|open3d"),
    ("suction contact model", r"pipeline/dexnet/contact(_mesh)?\.py|pipeline/grasping/suction"),
    ("physics", r"pipeline/simulation/"),
    ("CEM and GQ-CNN", r"pipeline/dexnet/(cem|gqcnn|sampling|quality|planner|training|labels)\.py"),
    (
        "DCNN planning",
        r"pipeline/planner/(planner|decode|ranking|scoring|evaluate|calibration)\.py",
    ),
    ("heap model and checks", r"pipeline/controller/"),
    ("the world's steps", r"pipeline/world/"),
    ("labels (hand level)", r"pipeline/labelling/|pipeline/grasping/"),
    ("storage", r"zipfile|pipeline/dataset/storage\.py|_hash_files|_fsync_tree"),
    ("logs", r"pipeline/tracking/|rerun|mcap|foxglove"),
)
OTHER = "other"


def parse_raw(text: str) -> list[tuple[list[str], int]]:
    """py-spy raw lines ``frame;frame;... count`` as (frames, outermost first; count)."""
    samples = []
    for line in text.splitlines():
        stack, _, count = line.rstrip().rpartition(" ")
        if stack and count.isdigit():
            samples.append((stack.split(";"), int(count)))
    return samples


def part_of(frames: list[str]) -> str:
    """The part of the method a sample belongs to: the first of :data:`PARTS` that matches
    any of its frames; :data:`OTHER` when none does."""
    for name, pattern in PARTS:
        if any(re.search(pattern, frame) for frame in frames):
            return name
    return OTHER


def summarise(samples: list[tuple[list[str], int]]) -> list[tuple[str, int, float]]:
    """(part, samples, share of all samples) for every part with samples, largest first."""
    counts: collections.Counter[str] = collections.Counter()
    for frames, n in samples:
        counts[part_of(frames)] += n
    total = sum(counts.values())
    return [(name, n, n / total) for name, n in counts.most_common()] if total else []


def print_summary(path: Path) -> None:
    rows = summarise(parse_raw(path.read_text()))
    total = sum(n for _, n, _ in rows)
    print(f"{path}: {total} samples")
    for name, n, share in rows:
        print(f"  {100 * share:5.1f} %  {name}  ({n})")


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """The command line: the stage, its Hydra overrides and the options, which may stand
    anywhere among them (``evaluate --rate 50 evaluate.num_trials=4``)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("stage", nargs="?", help="stage name, e.g. label")
    parser.add_argument("overrides", nargs="*", help="Hydra overrides for the stage")
    parser.add_argument("--rate", type=int, default=20, help="samples per second (20)")
    parser.add_argument("--out", type=Path, default=REPO_ROOT / "data" / "profile")
    parser.add_argument("--summarise", type=Path, help="summarise this sample file only")
    args = parser.parse_intermixed_args(argv)
    if args.summarise is None and not args.stage:
        parser.error("name a stage (e.g. label) or give --summarise FILE")
    return args


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    if args.summarise is not None:
        print_summary(args.summarise)
        return 0
    beside = Path(sys.executable).with_name("py-spy")  # the project's environment first
    spy = str(beside) if beside.exists() else shutil.which("py-spy")
    if spy is None:
        print(
            "error: py-spy is not installed: run `make setup` (it is in requirements.lock)",
            file=sys.stderr,
        )
        return 2
    args.out.mkdir(parents=True, exist_ok=True)
    out = args.out / f"{args.stage}.txt"
    cmd = [
        spy,
        "record",
        "--subprocesses",
        "--nonblocking",
        "--rate",
        str(args.rate),
        "--format",
        "raw",
        "-o",
        str(out),
        "--",
        sys.executable,
        "-m",
        stage_module(args.stage),
        *args.overrides,
    ]
    print("$", " ".join(cmd), flush=True)
    rc = subprocess.run(cmd, cwd=REPO_ROOT).returncode
    if rc != 0 or not out.is_file():
        print(f"error: the profiled stage exited with status {rc}", file=sys.stderr)
        return rc or 1
    print_summary(out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
