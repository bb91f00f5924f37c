"""Benchmark of the manipulation planner (fingers, with or without a palm).

Cases: the paper's experiment 1 (palm + one finger, 60 intervals as in its script, and
50: the planners' default grid), experiment 2 (two
fingers, 40 intervals), and the three-finger hand turning the ball 30 deg about a tilted
axis (20 intervals) and 90 deg about z (30 intervals). For each case:

* construction: the first solve on a fresh planner reports the NLP build time;
* solve: ``planner.solve`` wall clock with the NLP cached (median over ``--repeats``), and
  IPOPT's own time (``solution.ipopt_time``), iterations, status and certificate.

``--mumps-pivot-order`` sets IPOPT's ``mumps_pivot_order`` for the run (the project uses
5 = METIS; 7 = MUMPS's automatic choice) to measure the difference. Results go to ``--out``
(default ``benchmarks/results``) as ``manipulation.json`` and ``manipulation.md``.

    .venv/bin/python benchmarks/manipulation.py [--repeats 3] [--cases exp2,three_90]
        [--mumps-pivot-order 7] [--out DIR]
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
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import casadi as ca

import ocp.transcription.nlp_blocks as nlp_blocks
from ocp.one_finger import OneFingerPlanner
from ocp.robots.hands import load_hand
from ocp.solve.planner import (
    DesiredMotion,
    ManipulationPlanner,
    ManipulationProblem,
    MotionStep,
    ObjectPose,
    Tracking,
    hand_fingertips,
)
from ocp.spec.problem import ObjectSpec, SolverOptions

DEFAULT_OUT = Path(__file__).resolve().parent / "results"
ROOT = Path(__file__).resolve().parents[1]
TOL = Tracking(position_tolerance=1e-3, orientation_tolerance=math.radians(1.0))


def _experiment(name: str) -> ManipulationProblem:
    import importlib.util

    spec = importlib.util.spec_from_file_location(name, ROOT / "experiments" / f"{name}.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    problem = module.build_problem()
    if isinstance(problem, ManipulationProblem):
        return problem
    return OneFingerPlanner.manipulation_problem(problem)


def _three(angle_deg: float, axis: tuple[float, float, float], duration: float,
           n: int) -> ManipulationProblem:
    hand = load_hand("three_finger")
    ball = ObjectSpec("sphere", (hand.nominal_radius,))
    start = ObjectPose(position=hand.nominal_object_position)
    motion = DesiredMotion.from_steps(start, [MotionStep(duration, axis,
                                                         math.radians(angle_deg))])
    return ManipulationProblem(ball, hand_fingertips(hand, start, ball), duration,
                               initial_pose=start, motion=motion, tracking=TOL,
                               n_intervals=n, options=SolverOptions(time_limit=300.0))


CASES: dict[str, Callable[[], ManipulationProblem]] = {
    "exp1_one_finger": lambda: _experiment("experiment1"),
    # the same at the planners' default grid (a request's default n_intervals)
    "exp1_one_finger_N50": lambda: replace(_experiment("experiment1"), n_intervals=50),
    "exp2_two_fingers": lambda: _experiment("experiment2"),
    "three_30_tilted": lambda: _three(30.0, (1.0, 0.0, 1.0), 2.0, 20),
    "three_90_z": lambda: _three(90.0, (0.0, 0.0, 1.0), 3.0, 30),
}


def run_case(name: str, repeats: int, compile_dir: Path | None = None) -> dict[str, Any]:
    problem = CASES[name]()
    planner = ManipulationPlanner(compile_dir=compile_dir)
    t0 = time.perf_counter()
    first = planner.solve(problem)
    first_wall = time.perf_counter() - t0
    walls, ipopt = [], []
    sol = first
    for _ in range(repeats):
        t0 = time.perf_counter()
        sol = planner.solve(problem)
        walls.append(time.perf_counter() - t0)
        ipopt.append(sol.ipopt_time)
    row: dict[str, Any] = {
        "case": name,
        "contacts": len(sol.contacts),
        "n_intervals": problem.n_intervals,
        "build_s": first.build_time,
        "first_wall_s": first_wall,
        "solve_wall_median_s": statistics.median(walls),
        "ipopt_median_s": statistics.median(ipopt),
        "iterations": sol.iterations,
        "refinements": sol.refinements,
        "status": sol.status.value,
        "certificate_passed": not sol.certificate_failures,
        "max_slip": max((v for k, v in sol.certificate.items()
                         if k.startswith("max_slip_speed")), default=float("nan")),
        "min_cone_margin_rad": sol.certificate.get("min_cone_margin", float("nan")),
    }
    print(f"[bench] {name}: {row['status']}, IPOPT {row['ipopt_median_s'] * 1e3:.0f} ms, "
          f"{row['iterations']} iterations", file=sys.stderr)
    return row


def markdown(rows: list[dict[str, Any]], meta: dict[str, Any]) -> str:
    head = (f"Manipulation benchmark ({meta['date']}; {meta['cpus']} CPU, Python "
            f"{meta['python']}, CasADi {meta['casadi']}, mumps_pivot_order "
            f"{meta['mumps_pivot_order']}): build = first solve's NLP construction; "
            f"solve = median of {meta['repeats']} cached `planner.solve` calls (guess, IPOPT, "
            "certificate); IPOPT = median `solution.ipopt_time`.\n\n")
    lines = ["| case | contacts | N | build [s] | solve wall [s] | IPOPT [s] | iter | status "
             "| certificate | max slip [m/s] | min cone margin [deg] |",
             "|---|---:|---:|---:|---:|---:|---:|---|---|---:|---:|"]
    for r in rows:
        lines.append(
            f"| {r['case']} | {r['contacts']} | {r['n_intervals']} | {r['build_s']:.2f} | "
            f"{r['solve_wall_median_s']:.2f} | {r['ipopt_median_s']:.2f} | {r['iterations']} "
            f"| {r['status']} | {'passed' if r['certificate_passed'] else 'failed'} | "
            f"{r['max_slip']:.1e} | {math.degrees(r['min_cone_margin_rad']):.1f} |")
    return head + "\n".join(lines) + "\n"


def _option_value(text: str) -> Any:
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def main(argv: Sequence[str] | None = None) -> list[dict[str, Any]]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else "")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--cases", default=",".join(CASES))
    parser.add_argument("--mumps-pivot-order", type=int, default=None)
    parser.add_argument("--ipopt", action="append", default=[], metavar="KEY=VALUE",
                        help="override an IPOPT option for the run, e.g. "
                             "mu_strategy=adaptive (repeatable)")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    parser.add_argument("--compile-dir", type=Path, default=None,
                        help="compile the NLPs (C, gcc) and cache them here; the build column "
                             "then includes the compile unless the cache has them")
    args = parser.parse_args(argv)
    overrides: dict[str, Any] = {}
    if args.mumps_pivot_order is not None:
        overrides["ipopt.mumps_pivot_order"] = args.mumps_pivot_order
    for item in args.ipopt:
        key, _, value = item.partition("=")
        overrides[f"ipopt.{key.removeprefix('ipopt.')}"] = _option_value(value)
    nlp_blocks.IPOPT_OPTIONS = {**nlp_blocks.IPOPT_OPTIONS, **overrides}
    cases = [c for c in args.cases.split(",") if c]
    unknown = sorted(set(cases) - set(CASES))
    if unknown:
        parser.error(f"unknown cases {unknown}; known: {sorted(CASES)}")
    rows = [run_case(c, args.repeats, args.compile_dir) for c in cases]
    meta = {"date": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
            "cpus": os.cpu_count(), "python": platform.python_version(),
            "casadi": ca.__version__, "repeats": args.repeats,
            "mumps_pivot_order": nlp_blocks.IPOPT_OPTIONS["ipopt.mumps_pivot_order"],
            "ipopt_overrides": overrides, "compiled": args.compile_dir is not None}
    args.out.mkdir(parents=True, exist_ok=True)
    suffix = "" if args.mumps_pivot_order is None else f"_pivot{args.mumps_pivot_order}"
    suffix += "".join(f"_{k.removeprefix('ipopt.')}-{v}" for k, v in overrides.items()
                      if k != "ipopt.mumps_pivot_order")
    suffix += "_compiled" if args.compile_dir is not None else ""
    (args.out / f"manipulation{suffix}.json").write_text(
        json.dumps({"meta": meta, "rows": rows}, indent=2) + "\n", encoding="utf-8")
    text = markdown(rows, meta)
    (args.out / f"manipulation{suffix}.md").write_text(text, encoding="utf-8")
    print(text)
    return rows


if __name__ == "__main__":
    main()
