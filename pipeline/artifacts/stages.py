"""Running a pipeline stage by name from another stage (the study stages: robustness, unseen).

A study stage runs the stages it needs with the command's own overrides plus its own; each run
is reused when its version already exists (``run_stage``), so a study after ``make reproduce``
recomputes only what differs.
"""

from __future__ import annotations

import importlib
from pathlib import Path


def run_named_stage(stage: str, overrides: list[str], caller: str) -> Path:
    """Run (or reuse) ``pipeline.<stage>`` with these Hydra overrides; its artifact folder.

    ``caller``: the study's name, printed with the command. Raises ``RuntimeError`` when the
    stage returns no folder (a non-zero torchrun rank)."""
    from pipeline.cli import compose

    fn = getattr(importlib.import_module(f"pipeline.{stage}"), stage)
    print(f"[{caller}] {stage} {' '.join(overrides)}", flush=True)
    out = fn(compose(stage, list(overrides)))
    if out is None:
        raise RuntimeError(f"[{caller}] the {stage} stage returned no artifact (a non-zero "
                           "torchrun rank?)")
    return Path(out)
