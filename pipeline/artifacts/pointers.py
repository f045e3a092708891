"""Keeping each stage's ``latest`` pointer where it was while a study runs extra variants.

A study stage (robustness, ablation) runs other stages with its own overrides; each of those
runs re-points its stage's ``latest``. The report reads ``latest`` by default, so the study
puts the pointers back afterwards: ``latest`` keeps naming the ``make reproduce`` pipeline.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from contextlib import contextmanager
from pathlib import Path

from pipeline.artifacts.store import LATEST, point_latest


@contextmanager
def keep_latest(stage_dirs: Iterable[Path]):
    """Leave the ``latest`` symlink of each of ``stage_dirs`` as it was on entry: restored where
    it existed, removed where it did not (a study's artifacts never become ``latest``)."""
    dirs = [Path(d) for d in stage_dirs]
    before = {d: os.readlink(d / LATEST) for d in dirs if (d / LATEST).is_symlink()}
    try:
        yield
    finally:
        for d in dirs:
            if d in before:
                point_latest(d, before[d])
            elif (d / LATEST).is_symlink():
                (d / LATEST).unlink()
