"""The trials' books: Table 3's figures from the trial records, with their uncertainty.

Per planner (:func:`summarise`): trials, boxes, boxes picked, attempts, successes, and two
rates, each with its Wilson 95 % score interval (``scipy.stats.binomtest(...).proportion_ci``):

* success rate = successful attempts / attempts (the paper's Table 3 figure);
* boxes picked = picked / boxes in the bins (what the success rate leaves out: attempts that
  were never made, because the robot found no grasp it could take).

How the trials ended (``end_<reason>``: bin empty, no grasp, the failure limit, the attempt
limit), the failures by kind (``fail_<outcome>``), a row with no attempt's reason
(``no_attempt_reason``), pieces per hour from the simulated time, and how far the executed
servo strayed from the check's prediction. Deterministic: simulated time only.
"""

from __future__ import annotations

import math

import numpy as np

from pipeline.world.trial import OUTCOMES, TRIAL_ENDS, TrialResult

CONFIDENCE = 0.95
# The rate columns of a Table 3 row (``summarise``) that the studies' closed-loop rows copy.
RATE_KEYS = (
    "success_rate",
    "success_ci_low",
    "success_ci_high",
    "attempts",
    "successes",
    "picked",
    "boxes",
    "picked_rate",
    "picked_ci_low",
    "picked_ci_high",
    "pph_motion",
)


def wilson_interval(
    successes: int, trials: int, confidence: float = CONFIDENCE
) -> tuple[float, float]:
    """(low, high) Wilson score interval of a binomial proportion; (nan, nan) for 0 trials."""
    if trials <= 0:
        return float("nan"), float("nan")
    from scipy.stats import binomtest

    ci = binomtest(int(successes), int(trials)).proportion_ci(
        confidence_level=confidence, method="wilson"
    )
    return float(ci.low), float(ci.high)


def no_attempt_reason(rs: list[TrialResult]) -> str:
    """Why trials without a single attempt made none: "" when some attempt was made, else the
    trial ends and, for "no grasp", the planner's candidates and what rejected them."""
    if any(r.attempts for r in rs):
        return ""
    ends: dict[str, int] = {}
    cands, rejected = 0, {}
    for r in rs:
        ends[r.end] = ends.get(r.end, 0) + 1
        cands += int(r.no_grasp.get("candidates", 0))
        for k, v in r.no_grasp.get("rejected", {}).items():
            rejected[k] = rejected.get(k, 0) + int(v)
    why = ", ".join(f"{n} trials {e}" for e, n in sorted(ends.items()))
    if "no_grasp" in ends:
        if cands == 0:
            why += ": the planner proposed no grasp"
        else:
            top = ", ".join(f"{k} {v}" for k, v in sorted(rejected.items(), key=lambda x: -x[1]))
            why += f": {cands} candidates, every one rejected ({top})"
    return why


def summarise(results: list[TrialResult]) -> list[dict]:
    """Table 3's numbers per planner (module docstring)."""
    rows = []
    for name in dict.fromkeys(r.planner for r in results):
        rs = [r for r in results if r.planner == name]
        atts = [a for r in rs for a in r.attempts]
        succ = sum(a.outcome == "success" for a in atts)
        boxes, picked = sum(r.boxes for r in rs), sum(r.picked for r in rs)
        sim_s = sum(r.sim_s for r in rs)
        s_lo, s_hi = wilson_interval(succ, len(atts))
        p_lo, p_hi = wilson_interval(picked, boxes)
        row = {
            "planner": name,
            "trials": len(rs),
            "boxes": boxes,
            "picked": picked,
            "picked_rate": round(picked / boxes, 6) if boxes else float("nan"),
            "picked_ci_low": round(p_lo, 6),
            "picked_ci_high": round(p_hi, 6),
            "attempts": len(atts),
            "successes": succ,
            "success_rate": round(succ / len(atts), 6) if atts else float("nan"),
            "success_ci_low": round(s_lo, 6),
            "success_ci_high": round(s_hi, 6),
            "cleared_trials": sum(r.end == "bin_empty" for r in rs),
            "sim_s": round(sim_s, 3),
            "pph_motion": round(3600.0 * succ / sim_s, 1) if sim_s > 0 else float("nan"),
            "wrong_target": sum(a.wrong_target for a in atts),
            # DCNN attempts on candidates of the fallback tier (evaluate.dcnn_fallback_ratio)
            "second_tier_attempts": sum(a.second_tier for a in atts),
            "second_tier_successes": sum(a.second_tier and a.outcome == "success" for a in atts),
        }
        devs = [a.path_deviation_m for a in atts if a.path_deviation_m is not None]
        # how far the executed servo strayed from the path the run-time check predicted
        row["path_deviation_mm_median"] = (
            round(1000 * float(np.median(devs)), 2) if devs else float("nan")
        )
        row["path_deviation_mm_max"] = (
            round(1000 * float(np.max(devs)), 2) if devs else float("nan")
        )
        for o in OUTCOMES[1:]:
            row[f"fail_{o}"] = sum(a.outcome == o for a in atts)
        for e in TRIAL_ENDS:
            row[f"end_{e}"] = sum(r.end == e for r in rs)
        row["no_attempt_reason"] = no_attempt_reason(rs)
        rows.append(row)
    return rows


def convergence_rows(results: list[TrialResult]) -> list[dict]:
    """The servo error over time of the logged trials' attempts, one row per control step."""
    rows = []
    for r in results:
        for s in r.trace:
            e = s["error"]
            rows.append(
                {
                    "planner": r.planner,
                    "trial": r.trial,
                    "attempt": s["attempt"],
                    "step": s["step"],
                    "t_s": round(float(s["t"]), 4),
                    "translation_error": round(float(np.linalg.norm(e[:3])), 6),
                    "rotation_error_deg": round(float(np.degrees(np.linalg.norm(e[3:]))), 4),
                }
            )
    return rows


def finite(value):
    """NaN → None (JSON null); other values as they are."""
    return None if isinstance(value, float) and math.isnan(value) else value


def drops_by_mass(trials: list[dict], boxes_cfg) -> list[dict]:
    """How often the chosen pattern dropped a box, per planner, box type (by mass), pattern and
    planned pattern, from trial records (``trials.json``: each attempt's ``target_type``,
    ``pattern``, ``planned_pattern`` and ``outcome``; the box under G_opt at home, the books'
    knowledge).

    A box type's mass is ``boxes_cfg.density`` × its volume (kg). An attempt that held its box
    (success, or a drop) counts in ``held``: drops / held is how often the pattern, once sealed,
    failed to hold. ``planned`` is the planner's pattern ("point" for a single suction point),
    so that a single cup the planner chose and one the execution fell back on from a B
    (``evaluate.single_cup_fallback``) count apart; a record without it (written before the
    field existed) counts as planned as executed. Rows sorted by planner, then mass, then
    pattern (L, R, B), then planned pattern (L, R, B, point)."""
    mass = {str(t.name): float(boxes_cfg.density) * float(np.prod(t.size)) for t in boxes_cfg.types}
    counts: dict[tuple, list[int]] = {}
    for tr in trials:
        for a in tr["attempts"]:
            kind = a.get("target_type") or ""
            if kind not in mass or a["outcome"] not in ("success", "dropped"):
                continue
            planned = a.get("planned_pattern", a["pattern"]) or "point"
            c = counts.setdefault((tr["planner"], kind, a["pattern"], planned), [0, 0])
            c[0] += 1
            c[1] += a["outcome"] == "dropped"
    order = {"L": 0, "R": 1, "B": 2, "point": 3}
    rows = []
    for (planner, kind, pattern, planned), (held, dropped) in sorted(
        counts.items(),
        key=lambda kv: (kv[0][0], mass[kv[0][1]], order.get(kv[0][2], 4), order.get(kv[0][3], 4)),
    ):
        lo, hi = wilson_interval(dropped, held)
        rows.append(
            {
                "planner": planner,
                "box": kind,
                "mass_kg": round(mass[kind], 3),
                "pattern": pattern,
                "planned": planned,
                "held": held,
                "dropped": dropped,
                "drop_rate": round(dropped / held, 6) if held else float("nan"),
                "drop_ci_low": round(lo, 6),
                "drop_ci_high": round(hi, 6),
            }
        )
    return rows
