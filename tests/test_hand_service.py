"""Whole hands through the service's doors (issue 14, items 2-4 and 6): the built-in
Allegro-class hand by name, our own URDF and MJCF of it as text in the request (the same
plan), the catalog, and bad hand requests answered 422 naming the field and the reason
(over HTTP: through the model checker process, before any NLP is built)."""

from __future__ import annotations

import copy
import json
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest
from conftest import Server
from helpers import assert_close

from dexroll_client.models import ManipulationRequest, ManipulationResult, PlanStatus
from ocp.robots.allegro import mjcf_text, urdf_text
from planner_service.planners import solve as plan_request
from planner_service.planners.cache import FingerCache

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
TIPS = [{"name": n} for n in ("index_tip", "middle_tip", "ring_tip", "thumb_tip")]
#: The same caps' charts as the built-in hand's (ocp.robots.allegro.TIP_SIDES).
SIDES = [[0.5744, -0.6481, 0.0], [0.8424, 0.2009, 0.0], [0.0737, 0.8626, 0.0],
         [0.5119, -0.3655, 0.0]]


def turn(hand: dict[str, Any], angle: float = 0.1, n: int = 10) -> dict[str, Any]:
    """A 4-finger turn of the 60 mm ball about the palm's z axis, from the built-in
    hand's nominal grasp (the joints: its nominal ones)."""
    from ocp.robots.allegro import NOMINAL_Q

    return {
        "planner": "manipulation", "object": {"shape": "sphere", "dimensions": [0.03]},
        "hand": hand,
        "fingers": [{"hand_finger": k, "initial_q": list(NOMINAL_Q[k])} for k in range(4)],
        "initial_pose": {"position": [0.03, 0.0, 0.07], "orientation_wxyz": [1, 0, 0, 0]},
        "motion": {"kind": "steps",
                   "steps": [{"duration": 2.0, "axis": [0, 0, 1], "angle": angle}]},
        "tracking": {"position_tolerance": 0.001, "orientation_tolerance": 0.01745},
        "duration": 2.0, "n_intervals": n}


def own(fmt: str) -> dict[str, Any]:
    text = urdf_text() if fmt == "urdf" else mjcf_text()
    return {fmt: text, "tips": [dict(t, side=s) for t, s in zip(TIPS, SIDES, strict=True)]}


def solve(body: dict[str, Any]) -> Any:
    request = ManipulationRequest.model_validate(body)
    result, _ = plan_request(request, fingers=CACHE)
    return result


CACHE = FingerCache()


@pytest.fixture(scope="module")
def builtin_plan() -> Any:
    return solve(turn({"builtin": "allegro"}))


def test_the_builtin_hand_turns_the_ball_with_four_round_tips(builtin_plan: Any) -> None:
    result = builtin_plan
    assert result.status is PlanStatus.SOLVED, result.message
    cert = result.certificate
    assert cert.passed and not cert.failures
    for name in ("index", "middle", "ring", "thumb"):
        for law in ("max_slip_speed", "max_spin_rate", "max_gap_error", "max_cap_angle"):
            assert cert.values[f"{law}_{name}"] <= cert.tolerances[f"{law}_{name}"]
    assert [f.name for f in result.trajectory.fingers] == ["index", "middle", "ring", "thumb"]
    assert sum(len(f.joint_names) for f in result.trajectory.fingers) == 16


@pytest.mark.parametrize("fmt", ["urdf", "mjcf"])
def test_our_urdf_and_mjcf_of_the_hand_give_the_builtin_hands_plan(fmt: str,
                                                                    builtin_plan: Any) -> None:
    """The hand written twice (URDF, MJCF), sent as text with its tips read from the
    capsule geometry: the same plan as the built-in hand's."""
    result = solve(turn(own(fmt)))
    assert result.status is PlanStatus.SOLVED, result.message
    a, b = result.trajectory, builtin_plan.trajectory
    assert_close(np.array(a.object_position), np.array(b.object_position), atol=1e-7)
    for fa, fb in zip(a.fingers, b.fingers, strict=True):
        assert_close(np.array(fa.q), np.array(fb.q), atol=1e-6)
    for ca_, cb in zip(a.contacts, b.contacts, strict=True):
        assert_close(np.array(ca_.eta), np.array(cb.eta), atol=1e-6)


def test_the_client_plans_the_builtin_hand_over_http(live_server: Server) -> None:
    """The client's door: a 4-finger round-tip plan over HTTP, solved and certified, every
    finger's joints in the ROS-shaped joint trajectory."""
    from dexroll_client import DexrollClient

    with DexrollClient.from_url(live_server.url, timeout=120) as client:
        job = client.plan(turn({"builtin": "allegro"}), timeout=300)
    result = job.result
    assert isinstance(result, ManipulationResult) and result.status is PlanStatus.SOLVED
    assert result.certificate is not None and result.certificate.passed
    assert result.joint_trajectory is not None
    assert len(result.joint_trajectory.joint_names) == 16
    # the built-in hand's joints are motors limited by its URDF's effort (1 N m): the
    # commands over the wire, within it
    act = result.actuator_trajectory
    assert act is not None and [a.joint for a in act.actuators] == \
        result.joint_trajectory.joint_names
    assert {a.kind for a in act.actuators} == {"motor"}
    assert all(a.torque_range == [-1.0, 1.0] for a in act.actuators)
    assert 0.0 <= act.max_load <= 1.0 and len(act.t) == len(result.joint_trajectory.points)
    assert result.certificate.values["max_actuator_load"] == act.max_load


def test_the_examples_are_valid_requests() -> None:
    for name in ("allegro_turn.json", "hand_from_mjcf.json", "hand_from_urdf.json"):
        body = json.loads((EXAMPLES / name).read_text())
        ManipulationRequest.model_validate(body)


# -- bad hand requests: 422 naming the field, over HTTP ---------------------------------------

def _post(server: Server, body: dict[str, Any]) -> dict[str, str]:
    r = httpx.post(f"{server.url}/v1/plans", params={"wait": 0}, content=json.dumps(body),
                   headers={"content-type": "application/json"}, timeout=60)
    assert r.status_code == 422, r.text
    return {d["field"]: d["reason"] for d in r.json()["detail"]}


def test_a_tip_name_not_in_the_model_is_422(live_server: Server) -> None:
    body = turn(own("urdf"))
    body["hand"]["tips"][1]["name"] = "pinky_tip"
    fields = _post(live_server, body)
    assert "'pinky_tip' is not a link" in fields["hand.tips[1].name"]


def test_a_tip_without_round_geometry_and_no_surface_is_422(live_server: Server) -> None:
    body = turn(own("mjcf"))
    body["hand"]["mjcf"] = body["hand"]["mjcf"].replace('type="capsule"', 'type="box"', 1)
    fields = _post(live_server, body)
    assert "no sphere or capsule geom" in fields["hand.tips[0].surface"]


def test_a_coupling_it_cannot_plan_is_422_naming_what_and_why(live_server: Server) -> None:
    body = turn(own("mjcf"))
    body["hand"]["mjcf"] = body["hand"]["mjcf"].replace(
        "<worldbody>", '<equality><joint joint1="index_j2" joint2="index_j3" '
                       'polycoef="0 1 0.3 0 0"/></equality><worldbody>')
    fields = _post(live_server, body)
    assert "<equality><joint> couples 'index_j2'" in fields["hand.mjcf"]
    assert "polynomial of degree above 1" in fields["hand.mjcf"]


def test_an_unsupported_joint_is_422(live_server: Server) -> None:
    body = turn(own("urdf"))
    body["hand"]["urdf"] = body["hand"]["urdf"].replace(
        '<joint name="ring_j1" type="revolute">', '<joint name="ring_j1" type="floating">')
    fields = _post(live_server, body)
    assert "'ring_j1' is a 'floating' joint" in fields["hand.urdf"]


def test_an_unreachable_initial_grasp_is_422_with_finger_distance_and_limit(
        live_server: Server) -> None:
    body = turn({"builtin": "allegro"})
    body["fingers"][1]["initial_q"] = [0.0, 0.0, 0.0, 0.0]
    body["fingers"][2]["initial_q"] = [0.1, 0.3, 2.0, 0.8]
    fields = _post(live_server, body)
    assert "finger 'middle' cannot reach the initial grasp: its tip is" in \
        fields["fingers[1].initial_q"]
    assert "ring_j2 = 2 is above its limit 1.709" in fields["fingers[2].initial_q"]


def test_overlapping_fingertips_are_422(live_server: Server) -> None:
    body = turn({"builtin": "allegro"})
    body["fingers"][1] = copy.deepcopy(body["fingers"][0])
    body["fingers"][1]["name"] = "index_again"
    fields = _post(live_server, body)
    assert "their tips overlap by" in fields["fingers[1].initial_q"]


def test_a_400_joint_mjcf_hand_is_refused_by_the_checker_before_pinocchio(
        live_server: Server) -> None:
    chain = "".join(f'<body name="b{i}" pos="0 0 0.01"><joint name="j{i}" axis="0 1 0" '
                    'range="-1 1"/>' for i in range(400)) + "</body>" * 400
    body = turn({"mjcf": f"<mujoco><worldbody>{chain}</worldbody></mujoco>",
                 "tips": [{"name": "b399"}]})
    body["fingers"] = [{"hand_finger": 0}, {"hand_finger": 0, "name": "again"}]
    r = httpx.post(f"{live_server.url}/v1/plans", params={"wait": 0}, content=json.dumps(body),
                   headers={"content-type": "application/json"}, timeout=60)
    assert r.status_code == 422, r.text
    reasons = [d["reason"] for d in r.json()["detail"] if d["field"] == "hand.mjcf"]
    # the XML's nesting (a limit of the tree, counted while parsing) stops it first
    assert any("nested deeper than" in why or "joints; at most" in why for why in reasons), \
        r.text


def test_the_catalog_lists_the_allegro_with_its_models(live_server: Server) -> None:
    catalog = httpx.get(f"{live_server.url}/v1/models", timeout=30).json()
    hand = next(h for h in catalog["hands"] if h["name"] == "allegro")
    assert hand["n_fingers"] == 4 and hand["urdf"] == urdf_text()
    assert hand["mjcf"] == mjcf_text()
    assert hand["nominal_radius"] == 0.03
    assert [f["tip_surface"]["kind"] for f in hand["fingers"]] == ["capsule"] * 4
