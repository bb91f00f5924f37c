"""Plans executed in MuJoCo (docs/simulation.md): the figures of that page.

Plans the paper's experiments, the examples with fingers and the quick suite's problems
with fingers (collocation and the greedy method), executes each solved plan with the
simulator's defaults, and measures:

* ``plans``: each plan's worst and final position and orientation errors, contact losses,
  slip, normal forces, and the simulation's wall time;
* ``grip``: experiments 1 and 2 under other grips (squeeze, grip force), contact models
  (point contacts, rolling friction, a pyramidal cone, no no-slip iterations) and gains;
* ``timing``: experiment 1's 6 s, simulated on one core (the median of ``--repeats``).

Writes ``simulation.json`` and prints markdown tables. About two minutes on 2 cores.

    .venv/bin/python benchmarks/simulation.py --out /tmp/sim-bench
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import sys
import time
from pathlib import Path
from typing import Any

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from planner_service.bench.suite import expand, load_suite, units  # noqa: E402
from planner_service.cli import plan_request  # noqa: E402
from planner_service.execution import execution_plan  # noqa: E402
from planner_service.planners import REQUEST  # noqa: E402
from sim import SimOptions, simulate  # noqa: E402

#: Variations of the defaults tried on the paper's experiments.
VARIANTS: dict[str, dict[str, Any]] = {
    "defaults": {},
    "no grip": {"squeeze": 0.0, "grip_force": 0.0},
    "squeeze only (0.5 mm)": {"grip_force": 0.0},
    "grip force only (1 N)": {"squeeze": 0.0},
    "grip force only (3 N)": {"squeeze": 0.0, "grip_force": 3.0},
    "squeeze 0.2 mm": {"squeeze": 0.0002},
    "point contacts (condim 3)": {"condim": 3},
    "rolling friction (condim 6, 1e-4 m)": {"condim": 6, "rolling_friction": 1e-4},
    "no no-slip iterations": {"noslip_iterations": 0},
    "impratio 1": {"impratio": 1.0},
    "soft gains (kp 20, kv 0.2)": {"kp": 20.0, "kv": 0.2},
    "kinematic joints": {"mode": "kinematic"},
    "1 ms steps": {"timestep": 0.001},
}


def _plans() -> list[tuple[str, str, dict[str, Any]]]:
    out = [("paper", "experiment1",
            json.loads((ROOT / "docs" / "viewer-experiment1.json").read_text())),
           ("paper", "experiment2",
            json.loads((ROOT / "examples" / "experiment2_two_fingers.json").read_text()))]
    for path in sorted((ROOT / "examples").glob("*.json")):
        raw = json.loads(path.read_text())
        if raw.get("planner") in ("one_finger", "manipulation") and \
                path.stem != "experiment2_two_fingers":
            out.append(("examples", path.stem, raw))
    problems = expand(load_suite("quick"))
    for u in units(problems):
        if u.planner in ("one_finger", "manipulation") and u.method in ("collocation",
                                                                       "greedy"):
            if u.family == "paper" and u.method == "collocation":
                continue  # planned above
            out.append((f"quick/{u.family}", f"{u.problem_id} ({u.method})", u.request))
    return out


def _row(report: Any) -> dict[str, Any]:
    return {"passed": report.passed,
            "position_max_mm": report.position_error.max * 1e3,
            "position_final_mm": report.position_error.final * 1e3,
            "angle_max_deg": math.degrees(report.angle_error.max),
            "angle_final_deg": math.degrees(report.angle_error.final),
            "contacts_lost": report.contacts_lost,
            "slip_max_mm": max((c.slip_distance for c in report.contacts), default=0.0) * 1e3,
            "normal_force_min": min((c.normal_force_min for c in report.contacts),
                                    default=0.0),
            "normal_force_max": max((c.normal_force_max for c in report.contacts),
                                    default=0.0),
            "wall_time": report.wall_time, "duration": report.duration,
            "failures": report.failures}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", default="sim-bench", help="folder of simulation.json")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--skip-suite", action="store_true",
                        help="the experiments and examples only")
    args = parser.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    doc: dict[str, Any] = {"plans": [], "grip": {}, "timing": {}}
    executed: dict[str, Any] = {}
    for group, name, raw in _plans():
        if args.skip_suite and group.startswith("quick"):
            continue
        result, _ = plan_request(raw)
        entry: dict[str, Any] = {"group": group, "name": name,
                                 "status": result.status.value}
        if result.status.value == "solved":
            plan = execution_plan(result, REQUEST.validate_python(raw))
            report = simulate(plan)
            entry.update(_row(report))
            if group == "paper":
                executed[name] = plan
        doc["plans"].append(entry)
        print(json.dumps(entry), flush=True)
    for name, plan in executed.items():
        doc["grip"][name] = {}
        for label, options in VARIANTS.items():
            doc["grip"][name][label] = _row(simulate(plan, SimOptions.from_dict(options)))
    if "experiment1" in executed:
        times = []
        for _ in range(args.repeats):
            t0 = time.perf_counter()
            simulate(executed["experiment1"])
            times.append(time.perf_counter() - t0)
        doc["timing"] = {"experiment1_duration": executed["experiment1"].duration,
                         "wall_times": times, "median": statistics.median(times)}
    (out / "simulation.json").write_text(json.dumps(doc, indent=1) + "\n")
    print("\n| group | plan | passed | position worst / final [mm] | angle worst / final "
          "[deg] | contacts lost | slip worst [mm] | normal force [N] | wall [s] |")
    print("|---|---|---|---:|---:|---:|---:|---:|---:|")
    for e in doc["plans"]:
        if "passed" not in e:
            print(f"| {e['group']} | {e['name']} | not solved ({e['status']}) | | | | | | |")
            continue
        print(f"| {e['group']} | {e['name']} | {'yes' if e['passed'] else 'NO'} | "
              f"{e['position_max_mm']:.3f} / {e['position_final_mm']:.3f} | "
              f"{e['angle_max_deg']:.3f} / {e['angle_final_deg']:.3f} | "
              f"{e['contacts_lost']} | {e['slip_max_mm']:.3f} | "
              f"{e['normal_force_min']:.2f}..{e['normal_force_max']:.2f} | "
              f"{e['wall_time']:.2f} |")
    for name, variants in doc["grip"].items():
        print(f"\n{name}:\n\n| variant | passed | position worst [mm] | angle worst [deg] | "
              "contacts lost | slip worst [mm] |\n|---|---|---:|---:|---:|---:|")
        for label, e in variants.items():
            print(f"| {label} | {'yes' if e['passed'] else 'NO'} | "
                  f"{e['position_max_mm']:.3f} | {e['angle_max_deg']:.3f} | "
                  f"{e['contacts_lost']} | {e['slip_max_mm']:.3f} |")
    if doc["timing"]:
        print(f"\nexperiment 1 ({doc['timing']['experiment1_duration']:g} s): "
              f"{doc['timing']['median']:.2f} s wall (median of {args.repeats})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
