"""The report's tables (``Table``: one table, written as Markdown and as CSV) and the number
helpers the section modules share to turn manifest values into cells."""

from __future__ import annotations

import csv
import io
import re
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

    def _cell(self, value: Any, col: int, missing: str, formats: list[str]) -> str:
        if value is None:
            return missing
        fmt = formats[col] if col < len(formats) else ""
        return fmt.format(value) if fmt else str(value)

    def csv_text(self) -> str:
        formats = self.formats if self.csv_formats is None else self.csv_formats
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        w.writerow(self.headers)
        for row in self.rows:
            w.writerow([self._cell(v, i, "", formats) for i, v in enumerate(row)])
        return buf.getvalue()

    def markdown(self) -> str:
        align = ["---" if i < self.text_columns else "---:" for i in range(len(self.headers))]
        lines = ["| " + " | ".join(self.headers) + " |", "|" + "|".join(align) + "|"]
        for row in self.rows:
            lines.append("| " + " | ".join(self._cell(v, i, NONE, self.formats)
                                           for i, v in enumerate(row)) + " |")
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
