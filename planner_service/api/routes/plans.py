"""``/v1/plans``: submit a planning request, fetch a job, list jobs, cancel a job.

A job's plan is served as the worker stored it (compact JSON, read from SQLite in chunks
and streamed after the job's own fields): never parsed again, so that many reads of a
large plan cost the API little memory and no interpreter time. ``?result=false`` serves a
job without its plan (``result_bytes`` says how large it is). Jobs are their owner's
(:mod:`..access`): another owner's job is a 404."""

from __future__ import annotations

import asyncio
from collections.abc import Iterator
from contextlib import suppress
from datetime import UTC, datetime
from typing import Annotated, Any

from fastapi import APIRouter, Header, Query, Request, Response
from fastapi.responses import StreamingResponse

from dexroll_client.models import FieldError, Job, JobList, JobState, PlanRequest

from ...jobs.store import IdempotencyConflictError, JobRow, StorageError, Store
from ...models_check import CheckerBusyError
from ...planners import RESULT
from ...planners.structure import structure_key
from ..access import OwnerDep
from ..body import JSONBodyRoute
from ..deps import (
    CheckerDep,
    DispatcherDep,
    NotifierDep,
    ServiceError,
    SettingsDep,
    StoreDep,
    store_fault_error,
    unavailable_error,
)
from ..submission import (
    ModelSubmissions,
    StoreUnavailableError,
    checked_apart,
    submission_errors,
)
from .view import JobLinks, LinkedJob, with_links

__all__ = ["checked", "invalid_request", "job_model", "router"]

router = APIRouter(route_class=JSONBodyRoute)

#: The largest ``offset`` of a job listing: SQLite's integers are 64-bit signed.
MAX_OFFSET = 2**63 - 1
#: Retry-After of a full queue [s]: shorter than uvicorn's keep-alive (``dexroll serve``
#: keeps idle connections 15 s), so that a client's retry does not race the server
#: closing its connection.
QUEUE_FULL_RETRY_AFTER = 2


def _ts(t: float | None) -> datetime | None:
    return datetime.fromtimestamp(t, tz=UTC) if t is not None else None


def job_model(row: JobRow) -> LinkedJob:
    """The wire job of a stored one, with its links (the plan's view)."""
    if row.result is None and row.has_plan is not None:  # a row read without its result
        job = _job(row)
        view = f"/v1/plans/{row.id}/view" if job.state.terminal and row.has_plan else None
        return LinkedJob(**dict(job), links=JobLinks(view=view))
    return with_links(_job(row))


def job_response(row: JobRow, store: Store, status_code: int = 200,
                 headers: dict[str, str] | None = None, with_result: bool = True
                 ) -> Response:
    """A job as JSON, its stored plan streamed as it was stored (``row`` read without it:
    :meth:`Store.head`)."""
    body = job_model(row).model_dump_json()
    if not (with_result and row.result_bytes):
        return Response(body, status_code, headers, media_type="application/json")
    at = body.index(_NO_RESULT)  # the top-level field: nothing before it nests
    head, tail = body[:at + len('"result":')].encode(), body[at + len(_NO_RESULT):].encode()

    def chunks() -> Iterator[bytes]:
        yield head
        sent = False
        for chunk in store.result_chunks(row.id):
            sent = True
            yield chunk
        yield tail if sent else b"null" + tail  # purged meanwhile: no plan

    return StreamingResponse(chunks(), status_code, headers, media_type="application/json")


#: How a job without its plan says so in its JSON.
_NO_RESULT = '"result":null'


def _job(row: JobRow) -> Job:
    """The wire job of a stored one."""
    return Job(id=row.id, state=JobState(row.state), code=row.code, message=row.message,
               raw_status=row.raw_status, planner=row.planner,
               created_at=datetime.fromtimestamp(row.created_at, tz=UTC),
               started_at=_ts(row.started_at), finished_at=_ts(row.finished_at),
               worker_pid=row.worker_pid, result_bytes=row.result_bytes,
               result=RESULT.validate_json(row.result) if row.result else None)


def _row(store: Store, job_id: str, owner: str | None) -> JobRow:
    """A job without its result (``owner``'s; None: anyone's); 404 otherwise."""
    row = store.head(job_id, owner)
    if row is None:
        raise ServiceError(404, "not_found", f"no job {job_id!r}")
    return row


async def checked(body: PlanRequest, request: Request, store: Store, checker: Any,
                  owner: str | None) -> tuple[PlanRequest, list[tuple[str, str]]]:
    """A request checked as a submission is (:func:`~..submission.submission_errors`):
    cheap checks in a thread, a request carrying a model or searching a grasp in a checker
    process, waiting in threads of its own (the others never wait behind those); a warm
    start's job id replaced by that job's plan. The request and its (field, reason)
    errors; a busy checker or an unreadable store is a 503."""
    models: ModelSubmissions = request.app.state.model_submissions
    run = models.run if checked_apart(body) else asyncio.to_thread
    try:
        return await run(submission_errors, body, store, checker, owner)
    except CheckerBusyError as exc:
        raise ServiceError(503, "checker_busy", f"the service is checking other model files: "
                           f"{exc}", headers={"Retry-After": "2"}) from exc
    except StoreUnavailableError as exc:
        raise ServiceError(503, "store_unavailable", f"the job store cannot be read to "
                           f"look up warm_start.job_id: {exc}",
                           headers={"Retry-After": "1"}) from exc


#: The most fields a 422 of a submission lists.
MAX_FIELD_ERRORS = 50


def invalid_request(errors: list[tuple[str, str]]) -> ServiceError:
    """The 422 of a submission's (field, reason) errors (the first
    :data:`MAX_FIELD_ERRORS`)."""
    shown = errors[:MAX_FIELD_ERRORS]
    return ServiceError(422, "invalid_request", "; ".join(f"{f}: {r}" for f, r in shown),
                        [FieldError(field=f, reason=r) for f, r in shown])


@router.post("/v1/plans", status_code=201, response_model=LinkedJob,
             responses={202: {"model": LinkedJob, "description": "accepted; poll Location"}})
async def submit_plan(
    body: PlanRequest,
    request: Request,
    owner: OwnerDep,
    settings: SettingsDep,
    store: StoreDep,
    dispatcher: DispatcherDep,
    notifier: NotifierDep,
    checker: CheckerDep,
    wait: Annotated[float | None, Query(ge=0.0, le=600.0, allow_inf_nan=False, description=(
        "seconds to wait for the plan before answering 202 (capped by the service)"))
    ] = None,
    idempotency_key: Annotated[str | None, Header(max_length=200, description=(
        "a retried POST with the same key returns the same job (the key is its owner's)"))
    ] = None,
) -> Response:
    """Submit a planning request (`planner` picks the planner: `ball_on_palm`, the
    default, `one_finger` or `manipulation`): 201 with the finished job, or 202 and a
    Location. 503 + Retry-After while the job store cannot be written (disk full,
    read-only)."""
    refused = store_fault_error(store)
    if refused is not None:
        raise refused
    # cheap checks (no NLP): a finger's URDF and the inverse kinematics of its initial
    # grasp take milliseconds; a warm start's job id is replaced by that job's plan (the
    # new job is self-contained)
    body, errors = await checked(body, request, store, checker, owner)
    if errors:
        raise invalid_request(errors)
    capped = min(body.solver.time_limit, settings.max_time_limit)
    body = body.model_copy(update={"solver": body.solver.model_copy(
        update={"time_limit": capped})})
    refused = store_fault_error(store)  # faulted while the request was checked
    if refused is not None:
        raise refused
    refused = unavailable_error(dispatcher)
    if refused is not None:
        raise refused
    if store.count("queued") >= settings.max_queue:
        raise ServiceError(503, "queue_full",
                           f"{settings.max_queue} jobs are already queued",
                           headers={"Retry-After": str(QUEUE_FULL_RETRY_AFTER)})
    try:
        row, created = store.create(body.planner, body.model_dump_json(), capped,
                                    idempotency_key, owner or "",
                                    structure_key(body.planner, body.model_dump(mode="json")))
    except IdempotencyConflictError as exc:
        raise ServiceError(409, "idempotency_conflict", str(exc)) from exc
    except StorageError as exc:  # the store faulted on this very write
        raise store_fault_error(store) or ServiceError(
            503, "storage_error", str(exc), headers={"Retry-After": "5"}) from exc
    if created:
        dispatcher.wake()
    if not JobState(row.state).terminal:
        event = notifier.register(row.id)
        try:
            row = store.head(row.id) or row
            if not JobState(row.state).terminal:
                timeout = min(settings.default_wait if wait is None else wait,
                              settings.max_wait)
                with suppress(TimeoutError):
                    await asyncio.wait_for(event.wait(), timeout=timeout)
        finally:
            notifier.unregister(row.id, event)
    row = store.head(row.id) or row
    if not JobState(row.state).terminal:
        return job_response(row, store, 202, {"Location": f"/v1/plans/{row.id}",
                                              "Retry-After": "1"})
    return job_response(row, store, 201)


@router.get("/v1/plans/{job_id}", response_model=LinkedJob)
def get_plan(job_id: str, store: StoreDep, owner: OwnerDep,
             result: Annotated[bool, Query(description=(
                 "false: the job without its plan (`result_bytes` says how large it "
                 "is)"))] = True) -> Response:
    """A job: its state, and its plan once finished (as stored: the JSON the worker
    wrote, streamed)."""
    row = _row(store, job_id, owner)
    headers = None if JobState(row.state).terminal else {"Retry-After": "1"}
    return job_response(row, store, 200, headers, with_result=result)


@router.get("/v1/plans", response_model=JobList)
def list_plans(store: StoreDep, owner: OwnerDep,
               limit: Annotated[int, Query(ge=1, le=500)] = 50,
               offset: Annotated[int, Query(ge=0, le=MAX_OFFSET)] = 0) -> JobList:
    """Jobs (the API key's, with keys), newest first, without their plans."""
    rows, total = store.list(limit, offset, owner)
    nxt = offset + len(rows) if offset + len(rows) < total else None
    return JobList(items=[job_model(r) for r in rows], total=total, limit=limit,
                   offset=offset, next_offset=nxt)


@router.delete("/v1/plans/{job_id}", response_model=LinkedJob)
async def cancel_plan(job_id: str, store: StoreDep, dispatcher: DispatcherDep,
                      notifier: NotifierDep, owner: OwnerDep) -> Response:
    """Cancel a queued or running job; 409 if it has already finished."""
    row = _row(store, job_id, owner)
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
    return job_response(_row(store, job_id, owner), store)
