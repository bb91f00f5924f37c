"""Benchmark of the ball-on-palm planner: NLP construction and solve, timed apart.

For each problem and each number of collocation intervals N this measures

* construction: ``BallOnPalmPlanner().nlp_for(problem)`` on a fresh planner (empty NLP
  cache), median over ``--build-repeats``. The per-shape model (``ocp.ball_on_palm.model_for``)
  is process-wide and built once up front; its time is recorded separately.
* solve: ``planner.solve(problem)`` wall clock on a planner whose cache is warm (one untimed
  warm-up solve first, which also builds the NLPs of any grid refinement), median over
  ``--repeats``; plus the medians of ``stats.solve_time`` (IPOPT incl. initial guesses) and
  ``stats.certificate_time``, and the iterations, attempts, refinements, final N, status and
  the certificate's worst residuals.

Results go to ``--out`` (default ``benchmarks/results`` next to this file) as
``results.json`` (with machine info), ``results.csv`` and ``results.md``; the Markdown table
is also printed. Run from the repository root::

    .venv/bin/python benchmarks/ball_on_palm.py [--repeats 5] [--build-repeats 3]
        [--sizes 20,50,100] [--problems triangle,translate] [--out DIR]
"""

from __future__ import annotations

import argparse
import csv
import datetime as dt
import gc
import json
import math
import os
import platform
import statistics
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np

from ocp.ball_on_palm import (
    BallOnPalmPlanner,
    contact_coordinates,
    model_for,
    object_pose,
)
from ocp.geometry.surfaces import rotation_from_vector
from ocp.solution import Solution
from ocp.solve.ipopt import IPOPT_OPTIONS
from ocp.spec.problem import CONTACT_COORDS, BallOnPalmProblem, ObjectSpec, ViaPoint

OBJECT = ObjectSpec("sphere", (0.025,))
REST: tuple[float, float, float, float, float] = (0.0, 0.0, 0.0, 0.0, 0.0)
DEFAULT_SIZES: tuple[int, ...] = (20, 50, 100)
DEFAULT_OUT = Path(__file__).resolve().parent / "results"


def _all_coords(eta: Sequence[float]) -> dict[str, float]:
    return dict(zip(CONTACT_COORDS, (float(e) for e in eta), strict=True))


def triangle(n: int) -> BallOnPalmProblem:
    """The paper's triangle: two via-points on the palm, back to the start, 6 s."""
    return BallOnPalmProblem(
        object=OBJECT,
        initial=(0.0, 0.0, 0.0, 0.0, -math.pi / 2),
        goal={"x": 0.0, "y": 0.0},
        duration=6.0,
        via_points=(ViaPoint(2.0, {"x": 0.03, "y": 0.0}),
                    ViaPoint(4.0, {"x": 0.03, "y": 0.03})),
        n_intervals=n,
    )


def translate(n: int) -> BallOnPalmProblem:
    """Move the contact on the palm only (object orientation free), 2 s."""
    return BallOnPalmProblem(object=OBJECT, initial=REST, goal={"x": 0.04, "y": 0.02},
                             duration=2.0, n_intervals=n)


def full_goal(n: int) -> BallOnPalmProblem:
    """All five coordinates: palm point (0.03, -0.01) m and a general rotation, 2 s."""
    R0 = object_pose(OBJECT, REST)[0]
    R = rotation_from_vector((0.3, -0.2, 0.4)) @ R0
    goal = contact_coordinates(OBJECT, (0.03, -0.01), R)
    return BallOnPalmProblem(object=OBJECT, initial=REST, goal=_all_coords(goal),
                             duration=2.0, n_intervals=n)


def reorient_vertical_90(n: int) -> BallOnPalmProblem:
    """Pure rotation by 90 deg about the palm normal, back on the same contact points, 2 s."""
    return BallOnPalmProblem(object=OBJECT, initial=REST,
                             goal={"x": 0.0, "y": 0.0, "u": 0.0, "v": 0.0, "psi": math.pi / 2},
                             duration=2.0, n_intervals=n)


def reorient_horizontal_60(n: int) -> BallOnPalmProblem:
    """Rotation by 60 deg about the palm x axis, ending over the same palm point, 2 s."""
    R0 = object_pose(OBJECT, REST)[0]
    goal = contact_coordinates(OBJECT, (0.0, 0.0),
                               rotation_from_vector((math.radians(60.0), 0.0, 0.0)) @ R0)
    return BallOnPalmProblem(object=OBJECT, initial=REST, goal=_all_coords(goal),
                             duration=2.0, n_intervals=n)


PROBLEMS: dict[str, Callable[[int], BallOnPalmProblem]] = {
    "triangle": triangle,
    "translate": translate,
    "full_goal": full_goal,
    "reorient_vertical_90": reorient_vertical_90,
    "reorient_horizontal_60": reorient_horizontal_60,
}


@dataclass
class Row:
    """Measurements of one (problem, N) pair; times in s."""

    problem: str
    n_intervals: int
    build_times: list[float] = field(default_factory=list)
    #: The planner's own build_time of the NLP (measured inside ocp.ball_on_palm._build).
    nlp_build_times: list[float] = field(default_factory=list)
    n_variables: int = 0
    n_constraints: int = 0
    #: Untimed-for-the-median warm-up: solve on a cold cache (builds refinement NLPs too).
    first_solve_wall: float = math.nan
    first_solve_build: float = math.nan
    solve_walls: list[float] = field(default_factory=list)
    ipopt_times: list[float] = field(default_factory=list)
    cert_times: list[float] = field(default_factory=list)
    build_in_solve: list[float] = field(default_factory=list)
    iterations: list[int] = field(default_factory=list)
    attempts: list[int] = field(default_factory=list)
    refinements: list[int] = field(default_factory=list)
    final_n: list[int] = field(default_factory=list)
    statuses: list[str] = field(default_factory=list)
    raw_statuses: list[str] = field(default_factory=list)
    cert_passed: list[bool] = field(default_factory=list)
    max_position_defect: list[float] = field(default_factory=list)
    max_angle_defect: list[float] = field(default_factory=list)
    max_slip_speed: list[float] = field(default_factory=list)
    max_goal_error: list[float] = field(default_factory=list)
    objective: list[float] = field(default_factory=list)
    error: str | None = None

    def record(self, wall: float, sol: Solution) -> None:
        s, c = sol.stats, sol.certificate
        self.solve_walls.append(wall)
        self.ipopt_times.append(s.solve_time)
        self.cert_times.append(s.certificate_time)
        self.build_in_solve.append(s.build_time)
        self.iterations.append(s.iterations)
        self.attempts.append(s.attempts)
        self.refinements.append(s.refinements)
        self.final_n.append(s.n_intervals)
        self.statuses.append(sol.status.value)
        self.raw_statuses.append(s.raw_status)
        self.cert_passed.append(c.passed)
        self.max_position_defect.append(c.max_position_defect)
        self.max_angle_defect.append(c.max_angle_defect)
        self.max_slip_speed.append(c.max_slip_speed)
        self.max_goal_error.append(c.max_goal_error)
        self.objective.append(s.objective)

    def summary(self) -> dict[str, Any]:
        """Medians and worst cases: one flat record for the CSV and the table."""
        return {
            "problem": self.problem,
            "n_intervals": self.n_intervals,
            "n_variables": self.n_variables,
            "n_constraints": self.n_constraints,
            "build_median_s": _median(self.build_times),
            "nlp_build_median_s": _median(self.nlp_build_times),
            "first_solve_wall_s": self.first_solve_wall,
            "first_solve_build_s": self.first_solve_build,
            "solve_wall_median_s": _median(self.solve_walls),
            "solve_wall_min_s": min(self.solve_walls, default=math.nan),
            "solve_wall_max_s": max(self.solve_walls, default=math.nan),
            "ipopt_median_s": _median(self.ipopt_times),
            "certificate_median_s": _median(self.cert_times),
            "other_median_s": _median([w - i - c for w, i, c in
                                       zip(self.solve_walls, self.ipopt_times, self.cert_times,
                                           strict=True)]),
            "build_in_warm_solve_max_s": max(self.build_in_solve, default=math.nan),
            "iterations": _spread(self.iterations),
            "attempts": _spread(self.attempts),
            "refinements": _spread(self.refinements),
            "final_n_intervals": _spread(self.final_n),
            "status": "/".join(sorted(set(self.statuses))) or "-",
            "raw_status": "/".join(sorted(set(self.raw_statuses))) or "-",
            "certificate_passed": all(self.cert_passed) if self.cert_passed else False,
            "max_position_defect_m": max(self.max_position_defect, default=math.nan),
            "max_angle_defect_rad": max(self.max_angle_defect, default=math.nan),
            "max_slip_speed_m_s": max(self.max_slip_speed, default=math.nan),
            "max_goal_error": max(self.max_goal_error, default=math.nan),
            "objective_median": _median(self.objective),
            "error": self.error or "",
        }


def _median(xs: Sequence[float]) -> float:
    return float(statistics.median(xs)) if xs else math.nan


def _spread(xs: Sequence[int]) -> str:
    """'7' when every repeat agrees, else 'min-max'."""
    if not xs:
        return "-"
    lo, hi = min(xs), max(xs)
    return str(lo) if lo == hi else f"{lo}-{hi}"


def _timed_build(problem: BallOnPalmProblem) -> tuple[float, float, int, int]:
    """(wall s, planner's build_time s, n variables, n constraints) of a cold nlp_for."""
    planner = BallOnPalmPlanner()
    gc.collect()
    t0 = time.perf_counter()
    nlp, hit = planner.nlp_for(problem)
    wall = time.perf_counter() - t0
    assert not hit, "a fresh planner must not have a cached NLP"
    return wall, nlp.build_time, int(nlp.solver.nnz_in("x0")), int(nlp.n_g)


def bench_one(name: str, n: int, repeats: int, build_repeats: int) -> Row:
    problem = PROBLEMS[name](n)
    problem.validate()
    row = Row(name, n)
    for _ in range(build_repeats):
        wall, inner, row.n_variables, row.n_constraints = _timed_build(problem)
        row.build_times.append(wall)
        row.nlp_build_times.append(inner)

    planner = BallOnPalmPlanner()
    gc.collect()
    t0 = time.perf_counter()
    first = planner.solve(problem)  # cold: builds this NLP and those of any refinement
    row.first_solve_wall = time.perf_counter() - t0
    row.first_solve_build = first.stats.build_time
    for _ in range(repeats):
        gc.collect()
        t0 = time.perf_counter()
        sol = planner.solve(problem)
        row.record(time.perf_counter() - t0, sol)
    return row


def machine_info() -> dict[str, Any]:
    info: dict[str, Any] = {
        "platform": platform.platform(),
        "machine": platform.machine(),
        "processor": platform.processor(),
        "cpu_count": os.cpu_count(),
        "python": sys.version.split()[0],
        "python_implementation": platform.python_implementation(),
        "casadi": ca.__version__,
        "numpy": np.__version__,
        "ipopt_options": dict(IPOPT_OPTIONS),
        "date_utc": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
    }
    if hasattr(os, "sched_getaffinity"):
        info["cpu_affinity_count"] = len(os.sched_getaffinity(0))
    try:
        cpu = Path("/proc/cpuinfo").read_text().splitlines()
        info["cpu_model"] = next((ln.split(":", 1)[1].strip() for ln in cpu
                                  if ln.startswith("model name")), "")
    except OSError:
        pass
    repo = Path(__file__).resolve().parent.parent
    try:
        head = subprocess.run(["git", "rev-parse", "HEAD"], cwd=repo, capture_output=True,
                              text=True, check=True, timeout=10).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--", "ocp"], cwd=repo,
                               capture_output=True, text=True, check=True,
                               timeout=10).stdout.strip()
        info["git_commit"] = head
        info["git_ocp_dirty"] = bool(dirty)
    except (OSError, subprocess.SubprocessError):
        pass
    return info


# -- output ----------------------------------------------------------------------------------

#: (header, summary key, format): "ms" = seconds shown in ms, "g" = 2 significant digits.
TABLE_COLUMNS: tuple[tuple[str, str, str], ...] = (
    ("problem", "problem", "str"),
    ("N", "n_intervals", "str"),
    ("vars", "n_variables", "str"),
    ("build [ms]", "build_median_s", "ms"),
    ("solve wall [ms]", "solve_wall_median_s", "ms"),
    ("IPOPT+guess [ms]", "ipopt_median_s", "ms"),
    ("cert [ms]", "certificate_median_s", "ms"),
    ("iter", "iterations", "str"),
    ("att", "attempts", "str"),
    ("ref", "refinements", "str"),
    ("N final", "final_n_intervals", "str"),
    ("status", "status", "str"),
    ("angle defect [rad]", "max_angle_defect_rad", "g"),
    ("slip [m/s]", "max_slip_speed_m_s", "g"),
)


def _cell(fmt: str, value: Any) -> str:
    if isinstance(value, float):
        if math.isnan(value):
            return "-"
        if fmt == "ms":
            return f"{value * 1e3:.1f}"
        if fmt == "g":
            return f"{value:.2g}"
    return str(value)


def markdown_table(summaries: Sequence[dict[str, Any]], header: str) -> str:
    lines = [header, "",
             "| " + " | ".join(h for h, _, _ in TABLE_COLUMNS) + " |",
             "|" + "|".join("---" if k in ("problem", "status") else "---:"
                            for _, k, _ in TABLE_COLUMNS) + "|"]
    for s in summaries:
        lines.append("| " + " | ".join(_cell(f, s[k]) for _, k, f in TABLE_COLUMNS) + " |")
    errors = [f"- {s['problem']} N={s['n_intervals']}: {s['error']}"
              for s in summaries if s["error"]]
    if errors:
        lines += ["", "Errors:", *errors]
    return "\n".join(lines) + "\n"


def _json_safe(x: Any) -> Any:
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if isinstance(x, dict):
        return {k: _json_safe(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_json_safe(v) for v in x]
    return x


def write_results(out: Path, rows: Sequence[Row], args: argparse.Namespace,
                  info: dict[str, Any], model_build_s: float) -> str:
    out.mkdir(parents=True, exist_ok=True)
    summaries = [r.summary() for r in rows]
    header = (f"Ball-on-palm benchmark ({info['date_utc']}; {info['cpu_count']} CPU, "
              f"Python {info['python']}, CasADi {info['casadi']}): medians of "
              f"{args.build_repeats} cold builds and {args.repeats} warm solves. "
              f"\"solve wall\" is the whole `planner.solve` call (guesses, IPOPT, every "
              f"refinement, certificate); \"IPOPT+guess\" is `stats.solve_time`; residuals "
              f"are the worst over repeats.")
    table = markdown_table(summaries, header)
    (out / "results.md").write_text(table)
    with (out / "results.csv").open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(summaries[0]) if summaries else [])
        writer.writeheader()
        writer.writerows(summaries)
    payload = {
        "machine": info,
        "settings": {"repeats": args.repeats, "build_repeats": args.build_repeats,
                     "sizes": list(args.sizes), "problems": list(args.problems),
                     "object": {"shape": OBJECT.shape, "dimensions": list(OBJECT.dimensions)}},
        "model_build_s": model_build_s,
        "summary": summaries,
        "raw": [asdict(r) for r in rows],
    }
    (out / "results.json").write_text(json.dumps(_json_safe(payload), indent=2) + "\n")
    return table


# -- command line ----------------------------------------------------------------------------

def _positive_int(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {value}")
    return value


def _sizes(text: str) -> tuple[int, ...]:
    try:
        sizes = tuple(int(s) for s in text.split(",") if s.strip())
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"comma-separated integers expected: {text!r}") from exc
    if not sizes or min(sizes) < 1:
        raise argparse.ArgumentTypeError(f"positive sizes expected: {text!r}")
    return sizes


def _problems(text: str) -> tuple[str, ...]:
    names = tuple(s.strip() for s in text.split(",") if s.strip())
    unknown = [n for n in names if n not in PROBLEMS]
    if not names or unknown:
        raise argparse.ArgumentTypeError(
            f"unknown problem(s) {unknown}; choose from {', '.join(PROBLEMS)}")
    return names


def parse_args(argv: Sequence[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    p.add_argument("--repeats", type=_positive_int, default=5,
                   help="timed warm-cache solves per (problem, N); median reported (default 5)")
    p.add_argument("--build-repeats", type=_positive_int, default=3,
                   help="cold NLP constructions per (problem, N); median reported (default 3)")
    p.add_argument("--sizes", type=_sizes, default=DEFAULT_SIZES,
                   help="comma-separated numbers of intervals N (default 20,50,100)")
    p.add_argument("--problems", type=_problems, default=tuple(PROBLEMS),
                   help=f"comma-separated subset of: {', '.join(PROBLEMS)} (default all)")
    p.add_argument("--out", type=Path, default=DEFAULT_OUT,
                   help="output directory for results.{json,csv,md} "
                        "(default benchmarks/results)")
    return p.parse_args(argv)


def main(argv: Sequence[str] | None = None) -> None:
    args = parse_args(argv)
    info = machine_info()
    t0 = time.perf_counter()
    model_for(OBJECT.surface.name)  # process-wide cache; kept out of the per-NLP build times
    model_build_s = time.perf_counter() - t0

    rows: list[Row] = []
    for name in args.problems:
        for n in args.sizes:
            print(f"[bench] {name} N={n} ...", end="", file=sys.stderr, flush=True)
            t_row = time.perf_counter()
            try:
                row = bench_one(name, n, args.repeats, args.build_repeats)
            except Exception as exc:  # keep going: report the failure in the table
                row = Row(name, n, error=f"{type(exc).__name__}: {exc}")
            rows.append(row)
            s = row.summary()
            print(f" {s['status']}, solve {_cell('ms', s['solve_wall_median_s'])} ms "
                  f"({time.perf_counter() - t_row:.1f} s)", file=sys.stderr, flush=True)

    table = write_results(args.out, rows, args, info, model_build_s)
    print(table)
    print(f"results written to {args.out}", file=sys.stderr)


if __name__ == "__main__":
    main()
