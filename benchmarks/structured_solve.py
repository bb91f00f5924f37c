"""Benchmark of the structure-exploiting solve (issue 27, first step): the same grasps
solved by IPOPT on the kind-ordered NLP (today's), by IPOPT on the stage-ordered NLP and
by fatrop on the stage-ordered NLP (``ManipulationPlanner(solver="fatrop")``), side by
side in one run (the machine's load affects all alike), one BLAS thread.

For each case and solver: the NLP's construction (the first ``planner.build``: the
transcription and the solver; timed apart), then ``--repeats`` cold solves (the planner's
own guesses, the NLP cached) and, for experiment 1, warm re-plans with the goal moved
2 mm (``ocp.attempt`` from the cold plan's primal-dual point, certified). Reported: the
solver that returned the plan, its status and certificate, iterations, the solver calls'
time (``stats.ipopt_time``, median) and the time per iteration; fatrop's own split of its
time (search direction, Hessian and Jacobian evaluations) for the last cold solve.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/structured_solve.py [--repeats 5]
        [--cases exp1,three] [--out DIR]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
from manipulation import _experiment, _three

from ocp import AttemptOptions, attempt
from ocp.solve.planner import ManipulationPlanner, ManipulationProblem

DEFAULT_OUT = Path(__file__).resolve().parent / "results"

#: name -> (problem, its warm re-plan variant or None)
CASES: dict[str, tuple[Callable[[], ManipulationProblem],
                       Callable[[ManipulationProblem], ManipulationProblem] | None]] = {
    "exp1": (lambda: _experiment("experiment1"),
             lambda b: replace(b, palm=replace(b.palm, goal={  # type: ignore[arg-type]
                 k: v + (0.002 if k == "x" else 0.0)
                 for k, v in b.palm.goal.items()}))),  # type: ignore[union-attr]
    "three": (lambda: _three(30.0, (1.0, 0.0, 1.0), 2.0, 20), None),
}

#: label -> the planner's arguments
SOLVERS: dict[str, dict[str, Any]] = {
    "ipopt_kind": {},
    "ipopt_stage": {"stage_order": True},
    "fatrop_stage": {"solver": "fatrop"},
}


def _row(sols: list[Any]) -> dict[str, Any]:
    s = sols[-1].stats
    times = [x.stats.ipopt_time for x in sols]
    its = [x.stats.iterations for x in sols]
    med = statistics.median(times)
    return {"solver": s.solver, "status": sols[-1].status.value,
            "certified": bool(sols[-1].certificate and sols[-1].certificate.passed),
            "iterations": statistics.median(its), "solve_median_s": med,
            "per_iteration_ms": 1e3 * med / max(1, statistics.median(its))}


def run_case(name: str, repeats: int) -> dict[str, Any]:
    make, variant = CASES[name]
    out: dict[str, Any] = {}
    for label, kw in SOLVERS.items():
        problem = make()
        planner = ManipulationPlanner(**kw)
        t0 = time.perf_counter()
        nlp, _ = planner.build(problem)
        build = time.perf_counter() - t0
        cold = [planner.solve(problem) for _ in range(repeats)]
        row = {"build_s": build, "cold": _row(cold)}
        st = nlp.solver.stats() if hasattr(nlp.solver, "stats") else {}
        if "fatrop" in st:
            row["fatrop_split_s"] = {k: st["fatrop"][k] for k in (
                "compute_sd_time", "eval_hess_time", "eval_jac_time", "time_total")}
        if variant is not None:
            moved = variant(problem)
            warm = [attempt(moved, warm=cold[-1], planner=planner,
                            options=AttemptOptions(certify=True)) for _ in range(repeats)]
            row["warm"] = _row(warm)
        out[label] = row
        print(name, label, json.dumps(row), flush=True)
    return out


def main(argv: list[str] | None = None) -> dict[str, Any]:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--cases", default=",".join(CASES))
    ap.add_argument("--out", type=Path, default=DEFAULT_OUT)
    args = ap.parse_args(argv)
    results = {"threads": os.environ.get("OPENBLAS_NUM_THREADS"),
               "cases": {c: run_case(c, args.repeats) for c in args.cases.split(",")}}
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "structured_solve.json").write_text(json.dumps(results, indent=1))
    return results


if __name__ == "__main__":
    main()
