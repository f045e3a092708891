"""CSV tables of stage artifacts: one row per dict, the first row's keys as the header."""

from __future__ import annotations

import csv
from collections.abc import Sequence
from pathlib import Path


def write_rows(path: Path, rows: list[dict], empty_header: Sequence[str] = ("empty",)) -> None:
    """Write ``rows`` to ``path`` (Unix line ends); no rows: a header of ``empty_header``."""
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(
            f, fieldnames=list(rows[0]) if rows else list(empty_header), lineterminator="\n"
        )
        w.writeheader()
        w.writerows(rows)
