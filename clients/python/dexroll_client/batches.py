"""The wire contract's batches: many plan requests submitted as one, their progress, and
their results (docs/service.md, "Batches").

Import from :mod:`dexroll_client.models` (it re-exports everything).
"""

from __future__ import annotations

from datetime import datetime

from pydantic import Field

from dexroll_client.common import _Request, _Response
from dexroll_client.requests import PlanRequest

__all__ = ["MAX_BATCH", "Batch", "BatchRequest"]

#: The most plan requests one batch may hold.
MAX_BATCH = 1000


class BatchRequest(_Request):
    """Plan requests submitted together: each one a job of its own (the same checks as
    ``POST /v1/plans``, every item checked before any job is made; a 422 names each bad
    field as ``items[i].field``)."""

    items: list[PlanRequest] = Field(min_length=1, max_length=MAX_BATCH,
                                     description="the plan requests, in order")


class Batch(_Response):
    """A batch: its jobs in submission order and how many are in each state."""

    id: str
    size: int = Field(description="how many requests it was made of")
    created_at: datetime
    counts: dict[str, int] = Field(description="its jobs by state (queued, running, "
                                               "succeeded, ...; purged: no longer stored)")
    done: bool = Field(description="every job has ended")
    job_ids: list[str] = Field(description="its jobs, in submission order (GET "
                                           "/v1/plans/{id} each)")
