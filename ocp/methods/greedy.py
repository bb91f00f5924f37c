"""The paper's own method (section 3) for one flat fingertip rolling a ball on the palm.

A second method for :class:`~ocp.one_finger.OneFingerProblem`, beside the NLP of
:mod:`ocp.one_finger`: instead of optimising the whole motion at once it follows the
paper step by step over the time grid t_k = k dt, dt = duration / n_steps.

1. **Palm contact path.** The ball-on-palm problem ``problem.base`` is planned by
   :class:`~ocp.ball_on_palm.BallOnPalmPlanner` (min-effort collocation; the paper leaves the
   nonholonomic planning technique open). Its input w_p(t) = d/dt (x, y) (the paper's
   alpha_dot_p) is integrated with the rolling equations (RK4, with knots at the plan's
   collocation nodes and via-points, so that the piecewise-quadratic input with corners at
   via-points is integrated without crossing a corner), giving eta_p(t_k).
2. **Finger contact velocity over the ball, greedily.** At each t_k the finger contact's
   velocity over the ball w_f = alpha_dot_of [rad/s] is chosen to minimise
   F1 = max(Phi_p, Phi_f) at t_k + dt subject to F2 = |Delta Theta| <= delta. The grasp
   angles after the step are evaluated exactly on the stepped configuration: the palm
   contact point on the ball after the palm's step and the finger contact point
   alpha_of + w_f dt (the ball coordinates of a contact driven by its motion over the ball
   advance exactly so). That is the paper's first-order prediction, without its linearised
   normals. The search is the paper's grid search inside the ellipse that the rotation
   bound maps to in alpha_dot_of space (see :func:`rotation_ellipse`): a polar grid of
   ``grid = (n_radii, n_angles)`` points plus the origin. Candidates that would put the
   contact within ``problem.pad_margin`` of the pad's edge, outside the friction cone, or
   beyond the finger chart's pole margin are rejected when any other candidate is left;
   if none is left, the least-violating candidate is taken (counted in
   ``GreedyResult.fallback_steps``). Ties in F1 (within 1e-12 rad) go to the smallest
   rotation.
3. **Finger contact coordinates.** eta_f is integrated one step with the rolling equations
   (RK4, w_f held over the step): ``ContactPair(ball, pad).rates_driven_by_a`` with the ball
   side as the input. That pair orders its coordinates (u_f, v_f, x_f, y_f, psi_f); the
   paper's order (x_f, y_f, u_f, v_f, psi_f) is used everywhere outside it.
4. **Joint rates (eq. 5, 7).** The fingertip pose implied by the contact coordinates is
   g_pf(eta_p, eta_f) = g_po(eta_p) g_of(eta_f) (eq. 6, by ``ContactPair.pose``). Its
   velocity over the step, V_pf, is its numerical derivative: the secant twist from
   g_pf(t_k) to g_pf(t_k+1) (linear velocity of the frame's origin and angular velocity,
   both in palm coordinates, the row convention of
   :meth:`~ocp.robots.finger.FingerModel.frame_jacobian_pin`). Then
   q_dot = pinv(J(q_k)) (V_pf + c e_k / dt) and q_k+1 = q_k + q_dot dt, with e_k the closure
   error at t_k (position; rotation vector, palm frame) between the contact-derived pose
   and Pinocchio's forward kinematics of q_k. The **closure correction** c
   (``closure_gain``, default 1) is not in the paper: it pulls the joints back to the
   contact-derived pose (one Gauss-Newton step of inverse kinematics per step) so that
   Euler integration of the joints does not drift. ``closure_gain = 0`` is the paper's
   open-loop pseudo-inverse.

The paper's method has no notion of the finger's workspace, joint limits or singularities:
the result reports (``GreedyResult.failures``, ``ok``) the first time the closure error
exceeds :data:`CLOSURE_TOL`, a joint leaves its position or velocity limits, the grasp
leaves the friction cone, or no candidate was feasible; the plan is computed to the end
either way.

The rotation bound (section 3) with the paper's slip corrected (shared notes): with the
finger F as body A of eq. 3 and the ball O as body B,
``(-Delta Theta_y, Delta Theta_x) = (K_f + K~_of) R_psi M_o alpha_dot_of dt`` (the paper
prints ``(K_f + K~_of)^-1``), K~_of = R_psi K_o R_psi. For the flat pad K_f = 0 and this is
``R_psi K_o M_o alpha_dot_of dt`` = ``(1/rho) R_psi M_o alpha_dot_of dt`` for a sphere.

Units: SI (m, rad, s).
"""

from __future__ import annotations

import math
import time
from functools import cache
from typing import Any

import casadi as ca
import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike, NDArray

from ocp.ball_on_palm import BallOnPalmPlanner, coordinate_error
from ocp.geometry.contact import ContactPair
from ocp.geometry.grasp import grasp_cosines
from ocp.geometry.surfaces import Plane, Surface, rotation_from_vector
from ocp.methods.greedy_result import GreedyResult
from ocp.one_finger import OneFingerPlanner, OneFingerProblem
from ocp.solution import Solution
from ocp.spec.problem import CONTACT_COORDS, ProblemError
from ocp.transcription.collocation import rk4_step

__all__ = [
    "CLOSURE_TOL",
    "DEFAULT_GRID",
    "DEFAULT_N_STEPS",
    "DEFAULT_ROLLING_RATE",
    "GreedyResult",
    "candidate_grid",
    "greedy_plan",
    "rotation_angle",
    "rotation_ellipse",
]

FloatArray = NDArray[np.float64]

#: Default number of time steps over the horizon.
DEFAULT_N_STEPS = 200
#: Default bound on the finger's rolling speed over the ball [rad/s]: ``delta = None``
#: bounds the rolling angle per step by |Delta Theta| <= DEFAULT_ROLLING_RATE dt, so that
#: the bound means the same whatever n_steps. To keep the contact antipodal the finger must
#: roll over the ball as fast as the ball rolls on the palm (|w_p| / rho): 0.6-0.85 rad/s
#: on the paper's triangle (a 25 mm ball, 30 mm sides in 2 s); 1.5 rad/s leaves room to
#: correct a grasp while the ball rolls, and keeps the built-in finger's joint rates within
#: their limits (2-3 rad/s). At 200 steps over 2-6 s this is 0.015-0.045 rad per step.
DEFAULT_ROLLING_RATE = 1.5
#: Closure errors above these [m, rad] mark a plan as failed (the finger left its
#: workspace, met a singularity or diverged); the same tolerances as the NLP's certificate.
CLOSURE_TOL = (1e-4, 1e-3)
#: Default polar search grid (radii, angles) inside the rotation ellipse (plus its centre).
DEFAULT_GRID = (9, 24)
#: F1 values within this of the best [rad] are ties, broken by the smaller rotation.
_TIE_TOL = 1e-12
#: 90 deg rotation J with J (a, b) = (-b, a): (-DTheta_y, DTheta_x) = J (DTheta_x, DTheta_y).
_J90 = np.array([[0.0, -1.0], [1.0, 0.0]])


# -- the rotation bound -----------------------------------------------------------------------

def _R_psi(psi: float) -> FloatArray:
    c, s = math.cos(psi), math.sin(psi)
    return np.array([[c, -s], [-s, -c]])


def rotation_angle(M_o: ArrayLike, K_o: ArrayLike, psi_f: float, w_f: ArrayLike, dt: float,
                   K_f: ArrayLike | None = None) -> FloatArray:
    """(Delta Theta_x, Delta Theta_y) [rad]: the finger's rolling angle over one step.

    ``(-Delta Theta_y, Delta Theta_x) = (K_f + R_psi K_o R_psi) R_psi M_o w_f dt`` (the
    paper's expression with its slip corrected: K is not inverted). ``M_o`` [m], ``K_o``
    [1/m] are the ball's metric and curvature at the finger contact (in its chart patch),
    ``w_f`` = alpha_dot_of [rad/s], ``K_f`` the pad's curvature (None: flat, 0).
    """
    M, K = np.asarray(M_o, dtype=float), np.asarray(K_o, dtype=float)
    Kf = np.zeros((2, 2)) if K_f is None else np.asarray(K_f, dtype=float)
    Rp = _R_psi(psi_f)
    rel = (Kf + Rp @ K @ Rp) @ Rp @ M @ np.asarray(w_f, dtype=float) * dt
    return np.array([rel[1], -rel[0]])


def rotation_ellipse(M_o: ArrayLike, K_o: ArrayLike, psi_f: float, dt: float,
                     K_f: ArrayLike | None = None) -> FloatArray:
    """The paper's A with ``A (Delta Theta_x, Delta Theta_y) = alpha_dot_of`` [1/s].

    Inverting :func:`rotation_angle`:
    ``A = (1/dt) M_o^-1 R_psi (K_f + R_psi K_o R_psi)^-1 J``, J = [[0, -1], [1, 0]]; for
    the flat pad (K_f = 0) ``A = (1/dt) M_o^-1 K_o^-1 R_psi J``, and for a sphere of radius
    rho ``A = (1/dt) diag(1, 1/cos u_f) R_psi J``. (The paper prints M_o^-1 K_o R_psi J /
    dt, consistent with neither its own rotation formula nor the corrected one.) A maps
    the disc |Delta Theta| <= delta onto an ellipse with principal axes U and semi-axes
    sigma_i delta, ``A = U diag(sigma) V^T``.
    """
    M, K = np.asarray(M_o, dtype=float), np.asarray(K_o, dtype=float)
    Kf = np.zeros((2, 2)) if K_f is None else np.asarray(K_f, dtype=float)
    Rp = _R_psi(psi_f)
    return np.asarray(np.linalg.solve(M, Rp @ np.linalg.solve(Kf + Rp @ K @ Rp, _J90)) / dt)


def candidate_grid(n_radii: int, n_angles: int) -> FloatArray:
    """2 x (1 + n_radii n_angles) points of the unit disc: the centre, then radii
    i / n_radii (i = 1..n_radii) at angles 2 pi j / n_angles (j = 0..n_angles - 1)."""
    r = np.arange(1, n_radii + 1) / max(n_radii, 1)
    th = 2 * np.pi * np.arange(n_angles) / max(n_angles, 1)
    rr, tt = np.meshgrid(r, th, indexing="ij")
    pts = np.vstack([(rr * np.cos(tt)).ravel(), (rr * np.sin(tt)).ravel()])
    return np.hstack([np.zeros((2, 1)), pts])


# -- the result -------------------------------------------------------------------------------

class _Kinematics:
    """CasADi functions of the palm + flat finger contact for one object surface."""

    def __init__(self, surface: Surface) -> None:
        self.surface = surface
        palm = ContactPair(Plane, surface)  # A = palm, B = ball
        tip = ContactPair(surface, Plane)  # A = ball (finger patch), B = pad
        none = ca.SX(0, 1)
        eye = ca.SX.eye(3)
        ep = ca.SX.sym("eta_p", 5)
        ef = ca.SX.sym("eta_f", 5)  # paper order (x_f, y_f, u_f, v_f, psi_f)
        w = ca.SX.sym("w", 2)
        h = ca.SX.sym("h")
        shape = ca.SX.sym("shape", surface.n_params)
        Rcp = ca.SX.sym("Rcp", 3, 3)
        Rcf = ca.SX.sym("Rcf", 3, 3)

        self.palm_rates = ca.Function(
            "palm_rates", [ep, w, shape], [palm.rates_driven_by_a(ep, w, none, shape)])

        def pair_order(e: Any) -> Any:  # paper order <-> the pair's (u, v, x, y, psi)
            return ca.vertcat(e[2:4], e[0:2], e[4])

        def tip_rates(e: Any) -> Any:
            d = tip.rates_driven_by_a(pair_order(e), w, shape, none)
            return pair_order(d)

        # w is held over the step: the input argument of the RK4 step is unused
        step = rk4_step(lambda e, _u: tip_rates(e), ef, None, None, None, h)
        self.tip_step = ca.Function("tip_rk4", [ef, w, shape, h], [step])
        self._tip_step_maps: dict[int, ca.Function] = {}

        # grasp angles from the two contact points on the ball (ball frame)
        ap = ca.SX.sym("alpha_op", 2)
        af = ca.SX.sym("alpha_of", 2)
        pc_p, Rg_p, _, _, _ = surface.geometry(ap, shape)
        pc_f, Rg_f, M_f, K_f, _ = surface.geometry(af, shape)
        p1, n1 = Rcp @ pc_p, Rcp @ Rg_p[:, 2]
        p2, n2 = Rcf @ pc_f, Rcf @ Rg_f[:, 2]
        c1, c2, dist = grasp_cosines(p1, n1, p2, n2)

        def clipped_acos(c: Any) -> Any:
            return ca.acos(ca.fmin(ca.fmax(c / dist, -1), 1))

        self.grasp = ca.Function("grasp_angles", [ap, af, shape, Rcp, Rcf],
                                 [ca.vertcat(clipped_acos(c1), clipped_acos(c2))])
        self._grasp_maps: dict[int, ca.Function] = {}
        self.metric_curvature = ca.Function("ball_M_K", [af, shape], [M_f, K_f])

        # poses (eq. 6) and Cartesian contact data, palm frame
        R_po, p_po = palm.pose(ep, none, shape, eye, Rcp)
        R_of, p_of = tip.pose(pair_order(ef), shape, none, Rcf, eye)
        pc_p2, _, _, _, _ = surface.geometry(ep[2:4], shape)
        pc_f2, Rg_f2, _, _, _ = surface.geometry(ef[2:4], shape)
        self.cartesian = ca.Function(
            "greedy_cartesian", [ep, ef, shape, Rcp, Rcf],
            [R_po, p_po, R_po @ R_of, p_po + R_po @ p_of, p_po + R_po @ (Rcp @ pc_p2),
             p_po + R_po @ (Rcf @ pc_f2), R_po @ (Rcf @ Rg_f2[:, 2])],
            ["eta_p", "eta_f", "shape", "Rcp", "Rcf"],
            ["R_po", "p_po", "R_pf", "p_pf", "palm_contact", "finger_contact",
             "finger_normal"])

    def tip_step_map(self, n: int) -> ca.Function:
        if n not in self._tip_step_maps:
            self._tip_step_maps[n] = self.tip_step.map(n)
        return self._tip_step_maps[n]

    def grasp_map(self, n: int) -> ca.Function:
        if n not in self._grasp_maps:
            self._grasp_maps[n] = self.grasp.map(n)
        return self._grasp_maps[n]


@cache
def _kinematics(surface: Surface) -> _Kinematics:
    return _Kinematics(surface)


# -- helpers ----------------------------------------------------------------------------------

def _rotation_error(R_a: FloatArray, R_b: FloatArray) -> float:
    """Angle of R_a^T R_b [rad]."""
    c = (np.trace(R_a.T @ R_b) - 1.0) / 2.0
    return float(math.acos(min(1.0, max(-1.0, c))))


def _integrate_palm(kin: _Kinematics, plan: Solution, eta0: FloatArray, knots: FloatArray,
                    shape: FloatArray, duration: float) -> FloatArray:
    """eta_p at every knot by RK4 between consecutive knots, the palm plan's input sampled
    at the start (right limit), middle and end (left limit) of each piece."""
    a, b = knots[:-1], knots[1:]
    eps = 1e-9 * duration
    w = plan.sample(np.concatenate([a, (a + b) / 2, np.maximum(b - eps, a)])).w
    n = len(a)
    w0, wm, w1 = w[:n], w[n:2 * n], w[2 * n:]
    eta = np.zeros((len(knots), 5))
    eta[0] = eta0
    f = kin.palm_rates
    for i in range(n):
        eta[i + 1] = rk4_step(lambda x, u: np.asarray(f(x, u, shape)).ravel(), eta[i],
                              w0[i], wm[i], w1[i], b[i] - a[i])
    return eta


def _merge_knots(times: FloatArray, tol: float) -> FloatArray:
    """Sorted times with neighbours closer than ``tol`` merged (the first kept)."""
    s = np.sort(times)
    keep = np.concatenate([[True], np.diff(s) > tol])
    return s[keep]


def _index_of(knots: FloatArray, t: float) -> int:
    return int(np.argmin(np.abs(knots - t)))


# -- the planner ------------------------------------------------------------------------------

def _checked_settings(problem: OneFingerProblem, n_steps: int, delta: float | None,
                      grid: tuple[int, int], closure_gain: float) -> float:
    """The rolling bound per step (``delta``, its default when None); ProblemError naming
    every bad field of the problem and the settings."""
    errs = list(problem.errors())
    if not (isinstance(n_steps, int) and 1 <= n_steps <= 100_000):
        errs.append(("n_steps", f"must be an integer in [1, 100000], got {n_steps!r}"))
        n_steps = DEFAULT_N_STEPS
    if delta is None:
        delta = DEFAULT_ROLLING_RATE * problem.base.duration / n_steps
    if not (math.isfinite(delta) and 0.0 <= delta <= 1.0):
        errs.append(("delta", f"must be in [0, 1] rad per step, got {delta}"))
    if not (len(grid) == 2 and grid[0] >= 0 and grid[1] >= 1):
        errs.append(("grid", f"must be (n_radii >= 0, n_angles >= 1), got {grid}"))
    if not (math.isfinite(closure_gain) and 0.0 <= closure_gain <= 1.0):
        errs.append(("closure_gain", f"must be in [0, 1], got {closure_gain}"))
    if errs:
        raise ProblemError(errs)
    return delta


def _failures(t: FloatArray, pos_err: FloatArray, rot_err: FloatArray, margins: FloatArray,
              ratios: FloatArray, cone_margin: FloatArray, fallback_at: NDArray[np.bool_]
              ) -> tuple[list[str], list[float]]:
    """What the greedy plan breaks and from when: (messages, their first times)."""
    checks = (
        (f"closure error beyond {CLOSURE_TOL[0]:g} m / {CLOSURE_TOL[1]:g} rad (the finger "
         f"cannot follow the contacts: workspace boundary, singularity or divergence)",
         (pos_err > CLOSURE_TOL[0]) | (rot_err > CLOSURE_TOL[1])),
        ("joints beyond their position limits", margins < 0.0),
        ("joint rates beyond their velocity limits", ratios > 1.0),
        ("grasp outside the friction cone", cone_margin < 0.0),
        ("no candidate kept the contact on the pad, in the cone and off the chart poles",
         fallback_at),
    )
    failures: list[str] = []
    first: list[float] = []
    for what, bad in checks:
        if np.any(bad):
            t_bad = float(t[int(np.argmax(bad))])
            failures.append(f"{what} from t = {t_bad:.4g} s")
            first.append(t_bad)
    return failures, first


def _greedy_steps(problem: OneFingerProblem, kin: Any, eta_p: FloatArray, q0: FloatArray,
                  shape: FloatArray, Rcp: FloatArray, Rcf: FloatArray, dt: float,
                  delta: float, grid: tuple[int, int], closure_gain: float
                  ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray,
                             NDArray[np.bool_], float]:
    """Steps 2-4 of the method along the palm path ``eta_p``: at each step the candidate
    finger contact rates in the rotation ellipse, the one with the smallest grasp angle
    that keeps the contact on the pad, in the cone and off the chart poles (the least
    violating one when none does: ``fallback_at``), the finger's coordinates stepped, and
    its joints by the pseudo-inverse of the secant twist with the closure correction:
    (eta_f, q, q_dot, w_f, rotation steps, fallback steps, the Jacobian's smallest singular
    value)."""
    base, finger = problem.base, problem.finger
    n_steps = len(eta_p) - 1
    # 2.-4. greedy finger contact, its coordinates, the joints
    unit = candidate_grid(grid[0], grid[1]) if grid[0] > 0 else np.zeros((2, 1))
    unit_radius = np.linalg.norm(unit, axis=0)
    n_c = unit.shape[1]
    step_map = kin.tip_step_map(n_c)
    grasp_map = kin.grasp_map(n_c)
    cone = math.atan(problem.mu)
    pad_lim = float(finger.pad_half_size) - problem.pad_margin
    u_lim = base.object.u_limit(base.pole_margin)
    L = base.object.length_scale

    nq = finger.nq
    eta_f = np.zeros((n_steps + 1, 5))
    eta_f[0] = problem.contact.initial
    q = np.zeros((n_steps + 1, nq))
    q[0] = q0
    q_dot = np.zeros((n_steps + 1, nq))
    w_f = np.zeros((n_steps + 1, 2))
    rot_step = np.zeros(n_steps + 1)
    fallback_at = np.zeros(n_steps + 1, dtype=bool)
    min_sv = math.inf

    def contact_pose(k: int) -> tuple[FloatArray, FloatArray]:
        out = kin.cartesian(eta_p[k], eta_f[k], shape, Rcp, Rcf)
        return np.asarray(out[2]), np.asarray(out[3]).ravel()

    R_star, p_star = contact_pose(0)
    for k in range(n_steps):
        ef = eta_f[k]
        M_o, K_o = (np.asarray(a) for a in kin.metric_curvature(ef[2:4], shape))
        A = rotation_ellipse(M_o, K_o, ef[4], dt)
        U, S, _ = np.linalg.svd(A)
        cand = (U * S) @ (delta * unit)  # 2 x n_c values of alpha_dot_of [rad/s]
        E = np.asarray(step_map(ef, cand, shape, dt))  # 5 x n_c stepped eta_f
        ap_next = np.tile(eta_p[k + 1, 2:4][:, None], (1, n_c))
        phis = np.asarray(grasp_map(ap_next, E[2:4], shape, Rcp, Rcf))
        F1 = phis.max(axis=0)
        viol = (np.maximum(np.abs(E[0:2]).max(axis=0) - pad_lim, 0.0) / L
                + np.maximum(F1 - cone, 0.0)
                + np.maximum(np.abs(E[2]) - u_lim, 0.0))
        ok = viol <= 0.0
        if ok.any():
            score = np.where(ok, F1, np.inf)
        else:
            fallback_at[k] = True
            score = np.where(viol <= viol.min() + _TIE_TOL, F1, np.inf)
        ties = np.flatnonzero(score <= score.min() + _TIE_TOL)
        j = int(ties[np.argmin(unit_radius[ties])])
        w_f[k] = cand[:, j]
        rot_step[k] = delta * unit_radius[j]
        eta_f[k + 1] = E[:, j]

        # joints: secant twist of the contact-derived pose plus the closure correction
        R_next, p_next = contact_pose(k + 1)
        v = (p_next - p_star) / dt
        omega = np.asarray(pin.log3(R_next @ R_star.T)) / dt
        R_fk, p_fk = finger.fingertip_pose_pin(q[k])
        e = np.concatenate([p_star - p_fk, np.asarray(pin.log3(R_star @ R_fk.T))])
        J = finger.frame_jacobian_pin(q[k])
        min_sv = min(min_sv, float(np.linalg.svd(J, compute_uv=False)[-1]))
        q_dot[k] = np.linalg.pinv(J) @ (np.concatenate([v, omega]) + closure_gain * e / dt)
        q[k + 1] = q[k] + q_dot[k] * dt
        R_star, p_star = R_next, p_next
    return eta_f, q, q_dot, w_f, rot_step, fallback_at, min_sv


def greedy_plan(
    problem: OneFingerProblem,
    n_steps: int = DEFAULT_N_STEPS,
    delta: float | None = None,
    grid: tuple[int, int] = DEFAULT_GRID,
    closure_gain: float = 1.0,
    palm_plan: Solution | None = None,
    planner: OneFingerPlanner | None = None,
) -> GreedyResult:
    """Plan by the paper's section-3 method (see the module docstring).

    ``delta`` bounds the finger's rolling angle per step [rad] (None:
    :data:`DEFAULT_ROLLING_RATE` times dt; 0: the finger contact never moves over the
    ball); ``grid = (n_radii, n_angles)`` is the polar search grid in the
    rotation ellipse, plus its centre (n_radii = 0: the centre only); ``closure_gain`` in
    [0, 1] is the fraction of the closure error at t_k removed over the step (0: open-loop
    pseudo-inverse, as in the paper). ``palm_plan`` reuses a ball-on-palm plan of
    ``problem.base``; ``planner`` supplies the initial grasp (IK, ``initial_grasp``).

    Raises :class:`~ocp.spec.problem.ProblemError` for an invalid problem or settings, an
    initial grasp that is impossible, or a palm plan that failed.
    """
    t_start = time.perf_counter()
    delta = _checked_settings(problem, n_steps, delta, grid, closure_gain)
    base, finger = problem.base, problem.finger
    q0 = (planner or OneFingerPlanner()).initial_grasp(problem)

    # 1. palm contact path
    t_palm = time.perf_counter()
    if palm_plan is None:
        palm_plan = BallOnPalmPlanner().solve(base)
        if not palm_plan.ok:
            raise ProblemError([("base", f"the ball-on-palm plan failed: {palm_plan.message}")])
    palm_plan_time = time.perf_counter() - t_palm

    kin = _kinematics(base.object.surface)
    shape = np.asarray(base.object.params, dtype=float)
    Rcp = rotation_from_vector(base.object.chart_rotation)
    Rcf = rotation_from_vector(problem.contact.chart_rotation)
    T = base.duration
    dt = T / n_steps
    t = np.linspace(0.0, T, n_steps + 1)
    seg = base.segment_times
    knots = _merge_knots(np.concatenate([t, palm_plan.nodes.t, seg]), 1e-9 * T)
    eta_knots = _integrate_palm(kin, palm_plan, np.asarray(base.initial, dtype=float), knots,
                                shape, T)
    grid_idx = np.array([_index_of(knots, tk) for tk in t])
    eta_p = eta_knots[grid_idx]
    sampled = palm_plan.sample(t)
    w_p = sampled.w
    d = eta_p - sampled.eta
    d[:, 3:] = (d[:, 3:] + np.pi) % (2 * np.pi) - np.pi
    palm_integration_error = float(np.max(np.abs(d)))

    # 2.-4. greedy finger contact, its coordinates, the joints
    eta_f, q, q_dot, w_f, rot_step, fallback_at, min_sv = _greedy_steps(
        problem, kin, eta_p, q0, shape, Rcp, Rcf, dt, delta, grid, closure_gain)

    # 5. Cartesian quantities and reports
    n = n_steps + 1
    cart = kin.cartesian.map(n)(eta_p.T, eta_f.T, shape, Rcp, Rcf)

    def rotations(a: Any) -> FloatArray:
        return np.asarray(a).T.reshape(n, 3, 3).transpose(0, 2, 1)

    R_po, p_po = rotations(cart[0]), np.asarray(cart[1]).T
    R_pf, p_pf = rotations(cart[2]), np.asarray(cart[3]).T
    cp, cf, nf = (np.asarray(c).T for c in cart[4:7])
    phis_all = np.asarray(kin.grasp.map(n)(eta_p[:, 2:4].T, eta_f[:, 2:4].T, shape, Rcp,
                                           Rcf)).T
    R_fk_all = np.zeros((n, 3, 3))
    p_fk_all = np.zeros((n, 3))
    pos_err = np.zeros(n)
    rot_err = np.zeros(n)
    pad_point = np.zeros((n, 3))
    for k in range(n):
        R_fk_all[k], p_fk_all[k] = finger.fingertip_pose_pin(q[k])
        pos_err[k] = float(np.linalg.norm(p_fk_all[k] - p_pf[k]))
        rot_err[k] = _rotation_error(R_fk_all[k], R_pf[k])
        pad_point[k] = R_fk_all[k].T @ (cf[k] - p_fk_all[k])

    goal_error: dict[str, float] = {}
    for jv, vp in enumerate(base.via_points):
        eta_v = eta_knots[_index_of(knots, vp.time)]
        for c, val in vp.coords.items():
            goal_error[f"via_points[{jv}].{c}"] = coordinate_error(
                c, float(eta_v[CONTACT_COORDS.index(c)]), val)
    for c, val in base.goal.items():
        goal_error[f"goal.{c}"] = coordinate_error(
            c, float(eta_p[-1, CONTACT_COORDS.index(c)]), val)

    margins = np.minimum(q - finger.lower, finger.upper - q).min(axis=1)
    ratios = (np.abs(q_dot) / np.asarray(finger.velocity_limit)).max(axis=1)
    cone_margin = math.atan(problem.mu) - phis_all.max(axis=1)
    failures, first = _failures(t, pos_err, rot_err, margins, ratios, cone_margin,
                                fallback_at)
    return GreedyResult(
        t=t, eta_p=eta_p, eta_f=eta_f, q=q, q_dot=q_dot, w_p=w_p, w_f=w_f,
        rotation_step=rot_step, grasp_angles=phis_all,
        cone_margin=cone_margin,
        fingertip_rotation=R_fk_all, fingertip_position=p_fk_all,
        contact_fingertip_rotation=R_pf, contact_fingertip_position=p_pf,
        closure_position_error=pos_err, closure_rotation_error=rot_err,
        object_rotation=R_po, object_position=p_po, palm_contact_point=cp,
        finger_contact_point=cf, finger_contact_normal=nf, pad_point=pad_point,
        goal_error=goal_error, closure_error=(float(pos_err.max()), float(rot_err.max())),
        joint_effort=float(np.sum(q_dot**2) * dt),
        compute_time=time.perf_counter() - t_start, palm_plan_time=palm_plan_time,
        joint_limit_margin=float(margins.min()), max_velocity_ratio=float(ratios.max()),
        min_jacobian_singular_value=min_sv, fallback_steps=int(fallback_at.sum()),
        palm_integration_error=palm_integration_error, dt=dt, delta=delta,
        grid=(int(grid[0]), int(grid[1])), closure_gain=closure_gain,
        failures=tuple(failures), failure_time=min(first) if first else None,
        palm_plan=palm_plan)
