"""Closed-loop execution: a controller re-plans from the measured state while MuJoCo runs
(docs/simulation.md, "Closed loop").

:func:`simulate_disturbed` runs a plan open loop under :class:`~.disturbances.Disturbances`;
:func:`simulate_closed_loop` runs it with a controller called at ``rate`` [Hz] of
simulated time: at each control instant the simulation is paused, the controller gets the
measurement (:class:`SimMeasurement`: the joints' angles and rates, the object's pose with
the disturbances' noise, its twist) and answers with the rest of the motion (an
:class:`~.spec.ExecutionPlan` whose times are on the first plan's clock) or None (the
current reference goes on). By default the new reference replaces the servos' set points
from that step on: zero latency in simulated time; the controller's own wall time is
measured and reported beside (how far from real time it is on this machine). Errors are
measured against the first plan, as in an open-loop run: the goal does not move.

With ``latency=True`` the controller runs in real time: its wall time (at least
``min_latency``) is charged in simulated time, the servos keep the old set points
meanwhile and its answer takes over at the first step at or after the measurement's time
plus that latency. Control instants that fall while a call is still in flight are skipped
(each one an *overrun*; the last answer stays in force), and an answer still pending at
the plan's end is dropped. Work a controller reports as preparing its next call after
answering (``details["preparation_time"]``: a real-time iteration's linearisation) is not
charged as the answer's latency but keeps the controller busy: an instant that falls
within it is an overrun too. The report then gives each call's charged latency and where its
answer was applied, the overruns and the wall times' 99th percentile.

Like the rest of ``sim``, nothing here knows the planner: the service's adapter
(``planner_service.execution.closed_loop``) makes the controller from ``ocp``'s
re-planner.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import mujoco
import numpy as np

from .disturbances import Disturbances
from .options import SimOptions
from .report import SimReport
from .run import Simulation, StepRows, _linear, hermite
from .spec import ExecutionPlan, FloatArray

__all__ = ["ClosedLoopReport", "ControlEvent", "SimMeasurement", "run_disturbed",
           "simulate_closed_loop", "simulate_disturbed"]


@dataclass(frozen=True)
class SimMeasurement:
    """What the controller measures at time ``t`` (the plan's clock): per finger the
    joint angles ``q`` and rates ``q_dot``; the object's position [m] and orientation
    (w, x, y, z) with the disturbances' noise, its linear and angular velocity (palm
    frame; not noisy); per finger the grip's joint offset ``q_offset`` the executor
    commands on top of the plan's angles at that time (the squeeze into the object: a
    controller takes it off the measured joints before it estimates the grasp, else
    every call presses the fingertips in once more: experiment 2 at 20 Hz drifted
    1.4 mm before any disturbance)."""

    t: float
    q: list[FloatArray]
    q_dot: list[FloatArray]
    object_position: FloatArray
    object_wxyz: FloatArray
    object_velocity: FloatArray
    object_omega: FloatArray
    q_offset: list[FloatArray] | None = None


@dataclass(frozen=True)
class ControlEvent:
    """One call of the controller: its time, what it answered (``status``, the
    controller's word: "replanned", "unexplained", ...), its wall time [s] and a
    ``message``; ``details``: the controller's own numbers (with latency charged,
    :func:`simulate_closed_loop` adds "latency_charged" [s] and "applied_at": the time
    of the step its answer took over from, None when nothing was applied)."""

    t: float
    status: str
    wall_time: float
    message: str = ""
    details: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {"t": self.t, "status": self.status, "wall_time": self.wall_time,
                "message": self.message, **self.details}


#: A controller: (measurement) -> (the rest of the motion or None, its event).
Controller = Callable[[SimMeasurement], tuple[ExecutionPlan | None, ControlEvent]]


@dataclass(frozen=True)
class ClosedLoopReport:
    """A closed-loop run: the simulation's ``report`` (errors against the first plan),
    the control ``rate`` [Hz], every controller call (``events``), the object's final
    pose (position, wxyz); whether the controller's ``latency`` was charged in simulated
    time (its floor ``min_latency`` [s]) and how many control instants were skipped
    while a call was in flight (``overruns``)."""

    report: SimReport
    rate: float
    events: tuple[ControlEvent, ...]
    final_pose: FloatArray
    latency: bool = False
    min_latency: float = 0.0
    overruns: int = 0

    @property
    def wall_times(self) -> FloatArray:
        return np.array([e.wall_time for e in self.events if e.status != "kept"])

    def timing(self) -> dict[str, Any]:
        w = self.wall_times
        period = 1.0 / self.rate
        counts: dict[str, int] = {}
        for e in self.events:
            counts[e.status] = counts.get(e.status, 0) + 1
        med = float(np.median(w)) if w.size else None
        return {"rate": self.rate, "period": period, "calls": len(self.events),
                "statuses": counts,
                "wall_time_median": med,
                "wall_time_max": float(np.max(w)) if w.size else None,
                "wall_time_p99": float(np.percentile(w, 99)) if w.size else None,
                "real_time_factor": None if med is None else med / period,
                "latency_charged": self.latency, "min_latency": self.min_latency,
                "ticks": len(self.events), "overruns": self.overruns}

    def to_dict(self) -> dict[str, Any]:
        return {"report": self.report.to_dict(), "control": self.timing(),
                "final_pose": self.final_pose.tolist(),
                "events": [e.to_dict() for e in self.events]}


def _world(plan: ExecutionPlan, options: SimOptions | None, dist: Disturbances
           ) -> tuple[ExecutionPlan, SimOptions]:
    o = options or SimOptions()
    if o.object_mass is not None and dist.mass_scale != 1.0:
        o = replace(o, object_mass=o.object_mass * dist.mass_scale)
    return dist.scene_plan(plan), o


def simulate_disturbed(plan: ExecutionPlan, options: SimOptions | None = None,
                       disturbances: Disturbances | None = None) -> SimReport:
    """``plan`` executed open loop in the disturbed world (errors against ``plan``)."""
    return run_disturbed(plan, options, disturbances)[0]


def run_disturbed(plan: ExecutionPlan, options: SimOptions | None = None,
                  disturbances: Disturbances | None = None) -> tuple[SimReport, FloatArray]:
    """:func:`simulate_disturbed`'s report and the object's final pose (position, wxyz)."""
    dist = disturbances or Disturbances()
    world, o = _world(plan, options, dist)
    sim = Simulation(world, o)
    report = sim.run(dist.hook(sim))
    return report, sim.data.qpos[sim.object_qpos:sim.object_qpos + 7].copy()


def _set_reference(sim: Simulation, rows: StepRows, k: int, frag: ExecutionPlan) -> None:
    """The servos' rows from step ``k`` on from the re-plan ``frag`` (its times on the
    plan's clock; held at its end)."""
    o = sim.options
    offsets, torques, _ = sim._feedforward(frag)
    ts = rows.ts[k:]
    t = frag.t + float(sim.plan.t[0])
    for i, ref in enumerate(frag.references):
        q, qd = hermite(t, ref.q, ref.q_dot, ts)
        grip = _linear(t, offsets[i], ts)
        target = q + grip
        if rows.offset:
            rows.offset[i][k:] = grip
        rows.q_ref[i][k:] = target
        rows.qd_ref[i][k:] = qd
        rows.ctrl[i][k:] = target + (o.kv / o.kp) * qd
        rows.tau[i][k:] = _linear(t, torques[i], ts)


def simulate_closed_loop(plan: ExecutionPlan, controller: Controller, rate: float,
                         options: SimOptions | None = None,
                         disturbances: Disturbances | None = None, *,
                         latency: bool = False,
                         min_latency: float = 0.0) -> ClosedLoopReport:
    """``plan`` executed with ``controller`` called every 1 / ``rate`` s of simulated time
    (from one period after t = 0 to the end) in the disturbed world; errors against
    ``plan``.

    ``latency``: charge the controller's wall time, at least ``min_latency`` [s], in
    simulated time (see the module): a call measured at t answers from the first step
    starting at or after t + max(wall, ``min_latency``) (to within 1e-9 of a step), the
    control instants before that step are skipped (overruns) and an answer due after the
    last step is dropped. Without it (the default) an answer takes over at once and
    ``min_latency`` must be 0."""
    if not (math.isfinite(rate) and rate > 0):
        raise ValueError("rate must be positive")
    if not (math.isfinite(min_latency) and min_latency >= 0):
        raise ValueError("min_latency must be finite and >= 0")
    if min_latency and not latency:
        raise ValueError("min_latency needs latency=True (without it nothing is charged)")
    dist = disturbances or Disturbances()
    world, o = _world(plan, options, dist)
    sim = Simulation(world, o)
    kick = dist.hook(sim)
    measure = dist.noise()
    d = sim.data
    oq, od = sim.object_qpos, sim.object_dof
    period = 1.0 / rate
    every = max(1, round(period / o.timestep))
    events: list[ControlEvent] = []
    T = plan.duration
    # the call in flight (latency charged): its answer's first step, its event's index
    # and the answer
    pending: list[tuple[int, int, ExecutionPlan | None]] = []
    overruns = 0
    # the first step the controller is free again: after its answer, the work it reports
    # as preparing the next call (``preparation_time``) keeps it busy, not its answer late
    free_at = 0

    def land(k: int, t: float, rows: StepRows) -> None:
        """The answer in flight, applied from step ``k`` when it is due by then."""
        if not pending or k < pending[0][0]:
            return
        _, i, frag = pending.pop(0)
        if frag is not None:
            _set_reference(sim, rows, k, frag)
            e = events[i]
            events[i] = replace(e, details={**e.details, "applied_at": t})

    def hook(k: int, t: float, rows: StepRows) -> None:
        nonlocal overruns, free_at
        kick(k, t, rows)
        land(k, t, rows)
        if t <= 0.5 * o.timestep or t >= T - 0.5 * o.timestep:
            return
        if round(t / o.timestep) % every:
            return
        if pending or k < free_at:  # the last call (or its preparation) is still in
            overruns += 1          # flight: this instant is skipped
            return
        quat = d.qpos[oq + 3:oq + 7].copy()
        R = np.zeros(9)
        mujoco.mju_quat2Mat(R, quat)
        p, q = measure(d.qpos[oq:oq + 3].copy(), quat)
        meas = SimMeasurement(
            t, [d.qpos[f.qpos].copy() for f in sim.fingers],
            [d.qvel[f.dofs].copy() for f in sim.fingers], p, q,
            d.qvel[od:od + 3].copy(), R.reshape(3, 3) @ d.qvel[od + 3:od + 6],
            [g[k].copy() for g in rows.offset] if rows.offset else None)
        start = time.perf_counter()
        frag, event = controller(meas)
        wall = time.perf_counter() - start
        if not latency:
            events.append(replace(event, wall_time=wall))
            if frag is not None:
                _set_reference(sim, rows, k, frag)
            return
        # work the controller reports as its background's (a reference re-planned in a
        # process of its own, in parallel with the ticks) is not the tick's latency
        background = float(event.details.get("background_time", 0.0))
        preparation = float(event.details.get("preparation_time", 0.0))
        wall -= min(background + preparation, wall)
        charged = max(wall, min_latency)
        events.append(replace(event, wall_time=wall, details={
            **event.details, "latency_charged": charged, "applied_at": None}))
        # the first step starting at or after t + charged (steps are timestep apart)
        ahead = max(0, math.ceil(charged / o.timestep - 1e-9))
        pending.append((k + ahead, len(events) - 1, frag))
        free_at = k + max(0, math.ceil((charged + preparation) / o.timestep - 1e-9))
        land(k, t, rows)  # no time charged at all (a clock too coarse to see the call)

    report = sim.run(hook)
    return ClosedLoopReport(report, rate, tuple(events), d.qpos[oq:oq + 7].copy(),
                            latency, min_latency, overruns)
