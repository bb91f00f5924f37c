"""The hand file's actuator commands in a manipulation result (issue 37, item 1;
:mod:`ocp.robots.actuation`): computed from the returned joint trajectory (a rolling plan's
or a gait's), stated as ``actuator_trajectory``, and checked against the actuators'
limits: a plan that needs more torque than a joint's actuator gives, or a control outside
its range, is refused (``infeasible``, the joint, the torque and the limit named; the
certificate's ``actuator_limits`` failure)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from dexroll_client.models import (
    ActuatorModel,
    ActuatorTrajectoryModel,
    ManipulationResult,
    PlanStatus,
)

from .common import hand_fingers

__all__ = ["hand_actuation", "torque_limit_errors", "with_actuation"]

#: The certificate's entry: the largest share of a torque limit the plan needs.
LOAD = "max_actuator_load"


def hand_actuation(request: Any, hand: Any) -> Any:
    """The actuators of the request's hand (:meth:`ocp.robots.whole_hand.WholeHand.
    actuation`, with the request's ``hand.torque_limits``) when every finger is one of
    that hand's; None otherwise."""
    if hand_fingers(request, hand) is None:
        return None
    got = hand.actuation()
    limits = request.hand.torque_limits
    return got.with_limits(dict(limits)) if limits and got is not None else got


def torque_limit_errors(request: Any, hand: Any) -> list[tuple[str, str]]:
    """Why the request's ``hand.torque_limits`` cannot be applied, as (field, reason):
    a name that is not a joint of the hand's fingers, or a hand without actuators."""
    limits = request.hand.torque_limits if request.hand is not None else None
    if not limits:
        return []
    if not hasattr(hand, "actuation"):
        return [("hand.torque_limits", "for a hand of one model (`urdf`, `mjcf` or the "
                                       "built-in allegro); this hand's fingers have flat "
                                       "pads and no actuators")]
    joints = [n for f in hand.fingers for n in f.joint_names]
    bad = sorted(set(limits) - set(joints))
    shown = ", ".join(joints[:24]) + (" ..." if len(joints) > 24 else "")
    return [(f"hand.torque_limits.{n}", f"{n!r} is not a joint of the hand's fingers; "
                                        f"they are: {shown}") for n in bad]


def _rows(a: np.ndarray) -> list[list[float | None]]:
    return [[None if not math.isfinite(float(x)) else float(x) for x in r] for r in a]


def with_actuation(result: ManipulationResult, actuation: Any) -> ManipulationResult:
    """``result`` with its ``actuator_trajectory`` and the limits' check (module
    docstring); unchanged without an actuation or a joint trajectory."""
    jt = result.joint_trajectory
    if actuation is None or jt is None or not jt.points:
        return result
    names = [n.split("/")[-1] for n in jt.joint_names]
    t = np.array([p.t for p in jt.points])
    q = np.array([p.positions for p in jt.points])
    qd = np.array([p.velocities for p in jt.points])
    qdd = np.array([p.accelerations for p in jt.points])
    eff = np.array([p.effort for p in jt.points]) \
        if all(p.effort is not None for p in jt.points) else None
    act = actuation.commands(names, t, q, qd, qdd, eff)
    share = act.load()[0]
    block = ActuatorTrajectoryModel(
        actuators=[ActuatorModel(joint=a.joint, actuator=a.name or None, kind=a.kind,
                                 gear=a.gear, gain=a.gain, bias=list(a.bias),
                                 torque_range=None if a.torque_range is None else
                                 list(a.torque_range),
                                 ctrl_range=None if a.ctrl_range is None else
                                 list(a.ctrl_range))
                   for a in act.actuators],
        t=t.tolist(), torques=[[float(x) for x in r] for r in act.needed],
        controls=_rows(act.controls), max_load=share, notes=list(act.notes))
    update: dict[str, Any] = {"actuator_trajectory": block}
    refusals = act.refusals()
    cert = result.certificate
    if cert is not None:
        failures = [*cert.failures, *(f"actuator_limits: {r}" for r in refusals)]
        update["certificate"] = cert.model_copy(update={
            "values": {**cert.values, LOAD: share},
            "tolerances": {**cert.tolerances, LOAD: 1.0},
            "failures": failures, "passed": cert.passed and not refusals})
    if refusals and result.status is PlanStatus.SOLVED:
        update["status"] = PlanStatus.INFEASIBLE
        update["message"] = ("the hand's actuators cannot make this plan: "
                             + "; ".join(refusals))
    return result.model_copy(update=update)
