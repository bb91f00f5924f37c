"""``dexroll simulate RESULT.json``: execute a plan in MuJoCo, write a JSON report and a
plot of the object's errors over time (docs/simulation.md).

RESULT.json is a result as ``dexroll plan`` writes it, or a job as ``GET /v1/plans/{id}``
answers it. ``--request`` names the plan's request: its object, fingers and friction are
then used; without it they are inferred from the result as the viewer does (built-in
fingers and hands matched by their pad poses, mu from the plan's friction cone).

Exit codes: 0 the execution passed its tolerances, 1 it failed them, 2 the files cannot
be read, hold no plan a hand executes, or an option is out of range.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from pydantic import ValidationError

__all__ = ["add_arguments", "input_error", "input_errors", "main", "options_of",
           "report_path", "request_of"]

EXIT_PASSED, EXIT_FAILED, EXIT_INVALID = 0, 1, 2


def input_errors() -> tuple[type[Exception], ...]:
    """What a command's input may raise: each an exit 2 with :func:`input_error`'s line
    (imported when one is raised: the command line starts without the planners)."""
    from ..planners import ProblemError
    from . import NotExecutableError

    return (ValidationError, ProblemError, OSError, ValueError, NotExecutableError)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("result", help="a result file (dexroll plan) or a job's JSON "
                                       "(GET /v1/plans/{id})")
    parser.add_argument("--request", metavar="REQUEST.json",
                        help="the plan's request: its own object, fingers and friction "
                             "(default: inferred from the result)")
    parser.add_argument("-o", "--output",
                        help="the JSON report (default: ./<result>.sim.json)")
    parser.add_argument("--plot", help="the errors over time as a PNG (default: "
                                       "./<result>.sim.png; 'none': no plot)")
    parser.add_argument("--mode", choices=("servo", "kinematic", "replay"),
                        help="servo (default): the joints follow the plan through their "
                             "servos; kinematic: the joints are set to the plan; replay: "
                             "the object too (nothing simulated)")
    parser.add_argument("--squeeze", type=float, metavar="MM",
                        help="how far the fingertips' references go into the object "
                             "[mm] (default 0.5)")
    parser.add_argument("--force-control", choices=("off", "pi", "admittance"),
                        help="admittance: contact-force feedback on the plan's forces "
                             "as a shift of the servo's set point (a gait's default); pi: "
                             "the same feedback as joint torques; off: the planned forces "
                             "fed forward only (every other plan's default)")
    parser.add_argument("--grip-force", type=float, metavar="N",
                        help="each fingertip's push along its normal as torque "
                             "feed-forward [N] (default 1)")
    parser.add_argument("--kp", type=float, help="servo stiffness [N m/rad] (default 200)")
    parser.add_argument("--kv", type=float, help="servo damping [N m s/rad] (default 2)")
    parser.add_argument("--mass", type=float, metavar="KG",
                        help="the object's mass [kg] (default: the plan's, else 0.05)")
    parser.add_argument("--model", metavar="FILE",
                        help="execute on this MJCF hand model (its bodies, masses, "
                             "actuators, contact settings; meshes stripped), its fingertips "
                             "named as in --request's hand; 'request': the request's own "
                             "hand.mjcf")
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                        help="any other option of sim.SimOptions (JSON value), e.g. "
                             "--set condim=6 --set timestep=0.001")
    from . import loop_command

    loop_command.add_arguments(parser)


def options_of(args: argparse.Namespace) -> dict[str, Any]:
    """The simulator's options from the command line (ValueError for a bad --set)."""
    out: dict[str, Any] = {}
    for item in args.set:
        name, sep, value = item.partition("=")
        if not sep:
            raise ValueError(f"--set {item!r}: expected NAME=VALUE")
        try:
            out[name.strip()] = json.loads(value)
        except json.JSONDecodeError:
            out[name.strip()] = value
    if args.mode:
        out["mode"] = args.mode
    if args.squeeze is not None:
        out["squeeze"] = args.squeeze * 1e-3
    if args.force_control is not None:
        out["force_control"] = args.force_control
    if args.grip_force is not None:
        out["grip_force"] = args.grip_force
    if args.kp is not None:
        out["kp"] = args.kp
    if args.kv is not None:
        out["kv"] = args.kv
    if args.mass is not None:
        out["object_mass"] = args.mass
    return out


def request_of(args: argparse.Namespace) -> Any:
    """The plan's request from ``--request`` (None without it); pydantic's
    ValidationError, OSError or ValueError when it cannot be read (:func:`input_errors`)."""
    if not args.request:
        return None
    from ..planners import REQUEST

    return REQUEST.validate_python(json.loads(Path(args.request).read_text(encoding="utf-8")))


def input_error(exc: Exception, args: argparse.Namespace, unplannable: str) -> str:
    """The line that says why the command's input cannot be executed (one of
    :func:`input_errors`; ``unplannable``: what a ProblemError means here)."""
    from ..planners import ProblemError, validation_errors

    if isinstance(exc, ValidationError):
        reasons = "; ".join(f"{f}: {r}" for f, r in validation_errors(exc)[:5])
        return f"{args.request} is not a valid request: {reasons}"
    if isinstance(exc, ProblemError):
        return f"{unplannable}: {exc.errors}"
    return str(exc)


def report_path(args: argparse.Namespace) -> tuple[str, Path]:
    """(the result file's stem, the report's path: ``-o`` or ``<stem>.sim.json``)."""
    stem = Path(args.result).name.removesuffix(".json")
    return stem, Path(args.output) if args.output else Path(f"{stem}.sim.json")


def main(args: argparse.Namespace) -> int:
    try:
        from sim import plot
    except ImportError as exc:  # mujoco: the sim extra
        print(f"simulation needs MuJoCo: pip install 'dexroll[sim]' ({exc})", file=sys.stderr)
        return EXIT_INVALID
    from . import loop_command

    if loop_command.wanted(args):  # disturbances, the closed loop
        return loop_command.main(args)

    from ..plans import read_result
    from . import simulate_result

    path = Path(args.result)
    try:
        result, _ = read_result(path)
        request = request_of(args)
        model = getattr(args, "model", None)
        if model is not None and model != "request":
            model = Path(model).read_text(encoding="utf-8")
        report = simulate_result(result, request, options_of(args), model)
    except input_errors() as exc:
        print(input_error(exc, args, "the request's models cannot be loaded"),
              file=sys.stderr)
        return EXIT_INVALID
    stem, out = report_path(args)
    data = report.to_dict()
    out.write_text(json.dumps(data, indent=1) + "\n", encoding="utf-8")
    print(report.summary())
    print(f"report       {out}")
    if (args.plot or "").lower() != "none":
        figure = Path(args.plot) if args.plot else Path(f"{stem}.sim.png")
        try:
            plot(data, figure, stem)
            print(f"plot         {figure}")
        except ImportError:
            print("plot         not drawn: matplotlib is missing (pip install "
                  "'dexroll[figures]')", file=sys.stderr)
    return EXIT_PASSED if report.passed else EXIT_FAILED
