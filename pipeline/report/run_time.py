"""How long the reported artifacts took to make: ``tables/run_time.csv`` (wall-clock, volatile).

Every artifact's manifest records the wall-clock seconds of the run that made it
(``timings.total_s``; a run resumed after an interruption records its last part only). This
table sums them per stage of ``make reproduce``: each reported artifact with, following the
manifests' ``upstream`` versions, every artifact it was made from that no earlier stage made
(the ablation's evaluations count as the ablation, the robustness study's noisy pipeline and
evaluations as the robustness study, the unseen-size heaps and their trials as the unseen
stage). Each artifact counts once, however many artifacts were made from it. With the stages
run one after another on one machine, as ``make reproduce`` runs them, the total is the time
they took (the set-up and the report itself aside). Beside each stage: its share of the total
and its budget (``report.run_time_budget_min``, docs/performance.md).
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

from pipeline.artifacts import load_manifest
from pipeline.report.tables import Table
from pipeline.runtime.cli import REPRODUCE_STAGES

RUN_TIME_FILE = "tables/run_time.csv"
# The order of ``make reproduce``; a stage not listed here comes after them, by name.
STAGE_ORDER = REPRODUCE_STAGES


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
        row = per.setdefault(stage, {"stage": stage, "artifacts": 0, "seconds": 0.0, "untimed": 0})
        row["artifacts"] += 1
        seconds = (manifest.get("timings") or {}).get("total_s")
        if isinstance(seconds, (int, float)) and not isinstance(seconds, bool):
            row["seconds"] += float(seconds)
        else:
            row["untimed"] += 1
    order = {s: i for i, s in enumerate(STAGE_ORDER)}
    rows = sorted(per.values(), key=lambda r: (order.get(r["stage"], len(order)), r["stage"]))
    total = {
        "stage": "total",
        "artifacts": sum(r["artifacts"] for r in rows),
        "seconds": sum(r["seconds"] for r in rows),
        "untimed": sum(r["untimed"] for r in rows),
    }
    return rows + [total] if rows else []


def by_stage(roots: Iterable[Path], reported: dict[str, str]) -> dict[str, dict]:
    """``{version: manifest}`` of each artifact the report reads or was made from, each under
    ``stage`` = the reported stage (``reported``: stage -> version) that first reaches it, stages
    in ``STAGE_ORDER``; the manifest copies carry that stage as ``stage``."""
    order = {s: i for i, s in enumerate(STAGE_ORDER)}
    out: dict[str, dict] = {}
    for stage in sorted(reported, key=lambda s: (order.get(s, len(order)), s)):
        for version, manifest in made_from(roots, [reported[stage]]).items():
            out.setdefault(version, {**manifest, "stage": stage})
    return out


def run_time_table(
    roots: Iterable[Path], reported: dict[str, str], budget_min: dict[str, float] | None = None
) -> Table:
    """The run-time table of the reported artifacts (stage -> version) and those they were made
    from, per stage of ``make reproduce``, with each stage's share of the total and its budget
    (min; none: no budget)."""
    rows = run_time_rows(by_stage(roots, reported))
    budget_min = budget_min or {}
    total = rows[-1]["seconds"] if rows else 0.0
    budgets = [budget_min.get(r["stage"]) for r in rows[:-1]]
    if rows:
        budgets.append(
            sum(b for b in budgets if b is not None)
            if any(b is not None for b in budgets)
            else None
        )
    return Table(
        "run_time",
        ["stage", "artifacts", "wall-clock (min)", "share (%)", "budget (min)", "without a time"],
        [
            [
                r["stage"],
                r["artifacts"],
                r["seconds"] / 60.0,
                100.0 * r["seconds"] / total if total > 0 else None,
                b,
                r["untimed"],
            ]
            for r, b in zip(rows, budgets)
        ],
        ["", "{}", "{:.1f}", "{:.0f}", "{:g}", "{}"],
        csv_formats=["", "{}", "{:.2f}", "{:.1f}", "{}", "{}"],
    )
