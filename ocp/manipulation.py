"""Manipulating an object with any number of rolling contacts: one NLP for every grasp.

A grasp is data: an object (:class:`~ocp.problem.ObjectSpec`), an optional flat palm it
rests on (:class:`Palm`), and a list of flat fingertips (:class:`Fingertip`), each the pad
of a finger from a URDF. The paper's section 3 (one finger pressing a ball on the palm),
its section 4 (two fingers holding a ball in the air) and three or more fingers are the
same code with different data (:class:`ManipulationPlanner`).

States (scaled for IPOPT; docs/conventions.md)
    * the object block: with a palm, its contact coordinates eta_p = (x, y, u, v, psi),
      which fix the object's pose; without one, the object's pose itself: position
      p [m] in the palm frame and orientation quaternion (w, x, y, z) (its rotation is
      R(q / |q|), so the norm is not constrained);
    * for each fingertip i: eta_i = (x_i, y_i, u_i, v_i, psi_i) (pad point [m], object
      point [rad] in the contact's own chart patch, contact angle [rad]) and the finger's
      joint angles q_i.
Inputs
    * the object block: the palm contact velocity w_p = d/dt (x, y) [m/s], or the object's
      twist (v [m/s] in the palm frame, omega [rad/s] in the object frame);
    * for each fingertip: w_i = d/dt (u_i, v_i) [rad/s] (the contact's motion over the
      object, the paper's alpha_dot_of) and the joint rates q_dot_i.
Dynamics: the rolling equations at every contact (eq. 3 via :class:`ContactPair`); the
object's pose is a state only when no palm fixes it (q_dot = q (x) (0, omega) / 2).
Path constraints at every collocation point: each finger's closure (eq. 6: the fingertip
pose from the joints equals the pose from the object pose and the contact coordinates),
force closure with a margin (friction cones; :mod:`ocp.force_closure` for 3+ contacts),
contacts inside the pads, joint and joint-rate limits, chart pole margins, and, when the
request asks, hard bounds on the tracking error.
Objective (over normalised time): effort of every input, a weight times the grasp-angle
epigraph s >= 1 - cos Phi_i, and a weighted tracking error on SE(3) between the object's
pose and the desired one: |p - p_d|^2 / L^2 + (3 - tr(R_d^T R)) / 2 (the second term is
1 - cos of the rotation angle between R and R_d, not an Euler-angle difference).
"""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np
from numpy.typing import ArrayLike, NDArray

from .ball_on_palm import (
    BallOnPalmPlanner,
    Structure,
    goal_errors,
    model_for,
)
from .collocation import (
    NlpPoint,
    WarmStart,
    node_inputs,
    node_times,
    reintegrate,
    reintegrator,
)
from .compiled import BackgroundCompiler
from .contact import ContactPair
from .grasp import cone_cosine, grasp_angles_numeric
from .ipopt import IPOPT_WARM_OPTIONS
from .nlp_blocks import NLP as _NLP
from .nlp_blocks import build_manipulation_nlp
from .problem import (
    CONTACT_COORDS,
    MAX_INTERVALS,
    MAX_POSITION,
    BallOnPalmProblem,
    ObjectSpec,
    ProblemError,
    SolverOptions,
    ViaPoint,
)
from .solution import Status, quaternion_wxyz, status_from_ipopt
from .surfaces import SURFACES, Plane, rotation_from_vector

__all__ = [
    "ContactTrajectory",
    "DesiredMotion",
    "FingerTrajectory",
    "Fingertip",
    "ManipulationPlanner",
    "ManipulationProblem",
    "ManipulationSolution",
    "MotionStep",
    "ObjectPose",
    "Palm",
    "Tracking",
    "contact_chart_for_pad",
    "fingertip_errors",
    "hand_fingertips",
]

FloatArray = NDArray[np.float64]

#: Tracking bounds are imposed in the NLP at this fraction of the requested tolerance, so
#: that the motion between collocation points stays inside the tolerance itself.
TRACKING_BOUND_SHRINK = 0.95
#: Joint limits are imposed this far inside [rad or m] at the collocation points.
JOINT_LIMIT_MARGIN = 1e-4
#: Weight of the size of the internal-force variables (3+ contacts) in the objective.
FORCE_REGULARISATION = 1e-3
#: Pose tolerance of the inverse kinematics along the initial guess [m, rad], the initial
#: grasp's own. (A guess closed to 1e-8 only sent IPOPT down another path on experiment 1:
#: the same 14 iterations, one with an inertia correction, 30 % more time.)
IK_GUESS_TOL = 1e-10


# -- rotations ---------------------------------------------------------------------------------

def quaternion_matrix(q: ArrayLike) -> FloatArray:
    """Rotation matrix of a quaternion (w, x, y, z) (normalised first)."""
    w, x, y, z = np.asarray(q, dtype=float) / np.linalg.norm(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def _quat_rotation_sym(q: Any) -> Any:
    n2 = ca.dot(q, q)
    w, x, y, z = q[0], q[1], q[2], q[3]
    return ca.vertcat(
        ca.horzcat(n2 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)),
        ca.horzcat(2 * (x * y + w * z), n2 - 2 * (x * x + z * z), 2 * (y * z - w * x)),
        ca.horzcat(2 * (x * z - w * y), 2 * (y * z + w * x), n2 - 2 * (x * x + y * y))) / n2


def _quat_rate_sym(q: Any, omega: Any) -> Any:
    """d/dt q = q (x) (0, omega) / 2, omega in the body frame."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    a, b, c = omega[0], omega[1], omega[2]
    return 0.5 * ca.vertcat(-(x * a + y * b + z * c), w * a + y * c - z * b,
                            w * b + z * a - x * c, w * c + x * b - y * a)


def _axis_angle(axis: ArrayLike, angle: float) -> FloatArray:
    a = np.asarray(axis, dtype=float)
    return rotation_from_vector(a / np.linalg.norm(a) * angle)


def _log_rotation(R: FloatArray) -> FloatArray:
    """Rotation vector of R (angle in [0, pi])."""
    c = float(np.clip((np.trace(R) - 1) / 2, -1.0, 1.0))
    angle = math.acos(c)
    v = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    if angle < 1e-9:
        return v / 2
    if math.pi - angle < 1e-6:  # axis from the symmetric part
        M = (R + np.eye(3)) / 2
        axis = M[:, int(np.argmax(np.diag(M)))]
        return axis / np.linalg.norm(axis) * angle
    return v * angle / (2 * math.sin(angle))


def rotation_angle_between(Ra: FloatArray, Rb: FloatArray) -> FloatArray:
    """Geodesic angle [rad] between stacks of rotations (k, 3, 3)."""
    tr = np.einsum("kji,kji->k", Ra, Rb)  # tr(Ra^T Rb)
    return np.arccos(np.clip((tr - 1) / 2, -1.0, 1.0))


# -- problem data --------------------------------------------------------------------------------

@dataclass(frozen=True)
class ObjectPose:
    """A pose of the object in the palm frame: orientation quaternion (w, x, y, z) and
    position [m]."""

    orientation: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)
    position: tuple[float, float, float] = (0.0, 0.0, 0.0)

    @property
    def rotation(self) -> FloatArray:
        return quaternion_matrix(self.orientation)

    def errors(self, name: str) -> list[tuple[str, str]]:
        errs: list[tuple[str, str]] = []
        q = self.orientation
        if len(q) != 4 or not all(map(math.isfinite, q)) or \
                not 0.5 < math.sqrt(sum(c * c for c in q)) < 1.5:
            errs.append((f"{name}.orientation",
                         "must be a unit quaternion (w, x, y, z) of 4 finite numbers"))
        p = self.position
        if len(p) != 3 or not all(math.isfinite(c) and abs(c) <= MAX_POSITION for c in p):
            errs.append((f"{name}.position",
                         f"must be 3 finite numbers within +-{MAX_POSITION} m"))
        return errs


@dataclass(frozen=True)
class MotionStep:
    """One step of a desired object motion: over ``duration`` [s], rotate by ``angle``
    [rad] about ``axis`` (a direction in the palm frame, through the object's centre) and
    translate its centre by ``translation`` [m] (palm frame)."""

    duration: float
    axis: tuple[float, float, float] = (0.0, 0.0, 1.0)
    angle: float = 0.0
    translation: tuple[float, float, float] = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class DesiredMotion:
    """A desired object trajectory: poses at knot times, interpolated on SE(3).

    Between knots the orientation follows the geodesic (constant axis) and the position
    the straight line, both with the same time scaling: ``smooth`` (the default) eases in
    and out (3 s^2 - 2 s^3, zero velocity at every knot), else constant rate.
    """

    times: tuple[float, ...]
    orientations: tuple[tuple[float, float, float, float], ...]
    positions: tuple[tuple[float, float, float], ...]
    smooth: bool = True

    @staticmethod
    def from_steps(start: ObjectPose, steps: Sequence[MotionStep], smooth: bool = True
                   ) -> DesiredMotion:
        """The motion made of ``steps`` one after the other from ``start`` (the paper's
        "rotate about Z by 20 deg, then about Y by 20 deg, ...")."""
        R, p, t = start.rotation, np.asarray(start.position, dtype=float), 0.0
        times, quats, pos = [0.0], [tuple(quaternion_wxyz(R))], [tuple(p)]
        for s in steps:
            t += float(s.duration)
            if s.angle != 0.0:
                R = _axis_angle(s.axis, s.angle) @ R
            p = p + np.asarray(s.translation, dtype=float)
            times.append(t)
            quats.append(tuple(quaternion_wxyz(R)))
            pos.append(tuple(p))
        return DesiredMotion(tuple(times), tuple(quats), tuple(pos), smooth)

    def errors(self, name: str, duration: float) -> list[tuple[str, str]]:
        errs: list[tuple[str, str]] = []
        n = len(self.times)
        if n < 2 or len(self.orientations) != n or len(self.positions) != n:
            return [(name, "needs at least 2 knots, with as many orientations and positions "
                           f"as times (got {n}, {len(self.orientations)}, "
                           f"{len(self.positions)})")]
        ts = self.times
        if not all(map(math.isfinite, ts)) or ts[0] != 0.0 or \
                any(b <= a for a, b in itertools.pairwise(ts)):
            errs.append((f"{name}.times", "must start at 0 and increase strictly"))
        elif abs(ts[-1] - duration) > 1e-9 * max(1.0, duration):
            errs.append((f"{name}.times",
                         f"must end at the duration {duration} s, got {ts[-1]}"))
        for i, q in enumerate(self.orientations):
            errs += ObjectPose(q, self.positions[i]).errors(f"{name}[{i}]")
        return errs

    def at(self, t: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """(R (k, 3, 3), p (k, 3)) at times t (clipped to the knots' span)."""
        ts = np.asarray(self.times, dtype=float)
        tq = np.clip(np.atleast_1d(np.asarray(t, dtype=float)), ts[0], ts[-1])
        Rk = [quaternion_matrix(q) for q in self.orientations]
        Pk = np.asarray(self.positions, dtype=float)
        j = np.clip(np.searchsorted(ts, tq, side="right") - 1, 0, len(ts) - 2)
        s = (tq - ts[j]) / (ts[j + 1] - ts[j])
        if self.smooth:
            s = s * s * (3 - 2 * s)
        R = np.empty((len(tq), 3, 3))
        for i, (jj, ss) in enumerate(zip(j, s, strict=True)):
            R[i] = Rk[jj] @ rotation_from_vector(ss * _log_rotation(Rk[jj].T @ Rk[jj + 1]))
        p = Pk[j] + s[:, None] * (Pk[j + 1] - Pk[j])
        return R, p


@dataclass(frozen=True)
class Tracking:
    """How hard the object follows a :class:`DesiredMotion`.

    The weights multiply the integrals over normalised time of |p - p_d|^2 / L^2 and of
    1 - cos(angle between R and R_d); ``*_tolerance`` (when given) are hard bounds [m],
    [rad] on the errors at every instant (checked by the certificate between collocation
    points too).
    """

    position_weight: float = 1e4
    orientation_weight: float = 1e4
    position_tolerance: float | None = None
    orientation_tolerance: float | None = None


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

    finger: Any  # ocp.finger.FingerModel
    initial: tuple[float, float, float, float, float]
    chart_rotation: tuple[float, float, float] = (math.pi / 2, 0.0, 0.0)
    q_seed: tuple[float, ...] | None = None
    name: str = ""


def fingertip_errors(name: str, tip: Fingertip, obj: ObjectSpec, pad_margin: float,
                     pole_margin: float) -> list[tuple[str, str]]:
    """Why a fingertip's initial contact is invalid, as (field, reason) under ``name``:
    its chart patch, its coordinates, the pad (less ``pad_margin``) and the patch's poles."""
    errs: list[tuple[str, str]] = []
    if obj.shape in SURFACES and len(tip.chart_rotation) == 3 and \
            all(map(math.isfinite, tip.chart_rotation)):
        bad = obj.surface.chart_rotation_error(rotation_from_vector(tip.chart_rotation))
        if bad is not None:
            errs.append((f"{name}.chart_rotation", bad))
    else:
        errs.append((f"{name}.chart_rotation", "must be 3 finite numbers "
                                               "(rotation vector, rad)"))
    if len(tip.initial) != 5 or not all(map(math.isfinite, tip.initial)):
        return [*errs, (f"{name}.initial", "must be 5 finite numbers "
                                           "(x_f, y_f, u_f, v_f, psi_f)")]
    half = float(tip.finger.pad_half_size) - pad_margin
    for k, coord in ((0, "x_f"), (1, "y_f")):
        if abs(tip.initial[k]) > half:
            errs.append((f"{name}.initial.{coord}",
                         f"|{coord}| = {abs(tip.initial[k]):.4g} m leaves the pad "
                         f"(half size {tip.finger.pad_half_size} m less {pad_margin} m "
                         f"margin) by {abs(tip.initial[k]) - half:.4g} m"))
    u_lim = math.pi / 2 - pole_margin
    if abs(tip.initial[2]) > u_lim:
        errs.append((f"{name}.initial.u_f",
                     f"|u_f| = {abs(tip.initial[2]):.4f} rad is beyond the chart pole "
                     f"limit {u_lim:.4f} rad; rotate {name}.chart_rotation"))
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
            options=self.options)

    def segments(self) -> tuple[tuple[int, ...], FloatArray]:
        """(intervals per segment, segment boundary times): via-points split the grid."""
        if self.palm is not None:
            base = self.palm_problem()
            return base.segment_intervals(), base.segment_times
        return (self.n_intervals,), np.array([0.0, self.duration])

    def with_intervals(self, n: int) -> ManipulationProblem:
        return replace(self, n_intervals=n)

    def errors(self) -> list[tuple[str, str]]:
        """Every reason the problem is invalid, as (field, reason)."""
        errs: list[tuple[str, str]] = []
        palm_fields = ("initial", "goal", "via_points", "palm_half_extent",
                       "max_contact_speed")
        if self.palm is not None:
            for name, why in self.palm_problem().errors():
                if name == "goal" and self.motion is not None and "nothing to plan" in why:
                    continue  # the motion says what to do
                head = name.split(".")[0].split("[")[0]
                errs.append((f"palm.{name}" if head in palm_fields else name, why))
        else:
            # the object, grid and solver fields, checked by the palm problem's own rules
            errs += BallOnPalmProblem(self.object, (0.0, 0.0, 0.0, 0.0, 0.0), {"x": 0.0},
                                      self.duration, n_intervals=self.n_intervals,
                                      pole_margin=self.pole_margin,
                                      max_refinements=self.max_refinements,
                                      options=self.options).errors()
            if self.initial_pose is None:
                errs.append(("initial_pose", "required when no palm carries the object"))
            else:
                errs += self.initial_pose.errors("initial_pose")
            if self.motion is None:
                errs.append(("motion", "required when no palm carries the object: what "
                                       "should the object do?"))
        if self.motion is not None:
            errs += self.motion.errors("motion", self.duration)
        if self.n_contacts < 2:
            errs.append(("fingers", "a grasp needs at least two contacts (a palm and a "
                                    f"finger, or two fingers); got {self.n_contacts}"))
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
    from .contact import R_contact

    shape = np.asarray(obj.dimensions, dtype=float)
    _, Rg, _, _, _ = obj.surface.geometry([0.0, 0.0], shape)
    R_of = pose.rotation.T @ np.asarray(pad_rotation, dtype=float)
    Rc = R_of @ np.asarray(R_contact(0.0)).T @ np.asarray(Rg).T
    return tuple(float(c) for c in _log_rotation(Rc))  # type: ignore[return-value]


def hand_fingertips(hand: Any, pose: ObjectPose | None = None,
                    obj: ObjectSpec | None = None) -> tuple[Fingertip, ...]:
    """Fingertips of a built-in hand (:func:`ocp.hands.load_hand`) in its nominal grasp of a
    ball at ``pose`` (default: unrotated, at the hand's nominal position): each pad's centre
    on the ball where the pad's normal points (contact coordinates all zero, charts from
    :func:`contact_chart_for_pad`), the IK seeded with the hand's nominal joint angles."""
    from .hands import grasp_poses

    pose = pose or ObjectPose(position=tuple(hand.nominal_object_position))
    obj = obj or ObjectSpec("sphere", (hand.nominal_radius,))
    pads = grasp_poses(hand, pose.position, float(max(obj.dimensions)), pose.rotation)
    seeds = hand.nominal_q or (None,) * hand.n_fingers
    return tuple(
        Fingertip(finger, (0.0, 0.0, 0.0, 0.0, 0.0), contact_chart_for_pad(obj, pose, R),
                  q_seed=seed, name=f"f{k + 1}")
        for k, (finger, (R, _), seed) in enumerate(zip(hand.fingers, pads, seeds,
                                                       strict=True)))


# -- solution --------------------------------------------------------------------------------

@dataclass(frozen=True)
class ContactTrajectory:
    """One contact over the plan (rows are samples).

    ``eta`` = (body point x, y [m], object point u, v [rad], psi [rad]): for the palm the
    palm point, for a fingertip the pad point; ``w`` the contact's input (palm: d/dt (x, y)
    [m/s]; fingertip: d/dt (u, v) [rad/s]); ``point`` the contact point and ``normal`` the
    object's outward normal there, in the palm frame; ``force_angle`` the angle [rad]
    between the pushing direction (-normal) and the internal force of the grasp that
    certifies force closure (for two contacts: the paper's grasp angle).
    """

    name: str
    body: str  # "palm" or "finger"
    eta: FloatArray
    eta_dot: FloatArray
    w: FloatArray
    point: FloatArray
    normal: FloatArray
    force_angle: FloatArray


@dataclass(frozen=True)
class FingerTrajectory:
    """One finger over the plan: joint angles q [rad], rates q_dot [rad/s], the pad's pose
    (position [m], rotation) in the palm frame."""

    name: str
    joint_names: tuple[str, ...]
    q: FloatArray
    q_dot: FloatArray
    tip_position: FloatArray
    tip_rotation: FloatArray


@dataclass(frozen=True)
class ManipulationSolution:
    """A plan sampled on the collocation grid (nodes and midpoints, in time order)."""

    status: Status
    message: str
    raw_status: str
    iterations: int
    build_time: float
    solve_time: float
    t: FloatArray
    object_position: FloatArray
    object_rotation: FloatArray
    object_velocity: FloatArray  # [m/s], palm frame
    object_angular_velocity: FloatArray  # [rad/s], palm frame
    contacts: tuple[ContactTrajectory, ...]
    fingers: tuple[FingerTrajectory, ...]
    grasp_angle: FloatArray  # Phi*: the largest force angle over the contacts [rad]
    cone_margin: FloatArray  # atan(mu) - Phi* [rad]
    desired_position: FloatArray | None
    desired_rotation: FloatArray | None
    tracking_position_error: FloatArray | None  # [m]
    tracking_angle_error: FloatArray | None  # [rad]
    goal_error: dict[str, float]
    certificate: dict[str, float]
    certificate_failures: tuple[str, ...] = ()
    refinements: int = 0
    #: The collocation grid's raw values (states, inputs), for warm starts.
    X: FloatArray = field(default_factory=lambda: np.zeros((0, 0)), repr=False)
    U: FloatArray = field(default_factory=lambda: np.zeros((0, 0)), repr=False)
    #: IPOPT's primal-dual point at this plan, for a warm start of the same NLP.
    nlp_point: NlpPoint | None = field(default=None, repr=False)

    @property
    def ok(self) -> bool:
        return self.status is Status.SOLVED

    @property
    def warm_start(self) -> WarmStart:
        """This plan as the initial guess of another (its collocation points' states and
        inputs, and IPOPT's primal-dual point for a plan of the same NLP)."""
        return WarmStart(self.t, self.X, self.U, self.nlp_point)


# -- symbolic model --------------------------------------------------------------------------

def _vee_skew(E: Any) -> Any:
    """vee((E - E^T)/2): zero for E = I, ~ the rotation vector for E near I."""
    return ca.vertcat(E[2, 1] - E[1, 2], E[0, 2] - E[2, 0], E[1, 0] - E[0, 1]) / 2


def _vee(W: Any) -> Any:
    return ca.vertcat(W[2, 1], W[0, 2], W[1, 0])


@dataclass(frozen=True)
class _Layout:
    """Where each block sits in the state and input vectors."""

    palm: bool
    nqs: tuple[int, ...]

    @property
    def n_obj_x(self) -> int:
        return 5 if self.palm else 7

    @property
    def n_obj_u(self) -> int:
        return 2 if self.palm else 6

    def x_eta(self, i: int) -> slice:  # finger i's contact coordinates
        start = self.n_obj_x + sum(5 + n for n in self.nqs[:i])
        return slice(start, start + 5)

    def x_q(self, i: int) -> slice:
        s = self.x_eta(i).stop
        return slice(s, s + self.nqs[i])

    def u_w(self, i: int) -> slice:
        start = self.n_obj_u + sum(2 + n for n in self.nqs[:i])
        return slice(start, start + 2)

    def u_qd(self, i: int) -> slice:
        s = self.u_w(i).stop
        return slice(s, s + self.nqs[i])

    @property
    def nx(self) -> int:
        return self.n_obj_x + sum(5 + n for n in self.nqs)

    @property
    def nu(self) -> int:
        return self.n_obj_u + sum(2 + n for n in self.nqs)

    def x_scale(self, L: Any) -> list[Any]:
        out: list[Any] = [L, L, 1, 1, 1] if self.palm else [L, L, L, 1, 1, 1, 1]
        for n in self.nqs:
            out += [L, L, 1, 1, 1] + [1] * n
        return out

    def u_scale(self, L: Any, T: Any) -> list[Any]:
        out: list[Any] = [L / T, L / T] if self.palm else [L / T] * 3 + [1 / T] * 3
        for n in self.nqs:
            out += [1 / T, 1 / T] + [1 / T] * n
        return out

    def angle_columns(self) -> list[int]:
        cols = [2, 3, 4] if self.palm else [3, 4, 5, 6]
        for i in range(len(self.nqs)):
            e = self.x_eta(i)
            cols += [e.start + 2, e.start + 3, e.start + 4]
        return cols

    def length_columns(self) -> list[int]:
        cols = [0, 1] if self.palm else [0, 1, 2]
        for i in range(len(self.nqs)):
            e = self.x_eta(i)
            cols += [e.start, e.start + 1]
        return cols

    def joint_columns(self) -> list[int]:
        return [c for i in range(len(self.nqs)) for c in range(self.x_q(i).start,
                                                                self.x_q(i).stop)]


class _Model:
    """CasADi functions of one grasp structure (object shape, palm or not, the fingers)."""

    def __init__(self, shape: str, palm: bool, fingers: tuple[Any, ...]) -> None:
        surface = model_for(shape).surface
        self.surface = surface
        self.fingers = fingers
        lay = self.layout = _Layout(palm, tuple(int(f.nq) for f in fingers))
        self.nx, self.nu = lay.nx, lay.nu
        nf = len(fingers)
        self.n_contacts = nf + palm
        x = ca.SX.sym("x", self.nx)
        u = ca.SX.sym("u", self.nu)
        shape_p = ca.SX.sym("shape", surface.n_params)
        charts = [ca.SX.sym(f"Rc{i}", 3, 3) for i in range(self.n_contacts)]
        prm = ca.vertcat(shape_p, *[ca.vec(R) for R in charts])
        self.n_params = int(prm.numel())
        none = ca.SX(0, 1)
        eye = ca.SX.eye(3)
        tip = ContactPair(surface, Plane)  # A = object (finger patch), B = pad
        xdot_parts: list[Any] = []
        points, normals = [], []  # object frame
        if palm:
            pair = ContactPair(Plane, surface)  # A = palm, B = object
            eta_p = x[0:5]
            xdot_parts.append(pair.rates_driven_by_a(eta_p, u[0:2], none, shape_p))
            R_po, p_po = pair.pose(eta_p, none, shape_p, eye, charts[0])
            pc, Rg, _, _, _ = surface.geometry(eta_p[2:4], shape_p)
            points.append(charts[0] @ pc)
            normals.append(charts[0] @ Rg[:, 2])
        else:
            p_po, quat = x[0:3], x[3:7]
            R_po = _quat_rotation_sym(quat)
            xdot_parts += [u[0:3], _quat_rate_sym(quat, u[3:6])]
        closure, fk_R, fk_p, tip_R, tip_p = [], [], [], [], []
        for i, finger in enumerate(fingers):
            eta, q = x[lay.x_eta(i)], x[lay.x_q(i)]
            Rc = charts[i + palm]
            e = ca.vertcat(eta[2:4], eta[0:2], eta[4])  # the pair's order (u, v, x, y, psi)
            ed = tip.rates_driven_by_a(e, u[lay.u_w(i)], shape_p, none)
            xdot_parts += [ca.vertcat(ed[2:4], ed[0:2], ed[4]), u[lay.u_qd(i)]]
            R_of, p_of = tip.pose(e, shape_p, none, Rc, eye)
            R_pf, p_pf = R_po @ R_of, p_po + R_po @ p_of
            R_fk, p_fk = finger.fk(q)
            closure.append(ca.vertcat(p_pf - p_fk, _vee_skew(R_fk.T @ R_pf)))
            fk_R.append(R_fk)
            fk_p.append(p_fk)
            tip_R.append(R_pf)
            tip_p.append(p_pf)
            pc, Rg, _, _, _ = surface.geometry(eta[2:4], shape_p)
            points.append(Rc @ pc)
            normals.append(Rc @ Rg[:, 2])
        e_ = ca.SX.sym("e", 5)
        w_ = ca.SX.sym("w", 2)
        self.tip_rates = ca.Function("tip_rates", [e_, w_, shape_p],
                                     [tip.rates_driven_by_a(e_, w_, shape_p, none)])
        # one RK4 step of a fingertip's pad point and angle (x, y, psi) while its object
        # point goes from a (rate w0) to the next (rate w1) in time h: the initial guess
        c_, a_ = ca.SX.sym("c", 3), ca.SX.sym("a", 2)
        w0_, w1_, h_ = ca.SX.sym("w0", 2), ca.SX.sym("w1", 2), ca.SX.sym("h")
        e0 = ca.vertcat(a_, c_)  # the pair's order (u, v, x, y, psi)
        k1 = self.tip_rates(e0, w0_, shape_p)
        k2 = self.tip_rates(e0 + h_ / 2 * k1, (w0_ + w1_) / 2, shape_p)
        k3 = self.tip_rates(e0 + h_ / 2 * k2, (w0_ + w1_) / 2, shape_p)
        k4 = self.tip_rates(e0 + h_ * k3, w1_, shape_p)
        e1 = e0 + h_ / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        self._roll_step = ca.Function("roll_step", [c_, a_, w0_, w1_, h_, shape_p],
                                      [e1[2:5]])
        self._rolls: dict[int, ca.Function] = {}
        xdot = ca.vertcat(*xdot_parts)
        self.dynamics = ca.Function("manipulation_dynamics", [x, u, prm], [xdot],
                                    ["x", "u", "params"], ["x_dot"])
        self._reintegrators: dict[int, ca.Function] = {}
        self._mapped: dict[tuple[str, int], ca.Function] = {}
        P = ca.horzcat(*points)  # object frame, 3 x n
        N = ca.horzcat(*normals)
        cl = ca.vertcat(*closure) if closure else ca.SX(0, 1)
        self.path = ca.Function("manipulation_path", [x, prm], [cl, P, N, R_po, p_po],
                                ["x", "params"], ["closure", "points", "normals", "R_po",
                                                  "p_po"])
        self.cartesian = ca.Function(
            "manipulation_cartesian", [x, prm],
            [R_po, p_po, ca.horzcat(*tip_R) if tip_R else ca.SX(3, 0),
             ca.horzcat(*tip_p) if tip_p else ca.SX(3, 0), p_po + R_po @ P, R_po @ N],
            ["x", "params"], ["R_po", "p_po", "R_pf", "p_pf", "points", "normals"])
        # Rolling laws along a motion (certificate): each finger moves by its joints (FK),
        # the object by its pose; material points of both bodies at every contact.
        xd = ca.SX.sym("xd", self.nx)

        def dot(expr: Any) -> Any:
            return ca.reshape(ca.jtimes(ca.vec(expr), x, xd), expr.size1(), expr.size2())

        R_po_dot, p_po_dot = dot(R_po), dot(p_po)
        W_obj = R_po_dot @ R_po.T
        omega_obj = _vee(W_obj)
        outs = [p_po_dot, omega_obj]
        names = ["v_obj", "omega_obj"]
        if palm:
            outs += [R_po_dot @ points[0] + p_po_dot, ca.dot(omega_obj, R_po @ normals[0])]
            names += ["slip_palm", "spin_palm"]
        for i in range(nf):
            R_fk, p_fk = fk_R[i], fk_p[i]
            c_pt = p_po + R_po @ points[i + palm]
            on_pad = R_fk.T @ (c_pt - p_fk)
            v_pad = dot(R_fk) @ on_pad + dot(p_fk)
            v_obj = R_po_dot @ points[i + palm] + p_po_dot
            omega_rel = _vee(dot(R_fk) @ R_fk.T - W_obj)
            n_i = R_po @ normals[i + palm]
            outs += [v_pad - v_obj, ca.dot(omega_rel, n_i), ca.dot(R_fk[:, 2], p_po - p_fk),
                     R_fk[:, 2], on_pad]
            names += [f"slip_{i}", f"spin_{i}", f"centre_above_pad_{i}", f"pad_normal_{i}",
                      f"pad_point_{i}"]
        self.laws = ca.Function("manipulation_laws", [x, xd, prm], outs,
                                ["x", "x_dot", "params"], names)

    def roll(self, steps: int) -> ca.Function:
        """``steps`` RK4 steps of a pad point and angle (:attr:`_roll_step` accumulated):
        (c0, a (2 x k), w0 (2 x k), w1 (2 x k), h (1 x k), shape (. x k)) -> c (3 x k)."""
        if steps not in self._rolls:
            self._rolls[steps] = self._roll_step.mapaccum("roll", steps)
        return self._rolls[steps]

    def params(self, shape: FloatArray, charts: Sequence[FloatArray]) -> FloatArray:
        return np.concatenate([np.asarray(shape, dtype=float),
                               *[np.asarray(R).ravel(order="F") for R in charts]])

    def mapped(self, name: str, k: int) -> ca.Function:
        """The model's function ``name`` (cartesian, dynamics, laws) over k points, built
        once per size."""
        if (name, k) not in self._mapped:
            self._mapped[(name, k)] = getattr(self, name).map(k)
        return self._mapped[(name, k)]

    def reintegrator(self, n_sub: int) -> ca.Function:
        if n_sub not in self._reintegrators:
            self._reintegrators[n_sub] = reintegrator(self.dynamics, self.nx, self.nu,
                                                      self.n_params, n_sub)
        return self._reintegrators[n_sub]


# -- force closure ---------------------------------------------------------------------------

def force_angles(points: FloatArray, normals: FloatArray
                 ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """(Phi* (k,), per-contact force angles (k, n), grasp map onto (k,)) for contacts
    (k, n, 3) with the object's outward normals. Two contacts: the paper's grasp angles
    in closed form; three or more: :func:`ocp.force_closure.grasp_qualities`."""
    n = points.shape[1]
    if n == 2:
        ang = grasp_angles_numeric(points[:, 0], normals[:, 0], points[:, 1], normals[:, 1])
        onto = np.linalg.norm(points[:, 1] - points[:, 0], axis=1) > 0
        return ang.max(axis=1), ang, onto
    from .force_closure import grasp_qualities

    qs = grasp_qualities(points, normals)
    return (np.array([q.angle for q in qs]), np.array([q.contact_angles for q in qs]),
            np.array([q.rank_ok for q in qs]))


# -- the planner -----------------------------------------------------------------------------

def _charts(problem: ManipulationProblem) -> list[FloatArray]:
    out = [rotation_from_vector(problem.object.chart_rotation)] if problem.palm else []
    return out + [rotation_from_vector(c.chart_rotation) for c in problem.fingers]


def _goal_errors(problem: ManipulationProblem, X: FloatArray, ends: list[int]
                 ) -> dict[str, float]:
    if problem.palm is None:
        return {}
    out = goal_errors(problem.palm_problem(), X, ends)
    return {f"palm.{k}": v for k, v in out.items()}


def _fingerprint(key: tuple[Any, ...], m: _Model) -> str:
    """A structure key as a string that another process computes alike: the fingers by
    their models (URDF, tip frame, mount), not by identity."""
    import hashlib

    shape, palm, segments, goal_mask, via_masks, fingers, tracking = key
    parts = [repr((shape, palm, segments, goal_mask, via_masks, tracking, m.nx, m.nu))]
    for f in fingers:
        parts += [hashlib.sha256(f.urdf_text.encode()).hexdigest(), f.tip_frame,
                  repr(np.asarray(f.base_rotation).round(12).tolist()),
                  repr(np.asarray(f.base_position).round(12).tolist())]
    return hashlib.sha256("|".join(parts).encode()).hexdigest()[:32]


class ManipulationPlanner:
    """Direct-collocation planner for any grasp (NLPs cached per structure)."""

    def __init__(self, compile_dir: Path | None = None, background: bool = False) -> None:
        #: When set, each structure's NLP functions are generated as C, compiled with gcc
        #: and cached there (:func:`ocp.compiled.compiled_block_solver`): seconds the first
        #: time, IPOPT about 40 % faster on experiment 1 (docs/performance.md).
        self.compile_dir = compile_dir
        #: With ``background``, a new structure is solved in the virtual machine at once and
        #: compiled in a background thread (:class:`ocp.compiled.BackgroundCompiler`); the
        #: compiled solver replaces it at the first solve after the compile (a service
        #: worker: no request waits for gcc). Without, the first solve compiles.
        self.compiler = BackgroundCompiler(compile_dir) if compile_dir is not None \
            and background else None
        # keyed by the finger objects themselves (identity; the key keeps them alive)
        self._models: dict[tuple[Any, ...], _Model] = {}
        self._nlps: dict[tuple[Any, ...], _NLP] = {}
        self._palm = BallOnPalmPlanner()

    def model(self, problem: ManipulationProblem) -> _Model:
        key = (problem.object.shape, problem.palm is not None,
               tuple(c.finger for c in problem.fingers))
        if key not in self._models:
            self._models[key] = _Model(*key)
        return self._models[key]

    def _structure(self, problem: ManipulationProblem) -> tuple[Any, ...]:
        segments, _ = problem.segments()
        masks: tuple[Any, ...] = ((False,) * 5, ())
        if problem.palm is not None:
            st = Structure.of(problem.palm_problem())
            masks = (st.goal_mask, st.via_masks)
        return (problem.object.shape, problem.palm is not None, segments, *masks,
                tuple(c.finger for c in problem.fingers), problem.motion is not None)

    # ...................................................................................
    def _build(self, problem: ManipulationProblem) -> tuple[_NLP, bool]:
        key = self._structure(problem)
        if key in self._nlps:
            return self._nlps[key], True
        _, _, segments, goal_mask, via_masks, _, tracking = key
        m = self.model(problem)
        nlp = build_manipulation_nlp(m, segments, goal_mask, via_masks, tracking,
                                     FORCE_REGULARISATION, _fingerprint(key, m),
                                     None if self.compiler else self.compile_dir)
        self._nlps[key] = nlp
        if self.compiler is not None:
            self.compiler.submit(key, nlp.oracle, nlp.options, nlp.fingerprint)
        return nlp, False

    def adopt_compiled(self, wait: float = 0.0) -> int:
        """Swap in the compiled solvers of the background compiles that are done (waiting
        up to ``wait`` s for the pending ones); how many. Called before every solve."""
        if self.compiler is None:
            return 0
        done = self.compiler.finished(wait)
        for key, solver, options in done:
            nlp = self._nlps.get(key)
            if nlp is not None:
                nlp.solver, nlp.options, nlp.compiled = solver, options, True
                nlp.warm_solver = None  # rebuilt from the compiled options on first use
        return len(done)

    def prepare(self, problem: ManipulationProblem) -> float:
        """Build (and cache) the NLP of this problem's structure and its model's
        re-integrator, without solving: a service's warm-up. Returns the build time [s]
        (0 when already cached)."""
        nlp, hit = self._build(problem)
        self.model(problem).reintegrator(4)
        return 0.0 if hit else nlp.build_time

    # ...................................................................................
    def initial_state(self, problem: ManipulationProblem) -> FloatArray:
        """The state at t = 0, the fingers' joints by inverse kinematics; ProblemError
        saying why the initial grasp is impossible (unreachable, outside the joint limits,
        not in force closure)."""
        from .finger import PAPER_SEED, inverse_kinematics

        m = self.model(problem)
        lay = m.layout
        x = np.zeros(m.nx)
        if problem.palm is not None:
            x[0:5] = problem.palm.initial
        else:
            assert problem.initial_pose is not None
            x[0:3] = problem.initial_pose.position
            q = np.asarray(problem.initial_pose.orientation, dtype=float)
            x[3:7] = q / np.linalg.norm(q)
        for i, c in enumerate(problem.fingers):
            x[lay.x_eta(i)] = c.initial
        prm = m.params(np.asarray(problem.object.dimensions, dtype=float), _charts(problem))
        out = m.cartesian(x, prm)
        R_pf, p_pf = np.asarray(out[2]), np.asarray(out[3])
        errs: list[tuple[str, str]] = []
        for i, c in enumerate(problem.fingers):
            seed = np.asarray(c.q_seed if c.q_seed is not None else
                              PAPER_SEED[: c.finger.nq], dtype=float)
            if len(seed) < c.finger.nq:
                seed = np.concatenate([seed, np.zeros(c.finger.nq - len(seed))])
            ik = inverse_kinematics(c.finger, R_pf[:, 3 * i:3 * i + 3], p_pf[:, i], seed)
            name = f"fingers[{i}].initial"
            if not ik.converged:
                errs.append((name, f"the finger cannot reach the initial grasp: after "
                                   f"inverse kinematics its pad is {ik.position_error:.3g} m "
                                   f"and {ik.orientation_error:.3g} rad from it"))
            elif not ik.within_limits:
                errs.append((name, "the initial grasp needs joint angles outside the "
                                   "finger's limits"))
            x[lay.x_q(i)] = ik.q
        pts, nrm = np.asarray(out[4]).T[None], np.asarray(out[5]).T[None]
        phi, _, onto = force_angles(pts, nrm)
        cone = math.atan(problem.mu)
        if not (phi[0] < cone and onto[0]):
            errs.append(("fingers", f"the initial grasp is outside the friction cone (not in "
                                    f"force closure): grasp angle "
                                    f"{math.degrees(phi[0]):.2f} deg >= atan(mu) = "
                                    f"{math.degrees(cone):.2f} deg, by "
                                    f"{math.degrees(phi[0] - cone):.2f} deg"
                         if onto[0] else "the initial grasp's contacts cannot resist every "
                                         "wrench (grasp map not onto)"))
        if errs:
            raise ProblemError(errs)
        return x

    def solve(self, problem: ManipulationProblem,
              warm_start: WarmStart | ManipulationSolution | None = None
              ) -> ManipulationSolution:
        """Plan; ProblemError (before any NLP is built) on bad input or an impossible
        initial grasp. When IPOPT converges but the certificate finds the grid too coarse
        (slip between collocation points, closure, re-integration defects, tracking between
        points), the plan is re-solved on a grid twice as fine, warm-started, up to
        ``max_refinements`` times.

        ``warm_start``: a previous plan of a similar problem (a solution, or its
        :attr:`ManipulationSolution.warm_start`), the initial guess instead of the
        planner's own; when IPOPT does not converge from it, the plan is solved again from
        the planner's own guess (within the time limit).
        """
        problem.validate()
        self.adopt_compiled()
        warm = warm_start.warm_start if isinstance(warm_start, ManipulationSolution) \
            else warm_start
        if warm is not None:
            m = self.model(problem)
            errs = warm.errors("warm_start", m.nx, m.nu)
            if errs:
                raise ProblemError(errs)
        deadline = time.perf_counter() + problem.options.time_limit
        x0 = self.initial_state(problem)
        sol = self._solve_once(problem, x0, warm, deadline)
        build, solve, iters = sol.build_time, sol.solve_time, sol.iterations
        if warm is not None and sol.status not in (Status.SOLVED, Status.INACCURATE) \
                and time.perf_counter() < deadline:
            sol = self._solve_once(problem, x0, None, deadline)
            build, solve, iters = build + sol.build_time, solve + sol.solve_time, \
                iters + sol.iterations
        refinements = 0
        # failures that shrink with the grid (what happens between collocation points)
        discretisation = ("max_slip_speed_", "max_spin_rate_", "max_closure",
                          "max_length_defect", "max_angle_defect", "max_joint_defect",
                          "max_gap_error_", "max_tracking_", "max_joint_limit_violation_")
        while (sol.status is Status.INACCURATE
               and refinements < problem.max_refinements
               and 2 * problem.n_intervals <= MAX_INTERVALS
               and all(f.startswith(discretisation) for f in sol.certificate_failures)
               and time.perf_counter() < deadline):
            refinements += 1
            problem = problem.with_intervals(2 * problem.n_intervals)
            sol = self._solve_once(problem, x0, sol.warm_start, deadline)
            build, solve, iters = build + sol.build_time, solve + sol.solve_time, \
                iters + sol.iterations
        return replace(sol, build_time=build, solve_time=solve, iterations=iters,
                       refinements=refinements)

    def _scales(self, problem: ManipulationProblem, m: _Model
                ) -> tuple[FloatArray, FloatArray]:
        L, T = problem.object.length_scale, problem.duration
        lay = m.layout
        return (np.asarray(lay.x_scale(L), dtype=float),
                np.asarray(lay.u_scale(L, T), dtype=float))

    @staticmethod
    def parameters(problem: ManipulationProblem, nlp: _NLP) -> FloatArray:
        """The NLP parameter vector of a problem (its structure's NLP ``nlp``): object,
        segment durations, palm goal and via-points, charts, weights, cone, tracking
        tolerances and the desired poses at every collocation point."""
        segments, tb = problem.segments()
        t_nodes = node_times(segments, tb)
        tm = (t_nodes[:-1] + t_nodes[1:]) / 2
        charts = _charts(problem)
        shape = np.asarray(problem.object.dimensions, dtype=float)
        L = problem.object.length_scale
        goal = np.zeros(5)
        vias = np.zeros((5, 0))
        if problem.palm is not None:
            goal = np.array([problem.palm.goal.get(c, 0.0) for c in CONTACT_COORDS])
            vias = np.array([[vp.coords.get(c, 0.0) for c in CONTACT_COORDS]
                             for vp in problem.palm.via_points]).T.reshape(5, -1)
        tr = problem.tracking
        weights = [problem.object_effort_weight, problem.finger_effort_weight,
                   problem.joint_effort_weight, problem.grasp_weight, tr.position_weight,
                   tr.orientation_weight]
        tol = [1e6 if tr.position_tolerance is None else
               (TRACKING_BOUND_SHRINK * tr.position_tolerance / L) ** 2,
               1e6 if tr.orientation_tolerance is None else
               1 - math.cos(TRACKING_BOUND_SHRINK * tr.orientation_tolerance)]
        if problem.motion is not None:
            Rd, Pd = problem.motion.at(np.concatenate([t_nodes, tm]))
            Pd_, Rd_ = Pd.T, Rd.transpose(0, 2, 1).reshape(-1, 9).T  # column-major vec
        else:
            Pd_, Rd_ = np.zeros((3, 0)), np.zeros((9, 0))
        return np.asarray(nlp.params(shape, np.diff(tb), goal, vias, np.concatenate(
            [R.ravel(order="F") for R in charts]), weights, cone_cosine(problem.mu), tol,
            Pd_, Rd_)).ravel()

    def _solve_once(self, problem: ManipulationProblem, x0: FloatArray,
                    warm: WarmStart | None, deadline: float
                    ) -> ManipulationSolution:
        nlp, hit = self._build(problem)
        build_time = 0.0 if hit else nlp.build_time
        m = self.model(problem)
        x_scale, u_scale = self._scales(problem, m)
        segments, tb = problem.segments()
        t_nodes = node_times(segments, tb)
        n = len(t_nodes) - 1
        charts = _charts(problem)
        shape = np.asarray(problem.object.dimensions, dtype=float)
        prm = m.params(shape, charts)
        p = self.parameters(problem, nlp)
        lbx, ubx = self._bounds(problem, nlp, m, x0, x_scale, u_scale)
        if warm is None:
            X, Xm, U, Um = self._guess(problem, m, nlp, x0, t_nodes)
        else:
            X, Xm, U, Um = warm.on_grid(t_nodes, nlp.hs.left_cols, nlp.hs.right_cols,
                                        n + len(nlp.hs.segments))
            X[0] = x0  # the fixed initial state, exactly
        Sg, Fg = self._epigraph(problem, m, np.vstack([X, Xm]), prm)
        w0 = nlp.pack((X / x_scale).T, (Xm / x_scale).T, (U / u_scale).T, (Um / u_scale).T,
                      Sg[None, : n + 1], Sg[None, n + 1:], Fg)
        w0 = np.clip(np.asarray(w0).ravel(), lbx, ubx)
        solver, duals = nlp.solver, {}
        mult = warm.nlp_point_for(nlp.fingerprint, len(lbx), len(nlp.lbg)) \
            if warm is not None else None
        if mult is not None:  # the previous primal-dual point of this very NLP
            # states and inputs as interpolated above (this problem's scaling), the
            # epigraph and internal-force variables as they were
            n_xu = nlp.hs.w.numel()
            w0[n_xu:] = np.clip(mult.w[n_xu:], lbx[n_xu:], ubx[n_xu:])
            if nlp.warm_solver is None:
                t_build = time.perf_counter()
                nlp.warm_solver = ca.nlpsol("manipulation_warm", "ipopt", nlp.oracle,
                                            {**nlp.options, **IPOPT_WARM_OPTIONS})
                build_time += time.perf_counter() - t_build
            solver, duals = nlp.warm_solver, {"lam_x0": mult.lam_x, "lam_g0": mult.lam_g}
        nlp.stop.arm(deadline, problem.options.max_iter)
        t_solve = time.perf_counter()
        res = solver(x0=w0, p=p, lbx=lbx, ubx=ubx, lbg=nlp.lbg, ubg=nlp.ubg, **duals)
        solve_time = time.perf_counter() - t_solve
        stats = solver.stats()
        raw = str(stats["return_status"])
        status = nlp.stop.reason if raw == "User_Requested_Stop" and nlp.stop.reason \
            else status_from_ipopt(raw)
        Xs, Xms, Us, Ums = (np.asarray(a) for a in nlp.unpack(res["x"])[:4])
        X, Xm = Xs.T * x_scale, Xms.T * x_scale
        Ucols, Um = Us.T * u_scale, Ums.T * u_scale
        U0, U1 = Ucols[nlp.hs.left_cols], Ucols[nlp.hs.right_cols]
        sol = self._solution(problem, m, status, raw, int(stats["iter_count"]), build_time,
                             solve_time, t_nodes, X, Xm, U0, Um, U1, prm)
        point = [np.asarray(res[k]).ravel() for k in ("x", "lam_x", "lam_g")]
        if not all(np.all(np.isfinite(a)) for a in point):
            return sol
        return replace(sol, nlp_point=NlpPoint(nlp.fingerprint, *point))

    # ...................................................................................
    @staticmethod
    def _bounds(problem: ManipulationProblem, nlp: _NLP, m: _Model, x0: FloatArray,
                x_scale: FloatArray, u_scale: FloatArray) -> tuple[FloatArray, FloatArray]:
        n = nlp.hs.n_intervals
        n_seg = len(nlp.hs.segments)
        L = problem.object.length_scale
        u_lim = math.pi / 2 - problem.pole_margin
        inf = np.inf
        if problem.palm is not None:
            ext = problem.palm.palm_half_extent / L
            hi = [ext, ext, u_lim, inf, inf]
            uhi = [problem.palm.max_contact_speed] * 2
        else:
            hi = [MAX_POSITION / L] * 3 + [1.5] * 4
            uhi = [problem.max_object_speed] * 3 + [problem.max_object_rate] * 3
        lo = [-h for h in hi]
        for c in problem.fingers:
            pad = (float(c.finger.pad_half_size) - problem.pad_margin) / L
            # joint limits backed off at the collocation points, so that the motion between
            # them (checked by the certificate) stays inside the limits themselves
            lower, upper = np.asarray(c.finger.lower), np.asarray(c.finger.upper)
            back = np.minimum(JOINT_LIMIT_MARGIN, 0.01 * (upper - lower))
            hi += [pad, pad, u_lim, inf, inf, *(upper - back)]
            lo += [-pad, -pad, -u_lim, -inf, -inf, *(lower + back)]
            uhi += [100.0, 100.0, *np.asarray(c.finger.velocity_limit)]
        xb_hi, xb_lo = np.array(hi), np.array(lo)
        lo_x, hi_x = np.tile(xb_lo, (n + 1, 1)), np.tile(xb_hi, (n + 1, 1))
        lo_x[0] = hi_x[0] = x0 / x_scale
        lo_xm, hi_xm = np.tile(xb_lo, (n, 1)), np.tile(xb_hi, (n, 1))
        ub_in = np.array(uhi) / u_scale
        lo_u, hi_u = np.tile(-ub_in, (n + n_seg, 1)), np.tile(ub_in, (n + n_seg, 1))
        lo_um, hi_um = np.tile(-ub_in, (n, 1)), np.tile(ub_in, (n, 1))
        zeros_s, twos_s = np.zeros((1, n + 1)), 2 * np.ones((1, n + 1))
        big = 1e3 * np.ones((3 * nlp.n_force, 2 * n + 1))
        lbx = nlp.pack(lo_x.T, lo_xm.T, lo_u.T, lo_um.T, zeros_s, zeros_s[:, :n], -big)
        ubx = nlp.pack(hi_x.T, hi_xm.T, hi_u.T, hi_um.T, twos_s, twos_s[:, :n], big)
        return np.asarray(lbx).ravel(), np.asarray(ubx).ravel()

    @staticmethod
    def _epigraph(problem: ManipulationProblem, m: _Model, Xall: FloatArray,
                  prm: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Grasp epigraph values and internal-force guesses at the given states."""
        k = len(Xall)
        out = m.mapped("cartesian", k)(Xall.T, prm)
        nc = m.n_contacts
        pts = np.asarray(out[4]).T.reshape(k, nc, 3)
        nrm = np.asarray(out[5]).T.reshape(k, nc, 3)
        if nc == 2:
            phi, _, _ = force_angles(pts, nrm)
            return np.clip(1 - np.cos(phi), 0.0, 2.0), np.zeros((0, k))
        # a pushing guess: each contact pushes along its inward normal (scaled so that the
        # pushes sum to nc); IPOPT restores equilibrium
        F = -nrm.reshape(k, 3 * nc).T
        return np.full(k, 0.5), F

    def _object_guess(self, problem: ManipulationProblem, m: _Model, x0: FloatArray,
                      ts: FloatArray, prm: FloatArray) -> tuple[
                          FloatArray, FloatArray, Any, Any]:
        """Object block states and inputs at ts, pose(t) -> (R (k,3,3), p (k,3)), and the
        palm plan's inputs w(t) (None when no palm plan was made)."""
        T = problem.duration
        if problem.palm is not None:
            base = problem.palm_problem()
            if base.goal or base.via_points:
                plan = self._palm.solve(base, certify=False)  # a guess: no certificate

                def pose(t: FloatArray) -> tuple[FloatArray, FloatArray]:
                    tr = plan.sample(np.clip(t, 0.0, T))
                    return tr.object_rotation, tr.object_position

                def palm_w(t: FloatArray) -> FloatArray:
                    return plan.sample(t).w

                smp = plan.sample(ts)
                return smp.eta, smp.w, pose, palm_w
            xs = np.tile(x0, (len(ts), 1))
            R0, p0 = (np.asarray(a) for a in m.cartesian(x0, prm)[:2])

            def still(t: FloatArray) -> tuple[FloatArray, FloatArray]:
                t = np.atleast_1d(t)
                return np.tile(R0, (len(t), 1, 1)), np.tile(p0.ravel(), (len(t), 1))

            return xs[:, 0:5], np.zeros((len(ts), 2)), still, None
        assert problem.motion is not None
        motion = problem.motion

        def pose_m(t: FloatArray) -> tuple[FloatArray, FloatArray]:
            return motion.at(t)

        R, pos = motion.at(ts)
        quats = quaternion_wxyz(R)
        for i in range(1, len(quats)):  # sign continuity
            if np.dot(quats[i], quats[i - 1]) < 0:
                quats[i] = -quats[i]
        if np.dot(quats[0], x0[3:7]) < 0:
            quats = -quats
        dt = 1e-5 * T
        Rp, pp = motion.at(ts + dt)
        Rn, pn = motion.at(ts - dt)
        tp, tn = np.clip(ts + dt, 0, T), np.clip(ts - dt, 0, T)
        span = (tp - tn)[:, None]
        v = (pp - pn) / span
        Wb = np.einsum("kji,kjl->kil", R, Rp - Rn) / span[:, :, None]  # R^T dR/dt
        omega = np.stack([Wb[:, 2, 1] - Wb[:, 1, 2], Wb[:, 0, 2] - Wb[:, 2, 0],
                          Wb[:, 1, 0] - Wb[:, 0, 1]], axis=1) / 2
        return np.hstack([pos, quats]), np.hstack([v, omega]), pose_m, None

    def _guess(self, problem: ManipulationProblem, m: _Model, nlp: _NLP, x0: FloatArray,
               t_nodes: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """A consistent initial guess: the object's motion (the ball-on-palm plan, or the
        desired motion); each fingertip's contact point kept where it started relative to
        the object's centre (palm frame), its contact coordinates integrated with the
        rolling equations; the joints by inverse kinematics along the way (closure holds);
        joint rates by finite differences."""
        from .finger import inverse_kinematics, inverse_kinematics_batch

        lay = m.layout
        charts = _charts(problem)
        shape = np.asarray(problem.object.dimensions, dtype=float)
        prm = m.params(shape, charts)
        n = len(t_nodes) - 1
        tm = (t_nodes[:-1] + t_nodes[1:]) / 2
        ts = np.sort(np.concatenate([t_nodes, tm]))  # node, mid, node, ...
        Xo, Wo, pose, palm_w = self._object_guess(problem, m, x0, ts, prm)
        cart0 = m.cartesian(x0, prm)
        p_obj0 = np.asarray(cart0[1]).ravel()
        pts0 = np.asarray(cart0[4])
        X = np.zeros((len(ts), m.nx))
        W = np.zeros((len(ts), m.nu))
        X[:, : lay.n_obj_x], W[:, : lay.n_obj_u] = Xo, Wo
        X[0, : lay.n_obj_x] = x0[: lay.n_obj_x]
        dt = 1e-4 * problem.duration
        palm = problem.palm is not None
        for i, c in enumerate(problem.fingers):
            offset = pts0[:, i + palm] - p_obj0
            Rc = charts[i + palm]

            def ball_point(t: FloatArray, offset: FloatArray = offset,
                           Rc: FloatArray = Rc) -> FloatArray:
                R, _ = pose(t)
                pts = np.einsum("kji,j->ki", R, offset)  # R^T offset
                return np.asarray(m.surface.inverse(pts @ Rc, shape))  # rows Rc^T p

            alpha = ball_point(ts)
            rate = (ball_point(ts + dt) - ball_point(ts - dt)) / (2 * dt)
            rate[:, 1] = ((rate[:, 1] * 2 * dt + np.pi) % (2 * np.pi) - np.pi) / (2 * dt)
            ef = np.zeros((len(ts), 5))
            ef[:, 2:4] = alpha
            ef[0] = c.initial
            pad = np.asarray(m.roll(len(ts) - 1)(  # the pad point and angle, RK4 steps
                ef[0, [0, 1, 4]], alpha[:-1].T, rate[:-1].T, rate[1:].T, np.diff(ts)[None],
                np.tile(shape[:, None], (1, len(ts) - 1)))).T
            ef[1:, 0:2], ef[1:, 4] = pad[:, 0:2], pad[:, 2]
            X[:, lay.x_eta(i)] = ef
            W[:, lay.u_w(i)] = rate
        # joints by IK along the way, every finger: the pads' poses do not depend on the
        # joints (one batched evaluation); one batched IK from the initial grasp's joints,
        # and a sequential one from the previous point's where that does not converge
        X[0] = x0
        out = m.mapped("cartesian", len(ts))(X.T, prm)
        R_all = np.asarray(out[2]).reshape(3, len(ts), -1, 3)  # (3, k, finger, 3)
        p_all = np.asarray(out[3]).reshape(3, len(ts), -1)  # (3, k, finger)
        for i, c in enumerate(problem.fingers):
            q0 = x0[lay.x_q(i)]
            R_i, p_i = R_all[:, :, i, :].transpose(1, 0, 2), p_all[:, :, i].T
            qs, ok = inverse_kinematics_batch(c.finger, R_i, p_i, q0, tol=IK_GUESS_TOL)
            qs[0] = q0
            for j in (np.flatnonzero(~ok[1:]) + 1).tolist():  # from a neighbour instead
                qs[j] = inverse_kinematics(c.finger, R_i[j], p_i[j], qs[j - 1],
                                           tol=IK_GUESS_TOL).q
            X[:, lay.x_q(i)] = qs
            W[:, lay.u_qd(i)] = np.gradient(qs, ts, axis=0)
        Ucols = np.zeros((n + len(nlp.hs.segments), m.nu))
        Ucols[nlp.hs.left_cols] = W[0:-1:2]
        Ucols[nlp.hs.right_cols] = W[2::2]
        if palm_w is not None:  # the palm plan's inputs jump at via-points: both sides
            Ucols[:, 0:2] = node_inputs(palm_w, t_nodes, nlp.hs.left_cols,
                                        nlp.hs.right_cols, len(Ucols))
        return X[0::2], X[1::2], Ucols, W[1::2]

    # ...................................................................................
    def _solution(self, problem: ManipulationProblem, m: _Model, status: Status, raw: str,
                  iterations: int, build_time: float, solve_time: float, t_nodes: FloatArray,
                  X: FloatArray, Xm: FloatArray, U0: FloatArray, Um: FloatArray,
                  U1: FloatArray, prm: FloatArray) -> ManipulationSolution:
        lay = m.layout
        tm = (t_nodes[:-1] + t_nodes[1:]) / 2
        order = np.argsort(np.concatenate([t_nodes, tm]), kind="stable")
        t = np.concatenate([t_nodes, tm])[order]
        Xg = np.vstack([X, Xm])[order]
        Ug = np.vstack([np.vstack([U0, U1[-1:]]), Um])[order]
        k = len(t)
        xdot = np.asarray(m.mapped("dynamics", k)(Xg.T, Ug.T, prm)).T
        cart = m.mapped("cartesian", k)(Xg.T, prm)
        nc, nf = m.n_contacts, len(problem.fingers)
        R_po = np.asarray(cart[0]).T.reshape(k, 3, 3).transpose(0, 2, 1)
        p_po = np.asarray(cart[1]).T
        R_pf = np.asarray(cart[2]).T.reshape(k, nf, 3, 3).transpose(0, 1, 3, 2) \
            if nf else np.zeros((k, 0, 3, 3))
        p_pf = np.asarray(cart[3]).T.reshape(k, nf, 3)
        pts = np.asarray(cart[4]).T.reshape(k, nc, 3)
        nrm = np.asarray(cart[5]).T.reshape(k, nc, 3)
        laws = m.mapped("laws", k)(Xg.T, xdot.T, prm)
        v_obj, w_obj = np.asarray(laws[0]).T, np.asarray(laws[1]).T
        phi, angles, _ = force_angles(pts, nrm)
        margin = math.atan(problem.mu) - phi
        contacts: list[ContactTrajectory] = []
        if problem.palm is not None:
            contacts.append(ContactTrajectory("palm", "palm", Xg[:, 0:5], xdot[:, 0:5],
                                              Ug[:, 0:2], pts[:, 0], nrm[:, 0],
                                              angles[:, 0]))
        fingers: list[FingerTrajectory] = []
        palm = problem.palm is not None
        for i, c in enumerate(problem.fingers):
            name = c.name or f"finger{i}"
            e = lay.x_eta(i)
            contacts.append(ContactTrajectory(name, "finger", Xg[:, e], xdot[:, e],
                                              Ug[:, lay.u_w(i)], pts[:, i + palm],
                                              nrm[:, i + palm], angles[:, i + palm]))
            fingers.append(FingerTrajectory(name, tuple(c.finger.joint_names),
                                            Xg[:, lay.x_q(i)], Ug[:, lay.u_qd(i)],
                                            p_pf[:, i], R_pf[:, i]))
        Rd = Pd = ep = ea = None
        if problem.motion is not None:
            Rd, Pd = problem.motion.at(t)
            ep = np.linalg.norm(p_po - Pd, axis=1)
            ea = rotation_angle_between(Rd, R_po)
        segments, _ = problem.segments()
        ends = [0, *np.cumsum(segments).tolist()]
        goal_error = _goal_errors(problem, X, ends)
        cert, failures = self._certify(problem, m, t_nodes, X, U0, Um, U1, prm)
        if status is Status.SOLVED and failures:
            status = Status.INACCURATE
        message = {
            Status.SOLVED: "converged; certificate passed",
            Status.INACCURATE: "converged, but the certificate failed: " + "; ".join(failures),
        }.get(status, f"not solved: IPOPT {raw}; the last iterate is returned")
        return ManipulationSolution(
            status=status, message=message, raw_status=raw, iterations=iterations,
            build_time=build_time, solve_time=solve_time, t=t, object_position=p_po,
            object_rotation=R_po, object_velocity=v_obj, object_angular_velocity=w_obj,
            contacts=tuple(contacts), fingers=tuple(fingers), grasp_angle=phi,
            cone_margin=margin, desired_position=Pd, desired_rotation=Rd,
            tracking_position_error=ep, tracking_angle_error=ea, goal_error=goal_error,
            certificate=cert, certificate_failures=failures, X=Xg, U=Ug)

    def _certify(self, problem: ManipulationProblem, m: _Model, t_nodes: FloatArray,
                 X: FloatArray, U0: FloatArray, Um: FloatArray, U1: FloatArray,
                 prm: FloatArray) -> tuple[dict[str, float], tuple[str, ...]]:
        """Re-integrate the inputs (CVODES) and check the laws along that motion, each
        finger placed by Pinocchio's forward kinematics of its re-integrated joints."""
        if not all(np.all(np.isfinite(a)) for a in (X, U0, Um, U1)):
            return {}, ("the plan has non-finite states or inputs",)
        lay = m.layout
        F = m.reintegrator(4)
        try:
            Xr, sx, su = reintegrate(F, X[0], t_nodes, U0, Um, U1, prm, 4)
        except RuntimeError as exc:  # CVODES gave up: the plan is not a smooth motion
            return {}, (f"re-integration failed: {str(exc).splitlines()[-1]}",)
        n = len(sx)
        xd = np.asarray(m.mapped("dynamics", n)(sx.T, su.T, prm))
        laws = dict(zip(m.laws.name_out(), (np.asarray(a).T for a in
                                            m.mapped("laws", n)(sx.T, xd, prm)), strict=True))
        cart = m.mapped("cartesian", n)(sx.T, prm)
        nc, nf = m.n_contacts, len(problem.fingers)
        R_pf = np.asarray(cart[2]).T.reshape(n, nf, 3, 3).transpose(0, 1, 3, 2) \
            if nf else np.zeros((n, 0, 3, 3))
        p_pf = np.asarray(cart[3]).T.reshape(n, nf, 3)
        R_po = np.asarray(cart[0]).T.reshape(n, 3, 3).transpose(0, 2, 1)
        p_po = np.asarray(cart[1]).T
        pts = np.asarray(cart[4]).T.reshape(n, nc, 3)
        nrm = np.asarray(cart[5]).T.reshape(n, nc, 3)
        L = problem.object.length_scale
        shape = np.asarray(problem.object.dimensions, dtype=float)
        o = problem.options
        d = Xr - X
        speed = float(np.max(np.abs(laws["v_obj"]))) + L * float(
            np.max(np.abs(laws["omega_obj"]))) + L * float(np.max(np.abs(su)))
        cert: dict[str, float] = {
            "max_length_defect": float(np.max(np.abs(d[:, lay.length_columns()]))),
            "max_angle_defect": float(np.max(np.abs(d[:, lay.angle_columns()]))),
        }
        tol: dict[str, float] = {
            "max_length_defect": max(o.cert_position_tol, 1e-5),
            "max_angle_defect": o.cert_angle_tol * 10,
        }
        if nf:
            cert["max_joint_defect"] = float(np.max(np.abs(d[:, lay.joint_columns()])))
            tol["max_joint_defect"] = o.cert_angle_tol * 10
        if problem.palm is not None:
            cert["max_slip_speed_palm"] = float(np.max(np.linalg.norm(laws["slip_palm"],
                                                                      axis=1)))
            cert["max_spin_rate_palm"] = float(np.max(np.abs(laws["spin_palm"])))
            # the object touches the palm: support function of its shape along -z (no chart)
            heights = m.surface.support_heights(-R_po[:, 2, :], shape)  # rows R^T (-e_z)
            cert["max_height_error_palm"] = float(np.max(np.abs(p_po[:, 2] - heights)))
            tol["max_slip_speed_palm"] = 1e-8 * max(speed, 1e-3)
            tol["max_spin_rate_palm"] = 1e-8 * max(speed / L, 1e-3)
            tol["max_height_error_palm"] = 1e-9
        pos_err = rot_err = 0.0
        for i, c in enumerate(problem.fingers):
            name = c.name or f"finger{i}"
            q_i = sx[:, lay.x_q(i)]
            poses = [c.finger.fingertip_pose_pin(q) for q in q_i]  # Pinocchio, point by point
            R_pin = np.array([pose[0] for pose in poses])
            p_pin = np.array([pose[1] for pose in poses])
            pos_err = max(pos_err, float(np.max(np.linalg.norm(p_pin - p_pf[:, i], axis=1))))
            tr = np.einsum("kji,kji->k", R_pin, R_pf[:, i])  # trace(R_pin^T R_pf)
            rot_err = max(rot_err, float(np.max(np.arccos(np.clip((tr - 1) / 2, -1, 1)))))
            # the pad's plane is tangent to the object: support function along the pad normal
            pad_n = laws[f"pad_normal_{i}"]
            h = m.surface.support_heights(np.einsum("kji,kj->ki", R_po, -pad_n), shape)
            gap = laws[f"centre_above_pad_{i}"].ravel() - h
            cert[f"max_slip_speed_{name}"] = float(np.max(np.linalg.norm(laws[f"slip_{i}"],
                                                                         axis=1)))
            cert[f"max_spin_rate_{name}"] = float(np.max(np.abs(laws[f"spin_{i}"])))
            cert[f"max_gap_error_{name}"] = float(np.max(np.abs(gap)))
            cert[f"max_pad_excursion_{name}"] = float(np.max(np.abs(
                laws[f"pad_point_{i}"][:, 0:2])))
            cert[f"max_joint_limit_violation_{name}"] = float(max(
                np.max(q_i - c.finger.upper), np.max(c.finger.lower - q_i), 0.0))
            tol[f"max_slip_speed_{name}"] = 1e-2 * max(speed, 1e-3)
            tol[f"max_spin_rate_{name}"] = 1e-2 * max(speed / L, 1e-3)
            tol[f"max_gap_error_{name}"] = 1e-4
            tol[f"max_pad_excursion_{name}"] = float(c.finger.pad_half_size)
            tol[f"max_joint_limit_violation_{name}"] = 1e-6
        if nf:
            cert["max_closure_position_error"] = pos_err
            cert["max_closure_orientation_error"] = rot_err
            tol["max_closure_position_error"] = 1e-4
            tol["max_closure_orientation_error"] = 1e-3
        ts = np.concatenate([[t_nodes[0]], np.concatenate([
            t_nodes[k] + (t_nodes[k + 1] - t_nodes[k]) * np.linspace(0, 1, 5)[1:]
            for k in range(len(t_nodes) - 1)])])
        if problem.motion is not None:
            Rd, Pd = problem.motion.at(ts)
            cert["max_tracking_position_error"] = float(np.max(np.linalg.norm(p_po - Pd,
                                                                              axis=1)))
            cert["max_tracking_angle_error"] = float(np.max(rotation_angle_between(Rd, R_po)))
            tr = problem.tracking
            if tr.position_tolerance is not None:
                tol["max_tracking_position_error"] = tr.position_tolerance
            if tr.orientation_tolerance is not None:
                tol["max_tracking_angle_error"] = tr.orientation_tolerance
        phi, _, onto = force_angles(pts, nrm)
        cert["min_cone_margin"] = float(np.min(math.atan(problem.mu) - phi))
        cert["max_grasp_angle"] = float(np.max(phi))
        failures = [f"{k} {cert[k]:.3g} > {tol[k]:.3g}" for k in tol if not cert[k] <= tol[k]]
        if not cert["min_cone_margin"] >= -1e-6:
            failures.append(f"min_cone_margin {cert['min_cone_margin']:.3g} < 0 (force "
                            f"closure lost)")
        if not np.all(onto):
            failures.append("the grasp map is not onto at some sample (force closure lost)")
        cert.update({f"tol_{k}": v for k, v in tol.items()})
        return cert, tuple(failures)
