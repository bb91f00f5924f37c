"""The wire contract of a re-plan from a measured state (``POST /v1/plans/{id}/replan``,
docs/replanning.md "Through the service"): what a controller measured, and the corrected
rest of the motion.

A controller executing a finished job's plan sends, every control period, the time since
the plan's start and what it measures (each finger's joint angles and optionally rates;
the object's pose and optionally its twist; optionally each fingertip's measured contact
location); the service answers with the rest of the motion re-planned from that state:
every finger's joints as ROS 2's ``JointTrajectory`` and the plan's samples (object pose,
contacts, joints) from the measured instant on, with the re-plan's statistics. A state
the grasp cannot explain (a contact lost, the object dropped) is a 422 naming the field.

Import from :mod:`dexroll_client.replan`.
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field

from dexroll_client.common import (
    MAX_DURATION,
    MAX_FINGER_JOINTS,
    MAX_FINGERS,
    MAX_POSITION,
    MAX_SAMPLE_RATE,
    Count,
    Real,
    _Request,
    _Response,
)
from dexroll_client.results import JointTrajectoryModel, PlanSamplesModel

__all__ = ["ReplanEstimateModel", "ReplanRequest", "ReplanResult", "ReplanStatsModel"]

_Coordinate = Annotated[Real, Field(ge=-MAX_POSITION, le=MAX_POSITION)]
_Vector3 = Annotated[list[_Coordinate], Field(min_length=3, max_length=3)]
_Rate = Annotated[Real, Field(ge=-1e3, le=1e3)]
_Joints = Annotated[list[Annotated[Real, Field(ge=-100.0, le=100.0)]],
                    Field(min_length=1, max_length=MAX_FINGER_JOINTS)]
_JointRates = Annotated[list[_Rate], Field(min_length=1, max_length=MAX_FINGER_JOINTS)]


class ReplanRequest(_Request):
    """What a controller measured at time ``t`` of the plan's clock, and the re-plan's
    budget. Palm frame, SI units; fingers in the plan's order (its ``fingers``)."""

    t: Real = Field(ge=0.0, le=MAX_DURATION,
                    description="time since the plan's start [s] (the first plan's clock; "
                                "at most its duration)")
    q: Annotated[list[_Joints], Field(min_length=1, max_length=MAX_FINGERS)] = Field(
        description="each finger's measured joint angles [rad; m for a prismatic joint], "
                    "in the plan's finger and joint order")
    q_dot: Annotated[list[_JointRates], Field(min_length=1, max_length=MAX_FINGERS)] | None \
        = Field(default=None, description="each finger's measured joint rates (null: the "
                                          "plan's rates at t, made consistent)")
    object_position: _Vector3 = Field(description="the object's measured centre [m]")
    object_wxyz: Annotated[list[Annotated[Real, Field(ge=-2.0, le=2.0)]],
                           Field(min_length=4, max_length=4)] = Field(
        description="the object's measured orientation, quaternion (w, x, y, z) (normalised "
                    "here; not zero)")
    object_velocity: _Vector3 | None = Field(
        default=None, description="the object's measured velocity [m/s] (with "
                                  "`object_omega`; null: not measured)")
    object_omega: _Vector3 | None = Field(
        default=None, description="the object's measured angular velocity [rad/s], palm "
                                  "frame (with `object_velocity`)")
    contact_points: Annotated[list[_Vector3 | None],
                              Field(min_length=1, max_length=MAX_FINGERS)] | None = Field(
        default=None, description="each fingertip's measured contact location [m] (a "
                                  "tactile sensor's; null for a finger not measured): the "
                                  "estimate fits them, and one more than 3 mm from any "
                                  "contact the grasp explains is refused")
    max_iter: Count = Field(default=30, ge=1, le=500,
                            description="IPOPT iterations of the re-plan (its budget: the "
                                        "outcome is then the same on a loaded machine)")
    time_limit: Real = Field(default=10.0, gt=0.0, le=60.0,
                             description="wall-clock limit of the re-plan's IPOPT call [s] "
                                         "(a safety: the budget is `max_iter`; capped by "
                                         "the service's DEXROLL_REPLAN_TIME_LIMIT)")
    certify: bool = Field(default=False,
                          description="check the re-plan's certificate (tens of ms more): "
                                      "`stats.certified` then says whether it passed")
    sample_rate: Real | None = Field(
        default=None, gt=0.0, le=MAX_SAMPLE_RATE,
        description="the returned trajectory's rate [Hz] (null: the plan's collocation "
                    "points)")
    restart: bool = Field(default=False,
                          description="forget this plan's previous re-plans and warm-start "
                                      "from the first plan (also done for a `t` before the "
                                      "last re-plan's)")


class ReplanStatsModel(_Response):
    """What the re-plan took."""

    iterations: int = Field(description="IPOPT iterations")
    wall_time: float = Field(description="the re-plan in the service's re-plan process: "
                                         "estimate and IPOPT [s]")
    solve_time: float = Field(description="IPOPT's call alone [s]")
    estimate_time: float = Field(description="the state estimate alone [s]")
    setup_time: float = Field(description="building this plan's re-planner on this call "
                                          "(its first: the problem, its NLP, the first plan "
                                          "re-solved warm from the stored one) [s]; 0 when "
                                          "it was kept from an earlier call")
    converged: bool | None = Field(default=None,
                                   description="IPOPT converged within the budget (null: "
                                               "nothing solved: `kept`)")
    certified: bool | None = Field(default=None,
                                   description="the re-plan's certificate passed (null: not "
                                               "checked, `certify` false)")
    raw_status: str | None = Field(default=None, description="IPOPT's own word")


class ReplanEstimateModel(_Response):
    """The grasp's state nearest to the measurement (docs/replanning.md "From a measured
    state"), which the re-plan starts from exactly."""

    q: list[list[float]] = Field(description="each finger's joint angles, on the object")
    object_position: list[float] = Field(description="the object's centre [m]")
    object_wxyz: list[float] = Field(description="its orientation (w, x, y, z)")
    fingertip_shift: list[float] = Field(description="how far each fingertip moved to "
                                                     "touch the object [m]")
    object_shift: float = Field(description="the object's centre against the measured one "
                                            "[m]")
    object_turn: float = Field(description="its orientation against the measured one "
                                           "[rad]")
    contact_shift: list[float | None] | None = Field(
        default=None, description="each measured contact location against the estimated "
                                  "contact point [m] (null: not measured)")


class ReplanResult(_Response):
    """The rest of the motion, re-planned from the measured state at ``t``: ``status``
    ``replanned`` (the trajectory below, times from ``t``: execute it from now on),
    ``not_converged`` (IPOPT did not converge within the budget: no trajectory, keep
    executing the current one) or ``kept`` (less than the shortest horizon left: the
    current plan runs to its end)."""

    job_id: str = Field(description="the plan's job")
    status: Literal["replanned", "not_converged", "kept"]
    message: str = Field(default="", description="why not re-planned")
    t: float = Field(description="the measured time on the plan's clock [s]")
    duration: float | None = Field(default=None,
                                   description="the re-plan's horizon: the rest of the "
                                               "motion [s]")
    joint_trajectory: JointTrajectoryModel | None = Field(
        default=None, description="every finger's joints from `t` on (`time_from_start` "
                                  "from `t`); its first point is the estimated state")
    samples: PlanSamplesModel | None = Field(
        default=None, description="the object's pose, the contacts and the joints at the "
                                  "same times (`t` from the measured instant)")
    estimate: ReplanEstimateModel | None = None
    stats: ReplanStatsModel
