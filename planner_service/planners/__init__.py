"""The planners, as the service's doors (HTTP API, worker processes, command line) reach
them: one adapter per planner (:class:`~.base.PlannerAdapter`, one module each), all in
:data:`REGISTRY`.

The wire models live in ``dexroll_client.models`` (one definition, shared with the
client); the optimisation core (``ocp``) knows nothing of them, and only the adapters (and
the shared helpers of this package) touch the core's types.

Every planner is reached the same way: :func:`request_errors` (cheap: what is wrong with
a request, each field named), then :func:`solve` (plan it: the wire result and the core's
solution).
"""

from __future__ import annotations

from typing import Any

from pydantic import TypeAdapter

from dexroll_client.models import AnyPlanResult, PlanRequest
from ocp.ball_on_palm import BallOnPalmPlanner
from ocp.spec.problem import ProblemError

from .ball_on_palm import BallOnPalmAdapter
from .base import PlannerAdapter
from .cache import FINGERS, FingerCache, Planners
from .fields import FieldErrors, validation_errors, wire_field
from .greedy import GreedyAdapter
from .manipulation import ManipulationAdapter
from .one_finger import OneFingerAdapter

__all__ = [
    "FINGERS",
    "REGISTRY",
    "REQUEST",
    "RESULT",
    "BallOnPalmPlanner",
    "FingerCache",
    "PlannerAdapter",
    "Planners",
    "ProblemError",
    "adapter_for",
    "error_result",
    "invalid_result",
    "planner_of",
    "request_errors",
    "solve",
    "to_problem",
    "validation_errors",
    "wire_field",
]

#: Validates a request of any planner (``planner`` picks the model; default ball_on_palm).
REQUEST: TypeAdapter[PlanRequest] = TypeAdapter(PlanRequest)
#: Parses a result of any planner (by its ``planner``; default ball_on_palm).
RESULT: TypeAdapter[AnyPlanResult] = TypeAdapter(AnyPlanResult)

Adapter = PlannerAdapter[Any, Any, Any, Any]

#: Every planner's adapter, by the request's (``planner``, ``method``); ``method`` is None
#: for a planner with one method. The first adapter of a planner stands for it where only
#: its name is known (the result of a request that does not even validate).
REGISTRY: dict[tuple[str, str | None], Adapter] = {
    (a.planner, a.method): a for a in (BallOnPalmAdapter(), OneFingerAdapter(),
                                       GreedyAdapter(), ManipulationAdapter())}


def adapter_for(request: PlanRequest) -> Adapter:
    """The adapter of a request's planner (and method)."""
    return REGISTRY[(request.planner, getattr(request, "method", None))]


def _of_planner(planner: str) -> Adapter:
    """The adapter that stands for a planner known by name only (default ball_on_palm)."""
    return next((a for a in REGISTRY.values() if a.planner == planner),
                REGISTRY[("ball_on_palm", None)])


def planner_of(raw: object) -> str:
    """The planner a decoded request asks for (for the shape of an invalid result)."""
    planner = raw.get("planner") if isinstance(raw, dict) else None
    known = {a.planner for a in REGISTRY.values()}
    return planner if isinstance(planner, str) and planner in known else "ball_on_palm"


def to_problem(request: PlanRequest, fingers: FingerCache | None = None) -> Any:
    """The core's problem of a request (the core then validates it as a whole: see
    ``problem.errors()``, or :func:`request_errors` for every check); its fingers and
    hands loaded through ``fingers`` (default: this process's). ProblemError naming the
    wire fields the core cannot be given (``finger.urdf``, ``fingers[1].hand_finger``,
    ``motion.steps[2].axis``, ...)."""
    return adapter_for(request).to_problem(request, fingers or FINGERS)


def request_errors(request: PlanRequest, fingers: FingerCache | None = None) -> FieldErrors:
    """Everything wrong with a (schema-valid) request, as (field, reason) pairs; [] when it
    can be planned. Cheap (no NLP is built): the core's checks of the problem and, for a
    request with fingers, loading them and the inverse kinematics of the initial grasp
    (reachable, within the joint limits, in force closure / inside the friction cone), and
    that a ``warm_start`` fits the planner (its columns)."""
    return adapter_for(request).request_errors(request, fingers or FINGERS)


def solve(request: PlanRequest, palm: BallOnPalmPlanner | None = None,
          fingers: FingerCache | None = None) -> tuple[AnyPlanResult, Any]:
    """Plan a request: (the wire result, the core's solution). ProblemError for a request
    that cannot be planned (:func:`request_errors` names the same fields beforehand).
    ``palm``: the ball-on-palm planner (default: the core's process-wide one);
    ``fingers``: the fingers, hands and finger planners (default: this process's). A
    request's inline ``warm_start`` is passed to the planner (ProblemError naming
    ``warm_start.x`` etc. when it does not fit)."""
    result, solution = adapter_for(request).solve(request, Planners(palm, fingers or FINGERS))
    return result, solution


def invalid_result(errors: FieldErrors, planner: str = "ball_on_palm") -> AnyPlanResult:
    """The result of an invalid request to ``planner`` (status ``invalid_input``)."""
    result: AnyPlanResult = _of_planner(planner).invalid_result(errors)
    return result


def error_result(message: str, planner: str = "ball_on_palm") -> AnyPlanResult:
    """The result of a planner that failed unexpectedly (status ``error``)."""
    result: AnyPlanResult = _of_planner(planner).error_result(message)
    return result
