"""Issue 14's targets, measured: the four_finger_round family's solve time and success, the
NLP of one Allegro-class hand structure, and a worker's memory per hand structure.

Problems: the first ``--problems`` of the full suite's ``four_finger_round`` family (the
built-in hand's nominal grasp, 3-8 deg turns about random axes, <= 2 mm), or the example
``--request`` files. Each is planned ``--repeats`` times in this process through the
service's own path (``plan_request``'s adapter with a fresh ``Planners``): the first run
builds the structure's NLP (``build``), every run solves (``solve``: guess, IPOPT,
refinements, certificate: the planner's ``solve_time``); medians over the repeats.
``--compile DIR``: the NLP's functions as compiled C (``ManipulationPlanner(compile_dir)``,
gcc once per structure, cached in DIR), instead of CasADi's virtual machine.

Every process runs with one BLAS/OpenMP thread (as the bench's and the service's workers).
``--memory``: one fresh process per measurement (so that nothing is shared): the resident
set size (VmRSS) before building, after building the first problem's structure, and after
its first plan, and the NLP's size (variables, constraints, Jacobian and Hessian
non-zeros).

    .venv/bin/python tools/hand_bench.py [--problems 4] [--repeats 3] [--compile DIR]
    .venv/bin/python tools/hand_bench.py --memory
    .venv/bin/python tools/hand_bench.py --profile [--compile DIR]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
# one BLAS/OpenMP thread, as the bench's and the service's workers run (set before numpy,
# CasADi and IPOPT load their libraries)
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")


def rss_mb() -> float:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    raise RuntimeError("no VmRSS")


def family_requests(count: int) -> list[tuple[str, dict[str, Any]]]:
    from planner_service.bench.suite import expand, load_suite

    problems = expand(load_suite("full"), ["four_finger_round"], count)
    return [(p.id, p.request) for p in problems]


def _planners(compile_dir: Path | None) -> Any:
    from planner_service.planners.cache import FingerCache, Planners

    return Planners(fingers=FingerCache(compile_dir=compile_dir))


def plan_once(raw: dict[str, Any], planners: Any) -> dict[str, Any]:
    from planner_service.planners import REQUEST, adapter_for

    request = REQUEST.validate_python(raw)
    t0 = time.perf_counter()
    result, _ = adapter_for(request).solve(request, planners)
    wall = time.perf_counter() - t0
    d = result.model_dump()
    s = d.get("stats") or {}
    return {"status": d["status"], "certified": bool((d.get("certificate") or {}).get(
                "passed")),
            "iterations": s.get("iterations"), "N": s.get("n_intervals"),
            "refinements": s.get("refinements"), "build_s": s.get("build_time"),
            "solve_s": s.get("solve_time"), "wall_s": wall}


def nlp_size(planners: Any) -> dict[str, int]:
    """The sizes of the NLPs the manipulation planner holds (the last built)."""
    nlps = list(planners.fingers.manipulation.nlps.values())
    nlp = nlps[-1]
    jac = nlp.options["jac_g"]
    hess = nlp.options["hess_lag"]
    return {"variables": int(nlp.oracle.size1_in(0)), "constraints": len(nlp.lbg),
            "jacobian_nnz": int(jac.sparsity_out(jac.n_out() - 1).nnz()),
            "hessian_nnz": int(hess.sparsity_out(0).nnz()), "nlps_held": len(nlps)}


def memory(raw: dict[str, Any], compile_dir: Path | None) -> dict[str, Any]:
    """In this (fresh) process: RSS before, after the structure's build, after one plan."""
    import gc

    import ocp.solve.planner  # noqa: F401  (the libraries, imported before the baseline)
    from planner_service.planners import REQUEST, adapter_for

    planners = _planners(compile_dir)
    request = REQUEST.validate_python(raw)
    gc.collect()
    base = rss_mb()
    t0 = time.perf_counter()
    adapter = adapter_for(request)
    adapter.prepare(request, planners)
    gc.collect()
    built = rss_mb()
    build_wall = time.perf_counter() - t0
    out = plan_once(raw, planners)
    gc.collect()
    after = rss_mb()
    return {"rss_base_mb": base, "rss_built_mb": built, "rss_planned_mb": after,
            "build_wall_s": build_wall, "plan": out, "nlp": nlp_size(planners)}


def profile(raw: dict[str, Any], compile_dir: Path | None, repeats: int = 20
            ) -> dict[str, Any]:
    """Where an IPOPT iteration's time goes: the first problem's NLP (built as the planner
    does), each of its functions evaluated ``repeats`` times at a random point (median
    [ms]): the objective and constraints, their Jacobian, the Lagrangian's Hessian; in
    CasADi's virtual machine and, with ``compile_dir``, compiled; and one plan's IPOPT
    time split into its function calls and the rest (virtual machine)."""
    import casadi as ca
    import numpy as np

    from ocp.solve.compiled import compiled_block_solver
    from planner_service.planners import REQUEST, adapter_for

    planners = _planners(None)
    request = REQUEST.validate_python(raw)
    adapter_for(request).prepare(request, planners)
    nlp = list(planners.fingers.manipulation.nlps.values())[-1]
    rng = np.random.default_rng(0)
    x = rng.uniform(-0.1, 0.1, nlp.oracle.size1_in(0))
    p = rng.uniform(0.01, 0.1, nlp.oracle.size1_in(1))
    lam = rng.uniform(-1.0, 1.0, len(nlp.lbg))

    def timed(f: ca.Function, *args: Any) -> float:
        f(*args)
        ts = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            f(*args)
            ts.append(time.perf_counter() - t0)
        return 1e3 * statistics.median(ts)

    def row(options: dict[str, Any], oracle: ca.Function) -> dict[str, float]:
        return {"f_g_ms": timed(oracle, x, p),
                "jac_g_ms": timed(options["jac_g"], x, p),
                "hess_lag_ms": timed(options["hess_lag"], x, p, 1.0, lam)}

    out: dict[str, Any] = {"nlp": nlp_size(planners), "vm": row(nlp.options, nlp.oracle)}
    # one plan: IPOPT's own split of its time (the functions' calls and the rest: its
    # linear algebra and bookkeeping), from the solver's statistics
    out["plan"] = plan_once(raw, planners)
    st = nlp.solver.stats()
    calls = {k.removeprefix("t_wall_"): round(float(v), 3) for k, v in st.items()
             if k.startswith("t_wall_") and float(v) > 0}
    calls["functions"] = round(sum(v for k, v in calls.items() if k.startswith("nlp_")), 3)
    out["ipopt_wall_s"] = calls
    if compile_dir is not None:
        t0 = time.perf_counter()
        _, options = compiled_block_solver(nlp.oracle, nlp.options, nlp.fingerprint,
                                           compile_dir)
        out["compile_s"] = time.perf_counter() - t0
        out["compiled"] = row(options, nlp.oracle)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--problems", type=int, default=4)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--request", action="append", default=[],
                        help="a request file instead of the family (repeatable)")
    parser.add_argument("--compile", type=Path, default=None, metavar="DIR")
    parser.add_argument("--memory", action="store_true")
    parser.add_argument("--profile", action="store_true",
                        help="time the first problem's NLP functions (VM, --compile)")
    parser.add_argument("--child", default=None, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.request:
        reqs = [(Path(p).stem, json.loads(Path(p).read_text())) for p in args.request]
    else:
        reqs = family_requests(args.problems)
    if args.profile:
        print(json.dumps(profile(reqs[0][1], args.compile), indent=1))
        return
    if args.child is not None:  # one memory measurement, in its own process
        raw = dict(reqs)[args.child]
        print(json.dumps(memory(raw, args.compile)))
        return
    if args.memory:
        for name, _ in reqs:
            cmd = [sys.executable, __file__, "--child", name, "--problems", str(args.problems)]
            for r in args.request:
                cmd += ["--request", r]
            if args.compile is not None:
                cmd += ["--compile", str(args.compile)]
            out = subprocess.run(cmd, capture_output=True, text=True, check=True)
            m = json.loads(out.stdout.strip().splitlines()[-1])
            p = m["plan"]
            print(f"{name}: RSS {m['rss_base_mb']:.0f} MB -> built "
                  f"{m['rss_built_mb'] - m['rss_base_mb']:+.0f} MB -> planned "
                  f"{m['rss_planned_mb'] - m['rss_base_mb']:+.0f} MB in all; {p['status']}, "
                  f"N = {p['N']}, {p['refinements']} refinement(s); NLP {m['nlp']}")
            sys.stdout.flush()
        return
    print("| problem | status (certified) | N | refinements | iterations | build [s] | "
          "solve [s], median of repeats (all) | wall [s] |")
    print("|---|---|---|---|---|---|---|---|")
    solves_all = []
    solved = 0
    for name, raw in reqs:
        planners = _planners(args.compile)
        runs = [plan_once(raw, planners) for _ in range(args.repeats)]
        first = runs[0]
        solves = [float(r["solve_s"]) for r in runs]
        med = statistics.median(solves)
        solves_all.append(med)
        ok = first["status"] == "solved" and first["certified"]
        solved += ok
        print(f"| {name} | {first['status']} ({'yes' if first['certified'] else 'no'}) | "
              f"{first['N']} | {first['refinements']} | {first['iterations']} | "
              f"{first['build_s']:.2f} | {med:.2f} ({', '.join(f'{s:.2f}' for s in solves)})"
              f" | {statistics.median(r['wall_s'] for r in runs):.1f} |")
        sys.stdout.flush()
    print(f"\nsolved and certified {solved}/{len(reqs)}; median solve "
          f"{statistics.median(solves_all):.2f} s")


if __name__ == "__main__":
    main()
