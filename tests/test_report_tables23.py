"""Tables 2 and 3 of the report, from hand-made manifests."""

from pathlib import Path

from pipeline.report.ablation import ablation_table
from pipeline.report.baseline import table2_table
from pipeline.report.closed_loop import (
    failures_table, no_grasp_table, path_deviation_table, table3_table,
)
from pipeline.report.upstream import ArtifactInfo


def test_table2_puts_the_paper_beside_every_planner():
    info = ArtifactInfo(Path("x"), {"metrics": {"table2": {
        "radius_px": 30.0,
        "paper": {"within_30px": {"dexnet4": 0.5888, "ours": 0.7916}, "radius_px": 30.0},
        "rows": [{"planner": "dcnn", "name": "Ours", "images": 10, "no_grasp": 1,
                  "within_30px": 0.7, "median_distance_px": 12.5},
                 {"planner": "gqcnn", "name": "GQ", "images": 10, "no_grasp": 0,
                  "within_30px": 0.4, "median_distance_px": 35.0}]}}})
    t = table2_table(info)
    md = t.markdown()
    assert "58.88 %" in md and "79.16 %" in md  # the paper's rows
    # 7 of 10 images within 30 px, 1 without a grasp: 7 / 9 = 77.78 % of those with one.
    assert "| this reproduction | Ours | 70.00 % | 10 | 1 | 77.78 % | 12.5 |" in md
    assert t.csv_text().splitlines()[3].startswith("this reproduction,Ours,70.0000,10,1,77.7778,12.500")


def test_table3_rows_and_failures():
    row = {"planner": "dcnn", "success_rate": 0.75, "attempts": 8, "pph_motion": 1100.0,
           "picked": 6, "boxes": 12, "wrong_target": 1,
           "path_deviation_mm_median": 2.54, "path_deviation_mm_max": float("nan"), **{f"fail_{k}": 0 for k in ("no_seal", "dropped", "collision",
                                                          "joint_limits", "timeout",
                                                          "lost_target")},
           **{f"end_{e}": 0 for e in ("bin_empty", "no_grasp", "max_failures", "max_attempts")}}
    row["fail_collision"] = 2
    row["end_bin_empty"] = 1
    info = ArtifactInfo(Path("x"), {"metrics": {"table3": [row], "paper_table3": [
        {"system": "Ours (paper)", "hand": "suction (2 cups)", "success": 97.5,
         "planning_s": 0.034, "pph": "over 1000"}]}})
    md = table3_table(info).markdown()
    assert "97.5" in md and "over 1000" in md
    assert "75.0 %" in md and "1100.0" in md
    assert "| 6/12 | 50.0 % |" in md  # boxes picked, and their share
    dev = path_deviation_table(info).markdown()
    assert "| 8 | 2.5 | — |" in dev  # a missing deviation (no prediction) shows as —
    f = failures_table(info).csv_text().splitlines()
    assert f[1] == "dcnn,0,0,2,0,0,0,1,1,0,0,0,,"  # no fallback-tier counts: an older artifact
    row.update(second_tier_attempts=3, second_tier_successes=2)
    oracle = dict(row, planner="oracle")  # the oracle has no fallback tier, whatever it records
    info.manifest["metrics"]["table3"] = [row, oracle]
    f = failures_table(info).csv_text().splitlines()
    assert f[1:] == ["dcnn,0,0,2,0,0,0,1,1,0,0,0,3,2", "oracle,0,0,2,0,0,0,1,1,0,0,0,,"]
    assert "| dcnn | 0 | 0 | 2 | 0 | 0 | 0 | 1 | 1 | 0 | 0 | 0 | 3 | 2 |" in \
        failures_table(info).markdown()


def test_no_grasp_table_sums_the_no_grasp_endings(tmp_path):
    """Two DCNN trials ended with no grasp (2 + 1 boxes left; 0 + 3 candidates, of which 2
    collide and 1 repeats a failure), one ended with the bin empty; the oracle has none. The
    labels held an executable grasp in the first (its 2 boxes: perception lost them), not in the
    second; the oracle was not asked (—, empty in the CSV)."""
    import json

    trials = [
        {"planner": "dcnn", "end": "no_grasp",
         "no_grasp": {"boxes_left": 2, "candidates": 0, "checked": 0, "rejected": {},
                      "label_candidates": 1, "label_executable": True}},
        {"planner": "dcnn", "end": "no_grasp",
         "no_grasp": {"boxes_left": 1, "candidates": 3, "checked": 3,
                      "rejected": {"collision": 2, "repeat": 1},
                      "label_candidates": 2, "label_executable": False}},
        {"planner": "dcnn", "end": "bin_empty"},
        {"planner": "oracle", "end": "bin_empty"},
    ]
    (tmp_path / "trials.json").write_text(json.dumps(trials))
    info = ArtifactInfo(tmp_path, {"metrics": {"table3": [{"planner": "dcnn"},
                                                          {"planner": "oracle"}]}})
    assert no_grasp_table(info).csv_text().splitlines() == [
        "planner,trials,boxes left,candidates,rejected: collision,rejected: repeat,"
        "trials where the labels had a grasp,boxes left by those trials",
        "dcnn,2,3,3,2,1,1,2", "oracle,0,0,0,0,0,,"]
    assert "| oracle | 0 | 0 | 0 | 0 | 0 | — | — |" in no_grasp_table(info).markdown()


def test_ablation_table_by_hand():
    """One row: 9 of 10 attempts, 9 of 12 boxes (75 %), the overrides as text, a missing
    success rate (no attempt) shown as —."""
    row = {"planner": "oracle", "variant": "no_gate", "overrides":
           "evaluate.check_reachability=false", "success_rate": 0.9, "attempts": 10,
           "picked": 9, "boxes": 12, "pph_motion": 990.5, "fail_no_seal": 1,
           "fail_dropped": 0, "fail_collision": 0, "fail_lost_target": 0, "fail_timeout": 0,
           "end_no_grasp": 2}
    empty = dict(row, variant="all_off", success_rate=None, attempts=0, picked=0)
    md = ablation_table([row, empty]).markdown().splitlines()
    assert md[2] == ("| oracle | no_gate | evaluate.check_reachability=false | 90.0 % | 10 | "
                     "9/12 | 75.0 % | 990.5 | 1 | 0 | 0 | 0 | 0 | 2 |")
    assert md[3].startswith("| oracle | all_off | evaluate.check_reachability=false | — | 0 |")


def test_table2_shows_each_gqcnn_with_what_it_was_trained_on():
    from pipeline.dexnet.table2 import PLANNER_NAMES
    from pipeline.report.baseline import render_baseline

    rows = [{"planner": k, "name": PLANNER_NAMES[k], "images": 4, "no_grasp": 0,
             "within_30px": 0.5, "median_distance_px": 20.0} for k in ("gqcnn", "gqcnn_ood")]
    info = ArtifactInfo(Path("x"), {"metrics": {
        "table2": {"radius_px": 30.0, "rows": rows,
                   "paper": {"within_30px": {"dexnet4": 0.5888, "ours": 0.7916},
                             "radius_px": 30.0}},
        "gqcnn_ood": {"box_test": {"accuracy": 0.75, "precision": 0.5, "recall": 0.25}},
        "ood_candidate_labels": {"train": {"scenes": 3, "objects": 30, "candidates": 96}}}})
    t = table2_table(info)
    md = t.markdown()
    assert "| this reproduction | Dex-Net-style GQ-CNN + CEM, trained on the box heaps |" in md
    assert "| this reproduction | Dex-Net-style GQ-CNN + CEM, trained on non-box objects |" in md
    text = "\n".join(render_baseline(info, {"table2_centre_distance": t}, {}))
    assert "3 heaps of 30 random convex" in text and "accuracy 75.0 %" in text
