"""One gait step: a fingertip re-placed on the still object while the others hold it
(docs/gait.md). Three phases: **unload** (nothing moves; the forces go along a straight
line from the grasp's to the forces without this fingertip, its own to zero), **swing**
(:mod:`ocp.gait.swing`; the others hold with the forces without it), **load** (nothing
moves; back to forces with every fingertip, the landed one's from zero)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from ocp.certify.certificate import Check, CheckKind
from ocp.gait.checks import hold_checks, swing_checks
from ocp.gait.hold import Hold, deep_hold_forces, hold_forces
from ocp.gait.swing import (
    MIN_SWING,
    MIN_TIP_GAP,
    NARROW_SHARE,
    SwingDrive,
    SwingPlan,
    SwingSpec,
    plan_swing,
)
from ocp.geometry.bodies import point_segment_distance, tip_body
from ocp.shapes.held import Held

__all__ = ["GaitStep", "contact_of", "driven_factors", "driven_overrun", "driven_passes",
           "find_swing", "fit_driven", "grasp_hold", "liftable", "replace_finger",
           "swing_spec", "within_damping"]

FloatArray = NDArray[np.float64]

#: Samples of each force ramp the certificate checks.
RAMP_SAMPLES = 11


def contact_of(finger: Any, q: FloatArray, centre: FloatArray, radius: float
               ) -> tuple[FloatArray, FloatArray]:
    """(point, outward normal) of a round fingertip's contact on a ball, palm frame: where
    the line of centres meets the ball (:meth:`~ocp.shapes.held.Held.contact`)."""
    return Held(centre, np.eye(3), radius).contact(finger, q)


def grasp_hold(fingers: tuple[Any, ...], qs: tuple[FloatArray, ...], which: list[int],
               held: Held) -> Hold:
    """The still object ``held`` held by the fingertips ``which`` of a grasp at joints
    ``qs``."""
    pn = [held.contact(fingers[i], qs[i]) for i in which]
    return Hold(np.array([p for p, _ in pn]), np.array([n for _, n in pn]), held.centre,
                held.rotation)


def liftable(fingers: Any, qs: Any, held: Held, load: FloatArray) -> tuple[bool, ...]:
    """Per fingertip of a grasp of the still object ``held`` (``fingers`` at the joints
    ``qs``, every tip touching it): whether the others hold it without that one
    (:func:`hold_forces` with the load parameters ``load``), so that it can be
    re-placed."""
    n = len(fingers)
    qs = tuple(np.asarray(q, dtype=float) for q in qs)
    return tuple(hold_forces(grasp_hold(tuple(fingers), qs, [i for i in range(n) if i != k],
                                        held), load, held.radius) is not None
                 for k in range(n))


@dataclass(frozen=True)
class GaitStep:
    """Fingertip ``finger`` re-placed: the holds and their forces [N] (palm frame, one row
    per contact in ``which``) before, during and after the swing, the swing, the phases'
    durations, and why not (``status`` ``"solved"``, ``"infeasible"``: the others cannot
    hold the object, or the swing was not found)."""

    finger: int
    status: str
    message: str
    swing: SwingPlan | None
    holds: tuple[Hold, ...] = ()
    forces: tuple[FloatArray, ...] = ()
    which: tuple[tuple[int, ...], ...] = ()
    unload: float = 0.2
    load_time: float = 0.2
    q_after: tuple[FloatArray, ...] = field(default_factory=tuple)
    #: the roll the swing is made during (:mod:`ocp.gait.overlap`: the other fingertips
    #: roll the object meanwhile, and that roll's plan holds it); None: the object is
    #: still and held by the others' hold (``holds[1]``, ``forces[1]``)
    during_roll: int | None = None
    #: every finger's joints before the step (None: those after it but the re-placed
    #: finger's, where its swing began: the others did not move)
    q_before: tuple[FloatArray, ...] | None = None
    #: the fingertip re-placed by the step before, loaded during this one's unloading (a
    #: hand-over: one ramp from the forces with that one lifted to those with this one
    #: lifted, the ball still; the step before then has no loading of its own,
    #: ``load_time`` 0); None: every fingertip is loaded when this one's unloading starts
    landing: int | None = None

    @property
    def ok(self) -> bool:
        return self.status == "solved"

    @property
    def duration(self) -> float:
        return self.unload + (self.swing.duration if self.swing else 0.0) + self.load_time

    @property
    def ramp_profile(self) -> Literal["linear", "smoothstep"]:
        """How its force ramps move in time (:meth:`ramp_share`): ``"smoothstep"`` for a
        step made during a roll, ``"linear"`` with the object still."""
        return "smoothstep" if self.during_roll is not None else "linear"

    def ramp_share(self, x: FloatArray) -> FloatArray:
        """How far along a force ramp (0 to 1, :meth:`ramp_forces`' ``s``) its forces are
        at the fractions ``x`` of its time. A step made during a roll (``during_roll``):
        smoothstep, so that the forces' rates are zero where the ramp starts and ends,
        continuous with the roll beside it (with a share linear in time the 180 deg turn
        about +z of ``benchmarks/gait_turns.py``'s overlap options lost the middle
        fingertip's contact in MuJoCo for 1 ms, by 76 nm, 16 ms after a ramp's end). A
        step with the object still: linear in time (smoothstep's steeper middle, 1.5
        times the rate, lost the index's contact for 7.5 ms at t = 94.8 s of the 90 deg
        gait on ``examples/own_hand.xml`` driven by the file's own servos,
        ``tests/test_gait_mjcf.py``, while every ramp was smoothstep: 9a8671a to this)."""
        x = np.clip(np.asarray(x, dtype=float), 0.0, 1.0)
        return x * x * (3.0 - 2.0 * x) if self.ramp_profile == "smoothstep" else x

    def ramp_forces(self, which: str, s: float) -> FloatArray:
        """The forces of every contact of the grasp (a row each, zeros for the lifted one)
        at the fraction ``s`` of the ``"unload"`` or ``"load"`` ramp (a step during a roll
        has the others' forces at the roll's start and at its end: ``forces[1]`` and
        ``forces[2]``), or of the ``"swing"`` (the others' hold, whatever ``s``)."""
        full_before, full_after = self.forces[0], self.forces[-1]
        n = len(self.which[0])
        k = self.which[0].index(self.finger)
        lifted = self.forces[1] if which == "unload" else self.forces[-2]
        mid = np.insert(lifted, k, 0.0, axis=0)
        assert len(mid) == n
        if which == "swing":
            return mid
        if which == "unload":
            return (1 - s) * full_before + s * mid
        return (1 - s) * mid + s * full_after

    def checks(self, label: str, t0: float, load: FloatArray, min_normal: float
               ) -> list[Check]:
        """The step's laws: the swing's (:func:`~ocp.gait.checks.swing_checks`), and at
        samples of the ramps and the swing the hold's with the forces there: every held
        contact at least ``min_normal`` [N], the lifting (landing) one at least the ramp's
        share of it, zero at the lift-off (touch-down)."""
        if not self.ok or self.swing is None:
            return [Check(f"gait_step_{label}", 1.0, 0.0, CheckKind.PHYSICS,
                          reason=self.message)]
        out: list[Check] = []
        n = len(self.which[0])
        k = self.which[0].index(self.finger)
        ts_swing = t0 + self.unload
        t_load = ts_swing + self.swing.duration
        for name, hold, start, dur in (("unload", self.holds[0], t0, self.unload),
                                       ("load", self.holds[-1], t_load, self.load_time)):
            for s in (np.linspace(0.0, 1.0, RAMP_SAMPLES) if dur > 0.0 else ()):
                F = self.ramp_forces(name, float(s))
                share = (1 - s) if name == "unload" else s
                fmin = np.full(n, min_normal)
                fmin[k] = share * min_normal
                if name == "unload" and self.landing is not None:  # handed over
                    fmin[self.which[0].index(self.landing)] = s * min_normal
                out += hold_checks(hold, F, load, fmin, f"{name}_{label}",
                                   float(start + s * dur))
            edge = self.ramp_forces(name, 1.0 if name == "unload" else 0.0)[k]
            out.append(Check(f"{'liftoff' if name == 'unload' else 'touchdown'}_force_"
                             f"{label}", float(np.linalg.norm(edge)), 1e-12,
                             CheckKind.PHYSICS, time=float(start + (dur if name == "unload"
                                                                    else 0.0))))
        if self.during_roll is None:  # (else the roll's own certificate holds it)
            out += hold_checks(self.holds[1], self.forces[1], load,
                               np.full(n - 1, min_normal), f"swing_{label}", ts_swing)
        out += swing_checks(self.swing, label, ts_swing)
        return out


#: A swing keeps clear of this many of the hand's links (the nearest to the ball, padded
#: with far-away ones): one swing NLP per finger, whatever the hand's pose.
SWING_OBSTACLES = 8

#: The share of an actuator's torque limit a hold's forces may ask of its joint (the rest
#: for the motion's own terms: damping, inertia, the set points' errors).
HOLD_TORQUE_SHARE = 0.9


@dataclass(frozen=True)
class TorqueLimits:
    """Per finger, the joint torques [N m] its actuators give (lower, upper arrays, already
    times :data:`HOLD_TORQUE_SHARE`), and gravity [m/s^2] (palm frame) for its links'
    weight."""

    lower: tuple[FloatArray, ...]
    upper: tuple[FloatArray, ...]
    gravity: FloatArray
    #: per finger, the joint rates [rad/s] whose damping alone its actuators can overcome
    #: within their share (infinite without damping or limits)
    rate: tuple[FloatArray, ...] = ()
    #: the share of the actuators' range ``lower`` and ``upper`` are
    share: float = 1.0
    #: per finger, its joints' actuators (:class:`~ocp.robots.actuation.Actuator`): where
    #: a control is limited, the torque it gives depends on the joint's position
    actuators: tuple[tuple[Any, ...], ...] = ()
    #: per finger, its joints' viscous damping [N m s/rad]
    damping: tuple[FloatArray, ...] = ()

    def key(self) -> bytes:
        return b"".join(np.ascontiguousarray(a, dtype=float).tobytes()
                        for a in (*self.lower, *self.upper, self.gravity, [self.share])) \
            + repr(self.actuators).encode()

    @property
    def damped(self) -> bool:
        """Whether any finger's joint has viscous damping."""
        return any(np.any(np.asarray(c) > 0) for c in self.damping)

    def damping_overrun(self, i: int, Q: FloatArray, V: FloatArray) -> float:
        """How many times more torque than finger ``i``'s actuators give (at each sample's
        joints ``Q``, :meth:`at`) its joints' damping asks at the rates ``V``, at worst
        (1: just enough; inf: a joint moving against an actuator that gives nothing that
        way there), and the rates over :attr:`rate` (the least of either side's range);
        0 without damping."""
        worst = float(np.max(np.abs(V) / self.rate[i])) if self.rate else 0.0
        if not self.damping:
            return worst
        c = np.asarray(self.damping[i], dtype=float)
        for q, v in zip(Q, V, strict=True):
            worst = max(worst, self.overrun(i, q, c * np.asarray(v, dtype=float)))
        return worst

    def rate_overrun(self, i: int, V: FloatArray) -> float:
        """How many times faster than its joints' damping lets the actuators' torque
        ranges drive them finger ``i``'s rates ``V`` (rows) go at worst: the same path is
        within those ranges in this many times its time (the control ranges, which depend
        on the joints, aside: :meth:`damping_overrun`); 0 without limited rates."""
        return float(np.max(np.abs(V) / self.rate[i], initial=0.0)) if self.rate else 0.0

    def drive(self, i: int) -> SwingDrive | None:
        """What finger ``i``'s actuators give its joints' damping, for its swing's NLP
        (:class:`~ocp.gait.swing.SwingDrive`, at this share of their range; a servo's
        control-range ends are affine in its joint: :meth:`~ocp.robots.actuation.
        Actuator.range_at`); None when no joint of it is damped."""
        if not self.damping or not np.any(np.asarray(self.damping[i]) > 0):
            return None
        nq = len(self.damping[i])
        slope, lo_end, hi_end = np.zeros(nq), np.full(nq, -np.inf), np.full(nq, np.inf)
        for j, a in enumerate(self.actuators[i] if self.actuators else ()):
            ends = a.control_ends()
            if ends is not None:
                slope[j], lo_end[j], hi_end[j] = (self.share * e for e in ends)
        return SwingDrive(np.asarray(self.damping[i], dtype=float), slope, lo_end, hi_end,
                          np.asarray(self.lower[i], dtype=float),
                          np.asarray(self.upper[i], dtype=float))

    def overrun(self, i: int, q: Any, need: FloatArray) -> float:
        """How many times more than finger ``i``'s actuators give at its joints ``q``
        (:meth:`at`) the joint torques ``need`` ask, at worst over its joints (1: just
        enough; inf: a torque against an actuator that gives nothing that way)."""
        lo, hi = self.at(i, q)
        with np.errstate(divide="ignore", invalid="ignore"):
            r = np.where(need > 0, need / hi, np.where(need < 0, need / lo, 0.0))
        r = np.where(np.isnan(r), 0.0, np.where(r < 0, np.inf, r))
        return float(r.max(initial=0.0))

    def at(self, i: int, q: Any) -> tuple[FloatArray, FloatArray]:
        """Finger ``i``'s joint torque bounds at its joints ``q``: ``lower`` and ``upper``,
        narrowed where an actuator's control range reaches less there (a position servo
        near the end of its range: :meth:`~ocp.robots.actuation.Actuator.range_at`)."""
        lo, hi = np.array(self.lower[i], dtype=float), np.array(self.upper[i], dtype=float)
        if self.actuators:
            for j, a in enumerate(self.actuators[i]):
                a_lo, a_hi = a.range_at(float(np.asarray(q, dtype=float)[j]))
                lo[j], hi[j] = max(lo[j], self.share * a_lo), min(hi[j], self.share * a_hi)
        return lo, hi

    def full(self) -> TorqueLimits:
        """The same limits at the actuators' whole range."""
        return replace(self, lower=tuple(a / self.share for a in self.lower),
                       upper=tuple(a / self.share for a in self.upper), share=1.0)


#: What a swing that kept its gaps and clearance only at its NLP's nodes keeps more [m]
#: when planned again, beyond what it lacked between them (:func:`between_nodes`).
WIDER_AT_NODES = 5e-5
#: How many times finer the grid of a swing planned again on one is, when kept wider at
#: its nodes it still dips between them.
FINER = 2
#: What a swing on the finer grid keeps more [m] at its nodes than it still lacked between
#: them (less than :data:`WIDER_AT_NODES`: the finer grid's dips are smaller).
FINER_MARGIN = 1e-5


def between_nodes(plan: SwingPlan) -> float:
    """How much [m] a swing lacks, at worst, of its clearance from the object and its gaps
    from the others' bodies between its NLP's nodes (the certificate's dense checks,
    :func:`~ocp.gait.checks.swing_checks`); 0 when it keeps them. The NLP keeps them at
    the nodes; a tip moving on a curve between them can dip: 0.985 mm against 1 mm, 2.97
    against 2.99 mm, measured."""
    worst = 0.0
    for c in swing_checks(plan, "between"):
        if c.lower_bound and not c.passed and (
                c.name.startswith("swing_tip_gap_") or c.name.startswith("swing_clearance_")):
            worst = max(worst, float(c.tolerance - c.value))
    return worst


def dense_enough(plan: SwingPlan) -> SwingPlan:
    """The swing ``plan``, or where it keeps its gaps or clearance at its NLP's nodes but
    not between them (:func:`between_nodes`; the certificate's dense checks would fail
    it) the first of these planned again that keeps them densely: kept wider at the
    nodes by the shortfall and :data:`WIDER_AT_NODES`; the same with the least gap kept
    from the neighbours (``MIN_TIP_GAP``, ``NARROW_SHARE`` of a close one's); on a grid
    :data:`FINER` times finer (its dips are smaller), and kept wider at its nodes by what
    it still lacks; on that grid with a quarter of a close neighbour's gap kept. Measured
    on the rounded cube turned 90 deg about the palm's normal (docs/gait.md): of the middle
    finger's three swings short by 18, 45 and 33 um, the first was kept wider, the third
    certified on the finer grid, the second only with a quarter of its neighbour's gap
    at its ends kept (the index 1.48 mm away: half of it, 0.74 mm, asked before, 0.73 mm
    kept between the finer grid's nodes)."""
    short = between_nodes(plan) if plan.ok else 0.0
    if short <= 0.0:
        return plan
    narrow = replace(plan.spec, tip_gap=MIN_TIP_GAP,
                     neighbour_share=min(plan.spec.neighbour_share, NARROW_SHARE))
    finer = replace(plan.spec, n_intervals=FINER * plan.spec.n_intervals,
                    lift_intervals=FINER * plan.spec.lift_intervals)
    attempts = [(plan.spec, short + WIDER_AT_NODES), (narrow, short + WIDER_AT_NODES),
                (finer, 0.0), (replace(narrow, n_intervals=finer.n_intervals,
                                       lift_intervals=finer.lift_intervals,
                                       neighbour_share=narrow.neighbour_share / 2), 0.0)]
    while attempts:
        alt, dip = attempts.pop(0)
        wider = plan_swing(replace(alt, dip=alt.dip + dip))
        left = between_nodes(wider) if wider.ok else math.inf
        if left <= 0.0:
            return wider
        if alt is finer and dip == 0.0 and left < short:
            # on the finer grid it dips less: kept that much wider at its nodes
            attempts.insert(0, (finer, left + FINER_MARGIN))
    return plan


#: A swing is slowed for its joints' damping at most this many times (a joint driven
#: against an actuator that gives nothing that way is left to the actuators' check).
MAX_SLOWDOWN = 10.0


def hold_fits(fingers: tuple[Any, ...], qs: tuple[FloatArray, ...], which: list[int],
              hold: Hold, limits: TorqueLimits | None) -> Any:
    """Whether forces of the hold (rows: its contacts, the fingertips ``which``) keep every
    finger's joint torques (``J^T f`` and its links' weight) within ``limits``; None
    without limits."""
    if limits is None:
        return None
    from ocp.solution import joint_torques

    bounds = {i: limits.at(i, qs[i]) for i in which}

    def fits(F: FloatArray) -> bool:
        for row, i in enumerate(which):
            tau = joint_torques(fingers[i], np.asarray(qs[i], dtype=float)[None],
                                hold.points[row][None], hold.normals[row][None],
                                F[row][None], np.zeros(1), limits.gravity)[0]
            lo, hi = bounds[i]
            if np.any(tau > hi) or np.any(tau < lo):
                return False
        return True

    return fits


def hold_torque_refusal(fingers: tuple[Any, ...], qs: tuple[FloatArray, ...],
                        which: list[int], hold: Hold, load: FloatArray, L: float,
                        limits: TorqueLimits, names: tuple[str, ...]) -> str:
    """Why no forces of the hold keep the fingers ``which`` within their actuators'
    torques ``limits`` (at their full range): the joint, the torque its least-force hold
    asks and the limit; "" when some narrowing of the cones (:data:`~ocp.gait.hold.
    HOLD_MARGINS`) fits."""
    from ocp.gait.hold import HOLD_MARGINS, narrowed_load
    from ocp.solution import joint_torques

    fits = hold_fits(fingers, qs, which, hold, limits)
    least: tuple[float, FloatArray | None] = (np.inf, None)
    for extra in HOLD_MARGINS:
        F = hold_forces(hold, narrowed_load(load, extra), L)
        if F is None:
            continue
        if fits(F):
            return ""
        top = float((-np.einsum("ij,ij->i", F, hold.normals)).max())
        if top < least[0]:
            least = (top, F)
    F = least[1]
    if F is None:
        return ""  # the hold itself fails: its own reason is given elsewhere
    worst = (0.0, "", 0.0, 0.0, 0.0)
    for row, i in enumerate(which):
        tau = joint_torques(fingers[i], np.asarray(qs[i], dtype=float)[None],
                            hold.points[row][None], hold.normals[row][None], F[row][None],
                            np.zeros(1), limits.gravity)[0]
        lo_i, hi_i = limits.at(i, qs[i])
        for j, v in enumerate(tau):
            lo, hi = float(lo_i[j]), float(hi_i[j])
            over = v / hi if v > 0 and hi > 0 else v / lo if v < 0 and lo < 0 else 0.0
            if over > worst[0]:
                worst = (over, fingers[i].joint_names[j], float(v), lo, hi)
    _, joint, v, lo, hi = worst
    return (f"no forces that hold the ball keep {', '.join(names[i] for i in which)} within "
            f"their actuators: joint {joint} needs {v:.3g} N m, its actuator gives "
            f"{lo:.3g}..{hi:.3g} N m")


def deep_forces(fingers: tuple[Any, ...], qs: tuple[FloatArray, ...], which: list[int],
          hold: Hold, load: FloatArray, L: float, limits: TorqueLimits | None
          ) -> FloatArray | None:
    """The hold's deep forces (:func:`~ocp.gait.hold.deep_hold_forces`) within the
    actuators' torques where the cones allow."""
    key = b"" if limits is None else limits.key() + b"".join(
        np.ascontiguousarray(qs[i], dtype=float).tobytes() for i in which)
    F, _ = deep_hold_forces(hold, load, L, hold_fits(fingers, qs, which, hold, limits), key)
    if F is not None and limits is not None and limits.share < 1.0:
        full = limits.full()  # none fits the share: the whole range, if any does
        if not hold_fits(fingers, qs, which, hold, full)(F):
            G = deep_forces(fingers, qs, which, hold, load, L, full)
            if G is not None and hold_fits(fingers, qs, which, hold, full)(G):
                F = G
    return F


def swing_spec(fingers: tuple[Any, ...], qs: tuple[FloatArray, ...], k: int,
               landing_normal: FloatArray, q_target: FloatArray, held: Held,
               swing: dict[str, Any] | None, warm: SwingPlan | None,
               names: tuple[str, ...], limits: TorqueLimits | None, obstacles: Any
               ) -> SwingSpec:
    """The swing of fingertip ``k`` of the still object ``held`` (every finger at ``qs``)
    to its landing (:func:`replace_finger`'s arguments): the other tips and the nearest
    links as its obstacles, the gaps and duration its last swing ``warm`` needed."""
    centre = held.centre
    rest = [i for i in range(len(fingers)) if i != k]
    landing_point = None if held.ball else \
        held.contact(fingers[k], np.asarray(q_target, dtype=float))[0]
    others = []
    for i in rest:
        R, p = fingers[i].fingertip_pose_pin(qs[i])
        a, b = tip_body(fingers[i]).placed(R, p)
        others.append((a, b, tip_body(fingers[i]).r))
    other_names = [names[i] for i in rest]
    if obstacles is not None:
        c = np.asarray(centre, dtype=float)
        links = sorted(obstacles(qs, k, c), key=lambda o: float(
            point_segment_distance(c, o[1][0], o[1][1])) - o[1][2])[:SWING_OBSTACLES]
        far = c + 1.0
        links += [("(none)", (far, far, 0.0))] * (SWING_OBSTACLES - len(links))
        others += [seg for _, seg in links]
        other_names += [n for n, _ in links]
    spec = SwingSpec(fingers[k], np.asarray(qs[k], dtype=float),
                     np.asarray(q_target, dtype=float), np.asarray(landing_normal, float),
                     np.asarray(centre, dtype=float), float(held.radius), tuple(others),
                     name=names[k], other_names=tuple(other_names),
                     held=None if held.ball else held,
                     landing_contact=None if held.ball else landing_point,
                     **(swing or {}))
    if warm is not None and warm.spec.tip_gap is not None:
        # its last swing needed it
        spec = replace(spec, tip_gap=warm.spec.tip_gap,
                       neighbour_share=warm.spec.neighbour_share)
    if warm is not None and limits is not None and warm.spec.duration > spec.duration:
        spec = replace(spec, duration=warm.spec.duration)  # its last swing was slowed
    return spec


def find_swing(spec: SwingSpec, warm: SwingPlan | None = None, narrow_any: bool = True
               ) -> SwingPlan:
    """The swing ``spec`` planned (warm-started from ``warm`` on a ball), with the
    neighbours' gaps narrowed where keeping them leaves no path, and dense enough between
    its nodes (:func:`dense_enough`). Without ``narrow_any`` the gaps are narrowed only
    where the swing not found breaks one (:attr:`~ocp.gait.swing.SwingPlan.gap_broken`;
    one that breaks only the ball's clearance or the joints' motion is not planned twice
    more)."""
    # (a turned object that is not a ball asks no swing again: started cold, the egg's
    # 90 deg gait took 31 s against 34 s from each finger's last swing, the same plan)
    plan = plan_swing(spec, warm if spec.held is None else None)
    narrowing = narrow_any or plan.gap_broken
    if narrowing and plan.status == "infeasible" and spec.tip_gap is None \
            and max(spec.required_gaps(), default=0.0) > MIN_TIP_GAP:
        # the clearance kept from the neighbours too left no path: keep the least gap
        narrow = plan_swing(replace(spec, tip_gap=MIN_TIP_GAP))
        if narrow.ok:
            plan = narrow
    if narrowing and plan.status == "infeasible" and spec.neighbour_share > NARROW_SHARE:
        # a neighbour close at the start or the landing: keep half of that gap
        closer = plan_swing(replace(spec, tip_gap=MIN_TIP_GAP, neighbour_share=NARROW_SHARE))
        if closer.ok:
            plan = closer
    return dense_enough(plan)


#: A swing made slower for its joints' damping is given this much more time than the
#: overrun it corrects (the rates between the checked samples).
DAMPING_SLACK = 1.05
#: A swing planned again with the actuators' rows against the damping is given this
#: share of the time its first path would need scaled to the torque ranges' rates: a
#: rest-to-rest swing of least jerk peaks at 1.875 times its mean rate, one with the rows
#: may run at the rate bound most of the way (0.6 x 1.875 = 1.125 times the time at the
#: bound). On the MJCF hand's 90 deg turn every swing was found at 0.5 (1.09-1.65 times
#: its own path's time at the bound), none slower than asked (docs/gait.md).
DRIVEN_PACE = 0.6


def within_damping(plan: SwingPlan, limits: TorqueLimits, k: int,
                   warm: SwingPlan | None = None) -> SwingPlan:
    """Finger ``k``'s swing ``plan`` (still bodies), or where it asks more of the
    actuators than their range gives against its joints' damping (at each sample's
    joints: a servo near the end of its control range gives less) a slower one: planned
    again with the actuators' rows in its NLP (:meth:`TorqueLimits.drive`), in
    :data:`DRIVEN_PACE` of the time the torque ranges alone need for its path
    (:meth:`TorqueLimits.rate_overrun`; never faster than it was asked), free to run at
    the rate bound and to move slowly where a servo gives little; else, as before those
    rows, the same swing planned in the time its worst sample needs (when that is less
    than :data:`MAX_SLOWDOWN` times its own). On the MJCF hand's 90 deg turn a swing whose start
    lay 3 mrad inside a servo's control range was made 7 times slower by that sample
    alone (8.4 s) where its rates needed 1.5 times (docs/gait.md). ``warm``: the
    finger's last swing (:func:`~ocp.gait.swing.plan_swing`'s warm start)."""
    over = limits.damping_overrun(k, plan.Q, plan.V)
    if over <= 1.0:
        return plan
    drive = limits.drive(k)
    if drive is not None:
        for factor in driven_factors(limits.rate_overrun(k, plan.V),
                                     min(over, MAX_SLOWDOWN)):
            driven = dense_enough(plan_swing(replace(plan.spec, drive=drive,
                                                     duration=plan.spec.duration * factor),
                                             warm))
            if driven_passes(driven):
                return fit_driven(driven, limits, k)
    if over >= MAX_SLOWDOWN:  # (a joint driven against an actuator that gives nothing
        return plan  # that way: left to the actuators' check, as before the rows)
    slower = plan_swing(replace(plan.spec, duration=plan.spec.duration * over * DAMPING_SLACK))
    return slower if slower.ok else plan


#: Samples per interval at which a swing planned with the actuators' rows (kept at its
#: nodes and midpoints) is measured against them.
DRIVEN_SAMPLES = 8


def driven_overrun(limits: TorqueLimits, k: int, plan: SwingPlan) -> float:
    """:meth:`TorqueLimits.damping_overrun` of finger ``k``'s swing ``plan`` between its
    nodes too (:data:`DRIVEN_SAMPLES` per interval): a swing with the actuators' rows
    meets them at its nodes and midpoints, and may ask a little more between (0.4 % on a
    test swing)."""
    ts = np.linspace(0.0, plan.duration, DRIVEN_SAMPLES * (len(plan.t) - 1) + 1)
    Q, V, _ = plan.sample(ts)
    return limits.damping_overrun(k, Q, V)


def driven_passes(plan: SwingPlan) -> bool:
    """Whether a swing planned with the actuators' rows was found and passes its own
    dense checks (:func:`~ocp.gait.checks.swing_checks`): one at its rate bound most of
    the way may dip between its nodes where a slower one does not (on the MJCF hand a
    landing that went 66 um into the ball and back, warm-started from the finger's last
    swing), and then the swing is planned as before the rows."""
    return plan.ok and all(c.passed for c in swing_checks(plan, "driven"))


def fit_driven(plan: SwingPlan, limits: TorqueLimits, k: int) -> SwingPlan:
    """Finger ``k``'s swing ``plan`` with the actuators' rows (still bodies), or the same
    path in the little more time it needs between its nodes (:func:`driven_overrun`)."""
    left = driven_overrun(limits, k, plan)
    return plan if left <= 1.0 else plan.scaled(left * (1.0 + 1e-6))


def driven_factors(pace: float, over: float) -> list[float]:
    """The times (factors of a swing's) it is planned in with the actuators' rows when
    its path asks ``pace`` times (:meth:`TorqueLimits.rate_overrun`) and ``over`` times
    (:meth:`TorqueLimits.damping_overrun`) more than they give: :data:`DRIVEN_PACE` of
    the pace (never faster than it was asked), then halfway (geometrically) to the time in
    which the same path would do (``over`` and :data:`DAMPING_SLACK`), which the rows
    admit, when that is 10 % longer."""
    first, last = max(1.0, DRIVEN_PACE * pace), over * DAMPING_SLACK
    return [first] + ([math.sqrt(first * last)] if last > 1.1 * first else [])


def replace_finger(fingers: tuple[Any, ...], qs: tuple[FloatArray, ...], k: int,
                   landing_normal: FloatArray, q_target: FloatArray, held: Held,
                   load: FloatArray,
                   swing: dict[str, Any] | None = None, hold_time: float = 0.2,
                   warm: SwingPlan | None = None,
                   names: tuple[str, ...] | None = None,
                   limits: TorqueLimits | None = None,
                   obstacles: Any = None) -> GaitStep:
    """Re-place fingertip ``k`` of a grasp of the still object ``held`` (``fingers`` at
    the joints ``qs``, every tip touching) at the contact whose outward normal is
    ``landing_normal`` (palm frame), its joints seeded by ``q_target``. ``load``: the
    load parameters (:func:`~ocp.transcription.values.load_parameters`); ``swing``: fields of the
    :class:`~ocp.gait.swing.SwingSpec` (duration, clearance, ...); ``hold_time``: the
    unloading's and the loading's duration [s]; ``warm``: this finger's previous swing
    (:func:`~ocp.gait.swing.plan_swing`'s warm start); ``names``: the fingers' names (for
    messages; default from their joints); ``limits``: the actuators' torques, which the
    holds' forces keep to where the cones allow; ``obstacles(qs, k, centre)``: the hand's
    links the swing keeps clear of as it does of the other tips (name, (a, b, r)),
    the nearest :data:`SWING_OBSTACLES` to the ball kept, padded with far-away ones.
    On an object that is not a ball it lands on the object's point nearest its cap at
    ``q_target``. A grasp whose other fingertips cannot hold the object is
    ``infeasible`` at once, naming the finger."""
    L = held.radius
    allf = list(range(len(fingers)))
    rest = [i for i in allf if i != k]
    before = grasp_hold(fingers, qs, allf, held)
    during = grasp_hold(fingers, qs, rest, held)
    if names is None:
        names = tuple(f.joint_names[0].rsplit("_", 1)[0] if f.joint_names else str(i)
                      for i, f in enumerate(fingers))
    name = names[k]
    F_before = deep_forces(fingers, qs, allf, before, load, L, limits)
    F_during = deep_forces(fingers, qs, rest, during, load, L, limits)
    if F_before is None or F_during is None:
        why = ("the grasp cannot hold the object" if F_before is None else
               f"the other fingertips cannot hold the object with {name} lifted (no forces "
               "inside their friction cones balance its weight)")
        return GaitStep(k, "infeasible", why, None)
    if limits is not None:  # the holds within the actuators' whole range, or no step
        full = limits.full()
        for which, hold, F, lifted in ((allf, before, F_before, ""),
                                       (rest, during, F_during, f" with {name} lifted")):
            if hold_fits(fingers, qs, which, hold, full)(F):
                continue
            why = hold_torque_refusal(fingers, qs, which, hold, load, L, full, names)
            if why:
                return GaitStep(k, "infeasible", f"the hold{lifted}: {why}", None)
    spec = swing_spec(fingers, qs, k, landing_normal, q_target, held, swing, warm, names,
                      limits, obstacles)
    plan = None
    if warm is not None and warm.spec.drive is not None and limits is not None:
        # this finger's last swing needed the actuators' rows: this one with them at once,
        # in that swing's time (the grasp recurs; one swing NLP instead of two), else as
        # every swing
        again = find_swing(replace(spec, drive=limits.drive(k),
                                   duration=max(spec.duration, warm.spec.duration)), warm)
        plan = fit_driven(again, limits, k) if driven_passes(again) else None
    if plan is None:
        plan = find_swing(spec, warm)
        if plan.ok and limits is not None and limits.rate:
            plan = within_damping(plan, limits, k, warm)
    if plan.ok and plan.spec.fastest:  # the same path as fast as the limits allow
        factor = max(plan.fastest_factor(), MIN_SWING / plan.duration)
        if limits is not None and limits.rate:
            factor = max(factor, limits.damping_overrun(k, plan.Q, plan.V))
        if factor < 1.0:
            plan = plan.scaled(factor)
    if not plan.ok:
        return GaitStep(k, plan.status, plan.message, plan)
    q_after = tuple(plan.Q[-1] if i == k else np.asarray(qs[i], dtype=float) for i in allf)
    after = grasp_hold(fingers, q_after, allf, held)
    F_after = deep_forces(fingers, q_after, allf, after, load, L, limits)
    if F_after is None:
        return GaitStep(k, "infeasible", f"the grasp with {name} landed cannot hold the "
                                         "object", plan)
    return GaitStep(k, "solved", "", plan, (before, during, after),
                    (F_before, F_during, F_after), (tuple(allf), tuple(rest), tuple(allf)),
                    hold_time, hold_time, q_after)
