"""``dexroll simulate`` with disturbances and in closed loop (docs/simulation.md,
"Disturbances" and "Closed loop").

``--push``, ``--impulse``, ``--friction-scale``, ``--size-change``, ``--mass-scale`` and
``--pose-noise`` disturb an open-loop run as well as a closed-loop one; ``--closed-loop``
(with ``--request``: the plan is made again here, the controller needs the problem and
its NLP) runs a controller at ``--rate`` and the open-loop run on the same disturbances
beside it, and writes both to the report: by default the window controller
(:class:`ocp.WindowController`, 100 Hz, its latency charged in simulated time: the
simulation does not wait for it, docs/control.md), with ``--controller replan`` the
whole-remainder re-planner with MuJoCo paused at each call (4 Hz).

Exit codes: as ``dexroll simulate``; in closed loop 0 when the closed loop recovered (it
ends within the tolerances of the task's goal, 1 mm and 2 deg by default, with no
contact lost from 0.1 s after the last push on), 1 when it did not.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any

__all__ = ["add_arguments", "disturbances_of", "main", "wanted"]

EXIT_PASSED, EXIT_FAILED, EXIT_INVALID = 0, 1, 2


def add_arguments(parser: argparse.ArgumentParser) -> None:
    g = parser.add_argument_group("disturbances and closed loop")
    g.add_argument("--push", action="append", default=[], metavar="TIME,DX,DY,DZ",
                   help="displace the object by (DX, DY, DZ) metres in the palm frame at "
                        "TIME seconds (a kinematic shift: its position set, its velocity "
                        "kept); repeatable")
    g.add_argument("--impulse", action="append", default=[], metavar="TIME,PX,PY,PZ",
                   help="an impulse [N s] on the object at TIME (its velocity changed by "
                        "p / m); repeatable")
    g.add_argument("--friction-scale", type=float, metavar="S",
                   help="every contact's friction coefficient times S (the plan keeps "
                        "its own)")
    g.add_argument("--size-change", type=float, metavar="MM",
                   help="added to each of the object's semi-axes [mm] (a ball 1 mm "
                        "larger in diameter: 0.5)")
    g.add_argument("--mass-scale", type=float, metavar="S", help="the object's mass times S")
    g.add_argument("--pose-noise", metavar="MM,DEG",
                   help="standard deviations of the noise on the measured object pose "
                        "(closed loop)")
    g.add_argument("--seed", type=int, default=0, help="the noise's seed (default 0)")
    g.add_argument("--closed-loop", action="store_true",
                   help="control from the measured state at --rate (needs --request) and "
                        "compare with the open-loop run on the same disturbances")
    g.add_argument("--controller", choices=("window", "replan"), default="window",
                   help="window: a short window of the plan re-solved at every tick in "
                        "real time, its latency charged in simulated time (default); "
                        "replan: the rest of the motion re-planned with MuJoCo paused")
    g.add_argument("--backend", choices=("ipopt", "rti", "auto"), default="ipopt",
                   help="the window's solver: ipopt (IPOPT on the collocation window, "
                        "default), rti (real-time iterations by multiple shooting, QPs by "
                        "HPIPM, each tick linearised before its measurement), auto (the "
                        "faster of the two, measured before the run)")
    g.add_argument("--rate", type=float, default=None, metavar="HZ",
                   help="the controller's rate in simulated time (default 100 Hz for the "
                        "window, 4 Hz for the re-planner)")
    g.add_argument("--replan-iterations", type=int, default=None, metavar="N",
                   help="IPOPT iterations per tick (window, default 1) or per re-plan "
                        "(default 30)")
    g.add_argument("--compile-dir", default=None, metavar="DIR",
                   help="the window's NLP compiled to C and cached here (seconds of gcc "
                        "the first time; IPOPT faster per tick)")


def disturbances_of(args: argparse.Namespace) -> Any:
    """The :class:`sim.disturbances.Disturbances` of the command line (ValueError naming
    a bad one)."""
    from sim.disturbances import Disturbances, parse_kick

    noise = (0.0, 0.0)
    if args.pose_noise:
        parts = str(args.pose_noise).split(",")
        if len(parts) != 2:
            raise ValueError(f"--pose-noise {args.pose_noise!r}: expected MM,DEG")
        noise = (float(parts[0]) * 1e-3, math.radians(float(parts[1])))
    d = Disturbances(
        tuple(parse_kick(p) for p in args.push), tuple(parse_kick(p) for p in args.impulse),
        1.0 if args.friction_scale is None else args.friction_scale,
        0.0 if args.size_change is None else args.size_change * 1e-3,
        1.0 if args.mass_scale is None else args.mass_scale, noise, args.seed)
    d.check()
    return d


def wanted(args: argparse.Namespace) -> bool:
    """Whether the command line asks for a disturbance or the closed loop."""
    return bool(args.closed_loop or args.push or args.impulse or args.pose_noise
                or args.friction_scale is not None or args.size_change is not None
                or args.mass_scale is not None)


def _line(name: str, s: dict[str, Any]) -> str:
    lost = sum(v for v in s["contacts_lost_s"].values())
    ga = s.get("goal_angle_deg")
    goal = f"{s['goal_position_mm']:.3f} mm, " + ("orientation free" if ga is None
                                                  else f"{ga:.2f} deg")
    return (f"{name:<12} from the goal {goal}; from the plan: final "
            f"{s['position_final_mm']:.3f} mm, {s['angle_final_deg']:.2f} deg, worst "
            f"{s['position_worst_mm']:.3f} mm, {s['angle_worst_deg']:.2f} deg; contacts "
            f"lost {lost:.4g} s; recovered {'yes' if s['recovered'] else 'no'}")


def main(args: argparse.Namespace) -> int:
    from sim import SimOptions
    from sim.closed_loop import simulate_disturbed

    from ..plans import read_result
    from . import execution_plan
    from .command import input_error, input_errors, options_of, report_path, request_of

    path = Path(args.result)
    try:
        if getattr(args, "model", None) is not None:
            raise ValueError("--model: disturbances and the closed loop run on dexroll's "
                             "own scene only, not yet on a model of one's own")
        dist = disturbances_of(args)
        options = SimOptions.from_dict(options_of(args))
        window = args.controller == "window"
        rate = args.rate if args.rate is not None else 100.0 if window else 4.0
        iterations = args.replan_iterations if args.replan_iterations is not None \
            else 1 if window else 30
        if not (math.isfinite(rate) and rate > 0):
            raise ValueError("--rate must be positive")
        if iterations < 1:
            raise ValueError("--replan-iterations must be at least 1")
        request = request_of(args)
        if args.closed_loop and request is None:
            raise ValueError("--closed-loop needs the plan's --request (the re-planner "
                             "plans it again here)")
        if args.closed_loop:
            from ocp import ControllerOptions, ManipulationPlanner, ReplanOptions

            from .closed_loop import compare, first_plan

            first = first_plan(request)
            base = execution_plan(first.result, request)
            if window:
                planner = None if args.compile_dir is None else \
                    ManipulationPlanner(compile_dir=Path(args.compile_dir))
                data = compare(first, base, rate, options, dist,
                               control=ControllerOptions(max_iter=iterations,
                                                         backend=args.backend),
                               planner=planner)
            else:
                data = compare(first, base, rate, options, dist,
                               ReplanOptions(max_iter=iterations, time_limit=60.0))
        else:
            result, _ = read_result(path)
            report = simulate_disturbed(execution_plan(result, request), options, dist)
            data = {**report.to_dict(), "disturbances": dist.to_dict()}
    except input_errors() as exc:
        print(input_error(exc, args, "the request cannot be planned"), file=sys.stderr)
        return EXIT_INVALID
    _, out = report_path(args)
    out.write_text(json.dumps(data, indent=1) + "\n", encoding="utf-8")
    if not args.closed_loop:
        print(report.summary())
        print(f"report       {out}")
        return EXIT_PASSED if report.passed else EXIT_FAILED
    c = data["closed_loop"]["control"]
    print(_line("open loop", data["open_loop"]["summary"]))
    print(_line("closed loop", data["closed_loop"]["summary"]))
    med, factor = c["wall_time_median"], c["real_time_factor"]
    timing = "-" if med is None else f"{med * 1e3:.0f} ms ({factor:.2f} x the period)"
    if c.get("latency_charged"):
        cert = data["closed_loop"].get("certificates", {})
        p99 = c["wall_time_p99"]
        print(f"controller   window at {c['rate']:g} Hz, its latency charged in simulated "
              f"time: {c['ticks']} ticks {c['statuses']}, {c['overruns']} overruns; "
              f"tick wall time median {timing}, p99 "
              f"{'-' if p99 is None else f'{p99 * 1e3:.0f} ms'}; windows certified "
              f"{cert.get('certified')} of {cert.get('checked')}")
    else:
        print(f"controller   {c['rate']:g} Hz in simulated time, {c['calls']} calls "
              f"{c['statuses']}; re-plan wall time median {timing} (MuJoCo paused)")
    print(f"report       {out}")
    return EXIT_PASSED if data["closed_loop"]["summary"]["recovered"] else EXIT_FAILED
