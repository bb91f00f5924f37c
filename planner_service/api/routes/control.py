"""``WebSocket /v1/plans/{id}/control``: a controller session on a finished job's rolling
plan (docs/control.md "Through the service").

The robot sends each tick's measurement (``dexroll_client.control.ControlMeasurement``,
one JSON text message) and gets the tick's answer (``ControlAnswer``: the next window of
the plan from that state, the tick's status and KKT residuals, the service's times) or
an error message (``{"error", "message", "detail": [{"field", "reason"}]}``: a
measurement that does not fit the plan, a state the grasp cannot explain, a busy or
failed process), after which the session goes on. The ticks run in the re-plan
processes (:class:`~planner_service.jobs.replans.ReplanPool`, kind "control"), which keep
each plan's :class:`ocp.WindowController` (its NLP, the previous window's point) from
tick to tick; the first tick builds it (seconds). ``?backend=`` picks its solver (ipopt,
the default; rti; auto: :class:`ocp.ControllerOptions`'). Before the handshake the job is
checked:
closed with 1008 (policy) and the reason for an unknown job, one not finished or not
re-plannable; the API key and Host as for every route (``Access``).
"""

from __future__ import annotations

import asyncio
import json

from fastapi import APIRouter, WebSocket, WebSocketDisconnect
from pydantic import ValidationError

from dexroll_client.control import ControlMeasurement

from ...jobs.replans import ReplanPool, ReplanRefusedError
from ..deps import ServiceError
from .replan import replannable_job

__all__ = ["router"]

router = APIRouter()

#: A tick's IPOPT time limit in the process (the window controller's own is 1 s) [s]
TICK_TIME_LIMIT = 1.0


def _error(error: str, message: str, detail: list[tuple[str, str]] | None = None) -> str:
    return json.dumps({"error": error, "message": message,
                       "detail": [{"field": f, "reason": r} for f, r in detail or []]})


#: The window controller's solvers a session may ask for (``?backend=``; docs/control.md)
BACKENDS = ("ipopt", "rti", "auto")


@router.websocket("/v1/plans/{job_id}/control")
async def control_plan(websocket: WebSocket, job_id: str, backend: str = "ipopt") -> None:
    store = websocket.app.state.store
    owner = getattr(websocket.state, "owner", None)
    if backend not in BACKENDS:
        await websocket.close(code=1008, reason=f"invalid_request: backend: one of "
                                                f"{', '.join(BACKENDS)}, not {backend!r}"[:120])
        return
    try:
        row, fetch = await replannable_job(store, job_id, owner, "it can be controlled")
    except ServiceError as exc:
        await websocket.close(code=1008, reason=f"{exc.error}: {exc.message}"[:120])
        return

    pool: ReplanPool = websocket.app.state.replans
    loop = asyncio.get_running_loop()
    await websocket.accept()
    try:
        while True:
            text = await websocket.receive_text()
            try:
                body = ControlMeasurement.model_validate_json(text)
            except ValidationError as exc:
                detail = [(".".join(str(p) for p in e["loc"]) or "body", e["msg"])
                          for e in exc.errors()]
                await websocket.send_text(_error("invalid_request", "the measurement is "
                                                 "not a ControlMeasurement", detail))
                continue
            try:
                answer = await loop.run_in_executor(
                    pool.executor, pool.call, (job_id, row.finished_at, backend),
                    body.model_dump_json(), TICK_TIME_LIMIT, fetch, "control")
            except ReplanRefusedError as exc:
                await websocket.send_text(_error(exc.error, exc.message, exc.detail))
                continue
            await websocket.send_text(answer)
    except WebSocketDisconnect:
        return
