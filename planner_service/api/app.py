"""The HTTP API (FastAPI), versioned under /v1. OpenAPI docs at /docs.

POST /v1/plans           submit a planning request; 201 + the finished job when it ends
                         within ?wait= seconds, else 202 + Location to poll
GET  /v1/plans/{id}      a job (with its plan once finished)
GET  /v1/plans           jobs, newest first, paginated (?limit=&offset=)
DELETE /v1/plans/{id}    cancel a queued or running job
GET  /v1/models          built-in objects, fingers (with URDFs), hands and planners
POST /v1/plans/{id}/simulation  execute a finished plan in MuJoCo; GET: the stored report
POST /v1/plans/{id}/replan      the rest of a finished plan re-planned from a measured state
WS   /v1/plans/{id}/control     a controller session: each measurement, the next window
POST /v1/batches         many plan requests as one batch (every item checked first)
GET  /v1/batches/{id}    its jobs by state; /results: the jobs as NDJSON as they end
DELETE /v1/batches/{id}  cancel its jobs that have not ended
GET  /healthz, /readyz   liveness; readiness (store writable, a worker ready)

Every error is an ``ErrorBody`` (no traceback ever leaves the service); an invalid request
is a 422 naming each bad field; a failed solve is a finished job with its typed status.

A request's ``warm_start.job_id`` is resolved at submission: the job's plan (its result's
``collocation`` block) replaces it before the new job is stored, so that every stored job
is self-contained (a worker never looks another job up).
"""

from __future__ import annotations

import logging
from collections.abc import AsyncIterator, Awaitable, Callable, MutableMapping
from contextlib import asynccontextmanager
from typing import Any

from fastapi import FastAPI
from starlette.exceptions import HTTPException as StarletteHTTPException

from ..executors import executor
from ..jobs.replans import ReplanPool
from ..jobs.simulations import SimulationPool
from ..jobs.store import Store
from ..jobs.workers import Dispatcher
from ..models_check import ModelChecker
from ..settings import Settings
from .access import Access
from .deps import ERROR_RESPONSES, Notifier, add_error_handlers, error_response
from .routes import batches, control, health, models, plans, replan, simulation, view
from .submission import ModelSubmissions

__all__ = ["BodyLimit", "create_app"]

log = logging.getLogger("dexroll.service")


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
        too_large = error_response(413, "payload_too_large",
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


def create_app(settings: Settings | None = None) -> FastAPI:
    """The service: job store, worker pool and API, configured by ``settings``."""
    settings = settings or Settings()

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        store = Store(settings.db_path)
        requeued, failed = store.recover()
        if requeued or failed:
            log.info("recovered the job store: %d re-queued, %d failed", requeued, failed)

        def purge() -> None:  # retention: at start, then every minute (dispatcher thread)
            purged = store.purge(settings.retention_days, settings.max_jobs)
            if purged:
                log.info("retention: %d finished jobs purged (DEXROLL_RETENTION_DAYS=%g, "
                         "DEXROLL_MAX_JOBS=%d)", purged, settings.retention_days,
                         settings.max_jobs)

        purge()
        notifier: Notifier = app.state.notifier
        # where the heavy work runs: local processes, or Ray actors (one bridge for all)
        work = executor(settings.executor, settings.ray_address)
        dispatcher = Dispatcher(
            store, settings.workers, settings.kill_grace, notifier.notify, settings.warmup,
            None if settings.compile_dir is None else str(settings.compile_dir.resolve()),
            settings.max_result_bytes, warmup_first=settings.warmup_first,
            executor=work,
            retries=settings.retries)
        dispatcher.housekeeping = purge
        dispatcher.start()
        checker = ModelChecker(settings.model_limits(), settings.model_checkers)
        simulations = SimulationPool(settings.sim_processes, settings.sim_queue,
                                     settings.sim_time_limit, settings.sim_cpu_seconds, work)
        app.state.replans = replans = ReplanPool(
            settings.replan_processes, settings.replan_cache, settings.replan_queue,
            settings.replan_time_limit, settings.replan_setup_limit, work)
        app.state.store, app.state.dispatcher = store, dispatcher
        app.state.checker, app.state.simulations = checker, simulations
        app.state.model_submissions = submissions = ModelSubmissions(settings.model_checkers,
                                                                settings.max_queue)
        # the viewer's pages are built (a request's models loaded) under the same limits,
        # in a process of their own started by the first view asked for
        app.state.viewer = viewer = ModelChecker(settings.model_limits(), 1, lazy=True)
        try:
            yield
        finally:
            viewer.close()
            replans.close()
            submissions.close()
            simulations.close()
            checker.close()
            dispatcher.stop()
            work.close()
            store.close()

    app = FastAPI(title="dexroll", version="0.1.0", lifespan=lifespan,
                  description=__doc__, responses=ERROR_RESPONSES)
    app.state.settings, app.state.notifier = settings, Notifier()
    add_error_handlers(app)
    for routes in (plans, batches, models, health, view, simulation, replan, control):
        app.include_router(routes.router)
    app.add_middleware(BodyLimit, limit=settings.max_body_bytes)
    # outermost: a request from a host not served, or without a key, goes no further
    app.add_middleware(Access, keys=settings.keys(), hosts=settings.hosts())
    return app
