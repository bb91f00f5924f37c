"""Benchmark of warm starts: replanning a slightly different problem from the last plan.

For each case a base problem is planned once; then each variant (the goal moved, the motion
longer, the turn larger) is planned cold (the planner's own initial guess; the NLP already
built) and warm-started from the base plan (``solve(problem, warm_start=base)``, what a
request's ``warm_start`` does in the service). Reported per variant: status and
certificate of both, IPOPT iterations, IPOPT time (median of ``--repeats``) and the whole
``solve`` wall time (median). Results go to ``--out`` (default ``benchmarks/results``) as
``warm_start.json`` and ``warm_start.md``.

    .venv/bin/python benchmarks/warm_start.py [--repeats 3] [--out DIR]
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import math
import os
import platform
import statistics
import sys
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import casadi as ca

sys.path.insert(0, str(Path(__file__).resolve().parent))
from manipulation import _experiment, _three

from ocp.ball_on_palm import BallOnPalmPlanner
from ocp.solve.planner import ManipulationPlanner, ManipulationProblem
from ocp.spec.problem import BallOnPalmProblem, ObjectSpec

DEFAULT_OUT = Path(__file__).resolve().parent / "results"
RHO = 0.025


def _triangle(dx: float = 0.0, duration: float = 6.0) -> BallOnPalmProblem:
    """The paper's triangle (experiment 1's palm plan), N = 50; ``dx`` moves the via-points
    and the goal along x [m]."""
    from ocp.spec.problem import ViaPoint

    return BallOnPalmProblem(
        object=ObjectSpec("sphere", (RHO,)), initial=(0.0, 0.0, 0.0, 0.0, -math.pi / 2),
        goal={"x": dx, "y": 0.0}, duration=duration,
        via_points=(ViaPoint(duration / 3, {"x": 0.03 + dx, "y": 0.0}),
                    ViaPoint(2 * duration / 3, {"x": 0.03 + dx, "y": 0.03})),
        n_intervals=50)


def _exp1_goal(base: ManipulationProblem, dx: float) -> ManipulationProblem:
    assert base.palm is not None
    goal = {k: v + (dx if k == "x" else 0.0) for k, v in base.palm.goal.items()}
    return replace(base, palm=replace(base.palm, goal=goal))


def _exp1_longer(base: ManipulationProblem, factor: float) -> ManipulationProblem:
    assert base.palm is not None
    vias = tuple(replace(vp, time=vp.time * factor) for vp in base.palm.via_points)
    return replace(base, duration=base.duration * factor,
                   palm=replace(base.palm, via_points=vias))


def _three_angle(base: ManipulationProblem, angle_deg: float) -> ManipulationProblem:
    """The same grasp (the same finger objects: the NLP is shared) turning further."""
    other = _three(angle_deg, (1.0, 0.0, 1.0), base.duration, base.n_intervals)
    return replace(base, motion=other.motion)


#: (name, base problem, variants: (label, base -> variant)); a variant keeps the base's
#: finger objects, so that it shares the base's NLP as requests of a service do
Case = tuple[str, Callable[[], Any], list[tuple[str, Callable[[Any], Any]]]]
CASES: list[Case] = [
    ("ball_on_palm_triangle_N50", _triangle,
     [("goal and via-points +2 mm in x", lambda b: _triangle(0.002)),
      ("10 % longer", lambda b: _triangle(0.0, 6.6))]),
    ("exp1_one_finger_N60", lambda: _experiment("experiment1"),
     [("palm goal +2 mm in x", lambda b: _exp1_goal(b, 0.002)),
      ("10 % longer", lambda b: _exp1_longer(b, 1.1))]),
    ("three_fingers_30deg_N20", lambda: _three(30.0, (1.0, 0.0, 1.0), 2.0, 20),
     [("33 deg instead of 30", lambda b: _three_angle(b, 33.0))]),
]


def _outcome(sol: Any) -> tuple[str, bool, int, float]:
    """(status, certificate passed, iterations, IPOPT+guess time) of either planner's
    solution."""
    if hasattr(sol, "stats"):  # ball on palm
        return (sol.status.value, sol.certificate.passed, sol.stats.iterations,
                sol.stats.solve_time)
    return (sol.status.value, not sol.certificate_failures, sol.iterations, sol.solve_time)


def run_case(case: Case, repeats: int) -> list[dict[str, Any]]:
    name, base_of, variants = case
    base_problem = base_of()
    planner: Any = BallOnPalmPlanner() if isinstance(base_problem, BallOnPalmProblem) \
        else ManipulationPlanner()
    base = planner.solve(base_problem)
    rows = []
    for label, make in variants:
        problem = make(base_problem)
        planner.solve(problem)  # every NLP of the variant built (refinements included)
        row: dict[str, Any] = {"case": name, "variant": label}
        for mode in ("cold", "warm"):
            walls, solves, sol = [], [], None
            for _ in range(repeats):
                t0 = time.perf_counter()
                sol = planner.solve(problem, base) if mode == "warm" else \
                    planner.solve(problem)
                walls.append(time.perf_counter() - t0)
                solves.append(_outcome(sol)[3])
            status, passed, iters, _ = _outcome(sol)
            row.update({f"{mode}_status": status, f"{mode}_certified": passed,
                        f"{mode}_iterations": iters,
                        f"{mode}_solve_s": statistics.median(solves),
                        f"{mode}_wall_s": statistics.median(walls)})
        print(f"[bench] {name} / {label}: iterations {row['cold_iterations']} cold, "
              f"{row['warm_iterations']} warm", file=sys.stderr)
        rows.append(row)
    return rows


def markdown(rows: list[dict[str, Any]], meta: dict[str, Any]) -> str:
    head = (f"Warm-start benchmark ({meta['date']}; {meta['cpus']} CPU, Python "
            f"{meta['python']}, CasADi {meta['casadi']}): each variant planned cold (the "
            "planner's own guess) and warm-started from the base case's plan, the NLP "
            f"already built; times are medians of {meta['repeats']} solves: solve = guess + "
            "IPOPT (+ refinements), wall = the whole `solve` call (certificate included).\n\n")
    lines = ["| case | variant | cold: status, iter, solve [s], wall [s] | warm: status, "
             "iter, solve [s], wall [s] |", "|---|---|---|---|"]
    for r in rows:
        cells = []
        for mode in ("cold", "warm"):
            cert = "certified" if r[f"{mode}_certified"] else "NOT certified"
            cells.append(f"{r[f'{mode}_status']} ({cert}), {r[f'{mode}_iterations']}, "
                         f"{r[f'{mode}_solve_s']:.3f}, {r[f'{mode}_wall_s']:.3f}")
        lines.append(f"| {r['case']} | {r['variant']} | {cells[0]} | {cells[1]} |")
    return head + "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> list[dict[str, Any]]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else "")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    args = parser.parse_args(argv)
    rows = [row for case in CASES for row in run_case(case, args.repeats)]
    meta = {"date": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
            "cpus": os.cpu_count(), "python": platform.python_version(),
            "casadi": ca.__version__, "repeats": args.repeats}
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "warm_start.json").write_text(json.dumps({"meta": meta, "rows": rows},
                                                         indent=2) + "\n")
    md = markdown(rows, meta)
    (args.out / "warm_start.md").write_text(md)
    print(md)
    return rows


if __name__ == "__main__":
    main()
