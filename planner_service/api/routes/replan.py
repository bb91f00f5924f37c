"""``POST /v1/plans/{id}/replan``: the rest of a finished job's plan re-planned from a
measured state, for a controller executing it (docs/replanning.md "Through the service").

Answered synchronously from the service's re-plan processes
(:class:`~planner_service.jobs.replans.ReplanPool`: never a solver worker, which may be in
a plan of minutes, nor the API process), each keeping the re-planners of the plans it
re-planned last, so that a controller's calls are warm-started from its previous one.
404 for an unknown job; 409 for a job not finished, without a plan, or whose plan has no
re-plannable structure (a ball-on-palm plan, the greedy method's, a gait's); 422 naming
the field for a measurement that does not fit the plan (fingers, joints, a time after its
end) and for a state the grasp cannot explain (``unexplained_state``: a contact lost
names ``q[i]``, the object dropped ``object_position``, a measured contact elsewhere
``contact_points[i]``); 503 when the re-plan processes are busy or past their time.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from typing import Any

from fastapi import APIRouter, Request
from fastapi.responses import Response

from dexroll_client.models import ErrorBody, FieldError
from dexroll_client.replan import ReplanRequest, ReplanResult

from ...jobs.replans import ReplanPool, ReplanRefusedError
from ..access import OwnerDep
from ..body import JSONBodyRoute
from ..deps import ServiceError, StoreDep, finished_job

__all__ = ["router"]

router = APIRouter(route_class=JSONBodyRoute)

_RESPONSES: dict[int | str, dict[str, Any]] = {
    404: {"model": ErrorBody, "description": "no such job"},
    409: {"model": ErrorBody,
          "description": "the job has not finished, has no plan, or its plan has no "
                         "re-plannable structure (`not_replannable`: a ball-on-palm plan, "
                         "the greedy method's, a gait's)"},
    422: {"model": ErrorBody,
          "description": "a measurement that does not fit the plan (`invalid_request`), "
                         "or a state the grasp cannot explain (`unexplained_state`: a "
                         "contact lost, the object dropped); `detail` names the field"},
    503: {"model": ErrorBody,
          "description": "the re-plan processes are busy (Retry-After), or a re-plan went "
                         "past its time (its process replaced)"},
}

#: Planners whose plans are never re-planned (answered without asking a process).
_NOT_REPLANNABLE = {"ball_on_palm": "a ball-on-palm plan has no fingers: nothing to "
                                    "re-plan from joint angles"}


def _refused(exc: ReplanRefusedError) -> ServiceError:
    headers = None if exc.retry_after is None else {"Retry-After": str(exc.retry_after)}
    detail = [FieldError(field=f, reason=r) for f, r in exc.detail] or None
    return ServiceError(exc.status, exc.error, exc.message, detail, headers)


async def replannable_job(store: Any, job_id: str, owner: str | None, action: str
                          ) -> tuple[Any, Callable[[], tuple[str, str]]]:
    """A finished job whose plan a re-plan process can take (``finished_job``'s 404 and
    409s, and 409 ``not_replannable`` for a planner without one NLP to re-solve), and
    the function that reads its stored (result, request) JSON for a process that does not
    hold it yet (404 when it was purged since)."""
    row = finished_job(await asyncio.to_thread(store.head, job_id, owner), job_id, action)
    if row.planner in _NOT_REPLANNABLE:
        raise ServiceError(409, "not_replannable",
                           f"job {job_id}: {_NOT_REPLANNABLE[row.planner]}")

    def fetch() -> tuple[str, str]:
        full = store.get(job_id, owner)
        if full is None or full.result is None:
            raise ReplanRefusedError(404, "not_found", f"job {job_id} is gone (purged)")
        return full.result, full.request

    return row, fetch


@router.post("/v1/plans/{job_id}/replan", response_model=ReplanResult,
             responses=_RESPONSES)
async def replan_plan(job_id: str, body: ReplanRequest, request: Request, store: StoreDep,
                      owner: OwnerDep) -> Response:
    """Re-plan the rest of a finished job's plan from a measured state: the grasp's state
    nearest to the measurement (joints, object pose, optionally rates and contact
    locations), then the plan's NLP re-solved from it to the plan's goal, warm-started
    from this plan's previous re-plan (or the plan) shifted to `t`, within `max_iter`
    IPOPT iterations. The answer: the rest of the motion from `t` (`joint_trajectory`,
    `samples`) when it converged, and the re-plan's statistics. A plan's first re-plan
    builds its re-planner (seconds: `stats.setup_time`); later ones are warm. A state the
    grasp cannot explain is a 422 (`unexplained_state`) naming the field, never planned
    through."""
    row, fetch = await replannable_job(store, job_id, owner, "it can be re-planned")
    pool: ReplanPool = request.app.state.replans
    try:
        answer = await asyncio.get_running_loop().run_in_executor(
            pool.executor, pool.call, (job_id, row.finished_at), body.model_dump_json(),
            body.time_limit, fetch)
    except ReplanRefusedError as exc:
        raise _refused(exc) from exc
    # the process's JSON as it wrote it (a ReplanResult): not parsed again here
    return Response(answer, media_type="application/json")
