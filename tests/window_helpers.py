"""What the window controller's tests share: experiment 2's first plan, and a grasp
measured off it as a push leaves it."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ocp.control import WindowController
from ocp.geometry.rotations import quaternion_wxyz
from ocp.solve.estimate import Measurement, StateEstimate, estimate_state
from planner_service.execution.closed_loop import FirstPlan, first_plan
from planner_service.planners import REQUEST

EXPERIMENT2 = Path(__file__).resolve().parents[1] / "examples" / "experiment2_two_fingers.json"
#: A tick's wall-clock safety for the tests whose law is a window's convergence within an
#: iteration budget, not the real-time budget: with the default 1 s, 40 iterations under
#: the suite's load ran out of time and the tick was "tracked", not "converged".
NO_DEADLINE = 600.0


def experiment2() -> FirstPlan:
    """Experiment 2 planned here (certified)."""
    fp = first_plan(REQUEST.validate_python(json.loads(EXPERIMENT2.read_text())))
    assert fp.plan.certificate.passed
    return fp


def pushed_estimate(c: WindowController, first: FirstPlan, t: float,
                    offset: tuple[float, float, float]) -> StateEstimate:
    """The grasp's state estimated from the plan's joints and rates at ``t`` with the
    object measured ``offset`` [m] off the plan (the fingertips follow it: the estimate
    makes the state consistent); explained."""
    s = first.plan.sample([t])
    tips = c.model.fingertips
    meas = Measurement([s.x[0][tip.q_cols] for tip in tips],
                       s.object_position[0] + np.asarray(offset, dtype=float),
                       quaternion_wxyz(s.object_rotation[0]),
                       [s.x_dot[0][tip.q_cols] for tip in tips])
    est = estimate_state(c.problem, c.model, meas, *c.state_at(t))
    assert est.explained, est.problems
    return est
