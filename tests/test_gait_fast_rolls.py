"""Gaits that move faster (issue 40, items 1 and 3): rolls run as fast as the hand allows
(the request's ``gait.fastest_rolls``; ocp.gait.warp.RollClock's speed,
ocp.gait.planner.roll_speed) and spent fingertips landing where they roll farthest
(``gait.landing`` "farthest"; ocp.gait.planner.farthest_landings).

Laws: the clock at speed k runs the plan's whole path (s from 0 to its duration), at k
times its rate on the plateau, its rate and acceleration continuous (the finite
differences of s and s'), and at speed 1 it is the clock it always was; the speed found
keeps the clock's accelerations within the bound, and is 1 when the bound is already
reached. On examples/allegro_turn_90.json (spent re-placements, fastest swings): the fast
gait is certified, its rolls shorter on the gait's clock than their plans and each at one
of its limits, its torques (damping included) certified on the clock, its robot time
shorter than the same gait with rolls at the motion's rate, and it executes in MuJoCo. A
farthest landing is on the ball and reaches at least as far as home; with them the +y
turn needs fewer re-placements, and executes."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from ocp.gait.warp import MIN_ROLL_TIME, RollClock, fastest_speed

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("speed", [1.0, 1.7, 4.0])
def test_a_fast_clock_runs_the_whole_path_faster_and_smoothly(speed: float) -> None:
    clock = RollClock.of(2.0, speed)
    tau = np.linspace(0.0, clock.length, 40001)
    s, v, a = clock(tau)
    assert s[0] == 0.0 and s[-1] == pytest.approx(2.0, abs=1e-12)
    assert clock.length == pytest.approx(2.0 / speed + clock.ramp)
    assert v.max() == pytest.approx(speed) and v[0] == v[-1] == 0.0
    assert np.all(np.diff(s) >= 0.0)
    h = tau[1] - tau[0]
    assert np.abs(np.gradient(s, h) - v).max() < 1e-4 * speed
    assert np.abs(np.gradient(v, h) - a).max() < 1e-2 * speed


def test_speed_one_is_the_clock_it_was() -> None:
    """The gait's default rolls are the same: at speed 1, the warp of docs/gait.md."""
    clock = RollClock.of(1.5)
    assert clock.ramp == 0.2 and clock.length == pytest.approx(1.7)
    tau = np.array([0.0, 0.1, 0.2, 0.85, 1.5, 1.6, 1.7])
    s, v, _ = clock(tau)
    x = 0.5
    assert s[1] == pytest.approx(0.2 * (x**3 - x**4 / 2.0))
    assert s[3] == pytest.approx(0.85 - 0.1) and v[3] == 1.0
    assert s[-1] == pytest.approx(1.5)


def test_the_speed_found_keeps_the_bound() -> None:
    dur = 2.0
    s = np.linspace(0.0, dur, 401)
    qd = np.stack([0.3 * np.sin(np.pi * s / dur) ** 2, -0.1 * np.sin(np.pi * s / dur) ** 2], 1)
    qdd = np.gradient(qd, s, axis=0)
    vmax = np.array([6.0, 6.0])
    k = fastest_speed(dur, qd, qdd, vmax, 20.0)
    assert 1.0 < k <= dur / MIN_ROLL_TIME + 1e-12
    clock = RollClock.of(dur, k)
    tau = np.linspace(0.0, clock.length, 8001)
    ss, sv, sa = clock(tau)
    d1 = np.stack([np.interp(ss, s, c) for c in qd.T], 1)
    d2 = np.stack([np.interp(ss, s, c) for c in qdd.T], 1)
    acc = np.abs(d2 * sv[:, None] ** 2 + d1 * sa[:, None]).max()
    assert acc <= 20.0 * (1 + 1e-3)
    assert (np.abs(d1 * sv[:, None]) / vmax).max() <= 1.0
    # already at the bound at speed 1: not faster; a damping overrun of 2: at most 1
    assert fastest_speed(dur, qd, qdd, vmax, 1e-3) == 1.0
    assert fastest_speed(dur, qd, qdd, vmax, 20.0, damping=2.0) == 1.0


def _gait(fast_rolls: bool):
    from planner_service.planners import REQUEST
    from planner_service.planners.cache import FingerCache
    from planner_service.planners.gait import solve_gait
    from planner_service.planners.manipulation import manipulation_problem

    body = json.loads((ROOT / "examples" / "allegro_turn_90.json").read_text())
    body["gait"].update(replace="spent", fastest_swings=True, fastest_rolls=fast_rolls)
    request = REQUEST.validate_python(body)
    cache = FingerCache()
    problem = manipulation_problem(request, cache)
    result, gait = solve_gait(request, problem, cache.manipulation)
    return request, result, gait


@pytest.mark.slow
def test_fast_rolls_are_certified_shorter_and_execute() -> None:
    from planner_service.execution import simulate_result

    _, _, slow = _gait(False)
    request, result, gait = _gait(True)
    assert gait.ok and result.certificate is not None and result.certificate.passed
    assert math.degrees(gait.turned) == pytest.approx(90.0, abs=1e-3)
    assert gait.duration < slow.duration - 5.0  # measured: 28.6 s against 39.1 s
    values = result.certificate.values
    for r, (clock, roll) in enumerate(zip(gait.clocks, gait.rolls, strict=True)):
        assert clock.speed > 1.0 and clock.length < roll.duration
        # at one of its limits: the acceleration bound or the velocity limits
        assert max(values[f"roll{r}_clock_acceleration"] / 20.0,
                   values[f"roll{r}_clock_velocity"]) > 0.9
        assert f"roll{r}_clock_torque" in values
    report = simulate_result(result, request)
    assert report.passed, report.failures


@pytest.fixture(scope="module")
def landings() -> tuple[Any, ...]:
    """allegro_turn_90.json's searched grasp about +x and its farthest landings (rolls of
    30 deg): (problem, home joints, centre, radius, axis, landing joints)."""
    from ocp.gait.planner import farthest_landings
    from planner_service.planners import REQUEST
    from planner_service.planners.cache import FingerCache
    from planner_service.planners.manipulation import manipulation_problem

    body = json.loads((ROOT / "examples" / "allegro_turn_90.json").read_text())
    body["gait"].update(replace="spent", landing="farthest")
    problem = manipulation_problem(REQUEST.validate_python(body), FingerCache())
    q_home = tuple(np.asarray(t.q_seed, dtype=float) for t in problem.fingers)
    centre = np.asarray(problem.initial_pose.position, dtype=float)
    rho = float(problem.object.dimensions[0])
    axis = np.array([1.0, 0.0, 0.0])
    landed = farthest_landings(problem, q_home, centre, rho, axis, math.radians(30.0))
    return problem, q_home, centre, rho, axis, landed


def test_the_farthest_landing_touches_and_reaches_at_least_as_far_as_home(
        landings: tuple[Any, ...]) -> None:
    """ocp.gait.planner.farthest_landings on the searched grasp of allegro_turn_90.json:
    every landing is on the ball (to 1e-9 m) and reaches forward at least as far as the
    home contact, and at least one fingertip lands behind its home."""
    from ocp.robots.grasp_reach import roll, tip_state

    problem, q_home, centre, rho, axis, landed = landings
    moved = 0
    for tip, q0, q in zip(problem.fingers, q_home, landed, strict=True):
        f = tip.finger
        assert abs(tip_state(f, q, centre, rho).gap) < 1e-9
        ahead = roll(f, q, centre, rho, axis, math.pi, problem.pad_margin).reach
        home = roll(f, q0, centre, rho, axis, math.pi, problem.pad_margin).reach
        assert ahead >= home
        moved += bool(np.abs(q - q0).max() > 1e-6)
    assert moved >= 1


def test_landings_drawn_over_the_joints_reach_farther_and_keep_apart(
        landings: tuple[Any, ...]) -> None:
    """The landings of allegro_turn_90.json's searched grasp about +x may be drawn over
    each finger's joints (not only its home contact rolled back): the thumb's reaches at
    least 40 deg forward (48.6 measured; the best of its home contact rolled back: 21.7),
    and every landing away from home keeps LANDING_GAP from the other fingertips' bodies
    where they touch at home and where they land, its normal within LANDING_CONE of
    home's."""
    from ocp.gait.planner import LANDING_CONE, LANDING_GAP, landing_gap
    from ocp.robots.grasp_reach import roll, tip_state

    problem, q_home, centre, rho, axis, landed = landings
    fingers = tuple(t.finger for t in problem.fingers)
    thumb = [t.name for t in problem.fingers].index("thumb")
    assert math.degrees(roll(fingers[thumb], landed[thumb], centre, rho, axis, math.pi,
                             problem.pad_margin).reach) > 40.0
    for k, (f, q0, q) in enumerate(zip(fingers, q_home, landed, strict=True)):
        if np.abs(q - q0).max() < 1e-9:
            continue
        n0, n = tip_state(f, q0, centre, rho).n, tip_state(f, q, centre, rho).n
        assert float(n0 @ n) >= math.cos(LANDING_CONE) - 1e-12
        for at in (q_home, landed):
            qs = tuple(q if j == k else at[j] for j in range(len(fingers)))
            assert landing_gap(fingers, qs, k)[0] >= LANDING_GAP


@pytest.mark.slow
def test_farthest_landings_need_fewer_re_placements_and_execute() -> None:
    """About +y, with rolls of up to 30 deg: certified, fewer re-placements than landing
    home (28 measured with the same options, docs/gait.md), executed in MuJoCo."""
    from planner_service.execution import simulate_result
    from planner_service.planners import REQUEST
    from planner_service.planners.cache import FingerCache
    from planner_service.planners.gait import solve_gait
    from planner_service.planners.manipulation import manipulation_problem

    body = json.loads((ROOT / "examples" / "allegro_turn_90.json").read_text())
    body["motion"]["steps"][0]["axis"] = [0.0, 1.0, 0.0]
    body["gait"].update(replace="spent", fastest_swings=True, fastest_rolls=True,
                        landing="farthest", roll_step=math.radians(30.0))
    request = REQUEST.validate_python(body)
    cache = FingerCache()
    problem = manipulation_problem(request, cache)
    result, gait = solve_gait(request, problem, cache.manipulation)
    assert gait.ok and result.certificate is not None and result.certificate.passed
    assert math.degrees(gait.turned) == pytest.approx(90.0, abs=1e-3)
    assert len(gait.steps) < 28
    report = simulate_result(result, request)
    assert report.passed, report.failures
