"""Finger gaiting by rolling and re-placing: turn a ball farther than its grasp can roll
it (docs/gait.md, "The gait").

The strategy, **roll and reset**: roll the ball by a step about the requested axis (the
rolling planner, every fingertip touching: :class:`~ocp.solve.planner.
ManipulationPlanner`), then re-place each fingertip that the others can hold without at
the contact it had when the step began, relative to the palm (a ball turned about its
centre fills the same space, so the joints it had then touch it again: the grasp, and its
rolled reach, recur), and roll again, until the turn is made. A fingertip the others cannot
hold the ball without (the built-in hand's thumb, the only one opposing the three fingers)
keeps rolling: it bounds the turn.

The plan is phases stitched at rest (docs/gait.md says why): rolls (smooth timing: start
and end at rest), and per re-placed fingertip unload, swing, load (:mod:`ocp.gait.step`).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ocp.certify.certificate import Certificate, Check, CheckKind
from ocp.gait.overlap import (
    OVERLAP_HOLD_DEPTH,
    at_landing,
    hold_depth,
    lift_next,
    plan_overlap,
    stranded_fingers,
    without,
)
from ocp.gait.step import (
    HOLD_TORQUE_SHARE,
    GaitStep,
    TorqueLimits,
    grasp_hold,
    hold_torque_refusal,
    liftable,
    replace_finger,
)
from ocp.gait.warp import RollClock, fastest_speed
from ocp.geometry.bodies import segments_distance, tip_body
from ocp.geometry.rotations import axis_angle_rotation, log_rotation, quaternion_wxyz
from ocp.shapes.held import Held, held_object
from ocp.solution import ManipulationSolution
from ocp.spec.grasp import ManipulationProblem, fingertips_on_charts
from ocp.spec.motion import DesiredMotion, ObjectPose
from ocp.spec.problem import ObjectSpec, ProblemError
from ocp.transcription.values import load_parameters

__all__ = ["GaitPhase", "GaitPlan", "plan_gait"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class GaitPhase:
    """One phase of a gait: ``kind`` (roll, unload, swing, load), its times [s], which
    fingertips touch the object, the lifted finger's index (None in a roll)."""

    kind: str
    start: float
    end: float
    touching: tuple[bool, ...]
    lifted: int | None = None
    index: int = 0  # the roll's or the step's index in the plan's lists


@dataclass
class GaitPlan:
    """A gait: its phases, the rolls' plans and the gait steps, the certificate of every
    phase and switch, the status (``"solved"``, ``"infeasible"``, ``"failed"``) and why
    not, the turn made [rad], the planning's wall time [s]."""

    status: str
    message: str
    phases: list[GaitPhase] = field(default_factory=list)
    rolls: list[ManipulationSolution] = field(default_factory=list)
    steps: list[GaitStep] = field(default_factory=list)
    certificate: Certificate = field(default_factory=lambda: Certificate(()))
    turned: float = 0.0
    wall_time: float = 0.0
    nq: tuple[int, ...] = ()
    #: the fingers the others cannot hold the ball without: they roll throughout
    never_lifted: tuple[str, ...] = ()
    #: each roll's clock (:mod:`ocp.gait.warp`): its plan run so that it starts and ends
    #: still (the joints' accelerations continuous with the holds')
    clocks: list[RollClock] = field(default_factory=list)
    #: each roll's ball orientation at its start (palm frame): a roll is planned in the
    #: ball's frame there (:func:`_roll_problem`), its rotations R(t) are relative to it
    frames: list[FloatArray] = field(default_factory=list)
    #: the rolls made while a fingertip is re-placed (:mod:`ocp.gait.overlap`): roll index
    #: -> the gait step whose swing it carries (that roll's plan is of the others)
    carried: dict[int, int] = field(default_factory=dict)
    #: why a re-placement during a roll was not made (then made at rest), in order
    overlap_misses: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return self.status == "solved" and self.certificate.passed

    @property
    def duration(self) -> float:
        return self.phases[-1].end if self.phases else 0.0

    @property
    def replacements(self) -> int:
        """The re-placements made: the steps but a failed gait's last, which is kept with
        the swing it did not find (its message) and has no phase."""
        return sum(1 for st in self.steps if st.ok)

    def joints(self, t: float) -> tuple[FloatArray, FloatArray, FloatArray]:
        """(q, q_dot, q_ddot) of every finger's joints (concatenated) at time ``t``: the
        phase's own motion (a roll's returned polynomials, a swing's cubics; still in
        unload and load)."""
        ph = next((p for p in self.phases if t <= p.end), self.phases[-1])
        if ph.kind == "roll":
            q, v, a = self.roll_joints(ph.index, np.array([t - ph.start]))
            return q[0], v[0], a[0]
        step = self.steps[ph.index]
        q = self.still_joints(ph)
        zero = np.zeros_like(q)
        if ph.kind == "swing" and step.swing is not None:
            qk, vk, ak = step.swing.sample(t - ph.start)
            cut = np.cumsum((0, *self.nq))
            k = step.finger
            q, v, a = q.copy(), zero.copy(), zero.copy()
            q[cut[k]:cut[k + 1]], v[cut[k]:cut[k + 1]], a[cut[k]:cut[k + 1]] = qk[0], vk[0], ak[0]
            return q, v, a
        return q, zero, zero

    def still_joints(self, ph: GaitPhase) -> FloatArray:
        """Every finger's joints (concatenated) held in a phase with the ball still (an
        unload, a swing or a load): its step's after a load, else before it (in a swing,
        the swinging finger's where it starts)."""
        if ph.kind == "load":
            return np.concatenate(self.steps[ph.index].q_after)
        return self._before(ph.index)

    def rotation(self, r: int, R: FloatArray) -> FloatArray:
        """Roll ``r``'s ball rotations ``R`` (its plan's: from its start) in the palm
        frame."""
        return np.asarray(R, dtype=float) @ self.frames[r]

    def clock(self, r: int) -> RollClock:
        """Roll ``r``'s clock (its own, unwarped, for a plan made without)."""
        if r < len(self.clocks):
            return self.clocks[r]
        return RollClock(self.rolls[r].duration, 0.0)

    def roll_joints(self, r: int, tau: FloatArray
                    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """(q, q_dot, q_ddot) rows of every finger's joints at the times ``tau`` from roll
        ``r``'s start on the gait's clock (its plan's polynomials at the warped times)."""
        clock = self.clock(r)
        s, v, a = clock(tau)
        jt = self.rolls[r].joint_trajectory(s, efforts=False)
        out = clock.joints(jt.positions, jt.velocities, jt.accelerations, v, a)
        if r not in self.carried:
            return out
        # the others roll; the re-placed fingertip swings meanwhile (its own clock: the
        # swing starts and ends with the roll's)
        step = self.steps[self.carried[r]]
        assert step.swing is not None
        at = int(np.cumsum((0, *self.nq))[step.finger])
        swung = step.swing.sample(np.asarray(tau, dtype=float))
        return tuple(np.concatenate([x[:, :at], y, x[:, at:]], axis=1)  # type: ignore
                     for x, y in zip(out, swung, strict=True))

    def fingers_of(self, r: int) -> list[int]:
        """The fingers (indices) roll ``r``'s plan is of: every one, but the one re-placed
        during it (:attr:`carried`)."""
        every = list(range(len(self.nq)))
        if r not in self.carried:
            return every
        return [i for i in every if i != self.steps[self.carried[r]].finger]

    def _before(self, i: int) -> FloatArray:
        """Every finger's joints before gait step ``i`` (concatenated): those after it,
        but the re-placed finger's where its swing began (or the step's own
        ``q_before``: the others rolled meanwhile)."""
        step = self.steps[i]
        assert step.swing is not None
        if step.q_before is not None:
            return np.concatenate(step.q_before)
        return np.concatenate([step.swing.spec.q_start if k == step.finger else q
                               for k, q in enumerate(step.q_after)])


def is_ball(template: ManipulationProblem) -> bool:
    """Whether the gait's object is a ball (:meth:`ocp.shapes.Shape.ball_radius`)."""
    return template.object.kind.ball_radius(template.object.dimensions) is not None


#: How far [rad] an object may be tilted from a symmetry of the gait's first orientation
#: for its roll to be planned as a recurrence of the last (:func:`plan_start`).
RECUR_TILT = 0.05


def plan_start(template: ManipulationProblem, pose: ObjectPose) -> FloatArray | None:
    """The orientation a roll from ``pose`` starts at in its plan (:func:`_roll_problem`):
    a ball's the identity (any frame fixed in a uniform ball describes it). Another
    object's, when ``pose`` is the gait's first orientation turned by a symmetry S of its
    shape and tilted by less than :data:`RECUR_TILT` (an upright capsule or egg turned
    about its axis, a rounded cube by quarter turns): ``pose.rotation S^T``, the same
    solid at nearly the first orientation, so that the last roll's point starts a roll
    that nearly recurs. None otherwise (planned from ``pose`` itself, in the palm frame;
    the first roll too)."""
    if is_ball(template):
        return np.eye(3)
    F = (template.initial_pose or ObjectPose()).rotation.T @ pose.rotation
    if np.allclose(F, np.eye(3), rtol=0.0, atol=1e-12):  # (the first orientation itself)
        return None
    obj = template.object
    S = obj.surface.symmetry_near(F, obj.params)
    if S is None or float(np.linalg.norm(log_rotation(F @ S.T))) > RECUR_TILT:
        return None
    return np.asarray(pose.rotation @ S.T)


def roll_frame(template: ManipulationProblem, pose: ObjectPose) -> FloatArray:
    """The frame a roll from ``pose`` is planned in (:func:`_roll_problem`): its plan's
    rotations R(t) are R(t) times this one in the palm frame: a ball's orientation at the
    roll's start; the symmetry S of :func:`plan_start`; the identity for any other
    object."""
    start = plan_start(template, pose)
    if start is None:
        return np.eye(3)
    if is_ball(template):
        return pose.rotation
    return start.T @ pose.rotation


def held_at(template: ManipulationProblem, pose: ObjectPose) -> Held:
    """The gait's object at ``pose`` (:func:`~ocp.shapes.held.held_object`)."""
    return held_object(template.object, pose.position, pose.rotation)


def landing_on(template: ManipulationProblem, pose: ObjectPose, finger: Any,
               q: FloatArray) -> FloatArray:
    """Joints near ``q`` (within the limits and couplings) that put ``finger``'s round tip
    on the object at ``pose`` (:func:`~ocp.robots.first_grasp.onto_surface`: along the
    nearest point's normal), or ``q`` when none is found: where a fingertip of an object
    that is not a ball lands (the turned object no longer fills the space it did, so the
    joints it touched with do not touch it again)."""
    from ocp.robots.first_grasp import ObjectGeometry, onto_surface

    geo = ObjectGeometry.of(template.object, pose.rotation, template.pole_margin)
    got = onto_surface(finger, q, np.asarray(pose.position, dtype=float), geo)
    return q if got is None else np.asarray(got[0], dtype=float)


def _roll_problem(template: ManipulationProblem, qs: tuple[FloatArray, ...],
                  pose: ObjectPose, target: FloatArray, centre: FloatArray,
                  duration: float) -> ManipulationProblem:
    """A roll of the ball from ``pose`` to the orientation ``target`` (palm frame) and the
    centre ``centre``, the fingers starting at the joints ``qs``, planned in the ball's
    frame at the roll's start (its rotation the identity there, the goal ``target
    pose.rotation^T``): a uniform ball's motion does not depend on the frame fixed in it,
    and so a gait whose grasp recurs asks the same roll again, which the last roll's
    primal-dual point starts (:func:`plan_gait`). The plan's rotations R(t) are the
    ball's from the start: R(t) ``pose.rotation`` in the palm frame. An object that is
    not a ball is planned in the palm frame, from ``pose`` itself (its form turns with
    it): its R(t) are the palm frame's (:func:`roll_frame`)."""
    fingers = tuple(f.finger for f in template.fingers)
    names = tuple(f.name or f"finger{i}" for i, f in enumerate(template.fingers))
    ball = is_ball(template)
    # (an object that is not a ball is planned where it is, its frame its own, unless its
    # shape maps onto the gait's first: :func:`plan_start`)
    R_start = plan_start(template, pose)
    start = ObjectPose((1.0, 0.0, 0.0, 0.0), pose.position) if ball else pose \
        if R_start is None else ObjectPose(tuple(quaternion_wxyz(R_start)), pose.position)
    obj, tips = fingertips_on_charts(
        fingers, qs, replace(template.object, side_chart=False), start, names,
        tuple(f"{n}'s joints at the roll's start" for n in names), template.pole_margin,
        advise=False)
    goal = np.asarray(target, dtype=float)
    q1 = np.ravel(quaternion_wxyz(goal @ pose.rotation.T if ball else goal
                                  if R_start is None else goal @ pose.rotation.T @ R_start))
    w0, x0, y0, z0 = start.orientation
    if not ball and float(np.dot(q1, start.orientation)) < 0.0:  # the short way
        q1 = -q1
    motion = DesiredMotion((0.0, duration),
                           ((float(w0), float(x0), float(y0), float(z0)),
                            (float(q1[0]), float(q1[1]), float(q1[2]), float(q1[3]))),
                           (pose.position, (float(centre[0]), float(centre[1]),
                                            float(centre[2]))))
    return replace(template, object=obj, fingers=tips, initial_pose=start, motion=motion,
                   duration=duration)


#: The least distance [m] a roll is planned to keep between two fingertips' bodies: the
#: turn is cut where the fingers' rolled motion would bring two closer
#: (:func:`_roll_ahead`); a grasp that starts closer keeps 90 % of its gap.
ROLL_TIP_GAP = 5e-4
#: Points of a roll's predicted motion at which the tips' gaps are measured.
GAP_REACH_SAMPLES = 10


@dataclass(frozen=True)
class RollAhead:
    """What the fingers' rolled motion (:func:`~ocp.robots.grasp_reach.roll`: every 4-joint
    round fingertip's motion fixed by the ball's) says of a turn about an axis, up to
    ``upto`` [rad]: how far before its first finger stops (``reach``; ``upto`` when none
    does), which finger and why; how far before two fingertips' bodies come closer than
    ``need`` [m] (``apart``; ``upto`` when they do not, or when some finger's motion is
    not fixed by the ball's: the rolls' certificate measures their gaps still)."""

    reach: float
    who: str
    why: str
    apart: float
    need: float
    #: what comes within ``need`` at ``apart`` ("" two fingertips' bodies; else the hand's
    #: links, in words: ``problem.collision``)
    close: str = ""


def _roll_ahead(template: ManipulationProblem, qs: tuple[FloatArray, ...],
                centre: FloatArray, rho: float, axis: FloatArray, upto: float,
                rotation: FloatArray | None = None) -> RollAhead:
    """:class:`RollAhead` of the grasp at joints ``qs`` turned about ``axis``: one pass of
    the fingers' rolled motion in :data:`GAP_REACH_SAMPLES` equal parts of ``upto`` (the
    seams kept ``pad_margin`` away), the tips' gaps measured at the end of each part and
    the crossing of ``need`` (ROLL_TIP_GAP, or 90 % of the grasp's own gap) interpolated
    linearly; the pass ends at the first finger's stop. An object that is not a ball
    turns with its form from ``rotation`` (its axes at the turn's start, palm frame): the
    rolled motion on its surface (:func:`~ocp.robots.grasp_reach.roll` with ``held``)."""
    from ocp.robots.grasp_reach import roll
    from ocp.robots.turn_reach import rolls

    R0 = np.eye(3) if rotation is None else np.asarray(rotation, dtype=float)
    held = held_object(template.object, centre, R0)
    if held.ball:  # (a ball's turn does not depend on its axes)
        R0 = np.eye(3)
    fingers = tuple(f.finger for f in template.fingers)
    names = tuple(f.name or f"finger{i}" for i, f in enumerate(template.fingers))
    nq = tuple(len(q) for q in qs)
    g0, _ = tips_gaps(fingers, np.concatenate(qs)[None], nq)
    need = min(ROLL_TIP_GAP, 0.9 * g0)
    gaps = all(rolls(f) for f in fingers) and math.isfinite(g0)
    h = upto / GAP_REACH_SAMPLES
    q = [np.asarray(v, dtype=float) for v in qs]
    reach, who, why, apart = upto, "", "", upto
    g_prev, th = g0, 0.0
    links = _link_gap(template, fingers, centre, R0) if gaps else None
    l_prev = links(q).value if links is not None else math.inf
    l_need = max(min(ROLL_LINK_CLEARANCE, 0.9 * l_prev), MIN_ROLL_LINK_CLEARANCE)
    close = ""
    if l_prev < l_need:  # the grasp's links are too close already
        apart, need, close = 0.0, l_need, links(q).describe() if links else ""
    for _ in range(GAP_REACH_SAMPLES):
        for i, f in enumerate(fingers):
            if not rolls(f):
                continue
            m = roll(f, q[i], centre, rho, axis, h, template.pad_margin,
                     held=None if held.ball else held.turned(axis, th))
            if m.why and th + m.reach < reach:  # a stop (a joint limit, the seam, a fold)
                reach, who, why = th + m.reach, names[i], m.why
            q[i] = m.q
        if why:
            break
        if gaps and apart >= upto:
            g, _ = tips_gaps(fingers, np.concatenate(q)[None], nq)
            if g < need:
                apart = th + h * (g_prev - need) / max(g_prev - g, 1e-12)
            g_prev = g
        if links is not None and apart >= upto:
            c = links(q, None if held.ball else held.turned(axis, th + h).rotation)
            if c.value < l_need:
                apart = th + h * (l_prev - l_need) / max(l_prev - c.value, 1e-12)
                need, close = l_need, c.describe()
            l_prev = c.value
        th += h
    return RollAhead(reach, who, why, apart, need, close)


#: A roll is cut where the fingers' rolled motion brings two of the hand's links (MuJoCo's
#: pairs, not the touching tips and the ball) this close [m], or 90 % of the grasp's own
#: least gap if smaller, but never below :data:`MIN_ROLL_LINK_CLEARANCE`: the
#: certificate's 0.5 mm with room for the plan's tracking slack.
ROLL_LINK_CLEARANCE = 1e-3
MIN_ROLL_LINK_CLEARANCE = 6e-4


def _link_gap(template: ManipulationProblem, fingers: tuple[Any, ...],
              centre: FloatArray, rotation: FloatArray | None = None) -> Any:
    """The least clearance of the hand's links at joints (per finger) with the object at
    ``centre`` (``template.collision``), its axes ``rotation`` (palm frame; default the
    palm's) or as given to the function, as a function; None without a collision
    model."""
    coll = template.collision
    if coll is None:
        return None
    names = [n for f in fingers for n in f.joint_names]
    shape, dims = template.object.shape, template.object.dimensions

    R0 = np.eye(3) if rotation is None else np.asarray(rotation, dtype=float)

    def gap(q: list[FloatArray], R: FloatArray | None = None) -> Any:
        return coll.least(shape, dims, names, np.concatenate(q)[None],
                          (R0 if R is None else R)[None],
                          np.asarray(centre, dtype=float)[None])

    return gap


#: A roll the fingers' rolled reach shortens stops this far before the reach: the larger
#: of a degree and a tenth of it (docs/hands.md: turns 1 deg inside the reach were planned,
#: 3 deg beyond were not).
REACH_MARGIN = math.radians(1.0)
REACH_SHARE = 0.1
#: The least roll worth planning [rad]: a gait whose fingers cannot roll farther stops.
MIN_ROLL = math.radians(0.5)
#: How many times a gait halves its rolls when a fingertip finds no swing back after one.
MAX_ROLL_RETRIES = 2


#: Samples per second of a roll's clock at which its joints' rates and accelerations are
#: checked against their limits.
CLOCK_SAMPLES = 200


def _clock_checks(plan: GaitPlan, r: int, template: ManipulationProblem, t0: float,
                  q_before: tuple[FloatArray, ...] | None = None) -> list[Check]:
    """Roll ``r`` on its clock (starting at ``t0``): starting where the joints were
    (``q_before``: the positions continuous across the switch, to
    :data:`SWITCH_POSITION_TOL`), still at both ends (rates and accelerations zero:
    continuous with the holds'), its rates and accelerations within the joints' limits,
    sampled densely."""
    clock = plan.clock(r)
    n = max(int(clock.length * CLOCK_SAMPLES), 2)
    tau = np.linspace(0.0, clock.length, n + 1)
    q, v, a = plan.roll_joints(r, tau)
    out = []
    if q_before is not None:
        jump = float(np.abs(q[0] - np.concatenate(q_before)).max())
        out.append(Check(f"switch_position_roll{r}_start", jump, SWITCH_POSITION_TOL,
                         CheckKind.PHYSICS, time=t0))
    for end, k in (("start", 0), ("end", -1)):
        out.append(Check(f"switch_rate_roll{r}_{end}", float(np.abs(v[k]).max()), 1e-9,
                         CheckKind.PHYSICS, time=t0 + float(tau[k])))
        out.append(Check(f"switch_acceleration_roll{r}_{end}", float(np.abs(a[k]).max()),
                         1e-9, CheckKind.PHYSICS, time=t0 + float(tau[k])))
    vmax = np.concatenate([np.asarray(f.finger.velocity_limit, dtype=float)
                           for f in template.fingers])
    over_v = (np.abs(v) / vmax).max(axis=1)
    k = int(np.argmax(over_v))
    out.append(Check(f"roll{r}_clock_velocity", float(over_v[k]), 1.0 + 1e-9,
                     CheckKind.LIMITS, time=t0 + float(tau[k])))
    acc = np.abs(a).max(axis=1)
    k = int(np.argmax(acc))
    out.append(Check(f"roll{r}_clock_acceleration", float(acc[k]),
                     template.max_joint_acceleration * (1 + 1e-9), CheckKind.LIMITS,
                     time=t0 + float(tau[k])))
    # the fingertips' bodies apart from each other while they roll (the rolling NLP has
    # no rows for it; a swing's own check would find the overlap a roll left only later)
    q = plan.roll_joints(r, tau[::TIP_GAP_STRIDE])[0]
    gap, at = tips_gaps(tuple(f.finger for f in template.fingers), q, plan.nq)
    out.append(Check(f"roll{r}_tip_gap", gap, -TIP_GAP_TOL, CheckKind.PHYSICS,
                     lower_bound=True, time=t0 + float(tau[::TIP_GAP_STRIDE][at])))
    # the forces plus the joints' damping at the clock's rates (run faster than planned,
    # or slowed for the damping: :func:`roll_speed`)
    out += _clock_torques(plan, r, template, t0, tau[::TIP_GAP_STRIDE],
                          damped_only=clock.speed <= 1.0)
    return out


def roll_speed(sol: ManipulationSolution, template: ManipulationProblem,
               nq: tuple[int, ...], fastest: bool = True) -> float:
    """The speed a roll's path is run at. ``fastest``: the highest (at least 1) within the
    joints' velocity limits, the acceleration bound, and the share of the actuators' range
    its forces leave to the damping (1 - the force stage's
    :data:`~ocp.solve.force_plan.ROLL_TORQUE_SHARE`; :func:`~ocp.gait.warp.fastest_speed`);
    else 1 (the plan's own timing). Either is lowered, below 1 if need be, to where the
    roll's forces plus its joints' damping at the clock's rates stay within the actuators'
    whole range (:func:`damping_speed`, times :data:`DAMPING_SPEED_MARGIN`): a hand file
    whose joints are damped (``damping`` 1 N m s/rad against 0.7 N m actuators) cannot
    roll at the request's pace, so the roll is made slower, not refused."""
    from ocp.solve.force_plan import ROLL_TORQUE_SHARE

    whole = torque_limits(template, 1.0)
    damped = whole is not None and whole.damped
    if not fastest and not damped:
        return 1.0
    dur = float(sol.duration)
    s = np.linspace(0.0, dur, max(int(dur * CLOCK_SAMPLES), 2) + 1)
    jt = sol.joint_trajectory(s, efforts=False)
    speed = 1.0
    if fastest:
        vmax = np.concatenate([np.asarray(f.finger.velocity_limit, dtype=float)
                               for f in template.fingers])
        overrun = 0.0
        limits = torque_limits(template, 1.0 - ROLL_TORQUE_SHARE)
        if limits is not None:
            cut = np.cumsum((0, *nq))
            overrun = max(limits.damping_overrun(i, jt.positions[:, cut[i]:cut[i + 1]],
                                                 jt.velocities[:, cut[i]:cut[i + 1]])
                          for i in range(len(nq)))
        speed = fastest_speed(dur, jt.velocities, jt.accelerations, vmax,
                              SPEED_MARGIN * float(template.max_joint_acceleration), overrun)
    if whole is None or not damped:
        return speed
    bound = damping_speed(sol, whole, nq, s, jt.positions, jt.velocities)
    return speed if speed <= bound else DAMPING_SPEED_MARGIN * bound


#: A roll slowed for its joints' damping is run at this share of the speed at which its
#: forces and damping would take an actuator's whole range (the rest for the links'
#: inertia and the Coriolis terms, which the hand's actuator check adds).
DAMPING_SPEED_MARGIN = 0.9


def damping_speed(sol: ManipulationSolution, limits: TorqueLimits, nq: tuple[int, ...],
                  s: FloatArray, Q: FloatArray, V: FloatArray) -> float:
    """The highest speed at which roll ``sol``'s joint torques, its forces' at the plan's
    times ``s`` plus its joints' damping at the rates ``V`` (rows: those times; the
    plan's rates, speed 1) times the speed, stay within the actuators' whole range
    (``limits``, share 1) at the joints ``Q`` (inf without damped joints; 0 where the
    forces alone leave none: the roll's own certificate refuses that)."""
    if not limits.damped:
        return math.inf
    static = sol.joint_torques(s)
    cut = np.cumsum((0, *nq))
    top = math.inf
    for i in range(len(nq)):
        c = np.asarray(limits.damping[i], dtype=float)
        if not np.any(c > 0):
            continue
        for k in range(len(s)):
            lo, hi = limits.at(i, Q[k, cut[i]:cut[i + 1]])
            tau, rate = np.asarray(static[i][k], dtype=float), c * V[k, cut[i]:cut[i + 1]]
            room = np.where(rate > 0, hi - tau, np.where(rate < 0, lo - tau, np.inf))
            with np.errstate(divide="ignore", invalid="ignore"):
                each = np.where(rate != 0, room / rate, np.inf)
            top = min(top, max(float(each.min(initial=math.inf)), 0.0))
    return top


#: The share of the acceleration bound a fastest roll is timed to: its speed is found on
#: its plan's samples, the certificate checks the clock's own (denser) samples.
SPEED_MARGIN = 0.98


def _clock_torques(plan: GaitPlan, r: int, template: ManipulationProblem, t0: float,
                   tau: FloatArray, damped_only: bool = False) -> list[Check]:
    """Roll ``r``'s joint torques on its clock within the actuators' whole range: its
    forces' (at the plan's times) plus its joints' damping at the clock's rates (a roll
    run faster than planned asks more of the damping). ``damped_only``: none for a hand
    whose joints have no damping (a roll at its plan's pace or slower then asks only its
    forces' torques, which its own certificate checks)."""
    limits = torque_limits(template, 1.0)
    if limits is None or not limits.damping or (damped_only and not limits.damped):
        return []
    clock = plan.clock(r)
    s = clock(tau)[0]
    q, v, _ = plan.roll_joints(r, tau)
    worst, at = torque_overrun(limits, plan.fingers_of(r), plan.rolls[r].joint_torques(s),
                               q, v, plan.nq)
    return [Check(f"roll{r}_clock_torque", worst, 1.0 + 1e-9, CheckKind.LIMITS,
                  time=t0 + float(tau[at]))]


def torque_overrun(limits: TorqueLimits, fingers: list[int], static: list[FloatArray],
                   q: FloatArray, v: FloatArray, nq: tuple[int, ...]) -> tuple[float, int]:
    """(the largest share of its actuators' range a joint of the ``fingers`` (indices of
    ``limits``' and of the joint rows ``q``, ``v``: every finger's, concatenated) needs,
    the row where) for the torques ``static`` (per finger of ``fingers``, rows) plus its
    joints' damping at the rates ``v``."""
    cut = np.cumsum((0, *nq))
    worst, at = 0.0, 0
    for c_i, i in enumerate(fingers):  # (a swinging fingertip's: its swing's)
        c = np.asarray(limits.damping[i], dtype=float)
        for k in range(len(q)):
            over = limits.overrun(i, q[k, cut[i]:cut[i + 1]],
                                  static[c_i][k] + c * v[k, cut[i]:cut[i + 1]])
            if over > worst:
                worst, at = over, k
    return worst, at


#: How far [rad or m] a roll's first joints may be from the joints the phase before it
#: ended at: the contact coordinates a roll starts from close the tips' nanometre gaps
#: first (``ocp.spec.grasp.contact_from_joints``), moving the joints by nanoradians
#: (4e-9 measured between rolls separated by re-placements; a roll that starts where the
#: last one ended, its tips inside the ball by up to 13 nm, the rolling plan's contact rows'
#: accuracy, moves them by up to 1.02e-7 rad: 90 deg about -x with ``overlap``). The first
#: roll has no phase before it: it starts where the request's grasp is once its gaps (up
#: to 2 mm) are closed.
SWITCH_POSITION_TOL = 1e-6
#: Every how many of a roll's clock samples its fingertips' gaps are measured (40 a
#: second), and how far two tips' bodies may overlap [m] before the check fails.
TIP_GAP_STRIDE = 5
TIP_GAP_TOL = 1e-5


def pair_gaps(fingers: tuple[Any, ...], q: FloatArray, nq: tuple[int, ...]
              ) -> dict[tuple[int, int], FloatArray]:
    """Per pair of fingertips (i < j), the distance [m] between their bodies over the
    joint rows ``q`` (every finger's, concatenated; < 0: overlap)."""
    cut = np.cumsum((0, *nq))
    segs = []
    for c, f in enumerate(fingers):
        body = tip_body(f)
        ends = [body.placed(*f.fingertip_pose_pin(row[cut[c]:cut[c + 1]])) for row in q]
        segs.append((np.array([e[0] for e in ends]), np.array([e[1] for e in ends]),
                     body.r))
    return {(i, j): segments_distance(a0, b0, a1, b1) - r0 - r1
            for i, (a0, b0, r0) in enumerate(segs)
            for j, (a1, b1, r1) in enumerate(segs) if j > i}


def landing_gap(fingers: tuple[Any, ...], q_after: tuple[FloatArray, ...], k: int
                ) -> tuple[float, int]:
    """(the least distance [m] from fingertip ``k``'s body to the others', the nearest)
    with every finger at the joints ``q_after`` (``k`` landed: the others rolled meanwhile,
    and may have come into where it lands)."""
    gaps = pair_gaps(fingers, np.concatenate(q_after)[None], tuple(len(q) for q in q_after))
    return min(((float(g[0]), j if i == k else i) for (i, j), g in gaps.items()
                if k in (i, j)), default=(math.inf, -1))


def tips_gaps(fingers: tuple[Any, ...], q: FloatArray, nq: tuple[int, ...]
              ) -> tuple[float, int]:
    """(the least distance [m] between two fingertips' bodies over the joint rows ``q``
    (every finger's, concatenated; < 0: overlap), the row where it is)."""
    gaps = np.full(len(q), np.inf)
    for g in pair_gaps(fingers, q, nq).values():
        gaps = np.minimum(gaps, g)
    k = int(np.argmin(gaps))
    return float(gaps[k]), k


def _stopped(who: str, why: str, at: float, angle: float, ax: FloatArray,
             held: bool, what: str = "the ball") -> str:
    """Why a gait stops short: which finger, what stops it, after how much of the turn
    (``what``: the object, in words)."""
    head = (f"finger {who!r} ({why}) stops the turn after {math.degrees(at):.1f} deg of "
            f"{math.degrees(angle):.1f} deg about ({', '.join(f'{c:.3g}' for c in ax)})")
    return head + (f" and cannot be re-placed (the others cannot hold {what} without it)"
                   if held else " even from its re-placed contact")


def _too_few(step: float, left: int, rest: float, ahead: RollAhead, halved: str = ""
             ) -> str:
    """Why a gait stops at once: its rolls, cut to ``step`` [rad] (a gait's fingertips
    return to the grasp after each), would need more than the ``left`` rolls allowed for
    the ``rest`` [rad] of the turn; ``halved``: why the rolls were halved, when that is
    what cut them."""
    if halved:
        why = halved
    elif ahead.apart <= step + 1e-12 and ahead.apart < ahead.reach:
        why = (f"the hand's links come within {ahead.need * 1e3:.2f} mm ({ahead.close})"
               if ahead.close else
               f"two fingertips come within {ahead.need * 1e3:.2f} mm of each other")
    else:
        why = f"finger {ahead.who!r} stops ({ahead.why})" if ahead.why else "roll_step"
    return (f"each roll from this grasp is cut to {math.degrees(step):.2g} deg ({why}): "
            f"{left} more rolls (max_rolls) cannot turn the remaining "
            f"{math.degrees(rest):.1f} deg")


def _too_close(need: float, at: float, angle: float, ax: FloatArray, close: str = ""
               ) -> str:
    """Why a gait stops short: two fingertips' bodies (or the hand's links: ``close``)
    within ``need`` [m] after ``at``."""
    what = (f"the hand's links come within {need * 1e3:.2f} mm ({close})" if close else
            f"two fingertips come within {need * 1e3:.2f} mm of each other")
    return (f"{what} after {math.degrees(at):.1f} deg of {math.degrees(angle):.1f} deg "
            f"about ({', '.join(f'{c:.3g}' for c in ax)}): the grasp cannot roll on")


def _undo(plan: GaitPlan, checks: list[Check], never_lifted: set[str], before: tuple[Any, ...]
          ) -> tuple[Any, ...]:
    """Back to where the gait stood before a roll (``before``: the counts of its rolls,
    phases, steps and checks, then the loop's time, turn, pose, joints and the fingers
    never lifted): what came after dropped, the status solved again; (t, done, pose,
    q_now) then."""
    n_r, n_p, n_s, n_k, t, done, pose, q_now, lifted = before
    for r in [r for r in plan.carried if r >= n_r]:
        del plan.carried[r]
    del plan.rolls[n_r:], plan.clocks[n_r:], plan.frames[n_r:], plan.phases[n_p:]
    del plan.steps[n_s:], checks[n_k:]
    never_lifted.clear()
    never_lifted.update(lifted)
    plan.status, plan.message = "solved", ""
    return t, done, pose, q_now


#: A swing keeps clear of the hand's links within this distance [m] of the ball's surface
#: (its tip goes no farther from the ball than the clearance and its own length).
OBSTACLE_RANGE = 0.04


def swing_obstacles(template: ManipulationProblem) -> Any:
    """The hand's links a swing keeps clear of (``template.collision``'s
    :meth:`~ocp.robots.collision.HandCollision.obstacles` near the ball), as
    ``obstacles(qs, k, centre)``; None without a collision model."""
    coll = template.collision
    if coll is None:
        return None
    names = [n for f in template.fingers for n in f.finger.joint_names]
    shape, dims = template.object.shape, template.object.dimensions
    rho = float(max(dims))

    def obstacles(qs: tuple[FloatArray, ...], k: int, centre: FloatArray) -> list[Any]:
        return coll.obstacles(shape, dims, names, np.concatenate(qs), k,
                              near=(centre, rho + OBSTACLE_RANGE))

    return obstacles


def _holds_beyond_actuators(template: ManipulationProblem, fingers: tuple[Any, ...],
                            qs: tuple[FloatArray, ...], held: Held, load: FloatArray,
                            names: tuple[str, ...]) -> str:
    """Why the grasp held by every fingertip needs more torque than the actuators give at
    their full range, naming the joint, the torque and the limit; "" when it fits. (Each
    re-placement starts and ends with that hold; a hold with one fingertip lifted that
    does not fit leaves that fingertip rolling instead: :func:`~ocp.gait.step.
    replace_finger`.)"""
    limits = torque_limits(template, share=1.0)
    if limits is None:
        return ""
    allf = list(range(len(fingers)))
    hold = grasp_hold(fingers, qs, allf, held)
    why = hold_torque_refusal(fingers, qs, allf, hold, load, held.radius, limits, names)
    return f"the grasp's hold: {why}" if why else ""


def torque_limits(template: ManipulationProblem, share: float = HOLD_TORQUE_SHARE
                  ) -> TorqueLimits | None:
    """The fingers' actuator torques a gait's holds keep to (``template.actuation``, times
    ``share``: :data:`~ocp.gait.step.HOLD_TORQUE_SHARE`); None without actuators, limits
    or forces."""
    from ocp.robots.actuation import ranges_of

    act = template.actuation
    if act is None or template.forces is None:
        return None
    actuators = tuple(act.actuators(f.finger.joint_names)[0] for f in template.fingers)
    bounds = [ranges_of(acts, share) for acts in actuators]
    ctrl_limited = any(a.ctrl_range is not None and a.kind != "none"
                       for acts in actuators for a in acts)
    if not ctrl_limited and all(np.all(np.isinf(lo)) and np.all(np.isinf(hi))
                                for lo, hi in bounds):
        return None
    damping = tuple(np.asarray(act.damping(f.finger.joint_names), dtype=float)
                    for f in template.fingers)
    rates = []
    for c, (lo, hi) in zip(damping, bounds, strict=True):
        with np.errstate(divide="ignore", invalid="ignore"):
            rates.append(np.where(c > 0, np.minimum(-lo, hi) / c, np.inf))
    return TorqueLimits(tuple(lo for lo, _ in bounds), tuple(hi for _, hi in bounds),
                        np.asarray(template.forces.gravity, dtype=float), tuple(rates), share,
                        actuators, damping)


def spent_fingers(template: ManipulationProblem, q_now: tuple[FloatArray, ...],
                  centre: FloatArray, rho: float, axis: FloatArray, upto: float,
                  never_lifted: set[str], rotation: FloatArray | None = None) -> list[int]:
    """:func:`spent_reach`'s fingertips."""
    return spent_reach(template, q_now, centre, rho, axis, upto, never_lifted, rotation)[0]


def spent_reach(template: ManipulationProblem, q_now: tuple[FloatArray, ...],
                centre: FloatArray, rho: float, axis: FloatArray, upto: float,
                never_lifted: set[str], rotation: FloatArray | None = None
                ) -> tuple[list[int], dict[int, float]]:
    """(the fingertips to re-place before the next roll, each liftable fingertip's rolled
    reach [rad] up to ``(1 + SPENT_MARGIN) upto``, infinite where its motion is not fixed
    by the ball's). The fingertips to re-place before the next roll of ``upto`` [rad]
    about ``axis``:
    those whose rolled reach from the joints ``q_now`` (:func:`~ocp.robots.grasp_reach.
    roll`, the seams kept ``pad_margin`` away) falls short of ``(1 + SPENT_MARGIN) upto``,
    those whose motion the ball's does not fix (their reach is not known), and of two
    fingertips the roll brings within the tips' gap, the one that reaches less. A
    fingertip the others cannot hold the ball without is none of them (it rolls
    throughout)."""
    from ocp.robots.grasp_reach import roll
    from ocp.robots.turn_reach import rolls

    out = []
    reach: dict[int, float] = {}
    rolled: list[FloatArray] = []
    held = held_object(template.object, centre, np.eye(3) if rotation is None else rotation)
    for k, f in enumerate(template.fingers):
        r = roll(f.finger, q_now[k], centre, rho, axis, upto * (1.0 + SPENT_MARGIN),
                 template.pad_margin, held=None if held.ball else held) \
            if rolls(f.finger) else None
        rolled.append(np.asarray(q_now[k] if r is None else r.q, dtype=float))
        if (f.name or f"finger{k}") in never_lifted:
            continue
        reach[k] = math.inf if r is None else r.reach
        if r is None or r.why:
            out.append(k)
    # two fingertips the roll brings together: the one of the pair that reaches less
    ahead = _roll_ahead(template, q_now, centre, rho, axis, upto, rotation)
    if ahead.apart < upto and not ahead.close:
        fingers = tuple(f.finger for f in template.fingers)
        at = [q if k in out else rolled[k] for k, q in enumerate(q_now)]
        gaps = pair_gaps(fingers, np.concatenate(at)[None], tuple(len(q) for q in at))
        pair = min(gaps, key=lambda ij: float(gaps[ij][0]))
        liftable_ = [k for k in pair if k in reach]
        if liftable_ and not set(pair) & set(out):
            out.append(min(liftable_, key=lambda k: reach[k]))
    return sorted(out), reach


#: A fingertip is re-placed when its rolled reach is below the next roll's length and
#: this share of it more (its reach is spent, or will be after the next roll: a fingertip
#: rolled farther from where it began finds no swing back as often).
SPENT_MARGIN = 1.0
#: Re-placing only the spent fingertips, a roll is warm-started from the last one when
#: every joint starts within this [rad] of where the last one started (the grasp recurs;
#: re-placing every one, it recurs but for the never-lifted fingertips, and always is).
RECUR_TOL = 0.05
#: A fingertip within this [rad] of its landing joints in every joint is where it lands:
#: an overlap roll that would strand it is halved rather than it re-placed first (a swing
#: lands on its landing point, its joints within 2e-5 rad of the landing's on a hand with
#: coupled joints, where re-placing the one just landed, at rest, came before every
#: re-placement at rest again: docs/gait.md, session 33).
LANDED_TOL = 1e-3
#: The landing candidates of :func:`farthest_landings`: shares of the turn back.
LANDING_SHARES = (0.0, 0.25, 0.5, 0.75, 1.0)
#: How far [m] a landing candidate's tip centre may be from where it touches the ball.
LANDING_TOL = 1e-12
#: A landing drawn over the finger's joints (not its home contact rolled back) is
#: within this angle [rad] of home's normal on the ball ...
LANDING_CONE = math.radians(45.0)
#: ... and its tip body this far [m] from the other fingertips' at home and at their
#: landings.
LANDING_GAP = 3e-3
#: ... and reached by a swing from where the finger's home reach is spent: the farthest
#: reaching this many of them are tried.
LANDING_TRIES = 3


def farthest_landings(template: ManipulationProblem, q_home: tuple[FloatArray, ...],
                      centre: FloatArray, rho: float, axis: FloatArray, back: float
                      ) -> tuple[FloatArray, ...]:
    """Per fingertip, where a spent one lands: of its home contact (the joints ``q_home``),
    that contact rolled back about ``axis`` (:func:`~ocp.robots.grasp_reach.roll`
    with the ball turned by -``back`` times each of :data:`LANDING_SHARES`, as far as it
    rolls back without stopping: never at a joint limit, a seam kept ``pad_margin`` away,
    or a fold of its motion) and the finger's other contacts on the ball
    (:func:`~ocp.robots.first_grasp.finger_contacts`: its joints drawn over their ranges)
    whose normal is within :data:`LANDING_CONE` of home's and whose tip body keeps
    :data:`LANDING_GAP` from the other fingertips' where they touched when the gait began
    and where they land (chosen in the fingers' order), the hand's links as far apart
    (``template.collision``: at least the least of that gap and their clearance at home;
    each candidate but home itself so kept), a drawn one only when an at-rest swing
    (:func:`~ocp.gait.step.replace_finger`) reaches it from where the finger's home reach
    is spent (the others at home; the :data:`LANDING_TRIES` farthest tried), the one from
    which it rolls forward the farthest, the nearest home among those within 1 mrad of it;
    each placed on the ball to :data:`LANDING_TOL` (the rolled joints drift by up to a micrometre;
    :func:`~ocp.robots.grasp_reach.grasp_on_ball`, its couplings kept) so that the roll
    after its landing starts where its joints are."""
    from ocp.robots.first_grasp import finger_contacts
    from ocp.robots.grasp_reach import grasp_on_ball, roll, tip_state
    from ocp.robots.turn_reach import rolls

    fingers = tuple(f.finger for f in template.fingers)
    names = tuple(f.name or f"finger{i}" for i, f in enumerate(template.fingers))
    load, limits = load_parameters(template), torque_limits(template)
    obstacles = swing_obstacles(template)
    links = _link_gap(template, fingers, centre)  # (the hand's links, where modelled)
    floor = min(LANDING_GAP, links(list(q_home)).value) if links is not None else 0.0
    out: list[FloatArray] = []

    def apart(k: int, q: FloatArray) -> bool:  # clear of the others, home and landed
        beside = [tuple(q if j == k else at[j] for j in range(len(fingers)))
                  for at in (q_home, (*out, *q_home[k:]))]
        return min(landing_gap(fingers, qs, k)[0] for qs in beside) >= LANDING_GAP and (
            links is None or min(links(list(qs)).value for qs in beside) >= floor)

    for k, f in enumerate(fingers):
        best, best_reach, home = q_home[k], -1.0, 0.0
        if not rolls(f):
            out.append(best)
            continue
        for share in LANDING_SHARES:
            q = q_home[k]
            if share > 0.0:
                behind = roll(f, q_home[k], centre, rho, -axis, share * back,
                              template.pad_margin)
                if behind.why:  # stopped short (a joint limit, a seam, singular):
                    break  # no landing at the edge of its reach
                # on the ball exactly: its contact's normal kept, the couplings too
                placed = grasp_on_ball(f, behind.q, centre, rho,
                                       tip_state(f, behind.q, centre, rho).n,
                                       LANDING_TOL, template.pad_margin)
                if placed is None:
                    break
                if not apart(k, placed):
                    continue
                q = placed
            reach = roll(f, q, centre, rho, axis, math.pi, template.pad_margin).reach
            if share == 0.0:
                home = reach
            if reach > best_reach + 1e-3:
                best, best_reach = q, reach
        n_home = tip_state(f, q_home[k], centre, rho).n
        drawn, _ = finger_contacts(f, centre, rho, seeds=(q_home[k],),
                                   margin=template.pad_margin)
        farther = []
        for c in drawn:
            if float(c.normal @ n_home) < math.cos(LANDING_CONE):
                continue
            placed = grasp_on_ball(f, c.q, centre, rho, c.normal, LANDING_TOL,
                                   template.pad_margin)
            if placed is None or not apart(k, placed):
                continue
            reach = roll(f, placed, centre, rho, axis, math.pi, template.pad_margin).reach
            if reach > best_reach + 1e-3:
                farther.append((reach, placed, c.normal))
        # the farthest that a swing reaches from where the finger's home reach is spent
        # (the others at home, the ball still): one a swing cannot reach strands it
        # (four_finger_gait-018's middle finger, found by the bench family)
        if farther:
            spent = roll(f, q_home[k], centre, rho, axis, max(home - REACH_MARGIN, 0.0),
                         template.pad_margin).q
            at = tuple(spent if j == k else q for j, q in enumerate(q_home))
        for _, placed, normal in sorted(farther, key=lambda x: -x[0])[:LANDING_TRIES]:
            if replace_finger(fingers, at, k, normal, placed, Held(centre, np.eye(3), rho),
                              load, None, 0.2, None, names, limits, obstacles).ok:
                best = placed
                break
        out.append(best)
    return tuple(out)


def _replace_fingers(plan: GaitPlan, checks: list[Check], template: ManipulationProblem,
                     q_start: tuple[FloatArray, ...], q_now: tuple[FloatArray, ...],
                     pose: ObjectPose, t: float, load: FloatArray,
                     swing: dict[str, Any] | None, hold_time: float, never_lifted: set[str],
                     which: list[int] | None = None,
                     nearer: tuple[FloatArray, ...] | None = None
                     ) -> tuple[tuple[FloatArray, ...], float]:
    """After a roll: the fingertips ``which`` (default: every one) that the others can
    hold the ball without re-placed, in turn, at the contact they had at the joints
    ``q_start`` (relative to the palm), its phases, step and checks added to ``plan`` and
    ``checks``; (the joints after, the time); where no swing there is found, at the
    contact it had at the joints ``nearer`` when given (where this roll began). A step
    that fails sets the plan's status and ends the loop."""
    fingers = tuple(f.finger for f in template.fingers)
    nf = len(fingers)
    held = held_at(template, pose)
    assert template.forces is not None
    limits = torque_limits(template)
    obstacles = swing_obstacles(template)
    for k in (range(nf) if which is None else which):
        last = next((st.swing for st in reversed(plan.steps) if st.finger == k), None)
        for q_land in (q_start[k], *(() if nearer is None else (nearer[k],))):
            if not held.ball:  # where it touched, on the turned object (not on it now)
                q_land = landing_on(template, pose, fingers[k], q_land)
            _, n_back = held.contact(fingers[k], q_land)
            gs = replace_finger(fingers, q_now, k, n_back, q_land, held, load, swing,
                                hold_time, last,
                                tuple(f.name or f"finger{i}"
                                      for i, f in enumerate(template.fingers)), limits,
                                obstacles)
            if gs.ok or gs.swing is None:  # found, or the others cannot hold the ball
                break
        if gs.status == "infeasible" and gs.swing is None:
            never_lifted.add(template.fingers[k].name or f"finger{k}")
            continue  # it keeps rolling
        i = len(plan.steps)
        plan.steps.append(gs)
        if not gs.ok or gs.swing is None:
            plan.status, plan.message = "failed", f"gait step {i}: {gs.message}"
            break
        touching = tuple(j != k for j in range(nf))
        t1, t2 = t + gs.unload, t + gs.unload + gs.swing.duration
        plan.phases += [GaitPhase("unload", t, t1, (True,) * nf, k, i),
                        GaitPhase("swing", t1, t2, touching, k, i),
                        GaitPhase("load", t2, t2 + gs.load_time, (True,) * nf, k, i)]
        checks += gs.checks(f"step{i}", t, load, template.forces.min_normal_force)
        jump = float(np.abs(gs.swing.Q[0] - q_now[k]).max())
        checks.append(Check(f"switch_position_step{i}", jump, 1e-12, CheckKind.PHYSICS,
                            time=t))
        q_now = gs.q_after
        t = t2 + gs.load_time
    return q_now, t


def _replace_spent(plan: GaitPlan, checks: list[Check], template: ManipulationProblem,
                   q_home: tuple[FloatArray, ...], q_start: tuple[FloatArray, ...],
                   q_now: tuple[FloatArray, ...], pose: ObjectPose, t: float,
                   load: FloatArray, swing: dict[str, Any] | None, hold_time: float,
                   never_lifted: set[str], axis: FloatArray, upto: float
                   ) -> tuple[tuple[FloatArray, ...], float] | None:
    """After a roll: only the fingertips whose reach is spent for the next one of
    ``upto`` (:func:`spent_fingers`) re-placed, each where it touched when the gait began
    (``q_home``; where it touched when the roll began, ``q_start``, when no swing home is
    found): (the joints after, the time). None, with ``plan``, ``checks`` and
    ``never_lifted`` as they were, when one of them cannot be lifted or a step fails."""
    which = spent_fingers(template, q_now, np.asarray(pose.position, float),
                          float(template.object.dimensions[0]), axis, upto, never_lifted,
                          pose.rotation)
    return _replaced(plan, checks, template, q_home, q_start, q_now, pose, t, load, swing,
                     hold_time, never_lifted, which)


def _replaced(plan: GaitPlan, checks: list[Check], template: ManipulationProblem,
              q_land: tuple[FloatArray, ...], q_start: tuple[FloatArray, ...],
              q_now: tuple[FloatArray, ...], pose: ObjectPose, t: float, load: FloatArray,
              swing: dict[str, Any] | None, hold_time: float, never_lifted: set[str],
              which: list[int]) -> tuple[tuple[FloatArray, ...], float] | None:
    """The fingertips ``which`` re-placed with the ball still (:func:`_replace_fingers`:
    at ``q_land``, else where they touched when the roll began, ``q_start``): (the joints
    after, the time), or None, with ``plan``, ``checks`` and ``never_lifted`` as they
    were, when one of them cannot be lifted, a step fails, or one lands within
    :data:`ROLL_TIP_GAP` of another fingertip's body (the others rolled toward where it
    lands, as an overlap roll's landing is checked: on a hand with coupled joints a lone
    re-placement landed the middle 0.49 mm from the index, which the service's link
    clearance refused)."""
    marks = (len(plan.phases), len(plan.steps), len(checks), set(never_lifted))
    q_after, t_after = _replace_fingers(plan, checks, template, q_land, q_now, pose, t,
                                        load, swing, hold_time, never_lifted, which, q_start)
    fingers = tuple(f.finger for f in template.fingers)
    if plan.status == "solved" and never_lifted == marks[3] and all(
            landing_gap(fingers, q_after, k)[0] >= ROLL_TIP_GAP for k in which):
        return q_after, t_after
    del plan.phases[marks[0]:], plan.steps[marks[1]:], checks[marks[2]:]
    plan.status, plan.message = "solved", ""
    never_lifted.clear()
    never_lifted.update(marks[3])
    return None


def _overlap_roll(plan: GaitPlan, checks: list[Check], template: ManipulationProblem,
                  planner: Any, k: int, q_now: tuple[FloatArray, ...],
                  pose: ObjectPose, R0: FloatArray, ax: FloatArray, done: float, step: float,
                  seconds_per_radian: float, t: float, load: FloatArray,
                  swing: dict[str, Any] | None, hold_time: float, fastest_rolls: bool,
                  handover: int | None, lands: tuple[FloatArray, ...], never_lifted: set[str],
                  switch: bool = True
                  ) -> tuple[tuple[FloatArray, ...], float, float, ObjectPose] | str \
        | tuple[str, int]:
    """Fingertip ``k`` re-placed at its landing joints (``lands[k]``) while the others roll
    the ball by
    up to ``step`` [rad] about ``ax`` (:mod:`ocp.gait.overlap`): the roll's length cut to
    the others' rolled reach and gaps as every roll's, its plan, the swing on its clock,
    the holds around; its phases (unload, the roll with ``k`` lifted, load), plan, step
    and checks added to ``plan`` and ``checks`` (but the step's own: :func:`_step_checks`,
    once its loading is known). ``handover``: the step before, re-placed during the roll
    before and not yet loaded (the plan's last phase its loading): its loading and this
    step's unloading become one ramp (:attr:`~ocp.gait.step.GaitStep.landing`). (the
    joints after, the time, the turn made, the pose) or why not (``plan`` and ``checks``
    as they were). A roll after which another fingertip that can be lifted
    (not in ``never_lifted``) would find no swing to its landing (:func:`~ocp.gait.overlap.
    stranded_fingers`) is halved, up to :data:`MAX_ROLL_RETRIES` times; with ``switch``,
    (why, that fingertip) is returned at once instead: it is to be re-placed first, unless
    it is where it lands (within :data:`LANDED_TOL`: re-placing it moves it nowhere)."""
    centre = np.asarray(pose.position, dtype=float)
    rho = float(template.object.dimensions[0])
    names = tuple(f.name or f"finger{i}" for i, f in enumerate(template.fingers))
    depth = hold_depth(template, q_now, k, centre, rho, pose.rotation, load)
    if depth < 0.0:
        return f"the others cannot hold the ball with {names[k]!r} lifted"
    sub = without(template, k, min(depth, OVERLAP_HOLD_DEPTH))
    q_sub = tuple(q for i, q in enumerate(q_now) if i != k)
    ahead = _roll_ahead(sub, q_sub, centre, rho, ax, step)
    if ahead.why and ahead.reach < step - 1e-6:
        step = ahead.reach - max(REACH_MARGIN, REACH_SHARE * ahead.reach)
    step = min(step, ahead.apart)
    if step < MIN_ROLL:
        why = (f"without {names[k]!r} the others roll {math.degrees(max(step, 0.0)):.1f} "
               f"deg: " + (f"finger {ahead.who!r} stops ({ahead.why})" if ahead.why and
                           ahead.reach <= ahead.apart else "two come too close"))
        if switch and ahead.why and ahead.who in names and ahead.who not in never_lifted:
            return why, names.index(ahead.who)  # the one whose reach is spent first
        return why

    def problem(step: float) -> ManipulationProblem:  # the others' roll by ``step``
        return _roll_problem(sub, q_sub, pose, axis_angle_rotation(ax, done + step) @ R0,
                             centre, max(1.0, seconds_per_radian * step))

    prob = problem(step)
    # the last roll made without this fingertip, when the others start where it did
    warm = None
    for r in sorted(plan.carried, reverse=True):
        if plan.steps[plan.carried[r]].finger == k:
            last = plan.rolls[r]
            start = tuple(q for i, q in enumerate(plan.steps[plan.carried[r]].q_before or ())
                          if i != k)
            if last.ok and start and max(float(np.abs(a - b).max()) for a, b in
                                         zip(start, q_sub, strict=True)) <= RECUR_TOL:
                warm = last
                if last.stats is not None and last.stats.n_intervals > prob.n_intervals:
                    prob = prob.with_intervals(last.stats.n_intervals)
            break
    nq_sub = tuple(int(f.finger.nq) for f in sub.fingers)
    last_swing = next((st.swing for st in reversed(plan.steps) if st.finger == k), None)
    limits, obstacles = torque_limits(template), swing_obstacles(template)
    for _ in range(MAX_ROLL_RETRIES + 1):
        got, why, blocker = plan_overlap(
            template, planner, k, q_now, lands[k], prob, warm,
            lambda sol: roll_speed(sol, sub, nq_sub, fastest_rolls), centre, rho,
            pose.rotation, load, swing, hold_time, limits, names, last_swing)
        if got is None:
            if switch and blocker is not None and names[blocker] not in never_lifted:
                return why, blocker  # the fingertip in its way is re-placed first
            return why
        # the others' forces within their actuators (the roll's force stage keeps 90 % of
        # their range where it can, and plans without the bound where it cannot:
        # four_finger_gait-000's index 2.24 times its range, the ring lifted)
        whole = torque_limits(sub, 1.0)  # (the others', in their order)
        if whole is not None:
            tau = np.linspace(0.0, float(got.sol.duration), CLOCK_SAMPLES + 1)
            jt = got.sol.joint_trajectory(tau, efforts=False)
            over, _ = torque_overrun(whole, list(range(len(nq_sub))),
                                     got.sol.joint_torques(tau), jt.positions,
                                     0.0 * jt.velocities, nq_sub)
            if over > 1.0:
                return (f"without {names[k]!r} the others' forces need {over:.2f} times "
                        "an actuator's range")
        # the landing clear of the others where they rolled to
        apart, near = landing_gap(tuple(f.finger for f in template.fingers), got.q_after,
                                  k)
        if apart < ROLL_TIP_GAP:
            why = (f"finger {names[k]!r}'s landing is {apart * 1e3:.2f} mm from fingertip "
                   f"{names[near]!r} after {math.degrees(step):.1f} deg")
            if switch and names[near] not in never_lifted:  # that one is re-placed first
                return why, near
        else:
            # every other fingertip that can be lifted must still find a swing to its
            # landing after this roll (one rolled too far from it finds none)
            stranded = stranded_fingers(
                template, got.q_after, lands, centre, rho,
                [j for j in range(len(q_now)) if j != k and names[j] not in never_lifted],
                plan, limits, obstacles, swing)
            if not stranded:
                break
            why = (f"finger {names[stranded[0]]!r} would find no swing to its landing "
                   f"after {math.degrees(step):.1f} deg")
            # that one is re-placed first, unless it is where it lands (it has just
            # landed: re-placing it moves it nowhere, and this roll would strand it
            # again): then the roll is halved
            movable = [j for j in stranded if not at_landing(q_now[j], lands[j], LANDED_TOL)]
            if switch and movable:
                return why, movable[0]
        step /= 2.0
        if step < MIN_ROLL:
            return why
        prob, warm = problem(step), None
    else:
        return why
    assert got is not None
    r, i = len(plan.rolls), len(plan.steps)
    sol, clock = got.sol, got.clock
    step_ = replace(got.step, during_roll=r)
    if handover is not None:  # one ramp: the step before's loading, this one's unloading
        prev = plan.steps[handover]
        assert plan.phases[-1].kind == "load" and plan.phases[-1].index == handover
        t = plan.phases.pop().start
        plan.steps[handover] = replace(prev, load_time=0.0)
        F0 = np.insert(prev.forces[-2], prev.finger, 0.0, axis=0)
        step_ = replace(step_, landing=prev.finger, forces=(F0, *step_.forces[1:]))
    plan.rolls.append(sol)
    plan.frames.append(roll_frame(template, pose))
    plan.clocks.append(clock)
    plan.steps.append(step_)
    plan.carried[r] = i
    nf = len(template.fingers)
    t1 = t + hold_time
    t2 = t1 + clock.length
    plan.phases += [GaitPhase("unload", t, t1, (True,) * nf, k, i),
                    GaitPhase("roll", t1, t2, tuple(j != k for j in range(nf)), k, r),
                    GaitPhase("load", t2, t2 + hold_time, (True,) * nf, k, i)]
    checks += [replace(c, name=f"roll{r}_{c.name}",
                       time=None if c.time is None else t1 + clock.tau_of(c.time))
               for c in sol.certificate.checks]
    checks += _clock_checks(plan, r, template, t1, q_now)
    end = plan.rotation(r, sol.object_rotation[-1])
    pose = ObjectPose(tuple(quaternion_wxyz(end)), tuple(sol.object_position[-1]))
    return got.q_after, t2 + hold_time, done + step, pose


def _step_checks(plan: GaitPlan, i: int, load: FloatArray, template: ManipulationProblem
                 ) -> list[Check]:
    """Gait step ``i``'s checks (:meth:`~ocp.gait.step.GaitStep.checks`) from its
    unloading's start."""
    assert template.forces is not None
    t0 = next(p.start for p in plan.phases if p.kind == "unload" and p.index == i)
    return plan.steps[i].checks(f"step{i}", t0, load, template.forces.min_normal_force)


def plan_gait(template: ManipulationProblem, qs: tuple[Any, ...], axis: Any, angle: float,
              roll_step: float = math.radians(10.0), seconds_per_radian: float = 8.0,
              planner: Any = None, swing: dict[str, Any] | None = None,
              hold_time: float = 0.2, max_rolls: int = 40, replace_all: bool = True,
              fastest_rolls: bool = False, landing: str = "home",
              overlap: bool = False) -> GaitPlan:
    """Turn the ball of ``template`` (a grasp of round fingertips on a ball, with
    ``forces``: the holds need the object's weight) by ``angle`` [rad] about ``axis``
    (palm frame) from the joints ``qs`` (one array per finger), rolling by at most
    ``roll_step`` at a time and re-placing fingertips in between (the module's doc).
    When a fingertip finds no swing back after a roll, the gait goes back to before that
    roll and rolls half as far from then on, up to :data:`MAX_ROLL_RETRIES` times.
    ``swing``: fields of :class:`~ocp.gait.swing.SwingSpec` (duration, clearance);
    ``hold_time``: the unloading and loading around each swing [s]. ``replace_all``
    (default): after each roll every liftable fingertip is re-placed where it touched
    when that roll began ("roll and reset"); else only those whose reach is spent
    (:func:`spent_fingers`), each where it touched when the gait began (the ball turned
    about its centre fills the same space: that contact gives the grasp's searched
    reach again), or every one there when one of them cannot be lifted or finds no
    swing, and where it touched when the roll began when it finds no swing home.
    ``fastest_rolls``: each roll's path run as fast as the joints' velocity limits, the
    acceleration bound and the actuators' damping share allow (:func:`roll_speed`; its
    duration from ``seconds_per_radian`` an upper bound), its torques, damping's included,
    certified on its clock. ``landing`` (with the spent fingertips re-placed): "home",
    where each touched when the gait began, or "farthest", of that contact rolled back
    about the axis by up to ``roll_step``, the one from which it rolls forward the farthest
    (:func:`farthest_landings`). ``overlap`` (with the spent fingertips re-placed): each
    spent fingertip re-placed while the others roll the ball by the next step
    (:mod:`ocp.gait.overlap`), one per roll, the least-reaching first; where that is not
    found, at rest as without."""
    from ocp.solve.planner import ManipulationPlanner

    t_wall = time.perf_counter()
    planner = planner or ManipulationPlanner()
    if template.forces is None:
        return GaitPlan("infeasible", "a gait needs the object's load (forces): the other "
                                      "fingertips must hold it while one is lifted")
    ax = np.asarray(axis, dtype=float)
    ax = ax / np.linalg.norm(ax)
    pose0 = template.initial_pose or ObjectPose()
    R0, centre = pose0.rotation, np.asarray(pose0.position, dtype=float)
    fingers = tuple(f.finger for f in template.fingers)
    nf = len(fingers)
    load = load_parameters(template)
    rho = float(template.object.dimensions[0])
    held0 = held_object(template.object, centre, R0)
    if not held0.ball and (landing != "home" or overlap):
        return GaitPlan("infeasible", "farthest landings and overlap are planned on a "
                                      "ball alone")
    q_now = tuple(np.asarray(q, dtype=float) for q in qs)
    q_home = q_now  # where each fingertip touched when the gait began
    q_land: tuple[FloatArray, ...] | None = None  # where the spent ones land (made once)
    roll_starts: list[tuple[FloatArray, ...]] = []  # each roll's joints at its start
    roll_objects: dict[int, ObjectSpec] = {}  # each roll's object (its chart)
    pose = pose0
    plan = GaitPlan("solved", "", nq=tuple(int(f.nq) for f in fingers))
    names = tuple(f.name or f"finger{i}" for i, f in enumerate(template.fingers))
    # the fingers the others cannot hold the ball without (they roll throughout)
    never_lifted = {names[k] for k, ok in enumerate(liftable(fingers, q_now, held0, load))
                    if not ok}
    refusal = _holds_beyond_actuators(template, fingers, q_now, held0, load, names)
    if refusal:
        return GaitPlan("infeasible", refusal, never_lifted=tuple(sorted(never_lifted)),
                        nq=plan.nq, wall_time=time.perf_counter() - t_wall)
    checks: list[Check] = []
    t, done = 0.0, 0.0
    cap, retries = roll_step, 0  # the roll's length, halved where a re-placement failed
    halved = ""  # why it was last halved
    while done < angle - 1e-12 and len(plan.rolls) < max_rolls:
        step = min(cap, angle - done)
        ahead = _roll_ahead(template, q_now, np.asarray(pose.position, float), rho, ax, step,
                            pose.rotation)
        if ahead.why and ahead.reach < step - 1e-6:  # a finger stops short: roll to just
            step = ahead.reach - max(REACH_MARGIN, REACH_SHARE * ahead.reach)  # before it
            if step < MIN_ROLL:
                plan.status = "infeasible"
                plan.message = _stopped(ahead.who, ahead.why, done + max(ahead.reach, 0.0),
                                        angle, ax, ahead.who in never_lifted, held0.what)
                break
        # the tips' gaps: a turn that would bring two together stops before
        if ahead.apart < step and ahead.apart < MIN_ROLL:  # (a last roll may be shorter)
            plan.status, plan.message = "infeasible", _too_close(
                ahead.need, done + max(ahead.apart, 0.0), angle, ax, ahead.close)
            break
        step = min(step, ahead.apart)
        left = max_rolls - len(plan.rolls)
        if step * left < angle - done - 1e-9:  # each roll returns to this grasp: too short
            plan.status, plan.message = "infeasible", _too_few(
                step, left, angle - done, ahead,
                f"halved {retries} time(s) after {halved}" if step >= cap - 1e-12 and retries
                else "")
            break
        # where the plan stands before this roll, to go back to if what follows fails
        before = (len(plan.rolls), len(plan.phases), len(plan.steps), len(checks), t, done,
                  pose, q_now, set(never_lifted))
        target = axis_angle_rotation(ax, done + step) @ R0
        dur = max(1.0, seconds_per_radian * step)
        try:
            prob = _roll_problem(template, q_now, pose, target, centre, dur)
        except ProblemError as exc:  # its contacts on the turned object (not a ball's:
            # a contact rolled to where its chart cannot follow, an egg's end)
            plan.status = "failed" if plan.rolls else "infeasible"
            plan.message = (f"roll {len(plan.rolls)} ({math.degrees(done):.1f} deg on) could "
                            "not start: " + "; ".join(f"{f}: {r}" for f, r in exc.errors))
            break
        # the last roll, in its own start frame, is this one's warm start, primal-dual
        # point included: the grasp recurs, so it is (nearly) this very problem's optimum
        # (the last roll of every fingertip: one made while a fingertip swung is another
        # grasp's, :mod:`ocp.gait.overlap`; only rolls of every fingertip are in
        # ``roll_starts``, which the recurrence below is measured against)
        last_all = next((r for r in range(len(plan.rolls) - 1, -1, -1)
                         if r not in plan.carried), None)
        warm = plan.rolls[last_all] if last_all is not None and plan.rolls[last_all].ok \
            else None
        if warm is not None and not replace_all and roll_starts and max(
                float(np.abs(a - b).max()) for a, b in zip(roll_starts[-1], q_now,
                                                           strict=True)) > RECUR_TOL:
            warm = None  # a grasp of other contacts: the last roll's point is no start
        if warm is not None and last_all is not None \
                and (roll_objects.get(last_all, prob.object) != prob.object
                     or warm.chart_switch is not None):
            warm = None  # its contacts on the other chart (an egg's side chart, or two)
        multipliers = None
        if plan_start(template, pose) is None:  # its turned form is another solid: no
            # roll recurs (the egg's 90 deg gait about a short axis took 38 s warm-started
            # from the last roll, 21 s started cold), but the last roll's multipliers
            # start this one's from its own guess (the egg's: 6-10 iterations instead of
            # 23-37, ``MULTIPLIER_PUSH``)
            multipliers = warm.nlp_point if warm is not None else None
            warm = None
        if warm is not None and warm.stats is not None \
                and warm.stats.n_intervals > prob.n_intervals:
            # the last roll's certificate refined its grid: this one starts there, where
            # the last one's primal-dual point is (its coarse grid would be refined again)
            prob = prob.with_intervals(warm.stats.n_intervals)
        try:
            sol = planner.solve(prob, warm, reach_checked=True,  # (_roll_ahead)
                                multipliers=multipliers)
        except ProblemError as exc:  # the roll's own start (the gait's, not the request's)
            plan.status = "failed"
            plan.message = (f"roll {len(plan.rolls)} ({math.degrees(done):.1f} deg on) could "
                            "not start: " + "; ".join(f"{f}: {r}" for f, r in exc.errors))
            break
        r = len(plan.rolls)
        plan.rolls.append(sol)
        # (its chart: the planner may have taken the side chart, ``turns_off_chart``)
        roll_objects[r] = replace(prob.object, side_chart=sol.object_side_chart)
        roll_starts.append(q_now)
        plan.frames.append(roll_frame(template, pose))
        clock = RollClock.of(dur, roll_speed(sol, template, plan.nq, fastest_rolls)
                             if sol.ok else 1.0)
        plan.clocks.append(clock)
        plan.phases.append(GaitPhase("roll", t, t + clock.length, (True,) * nf, None, r))
        checks += [replace(c, name=f"roll{r}_{c.name}",
                           time=None if c.time is None else t + clock.tau_of(c.time))
                   for c in sol.certificate.checks]
        if not (sol.ok and sol.certificate.passed):
            plan.status = "failed" if plan.rolls[:-1] or sol.ok else "infeasible"
            plan.message = (f"roll {r} ({math.degrees(done):.1f} to "
                            f"{math.degrees(done + step):.1f} deg) was not certified: "
                            f"{sol.status}; " + "; ".join(sol.certificate.failures[:3]))
            if not held0.ball and retries < MAX_ROLL_RETRIES and step / 2 >= MIN_ROLL:
                # no rolled reach told this roll's length (a ball's): half as far
                halved = plan.message
                t, done, pose, q_now = _undo(plan, checks, never_lifted, before)
                cap, retries = step / 2, retries + 1
                continue
            break
        checks += _clock_checks(plan, r, template, t, q_now if r else None)
        q_end = np.split(plan.roll_joints(r, np.array([clock.length]))[0][0],
                         np.cumsum(plan.nq)[:-1])
        t += clock.length
        done += step
        pose = ObjectPose(tuple(quaternion_wxyz(plan.rotation(r, sol.object_rotation[-1]))),
                          tuple(sol.object_position[-1]))
        q_start = q_now
        q_now = tuple(q_end)
        if done >= angle - 1e-12:
            break
        if not replace_all:
            if q_land is None:
                q_land = q_home if landing == "home" else farthest_landings(
                    template, q_home, centre, rho, ax, roll_step)
            if overlap:  # the spent fingertips re-placed one at a time during the rolls
                waiting = None  # the last step, its checks waiting for its loading
                switched = False  # whether k is a fingertip another's roll would strand
                k: int | None = None
                rested: set[int] = set()  # re-placed at rest since the last roll
                while done < angle - 1e-12 and len(plan.rolls) < max_rolls:
                    if not switched:  # the spent one that reaches least
                        k = lift_next(*spent_reach(
                            template, q_now, np.asarray(pose.position, dtype=float), rho,
                            ax, min(cap, angle - done), never_lifted))
                        if k is None:
                            break
                    assert k is not None
                    res = _overlap_roll(plan, checks, template, planner, k, q_now, pose, R0,
                                        ax, done, min(cap, angle - done),
                                        seconds_per_radian, t, load, swing, hold_time,
                                        fastest_rolls, waiting, q_land, never_lifted,
                                        not switched)
                    if isinstance(res, tuple) and isinstance(res[0], str):
                        plan.overlap_misses.append(res[0])
                        k, switched = int(res[1]), True  # the stranded one first
                        continue
                    if isinstance(res, str):
                        plan.overlap_misses.append(res)
                        if k in rested:
                            break
                        # that fingertip alone re-placed with the ball still, and the
                        # others on (once each until a roll is made): not every spent one
                        if waiting is not None:  # loaded by itself
                            checks += _step_checks(plan, waiting, load, template)
                            waiting = None
                        alone = _replaced(plan, checks, template, q_land, q_start, q_now,
                                          pose, t, load, swing, hold_time, never_lifted,
                                          [k])
                        if alone is None:
                            break
                        rested.add(k)
                        (q_now, t), switched = alone, False
                        continue
                    rested.clear()
                    switched = False
                    if waiting is not None:  # loaded while the next one is unloaded
                        checks += _step_checks(plan, waiting, load, template)
                    waiting = len(plan.steps) - 1
                    q_start = q_now
                    q_now, t, done, pose = res
                if waiting is not None:  # loaded by itself
                    checks += _step_checks(plan, waiting, load, template)
                if done >= angle - 1e-12:
                    break
                if k is None or len(plan.rolls) >= max_rolls:
                    continue  # none spent: the next roll with every fingertip
            got = _replace_spent(plan, checks, template, q_land, q_start, q_now, pose, t,
                                 load, swing, hold_time, never_lifted, ax,
                                 min(cap, angle - done))
            if got is not None:
                q_now, t = got
                continue
        # every liftable fingertip: where it touched when this roll began (roll and
        # reset), or, when re-placing the spent ones failed, where the gait began (its
        # grasp, whose fingertips could all be lifted)
        q_now, t = _replace_fingers(plan, checks, template,
                                    q_start if replace_all else q_home, q_now, pose, t,
                                    load, swing, hold_time, never_lifted,
                                    nearer=None if replace_all else q_start)
        if plan.status != "solved":
            if retries < MAX_ROLL_RETRIES and step / 2 >= MIN_ROLL:
                # a fingertip found no swing back after this roll: roll half as far (a
                # shorter roll leaves the tips nearer where they land) from where it began,
                # and keep the shorter rolls (the grasp recurs)
                halved = plan.message  # why: the swing that was not found
                t, done, pose, q_now = _undo(plan, checks, never_lifted, before)
                cap, retries = step / 2, retries + 1
                continue
            break
    plan.turned = done
    plan.never_lifted = tuple(nm for nm in names if nm in never_lifted)
    if plan.status == "solved" and done < angle - 1e-9:
        plan.status, plan.message = "failed", f"{max_rolls} rolls did not make the turn"
    plan.certificate = Certificate.of(checks)
    plan.wall_time = time.perf_counter() - t_wall
    return plan
