"""The window controller against today's warm re-plan (issue 41; docs/control.md).

Per plan (experiment 1, experiment 2, three fingers, the Allegro hand's rolling turn):

* **re-plan** (before): the rest of the motion re-solved warm from the plan's own state
  (``ocp.attempt`` on ``problem.remaining(t)``, the shifted plan as warm start, 30 IPOPT
  iterations at most) every 0.25 s: wall time per call, iterations;
* **window** (now): ``ocp.WindowController`` ticking every 10 ms along the plan from the
  plan's own state: IPOPT on its collocation NLP in CasADi's virtual machine and compiled
  to C, and the real-time-iteration backend (multiple shooting, HPIPM; each tick prepared
  after the last one's answer, the preparation timed apart); construction (``prepare``:
  the NLP, its solvers, the converged first window) timed apart from the ticks; per tick
  the wall time (median, p99), the solver's share, iterations, the primal infeasibility
  left; every ``--certify-every``-th window certified (outside the ticks).

Then the closed loop in MuJoCo (``--loop``): experiments 1 and 2 pushed 3 mm sideways at
2 s (and undisturbed), the window controller (IPOPT, RTI) at 100 Hz with its latency
charged in simulated time beside the 4 Hz re-planner with MuJoCo paused: final error, recovered,
ticks, overruns, wall times, windows certified.

    PYTHONPATH=. .venv/bin/python benchmarks/controller.py [--only NAME] [--loop]
        [--out FILE]
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from ocp import (  # noqa: E402
    AttemptOptions,
    ControllerOptions,
    ManipulationPlanner,
    WindowController,
    attempt,
    shifted,
)
from planner_service.execution import execution_plan  # noqa: E402
from planner_service.execution.closed_loop import compare, first_plan  # noqa: E402
from planner_service.planners import REQUEST  # noqa: E402

PLANS = [
    ("experiment 1", "docs/viewer-experiment1.json"),
    ("experiment 2", "examples/experiment2_two_fingers.json"),
    ("three fingers", "examples/three_finger_turn.json"),
    ("Allegro turn", "examples/allegro_turn.json"),
]


def _ms(values: list[float]) -> dict[str, float]:
    a = 1e3 * np.asarray(values)
    return {"median_ms": float(np.median(a)), "p99_ms": float(np.percentile(a, 99)),
            "max_ms": float(a.max())}


def replan_ticks(fp: Any, period: float = 0.25) -> dict[str, Any]:
    """Today's warm re-plan of the rest from the plan's own state every ``period``."""
    planner = ManipulationPlanner()
    problem, plan = fp.problem.with_intervals(fp.plan.stats.n_intervals), fp.plan
    walls, its = [], []
    t = period
    while problem.duration - t > 0.3:
        x, u = plan.interpolate([t])
        rest = problem.remaining(t)
        t0 = time.perf_counter()
        sol = attempt(rest, x0=x[0], u0=u[0], warm=shifted(plan, t),
                      options=AttemptOptions(max_iter=30), planner=planner)
        if t > period:  # the first call builds the NLP
            walls.append(time.perf_counter() - t0)
            its.append(sol.stats.iterations)
        t += period
    return {"calls": len(walls), **_ms(walls), "iterations_median": statistics.median(its)}


def window_ticks(fp: Any, compiled: Path | None, options: ControllerOptions,
                 certify_every: int) -> dict[str, Any]:
    """The window controller ticking every 10 ms along the plan from its own state."""
    planner = ManipulationPlanner(compile_dir=compiled)
    t0 = time.perf_counter()
    c = WindowController(fp.problem, fp.plan, options, planner)
    construction = c.prepare()
    build = time.perf_counter() - t0
    ts = np.arange(0.01, fp.plan.duration, 0.01)
    preps = []
    for t in ts:
        preps.append(c.prepare_next(float(t)))  # (RTI: its linearisation; IPOPT: 0)
        c.tick(float(t), c.state_at(float(t))[0])
    ticks = c.ticks
    checked = certified = 0
    t_cert = []
    for k, tick in enumerate(ticks):
        if k % certify_every == 0:
            s0 = time.perf_counter()
            certified += bool(c.certify(tick).passed)
            t_cert.append(time.perf_counter() - s0)
            checked += 1
    pinf = [tk.primal_infeasibility or 0.0 for tk in ticks]
    return {"construction_s": build, "prepare_s": construction, "ticks": len(ticks),
            **_ms([tk.wall_time for tk in ticks]),
            "ipopt_median_ms": 1e3 * float(np.median([tk.solve_time for tk in ticks])),
            "preparation_median_ms": 1e3 * float(np.median(preps)),
            "selection": c.selection,
            "iterations_median": statistics.median(tk.iterations for tk in ticks),
            "primal_infeasibility_median": float(np.median(pinf)),
            "primal_infeasibility_max": float(np.max(pinf)),
            "certified": certified, "checked": checked,
            "certificate_median_ms": 1e3 * float(np.median(t_cert))}


def closed_loops(fp: Any, request: Any, compiled: Path | None) -> list[dict[str, Any]]:
    from sim.disturbances import Disturbances, parse_kick

    base = execution_plan(fp.result, request)
    rows = []
    for label, dist in (("none", Disturbances()),
                        ("push 3 mm at 2 s", Disturbances(pushes=(parse_kick("2.0,0,0.003,0"),)))):
        for kind in ("window IPOPT 100 Hz (latency charged)",
                     "window RTI 100 Hz (latency charged)", "re-plan 4 Hz (paused)"):
            t0 = time.perf_counter()
            if kind.startswith("window"):
                backend = "rti" if "RTI" in kind else "ipopt"
                out = compare(fp, base, 100.0, None, dist,
                              control=ControllerOptions(backend=backend),
                              planner=ManipulationPlanner(compile_dir=compiled))
            else:
                out = compare(fp, base, 4.0, None, dist)
            c = out["closed_loop"]
            s, o, t = c["summary"], out["open_loop"]["summary"], c["control"]
            cert = c.get("certificates") or {}
            rows.append({"disturbance": label, "controller": kind,
                         "open_final_mm": o["position_final_mm"],
                         "final_mm": s["position_final_mm"],
                         "final_deg": s["angle_final_deg"], "recovered": s["recovered"],
                         "contact_lost_after": s["contact_lost_after_kicks"],
                         "calls": t["calls"], "overruns": t.get("overruns"),
                         "wall_median_ms": 1e3 * (t["wall_time_median"] or 0.0),
                         "wall_p99_ms": 1e3 * (t.get("wall_time_p99") or 0.0),
                         "certified": cert.get("certified"), "checked": cert.get("checked"),
                         "run_s": time.perf_counter() - t0})
    return rows


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", default="controller.json")
    ap.add_argument("--only", action="append", default=[])
    ap.add_argument("--loop", action="store_true", help="also the MuJoCo closed loops")
    ap.add_argument("--certify-every", type=int, default=10)
    ap.add_argument("--max-iter", type=int, default=1)
    args = ap.parse_args()
    options = ControllerOptions(max_iter=args.max_iter)
    out: dict[str, Any] = {"options": repr(options), "plans": {}}
    compiled = Path(tempfile.mkdtemp(prefix="dexroll-controller-"))
    print("| plan | method | ticks | median ms | p99 ms | solver ms | preparation ms | "
          "iterations | certified |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name, path in PLANS:
        if args.only and name not in args.only:
            continue
        request = REQUEST.validate_python(json.loads((ROOT / path).read_text()))
        fp = first_plan(request)
        rows: dict[str, Any] = {"replan": replan_ticks(fp)}
        r = rows["replan"]
        print(f"| {name} | warm re-plan every 0.25 s | {r['calls']} | {r['median_ms']:.1f} "
              f"| {r['p99_ms']:.1f} | | {r['iterations_median']} | |")
        for label, cdir, backend in (("window IPOPT, VM", None, "ipopt"),
                                     ("window IPOPT, compiled", compiled, "ipopt"),
                                     ("window RTI (HPIPM), VM", None, "rti"),
                                     ("window RTI (HPIPM), compiled", compiled, "rti")):
            w = window_ticks(fp, cdir, replace(options, backend=backend),
                             args.certify_every)
            rows[label] = w
            print(f"| {name} | {label} | {w['ticks']} | {w['median_ms']:.1f} | "
                  f"{w['p99_ms']:.1f} | {w['ipopt_median_ms']:.1f} | "
                  f"{w['preparation_median_ms']:.1f} | {w['iterations_median']} | "
                  f"{w['certified']}/{w['checked']} |")
        if args.loop and name in ("experiment 1", "experiment 2"):
            rows["closed_loop"] = closed_loops(fp, request, compiled)
            for lr in rows["closed_loop"]:
                print(f"|   {lr['disturbance']} | {lr['controller']} | final "
                      f"{lr['final_mm']:.2f} mm {lr['final_deg']:.2f} deg (open "
                      f"{lr['open_final_mm']:.2f} mm) | recovered {lr['recovered']} | "
                      f"calls {lr['calls']} overruns {lr['overruns']} | "
                      f"{lr['wall_median_ms']:.1f} / {lr['wall_p99_ms']:.1f} ms | "
                      f"certified {lr['certified']}/{lr['checked']} | |")
        out["plans"][name] = rows
        Path(args.out).write_text(json.dumps(out, indent=1) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
