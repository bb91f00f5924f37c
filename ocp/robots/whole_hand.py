"""Whole-hand models from one URDF or MJCF text: fingers named by their fingertip links.

A hand comes as one file for the whole hand. :func:`load_whole_hand` builds it with
Pinocchio (``buildModelFromXML`` for a URDF, ``buildModelFromMJCF`` for an MJCF), and
makes one :class:`~ocp.robots.finger.FingerModel` per named fingertip: the chain from the
hand's root to that link (body, or a frame of it; the joints of the other fingers held out
of it), mounted in the palm frame by the request's mount, its fingertip surface read from
the link's collision geometry (a sphere or a capsule: its size and offset) or given.

An MJCF is read in MuJoCo's frames (:mod:`ocp.robots.mjcf_frames`: what Pinocchio 4.1
misreads is corrected or refused), and the result is checked when it is loaded: its
bodies and sites against MuJoCo's ``mj_kinematics`` of the same text (where MuJoCo is
installed), a URDF's links against its own joint origins (:mod:`ocp.robots.urdf_frames`);
a model read in another frame is refused (:func:`frame_problems`).

What Pinocchio would not model is refused before it builds anything, naming what and
where (:class:`HandModelError`, (field, reason) pairs): an MJCF ``<include>`` (a file the
service would read), joint couplings it does not plan (URDF ``<mimic>``; MJCF couplings
that are not linear or span two fingers: the linear ones are read as MuJoCo compiles
them, :mod:`ocp.robots.couplings`), joint types other than revolute/hinge and
prismatic/slide (ball, free, planar, floating, continuous without limits).
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ocp.geometry.tips import TipSurface, capsule_tip, sphere_tip
from ocp.robots.mjcf_frames import MjcfReadError, build_mjcf, mujoco_disagreements, site_pose
from ocp.robots.urdf_frames import kinematic_urdf, urdf_disagreements

__all__ = ["DEFAULT_VELOCITY", "HandModelError", "TipSpec", "WholeHand", "load_whole_hand",
           "model_problems", "tip_geometry"]

FloatArray = NDArray[np.float64]

#: Joint velocity limit where a model gives none (an MJCF) [rad/s, m/s].
DEFAULT_VELOCITY = 6.0


class HandModelError(ValueError):
    """A hand model that cannot be used: ``errors`` are (field, reason) pairs, fields
    relative to the hand's spec (``model``, ``tips[1].name``, ...)."""

    def __init__(self, errors: list[tuple[str, str]]) -> None:
        super().__init__("; ".join(f"{f}: {r}" for f, r in errors))
        self.errors = errors


@dataclass(frozen=True)
class TipSpec:
    """A fingertip of the hand: the link (URDF), body (MJCF) or frame ``name`` the finger
    ends at, and its surface (None: read from that link's sphere or capsule collision
    geometry). ``side``: for a capsule read from the model, the direction (link frame)
    across its axis the contacts lean to (default: the link's x axis, else y)."""

    name: str
    surface: TipSurface | None = None
    side: tuple[float, float, float] | None = None


def _floats(text: str | None, n: int, default: Sequence[float]) -> FloatArray:
    if text is None:
        return np.asarray(default, dtype=float)
    vals = [float(v) for v in text.split()]
    if len(vals) != n:
        raise ValueError(f"expected {n} numbers, got {text!r}")
    return np.asarray(vals, dtype=float)


def _quat(q: FloatArray) -> FloatArray:
    w, x, y, z = q / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def _rpy(rpy: FloatArray) -> FloatArray:
    r, p, y = rpy
    cr, sr, cp, sp, cy, sy = (math.cos(r), math.sin(r), math.cos(p), math.sin(p),
                              math.cos(y), math.sin(y))
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


def _side(side: ArrayLike | None, axis: FloatArray) -> FloatArray:
    if side is not None:
        return np.asarray(side, dtype=float)
    for cand in (np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])):
        if np.linalg.norm(cand - np.dot(cand, axis) * axis) > 0.5:
            return cand
    return np.array([0.0, 0.0, 1.0])  # pragma: no cover - unreachable


def _capsule(r: float, half: float, centre: FloatArray, R: FloatArray,
             side: ArrayLike | None, tip: tuple[FloatArray, FloatArray] | None = None
             ) -> TipSurface:
    """The cap of a capsule (axis its frame's z, ``R``, ``centre`` in the link frame)
    farther from the link's origin (the fingertip's end), in the tip frame ``tip`` (its
    rotation and origin in the link frame; None: the link frame, as ``side``)."""
    axis = R[:, 2]
    ends = [centre + half * axis, centre - half * axis]
    k = int(np.argmax([np.linalg.norm(e) for e in ends]))
    out = axis if k == 0 else -axis
    cap = ends[k]
    if tip is not None:
        cap, out = tip[0].T @ (cap - tip[1]), tip[0].T @ out
    return capsule_tip(r, cap, out, _side(side, out), half)


def _mjcf_defaults(root: ET.Element) -> dict[str, dict[str, str]]:
    """geom attributes of every MJCF default class, inheritance resolved."""
    out: dict[str, dict[str, str]] = {}

    def walk(el: ET.Element, inherited: dict[str, str]) -> None:
        name = el.get("class", "main")
        geom = dict(inherited)
        for child in el:
            if child.tag == "geom":
                geom.update(child.attrib)
        out[name] = geom
        for child in el:
            if child.tag == "default":
                walk(child, geom)

    for d in root.iter("default"):
        if d not in [c for p in root.iter("default") for c in p]:  # top-level defaults
            walk(d, {})
    return out


def tip_geometry(text: str, fmt: str, name: str, side: ArrayLike | None = None
                 ) -> TipSurface | str:
    """The fingertip surface of link/body ``name`` from the model text's collision
    geometry (a sphere or capsule on it: URDF ``<collision>``, MJCF ``<geom>`` that
    collides with the object, :func:`touches_object`, not a visual one; of several, the
    one reaching farthest along the finger (from its last joint out through the link's
    or body's origin, :func:`_outward`: the finger's end; from the origin where the chain
    has no length), or for an MJCF site the one nearest the site, in the site's frame),
    or why there is none (a string). An MJCF's geoms are read by ``pos`` and ``quat`` or
    ``fromto``: give the text :func:`~ocp.robots.mjcf_frames.normalise_mjcf` wrote."""
    root = ET.fromstring(text)
    if fmt == "urdf":
        link = next((ln for ln in root.iter("link") if ln.get("name") == name), None)
        if link is None:
            return f"no link {name!r} carries collision geometry in the URDF"
        kinds, tips = [], []
        for col in link.iter("collision"):
            origin = col.find("origin")
            p = _floats(None if origin is None else origin.get("xyz"), 3, (0, 0, 0))
            R = _rpy(_floats(None if origin is None else origin.get("rpy"), 3, (0, 0, 0)))
            geo = col.find("geometry")
            for g in [] if geo is None else list(geo):
                kinds.append(g.tag)
                if g.tag in ("sphere", "capsule"):
                    half = float(g.get("length", "nan")) / 2 if g.tag == "capsule" else 0.0
                    tips.append((g.tag, p, R, half, float(g.get("radius", "nan"))))
        if not tips:
            return (f"link {name!r} has no sphere or capsule collision geometry (it has "
                    f"{kinds or 'none'}): give the fingertip's surface in the request")
        out = _outward(root, "urdf", name)
        kind, p, R, half, r = max(tips, key=lambda t: _reach(t, None, out))
        return sphere_tip(r, p, R) if kind == "sphere" else _capsule(r, half, p, R, side)
    defaults = _mjcf_defaults(root)
    parents = {c: p for p in root.iter() for c in p}
    body = next((b for b in root.iter("body") if b.get("name") == name), None)
    R_s, p_s = np.eye(3), np.zeros(3)  # the tip frame in the body's
    site = None
    if body is None:
        site = next((s for s in root.iter("site") if s.get("name") == name), None)
        if site is None:
            return f"no body or site {name!r} in the MJCF"
        body = parents[site]
        R_s, p_s = site_pose(root, site)
    kinds, skipped = [], []
    poses: list[tuple[str, FloatArray, FloatArray, float, float] | str] = []
    for g in body.findall("geom"):
        cls = g.get("class")
        el: ET.Element | None = body
        while cls is None and el is not None:
            cls = el.get("childclass")
            el = parents.get(el)
        attrs = {**defaults.get("main", {}), **defaults.get(cls or "main", {}), **g.attrib}
        kind = attrs.get("type", "sphere")
        kinds.append(kind)
        if kind not in ("sphere", "capsule"):
            continue
        if not touches_object(attrs):
            skipped.append(attrs.get("name") or kind)
            continue
        poses.append(_tip_pose(name, attrs, kind))
    if not poses:
        why = f"; not colliding with the object: {skipped}" if skipped else ""
        return (f"body {name!r} has no sphere or capsule geom that collides with the object "
                f"(it has {kinds or 'none'}{why}): give the fingertip's surface in the "
                "request")

    out = _outward(root, "mjcf", str(body.get("name") or ""), parents)
    got = max(poses, key=lambda t: -math.inf if isinstance(t, str)
              else _reach(t, None if site is None else p_s, out))
    if isinstance(got, str):
        return got
    kind, p, R, half, r = got
    if kind == "sphere":
        return sphere_tip(r, R_s.T @ (p - p_s), R_s.T @ R)
    return _capsule(r, half, p, R, side, (R_s, p_s))


def _reach(tip: tuple[str, FloatArray, FloatArray, float, float],
           site: FloatArray | None, outward: FloatArray | None = None) -> float:
    """How well a sphere or capsule (kind, centre, rotation, half length, radius) in its
    body's frame is that body's fingertip: how far its surface reaches along the finger
    (``outward``, :func:`_outward`: the finger's end is the outermost; a geom behind the
    origin, toward the palm, reaches less), without a direction the distance it reaches
    from the body's origin, or minus its axis's distance from the tip's ``site`` when one
    is named."""
    _, p, R, half, r = tip
    a, b = p - half * R[:, 2], p + half * R[:, 2]
    if site is not None:
        ab = b - a
        s = float(np.clip((site - a) @ ab / (ab @ ab), 0.0, 1.0)) if ab @ ab > 0 else 0.0
        return -float(np.linalg.norm(a + s * ab - site))
    if outward is not None:
        return max(float(a @ outward), float(b @ outward)) + r
    return max(float(np.linalg.norm(a)), float(np.linalg.norm(b))) + r


#: A link's or body's offset from its parent shorter than this [m] is no length of the
#: finger (:func:`_outward` looks further up the chain).
_NO_LENGTH = 1e-9


def _outward(root: ET.Element, fmt: str, name: str,
             parents: dict[ET.Element, ET.Element] | None = None) -> FloatArray | None:
    """The direction the finger extends in at its tip link or body ``name``, in that
    frame: from the nearest origin up the chain that is not the tip's own (a parent
    link's or body's) to the tip's origin, the chain's rotations at its joints' zero
    positions; None when no origin up the chain differs (a tip at the root)."""
    M = np.eye(3)  # the current frame's vectors in the tip's frame
    if fmt == "urdf":
        by_child = {c.get("link"): j for j in root.iter("joint")
                    for c in j.findall("child")}
        link = name
        for _ in range(64):
            joint = by_child.get(link)
            if joint is None:
                return None
            origin = joint.find("origin")
            xyz = _floats(None if origin is None else origin.get("xyz"), 3, (0, 0, 0))
            R = _rpy(_floats(None if origin is None else origin.get("rpy"), 3, (0, 0, 0)))
            M = M @ R.T
            if float(np.linalg.norm(xyz)) > _NO_LENGTH:
                d = M @ xyz
                return np.asarray(d / np.linalg.norm(d), dtype=float)
            parent = joint.find("parent")
            if parent is None:
                return None
            link = str(parent.get("link"))
        return None
    parents = parents if parents is not None else {c: p for p in root.iter() for c in p}
    body = next((b for b in root.iter("body") if b.get("name") == name), None)
    while body is not None and body.tag == "body":
        pos = _floats(body.get("pos"), 3, (0, 0, 0))
        R = _quat(_floats(body.get("quat"), 4, (1, 0, 0, 0)))
        M = M @ R.T
        if float(np.linalg.norm(pos)) > _NO_LENGTH:
            d = M @ pos
            return np.asarray(d / np.linalg.norm(d), dtype=float)
        body = parents.get(body)
    return None


def touches_object(attrs: dict[str, str]) -> bool:
    """Whether an MJCF geom (its attributes, defaults resolved) collides with the object
    of dexroll's scenes (``contype`` and ``conaffinity`` 1: MuJoCo's rule, either geom's
    type against the other's affinity); a visual geom (both 0) does not."""
    contype, affinity = int(attrs.get("contype", "1")), int(attrs.get("conaffinity", "1"))
    return bool(contype & 1 or affinity & 1)


def _tip_pose(name: str, attrs: dict[str, str], kind: str
              ) -> tuple[str, FloatArray, FloatArray, float, float] | str:
    """A sphere or capsule geom's (kind, centre, rotation, half length, radius) in its
    body's frame, or why it cannot be read."""
    size = _floats(attrs.get("size"), len(attrs.get("size", "").split()) or 1, (0,))
    if any(k in attrs for k in ("euler", "axisangle", "xyaxes", "zaxis")):
        return (f"geom of {name!r}: its orientation is given by "
                f"{[k for k in ('euler', 'axisangle', 'xyaxes', 'zaxis') if k in attrs]}"
                "; only pos, quat or fromto are read: give the fingertip's surface in "
                "the request")
    if "fromto" in attrs:
        ft = _floats(attrs["fromto"], 6, (0,) * 6)
        a, b = ft[:3], ft[3:]
        z = (b - a) / np.linalg.norm(b - a)
        x = np.cross(z, [1.0, 0, 0] if abs(z[0]) < 0.9 else [0, 1.0, 0])
        x /= np.linalg.norm(x)
        R = np.column_stack([x, np.cross(z, x), z])
        p, half = (a + b) / 2, float(np.linalg.norm(b - a)) / 2
    else:
        p = _floats(attrs.get("pos"), 3, (0, 0, 0))
        R = _quat(_floats(attrs.get("quat"), 4, (1, 0, 0, 0)))
        half = float(size[1]) if len(size) > 1 and kind == "capsule" else 0.0
    return kind, p, R, half, float(size[0])


def model_problems(text: str, fmt: str) -> list[tuple[str, str]]:
    """What Pinocchio would not model faithfully in the model text, as ("model", reason):
    includes, couplings not planned, unsupported joint types; [] when none."""
    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        return [("model", f"not well-formed XML: {exc}")]
    errs: list[tuple[str, str]] = []
    if fmt == "mjcf":
        if root.tag != "mujoco":
            return [("model", f"an MJCF's root element is <mujoco>, got <{root.tag}>")]
        for inc in root.iter("include"):
            errs.append(("model", f"<include file={inc.get('file')!r}>: included files are "
                                  "not read; send the whole model as one text"))
        errs += _coupling_problems(root)
        for j in root.iter("freejoint"):
            errs.append(("model", f"<freejoint name={j.get('name')!r}>: a free joint; only "
                                  "hinge and slide joints are supported"))
        for world in root.iter("worldbody"):  # the bodies' joints, not default classes'
            for j in world.iter("joint"):
                kind = j.get("type", "hinge")
                if kind not in ("hinge", "slide"):
                    errs.append(("model", f"joint {j.get('name')!r} is a {kind!r} joint; "
                                          "only hinge and slide joints are supported"))
            for body in world.iter("body"):
                joints = [j.get("name") or "(unnamed)" for j in body.findall("joint")]
                if len(joints) > 1:
                    errs.append(("model", f"body {body.get('name')!r} has {len(joints)} "
                                          f"joints {joints}: MuJoCo moves it by each in "
                                          "turn, dexroll's kinematics take one joint a "
                                          "body; give each joint a body of its own (at "
                                          "the same place, no geoms)"))
    else:
        if root.tag != "robot":
            return [("model", f"a URDF's root element is <robot>, got <{root.tag}>")]
        for j in root.iter("joint"):
            kind_u = j.get("type")
            if j.find("mimic") is not None:
                errs.append(("model", f"joint {j.get('name')!r} mimics "
                                      f"{j.find('mimic').get('joint')!r}: a joint "  # type: ignore[union-attr]
                                      "coupling; coupled joints are not modelled, so this "
                                      "hand is refused"))
            if kind_u not in ("revolute", "prismatic", "fixed"):
                errs.append(("model", f"joint {j.get('name')!r} is a {kind_u!r} joint; only "
                                      "revolute, prismatic and fixed joints are supported"))
            if kind_u in ("revolute", "prismatic"):
                if j.find("limit") is None:  # (urdfdom's reason goes to stderr alone)
                    errs.append(("model", f"joint {j.get('name')!r} ({kind_u}) has no "
                                          "<limit>: the URDF format requires one (lower, "
                                          "upper, effort, velocity)"))
                axis = j.find("axis")
                xyz = _floats(None if axis is None else axis.get("xyz"), 3, (1, 0, 0))
                if not np.all(np.isfinite(xyz)) or float(np.linalg.norm(xyz)) < 1e-9:
                    errs.append(("model", f"joint {j.get('name')!r} has the axis "
                                          f"{axis.get('xyz') if axis is not None else ''!r}: "
                                          "an axis must have a direction (a nonzero xyz)"))
    return errs


def _coupling_problems(root: ET.Element) -> list[tuple[str, str]]:
    """An MJCF's couplings of joints that are not planned, as ("model", reason) naming
    each (:mod:`ocp.robots.couplings` plans the linear ones): a ``weld`` or ``connect``
    equality (a closed chain), a joint or tendon equality whose polynomial is not linear,
    a ``<spatial>`` tendon that is limited, held by an equality or driven, a fixed tendon
    over several joints driven by an actuator (a transmission, not a coupling)."""
    errs: list[tuple[str, str]] = []
    equalities = [el for eq in root.iter("equality") for el in eq]
    in_equality = {el.get(k) for el in equalities if el.tag == "tendon"
                   for k in ("tendon1", "tendon2")}
    driven = {el.get("tendon") for act in root.iter("actuator") for el in act}
    why = "it is not planned, so this hand is refused"
    for el in equalities:
        name = f" {el.get('name')!r}" if el.get("name") else ""
        if el.tag in ("weld", "connect"):
            errs.append(("model", f"<equality><{el.tag}{name}> closes a kinematic chain "
                                  f"({el.get('body1') or el.get('site1')!r}): {why}"))
        elif el.tag in ("joint", "tendon") and el.get("active", "true") != "false":
            poly = [float(v) for v in (el.get("polycoef") or "0 1 0 0 0").split()]
            if any(abs(v) > 0.0 for v in poly[2:]):
                errs.append(("model", f"<equality><{el.tag}{name}> couples "
                                      f"{el.get(el.tag + '1')!r} by a polynomial of degree "
                                      f"above 1 (polycoef {el.get('polycoef')}): only linear "
                                      f"couplings are planned, so this hand is refused"))
    for tendons in root.iter("tendon"):
        for t in tendons:
            tname = t.get("name")
            joints = [j.get("joint") for j in t if j.tag == "joint"]
            limited = t.get("limited") == "true" or (t.get("limited") != "false"
                                                      and t.get("range") is not None)
            if t.tag == "spatial" and (limited or tname in in_equality or tname in driven):
                how = "limited" if limited else "held by an <equality>" \
                    if tname in in_equality else "driven by an actuator"
                errs.append(("model", f"spatial tendon {tname!r} ({how}) routes over sites "
                                      f"and couples the joints it crosses: {why}"))
            elif t.tag == "fixed" and len(joints) > 1 and tname in driven:
                errs.append(("model", f"tendon {tname!r} over joints "
                                      f"{', '.join(repr(j) for j in joints)} is driven by an "
                                      "actuator: a transmission to several joints is not "
                                      "commanded, so this hand is refused"))
    return errs


def tendon_limits(text: str) -> dict[str, tuple[float, float]]:
    """The limits [rad or m] that limited fixed tendons over one joint put on that joint,
    as MuJoCo reads them (``range / coef``); {} without MuJoCo or when it cannot compile
    the text."""
    try:
        import mujoco
    except ImportError:
        return {}
    from ocp.robots.mjcf_frames import mujoco_text

    try:
        m = mujoco.MjModel.from_xml_string(mujoco_text(text))
    except Exception:  # MuJoCo's reason is the frame check's to report
        return {}
    out: dict[str, tuple[float, float]] = {}
    for t in range(m.ntendon):
        adr, num = int(m.tendon_adr[t]), int(m.tendon_num[t])
        if num != 1 or not m.tendon_limited[t] or \
                int(m.wrap_type[adr]) != int(mujoco.mjtWrap.mjWRAP_JOINT):
            continue
        coef = float(m.wrap_prm[adr])
        if coef == 0.0:
            continue
        name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, int(m.wrap_objid[adr]))
        a, b = sorted(float(x) / coef for x in m.tendon_range[t])
        lo, hi = out.get(name, (-np.inf, np.inf))
        out[name] = (max(lo, a), min(hi, b))
    return out


def _build(text: str, fmt: str) -> tuple[Any, str]:
    """Pinocchio's model of the text, an MJCF's frames made MuJoCo's, and the text its
    geometry is read from (an MJCF's orientations as quaternions:
    :func:`~ocp.robots.mjcf_frames.build_mjcf`)."""
    import pinocchio as pin

    if fmt == "urdf":
        return pin.buildModelFromXML(kinematic_urdf(text)), text
    return build_mjcf(text)


def frame_problems(text: str, fmt: str, model: Any) -> list[tuple[str, str]]:
    """Where the model built from ``text`` puts a body, site or link elsewhere than the
    file's own reader does, or reads other joint limits, as ("model", reason) pairs: for
    an MJCF MuJoCo's ``mj_kinematics`` of the same text (nothing when MuJoCo is not
    installed), for a URDF the URDF's own joint origins (:mod:`ocp.robots.urdf_frames`)."""
    if fmt == "mjcf":
        found = mujoco_disagreements(text, model)
        why = "dexroll's reading of the MJCF differs from MuJoCo's, so it is refused"
    else:
        found = urdf_disagreements(text, model)
        why = "Pinocchio's reading of the URDF differs from its joint origins, so it is refused"
    return [("model", r if r.startswith("MuJoCo cannot") else f"{r} ({why})")
            for r in found or []]


def effort_limits(finger: Any) -> FloatArray:
    """A finger's joints' effort limits [N m] as its model gives them (Pinocchio's
    ``effortLimit``: a URDF's ``effort``), in its joint order."""
    m = finger.model
    out = []
    for n in finger.joint_names:
        j = m.getJointId(n)
        out.append(float(m.effortLimit[m.joints[j].idx_v]) if j < m.njoints else np.inf)
    return np.asarray(out, dtype=float)


@dataclass(frozen=True, eq=False)
class WholeHand:
    """A hand from one model text: one finger per fingertip (in the order of ``tips``)."""

    name: str
    format: str
    text: str
    tips: tuple[TipSpec, ...]
    fingers: tuple[Any, ...]  # FingerModel
    mount: tuple[FloatArray, FloatArray]
    #: Joints shared by several fingers (a wrist), held at these values [rad or m]: not
    #: planned (:func:`shared_joints`).
    held: dict[str, float] = field(default_factory=dict)
    #: What :meth:`collision` and :meth:`actuation` built, by their arguments.
    _made: dict[tuple[Any, ...], Any] = field(default_factory=dict, repr=False)

    def actuation(self) -> Any:
        """The hand's actuators as its file says (:mod:`ocp.robots.actuation`): an MJCF's
        as MuJoCo reads them (None without MuJoCo), a URDF's joints as motors limited by
        their ``effort``."""
        from ocp.robots.actuation import HandActuation, UrdfActuation

        got = self._made.get(("actuation",))
        if got is None:
            if self.format == "mjcf":
                try:
                    import mujoco  # noqa: F401
                except ImportError:
                    return None
                got = HandActuation(self.text, self.mount, dict(self.held),
                                    couplings=tuple(c for f in self.fingers
                                                    for c in f.couplings))
            else:
                got = UrdfActuation({n: float(e) for f in self.fingers for n, e in zip(
                    f.joint_names, effort_limits(f), strict=True)})
            self._made[("actuation",)] = got
        return got

    def collision(self, fingers: Sequence[int]) -> Any:
        """The hand's collision geoms as MuJoCo collides them, with the tips of
        ``fingers`` (indices into :attr:`fingers`, a plan's order) as the fingertips a
        plan touches with (:class:`ocp.robots.collision.HandCollision`); None for a URDF
        (its links' collisions are not checked) or without MuJoCo."""
        if self.format != "mjcf":
            return None
        try:
            import mujoco  # noqa: F401
        except ImportError:
            return None
        from ocp.robots.collision import HandCollision

        key = tuple(int(i) for i in fingers)
        got = self._made.get(key)
        if got is None:
            got = self._made[key] = HandCollision(
                self.text, tuple(self.tips[i].name for i in key), self.mount,
                dict(self.held))
        return got

    @property
    def n_fingers(self) -> int:
        return len(self.fingers)

    @property
    def tip_names(self) -> tuple[str, ...]:
        return tuple(t.name for t in self.tips)


def load_whole_hand(text: str, fmt: str, tips: Sequence[TipSpec],
                    mount_rotation: ArrayLike | None = None,
                    mount_position: ArrayLike | None = None, name: str = "hand"
                    ) -> WholeHand:
    """The hand of a URDF (``fmt`` "urdf") or MJCF ("mjcf") text with fingers ending at
    ``tips``, its root mounted at (``mount_rotation``, ``mount_position``) in the palm
    frame (default: the palm frame itself): for an MJCF, MuJoCo's world frame. Raises
    :class:`HandModelError` naming ``model``, ``tips[i].name`` or ``tips[i].surface``;
    ``model`` also where the built model puts a body, site or link elsewhere than the
    file's own reader (:func:`frame_problems`)."""
    from ocp.robots.finger import finger_from_model

    if fmt not in ("urdf", "mjcf"):
        raise HandModelError([("format", f"must be 'urdf' or 'mjcf', got {fmt!r}")])
    errs = model_problems(text, fmt)
    if errs:
        raise HandModelError(errs)
    if not tips:
        raise HandModelError([("tips", "name at least one fingertip link")])
    try:
        model, read = _build(text, fmt)
    except MemoryError:
        raise
    except MjcfReadError as exc:
        raise HandModelError([("model", str(exc))]) from exc
    except Exception as exc:
        raise HandModelError([("model", f"Pinocchio cannot build the {fmt.upper()}: "
                                        f"{str(exc)[:300]}")]) from exc
    errs = frame_problems(text, fmt, model)  # reported with the tips' own
    if fmt == "mjcf":  # tendons over one joint: that joint's limits
        for joint, (lo, hi) in tendon_limits(text).items():
            if model.existJointName(joint):
                i = model.joints[int(model.getJointId(joint))].idx_q
                model.lowerPositionLimit[i] = max(float(model.lowerPositionLimit[i]), lo)
                model.upperPositionLimit[i] = min(float(model.upperPositionLimit[i]), hi)
    frames = sorted({str(f.name) for f in model.frames} - {"universe"})
    R = np.eye(3) if mount_rotation is None else np.asarray(mount_rotation, dtype=float)
    p = np.zeros(3) if mount_position is None else np.asarray(mount_position, dtype=float)
    held = shared_joints(model, [t.name for t in tips if model.existFrame(t.name)])
    fingers: list[Any] = []
    seen: dict[str, int] = {}
    for i, tip in enumerate(tips):
        where = f"tips[{i}]"
        if tip.name in seen:
            errs.append((f"{where}.name", f"{tip.name!r} is also tips[{seen[tip.name]}]"))
            continue
        seen[tip.name] = i
        if not model.existFrame(tip.name):
            shown = ", ".join(frames[:40]) + (" ..." if len(frames) > 40 else "")
            errs.append((f"{where}.name", f"{tip.name!r} is not a link, body or frame of "
                                          f"the model; it has: {shown}"))
            continue
        surface = tip.surface
        if surface is None:
            got = tip_geometry(read, fmt, tip.name, tip.side)
            if isinstance(got, str):
                errs.append((f"{where}.surface", got))
                continue
            surface = got
        bad = surface.errors(f"{where}.surface")
        if bad:
            errs += bad
            continue
        try:
            fingers.append(finger_from_model(model, text, tip.name, R, p, tip=surface,
                                             default_velocity=DEFAULT_VELOCITY,
                                             held=held))
        except ValueError as exc:
            errs.append((f"{where}.name", str(exc)))
    if not errs and fmt == "mjcf":
        fingers, errs = _coupled(text, fingers, held)
    if errs:
        raise HandModelError(errs)
    return WholeHand(name, fmt, text, tuple(tips), tuple(fingers), (R, p), held)


def _coupled(text: str, fingers: list[Any], held: dict[str, float]
             ) -> tuple[list[Any], list[tuple[str, str]]]:
    """The fingers with the MJCF's couplings of their joints
    (:func:`~ocp.robots.couplings.hand_couplings`), and the couplings refused."""
    from dataclasses import replace

    from ocp.robots.couplings import hand_couplings

    try:
        per, errs = hand_couplings(text, [f.joint_names for f in fingers], held)
    except ImportError:  # without MuJoCo its couplings cannot be read: refused if any
        return fingers, [("model", r) for r in _unread_couplings(text)]
    except Exception:  # MuJoCo's reason is the frame check's to report
        return fingers, []
    return ([replace(f, couplings=c) if c else f for f, c in zip(fingers, per, strict=True)],
            [("model", r) for r in errs])


def _unread_couplings(text: str) -> list[str]:
    """Without MuJoCo: the limited fixed tendons over several joints and the joint and
    tendon equalities of the text, each a coupling that cannot be read."""
    root = ET.fromstring(text)
    out = [f"tendon {t.get('name')!r} couples joints: reading couplings needs MuJoCo "
           "(pip install mujoco)" for tendons in root.iter("tendon") for t in tendons
           if t.tag == "fixed" and len([j for j in t if j.tag == "joint"]) > 1
           and (t.get("limited") == "true" or t.get("range") is not None)]
    out += [f"<equality><{el.tag}> {el.get('name') or ''} couples joints: reading "
            "couplings needs MuJoCo (pip install mujoco)" for eq in root.iter("equality")
            for el in eq if el.tag in ("joint", "tendon")]
    return out


def shared_joints(model: Any, tips: Sequence[str]) -> dict[str, float]:
    """The joints on the paths of two or more of ``tips`` whose paths differ (a wrist, an
    arm: they would move several fingers at once), each with the value it is held at: 0
    (the joint's reference in the file), or the nearer end of its range when 0 is outside
    it."""
    from ocp.robots.finger import tip_path

    paths = {tuple(tip_path(model, t)) for t in tips}  # two tips on one chain: one path
    count: dict[str, int] = {}
    for path in paths:
        for n in path:
            count[n] = count.get(n, 0) + 1
    out = {}
    for n, k in count.items():
        if k > 1:
            j = model.joints[int(model.getJointId(n))]
            lo = float(model.lowerPositionLimit[j.idx_q])
            hi = float(model.upperPositionLimit[j.idx_q])
            out[n] = min(max(0.0, lo), hi)
    return out
