"""The closed-loop family (issue 28, docs/simulation.md "Closed loop"): each plan executed
open loop and closed loop (re-planned from the measured state at RATE in simulated time)
in the same disturbed world: no disturbance, a 3 mm push mid-motion, friction times 0.7,
a ball 1 mm larger in diameter. Prints a Markdown table and writes every run's summary
and controller timing as JSON.

    PYTHONPATH=. .venv/bin/python benchmarks/closed_loop.py [--out FILE] [--only NAME]
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from ocp import ControllerOptions  # noqa: E402
from ocp.solve.replan import ReplanOptions  # noqa: E402
from planner_service.execution import execution_plan  # noqa: E402
from planner_service.execution.closed_loop import compare, first_plan  # noqa: E402
from planner_service.planners import REQUEST  # noqa: E402
from sim.disturbances import Disturbances, Kick  # noqa: E402

#: (name, request, mid-motion push (time, displacement: in the plane the contacts allow
#: the object to slide in: the palm's plane, the pads' planes), the re-plans' options:
#: warm from the shifted plan's multipliers for the experiments (8-11 iterations), from
#: its primal point alone for the hands (three fingers: 22-25 iterations instead of 48-50,
#: docs/performance.md "Closing the loop"))
PLANS = [
    ("experiment 1", "docs/viewer-experiment1.json", Kick(3.0, (0.003, 0.0, 0.0)),
     ReplanOptions(max_iter=30)),
    ("experiment 2", "examples/experiment2_two_fingers.json", Kick(2.0, (0.0, 0.003, 0.0)),
     ReplanOptions(max_iter=30)),
    ("three fingers", "examples/three_finger_turn.json", Kick(1.5, (0.0, 0.0, 0.003)),
     ReplanOptions(max_iter=60, warm_duals=False)),
    ("four fingers (Allegro)", "examples/allegro_turn.json", None,
     ReplanOptions(max_iter=60, warm_duals=False)),
]


def variants(push: Kick | None) -> list[tuple[str, Disturbances]]:
    out = [("none", Disturbances())]
    if push is not None:
        out.append(("push 3 mm", Disturbances(pushes=(push,))))
        out.append(("push 3 mm, pose noise 0.2 mm / 0.5 deg",
                    Disturbances(pushes=(push,), pose_noise=(2e-4, math.radians(0.5)))))
    out += [("friction x0.7", Disturbances(friction_scale=0.7)),
            ("ball +1 mm (diameter)", Disturbances(size_change=0.5e-3))]
    return out


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", default="closed_loop.json")
    ap.add_argument("--only", action="append", default=[])
    ap.add_argument("--rate", type=float, default=None,
                    help="default 4 Hz (replan), 100 Hz (window)")
    ap.add_argument("--controller", choices=("replan", "window"), default="replan",
                    help="window: the window controller in real time, its latency "
                         "charged in simulated time (docs/control.md)")
    ap.add_argument("--only-variant", action="append", default=[])
    args = ap.parse_args()
    rows: list[dict[str, Any]] = []
    for name, path, push, replan in PLANS:
        if args.only and name not in args.only:
            continue
        request = REQUEST.validate_python(json.loads((ROOT / path).read_text()))
        t0 = time.perf_counter()
        first = first_plan(request)
        plan_time = time.perf_counter() - t0
        base = execution_plan(first.result, request)
        for label, dist in variants(push):
            if args.only_variant and label not in args.only_variant:
                continue
            t1 = time.perf_counter()
            if args.controller == "window":
                out = compare(first, base, args.rate or 100.0, disturbances=dist,
                              control=ControllerOptions())
            else:
                out = compare(first, base, args.rate or 4.0, disturbances=dist,
                              replan=replan)
            c = out["closed_loop"]["control"]
            walls = [e["wall_time"] for e in out["closed_loop"]["events"]
                     if e["status"] != "kept"]
            its = [e["iterations"] for e in out["closed_loop"]["events"]
                   if e["status"] != "kept" and "iterations" in e]
            row = {"plan": name, "disturbance": label, "first_plan_s": plan_time,
                   "open": out["open_loop"]["summary"],
                   "closed": out["closed_loop"]["summary"], "control": c,
                   "setup_s": out["closed_loop"]["setup_time"],
                   "iterations_median": statistics.median(its) if its else None,
                   "wall_times": walls, "run_s": time.perf_counter() - t1}
            rows.append(row)
            o, k = row["open"], row["closed"]

            def goal(s: dict[str, Any]) -> str:
                a = s["goal_angle_deg"]
                return f"{s['goal_position_mm']:.2f} / {'free' if a is None else f'{a:.2f}'}"

            print(f"| {name} | {label} | {goal(o)} | {'yes' if o['recovered'] else 'no'} | "
                  f"{goal(k)} | {'yes' if k['recovered'] else 'no'} | "
                  f"{k['position_worst_mm']:.2f} / {k['angle_worst_deg']:.2f} | "
                  f"{c['statuses']}"
                  + (f", {c['overruns']} overruns, windows certified "
                     f"{out['closed_loop']['certificates']['certified']}/"
                     f"{out['closed_loop']['certificates']['checked']}"
                     if c.get("latency_charged") else "") + " | "
                  f"{1e3 * (c['wall_time_median'] or 0):.0f} | "
                  f"{row['iterations_median']} |", flush=True)
            Path(args.out).write_text(json.dumps(rows, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
