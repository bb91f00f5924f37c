"""Conversions at the edge: wire requests -> core problems, core solutions -> wire results.

The wire models live in ``dexroll_client.models`` (one definition, shared with the
client); the optimisation core (``ocp``) knows nothing of them.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from pydantic import ValidationError

from dexroll_client.models import (
    BallOnPalmRequest,
    CertificateModel,
    FieldError,
    PlanRequest,
    PlanResult,
    PlanStatus,
    StatsModel,
    TrajectoryModel,
)
from ocp.problem import BallOnPalmProblem, ObjectSpec, SolverOptions, ViaPoint
from ocp.solution import Solution, Trajectory

__all__ = ["invalid_result", "result_from_solution", "to_problem", "validation_errors"]


def to_problem(request: PlanRequest) -> BallOnPalmProblem:
    """The core's problem for a request (the core then validates it as a whole)."""
    if not isinstance(request, BallOnPalmRequest):  # pragma: no cover - one planner so far
        raise TypeError(f"no planner for {type(request).__name__}")
    o = request.solver
    rv = request.object.chart_rotation
    return BallOnPalmProblem(
        object=ObjectSpec(request.object.shape, tuple(request.object.dimensions),
                          (rv[0], rv[1], rv[2])),
        initial=request.initial.as_tuple(),
        goal=request.goal.as_dict(),
        duration=request.duration,
        via_points=tuple(ViaPoint(vp.time, vp.coords.as_dict()) for vp in request.via_points),
        n_intervals=request.n_intervals,
        pole_margin=request.pole_margin,
        max_contact_speed=request.max_contact_speed,
        palm_half_extent=request.palm_half_extent,
        max_refinements=request.max_refinements,
        options=SolverOptions(max_iter=o.max_iter, time_limit=o.time_limit,
                              cert_position_tol=o.cert_position_tol,
                              cert_angle_tol=o.cert_angle_tol),
    )


def validation_errors(exc: ValidationError) -> list[tuple[str, str]]:
    """(field, reason) pairs of a pydantic error, with dotted field paths."""
    out = []
    for e in exc.errors(include_url=False):
        loc = ".".join(str(p) for p in e["loc"]) or "request"
        out.append((loc, str(e["msg"])))
    return out


def invalid_result(errors: list[tuple[str, str]]) -> PlanResult:
    return PlanResult(status=PlanStatus.INVALID_INPUT,
                      message="; ".join(f"{f}: {r}" for f, r in errors),
                      errors=[FieldError(field=f, reason=r) for f, r in errors])


def _trajectory(traj: Trajectory) -> TrajectoryModel | None:
    d = traj.to_dict()
    if not all(np.all(np.isfinite(np.asarray(v, dtype=float))) for v in d.values()):
        return None  # JSON has no NaN; a diverged last iterate is reported by its status
    return TrajectoryModel(**d)


def _finite_or_none(x: float) -> float | None:
    return float(x) if np.isfinite(x) else None


def result_from_solution(sol: Solution, sample_times: list[float] | None = None
                         ) -> PlanResult:
    c = sol.certificate
    cert = CertificateModel(
        passed=c.passed, max_position_defect=_finite_or_none(c.max_position_defect),
        max_angle_defect=_finite_or_none(c.max_angle_defect),
        max_slip_speed=_finite_or_none(c.max_slip_speed),
        max_spin_rate=_finite_or_none(c.max_spin_rate),
        max_height_error=_finite_or_none(c.max_height_error),
        max_goal_error=_finite_or_none(c.max_goal_error), n_samples=c.n_samples,
        tolerances=dict(c.tolerances), failures=list(c.failures))
    stats: dict[str, Any] = sol.stats.to_dict()
    if not np.isfinite(stats["objective"]):
        stats["objective"] = -1.0
    grid = _trajectory(sol.grid)
    samples = _trajectory(sol.sample(sample_times)) if sample_times and grid else None
    message = sol.message if grid is not None else sol.message + " (non-finite iterate omitted)"
    goal_error = {k: v for k, v in sol.goal_error.items() if np.isfinite(v)}
    return PlanResult(status=PlanStatus(sol.status.value), message=message,
                      stats=StatsModel(**stats), goal_error=goal_error, certificate=cert,
                      grid=grid, samples=samples)
