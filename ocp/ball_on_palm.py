"""Rolling an object on a flat palm: eq. 8 of the paper as a direct-collocation NLP.

State: the palm/object contact coordinates eta_p = (x, y, u, v, psi); input: the palm
contact velocity w = d/dt (x, y) [m/s]. The dynamics are the general rolling equations
(:meth:`ocp.contact.ContactPair.rates_driven_by_a`) for the plane against the object's
surface; for a sphere they are the paper's eq. 8 (tested). Objective: control effort
integral |w|^2 dt. Goals and via-points are equality constraints on any subset of eta.

One NLP is built per problem *structure* (object shape, intervals per segment, which
coordinates each goal/via-point fixes) and cached; everything that changes between
requests (initial state, goal values, radius, segment durations, bounds) is a parameter
or a bound.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, replace
from functools import cache
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np
from numpy.typing import ArrayLike, NDArray

from .collocation import (
    HermiteSimpson,
    WarmStart,
    hermite_sample,
    node_inputs,
    node_times,
    reintegrate,
    reintegrator,
    target_residuals,
)
from .contact import ContactPair
from .ipopt import IPOPT_OPTIONS, StopCallback
from .parameters import Parameters
from .problem import (
    CONTACT_COORDS,
    MAX_INTERVALS,
    PERIODIC,
    BallOnPalmProblem,
    ObjectSpec,
    ProblemError,
)
from .solution import (
    Certificate,
    Solution,
    SolverStats,
    Status,
    Trajectory,
    status_from_ipopt,
)
from .surfaces import SURFACES, Plane, Surface, rotation_from_vector

__all__ = ["BallOnPalmModel", "BallOnPalmPlanner", "model_for", "plan"]

FloatArray = NDArray[np.float64]
NX, NU = 5, 2
_GUESS_SUBSTEPS = 2  # RK4 steps per half interval in the initial-guess simulation


def wrap_difference(a: FloatArray | float, b: FloatArray | float) -> FloatArray:
    """a - b wrapped into [-pi, pi)."""
    return np.asarray((np.asarray(a) - np.asarray(b) + np.pi) % (2 * np.pi) - np.pi)


def coordinate_error(coord: str, value: float, target: float) -> float:
    """|value - target| in m or rad, modulo 2 pi for the periodic coordinates."""
    i = CONTACT_COORDS.index(coord)
    d = float(wrap_difference(value, target)) if PERIODIC[i] else value - target
    return abs(d)


@dataclass(frozen=True)
class BallOnPalmModel:
    """Named CasADi functions of the palm/object contact for one object shape."""

    surface: Surface
    #: (eta, w, params) -> eta_dot: the rolling equations, eq. 3 / eq. 8.
    dynamics: ca.Function
    #: (eta, w, params, chart) -> (R_po, p_po, contact_point, contact_normal, omega_roll)
    kinematics: ca.Function
    #: (eta, eta_dot, params, chart) -> (v_slip [m/s], omega [rad/s]), from d/dt g_po.
    twist: ca.Function

    @staticmethod
    def build(surface: Surface) -> BallOnPalmModel:
        pair = ContactPair(Plane, surface)
        eta = ca.SX.sym("eta", NX)
        eta_dot = ca.SX.sym("eta_dot", NX)
        w = ca.SX.sym("w", NU)
        params = ca.SX.sym("params", surface.n_params)
        chart = ca.SX.sym("chart", 3, 3)
        none = ca.SX(0, 1)
        eye = ca.SX.eye(3)
        dyn = ca.Function("ball_on_palm_dynamics", [eta, w, params],
                          [pair.rates_driven_by_a(eta, w, none, params)],
                          ["eta", "w", "params"], ["eta_dot"])
        R_po, p_po = pair.pose(eta, none, params, eye, chart)
        cp, cn = pair.contact_point(eta, none, eye)
        omega = pair.rolling_velocity(eta, w, none, params)
        kin = ca.Function("ball_on_palm_kinematics", [eta, w, params, chart],
                          [R_po, p_po, cp, cn, omega],
                          ["eta", "w", "params", "chart"],
                          ["R_po", "p_po", "contact_point", "contact_normal", "omega_roll"])
        # Velocity of the object's material point at the contact, relative to the palm:
        # v = dR/dt p_b + dp/dt with p_b = chart f_b(alpha_b) held fixed in the object.
        R_dot = ca.reshape(ca.jtimes(ca.vec(R_po), eta, eta_dot), 3, 3)
        p_dot = ca.jtimes(p_po, eta, eta_dot)
        p_b = chart @ surface.geometry(eta[2:4], params)[0]
        v_slip = R_dot @ p_b + p_dot
        W = R_dot @ R_po.T
        omega_s = ca.vertcat(W[2, 1], W[0, 2], W[1, 0])
        twist = ca.Function("ball_on_palm_contact_twist", [eta, eta_dot, params, chart],
                            [v_slip, omega_s], ["eta", "eta_dot", "params", "chart"],
                            ["v_slip", "omega"])
        return BallOnPalmModel(surface, dyn, kin, twist)

    @cache  # noqa: B019 - models live for the whole process
    def guess_simulator(self, n: int) -> ca.Function:
        """RK4 over n intervals: (x0, W, h, params, u_lim) -> (X nodes 1..n, X midpoints).

        W holds the input at 2 * _GUESS_SUBSTEPS + 1 equally spaced times per interval
        (columns interval-major). The latitude is clipped to the chart's allowed band.
        """
        m = _GUESS_SUBSTEPS
        x = ca.SX.sym("x", NX)
        Wk = ca.SX.sym("W", NU, 2 * m + 1)
        h = ca.SX.sym("h")
        params = ca.SX.sym("params", self.surface.n_params)
        u_lim = ca.SX.sym("u_lim")
        dt = h / (2 * m)

        def f(xx: ca.SX, j: int) -> ca.SX:  # input at sub-time j/2 (half steps use averages)
            w = Wk[:, j // 2] if j % 2 == 0 else (Wk[:, j // 2] + Wk[:, j // 2 + 1]) / 2
            return self.dynamics(xx, w, params)

        xs = x
        mid = x
        for i in range(2 * m):
            k1 = f(xs, 2 * i)
            k2 = f(xs + dt / 2 * k1, 2 * i + 1)
            k3 = f(xs + dt / 2 * k2, 2 * i + 1)
            k4 = f(xs + dt * k3, 2 * i + 2)
            xs = xs + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
            xs = ca.vertcat(xs[0:2], ca.fmin(ca.fmax(xs[2], -u_lim), u_lim), xs[3:])
            if i == m - 1:
                mid = xs
        step = ca.Function("guess_step", [x, Wk, h, params, u_lim], [xs, mid])
        sim = step.mapaccum("guess_sim", n, [0], [0])
        Wall = ca.SX.sym("Wall", NU, n * (2 * m + 1))
        hs = ca.SX.sym("hs", 1, n)
        Wsplit = ca.horzsplit(Wall, list(range(0, n * (2 * m + 1) + 1, 2 * m + 1)))
        Xn, Xm = sim(x, ca.horzcat(*Wsplit), hs, ca.repmat(params, 1, n), ca.repmat(u_lim, 1, n))
        return ca.Function("guess_simulator", [x, Wall, hs, params, u_lim], [Xn, Xm],
                           ["x0", "W", "h", "params", "u_lim"], ["X", "Xm"])

    @cache  # noqa: B019 - models live for the whole process
    def mapped(self, name: str, m: int) -> ca.Function:
        """The model's function ``name`` (dynamics, kinematics, twist) over m samples."""
        return getattr(self, name).map(m)

    @cache  # noqa: B019 - one integrator per model, models live for the process
    def reintegrator(self, n_sub: int) -> ca.Function:
        """CVODES over one interval with the collocation input (see collocation.py)."""
        return reintegrator(self.dynamics, NX, NU, self.surface.n_params, n_sub)


@cache
def model_for(shape: str) -> BallOnPalmModel:
    """The (cached) model for an object shape name ("sphere", "ellipsoid")."""
    return BallOnPalmModel.build(SURFACES[shape])


# -- NLP -----------------------------------------------------------------------------------

@dataclass(frozen=True)
class Structure:
    """What fixes the shape of the NLP; everything else is a parameter or a bound."""

    shape: str
    segments: tuple[int, ...]
    goal_mask: tuple[bool, ...]
    via_masks: tuple[tuple[bool, ...], ...]

    @staticmethod
    def of(problem: BallOnPalmProblem) -> Structure:
        def mask(coords: Any) -> tuple[bool, ...]:
            return tuple(c in coords for c in CONTACT_COORDS)

        return Structure(problem.object.shape, problem.segment_intervals(),
                         mask(problem.goal), tuple(mask(vp.coords) for vp in problem.via_points))


@dataclass
class _NLP:
    structure: Structure
    solver: ca.Function
    stop: StopCallback
    unpack: ca.Function
    pack: ca.Function
    params: Parameters  # shape, seg_T, goal, vias
    left_cols: list[int]  # input column at the start of each interval
    right_cols: list[int]  # input column at the end of each interval
    n_g: int
    build_time: float


def _build(st: Structure, compile_dir: Path | None = None) -> _NLP:
    t0 = time.perf_counter()
    model = model_for(st.shape)
    n_seg = len(st.segments)
    n_via = len(st.via_masks)
    hs = HermiteSimpson(NX, NU, st.segments)
    decl = Parameters.of(shape=(model.surface.n_params, 1), seg_T=(n_seg, 1), goal=(NX, 1),
                         vias=(NX, n_via))
    p = ca.SX.sym("p", decl.size)
    prm = decl.unpack(p)
    shape_p, seg_T, goal, vias = prm["shape"], prm["seg_T"], prm["goal"], prm["vias"]
    L = ca.mmax(shape_p)  # length scale [m]
    T = ca.sum1(seg_T)
    x_scale = ca.vertcat(L, L, 1, 1, 1)
    u_scale = ca.vertcat(L, L) / T

    g = [hs.defects(model.dynamics, shape_p, x_scale, u_scale, seg_T)]

    ends = hs.segment_end_nodes
    for j, vmask in enumerate(st.via_masks):
        g += target_residuals(hs.X[:, ends[j]], vias[:, j], vmask, x_scale, PERIODIC)
    g += target_residuals(hs.X[:, ends[-1]], goal, st.goal_mask, x_scale, PERIODIC)
    g_all = ca.vertcat(*g)

    us = ca.SX.sym("us", NU)
    effort = hs.simpson(ca.Function("effort", [ca.SX.sym("xs", NX), us], [ca.sumsqr(us)]),
                        seg_T / T)

    stop = StopCallback(hs.w.numel(), g_all.numel(), p.numel())
    opts = {
        "ipopt.print_level": 0,
        "ipopt.sb": "yes",
        "print_time": False,
        "ipopt.max_iter": 100_000,  # per-solve limits come from the callback
        **IPOPT_OPTIONS,
        "iteration_callback": stop,
        "error_on_fail": False,
    }
    solver = ca.nlpsol("ball_on_palm", "ipopt", {"x": hs.w, "p": p, "f": effort, "g": g_all},
                       opts)
    if compile_dir is not None:
        from .compiled import compiled_solver

        solver, _ = compiled_solver(solver, repr(st), opts, compile_dir)
    return _NLP(st, solver, stop, hs.unpack(), hs.pack(), decl, hs.left_cols,
                hs.right_cols, g_all.numel(),
                time.perf_counter() - t0)


# -- initial guesses -----------------------------------------------------------------------

def _palm_anchors(problem: BallOnPalmProblem) -> FloatArray:
    """Palm points the reference path passes at the segment boundaries (2 x n_seg+1)."""
    pts = [np.array(problem.initial[:2], dtype=float)]
    for coords in [*(vp.coords for vp in problem.via_points), problem.goal]:
        q = pts[-1].copy()
        for i, c in enumerate(("x", "y")):
            if c in coords:
                q[i] = coords[c]
        pts.append(q)
    return np.array(pts).T


def _reference_input(problem: BallOnPalmProblem, loop: float) -> Callable[[FloatArray],
                                                                         FloatArray]:
    """w(t) of a reference palm path: straight lines between anchors plus a closed loop.

    The system is nonholonomic: a straight-line guess cannot change the object's
    orientation without moving it, and IPOPT started there can stall and report the
    problem infeasible. A loop of signed size ``loop`` (fraction of the object size),
    superposed over the whole horizon, gives the guess the net rotation a pure
    reorientation needs (the holonomy of rolling around a closed path).
    """
    anchors = _palm_anchors(problem)
    tb = problem.segment_times
    T = problem.duration
    r = abs(loop) * problem.object.length_scale
    sgn = 1.0 if loop >= 0 else -1.0

    def w(t: FloatArray) -> FloatArray:
        seg = np.clip(np.searchsorted(tb, t, side="right") - 1, 0, len(tb) - 2)
        lin = (anchors[:, seg + 1] - anchors[:, seg]) / (tb[seg + 1] - tb[seg])
        ph = 2 * np.pi * t / T
        loop_v = (2 * np.pi / T) * r * np.vstack([-np.sin(ph), sgn * np.cos(ph)])
        return np.asarray(lin + loop_v)

    return w


def _simulate_guess(model: BallOnPalmModel, problem: BallOnPalmProblem, t_nodes: FloatArray,
                    w_of_t: Callable[[FloatArray], FloatArray], nlp: _NLP
                    ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Forward-simulate the reference input (RK4): a dynamically consistent initial guess."""
    n = len(t_nodes) - 1
    h = np.diff(t_nodes)
    frac = np.arange(_GUESS_SUBSTEPS * 2 + 1) / (_GUESS_SUBSTEPS * 2)
    times = (t_nodes[:-1, None] + h[:, None] * frac[None, :]).ravel()
    W = w_of_t(times)  # nu x (n * (2 substeps + 1))
    u_lim = math.pi / 2 - problem.pole_margin
    Xn, Xm = model.guess_simulator(n)(np.asarray(problem.initial, dtype=float), W, h,
                                      list(problem.object.dimensions), u_lim)
    X = np.vstack([np.asarray(problem.initial, dtype=float), np.asarray(Xn).T])
    tm = (t_nodes[:-1] + t_nodes[1:]) / 2
    # node inputs per segment: evaluated just inside the interval they belong to
    U = node_inputs(lambda ts: w_of_t(ts).T, t_nodes, nlp.left_cols, nlp.right_cols,
                    n + len(nlp.structure.segments))
    return X, np.asarray(Xm).T, U, w_of_t(tm).T


def _guesses(model: BallOnPalmModel, problem: BallOnPalmProblem, t_nodes: FloatArray, nlp: _NLP,
             warm: Solution | WarmStart | None
             ) -> Iterator[tuple[FloatArray, FloatArray, FloatArray, FloatArray]]:
    """Initial guesses (X, Xm, U, Um) in the order they are tried.

    A warm start comes first: a previous plan of the same duration sampled with its
    collocation polynomials, or any :class:`~ocp.collocation.WarmStart` (interpolated,
    stretched to the duration); then forward simulations of reference palm paths (see
    :func:`_reference_input`).
    """
    if isinstance(warm, Solution) and abs(float(warm.nodes.t[-1]) - problem.duration) < 1e-9:
        n = len(t_nodes) - 1
        tm = (t_nodes[:-1] + t_nodes[1:]) / 2
        U = node_inputs(lambda ts: warm.sample(ts).w, t_nodes, nlp.left_cols,
                        nlp.right_cols, n + len(nlp.structure.segments))
        sm = warm.sample(tm)
        yield warm.sample(t_nodes).eta, sm.eta, U, sm.w
    elif warm is not None:
        ws = warm.warm_start if isinstance(warm, Solution) else warm
        X, Xm, U, Um = ws.on_grid(t_nodes, nlp.left_cols, nlp.right_cols,
                                  len(t_nodes) - 1 + len(nlp.structure.segments))
        X[0] = problem.initial
        yield X, Xm, U, Um
    for loop in _guess_loops(problem):
        yield _simulate_guess(model, problem, t_nodes, _reference_input(problem, loop), nlp)


def _rotation_symmetric(problem: BallOnPalmProblem) -> bool:
    """True for a pure reorientation about the palm normal with no via-points.

    The goal fixes the palm point and the object point to their initial values, so the net
    motion is a rotation about the vertical through the contact. Rotating a whole plan about
    that vertical leaves both its cost and its final pose unchanged: the optima form a
    continuum, on which IPOPT's convergence stalls unless one member is picked (the gauge
    bound in :meth:`BallOnPalmPlanner._bounds`).
    """
    if problem.via_points or "psi" not in problem.goal:
        return False
    return all(c in problem.goal and abs(problem.goal[c] - problem.initial[i]) < 1e-12
               for i, c in enumerate(CONTACT_COORDS[:4]))


def _guess_loops(problem: BallOnPalmProblem) -> list[float]:
    """Loop sizes to try, in order: loops first when the object's orientation is a target."""
    orient = any(c in problem.goal for c in ("u", "v", "psi")) or any(
        c in vp.coords for vp in problem.via_points for c in ("u", "v", "psi"))
    return [0.5, -0.5, 0.0, 1.0, -1.0] if orient else [0.0, 0.5, -0.5]


# -- the planner ---------------------------------------------------------------------------

class BallOnPalmPlanner:
    """Plans with a cache of NLPs keyed by problem structure (one per process is enough)."""

    def __init__(self, n_reintegration_substeps: int = 8, max_iter_per_guess: int = 300,
                 compile_dir: Path | None = None) -> None:
        self._cache: dict[Structure, _NLP] = {}
        #: When set, each structure's NLP functions are generated as C, compiled with gcc
        #: and cached there as a shared library (:mod:`ocp.compiled`): slow to build the
        #: first time (tens of seconds), faster to solve, for structures used many times.
        self.compile_dir = compile_dir
        self.n_sub = n_reintegration_substeps
        #: IPOPT iterations spent on one initial guess before the next one is tried.
        self.max_iter_per_guess = max_iter_per_guess

    def nlp_for(self, problem: BallOnPalmProblem) -> tuple[_NLP, bool]:
        """The NLP for this problem's structure, and whether it came from the cache."""
        st = Structure.of(problem)
        hit = st in self._cache
        if not hit:
            self._cache[st] = _build(st, self.compile_dir)
        return self._cache[st], hit

    def solve(self, problem: BallOnPalmProblem,
              warm_start: Solution | WarmStart | None = None, *,
              certify: bool = True) -> Solution:
        """Plan; raises :class:`ProblemError` (before building anything) on bad input.

        ``warm_start``: a previous plan of a similar problem (or its ``warm_start``), tried
        first as the initial guess (the planner's own guesses follow if IPOPT does not
        converge from it). When IPOPT converges but the certificate finds the
        discretisation too coarse (state defect), the plan is re-solved on a grid twice as
        fine, warm-started from the coarse one, up to ``problem.max_refinements`` times.

        ``certify=False`` (for a plan that only seeds another planner's initial guess): no
        certificate and so no refinement; the plan is at best ``INACCURATE`` and its
        certificate's only failure says that it was not checked.
        """
        problem.validate()
        if isinstance(warm_start, WarmStart):
            errs = warm_start.errors("warm_start", NX, NU)
            if errs:
                raise ProblemError(errs)
        deadline = time.perf_counter() + problem.options.time_limit
        iter_budget = problem.options.max_iter
        totals = {"build": 0.0, "solve": 0.0, "ipopt": 0.0, "cert": 0.0, "iter": 0,
                  "attempts": 0}
        sol = self._solve_once(problem, warm_start, deadline, iter_budget, totals, certify)
        refinements = 0
        while (sol.status is Status.INACCURATE and refinements < problem.max_refinements
               and 2 * problem.n_intervals <= MAX_INTERVALS
               and all(f.startswith(("angle_defect", "position_defect", "goal"))
                       for f in sol.certificate.failures)):
            refinements += 1
            problem = replace(problem, n_intervals=2 * problem.n_intervals)
            sol = self._solve_once(problem, sol, deadline, iter_budget - int(totals["iter"]),
                                   totals)
        stats = replace(sol.stats, iterations=int(totals["iter"]),
                        attempts=int(totals["attempts"]), build_time=totals["build"],
                        solve_time=totals["solve"], certificate_time=totals["cert"],
                        ipopt_time=totals["ipopt"],
                        refinements=refinements)
        return replace(sol, stats=stats)

    def _solve_once(self, problem: BallOnPalmProblem, warm: Solution | WarmStart | None,
                    deadline: float, iter_budget: int, totals: dict[str, float],
                    certify: bool = True) -> Solution:
        nlp, hit = self.nlp_for(problem)
        build_time = 0.0 if hit else nlp.build_time
        model = model_for(problem.object.shape)

        L = problem.object.length_scale
        seg_T = np.diff(problem.segment_times)
        T = problem.duration
        x_scale = np.array([L, L, 1, 1, 1])
        u_scale = L / T
        goal = np.array([problem.goal.get(c, 0.0) for c in CONTACT_COORDS])
        vias = np.array([[vp.coords.get(c, 0.0) for c in CONTACT_COORDS]
                         for vp in problem.via_points]).T.reshape(NX, -1)
        p = nlp.params.pack(shape=problem.object.dimensions, seg_T=seg_T, goal=goal, vias=vias)
        lbx, ubx = self._bounds(problem, nlp, x_scale, u_scale)

        t_nodes = self._node_times(problem, nlp.structure)
        attempts: list[dict[str, Any]] = []
        ipopt_time = 0.0
        t_solve = time.perf_counter()
        for X, Xm, U, Um in _guesses(model, problem, t_nodes, nlp, warm):
            w0 = nlp.pack((X / x_scale).T, (Xm / x_scale).T, U.T / u_scale, Um.T / u_scale)
            w0 = np.clip(np.asarray(w0).ravel(), lbx, ubx)
            remaining_iter = iter_budget - sum(a["iter"] for a in attempts)
            nlp.stop.arm(deadline, max(1, min(remaining_iter, self.max_iter_per_guess)))
            t_ipopt = time.perf_counter()
            res = nlp.solver(x0=w0, p=p, lbx=lbx, ubx=ubx, lbg=0.0, ubg=0.0)
            ipopt_time += time.perf_counter() - t_ipopt
            stats = nlp.solver.stats()
            raw = str(stats["return_status"])
            status = nlp.stop.reason if raw == "User_Requested_Stop" and nlp.stop.reason \
                else status_from_ipopt(raw)
            g = np.asarray(res["g"]).ravel()
            attempts.append({"w": np.asarray(res["x"]).ravel(), "status": status, "raw": raw,
                             "iter": int(stats["iter_count"]), "f": float(res["f"]),
                             "viol": float(np.max(np.abs(g))) if g.size else 0.0})
            if status is Status.SOLVED or nlp.stop.reason is Status.TIME_LIMIT \
                    or remaining_iter <= self.max_iter_per_guess:
                break
        solve_time = time.perf_counter() - t_solve
        best = next((a for a in attempts if a["status"] is Status.SOLVED),
                    min(attempts, key=lambda a: a["viol"]))
        sol = self._solution(problem, nlp, model, best, attempts, t_nodes, x_scale, u_scale,
                             build_time, hit, solve_time, certify)
        totals["build"] += build_time
        totals["solve"] += solve_time
        totals["ipopt"] += ipopt_time
        totals["cert"] += sol.stats.certificate_time
        totals["iter"] += sol.stats.iterations
        totals["attempts"] += sol.stats.attempts
        return sol

    # -- helpers --------------------------------------------------------------------------
    @staticmethod
    def _node_times(problem: BallOnPalmProblem, st: Structure) -> FloatArray:
        return node_times(st.segments, problem.segment_times)

    @staticmethod
    def _bounds(problem: BallOnPalmProblem, nlp: _NLP, x_scale: FloatArray, u_scale: float
                ) -> tuple[FloatArray, FloatArray]:
        n = sum(nlp.structure.segments)
        L = problem.object.length_scale
        u_lim = math.pi / 2 - problem.pole_margin
        xb = np.array([problem.palm_half_extent / L] * 2 + [u_lim, np.inf, np.inf])
        ub_x = np.tile(xb, (n + 1, 1))
        ub_x[0] = np.asarray(problem.initial) / x_scale
        lb_x = -np.tile(xb, (n + 1, 1))
        lb_x[0] = ub_x[0]
        ub_xm = np.tile(xb, (n, 1))
        ub_u = np.full((n + len(nlp.structure.segments), NU),
                       problem.max_contact_speed / u_scale)
        ub_um = np.full((n, NU), problem.max_contact_speed / u_scale)
        lb_u = -ub_u
        if _rotation_symmetric(problem):
            # Gauge: the plan's rotation about the contact normal is free; depart along +x.
            c0 = nlp.left_cols[0]
            lb_u[c0, 0], lb_u[c0, 1], ub_u[c0, 1] = 0.0, 0.0, 0.0
        lbx = nlp.pack(lb_x.T, -ub_xm.T, lb_u.T, -ub_um.T)
        ubx = nlp.pack(ub_x.T, ub_xm.T, ub_u.T, ub_um.T)
        return np.asarray(lbx).ravel(), np.asarray(ubx).ravel()

    def _solution(self, problem: BallOnPalmProblem, nlp: _NLP, model: BallOnPalmModel,
                  best: dict[str, Any], attempts: list[dict[str, Any]], t_nodes: FloatArray,
                  x_scale: FloatArray, u_scale: float, build_time: float, hit: bool,
                  solve_time: float, check: bool = True) -> Solution:
        Xs, Xms, Us, Ums = (np.asarray(a) for a in nlp.unpack(best["w"]))
        X, Xm = (Xs.T * x_scale), (Xms.T * x_scale)
        Ucols, Um = Us.T * u_scale, Ums.T * u_scale
        U0, U1 = Ucols[nlp.left_cols], Ucols[nlp.right_cols]
        U = np.vstack([U0, U1[-1:]])  # node inputs, outgoing at via-points
        params = np.asarray(problem.object.dimensions, dtype=float)
        chart = rotation_from_vector(problem.object.chart_rotation)
        n = len(U0)
        F0 = np.asarray(model.dynamics.map(n)(X[:-1].T, U0.T, params)).T
        F1 = np.asarray(model.dynamics.map(n)(X[1:].T, U1.T, params)).T
        t_mid = (t_nodes[:-1] + t_nodes[1:]) / 2

        def trajectory(t: FloatArray, eta: FloatArray, w: FloatArray) -> Trajectory:
            m = len(t)
            eta_dot = np.asarray(model.dynamics.map(m)(eta.T, w.T, params)).T
            R, pos, cp, cn, om = model.kinematics.map(m)(eta.T, w.T, params, np.tile(chart, m))
            return Trajectory(t=t, eta=eta, eta_dot=eta_dot, w=w,
                              rolling_velocity=np.asarray(om).T,
                              object_position=np.asarray(pos).T,
                              object_rotation=np.asarray(R).T.reshape(m, 3, 3).transpose(0, 2, 1),
                              contact_point=np.asarray(cp).T, contact_normal=np.asarray(cn).T)

        order = np.argsort(np.concatenate([t_nodes, t_mid]), kind="stable")
        grid = trajectory(np.concatenate([t_nodes, t_mid])[order],
                          np.vstack([X, Xm])[order], np.vstack([U, Um])[order])
        nodes = trajectory(t_nodes, X, U)

        def sampler(t: FloatArray) -> Trajectory:
            if np.any((t < -1e-12) | (t > problem.duration + 1e-12)):
                raise ValueError(f"sample times must lie in [0, {problem.duration}] s")
            x, u = hermite_sample(t_nodes, X, F0, F1, U0, Um, U1,
                                  np.clip(t, 0, problem.duration))
            return trajectory(t, x, u)

        ends = [0, *np.cumsum(nlp.structure.segments).tolist()]
        goal_error = goal_errors(problem, X, ends)
        t_cert = time.perf_counter()
        cert = certify(problem, model, t_nodes, X, U0, Um, U1, ends, self.n_sub) if check \
            else Certificate(math.nan, math.nan, math.nan, math.nan, math.nan, math.nan,
                             0, {}, ("not certified (planned as an initial guess)",))
        cert_time = time.perf_counter() - t_cert

        status: Status = best["status"]
        if status is Status.SOLVED and not cert.passed:
            status = Status.INACCURATE
        message = {
            Status.SOLVED: "converged; certificate passed",
            Status.INACCURATE: "converged, but the certificate failed: "
                               + "; ".join(cert.failures) + " (refine n_intervals)",
            Status.INFEASIBLE: "IPOPT reports the goals locally infeasible from every initial "
                               "guess tried; the last iterate is returned",
            Status.ITERATION_LIMIT: f"iteration limit {problem.options.max_iter} reached; "
                                    "the last iterate is returned",
            Status.TIME_LIMIT: f"time limit {problem.options.time_limit} s reached; "
                               "the last iterate is returned",
            Status.NUMERICAL_ERROR: f"IPOPT stopped with {best['raw']}; "
                                    "the last iterate is returned",
        }[status]
        stats = SolverStats(raw_status=best["raw"],
                            iterations=sum(a["iter"] for a in attempts),
                            attempts=len(attempts), build_time=build_time,
                            solve_time=solve_time, certificate_time=cert_time,
                            objective=float(best["f"]) * problem.object.length_scale**2
                            / problem.duration, cache_hit=hit, n_intervals=len(t_nodes) - 1)
        return Solution(status=status, message=message, stats=stats, grid=grid, nodes=nodes,
                        certificate=cert, goal_error=goal_error, _sampler=sampler)



def goal_errors(problem: BallOnPalmProblem, X: FloatArray, ends: list[int]
                ) -> dict[str, float]:
    """Error of every goal and via-point coordinate (m or wrapped rad) of the palm contact
    coordinates ``X[:, 0:5]`` at the segment end nodes ``ends`` (0 first)."""
    out: dict[str, float] = {}
    for j, vp in enumerate(problem.via_points):
        for c, val in vp.coords.items():
            out[f"via_points[{j}].{c}"] = coordinate_error(
                c, X[ends[j + 1], CONTACT_COORDS.index(c)], val)
    for c, val in problem.goal.items():
        out[f"goal.{c}"] = coordinate_error(c, X[ends[-1], CONTACT_COORDS.index(c)], val)
    return out


def certify(problem: BallOnPalmProblem, model: BallOnPalmModel, t_nodes: FloatArray,
            X: FloatArray, U0: FloatArray, Um: FloatArray, U1: FloatArray, ends: list[int],
            n_sub: int) -> Certificate:
    """The physical certificate of a plan, computed independently of the NLP.

    Re-integrates the collocation inputs from the initial state with CVODES over the whole
    horizon (never reset to the NLP's states), then checks the rolling laws along the
    re-integrated motion at ``n_sub`` points per interval. See :class:`Certificate`.
    """
    params = np.asarray(problem.object.dimensions, dtype=float)
    chart = rotation_from_vector(problem.object.chart_rotation)
    if not (np.all(np.isfinite(X)) and np.all(np.isfinite(U0)) and np.all(np.isfinite(Um))
            and np.all(np.isfinite(U1))):
        nan = float("nan")
        return Certificate(max_position_defect=nan, max_angle_defect=nan, max_slip_speed=nan,
                           max_spin_rate=nan, max_height_error=nan, max_goal_error=nan,
                           n_samples=0, tolerances={},
                           failures=("the plan has non-finite states or inputs",))
    Xr_arr, sx, sw = reintegrate(model.reintegrator(n_sub), X[0], t_nodes, U0, Um, U1,
                                 params, n_sub)
    m = len(sx)
    eta_dot = np.asarray(model.mapped("dynamics", m)(sx.T, sw.T, params))
    v_slip, omega = model.mapped("twist", m)(sx.T, eta_dot, params, np.tile(chart, m))
    v_slip, omega = np.asarray(v_slip).T, np.asarray(omega).T
    R, pos, _cp, cn, _ = model.mapped("kinematics", m)(sx.T, sw.T, params, np.tile(chart, m))
    R = np.asarray(R).T.reshape(m, 3, 3).transpose(0, 2, 1)
    pos, cn = np.asarray(pos).T, np.asarray(cn).T
    spin = np.abs(np.sum(omega * cn, axis=1))
    # Height of the object's lowest point above the palm plane z = 0, from the closed-form
    # support function of the shape in the object frame (no chart involved): the palm's
    # downward normal in the object frame is -R^T e_z, minus the third row of R.
    heights = pos[:, 2] - model.surface.support_heights(-R[:, 2, :], params)
    d = Xr_arr - X
    pos_def = float(np.max(np.abs(d[:, :2])))
    ang = np.column_stack([d[:, 2], wrap_difference(Xr_arr[:, 3:], X[:, 3:])])
    ang_def = float(np.max(np.abs(ang)))
    goal_err = goal_errors(problem, Xr_arr, ends)
    max_goal = max(goal_err.values(), default=0.0)

    o = problem.options
    speed = float(np.max(np.linalg.norm(sw, axis=1)))
    omega_max = float(np.max(np.linalg.norm(omega, axis=1)))
    tol = {
        "position_defect": o.cert_position_tol,
        "angle_defect": o.cert_angle_tol,
        "slip_speed": 1e-9 * max(speed, 1e-3),
        "spin_rate": 1e-9 * max(omega_max, 1e-3),
        "height": 1e-9 * problem.object.length_scale,
        "goal": max(o.cert_position_tol, o.cert_angle_tol),
    }
    vals = {
        "position_defect": pos_def,
        "angle_defect": ang_def,
        "slip_speed": float(np.max(np.linalg.norm(v_slip, axis=1))),
        "spin_rate": float(np.max(spin)),
        "height": float(np.max(np.abs(heights))),
        "goal": max_goal,
    }
    failures = tuple(f"{k} {vals[k]:.3g} > {tol[k]:.3g}" for k in vals if not vals[k] <= tol[k])
    return Certificate(max_position_defect=pos_def, max_angle_defect=ang_def,
                       max_slip_speed=vals["slip_speed"], max_spin_rate=vals["spin_rate"],
                       max_height_error=vals["height"], max_goal_error=max_goal,
                       n_samples=m, tolerances=tol, failures=failures)


def contact_coordinates(obj: ObjectSpec, position_xy: ArrayLike, rotation: ArrayLike
                        ) -> tuple[float, float, float, float, float]:
    """Contact coordinates (x, y, u, v, psi) of the object resting on the palm.

    ``rotation`` is the object's orientation in the palm frame (3x3) and ``position_xy``
    the palm point under it [m]. The inverse of the pose map: the contact point on the
    object is the support point whose outward normal points down the palm normal, (u, v)
    its coordinates in the object's chart, psi the angle between the two contact frames.
    """
    R = np.asarray(rotation, dtype=float).reshape(3, 3)
    surf, params = obj.surface, obj.dimensions
    chart = rotation_from_vector(obj.chart_rotation)
    p_b = surf.support_point(R.T @ np.array([0.0, 0.0, -1.0]), params)
    u, v = surf.inverse(chart.T @ p_b, params)
    _, R_gauss, _, _, _ = surf.geometry([u, v], params)
    R_cc = R @ chart @ np.asarray(R_gauss)  # palm contact frame is the identity
    psi = math.atan2(-R_cc[0, 1], R_cc[0, 0])
    xy = np.asarray(position_xy, dtype=float)
    return (float(xy[0]), float(xy[1]), float(u), float(v), psi)


def object_pose(obj: ObjectSpec, eta: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """(R_po, p_po): the object's pose in the palm frame at contact coordinates ``eta``."""
    model = model_for(obj.shape)
    chart = rotation_from_vector(obj.chart_rotation)
    R, p, _, _, _ = model.kinematics(np.asarray(eta, dtype=float), [0.0, 0.0],
                                     list(obj.dimensions), chart)
    return np.asarray(R), np.asarray(p).ravel()


_DEFAULT = BallOnPalmPlanner()


def plan(problem: BallOnPalmProblem, warm_start: Solution | WarmStart | None = None
         ) -> Solution:
    """Plan with the process-wide planner (and its NLP cache); ``warm_start`` as in
    :meth:`BallOnPalmPlanner.solve`."""
    return _DEFAULT.solve(problem, warm_start)


__all__ += ["ProblemError", "certify", "contact_coordinates", "object_pose"]
