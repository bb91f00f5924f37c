"""The paper's experiment 2: two flat fingertips manipulating a ball (section 5.2).

The desired motion is the paper's: rotate the ball about the palm's Z axis by 20 deg, then
about Y by 20 deg, then about Z by -20 deg, then about Y by -20 deg (1 s each here; the paper
gives no times), held in the air by the built-in two-finger hand (:mod:`ocp.robots.hands`: two
K3S-like fingers on opposite sides, pads pressing on the ball's +x and -x sides). The plan
comes from the general planner (:class:`ocp.solve.planner.ManipulationPlanner`), which tracks
the motion on SE(3) within 1 mm and 1 deg while keeping the grasp near antipodal.

Writes to ``--out`` (default ``docs/figures/``):

* ``fig9_positions.png``: the ball centre and both fingertips (pad centres, by Pinocchio's
  forward kinematics of the planned joint angles) in X, Y and Z over time, the desired ball
  centre dashed (the paper's figure 9);
* ``fig10_contacts_on_fingertips.png``: each contact's path across its pad, in pad
  coordinates (x_f, y_f), with the pad's outline (the paper's figure 10);
* ``exp2_tracking_and_grasp.png``: the ball's rotation from its start (planned and desired),
  the orientation tracking error and the grasp angle max(Phi_1, Phi_2) over time;
* ``experiment2_summary.json``: the numbers (SI units; key suffixes say which).

Run from the repository root: ``.venv/bin/python experiments/experiment2.py [--out DIR]``.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from numpy.typing import NDArray

from ocp.geometry.rotations import rotation_angle_between
from ocp.robots.hands import Hand, load_hand
from ocp.solve.planner import (
    DesiredMotion,
    ManipulationPlanner,
    ManipulationProblem,
    ManipulationSolution,
    MotionStep,
    ObjectPose,
    Tracking,
    hand_fingertips,
)
from ocp.spec.problem import ObjectSpec

FloatArray = NDArray[np.float64]

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_OUT = ROOT / "docs" / "figures"
DEG = math.pi / 180

#: The paper's sequence: (axis in the palm frame, angle) for 1 s each.
SEQUENCE = (((0.0, 0.0, 1.0), 20 * DEG), ((0.0, 1.0, 0.0), 20 * DEG),
            ((0.0, 0.0, 1.0), -20 * DEG), ((0.0, 1.0, 0.0), -20 * DEG))
STEP_DURATION = 1.0
N_INTERVALS = 40
MU = 0.5
POSITION_TOLERANCE = 1e-3  # m
ORIENTATION_TOLERANCE = 1 * DEG

FIGURES = ("fig9_positions.png", "fig10_contacts_on_fingertips.png",
           "exp2_tracking_and_grasp.png")
SUMMARY = "experiment2_summary.json"
COLORS = {"ball": "k", "f1": "tab:blue", "f2": "tab:orange"}


def build_problem(hand: Hand | None = None) -> ManipulationProblem:
    """Experiment 2 as this project sets it up (SI units, default objective weights)."""
    hand = hand or load_hand("two_finger")
    obj = ObjectSpec("sphere", (hand.nominal_radius,))
    start = ObjectPose(position=hand.nominal_object_position)
    steps = [MotionStep(STEP_DURATION, axis, angle) for axis, angle in SEQUENCE]
    motion = DesiredMotion.from_steps(start, steps)
    return ManipulationProblem(
        object=obj, fingers=hand_fingertips(hand, start, obj), duration=motion.times[-1],
        initial_pose=start, motion=motion, mu=MU, n_intervals=N_INTERVALS,
        tracking=Tracking(position_tolerance=POSITION_TOLERANCE,
                          orientation_tolerance=ORIENTATION_TOLERANCE))


def path_length(p: FloatArray) -> float:
    return float(np.sum(np.linalg.norm(np.diff(p, axis=0), axis=1)))


def new_figure(width: float, height: float) -> Figure:
    fig = Figure(figsize=(width, height), dpi=120, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def knots(ax: Any, problem: ManipulationProblem) -> None:
    assert problem.motion is not None
    for tk in problem.motion.times[1:-1]:
        ax.axvline(tk, color="0.8", lw=0.8, zorder=0)


def figure9(problem: ManipulationProblem, sol: ManipulationSolution, tips: FloatArray,
            path: Path) -> None:
    mm = 1e3
    fig = new_figure(10.0, 7.5)
    axes = fig.subplots(3, 1, sharex=True)
    _, pd = problem.motion.at(sol.t)  # type: ignore[union-attr]
    for j, (ax, label) in enumerate(zip(axes, "XYZ", strict=True)):
        ax.plot(sol.t, sol.object_position[:, j] * mm, color=COLORS["ball"], label="ball centre")
        ax.plot(sol.t, pd[:, j] * mm, color=COLORS["ball"], ls="--", lw=0.9,
                label="desired ball centre")
        for k, f in enumerate(sol.fingers):
            ax.plot(sol.t, tips[k][:, j] * mm, color=COLORS[f.name], label=f"fingertip {f.name}")
        ax.set_ylabel(f"{label} [mm]")
        knots(ax, problem)
        ax.grid(True, lw=0.3)
    axes[0].legend(loc="upper right", fontsize=8, ncols=4)
    axes[-1].set_xlabel("t [s]")
    fig.suptitle("Experiment 2: ball and fingertip positions (palm frame; cf. the paper's fig. 9)")
    fig.savefig(path)


def figure10(problem: ManipulationProblem, sol: ManipulationSolution, path: Path) -> None:
    mm = 1e3
    fig = new_figure(10.0, 5.0)
    axes = fig.subplots(1, len(sol.contacts), sharex=True, sharey=True)
    reach = max(float(np.max(np.abs(c.eta[:, 0:2]))) for c in sol.contacts) * mm + 5.0
    for ax, c, tip in zip(axes, sol.contacts, problem.fingers, strict=True):
        half = float(tip.finger.pad_half_size) * mm
        usable = half - problem.pad_margin * mm
        ax.plot([-half, half, half, -half, -half], [-half, -half, half, half, -half],
                color="0.4", lw=1.0, label="pad edge")
        ax.plot([-usable, usable, usable, -usable, -usable],
                [-usable, -usable, usable, usable, -usable], color="0.7", lw=0.8, ls=":",
                label="pad margin")
        ax.plot(c.eta[:, 0] * mm, c.eta[:, 1] * mm, color=COLORS[c.name], label="contact path")
        ax.plot(c.eta[0, 0] * mm, c.eta[0, 1] * mm, "o", color=COLORS[c.name], ms=5,
                label="start")
        ax.plot(c.eta[-1, 0] * mm, c.eta[-1, 1] * mm, "s", color=COLORS[c.name], ms=5,
                label="end")
        ax.set_xlim(-reach, reach)
        ax.set_ylim(-reach, reach)
        ax.set_title(f"fingertip {c.name} (pad +-{half:.0f} mm)")
        ax.set_xlabel("x_f [mm] (pad x: up at the start)")
        ax.set_aspect("equal")
        ax.grid(True, lw=0.3)
    axes[0].set_ylabel("y_f [mm]")
    axes[0].legend(loc="lower left", fontsize=8)
    fig.suptitle("Experiment 2: contact paths on the fingertips (cf. the paper's fig. 10)")
    fig.savefig(path)


def figure_tracking(problem: ManipulationProblem, sol: ManipulationSolution,
                    path: Path) -> None:
    fig = new_figure(10.0, 6.0)
    axes = fig.subplots(2, 1, sharex=True)
    Rd, _ = problem.motion.at(sol.t)  # type: ignore[union-attr]
    R0 = np.tile(sol.object_rotation[0], (len(sol.t), 1, 1))
    axes[0].plot(sol.t, np.degrees(rotation_angle_between(R0, sol.object_rotation)), "k",
                 label="planned")
    axes[0].plot(sol.t, np.degrees(rotation_angle_between(R0, Rd)), "k--", lw=0.9,
                 label="desired")
    axes[0].set_ylabel("rotation from start [deg]")
    axes[0].legend(fontsize=8)
    assert sol.tracking_angle_error is not None
    axes[1].plot(sol.t, np.degrees(sol.tracking_angle_error), color="tab:red",
                 label="orientation tracking error")
    axes[1].plot(sol.t, np.degrees(sol.grasp_angle), color="tab:green",
                 label="grasp angle max(Phi_1, Phi_2)")
    axes[1].axhline(np.degrees(ORIENTATION_TOLERANCE), color="tab:red", ls=":", lw=0.8,
                    label="tolerance")
    axes[1].set_ylabel("[deg]")
    axes[1].set_xlabel("t [s]")
    axes[1].legend(fontsize=8)
    for ax in axes:
        knots(ax, problem)
        ax.grid(True, lw=0.3)
    fig.suptitle("Experiment 2: tracking on SE(3) and grasp quality")
    fig.savefig(path)


def main(argv: Sequence[str] | None = None) -> dict[str, Any]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else "")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT,
                        help=f"output folder (default: {DEFAULT_OUT})")
    args = parser.parse_args(argv)
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)

    hand = load_hand("two_finger")
    problem = build_problem(hand)
    t0 = time.perf_counter()
    sol = ManipulationPlanner().solve(problem)
    wall = time.perf_counter() - t0
    tips = np.array([[tip.finger.fingertip_pose_pin(q)[1] for q in f.q]
                     for tip, f in zip(problem.fingers, sol.fingers, strict=True)])
    figure9(problem, sol, tips, out / FIGURES[0])
    figure10(problem, sol, out / FIGURES[1])
    figure_tracking(problem, sol, out / FIGURES[2])

    cert = sol.certificate
    assert sol.tracking_position_error is not None and sol.tracking_angle_error is not None
    summary: dict[str, Any] = {
        "experiment": "paper's experiment 2: two flat fingertips manipulating a ball",
        "setup": {
            "hand": hand.name,
            "ball_radius_m": hand.nominal_radius,
            "ball_centre_m": list(hand.nominal_object_position),
            "sequence_axis_angle_rad": [[list(a), ang] for a, ang in SEQUENCE],
            "step_duration_s": STEP_DURATION,
            "n_intervals": N_INTERVALS,
            "mu": MU,
            "position_tolerance_m": POSITION_TOLERANCE,
            "orientation_tolerance_rad": ORIENTATION_TOLERANCE,
            "pad_half_size_m": hand.pad_half_size,
        },
        "status": sol.status.value,
        "message": sol.message,
        "iterations": sol.iterations,
        "refinements": sol.refinements,
        "build_time_s": sol.build_time,
        "solve_time_s": sol.ipopt_time,
        "wall_time_s": wall,
        "max_tracking_position_error_m": float(sol.tracking_position_error.max()),
        "max_tracking_angle_error_rad": float(sol.tracking_angle_error.max()),
        "max_rotation_from_start_rad": float(np.max(rotation_angle_between(
            np.tile(sol.object_rotation[0], (len(sol.t), 1, 1)), sol.object_rotation))),
        "max_grasp_angle_rad": float(sol.grasp_angle.max()),
        "min_cone_margin_rad": float(sol.cone_margin.min()),
        "fingers": {
            f.name: {
                "fingertip_path_length_m": path_length(tips[k]),
                "pad_contact_path_length_m": path_length(c.eta[:, 0:2]),
                "pad_excursion_m": float(np.max(np.abs(c.eta[:, 0:2]))),
                "joint_range_rad": (f.q.max(axis=0) - f.q.min(axis=0)).tolist(),
                "max_slip_speed_m_per_s": cert.get(f"max_slip_speed_{f.name}"),
            }
            for k, (f, c) in enumerate(zip(sol.fingers, sol.contacts, strict=True))},
        "closure_error_m": cert.get("max_closure_position_error"),
        "closure_error_rad": cert.get("max_closure_orientation_error"),
        "certificate_passed": bool(cert) and not sol.certificate_failures,
        "certificate_failures": list(sol.certificate_failures),
        "figures": list(FIGURES),
    }
    (out / SUMMARY).write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
    print(f"{sol.status.value}: {sol.message}")
    print(f"tracking <= {summary['max_tracking_position_error_m'] * 1e3:.3g} mm, "
          f"{math.degrees(summary['max_tracking_angle_error_rad']):.3g} deg; grasp angle <= "
          f"{math.degrees(summary['max_grasp_angle_rad']):.3g} deg; build "
          f"{sol.build_time:.2f} s, solve {sol.ipopt_time:.2f} s, {sol.iterations} iterations")
    print(f"wrote {', '.join(FIGURES)} and {SUMMARY} to {out}")
    return summary


if __name__ == "__main__":
    main()
