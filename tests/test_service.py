"""The planning service, through real uvicorn servers on loopback ports (see conftest)."""

from __future__ import annotations

import json
import os
import signal
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import httpx
import pytest
from conftest import Server

from planner_service.api.app import create_app
from planner_service.jobs.store import Store
from planner_service.settings import Settings

ROOT = Path(__file__).resolve().parents[1]
TRIANGLE: dict[str, Any] = json.loads((ROOT / "examples" / "triangle.json").read_text())
#: A request whose NLP takes seconds to build (thousands of intervals): a job that is
#: still running when the test acts on it.
SLOW: dict[str, Any] = {**TRIANGLE, "n_intervals": 1800, "max_refinements": 0}


def post(server: Server, body: Any, wait: float = 30.0, **headers: str) -> httpx.Response:
    content = body if isinstance(body, (str, bytes)) else json.dumps(body)
    return httpx.post(f"{server.url}/v1/plans", params={"wait": wait}, content=content,
                      headers={"content-type": "application/json", **headers}, timeout=60)


def get_job(server: Server, job_id: str) -> dict[str, Any]:
    r = httpx.get(f"{server.url}/v1/plans/{job_id}", timeout=10)
    assert r.status_code == 200, r.text
    body: dict[str, Any] = r.json()
    return body


def wait_until(server: Server, job_id: str, predicate: Callable[[dict[str, Any]], bool],
               timeout: float = 90.0) -> dict[str, Any]:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        job = get_job(server, job_id)
        if predicate(job):
            return job
        time.sleep(0.05)
    raise AssertionError(f"job {job_id} never satisfied the condition: {job}")


def terminal(job: dict[str, Any]) -> bool:
    return job["state"] not in ("queued", "running")


def assert_certified_triangle(job: dict[str, Any]) -> None:
    assert job["state"] == "succeeded", job["message"]
    result = job["result"]
    assert result["status"] == "solved" and result["certificate"]["passed"]
    final = result["grid"]["eta"][-1]
    assert abs(final[0]) < 1e-6 and abs(final[1]) < 1e-6  # back at the origin
    assert result["certificate"]["max_slip_speed"] <= result["certificate"]["tolerances"][
        "slip_speed"]


# -- the happy path --------------------------------------------------------------------------

def test_plan_end_to_end(live_server: Server) -> None:
    r = post(live_server, TRIANGLE)
    assert r.status_code == 201, r.text
    job = r.json()
    assert_certified_triangle(job)
    # the same job, fetched again, is unchanged
    assert get_job(live_server, job["id"])["result"] == job["result"]


def test_a_short_wait_answers_202_with_location_then_the_job_finishes(live_server: Server
                                                                      ) -> None:
    body = {**TRIANGLE, "duration": 6.5}  # a structure of its own: not instantly done
    r = post(live_server, body, wait=0.0)
    assert r.status_code in (201, 202)
    if r.status_code == 202:
        assert r.headers["location"] == f"/v1/plans/{r.json()['id']}"
        assert float(r.headers["retry-after"]) > 0
    job = wait_until(live_server, r.json()["id"], terminal)
    assert job["state"] == "succeeded"


@pytest.mark.parametrize("wait", ["nan", "inf", "-1", "601"])
def test_a_wait_that_is_no_number_of_seconds_is_refused_naming_it(live_server: Server,
                                                                  wait: str) -> None:
    """``?wait=`` must be a finite number of seconds in [0, 600]: NaN and infinity are
    refused as not finite (they were "less than or equal to 600"), before any job."""
    r = httpx.post(f"{live_server.url}/v1/plans", params={"wait": wait}, json=TRIANGLE,
                   timeout=30)
    assert r.status_code == 422, r.text
    text = r.text.lower()
    assert "wait" in text
    if wait in ("nan", "inf"):
        assert "finite" in text


def test_idempotency_key_gives_one_job(live_server: Server) -> None:
    key = f"test-{time.monotonic_ns()}"
    first = post(live_server, TRIANGLE, **{"Idempotency-Key": key})
    second = post(live_server, TRIANGLE, **{"Idempotency-Key": key})
    assert first.status_code == 201 and second.status_code == 201
    assert first.json()["id"] == second.json()["id"]
    other = post(live_server, {**TRIANGLE, "duration": 7.0}, **{"Idempotency-Key": key})
    assert other.status_code == 409
    assert other.json()["error"] == "idempotency_conflict"


def test_list_is_paginated(live_server: Server) -> None:
    post(live_server, TRIANGLE)
    post(live_server, TRIANGLE)
    r = httpx.get(f"{live_server.url}/v1/plans", params={"limit": 1})
    page = r.json()
    assert r.status_code == 200 and len(page["items"]) == 1 and page["total"] >= 2
    assert page["next_offset"] == 1 and page["items"][0]["result"] is None
    nxt = httpx.get(f"{live_server.url}/v1/plans", params={"limit": 1, "offset": 1}).json()
    assert nxt["items"][0]["id"] != page["items"][0]["id"]


def test_models_lists_objects_and_planners(live_server: Server) -> None:
    r = httpx.get(f"{live_server.url}/v1/models")
    assert r.status_code == 200
    body = r.json()
    assert "ball_on_palm" in body["planners"]
    assert {o["shape"] for o in body["objects"]} == {"sphere", "ellipsoid", "capsule",
                                                      "superellipsoid"}
    capsule = next(o for o in body["objects"] if o["shape"] == "capsule")
    assert capsule["parameters"] == ["radius", "half_length"]


def test_health_and_readiness(live_server: Server) -> None:
    assert httpx.get(f"{live_server.url}/healthz").json() == {"status": "ok"}
    ready = httpx.get(f"{live_server.url}/readyz")
    assert ready.status_code == 200 and ready.json()["workers"] == 2


# -- bad requests ----------------------------------------------------------------------------

@pytest.mark.parametrize(("body", "field"), [
    (json.dumps(TRIANGLE).replace('"duration": 6.0', '"duration": NaN'), "duration"),
    (json.dumps(TRIANGLE).replace('"duration": 6.0', '"duration": Infinity'), "duration"),
    ({**TRIANGLE, "colour": "red"}, "colour"),
    ({**TRIANGLE, "goal": {"x": 0.0, "w": 1.0}}, "goal.w"),
    ({**TRIANGLE, "object": {"shape": "sphere", "dimensions": [-0.025]}}, "object.dimensions.0"),
    ({**TRIANGLE, "goal": {"u": 1.55}}, "goal.u"),  # at the chart pole: the core names it
    ({**TRIANGLE, "via_points": [{"time": 9.0, "coords": {"x": 0.0}}]}, "via_points[0].time"),
    ("{not json", "body"),
])
def test_invalid_requests_get_422_naming_the_field(live_server: Server, body: Any, field: str
                                                   ) -> None:
    r = post(live_server, body, wait=0.0)
    assert r.status_code == 422, r.text
    err = r.json()
    assert err["error"] == "invalid_request"
    assert field in {d["field"] for d in err["detail"]}, err
    assert "Traceback" not in r.text


def test_oversized_body_gets_413(live_server: Server) -> None:
    body = {**TRIANGLE, "sample_times": [0.5] * 300_000}  # 1.5 MB of JSON
    r = post(live_server, body, wait=0.0)
    assert r.status_code == 413
    assert r.json()["error"] == "payload_too_large"
    chunked = httpx.post(f"{live_server.url}/v1/plans", timeout=30,
                         content=iter([b"[" + b"0," * 600_000, b"0]"]),
                         headers={"content-type": "application/json"})
    assert chunked.status_code == 413


def test_unknown_job_is_404_with_error_body(live_server: Server) -> None:
    for method in ("GET", "DELETE"):
        r = httpx.request(method, f"{live_server.url}/v1/plans/nope")
        assert r.status_code == 404 and r.json()["error"] == "not_found"


# -- jobs that end badly ---------------------------------------------------------------------

def test_cancel_a_running_plan(live_server: Server) -> None:
    job = post(live_server, SLOW, wait=0.0).json()
    wait_until(live_server, job["id"], lambda j: j["state"] == "running")
    r = httpx.delete(f"{live_server.url}/v1/plans/{job['id']}", timeout=30)
    assert r.status_code == 200 and r.json()["state"] == "cancelled"
    assert get_job(live_server, job["id"])["state"] == "cancelled"
    again = httpx.delete(f"{live_server.url}/v1/plans/{job['id']}", timeout=30)
    assert again.status_code == 409 and again.json()["error"] == "already_finished"
    # the service is healthy and plans again
    assert_certified_triangle(post(live_server, TRIANGLE).json())


def test_too_short_time_limit_times_out_and_service_stays_healthy(live_server: Server
                                                                  ) -> None:
    body = {**SLOW, "solver": {"time_limit": 0.2}}
    job = post(live_server, body, wait=0.0).json()
    job = wait_until(live_server, job["id"], terminal)
    assert job["state"] == "timed_out"
    assert job["code"] in ("time_limit", "killed_at_time_limit")
    assert httpx.get(f"{live_server.url}/healthz").status_code == 200
    assert_certified_triangle(post(live_server, TRIANGLE, wait=60).json())


def test_a_job_whose_worker_is_lost_is_queued_again_once_then_fails_with_reason(
        live_server: Server) -> None:
    """A worker killed under a job puts it back in the queue (DEXROLL_RETRIES=1); killed
    again, the job fails worker_died naming the process and how it died; the next job
    succeeds."""
    job = post(live_server, SLOW, wait=0.0).json()
    first = wait_until(live_server, job["id"],
                       lambda j: j["state"] == "running" and j["worker_pid"] is not None)
    os.kill(first["worker_pid"], signal.SIGKILL)
    second = wait_until(live_server, job["id"],
                        lambda j: j["state"] == "running" and j["worker_pid"] is not None
                        and j["worker_pid"] != first["worker_pid"])
    os.kill(second["worker_pid"], signal.SIGKILL)
    job = wait_until(live_server, job["id"], terminal)
    assert job["state"] == "failed" and job["code"] == "worker_died"
    assert str(second["worker_pid"]) in job["message"] and "exit code -9" in job["message"]
    assert "attempt 2" in job["message"]
    assert_certified_triangle(post(live_server, TRIANGLE, wait=60).json())


def test_restart_keeps_finished_jobs_and_runs_queued_ones(
        server_factory: Callable[..., Server], tmp_path: Path) -> None:
    """... and (on the first service: one worker, a queue of one) a full queue answers 503
    (one service start fewer than a test each: suite time)."""
    data = tmp_path / "kept"
    first = server_factory(data, DEXROLL_WORKERS="1", DEXROLL_MAX_QUEUE="1")
    done = post(first, TRIANGLE).json()
    assert_certified_triangle(done)
    full_queue_answers_503_with_retry_after(first)
    first.stop()
    # a job left queued in the store while the service was down
    store = Store(Settings(data_dir=data).db_path)
    queued, _ = store.create("ball_on_palm", json.dumps(TRIANGLE), 60.0, None)
    store.close()
    second = server_factory(data)
    assert get_job(second, done["id"])["result"] == done["result"]
    assert_certified_triangle(wait_until(second, queued.id, terminal))


def full_queue_answers_503_with_retry_after(server: Server) -> None:
    """On a service of one worker and a queue of one."""
    running = post(server, SLOW, wait=0.0).json()
    wait_until(server, running["id"], lambda j: j["state"] == "running")
    queued = post(server, {**SLOW, "duration": 6.1}, wait=0.0)
    assert queued.status_code == 202
    full = post(server, {**SLOW, "duration": 6.2}, wait=0.0)
    assert full.status_code == 503 and full.json()["error"] == "queue_full"
    assert float(full.headers["retry-after"]) > 0
    # cancelling the queued job frees the queue, and it never ran
    cancelled = httpx.delete(f"{server.url}/v1/plans/{queued.json()['id']}").json()
    assert cancelled["state"] == "cancelled" and cancelled["started_at"] is None
    # the running one too (else the restarted service would run it again)
    stopped = httpx.delete(f"{server.url}/v1/plans/{running['id']}", timeout=30).json()
    assert stopped["state"] == "cancelled"


# -- the contract ----------------------------------------------------------------------------

def test_committed_openapi_matches_the_app() -> None:
    committed = json.loads((ROOT / "openapi.json").read_text())
    assert committed == create_app(Settings()).openapi(), (
        "the API changed: regenerate with `dexroll openapi > openapi.json`")
