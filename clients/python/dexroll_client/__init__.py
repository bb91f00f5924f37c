"""Python client of the dexroll planning service, and its wire models.

    from dexroll_client import DexrollClient

    with DexrollClient.from_url("http://127.0.0.1:8000") as client:
        job = client.plan({"initial": {"x": 0, "y": 0, "u": 0, "v": 0, "psi": 0},
                           "goal": {"x": 0.03}, "duration": 2.0}, timeout=60)
        print(job.state, job.result.status if job.result else None)

See ``README.md`` next to this package for more, :mod:`dexroll_client.errors` for the
exception tree.
"""

from __future__ import annotations

from dexroll_client.client import AsyncDexrollClient, DexrollClient, RequestLike
from dexroll_client.errors import (
    APIError,
    ConflictError,
    DexrollError,
    InvalidRequestError,
    NotFoundError,
    PlanTimeoutError,
    RequestTooLargeError,
    ServiceUnavailableError,
    TransportError,
)
from dexroll_client.models import (
    AnyPlanResult,
    BallOnPalmRequest,
    CertificateModel,
    ContactCoordinates,
    ErrorBody,
    FieldError,
    FingerCertificateModel,
    FingerContactCoordinates,
    FingerContactModel,
    FingerInfo,
    FingerModelSpec,
    FingerPlanResult,
    FingerStatsModel,
    FingerTrajectoryModel,
    Job,
    JobList,
    JobState,
    ModelCatalog,
    ObjectModel,
    OneFingerRequest,
    PartialContactCoordinates,
    PlanRequest,
    PlanResult,
    PlanStatus,
    SolverModel,
    StatsModel,
    TrajectoryModel,
    ViaPointModel,
)

__all__ = [
    "APIError",
    "AnyPlanResult",
    "AsyncDexrollClient",
    "BallOnPalmRequest",
    "CertificateModel",
    "ConflictError",
    "ContactCoordinates",
    "DexrollClient",
    "DexrollError",
    "ErrorBody",
    "FieldError",
    "FingerCertificateModel",
    "FingerContactCoordinates",
    "FingerContactModel",
    "FingerInfo",
    "FingerModelSpec",
    "FingerPlanResult",
    "FingerStatsModel",
    "FingerTrajectoryModel",
    "InvalidRequestError",
    "Job",
    "JobList",
    "JobState",
    "ModelCatalog",
    "NotFoundError",
    "ObjectModel",
    "OneFingerRequest",
    "PartialContactCoordinates",
    "PlanRequest",
    "PlanResult",
    "PlanStatus",
    "PlanTimeoutError",
    "RequestLike",
    "RequestTooLargeError",
    "ServiceUnavailableError",
    "SolverModel",
    "StatsModel",
    "TrajectoryModel",
    "TransportError",
    "ViaPointModel",
]
