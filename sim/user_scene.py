"""The user's MJCF hand made a MuJoCo scene for executing a plan (docs/simulation.md,
"On your own model"): the file as MuJoCo reads it with three changes, each reported. Every
mesh geom removed (meshes are files the service never reads: their collisions and, on a
body without an ``<inertial>``, their mass go with them; a geom whose mesh comes from its
default class is a small sphere without mass or contacts) and the mesh assets with them,
keyframes dropped (the object adds a free joint); the physics step and gravity the
simulator's and the plan's (the file's are reported); the object added as a free body at
the plan's initial pose (the plan's shape and mass; its friction the plan's ``mu`` and the
simulator's torsional and rolling friction, its ``condim`` the simulator's; its ``solmix``
tiny, so that each contact takes the hand geom's ``solref`` and ``solimp``). A ``mount``
places the model's world frame in the palm frame (a body wrapping the world's bodies).
Moving bodies left without mass are named (:func:`massless_links`) or given one
(:func:`with_inertials`).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from typing import Any

import mujoco
import numpy as np

from ocp.robots.mjcf_frames import strip_files

from .options import SimOptions
from .scene import quat_of_matrix
from .spec import ExecutionPlan, FloatArray

__all__ = ["MASSLESS", "OBJECT", "OBJECT_SOLMIX", "UserModel", "compiled", "massless_links",
           "user_scene", "with_inertials"]

#: The object's body, joint and geom in the scene (not a name a hand file uses).
OBJECT = "dexroll_object"
#: The object's ``solmix``: each contact takes the hand geom's solref and solimp.
OBJECT_SOLMIX = 1e-6
#: MuJoCo's defaults of what a file may leave out.
_MJ_TIMESTEP, _MJ_GRAVITY = 0.002, (0.0, 0.0, -9.81)


@dataclass(frozen=True)
class UserModel:
    """The user's hand: its MJCF ``text``, per finger of the plan the body or site its
    tip is (``tips``, in the plan's finger order), and the pose of the model's world frame
    in the palm frame (``mount``: rotation, position)."""

    text: str
    tips: tuple[str, ...]
    mount_rotation: FloatArray = field(default_factory=lambda: np.eye(3))
    mount_position: FloatArray = field(default_factory=lambda: np.zeros(3))


def _v(x: Any) -> str:
    return " ".join(f"{float(v):.17g}" for v in np.asarray(x, dtype=float).ravel())


def _floats(text: str | None, default: tuple[float, ...]) -> tuple[float, ...]:
    return default if text is None else tuple(float(v) for v in text.split())


def user_scene(plan: ExecutionPlan, model: UserModel, options: SimOptions
               ) -> tuple[str, dict[str, Any]]:
    """The scene's MJCF (module docstring) and what was changed in the file: meshes
    removed (the geoms, where), keyframes dropped, the file's step and gravity."""
    root = ET.fromstring(model.text)
    parents = {c: p for p in root.iter() for c in p}
    removed: list[str] = []
    massless: set[str] = set()
    for geom in list(root.iter("geom")):
        parent = parents[geom]
        if parent.tag == "default":
            continue
        if "mesh" in geom.attrib or geom.get("type") in ("mesh", "hfield") \
                or "hfield" in geom.attrib:
            body = parent.get("name", "(unnamed body)")
            removed.append(f"{body}/{geom.get('name') or geom.get('mesh') or 'geom'}")
            if parent.find("inertial") is None:
                massless.add(body)
            parent.remove(geom)
    keyframes = [k for k in root.iter("keyframe")]
    for k in keyframes:
        root.remove(k)
    opt = root.find("option")
    if opt is None:
        opt = ET.Element("option")
        root.insert(1 if root.find("compiler") is not None else 0, opt)
    file_step = float(opt.get("timestep", _MJ_TIMESTEP))
    file_gravity = _floats(opt.get("gravity"), _MJ_GRAVITY)
    opt.set("timestep", f"{options.timestep:.17g}")
    opt.set("gravity", _v(plan.gravity))
    world = root.find("worldbody")
    if world is None:
        raise ValueError("the model has no <worldbody>")
    if not (np.allclose(model.mount_rotation, np.eye(3)) and
            np.allclose(model.mount_position, 0.0)):
        mount = ET.Element("body", name="dexroll_mount", pos=_v(model.mount_position),
                           quat=_v(quat_of_matrix(model.mount_rotation)))
        for child in list(world):
            if child.tag in ("body", "geom", "site", "camera", "light", "frame"):
                world.remove(child)
                mount.append(child)
        world.append(mount)
    torsion = options.torsional_friction if options.torsional_friction is not None else \
        plan.torsional_friction if plan.torsional_friction is not None else \
        options.DEFAULT_TORSIONAL
    strip_files(root, inert=True)  # the default classes' mesh geoms: no mass, no contacts
    plan.object.add_asset(root)  # the object's own mesh, if it is one (vertices inline)
    obj = ET.SubElement(world, "body", name=OBJECT, pos=_v(plan.object_position[0]),
                        quat=_v(plan.object_wxyz[0] / np.linalg.norm(plan.object_wxyz[0])))
    ET.SubElement(obj, "freejoint", name=OBJECT)
    mass = options.object_mass if options.object_mass is not None else plan.object.mass
    # its inertia stated: a file's <compiler inertiafromgeom="false"> would leave the body
    # MuJoCo's boundmass (1e-6 kg) and no inertia
    obj.append(_object_inertial(plan, mass))
    ET.SubElement(obj, "geom", plan.object.geom_attributes(), name=OBJECT,
                  mass=f"{mass:.17g}", contype="1", conaffinity="1", condim=str(options.condim),
                  friction=_v([plan.mu, torsion, options.rolling_friction]),
                  solmix=f"{OBJECT_SOLMIX:.17g}", priority="0", margin="0", gap="0",
                  rgba="0.9 0.5 0.1 1")
    changes = {"meshes_removed": removed,
               "bodies_without_inertial_that_lost_mesh_geoms": sorted(massless),
               "keyframes_dropped": len(keyframes),
               "file_timestep": file_step, "file_gravity": list(file_gravity)}
    return ET.tostring(root, encoding="unicode"), changes


def _object_inertial(plan: ExecutionPlan, mass: float) -> ET.Element:
    """The object body's ``<inertial>``: the uniform solid of its geom weighing ``mass``
    [kg], as MuJoCo computes it from the geom alone (a model of the object by itself)."""
    root = ET.Element("mujoco")
    plan.object.add_asset(root)
    body = ET.SubElement(ET.SubElement(root, "worldbody"), "body")
    ET.SubElement(body, "freejoint")
    ET.SubElement(body, "geom", plan.object.geom_attributes(), mass=f"{mass:.17g}")
    m = mujoco.MjModel.from_xml_string(ET.tostring(root, encoding="unicode"))
    return ET.Element("inertial", pos=_v(m.body_ipos[1]), quat=_v(m.body_iquat[1]),
                      mass=_v(m.body_mass[1]), diaginertia=_v(m.body_inertia[1]))


#: A moving body lighter than this [kg] has no mass of its own (MuJoCo's ``boundmass``
#: the scene sets is 1e-6 kg).
MASSLESS = 1e-5


def compiled(xml: str) -> Any:
    try:
        return mujoco.MjModel.from_xml_string(xml)
    except ValueError as exc:
        raise ValueError(f"MuJoCo cannot compile the model: {exc}") from exc


def massless_links(m: Any) -> list[str]:
    """The names of the model's bodies that move (a joint of their own, the object's
    aside) and weigh less than :data:`MASSLESS`."""
    out = []
    for b in range(1, m.nbody):
        name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, b) or f"body {b}"
        if name != OBJECT and int(m.body_jntnum[b]) > 0 and float(m.body_mass[b]) < MASSLESS:
            out.append(name)
    return out


def with_inertials(xml: str, m: Any, bodies: list[str], mass: float) -> str:
    """``xml`` with each of ``bodies`` given ``mass`` [kg] spread evenly over the box that
    bounds its collision geoms (all its geoms when none collides) in the compiled ``m``:
    its centre the centre of mass, the box's inertia."""
    root = ET.fromstring(xml)
    boxes: dict[str, tuple[FloatArray, FloatArray]] = {}
    for name in bodies:
        b = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, name)
        geoms = [g for g in range(m.ngeom) if int(m.geom_bodyid[g]) == b]
        touching = [g for g in geoms if m.geom_contype[g] or m.geom_conaffinity[g]]
        lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
        R = np.zeros(9)
        for g in touching or geoms:
            mujoco.mju_quat2Mat(R, m.geom_quat[g])
            Rg = R.reshape(3, 3)
            centre = m.geom_pos[g] + Rg @ m.geom_aabb[g, :3]
            half = np.abs(Rg) @ m.geom_aabb[g, 3:]
            lo, hi = np.minimum(lo, centre - half), np.maximum(hi, centre + half)
        if not geoms:
            lo, hi = np.full(3, -0.005), np.full(3, 0.005)
        boxes[name] = ((lo + hi) / 2, np.maximum(hi - lo, 1e-3))
    for body in root.iter("body"):
        got = boxes.get(body.get("name", ""))
        if got is None:
            continue
        centre, (a, b_, c) = got
        for old in body.findall("inertial"):
            body.remove(old)
        inertia = [mass / 12.0 * (b_ * b_ + c * c), mass / 12.0 * (a * a + c * c),
                   mass / 12.0 * (a * a + b_ * b_)]
        body.insert(0, ET.Element("inertial", pos=_v(centre), mass=f"{mass:.17g}",
                                  diaginertia=_v(inertia)))
    return ET.tostring(root, encoding="unicode")
