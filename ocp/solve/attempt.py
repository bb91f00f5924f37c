"""One solve of a grasp's cached NLP: the seam that re-planning is built on.

:func:`attempt` solves the NLP of a problem's structure (built once and cached by the
planner) from a given initial state, moving or at rest, and a given warm point (a previous
plan, its IPOPT primal-dual point), within an iteration and time budget, and returns the
plan with its statistics. A receding-horizon controller calls it in a loop
(docs/replanning.md)::

    planner = ManipulationPlanner()
    sol = planner.solve(problem)                     # the first plan, certified
    for k in range(1, steps):
        t = k * period                               # now; measure the state
        x, u = measured_state(t)
        rest = replace(problem, duration=problem.duration - t)
        sol = attempt(rest, x0=x, u0=u, warm=shifted(sol, period),
                      options=AttemptOptions(max_iter=10), planner=planner)

The planner's own policy (its initial guesses in turn, grid refinement, re-patching, the
force stages: :class:`~ocp.solve.planner.ManipulationPlanner`) is made of the same three
steps this module has: :func:`setup` (the problem's values on its NLP: parameters, bounds,
the fixed initial state), :func:`run` (one IPOPT call from one initial point) and
:func:`finish` (the plan from the best point: trajectory, certificate, statistics).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from ocp.certify.certificate import Certificate
from ocp.solution import (
    Collocation,
    ManipulationSolution,
    SolverStats,
    Status,
    status_from_ipopt,
)
from ocp.solve.assemble import assemble_solution, planned_forces
from ocp.solve.certify import certify_grasp
from ocp.solve.guesses import Guess, Strategy, epigraph_guess, strategy_for
from ocp.solve.ipopt import NLP as _NLP
from ocp.solve.ipopt import kkt_residuals, warm_solver
from ocp.solve.switched import (
    plan_charts,
    restated,
    sampled_guess,
    switch_parameters,
    with_refs,
)
from ocp.spec.grasp import ManipulationProblem, contact_charts, support_goal_errors
from ocp.spec.problem import ProblemError
from ocp.transcription.chart_switch import PlanCharts
from ocp.transcription.collocation import NlpPoint, WarmStart, node_times
from ocp.transcription.grasp_model import GraspModel
from ocp.transcription.nlp_blocks import LOAD_VARS
from ocp.transcription.values import bounds, load_parameters, scales
from ocp.transcription.values import parameters as nlp_parameters

if TYPE_CHECKING:
    from ocp.solve.planner import ManipulationPlanner

__all__ = ["AttemptOptions", "IpoptRun", "Setup", "attempt", "collocation_of", "finish",
           "run", "setup", "shifted"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class AttemptOptions:
    """The budget of one :func:`attempt`: IPOPT iterations and wall time [s] (None: the
    problem's ``options``), and whether the plan is certified (seconds for a multi-finger
    grasp: a controller re-planning many times a second certifies the plan it finally
    executes, or every k-th one)."""

    max_iter: int | None = None
    time_limit: float | None = None
    certify: bool = False
    #: a warm start's push into the interior (IPOPT's ``warm_start_bound_push`` and its
    #: kin; None: :data:`~ocp.solve.ipopt.IPOPT_WARM_OPTIONS`' 1e-9). 1e-6 took fewer
    #: iterations toward a moved goal or from a moved start (the Allegro hand: 10 instead
    #: of 24), more from the warm plan's own optimum (7 instead of 3; docs/performance.md
    #: "Controller speed")
    warm_push: float | None = None


@dataclass
class Setup:
    """A problem on its structure's cached NLP: everything fixed before IPOPT runs (the
    parameter vector, the variable bounds with the initial state fixed, the grid)."""

    problem: ManipulationProblem
    nlp: _NLP
    model: GraspModel
    strategy: Strategy
    x0: FloatArray  # the initial state, physical units
    x_scale: FloatArray
    u_scale: FloatArray
    t_nodes: FloatArray
    prm: FloatArray  # the grasp model's parameters (shape, charts)
    p: FloatArray  # the NLP's parameter vector
    lbx: FloatArray
    ubx: FloatArray
    build_time: float  # building the NLP (0 when cached) and any solver made for it
    cache_hit: bool
    #: the charts the plan's points are on (one, or two with ``problem.chart_switch``)
    charts: PlanCharts = field(default_factory=lambda: PlanCharts((), ()))


@dataclass
class IpoptRun:
    """One IPOPT call: its outcome and the point it ended at (scaled NLP variables)."""

    status: Status
    raw: str
    iterations: int
    objective: float
    violation: float
    w: FloatArray
    time: float  # the IPOPT call [s]
    point: NlpPoint | None = field(default=None, repr=False)
    #: the solver whose point this is (``nlp.solver``'s ``stats()["solver"]``)
    solver: str = "ipopt"


def setup(planner: ManipulationPlanner, problem: ManipulationProblem,
          x0: FloatArray | None = None) -> Setup:
    """The problem's values on its structure's NLP (built, or taken from the planner's
    cache). ``x0``: the state at t = 0 (default: the problem's initial grasp, its joints by
    inverse kinematics); the input at t = 0 is the problem's ``initial_input`` when it has
    one."""
    nlp, hit = planner.build(problem)
    m = planner.model(problem)
    if x0 is None:
        x0 = planner.initial_state(problem)
    x_scale, u_scale = scales(problem, m)
    segments, tb = problem.segments()
    t_nodes = node_times(segments, tb)
    prm = m.params(np.asarray(problem.object.params, dtype=float), contact_charts(problem))
    charts = plan_charts(planner.model, problem, m, prm)
    p = nlp_parameters(problem, nlp, (x_scale, u_scale), switch_parameters(charts))
    lbx, ubx = bounds(problem, nlp, m, x0, x_scale, u_scale)
    strategy = strategy_for(problem)
    strategy.adjust_bounds(problem, nlp, lbx, ubx)
    return Setup(problem, nlp, m, strategy, np.asarray(x0, dtype=float), x_scale, u_scale,
                 t_nodes, prm, p, lbx, ubx, 0.0 if hit else nlp.build_time, hit, charts)


def initial_point(s: Setup, guess: Guess, aux: bool = True) -> FloatArray:
    """The NLP's initial point from a guess of the states and inputs (X, Xm, U, Um; physical
    units): the epigraph and force variables guessed from it (``aux`` False: zeros, for a
    warm start that takes them from a previous point), everything clipped into the
    bounds."""
    X, Xm, U, Um = guess
    nlp, n = s.nlp, len(s.t_nodes) - 1
    with_refs(s, X)  # (a plan whose contacts change chart: the switch's angles)
    if aux:
        Sg, Fg = epigraph_guess(s.model, np.vstack([X, Xm]), s.prm,
                                load_parameters(s.problem) if nlp.n_load else None,
                                s.charts if s.charts.switched else None)
    else:
        n_f = 3 * nlp.n_force + LOAD_VARS * nlp.n_load
        Sg, Fg = np.zeros((nlp.n_epigraph, 2 * n + 1)), np.zeros((n_f, 2 * n + 1))
    w0 = nlp.pack((X / s.x_scale).T, (Xm / s.x_scale).T, (U / s.u_scale).T,
                  (Um / s.u_scale).T, Sg[:, : n + 1], Sg[:, n + 1:], Fg)
    return np.clip(np.asarray(w0).ravel(), s.lbx, s.ubx)


def run(s: Setup, w0: FloatArray, point: NlpPoint | None, deadline: float,
        max_iter: int, warm_push: float | None = None, solver: Any = None) -> IpoptRun:
    """One IPOPT call from ``w0`` within ``max_iter`` iterations and the ``deadline``
    (``time.perf_counter()``). ``point``: a previous primal-dual point of this very NLP
    (its multipliers start IPOPT's, with a warm-start barrier; its epigraph and force
    variables replace ``w0``'s; ``warm_push``: :class:`AttemptOptions`'; ``solver``: the
    warm solver to use instead, e.g. :func:`~ocp.solve.ipopt.realtime_solver`)."""
    nlp = s.nlp
    chosen, solver, duals = solver, nlp.solver, {}
    if point is not None:
        aux = nlp.aux_indices()
        w0 = w0.copy()
        w0[aux] = np.clip(point.w[aux], s.lbx[aux], s.ubx[aux])
        key = (float(warm_push or 0.0), nlp.compiled)
        if warm_push is None:
            if nlp.warm_solver is None:
                t_build = time.perf_counter()
                nlp.warm_solver = warm_solver(nlp)
                s.build_time += time.perf_counter() - t_build
            solver = nlp.warm_solver
        else:
            if key not in nlp.warm_solvers:
                t_build = time.perf_counter()
                nlp.warm_solvers[key] = warm_solver(nlp, warm_push)
                s.build_time += time.perf_counter() - t_build
            solver = nlp.warm_solvers[key]
        duals = {"lam_x0": point.lam_x, "lam_g0": point.lam_g}
        if chosen is not None:
            solver = chosen
    nlp.stop.arm(deadline, max_iter)
    t0 = time.perf_counter()
    res = solver(x0=w0, p=s.p, lbx=s.lbx, ubx=s.ubx, lbg=nlp.lbg, ubg=nlp.ubg, **duals)
    elapsed = time.perf_counter() - t0
    st = solver.stats()
    raw = str(st["return_status"])
    status = nlp.stop.reason if raw == "User_Requested_Stop" and nlp.stop.reason \
        else status_from_ipopt(raw)
    g = np.asarray(res["g"]).ravel()
    viol = float(np.max(np.maximum(nlp.lbg - g, g - nlp.ubg), initial=0.0))
    out = [np.asarray(res[k]).ravel() for k in ("x", "lam_x", "lam_g")]
    return IpoptRun(status, raw, int(st["iter_count"]), float(res["f"]),
                    viol if math.isfinite(viol) else math.inf, out[0], elapsed,
                    NlpPoint(nlp.fingerprint, *out)
                    if all(np.all(np.isfinite(a)) for a in out) else None,
                    str(st.get("solver", "ipopt")))


def collocation_of(s: Setup, w: FloatArray) -> Collocation:
    """The states and inputs of an NLP point ``w`` (scaled variables) on its grid, in
    physical units: the nodes' and midpoints' states, each interval's inputs at its start,
    midpoint and end."""
    Xs, Xms, Us, Ums = (np.asarray(a) for a in s.nlp.unpack(w)[:4])
    Ucols = Us.T * s.u_scale
    return Collocation(s.t_nodes, Xs.T * s.x_scale, Xms.T * s.x_scale,
                       Ucols[s.nlp.hs.left_cols], Ums.T * s.u_scale,
                       Ucols[s.nlp.hs.right_cols])


def finish(s: Setup, runs: list[IpoptRun], solve_time: float, deadline: float,
           certify: bool) -> ManipulationSolution:
    """The plan of the best run (the first solved one, else the least infeasible): its
    collocation values, trajectory, certificate (when ``certify`` and the deadline is not
    past) and statistics over all ``runs`` (``solve_time``: the whole loop that made them,
    guesses included)."""
    problem, nlp, m = s.problem, s.nlp, s.model
    best = next((r for r in runs if r.status is Status.SOLVED),
                min(runs, key=lambda r: r.violation))
    col = collocation_of(s, best.w)
    charts = s.charts
    if charts.switched:  # each interval's end input on its own chart
        with_refs(s, col.X)  # continued from the plan's own angles before the switch
        col = replace(col, U1=charts.first_chart_inputs(col.X, col.U1))
    if nlp.n_load:  # the planned forces, after the internal forces' rows
        col = replace(col, forces=planned_forces(
            problem, m, np.asarray(nlp.unpack(best.w)[6])[3 * nlp.n_force:], col.X, col.Xm,
            s.prm, charts))
    # one deadline over the whole plan: past it, no certificate either (seconds for a
    # multi-finger grasp); the plan is the last iterate, stopped by the time limit
    late = certify and time.perf_counter() >= deadline
    status = Status.TIME_LIMIT if late else best.status
    t_cert = time.perf_counter()
    traj = charts.interpolant(s.t_nodes, col.X, col.U0, col.Um, col.U1)
    cert = certify_grasp(problem, m, traj, s.prm, problem.tolerances, col.forces, charts) \
        if certify and not late else \
        Certificate.failed("not certified: the time limit was reached first" if late
                           else "not certified (planned as an initial guess)")
    cert_time = time.perf_counter() - t_cert
    segments, _ = problem.segments()
    goal_error = support_goal_errors(problem, col.X, [0, *np.cumsum(segments).tolist()])
    sol = assemble_solution(problem, m, status, best.raw, col, traj, s.prm, cert, goal_error,
                            charts)
    iterations = sum(r.iterations for r in runs)
    ipopt_time = sum(r.time for r in runs)
    primal = dual = None
    if best.point is not None:
        pt = best.point
        primal, dual = kkt_residuals(nlp, pt.w, s.p, pt.lam_g, pt.lam_x, s.lbx, s.ubx)
    stats = SolverStats(raw_status=best.raw, iterations=iterations, attempts=len(runs),
                        build_time=s.build_time, solve_time=solve_time,
                        certificate_time=cert_time, objective=best.objective,
                        cache_hit=s.cache_hit, n_intervals=len(s.t_nodes) - 1,
                        ipopt_time=ipopt_time, solver=best.solver,
                        primal_infeasibility=primal, dual_infeasibility=dual)
    return replace(sol, stats=stats, nlp_point=best.point)


def _checked_state(problem: ManipulationProblem, m: GraspModel, name: str, value: Any,
                   size: int) -> FloatArray:
    a = np.asarray(value, dtype=float).ravel()
    if a.shape != (size,) or not np.all(np.isfinite(a)):
        raise ProblemError([(name, f"must be {size} finite numbers (the grasp's "
                                   f"{'states' if name == 'x0' else 'inputs'} in its "
                                   f"layout), got shape {np.shape(value)}")])
    return a


def _closure_errors(problem: ManipulationProblem, m: GraspModel, x0: FloatArray
                    ) -> list[tuple[str, str]]:
    """Whether each fingertip is where its joints put it at ``x0`` (eq. 6, within the
    certificate's closure tolerances): a state the grasp cannot explain is not planned
    through."""
    if not m.fingertips:
        return []
    prm = m.params(np.asarray(problem.object.params, dtype=float), contact_charts(problem))
    closure = np.asarray(m.path(x0, prm)[0]).ravel().reshape(-1, 6)
    pol, errs = problem.tolerances, []
    for i, row in enumerate(closure):
        dp, dr = float(np.linalg.norm(row[:3])), float(np.linalg.norm(row[3:]))
        if dp > pol.closure_position or dr > pol.closure_orientation:
            errs.append((f"x0 (finger {i})",
                         f"the fingertip is {dp:.3g} m and {dr:.3g} rad from where its "
                         f"contact coordinates put it (closure tolerances "
                         f"{pol.closure_position:g} m, {pol.closure_orientation:g} rad): "
                         "estimate the contact coordinates from the joints first"))
    return errs


def attempt(problem: ManipulationProblem, *, x0: Any = None, u0: Any = None,
            warm: ManipulationSolution | WarmStart | None = None,
            options: AttemptOptions | None = None,
            planner: ManipulationPlanner | None = None) -> ManipulationSolution:
    """Solve the cached NLP of ``problem``'s structure once.

    ``x0``: the state at t = 0 in the grasp's layout (physical units; default the
    problem's initial grasp): every fingertip must be where its joints put it (else
    :class:`ProblemError` naming the finger). ``u0``: the input at t = 0 (a moving start:
    the first input is fixed to it; default at rest with the smooth timing). ``warm``: a
    previous plan or warm start (:func:`shifted` for a receding horizon): its states and
    inputs interpolated on this grid, and its IPOPT primal-dual point when it belongs to
    this very NLP; default the strategy's first own guess. ``options``: the iteration and
    time budget and whether to certify. ``planner``: whose NLP cache (default the
    process-wide planner's).

    One IPOPT call, no refinement, no re-patching: the result says what IPOPT reached
    (``status``; ``stats.iterations``), with a certificate only when asked."""
    if planner is None:
        from ocp.solve.planner import default_planner

        planner = default_planner()
    opts = options or AttemptOptions()
    problem.validate()
    m = planner.model(problem)
    if x0 is not None:
        x0 = _checked_state(problem, m, "x0", x0, m.nx)
        errs = _closure_errors(problem, m, x0)
        if errs:
            raise ProblemError(errs)
    if u0 is not None:
        u0 = _checked_state(problem, m, "u0", u0, m.nu)
        problem = replace(problem, initial_input=tuple(float(v) for v in u0))
    if problem.reference is not None:
        errs = problem.reference.errors(m.nx, m.nu, problem.duration)
        if errs:
            raise ProblemError(errs)
    if warm is not None:
        ws = warm.warm_start if isinstance(warm, ManipulationSolution) else warm
        errs = ws.errors("warm", m.nx, m.nu)
        if errs:
            raise ProblemError(errs)
    time_limit = problem.options.time_limit if opts.time_limit is None else opts.time_limit
    max_iter = problem.options.max_iter if opts.max_iter is None else opts.max_iter
    deadline = time.perf_counter() + time_limit
    planner.adopt_compiled()
    s = setup(planner, problem, x0)
    t_loop = time.perf_counter()
    point = None
    if warm is not None:
        ws = warm.warm_start if isinstance(warm, ManipulationSolution) else warm
        sampled = sampled_guess(warm, s) if isinstance(warm, ManipulationSolution) else None
        guess = sampled or restated(s, s.strategy.warm_guess(warm, problem, s.nlp, s.x0,
                                                              s.t_nodes))
        point = ws.nlp_point_for(s.nlp.fingerprint, s.nlp.pack.nnz_out(0), len(s.nlp.lbg))
    else:
        guess = restated(s, next(iter(s.strategy.own_guesses(planner, problem, m, s.nlp,
                                                             s.x0, s.t_nodes))))
    r = run(s, initial_point(s, guess), point, deadline, max_iter, opts.warm_push)
    return finish(s, [r], time.perf_counter() - t_loop, deadline, opts.certify)


def shifted(sol: ManipulationSolution, dt: float) -> WarmStart:
    """A plan's rest after ``dt`` seconds as a warm start of the plan that starts then
    (a receding or shrinking horizon): its states and inputs from ``dt`` on, at its
    collocation points' times moved back by ``dt`` (a horizon kept at the plan's duration
    holds the last state after its end), and its IPOPT primal-dual point (the next plan's
    NLP is the same when its grid is, the usual approximation of shifting the
    multipliers along)."""
    if not 0.0 <= dt < sol.duration:
        raise ValueError(f"dt must be in [0, {sol.duration}) s, got {dt}")
    ts = sol.t[sol.t > dt + 1e-12]
    ts = np.concatenate([[dt], ts])
    x, u = sol.interpolate(ts)
    return WarmStart(ts - dt, x, u, sol.nlp_point)
