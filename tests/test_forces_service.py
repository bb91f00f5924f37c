"""Forces in the plan through the service's doors (issue 15): the request's `forces`
fields are 422s naming the field when bad; a plan with forces carries each contact's
force and each finger's joint torques on its trajectory, and MuJoCo executes it with
those forces alone (no squeeze, no grip force of its own)."""

from __future__ import annotations

import copy
import json
import math
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest
from conftest import Server

from dexroll_client.models import ManipulationResult, PlanStatus
from planner_service.cli import plan_request
from planner_service.planners import REQUEST

ROOT = Path(__file__).resolve().parents[1]
EXP2: dict[str, Any] = json.loads(
    (ROOT / "examples" / "experiment2_two_fingers.json").read_text(encoding="utf-8"))
FORCES = {"mass": 0.05, "min_normal_force": 1.0, "torsional_friction": 0.005}


def with_forces(**forces: Any) -> dict[str, Any]:
    body = copy.deepcopy(EXP2)
    body["forces"] = {**FORCES, **forces}
    return body


@pytest.fixture(scope="module")
def http(live_server: Server) -> Iterator[httpx.Client]:
    with httpx.Client(base_url=live_server.url, timeout=60) as c:
        yield c


@pytest.mark.parametrize(("patch", "field"), [
    ({"mass": -0.1}, "forces.mass"),
    ({"mass": 0.0}, "forces.mass"),
    ({"gravity": [0.0, 0.0]}, "forces.gravity"),
    ({"gravity": [0.0, "NaN", -9.81]}, "forces.gravity.1"),
    ({"min_normal_force": -1.0}, "forces.min_normal_force"),
    ({"torsional_friction": 1.0}, "forces.torsional_friction"),
    ({"inertia": [1e-5, -1e-5, 1e-5]}, "forces.inertia.1"),
    ({"cone_margin": 0.5}, "forces.cone_margin"),  # the core's: atan(0.5) = 0.46 rad
    ({"surprise": 1}, "forces.surprise"),
])
def test_bad_forces_are_422_naming_the_field(http: httpx.Client, patch: dict[str, Any],
                                             field: str) -> None:
    body = with_forces(**patch)
    text = json.dumps(body).replace('"NaN"', "NaN")
    r = http.post("/v1/plans", content=text, headers={"content-type": "application/json"})
    assert r.status_code == 422, r.text
    fields = [d["field"] for d in r.json()["detail"]]
    assert field in fields, fields


@pytest.fixture(scope="module")
def planned() -> ManipulationResult:
    result, summary = plan_request({**with_forces(), "sample_rate": 20.0})
    assert isinstance(result, ManipulationResult)
    assert result.status is PlanStatus.SOLVED, summary
    return result


def test_the_result_carries_forces_and_joint_torques(planned: ManipulationResult) -> None:
    traj = planned.trajectory
    assert traj is not None
    k = len(traj.t)
    weight = np.array([0.0, 0.0, -9.81]) * FORCES["mass"]
    f = np.array([c.force for c in traj.contacts])  # contacts x k x 3
    assert f.shape == (2, k, 3)
    # the forces balance the weight at every sample of the grid (collocation points)
    assert np.max(np.abs(f.sum(axis=0) + weight)) < 1e-9
    for fin in traj.fingers:
        assert fin.joint_torques is not None
        assert np.asarray(fin.joint_torques).shape == (k, len(fin.joint_names))
    cert = planned.certificate
    assert cert is not None and cert.passed
    assert cert.values["min_normal_force"] >= FORCES["min_normal_force"] * (1 - 1e-3)
    # at the controller's rate too: forces balancing the weight between collocation points
    # (quadratic on each interval, the weight constant: to round-off), and the joint
    # trajectory's `effort` is the fingers' joint torques side by side
    smp = planned.samples
    assert smp is not None
    fs = np.array([c.force for c in smp.contacts])
    assert fs.shape == (2, len(smp.t), 3)
    assert np.max(np.abs(fs.sum(axis=0) + weight)) < 1e-9
    jt = planned.joint_trajectory
    assert jt is not None
    effort = np.array([p.effort for p in jt.points])
    assert np.allclose(effort, np.hstack([f.joint_torques for f in smp.fingers]), atol=1e-12)
    # without `forces` the wire result has none (a kinematic plan, as before)
    assert REQUEST.validate_python(EXP2).forces is None  # type: ignore[union-attr]


def test_mujoco_executes_the_plan_with_its_own_forces(planned: ManipulationResult) -> None:
    """The plan's joint torques as feed-forward, no squeeze, no grip force of the
    simulator's own: the object follows the plan within the default tolerances."""
    from planner_service.execution import execution_plan
    from sim import SimOptions, simulate

    request = REQUEST.validate_python(with_forces())
    plan = execution_plan(planned, request)
    assert plan.has_forces
    report = simulate(plan, SimOptions(squeeze=0.0, grip_force=0.0, use_plan_forces=True))
    assert any("the plan's" in n for n in report.notes), report.notes
    print(f"executed: position {report.position_error.max * 1e3:.3f} mm, angle "
          f"{math.degrees(report.angle_error.max):.3f} deg, passed {report.passed}")
    assert report.passed, report.failures


# -- one finger pressing the ball on the palm: the paper's experiment 1 --------------------

EXP1: dict[str, Any] = json.loads(
    (ROOT / "docs" / "viewer-experiment1.json").read_text(encoding="utf-8"))


def test_one_finger_plans_palm_and_finger_forces_that_mujoco_follows() -> None:
    from dexroll_client.models import FingerPlanResult
    from planner_service.execution import execution_plan
    from sim import SimOptions, simulate

    body = {**copy.deepcopy(EXP1), "forces": FORCES}
    result, summary = plan_request(body)
    assert isinstance(result, FingerPlanResult)
    assert result.status is PlanStatus.SOLVED, summary
    traj = result.trajectory
    assert traj is not None and traj.joint_torques is not None
    palm = np.asarray(traj.palm_contact_force)
    tip = np.asarray(traj.finger_contact_force)
    weight = np.array([0.0, 0.0, -9.81]) * FORCES["mass"]
    assert np.max(np.abs(palm + tip + weight)) < 1e-9
    # the palm pushes up, at least the grip; the pad presses down on the ball
    assert np.all(palm[:, 2] >= FORCES["min_normal_force"] - 1e-9)
    report = simulate(execution_plan(result, REQUEST.validate_python(body)),
                      SimOptions(squeeze=0.0, grip_force=0.0, use_plan_forces=True))
    print(f"experiment 1 executed: position {report.position_error.max * 1e3:.3f} mm, angle "
          f"{math.degrees(report.angle_error.max):.3f} deg, passed {report.passed}, "
          f"{report.failures}")
    # the object follows the plan (smooth timing, the default) on the plan's own forces
    # alone, and no contact breaks (with the paper's piecewise timing the fingertip's did,
    # for 4 ms at the via-point t = 4 s where the joint rates jump: docs/timing.md)
    tol = SimOptions().tolerances
    assert report.position_error.max <= tol.position
    assert report.angle_error.max <= tol.angle
    assert all(c.lost_time == 0.0 and not c.loss_events for c in report.contacts), \
        report.failures
    assert report.passed, report.failures


def test_the_greedy_method_does_not_plan_forces() -> None:
    result, _ = plan_request({**copy.deepcopy(EXP1), "forces": FORCES, "method": "greedy"})
    assert result.status is PlanStatus.INVALID_INPUT
    assert "forces" in result.message, result.message


def test_the_bench_plans_forces_and_executes_on_them(planned: ManipulationResult) -> None:
    """``dexroll bench --forces``: every collocation finger request gets the ``forces``
    block (the greedy method's and the palm planners' do not: they plan none); a planned
    row of a request with forces is executed in MuJoCo on the plan's own forces alone (no
    squeeze or grip of the simulator's) and passes."""
    from planner_service.bench.command import forces_option, with_forces
    from planner_service.bench.rows import execute
    from planner_service.bench.suite import SuiteError, Unit, expand, load_suite, units

    assert forces_option("0.05") == {"mass": 0.05, "min_normal_force": 1.0,
                                     "torsional_friction": 0.005}
    assert forces_option("0.1,2,0") == {"mass": 0.1, "min_normal_force": 2.0,
                                        "torsional_friction": 0.0}
    for bad in ("", "a", "1,2,3,4"):
        with pytest.raises(SuiteError, match="--forces"):
            forces_option(bad)
    todo = with_forces(units(expand(load_suite("quick"), ["one_finger", "translation"], 1)),
                       FORCES)
    got = {(u.family, u.method): "forces" in u.request for u in todo}
    assert got[("one_finger", "collocation")] and not got[("one_finger", "greedy")]
    assert not got[("translation", "collocation")]
    unit = Unit("paper", "experiment2", "collocation", "manipulation",
                {**copy.deepcopy(EXP2), "forces": FORCES}, "solved")
    row = execute(unit, planned)
    assert row["exec_status"] == "passed", row.get("exec_message")
    # the same plan with the simulator's grip instead (a request without forces) passes too
    plain = execute(replace(unit, request=copy.deepcopy(EXP2)), planned)
    assert plain["exec_status"] == "passed", plain.get("exec_message")
