"""The closed loop in real time (``sim.closed_loop.simulate_closed_loop(latency=True)``):
the controller's latency charged in simulated time. No plan is solved here: a ball at
rest on the palm and one finger swinging through the air beside it, run in MuJoCo. The
controller answers with the rest of the same plan, its joint angles shifted by a marker
of 0.1 mrad per call (the physics practically unchanged), so that the servos' rows in
force at every step say which answer was in force there. Laws: an answer takes over at
the first step at or after its measurement's time plus the charged latency (max(wall,
min_latency)), never earlier; the control instants that fall while a call is in flight
are skipped and counted as overruns; an answer due after the plan's end is dropped;
without latency an answer takes over at its own tick's step. Nothing depends on how
fast the machine is: ``min_latency`` floors the charged latency, and the laws are
checked against the latencies the report says it charged."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import pytest

pytest.importorskip("mujoco")

from sim import (
    ContactSpec,
    ExecutionPlan,
    FingerReference,
    FingerSpec,
    JointSpec,
    ObjectSpec,
    SimOptions,
    TipShape,
)
from sim.closed_loop import (
    ClosedLoopReport,
    ControlEvent,
    SimMeasurement,
    simulate_closed_loop,
)
from sim.disturbances import Disturbances
from sim.run import StepRows

RADIUS = 0.025
DURATION = 1.0
RATE = 10.0
#: The joint offset [rad] of call n's answer: (n + 1) * MARK.
MARK = 1e-4
DT = SimOptions().timestep


def swing_plan() -> ExecutionPlan:
    """A ball at rest on the palm; one finger of one hinge, 10 cm away, swinging 0.5 rad
    (a cubic) and back over :data:`DURATION` without touching it."""
    t = np.linspace(0.0, DURATION, 11)
    s = t / DURATION
    q = (0.5 * (3 * s**2 - 2 * s**3) * (1 - s) * 4)[:, None]
    q_dot = np.gradient(q[:, 0], t)[:, None]
    joint = JointSpec("hinge", "revolute", (0.0, 1.0, 0.0), np.eye(3), np.zeros(3))
    finger = FingerSpec("f", (joint,), np.eye(3), np.array([0.1, 0.0, 0.1]), np.eye(3),
                        np.array([0.0, 0.0, 0.05]), TipShape("sphere", (0.01,)), "f")
    n = t.size
    palm = ContactSpec("palm", "palm", None, np.zeros((n, 3)), np.tile([0.0, 0, -1], (n, 1)))
    return ExecutionPlan(t, ObjectSpec("sphere", (RADIUS,), 0.05, "sphere", (RADIUS,)),
                         np.tile([0.0, 0.0, RADIUS], (n, 1)), np.tile([1.0, 0, 0, 0], (n, 1)),
                         (finger,), (FingerReference(q, q_dot),), (palm,), 0.1, 0.5)


@pytest.fixture(scope="module")
def plan() -> ExecutionPlan:
    return swing_plan()


def tail(plan: ExecutionPlan, t: float, shift: float) -> ExecutionPlan:
    """The plan from its last sample at or before ``t`` on, the joints shifted by
    ``shift`` [rad]."""
    i = int(np.searchsorted(plan.t, t, side="right")) - 1
    return replace(plan, t=plan.t[i:], object_position=plan.object_position[i:],
                   object_wxyz=plan.object_wxyz[i:],
                   references=tuple(FingerReference(r.q[i:] + shift, r.q_dot[i:])
                                    for r in plan.references),
                   contacts=tuple(replace(c, point=c.point[i:],
                                          normal=None if c.normal is None else c.normal[i:])
                                  for c in plan.contacts))


@dataclass
class Marking:
    """The controller: call n answers with the rest of the plan marked (n + 1) *
    :data:`MARK`; ``None`` for the calls in ``silent`` (the reference goes on). The
    fragments are made before the run, so that a call costs next to nothing."""

    plan: ExecutionPlan
    silent: frozenset[int] = frozenset()
    calls: list[float] = field(default_factory=list)

    def __post_init__(self) -> None:
        ticks = [j / RATE for j in range(1, int(DURATION * RATE) + 1)]
        self.fragments = [tail(self.plan, t, (n + 1) * MARK) for n, t in enumerate(ticks)]

    def __call__(self, m: SimMeasurement) -> tuple[ExecutionPlan | None, ControlEvent]:
        n = len(self.calls)
        self.calls.append(m.t)
        frag = None if n in self.silent else self.fragments[n]
        return frag, ControlEvent(m.t, "kept" if frag is None else "replanned", 0.0,
                                  details={"call": n})


@dataclass(frozen=True)
class Watched(Disturbances):
    """No disturbance; its step hook keeps the controller's rows and their first version
    (at step 0, before any call): after the run, ``rows.q_ref`` holds what each step
    used."""

    seen: list[Any] = field(default_factory=list)

    def hook(self, sim: Any) -> Any:
        inner = super().hook(sim)

        def hook(k: int, t: float, rows: StepRows) -> None:
            if not self.seen:
                self.seen.extend([rows, [q.copy() for q in rows.q_ref]])
            inner(k, t, rows)

        return hook


def run(plan: ExecutionPlan, **kw: Any) -> tuple[ClosedLoopReport, np.ndarray, np.ndarray,
                                                 Marking]:
    """The closed loop at :data:`RATE`; per step its time on the plan's clock and which
    call's answer was in force there (-1: the first plan's)."""
    w = Watched()
    ctl = Marking(plan, kw.pop("silent", frozenset()))
    report = simulate_closed_loop(plan, ctl, RATE, disturbances=w, **kw)
    rows, first = w.seen
    n_steps = rows.ts.size - 1  # the last row is no step's
    diff = (rows.q_ref[0] - first[0])[:n_steps, 0]
    which = np.rint(diff / MARK).astype(int) - 1
    assert np.allclose(diff, (which + 1) * MARK, atol=MARK / 100), "a marker is off"
    t = rows.ts[:n_steps] - plan.t[0]
    assert np.isclose(t[1] - t[0], DT)
    return report, t, which, ctl


def instants() -> list[float]:
    """The control instants: every period from one period on, before the plan's end."""
    return [j / RATE for j in range(1, int(DURATION * RATE) + 1)
            if j / RATE < DURATION - DT / 2]


def first_step_at(t: np.ndarray, time: float) -> int | None:
    """The first step starting at or after ``time`` (None: none)."""
    after = np.flatnonzero(t >= time - 1e-9 * DT)
    return int(after[0]) if after.size else None


def check_law(report: ClosedLoopReport, t: np.ndarray, which: np.ndarray,
              min_latency: float) -> list[float]:
    """The real-time law, from the latencies the report charged; the overruns' times."""
    events = report.events
    assert report.latency and report.timing()["latency_charged"] is True
    calls = [e.t for e in events]
    # every charged latency is the wall time, at least the floor
    for e in events:
        assert e.details["latency_charged"] == max(e.wall_time, min_latency)
    # the schedule: an instant is called unless a call is in flight over it
    due, expected_calls, skipped = -math.inf, [], []
    for ti in instants():
        if ti < due - 1e-9 * DT:
            skipped.append(ti)
            continue
        expected_calls.append(ti)
        due = ti + events[len(expected_calls) - 1].details["latency_charged"] \
            if len(expected_calls) <= len(events) else math.inf
    assert calls == pytest.approx(expected_calls, abs=1e-12)
    assert report.overruns == len(skipped) == report.timing()["overruns"]
    assert report.timing()["ticks"] == len(events) == report.timing()["calls"]
    # each answer takes over at the first step at or after its time plus its latency
    # (never earlier); until then the last one applied goes on; one due after the end
    # is dropped
    expected = np.full(t.size, -1)
    for n, e in enumerate(events):
        k = first_step_at(t, e.t + e.details["latency_charged"])
        assert e.details["applied_at"] == (None if k is None else pytest.approx(t[k]))
        if k is not None:
            expected[k:] = n
            assert t[k] >= e.t + e.details["latency_charged"] - 1e-9 * DT
            assert k == 0 or t[k - 1] < e.t + e.details["latency_charged"]
    assert np.array_equal(which, expected), np.flatnonzero(which != expected)[:5]
    return skipped


def test_an_answer_takes_over_once_its_latency_has_passed(plan: ExecutionPlan) -> None:
    """30 ms charged at 10 Hz: every instant is called (nothing in flight a period on),
    each answer in force from the first step 30 ms after its measurement (60 steps of
    0.5 ms), the old set points until then."""
    report, t, which, ctl = run(plan, latency=True, min_latency=0.03)
    check_law(report, t, which, 0.03)
    assert ctl.calls == pytest.approx([e.t for e in report.events])
    lat = np.array([e.details["latency_charged"] for e in report.events])
    assert np.all(lat >= 0.03)
    if np.all(lat < 0.1):  # the cheap controller's case: nothing skipped
        assert report.overruns == 0 and len(report.events) == 9
    for e in report.events:
        k = first_step_at(t, e.t)
        assert k is not None
        n = e.details["call"]
        assert which[k] == n - 1  # its own tick still runs on the last answer
        if e.details["latency_charged"] == 0.03:
            assert which[k + 59] == n - 1 and which[k + 60] == n
    timing = report.timing()
    assert timing["wall_time_p99"] == pytest.approx(np.percentile(report.wall_times, 99))
    assert timing["wall_time_median"] == pytest.approx(np.median(report.wall_times))
    assert timing["real_time_factor"] == pytest.approx(timing["wall_time_median"] * RATE)
    assert timing["min_latency"] == 0.03
    assert report.to_dict()["control"]["overruns"] == report.overruns


@pytest.mark.parametrize("floor", [0.25, 0.35])
def test_instants_inside_a_call_in_flight_are_overruns(plan: ExecutionPlan,
                                                       floor: float) -> None:
    """250 ms charged at 10 Hz: the two instants after each call fall while it is in
    flight (skipped: overruns; calls at 0.1, 0.4, 0.7 s, six overruns); 350 ms: three
    (calls at 0.1, 0.5, 0.9 s), the last answer due after the plan's end, dropped."""
    report, t, which, _ = run(plan, latency=True, min_latency=floor)
    skipped = check_law(report, t, which, floor)
    calls = [e.t for e in report.events]
    # at least the instants within the floor after each call are skipped, whatever the
    # machine's speed
    per_call = math.floor(floor * RATE + 1e-9)
    for c in calls:
        inside = [c + j / RATE for j in range(1, per_call + 1)
                  if c + j / RATE < DURATION - DT / 2]
        assert all(any(abs(s - x) < 1e-9 for s in skipped) for x in inside)
    lat = [e.details["latency_charged"] for e in report.events]
    if all(x == floor for x in lat):  # the cheap controller's case
        if floor == 0.25:
            assert calls == pytest.approx([0.1, 0.4, 0.7]) and report.overruns == 6
            assert report.events[-1].details["applied_at"] == pytest.approx(0.95)
        else:
            assert calls == pytest.approx([0.1, 0.5, 0.9]) and report.overruns == 6
            assert report.events[-1].details["applied_at"] is None  # due at 1.25 s
            assert which.max() == 1
    assert report.timing()["overruns"] == report.overruns == len(skipped)


def test_a_silent_answer_keeps_the_reference_but_still_takes_its_time(
        plan: ExecutionPlan) -> None:
    """A call answering None (the reference goes on) is in flight as long as any: the
    instants inside it are overruns, nothing is applied when it lands."""
    report, t, which, _ = run(plan, latency=True, min_latency=0.15, silent=frozenset({0}))
    assert report.events[0].t == pytest.approx(0.1)
    assert report.events[0].details["applied_at"] is None
    assert report.events[1].t >= 0.25 - 1e-9  # 0.2 s was in flight
    assert report.overruns >= 1
    k = first_step_at(t, report.events[1].t + report.events[1].details["latency_charged"])
    assert k is not None
    assert np.all(which[:k] == -1) and which[k] == 1


@dataclass
class Preparing(Marking):
    """A controller that says it prepares its next call for ``preparation`` [s] after
    answering (a real-time iteration's linearisation): reported, not spent here."""

    preparation: float = 0.15

    def __call__(self, m: SimMeasurement) -> tuple[ExecutionPlan | None, ControlEvent]:
        frag, event = super().__call__(m)
        return frag, replace(event, details={**event.details,
                                             "preparation_time": self.preparation})


def test_a_preparation_after_the_answer_keeps_the_controller_busy_not_the_answer_late(
        plan: ExecutionPlan) -> None:
    """30 ms charged, 150 ms of preparation reported after each answer, at 10 Hz: each
    answer takes over 30 ms after its measurement (the preparation is not its latency),
    and the instant 100 ms on falls within the preparation (an overrun): calls at 0.1,
    0.3, 0.5, 0.7 and 0.9 s, four overruns."""
    w = Watched()
    ctl = Preparing(plan)
    report = simulate_closed_loop(plan, ctl, RATE, disturbances=w, latency=True,
                                  min_latency=0.03)
    calls = [e.t for e in report.events]
    assert calls == pytest.approx([0.1, 0.3, 0.5, 0.7, 0.9])
    assert report.overruns == 4
    for e in report.events:
        assert e.details["latency_charged"] == pytest.approx(0.03)  # wall - preparation
        assert e.details["applied_at"] == pytest.approx(e.t + 0.03, abs=DT)


def test_without_latency_an_answer_takes_over_at_its_own_tick(plan: ExecutionPlan) -> None:
    """The default: every instant called, each answer in force from its tick's own step,
    no overruns, nothing charged."""
    report, t, which, _ = run(plan)
    calls = [e.t for e in report.events]
    assert calls == pytest.approx(instants())
    expected = np.full(t.size, -1)
    for n, c in enumerate(calls):
        k = first_step_at(t, c)
        assert k is not None and abs(t[k] - c) < 1e-9
        expected[k:] = n
    assert np.array_equal(which, expected)
    assert not report.latency and report.overruns == 0
    timing = report.timing()
    assert timing["latency_charged"] is False and timing["overruns"] == 0
    assert timing["ticks"] == timing["calls"] == 9
    assert all("latency_charged" not in e.details for e in report.events)


def test_the_latency_options_are_checked(plan: ExecutionPlan) -> None:
    ctl = Marking(plan)
    for bad in (-0.01, math.nan, math.inf):
        with pytest.raises(ValueError, match="min_latency"):
            simulate_closed_loop(plan, ctl, RATE, latency=True, min_latency=bad)
    with pytest.raises(ValueError, match="latency=True"):
        simulate_closed_loop(plan, ctl, RATE, min_latency=0.1)
