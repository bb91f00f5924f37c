"""The benchmark report links the views of each family's best and worst plan
(planner_service/bench/views.py)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from planner_service.bench.command import run_bench
from planner_service.bench.views import pick


def row(family: str, pid: str, method: str, ok: bool, t: float | None,
        status: str | None = None) -> dict[str, Any]:
    return {"family": family, "problem_id": pid, "method": method, "ok": ok,
            "solve_time": t, "status": status or ("solved" if ok else "inaccurate")}


def test_pick_the_fastest_success_and_the_first_failure() -> None:
    rows = [row("a", "a-0", "collocation", True, 0.3), row("a", "a-1", "collocation", True, 0.1),
            row("a", "a-2", "collocation", False, 0.05), row("a", "a-3", "greedy", False, 0.2),
            row("a", "a-0", "casadi_plain", True, 0.01),  # a peer: no plan to draw
            row("b", "b-0", "collocation", True, 0.2), row("b", "b-1", "collocation", True, 0.4),
            row("c", "c-0", "collocation", True, 0.2),
            row("d", "d-0", "collocation", False, None, status="invalid_input")]
    chosen = pick(rows)
    assert chosen["a"]["best"]["problem_id"] == "a-1"
    assert chosen["a"]["worst"]["problem_id"] == "a-2"
    # every run succeeded: the worst is the slowest
    assert (chosen["b"]["best"]["problem_id"], chosen["b"]["worst"]["problem_id"]) == \
        ("b-0", "b-1")
    assert set(chosen["c"]) == {"best"}  # one run: one view
    assert "d" not in chosen  # no plan


def test_the_report_links_the_views(tmp_path: Path) -> None:
    code, doc = run_bench("quick", workers=1, out=tmp_path, families=["translation"],
                          methods=["collocation"], limit=2, progress=False, views=True)
    assert code == 0
    views = doc["views"]
    assert [v["which"] for v in views] == ["best", "worst"]
    report = (tmp_path / "report.md").read_text()
    assert "## Views of the plans" in report
    for v in views:
        assert v["error"] is None and v["family"] == "translation"
        page = (tmp_path / v["path"]).read_text()
        assert page.startswith("<!DOCTYPE html>") and f"({v['path']})" in report
        assert f"translation {v['which']}: {v['problem_id']}" in page
    stored = json.loads((tmp_path / "results.json").read_text())
    assert stored["views"] == views
