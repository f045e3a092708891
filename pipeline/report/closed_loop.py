"""Closed-loop section: the paper's Table 3 (bin-picking success rate and speed, Secs. 5, 6), from
the evaluation artifact (``data/evaluate/<version>``, ``report.evaluate_version``; optional; the
``test`` split in the default experiment), with the ``all_on`` and ``simulator_knowledge`` rows
of the ablation artifact (``report.ablation_version``; the ``dev`` split) where one exists.

Tables ``table3_success`` (success rate and boxes picked with their Wilson 95 % intervals, PPH,
why a row made no attempt), ``table3_failures`` (failed attempts by kind, how trials ended),
``table3_no_grasp`` (the trials that ended with no grasp: boxes left, rejections by reason),
``table3_path_deviation`` (executed vs. predicted servo path, mm) and ``table3_timing``
(measured wall-clock figures, volatile); figure ``servo_convergence.png`` (the servo's
translation and rotation error over simulated time).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pipeline.report.ablation import SIMULATOR_KNOWLEDGE, AblationInfo, resolve_ablation
from pipeline.report.ablation import SPLIT as DEV_SPLIT
from pipeline.report.figures import figure_servo_convergence
from pipeline.report.section import Context, Section
from pipeline.report.tables import (
    Column,
    Table,
    book_columns,
    count_column,
    drops_table,
    end_columns,
    failure_columns,
    number,
    pph_column,
    reason_column,
    spread_column,
    table_of,
    text_column,
)
from pipeline.report.upstream import ArtifactInfo, lacks_metrics, resolve_upstream

TABLE3_SECTION = "Table 3: closed-loop bin-picking (Secs. 5, 6)"
EVALUATE_NOT_RUN = "Closed-loop evaluation: not run yet (`make evaluate`)."
PLANNER_LABELS = {
    "dcnn": "ours: DCNN + descriptor + 2.5D VS (2 cups)",
    "dexnet": "Dex-Net-style GQ-CNN + CEM, trained on the box heaps, same robot (1 cup)",
    "dexnet_ood": "Dex-Net-style GQ-CNN + CEM, trained on non-box objects, same robot (1 cup)",
    "oracle": "oracle: the labelling stage's labels on the home image (ground "
    "truth; the ceiling of execution, not a planner)",
}
FAILURE_MEANING = {
    "no_seal": "a cup's rim did not lie on one face of one box (edge, corner, small face, "
    "tilt beyond the cup's compliance)",
    "dropped": "sealed, but the active cups cannot hold the box's weight and torque",
    "collision": "the arm or hand touched the bin (a protective stop; other boxes are pushed "
    "aside under physics unless evaluate.stop_on_box_contact)",
    "joint_limits": "the servo ran into joint limits",
    "timeout": "the servo did not converge in time",
    "lost_target": "the descriptor found no surface at the tracked point",
}
PAPER_SOURCE = "paper (real robot)"
PAPER_TRIALS = 10  # the paper's Sec. 6: 10 trials of 12 boxes per planner
# The ablation's variants shown in Table 3 (on the dev split), in this order.
DEV_VARIANTS = ("all_on", SIMULATOR_KNOWLEDGE)
# An evaluation made before ``evaluate.split`` drew its heaps from the stream that is now dev's
# (pipeline.world.trial.HEAP_STREAMS: dev keeps the earlier keys).
SPLIT_BEFORE_SPLITS = DEV_SPLIT


@dataclass
class EvaluateInfo(ArtifactInfo):
    """The evaluation artifact: folder and manifest (``metrics.table3``, ``paper_table3``), with
    ``servo_convergence.csv`` (servo error over simulated time, s). ``ablation``: the ablation
    artifact whose dev rows Table 3 shows too (None: none), set by ``ClosedLoopSection.
    configure``."""

    ablation: AblationInfo | None = None

    @classmethod
    def load(cls, folder: Path, manifest: dict) -> EvaluateInfo:
        """Raises ``ArtifactError`` when the manifest lacks Table 3."""
        if not (manifest.get("metrics") or {}).get("table3"):
            raise lacks_metrics(folder, "evaluate", "metrics.table3")
        return cls(folder, manifest)


def resolve_evaluate(root: Path, version: str) -> EvaluateInfo | None:
    """The evaluation artifact to report, or None when ``version`` is "latest" and none exists."""
    return resolve_upstream(root, "evaluate", version, EvaluateInfo.load)


def split_of(manifest: dict) -> str:
    """The evaluation's ``evaluate.split`` (``SPLIT_BEFORE_SPLITS`` for an artifact made before
    the splits)."""
    ev = (manifest.get("config") or {}).get("evaluate") or {}
    return str(ev.get("split") or SPLIT_BEFORE_SPLITS)


def _hand(planner: str) -> str:
    return "suction (1 cup)" if planner in ("dexnet", "dexnet_ood") else "suction (2 cups)"


def _trials(n: Any) -> str:
    """ ", 100 trials" ("" where the count is not known)."""
    return "" if n is None else f", {n} trial{'' if n == 1 else 's'}"


def evaluation_rows(info: ArtifactInfo) -> list[dict]:
    """The evaluation's Table 3 rows with their ``source`` (the row's label: this reproduction,
    the split, the trials), ``split``, ``variant`` ("") and ``heaps`` (split and trials,
    short)."""
    split = split_of(info.manifest)
    rows = []
    for r in info.metrics["table3"]:
        n = r.get("trials")
        rows.append(
            {
                **r,
                "source": f"this reproduction, {split} split{_trials(n)}",
                "split": split,
                "variant": "",
                "heaps": f"{split}{_trials(n)}",
            }
        )
    return rows


def _dev_source(variant: str, n: int | None) -> str:
    """How Table 3 labels an ablation row on the dev split."""
    if variant == SIMULATOR_KNOWLEDGE:
        return (
            "simulator knowledge: the run-time check sees the heap's true boxes (not a real "
            f"cell), {DEV_SPLIT} split{_trials(n)}"
        )
    size = "the paper's size; " if n == PAPER_TRIALS else ""
    return f"this reproduction, {DEV_SPLIT} split{_trials(n)} ({size}the heaps development used)"


def dev_rows(ablation: AblationInfo | None) -> list[dict]:
    """The ablation's rows of ``DEV_VARIANTS`` (every planner; none without an ablation), with
    ``source``, ``split`` (dev: the ablation never runs on test), ``trials`` and ``heaps``."""
    if ablation is None:
        return []
    n = ablation.trials
    return [
        {
            **r,
            "source": _dev_source(v, n),
            "split": DEV_SPLIT,
            "trials": n,
            "heaps": f"{DEV_SPLIT}{_trials(n)}"
            + (", simulator knowledge" if v == SIMULATOR_KNOWLEDGE else ""),
        }
        for v in DEV_VARIANTS
        for r in ablation.rows
        if r.get("variant") == v
    ]


def paper_rows(info: ArtifactInfo) -> list[dict]:
    """The paper's Table 3 (``paper_table3``: success in percent) as rows of ours."""
    return [
        {
            "source": PAPER_SOURCE,
            "system": r["system"],
            "hand": r["hand"],
            "success_rate": r["success"] / 100.0,
            "pph_motion": r["pph"],
            "no_attempt_reason": "",
        }
        for r in info.metrics["paper_table3"]
    ]


def _system(r: dict) -> str:
    return r.get("system") or PLANNER_LABELS.get(r["planner"], r["planner"])


def table3_table(info: ArtifactInfo, ablation: AblationInfo | None = None) -> Table:
    """Table 3: the paper's rows, the evaluation's and the ablation's dev rows (``dev_rows``):
    success rate and boxes picked with their Wilson 95 % intervals (percent), PPH of the
    robot's simulated motion, why a row made no attempt. CSV: the split and trials in columns
    of their own, rates and interval bounds in percent."""
    rows = paper_rows(info) + evaluation_rows(info) + dev_rows(ablation)
    columns = [
        spread_column("", "source", ("source", "split", "trials")),
        Column("system", _system),
        Column("hand", lambda r: r.get("hand") or _hand(r["planner"])),
        *book_columns(),
        pph_column("mean PPH (motion only)"),
        reason_column(),
    ]
    return table_of("table3_success", columns, rows, text_columns=3)


def failures_table(info: ArtifactInfo, ablation: AblationInfo | None = None) -> Table:
    """Failed attempts by kind, successes on another box, how the trials ended, and the DCNN's
    attempts on candidates of its fallback tier and their successes (``evaluate.
    dcnn_fallback_ratio``; — for the other planners and for artifacts that predate it), per
    planner: the evaluation's rows, then the ablation's dev rows (``dev_rows``; — where the
    ablation does not keep a count)."""

    def tier(key: str):
        return lambda r: int(r[key]) if r["planner"] == "dcnn" and key in r else None

    columns = [
        text_column("planner", "planner"),
        spread_column("heaps", "heaps", ("split", "trials", "variant")),
        *failure_columns(),
        count_column("success on another box", "wrong_target"),
        *end_columns(),
        Column("second-tier attempts", tier("second_tier_attempts")),
        Column("second-tier successes", tier("second_tier_successes")),
    ]
    return table_of(
        "table3_failures", columns, evaluation_rows(info) + dev_rows(ablation), text_columns=2
    )


def no_grasp_table(info: EvaluateInfo) -> Table:
    """The trials that ended with "no grasp", per planner (from ``trials.json``): how many, the
    boxes they left in the bin, the planner's candidates at that last home image, and the
    (candidate, pattern) pairs the run-time check rejected there, per reason; then, where the
    evaluation asked the labels on that image (``evaluate.label_no_grasp``), in how many of the
    trials the labels held a grasp that passed the same check (perception lost the boxes) and
    the boxes those trials left. Not asked (the oracle itself, or the option off): —."""
    import json

    trials = (
        json.loads((info.folder / "trials.json").read_text())
        if (info.folder / "trials.json").exists()
        else []
    )
    ends = [t for t in trials if t.get("end") == "no_grasp" and t.get("no_grasp")]
    reasons = sorted({k for t in ends for k in t["no_grasp"].get("rejected", {})})
    headers = [
        "planner",
        "trials",
        "boxes left",
        "candidates",
        *(f"rejected: {k}" for k in reasons),
        "trials where the labels had a grasp",
        "boxes left by those trials",
    ]
    rows = []
    for r in info.metrics["table3"]:
        mine = [t["no_grasp"] for t in ends if t["planner"] == r["planner"]]
        asked = [n for n in mine if "label_executable" in n]
        lost = [n for n in asked if n["label_executable"]]
        rows.append(
            [
                r["planner"],
                len(mine),
                sum(int(n["boxes_left"]) for n in mine),
                sum(int(n["candidates"]) for n in mine),
                *(sum(int(n.get("rejected", {}).get(k, 0)) for n in mine) for k in reasons),
                len(lost) if asked else None,
                sum(int(n["boxes_left"]) for n in lost) if asked else None,
            ]
        )
    return Table("table3_no_grasp", headers, rows)


def table3_timing_table(info: EvaluateInfo) -> Table:
    """Measured wall-clock figures of the evaluation run (volatile)."""
    t = (info.manifest.get("timings") or {}).get("planners", {})
    headers = [
        "planner",
        "planning time median (ms; planner + run-time check)",
        "PPH incl. planning",
        "descriptor (ms/frame)",
        "control loop (Hz, wall)",
        "sim s per wall s",
        "trial wall time (s)",
    ]
    rows = [
        [
            PLANNER_LABELS.get(k, k),
            v.get("planning_ms_median"),
            v.get("pph_with_planning"),
            v.get("descriptor_ms_median"),
            v.get("control_loop_hz"),
            v.get("sim_s_per_wall_s"),
            v.get("trial_wall_s_mean"),
        ]
        for k, v in t.items()
    ]
    return Table("table3_timing", headers, rows)


def path_deviation_table(info: EvaluateInfo) -> Table:
    """How far the executed servo came from the path the run-time check predicted."""
    headers = ["planner", "attempts", "median (mm)", "largest (mm)"]
    rows = [
        [
            PLANNER_LABELS.get(r["planner"], r["planner"]),
            int(r["attempts"]),
            number(r.get("path_deviation_mm_median")),
            number(r.get("path_deviation_mm_max")),
        ]
        for r in info.metrics["table3"]
    ]
    return Table("table3_path_deviation", headers, rows, ["", "{}", "{:.1f}", "{:.1f}"])


def _split_note(split: str) -> str:
    """What the evaluation's heaps are: the held-out test stream, or development's."""
    if split == "test":
        return (
            "The test heaps are a seed stream of their own, disjoint from the dev heaps that "
            "development and the ablation use: nothing (no threshold, option or variant) is "
            "chosen on them."
        )
    return (
        f"These heaps are the {split} stream's (`evaluate.split={split}`, or an artifact "
        "made before the splits): development used them, so these rows are not held out."
    )


def _dev_rows_note(ablation: AblationInfo | None, split: str) -> list[str]:
    """The paragraph on the ablation's rows under the evaluation's ([] without them)."""
    if not dev_rows(ablation):
        return []
    n = ablation.trials
    size = _trials(n) + (", the paper's size" if n == PAPER_TRIALS else "")
    return [
        f"Under this reproduction's {split} rows, rows of the ablation artifact "
        f"`{ablation.version}` on the {DEV_SPLIT} split{size}: *all_on* (every default, as "
        "in the rows above, on the heaps development used) and *simulator knowledge* (the "
        "run-time check given the heap's true boxes, hidden ones included: ground truth a "
        "real cell lacks, shown only to measure what the robot's own model of the heap "
        "costs). Their failures and trial ends are in the second table below and in the "
        "ablation section.",
        "",
    ]


def _knowledge_note(ev: dict, planners: list[str]) -> str:
    """What the robot knows when it decides, by the evaluation's ``evaluate.collision_model``
    (and, when ``planners`` hold the oracle, what the oracle knows)."""
    model = ev.get("collision_model")
    if model == "observed":
        check = "the same observation-only check"
        robot = (
            "The robot decides from its depth image alone (observation-only): the planner "
            "reads the home depth image, the servo each new image, and the run-time check "
            "tests the pose and the path against the bin and a model of the heap built from "
            "that image (`evaluate.collision_model=observed`; a hidden box is unknown to "
            "it)."
        )
    elif model is None:
        check = "the same check"
        robot = (
            "This evaluation artifact was made before `evaluate.collision_model`: its "
            "run-time check tested the robot against the simulator's true boxes (simulator "
            "knowledge a real cell lacks); rerun `make evaluate` for the observation-only "
            "figures."
        )
    else:
        check = "the same check"
        robot = (
            f"This evaluation ran with `evaluate.collision_model={model}`: the run-time "
            "check saw the heap's true boxes (simulator knowledge a real cell lacks), not a "
            "model from the depth image."
        )
    oracle = (
        " The *oracle* row plans from ground truth (the labelling stage's labels, "
        "computed from the simulator's ideal depth, instance mask and box poses) but "
        f"executes through {check} and servo: the ceiling of execution, not a planner."
        if "oracle" in planners
        else ""
    )
    return "**What the robot knows.** " + robot + oracle


def _timing_note(cfg: dict) -> str:
    """What the simulated time that PPH counts leaves out."""
    motion = cfg.get("motion") or {}
    return (
        "**What the simulated time leaves out.** PPH counts simulated seconds of robot "
        f"motion: servoing at {(cfg.get('servo') or {}).get('control_rate_hz')} Hz, the "
        "approach, suction on and off, the lift, and point-to-point moves to the conveyor and "
        "back (trapezoidal joint profiles at `motion.max_joint_speed` = "
        f"{motion.get('max_joint_speed')} rad/s and `motion.max_joint_accel` = "
        f"{motion.get('max_joint_accel')} rad/s²). During servoing and the approach the joints "
        "are set every control period (teleported) at up to the speed limits, with no "
        "acceleration limit. There is no sensing, computing or control latency (the measured "
        "planning time is added only in [tables/table3_timing.csv](tables/table3_timing.csv), "
        "wall-clock, not part of the reproducibility check), no settling time (neither the "
        "arm's after a move nor the heap's after a pick is on the clock), and the carry to the "
        "conveyor is a point-to-point move whose duration is computed, not simulated with the "
        "box on the cups. A real cell would run slower than these figures; the paper's are a "
        "real robot's."
    )


def render_evaluate(
    info: EvaluateInfo, tables: dict[str, Table], ablation: AblationInfo | None = None
) -> list[str]:
    """README lines of the Table 3 section (``ablation``: the artifact whose dev rows Table 3
    shows, None: none)."""
    out: list[str] = []
    cfg = info.manifest.get("config", {})
    ev = cfg.get("evaluate") or {}
    split = split_of(info.manifest)
    out += [
        f"Pick-and-place trials in pybullet (evaluation artifact `{info.version}`, "
        f"{split} split): {ev.get('num_trials')} trials of {ev.get('boxes_per_trial')} boxes "
        "per planner, the same heaps (same seeds) for every planner, boxes of `eval_boxes` "
        "(the paper's three sizes and four others). " + _split_note(split) + " Success "
        "rate = successful grasps / attempts (the paper's figure); boxes picked = boxes taken "
        "out of the bins / boxes dropped in (what the success rate leaves out: boxes the robot "
        "found no grasp for); both with their Wilson 95 % score interval in brackets. PPH = "
        "successful picks per hour of *simulated* robot time (below: what it leaves out). The "
        "paper's rows are copied from its Table 3 (a real robot; it gives no interval or "
        "attempt count). A row with no attempt says why in its last column (how its trials "
        'ended; for "no grasp", the planner\'s candidates and what rejected them).',
        "",
        *_dev_rows_note(ablation, split),
        tables["table3_success"].markdown(),
        _timing_note(cfg),
        "",
        _knowledge_note(ev, [r["planner"] for r in info.metrics["table3"]]),
        "",
        "Failures by kind (attempts) and how the trials ended, per planner and heaps:",
        "",
        tables["table3_failures"].markdown(),
        *[f"- *{k}*: {v}" for k, v in FAILURE_MEANING.items()],
        "",
        f'The {split} trials that ended with "no grasp": the boxes they left, the planner\'s '
        "candidates at that home image, and why the run-time check rejected them (a "
        "robot-level NG reason; `descriptor`: no surface at the point; `hand_fit`: the "
        "pattern's cups do not lie on the surface; `repeat`: a retry of a failed plan; "
        "docs/closed_loop.md). Zero candidates: the planner proposed nothing. The last two "
        "columns ask the labelling stage's labels on the same home image "
        "(`evaluate.label_no_grasp`): a trial counts when one of their graspable points passes "
        "the same check, so perception, not execution, lost its boxes; the other trials' boxes "
        "no labelled grasp could take (— where not asked).",
        "",
        tables["table3_no_grasp"].markdown(),
        "The run-time check predicts the servo's camera path from home on the surface it "
        "checks (`robot.path_check`, docs/closed_loop.md). The farthest the executed camera came "
        f"from that prediction, per attempt ({split} trials):",
        "",
        tables["table3_path_deviation"].markdown(),
    ]
    if "table3_drops_by_mass" in tables:
        out += [
            f"How often the pattern executed dropped a box that it had held at first, by box "
            f"mass (mass = density × volume; {split} trials) and by the pattern the planner "
            f"chose (a single cup planned as B is the execution's fallback, "
            f"evaluate.single_cup_fallback; point: a single suction point):",
            "",
            tables["table3_drops_by_mass"].markdown(),
        ]
    out += [
        "CSV versions: [tables/table3_success.csv](tables/table3_success.csv), "
        "[tables/table3_failures.csv](tables/table3_failures.csv), "
        "[tables/table3_no_grasp.csv](tables/table3_no_grasp.csv), "
        "[tables/table3_path_deviation.csv](tables/table3_path_deviation.csv)"
        + (
            ", [tables/table3_drops_by_mass.csv](tables/table3_drops_by_mass.csv)"
            if "table3_drops_by_mass" in tables
            else ""
        )
        + ".",
        "",
    ]
    return out


class ClosedLoopSection(Section):
    name = "evaluate"
    not_run = EVALUATE_NOT_RUN
    paper_table, heading = "Table 3 (bin-picking success rate and speed)", TABLE3_SECTION

    def resolve(self, ctx: Context) -> EvaluateInfo | None:
        return resolve_evaluate(ctx.root, ctx.requested("evaluate"))

    def configure(self, info: EvaluateInfo, ctx: Context) -> dict[str, Any]:
        """The ablation artifact whose dev rows Table 3 shows: the ablation section's, or resolved
        here when it has not been (its version is in the report's upstream either way)."""
        info.ablation = (
            ctx.found["ablation"]
            if "ablation" in ctx.found
            else resolve_ablation(ctx.root, ctx.requested("ablation"))
        )
        return {}

    def tables(self, info: EvaluateInfo, ctx: Context) -> list[Table]:
        out = [
            table3_table(info, info.ablation),
            failures_table(info, info.ablation),
            no_grasp_table(info),
            table3_timing_table(info),
            path_deviation_table(info),
        ]
        drops = info.manifest.get("metrics", {}).get("drops_by_mass")
        if drops:  # evaluations made before the drops were counted have none
            out.append(drops_table("table3_drops_by_mass", drops))
        return out

    def figures(self, info: EvaluateInfo, ctx: Context, folder: Path) -> dict[str, str]:
        figure_servo_convergence(
            info.folder / "servo_convergence.csv", folder / "figures" / "servo_convergence.png"
        )
        return {
            "figures/servo_convergence.png": (
                "Visual-servoing error over simulated time for the attempts of the logged "
                "trials: translation error |p_e − p_e*| (normalised) and rotation error |uθ|."
            )
        }

    def body(
        self, info: EvaluateInfo, tables: dict[str, Table], figures: dict[str, str]
    ) -> list[str]:
        return render_evaluate(info, tables, info.ablation if info is not None else None)
