"""The wire contract's jobs: a job's state and its plan once finished, pages of jobs, and
the body of every HTTP error.

Import from :mod:`dexroll_client.models` (it re-exports everything).
"""

from __future__ import annotations

from datetime import datetime
from enum import StrEnum

from pydantic import Field

from dexroll_client.common import _Response
from dexroll_client.results import AnyPlanResult, FieldError

__all__ = ["ErrorBody", "Job", "JobList", "JobState"]

class JobState(StrEnum):
    """Where a job is. Every job ends in exactly one terminal state."""

    QUEUED = "queued"
    RUNNING = "running"
    #: Terminal: the plan is solved and certified.
    SUCCEEDED = "succeeded"
    #: Terminal: the goals cannot be reached (IPOPT: locally infeasible).
    INFEASIBLE = "infeasible"
    #: Terminal: the time limit ended the solve (``code`` says how).
    TIMED_OUT = "timed_out"
    #: Terminal: cancelled by DELETE before it finished.
    CANCELLED = "cancelled"
    #: Terminal: anything else (``code``: iteration_limit, inaccurate, numerical_error,
    #: worker_died, interrupted, error).
    FAILED = "failed"

    @property
    def terminal(self) -> bool:
        return self not in (JobState.QUEUED, JobState.RUNNING)


class Job(_Response):
    id: str
    state: JobState
    code: str | None = Field(default=None, description="typed outcome code (terminal only)")
    message: str | None = None
    raw_status: str | None = Field(default=None, description="the solver's raw status")
    planner: str
    created_at: datetime
    started_at: datetime | None = None
    finished_at: datetime | None = None
    worker_pid: int | None = Field(default=None, description="process id of the worker that "
                                                             "ran (or runs) the job")
    result_bytes: int | None = Field(default=None, description=(
        "size of the stored plan's JSON [bytes] (null: none); `GET /v1/plans/{id}?"
        "result=false` gives the job without it"))
    result: AnyPlanResult | None = Field(default=None, description="the plan, once finished "
                                                                "(also after a failure: the "
                                                                "last iterate)")


class JobList(_Response):
    items: list[Job]
    total: int = Field(description="jobs in the store")
    limit: int
    offset: int
    next_offset: int | None = Field(description="offset of the next page (null: last page)")


class ErrorBody(_Response):
    """Body of every 4xx/5xx response."""

    error: str = Field(description="machine-readable code, e.g. invalid_request")
    message: str
    detail: list[FieldError] = Field(default_factory=list)
