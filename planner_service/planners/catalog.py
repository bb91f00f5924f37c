"""The catalog of ``GET /v1/models``: the built-in objects, fingers and hands (as the
core loads them), and the planners."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from dexroll_client.models import (
    BUILTIN_FINGERS,
    BUILTIN_HANDS,
    PLANNERS,
    FingerInfo,
    FingerModelSpec,
    HandFingerInfo,
    HandInfo,
    HandModel,
    ModelCatalog,
    ObjectInfo,
)
from ocp.geometry.rotations import quaternion_wxyz
from ocp.shapes import SHAPES
from ocp.solve.planner import hand_fingertips

from .cache import FingerCache, hand_finger_name

__all__ = ["model_catalog", "rotation_vector"]


def rotation_vector(R: Any) -> list[float]:
    """The rotation vector [rad] (angle in [0, pi]) of a rotation matrix."""
    w, *v = (float(c) for c in quaternion_wxyz(np.asarray(R, dtype=float)).reshape(4))
    norm = math.sqrt(sum(c * c for c in v))
    if norm < 1e-15:
        return [0.0, 0.0, 0.0]
    angle = 2.0 * math.atan2(norm, w)
    return [angle * c / norm for c in v]


def model_catalog(cache: FingerCache) -> ModelCatalog:
    """Built-in objects, fingers (with their URDFs), hands and planners; the fingers and
    hands loaded through ``cache``."""
    objects = [ObjectInfo(shape=name, parameters=list(s.parameters), description=s.description)
               for name, s in SHAPES.items()]
    fingers = []
    for name in BUILTIN_FINGERS:
        f = cache.finger(FingerModelSpec(builtin=name))
        fingers.append(FingerInfo(
            name=name, tip_frame=f.tip_frame, n_joints=f.nq,
            joint_names=list(f.joint_names), pad_half_size=f.pad_half_size,
            base_position=[float(x) for x in f.base_position],
            base_rotation=rotation_vector(f.base_rotation), urdf=f.urdf_text))
    hands = []
    for name in BUILTIN_HANDS:
        if name == "allegro":
            hands.append(_allegro_info(cache))
            continue
        with cache.lock:
            hand = cache.hand(HandModel(builtin=name))
        nominal = hand_fingertips(hand)
        hands.append(HandInfo(
            name=name, n_fingers=hand.n_fingers,
            fingers=[HandFingerInfo(
                name=hand_finger_name(hand, k), tip_frame=f.tip_frame, n_joints=f.nq,
                joint_names=list(f.joint_names), pad_half_size=f.pad_half_size,
                base_position=[float(x) for x in hand.mounts[k][1]],
                base_rotation=rotation_vector(hand.mounts[k][0]),
                nominal_q=None if hand.nominal_q is None else list(hand.nominal_q[k]),
                nominal_chart_rotation=list(nominal[k].chart_rotation))
                for k, f in enumerate(hand.fingers)],
            nominal_object_position=list(hand.nominal_object_position),
            nominal_radius=hand.nominal_radius, urdf=hand.urdf_text))
    return ModelCatalog(planners=list(PLANNERS), objects=objects, fingers=fingers,
                        hands=hands)


def _allegro_info(cache: FingerCache) -> HandInfo:
    """The built-in Allegro-class hand: its round fingertips and nominal grasp."""
    from ocp.robots.allegro import (
        NOMINAL_OBJECT_POSITION,
        NOMINAL_Q,
        NOMINAL_RADIUS,
        mjcf_text,
    )
    from ocp.spec.grasp import fingertips_from_joints
    from ocp.spec.motion import ObjectPose
    from ocp.spec.problem import ObjectSpec

    with cache.lock:
        hand = cache.hand(HandModel(builtin="allegro"))
    names = tuple(hand_finger_name(hand, k) for k in range(hand.n_fingers))
    tips = fingertips_from_joints(hand.fingers, NOMINAL_Q, ObjectSpec("sphere", (NOMINAL_RADIUS,)),
                                  ObjectPose(position=NOMINAL_OBJECT_POSITION), names, names)
    R, p = hand.mount
    return HandInfo(
        name="allegro", n_fingers=hand.n_fingers,
        fingers=[HandFingerInfo(
            name=names[k], tip_frame=f.tip_frame, n_joints=f.nq,
            joint_names=list(f.joint_names), pad_half_size=None,
            tip_surface=f.tip_surface.describe(),
            nominal_initial=list(tips[k].initial),
            base_position=[float(x) for x in p], base_rotation=rotation_vector(R),
            nominal_q=list(NOMINAL_Q[k]),
            nominal_chart_rotation=list(tips[k].chart_rotation))
            for k, f in enumerate(hand.fingers)],
        nominal_object_position=list(NOMINAL_OBJECT_POSITION),
        nominal_radius=NOMINAL_RADIUS, urdf=hand.text, mjcf=mjcf_text())
