"""The wire contract of the dexroll service: requests, results, jobs (pydantic).

This package is the one definition of the contract: the service imports it, the client
uses it, the command line validates request files with it. It depends on pydantic only.
SI units throughout (m, rad, s); every field's unit is in its description. Request models
forbid unknown fields and NaN/infinity, and bound every number and array length.

This module gathers the whole contract under one import path; the definitions live in
:mod:`dexroll_client.requests` (one request per planner on a shared base, warm starts),
:mod:`dexroll_client.results` (one result per planner on shared bases, the
``collocation`` block), :mod:`dexroll_client.jobs` (jobs, error bodies),
:mod:`dexroll_client.catalog` (``GET /v1/models``) and :mod:`dexroll_client.common`
(limits, base classes).
"""

from __future__ import annotations

from dexroll_client.catalog import (
    FingerInfo,
    HandFingerInfo,
    HandInfo,
    ModelCatalog,
    ObjectInfo,
)
from dexroll_client.common import (
    BUILTIN_FINGERS,
    BUILTIN_HANDS,
    MAX_DURATION,
    MAX_FINGER_JOINTS,
    MAX_FINGERS,
    MAX_INTERVALS,
    MAX_MOTION_KNOTS,
    MAX_NLP_POINT,
    MAX_POSITION,
    MAX_SAMPLE_RATE,
    MAX_SAMPLES,
    MAX_URDF_CHARS,
    MAX_VIA_POINTS,
    MAX_WARM_START_COLUMNS,
    PLANNERS,
    NlpPointModel,
)
from dexroll_client.jobs import ErrorBody, Job, JobList, JobState
from dexroll_client.requests import (
    WARM_START_DESCRIPTION as WARM_START_DESCRIPTION,
)
from dexroll_client.requests import Angle as Angle
from dexroll_client.requests import (
    BallOnPalmRequest,
    ContactCoordinates,
    FingerContactCoordinates,
    FingerContactModel,
    FingerModelSpec,
    FingertipModel,
    ForcesModel,
    HandModel,
    HandTipModel,
    ManipulationRequest,
    MotionModel,
    MotionSamplesModel,
    MotionStepModel,
    MotionStepsModel,
    MountModel,
    ObjectModel,
    ObjectPoseModel,
    OneFingerRequest,
    PalmModel,
    PartialContactCoordinates,
    PlanRequest,
    PlanRequestBase,
    SolverModel,
    TipSurfaceModel,
    TrackingModel,
    ViaPointModel,
    WarmStartModel,
)
from dexroll_client.requests import ColumnNames as ColumnNames
from dexroll_client.requests import Position as Position
from dexroll_client.requests import Quaternion as Quaternion
from dexroll_client.requests import RotationVector as RotationVector
from dexroll_client.requests import WarmRows as WarmRows
from dexroll_client.requests import WarmValue as WarmValue
from dexroll_client.results import (
    COLLOCATION_DESCRIPTION as COLLOCATION_DESCRIPTION,
)
from dexroll_client.results import (
    AnyPlanResult,
    CertificateBase,
    CertificateModel,
    CollocationModel,
    ContactSamplesModel,
    ContactTrajectoryModel,
    DurationModel,
    FieldError,
    FingerCertificateModel,
    FingerJointsModel,
    FingerPlanResult,
    FingerSamplesModel,
    FingerStatsModel,
    FingerTrajectoryModel,
    JointTrajectoryModel,
    JointTrajectoryPointModel,
    ManipulationCertificateModel,
    ManipulationResult,
    ManipulationStatsModel,
    ManipulationTrajectoryModel,
    PlanResult,
    PlanResultBase,
    PlanSamplesModel,
    PlanStatus,
    RateBreakModel,
    StatsBase,
    StatsModel,
    TrajectoryModel,
)
from dexroll_client.results import Rows as Rows

__all__ = [
    "BUILTIN_FINGERS",
    "BUILTIN_HANDS",
    "MAX_DURATION",
    "MAX_FINGERS",
    "MAX_FINGER_JOINTS",
    "MAX_INTERVALS",
    "MAX_MOTION_KNOTS",
    "MAX_NLP_POINT",
    "MAX_POSITION",
    "MAX_SAMPLES",
    "MAX_SAMPLE_RATE",
    "MAX_URDF_CHARS",
    "MAX_VIA_POINTS",
    "MAX_WARM_START_COLUMNS",
    "PLANNERS",
    "AnyPlanResult",
    "BallOnPalmRequest",
    "CertificateBase",
    "CertificateModel",
    "CollocationModel",
    "ContactCoordinates",
    "ContactSamplesModel",
    "ContactTrajectoryModel",
    "DurationModel",
    "ErrorBody",
    "FieldError",
    "FingerCertificateModel",
    "FingerContactCoordinates",
    "FingerContactModel",
    "FingerInfo",
    "FingerJointsModel",
    "FingerModelSpec",
    "FingerPlanResult",
    "FingerSamplesModel",
    "FingerStatsModel",
    "FingerTrajectoryModel",
    "FingertipModel",
    "ForcesModel",
    "HandFingerInfo",
    "HandInfo",
    "HandModel",
    "HandTipModel",
    "Job",
    "JobList",
    "JobState",
    "JointTrajectoryModel",
    "JointTrajectoryPointModel",
    "ManipulationCertificateModel",
    "ManipulationRequest",
    "ManipulationResult",
    "ManipulationStatsModel",
    "ManipulationTrajectoryModel",
    "ModelCatalog",
    "MotionModel",
    "MotionSamplesModel",
    "MotionStepModel",
    "MotionStepsModel",
    "MountModel",
    "NlpPointModel",
    "ObjectInfo",
    "ObjectModel",
    "ObjectPoseModel",
    "OneFingerRequest",
    "PalmModel",
    "PartialContactCoordinates",
    "PlanRequest",
    "PlanRequestBase",
    "PlanResult",
    "PlanResultBase",
    "PlanSamplesModel",
    "PlanStatus",
    "RateBreakModel",
    "SolverModel",
    "StatsBase",
    "StatsModel",
    "TipSurfaceModel",
    "TrackingModel",
    "TrajectoryModel",
    "ViaPointModel",
    "WarmStartModel",
]
