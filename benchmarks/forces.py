"""Benchmark of planned forces (issue 15, docs/forces.md): the solve time a plan's forces
add, and the size of the inertial wrench the quasi-static model leaves out.

Each problem is solved three ways: without forces, with forces in two stages (the
kinematics, then the forces point by point: the planner's default) and with the coupled
NLP (``two_stage_forces = False``), old and new side by side in one run.

Problems: the paper's experiments (experiment 1: docs/viewer-experiment1.json; 2:
examples/experiment2_two_fingers.json) and the quick bench suite's finger families
(one_finger, two_fingers, three_fingers). Each is solved by the library's planner without
and with ``forces`` (50 g, 1 N minimum, 5 mm torsional friction), a fresh planner each, its
NLP built before the clock starts; reported: status, IPOPT iterations, refinements, the
plan's ``stats.solve_time`` (guesses and IPOPT, every refinement), the ratio. Then, on
the experiments' plans, the object's acceleration and the inertial moment
``I alpha + w x I w`` (solid body) by central differences of the returned trajectory
inside every interval (the paper's piecewise timing has velocity jumps at via-points:
impulses no smooth model holds, counted apart), against the weight ``m g`` and
``m g L``.

    .venv/bin/python benchmarks/forces.py [--mass 0.05]
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from ocp.one_finger import OneFingerPlanner
from ocp.solve.planner import ManipulationPlanner, ManipulationProblem
from ocp.spec.problem import ForceSpec
from planner_service.bench.suite import expand, load_suite
from planner_service.planners import REQUEST
from planner_service.planners.cache import FingerCache
from planner_service.planners.manipulation import manipulation_problem
from planner_service.planners.one_finger import one_finger_problem

ROOT = Path(__file__).resolve().parents[1]
EXPERIMENTS = {"experiment1": ROOT / "docs" / "viewer-experiment1.json",
               "experiment2": ROOT / "examples" / "experiment2_two_fingers.json"}


def problem_of(raw: dict[str, Any], cache: FingerCache) -> ManipulationProblem:
    request: Any = REQUEST.validate_python(raw)
    if request.planner == "one_finger":
        return OneFingerPlanner.manipulation_problem(one_finger_problem(request, cache))
    return manipulation_problem(request, cache)


def inertial_terms(problem: ManipulationProblem, sol: Any) -> tuple[float, float]:
    """(max |a| / g, max |I alpha + w x I w| / (m g L)) inside the intervals."""
    tn = sol.trajectory.t_nodes
    ss = np.linspace(0.05, 0.95, 19)
    t = np.concatenate([tn[k] + (tn[k + 1] - tn[k]) * ss for k in range(len(tn) - 1)])
    d = 1e-3 * float(np.min(np.diff(tn)))

    def pose(tt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        smp = sol.sample(tt)
        return smp.object_position, smp.object_rotation

    def omega(tt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        (_, Rp), (_, Rm), (_, R0) = pose(tt + d), pose(tt - d), pose(tt)
        W = np.einsum("kij,klj->kil", (Rp - Rm) / (2 * d), R0)
        return np.stack([W[:, 2, 1], W[:, 0, 2], W[:, 1, 0]], axis=1), R0

    (p0, _), (pp, _), (pm, _) = pose(t), pose(t + d), pose(t - d)
    a = (pp - 2 * p0 + pm) / d**2
    w, R = omega(t)
    alpha = (omega(t + d)[0] - omega(t - d)[0]) / (2 * d)
    inertia = np.array(ForceSpec(1.0).principal_inertia(problem.object))  # per kg
    wo, ao = np.einsum("kji,kj->ki", R, w), np.einsum("kji,kj->ki", R, alpha)
    moment = ao * inertia + np.cross(wo, wo * inertia)
    g, L = 9.81, problem.object.length_scale
    return (float(np.linalg.norm(a, axis=1).max() / g),
            float(np.linalg.norm(moment, axis=1).max() / (g * L)))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--mass", type=float, default=0.05)
    args = ap.parse_args()
    load = ForceSpec(mass=args.mass, min_normal_force=1.0, torsional_friction=0.005)
    cache = FingerCache()
    raws = [(name, json.loads(path.read_text(encoding="utf-8")))
            for name, path in EXPERIMENTS.items()]
    raws += [(p.id, p.request) for p in expand(load_suite("quick"),
                                                ["one_finger", "two_fingers", "three_fingers"])]
    ratios, coupled_ratios = [], []
    totals = {"plain": 0.0, "forces": 0.0, "coupled": 0.0}
    print("| problem | plain: status, iterations, refinements, solve [s] | forces, two "
          "stages: ... | forces, coupled NLP: ... | ratio two stages | ratio coupled |")
    print("|---|---|---|---|---:|---:|")
    plans = {}
    for name, raw in raws:
        problem = problem_of(raw, cache)
        cells = []
        times = {}
        for tag, pr in (("plain", problem), ("forces", replace(problem, forces=load)),
                        ("coupled", replace(problem, forces=load))):
            planner = ManipulationPlanner()
            planner.two_stage_forces = tag != "coupled"
            planner.prepare(pr)  # two stages: the kinematic NLP; coupled: its own
            t0 = time.perf_counter()
            sol = planner.solve(pr)
            _ = time.perf_counter() - t0
            times[tag] = sol.stats.solve_time
            totals[tag] += sol.stats.solve_time
            cells.append(f"{sol.status.value}, {sol.iterations}, {sol.refinements}, "
                         f"{sol.stats.solve_time:.2f}")
            if tag == "plain" and name in EXPERIMENTS:
                plans[name] = (problem, sol)
        ratios.append(times["forces"] / times["plain"])
        coupled_ratios.append(times["coupled"] / times["plain"])
        print(f"| {name} | {cells[0]} | {cells[1]} | {cells[2]} | {ratios[-1]:.2f} | "
              f"{coupled_ratios[-1]:.2f} |", flush=True)
    print(f"\nmedian ratio: two stages {statistics.median(ratios):.2f}, coupled "
          f"{statistics.median(coupled_ratios):.2f}; total solve {totals['plain']:.1f} s -> "
          f"{totals['forces']:.1f} s two stages ({totals['forces'] / totals['plain']:.2f}x), "
          f"{totals['coupled']:.1f} s coupled ({totals['coupled'] / totals['plain']:.2f}x)")
    for name, (problem, sol) in plans.items():
        acc, mom = inertial_terms(problem, sol)
        print(f"{name}: inertial force <= {acc:.2e} m g, inertial moment <= {mom:.2e} m g L "
              f"(inside intervals); velocity jumps at {len(sol.break_nodes())} nodes")


if __name__ == "__main__":
    main()
