"""What the service needs of a planner: :class:`PlannerAdapter`, implemented once per
planner (one module each) and registered in :data:`planner_service.planners.REGISTRY`.

An adapter is the only place where a planner's wire request meets the core's (``ocp``)
problem and solution types: it converts the request to the core's problem, names what is
wrong with it in wire fields (through its :class:`~.fields.FieldMap`), plans it, converts
the core's solution to the wire result, and names the columns of the plan's warm start.
"""

from __future__ import annotations

import contextlib
from abc import ABC, abstractmethod
from typing import Generic, TypeVar

from dexroll_client.models import (
    BallOnPalmRequest,
    FieldError,
    FingerPlanResult,
    ManipulationRequest,
    ManipulationResult,
    OneFingerRequest,
    PlanResult,
    PlanStatus,
)
from ocp.spec.problem import ProblemError

from .cache import FingerCache, Planners
from .columns import ColumnNames, warm_start_errors
from .fields import FieldErrors, FieldMap, Rule

__all__ = ["SOLVER_FIELDS", "PlannerAdapter"]

RequestT = TypeVar("RequestT", bound=BallOnPalmRequest | OneFingerRequest | ManipulationRequest)
ProblemT = TypeVar("ProblemT")
SolutionT = TypeVar("SolutionT")
ResultT = TypeVar("ResultT", bound=PlanResult | FingerPlanResult | ManipulationResult)

#: Every core problem's solver options (``options``) are a request's ``solver``.
SOLVER_FIELDS = FieldMap(Rule("options", "solver"))


class PlannerAdapter(ABC, Generic[RequestT, ProblemT, SolutionT, ResultT]):
    """One planner, as the service's doors (HTTP API, workers, command line) reach it.

    ``RequestT`` is the planner's wire request, ``ProblemT`` and ``SolutionT`` the core's
    problem and solution, ``ResultT`` the wire result. Adapters hold no state: the
    planners and their caches come in as :class:`~.cache.Planners` / ``FingerCache``.
    """

    #: The request's ``planner`` this adapter serves, and its ``method`` (None: the
    #: planner has one method).
    planner: str
    method: str | None = None
    #: The planner's wire result (also that of an invalid request or a failed planner).
    result_type: type[ResultT]
    #: Whether its requests' checks use the process's fingers (and hold their lock, which
    #: a check loading a request's hand holds for its load and inverse kinematics).
    uses_fingers: bool = True

    def fields(self, request: RequestT) -> FieldMap:
        """The core's field paths of this request's problem -> the request's wire paths."""
        return SOLVER_FIELDS

    # -- the request -------------------------------------------------------------------------
    @abstractmethod
    def to_problem(self, request: RequestT, fingers: FingerCache) -> ProblemT:
        """The core's problem of a request (its fingers and hands loaded from ``fingers``);
        ProblemError naming the wire fields the core cannot even be given (a finger that
        does not load, a hand finger that does not exist, ...)."""

    @abstractmethod
    def problem_errors(self, request: RequestT, problem: ProblemT, fingers: FingerCache
                       ) -> FieldErrors:
        """What is wrong with a request's problem, in the core's field names: the core's
        checks and, once they pass, those that need the fingers (the inverse kinematics of
        the initial grasp: reachable, within the joint limits, in force closure)."""

    @abstractmethod
    def collocation_names(self, problem: ProblemT) -> ColumnNames:
        """(state names, input names): the columns of a plan of ``problem`` at its
        collocation points (a result's ``collocation`` block, a request's
        ``warm_start``)."""

    def warm_start_errors(self, request: RequestT, problem: ProblemT) -> FieldErrors:
        """What is wrong with a request's ``warm_start`` for its problem (wire fields)."""
        return warm_start_errors(request, self.collocation_names(problem))

    def request_errors(self, request: RequestT, fingers: FingerCache) -> FieldErrors:
        """Everything wrong with a (schema-valid) request, in wire fields; [] when it can
        be planned. Cheap: no NLP is built."""
        with fingers.lock if self.uses_fingers else contextlib.nullcontext():
            try:
                problem = self.to_problem(request, fingers)
            except ProblemError as exc:
                return list(exc.errors)
            errors = self.fields(request).errors(self.problem_errors(request, problem,
                                                                     fingers))
            return errors + self.warm_start_errors(request, problem)

    # -- the plan ----------------------------------------------------------------------------
    @abstractmethod
    def solve(self, request: RequestT, planners: Planners) -> tuple[ResultT, SolutionT]:
        """Plan a request: (the wire result, the core's solution). ProblemError, in wire
        fields, for a request that cannot be planned (:meth:`request_errors` names the
        same fields beforehand). A request's inline ``warm_start`` is the planner's initial
        guess."""

    @abstractmethod
    def to_result(self, request: RequestT, problem: ProblemT, solution: SolutionT
                  ) -> ResultT:
        """The wire result of the core's solution of a request's problem."""

    @abstractmethod
    def prepare(self, request: RequestT, planners: Planners) -> float:
        """Build (and cache) the NLP of a (valid) request's structure without solving (a
        worker's warm-up); its build time [s], 0 when it was cached or none is needed."""

    @abstractmethod
    def summary(self, result: ResultT, solution: SolutionT) -> str:
        """One screen on a plan (the command line's)."""

    # -- results without a plan --------------------------------------------------------------
    def invalid_result(self, errors: FieldErrors) -> ResultT:
        """The result of an invalid request (status ``invalid_input``, each field named)."""
        return self.result_type(status=PlanStatus.INVALID_INPUT,
                                message="; ".join(f"{f}: {r}" for f, r in errors),
                                errors=[FieldError(field=f, reason=r) for f, r in errors])

    def error_result(self, message: str) -> ResultT:
        """The result of a planner that failed unexpectedly (status ``error``)."""
        return self.result_type(status=PlanStatus.ERROR, message=message)
