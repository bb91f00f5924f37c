"""The palm contact's chart patch chosen by the planner when a plan rides the pole bound
of the request's (ocp/spec/patches.py, docs/conventions.md "Chart patches")."""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from helpers import assert_close

from ocp.ball_on_palm import BallOnPalmPlanner
from ocp.contacts.palm_model import object_pose
from ocp.geometry.surfaces import Chart
from ocp.solution import Status
from ocp.spec.patches import recharted_coordinates
from ocp.spec.problem import BallOnPalmProblem, ObjectSpec

ROOT = Path(__file__).resolve().parents[1]
KEYS = ("x", "y", "u", "v", "psi")


@pytest.mark.parametrize("seed", range(4))
def test_restated_coordinates_are_the_same_pose(seed: int) -> None:
    rng = np.random.default_rng(seed)
    old = ObjectSpec("sphere", (0.03,), tuple(rng.normal(size=3)))
    new = ObjectSpec("sphere", (0.03,), tuple(rng.normal(size=3)))
    eta = {"x": 0.01, "y": -0.02, "u": rng.uniform(-1.2, 1.2), "v": rng.uniform(-3, 3),
           "psi": rng.uniform(-3, 3)}
    again = recharted_coordinates(Chart.of(old.surface, old.dimensions, old.chart_rotation),
                                  Chart.of(new.surface, new.dimensions, new.chart_rotation),
                                  eta)
    assert again is not None
    R0, p0 = object_pose(old, [eta[k] for k in KEYS])
    R1, p1 = object_pose(new, [again[k] for k in KEYS])
    assert_close(R1, R0, atol=1e-12)
    assert_close(p1, p0, atol=1e-15)


def test_a_contact_angle_without_its_point_cannot_be_restated() -> None:
    s = ObjectSpec("sphere", (0.03,))
    a, b = Chart.of(s.surface, s.dimensions), Chart.of(s.surface, s.dimensions, (0, 1, 0))
    assert recharted_coordinates(a, b, {"x": 0.0, "psi": 0.3}) is None
    assert recharted_coordinates(a, b, {"u": 0.1}) is None
    assert recharted_coordinates(a, b, {"x": 0.01, "y": 0.02}) == {"x": 0.01, "y": 0.02}


@pytest.fixture(scope="module")
def reorientation() -> BallOnPalmProblem:
    """The example turning the ball 60 deg about a horizontal axis: its optimal contact
    loop runs into the pole bound of the default patch."""
    body = json.loads((ROOT / "examples" / "reorient_horizontal_60deg.json").read_text())
    return BallOnPalmProblem(object=ObjectSpec("sphere", tuple(body["object"]["dimensions"])),
                             initial=tuple(body["initial"][k] for k in KEYS),
                             goal=body["goal"], duration=body["duration"],
                             n_intervals=body["n_intervals"])


def test_a_plan_riding_the_pole_bound_is_planned_in_a_clear_patch(
        reorientation: BallOnPalmProblem) -> None:
    problem = replace(reorientation, max_refinements=0)
    limit = math.pi / 2 - problem.pole_margin
    fixed = BallOnPalmPlanner()
    fixed.general.auto_patch = False
    riding = fixed.solve(problem)
    assert riding.plan is not None and riding.plan.raw_status == "Solve_Succeeded"
    assert np.max(np.abs(riding.grid.eta[:, 2])) >= limit - 1e-6  # on the bound
    assert riding.chart_rotation == (0.0, 0.0, 0.0)

    sol = BallOnPalmPlanner().solve(problem)
    assert sol.status is Status.SOLVED, sol.message
    assert sol.stats.refinements == 0
    assert sol.chart_rotation != (0.0, 0.0, 0.0)
    assert np.max(np.abs(sol.grid.eta[:, 2])) < limit - 0.1  # clear of the new poles
    # the same physical start and goal: the object's poses in the request's patch
    for row, coords in ((0, problem.initial), (-1, tuple(problem.goal[k] for k in KEYS))):
        R, p = object_pose(problem.object, coords)
        assert_close(sol.grid.object_rotation[row], R, atol=1e-6)
        assert_close(sol.grid.object_position[row], p, atol=1e-8)
    # and its plan is cheaper to certify than the one on the bound: fewer intervals pass
    assert sol.certificate.passed


def test_a_spheroid_keeps_its_patch() -> None:
    """A spheroid's poles are its axis of revolution: no other patch describes it."""
    from ocp.spec.grasp import ManipulationProblem, Palm
    from ocp.spec.patches import pole_clear_patch

    obj = ObjectSpec("ellipsoid", (0.03, 0.02))
    problem = ManipulationProblem(obj, (), 1.0, palm=Palm((0, 0, 0, 0, 0), {"x": 0.01}))
    path = np.array([[0.03, 0.0, 0.0], [0.0, 0.0, 0.02]])
    assert pole_clear_patch(problem, path) is None
