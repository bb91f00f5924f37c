"""One problem type, one solution type: the paper's settings are presets that build a
ManipulationProblem, planned by the one pipeline into a ManipulationSolution, the same
plan as their front ends present."""

from __future__ import annotations

import math

import numpy as np
import pytest
from helpers import assert_close

import ocp
from ocp import ManipulationProblem, ManipulationSolution, ObjectSpec, plan, presets
from ocp.one_finger import FingerContact, OneFingerProblem
from ocp.robots.finger import load_finger
from ocp.spec.problem import BallOnPalmProblem, ProblemError

BALL = ObjectSpec("sphere", (0.025,))


def test_ball_on_palm_is_a_grasp_planned_as_any_other() -> None:
    problem = presets.ball_on_palm(BALL, initial=(0.0, 0.0, 0.0, 0.0, 0.0),
                                   goal={"x": 0.01, "y": 0.005}, duration=1.0, n_intervals=12)
    assert isinstance(problem, ManipulationProblem) and problem.palm is not None
    assert problem.fingers == ()
    sol = plan(problem)
    assert isinstance(sol, ManipulationSolution)
    assert sol.status is ocp.Status.SOLVED and sol.certificate.passed
    assert_close(sol.contacts[0].eta[-1][:2], [0.01, 0.005], atol=1e-6)
    # the front end's plan of the same problem is the same plan
    front = plan(BallOnPalmProblem(BALL, (0.0, 0.0, 0.0, 0.0, 0.0), {"x": 0.01, "y": 0.005},
                                   1.0, n_intervals=12))
    assert isinstance(front, ocp.PalmSolution) and ocp.Solution is ocp.PalmSolution
    assert_close(front.grid.eta, sol.contacts[0].eta, atol=1e-9)


def test_one_finger_is_the_front_ends_problem() -> None:
    base = BallOnPalmProblem(BALL, (0.0, 0.0, 0.0, 0.0, -math.pi / 2), {"x": 0.01}, 1.0,
                             n_intervals=12)
    contact = FingerContact(initial=(0.0, 0.0, 0.2, 0.0, 0.0),
                            chart_rotation=(0.0, 0.0, math.pi))
    problem = presets.one_finger(base, contact, mu=0.5)
    finger = problem.fingers[0].finger
    front = ocp.OneFingerPlanner.manipulation_problem(
        OneFingerProblem(base=base, finger=finger, contact=contact, mu=0.5))
    assert problem == front and problem.fingers[0].name == "finger"
    assert finger.nq == load_finger().nq


def test_a_preset_names_the_bad_field_as_given() -> None:
    with pytest.raises(ProblemError, match="duration"):
        presets.ball_on_palm(BALL, initial=(0.0,) * 5, goal={"x": 0.01}, duration=-1.0)
    base = BallOnPalmProblem(BALL, (0.0,) * 5, {"x": 0.01}, 1.0)
    with pytest.raises(ProblemError, match="mu"):
        presets.one_finger(base, FingerContact(initial=(0.0, 0.0, 0.2, 0.0, 0.0)), mu=-1.0)


def test_the_timing_record_is_the_stats() -> None:
    """One record of a plan's work: the solution's figures are its stats'."""
    sol = plan(presets.ball_on_palm(BALL, initial=(0.0,) * 5, goal={"x": 0.005},
                                    duration=1.0, n_intervals=10))
    s = sol.stats
    assert s is not None and s.iterations > 0
    assert (sol.iterations, sol.build_time, sol.ipopt_time, sol.refinements) == (
        s.iterations, s.build_time, s.ipopt_time, s.refinements)
    assert np.isfinite(s.solve_time) and s.solve_time >= s.ipopt_time
