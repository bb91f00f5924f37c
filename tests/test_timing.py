"""Laws of the smooth timing (docs/timing.md) on real plans: at rest at both ends, no
velocity jump anywhere (via-points included) while the via-points are still met at their
times, every joint's acceleration within the request's bound (and the bound active when it
is tight), the paper's piecewise timing still there on request (and rejected by the timing
checks, which therefore can fail); bad timing fields named."""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from ocp.ball_on_palm import grasp_problem
from ocp.one_finger import FingerContact, OneFingerPlanner, OneFingerProblem
from ocp.robots.finger import load_finger
from ocp.solution import ManipulationSolution, Status
from ocp.solve.certify import timing_checks
from ocp.solve.planner import ManipulationPlanner, ManipulationProblem
from ocp.spec.problem import BallOnPalmProblem, ObjectSpec, ProblemError, ViaPoint

ROOT = Path(__file__).resolve().parents[1]
RHO = 0.025
PLANNER = ManipulationPlanner()
VIA_TIMES = (2.0, 4.0)


def triangle(timing: str) -> ManipulationProblem:
    """The ball rolled round the paper's triangle on the palm (via-points at 2 and 4 s)."""
    return grasp_problem(BallOnPalmProblem(
        object=ObjectSpec("sphere", (RHO,)), initial=(0.0, 0.0, 0.0, 0.0, -math.pi / 2),
        goal={"x": 0.0, "y": 0.0}, duration=6.0, n_intervals=60, timing=timing,
        via_points=(ViaPoint(VIA_TIMES[0], {"x": 0.03, "y": 0.0}),
                    ViaPoint(VIA_TIMES[1], {"x": 0.03, "y": 0.03}))))


def roll(**fields: object) -> ManipulationProblem:
    """One flat fingertip on the ball while it rolls 10 mm along the palm in 2 s."""
    base = BallOnPalmProblem(object=ObjectSpec("sphere", (RHO,)),
                             initial=(0.0, 0.0, 0.0, 0.0, -math.pi / 2),
                             goal={"x": 0.01, "y": 0.0}, duration=2.0, n_intervals=40)
    contact = FingerContact(initial=(0.0, 0.0, 0.2, 0.0, 0.0),
                            chart_rotation=(0.0, 0.0, math.pi))
    problem = OneFingerPlanner.manipulation_problem(
        OneFingerProblem(base=base, finger=load_finger(), contact=contact, mu=0.5))
    return replace(problem, **fields)  # type: ignore[arg-type]


@pytest.fixture(scope="module")
def triangles() -> dict[str, ManipulationSolution]:
    plans = {t: PLANNER.solve(triangle(t)) for t in ("smooth", "paper")}
    for t, plan in plans.items():
        assert plan.status is Status.SOLVED, (t, plan.message)
    return plans


@pytest.fixture(scope="module")
def rolls() -> dict[str, ManipulationSolution]:
    """The roll with the default bound, and with a bound of 60 % of the acceleration its
    default plan reaches."""
    free = PLANNER.solve(roll())
    assert free.status is Status.SOLVED, free.message
    limit = 0.6 * max_joint_acceleration(free, roll())
    tight = PLANNER.solve(roll(max_joint_acceleration=limit))
    assert tight.status is Status.SOLVED, tight.message
    return {"free": free, "tight": tight}


def max_joint_acceleration(plan: ManipulationSolution, problem: ManipulationProblem) -> float:
    """The largest joint acceleration of the returned trajectory, densely sampled (the
    polynomials' second derivative)."""
    cols = PLANNER.model(problem).joint_columns()
    t = np.linspace(0.0, plan.duration, 4001)
    return float(np.abs(plan.sample(t).x_ddot[:, cols]).max())


def test_a_smooth_plan_starts_and_ends_at_rest(triangles: dict[str, ManipulationSolution],
                                               rolls: dict[str, ManipulationSolution]) -> None:
    for plan in (triangles["smooth"], rolls["free"]):
        ends = plan.sample(np.array([0.0, plan.duration]))
        assert np.max(np.abs(ends.x_dot)) < 1e-12
        assert np.max(np.abs(ends.u)) < 1e-12
        assert np.max(np.abs(plan.object_velocity[[0, -1]])) < 1e-12
        assert np.max(np.abs(plan.object_angular_velocity[[0, -1]])) < 1e-12
        # and it moves in between
        assert np.max(np.abs(plan.object_velocity)) > 1e-3


def test_no_velocity_jumps_and_via_points_met_at_their_times(
        triangles: dict[str, ManipulationSolution]) -> None:
    smooth, paper = triangles["smooth"], triangles["paper"]
    assert smooth.break_nodes() == []
    for tv, xy in zip(VIA_TIMES, ([0.03, 0.0], [0.03, 0.03]), strict=True):
        t = np.array([tv])
        left, right = smooth.sample(t, side="left"), smooth.sample(t, side="right")
        assert np.max(np.abs(left.x_dot - right.x_dot)) < 1e-12
        assert np.abs(right.x[0, :2] - xy).max() < 1e-6  # the palm point at its time
        # the paper's timing turns the corner with a jump of the palm contact's velocity
        pl, pr = paper.sample(t, side="left"), paper.sample(t, side="right")
        assert np.max(np.abs(pl.x_dot[:, :2] - pr.x_dot[:, :2])) > 5e-3
    # densely (every ms), the palm contact's velocity changes by less than 1 % of its
    # peak from one sample to the next; the paper's plan by a third of it at via-points
    t = np.linspace(0.0, 6.0, 6001)
    for plan, bound in ((smooth, lambda peak: 0.01 * peak), (paper, None)):
        v = plan.sample(t).x_dot[:, :2]
        peak = np.max(np.linalg.norm(v, axis=1))
        step = np.max(np.linalg.norm(np.diff(v, axis=0), axis=1))
        if bound is not None:
            assert step < bound(peak)
        else:
            assert step > peak / 3


def test_the_certificate_checks_the_timing_and_can_fail(
        triangles: dict[str, ManipulationSolution]) -> None:
    smooth, paper = triangles["smooth"], triangles["paper"]
    names = {c.name for c in smooth.certificate.checks}
    assert {"max_rest_rate", "max_velocity_jump"} <= names
    assert smooth.certificate.passed
    assert "max_rest_rate" not in {c.name for c in paper.certificate.checks}
    m = PLANNER.model(triangle("paper"))
    failed = {c.name for c in timing_checks(triangle("smooth"), m, paper.trajectory)
              if not c.passed}
    assert failed == {"max_rest_rate", "max_velocity_jump"}


def test_joint_accelerations_stay_within_the_bound(
        rolls: dict[str, ManipulationSolution]) -> None:
    free, tight = rolls["free"], rolls["tight"]
    default = roll().max_joint_acceleration
    assert max_joint_acceleration(free, roll()) <= default * (1 + 1e-6)
    limit = 0.6 * max_joint_acceleration(free, roll())
    reached = max_joint_acceleration(tight, roll())
    assert reached <= limit * (1 + 1e-6)
    assert reached >= 0.95 * limit  # the bound is what shapes the plan
    check = {c.name: c for c in tight.certificate.checks}["max_joint_acceleration"]
    assert check.passed and check.tolerance == pytest.approx(limit, rel=1e-5)
    assert tight.certificate.passed
    # and the same goal is reached
    assert max(tight.goal_error.values()) < 1e-6


def test_the_wire_carries_the_timing() -> None:
    """A one-finger request planned through the wire: its joint trajectory at rest at both
    ends, no rate breaks; with "paper" timing the start at full speed."""
    from planner_service.cli import plan_request

    raw = json.loads((ROOT / "examples" / "one_finger_roll.json").read_text())
    raw = dict(raw, sample_rate=50.0)
    out = {}
    for timing in ("smooth", "paper"):
        result, _ = plan_request(dict(raw, timing=timing))
        assert result.status == "solved", result.message
        jt = result.joint_trajectory
        assert jt is not None
        out[timing] = (np.array([p.velocities for p in jt.points]), list(jt.rate_breaks))
    v, breaks = out["smooth"]
    assert np.abs(v[[0, -1]]).max() < 1e-9 and breaks == []
    assert np.abs(out["paper"][0][0]).max() > 1e-3


@pytest.mark.parametrize(("fields", "name"), [
    ({"timing": "fast"}, "timing"),
    ({"ramp_time": 0.0}, "ramp_time"),
    ({"ramp_time": 9.0}, "ramp_time"),
    ({"max_joint_acceleration": 0.0}, "max_joint_acceleration"),
    ({"max_joint_acceleration": math.inf}, "max_joint_acceleration"),
])
def test_bad_timing_fields_are_named(fields: dict[str, object], name: str) -> None:
    with pytest.raises(ProblemError) as info:
        roll(**fields).validate()
    assert name in {f for f, _ in info.value.errors}, info.value.errors
    from planner_service.cli import plan_request

    raw = json.loads((ROOT / "examples" / "one_finger_roll.json").read_text())
    result, _ = plan_request(dict(raw, **{k: (None if v == math.inf else v)
                                          for k, v in fields.items()}))
    if fields.get("max_joint_acceleration") != math.inf:
        assert result.status == "invalid_input"
        assert any(e.field == name for e in result.errors), result.errors
