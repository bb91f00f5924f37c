"""Conversions at the edge: wire requests -> core problems, core solutions -> wire results.

The wire models live in ``dexroll_client.models`` (one definition, shared with the
client); the optimisation core (``ocp``) knows nothing of them.

Every planner is reached the same way, by the command line, the worker processes and the
HTTP API alike: :func:`request_errors` (cheap: what is wrong with a request, each field
named), then :func:`solve` (plan it; the wire result and the core's solution).
"""

from __future__ import annotations

import math
import threading
from collections.abc import Sequence
from typing import Any

import numpy as np
from pydantic import TypeAdapter, ValidationError

from dexroll_client.models import (
    MAX_FINGER_JOINTS,
    AnyPlanResult,
    BallOnPalmRequest,
    CertificateModel,
    FieldError,
    FingerCertificateModel,
    FingerModelSpec,
    FingerPlanResult,
    FingerStatsModel,
    FingerTrajectoryModel,
    OneFingerRequest,
    PlanRequest,
    PlanResult,
    PlanStatus,
    StatsModel,
    TrajectoryModel,
)
from ocp.ball_on_palm import BallOnPalmPlanner
from ocp.ball_on_palm import plan as plan_ball_on_palm
from ocp.finger import FingerModel, load_finger
from ocp.greedy import GreedyResult, greedy_plan
from ocp.one_finger import FingerContact, OneFingerPlanner, OneFingerProblem, OneFingerSolution
from ocp.problem import BallOnPalmProblem, ObjectSpec, ProblemError, SolverOptions, ViaPoint
from ocp.solution import Solution, Trajectory, quaternion_wxyz
from ocp.surfaces import rotation_from_vector

__all__ = [
    "REQUEST",
    "RESULT",
    "FingerCache",
    "error_result",
    "invalid_result",
    "planner_of",
    "request_errors",
    "result_from_finger_solution",
    "result_from_solution",
    "rotation_vector",
    "solve",
    "to_problem",
    "validation_errors",
    "wire_field",
]

#: Validates a request of any planner (``planner`` picks the model; default ball_on_palm).
REQUEST: TypeAdapter[PlanRequest] = TypeAdapter(PlanRequest)
#: Parses a result of any planner (by its ``planner``; default ball_on_palm).
RESULT: TypeAdapter[AnyPlanResult] = TypeAdapter(AnyPlanResult)

_PLANNER_TAGS = ("ball_on_palm", "one_finger")


class FingerCache:
    """A process's finger models and its one-finger planner, kept together.

    The planner caches its NLPs per finger object, so the same request finger must map to
    the same :class:`~ocp.finger.FingerModel` object from job to job (cached here by URDF
    text, tip frame, mount and pad size) for its NLP to be reused. With more than
    ``max_fingers`` distinct fingers, the fingers and the planner (with the NLPs it holds
    for them) are dropped together and start afresh, which bounds the memory. Thread-safe
    (one lock for loading and checking).
    """

    def __init__(self, max_fingers: int = 16) -> None:
        self.max_fingers = max_fingers
        self.lock = threading.RLock()
        self._fingers: dict[tuple[Any, ...], FingerModel] = {}
        self._planner: OneFingerPlanner | None = None

    @property
    def planner(self) -> OneFingerPlanner:
        """The process's one-finger planner (its NLP cache lives as long as the fingers)."""
        with self.lock:
            if self._planner is None:
                self._planner = OneFingerPlanner()
            return self._planner

    @staticmethod
    def _key(spec: FingerModelSpec) -> tuple[Any, ...]:
        source = f"builtin:{spec.builtin or 'k3s'}" if spec.urdf is None else spec.urdf
        return (source, spec.tip_frame,
                None if spec.base_position is None else tuple(spec.base_position),
                None if spec.base_rotation is None else tuple(spec.base_rotation),
                spec.pad_half_size)

    def finger(self, spec: FingerModelSpec) -> FingerModel:
        """The finger of a request; ProblemError naming ``finger.urdf`` or
        ``finger.tip_frame`` when it cannot be loaded."""
        key = self._key(spec)
        with self.lock:
            cached = self._fingers.get(key)
            if cached is not None:
                return cached
            finger = _load(spec)
            if len(self._fingers) >= self.max_fingers:
                self._fingers.clear()
                self._planner = None  # its NLPs refer to the fingers just dropped
            self._fingers[key] = finger
            return finger


def _load(spec: FingerModelSpec) -> FingerModel:
    if spec.urdf is not None and not spec.urdf.lstrip().startswith("<"):
        # load_finger would read a file of that name: never for a request
        raise ProblemError([("finger.urdf", "must be the URDF document itself (XML text)")])
    try:
        finger = load_finger(
            urdf=spec.urdf, tip_frame=spec.tip_frame,
            base_rotation=None if spec.base_rotation is None else
            rotation_from_vector(spec.base_rotation),
            base_position=spec.base_position,
            pad_half_size=spec.pad_half_size)
    except Exception as exc:  # whatever a user's URDF does to the loader, it is the URDF's
        reason = str(exc) or type(exc).__name__
        field = "finger.tip_frame" if repr(spec.tip_frame) in reason else "finger.urdf"
        raise ProblemError([(field, reason)]) from exc
    if finger.nq > MAX_FINGER_JOINTS:
        raise ProblemError([("finger.urdf", f"the finger has {finger.nq} joints; at most "
                                            f"{MAX_FINGER_JOINTS} are supported")])
    return finger


#: The fingers (and one-finger planner) of this process.
FINGERS = FingerCache()


def _base_problem(request: BallOnPalmRequest | OneFingerRequest) -> BallOnPalmProblem:
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


def to_problem(request: PlanRequest, fingers: FingerCache | None = None
               ) -> BallOnPalmProblem | OneFingerProblem:
    """The core's problem for a request (the core then validates it as a whole: see
    ``problem.errors()``, or :func:`request_errors` for every check). A one-finger request
    loads its finger (cached in ``fingers``, default this process's); ProblemError naming
    ``finger.urdf``/``finger.tip_frame`` when it cannot."""
    if isinstance(request, BallOnPalmRequest):
        return _base_problem(request)
    if isinstance(request, OneFingerRequest):
        finger = (fingers or FINGERS).finger(request.finger)
        c = request.finger_contact
        rv = c.chart_rotation
        return OneFingerProblem(
            base=_base_problem(request), finger=finger,
            contact=FingerContact(initial=c.initial.as_tuple(),
                                  chart_rotation=(rv[0], rv[1], rv[2]),
                                  q_seed=None if c.q_seed is None else tuple(c.q_seed)),
            mu=request.mu, grasp_weight=request.grasp_weight,
            finger_effort_weight=request.finger_effort_weight,
            joint_effort_weight=request.joint_effort_weight, pad_margin=request.pad_margin)
    raise TypeError(f"no planner for {type(request).__name__}")  # pragma: no cover


def _seed_errors(problem: OneFingerProblem) -> list[tuple[str, str]]:
    nq = int(problem.finger.nq)
    seed = problem.contact.q_seed
    if seed is not None and len(seed) != nq:
        return [("finger_contact.q_seed", f"must have one angle per joint: the finger has "
                                          f"{nq} joints, got {len(seed)}")]
    if seed is None and nq > 6:
        return [("finger_contact.q_seed", f"required for a finger with {nq} joints (the "
                                          "default seed has 6)")]
    return []


def request_errors(request: PlanRequest, fingers: FingerCache | None = None
                   ) -> list[tuple[str, str]]:
    """Everything wrong with a (schema-valid) request, as (field, reason) pairs; [] when it
    can be planned. Cheap (no NLP is built): the core's checks of the problem and, for a
    one-finger request, loading the finger and the inverse kinematics of the initial grasp
    (reachable, within the joint limits, inside the friction cone)."""
    cache = fingers or FINGERS
    with cache.lock:
        try:
            problem = to_problem(request, cache)
        except ProblemError as exc:
            return list(exc.errors)
        errors = list(problem.errors())
        if isinstance(problem, OneFingerProblem):
            errors += _seed_errors(problem)
            if not errors:
                try:
                    cache.planner.initial_grasp(problem)
                except ProblemError as exc:
                    errors += exc.errors
        return errors


def solve(request: PlanRequest, palm: BallOnPalmPlanner | None = None,
          fingers: FingerCache | None = None
          ) -> tuple[AnyPlanResult, Solution | OneFingerSolution | GreedyResult]:
    """Plan a request: (the wire result, the core's solution). ProblemError for a request
    that cannot be planned (:func:`request_errors` names the same fields beforehand).
    ``palm``: the ball-on-palm planner (default: the process-wide one); ``fingers``: the
    fingers and one-finger planner (default: this process's)."""
    if isinstance(request, BallOnPalmRequest):
        problem = _base_problem(request)
        sol = palm.solve(problem) if palm is not None else plan_ball_on_palm(problem)
        return result_from_solution(sol, request.sample_times), sol
    cache = fingers or FINGERS
    finger_problem = to_problem(request, cache)
    assert isinstance(finger_problem, OneFingerProblem)
    errors = _seed_errors(finger_problem)
    if errors:
        raise ProblemError(errors)
    if request.method == "greedy":
        greedy = greedy_plan(finger_problem, planner=cache.planner)
        return result_from_greedy(greedy, finger_problem.finger.joint_names), greedy
    finger_sol = cache.planner.solve(finger_problem)
    return result_from_finger_solution(finger_sol, finger_problem.finger.joint_names), \
        finger_sol


def rotation_vector(R: Any) -> list[float]:
    """The rotation vector [rad] (angle in [0, pi]) of a rotation matrix."""
    w, *v = (float(c) for c in quaternion_wxyz(np.asarray(R, dtype=float)).reshape(4))
    norm = math.sqrt(sum(c * c for c in v))
    if norm < 1e-15:
        return [0.0, 0.0, 0.0]
    angle = 2.0 * math.atan2(norm, w)
    return [angle * c / norm for c in v]


def wire_field(loc: Sequence[int | str]) -> str:
    """The dotted field of a pydantic error location in a request body, without the tag
    of the planner's model that a discriminated union puts first."""
    parts = [str(p) for p in loc]
    if parts and parts[0] in _PLANNER_TAGS:
        parts = parts[1:]
    return ".".join(parts)


def validation_errors(exc: ValidationError) -> list[tuple[str, str]]:
    """(field, reason) pairs of a pydantic error, with dotted field paths."""
    out = []
    for e in exc.errors(include_url=False):
        field = wire_field(e["loc"]) or "request"
        if e["type"] == "invalid_planner":
            field = "planner"
        out.append((field, str(e["msg"])))
    return out


def planner_of(raw: object) -> str:
    """The planner a decoded request asks for (for the shape of an invalid result)."""
    planner = raw.get("planner") if isinstance(raw, dict) else None
    return planner if planner in _PLANNER_TAGS else "ball_on_palm"


def invalid_result(errors: list[tuple[str, str]], planner: str = "ball_on_palm"
                   ) -> AnyPlanResult:
    message = "; ".join(f"{f}: {r}" for f, r in errors)
    fields = [FieldError(field=f, reason=r) for f, r in errors]
    if planner == "one_finger":
        return FingerPlanResult(status=PlanStatus.INVALID_INPUT, message=message,
                                errors=fields)
    return PlanResult(status=PlanStatus.INVALID_INPUT, message=message, errors=fields)


def error_result(message: str, planner: str = "ball_on_palm") -> AnyPlanResult:
    """The result of a planner that failed unexpectedly (status ``error``)."""
    if planner == "one_finger":
        return FingerPlanResult(status=PlanStatus.ERROR, message=message)
    return PlanResult(status=PlanStatus.ERROR, message=message)


def _all_finite(d: dict[str, Any]) -> bool:
    return all(np.all(np.isfinite(np.asarray(v, dtype=float))) for v in d.values())


def _trajectory(traj: Trajectory) -> TrajectoryModel | None:
    d = traj.to_dict()
    if not _all_finite(d):
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


def _finger_trajectory(sol: OneFingerSolution | GreedyResult) -> FingerTrajectoryModel | None:
    if isinstance(sol, GreedyResult):  # its rates: differences of its steps
        eta_p_dot, eta_f_dot = np.gradient(sol.eta_p, sol.t, axis=0), np.gradient(
            sol.eta_f, sol.t, axis=0)
    else:
        eta_p_dot, eta_f_dot = sol.eta_p_dot, sol.eta_f_dot
    d: dict[str, Any] = {
        "t": sol.t, "eta_p": sol.eta_p, "eta_f": sol.eta_f, "eta_p_dot": eta_p_dot,
        "eta_f_dot": eta_f_dot, "q": sol.q, "q_dot": sol.q_dot,
        "w_p": sol.w_p, "w_f": sol.w_f, "object_position": sol.object_position,
        "object_orientation_wxyz": quaternion_wxyz(sol.object_rotation),
        "fingertip_position": sol.fingertip_position,
        "fingertip_orientation_wxyz": quaternion_wxyz(sol.fingertip_rotation),
        "palm_contact_point": sol.palm_contact_point,
        "finger_contact_point": sol.finger_contact_point,
        "finger_contact_normal": sol.finger_contact_normal,
        "grasp_angles": sol.grasp_angles, "cone_margin": sol.cone_margin}
    if not _all_finite(d):
        return None  # JSON has no NaN; a diverged last iterate is reported by its status
    return FingerTrajectoryModel(**{k: np.asarray(v, dtype=float).tolist()
                                    for k, v in d.items()})


def result_from_finger_solution(sol: OneFingerSolution, joint_names: Sequence[str] = ()
                                ) -> FingerPlanResult:
    """The wire result of a one-finger plan (``joint_names``: the finger's, in q order)."""
    values = {k: float(v) for k, v in sol.certificate.items()
              if not k.startswith("tol_") and math.isfinite(v)}
    tolerances = {k[len("tol_"):]: float(v) for k, v in sol.certificate.items()
                  if k.startswith("tol_") and math.isfinite(v)}
    failures = list(sol.certificate_failures)
    cert = FingerCertificateModel(passed=bool(values) and not failures, values=values,
                                  tolerances=tolerances, failures=failures)
    trajectory = _finger_trajectory(sol)
    message = sol.message if trajectory is not None else \
        sol.message + " (non-finite iterate omitted)"
    return FingerPlanResult(
        status=PlanStatus(sol.status.value), message=message,
        stats=FingerStatsModel(raw_status=sol.raw_status, iterations=sol.iterations,
                               build_time=sol.build_time, solve_time=sol.solve_time,
                               refinements=sol.refinements),
        goal_error={k: float(v) for k, v in sol.goal_error.items() if math.isfinite(v)},
        certificate=cert, joint_names=list(joint_names), trajectory=trajectory)


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
        certificate=cert, joint_names=list(joint_names), trajectory=_finger_trajectory(res))
