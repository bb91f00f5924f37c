"""``/v1/plans/{id}/view``: a finished job's plan as an animated 3D page (docs/viewer.md),
and the ``links`` a job's JSON carries to it."""

from __future__ import annotations

import threading
from collections import OrderedDict
from typing import Any

from fastapi import APIRouter, Request
from fastapi.responses import HTMLResponse
from pydantic import BaseModel, Field

from dexroll_client.models import Job

from ...models_check import CheckerBusyError, ModelChecker, Task, TaskError, TaskLimitError
from ...view import has_plan
from ...view.page import content_security_policy
from ..access import OwnerDep
from ..deps import ERROR_RESPONSES, ServiceError, StoreDep, finished_job

__all__ = ["JobLinks", "LinkedJob", "router", "with_links"]

router = APIRouter()

#: Pages kept ready (the last ones asked for), by job id and end time.
CACHED_PAGES = 8
_pages: OrderedDict[tuple[str, float | None], tuple[str, str]] = OrderedDict()
_lock = threading.Lock()


class JobLinks(BaseModel):
    view: str | None = Field(default=None, description="the plan's animated 3D view (an "
                                                       "HTML page; null until the job has "
                                                       "finished with a plan)")


class LinkedJob(Job):
    links: JobLinks = Field(default_factory=JobLinks,
                            description="related resources of the job")


def with_links(job: Job) -> LinkedJob:
    """The job with its links (``links.view`` once it has a plan to show)."""
    view = f"/v1/plans/{job.id}/view" if job.state.terminal and job.result is not None \
        and has_plan(job.result) else None
    return LinkedJob(**dict(job), links=JobLinks(view=view))


#: The page is HTML, its errors the service's JSON ErrorBody: documented so (a route's
#: response class would otherwise give the errors its text/html media type).
_ERROR_JSON = {"application/json": {"schema": {"$ref": "#/components/schemas/ErrorBody"}}}
VIEW_RESPONSES: dict[int | str, dict[str, Any]] = {
    **{code: {"description": r["description"], "content": _ERROR_JSON}
       for code, r in ERROR_RESPONSES.items()},
    200: {"content": {"text/html": {"schema": {"type": "string"}}},
          "description": "one self-contained page (no other request)",
          "headers": {"Content-Security-Policy": {
              "description": "default-src 'none': the page's own inline scripts and style "
                             "(by their SHA-256 hashes) and a data: icon, nothing else",
              "schema": {"type": "string"}}}},
    409: {"description": "the job has not finished, or ended without a plan, or its plan "
                         "cannot be drawn within the service's model limits",
          "content": _ERROR_JSON}}


@router.get("/v1/plans/{job_id}/view", response_class=HTMLResponse,
            responses=VIEW_RESPONSES)
def view_plan(job_id: str, request: Request, store: StoreDep, owner: OwnerDep
              ) -> HTMLResponse:
    """A finished job's plan as an animated 3D page: the palm, the object, the fingers
    from their own models, the contacts and their traces, a timeline. The page is
    self-contained (three.js and the plan inlined): save it to view it offline. 409 while
    the job runs, or when it ended without a plan. The page is built in a process of its
    own under the model checker's time and memory limits (409 past them)."""
    # with API keys, another owner's job is unknown here
    row = finished_job(store.get(job_id, owner), job_id, "its view is ready", plan=None)
    key = (row.id, row.finished_at)
    with _lock:
        cached = _pages.get(key)
        if cached is not None:
            _pages.move_to_end(key)
    if cached is None:
        if row.result is None:
            raise ServiceError(409, "no_plan", f"job {job_id} ended ({row.state}) without "
                                               "a plan to show")
        page = _page(request.app.state.viewer, job_id, row.state, row.result, row.request)
        cached = page, content_security_policy(page, header=True)
        with _lock:
            _pages[key] = cached
            while len(_pages) > CACHED_PAGES:
                _pages.popitem(last=False)
    page, policy = cached
    return HTMLResponse(page, headers={"Content-Security-Policy": policy})


def _page(viewer: ModelChecker, job_id: str, state: str, result: str, plan_request: str
          ) -> str:
    """The page of a job, built in a viewer process (the request's models are loaded
    there, under the model checker's limits)."""
    try:
        page: str = viewer.call(Task("view", (result, plan_request, f"job {job_id}")))
    except TaskError as exc:
        if exc.kind not in ("NoPlanError", "ProblemError"):
            raise ServiceError(500, "internal_error", f"the viewer failed: {exc.kind}") \
                from exc
        raise ServiceError(409, "no_plan", f"job {job_id} ended ({state}) without a plan "
                                           f"to show: {exc.message}") from exc
    except TaskLimitError as exc:
        raise ServiceError(409, "not_viewable", f"job {job_id}'s plan cannot be drawn "
                                                f"within the model limits: {exc}") from exc
    except CheckerBusyError as exc:
        raise ServiceError(503, "viewer_busy", f"the viewer is busy: {exc}",
                           headers={"Retry-After": "2"}) from exc
    return page
