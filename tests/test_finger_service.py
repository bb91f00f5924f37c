"""The one-finger planner through every door: the HTTP API (a real service, the real
client), the command line, and the wire models they share."""

from __future__ import annotations

import copy
import json
import math
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pinocchio as pin
import pytest
from conftest import Server
from helpers import assert_close
from pydantic import TypeAdapter, ValidationError

from dexroll_client import (
    BallOnPalmRequest,
    DexrollClient,
    FingerPlanResult,
    InvalidRequestError,
    Job,
    JobState,
    OneFingerRequest,
    PlanRequest,
    PlanResult,
    PlanStatus,
)
from dexroll_client.models import MAX_FINGER_JOINTS
from ocp.one_finger import OneFingerProblem
from ocp.robots.finger import load_finger

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE_FILE = ROOT / "examples" / "one_finger_roll.json"
#: The 10 mm roll of tests/test_one_finger.py, as a request.
ROLL: dict[str, Any] = json.loads(EXAMPLE_FILE.read_text())
REQUEST: TypeAdapter[PlanRequest] = TypeAdapter(PlanRequest)


def roll(**patch: Any) -> dict[str, Any]:
    body = copy.deepcopy(ROLL)
    body.update(patch)
    return body


def rotation_wxyz(q: list[float]) -> np.ndarray:
    w, x, y, z = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


@pytest.fixture(scope="module")
def client(live_server: Server) -> Iterator[DexrollClient]:
    with DexrollClient.from_url(live_server.url, timeout=60) as c:
        yield c


@pytest.fixture(scope="module")
def planned(client: DexrollClient) -> Job:
    return client.plan(ROLL, timeout=180)


# -- the wire models -------------------------------------------------------------------------

def test_planner_field_picks_the_model_and_defaults_to_ball_on_palm() -> None:
    finger = REQUEST.validate_python(ROLL)
    assert isinstance(finger, OneFingerRequest)
    assert finger.finger.builtin == "k3s" and finger.finger.pad_half_size == 0.05
    assert finger.finger_contact.chart_rotation == [0.0, 0.0, math.pi]
    palm = REQUEST.validate_python({"initial": ROLL["initial"], "goal": {"x": 0.01},
                                    "duration": 1.0})
    assert isinstance(palm, BallOnPalmRequest) and palm.planner == "ball_on_palm"
    # a finger field in a ball-on-palm request is an unknown field, not a silent default
    with pytest.raises(ValidationError, match="finger_contact"):
        REQUEST.validate_python({k: v for k, v in ROLL.items() if k != "planner"})


def test_wire_defaults_are_the_cores() -> None:
    """The wire contract cannot import the core: the defaults they share are pinned here
    (except the finger chart patch: the wire's default faces the ball's top)."""
    request = OneFingerRequest.model_validate(ROLL)
    for name in ("mu", "grasp_weight", "finger_effort_weight", "joint_effort_weight",
                 "pad_margin"):
        assert OneFingerRequest.model_fields[name].default == \
            OneFingerProblem.__dataclass_fields__[name].default, name
    assert request.finger_contact.q_seed is None  # the core's paper seed
    assert load_finger().nq <= MAX_FINGER_JOINTS


@pytest.mark.parametrize(("patch", "words"), [
    ({"finger": {"urdf": "/etc/passwd"}}, "XML text"),
    ({"finger": {"builtin": "k3s", "urdf": "<robot/>"}}, "not both"),
    ({"mu": 0.0}, "greater than 0"),
    ({"mu": float("nan")}, "finite"),
    ({"sample_times": [0.5], "method": "greedy"}, "no polynomials"),
    ({"sample_times": [0.5], "sample_rate": 100.0}, "not both"),
    ({"finger_contact": {"initial": {"x_f": 0, "y_f": 0, "u_f": 0.2, "v_f": 0}}}, "psi_f"),
])
def test_bad_finger_requests_fail_in_the_model(patch: dict[str, Any], words: str) -> None:
    with pytest.raises(ValidationError, match=words):
        OneFingerRequest.model_validate(roll(**patch))


def test_results_of_either_planner_parse_and_old_results_are_ball_on_palm() -> None:
    job = {"id": "j", "state": "failed", "planner": "ball_on_palm",
           "created_at": "2024-01-01T00:00:00Z",
           "result": {"status": "error", "message": "m"}}  # stored before `planner` existed
    assert isinstance(Job.model_validate(job).result, PlanResult)
    job["result"] = {"planner": "one_finger", "status": "error", "message": "m"}
    assert isinstance(Job.model_validate(job).result, FingerPlanResult)


# -- the HTTP API, through the client ---------------------------------------------------------

def test_one_finger_plan_end_to_end(planned: Job) -> None:
    job = planned
    assert job.state is JobState.SUCCEEDED, job.message
    assert job.planner == "one_finger"
    result = job.result
    assert isinstance(result, FingerPlanResult)
    assert result.status is PlanStatus.SOLVED
    assert result.certificate is not None and result.certificate.passed
    assert not result.certificate.failures
    assert result.stats is not None and result.stats.iterations > 0
    assert result.goal_error and max(result.goal_error.values()) < 1e-6
    traj = result.trajectory
    assert traj is not None
    assert traj.t[0] == 0.0 and abs(traj.t[-1] - ROLL["duration"]) < 1e-12
    assert abs(traj.eta_p[-1][0] - ROLL["goal"]["x"]) < 1e-6
    assert_close(np.array(traj.eta_p_dot)[:, :2], np.array(traj.w_p), atol=1e-12)
    # inside the friction cone at every sample
    cone = math.atan(ROLL["mu"])
    assert all(max(phis) < cone for phis in traj.grasp_angles)
    assert all(m > 0.0 for m in traj.cone_margin)
    assert_close(np.array(traj.cone_margin), cone - np.max(traj.grasp_angles, axis=1),
                 atol=1e-12)


def test_fingertip_pose_is_pinocchio_fk_of_the_joint_angles(planned: Job) -> None:
    result = planned.result
    assert isinstance(result, FingerPlanResult) and result.trajectory is not None
    traj = result.trajectory
    finger = load_finger(pad_half_size=0.05)
    assert result.joint_names == list(finger.joint_names)
    # the closure is kept at the velocity level and the positions follow by integration:
    # their drift is the grid's (O(h^4)), well inside the certificate's 1e-5 m and 1e-4 rad
    for q, p, quat in zip(traj.q, traj.fingertip_position, traj.fingertip_orientation_wxyz,
                          strict=True):
        R_pin, p_pin = finger.fingertip_pose_pin(q)
        assert_close(p_pin, np.array(p), atol=1e-6)
        assert_close(R_pin, rotation_wxyz(quat), atol=1e-5)


def test_models_lists_the_builtin_finger_whose_urdf_gives_the_same_kinematics(
        client: DexrollClient, planned: Job) -> None:
    catalog = client.models()
    assert set(catalog.planners) == {"ball_on_palm", "one_finger", "manipulation"}
    (k3s,) = [f for f in catalog.fingers if f.name == "k3s"]
    assert k3s.n_joints == 6 and k3s.tip_frame == "fingertip" and len(k3s.joint_names) == 6
    model = pin.buildModelFromXML(k3s.urdf)
    assert model.nq == k3s.n_joints and model.existFrame(k3s.tip_frame)
    assert k3s.base_position is not None and k3s.base_rotation is not None
    from_urdf = load_finger(k3s.urdf, tip_frame=k3s.tip_frame,
                            base_position=k3s.base_position,
                            base_rotation=pin.exp3(np.array(k3s.base_rotation)))
    builtin = load_finger()
    assert isinstance(planned.result, FingerPlanResult) and planned.result.trajectory
    for q in planned.result.trajectory.q[:: 10]:
        R1, p1 = from_urdf.fingertip_pose_pin(q)
        R2, p2 = builtin.fingertip_pose_pin(q)
        assert_close(p1, p2, atol=1e-12)
        assert_close(R1, R2, atol=1e-12)


def test_a_urdf_of_ones_own_is_planned_the_same_way(client: DexrollClient, planned: Job
                                                    ) -> None:
    """The built-in finger given as a user URDF (with its mount): the same plan."""
    (k3s,) = [f for f in client.models().fingers if f.name == "k3s"]
    body = roll(finger={"urdf": k3s.urdf, "tip_frame": k3s.tip_frame,
                        "base_position": k3s.base_position,
                        "base_rotation": k3s.base_rotation, "pad_half_size": 0.05})
    job = client.plan(body, timeout=180)
    assert job.state is JobState.SUCCEEDED, job.message
    assert isinstance(job.result, FingerPlanResult) and job.result.trajectory is not None
    assert isinstance(planned.result, FingerPlanResult) and planned.result.trajectory
    assert_close(np.array(job.result.trajectory.q), np.array(planned.result.trajectory.q),
                 atol=1e-6)


def test_impossible_initial_grasp_is_422_with_the_reason(client: DexrollClient) -> None:
    body = roll(finger_contact={**ROLL["finger_contact"],
                                "initial": {**ROLL["finger_contact"]["initial"], "u_f": 1.2}})
    with pytest.raises(InvalidRequestError) as info:
        client.submit(body, wait=0)
    assert info.value.status_code == 422
    reasons = {d.field: d.reason for d in info.value.detail}
    assert "finger_contact.initial" in reasons, info.value.detail
    assert "friction cone" in reasons["finger_contact.initial"]


@pytest.mark.parametrize(("finger", "field", "words"), [
    ({"urdf": "<robot name='broken'><link name="}, "finger.urdf", "URDF"),
    ({"builtin": "k3s", "tip_frame": "no_such_frame"}, "finger.tip_frame", "no_such_frame"),
])
def test_bad_finger_is_422_naming_the_field(client: DexrollClient, finger: dict[str, Any],
                                            field: str, words: str) -> None:
    with pytest.raises(InvalidRequestError) as info:
        client.submit(roll(finger=finger), wait=0)
    reasons = {d.field: d.reason for d in info.value.detail}
    assert field in reasons, info.value.detail
    assert words in reasons[field]
    assert "Traceback" not in str(info.value)


@pytest.mark.parametrize(("body", "field"), [
    (roll(planner="two_fingers"), "planner"),
    (roll(mu=-1), "mu"),
    (roll(finger={"urdf": "finger.urdf"}), "finger.urdf"),
    (roll(finger_contact={"initial": {"x_f": 0, "y_f": 0, "u_f": 0, "v_f": 0, "psi_f": 0},
                          "q_seed": [0.0, 0.1]}), "finger_contact.q_seed"),
    ({**roll(), "finger_contact": {"initial": {"x_f": 0.049, "y_f": 0, "u_f": 0.2, "v_f": 0,
                                               "psi_f": 0}}}, "finger_contact.initial.x_f"),
])
def test_invalid_finger_requests_get_422_over_http(live_server: Server, body: dict[str, Any],
                                                   field: str) -> None:
    r = httpx.post(f"{live_server.url}/v1/plans", params={"wait": 0}, json=body, timeout=30)
    assert r.status_code == 422, r.text
    assert field in {d["field"] for d in r.json()["detail"]}, r.json()


def test_the_greedy_method_refuses_sample_times(live_server: Server) -> None:
    body = roll(method="greedy", sample_rate=100.0)
    r = httpx.post(f"{live_server.url}/v1/plans", params={"wait": 0}, json=body, timeout=30)
    assert r.status_code == 422, r.text
    assert "method" in {d["field"] for d in r.json()["detail"]}, r.json()


def test_a_one_finger_plan_at_500_hz(client: DexrollClient) -> None:
    """The example at a controller's rate: the finger's joint trajectory, ROS 2 shaped,
    and the samples, from the polynomials the certificate checked."""
    job = client.plan(roll(sample_rate=500.0), timeout=180)
    result = job.result
    assert isinstance(result, FingerPlanResult) and result.status is PlanStatus.SOLVED
    jt, smp = result.joint_trajectory, result.samples
    assert jt is not None and smp is not None
    assert jt.joint_names == result.joint_names
    n = round(ROLL["duration"] * 500) + 1
    assert len(jt.points) == n and len(smp.t) == n
    pos = np.array([p.positions for p in jt.points])
    vel = np.array([p.velocities for p in jt.points])
    acc = np.array([p.accelerations for p in jt.points])
    # central differences over 2 ms: off the derivative by at most dt max |q''| (the
    # accelerations are piecewise linear and jump at nodes)
    dt = 1 / 500
    bound = dt * np.maximum(np.abs(acc[:-2]), np.abs(acc[2:])).max(axis=0)
    assert np.all(np.abs((pos[2:] - pos[:-2]) / (2 * dt) - vel[1:-1]) <= bound + 1e-12)
    assert [c.name for c in smp.contacts] == ["palm", "finger"]
    assert_close(np.array(smp.fingers[0].q), pos, atol=0.0)
    # the plan's via-point-free grid: no rate break; the last point is the end
    assert not jt.rate_breaks and jt.points[-1].t == ROLL["duration"]


# -- the command line ------------------------------------------------------------------------

def test_cli_plans_the_finger_example(tmp_path: Path) -> None:
    out = tmp_path / "result.json"
    proc = subprocess.run([sys.executable, "-m", "planner_service.cli", "plan",
                           str(EXAMPLE_FILE), "-o", str(out)], cwd=tmp_path,
                          capture_output=True, text=True, timeout=600, check=False)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    for words in ("status       solved", "iterations", "solve", "goal error",
                  "certificate  PASSED", "grasp angle", "cone margin"):
        assert words in proc.stdout, proc.stdout
    assert len(proc.stdout.splitlines()) <= 24
    result = FingerPlanResult.model_validate_json(out.read_text())
    assert result.status is PlanStatus.SOLVED and result.certificate is not None
    assert result.certificate.passed and result.trajectory is not None


def test_the_papers_greedy_method_answers_the_same_request(client: DexrollClient,
                                                          planned: Job) -> None:
    """method=greedy plans the same request by the paper's section-3 method: the same palm
    goal, a grasp brought towards antipodal inside the cone, the fingertip where Pinocchio's
    FK of the joint angles puts it (up to its closure tolerance), comparable to the NLP."""
    job = client.plan(roll(method="greedy"), timeout=180)
    assert job.state is JobState.SUCCEEDED, job.message
    result = job.result
    assert isinstance(result, FingerPlanResult) and result.trajectory is not None
    assert result.stats is not None and result.stats.raw_status == "greedy"
    assert result.certificate is not None and result.certificate.passed
    traj = result.trajectory
    assert abs(traj.eta_p[-1][0] - ROLL["goal"]["x"]) < 1e-6
    worst = np.max(traj.grasp_angles, axis=1)
    assert worst[-1] < 0.25 * worst[0] and np.all(worst < math.atan(ROLL["mu"]))
    finger = load_finger()
    for q, p in zip(traj.q, traj.fingertip_position, strict=True):
        assert_close(finger.fingertip_pose_pin(q)[1], np.array(p), atol=1e-12)
    assert result.certificate.values["max_closure_position_error"] < 1e-4
    # the same request by the NLP starts from the same initial grasp
    nlp = planned.result
    assert isinstance(nlp, FingerPlanResult) and nlp.trajectory is not None
    assert_close(np.array(traj.q[0]), np.array(nlp.trajectory.q[0]), atol=1e-9)
