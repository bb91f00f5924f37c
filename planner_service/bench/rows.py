"""One row of results per (problem, method): built from a wire result (library or service)
or a peer's outcome, and run in-process by :func:`run_unit` (a pool worker, a Ray actor).

A row is a flat JSON dict (see ``FIELDS``); ``certificate`` holds every value of the
result's certificate, the ``cert_*`` fields the residuals the report compares across
planners (worst over contacts). Rows of the same unit agree whichever way they were run,
except in the ``VOLATILE`` fields (times, which process ran it, its memory).
"""

from __future__ import annotations

import importlib
import math
import os
import resource
import sys
import time
from collections.abc import Callable, Mapping
from typing import Any

from .suite import PEER_METHODS, Unit

__all__ = [
    "FIELDS",
    "VOLATILE",
    "comparable",
    "differences",
    "error_row",
    "execute",
    "peer_status",
    "row_from_peer",
    "row_from_result",
    "run_unit",
]

#: The columns of a row, in CSV order (``certificate``: a dict, JSON only; ``failures``: a
#: list, joined with "; " in the CSV).
FIELDS: tuple[str, ...] = (
    "family", "problem_id", "method", "planner", "expected", "status", "certificate_passed",
    "ok", "solve_time", "build_time", "wall_time", "iterations", "refinements",
    "n_intervals", "solver", "goal_error_max", "turn_asked_deg", "turn_made_deg",
    "cert_slip_speed_max", "cert_spin_rate_max",
    "cert_closure_position_max", "cert_closure_orientation_max", "cert_position_defect_max",
    "cert_angle_defect_max", "cert_cone_margin_min", "failures", "message", "worker_pid",
    "peak_rss_mb", "exec_status", "exec_position_error_max", "exec_angle_error_max",
    "exec_contacts_lost", "exec_wall_time", "exec_message", "certificate")
#: Fields that depend on the run, not on the problem: left out when rows are compared. The
#: execution's numbers are a physics simulation of the plan: round-off differences between
#: two runs' plans may move them a little (its pass or fail, ``exec_status``, is compared).
VOLATILE: frozenset[str] = frozenset({"solve_time", "build_time", "wall_time", "worker_pid",
                                      "peak_rss_mb", "exec_position_error_max",
                                      "exec_angle_error_max", "exec_contacts_lost",
                                      "exec_wall_time", "exec_message"})
#: Plans of these planners have fingers: a solved one is executed in MuJoCo
#: (docs/simulation.md) when MuJoCo is installed and ``DEXROLL_BENCH_EXECUTE`` is not "0".
EXECUTED_PLANNERS = ("one_finger", "manipulation")

#: certificate residual field -> (how to combine, certificate keys it takes, by prefix).
_RESIDUALS: dict[str, tuple[Callable[..., float], tuple[str, ...]]] = {
    "cert_slip_speed_max": (max, ("max_slip_speed",)),
    "cert_spin_rate_max": (max, ("max_spin_rate",)),
    "cert_closure_position_max": (max, ("max_closure_position_error",)),
    "cert_closure_orientation_max": (max, ("max_closure_orientation_error",)),
    "cert_position_defect_max": (max, ("max_position_defect", "max_length_defect")),
    "cert_angle_defect_max": (max, ("max_angle_defect",)),
    "cert_cone_margin_min": (min, ("min_cone_margin",)),
}


def _finite(x: Any) -> float | None:
    try:
        v = float(x)
    except (TypeError, ValueError):
        return None
    return v if math.isfinite(v) else None


def residuals(values: Mapping[str, float]) -> dict[str, float | None]:
    """The ``cert_*`` fields of a certificate's values (None when it has no such check)."""
    out: dict[str, float | None] = {}
    for name, (combine, prefixes) in _RESIDUALS.items():
        found = [f for k, v in values.items()
                 if k.startswith(prefixes) and (f := _finite(v)) is not None]
        out[name] = combine(found) if found else None
    return out


def _peak_rss_mb() -> float:
    """Peak resident memory of this process [MiB] (ru_maxrss: KiB on Linux, B on macOS)."""
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return rss / (1024.0 * 1024.0) if sys.platform == "darwin" else rss / 1024.0


def _solver(unit: Unit, stats: Any) -> str | None:
    """The NLP solver of a result: its stats' ``solver`` where the planner reports one (the
    manipulation planner), else IPOPT, which every other planner of ours solves with; the
    greedy method solves no NLP."""
    if unit.method == "greedy":
        return None
    return getattr(stats, "solver", None) or "ipopt"


def _base(unit: Unit) -> dict[str, Any]:
    row: dict[str, Any] = dict.fromkeys(FIELDS)
    row.update(family=unit.family, problem_id=unit.problem_id, method=unit.method,
               planner=unit.planner, expected=unit.expected, certificate={}, failures=[],
               certificate_passed=False, ok=False)
    return row


def error_row(unit: Unit, status: str, message: str, wall_time: float | None = None,
              worker_pid: int | None = None, peak_rss_mb: float | None = None
              ) -> dict[str, Any]:
    """A row for a unit that produced no plan (invalid request, a crash, a dead worker)."""
    row = _base(unit)
    row.update(status=status, message=message, wall_time=wall_time, worker_pid=worker_pid,
               peak_rss_mb=peak_rss_mb)
    return row


def row_from_result(unit: Unit, result: Any, wall_time: float | None,
                    worker_pid: int | None, peak_rss_mb: float | None) -> dict[str, Any]:
    """The row of a wire result of any planner (``dexroll_client.models``)."""
    row = _base(unit)
    row.update(status=str(result.status.value), message=result.message,
               wall_time=wall_time, worker_pid=worker_pid, peak_rss_mb=peak_rss_mb)
    if result.errors:
        row["failures"] = [f"{e.field}: {e.reason}" for e in result.errors]
    stats = result.stats
    if stats is not None:
        row.update(solve_time=_finite(stats.solve_time), build_time=_finite(stats.build_time),
                   iterations=int(stats.iterations),
                   refinements=int(getattr(stats, "refinements", 0) or 0),
                   n_intervals=getattr(stats, "n_intervals", None),
                   solver=_solver(unit, stats))
    if result.goal_error:
        row["goal_error_max"] = _finite(max(result.goal_error.values()))
    gait = getattr(result, "gait", None)
    if gait is not None:  # a gait: the turn asked (its one rotation step) and made
        step = unit.request["motion"]["steps"][0]
        row.update(turn_asked_deg=math.degrees(float(step["angle"])),
                   turn_made_deg=math.degrees(float(gait.turned)))
    cert = result.certificate
    if cert is not None:
        values = getattr(cert, "values", None)
        if values is None:  # a ball-on-palm certificate: named fields
            values = {k: v for k in ("max_position_defect", "max_angle_defect",
                                     "max_slip_speed", "max_spin_rate", "max_height_error",
                                     "max_goal_error")
                      if (v := getattr(cert, k)) is not None}
        values = {k: float(v) for k, v in values.items()}
        row.update(certificate=values, certificate_passed=bool(cert.passed),
                   failures=list(cert.failures))
        row.update(residuals(values))
    row["ok"] = row["status"] == "solved" and row["certificate_passed"]
    if row["ok"] and unit.planner in EXECUTED_PLANNERS:
        row.update(execute(unit, result))
    return row


def execute(unit: Unit, result: Any) -> dict[str, Any]:
    """The ``exec_*`` fields of a solved plan executed in MuJoCo with the simulator's
    defaults (docs/simulation.md; a plan with forces on its own forces alone):
    ``exec_status`` 'passed' or 'failed' (its tolerances: 1 mm, 2 deg, no contact lost), or
    'error' (``exec_message`` says why); none when MuJoCo is not installed or
    ``DEXROLL_BENCH_EXECUTE=0``. Never raises."""
    if os.environ.get("DEXROLL_BENCH_EXECUTE", "1") == "0":
        return {}
    try:
        importlib.import_module("mujoco")
    except ImportError:
        return {}
    t0 = time.perf_counter()
    try:
        from planner_service.execution import simulate_result
        from planner_service.planners import REQUEST

        # a plan with its own forces is executed on them alone (no squeeze or grip of the
        # simulator's own; a gait with its own squeeze, docs/gait.md); one without, with
        # the simulator's grip
        own = None
        if unit.request.get("forces"):
            own = {"grip_force": 0.0} if unit.request.get("gait") else \
                {"squeeze": 0.0, "grip_force": 0.0}
        report = simulate_result(result, REQUEST.validate_python(unit.request), own)
    except Exception as exc:  # a failure is a row's field, never a crash of the benchmark
        return {"exec_status": "error", "exec_message": f"{type(exc).__name__}: {exc}",
                "exec_wall_time": time.perf_counter() - t0}
    return {"exec_status": "passed" if report.passed else "failed",
            "exec_position_error_max": report.position_error.max,
            "exec_angle_error_max": report.angle_error.max,
            "exec_contacts_lost": report.contacts_lost,
            "exec_wall_time": time.perf_counter() - t0,
            "exec_message": "; ".join(report.failures)}


def row_from_peer(unit: Unit, outcome: Any, wall_time: float | None, worker_pid: int | None,
                  peak_rss_mb: float | None) -> dict[str, Any]:
    """The row of a peer's ``PeerOutcome``. Its certificate passed when it says so (a
    ``passed`` entry), else when its status is ``solved``."""
    row = _base(unit)
    cert = {str(k): float(v) for k, v in dict(outcome.certificate or {}).items()
            if _finite(v) is not None}
    passed = bool(cert.pop("passed")) if "passed" in cert else outcome.status == "solved"
    row.update(status=str(outcome.status), message=str(outcome.message),
               solve_time=_finite(outcome.solve_time), build_time=_finite(outcome.build_time),
               iterations=None if outcome.iterations is None else int(outcome.iterations),
               goal_error_max=_finite(outcome.goal_error), certificate=cert,
               solver=getattr(outcome, "solver", None) or "ipopt",
               certificate_passed=passed, wall_time=wall_time, worker_pid=worker_pid,
               peak_rss_mb=peak_rss_mb)
    row.update(residuals(cert))
    row["ok"] = row["status"] == "solved" and passed
    return row


def comparable(row: Mapping[str, Any]) -> dict[str, Any]:
    """The row without its run-dependent fields (``VOLATILE``)."""
    return {k: v for k, v in row.items() if k not in VOLATILE}


def differences(a: Mapping[str, Any], b: Mapping[str, Any], rel: float = 0.0,
                floor: float = 0.0) -> dict[str, tuple[Any, Any]]:
    """The fields (``certificate.<key>`` for its values) in which two rows of the same
    unit differ, ``VOLATILE`` ones left out; numbers within ``rel`` (relative) agree, and
    so do numbers that differ by at most ``floor`` (absolute: residuals at round-off)."""
    def same(x: Any, y: Any) -> bool:
        if isinstance(x, float) and isinstance(y, float):
            return x == y or abs(x - y) <= max(rel * max(abs(x), abs(y)), floor)
        return bool(x == y)

    out: dict[str, tuple[Any, Any]] = {}
    ca, cb = comparable(a), comparable(b)
    for k in sorted(set(ca) | set(cb)):
        x, y = ca.get(k), cb.get(k)
        if k == "certificate" and isinstance(x, dict) and isinstance(y, dict):
            for c in sorted(set(x) | set(y)):
                if not same(x.get(c), y.get(c)):
                    out[f"certificate.{c}"] = (x.get(c), y.get(c))
        elif not same(x, y):
            out[k] = (x, y)
    return out


# -- peers -----------------------------------------------------------------------------------

def peer_status() -> dict[str, str | None]:
    """Each peer method -> None when it can run here, else why not. Never raises."""
    try:
        peers = importlib.import_module("planner_service.bench.peers")
    except Exception as exc:  # not installed, or broken: either way the peers are skipped
        why = f"planner_service.bench.peers cannot be imported ({type(exc).__name__}: {exc})"
        return dict.fromkeys(PEER_METHODS, why)
    try:
        available = dict(peers.available())
        methods = dict(peers.PEER_METHODS)
    except Exception as exc:
        why = f"planner_service.bench.peers is unusable ({type(exc).__name__}: {exc})"
        return dict.fromkeys(PEER_METHODS, why)
    out: dict[str, str | None] = {}
    for m in PEER_METHODS:
        if m not in methods:
            out[m] = f"planner_service.bench.peers has no method {m!r}"
        elif not available.get(m, False):
            out[m] = f"{m} is not installed (planner_service.bench.peers.available())"
        else:
            out[m] = None
    return out


# -- running one unit in this process ---------------------------------------------------------

def run_unit(unit: Unit) -> dict[str, Any]:
    """Plan one unit in this process with the library, as the service does
    (``request_errors``, then ``solve``, with this process's planner caches), or with its
    peer; the row. Never raises: a failure is a row with status ``error``."""
    from pydantic import ValidationError

    from ocp.spec.problem import ProblemError
    from planner_service.planners import REQUEST, request_errors, solve, validation_errors

    t0 = time.perf_counter()
    pid = os.getpid()

    def fail(status: str, message: str) -> dict[str, Any]:
        return error_row(unit, status, message, time.perf_counter() - t0, pid, _peak_rss_mb())

    try:
        request = REQUEST.validate_python(unit.request)
    except ValidationError as exc:
        return fail("invalid_input", "; ".join(f"{f}: {r}" for f, r in validation_errors(exc)))
    try:
        errors = request_errors(request)
        if errors:
            return fail("invalid_input", "; ".join(f"{f}: {r}" for f, r in errors))
        if unit.method in PEER_METHODS:
            peers = importlib.import_module("planner_service.bench.peers")
            outcome = peers.PEER_METHODS[unit.method](request)
            return row_from_peer(unit, outcome, time.perf_counter() - t0, pid, _peak_rss_mb())
        result, _ = solve(request)
    except ProblemError as exc:
        return fail("invalid_input", str(exc))
    except Exception as exc:  # a failure is a row, never a crash of the benchmark
        return fail("error", f"{type(exc).__name__}: {exc}")
    return row_from_result(unit, result, time.perf_counter() - t0, pid, _peak_rss_mb())
