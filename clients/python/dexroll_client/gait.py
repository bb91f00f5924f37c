"""Finger gaiting on the wire (docs/gait.md): the request's ``gait`` option and the
result's ``gait`` block."""

from __future__ import annotations

import math
from typing import Literal

from pydantic import Field, ValidationInfo, field_validator

from dexroll_client.common import Real, _Request, _Response

__all__ = [
    "GaitContactModel",
    "GaitFingerModel",
    "GaitModel",
    "GaitPhaseModel",
    "GaitResultModel",
    "GaitSamplesModel",
    "GaitTipModel",
]


class GaitModel(_Request):
    """Turn the ball farther than rolling can, by rolling and re-placing fingertips: the
    motion's one rotation step (its axis and angle) is made by rolls of at most
    ``roll_step``, each followed by the re-placement of every fingertip the others can
    hold the ball without (unload, swing clear, land, load). Needs ``forces`` (the holds
    carry the ball's weight), a ball, round fingertips and no palm."""

    roll_step: Real = Field(default=math.radians(10.0), gt=0.0, le=math.pi / 2,
                            description="the largest turn of one roll [rad]")
    swing_duration: Real = Field(default=0.8, ge=0.1, le=10.0,
                                 description="a fingertip's swing from lift-off to "
                                             "touch-down [s]")
    fastest_swings: bool = Field(
        default=False,
        description="swing_duration an upper bound: each swing found is timed as fast as "
                    "the joints' velocity limits, an acceleration of 20 rad/s^2 and the "
                    "actuators' damping allow (its path unchanged), at least 0.15 s")
    fastest_rolls: bool = Field(
        default=False,
        description="each roll's duration (from the motion's rate) an upper bound: its path "
                    "is run as fast as the joints' velocity limits, an acceleration of 20 "
                    "rad/s^2 and the share of the actuators' torque its forces leave to "
                    "the joints' damping allow (the same path: no slip, the same forces), "
                    "at least 0.3 s between its ramps; its torques, damping included, "
                    "certified on its clock")
    hold_time: Real = Field(default=0.2, ge=0.01, le=5.0,
                            description="the unloading before a lift-off and the loading "
                                        "after a touch-down, each [s]")
    replace: Literal["all", "spent"] = Field(
        default="all",
        description="which fingertips are re-placed after a roll: 'all': every one the "
                    "others can hold the ball without, where it touched when that roll "
                    "began; 'spent': only those whose rolled reach is spent for the next "
                    "two rolls' worth (or that the next roll brings within 0.5 mm of "
                    "another), each where it touched when the gait began (all of them "
                    "there when one cannot be lifted or finds no swing): fewer "
                    "re-placements, a shorter motion (docs/gait.md)")
    landing: Literal["home", "farthest"] = Field(
        default="home",
        description="where a spent fingertip lands (with replace 'spent'): 'home', where "
                    "it touched when the gait began; 'farthest', of that contact, the "
                    "contacts it would have rolled back to (the ball turned back by 1/4, "
                    "1/2, 3/4 and all of roll_step) and contacts drawn over its joints "
                    "(within 45 deg of home's normal, 3 mm from the other fingertips, "
                    "reached by a swing), the one from which it rolls forward the "
                    "farthest: fewer, longer rolls (docs/gait.md)")

    overlap: bool = Field(
        default=False,
        description="(with replace 'spent') each spent fingertip re-placed while the "
                    "others roll the ball by the next step: it is unloaded, swings clear "
                    "and lands during that roll (the others' bodies and the hand's links "
                    "moving obstacles of its swing), and is loaded when the ball stops; "
                    "one per roll, the least-reaching first, at rest as without where no "
                    "such swing is found (docs/gait.md)")

    @field_validator("overlap")
    @classmethod
    def _overlap_needs_spent(cls, value: bool, info: ValidationInfo) -> bool:
        if value and info.data.get("replace") != "spent":
            raise ValueError("overlap re-places the spent fingertips during the rolls: it "
                             "needs replace 'spent'")
        return value

    @field_validator("landing")
    @classmethod
    def _landing_needs_spent(cls, value: str, info: ValidationInfo) -> str:
        if value != "home" and info.data.get("replace") != "spent":
            raise ValueError("landing 'farthest' chooses where a spent fingertip lands: it "
                             "needs replace 'spent' (replace 'all' resets every fingertip "
                             "where it touched when its roll began)")
        return value

    clearance: Real = Field(default=0.003, ge=0.0, le=0.05,
                            description="the least distance [m] between a swinging "
                                        "fingertip's surface and the ball's, and (or the "
                                        "gaps it starts and lands with, if smaller) the "
                                        "other fingertips' (1 mm from them when keeping "
                                        "the clearance leaves the swing no path)")


class GaitPhaseModel(_Response):
    """One phase of a gait."""

    kind: Literal["roll", "unload", "swing", "load"] = Field(
        description="roll: every fingertip rolls the ball (with overlap, all but "
                    "lifted_finger, which swings meanwhile); unload: the forces move off the "
                    "fingertip about to lift (and onto the one re-placed before, when it "
                    "follows a roll with a swing); swing: it moves clear and lands; load: "
                    "back")
    start: float = Field(description="[s] from the plan's start")
    end: float = Field(description="[s]")
    touching: list[bool] = Field(description="per finger (the request's order), whether "
                                             "its tip touches the ball")
    lifted_finger: str | None = Field(default=None, description="the finger re-placed "
                                                                "(in a roll: the one that "
                                                                "swings while the others "
                                                                "roll, with overlap; else "
                                                                "null)")


Rows = list[list[float]]


class GaitContactModel(_Response):
    """A fingertip's contact over the gait (rows: the samples' times)."""

    name: str
    active: list[float] = Field(description="1 touching, 0 lifted clear of the ball, between: "
                                            "its force ramping, or lifting off and landing")
    touching: list[bool] | None = Field(
        default=None, description="whether the fingertip touches the ball at each sample "
                                  "(false while a swing carries it; a switch's time belongs "
                                  "to the phase it starts)")
    point: Rows = Field(description="where the line of centres meets the ball [m], palm "
                                    "frame (the contact while it touches)")
    normal: Rows = Field(description="the ball's outward normal there")
    force: Rows = Field(description="the planned force the fingertip applies to the ball "
                                    "[N], palm frame (zero while lifted)")
    point_velocity: Rows | None = Field(
        default=None, description="the contact point's velocity [m/s], palm frame (of "
                                  "`point`, from the plan's joint rates and the object's "
                                  "velocities; a switch's time with the phase it starts)")
    velocity_over_object: Rows | None = Field(
        default=None, description="`point_velocity` less the velocity of the object's "
                                  "material point there [m/s], palm frame: the contact's "
                                  "motion over the object's surface (tangent to it while "
                                  "the fingertip touches; zero while the object is at rest "
                                  "and the fingertip on it)")


class GaitTipModel(_Response):
    """A fingertip's body in its tip frame (the frame ``tip_position`` and
    ``tip_orientation_wxyz`` give): the segment from ``a`` (the cap's centre, where
    contacts are) to ``b`` [m] swept by a sphere of ``radius`` [m] (a sphere tip: a = b)."""

    kind: Literal["sphere", "capsule"]
    radius: float
    a: list[float]
    b: list[float]


class GaitFingerModel(_Response):
    """A finger's tip frame over the gait (its joints: the result's joint_trajectory)."""

    name: str
    tip_position: Rows
    tip_orientation_wxyz: Rows
    tip: GaitTipModel | None = Field(default=None, description="the fingertip's body in "
                                                               "that frame")
    joint_names: list[str] = Field(
        default_factory=list,
        description="this finger's columns of the result's joint_trajectory, by name (the "
                    "model's joint names; '<finger>/<joint>' only where two fingers share "
                    "one)")


class GaitSamplesModel(_Response):
    """The gait at the joint trajectory's times: the ball's pose, every fingertip's
    contact and activity, every tip frame's pose (palm frame)."""

    t: list[float]
    object_position: Rows
    object_orientation_wxyz: Rows
    object_velocity: Rows | None = Field(default=None, description="the ball's velocity "
                                                                   "[m/s], palm frame")
    object_angular_velocity: Rows | None = Field(default=None, description=(
        "the ball's angular velocity [rad/s], palm frame (zero in the holds and in swings "
        "at rest; a swing during a roll (`overlap`) turns it)"))
    contacts: list[GaitContactModel]
    fingers: list[GaitFingerModel]


class GaitResultModel(_Response):
    """What a gait did: its phases, the turn made, the rolls and re-placements, and the
    fingers the others could not hold the ball without (they rolled throughout)."""

    phases: list[GaitPhaseModel]
    turned: float = Field(description="the turn made [rad] (the request's when solved)")
    rolls: int
    replacements: int
    never_lifted: list[str] = Field(default_factory=list,
                                    description="fingers that could not be lifted")
    wall_time: float = Field(description="planning the whole gait [s]")
    samples: GaitSamplesModel | None = Field(default=None, description="the gait at the "
                                                                       "joint trajectory's "
                                                                       "times")
