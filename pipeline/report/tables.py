"""The report's tables (``Table``: one table, written as Markdown and as CSV) and the number
helpers the section modules share to turn manifest values into cells.

Tables of dict rows (``table_of``) are made of ``Column``s: one Markdown cell each, standing
for one or more plain CSV columns. The closed-loop sections (Table 3, the ablation, the
robustness study) share their columns here (``rate_ci``, ``book_columns``, ``end_columns``,
``failure_columns``, ``pph_column``, ``reason_column``): the keys of an evaluation's
``metrics.table3`` rows (``pipeline.world.books.summarise``), a missing one shown as —.
"""

from __future__ import annotations

import csv
import io
import re
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

NONE = "—"  # shown in Markdown where a value does not exist (e.g. an empty split)


@dataclass
class Table:
    """A table written both as Markdown (formatted) and as CSV (plain values)."""

    name: str  # CSV file stem
    headers: list[str]
    rows: list[list[Any]]  # None = no value (empty split, no boxes of a type)
    formats: list[str] = field(default_factory=list)  # per column, e.g. "{:.2f}"; "" = str()
    csv_formats: list[str] | None = None  # the CSV's, when not ``formats`` ("" = full precision)
    text_columns: int = 1  # leading columns aligned left in Markdown
    left_columns: tuple[int, ...] = ()  # further columns aligned left (e.g. a trailing note)
    # The CSV's own columns and rows, when not the Markdown's (e.g. a rate and its interval:
    # one Markdown cell, three CSV columns); ``csv_formats`` then index these.
    csv_headers: list[str] | None = None
    csv_rows: list[list[Any]] | None = None

    def _cell(self, value: Any, col: int, missing: str, formats: list[str]) -> str:
        if value is None:
            return missing
        fmt = formats[col] if col < len(formats) else ""
        return fmt.format(value) if fmt else str(value)

    def csv_text(self) -> str:
        formats = self.formats if self.csv_formats is None else self.csv_formats
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        w.writerow(self.headers if self.csv_headers is None else self.csv_headers)
        for row in self.rows if self.csv_rows is None else self.csv_rows:
            w.writerow([self._cell(v, i, "", formats) for i, v in enumerate(row)])
        return buf.getvalue()

    def markdown(self) -> str:
        align = [
            "---" if i < self.text_columns or i in self.left_columns else "---:"
            for i in range(len(self.headers))
        ]
        lines = ["| " + " | ".join(self.headers) + " |", "|" + "|".join(align) + "|"]
        for row in self.rows:
            lines.append(
                "| "
                + " | ".join(self._cell(v, i, NONE, self.formats) for i, v in enumerate(row))
                + " |"
            )
        return "\n".join(lines) + "\n"


def pct(n: int, total: int) -> float | None:
    """Percentage, unrounded (the tables round it once, when formatting)."""
    return 100.0 * n / total if total else None


def number(value: Any) -> float | None:
    """A table value as a float; None for a missing or not-a-number value (shown as —)."""
    if value is None or isinstance(value, bool):
        return None
    try:
        x = float(value)
    except (TypeError, ValueError):
        return None
    return x if np.isfinite(x) else None


def integer(value: Any) -> int | None:
    """A table value rounded to an int; None where ``number`` gives None."""
    x = number(value)
    return None if x is None else int(round(x))


def times(value: Any, factor: float = 100.0) -> float | None:
    """``factor`` times a table value (a fraction as percent by default); None stays None."""
    x = number(value)
    return None if x is None else factor * x


def within_key(rows: list[dict]) -> tuple[str, str]:
    """The Table 2 rows' ``within_<r>px`` key and its radius as text (``"30"``)."""
    for r in rows:
        for k in r:
            m = re.fullmatch(r"within_(.+)px", k)
            if m:
                return k, m.group(1)
    return "within_30px", "30"


def fraction(n: Any, total: Any) -> float | None:
    """n / total as a fraction; None when either is missing or total is 0."""
    a, b = number(n), number(total)
    return None if a is None or not b else a / b


def ratio(n: Any, total: Any) -> str | None:
    """ "n/total" (integers), None when either is missing."""
    a, b = integer(n), integer(total)
    return None if a is None or b is None else f"{a}/{b}"


def rate_ci(rate: Any, low: Any, high: Any) -> str:
    """A rate and its 95 % interval (fractions) as percent to one decimal: "97.9 % (96.8–98.7)";
    the rate alone where the interval is missing (e.g. the paper's rows), — where the rate is
    (no attempt; NaN)."""
    r, lo, hi = times(rate), times(low), times(high)
    if r is None:
        return NONE
    return f"{r:.1f} %" if lo is None or hi is None else f"{r:.1f} % ({lo:.1f}–{hi:.1f})"


@dataclass(frozen=True)
class Column:
    """One column of a table of dict rows (``table_of``): its Markdown cell and the plain CSV
    columns it stands for."""

    header: str
    cell: Callable[[dict], Any]  # row -> Markdown value (None: —)
    fmt: str = ""  # the Markdown value's format ("" = str())
    # (header, row -> value, format) per CSV column; None: one, the Markdown's header and value
    # with ``csv_fmt`` (None: ``fmt``)
    csv: tuple[tuple[str, Callable[[dict], Any], str], ...] | None = None
    csv_fmt: str | None = None
    text: bool = False  # aligned left in Markdown

    def csv_columns(self) -> tuple[tuple[str, Callable[[dict], Any], str], ...]:
        if self.csv is not None:
            return self.csv
        return ((self.header, self.cell, self.fmt if self.csv_fmt is None else self.csv_fmt),)


def table_of(name: str, columns: list[Column], rows: list[dict], text_columns: int = 1) -> Table:
    """The table of ``rows``, one Markdown column and one or more CSV columns per column."""
    plain = [c for col in columns for c in col.csv_columns()]
    return Table(
        name,
        [c.header for c in columns],
        [[c.cell(r) for c in columns] for r in rows],
        [c.fmt for c in columns],
        csv_formats=[f for _, _, f in plain],
        text_columns=text_columns,
        left_columns=tuple(i for i, c in enumerate(columns) if c.text),
        csv_headers=[h for h, _, _ in plain],
        csv_rows=[[get(r) for _, get, _ in plain] for r in rows],
    )


def text_column(header: str, key: str) -> Column:
    """The row's ``key`` as text, aligned left (— where missing)."""
    return Column(header, lambda r: None if r.get(key) is None else str(r[key]), text=True)


def spread_column(header: str, key: str, csv_keys: tuple[str, ...]) -> Column:
    """The row's ``key`` in one Markdown column; in the CSV, the row's ``csv_keys`` (each in a
    column of its own, named by the key, empty where missing) in its place."""
    return Column(
        header, lambda r: r[key], csv=tuple((k, lambda r, k=k: r.get(k), "") for k in csv_keys)
    )


def count_column(header: str, key: str) -> Column:
    """The row's ``key`` as an integer (— where missing)."""
    return Column(header, lambda r: integer(r.get(key)))


PERCENT_CSV = "{:.2f}"  # the CSV's percentages (the Markdown's: one decimal)


def rate_column(name: str, key: str, rate: Callable[[dict], Any] | None = None) -> Column:
    """The rate ``<key>_rate`` with its 95 % interval ``<key>_ci_low`` – ``<key>_ci_high``
    (fractions; ``rate``: the row's rate where not that key): Markdown one cell (``rate_ci``),
    CSV three columns in percent."""
    get = rate or (lambda r: r.get(f"{key}_rate"))
    low, high = (lambda r: r.get(f"{key}_ci_low")), (lambda r: r.get(f"{key}_ci_high"))
    return Column(
        f"{name} (95 % CI)",
        lambda r: rate_ci(get(r), low(r), high(r)),
        csv=(
            (f"{name} (%)", lambda r: times(get(r)), PERCENT_CSV),
            (f"{name}, 95 % CI low (%)", lambda r: times(low(r)), PERCENT_CSV),
            (f"{name}, 95 % CI high (%)", lambda r: times(high(r)), PERCENT_CSV),
        ),
    )


def ratio_column(header: str, key: str, total: str, csv_header: str) -> Column:
    """Markdown "n/total" of the row's ``key`` and ``total``; CSV two integer columns."""
    return Column(
        header,
        lambda r: ratio(r.get(key), r.get(total)),
        csv=(
            (csv_header, lambda r: integer(r.get(key)), ""),
            (total, lambda r: integer(r.get(total)), ""),
        ),
    )


def picked_rate(row: dict) -> float | None:
    """Boxes picked / boxes (fraction): ``picked_rate``, or computed for rows made before it."""
    rate = number(row.get("picked_rate"))
    return rate if "picked_rate" in row else fraction(row.get("picked"), row.get("boxes"))


def book_columns() -> list[Column]:
    """Success rate (successful attempts / attempts) and boxes picked (picked / boxes in the
    bins), each with its Wilson 95 % interval, and their counts."""
    return [
        rate_column("success rate", "success"),
        ratio_column("successes / attempts", "successes", "attempts", "successes"),
        ratio_column("boxes picked", "picked", "boxes", "boxes picked"),
        rate_column("boxes picked", "picked", picked_rate),
    ]


def _pph(value: Any) -> Any:
    """Pieces per hour: a number, or the text a paper row gives (e.g. "over 1000")."""
    return value if isinstance(value, str) else number(value)


def pph_column(header: str = "PPH (motion only)") -> Column:
    """``pph_motion``: successful picks per hour of simulated robot motion (one decimal)."""

    def cell(r: dict) -> Any:
        v = _pph(r.get("pph_motion"))
        return f"{v:.1f}" if isinstance(v, float) else v

    return Column(header, cell, csv=((header, lambda r: _pph(r.get("pph_motion")), ""),))


TRIAL_END_NAMES = {
    "bin_empty": "bin empty",
    "no_grasp": "no grasp",
    "max_failures": "failure limit",
    "max_attempts": "attempt limit",
}


def end_columns() -> list[Column]:
    """How many trials ended each way (``end_<reason>``; ``pipeline.world.trial.TRIAL_ENDS``)."""
    from pipeline.world.trial import TRIAL_ENDS

    return [
        count_column(f"trials ended: {TRIAL_END_NAMES.get(e, e)}", f"end_{e}") for e in TRIAL_ENDS
    ]


def failure_columns() -> list[Column]:
    """Failed attempts by kind (``fail_<outcome>``; ``pipeline.world.trial.OUTCOMES``)."""
    from pipeline.world.trial import OUTCOMES

    return [count_column(f"failed: {k}", f"fail_{k}") for k in OUTCOMES[1:]]


def reason_column() -> Column:
    """Why a row made no attempt (``no_attempt_reason``: its trial ends and, for "no grasp",
    the candidates and what rejected them); empty for a row with attempts, — where unknown."""
    return text_column("no attempt: why", "no_attempt_reason")


def trial_columns(pph_header: str = "PPH (motion only)") -> list[Column]:
    """The columns of a closed-loop row: boxes picked and success with their intervals, PPH,
    the failures by kind, how the trials ended and why a row made no attempt."""
    return [
        *book_columns(),
        pph_column(pph_header),
        *failure_columns(),
        *end_columns(),
        reason_column(),
    ]


def drops_table(name: str, rows: list[dict]) -> Table:
    """How often each pattern dropped a box, by box mass (``drops_by_mass`` rows of an
    evaluation: planner, box, mass, pattern executed, pattern planned, held, dropped, drop rate
    with its 95 % interval)."""
    columns = [
        text_column("planner", "planner"),
        text_column("box", "box"),
        Column("mass (kg)", lambda r: number(r.get("mass_kg")), "{:.3f}"),
        text_column("pattern", "pattern"),
        text_column("planned", "planned"),
        count_column("held at first", "held"),
        count_column("dropped", "dropped"),
        rate_column("drop rate", "drop"),
    ]
    return table_of(name, columns, rows, text_columns=2)
