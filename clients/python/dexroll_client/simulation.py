"""The wire contract of a plan's execution in MuJoCo (``POST /v1/plans/{id}/simulation``,
docs/simulation.md): the options of a run and its report.

Import from :mod:`dexroll_client.simulation`.
"""

from __future__ import annotations

import math
from typing import Annotated, Any, Literal

from pydantic import Field, ValidationInfo, field_validator, model_validator

from dexroll_client.common import (
    MAX_DURATION,
    Count,
    OptionalCount,
    Real,
    _Request,
    _Response,
)

__all__ = [
    "ClosedLoopBlock",
    "ClosedLoopOptions",
    "ContactExecutionModel",
    "ControlEventModel",
    "ControlTimingModel",
    "DisturbanceOptions",
    "ErrorSummaryModel",
    "KickModel",
    "LoopSummaryModel",
    "OpenLoopBlock",
    "PoseNoiseModel",
    "SimulationOptions",
    "SimulationReport",
    "SimulationSeriesModel",
    "SimulationTolerances",
]


class SimulationTolerances(_Request):
    """What an execution must meet to pass."""

    position: Real = Field(default=1e-3, gt=0.0, le=1.0,
                           description="worst distance of the object's centre from the "
                                       "plan's [m]")
    angle: Real = Field(default=math.radians(2.0), gt=0.0, le=math.pi,
                        description="worst angle between the object's orientation and the "
                                    "plan's [rad]")
    contact_loss: Real = Field(default=0.0, ge=0.0, le=3600.0,
                               description="time a planned contact may be lost, in all, "
                                           "after settling [s]")


class KickModel(_Request):
    """A push or an impulse on the object at a time of the plan's clock, palm frame."""

    time: Real = Field(ge=0.0, le=MAX_DURATION, description="when [s] (the plan's clock)")
    vector: Annotated[list[Annotated[Real, Field(ge=-0.1, le=0.1)]],
                      Field(min_length=3, max_length=3)] = Field(
        description="a push: the displacement [m] (a kinematic shift: the object's position "
                    "set that far in one step, its velocity kept); an impulse: [N s] (its "
                    "velocity changed by p / m)")


class PoseNoiseModel(_Request):
    """Gaussian noise on the object's pose as the closed loop's controller measures it."""

    position: Real = Field(default=0.0, ge=0.0, le=0.1,
                           description="standard deviation of the position [m]")
    angle: Real = Field(default=0.0, ge=0.0, le=math.pi,
                        description="standard deviation of the orientation [rad]")


class DisturbanceOptions(_Request):
    """What the world does that the plan did not expect (docs/simulation.md,
    "Disturbances"; the command line's ``--push``, ``--impulse``, ``--friction-scale``,
    ``--size-change``, ``--mass-scale``, ``--pose-noise``, ``--seed``): open and closed
    loop alike."""

    pushes: list[KickModel] = Field(default_factory=list, max_length=100,
                                    description="the object displaced (`vector` [m])")
    impulses: list[KickModel] = Field(default_factory=list, max_length=100,
                                      description="impulses on the object (`vector` [N s])")
    friction_scale: Real = Field(default=1.0, gt=0.0, le=10.0,
                                 description="every contact's friction coefficient times "
                                             "this (the plan keeps its own)")
    size_change: Real = Field(default=0.0, gt=-0.05, lt=0.05,
                              description="added to each of the object's semi-axes [m] (a "
                                          "ball 1 mm larger in diameter: 0.0005)")
    mass_scale: Real = Field(default=1.0, ge=0.01, le=100.0,
                             description="the object's mass times this (0.01 to 100)")
    pose_noise: PoseNoiseModel = Field(default_factory=PoseNoiseModel,
                                       description="noise on the measured pose (closed loop)")
    seed: Count = Field(default=0, ge=0, le=2**31 - 1, description="the noise's seed")


class ClosedLoopOptions(_Request):
    """Control from the measured state while MuJoCo runs (docs/simulation.md, "Closed
    loop"; docs/control.md; the command line's ``--closed-loop``): the open-loop run in
    the same disturbed world beside it."""

    controller: Literal["replan", "window"] = Field(
        default="replan",
        description="replan: the rest of the motion re-planned at `rate`, MuJoCo paused at "
                    "each call; window: a short window of the plan re-solved at every tick "
                    "in real time (the simulation does not wait: each tick's latency is "
                    "charged in simulated time), every window certified after the run")
    rate: Real = Field(default=4.0, gt=0.0, le=200.0,
                       description="the controller's rate in simulated time [Hz] (at most "
                                   "50 for replan)")
    max_iter: Count = Field(default=30, ge=1, le=500,
                            description="IPOPT iterations per re-plan, or per window tick "
                                        "(the command line's window default: 1)")
    backend: Literal["ipopt", "rti", "auto"] = Field(
        default="ipopt",
        description="the window's solver (controller window): ipopt (IPOPT on the "
                    "collocation window), rti (real-time iterations by multiple shooting, "
                    "QPs by HPIPM, each tick linearised before its measurement: the faster "
                    "for one fingertip), auto (both measured before the run, the faster "
                    "kept; docs/control.md)")

    @model_validator(mode="after")
    def _replan_rate(self) -> ClosedLoopOptions:
        if self.controller == "replan" and self.rate > 50.0:
            raise ValueError("rate: at most 50 Hz for the re-planner (MuJoCo pauses for "
                             "each re-plan); the window controller runs up to 200 Hz")
        return self

    @field_validator("backend")
    @classmethod
    def _window_backend(cls, v: str, info: ValidationInfo) -> str:
        if info.data.get("controller") == "replan" and v != "ipopt":
            raise ValueError("the re-planner solves with IPOPT; 'rti' and 'auto' are the "
                             "window controller's (controller 'window')")
        return v


class SimulationOptions(_Request):
    """How the plan is executed (defaults: docs/simulation.md). Unset fields take the
    simulator's defaults."""

    model: Literal["scene", "request"] | None = Field(
        default=None, description="scene (default): dexroll's scene of the plan's models "
                                  "(docs/simulation.md); request: the request's own MJCF "
                                  "hand (`hand.mjcf`) with its bodies, masses, actuators and "
                                  "contact settings (meshes stripped), driven through its "
                                  "actuators (mode servo)")
    mode: Literal["servo", "kinematic", "replay"] = Field(
        default="servo", description="servo: the joints follow the plan through position "
                                     "servos; kinematic: the joints are set to the plan; "
                                     "replay: the object too (nothing simulated)")
    squeeze: Real | None = Field(default=None, ge=0.0, le=0.01,
                                 description="how far the fingertips' references go into "
                                             "the object along the pad's normal [m] "
                                             "(default 0.0005)")
    force_control: Literal["off", "pi", "admittance"] | None = Field(
        default=None, description="off: the plan's forces fed forward only (J^T f); pi: "
                                  "contact-force feedback on top, each fingertip's "
                                  "measured normal force brought to the planned one by a "
                                  "PI law along the planned normal as joint torques; "
                                  "admittance: the same error shifts the servo's set "
                                  "point along the planned normal (docs/simulation.md, "
                                  "\"Force control\"); default: the plan's own "
                                  "(admittance for a gait), else off")
    force_kp: Real | None = Field(default=None, ge=0.0, le=100.0,
                                  description="force control's proportional gain [N/N] "
                                              "(default 0.1)")
    force_ki: Real | None = Field(default=None, ge=0.0, le=1e5,
                                  description="force control's integral gain [1/s] "
                                              "(default 400)")
    force_limit: Real | None = Field(default=None, ge=0.0, le=1000.0,
                                     description="force control's largest correction [N] "
                                                 "(default 3)")
    force_min: Real | None = Field(default=None, ge=0.0, le=100.0,
                                   description="the least normal force [N] force control "
                                               "holds a contact the plan has touching at "
                                               "(default 0.65)")
    force_shift_ki: Real | None = Field(default=None, ge=0.0, le=10.0,
                                        description="admittance force control's gain: the "
                                                    "set point's shift per unit force "
                                                    "error and second [m/(N s)] (default "
                                                    "0.02)")
    force_shift_limit: Real | None = Field(default=None, ge=0.0, le=0.01,
                                           description="admittance force control's largest "
                                                       "shift into the object [m] (default "
                                                       "0.0005)")
    grip_force: Real | None = Field(default=None, ge=0.0, le=1000.0,
                                    description="each fingertip's push along its normal, "
                                                "as torque feed-forward J^T f [N] "
                                                "(default 1)")
    kp: Real | None = Field(default=None, gt=0.0, le=1e6,
                            description="servo stiffness [N m/rad] (default 200)")
    kv: Real | None = Field(default=None, ge=0.0, le=1e5,
                            description="servo damping [N m s/rad] (default 2)")
    object_mass: Real | None = Field(default=None, gt=0.0, le=100.0,
                                     description="the object's mass [kg] (default: the "
                                                 "plan's, else 0.05)")
    condim: Literal[3, 4, 6] | None = Field(
        default=None, description="MuJoCo's contact dimension: 3 point contact, 4 with "
                                  "torsional friction (default), 6 with rolling friction")
    torsional_friction: Real | None = Field(default=None, ge=0.0, le=1.0,
                                            description="torsional friction [m] (default: "
                                                        "the plan's, else 0.005)")
    rolling_friction: Real | None = Field(default=None, ge=0.0, le=1.0,
                                          description="rolling friction [m] with condim 6 "
                                                      "(default 0)")
    impratio: Real | None = Field(default=None, gt=0.0, le=1000.0,
                                  description="MuJoCo's ratio of frictional to normal "
                                              "constraint impedance (default 10)")
    noslip_iterations: OptionalCount = Field(default=None, ge=0, le=100,
                                            description="MuJoCo's no-slip solver "
                                                        "iterations (default 3)")
    use_plan_forces: bool | None = Field(default=None,
                                         description="a plan that states contact forces or "
                                                     "joint torques is executed with them "
                                                     "as feed-forward instead of "
                                                     "`grip_force` (default true)")
    timestep: Real | None = Field(default=None, ge=1e-5, le=2e-3,
                                  description="the physics step [s] (default 0.0005)")
    settle: Real | None = Field(default=None, ge=0.0, le=5.0,
                                description="the grasp is held before t = 0 for this "
                                            "long [s] (default 0.2)")
    record_every: OptionalCount = Field(default=None, ge=1, le=100_000,
                                       description="steps between the report's series "
                                                   "rows (default 10)")
    tolerances: SimulationTolerances = Field(default_factory=SimulationTolerances)
    disturbances: DisturbanceOptions | None = Field(
        default=None, description="pushes, impulses, friction, size and mass changes, pose "
                                  "noise (null: none); the report then has `disturbances`")
    closed_loop: ClosedLoopOptions | None = Field(
        default=None, description="re-plan from the measured state at `rate` (a plan with "
                                  "fingers by direct collocation, on dexroll's scene with "
                                  "servos): the report is the closed loop's, with "
                                  "`open_loop` (the same world, open loop) and `closed_loop` "
                                  "(the controller's calls and timing) beside it")

    def simulator_options(self) -> dict[str, Any]:
        """The fields set, as the simulator's option names (``sim.SimOptions``); the
        disturbances and the closed loop as their own keys (``sim.disturbances``)."""
        out = self.model_dump(exclude_none=True, exclude={"disturbances", "closed_loop"})
        if self.disturbances is not None:
            d = self.disturbances
            out["disturbances"] = {
                "pushes": [k.model_dump() for k in d.pushes],
                "impulses": [k.model_dump() for k in d.impulses],
                "friction_scale": d.friction_scale, "size_change": d.size_change,
                "mass_scale": d.mass_scale,
                "pose_noise": [d.pose_noise.position, d.pose_noise.angle], "seed": d.seed}
        if self.closed_loop is not None:
            out["closed_loop"] = self.closed_loop.model_dump()
        return out


class ErrorSummaryModel(_Response):
    max: float = Field(description="worst value over the plan's horizon [m or rad]")
    worst_at: float | None = Field(default=None, description="its time [s]")
    final: float = Field(description="value at the plan's end [m or rad]")
    rms: float = Field(description="root mean square over the horizon [m or rad]")


class ContactExecutionModel(_Response):
    """One planned contact during the executed plan (from t = 0)."""

    name: str = Field(description="the contact's name, as in the plan")
    body: str = Field(description="'palm' or 'finger'")
    lost_time: float = Field(description="time without touching (no normal force) [s]")
    loss_events: int = Field(description="separate losses")
    first_loss_at: float | None = Field(default=None, description="the first loss [s]")
    slip_distance: float = Field(description="integral of the tangential speed of the "
                                             "object's material point relative to the "
                                             "touching body [m]")
    max_slip_speed: float = Field(description="its worst [m/s]")
    normal_force_min: float = Field(description="[N]")
    normal_force_mean: float = Field(description="[N]")
    normal_force_max: float = Field(description="[N]")
    planned_normal_force_mean: float | None = Field(
        default=None, description="the plan's normal force at this contact, its mean [N] "
                                  "(null: the plan states no forces)")
    normal_force_error_max: float | None = Field(
        default=None, description="worst |simulated - planned| normal force [N] (null: the "
                                  "plan states no forces)")
    unplanned_touch_time: float = Field(
        default=0.0, description="time the fingertip touched the object while the plan has "
                                 "it lifted clear (a gait) [s]")
    lost_separation_max: float | None = Field(
        default=None, description="the largest distance between the touching bodies at a "
                                  "step counted as a loss [m] (micrometres: a stiff "
                                  "contact's flicker; null: no loss)")


class SimulationSeriesModel(_Response):
    t: list[float] = Field(description="recorded times [s] (negative: settling)")
    position_error: list[float] = Field(description="[m]")
    angle_error: list[float] = Field(description="[rad]")
    normal_force: dict[str, list[float]] = Field(description="each contact's normal force "
                                                             "[N]")


class LoopSummaryModel(_Response):
    """A disturbed run's figures (open or closed loop), side by side."""

    passed: bool = Field(description="the run's report passed (against the first plan)")
    position_final_mm: float = Field(description="final distance from the first plan [mm]")
    position_worst_mm: float = Field(description="worst distance from the first plan [mm]")
    angle_final_deg: float = Field(description="final angle from the first plan [deg]")
    angle_worst_deg: float = Field(description="worst angle from the first plan [deg]")
    contacts_lost_s: dict[str, float] = Field(description="each contact's lost time [s]")
    contact_lost_after_kicks: bool = Field(description="a contact lost from 0.1 s after the "
                                                       "last push or impulse on")
    goal_position_mm: float | None = Field(default=None,
                                           description="final distance from the task's goal "
                                                       "[mm]")
    goal_angle_deg: float | None = Field(default=None,
                                         description="final angle from the task's goal [deg] "
                                                     "(null: the task leaves it free)")
    recovered: bool = Field(description="ends within the tolerances of the goal, no contact "
                                        "lost after the kicks")


class ControlTimingModel(_Response):
    """The closed loop's controller: its rate and the re-plans' wall time."""

    rate: float = Field(description="[Hz] in simulated time")
    period: float = Field(description="[s]")
    calls: int
    statuses: dict[str, int] = Field(description="calls by status (replanned, "
                                                 "not_converged, unexplained, kept, refused)")
    wall_time_median: float | None = Field(default=None, description="[s]")
    wall_time_max: float | None = Field(default=None, description="[s]")
    wall_time_p99: float | None = Field(default=None, description="[s]")
    real_time_factor: float | None = Field(default=None,
                                           description="median wall time over the period "
                                                       "(above 1: slower than real time)")
    latency_charged: bool = Field(default=False,
                                  description="each call's wall time passed in simulated "
                                              "time before its answer took over (window)")
    ticks: int | None = Field(default=None, description="calls made")
    overruns: int | None = Field(default=None,
                                 description="control instants skipped while a call was in "
                                             "flight (the last answer kept)")


class ControlEventModel(_Response):
    """One controller call."""

    t: float = Field(description="simulated time [s]")
    status: str
    wall_time: float = Field(description="[s]")
    message: str = ""
    iterations: int | None = None
    solve_time: float | None = None
    estimate_time: float | None = None
    fingertip_shift: list[float] | None = None
    object_shift: float | None = None
    object_turn: float | None = None
    primal_infeasibility: float | None = Field(
        default=None, description="the window's KKT residuals after its iterations")
    dual_infeasibility: float | None = None
    latency_charged: float | None = Field(default=None, description="[s] (window)")


class WindowCertificatesModel(_Response):
    """Every window of the window controller checked by the plan's certificate after the
    run."""

    windows: int
    checked: int
    certified: int
    failed: list[dict[str, Any]] = Field(description="each failed window: its tick time "
                                                     "`t` and the `checks` that failed")


class ClosedLoopBlock(_Response):
    """The closed loop's own figures (its report is the top level's)."""

    summary: LoopSummaryModel
    control: ControlTimingModel
    events: list[ControlEventModel]
    setup_time: float = Field(description="building the re-planner's NLPs before the run, "
                                          "and the first plan re-solved warm [s]")
    final_pose: list[float] = Field(description="the object's final position and wxyz")
    certificates: WindowCertificatesModel | None = Field(
        default=None, description="the window controller's windows, certified")


class OpenLoopBlock(_Response):
    """The open-loop run in the same disturbed world."""

    summary: LoopSummaryModel
    report: SimulationReport


class SimulationReport(_Response):
    """How closely a plan's object followed the plan when a hand executed it in MuJoCo."""

    job_id: str | None = Field(default=None, description="the plan's job")
    passed: bool = Field(description="within the tolerances, no contact lost")
    failures: list[str] = Field(description="what failed, with values")
    mode: str
    position_error: ErrorSummaryModel = Field(description="|p - p_plan| [m]")
    angle_error: ErrorSummaryModel = Field(description="angle of R_plan^T R [rad]")
    contacts: list[ContactExecutionModel]
    tolerances: dict[str, float]
    options: dict[str, Any] = Field(description="every simulator option of the run")
    duration: float = Field(description="the plan's horizon [s]")
    steps: int = Field(description="physics steps, settling included")
    wall_time: float = Field(description="the run's wall time [s]")
    mujoco_version: str
    notes: list[str] = Field(default_factory=list,
                             description="where the models, mass, friction and grip came "
                                         "from")
    series: SimulationSeriesModel | None = None
    model: dict[str, Any] | None = Field(
        default=None, description="executed on the request's own hand model: every setting "
                                  "of the scene and the drive, the fingertip contacts' "
                                  "settings against the file's, each joint's feed-forward "
                                  "torque against its actuator's range (null: dexroll's "
                                  "scene)")
    disturbances: dict[str, Any] | None = Field(
        default=None, description="the disturbances of the run, as applied (null: none)")
    open_loop: OpenLoopBlock | None = Field(
        default=None, description="with `closed_loop`: the open-loop run in the same world")
    closed_loop: ClosedLoopBlock | None = Field(
        default=None, description="with `closed_loop`: the controller's summary, calls and "
                                  "timing (this report is the closed loop's run)")


OpenLoopBlock.model_rebuild()
