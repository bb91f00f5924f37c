"""The wire contract of a plan's execution in MuJoCo (``POST /v1/plans/{id}/simulation``,
docs/simulation.md): the options of a run and its report.

Import from :mod:`dexroll_client.simulation`.
"""

from __future__ import annotations

import math
from typing import Any, Literal

from pydantic import Field

from dexroll_client.common import OptionalCount, Real, _Request, _Response

__all__ = [
    "ContactExecutionModel",
    "ErrorSummaryModel",
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

    def simulator_options(self) -> dict[str, Any]:
        """The fields set, as the simulator's option names (``sim.SimOptions``)."""
        return self.model_dump(exclude_none=True)


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
