"""The MJCF scene of a plan: the palm, the object on a free joint, every finger as nested
bodies built from its chain, a fingertip geom of the planned surface, one servo actuator
per joint.

Names: the object's body and geom ``object``; the palm's geom ``palm``; a finger's
bodies ``<finger>/<joint>``, its fingertip body ``<finger>/tip`` with the geom
``<finger>/pad`` and the site ``<finger>/tip`` (the fingertip frame); joints and
actuators ``<finger>/<joint>``. Only the object collides, with the palm and the
fingertips (links pass through each other and the palm: the plan keeps them clear
kinematically, and the simulator checks the contacts the plan has).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np

from .options import SimOptions
from .spec import ExecutionPlan, FingerSpec

__all__ = ["KINEMATIC_ARMATURE", "mjcf", "quat_of_matrix"]

#: A joint's armature when the mode sets the fingers to the plan [kg m^2].
KINEMATIC_ARMATURE = 1e3


def quat_of_matrix(R: np.ndarray) -> np.ndarray:
    """The unit quaternion (w, x, y, z), w >= 0, of a rotation matrix."""
    R = np.asarray(R, dtype=float)
    t = float(np.trace(R))
    if t > 0:
        s = 2.0 * np.sqrt(t + 1.0)
        q = np.array([0.25 * s, (R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s,
                      (R[1, 0] - R[0, 1]) / s])
    else:
        i = int(np.argmax(np.diag(R)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * np.sqrt(max(1.0 + R[i, i] - R[j, j] - R[k, k], 1e-300))
        q = np.empty(4)
        q[0] = (R[k, j] - R[j, k]) / s
        q[1 + i] = 0.25 * s
        q[1 + j] = (R[j, i] + R[i, j]) / s
        q[1 + k] = (R[k, i] + R[i, k]) / s
    q /= np.linalg.norm(q)
    return q if q[0] >= 0 else -q


def _v(x: object) -> str:
    return " ".join(f"{float(v):.17g}" for v in np.asarray(x, dtype=float).ravel())


def _pose(el: ET.Element, R: np.ndarray, p: np.ndarray) -> None:
    el.set("pos", _v(p))
    el.set("quat", _v(quat_of_matrix(R)))


def _finger(parent: ET.Element, finger: FingerSpec, options: SimOptions) -> None:
    base = ET.SubElement(parent, "body", name=f"{finger.name}/base")
    _pose(base, finger.base_rotation, finger.base_position)
    body = base
    m, I = options.link_mass, max(options.link_mass * 1e-4, 1e-8)
    # a finger moved kinematically is set to the plan at every step: so heavy that the
    # contacts cannot push it within one
    armature = options.armature if options.mode == "servo" else KINEMATIC_ARMATURE
    for j in finger.joints:
        body = ET.SubElement(body, "body", name=f"{finger.name}/{j.name}", gravcomp="1")
        _pose(body, j.rotation, j.translation)
        ET.SubElement(body, "inertial", pos="0 0 0", mass=f"{m:.17g}",
                      diaginertia=f"{I:.17g} {I:.17g} {I:.17g}")
        joint = ET.SubElement(body, "joint", name=f"{finger.name}/{j.name}",
                              type="hinge" if j.kind == "revolute" else "slide",
                              axis=_v(j.axis), armature=f"{armature:.17g}")
        joint.set("limited", "false")  # the plan keeps them; the servo must not be clipped
    tip = ET.SubElement(body, "body", name=f"{finger.name}/tip", gravcomp="1")
    _pose(tip, finger.tip_rotation, finger.tip_translation)
    kind, size, pos, rot = finger.tip.geom()
    ET.SubElement(tip, "geom", name=f"{finger.name}/pad", type=kind, size=_v(size),
                  pos=_v(pos), quat=_v(quat_of_matrix(rot)), contype="0", conaffinity="1",
                  mass="0", rgba="0.15 0.15 0.15 1")
    ET.SubElement(tip, "site", name=f"{finger.name}/tip", pos="0 0 0", size="0.002")


def mjcf(plan: ExecutionPlan, options: SimOptions) -> str:
    """The scene's MJCF (see the module) with the plan's initial pose as ``qpos0``."""
    root = ET.Element("mujoco", model="dexroll_plan")
    ET.SubElement(root, "compiler", angle="radian", autolimits="true")
    opt = ET.SubElement(root, "option", timestep=f"{options.timestep:.17g}",
                        gravity=_v(plan.gravity), cone="elliptic",
                        impratio=f"{options.impratio:.17g}",
                        noslip_iterations=str(options.noslip_iterations),
                        integrator="implicitfast")
    opt.set("iterations", "100")
    ET.SubElement(opt, "flag", warmstart="enable")
    torsion = options.torsional_friction if options.torsional_friction is not None else \
        plan.torsional_friction if plan.torsional_friction is not None else \
        options.DEFAULT_TORSIONAL
    default = ET.SubElement(root, "default")
    ET.SubElement(default, "geom", condim=str(options.condim),
                  friction=_v([plan.mu, torsion, options.rolling_friction]),
                  solref=_v(options.solref), solimp="0.95 0.99 0.0005 0.5 2")
    world = ET.SubElement(root, "worldbody")
    if plan.palm_half_extent is not None:
        h = plan.palm_half_extent
        ET.SubElement(world, "geom", name="palm", type="plane", size=_v([h, h, 0.01]),
                      contype="0", conaffinity="1", rgba="0.8 0.8 0.75 1")
    obj = ET.SubElement(world, "body", name="object")
    obj.set("pos", _v(plan.object_position[0]))
    obj.set("quat", _v(plan.object_wxyz[0] / np.linalg.norm(plan.object_wxyz[0])))
    ET.SubElement(obj, "freejoint", name="object")
    mass = options.object_mass if options.object_mass is not None else plan.object.mass
    plan.object.add_asset(root)
    ET.SubElement(obj, "geom", plan.object.geom_attributes(), name="object",
                  mass=f"{mass:.17g}", contype="1", conaffinity="1", rgba="0.9 0.5 0.1 1")
    for finger in plan.fingers:
        _finger(world, finger, options)
    actuators = ET.SubElement(root, "actuator")
    for finger in plan.fingers:
        for j in finger.joints:
            name = f"{finger.name}/{j.name}"
            ET.SubElement(actuators, "general", name=name, joint=name,
                          gaintype="fixed", biastype="affine", gainprm=f"{options.kp:.17g}",
                          biasprm=f"0 {-options.kp:.17g} {-options.kv:.17g}",
                          ctrllimited="false", forcelimited="false")
    return ET.tostring(root, encoding="unicode")
