"""The report's robustness section, from a hand-made robustness artifact (no stage runs)."""

from __future__ import annotations

import csv
import io
import json
import math
from pathlib import Path

import pytest

from pipeline.artifacts import ArtifactError, run_stage
from pipeline.cli import compose
from pipeline.report.robustness import (
    ROBUSTNESS_NOT_RUN, ROBUSTNESS_SECTION, render_robustness, resolve_robustness,
    robustness_closed_loop_table, robustness_failures_table, robustness_generation,
    robustness_policies_table, robustness_sensor_table, robustness_table1_table,
    robustness_table2_table,
)
from pipeline.report.stage import NOT_AFFECTING_RESULT

VERSION = "00000000000000aa"
NAN = float("nan")
SENSOR = {"name": "sr300", "enabled": True, "noise_sigma_0": 0.0005, "projector_baseline": 0.025,
          "dropout_angle_deg": 78.0, "quantisation_step": 0.000125}


def _cl(group: str, variant: str, rate: float, attempts: int, successes: int, picked: int,
        pph: float, **fails: int) -> dict:
    return {"group": group, "variant": variant, "model": "clean",
            "overrides": "-" if variant in ("clean_ideal", "paper") else f"x.{variant}=1",
            "success_rate": rate, "attempts": attempts, "successes": successes,
            "picked": picked, "boxes": 12, "pph_motion": pph,
            "fail_no_seal": fails.get("no_seal", 0), "fail_collision": fails.get("collision", 0),
            "evaluate_version": f"e{variant}"}


TABLES = {
    "table1": [
        {"model": "clean", "input": "ideal", "top1": 0.5, "top1pct": 0.25, "top5pct": 0.125,
         "top10pct": NAN, "predictions": 676, "images": 4},
        {"model": "noisy", "input": "sensor+fill_median", "top1": 1.0, "top1pct": 0.0,
         "top5pct": None, "top10pct": 0.333333, "predictions": 600, "images": 4},
    ],
    "table2": [
        {"planner": "dcnn_clean", "input": "ideal", "images": 4, "no_grasp": 1,
         "within_30px": 0.75, "median_distance_px": 12.345},
        {"planner": "gqcnn", "input": "sensor", "images": 4, "no_grasp": 4,
         "within_30px": 0.0, "median_distance_px": NAN},
    ],
    "closed_loop": [
        _cl("sensor", "clean_ideal", 0.8, 10, 8, 8, 1234.5, no_seal=2),
        _cl("sensor", "noisy_sensor", NAN, 0, 0, 0, NAN),
        _cl("policy", "paper", 0.75, 12, 9, 9, 1000.0, no_seal=3),
        _cl("policy", "height_tiebreak", 0.9, 10, 9, 9, 1100.0, collision=1),
        _cl("policy", "area_check", 0.6, 10, 6, 6, 950.5),
        _cl("policy", "both", NAN, 0, 0, 0, NAN),
    ],
}


def _fake_robustness(root: Path, version: str = VERSION, data: dict | None = None) -> Path:
    """A complete robustness artifact (manifest, hashes, ``latest``) holding ``data``."""
    data = data if data is not None else {**TABLES, "sensor": SENSOR, "artifacts": {
        "generate_noisy": "00000000000000bb", "train_clean": "c" * 16, "train_noisy": "d" * 16}}

    def body(run) -> None:
        # json.dumps writes NaN as the robustness stage does
        (run.work_dir / "robustness.json").write_text(json.dumps(data, indent=1) + "\n")

    config = {"robustness": {"sensor": "sr300", "closed_loop_trials": 2}}
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
        ["clean-trained", "ideal", "50.00 %", "25.00 %", "12.50 %", "—", "676", "4"],
        ["noisy-trained", "sensor+fill_median", "100.00 %", "0.00 %", "—", "33.33 %", "600", "4"]]
    assert _csv_rows(t) == [
        ["clean-trained", "ideal", "50.0000", "25.0000", "12.5000", "", "676", "4"],
        ["noisy-trained", "sensor+fill_median", "100.0000", "0.0000", "", "33.3333", "600", "4"]]


def test_table2_percentages(info) -> None:
    t = robustness_table2_table(info)
    assert t.headers == ["planner", "input", "images", "within 30 px", "no grasp",
                         "median distance (px)"]
    assert _md_rows(t) == [["ours (DCNN), clean-trained", "ideal", "4", "75.00 %", "1", "12.3"],
                           ["Dex-Net-style GQ-CNN + CEM", "sensor", "4", "0.00 %", "4", "—"]]
    assert _csv_rows(t)[0] == ["ours (DCNN), clean-trained", "ideal", "4", "75.0000", "1",
                               "12.345"]
    assert _csv_rows(t)[1][-1] == ""


def test_closed_loop_sensor_rows(info) -> None:
    t = robustness_closed_loop_table(info)
    assert _md_rows(t) == [
        ["clean_ideal", "clean-trained", "-", "80.0 %", "8/10", "8/12", "1234.5"],
        ["noisy_sensor", "clean-trained", "x.noisy_sensor=1", "—", "0/0", "0/12", "—"]]


def test_policies_differ_from_the_paper_row(info) -> None:
    t = robustness_policies_table(info)
    assert t.headers[-2:] == ["success rate vs. paper (pp)", "PPH vs. paper"]
    md = {r[0]: r for r in _md_rows(t)}
    assert list(md) == ["paper", "height_tiebreak", "area_check", "both"]
    # by hand: 90 % - 75 % = +15 pp, 1100 - 1000 = +100 PPH; 60 % - 75 % = -15 pp,
    # 950.5 - 1000 = -49.5 PPH; the reference row and an undefined rate have no difference
    assert md["paper"][3:] == ["75.0 %", "9/12", "9/12", "1000.0", "—", "—"]
    assert md["height_tiebreak"][-2:] == ["+15.0", "+100.0"]
    assert md["area_check"][-2:] == ["-15.0", "-49.5"]
    assert md["both"][-2:] == ["—", "—"]
    csv_rows = {r[0]: r for r in _csv_rows(t)}
    assert csv_rows["height_tiebreak"][-2:] == ["15.0000", "100.0"]
    assert csv_rows["area_check"][-2:] == ["-15.0000", "-49.5"]
    assert csv_rows["paper"][-2:] == ["", ""]
    assert [r[0] for r in _md_rows(robustness_closed_loop_table(info))] == [
        "clean_ideal", "noisy_sensor"]  # the sensor rows are not policies


def test_failures_and_sensor_tables(info) -> None:
    f = robustness_failures_table(info)
    assert f.headers == ["group", "variant", "no_seal", "collision"]
    assert _csv_rows(f)[0] == ["sensor", "clean_ideal", "2", "0"]
    assert _csv_rows(f)[3] == ["policy", "height_tiebreak", "0", "1"]
    s = {r[0]: r[1] for r in _csv_rows(robustness_sensor_table(info))}
    assert s == {"name": "sr300", "enabled": "true", "noise_sigma_0": "0.0005",
                 "projector_baseline": "0.025", "dropout_angle_deg": "78",
                 "quantisation_step": "0.000125"}


def test_section_text(info) -> None:
    tables = {t.name: t for t in (
        robustness_sensor_table(info), robustness_table1_table(info),
        robustness_table2_table(info), robustness_closed_loop_table(info),
        robustness_policies_table(info), robustness_failures_table(info))}
    text = "\n".join(render_robustness(info, tables, None, "No depth figure: missing."))
    assert text.startswith(f"## {ROBUSTNESS_SECTION}")
    for heading in ("### Sensor model", "### Sensor noise: Table 1", "### Sensor noise: Table 2",
                    "### Sensor noise: closed loop", "### Sec. 8.4 failure cases: closed loop"):
        assert heading in text.splitlines()
    assert VERSION in text and "00000000000000bb" in text and "2 trials each" in text
    assert "No depth figure: missing." in text and ROBUSTNESS_NOT_RUN not in text
    assert "| height_tiebreak | clean-trained | x.height_tiebreak=1 | 90.0 % |" in text
    figure = "figures/robustness_depth.png"
    assert f"]({figure})" in "\n".join(render_robustness(info, tables, figure))


def test_absent_study_says_how_to_run_it(tmp_path: Path) -> None:
    assert resolve_robustness(tmp_path / "data", "latest") is None
    text = "\n".join(render_robustness(None, {}, None))
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
