"""``/v1/plans``: submit a planning request, fetch a job, list jobs, cancel a job."""

from __future__ import annotations

import asyncio
from contextlib import suppress
from datetime import UTC, datetime
from typing import Annotated

from fastapi import APIRouter, Header, Query, Response

from dexroll_client.models import FieldError, Job, JobList, JobState, PlanRequest

from ...jobs.store import IdempotencyConflictError, JobRow, Store
from ...models_check import CheckerBusyError
from ...planners import RESULT
from ..deps import CheckerDep, DispatcherDep, NotifierDep, ServiceError, SettingsDep, StoreDep
from ..submission import StoreUnavailableError, submission_errors
from .view import LinkedJob, with_links

__all__ = ["job_model", "router"]

router = APIRouter()

#: The largest ``offset`` of a job listing: SQLite's integers are 64-bit signed.
MAX_OFFSET = 2**63 - 1


def _ts(t: float | None) -> datetime | None:
    return datetime.fromtimestamp(t, tz=UTC) if t is not None else None


def job_model(row: JobRow) -> LinkedJob:
    """The wire job of a stored one, with its links (the plan's view)."""
    return with_links(_job(row))


def _job(row: JobRow) -> Job:
    """The wire job of a stored one."""
    return Job(id=row.id, state=JobState(row.state), code=row.code, message=row.message,
               raw_status=row.raw_status, planner=row.planner,
               created_at=datetime.fromtimestamp(row.created_at, tz=UTC),
               started_at=_ts(row.started_at), finished_at=_ts(row.finished_at),
               worker_pid=row.worker_pid,
               result=RESULT.validate_json(row.result) if row.result else None)


def _row(store: Store, job_id: str) -> JobRow:
    row = store.get(job_id)
    if row is None:
        raise ServiceError(404, "not_found", f"no job {job_id!r}")
    return row


@router.post("/v1/plans", status_code=201, response_model=LinkedJob,
             responses={202: {"model": Job, "description": "accepted; poll Location"}})
async def submit_plan(
    body: PlanRequest,
    response: Response,
    settings: SettingsDep,
    store: StoreDep,
    dispatcher: DispatcherDep,
    notifier: NotifierDep,
    checker: CheckerDep,
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
        body, errors = await asyncio.to_thread(submission_errors, body, store, checker)
    except CheckerBusyError as exc:
        raise ServiceError(503, "checker_busy", f"the service is checking other model files: "
                           f"{exc}", headers={"Retry-After": "2"}) from exc
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
    if store.count("queued") >= settings.max_queue:
        raise ServiceError(503, "queue_full",
                           f"{settings.max_queue} jobs are already queued",
                           headers={"Retry-After": "5"})
    try:
        row, created = store.create(body.planner, body.model_dump_json(), capped,
                                    idempotency_key)
    except IdempotencyConflictError as exc:
        raise ServiceError(409, "idempotency_conflict", str(exc)) from exc
    if created:
        dispatcher.wake()
    if not JobState(row.state).terminal:
        event = notifier.register(row.id)
        try:
            row = store.get(row.id) or row
            if not JobState(row.state).terminal:
                timeout = min(settings.default_wait if wait is None else wait,
                              settings.max_wait)
                with suppress(TimeoutError):
                    await asyncio.wait_for(event.wait(), timeout=timeout)
                row = store.get(row.id) or row
        finally:
            notifier.unregister(row.id, event)
    if not JobState(row.state).terminal:
        response.status_code = 202
        response.headers["Location"] = f"/v1/plans/{row.id}"
        response.headers["Retry-After"] = "1"
    return job_model(row)


@router.get("/v1/plans/{job_id}", response_model=LinkedJob)
def get_plan(job_id: str, response: Response, store: StoreDep) -> Job:
    """A job: its state, and its plan once finished."""
    row = _row(store, job_id)
    if not JobState(row.state).terminal:
        response.headers["Retry-After"] = "1"
    return job_model(row)


@router.get("/v1/plans", response_model=JobList)
def list_plans(store: StoreDep,
               limit: Annotated[int, Query(ge=1, le=500)] = 50,
               offset: Annotated[int, Query(ge=0, le=MAX_OFFSET)] = 0) -> JobList:
    """Jobs, newest first, without their plans."""
    rows, total = store.list(limit, offset)
    nxt = offset + len(rows) if offset + len(rows) < total else None
    return JobList(items=[job_model(r) for r in rows], total=total, limit=limit,
                   offset=offset, next_offset=nxt)


@router.delete("/v1/plans/{job_id}", response_model=LinkedJob)
async def cancel_plan(job_id: str, store: StoreDep, dispatcher: DispatcherDep,
                      notifier: NotifierDep) -> Job:
    """Cancel a queued or running job; 409 if it has already finished."""
    row = _row(store, job_id)
    if JobState(row.state).terminal:
        raise ServiceError(409, "already_finished",
                           f"job {job_id} already ended: {row.state}")
    if not store.cancel_queued(job_id):
        event = notifier.register(job_id)
        try:
            dispatcher.cancel_running(job_id)
            with suppress(TimeoutError):
                await asyncio.wait_for(event.wait(), timeout=10.0)
        finally:
            notifier.unregister(job_id, event)
    return job_model(_row(store, job_id))
