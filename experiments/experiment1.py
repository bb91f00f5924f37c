"""The paper's experiment 1: one flat fingertip rolling a ball on the palm (section 5.2).

Builds the experiment as this project sets it up (docs/experiments.md), plans it with both
methods of the library:

* ``nlp``: the direct-collocation NLP, :class:`ocp.one_finger.OneFingerPlanner`;
* ``greedy``: the paper's own step-by-step method, :func:`ocp.methods.greedy.greedy_plan`;

and writes to ``--out`` (default ``docs/figures/``):

* ``fig6_paths.png``: ball centre and fingertip (pad centre) paths in the palm's x-y plane,
  the desired triangle dashed (the paper's figure 6, oabo and OABO);
* ``fig7_contact_on_fingertip.png``: the finger contact's path across the pad, in pad
  coordinates (x_f, y_f), with the pad's outline (the paper's figure 7);
* ``grasp_angles.png``: max(Phi_p, Phi_f) over time, with atan(mu);
* ``joint_angles.png``: the finger's joint angles over time;
* ``experiment1_summary.json``: the numbers of both plans (SI units; key suffixes say
  which: ``_s``, ``_m``, ``_rad``, ``_rad2_per_s``).

Run from the repository root: ``.venv/bin/python experiments/experiment1.py [--out DIR]``.
The figures are plans, not measurements: there is no sensor noise in them.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from numpy.typing import NDArray

from ocp.methods.greedy import GreedyResult, greedy_plan
from ocp.one_finger import FingerContact, OneFingerPlanner, OneFingerProblem, OneFingerSolution
from ocp.robots.finger import PAPER_SEED_DEG, FingerModel, load_finger
from ocp.spec.problem import BallOnPalmProblem, ObjectSpec, ViaPoint

FloatArray = NDArray[np.float64]

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_OUT = ROOT / "docs" / "figures"

#: Ball radius [m]: ours, the paper does not give it.
RHO = 0.025
#: The palm contact's path: the triangle (0, 0) -> (30, 0) -> (30, 30) -> (0, 0) mm, a side
#: every 2 s.
TRIANGLE_M = ((0.0, 0.0), (0.03, 0.0), (0.03, 0.03), (0.0, 0.0))
VIA_TIMES = (2.0, 4.0)
DURATION = 6.0
N_INTERVALS = 60
MU = 0.5
#: The finger contact at t = 0 (x_f, y_f, u_f, v_f, psi_f) and its chart patch on the ball
#: (half a turn about the ball's z): patch point (0, 0) is the ball's top at the start, so
#: u_f = 0.2 rad starts the contact 11.5 deg from the top, grasp angles 5.7 deg.
FINGER_CONTACT_INITIAL = (0.0, 0.0, 0.2, 0.0, 0.0)
FINGER_CHART_ROTATION = (0.0, 0.0, math.pi)
#: Grasp angle below which the grasp counts as antipodal in the summary [rad].
CONVERGED = math.radians(1.0)

METHODS = ("nlp", "greedy")
LABELS = {"nlp": "NLP (direct collocation)", "greedy": "greedy (the paper's method)"}
COLORS = {"nlp": "tab:blue", "greedy": "tab:orange"}

FIGURES = ("fig6_paths.png", "fig7_contact_on_fingertip.png", "grasp_angles.png",
           "joint_angles.png")
SUMMARY = "experiment1_summary.json"


def build_problem(finger: FingerModel | None = None) -> OneFingerProblem:
    """Experiment 1 as this project sets it up (SI units; default objective weights)."""
    _, (xa, ya), (xb, yb), (xo, yo) = TRIANGLE_M
    base = BallOnPalmProblem(
        object=ObjectSpec("sphere", (RHO,)),
        initial=(0.0, 0.0, 0.0, 0.0, -math.pi / 2),
        goal={"x": xo, "y": yo},
        duration=DURATION,
        via_points=(ViaPoint(VIA_TIMES[0], {"x": xa, "y": ya}),
                    ViaPoint(VIA_TIMES[1], {"x": xb, "y": yb})),
        n_intervals=N_INTERVALS,
        timing="paper",  # the paper's piecewise inputs, as its figures
    )
    contact = FingerContact(initial=FINGER_CONTACT_INITIAL,
                            chart_rotation=FINGER_CHART_ROTATION,
                            q_seed=tuple(math.radians(a) for a in PAPER_SEED_DEG))
    return OneFingerProblem(base=base, finger=finger or load_finger(), contact=contact, mu=MU)


# -- the two plans, in one shape -------------------------------------------------------------

@dataclass(frozen=True)
class Run:
    """What the figures and the summary need of one plan (palm frame, SI units)."""

    method: str
    t: FloatArray
    ball_centre: FloatArray  # (n, 3) [m]
    fingertip: FloatArray  # (n, 3) pad centre by Pinocchio's FK of q [m]
    pad_contact: FloatArray  # (n, 2) (x_f, y_f) [m]
    grasp: FloatArray  # (n,) max(Phi_p, Phi_f) [rad]
    cone_margin: FloatArray  # (n,) [rad]
    q: FloatArray  # (n, nq) [rad]
    summary: dict[str, Any]


def path_length(p: FloatArray) -> float:
    return float(np.sum(np.linalg.norm(np.diff(p, axis=0), axis=1)))


def simpson_samples(t: FloatArray, f: FloatArray) -> float:
    """Simpson's rule over consecutive (node, midpoint, node) triples of samples."""
    h = t[2::2] - t[:-2:2]
    return float(np.sum(h / 6 * (f[:-2:2] + 4 * f[1::2] + f[2::2])))


def grasp_summary(t: FloatArray, grasp: FloatArray, margin: FloatArray) -> dict[str, Any]:
    below = np.flatnonzero(grasp < CONVERGED)
    k = int(below[0]) if below.size else None
    return {
        "grasp_angle_start_rad": float(grasp[0]),
        "grasp_angle_end_rad": float(grasp[-1]),
        "grasp_angle_max_rad": float(grasp.max()),
        "time_below_1deg_s": None if k is None else float(t[k]),
        "grasp_angle_max_after_below_1deg_rad": None if k is None else float(grasp[k:].max()),
        "min_cone_margin_rad": float(margin.min()),
    }


def geometry_summary(ball: FloatArray, tip: FloatArray, pad: FloatArray) -> dict[str, Any]:
    return {
        "pad_excursion_m": float(np.max(np.abs(pad))),
        "ball_centre_path_length_m": path_length(ball[:, :2]),
        "fingertip_path_length_m": path_length(tip[:, :2]),
        "pad_contact_path_length_m": path_length(pad),
    }


def run_nlp(problem: OneFingerProblem) -> tuple[Run, OneFingerSolution]:
    t0 = time.perf_counter()
    sol = OneFingerPlanner().solve(problem)
    wall = time.perf_counter() - t0
    finger = problem.finger
    tip = np.array([finger.fingertip_pose_pin(q)[1] for q in sol.q])
    grasp = sol.grasp_angles.max(axis=1)
    cert = sol.certificate
    summary: dict[str, Any] = {
        "method": LABELS["nlp"],
        "status": sol.status.value,
        "ok": sol.ok,
        "message": sol.message,
        "build_time_s": sol.build_time,
        "solve_time_s": sol.solve_time,
        "wall_time_s": wall,
        "iterations": sol.iterations,
        "steps": None,
        "goal_error_m": max(sol.goal_error.values()),
        "reintegrated_position_defect_m": cert.get("max_position_defect"),
        **grasp_summary(sol.t, grasp, sol.cone_margin),
        **geometry_summary(sol.object_position, tip, sol.eta_f[:, 0:2]),
        "joint_effort_rad2_per_s": simpson_samples(sol.t, np.sum(sol.q_dot**2, axis=1)),
        "max_joint_rate_ratio": float(np.max(np.abs(sol.q_dot) / finger.velocity_limit)),
        "closure_error_m": cert.get("max_closure_position_error"),
        "closure_error_rad": cert.get("max_closure_orientation_error"),
        "certificate_passed": bool(cert) and not sol.certificate_failures,
        "certificate_failures": list(sol.certificate_failures),
        "failures": [] if sol.ok else [sol.message],
    }
    run = Run("nlp", sol.t, sol.object_position, tip, sol.eta_f[:, 0:2], grasp,
              sol.cone_margin, sol.q, summary)
    return run, sol


def run_greedy(problem: OneFingerProblem) -> tuple[Run, GreedyResult]:
    t0 = time.perf_counter()
    res = greedy_plan(problem)
    wall = time.perf_counter() - t0
    grasp = res.max_grasp_angle
    summary: dict[str, Any] = {
        "method": LABELS["greedy"],
        "status": "ok" if res.ok else "failed",
        "ok": res.ok,
        "message": "the plan holds" if res.ok else "; ".join(res.failures),
        "build_time_s": None,
        "solve_time_s": res.compute_time,
        "palm_plan_time_s": res.palm_plan_time,
        "wall_time_s": wall,
        "iterations": None,
        "steps": len(res.t) - 1,
        "goal_error_m": max(res.goal_error.values()),
        "reintegrated_position_defect_m": None,
        **grasp_summary(res.t, grasp, res.cone_margin),
        **geometry_summary(res.object_position, res.fingertip_position, res.eta_f[:, 0:2]),
        "joint_effort_rad2_per_s": res.joint_effort,
        "max_joint_rate_ratio": res.max_velocity_ratio,
        "closure_error_m": res.closure_error[0],
        "closure_error_rad": res.closure_error[1],
        "certificate_passed": None,
        "certificate_failures": [],
        "failures": list(res.failures),
    }
    run = Run("greedy", res.t, res.object_position, res.fingertip_position,
              res.eta_f[:, 0:2], grasp, res.cone_margin, res.q, summary)
    return run, res


# -- figures ----------------------------------------------------------------------------------

def new_figure(width: float, height: float) -> Figure:
    fig = Figure(figsize=(width, height), dpi=120, layout="constrained")
    FigureCanvasAgg(fig)  # headless: the Agg canvas, no pyplot, no display
    return fig


def mark_times(ax: Axes, run: Run, xy: FloatArray, times: Sequence[float],
               marker: str) -> None:
    idx = [int(np.argmin(np.abs(run.t - tk))) for tk in times]
    ax.plot(xy[idx, 0], xy[idx, 1], marker, color=COLORS[run.method], ms=5, ls="none")


def figure6(runs: dict[str, Run], path: Path) -> None:
    mm = 1e3
    tri = np.array(TRIANGLE_M) * mm
    fig = new_figure(11.0, 5.4)
    axes = fig.subplots(1, 2, sharex=True, sharey=True)
    for ax, method in zip(axes, METHODS, strict=True):
        run = runs[method]
        ball, tip = run.ball_centre[:, :2] * mm, run.fingertip[:, :2] * mm
        ax.plot(tri[:, 0], tri[:, 1], "k--", lw=1.2, label="desired ball centre (oabo)")
        ref = tip[0] + 2 * tri  # pure rolling on the ball's top: twice the ball's motion
        ax.plot(ref[:, 0], ref[:, 1], ":", color="0.45", lw=1.2,
                label="2 x triangle from the fingertip's start")
        ax.plot(ball[:, 0], ball[:, 1], color=COLORS[method], lw=1.6,
                label="ball centre (oabo)")
        ax.plot(tip[:, 0], tip[:, 1], color=COLORS[method], lw=2.4, alpha=0.55,
                label="fingertip pad centre (OABO)")
        mark_times(ax, run, ball, (0.0, *VIA_TIMES), "o")
        mark_times(ax, run, tip, (0.0, *VIA_TIMES), "s")
        for name, p in zip("oab", tri[:3], strict=True):
            ax.annotate(name, p, textcoords="offset points", xytext=(-10, -12))
        for name, p in zip("OAB", ref[:3], strict=True):
            ax.annotate(name, p, textcoords="offset points", xytext=(5, 5))
        ax.set_title(LABELS[method])
        ax.set_xlabel("palm x [mm]")
        ax.set_aspect("equal")
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("palm y [mm]")
    axes[0].legend(loc="upper left", fontsize=8)
    fig.suptitle("Experiment 1: ball centre and fingertip in the palm plane "
                 "(markers at t = 0, 2, 4 s)")
    fig.savefig(path)


def figure7(runs: dict[str, Run], half: float, margin: float, path: Path) -> None:
    mm = 1e3
    fig = new_figure(6.4, 6.0)
    ax = fig.subplots()
    h, hm = half * mm, (half - margin) * mm
    sq = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1], [-1, -1]], dtype=float)
    ax.fill(h * sq[:, 0], h * sq[:, 1], color="0.93", zorder=0)
    ax.plot(h * sq[:, 0], h * sq[:, 1], "k-", lw=1.2, label="pad outline")
    ax.plot(hm * sq[:, 0], hm * sq[:, 1], "k:", lw=0.8, label="pad margin")
    for method in METHODS:
        run = runs[method]
        pad = run.pad_contact * mm
        ax.plot(pad[:, 0], pad[:, 1], color=COLORS[method], lw=1.8, label=LABELS[method])
        mark_times(ax, run, pad, (0.0, *VIA_TIMES, DURATION), "o")
    ax.plot([0], [0], "k+", ms=10)
    ax.set_xlabel("pad $x_f$ [mm]")
    ax.set_ylabel("pad $y_f$ [mm]")
    ax.set_aspect("equal")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper right", fontsize=8)
    ax.set_title("Finger contact across the fingertip pad\n(markers at t = 0, 2, 4, 6 s)")
    fig.savefig(path)


def time_axes_decor(ax: Axes) -> None:
    for tv in VIA_TIMES:
        ax.axvline(tv, color="0.6", lw=0.8, ls=":")
    ax.set_xlim(0.0, DURATION)
    ax.grid(alpha=0.3)


def figure_grasp(runs: dict[str, Run], mu: float, path: Path) -> None:
    cone = math.degrees(math.atan(mu))
    fig = new_figure(8.0, 6.4)
    top, bottom = fig.subplots(2, 1, sharex=True)
    for method in METHODS:
        run = runs[method]
        deg = np.degrees(run.grasp)
        top.plot(run.t, deg, color=COLORS[method], label=LABELS[method])
        bottom.semilogy(run.t, np.maximum(deg, 1e-3), color=COLORS[method])
    for ax in (top, bottom):
        ax.axhline(cone, color="crimson", lw=1.2,
                   label=f"friction cone atan(mu) = {cone:.1f} deg (mu = {mu:g})")
        ax.axhline(1.0, color="0.3", lw=0.8, ls="--", label="1 deg")
        time_axes_decor(ax)
    top.set_ylim(0.0, cone * 1.1)
    top.set_ylabel("max($\\Phi_p$, $\\Phi_f$) [deg]")
    bottom.set_ylabel("[deg], log scale")
    bottom.set_xlabel("t [s]  (dotted: via-points)")
    top.legend(fontsize=8, loc="center right")
    top.set_title("Grasp angle (0: antipodal; force closure below atan(mu))")
    fig.savefig(path)


def figure_joints(runs: dict[str, Run], finger: FingerModel, path: Path) -> None:
    nq = finger.nq
    cols = 3
    rows = math.ceil(nq / cols)
    fig = new_figure(11.0, 3.2 * rows)
    axes = np.atleast_1d(fig.subplots(rows, cols, sharex=True)).ravel()
    for i in range(nq):
        ax = axes[i]
        for method in METHODS:
            run = runs[method]
            ax.plot(run.t, np.degrees(run.q[:, i]), color=COLORS[method],
                    ls="-" if method == "nlp" else "--", label=LABELS[method])
        ax.axhline(PAPER_SEED_DEG[i], color="0.5", lw=0.8, ls=":", label="paper's initial angle")
        ax.set_title(f"q{i + 1} ({finger.joint_names[i]})", fontsize=9)
        ax.set_ylabel("[deg]")
        time_axes_decor(ax)
    for ax in axes[nq:]:
        ax.set_visible(False)
    for ax in axes[(rows - 1) * cols:]:
        ax.set_xlabel("t [s]")
    axes[0].legend(fontsize=7)
    fig.suptitle("Finger joint angles (the paper's initial angles seed the initial grasp)")
    fig.savefig(path)


# -- report -----------------------------------------------------------------------------------

def fmt(value: Any, scale: float = 1.0, spec: str = ".3g") -> str:
    if value is None:
        return "-"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, str):
        return value
    if spec == "d":
        return str(int(value))
    return format(value * scale, spec)


TABLE_ROWS: tuple[tuple[str, str, float, str], ...] = (
    ("status", "status", 1.0, ""),
    ("build time [s]", "build_time_s", 1.0, ".2f"),
    ("solve time [s]", "solve_time_s", 1.0, ".2f"),
    ("wall time [s]", "wall_time_s", 1.0, ".2f"),
    ("IPOPT iterations", "iterations", 1.0, "d"),
    ("steps", "steps", 1.0, "d"),
    ("goal error (worst) [m]", "goal_error_m", 1.0, ".2g"),
    ("grasp angle start [deg]", "grasp_angle_start_rad", 180 / math.pi, ".2f"),
    ("grasp angle end [deg]", "grasp_angle_end_rad", 180 / math.pi, ".2f"),
    ("grasp angle max [deg]", "grasp_angle_max_rad", 180 / math.pi, ".2f"),
    ("time to < 1 deg [s]", "time_below_1deg_s", 1.0, ".2f"),
    ("max after < 1 deg [deg]", "grasp_angle_max_after_below_1deg_rad", 180 / math.pi,
     ".2f"),
    ("min cone margin [deg]", "min_cone_margin_rad", 180 / math.pi, ".2f"),
    ("pad excursion [mm]", "pad_excursion_m", 1e3, ".1f"),
    ("ball centre path [mm]", "ball_centre_path_length_m", 1e3, ".1f"),
    ("fingertip path [mm]", "fingertip_path_length_m", 1e3, ".1f"),
    ("contact path on pad [mm]", "pad_contact_path_length_m", 1e3, ".1f"),
    ("joint effort [rad^2/s]", "joint_effort_rad2_per_s", 1.0, ".3f"),
    ("max |q_dot|/limit", "max_joint_rate_ratio", 1.0, ".2f"),
    ("closure error [m]", "closure_error_m", 1.0, ".2g"),
    ("closure error [rad]", "closure_error_rad", 1.0, ".2g"),
    ("certificate passed", "certificate_passed", 1.0, ""),
)


def table(summary: dict[str, Any]) -> str:
    methods = summary["methods"]
    lines = [f"{'':28s}{'NLP':>14s}{'greedy':>14s}"]
    for label, key, scale, spec in TABLE_ROWS:
        cells = [fmt(methods[m].get(key), scale, spec) if spec else fmt(methods[m].get(key))
                 for m in METHODS]
        lines.append(f"{label:28s}" + "".join(f"{c:>14s}" for c in cells))
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> dict[str, Any]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else "")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT,
                        help=f"output folder (default: {DEFAULT_OUT})")
    args = parser.parse_args(argv)
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)

    problem = build_problem()
    finger = problem.finger
    nlp, _ = run_nlp(problem)
    greedy, _ = run_greedy(problem)
    runs = {"nlp": nlp, "greedy": greedy}

    figure6(runs, out / FIGURES[0])
    figure7(runs, float(finger.pad_half_size), problem.pad_margin, out / FIGURES[1])
    figure_grasp(runs, problem.mu, out / FIGURES[2])
    figure_joints(runs, finger, out / FIGURES[3])

    summary: dict[str, Any] = {
        "experiment": "paper's experiment 1: one flat fingertip rolling a ball on the palm",
        "setup": {
            "ball_radius_m": RHO,
            "palm_initial_eta_p": list(problem.base.initial),
            "triangle_m": [list(p) for p in TRIANGLE_M],
            "via_point_times_s": list(VIA_TIMES),
            "duration_s": DURATION,
            "n_intervals": N_INTERVALS,
            "finger_contact_initial": list(FINGER_CONTACT_INITIAL),
            "finger_chart_rotation_rad": list(FINGER_CHART_ROTATION),
            "q_seed_deg": list(PAPER_SEED_DEG),
            "mu": problem.mu,
            "pad_half_size_m": float(finger.pad_half_size),
            "pad_margin_m": problem.pad_margin,
            "weights": {"grasp": problem.grasp_weight,
                        "finger_effort": problem.finger_effort_weight,
                        "joint_effort": problem.joint_effort_weight},
            "greedy_steps": greedy.summary["steps"],
        },
        "methods": {"nlp": nlp.summary, "greedy": greedy.summary},
        "figures": list(FIGURES),
    }
    (out / SUMMARY).write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
    print(table(summary))
    print(f"wrote {', '.join(FIGURES)} and {SUMMARY} to {out}")
    return summary


if __name__ == "__main__":
    main()
