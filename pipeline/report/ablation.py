"""Ablation section: what each execution extension of the closed loop contributes, from the
ablation artifact (``data/ablation/<version>``, ``report.ablation_version``; optional;
``pipeline.stages.ablation``).

Table ``ablation``: per planner and variant (every run on the ``dev`` split), the closed loop's
success rate and boxes picked with their Wilson 95 % intervals, PPH, the failures by kind, how
the trials ended and why a row made no attempt (the manifest's ``metrics.ablation`` rows; a key
an older artifact lacks shows as —). No figure.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from pipeline.report.section import Context, Section
from pipeline.report.tables import Table, integer, table_of, text_column, trial_columns
from pipeline.report.upstream import ArtifactInfo, lacks_metrics, resolve_upstream

ABLATION_SECTION = "Ablation: what each execution extension contributes"
ABLATION_NOT_RUN = "Ablation: not run yet (`make ablation`)."
SPLIT = (
    "dev"  # every ablation run's (pipeline.stages.ablation.SPLIT); Table 3's headline is on test
)
SIMULATOR_KNOWLEDGE = "simulator_knowledge"  # the variant whose check sees the true boxes


class AblationInfo(ArtifactInfo):
    """The ablation artifact: folder and manifest, whose ``metrics.ablation`` are the rows."""

    @property
    def rows(self) -> list[dict]:
        """One row per planner and variant (``metrics.ablation``)."""
        return self.metrics["ablation"]

    @property
    def trials(self) -> int | None:
        """Trials per planner and variant (the config's ``ablation.trials``; None: unknown)."""
        return integer(((self.manifest.get("config") or {}).get("ablation") or {}).get("trials"))

    @classmethod
    def load(cls, folder: Path, manifest: dict) -> AblationInfo:
        """Raises ``ArtifactError`` when the manifest lacks the rows."""
        rows = (manifest.get("metrics") or {}).get("ablation")
        if not isinstance(rows, list):
            raise lacks_metrics(folder, "ablation", "metrics.ablation")
        return cls(folder, manifest)


def resolve_ablation(root: Path, version: str) -> AblationInfo | None:
    """The ablation artifact to report, or None when ``version`` is "latest" and none exists."""
    return resolve_upstream(root, "ablation", version, AblationInfo.load)


def ablation_table(rows: list[dict]) -> Table:
    """The ablation rows (``metrics.ablation``) as a table: rates in percent with their 95 %
    intervals (CSV: rate and bounds in columns of their own)."""
    columns = [
        text_column("planner", "planner"),
        text_column("variant", "variant"),
        text_column("overrides", "overrides"),
        *trial_columns("PPH (motion)"),
    ]
    return table_of("ablation", columns, rows, text_columns=3)


def _meanings(rows: list[dict]) -> dict[str, str]:
    """Each variant's ``meaning`` (``ablation.variants``, stored with its rows), in row order;
    an artifact made before variants had one shows its overrides instead."""
    return {r["variant"]: r.get("meaning") or f"`{r['overrides']}`" for r in rows}


def render_ablation(info: AblationInfo, tables: dict[str, Table]) -> list[str]:
    """README lines of the ablation section."""
    boxes = sorted({integer(r.get("boxes")) for r in info.rows} - {None})
    trials = info.trials
    knowledge = any(r.get("variant") == SIMULATOR_KNOWLEDGE for r in info.rows)
    return [
        f"Ablation artifact `{info.version}` (`python -m pipeline.stages.ablation`): "
        "each extension "
        "of the closed loop turned off on its own, then all at once, every run on the "
        f"**{SPLIT} split**: the heaps development used, the same for every row"
        + (f", {trials} trials per planner and variant" if trials is not None else "")
        + "; Table 3's headline rows are measured on the test split, which nothing here is "
        "chosen on (one evaluation artifact per row, named in the CSV). For the oracle the "
        "labels and the run-time check follow the same switches, so its rows show what the "
        "extension does to execution alone; the DCNN keeps the network trained on the default "
        "labels, and a variant changes its execution only. "
        + (
            f"*{SIMULATOR_KNOWLEDGE}* is no extension but a measure: it gives the run-time check "
            "the heap's true boxes, ground truth a real cell lacks, to show what the robot's own "
            "model of the heap (from its depth image) costs. "
            if knowledge
            else ""
        )
        + f"Boxes per planner and variant: {', '.join(str(b) for b in boxes)}. Success rate "
        "and boxes picked with their Wilson 95 % score intervals in brackets; failures by kind "
        "as in Table 3's list; a row with no attempt says why in its last column.",
        "",
        tables["ablation"].markdown(),
        *[f"- *{name}*: {meaning}" for name, meaning in _meanings(info.rows).items()],
        "",
        "CSV version: [tables/ablation.csv](tables/ablation.csv).",
        "",
    ]


class AblationSection(Section):
    name, heading, not_run = "ablation", ABLATION_SECTION, ABLATION_NOT_RUN

    def resolve(self, ctx: Context) -> AblationInfo | None:
        return resolve_ablation(ctx.root, ctx.requested("ablation"))

    def tables(self, info: AblationInfo, ctx: Context) -> list[Table]:
        return [ablation_table(info.rows)]

    def body(
        self, info: AblationInfo, tables: dict[str, Table], figures: dict[str, str]
    ) -> list[str]:
        return render_ablation(info, tables)

    def metrics(self, info: AblationInfo | None) -> dict[str, Any]:
        return {}  # the report's metrics name no ablation version (its upstream does)
