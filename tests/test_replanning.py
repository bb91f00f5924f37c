"""The public one-NLP seam (:func:`ocp.solve.attempt.attempt`): solve a problem's cached
NLP from a given (measured, possibly moving) state and a warm point; the receding-horizon
loop of docs/replanning.md, run."""

from __future__ import annotations

import math
import re
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from helpers import assert_close, experiment1

from ocp import AttemptOptions, attempt, shifted
from ocp.solution import Status
from ocp.solve.planner import ManipulationPlanner, ManipulationProblem
from ocp.spec.problem import ObjectSpec, ProblemError, ViaPoint

PLANNER = ManipulationPlanner()
ROOT = Path(__file__).resolve().parents[1]
GOAL = {"x": 0.012, "y": 0.006}


def palm_and_finger(duration: float = 2.0) -> ManipulationProblem:
    """The paper's experiment-1 grasp (the built-in finger pressing the ball on the palm)
    rolling the ball 13 mm over the palm, 16 intervals, the smooth timing."""
    return experiment1(GOAL, duration=duration)


@pytest.fixture(scope="module")
def first() -> tuple[ManipulationProblem, object]:
    problem = palm_and_finger()
    sol = PLANNER.solve(problem)
    assert sol.status is Status.SOLVED and sol.certificate.passed, sol.certificate
    # the grid the certificate asked for (the plan may have been refined): its NLP
    assert sol.stats is not None
    return problem.with_intervals(sol.stats.n_intervals), sol


def test_an_attempt_from_its_own_plan_stays_there(first: tuple) -> None:
    """Warm-started at a plan of this very NLP (its primal-dual point), one attempt is
    already at the optimum: a few iterations, the same plan."""
    problem, sol = first
    again = attempt(problem, warm=sol, planner=PLANNER)
    # not certified (not asked): converged, and "inaccurate" until a certificate says more
    assert again.converged and again.status is Status.INACCURATE
    assert "not certified" in again.message
    assert again.stats is not None and again.stats.cache_hit
    assert again.stats.iterations <= 5, again.stats
    # the same optimum to IPOPT's tolerance (its objective to 1e-4; the joints, along
    # which the objective is flattest, to 1e-3 rad)
    assert sol.stats is not None
    assert math.isclose(again.stats.objective, sol.stats.objective, rel_tol=1e-4)
    assert_close(again.X, sol.X, atol=1e-3)


def test_a_moving_start_keeps_the_measured_state_and_rates(first: tuple) -> None:
    """From the plan's state and inputs at t = 0.5 s (the object rolling, the finger
    moving), the rest of the motion is planned from exactly that state and with exactly
    those first inputs (not pinned to rest), and it reaches the same goal."""
    problem, sol = first
    dt = 0.5
    now = sol.sample([dt])
    assert np.max(np.abs(now.u)) > 1e-3  # really moving
    rest = replace(problem, duration=problem.duration - dt)
    new = attempt(rest, x0=now.x[0], u0=now.u[0], warm=shifted(sol, dt),
                  options=AttemptOptions(max_iter=200, certify=True), planner=PLANNER)
    assert new.status is Status.SOLVED, new.stats
    assert new.certificate.passed, new.certificate.failures
    assert_close(new.X[0], now.x[0], atol=1e-12 * (1 + np.abs(now.x[0])))
    assert_close(new.U[0], now.u[0], atol=1e-9 * (1 + np.abs(now.u[0])))
    palm = new.contacts[0].eta[-1]
    assert_close(palm[:2], [GOAL["x"], GOAL["y"]], atol=1e-6)
    # cold (no warm start: the palm's sub-plan guesses from rest), the same laws
    cold = attempt(rest, x0=now.x[0], u0=now.u[0],
                   options=AttemptOptions(max_iter=200, certify=True), planner=PLANNER)
    assert cold.status is Status.SOLVED and cold.certificate.passed, cold.stats
    assert_close(cold.X[0], now.x[0], atol=1e-12 * (1 + np.abs(now.x[0])))
    assert_close(cold.U[0], now.u[0], atol=1e-9 * (1 + np.abs(now.u[0])))


def test_the_receding_horizon_loop_of_the_docs(first: tuple) -> None:
    """docs/replanning.md's loop: re-plan every 0.25 s from the state the last plan
    reaches (the 'measured' one here), shrinking the horizon, each warm-started at the
    last plan shifted in time; every re-plan solves within its small iteration budget, is
    continuous with the executed motion, and the last one is certified and at the goal."""
    problem, sol = first
    period, t = 0.25, 0.0
    while problem.duration - t > 2 * period:
        t += period
        now = sol.sample([period])  # the state and rates one period later
        rest = replace(problem, duration=problem.duration - t)
        last = problem.duration - t <= 3 * period
        sol = attempt(rest, x0=now.x[0], u0=now.u[0], warm=shifted(sol, period),
                      options=AttemptOptions(max_iter=30, certify=last), planner=PLANNER)
        assert sol.converged, (t, sol.stats)
        assert sol.status is (Status.SOLVED if last else Status.INACCURATE)
        assert_close(sol.X[0], now.x[0], atol=1e-12 * (1 + np.abs(now.x[0])))
    assert sol.certificate.passed, sol.certificate.failures
    assert_close(sol.contacts[0].eta[-1][:2], [GOAL["x"], GOAL["y"]], atol=1e-6)


def test_a_state_the_grasp_cannot_explain_is_refused(first: tuple) -> None:
    """A fingertip away from where its joints put it (a joint angle off by 0.05 rad), a
    state of the wrong size or not finite: a ProblemError naming the field, no solve."""
    problem, sol = first
    x = sol.X[0].copy()
    q0 = PLANNER.model(problem).fingertips[0].q_cols.start
    x[q0 + 1] += 0.05
    with pytest.raises(ProblemError) as e:
        attempt(problem, x0=x, planner=PLANNER)
    assert "x0 (finger 0)" in str(e.value) and "from where its contact" in str(e.value)
    for bad in (sol.X[0][:-1], np.full_like(sol.X[0], np.nan)):
        with pytest.raises(ProblemError, match="x0"):
            attempt(problem, x0=bad, planner=PLANNER)
    with pytest.raises(ProblemError, match="u0"):
        attempt(problem, u0=np.zeros(3), planner=PLANNER)


def test_shifted_is_the_rest_of_the_plan(first: tuple) -> None:
    _, sol = first
    ws = shifted(sol, 0.5)
    assert ws.t[0] == 0.0 and math.isclose(ws.t[-1], sol.duration - 0.5)
    assert_close(ws.x, sol.interpolate(ws.t + 0.5)[0], atol=1e-12)
    with pytest.raises(ValueError, match="dt"):
        shifted(sol, sol.duration)


def test_the_certificate_holds_a_moving_start_to_its_given_input(first: tuple) -> None:
    """The smooth timing's start law: a plan from rest starts with zero rates; a moving
    start starts with the given input, and a plan that does not is caught."""
    from ocp.solve.certify import timing_checks

    problem, sol = first
    m = PLANNER.model(problem)
    checks = {c.name: c for c in timing_checks(problem, m, sol.trajectory)}
    assert checks["max_rest_rate"].passed and "max_initial_input_error" not in checks
    u0 = sol.collocation.U0[0] + 0.05 * np.max(np.abs(sol.collocation.U0), axis=0)
    moving = replace(problem, initial_input=tuple(u0))
    checks = {c.name: c for c in timing_checks(moving, m, sol.trajectory)}
    assert not checks["max_initial_input_error"].passed
    assert checks["max_initial_input_error"].value >= 0.04


def test_the_docs_loop_runs_as_written(tmp_path: Path) -> None:
    """docs/replanning.md's Python block, run in a fresh interpreter: every re-plan
    printed converged."""
    block = re.findall(r"```python\n(.*?)```", (ROOT / "docs" / "replanning.md").read_text(),
                       flags=re.S)
    assert len(block) == 1
    script = tmp_path / "loop.py"
    script.write_text(block[0])
    proc = subprocess.run([sys.executable, str(script)], capture_output=True, text=True,
                          timeout=600, check=False)
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.strip().splitlines()
    assert len(lines) >= 4 and all(line.endswith("converged True") for line in lines), \
        proc.stdout


def test_the_rest_of_a_problem_follows_the_same_motion_and_targets() -> None:
    """ManipulationProblem.remaining(dt): the desired poses are the original's dt later,
    the via-points still ahead are moved back by dt (those passed dropped), the phases
    still ahead kept (the current one shortened), the grid size kept."""
    from ocp.spec.grasp import Palm
    from ocp.spec.motion import DesiredMotion, MotionStep, ObjectPose
    from ocp.spec.phases import ContactPhase
    from ocp.spec.problem import ViaPoint

    problem = palm_and_finger(duration=2.0)
    assert problem.palm is not None
    palm = Palm(problem.palm.initial, problem.palm.goal,
                (ViaPoint(0.5, {"x": 0.004}), ViaPoint(1.5, {"x": 0.009})))
    start = ObjectPose(position=(0.0, 0.0, 0.025))
    motion = DesiredMotion.from_steps(start, [MotionStep(1.0, (0, 0, 1), 0.2),
                                              MotionStep(1.0, (0, 1, 0), 0.1)])
    phases = (ContactPhase(0.8, (True,)), ContactPhase(1.2, (True,)))
    full = replace(problem, palm=palm, motion=motion, phases=phases)
    rest = full.remaining(0.7)
    assert math.isclose(rest.duration, 1.3) and rest.n_intervals == full.n_intervals
    assert rest.palm is not None and [vp.time for vp in rest.palm.via_points] == \
        pytest.approx([0.8])
    assert [ph.duration for ph in rest.phases or ()] == pytest.approx([0.1, 1.2])
    s = np.linspace(0.0, rest.duration, 7)
    assert rest.motion is not None
    R1, p1 = rest.motion.at(s)
    R0, p0 = motion.at(s + 0.7)
    assert_close(R1, R0, atol=1e-15)
    assert_close(p1, p0, atol=1e-15)
    assert not [e for e in rest.motion.errors("motion", rest.duration)]
    with pytest.raises(ValueError, match="dt"):
        full.remaining(2.0)


def test_a_tracking_grasp_replans_its_remaining_motion() -> None:
    """Three fingers turning the ball 10 deg in 1 s, re-planned every 0.25 s from where
    the last plan is (a receding horizon on the rest of the desired motion): each re-plan
    starts at the measured state, converges, and the certified last one tracks the
    motion's end."""
    from ocp.robots.hands import load_hand
    from ocp.spec.grasp import hand_fingertips
    from ocp.spec.motion import DesiredMotion, MotionStep, ObjectPose, Tracking

    hand = load_hand("three_finger")
    obj = ObjectSpec("sphere", (0.025,))
    start = ObjectPose(position=hand.nominal_object_position)
    motion = DesiredMotion.from_steps(start, [MotionStep(1.0, (0.0, 0.0, 1.0),
                                                         math.radians(10))])
    problem = ManipulationProblem(
        obj, hand_fingertips(hand, start, obj), 1.0, initial_pose=start, motion=motion,
        tracking=Tracking(position_tolerance=1e-3, orientation_tolerance=math.radians(1)),
        n_intervals=12)
    sol = PLANNER.solve(problem)
    assert sol.status is Status.SOLVED, sol.message
    assert sol.stats is not None
    problem = problem.with_intervals(sol.stats.n_intervals)
    period, t = 0.25, 0.0
    while problem.duration - t > period + 1e-9:
        t += period
        now = sol.sample([period])
        last = problem.duration - t <= period + 1e-9
        sol = attempt(problem.remaining(t), x0=now.x[0], u0=now.u[0],
                      warm=shifted(sol, period),
                      options=AttemptOptions(max_iter=50, certify=last), planner=PLANNER)
        assert sol.converged, (t, sol.stats)
        assert_close(sol.X[0], now.x[0], atol=1e-12 * (1 + np.abs(now.x[0])))
    assert sol.status is Status.SOLVED, sol.certificate.failures
    R_end, _ = motion.at([1.0])
    angle = np.arccos(np.clip((np.trace(R_end[0].T @ sol.object_rotation[-1]) - 1) / 2,
                              -1, 1))
    assert angle <= math.radians(1)


def test_a_measured_ball_on_the_palm_is_estimated_or_refused(first: tuple) -> None:
    """The palm grasp's state from a measurement (ocp.estimate_state): the ball measured
    0.3 mm into the palm and 1 mm along x, the joints 1 mrad off: explained, on closure,
    the ball back on the palm (its measured x kept) and taken by attempt as x0; measured
    5 mm above the palm, it is not a state of the grasp (lifted: unexplained)."""
    from ocp import Measurement, estimate_state
    from ocp.geometry.rotations import quaternion_wxyz

    problem, sol = first
    m = PLANNER.model(problem)
    s = sol.sample([0.5])
    tip = m.fingertips[0]
    x, u = s.x[0], s.u[0]

    def measured(dp: tuple[float, float, float]) -> Measurement:
        return Measurement([x[tip.q_cols] + 1e-3], s.object_position[0] + np.asarray(dp),
                           quaternion_wxyz(s.object_rotation[0]), [u[tip.qd_cols]])

    est = estimate_state(problem, m, measured((1e-3, 0.0, -3e-4)), x, u)
    assert est.explained, est.problems
    assert est.closure <= 1e-9 and est.u is not None
    assert est.object_shift == pytest.approx(3e-4, abs=2e-5)  # back onto the palm
    assert est.x[0] == pytest.approx(x[0] + 1e-3, abs=2e-5)  # the palm contact's x
    rest = replace(problem, duration=problem.duration - 0.5)
    new = attempt(rest, x0=est.x, u0=est.u, warm=shifted(sol, 0.5),
                  options=AttemptOptions(max_iter=50), planner=PLANNER)
    assert_close(new.X[0], est.x, atol=1e-12 * (1 + np.abs(est.x)))
    lifted = estimate_state(problem, m, measured((0.0, 0.0, 5e-3)), x, u)
    assert not lifted.explained and any("object" in p for p in lifted.problems)


def test_the_rest_of_a_problem_keeps_its_segments_intervals() -> None:
    """A shrinking horizon keeps each via-point segment's intervals (the passed ones' go to
    the segment under way): the NLP's structure changes only when a via-point is passed,
    and the grid's size never."""
    problem = experiment1({"x": 0.0, "y": 0.0}, duration=6.0, n_intervals=60,
                          via_points=(ViaPoint(2.0, {"x": 0.03}),
                                      ViaPoint(4.0, {"x": 0.03, "y": 0.03})))
    counts, _ = problem.segments()
    assert counts == (20, 20, 20)
    seen = set()
    for t in np.arange(0.05, 5.9, 0.05):
        rest = problem.remaining(float(t))
        got, bounds = rest.segments()
        assert sum(got) == 60 and bounds[-1] == pytest.approx(6.0 - t)
        ahead = [k for k in range(3) if k * 2.0 + 2.0 > t + 1e-9]
        assert got == (sum(counts[:ahead[0] + 1]), *counts[ahead[0] + 1:])
        seen.add(got)
    assert seen == {(20, 20, 20), (40, 20), (60,)}
    # a rest of a rest: the same allocation as the rest of the whole at the same time
    assert problem.remaining(1.0).remaining(2.5).segments()[0] == \
        problem.remaining(3.5).segments()[0]
    # a refinement (another grid size) splits in proportion again (1 s and 2 s left)
    assert problem.remaining(3.0).with_intervals(30).segments()[0] == (10, 20)
