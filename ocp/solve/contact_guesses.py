"""The initial guesses of each contact kind (the kinds' models: :mod:`ocp.contacts`);
:func:`ocp.solve.guesses.grasp_guess` assembles them.

* the object block's motion (:func:`object_guess`): for the support, the plan of the
  object on the palm alone (:func:`palm_subplan`, a sub-plan by the pipeline itself), or
  the object at rest; for the free object, the desired motion;
* a fingertip's contact coordinates (:func:`guess_contact`): the contact point kept where
  it started relative to the object's centre, the tip point and angle rolled along (RK4,
  :func:`roll`); for a round tip on a finger of fewer than six joints the closure-keeping
  integration instead (:func:`integrated_guess`), which gives the joints too;
* a fingertip's joints (:func:`guess_joints`): batched inverse kinematics of the tip poses
  the contact coordinates give.
"""

from __future__ import annotations

import weakref
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Protocol

import casadi as ca
import numpy as np
from numpy.typing import NDArray

from ocp.contacts import FingertipContact, FreeObject, ObjectBlock, SupportContact, SymbolicGrasp

if TYPE_CHECKING:
    from ocp.solution import ManipulationSolution
    from ocp.spec.grasp import ManipulationProblem

__all__ = ["GUESS_SUBSTEPS", "IK_GUESS_TOL", "InputOfTime", "ObjectGuess", "PoseOfTime",
           "SubPlanner", "guess_contact", "guess_joints", "integrated_guess", "object_guess",
           "palm_subplan", "roll"]

FloatArray = NDArray[np.float64]
#: The object's pose at times t: (R (k, 3, 3), p (k, 3)), palm frame.
PoseOfTime = Callable[[FloatArray], tuple[FloatArray, FloatArray]]
#: A block's input at times t, rows.
InputOfTime = Callable[[FloatArray], FloatArray]
#: An object block's guess: its states and inputs at the guess's times, the object's pose
#: as a function of time, and the block's input as one when it jumps (at via-points: the
#: guess then takes both sides), else None.
ObjectGuess = tuple[FloatArray, FloatArray, PoseOfTime, InputOfTime | None]

#: Pose tolerance of the inverse kinematics along the initial guess [m, rad], the initial
#: grasp's own. (A guess closed to 1e-8 only sent IPOPT down another path on experiment 1:
#: the same 14 iterations, one with an inertia correction, 30 % more time.)
IK_GUESS_TOL = 1e-10
#: Midpoint steps per collocation point of the integrated initial guess of a round tip on
#: a finger of fewer than six joints (:func:`integrated_guess`; its closure feedback keeps
#: it on the closure manifold). The first three four_finger_round plans of the full suite:
#: the same IPOPT iterations (25, 17, 20) with 8 and with 2, the plan's wall time
#: 11.0 / 6.9 / 7.6 s -> 7.7 / 4.3 / 5.5 s (under load).
GUESS_SUBSTEPS = 2

#: Each fingertip contact's CasADi functions of the guess, built once per contact (the
#: contacts live as long as their cached grasp model): its RK4 rolls by step count, its
#: closure terms.
_ROLLS: weakref.WeakKeyDictionary[FingertipContact, dict[int, Any]] = \
    weakref.WeakKeyDictionary()
_TERMS: weakref.WeakKeyDictionary[FingertipContact, Any] = weakref.WeakKeyDictionary()


class SubPlanner(Protocol):
    """What the support's guess asks of the pipeline: the plan of a sub-problem."""

    def solve(self, problem: ManipulationProblem, warm_start: Any = None, *,
              certify: bool = True) -> ManipulationSolution: ...


# -- the object blocks -------------------------------------------------------------------

def palm_subplan(planner: SubPlanner, problem: ManipulationProblem, ts: FloatArray
                 ) -> ObjectGuess:
    """The plan of the object on the palm alone to the support's goal and via-points
    (``problem.palm_only()`` by the pipeline's palm strategies: loop guesses for pure
    reorientations, gauge bound; not certified: a guess): its states and inputs at ts, the
    object's pose and the palm's input as functions of time (the input jumps at
    via-points)."""
    T = problem.duration
    plan = planner.solve(problem.palm_only(), certify=False)

    def pose(t: FloatArray) -> tuple[FloatArray, FloatArray]:
        tr = plan.sample(np.clip(t, 0.0, T))
        return tr.object_rotation, tr.object_position

    def palm_w(t: FloatArray) -> FloatArray:
        return np.asarray(plan.sample(t).u)

    smp = plan.sample(ts)
    return smp.x, smp.u, pose, palm_w


def _support_guess(planner: SubPlanner, problem: ManipulationProblem, x0: FloatArray,
                   ts: FloatArray, R0: FloatArray, p0: FloatArray) -> ObjectGuess:
    """The palm's sub-plan (:func:`palm_subplan`), or the object at rest when the support
    has no goal."""
    assert problem.palm is not None
    if problem.palm.goal or problem.palm.via_points:
        return palm_subplan(planner, problem, ts)

    def still(t: FloatArray) -> tuple[FloatArray, FloatArray]:
        t = np.atleast_1d(t)
        return np.tile(R0, (len(t), 1, 1)), np.tile(p0, (len(t), 1))

    return np.tile(x0, (len(ts), 1)), np.zeros((len(ts), 2)), still, None


def _free_object_guess(problem: ManipulationProblem, x0: FloatArray, ts: FloatArray
                       ) -> ObjectGuess:
    """The desired motion itself: its poses, its twist by central differences."""
    from ocp.geometry.rotations import quaternion_wxyz

    T = problem.duration
    assert problem.motion is not None
    motion = problem.motion
    R, pos = motion.at(ts)
    quats = quaternion_wxyz(R)
    for i in range(1, len(quats)):  # sign continuity
        if np.dot(quats[i], quats[i - 1]) < 0:
            quats[i] = -quats[i]
    if np.dot(quats[0], x0[3:7]) < 0:
        quats = -quats
    dt = 1e-5 * T
    Rp, pp = motion.at(ts + dt)
    Rn, pn = motion.at(ts - dt)
    tp, tn = np.clip(ts + dt, 0, T), np.clip(ts - dt, 0, T)
    span = (tp - tn)[:, None]
    v = (pp - pn) / span
    Wb = np.einsum("kji,kjl->kil", R, Rp - Rn) / span[:, :, None]  # R^T dR/dt
    omega = np.stack([Wb[:, 2, 1] - Wb[:, 1, 2], Wb[:, 0, 2] - Wb[:, 2, 0],
                      Wb[:, 1, 0] - Wb[:, 0, 1]], axis=1) / 2
    return np.hstack([pos, quats]), np.hstack([v, omega]), motion.at, None


def object_guess(planner: SubPlanner, problem: ManipulationProblem, block: ObjectBlock,
                 x0: FloatArray, ts: FloatArray, R0: FloatArray, p0: FloatArray
                 ) -> ObjectGuess:
    """The initial guess's object motion by the kind of object block: the block's states
    and inputs at times ts (from its state x0 at t = 0, the object's pose (R0, p0) then),
    the object's pose as a function of time, and the block's input as one when it jumps,
    else None."""
    if isinstance(block, SupportContact):
        return _support_guess(planner, problem, x0, ts, R0, p0)
    if isinstance(block, FreeObject):
        return _free_object_guess(problem, x0, ts)
    raise TypeError(f"no initial guess for the object block {type(block).__name__}")


# -- the fingertips ----------------------------------------------------------------------

def roll(contact: FingertipContact, steps: int) -> Any:
    """``steps`` RK4 steps of a round tip's point and the contact angle (a, b, psi) while
    the object point goes along given points and rates: (c0 (3), alpha (2 x k), w0 (2 x
    k), w1 (2 x k), h (1 x k), shape (. x k)) -> c (3 x k); the initial guess's roll."""
    rolls = _ROLLS.setdefault(contact, {})
    if steps not in rolls:
        np_ = contact.surface.n_params
        shape_p = ca.SX.sym("shape", np_)
        e_, w_ = ca.SX.sym("e", 5), ca.SX.sym("w", 2)
        rates = ca.Function("tip_rates", [e_, w_, shape_p], [
            contact.pair_rates(contact.surface, e_, w_, shape_p, contact.tip)])
        c_, a_ = ca.SX.sym("c", 3), ca.SX.sym("a", 2)
        w0_, w1_, h_ = ca.SX.sym("w0", 2), ca.SX.sym("w1", 2), ca.SX.sym("h")
        # one classic RK4 step (as the grasp model's for the flat pad)
        x0, wm = ca.vertcat(a_, c_), (w0_ + w1_) / 2
        k1 = rates(x0, w0_, shape_p)
        k2 = rates(x0 + h_ / 2 * k1, wm, shape_p)
        k3 = rates(x0 + h_ / 2 * k2, wm, shape_p)
        k4 = rates(x0 + h_ * k3, w1_, shape_p)
        e1 = x0 + h_ / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        step = ca.Function("roll_step", [c_, a_, w0_, w1_, h_, shape_p], [e1[2:5]])
        rolls[steps] = step.mapaccum("roll", steps)
    return rolls[steps]


def carries(contact: FingertipContact, problem: ManipulationProblem) -> bool:
    """Whether the initial guess is the integrated one (:func:`integrated_guess`): a round
    tip on a finger of fewer than 6 joints, whose joints cannot follow the 6-D poses of a
    tip rolled along a made-up contact path (closure would break)."""
    return contact.tip.round and int(contact.finger.nq) < 6


def guess_contact(contact: FingertipContact, problem: ManipulationProblem, pose: PoseOfTime,
                  ts: FloatArray, offset: FloatArray, chart: FloatArray, shape: FloatArray,
                  flat_roll: Any) -> tuple[FloatArray, FloatArray, FloatArray | None]:
    """The initial guess's contact coordinates and inputs at times ts, and the joints when
    the guess found them (the integrated guess, :func:`carries`; else None): the contact
    point kept where it started relative to the object's centre (``offset``, palm frame)
    while the object moves by ``pose``; its object point by the inverse chart, its rate by
    central differences, the tip point and angle rolled along (RK4 of the rolling
    equations: ``flat_roll``, the grasp model's for a flat pad, else :func:`roll` with the
    tip's curvature)."""
    if carries(contact, problem):
        return integrated_guess(contact, problem, pose, ts, chart, shape)
    steps = roll(contact, len(ts) - 1) if contact.tip.round else flat_roll
    dt = 1e-4 * problem.duration

    def ball_point(t: FloatArray) -> FloatArray:
        R, _ = pose(t)
        pts = np.einsum("kji,j->ki", R, offset)  # R^T offset
        return np.asarray(contact.surface.inverse(pts @ chart, shape))  # rows Rc^T p

    alpha = ball_point(ts)
    rate = (ball_point(ts + dt) - ball_point(ts - dt)) / (2 * dt)
    rate[:, 1] = ((rate[:, 1] * 2 * dt + np.pi) % (2 * np.pi) - np.pi) / (2 * dt)
    ef = np.zeros((len(ts), 5))
    ef[:, 2:4] = alpha
    ef[0] = contact.spec(problem).initial
    pad = np.asarray(steps(  # the pad point and angle, RK4 steps
        ef[0, [0, 1, 4]], alpha[:-1].T, rate[:-1].T, rate[1:].T, np.diff(ts)[None],
        np.tile(shape[:, None], (1, len(ts) - 1)))).T
    ef[1:, 0:2], ef[1:, 4] = pad[:, 0:2], pad[:, 2]
    return ef, rate, None


def closure_terms(contact: FingertipContact) -> Any:
    """CasADi function (eta, q, R_po, p_po, chart, shape) -> (C, C_eta E, C_q, C_R, C_p,
    E): the closure residual, its derivative along the contact inputs w (eta_dot = E w),
    along the joints, and along vec(R_po) and p_po."""
    if contact not in _TERMS:
        nq = int(contact.finger.nq)
        e, q = ca.SX.sym("eta", 5), ca.SX.sym("q", nq)
        R, p = ca.SX.sym("R", 3, 3), ca.SX.sym("p", 3)
        chart = ca.SX.sym("chart", 3, 3)
        shape = ca.SX.sym("shape", contact.surface.n_params)
        w = ca.SX.sym("w", 2)
        x = ca.vertcat(e, q)
        g = SymbolicGrasp(contact.surface, shape, x, ca.SX.sym("xd", 5 + nq), R_po=R, p_po=p)
        C = contact.closure(g, x, chart)
        ed = contact.rates(g, x, ca.vertcat(w, ca.SX.zeros(nq)), chart)[0:5]
        E = ca.jacobian(ed, w)
        _TERMS[contact] = ca.Function("closure_terms", [e, q, R, p, chart, shape], [
            C, ca.jacobian(C, e) @ E, ca.jacobian(C, q), ca.jacobian(C, ca.vec(R)),
            ca.jacobian(C, p), E])
    return _TERMS[contact]


def integrated_guess(contact: FingertipContact, problem: ManipulationProblem,
                     pose: PoseOfTime, ts: FloatArray, chart: FloatArray, shape: FloatArray
                     ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """A guess that rolls and closes: from the initial grasp (its joints by inverse
    kinematics), the contact inputs w and the joint rates that keep closure along the
    object's motion (d/dt closure = 0, solved at each step for (w, q_dot): six equations
    in 2 + nq unknowns, the least-norm solution, a feedback on the closure residual),
    integrated with small steps; the joints are clipped into their limits. Returns the
    contact coordinates, the contact inputs and the joints at ts."""
    from ocp.robots.finger import PAPER_SEED, inverse_kinematics

    f, spec = contact.finger, contact.spec(problem)
    nq = int(f.nq)
    terms = closure_terms(contact)
    e = np.asarray(spec.initial, dtype=float)
    R0, p0 = pose(np.asarray(ts[:1], dtype=float))
    # the initial grasp's joints: IK of the tip frame where the contact puts it
    g0 = SymbolicGrasp(contact.surface, ca.DM(shape), ca.DM(0, 1), ca.DM(0, 1),
                       R_po=ca.DM(R0[0]), p_po=ca.DM(p0[0]), none=ca.DM(0, 1),
                       eye=ca.DM.eye(3))
    R_l, p_l = (ca.evalf(a) for a in contact.pad_pose(g0, ca.DM(e), ca.DM(chart)))
    seed = np.asarray(spec.q_seed if spec.q_seed is not None else
                      PAPER_SEED[:nq], dtype=float)
    q = inverse_kinematics(f, np.asarray(R_l), np.asarray(p_l).ravel(), seed).q.copy()
    n_sub = GUESS_SUBSTEPS
    qs = np.zeros((len(ts), nq))
    ef = np.zeros((len(ts), 5))
    W = np.zeros((len(ts), 2))
    qs[0], ef[0] = q, e

    def inputs(t: float, e: FloatArray, q: FloatArray) -> tuple[FloatArray, FloatArray,
                                                                FloatArray]:
        dt = 1e-5 * problem.duration
        Rm, pm = pose(np.array([t - dt, t, t + dt]))
        C, Aw, Aq, CR, Cp, E = (np.asarray(a) for a in terms(
            e, q, Rm[1], pm[1], chart, shape))
        Rd = (Rm[2] - Rm[0]) / (2 * dt)
        pd = (pm[2] - pm[0]) / (2 * dt)
        rhs = -(CR @ Rd.ravel(order="F") + Cp @ pd) - 10.0 / problem.duration * \
            C.ravel()
        A = np.hstack([Aw, Aq])
        sol = A.T @ np.linalg.solve(A @ A.T + 1e-12 * np.eye(6), rhs)
        w, qd = sol[:2], sol[2:]
        return w, (E @ w).ravel(), qd

    for k in range(len(ts) - 1):
        h = (ts[k + 1] - ts[k]) / n_sub
        t = float(ts[k])
        for _ in range(n_sub):  # midpoint steps
            _, ed, qd = inputs(t, e, q)
            em, qm = e + h / 2 * ed, np.clip(q + h / 2 * qd, f.lower, f.upper)
            _, ed, qd = inputs(t + h / 2, em, qm)
            e, q = e + h * ed, np.clip(q + h * qd, f.lower, f.upper)
            t += h
        W[k] = inputs(float(ts[k]), ef[k], qs[k])[0]
        ef[k + 1], qs[k + 1] = e, q
    W[-1] = inputs(float(ts[-1]), ef[-1], qs[-1])[0]
    return ef, W, qs


def guess_joints(contact: FingertipContact, R: FloatArray, p: FloatArray, q0: FloatArray,
                 ts: FloatArray, found: FloatArray | None = None
                 ) -> tuple[FloatArray, FloatArray]:
    """The joints (and their rates, by differences) that put the pad at the poses (R (k, 3,
    3), p (k, 3)) at times ts: the joints the contact's guess ``found`` (from the initial
    grasp's q0) when it has them, else one batched inverse kinematics from q0, and a
    sequential one from the previous point's where that does not converge."""
    from ocp.robots.finger import inverse_kinematics, inverse_kinematics_batch

    if found is not None:
        qs = found.copy()
        qs[0] = q0
        return qs, np.gradient(qs, ts, axis=0)
    qs, ok = inverse_kinematics_batch(contact.finger, R, p, q0, tol=IK_GUESS_TOL)
    qs[0] = q0
    for j in (np.flatnonzero(~ok[1:]) + 1).tolist():  # from a neighbour instead
        qs[j] = inverse_kinematics(contact.finger, R[j], p[j], qs[j - 1],
                                   tol=IK_GUESS_TOL).q
    return qs, np.gradient(qs, ts, axis=0)
