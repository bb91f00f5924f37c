"""The HTTP API (FastAPI), versioned under /v1. OpenAPI docs at /docs.

POST /v1/plans           submit a planning request; 201 + the finished job when it ends
                         within ?wait= seconds, else 202 + Location to poll
GET  /v1/plans/{id}      a job (with its plan once finished)
GET  /v1/plans           jobs, newest first, paginated (?limit=&offset=)
DELETE /v1/plans/{id}    cancel a queued or running job
GET  /v1/models          built-in objects, fingers (with URDFs), hands and planners
GET  /healthz, /readyz   liveness; readiness (store reachable, a worker ready)

Every error is an ``ErrorBody`` (no traceback ever leaves the service); an invalid request
is a 422 naming each bad field; a failed solve is a finished job with its typed status.

A request's ``warm_start.job_id`` is resolved at submission: the job's plan (its result's
``collocation`` block) replaces it before the new job is stored, so that every stored job
is self-contained (a worker never looks another job up).
"""

from __future__ import annotations

import asyncio
import logging
import threading
from collections.abc import AsyncIterator, Awaitable, Callable, MutableMapping
from contextlib import asynccontextmanager, suppress
from datetime import UTC, datetime
from typing import Annotated, Any

from fastapi import FastAPI, Header, Query, Request, Response
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from pydantic import ValidationError
from starlette.exceptions import HTTPException as StarletteHTTPException

from dexroll_client.models import (
    AnyPlanResult,
    ErrorBody,
    FieldError,
    Job,
    JobList,
    JobState,
    ModelCatalog,
    PlanRequest,
    WarmStartModel,
)

from .planners import FINGERS, RESULT, request_errors, wire_field
from .planners.catalog import model_catalog
from .settings import Settings
from .store import IdempotencyConflictError, JobRow, Store
from .workers import Dispatcher

__all__ = ["StoreUnavailableError", "create_app", "resolve_warm_start", "submission_errors"]

log = logging.getLogger("dexroll.service")

ERROR_RESPONSES: dict[int | str, dict[str, Any]] = {
    code: {"model": ErrorBody, "description": text} for code, text in [
        (404, "no such job"), (409, "conflict (idempotency key reuse, job already finished)"),
        (413, "request body too large"), (422, "invalid request: each bad field named"),
        (503, "queue full, not ready, or the job store unavailable; retry after "
               "Retry-After seconds")]}


class ServiceError(Exception):
    """An error answered with an ErrorBody."""

    def __init__(self, status: int, error: str, message: str,
                 detail: list[FieldError] | None = None,
                 headers: dict[str, str] | None = None) -> None:
        super().__init__(message)
        self.status, self.error, self.message = status, error, message
        self.detail = detail or []
        self.headers = headers


def _error_response(status: int, error: str, message: str,
                    detail: list[FieldError] | None = None,
                    headers: dict[str, str] | None = None) -> JSONResponse:
    body = ErrorBody(error=error, message=message, detail=detail or [])
    return JSONResponse(body.model_dump(mode="json"), status_code=status, headers=headers)


class BodyLimit:
    """ASGI middleware: request bodies over ``limit`` bytes get 413 before being parsed."""

    def __init__(self, app: Callable[..., Awaitable[None]], limit: int) -> None:
        self.app, self.limit = app, limit

    async def __call__(self, scope: MutableMapping[str, Any], receive: Any, send: Any) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        headers = dict(scope.get("headers") or [])
        length = headers.get(b"content-length")
        too_large = _error_response(413, "payload_too_large",
                                    f"request bodies are limited to {self.limit} bytes")
        if length is not None and length.isdigit() and int(length) > self.limit:
            await too_large(scope, receive, send)
            return
        received = 0

        async def limited_receive() -> Any:
            nonlocal received
            message = await receive()
            if message["type"] == "http.request":
                received += len(message.get("body", b""))
                if received > self.limit:  # FastAPI re-raises HTTPException from body reads
                    raise StarletteHTTPException(
                        413, f"request bodies are limited to {self.limit} bytes")
            return message

        await self.app(scope, limited_receive, send)


class Notifier:
    """Lets request handlers await the end of a job that the dispatcher thread reports."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._waiters: dict[str, list[tuple[asyncio.AbstractEventLoop, asyncio.Event]]] = {}

    def register(self, job_id: str) -> asyncio.Event:
        event = asyncio.Event()
        with self._lock:
            self._waiters.setdefault(job_id, []).append((asyncio.get_running_loop(), event))
        return event

    def unregister(self, job_id: str, event: asyncio.Event) -> None:
        with self._lock:
            waiters = [w for w in self._waiters.get(job_id, []) if w[1] is not event]
            if waiters:
                self._waiters[job_id] = waiters
            else:
                self._waiters.pop(job_id, None)

    def notify(self, job_id: str) -> None:
        with self._lock:
            waiters = list(self._waiters.get(job_id, []))
        for loop, event in waiters:
            loop.call_soon_threadsafe(event.set)


def _ts(t: float | None) -> datetime | None:
    return datetime.fromtimestamp(t, tz=UTC) if t is not None else None


def job_model(row: JobRow) -> Job:
    return Job(id=row.id, state=JobState(row.state), code=row.code, message=row.message,
               raw_status=row.raw_status, planner=row.planner,
               created_at=datetime.fromtimestamp(row.created_at, tz=UTC),
               started_at=_ts(row.started_at), finished_at=_ts(row.finished_at),
               worker_pid=row.worker_pid,
               result=RESULT.validate_json(row.result) if row.result else None)


class StoreUnavailableError(Exception):
    """The job store could not be read."""


def resolve_warm_start(body: PlanRequest, store: Store
                       ) -> tuple[PlanRequest, list[tuple[str, str]]]:
    """The request with its ``warm_start.job_id`` replaced by that job's plan (``t``, ``x``,
    ``u`` and the column names of its result's ``collocation`` block), or the reasons, all
    under ``warm_start.job_id``, why the job cannot be used (unknown, not finished, another
    planner, no plan). A request without a job id is returned as it is.
    StoreUnavailableError when the store cannot be read."""
    ws = body.warm_start
    if ws is None or ws.job_id is None:
        return body, []
    job_id = ws.job_id

    def refused(reason: str) -> tuple[PlanRequest, list[tuple[str, str]]]:
        return body, [("warm_start.job_id", reason)]

    try:
        row = store.get(job_id)
    except Exception as exc:  # sqlite errors: the store is unavailable, not the request bad
        raise StoreUnavailableError(str(exc)) from exc
    if row is None:
        return refused(f"no job {job_id!r} in this service")
    if not JobState(row.state).terminal:
        return refused(f"job {job_id} is still {row.state}: warm-start from it once it has "
                       "finished")
    if row.planner != body.planner:
        return refused(f"job {job_id} is a {row.planner} plan; this request is for the "
                       f"{body.planner} planner")
    result: AnyPlanResult | None = None
    if row.result:
        try:
            result = RESULT.validate_json(row.result)
        except ValidationError:
            log.warning("job %s: its stored result does not parse", job_id, exc_info=True)
    if result is None or result.collocation is None:
        return refused(f"job {job_id} ended {row.state} ({row.code}) without a plan at its "
                       "collocation points to start from")
    try:
        inline = WarmStartModel.from_result(result)
    except (ValidationError, ValueError) as exc:
        reason = exc.errors()[0]["msg"] if isinstance(exc, ValidationError) else str(exc)
        return refused(f"job {job_id}'s plan cannot be used as a warm start: {reason}")
    return body.model_copy(update={"warm_start": inline}), []


def _from_job(job_id: str, errors: list[tuple[str, str]]) -> list[tuple[str, str]]:
    """Errors of a warm start resolved from a job, renamed to ``warm_start.job_id`` (the
    field the client gave) with the inline field in the reason."""
    out = []
    for field, reason in errors:
        if field == "warm_start" or field.startswith("warm_start."):
            sub = field.removeprefix("warm_start").lstrip(".")
            reason = f"job {job_id}'s plan does not fit this request: " + \
                (f"{sub}: {reason}" if sub else reason)
            field = "warm_start.job_id"
        out.append((field, reason))
    return out


def submission_errors(body: PlanRequest, store: Store
                      ) -> tuple[PlanRequest, list[tuple[str, str]]]:
    """What ``POST /v1/plans`` checks before storing a job: the request with its warm
    start's job id resolved (:func:`resolve_warm_start`), and every error of it as
    (field, reason) pairs (:func:`~planner_service.planners.request_errors`; those of a plan
    that came from a job named ``warm_start.job_id``). StoreUnavailableError when the store
    cannot be read."""
    job_id = body.warm_start.job_id if body.warm_start is not None else None
    body, errors = resolve_warm_start(body, store)
    if errors:  # check the rest of the request too: every bad field at once
        body = body.model_copy(update={"warm_start": None})
    more = request_errors(body)
    return body, errors + (_from_job(job_id, more) if job_id is not None else more)


def create_app(settings: Settings | None = None) -> FastAPI:
    """The service: job store, worker pool and API, configured by ``settings``."""
    settings = settings or Settings()
    notifier = Notifier()
    state: dict[str, Any] = {}

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        store = Store(settings.db_path)
        requeued, failed = store.recover()
        if requeued or failed:
            log.info("recovered the job store: %d re-queued, %d failed", requeued, failed)
        dispatcher = Dispatcher(
            store, settings.workers, settings.kill_grace, notifier.notify, settings.warmup,
            None if settings.compile_dir is None else str(settings.compile_dir.resolve()))
        dispatcher.start()
        state.update(store=store, dispatcher=dispatcher)
        try:
            yield
        finally:
            dispatcher.stop()
            store.close()

    app = FastAPI(title="dexroll", version="0.1.0", lifespan=lifespan,
                  description=__doc__, responses=ERROR_RESPONSES)

    def store() -> Store:
        s: Store = state["store"]
        return s

    def dispatcher() -> Dispatcher:
        d: Dispatcher = state["dispatcher"]
        return d

    def get_row(job_id: str) -> JobRow:
        row = store().get(job_id)
        if row is None:
            raise ServiceError(404, "not_found", f"no job {job_id!r}")
        return row

    # -- errors ------------------------------------------------------------------------------
    @app.exception_handler(ServiceError)
    async def _service_error(request: Request, exc: ServiceError) -> JSONResponse:
        return _error_response(exc.status, exc.error, exc.message, exc.detail, exc.headers)

    @app.exception_handler(RequestValidationError)
    async def _invalid(request: Request, exc: RequestValidationError) -> JSONResponse:
        detail = []
        for e in exc.errors():
            loc = [str(p) for p in e.get("loc", ())]
            where = loc[0] if loc and loc[0] in ("body", "query", "header", "path") else None
            if where is not None:
                loc = loc[1:]
            field = (wire_field(loc) if where == "body" else ".".join(loc)) or "body"
            reason = str(e.get("msg", "invalid"))
            if e.get("type") == "invalid_planner":
                field = "planner"
            if e.get("type") == "json_invalid":
                field, reason = "body", f"not valid JSON: {e.get('ctx', {}).get('error', '')}"
            detail.append(FieldError(field=field, reason=reason))
        message = "; ".join(f"{d.field}: {d.reason}" for d in detail)
        return _error_response(422, "invalid_request", message, detail)

    @app.exception_handler(StarletteHTTPException)
    async def _http_error(request: Request, exc: StarletteHTTPException) -> JSONResponse:
        name = {404: "not_found", 405: "method_not_allowed",
                413: "payload_too_large"}.get(exc.status_code, "http_error")
        return _error_response(exc.status_code, name, str(exc.detail))

    @app.exception_handler(Exception)
    async def _unexpected(request: Request, exc: Exception) -> JSONResponse:
        log.exception("unexpected error on %s %s", request.method, request.url.path)
        return _error_response(500, "internal_error",
                               f"unexpected {type(exc).__name__}; see the service log")

    # -- plans -------------------------------------------------------------------------------
    @app.post("/v1/plans", status_code=201, response_model=Job,
              responses={202: {"model": Job, "description": "accepted; poll Location"}})
    async def submit_plan(
        body: PlanRequest,
        response: Response,
        wait: Annotated[float | None, Query(ge=0.0, le=600.0, description=(
            "seconds to wait for the plan before answering 202 (capped by the service)"))
        ] = None,
        idempotency_key: Annotated[str | None, Header(max_length=200, description=(
            "a retried POST with the same key returns the same job"))] = None,
    ) -> Job:
        """Submit a planning request (`planner` picks the planner: `ball_on_palm`, the
        default, `one_finger` or `manipulation`): 201 with the finished job, or 202 and a
        Location."""
        # cheap checks (no NLP), in a thread: a finger's URDF and the inverse kinematics
        # of its initial grasp take milliseconds; a warm start's job id is replaced by
        # that job's plan (the new job is self-contained)
        try:
            body, errors = await asyncio.to_thread(submission_errors, body, store())
        except StoreUnavailableError as exc:
            raise ServiceError(503, "store_unavailable", f"the job store cannot be read to "
                               f"look up warm_start.job_id: {exc}",
                               headers={"Retry-After": "1"}) from exc
        if errors:
            detail = [FieldError(field=f, reason=r) for f, r in errors]
            raise ServiceError(422, "invalid_request",
                               "; ".join(f"{f}: {r}" for f, r in errors), detail)
        capped = min(body.solver.time_limit, settings.max_time_limit)
        body = body.model_copy(update={"solver": body.solver.model_copy(
            update={"time_limit": capped})})
        if store().count("queued") >= settings.max_queue:
            raise ServiceError(503, "queue_full",
                               f"{settings.max_queue} jobs are already queued",
                               headers={"Retry-After": "5"})
        try:
            row, created = store().create(body.planner, body.model_dump_json(), capped,
                                          idempotency_key)
        except IdempotencyConflictError as exc:
            raise ServiceError(409, "idempotency_conflict", str(exc)) from exc
        if created:
            dispatcher().wake()
        if not JobState(row.state).terminal:
            event = notifier.register(row.id)
            try:
                row = store().get(row.id) or row
                if not JobState(row.state).terminal:
                    timeout = min(settings.default_wait if wait is None else wait,
                                  settings.max_wait)
                    with suppress(TimeoutError):
                        await asyncio.wait_for(event.wait(), timeout=timeout)
                    row = store().get(row.id) or row
            finally:
                notifier.unregister(row.id, event)
        if not JobState(row.state).terminal:
            response.status_code = 202
            response.headers["Location"] = f"/v1/plans/{row.id}"
            response.headers["Retry-After"] = "1"
        return job_model(row)

    @app.get("/v1/plans/{job_id}", response_model=Job)
    def get_plan(job_id: str, response: Response) -> Job:
        """A job: its state, and its plan once finished."""
        row = get_row(job_id)
        if not JobState(row.state).terminal:
            response.headers["Retry-After"] = "1"
        return job_model(row)

    @app.get("/v1/plans", response_model=JobList)
    def list_plans(limit: Annotated[int, Query(ge=1, le=500)] = 50,
                   offset: Annotated[int, Query(ge=0)] = 0) -> JobList:
        """Jobs, newest first, without their plans."""
        rows, total = store().list(limit, offset)
        nxt = offset + len(rows) if offset + len(rows) < total else None
        return JobList(items=[job_model(r) for r in rows], total=total, limit=limit,
                       offset=offset, next_offset=nxt)

    @app.delete("/v1/plans/{job_id}", response_model=Job)
    async def cancel_plan(job_id: str) -> Job:
        """Cancel a queued or running job; 409 if it has already finished."""
        row = get_row(job_id)
        if JobState(row.state).terminal:
            raise ServiceError(409, "already_finished",
                               f"job {job_id} already ended: {row.state}")
        if not store().cancel_queued(job_id):
            event = notifier.register(job_id)
            try:
                dispatcher().cancel_running(job_id)
                with suppress(TimeoutError):
                    await asyncio.wait_for(event.wait(), timeout=10.0)
            finally:
                notifier.unregister(job_id, event)
        return job_model(get_row(job_id))

    # -- models and health ----------------------------------------------------------------------
    @app.get("/v1/models", response_model=ModelCatalog)
    def models() -> ModelCatalog:
        """Built-in objects, fingers (with their URDFs), hands and planners."""
        return model_catalog(FINGERS)

    @app.get("/healthz")
    def healthz() -> dict[str, str]:
        """Liveness: the process answers."""
        return {"status": "ok"}

    @app.get("/readyz", responses={503: {"model": ErrorBody}})
    def readyz() -> Any:
        """Readiness: the job store answers and at least one worker is ready."""
        try:
            queued = store().count("queued")
        except Exception as exc:  # the store is the service's memory: not ready without it
            return _error_response(503, "not_ready", f"job store unavailable: {exc}")
        workers = dispatcher().ready_workers
        if workers < 1:
            return _error_response(503, "not_ready", "no solver worker is ready yet",
                                   headers={"Retry-After": "1"})
        return {"status": "ready", "workers": workers, "queued": queued}

    app.add_middleware(BodyLimit, limit=settings.max_body_bytes)
    return app
