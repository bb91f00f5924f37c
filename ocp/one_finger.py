"""One flat fingertip rolling a ball on the palm: the paper's section 3.

This is the paper's first case in its own vocabulary (a ball-on-palm problem ``base`` and
one finger contact); the planning is :class:`~ocp.solve.planner.ManipulationPlanner`'s, with
a palm and one fingertip as data.

States: palm contact coordinates eta_p = (x, y, u_p, v_p, psi_p), fingertip contact
coordinates eta_f = (x_f, y_f, u_f, v_f, psi_f) (pad point, ball point in the finger
contact's own chart patch, contact angle; the paper's order), joint angles q.
Inputs: palm contact velocity w_p = d/dt (x, y) [m/s], the finger contact's velocity over
the ball w_f = d/dt (u_f, v_f) [rad/s] (the paper's alpha_dot_of), joint rates q_dot.

Dynamics: the rolling equations at both contacts (eq. 3 via ContactPair). Path constraints
at every collocation point: finger closure (eq. 6: the fingertip pose from q equals the
pose from the contact coordinates), both contacts inside the friction cone in cosine form,
the contact inside the pad, joint and joint-rate limits, chart pole margins. Objective:
control effort plus a weight times the grasp-angle epigraph s >= 1 - cos Phi_i (the smooth
surrogate of max(Phi_p, Phi_f), Phi^2/2 near antipodal), integrated over time.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ocp.solution import Status
from ocp.solve.planner import (
    Fingertip,
    GraspSample,
    ManipulationPlanner,
    ManipulationProblem,
    ManipulationSolution,
    Palm,
    fingertip_errors,
)
from ocp.spec.problem import (
    DEFAULT_FINGER_CHART_ROTATION,
    DEFAULT_MAX_JOINT_ACCELERATION,
    BallOnPalmProblem,
    ForceSpec,
    ProblemError,
    joint_acceleration_errors,
)
from ocp.transcription.collocation import NlpPoint, WarmStart

__all__ = ["FingerContact", "OneFingerPlanner", "OneFingerProblem", "OneFingerSolution"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class FingerContact:
    """The fingertip/ball contact at t = 0.

    ``initial`` = (x_f, y_f, u_f, v_f, psi_f): pad point [m], ball point [rad] in this
    contact's chart patch, contact angle [rad]. ``chart_rotation`` is the rotation vector
    [rad] of that patch in the ball frame (default: a quarter turn about the ball's x axis,
    so the patch's poles lie on the ball's y axis, away from where a fingertip pressing from
    above goes). ``q_seed`` seeds the inverse kinematics of the initial grasp [rad].
    """

    initial: tuple[float, float, float, float, float]
    chart_rotation: tuple[float, float, float] = DEFAULT_FINGER_CHART_ROTATION
    q_seed: tuple[float, ...] | None = None


@dataclass(frozen=True)
class OneFingerProblem:
    """The ball-on-palm problem (``base``: object, palm contact, goals, grid, limits) with a
    finger pressing on the ball."""

    base: BallOnPalmProblem
    finger: Any  # ocp.robots.finger.FingerModel
    contact: FingerContact
    mu: float = 0.5
    #: Weights of the objective (scaled, dimensionless terms): palm contact effort has
    #: weight 1. Grasp quality dominates by default (the paper's second objective): moving
    #: the finger contact over the ball and the joints is cheap, so the grasp converges to
    #: antipodal quickly and stays there.
    grasp_weight: float = 100.0
    finger_effort_weight: float = 0.01
    joint_effort_weight: float = 0.01
    pad_margin: float = 0.002  # m kept between the contact and the pad's edge
    #: Plan the contact forces (docs/forces.md); None: a kinematic plan.
    forces: ForceSpec | None = None
    #: The bound on each joint's acceleration of a smooth plan (``base.timing``) [rad/s^2].
    max_joint_acceleration: float = DEFAULT_MAX_JOINT_ACCELERATION

    def errors(self) -> list[tuple[str, str]]:
        errs = list(self.base.errors())
        errs += joint_acceleration_errors(self.max_joint_acceleration)
        if self.forces is not None:
            errs += self.forces.errors("forces", self.mu)
        if not (math.isfinite(self.mu) and 0.0 < self.mu <= 10.0):
            errs.append(("mu", f"must be in (0, 10], got {self.mu}"))
        for name in ("grasp_weight", "finger_effort_weight", "joint_effort_weight"):
            value = getattr(self, name)
            if not (math.isfinite(value) and 0.0 <= value <= 1e6):
                errs.append((name, f"must be in [0, 1e6], got {value}"))
        c = self.contact
        errs += fingertip_errors("finger_contact", Fingertip(self.finger, c.initial,
                                                             c.chart_rotation),
                                 self.base.object, self.pad_margin, self.base.pole_margin)
        return errs


@dataclass(frozen=True)
class OneFingerSolution:
    """A one-finger plan. Trajectories are sampled on the collocation grid (rows)."""

    status: Status
    message: str
    raw_status: str
    iterations: int
    build_time: float
    solve_time: float
    t: FloatArray
    eta_p: FloatArray
    eta_f: FloatArray
    eta_p_dot: FloatArray  # rates of the palm contact coordinates ([m/s], [rad/s])
    eta_f_dot: FloatArray  # rates of the finger contact coordinates ([m/s], [rad/s])
    q: FloatArray
    q_dot: FloatArray
    w_p: FloatArray
    w_f: FloatArray
    object_position: FloatArray
    object_rotation: FloatArray
    fingertip_position: FloatArray
    fingertip_rotation: FloatArray
    palm_contact_point: FloatArray
    finger_contact_point: FloatArray
    finger_contact_normal: FloatArray
    grasp_angles: FloatArray  # (Phi_p, Phi_f) [rad]
    cone_margin: FloatArray  # atan(mu) - max(Phi_p, Phi_f) [rad]
    goal_error: dict[str, float]
    certificate: dict[str, float]
    certificate_failures: tuple[str, ...] = field(default=())
    #: The time [s] of each check's worst sample (the certificate's checks along the motion).
    certificate_times: dict[str, float] = field(default_factory=dict)
    #: Grid doublings after the first solve (the returned plan has 2**refinements times the
    #: requested intervals).
    refinements: int = 0
    #: IPOPT's primal-dual point at this plan, for a warm start of the same NLP.
    nlp_point: NlpPoint | None = field(default=None, repr=False)
    #: The grasp pipeline's own plan (its collocation values and polynomials).
    plan: ManipulationSolution | None = field(default=None, repr=False, compare=False)
    #: The planned forces (palm frame, N, on the object) and joint torques [N m] of a plan
    #: with ``forces``; None otherwise.
    palm_contact_force: FloatArray | None = None
    finger_contact_force: FloatArray | None = None
    joint_torques: FloatArray | None = None

    @property
    def ok(self) -> bool:
        return self.status is Status.SOLVED

    def sample(self, t: FloatArray | list[float]) -> GraspSample:
        """The plan at any times in [0, duration] from the collocation polynomials: states
        (eta_p, eta_f, q) and inputs (w_p, w_f, q_dot) in the grasp's layout, the object's
        pose (:meth:`ocp.solve.planner.ManipulationSolution.sample`)."""
        if self.plan is None:
            raise ValueError("this plan has no collocation polynomials")
        return self.plan.sample(t)

    @property
    def warm_start(self) -> WarmStart:
        """This plan as the initial guess of another: states (eta_p, eta_f, q) and inputs
        (w_p, w_f, q_dot) at its collocation points."""
        return WarmStart(self.t, np.hstack([self.eta_p, self.eta_f, self.q]),
                         np.hstack([self.w_p, self.w_f, self.q_dot]), self.nlp_point)


#: Certificate keys of the general planner -> this planner's names.
_CERT_NAMES = {
    "max_length_defect": "max_position_defect",
    "max_pad_excursion_finger": "max_pad_excursion",
    "max_joint_limit_violation_finger": "max_joint_limit_violation",
}
#: Error fields of the general planner -> this planner's names.
_FIELD_NAMES = {"fingers[0].initial": "finger_contact.initial",
                "fingers": "finger_contact.initial"}


def _renamed(exc: ProblemError) -> ProblemError:
    return ProblemError([(_FIELD_NAMES.get(f, f), r) for f, r in exc.errors])


def _rename(text: str) -> str:
    for old, new in _CERT_NAMES.items():
        text = text.replace(old, new)
    return text


class OneFingerPlanner:
    """Direct-collocation planner for a palm + one finger grasp (the general
    :class:`~ocp.solve.planner.ManipulationPlanner` with that data; NLPs cached per
    structure)."""

    def __init__(self, general: ManipulationPlanner | None = None) -> None:
        self.general = general or ManipulationPlanner()

    @staticmethod
    def manipulation_problem(problem: OneFingerProblem) -> ManipulationProblem:
        """The same problem as a grasp: a palm and one fingertip named "finger"."""
        b, c = problem.base, problem.contact
        return ManipulationProblem(
            object=b.object,
            fingers=(Fingertip(problem.finger, c.initial, c.chart_rotation, c.q_seed,
                               name="finger"),),
            duration=b.duration,
            palm=Palm(b.initial, b.goal, b.via_points, b.palm_half_extent,
                      b.max_contact_speed),
            mu=problem.mu, object_effort_weight=1.0,
            finger_effort_weight=problem.finger_effort_weight,
            joint_effort_weight=problem.joint_effort_weight,
            grasp_weight=problem.grasp_weight, pad_margin=problem.pad_margin,
            n_intervals=b.n_intervals, pole_margin=b.pole_margin,
            max_refinements=b.max_refinements, options=b.options, forces=problem.forces,
            timing=b.timing, ramp_time=b.ramp_time,
            max_joint_acceleration=problem.max_joint_acceleration)

    def initial_grasp(self, problem: OneFingerProblem) -> FloatArray:
        """Joint angles of the initial grasp by inverse kinematics, or ProblemError saying
        why the grasp is not possible (unreachable, outside limits, outside the cone)."""
        general = self.manipulation_problem(problem)
        try:
            x0 = self.general.initial_state(general)
        except ProblemError as exc:
            raise _renamed(exc) from None
        return np.asarray(x0[self.general.model(general).fingertips[0].q_cols], dtype=float)

    def solve(self, problem: OneFingerProblem,
              warm_start: WarmStart | OneFingerSolution | None = None) -> OneFingerSolution:
        """Plan; ProblemError (before any NLP is built) on bad input or an impossible
        initial grasp. When IPOPT converges but the certificate finds the grid too coarse
        (finger slip or spin between collocation points, closure, re-integration defects),
        the plan is re-solved on a grid twice as fine, warm-started from the coarse one, up
        to ``problem.base.max_refinements`` times.

        ``warm_start``: a previous plan of a similar problem (or its ``warm_start``), the
        initial guess instead of the planner's own (which is the fallback when IPOPT does
        not converge from it)."""
        errs = problem.errors()
        if errs:
            raise ProblemError(errs)
        warm = warm_start.warm_start if isinstance(warm_start, OneFingerSolution) \
            else warm_start
        try:
            general = self.general.solve(self.manipulation_problem(problem), warm)
        except ProblemError as exc:  # an impossible initial grasp, in this planner's names
            raise _renamed(exc) from None
        return self.from_general(general)

    @staticmethod
    def from_general(sol: ManipulationSolution) -> OneFingerSolution:
        palm, tip = sol.contacts
        finger = sol.fingers[0]
        cert = {_rename(k): v for k, v in sol.certificate.items()}
        return OneFingerSolution(
            status=sol.status, message=_rename(sol.message), raw_status=sol.raw_status,
            iterations=sol.iterations, build_time=sol.build_time, solve_time=sol.ipopt_time,
            t=sol.t, eta_p=palm.eta, eta_f=tip.eta, eta_p_dot=palm.eta_dot,
            eta_f_dot=tip.eta_dot, q=finger.q, q_dot=finger.q_dot, w_p=palm.w, w_f=tip.w,
            object_position=sol.object_position, object_rotation=sol.object_rotation,
            fingertip_position=finger.tip_position, fingertip_rotation=finger.tip_rotation,
            palm_contact_point=palm.point, finger_contact_point=tip.point,
            finger_contact_normal=tip.normal,
            grasp_angles=np.column_stack([palm.force_angle, tip.force_angle]),
            cone_margin=sol.cone_margin,
            goal_error={k.removeprefix("palm."): v for k, v in sol.goal_error.items()},
            certificate=cert,
            certificate_times={_rename(k): v for k, v in sol.certificate.times().items()},
            certificate_failures=tuple(_rename(f) for f in sol.certificate_failures),
            refinements=sol.refinements, nlp_point=sol.nlp_point, plan=sol,
            palm_contact_force=palm.force, finger_contact_force=tip.force,
            joint_torques=finger.joint_torques)
