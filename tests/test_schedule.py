"""The learning-rate schedule (pipeline/planner/schedule.py): hand-worked values and torch's
OneCycleLR as the reference implementation."""

import math

import pytest
import torch

from pipeline.planner.schedule import ScheduleConfig, learning_rate, schedule_config
from pipeline.runtime.cli import compose


def onecycle(max_lr=1e-3, warmup=0.3, div=25.0, final=1e4) -> ScheduleConfig:
    return ScheduleConfig("onecycle", 1e-4, max_lr, warmup, div, final)


def test_constant_is_the_paper_rate_at_every_step():
    sc = ScheduleConfig("constant", 1e-4, 1e-3, 0.3, 25.0, 1e4)
    assert {learning_rate(s, 10, sc) for s in range(10)} == {1e-4}


def test_onecycle_by_hand():
    # 11 steps, warm-up 0.2: the peak at step 0.2 * 11 - 1 = 1.2, the end at step 10.
    sc = onecycle(max_lr=1.0, warmup=0.2, div=10.0, final=100.0)
    assert learning_rate(0, 11, sc) == pytest.approx(0.1)  # max_lr / div
    # step 1 of the rise: pct = 1 / 1.2; 1 + (0.1 - 1) / 2 * (cos(pi / 1.2) + 1)
    assert learning_rate(1, 11, sc) == pytest.approx(1 - 0.45 * (math.cos(math.pi / 1.2) + 1))
    # the last step (10) ends at max_lr / div / final = 0.1 / 100
    assert learning_rate(10, 11, sc) == pytest.approx(1e-3)
    mid = (learning_rate(5, 11, sc), learning_rate(6, 11, sc))
    assert mid[0] > (1.0 + 1e-3) / 2 > mid[1]  # the half-cosine's midpoint lies between 5 and 6


@pytest.mark.parametrize("steps,warmup", [(150 * 12, 0.3), (37, 0.25), (5, 0.5)])
def test_onecycle_matches_torch(steps, warmup):
    sc = onecycle(warmup=warmup)
    opt = torch.optim.SGD([torch.nn.Parameter(torch.zeros(1))], lr=sc.max_lr)
    ref = torch.optim.lr_scheduler.OneCycleLR(
        opt,
        max_lr=sc.max_lr,
        total_steps=steps,
        pct_start=warmup,
        anneal_strategy="cos",
        div_factor=sc.div_factor,
        final_div_factor=sc.final_div_factor,
        cycle_momentum=False,
    )
    for step in range(steps):
        assert learning_rate(step, steps, sc) == pytest.approx(
            opt.param_groups[0]["lr"], rel=1e-9
        ), step
        opt.step()
        ref.step()


def test_bad_schedule_is_named():
    with pytest.raises(ValueError, match="train.schedule.name='cyclic'"):
        ScheduleConfig("cyclic", 1e-4, 1e-3, 0.3, 25.0, 1e4)
    with pytest.raises(ValueError, match="warmup_fraction"):
        onecycle(warmup=1.0)
    with pytest.raises(ValueError, match="outside a run of 10 steps"):
        learning_rate(10, 10, onecycle())


def test_composed_configs_have_a_schedule():
    for experiment in ("smoke", "default", "paper"):
        sc = schedule_config(compose("train", [f"experiment={experiment}"]))
        assert sc.name in ("constant", "onecycle")
    assert schedule_config(compose("train", ["experiment=paper"])).name == "constant"
