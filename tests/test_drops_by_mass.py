"""How often a pattern dropped its box, by box mass and by where the pattern came from
(``pipeline.world.books.drops_by_mass``), on trial records worked out by hand."""

from types import SimpleNamespace

import pytest

from pipeline.world.books import drops_by_mass

BOXES = SimpleNamespace(
    density=400.0,
    types=[
        SimpleNamespace(name="large", size=(0.5, 0.4, 0.3)),  # 0.06 m³: 24 kg
        SimpleNamespace(name="small", size=(0.2, 0.1, 0.1)),  # 0.002 m³: 0.8 kg
    ],
)


def _att(kind, pattern, planned, outcome):
    return {"target_type": kind, "pattern": pattern, "planned_pattern": planned, "outcome": outcome}


def test_single_cups_the_planner_chose_and_fallbacks_from_b_count_apart():
    trials = [
        {
            "planner": "dcnn",
            "attempts": [
                _att("large", "L", "L", "dropped"),
                _att("large", "L", "B", "dropped"),  # the execution fell back from a B
                _att("large", "L", "B", "success"),
                _att("large", "B", "B", "success"),
                _att("small", "R", "R", "success"),
                _att("large", "L", "L", "no_seal"),  # never held: not counted
                _att("", "L", "L", "dropped"),  # no box under G_opt: not counted
            ],
        },
        {"planner": "dexnet", "attempts": [_att("small", "L", "", "dropped")]},
    ]
    rows = drops_by_mass(trials, BOXES)
    keys = ("planner", "box", "pattern", "planned", "held", "dropped")
    got = [tuple(r[k] for k in keys) for r in rows]
    assert got == [
        ("dcnn", "small", "R", "R", 1, 0),  # 0.8 kg before 24 kg
        ("dcnn", "large", "L", "L", 1, 1),
        ("dcnn", "large", "L", "B", 2, 1),
        ("dcnn", "large", "B", "B", 1, 0),
        ("dexnet", "small", "L", "point", 1, 1),  # a single suction point
    ]
    assert [r["mass_kg"] for r in rows] == [0.8, 24.0, 24.0, 24.0, 0.8]
    half = rows[2]
    assert half["drop_rate"] == 0.5
    # Wilson 95 % interval of 1 in 2 (z = 1.96): (p + z²/2n ∓ z√(p(1−p)/n + z²/4n²)) / (1 + z²/n)
    assert half["drop_ci_low"] == pytest.approx(0.094531, abs=1e-6)
    assert half["drop_ci_high"] == pytest.approx(0.905469, abs=1e-6)


def test_a_record_without_the_planned_pattern_counts_as_planned_as_executed():
    old = {"target_type": "large", "pattern": "B", "outcome": "success"}
    (row,) = drops_by_mass([{"planner": "oracle", "attempts": [old]}], BOXES)
    assert (row["pattern"], row["planned"], row["held"], row["dropped"]) == ("B", "B", 1, 0)
