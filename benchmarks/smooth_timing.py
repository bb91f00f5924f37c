"""Benchmark of the smooth timing (issue 15, part 2; docs/timing.md): the paper's piecewise
timing and the smooth one side by side, on the same requests, in one run.

Problems: the paper's experiments (experiment 1: docs/viewer-experiment1.json; 2:
examples/experiment2_two_fingers.json) and the quick bench suite's finger families
(one_finger, two_fingers, three_fingers), each with ``forces`` (50 g, 1 N minimum normal
force, 5 mm torsional friction). Each request is planned with ``timing`` "paper" and
"smooth" through the wire (:func:`planner_service.cli.plan_request`, a fresh planner each:
the reported solve time is the plan's ``stats.solve_time``, guesses and IPOPT over every
refinement, without the NLP's construction), then executed in MuJoCo on the plan's own
forces (the simulator's squeeze and grip force 0). Reported per plan: status, IPOPT
iterations, refinements, solve time; the execution's verdict, worst position and angle
errors, contact losses; then the median ratio of the solve times (smooth / paper).

    .venv/bin/python benchmarks/smooth_timing.py [--families one_finger,two_fingers]
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
from pathlib import Path
from typing import Any

from planner_service.bench.suite import expand, load_suite
from planner_service.cli import plan_request
from planner_service.execution import simulate_result
from planner_service.planners import REQUEST

ROOT = Path(__file__).resolve().parents[1]
EXPERIMENTS = {"experiment1": ROOT / "docs" / "viewer-experiment1.json",
               "experiment2": ROOT / "examples" / "experiment2_two_fingers.json"}
FORCES = {"mass": 0.05, "min_normal_force": 1.0, "torsional_friction": 0.005}
SIM = {"squeeze": 0.0, "grip_force": 0.0}


def run(raw: dict[str, Any], timing: str) -> tuple[str, float | None]:
    req_raw = dict(raw, timing=timing, forces=FORCES)
    result, _ = plan_request(req_raw)
    d = json.loads(result.model_dump_json())
    st = d.get("stats") or {}
    solve = st.get("solve_time")
    cell = (f"{d['status']}, {st.get('iterations')}, {st.get('refinements', 0)}, "
            f"{solve:.2f}" if solve is not None else d["status"])
    if d["status"] != "solved":
        return f"{cell} | not executed", None
    report = simulate_result(result, REQUEST.validate_python(req_raw), SIM)
    lost = sum(c.lost_time for c in report.contacts)
    verdict = "passed" if report.passed else "FAILED: " + "; ".join(report.failures)[:120]
    return (f"{cell} | {verdict}, {report.position_error.max * 1e3:.3f} mm, "
            f"{math.degrees(report.angle_error.max):.3f} deg, lost {lost * 1e3:.1f} ms",
            float(solve))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--families", default="one_finger,two_fingers,three_fingers")
    args = ap.parse_args()
    raws = [(name, json.loads(path.read_text(encoding="utf-8")))
            for name, path in EXPERIMENTS.items()]
    families = [f for f in args.families.split(",") if f]
    if families:
        raws += [(p.id, p.request) for p in expand(load_suite("quick"), families)]
    print("| problem | timing | status, iterations, refinements, solve [s] | executed on "
          "its own forces: verdict, worst position, worst angle, contact lost |")
    print("|---|---|---|---|")
    ratios = []
    for name, raw in raws:
        times = {}
        for timing in ("paper", "smooth"):
            cell, solve = run(raw, timing)
            times[timing] = solve
            print(f"| {name} | {timing} | {cell} |", flush=True)
        if times["paper"] and times["smooth"]:
            ratios.append(times["smooth"] / times["paper"])
    if ratios:
        print(f"\nsolve time smooth / paper: median {statistics.median(ratios):.2f} "
              f"({len(ratios)} problems)")


if __name__ == "__main__":
    main()
