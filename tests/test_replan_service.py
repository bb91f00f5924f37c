"""Closing the loop through the service (issue 28, parts 2 and 3; docs/replanning.md
"Through the service", docs/simulation.md "Closed loop"): ``POST /v1/plans/{id}/replan``
and the client's ``replan`` on a real service (uvicorn on loopback), and the simulation
door's disturbances and closed loop. The one-finger roll (experiment 1's grasp without
its via-points) on a coarse grid: a few seconds to plan, a fraction of a second a
re-plan."""

from __future__ import annotations

import asyncio
import json
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest
from conftest import Server

from dexroll_client import AsyncDexrollClient, DexrollClient
from dexroll_client.errors import ConflictError, InvalidRequestError, NotFoundError
from dexroll_client.replan import ReplanRequest, ReplanResult

ROOT = Path(__file__).resolve().parents[1]
GOAL = (0.01, 0.0)  # examples/one_finger_roll.json: the palm contact's goal (x, y) [m]


@pytest.fixture(scope="module")
def roll(live_server: Server) -> tuple[str, dict[str, Any]]:
    """A finished one-finger plan (16 intervals) and its result."""
    request = json.loads((ROOT / "examples" / "one_finger_roll.json").read_text())
    request["n_intervals"] = 16
    with DexrollClient.from_url(live_server.url) as client:
        job = client.plan(request, timeout=300)
    assert job.state.value == "succeeded", job.message
    result = httpx.get(f"{live_server.url}/v1/plans/{job.id}", timeout=30).json()["result"]
    return job.id, result


def measured(result: dict[str, Any], t: float, dp: tuple[float, float, float] = (0, 0, 0)
             ) -> dict[str, Any]:
    """The plan's own state at a collocation point ``t`` as a measurement, the object
    moved by ``dp`` [m]."""
    tr = result["trajectory"]
    k = int(np.argmin(np.abs(np.asarray(tr["t"]) - t)))
    return {"t": tr["t"][k], "q": [tr["q"][k]],
            "object_position": (np.asarray(tr["object_position"][k]) + dp).tolist(),
            "object_wxyz": tr["object_orientation_wxyz"][k]}


def check_starts_at_estimate_and_ends_at_goal(answer: ReplanResult,
                                              body: dict[str, Any]) -> None:
    """The re-plan's laws: it starts at exactly the estimated state, the estimate is
    within the reported shifts of the measurement, and a converged re-plan ends at the
    goal, its horizon the rest of the motion."""
    assert answer.status == "replanned", answer.message
    assert answer.stats.converged and answer.stats.iterations >= 1
    assert answer.stats.wall_time >= answer.stats.solve_time >= 0
    est, smp, jt = answer.estimate, answer.samples, answer.joint_trajectory
    assert est is not None and smp is not None and jt is not None
    assert answer.t == body["t"] and smp.t[0] == 0.0
    assert jt.points[0].t == 0.0
    # the first sample is the estimated state (the NLP's x0, fixed)
    np.testing.assert_allclose(jt.points[0].positions, est.q[0], atol=1e-9)
    np.testing.assert_allclose(smp.fingers[0].q[0], est.q[0], atol=1e-9)
    np.testing.assert_allclose(smp.object_position[0], est.object_position, atol=1e-9)
    # the estimate is the measurement moved as little as closure needs, as reported
    shift = np.linalg.norm(np.subtract(est.object_position, body["object_position"]))
    assert shift == pytest.approx(est.object_shift, abs=1e-9)
    assert est.fingertip_shift[0] <= 3e-3 and est.object_shift <= 3e-3
    # converged: at the goal at the end, the rest of the motion
    assert answer.duration == pytest.approx(2.0 - body["t"], abs=1e-9)
    assert smp.t[-1] == pytest.approx(answer.duration, abs=1e-9)
    np.testing.assert_allclose(smp.object_position[-1][:2], GOAL, atol=1e-6)


def test_a_replan_starts_at_the_measured_state_and_ends_at_the_goal(
        live_server: Server, roll: tuple[str, dict[str, Any]]) -> None:
    job_id, result = roll
    with DexrollClient.from_url(live_server.url) as client:
        # the plan's own state: the estimate is the measurement itself
        body = measured(result, 0.5)
        answer = client.replan(job_id, body)
        check_starts_at_estimate_and_ends_at_goal(answer, body)
        assert answer.job_id == job_id and answer.stats.certified is None
        np.testing.assert_allclose(answer.estimate.q[0], body["q"][0], atol=1e-6)
        np.testing.assert_allclose(answer.estimate.object_position, body["object_position"],
                                   atol=1e-6)
        # pushed 1 mm along the palm: explained (the fingertip follows), re-planned from
        # there, certified on request, at a controller's rate
        pushed = measured(result, 1.0, (0.001, 0.0, 0.0))
        again = client.replan(job_id, ReplanRequest.model_validate(pushed), certify=True,
                              sample_rate=50.0)
        check_starts_at_estimate_and_ends_at_goal(again, pushed)
        assert again.stats.setup_time == 0.0  # the re-planner was kept from the first call
        assert again.stats.certified is True
        np.testing.assert_allclose(np.diff(again.samples.t[:-1]), 0.02, atol=1e-9)
        assert again.estimate.object_shift < 1e-3
        # too near the end: the plan runs to its end
        late = client.replan(job_id, measured(result, 1.875))
        assert late.status == "kept" and late.joint_trajectory is None

    async def from_async() -> ReplanResult:
        async with AsyncDexrollClient.from_url(live_server.url) as client:
            return await client.replan(job_id, **measured(result, 0.25))

    check_starts_at_estimate_and_ends_at_goal(asyncio.run(from_async()),
                                              measured(result, 0.25))


def test_a_state_the_grasp_cannot_explain_is_refused_naming_the_field(
        live_server: Server, roll: tuple[str, dict[str, Any]]) -> None:
    job_id, result = roll
    url = f"{live_server.url}/v1/plans/{job_id}/replan"
    lifted = measured(result, 0.5, (0.0, 0.0, 0.005))  # 5 mm above the palm: dropped
    r = httpx.post(url, json=lifted, timeout=120)
    assert r.status_code == 422, r.text
    body = r.json()
    assert body["error"] == "unexplained_state"
    assert "object_position" in [d["field"] for d in body["detail"]]
    # the finger's joints bent away from the ball: its contact lost
    lost = measured(result, 0.5)
    lost["q"] = [(np.asarray(lost["q"][0]) + np.array([0.0, 0.3, -0.3, 0.0, 0.0, 0.0])
                  ).tolist()]
    with DexrollClient.from_url(live_server.url) as client, \
            pytest.raises(InvalidRequestError) as err:
        client.replan(job_id, lost)
    assert err.value.error == "unexplained_state"
    assert err.value.detail[0].field == "q[0]"
    # a measured contact 10 mm from the plan's (the joints and the object where the plan
    # has them): elsewhere
    here = measured(result, 0.5)
    k = result["trajectory"]["t"].index(here["t"])
    point = np.asarray(result["trajectory"]["finger_contact_point"][k])
    elsewhere = {**here, "contact_points": [(point + np.array([0.0, 0.01, 0.0])).tolist()]}
    r = httpx.post(url, json=elsewhere, timeout=120)
    assert r.status_code == 422, r.text
    assert "contact_points[0]" in [d["field"] for d in r.json()["detail"]], r.text
    # measured where the plan has it: fitted, re-planned
    at = httpx.post(url, json={**here, "contact_points": [point.tolist()]}, timeout=120)
    assert at.status_code == 200, at.text
    assert at.json()["estimate"]["contact_shift"][0] < 1e-6
    # measurements that do not fit the plan
    for change, field in (({"q": [[0.0, 0.1]]}, "q[0]"), ({"t": 2.5}, "t"),
                          ({"object_wxyz": [0, 0, 0, 0]}, "object_wxyz"),
                          ({"q_dot": [[0.0] * 6, [0.0] * 6]}, "q_dot"),
                          ({"object_velocity": [0, 0, 0]}, "object_omega")):
        r = httpx.post(url, json={**measured(result, 0.5), **change}, timeout=120)
        assert r.status_code == 422, (change, r.text)
        assert r.json()["detail"][0]["field"] == field, r.text
    r = httpx.post(url, json={**measured(result, 0.5), "max_iter": 0}, timeout=120)
    assert r.status_code == 422 and r.json()["detail"][0]["field"] == "max_iter"


def test_unknown_and_unreplannable_plans(live_server: Server,
                                         roll: tuple[str, dict[str, Any]]) -> None:
    _, result = roll
    with DexrollClient.from_url(live_server.url) as client:
        with pytest.raises(NotFoundError):
            client.replan("nope", measured(result, 0.5))
        palm = client.plan({"initial": {"x": 0, "y": 0, "u": 0, "v": 0, "psi": 0},
                            "goal": {"x": 0.02}, "duration": 1.0, "n_intervals": 10},
                           timeout=120)
        assert palm.state.value == "succeeded", palm.message
        with pytest.raises(ConflictError, match="no fingers") as err:
            client.replan(palm.id, measured(result, 0.5))
        assert err.value.error == "not_replannable"
        # the greedy method's plan is its steps: answered by the re-plan process
        request = json.loads((ROOT / "examples" / "one_finger_roll.json").read_text())
        greedy = client.plan({**request, "n_intervals": 16, "method": "greedy"}, timeout=120)
        assert greedy.state.value == "succeeded", greedy.message
        with pytest.raises(ConflictError, match="greedy") as err:
            client.replan(greedy.id, measured(result, 0.5))
        assert err.value.error == "not_replannable"


def test_a_pushed_closed_loop_through_the_service_ends_nearer_the_goal(
        live_server: Server, roll: tuple[str, dict[str, Any]]) -> None:
    """The simulation door's closed loop against a 3 mm push along the palm: the same
    world open loop keeps the push, the closed loop (re-planning at 4 Hz) ends nearer the
    goal; bad options are 422s naming the field."""
    job_id, _ = roll
    url = f"{live_server.url}/v1/plans/{job_id}/simulation"
    push = {"pushes": [{"time": 0.8, "vector": [0.003, 0.0, 0.0]}]}
    with DexrollClient.from_url(live_server.url) as client:
        report = client.simulate(job_id, disturbances=push, closed_loop={"rate": 4.0})
    assert report.open_loop is not None and report.closed_loop is not None
    opened, closed = report.open_loop.summary, report.closed_loop.summary
    assert closed.goal_position_mm < opened.goal_position_mm
    assert not closed.contact_lost_after_kicks
    assert report.disturbances["pushes"][0]["vector"] == [0.003, 0.0, 0.0]
    control = report.closed_loop.control
    assert control.statuses.get("replanned", 0) >= 1 and "unexplained" not in control.statuses
    assert control.calls == len(report.closed_loop.events)
    # the report is the closed loop's: its final error is its summary's
    assert report.position_error.final * 1e3 == pytest.approx(closed.position_final_mm)
    for body, field in (({"disturbances": {"pushes": [{"time": 9.0, "vector": [0, 0, 0]}]}},
                         "disturbances.pushes[0].time"),
                        ({"closed_loop": {"rate": 0}}, "closed_loop.rate"),
                        ({"closed_loop": {"backend": "rti"}}, "closed_loop.backend"),
                        ({"closed_loop": {"controller": "window", "backend": "acados"}},
                         "closed_loop.backend"),
                        ({"disturbances": {"friction_scale": -1}},
                         "disturbances.friction_scale"),
                        ({"disturbances": {"mass_scale": 1e-300}},
                         "disturbances.mass_scale"),
                        ({"closed_loop": {}, "mode": "kinematic"}, "mode")):
        r = httpx.post(url, json=body, timeout=120)
        assert r.status_code == 422, (body, r.text)
        assert r.json()["detail"][0]["field"] == field, r.text


def test_the_window_controller_by_real_time_iterations_through_the_service(
        live_server: Server, roll: tuple[str, dict[str, Any]]) -> None:
    """The simulation door's closed loop with the window controller on the RTI backend
    (``closed_loop.backend``, 100 Hz, latency charged) against the same 3 mm push: it ends
    nearer the goal than the same world open loop, every tick's window was solved, and
    the windows were checked by the certificate after the run."""
    job_id, _ = roll
    push = {"pushes": [{"time": 0.8, "vector": [0.003, 0.0, 0.0]}]}
    with DexrollClient.from_url(live_server.url) as client:
        report = client.simulate(job_id, disturbances=push, closed_loop={
            "controller": "window", "rate": 100.0, "max_iter": 1, "backend": "rti"})
    assert report.open_loop is not None and report.closed_loop is not None
    opened, closed = report.open_loop.summary, report.closed_loop.summary
    assert closed.goal_position_mm < opened.goal_position_mm
    control = report.closed_loop.control
    assert control.calls >= 10 and "failed" not in control.statuses
    assert all(e.message.startswith("hpipm") for e in report.closed_loop.events
               if e.status in ("tracked", "converged"))
    cert = report.closed_loop.model_dump().get("certificates") or {}
    assert cert.get("checked", 0) >= 10


def test_a_controller_session_answers_each_tick_with_the_next_window(
        live_server: Server, roll: tuple[str, dict[str, Any]]) -> None:
    """``WebSocket /v1/plans/{id}/control`` on a real service: the client's controller
    object sends the plan's own states every 10 ms of plan time for 0.3 s; each answer
    is a window from the measured instant (its first joints the measured ones, within
    the estimate's projection), tracked within the one-iteration budget, nearly
    feasible; the service's own share of a tick (the round trip less the process's
    wall time) is measured. A measurement with two fingers for the plan's one is
    answered with an error naming ``q`` and the session goes on; an unknown job's
    session is refused before the handshake."""
    from dexroll_client.control import ControlError

    job_id, result = roll
    with DexrollClient.from_url(live_server.url) as client, \
            client.controller(job_id) as ctl:
        answers = []
        tr = result["trajectory"]
        for t in np.arange(0.5, 0.8, 0.01):
            body = measured(result, float(t))
            a = ctl.tick(body["t"], body["q"], body["object_position"], body["object_wxyz"])
            answers.append((body, a))
        with pytest.raises(ControlError) as err:
            ctl.tick(0.9, [tr["q"][0], tr["q"][0]], [0.0, 0.0, 0.03], [1.0, 0.0, 0.0, 0.0])
        assert err.value.error == "invalid_request"
        assert [f for f, _ in err.value.detail] == ["q"]
        body = measured(result, 1.0)
        assert ctl.tick(body["t"], body["q"], body["object_position"],
                        body["object_wxyz"]).status in ("tracked", "converged")
        overhead = [rt - a.wall_time for rt, (_, a) in zip(ctl.round_trips, answers,
                                                            strict=False)]
    assert answers[0][1].setup_time > 0 and all(a.setup_time == 0 for _, a in answers[1:])
    for body, a in answers:
        assert a.status in ("tracked", "converged") and a.iterations == 1
        assert a.t == body["t"] and a.window is not None
        assert a.window.t[0] == 0.0 and a.window.t[-1] == pytest.approx(0.5)
        np.testing.assert_allclose(a.window.q[0][0], body["q"][0], atol=1e-6)
        assert a.primal_infeasibility is not None and a.primal_infeasibility < 1e-3
        assert a.wall_time >= a.solve_time + a.estimate_time > 0
    assert all(o > 0 for o in overhead[1:])
    with DexrollClient.from_url(live_server.url) as client, \
            pytest.raises(ControlError) as refused:
        client.controller("no-such-job")
    assert refused.value.error == "rejected"


def test_a_controller_session_on_real_time_iterations(
        live_server: Server, roll: tuple[str, dict[str, Any]]) -> None:
    """``?backend=rti``: the same session's ticks solved by the RTI backend (each window
    starts at the measured joints, an HPIPM QP a tick, nearly feasible); an unknown
    backend is refused before the handshake, naming it."""
    from dexroll_client.control import ControlError

    job_id, result = roll
    with DexrollClient.from_url(live_server.url) as client:
        with client.controller(job_id, backend="rti") as ctl:
            for t in np.arange(0.5, 0.6, 0.01):
                body = measured(result, float(t))
                a = ctl.tick(body["t"], body["q"], body["object_position"],
                             body["object_wxyz"])
                assert a.status in ("tracked", "converged"), a
                assert a.window is not None
                np.testing.assert_allclose(a.window.q[0][0], body["q"][0], atol=1e-6)
                assert a.primal_infeasibility is not None and a.primal_infeasibility < 1e-3
        with pytest.raises(ValueError, match="backend"):  # refused here first
            client.controller(job_id, backend="acados")
    # ... and by the service before the handshake (1008, the reason naming it)
    ws_url = live_server.url.replace("http", "ws", 1)
    with pytest.raises(ControlError) as refused:
        from dexroll_client.control import ControlSession

        ControlSession(f"{ws_url}/v1/plans/{job_id}/control?backend=acados", {}, 30.0)
    assert refused.value.error == "rejected" and "backend" in str(refused.value)
