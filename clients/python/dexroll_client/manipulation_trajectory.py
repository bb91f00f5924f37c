"""A manipulation plan at its collocation points (nodes and midpoints): the ``trajectory``
block of a rolling plan's result, and of each roll of a gait's (``gait.trajectory.rolls``).

Import from :mod:`dexroll_client.models` (it re-exports everything).
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from dexroll_client.common import _Response

__all__ = ["ContactTrajectoryModel", "FingerJointsModel", "ManipulationTrajectoryModel"]

Rows = list[list[float]]


class ContactTrajectoryModel(_Response):
    """One contact of a manipulation plan over time; rows are samples. Palm frame, SI
    units."""

    name: str = Field(description="'palm', or the fingertip's name")
    body: Literal["palm", "finger"] = Field(description="the body touching the object")
    eta: Rows = Field(description="contact coordinates: the body's point (x, y) [m] (palm: "
                                  "palm plane; finger: pad frame), the object's point "
                                  "(u, v) [rad] in this contact's chart patch, the contact "
                                  "angle psi [rad]")
    eta_dot: Rows = Field(description="rates of the contact coordinates ([m/s], [rad/s])")
    w: Rows = Field(description="the contact's input: palm d/dt (x, y) [m/s]; fingertip "
                                "d/dt (u, v) [rad/s] (its motion over the object)")
    point: Rows = Field(description="the contact point [m]")
    normal: Rows = Field(description="the object's outward normal at the contact (unit)")
    force_angle: list[float] = Field(
        description="angle between the contact's push (-normal) and the internal force of "
                    "the grasp that certifies force closure [rad] (two contacts: the "
                    "paper's grasp angle)")
    force: Rows | None = Field(
        default=None, description="the planned force the contact's body (palm, fingertip) "
                                  "exerts on the object [N], palm frame; null without "
                                  "`forces` in the request")
    torsion: list[float] | None = Field(
        default=None, description="the planned moment about the object's outward normal "
                                  "[N m] (soft finger); null without `forces`")


class FingerJointsModel(_Response):
    """One finger of a manipulation plan over time; rows are samples."""

    name: str = Field(description="the fingertip's name (as in `contacts`)")
    joint_names: list[str] = Field(description="the finger's joints, in the order of `q`")
    q: Rows = Field(description="joint angles [rad; m for a prismatic joint]")
    q_dot: Rows = Field(description="joint rates [rad/s; m/s for a prismatic joint]")
    tip_position: Rows = Field(description="origin of the fingertip (pad) frame in the palm "
                                           "frame [m]")
    tip_orientation_wxyz: Rows = Field(description="fingertip (pad) frame orientation in "
                                                   "the palm frame, unit quaternion "
                                                   "(w, x, y, z), w >= 0")
    joint_torques: Rows | None = Field(
        default=None, description="joint torques [N m; N for a prismatic joint] that exert "
                                  "the planned contact force and torsion, J^T (f; m) at the "
                                  "contact point, and hold the finger's links against gravity "
                                  "when its model has inertias (the built-in ones have "
                                  "none); null without `forces`")


class ManipulationTrajectoryModel(_Response):
    """A manipulation plan at the collocation points (nodes and midpoints); rows are
    samples. Palm frame, SI units."""

    t: list[float] = Field(description="sample times [s]")
    object_position: Rows = Field(description="object centre [m]")
    object_orientation_wxyz: Rows = Field(description="object orientation, unit quaternion "
                                                      "(w, x, y, z), w >= 0")
    object_velocity: Rows = Field(description="velocity of the object's centre [m/s]")
    object_angular_velocity: Rows = Field(description="the object's angular velocity, palm "
                                                      "frame [rad/s]")
    contacts: list[ContactTrajectoryModel] = Field(description="every contact: the palm's "
                                                               "first (if any), then the "
                                                               "fingertips' in request order")
    fingers: list[FingerJointsModel] = Field(description="every finger, in request order")
    grasp_angle: list[float] = Field(description="the largest force angle over the "
                                                 "contacts [rad]")
    cone_margin: list[float] = Field(description="atan(mu) - grasp_angle: positive inside "
                                                 "every friction cone [rad]")
    desired_position: Rows | None = Field(default=None, description="the desired object "
                                                                    "centre [m] (null "
                                                                    "without `motion`)")
    desired_orientation_wxyz: Rows | None = Field(
        default=None, description="the desired object orientation, unit quaternion "
                                  "(w, x, y, z), w >= 0 (null without `motion`)")
    tracking_position_error: list[float] | None = Field(
        default=None, description="|p - p_d| [m] (null without `motion`)")
    tracking_angle_error: list[float] | None = Field(
        default=None, description="angle between the object's orientation and the desired "
                                  "one [rad] (null without `motion`)")
