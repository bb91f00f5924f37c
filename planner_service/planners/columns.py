"""Warm starts, both ways: a plan's columns at its collocation points.

A result's ``collocation`` block is the core solution's ``warm_start`` (states and inputs
at the collocation points) with every column named (each adapter's
``collocation_names``); a request's inline ``warm_start`` becomes an
:class:`ocp.transcription.collocation.WarmStart` for the planner (a ``job_id`` is the service's to
resolve before the request gets here).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from dexroll_client.models import CollocationModel, NlpPointModel, PlanRequest
from ocp.spec.problem import ProblemError
from ocp.transcription.collocation import NlpPoint, WarmStart

from .common import rows
from .fields import FieldErrors

__all__ = [
    "BALL_ON_PALM_INPUTS",
    "BALL_ON_PALM_STATES",
    "ColumnNames",
    "collocation_block",
    "grasp_names",
    "warm_start_errors",
    "warm_start_of",
]

#: (state names, input names): the columns of a plan.
ColumnNames = tuple[list[str], list[str]]

#: Columns of a ball-on-palm plan: the contact coordinates; the palm contact velocity.
BALL_ON_PALM_STATES = ("x", "y", "u", "v", "psi")
BALL_ON_PALM_INPUTS = ("w_x", "w_y")
#: Columns of a free object (no palm): position and quaternion (w, x, y, z); velocity (palm
#: frame) and angular velocity in the object's own frame (ocp.solve.planner._quat_rate_sym).
_FREE_OBJECT_STATES = ("object.position.x", "object.position.y", "object.position.z",
                       "object.orientation.w", "object.orientation.x",
                       "object.orientation.y", "object.orientation.z")
_FREE_OBJECT_INPUTS = ("object.velocity.x", "object.velocity.y", "object.velocity.z",
                       "object.angular_velocity_body.x", "object.angular_velocity_body.y",
                       "object.angular_velocity_body.z")


def grasp_names(palm: bool, fingers: Sequence[tuple[str, Sequence[str]]]) -> ColumnNames:
    """(state names, input names) of the general planner's layout (``ocp.solve.planner``):
    the object block (the palm contact, or the free object's pose), then per fingertip
    (its contact name, its joint names) the contact coordinates and the joints."""
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


def collocation_block(ws: WarmStart, names: ColumnNames) -> CollocationModel | None:
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
    return CollocationModel(t=rows(t), x=rows(x), u=rows(u), state_names=states,
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


def warm_start_errors(request: PlanRequest, names: ColumnNames) -> FieldErrors:
    """What is wrong with a request's ``warm_start`` for a plan of columns ``names``,
    fields named (``warm_start.t``, ``warm_start.x``, ``warm_start.state_names``, ...)."""
    ws = request.warm_start
    if ws is None:
        return []
    try:
        warm = warm_start_of(request)
    except ProblemError as exc:
        return list(exc.errors)
    assert warm is not None
    states, inputs = names
    errors = warm.errors("warm_start", len(states), len(inputs))
    for field, given, expected in (("state_names", ws.state_names, states),
                                   ("input_names", ws.input_names, inputs)):
        if given is not None and list(given) != expected:
            errors.append((f"warm_start.{field}", _names_mismatch(given, expected)))
    return errors
