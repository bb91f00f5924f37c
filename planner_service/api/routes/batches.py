"""``/v1/batches``: many plan requests as one submission (docs/service.md, "Batches").

``POST /v1/batches`` checks every item as ``POST /v1/plans`` checks a request (a 422 names
each bad field as ``items[i].field``, and no job is made), then stores all its jobs in one
transaction; ``GET /v1/batches/{id}`` counts them by state; ``GET
/v1/batches/{id}/results`` streams them as NDJSON, one finished job (with its plan) a line,
in submission order or as they finish (``order``), until every one has ended;
``DELETE /v1/batches/{id}`` cancels those not yet ended. The jobs are ordinary jobs
(``GET /v1/plans/{id}`` each), their owner's."""

from __future__ import annotations

import asyncio
import time
from collections import Counter
from collections.abc import AsyncIterator
from datetime import UTC, datetime
from typing import Annotated, Literal

from fastapi import APIRouter, Query, Request, Response
from fastapi.responses import StreamingResponse

from dexroll_client.models import MAX_BATCH, Batch, BatchRequest, JobState

from ...jobs.store import JobRow, StorageError, Store
from ...planners.structure import structure_key
from ..access import OwnerDep
from ..body import JSONBodyRoute
from ..deps import (
    CheckerDep,
    DispatcherDep,
    ServiceError,
    SettingsDep,
    StoreDep,
    store_fault_error,
    unavailable_error,
)
from .plans import QUEUE_FULL_RETRY_AFTER, checked, invalid_request, job_model

__all__ = ["router"]

router = APIRouter(route_class=JSONBodyRoute)

#: How often a results stream looks for jobs that ended [s].
POLL = 0.2


def _batch_model(batch_id: str, created_at: float, size: int, rows: list[JobRow]) -> Batch:
    counts = Counter(r.state for r in rows)
    if len(rows) < size:
        counts["purged"] = size - len(rows)
    return Batch(id=batch_id, size=size, created_at=datetime.fromtimestamp(created_at, tz=UTC),
                 counts=dict(counts), done=all(JobState(r.state).terminal for r in rows),
                 job_ids=[r.id for r in rows])


def _batch(store: Store, batch_id: str, owner: str | None
           ) -> tuple[float, int, list[JobRow]]:
    found = store.batch(batch_id, owner)
    if found is None:
        raise ServiceError(404, "not_found", f"no batch {batch_id!r}")
    return found


@router.post("/v1/batches", status_code=201, response_model=Batch)
async def submit_batch(body: BatchRequest, request: Request, owner: OwnerDep,
                       settings: SettingsDep, store: StoreDep, dispatcher: DispatcherDep,
                       checker: CheckerDep) -> Batch:
    """Submit many plan requests at once (at most 1 000): each is checked as `POST
    /v1/plans` checks one (a 422 names every bad field as `items[i].field`, and then no
    job is made), then all become queued jobs together. 503 + Retry-After while the
    store cannot be written or the queue has no room for them."""
    refused = store_fault_error(store)
    if refused is not None:
        raise refused
    items, errors = [], []
    for i, item in enumerate(body.items):
        item, errs = await checked(item, request, store, checker, owner)
        items.append(item)
        errors += [(f"items[{i}].{f}", r) for f, r in errs]
    if errors:
        raise invalid_request(errors)
    room = settings.max_queue + MAX_BATCH - store.count("queued")
    if len(items) > room:
        raise ServiceError(503, "queue_full",
                           f"{store.count('queued')} jobs are queued: no room for "
                           f"{len(items)} more", headers={"Retry-After": str(
                               QUEUE_FULL_RETRY_AFTER)})
    refused = unavailable_error(dispatcher)
    if refused is not None:
        raise refused
    rows: list[tuple[str, str, float, str]] = []
    for item in items:
        capped = min(item.solver.time_limit, settings.max_time_limit)
        item = item.model_copy(update={"solver": item.solver.model_copy(
            update={"time_limit": capped})})
        rows.append((str(item.planner), item.model_dump_json(), capped,
                     structure_key(str(item.planner), item.model_dump(mode="json"))))
    try:
        batch_id, _ = store.create_batch(rows, owner or "")
    except StorageError as exc:
        raise store_fault_error(store) or ServiceError(
            503, "storage_error", str(exc), headers={"Retry-After": "5"}) from exc
    dispatcher.wake()
    return _batch_model(batch_id, *_batch(store, batch_id, owner))


@router.get("/v1/batches/{batch_id}", response_model=Batch)
def get_batch(batch_id: str, store: StoreDep, owner: OwnerDep) -> Batch:
    """A batch's progress: its jobs by state, whether all have ended, their ids."""
    return _batch_model(batch_id, *_batch(store, batch_id, owner))


@router.get("/v1/batches/{batch_id}/results",
            responses={200: {"content": {"application/x-ndjson": {}},
                             "description": "one finished job (with its plan) a line"}})
def batch_results(batch_id: str, store: StoreDep, owner: OwnerDep,
                  order: Annotated[Literal["submission", "finished"], Query(description=(
                      "submission: the jobs in the batch's order, each when it has ended; "
                      "finished: each as soon as it ends"))] = "submission",
                  result: Annotated[bool, Query(description=(
                      "false: the jobs without their plans"))] = True) -> Response:
    """The batch's jobs as NDJSON, one ended job a line (as `GET /v1/plans/{id}` answers
    it), streamed until every one has ended: in submission order or as they finish. A job
    purged meanwhile is a line `{"id": ..., "state": "purged"}`."""
    _, _, first = _batch(store, batch_id, owner)
    ids = [r.id for r in first]

    async def lines() -> AsyncIterator[bytes]:
        sent: set[str] = set()
        while len(sent) < len(ids):
            found = await asyncio.to_thread(store.batch, batch_id, owner)
            rows = {r.id: r for r in (found[2] if found is not None else [])}
            ready = []
            for job_id in ids:
                if job_id in sent:
                    continue
                row = rows.get(job_id)
                ended = row is None or JobState(row.state).terminal
                if not ended and order == "submission":
                    break
                if ended:
                    ready.append((job_id, row))
            if order == "finished":
                ready.sort(key=lambda jr: (jr[1].finished_at or 0.0) if jr[1] else 0.0)
            for job_id, row in ready:
                sent.add(job_id)
                if row is None:
                    yield (f'{{"id":"{job_id}","state":"purged"}}\n').encode()
                    continue
                full = store.get(job_id) if result else row
                yield job_model(full or row).model_dump_json().encode() + b"\n"
            if len(sent) < len(ids):
                await asyncio.sleep(POLL)

    return StreamingResponse(lines(), media_type="application/x-ndjson")


@router.delete("/v1/batches/{batch_id}", response_model=Batch)
async def cancel_batch(batch_id: str, store: StoreDep, dispatcher: DispatcherDep,
                       owner: OwnerDep) -> Batch:
    """Cancel the batch's jobs that have not ended (queued ones at once, running ones
    stopped by their worker); the batch as it is then."""
    _, _, rows = _batch(store, batch_id, owner)
    running = [r.id for r in rows if r.state == "running"]
    for r in rows:
        if r.state == "queued" and not store.cancel_queued(r.id):
            running.append(r.id)  # claimed meanwhile
    for job_id in running:
        dispatcher.cancel_running(job_id)
    deadline = time.monotonic() + 10.0
    while running and time.monotonic() < deadline:  # the workers' answers
        _, _, rows = _batch(store, batch_id, owner)
        if all(JobState(r.state).terminal for r in rows if r.id in running):
            break
        await asyncio.sleep(POLL)
    return _batch_model(batch_id, *_batch(store, batch_id, owner))
