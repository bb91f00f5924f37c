"""The wire contract's requests: one model per planner (``planner`` tells them apart) on
one base (:class:`PlanRequestBase`: the fields every planner shares), their parts, and warm
starts.

Import from :mod:`dexroll_client.models` (it re-exports everything).
"""

from __future__ import annotations

import math
from typing import Annotated, Any, Literal

from pydantic import (
    ConfigDict,
    Discriminator,
    Field,
    Tag,
    ValidationInfo,
    field_validator,
    model_validator,
)

from dexroll_client.common import (
    MAX_DURATION,
    MAX_FINGER_JOINTS,
    MAX_FINGERS,
    MAX_INTERVALS,
    MAX_MOTION_KNOTS,
    MAX_POSITION,
    MAX_SAMPLE_RATE,
    MAX_SAMPLES,
    MAX_URDF_CHARS,
    MAX_VIA_POINTS,
    MAX_WARM_START_COLUMNS,
    MIN_DURATION,
    MIN_SIZE,
    Count,
    NlpPointModel,
    OptionalCount,
    Real,
    _planner_of,
    _Request,
)
from dexroll_client.gait import GaitModel
from dexroll_client.results import (
    CollocationModel,
    FingerPlanResult,
    ManipulationResult,
    PlanResult,
)

__all__ = [
    "BallOnPalmRequest",
    "ContactCoordinates",
    "FingerContactCoordinates",
    "FingerContactModel",
    "FingerModelSpec",
    "FingertipModel",
    "GraspModel",
    "GraspSearchModel",
    "HandModel",
    "HandTipModel",
    "ManipulationRequest",
    "MotionModel",
    "MotionSamplesModel",
    "MotionStepModel",
    "MotionStepsModel",
    "MountModel",
    "ObjectModel",
    "ObjectPoseModel",
    "OneFingerRequest",
    "PalmModel",
    "PartialContactCoordinates",
    "PlanRequest",
    "PlanRequestBase",
    "SolverModel",
    "TipSurfaceModel",
    "TrackingModel",
    "ViaPointModel",
    "WarmStartModel",
]

Position = Annotated[Real, Field(ge=-MAX_POSITION, le=MAX_POSITION)]
Angle = Annotated[Real, Field(ge=-100.0, le=100.0)]


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

    shape: Literal["sphere", "ellipsoid", "capsule", "superellipsoid"] = Field(
        default="sphere",
        description="'sphere', 'ellipsoid', 'capsule' or 'superellipsoid' (a box with "
                    "rounded edges; the service's catalog describes each)")
    dimensions: list[Annotated[Real, Field(ge=MIN_SIZE, le=1.0)]] = Field(
        default_factory=lambda: [0.025], min_length=1, max_length=4,
        description="sphere: [radius]; ellipsoid: [a, c], semi-axes a, a, c of revolution "
                    "about its z axis, or [a, b, c] along its x, y, z axes; capsule: "
                    "[radius, half_length], its axis the object's z; superellipsoid: "
                    "[a, b, c, edge_radius], half sides and the rounding of its edges [m]")
    chart_rotation: list[Annotated[Real, Field(ge=-2 * math.pi, le=2 * math.pi)]] = Field(
        default_factory=lambda: [0.0, 0.0, 0.0], min_length=3, max_length=3,
        description="rotation vector [rad] of the object's chart patch in the object frame")


class ViaPointModel(_Request):
    time: Real = Field(gt=0.0, le=MAX_DURATION, description="time of the via-point [s]")
    coords: PartialContactCoordinates = Field(description="coordinates to pass through")


class SolverModel(_Request):
    max_iter: Count = Field(default=1000, ge=1, le=100_000,
                          description="IPOPT iteration limit, all initial guesses together")
    time_limit: Real = Field(default=60.0, gt=0.0, le=3600.0,
                              description="wall-clock limit of the solve [s] (the service "
                                          "caps it at its own maximum)")
    cert_position_tol: Real = Field(default=1e-6, gt=0.0, le=1e-2, description=(
        "certificate tolerance on the re-integration defect of x, y [m]"))
    cert_angle_tol: Real = Field(default=1e-4, gt=0.0, le=1e-1, description=(
        "certificate tolerance on the re-integration defect of u, v, psi [rad]"))


# -- warm starts -----------------------------------------------------------------------------

WarmValue = Annotated[Real, Field(ge=-1e6, le=1e6)]
WarmRows = list[Annotated[list[WarmValue], Field(min_length=1,
                                                  max_length=MAX_WARM_START_COLUMNS)]]
ColumnNames = list[Annotated[str, Field(min_length=1, max_length=200)]]


class WarmStartModel(_Request):
    """A previous plan as the initial guess of this one: either ``job_id`` (a finished job
    of this service, with the same planner, whose result has a ``collocation`` block) or
    the plan itself, ``t``, ``x``, ``u`` (a result's ``collocation`` block, passed as it
    is: its ``state_names`` and ``input_names`` are optional and, when given, must be this
    request's columns, which catches a plan of another hand or finger).

    The service replaces ``job_id`` by that job's ``t``, ``x``, ``u`` at submission. A plan
    of another duration is stretched in time to this request's (its inputs, all rates,
    scaled by the inverse ratio), interpolated onto this request's grid, and its first state
    replaced by this request's initial state. IPOPT starts from it; if it does not converge
    from there, the planner falls back to its own initial guesses (within the time limit).
    The layout of the columns is the result's ``collocation`` block's (see
    :class:`CollocationModel`)."""

    job_id: str | None = Field(
        default=None, min_length=1, max_length=200, pattern=r"^[A-Za-z0-9_.\-]+$",
        description="the `id` of a finished job of this service with the same planner, "
                    "whose result has a `collocation` block (give this, or `t`, `x`, `u`)")
    t: list[Annotated[Real, Field(ge=0.0, le=MAX_DURATION)]] | None = Field(
        default=None, min_length=2, max_length=MAX_SAMPLES,
        description="the plan's sample times [s], from 0, strictly increasing (a result's "
                    "`collocation.t`)")
    x: WarmRows | None = Field(
        default=None, max_length=MAX_SAMPLES,
        description="the plan's states, one row per time in `t`, columns as a result's "
                    "`collocation.state_names` (SI units: m, rad)")
    u: WarmRows | None = Field(
        default=None, max_length=MAX_SAMPLES,
        description="the plan's inputs, one row per time in `t`, columns as a result's "
                    "`collocation.input_names` (SI units: m/s, rad/s)")
    state_names: ColumnNames | None = Field(
        default=None, max_length=MAX_WARM_START_COLUMNS,
        description="optional: the names of the columns of `x` (a result's "
                    "`collocation.state_names`); when given they must be this request's")
    input_names: ColumnNames | None = Field(
        default=None, max_length=MAX_WARM_START_COLUMNS,
        description="optional: the names of the columns of `u` (a result's "
                    "`collocation.input_names`); when given they must be this request's")
    nlp_point: NlpPointModel | None = Field(
        default=None, description="optional: IPOPT's primal-dual point at that plan (a "
                                  "result's `collocation.nlp_point`), used when this "
                                  "request has the same NLP")

    @field_validator("t")
    @classmethod
    def _times(cls, value: list[float] | None) -> list[float] | None:
        if value is None:
            return value
        if value[0] > 1e-12 * max(1.0, value[-1]):
            raise ValueError(f"must start at 0 (the plan's start), got {value[0]}")
        for i in range(1, len(value)):
            if value[i] <= value[i - 1]:
                raise ValueError(f"must increase strictly: t[{i}] = {value[i]} follows "
                                 f"t[{i - 1}] = {value[i - 1]}")
        return value

    @field_validator("x", "u")
    @classmethod
    def _rows(cls, value: list[list[float]] | None, info: ValidationInfo
              ) -> list[list[float]] | None:
        if value is None:
            return value
        widths = sorted({len(row) for row in value})
        if len(widths) > 1:
            raise ValueError(f"every row must have the same number of columns, got rows of "
                             f"{', '.join(map(str, widths))} columns")
        t = info.data.get("t")
        if t is not None and len(value) != len(t):
            raise ValueError(f"must have one row per time in `t` ({len(t)} rows), got "
                             f"{len(value)}")
        return value

    @field_validator("state_names", "input_names")
    @classmethod
    def _names(cls, value: list[str] | None, info: ValidationInfo) -> list[str] | None:
        if value is None:
            return value
        key = "x" if info.field_name == "state_names" else "u"
        rows = info.data.get(key)
        if rows and len(value) != len(rows[0]):
            raise ValueError(f"must name every column of `{key}` ({len(rows[0])}), got "
                             f"{len(value)} names")
        if len(set(value)) != len(value):
            raise ValueError("names must be unique")
        return value

    @model_validator(mode="after")
    def _one_form(self) -> WarmStartModel:
        inline = [k for k in ("t", "x", "u") if getattr(self, k) is not None]
        named = self.state_names is not None or self.input_names is not None \
            or self.nlp_point is not None
        if self.job_id is not None:
            if inline or named:
                raise ValueError("give either `job_id` or the plan's `t`, `x`, `u`, not both")
            return self
        if not inline:
            raise ValueError("give `job_id` (a finished job of this service) or a plan's "
                             "`t`, `x` and `u` (a result's `collocation` block)")
        missing = [k for k in ("t", "x", "u") if k not in inline]
        if missing:
            raise ValueError(f"{', '.join(f'`{k}`' for k in missing)} missing: give the "
                             "plan's `t`, `x` and `u` together")
        return self

    @classmethod
    def from_result(cls, result: PlanResult | FingerPlanResult | ManipulationResult
                    | CollocationModel) -> WarmStartModel:
        """The inline warm start of a result (its ``collocation`` block, names included),
        or of a ``collocation`` block itself; ValueError when the result has none (an
        invalid request, a greedy plan, a diverged last iterate)."""
        c = result if isinstance(result, CollocationModel) else result.collocation
        if c is None:
            status = getattr(result, "status", None)
            raise ValueError("the result has no `collocation` block to warm-start from"
                             + (f" (its status: {status})" if status is not None else ""))
        return cls(t=c.t, x=c.x, u=c.u, state_names=c.state_names,
                   input_names=c.input_names, nlp_point=c.nlp_point)


WARM_START_DESCRIPTION = (
    "optional: a previous plan as IPOPT's initial guess (a finished job's id, or a "
    "result's `collocation` block); stretched to this duration; the planner falls back to "
    "its own guesses when IPOPT does not converge from it")


def _times_inside(value: list[float] | None, info: ValidationInfo) -> list[float] | None:
    duration = info.data.get("duration")
    if value and duration is not None and max(value) > duration:
        raise ValueError(f"sample times must lie in [0, duration = {duration} s], "
                         f"got {max(value)}")
    return value


def _rate_fits(value: float | None, info: ValidationInfo) -> float | None:
    if value is None:
        return value
    if info.data.get("sample_times"):
        raise ValueError("give either `sample_times` or `sample_rate`, not both")
    duration = info.data.get("duration")
    if duration is not None and duration * value + 1 > MAX_SAMPLES:
        raise ValueError(f"{value} Hz over {duration} s gives more than {MAX_SAMPLES} "
                         "samples")
    return value


TIMING_DESCRIPTION = (
    "'smooth' (the default): the motion starts and ends at rest and every velocity (object, "
    "contacts, joints) is continuous, also at via-points, which are still met at their "
    "times; each joint's acceleration stays within `max_joint_acceleration` where the plan "
    "has joints. 'paper': the paper's piecewise timing (full speed at the start and the end, "
    "velocity jumps at via-points), for reproducing its figures")
RAMP_TIME_DESCRIPTION = (
    "a 'smooth' plan's ramps' time constant [s]: the objective weighs the rate of change of "
    "every velocity by its square, so that the plan speeds up and slows down over about "
    "this time; null: 15 % of the duration (ignored by 'paper' timing)")
MAX_JOINT_ACCELERATION_DESCRIPTION = (
    "bound on every joint's acceleration [rad/s^2] of a 'smooth' plan (ignored by 'paper' "
    "timing)")

SAMPLE_TIMES_DESCRIPTION = (
    "times [s] at which to return the plan (its collocation polynomials, the trajectory the "
    "certificate checked): `samples` and the `joint_trajectory`; null: the collocation "
    "points (not with `gait`, whose duration is its planner's: give `sample_rate`)")
SAMPLE_RATE_DESCRIPTION = (
    "a controller's rate [Hz]: the plan returned at k / rate for every k with k / rate < "
    "duration, then at duration (instead of `sample_times`)")


class PlanRequestBase(_Request):
    """What every planner's request shares, declared once: the object, the horizon and its
    grid, the refinements the certificate may ask for, the timing law, the solver's limits,
    where the plan is returned (``sample_times`` or ``sample_rate``) and the warm start.

    Each planner's request narrows ``planner`` to its own name and adds its own fields
    after these (the palm contact and its goals, fingers, a desired motion, weights and
    bounds)."""

    planner: str = Field(description="which planner")
    object: ObjectModel = Field(default_factory=ObjectModel)
    duration: Real = Field(ge=MIN_DURATION, le=MAX_DURATION, description="planning horizon [s]")
    n_intervals: Count = Field(default=50, ge=1, le=MAX_INTERVALS,
                             description="collocation intervals over the horizon")
    max_refinements: Count = Field(default=2, ge=0, le=5,
                                 description="grid refinements allowed when the certificate "
                                             "finds the grid too coarse (each makes it 2, "
                                             "4 or 8 times as fine)")
    timing: Literal["smooth", "paper"] = Field(default="smooth",
                                               description=TIMING_DESCRIPTION)
    ramp_time: Real | None = Field(default=None, gt=0.0, le=MAX_DURATION,
                                   description=RAMP_TIME_DESCRIPTION)
    solver: SolverModel = Field(default_factory=SolverModel)
    sample_times: list[Annotated[Real, Field(ge=0.0, le=MAX_DURATION)]] | None = Field(
        default=None, max_length=MAX_SAMPLES, description=SAMPLE_TIMES_DESCRIPTION)
    sample_rate: Real | None = Field(default=None, gt=0.0, le=MAX_SAMPLE_RATE,
                                     description=SAMPLE_RATE_DESCRIPTION)
    warm_start: WarmStartModel | None = Field(default=None,
                                              description=WARM_START_DESCRIPTION)

    @field_validator("sample_times")
    @classmethod
    def _samples_inside_horizon(cls, value: list[float] | None, info: ValidationInfo
                                ) -> list[float] | None:
        return _times_inside(value, info)

    @field_validator("sample_rate")
    @classmethod
    def _rate_within_limits(cls, value: float | None, info: ValidationInfo
                            ) -> float | None:
        return _rate_fits(value, info)


class _PalmRequest(PlanRequestBase):
    """What the planners of an object on the palm (ball_on_palm, one_finger) add: the palm
    contact, its goals and via-points, and the palm's bounds."""

    initial: ContactCoordinates = Field(description="contact coordinates at t = 0")
    goal: PartialContactCoordinates = Field(
        default_factory=PartialContactCoordinates,
        description="coordinates required at t = duration (any subset)")
    via_points: list[ViaPointModel] = Field(default_factory=list, max_length=MAX_VIA_POINTS)
    pole_margin: Real = Field(default=math.radians(15.0), gt=0.0, lt=math.pi / 2,
                               description="keep |u| <= pi/2 - pole_margin [rad]")
    max_contact_speed: Real = Field(default=1.0, gt=0.0, le=100.0,
                                     description="bound on each palm contact velocity "
                                                 "component [m/s]")
    palm_half_extent: Real = Field(default=0.5, gt=0.0, le=MAX_POSITION,
                                    description="palm coordinates stay in [-e, e] [m]")


class BallOnPalmRequest(_PalmRequest):
    """Roll an object on the flat palm between contact configurations (paper, section 3)."""

    planner: Literal["ball_on_palm"] = Field(default="ball_on_palm",
                                             description="which planner")


RotationVector = list[Annotated[Real, Field(ge=-2 * math.pi, le=2 * math.pi)]]


class FingerModelSpec(_Request):
    """The finger: a built-in one (``{"builtin": "k3s"}``, the default) or one's own URDF
    (``{"urdf": "<robot ...>...</robot>", "tip_frame": "..."}``), and its mount on the palm.

    The finger is a serial chain of revolute and prismatic joints; its tip frame is the
    flat square pad's frame: origin at the centre of the pad surface, +z the pad's outward
    normal (docs/conventions.md)."""

    builtin: Literal["k3s"] | None = Field(
        default=None, description="a built-in finger (GET /v1/models lists them); the "
                                  "default when `urdf` is not given")
    urdf: str | None = Field(
        default=None, min_length=1, max_length=MAX_URDF_CHARS,
        description="the finger's URDF document, as XML text (not a path); lengths in m, "
                    "angles in rad")
    tip_frame: str = Field(default="fingertip", min_length=1, max_length=200,
                           description="the URDF frame (link or joint) of the pad")
    base_position: list[Position] | None = Field(
        default=None, min_length=3, max_length=3,
        description="origin of the finger's base (the URDF root) in the palm frame [m]; "
                    "default: a built-in finger's own mount (GET /v1/models), the palm "
                    "origin for a URDF")
    base_rotation: RotationVector | None = Field(
        default=None, min_length=3, max_length=3,
        description="rotation vector [rad] of the finger's base in the palm frame; "
                    "default: a built-in finger's own mount (GET /v1/models), none (base "
                    "axes parallel to the palm's) for a URDF")
    pad_half_size: Real | None = Field(
        default=None, ge=MIN_SIZE, le=0.5,
        description="half the side of the square pad [m]; default: the built-in "
                    "finger's (GET /v1/models)")

    @field_validator("urdf")
    @classmethod
    def _urdf_is_text(cls, value: str | None) -> str | None:
        if value is not None and not value.lstrip().startswith("<"):
            raise ValueError("must be the URDF document itself (XML text starting with "
                             "'<'), not a file name")
        return value

    @model_validator(mode="after")
    def _one_source(self) -> FingerModelSpec:
        if self.builtin is not None and self.urdf is not None:
            raise ValueError("give either `builtin` or `urdf`, not both")
        return self


class FingerContactCoordinates(_Request):
    """The fingertip/ball contact coordinates eta_f = (x_f, y_f, u_f, v_f, psi_f)."""

    x_f: Position = Field(description="contact point on the pad, x in the pad frame [m]")
    y_f: Position = Field(description="contact point on the pad, y in the pad frame [m]")
    u_f: Angle = Field(description="ball chart latitude in the finger contact's chart "
                                   "patch [rad]")
    v_f: Angle = Field(description="ball chart longitude in the finger contact's chart "
                                   "patch [rad]")
    psi_f: Angle = Field(description="contact angle psi_f [rad]")

    def as_tuple(self) -> tuple[float, float, float, float, float]:
        return (self.x_f, self.y_f, self.u_f, self.v_f, self.psi_f)


class FingerContactModel(_Request):
    """Where the fingertip touches the ball at t = 0, and the ball chart patch its
    coordinates are measured in."""

    initial: FingerContactCoordinates = Field(description="finger contact coordinates at "
                                                          "t = 0")
    chart_rotation: RotationVector = Field(
        default_factory=lambda: [0.0, 0.0, math.pi], min_length=3, max_length=3,
        description="rotation vector [rad] of the finger contact's chart patch in the "
                    "object frame. The default [0, 0, pi] puts patch point (u_f, v_f) = "
                    "(0, 0) at the antipode of the object chart's (0, 0): with the default "
                    "object.chart_rotation and the palm contact starting at u = v = 0, that "
                    "is the ball's top at t = 0")
    q_seed: list[Angle] | None = Field(
        default=None, min_length=1, max_length=MAX_FINGER_JOINTS,
        description="joint angles [rad; m for a prismatic joint] from which the inverse "
                    "kinematics of the initial grasp starts, one per joint; default: the "
                    "paper's (0, -22.68, -12.34, 0, 47.65, 0) deg")


class ForcesModel(_Request):
    """Plan the contact forces (docs/forces.md): the object's load and the grip. At every
    collocation point each contact's force (and, for soft fingers, its torsion about the
    normal) holds the object in quasi-static equilibrium with its weight, inside the
    friction cone less ``cone_margin``, with at least ``min_normal_force`` along the normal;
    the result gives each contact's force and each finger's joint torques."""

    mass: Real = Field(gt=0.0, le=100.0, description="the object's mass [kg]")
    inertia: list[Annotated[Real, Field(gt=0.0, le=100.0)]] | None = Field(
        default=None, min_length=3, max_length=3,
        description="principal moments of inertia about the object's axes [kg m^2]; null: "
                    "the solid sphere's or ellipsoid's of that mass")
    gravity: list[Annotated[Real, Field(ge=-100.0, le=100.0)]] = Field(
        default_factory=lambda: [0.0, 0.0, -9.81], min_length=3, max_length=3,
        description="gravity in the palm frame [m/s^2]")
    min_normal_force: Real = Field(
        default=0.5, gt=0.0, le=1000.0,
        description="the grip: every contact pushes at least this hard along its normal [N]")
    torsional_friction: Real = Field(
        default=0.0, ge=0.0, le=0.1,
        description="soft-finger torsional friction [m]: the moment about the normal within "
                    "this times the normal force (0: hard point contacts)")
    cone_margin: Real = Field(
        default=0.05, ge=0.0, lt=math.pi / 2,
        description="the planned forces stay this far inside the friction cones [rad] (less "
                    "than atan(mu))")


def _planner_required(schema: dict[str, Any]) -> None:
    """The JSON schema of a request the wire tells apart by its ``planner`` only: the field
    required and without a default (a body without it is a ball_on_palm request; a
    Python caller naming the class has chosen its planner already)."""
    schema["required"] = ["planner", *(r for r in schema.get("required", [])
                                      if r != "planner")]
    schema["properties"]["planner"].pop("default", None)


class OneFingerRequest(_PalmRequest):
    """Roll a ball on the palm with one flat fingertip pressing on it, keeping the grasp
    inside the friction cone (paper, section 3). The plan holds the palm contact, the
    finger contact and the finger's joint angles (at ``sample_times`` or ``sample_rate``
    too, with its ``joint_trajectory``; not with the greedy method)."""

    model_config = ConfigDict(json_schema_extra=_planner_required)

    planner: Literal["one_finger"] = Field(
        default="one_finger",
        description="which planner (a request body must say 'one_finger': a body without "
                    "`planner` is a ball_on_palm request)")
    finger: FingerModelSpec = Field(default_factory=FingerModelSpec)
    finger_contact: FingerContactModel = Field(description="the fingertip/ball contact")
    mu: Real = Field(default=0.5, gt=0.0, le=10.0,
                      description="friction coefficient at both contacts (dimensionless); "
                                  "the friction cone's half-angle is atan(mu) [rad]")
    forces: ForcesModel | None = Field(
        default=None, description="plan the palm's and the fingertip's forces for this load "
                                  "and grip (method 'collocation'); null (the default): a "
                                  "kinematic plan")
    grasp_weight: Real = Field(
        default=100.0, ge=0.0, le=1e6,
        description="objective weight (dimensionless) of the grasp-angle term, the time "
                    "average of 1 - cos of the larger grasp angle (0 for an antipodal grasp)")
    finger_effort_weight: Real = Field(
        default=0.01, ge=0.0, le=1e6,
        description="objective weight (dimensionless) of the finger contact's velocity "
                    "over the ball |w_f|^2 [rad^2/s^2], relative to the palm contact's")
    joint_effort_weight: Real = Field(
        default=0.01, ge=0.0, le=1e6,
        description="objective weight (dimensionless) of the joint rates |q_dot|^2 "
                    "[rad^2/s^2]")
    pad_margin: Real = Field(default=0.002, ge=0.0, le=0.1,
                              description="distance kept between the finger contact and "
                                          "the pad's edge [m]")
    max_joint_acceleration: Real = Field(default=20.0, gt=0.0, le=1e5,
                                          description=MAX_JOINT_ACCELERATION_DESCRIPTION)
    method: Literal["collocation", "greedy"] = Field(
        default="collocation",
        description="'collocation': the direct-collocation NLP (effort plus grasp quality "
                    "over the whole horizon); 'greedy': the paper's own method (section 3): "
                    "the finger contact velocity chosen step by step by a grid search in the "
                    "ellipse bounding the rolling angle, joint rates from the Jacobian's "
                    "pseudo-inverse (200 steps); the weights do not apply to it, `timing` only "
                    "to the ball-on-palm plan whose path it follows")

    @field_validator("method")
    @classmethod
    def _greedy_has_no_polynomials(cls, value: str, info: ValidationInfo) -> str:
        if value == "greedy" and (info.data.get("sample_times")
                                  or info.data.get("sample_rate") is not None):
            raise ValueError("the greedy method's plan is its steps (no polynomials to "
                             "sample): drop `sample_times` / `sample_rate`, or use "
                             "'collocation'")
        return value


# -- manipulation: any grasp (an optional palm, one or more fingertips) ----------------------

Quaternion = list[Annotated[Real, Field(ge=-2.0, le=2.0)]]


class MountModel(_Request):
    """Where a hand's finger is mounted: the pose of its base in the palm frame."""

    position: list[Position] = Field(min_length=3, max_length=3,
                                     description="origin of the finger's base in the palm "
                                                 "frame [m]")
    rotation: RotationVector = Field(
        default_factory=lambda: [0.0, 0.0, 0.0], min_length=3, max_length=3,
        description="rotation vector [rad] of the finger's base in the palm frame")


class TipSurfaceModel(_Request):
    """A fingertip surface in its link's frame: a sphere, a spheroid, or a capsule (its
    hemispherical cap: contacts stay on it)."""

    kind: Literal["sphere", "spheroid", "capsule"] = Field(
        description="the tip's shape")
    dimensions: list[Annotated[Real, Field(gt=0.0, le=1.0)]] = Field(
        min_length=1, max_length=2,
        description="[m]: sphere [r]; spheroid [a, c] (semi-axes a, a, c about the tip "
                    "frame's z); capsule [r] or [r, half_length]")
    position: list[Position] = Field(
        default_factory=lambda: [0.0, 0.0, 0.0], min_length=3, max_length=3,
        description="in the link frame [m]: the sphere's or spheroid's centre, the "
                    "capsule cap's centre")
    rotation: RotationVector = Field(
        default_factory=lambda: [0.0, 0.0, 0.0], min_length=3, max_length=3,
        description="sphere, spheroid: rotation vector [rad] of the tip frame in the link "
                    "frame (the chart's poles on its z axis, (0, 0) on its x axis)")
    axis: list[Real] | None = Field(
        default=None, min_length=3, max_length=3,
        description="capsule: its axis out of the cap (link frame); required for a capsule")
    side: list[Real] | None = Field(
        default=None, min_length=3, max_length=3,
        description="capsule: the direction across the axis the contacts lean to (link "
                    "frame); default the link's x axis (else y)")


class HandTipModel(_Request):
    """A fingertip of a hand model: the link (URDF) or body (MJCF) its finger ends at."""

    name: str = Field(min_length=1, max_length=200,
                      description="the fingertip's link (URDF), body or site (MJCF), or a "
                                  "frame of the model")
    surface: TipSurfaceModel | None = Field(
        default=None, description="the tip's surface; default: read from the link's sphere "
                                  "or capsule collision geometry")
    side: list[Real] | None = Field(
        default=None, min_length=3, max_length=3,
        description="for a capsule read from the model: the direction (link frame) across "
                    "its axis the contacts lean to (the cap's chart puts its poles across "
                    "both); default the link's x axis")


class HandModel(_Request):
    """A hand: a built-in one (``GET /v1/models`` lists them), or one's own whole-hand
    model (``urdf`` or ``mjcf`` text with its fingertips named in ``tips``); its fingers
    are picked by ``fingers[].hand_finger`` (an index into the hand's fingers, or into
    ``tips``)."""

    builtin: Literal["two_finger", "three_finger", "allegro"] | None = Field(
        default=None, description="a built-in hand: 'two_finger', 'three_finger' (flat "
                                  "pads) or 'allegro' (4 fingers, 16 joints, capsule tips)")
    urdf: str | None = Field(default=None, min_length=1,
                             description="a whole hand's URDF document (XML text)")
    mjcf: str | None = Field(default=None, min_length=1,
                             description="a whole hand's MJCF document (XML text, one file: "
                                         "no <include>)")
    tips: list[HandTipModel] | None = Field(
        default=None, min_length=1, max_length=MAX_FINGERS,
        description="with `urdf` or `mjcf`: the fingertips, one finger each (the chain "
                    "from the model's root to the tip)")
    mount: MountModel | None = Field(
        default=None, description="with `urdf` or `mjcf`: the pose of the model's root in "
                                  "the palm frame; default the palm frame itself")
    mounts: list[MountModel] | None = Field(
        default=None, min_length=1, max_length=MAX_FINGERS,
        description="two_finger, three_finger: the fingers' mounts on the palm, one per "
                    "finger of the hand in its order; default: the hand's own "
                    "(GET /v1/models)")
    torque_limits: dict[str, Annotated[Real, Field(gt=0.0, le=1e4)]] | None = Field(
        default=None, max_length=MAX_FINGERS * MAX_FINGER_JOINTS,
        description="with `urdf` or `mjcf`, or the built-in allegro: the torque [N m] each "
                    "named joint's actuator gives, either way (over the file's forcerange "
                    "or effort; a joint the file leaves unlimited gets one); the plan's "
                    "holds, rolls and swings keep within them and a plan that cannot is "
                    "refused (docs/actuation.md)")

    @model_validator(mode="after")
    def _one_source(self) -> HandModel:
        given = [k for k in ("builtin", "urdf", "mjcf") if getattr(self, k) is not None]
        if len(given) != 1:
            raise ValueError("give exactly one of `builtin`, `urdf` or `mjcf`")
        if self.builtin is None and not self.tips:
            raise ValueError("a hand model (`urdf` or `mjcf`) needs `tips`: its fingertip "
                             "links")
        if self.builtin is not None and self.tips is not None:
            raise ValueError("`tips` are for a hand model (`urdf` or `mjcf`); a built-in "
                             "hand has its own")
        if self.mounts is not None and self.builtin not in ("two_finger", "three_finger"):
            raise ValueError("`mounts` reconfigure the two_finger and three_finger hands; "
                             "use `mount` for a hand model")
        return self


class FingertipModel(_Request):
    """One fingertip touching the object: which finger (``finger``: a finger model, or
    ``hand_finger``: the index of a finger of ``hand``; exactly one of the two), where its
    flat pad touches the object at t = 0, and the object chart patch its contact
    coordinates are measured in."""

    finger: FingerModelSpec | None = Field(
        default=None, description="the finger (a built-in one or a URDF, and its mount); "
                                  "give this or `hand_finger`")
    hand_finger: OptionalCount = Field(
        default=None, ge=0, lt=MAX_FINGERS, validate_default=True,
        description="index of a finger of the request's `hand` (0-based, in the hand's "
                    "order; requires `hand`); give this or `finger`")
    name: str | None = Field(
        default=None, min_length=1, max_length=40, pattern=r"^[A-Za-z][A-Za-z0-9_\-]*$",
        description="a name for this contact in the result (unique, not 'palm'); default: "
                    "the hand's name of the finger, else 'finger<i>'")
    initial: FingerContactCoordinates | None = Field(
        default=None,
        description="the contact coordinates at t = 0: (x_f, y_f) on the pad [m] (a round "
                    "tip: its chart's latitude and longitude [rad]), (u_f, v_f) on the "
                    "object in this contact's chart patch [rad], psi_f [rad]; give it with "
                    "`chart_rotation`, or neither: the contact where `initial_q` (default "
                    "the hand's nominal grasp) puts a round tip on the object")
    initial_q: list[Angle] | None = Field(
        default=None, min_length=1, max_length=MAX_FINGER_JOINTS,
        description="a round tip, without `initial`: the finger's joint angles at t = 0 "
                    "[rad]; its contact is where they put the tip on the object (its nearest "
                    "point; a gap up to 2 mm is closed by the least joint motion); default: "
                    "the hand's nominal grasp")
    chart_rotation: RotationVector | None = Field(
        default=None, min_length=3, max_length=3,
        description="rotation vector [rad] of this contact's chart patch in the object "
                    "frame: patch point (u_f, v_f) = (0, 0) is where the rotated x axis "
                    "leaves the object (keep the contact near it, away from the patch's "
                    "poles at u_f = +-pi/2)")
    q_seed: list[Angle] | None = Field(
        default=None, min_length=1, max_length=MAX_FINGER_JOINTS,
        description="joint angles [rad; m for a prismatic joint] from which the inverse "
                    "kinematics of the initial grasp starts, one per joint; default: a hand "
                    "finger's nominal grasp angles (GET /v1/models), else the paper's "
                    "(0, -22.68, -12.34, 0, 47.65, 0) deg")

    @field_validator("hand_finger")
    @classmethod
    def _one_finger_source(cls, value: int | None, info: ValidationInfo) -> int | None:
        if "finger" not in info.data:  # `finger` itself is invalid: reported there
            return value
        if value is not None and info.data["finger"] is not None:
            raise ValueError("give either `finger` or `hand_finger`, not both")
        if value is None and info.data["finger"] is None:
            raise ValueError("give `finger` (a finger model) or `hand_finger` (the index of "
                             "a finger of `hand`)")
        return value

    @model_validator(mode="after")
    def _initial_contact(self) -> FingertipModel:
        if (self.initial is None) != (self.chart_rotation is None):
            raise ValueError("give `initial` with `chart_rotation` (the patch its "
                             "coordinates are in), or neither (the contact from "
                             "`initial_q` or the hand's nominal grasp)")
        if self.initial is not None and self.initial_q is not None:
            raise ValueError("give `initial` (contact coordinates) or `initial_q` (joint "
                             "angles), not both")
        return self


class PalmModel(_Request):
    """A flat palm (the palm frame's z = 0 plane) carrying the object, and the palm
    contact's coordinates eta_p = (x, y, u, v, psi) in the object's chart
    (``object.chart_rotation``)."""

    initial: ContactCoordinates = Field(description="palm contact coordinates at t = 0")
    goal: PartialContactCoordinates = Field(
        default_factory=PartialContactCoordinates,
        description="palm contact coordinates required at t = duration (any subset)")
    via_points: list[ViaPointModel] = Field(default_factory=list, max_length=MAX_VIA_POINTS)
    palm_half_extent: Real = Field(default=0.5, gt=0.0, le=MAX_POSITION,
                                    description="palm coordinates stay in [-e, e] [m]")
    max_contact_speed: Real = Field(default=1.0, gt=0.0, le=100.0,
                                     description="bound on each palm contact velocity "
                                                 "component [m/s]")


class ObjectPoseModel(_Request):
    """A pose of the object in the palm frame."""

    orientation_wxyz: Quaternion = Field(
        default_factory=lambda: [1.0, 0.0, 0.0, 0.0], min_length=4, max_length=4,
        description="orientation, unit quaternion (w, x, y, z)")
    position: list[Position] = Field(min_length=3, max_length=3,
                                     description="the object's centre [m]")


class MotionStepModel(_Request):
    """Over ``duration``, rotate the object by ``angle`` about ``axis`` (through its
    centre) and translate its centre by ``translation``."""

    duration: Real = Field(ge=MIN_DURATION, le=MAX_DURATION,
                           description="duration of the step [s]")
    axis: list[Annotated[Real, Field(ge=-1e3, le=1e3)]] = Field(
        default_factory=lambda: [0.0, 0.0, 1.0], min_length=3, max_length=3,
        description="rotation axis, a direction in the palm frame (any length but zero)")
    angle: Angle = Field(default=0.0, description="rotation angle about `axis` [rad] "
                                                  "(right hand)")
    translation: list[Position] = Field(
        default_factory=lambda: [0.0, 0.0, 0.0], min_length=3, max_length=3,
        description="displacement of the object's centre, palm frame [m]")


class MotionStepsModel(_Request):
    """A desired motion as steps one after the other from the initial pose (the paper's
    'rotate about Z by 20 deg, then about Y by 20 deg, ...'); the steps' durations add up
    to the request's duration."""

    kind: Literal["steps"] = Field(description="'steps'")
    steps: list[MotionStepModel] = Field(min_length=1, max_length=MAX_MOTION_KNOTS - 1)
    smooth: bool = Field(default=True, description="ease in and out of every step (zero "
                                                   "velocity between steps); else constant "
                                                   "rate")


class MotionSamplesModel(_Request):
    """A desired motion as poses at knot times (from 0 to the request's duration),
    interpolated on SE(3): the geodesic between orientations, the straight line between
    positions."""

    kind: Literal["samples"] = Field(description="'samples'")
    times: list[Annotated[Real, Field(ge=0.0, le=MAX_DURATION)]] = Field(
        min_length=2, max_length=MAX_MOTION_KNOTS,
        description="knot times [s], from 0 to the duration, increasing")
    orientations_wxyz: list[Annotated[Quaternion, Field(min_length=4, max_length=4)]] = Field(
        min_length=2, max_length=MAX_MOTION_KNOTS,
        description="the object's orientation at each knot, unit quaternion (w, x, y, z)")
    positions: list[Annotated[list[Position], Field(min_length=3, max_length=3)]] = Field(
        min_length=2, max_length=MAX_MOTION_KNOTS,
        description="the object's centre at each knot, palm frame [m]")
    smooth: bool = Field(default=True, description="ease in and out of every knot (zero "
                                                   "velocity at knots); else constant rate")


#: A desired object motion, told apart by its ``kind``.
MotionModel = Annotated[MotionStepsModel | MotionSamplesModel, Field(discriminator="kind")]


class TrackingModel(_Request):
    """How hard the object follows ``motion``: weights of the tracking terms of the
    objective, and optional hard bounds on the tracking errors at every instant."""

    position_weight: Real = Field(
        default=1e4, ge=0.0, le=1e8,
        description="weight (dimensionless) of the time average of |p - p_d|^2 / L^2 (L: "
                    "the object's largest semi-axis)")
    orientation_weight: Real = Field(
        default=1e4, ge=0.0, le=1e8,
        description="weight (dimensionless) of the time average of 1 - cos(angle between "
                    "the object's orientation and the desired one)")
    position_tolerance: Real | None = Field(
        default=None, gt=0.0, le=MAX_POSITION,
        description="bound on |p - p_d| at every instant [m] (checked by the certificate); "
                    "null: none")
    orientation_tolerance: Real | None = Field(
        default=None, gt=0.0, le=math.pi,
        description="bound on the angle between the object's orientation and the desired "
                    "one at every instant [rad]; null: none")


class GraspSearchModel(_Request):
    """How the first grasp is searched (docs/hands.md, "A first grasp for any hand")."""

    samples: int = Field(
        default=1500, ge=50, le=20000,
        description="joint vectors drawn per searched finger within its limits (its nominal "
                    "grasp and `q_seed` first); those whose round tip comes near the ball "
                    "with its cap facing it are pulled onto it")
    candidates: int = Field(
        default=8, ge=1, le=16,
        description="contacts per finger weighed in combinations: its farthest-reaching "
                    "toward the motion and as many of its most distinct normals")
    min_gap: Real = Field(default=0.001, ge=0.0, le=0.05,
                          description="least distance between two fingertips [m]")
    maximise_reach: bool = Field(
        default=True,
        description="roll every candidate through the motion's turns and take the grasp "
                    "whose least finger reach toward them is largest (then the most "
                    "closed); false: the most closed grasp (contacts opposing best)")
    seed: int = Field(default=0, ge=0, le=2**31 - 1,
                      description="the random draw's seed (the same request, the same grasp)")


def _grasp_kind(value: object) -> str:
    """The tag of a request's ``grasp``: the shorthand 'auto' (any string) or the object."""
    return "auto" if isinstance(value, str) else "search"


class GraspModel(_Request):
    """A first grasp found for the request: the joint angles of every finger that gives
    neither `initial_q` nor `initial`, every chosen fingertip touching the ball, the
    contacts in force closure."""

    search: GraspSearchModel = Field(default_factory=GraspSearchModel,
                                     description="the search's settings")


class ManipulationRequest(PlanRequestBase):
    """Manipulate an object with any grasp: an optional flat palm carrying it and one or
    more flat fingertips rolling on it (paper, sections 3 and 4, and beyond). Without a
    palm the object starts at ``initial_pose`` and follows ``motion``; with one, its pose
    comes from the palm contact, driven to the palm's goal/via-points and/or ``motion``.
    The plan is returned at the collocation points, and at ``sample_times`` or
    ``sample_rate`` when given (``samples``); ``joint_trajectory`` at the latter."""

    planner: Literal["manipulation"] = Field(description="which planner")
    hand: HandModel | None = Field(
        default=None, description="a built-in hand whose fingers `fingers[].hand_finger` "
                                  "picks; required when a fingertip gives `hand_finger` "
                                  "(else 422 naming `fingers[i].hand_finger`)")
    fingers: list[FingertipModel] = Field(min_length=1, max_length=MAX_FINGERS,
                                          description="the fingertips touching the object")
    palm: PalmModel | None = Field(default=None, description="the palm carrying the object; "
                                                             "null: held by the fingers alone")
    initial_pose: ObjectPoseModel | None = Field(
        default=None, description="the object's pose at t = 0 (required without a palm; "
                                  "with one, the palm contact fixes it)")
    motion: MotionModel | None = Field(default=None,
                                       description="the desired object motion (required "
                                                   "without a palm)")
    tracking: TrackingModel = Field(default_factory=TrackingModel)
    grasp: Annotated[Annotated[Literal["auto"], Tag("auto")]
                     | Annotated[GraspModel, Tag("search")],
                     Discriminator(_grasp_kind)] | None = Field(
        default=None,
        description="find the initial grasp (a ball held by round fingertips, no palm): "
                    "joint angles of every finger without `initial_q` or `initial` that put "
                    "its tip on the ball with the contacts opposing each other (force "
                    "closure), maximising the rolled reach toward `motion`; the result's "
                    "`grasp` says which was used. 'auto': {\"search\": {}}; null: the "
                    "fingers' `initial_q` (or the hand's nominal grasp)")
    gait: GaitModel | None = Field(
        default=None, description="turn the ball by `motion`'s one rotation step farther "
                                   "than rolling can: rolls and fingertip re-placements "
                                   "(docs/gait.md); null: one rolling plan")
    forces: ForcesModel | None = Field(
        default=None, description="plan the contact forces for this load and grip; null (the "
                                  "default): a kinematic plan")
    mu: Real = Field(default=0.5, gt=0.0, le=10.0,
                      description="friction coefficient at every contact (dimensionless); "
                                  "the friction cone's half-angle is atan(mu) [rad]")
    object_effort_weight: Real = Field(
        default=1.0, ge=0.0, le=1e6,
        description="objective weight (dimensionless) of the object's own motion: the palm "
                    "contact velocity, or the free object's twist (scaled by the object's "
                    "size and the duration)")
    finger_effort_weight: Real = Field(
        default=0.01, ge=0.0, le=1e6,
        description="objective weight (dimensionless) of the fingertip contacts' motion "
                    "over the object |w_i|^2 [rad^2/s^2]")
    joint_effort_weight: Real = Field(
        default=0.01, ge=0.0, le=1e6,
        description="objective weight (dimensionless) of the joint rates |q_dot|^2 "
                    "[rad^2/s^2]")
    grasp_weight: Real = Field(
        default=100.0, ge=0.0, le=1e6,
        description="objective weight (dimensionless) of the grasp-quality term, the time "
                    "average of 1 - cos of the largest force angle (0: every contact pushes "
                    "along its normal)")
    pad_margin: Real = Field(default=0.002, ge=0.0, le=0.1,
                              description="distance kept between each contact and its "
                                          "pad's edge [m]")
    max_joint_acceleration: Real = Field(default=20.0, gt=0.0, le=1e5,
                                          description=MAX_JOINT_ACCELERATION_DESCRIPTION)
    pole_margin: Real = Field(default=math.radians(15.0), gt=0.0, lt=math.pi / 2,
                               description="keep |u| <= pi/2 - pole_margin on every contact's "
                                           "chart patch [rad]")
    max_object_speed: Real = Field(default=1.0, gt=0.0, le=100.0,
                                    description="bound on each component of a free object's "
                                                "velocity [m/s]")
    max_object_rate: Real = Field(default=20.0, gt=0.0, le=1000.0,
                                   description="bound on each component of a free object's "
                                               "angular velocity [rad/s]")


#: Every planning request, told apart by its ``planner`` field ("ball_on_palm" when the
#: field is absent). Later planners join this union (one endpoint serves them all).
PlanRequest = Annotated[
    Annotated[BallOnPalmRequest, Tag("ball_on_palm")]
    | Annotated[OneFingerRequest, Tag("one_finger")]
    | Annotated[ManipulationRequest, Tag("manipulation")],
    Discriminator(_planner_of, custom_error_type="invalid_planner",
                  custom_error_message="planner must be one of 'ball_on_palm', "
                                       "'one_finger', 'manipulation'"),
]
