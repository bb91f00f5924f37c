"""Closed-loop execution of a request's plan: ``ocp``'s re-planner
(:class:`ocp.solve.replan.Replanner`) as the controller of ``sim``'s closed loop
(:func:`sim.closed_loop.simulate_closed_loop`), and the open-loop run on the same
disturbances beside it (docs/simulation.md, "Closed loop").

:func:`first_plan` plans a request in this process and keeps what the loop needs: the
wire result (for the simulator's models), the core's problem as one
:class:`~ocp.spec.grasp.ManipulationProblem` and its plan. :class:`ReplanController` turns
each measurement into the core's, re-plans, and hands the simulator the rest of the
motion. :func:`compare` runs both loops and reports them side by side.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ocp import (
    ManipulationProblem,
    ManipulationSolution,
    Measurement,
    OneFingerPlanner,
    OneFingerProblem,
    Replanner,
    ReplanOptions,
    quaternion_wxyz,
)

__all__ = ["FirstPlan", "ReplanController", "compare", "first_plan", "goal_of",
           "replannable", "stored_first_plan", "summary"]


@dataclass(frozen=True)
class FirstPlan:
    """A request planned in this process: the wire ``result``, the core's ``problem``
    (one-finger requests as the general problem) and its ``plan``."""

    result: Any
    problem: ManipulationProblem
    plan: ManipulationSolution


def first_plan(request: Any) -> FirstPlan:
    """Plan ``request`` here (the service's own adapters and fingers). ValueError when it
    is not a plan with fingers of the direct-collocation planner."""
    from ..planners import solve, to_problem

    result, solution = solve(request)
    problem = to_problem(request)
    if isinstance(problem, OneFingerProblem):
        problem = OneFingerPlanner.manipulation_problem(problem)
    plan = getattr(solution, "plan", solution)
    if not isinstance(problem, ManipulationProblem) or not isinstance(
            plan, ManipulationSolution) or not problem.fingers:
        raise ValueError("closed loop: only plans with fingers made by direct collocation "
                         "(planner one_finger with method collocation, or manipulation) "
                         "are re-planned")
    return FirstPlan(result, problem, plan)


def replannable(request: Any, result: Any) -> str | None:
    """Why a stored plan cannot be re-planned (None: it can): only a plan with fingers made
    by direct collocation (planner ``one_finger`` with method ``collocation``, or
    ``manipulation`` without a ``gait``) whose result holds its ``collocation`` block has
    the one NLP a re-plan re-solves."""
    planner = getattr(request, "planner", None)
    if planner == "ball_on_palm":
        return "a ball-on-palm plan has no fingers: nothing to re-plan from joint angles"
    if planner == "one_finger" and getattr(request, "method", "collocation") != "collocation":
        return ("a plan of the greedy method is its steps, not one NLP: re-plan a plan of "
                "method 'collocation'")
    if planner == "manipulation" and getattr(request, "gait", None) is not None:
        return ("a gait's plan is a sequence of NLPs (rolls, holds, re-placements), not one: "
                "re-plan a rolling plan (no `gait`)")
    if planner not in ("one_finger", "manipulation"):
        return f"planner {planner!r} has no re-plannable structure"
    if getattr(result, "collocation", None) is None:
        return "its result has no `collocation` block (no plan, or not one NLP's)"
    return None


def stored_first_plan(request: Any, result: Any) -> FirstPlan:
    """The :class:`FirstPlan` of a stored job: its ``request`` planned again here, warm from
    the stored ``result``'s ``collocation`` block (its primal-dual point: IPOPT starts at
    the stored plan's optimum, a few iterations), and the stored ``result`` itself as the
    executed plan's. ValueError when it is not re-plannable (:func:`replannable`)."""
    from dexroll_client.models import WarmStartModel

    why = replannable(request, result)
    if why is not None:
        raise ValueError(why)
    block = result.collocation.model_dump()
    warm = request.model_copy(update={"warm_start": WarmStartModel.model_validate(block)})
    again = first_plan(warm)
    return FirstPlan(result, again.problem, again.plan)


class ReplanController:
    """The controller of sim's closed loop: each measurement estimated into the grasp's
    state and the rest of the motion re-planned (:class:`Replanner`); the new plan as the
    simulator's reference (joints, rates and contact points at 4 samples per interval)."""

    def __init__(self, first: FirstPlan, base: Any, options: ReplanOptions | None = None
                 ) -> None:
        self.replanner = Replanner(first.problem, first.plan, options=options)
        self.base = base
        m = self.replanner.model
        self.prm = self.replanner.params
        self.columns = {id(c): j for j, c in enumerate(m.point_contacts)}

    def fragment(self, sol: ManipulationSolution, t0: float) -> Any:
        """The simulator's plan of ``sol`` (the rest of the motion from ``t0``)."""
        from dataclasses import replace

        from sim import ContactSpec, FingerReference

        m = self.replanner.model
        n = sol.stats.n_intervals if sol.stats is not None else 16
        ts = np.linspace(0.0, sol.duration, 4 * n + 1)
        s = sol.sample(ts)
        refs, points = [], {}
        for spec, tip in zip(self.base.fingers, m.fingertips, strict=True):
            refs.append(FingerReference(s.x[:, tip.q_cols], s.x_dot[:, tip.q_cols]))
            j = self.columns[id(tip)]
            points[spec.name] = np.array([
                np.asarray(m.cartesian(x, self.prm)[4])[:, j] for x in s.x])
        contacts = tuple(
            ContactSpec(c.name, c.body, c.finger, points[c.finger], None)
            if c.finger in points else
            ContactSpec(c.name, c.body, c.finger, np.repeat(c.point[:1], ts.size, axis=0))
            for c in self.base.contacts)
        return replace(self.base, t=ts + t0, object_position=s.object_position,
                       object_wxyz=quaternion_wxyz(s.object_rotation),
                       references=tuple(refs), contacts=contacts)

    def __call__(self, meas: Any) -> tuple[Any, Any]:
        from sim.closed_loop import ControlEvent

        r = self.replanner.replan(meas.t, Measurement(
            meas.q, meas.object_position, meas.object_wxyz, meas.q_dot,
            meas.object_velocity, meas.object_omega))
        est = r.estimate
        details: dict[str, Any] = {
            "iterations": r.iterations, "solve_time": r.solve_time,
            "estimate_time": r.estimate_time}
        if est is not None:
            details.update(fingertip_shift=list(est.fingertip_shift),
                           object_shift=est.object_shift, object_turn=est.object_turn)
        frag = self.fragment(r.plan, r.t) if r.status == "replanned" and r.plan else None
        return frag, ControlEvent(r.t, r.status, r.wall_time, r.message, details)


#: After a push or impulse, contact losses within this time [s] are the push's own
#: transient (the object jumps; a fingertip re-touches within a few steps): a run that
#: loses no contact after it "recovers".
SETTLE_AFTER_KICK = 0.1


def goal_of(first: FirstPlan) -> tuple[np.ndarray, np.ndarray | None]:
    """The task's goal pose: a desired motion's end (position, rotation); otherwise the
    first plan's final position (at the goal the problem states: a palm's (x, y)) and its
    final orientation only for a grasp without a palm (a palm's goal leaves the ball's
    orientation free: rolling to the same point by another path turns it otherwise)."""
    problem, plan = first.problem, first.plan
    if problem.motion is not None:
        R, p = problem.motion.at([problem.duration])
        return np.asarray(p[0]), np.asarray(R[0])
    return np.asarray(plan.object_position[-1]), \
        None if problem.palm is not None else np.asarray(plan.object_rotation[-1])


def _matrix(wxyz: Any) -> np.ndarray:
    """The rotation matrix of a quaternion (w, x, y, z)."""
    w, x, y, z = np.asarray(wxyz, dtype=float) / np.linalg.norm(wxyz)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def summary(report: Any, disturbances: Any = None, final_pose: Any = None,
            goal: tuple[np.ndarray, np.ndarray | None] | None = None) -> dict[str, Any]:
    """A run's figures side by side: passed, final and worst errors against the first
    plan [mm, deg], each contact's lost time [s]; with the final pose and the task's
    ``goal``, the final errors against the goal (``goal_angle_deg`` None when the task
    leaves the orientation free); ``recovered``: the final errors (against the goal when
    given) within the report's tolerances and no contact lost (none touching at a
    recorded time) from :data:`SETTLE_AFTER_KICK` after the last push or impulse on."""
    d = report.to_dict()
    lost = {c["name"]: c["lost_time"] for c in d["contacts"]}
    kicks = [] if disturbances is None else \
        [k.time for k in (*disturbances.pushes, *disturbances.impulses)]
    after = max(kicks, default=-math.inf) + SETTLE_AFTER_KICK
    t = np.asarray(d["series"]["t"], dtype=float)
    late = (t >= 0) & (t > after)
    lost_late = {name: bool(np.any(np.asarray(f, dtype=float)[late] <= 1e-6))
                 for name, f in d["series"]["normal_force"].items()}
    tol = d["tolerances"]
    pos, ang = d["position_error"]["final"], d["angle_error"]["final"]
    out: dict[str, Any] = {
        "passed": d["passed"],
        "position_final_mm": 1e3 * pos,
        "position_worst_mm": 1e3 * d["position_error"]["max"],
        "angle_final_deg": math.degrees(ang),
        "angle_worst_deg": math.degrees(d["angle_error"]["max"]),
        "contacts_lost_s": lost,
        "contact_lost_after_kicks": any(lost_late.values())}
    if final_pose is not None and goal is not None:
        fp = np.asarray(final_pose, dtype=float)
        pos = float(np.linalg.norm(fp[:3] - goal[0]))
        R = _matrix(fp[3:])
        ang = 0.0 if goal[1] is None else float(np.arccos(np.clip(
            (np.trace(goal[1].T @ R) - 1.0) / 2.0, -1.0, 1.0)))
        out["goal_position_mm"] = 1e3 * pos
        out["goal_angle_deg"] = None if goal[1] is None else math.degrees(ang)
    out["recovered"] = bool(pos <= tol["position"] and ang <= tol["angle"]
                            and not any(lost_late.values()))
    return out


def compare(first: FirstPlan, base: Any, rate: float, options: Any = None,
            disturbances: Any = None, replan: ReplanOptions | None = None
            ) -> dict[str, Any]:
    """``base`` (the simulator's plan of ``first``) executed open loop and closed loop
    (re-planning at ``rate`` [Hz]) in the same disturbed world: both reports, each one's
    summary (``recovered``: final error within 1 mm and 2 deg, no contact lost) and the
    controller's timing."""
    from sim.closed_loop import run_disturbed, simulate_closed_loop

    open_report, open_final = run_disturbed(base, options, disturbances)
    goal = goal_of(first)
    controller = ReplanController(first, base, replan)
    period = 1.0 / rate
    setup = controller.replanner.prepare(
        [k * period for k in range(1, int(first.plan.duration / period) + 1)])
    closed = simulate_closed_loop(base, controller, rate, options, disturbances)
    return {"disturbances": None if disturbances is None else disturbances.to_dict(),
            "open_loop": {"summary": summary(open_report, disturbances, open_final, goal),
                          "report": open_report.to_dict()},
            "closed_loop": {"summary": summary(closed.report, disturbances,
                                               closed.final_pose, goal),
                            "setup_time": setup, **closed.to_dict()}}
