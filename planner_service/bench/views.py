"""The plans a benchmark report shows: per family, the view (docs/viewer.md) of its best and
its worst run, written next to the report as standalone pages (``views/``).

Of a family's runs by the project's planners (not the peers, which return no plan a view
could draw), the **best** is the fastest run that succeeded (solved, certificate passed);
the **worst** is the first run that did not succeed, or when every run did, the slowest.
A family with one such run has one view. The rows hold no plans, so each chosen run is
planned again in this process with the library: the planners are deterministic, the plan
is the run's (its solve time is not, and the report gives the run's).
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from .suite import PEER_METHODS

__all__ = ["VIEWS_DIR", "pick", "write_views"]

Row = dict[str, Any]

#: The folder of the views, in the report's folder.
VIEWS_DIR = "views"
#: Statuses of runs without a plan to draw.
_NO_PLAN = frozenset({"invalid_input", "error", "unavailable", "worker_died", "cancelled",
                      "killed_at_time_limit"})


def _time(row: Row) -> float:
    t = row.get("solve_time")
    return float(t) if t is not None and math.isfinite(t) else math.inf


def pick(rows: Sequence[Row]) -> dict[str, dict[str, Row]]:
    """Per family (in the rows' order): ``{"best": row, "worst": row}`` (see the module;
    one of them when the family has one run with a plan)."""
    families: dict[str, list[Row]] = {}
    for r in rows:
        if r["method"] not in PEER_METHODS and r["status"] not in _NO_PLAN:
            families.setdefault(r["family"], []).append(r)
    out: dict[str, dict[str, Row]] = {}
    for family, runs in families.items():
        ok = [r for r in runs if r["ok"]]
        failed = [r for r in runs if not r["ok"]]
        chosen: dict[str, Row] = {}
        if ok:
            chosen["best"] = min(ok, key=lambda r: (_time(r), r["problem_id"], r["method"]))
        if failed:
            chosen["worst"] = min(failed, key=lambda r: (r["problem_id"], r["method"]))
        elif len(ok) > 1:
            chosen["worst"] = max(ok, key=lambda r: (_time(r), r["problem_id"], r["method"]))
        out[family] = chosen
    return out


def _file_name(family: str, which: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", f"{family}-{which}") + ".html"


def write_views(out: Path, rows: Sequence[Row], problems: Sequence[dict[str, Any]]
                ) -> list[dict[str, Any]]:
    """Plan each chosen run again and write its view into ``out/views/``; one entry per
    view (family, which, problem_id, method, status, solve_time, path relative to ``out``,
    or ``error`` saying why there is no page)."""
    from ..planners import REQUEST, solve
    from ..view import view_html

    requests = {(p["family"], p["id"]): p["request"] for p in problems}
    entries: list[dict[str, Any]] = []
    for family, chosen in pick(rows).items():
        for which in ("best", "worst"):
            row = chosen.get(which)
            if row is None:
                continue
            entry: dict[str, Any] = {
                "family": family, "which": which, "problem_id": row["problem_id"],
                "method": row["method"], "status": row["status"], "ok": row["ok"],
                "solve_time": row.get("solve_time"), "path": None, "error": None}
            entries.append(entry)
            raw = requests.get((family, row["problem_id"]))
            if raw is None:
                entry["error"] = "its request is not in the report"
                continue
            if row["method"] == "greedy":
                raw = dict(raw, method="greedy")
            try:
                request = REQUEST.validate_python(raw)
                result, _ = solve(request)
                title = f"{family} {which}: {row['problem_id']} ({row['method']})"
                page = view_html(result, request, title)
            except Exception as exc:  # a missing view is a note, never a failed report
                entry["error"] = f"{type(exc).__name__}: {exc}"
                continue
            path = out / VIEWS_DIR / _file_name(family, which)
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(page, encoding="utf-8")
            entry["path"] = f"{VIEWS_DIR}/{path.name}"
    return entries
