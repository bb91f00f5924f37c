"""Command line: ``dexroll serve``, ``dexroll plan request.json``, ``dexroll demo [folder]``,
``dexroll bench SUITE`` (docs/benchmarks.md), ``dexroll view RESULT.json`` (docs/viewer.md),
``dexroll simulate RESULT.json`` (the plan executed in MuJoCo: docs/simulation.md),
``dexroll batch REQUESTS.jsonl`` (many requests on a running service: docs/service.md).

A request file is any planner's request (its ``planner`` field: ``ball_on_palm``, the
default, ``one_finger`` or ``manipulation``), the same JSON as ``POST /v1/plans`` takes.
``dexroll plan request.json --warm-start previous.result.json`` starts the solver from a
previous plan (a result file as ``dexroll plan`` writes it: its ``collocation`` block).

Exit codes: 0 the plan is solved (certificate passed), 1 a plan was computed but is not
solved (see its status), 2 the request is invalid (each bad field is named on stderr).
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from pathlib import Path

from pydantic import ValidationError

from dexroll_client.models import AnyPlanResult, PlanStatus

from . import batch_command
from .bench import command as bench_command
from .execution import command as simulate_command
from .planners import (
    REQUEST,
    RESULT,
    Planners,
    ProblemError,
    adapter_for,
    error_result,
    invalid_result,
    planner_of,
    request_errors,
    validation_errors,
)
from .view import command as view_command

__all__ = ["main", "plan_request", "with_warm_start"]

EXIT_SOLVED, EXIT_NOT_SOLVED, EXIT_INVALID = 0, 1, 2
log = logging.getLogger("dexroll")


def plan_request(raw: object) -> tuple[AnyPlanResult, str]:
    """Validate and plan a decoded JSON request: (result, one-screen summary)."""
    planner = planner_of(raw)
    try:
        request = REQUEST.validate_python(raw)
    except ValidationError as exc:
        result = invalid_result(validation_errors(exc), planner)
        return result, _invalid_summary(result)
    errors = request_errors(request)
    if errors:
        result = invalid_result(errors, planner)
        return result, _invalid_summary(result)
    adapter = adapter_for(request)
    try:
        result, solution = adapter.solve(request, Planners())
    except ProblemError as exc:
        result = invalid_result(exc.errors, planner)
        return result, _invalid_summary(result)
    except Exception as exc:  # a failure is a typed result, never a traceback
        log.exception("planner failed")
        result = error_result(f"planner failed: {exc!r}", planner)
        return result, f"status       error\nmessage      {result.message}"
    return result, adapter.summary(result, solution)


def _invalid_summary(result: AnyPlanResult) -> str:
    lines = ["status       invalid_input"]
    lines += [f"  {e.field}: {e.reason}" for e in result.errors]
    return "\n".join(lines)


def _read(path: Path) -> tuple[object | None, AnyPlanResult | None]:
    try:
        return json.loads(path.read_text()), None
    except (OSError, UnicodeDecodeError) as exc:
        return None, invalid_result([("request", f"cannot read {path}: {exc}")])
    except json.JSONDecodeError as exc:
        return None, invalid_result([("request", f"{path} is not valid JSON: {exc}")])


def _exit_code(result: AnyPlanResult) -> int:
    if result.status is PlanStatus.INVALID_INPUT:
        return EXIT_INVALID
    return EXIT_SOLVED if result.status is PlanStatus.SOLVED else EXIT_NOT_SOLVED


def with_warm_start(raw: object, path: Path) -> tuple[object, AnyPlanResult | None]:
    """The decoded request ``raw`` with the plan of the result file ``path`` (its
    ``collocation`` block) as its ``warm_start``; or the invalid result saying why not."""
    planner = planner_of(raw)
    previous, failed = _read(path)
    if failed is not None:
        return raw, invalid_result([("warm_start", failed.errors[0].reason)], planner)
    try:
        result = RESULT.validate_python(previous)
    except ValidationError as exc:
        reason = f"{path} is not a result file: {validation_errors(exc)[0][1]}"
        return raw, invalid_result([("warm_start", reason)], planner)
    if result.planner != planner:
        return raw, invalid_result([("warm_start", f"{path} is a {result.planner} plan; the "
                                                   f"request is for the {planner} planner")],
                                   planner)
    if result.collocation is None:
        return raw, invalid_result([("warm_start", f"{path} holds no plan at its collocation "
                                                   f"points (status {result.status.value})")],
                                   planner)
    if not isinstance(raw, dict):  # the request's own validation says what is wrong
        return raw, None
    return {**raw, "warm_start": result.collocation.model_dump(mode="json")}, None


def _cmd_plan(args: argparse.Namespace) -> int:
    path = Path(args.request)
    raw, failed = _read(path)
    if failed is None and args.warm_start:
        raw, failed = with_warm_start(raw, Path(args.warm_start))
    if failed is not None:
        result, summary = failed, _invalid_summary(failed)
    else:
        result, summary = plan_request(raw)
    out = Path(args.output) if args.output else Path(f"{path.stem}.result.json")
    out.write_text(result.model_dump_json(indent=1))
    stream = sys.stderr if result.status is PlanStatus.INVALID_INPUT else sys.stdout
    print(f"{path}:\n{summary}\nresult       {out}", file=stream)
    return _exit_code(result)


def _cmd_demo(args: argparse.Namespace) -> int:
    folder = Path(args.folder)
    files = sorted(folder.glob("*.json"))
    if not files:
        print(f"no request files (*.json) in {folder}", file=sys.stderr)
        return EXIT_INVALID
    worst = EXIT_SOLVED
    for path in files:
        raw, failed = _read(path)
        result, summary = (failed, _invalid_summary(failed)) if failed else plan_request(raw)
        print(f"== {path.name}\n{summary}\n")
        worst = max(worst, _exit_code(result))
    return worst


def _cmd_serve(args: argparse.Namespace) -> int:
    import uvicorn

    from .api.app import create_app
    from .settings import Settings

    overrides = {k: v for k, v in (("host", args.host), ("port", args.port),
                                   ("data_dir", args.data_dir), ("workers", args.workers))
                 if v is not None}
    if args.ray is not None:  # the solver workers as actors on this Ray cluster
        overrides.update(executor="ray", ray_address=args.ray)
    settings = Settings(**overrides)
    logging.basicConfig(level=settings.log_level.upper(),
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    log.info("dexroll service on http://%s:%d (data in %s, %d workers, %s)", settings.host,
             settings.port, settings.data_dir, settings.workers,
             "local processes" if settings.executor == "local" else
             f"Ray actors on {settings.ray_address}")
    if not settings.keys() and settings.host not in ("127.0.0.1", "localhost", "::1"):
        log.warning("*** NO API KEYS: anyone who reaches %s:%d can plan, read and cancel "
                    "every job. Set DEXROLL_API_KEYS (or DEXROLL_API_KEYS_FILE), or bind "
                    "127.0.0.1 (README: Configuration, Docker) ***", settings.host,
                    settings.port)
    # idle connections kept 15 s: longer than any Retry-After the service sends (<= 2 s),
    # so that a client retrying after one does not race the server closing its connection
    uvicorn.run(create_app(settings), host=settings.host, port=settings.port,
                log_level=settings.log_level.lower(), timeout_keep_alive=15)
    return 0


def _cmd_openapi(args: argparse.Namespace) -> int:
    from .api.app import create_app
    from .settings import Settings

    print(json.dumps(create_app(Settings()).openapi(), indent=1, sort_keys=True))
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="dexroll", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("plan", help="solve a request file, write the result as JSON")
    p.add_argument("request", help="request JSON file (SI units)")
    p.add_argument("-o", "--output", help="result file (default: ./<request>.result.json)")
    p.add_argument("--warm-start", metavar="RESULT.json",
                   help="start the solver from a previous plan: a result file of the same "
                        "planner as this command writes it (its `collocation` block "
                        "replaces the request's `warm_start`)")
    p.set_defaults(func=_cmd_plan)
    d = sub.add_parser("demo", help="plan every request in a folder and print summaries")
    d.add_argument("folder", nargs="?", default="examples")
    d.set_defaults(func=_cmd_demo)
    v = sub.add_parser("serve", help="run the planning service (settings: DEXROLL_* "
                                     "environment variables; flags override them)")
    v.add_argument("--host")
    v.add_argument("--port", type=int)
    v.add_argument("--data-dir")
    v.add_argument("--workers", type=int)
    v.add_argument("--ray", metavar="ADDRESS", nargs="?", const="auto",
                   help="run the solver workers as actors on the Ray cluster at ADDRESS "
                        "(default 'auto': the one this machine joined with `ray start`); "
                        "needs the distributed extra (pip install 'dexroll[distributed]')")
    v.set_defaults(func=_cmd_serve)
    o = sub.add_parser("openapi", help="print the service's OpenAPI document (the contract "
                                       "committed as openapi.json)")
    o.set_defaults(func=_cmd_openapi)
    b = sub.add_parser("bench", help="run a benchmark suite (quick, full or a suite file) "
                                     "and write a report (docs/benchmarks.md)")
    bench_command.add_arguments(b)
    b.set_defaults(func=bench_command.main)
    w = sub.add_parser("view", help="write a plan's animated 3D view as one standalone "
                                    "HTML file (docs/viewer.md)")
    view_command.add_arguments(w)
    w.set_defaults(func=view_command.main)
    s = sub.add_parser("simulate", help="execute a plan in MuJoCo: a JSON report of how "
                                        "closely the object followed it and a plot "
                                        "(docs/simulation.md)")
    simulate_command.add_arguments(s)
    s.set_defaults(func=simulate_command.main)
    m = sub.add_parser("batch", help="plan many requests (a JSON a line) on a running "
                                     "service as one batch, with a progress bar "
                                     "(docs/service.md)")
    batch_command.add_arguments(m)
    m.set_defaults(func=batch_command.main)
    args = parser.parse_args(argv)
    return int(args.func(args))


if __name__ == "__main__":
    sys.exit(main())
