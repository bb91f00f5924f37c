"""Finger gaiting on the wire (docs/gait.md): the request's ``gait`` option and the
result's ``gait`` block."""

from __future__ import annotations

import math
from typing import Literal

from pydantic import Field, ValidationInfo, field_validator

from dexroll_client.common import Real, _Request, _Response
from dexroll_client.manipulation_trajectory import ManipulationTrajectoryModel

__all__ = [
    "GaitClockModel",
    "GaitContactModel",
    "GaitFingerModel",
    "GaitHoldModel",
    "GaitModel",
    "GaitPhaseModel",
    "GaitResultModel",
    "GaitRollModel",
    "GaitSamplesModel",
    "GaitSwingModel",
    "GaitTipModel",
    "GaitTrajectoryModel",
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


class GaitClockModel(_Response):
    """How a roll's own plan is run on the gait's clock. With ``tau`` the time [s] from the
    roll's phase start, ``d`` the ramp, ``D = duration / speed`` and ``L = D + d`` the
    phase's length: the plan's time is ``s = speed * u(tau)``, where ``u`` is
    ``d (x^3 - x^4 / 2)`` with ``x = tau / d`` on the first ramp (tau < d),
    ``tau - d / 2`` between the ramps, and ``D - d (y^3 - y^4 / 2)`` with
    ``y = (L - tau) / d`` on the last (tau > L - d); ``u = min(tau, D)`` when ``d`` is 0.
    The plan's joints q(s) are run as q(s(tau)): rates q'(s) s', accelerations
    q''(s) s'^2 + q'(s) s''."""

    duration: float = Field(description="the roll's own plan's duration [s]")
    ramp: float = Field(description="the ramps' length d [s]")
    speed: float = Field(description="the plan's rate between the ramps (1: as planned)")


class GaitRollModel(_Response):
    """One roll of a gait as it was certified: its own plan at its collocation points,
    and the clock it is run on."""

    phase: int = Field(description="its phase's index in `phases`")
    start: float = Field(description="its phase's start [s] on the gait's clock")
    clock: GaitClockModel
    fingers: list[str] = Field(description="the fingers its plan is of (every one but the "
                                           "fingertip re-placed meanwhile, with overlap)")
    trajectory: ManipulationTrajectoryModel = Field(
        description="the roll's plan at its collocation points (nodes at the even rows, "
                    "interval midpoints at the odd ones), its times `t` on the plan's own "
                    "clock from 0, the palm frame (the contacts' `eta` on the roll's own "
                    "charts). Between two nodes each joint is the cubic Hermite polynomial "
                    "through its angles and rates (`q`, `q_dot`) at the two nodes")


class GaitSwingModel(_Response):
    """One fingertip's swing as it was certified: on each interval of its grid, from a node
    of time ``t_k``, ``q(t) = q_k + q_dot_k h + q_ddot_k h^2 / 2 + jerk_k h^3 / 6`` with
    ``h = t - t_k`` (rates and accelerations its derivatives)."""

    phase: int = Field(description="the index in `phases` of the phase it is made in: a "
                                   "`swing`, or the `roll` during which it is made")
    finger: str
    start: float = Field(description="its start [s] on the gait's clock (its phase's)")
    t: list[float] = Field(description="its grid's nodes [s from its start]")
    q: Rows = Field(description="the finger's joints at the nodes [rad]")
    q_dot: Rows = Field(description="their rates at the nodes [rad/s]")
    q_ddot: Rows = Field(description="their accelerations at the nodes [rad/s^2]")
    jerk: Rows = Field(description="their jerk on each interval [rad/s^3] (one row fewer)")


class GaitHoldModel(_Response):
    """A phase with the ball still (an `unload`, `swing` or `load`): the joints held and
    the forces on the ramp (in a swing, constant)."""

    phase: int = Field(description="its index in `phases`")
    q: list[float] = Field(description="every joint (the joint trajectory's order), still "
                                       "[rad]; in a swing, the swinging finger's at its "
                                       "start (its motion is its `swings` entry's)")
    forces_start: Rows = Field(description="every fingertip's force on the ball at the "
                                           "phase's start [N], palm frame")
    forces_end: Rows = Field(description="... at its end [N]")
    profile: Literal["linear", "smoothstep"] = Field(
        description="how the forces move from start to end over the phase's fraction x: "
                    "x (linear) or 3 x^2 - 2 x^3 (smoothstep)")


class GaitTrajectoryModel(_Response):
    """The gait as it was certified, piece by piece: every roll's own plan and clock,
    every swing's polynomials, every hold's joints and force ramp. The joint trajectory's
    samples are these pieces at its times (:meth:`GaitResultModel.joints_at` evaluates
    them at any time)."""

    rolls: list[GaitRollModel]
    swings: list[GaitSwingModel]
    holds: list[GaitHoldModel]


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
    trajectory: GaitTrajectoryModel | None = Field(
        default=None, description="the pieces the gait is made of, as they were "
                                  "certified (exact at any time, not only at the samples')")

    def joints_at(self, t: float) -> tuple[list[float], list[float], list[float]]:
        """Every joint's angle, rate and acceleration (the joint trajectory's order) at
        the time ``t`` [s] of the gait, from :attr:`trajectory`'s pieces (a time at a
        switch belongs to the phase that ends there)."""
        if self.trajectory is None or not self.phases:
            raise ValueError("this gait carries no trajectory")
        i = next((j for j, p in enumerate(self.phases) if t <= p.end), len(self.phases) - 1)
        ph = self.phases[i]
        swing = next((s for s in self.trajectory.swings if s.phase == i), None)
        roll = next((r for r in self.trajectory.rolls if r.phase == i), None)
        if roll is not None:
            s, ds, dds = _clock(roll.clock, t - roll.start)
            per: dict[str, tuple[list[float], list[float], list[float]]] = {}
            for rf in roll.trajectory.fingers:
                q, v, a = _hermite(roll.trajectory.t, rf.q, rf.q_dot, s)
                per[rf.name] = (q, [x * ds for x in v],
                               [y * ds * ds + x * dds for x, y in zip(v, a, strict=True)])
            if swing is not None:
                per[swing.finger] = _swing(swing, t - swing.start)
            out: tuple[list[float], list[float], list[float]] = ([], [], [])
            assert self.samples is not None  # (the fingers' order)
            for f in self.samples.fingers:
                for part, got in zip(out, per[f.name], strict=True):
                    part.extend(got)
            return out
        hold = next(h for h in self.trajectory.holds if h.phase == i)
        q, v, a = list(hold.q), [0.0] * len(hold.q), [0.0] * len(hold.q)
        if ph.kind == "swing" and swing is not None:
            assert self.samples is not None
            at = 0
            for f in self.samples.fingers:
                if f.name == swing.finger:
                    qs, vs, as_ = _swing(swing, t - swing.start)
                    n = len(qs)
                    q[at:at + n], v[at:at + n], a[at:at + n] = qs, vs, as_
                at += len(f.joint_names)
        return q, v, a


def _clock(c: GaitClockModel, tau: float) -> tuple[float, float, float]:
    """(s, ds/dtau, d2s/dtau2) of a roll's clock (:class:`GaitClockModel`)."""
    d, D = c.ramp, c.duration / c.speed
    L = D + d
    t = min(max(tau, 0.0), L)
    if d <= 0.0:
        return c.speed * min(t, D), c.speed, 0.0
    if t < d:
        x = t / d
        u, du, ddu = d * (x**3 - x**4 / 2), 3 * x**2 - 2 * x**3, (6 * x - 6 * x**2) / d
    elif t > L - d:
        y = (L - t) / d
        u, du, ddu = D - d * (y**3 - y**4 / 2), 3 * y**2 - 2 * y**3, -(6 * y - 6 * y**2) / d
    else:
        u, du, ddu = t - d / 2, 1.0, 0.0
    return c.speed * u, c.speed * du, c.speed * ddu


def _hermite(ts: list[float], q: Rows, qd: Rows, s: float
             ) -> tuple[list[float], list[float], list[float]]:
    """The cubic Hermite polynomial through the nodes (the even rows) around ``s``: its
    value and first two derivatives, per column."""
    nodes = range(0, len(ts), 2)
    k = max((j for j in nodes if ts[j] <= s and j + 2 < len(ts)), default=0)
    t0, t1 = ts[k], ts[k + 2]
    h = t1 - t0
    x = min(max((s - t0) / h, 0.0), 1.0)
    h00, h10, h01, h11 = 2 * x**3 - 3 * x**2 + 1, x**3 - 2 * x**2 + x, -2 * x**3 + 3 * x**2, \
        x**3 - x**2
    d00, d10, d01, d11 = 6 * x**2 - 6 * x, 3 * x**2 - 4 * x + 1, -6 * x**2 + 6 * x, \
        3 * x**2 - 2 * x
    e00, e10, e01, e11 = 12 * x - 6, 6 * x - 4, -12 * x + 6, 6 * x - 2
    out: tuple[list[float], list[float], list[float]] = ([], [], [])
    for j in range(len(q[k])):
        p0, p1, m0, m1 = q[k][j], q[k + 2][j], qd[k][j] * h, qd[k + 2][j] * h
        out[0].append(h00 * p0 + h10 * m0 + h01 * p1 + h11 * m1)
        out[1].append((d00 * p0 + d10 * m0 + d01 * p1 + d11 * m1) / h)
        out[2].append((e00 * p0 + e10 * m0 + e01 * p1 + e11 * m1) / h**2)
    return out


def _swing(sw: GaitSwingModel, tau: float) -> tuple[list[float], list[float], list[float]]:
    """A swing's joints at ``tau`` [s from its start] (:class:`GaitSwingModel`)."""
    n = len(sw.t) - 1
    tt = min(max(tau, 0.0), sw.t[-1])
    k = min(int(tt / (sw.t[-1] / n)), n - 1)
    h = tt - sw.t[k]
    q, v, a, j = sw.q[k], sw.q_dot[k], sw.q_ddot[k], sw.jerk[k]
    return ([q[i] + v[i] * h + a[i] * h * h / 2 + j[i] * h**3 / 6 for i in range(len(q))],
            [v[i] + a[i] * h + j[i] * h * h / 2 for i in range(len(q))],
            [a[i] + j[i] * h for i in range(len(q))])
