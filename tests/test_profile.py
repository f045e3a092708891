"""The profile summary (pipeline.tools.profile) on py-spy samples written by hand."""

from __future__ import annotations

import pytest

from pipeline.tools.profile import OTHER, parse_raw, part_of, summarise

RAW = "\n".join(
    [
        # 6 samples of the labels' robot check, 4 of them in the servo's predicted motion
        "main (pipeline/stages/label.py:1);check_grasp (pipeline/labelling/grasp_check.py:9);"
        "servo_motion (pipeline/servo/predict.py:80) 4",
        "main (pipeline/stages/label.py:1);check_grasp (pipeline/labelling/grasp_check.py:9);"
        "in_collision (pipeline/robot/model.py:300) 2",
        # 8 samples of training: 5 in backward, 3 in the forward pass
        "fit (pipeline/planner/fit.py:1);backward (torch/_tensor.py:5);"
        "_engine_run_backward (torch/autograd/graph.py:8) 5",
        "fit (pipeline/planner/fit.py:1);forward (torch/nn/modules/conv.py:7) 3",
        # 2 samples nothing claims
        "sleep (time.py:1) 2",
        "a line that is not a sample",
    ]
)


def test_parse_raw_reads_stacks_and_counts():
    samples = parse_raw(RAW)
    assert [n for _, n in samples] == [4, 2, 5, 3, 2]
    assert samples[0][0][-1] == "servo_motion (pipeline/servo/predict.py:80)"


def test_each_sample_goes_to_the_first_part_on_its_stack():
    samples = parse_raw(RAW)
    assert [part_of(frames) for frames, _ in samples] == [
        "servo",
        "robot checks (IK, collisions)",
        "backward",
        "forward",
        OTHER,
    ]


def test_shares_worked_by_hand():
    # 16 samples: backward 5, servo 4, forward 3, robot checks 2, other 2
    rows = {name: (n, share) for name, n, share in summarise(parse_raw(RAW))}
    assert sum(n for n, _ in rows.values()) == 16
    assert rows["backward"] == (5, pytest.approx(5 / 16))
    assert rows["servo"] == (4, pytest.approx(0.25))
    assert rows["forward"] == (3, pytest.approx(3 / 16))
    assert rows["robot checks (IK, collisions)"] == (2, pytest.approx(0.125))
    assert rows[OTHER] == (2, pytest.approx(0.125))
    assert summarise([]) == []


@pytest.mark.parametrize(
    "argv",
    [
        ["evaluate", "--rate", "50", "evaluate.num_trials=4", "planner=dcnn"],
        ["--rate", "50", "evaluate", "evaluate.num_trials=4", "planner=dcnn"],
        ["evaluate", "evaluate.num_trials=4", "planner=dcnn", "--rate", "50"],
    ],
)
def test_options_may_stand_anywhere_on_the_command_line(argv):
    from pipeline.tools.profile import parse_args

    args = parse_args(argv)
    assert (args.stage, args.overrides, args.rate) == (
        "evaluate",
        ["evaluate.num_trials=4", "planner=dcnn"],
        50,
    )


def test_no_stage_and_no_sample_file_is_an_error(capsys):
    from pipeline.tools.profile import parse_args

    with pytest.raises(SystemExit):
        parse_args(["--rate", "50"])
    assert "name a stage" in capsys.readouterr().err
