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

import math
import time
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np
from numpy.typing import ArrayLike, NDArray

from .ball_on_palm import BallOnPalmPlanner, Structure, goal_errors
from .certificate import Certificate, CheckKind
from .certify import GRASP_TOLERANCES, TolerancePolicy, certify_grasp
from .collocation import NlpPoint, WarmStart, node_inputs, node_times
from .compiled import BackgroundCompiler
from .grasp import cone_cosine, force_angles
from .grasp_model import GraspModel
from .ipopt import IPOPT_WARM_OPTIONS
from .motion import DesiredMotion, MotionStep, ObjectPose, Tracking
from .nlp_blocks import NLP as _NLP
from .nlp_blocks import build_manipulation_nlp
from .problem import (
    CONTACT_COORDS,
    DEFAULT_FINGER_CHART_ROTATION,
    MAX_INTERVALS,
    MAX_POSITION,
    BallOnPalmProblem,
    ObjectSpec,
    ProblemError,
    SolverOptions,
    ViaPoint,
)
from .rotations import log_rotation, rotation_angle_between
from .solution import Status, status_from_ipopt
from .surfaces import SURFACES, rotation_from_vector

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
#: Weight of the size of the internal-force variables (3+ contacts) in the objective.
FORCE_REGULARISATION = 1e-3
#: Pose tolerance of the inverse kinematics along the initial guess [m, rad], the initial
#: grasp's own. (A guess closed to 1e-8 only sent IPOPT down another path on experiment 1:
#: the same 14 iterations, one with an inertia correction, 30 % more time.)
IK_GUESS_TOL = 1e-10


# -- problem data --------------------------------------------------------------------------------

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
    chart_rotation: tuple[float, float, float] = DEFAULT_FINGER_CHART_ROTATION
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
    #: How strictly the certificate checks the plan (:mod:`ocp.certify`).
    tolerances: TolerancePolicy = GRASP_TOLERANCES

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
    return tuple(float(c) for c in log_rotation(Rc))  # type: ignore[return-value]


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
    certificate: Certificate
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


# -- the planner -----------------------------------------------------------------------------

def _charts(problem: ManipulationProblem) -> list[FloatArray]:
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


@dataclass(frozen=True)
class GraspStructure:
    """What fixes the shape of a grasp's NLP (everything else is a parameter or a bound):
    the NLPs are cached by it. The fingers are compared by identity (the key keeps them
    alive); :meth:`fingerprint` names the same structure alike in another process."""

    shape: str
    palm: bool
    segments: tuple[int, ...]
    goal_mask: tuple[bool, ...]
    via_masks: tuple[tuple[bool, ...], ...]
    fingers: tuple[Any, ...]
    tracking: bool

    @staticmethod
    def of(problem: ManipulationProblem) -> GraspStructure:
        segments, _ = problem.segments()
        goal_mask: tuple[bool, ...] = (False,) * 5
        via_masks: tuple[tuple[bool, ...], ...] = ()
        if problem.palm is not None:
            st = Structure.of(problem.palm_problem())
            goal_mask, via_masks = st.goal_mask, st.via_masks
        return GraspStructure(problem.object.shape, problem.palm is not None, segments,
                              goal_mask, via_masks, tuple(c.finger for c in problem.fingers),
                              problem.motion is not None)

    @property
    def model_key(self) -> tuple[Any, ...]:
        """The part that fixes the grasp model (:class:`GraspModel`'s arguments)."""
        return (self.shape, self.palm, self.fingers)

    def fingerprint(self, m: GraspModel) -> str:
        """The structure as a string that another process computes alike: the fingers by
        their models (URDF, tip frame, mount), not by identity."""
        import hashlib

        parts = [repr((self.shape, self.palm, self.segments, self.goal_mask, self.via_masks,
                       self.tracking, m.nx, m.nu))]
        for f in self.fingers:
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
        self._models: dict[tuple[Any, ...], GraspModel] = {}
        self._nlps: dict[GraspStructure, _NLP] = {}
        self._palm = BallOnPalmPlanner()

    def model(self, problem: ManipulationProblem) -> GraspModel:
        key = (problem.object.shape, problem.palm is not None,
               tuple(c.finger for c in problem.fingers))
        if key not in self._models:
            self._models[key] = GraspModel(*key)
        return self._models[key]

    # ...................................................................................
    def _build(self, problem: ManipulationProblem) -> tuple[_NLP, bool]:
        key = GraspStructure.of(problem)
        if key in self._nlps:
            return self._nlps[key], True
        m = self.model(problem)
        nlp = build_manipulation_nlp(m, key.segments, key.goal_mask, key.via_masks,
                                     key.tracking, FORCE_REGULARISATION, key.fingerprint(m),
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
        x = np.zeros(m.nx)
        x[m.object.xs] = m.object.initial(problem)
        for tip in m.fingertips:
            x[tip.eta_cols] = tip.spec(problem).initial
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
            x[m.fingertips[i].q_cols] = ik.q
        pts, nrm = np.asarray(out[4]).T[None], np.asarray(out[5]).T[None]
        phi, _, onto = force_angles(pts, nrm)
        cone = math.atan(problem.mu)
        if m.n_contacts >= 2 and not (phi[0] < cone and onto[0]):
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
        # only failures that shrink with the grid (what happens between collocation
        # points), decided by the checks' kind
        while (sol.status is Status.INACCURATE
               and refinements < problem.max_refinements
               and 2 * problem.n_intervals <= MAX_INTERVALS
               and sol.certificate.failed_kinds() <= {CheckKind.DISCRETISATION}
               and time.perf_counter() < deadline):
            refinements += 1
            problem = problem.with_intervals(2 * problem.n_intervals)
            sol = self._solve_once(problem, x0, sol.warm_start, deadline)
            build, solve, iters = build + sol.build_time, solve + sol.solve_time, \
                iters + sol.iterations
        return replace(sol, build_time=build, solve_time=solve, iterations=iters,
                       refinements=refinements)

    def _scales(self, problem: ManipulationProblem, m: GraspModel
                ) -> tuple[FloatArray, FloatArray]:
        L, T = problem.object.length_scale, problem.duration
        return (np.asarray(m.x_scale(L), dtype=float),
                np.asarray(m.u_scale(L, T), dtype=float))

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
        return nlp.params.pack(
            shape=shape, seg_T=np.diff(tb), goal=goal, vias=vias,
            charts=np.concatenate([R.ravel(order="F") for R in charts]), weights=weights,
            ccone=[cone_cosine(problem.mu)], tol=tol, Pd=Pd_, Rd=Rd_)

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
                      Sg[:, : n + 1], Sg[:, n + 1:], Fg)
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
    def _bounds(problem: ManipulationProblem, nlp: _NLP, m: GraspModel, x0: FloatArray,
                x_scale: FloatArray, u_scale: FloatArray) -> tuple[FloatArray, FloatArray]:
        n = nlp.hs.n_intervals
        n_seg = len(nlp.hs.segments)
        lo: list[float] = []
        hi: list[float] = []
        uhi: list[float] = []
        for c in m.contacts:  # physical bounds, scaled as the states and inputs
            lo_c, hi_c, uhi_c = c.bounds(problem)
            lo, hi, uhi = lo + lo_c, hi + hi_c, uhi + uhi_c
        xb_hi, xb_lo = np.array(hi) / x_scale, np.array(lo) / x_scale
        lo_x, hi_x = np.tile(xb_lo, (n + 1, 1)), np.tile(xb_hi, (n + 1, 1))
        lo_x[0] = hi_x[0] = x0 / x_scale
        lo_xm, hi_xm = np.tile(xb_lo, (n, 1)), np.tile(xb_hi, (n, 1))
        ub_in = np.array(uhi) / u_scale
        lo_u, hi_u = np.tile(-ub_in, (n + n_seg, 1)), np.tile(ub_in, (n + n_seg, 1))
        lo_um, hi_um = np.tile(-ub_in, (n, 1)), np.tile(ub_in, (n, 1))
        ns = nlp.n_epigraph
        zeros_s, twos_s = np.zeros((ns, n + 1)), 2 * np.ones((ns, n + 1))
        big = 1e3 * np.ones((3 * nlp.n_force, 2 * n + 1))
        lbx = nlp.pack(lo_x.T, lo_xm.T, lo_u.T, lo_um.T, zeros_s, zeros_s[:, :n], -big)
        ubx = nlp.pack(hi_x.T, hi_xm.T, hi_u.T, hi_um.T, twos_s, twos_s[:, :n], big)
        return np.asarray(lbx).ravel(), np.asarray(ubx).ravel()

    @staticmethod
    def _epigraph(problem: ManipulationProblem, m: GraspModel, Xall: FloatArray,
                  prm: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Grasp epigraph values (1 x k; 0 x k for one contact) and internal-force guesses
        at the given states."""
        k = len(Xall)
        if m.n_contacts < 2:  # no force closure to certify: neither
            return np.zeros((0, k)), np.zeros((0, k))
        out = m.mapped("cartesian", k)(Xall.T, prm)
        nc = m.n_contacts
        pts = np.asarray(out[4]).T.reshape(k, nc, 3)
        nrm = np.asarray(out[5]).T.reshape(k, nc, 3)
        if nc == 2:
            phi, _, _ = force_angles(pts, nrm)
            return np.clip(1 - np.cos(phi), 0.0, 2.0)[None], np.zeros((0, k))
        # a pushing guess: each contact pushes along its inward normal (scaled so that the
        # pushes sum to nc); IPOPT restores equilibrium
        F = -nrm.reshape(k, 3 * nc).T
        return np.full((1, k), 0.5), F

    def _guess(self, problem: ManipulationProblem, m: GraspModel, nlp: _NLP, x0: FloatArray,
               t_nodes: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """A consistent initial guess: the object's motion (the ball-on-palm plan, or the
        desired motion); each fingertip's contact point kept where it started relative to
        the object's centre (palm frame), its contact coordinates integrated with the
        rolling equations; the joints by inverse kinematics along the way (closure holds);
        joint rates by finite differences."""
        from .finger import inverse_kinematics, inverse_kinematics_batch

        charts = _charts(problem)
        shape = np.asarray(problem.object.dimensions, dtype=float)
        prm = m.params(shape, charts)
        n = len(t_nodes) - 1
        tm = (t_nodes[:-1] + t_nodes[1:]) / 2
        ts = np.sort(np.concatenate([t_nodes, tm]))  # node, mid, node, ...
        cart0 = m.cartesian(x0, prm)
        obj = m.object
        Xo, Wo, pose, obj_w = obj.guess(problem, x0[obj.xs], ts, np.asarray(cart0[0]),
                                        np.asarray(cart0[1]).ravel(), self._palm)
        p_obj0 = np.asarray(cart0[1]).ravel()
        pts0 = np.asarray(cart0[4])
        X = np.zeros((len(ts), m.nx))
        W = np.zeros((len(ts), m.nu))
        X[:, obj.xs], W[:, obj.us] = Xo, Wo
        X[0, obj.xs] = x0[obj.xs]
        dt = 1e-4 * problem.duration
        for tip in m.fingertips:
            k = m.point_contacts.index(tip)
            offset = pts0[:, k] - p_obj0
            Rc = charts[k]

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
            ef[0] = tip.spec(problem).initial
            pad = np.asarray(m.roll(len(ts) - 1)(  # the pad point and angle, RK4 steps
                ef[0, [0, 1, 4]], alpha[:-1].T, rate[:-1].T, rate[1:].T, np.diff(ts)[None],
                np.tile(shape[:, None], (1, len(ts) - 1)))).T
            ef[1:, 0:2], ef[1:, 4] = pad[:, 0:2], pad[:, 2]
            X[:, tip.eta_cols] = ef
            W[:, tip.w_cols] = rate
        # joints by IK along the way, every finger: the pads' poses do not depend on the
        # joints (one batched evaluation); one batched IK from the initial grasp's joints,
        # and a sequential one from the previous point's where that does not converge
        X[0] = x0
        out = m.mapped("cartesian", len(ts))(X.T, prm)
        R_all = np.asarray(out[2]).reshape(3, len(ts), -1, 3)  # (3, k, finger, 3)
        p_all = np.asarray(out[3]).reshape(3, len(ts), -1)  # (3, k, finger)
        for i, tip in enumerate(m.fingertips):
            q0 = x0[tip.q_cols]
            R_i, p_i = R_all[:, :, i, :].transpose(1, 0, 2), p_all[:, :, i].T
            qs, ok = inverse_kinematics_batch(tip.finger, R_i, p_i, q0, tol=IK_GUESS_TOL)
            qs[0] = q0
            for j in (np.flatnonzero(~ok[1:]) + 1).tolist():  # from a neighbour instead
                qs[j] = inverse_kinematics(tip.finger, R_i[j], p_i[j], qs[j - 1],
                                           tol=IK_GUESS_TOL).q
            X[:, tip.q_cols] = qs
            W[:, tip.qd_cols] = np.gradient(qs, ts, axis=0)
        Ucols = np.zeros((n + len(nlp.hs.segments), m.nu))
        Ucols[nlp.hs.left_cols] = W[0:-1:2]
        Ucols[nlp.hs.right_cols] = W[2::2]
        if obj_w is not None:  # the palm plan's inputs jump at via-points: both sides
            Ucols[:, obj.us] = node_inputs(obj_w, t_nodes, nlp.hs.left_cols,
                                           nlp.hs.right_cols, len(Ucols))
        return X[0::2], X[1::2], Ucols, W[1::2]

    # ...................................................................................
    def _solution(self, problem: ManipulationProblem, m: GraspModel, status: Status, raw: str,
                  iterations: int, build_time: float, solve_time: float, t_nodes: FloatArray,
                  X: FloatArray, Xm: FloatArray, U0: FloatArray, Um: FloatArray,
                  U1: FloatArray, prm: FloatArray) -> ManipulationSolution:
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
        contacts = [ContactTrajectory(c.label(problem), c.body, Xg[:, c.eta_cols],
                                      xdot[:, c.eta_cols], Ug[:, c.w_cols], pts[:, k],
                                      nrm[:, k], angles[:, k])
                    for k, c in enumerate(m.point_contacts)]
        fingers = [FingerTrajectory(tip.label(problem), tuple(tip.finger.joint_names),
                                    Xg[:, tip.q_cols], Ug[:, tip.qd_cols], p_pf[:, i],
                                    R_pf[:, i]) for i, tip in enumerate(m.fingertips)]
        Rd = Pd = ep = ea = None
        if problem.motion is not None:
            Rd, Pd = problem.motion.at(t)
            ep = np.linalg.norm(p_po - Pd, axis=1)
            ea = rotation_angle_between(Rd, R_po)
        segments, _ = problem.segments()
        ends = [0, *np.cumsum(segments).tolist()]
        goal_error = support_goal_errors(problem, X, ends)
        cert = certify_grasp(problem, m, t_nodes, X, U0, Um, U1, prm, problem.tolerances)
        failures = cert.failures
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
