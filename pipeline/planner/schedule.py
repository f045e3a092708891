"""The learning rate of each training step (not the paper: Sec. 6 gives Adam at a constant 1e-4).

``constant``: ``train.lr`` at every step (the paper).

``onecycle`` (Smith and Topin, "Super-convergence", 2019; torch's ``OneCycleLR`` with
``anneal_strategy='cos'`` and two phases): the rate rises from ``max_lr / div_factor`` to
``max_lr`` over the first ``warmup_fraction`` of the steps along a half cosine, then falls along
a half cosine to ``max_lr / div_factor / final_div_factor`` at the last step. A high rate early
and an annealed one late reach the constant rate's validation loss in fewer epochs, which is
what the reproduce-time budget needs (docs/training.md, "Learning-rate schedule", gives the
measured comparison).

The rate is a pure function of the step index and the run's step count, set into the
optimiser before every step: a resumed run needs no scheduler state to continue on the same
curve (``tests/test_schedule.py`` checks it against ``torch.optim.lr_scheduler.OneCycleLR``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

SCHEDULES = ("constant", "onecycle")


@dataclass(frozen=True)
class ScheduleConfig:
    """``train.schedule`` with ``train.lr`` (see the module docstring)."""

    name: str  # "constant" | "onecycle"
    lr: float  # constant: the rate (paper: 1e-4)
    max_lr: float  # onecycle: the peak rate
    warmup_fraction: float  # onecycle: share of the steps spent rising to max_lr
    div_factor: float  # onecycle: the first rate is max_lr / div_factor
    final_div_factor: float  # onecycle: the last rate is that / final_div_factor

    def __post_init__(self):
        if self.name not in SCHEDULES:
            raise ValueError(f"train.schedule.name={self.name!r}; choose one of {SCHEDULES}")
        if self.name == "onecycle" and not 0.0 < self.warmup_fraction < 1.0:
            raise ValueError(
                f"train.schedule.warmup_fraction={self.warmup_fraction} must lie "
                "strictly between 0 and 1"
            )


def schedule_config(cfg) -> ScheduleConfig:
    """The schedule of a composed config (``train.lr`` and ``train.schedule``)."""
    s = cfg.train.schedule
    return ScheduleConfig(
        str(s.name),
        float(cfg.train.lr),
        float(s.max_lr),
        float(s.warmup_fraction),
        float(s.div_factor),
        float(s.final_div_factor),
    )


def _cos(start: float, end: float, pct: float) -> float:
    return end + (start - end) / 2.0 * (math.cos(math.pi * pct) + 1.0)


def learning_rate(step: int, total_steps: int, sc: ScheduleConfig) -> float:
    """The rate of optimiser step ``step`` (0-based) of a run of ``total_steps`` steps."""
    if sc.name == "constant":
        return sc.lr
    if not 0 <= step < total_steps:
        raise ValueError(f"step {step} outside a run of {total_steps} steps")
    initial = sc.max_lr / sc.div_factor
    final = initial / sc.final_div_factor
    peak_step = float(sc.warmup_fraction * total_steps) - 1.0
    if step <= peak_step:
        return _cos(initial, sc.max_lr, step / peak_step if peak_step > 0 else 1.0)
    return _cos(sc.max_lr, final, (step - peak_step) / (total_steps - 1 - peak_step))
