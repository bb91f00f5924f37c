"""What the viewer draws a plan with: the object's shape, the palm and each finger's model.

From the plan's request when there is one (the service has every job's request; the
command line takes ``--request``): the same object and the same fingers (URDF, mount,
pad) the planner used, loaded by the planners' own conversion. From the result alone
otherwise: the object's shape fitted to its contact points, each finger matched to a
built-in finger or hand finger whose forward kinematics at the plan's joint angles puts
the pad where the plan has it (none found: the pads alone are drawn).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from dexroll_client.models import PlanRequest
from ocp import (
    HAND_NAMES,
    BallOnPalmProblem,
    FingerModel,
    ManipulationProblem,
    load_finger,
    load_hand,
)

from .tracks import PlanTracks

__all__ = ["SceneModels", "infer_models", "models_from_request", "quaternion_matrices"]

#: A finger model matches a plan's finger when its FK at the plan's joint angles puts the
#: pad within this of the plan's pad pose [m, rad] at every checked sample.
MATCH_TOLERANCE = 1e-5


@dataclass
class SceneModels:
    """The object (``shape``: 'sphere' or 'ellipsoid'; ``dimensions`` [m]), the palm's
    half extent [m] (None: no palm in the plan), each finger's model (None: unknown, the
    pad alone is drawn) and notes on where each came from."""

    shape: str
    dimensions: tuple[float, ...]
    palm_half_extent: float | None
    fingers: list[FingerModel | None]
    notes: list[str] = field(default_factory=list)


def quaternion_matrices(wxyz: np.ndarray) -> np.ndarray:
    """Rotation matrices (k, 3, 3) of unit quaternions (k, 4) (w, x, y, z)."""
    q = np.asarray(wxyz, dtype=float).reshape(-1, 4)
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    w, x, y, z = q.T
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ], axis=1)


def models_from_request(request: PlanRequest, tracks: PlanTracks) -> SceneModels:
    """The object, palm and fingers of the plan's own request (ProblemError when the
    request's fingers cannot be loaded)."""
    from ..planners import FINGERS, to_problem  # the planners' conversion: the same models

    with FINGERS.lock:  # the process's finger cache, shared with the request checks
        problem: Any = to_problem(request, FINGERS)
    if isinstance(problem, BallOnPalmProblem):
        return SceneModels(problem.object.shape, tuple(problem.object.dimensions),
                           problem.palm_half_extent, [], ["object and palm: the request's"])
    if isinstance(problem, ManipulationProblem):
        models: list[FingerModel | None] = [tip.finger for tip in problem.fingers]
        palm = None if problem.palm is None else problem.palm.palm_half_extent
        obj = problem.object
    else:  # a one-finger problem: its palm part and its finger
        models = [problem.finger]
        palm, obj = problem.base.palm_half_extent, problem.base.object
    if len(models) != len(tracks.fingers):
        models = [None] * len(tracks.fingers)
    return SceneModels(obj.shape, tuple(obj.dimensions), palm, models,
                       ["object, palm and fingers: the request's"])


def _fit_object(tracks: PlanTracks) -> tuple[str, tuple[float, ...], str]:
    """A sphere or an ellipsoid of revolution about the object's z axis through the
    contact points seen in the object's frame (least squares)."""
    R = quaternion_matrices(tracks.object_wxyz)
    pts = [np.einsum("kji,kj->ki", R, c.point - tracks.object_position)
           for c in tracks.contacts]
    if not pts:
        return "sphere", (0.025,), "object: no contacts, a 25 mm ball drawn"
    p = np.concatenate(pts)
    r = np.linalg.norm(p, axis=1)
    if np.ptp(r) <= 1e-6 * max(float(np.max(r)), 1e-9):
        return "sphere", (float(np.median(r)),), "object: a ball fitted to the contacts"
    A = np.stack([p[:, 0] ** 2 + p[:, 1] ** 2, p[:, 2] ** 2], axis=1)
    sol, *_ = np.linalg.lstsq(A, np.ones(len(p)), rcond=None)
    if np.all(sol > 0) and np.linalg.matrix_rank(A) == 2:
        a, c = (float(1 / math.sqrt(s)) for s in sol)
        return "ellipsoid", (a, c), "object: an ellipsoid fitted to the contacts"
    return "sphere", (float(np.median(r)),), "object: a ball fitted to the contacts"


def _candidates() -> list[FingerModel]:
    out = [load_finger()]
    for name in HAND_NAMES:
        out += list(load_hand(name).fingers)
    return out


def _matches(model: FingerModel, track: Any) -> bool:
    if model.nq != track.q.shape[1] or tuple(model.joint_names) != track.joint_names:
        return False
    R_plan = quaternion_matrices(track.tip_wxyz)
    for k in {0, len(track.q) // 2, len(track.q) - 1}:
        R, p = model.fingertip_pose_pin(track.q[k])
        if np.linalg.norm(p - track.tip_position[k]) > MATCH_TOLERANCE or \
                np.linalg.norm(R - R_plan[k]) > MATCH_TOLERANCE:
            return False
    return True


def infer_models(tracks: PlanTracks) -> SceneModels:
    """The object and fingers of a plan whose request is not at hand (see the module)."""
    shape, dims, note = _fit_object(tracks)
    notes = [note + " (the request was not given)"]
    fingers: list[FingerModel | None] = []
    candidates = _candidates() if tracks.fingers else []
    for f in tracks.fingers:
        found = next((m for m in candidates if _matches(m, f)), None)
        fingers.append(found)
        notes.append(f"finger {f.name}: " + ("a built-in model matched its pad poses"
                                             if found else "no model known, its pad alone"))
    has_palm = any(c.body == "palm" for c in tracks.contacts)
    return SceneModels(shape, dims, 0.5 if has_palm else None, fingers, notes)
