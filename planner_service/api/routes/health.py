"""``/healthz`` (liveness) and ``/readyz`` (readiness)."""

from __future__ import annotations

import contextlib
from typing import Any

from fastapi import APIRouter, Request

from dexroll_client.models import ErrorBody

from ..deps import STORE_RETRY_AFTER, DispatcherDep, StoreDep, error_response

__all__ = ["router"]

router = APIRouter()

#: /readyz writes one row to the store at most this often [s] to see that it can be
#: written (before, a read-only store was reported only after a job's write had failed)
READY_PROBE_AGE = 1.0


@router.get("/healthz")
async def healthz() -> dict[str, str]:
    """Liveness: the process answers (on the event loop itself, never queued behind the
    thread pool that the other routes share)."""
    return {"status": "ok"}


@router.get("/readyz", responses={503: {"model": ErrorBody}})
def readyz(request: Request, store: StoreDep, dispatcher: DispatcherDep) -> Any:
    """Readiness: the job store answers and can be written, the dispatcher runs, and at
    least one worker is ready."""
    retry = {"Retry-After": str(STORE_RETRY_AFTER)}
    try:
        queued = store.count("queued")
        if store.fault is None:  # a read-only or full store, found now (a faulted one is
            # the dispatcher's to probe and resume); a probe that fails otherwise (a busy
            # store) is no fault: readiness goes by the recorded fault alone
            with contextlib.suppress(Exception):
                store.probe_if_stale(READY_PROBE_AGE)
    except Exception as exc:  # the store is the service's memory: not ready without it
        return error_response(503, "not_ready", f"job store unavailable: {exc}",
                              headers=retry)
    if store.fault is not None:
        return error_response(503, "not_ready", f"the job store cannot be written "
                              f"({store.fault}); new jobs are refused until it can",
                              headers=retry)
    if not dispatcher.is_alive():
        return error_response(503, "not_ready", "the dispatcher is not running")
    workers = dispatcher.ready_workers
    if workers < 1:
        reason = dispatcher.executor.unavailable()
        return error_response(503, "not_ready", "no solver worker is ready yet" + (
            f": {reason}" if reason else ""), headers={"Retry-After": "1"})
    simulations = request.app.state.simulations.stats()
    return {"status": "ready", "workers": workers, "queued": queued,
            "simulations": simulations, "executor": dispatcher.executor.describe(),
            "cache": dict(dispatcher.cache), "requeued": dispatcher.requeued,
            "dispatch": dispatcher.dispatch()}
