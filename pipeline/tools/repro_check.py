"""Reproducibility check (``make repro-check``): run the smoke pipeline twice, compare artifacts.

Each run goes into a fresh ``paths.root``; for every stage the two artifacts must have the same
version and the same sha256 for every file. Rerun logs are not byte-stable (chunk ids carry a
time stamp), so ``log.rrd`` files are compared by content with ``rerun rrd compare``, and where
that reports a difference, row by row regardless of chunking (``rrd_rows_equal``). Files a
manifest lists in ``metrics.volatile_files`` (measured wall-clock times, e.g. the report's
``tables/planning_time.csv``) are skipped, and the skip is printed.

    python -m pipeline.tools.repro_check [--keep] [--workdir DIR]

Exit status 0 when everything matches, 1 on any difference (each one is printed).
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

from pipeline.artifacts.fingerprint import stage_module
from pipeline.artifacts.store import available_versions, load_manifest, resolve_artifact
from pipeline.runtime.cli import REPRODUCE_STAGES
from pipeline.tools.view import MODEL_STAGES
from pipeline.tracking import rrd_equal

# The smoke pipeline, in order.
STAGES = (*REPRODUCE_STAGES, "report")


def rrd_rows(path: Path) -> list[str]:
    """The recording's rows as a sorted list of digests of (entity, static, timelines and
    component values), row ids left out: the data, whatever chunks the SDK cut it into."""
    import hashlib
    import json

    from rerun.chunk import RrdReader

    rows = []
    for chunk in RrdReader(str(path)).stream():
        batch = chunk.to_record_batch()
        names = [n for n in batch.schema.names if "RowId" not in n]
        cols = {n: _plain(batch.column(batch.schema.get_field_index(n))) for n in names}
        for k in range(batch.num_rows):
            row = json.dumps(
                [chunk.entity_path, chunk.is_static, {n: cols[n][k] for n in names}],
                sort_keys=True,
                default=str,
            )
            rows.append(hashlib.sha256(row.encode()).hexdigest())
    return sorted(rows)


def _plain(column) -> list:
    """A record batch column as Python values; durations and timestamps (a recording's duration
    and time-stamp timelines, in nanoseconds) as integer nanoseconds, which need no pandas."""
    import pyarrow as pa

    if pa.types.is_duration(column.type) or pa.types.is_timestamp(column.type):
        column = column.cast(pa.int64())
    return column.to_pylist()


def rrd_rows_equal(a: Path, b: Path) -> bool:
    """Same rows in both recordings (``rrd_rows``). ``rerun rrd compare`` compares chunk by
    chunk, so the same data split into other chunks (the SDK's batching) reads as different."""
    return rrd_rows(a) == rrd_rows(b)


def _rrd_compare_output(a: Path, b: Path) -> str:
    """The last lines of ``rerun rrd compare``'s output, to say what differs."""
    from pipeline.tools.view import rerun_executable

    res = subprocess.run(
        [rerun_executable(), "rrd", "compare", str(a), str(b)], capture_output=True, text=True
    )
    text = (res.stdout + res.stderr).strip().splitlines()
    return " | ".join(text[-3:]) if text else f"exit status {res.returncode}"


def run_pipeline(root: Path, extra: list[str]) -> None:
    for stage in STAGES:
        cmd = [
            sys.executable,
            "-m",
            stage_module(stage),
            "experiment=smoke",
            f"paths.root={root}",
            "logging.progress=false",
            *extra,
        ]
        print("$", " ".join(cmd), flush=True)
        subprocess.run(cmd, check=True)


def compare_artifacts(stage: str, a: Path, b: Path) -> list[str]:
    """Differences between two artifact folders of a stage (empty when identical): version,
    file list, sha256 of every file, Rerun logs by content; volatile files skipped."""
    if a.name != b.name:
        return [f"{stage}: versions differ ({a.name} vs {b.name})"]
    diffs = []
    ma, mb = load_manifest(a), load_manifest(b)
    fa, fb = ma["files"], mb["files"]
    volatile = set((ma.get("metrics") or {}).get("volatile_files") or [])
    for rel in sorted(set(fa) | set(fb)):
        if rel in volatile and rel in fa and rel in fb:
            print(f"[repro-check] {stage}/{rel}: skipped (wall-clock timings)")
        elif rel not in fa or rel not in fb:
            diffs.append(f"{stage}/{rel}: present in only one run")
        elif rel.endswith(".rrd"):
            if not rrd_equal(a / rel, b / rel) and not rrd_rows_equal(a / rel, b / rel):
                diffs.append(
                    f"{stage}/{rel}: Rerun recordings differ (rerun rrd compare: "
                    f"{_rrd_compare_output(a / rel, b / rel)})"
                )
        elif fa[rel]["sha256"] != fb[rel]["sha256"]:
            diffs.append(f"{stage}/{rel}: sha256 differs")
    print(f"[repro-check] {stage} {a.name}: {len(fa)} files compared")
    return diffs


def compare(root_a: Path, root_b: Path) -> list[str]:
    """Differences between the two runs' artifacts, every version of every stage (empty when
    identical)."""
    diffs = []
    for stage in STAGES:
        top = "models" if stage in MODEL_STAGES else "data"
        # every complete artifact (the robustness study makes several per stage)
        va, vb = available_versions(root_a / top, stage), available_versions(root_b / top, stage)
        if va != vb:
            diffs.append(f"{stage}: the runs made different versions ({va} vs {vb})")
        if not va:
            diffs.append(f"{stage}: no artifact in the first run")
        for version in sorted(set(va) & set(vb)):
            diffs += compare_artifacts(
                stage,
                resolve_artifact(root_a / top, stage, version),
                resolve_artifact(root_b / top, stage, version),
            )
    return diffs


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--workdir", type=Path, help="the two runs' folder (default: a temporary one)"
    )
    parser.add_argument("--keep", action="store_true", help="keep the two runs' folders")
    parser.add_argument("overrides", nargs="*", help="extra Hydra overrides for every stage")
    args = parser.parse_args(argv)
    work = Path(tempfile.mkdtemp(prefix="repro-check-", dir=args.workdir))
    try:
        for name in ("run1", "run2"):
            run_pipeline(work / name, args.overrides)
        diffs = compare(work / "run1", work / "run2")
    finally:
        if not args.keep:
            shutil.rmtree(work, ignore_errors=True)
        else:
            print(f"[repro-check] runs kept in {work}")
    if diffs:
        print("[repro-check] FAILED: the two runs differ:")
        for d in diffs:
            print("  " + d)
        return 1
    print("[repro-check] OK: both runs produced identical artifacts")
    return 0


if __name__ == "__main__":
    sys.exit(main())
