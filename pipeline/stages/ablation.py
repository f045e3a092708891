"""Ablation of the closed loop's execution: each extension on and off, on the same heaps.

    python -m pipeline.stages.ablation [experiment=default] [ablation.planners=[oracle,dcnn]]

Each variant of ``ablation.variants`` (``conf/stage/ablation.yaml``) is one run of the evaluation
stage with the variant's overrides, for each planner that ``ablation.variant_planners`` names for
it (those of ``ablation.planners`` where it names none; rows grouped by planner in the
evaluation's order of planners), with
``ablation.trials`` trials, on the ``dev`` heaps (the ablation is development; the report's
Table 3 is measured on ``test``, which nothing is chosen on; the heaps depend only on ``seed``,
the split and the trial index). Every run is an evaluation artifact of its own (reused when its
version exists); this stage gathers their Table 3 rows:

    ablation.csv    planner, variant, overrides, success rate, attempts, successes, boxes picked,
                    PPH (motion), failure counts, trial ends, the evaluation's version
    ablation.json   the same rows

The oracle planner (the labels computed on the home image) and the DCNN are the default. The
oracle's labels and run-time check follow the same switches, so its rows isolate what an
extension does to execution. For the DCNN the network is the one trained on the default labels;
a variant changes only its run-time execution. The evaluation stage's ``latest`` is put back
afterwards, so that it still names the ``make reproduce`` evaluation.
"""

from __future__ import annotations

import json
from pathlib import Path

from omegaconf import DictConfig

from pipeline.artifacts import stage_config
from pipeline.artifacts.csvfile import write_rows
from pipeline.artifacts.store import StageRun
from pipeline.runtime.cli import compose, data_root, scale_overrides, stage_command
from pipeline.runtime.stage_artifacts import run_stage_from_config
from pipeline.tracking import StageLog
from pipeline.world.books import RATE_KEYS, finite

STAGE = "ablation"
SECTIONS = ("seed", "ablation")
NOT_AFFECTING_RESULT = ("ablation.force",)
SPLIT = "dev"  # the ablation chooses between execution variants: never on the test heaps
ROW_KEYS = (*RATE_KEYS, "path_deviation_mm_median", "path_deviation_mm_max", "no_attempt_reason")


def run_variants(cfg: DictConfig, base: list[str]) -> list[dict]:
    """One evaluation per (planner, variant) and its Table 3 row, in config order."""
    from pipeline.artifacts.pointers import keep_latest
    from pipeline.stages.evaluate import PLANNERS, evaluate

    ab = cfg.ablation

    def planners_of(variant) -> list[str]:
        return [str(p) for p in ab.variant_planners.get(variant.name, ab.planners)]

    used = {p for v in ab.variants for p in planners_of(v)}
    rows = []
    with keep_latest([data_root(cfg) / "evaluate"]):
        for planner in [p for p in PLANNERS if p in used]:
            for v in ab.variants:
                if planner not in planners_of(v):
                    continue
                overrides = [str(o) for o in v.overrides]
                extra = [
                    f"planner={planner}",
                    f"evaluate.num_trials={int(ab.trials)}",
                    f"evaluate.split={SPLIT}",
                    *overrides,
                ]
                print(
                    f"[{STAGE}] {planner} / {v.name}: evaluate {' '.join(base + extra)}", flush=True
                )
                out = Path(evaluate(compose("evaluate", base + extra)))
                t3 = json.loads((out / "manifest.json").read_text())["metrics"]["table3"]
                row = next(r for r in t3 if r["planner"] == planner)
                rows.append(
                    {
                        "planner": planner,
                        "variant": str(v.name),
                        "meaning": str(v.meaning),
                        "overrides": " ".join(overrides) or "-",
                        **{k: finite(row.get(k)) for k in ROW_KEYS},
                        **{k: val for k, val in row.items() if k.startswith(("fail_", "end_"))},
                        "evaluate_version": out.name,
                    }
                )
    return rows


def ablation(cfg: DictConfig, overrides: list[str] | None = None) -> Path:
    """Run the ablation; returns its artifact folder. ``overrides``: passed to every run (the
    command line's own, by default none)."""
    from pipeline.stages.evaluate import PLANNERS

    ab = cfg.ablation
    for planner in ab.planners:
        if str(planner) not in PLANNERS:
            raise ValueError(
                f"ablation.planners has {planner!r}: choose from {', '.join(PLANNERS)}"
            )
    names = [str(v.name) for v in ab.variants]
    if len(set(names)) != len(names):
        raise ValueError(f"ablation.variants has repeated names: {names}; give each its own")
    for name, planners in ab.variant_planners.items():
        for planner in planners:
            if str(planner) not in PLANNERS:
                raise ValueError(
                    f"ablation.variant_planners.{name} has {planner!r}: choose "
                    f"from {', '.join(PLANNERS)}"
                )
    base = scale_overrides(cfg, overrides)
    rows = run_variants(cfg, base)
    upstream = {f"{r['planner']}/{r['variant']}": r["evaluate_version"] for r in rows}
    config = stage_config(cfg, SECTIONS, NOT_AFFECTING_RESULT)

    def body(run: StageRun) -> None:
        write_rows(run.work_dir / "ablation.csv", rows)
        (run.work_dir / "ablation.json").write_text(json.dumps(rows, indent=1) + "\n")
        run.metrics["ablation"] = rows
        with StageLog.for_stage(run.work_dir, STAGE, run.version) as log:
            for i, row in enumerate(rows):
                log.set_time(sequences={"variant": i}, clock_ns=i * 1_000_000_000)
                if row["success_rate"] is not None:
                    log.log_scalar(f"{row['planner']}/success_rate", float(row["success_rate"]))
                log.log_text("log", "ablation: " + json.dumps(row))

    return run_stage_from_config(cfg, STAGE, config, upstream, body)


main = stage_command("ablation", ablation, study=True)


if __name__ == "__main__":
    main()
