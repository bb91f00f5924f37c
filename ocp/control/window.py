"""A controller that tracks a certified plan over a short window at a fixed rate
(docs/control.md).

The whole-remainder re-plan (:class:`~ocp.solve.replan.Replanner`) solves the rest of the
motion; at a controller's rate it cannot. :class:`WindowController` solves, at every tick,
the grasp's NLP over the next ``horizon`` seconds only (``intervals`` collocation
intervals) from the measured state, tracking the reference plan's states and inputs (a
:class:`~ocp.spec.reference.Reference`: weighted terms, the object's pose above the
joints and contact coordinates, the last node weighted more: the terminal condition,
soft, so that a pushed grasp still has a window), its first and last inputs free and
consistent with the states (a window starts and ends moving), under the plan's own
constraints (rolling, closure at the position and velocity levels, force closure in the
friction cones, joint limits and accelerations). Each tick warm-starts IPOPT
(:func:`~ocp.solve.ipopt.realtime_solver`) from the previous window's primal-dual point
and stops after ``max_iter`` iterations (a real-time budget; two for a few ticks after a
window was left unsettled); the tick reports the KKT residuals the budget left. The
reference can be replaced by a re-plan of the rest (:meth:`WindowController.retarget`).

Why tracking and not the plan's own objective: a window that minimises the plan's effort
and grasp angle over 0.5 s finds, on a grid of 10 intervals, a motion other than the
reference that the dense certificate catches slipping (experiment 1: the fingertip's spin
rate 1.1-2x its tolerance after 2 iterations, slip 2.3x after 10); the reference was
certified on its own grid, and a window that stays near it is certified too
(docs/control.md, "Why windows slipped, and what fixed it").

Every window can be certified (:meth:`WindowController.certify`: the same dense checks as
a plan's), outside the tick's budget.
"""

from __future__ import annotations

import math
import time
from collections import deque
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from ocp.certify.certificate import Certificate
from ocp.solution import Collocation, ManipulationSolution, Status
from ocp.solve.attempt import Setup, collocation_of, finish, initial_point, setup
from ocp.solve.backend import WINDOW_BACKENDS, window_backend
from ocp.spec.grasp import ManipulationProblem, contact_charts
from ocp.spec.motion import Tracking
from ocp.spec.problem import ProblemError
from ocp.spec.reference import Reference
from ocp.transcription.collocation import NlpPoint
from ocp.transcription.values import reference_parameters

if TYPE_CHECKING:
    from ocp.solve.planner import ManipulationPlanner

__all__ = ["PREPARE_ITERATIONS", "ControllerOptions", "Tick", "WindowController"]

FloatArray = NDArray[np.float64]

#: IPOPT iterations of :meth:`WindowController.prepare`'s window at t = 0 (to convergence)
PREPARE_ITERATIONS = 50

#: ticks each backend is measured on by ``backend="auto"`` (:meth:`WindowController.prepare`)
SELECT_TICKS = 10


def _window_points(c: Collocation) -> tuple[FloatArray, FloatArray, FloatArray]:
    """A window's collocation points in time order: their times (nodes and midpoints),
    states and inputs."""
    tp = np.concatenate([c.t_nodes, (c.t_nodes[:-1] + c.t_nodes[1:]) / 2])
    order = np.argsort(tp)
    xp = np.vstack([c.X, c.Xm])[order]
    up = np.vstack([np.vstack([c.U0, c.U1[-1:]]), c.Um])[order]
    return tp[order], xp, up


@dataclass(frozen=True)
class ControllerOptions:
    """The window: ``horizon`` [s] and its collocation ``intervals``; the real-time budget:
    IPOPT iterations per tick (``max_iter``) and a wall-clock safety (``time_limit`` [s]);
    the tracking weights (:class:`~ocp.spec.reference.Reference`). Near the reference's
    end the window keeps its horizon and tracks the reference's final state at rest past
    it: the same NLP, its scaling and its multipliers from tick to tick (a window that
    shrank to what was left lost IPOPT's multipliers at every tick, and one iteration from
    the primal point alone left experiment 1's last 0.35 s slipping 1.05-1.84x its
    tolerance)."""

    horizon: float = 0.5
    intervals: int = 10
    max_iter: int = 1
    #: the budget of a tick whose previous window was left more than ``settled_tol``
    #: infeasible (scaled NLP units; after a disturbance): one iteration a tick left
    #: experiment 2's windows after a 3 mm push 1e-3 infeasible to the end and half of
    #: them failed the certificate; two a tick, 130 of 133 passed
    unsettled_max_iter: int = 2
    settled_tol: float = 1e-5
    #: how many ticks the unsettled budget lasts after a window was last left unsettled
    #: (without it the budget alternated, a converged window of two iterations followed
    #: by one of one left unsettled, and a quarter of the windows failed)
    settle_ticks: int = 10
    time_limit: float = 1.0
    state_weight: float = 1e5
    input_weight: float = 1e4
    terminal_weight: float = 10.0
    #: the weight of the states other than the object's pose (the joints, the
    #: fingertips' contact coordinates) relative to the object's (1): a pushed grasp
    #: cannot roll back every contact coordinate within a window, the object's pose it can
    grasp_state_weight: float = 0.1
    #: the window's first input fixed to the measured one (a measurement of the rates
    #: consistent with the grasp: the estimate's); else free, tracked toward it and
    #: consistent with the measured state: a measured rate that MuJoCo's servos make noisy
    #: does not force a jerk into the window
    fix_start: bool = False
    #: the Hessian of the objective alone (Gauss-Newton: positive semidefinite, one
    #: factorisation per iteration) instead of the Lagrangian's exact one
    gauss_newton: bool = False
    #: the warm start's push into the interior (:func:`~ocp.solve.ipopt.warm_solver`'s;
    #: None: its 1e-9). A window's point is the previous window's, shifted: at 1e-9 the
    #: internal forces of three or more contacts, tight on their cones, could not follow
    #: (the three-finger turn's windows 0.09 infeasible after their iteration, and 53 ms
    #: per tick in inertia corrections); at 1e-2 they converge within a few ticks (1e-5)
    #: and a tick costs 17.5 ms
    warm_push: float | None = 1e-2
    #: how many ticks the controller keeps (``WindowController.ticks``; each holds its
    #: window's NLP values, tens of kB): a robot ticks for hours
    history: int = 10_000
    #: the initial guess of a tick's window: the previous window shifted (True) or the
    #: reference (False); IPOPT's multipliers are the previous window's either way
    shift_warm: bool = False
    #: the solver of a tick (:data:`~ocp.solve.backend.WINDOW_BACKENDS`): "ipopt" (IPOPT
    #: warm from the previous window, :func:`~ocp.solve.ipopt.realtime_solver`) or "rti"
    #: (real-time iterations by multiple shooting, Gauss-Newton QPs solved by HPIPM,
    #: :mod:`~ocp.solve.rti`; a smooth timing, every fingertip touching); "auto": the
    #: faster of the two on this problem and machine, measured by
    #: :meth:`WindowController.prepare`
    backend: str = "ipopt"

    def errors(self) -> list[tuple[str, str]]:
        errs: list[tuple[str, str]] = []
        if not (math.isfinite(self.horizon) and 0.0 < self.horizon <= 10.0):
            errs.append(("horizon", f"must be in (0, 10] s, got {self.horizon}"))
        if not 2 <= self.intervals <= 200:
            errs.append(("intervals", f"must be in [2, 200], got {self.intervals}"))
        if not 1 <= self.max_iter <= 1000:
            errs.append(("max_iter", f"must be in [1, 1000], got {self.max_iter}"))
        if not 1 <= self.unsettled_max_iter <= 1000:
            errs.append(("unsettled_max_iter",
                         f"must be in [1, 1000], got {self.unsettled_max_iter}"))
        if not (math.isfinite(self.settled_tol) and self.settled_tol > 0):
            errs.append(("settled_tol", f"must be > 0, got {self.settled_tol}"))
        if not 1 <= self.history <= 10_000_000:
            errs.append(("history", f"must be in [1, 1e7], got {self.history}"))
        if self.backend not in (*WINDOW_BACKENDS, "auto"):
            errs.append(("backend", f"must be one of {(*WINDOW_BACKENDS, 'auto')}, got "
                                    f"{self.backend!r}"))
        if not 0 <= self.settle_ticks <= 100_000:
            errs.append(("settle_ticks", f"must be in [0, 100000], got {self.settle_ticks}"))
        return errs


@dataclass
class Tick:
    """One tick of the controller at time ``t`` (the reference's clock): ``status``
    ("tracked": a window solved within the budget; "converged": and IPOPT converged;
    "failed": IPOPT's point unusable),
    the window's values (``collocation``: its node times from 0 = ``t``, states and
    inputs), IPOPT's ``iterations`` and time (``solve_time`` [s]), the whole tick's
    ``wall_time`` [s], and the KKT residuals the budget left (``primal_infeasibility``,
    ``dual_infeasibility``: the NLP's scaled units). ``certificate`` is filled by
    :meth:`WindowController.certify`."""

    t: float
    status: str
    horizon: float
    collocation: Collocation | None
    iterations: int = 0
    solve_time: float = 0.0
    wall_time: float = 0.0
    primal_infeasibility: float | None = None
    dual_infeasibility: float | None = None
    raw_status: str = ""
    certificate: Certificate | None = None
    #: the preparation made for this tick before its measurement
    #: (:meth:`WindowController.prepare_next`; the RTI backend's linearisation), not in
    #: ``wall_time``; 0 when there was none (the tick linearised within its wall time)
    prepare_time: float = 0.0
    #: the window's problem and NLP values (to assemble its plan on demand)
    _setup: Setup | None = field(default=None, repr=False)
    _point: NlpPoint | None = field(default=None, repr=False)
    _w: FloatArray | None = field(default=None, repr=False)
    _raw: tuple[Status, str, float, str] | None = field(default=None, repr=False)

    @property
    def certified(self) -> bool | None:
        return None if self.certificate is None else self.certificate.passed

    @property
    def input(self) -> FloatArray | None:
        """The window's first input (the grasp's input layout, physical units; joint
        rates among them): what the tick commands now. None when no window was solved."""
        return None if self.collocation is None else self.collocation.U0[0]


class WindowController:
    """Tracks ``reference`` (a certified plan of ``problem``) over a short window at each
    :meth:`tick` (see the module). ``planner``: whose NLP cache (default the process-wide
    planner's)."""

    def __init__(self, problem: ManipulationProblem, reference: ManipulationSolution,
                 options: ControllerOptions | None = None,
                 planner: ManipulationPlanner | None = None) -> None:
        if planner is None:
            from ocp.solve.planner import default_planner

            planner = default_planner()
        self.options = o = options or ControllerOptions()
        errs = [(f"options.{k}", v) for k, v in o.errors()]
        if problem.phases is not None and len(problem.phases) > 1:
            errs.append(("problem.phases", "the window controller tracks plans of one "
                                           "contact phase (a rolling plan), not a gait's"))
        if not problem.fingers:
            errs.append(("problem.fingers", "the window controller tracks grasps with "
                                            "fingers"))
        if reference.chart_switch is not None:
            errs.append(("reference", "the plan's contacts change chart at t = "
                                      f"{reference.chart_switch.time:g} s; tracking a plan "
                                      "across a chart switch is not built"))
        if errs:
            raise ProblemError(errs)
        #: the window's solver (:mod:`ocp.solve.backend`; "auto": IPOPT until
        #: :meth:`prepare` has measured the backends)
        self.backend = window_backend("ipopt" if o.backend == "auto" else o.backend,
                                      gauss_newton=o.gauss_newton, warm_push=o.warm_push,
                                      compile_dir=planner.compile_dir)
        #: ``backend="auto"``: what :meth:`prepare` measured and chose
        self.selection: dict[str, Any] | None = None
        #: the tick prepared (:meth:`prepare_next`): its time, the preparation's wall time
        self._prepared: tuple[float, float] | None = None
        self.planner, self.reference = planner, reference
        self.problem = problem
        self.duration = float(reference.duration)
        #: when the reference starts on the controller's clock (:meth:`retarget`)
        self.start = 0.0
        palm = problem.palm
        if palm is not None:
            palm = replace(palm, goal={}, via_points=())
        #: the window's problem, but for its horizon, ends and reference
        self.template = replace(problem, palm=palm, motion=None, tracking=Tracking(),
                                forces=None, n_intervals=o.intervals, segment_counts=None,
                                phases=None)
        self.model = m = planner.model(self.template)
        #: the grasp model's parameters (the object's shape, the contacts' charts)
        self.params = m.params(np.asarray(problem.object.params, dtype=float),
                               contact_charts(problem))
        #: each state's tracking weight: the object's pose 1 (a free object's block; on a
        #: palm the contact's point (x, y): the ball's chart coordinates and contact angle
        #: turn with its rolling, and a pushed ball rolled back to the reference's
        #: position in a window cannot also come back to its orientation), the others less
        weights = np.full(m.nx, o.grasp_state_weight)
        obj = m.contacts[0].xs
        weights[obj] = 1.0
        if problem.palm is not None:
            weights[obj.start + 2:obj.stop] = o.grasp_state_weight
        self.state_weights = tuple(float(v) for v in weights)
        self._last: Tick | None = None
        self._base: Setup | None = None
        self._unsettled = 0
        self._x0_index = self._u0_index = np.zeros(0, dtype=np.int64)
        #: the last ``options.history`` ticks (to certify them beside the loop)
        self.ticks: deque[Tick] = deque(maxlen=o.history)

    # -- the reference --------------------------------------------------------------------
    def retarget(self, reference: ManipulationSolution, start: float) -> None:
        """Track ``reference`` from now on, a plan of the same grasp that starts at
        ``start`` on the controller's clock (the rest of the motion re-planned from a
        measured state: :class:`~ocp.solve.replan.Replanner`) and ends at the same time.
        The window's NLP is the same; the next window starts from the last one's point."""
        self.reference, self.start = reference, float(start)
        # the previous window's point was for the old reference: the next few ticks take
        # the unsettled budget
        self._unsettled = self.options.settle_ticks

    def state_at(self, t: float) -> tuple[FloatArray, FloatArray]:
        """The reference's state and input at ``t`` (the controller's clock; clamped into
        the reference's duration)."""
        s = t - self.start
        x, u = self.reference.interpolate([min(max(s, 0.0), self.reference.duration)])
        return x[0], u[0]

    def window(self, t: float, u0: FloatArray | None = None) -> ManipulationProblem:
        """The window's problem at ``t``: its horizon, the reference's states and inputs at
        its collocation points (past the reference's end its final state, at rest), the
        input at its start ``u0`` (None: the reference's): fixed with ``fix_start``,
        else tracked there like the reference's inputs, the window's own first input
        free but consistent with the measured state (the closure at the velocity level);
        its end moving, tracked."""
        o = self.options
        T = o.horizon
        n = o.intervals
        ts = np.linspace(0.0, T, 2 * n + 1)
        s = t - self.start + ts
        x, u = self.reference.interpolate(np.clip(s, 0.0, self.reference.duration))
        u[s > self.reference.duration] = 0.0
        if u0 is not None:
            u[0] = u0
        ref = Reference(ts, x, u, state_weight=o.state_weight, input_weight=o.input_weight,
                        terminal_weight=o.terminal_weight, state_weights=self.state_weights)
        return replace(self.template, duration=T, reference=ref,
                       initial_input=tuple(float(v) for v in u[0]) if o.fix_start else None)

    # -- a tick ---------------------------------------------------------------------------
    def prepare(self) -> float:
        """Build the window's NLP and its solvers before the loop, and solve the window at
        t = 0 from the reference to convergence: the first tick starts from its
        primal-dual point (from a cold point one iteration left experiment 2's first
        window uncertified in MuJoCo). The wall time [s] it took."""
        t0 = time.perf_counter()
        if self.options.backend == "auto":
            self.selection = self._select()
        self._converge()
        self.ticks.clear()
        return time.perf_counter() - t0

    def _converge(self) -> Tick:
        """The window at t = 0 from the reference's state, solved to convergence."""
        o = self.options
        self.options = replace(o, max_iter=max(o.max_iter, PREPARE_ITERATIONS))
        try:
            return self.tick(0.0, self.state_at(0.0)[0])
        finally:
            self.options = o

    def _select(self) -> dict[str, Any]:
        """``backend="auto"``: each backend that can solve the window measured on
        :data:`SELECT_TICKS` ticks along the reference (every 10 ms from the converged
        window at t = 0, each tick prepared), its last window certified; the one whose
        window passed with the least busy time a tick (the tick's wall time and its
        preparation's, medians) is kept. The measurements and the choice."""
        o = self.options
        measured: dict[str, dict[str, Any]] = {}
        ts = [min(k * 0.01, self.duration) for k in range(1, SELECT_TICKS + 1)]
        made: dict[str, Any] = {}
        for name in WINDOW_BACKENDS:
            backend = window_backend(name, gauss_newton=o.gauss_newton,
                                     warm_push=o.warm_push,
                                     compile_dir=self.planner.compile_dir)
            why = backend.unsupported(self._setup(self.window(0.0), self.state_at(0.0)[0]))
            if why is not None:
                measured[name] = {"unsupported": why}
                continue
            self.backend = made[name] = backend
            self._last, self._prepared, self._unsettled = None, None, 0
            self._converge()
            walls, preps = [], []
            for t in ts:
                preps.append(self.prepare_next(t))
                walls.append(self.tick(t, self.state_at(t)[0]).wall_time)
            last = self.ticks[-1]
            measured[name] = {
                "tick_median": float(np.median(walls)),
                "preparation_median": float(np.median(preps)),
                "busy_median": float(np.median(np.add(walls, preps))),
                "certified": bool(self.certify(last).passed)}
            self.ticks.clear()
        ok = [n for n in made if measured[n]["certified"]] or list(made)
        chosen = min(ok, key=lambda n: measured[n]["busy_median"])
        self.backend = made[chosen]
        self._last, self._prepared, self._unsettled = None, None, 0
        return {"chosen": chosen, "measured": measured}

    def tick(self, t: float, x: FloatArray, u: FloatArray | None = None) -> Tick:
        """One tick at time ``t`` from the measured state ``x`` and input ``u`` (the
        grasp's layouts, physical units: :func:`~ocp.solve.estimate.estimate_state` makes
        them from joints and the object's pose; ``u`` None: the reference's, a window
        whose first input is free)."""
        o = self.options
        t_start = time.perf_counter()
        problem = self.window(t, u)
        s = self._setup(problem, np.asarray(x, dtype=float))
        guess = self._guess(t, s)
        prev = self._last
        point = prev._point if prev is not None and prev._point is not None \
            and prev._point.nlp == s.nlp.fingerprint else None
        if prev is not None and (prev.primal_infeasibility or 0.0) > o.settled_tol:
            self._unsettled = o.settle_ticks
        budget = max(o.max_iter, o.unsettled_max_iter) if self._unsettled > 0 else o.max_iter
        self._unsettled -= 1
        deadline = time.perf_counter() + o.time_limit
        prepare_time = 0.0
        if self._prepared is not None:  # (made for this tick, or stale: dropped either way)
            prepare_time = self._prepared[1] if self._prepared[0] == t else 0.0
            self._prepared = None
        r, primal, dual = self.backend.solve(s, self._warm_point(s, guess, point), point,
                                             deadline, budget)
        col = collocation_of(s, r.w)
        ok = r.point is not None and np.all(np.isfinite(r.w))
        status = "failed" if not ok else \
            "converged" if r.status is Status.SOLVED else "tracked"
        out = Tick(t, status, problem.duration, col if ok else None, r.iterations, r.time,
                   0.0, primal, dual, r.raw, prepare_time=prepare_time, _setup=s,
                   _point=r.point, _w=r.w, _raw=(r.status, r.raw, r.objective, r.solver))
        out.wall_time = time.perf_counter() - t_start
        if ok:
            self._last = out
        self.ticks.append(out)
        return out

    def prepare_next(self, t: float) -> float:
        """Prepare the tick at ``t`` before its state is measured (the RTI backend: the QP
        linearised at the window's guess from the state the last window predicts at
        ``t``; the measurement then enters only the QP's bounds); the wall time [s] it
        took. A controller calls it right after sending a tick's input. Nothing to
        prepare for IPOPT (0)."""
        last = self._last
        if last is None or last.collocation is None or not self.backend.prepares:
            return 0.0
        t0 = time.perf_counter()
        tp, xp, _ = _window_points(last.collocation)
        dt = min(max(t - last.t, 0.0), float(tp[-1]))
        x = np.array([np.interp(dt, tp, xp[:, j]) for j in range(xp.shape[1])])
        s = self._setup(self.window(t), x)
        self.backend.prepare(s, self._warm_point(s, self._guess(t, s), last._point))
        wall = time.perf_counter() - t0
        self._prepared = (t, wall)
        return wall

    @staticmethod
    def _warm_point(s: Setup, guess: tuple[FloatArray, FloatArray, FloatArray, FloatArray],
                    point: NlpPoint | None) -> FloatArray:
        """The window's initial point: the guess's states and inputs, the other variables
        (epigraph, forces, copies) the previous window's."""
        w = initial_point(s, guess, aux=point is None)
        if point is not None:
            aux = s.nlp.aux_indices()
            w[aux] = np.clip(point.w[aux], s.lbx[aux], s.ubx[aux])
        return w

    def _setup(self, problem: ManipulationProblem, x: FloatArray) -> Setup:
        """The window's values on its NLP: the first tick's :func:`~ocp.solve.attempt.setup`
        kept, and at every later tick only what changes (the measured state's bounds,
        the reference's parameters) written into copies of its vectors: the same values
        as a new setup (tested), without recomputing the bounds and parameters that do
        not change."""
        base = self._base
        if base is None:  # (every window has the same horizon and grid)
            base = setup(self.planner, problem, x)
            why = self.backend.unsupported(base)
            if why is not None:
                raise ProblemError([("options.backend", why)])
            self._base = base
            parts = base.nlp.unpack(np.arange(len(base.lbx), dtype=float))
            self._x0_index = np.asarray(parts[0])[:, 0].round().astype(np.int64)
            self._u0_index = np.asarray(parts[2])[:, base.nlp.hs.left_cols[0]].round() \
                .astype(np.int64)
            return base
        lbx, ubx = base.lbx.copy(), base.ubx.copy()
        lbx[self._x0_index] = ubx[self._x0_index] = x / base.x_scale
        if problem.initial_input is not None:  # ``fix_start``: the measured input
            lbx[self._u0_index] = ubx[self._u0_index] = \
                np.asarray(problem.initial_input, dtype=float) / base.u_scale
        p = base.p.copy()
        offsets = base.nlp.params.offsets()
        values = reference_parameters(problem, base.t_nodes, (base.x_scale, base.u_scale))
        for name, value in values.items():
            p[offsets[name]] = np.asarray(value, dtype=float).ravel(order="F")
        return replace(base, problem=problem, x0=x, p=p, lbx=lbx, ubx=ubx, build_time=0.0,
                       cache_hit=True)

    def _guess(self, t: float, s: Setup) -> tuple[FloatArray, FloatArray, FloatArray,
                                                   FloatArray]:
        """The window's initial guess (X, Xm, U at the input columns, Um): the previous
        window at the same times, shifted by the time since it (linear between its
        collocation points), the reference past its end; the first state the measured one."""
        t_nodes = s.t_nodes
        tm = (t_nodes[:-1] + t_nodes[1:]) / 2
        hs = s.nlp.hs
        ref = s.problem.reference
        assert ref is not None
        X, U = ref.at(t_nodes)
        Xm, Um = ref.at(tm)
        prev = self._last
        if self.options.shift_warm and prev is not None and prev.collocation is not None:
            dt = t - prev.t
            tp, xp, up = _window_points(prev.collocation)

            def shift(values: FloatArray, base: FloatArray, ts: FloatArray) -> FloatArray:
                inside = ts + dt <= tp[-1]
                out = base.copy()
                for j in range(values.shape[1]):
                    out[inside, j] = np.interp(ts[inside] + dt, tp, values[:, j])
                return out

            X, Xm = shift(xp, X, t_nodes), shift(xp, Xm, tm)
            U, Um = shift(up, U, t_nodes), shift(up, Um, tm)
        # the measured state's offset from the guess, fading out over the window (a pushed
        # grasp returns to the reference): one IPOPT iteration from a guess that jumps
        # from the measured state to the reference in the first interval left experiment
        # 2 pushed 3 mm 0.065 infeasible, its window uncertified
        fade = lambda ts: (1.0 - ts / t_nodes[-1])[:, None] ** 2  # noqa: E731
        dx = s.x0 - X[0]
        X, Xm = X + fade(t_nodes) * dx, Xm + fade(tm) * dx
        X[0] = s.x0
        Ucols = np.zeros((hs.n_input_cols, U.shape[1]))
        Ucols[hs.left_cols] = U[:-1]
        Ucols[hs.right_cols] = U[1:]
        return X, Xm, Ucols, Um

    # -- what a tick made -----------------------------------------------------------------
    def plan(self, tick: Tick, certify: bool = False) -> ManipulationSolution:
        """The tick's window as a plan (its trajectory, contacts, fingers: on the window's
        clock, 0 at the tick), certified when asked (seconds for a hand: outside the
        tick's budget)."""
        if tick._setup is None or tick._raw is None or tick._w is None:
            raise ValueError(f"the tick at t = {tick.t:g} s solved no window ({tick.status})")
        from ocp.solve.attempt import IpoptRun

        status, raw, objective, solver = tick._raw
        r = IpoptRun(status, raw, tick.iterations, objective, 0.0, tick._w, tick.solve_time,
                     tick._point, solver)
        sol = finish(tick._setup, [r], tick.solve_time, math.inf, certify)
        if certify:
            tick.certificate = sol.certificate
        return sol

    def certify(self, tick: Tick) -> Certificate:
        """The tick's window checked by the plan's certificate (every dense check of
        :func:`~ocp.solve.certify.certify_grasp`); also stored in ``tick.certificate``."""
        if tick.collocation is None:
            tick.certificate = Certificate.failed(f"no window at t = {tick.t:g} s "
                                                  f"({tick.status})")
            return tick.certificate
        return self.plan(tick, certify=True).certificate
