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

__all__ = ["FirstPlan", "ReplanController", "ReplanSession", "TrackingController",
           "closed_loop_report", "compare", "first_plan", "goal_of", "replannable",
           "stored_first_plan", "summary"]


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


def measured_joints(meas: Any) -> list[Any]:
    """The measured joint angles less the grip's offset the executor commands on top of the
    plan (``SimMeasurement.q_offset``): the grasp the plan knows, without the squeeze."""
    if getattr(meas, "q_offset", None) is None:
        return list(meas.q)
    return [q - off for q, off in zip(meas.q, meas.q_offset, strict=True)]


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
            measured_joints(meas), meas.object_position, meas.object_wxyz, meas.q_dot,
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


class TrackingController:
    """The controller of sim's real-time closed loop: each measurement estimated into the
    grasp's state (from the reference's state at that time) and a window of the plan
    re-solved from it (:class:`ocp.control.WindowController`, its real-time iteration
    budget); the window's collocation points as the simulator's reference from the tick
    on. Every window is kept (``ticks``) and certified after the run
    (:meth:`certify_all`: outside the ticks' budget)."""

    def __init__(self, first: FirstPlan, base: Any, options: Any = None,
                 planner: Any = None, reference_rate: float | None = 4.0,
                 retarget_distance: float = 1e-3, period: float | None = None) -> None:
        from ocp import WindowController

        self.control = WindowController(first.problem, first.plan, options, planner)
        #: the control period [s]: after each answer the next tick is prepared
        #: (:meth:`~ocp.control.window.WindowController.prepare_next`, the RTI backend's
        #: linearisation) for the time one period on; its time is reported as
        #: ``preparation_time``, the controller busy but the answer already sent
        self.period = period
        self._preparation = 0.0
        #: the reference re-planned from the measured state every 1 / ``reference_rate``
        #: s of simulated time when the object is off it, as a background process would
        #: (its time is not charged to the ticks: ``background_time``), the window
        #: tracking the new plan from then on. None: the first plan tracked throughout
        self.replanner = None if reference_rate is None else \
            Replanner(first.problem, first.plan, options=ReplanOptions(time_limit=60.0))
        self.reference_period = math.inf if reference_rate is None else 1.0 / reference_rate
        self._next_replan = self.reference_period
        #: re-planned only when the object is farther than this from the reference [m] (the
        #: task's tolerance; 0.5 mm re-planned experiment 1 on its own tracking error)
        #: (undisturbed, the reference is the plan: re-planning it anyway changed it near
        #: the end, and two of experiment 2's 199 windows failed the certificate)
        self.retarget_distance = retarget_distance
        self.base = base
        m = self.control.model
        self.columns = [j for tip in m.fingertips for j, c in enumerate(m.point_contacts)
                        if c is tip]
        #: (tick time, certificate failures) of the windows certified
        self.failures: list[tuple[float, list[str]]] = []

    def prepare(self) -> float:
        return self.control.prepare()

    def fragment(self, tick: Any) -> Any:
        """The simulator's plan of a tick's window (its collocation points, on the first
        plan's clock)."""
        from dataclasses import replace

        from sim import ContactSpec, FingerReference

        m, col = self.control.model, tick.collocation
        ts = np.linspace(0.0, float(col.t_nodes[-1]), 2 * (len(col.t_nodes) - 1) + 1)
        x, xd, R, p, pts = window_at(self.control, tick, ts)
        refs, points = [], {}
        for spec, tip, j in zip(self.base.fingers, m.fingertips, self.columns, strict=True):
            refs.append(FingerReference(x[:, tip.q_cols], xd[:, tip.q_cols]))
            points[spec.name] = pts[:, j]
        contacts = tuple(
            ContactSpec(c.name, c.body, c.finger, points[c.finger], None)
            if c.finger in points else
            ContactSpec(c.name, c.body, c.finger, np.repeat(c.point[:1], ts.size, axis=0))
            for c in self.base.contacts)
        return replace(self.base, t=ts + tick.t, object_position=p,
                       object_wxyz=quaternion_wxyz(R), references=tuple(refs),
                       contacts=contacts)

    def __call__(self, meas: Any) -> tuple[Any, Any]:
        import time

        from ocp import estimate_state
        from sim.closed_loop import ControlEvent

        background = 0.0
        details0: dict[str, Any] = {}
        if self.replanner is not None and meas.t >= self._next_replan - 1e-9:
            self._next_replan = meas.t + self.reference_period
            t_bg = time.perf_counter()
            c = self.control
            ref = c.reference.sample([min(max(meas.t - c.start, 0.0),
                                          c.reference.duration)])
            off = float(np.linalg.norm(np.asarray(meas.object_position)
                                       - ref.object_position[0]))
            if off > self.retarget_distance:
                r = self.replanner.replan(meas.t, Measurement(
                    measured_joints(meas), meas.object_position, meas.object_wxyz))
                if r.status == "replanned" and r.plan is not None:
                    c.retarget(r.plan, r.t)
                details0 = {"reference": r.status}
            background = time.perf_counter() - t_bg
            details0 = {**details0, "background_time": background,
                        "reference_offset": off}
        t0 = time.perf_counter()
        c = self.control
        est = estimate_state(c.problem, c.model, Measurement(
            measured_joints(meas), meas.object_position, meas.object_wxyz, meas.q_dot,
            meas.object_velocity, meas.object_omega), *c.state_at(meas.t))
        t_est = time.perf_counter() - t0
        if not est.explained:
            return None, ControlEvent(meas.t, "unexplained", 0.0, "; ".join(est.problems),
                                      {"estimate_time": t_est, **details0})
        # the measured rates (MuJoCo's servos make them ring) enter only a window whose
        # first input is fixed to them (``fix_start``); else it starts at the reference's
        u = est.u if c.options.fix_start and est.u is not None else None
        tick = c.tick(meas.t, est.x, u)
        details: dict[str, Any] = {
            "iterations": tick.iterations, "solve_time": tick.solve_time,
            "estimate_time": t_est, "primal_infeasibility": tick.primal_infeasibility,
            "dual_infeasibility": tick.dual_infeasibility, **details0}
        frag = self.fragment(tick) if tick.collocation is not None else None
        if self.period is not None:
            # prepared for the first instant the controller will be free at: the call so
            # far and the last preparation may span more than a period (a tick prepared
            # for an instant it then skips is solved unprepared)
            busy = time.perf_counter() - t0 + self._preparation
            ahead = max(1, math.ceil(busy / self.period - 1e-9))
            self._preparation = c.prepare_next(meas.t + ahead * self.period)
            details["preparation_time"] = self._preparation
        return frag, ControlEvent(meas.t, tick.status, 0.0, tick.raw_status, details)

    def certify_all(self, every: int = 1) -> dict[str, Any]:
        """Every ``every``-th window certified: how many, how many passed, and the ticks
        that failed with their failed checks."""
        checked = passed = 0
        for k, tick in enumerate(self.control.ticks):
            if k % every:
                continue
            cert = self.control.certify(tick)
            checked += 1
            if cert.passed:
                passed += 1
            else:
                self.failures.append((tick.t, [ch.name for ch in cert.checks
                                               if not ch.passed]))
        return {"windows": len(self.control.ticks), "checked": checked, "certified": passed,
                "failed": [{"t": t, "checks": names} for t, names in self.failures]}


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
            disturbances: Any = None, replan: ReplanOptions | None = None,
            control: Any = None, planner: Any = None) -> dict[str, Any]:
    """``base`` (the simulator's plan of ``first``) executed open loop and closed loop
    in the same disturbed world: both reports, each one's summary (``recovered``: final
    error within 1 mm and 2 deg, no contact lost) and the controller's timing. The closed
    loop: with ``control`` (:class:`ocp.ControllerOptions`) the window controller at
    ``rate`` [Hz] in real time (its latency charged in simulated time, every window
    certified after the run: ``certificates``); else the whole-remainder re-planner with
    MuJoCo paused at each call (``replan``). ``planner``: the window's NLP cache (e.g.
    compiled; default the process-wide planner's)."""
    from sim.closed_loop import run_disturbed, simulate_closed_loop

    open_report, open_final = run_disturbed(base, options, disturbances)
    goal = goal_of(first)
    extra: dict[str, Any] = {}
    if control is not None:
        tracker = TrackingController(first, base, control, planner, period=1.0 / rate)
        setup = tracker.prepare()
        closed = simulate_closed_loop(base, tracker, rate, options, disturbances,
                                      latency=True)
        extra["certificates"] = tracker.certify_all()
    else:
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
                            "setup_time": setup, **closed.to_dict(), **extra}}


def closed_loop_report(request: Any, result: Any, plan: Any, options: dict[str, Any],
                       disturbed: dict[str, Any] | None, loop: dict[str, Any]
                       ) -> tuple[str, Any]:
    """The simulation door's closed loop (``planner_service.jobs.simulations``): a stored
    job's ``plan`` (the simulator's, of ``result``) executed closed loop and open loop in
    the same disturbed world, as ``dexroll simulate --closed-loop``: ("ok", the closed
    loop's report with ``disturbances``, ``open_loop`` and ``closed_loop`` beside it), or
    ("not_replannable", why)."""
    from sim import SimOptions
    from sim.disturbances import Disturbances

    why = replannable(request, result)
    if why is not None:
        return ("not_replannable", f"closed_loop: {why}")
    options = {k: v for k, v in options.items() if k != "model"}
    dist = Disturbances.from_dict(disturbed)
    first = stored_first_plan(request, result)
    if loop.get("controller", "replan") == "window":
        from ocp import ControllerOptions

        data = compare(first, plan, float(loop["rate"]), SimOptions.from_dict(options), dist,
                       control=ControllerOptions(max_iter=int(loop["max_iter"]),
                                                 backend=str(loop.get("backend", "ipopt"))))
    else:
        data = compare(first, plan, float(loop["rate"]), SimOptions.from_dict(options),
                       dist, ReplanOptions(max_iter=int(loop["max_iter"]), time_limit=60.0))
    closed = dict(data["closed_loop"])
    report = closed.pop("report")
    return ("ok", {**report, "disturbances": data["disturbances"],
                   "open_loop": data["open_loop"], "closed_loop": closed})


def measurement_errors(m: Any, duration: float, t: float, object_wxyz: Any,
                       **joint_rows: Any) -> list[tuple[str, str]]:
    """What does not fit the plan in a (schema-valid) measurement, fields named: each
    given per-finger joint field (``q``, ``q_dot``; None: not measured) of the plan's
    fingers and joints (``m``: its grasp model), a rotation for ``object_wxyz``, a time
    ``t`` within the plan's ``duration``. The re-plan route's and the controller
    session's checks."""
    n = len(m.fingertips)
    joints = [int(np.arange(m.nx)[tip.q_cols].size) for tip in m.fingertips]
    errors: list[tuple[str, str]] = []
    for name, value in joint_rows.items():
        if value is None:
            continue
        if len(value) != n:
            errors.append((name, f"{len(value)} fingers measured, the plan has {n}"))
            continue
        errors += [(f"{name}[{i}]", f"{len(row)} joints, finger {i} of the plan has {k}")
                   for i, (row, k) in enumerate(zip(value, joints, strict=True))
                   if len(row) != k]
    if float(np.linalg.norm(object_wxyz)) < 1e-6:
        errors.append(("object_wxyz", "not a rotation: a zero quaternion"))
    if t > duration + 1e-9:
        errors.append(("t", f"{t:g} s is after the plan's end ({duration:g} s)"))
    return errors


def window_at(control: Any, tick: Any, ts: Any) -> tuple[np.ndarray, ...]:
    """A tick's window (``control``: its :class:`ocp.WindowController`) at times ``ts``
    from the tick: the states and their rates (the collocation polynomials), the object's
    rotation matrices and position, each point contact's point (palm frame)."""
    m, col, prm = control.model, tick.collocation, control.params
    traj = m.interpolant(col.t_nodes, col.X, col.U0, col.Um, col.U1, prm)
    x, xd = traj(ts), traj(ts, order=1)
    cart = m.mapped("cartesian", len(ts))(x.T, prm)
    R = np.asarray(cart[0]).T.reshape(len(ts), 3, 3).transpose(0, 2, 1)
    return x, xd, R, np.asarray(cart[1]).T, np.asarray(cart[4]).T.reshape(len(ts), -1, 3)


class ReplanSession:
    """A stored plan's re-planner in the service's re-plan process
    (``planner_service.jobs.replans``; docs/replanning.md "Through the service"): the plan
    planned again warm from its stored result (:func:`stored_first_plan`) and its
    :class:`Replanner`, which keeps the plan being executed (the last re-plan) from call to
    call. ValueError when the request cannot be planned again here."""

    def __init__(self, request: Any, result: Any) -> None:
        from ocp import ProblemError

        try:
            self.first = stored_first_plan(request, result)
        except ProblemError as exc:
            raise ValueError(str(exc.errors)) from exc
        self.replanner = Replanner(self.first.problem, self.first.plan,
                                   options=ReplanOptions())

    def shape_errors(self, body: Any) -> list[tuple[str, str]]:
        """What does not fit the plan in a (schema-valid) re-plan request
        (``dexroll_client.replan.ReplanRequest``), fields named."""
        rp = self.replanner
        m = rp.model
        n = len(m.fingertips)
        errors = measurement_errors(m, float(rp.problem.duration), body.t, body.object_wxyz,
                                    q=body.q, q_dot=body.q_dot)
        if body.contact_points is not None and len(body.contact_points) != n:
            errors.append(("contact_points", f"{len(body.contact_points)} given, the plan "
                                             f"has {n} fingers"))
        if (body.object_velocity is None) != (body.object_omega is None):
            name = "object_omega" if body.object_omega is None else "object_velocity"
            errors.append((name, "give object_velocity and object_omega together (or "
                                 "neither)"))
        return errors

    def replan(self, job_id: str, body: Any, setup: float, time_cap: float
               ) -> tuple[str, Any]:
        """One re-plan from ``body`` (a ``ReplanRequest``): ("ok", the wire
        ``ReplanResult`` as a dict), ("invalid", [(field, reason)]) for a measurement that
        does not fit the plan, ("unexplained", [(field, reason)]) for a state the grasp
        cannot explain. ``setup``: the seconds this call spent building the session;
        ``time_cap``: the service's cap on the IPOPT call's time limit."""
        from dataclasses import replace

        errors = self.shape_errors(body)
        if errors:
            return ("invalid", errors)
        rp = self.replanner
        if body.restart or body.t < rp.start - 1e-9:
            rp.reset()
        rp.options = replace(rp.options, max_iter=body.max_iter,
                             time_limit=min(body.time_limit, time_cap),
                             certify=body.certify)
        r = rp.replan(body.t, Measurement(
            body.q, body.object_position, body.object_wxyz, body.q_dot,
            body.object_velocity, body.object_omega, body.contact_points))
        if r.status == "unexplained" and r.estimate is not None:
            return ("unexplained", list(zip(r.estimate.fields, r.estimate.problems,
                                            strict=True)))
        if r.status == "refused":
            return ("unexplained", [("q", r.message)])
        return ("ok", self._answer(job_id, body, r, setup))

    def _answer(self, job_id: str, body: Any, r: Any, setup: float) -> dict[str, Any]:
        """The wire ReplanResult (as a dict) of one :class:`~ocp.solve.replan.Replan`."""
        from ..planners.samples import joint_trajectory_block, samples_block

        rp = self.replanner
        m = rp.model
        plan = r.plan if r.status == "replanned" else None
        out: dict[str, Any] = {"job_id": job_id, "status": r.status, "message": r.message,
                               "t": r.t}
        if plan is not None:
            times = plan.t if body.sample_rate is None else _rate_times(
                float(plan.duration), float(body.sample_rate))
            jt = joint_trajectory_block(plan, None if body.sample_rate is None else times)
            smp = samples_block(plan, np.asarray(times, dtype=float))
            out.update(duration=float(plan.duration),
                       joint_trajectory=None if jt is None else jt.model_dump(mode="json"),
                       samples=None if smp is None else smp.model_dump(mode="json"))
        est = r.estimate
        if est is not None:
            _, _, _, R, p = m.path(est.x, rp.params)
            wxyz = quaternion_wxyz(np.asarray(R, dtype=float)).reshape(-1, 4)[0]
            out["estimate"] = {
                "q": [np.asarray(est.x)[tip.q_cols].tolist() for tip in m.fingertips],
                "object_position": np.asarray(p, dtype=float).ravel().tolist(),
                "object_wxyz": wxyz.tolist(),
                "fingertip_shift": list(est.fingertip_shift),
                "object_shift": est.object_shift, "object_turn": est.object_turn,
                "contact_shift": list(est.contact_shift) if body.contact_points is not None
                else None}
        solved = r.plan
        stats = solved.stats if solved is not None else None
        out["stats"] = {
            "iterations": r.iterations, "wall_time": r.wall_time,
            "solve_time": r.solve_time, "estimate_time": r.estimate_time,
            "setup_time": setup,
            "converged": None if solved is None else bool(solved.converged),
            "certified": None if solved is None or not body.certify
            else bool(solved.certificate.passed),
            "raw_status": None if stats is None else stats.raw_status}
        return out


def _rate_times(duration: float, rate: float) -> np.ndarray:
    """k / rate for every k with k / rate < duration, then the duration itself (as a
    request's ``sample_rate`` samples a plan)."""
    t = np.arange(math.ceil(duration * rate) + 1) / rate
    return np.append(t[t < duration - 1e-12], duration)


class TrackingSession:
    """A stored plan's window controller in the service's re-plan process (``WebSocket
    /v1/plans/{id}/control``; docs/control.md "Through the service"): the plan planned
    again warm from its stored result and its :class:`ocp.WindowController` (its
    ``backend``: :class:`ocp.ControllerOptions`'), prepared, kept from tick to tick.
    ValueError when the request cannot be planned again here, or the backend cannot solve
    its window."""

    def __init__(self, request: Any, result: Any, backend: str = "ipopt") -> None:
        from ocp import ControllerOptions, ProblemError, WindowController

        try:
            self.first = stored_first_plan(request, result)
            self.control = WindowController(self.first.problem, self.first.plan,
                                            ControllerOptions(backend=backend))
            self.control.prepare()  # (a backend that cannot solve the window says so)
        except ProblemError as exc:
            raise ValueError("; ".join(f"{f}: {r}" for f, r in exc.errors)) from exc
        self.control.ticks.clear()  # the session keeps no history: a robot ticks for hours

    def tick(self, body: Any, setup: float) -> tuple[str, Any]:
        """One tick from ``body`` (a ``ControlMeasurement``): ("ok", the answer as a
        dict), ("invalid" | "unexplained", [(field, reason)])."""
        import time

        from ocp import estimate_state

        t0 = time.perf_counter()
        c = self.control
        m = c.model
        errors = measurement_errors(m, c.duration, body.t, body.object_wxyz, q=body.q)
        if errors:
            return "invalid", errors
        est = estimate_state(c.problem, m, Measurement(
            [np.asarray(q, dtype=float) for q in body.q],
            np.asarray(body.object_position, dtype=float),
            np.asarray(body.object_wxyz, dtype=float)), *c.state_at(body.t))
        t_est = time.perf_counter() - t0
        if not est.explained:
            return "unexplained", list(zip(est.fields, est.problems, strict=True))
        tick = c.tick(float(body.t), est.x)
        c.ticks.clear()
        window = None
        if tick.collocation is not None:
            ts = tick.collocation.t_nodes
            x, xd, _, p, _ = window_at(c, tick, ts)
            window = {"t": ts.tolist(),
                      "q": [x[:, tip.q_cols].tolist() for tip in m.fingertips],
                      "q_dot": [xd[:, tip.q_cols].tolist() for tip in m.fingertips],
                      "object_position": p.tolist()}
        return "ok", {"t": tick.t, "status": tick.status, "iterations": tick.iterations,
                      "primal_infeasibility": tick.primal_infeasibility,
                      "dual_infeasibility": tick.dual_infeasibility,
                      "solve_time": tick.solve_time, "estimate_time": t_est,
                      "wall_time": time.perf_counter() - t0, "setup_time": setup,
                      "window": window}
