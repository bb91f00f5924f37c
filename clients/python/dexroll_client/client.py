"""Synchronous and asynchronous clients of the dexroll planning service.

Both clients wrap an injected httpx client (``httpx.Client`` / ``httpx.AsyncClient``, with
``base_url`` set) or create their own with ``from_url``::

    with DexrollClient.from_url("http://127.0.0.1:8000") as client:
        job = client.plan(request, timeout=120)          # submit, then wait until finished

    async with AsyncDexrollClient.from_url("http://127.0.0.1:8000") as client:
        job = await client.plan(request, timeout=120)

A context manager (and ``close()``) closes only an httpx client the dexroll client created
itself; an injected one stays open, its owner closes it.

Requests may be a :class:`~dexroll_client.models.PlanRequest` or a plain dict; a dict is
validated with the model first, so a bad request fails locally (pydantic's
``ValidationError`` names the field) before any HTTP.

Warm starts: ``plan(request, warm_start=previous)`` (and ``submit``) start IPOPT from a
previous plan: ``previous`` is a result (its ``collocation`` block is sent), a ``Job`` of
this service or its id (the service looks the job up), a ``CollocationModel`` or a
``WarmStartModel``::

    first = client.plan(request, timeout=120)
    again = client.plan(slightly_different_request, warm_start=first.result, timeout=120)

Errors (see :mod:`dexroll_client.errors`)::

    DexrollError
     ├── TransportError            no HTTP response, after the retries (wraps the httpx
     │                             exception)
     ├── PlanTimeoutError          plan() gave up waiting (.job_id if a job was created)
     └── APIError                  4xx/5xx: .status_code, .error, .message, .detail, .body
          ├── InvalidRequestError  (422)
          ├── RequestTooLargeError (413)
          ├── UnauthorizedError    (401)
          ├── NotFoundError        (404)
          ├── ConflictError        (409)
          └── ServiceUnavailableError (503; .retry_after)

Retries: a request that got no response (connection refused or reset, the server closing
a kept-alive connection as the request went out, a timeout) is sent again, up to
``retries`` times with exponential backoff and full jitter, when sending it twice is safe:
GET, DELETE, and a POST with an ``Idempotency-Key`` (``plan()`` always sends one; give
``idempotency_key`` to ``submit`` for the same). A 503 is retried by ``plan()`` after its
``Retry-After`` (with jitter). ``api_key``: sent as ``Authorization: Bearer <key>`` to a
service with API keys.

Design: every operation is written once, as a generator that yields what to do (send an HTTP
request, sleep) and decodes the responses it is sent back (sans-I/O). The sync client runs
these generators with ``httpx.Client`` and ``time.sleep``, the async one with
``httpx.AsyncClient`` and ``asyncio.sleep``; neither holds any protocol logic of its own.
"""

from __future__ import annotations

import asyncio
import builtins
import math
import random
import time
import uuid
from collections.abc import (
    AsyncIterator,
    Awaitable,
    Callable,
    Generator,
    Iterable,
    Iterator,
    Mapping,
)
from dataclasses import dataclass, field
from types import TracebackType
from typing import Any, Self, TypeVar
from urllib.parse import quote

import httpx
from pydantic import BaseModel, TypeAdapter, ValidationError

from dexroll_client.control import ControlSession
from dexroll_client.errors import (
    APIError,
    PlanTimeoutError,
    TransportError,
    error_from_response,
    parse_retry_after,
)
from dexroll_client.models import (
    Batch,
    BatchRequest,
    CollocationModel,
    FingerPlanResult,
    Job,
    JobList,
    ManipulationResult,
    ModelCatalog,
    PlanRequest,
    PlanResult,
    WarmStartModel,
)
from dexroll_client.replan import ReplanRequest, ReplanResult
from dexroll_client.simulation import SimulationOptions, SimulationReport

__all__ = ["DEFAULT_TIMEOUT", "MAX_WAIT", "RETRIES", "AsyncDexrollClient", "DexrollClient",
           "RequestLike", "WarmStartLike", "warm_start_model"]

#: The service's cap on ``POST /v1/plans?wait=`` [s].
MAX_WAIT = 30.0
#: Default httpx timeout of clients made by ``from_url`` [s].
DEFAULT_TIMEOUT = 30.0
#: Extra read time granted to a request beyond the ``wait`` it asks the service for [s].
_WAIT_MARGIN = 10.0
#: Read time granted to a cancel: the service waits (up to 10 s) for the worker to stop [s].
_CANCEL_READ_TIMEOUT = 20.0
#: A plan's execution in MuJoCo runs while the request waits [s].
_SIMULATE_READ_TIMEOUT = 300.0
#: A plan's first re-plan builds its re-planner (the service's DEXROLL_REPLAN_SETUP_LIMIT)
#: while the request waits [s].
_REPLAN_READ_TIMEOUT = 330.0

#: Retries of a request that got no response and is safe to send again (see the module),
#: and the first backoff [s] (doubled each retry; the pause is drawn in [0, backoff]).
RETRIES = 3
RETRY_BACKOFF = 0.25

#: A plan request: the model, or a dict of the same shape (validated before sending).
RequestLike = PlanRequest | Mapping[str, Any]
#: A previous plan to warm-start from: a result (its ``collocation`` block), a job of this
#: service or its id (looked up by the service), a collocation block, a ``WarmStartModel``,
#: or a dict of a ``WarmStartModel``'s shape (e.g. a result's ``collocation`` as JSON).
WarmStartLike = (WarmStartModel | CollocationModel | PlanResult | FingerPlanResult
                 | ManipulationResult | Job | str | Mapping[str, Any])

_M = TypeVar("_M", bound=BaseModel)
_T = TypeVar("_T")

_REQUEST = TypeAdapter(PlanRequest)


# -- sans-I/O core: what to send, how to read the answer --------------------------------------

@dataclass(frozen=True)
class _Call:
    """One HTTP request to make (relative to the httpx client's ``base_url``)."""

    method: str
    path: str
    params: dict[str, str | int] = field(default_factory=dict)
    headers: dict[str, str] = field(default_factory=dict)
    json: Any = None
    #: The response may take this long to start (server-side long poll) [s].
    min_read_timeout: float | None = None


@dataclass(frozen=True)
class _Sleep:
    seconds: float


#: An operation: yields calls (answered with their response) and sleeps (answered with
#: None); returns the operation's result.
_Op = Generator[_Call | _Sleep, httpx.Response | None, _T]


def warm_start_model(previous: WarmStartLike, planner: str | None = None) -> WarmStartModel:
    """The ``warm_start`` of a request from a previous plan (see :data:`WarmStartLike`).

    A result or a job of another planner than ``planner`` (when given) raises ValueError,
    as does a result without a ``collocation`` block (no plan, a greedy plan, a diverged
    last iterate); a job is passed by id (the service checks that it has finished)."""
    if isinstance(previous, WarmStartModel):
        return previous
    if isinstance(previous, str):
        if not previous:
            raise ValueError("a warm start's job id must be a non-empty string")
        return WarmStartModel(job_id=previous)
    if isinstance(previous, Job | PlanResult | FingerPlanResult | ManipulationResult):
        if planner is not None and previous.planner != planner:
            what = "job" if isinstance(previous, Job) else "plan"
            raise ValueError(f"a {previous.planner} {what} cannot warm-start a {planner} "
                             "request")
        if isinstance(previous, Job):
            return WarmStartModel(job_id=previous.id)
        return WarmStartModel.from_result(previous)
    if isinstance(previous, CollocationModel):
        return WarmStartModel.from_result(previous)
    if isinstance(previous, Mapping):
        return WarmStartModel.model_validate(previous)
    raise TypeError(f"cannot warm-start from a {type(previous).__name__}: give a result, a "
                    "Job, a job id, a CollocationModel or a WarmStartModel")


def _as_request(request: RequestLike, warm_start: WarmStartLike | None = None) -> PlanRequest:
    """The request as a validated model (raises pydantic's ValidationError, locally), with
    ``warm_start`` (when given) as its ``warm_start``."""
    req = _REQUEST.validate_python(request)
    if warm_start is None:
        return req
    return req.model_copy(update={"warm_start": warm_start_model(warm_start, req.planner)})


def _job_path(job_id: str) -> str:
    if not isinstance(job_id, str) or not job_id:
        raise ValueError(f"job_id must be a non-empty string, got {job_id!r}")
    return f"/v1/plans/{quote(job_id, safe='')}"


def _format_seconds(seconds: float) -> str:
    return f"{seconds:.3f}".rstrip("0").rstrip(".") or "0"


def _submit_call(request: PlanRequest, wait: float | None,
                 idempotency_key: str | None) -> _Call:
    params: dict[str, str | int] = {}
    min_read: float | None = None
    if wait is not None:
        if not (math.isfinite(wait) and wait >= 0.0):
            raise ValueError(f"wait must be a finite number of seconds >= 0, got {wait!r}")
        params["wait"] = _format_seconds(wait)
        min_read = wait + _WAIT_MARGIN
    headers: dict[str, str] = {}
    if idempotency_key is not None:
        if not (idempotency_key and idempotency_key.isascii() and idempotency_key.isprintable()):
            raise ValueError("idempotency_key must be a non-empty string of printable ASCII "
                             f"characters, got {idempotency_key!r}")
        headers["Idempotency-Key"] = idempotency_key
    body = request.model_dump(mode="json")
    if body.get("warm_start") is None:  # a service older than warm starts refuses the key
        body.pop("warm_start", None)
    return _Call("POST", "/v1/plans", params=params, headers=headers, json=body,
                 min_read_timeout=min_read)


def _simulate_call(job_id: str, options: SimulationOptions | Mapping[str, Any] | None,
                   fields: Mapping[str, Any]) -> _Call:
    if options is None:
        model = SimulationOptions.model_validate(dict(fields))
    elif isinstance(options, SimulationOptions):
        model = options.model_copy(update=dict(fields)) if fields else options
    else:
        model = SimulationOptions.model_validate({**options, **fields})
    return _Call("POST", f"{_job_path(job_id)}/simulation",
                 json=model.model_dump(mode="json", exclude_none=True),
                 min_read_timeout=_SIMULATE_READ_TIMEOUT)


def _replan_call(job_id: str, measured: ReplanRequest | Mapping[str, Any] | None,
                 fields: Mapping[str, Any]) -> _Call:
    if measured is None:
        model = ReplanRequest.model_validate(dict(fields))
    elif isinstance(measured, ReplanRequest):
        model = measured.model_copy(update=dict(fields)) if fields else measured
        model = ReplanRequest.model_validate(model.model_dump())
    else:
        model = ReplanRequest.model_validate({**measured, **fields})
    return _Call("POST", f"{_job_path(job_id)}/replan",
                 json=model.model_dump(mode="json", exclude_none=True),
                 min_read_timeout=_REPLAN_READ_TIMEOUT)


def _batch_path(batch_id: str) -> str:
    if not isinstance(batch_id, str) or not batch_id:
        raise ValueError(f"batch_id must be a non-empty string, got {batch_id!r}")
    return f"/v1/batches/{quote(batch_id, safe='')}"


def _batch_call(requests: Iterable[RequestLike]) -> _Call:
    """``POST /v1/batches`` of the requests, checked here first (pydantic's
    ValidationError located at ``("items", i, ...)``)."""
    body = BatchRequest.model_validate({"items": [
        r.model_dump(mode="json") if isinstance(r, BaseModel) else r for r in requests]})
    return _Call("POST", "/v1/batches", json=body.model_dump(mode="json"),
                 min_read_timeout=_SIMULATE_READ_TIMEOUT)


def _batch_line(line: str) -> Job | None:
    """A job of a batch's NDJSON results (None: a blank line, a purged job)."""
    if not line.strip() or '"state":"purged"' in line:
        return None
    return Job.model_validate_json(line)


def _cancel_call(job_id: str) -> _Call:
    return _Call("DELETE", _job_path(job_id), min_read_timeout=_CANCEL_READ_TIMEOUT)


def _decode(response: httpx.Response, model: type[_M]) -> _M:
    """The body of a 2xx response as ``model``; an :class:`APIError` for anything else."""
    if not response.is_success:
        raise error_from_response(response)
    try:
        return model.model_validate_json(response.content)
    except ValidationError as exc:
        raise APIError(
            response.status_code, "invalid_response",
            f"the service's {response.request.method} {response.request.url.path} answer is "
            f"not a valid {model.__name__}: {exc.error_count()} error(s), first: "
            f"{exc.errors()[0]['msg']} at {'.'.join(map(str, exc.errors()[0]['loc']))}",
            response=response) from exc


def _probe(response: httpx.Response) -> bool:
    """A health/readiness answer: 2xx is True, 5xx is False, anything else an error."""
    if response.is_success:
        return True
    if response.is_server_error:
        return False
    raise error_from_response(response)


def _exchange(call: _Call) -> Generator[_Call | _Sleep, httpx.Response | None, httpx.Response]:
    response = yield call
    if response is None:  # pragma: no cover - a driver bug
        raise RuntimeError("the driver answered an HTTP call with no response")
    return response


def _one(call: _Call, model: type[_M]) -> _Op[_M]:
    response = yield from _exchange(call)
    return _decode(response, model)


def _probe_op(path: str) -> _Op[bool]:
    response = yield from _exchange(_Call("GET", path))
    return _probe(response)


def _submit_op(request: RequestLike, wait: float | None, idempotency_key: str | None,
               warm_start: WarmStartLike | None = None) -> _Op[Job]:
    call = _submit_call(_as_request(request, warm_start), wait, idempotency_key)
    return (yield from _one(call, Job))


def _plan_op(request: RequestLike, *, timeout: float | None, idempotency_key: str | None,
             poll_initial: float, poll_max: float, warm_start: WarmStartLike | None = None
             ) -> _Op[Job]:
    """Submit, then wait until the job is terminal (see ``DexrollClient.plan``)."""
    req = _as_request(request, warm_start)
    if timeout is not None and not (timeout >= 0.0 and math.isfinite(timeout)):
        raise ValueError(f"timeout must be None or a finite number >= 0, got {timeout!r}")
    if not (math.isfinite(poll_initial) and poll_initial > 0.0):
        raise ValueError(f"poll_initial must be > 0, got {poll_initial!r}")
    if not (math.isfinite(poll_max) and poll_max >= poll_initial):
        raise ValueError(f"poll_max must be >= poll_initial, got {poll_max!r}")
    # One key for every attempt: a POST retried after a 503 cannot create a second job.
    key = idempotency_key if idempotency_key is not None else str(uuid.uuid4())
    deadline = None if timeout is None else time.monotonic() + timeout

    def remaining() -> float:
        return math.inf if deadline is None else deadline - time.monotonic()

    # 1. Submit, long-polling on the POST; retry while the queue is full (503).
    delay = poll_initial
    while True:
        wait = max(0.0, min(remaining(), MAX_WAIT))
        response = yield from _exchange(_submit_call(req, wait, key))
        if response.status_code != 503:
            job = _decode(response, Job)
            break
        unavailable = error_from_response(response)
        asked = parse_retry_after(response.headers.get("Retry-After"))
        left = remaining()
        if left <= 0.0 or (asked is not None and asked > left):
            hint = "" if asked is None else f" and asked to retry after {asked:g} s"
            raise PlanTimeoutError(
                f"the service was unavailable{hint}, beyond the {timeout} s timeout: "
                f"{unavailable.message}", timeout=timeout) from unavailable
        # many clients turned away together must not come back together: jitter
        pause = asked * random.uniform(1.0, 1.25) if asked is not None else min(delay, left)
        delay = min(2.0 * delay, poll_max)
        yield _Sleep(pause)

    # 2. Poll with capped exponential backoff; the first poll, and any after a 503, no
    # sooner than its Retry-After (a Retry-After on a 200 has no standard meaning: ignored,
    # so that the caller's backoff still applies).
    delay = poll_initial
    retry_after = parse_retry_after(response.headers.get("Retry-After"))
    while not job.state.terminal:
        left = remaining()
        if left <= 0.0:
            raise PlanTimeoutError(
                f"job {job.id} still {job.state.value} after the {timeout} s timeout; it "
                f"keeps running on the service (get() or cancel() it by id)",
                job_id=job.id, job=job, timeout=timeout)
        yield _Sleep(min(max(delay, retry_after or 0.0), left))
        delay = min(2.0 * delay, poll_max)
        response = yield from _exchange(_Call("GET", _job_path(job.id)))
        if response.status_code == 503:  # briefly unavailable: keep polling
            retry_after = parse_retry_after(response.headers.get("Retry-After"))
            continue
        retry_after = None
        job = _decode(response, Job)
    return job


def _request_timeout(client_timeout: httpx.Timeout, call: _Call) -> httpx.Timeout:
    """The client's timeout, with the read timeout raised to cover a server-side wait."""
    need = call.min_read_timeout
    if need is None or client_timeout.read is None or client_timeout.read >= need:
        return client_timeout
    return httpx.Timeout(connect=client_timeout.connect, read=need,
                         write=client_timeout.write, pool=client_timeout.pool)


def _check_base_url(http: httpx.Client | httpx.AsyncClient) -> None:
    if not str(http.base_url):
        raise ValueError("the httpx client needs a base_url (e.g. "
                         "httpx.Client(base_url='http://127.0.0.1:8000')), or use from_url()")


def _idempotent(call: _Call) -> bool:
    """Whether sending ``call`` twice has the effect of sending it once."""
    return call.method in ("GET", "HEAD", "DELETE") or (
        call.method == "POST" and "Idempotency-Key" in call.headers)


def _retry_pause(call: _Call, exc: httpx.RequestError, attempt: int, retries: int
                 ) -> float | None:
    """How long to wait before sending ``call`` again after ``exc`` (attempt 0 is the
    first retry); None: do not (not safe, not a transient failure, or no retries left)."""
    transient = isinstance(exc, httpx.NetworkError | httpx.TimeoutException
                           | httpx.RemoteProtocolError)
    if attempt >= retries or not transient or not _idempotent(call):
        return None
    return random.uniform(0.0, RETRY_BACKOFF * 2.0 ** attempt)  # full jitter


def _bearer(api_key: str | None, headers: Mapping[str, str] | None) -> dict[str, str]:
    out = dict(headers or {})
    if api_key is not None:
        out["Authorization"] = f"Bearer {api_key}"
    return out


def _transport_error(call: _Call, exc: httpx.RequestError) -> TransportError:
    return TransportError(f"{call.method} {call.path} failed: {type(exc).__name__}: {exc}",
                          cause=exc)


# -- the synchronous client -------------------------------------------------------------------

class DexrollClient:
    """Blocking client of the dexroll service, wrapping an ``httpx.Client``.

    ``http`` must have ``base_url`` set to the service root; it is not closed by this client
    (use ``from_url`` to let the client own one).
    """

    def __init__(self, http: httpx.Client, *, retries: int = RETRIES) -> None:
        _check_base_url(http)
        self._http = http
        self._owns_http = False
        self._sleep: Callable[[float], None] = time.sleep
        self.retries = retries

    @classmethod
    def from_url(cls, base_url: str, *, timeout: float | httpx.Timeout = DEFAULT_TIMEOUT,
                 headers: Mapping[str, str] | None = None, api_key: str | None = None,
                 retries: int = RETRIES) -> Self:
        """A client with its own ``httpx.Client`` (closed by ``close()`` / the ``with``);
        ``api_key`` for a service with API keys; ``retries`` of a request that got no
        response and is safe to send again."""
        client = cls(httpx.Client(base_url=base_url, timeout=timeout,
                                  headers=_bearer(api_key, headers)), retries=retries)
        client._owns_http = True
        return client

    @property
    def http(self) -> httpx.Client:
        """The wrapped httpx client."""
        return self._http

    def close(self) -> None:
        """Close the httpx client if this client created it (``from_url``)."""
        if self._owns_http:
            self._http.close()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"{type(self).__name__}({str(self._http.base_url)!r})"

    def _send(self, call: _Call) -> httpx.Response:
        attempt = 0
        while True:
            try:
                return self._http.request(
                    call.method, call.path, params=call.params or None,
                    headers=call.headers or None, json=call.json,
                    timeout=_request_timeout(self._http.timeout, call))
            except httpx.RequestError as exc:
                pause = _retry_pause(call, exc, attempt, self.retries)
                if pause is None:
                    raise _transport_error(call, exc) from exc
                attempt += 1
                self._sleep(pause)

    def _run(self, op: _Op[_T]) -> _T:
        try:
            step = next(op)
            while True:
                if isinstance(step, _Sleep):
                    self._sleep(step.seconds)
                    step = op.send(None)
                else:
                    step = op.send(self._send(step))
        except StopIteration as done:
            result: _T = done.value
            return result
        finally:
            op.close()

    def submit(self, request: RequestLike, *, wait: float | None = None,
               idempotency_key: str | None = None,
               warm_start: WarmStartLike | None = None) -> Job:
        """Submit a plan request; the job, finished (with ``result``) if it finished within
        ``wait`` seconds (service default 1 s, max 30), else queued or running.

        With ``idempotency_key``, a retried submit returns the job of the first one (a
        different body with the same key raises ConflictError). ``warm_start``: a previous
        plan to start from (see :meth:`plan`).
        """
        return self._run(_submit_op(request, wait, idempotency_key, warm_start))

    def get(self, job_id: str) -> Job:
        """The job (with ``result`` once terminal); NotFoundError for an unknown id."""
        return self._run(_one(_Call("GET", _job_path(job_id)), Job))

    def cancel(self, job_id: str) -> Job:
        """Cancel a job; the cancelled job. ConflictError (``error == "already_finished"``)
        if it was already terminal, NotFoundError for an unknown id."""
        return self._run(_one(_cancel_call(job_id), Job))

    def list(self, limit: int = 50, offset: int = 0) -> JobList:
        """One page of jobs (without results); ``next_offset`` is None on the last page."""
        call = _Call("GET", "/v1/plans", params={"limit": limit, "offset": offset})
        return self._run(_one(call, JobList))

    def models(self) -> ModelCatalog:
        """The planners, objects and fingers the service knows."""
        return self._run(_one(_Call("GET", "/v1/models"), ModelCatalog))

    def simulate(self, job_id: str,
                 options: SimulationOptions | Mapping[str, Any] | None = None,
                 **fields: Any) -> SimulationReport:
        """Execute a finished job's plan in MuJoCo (``POST /v1/plans/{id}/simulation``,
        docs/simulation.md): the report, also stored as the job's latest. ``options`` (or
        keyword fields, e.g. ``squeeze=0.0005, mode="kinematic"``): a
        :class:`~dexroll_client.simulation.SimulationOptions`. ConflictError for a job
        without a plan a hand executes, NotFoundError for an unknown id."""
        return self._run(_one(_simulate_call(job_id, options, fields), SimulationReport))

    def replan(self, job_id: str,
               measured: ReplanRequest | Mapping[str, Any] | None = None,
               **fields: Any) -> ReplanResult:
        """Re-plan the rest of a finished job's plan from a measured state
        (``POST /v1/plans/{id}/replan``, docs/replanning.md "Through the service"):
        ``measured`` (or keyword fields, e.g. ``t=1.0, q=[[...]], object_position=[...],
        object_wxyz=[...]``) a :class:`~dexroll_client.replan.ReplanRequest`. The answer's
        ``status`` says whether to follow its ``joint_trajectory`` (``replanned``) or keep
        the current one. InvalidRequestError (422) for a measurement that does not fit the
        plan or a state the grasp cannot explain (``error`` ``unexplained_state``, the
        field in ``detail``), ConflictError for a plan that cannot be re-planned,
        NotFoundError for an unknown id."""
        return self._run(_one(_replan_call(job_id, measured, fields), ReplanResult))

    def controller(self, job_id: str, open_timeout: float = 30.0,
                   backend: str = "ipopt") -> ControlSession:
        """A controller session on a finished job's rolling plan
        (``WebSocket /v1/plans/{id}/control``, docs/control.md "Through the service"):
        its ``tick(t, q, object_position, object_wxyz)`` answers each measurement with
        the next window of the plan from it (:class:`~dexroll_client.control.ControlAnswer`);
        close it (or use ``with``) when the motion ends. The session's first tick builds
        the service's controller (seconds: ``setup_time``). ``backend``: the window's
        solver, ``"ipopt"`` (the default), ``"rti"`` (real-time iterations, faster for one
        fingertip) or ``"auto"`` (docs/control.md)."""
        base = str(self._http.base_url).rstrip("/")
        url = "ws" + base[4:] if base.startswith("http") else base
        headers = {k: v for k, v in self._http.headers.items()
                   if k.lower() in ("authorization", "x-api-key")}
        if backend not in ("ipopt", "rti", "auto"):
            raise ValueError(f"backend: one of 'ipopt', 'rti', 'auto', not {backend!r}")
        query = "" if backend == "ipopt" else f"?backend={quote(backend, safe='')}"
        return ControlSession(f"{url}{_job_path(job_id)}/control{query}", headers,
                              open_timeout)

    def simulation(self, job_id: str) -> SimulationReport:
        """A job's latest simulation report (NotFoundError: none yet)."""
        return self._run(_one(_Call("GET", f"{_job_path(job_id)}/simulation"),
                              SimulationReport))

    def health(self) -> bool:
        """Whether the service is alive (``/healthz``); TransportError if unreachable."""
        return self._run(_probe_op("/healthz"))

    def ready(self) -> bool:
        """Whether the service accepts work (``/readyz``); TransportError if unreachable."""
        return self._run(_probe_op("/readyz"))

    # -- batches (docs/service.md, "Batches") -----------------------------------------------
    def submit_batch(self, requests: Iterable[RequestLike]) -> Batch:
        """Submit many plan requests as one batch (``POST /v1/batches``, at most
        :data:`~dexroll_client.batches.MAX_BATCH`): every one checked first, here
        (pydantic's ValidationError, located at ``("items", i, ...)``) and by the service
        (InvalidRequestError naming ``items[i].field``), and no job made; then all queued.
        The batch: its jobs' ids in order and their counts by state."""
        return self._run(_one(_batch_call(requests), Batch))

    def batch(self, batch_id: str) -> Batch:
        """A batch's progress (its jobs' counts by state, ``done``)."""
        return self._run(_one(_Call("GET", _batch_path(batch_id)), Batch))

    def cancel_batch(self, batch_id: str) -> Batch:
        """Cancel the batch's jobs that have not ended; the batch then."""
        return self._run(_one(_Call("DELETE", _batch_path(batch_id),
                                    min_read_timeout=_CANCEL_READ_TIMEOUT), Batch))

    def batch_results(self, batch_id: str, order: str = "submission",
                      result: bool = True) -> Iterator[Job]:
        """The batch's jobs as they end (``GET /v1/batches/{id}/results``, NDJSON): in
        submission order (``order="submission"``) or as each finishes (``"finished"``),
        each with its plan unless ``result`` is False; a job purged meanwhile is skipped.
        Ends when every job has ended."""
        params = {"order": order, "result": "true" if result else "false"}
        with self._http.stream("GET", f"{_batch_path(batch_id)}/results", params=params,
                               timeout=httpx.Timeout(self._http.timeout.connect,
                                                     read=None)) as response:
            if not response.is_success:
                response.read()
                raise error_from_response(response)
            for line in response.iter_lines():
                job = _batch_line(line)
                if job is not None:
                    yield job

    def plan_many(self, requests: Iterable[RequestLike], *,
                  progress: Callable[[int, int], None] | None = None) -> builtins.list[Job]:
        """Plan many requests as one batch and wait for all: their terminal jobs, in the
        requests' order (each with its plan). ``progress(done, total)`` is called as each
        one ends."""
        batch = self.submit_batch(requests)
        jobs: dict[str, Job] = {}
        for job in self.batch_results(batch.id, order="finished"):
            jobs[job.id] = job
            if progress is not None:
                progress(len(jobs), batch.size)
        return [jobs[i] for i in batch.job_ids if i in jobs]

    def plan(self, request: RequestLike, *, timeout: float | None = None,
             idempotency_key: str | None = None, poll_initial: float = 0.1,
             poll_max: float = 2.0, warm_start: WarmStartLike | None = None) -> Job:
        """Submit a request and wait until its job is terminal; the terminal job, whatever
        its state (succeeded, infeasible, timed_out, failed, cancelled): look at
        ``job.state`` and ``job.result.status``.

        Polls with exponential backoff from ``poll_initial`` to ``poll_max`` seconds, never
        sooner than a ``Retry-After``; a full queue (503) on submit is retried after its
        ``Retry-After``, with the same idempotency key (a fresh uuid4 when none is given),
        so retries never create two jobs. After ``timeout`` seconds (None: no limit) raises
        PlanTimeoutError, whose ``job_id`` names the job if one was created.

        ``warm_start``: a previous plan of a similar problem as IPOPT's initial guess,
        replacing the request's own ``warm_start``: a result of the same planner (its
        ``collocation`` block is sent), a finished ``Job`` of this service or its id (the
        service looks it up; 422 naming ``warm_start.job_id`` if it cannot be used), a
        ``CollocationModel`` or a ``WarmStartModel``. ValueError, locally, for a result or
        job of another planner or a result without a ``collocation`` block.
        """
        return self._run(_plan_op(request, timeout=timeout, idempotency_key=idempotency_key,
                                  poll_initial=poll_initial, poll_max=poll_max,
                                  warm_start=warm_start))


# -- the asynchronous client ------------------------------------------------------------------

class AsyncDexrollClient:
    """Asynchronous client of the dexroll service, wrapping an ``httpx.AsyncClient``; the
    same methods as :class:`DexrollClient`, as coroutines."""

    def __init__(self, http: httpx.AsyncClient, *, retries: int = RETRIES) -> None:
        _check_base_url(http)
        self._http = http
        self._owns_http = False
        self._sleep: Callable[[float], Awaitable[None]] = asyncio.sleep
        self.retries = retries

    @classmethod
    def from_url(cls, base_url: str, *, timeout: float | httpx.Timeout = DEFAULT_TIMEOUT,
                 headers: Mapping[str, str] | None = None, api_key: str | None = None,
                 retries: int = RETRIES) -> Self:
        """A client with its own ``httpx.AsyncClient`` (closed by ``aclose()`` / the
        ``async with``); see :meth:`DexrollClient.from_url`."""
        client = cls(httpx.AsyncClient(base_url=base_url, timeout=timeout,
                                       headers=_bearer(api_key, headers)), retries=retries)
        client._owns_http = True
        return client

    @property
    def http(self) -> httpx.AsyncClient:
        """The wrapped httpx client."""
        return self._http

    async def aclose(self) -> None:
        """Close the httpx client if this client created it (``from_url``)."""
        if self._owns_http:
            await self._http.aclose()

    async def __aenter__(self) -> Self:
        return self

    async def __aexit__(self, exc_type: type[BaseException] | None,
                        exc: BaseException | None, tb: TracebackType | None) -> None:
        await self.aclose()

    def __repr__(self) -> str:
        return f"{type(self).__name__}({str(self._http.base_url)!r})"

    async def _send(self, call: _Call) -> httpx.Response:
        attempt = 0
        while True:
            try:
                return await self._http.request(
                    call.method, call.path, params=call.params or None,
                    headers=call.headers or None, json=call.json,
                    timeout=_request_timeout(self._http.timeout, call))
            except httpx.RequestError as exc:
                pause = _retry_pause(call, exc, attempt, self.retries)
                if pause is None:
                    raise _transport_error(call, exc) from exc
                attempt += 1
                await self._sleep(pause)

    async def _run(self, op: _Op[_T]) -> _T:
        try:
            step = next(op)
            while True:
                if isinstance(step, _Sleep):
                    await self._sleep(step.seconds)
                    step = op.send(None)
                else:
                    step = op.send(await self._send(step))
        except StopIteration as done:
            result: _T = done.value
            return result
        finally:
            op.close()

    async def submit(self, request: RequestLike, *, wait: float | None = None,
                     idempotency_key: str | None = None,
                     warm_start: WarmStartLike | None = None) -> Job:
        """See :meth:`DexrollClient.submit`."""
        return await self._run(_submit_op(request, wait, idempotency_key, warm_start))

    async def get(self, job_id: str) -> Job:
        """See :meth:`DexrollClient.get`."""
        return await self._run(_one(_Call("GET", _job_path(job_id)), Job))

    async def cancel(self, job_id: str) -> Job:
        """See :meth:`DexrollClient.cancel`."""
        return await self._run(_one(_cancel_call(job_id), Job))

    async def list(self, limit: int = 50, offset: int = 0) -> JobList:
        """See :meth:`DexrollClient.list`."""
        call = _Call("GET", "/v1/plans", params={"limit": limit, "offset": offset})
        return await self._run(_one(call, JobList))

    async def models(self) -> ModelCatalog:
        """See :meth:`DexrollClient.models`."""
        return await self._run(_one(_Call("GET", "/v1/models"), ModelCatalog))

    async def simulate(self, job_id: str,
                       options: SimulationOptions | Mapping[str, Any] | None = None,
                       **fields: Any) -> SimulationReport:
        """See :meth:`DexrollClient.simulate`."""
        return await self._run(_one(_simulate_call(job_id, options, fields),
                                    SimulationReport))

    async def replan(self, job_id: str,
                     measured: ReplanRequest | Mapping[str, Any] | None = None,
                     **fields: Any) -> ReplanResult:
        """See :meth:`DexrollClient.replan`."""
        return await self._run(_one(_replan_call(job_id, measured, fields), ReplanResult))

    async def simulation(self, job_id: str) -> SimulationReport:
        """See :meth:`DexrollClient.simulation`."""
        return await self._run(_one(_Call("GET", f"{_job_path(job_id)}/simulation"),
                                    SimulationReport))

    async def health(self) -> bool:
        """See :meth:`DexrollClient.health`."""
        return await self._run(_probe_op("/healthz"))

    async def ready(self) -> bool:
        """See :meth:`DexrollClient.ready`."""
        return await self._run(_probe_op("/readyz"))

    async def submit_batch(self, requests: Iterable[RequestLike]) -> Batch:
        """:meth:`DexrollClient.submit_batch`, awaited."""
        return await self._run(_one(_batch_call(requests), Batch))

    async def batch(self, batch_id: str) -> Batch:
        """:meth:`DexrollClient.batch`, awaited."""
        return await self._run(_one(_Call("GET", _batch_path(batch_id)), Batch))

    async def cancel_batch(self, batch_id: str) -> Batch:
        """:meth:`DexrollClient.cancel_batch`, awaited."""
        return await self._run(_one(_Call("DELETE", _batch_path(batch_id),
                                          min_read_timeout=_CANCEL_READ_TIMEOUT), Batch))

    async def batch_results(self, batch_id: str, order: str = "submission",
                            result: bool = True) -> AsyncIterator[Job]:
        """:meth:`DexrollClient.batch_results`, as an async iterator."""
        params = {"order": order, "result": "true" if result else "false"}
        async with self._http.stream("GET", f"{_batch_path(batch_id)}/results",
                                     params=params, timeout=httpx.Timeout(
                                         self._http.timeout.connect, read=None)) as response:
            if not response.is_success:
                await response.aread()
                raise error_from_response(response)
            async for line in response.aiter_lines():
                job = _batch_line(line)
                if job is not None:
                    yield job

    async def plan_many(self, requests: Iterable[RequestLike], *,
                        progress: Callable[[int, int], None] | None = None
                        ) -> builtins.list[Job]:
        """:meth:`DexrollClient.plan_many`, awaited."""
        batch = await self.submit_batch(requests)
        jobs: dict[str, Job] = {}
        async for job in self.batch_results(batch.id, order="finished"):
            jobs[job.id] = job
            if progress is not None:
                progress(len(jobs), batch.size)
        return [jobs[i] for i in batch.job_ids if i in jobs]

    async def plan(self, request: RequestLike, *, timeout: float | None = None,
                   idempotency_key: str | None = None, poll_initial: float = 0.1,
                   poll_max: float = 2.0, warm_start: WarmStartLike | None = None) -> Job:
        """See :meth:`DexrollClient.plan`."""
        return await self._run(_plan_op(request, timeout=timeout,
                                        idempotency_key=idempotency_key,
                                        poll_initial=poll_initial, poll_max=poll_max,
                                        warm_start=warm_start))
