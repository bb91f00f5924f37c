"""An egg's fingertip contact at one of its ends, or carried over one by the motion: the
plan is made on the egg's side chart (``ObjectSpec.side_chart``: its poles on the
equator), chosen by the planner (ocp/spec/patches.py, docs/shapes.md "Charts").

* a problem restated on the side chart (:func:`side_charted`) touches the egg at the same
  points with the same contact frames, every contact on its patch's equator;
* ``examples/egg_by_its_end.json`` (the egg lying across the fingers, the index's tip on
  its end, beyond the own chart's bound: a 422 before) is measured on the side chart,
  planned and certified, its index touching the end throughout (the example is executed in
  MuJoCo by tests/test_sim.py);
* a turn that carries the ring's contact past the own chart's bound (the request's
  ``pole_margin`` of 0.52 rad puts the bound just above it): predicted by the fingers'
  rolled motion on the egg, planned on the side chart and certified (on the own chart it
  ran to the 60 s limit).
"""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from helpers import assert_close

from ocp.geometry.rotations import quaternion_matrix
from ocp.geometry.surfaces import Chart
from ocp.spec.grasp import fingertips_from_joints
from ocp.spec.patches import _psi_matrix, side_charted, turns_off_chart
from ocp.spec.problem import ProblemError
from planner_service.planners import REQUEST, solve
from planner_service.planners.cache import FingerCache
from planner_service.planners.manipulation import manipulation_problem

ROOT = Path(__file__).resolve().parents[1]
CACHE = FingerCache()


def _request(name: str, **changes: Any) -> Any:
    raw = json.loads((ROOT / "examples" / name).read_text())
    raw.update(changes)
    return REQUEST.validate_python(raw)


def test_a_problem_on_the_side_chart_touches_the_egg_where_it_did() -> None:
    problem = manipulation_problem(_request("egg_turn.json"), CACHE)
    assert not problem.object.side_chart
    alt = side_charted(problem)
    assert alt is not None and alt.object.side_chart
    assert side_charted(alt) is None  # already there
    for a, b in zip(problem.fingers, alt.fingers, strict=True):
        old = Chart.of(problem.object.surface, problem.object.params, a.chart_rotation)
        new = Chart.of(alt.object.surface, alt.object.params, b.chart_rotation)
        p0, G0 = old.frame(a.initial[2:4])
        p1, G1 = new.frame(b.initial[2:4])
        assert_close(p1, p0, atol=1e-12)  # the same point of the egg
        # the same contact frame: G R_psi^T is what the contact angle turns
        assert_close(G1 @ _psi_matrix(b.initial[4]), G0 @ _psi_matrix(a.initial[4]),
                     atol=1e-10)
        assert b.initial[:2] == a.initial[:2]  # the same point of the tip
        assert abs(b.initial[2]) < 1e-9  # on its patch's equator


def test_an_egg_held_by_its_end_is_planned_on_its_side_chart() -> None:
    request = _request("egg_by_its_end.json")
    problem = manipulation_problem(request, CACHE)
    assert problem.object.side_chart
    assert max(abs(t.initial[2]) for t in problem.fingers) < 1e-9
    own = replace(problem.object, side_chart=False)
    with pytest.raises(ProblemError, match=r"index.*beyond the bound"):
        fingertips_from_joints(tuple(t.finger for t in problem.fingers),
                               tuple(t.q_seed for t in problem.fingers), own,
                               problem.initial_pose, tuple(t.name for t in problem.fingers),
                               tuple(f"fingers[{k}].initial_q" for k in range(4)),
                               problem.pole_margin)
    result, sol = solve(request)
    assert result.status.value == "solved", result.message
    assert sol.object_side_chart and result.certificate is not None
    assert result.certificate.passed
    # the result says which chart its fingertips' coordinates are on, with their patches
    assert result.contact_charts is not None and len(result.contact_charts) == 1
    assert result.contact_charts[0].chart == "ellipsoid_side"
    assert np.allclose(result.contact_charts[0].patches,
                       [t.chart_rotation for t in problem.fingers])
    # the index's contact on the egg's end (semi-axis 40 mm) at the start and the end
    traj = result.trajectory
    assert traj is not None
    index = next(c for c in traj.contacts if c.name == "index")
    for k in (0, -1):
        R = quaternion_matrix(traj.object_orientation_wxyz[k])
        body = R.T @ (np.asarray(index.point[k]) - np.asarray(traj.object_position[k]))
        assert abs(body[2]) > 0.036, body  # within 16 deg of the end


def _near_bound(axis: tuple[float, float, float]) -> Any:
    """examples/egg_turn.json turned 10 deg about ``axis`` with a pole margin that puts the
    own chart's bound (1.0508 rad) just above its ring's contact (-1.048 rad)."""
    raw = json.loads((ROOT / "examples" / "egg_turn.json").read_text())
    raw["pole_margin"] = 0.52
    raw["motion"]["steps"][0].update(axis=list(axis), angle=math.radians(10.0))
    return REQUEST.validate_python(raw)


@pytest.mark.parametrize("axis", [(0.0, 0.0, -1.0), pytest.param(
    (-1.0, 1.0, 0.0), marks=pytest.mark.slow)])  # (the second: 12-30 s, the same law)
def test_a_turn_carrying_a_contact_over_the_own_charts_bound_is_planned_on_the_side(
        axis: tuple[float, float, float]) -> None:
    request = _near_bound(axis)
    problem = manipulation_problem(request, CACHE)
    assert not problem.object.side_chart  # every contact within the bound at the start
    planner = CACHE.manipulation
    assert turns_off_chart(problem, lambda: planner._initial_joints(problem))
    # turned the other way, the ring's contact goes down the egg: its own chart
    back = manipulation_problem(_near_bound((-axis[0], -axis[1], -axis[2])), CACHE)
    assert not turns_off_chart(back, lambda: planner._initial_joints(back))
    result, sol = solve(request)
    assert result.status.value == "solved", result.message
    assert sol.object_side_chart
