"""A re-planning controller: the rest of a motion re-planned from the measured state
(docs/replanning.md, "From a measured state").

:class:`Replanner` holds a problem and its current plan. Every control period the
controller calls :meth:`Replanner.replan` with the time (on the first plan's clock) and a
:class:`~ocp.solve.estimate.Measurement`; it

1. estimates the grasp's state from the measurement (:func:`~ocp.solve.estimate.
   estimate_state`, from the current plan's state at that time): a state the grasp cannot
   explain (a contact lost, the object dropped) is reported (``status`` "unexplained")
   and not planned through;
2. re-solves the cached NLP of the rest of the problem (:meth:`ManipulationProblem.
   remaining`: a **shrinking horizon**, the goal, the via-points and the desired motion
   kept at their times) from that state and its rates (a moving start), warm-started at
   the current plan shifted in time, within an iteration and time budget
   (:func:`~ocp.solve.attempt.attempt`);
3. keeps the new plan when IPOPT converged (else the current one goes on).

Why shrinking, not receding: the tasks dexroll plans have a fixed end (a goal at the
duration, via-points at given times, a desired motion on a clock); a receding horizon of
constant length would need a terminal cost or a goal past the task's end. The grid size is
kept, so the NLP is the cached one (its intervals shorten with the horizon), and near the
end (less than ``min_horizon`` left) the last plan is executed to its end.

A desired motion's hard tracking tolerances are kept in a re-plan from an object within
half of each of them from the desired pose, and dropped otherwise (the weighted tracking
terms stay): a pushed object starts outside them, and a plan that must be within 1 mm of
the desired path from its first instant does not exist. Same NLP either way (the bounds
are values), same cache.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np

from ocp.solution import ManipulationSolution
from ocp.solve.attempt import AttemptOptions, attempt, shifted
from ocp.solve.estimate import (
    EstimateOptions,
    Measurement,
    StateEstimate,
    _rotation,
    estimate_state,
)
from ocp.spec.grasp import ManipulationProblem, contact_charts
from ocp.spec.problem import ProblemError

if TYPE_CHECKING:
    from ocp.solve.planner import ManipulationPlanner

__all__ = ["STRICT_FRACTION", "Replan", "ReplanOptions", "Replanner"]

#: A re-plan keeps the desired motion's hard tracking tolerances when the measured object
#: is within this fraction of each of them from the desired pose (else they are dropped).
STRICT_FRACTION = 0.5


@dataclass(frozen=True)
class ReplanOptions:
    """A re-plan's budget (IPOPT iterations ``max_iter``, wall time ``time_limit`` [s]),
    ``min_horizon`` [s] (less left: no re-plan, the plan goes on), whether the hard
    tracking tolerances are dropped (``relax_tracking``), whether the object on a palm is
    to end in the first plan's final orientation too (``hold_final_pose``: its chart
    point and contact angle added to the goal, where the problem's goal leaves them
    free), whether IPOPT starts from the shifted plan's multipliers too (``warm_duals``;
    else from its primal point alone, with IPOPT's own initial barrier), whether each
    re-plan is certified (``certify``: a converged re-plan is then ``solved`` only with a
    passed certificate), and the estimate's options."""

    max_iter: int = 30
    time_limit: float = 10.0
    min_horizon: float = 0.3
    relax_tracking: bool = True
    hold_final_pose: bool = False
    warm_duals: bool = True
    certify: bool = False
    estimate: EstimateOptions = field(default_factory=EstimateOptions)


@dataclass(frozen=True)
class Replan:
    """One call of :meth:`Replanner.replan`: ``status`` "replanned" (``plan`` is the new
    one, starting at ``t``), "unexplained" (the measurement is not a state of the grasp:
    ``message`` says why; nothing planned), "not_converged" (IPOPT did not converge within
    the budget: the current plan goes on), "kept" (too near the end to re-plan) or
    "refused" (the estimated state refused by the NLP's checks); ``wall_time`` [s] the
    estimate and the solve, ``solve_time`` the IPOPT call alone, ``iterations``."""

    t: float
    status: str
    plan: ManipulationSolution | None
    estimate: StateEstimate | None
    wall_time: float
    solve_time: float = 0.0
    estimate_time: float = 0.0
    iterations: int = 0
    message: str = ""


class Replanner:
    """The re-planning controller of ``problem`` from its ``first`` plan (see the module):
    ``plan`` is the plan being executed, ``start`` the time it starts at (the first plan's
    clock), ``history`` every :class:`Replan`."""

    def __init__(self, problem: ManipulationProblem, first: ManipulationSolution,
                 planner: ManipulationPlanner | None = None,
                 options: ReplanOptions | None = None) -> None:
        if planner is None:
            from ocp.solve.planner import default_planner

            planner = default_planner()
        self.options = options or ReplanOptions()
        if first.chart_switch is not None:
            raise ProblemError([("first", "the plan's contacts change chart at t = "
                                          f"{first.chart_switch.time:g} s; re-planning a "
                                          "plan across a chart switch is not built")])
        n = first.stats.n_intervals if first.stats is not None else problem.n_intervals
        problem = problem.with_intervals(n)
        #: the problem with its hard tracking tolerances (re-plans from within them)
        self.strict: ManipulationProblem | None = None
        tr = problem.tracking
        if self.options.relax_tracking and problem.motion is not None and (
                tr.position_tolerance is not None or tr.orientation_tolerance is not None):
            self.strict = problem
            problem = replace(problem, tracking=replace(
                problem.tracking, position_tolerance=None, orientation_tolerance=None))
        if self.options.hold_final_pose and problem.palm is not None and first.contacts:
            end = np.asarray(first.contacts[0].eta)[-1]
            goal = dict(problem.palm.goal)
            for k, name in enumerate(("x", "y", "u", "v", "psi")):
                goal.setdefault(name, float(end[k]))
            problem = replace(problem, palm=replace(problem.palm, goal=goal))
        if self.strict is not None:
            self.strict = replace(self.strict, palm=problem.palm)
        self.problem, self.planner = problem, planner
        self.model = planner.model(problem)
        #: the grasp model's parameters (the object's shape, the contacts' charts)
        self.params = self.model.params(np.asarray(problem.object.params, dtype=float),
                                        contact_charts(problem))
        self.plan, self.start = first, 0.0
        #: the first plan (:meth:`reset` goes back to it)
        self.first = first
        self.history: list[Replan] = []

    def reset(self) -> None:
        """Back to the first plan (a controller that starts the motion again)."""
        self.plan, self.start = self.first, 0.0

    def prepare(self, times: Sequence[float]) -> float:
        """Build, before the loop, every NLP the re-plans at ``times`` will use (one per
        structure: the via-points still ahead change it) and its warm-start solver, by a
        one-iteration attempt from the first plan; the wall time [s] it took."""
        from ocp.solve.nlp_cache import GraspStructure

        t0 = time.perf_counter()
        seen: set[GraspStructure] = set()
        for t in times:
            if self.problem.duration - t < self.options.min_horizon or t <= 0:
                continue
            rest = self.problem.remaining(t)
            key = GraspStructure.of(rest)
            if key in seen:
                continue
            seen.add(key)
            x, u = self.state_at(t)
            attempt(rest, x0=x, u0=u, warm=shifted(self.plan, t),
                    options=AttemptOptions(max_iter=1), planner=self.planner)
        return time.perf_counter() - t0

    def state_at(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """The current plan's state and input at time ``t`` (the first plan's clock)."""
        s = min(max(t - self.start, 0.0), self.plan.duration)
        x, u = self.plan.interpolate([s])
        return x[0], u[0]

    def _rest(self, t: float, measured: Measurement) -> ManipulationProblem:
        """The rest of the problem at ``t``: with the hard tracking tolerances when the
        measured object is well within them of the desired pose at ``t`` (within
        :data:`STRICT_FRACTION` of each), without them otherwise (a pushed object)."""
        strict = self.strict
        if strict is None or strict.motion is None:
            return self.problem.remaining(t)
        R_d, p_d = strict.motion.at([t])
        R_m = _rotation(measured.object_wxyz)
        dp = float(np.linalg.norm(np.asarray(measured.object_position, dtype=float) - p_d[0]))
        c = (np.trace(R_d[0].T @ R_m) - 1.0) / 2.0
        da = float(np.arccos(np.clip(c, -1.0, 1.0)))
        tr = strict.tracking
        inside = (tr.position_tolerance is None
                  or dp <= STRICT_FRACTION * tr.position_tolerance) and \
            (tr.orientation_tolerance is None or da <= STRICT_FRACTION * tr.orientation_tolerance)
        return (strict if inside else self.problem).remaining(t)

    def replan(self, t: float, measured: Measurement) -> Replan:
        """Re-plan the rest of the motion from ``measured`` at time ``t``."""
        o = self.options
        t0 = time.perf_counter()
        if self.problem.duration - t < o.min_horizon:
            out = Replan(t, "kept", None, None, time.perf_counter() - t0,
                         message=f"{self.problem.duration - t:.3g} s left: the plan goes on")
            self.history.append(out)
            return out
        x_plan, u_plan = self.state_at(t)
        est = estimate_state(self.problem, self.model, measured, x_plan, u_plan, o.estimate)
        t_est = time.perf_counter() - t0
        if not est.explained:
            out = Replan(t, "unexplained", None, est, time.perf_counter() - t0,
                         estimate_time=t_est, message="; ".join(est.problems))
            self.history.append(out)
            return out
        rest = self._rest(t, measured)
        warm = shifted(self.plan, min(max(t - self.start, 0.0), self.plan.duration * 0.999))
        if not o.warm_duals:
            warm = replace(warm, nlp_point=None)
        try:
            sol = attempt(rest, x0=est.x, u0=est.u, warm=warm,
                          options=AttemptOptions(max_iter=o.max_iter, time_limit=o.time_limit,
                                                 certify=o.certify),
                          planner=self.planner)
        except ProblemError as exc:
            out = Replan(t, "refused", None, est, time.perf_counter() - t0,
                         estimate_time=t_est, message=str(exc.errors))
            self.history.append(out)
            return out
        stats = sol.stats
        wall = time.perf_counter() - t0
        its = stats.iterations if stats is not None else 0
        ipopt = stats.ipopt_time if stats is not None else 0.0
        if not sol.converged:
            out = Replan(t, "not_converged", sol, est, wall, ipopt, t_est, its,
                         f"{sol.status.value} (IPOPT: "
                         f"{stats.raw_status if stats else '-'})")
        else:
            self.plan, self.start = sol, t
            out = Replan(t, "replanned", sol, est, wall, ipopt, t_est, its)
        self.history.append(out)
        return out
