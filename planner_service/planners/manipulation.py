"""The manipulation planner: any grasp, an optional palm and one or more fingertips
(``ocp.solve.planner``), following a desired object motion and/or the palm's goals."""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

from dexroll_client.models import (
    ContactChartModel,
    GraspFingerModel,
    GraspSearchModel,
    GraspUsedModel,
    ManipulationCertificateModel,
    ManipulationRequest,
    ManipulationResult,
    ManipulationStatsModel,
    MotionSamplesModel,
    PlanStatus,
)
from ocp.ball_on_palm import object_pose
from ocp.geometry.rotations import log_rotation, quaternion_wxyz
from ocp.robots.finger import FingerModel
from ocp.robots.hands import Hand
from ocp.solve.planner import (
    DesiredMotion,
    Fingertip,
    ManipulationProblem,
    ManipulationSolution,
    MotionStep,
    ObjectPose,
    Palm,
    Tracking,
)
from ocp.spec.grasp import fingertips_on_charts
from ocp.spec.problem import ObjectSpec, ProblemError, ViaPoint

from .actuation import hand_actuation, torque_limit_errors, with_actuation
from .base import SOLVER_FIELDS, PlannerAdapter
from .cache import FingerCache, Planners, hand_finger_name
from .columns import ColumnNames, collocation_block, grasp_names, warm_start_of
from .common import (
    finger_certificate,
    force_spec,
    hand_fingers,
    object_spec,
    solver_options,
)
from .fields import FieldErrors, FieldMap, Rule
from .gait import gait_errors, solve_gait
from .samples import joint_trajectory_block, requested_times, samples_block
from .trajectory import manipulation_trajectory

__all__ = [
    "ManipulationAdapter",
    "manipulation_problem",
    "manipulation_summary",
    "result_from_manipulation_solution",
]

_POSE_FIELDS = FieldMap(Rule("initial_pose.orientation", "initial_pose.orientation_wxyz"))
#: The core's names of a manipulation problem -> the request's, for a motion given as
#: steps: the core's motion is the steps' knots (``motion.times``, ``motion[i]``), which
#: the request does not have; they are its ``motion.steps``.
MANIPULATION_FIELDS = SOLVER_FIELDS + _POSE_FIELDS + FieldMap(
    Rule("motion[{i}]", "motion.steps", keep_rest=False),
    Rule("motion.{*}", "motion.steps", keep_rest=False))
#: ... for a motion given as samples: the core's knot ``motion[i]`` is the request's i-th
#: orientation and position.
MANIPULATION_SAMPLES_FIELDS = SOLVER_FIELDS + _POSE_FIELDS + FieldMap(
    Rule("motion[{i}].orientation", "motion.orientations_wxyz[{i}]"),
    Rule("motion[{i}].position", "motion.positions[{i}]"))


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
    if obj.errors():
        return None
    try:
        R, p = object_pose(obj, palm.initial)
    except Exception:  # invalid data the core's checks report by name
        return None
    if not (np.all(np.isfinite(R)) and np.all(np.isfinite(p))):
        return None
    w, x, y, z = (float(c) for c in quaternion_wxyz(R))
    return ObjectPose((w, x, y, z), (float(p[0]), float(p[1]), float(p[2])))


def _nominal_q(request: ManipulationRequest, hand: Any
               ) -> tuple[tuple[float, ...], ...] | None:
    """The joint angles of a hand's nominal grasp, per finger (None: it has none)."""
    if isinstance(hand, Hand):
        return hand.nominal_q
    if request.hand is not None and request.hand.builtin == "allegro":
        from ocp.robots.allegro import NOMINAL_Q

        return NOMINAL_Q
    return None


def _search_grasp(request: ManipulationRequest, cache: FingerCache, hand: Any,
                  obj: ObjectSpec, palm: Palm | None, start: ObjectPose | None,
                  motion: DesiredMotion | None,
                  from_joints: list[tuple[int, FingerModel, tuple[float, ...] | None, str, str]],
                  info: list[tuple[int | None, list[tuple[float, ...]]]], skip: int = 0
                  ) -> list[tuple[str, str]] | tuple[list[Any], GraspUsedModel]:
    """The request's ``grasp`` search (:func:`ocp.robots.first_grasp.first_grasp`): the
    fingers' joints (``from_joints`` with every searched q filled in, the models those of
    the hand with the found tip sides) and the wire account of it; or the reasons, as
    (field, reason), why there is none. ``skip``: the grasp after the ``skip`` best
    (:func:`~ocp.robots.first_grasp.first_grasp`'s)."""
    import json
    import time

    from ocp.robots.first_grasp import (
        GraspNotFoundError,
        ObjectGeometry,
        desired_turns,
        first_grasp,
    )
    from ocp.robots.grasp_reach import _tip
    from ocp.shapes.held import gait_shape_error, held_object

    if palm is not None:
        return [("grasp", "a grasp search places fingertips on a ball held by the fingers "
                          "alone: not with a palm")]
    if start is None:
        return [("initial_pose", "required by `grasp`: where the ball is held")]
    if len(request.fingers) < 2:
        return [("fingers", f"a grasp search places at least two fingertips (the fingers "
                            f"alone hold the object), got {len(request.fingers)}")]
    if len(from_joints) != len(request.fingers):
        return []  # some finger could not be placed: its own error says why
    if all(q is not None for _, _, q, _, _ in from_joints):
        return [("grasp", "every finger gives `initial_q`: nothing to search (drop "
                          "`grasp`, or a finger's `initial_q`)")]
    opts = request.grasp if not isinstance(request.grasp, str) else None
    search = opts.search if opts is not None else GraspSearchModel()
    turns = desired_turns(motion) if motion is not None and search.maximise_reach else []
    centre = np.asarray(start.position, dtype=float)
    radius = float(obj.dimensions[0])
    body: float | ObjectGeometry = radius if obj.shape == "sphere" else \
        ObjectGeometry.of(obj, start.rotation, request.pole_margin)
    models = [m for _, m, _, _, _ in from_joints]
    names = [n for _, _, _, n, _ in from_joints]
    key = json.dumps([request.hand.model_dump_json() if request.hand else None,
                      [f.model_dump_json(include={"finger", "hand_finger", "initial_q",
                                                  "q_seed", "name"})
                       for f in request.fingers],
                      request.object.model_dump_json(), list(start.position),
                      [(t.axis.tolist(), t.angle) for t in turns], request.mu,
                      request.pad_margin, search.model_dump_json(),
                      request.gait is not None,
                      request.forces.model_dump_json() if request.forces else None, skip]
                     + ([list(start.orientation), request.pole_margin]
                        if obj.shape != "sphere" else []))

    # an object with a closed-form nearest point: its grasps rolled on its surface
    surface = held_object(obj, centre, np.asarray(start.rotation, dtype=float)) \
        if gait_shape_error(obj) is None else None
    prefer = None
    if request.gait is not None and surface is not None:
        # a gait re-places fingertips: each one liftable (on a shape a gait can hold:
        # others are refused naming object.shape)
        from ocp.gait.step import liftable
        from ocp.transcription.values import load_vector

        load = load_vector(force_spec(request.forces), request.mu, len(models))

        def prefer(contacts: tuple[Any, ...]) -> bool:
            return all(liftable(models, [ct.q for ct in contacts], surface, load))

    collision = _hand_collision(request, hand)
    clear = None
    if collision is not None:
        joints = [n for m in models for n in m.joint_names]
        R0 = np.asarray(start.rotation, dtype=float)[None]

        def clear(q: np.ndarray) -> Any:
            return collision.least(obj.shape, obj.dimensions, joints, q,
                                   np.repeat(R0, len(q), axis=0),
                                   np.repeat(centre[None], len(q), axis=0))

    def run() -> Any:
        t0 = time.perf_counter()
        got = first_grasp(models, centre, body, turns, request.mu,
                          fixed=[q for _, _, q, _, _ in from_joints],
                          seeds=[s for _, s in info], samples=search.samples,
                          keep=search.candidates, min_gap=search.min_gap,
                          margin=request.pad_margin, seed=search.seed, names=names,
                          prefer=prefer, clear=clear, held=surface, skip=skip)
        return got, time.perf_counter() - t0

    try:
        found, took = cache.grasp(key, run)
    except GraspNotFoundError as exc:
        return list(exc.errors)
    # each searched capsule's chart side: its contact's direction across the cap's axis
    sides: list[tuple[float, float, float] | None] = []
    for (_, m, q, _, _), ct in zip(from_joints, found.contacts, strict=True):
        side = None
        _, axis, _ = _tip(m)
        if q is None and axis is not None:
            v = ct.link_direction - (ct.link_direction @ axis) * axis
            if np.linalg.norm(v) > math.sin(math.radians(10.0)):
                v = v / np.linalg.norm(v)
                side = (float(v[0]), float(v[1]), float(v[2]))
        sides.append(side)
    used_sides = list(sides)
    if request.hand is not None and hand is not None and any(sides):
        per_hand: list[tuple[float, float, float] | None] = [None] * len(hand.fingers)
        for (hf, _), side in zip(info, sides, strict=True):
            if hf is not None and side is not None:
                per_hand[hf] = side
        builtin = request.hand.builtin
        if builtin == "allegro" or (builtin is None and request.hand.tips is not None):
            variant = cache.hand_with_sides(request.hand, tuple(per_hand))
            for k, (hf, _) in enumerate(info):
                if hf is not None:
                    place, _, q, name, field = from_joints[k]
                    from_joints[k] = (place, variant.fingers[hf], q, name, field)
                    tip = request.hand.tips[hf] if request.hand.tips else None
                    if tip is not None and (tip.side is not None or tip.surface is not None):
                        used_sides[k] = None  # the request's own tip kept
        else:
            used_sides = [None] * len(sides)
    else:
        used_sides = [None] * len(sides) if request.hand is None else used_sides
    filled = [(place, m, tuple(float(x) for x in ct.q), name, field)
              for (place, m, _, name, field), ct in zip(from_joints, found.contacts,
                                                         strict=True)]
    fingers = [GraspFingerModel(
        name=name, searched=q is None, q=[float(x) for x in ct.q],
        contact_point=[float(x) for x in (centre + radius * ct.normal if ct.point is None
                                          else ct.point)],
        contact_normal=[float(x) for x in ct.normal],
        tip_side=None if side is None else list(side),
        reach=ct.reach, stop=(ct.stop or None) if ct.reach is not None else None)
        for (_, _, q, name, _), ct, side in zip(from_joints, found.contacts, used_sides,
                                                strict=True)]
    return filled, GraspUsedModel(
        fingers=fingers, reach=found.reach, requested_turn=found.requested,
        closure=found.closure, grasp_angle=found.grasp_angle, tip_gap=found.gap,
        candidates=list(found.candidates), combinations=found.combinations,
        search_time=took, rank=skip)


def _hand_collision(request: ManipulationRequest, hand: Any) -> Any:
    """The request's hand's collision geoms with its fingers' tips
    (:meth:`ocp.robots.whole_hand.WholeHand.collision`): None unless every finger is one
    of a whole hand's (a URDF's links are not checked)."""
    which = hand_fingers(request, hand)
    return None if which is None else hand.collision(which)


def _initial_clearance(collision: Any, obj: ObjectSpec, start: ObjectPose,
                       from_joints: list[tuple[int, FingerModel, tuple[float, ...] | None,
                                               str, str]]) -> list[tuple[str, str]]:
    """Why the initial grasp's links are not clear of the object and of each other (the
    fields of the fingers' joints), [] when they are."""
    from ocp.robots.collision import LINK_CLEARANCE

    got = collision.least(obj.shape, obj.dimensions,
                          [n for _, m, _, _, _ in from_joints for n in m.joint_names],
                          np.concatenate([q for _, _, q, _, _ in from_joints])[None],
                          np.asarray(start.rotation, dtype=float)[None],
                          np.asarray(start.position, dtype=float)[None])
    if got.passed:
        return []
    where = from_joints[got.fingers[0] if got.fingers else 0][4]
    return [(where, f"at the initial grasp {got.describe()}: the hand's links "
                                f"(but the touching fingertips with the object) must keep "
                                f"{LINK_CLEARANCE * 1e3:g} mm from the object and from "
                                "each other, as MuJoCo collides them")]


def manipulation_problem(request: ManipulationRequest, cache: FingerCache
                         ) -> ManipulationProblem:
    """The core's problem of a manipulation request; ProblemError naming the wire fields
    the core cannot even be given (a finger that does not load, a hand finger that does
    not exist, duplicate names, a motion step without an axis, a `grasp` search that
    finds nothing)."""
    return problem_and_grasp(request, cache)[0]


def problem_and_grasp(request: ManipulationRequest, cache: FingerCache, skip: int = 0
                      ) -> tuple[ManipulationProblem, GraspUsedModel | None]:
    """:func:`manipulation_problem` and the grasp its ``grasp`` search found (None: no
    search; ``skip``: the search's grasp after the ``skip`` best)."""
    errors: list[tuple[str, str]] = []
    hand: Any = None  # Hand (flat pads) or WholeHand
    if request.hand is not None:
        try:
            hand = cache.hand(request.hand)
        except ProblemError as exc:
            errors += exc.errors
    tips: list[Fingertip | None] = []
    #: fingers whose contact comes from joint angles: (place, model, q, name, field); q
    #: None: searched (``grasp``)
    from_joints: list[tuple[int, FingerModel, tuple[float, ...] | None, str, str]] = []
    #: per finger: (its hand_finger or None, its seeds for a search)
    search_info: list[tuple[int | None, list[tuple[float, ...]]]] = []
    names: dict[str, int] = {}
    for i, f in enumerate(request.fingers):
        where = f"fingers[{i}]"
        model: FingerModel | None = None
        default_name = f"finger{i}"
        default_seed: tuple[float, ...] | None = None
        if f.finger is not None:
            try:
                model = cache.finger(f.finger, f"{where}.finger")
            except ProblemError as exc:
                errors += exc.errors
        elif f.hand_finger is not None:
            if request.hand is None:
                errors.append((f"{where}.hand_finger", "no `hand` in the request to pick a "
                                                       "finger from"))
            elif hand is not None:
                n = len(hand.fingers)
                if f.hand_finger >= n:
                    errors.append((f"{where}.hand_finger",
                                   f"the {request.hand.builtin or 'request'}'s hand has {n} "
                                   f"fingers (indices 0 to {n - 1}), got {f.hand_finger}"))
                else:
                    model = hand.fingers[f.hand_finger]
                    default_name = hand_finger_name(hand, f.hand_finger)
                    nominal = _nominal_q(request, hand)
                    if nominal is not None:
                        default_seed = nominal[f.hand_finger]
        search_info.append((f.hand_finger if f.finger is None else None,
                            [q for q in (default_seed, None if f.q_seed is None else
                                         tuple(f.q_seed)) if q is not None]))
        name = f.name or default_name
        if request.grasp is not None and f.initial is not None:
            errors.append((f"{where}.initial", "with `grasp`, a finger starts from "
                                               "`initial_q` or is searched: drop `initial` "
                                               "and `chart_rotation`"))
        if name == "palm":
            errors.append((f"{where}.name", "'palm' names the palm contact; choose another"))
        elif name in names:
            errors.append((f"{where}.name", f"{name!r} is also the name of "
                                            f"fingers[{names[name]}]; names must be unique"))
        names.setdefault(name, i)
        if model is not None and f.initial is not None and f.chart_rotation is not None:
            rv = f.chart_rotation
            tips.append(Fingertip(model, f.initial.as_tuple(), (rv[0], rv[1], rv[2]),
                                  default_seed if f.q_seed is None else tuple(f.q_seed),
                                  name))
        elif model is not None:  # the contact where the joints put the tip
            q0 = tuple(f.initial_q) if f.initial_q is not None else default_seed
            searched = request.grasp is not None and f.initial_q is None
            if searched and not model.tip_surface.round:
                errors.append((f"{where}.hand_finger" if f.hand_finger is not None else
                               f"{where}.finger", "a `grasp` search needs a round fingertip "
                                                  "(sphere or capsule), not a flat pad"))
            elif searched:
                from_joints.append((len(tips), model, None, name, f"{where}.initial_q"))
            elif q0 is None:
                errors.append((f"{where}.initial", "give `initial` and `chart_rotation`, or "
                                                   "`initial_q` (this finger has no nominal "
                                                   "grasp)"))
            elif not model.tip_surface.round:
                errors.append((f"{where}.initial", "a flat pad's contact needs `initial` and "
                                                   "`chart_rotation` (contacts from joint "
                                                   "angles are for round tips)"))
            else:
                from_joints.append((len(tips), model, q0, name, f"{where}.initial_q"
                                    if f.initial_q is not None else f"{where}.initial"))
            tips.append(None)
    obj = object_spec(request.object)
    # the object's own checks first: its fingertips are measured on it (a sphere given two
    # dimensions reached CasADi's shape check: a 500), and they are its fields' reasons
    errors += obj.errors()
    start = motion_start = None
    if request.initial_pose is not None:
        q, p = request.initial_pose.orientation_wxyz, request.initial_pose.position
        if not any(q):
            errors.append(("initial_pose.orientation_wxyz", "a quaternion must not be "
                                                            "zero (the identity is 1, 0, 0, 0)"))
            q = [1.0, 0.0, 0.0, 0.0]
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
    grasp_used: GraspUsedModel | None = None
    if request.grasp is not None and not errors:
        outcome = _search_grasp(request, cache, hand, obj, palm, motion_start, motion,
                                from_joints, search_info, skip)
        if isinstance(outcome, list):
            errors += outcome
        else:
            from_joints, grasp_used = outcome
    if from_joints and not errors:
        if motion_start is None:
            errors.append(("initial_pose", "required to place the object among fingertips "
                                           "given by joint angles"))
        else:
            # every fingertip from its joints and no palm: an egg touched at an end, beyond
            # its own chart's bound, is measured on its side chart (share 1; no contact's
            # coordinates were given on its own chart: else never, share inf)
            share = 1.0 if palm is None and len(from_joints) == len(request.fingers) \
                else math.inf
            try:
                obj, found = fingertips_on_charts(
                    tuple(m for _, m, _, _, _ in from_joints),
                    tuple(q for _, _, q, _, _ in from_joints if q is not None), obj,
                    motion_start,
                    tuple(n for _, _, _, n, _ in from_joints),
                    tuple(w for _, _, _, _, w in from_joints), request.pole_margin,
                    share=share)
            except ProblemError as exc:
                errors += exc.errors
            else:
                for (k, _, _, _, _), tip in zip(from_joints, found, strict=True):
                    tips[k] = tip
    if not errors:
        errors += torque_limit_errors(request, hand)
    collision = None if errors else _hand_collision(request, hand)
    actuation = None if errors else hand_actuation(request, hand)
    if collision is not None and motion_start is not None and from_joints and \
            len(from_joints) == len(request.fingers) and \
            all(q is not None for _, _, q, _, _ in from_joints):
        errors += _initial_clearance(collision, obj, motion_start, from_joints)
    if errors:
        raise ProblemError(errors)
    tr = request.tracking
    forces = force_spec(request.forces)
    return _problem(request, obj, tips, palm, start, motion, tr, forces,
                    collision, actuation), grasp_used


#: A gait from a searched grasp that does not plan (a finger stops the turn, a swing is
#: not found) is tried from the search's next grasps, up to this many more.
GAIT_GRASP_RETRIES = 2


def _next_grasps(request: ManipulationRequest, fingers: FingerCache, planner: Any,
                 result: ManipulationResult, gait: Any, problem: ManipulationProblem,
                 grasp: GraspUsedModel, started: float
                 ) -> tuple[ManipulationResult, Any, ManipulationProblem, GraspUsedModel]:
    """The gait from the searched grasp after the best (:data:`GAIT_GRASP_RETRIES`), the
    first that plans; when none does, the one that turned farthest, the best grasp's on a
    tie; its message names the others tried. A next grasp is tried only when the request's
    time limit (``solver.time_limit``, the time its job has left in the service) leaves
    room for another gait as long as the average so far (``started``: when the first
    began, ``time.perf_counter``). (result, gait, problem, grasp)."""
    tried = [(result, gait, problem, grasp)]
    out_of_time = False
    for skip in range(1, GAIT_GRASP_RETRIES + 1):
        spent = time.perf_counter() - started
        if spent * (len(tried) + 1) / len(tried) > float(request.solver.time_limit):
            out_of_time = True
            break
        try:
            with fingers.lock:
                alt_problem, alt_grasp = problem_and_grasp(request, fingers, skip)
            if alt_problem.errors():
                break
            alt_res, alt_gait = solve_gait(request, alt_problem, planner)
        except ProblemError:  # no other grasp, or one the gait cannot start from
            break
        assert alt_grasp is not None  # (a search's)
        tried.append((alt_res, alt_gait, alt_problem, alt_grasp))
        if alt_gait.ok:
            break
    best = max(tried, key=lambda x: (x[1].ok, x[1].turned))
    if out_of_time:
        limit = float(request.solver.time_limit)
        best = (best[0].model_copy(update={"message": f"{best[0].message} (the search's "
                                                      "next grasps not tried within the "
                                                      f"time limit of {limit:g} s)"}),
                *best[1:])
    if len(tried) > 1:
        others = "; ".join(f"grasp {g.rank}: {r.status.value}, {math.degrees(gp.turned):.1f} "
                           f"deg ({r.message[:120]})" for r, gp, _, g in tried if g is not best[3])
        best = (best[0].model_copy(update={"message": f"{best[0].message} (from the search's "
                                                      f"grasp {best[3].rank}; also tried: "
                                                      f"{others})"}), *best[1:])
    return best


def _problem(request: ManipulationRequest, obj: ObjectSpec, tips: list[Fingertip | None],
             palm: Palm | None, start: ObjectPose | None, motion: DesiredMotion | None,
             tr: Any, forces: Any, collision: Any = None, actuation: Any = None
             ) -> ManipulationProblem:
    return ManipulationProblem(
        object=obj, fingers=tuple(t for t in tips if t is not None), duration=request.duration,
        palm=palm,
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
        options=solver_options(request.solver), forces=forces, timing=request.timing,
        ramp_time=request.ramp_time,
        max_joint_acceleration=request.max_joint_acceleration, collision=collision,
        actuation=actuation)


class ManipulationAdapter(PlannerAdapter[ManipulationRequest, ManipulationProblem,
                                           ManipulationSolution, ManipulationResult]):
    planner = "manipulation"
    result_type = ManipulationResult

    def fields(self, request: ManipulationRequest) -> FieldMap:
        if request.motion is not None and request.motion.kind == "samples":
            return MANIPULATION_SAMPLES_FIELDS
        return MANIPULATION_FIELDS

    def to_problem(self, request: ManipulationRequest, fingers: FingerCache
                   ) -> ManipulationProblem:
        """ProblemError naming the wire fields the core cannot be given (e.g.
        ``fingers[1].hand_finger``, ``motion.steps[2].axis``)."""
        return manipulation_problem(request, fingers)

    def problem_errors(self, request: ManipulationRequest, problem: ManipulationProblem,
                       fingers: FingerCache) -> FieldErrors:
        errors = list(problem.errors())
        if not errors:
            try:
                fingers.manipulation.initial_state(problem)
            except ProblemError as exc:
                errors += exc.errors
        return errors

    def collocation_names(self, problem: ManipulationProblem) -> ColumnNames:
        return grasp_names(problem.palm is not None,
                           [(tip.name or f"finger{i}", tuple(tip.finger.joint_names))
                            for i, tip in enumerate(problem.fingers)])

    def request_errors(self, request: ManipulationRequest, fingers: FingerCache
                       ) -> FieldErrors:
        errors = super().request_errors(request, fingers)
        if request.gait is not None:
            try:
                with fingers.lock:
                    problem = manipulation_problem(request, fingers)
            except ProblemError:
                return errors  # the errors name why there is no problem
            errors += [e for e in gait_errors(request, problem) if e not in errors]
        return errors

    def solve(self, request: ManipulationRequest, planners: Planners
              ) -> tuple[ManipulationResult, Any]:
        warm = warm_start_of(request)
        fingers, fields = planners.fingers, self.fields(request)
        with fingers.lock:  # the hand and fingers, by the cache's rules
            problem, grasp = problem_and_grasp(request, fingers)
            planner = fingers.manipulation
        actuation = problem.actuation
        errors = fields.errors(problem.errors())
        if errors:
            raise ProblemError(errors)
        if request.gait is not None:  # finger gaiting: rolls and re-placements
            errors = gait_errors(request, problem)
            if errors:
                raise ProblemError(errors)
            started = time.perf_counter()
            gait_res, gait = solve_gait(request, problem, planner)
            if grasp is not None and not gait.ok:
                gait_res, gait, problem, grasp = _next_grasps(request, fingers, planner,
                                                              gait_res, gait, problem, grasp,
                                                              started)
                actuation = problem.actuation
            return with_actuation(gait_res, actuation).model_copy(update={"grasp": grasp}), \
                gait
        try:
            sol = planner.solve(problem, warm)
        except ProblemError as exc:
            raise ProblemError(fields.errors(exc.errors)) from exc
        result = with_actuation(self.to_result(request, problem, sol), actuation)
        if grasp is not None:
            result = result.model_copy(update={"grasp": grasp})
        return result, sol

    def to_result(self, request: ManipulationRequest, problem: ManipulationProblem,
                  solution: ManipulationSolution) -> ManipulationResult:
        return result_from_manipulation_solution(solution, requested_times(request))

    def prepare(self, request: ManipulationRequest, planners: Planners) -> float:
        fingers = planners.fingers
        with fingers.lock:
            problem = manipulation_problem(request, fingers)
            general = fingers.manipulation
        built = general.prepare(problem)
        if request.gait is not None:  # a gait's swings: one NLP per finger (two where
            from ocp.gait.planner import torque_limits  # the joints are damped: with the
            from ocp.gait.step import SWING_OBSTACLES  # actuators' rows too)
            from ocp.gait.swing import prepare_swings

            limits = torque_limits(problem)
            built += prepare_swings(tuple(tip.finger for tip in problem.fingers),
                                    obstacles=SWING_OBSTACLES if problem.collision is not None
                                    else 0, driven=limits is not None and limits.damped)
        return built

    def summary(self, result: ManipulationResult, solution: Any) -> str:
        return manipulation_summary(result)


def result_from_manipulation_solution(sol: ManipulationSolution, times: Any = None
                                      ) -> ManipulationResult:
    """The wire result of a manipulation plan (``times``: the request's sample times,
    :func:`~.samples.requested_times`). A plan with non-finite values (a diverged last
    iterate) keeps its status and drops its trajectory (JSON has no NaN)."""
    cert = finger_certificate(ManipulationCertificateModel, sol.certificate)
    trajectory = manipulation_trajectory(sol)
    message = sol.message if trajectory is not None or sol.t.size == 0 else \
        sol.message + " (non-finite iterate omitted)"
    status = PlanStatus(sol.status.value)
    if trajectory is None and status is PlanStatus.SOLVED:  # pragma: no cover - defensive
        status = PlanStatus.NUMERICAL_ERROR
    timing = [sol.build_time, sol.ipopt_time]
    collocation = None if trajectory is None else collocation_block(
        sol.warm_start, grasp_names(any(c.body == "palm" for c in sol.contacts),
                                     [(f.name, tuple(f.joint_names)) for f in sol.fingers]))
    return ManipulationResult(
        status=status, message=message,
        stats=ManipulationStatsModel(
            raw_status=sol.raw_status, iterations=sol.iterations,
            build_time=timing[0] if math.isfinite(timing[0]) else 0.0,
            solve_time=timing[1] if math.isfinite(timing[1]) else 0.0,
            refinements=sol.refinements, n_intervals=max((len(sol.t) - 1) // 2, 0),
            solver=sol.stats.solver if sol.stats is not None else None,
            primal_infeasibility=_finite_or_none(sol.primal_infeasibility),
            dual_infeasibility=_finite_or_none(sol.dual_infeasibility)),
        goal_error={k: float(v) for k, v in sol.goal_error.items() if math.isfinite(v)},
        certificate=cert, trajectory=trajectory,
        chart_rotation=list(sol.object_chart_rotation)
        if trajectory and sol.object_chart_rotation else None,
        samples=samples_block(sol, times) if trajectory else None,
        joint_trajectory=joint_trajectory_block(sol, times) if trajectory else None,
        collocation=collocation,
        contact_charts=_contact_charts(sol) if trajectory else None)


def _contact_charts(sol: ManipulationSolution) -> list[ContactChartModel] | None:
    """The charts the fingertips' contact coordinates are on (an egg's side chart, or two
    with a switch inside the plan); None: the request's own throughout."""
    interp = sol._interpolant
    if interp is None or not (sol.object_side_chart or sol.chart_switch is not None):
        return None
    charts = interp.charts
    starts = [0.0] if sol.chart_switch is None else [0.0, float(sol.chart_switch.time)]
    out = []
    for t0, m, prm in zip(starts, charts.models, charts.prms, strict=False):
        Rs = np.asarray(prm[m.surface.n_params:], dtype=float).reshape(-1, 3, 3)
        Rs = Rs.transpose(0, 2, 1)  # (each chart's vec is column-major)
        tips = [m.point_contacts.index(t) for t in m.fingertips]
        out.append(ContactChartModel(t=t0, chart=str(m.surface.name), patches=[
            [float(x) for x in log_rotation(Rs[k])] for k in tips]))
    return out


def _finite_or_none(value: float | None) -> float | None:
    return value if value is not None and math.isfinite(value) else None


def manipulation_summary(result: ManipulationResult) -> str:
    """One screen on a manipulation plan. Only a ``solved`` plan is certified; any other
    says "not certified" on its first line, before any figure, and its tracking and force
    lines are marked as the last iterate's, so that none reads as a result."""
    certified = result.status is PlanStatus.SOLVED
    mark = "" if certified else "not certified: "
    ipopt = ""
    if result.stats is not None:
        ipopt = f"  (IPOPT: {result.stats.raw_status})" if result.stats.raw_status else \
            "  (answered before any NLP was built)"
    lines = [f"status       {result.status.value}" + ("" if certified else ", not certified")
             + ipopt,
             f"message      {result.message}"]
    if result.stats is not None and result.stats.raw_status:
        s = result.stats
        lines += [f"iterations   {s.iterations}, N = {s.n_intervals}, {s.refinements} "
                  "refinement(s)",
                  f"time         build {s.build_time * 1e3:.1f} ms, solve "
                  f"{s.solve_time * 1e3:.1f} ms"]
    t = result.trajectory
    if t is not None:
        lines.append("contacts     " + ", ".join(c.name for c in t.contacts))
        if all(c.force is not None for c in t.contacts) and t.contacts:
            normal = [-float(np.dot(f, n)) for c in t.contacts
                      for f, n in zip(c.force or [], c.normal, strict=True)]
            lines.append(f"forces       {mark}normal {min(normal):.3g} to {max(normal):.3g}"
                         " N (planned, every contact)")
    if result.goal_error:
        worst_goal = max(result.goal_error.values())
        lines.append(f"goal error   {worst_goal:.3g} (worst of {len(result.goal_error)} "
                     "palm targets)")
    g = result.grasp
    if g is not None:
        reach = ""
        if g.reach is not None:
            least = min(g.fingers, key=lambda f: f.reach if f.reach is not None else 1e9)
            stop = f", {least.stop}" if least.stop else ""
            reach = (f": reach {math.degrees(g.reach):.3g} of {math.degrees(g.requested_turn):.3g}"
                     f" deg toward the motion (least: {least.name}{stop})")
        lines.append(f"grasp        searched in {g.search_time:.2g} s{reach}, closure "
                     f"{g.closure:.2g}; its joints and tip sides: the result's `grasp`")
    c = result.certificate
    if t is not None and t.tracking_position_error and t.tracking_angle_error:
        tol = c.tolerances if c is not None else {}
        bounds = ""
        if "max_tracking_position_error" in tol and "max_tracking_angle_error" in tol:
            bounds = (f" (tolerances {tol['max_tracking_position_error'] * 1e3:.3g} mm, "
                      f"{math.degrees(tol['max_tracking_angle_error']):.3g} deg)")
        lines.append(f"tracking     {mark}{max(t.tracking_position_error) * 1e3:.3g} mm, "
                     f"{math.degrees(max(t.tracking_angle_error)):.3g} deg worst{bounds}"
                     + ("" if certified else " (the last iterate's, not a plan's)"))
    gt = result.gait
    if gt is not None:
        moves = ", ".join(p.lifted_finger or "" for p in gt.phases  # (at rest, or while
                          if p.kind in ("swing", "roll") and p.lifted_finger)  # rolling)
        lines.append(f"gait         {mark}turned {math.degrees(gt.turned):.1f} deg in {gt.rolls} "
                     f"roll(s) and {gt.replacements} re-placement(s) ({moves or 'none'}); "
                     f"{gt.phases[-1].end if gt.phases else 0.0:.2f} s, planned in "
                     f"{gt.wall_time:.1f} s")
        if gt.never_lifted:
            lines.append(f"  never lifted: {', '.join(gt.never_lifted)} (the others cannot "
                         "hold the ball without it)")
    if c is not None:
        lines.append("certificate  " + ("PASSED" if c.passed else "FAILED"))
        slips = [v for k, v in c.values.items() if k.startswith("max_slip_speed_")]
        if slips:
            lines.append(f"  slip       {max(slips):.3g} m/s worst over "
                         f"{len(slips)} contact(s)")
        lines += [f"  {f}" for f in c.failures[:6]]
    if t is not None and t.grasp_angle:
        lines.append(f"grasp angle  {math.degrees(t.grasp_angle[0]):.2f} deg at start, "
                     f"{math.degrees(t.grasp_angle[-1]):.2f} at end, "
                     f"{math.degrees(max(t.grasp_angle)):.2f} max (largest force angle)")
        lines.append(f"cone margin  {math.degrees(min(t.cone_margin)):.2f} deg minimum "
                     "(> 0: force closure inside the friction cones)")
    return "\n".join(lines)
