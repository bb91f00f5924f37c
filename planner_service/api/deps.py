"""What the routes depend on: the service's settings, job store, dispatcher and job-end
notifier (``Annotated`` dependencies, kept on ``app.state`` by :func:`.app.create_app`),
and the errors they answer with (every one an ``ErrorBody``; no traceback ever leaves
the service)."""

from __future__ import annotations

import asyncio
import logging
import sqlite3
import threading
from typing import Annotated, Any

from fastapi import Depends, FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.routing import Match

from dexroll_client.models import ErrorBody, FieldError, JobState

from ..jobs.store import JobRow, Store
from ..jobs.workers import Dispatcher
from ..models_check import ModelChecker
from ..planners.fields import planner_hint, wire_field
from ..settings import Settings

__all__ = [
    "ERROR_RESPONSES",
    "CheckerDep",
    "DispatcherDep",
    "Notifier",
    "NotifierDep",
    "ServiceError",
    "SettingsDep",
    "StoreDep",
    "add_error_handlers",
    "error_response",
    "store_fault_error",
    "unavailable_error",
]

log = logging.getLogger("dexroll.service")


# -- dependencies ----------------------------------------------------------------------------

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


async def get_settings(request: Request) -> Settings:
    settings: Settings = request.app.state.settings
    return settings


async def get_store(request: Request) -> Store:
    """The job store (opened when the service starts)."""
    store: Store = request.app.state.store
    return store


async def get_dispatcher(request: Request) -> Dispatcher:
    """The dispatcher of the worker processes (started with the service)."""
    dispatcher: Dispatcher = request.app.state.dispatcher
    return dispatcher


async def get_checker(request: Request) -> ModelChecker:
    """The checker of model texts from requests (started with the service)."""
    checker: ModelChecker = request.app.state.checker
    return checker


async def get_notifier(request: Request) -> Notifier:
    notifier: Notifier = request.app.state.notifier
    return notifier


SettingsDep = Annotated[Settings, Depends(get_settings)]
StoreDep = Annotated[Store, Depends(get_store)]
DispatcherDep = Annotated[Dispatcher, Depends(get_dispatcher)]
NotifierDep = Annotated[Notifier, Depends(get_notifier)]
CheckerDep = Annotated[ModelChecker, Depends(get_checker)]


# -- errors ----------------------------------------------------------------------------------

#: The error responses every route may give (in the OpenAPI document).
ERROR_RESPONSES: dict[int | str, dict[str, Any]] = {
    code: {"model": ErrorBody, "description": text} for code, text in [
        (400, "a Host header not in the service's allow-list (DEXROLL_ALLOWED_HOSTS)"),
        (401, "an API key is required (DEXROLL_API_KEYS set) and none or a wrong one was "
              "given"),
        (404, "no such job (or not this API key's)"),
        (405, "method not allowed (the Allow header lists those that are)"),
        (409, "conflict (idempotency key reuse, job already finished)"),
        (413, "request body too large"), (422, "invalid request: each bad field named"),
        (500, "an unexpected error in the service (never a failed solve: that is a "
              "finished job)"),
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


def finished_job(row: JobRow | None, job_id: str, action: str, plan: str | None = "a plan"
                 ) -> JobRow:
    """The job ``row`` (the store's ``get`` or ``head``) once it has finished: a 404
    when there is none, a 409 ``not_finished`` while it runs (``action``: what may then
    be done with it, e.g. "it can be simulated"), and a 409 ``no_plan`` when it ended
    without ``plan`` (None: not checked here)."""
    if row is None:
        raise ServiceError(404, "not_found", f"no job {job_id!r}")
    if not JobState(row.state).terminal:
        raise ServiceError(409, "not_finished", f"job {job_id} is {row.state}: {action} "
                                                "once it has finished",
                           headers={"Retry-After": "1"})
    if plan is not None and not row.result_bytes:
        raise ServiceError(409, "no_plan", f"job {job_id} ended ({row.state}) without {plan}")
    return row


def error_response(status: int, error: str, message: str,
                   detail: list[FieldError] | None = None,
                   headers: dict[str, str] | None = None) -> JSONResponse:
    body = ErrorBody(error=error, message=message, detail=detail or [])
    return JSONResponse(body.model_dump(mode="json"), status_code=status, headers=headers)


#: Retry-After of an answer refused because the job store cannot be written [s]: the
#: dispatcher probes the store every second and resumes as soon as a write succeeds.
STORE_RETRY_AFTER = 5


#: Retry-After of a submission refused while no worker can be started [s]: the dispatcher
#: tries again with a back-off of at most 30 s.
UNAVAILABLE_RETRY_AFTER = 10


def unavailable_error(dispatcher: Dispatcher) -> ServiceError | None:
    """The 503 that refuses new jobs while no worker is ready and none can be started (a
    Ray cluster that went away); None: jobs can be run."""
    reason = dispatcher.unavailable()
    if reason is None:
        return None
    return ServiceError(503, "workers_unavailable",
                        f"no solver worker can run jobs now: {reason}; jobs already "
                        "queued wait, new ones are refused until a worker is ready",
                        headers={"Retry-After": str(UNAVAILABLE_RETRY_AFTER)})


def store_fault_error(store: Store) -> ServiceError | None:
    """The 503 that refuses new work while the store cannot be written (None: it can)."""
    fault = store.fault
    if fault is None:
        return None
    return ServiceError(503, "storage_error", f"the job store cannot be written ({fault}); "
                        "new work is refused until it can (the service resumes by itself "
                        "when space returns)",
                        headers={"Retry-After": str(STORE_RETRY_AFTER)})


#: The most fields a 422 names (the rest are counted in its message).
MAX_DETAIL = 50


#: FastAPI's detail when a request body cannot be decoded at all (raised as a 400).
_BODY_PARSE_ERROR = "There was an error parsing the body"


def _body_reason(cause: BaseException | None) -> str:
    """Why a body could not be decoded, for a 422 naming ``body``."""
    if isinstance(cause, UnicodeDecodeError):
        return (f"not valid JSON: the body is not UTF-8 text (byte {cause.start}: "
                f"{cause.reason})")
    if isinstance(cause, RecursionError):
        return "not valid JSON: nested too deeply (arrays and objects within each other)"
    return f"not valid JSON: {type(cause).__name__ if cause else 'cannot be decoded'}"


def _allowed_methods(request: Request) -> set[str]:
    """The methods of every route of the request's path."""
    methods: set[str] = set()
    routes = list(request.app.router.routes)
    while routes:
        route = routes.pop()
        inner = getattr(route, "original_router", None)  # an included router (FastAPI)
        if inner is not None:
            routes += list(inner.routes)
            continue
        match, _ = route.matches(request.scope)
        if match is not Match.NONE:
            methods |= set(getattr(route, "methods", None) or ())
    return methods


def add_error_handlers(app: FastAPI) -> None:
    """Answer every error with an ErrorBody: the service's own, an invalid request (422,
    each field named as the wire names it), HTTP errors, and anything unexpected (500)."""

    @app.exception_handler(ServiceError)
    async def _service_error(request: Request, exc: ServiceError) -> JSONResponse:
        return error_response(exc.status, exc.error, exc.message, exc.detail, exc.headers)

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
        detail = [FieldError(field=f, reason=r) for f, r in planner_hint(
            getattr(exc, "body", None), [(d.field, d.reason) for d in detail])] + detail
        message = "; ".join(f"{d.field}: {d.reason}" for d in detail[:MAX_DETAIL])
        if len(detail) > MAX_DETAIL:  # the answer's size is bounded: the first are named
            message += f" …and {len(detail) - MAX_DETAIL:,} more"
        return error_response(422, "invalid_request", message, detail[:MAX_DETAIL])

    @app.exception_handler(StarletteHTTPException)
    async def _http_error(request: Request, exc: StarletteHTTPException) -> JSONResponse:
        if exc.status_code == 400 and exc.detail == _BODY_PARSE_ERROR:
            # FastAPI's answer to a body that json.loads cannot even start on: bytes that
            # are not UTF-8, or JSON nested deeper than the decoder's recursion limit
            reason = _body_reason(exc.__cause__)
            return error_response(422, "invalid_request", f"body: {reason}",
                                  [FieldError(field="body", reason=reason)])
        name = {404: "not_found", 405: "method_not_allowed",
                413: "payload_too_large"}.get(exc.status_code, "http_error")
        headers = dict(exc.headers) if exc.headers else {}
        if exc.status_code == 405:  # every method of the path (Starlette names one route's)
            headers["Allow"] = ", ".join(sorted(_allowed_methods(request)))
        return error_response(exc.status_code, name, str(exc.detail), headers=headers or None)

    @app.exception_handler(sqlite3.OperationalError)
    async def _store_error(request: Request, exc: sqlite3.OperationalError) -> JSONResponse:
        # the store is the service's memory: when it cannot be read or written (disk
        # full, read-only, locked past its timeout) the service is unavailable, not broken
        log.warning("job store error on %s %s: %s", request.method, request.url.path, exc)
        return error_response(503, "store_unavailable",
                              f"the job store cannot be used now: {exc}",
                              headers={"Retry-After": str(STORE_RETRY_AFTER)})

    @app.exception_handler(Exception)
    async def _unexpected(request: Request, exc: Exception) -> JSONResponse:
        log.exception("unexpected error on %s %s", request.method, request.url.path)
        return error_response(500, "internal_error",
                              f"unexpected {type(exc).__name__}; see the service log")
