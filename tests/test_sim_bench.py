"""The bench's "executed" column (docs/simulation.md, docs/benchmarks.md): every solved
plan with fingers is run in MuJoCo by the row that reports it, whichever runner made it,
and the report says per family how many executions passed and their worst errors."""

from __future__ import annotations

from typing import Any

import pytest

from planner_service.bench.report import _table, summarise
from planner_service.bench.rows import FIELDS, VOLATILE, run_unit
from planner_service.bench.suite import expand, load_suite, units


@pytest.fixture(scope="module")
def rows() -> list[dict[str, Any]]:
    """One problem of each family with fingers in the quick suite, by collocation, and
    one ball-on-palm problem (nothing to execute)."""
    problems = expand(load_suite("quick"), families=["translation", "one_finger",
                                                     "two_fingers"], limit=1)
    return [run_unit(u) for u in units(problems) if u.method == "collocation"]


def test_solved_finger_plans_are_executed_and_pass(rows: list[dict[str, Any]]) -> None:
    by_family = {r["family"]: r for r in rows}
    assert set(by_family) == {"translation", "one_finger", "two_fingers"}
    for row in rows:
        assert set(row) == set(FIELDS)
        assert row["ok"], row["message"]
    assert by_family["translation"]["exec_status"] is None  # a ball on the palm alone
    for family in ("one_finger", "two_fingers"):
        row = by_family[family]
        assert row["exec_status"] == "passed", row["exec_message"]
        assert 0 <= row["exec_position_error_max"] <= 1e-3
        assert 0 <= row["exec_angle_error_max"] <= 0.035
        assert row["exec_contacts_lost"] == 0 and row["exec_wall_time"] > 0
    assert "exec_status" not in VOLATILE and "exec_position_error_max" in VOLATILE


def test_the_report_has_an_executed_column(rows: list[dict[str, Any]]) -> None:
    summary = summarise(rows, ["translation", "one_finger", "two_fingers"])
    by = {s["family"]: s for s in summary}
    assert by["translation"]["executed"] == 0
    assert by["one_finger"]["executed"] == by["one_finger"]["executed_passed"] == 1
    assert by["two_fingers"]["exec_position_error_max"] <= 1e-3
    table = _table(summary)
    assert "executed (worst mm, deg)" in table[0]
    line = next(t for t in table if t.startswith("| one_finger"))
    assert "| 1/1 (" in line and line.endswith("°) |")
    assert next(t for t in table if t.startswith("| translation")).endswith("| – |")


def test_execution_can_be_turned_off(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("DEXROLL_BENCH_EXECUTE", "0")
    problems = expand(load_suite("quick"), families=["one_finger"], limit=1)
    row = run_unit(next(u for u in units(problems) if u.method == "greedy"))
    assert row["ok"] and row["exec_status"] is None
