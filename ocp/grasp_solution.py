"""A grasp's plan: the object's motion, every contact's coordinates and every finger's
joints on the collocation grid, the certificate, and the collocation polynomials to sample
it at any time (:meth:`ManipulationSolution.sample`)."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from .certificate import Certificate
from .collocation import NlpPoint, WarmStart, hermite_sample
from .grasp import force_angles
from .rotations import rotation_angle_between
from .solution import SolverStats, Status

if TYPE_CHECKING:
    from .grasp_model import GraspModel
    from .grasp_spec import ManipulationProblem

__all__ = ["Collocation", "ContactTrajectory", "FingerTrajectory", "GraspSample",
           "ManipulationSolution", "assemble_solution"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class ContactTrajectory:
    """One contact over the plan (rows are samples).

    ``eta`` = (body point x, y [m], object point u, v [rad], psi [rad]): for the palm the
    palm point, for a fingertip the pad point; ``w`` the contact's input (palm: d/dt (x, y)
    [m/s]; fingertip: d/dt (u, v) [rad/s]); ``point`` the contact point and ``normal`` the
    object's outward normal there, in the palm frame; ``force_angle`` the angle [rad]
    between the pushing direction (-normal) and the internal force of the grasp that
    certifies force closure (for two contacts: the paper's grasp angle).
    """

    name: str
    body: str  # "palm" or "finger"
    eta: FloatArray
    eta_dot: FloatArray
    w: FloatArray
    point: FloatArray
    normal: FloatArray
    force_angle: FloatArray


@dataclass(frozen=True)
class FingerTrajectory:
    """One finger over the plan: joint angles q [rad], rates q_dot [rad/s], the pad's pose
    (position [m], rotation) in the palm frame."""

    name: str
    joint_names: tuple[str, ...]
    q: FloatArray
    q_dot: FloatArray
    tip_position: FloatArray
    tip_rotation: FloatArray


@dataclass(frozen=True)
class Collocation:
    """The NLP's own values of a plan: node times, states at the nodes (rows) and at the
    interval midpoints, each interval's inputs at its start (U0), midpoint (Um) and end
    (U1; at a via-point node the incoming input, U0 of the next interval the outgoing).
    The states between are each interval's cubic Hermite polynomial, the inputs the
    quadratic through (U0, Um, U1): :meth:`ManipulationSolution.sample`."""

    t_nodes: FloatArray
    X: FloatArray
    Xm: FloatArray
    U0: FloatArray
    Um: FloatArray
    U1: FloatArray


@dataclass(frozen=True)
class GraspSample:
    """A plan at given times (rows): states x and inputs u in the grasp's layout (the
    contacts' blocks, :mod:`ocp.contacts`), their rates, the object's pose (palm frame)."""

    t: FloatArray
    x: FloatArray
    u: FloatArray
    x_dot: FloatArray
    object_position: FloatArray
    object_rotation: FloatArray


@dataclass(frozen=True)
class ManipulationSolution:
    """A plan sampled on the collocation grid (nodes and midpoints, in time order)."""

    status: Status
    message: str
    raw_status: str
    iterations: int
    build_time: float
    solve_time: float
    t: FloatArray
    object_position: FloatArray
    object_rotation: FloatArray
    object_velocity: FloatArray  # [m/s], palm frame
    object_angular_velocity: FloatArray  # [rad/s], palm frame
    contacts: tuple[ContactTrajectory, ...]
    fingers: tuple[FingerTrajectory, ...]
    grasp_angle: FloatArray  # Phi*: the largest force angle over the contacts [rad]
    cone_margin: FloatArray  # atan(mu) - Phi* [rad]
    desired_position: FloatArray | None
    desired_rotation: FloatArray | None
    tracking_position_error: FloatArray | None  # [m]
    tracking_angle_error: FloatArray | None  # [rad]
    goal_error: dict[str, float]
    certificate: Certificate
    certificate_failures: tuple[str, ...] = ()
    refinements: int = 0
    #: The collocation grid's raw values (states, inputs), for warm starts.
    X: FloatArray = field(default_factory=lambda: np.zeros((0, 0)), repr=False)
    U: FloatArray = field(default_factory=lambda: np.zeros((0, 0)), repr=False)
    #: IPOPT's primal-dual point at this plan, for a warm start of the same NLP.
    nlp_point: NlpPoint | None = field(default=None, repr=False)
    #: Solver statistics of the whole plan (every initial guess tried, every refinement;
    #: ``solve_time`` here is the whole attempt loop, ``ipopt_time`` the IPOPT calls).
    stats: SolverStats | None = None
    #: The NLP's own values (for sampling and for the ball-on-palm's view).
    collocation: Collocation | None = field(default=None, repr=False)
    _sampler: Callable[[FloatArray], GraspSample] | None = field(
        default=None, repr=False, compare=False)

    @property
    def ok(self) -> bool:
        return self.status is Status.SOLVED

    @property
    def warm_start(self) -> WarmStart:
        """This plan as the initial guess of another (its collocation points' states and
        inputs, and IPOPT's primal-dual point for a plan of the same NLP)."""
        return WarmStart(self.t, self.X, self.U, self.nlp_point)

    @property
    def duration(self) -> float:
        return float(self.t[-1])

    def sample(self, t: FloatArray | list[float]) -> GraspSample:
        """The plan at any times in [0, duration], from the collocation polynomials (the
        states' cubic Hermite polynomial and the inputs' quadratic of each interval; a time
        on a via-point node gets the outgoing input)."""
        if self._sampler is None:
            raise ValueError("this plan has no collocation polynomials (non-finite values)")
        t = np.atleast_1d(np.asarray(t, dtype=float))
        if np.any((t < -1e-12) | (t > self.duration + 1e-12)):
            raise ValueError(f"sample times must lie in [0, {self.duration}] s")
        return self._sampler(np.clip(t, 0.0, self.duration))


def _sampler(m: GraspModel, col: Collocation, prm: FloatArray
             ) -> Callable[[FloatArray], GraspSample]:
    n = len(col.U0)
    F0 = np.asarray(m.mapped("dynamics", n)(col.X[:-1].T, col.U0.T, prm)).T
    F1 = np.asarray(m.mapped("dynamics", n)(col.X[1:].T, col.U1.T, prm)).T

    def sample(t: FloatArray) -> GraspSample:
        x, u = hermite_sample(col.t_nodes, col.X, F0, F1, col.U0, col.Um, col.U1, t)
        k = len(t)
        xd = np.asarray(m.dynamics.map(k)(x.T, u.T, prm)).T
        cart = m.cartesian.map(k)(x.T, prm)
        R = np.asarray(cart[0]).T.reshape(k, 3, 3).transpose(0, 2, 1)
        return GraspSample(t, x, u, xd, np.asarray(cart[1]).T, R)

    return sample


def assemble_solution(problem: ManipulationProblem, m: GraspModel, status: Status, raw: str,
                      col: Collocation, prm: FloatArray, cert: Certificate,
                      goal_error: dict[str, float]) -> ManipulationSolution:
    """The plan on its collocation grid (nodes and midpoints in time order): every
    contact's and finger's trajectory, the object's motion, force closure, tracking; the
    status made ``inaccurate`` when the certificate fails."""
    t_nodes, X, Xm, U0, Um, U1 = col.t_nodes, col.X, col.Xm, col.U0, col.Um, col.U1
    tm = (t_nodes[:-1] + t_nodes[1:]) / 2
    order = np.argsort(np.concatenate([t_nodes, tm]), kind="stable")
    t = np.concatenate([t_nodes, tm])[order]
    Xg = np.vstack([X, Xm])[order]
    Ug = np.vstack([np.vstack([U0, U1[-1:]]), Um])[order]
    k = len(t)
    xdot = np.asarray(m.mapped("dynamics", k)(Xg.T, Ug.T, prm)).T
    cart = m.mapped("cartesian", k)(Xg.T, prm)
    nc, nf = m.n_contacts, len(m.fingertips)
    R_po = np.asarray(cart[0]).T.reshape(k, 3, 3).transpose(0, 2, 1)
    p_po = np.asarray(cart[1]).T
    R_pf = np.asarray(cart[2]).T.reshape(k, nf, 3, 3).transpose(0, 1, 3, 2) \
        if nf else np.zeros((k, 0, 3, 3))
    p_pf = np.asarray(cart[3]).T.reshape(k, nf, 3)
    pts = np.asarray(cart[4]).T.reshape(k, nc, 3)
    nrm = np.asarray(cart[5]).T.reshape(k, nc, 3)
    laws = m.mapped("laws", k)(Xg.T, xdot.T, prm)
    v_obj, w_obj = np.asarray(laws[0]).T, np.asarray(laws[1]).T
    phi, angles, _ = force_angles(pts, nrm)
    margin = math.atan(problem.mu) - phi
    contacts = [ContactTrajectory(c.label(problem), c.body, Xg[:, c.eta_cols],
                                  xdot[:, c.eta_cols], Ug[:, c.w_cols], pts[:, j],
                                  nrm[:, j], angles[:, j])
                for j, c in enumerate(m.point_contacts)]
    fingers = [FingerTrajectory(tip.label(problem), tuple(tip.finger.joint_names),
                                Xg[:, tip.q_cols], Ug[:, tip.qd_cols], p_pf[:, i],
                                R_pf[:, i]) for i, tip in enumerate(m.fingertips)]
    Rd = Pd = ep = ea = None
    if problem.motion is not None:
        Rd, Pd = problem.motion.at(t)
        ep = np.linalg.norm(p_po - Pd, axis=1)
        ea = rotation_angle_between(Rd, R_po)
    failures = cert.failures
    if status is Status.SOLVED and failures:
        status = Status.INACCURATE
    message = {
        Status.SOLVED: "converged; certificate passed",
        Status.INACCURATE: "converged, but the certificate failed: " + "; ".join(failures),
    }.get(status, f"not solved: IPOPT {raw}; the last iterate is returned")
    finite = all(np.all(np.isfinite(a)) for a in (X, Xm, U0, Um, U1))
    return ManipulationSolution(
        status=status, message=message, raw_status=raw, iterations=0, build_time=0.0,
        solve_time=0.0, t=t, object_position=p_po, object_rotation=R_po,
        object_velocity=v_obj, object_angular_velocity=w_obj, contacts=tuple(contacts),
        fingers=tuple(fingers), grasp_angle=phi, cone_margin=margin, desired_position=Pd,
        desired_rotation=Rd, tracking_position_error=ep, tracking_angle_error=ea,
        goal_error=goal_error, certificate=cert, certificate_failures=failures, X=Xg, U=Ug,
        collocation=col, _sampler=_sampler(m, col, prm) if finite else None)
