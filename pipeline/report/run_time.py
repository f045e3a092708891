"""How long the reported artifacts took to make: ``tables/run_time.csv`` (wall-clock, volatile).

Every artifact's manifest records the wall-clock seconds of the run that made it
(``timings.total_s``; a run resumed after an interruption records its last part only). This
table sums them per stage over every artifact the report reads and, following each manifest's
``upstream`` versions, every artifact those were made from (a study's noisy pipeline, the
ablation's and the robustness study's evaluations, the unseen-size heaps). Each artifact counts
once, however many artifacts were made from it. With the stages run one after another on one
machine, as ``make reproduce`` runs them, the total is the time they took (the set-up and the
report itself aside).
"""

from __future__ import annotations

from pathlib import Path
from typing import Iterable

from pipeline.artifacts import load_manifest
from pipeline.report.tables import Table

RUN_TIME_FILE = "tables/run_time.csv"
# The order of ``make reproduce``; a stage not listed here comes after them, by name.
STAGE_ORDER = ("generate", "label", "train", "baseline", "evaluate", "unseen", "ablation",
               "robustness")


def _folder(roots: Iterable[Path], version: str) -> Path | None:
    """The artifact folder ``<root>/<stage>/<version>`` holding a manifest, None if none."""
    for root in roots:
        for manifest in sorted(Path(root).glob(f"*/{version}/manifest.json")):
            return manifest.parent
    return None


def made_from(roots: Iterable[Path], versions: Iterable[str]) -> dict[str, dict]:
    """``{version: manifest}`` of the artifacts ``versions`` and, recursively, of every upstream
    version their manifests name that exists under one of ``roots`` (the data and models
    folders). A version that is not found (``none``, a removed artifact) is left out."""
    roots = [Path(r) for r in roots]
    found: dict[str, dict] = {}
    todo = [str(v) for v in versions]
    while todo:
        version = todo.pop()
        if version in found:
            continue
        folder = _folder(roots, version)
        if folder is None:
            continue
        found[version] = manifest = load_manifest(folder)
        todo += [str(v) for v in (manifest.get("upstream") or {}).values() if isinstance(v, str)]
    return found


def run_time_rows(manifests: dict[str, dict]) -> list[dict]:
    """Per stage: artifacts, their summed ``timings.total_s`` (s) and how many of them record
    none; stages in ``STAGE_ORDER``, then a ``total`` row."""
    per: dict[str, dict] = {}
    for manifest in manifests.values():
        stage = str(manifest.get("stage"))
        row = per.setdefault(stage, {"stage": stage, "artifacts": 0, "seconds": 0.0,
                                     "untimed": 0})
        row["artifacts"] += 1
        seconds = (manifest.get("timings") or {}).get("total_s")
        if isinstance(seconds, (int, float)) and not isinstance(seconds, bool):
            row["seconds"] += float(seconds)
        else:
            row["untimed"] += 1
    order = {s: i for i, s in enumerate(STAGE_ORDER)}
    rows = sorted(per.values(), key=lambda r: (order.get(r["stage"], len(order)), r["stage"]))
    total = {"stage": "total", "artifacts": sum(r["artifacts"] for r in rows),
             "seconds": sum(r["seconds"] for r in rows),
             "untimed": sum(r["untimed"] for r in rows)}
    return rows + [total] if rows else []


def run_time_table(roots: Iterable[Path], versions: Iterable[str]) -> Table:
    """The run-time table of the artifacts ``versions`` and those they were made from."""
    rows = run_time_rows(made_from(roots, versions))
    return Table("run_time", ["stage", "artifacts", "wall-clock (min)", "without a time"],
                 [[r["stage"], r["artifacts"], r["seconds"] / 60.0, r["untimed"]] for r in rows],
                 ["", "{}", "{:.1f}", "{}"], csv_formats=["", "{}", "{:.2f}", "{}"])
