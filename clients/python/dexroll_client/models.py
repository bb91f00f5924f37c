"""The wire contract of the dexroll service: requests, results, jobs (pydantic).

This module is the one definition of the contract: the service imports it, the client
uses it, the command line validates request files with it. It depends on pydantic only.
SI units throughout (m, rad, s); every field's unit is in its description. Request models
forbid unknown fields and NaN/infinity, and bound every number and array length.
"""

from __future__ import annotations

import math
from datetime import datetime
from enum import StrEnum
from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationInfo, field_validator

__all__ = [
    "MAX_DURATION",
    "MAX_INTERVALS",
    "MAX_POSITION",
    "MAX_SAMPLES",
    "MAX_VIA_POINTS",
    "BallOnPalmRequest",
    "CertificateModel",
    "ContactCoordinates",
    "ErrorBody",
    "FieldError",
    "Job",
    "JobList",
    "JobState",
    "ModelCatalog",
    "ObjectInfo",
    "ObjectModel",
    "PartialContactCoordinates",
    "PlanRequest",
    "PlanResult",
    "PlanStatus",
    "SolverModel",
    "StatsModel",
    "TrajectoryModel",
    "ViaPointModel",
]

#: Limits of a request (the service's core enforces the same ones; a test checks).
MAX_INTERVALS = 2000
MAX_VIA_POINTS = 50
MAX_POSITION = 10.0  # m
MAX_DURATION = 3600.0  # s
MAX_SAMPLES = 10_000


class _Request(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False, frozen=True)


class _Response(BaseModel):
    # Responses ignore fields they do not know, so that a client keeps working when a newer
    # service adds one.
    model_config = ConfigDict(extra="ignore", allow_inf_nan=False)


Position = Annotated[float, Field(ge=-MAX_POSITION, le=MAX_POSITION)]
Angle = Annotated[float, Field(ge=-100.0, le=100.0)]


# -- requests -------------------------------------------------------------------------------

class PartialContactCoordinates(_Request):
    """Any subset of the palm/object contact coordinates eta_p = (x, y, u, v, psi)."""

    x: Position | None = Field(default=None, description="palm contact point x [m]")
    y: Position | None = Field(default=None, description="palm contact point y [m]")
    u: Angle | None = Field(default=None, description="object chart latitude u [rad]")
    v: Angle | None = Field(default=None, description="object chart longitude v [rad]")
    psi: Angle | None = Field(default=None, description="contact angle psi [rad]")

    def as_dict(self) -> dict[str, float]:
        return {k: float(v) for k, v in self.model_dump().items() if v is not None}


class ContactCoordinates(_Request):
    """All five palm/object contact coordinates eta_p = (x, y, u, v, psi)."""

    x: Position = Field(description="palm contact point x [m]")
    y: Position = Field(description="palm contact point y [m]")
    u: Angle = Field(description="object chart latitude u [rad]")
    v: Angle = Field(description="object chart longitude v [rad]")
    psi: Angle = Field(description="contact angle psi [rad]")

    def as_tuple(self) -> tuple[float, float, float, float, float]:
        return (self.x, self.y, self.u, self.v, self.psi)


class ObjectModel(_Request):
    """The rolled object and the chart its contact coordinates are measured in."""

    shape: Literal["sphere", "ellipsoid"] = Field(
        default="sphere",
        description="'sphere' or 'ellipsoid' (of revolution about its z axis)")
    dimensions: list[Annotated[float, Field(gt=0.0, le=1.0)]] = Field(
        default_factory=lambda: [0.025], min_length=1, max_length=2,
        description="sphere: [radius] [m]; ellipsoid: [equatorial semi-axis, polar "
                    "semi-axis] [m]")
    chart_rotation: list[Annotated[float, Field(ge=-2 * math.pi, le=2 * math.pi)]] = Field(
        default_factory=lambda: [0.0, 0.0, 0.0], min_length=3, max_length=3,
        description="rotation vector [rad] of the object's chart patch in the object frame")


class ViaPointModel(_Request):
    time: float = Field(gt=0.0, le=MAX_DURATION, description="time of the via-point [s]")
    coords: PartialContactCoordinates = Field(description="coordinates to pass through")


class SolverModel(_Request):
    max_iter: int = Field(default=1000, ge=1, le=100_000,
                          description="IPOPT iteration limit, all initial guesses together")
    time_limit: float = Field(default=60.0, gt=0.0, le=3600.0,
                              description="wall-clock limit of the solve [s] (the service "
                                          "caps it at its own maximum)")
    cert_position_tol: float = Field(default=1e-6, gt=0.0, le=1e-2, description=(
        "certificate tolerance on the re-integration defect of x, y [m]"))
    cert_angle_tol: float = Field(default=1e-4, gt=0.0, le=1e-1, description=(
        "certificate tolerance on the re-integration defect of u, v, psi [rad]"))


class BallOnPalmRequest(_Request):
    """Roll an object on the flat palm between contact configurations (paper, section 3)."""

    planner: Literal["ball_on_palm"] = Field(default="ball_on_palm",
                                             description="which planner")
    object: ObjectModel = Field(default_factory=ObjectModel)
    initial: ContactCoordinates = Field(description="contact coordinates at t = 0")
    goal: PartialContactCoordinates = Field(
        default_factory=PartialContactCoordinates,
        description="coordinates required at t = duration (any subset)")
    via_points: list[ViaPointModel] = Field(default_factory=list, max_length=MAX_VIA_POINTS)
    duration: float = Field(gt=0.0, le=MAX_DURATION, description="planning horizon [s]")
    n_intervals: int = Field(default=50, ge=1, le=MAX_INTERVALS,
                             description="collocation intervals over the horizon")
    pole_margin: float = Field(default=math.radians(15.0), gt=0.0, lt=math.pi / 2,
                               description="keep |u| <= pi/2 - pole_margin [rad]")
    max_contact_speed: float = Field(default=1.0, gt=0.0, le=100.0,
                                     description="bound on each palm contact velocity "
                                                 "component [m/s]")
    palm_half_extent: float = Field(default=0.5, gt=0.0, le=MAX_POSITION,
                                    description="palm coordinates stay in [-e, e] [m]")
    max_refinements: int = Field(default=2, ge=0, le=5,
                                 description="grid doublings allowed when the certificate "
                                             "finds the grid too coarse")
    solver: SolverModel = Field(default_factory=SolverModel)
    sample_times: list[Annotated[float, Field(ge=0.0, le=MAX_DURATION)]] | None = Field(
        default=None, max_length=MAX_SAMPLES,
        description="extra times [s] at which to sample the plan (collocation polynomials)")

    @field_validator("sample_times")
    @classmethod
    def _samples_inside_horizon(cls, value: list[float] | None, info: ValidationInfo
                                ) -> list[float] | None:
        duration = info.data.get("duration")
        if value and duration is not None and max(value) > duration:
            raise ValueError(f"sample times must lie in [0, duration = {duration} s], "
                             f"got {max(value)}")
        return value


#: Every planning request, told apart by its ``planner`` field. Later planners join this
#: union (one endpoint serves them all).
PlanRequest = BallOnPalmRequest


# -- results --------------------------------------------------------------------------------

class PlanStatus(StrEnum):
    """Outcome of a plan (same values as ``ocp.solution.Status``)."""

    SOLVED = "solved"
    INACCURATE = "inaccurate"
    INFEASIBLE = "infeasible"
    ITERATION_LIMIT = "iteration_limit"
    TIME_LIMIT = "time_limit"
    NUMERICAL_ERROR = "numerical_error"
    INVALID_INPUT = "invalid_input"
    ERROR = "error"


Rows = list[list[float]]


class TrajectoryModel(_Response):
    """A plan sampled at times t; rows are samples. Palm frame, SI units."""

    t: list[float] = Field(description="sample times [s]")
    eta: Rows = Field(description="contact coordinates (x [m], y [m], u [rad], v [rad], "
                                  "psi [rad])")
    eta_dot: Rows = Field(description="rates of the contact coordinates ([m/s], [rad/s])")
    w: Rows = Field(description="palm contact velocity d/dt (x, y), the input [m/s]")
    rolling_velocity: Rows = Field(description="(omega_x, omega_y) of the palm relative to "
                                               "the object, palm contact frame [rad/s]")
    object_position: Rows = Field(description="object centre in the palm frame [m]")
    object_orientation_wxyz: Rows = Field(description="object orientation in the palm frame,"
                                                      " unit quaternion (w, x, y, z), w >= 0")
    contact_point: Rows = Field(description="contact point in the palm frame [m]")
    contact_normal: Rows = Field(description="palm outward normal at the contact (unit)")


class CertificateModel(_Response):
    """Physical validity, computed independently of the NLP by re-integrating the inputs."""

    passed: bool
    max_position_defect: float | None = Field(
        description="worst re-integration defect of x, y [m] (null: not computed)")
    max_angle_defect: float | None = Field(
        description="worst re-integration defect of u, v, psi [rad]")
    max_slip_speed: float | None = Field(
        description="worst speed of the object's contact point relative to the palm [m/s]")
    max_spin_rate: float | None = Field(
        description="worst object angular velocity about the contact normal [rad/s]")
    max_height_error: float | None = Field(
        description="worst gap/penetration between object and palm [m]")
    max_goal_error: float | None = Field(
        description="worst goal or via-point error of the re-integrated motion [m or rad]")
    n_samples: int = Field(description="samples checked along the re-integrated motion")
    tolerances: dict[str, float] = Field(description="tolerance of each check (units as "
                                                     "the checked quantity)")
    failures: list[str] = Field(description="checks that failed, with values")


class StatsModel(_Response):
    raw_status: str = Field(description="IPOPT's return status")
    iterations: int = Field(description="IPOPT iterations, all attempts and refinements")
    attempts: int = Field(description="initial guesses tried")
    build_time: float = Field(description="NLP construction time [s] (0 when cached)")
    solve_time: float = Field(description="IPOPT and initial-guess time [s]")
    certificate_time: float = Field(description="certificate time [s]")
    objective: float = Field(description="control effort integral |w|^2 dt [m^2/s]")
    cache_hit: bool = Field(description="the NLP came from the structure cache")
    refinements: int = Field(description="grid doublings after the first solve")
    n_intervals: int = Field(description="collocation intervals of the returned plan")


class FieldError(_Response):
    field: str = Field(description="dotted path of the offending field")
    reason: str


class PlanResult(_Response):
    """A plan, or why there is none. ``grid``: the collocation points (nodes and
    midpoints); ``samples``: the request's ``sample_times``."""

    status: PlanStatus
    message: str
    errors: list[FieldError] = Field(default_factory=list)
    stats: StatsModel | None = None
    goal_error: dict[str, float] | None = Field(
        default=None, description="error of each goal/via-point coordinate [m or rad]")
    certificate: CertificateModel | None = None
    grid: TrajectoryModel | None = None
    samples: TrajectoryModel | None = None


# -- jobs -----------------------------------------------------------------------------------

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
    result: PlanResult | None = Field(default=None, description="the plan, once finished "
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


class ObjectInfo(_Response):
    shape: str
    parameters: list[str] = Field(description="names of `object.dimensions`, in order [m]")
    description: str


class FingerInfo(_Response):
    name: str
    tip_frame: str
    n_joints: int
    urdf: str = Field(description="the URDF document")


class ModelCatalog(_Response):
    planners: list[str]
    objects: list[ObjectInfo]
    fingers: list[FingerInfo]
