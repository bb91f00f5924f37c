"""Conversions at the edge: wire requests -> core problems, core solutions -> wire results.

The wire models live in ``dexroll_client.models`` (one definition, shared with the
client); the optimisation core (``ocp``) knows nothing of them.

Every planner is reached the same way, by the command line, the worker processes and the
HTTP API alike: :func:`request_errors` (cheap: what is wrong with a request, each field
named), then :func:`solve` (plan it; the wire result and the core's solution).

Warm starts: a result's ``collocation`` block is the core solution's ``warm_start`` (states
and inputs at the collocation points) with every column named (:func:`collocation_names`);
a request's inline ``warm_start`` becomes an :class:`ocp.collocation.WarmStart` for the
planner (a ``job_id`` is the service's to resolve before the request gets here).
"""

from __future__ import annotations

import math
import threading
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from pydantic import TypeAdapter, ValidationError

from dexroll_client.models import (
    MAX_FINGER_JOINTS,
    AnyPlanResult,
    BallOnPalmRequest,
    CertificateModel,
    CollocationModel,
    ContactTrajectoryModel,
    FieldError,
    FingerCertificateModel,
    FingerJointsModel,
    FingerModelSpec,
    FingerPlanResult,
    FingerStatsModel,
    FingerTrajectoryModel,
    HandModel,
    ManipulationCertificateModel,
    ManipulationRequest,
    ManipulationResult,
    ManipulationStatsModel,
    ManipulationTrajectoryModel,
    MotionSamplesModel,
    NlpPointModel,
    OneFingerRequest,
    PlanRequest,
    PlanResult,
    PlanStatus,
    SolverModel,
    StatsModel,
    TrajectoryModel,
)
from ocp.ball_on_palm import BallOnPalmPlanner, object_pose
from ocp.ball_on_palm import plan as plan_ball_on_palm
from ocp.collocation import NlpPoint, WarmStart
from ocp.finger import FingerModel, load_finger
from ocp.greedy import GreedyResult, greedy_plan
from ocp.hands import Hand, load_hand
from ocp.manipulation import (
    DesiredMotion,
    Fingertip,
    ManipulationPlanner,
    ManipulationProblem,
    ManipulationSolution,
    MotionStep,
    ObjectPose,
    Palm,
    Tracking,
)
from ocp.one_finger import FingerContact, OneFingerPlanner, OneFingerProblem, OneFingerSolution
from ocp.problem import BallOnPalmProblem, ObjectSpec, ProblemError, SolverOptions, ViaPoint
from ocp.solution import Solution, Trajectory, quaternion_wxyz
from ocp.surfaces import SURFACES, rotation_from_vector

__all__ = [
    "REQUEST",
    "RESULT",
    "FingerCache",
    "collocation_names",
    "error_result",
    "invalid_result",
    "planner_of",
    "request_errors",
    "result_from_finger_solution",
    "result_from_manipulation_solution",
    "result_from_solution",
    "rotation_vector",
    "solve",
    "to_problem",
    "validation_errors",
    "warm_start_errors",
    "warm_start_of",
    "wire_field",
]

#: Validates a request of any planner (``planner`` picks the model; default ball_on_palm).
REQUEST: TypeAdapter[PlanRequest] = TypeAdapter(PlanRequest)
#: Parses a result of any planner (by its ``planner``; default ball_on_palm).
RESULT: TypeAdapter[AnyPlanResult] = TypeAdapter(AnyPlanResult)

_PLANNER_TAGS = ("ball_on_palm", "one_finger", "manipulation")
_MOTION_TAGS = ("steps", "samples")


class FingerCache:
    """A process's finger models, hands and finger planners, kept together.

    The planners cache their NLPs per finger object, so the same request finger (or hand)
    must map to the same :class:`~ocp.finger.FingerModel` objects from job to job (cached
    here by URDF text, tip frame, mount and pad size; hands by name and mounts) for its NLP
    to be reused. The one-finger planner and the manipulation planner share one NLP cache
    (the one-finger planner is the general one with one finger's data). With more than
    ``max_fingers`` distinct fingers (a hand's fingers count), the fingers, the hands and
    the planners (with the NLPs they hold for them) are dropped together and start afresh,
    which bounds the memory. Thread-safe (one lock for loading and checking).
    """

    def __init__(self, max_fingers: int = 16, compile_dir: Path | None = None,
                 background: bool = False) -> None:
        self.max_fingers = max_fingers
        #: where the finger planners compile and cache their NLPs (None: not compiled), and
        #: whether in a background thread while the virtual machine solves
        #: (:class:`ocp.manipulation.ManipulationPlanner`)
        self.compile_dir = compile_dir
        self.background = background
        self.lock = threading.RLock()
        self._fingers: dict[tuple[Any, ...], FingerModel] = {}
        self._hands: dict[tuple[Any, ...], Hand] = {}
        self._planner: OneFingerPlanner | None = None

    @property
    def planner(self) -> OneFingerPlanner:
        """The process's one-finger planner (its NLP cache lives as long as the fingers)."""
        with self.lock:
            if self._planner is None:
                self._planner = OneFingerPlanner(ManipulationPlanner(self.compile_dir,
                                                                     self.background))
            return self._planner

    @property
    def manipulation(self) -> ManipulationPlanner:
        """The process's manipulation planner (the one-finger planner's own)."""
        return self.planner.general

    def _count(self) -> int:
        return len(self._fingers) + sum(len(h.fingers) for h in self._hands.values())

    def _make_room(self, n: int) -> None:
        if self._count() + n > self.max_fingers:
            self._fingers.clear()
            self._hands.clear()
            self._planner = None  # its NLPs refer to the fingers just dropped

    @staticmethod
    def _key(spec: FingerModelSpec) -> tuple[Any, ...]:
        source = f"builtin:{spec.builtin or 'k3s'}" if spec.urdf is None else spec.urdf
        return (source, spec.tip_frame,
                None if spec.base_position is None else tuple(spec.base_position),
                None if spec.base_rotation is None else tuple(spec.base_rotation),
                spec.pad_half_size)

    def finger(self, spec: FingerModelSpec) -> FingerModel:
        """The finger of a request; ProblemError naming ``finger.urdf`` or
        ``finger.tip_frame`` when it cannot be loaded."""
        key = self._key(spec)
        with self.lock:
            cached = self._fingers.get(key)
            if cached is not None:
                return cached
            finger = _load(spec)
            self._make_room(1)
            self._fingers[key] = finger
            return finger

    def hand(self, spec: HandModel) -> Hand:
        """The built-in hand of a request (its fingers on the request's mounts);
        ProblemError naming ``hand.mounts`` when they do not fit the hand."""
        mounts = None if spec.mounts is None else tuple(
            (tuple(m.position), tuple(m.rotation)) for m in spec.mounts)
        key = (spec.builtin, mounts)
        with self.lock:
            cached = self._hands.get(key)
            if cached is not None:
                return cached
            hand = _load_hand(spec)
            self._make_room(len(hand.fingers))
            self._hands[key] = hand
            return hand


def _load(spec: FingerModelSpec) -> FingerModel:
    if spec.urdf is not None and not spec.urdf.lstrip().startswith("<"):
        # load_finger would read a file of that name: never for a request
        raise ProblemError([("finger.urdf", "must be the URDF document itself (XML text)")])
    try:
        finger = load_finger(
            urdf=spec.urdf, tip_frame=spec.tip_frame,
            base_rotation=None if spec.base_rotation is None else
            rotation_from_vector(spec.base_rotation),
            base_position=spec.base_position,
            pad_half_size=spec.pad_half_size)
    except Exception as exc:  # whatever a user's URDF does to the loader, it is the URDF's
        reason = str(exc) or type(exc).__name__
        field = "finger.tip_frame" if repr(spec.tip_frame) in reason else "finger.urdf"
        raise ProblemError([(field, reason)]) from exc
    if finger.nq > MAX_FINGER_JOINTS:
        raise ProblemError([("finger.urdf", f"the finger has {finger.nq} joints; at most "
                                            f"{MAX_FINGER_JOINTS} are supported")])
    return finger


def _load_hand(spec: HandModel) -> Hand:
    mounts = None if spec.mounts is None else [
        (rotation_from_vector(m.rotation), np.asarray(m.position, dtype=float))
        for m in spec.mounts]
    try:
        return load_hand(spec.builtin, mounts=mounts)
    except ValueError as exc:  # the mounts do not fit the hand
        raise ProblemError([("hand.mounts" if spec.mounts is not None else "hand.builtin",
                             str(exc))]) from exc


def hand_finger_name(hand: Hand, index: int) -> str:
    """The hand's name of its finger ``index`` (its tip frame's prefix: f1, f2, ...)."""
    return hand.tip_frames[index].removesuffix("_fingertip")


#: The fingers (and one-finger planner) of this process.
FINGERS = FingerCache()


def _base_problem(request: BallOnPalmRequest | OneFingerRequest) -> BallOnPalmProblem:
    o = request.solver
    rv = request.object.chart_rotation
    return BallOnPalmProblem(
        object=ObjectSpec(request.object.shape, tuple(request.object.dimensions),
                          (rv[0], rv[1], rv[2])),
        initial=request.initial.as_tuple(),
        goal=request.goal.as_dict(),
        duration=request.duration,
        via_points=tuple(ViaPoint(vp.time, vp.coords.as_dict()) for vp in request.via_points),
        n_intervals=request.n_intervals,
        pole_margin=request.pole_margin,
        max_contact_speed=request.max_contact_speed,
        palm_half_extent=request.palm_half_extent,
        max_refinements=request.max_refinements,
        options=SolverOptions(max_iter=o.max_iter, time_limit=o.time_limit,
                              cert_position_tol=o.cert_position_tol,
                              cert_angle_tol=o.cert_angle_tol),
    )


# -- manipulation requests -------------------------------------------------------------------

def _solver_options(o: SolverModel) -> SolverOptions:
    return SolverOptions(max_iter=o.max_iter, time_limit=o.time_limit,
                         cert_position_tol=o.cert_position_tol,
                         cert_angle_tol=o.cert_angle_tol)


def _prefixed(prefix: str, exc: ProblemError) -> ProblemError:
    return ProblemError([(f"{prefix}.{f}", r) for f, r in exc.errors])


def _motion(request: ManipulationRequest, start: ObjectPose | None
            ) -> tuple[DesiredMotion | None, list[tuple[str, str]]]:
    """The desired motion of a request from the object's pose ``start`` at t = 0, or the
    reasons it has none (wire names)."""
    m = request.motion
    if m is None:
        return None, []
    if isinstance(m, MotionSamplesModel):  # the core checks the knots
        return DesiredMotion(tuple(m.times),
                             tuple(tuple(q) for q in m.orientations_wxyz),  # type: ignore[misc]
                             tuple(tuple(p) for p in m.positions),  # type: ignore[misc]
                             m.smooth), []
    errors = [(f"motion.steps[{i}].axis", "must not be zero: a rotation needs an axis")
              for i, s in enumerate(m.steps) if math.hypot(*s.axis) < 1e-12]
    total = math.fsum(s.duration for s in m.steps)
    if abs(total - request.duration) > 1e-9 * max(1.0, request.duration):
        errors.append(("motion.steps", f"the steps' durations add up to {total:.6g} s, not "
                                       f"the duration {request.duration} s"))
    if errors:
        return None, errors
    if start is None:  # the request is invalid (its errors name why): any start will do
        start = ObjectPose()
    steps = [MotionStep(s.duration, (s.axis[0], s.axis[1], s.axis[2]), s.angle,
                        (s.translation[0], s.translation[1], s.translation[2]))
             for s in m.steps]
    return DesiredMotion.from_steps(start, steps, m.smooth), []


def _palm_pose(obj: ObjectSpec, palm: Palm) -> ObjectPose | None:
    """The object's pose on the palm at t = 0 (None when the object's data cannot give
    one: the core's checks name the field)."""
    if obj.shape not in SURFACES or obj.surface.validate_params(obj.dimensions):
        return None
    try:
        R, p = object_pose(obj, palm.initial)
    except Exception:  # invalid data the core's checks report by name
        return None
    if not (np.all(np.isfinite(R)) and np.all(np.isfinite(p))):
        return None
    w, x, y, z = (float(c) for c in quaternion_wxyz(R))
    return ObjectPose((w, x, y, z), (float(p[0]), float(p[1]), float(p[2])))


def _manipulation_problem(request: ManipulationRequest, cache: FingerCache
                          ) -> ManipulationProblem:
    """The core's problem of a manipulation request; ProblemError naming the wire fields
    the core cannot even be given (a finger that does not load, a hand finger that does
    not exist, duplicate names, a motion step without an axis)."""
    errors: list[tuple[str, str]] = []
    hand: Hand | None = None
    if request.hand is not None:
        try:
            hand = cache.hand(request.hand)
        except ProblemError as exc:
            errors += exc.errors
    tips: list[Fingertip] = []
    names: dict[str, int] = {}
    for i, f in enumerate(request.fingers):
        where = f"fingers[{i}]"
        model: FingerModel | None = None
        default_name = f"finger{i}"
        default_seed: tuple[float, ...] | None = None
        if f.finger is not None:
            try:
                model = cache.finger(f.finger)
            except ProblemError as exc:
                errors += _prefixed(where, exc).errors
        elif f.hand_finger is not None:
            if request.hand is None:
                errors.append((f"{where}.hand_finger", "no `hand` in the request to pick a "
                                                       "finger from"))
            elif hand is not None:
                n = len(hand.fingers)
                if f.hand_finger >= n:
                    errors.append((f"{where}.hand_finger",
                                   f"the {request.hand.builtin} hand has {n} fingers "
                                   f"(indices 0 to {n - 1}), got {f.hand_finger}"))
                else:
                    model = hand.fingers[f.hand_finger]
                    default_name = hand_finger_name(hand, f.hand_finger)
                    if hand.nominal_q is not None:
                        default_seed = hand.nominal_q[f.hand_finger]
        name = f.name or default_name
        if name == "palm":
            errors.append((f"{where}.name", "'palm' names the palm contact; choose another"))
        elif name in names:
            errors.append((f"{where}.name", f"{name!r} is also the name of "
                                            f"fingers[{names[name]}]; names must be unique"))
        names.setdefault(name, i)
        if model is not None:
            rv = f.chart_rotation
            tips.append(Fingertip(model, f.initial.as_tuple(), (rv[0], rv[1], rv[2]),
                                  default_seed if f.q_seed is None else tuple(f.q_seed),
                                  name))
    rv = request.object.chart_rotation
    obj = ObjectSpec(request.object.shape, tuple(request.object.dimensions),
                     (rv[0], rv[1], rv[2]))
    start = motion_start = None
    if request.initial_pose is not None:
        q, p = request.initial_pose.orientation_wxyz, request.initial_pose.position
        start = motion_start = ObjectPose((q[0], q[1], q[2], q[3]), (p[0], p[1], p[2]))
    palm = None
    if request.palm is not None:
        pm = request.palm
        palm = Palm(pm.initial.as_tuple(), pm.goal.as_dict(),
                    tuple(ViaPoint(vp.time, vp.coords.as_dict()) for vp in pm.via_points),
                    pm.palm_half_extent, pm.max_contact_speed)
        if start is not None:
            errors.append(("initial_pose", "not used with a palm: the palm contact "
                                           "(palm.initial) fixes the object's pose at t = 0"))
        motion_start = _palm_pose(obj, palm)
    motion, motion_errors = _motion(request, motion_start)
    errors += motion_errors
    if errors:
        raise ProblemError(errors)
    tr = request.tracking
    return ManipulationProblem(
        object=obj, fingers=tuple(tips), duration=request.duration, palm=palm,
        initial_pose=start,
        motion=motion,
        tracking=Tracking(tr.position_weight, tr.orientation_weight, tr.position_tolerance,
                          tr.orientation_tolerance),
        mu=request.mu, object_effort_weight=request.object_effort_weight,
        finger_effort_weight=request.finger_effort_weight,
        joint_effort_weight=request.joint_effort_weight, grasp_weight=request.grasp_weight,
        pad_margin=request.pad_margin, n_intervals=request.n_intervals,
        pole_margin=request.pole_margin, max_object_speed=request.max_object_speed,
        max_object_rate=request.max_object_rate, max_refinements=request.max_refinements,
        options=_solver_options(request.solver))


def _wire_name(field: str, request: ManipulationRequest) -> str:
    """The wire name of a field the core names (``ManipulationProblem.errors()``)."""
    if field.startswith("options."):
        return "solver." + field.removeprefix("options.")
    if field == "initial_pose.orientation":
        return "initial_pose.orientation_wxyz"
    if field == "motion" or field.startswith(("motion.", "motion[")):
        if isinstance(request.motion, MotionSamplesModel):
            # the core's motion[i].orientation / .position are the wire's i-th knot
            head, _, rest = field.partition("].")
            if rest in ("orientation", "position"):
                index = head.removeprefix("motion[")
                what = "orientations_wxyz" if rest == "orientation" else "positions"
                return f"motion.{what}[{index}]"
            return field
        # a motion made of steps: its knots are the steps' ends
        return "motion.steps" if field != "motion" else field
    return field


def _manipulation_errors(problem: ManipulationProblem, request: ManipulationRequest
                         ) -> list[tuple[str, str]]:
    return [(_wire_name(f, request), r) for f, r in problem.errors()]


def to_problem(request: PlanRequest, fingers: FingerCache | None = None
               ) -> BallOnPalmProblem | OneFingerProblem | ManipulationProblem:
    """The core's problem for a request (the core then validates it as a whole: see
    ``problem.errors()``, or :func:`request_errors` for every check). A one-finger request
    loads its finger (cached in ``fingers``, default this process's); ProblemError naming
    ``finger.urdf``/``finger.tip_frame`` when it cannot. A manipulation request loads its
    hand and fingers the same way; ProblemError naming the wire fields (e.g.
    ``fingers[1].hand_finger``, ``motion.steps[2].axis``) the core cannot be given."""
    if isinstance(request, BallOnPalmRequest):
        return _base_problem(request)
    if isinstance(request, ManipulationRequest):
        return _manipulation_problem(request, fingers or FINGERS)
    if isinstance(request, OneFingerRequest):
        finger = (fingers or FINGERS).finger(request.finger)
        c = request.finger_contact
        rv = c.chart_rotation
        return OneFingerProblem(
            base=_base_problem(request), finger=finger,
            contact=FingerContact(initial=c.initial.as_tuple(),
                                  chart_rotation=(rv[0], rv[1], rv[2]),
                                  q_seed=None if c.q_seed is None else tuple(c.q_seed)),
            mu=request.mu, grasp_weight=request.grasp_weight,
            finger_effort_weight=request.finger_effort_weight,
            joint_effort_weight=request.joint_effort_weight, pad_margin=request.pad_margin)
    raise TypeError(f"no planner for {type(request).__name__}")  # pragma: no cover


def _seed_errors(problem: OneFingerProblem) -> list[tuple[str, str]]:
    nq = int(problem.finger.nq)
    seed = problem.contact.q_seed
    if seed is not None and len(seed) != nq:
        return [("finger_contact.q_seed", f"must have one angle per joint: the finger has "
                                          f"{nq} joints, got {len(seed)}")]
    if seed is None and nq > 6:
        return [("finger_contact.q_seed", f"required for a finger with {nq} joints (the "
                                          "default seed has 6)")]
    return []


# -- warm starts -----------------------------------------------------------------------------

#: Columns of a ball-on-palm plan: the contact coordinates; the palm contact velocity.
BALL_ON_PALM_STATES = ("x", "y", "u", "v", "psi")
BALL_ON_PALM_INPUTS = ("w_x", "w_y")
#: Columns of a free object (no palm): position and quaternion (w, x, y, z); velocity (palm
#: frame) and angular velocity in the object's own frame (ocp.manipulation._quat_rate_sym).
_FREE_OBJECT_STATES = ("object.position.x", "object.position.y", "object.position.z",
                       "object.orientation.w", "object.orientation.x",
                       "object.orientation.y", "object.orientation.z")
_FREE_OBJECT_INPUTS = ("object.velocity.x", "object.velocity.y", "object.velocity.z",
                       "object.angular_velocity_body.x", "object.angular_velocity_body.y",
                       "object.angular_velocity_body.z")


def _grasp_names(palm: bool, fingers: Sequence[tuple[str, Sequence[str]]]
                 ) -> tuple[list[str], list[str]]:
    """(state names, input names) of the general planner's layout (``ocp.manipulation``'s
    ``_Layout``): the object block (the palm contact, or the free object's pose), then per
    fingertip (its contact name, its joint names) the contact coordinates and the joints."""
    if palm:
        states = [f"palm.{c}" for c in BALL_ON_PALM_STATES]
        inputs = [f"palm.{c}" for c in BALL_ON_PALM_INPUTS]
    else:
        states, inputs = list(_FREE_OBJECT_STATES), list(_FREE_OBJECT_INPUTS)
    for name, joints in fingers:
        states += [f"{name}.{c}" for c in BALL_ON_PALM_STATES]
        states += [f"{name}.q.{j}" for j in joints]
        inputs += [f"{name}.w_u", f"{name}.w_v"] + [f"{name}.q_dot.{j}" for j in joints]
    return states, inputs


def collocation_names(problem: BallOnPalmProblem | OneFingerProblem | ManipulationProblem
                      ) -> tuple[list[str], list[str]]:
    """(state names, input names): the columns of a plan of ``problem`` at its collocation
    points (a result's ``collocation`` block, a request's ``warm_start``). A one-finger plan
    is the general planner's with the palm and one fingertip named ``finger``."""
    if isinstance(problem, BallOnPalmProblem):
        return list(BALL_ON_PALM_STATES), list(BALL_ON_PALM_INPUTS)
    if isinstance(problem, OneFingerProblem):
        return _grasp_names(True, [("finger", tuple(problem.finger.joint_names))])
    return _grasp_names(problem.palm is not None,
                        [(tip.name or f"finger{i}", tuple(tip.finger.joint_names))
                         for i, tip in enumerate(problem.fingers)])


def _collocation(ws: WarmStart, names: tuple[list[str], list[str]]
                 ) -> CollocationModel | None:
    """The wire block of a solution's ``warm_start`` (None when it does not fit its names
    or holds non-finite values: JSON has no NaN)."""
    t, x, u = (np.asarray(a, dtype=float) for a in (ws.t, ws.x, ws.u))
    states, inputs = names
    if t.ndim != 1 or len(t) < 2 or x.shape != (len(t), len(states)) \
            or u.shape != (len(t), len(inputs)):
        return None
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(x)) and np.all(np.isfinite(u))):
        return None
    pt = ws.nlp_point
    point = None if pt is None else NlpPointModel(
        nlp=pt.nlp, w=pt.w.tolist(), lam_x=pt.lam_x.tolist(), lam_g=pt.lam_g.tolist())
    return CollocationModel(t=_rows(t), x=_rows(x), u=_rows(u), state_names=states,
                            input_names=inputs, nlp_point=point)


def warm_start_of(request: PlanRequest) -> WarmStart | None:
    """The core's warm start of a request (None without one). ProblemError naming
    ``warm_start.job_id`` for a job id: the service resolves those at submission; the
    planners need the plan itself."""
    ws = request.warm_start
    if ws is None:
        return None
    if ws.t is None or ws.x is None or ws.u is None:
        raise ProblemError([("warm_start.job_id", "a job id is looked up by the service "
                                                  "(POST /v1/plans); here give the plan "
                                                  "itself: `t`, `x`, `u` (a result's "
                                                  "`collocation` block)")])
    pt = ws.nlp_point
    point = None if pt is None else NlpPoint(pt.nlp, np.asarray(pt.w, dtype=float),
                                             np.asarray(pt.lam_x, dtype=float),
                                             np.asarray(pt.lam_g, dtype=float))
    return WarmStart.of(ws.t, ws.x, ws.u, point)


def _names_mismatch(given: Sequence[str], expected: Sequence[str]) -> str:
    diff = next((i for i, (a, b) in enumerate(zip(given, expected, strict=False)) if a != b),
                min(len(given), len(expected)))
    where = (f"column {diff} is {given[diff]!r} in the warm start, "
             f"{expected[diff]!r} in this request's plan" if diff < min(len(given),
                                                                        len(expected))
             else f"the warm start has {len(given)} columns, this request's plan "
                  f"{len(expected)}")
    shown = ", ".join(expected[:24]) + (", ..." if len(expected) > 24 else "")
    return (f"not this request's columns: {where} (a plan of another planner, grasp, hand "
            f"or finger?). This request's: {shown}. Drop the names to use the plan anyway")


def warm_start_errors(request: PlanRequest,
                      problem: BallOnPalmProblem | OneFingerProblem | ManipulationProblem
                      ) -> list[tuple[str, str]]:
    """What is wrong with a request's ``warm_start`` for its problem, fields named
    (``warm_start.t``, ``warm_start.x``, ``warm_start.state_names``, ...)."""
    ws = request.warm_start
    if ws is None:
        return []
    if isinstance(request, OneFingerRequest) and request.method == "greedy":
        return [("warm_start", "not used by the greedy method (it chooses each step from "
                               "the current state, with no initial guess): drop it or use "
                               "method 'collocation'")]
    try:
        warm = warm_start_of(request)
    except ProblemError as exc:
        return list(exc.errors)
    assert warm is not None
    states, inputs = collocation_names(problem)
    errors = warm.errors("warm_start", len(states), len(inputs))
    for field, given, expected in (("state_names", ws.state_names, states),
                                   ("input_names", ws.input_names, inputs)):
        if given is not None and list(given) != expected:
            errors.append((f"warm_start.{field}", _names_mismatch(given, expected)))
    return errors


def request_errors(request: PlanRequest, fingers: FingerCache | None = None
                   ) -> list[tuple[str, str]]:
    """Everything wrong with a (schema-valid) request, as (field, reason) pairs; [] when it
    can be planned. Cheap (no NLP is built): the core's checks of the problem and, for a
    request with fingers, loading them and the inverse kinematics of the initial grasp
    (reachable, within the joint limits, in force closure / inside the friction cone), and
    that a ``warm_start`` fits the planner (its columns, see :func:`warm_start_errors`)."""
    cache = fingers or FINGERS
    with cache.lock:
        try:
            problem = to_problem(request, cache)
        except ProblemError as exc:
            return list(exc.errors)
        if isinstance(problem, ManipulationProblem):
            assert isinstance(request, ManipulationRequest)
            errors = _manipulation_errors(problem, request)
            if not errors:
                try:
                    cache.manipulation.initial_state(problem)
                except ProblemError as exc:
                    errors += exc.errors
            return errors + warm_start_errors(request, problem)
        errors = list(problem.errors())
        if isinstance(problem, OneFingerProblem):
            errors += _seed_errors(problem)
            if not errors:
                try:
                    cache.planner.initial_grasp(problem)
                except ProblemError as exc:
                    errors += exc.errors
        return errors + warm_start_errors(request, problem)


def solve(request: PlanRequest, palm: BallOnPalmPlanner | None = None,
          fingers: FingerCache | None = None
          ) -> tuple[AnyPlanResult,
                     Solution | OneFingerSolution | GreedyResult | ManipulationSolution]:
    """Plan a request: (the wire result, the core's solution). ProblemError for a request
    that cannot be planned (:func:`request_errors` names the same fields beforehand).
    ``palm``: the ball-on-palm planner (default: the process-wide one); ``fingers``: the
    fingers, hands and finger planners (default: this process's). A request's inline
    ``warm_start`` is passed to the planner (the planner raises ProblemError naming
    ``warm_start.x`` etc. when it does not fit)."""
    warm = warm_start_of(request)
    if isinstance(request, BallOnPalmRequest):
        problem = _base_problem(request)
        sol = palm.solve(problem, warm) if palm is not None else \
            plan_ball_on_palm(problem, warm)
        return result_from_solution(sol, request.sample_times), sol
    cache = fingers or FINGERS
    if isinstance(request, ManipulationRequest):
        with cache.lock:  # the hand and fingers, by the cache's rules
            manipulation = _manipulation_problem(request, cache)
            planner = cache.manipulation
        errors = _manipulation_errors(manipulation, request)
        if errors:
            raise ProblemError(errors)
        manip_sol = planner.solve(manipulation, warm)
        return result_from_manipulation_solution(manip_sol), manip_sol
    finger_problem = to_problem(request, cache)
    assert isinstance(finger_problem, OneFingerProblem)
    errors = _seed_errors(finger_problem)
    if errors:
        raise ProblemError(errors)
    if request.method == "greedy":
        if warm is not None:
            raise ProblemError(warm_start_errors(request, finger_problem))
        greedy = greedy_plan(finger_problem, planner=cache.planner)
        return result_from_greedy(greedy, finger_problem.finger.joint_names), greedy
    finger_sol = cache.planner.solve(finger_problem, warm)
    return result_from_finger_solution(finger_sol, finger_problem.finger.joint_names), \
        finger_sol


def rotation_vector(R: Any) -> list[float]:
    """The rotation vector [rad] (angle in [0, pi]) of a rotation matrix."""
    w, *v = (float(c) for c in quaternion_wxyz(np.asarray(R, dtype=float)).reshape(4))
    norm = math.sqrt(sum(c * c for c in v))
    if norm < 1e-15:
        return [0.0, 0.0, 0.0]
    angle = 2.0 * math.atan2(norm, w)
    return [angle * c / norm for c in v]


def wire_field(loc: Sequence[int | str]) -> str:
    """The dotted field of a pydantic error location in a request body, without the tags
    that discriminated unions put in it (the planner's first, a motion's kind)."""
    parts = [str(p) for p in loc]
    if parts and parts[0] in _PLANNER_TAGS:
        parts = parts[1:]
    if len(parts) > 1 and parts[0] == "motion" and parts[1] in _MOTION_TAGS:
        del parts[1]  # the tag of the motion's kind (also a manipulation request's)
    return ".".join(parts)


def validation_errors(exc: ValidationError) -> list[tuple[str, str]]:
    """(field, reason) pairs of a pydantic error, with dotted field paths."""
    out = []
    for e in exc.errors(include_url=False):
        field = wire_field(e["loc"]) or "request"
        if e["type"] == "invalid_planner":
            field = "planner"
        out.append((field, str(e["msg"])))
    return out


def planner_of(raw: object) -> str:
    """The planner a decoded request asks for (for the shape of an invalid result)."""
    planner = raw.get("planner") if isinstance(raw, dict) else None
    return planner if planner in _PLANNER_TAGS else "ball_on_palm"


def invalid_result(errors: list[tuple[str, str]], planner: str = "ball_on_palm"
                   ) -> AnyPlanResult:
    message = "; ".join(f"{f}: {r}" for f, r in errors)
    fields = [FieldError(field=f, reason=r) for f, r in errors]
    if planner == "one_finger":
        return FingerPlanResult(status=PlanStatus.INVALID_INPUT, message=message,
                                errors=fields)
    if planner == "manipulation":
        return ManipulationResult(status=PlanStatus.INVALID_INPUT, message=message,
                                  errors=fields)
    return PlanResult(status=PlanStatus.INVALID_INPUT, message=message, errors=fields)


def error_result(message: str, planner: str = "ball_on_palm") -> AnyPlanResult:
    """The result of a planner that failed unexpectedly (status ``error``)."""
    if planner == "one_finger":
        return FingerPlanResult(status=PlanStatus.ERROR, message=message)
    if planner == "manipulation":
        return ManipulationResult(status=PlanStatus.ERROR, message=message)
    return PlanResult(status=PlanStatus.ERROR, message=message)


def _all_finite(d: dict[str, Any]) -> bool:
    return all(np.all(np.isfinite(np.asarray(v, dtype=float))) for v in d.values())


def _trajectory(traj: Trajectory) -> TrajectoryModel | None:
    d = traj.to_dict()
    if not _all_finite(d):
        return None  # JSON has no NaN; a diverged last iterate is reported by its status
    return TrajectoryModel(**d)


def _finite_or_none(x: float) -> float | None:
    return float(x) if np.isfinite(x) else None


def result_from_solution(sol: Solution, sample_times: list[float] | None = None
                         ) -> PlanResult:
    c = sol.certificate
    cert = CertificateModel(
        passed=c.passed, max_position_defect=_finite_or_none(c.max_position_defect),
        max_angle_defect=_finite_or_none(c.max_angle_defect),
        max_slip_speed=_finite_or_none(c.max_slip_speed),
        max_spin_rate=_finite_or_none(c.max_spin_rate),
        max_height_error=_finite_or_none(c.max_height_error),
        max_goal_error=_finite_or_none(c.max_goal_error), n_samples=c.n_samples,
        tolerances=dict(c.tolerances), failures=list(c.failures))
    stats: dict[str, Any] = sol.stats.to_dict()
    if not np.isfinite(stats["objective"]):
        stats["objective"] = -1.0
    grid = _trajectory(sol.grid)
    samples = _trajectory(sol.sample(sample_times)) if sample_times and grid else None
    message = sol.message if grid is not None else sol.message + " (non-finite iterate omitted)"
    goal_error = {k: v for k, v in sol.goal_error.items() if np.isfinite(v)}
    collocation = None if grid is None else _collocation(
        sol.warm_start, (list(BALL_ON_PALM_STATES), list(BALL_ON_PALM_INPUTS)))
    return PlanResult(status=PlanStatus(sol.status.value), message=message,
                      stats=StatsModel(**stats), goal_error=goal_error, certificate=cert,
                      grid=grid, samples=samples, collocation=collocation)


def _finger_trajectory(sol: OneFingerSolution | GreedyResult) -> FingerTrajectoryModel | None:
    if isinstance(sol, GreedyResult):  # its rates: differences of its steps
        eta_p_dot, eta_f_dot = np.gradient(sol.eta_p, sol.t, axis=0), np.gradient(
            sol.eta_f, sol.t, axis=0)
    else:
        eta_p_dot, eta_f_dot = sol.eta_p_dot, sol.eta_f_dot
    d: dict[str, Any] = {
        "t": sol.t, "eta_p": sol.eta_p, "eta_f": sol.eta_f, "eta_p_dot": eta_p_dot,
        "eta_f_dot": eta_f_dot, "q": sol.q, "q_dot": sol.q_dot,
        "w_p": sol.w_p, "w_f": sol.w_f, "object_position": sol.object_position,
        "object_orientation_wxyz": quaternion_wxyz(sol.object_rotation),
        "fingertip_position": sol.fingertip_position,
        "fingertip_orientation_wxyz": quaternion_wxyz(sol.fingertip_rotation),
        "palm_contact_point": sol.palm_contact_point,
        "finger_contact_point": sol.finger_contact_point,
        "finger_contact_normal": sol.finger_contact_normal,
        "grasp_angles": sol.grasp_angles, "cone_margin": sol.cone_margin}
    if not _all_finite(d):
        return None  # JSON has no NaN; a diverged last iterate is reported by its status
    return FingerTrajectoryModel(**{k: np.asarray(v, dtype=float).tolist()
                                    for k, v in d.items()})


def result_from_finger_solution(sol: OneFingerSolution, joint_names: Sequence[str] = ()
                                ) -> FingerPlanResult:
    """The wire result of a one-finger plan (``joint_names``: the finger's, in q order)."""
    values = {k: float(v) for k, v in sol.certificate.items()
              if not k.startswith("tol_") and math.isfinite(v)}
    tolerances = {k[len("tol_"):]: float(v) for k, v in sol.certificate.items()
                  if k.startswith("tol_") and math.isfinite(v)}
    failures = list(sol.certificate_failures)
    cert = FingerCertificateModel(passed=bool(values) and not failures, values=values,
                                  tolerances=tolerances, failures=failures)
    trajectory = _finger_trajectory(sol)
    message = sol.message if trajectory is not None else \
        sol.message + " (non-finite iterate omitted)"
    nq = int(np.shape(sol.q)[1]) if np.ndim(sol.q) == 2 else 0
    joints = list(joint_names) if len(joint_names) == nq else [f"j{i}" for i in range(nq)]
    collocation = None if trajectory is None else _collocation(
        sol.warm_start, _grasp_names(True, [("finger", joints)]))
    return FingerPlanResult(
        status=PlanStatus(sol.status.value), message=message,
        stats=FingerStatsModel(raw_status=sol.raw_status, iterations=sol.iterations,
                               build_time=sol.build_time, solve_time=sol.solve_time,
                               refinements=sol.refinements),
        goal_error={k: float(v) for k, v in sol.goal_error.items() if math.isfinite(v)},
        certificate=cert, joint_names=list(joint_names), trajectory=trajectory,
        collocation=collocation)


def result_from_greedy(res: GreedyResult, joint_names: Sequence[str] = ()) -> FingerPlanResult:
    """The wire result of a plan by the paper's greedy method. Its checks (closure of the
    pseudo-inverse joint rates against Pinocchio's FK, joint limits, friction cone, feasible
    steps) stand in the certificate; a plan with any failure is 'inaccurate'."""
    values = {
        "max_closure_position_error": float(res.closure_error[0]),
        "max_closure_orientation_error": float(res.closure_error[1]),
        "min_cone_margin": float(np.min(res.cone_margin)),
        "joint_limit_margin": float(res.joint_limit_margin),
        "max_velocity_ratio": float(res.max_velocity_ratio),
        "fallback_steps": float(res.fallback_steps),
        "palm_integration_error": float(res.palm_integration_error),
        "joint_effort": float(res.joint_effort),
    }
    values = {k: v for k, v in values.items() if math.isfinite(v)}
    failures = list(res.failures)
    cert = FingerCertificateModel(passed=not failures, values=values,
                                  tolerances={}, failures=failures)
    status = PlanStatus.SOLVED if not failures else PlanStatus.INACCURATE
    message = ("greedy plan (the paper's method); its checks passed" if not failures else
               "greedy plan (the paper's method) failed its checks: " + "; ".join(failures))
    return FingerPlanResult(
        status=status, message=message,
        stats=FingerStatsModel(raw_status="greedy", iterations=len(res.t) - 1, build_time=0.0,
                               solve_time=float(res.compute_time)),
        goal_error={k: float(v) for k, v in res.goal_error.items() if math.isfinite(v)},
        certificate=cert, joint_names=list(joint_names), trajectory=_finger_trajectory(res))


def _rows(a: Any) -> list[Any]:
    out: list[Any] = np.asarray(a, dtype=float).tolist()
    return out


def _certificate_parts(certificate: Mapping[str, float]
                       ) -> tuple[dict[str, float], dict[str, float]]:
    """(values, tolerances) of a core certificate dict (its ``tol_<key>`` entries are the
    tolerances), finite entries only."""
    values = {k: float(v) for k, v in certificate.items()
              if not k.startswith("tol_") and math.isfinite(v)}
    tolerances = {k.removeprefix("tol_"): float(v) for k, v in certificate.items()
                  if k.startswith("tol_") and math.isfinite(v)}
    return values, tolerances


def _manipulation_trajectory(sol: ManipulationSolution) -> ManipulationTrajectoryModel | None:
    arrays: dict[str, Any] = {
        "t": sol.t, "object_position": sol.object_position,
        "object_rotation": sol.object_rotation, "object_velocity": sol.object_velocity,
        "object_angular_velocity": sol.object_angular_velocity,
        "grasp_angle": sol.grasp_angle, "cone_margin": sol.cone_margin}
    optional = {"desired_position": sol.desired_position,
                "desired_rotation": sol.desired_rotation,
                "tracking_position_error": sol.tracking_position_error,
                "tracking_angle_error": sol.tracking_angle_error}
    arrays.update({k: v for k, v in optional.items() if v is not None})
    for c in sol.contacts:
        arrays.update({f"{c.name}.{k}": getattr(c, k) for k in
                       ("eta", "eta_dot", "w", "point", "normal", "force_angle")})
    for f in sol.fingers:
        arrays.update({f"{f.name}.{k}": getattr(f, k) for k in
                       ("q", "q_dot", "tip_position", "tip_rotation")})
    if not _all_finite(arrays):
        return None  # JSON has no NaN; a diverged last iterate is reported by its status
    return ManipulationTrajectoryModel(
        t=_rows(sol.t), object_position=_rows(sol.object_position),
        object_orientation_wxyz=_rows(quaternion_wxyz(sol.object_rotation)),
        object_velocity=_rows(sol.object_velocity),
        object_angular_velocity=_rows(sol.object_angular_velocity),
        contacts=[ContactTrajectoryModel(
            name=c.name, body="palm" if c.body == "palm" else "finger", eta=_rows(c.eta),
            eta_dot=_rows(c.eta_dot), w=_rows(c.w), point=_rows(c.point),
            normal=_rows(c.normal), force_angle=_rows(c.force_angle))
            for c in sol.contacts],
        fingers=[FingerJointsModel(
            name=f.name, joint_names=list(f.joint_names), q=_rows(f.q), q_dot=_rows(f.q_dot),
            tip_position=_rows(f.tip_position),
            tip_orientation_wxyz=_rows(quaternion_wxyz(f.tip_rotation)))
            for f in sol.fingers],
        grasp_angle=_rows(sol.grasp_angle), cone_margin=_rows(sol.cone_margin),
        desired_position=None if sol.desired_position is None else
        _rows(sol.desired_position),
        desired_orientation_wxyz=None if sol.desired_rotation is None else
        _rows(quaternion_wxyz(sol.desired_rotation)),
        tracking_position_error=None if sol.tracking_position_error is None else
        _rows(sol.tracking_position_error),
        tracking_angle_error=None if sol.tracking_angle_error is None else
        _rows(sol.tracking_angle_error))


def result_from_manipulation_solution(sol: ManipulationSolution) -> ManipulationResult:
    """The wire result of a manipulation plan. A plan with non-finite values (a diverged
    last iterate) keeps its status and drops its trajectory (JSON has no NaN)."""
    values, tolerances = _certificate_parts(sol.certificate)
    failures = list(sol.certificate_failures)
    cert = ManipulationCertificateModel(passed=bool(values) and not failures, values=values,
                                        tolerances=tolerances, failures=failures)
    trajectory = _manipulation_trajectory(sol)
    message = sol.message if trajectory is not None else \
        sol.message + " (non-finite iterate omitted)"
    status = PlanStatus(sol.status.value)
    if trajectory is None and status is PlanStatus.SOLVED:  # pragma: no cover - defensive
        status = PlanStatus.NUMERICAL_ERROR
    timing = [sol.build_time, sol.solve_time]
    collocation = None if trajectory is None else _collocation(
        sol.warm_start, _grasp_names(any(c.body == "palm" for c in sol.contacts),
                                     [(f.name, tuple(f.joint_names)) for f in sol.fingers]))
    return ManipulationResult(
        status=status, message=message,
        stats=ManipulationStatsModel(
            raw_status=sol.raw_status, iterations=sol.iterations,
            build_time=timing[0] if math.isfinite(timing[0]) else 0.0,
            solve_time=timing[1] if math.isfinite(timing[1]) else 0.0,
            refinements=sol.refinements, n_intervals=max((len(sol.t) - 1) // 2, 0)),
        goal_error={k: float(v) for k, v in sol.goal_error.items() if math.isfinite(v)},
        certificate=cert, trajectory=trajectory, collocation=collocation)
