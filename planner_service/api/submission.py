"""What ``POST /v1/plans`` checks before it stores a job: the request's every error, and
its ``warm_start.job_id`` resolved (the job's plan, its result's ``collocation`` block,
replaces it, so that every stored job is self-contained: a worker never looks another job
up)."""

from __future__ import annotations

import asyncio
import logging
import threading
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import TypeVar

from pydantic import ValidationError

from dexroll_client.models import AnyPlanResult, JobState, PlanRequest, WarmStartModel

from ..jobs.store import Store
from ..models_check import (
    CheckerBusyError,
    ModelChecker,
    Task,
    TaskError,
    TaskLimitError,
    request_models,
)
from ..planners import RESULT, request_errors

__all__ = [
    "REQUEST_CHECK_SECONDS",
    "ModelSubmissions",
    "StoreUnavailableError",
    "checked_apart",
    "model_errors",
    "resolve_warm_start",
    "submission_errors",
]

log = logging.getLogger("dexroll.service")

T = TypeVar("T")


class ModelSubmissions:
    """Where the checks of a submission checked apart (:func:`checked_apart`: a model, a
    grasp search) wait for a checker process: threads of their own (one more than the
    checker processes: one reads the store for a warm start while the others wait), at
    most ``bound`` submissions waiting (beyond: CheckerBusyError, a 503 with Retry-After).
    Any other submission never waits behind them: its checks run in the event loop's
    default threads."""

    def __init__(self, checkers: int, bound: int) -> None:
        self._pool = ThreadPoolExecutor(checkers + 1, thread_name_prefix="dexroll-models")
        self._lock = threading.Lock()
        self._waiting = 0
        self.bound = bound

    async def run(self, fn: Callable[..., T], *args: object) -> T:
        """``fn(*args)`` in these threads (CheckerBusyError when ``bound`` wait already)."""
        with self._lock:
            if self._waiting >= self.bound:
                raise CheckerBusyError(f"{self.bound} requests with models are waiting for "
                                       "their checks")
            self._waiting += 1
        try:
            return await asyncio.get_running_loop().run_in_executor(self._pool, fn, *args)
        finally:
            with self._lock:
                self._waiting -= 1

    def close(self) -> None:
        self._pool.shutdown(wait=False, cancel_futures=True)


class StoreUnavailableError(Exception):
    """The job store could not be read."""


def resolve_warm_start(body: PlanRequest, store: Store, owner: str | None = None
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
        row = store.get(job_id, owner)  # another owner's job is unknown here
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


def model_errors(body: PlanRequest, checker: ModelChecker | None
                 ) -> list[tuple[str, str]]:
    """The errors of every model text the request carries (a finger's URDF), each checked
    in an isolated process by ``checker`` before this process loads any (None: not
    checked). CheckerBusyError when no checker came free."""
    if checker is None:
        return []
    return [(f"{m.where}.{field}", reason) for m in request_models(body)
            for field, reason in checker.check(m)]


def submission_errors(body: PlanRequest, store: Store, checker: ModelChecker | None = None,
                      owner: str | None = None) -> tuple[PlanRequest, list[tuple[str, str]]]:
    """What ``POST /v1/plans`` checks before storing a job: the request with its warm
    start's job id resolved (:func:`resolve_warm_start`), and every error of it as
    (field, reason) pairs (:func:`~planner_service.planners.request_errors`; those of a plan
    that came from a job named ``warm_start.job_id``). StoreUnavailableError when the store
    cannot be read. With a ``checker``, the request's model texts are checked first, in
    isolation (:func:`model_errors`); a model that fails ends the checks there (the rest
    needs it loaded)."""
    errors = model_errors(body, checker)
    if errors:
        return body, errors
    job_id = body.warm_start.job_id if body.warm_start is not None else None
    body, errors = resolve_warm_start(body, store, owner)
    if errors:  # check the rest of the request too: every bad field at once
        body = body.model_copy(update={"warm_start": None})
    more = _checked_elsewhere(body, checker)
    if more is None:  # no model of its own: the API's fingers (built-in ones)
        more = request_errors(body)
    return body, errors + (_from_job(job_id, more) if job_id is not None else more)


#: The time a checker process has for the rest of a request's checks once its models
#: passed theirs [s] (at least the model checks' own): a grasp search takes seconds
#: (docs/hands.md: 0.4-5 s measured), more on a loaded machine.
REQUEST_CHECK_SECONDS = 30.0


def checked_apart(body: PlanRequest) -> bool:
    """Whether a request's checks run in a checker process: it carries a model (a URDF,
    an MJCF), or its checks search a grasp (seconds of the interpreter). Such requests
    wait in threads of their own (:class:`ModelSubmissions`), never in the API's."""
    return bool(request_models(body)) or getattr(body, "grasp", None) is not None


def _checked_elsewhere(body: PlanRequest, checker: ModelChecker | None
                       ) -> list[tuple[str, str]] | None:
    """The errors of a request checked apart (:func:`checked_apart`), found in a checker
    process (its models loaded and its grasp searched there, under the checker's memory
    limit: a request checked in the API never waits for the API's fingers meanwhile);
    None for any other request (or without a checker)."""
    if checker is None or not checked_apart(body):
        return None
    try:
        errors: list[tuple[str, str]] = checker.call(
            Task("request_errors", (body.model_dump_json(),)),
            max(checker.limits.time_limit, REQUEST_CHECK_SECONDS))
    except TaskLimitError as exc:
        models = request_models(body)
        field = f"{models[0].where}.{models[0].field}" if models else "grasp"
        return [(field, f"checking the request: {exc}")]
    except TaskError as exc:
        raise RuntimeError(f"the request's checks failed: {exc.kind}: {exc.message}") \
            from exc
    return [(str(field), str(reason)) for field, reason in errors]
