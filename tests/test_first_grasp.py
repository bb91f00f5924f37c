"""A first grasp for any hand (issue 24, item 2): ``ocp.robots.first_grasp`` and the
request's ``grasp`` option, with the built-in hand and with ``examples/own_hand.xml`` (a
whole-hand MJCF of our own in the Menagerie's style: posed root, degrees, default
classes, absent meshes). Laws, not a run's numbers: every tip on the ball, the contacts in
force closure by the planner's own test, the tips apart, the joints within their limits,
the reported reach the chosen joints' own roll; nothing found is a 422 naming the finger."""

from __future__ import annotations

import copy
import json
import math
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest
from conftest import Server

from dexroll_client.models import ManipulationRequest
from ocp.geometry.grasp import force_angles
from ocp.robots.allegro import NOMINAL_OBJECT_POSITION, NOMINAL_RADIUS, load_allegro
from ocp.robots.first_grasp import GraspNotFoundError, Misses, desired_turns, first_grasp
from ocp.robots.grasp_reach import roll, tip_state, tips_gap
from planner_service.planners import request_errors
from planner_service.planners.cache import FingerCache
from planner_service.planners.manipulation import problem_and_grasp

ROOT = Path(__file__).resolve().parents[1]
OWN_TIPS = ("ff_tip", "mf_tip", "rf_tip", "th_tip")
CACHE = FingerCache()


def own_hand_request(angle: float = 0.2618, **extra: Any) -> dict[str, Any]:
    """examples/allegro_turn.json on examples/own_hand.xml, the grasp searched."""
    body = json.loads((ROOT / "examples" / "allegro_turn.json").read_text())
    body["hand"] = {"mjcf": (ROOT / "examples" / "own_hand.xml").read_text(),
                    "tips": [{"name": n} for n in OWN_TIPS]}
    body["motion"]["steps"][0]["angle"] = angle
    body["grasp"] = "auto"
    body.update(extra)
    return body


def _assert_a_grasp(fingers: Any, qs: Any, centre: Any, radius: float, mu: float) -> None:
    for f, q in zip(fingers, qs, strict=True):
        assert f.within_limits(q)
        assert abs(tip_state(f, q, centre, radius).gap) < 1e-6  # the tip on the ball
    assert tips_gap(fingers, qs) >= 1e-3
    normals = np.array([tip_state(f, q, centre, radius).n for f, q in zip(fingers, qs,
                                                                           strict=True)])
    phi, _, onto = force_angles((np.asarray(centre) + radius * normals)[None], normals[None])
    assert onto[0] and phi[0] < math.atan(mu)


def test_a_grasp_of_any_hand_without_its_nominal_grasp() -> None:
    hand = load_allegro()
    got = first_grasp(hand.fingers, NOMINAL_OBJECT_POSITION, NOMINAL_RADIUS, mu=0.5)
    _assert_a_grasp(hand.fingers, got.q, NOMINAL_OBJECT_POSITION, NOMINAL_RADIUS, 0.5)
    assert got.closure > 0.0 and got.reach is None


def test_two_fingers_oppose_within_the_friction_cone() -> None:
    hand = load_allegro()
    fingers = (hand.fingers[1], hand.fingers[3])
    got = first_grasp(fingers, NOMINAL_OBJECT_POSITION, NOMINAL_RADIUS, mu=0.5)
    _assert_a_grasp(fingers, got.q, NOMINAL_OBJECT_POSITION, NOMINAL_RADIUS, 0.5)


def test_a_ball_out_of_reach_names_every_finger() -> None:
    hand = load_allegro()
    with pytest.raises(GraspNotFoundError) as exc:
        first_grasp(hand.fingers, (0.5, 0.0, 0.5), NOMINAL_RADIUS, samples=200)
    assert [f for f, _ in exc.value.errors] == [f"fingers[{i}]" for i in range(4)]
    assert "cannot touch the ball" in exc.value.errors[0][1]
    assert "its tip's centre came no closer than" in exc.value.errors[0][1]
    # samples that came near, counted by what stopped them (the sweep's Shadow-style
    # hand: 340 near, 323 facing away, 12 pulled on and no joints found touching)
    misses = Misses(near=40, away=30, tried=10, unpulled=6, inside=4)
    why = misses.why(1500, "the ball")
    assert why.startswith("of 1500 joint vectors within its limits 40 brought its tip near")
    assert "30 with the cap facing away" in why and "6 found no joints touching" in why
    assert "4 put a link inside the ball" in why and "off the cap" not in why


def test_a_grasp_not_found_says_which_condition_no_combination_meets() -> None:
    """Tips that cannot be kept apart are named as that, not as a closure that fails
    (the message gave the most closed grasp's closure, > 0, beside the real blocker)."""
    hand = load_allegro()
    with pytest.raises(GraspNotFoundError) as exc:
        first_grasp(hand.fingers, NOMINAL_OBJECT_POSITION, NOMINAL_RADIUS, samples=200,
                    min_gap=0.2)
    (field, why), = exc.value.errors
    assert field == "grasp" and "in none are the tips 200 mm apart" in why, why
    assert "force closure" not in why


def test_the_request_option_on_our_mjcf_reports_the_grasp_it_used() -> None:
    request = ManipulationRequest.model_validate(own_hand_request())
    assert request_errors(request, CACHE) == []
    problem, grasp = problem_and_grasp(request, CACHE)
    assert grasp is not None and all(f.searched for f in grasp.fingers)
    fingers = [tip.finger for tip in problem.fingers]
    qs = [np.array(f.q) for f in grasp.fingers]
    centre = request.initial_pose.position  # type: ignore[union-attr]
    _assert_a_grasp(fingers, qs, centre, NOMINAL_RADIUS, request.mu)
    # the contacts the result names are where the joints put the tips
    for f, q, g in zip(fingers, qs, grasp.fingers, strict=True):
        s = tip_state(f, q, centre, NOMINAL_RADIUS)
        assert np.allclose(s.contact, g.contact_point, atol=1e-6)
        assert g.tip_side is not None  # each cap's chart centred on its contact
    # the reach it reports is the chosen joints' own roll toward the motion (the least
    # finger's), up to the whole turn
    turns = desired_turns(problem.motion)
    assert grasp.requested_turn == pytest.approx(0.2618)
    rolled = [roll(f, q, centre, NOMINAL_RADIUS, turns[0].axis, turns[0].angle,
                   request.pad_margin).reach for f, q in zip(fingers, qs, strict=True)]
    assert grasp.reach == pytest.approx(min(rolled), abs=1e-9)
    # the joints given back in a request without `grasp` are the same grasp
    plain = own_hand_request(grasp=None)
    for k, g in enumerate(grasp.fingers):
        plain["fingers"][k]["initial_q"] = g.q
        plain["hand"]["tips"][k]["side"] = g.tip_side
    assert request_errors(ManipulationRequest.model_validate(plain), CACHE) == []


def test_the_builtin_hand_takes_the_searched_tip_sides() -> None:
    body = own_hand_request(grasp={"search": {"maximise_reach": False}})
    body["hand"] = {"builtin": "allegro"}
    request = ManipulationRequest.model_validate(body)
    problem, grasp = problem_and_grasp(request, CACHE)
    assert grasp is not None and grasp.reach is None and grasp.closure > 0.0
    centre = request.initial_pose.position  # type: ignore[union-attr]
    for tip, g in zip(problem.fingers, grasp.fingers, strict=True):
        assert g.tip_side is not None
        # each contact on its cap chart's equator: across the chart's poles
        pole = np.asarray(tip.finger.tip_surface.R)[:, 2]  # the poles' axis, tip frame
        m = tip_state(tip.finger, g.q, centre, NOMINAL_RADIUS).m
        assert abs(float(pole @ m)) < 1e-6
    assert request_errors(request, CACHE) == []


@pytest.mark.parametrize(("change", "field", "words"), [
    (lambda b: b.update(grasp={"search": {"samples": 5}}), "grasp.search.samples",
     "greater than or equal to 50"),
    (lambda b: b.update(initial_pose={"position": [0.5, 0, 0.5]}), "fingers[2]",
     "cannot touch the ball"),
    (lambda b: b["fingers"][1].update(initial={"x_f": 0, "y_f": 0, "u_f": 0, "v_f": 0,
                                                "psi_f": 0}, chart_rotation=[0, 0, 0]),
     "fingers[1].initial", "with `grasp`"),
    # one finger alone holds nothing (was a 500: the search's tip gap of one tip, inf)
    (lambda b: b.update(fingers=b["fingers"][:1]), "fingers", "at least two fingertips"),
    # the object's own reasons on its own field, before its fingertips are measured on it
    # (a sphere's second dimension was a 500 from CasADi; an ellipsoid's fourth a 500
    # from the search; a capsule's third was put on each finger's initial_q)
    (lambda b: b.update(object={"shape": "sphere", "dimensions": [0.03, 0.03]}),
     "object.dimensions", "a sphere has 1 dimension"),
    (lambda b: b.update(object={"shape": "ellipsoid", "dimensions": [0.03] * 4}),
     "object.dimensions", "an ellipsoid has 2 dimensions"),
    (lambda b: b.update(object={"shape": "capsule", "dimensions": [0.01, 0.02, 0.03]}),
     "object.dimensions", "a capsule has 2 dimensions"),
    # a zero quaternion (was a least-squares failure blamed on every finger)
    (lambda b: b["initial_pose"].update(orientation_wxyz=[0, 0, 0, 0]),
     "initial_pose.orientation_wxyz", "must not be zero"),
    # no planner: read as ball_on_palm, whose errors never said that planner was missing
    (lambda b: b.pop("planner"), "planner", "'manipulation' takes them: name the planner"),
])
def test_bad_grasp_requests_are_422_naming_the_field(live_server: Server, change: Any,
                                                     field: str, words: str) -> None:
    body = copy.deepcopy(own_hand_request())
    body["hand"] = {"builtin": "allegro"}  # (the checker's model text: tested above)
    change(body)
    r = httpx.post(f"{live_server.url}/v1/plans", params={"wait": 0},
                   content=json.dumps(body), headers={"content-type": "application/json"},
                   timeout=60)
    assert r.status_code == 422, r.text
    fields = {d["field"]: d["reason"] for d in r.json()["detail"]}
    assert words in fields[field], fields


def test_a_gait_searches_a_grasp_in_which_every_fingertip_can_be_lifted() -> None:
    """With `gait` the search prefers a grasp whose every fingertip the others hold the
    ball without (a gait re-places each): 180 deg about the palm's z at mu = 1, where the
    grasp of the largest reach alone keeps the thumb (docs/gait.md)."""
    from ocp.gait.step import liftable
    from ocp.shapes.held import Held
    from ocp.transcription.values import load_parameters

    body = json.loads((ROOT / "examples" / "allegro_gait.json").read_text())
    body.update(mu=1.0, grasp="auto")
    body["motion"]["steps"][0].update(axis=[0, 0, 1], angle=math.pi, duration=25.2)
    body["duration"] = 25.2
    request = ManipulationRequest.model_validate(body)
    problem, grasp = problem_and_grasp(request, CACHE)
    assert grasp is not None
    fingers = [tip.finger for tip in problem.fingers]
    qs = [np.array(f.q) for f in grasp.fingers]
    centre = np.asarray(request.initial_pose.position)  # type: ignore[union-attr]
    _assert_a_grasp(fingers, qs, centre, NOMINAL_RADIUS, request.mu)
    load = load_parameters(problem)
    assert all(liftable(fingers, qs, Held(centre, np.eye(3), NOMINAL_RADIUS), load))
    # the same search without the gait's preference: the largest reach, the thumb held
    body.pop("gait")
    _, plain_grasp = problem_and_grasp(ManipulationRequest.model_validate(body), CACHE)
    assert plain_grasp is not None and plain_grasp.reach >= grasp.reach  # type: ignore[operator]
    plain_qs = [np.array(f.q) for f in plain_grasp.fingers]
    assert not all(liftable(fingers, plain_qs, Held(centre, np.eye(3), NOMINAL_RADIUS), load))


def test_the_searchs_next_grasps_are_other_valid_grasps_in_its_order() -> None:
    """``skip``: the search's grasp after the ``skip`` best (what a gait that does not plan
    from the best tries next), each a grasp by the same laws, none the same, in the
    search's order (no motion: the most closed first); beyond the grasps weighed, none."""
    hand = load_allegro()
    got = [first_grasp(hand.fingers, NOMINAL_OBJECT_POSITION, NOMINAL_RADIUS, mu=0.5, skip=k)
           for k in range(3)]
    for g in got:
        _assert_a_grasp(hand.fingers, g.q, NOMINAL_OBJECT_POSITION, NOMINAL_RADIUS, 0.5)
    keys = {tuple(np.round(np.concatenate(g.q), 9)) for g in got}
    assert len(keys) == 3
    assert got[0].closure >= got[1].closure >= got[2].closure
    with pytest.raises(GraspNotFoundError, match="no grasp besides"):
        first_grasp(hand.fingers, NOMINAL_OBJECT_POSITION, NOMINAL_RADIUS, mu=0.5,
                    skip=10_000)


def test_the_wire_account_names_the_rank_of_the_grasp_used() -> None:
    body = own_hand_request()
    request = ManipulationRequest.model_validate(body)
    _, best = problem_and_grasp(request, CACHE)
    _, next_ = problem_and_grasp(request, CACHE, skip=1)
    assert best is not None and next_ is not None
    assert (best.rank, next_.rank) == (0, 1)
    assert [f.q for f in best.fingers] != [f.q for f in next_.fingers]
