"""The Python client (dexroll_client): unit tests on mock transports, then live tests.

Tests named ``*_live_*`` talk to a real service (the ``live_server`` fixture: uvicorn and
two solver workers); the others need no server (``httpx.MockTransport``), so
``pytest tests/test_client.py -k "not live"`` runs without one.
"""

from __future__ import annotations

import asyncio
import json
import subprocess
import sys
import time
import uuid
from collections.abc import Callable, Iterator
from datetime import UTC, datetime, timedelta
from email.utils import format_datetime
from pathlib import Path
from typing import Any

import httpx
import pytest
from pydantic import ValidationError

from dexroll_client import (
    APIError,
    AsyncDexrollClient,
    BallOnPalmRequest,
    ConflictError,
    DexrollClient,
    DexrollError,
    InvalidRequestError,
    JobState,
    NotFoundError,
    PlanStatus,
    PlanTimeoutError,
    RequestTooLargeError,
    ServiceUnavailableError,
    TransportError,
)
from dexroll_client.errors import parse_retry_after

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
BASE = "http://dexroll.test"


def triangle() -> dict[str, Any]:
    data: dict[str, Any] = json.loads((EXAMPLES / "triangle.json").read_text())
    return data


# -- mock service helpers -----------------------------------------------------------------------

def job_json(job_id: str, state: str, *, result: bool = False) -> dict[str, Any]:
    body: dict[str, Any] = {"id": job_id, "state": state, "planner": "ball_on_palm",
                            "created_at": "2024-01-01T00:00:00Z"}
    if result:
        body["result"] = {"status": "solved", "message": "solved and certified"}
    return body


def error_json(error: str, message: str, detail: list[dict[str, str]] | None = None
               ) -> dict[str, Any]:
    return {"error": error, "message": message, "detail": detail or []}


Handler = Callable[[httpx.Request], httpx.Response]


def mock_client(handler: Handler) -> tuple[DexrollClient, list[float]]:
    """A client on a mock transport, whose sleeps are recorded instead of slept."""
    client = DexrollClient(httpx.Client(base_url=BASE, transport=httpx.MockTransport(handler)))
    sleeps: list[float] = []
    client._sleep = sleeps.append
    return client, sleeps


class Recorder:
    """A scripted service: answers each request with the next scripted response."""

    def __init__(self, *responses: httpx.Response) -> None:
        self.responses = list(responses)
        self.requests: list[httpx.Request] = []

    def __call__(self, request: httpx.Request) -> httpx.Response:
        self.requests.append(request)
        if not self.responses:
            raise AssertionError(f"unexpected request {request.method} {request.url}")
        return self.responses.pop(0)


def queue_full_then_done() -> Recorder:
    """503 (Retry-After 2), then 202 (Retry-After 1), then a running GET, then finished."""
    return Recorder(
        httpx.Response(503, json=error_json("queue_full", "64 jobs are already queued"),
                       headers={"Retry-After": "2"}),
        httpx.Response(202, json=job_json("j1", "queued"),
                       headers={"Location": "/v1/plans/j1", "Retry-After": "1"}),
        # a Retry-After on a 200 has no standard meaning: the backoff applies
        httpx.Response(200, json=job_json("j1", "running"), headers={"Retry-After": "9"}),
        httpx.Response(200, json=job_json("j1", "succeeded", result=True)),
    )


def check_queue_full_then_done(service: Recorder, sleeps: list[float], job: Any) -> None:
    assert job.id == "j1" and job.state is JobState.SUCCEEDED
    assert job.result is not None and job.result.status is PlanStatus.SOLVED
    methods = [(r.method, r.url.path) for r in service.requests]
    assert methods == [("POST", "/v1/plans"), ("POST", "/v1/plans"),
                       ("GET", "/v1/plans/j1"), ("GET", "/v1/plans/j1")]
    keys = [r.headers.get("Idempotency-Key") for r in service.requests[:2]]
    assert keys[0] and keys[0] == keys[1]
    uuid.UUID(keys[0])  # generated: a uuid4
    # the 503's Retry-After (with up to 25 % jitter: clients turned away together do not
    # come back together), then the 202's Retry-After, then backoff (0.1 doubled)
    assert 2.0 <= sleeps[0] <= 2.5 and sleeps[1:] == [1.0, 0.2], sleeps
    assert json.loads(service.requests[1].content)["duration"] == 6.0


# -- unit tests (mock transports, no server) ----------------------------------------------------

def test_plan_retries_a_full_queue_with_the_same_key_then_polls() -> None:
    service = queue_full_then_done()
    client, sleeps = mock_client(service)
    job = client.plan(triangle(), timeout=60)
    check_queue_full_then_done(service, sleeps, job)


def test_async_plan_retries_a_full_queue_with_the_same_key_then_polls() -> None:
    service = queue_full_then_done()
    sleeps: list[float] = []

    async def record(seconds: float) -> None:
        sleeps.append(seconds)

    async def main() -> Any:
        http = httpx.AsyncClient(base_url=BASE, transport=httpx.MockTransport(service))
        async with AsyncDexrollClient(http) as client:
            client._sleep = record
            job = await client.plan(triangle(), timeout=60)
        assert not http.is_closed  # injected: its owner closes it
        await http.aclose()
        return job

    check_queue_full_then_done(service, sleeps, asyncio.run(main()))


def test_plan_keeps_the_callers_idempotency_key_and_polls_with_capped_backoff() -> None:
    running = httpx.Response(200, json=job_json("j2", "running"))
    service = Recorder(httpx.Response(202, json=job_json("j2", "queued")),
                       *[running] * 4,
                       httpx.Response(503, json=error_json("busy", "restarting"),
                                      headers={"Retry-After": "3"}),
                       running,
                       httpx.Response(200, json=job_json("j2", "infeasible", result=True)))
    client, sleeps = mock_client(service)
    job = client.plan(BallOnPalmRequest.model_validate(triangle()), idempotency_key="k-1",
                      poll_initial=0.5, poll_max=2.0)
    assert job.state is JobState.INFEASIBLE  # any terminal state is returned, not raised
    assert service.requests[0].headers["Idempotency-Key"] == "k-1"
    assert service.requests[0].url.params["wait"] == "30"  # no timeout: the longest wait
    # backoff 0.5 doubled up to 2; a 503 while polling: its Retry-After
    assert sleeps == [0.5, 1.0, 2.0, 2.0, 2.0, 3.0, 2.0]
    with pytest.raises(ValueError, match="idempotency_key"):
        client.submit(triangle(), idempotency_key="clé")


def test_plan_returns_at_once_when_the_post_finishes() -> None:
    service = Recorder(httpx.Response(201, json=job_json("j3", "succeeded", result=True)))
    client, sleeps = mock_client(service)
    job = client.plan(triangle(), timeout=5.0)
    assert job.state is JobState.SUCCEEDED and sleeps == [] and len(service.requests) == 1
    assert float(service.requests[0].url.params["wait"]) <= 5.0


def test_plan_times_out_with_the_job_id_when_the_job_never_finishes() -> None:
    def service(request: httpx.Request) -> httpx.Response:
        if request.method == "POST":
            return httpx.Response(202, json=job_json("slow", "queued"))
        return httpx.Response(200, json=job_json("slow", "running"))

    client = DexrollClient(httpx.Client(base_url=BASE, transport=httpx.MockTransport(service)))
    with pytest.raises(PlanTimeoutError) as info:  # real sleeps, tiny timeouts
        client.plan(triangle(), timeout=0.2, poll_initial=0.01, poll_max=0.05)
    assert info.value.job_id == "slow" and info.value.timeout == 0.2
    assert info.value.job is not None and info.value.job.state is JobState.RUNNING
    assert isinstance(info.value, DexrollError) and "slow" in str(info.value)


def test_plan_gives_up_when_the_queue_stays_full_past_the_timeout() -> None:
    service = Recorder(httpx.Response(503, json=error_json("queue_full", "full"),
                                      headers={"Retry-After": "60"}))
    client, sleeps = mock_client(service)
    with pytest.raises(PlanTimeoutError) as info:
        client.plan(triangle(), timeout=5)
    assert info.value.job_id is None and sleeps == []  # no point waiting 60 s for 5
    assert isinstance(info.value.__cause__, ServiceUnavailableError)


def test_submit_maps_503_to_service_unavailable_with_retry_after() -> None:
    when = format_datetime(datetime.now(UTC) + timedelta(seconds=120), usegmt=True)
    for header, expected in [("7", 7.0), (when, 120.0), ("soon", None)]:
        service = Recorder(httpx.Response(503, json=error_json("queue_full", "full"),
                                          headers={"Retry-After": header}))
        client, _ = mock_client(service)
        with pytest.raises(ServiceUnavailableError) as info:
            client.submit(triangle(), wait=0)
        assert info.value.status_code == 503 and info.value.error == "queue_full"
        if expected is None:
            assert info.value.retry_after is None
        else:
            assert info.value.retry_after == pytest.approx(expected, abs=2.0)
        assert service.requests[0].url.params["wait"] == "0"
    assert parse_retry_after("-3") == 0.0 and parse_retry_after(None) is None


@pytest.mark.parametrize(("status", "cls"), [
    (404, NotFoundError), (409, ConflictError), (413, RequestTooLargeError),
    (422, InvalidRequestError), (503, ServiceUnavailableError), (400, APIError),
    (500, APIError)])
def test_error_bodies_map_to_the_exception_tree(status: int, cls: type[APIError]) -> None:
    detail = [{"field": "goal.u", "reason": "beyond the pole limit"}]
    service = Recorder(httpx.Response(status, json=error_json("some_code", "told", detail)))
    client, _ = mock_client(service)
    with pytest.raises(cls) as info:
        client.get("abc")
    err = info.value
    assert type(err) is cls and isinstance(err, DexrollError)
    assert (err.status_code, err.error, err.message) == (status, "some_code", "told")
    assert err.fields() == ["goal.u"] and err.body is not None
    assert "goal.u: beyond the pole limit" in str(err)


def test_non_json_error_body_is_still_an_api_error() -> None:
    html = "<html><body><h1>502 Bad Gateway</h1>\n<p>nginx</p></body></html>"
    for status, body in [(500, "Internal Server Error"), (502, html), (500, "")]:
        service = Recorder(httpx.Response(status, text=body,
                                          headers={"Content-Type": "text/html"}))
        client, _ = mock_client(service)
        with pytest.raises(APIError) as info:
            client.list()
        err = info.value
        assert type(err) is APIError and err.status_code == status
        assert err.error == f"http_{status}" and err.body is None and err.detail == []
        assert (body.split("<h1>")[-1][:15] if body else "empty body") in err.message


def test_a_malformed_success_body_is_an_api_error() -> None:
    service = Recorder(httpx.Response(200, json={"id": "x"}))
    client, _ = mock_client(service)
    with pytest.raises(APIError, match="not a valid Job") as info:
        client.get("x")
    assert info.value.error == "invalid_response"


def test_connect_error_is_wrapped_in_transport_error() -> None:
    def refuse(request: httpx.Request) -> httpx.Response:
        raise httpx.ConnectError("connection refused", request=request)

    client, _ = mock_client(refuse)
    for call in (client.health, client.models, lambda: client.plan(triangle(), timeout=1)):
        with pytest.raises(TransportError) as info:
            call()
        assert isinstance(info.value.cause, httpx.ConnectError)
        assert info.value.__cause__ is info.value.cause
        assert info.value.request is not None and "connection refused" in str(info.value)


def test_bad_dict_fails_locally_before_any_http() -> None:
    service = Recorder()  # any request would fail the test
    client, _ = mock_client(service)
    bad = {**triangle(), "bogus_field": 1}
    for call in (client.submit, client.plan):
        with pytest.raises(ValidationError, match="bogus_field"):
            call(bad)
    with pytest.raises(ValidationError, match="duration"):
        client.submit({"initial": {"x": 0, "y": 0, "u": 0, "v": 0, "psi": 0}})
    assert service.requests == []


def test_requests_paths_and_parameters() -> None:
    service = Recorder(
        httpx.Response(200, json={"items": [], "total": 0, "limit": 5, "offset": 10,
                                  "next_offset": None}),
        httpx.Response(200, json=job_json("a/b", "cancelled")),
        httpx.Response(200, json={"status": "ok"}),
        httpx.Response(503, json=error_json("not_ready", "no worker yet")),
        httpx.Response(202, json=job_json("j", "queued")),
    )
    client, _ = mock_client(service)
    assert client.list(limit=5, offset=10).next_offset is None
    assert client.cancel("a/b").state is JobState.CANCELLED
    assert client.health() is True and client.ready() is False
    client.submit(triangle(), wait=2.5, idempotency_key="key")
    r = service.requests
    assert (r[0].method, r[0].url.path, dict(r[0].url.params)) == (
        "GET", "/v1/plans", {"limit": "5", "offset": "10"})
    assert (r[1].method, r[1].url.raw_path) == ("DELETE", b"/v1/plans/a%2Fb")
    assert r[1].extensions["timeout"]["read"] >= 10.0  # the service waits for the worker
    assert [q.url.path for q in r[2:4]] == ["/healthz", "/readyz"]
    assert r[4].url.params["wait"] == "2.5" and r[4].headers["Idempotency-Key"] == "key"
    # the read timeout covers the server-side wait
    assert r[4].extensions["timeout"]["read"] >= 2.5
    with pytest.raises(ValueError, match="job_id"):
        client.get("")


def test_context_manager_closes_only_a_client_it_created() -> None:
    injected = httpx.Client(base_url=BASE, transport=httpx.MockTransport(Recorder()))
    with DexrollClient(injected) as client:
        assert client.http is injected
    assert not injected.is_closed
    injected.close()
    with DexrollClient.from_url(BASE, timeout=3.0) as owned:
        assert owned.http.timeout.read == 3.0 and str(owned.http.base_url) == BASE
    assert owned.http.is_closed
    with pytest.raises(ValueError, match="base_url"):
        DexrollClient(httpx.Client())


def test_async_context_manager_closes_only_a_client_it_created() -> None:
    async def main() -> None:
        async with AsyncDexrollClient.from_url(BASE) as owned:
            pass
        assert owned.http.is_closed
        injected = httpx.AsyncClient(base_url=BASE)
        async with AsyncDexrollClient(injected):
            pass
        assert not injected.is_closed
        await injected.aclose()

    asyncio.run(main())


def test_the_client_package_loads_no_service_or_solver_module() -> None:
    code = ("import sys, dexroll_client, dexroll_client.client, dexroll_client.errors;"
            "bad = [m for m in sys.modules if m.split('.')[0] in ('planner_service', 'ocp', "
            "'casadi', 'fastapi', 'numpy', 'uvicorn', 'pinocchio')]; print(bad);"
            "sys.exit(bool(bad))")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=False)
    assert proc.returncode == 0, proc.stdout + proc.stderr


# -- live tests (a real service: uvicorn + 2 solver workers) ------------------------------------

@pytest.fixture
def client(live_server: Any) -> Iterator[DexrollClient]:
    with DexrollClient.from_url(live_server.url, timeout=30.0) as c:
        yield c


def quick_request() -> dict[str, Any]:
    """A small plan that solves in well under a second."""
    return {"initial": {"x": 0.0, "y": 0.0, "u": 0.0, "v": 0.0, "psi": 0.0},
            "goal": {"x": 0.02}, "duration": 1.0, "n_intervals": 10}


def test_live_plan_triangle_end_to_end(client: DexrollClient) -> None:
    assert client.health() and client.ready()
    request = triangle()
    job = client.plan(request, timeout=120)
    assert job.state is JobState.SUCCEEDED, job
    result = job.result
    assert result is not None and result.status is PlanStatus.SOLVED, result
    assert result.certificate is not None and result.certificate.passed, result.certificate
    assert result.grid is not None
    x, y = result.grid.eta[-1][:2]
    assert (x, y) == (pytest.approx(request["goal"]["x"], abs=1e-6),
                      pytest.approx(request["goal"]["y"], abs=1e-6))
    assert result.grid.t[-1] == pytest.approx(request["duration"])


def test_live_idempotent_submit_returns_the_same_job(client: DexrollClient) -> None:
    key = f"test-{uuid.uuid4()}"
    first = client.submit(quick_request(), wait=0, idempotency_key=key)
    second = client.submit(quick_request(), wait=0, idempotency_key=key)
    assert first.id == second.id
    other = client.submit(quick_request(), wait=0)
    assert other.id != first.id
    with pytest.raises(ConflictError) as info:  # same key, another body
        client.submit({**quick_request(), "duration": 2.0}, idempotency_key=key)
    assert info.value.status_code == 409
    assert client.plan(quick_request(), idempotency_key=key, timeout=60).id == first.id


def test_live_cancel_a_running_plan(client: DexrollClient) -> None:
    slow = {**triangle(), "n_intervals": 2000, "max_refinements": 0}
    job = client.submit(slow, wait=0)
    deadline = time.monotonic() + 60.0
    while job.state is JobState.QUEUED and time.monotonic() < deadline:  # until a worker
        time.sleep(0.05)                                                  # has it
        job = client.get(job.id)
    assert job.state is JobState.RUNNING, job
    cancelled = client.cancel(job.id)
    assert cancelled.id == job.id and cancelled.state is JobState.CANCELLED, cancelled
    assert client.get(job.id).state is JobState.CANCELLED
    with pytest.raises(ConflictError) as info:
        client.cancel(job.id)
    assert info.value.error == "already_finished"


def test_live_list_and_get(client: DexrollClient) -> None:
    job = client.plan(quick_request(), timeout=60)
    assert job.state.terminal and job.result is not None
    page = client.list(limit=500)
    assert job.id in [j.id for j in page.items]
    assert all(j.result is None for j in page.items)
    assert page.total >= len(page.items) >= 1 and page.limit == 500 and page.offset == 0
    first = client.list(limit=1)
    assert len(first.items) == 1 and first.total == page.total
    assert (first.next_offset == 1) == (page.total > 1)
    got = client.get(job.id)
    assert got.id == job.id and got.state is job.state and got.result == job.result


def test_live_models(client: DexrollClient) -> None:
    catalog = client.models()
    assert "ball_on_palm" in catalog.planners
    shapes = {o.shape: o for o in catalog.objects}
    assert "sphere" in shapes and shapes["sphere"].parameters


def test_live_errors(client: DexrollClient) -> None:
    with pytest.raises(NotFoundError) as missing:
        client.get("no-such-job")
    assert missing.value.status_code == 404 and missing.value.body is not None
    with pytest.raises(NotFoundError):
        client.cancel("no-such-job")
    with pytest.raises(ValidationError, match="bogus"):  # locally, before any HTTP
        client.submit({**quick_request(), "bogus": True})
    beyond_pole = {**quick_request(), "goal": {"u": 1.55}}  # valid for pydantic
    BallOnPalmRequest.model_validate(beyond_pole)
    with pytest.raises(InvalidRequestError) as invalid:
        client.plan(beyond_pole, timeout=30)
    assert invalid.value.status_code == 422
    assert "goal.u" in invalid.value.fields(), invalid.value


def test_live_async_plan_end_to_end(live_server: Any) -> None:
    async def main() -> Any:
        async with AsyncDexrollClient.from_url(live_server.url) as client:
            assert await client.health() and await client.ready()
            jobs = await asyncio.gather(client.plan(triangle(), timeout=120),
                                        client.plan(quick_request(), timeout=120))
            listed = await client.list(limit=500)
            assert {j.id for j in jobs} <= {j.id for j in listed.items}
            assert (await client.get(jobs[0].id)).id == jobs[0].id
            assert "ball_on_palm" in (await client.models()).planners
            with pytest.raises(NotFoundError):
                await client.get("no-such-job")
            return jobs

    big, small = asyncio.run(main())
    assert big.state is JobState.SUCCEEDED and small.state is JobState.SUCCEEDED
    assert big.result is not None and big.result.status is PlanStatus.SOLVED
    assert big.result.certificate is not None and big.result.certificate.passed

