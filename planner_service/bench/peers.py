"""Peers: the same ball-on-palm NLP solved by other methods, for side-by-side timing.

Each peer takes the wire request (:class:`dexroll_client.models.BallOnPalmRequest`), poses
the problem the project's planner (:class:`ocp.ball_on_palm.BallOnPalmPlanner`) poses, solves
it once from the project's *first* initial guess, and returns a :class:`PeerOutcome`: times
of construction and solve measured apart, IPOPT's iterations, the worst goal/via-point
error, and the project's physical certificate of the peer's plan (its inputs re-integrated
with CVODES from the initial state, the rolling laws checked along that motion:
:func:`ocp.ball_on_palm.certify`), so that a report compares validity, not just speed.

``casadi_plain``
    The project's NLP written the plain way: built per request with every value (radius,
    durations, goal, via-points) baked in as a constant, an MX graph calling the project's
    dynamics ``palm_model(shape).dynamics`` and ``nlpsol(..., "ipopt", {"expand": True})``
    (what ``ca.Opti`` does underneath). Mathematically the same NLP as the project's: the
    same separated Hermite-Simpson discretisation on the same grid (segments between
    via-points, an incoming and an outgoing input at each via-point node), the same scaled
    variables (state / (L, L, 1, 1, 1), input / (L / T), L the object's length scale, T the
    duration), the same objective (Simpson's rule of |w|^2, times T / L^2), bounds, goal
    and via-point constraints (``2 sin(d / 2) = 0`` for the periodic v and psi), the same
    gauge bound on the first input of a pure reorientation about the palm normal, the same
    variable order, the project's ``IPOPT_OPTIONS``, and the project's first initial
    guess. Differences: one attempt only (the project tries further guesses when one fails,
    and refines the grid when the certificate fails), no per-solve deadline callback
    (``max_wall_time`` instead).

``drake``
    pydrake's ``DirectCollocation`` with Drake's ``IpoptSolver``, for the sphere (the
    paper's eq. 8, :func:`ocp.geometry.contact.ball_on_plane_eq8`, typed in ``pydrake.symbolic`` as
    a ``SymbolicVectorSystem``). The system is written in the project's scaled variables
    (state eta / (L, L, 1, 1, 1), input w / (L / T), time in s), so that IPOPT's tolerances
    mean the same. Mapping:

    * grid: one ``DirectCollocation`` per segment between via-points (the project's
      ``problem.segment_intervals()`` intervals each), all adding to one
      ``MathematicalProgram`` (the constructor's ``prog``), each with its time step fixed
      (minimum = maximum) to the project's interval: the grids are identical, via-points
      on the segment end knots exactly. A segment's last knot and the next one's first are
      separate variables joined by linear equalities (the project shares the node), so the
      input may jump at a via-point as the project's does;
    * dynamics: Drake's collocation is Hermite-Simpson in the *compressed* form (no
      midpoint state variables; the defect is imposed on the state rate at the midpoint,
      which is the project's defect divided by 2h/3) with a first-order-hold input: the
      input is piecewise linear, where the project's is quadratic per interval with a free
      midpoint value;
    * cost: ``AddRunningCost(|w~|^2 / T)``, which Drake integrates with the trapezoidal
      rule over its knots; the reported ``objective`` is the exact integral of |w|^2 of the
      plan's own (piecewise-linear) input, as the project's is Simpson's rule of its own;
    * bounds: state bounds (palm extent, |u| <= pi/2 - pole_margin) at the knots only
      (the project also bounds its midpoint states), input bounds at the knots (the FOH
      input between them stays inside); the initial state is fixed by a bounding box;
    * goal and via-points: linear equalities on x, y, u at the segment end knots,
      ``2 sin(d / 2) = 0`` on v and psi; the same gauge bound on the first input of a pure
      reorientation about the palm normal;
    * initial guess: the project's first guess (its node states, and its node inputs,
      which are the segments' knot inputs one for one), clipped into the bounds;
    * IPOPT: the project's ``IPOPT_OPTIONS`` (without the ``ipopt.`` prefix) except the
      MUMPS ordering (Drake's IPOPT is built with SPRAL as its only linear solver) and the
      barrier strategy (adaptive from IPOPT's default start, which suits its quasi-Newton
      Hessian; :func:`drake_ipopt_options`), the request's ``max_iter`` and
      ``max_wall_time``. Drake gives IPOPT first derivatives only and sets a
      limited-memory (L-BFGS) Hessian approximation, where CasADi gives the exact Hessian
      of the Lagrangian (a reorientation takes about twice our iterations).

    Shapes other than the sphere are ``unavailable`` for this peer (eq. 8 is the sphere's).

Status is ``"solved"`` only when the solver reports success and the worst goal/via-point
error of the plan is at most :data:`GOAL_TOLERANCE`; ``"unavailable"`` when the peer is not
installed or does not model the request. The certificate's ``passed`` is 1.0 or 0.0.

Run ``python -m planner_service.bench.peers REQUEST.json [--sizes 50,100] [--repeats 3]``
to print the medians of the project's cached planner and each peer on a request.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import importlib.util
import json
import math
import os
import re
import statistics
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np
from numpy.typing import NDArray

from dexroll_client.models import BallOnPalmRequest
from ocp import (
    CONTACT_COORDS,
    IPOPT_OPTIONS,
    PALM_NX,
    PERIODIC,
    BallOnPalmPlanner,
    BallOnPalmProblem,
    Certificate,
    Status,
    Structure,
    certify_palm_plan,
    goal_errors,
    guess_loops,
    left_input_columns,
    node_times,
    palm_model,
    reference_input,
    simulate_guess,
    status_from_ipopt,
)
from ocp import rotation_symmetric as _rotation_symmetric
from planner_service.planners import to_problem

__all__ = ["GOAL_TOLERANCE", "PEER_METHODS", "PeerOutcome", "available", "compare"]

FloatArray = NDArray[np.float64]
NU = 2
#: Worst goal/via-point error [m or rad] of a plan that counts as solved.
GOAL_TOLERANCE = 1e-6


@dataclass(frozen=True)
class PeerOutcome:
    """One solve of a request by one method.

    ``build_time``: constructing the NLP [s]; ``solve_time``: the solver call [s];
    ``goal_error``: worst goal/via-point coordinate error of the plan (m or wrapped rad);
    ``certificate``: the project's certificate of the plan (``passed`` 1.0/0.0 and the
    worst residuals). ``objective``: the effort integral of |w|^2 dt [m^2/s] of the plan's
    own input polynomial; ``t``, ``eta``, ``w``: the plan at its nodes (w: outgoing).
    """

    status: str  # "solved" | "failed" | "unavailable"
    build_time: float
    solve_time: float
    iterations: int | None
    goal_error: float | None
    certificate: dict[str, float]
    message: str
    objective: float | None = None
    t: FloatArray | None = field(default=None, compare=False, repr=False)
    eta: FloatArray | None = field(default=None, compare=False, repr=False)
    w: FloatArray | None = field(default=None, compare=False, repr=False)


def available() -> dict[str, bool]:
    """Which peers can run here: ``drake`` when pydrake is importable."""
    return {"casadi_plain": True, "drake": importlib.util.find_spec("pydrake") is not None}


# -- shared pieces ---------------------------------------------------------------------------

@dataclass(frozen=True)
class _Grid:
    """The project's grid of a problem: node times, segments, input columns."""

    structure: Structure
    t_nodes: FloatArray
    left_cols: list[int]  # input column at the start of each interval
    right_cols: list[int]  # input column at the end of each interval
    ends: list[int]  # node index of each segment boundary, 0 first

    @staticmethod
    def of(problem: BallOnPalmProblem) -> _Grid:
        st = Structure.of(problem)
        seg = st.segments
        left = left_input_columns(seg)
        return _Grid(st, node_times(seg, problem.segment_times), left,
                     [c + 1 for c in left], [0, *np.cumsum(seg).tolist()])

    @property
    def n(self) -> int:
        return len(self.t_nodes) - 1

    @property
    def h(self) -> FloatArray:
        return np.diff(self.t_nodes)


def _problem(request: BallOnPalmRequest) -> BallOnPalmProblem:
    """The request's problem with the paper's timing: the peers' NLPs are the paper's
    (piecewise inputs, free at the start and the end; docs/timing.md), and their plans are
    certified as such. A comparison with the project's planner plans the same timing (the
    suites' ball-on-palm families ask for it)."""
    problem = to_problem(request)
    if not isinstance(problem, BallOnPalmProblem):  # pragma: no cover - typed input
        raise TypeError(f"a ball-on-palm request is needed, got {type(request).__name__}")
    problem = replace(problem, timing="paper")
    problem.validate()
    return problem


def _first_guess(problem: BallOnPalmProblem, grid: _Grid
                 ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """The project's first initial guess (X, Xm, U, Um): physical units, rows = times.

    ``U`` has the project's input columns (an incoming and an outgoing column at each
    via-point node); only the grid layout of the NLP is read by the guess functions.
    """
    return simulate_guess(problem, grid.t_nodes,
                          reference_input(problem, guess_loops(problem)[0]), grid.left_cols,
                          grid.right_cols, len(grid.t_nodes) - 1 + len(grid.structure.segments))


def _scales(problem: BallOnPalmProblem) -> tuple[float, FloatArray, float]:
    L = problem.object.length_scale
    return L, np.array([L, L, 1.0, 1.0, 1.0]), L / problem.duration


def _assess(problem: BallOnPalmProblem, grid: _Grid, X: FloatArray, U0: FloatArray,
            Um: FloatArray, U1: FloatArray) -> tuple[float, Certificate, float]:
    """(worst goal error, certificate, effort integral) of a plan at the nodes."""
    errs = goal_errors(problem, X, grid.ends)
    cert = certify_palm_plan(problem, grid.t_nodes, X, U0, Um, U1)
    sq = [np.sum(np.square(a), axis=1) for a in (U0, Um, U1)]
    effort = float(np.sum(grid.h / 6 * (sq[0] + 4 * sq[1] + sq[2])))
    return float(max(errs.values(), default=0.0)), cert, effort


def _certificate_dict(cert: Certificate) -> dict[str, float]:
    values = {k: cert.get(k, math.nan) for k in (
        "max_position_defect", "max_angle_defect", "max_slip_speed", "max_spin_rate",
        "max_height_error", "max_goal_error")}
    return {"passed": 1.0 if cert.passed else 0.0, **{k: float(v) for k, v in values.items()}}


def _outcome(problem: BallOnPalmProblem, grid: _Grid, ok: bool, raw: str, build: float,
             solve: float, iterations: int | None, X: FloatArray, U0: FloatArray,
             Um: FloatArray, U1: FloatArray) -> PeerOutcome:
    goal_error, cert, effort = _assess(problem, grid, X, U0, Um, U1)
    solved = ok and goal_error <= GOAL_TOLERANCE
    why = "" if solved else (f"; goal error {goal_error:.3g} > {GOAL_TOLERANCE:g}" if ok
                             else "; the solver did not converge")
    cert_text = "certificate passed" if cert.passed else \
        "certificate failed: " + "; ".join(cert.failures)
    return PeerOutcome("solved" if solved else "failed", build, solve, iterations, goal_error,
                       _certificate_dict(cert), f"IPOPT: {raw}{why}; {cert_text}",
                       objective=effort, t=grid.t_nodes.copy(), eta=X,
                       w=np.vstack([U0, U1[-1:]]))


def _unavailable(message: str) -> PeerOutcome:
    return PeerOutcome("unavailable", 0.0, 0.0, None, None, {}, message)


def _box(problem: BallOnPalmProblem) -> FloatArray:
    """Upper bounds of the scaled state (x, y, u; v and psi free)."""
    L = problem.object.length_scale
    u_lim = math.pi / 2 - problem.pole_margin
    return np.array([problem.palm_half_extent / L] * 2 + [u_lim, np.inf, np.inf])


# -- casadi_plain ----------------------------------------------------------------------------

def casadi_plain(request: BallOnPalmRequest) -> PeerOutcome:
    """The project's NLP built per request, values baked in, MX + ``expand=True``."""
    problem = _problem(request)
    grid = _Grid.of(problem)
    model = palm_model(problem.object.surface.name)  # process-wide, as for the project's planner
    X0, Xm0, U0g, Um0 = _first_guess(problem, grid)

    t0 = time.perf_counter()
    n, n_seg = grid.n, len(grid.structure.segments)
    _, x_scale, u_scale = _scales(problem)
    T = problem.duration
    rho = ca.DM(list(problem.object.dimensions))
    X = ca.MX.sym("X", PALM_NX, n + 1)
    Xm = ca.MX.sym("Xm", PALM_NX, n)
    U = ca.MX.sym("U", NU, n + n_seg)
    Um = ca.MX.sym("Um", NU, n)
    w = ca.vertcat(ca.vec(X), ca.vec(Xm), ca.vec(U), ca.vec(Um))
    inv_sx = ca.DM(1.0 / x_scale)
    sx = ca.DM(x_scale)

    def f(x: ca.MX, u: ca.MX) -> ca.MX:  # scaled state rate of scaled state and input
        return inv_sx * model.dynamics(sx * x, u_scale * u, rho)

    rates: dict[tuple[int, int], ca.MX] = {}

    def f_node(k: int, col: int) -> ca.MX:
        if (k, col) not in rates:
            rates[k, col] = f(X[:, k], U[:, col])
        return rates[k, col]

    g: list[ca.MX] = []
    effort: ca.MX = 0
    for k, h in enumerate(grid.h.tolist()):
        lc, rc = grid.left_cols[k], grid.right_cols[k]
        f0, f1 = f_node(k, lc), f_node(k + 1, rc)
        fm = f(Xm[:, k], Um[:, k])
        g.append(Xm[:, k] - (X[:, k] + X[:, k + 1]) / 2 - h / 8 * (f0 - f1))
        g.append(X[:, k + 1] - X[:, k] - h / 6 * (f0 + 4 * fm + f1))
        effort += h / T / 6 * (ca.sumsqr(U[:, lc]) + 4 * ca.sumsqr(Um[:, k])
                               + ca.sumsqr(U[:, rc]))

    def targets(node: int, coords: dict[str, float]) -> list[ca.MX]:
        out = []
        for i, c in enumerate(CONTACT_COORDS):
            if c not in coords:
                continue
            if PERIODIC[i]:
                out.append(2 * ca.sin((X[i, node] - coords[c]) / 2))
            else:
                out.append(X[i, node] - coords[c] / x_scale[i])
        return out

    for j, vp in enumerate(problem.via_points):
        g += targets(grid.ends[j + 1], dict(vp.coords))
    g += targets(grid.ends[-1], dict(problem.goal))
    g_all = ca.vertcat(*g)

    xb = _box(problem)
    ub_x = np.tile(xb, (n + 1, 1))
    ub_x[0] = np.asarray(problem.initial) / x_scale
    lb_x = -ub_x
    lb_x[0] = ub_x[0]
    ub_u = np.full((n + n_seg, NU), problem.max_contact_speed / u_scale)
    lb_u = -ub_u
    if _rotation_symmetric(problem):  # the project's gauge: depart along +x
        c0 = grid.left_cols[0]
        lb_u[c0, 0], lb_u[c0, 1], ub_u[c0, 1] = 0.0, 0.0, 0.0
    ub_um = np.full((n, NU), problem.max_contact_speed / u_scale)
    ub_xm = np.tile(xb, (n, 1))

    def flat(*blocks: FloatArray) -> FloatArray:  # rows = columns of X, Xm, U, Um
        return np.concatenate([b.ravel() for b in blocks])

    lbx = flat(lb_x, -ub_xm, lb_u, -ub_um)
    ubx = flat(ub_x, ub_xm, ub_u, ub_um)
    x_init = np.clip(flat(X0 / x_scale, Xm0 / x_scale, U0g / u_scale, Um0 / u_scale), lbx, ubx)
    opts = {
        "expand": True,
        "print_time": False,
        "error_on_fail": False,
        "ipopt.print_level": 0,
        "ipopt.sb": "yes",
        "ipopt.max_iter": problem.options.max_iter,
        "ipopt.max_wall_time": problem.options.time_limit,
        **IPOPT_OPTIONS,
    }
    solver = ca.nlpsol("ball_on_palm_plain", "ipopt", {"x": w, "f": effort, "g": g_all}, opts)
    build = time.perf_counter() - t0

    t1 = time.perf_counter()
    res = solver(x0=x_init, lbx=lbx, ubx=ubx, lbg=0.0, ubg=0.0)
    solve = time.perf_counter() - t1
    stats = solver.stats()
    raw = str(stats["return_status"])

    sol = np.asarray(res["x"]).ravel()
    sizes = [PALM_NX * (n + 1), PALM_NX * n, NU * (n + n_seg), NU * n]
    Xs, _, Us, Ums = np.split(sol, np.cumsum(sizes)[:-1])
    Xp = Xs.reshape(n + 1, PALM_NX) * x_scale
    Ucols = Us.reshape(n + n_seg, NU) * u_scale
    Ump = Ums.reshape(n, NU) * u_scale
    ok = status_from_ipopt(raw) is Status.SOLVED
    return _outcome(problem, grid, ok, raw, build, solve, int(stats["iter_count"]), Xp,
                    Ucols[grid.left_cols], Ump, Ucols[grid.right_cols])


# -- drake -----------------------------------------------------------------------------------

_IPOPT_ITERATIONS = re.compile(r"Number of Iterations\.*:\s*(\d+)")


def drake_ipopt_options(problem: BallOnPalmProblem) -> dict[str, Any]:
    """The project's ``IPOPT_OPTIONS`` as far as Drake's IPOPT takes them.

    Drake's IPOPT is built with SPRAL as its only linear solver, so the MUMPS options
    (``mumps_pivot_order``) do not map and are left out; Drake itself sets
    ``hessian_approximation`` to ``limited-memory`` (it evaluates first derivatives only).
    The barrier is IPOPT's adaptive strategy from its default start: the project's
    monotone barrier from mu = 1e-3 suits an exact Hessian, and with Drake's L-BFGS it
    ended the 90 deg reorientation in a restoration failure.
    """
    opts: dict[str, Any] = {k.removeprefix("ipopt."): v for k, v in IPOPT_OPTIONS.items()
                            if not k.removeprefix("ipopt.").startswith(("mumps_", "mu_"))}
    opts.update(mu_strategy="adaptive", print_level=0, max_iter=problem.options.max_iter,
                max_wall_time=float(problem.options.time_limit))
    return opts


def drake(request: BallOnPalmRequest) -> PeerOutcome:
    """pydrake's DirectCollocation + IpoptSolver on the same problem (see the module doc)."""
    try:
        # imported by name: pydrake stays untyped for mypy whether it is installed or not
        planning = importlib.import_module("pydrake.planning")
        solvers = importlib.import_module("pydrake.solvers")
        symbolic = importlib.import_module("pydrake.symbolic")
        primitives = importlib.import_module("pydrake.systems.primitives")
    except ImportError as exc:
        return _unavailable(f"pydrake is not installed ({exc}); pip install 'dexroll[peers]'")
    DirectCollocation, SymbolicVectorSystem = (planning.DirectCollocation,
                                               primitives.SymbolicVectorSystem)
    IpoptSolver, SolverOptions = solvers.IpoptSolver, solvers.SolverOptions
    Variable, cos, sin, tan = symbolic.Variable, symbolic.cos, symbolic.sin, symbolic.tan
    problem = _problem(request)
    if problem.object.shape != "sphere":
        return _unavailable("the drake peer models the sphere only (the paper's eq. 8); "
                            f"got {problem.object.shape!r}")
    if not IpoptSolver().available():  # pragma: no cover - every pip wheel has IPOPT
        return _unavailable("this Drake has no IPOPT")
    grid = _Grid.of(problem)
    X0, _Xm0, U0g, _Um0 = _first_guess(problem, grid)

    t0 = time.perf_counter()
    _, x_scale, u_scale = _scales(problem)
    T = problem.duration
    rho = float(problem.object.dimensions[0])
    s = [Variable(f"s{i}") for i in range(PALM_NX)]  # scaled state
    q = [Variable(f"q{i}") for i in range(NU)]  # scaled input
    u, psi = s[2], s[4]
    w1, w2 = u_scale * q[0], u_scale * q[1]
    c, sn = cos(psi), sin(psi)
    # eq. 8 (ocp.geometry.contact.ball_on_plane_eq8), divided by the state scale
    eta_dot = [w1, w2, (c * w1 - sn * w2) / rho, -(sn * w1 + c * w2) / (rho * cos(u)),
               tan(u) * (sn * w1 + c * w2) / rho]
    system = SymbolicVectorSystem(state=s, input=q,
                                  dynamics=[eta_dot[i] / x_scale[i] for i in range(PALM_NX)])
    context = system.CreateDefaultContext()
    # one DirectCollocation per segment between via-points, all in one program: the input
    # may jump at a via-point node, as the project's does; the states join by equalities
    x_init = np.asarray(problem.initial) / x_scale
    xb = _box(problem)
    ub = problem.max_contact_speed / u_scale
    h = grid.h
    prog = None
    segments: list[Any] = []
    for s_i, n_s in enumerate(grid.structure.segments):
        h_s = float(h[grid.ends[s_i]])
        dircol = DirectCollocation(system, context, num_time_samples=n_s + 1,
                                   minimum_time_step=h_s, maximum_time_step=h_s, prog=prog)
        prog = dircol.prog()
        for k in range(n_s):
            prog.SetInitialGuess(dircol.time_step(k), [h_s])
        qq = dircol.input()
        dircol.AddRunningCost((qq[0] * qq[0] + qq[1] * qq[1]) / T)
        for k in range(n_s + 1):
            prog.AddBoundingBoxConstraint(-xb, xb, dircol.state(k))
            prog.AddBoundingBoxConstraint(-ub * np.ones(NU), ub * np.ones(NU), dircol.input(k))
        if segments:
            prog.AddLinearEqualityConstraint(
                np.hstack([np.eye(PALM_NX), -np.eye(PALM_NX)]), np.zeros(PALM_NX),
                np.concatenate([segments[-1].final_state(), dircol.initial_state()]))
        segments.append(dircol)
    assert prog is not None
    prog.AddBoundingBoxConstraint(x_init, x_init, segments[0].initial_state())
    if _rotation_symmetric(problem):  # the project's gauge: depart along +x
        prog.AddBoundingBoxConstraint(np.zeros(NU), np.array([ub, 0.0]), segments[0].input(0))

    def targets(state: Any, coords: dict[str, float]) -> None:
        for i, name in enumerate(CONTACT_COORDS):
            if name not in coords:
                continue
            if PERIODIC[i]:
                prog.AddConstraint(2 * sin((state[i] - coords[name]) / 2), 0.0, 0.0)
            else:
                prog.AddLinearEqualityConstraint(state[i] == coords[name] / x_scale[i])

    for j, vp in enumerate(problem.via_points):
        targets(segments[j].final_state(), dict(vp.coords))
    targets(segments[-1].final_state(), dict(problem.goal))

    # the project's first guess (its input columns are the segments' knots), in the bounds
    S0 = np.clip(X0 / x_scale, -xb, xb)
    S0[0] = x_init
    Q0 = np.clip(U0g / u_scale, -ub, ub)
    for s_i, dircol in enumerate(segments):
        for k in range(grid.structure.segments[s_i] + 1):
            prog.SetInitialGuess(dircol.state(k), S0[grid.ends[s_i] + k])
            prog.SetInitialGuess(dircol.input(k), Q0[grid.ends[s_i] + s_i + k])

    solver = IpoptSolver()
    options = SolverOptions()
    sid = solver.solver_id()
    for key, value in drake_ipopt_options(problem).items():
        options.SetOption(sid, key, value)
    fd, log = tempfile.mkstemp(prefix="dexroll-drake-ipopt-", suffix=".txt")
    os.close(fd)
    options.SetOption(sid, "output_file", log)
    options.SetOption(sid, "file_print_level", 3)  # the summary only: the iteration count
    build = time.perf_counter() - t0

    try:
        t1 = time.perf_counter()
        result = solver.Solve(prog, None, options)
        solve = time.perf_counter() - t1
        found = _IPOPT_ITERATIONS.search(Path(log).read_text(errors="replace"))
    finally:
        with contextlib.suppress(OSError):
            os.unlink(log)
    details = result.get_solver_details()
    raw = str(details.ConvertStatusToString())
    S = [np.asarray(d.GetStateSamples(result)).T * x_scale for d in segments]
    W = [np.asarray(d.GetInputSamples(result)).T * u_scale for d in segments]
    Xp = np.vstack([S[0], *(x[1:] for x in S[1:])])
    U0 = np.vstack([w[:-1] for w in W])
    U1 = np.vstack([w[1:] for w in W])
    return _outcome(problem, grid, bool(result.is_success()), raw, build, solve,
                    int(found.group(1)) if found else None, Xp, U0, (U0 + U1) / 2, U1)


PEER_METHODS: dict[str, Callable[[BallOnPalmRequest], PeerOutcome]] = {
    "casadi_plain": casadi_plain,
    "drake": drake,
}


# -- side by side ----------------------------------------------------------------------------

def compare(request: BallOnPalmRequest, repeats: int = 3,
            methods: Sequence[str] = ("ours", *PEER_METHODS),
            planner: BallOnPalmPlanner | None = None) -> dict[str, dict[str, Any]]:
    """Medians over ``repeats`` solves of the project's cached planner and each peer.

    ``ours``: ``BallOnPalmPlanner.solve`` with its NLP already cached (one untimed warm-up
    solve first): ``wall`` the whole call (guesses, IPOPT, refinements, certificate),
    ``solve`` its ``stats.solve_time`` (initial guesses + IPOPT), ``ipopt`` the IPOPT calls
    alone (``stats.ipopt_time``). Peers: ``build`` and ``solve`` = ``ipopt`` (the IPOPT
    call) as in :class:`PeerOutcome`, ``wall`` the whole peer call (build, solve and the
    certificate). Timings are wall clock on this machine.
    """
    out: dict[str, dict[str, Any]] = {}
    for name in methods:
        if name == "ours":
            planner = planner or BallOnPalmPlanner()
            problem = _problem(request)
            planner.solve(problem)  # warm: the cache holds the NLP
            walls, solves, ipopts, sols = [], [], [], []
            for _ in range(repeats):
                t0 = time.perf_counter()
                sol = planner.solve(problem)
                walls.append(time.perf_counter() - t0)
                solves.append(sol.stats.solve_time)
                ipopts.append(sol.stats.ipopt_time)
                sols.append(sol)
            last = sols[-1]
            out[name] = {"status": str(last.status), "wall": statistics.median(walls),
                         "solve": statistics.median(solves),
                         "ipopt": statistics.median(ipopts), "build": 0.0,
                         "iterations": last.stats.iterations,
                         "objective": last.stats.objective,
                         "goal_error": max(last.goal_error.values(), default=0.0),
                         "certificate_passed": last.certificate.passed,
                         "n_final": last.stats.n_intervals}
            continue
        if name not in PEER_METHODS:
            raise KeyError(f"unknown method {name!r}; one of {['ours', *PEER_METHODS]}")
        runs: list[PeerOutcome] = []
        walls = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            runs.append(PEER_METHODS[name](request))
            walls.append(time.perf_counter() - t0)
            if runs[-1].status == "unavailable":
                break
        last_run = runs[-1]
        out[name] = {"status": last_run.status, "wall": statistics.median(walls),
                     "solve": statistics.median(r.solve_time for r in runs),
                     "ipopt": statistics.median(r.solve_time for r in runs),
                     "build": statistics.median(r.build_time for r in runs),
                     "iterations": last_run.iterations, "objective": last_run.objective,
                     "goal_error": last_run.goal_error,
                     "certificate_passed": bool(last_run.certificate.get("passed", 0.0)),
                     "message": last_run.message}
    return out


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m planner_service.bench.peers",
                                     description=__doc__.split("\n")[0] if __doc__ else None)
    parser.add_argument("requests", nargs="+", type=Path, help="ball-on-palm request files")
    parser.add_argument("--sizes", default="50,100", help="comma-separated n_intervals")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--methods", default=",".join(("ours", *PEER_METHODS)))
    parser.add_argument("--rounds", type=int, default=1,
                        help="run the methods side by side this many times, interleaved, and "
                             "report the median over rounds (this machine's timing drifts by "
                             "tens of percent between runs; interleaving compares like with "
                             "like)")
    args = parser.parse_args(argv)
    planner = BallOnPalmPlanner()
    print("| request | N | method | status | build [ms] | solve [ms] | IPOPT [ms] | wall [ms] "
          "| iter | objective | goal error | cert |")
    print("|---|---:|---|---|---:|---:|---:|---:|---:|---:|---:|---|")
    for path in args.requests:
        data = json.loads(path.read_text())
        for n in (int(v) for v in args.sizes.split(",")):
            request = BallOnPalmRequest.model_validate({**data, "n_intervals": n})
            rounds = [compare(request, args.repeats, args.methods.split(","), planner)
                      for _ in range(max(1, args.rounds))]
            rows = rounds[-1]
            for name, r in rows.items():
                for key in ("solve", "ipopt", "wall", "build"):
                    r[key] = statistics.median(rnd[name][key] for rnd in rounds)
                obj = "" if r["objective"] is None else f"{r['objective']:.6g}"
                ge = "" if r["goal_error"] is None else f"{r['goal_error']:.2g}"
                print(f"| {path.stem} | {n} | {name} | {r['status']} | {1e3 * r['build']:.1f} "
                      f"| {1e3 * r['solve']:.1f} | {1e3 * r['ipopt']:.1f} "
                      f"| {1e3 * r['wall']:.1f} | {r['iterations']} "
                      f"| {obj} | {ge} | {'passed' if r['certificate_passed'] else 'FAILED'} |",
                      flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
