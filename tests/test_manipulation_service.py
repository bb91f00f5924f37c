"""The manipulation planner (any grasp) through every door: the HTTP API (a real service,
the real client), the command line, and the wire models they share.

One full solve per door: the paper's experiment 2 with the built-in two-finger hand,
planned over HTTP once (module fixture) and by the command line once; every other test
here is cheap (wire models, 422s from the checks that run before any NLP).
"""

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
import pytest
from conftest import Server
from helpers import assert_close
from pydantic import TypeAdapter, ValidationError

from dexroll_client import (
    DexrollClient,
    InvalidRequestError,
    Job,
    JobState,
    ManipulationRequest,
    ManipulationResult,
    PlanRequest,
    PlanStatus,
)
from ocp.geometry.surfaces import rotation_from_vector
from ocp.robots.hands import load_hand
from ocp.solve.planner import ManipulationProblem

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE_FILE = ROOT / "examples" / "experiment2_two_fingers.json"
#: The paper's experiment 2 with the built-in two-finger hand, as a request.
EXP2: dict[str, Any] = json.loads(EXAMPLE_FILE.read_text())
REQUEST: TypeAdapter[PlanRequest] = TypeAdapter(PlanRequest)
DEG = math.pi / 180


def exp2(**patch: Any) -> dict[str, Any]:
    body = copy.deepcopy(EXP2)
    body.update(patch)
    return body


def rotation_wxyz(q: list[float]) -> np.ndarray:
    w, x, y, z = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def angle_between(Ra: np.ndarray, Rb: np.ndarray) -> float:
    return float(np.arccos(np.clip((np.trace(Ra.T @ Rb) - 1) / 2, -1.0, 1.0)))


@pytest.fixture(scope="module")
def client(live_server: Server) -> Iterator[DexrollClient]:
    with DexrollClient.from_url(live_server.url, timeout=60) as c:
        yield c


#: The controller rate the HTTP plan is asked for [Hz].
RATE = 100.0


@pytest.fixture(scope="module")
def planned(client: DexrollClient) -> Job:
    return client.plan({**EXP2, "sample_rate": RATE}, timeout=300)


@pytest.fixture(scope="module")
def result(planned: Job) -> ManipulationResult:
    assert planned.state is JobState.SUCCEEDED, planned.message
    assert isinstance(planned.result, ManipulationResult)
    return planned.result


# -- the wire models -------------------------------------------------------------------------

def test_the_example_is_a_manipulation_request_with_the_papers_motion() -> None:
    request = REQUEST.validate_python(EXP2)
    assert isinstance(request, ManipulationRequest)
    assert request.hand is not None and request.hand.builtin == "two_finger"
    assert request.palm is None and request.motion is not None
    assert request.motion.kind == "steps"
    steps = [(s.axis, round(s.angle / DEG, 9), s.duration) for s in request.motion.steps]
    assert steps == [([0, 0, 1], 20, 1), ([0, 1, 0], 20, 1), ([0, 0, 1], -20, 1),
                     ([0, 1, 0], -20, 1)]
    assert request.duration == 4.0 and request.n_intervals == 40
    assert request.tracking.position_tolerance == 1e-3
    assert request.tracking.orientation_tolerance == pytest.approx(DEG)
    hand = load_hand("two_finger")
    assert request.object.dimensions == [hand.nominal_radius]
    assert request.initial_pose is not None
    assert tuple(request.initial_pose.position) == hand.nominal_object_position


def test_wire_defaults_are_the_cores() -> None:
    """The wire contract cannot import the core: the defaults they share are pinned here."""
    core = ManipulationProblem.__dataclass_fields__
    for name in ("mu", "object_effort_weight", "finger_effort_weight",
                 "joint_effort_weight", "grasp_weight", "pad_margin", "n_intervals",
                 "pole_margin", "max_object_speed", "max_object_rate", "max_refinements"):
        assert ManipulationRequest.model_fields[name].default == core[name].default, name
    from dexroll_client.models import TrackingModel
    from ocp.solve.planner import Tracking

    for name, f in Tracking.__dataclass_fields__.items():
        assert TrackingModel.model_fields[name].default == f.default, name


@pytest.mark.parametrize(("patch", "field", "words"), [
    ({"fingers": [{**EXP2["fingers"][0], "finger": {"builtin": "k3s"}}, EXP2["fingers"][1]]},
     "fingers.0.hand_finger", "not both"),
    ({"fingers": [{k: v for k, v in EXP2["fingers"][0].items() if k != "hand_finger"},
                  EXP2["fingers"][1]]}, "fingers.0.hand_finger", "give `finger`"),
    ({"fingers": []}, "fingers", "at least 1"),
    ({"motion": {"kind": "spiral"}}, "motion", "spiral"),
    ({"motion": {**EXP2["motion"], "steps": [{**EXP2["motion"]["steps"][0],
                                              "duration": -1.0}]}},
     "motion.steps.0.duration", "greater than or equal to 0.001"),
    ({"tracking": {"position_tolerance": float("nan")}}, "tracking.position_tolerance",
     "finite"),
    ({"hand": {"builtin": "four_finger"}}, "hand.builtin", "two_finger"),
])
def test_bad_requests_fail_in_the_model_naming_the_field(live_server: Server,
                                                         patch: dict[str, Any], field: str,
                                                         words: str) -> None:
    """Checked by the wire model, by the client before any HTTP and by the service alike."""
    body = exp2(**patch)
    with pytest.raises(ValidationError, match=words):
        ManipulationRequest.model_validate(body)
    # (json.dumps writes NaN as the service's JSON parser reads it)
    r = httpx.post(f"{live_server.url}/v1/plans", params={"wait": 0},
                   content=json.dumps(body), headers={"content-type": "application/json"},
                   timeout=30)
    assert r.status_code == 422, r.text
    fields = {d["field"]: d["reason"] for d in r.json()["detail"]}
    assert field in fields, fields
    assert words in fields[field]


# -- the HTTP API, through the client ---------------------------------------------------------

def test_experiment2_over_http_is_solved_with_a_passed_certificate(
        planned: Job, result: ManipulationResult) -> None:
    assert planned.planner == "manipulation"
    assert result.status is PlanStatus.SOLVED, result.message
    cert = result.certificate
    assert cert is not None and cert.passed and not cert.failures
    assert result.stats is not None and result.stats.iterations > 0
    assert result.stats.n_intervals >= EXP2["n_intervals"]
    # every check within its tolerance; no slip and no spin at either fingertip
    for key, tol in cert.tolerances.items():
        assert cert.values[key] <= tol, key
    for name in ("f1", "f2"):
        for law in ("max_slip_speed", "max_spin_rate"):
            assert f"{law}_{name}" in cert.tolerances
            assert cert.values[f"{law}_{name}"] <= cert.tolerances[f"{law}_{name}"]
    assert "max_tracking_position_error" in cert.tolerances
    assert cert.tolerances["max_tracking_position_error"] == 1e-3


def test_the_object_tracks_the_motion_within_the_tolerances(result: ManipulationResult
                                                            ) -> None:
    traj = result.trajectory
    assert traj is not None
    assert traj.t[0] == 0.0 and abs(traj.t[-1] - EXP2["duration"]) < 1e-12
    assert traj.desired_position is not None and traj.desired_orientation_wxyz is not None
    assert traj.tracking_position_error is not None and traj.tracking_angle_error is not None
    tol_p = EXP2["tracking"]["position_tolerance"]
    tol_a = EXP2["tracking"]["orientation_tolerance"]
    for k in range(len(traj.t)):
        R, Rd = (rotation_wxyz(traj.object_orientation_wxyz[k]),
                 rotation_wxyz(traj.desired_orientation_wxyz[k]))
        ep = float(np.linalg.norm(np.subtract(traj.object_position[k],
                                              traj.desired_position[k])))
        ea = angle_between(Rd, R)
        assert ep <= tol_p and ea <= tol_a, traj.t[k]
        assert traj.tracking_position_error[k] == pytest.approx(ep, abs=1e-12)
        assert traj.tracking_angle_error[k] == pytest.approx(ea, abs=1e-6)
    # the desired motion is the request's steps about palm axes: at the knots
    R0 = rotation_wxyz(EXP2["initial_pose"]["orientation_wxyz"])
    Rz, Ry = rotation_from_vector([0, 0, 20 * DEG]), rotation_from_vector([0, 20 * DEG, 0])
    knots = {1.0: Rz @ R0, 2.0: Ry @ Rz @ R0, 3.0: Rz.T @ Ry @ Rz @ R0,
             4.0: Ry.T @ Rz.T @ Ry @ Rz @ R0}
    for tk, Rk in knots.items():
        k = int(np.argmin(np.abs(np.array(traj.t) - tk)))
        assert abs(traj.t[k] - tk) < 1e-9
        assert_close(rotation_wxyz(traj.desired_orientation_wxyz[k]), Rk, atol=1e-9)
        assert angle_between(Rk, rotation_wxyz(traj.object_orientation_wxyz[k])) <= tol_a
    # and the object does turn: 20 deg after the first second
    k1 = int(np.argmin(np.abs(np.array(traj.t) - 1.0)))
    turned = angle_between(R0, rotation_wxyz(traj.object_orientation_wxyz[k1]))
    assert turned == pytest.approx(20 * DEG, abs=tol_a)


def test_the_grasp_stays_inside_the_friction_cones(result: ManipulationResult) -> None:
    traj = result.trajectory
    assert traj is not None
    cone = math.atan(EXP2["mu"])
    assert all(m > 0.0 for m in traj.cone_margin)
    assert_close(np.array(traj.cone_margin), cone - np.array(traj.grasp_angle), atol=1e-12)
    assert [c.name for c in traj.contacts] == ["f1", "f2"]
    assert all(c.body == "finger" for c in traj.contacts)
    worst = np.max([c.force_angle for c in traj.contacts], axis=0)
    assert_close(worst, np.array(traj.grasp_angle), atol=1e-12)


def test_each_fingertip_is_where_pinocchio_puts_it(result: ManipulationResult) -> None:
    """Pinocchio's forward kinematics of each finger's returned joint angles gives the
    returned pad pose (closure, eq. 6), and each pad touches the ball at its contact."""
    traj = result.trajectory
    assert traj is not None
    hand = load_hand("two_finger")
    radius = EXP2["object"]["dimensions"][0]
    assert [f.name for f in traj.fingers] == ["f1", "f2"]
    for finger, model, contact in zip(traj.fingers, hand.fingers, traj.contacts, strict=True):
        assert finger.joint_names == list(model.joint_names)
        for k, q in enumerate(finger.q):
            assert np.all(np.asarray(q) >= model.lower - 1e-9)
            assert np.all(np.asarray(q) <= model.upper + 1e-9)
            R_pin, p_pin = model.fingertip_pose_pin(q)
            assert_close(p_pin, np.array(finger.tip_position[k]), atol=2e-7)
            assert_close(R_pin, rotation_wxyz(finger.tip_orientation_wxyz[k]), atol=2e-6)
            # the pad's plane is tangent to the ball, at the contact point
            n_pad = R_pin[:, 2]
            centre = np.array(traj.object_position[k])
            assert float(n_pad @ (centre - p_pin)) == pytest.approx(radius, abs=1e-6)
            assert_close(np.array(contact.normal[k]), -n_pad, atol=1e-5)


# -- 422s over HTTP: the checks before any NLP -------------------------------------------------

def invalid(client: DexrollClient, body: dict[str, Any]) -> dict[str, str]:
    with pytest.raises(InvalidRequestError) as info:
        client.submit(body, wait=0)
    assert info.value.status_code == 422
    assert "Traceback" not in str(info.value)
    return {d.field: d.reason for d in info.value.detail}


def test_missing_initial_pose_without_a_palm_is_422(client: DexrollClient) -> None:
    body = exp2()
    del body["initial_pose"]
    reasons = invalid(client, body)
    assert "initial_pose" in reasons and "required" in reasons["initial_pose"]


def test_a_hand_finger_out_of_range_is_422(client: DexrollClient) -> None:
    body = exp2()
    body["fingers"][1]["hand_finger"] = 2
    reasons = invalid(client, body)
    assert "fingers[1].hand_finger" in reasons, reasons
    assert "2 fingers" in reasons["fingers[1].hand_finger"]


def test_a_zero_rotation_axis_is_422(client: DexrollClient) -> None:
    body = exp2()
    body["motion"]["steps"][2]["axis"] = [0.0, 0.0, 0.0]
    reasons = invalid(client, body)
    assert "motion.steps[2].axis" in reasons, reasons
    assert "zero" in reasons["motion.steps[2].axis"]


def test_an_unreachable_initial_grasp_is_422_with_the_reason(client: DexrollClient) -> None:
    body = exp2()
    body["initial_pose"]["position"] = [0.0, 0.0, 0.2]  # 120 mm above the nominal grasp
    reasons = invalid(client, body)
    for i in (0, 1):
        assert f"fingers[{i}].initial" in reasons, reasons
        assert "cannot reach" in reasons[f"fingers[{i}].initial"]


def test_models_lists_the_planner_and_the_hands(client: DexrollClient) -> None:
    catalog = client.models()
    assert "manipulation" in catalog.planners
    hands = {h.name: h for h in catalog.hands}
    assert set(hands) == {"two_finger", "three_finger", "allegro"}
    allegro = hands.pop("allegro")  # round tips: tests/test_hand_service.py
    assert allegro.n_fingers == 4 and allegro.mjcf and allegro.fingers[0].pad_half_size is None
    for name, info in hands.items():
        hand = load_hand(name)
        assert info.n_fingers == hand.n_fingers == len(info.fingers)
        assert info.nominal_radius == hand.nominal_radius
        assert tuple(info.nominal_object_position) == hand.nominal_object_position
        for k, f in enumerate(info.fingers):
            assert f.name == f"f{k + 1}" and f.joint_names == list(hand.fingers[k].joint_names)
            assert f.nominal_q is not None
    # the example's charts are the hand's nominal ones
    for f, info_f in zip(EXP2["fingers"], hands["two_finger"].fingers, strict=True):
        assert_close(np.array(f["chart_rotation"]), np.array(info_f.nominal_chart_rotation),
                     atol=1e-12)


def test_the_plan_at_a_controllers_rate_is_the_returned_trajectory(
        result: ManipulationResult) -> None:
    """``sample_rate``: every finger's joints at k / rate and at the end, ROS 2 shaped;
    the velocities agree with the positions' central differences and the accelerations
    with the velocities' (the cubic's derivatives), the samples with the grid at the times
    they share; the certificate names where its worst values are."""
    jt, smp, tr = result.joint_trajectory, result.samples, result.trajectory
    assert jt is not None and smp is not None and tr is not None
    T = EXP2["duration"]
    n = round(T * RATE) + 1
    assert len(jt.points) == len(smp.t) == n
    assert [p.t for p in jt.points] == pytest.approx(np.arange(n) / RATE, abs=1e-12)
    last = jt.points[-1].time_from_start
    assert (last.sec, last.nanosec) == (4, 0)
    names = [j for f in tr.fingers for j in f.joint_names]
    assert len(jt.joint_names) == len(names) and len(set(jt.joint_names)) == len(names)
    pos = np.array([p.positions for p in jt.points])
    vel = np.array([p.velocities for p in jt.points])
    acc = np.array([p.accelerations for p in jt.points])
    # central differences: off the derivative by at most dt max |q''| (the accelerations
    # are piecewise linear and jump at nodes)
    bound = np.maximum(np.abs(acc[:-2]), np.abs(acc[2:])).max(axis=0) / RATE
    assert np.all(np.abs((pos[2:] - pos[:-2]) * RATE / 2 - vel[1:-1]) <= bound + 1e-12)
    # accelerations are the derivative of velocities inside an interval (they jump at
    # nodes, where the cubic's pieces meet)
    nodes = np.array(tr.t[::2])
    t = np.arange(n) / RATE
    inside = [i for i in range(1, n - 1)
              if not np.any((nodes > t[i - 1] + 1e-12) & (nodes < t[i + 1] - 1e-12))]
    assert len(inside) > n / 4
    fd = (vel[2:] - vel[:-2]) * RATE / 2
    assert_close(fd[np.array(inside) - 1], acc[inside], atol=1e-3)
    assert not jt.rate_breaks  # the motion's steps are one smooth segment of the NLP
    # the samples' joints are the joint trajectory's; at the grid's times, the grid's
    q = np.hstack([np.array(f.q) for f in smp.fingers])
    assert_close(q, pos, atol=0.0)
    grid_q = np.hstack([np.array(f.q) for f in tr.fingers])
    shared = [i for i, t in enumerate(tr.t) if abs(t * RATE - round(t * RATE)) < 1e-9]
    assert len(shared) >= 5
    rows = [round(tr.t[i] * RATE) for i in shared]
    assert_close(q[rows], grid_q[shared], atol=1e-12)
    c = result.certificate
    assert c is not None and c.times
    assert set(c.times) <= set(c.values)
    assert all(0.0 <= t <= T for t in c.times.values())


@pytest.mark.parametrize(("patch", "field"), [
    ({"sample_times": [0.5, 1.0], "sample_rate": 10.0}, "sample_rate"),
    ({"sample_rate": 5000.0}, "sample_rate"),  # 20001 samples
    ({"sample_times": [1.0, 4.5]}, "sample_times"),  # after the end
])
def test_bad_sample_times_are_422_naming_the_field(live_server: Server, patch: dict[str, Any],
                                                   field: str) -> None:
    r = httpx.post(f"{live_server.url}/v1/plans", params={"wait": 0},
                   json={**EXP2, **patch}, timeout=30)
    assert r.status_code == 422, r.text
    assert field in {d["field"] for d in r.json()["detail"]}, r.json()


# -- the command line ------------------------------------------------------------------------

def test_cli_plans_the_example_to_the_same_plan(tmp_path: Path, result: ManipulationResult
                                                ) -> None:
    out = tmp_path / "result.json"
    proc = subprocess.run([sys.executable, "-m", "planner_service.cli", "plan",
                           str(EXAMPLE_FILE), "-o", str(out)], cwd=tmp_path,
                          capture_output=True, text=True, timeout=600, check=False)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    for words in ("status       solved", "iterations", "solve", "tracking",
                  "certificate  PASSED", "grasp angle", "cone margin", "f1, f2"):
        assert words in proc.stdout, proc.stdout
    assert len(proc.stdout.splitlines()) <= 24
    cli = ManipulationResult.model_validate_json(out.read_text())
    assert cli.status is PlanStatus.SOLVED and cli.certificate is not None
    assert cli.certificate.passed and cli.trajectory is not None
    assert result.trajectory is not None
    for a, b in zip(cli.trajectory.fingers, result.trajectory.fingers, strict=True):
        assert_close(np.array(a.q), np.array(b.q), atol=1e-6)


def test_cli_names_the_bad_field_and_exits_2(tmp_path: Path) -> None:
    bad = tmp_path / "bad.json"
    body = exp2()
    body["fingers"][1]["hand_finger"] = 4
    bad.write_text(json.dumps(body))
    proc = subprocess.run([sys.executable, "-m", "planner_service.cli", "plan", str(bad),
                           "-o", str(tmp_path / "out.json")], cwd=tmp_path,
                          capture_output=True, text=True, timeout=300, check=False)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert "fingers[1].hand_finger" in proc.stderr and "Traceback" not in proc.stderr
    out = ManipulationResult.model_validate_json((tmp_path / "out.json").read_text())
    assert out.status is PlanStatus.INVALID_INPUT


def test_a_diverged_plan_is_a_typed_result_without_nan() -> None:
    """A last iterate with NaN (IPOPT diverged) becomes a result with its typed status and
    no trajectory (JSON has no NaN), never an error of the service."""
    from ocp.certify.certificate import Certificate
    from ocp.solution import Status
    from ocp.solve.planner import ContactTrajectory, FingerTrajectory, ManipulationSolution
    from planner_service.planners.manipulation import result_from_manipulation_solution

    k = 3
    bad = np.full((k, 3), np.nan)
    sol = ManipulationSolution(
        status=Status.NUMERICAL_ERROR, message="not solved", raw_status="Error_In_Step_Computation",
        t=np.linspace(0.0, 1.0, k),
        object_position=bad, object_rotation=np.tile(np.eye(3), (k, 1, 1)),
        object_velocity=bad, object_angular_velocity=bad,
        contacts=(ContactTrajectory("f1", "finger", np.zeros((k, 5)), np.zeros((k, 5)),
                                    np.zeros((k, 2)), bad, bad, np.zeros(k)),),
        fingers=(FingerTrajectory("f1", ("j1",), np.zeros((k, 1)), np.zeros((k, 1)), bad,
                                  np.tile(np.eye(3), (k, 1, 1))),),
        grasp_angle=np.full(k, np.nan), cone_margin=np.full(k, np.nan),
        desired_position=None, desired_rotation=None, tracking_position_error=None,
        tracking_angle_error=None, goal_error={"palm.x": float("nan")},
        certificate=Certificate.failed("the plan has non-finite states or inputs"),
        certificate_failures=("the plan has non-finite states or inputs",))
    result = result_from_manipulation_solution(sol)
    assert result.status is PlanStatus.NUMERICAL_ERROR and result.trajectory is None
    assert "non-finite" in result.message
    assert result.certificate is not None and not result.certificate.passed
    assert result.goal_error == {} and result.certificate.values == {}
    again = ManipulationResult.model_validate_json(result.model_dump_json())
    assert again.status is PlanStatus.NUMERICAL_ERROR
