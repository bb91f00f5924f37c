"""Benchmark of warm starts: replanning a slightly different problem from the last plan.

For each case a base problem is planned once; then each variant (the goal moved, the motion
longer, the turn larger) is planned cold (the planner's own initial guess; the NLP already
built) and warm-started from the base plan (``solve(problem, warm_start=base)``, what a
request's ``warm_start`` does in the service). Reported per variant: status and
certificate of both, IPOPT iterations, IPOPT time (median of ``--repeats``) and the whole
``solve`` wall time (median). Results go to ``--out`` (default ``benchmarks/results``) as
``warm_start.json`` and ``warm_start.md``.

    .venv/bin/python benchmarks/warm_start.py [--repeats 3] [--out DIR]

``--replan`` (issue 27) measures a controller's re-plan instead: experiment 1, three
fingers (``examples/three_finger_turn.json``) and four fingers (``examples/allegro_turn.json``)
planned once (cold, certified), then the rest of the motion 50 ms later, from the plan's
state there with the object moved 1 mm in x (made a state of the grasp by
``ocp.estimate_state``), toward a goal moved 2 mm in x (experiment 1: the palm goal; the
hands: the desired motion's end, moved in proportion along it), by ``ocp.attempt``: cold
(the planner's own guess), warm (the shifted plan, its primal-dual point), warm from its
primal point alone, warm with other IPOPT warm-start settings, and warm with a fixed
iteration budget (``AttemptOptions(max_iter=k)``); each certified, the certificate timed
apart; the NLP's construction and the warm solver's timed apart. Writes ``replan.json`` and
``replan.md``; one BLAS thread.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/warm_start.py --replan \
        [--repeats 5] [--cases exp1,three,four] [--compile DIR]
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


#: IPOPT warm-start settings tried for the re-plan, beside the library's
#: (``IPOPT_WARM_OPTIONS``): label -> options replacing the library's
WARM_VARIANTS: dict[str, dict[str, Any]] = {
    "mu_init 1e-4": {"ipopt.mu_init": 1e-4},
    "mu_init 1e-8": {"ipopt.mu_init": 1e-8},
    "pushes 1e-6": {f"ipopt.warm_start_{k}": 1e-6 for k in (
        "bound_push", "bound_frac", "slack_bound_push", "slack_bound_frac",
        "mult_bound_push")},
    "adaptive barrier": {"ipopt.mu_strategy": "adaptive"},
    "AMD ordering": {"ipopt.mumps_pivot_order": 0},
    "QAMD ordering": {"ipopt.mumps_pivot_order": 6},
}

#: the fixed iteration budgets measured
BUDGETS = (1, 2, 3)

REPLAN_DT = 0.05
GOAL_SHIFT = 0.002
START_SHIFT = 0.001


def _request_problem(name: str) -> ManipulationProblem:
    from planner_service.planners import REQUEST, to_problem

    root = Path(__file__).resolve().parents[1]
    request = REQUEST.validate_python(json.loads((root / "examples" / name).read_text()))
    problem: ManipulationProblem = to_problem(request)
    return problem


REPLAN_CASES: dict[str, Callable[[], ManipulationProblem]] = {
    "exp1": lambda: _experiment("experiment1"),
    "three": lambda: _request_problem("three_finger_turn.json"),
    "four": lambda: _request_problem("allegro_turn.json"),
}


def _goal_moved(problem: ManipulationProblem, dx: float) -> ManipulationProblem:
    """The goal moved ``dx`` in x: the palm goal, or the desired motion's knots in
    proportion to their time (the start where it was, the end ``dx`` further)."""
    if problem.palm is not None and "x" in problem.palm.goal:
        return _exp1_goal(problem, dx)
    mo = problem.motion
    assert mo is not None
    end = mo.times[-1]
    pos = tuple((p[0] + dx * t / end, p[1], p[2]) for t, p in zip(mo.times, mo.positions,
                                                                   strict=True))
    return replace(problem, motion=replace(mo, positions=pos))


def _moved_start(planner: ManipulationPlanner, problem: ManipulationProblem, plan: Any,
                 t: float, dx: float) -> tuple[Any, Any, Any]:
    """The plan's state at ``t`` with the object moved ``dx`` in x, made a state of the
    grasp by the estimate (the joints as planned); (x, u, the estimate)."""
    from ocp import Measurement, estimate_state
    from ocp.geometry.rotations import quaternion_wxyz

    m = planner.model(problem)
    smp = plan.sample([t])
    x, u = smp.x[0], smp.u[0]
    meas = Measurement([x[tip.q_cols] for tip in m.fingertips],
                       smp.object_position[0] + [dx, 0.0, 0.0],
                       quaternion_wxyz(smp.object_rotation[0]),
                       [u[tip.qd_cols] for tip in m.fingertips])
    est = estimate_state(problem, m, meas, x, u)
    if not est.explained:
        raise RuntimeError(f"the moved start is not a state of the grasp: {est.problems}")
    return est.x, est.u, est


def _attempt_row(label: str, runs: list[Any], walls: list[float], cpus: list[float]
                 ) -> dict[str, Any]:
    """A re-plan's figures over its repeats: medians of the IPOPT call, of the attempt
    without its certificate and of the process's CPU time over the attempt (certificate
    included: on a loaded machine the least distorted figure); the last run's outcome."""
    last = runs[-1]
    st = last.stats
    return {"variant": label, "status": last.status.value, "raw": st.raw_status,
            "certified": bool(last.certificate.passed), "iterations": st.iterations,
            "ipopt_s": statistics.median(r.stats.ipopt_time for r in runs),
            "attempt_s": statistics.median(w - r.stats.certificate_time
                                           for r, w in zip(runs, walls, strict=True)),
            "certificate_s": statistics.median(r.stats.certificate_time for r in runs),
            "cpu_s": statistics.median(cpus),
            "primal_inf": st.primal_infeasibility, "dual_inf": st.dual_infeasibility,
            "objective": st.objective}


def replan_case(name: str, repeats: int, compile_dir: Path | None) -> dict[str, Any]:
    from ocp import AttemptOptions, attempt, shifted
    from ocp.solve.ipopt import IPOPT_WARM_OPTIONS

    problem = REPLAN_CASES[name]()
    planner = ManipulationPlanner(compile_dir=compile_dir)
    t0 = time.perf_counter()
    planner.build(problem)
    build = time.perf_counter() - t0
    firsts, walls, cpus = [], [], []
    for _ in range(repeats):
        c0 = time.process_time()
        t0 = time.perf_counter()
        firsts.append(planner.solve(problem))
        walls.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
    base = firsts[-1]
    n = base.stats.n_intervals
    first = {"status": base.status.value, "certified": bool(base.certificate.passed),
             "iterations": base.stats.iterations, "n_intervals": n,
             "refinements": base.stats.refinements,
             "ipopt_s": statistics.median(f.stats.ipopt_time for f in firsts),
             "solve_s": statistics.median(f.stats.solve_time for f in firsts),
             "wall_s": statistics.median(walls), "cpu_s": statistics.median(cpus),
             "certificate_s": statistics.median(f.stats.certificate_time for f in firsts)}
    print(f"[replan] {name}: first plan {json.dumps(first)}", file=sys.stderr, flush=True)
    grid = problem.with_intervals(n)
    rest = _goal_moved(grid, GOAL_SHIFT).remaining(REPLAN_DT)
    if rest.motion is not None:  # as ocp.Replanner from a start 1 mm off the desired path:
        # the hard tracking tolerances (1 mm) dropped, the weighted tracking terms kept
        rest = replace(rest, tracking=replace(rest.tracking, position_tolerance=None,
                                              orientation_tolerance=None))
    x0, u0, _ = _moved_start(planner, grid, base, REPLAN_DT, START_SHIFT)
    warm = shifted(base, REPLAN_DT)
    primal_only = replace(warm, nlp_point=None)
    # the re-plan's structure built and its warm solver made (timed apart)
    t0 = time.perf_counter()
    prep = attempt(rest, x0=x0, u0=u0, warm=warm, options=AttemptOptions(max_iter=1),
                   planner=planner)
    replan_build = {"attempt_s": time.perf_counter() - t0,
                    "build_s": prep.stats.build_time}
    nlp, _ = planner.build(rest)
    library_warm = nlp.warm_solver

    def timed(label: str, w: Any, max_iter: int | None = None, moving: bool = True
              ) -> dict[str, Any]:
        runs, ws, cpus = [], [], []
        for _ in range(repeats):
            c1 = time.process_time()
            t1 = time.perf_counter()
            runs.append(attempt(rest, x0=x0, u0=u0 if moving else None, warm=w,
                                planner=planner,
                                options=AttemptOptions(max_iter=max_iter, certify=True)))
            ws.append(time.perf_counter() - t1)
            cpus.append(time.process_time() - c1)
        row = _attempt_row(label, runs, ws, cpus)
        print(f"[replan] {name}: {json.dumps(row)}", file=sys.stderr, flush=True)
        return row

    # the planner's own guess of a moving start fails on a grasp with a palm (its palm
    # sub-plan is given the grasp's inputs: docs/performance.md), so cold starts at rest
    rows = [timed("cold (own guess, from rest)", None, moving=False), timed("warm", warm),
            timed("warm, primal point only", primal_only)]
    rows += [timed(f"warm, {k} iteration{'s' if k > 1 else ''}", warm, k) for k in BUDGETS]
    import casadi as ca

    for label, opts in WARM_VARIANTS.items():
        nlp.warm_solver = ca.nlpsol("manipulation_warm", "ipopt", nlp.oracle,
                                    {**nlp.options, **IPOPT_WARM_OPTIONS, **opts})
        rows.append(timed(f"warm, {label}", warm))
    nlp.warm_solver = library_warm
    return {"case": name, "build_s": build, "compiled": nlp.compiled,
            "variables": nlp.pack.nnz_out(0), "rows": len(nlp.lbg), "first": first,
            "replan_build": replan_build, "replans": rows}


def replan_markdown(cases: list[dict[str, Any]], meta: dict[str, Any]) -> str:
    head = (f"Re-plan benchmark ({meta['date']}; {meta['cpus']} CPU, load average "
            f"{meta['load']}, CasADi {meta['casadi']}, one BLAS thread; medians of "
            f"{meta['repeats']}): the rest of the motion {1e3 * REPLAN_DT:.0f} ms in, the "
            f"object moved {1e3 * START_SHIFT:.0f} mm, the goal {1e3 * GOAL_SHIFT:.0f} mm; "
            "IPOPT = the solver call, attempt = the whole `ocp.attempt` without its "
            "certificate; CPU = the process's CPU time over the attempt, certificate "
            "included; inf_pr / inf_du at the returned point.\n\n")
    lines = ["| case | variant | status | certified | iterations | IPOPT [ms] | attempt "
             "[ms] | certificate [ms] | CPU [ms] | inf_pr | inf_du |",
             "|---|---|---|---|---:|---:|---:|---:|---:|---:|---:|"]
    for c in cases:
        f = c["first"]
        lines.append(f"| {c['case']} (N = {f['n_intervals']}, {c['variables']} variables"
                     f"{', compiled' if c['compiled'] else ''}) | first plan (`solve`, "
                     f"build {c['build_s']:.2f} s) | {f['status']} | {f['certified']} | "
                     f"{f['iterations']} | {1e3 * f['ipopt_s']:.0f} | "
                     f"{1e3 * (f['wall_s'] - f['certificate_s']):.0f} | "
                     f"{1e3 * f['certificate_s']:.0f} | {1e3 * f.get('cpu_s', 0):.0f} | | |")
        for r in c["replans"]:
            lines.append(f"| | {r['variant']} | {r['status']} | {r['certified']} | "
                         f"{r['iterations']} | {1e3 * r['ipopt_s']:.0f} | "
                         f"{1e3 * r['attempt_s']:.0f} | {1e3 * r['certificate_s']:.0f} | "
                         f"{1e3 * r.get('cpu_s', 0):.0f} | "
                         f"{r['primal_inf']:.1e} | {r['dual_inf']:.1e} |")
    return head + "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> list[dict[str, Any]]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else "")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    parser.add_argument("--replan", action="store_true",
                        help="the re-plan measurement (issue 27) instead")
    parser.add_argument("--cases", default=",".join(REPLAN_CASES))
    parser.add_argument("--compile", type=Path, default=None,
                        help="compile the NLPs' functions, cached in this folder")
    args = parser.parse_args(argv)
    meta = {"date": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
            "cpus": os.cpu_count(), "python": platform.python_version(),
            "casadi": ca.__version__, "repeats": args.repeats}
    args.out.mkdir(parents=True, exist_ok=True)
    if args.replan:
        cases = [replan_case(c, args.repeats, args.compile) for c in args.cases.split(",")]
        meta["load"] = " / ".join(f"{x:.1f}" for x in os.getloadavg())
        _write(args.out / "replan", {"meta": meta, "cases": cases}, replan_markdown(cases, meta))
        return cases
    rows = [row for case in CASES for row in run_case(case, args.repeats)]
    _write(args.out / "warm_start", {"meta": meta, "rows": rows}, markdown(rows, meta))
    return rows


def _write(stem: Path, data: dict[str, Any], md: str) -> None:
    """The run's figures as ``stem``.json and its table as ``stem``.md (printed)."""
    stem.with_suffix(".json").write_text(json.dumps(data, indent=1) + "\n")
    stem.with_suffix(".md").write_text(md)
    print(md)


if __name__ == "__main__":
    main()
