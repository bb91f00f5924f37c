"""The planning pipeline of every grasp: problem -> transcription -> solve -> solution ->
certificate.

A grasp (:class:`~ocp.spec.grasp.ManipulationProblem`) is a list of contacts
(:mod:`ocp.contacts`): an object block (the palm carrying the object, or the object's pose
when fingers alone hold it) and the fingertips. :class:`ManipulationPlanner`

1. builds the grasp's model from its contacts
   (:class:`~ocp.transcription.grasp_model.GraspModel`) and
   the NLP of its structure (:class:`GraspStructure`, cached): direct collocation
   (Hermite-Simpson) from blocks (:func:`~ocp.transcription.nlp_blocks.build_manipulation_nlp`), its
   parameters declared by name (:class:`~ocp.transcription.parameters.Parameters`);
2. solves it with IPOPT from the initial guesses of the grasp's strategy
   (:mod:`ocp.solve.guesses`: the fingers' consistent guess, or the palm's simulated reference
   paths with loops), in turn, within the request's time and iteration limits;
3. assembles the plan (:func:`~ocp.solve.assemble.assemble_solution`);
4. certifies it independently (:func:`~ocp.solve.certify.certify_grasp`), and when only
   discretisation checks fail solves again on a grid twice as fine, warm-started.

The object on the palm alone (the paper's ball on palm, :mod:`ocp.ball_on_palm`), one
finger pressing the ball on the palm (its section 3), two fingers holding it in the air
(its section 4) and three or more fingers are the same pipeline with different data.

States (scaled for IPOPT; docs/conventions.md): each contact's block in turn (see
:mod:`ocp.contacts`). Dynamics: the rolling equations at every contact (eq. 3 via
:class:`~ocp.geometry.contact.ContactPair`). Path constraints at every collocation point: each
finger's closure (eq. 6), force closure with a margin (friction cones;
:mod:`ocp.geometry.force_closure` for 3+ contacts), contacts inside the pads, joint and joint-rate
limits, chart pole margins, and, when the request asks, hard bounds on the tracking error.
Objective (over normalised time): effort of every input, a weight times the grasp-angle
epigraph s >= 1 - cos Phi_i, and a weighted tracking error on SE(3) between the object's
pose and the desired one: |p - p_d|^2 / L^2 + (3 - tr(R_d^T R)) / 2.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ocp.certify.certificate import Certificate
from ocp.robots.turn_reach import problem_shortfall
from ocp.solution import (
    ContactTrajectory,
    FingerTrajectory,
    GraspSample,
    ManipulationSolution,
    SolverStats,
    Status,
)
from ocp.solve.attempt import IpoptRun, Setup, finish, initial_point, run, setup
from ocp.solve.compiled import BackgroundCompiler
from ocp.solve.force_plan import with_earlier, with_forces
from ocp.solve.guesses import (
    Guess,
    Strategy,
    strategy_for,
)
from ocp.solve.initial import initial_state
from ocp.solve.ipopt import NLP as _NLP
from ocp.solve.nlp_cache import MAX_CACHED_NLPS, GraspStructure, NlpCache
from ocp.solve.switched import restated, sampled_guess
from ocp.spec.chart_switch import snapped
from ocp.spec.grasp import (
    Fingertip,
    ManipulationProblem,
    Palm,
    contact_chart_for_pad,
    fingertip_errors,
    hand_fingertips,
)
from ocp.spec.motion import DesiredMotion, MotionStep, ObjectPose, Tracking
from ocp.spec.patches import (
    pole_clear_patch,
    recharted,
    rides_bound,
    rides_pole,
    side_charted,
    switching_chart,
    turns_off_chart,
)
from ocp.spec.problem import MAX_INTERVALS, ProblemError
from ocp.transcription.collocation import NlpPoint, WarmStart, node_times
from ocp.transcription.force_stage import ForceStage
from ocp.transcription.grasp_model import GraspModel
from ocp.transcription.values import parameters as nlp_parameters

__all__ = [
    "ContactTrajectory",
    "DesiredMotion",
    "FingerTrajectory",
    "Fingertip",
    "GraspSample",
    "GraspStructure",
    "ManipulationPlanner",
    "ManipulationProblem",
    "ManipulationSolution",
    "MotionStep",
    "ObjectPose",
    "Palm",
    "Tracking",
    "contact_chart_for_pad",
    "fingertip_errors",
    "hand_fingertips",
]

FloatArray = NDArray[np.float64]

#: How far a guess started with a neighbouring plan's multipliers (the ``multipliers`` of
#: :meth:`ManipulationPlanner.solve`) and its bound multipliers are pushed inside (IPOPT's
#: ``warm_start_*_push`` and ``_frac``; the warm start's barrier, 1e-6). The guess is not
#: that plan's optimum, so not the 1e-9 of a warm start from the same problem's point.
#: Measured on ``examples/egg_gait.json`` (13 rolls of a turned egg, each from the last
#: roll's multipliers): the rolls' kinematic stages took 120 IPOPT iterations in all
#: against 361 cold (24 for the first roll, then 6-10 instead of 23-37); pushes of 1e-3
#: with the barrier at 1e-4, or 1e-2 at 1e-3, took 130-140.
MULTIPLIER_PUSH = 1e-2


def warm_grid_factor(problem: ManipulationProblem,
                     warm_start: WarmStart | ManipulationSolution | None) -> int:
    """How many times finer than the problem's grid a warm start's is, when the warm start
    is a plan on this problem's grid refined (its collocation points are the problem's on
    a grid 2, 4, 8, ... times as fine, the same duration and via-point times); else 1."""
    if warm_start is None:
        return 1
    ws = warm_start.warm_start if isinstance(warm_start, ManipulationSolution) else warm_start
    n, pts = problem.n_intervals, len(ws.t)
    m = (pts - 1) // 2
    k = m // n
    if pts % 2 == 0 or m <= n or m % n or k & (k - 1) or m > MAX_INTERVALS:
        return 1
    segments, tb = problem.with_intervals(m).segments()
    t_nodes = node_times(segments, tb)
    t_all = np.empty(2 * len(t_nodes) - 1)
    t_all[0::2], t_all[1::2] = t_nodes, (t_nodes[:-1] + t_nodes[1:]) / 2
    if len(t_all) != pts or not np.allclose(ws.t, t_all, rtol=0.0,
                                            atol=1e-9 * max(1.0, float(tb[-1]))):
        return 1
    return k


@dataclass
class _Totals:
    """What a plan spent over its guesses and refinements."""

    build: float = 0.0
    solve: float = 0.0  # the attempt loops (guesses and IPOPT)
    ipopt: float = 0.0
    certificate: float = 0.0
    iterations: int = 0
    attempts: int = 0


class ManipulationPlanner:
    """Direct-collocation planner for any grasp (NLPs cached per structure): see the
    module's doc."""

    def __init__(self, compile_dir: Path | None = None, background: bool = False,
                 max_iter_per_guess: int = 300, max_nlps: int = MAX_CACHED_NLPS,
                 solver: str = "ipopt", stage_order: bool | None = None) -> None:
        #: The NLPs built, by structure, and the grasps' models
        #: (:class:`~ocp.solve.nlp_cache.NlpCache`: ``compile_dir``, ``background``,
        #: ``max_nlps``, ``solver``, ``stage_order`` are its).
        self.nlps = NlpCache(compile_dir, background, max_nlps, solver, stage_order)
        #: IPOPT iterations on one initial guess of the palm's strategy before its next.
        self.max_iter_per_guess = max_iter_per_guess
        #: Re-plan in another patch of the object's chart when a plan's palm contact rides
        #: its patch's pole bound (:func:`repatched`; spheres only).
        self.auto_patch = True
        #: Plan a problem's forces in two stages (:mod:`ocp.transcription.force_stage`):
        #: the kinematics, then the forces at its collocation points; the coupled NLP only
        #: when some point admits no forces. False: always the coupled NLP.
        self.two_stage_forces = True
        self._force_stages: dict[GraspModel, ForceStage] = {}

    @property
    def compile_dir(self) -> Path | None:
        return self.nlps.compile_dir

    @property
    def solver(self) -> str:
        return self.nlps.solver

    @property
    def stage_order(self) -> bool:
        return self.nlps.stage_order

    @property
    def compiler(self) -> BackgroundCompiler | None:
        return self.nlps.compiler

    def model(self, problem: ManipulationProblem) -> GraspModel:
        return self.nlps.model(problem)

    def build(self, problem: ManipulationProblem) -> tuple[_NLP, bool]:
        """The NLP of this problem's structure (:class:`GraspStructure`), built or from
        the cache, and whether it was cached."""
        return self.nlps.get(problem)

    def structure_key(self, problem: ManipulationProblem) -> str:
        """The key of the NLP this problem is solved on (:meth:`NlpCache.structure_key`)."""
        return self.nlps.structure_key(problem)

    def adopt_compiled(self, wait: float = 0.0) -> int:
        """Swap in the compiled solvers of the background compiles that are done (waiting
        up to ``wait`` s for the pending ones); how many. Called before every solve."""
        return self.nlps.adopt_compiled(wait)

    def prepare(self, problem: ManipulationProblem) -> float:
        """Build (and cache) the NLP of this problem's structure and its model's
        re-integrator, without solving: a service's warm-up. Returns the build time [s]
        (0 when already cached). A problem with forces planned in two stages builds the
        kinematic NLP its first stage solves (the coupled one only if ever needed)."""
        if problem.forces is not None and self.two_stage_forces:
            problem = replace(problem, forces=None)
        nlp, hit = self.build(problem)
        self.model(problem).reintegrator(2)  # the certificate's: nodes and midpoints
        return 0.0 if hit else nlp.build_time

    def initial_state(self, problem: ManipulationProblem) -> FloatArray:
        """The state at t = 0, the fingers' joints by inverse kinematics; ProblemError
        saying why the initial grasp is impossible (unreachable, outside the joint limits,
        not in force closure): :func:`~ocp.solve.initial.initial_state`."""
        return initial_state(self.model(problem), problem)

    def solve(self, problem: ManipulationProblem,
              warm_start: WarmStart | ManipulationSolution | None = None, *,
              certify: bool = True, reach_checked: bool = False,
              multipliers: NlpPoint | None = None) -> ManipulationSolution:
        """Plan; ProblemError (before any NLP is built) on bad input or an impossible
        initial grasp. When IPOPT converges but the certificate finds the grid too coarse
        (only discretisation checks fail: slip between collocation points, closure,
        re-integration defects, tracking between points), the plan is re-solved on a grid
        2, 4 or 8 times as fine (:meth:`~ocp.certify.certificate.Certificate.refinement_factor`:
        what the worst failed check needs), warm-started, up to ``max_refinements`` times.

        ``warm_start``: a previous plan of a similar problem (a solution, or its
        :attr:`ManipulationSolution.warm_start`), the first initial guess; when IPOPT does
        not converge from it, the strategy's own guesses follow (within the limits).
        A warm start that is a plan of this problem on a refined grid
        (:func:`warm_grid_factor`) starts on that grid, counted as one refinement.
        ``certify=False`` (a plan that only seeds another's initial guess): no certificate
        and so no refinement; the plan is at best ``inaccurate``. ``reach_checked``: the
        caller has cut the turn at the grasp's rolled reach itself (a gait's rolls), so
        :meth:`beyond_reach` is not asked again. ``multipliers``: IPOPT's primal-dual point
        of a neighbouring plan whose states are no start for this one (a gait's last roll
        of an egg, turned since): without a warm start, the first of the strategy's own
        guesses starts from it with those multipliers (and its epigraph and force
        variables) when it is this NLP's (:data:`MULTIPLIER_PUSH`).

        A problem with ``forces`` is planned in two stages (``two_stage_forces``): its
        kinematics as without them, then the forces at the plan's collocation points
        (:mod:`ocp.transcription.force_stage`), certified with them; when some point admits
        no forces, or the certificate fails with them, the coupled NLP, from the kinematic
        plan, within what is left of the time limit.
        """
        problem.validate()
        if certify and not reach_checked:
            refused = self.beyond_reach(problem)
            if refused is not None:
                return refused
        if certify and self.auto_patch and problem.chart_switch is None:
            problem = self._charted(problem)
        problem = snapped(problem)  # (a chart switch at its node, for every stage)
        if problem.forces is None or not self.two_stage_forces or not certify:
            return self._plan(problem, warm_start, certify, multipliers)
        t0 = time.perf_counter()
        kin = self._plan(replace(problem, forces=None), warm_start, certify, multipliers)
        if kin.status is Status.SOLVED:
            out = with_forces(self.model, self._force_stages, problem, kin)
            if out is not None:
                return out
        left = problem.options.time_limit - (time.perf_counter() - t0)
        limited = replace(problem, options=replace(problem.options, time_limit=max(left, 1e-3)))
        if kin.object_side_chart:  # from the kinematic plan on its chart (an egg's side)
            limited = side_charted(limited) or limited
        coupled = self._plan(
            limited, kin if kin.status in (Status.SOLVED, Status.INACCURATE) else warm_start,
            certify)
        return with_earlier(coupled, kin)

    def _charted(self, problem: ManipulationProblem) -> ManipulationProblem:
        """The problem on the charts that carry its contacts' predicted paths (an egg's):
        switching chart inside the plan where neither of the object's carries them
        throughout (:func:`~ocp.spec.patches.switching_chart`), else on the side chart
        where the motion carries a contact over an end
        (:func:`~ocp.spec.patches.turns_off_chart`), else as it is."""
        cached: list[list[FloatArray]] = []

        def joints() -> list[FloatArray]:
            if not cached:
                cached.append(self._initial_joints(problem))
            return cached[0]

        spec = switching_chart(problem, joints)
        if spec is not None:
            return replace(problem, chart_switch=spec)
        if turns_off_chart(problem, joints):
            return side_charted(problem) or problem  # (an egg's contact over its end)
        return problem

    def beyond_reach(self, problem: ManipulationProblem) -> ManipulationSolution | None:
        """A turn the grasp cannot roll through, answered without an NLP
        (:func:`unplanned_turn`); None for any other problem."""
        return unplanned_turn(problem, lambda: self._initial_joints(problem))

    def _initial_joints(self, problem: ManipulationProblem) -> list[FloatArray]:
        """Each finger's joints at t = 0 (its initial state's)."""
        x0 = self.initial_state(problem)
        return [x0[tip.q_cols] for tip in self.model(problem).fingertips]

    def _plan(self, problem: ManipulationProblem,
              warm_start: WarmStart | ManipulationSolution | None, certify: bool,
              multipliers: NlpPoint | None = None) -> ManipulationSolution:
        """:meth:`solve`'s pipeline for one NLP kind (the coupled one when ``forces``)."""
        self.adopt_compiled()
        problem = snapped(problem)  # (a chart switch at its node: refinements keep it)
        if warm_start is not None:
            m = self.model(problem)
            ws = warm_start.warm_start if isinstance(warm_start, ManipulationSolution) \
                else warm_start
            errs = ws.errors("warm_start", m.nx, m.nu)
            if errs:
                raise ProblemError(errs)
        deadline = time.perf_counter() + problem.options.time_limit
        x0 = self.initial_state(problem)
        strategy = strategy_for(problem)
        totals = _Totals()
        budget = problem.options.max_iter
        refinements = 0
        factor = warm_grid_factor(problem, warm_start) if certify else 1
        if factor > 1 and problem.max_refinements > 0:
            # a plan of this problem on a grid its certificate refined: start there (the
            # coarse grid would fail the certificate again; 3 iterations instead of 49 on
            # the four-finger round-tip contract plan)
            problem = problem.with_intervals(factor * problem.n_intervals)
            refinements = 1
        sol = self._solve_once(problem, strategy, x0, warm_start, deadline, budget, totals,
                               certify, multipliers)
        if self.auto_patch and certify and problem.chart_switch is None:
            problem, strategy, x0, sol = repatched(self, problem, strategy, x0, sol, deadline,
                                                   budget, totals)
        # only failures that shrink with the grid (what happens between collocation
        # points), decided by the checks' kind (an inaccurate plan has failed checks)
        while (certify and sol.status is Status.INACCURATE
               and refinements < problem.max_refinements
               and 2 * problem.n_intervals <= MAX_INTERVALS
               and sol.certificate.refinable
               and time.perf_counter() < deadline):
            refinements += 1
            factor = sol.certificate.refinement_factor()
            while factor > 2 and factor * problem.n_intervals > MAX_INTERVALS:
                factor //= 2
            problem = problem.with_intervals(factor * problem.n_intervals)
            left = budget - totals.iterations if strategy.shared_budget else budget
            sol = self._solve_once(problem, strategy, x0, sol, deadline, left, totals, True)
        assert sol.stats is not None
        stats = replace(sol.stats, iterations=totals.iterations, attempts=totals.attempts,
                        build_time=totals.build, solve_time=totals.solve,
                        certificate_time=totals.certificate, ipopt_time=totals.ipopt,
                        refinements=refinements)
        return replace(sol, stats=stats,
                       object_chart_rotation=tuple(problem.object.chart_rotation)
                       if problem.palm is not None else None,
                       object_side_chart=problem.object.side_chart)

    @staticmethod
    def parameters(problem: ManipulationProblem, nlp: _NLP) -> FloatArray:
        """The NLP parameter vector of a problem (:func:`~ocp.transcription.values.parameters`)."""
        return nlp_parameters(problem, nlp)

    def _guesses(self, problem: ManipulationProblem, strategy: Strategy, m: GraspModel,
                 nlp: _NLP, x0: FloatArray, t_nodes: FloatArray,
                 warm: WarmStart | ManipulationSolution | None,
                 multipliers: NlpPoint | None = None, s: Setup | None = None
                 ) -> Iterator[tuple[Guess, NlpPoint | None, float | None]]:
        """The initial guesses in the order they are tried, each with the primal-dual
        point IPOPT starts from and its push (:func:`~ocp.solve.attempt.run`'s
        ``warm_push``): the warm start (with IPOPT's point when it is this very NLP's and
        the strategy takes it), then the strategy's own, the first of them with
        ``multipliers`` (:meth:`solve`'s, pushed :data:`MULTIPLIER_PUSH`) when there is no
        warm start and they are this NLP's. A plan whose contacts change chart (``s``'s
        charts) takes each guess on the chart of each point (:mod:`ocp.solve.switched`)."""
        def charted(g: Guess) -> Guess:
            return g if s is None else restated(s, g)

        sizes = (nlp.fingerprint, nlp.pack.nnz_out(0), len(nlp.lbg))
        if warm is not None:
            ws = warm if isinstance(warm, WarmStart) else warm.warm_start
            mult = ws.nlp_point_for(*sizes) if strategy.use_nlp_point else None
            sampled = sampled_guess(warm, s) if s is not None and \
                isinstance(warm, ManipulationSolution) else None
            yield sampled or charted(strategy.warm_guess(warm, problem, nlp, x0, t_nodes)), \
                mult, None
        first = multipliers if warm is None and multipliers is not None \
            and strategy.use_nlp_point and multipliers.fits(*sizes) else None
        for g in strategy.own_guesses(self, problem, m, nlp, x0, t_nodes):
            yield charted(g), first, None if first is None else MULTIPLIER_PUSH
            first = None

    def _solve_once(self, problem: ManipulationProblem, strategy: Strategy, x0: FloatArray,
                    warm: WarmStart | ManipulationSolution | None, deadline: float,
                    budget: int, totals: _Totals, certify: bool,
                    multipliers: NlpPoint | None = None) -> ManipulationSolution:
        """The initial guesses in turn (:meth:`_guesses`, ``multipliers`` its), each one
        IPOPT call (:func:`~ocp.solve.attempt.run`) within what is left of the budget,
        until one solves: the plan of the best (:func:`~ocp.solve.attempt.finish`)."""
        s = setup(self, problem, x0)
        s.strategy = strategy
        cap = self.max_iter_per_guess if strategy.caps_guesses else None
        runs: list[IpoptRun] = []
        t_loop = time.perf_counter()
        for guess, point, push in self._guesses(problem, strategy, s.model, s.nlp, x0,
                                                s.t_nodes, warm, multipliers, s):
            used = sum(r.iterations for r in runs) if strategy.shared_budget else 0
            remaining = budget - used
            limit = remaining if cap is None else max(1, min(remaining, cap))
            runs.append(run(s, initial_point(s, guess), point, deadline, limit, push))
            if runs[-1].status is Status.SOLVED or s.nlp.stop.reason is Status.TIME_LIMIT \
                    or (cap is not None and remaining <= cap) \
                    or time.perf_counter() >= deadline:
                break
        sol = finish(s, runs, time.perf_counter() - t_loop, deadline, certify)
        assert sol.stats is not None
        totals.build += sol.stats.build_time
        totals.solve += sol.stats.solve_time
        totals.ipopt += sol.stats.ipopt_time
        totals.certificate += sol.stats.certificate_time
        totals.iterations += sol.stats.iterations
        totals.attempts += sol.stats.attempts
        return sol


def repatched(planner: ManipulationPlanner, problem: ManipulationProblem, strategy: Strategy,
              x0: FloatArray, sol: ManipulationSolution, deadline: float, budget: int,
              totals: _Totals
              ) -> tuple[ManipulationProblem, Strategy, FloatArray, ManipulationSolution]:
    """When a contact's path rides a bound of the object's chart (a bound of the chart,
    not of the physics), the plan again on a chart far from it (:mod:`ocp.spec.patches`),
    kept when it is solved and clear of the bound, or when the first plan was not solved:
    the palm contact at its patch's pole bound, in a patch whose poles are far from its
    path (spheres only); a fingertip's contact at its chart's bound (an egg's end), on the
    object's side chart (:func:`~ocp.spec.patches.side_charted`)."""
    alt = _clear_chart(problem, sol)
    if alt is None or time.perf_counter() >= deadline:
        return problem, strategy, x0, sol
    try:
        alt_x0 = planner.initial_state(alt)
    except ProblemError:
        return problem, strategy, x0, sol
    alt_strategy = strategy_for(alt)
    left = budget - totals.iterations if alt_strategy.shared_budget else budget
    alt_sol = planner._solve_once(alt, alt_strategy, alt_x0, None, deadline, left, totals,
                               True)
    clear = alt_sol.status in (Status.SOLVED, Status.INACCURATE) and not _rides(alt, alt_sol)
    if clear or (sol.status is not Status.SOLVED and alt_sol.status is Status.SOLVED):
        return alt, alt_strategy, alt_x0, alt_sol
    return problem, strategy, x0, sol


def _rides(problem: ManipulationProblem, sol: ManipulationSolution) -> bool:
    """Whether the plan ``sol`` rides a bound of its chart: the palm contact its patch's
    pole bound (a plan solved or inaccurate), or a fingertip's contact its chart's."""
    if not sol.contacts or not np.isfinite(sol.contacts[0].eta).all():
        return False
    if problem.palm is not None:
        return sol.status in (Status.SOLVED, Status.INACCURATE) \
            and rides_pole(problem, sol.contacts[0].eta[:, 2])
    return any(rides_bound(problem, c.eta[:, 2]) for c in sol.contacts)


def _clear_chart(problem: ManipulationProblem, sol: ManipulationSolution
                 ) -> ManipulationProblem | None:
    """The problem on a chart clear of the bound its plan ``sol`` rides (above); None
    when it rides none, or there is no other chart."""
    if not _rides(problem, sol):
        return None
    if problem.palm is not None:
        palm = sol.contacts[0]
        path = np.einsum("kji,kj->ki", sol.object_rotation, palm.point - sol.object_position)
        rotvec = pole_clear_patch(problem, path)
        return recharted(problem, rotvec) if rotvec is not None else None
    return side_charted(problem)


def unplanned_turn(problem: ManipulationProblem,
                   joints: Callable[[], list[FloatArray]]) -> ManipulationSolution | None:
    """A turn of a ball in round fingertips that the grasp cannot roll through (a
    finger stops at a joint limit or its cap's seam well short of it:
    :func:`~ocp.robots.turn_reach.problem_shortfall`), answered without an NLP: an
    ``infeasible`` plan without samples whose message names the finger, the limit and
    the angle; None for any other problem (``joints``: the fingers' initial joints, asked
    for only when the check applies). Milliseconds to a few hundred."""
    t0 = time.perf_counter()
    short = problem_shortfall(problem, joints)
    if short is None:
        return None
    reason = ("not planned: the turn is beyond the grasp's rolled reach (finger "
              f"{short.finger!r}, the message says where)")
    e, e3 = np.zeros(0), np.zeros((0, 3))
    return ManipulationSolution(
        status=Status.INFEASIBLE, message=short.message, raw_status="", t=e,
        object_position=e3, object_rotation=np.zeros((0, 3, 3)), object_velocity=e3,
        object_angular_velocity=e3, contacts=(), fingers=(), grasp_angle=e,
        cone_margin=e, desired_position=None, desired_rotation=None,
        tracking_position_error=None, tracking_angle_error=None, goal_error={},
        certificate=Certificate.failed(reason), certificate_failures=(reason,),
        stats=SolverStats(raw_status="", iterations=0, attempts=0, build_time=0.0,
                          solve_time=time.perf_counter() - t0, certificate_time=0.0,
                          objective=math.nan, cache_hit=False))


_DEFAULT: ManipulationPlanner | None = None


def default_planner() -> ManipulationPlanner:
    """The process-wide planner: one NLP cache for every kind of grasp (the front ends'
    default planners share it)."""
    global _DEFAULT
    if _DEFAULT is None:
        _DEFAULT = ManipulationPlanner()
    return _DEFAULT
