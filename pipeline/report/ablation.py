"""Ablation section: what each execution extension of the closed loop contributes, from the
ablation artifact (``data/ablation/<version>``, ``report.ablation_version``; optional;
``pipeline.ablation``).

Table ``ablation``: per planner and variant, the closed loop's success rate, boxes picked, PPH
and failures (the manifest's ``metrics.ablation`` rows). No figure.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from pipeline.artifacts import ArtifactError
from pipeline.report.section import Context, Section
from pipeline.report.tables import Table, integer, number, pct, times
from pipeline.report.upstream import ArtifactInfo, resolve_upstream

ABLATION_SECTION = "Ablation: what each execution extension contributes"
ABLATION_NOT_RUN = "Ablation: not run yet (`make ablation`)."


class AblationInfo(ArtifactInfo):
    """The ablation artifact: folder and manifest, whose ``metrics.ablation`` are the rows."""

    @property
    def rows(self) -> list[dict]:
        """One row per planner and variant (``metrics.ablation``)."""
        return self.metrics["ablation"]

    @classmethod
    def load(cls, folder: Path, manifest: dict) -> AblationInfo:
        """Raises ``ArtifactError`` when the manifest lacks the rows."""
        rows = (manifest.get("metrics") or {}).get("ablation")
        if not isinstance(rows, list):
            raise ArtifactError(f"{folder.name}/manifest.json (ablation) lacks metrics.ablation; "
                                "recompute it with `make ablation` (ablation.force=true).")
        return cls(folder, manifest)


def resolve_ablation(root: Path, version: str) -> AblationInfo | None:
    """The ablation artifact to report, or None when ``version`` is "latest" and none exists."""
    return resolve_upstream(root, "ablation", version, AblationInfo.load)


def ablation_table(rows: list[dict]) -> Table:
    """The ablation rows (``metrics.ablation``) as a table; rates in percent."""
    headers = ["planner", "variant", "overrides", "success rate", "attempts", "boxes picked",
               "boxes picked (%)", "PPH (motion)", "no seal", "dropped", "collision",
               "lost target", "timeout", "trials ended: no grasp"]
    out = [[r["planner"], r["variant"], r["overrides"], times(r.get("success_rate")),
            integer(r.get("attempts")), f"{integer(r.get('picked'))}/{integer(r.get('boxes'))}",
            pct(int(r["picked"]), int(r["boxes"])), number(r.get("pph_motion")),
            integer(r.get("fail_no_seal")), integer(r.get("fail_dropped")),
            integer(r.get("fail_collision")), integer(r.get("fail_lost_target")),
            integer(r.get("fail_timeout")), integer(r.get("end_no_grasp"))] for r in rows]
    return Table("ablation", headers, out,
                 ["", "", "", "{:.1f} %", "{}", "{}", "{:.1f} %", "{}", "{}", "{}", "{}", "{}",
                  "{}", "{}"], text_columns=3)


def _meanings(rows: list[dict]) -> dict[str, str]:
    """Each variant's ``meaning`` (``ablation.variants``, stored with its rows), in row order;
    an artifact made before variants had one shows its overrides instead."""
    return {r["variant"]: r.get("meaning") or f"`{r['overrides']}`" for r in rows}


def render_ablation(info: AblationInfo | None, tables: dict[str, Table]) -> list[str]:
    """README lines of the ablation section."""
    out = [f"## {ABLATION_SECTION}", ""]
    if info is None:
        return out + [ABLATION_NOT_RUN, ""]
    trials = sorted({int(r["boxes"]) for r in info.rows})
    out += [
        f"Ablation artifact `{info.version}` (`python -m pipeline.ablation`): each extension "
        "of the closed loop turned off on its own, then all at once, on the same heaps as "
        "Table 3 (one evaluation artifact per row, named in the CSV). For the oracle the labels "
        "and the run-time check follow the same switches, so its rows show what the extension "
        "does to execution alone; the DCNN keeps the network trained on the default labels, "
        "and a variant changes its execution only. Boxes per planner and variant: "
        f"{', '.join(str(t) for t in trials)}.",
        "",
        tables["ablation"].markdown(),
        *[f"- *{name}*: {meaning}" for name, meaning in _meanings(info.rows).items()],
        "",
        "CSV version: [tables/ablation.csv](tables/ablation.csv).",
        "",
    ]
    return out


class AblationSection(Section):
    name = "ablation"

    def resolve(self, ctx: Context) -> AblationInfo | None:
        return resolve_ablation(ctx.root, ctx.requested("ablation"))

    def tables(self, info: AblationInfo, ctx: Context) -> list[Table]:
        return [ablation_table(info.rows)]

    def markdown(self, info: AblationInfo | None, tables: dict[str, Table],
                 figures: dict[str, str]) -> list[str]:
        return render_ablation(info, tables)

    def metrics(self, info: AblationInfo | None) -> dict[str, Any]:
        return {}  # the report's metrics name no ablation version (its upstream does)
