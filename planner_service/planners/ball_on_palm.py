"""The ball-on-palm planner: an object rolled on the flat palm (``ocp.ball_on_palm``)."""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

from dexroll_client.models import (
    BallOnPalmRequest,
    CertificateModel,
    OneFingerRequest,
    PlanResult,
    PlanStatus,
    StatsModel,
    TrajectoryModel,
)
from ocp.ball_on_palm import plan
from ocp.solution import Solution, Trajectory
from ocp.spec.problem import BallOnPalmProblem, ProblemError, ViaPoint

from .base import PlannerAdapter
from .cache import FingerCache, Planners
from .columns import (
    BALL_ON_PALM_INPUTS,
    BALL_ON_PALM_STATES,
    ColumnNames,
    collocation_block,
    warm_start_of,
)
from .common import all_finite, check_values, finite_or_none, object_spec, solver_options
from .fields import FieldErrors
from .samples import requested_times

__all__ = ["BallOnPalmAdapter", "ball_on_palm_problem", "result_from_solution"]


def ball_on_palm_problem(request: BallOnPalmRequest | OneFingerRequest) -> BallOnPalmProblem:
    """The core's ball-on-palm problem of a request (a one-finger request's palm part)."""
    return BallOnPalmProblem(
        object=object_spec(request.object),
        initial=request.initial.as_tuple(),
        goal=request.goal.as_dict(),
        duration=request.duration,
        via_points=tuple(ViaPoint(vp.time, vp.coords.as_dict()) for vp in request.via_points),
        n_intervals=request.n_intervals,
        pole_margin=request.pole_margin,
        max_contact_speed=request.max_contact_speed,
        palm_half_extent=request.palm_half_extent,
        max_refinements=request.max_refinements,
        options=solver_options(request.solver),
        timing=request.timing,
        ramp_time=request.ramp_time,
    )


class BallOnPalmAdapter(PlannerAdapter[BallOnPalmRequest, BallOnPalmProblem, Solution,
                                       PlanResult]):
    planner = "ball_on_palm"
    result_type = PlanResult
    uses_fingers = False

    def to_problem(self, request: BallOnPalmRequest, fingers: FingerCache
                   ) -> BallOnPalmProblem:
        return ball_on_palm_problem(request)

    def problem_errors(self, request: BallOnPalmRequest, problem: BallOnPalmProblem,
                       fingers: FingerCache) -> FieldErrors:
        return list(problem.errors())

    def collocation_names(self, problem: BallOnPalmProblem) -> ColumnNames:
        return list(BALL_ON_PALM_STATES), list(BALL_ON_PALM_INPUTS)

    def solve(self, request: BallOnPalmRequest, planners: Planners
              ) -> tuple[PlanResult, Solution]:
        warm = warm_start_of(request)
        problem = ball_on_palm_problem(request)
        try:
            sol = planners.palm.solve(problem, warm) if planners.palm is not None else \
                plan(problem, warm)
        except ProblemError as exc:
            raise ProblemError(self.fields(request).errors(exc.errors)) from exc
        return self.to_result(request, problem, sol), sol

    def to_result(self, request: BallOnPalmRequest, problem: BallOnPalmProblem,
                  solution: Solution) -> PlanResult:
        return result_from_solution(solution, requested_times(request))

    def prepare(self, request: BallOnPalmRequest, planners: Planners) -> float:
        if planners.palm is None:  # the core's process-wide planner builds as it solves
            return 0.0
        problem = ball_on_palm_problem(request)
        t0 = time.perf_counter()
        _, hit = planners.palm.nlp_for(problem)
        return 0.0 if hit else time.perf_counter() - t0

    def summary(self, result: PlanResult, solution: Solution) -> str:
        return solution.summary()


def _trajectory(traj: Trajectory) -> TrajectoryModel | None:
    d = traj.to_dict()
    if not all_finite(d):
        return None  # JSON has no NaN; a diverged last iterate is reported by its status
    return TrajectoryModel(**d)


def result_from_solution(sol: Solution, sample_times: Any = None) -> PlanResult:
    """The wire result of a ball-on-palm plan (``sample_times``: the request's,
    :func:`~.samples.requested_times`)."""
    c = sol.certificate
    values = check_values(c)

    def value(name: str) -> float | None:
        return finite_or_none(values.get(name, math.nan))

    cert = CertificateModel(
        passed=c.passed, max_position_defect=value("max_position_defect"),
        max_angle_defect=value("max_angle_defect"), max_slip_speed=value("max_slip_speed"),
        max_spin_rate=value("max_spin_rate"), max_height_error=value("max_height_error"),
        max_goal_error=value("max_goal_error"), n_samples=c.n_samples,
        tolerances=c.tolerances(), times=c.times(), failures=list(c.failures))
    stats: dict[str, Any] = sol.stats.to_dict()
    if not np.isfinite(stats["objective"]):
        stats["objective"] = -1.0
    grid = _trajectory(sol.grid)
    samples = _trajectory(sol.sample(sample_times)) \
        if sample_times is not None and len(sample_times) and grid else None
    message = sol.message if grid is not None else sol.message + " (non-finite iterate omitted)"
    goal_error = {k: v for k, v in sol.goal_error.items() if np.isfinite(v)}
    collocation = None if grid is None else collocation_block(
        sol.warm_start, (list(BALL_ON_PALM_STATES), list(BALL_ON_PALM_INPUTS)))
    return PlanResult(status=PlanStatus(sol.status.value), message=message,
                      stats=StatsModel(**stats), goal_error=goal_error, certificate=cert,
                      grid=grid, samples=samples, collocation=collocation,
                      chart_rotation=list(sol.chart_rotation) if grid else None)
