"""The report's README.md: its header, the "Artifacts used" table, every section's Markdown,
the figure list and the closing note on the paper's tables."""

from __future__ import annotations

from collections.abc import Sequence

from pipeline.report.section import Section
from pipeline.report.tables import NONE, Table
from pipeline.report.upstream import ArtifactInfo

Part = tuple[Section, ArtifactInfo | None]  # a section and its artifact (None: not run yet)


def _commit(manifest: dict) -> str:
    code = manifest.get("code", {})
    commit = code.get("commit")
    if not commit:
        return "unknown"
    return f"`{commit[:10]}`" + (" (+ uncommitted changes)" if code.get("dirty") else "")


def render_readme(
    version: str,
    used: Sequence[Part],
    parts: Sequence[Part],
    tables: dict[str, Table],
    figures: dict[str, str],
) -> str:
    """The README of report artifact ``version``.

    ``used``: the sections in the order of the "Artifacts used" table (the artifacts found,
    then a "not run yet" row for each one missing); ``parts``: the sections in the README's
    order; ``tables`` by name and ``figures`` (relative path: caption) of the artifact.
    """
    out = [
        "# Bin-picking reproduction: report",
        "",
        f"Report artifact `{version}`, built by `python -m pipeline.report` (`make report`) "
        "from the "
        "artifacts below. Every number here is computed from those artifacts; nothing is copied "
        "from the paper.",
        "",
        "## Artifacts used",
        "",
        "| stage | version | git commit |",
        "|---|---|---|",
    ]
    for section, info in used:
        if info is not None:
            out.append(f"| {section.name} | `{info.version}` | {_commit(info.manifest)} |")
    for section, info in used:
        if info is None:
            out.append(f"| {section.name} | not run yet (`make {section.name}`) | {NONE} |")
    out += [
        "",
        "Each artifact lives in `data/<stage>/<version>/`; its `manifest.json` holds the full "
        "config, package versions, creation time and file hashes (`make verify` re-checks them).",
        "",
    ]
    if "run_time" in tables:
        out += [
            "How long each stage took to make these artifacts and those they were made from, "
            "summed from their manifests on the machines that ran them: "
            "[tables/run_time.csv](tables/run_time.csv) (wall-clock, so it is not part of the "
            "reproducibility check).",
            "",
        ]
    for section, info in parts:
        out += section.markdown(info, tables, figures)
    out += ["## Figures", ""]
    for rel, caption in figures.items():
        out += [f"![{caption}]({rel})", "", f"*{caption}*", ""]
    out += [
        "## Paper tables",
        "",
        "".join(
            section.paper_table_sentence(info)
            for section, info in parts
            if section.paper_table is not None
        ),
        "",
    ]
    return "\n".join(out)
