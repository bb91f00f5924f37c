"""The planners' registry and field names (planner_service.planners): one adapter for every
planner and method the wire contract offers, and the core's field paths renamed to the
wire's by one map per planner. Cheap: no NLP is built."""

from __future__ import annotations

import typing

import pytest
from pydantic import BaseModel

from dexroll_client.models import PLANNERS, PlanRequest
from planner_service.planners import REGISTRY, REQUEST, adapter_for, invalid_result
from planner_service.planners.fields import FieldMap, Rule
from planner_service.planners.manipulation import (
    MANIPULATION_FIELDS,
    MANIPULATION_SAMPLES_FIELDS,
)
from planner_service.planners.one_finger import ONE_FINGER_FIELDS


def _request_models() -> list[type[BaseModel]]:
    union = typing.get_args(PlanRequest)[0]
    return [typing.get_args(member)[0] for member in typing.get_args(union)]


def _literals(model: type[BaseModel], field: str) -> tuple[str, ...]:
    info = model.model_fields.get(field)
    return () if info is None else typing.get_args(info.annotation)


def test_every_planner_and_method_of_the_wire_has_one_adapter() -> None:
    wanted = set()
    for model in _request_models():
        (planner,) = _literals(model, "planner")
        wanted |= {(planner, m) for m in _literals(model, "method") or (None,)}
    assert set(REGISTRY) == wanted
    assert {planner for planner, _ in REGISTRY} == set(PLANNERS)
    for (planner, method), adapter in REGISTRY.items():
        assert (adapter.planner, adapter.method) == (planner, method)


@pytest.mark.parametrize("planner", PLANNERS)
def test_an_invalid_request_gets_its_planners_result(planner: str) -> None:
    result = invalid_result([("a.b", "why")], planner)
    assert result.planner == planner and result.errors[0].field == "a.b"


def test_a_request_finds_its_adapter_by_planner_and_method() -> None:
    body = {"planner": "one_finger", "initial": {"x": 0, "y": 0, "u": 0, "v": 0, "psi": 0},
            "duration": 1.0, "finger_contact": {"initial": {
                "x_f": 0, "y_f": 0, "u_f": 0, "v_f": 0, "psi_f": 0}}}
    for method in ("collocation", "greedy"):
        adapter = adapter_for(REQUEST.validate_python({**body, "method": method}))
        assert (adapter.planner, adapter.method) == ("one_finger", method)


@pytest.mark.parametrize(("fields", "core", "wire"), [
    (FieldMap(), "goal.u", "goal.u"),
    (ONE_FINGER_FIELDS, "options.max_iter", "solver.max_iter"),
    (ONE_FINGER_FIELDS, "fingers[0].initial", "finger_contact.initial"),
    (ONE_FINGER_FIELDS, "fingers[0].initial.x_f", "finger_contact.initial.x_f"),
    (ONE_FINGER_FIELDS, "fingers", "finger_contact.initial"),
    (ONE_FINGER_FIELDS, "finger_contact.initial", "finger_contact.initial"),
    (ONE_FINGER_FIELDS, "fingertip", "fingertip"),  # whole segments only
    (MANIPULATION_FIELDS, "initial_pose.orientation", "initial_pose.orientation_wxyz"),
    (MANIPULATION_FIELDS, "initial_pose.position", "initial_pose.position"),
    (MANIPULATION_FIELDS, "motion", "motion"),
    (MANIPULATION_FIELDS, "motion.times", "motion.steps"),
    (MANIPULATION_FIELDS, "motion[3].orientation", "motion.steps"),
    (MANIPULATION_FIELDS, "fingers[1].initial.u_f", "fingers[1].initial.u_f"),
    (MANIPULATION_SAMPLES_FIELDS, "motion[3].orientation", "motion.orientations_wxyz[3]"),
    (MANIPULATION_SAMPLES_FIELDS, "motion[12].position", "motion.positions[12]"),
    (MANIPULATION_SAMPLES_FIELDS, "motion.times", "motion.times"),
    (FieldMap(Rule("a[{i}].b", "c[{i}]", keep_rest=False)), "a[2].b.d", "c[2]"),
])
def test_core_fields_get_their_wire_names(fields: FieldMap, core: str, wire: str) -> None:
    assert fields.wire(core) == wire
