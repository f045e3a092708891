"""Tables 2 and 3 of the report, from hand-made manifests."""

from pathlib import Path

from pipeline.report.ablation import ablation_table
from pipeline.report.baseline import table2_table
from pipeline.report.closed_loop import (
    failures_table,
    no_grasp_table,
    path_deviation_table,
    table3_table,
)
from pipeline.report.upstream import ArtifactInfo


def test_table2_puts_the_paper_beside_every_planner():
    info = ArtifactInfo(
        Path("x"),
        {
            "metrics": {
                "table2": {
                    "radius_px": 30.0,
                    "paper": {
                        "within_30px": {"dexnet4": 0.5888, "ours": 0.7916},
                        "radius_px": 30.0,
                    },
                    "rows": [
                        {
                            "planner": "dcnn",
                            "name": "Ours",
                            "images": 10,
                            "no_grasp": 1,
                            "within_30px": 0.7,
                            "median_distance_px": 12.5,
                        },
                        {
                            "planner": "gqcnn",
                            "name": "GQ",
                            "images": 10,
                            "no_grasp": 0,
                            "within_30px": 0.4,
                            "median_distance_px": 35.0,
                        },
                    ],
                }
            }
        },
    )
    t = table2_table(info)
    md = t.markdown()
    assert "58.88 %" in md and "79.16 %" in md  # the paper's rows
    # 7 of 10 images within 30 px, 1 without a grasp: 7 / 9 = 77.78 % of those with one.
    assert "| this reproduction | Ours | 70.00 % | 10 | 1 | 77.78 % | 12.5 |" in md
    assert (
        t.csv_text()
        .splitlines()[3]
        .startswith("this reproduction,Ours,70.0000,10,1,77.7778,12.500")
    )


FAILS = ("no_seal", "dropped", "collision", "joint_limits", "timeout", "lost_target")
ENDS = ("bin_empty", "no_grasp", "max_failures", "max_attempts")
PAPER_OURS = {
    "system": "Ours (paper)",
    "hand": "suction (2 cups)",
    "success": 97.5,
    "planning_s": 0.034,
    "pph": "over 1000",
}


def _old_row() -> dict:
    """A Table 3 row as evaluations wrote it before the intervals, the picked rate and the
    no-attempt reason (pipeline.world.books.summarise)."""
    row = {
        "planner": "dcnn",
        "trials": 1,
        "success_rate": 0.75,
        "attempts": 8,
        "successes": 6,
        "pph_motion": 1100.0,
        "picked": 6,
        "boxes": 12,
        "wrong_target": 1,
        "path_deviation_mm_median": 2.54,
        "path_deviation_mm_max": float("nan"),
        **{f"fail_{k}": 0 for k in FAILS},
        **{f"end_{e}": 0 for e in ENDS},
    }
    row.update(fail_collision=2, end_bin_empty=1)
    return row


def _evaluation(rows: list[dict], split: str | None = "test") -> ArtifactInfo:
    config = {"evaluate": {"num_trials": 1, "boxes_per_trial": 12}}
    if split is not None:
        config["evaluate"]["split"] = split
    return ArtifactInfo(
        Path("x"), {"config": config, "metrics": {"table3": rows, "paper_table3": [PAPER_OURS]}}
    )


def _md_rows(table) -> list[list[str]]:
    return [
        [c.strip() for c in line.strip().strip("|").split("|")]
        for line in table.markdown().splitlines()[2:]
    ]


def test_table3_rows_and_failures_of_an_old_artifact():
    """An evaluation made before the splits and the intervals: its rows still render, the
    interval and the no-attempt reason as —, the picked share computed (6/12 = 50 %), the split
    the dev stream's (the heaps every evaluation before the splits drew)."""
    row = _old_row()
    info = _evaluation([row], split=None)
    t = table3_table(info)
    md = _md_rows(t)
    assert md[0] == [
        "paper (real robot)",
        "Ours (paper)",
        "suction (2 cups)",
        "97.5 %",
        "—",
        "—",
        "—",
        "over 1000",
        "",
    ]
    assert md[1][0] == "this reproduction, dev split, 1 trial"
    # 6 of 8 attempts, no interval; 6 of 12 boxes; no reason recorded: —
    assert md[1][3:] == ["75.0 %", "6/8", "6/12", "50.0 %", "1100.0", "—"]
    csv_rows = t.csv_text().splitlines()
    assert csv_rows[2] == (
        '"this reproduction, dev split, 1 trial",dev,1,'
        "ours: DCNN + descriptor + 2.5D VS (2 cups),suction (2 cups),"
        "75.00,,,6,8,6,12,50.00,,,1100.0,"
    )
    dev = path_deviation_table(info).markdown()
    assert "| 8 | 2.5 | — |" in dev  # a missing deviation (no prediction) shows as —
    f = failures_table(info).csv_text().splitlines()
    assert f[1] == "dcnn,dev,1,,0,0,2,0,0,0,1,1,0,0,0,,"  # no fallback-tier counts: older
    row.update(second_tier_attempts=3, second_tier_successes=2)
    oracle = dict(row, planner="oracle")  # the oracle has no fallback tier, whatever it records
    info.manifest["metrics"]["table3"] = [row, oracle]
    f = failures_table(info).csv_text().splitlines()
    assert f[1:] == [
        "dcnn,dev,1,,0,0,2,0,0,0,1,1,0,0,0,3,2",
        "oracle,dev,1,,0,0,2,0,0,0,1,1,0,0,0,,",
    ]
    assert (
        "| dcnn | dev, 1 trial | 0 | 0 | 2 | 0 | 0 | 0 | 1 | 1 | 0 | 0 | 0 | 3 | 2 |"
        in failures_table(info).markdown()
    )


def _new_row(planner: str = "dcnn", **changes) -> dict:
    """A row as ``summarise`` writes it now: 116 of 117 attempts succeed, 116 of 118 boxes
    picked; the Wilson 95 % intervals (``wilson_interval``, rounded to 6 decimals):
    116/117 → 0.953170–0.998490, 116/118 → 0.940187–0.995343."""
    row = dict(
        _old_row(),
        planner=planner,
        trials=100,
        attempts=117,
        successes=116,
        success_rate=0.991453,
        success_ci_low=0.95317,
        success_ci_high=0.99849,
        picked=116,
        boxes=118,
        picked_rate=0.983051,
        picked_ci_low=0.940187,
        picked_ci_high=0.995343,
        pph_motion=1036.1,
        no_attempt_reason="",
    )
    row.update(changes)
    return row


def test_the_interval_formatting_by_hand():
    from pipeline.report.tables import rate_ci

    # 116/117 = 0.99145 → 99.1 %; 0.95317 → 95.3, 0.99849 → 99.8 (one decimal, rounded)
    assert rate_ci(0.991453, 0.95317, 0.99849) == "99.1 % (95.3–99.8)"
    assert rate_ci(0.975, None, None) == "97.5 %"  # no interval (the paper's rows)
    assert rate_ci(float("nan"), float("nan"), float("nan")) == "—"  # no attempt
    assert rate_ci(None, 0.1, 0.2) == "—"
    assert rate_ci(1.0, 0.9676, 1.0) == "100.0 % (96.8–100.0)"


def test_table3_shows_the_intervals_the_split_and_why_no_attempt_was_made():
    """The test rows (100 trials) with their intervals; an oracle row without a single attempt
    (its 100 trials ended with no grasp) says why; the CSV keeps the numbers in columns of
    their own (percent, two decimals)."""
    why = "100 trials no_grasp: 7 candidates, every one rejected (collision 5, descriptor 2)"
    empty = _new_row(
        "oracle",
        attempts=0,
        successes=0,
        success_rate=float("nan"),
        success_ci_low=float("nan"),
        success_ci_high=float("nan"),
        picked=0,
        boxes=1200,
        picked_rate=0.0,
        picked_ci_low=0.0,
        picked_ci_high=0.003191,
        pph_motion=float("nan"),
        no_attempt_reason=why,
        end_bin_empty=0,
        end_no_grasp=100,
        fail_collision=0,
        wrong_target=0,
    )
    t = table3_table(_evaluation([_new_row(), empty]))
    assert t.headers == [
        "",
        "system",
        "hand",
        "success rate (95 % CI)",
        "successes / attempts",
        "boxes picked",
        "boxes picked (95 % CI)",
        "mean PPH (motion only)",
        "no attempt: why",
    ]
    md = _md_rows(t)
    assert md[1] == [
        "this reproduction, test split, 100 trials",
        "ours: DCNN + descriptor + 2.5D VS (2 cups)",
        "suction (2 cups)",
        "99.1 % (95.3–99.8)",
        "116/117",
        "116/118",
        "98.3 % (94.0–99.5)",
        "1036.1",
        "",
    ]
    # 0 of 1200 boxes: 0.0 %, interval 0.0–0.3 %
    assert md[2][3:] == ["—", "0/0", "0/1200", "0.0 % (0.0–0.3)", "—", why]
    assert t.markdown().splitlines()[1].endswith("|---:|---|")  # the reason is text
    csv_rows = t.csv_text().splitlines()
    assert csv_rows[0].startswith(
        'source,split,trials,system,hand,success rate (%),"success rate, 95 % CI low (%)"'
    )
    assert csv_rows[2].endswith(
        ",test,100,ours: DCNN + descriptor + 2.5D VS (2 cups),"
        "suction (2 cups),99.15,95.32,99.85,116,117,116,118,98.31,94.02,"
        "99.53,1036.1,"
    )
    assert csv_rows[3].endswith(',,,,0,0,0,1200,0.00,0.00,0.32,,"' + why + '"')
    f = _md_rows(failures_table(_evaluation([_new_row(), empty])))
    assert f[1][:2] == ["oracle", "test, 100 trials"]
    assert f[1][2:] == ["0"] * 7 + ["0", "100", "0", "0", "—", "—"]


def _ablation(rows: list[dict], trials: int = 10):
    from pipeline.report.ablation import AblationInfo

    return AblationInfo(
        Path("a"), {"config": {"ablation": {"trials": trials}}, "metrics": {"ablation": rows}}
    )


def _ablation_row(planner: str, variant: str, successes: int, attempts: int, **changes) -> dict:
    """An ablation row (pipeline.stages.ablation: ROW_KEYS, fail_*, end_*, no trials or wrong-target
    counts)."""
    row = {
        k: v
        for k, v in _new_row(planner).items()
        if k not in ("trials", "wrong_target", "second_tier_attempts", "second_tier_successes")
    }
    row.update(
        variant=variant,
        meaning=f"{variant} meaning",
        overrides="-",
        evaluate_version=f"e_{variant}",
        successes=successes,
        attempts=attempts,
        **changes,
    )
    return row


def test_table3_adds_the_ablations_dev_rows():
    """Under the test rows: the ablation's all_on rows of each planner, then its
    simulator_knowledge rows, each labelled with the split and the trials; other variants stay
    in the ablation's own table. Their failures and trial ends are in the failures table."""
    rows = [
        _ablation_row(p, v, 110, 111)
        for p in ("oracle", "dcnn")
        for v in ("all_on", "no_gate", "simulator_knowledge")
    ]
    rows[4].update(fail_no_seal=3, end_max_failures=1)  # dcnn / no_gate: not shown
    rows[5].update(fail_dropped=2, end_max_attempts=1)  # dcnn / simulator_knowledge
    ablation = _ablation(rows)
    info = _evaluation([_new_row()])
    md = _md_rows(table3_table(info, ablation))
    dev = "this reproduction, dev split, 10 trials (the paper's size; the heaps development used)"
    knows = (
        "simulator knowledge: the run-time check sees the heap's true boxes (not a real "
        "cell), dev split, 10 trials"
    )
    assert [(r[0], r[1][:5]) for r in md[1:]] == [
        ("this reproduction, test split, 100 trials", "ours:"),
        (dev, "oracl"),
        (dev, "ours:"),
        (knows, "oracl"),
        (knows, "ours:"),
    ]
    assert md[2][3:5] == ["99.1 % (95.3–99.8)", "110/111"]  # the row's own interval, as stored
    f = _md_rows(failures_table(info, ablation))
    assert [r[:2] for r in f] == [
        ["dcnn", "test, 100 trials"],
        ["oracle", "dev, 10 trials"],
        ["dcnn", "dev, 10 trials"],
        ["oracle", "dev, 10 trials, simulator knowledge"],
        ["dcnn", "dev, 10 trials, simulator knowledge"],
    ]
    # dcnn / simulator_knowledge: 2 dropped; 1 trial at the attempt limit; the ablation keeps
    # no success-on-another-box or second-tier counts (—)
    assert f[4][2:] == ["0", "2", "2", "0", "0", "0", "—", "1", "0", "0", "1", "—", "—"]
    csv_rows = failures_table(info, ablation).csv_text().splitlines()
    assert csv_rows[5].startswith("dcnn,dev,10,simulator_knowledge,0,2,2,")
    assert table3_table(info, None).rows == table3_table(info).rows  # no ablation: no dev rows


def test_table3_section_text():
    from pipeline.report.closed_loop import render_evaluate

    info = _evaluation([_new_row(), _new_row("oracle")])
    info.manifest["config"].update(
        evaluate={
            "split": "test",
            "num_trials": 100,
            "boxes_per_trial": 12,
            "collision_model": "observed",
        },
        motion={"max_joint_speed": 3.14, "max_joint_accel": 10.0},
        servo={"control_rate_hz": 30.0},
    )
    ablation = _ablation([_ablation_row("oracle", "all_on", 110, 111)])
    tables = {
        t.name: t
        for t in (
            table3_table(info, ablation),
            failures_table(info, ablation),
            path_deviation_table(info),
        )
    }
    tables["table3_no_grasp"] = tables["table3_path_deviation"]  # no trials.json here
    text = "\n".join(render_evaluate(info, tables, ablation))
    assert "(evaluation artifact `x`, test split): 100 trials of 12 boxes" in text
    assert "nothing (no threshold, option or variant) is chosen on them" in text
    assert "ablation artifact `a` on the dev split, 10 trials, the paper's size" in text
    # the honest timing, next to the PPH
    for words in (
        "teleported",
        "no acceleration limit",
        "trapezoidal joint profiles at "
        "`motion.max_joint_speed` = 3.14 rad/s and `motion.max_joint_accel` = 10.0",
        "no sensing, computing or control latency",
        "no settling time",
        "point-to-point move whose duration is computed",
        "A real cell would run slower than these figures",
    ):
        assert words in text
    assert text.index("What the simulated time leaves out") > text.index("| 1036.1 |")
    assert "depth image alone (observation-only)" in text
    assert "The *oracle* row plans from ground truth" in text
    assert "through the same observation-only check" in text
    old = _evaluation([_old_row()], split=None)
    tables = {
        t.name: t for t in (table3_table(old), failures_table(old), path_deviation_table(old))
    }
    tables["table3_no_grasp"] = tables["table3_path_deviation"]
    text = "\n".join(render_evaluate(old, tables))
    assert "made before `evaluate.collision_model`" in text
    assert "The *oracle* row" not in text  # no oracle row here
    assert "development used them, so these rows are not held out" in text
    assert "ablation artifact" not in text


def test_no_grasp_table_sums_the_no_grasp_endings(tmp_path):
    """Two DCNN trials ended with no grasp (2 + 1 boxes left; 0 + 3 candidates, of which 2
    collide and 1 repeats a failure), one ended with the bin empty; the oracle has none. The
    labels held an executable grasp in the first (its 2 boxes: perception lost them), not in the
    second; the oracle was not asked (—, empty in the CSV)."""
    import json

    trials = [
        {
            "planner": "dcnn",
            "end": "no_grasp",
            "no_grasp": {
                "boxes_left": 2,
                "candidates": 0,
                "checked": 0,
                "rejected": {},
                "label_candidates": 1,
                "label_executable": True,
            },
        },
        {
            "planner": "dcnn",
            "end": "no_grasp",
            "no_grasp": {
                "boxes_left": 1,
                "candidates": 3,
                "checked": 3,
                "rejected": {"collision": 2, "repeat": 1},
                "label_candidates": 2,
                "label_executable": False,
            },
        },
        {"planner": "dcnn", "end": "bin_empty"},
        {"planner": "oracle", "end": "bin_empty"},
    ]
    (tmp_path / "trials.json").write_text(json.dumps(trials))
    info = ArtifactInfo(
        tmp_path, {"metrics": {"table3": [{"planner": "dcnn"}, {"planner": "oracle"}]}}
    )
    assert no_grasp_table(info).csv_text().splitlines() == [
        "planner,trials,boxes left,candidates,rejected: collision,rejected: repeat,"
        "trials where the labels had a grasp,boxes left by those trials",
        "dcnn,2,3,3,2,1,1,2",
        "oracle,0,0,0,0,0,,",
    ]
    assert "| oracle | 0 | 0 | 0 | 0 | 0 | — | — |" in no_grasp_table(info).markdown()


def test_ablation_table_by_hand():
    """An old row (made before the intervals): 9 of 10 attempts, 9 of 12 boxes (75 %), the
    overrides as text, a missing success rate (no attempt) and missing keys shown as —; a new
    row with its intervals, trial ends, every failure kind and the reason for no attempt."""
    row = {
        "planner": "oracle",
        "variant": "no_gate",
        "overrides": "evaluate.check_reachability=false",
        "success_rate": 0.9,
        "attempts": 10,
        "successes": 9,
        "picked": 9,
        "boxes": 12,
        "pph_motion": 990.5,
        "fail_no_seal": 1,
        "fail_dropped": 0,
        "fail_collision": 0,
        "fail_lost_target": 0,
        "fail_timeout": 0,
        "end_no_grasp": 2,
    }
    empty = dict(row, variant="all_off", success_rate=None, attempts=0, successes=0, picked=0)
    why = "10 trials no_grasp: the planner proposed no grasp"
    new = _ablation_row("dcnn", "all_on", 116, 117, fail_timeout=1, end_bin_empty=8, end_no_grasp=2)
    none = _ablation_row(
        "dcnn",
        "no_gate",
        0,
        0,
        success_rate=None,
        success_ci_low=None,
        success_ci_high=None,
        picked=0,
        picked_rate=0.0,
        picked_ci_low=0.0,
        picked_ci_high=0.030935,
        pph_motion=None,
        no_attempt_reason=why,
        end_bin_empty=0,
        end_no_grasp=10,
        fail_collision=0,
    )
    t = ablation_table([row, empty, new, none])
    assert t.headers[3:] == [
        "success rate (95 % CI)",
        "successes / attempts",
        "boxes picked",
        "boxes picked (95 % CI)",
        "PPH (motion)",
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
    assert md[0] == [
        "oracle",
        "no_gate",
        "evaluate.check_reachability=false",
        "90.0 %",
        "9/10",
        "9/12",
        "75.0 %",
        "990.5",
        "1",
        "0",
        "0",
        "—",
        "0",
        "0",
        "—",
        "2",
        "—",
        "—",
        "—",
    ]
    assert md[1][:5] == ["oracle", "all_off", "evaluate.check_reachability=false", "—", "0/0"]
    assert md[2][3:] == [
        "99.1 % (95.3–99.8)",
        "116/117",
        "116/118",
        "98.3 % (94.0–99.5)",
        "1036.1",
        "0",
        "0",
        "2",
        "0",
        "1",
        "0",
        "8",
        "2",
        "0",
        "0",
        "",
    ]
    # 0 of 120 boxes picked: 0.0 %, interval 0.0–3.1 %; the reason in the last column
    assert md[3][3:8] == ["—", "0/0", "0/118", "0.0 % (0.0–3.1)", "—"]
    assert md[3][-1] == why
    csv_rows = t.csv_text().splitlines()
    assert csv_rows[1] == (
        "oracle,no_gate,evaluate.check_reachability=false,90.00,,,9,10,9,12,"
        "75.00,,,990.5,1,0,0,,0,0,,2,,,"
    )
    assert csv_rows[3].startswith("dcnn,all_on,-,99.15,95.32,99.85,116,117,116,118,98.31,")


def test_ablation_section_says_it_runs_on_the_dev_split():
    from pipeline.report.ablation import render_ablation

    rows = [_ablation_row("dcnn", v, 116, 117) for v in ("all_on", "simulator_knowledge")]
    info = _ablation(rows)
    text = "\n".join(render_ablation(info, {"ablation": ablation_table(rows)}))
    assert "every run on the **dev split**" in text and "10 trials per planner" in text
    assert "*simulator_knowledge* is no extension" in text
    assert "- *simulator_knowledge*: simulator_knowledge meaning" in text


def test_table2_shows_each_gqcnn_with_what_it_was_trained_on():
    from pipeline.dexnet.table2 import PLANNER_NAMES
    from pipeline.report.baseline import render_baseline

    rows = [
        {
            "planner": k,
            "name": PLANNER_NAMES[k],
            "images": 4,
            "no_grasp": 0,
            "within_30px": 0.5,
            "median_distance_px": 20.0,
        }
        for k in ("gqcnn", "gqcnn_ood")
    ]
    info = ArtifactInfo(
        Path("x"),
        {
            "metrics": {
                "table2": {
                    "radius_px": 30.0,
                    "rows": rows,
                    "paper": {
                        "within_30px": {"dexnet4": 0.5888, "ours": 0.7916},
                        "radius_px": 30.0,
                    },
                },
                "gqcnn_ood": {"box_test": {"accuracy": 0.75, "precision": 0.5, "recall": 0.25}},
                "ood_candidate_labels": {"train": {"scenes": 3, "objects": 30, "candidates": 96}},
            }
        },
    )
    t = table2_table(info)
    md = t.markdown()
    assert "| this reproduction | Dex-Net-style GQ-CNN + CEM, trained on the box heaps |" in md
    assert "| this reproduction | Dex-Net-style GQ-CNN + CEM, trained on non-box objects |" in md
    text = "\n".join(render_baseline(info, {"table2_centre_distance": t}, {}))
    assert "3 heaps of 30 random convex" in text and "accuracy 75.0 %" in text


def _stage(root: Path, stage: str, version: str, metrics: dict, config: dict) -> None:
    """A complete hand-made artifact of ``stage`` (manifest, hashes, ``latest``)."""
    from pipeline.artifacts import run_stage

    def body(run) -> None:
        (run.work_dir / "note.txt").write_text(stage + "\n")
        run.metrics.update(metrics)

    run_stage(root, stage, version, config, {}, body, say=lambda _: None)


def test_section_finds_the_ablation_for_its_dev_rows(tmp_path):
    """The section reads the ablation the report resolved (``ctx.found``), or resolves it
    itself; without one, Table 3 has no dev rows and says nothing of them."""
    from omegaconf import OmegaConf

    from pipeline.report.closed_loop import ClosedLoopSection
    from pipeline.report.section import Context

    data = tmp_path / "data"
    _stage(
        data,
        "evaluate",
        "00000000000000e1",
        {"table3": [_new_row()], "paper_table3": [PAPER_OURS]},
        {
            "evaluate": {
                "split": "test",
                "num_trials": 100,
                "boxes_per_trial": 12,
                "collision_model": "observed",
            }
        },
    )
    cfg = OmegaConf.create(
        {
            "paths": {"data": str(data)},
            "report": {"evaluate_version": "latest", "ablation_version": "latest"},
        }
    )
    section = ClosedLoopSection()

    def build(ctx: Context) -> tuple[list[list[str]], str]:
        info = section.resolve(ctx)
        assert section.configure(info, ctx) == {}  # the ablation is an upstream of its own
        tables = {t.name: t for t in section.tables(info, ctx)}
        return _md_rows(tables["table3_success"]), "\n".join(section.markdown(info, tables, {}))

    md, text = build(Context(cfg))  # no ablation artifact yet
    assert [r[0] for r in md] == ["paper (real robot)", "this reproduction, test split, 100 trials"]
    assert "ablation artifact" not in text
    _stage(
        data,
        "ablation",
        "00000000000000a1",
        {"ablation": [_ablation_row("dcnn", v, 116, 117) for v in ("all_on", "no_gate")]},
        {"ablation": {"trials": 10}},
    )
    md, text = build(Context(cfg))  # resolved by the section itself
    assert md[2][0].startswith("this reproduction, dev split, 10 trials (the paper's size")
    assert len(md) == 3 and "ablation artifact `00000000000000a1` on the dev split" in text
    md, _ = build(Context(cfg, found={"ablation": None}))  # the report found none
    assert len(md) == 2
