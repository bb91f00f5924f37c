"""A plan's execution in MuJoCo, as the service's doors reach it (docs/simulation.md).

:func:`execution_plan` turns a wire result (and, when at hand, its request) into the
simulator's :class:`sim.ExecutionPlan`, with the viewer's readers: the plan's arrays
(:func:`planner_service.plans.tracks.tracks_of`) and its models (the request's own object,
palm and fingers through the planners' conversion, or inferred from the result:
:mod:`planner_service.plans.models`). :func:`simulate_result` runs it and returns the
report as JSON-ready data.

Plans that carry contact forces or joint torques (issue 15, part 1) are executed with
them as feed-forward: :func:`plan_forces` is the one place that reads them from a result.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from dexroll_client.models import (
    AnyPlanResult,
    FingerPlanResult,
    ManipulationResult,
    PlanRequest,
)

from ..plans.models import SceneModels, infer_models, models_from_request
from ..plans.shapes import pad_thickness
from ..plans.tracks import NoPlanError, PlanTracks, tracks_of

__all__ = ["NotExecutableError", "execution_plan", "finger_spec", "plan_forces",
           "simulate_result", "user_model", "with_rate_breaks"]

#: Friction coefficient when neither the request nor the result states it.
DEFAULT_MU = 0.5


class NotExecutableError(ValueError):
    """The result holds no plan that a hand executes (no plan, no fingers, a finger
    without a model)."""


def _q_dot(result: AnyPlanResult) -> list[np.ndarray]:
    """Each finger's joint rates at the trajectory's times (a gait's: its joint
    trajectory's, every finger's columns together: split by the caller)."""
    if isinstance(result, ManipulationResult) and result.trajectory is None and \
            result.gait is not None and result.joint_trajectory is not None:
        return [np.asarray([p.velocities for p in result.joint_trajectory.points],
                           dtype=float)]
    if isinstance(result, FingerPlanResult) and result.trajectory is not None:
        return [np.asarray(result.trajectory.q_dot, dtype=float)]
    if isinstance(result, ManipulationResult) and result.trajectory is not None:
        return [np.asarray(f.q_dot, dtype=float) for f in result.trajectory.fingers]
    return []


def plan_forces(result: AnyPlanResult) -> list[tuple[np.ndarray | None, np.ndarray | None]]:
    """Per finger, (joint torques (times x joints) [N m], the force the fingertip applies
    to the object in the palm frame (times x 3) [N]) when the result carries them, else
    (None, None). Read from a manipulation trajectory's ``fingers[i].joint_torques`` and
    ``contacts[j].force`` (the fingertip's contact), and from a one-finger trajectory's
    ``joint_torques`` and ``finger_contact_force``; today's results have none."""
    out: list[tuple[np.ndarray | None, np.ndarray | None]] = []

    def rows(x: object) -> np.ndarray | None:
        if x is None:
            return None
        a = np.asarray(x, dtype=float)
        return a if a.ndim == 2 and np.all(np.isfinite(a)) else None

    if isinstance(result, FingerPlanResult) and result.trajectory is not None:
        tr = result.trajectory
        out.append((rows(getattr(tr, "joint_torques", None)),
                    rows(getattr(tr, "finger_contact_force", None))))
    elif isinstance(result, ManipulationResult) and result.trajectory is not None:
        force_of = {c.name: rows(getattr(c, "force", None))
                    for c in result.trajectory.contacts}
        for f in result.trajectory.fingers:
            out.append((rows(getattr(f, "joint_torques", None)), force_of.get(f.name)))
    return out


def _limit(x: object) -> float | None:
    """A joint limit, None when unbounded."""
    v = float(x)  # type: ignore[arg-type]
    return v if math.isfinite(v) else None


def object_spec(shape: str, dimensions: tuple[float, ...], mass: float) -> Any:
    """The simulator's object (a ``sim.ObjectSpec``): the shape's MuJoCo geom
    (:meth:`ocp.shapes.Shape.mujoco_geom`) and ``mass`` [kg]."""
    from ocp import shape_of
    from sim import ObjectSpec

    geom = shape_of(shape).mujoco_geom(dimensions)
    return ObjectSpec(geom.type, geom.size, mass, shape, tuple(dimensions), geom.vertices)


def _tip_shape(model: Any, tip_shape: Any) -> Any:
    """The simulator's fingertip (a ``sim.TipShape``) of a finger model: its tip surface
    (``model.tip``, ocp/geometry/tips.py: pad, sphere, spheroid, capsule cap) placed as
    the planner places it; a flat pad of the model's half size without one."""
    tip = getattr(model, "tip", None)
    kind = getattr(tip, "kind", "pad")
    R = np.asarray(getattr(tip, "rotation", np.eye(3)), dtype=float)
    p = np.asarray(getattr(tip, "offset", np.zeros(3)), dtype=float)
    params = tuple(float(x) for x in getattr(tip, "params", ()))
    if kind == "sphere":
        return tip_shape("sphere", params[:1], R, p)
    if kind == "spheroid":
        return tip_shape("ellipsoid", params[:2], R, p)
    if kind == "capsule":
        extra = tuple(float(x) for x in getattr(tip, "extra", ()))
        return tip_shape("capsule", (params[0], extra[0] if extra else 0.0), R, p)
    h = float(params[0]) if params else float(model.pad_half_size)
    return tip_shape("box", (h, h, pad_thickness(model)), R, p)


def _mu(request: PlanRequest | None, tracks: PlanTracks) -> tuple[float, str | None]:
    mu = getattr(request, "mu", None) if request is not None else None
    if isinstance(mu, int | float) and mu > 0:
        return float(mu), None
    if tracks.cone_half_angle is not None:
        return math.tan(tracks.cone_half_angle), "friction: atan(mu) from the plan's cone"
    return DEFAULT_MU, f"friction: not known, mu = {DEFAULT_MU}"


def finger_spec(name: str, model: Any) -> Any:
    """The simulator's finger (a ``sim.FingerSpec``) of a finger model
    (:class:`~ocp.robots.finger.FingerModel`): its joints, base, tip frame and tip."""
    from sim import FingerSpec, JointSpec, TipShape

    joints = tuple(JointSpec(
        j.name, j.kind, (float(j.axis[0]), float(j.axis[1]), float(j.axis[2])),
        np.asarray(j.placement_rotation, dtype=float),
        np.asarray(j.placement_translation, dtype=float),
        _limit(model.lower[j.index_q]), _limit(model.upper[j.index_q]))
        for j in model.chain)
    return FingerSpec(name, joints, np.asarray(model.base_rotation, dtype=float),
                      np.asarray(model.base_position, dtype=float),
                      np.asarray(model.tip_rotation, dtype=float),
                      np.asarray(model.tip_translation, dtype=float),
                      _tip_shape(model, TipShape), name)


def execution_plan(result: AnyPlanResult, request: PlanRequest | None = None
                   ) -> Any:
    """The simulator's plan (a :class:`sim.ExecutionPlan`) of a wire result, with its
    request's models when given (inferred from the result otherwise, as the viewer
    does). :class:`NotExecutableError` when there is nothing a hand executes;
    ProblemError when the request's fingers cannot be loaded."""
    from sim import DEFAULT_MASS, ContactSpec, ExecutionPlan, FingerReference

    try:
        tracks = tracks_of(result)
    except NoPlanError as exc:
        raise NotExecutableError(str(exc)) from exc
    if not tracks.fingers:
        raise NotExecutableError(f"a {tracks.planner} plan has no fingers: nothing for a "
                                 "hand to execute")
    if not np.all(np.isfinite(tracks.object_position)):
        raise NotExecutableError("the plan is not finite")
    models: SceneModels = infer_models(tracks) if request is None \
        else models_from_request(request, tracks)
    if isinstance(result, ManipulationResult) and result.trajectory is None and \
            result.gait is not None and result.gait.samples is not None:
        return _gait_plan(result, request, tracks, models)
    rates = _q_dot(result)
    forces = plan_forces(result)
    fingers, refs = [], []
    for k, (track, model) in enumerate(zip(tracks.fingers, models.fingers, strict=True)):
        if model is None:
            raise NotExecutableError(f"finger {track.name}: no model known (give the "
                                     "plan's request)")
        fingers.append(finger_spec(track.name, model))
        torques, force = forces[k] if k < len(forces) else (None, None)
        refs.append(FingerReference(track.q, rates[k], torques, force))
    contacts = tuple(ContactSpec(c.name, c.body, c.name if c.body == "finger" else None,
                                 c.point, c.normal) for c in tracks.contacts)
    mu, mu_note = _mu(request, tracks)
    obj_request = getattr(request, "object", None)
    mass = getattr(obj_request, "mass", None)
    gravity = getattr(request, "gravity", None)
    torsion = getattr(request, "torsional_friction", None)
    load = getattr(request, "forces", None)  # a plan with forces: its load (docs/forces.md)
    if load is not None:
        mass, gravity = load.mass, load.gravity
        torsion = load.torsional_friction if load.torsional_friction > 0 else torsion
    notes = list(models.notes) + ([mu_note] if mu_note else [])
    if mass is None:
        notes.append(f"object mass: not in the plan, {DEFAULT_MASS} kg (solid)")
    plan = ExecutionPlan(
        tracks.t, object_spec(models.shape, tuple(models.dimensions),
                              float(mass) if mass is not None else DEFAULT_MASS),
        tracks.object_position, tracks.object_wxyz, tuple(fingers), tuple(refs), contacts,
        models.palm_half_extent, mu, None if torsion is None else float(torsion),
        (0.0, 0.0, -9.81) if gravity is None else
        (float(gravity[0]), float(gravity[1]), float(gravity[2])), tuple(notes))
    plan = with_rate_breaks(plan, result)
    plan.check()
    return plan


def _gait_plan(result: ManipulationResult, request: PlanRequest | None, tracks: PlanTracks,
               models: SceneModels) -> Any:
    """The simulator's plan of a gait result (docs/gait.md): its samples, the request's
    models and load."""
    from ocp import GaitSamples

    from .gait import samples_execution_plan

    gs = result.gait.samples if result.gait is not None else None
    load = getattr(request, "forces", None)
    if gs is None or load is None or any(m is None for m in models.fingers):
        raise NotExecutableError("a gait is executed with its request (its fingers and "
                                 "load): give the request (dexroll simulate --request)")
    qd = _q_dot(result)[0]
    acc = np.zeros_like(qd)

    def stack(attr: str) -> np.ndarray:
        return np.stack([np.asarray(getattr(c, attr), dtype=float) for c in gs.contacts],
                        axis=1)

    smp = GaitSamples(tracks.t, np.hstack([f.q for f in tracks.fingers]), qd, acc,
                      tracks.object_position, tracks.object_wxyz, stack("point"),
                      stack("normal"), stack("force"),
                      np.asarray([c.active for c in gs.contacts], dtype=float).T,
                      np.stack([f.tip_position for f in tracks.fingers], axis=1),
                      np.stack([f.tip_wxyz for f in tracks.fingers], axis=1))
    mu, mu_note = _mu(request, tracks)
    return samples_execution_plan(
        smp, tuple(f.name for f in tracks.fingers), tuple(models.fingers), models.shape,
        tuple(models.dimensions), float(load.mass), mu, tuple(load.gravity),
        (*models.notes, *([mu_note] if mu_note else [])))


def with_rate_breaks(plan: Any, result: AnyPlanResult) -> Any:
    """The plan with a second row at each of the result's rate breaks (the paper's
    piecewise timing: the joint velocities jump at a via-point; the trajectory's row there
    has the outgoing ones): the same time and positions with the incoming velocities
    (``joint_trajectory.rate_breaks[].velocities_before``) first, so that the simulator's
    reference follows the plan's polynomial on both sides of the break."""
    from dataclasses import replace

    jt = getattr(result, "joint_trajectory", None)
    breaks = list(getattr(jt, "rate_breaks", None) or [])
    width = sum(f.nq for f in plan.fingers)
    if not breaks or jt is None or len(jt.joint_names) != width:
        return plan
    t = plan.t
    rows = []  # (index of the break's row, the incoming velocities of every joint)
    for b in breaks:
        hits = np.flatnonzero(np.abs(t - b.t) <= 1e-9 * max(1.0, abs(b.t)))
        if hits.size == 1 and len(b.velocities_before) == width:
            rows.append((int(hits[0]), np.asarray(b.velocities_before, dtype=float)))
    if not rows:
        return plan
    index = np.arange(t.size)
    at = np.array([i for i, _ in rows])
    order = np.insert(index, at, at)  # each break's row twice: the copy first
    copies = at + np.arange(at.size)  # where the copies land in the new arrays

    def dup(a: np.ndarray | None) -> np.ndarray | None:
        return None if a is None else np.asarray(a)[order]

    refs = []
    start = 0
    for f, r in zip(plan.fingers, plan.references, strict=True):
        q_dot = np.asarray(r.q_dot)[order].copy()
        for c, (_, before) in zip(copies, rows, strict=True):
            q_dot[c] = before[start:start + f.nq]
        start += f.nq
        refs.append(replace(r, q=np.asarray(r.q)[order], q_dot=q_dot,
                            joint_torques=dup(r.joint_torques),
                            contact_force=dup(r.contact_force)))
    return replace(plan, t=t[order], object_position=plan.object_position[order],
                   object_wxyz=plan.object_wxyz[order], references=tuple(refs),
                   contacts=tuple(replace(c, point=c.point[order], normal=dup(c.normal))
                                  for c in plan.contacts))


def user_model(request: PlanRequest | None, plan: Any, text: str | None = None) -> Any:
    """The user's hand model a plan is executed on (a ``sim.user_model.UserModel``): the
    MJCF ``text`` (default: the request's ``hand.mjcf``), the tip of each of the plan's
    fingers (the request's ``hand.tips[hand_finger].name``; the built-in allegro's tip
    links) and the request's ``mount``. NotExecutableError when the request has no hand
    model to take them from."""
    from sim.user_model import UserModel

    hand = getattr(request, "hand", None)
    if hand is None:
        raise NotExecutableError("executing on a hand model needs the plan's request with "
                                 "its `hand` (the fingertips' names)")
    if text is None:
        if hand.mjcf is None:
            raise NotExecutableError("the request's hand is not an MJCF model: give the "
                                     "model file (dexroll simulate --model FILE)")
        text = hand.mjcf
    if hand.tips is not None:
        names = [t.name for t in hand.tips]
    elif hand.builtin == "allegro":
        from ..planners.cache import load_hand_model

        names = list(load_hand_model(hand).tip_names)
    else:
        raise NotExecutableError(f"the {hand.builtin} hand's fingers are not a hand model's")
    tips = []
    for f in getattr(request, "fingers", []):
        if f.hand_finger is None:
            raise NotExecutableError("a finger not of the request's hand cannot be executed "
                                     "on its model")
        tips.append(names[f.hand_finger])
    if len(tips) != len(plan.fingers):
        raise NotExecutableError(f"{len(tips)} fingers in the request, {len(plan.fingers)} "
                                 "in the plan")
    R, p = np.eye(3), np.zeros(3)
    if hand.mount is not None:  # the rotation vector's matrix (Rodrigues)
        w = np.asarray(hand.mount.rotation, dtype=float)
        angle = float(np.linalg.norm(w))
        if angle > 0.0:
            k = w / angle
            K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
            R = np.eye(3) + math.sin(angle) * K + (1.0 - math.cos(angle)) * K @ K
        p = np.asarray(hand.mount.position, dtype=float)
    return UserModel(text, tuple(tips), np.asarray(R, dtype=float), p)


def simulate_result(result: AnyPlanResult, request: PlanRequest | None = None,
                    options: dict[str, Any] | None = None,
                    model: str | None = None) -> Any:
    """Execute a wire result's plan in MuJoCo: the :class:`sim.SimReport`. ``options``:
    :class:`sim.SimOptions` fields (ValueError naming a bad one), and ``model``:
    "request" to execute it on the request's own MJCF hand (its actuators, masses and
    contact settings: ``sim.user_model``), or an MJCF text to execute it on; None:
    dexroll's scene."""
    from sim import SimOptions, simulate

    raw = dict(options or {})
    model = raw.pop("model", None) if model is None else model
    sim_options = SimOptions.from_dict(raw)
    plan = execution_plan(result, request)
    if model is None or model == "scene":
        return simulate(plan, sim_options)
    from sim.user_model import simulate_on_model

    return simulate_on_model(plan, user_model(request, plan,
                                              None if model == "request" else model),
                             sim_options)
