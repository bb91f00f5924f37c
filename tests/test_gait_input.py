"""Gait requests no gait can serve (issue 26, deliverable 6; docs/gait.md "Bad input"):
too few fingertips, a grasp none of whose fingertips the others can hold the ball without,
a turn beyond the reach of a finger that cannot be re-placed or beyond the planner's
rolls. Each is answered before any roll is planned: a 422 naming the field, or a typed
``infeasible`` result naming the finger and the law, never a time-out or a 500."""

from __future__ import annotations

import copy
import json
import math
import re
from pathlib import Path
from typing import Any

import httpx
import numpy as np

from tests.conftest import Server

EXAMPLE = json.loads((Path(__file__).resolve().parents[1] / "examples" /
                      "allegro_gait.json").read_text())


def _body(**motion: Any) -> dict[str, Any]:
    body = copy.deepcopy(EXAMPLE)
    body["motion"]["steps"][0].update(motion)
    body["duration"] = body["motion"]["steps"][0]["duration"]
    return body


def _post(server: Server, body: dict[str, Any]) -> httpx.Response:
    return httpx.post(f"{server.url}/v1/plans", params={"wait": 120},
                      content=json.dumps(body),
                      headers={"content-type": "application/json"}, timeout=180)


def _fields(r: httpx.Response) -> dict[str, str]:
    assert r.status_code == 422, r.text
    out: dict[str, str] = {}
    for d in r.json()["detail"]:
        out[d["field"]] = out.get(d["field"], "") + d["reason"] + "; "
    return out


def _infeasible(r: httpx.Response) -> dict[str, Any]:
    """The typed answer: infeasible, no roll planned, the gait block's accounting."""
    assert r.status_code in (200, 201), r.text
    job = r.json()
    assert job["state"] == "infeasible", job  # a typed answer, not an error
    res = job["result"]
    assert res["status"] == "infeasible", res
    gait = res["gait"]
    assert gait["rolls"] == 0 and gait["phases"] == [] and gait["turned"] == 0.0
    assert res["joint_trajectory"] is None and gait["samples"] is None
    return res


def test_fewer_than_three_fingertips_is_422_naming_the_fingers(live_server: Server) -> None:
    for n in (1, 2):
        body = copy.deepcopy(EXAMPLE)
        body["fingers"] = body["fingers"][:n]
        reason = _fields(_post(live_server, body))["fingers"]
        assert "at least three fingertips" in reason and f"got {n}" in reason


def test_a_farthest_landing_without_spent_re_placements_is_422(live_server: Server) -> None:
    body = copy.deepcopy(EXAMPLE)
    body["gait"]["landing"] = "farthest"
    reason = _fields(_post(live_server, body))["gait.landing"]
    assert "needs replace 'spent'" in reason


def test_sample_times_are_422_a_gaits_duration_being_its_planners(live_server: Server
                                                                   ) -> None:
    body = copy.deepcopy(EXAMPLE)
    body["sample_times"] = [0.0, 0.5, 1.0]
    reason = _fields(_post(live_server, body))["sample_times"]
    assert "give `sample_rate`" in reason and "its planner's" in reason


def test_a_grasp_no_fingertip_of_which_can_be_lifted_is_infeasible(live_server: Server
                                                                    ) -> None:
    """Index, middle and thumb hold the ball (the request is valid, and rolls), but no two
    of them do: the answer names each and the cones' law, and how far rolling alone
    would turn it."""
    body = copy.deepcopy(EXAMPLE)
    body["fingers"] = [body["fingers"][i] for i in (0, 1, 3)]
    res = _infeasible(_post(live_server, body))
    assert res["gait"]["never_lifted"] == ["index", "middle", "thumb"]
    msg = res["message"]
    assert msg.startswith("no fingertip can be lifted") and "friction cones" in msg
    assert "index, middle, thumb" in msg and "rolling alone" in msg


def test_a_ball_too_heavy_to_lift_a_finger_off_names_it(live_server: Server) -> None:
    """At mu = 0.15 the index, middle and thumb hold the 50 g ball without the ring finger,
    squeezing it; not a 0.5 kg one within the plan's bound on the forces (each component
    20 times the weight). The ring finger then rolls through the whole turn, and its joint
    stops it before 20 deg about -y: the answer names the ring finger, the hold's law and
    the weight; the same turn of the 50 g ball passes the same laws."""
    from ocp.gait.feasibility import gait_outlook

    body = copy.deepcopy(EXAMPLE)
    body["mu"] = 0.15
    body["forces"]["mass"] = 0.5
    res = _infeasible(_post(live_server, body))
    assert res["gait"]["never_lifted"] == ["ring", "thumb"]
    msg = res["message"]
    assert msg.startswith("finger 'ring' (joint limit (ring_j") and "of 20.0 deg" in msg
    assert "cannot hold the ball: no forces inside their friction cones" in msg
    assert "its weight of 4.91 N" in msg
    light, qs = _grasp(mu=0.15, mass=0.05)
    outlook = gait_outlook(light, qs, (0, -1, 0), math.radians(20), math.radians(10))
    assert outlook.feasible and outlook.never_lifted == ("thumb",)
    heavy, qs = _grasp(mu=0.15, mass=0.5)
    assert gait_outlook(heavy, qs, (0, -1, 0), math.radians(20),
                        math.radians(10)).message == msg


def test_a_turn_beyond_the_never_lifted_fingers_reach_names_its_limit(
        live_server: Server) -> None:
    """At mu = 0.5 the built-in hand's thumb cannot be lifted (docs/gait.md), so it rolls
    through the whole turn: 90 deg about +z is beyond its joints. The answer names the
    thumb, its joint and the turn it allows; that turn, asked for, passes the same laws,
    and a turn beyond it does not (the bound is the law's, not the message's)."""
    from ocp.gait.feasibility import gait_outlook

    res = _infeasible(_post(live_server, _body(axis=[0, 0, 1], angle=math.pi / 2,
                                               duration=12.6)))
    msg = res["message"]
    assert res["gait"]["never_lifted"] == ["thumb"]
    assert msg.startswith("finger 'thumb' (joint limit (thumb_j") and \
        "cannot be re-placed" in msg and "of 90.0 deg about (0, 0, 1)" in msg
    bound = math.radians(float(re.search(r"at most ([0-9.]+) deg", msg).group(1)))
    assert 0.0 < bound < math.pi / 2
    problem, qs = _grasp(mu=0.5)
    assert gait_outlook(problem, qs, (0, 0, 1), bound - math.radians(0.2),
                        math.radians(10)).feasible
    assert not gait_outlook(problem, qs, (0, 0, 1), bound + math.radians(0.2),
                            math.radians(10)).feasible


def test_a_turn_beyond_the_planners_rolls_is_refused(live_server: Server) -> None:
    """The rolls' cap: by arithmetic (the request's roll_step, a 422) and by the grasp's
    reach (at mu = 1.0 every fingertip is re-placed, but the middle finger rolls only a
    few degrees about +x before a joint stops it: 180 deg take more rolls than a gait
    plans)."""
    from ocp.gait.feasibility import MAX_ROLLS

    body = _body(angle=math.pi)
    body["gait"]["roll_step"] = math.pi / (MAX_ROLLS + 5)
    assert f"at most {MAX_ROLLS}" in _fields(_post(live_server, body))["gait.roll_step"]
    body = _body(axis=[1, 0, 0], angle=math.pi, duration=25.0)
    body["mu"] = 1.0
    res = _infeasible(_post(live_server, body))
    assert res["gait"]["never_lifted"] == []
    m = re.search(r"finger 'middle' \(joint limit \(middle_j\d\)\) rolls the ball ([0-9.]+) "
                  r"deg at most .* take at least (\d+) rolls, more than a gait's (\d+)",
                  res["message"])
    assert m is not None, res["message"]
    step, need, cap = float(m.group(1)), int(m.group(2)), int(m.group(3))
    assert cap == MAX_ROLLS < need and abs(need - 180.0 / step) <= 180.0 / step ** 2 * 0.05 + 1


def test_too_little_friction_for_the_grasp_is_infeasible(live_server: Server) -> None:
    """Index, middle and thumb at mu = 0.1: not even the whole grasp holds the ball (three
    contacts' forces push through the ball's centre but for their friction, and three
    normals do not span every direction of its weight); at mu = 0.5 it does, and the
    answer is the lifts' (the law, not the number)."""
    body = copy.deepcopy(EXAMPLE)
    body["fingers"] = [body["fingers"][i] for i in (0, 1, 3)]
    body["mu"] = 0.1
    res = _infeasible(_post(live_server, body))
    assert "(index, middle, thumb) cannot hold the ball in their grasp" in res["message"]
    assert "mu 0.1 less the cone margin 0.05 rad" in res["message"]
    body["mu"] = 0.5
    res = _infeasible(_post(live_server, body))
    assert res["message"].startswith("no fingertip can be lifted")


def _grasp(mu: float, mass: float = 0.05) -> tuple[Any, tuple[Any, ...]]:
    """The example's grasp (the built-in hand's nominal joints on the 60 mm, 50 g ball)."""
    from ocp.robots.allegro import NOMINAL_Q, load_allegro
    from ocp.spec.grasp import ManipulationProblem, fingertips_from_joints
    from ocp.spec.motion import ObjectPose
    from ocp.spec.problem import ForceSpec, ObjectSpec

    hand, ball = load_allegro(), ObjectSpec("sphere", (0.03,))
    pose = ObjectPose(position=(0.03, 0.0, 0.07))
    qs = tuple(np.array(q) for q in NOMINAL_Q)
    tips = fingertips_from_joints(hand.fingers, qs, ball, pose,
                                  ("index", "middle", "ring", "thumb"),
                                  tuple(f"fingers[{i}].initial_q" for i in range(4)))
    return ManipulationProblem(object=ball, fingers=tips, duration=1.0, initial_pose=pose,
                               n_intervals=16, forces=ForceSpec(mass=mass), mu=mu), qs


def test_overlap_without_spent_re_placements_is_422(live_server: Server) -> None:
    body = copy.deepcopy(EXAMPLE)
    body["gait"]["overlap"] = True
    reason = _fields(_post(live_server, body))["gait.overlap"]
    assert "needs replace 'spent'" in reason
