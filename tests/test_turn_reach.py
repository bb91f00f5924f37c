"""A turn a round-tip grasp cannot roll through is answered ``infeasible`` at once, naming
the finger, the limit and the angle (issue 24, item 3); a turn within the reach is not
refused; an uncertified result's summary says so before any figure.

The built-in hand's nominal grasp rolls 15.5 deg about +z before the thumb's j0 reaches its
upper limit and 3.4 deg about +x before the middle finger's j2 does (docs/hands.md, "How far
a fingertip grasp can turn a ball").
"""

from __future__ import annotations

import copy
import json
import math
import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from dexroll_client.models import ManipulationRequest, ManipulationResult, PlanStatus
from ocp.geometry.rotations import axis_angle_rotation
from ocp.robots.turn_reach import MARGIN, RELATIVE_MARGIN, motion_turns, refusal_reach
from planner_service.bench.suite import expand, load_suite
from planner_service.cli import plan_request
from planner_service.planners import FINGERS
from planner_service.planners.manipulation import manipulation_problem, manipulation_summary

ROOT = Path(__file__).resolve().parents[1]
ALLEGRO_TURN = json.loads((ROOT / "examples" / "allegro_turn.json").read_text())


def _turn(axis: list[float], degrees: float) -> dict[str, Any]:
    request = copy.deepcopy(ALLEGRO_TURN)
    request["motion"]["steps"][0].update(axis=axis, angle=math.radians(degrees))
    return request


def _first_figure(text: str) -> int:
    match = re.search(r"\d", text)
    return match.start() if match else len(text)


@pytest.mark.parametrize(("axis", "degrees", "words"), [
    ([0, 0, 1], 30.0, ("finger 'thumb'", "joint 'thumb_j0' upper limit", "after 15.5 deg",
                       "30 deg turn about z")),
    ([1, 0, 0], 10.0, ("finger 'middle'", "joint 'middle_j2' upper limit", "after 3.4 deg",
                       "10 deg turn about x")),
], ids=["30deg-z", "10deg-x"])
def test_a_turn_beyond_the_nominal_grasps_reach_is_answered_infeasible_without_an_nlp(
        axis: list[float], degrees: float, words: tuple[str, ...]) -> None:
    result, summary = plan_request(_turn(axis, degrees))
    assert isinstance(result, ManipulationResult)
    assert result.status is PlanStatus.INFEASIBLE
    for w in (*words, "rolling alone cannot turn further", "search_grasp", "finger gaiting"):
        assert w in result.message, result.message
    assert result.stats is not None and result.stats.iterations == 0  # no NLP solved
    assert result.trajectory is None and result.samples is None
    assert result.certificate is not None and not result.certificate.passed
    again = ManipulationResult.model_validate_json(result.model_dump_json())
    assert again.status is PlanStatus.INFEASIBLE and again.message == result.message
    assert summary.index("not certified") < _first_figure(summary), summary
    assert result.message in summary


def test_turns_within_the_reach_are_not_refused() -> None:
    """The example (15 deg about z) and 3 deg about +x, both inside the nominal grasp's
    reach: the check passes them to the planner (tests/test_cli.py plans the example)."""
    planner = FINGERS.manipulation
    for request in (ALLEGRO_TURN, _turn([1, 0, 0], 3.0)):
        problem = manipulation_problem(ManipulationRequest.model_validate(request), FINGERS)
        assert planner.beyond_reach(problem) is None


def _manipulation_requests() -> list[tuple[str, dict[str, Any]]]:
    out = [(p.name, json.loads(p.read_text())) for p in sorted((ROOT / "examples").glob("*.json"))]
    out += [(p.id, p.request) for p in expand(load_suite("quick"))]
    # (a gait's turn is its rolls', each checked by the gait planner: docs/gait.md)
    return [(n, r) for n, r in out if r.get("planner") == "manipulation" and "gait" not in r]


def test_no_example_and_no_problem_of_the_quick_suite_is_refused() -> None:
    """Every manipulation request the project plans today (the examples, the quick suite's
    hand families) goes on to the planner."""
    requests = _manipulation_requests()
    assert {"allegro_turn.json", "hand_from_urdf.json", "hand_from_mjcf.json"} <= \
        {n for n, _ in requests}
    planner = FINGERS.manipulation
    for name, request in requests:
        problem = manipulation_problem(ManipulationRequest.model_validate(request), FINGERS)
        refused = planner.beyond_reach(problem)
        assert refused is None, (name, refused.message if refused else "")


def test_the_refusal_bound_leaves_the_tolerance_and_the_margin() -> None:
    """A turn is refused exactly when the reach falls short of it, less the tolerance, by
    more than max(MARGIN, RELATIVE_MARGIN * reach)."""
    tol = math.radians(1.0)
    for requested in np.radians([8.0, 10.0, 30.0, 90.0]):
        r = refusal_reach(float(requested), tol)
        assert math.isclose(r + max(MARGIN, RELATIVE_MARGIN * r), requested - tol)


def test_a_motions_turns_about_one_axis_add_up_and_holds_drop() -> None:
    z, x = np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0])
    R1 = axis_angle_rotation(z, math.radians(10.0))
    R2 = axis_angle_rotation(z, math.radians(30.0))
    R3 = axis_angle_rotation(x, math.radians(5.0)) @ R2
    turns = motion_turns([np.eye(3), R1, R1, R2, R3])
    assert len(turns) == 2
    assert np.allclose(turns[0].axis, z) and math.isclose(turns[0].angle, math.radians(30.0))
    assert np.allclose(turns[1].axis, x) and math.isclose(turns[1].angle, math.radians(5.0))


def test_an_uncertified_results_summary_says_so_before_any_figure() -> None:
    """A time-limited last iterate's tracking error is not a result: the status line says
    "not certified" first, and the tracking line starts with it."""
    from dexroll_client.models import ManipulationStatsModel, ManipulationTrajectoryModel

    trajectory = ManipulationTrajectoryModel.model_construct(
        contacts=[], tracking_position_error=[0.0, 0.0032], tracking_angle_error=[0.0, 0.07],
        grasp_angle=[], cone_margin=[])
    stats = ManipulationStatsModel(raw_status="User_Requested_Stop", iterations=271,
                                   build_time=0.7, solve_time=58.5, refinements=0,
                                   n_intervals=20)
    for status in (PlanStatus.TIME_LIMIT, PlanStatus.INACCURATE):
        result = ManipulationResult.model_construct(
            status=status, message="not solved", stats=stats, goal_error=None,
            certificate=None, trajectory=trajectory)
        summary = manipulation_summary(result)
        assert summary.index("not certified") < _first_figure(summary), summary
        tracking = next(line for line in summary.splitlines() if line.startswith("tracking"))
        assert tracking.split(maxsplit=1)[1].startswith("not certified: 3.2 mm"), tracking
    solved = ManipulationResult.model_construct(
        status=PlanStatus.SOLVED, message="converged; certificate passed", stats=stats,
        goal_error=None, certificate=None, trajectory=trajectory)
    assert "not certified" not in manipulation_summary(solved)
