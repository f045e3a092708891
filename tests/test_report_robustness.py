"""The report's robustness section, from a hand-made robustness artifact (no stage runs)."""

from __future__ import annotations

import csv
import io
import json
import math
from pathlib import Path

import pytest

from pipeline.artifacts import ArtifactError, run_stage
from pipeline.report.robustness import (
    ROBUSTNESS_NOT_RUN,
    ROBUSTNESS_SECTION,
    RobustnessSection,
    render_robustness,
    resolve_robustness,
    robustness_closed_loop_table,
    robustness_failures_table,
    robustness_generation,
    robustness_policies_table,
    robustness_sensor_table,
    robustness_table1_table,
    robustness_table2_table,
)
from pipeline.report.stage import NOT_AFFECTING_RESULT
from pipeline.runtime.cli import compose

VERSION = "00000000000000aa"
NAN = float("nan")
SENSOR = {
    "name": "sr300",
    "enabled": True,
    "noise_sigma_0": 0.0005,
    "projector_baseline": 0.025,
    "dropout_angle_deg": 78.0,
    "quantisation_step": 0.000125,
}


# Wilson 95 % score intervals (pipeline.world.books.wilson_interval, rounded to 6 decimals) of
# (successes, trials)
WILSON = {
    (8, 10): (0.490162, 0.943318),
    (9, 12): (0.467695, 0.911058),
    (9, 10): (0.59585, 0.982124),
    (6, 10): (0.312674, 0.83182),
    (8, 12): (0.390622, 0.86188),
    (6, 12): (0.253782, 0.746218),
    (0, 12): (0.0, 0.242494),
    (21, 22): (0.78202, 0.991931),
    (21, 24): (0.689961, 0.956557),
    (0, 0): (NAN, NAN),
}
NO_ATTEMPT = "1 trials no_grasp: 3 candidates, every one rejected (descriptor 3)"


def _cl(
    group: str,
    variant: str,
    rate: float,
    attempts: int,
    successes: int,
    picked: int,
    pph: float,
    split: str = "dev",
    trials: int = 1,
    boxes: int = 12,
    **fails: int,
) -> dict:
    """A closed-loop row as pipeline.stages.robustness.closed_loop_rows writes it: its split,
    trials, rates with their intervals, failures by kind, trial ends, why no attempt was made."""
    s_lo, s_hi = WILSON[(successes, attempts)]
    p_lo, p_hi = WILSON[(picked, boxes)]
    return {
        "group": group,
        "variant": variant,
        "model": "clean",
        "split": split,
        "trials": trials,
        "overrides": "-" if variant in ("clean_ideal", "paper") else f"x.{variant}=1",
        "success_rate": rate,
        "success_ci_low": s_lo,
        "success_ci_high": s_hi,
        "attempts": attempts,
        "successes": successes,
        "picked": picked,
        "boxes": boxes,
        "picked_rate": picked / boxes,
        "picked_ci_low": p_lo,
        "picked_ci_high": p_hi,
        "pph_motion": pph,
        "no_attempt_reason": "" if attempts else NO_ATTEMPT,
        **{
            f"fail_{k}": fails.get(k, 0)
            for k in ("no_seal", "dropped", "collision", "joint_limits", "timeout", "lost_target")
        },
        "end_bin_empty": int(picked == boxes),
        "end_no_grasp": trials - int(picked == boxes),
        "end_max_failures": 0,
        "end_max_attempts": 0,
        "evaluate_version": f"e{variant}",
    }


def _old(row: dict) -> dict:
    """The row as the study wrote it before the splits and intervals (no split, trials,
    intervals, picked rate, trial ends or reason; two failure kinds)."""
    keep = (
        "group",
        "variant",
        "model",
        "overrides",
        "success_rate",
        "attempts",
        "successes",
        "picked",
        "boxes",
        "pph_motion",
        "fail_no_seal",
        "fail_collision",
        "evaluate_version",
    )
    return {k: row[k] for k in keep}


TABLES = {
    "table1": [
        {
            "model": "clean",
            "input": "ideal",
            "top1": 0.5,
            "top1pct": 0.25,
            "top5pct": 0.125,
            "top10pct": NAN,
            "predictions": 676,
            "images": 4,
        },
        {
            "model": "noisy",
            "input": "sensor+fill_median",
            "top1": 1.0,
            "top1pct": 0.0,
            "top5pct": None,
            "top10pct": 0.333333,
            "predictions": 600,
            "images": 4,
        },
    ],
    "table2": [
        {
            "planner": "dcnn_clean",
            "input": "ideal",
            "images": 4,
            "no_grasp": 1,
            "within_30px": 0.75,
            "median_distance_px": 12.345,
        },
        {
            "planner": "gqcnn",
            "input": "sensor",
            "images": 4,
            "no_grasp": 4,
            "within_30px": 0.0,
            "median_distance_px": NAN,
        },
    ],
    "closed_loop": [
        _cl("sensor", "clean_ideal", 0.8, 10, 8, 8, 1234.5, no_seal=2),
        _cl("sensor", "noisy_sensor", NAN, 0, 0, 0, NAN),
        _cl(
            "sensor",
            "noisy_sensor_test",
            21 / 22,
            22,
            21,
            21,
            1111.1,
            split="test",
            trials=2,
            boxes=24,
            dropped=1,
        ),
        _cl("policy", "paper", 0.75, 12, 9, 9, 1000.0, no_seal=3),
        _cl("policy", "height_tiebreak", 0.9, 10, 9, 9, 1100.0, collision=1),
        _cl("policy", "area_check", 0.6, 10, 6, 6, 950.5),
        _cl("policy", "both", NAN, 0, 0, 0, NAN),
    ],
}


def _fake_robustness(root: Path, version: str = VERSION, data: dict | None = None) -> Path:
    """A complete robustness artifact (manifest, hashes, ``latest``) holding ``data``."""
    data = (
        data
        if data is not None
        else {
            **TABLES,
            "sensor": SENSOR,
            "artifacts": {
                "generate_noisy": "00000000000000bb",
                "train_clean": "c" * 16,
                "train_noisy": "d" * 16,
            },
        }
    )

    def body(run) -> None:
        # json.dumps writes NaN as the robustness stage does
        (run.work_dir / "robustness.json").write_text(json.dumps(data, indent=1) + "\n")

    config = {"robustness": {"sensor": "sr300", "closed_loop_trials": 1}}
    return run_stage(root / "data", "robustness", version, config, {}, body, say=lambda _: None)


@pytest.fixture
def info(tmp_path: Path):
    _fake_robustness(tmp_path)
    return resolve_robustness(tmp_path / "data", "latest")


def _md_rows(table) -> list[list[str]]:
    lines = table.markdown().splitlines()[2:]
    return [[c.strip() for c in line.strip().strip("|").split("|")] for line in lines]


def _csv_rows(table) -> list[list[str]]:
    return list(csv.reader(io.StringIO(table.csv_text())))[1:]


def test_resolves_the_artifact(tmp_path: Path, info) -> None:
    assert info.version == VERSION
    assert info.data["sensor"]["name"] == "sr300"
    assert math.isnan(info.data["table2"][1]["median_distance_px"])
    assert robustness_generation(tmp_path / "data", info) is None  # no generation artifact


def test_table1_percentages(info) -> None:
    t = robustness_table1_table(info)
    assert t.headers[:6] == ["network", "input", "Top 1", "Top 1 %", "Top 5 %", "Top 10 %"]
    assert _md_rows(t) == [
        ["network under test", "ideal", "50.00 %", "25.00 %", "12.50 %", "—", "676", "4"],
        ["sensor-trained", "sensor+fill_median", "100.00 %", "0.00 %", "—", "33.33 %", "600", "4"],
    ]
    assert _csv_rows(t) == [
        ["network under test", "ideal", "50.0000", "25.0000", "12.5000", "", "676", "4"],
        ["sensor-trained", "sensor+fill_median", "100.0000", "0.0000", "", "33.3333", "600", "4"],
    ]


def test_table2_percentages(info) -> None:
    t = robustness_table2_table(info)
    assert t.headers == [
        "planner",
        "input",
        "images",
        "within 30 px",
        "no grasp",
        "median distance (px)",
    ]
    assert _md_rows(t) == [
        ["ours (DCNN), network under test", "ideal", "4", "75.00 %", "1", "12.3"],
        ["Dex-Net-style GQ-CNN + CEM", "sensor", "4", "0.00 %", "4", "—"],
    ]
    assert _csv_rows(t)[0] == [
        "ours (DCNN), network under test",
        "ideal",
        "4",
        "75.0000",
        "1",
        "12.345",
    ]
    assert _csv_rows(t)[1][-1] == ""


def test_closed_loop_sensor_rows(info) -> None:
    """Each variant's split and trials, success rate and boxes picked with their intervals,
    PPH, failures by kind, trial ends, and why a variant made no attempt."""
    t = robustness_closed_loop_table(info)
    assert t.headers == [
        "variant",
        "network",
        "overrides",
        "split",
        "trials",
        "success rate (95 % CI)",
        "successes / attempts",
        "boxes picked",
        "boxes picked (95 % CI)",
        "PPH (motion only)",
        "failed: no_seal",
        "failed: dropped",
        "failed: collision",
        "failed: joint_limits",
        "failed: timeout",
        "failed: lost_target",
        "trials ended: bin empty",
        "trials ended: no grasp",
        "trials ended: failure limit",
        "trials ended: attempt limit",
        "no attempt: why",
    ]
    md = _md_rows(t)
    # 8/10 = 80.0 % (49.0–94.3); 8/12 = 66.7 % (39.1–86.2); 2 no seal; its trial: no grasp
    assert md[0] == [
        "clean_ideal",
        "network under test",
        "-",
        "dev",
        "1",
        "80.0 % (49.0–94.3)",
        "8/10",
        "8/12",
        "66.7 % (39.1–86.2)",
        "1234.5",
        "2",
        "0",
        "0",
        "0",
        "0",
        "0",
        "0",
        "1",
        "0",
        "0",
        "",
    ]
    # no attempt: no rate, 0/12 boxes = 0.0 % (0.0–24.2), the reason
    assert md[1][3:10] == ["dev", "1", "—", "0/0", "0/12", "0.0 % (0.0–24.2)", "—"]
    assert md[1][-1] == NO_ATTEMPT
    # the headline row on the test split: 21/22 = 95.5 % (78.2–99.2), 21/24 = 87.5 % (69.0–95.7)
    assert md[2][:10] == [
        "noisy_sensor_test",
        "network under test",
        "x.noisy_sensor_test=1",
        "test",
        "2",
        "95.5 % (78.2–99.2)",
        "21/22",
        "21/24",
        "87.5 % (69.0–95.7)",
        "1111.1",
    ]
    assert md[2][10:12] == ["0", "1"]  # 1 dropped
    rows = _csv_rows(t)
    assert rows[0][:14] == [
        "clean_ideal",
        "network under test",
        "-",
        "dev",
        "1",
        "80.00",
        "49.02",
        "94.33",
        "8",
        "10",
        "8",
        "12",
        "66.67",
        "39.06",
    ]
    assert rows[1][5:8] == ["", "", ""] and rows[1][-1] == NO_ATTEMPT


def test_an_old_study_still_renders(tmp_path: Path) -> None:
    """A study made before the splits, intervals and reasons: its rows render, the missing
    values as —, and the text gives the config's trials as before."""
    data = {
        **TABLES,
        "closed_loop": [_old(r) for r in TABLES["closed_loop"]],
        "sensor": SENSOR,
        "artifacts": {"generate_noisy": "00000000000000bb"},
    }
    _fake_robustness(tmp_path, data=data)
    old = resolve_robustness(tmp_path / "data", "latest")
    md = _md_rows(robustness_closed_loop_table(old))
    assert md[0] == [
        "clean_ideal",
        "network under test",
        "-",
        "—",
        "—",
        "80.0 %",
        "8/10",
        "8/12",
        "66.7 %",
        "1234.5",
        "2",
        "—",
        "0",
        "—",
        "—",
        "—",
        "—",
        "—",
        "—",
        "—",
        "—",
    ]
    assert md[1][5:10] == ["—", "0/0", "0/12", "0.0 %", "—"]
    text = "\n".join(render_robustness(old, _tables(old), None))
    assert "(1 trial each), all on the same heaps and seeds" in text


def test_policies_differ_from_the_paper_row(info) -> None:
    t = robustness_policies_table(info)
    assert t.headers[-3:] == ["success rate vs. paper (pp)", "PPH vs. paper", "no attempt: why"]
    # the closed-loop table's columns, the differences before the reason
    assert t.headers[:-3] == robustness_closed_loop_table(info).headers[:-1]
    md = {r[0]: r for r in _md_rows(t)}
    assert list(md) == ["paper", "height_tiebreak", "area_check", "both"]
    # by hand: 90 % - 75 % = +15 pp, 1100 - 1000 = +100 PPH; 60 % - 75 % = -15 pp,
    # 950.5 - 1000 = -49.5 PPH; the reference row and an undefined rate have no difference
    assert md["paper"][5:10] == [
        "75.0 % (46.8–91.1)",
        "9/12",
        "9/12",
        "75.0 % (46.8–91.1)",
        "1000.0",
    ]
    assert md["paper"][-3:] == ["—", "—", ""]
    assert md["height_tiebreak"][-3:-1] == ["+15.0", "+100.0"]
    assert md["area_check"][-3:-1] == ["-15.0", "-49.5"]
    assert md["both"][-3:] == ["—", "—", NO_ATTEMPT]
    csv_rows = {r[0]: r for r in _csv_rows(t)}
    assert csv_rows["height_tiebreak"][-3:-1] == ["15.0000", "100.0"]
    assert csv_rows["area_check"][-3:-1] == ["-15.0000", "-49.5"]
    assert csv_rows["paper"][-3:] == ["", "", ""]
    assert [r[0] for r in _md_rows(robustness_closed_loop_table(info))] == [
        "clean_ideal",
        "noisy_sensor",
        "noisy_sensor_test",
    ]  # the sensor rows are no policies


def test_failures_and_sensor_tables(info) -> None:
    f = robustness_failures_table(info)
    assert f.headers == [
        "group",
        "variant",
        "no_seal",
        "dropped",
        "collision",
        "joint_limits",
        "timeout",
        "lost_target",
    ]
    assert _csv_rows(f)[0] == ["sensor", "clean_ideal", "2", "0", "0", "0", "0", "0"]
    assert _csv_rows(f)[2] == ["sensor", "noisy_sensor_test", "0", "1", "0", "0", "0", "0"]
    assert _csv_rows(f)[4] == ["policy", "height_tiebreak", "0", "0", "1", "0", "0", "0"]
    s = {r[0]: r[1] for r in _csv_rows(robustness_sensor_table(info))}
    assert s == {
        "name": "sr300",
        "enabled": "true",
        "noise_sigma_0": "0.0005",
        "projector_baseline": "0.025",
        "dropout_angle_deg": "78",
        "quantisation_step": "0.000125",
    }


def _tables(info) -> dict:
    return {
        t.name: t
        for t in (
            robustness_sensor_table(info),
            robustness_table1_table(info),
            robustness_table2_table(info),
            robustness_closed_loop_table(info),
            robustness_policies_table(info),
            robustness_failures_table(info),
        )
    }


def test_section_text(info) -> None:
    tables = _tables(info)
    text = "\n".join(render_robustness(info, tables, None, "No depth figure: missing."))
    assert RobustnessSection().markdown(info, tables, {})[0] == f"## {ROBUSTNESS_SECTION}"
    for heading in (
        "### Sensor model",
        "### Sensor noise: Table 1",
        "### Sensor noise: Table 2",
        "### Sensor noise: closed loop",
        "### Sec. 8.4 failure cases: closed loop",
    ):
        assert heading in text.splitlines()
    assert VERSION in text and "00000000000000bb" in text
    # the splits: 6 dev variants of 1 trial, the test variant of 2 on Table 3's heaps
    assert "The 6 dev variants (1 trial each) share the heaps development used" in text
    assert (
        "The test variants (`noisy_sensor_test`; 2 trials each) run on Table 3's test "
        "heaps, which nothing is chosen on"
    ) in text
    assert "A variant with no attempt says why in its last column" in text
    assert "No depth figure: missing." in text and ROBUSTNESS_NOT_RUN not in text
    assert (
        "| height_tiebreak | network under test | x.height_tiebreak=1 | dev | 1 "
        "| 90.0 % (59.6–98.2) |"
    ) in text
    figure = "figures/robustness_depth.png"
    assert f"]({figure})" in "\n".join(render_robustness(info, tables, figure))


def test_absent_study_says_how_to_run_it(tmp_path: Path) -> None:
    assert resolve_robustness(tmp_path / "data", "latest") is None
    text = "\n".join(RobustnessSection().markdown(None, {}, {}))
    assert ROBUSTNESS_NOT_RUN in text and "make robustness" in text
    assert "report.robustness_version" in NOT_AFFECTING_RESULT
    assert compose("report", ["experiment=smoke"]).report.robustness_version == "latest"


def test_mistyped_version_is_an_error(tmp_path: Path) -> None:
    with pytest.raises(ArtifactError, match="report.robustness_version=0123456789abcdef"):
        resolve_robustness(tmp_path / "data", "0123456789abcdef")  # none exist
    _fake_robustness(tmp_path)
    with pytest.raises(ArtifactError, match="report.robustness_version") as e:
        resolve_robustness(tmp_path / "data", VERSION[:-1] + "b")
    assert VERSION in str(e.value)  # the available versions are listed


def test_incomplete_study_is_an_error(tmp_path: Path) -> None:
    _fake_robustness(tmp_path, data={"table1": []})
    with pytest.raises(ArtifactError, match="make robustness"):
        resolve_robustness(tmp_path / "data", "latest")
