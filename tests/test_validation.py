"""Bad input gets a clear error naming the field and the reason, before any NLP is built."""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import pytest
from pydantic import ValidationError

from dexroll_client.models import BallOnPalmRequest
from ocp.ball_on_palm import BallOnPalmPlanner
from ocp.spec.problem import BallOnPalmProblem, ObjectSpec, ProblemError, ViaPoint
from planner_service.planners import to_problem, validation_errors

GOOD = BallOnPalmProblem(object=ObjectSpec("sphere", (0.025,)), initial=(0, 0, 0, 0, 0),
                         goal={"x": 0.02}, duration=1.0)


@pytest.mark.parametrize(("problem", "field", "words"), [
    (replace(GOOD, object=ObjectSpec("sphere", (0.0,))), "object.dimensions", "> 0"),
    (replace(GOOD, object=ObjectSpec("sphere", (-0.01,))), "object.dimensions", "> 0"),
    (replace(GOOD, object=ObjectSpec("sphere", (math.nan,))), "object.dimensions", "finite"),
    (replace(GOOD, object=ObjectSpec("cube", (0.02,))), "object.shape", "unknown"),
    (replace(GOOD, object=ObjectSpec("ellipsoid", (0.02,))), "object.dimensions", "2 dim"),
    (replace(GOOD, initial=(0, math.nan, 0, 0, 0)), "initial.y", "finite"),
    (replace(GOOD, initial=(0, 0, 0, 0)), "initial", "5 coordinates"),  # type: ignore[arg-type]
    (replace(GOOD, goal={"w": 1.0}), "goal.w", "unknown coordinate"),
    (replace(GOOD, goal={"x": math.inf}), "goal.x", "finite"),
    (replace(GOOD, goal={"u": math.pi / 2}), "goal.u", "pole"),
    (replace(GOOD, goal={"u": -1.4}), "goal.u", "pole"),
    (replace(GOOD, initial=(0, 0, 1.5, 0, 0)), "initial.u", "pole"),
    (replace(GOOD, goal={}), "goal", "nothing to plan"),
    (replace(GOOD, goal={"x": 0.9}), "goal.x", "outside the palm"),
    (replace(GOOD, duration=0.0), "duration", "(0,"),
    (replace(GOOD, duration=-1.0), "duration", "(0,"),
    (replace(GOOD, duration=math.nan), "duration", "(0,"),
    (replace(GOOD, n_intervals=0), "n_intervals", "must be in"),
    (replace(GOOD, pole_margin=0.0), "pole_margin", "(0, pi/2)"),
    (replace(GOOD, via_points=(ViaPoint(2.0, {"x": 0.01}),)), "via_points[0].time", "inside"),
    (replace(GOOD, via_points=(ViaPoint(0.5, {"q": 0.01}),)), "via_points[0].coords.q",
     "unknown coordinate"),
    (replace(GOOD, via_points=(ViaPoint(0.6, {"x": 0.0}), ViaPoint(0.4, {"x": 0.0}))),
     "via_points[1].time", "strictly increasing"),
])
def test_bad_problem_names_field_and_reason(problem: BallOnPalmProblem, field: str,
                                            words: str) -> None:
    planner = BallOnPalmPlanner()
    with pytest.raises(ProblemError) as info:
        planner.solve(problem)
    fields = {f: r for f, r in info.value.errors}
    assert field in fields, info.value.errors
    assert words in fields[field], fields[field]
    assert field in str(info.value)
    assert len(planner.general.nlps) == 0, "no NLP may be built for an invalid problem"


def test_every_error_is_reported_at_once() -> None:
    bad = replace(GOOD, object=ObjectSpec("sphere", (-1.0,)), duration=-1.0,
                  goal={"w": 1.0, "u": 2.0})
    fields = {f for f, _ in bad.errors()}
    assert {"object.dimensions", "duration", "goal.w", "goal.u"} <= fields


def test_valid_problem_has_no_errors() -> None:
    assert GOOD.errors() == []


REQUEST: dict[str, Any] = {"initial": {"x": 0, "y": 0, "u": 0, "v": 0, "psi": 0},
                           "goal": {"x": 0.02}, "duration": 1.0}


@pytest.mark.parametrize(("patch", "field"), [
    ({"duration": float("nan")}, "duration"),
    ({"duration": 0}, "duration"),
    ({"goal": {"w": 1.0}}, "goal.w"),
    ({"goal": {"x": float("inf")}}, "goal.x"),
    ({"object": {"shape": "sphere", "dimensions": [0.0]}}, "object.dimensions.0"),
    ({"object": {"shape": "cube"}}, "object.shape"),
    ({"initial": {"x": 0, "y": 0, "u": 0, "v": 0}}, "initial.psi"),
    ({"colour": "red"}, "colour"),
    ({"n_intervals": 10**6}, "n_intervals"),
    ({"sample_times": [0.5, 3.0]}, "sample_times"),
])
def test_bad_request_names_field(patch: dict[str, Any], field: str) -> None:
    with pytest.raises(ValidationError) as info:
        BallOnPalmRequest.model_validate({**REQUEST, **patch})
    errors = validation_errors(info.value)
    assert field in {f for f, _ in errors}, errors
    assert all("Traceback" not in r for _, r in errors)


def test_request_reaches_core_validation_for_physics_errors() -> None:
    """A goal at a chart pole passes the schema's ranges; the core names it."""
    request = BallOnPalmRequest.model_validate({**REQUEST, "goal": {"u": 1.55}})
    with pytest.raises(ProblemError) as info:
        to_problem(request).validate()
    assert info.value.errors[0][0] == "goal.u"
