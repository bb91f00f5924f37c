"""The one-finger planner: a ball rolled on the palm with one fingertip pressing on it
(``ocp.one_finger``), by direct collocation: the general planner
(``ocp.solve.planner``) with a palm and one fingertip named ``finger``.

:class:`FingerAdapter` is what both of the one-finger planner's methods share (the
request, the problem, its checks, the wire result); the greedy method is
:mod:`.greedy`'s.
"""

from __future__ import annotations

import math
from abc import abstractmethod
from collections.abc import Sequence
from typing import Any, TypeVar

import numpy as np

from dexroll_client.models import (
    FingerCertificateModel,
    FingerPlanResult,
    FingerStatsModel,
    FingerTrajectoryModel,
    OneFingerRequest,
    PlanStatus,
)
from ocp.certify.certificate import Certificate
from ocp.geometry.rotations import quaternion_wxyz
from ocp.methods.greedy import GreedyResult
from ocp.one_finger import FingerContact, OneFingerPlanner, OneFingerProblem, OneFingerSolution
from ocp.spec.problem import ProblemError
from ocp.transcription.collocation import WarmStart

from .ball_on_palm import ball_on_palm_problem
from .base import SOLVER_FIELDS, PlannerAdapter
from .cache import FingerCache, Planners
from .columns import ColumnNames, collocation_block, grasp_names, warm_start_of
from .common import all_finite, finger_certificate, force_spec
from .fields import FieldErrors, FieldMap, Rule
from .samples import joint_trajectory_block, requested_times, samples_block

__all__ = [
    "ONE_FINGER_CHECK_NAMES",
    "ONE_FINGER_FIELDS",
    "FingerAdapter",
    "OneFingerAdapter",
    "finger_summary",
    "finger_trajectory",
    "result_from_finger_solution",
    "seed_errors",
]

SolutionT = TypeVar("SolutionT")

#: The general planner's names of a one-finger problem (a palm and ``fingers[0]``) ->
#: the one-finger request's: the fingertip is ``finger_contact``, and the grasp's force
#: closure is its initial contact's.
ONE_FINGER_FIELDS = SOLVER_FIELDS + FieldMap(
    Rule("fingers[0]", "finger_contact"),
    Rule("fingers", "finger_contact.initial", keep_rest=False))


#: The one-finger result's names of the general planner's checks, where they differ: the
#: one-finger planner's own vocabulary, which predates the general planner (the palm
#: contact's length defect is ``max_position_defect``, as on the ball-on-palm certificate;
#: the one fingertip's checks carry no ``_finger`` suffix). The core's one-finger solution
#: restates its flat certificate in the same names.
ONE_FINGER_CHECK_NAMES = {
    "max_length_defect": "max_position_defect",
    "max_pad_excursion_finger": "max_pad_excursion",
    "max_joint_limit_violation_finger": "max_joint_limit_violation",
}


def one_finger_check_name(text: str) -> str:
    """A check's name, or a failure's text, in the one-finger result's vocabulary."""
    for general, own in ONE_FINGER_CHECK_NAMES.items():
        text = text.replace(general, own)
    return text


def one_finger_problem(request: OneFingerRequest, fingers: FingerCache) -> OneFingerProblem:
    finger = fingers.finger(request.finger)
    c = request.finger_contact
    rv = c.chart_rotation
    return OneFingerProblem(
        base=ball_on_palm_problem(request), finger=finger,
        contact=FingerContact(initial=c.initial.as_tuple(),
                              chart_rotation=(rv[0], rv[1], rv[2]),
                              q_seed=None if c.q_seed is None else tuple(c.q_seed)),
        mu=request.mu, grasp_weight=request.grasp_weight,
        finger_effort_weight=request.finger_effort_weight,
        joint_effort_weight=request.joint_effort_weight, pad_margin=request.pad_margin,
        forces=force_spec(request.forces),
        max_joint_acceleration=request.max_joint_acceleration)


def seed_errors(problem: OneFingerProblem) -> FieldErrors:
    """What is wrong with the seed of the initial grasp's inverse kinematics."""
    nq = int(problem.finger.nq)
    seed = problem.contact.q_seed
    if seed is not None and len(seed) != nq:
        return [("finger_contact.q_seed", f"must have one angle per joint: the finger has "
                                          f"{nq} joints, got {len(seed)}")]
    if seed is None and nq > 6:
        return [("finger_contact.q_seed", f"required for a finger with {nq} joints (the "
                                          "default seed has 6)")]
    return []


class FingerAdapter(PlannerAdapter[OneFingerRequest, OneFingerProblem, SolutionT,
                                   FingerPlanResult]):
    """The one-finger planner, whichever its method (``plan`` is the method's)."""

    planner = "one_finger"
    result_type = FingerPlanResult

    def fields(self, request: OneFingerRequest) -> FieldMap:
        return ONE_FINGER_FIELDS

    def to_problem(self, request: OneFingerRequest, fingers: FingerCache) -> OneFingerProblem:
        """ProblemError naming ``finger.urdf``/``finger.tip_frame`` when the finger cannot
        be loaded."""
        return one_finger_problem(request, fingers)

    def problem_errors(self, request: OneFingerRequest, problem: OneFingerProblem,
                       fingers: FingerCache) -> FieldErrors:
        errors = list(problem.errors()) + seed_errors(problem)
        if not errors:
            try:
                fingers.manipulation.initial_state(
                    OneFingerPlanner.manipulation_problem(problem))
            except ProblemError as exc:
                errors += exc.errors
        return errors

    def collocation_names(self, problem: OneFingerProblem) -> ColumnNames:
        """The general planner's with the palm and one fingertip named ``finger``."""
        return grasp_names(True, [("finger", tuple(problem.finger.joint_names))])

    def solve(self, request: OneFingerRequest, planners: Planners
              ) -> tuple[FingerPlanResult, SolutionT]:
        warm = warm_start_of(request)
        problem = one_finger_problem(request, planners.fingers)
        errors = seed_errors(problem)
        if errors:
            raise ProblemError(errors)
        try:
            solution = self.plan(request, problem, warm, planners.fingers)
        except ProblemError as exc:
            raise ProblemError(self.fields(request).errors(exc.errors)) from exc
        return self.to_result(request, problem, solution), solution

    @abstractmethod
    def plan(self, request: OneFingerRequest, problem: OneFingerProblem,
             warm: WarmStart | None, fingers: FingerCache) -> SolutionT:
        """The method's plan (ProblemError in the core's field names)."""

    def summary(self, result: FingerPlanResult, solution: SolutionT) -> str:
        return finger_summary(result)


class OneFingerAdapter(FingerAdapter[OneFingerSolution]):
    """The direct-collocation method."""

    method = "collocation"

    def plan(self, request: OneFingerRequest, problem: OneFingerProblem,
             warm: WarmStart | None, fingers: FingerCache) -> OneFingerSolution:
        errors = problem.errors()
        if errors:
            raise ProblemError(errors)
        general = fingers.manipulation.solve(OneFingerPlanner.manipulation_problem(problem),
                                             warm)
        return OneFingerPlanner.from_general(general)

    def to_result(self, request: OneFingerRequest, problem: OneFingerProblem,
                  solution: OneFingerSolution) -> FingerPlanResult:
        return result_from_finger_solution(solution, problem.finger.joint_names,
                                           requested_times(request))

    def prepare(self, request: OneFingerRequest, planners: Planners) -> float:
        fingers = planners.fingers
        with fingers.lock:
            problem = one_finger_problem(request, fingers)
            general = fingers.manipulation
        return general.prepare(OneFingerPlanner.manipulation_problem(problem))


def finger_trajectory(sol: OneFingerSolution | GreedyResult, eta_p_dot: Any, eta_f_dot: Any
                      ) -> FingerTrajectoryModel | None:
    """The wire trajectory of a one-finger plan (either method's: the same arrays), with
    the rates of its contact coordinates ``eta_p_dot``, ``eta_f_dot``; None when it holds
    non-finite values."""
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
    for k in ("palm_contact_force", "finger_contact_force", "joint_torques"):
        v = getattr(sol, k, None)
        if v is not None:
            d[k] = v
    if not all_finite(d):
        return None  # JSON has no NaN; a diverged last iterate is reported by its status
    return FingerTrajectoryModel(**{k: np.asarray(v, dtype=float).tolist()
                                    for k, v in d.items()})


def result_from_finger_solution(sol: OneFingerSolution, joint_names: Sequence[str] = (),
                                times: Any = None) -> FingerPlanResult:
    """The wire result of a one-finger plan (``joint_names``: the finger's, in q order;
    ``times``: the request's sample times, :func:`~.samples.requested_times`)."""
    # the typed certificate is the general planner's plan's (the solution's own is its
    # flat restatement); a solution without that plan was never checked
    checked = sol.plan.certificate if sol.plan is not None else \
        Certificate.failed("no plan of the general planner to check")
    cert = finger_certificate(FingerCertificateModel, checked, one_finger_check_name)
    trajectory = finger_trajectory(sol, sol.eta_p_dot, sol.eta_f_dot)
    message = sol.message if trajectory is not None else \
        sol.message + " (non-finite iterate omitted)"
    nq = int(np.shape(sol.q)[1]) if np.ndim(sol.q) == 2 else 0
    joints = list(joint_names) if len(joint_names) == nq else [f"j{i}" for i in range(nq)]
    collocation = None if trajectory is None else collocation_block(
        sol.warm_start, grasp_names(True, [("finger", joints)]))
    return FingerPlanResult(
        status=PlanStatus(sol.status.value), message=message,
        stats=FingerStatsModel(raw_status=sol.raw_status, iterations=sol.iterations,
                               build_time=sol.build_time, solve_time=sol.solve_time,
                               refinements=sol.refinements),
        goal_error={k: float(v) for k, v in sol.goal_error.items() if math.isfinite(v)},
        certificate=cert, joint_names=list(joint_names), trajectory=trajectory,
        chart_rotation=list(sol.plan.object_chart_rotation)
        if trajectory and sol.plan and sol.plan.object_chart_rotation else None,
        samples=samples_block(sol.plan, times) if trajectory else None,
        joint_trajectory=joint_trajectory_block(sol.plan, times) if trajectory else None,
        collocation=collocation)


def finger_summary(result: FingerPlanResult) -> str:
    """One screen on a one-finger plan."""
    lines = [f"status       {result.status.value}"
             + (f"  (IPOPT: {result.stats.raw_status})" if result.stats else ""),
             f"message      {result.message}"]
    if result.stats is not None:
        s = result.stats
        lines += [f"iterations   {s.iterations}",
                  f"time         build {s.build_time * 1e3:.1f} ms, solve "
                  f"{s.solve_time * 1e3:.1f} ms"]
    if result.goal_error:
        worst_goal = max(result.goal_error.values())
        lines.append(f"goal error   {worst_goal:.3g} (worst of {len(result.goal_error)} "
                     "targets)")
    c = result.certificate
    if c is not None:
        lines.append("certificate  " + ("PASSED" if c.passed else "FAILED"))
        lines += [f"  {f}" for f in c.failures[:6]]
    t = result.trajectory
    if t is not None and t.grasp_angles:
        worst = [max(row) for row in t.grasp_angles]
        lines.append(f"grasp angle  {math.degrees(worst[0]):.2f} deg at start, "
                     f"{math.degrees(worst[-1]):.2f} at end, {math.degrees(max(worst)):.2f} "
                     "max (larger of palm/finger)")
        lines.append(f"cone margin  {math.degrees(min(t.cone_margin)):.2f} deg minimum "
                     "(> 0: inside the friction cone)")
    return "\n".join(lines)
