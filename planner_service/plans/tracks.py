"""A plan's arrays in one shape whatever its planner: the object's pose, every contact's
point and normal, every finger's joints and pad pose over time (palm frame, SI units).

The three planners' wire results (``ball_on_palm``, ``one_finger``, ``manipulation``) say
the same things under different names; :func:`tracks_of` reads any of them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dexroll_client.models import (
    AnyPlanResult,
    FingerPlanResult,
    ManipulationResult,
    PlanResult,
)

__all__ = ["ContactTrack", "FingerTrack", "NoPlanError", "PlanTracks", "has_plan", "tracks_of"]

FloatArray = NDArray[np.float64]


class NoPlanError(ValueError):
    """The result holds no plan to show (an invalid request, or a non-finite iterate)."""


@dataclass(frozen=True)
class ContactTrack:
    """One contact: its name, the body touching the object (``palm`` or ``finger``), the
    contact point and the object's outward normal there (rows are samples)."""

    name: str
    body: str
    point: FloatArray
    normal: FloatArray
    #: per sample, 1 touching, 0 its fingertip lifted clear (a gait; between: a ramp);
    #: None: touching throughout
    active: FloatArray | None = None


@dataclass(frozen=True)
class FingerTrack:
    """One finger: joint angles q (rows are samples, columns ``joint_names``) and the pad
    frame's pose (origin, quaternion w, x, y, z) in the palm frame."""

    name: str
    joint_names: tuple[str, ...]
    q: FloatArray
    tip_position: FloatArray
    tip_wxyz: FloatArray


@dataclass(frozen=True)
class PlanTracks:
    """A plan at its samples ``t`` [s]: the object's centre and orientation (w, x, y, z),
    the contacts, the fingers, the grasp angle [rad] (None: the planner has none) and the
    friction cone's half angle atan(mu) [rad] (None: not known from the result)."""

    planner: str
    status: str
    message: str
    t: FloatArray
    object_position: FloatArray
    object_wxyz: FloatArray
    contacts: tuple[ContactTrack, ...]
    fingers: tuple[FingerTrack, ...]
    grasp_angle: FloatArray | None
    cone_half_angle: float | None

    @property
    def n(self) -> int:
        return int(self.t.size)


def _a(rows: object) -> FloatArray:
    return np.asarray(rows, dtype=float)


def _cone(grasp: FloatArray | None, margin: object) -> float | None:
    """atan(mu) from a plan's grasp angle and cone margin (margin = atan(mu) - angle)."""
    if grasp is None or margin is None:
        return None
    m = _a(margin)
    if m.shape != grasp.shape or m.size == 0:
        return None
    value = float(np.median(m + grasp))
    return value if math.isfinite(value) and 0.0 < value < math.pi / 2 else None


def has_plan(result: AnyPlanResult) -> bool:
    """Whether a result holds a plan to show (cheap: :func:`tracks_of` reads it)."""
    if isinstance(result, PlanResult):
        return result.grid is not None
    return getattr(result, "trajectory", None) is not None or \
        getattr(getattr(result, "gait", None), "samples", None) is not None


def tracks_of(result: AnyPlanResult) -> PlanTracks:
    """The plan of a wire result of any planner; :class:`NoPlanError` when it has none."""
    status, message = result.status.value, result.message
    if isinstance(result, PlanResult):
        g = result.grid
        if g is None:
            raise NoPlanError(f"the result holds no plan (status {status}: {message})")
        palm = ContactTrack("palm", "palm", _a(g.contact_point), -_a(g.contact_normal))
        return PlanTracks("ball_on_palm", status, message, _a(g.t), _a(g.object_position),
                          _a(g.object_orientation_wxyz), (palm,), (), None, None)
    if isinstance(result, FingerPlanResult):
        tr = result.trajectory
        if tr is None:
            raise NoPlanError(f"the result holds no plan (status {status}: {message})")
        centre, normal = _a(tr.object_position), _a(tr.finger_contact_normal)
        palm_point = _a(tr.palm_contact_point)
        palm_normal = palm_point - centre
        palm_normal /= np.maximum(np.linalg.norm(palm_normal, axis=1, keepdims=True), 1e-12)
        grasp = np.max(_a(tr.grasp_angles), axis=1)
        q = _a(tr.q)
        names = tuple(result.joint_names) if len(result.joint_names) == q.shape[1] else \
            tuple(f"j{i}" for i in range(q.shape[1]))
        return PlanTracks(
            "one_finger", status, message, _a(tr.t), centre, _a(tr.object_orientation_wxyz),
            (ContactTrack("palm", "palm", palm_point, palm_normal),
             ContactTrack("finger", "finger", _a(tr.finger_contact_point), normal)),
            (FingerTrack("finger", names, q, _a(tr.fingertip_position),
                         _a(tr.fingertip_orientation_wxyz)),),
            grasp, _cone(grasp, tr.cone_margin))
    if isinstance(result, ManipulationResult):
        m = result.trajectory
        gs = result.gait.samples if result.gait is not None else None
        if m is None and gs is not None and result.joint_trajectory is not None:
            return _gait_tracks(result, gs, status, message)
        if m is None:
            raise NoPlanError(f"the result holds no plan (status {status}: {message})")
        grasp = _a(m.grasp_angle)
        return PlanTracks(
            "manipulation", status, message, _a(m.t), _a(m.object_position),
            _a(m.object_orientation_wxyz),
            tuple(ContactTrack(c.name, c.body, _a(c.point), _a(c.normal)) for c in m.contacts),
            tuple(FingerTrack(f.name, tuple(f.joint_names), _a(f.q), _a(f.tip_position),
                              _a(f.tip_orientation_wxyz)) for f in m.fingers),
            grasp, _cone(grasp, m.cone_margin))
    raise NoPlanError(f"no viewer for a {type(result).__name__}")


def _gait_tracks(result: ManipulationResult, gs: Any, status: str, message: str
                 ) -> PlanTracks:
    """A gait's plan (docs/gait.md): its samples, the joints from its joint trajectory
    (each finger's columns by its ``joint_names``; a result from before they were given:
    the columns named ``<finger>/<joint>``)."""
    jt = result.joint_trajectory
    assert jt is not None
    q_all = _a([p.positions for p in jt.points])
    fingers = []
    for f in gs.fingers:
        if f.joint_names:
            cols = [jt.joint_names.index(nm) for nm in f.joint_names]
        else:
            cols = [i for i, nm in enumerate(jt.joint_names) if nm.startswith(f"{f.name}/")]
        fingers.append(FingerTrack(f.name, tuple(jt.joint_names[i].split("/")[-1]
                                                 for i in cols), q_all[:, cols],
                                   _a(f.tip_position), _a(f.tip_orientation_wxyz)))
    return PlanTracks(
        "manipulation", status, message, _a(gs.t), _a(gs.object_position),
        _a(gs.object_orientation_wxyz),
        tuple(ContactTrack(c.name, "finger", _a(c.point), _a(c.normal), _a(c.active))
              for c in gs.contacts), tuple(fingers), None, None)
