"""Wire contract: planning requests and results (pydantic), SI units throughout.

The same request is taken by the command line (``dexroll plan request.json``) and, later,
by the HTTP API. Models forbid unknown fields and NaN/infinity; every number has a range.
Conversion to the optimisation core's problem types happens here, at the edge: ``ocp``
never imports this package.
"""

from __future__ import annotations

import math
from typing import Annotated, Any, Literal

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    ValidationError,
    ValidationInfo,
    field_validator,
)

from ocp.problem import (
    MAX_DURATION,
    MAX_INTERVALS,
    MAX_POSITION,
    MAX_VIA_POINTS,
    BallOnPalmProblem,
    ObjectSpec,
    SolverOptions,
    ViaPoint,
)
from ocp.solution import Solution, Status

__all__ = [
    "BallOnPalmRequest",
    "ContactCoordinates",
    "PartialContactCoordinates",
    "PlanResult",
    "validation_errors",
]

MAX_SAMPLES = 10_000


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False, frozen=True)


Position = Annotated[float, Field(ge=-MAX_POSITION, le=MAX_POSITION)]
Angle = Annotated[float, Field(ge=-100.0, le=100.0)]


class PartialContactCoordinates(_Model):
    """Any subset of the palm/object contact coordinates eta_p = (x, y, u, v, psi)."""

    x: Position | None = Field(None, description="palm contact point x [m]")
    y: Position | None = Field(None, description="palm contact point y [m]")
    u: Angle | None = Field(None, description="object chart latitude u [rad]")
    v: Angle | None = Field(None, description="object chart longitude v [rad]")
    psi: Angle | None = Field(None, description="contact angle psi [rad]")

    def as_dict(self) -> dict[str, float]:
        return {k: float(v) for k, v in self.model_dump().items() if v is not None}


class ContactCoordinates(_Model):
    """All five palm/object contact coordinates eta_p = (x, y, u, v, psi)."""

    x: Position = Field(description="palm contact point x [m]")
    y: Position = Field(description="palm contact point y [m]")
    u: Angle = Field(description="object chart latitude u [rad]")
    v: Angle = Field(description="object chart longitude v [rad]")
    psi: Angle = Field(description="contact angle psi [rad]")

    def as_tuple(self) -> tuple[float, float, float, float, float]:
        return (self.x, self.y, self.u, self.v, self.psi)


class ObjectModel(_Model):
    """The rolled object and the chart its contact coordinates are measured in."""

    shape: Literal["sphere", "ellipsoid"] = Field(
        "sphere", description="'sphere' or 'ellipsoid' (of revolution about its z axis)")
    dimensions: list[Annotated[float, Field(gt=0.0, le=1.0)]] = Field(
        default_factory=lambda: [0.025], min_length=1, max_length=2,
        description="sphere: [radius] [m]; ellipsoid: [equatorial semi-axis, polar semi-axis]"
                    " [m]")
    chart_rotation: list[Annotated[float, Field(ge=-2 * math.pi, le=2 * math.pi)]] = Field(
        default_factory=lambda: [0.0, 0.0, 0.0], min_length=3, max_length=3,
        description="rotation vector [rad] of the object's chart patch in the object frame")


class ViaPointModel(_Model):
    time: float = Field(gt=0.0, le=MAX_DURATION, description="time of the via-point [s]")
    coords: PartialContactCoordinates = Field(description="coordinates to pass through")


class SolverModel(_Model):
    max_iter: int = Field(1000, ge=1, le=100_000, description="IPOPT iteration limit, all "
                                                              "initial guesses together")
    time_limit: float = Field(60.0, gt=0.0, le=3600.0, description="wall-clock limit [s]")
    cert_position_tol: float = Field(1e-6, gt=0.0, le=1e-2, description=(
        "certificate tolerance on the re-integration defect of x, y [m]"))
    cert_angle_tol: float = Field(1e-4, gt=0.0, le=1e-1, description=(
        "certificate tolerance on the re-integration defect of u, v, psi [rad]"))


class BallOnPalmRequest(_Model):
    """Roll an object on the flat palm between contact configurations (paper, section 3)."""

    planner: Literal["ball_on_palm"] = Field("ball_on_palm", description="which planner")
    object: ObjectModel = Field(default_factory=ObjectModel)
    initial: ContactCoordinates = Field(description="contact coordinates at t = 0")
    goal: PartialContactCoordinates = Field(
        default_factory=PartialContactCoordinates,
        description="coordinates required at t = duration (any subset)")
    via_points: list[ViaPointModel] = Field(default_factory=list, max_length=MAX_VIA_POINTS)
    duration: float = Field(gt=0.0, le=MAX_DURATION, description="planning horizon [s]")
    n_intervals: int = Field(50, ge=1, le=MAX_INTERVALS,
                             description="collocation intervals over the horizon")
    pole_margin: float = Field(math.radians(15.0), gt=0.0, lt=math.pi / 2,
                               description="keep |u| <= pi/2 - pole_margin [rad]")
    max_contact_speed: float = Field(1.0, gt=0.0, le=100.0,
                                     description="bound on each palm contact velocity "
                                                 "component [m/s]")
    palm_half_extent: float = Field(0.5, gt=0.0, le=MAX_POSITION,
                                    description="palm coordinates stay in [-e, e] [m]")
    max_refinements: int = Field(2, ge=0, le=5, description="grid doublings allowed when the "
                                                            "certificate finds the grid coarse")
    solver: SolverModel = Field(default_factory=SolverModel)
    sample_times: list[Annotated[float, Field(ge=0.0, le=MAX_DURATION)]] | None = Field(
        None, max_length=MAX_SAMPLES,
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

    def to_problem(self) -> BallOnPalmProblem:
        """The core's problem (which runs its own whole-problem validation)."""
        o = self.solver
        return BallOnPalmProblem(
            object=ObjectSpec(self.object.shape, tuple(self.object.dimensions),
                              (self.object.chart_rotation[0], self.object.chart_rotation[1],
                               self.object.chart_rotation[2])),
            initial=self.initial.as_tuple(),
            goal=self.goal.as_dict(),
            duration=self.duration,
            via_points=tuple(ViaPoint(vp.time, vp.coords.as_dict()) for vp in self.via_points),
            n_intervals=self.n_intervals,
            pole_margin=self.pole_margin,
            max_contact_speed=self.max_contact_speed,
            palm_half_extent=self.palm_half_extent,
            max_refinements=self.max_refinements,
            options=SolverOptions(max_iter=o.max_iter, time_limit=o.time_limit,
                                  cert_position_tol=o.cert_position_tol,
                                  cert_angle_tol=o.cert_angle_tol),
        )


def validation_errors(exc: ValidationError) -> list[tuple[str, str]]:
    """(field, reason) pairs of a pydantic error, with dotted field paths."""
    out = []
    for e in exc.errors(include_url=False):
        loc = ".".join(str(p) for p in e["loc"]) or "request"
        out.append((loc, str(e["msg"])))
    return out


class FieldError(_Model):
    field: str = Field(description="dotted path of the offending field")
    reason: str


class PlanResult(_Model):
    """A plan (or why there is none). Trajectories: rows are samples; SI units.

    ``grid`` samples the collocation points (nodes and midpoints); ``samples`` the caller's
    ``sample_times``. Each trajectory has t [s], eta (x [m], y [m], u, v, psi [rad]),
    eta_dot, w (palm contact velocity [m/s]), rolling_velocity [rad/s], object_position
    [m], object_orientation_wxyz (unit quaternion, palm frame), contact_point [m],
    contact_normal.
    """

    status: Status
    message: str
    errors: list[FieldError] = Field(default_factory=list)
    stats: dict[str, Any] | None = None
    goal_error: dict[str, float] | None = Field(None, description="per target, m or rad")
    certificate: dict[str, Any] | None = None
    grid: dict[str, Any] | None = None
    samples: dict[str, Any] | None = None

    @staticmethod
    def from_solution(sol: Solution, sample_times: list[float] | None = None) -> PlanResult:
        d = sol.to_dict()
        samples = sol.sample(sample_times).to_dict() if sample_times else None
        return PlanResult(status=sol.status, message=sol.message, stats=d["stats"],
                          goal_error=d["goal_error"], certificate=d["certificate"],
                          grid=d["grid"], samples=samples)

    @staticmethod
    def invalid(errors: list[tuple[str, str]]) -> PlanResult:
        return PlanResult(status=Status.INVALID_INPUT,
                          message="; ".join(f"{f}: {r}" for f, r in errors),
                          errors=[FieldError(field=f, reason=r) for f, r in errors])
