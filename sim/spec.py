"""What the simulator executes: a plan's models and its reference motion as plain data.

An :class:`ExecutionPlan` is everything MuJoCo needs and nothing of the planner: the
object (shape, size, mass), the palm (a plane, or none), every finger as a serial chain
(joint placements, kinds and axes, the mount on the palm, the fingertip frame and the
fingertip's shape in it), the friction, and the plan's motion at its sample times: each
finger's joint angles and rates, the object's pose, every contact's planned point. Plans
whose results carry forces or joint torques add them (``contact_forces``,
``joint_torques``): the controller then uses them as feed-forward.

Frames and units follow docs/conventions.md: SI, the palm frame P is the world (the palm
is the plane z = 0, the object on its z > 0 side), quaternions are (w, x, y, z). The
fingertip frame of a flat pad has its origin at the centre of the pad's surface and +z
its outward normal.

The module is independent of the planner (``ocp``) and of the service: the service's
adapter (``planner_service.execution``) builds a plan from a result and its request, and
:meth:`ExecutionPlan.to_dict` / :meth:`ExecutionPlan.from_dict` write and read it as JSON.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "DEFAULT_MASS",
    "ContactSpec",
    "ExecutionPlan",
    "FingerReference",
    "FingerSpec",
    "JointSpec",
    "ObjectSpec",
    "TipShape",
]

FloatArray = NDArray[np.float64]

#: The object's mass when the plan does not state one [kg]: 50 g (a 25 mm-radius ball of
#: density 764 kg/m^3, a light wooden ball). Inertia: the solid body's, from its shape.
DEFAULT_MASS = 0.05
#: The name of the object's mesh in a scene's ``<asset>``, when its geom is a mesh.
OBJECT_MESH = "dexroll_object_mesh"


def _a(x: Any) -> FloatArray:
    return np.asarray(x, dtype=float)


@dataclass(frozen=True)
class ObjectSpec:
    """The object as MuJoCo collides and weighs it: its geom's ``geom_type`` and
    ``geom_size`` as MJCF reads them [m], in the object's frame (its centre and axes), its
    ``mass`` [kg] (MuJoCo gives it the inertia of that uniform solid); and, for the
    reports, the ``shape`` and ``dimensions`` the plan's request named (the planner's
    shapes make the geom: ``ocp.shapes.Shape.mujoco_geom``)."""

    geom_type: str
    geom_size: tuple[float, ...]
    mass: float = DEFAULT_MASS
    shape: str = ""
    dimensions: tuple[float, ...] = ()
    #: a mesh geom's vertices (x, y, z flattened) [m]: MuJoCo collides their convex hull
    geom_vertices: tuple[float, ...] = ()

    def geom_attributes(self) -> dict[str, str]:
        """The geom element's ``type`` and ``size`` (a mesh's name), at full precision."""
        if self.geom_type == "mesh":
            return {"type": "mesh", "mesh": OBJECT_MESH}
        return {"type": self.geom_type,
                "size": " ".join(f"{float(x):.17g}" for x in self.geom_size)}

    def add_asset(self, root: ET.Element) -> None:
        """A mesh geom's ``<mesh>`` in the scene's ``<asset>`` (made when missing)."""
        if self.geom_type != "mesh":
            return
        asset = root.find("asset")
        if asset is None:
            asset = ET.Element("asset")
            root.insert(0, asset)
        ET.SubElement(asset, "mesh", name=OBJECT_MESH,
                      vertex=" ".join(f"{float(x):.17g}" for x in self.geom_vertices))


@dataclass(frozen=True)
class JointSpec:
    """One joint of a finger's chain: its placement in its parent joint's frame (the
    finger's base frame for the first) and its motion: 'revolute' about ``axis`` [rad] or
    'prismatic' along it [m]; position limits (None: unlimited)."""

    name: str
    kind: str
    axis: tuple[float, float, float]
    rotation: FloatArray
    translation: FloatArray
    lower: float | None = None
    upper: float | None = None


@dataclass(frozen=True)
class TipShape:
    """The fingertip's surface, placed in the fingertip frame (the frame the finger's
    kinematics gives) by ``rotation`` and ``offset`` [m] (``p_tip = rotation p + offset``),
    as the planner places its tip surfaces (ocp/geometry/tips.py): ``kind`` 'box' (a flat
    pad: ``size`` (half x, half y, thickness); its frame's origin the centre of the pad's
    surface, +z its outward normal, the body below), 'sphere' (``size`` (radius,), its
    frame's origin the centre), 'ellipsoid' (an ellipsoid of revolution: (a, c), axis z,
    origin the centre) or 'capsule' (``size`` (radius, half length of the cylinder): its
    frame's origin the centre of the cap that touches, the capsule's axis pointing out of
    the cap along the frame's -y, the cylinder on +y)."""

    kind: str
    size: tuple[float, ...]
    rotation: FloatArray = field(default_factory=lambda: np.eye(3))
    offset: FloatArray = field(default_factory=lambda: np.zeros(3))

    def geom(self) -> tuple[str, FloatArray, FloatArray, FloatArray]:
        """(MuJoCo geom type, size, position, rotation matrix) in the fingertip frame."""
        R, o = _a(self.rotation), _a(self.offset)
        if self.kind == "box":
            hx, hy, thick = self.size
            return "box", _a([hx, hy, thick / 2]), o + R @ _a([0.0, 0.0, -thick / 2]), R
        if self.kind == "sphere":
            return "sphere", _a([self.size[0]]), o, R
        if self.kind == "ellipsoid":
            a, c = self.size[:2]
            return "ellipsoid", _a([a, a, c]), o, R
        if self.kind == "capsule":
            r, half = self.size[0], self.size[1] if len(self.size) > 1 else 0.0
            if half <= 0:
                return "sphere", _a([r]), o, R
            # MuJoCo's capsule lies along its z: turn it onto the frame's y
            Rx = _a([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
            return "capsule", _a([r, half]), o + R @ _a([0.0, half, 0.0]), R @ Rx
        raise ValueError(f"unknown fingertip shape {self.kind!r}")


@dataclass(frozen=True)
class FingerSpec:
    """A finger: its chain, its base's mount in the palm frame, its fingertip frame's
    placement in the last joint's frame and the fingertip's shape; ``contact`` names the
    plan's contact of this fingertip."""

    name: str
    joints: tuple[JointSpec, ...]
    base_rotation: FloatArray
    base_position: FloatArray
    tip_rotation: FloatArray
    tip_translation: FloatArray
    tip: TipShape
    contact: str

    @property
    def nq(self) -> int:
        return len(self.joints)

    @property
    def joint_names(self) -> tuple[str, ...]:
        return tuple(j.name for j in self.joints)


@dataclass(frozen=True)
class ContactSpec:
    """A planned contact: its name, the body touching the object ('palm' or 'finger'),
    the finger's name (None for the palm), the planned contact point [m] and the object's
    outward normal there (None: not known) at the plan's times (rows); ``active``: at
    those times, 1 where the plan has it touching, 0 where its fingertip is lifted
    (finger gaiting; between: a force ramp), None: touching throughout."""

    name: str
    body: str
    finger: str | None
    point: FloatArray
    normal: FloatArray | None = None
    active: FloatArray | None = None


@dataclass(frozen=True)
class FingerReference:
    """A finger's planned joints at the plan's times: angles ``q`` and rates ``q_dot``
    (rows: times; columns: the finger's joints) [rad, rad/s; m, m/s for prismatic joints].
    ``joint_torques`` (the plan's, when it has them) [N m]; ``contact_force``: the force
    the fingertip applies to the object, palm frame [N], at the contact's planned point."""

    q: FloatArray
    q_dot: FloatArray
    joint_torques: FloatArray | None = None
    contact_force: FloatArray | None = None


@dataclass(frozen=True)
class ExecutionPlan:
    """A plan to execute (see the module): ``t`` [s] its sample times (increasing),
    ``object_position`` [m] and ``object_wxyz`` (rows: times), every finger and its
    reference (same order), the contacts, the palm (``palm_half_extent`` [m]; None: no
    palm), the friction coefficient ``mu``, the torsional friction ``torsional_friction``
    [m] (None: the simulator's default) and gravity [m/s^2] in the palm frame."""

    t: FloatArray
    object: ObjectSpec
    object_position: FloatArray
    object_wxyz: FloatArray
    fingers: tuple[FingerSpec, ...]
    references: tuple[FingerReference, ...]
    contacts: tuple[ContactSpec, ...]
    palm_half_extent: float | None
    mu: float
    torsional_friction: float | None = None
    gravity: tuple[float, float, float] = (0.0, 0.0, -9.81)
    notes: tuple[str, ...] = field(default=())
    #: the grip's squeeze [m] this plan is executed with unless the options give one
    #: (None: :data:`SimOptions.DEFAULT_SQUEEZE`)
    squeeze: float | None = None
    #: the force control (``SimOptions.force_control``) this plan is executed with unless
    #: the options give one (None: 'off')
    force_control: str | None = None

    @property
    def duration(self) -> float:
        return float(self.t[-1] - self.t[0])

    @property
    def has_forces(self) -> bool:
        return any(r.joint_torques is not None or r.contact_force is not None
                   for r in self.references)

    def check(self) -> None:
        """ValueError when the arrays do not fit together."""
        n = self.t.size
        if n < 2 or not np.all(np.diff(self.t) >= 0):
            raise ValueError("the plan needs two or more increasing sample times")
        if self.object_position.shape != (n, 3) or self.object_wxyz.shape != (n, 4):
            raise ValueError("the object's pose needs one row per sample time")
        if len(self.fingers) != len(self.references):
            raise ValueError("one reference per finger")
        for f, r in zip(self.fingers, self.references, strict=True):
            if r.q.shape != (n, f.nq) or r.q_dot.shape != (n, f.nq):
                raise ValueError(f"finger {f.name}: q and q_dot need {n} rows of {f.nq}")
        if not (math.isfinite(self.mu) and self.mu > 0):
            raise ValueError("mu must be positive")

    # -- JSON -----------------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        def joint(j: JointSpec) -> dict[str, Any]:
            return {"name": j.name, "kind": j.kind, "axis": list(j.axis),
                    "rotation": j.rotation.tolist(), "translation": j.translation.tolist(),
                    "lower": j.lower, "upper": j.upper}

        def finger(f: FingerSpec, r: FingerReference) -> dict[str, Any]:
            return {"name": f.name, "contact": f.contact,
                    "joints": [joint(j) for j in f.joints],
                    "base_rotation": f.base_rotation.tolist(),
                    "base_position": f.base_position.tolist(),
                    "tip_rotation": f.tip_rotation.tolist(),
                    "tip_translation": f.tip_translation.tolist(),
                    "tip": {"kind": f.tip.kind, "size": list(f.tip.size),
                            "rotation": _a(f.tip.rotation).tolist(),
                            "offset": _a(f.tip.offset).tolist()},
                    "q": r.q.tolist(), "q_dot": r.q_dot.tolist(),
                    "joint_torques": None if r.joint_torques is None
                    else r.joint_torques.tolist(),
                    "contact_force": None if r.contact_force is None
                    else r.contact_force.tolist()}

        return {
            "t": self.t.tolist(),
            "object": {"geom_type": self.object.geom_type,
                       "geom_size": list(self.object.geom_size),
                       "geom_vertices": list(self.object.geom_vertices),
                       "mass": self.object.mass,
                       "shape": self.object.shape, "dimensions": list(self.object.dimensions)},
            "object_position": self.object_position.tolist(),
            "object_wxyz": self.object_wxyz.tolist(),
            "fingers": [finger(f, r) for f, r in zip(self.fingers, self.references,
                                                     strict=True)],
            "contacts": [{"name": c.name, "body": c.body, "finger": c.finger,
                          "point": c.point.tolist(),
                          "normal": None if c.normal is None else c.normal.tolist(),
                          "active": None if c.active is None else c.active.tolist()}
                         for c in self.contacts],
            "palm_half_extent": self.palm_half_extent, "mu": self.mu,
            "torsional_friction": self.torsional_friction, "gravity": list(self.gravity),
            "notes": list(self.notes), "squeeze": self.squeeze,
            "force_control": self.force_control,
        }

    @staticmethod
    def from_dict(raw: dict[str, Any]) -> ExecutionPlan:
        def joint(j: dict[str, Any]) -> JointSpec:
            ax = [float(x) for x in j["axis"]]
            return JointSpec(str(j["name"]), str(j["kind"]), (ax[0], ax[1], ax[2]),
                             _a(j["rotation"]), _a(j["translation"]), j.get("lower"),
                             j.get("upper"))

        fingers, refs = [], []
        for f in raw["fingers"]:
            fingers.append(FingerSpec(
                str(f["name"]), tuple(joint(j) for j in f["joints"]), _a(f["base_rotation"]),
                _a(f["base_position"]), _a(f["tip_rotation"]), _a(f["tip_translation"]),
                TipShape(str(f["tip"]["kind"]), tuple(float(s) for s in f["tip"]["size"]),
                         _a(f["tip"].get("rotation", np.eye(3))),
                         _a(f["tip"].get("offset", np.zeros(3)))),
                str(f["contact"])))
            refs.append(FingerReference(
                _a(f["q"]), _a(f["q_dot"]),
                None if f.get("joint_torques") is None else _a(f["joint_torques"]),
                None if f.get("contact_force") is None else _a(f["contact_force"])))
        o = raw["object"]
        g = [float(x) for x in raw.get("gravity", (0.0, 0.0, -9.81))]
        plan = ExecutionPlan(
            _a(raw["t"]), ObjectSpec(str(o["geom_type"]),
                                     tuple(float(d) for d in o["geom_size"]),
                                     float(o.get("mass", DEFAULT_MASS)), str(o.get("shape", "")),
                                     tuple(float(d) for d in o.get("dimensions", ())),
                                     tuple(float(d) for d in o.get("geom_vertices", ()))),
            _a(raw["object_position"]), _a(raw["object_wxyz"]), tuple(fingers), tuple(refs),
            tuple(ContactSpec(str(c["name"]), str(c["body"]), c.get("finger"), _a(c["point"]),
                              None if c.get("normal") is None else _a(c["normal"]),
                              None if c.get("active") is None else _a(c["active"]))
                  for c in raw["contacts"]),
            raw.get("palm_half_extent"), float(raw["mu"]), raw.get("torsional_friction"),
            (g[0], g[1], g[2]), tuple(raw.get("notes", ())),
            squeeze=None if raw.get("squeeze") is None else float(raw["squeeze"]),
            force_control=raw.get("force_control"))
        plan.check()
        return plan
