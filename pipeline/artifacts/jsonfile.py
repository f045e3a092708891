"""Strict JSON files of stage artifacts: NaN and ±inf become null, never invalid JSON."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np


def json_safe(obj):
    """``obj`` with every NaN and ±inf float (e.g. the success rate of a variant with no
    attempt, the median distance of a planner that never found a grasp) → None (JSON null)."""
    if isinstance(obj, float):
        return obj if np.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_safe(v) for v in obj]
    return obj


def write_json(path: Path, obj) -> None:
    """``json_safe(obj)`` to ``path``, indented, strict (``allow_nan=False``)."""
    Path(path).write_text(json.dumps(json_safe(obj), indent=1, allow_nan=False) + "\n")
