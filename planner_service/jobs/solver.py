"""The solver worker's body: what a worker process (or Ray actor) of the service does with
a job. Built once per worker by its executor (:mod:`planner_service.executors`); the
dispatcher (:mod:`.workers`) calls its methods one at a time.

It keeps one planner per kind, and so their caches of built NLPs, from job to job: the
ball-on-palm planner, and the finger planners (one-finger and manipulation, one NLP cache)
with the finger models and hands they were built for (``FingerCache``).
"""

from __future__ import annotations

import logging
import os
import socket
import time
from pathlib import Path
from typing import Any

from dexroll_client.models import JobState, PlanStatus

__all__ = ["REPLY_TIME", "SolverWorker", "job_outcome"]

#: The worker's planner is given the time left minus this much, for the reply to travel [s].
REPLY_TIME = 0.05

log = logging.getLogger("dexroll.workers")


def job_outcome(status: PlanStatus) -> JobState:
    """The terminal job state for a plan's status."""
    return {
        PlanStatus.SOLVED: JobState.SUCCEEDED,
        PlanStatus.INFEASIBLE: JobState.INFEASIBLE,
        PlanStatus.TIME_LIMIT: JobState.TIMED_OUT,
    }.get(status, JobState.FAILED)


class SolverWorker:
    """Plans requests in this process, keeping the planners' caches between them.

    ``compile_dir``: where the finger NLPs are compiled to C (in a background thread, the
    virtual machine solving meanwhile; None: not compiled). The ball-on-palm NLP is not
    compiled here: it is written out in SX, its compile takes tens of seconds in the
    foreground, and since the closed-form geometry its function evaluations are a small
    part of its solve. ``max_result_bytes``: a result's JSON above this is not returned
    (the job fails ``result_too_large``)."""

    def __init__(self, compile_dir: str | None = None, max_result_bytes: int = 1 << 62
                 ) -> None:
        from ..planners import BallOnPalmPlanner, FingerCache

        self.palm = BallOnPalmPlanner()
        self.fingers = FingerCache(
            compile_dir=None if compile_dir is None else Path(compile_dir), background=True)
        self.max_result_bytes = max_result_bytes

    def ready(self) -> dict[str, Any]:
        """The worker is up (its planners imported): its process id and host."""
        return {"pid": os.getpid(), "host": socket.gethostname()}

    def warm(self, name: str, text: str) -> float | None:
        """Build the NLP of the warm-up request ``text`` (the file ``name``): its build
        time [s] (0: cached already), None when it is not a valid request."""
        from ..warmup import warm_text

        return warm_text(name, text, self.palm, self.fingers)

    def solve(self, job_id: str, request_json: str, seconds: float
              ) -> tuple[str, str, str, str | None, str | None, bool, bool | None, float]:
        """Plan one job within ``seconds`` (the time left of its one deadline, which
        started when the dispatcher handed it over). The verdict: (job state, code,
        message, raw solver status, result JSON or None, whether the result holds a plan
        to view, whether its NLP came from this worker's cache (None: not known), the
        seconds spent here)."""
        started = time.perf_counter()
        from ..planners import REQUEST, ProblemError, error_result, invalid_result, solve
        from ..view import has_plan

        planner = "ball_on_palm"
        try:
            request = REQUEST.validate_json(request_json)
            planner = request.planner
            left = seconds - REPLY_TIME
            request = request.model_copy(update={"solver": request.solver.model_copy(
                update={"time_limit": max(left, 1e-3)})})
            result, _ = solve(request, self.palm, self.fingers)
        except ProblemError as exc:  # checked at submission; the store may be older
            result = invalid_result(exc.errors, planner)
        except Exception as exc:  # a typed error, never a dead worker on a bad job
            log.exception("job %s failed in the worker", job_id)
            result = error_result(f"planner failed: {exc!r}", planner)
        result_json = result.model_dump_json()
        stats = result.stats
        raw = stats.raw_status if stats else None
        hit = getattr(stats, "cache_hit", None)  # else: nothing built is a cache hit
        build = getattr(stats, "build_time", None)
        if hit is None and build is not None:
            hit = bool(build == 0.0)
        if len(result_json) > self.max_result_bytes:
            return (JobState.FAILED.value, "result_too_large",
                    f"the plan ended {result.status.value}, but its JSON is "
                    f"{len(result_json)} bytes, over the service's limit of "
                    f"{self.max_result_bytes} (DEXROLL_MAX_RESULT_BYTES): ask for fewer "
                    "intervals or sample times", raw, None, False, hit,
                    time.perf_counter() - started)
        return (job_outcome(result.status).value, result.status.value, result.message, raw,
                result_json, has_plan(result), hit, time.perf_counter() - started)
