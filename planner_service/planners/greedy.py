"""The one-finger planner's greedy method: the paper's own (section 3, ``ocp.methods.greedy``),
step by step, with no NLP and no initial guess."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from dexroll_client.models import (
    FingerCertificateModel,
    FingerPlanResult,
    FingerStatsModel,
    OneFingerRequest,
    PlanStatus,
)
from ocp.methods.greedy import GreedyResult, greedy_plan
from ocp.one_finger import OneFingerProblem
from ocp.spec.problem import ProblemError
from ocp.transcription.collocation import WarmStart

from .cache import FingerCache, Planners
from .fields import FieldErrors
from .one_finger import FingerAdapter, finger_trajectory

__all__ = ["GreedyAdapter", "result_from_greedy"]


class GreedyAdapter(FingerAdapter[GreedyResult]):
    """The greedy method: a one-finger request with ``method`` 'greedy'."""

    method = "greedy"

    def warm_start_errors(self, request: OneFingerRequest, problem: OneFingerProblem
                          ) -> FieldErrors:
        errors: FieldErrors = []
        if request.forces is not None:  # (the request's other fields the method ignores)
            errors.append(("forces", "planned forces need method 'collocation' (the greedy "
                                     "method plans kinematics only)"))
        if request.warm_start is None:
            return errors
        return [*errors, ("warm_start", "not used by the greedy method (it chooses each step "
                                        "from the current state, with no initial guess): drop "
                                        "it or use method 'collocation'")]

    def plan(self, request: OneFingerRequest, problem: OneFingerProblem,
             warm: WarmStart | None, fingers: FingerCache) -> GreedyResult:
        if warm is not None:
            raise ProblemError(self.warm_start_errors(request, problem))
        return greedy_plan(problem, planner=fingers.planner)

    def to_result(self, request: OneFingerRequest, problem: OneFingerProblem,
                  solution: GreedyResult) -> FingerPlanResult:
        return result_from_greedy(solution, problem.finger.joint_names)

    def prepare(self, request: OneFingerRequest, planners: Planners) -> float:
        return 0.0  # the greedy method builds no NLP


def result_from_greedy(res: GreedyResult, joint_names: Sequence[str] = ()) -> FingerPlanResult:
    """The wire result of a plan by the paper's greedy method. Its checks (closure of the
    pseudo-inverse joint rates against Pinocchio's FK, joint limits, friction cone, feasible
    steps) stand in the certificate; a plan with any failure is 'inaccurate'."""
    values = {
        "max_closure_position_error": float(res.closure_error[0]),
        "max_closure_orientation_error": float(res.closure_error[1]),
        "min_cone_margin": float(np.min(res.cone_margin)),
        "joint_limit_margin": float(res.joint_limit_margin),
        "max_velocity_ratio": float(res.max_velocity_ratio),
        "fallback_steps": float(res.fallback_steps),
        "palm_integration_error": float(res.palm_integration_error),
        "joint_effort": float(res.joint_effort),
    }
    values = {k: v for k, v in values.items() if math.isfinite(v)}
    failures = list(res.failures)
    cert = FingerCertificateModel(passed=not failures, values=values,
                                  tolerances={}, failures=failures)
    status = PlanStatus.SOLVED if not failures else PlanStatus.INACCURATE
    message = ("greedy plan (the paper's method); its checks passed" if not failures else
               "greedy plan (the paper's method) failed its checks: " + "; ".join(failures))
    return FingerPlanResult(
        status=status, message=message,
        stats=FingerStatsModel(raw_status="greedy", iterations=len(res.t) - 1, build_time=0.0,
                               solve_time=float(res.compute_time)),
        goal_error={k: float(v) for k, v in res.goal_error.items() if math.isfinite(v)},
        certificate=cert, joint_names=list(joint_names), trajectory=finger_trajectory(
            res, np.gradient(res.eta_p, res.t, axis=0), np.gradient(res.eta_f, res.t, axis=0)))
