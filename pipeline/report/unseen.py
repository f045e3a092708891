"""Unseen-sizes section: Tables 1 and 2 on box sizes not seen in training, from the unseen-size
artifact (``data/unseen/<version>``, ``report.unseen_version``; optional;
``pipeline.stages.unseen``).

Tables ``unseen_table1`` (precision of the trained network, percent) and ``unseen_table2``
(every planner's share of optimal grasp points within the radius, pixels), each on the seen- and
the unseen-size test split; with the artifact's closed loop, ``unseen_closed_loop`` (Table 3's
books per planner on heaps of the unseen sizes) and ``unseen_drops_by_mass`` (how often each
pattern dropped a box, by mass). No figure.
"""

from __future__ import annotations

from pathlib import Path

from pipeline.report import tables as fmt
from pipeline.report.section import Context, Section
from pipeline.report.tables import Table, drops_table, table_of, text_column, trial_columns
from pipeline.report.upstream import ArtifactInfo, lacks_metrics, resolve_upstream

UNSEEN_SECTION = (
    "Unseen box sizes: Tables 1 and 2 and the closed loop on boxes not seen in training"
)
UNSEEN_NOT_RUN = "Unseen box sizes: not run yet (`make unseen`)."
METRIC_LISTS = ("table1", "table2", "boxes")


class UnseenInfo(ArtifactInfo):
    """The unseen-size artifact: folder and manifest (``metrics.table1``, ``table2``: rows per
    box-size set, ``boxes``: the unseen box types, sizes in metres)."""

    @classmethod
    def load(cls, folder: Path, manifest: dict) -> UnseenInfo:
        """Raises ``ArtifactError`` when the manifest lacks the tables or the boxes."""
        metrics = manifest.get("metrics") or {}
        if not all(isinstance(metrics.get(k), list) for k in METRIC_LISTS):
            raise lacks_metrics(folder, "unseen", "metrics.table1 / table2 / boxes")
        return cls(folder, manifest)


def resolve_unseen(root: Path, version: str) -> UnseenInfo | None:
    """The unseen-size artifact to report, or None when ``version`` is "latest" and none
    exists."""
    return resolve_upstream(root, "unseen", version, UnseenInfo.load)


def unseen_table1(metrics: dict) -> Table:
    """Table 1 of the trained network on the seen- and the unseen-size test split (percent)."""
    keys = (
        "top1",
        "top1pct",
        "top5pct",
        "top10pct",
        "per_image_top1pct",
        "per_image_top5pct",
        "per_image_top10pct",
    )
    headers = [
        "box sizes",
        "th",
        "Top 1",
        "Top 1 % (pooled)",
        "Top 5 % (pooled)",
        "Top 10 % (pooled)",
        "Top 1 % (per image)",
        "Top 5 % (per image)",
        "Top 10 % (per image)",
        "scored images",
        "no prediction",
    ]
    rows = [
        [
            r["set"],
            fmt.number(r.get("threshold")),
            *(fmt.times(r.get(k)) for k in keys),
            fmt.integer(r.get("scored_images")),
            fmt.integer(r.get("no_prediction_images")),
        ]
        for r in metrics["table1"]
    ]
    return Table(
        "unseen_table1",
        headers,
        rows,
        ["", "{:g}"] + ["{:.2f} %"] * len(keys) + ["{}", "{}"],
        text_columns=1,
    )


def unseen_table2(metrics: dict) -> Table:
    """Table 2 of every planner on the seen- and the unseen-size test split (percent)."""
    key, radius = fmt.within_key(metrics["table2"])
    headers = [
        "box sizes",
        "planner",
        f"less than {radius} px",
        "images",
        "no grasp",
        "median distance (px)",
    ]
    rows = [
        [
            r["set"],
            r.get("name", r["planner"]),
            fmt.times(r.get(key)),
            fmt.integer(r.get("images")),
            fmt.integer(r.get("no_grasp")),
            fmt.number(r.get("median_distance_px")),
        ]
        for r in metrics["table2"]
    ]
    return Table(
        "unseen_table2", headers, rows, ["", "", "{:.2f} %", "{}", "{}", "{:.1f}"], text_columns=2
    )


def unseen_closed_loop(metrics: dict) -> Table:
    """The closed loop on the unseen sizes: per planner, Table 3's books (success and boxes
    picked with their 95 % intervals), PPH, failures by kind, trial ends, why no attempt."""
    from pipeline.report.closed_loop import PLANNER_LABELS

    rows = [
        {**r, "label": PLANNER_LABELS.get(r["planner"], r["planner"])}
        for r in metrics.get("closed_loop") or []
    ]
    columns = [text_column("planner", "label"), *trial_columns()]
    return table_of("unseen_closed_loop", columns, rows)


def render_unseen(info: UnseenInfo, tables: dict[str, Table]) -> list[str]:
    """README lines of the unseen-sizes section."""
    out: list[str] = []
    sizes = ", ".join(
        f"{b['name']} {' x '.join(f'{1000 * x:g}' for x in b['size'])} mm"
        for b in info.metrics["boxes"]
    )
    out += [
        f"Unseen-size artifact `{info.version}` (`python -m pipeline.stages.unseen`): the trained "
        "network and the Dex-Net-style planners on a test split of heaps of boxes outside their "
        f"training distribution ({sizes}), beside the same tables on the paper's sizes' "
        "test split (*seen*, from the train and baseline artifacts). Definitions as in "
        "Tables 1 and 2 above; the network plans at its calibrated th.",
        "",
        tables["unseen_table1"].markdown(),
        tables["unseen_table2"].markdown(),
        "CSV versions: [tables/unseen_table1.csv](tables/unseen_table1.csv), "
        "[tables/unseen_table2.csv](tables/unseen_table2.csv).",
        "",
    ]
    if "unseen_closed_loop" in tables:
        evaluation = info.metrics.get("artifacts", {}).get("evaluate_unseen") or (
            info.manifest.get("upstream") or {}
        ).get("evaluate_unseen", "")
        out += [
            f"**The closed loop on the unseen sizes** (evaluation artifact `{evaluation}`): "
            "every planner on the same heaps of 12 boxes of the unseen sizes, drawn from the "
            "**test** stream, the robot deciding from its camera alone, as Table 3. Success "
            "rate = successful attempts / attempts, boxes picked = picked / boxes in the bins, "
            "each with its Wilson 95 % interval.",
            "",
            tables["unseen_closed_loop"].markdown(),
            "How often the pattern executed dropped a box that it had held at first, by box "
            "mass (mass = density × volume) and by the pattern the planner chose (a single "
            "cup planned as B is the execution's fallback, evaluate.single_cup_fallback; "
            "point: a single suction point):",
            "",
            tables["unseen_drops_by_mass"].markdown(),
            "CSV versions: [tables/unseen_closed_loop.csv](tables/unseen_closed_loop.csv), "
            "[tables/unseen_drops_by_mass.csv](tables/unseen_drops_by_mass.csv).",
            "",
        ]
    return out


class UnseenSection(Section):
    name, heading, not_run = "unseen", UNSEEN_SECTION, UNSEEN_NOT_RUN

    def resolve(self, ctx: Context) -> UnseenInfo | None:
        return resolve_unseen(ctx.root, ctx.requested("unseen"))

    def tables(self, info: UnseenInfo, ctx: Context) -> list[Table]:
        out = [unseen_table1(info.metrics), unseen_table2(info.metrics)]
        if info.metrics.get("closed_loop"):
            out += [
                unseen_closed_loop(info.metrics),
                drops_table("unseen_drops_by_mass", info.metrics.get("drops_by_mass") or []),
            ]
        return out

    def body(
        self, info: UnseenInfo, tables: dict[str, Table], figures: dict[str, str]
    ) -> list[str]:
        return render_unseen(info, tables)
