"""One flat fingertip rolling a ball on the palm: the paper's section 3 as one NLP.

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
import time
from dataclasses import dataclass, field, replace
from typing import Any

import casadi as ca
import numpy as np
from numpy.typing import NDArray

from .ball_on_palm import (
    IPOPT_OPTIONS,
    BallOnPalmPlanner,
    Structure,
    _StopCallback,
    model_for,
)
from .collocation import HermiteSimpson, reintegrate, reintegrator
from .contact import ContactPair
from .grasp import cone_cosine, grasp_angles_numeric, grasp_cosines
from .problem import CONTACT_COORDS, PERIODIC, BallOnPalmProblem
from .solution import Status, status_from_ipopt
from .surfaces import SURFACES, Plane, rotation_from_vector

__all__ = ["FingerContact", "OneFingerPlanner", "OneFingerProblem", "OneFingerSolution"]

FloatArray = NDArray[np.float64]

#: The paper's initial joint angles of experiment 1 [deg]: the default IK seed.
PAPER_SEED_DEG = (0.0, -22.68, -12.34, 0.0, 47.65, 0.0)


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
    chart_rotation: tuple[float, float, float] = (math.pi / 2, 0.0, 0.0)
    q_seed: tuple[float, ...] | None = None


@dataclass(frozen=True)
class OneFingerProblem:
    """The ball-on-palm problem (``base``: object, palm contact, goals, grid, limits) with a
    finger pressing on the ball."""

    base: BallOnPalmProblem
    finger: Any  # ocp.finger.FingerModel
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

    def errors(self) -> list[tuple[str, str]]:
        errs = list(self.base.errors())
        if not (math.isfinite(self.mu) and 0.0 < self.mu <= 10.0):
            errs.append(("mu", f"must be in (0, 10], got {self.mu}"))
        for name in ("grasp_weight", "finger_effort_weight", "joint_effort_weight"):
            value = getattr(self, name)
            if not (math.isfinite(value) and 0.0 <= value <= 1e6):
                errs.append((name, f"must be in [0, 1e6], got {value}"))
        c = self.contact
        why = self.base.object.surface.chart_rotation_error(
            rotation_from_vector(c.chart_rotation)) if self.base.object.shape in SURFACES \
            else None
        if why is not None:
            errs.append(("finger_contact.chart_rotation", why))
        if len(c.initial) != 5 or not all(map(math.isfinite, c.initial)):
            errs.append(("finger_contact.initial", "must be 5 finite numbers "
                                                   "(x_f, y_f, u_f, v_f, psi_f)"))
        half = float(self.finger.pad_half_size) - self.pad_margin
        if len(c.initial) == 5:
            for i, name in ((0, "x_f"), (1, "y_f")):
                if abs(c.initial[i]) > half:
                    errs.append((f"finger_contact.initial.{name}",
                                 f"|{name}| = {abs(c.initial[i]):.4g} m leaves the pad "
                                 f"(half size {self.finger.pad_half_size} m less "
                                 f"{self.pad_margin} m margin) by "
                                 f"{abs(c.initial[i]) - half:.4g} m"))
            u_lim = math.pi / 2 - self.base.pole_margin
            if abs(c.initial[2]) > u_lim:
                errs.append(("finger_contact.initial.u_f",
                             f"|u_f| = {abs(c.initial[2]):.4f} rad is beyond the chart pole "
                             f"limit {u_lim:.4f} rad; rotate finger_contact.chart_rotation"))
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
    #: Grid doublings after the first solve (the returned plan has 2**refinements times the
    #: requested intervals).
    refinements: int = 0

    @property
    def ok(self) -> bool:
        return self.status is Status.SOLVED


# -- symbolic model --------------------------------------------------------------------------

def _vee_skew(E: Any) -> Any:
    """vee((E - E^T)/2): zero for E = I, ~ the rotation vector for E near I."""
    return ca.vertcat(E[2, 1] - E[1, 2], E[0, 2] - E[2, 0], E[1, 0] - E[0, 1]) / 2


class _Model:
    """CasADi functions of the palm + one finger grasp (one object shape, one finger)."""

    def reintegrator(self, n_sub: int) -> ca.Function:
        """CVODES over one interval with the collocation input (built once per n_sub)."""
        if n_sub not in self._reintegrators:
            self._reintegrators[n_sub] = reintegrator(self.dynamics, self.nx, self.nu,
                                                      self.n_params, n_sub)
        return self._reintegrators[n_sub]

    @staticmethod
    def params(shape: FloatArray, Rcp: FloatArray, Rcf: FloatArray) -> FloatArray:
        """The dynamics' parameter vector (shape, vec(Rcp), vec(Rcf)), column-major."""
        return np.concatenate([shape, Rcp.ravel(order="F"), Rcf.ravel(order="F")])

    def __init__(self, shape: str, finger: Any) -> None:
        surface = model_for(shape).surface
        self.surface = surface
        self.nq = int(finger.nq)
        self.nx = 10 + self.nq
        self.nu = 4 + self.nq
        palm = ContactPair(Plane, surface)  # A = palm, B = ball
        tip = ContactPair(surface, Plane)  # A = ball (finger patch), B = pad
        x = ca.SX.sym("x", self.nx)
        u = ca.SX.sym("u", self.nu)
        shape_p = ca.SX.sym("shape", surface.n_params)
        Rcp = ca.SX.sym("Rcp", 3, 3)  # palm contact patch on the ball
        Rcf = ca.SX.sym("Rcf", 3, 3)  # finger contact patch on the ball
        none = ca.SX(0, 1)
        eye = ca.SX.eye(3)
        eta_p, eta_f, q = x[0:5], x[5:10], x[10:]
        # the tip pair orders coordinates (ball u, v, pad x, y, psi)
        e = ca.vertcat(eta_f[2:4], eta_f[0:2], eta_f[4])
        ep_dot = palm.rates_driven_by_a(eta_p, u[0:2], none, shape_p)
        ed = tip.rates_driven_by_a(e, u[2:4], shape_p, none)
        ef_dot = ca.vertcat(ed[2:4], ed[0:2], ed[4])
        R_po, p_po = palm.pose(eta_p, none, shape_p, eye, Rcp)
        R_of, p_of = tip.pose(e, shape_p, none, Rcf, eye)
        R_pf = R_po @ R_of
        p_pf = p_po + R_po @ p_of
        R_fk, p_fk = finger.fk(q)
        xdot = ca.vertcat(ep_dot, ef_dot, u[4:])
        #: dynamics(x, u, params) with params = (shape, vec(Rcp), vec(Rcf)), column-major
        self.dynamics = ca.Function("one_finger_dynamics",
                                    [x, u, ca.vertcat(shape_p, ca.vec(Rcp), ca.vec(Rcf))],
                                    [xdot], ["x", "u", "params"], ["x_dot"])
        self.n_params = surface.n_params + 18
        # the finger contact's rates alone (initial guesses), (e, w_f, shape) -> e_dot
        self.tip_rates = ca.Function("tip_rates", [e, u[2:4], shape_p], [ed])
        self._reintegrators: dict[int, ca.Function] = {}
        closure_pos = p_pf - p_fk
        closure_rot = _vee_skew(R_fk.T @ R_pf)
        # contacts on the ball, in the ball frame
        pc_p, Rg_p, _, _, _ = surface.geometry(eta_p[2:4], shape_p)
        pc_f, Rg_f, _, _, _ = surface.geometry(eta_f[2:4], shape_p)
        p1, n1 = Rcp @ pc_p, Rcp @ Rg_p[:, 2]
        p2, n2 = Rcf @ pc_f, Rcf @ Rg_f[:, 2]
        c1, c2, dist = grasp_cosines(p1, n1, p2, n2)
        self.path = ca.Function(
            "one_finger_path", [x, shape_p, Rcp, Rcf],
            [closure_pos, closure_rot, c1, c2, dist],
            ["x", "shape", "Rcp", "Rcf"],
            ["closure_pos", "closure_rot", "c_palm", "c_finger", "dist"])

        self.cartesian = ca.Function(
            "one_finger_cartesian", [x, shape_p, Rcp, Rcf],
            [R_po, p_po, R_pf, p_pf, p_po + R_po @ p1, p_po + R_po @ p2, R_po @ n2],
            ["x", "shape", "Rcp", "Rcf"],
            ["R_po", "p_po", "R_pf", "p_pf", "palm_contact", "finger_contact",
             "finger_normal"])
        # Rolling laws along a motion (certificate): the finger moves by its joints (FK of
        # q), the ball by the palm contact coordinates; both contacts' material points.
        xd = ca.SX.sym("xd", self.nx)

        def dot(expr: Any) -> Any:
            return ca.reshape(ca.jtimes(ca.vec(expr), x, xd), expr.size1(), expr.size2())

        R_po_dot, p_po_dot, R_fk_dot, p_fk_dot = dot(R_po), dot(p_po), dot(R_fk), dot(p_fk)
        contact_f = p_po + R_po @ p2  # finger contact point, palm frame
        on_pad = R_fk.T @ (contact_f - p_fk)  # the same point in the pad frame (FK)
        v_pad = R_fk_dot @ on_pad + p_fk_dot  # pad material point at the contact
        v_ball_f = R_po_dot @ p2 + p_po_dot  # ball material point at the finger contact
        v_ball_p = R_po_dot @ p1 + p_po_dot  # ball material point at the palm contact
        W_ball = R_po_dot @ R_po.T
        W_rel = R_fk_dot @ R_fk.T - W_ball
        omega_ball = ca.vertcat(W_ball[2, 1], W_ball[0, 2], W_ball[1, 0])
        omega_rel = ca.vertcat(W_rel[2, 1], W_rel[0, 2], W_rel[1, 0])
        n_f = R_po @ n2
        self.laws = ca.Function(
            "one_finger_laws", [x, xd, shape_p, Rcp, Rcf],
            [v_pad - v_ball_f, ca.dot(omega_rel, n_f), v_ball_p, omega_ball[2],
             ca.dot(R_fk[:, 2], p_po - p_fk), R_fk[:, 2], R_po, on_pad],
            ["x", "x_dot", "shape", "Rcp", "Rcf"],
            ["slip_finger", "spin_finger", "slip_palm", "spin_palm", "centre_above_pad",
             "pad_normal", "R_po", "pad_point"])


# -- the planner -----------------------------------------------------------------------------

@dataclass
class _NLP:
    solver: ca.Function
    stop: _StopCallback
    hs: HermiteSimpson
    unpack: ca.Function
    pack: ca.Function
    params: ca.Function
    lbg: FloatArray  # constraint bounds (equalities, cones, epigraph)
    ubg: FloatArray
    build_time: float


class OneFingerPlanner:
    """Direct-collocation planner for a palm + one finger grasp (cached per structure)."""

    def __init__(self) -> None:
        # Keyed by the finger object itself (hashed by identity; the key keeps it alive, so
        # a new finger can never be mistaken for a freed one with the same id).
        self._models: dict[tuple[str, Any], _Model] = {}
        self._nlps: dict[tuple[Any, ...], _NLP] = {}
        self._palm = BallOnPalmPlanner()

    def model(self, shape: str, finger: Any) -> _Model:
        key = (shape, finger)
        if key not in self._models:
            self._models[key] = _Model(shape, finger)
        return self._models[key]

    # ...................................................................................
    def _build(self, problem: OneFingerProblem) -> tuple[_NLP, bool]:
        st = Structure.of(problem.base)
        key = (st, problem.finger)
        if key in self._nlps:
            return self._nlps[key], True
        t0 = time.perf_counter()
        m = self.model(problem.base.object.shape, problem.finger)
        hs = HermiteSimpson(m.nx, m.nu, st.segments)
        n = hs.n_intervals
        shape_p = ca.SX.sym("shape", m.surface.n_params)
        seg_T = ca.SX.sym("seg_T", len(st.segments))
        goal = ca.SX.sym("goal", 5)
        vias = ca.SX.sym("vias", 5, len(st.via_masks))
        Rcp = ca.SX.sym("Rcp", 3, 3)
        Rcf = ca.SX.sym("Rcf", 3, 3)
        weights = ca.SX.sym("weights", 4)  # palm effort, finger effort, joint effort, grasp
        ccone = ca.SX.sym("ccone")
        p = ca.vertcat(shape_p, seg_T, goal, ca.vec(vias), ca.vec(Rcp), ca.vec(Rcf), weights,
                       ccone)
        L = ca.mmax(shape_p)
        T = ca.sum1(seg_T)
        x_scale = ca.vertcat(L, L, 1, 1, 1, L, L, 1, 1, 1, ca.DM.ones(m.nq))
        u_scale = ca.vertcat(L / T, L / T, 1 / T, 1 / T, ca.DM.ones(m.nq) / T)
        S = ca.SX.sym("S", 1, n + 1)  # grasp epigraph at nodes
        Sm = ca.SX.sym("Sm", 1, n)  # and midpoints
        g: list[Any] = [hs.defects(m.dynamics, ca.vertcat(shape_p, ca.vec(Rcp), ca.vec(Rcf)),
                                   x_scale, u_scale, seg_T)]
        lbg: list[float] = [0.0] * g[0].numel()
        ubg: list[float] = [0.0] * g[0].numel()

        def add(expr: Any, lo: float, hi: float) -> None:
            g.append(expr)
            lbg.extend([lo] * expr.numel())
            ubg.extend([hi] * expr.numel())

        def path(xs: Any, s: Any, closure: bool) -> None:
            cp, cr, c1, c2, dist = m.path(x_scale * xs, shape_p, Rcp, Rcf)
            if closure:  # eq. 6: the fingertip where the finger's kinematics put it
                add(ca.vertcat(cp / L, cr), 0.0, 0.0)
            add(ca.vertcat(c1 - dist * ccone, c2 - dist * ccone) / L, 0.0, math.inf)
            add(ca.vertcat(s - (1 - c1 / dist), s - (1 - c2 / dist)), 0.0, math.inf)

        for k in range(n + 1):
            path(hs.X[:, k], S[k], closure=k > 0)  # node 0 is fixed by the IK of the start
        for k in range(n):
            path(hs.Xm[:, k], Sm[k], closure=True)

        def target(x_node: Any, value: Any, mask: tuple[bool, ...]) -> None:
            for i, on in enumerate(mask):
                if on:
                    r = 2 * ca.sin((x_node[i] - value[i]) / 2) if PERIODIC[i] else \
                        x_node[i] - value[i] / x_scale[i]
                    add(r, 0.0, 0.0)

        ends = hs.segment_end_nodes
        for j, vmask in enumerate(st.via_masks):
            target(hs.X[:, ends[j]], vias[:, j], vmask)
        target(hs.X[:, ends[-1]], goal, st.goal_mask)

        us = ca.SX.sym("us", m.nu)
        xs_ = ca.SX.sym("xs", m.nx)
        effort = 0
        for i, part in enumerate((slice(0, 2), slice(2, 4), slice(4, m.nu))):
            term = ca.Function(f"effort{i}", [xs_, us], [ca.sumsqr(us[part])])
            effort += weights[i] * hs.simpson(term, seg_T / T)
        grasp = 0
        for k, h in enumerate(hs.steps(seg_T / T)):
            grasp += h / 6 * (S[k] + 4 * Sm[k] + S[k + 1])
        f = effort + weights[3] * grasp

        w = ca.vertcat(hs.w, S.T, Sm.T)
        g_all = ca.vertcat(*g)
        stop = _StopCallback(w.numel(), g_all.numel(), p.numel())
        solver = ca.nlpsol("one_finger", "ipopt", {"x": w, "p": p, "f": f, "g": g_all}, {
            "ipopt.print_level": 0, "ipopt.sb": "yes", "print_time": False,
            "ipopt.max_iter": 100_000, **IPOPT_OPTIONS, "iteration_callback": stop,
            "error_on_fail": False})
        unpack = ca.Function("unpack", [w], [hs.X, hs.Xm, hs.U, hs.Um, S, Sm])
        pack = ca.Function("pack", [hs.X, hs.Xm, hs.U, hs.Um, S, Sm], [w])
        params = ca.Function("params", [shape_p, seg_T, goal, vias, Rcp, Rcf, weights, ccone],
                             [p])
        nlp = _NLP(solver, stop, hs, unpack, pack, params, np.array(lbg), np.array(ubg),
                   time.perf_counter() - t0)
        self._nlps[key] = nlp
        return nlp, False

    # ...................................................................................
    def initial_grasp(self, problem: OneFingerProblem) -> FloatArray:
        """Joint angles of the initial grasp by inverse kinematics, or ProblemError saying
        why the grasp is not possible (unreachable, outside limits, outside the cone)."""
        from .finger import inverse_kinematics
        from .problem import ProblemError

        base, finger = problem.base, problem.finger
        m = self.model(base.object.shape, finger)
        x = np.zeros(m.nx)
        x[0:5] = base.initial
        x[5:10] = problem.contact.initial
        shape = list(base.object.dimensions)
        Rcp = rotation_from_vector(base.object.chart_rotation)
        Rcf = rotation_from_vector(problem.contact.chart_rotation)
        out = m.cartesian(x, shape, Rcp, Rcf)
        R_pf, p_pf = np.asarray(out[2]), np.asarray(out[3]).ravel()
        seed = np.asarray(problem.contact.q_seed if problem.contact.q_seed is not None
                          else np.radians(PAPER_SEED_DEG)[: m.nq], dtype=float)
        ik = inverse_kinematics(finger, R_pf, p_pf, seed)
        errs: list[tuple[str, str]] = []
        if not ik.converged:
            errs.append(("finger_contact.initial",
                         f"the finger cannot reach the initial grasp: after inverse "
                         f"kinematics the fingertip is {ik.position_error:.3g} m and "
                         f"{ik.orientation_error:.3g} rad from it"))
        elif not ik.within_limits:
            errs.append(("finger_contact.initial",
                         "the initial grasp needs joint angles outside the finger's limits"))
        p1 = np.asarray(out[4]).ravel()
        p2, n2 = np.asarray(out[5]).ravel(), np.asarray(out[6]).ravel()
        phi_p, phi_f = grasp_angles_numeric(p1, np.array([0.0, 0.0, -1.0]), p2, n2)
        cone = math.atan(problem.mu)
        if max(phi_p, phi_f) >= cone:
            errs.append(("finger_contact.initial",
                         f"the initial grasp is outside the friction cone: max grasp angle "
                         f"{math.degrees(max(phi_p, phi_f)):.2f} deg >= atan(mu) = "
                         f"{math.degrees(cone):.2f} deg, by "
                         f"{math.degrees(max(phi_p, phi_f) - cone):.2f} deg"))
        if errs:
            raise ProblemError(errs)
        return np.asarray(ik.q, dtype=float)

    def solve(self, problem: OneFingerProblem) -> OneFingerSolution:
        """Plan; ProblemError (before any NLP is built) on bad input or an impossible
        initial grasp. When IPOPT converges but the certificate finds the grid too coarse
        (finger slip or spin between collocation points, closure, re-integration defects),
        the plan is re-solved on a grid twice as fine, warm-started from the coarse one, up
        to ``problem.base.max_refinements`` times."""
        from .problem import MAX_INTERVALS, ProblemError

        errs = problem.errors()
        if errs:
            raise ProblemError(errs)
        deadline = time.perf_counter() + problem.base.options.time_limit
        q0 = self.initial_grasp(problem)
        sol = self._solve_once(problem, q0, None, deadline)
        refinements, build, solve, iters = 0, sol.build_time, sol.solve_time, sol.iterations
        discretisation = ("max_slip_speed_finger", "max_spin_rate_finger", "max_closure",
                          "max_position_defect", "max_angle_defect", "max_joint_defect",
                          "max_gap_error_finger")
        while (sol.status is Status.INACCURATE
               and refinements < problem.base.max_refinements
               and 2 * problem.base.n_intervals <= MAX_INTERVALS
               and all(f.startswith(discretisation) for f in sol.certificate_failures)
               and time.perf_counter() < deadline):
            refinements += 1
            problem = replace(problem, base=replace(problem.base,
                                                    n_intervals=2 * problem.base.n_intervals))
            sol = self._solve_once(problem, q0, sol, deadline)
            build, solve, iters = build + sol.build_time, solve + sol.solve_time, \
                iters + sol.iterations
        return replace(sol, build_time=build, solve_time=solve, iterations=iters,
                       refinements=refinements)

    def _solve_once(self, problem: OneFingerProblem, q0: FloatArray,
                    warm: OneFingerSolution | None, deadline: float) -> OneFingerSolution:
        nlp, hit = self._build(problem)
        build_time = 0.0 if hit else nlp.build_time
        base = problem.base
        m = self.model(base.object.shape, problem.finger)
        L = base.object.length_scale
        T = base.duration
        x_scale = np.concatenate([[L, L, 1, 1, 1, L, L, 1, 1, 1], np.ones(m.nq)])
        u_scale = np.concatenate([[L / T, L / T, 1 / T, 1 / T], np.ones(m.nq) / T])
        st = Structure.of(base)
        t_nodes = BallOnPalmPlanner._node_times(base, st)
        Rcp = rotation_from_vector(base.object.chart_rotation)
        Rcf = rotation_from_vector(problem.contact.chart_rotation)
        shape = np.asarray(base.object.dimensions, dtype=float)
        goal = np.array([base.goal.get(c, 0.0) for c in CONTACT_COORDS])
        vias = np.array([[vp.coords.get(c, 0.0) for c in CONTACT_COORDS]
                         for vp in base.via_points]).T.reshape(5, -1)
        weights = [1.0, problem.finger_effort_weight, problem.joint_effort_weight,
                   problem.grasp_weight]
        p = nlp.params(shape, np.diff(base.segment_times), goal, vias, Rcp, Rcf, weights,
                       cone_cosine(problem.mu))
        lbx, ubx = self._bounds(problem, nlp, m, q0, x_scale, u_scale)
        if warm is None:
            X, Xm, U, Um = self._guess(problem, m, nlp, q0, t_nodes, Rcp, Rcf)
        else:
            X, Xm, U, Um = self._guess_from(warm, nlp, t_nodes)
        Sg = self._epigraph(m, X, shape, Rcp, Rcf)
        Smg = self._epigraph(m, Xm, shape, Rcp, Rcf)
        w0 = nlp.pack((X / x_scale).T, (Xm / x_scale).T, (U / u_scale).T, (Um / u_scale).T,
                      Sg[None, :], Smg[None, :])
        w0 = np.clip(np.asarray(w0).ravel(), lbx, ubx)
        nlp.stop.arm(deadline, base.options.max_iter)
        t_solve = time.perf_counter()
        res = nlp.solver(x0=w0, p=p, lbx=lbx, ubx=ubx, lbg=nlp.lbg, ubg=nlp.ubg)
        solve_time = time.perf_counter() - t_solve
        stats = nlp.solver.stats()
        raw = str(stats["return_status"])
        status = nlp.stop.reason if raw == "User_Requested_Stop" and nlp.stop.reason \
            else status_from_ipopt(raw)
        Xs, Xms, Us, Ums, _, _ = (np.asarray(a) for a in nlp.unpack(res["x"]))
        X, Xm = Xs.T * x_scale, Xms.T * x_scale
        Ucols, Um = Us.T * u_scale, Ums.T * u_scale
        U0, U1 = Ucols[nlp.hs.left_cols], Ucols[nlp.hs.right_cols]
        return self._solution(problem, m, status, raw, int(stats["iter_count"]), build_time,
                              solve_time, t_nodes, X, Xm, U0, Um, U1, Rcp, Rcf, shape)

    # ...................................................................................
    @staticmethod
    def _bounds(problem: OneFingerProblem, nlp: _NLP, m: _Model, q0: FloatArray,
                x_scale: FloatArray, u_scale: FloatArray) -> tuple[FloatArray, FloatArray]:
        base, finger = problem.base, problem.finger
        n = nlp.hs.n_intervals
        n_seg = len(nlp.hs.segments)
        L = base.object.length_scale
        u_lim = math.pi / 2 - base.pole_margin
        pad = (float(finger.pad_half_size) - problem.pad_margin) / L
        inf = np.inf
        xb_hi = np.concatenate([[base.palm_half_extent / L] * 2, [u_lim, inf, inf],
                                [pad, pad, u_lim, inf, inf], np.asarray(finger.upper)])
        xb_lo = np.concatenate([[-base.palm_half_extent / L] * 2, [-u_lim, -inf, -inf],
                                [-pad, -pad, -u_lim, -inf, -inf], np.asarray(finger.lower)])
        x0 = np.concatenate([base.initial, problem.contact.initial, q0]) / x_scale
        lo_x, hi_x = np.tile(xb_lo, (n + 1, 1)), np.tile(xb_hi, (n + 1, 1))
        lo_x[0] = hi_x[0] = x0
        lo_xm, hi_xm = np.tile(xb_lo, (n, 1)), np.tile(xb_hi, (n, 1))
        ub_in = np.concatenate([[base.max_contact_speed] * 2, [100.0, 100.0],
                                np.asarray(finger.velocity_limit)]) / u_scale
        lo_u, hi_u = np.tile(-ub_in, (n + n_seg, 1)), np.tile(ub_in, (n + n_seg, 1))
        lo_um, hi_um = np.tile(-ub_in, (n, 1)), np.tile(ub_in, (n, 1))
        zeros_s, twos_s = np.zeros((1, n + 1)), 2 * np.ones((1, n + 1))
        lbx = nlp.pack(lo_x.T, lo_xm.T, lo_u.T, lo_um.T, zeros_s, zeros_s[:, :n])
        ubx = nlp.pack(hi_x.T, hi_xm.T, hi_u.T, hi_um.T, twos_s, twos_s[:, :n])
        return np.asarray(lbx).ravel(), np.asarray(ubx).ravel()

    @staticmethod
    def _guess_from(coarse: OneFingerSolution, nlp: _NLP, t_nodes: FloatArray
                    ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """An initial guess on a finer grid, interpolated from a coarse plan's samples."""
        Xc = np.hstack([coarse.eta_p, coarse.eta_f, coarse.q])
        Uc = np.hstack([coarse.w_p, coarse.w_f, coarse.q_dot])

        def at(values: FloatArray, t: FloatArray) -> FloatArray:
            return np.column_stack([np.interp(t, coarse.t, values[:, j])
                                    for j in range(values.shape[1])])

        n = len(t_nodes) - 1
        tm = (t_nodes[:-1] + t_nodes[1:]) / 2
        eps = 1e-9 * float(t_nodes[-1])
        U = np.zeros((n + len(nlp.hs.segments), Uc.shape[1]))
        U[nlp.hs.left_cols] = at(Uc, t_nodes[:-1] + eps)
        U[nlp.hs.right_cols] = at(Uc, t_nodes[1:] - eps)
        X = at(Xc, t_nodes)
        X[0] = Xc[0]  # the fixed initial state, exactly
        return X, at(Xc, tm), U, at(Uc, tm)

    @staticmethod
    def _epigraph(m: _Model, X: FloatArray, shape: FloatArray, Rcp: FloatArray,
                  Rcf: FloatArray) -> FloatArray:
        _, _, c1, c2, dist = m.path.map(len(X))(X.T, shape, Rcp, Rcf)
        c1, c2, dist = (np.asarray(a).ravel() for a in (c1, c2, dist))
        return np.clip(np.maximum(1 - c1 / dist, 1 - c2 / dist), 0.0, 2.0)

    def _guess(self, problem: OneFingerProblem, m: _Model, nlp: _NLP, q0: FloatArray,
               t_nodes: FloatArray, Rcp: FloatArray, Rcf: FloatArray
               ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """A consistent initial guess: the ball-on-palm plan; the finger contact kept at
        its initial place relative to the ball centre (palm frame), its contact
        coordinates integrated with the rolling equations; joints by inverse kinematics
        along the way (closure holds); joint rates by finite differences."""
        from .finger import inverse_kinematics

        base = problem.base
        palm_plan = self._palm.solve(base)
        surface, shape = m.surface, np.asarray(base.object.dimensions, dtype=float)
        n = len(t_nodes) - 1
        tm = (t_nodes[:-1] + t_nodes[1:]) / 2
        ts = np.sort(np.concatenate([t_nodes, tm]))  # node, mid, node, ...
        eps = 1e-9 * base.duration
        x_init = np.concatenate([base.initial, problem.contact.initial, q0])
        cart0 = m.cartesian(x_init, shape, Rcp, Rcf)
        offset = np.asarray(cart0[5]).ravel() - np.asarray(cart0[1]).ravel()

        def finger_ball_point(t: FloatArray) -> FloatArray:
            traj = palm_plan.sample(np.clip(t, 0.0, base.duration))
            pts = np.einsum("kji,j->ki", traj.object_rotation, offset)  # R^T offset
            return np.array([surface.inverse(Rcf.T @ p_, shape) for p_ in pts])

        dt = 1e-4 * base.duration
        alpha = finger_ball_point(ts)
        alpha_rate = (finger_ball_point(ts + dt) - finger_ball_point(ts - dt)) / (2 * dt)
        alpha_rate[:, 1] = ((alpha_rate[:, 1] * 2 * dt + np.pi) % (2 * np.pi) - np.pi) / (2 * dt)
        palm = palm_plan.sample(ts)
        eta_p = palm.eta
        # integrate the finger contact (pad point and psi) with the rolling equations
        rates = m.tip_rates
        ef = np.zeros((len(ts), 5))
        ef[0] = problem.contact.initial
        for k in range(len(ts) - 1):
            h = ts[k + 1] - ts[k]
            e_k = np.array([alpha[k, 0], alpha[k, 1], ef[k, 0], ef[k, 1], ef[k, 4]])
            w0_, w1_ = alpha_rate[k], alpha_rate[k + 1]
            k1 = np.asarray(rates(e_k, w0_, shape)).ravel()
            k2 = np.asarray(rates(e_k + h / 2 * k1, (w0_ + w1_) / 2, shape)).ravel()
            k3 = np.asarray(rates(e_k + h / 2 * k2, (w0_ + w1_) / 2, shape)).ravel()
            k4 = np.asarray(rates(e_k + h * k3, w1_, shape)).ravel()
            e_next = e_k + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
            ef[k + 1] = [e_next[2], e_next[3], alpha[k + 1, 0], alpha[k + 1, 1], e_next[4]]
        ef[0, 2:4] = problem.contact.initial[2:4]
        # joints by IK along the way
        qs = np.zeros((len(ts), m.nq))
        qs[0] = q0
        for k in range(1, len(ts)):
            xk = np.concatenate([eta_p[k], ef[k], qs[k - 1]])
            out = m.cartesian(xk, shape, Rcp, Rcf)
            ik = inverse_kinematics(problem.finger, np.asarray(out[2]),
                                    np.asarray(out[3]).ravel(), qs[k - 1])
            qs[k] = ik.q
        X = np.hstack([eta_p, ef, qs])
        qd = np.gradient(qs, ts, axis=0)
        W = np.hstack([palm.w, alpha_rate, qd])
        Ucols = np.zeros((n + len(nlp.hs.segments), m.nu))
        Ucols[nlp.hs.left_cols] = np.hstack([palm_plan.sample(t_nodes[:-1] + eps).w,
                                             alpha_rate[0:-1:2], qd[0:-1:2]])
        Ucols[nlp.hs.right_cols] = np.hstack([palm_plan.sample(t_nodes[1:] - eps).w,
                                              alpha_rate[2::2], qd[2::2]])
        return X[0::2], X[1::2], Ucols, W[1::2]

    # ...................................................................................
    def _solution(self, problem: OneFingerProblem, m: _Model, status: Status, raw: str,
                  iterations: int, build_time: float, solve_time: float, t_nodes: FloatArray,
                  X: FloatArray, Xm: FloatArray, U0: FloatArray, Um: FloatArray,
                  U1: FloatArray, Rcp: FloatArray, Rcf: FloatArray, shape: FloatArray
                  ) -> OneFingerSolution:
        base = problem.base
        tm = (t_nodes[:-1] + t_nodes[1:]) / 2
        order = np.argsort(np.concatenate([t_nodes, tm]), kind="stable")
        t = np.concatenate([t_nodes, tm])[order]
        Xg = np.vstack([X, Xm])[order]
        Ug = np.vstack([np.vstack([U0, U1[-1:]]), Um])[order]
        k = len(t)
        xdot = np.asarray(m.dynamics.map(k)(Xg.T, Ug.T, m.params(shape, Rcp, Rcf))).T
        cart = m.cartesian.map(k)(Xg.T, shape, Rcp, Rcf)
        R_po = np.asarray(cart[0]).T.reshape(k, 3, 3).transpose(0, 2, 1)
        p_po = np.asarray(cart[1]).T
        R_pf = np.asarray(cart[2]).T.reshape(k, 3, 3).transpose(0, 2, 1)
        p_pf = np.asarray(cart[3]).T
        cp, cf, nf = (np.asarray(c).T for c in cart[4:7])
        down = np.array([0.0, 0.0, -1.0])
        phis = np.array([grasp_angles_numeric(cp[i], down, cf[i], nf[i]) for i in range(k)])
        margin = math.atan(problem.mu) - phis.max(axis=1)
        ends = [0, *BallOnPalmPlanner._segment_end_nodes(Structure.of(base))]
        goal_error = BallOnPalmPlanner._goal_errors(base, X, ends)  # eta_p: X[:, 0:5]
        cert, failures = self._certify(problem, m, t_nodes, X, U0, Um, U1, Rcp, Rcf, shape)
        if status is Status.SOLVED and failures:
            status = Status.INACCURATE
        message = {
            Status.SOLVED: "converged; certificate passed",
            Status.INACCURATE: "converged, but the certificate failed: " + "; ".join(failures),
        }.get(status, f"not solved: IPOPT {raw}; the last iterate is returned")
        return OneFingerSolution(
            status=status, message=message, raw_status=raw, iterations=iterations,
            build_time=build_time, solve_time=solve_time, t=t, eta_p=Xg[:, 0:5],
            eta_f=Xg[:, 5:10], eta_p_dot=xdot[:, 0:5], eta_f_dot=xdot[:, 5:10], q=Xg[:, 10:],
            q_dot=Ug[:, 4:],
            w_p=Ug[:, 0:2], w_f=Ug[:, 2:4],
            object_position=p_po, object_rotation=R_po, fingertip_position=p_pf,
            fingertip_rotation=R_pf, palm_contact_point=cp, finger_contact_point=cf,
            finger_contact_normal=nf, grasp_angles=phis, cone_margin=margin,
            goal_error=goal_error, certificate=cert, certificate_failures=failures)

    def _certify(self, problem: OneFingerProblem, m: _Model, t_nodes: FloatArray,
                 X: FloatArray, U0: FloatArray, Um: FloatArray, U1: FloatArray,
                 Rcp: FloatArray, Rcf: FloatArray, shape: FloatArray
                 ) -> tuple[dict[str, float], tuple[str, ...]]:
        """Re-integrate the inputs (CVODES) and check the laws along that motion, with the
        finger placed by Pinocchio's forward kinematics of the re-integrated joints."""

        base, finger = problem.base, problem.finger
        if not (np.all(np.isfinite(X)) and np.all(np.isfinite(U0)) and
                np.all(np.isfinite(Um)) and np.all(np.isfinite(U1))):
            return {}, ("the plan has non-finite states or inputs",)
        prm = m.params(shape, Rcp, Rcf)
        F = m.reintegrator(4)
        try:
            Xr, sx, su = reintegrate(F, X[0], t_nodes, U0, Um, U1, prm, 4)
        except RuntimeError as exc:  # CVODES gave up: the plan is not a smooth motion
            return {}, (f"re-integration failed: {str(exc).splitlines()[-1]}",)
        n = len(sx)
        xd = np.asarray(m.dynamics.map(n)(sx.T, su.T, prm))
        laws = m.laws.map(n)(sx.T, xd, shape, Rcp, Rcf)
        slip_f, spin_f, slip_p, spin_p, centre_above, _, _, pad_pt = (np.asarray(a).T
                                                                     for a in laws)
        # closure, with Pinocchio's own forward kinematics
        cart = m.cartesian.map(n)(sx.T, shape, Rcp, Rcf)
        R_pf = np.asarray(cart[2]).T.reshape(n, 3, 3).transpose(0, 2, 1)
        p_pf = np.asarray(cart[3]).T
        pos_err, rot_err = 0.0, 0.0
        for i in range(n):
            R_pin, p_pin = finger.fingertip_pose_pin(sx[i, 10:])
            pos_err = max(pos_err, float(np.linalg.norm(p_pin - p_pf[i])))
            E = R_pin.T @ R_pf[i]
            rot_err = max(rot_err, float(np.arccos(np.clip((np.trace(E) - 1) / 2, -1, 1))))
        rho = m.surface.support_height([0.0, 0.0, 1.0], shape)
        cp, cf, nf = (np.asarray(c).T for c in cart[4:7])
        p_po = np.asarray(cart[1]).T
        down = np.array([0.0, 0.0, -1.0])
        phis = np.array([grasp_angles_numeric(cp[i], down, cf[i], nf[i]) for i in range(n)])
        L = base.object.length_scale
        d = Xr - X
        speed = float(np.max(np.abs(su[:, 0:2]))) + L * float(np.max(np.abs(su[:, 2:4])))
        cert = {
            "max_position_defect": float(np.max(np.abs(d[:, [0, 1, 5, 6]]))),
            "max_angle_defect": float(np.max(np.abs(d[:, [2, 3, 4, 7, 8, 9]]))),
            "max_joint_defect": float(np.max(np.abs(d[:, 10:]))),
            "max_closure_position_error": pos_err,
            "max_closure_orientation_error": rot_err,
            "max_slip_speed_palm": float(np.max(np.linalg.norm(slip_p, axis=1))),
            "max_spin_rate_palm": float(np.max(np.abs(spin_p))),
            "max_slip_speed_finger": float(np.max(np.linalg.norm(slip_f, axis=1))),
            "max_spin_rate_finger": float(np.max(np.abs(spin_f))),
            "max_height_error_palm": float(np.max(np.abs(p_po[:, 2] - rho))),
            "max_gap_error_finger": float(np.max(np.abs(centre_above.ravel() - rho))),
            "max_pad_excursion": float(np.max(np.abs(pad_pt[:, 0:2]))),
            "min_cone_margin": float(np.min(math.atan(problem.mu) - phis.max(axis=1))),
            "max_joint_limit_violation": float(max(
                np.max(sx[:, 10:] - finger.upper), np.max(finger.lower - sx[:, 10:]), 0.0)),
        }
        o = base.options
        tol = {
            "max_position_defect": max(o.cert_position_tol, 1e-5),
            "max_angle_defect": o.cert_angle_tol * 10,
            "max_joint_defect": o.cert_angle_tol * 10,
            "max_closure_position_error": 1e-4,
            "max_closure_orientation_error": 1e-3,
            "max_slip_speed_palm": 1e-8 * max(speed, 1e-3),
            "max_spin_rate_palm": 1e-8 * max(speed / L, 1e-3),
            "max_slip_speed_finger": 1e-2 * max(speed, 1e-3),
            "max_spin_rate_finger": 1e-2 * max(speed / L, 1e-3),
            "max_height_error_palm": 1e-9,
            "max_gap_error_finger": 1e-4,
            "max_pad_excursion": float(finger.pad_half_size),
            "max_joint_limit_violation": 1e-6,
        }
        failures = [f"{k} {cert[k]:.3g} > {tol[k]:.3g}" for k in tol if not cert[k] <= tol[k]]
        if not cert["min_cone_margin"] >= -1e-6:
            failures.append(f"min_cone_margin {cert['min_cone_margin']:.3g} < 0")
        cert.update({f"tol_{k}": v for k, v in tol.items()})
        return cert, tuple(failures)
