"""A grasp as data: the object, an optional flat palm it rests on (:class:`Palm`), the
flat fingertips holding it (:class:`Fingertip`), the horizon and what to achieve
(:class:`ManipulationProblem`). The paper's ball on the palm (the palm alone), its
section 3 (one finger pressing the ball on the palm), its section 4 (two fingers holding
the ball in the air) and three or more fingers are the same type with different data.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ocp.certify.certificate import GRASP_TOLERANCES, PALM_TOLERANCES, TolerancePolicy
from ocp.geometry.rotations import log_rotation
from ocp.geometry.surfaces import rotation_from_vector
from ocp.robots.couplings import coupled_step
from ocp.robots.first_grasp import ObjectGeometry, onto_surface
from ocp.robots.grasp_reach import at_tendon_bounds
from ocp.spec.chart_switch import ChartSwitchSpec, switch_errors
from ocp.spec.motion import DesiredMotion, ObjectPose, Tracking
from ocp.spec.phases import ContactPhase, phase_errors, phase_intervals
from ocp.spec.problem import (
    DEFAULT_FINGER_CHART_ROTATION,
    DEFAULT_MAX_JOINT_ACCELERATION,
    DEFAULT_RAMP_FRACTION,
    MAX_POSITION,
    BallOnPalmProblem,
    ForceSpec,
    ObjectSpec,
    ProblemError,
    SolverOptions,
    ViaPoint,
    beyond_u_limit,
    goal_errors,
    joint_acceleration_errors,
)
from ocp.spec.reference import Reference

__all__ = ["Fingertip", "ManipulationProblem", "Palm", "contact_chart_for_pad",
           "contact_charts", "contact_from_joints", "fingertip_errors", "fingertips_from_joints",
           "fingertips_on_charts",
           "hand_fingertips", "support_goal_errors"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Palm:
    """A flat palm (the z = 0 plane of the palm frame) carrying the object.

    ``initial`` are the palm contact coordinates (x, y, u, v, psi) at t = 0 in the
    object's chart (``ObjectSpec.chart_rotation``); ``goal`` and ``via_points`` fix any
    subsets of them at the end and at interior times (as in the ball-on-palm problem).
    """

    initial: tuple[float, float, float, float, float]
    goal: Mapping[str, float] = field(default_factory=dict)
    via_points: tuple[ViaPoint, ...] = ()
    palm_half_extent: float = 0.5
    max_contact_speed: float = 1.0


@dataclass(frozen=True)
class Fingertip:
    """A finger whose flat pad touches the object.

    ``initial`` = (x_f, y_f, u_f, v_f, psi_f) at t = 0: pad point [m], object point [rad]
    in this contact's chart patch (rotated in the object frame by ``chart_rotation``, a
    rotation vector [rad]; choose it so that the contact stays away from the patch's
    poles), contact angle [rad]. ``q_seed`` seeds the inverse kinematics of the initial
    grasp (default: the paper's initial angles).
    """

    finger: Any  # ocp.robots.finger.FingerModel
    initial: tuple[float, float, float, float, float]
    chart_rotation: tuple[float, float, float] = DEFAULT_FINGER_CHART_ROTATION
    q_seed: tuple[float, ...] | None = None
    name: str = ""


def fingertip_errors(name: str, tip: Fingertip, obj: ObjectSpec, pad_margin: float,
                     pole_margin: float) -> list[tuple[str, str]]:
    """Why a fingertip's initial contact is invalid, as (field, reason) under ``name``:
    its chart patch, its coordinates, the pad (less ``pad_margin``) and the patch's poles."""
    errs: list[tuple[str, str]] = []
    if len(tip.chart_rotation) != 3 or not all(map(math.isfinite, tip.chart_rotation)):
        errs.append((f"{name}.chart_rotation", "must be 3 finite numbers "
                                               "(rotation vector, rad)"))
    elif not obj.errors():
        bad = obj.surface.chart_rotation_error(rotation_from_vector(tip.chart_rotation),
                                               obj.params)
        if bad is not None:
            errs.append((f"{name}.chart_rotation", bad))
        elif tip.finger.tip_surface.surface.developable and obj.surface.developable:
            errs.append((name, f"a flat pad touches a {obj.shape} along a line, not at a "
                               "point as the planner's contacts do: use round fingertips"))
    if len(tip.initial) != 5 or not all(map(math.isfinite, tip.initial)):
        return [*errs, (f"{name}.initial", "must be 5 finite numbers "
                                           "(x_f, y_f, u_f, v_f, psi_f)")]
    surface = tip.finger.tip_surface
    if surface.kind == "pad":
        half = float(tip.finger.pad_half_size) - pad_margin
        for k, coord in ((0, "x_f"), (1, "y_f")):
            if abs(tip.initial[k]) > half:
                errs.append((f"{name}.initial.{coord}",
                             f"|{coord}| = {abs(tip.initial[k]):.4g} m leaves the pad "
                             f"(half size {tip.finger.pad_half_size} m less {pad_margin} m "
                             f"margin) by {abs(tip.initial[k]) - half:.4g} m"))
    else:
        bounds = surface.bounds(pad_margin, pole_margin)
        poles = ("the tip chart's pole limit (place the tip frame, a capsule's `side`, so "
                 "that the contact starts near the chart's equator)")
        why = {"capsule": "the capsule's cap (0 <= v <= pi in the tip's chart, less the "
                          "margin; its cylindrical side is not a contact surface here) and "
                          + poles, "sphere": poles, "spheroid": poles}
        for k, coord in ((0, "x_f"), (1, "y_f")):
            lo, hi = bounds[k]
            if not lo <= tip.initial[k] <= hi:
                errs.append((f"{name}.initial.{coord}",
                             f"{coord} = {tip.initial[k]:.4f} rad (the {surface.kind} tip's "
                             f"chart coordinate) is outside [{lo:.4f}, {hi:.4f}]: "
                             f"{why[surface.kind]}"))
    valid = not obj.errors()
    u_lim = obj.u_limit(pole_margin) if valid else math.pi / 2
    if abs(tip.initial[2]) > u_lim:
        errs.append((f"{name}.initial.u_f",
                     beyond_u_limit(obj, tip.initial[2], u_lim, f"{name}.chart_rotation")
                     if valid else f"|u_f| = {abs(tip.initial[2]):.4f} rad is beyond the "
                                   f"chart's poles {u_lim:.4f} rad"))
    return errs


@dataclass(frozen=True)
class ManipulationProblem:
    """A grasp (object, optional palm, fingertips), a horizon and what to achieve.

    Without a palm the object's pose at t = 0 is ``initial_pose`` and what it should do is
    ``motion`` (tracked with ``tracking``). With a palm the object's pose comes from the
    palm contact; the palm's goal and via-points and/or a ``motion`` say where it goes.
    """

    object: ObjectSpec
    fingers: tuple[Fingertip, ...]
    duration: float
    palm: Palm | None = None
    initial_pose: ObjectPose | None = None
    motion: DesiredMotion | None = None
    tracking: Tracking = field(default_factory=Tracking)
    mu: float = 0.5
    #: Weights of the objective terms (dimensionless, scaled): the object's own motion
    #: (the palm contact velocity, or the free object's twist), the fingertip contacts'
    #: motion over the object, the joint rates, and the grasp-angle epigraph.
    object_effort_weight: float = 1.0
    finger_effort_weight: float = 0.01
    joint_effort_weight: float = 0.01
    grasp_weight: float = 100.0
    pad_margin: float = 0.002  # m kept between a contact and its pad's edge
    n_intervals: int = 50
    pole_margin: float = math.radians(15.0)
    max_object_speed: float = 1.0  # m/s, each component of a free object's velocity
    max_object_rate: float = 20.0  # rad/s, each component of a free object's angular rate
    max_refinements: int = 2
    options: SolverOptions = field(default_factory=SolverOptions)
    #: How strictly the certificate checks the plan (:mod:`ocp.solve.certify`).
    tolerances: TolerancePolicy = GRASP_TOLERANCES
    #: Plan the contact forces (the object's load, the grip; docs/forces.md); None (the
    #: default): a kinematic plan, as before.
    forces: ForceSpec | None = None
    #: The plan's timing (docs/timing.md, :data:`~ocp.spec.problem.TIMINGS`): ``"smooth"``
    #: starts and ends at rest, every velocity continuous, each joint's acceleration within
    #: ``max_joint_acceleration`` [rad/s^2]; ``"paper"`` the paper's piecewise inputs.
    timing: str = "smooth"
    max_joint_acceleration: float = DEFAULT_MAX_JOINT_ACCELERATION
    #: The smooth plan's ramps' time constant [s] (None: :data:`DEFAULT_RAMP_FRACTION` of
    #: the duration): the objective weighs each input's rate of change by its square
    #: (docs/timing.md).
    ramp_time: float | None = None
    #: The input at t = 0 in the grasp's input layout (physical units): a plan that starts
    #: moving, re-planned from a measured state (:func:`ocp.solve.attempt.attempt`'s
    #: ``u0``). None: at rest with the smooth timing, free with the paper's.
    initial_input: tuple[float, ...] | None = None
    #: A trajectory to track (:class:`~ocp.spec.reference.Reference`: states and inputs
    #: over the horizon, weighted terms of the objective): the window of a longer plan
    #: that a controller re-solves (:mod:`ocp.control`); such a plan ends moving (its last
    #: input free, tracked). None: no such terms.
    reference: Reference | None = field(default=None, compare=False, repr=False)
    #: The motion's contact phases (:mod:`ocp.spec.phases`): which fingertips touch the
    #: object when. None: one phase, every fingertip touching throughout.
    phases: tuple[ContactPhase, ...] | None = None
    #: Intervals per segment between the palm's via-points, kept as they were by a
    #: re-plan's :meth:`remaining` (so that the shrinking horizon keeps its NLP's
    #: structure); None: in proportion to the segments' durations.
    segment_counts: tuple[int, ...] | None = None
    #: The hand's collision geoms as MuJoCo collides them, the fingertips in
    #: :attr:`fingers`' order (:class:`ocp.robots.collision.HandCollision`): the
    #: certificate keeps every other pair :data:`~ocp.robots.collision.LINK_CLEARANCE`
    #: apart. None: only the fingertips' own checks (a URDF hand, fingers of their own).
    collision: Any = field(default=None, compare=False, repr=False)
    #: The hand's actuators (:mod:`ocp.robots.actuation`: an object with ``actuators(joint
    #: names)``): a gait's holds keep their joints' torques within them where the cones
    #: allow. None: no limits known.
    actuation: Any = field(default=None, compare=False, repr=False)
    #: The fingertips' contacts change chart at a time of the motion
    #: (:class:`~ocp.spec.chart_switch.ChartSwitchSpec`: an egg's contact rolling from
    #: around its equator up to an end); None: the problem's charts throughout.
    chart_switch: ChartSwitchSpec | None = None

    @property
    def ramp_time_fraction(self) -> float:
        """The ramps' time constant over the duration."""
        if self.ramp_time is None:
            return DEFAULT_RAMP_FRACTION
        return self.ramp_time / self.duration

    @property
    def smooth(self) -> bool:
        return self.timing == "smooth"

    @property
    def n_contacts(self) -> int:
        return len(self.fingers) + (self.palm is not None)

    def palm_problem(self) -> BallOnPalmProblem:
        """The ball-on-palm problem of the palm contact (its grid, goals, limits)."""
        assert self.palm is not None
        pm = self.palm
        return BallOnPalmProblem(
            object=self.object, initial=pm.initial, goal=pm.goal, duration=self.duration,
            via_points=pm.via_points, n_intervals=self.n_intervals,
            pole_margin=self.pole_margin, max_contact_speed=pm.max_contact_speed,
            palm_half_extent=pm.palm_half_extent, max_refinements=self.max_refinements,
            options=self.options, timing=self.timing, ramp_time=self.ramp_time)

    def segments(self) -> tuple[tuple[int, ...], FloatArray]:
        """(intervals per segment, segment boundary times): via-points split the grid."""
        if self.palm is not None:
            base = self.palm_problem()
            times = base.segment_times
            if self.segment_counts is not None and len(self.segment_counts) == times.size - 1 \
                    and sum(self.segment_counts) == self.n_intervals:
                return tuple(self.segment_counts), times
            return base.segment_intervals(), times
        return (self.n_intervals,), np.array([0.0, self.duration])

    def schedule(self) -> tuple[tuple[int, tuple[bool, ...]], ...] | None:
        """The phases on the grid: (intervals, touching) per phase; None for one phase
        with every fingertip touching (the transcription's default)."""
        if self.phases is None or (len(self.phases) == 1 and all(self.phases[0].touching)):
            return None
        counts = phase_intervals(self.phases, self.n_intervals)
        return tuple((k, tuple(bool(t) for t in ph.touching))
                     for k, ph in zip(counts, self.phases, strict=True))

    def remaining(self, dt: float) -> ManipulationProblem:
        """The rest of this problem ``dt`` seconds in (a shrinking horizon: re-planning
        part-way): the duration shortened, the desired motion followed from its pose at
        ``dt`` on (its ``t0``), the palm's via-points still ahead moved back by ``dt``
        (those passed dropped) with the intervals each segment had (a passed segment's go
        to the segment under way: the NLP's structure changes only when a via-point is
        passed), the contact phases still ahead; the same grid size. Its
        initial state is the measured one (:func:`ocp.solve.attempt.attempt`'s ``x0``)."""
        if not (math.isfinite(dt) and 0.0 < dt < self.duration):
            raise ValueError(f"dt must be in (0, {self.duration}) s, got {dt}")
        eps = 1e-9 * self.duration
        motion = None if self.motion is None else \
            replace(self.motion, t0=self.motion.t0 + dt)
        palm = self.palm
        counts = None
        if palm is not None:  # the segments ahead keep their intervals; the passed ones'
            now, bounds = self.segments()  # go to the segment under way
            ahead = [k for k in range(len(now)) if bounds[k + 1] > dt + eps]
            passed = sum(now[:ahead[0]]) if ahead else 0
            counts = tuple(now[k] + (passed if k == ahead[0] else 0) for k in ahead)
            palm = replace(palm, via_points=tuple(
                replace(vp, time=vp.time - dt) for vp in palm.via_points if vp.time > dt + eps))
        phases = self.phases
        if phases is not None:
            kept, t = [], 0.0
            for ph in phases:
                end = t + ph.duration
                if end > dt + eps:
                    kept.append(replace(ph, duration=end - max(t, dt)))
                t = end
            phases = tuple(kept)
        return replace(self, duration=self.duration - dt, motion=motion, palm=palm,
                       phases=phases, segment_counts=counts)

    def with_intervals(self, n: int) -> ManipulationProblem:
        return replace(self, n_intervals=n, segment_counts=None)

    def palm_only(self) -> ManipulationProblem:
        """The object on this problem's palm alone (its grid, goals, limits and solver
        options; the palm's tolerances): its plan seeds a finger grasp's initial guess
        (from rest: a moving start's input is the grasp's, its phases the fingertips')."""
        return replace(self, fingers=(), motion=None, forces=None, tracking=Tracking(),
                       object_effort_weight=1.0, tolerances=PALM_TOLERANCES,
                       initial_input=None, reference=None, phases=None,
                       collision=None, actuation=None)

    def errors(self) -> list[tuple[str, str]]:
        """Every reason the problem is invalid, as (field, reason)."""
        errs: list[tuple[str, str]] = []
        palm_fields = ("initial", "goal", "via_points", "palm_half_extent",
                       "max_contact_speed")
        if self.palm is not None:
            for name, why in self.palm_problem().errors():
                if name == "goal" and (self.motion is not None or self.reference is not None) \
                        and "nothing to plan" in why:
                    continue  # the motion (the reference) says what to do
                head = name.split(".")[0].split("[")[0]
                errs.append((f"palm.{name}" if head in palm_fields else name, why))
        else:
            # the object, grid and solver fields, checked by the palm problem's own rules
            errs += BallOnPalmProblem(self.object, (0.0, 0.0, 0.0, 0.0, 0.0), {"x": 0.0},
                                      self.duration, n_intervals=self.n_intervals,
                                      pole_margin=self.pole_margin,
                                      max_refinements=self.max_refinements,
                                      options=self.options, timing=self.timing,
                                      ramp_time=self.ramp_time).setting_errors()
            if self.initial_pose is None:
                errs.append(("initial_pose", "required when no palm carries the object"))
            else:
                errs += self.initial_pose.errors("initial_pose")
            if self.motion is None and self.reference is None:
                errs.append(("motion", "required when no palm carries the object: what "
                                       "should the object do?"))
        if self.motion is not None:
            errs += self.motion.errors("motion", self.duration)
        if self.palm is None and self.n_contacts < 2:
            errs.append(("fingers", "without a palm, a grasp needs at least two contacts "
                                    f"(two fingers); got {self.n_contacts}"))
        if not (math.isfinite(self.mu) and 0.0 < self.mu <= 10.0):
            errs.append(("mu", f"must be in (0, 10], got {self.mu}"))
        for name in ("object_effort_weight", "finger_effort_weight", "joint_effort_weight",
                     "grasp_weight"):
            value = getattr(self, name)
            if not (math.isfinite(value) and 0.0 <= value <= 1e6):
                errs.append((name, f"must be in [0, 1e6], got {value}"))
        tr = self.tracking
        for name in ("position_weight", "orientation_weight"):
            value = getattr(tr, name)
            if not (math.isfinite(value) and 0.0 <= value <= 1e8):
                errs.append((f"tracking.{name}", f"must be in [0, 1e8], got {value}"))
        for name, hi in (("position_tolerance", MAX_POSITION),
                         ("orientation_tolerance", math.pi)):
            value = getattr(tr, name)
            if value is not None and not (math.isfinite(value) and 0.0 < value <= hi):
                errs.append((f"tracking.{name}", f"must be in (0, {hi:.4g}], got {value}"))
        if (tr.position_tolerance is not None or tr.orientation_tolerance is not None) \
                and self.motion is None:
            errs.append(("tracking", "tolerances given but no motion to track"))
        for name in ("max_object_speed", "max_object_rate"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                errs.append((name, f"must be > 0, got {value}"))
        for i, c in enumerate(self.fingers):
            name = f"fingers[{i}]"
            errs += fingertip_errors(name, c, self.object, self.pad_margin, self.pole_margin)
            if c.q_seed is not None and len(c.q_seed) != c.finger.nq:
                errs.append((f"{name}.q_seed",
                             f"must have {c.finger.nq} joint angles, got {len(c.q_seed)}"))
        errs += joint_acceleration_errors(self.max_joint_acceleration)
        if self.phases is not None:
            errs += phase_errors(self.phases, self.duration, len(self.fingers),
                                 self.n_intervals, self.palm is not None,
                                 len(self.palm.via_points) if self.palm else 0)
            if len(self.phases) > 1 and not any(e[0].startswith("phases") for e in errs):
                errs.append(("phases", "plans with more than one contact phase (a fingertip "
                                       "lifted) are not planned yet: the swing's initial "
                                       "guess, clearance and certificate come with finger "
                                       "gaiting; the NLP of such a schedule is built by "
                                       "ManipulationPlanner.build"))
        if self.forces is not None:
            errs += self.forces.errors("forces", self.mu)
            if not self.fingers:
                errs.append(("forces", "planned forces need a fingertip contact"))
        errs += switch_errors(self)
        return errs

    def validate(self) -> None:
        errs = self.errors()
        if errs:
            raise ProblemError(errs)


def contact_chart_for_pad(obj: ObjectSpec, pose: ObjectPose, pad_rotation: ArrayLike
                          ) -> tuple[float, float, float]:
    """The chart rotation (rotation vector [rad]) of a fingertip contact's patch that puts
    patch point (u, v) = (0, 0) with psi = 0 under a pad of rotation ``pad_rotation`` (palm
    frame; its +z is the pad's outward normal, facing the object).

    With it, the fingertip's initial contact coordinates (0, 0, 0, 0, 0) mean "the pad's
    centre touches the object where the pad's normal points, the pad turned as given": the
    usual way to state a grasp from the fingers' pad poses. The contact then sits on the
    patch's equator, as far from its poles as it can be.
    """
    from ocp.geometry.contact import R_contact

    shape = np.asarray(obj.params, dtype=float)
    _, Rg, _, _, _ = obj.surface.geometry([0.0, 0.0], shape)
    R_of = pose.rotation.T @ np.asarray(pad_rotation, dtype=float)
    Rc = R_of @ np.asarray(R_contact(0.0)).T @ np.asarray(Rg).T
    return tuple(float(c) for c in log_rotation(Rc))  # type: ignore[return-value]


def hand_fingertips(hand: Any, pose: ObjectPose | None = None,
                    obj: ObjectSpec | None = None) -> tuple[Fingertip, ...]:
    """Fingertips of a built-in hand (:func:`ocp.robots.hands.load_hand`) in its nominal grasp of a
    ball at ``pose`` (default: unrotated, at the hand's nominal position): each pad's centre
    on the ball where the pad's normal points (contact coordinates all zero, charts from
    :func:`contact_chart_for_pad`), the IK seeded with the hand's nominal joint angles."""
    from ocp.robots.hands import grasp_poses

    pose = pose or ObjectPose(position=tuple(hand.nominal_object_position))
    obj = obj or ObjectSpec("sphere", (hand.nominal_radius,))
    pads = grasp_poses(hand, pose.position, float(max(obj.dimensions)), pose.rotation)
    seeds = hand.nominal_q or (None,) * hand.n_fingers
    return tuple(
        Fingertip(finger, (0.0, 0.0, 0.0, 0.0, 0.0), contact_chart_for_pad(obj, pose, R),
                  q_seed=seed, name=f"f{k + 1}")
        for k, (finger, (R, _), seed) in enumerate(zip(hand.fingers, pads, seeds,
                                                       strict=True)))


def contact_charts(problem: ManipulationProblem) -> list[FloatArray]:
    """The chart rotation of every point contact (the palm first, then each fingertip)."""
    out = [rotation_from_vector(problem.object.chart_rotation)] if problem.palm else []
    return out + [rotation_from_vector(c.chart_rotation) for c in problem.fingers]


def support_goal_errors(problem: ManipulationProblem, X: FloatArray, ends: list[int]
                        ) -> dict[str, float]:
    """Error of every goal and via-point coordinate of the support contact (``palm.goal.x``,
    ...) at the segment end nodes ``ends`` of the states X (m or wrapped rad)."""
    if problem.palm is None:
        return {}
    out = goal_errors(problem.palm_problem(), X, ends)
    return {f"palm.{k}": v for k, v in out.items()}


#: A fingertip this far from the object at the given joint angles is refused [m]; nearer,
#: the joints are moved the least to close the gap.
MAX_INITIAL_GAP = 2e-3


def _onto_ball(finger: Any, q: FloatArray, c_obj: FloatArray, rho: float
               ) -> tuple[FloatArray, float]:
    """(joints, gap [m] at ``q``) of a round tip and the ball of radius ``rho`` [m] centred
    at ``c_obj``: a gap within :data:`MAX_INITIAL_GAP` closed by the least joint motion
    (Gauss-Newton along the line of centres; another shape's:
    :func:`~ocp.robots.first_grasp.onto_surface`); ``q`` as it is beyond."""
    tip = finger.tip_surface
    r = tip.params[0]

    def distance(centre: FloatArray) -> tuple[float, FloatArray]:
        d = c_obj - centre
        return float(np.linalg.norm(d)) - r - rho, -(d / np.linalg.norm(d))

    R_l, p_l = finger.fingertip_pose_pin(q)
    centre = p_l + R_l @ tip.p
    gap0, _ = distance(centre)
    if abs(gap0) <= MAX_INITIAL_GAP:
        for _ in range(20):
            gap, n = distance(centre)
            if abs(gap) <= 1e-13:
                break
            J = finger.frame_jacobian_pin(q)
            Jc = J[:3] - np.cross(R_l @ tip.p, J[3:].T).T  # the centre's velocity
            g = n @ Jc  # d gap / dq
            q = coupled_step(finger, q, -gap * g / max(float(g @ g), 1e-18))
            R_l, p_l = finger.fingertip_pose_pin(q)
            centre = p_l + R_l @ tip.p
    return q, gap0


def contact_from_joints(finger: Any, q: ArrayLike, obj: Any, pose: Any,
                        pole_margin: float = ManipulationProblem.pole_margin,
                        advise: bool = True
                        ) -> tuple[tuple[float, ...], tuple[float, float, float], float]:
    """The contact coordinates of a round fingertip (a sphere or a capsule's cap) on a
    closed convex object where the joints ``q`` put it: (initial (a, b, u, v, psi), the
    rotation vector of the object chart patch they are in, the gap [m]: the tip's distance
    from the object at ``q``, negative when they overlap). A gap within
    :data:`MAX_INITIAL_GAP` is closed first by the least joint motion, so that the
    coordinates are where joints near ``q`` put the tip exactly (the inverse kinematics of
    the initial grasp, a 6-D pose, then has a solution for a finger of fewer than 6
    joints); beyond it they are those of the nearest points, for the caller to refuse.

    On a ball the contact is where the line of centres meets the tip, in the patch that
    puts it at (u, v, psi) = (0, 0, 0) (:func:`contact_chart_for_pad`). On any other
    object it is the object's point nearest to the tip's centre
    (:func:`nearest_surface_point`), in the object's own patch (``obj.chart_rotation``),
    or, beyond half its bound, in the patch of the shape's symmetries that keeps it
    farthest from the poles (:func:`_pole_clear_symmetry`), psi between the two contact
    frames; ValueError when it lies beyond the chart's bound ``obj.u_limit(pole_margin)``
    (saying how a request's grasp could avoid it, unless ``advise`` is false: a gait's
    roll, whose joints no request gave)."""
    tip = finger.tip_surface
    if tip.kind not in ("sphere", "capsule"):
        raise ValueError("contacts from joint angles need a sphere or capsule tip")
    r = tip.params[0]
    c_obj = np.asarray(pose.position, dtype=float)
    qa = np.asarray(q, dtype=float)
    if obj.shape == "sphere":
        qa, gap0 = _onto_ball(finger, qa, c_obj, float(obj.dimensions[0]))
        R_l, p_l = finger.fingertip_pose_pin(qa)
        R_t = R_l @ tip.R
        d = c_obj - (p_l + R_l @ tip.p)
        dist = float(np.linalg.norm(d))
        ab = tip.surface.inverse(R_t.T @ (d / dist), (1.0,))
        _, G, _, _, _ = tip.surface.geometry(ab, (r,))
        chart = contact_chart_for_pad(obj, pose, R_t @ np.asarray(G))
        return (float(ab[0]), float(ab[1]), 0.0, 0.0, 0.0), chart, gap0
    return _contact_on_surface(finger, qa, obj, pose, pole_margin, advise)


def _contact_on_surface(finger: Any, q: FloatArray, obj: Any, pose: Any, pole_margin: float,
                        advise: bool = True
                        ) -> tuple[tuple[float, ...], tuple[float, float, float], float]:
    """:func:`contact_from_joints` on an object other than a ball."""
    if obj.errors():
        raise ValueError("contacts from joint angles need a valid object: "
                         + "; ".join(f"{f}: {why}" for f, why in obj.errors()))
    surface, dims = obj.surface, obj.params  # the chart's parameters
    rotvec = tuple(float(x) for x in obj.chart_rotation)
    R_c = rotation_from_vector(rotvec)
    bad = surface.chart_rotation_error(R_c, dims)
    if bad is not None:
        raise ValueError(f"object.chart_rotation, the patch of contacts from joint "
                         f"angles: {bad}")
    tip = finger.tip_surface
    r = tip.params[0]
    c_obj = np.asarray(pose.position, dtype=float)
    geo = ObjectGeometry.of(obj, pose.rotation, pole_margin)
    R_l, p_l = finger.fingertip_pose_pin(q)
    try:
        alpha, t, _ = geo.nearest(p_l + R_l @ tip.p - c_obj)
        gap0 = t - r
        # a small gap closed by the least joint motion, as the first-grasp search does
        got = onto_surface(finger, q, c_obj, geo, alpha, tol=1e-13) \
            if abs(gap0) <= MAX_INITIAL_GAP else None
    except NotImplementedError as exc:
        raise ValueError(f"contacts from joint angles need a closed convex object: {exc}"
                         ) from None
    if got is not None:
        q, alpha = got[0], got[1]
        R_l, _ = finger.fingertip_pose_pin(q)
    u, v = (float(x) for x in np.asarray(alpha))
    limit = geo.u_limit
    if getattr(obj, "side_chart", False):  # on its side chart's equator (an egg's)
        p = R_c @ np.asarray(surface.geometry([u, v], dims)[0], dtype=float).reshape(3)
        R_side = surface.axis_patch(p)
        if R_side is not None:
            R_c = np.asarray(R_side, dtype=float)
            u, v = (float(x) for x in surface.inverse(R_c.T @ p, dims))
            rotvec = tuple(float(x) for x in log_rotation(R_c))
            geo = replace(geo, rotation=np.asarray(pose.rotation, dtype=float) @ R_c)
    if abs(u) > RECHART_SHARE * limit:
        turned = _pole_clear_symmetry(surface, dims, R_c, (u, v))
        if turned is not None:
            R_c, (u, v) = turned
            rotvec = tuple(float(x) for x in log_rotation(R_c))
            geo = replace(geo, rotation=np.asarray(pose.rotation, dtype=float) @ R_c)
    if abs(u) > limit:
        raise ValueError(
            f"its contact on the {obj.shape} is at u = {u:.4f}, beyond the bound {limit:.4f} "
            f"of the object's chart ({surface.u_limit_name}), which cannot be turned away "
            f"on a {obj.shape}" + (": touch it farther from the ends of its z axis, or turn "
                                   "the object (initial_pose.orientation)" if advise else ""))
    _, G_o, _, _, _ = surface.geometry([u, v], dims)
    R_oc = geo.rotation @ np.asarray(G_o, dtype=float)  # the object's contact frame, palm
    R_t = R_l @ tip.R
    ab = tip.surface.inverse(-(R_t.T @ R_oc[:, 2]), (1.0,))
    _, G_t, _, _, _ = tip.surface.geometry(ab, (r,))
    Rx = R_oc.T @ R_t @ np.asarray(G_t, dtype=float)  # R_contact(psi)
    psi = math.atan2(-Rx[0, 1], Rx[0, 0])
    return (float(ab[0]), float(ab[1]), u, v, psi), rotvec, gap0  # type: ignore[return-value]


#: A contact beyond this share of its chart's bound on |u| is put in the patch of the
#: object's symmetries that keeps it farthest from the poles, where one does better
#: (:func:`_pole_clear_symmetry`); nearer, it stays in the object's own patch.
RECHART_SHARE = 0.5


def _pole_clear_symmetry(surface: Any, params: Any, R_c: FloatArray, alpha: Any
                         ) -> tuple[FloatArray, tuple[float, float]] | None:
    """A chart patch for the contact at ``alpha`` of patch ``R_c`` (object frame) that
    puts it nearest the chart's equator among the patches the surface allows
    (``Surface.symmetries``: a rounded cube's 24 quarter and half turns), as (its
    rotation, the contact's coordinates there); None when none does better by a
    microradian (an egg's or a capsule's poles are its ends: no symmetry moves them).
    This is how a gait's contact that has rolled toward a pole goes on in another chart
    at its next roll (docs/shapes.md, "Charts")."""
    p = R_c @ np.asarray(surface.geometry(alpha, params)[0], dtype=float).reshape(3)
    best, best_u = None, abs(float(alpha[0])) - 1e-6
    for R in surface.symmetries(params):
        a = np.asarray(surface.inverse(R.T @ p, params), dtype=float)
        if abs(float(a[0])) < best_u:
            best, best_u = (np.asarray(R, dtype=float), (float(a[0]), float(a[1]))), \
                abs(float(a[0]))
    return best


def fingertips_from_joints(fingers: tuple[Any, ...], qs: tuple[Any, ...], obj: ObjectSpec,
                           pose: ObjectPose, names: tuple[str, ...],
                           where: tuple[str, ...],
                           pole_margin: float = ManipulationProblem.pole_margin,
                           advise: bool = True) -> tuple[Fingertip, ...]:
    """Round fingertips on a closed convex object at the joint angles ``qs`` of
    ``fingers``: their contact coordinates where the joints put them
    (:func:`contact_from_joints`); ProblemError naming ``where[i]`` (the field of finger
    i's joints) with the reason: joints outside their limits (which, by how much), a tip
    too far from the object or inside it (which finger, how far), a contact off a
    capsule's cap or beyond the object chart's bound (``pole_margin`` [rad] from its
    poles; ``advise``: :func:`contact_from_joints`'), two tips overlapping."""
    errs: list[tuple[str, str]] = []
    tips: list[Fingertip] = []
    centres: list[tuple[int, FloatArray, float]] = []
    for i, (f, q, name) in enumerate(zip(fingers, qs, names, strict=True)):
        q = np.asarray(q, dtype=float)
        if q.shape != (f.nq,) or not np.all(np.isfinite(q)):
            errs.append((where[i], f"must be {f.nq} finite joint angles, got {q.size}"))
            continue
        bad = [f"{j} = {v:.4g} is {'below' if v < lo else 'above'} its limit "
               f"{lo if v < lo else hi:.4g} by {max(lo - v, v - hi):.3g}"
               for j, v, lo, hi in zip(f.joint_names, q, f.lower, f.upper, strict=True)
               if not lo <= v <= hi]
        bad += [f"{c.describe()} is {v:.4g}, outside by {max(c.lower - v, v - c.upper):.3g}"
                for c in getattr(f, "couplings", ())
                for v in [float(c.row(f.joint_names) @ q)]
                if not c.lower - 1e-9 <= v <= c.upper + 1e-9]
        if bad:
            errs.append((where[i], f"finger {name!r}: " + "; ".join(bad)))
            continue
        if obj.shape == "sphere" and f.tip_surface.round:  # passive joints' tendons
            held = at_tendon_bounds(f, q, pose.position, float(obj.dimensions[0]))
            if isinstance(held, str):
                errs.append((where[i], f"finger {name!r}: {held}"))
                continue
            f, q = held
        try:
            init, chart, gap = contact_from_joints(f, q, obj, pose, pole_margin, advise)
        except ValueError as exc:
            errs.append((where[i], f"finger {name!r}: {exc}"))
            continue
        if abs(gap) > MAX_INITIAL_GAP:
            what = "from" if gap > 0 else "inside"
            errs.append((where[i], f"finger {name!r} cannot reach the initial grasp: its tip "
                                   f"is {abs(gap) * 1e3:.3g} mm {what} the object at these "
                                   f"joint angles (at most {MAX_INITIAL_GAP * 1e3:g} mm is "
                                   "closed by moving the joints)"))
            continue
        tip = f.tip_surface
        (a_lo, a_hi), (b_lo, b_hi) = tip.bounds(0.0, 0.0)
        if not (a_lo <= init[0] <= a_hi and b_lo <= init[1] <= b_hi):
            errs.append((where[i], f"finger {name!r} touches the object off its "
                                   f"{tip.kind}'s usable part (tip coordinates "
                                   f"{init[0]:.3f}, {init[1]:.3f} rad): "
                                   + ("on the cylindrical side, not the cap"
                                      if tip.kind == "capsule" else "at its chart's pole")))
            continue
        R, p = f.fingertip_pose_pin(q)
        centres.append((i, p + R @ tip.p, float(max(tip.params))))
        tips.append(Fingertip(f, init, chart,  # type: ignore[arg-type]
                              tuple(float(v) for v in q), name))
    for (i, ci, ri), (j, cj, rj) in ((a, b) for k, a in enumerate(centres)
                                     for b in centres[k + 1:]):
        overlap = ri + rj - float(np.linalg.norm(ci - cj))
        if overlap > 0:
            errs.append((where[j], f"fingers {names[i]!r} and {names[j]!r}: their tips "
                                   f"overlap by {overlap * 1e3:.3g} mm"))
    if errs:
        raise ProblemError(errs)
    return tuple(tips)


#: A gait's roll of an object with a side chart (an egg) puts its round fingertips on it
#: when a contact lies beyond this share of its own chart's bound there (or beyond the
#: bound): nearer the equator they keep the object's own chart (and the plans they had
#: before the side chart: examples/egg_gait.json's first rolls, 34-47 deg up, plan the
#: same gait either way, to 6e-6 N and 4e-7 in the quaternion). A request's one rolling
#: plan takes the side chart only for a contact beyond the bound (``share`` 1: every
#: request planned before plans as it did; examples/egg_turn.json's ring is at 0.8006).
SIDE_SHARE = 0.8


def fingertips_on_charts(fingers: tuple[Any, ...], qs: tuple[Any, ...], obj: ObjectSpec,
                         pose: ObjectPose, names: tuple[str, ...], where: tuple[str, ...],
                         pole_margin: float = ManipulationProblem.pole_margin,
                         advise: bool = True, share: float = SIDE_SHARE
                         ) -> tuple[ObjectSpec, tuple[Fingertip, ...]]:
    """:func:`fingertips_from_joints` on the chart that suits them: the object as it
    is, or, where a contact lies beyond ``share`` of its bound on the object's own chart
    (or beyond the bound: an egg touched at an end) and the shape has a side chart (an
    egg's, whose poles are on its equator), on that one, each contact on its patch's
    equator, when that puts the contact farthest up its chart nearer its equator: (the
    object as measured, with ``side_chart`` set or not, the fingertips). An object asked
    on its side chart stays there; ``share`` infinite: the own chart always."""
    def on(o: ObjectSpec) -> tuple[tuple[Fingertip, ...], float]:
        tips = fingertips_from_joints(fingers, qs, o, pose, names, where, pole_margin,
                                      advise)
        return tips, max((abs(float(t.initial[2])) for t in tips), default=0.0)

    if obj.side_chart or obj.kind.side_surface(obj.dimensions) is None:
        return obj, on(obj)[0]
    try:
        tips, worst = on(obj)
        error = None
    except ProblemError as exc:
        tips, worst, error = (), math.inf, exc
    if worst > share * obj.u_limit(pole_margin):
        side = replace(obj, side_chart=True)
        try:
            on_side, up = on(side)
        except ProblemError:
            pass
        else:
            if up < worst:
                return side, on_side
    if error is not None:
        raise error
    return obj, tips
