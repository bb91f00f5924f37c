"""An MJCF's frames as MuJoCo reads them: what Pinocchio 4.1 misreads, corrected or refused,
and MuJoCo's own kinematics of the same text as the check when a hand is loaded.

A model file means what MuJoCo says it means. Pinocchio 4.1's ``buildModelFromMJCF``
disagrees with MuJoCo 3 on these (each measured against ``mj_kinematics``, see
``docs/hands.md``), and :func:`build_mjcf` makes its reading MuJoCo's:

- the pose of a fixed-base model's first body under ``<worldbody>`` is dropped (Pinocchio
  issue #2782, fixed upstream after 4.1 by pull request #2934): :func:`fix_model` puts
  the root body's pose back on every joint and frame hanging from the universe, as the
  correction ``C = T_root * inv(T_read)`` (identity for a Pinocchio that reads it);
- ``euler`` with an extrinsic (upper-case) ``eulerseq``, and ``axisangle`` with an axis
  that is not a unit vector, are misread: :func:`normalise_mjcf` writes every orientation
  (``euler``, ``axisangle``, ``xyaxes``, ``zaxis``, ``quat``) as a unit ``quat`` by
  MuJoCo's rules (angles in the compiler's unit: degrees unless ``angle="radian"``),
  in the bodies and in the default classes, before Pinocchio reads the text;
- a site on a body without a joint below another such body is placed with the body's
  pose relative to its parent body instead of its joint (the second bug #2934 fixes):
  :func:`fix_model` places every site on its body's frame;
- only the first body under ``<worldbody>`` is read, and ``<frame>`` elements are not:
  refused (:func:`mjcf_structure_problems`).

:func:`mujoco_disagreements` then compares the result with MuJoCo's ``mj_kinematics`` of
the same text (meshes, textures and height fields stripped: :func:`mujoco_text`): every
body's and site's pose at the joints' nominal vector and a few random ones within the
limits, and every joint's limits. Where MuJoCo is not installed (it is in the ``sim`` and
``dev`` extras) the check is skipped and the corrections above are all there is.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["FRAME_TOLERANCE", "MjcfReadError", "build_mjcf", "fix_model",
           "mjcf_structure_problems", "mujoco_disagreements", "mujoco_text", "normalise_mjcf",
           "orientation_quat", "quat_matrix", "site_pose"]

FloatArray = NDArray[np.float64]

#: How far dexroll's body and site poses may be from MuJoCo's: [m] and [rad].
FRAME_TOLERANCE = 1e-6

#: The elements whose orientation Pinocchio reads or a hand's tips use.
_ORIENTED = ("body", "geom", "site", "inertial", "camera", "light")
_ALTERNATIVES = ("axisangle", "euler", "xyaxes", "zaxis")


class MjcfReadError(ValueError):
    """An MJCF that dexroll cannot read as MuJoCo does: the reasons, joined."""


def _nums(text: str, n: int, what: str) -> FloatArray:
    vals = np.array([float(v) for v in text.split()], dtype=float)
    if vals.shape != (n,) or not np.all(np.isfinite(vals)):
        raise ValueError(f"{what}: expected {n} finite numbers, got {text!r}")
    return vals


def _qmul(a: FloatArray, b: FloatArray) -> FloatArray:
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return np.array([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
                     w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                     w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
                     w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2])


def _axis_quat(axis: FloatArray, angle: float) -> FloatArray:
    n = float(np.linalg.norm(axis))
    if n < 1e-12:
        raise ValueError("a rotation axis of zero length")
    return np.concatenate([[math.cos(angle / 2)], math.sin(angle / 2) * axis / n])


def _matrix_quat(R: FloatArray) -> FloatArray:
    import pinocchio as pin

    q = pin.Quaternion(np.asarray(R, dtype=float))  # x, y, z, w
    return np.array([q.w, q.x, q.y, q.z])


def quat_matrix(q: FloatArray) -> FloatArray:
    """The rotation matrix of the quaternion ``q`` = (w, x, y, z), normalised."""
    w, x, y, z = np.asarray(q, dtype=float) / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def orientation_quat(attrs: dict[str, str], degrees: bool, eulerseq: str
                     ) -> FloatArray | None:
    """The unit quaternion (w, x, y, z) an MJCF element's orientation attributes mean to
    MuJoCo (``quat``, ``axisangle``, ``euler`` in the sequence ``eulerseq``: lower case a
    rotation about the moving axis, upper case about the fixed one; ``xyaxes``,
    ``zaxis``), angles in degrees when ``degrees``; None when it has none. ValueError
    for two of them on one element, or malformed numbers."""
    given = [k for k in ("quat", *_ALTERNATIVES) if k in attrs]
    if not given:
        return None
    if len(given) > 1:
        raise ValueError(f"orientation given twice ({', '.join(given)})")
    kind = given[0]
    unit = math.pi / 180 if degrees else 1.0
    if kind == "quat":
        q = _nums(attrs["quat"], 4, "quat")
        if np.linalg.norm(q) < 1e-12:
            raise ValueError("quat of zero length")
        return q / np.linalg.norm(q)
    if kind == "axisangle":
        v = _nums(attrs["axisangle"], 4, "axisangle")
        return _axis_quat(v[:3], float(v[3]) * unit)
    if kind == "euler":
        angles = _nums(attrs["euler"], 3, "euler") * unit
        q = np.array([1.0, 0.0, 0.0, 0.0])
        for letter, a in zip(eulerseq, angles, strict=True):
            r = _axis_quat(np.eye(3)["xyz".index(letter.lower())], float(a))
            q = _qmul(q, r) if letter.islower() else _qmul(r, q)
        return q / np.linalg.norm(q)
    if kind == "xyaxes":
        v = _nums(attrs["xyaxes"], 6, "xyaxes")
        x = v[:3] / np.linalg.norm(v[:3])
        y = v[3:] - np.dot(x, v[3:]) * x
        y /= np.linalg.norm(y)
        return _matrix_quat(np.column_stack([x, y, np.cross(x, y)]))
    z = _nums(attrs["zaxis"], 3, "zaxis")
    z /= np.linalg.norm(z)
    axis = np.cross([0.0, 0.0, 1.0], z)
    s = float(np.linalg.norm(axis))
    axis = np.array([1.0, 0.0, 0.0]) if s < 1e-10 else axis / s
    return _axis_quat(axis, math.atan2(s, float(z[2])))


def _compiler(root: ET.Element) -> tuple[bool, str]:
    """(angles in degrees, eulerseq) of the MJCF's ``<compiler>`` (MuJoCo's defaults:
    degrees, "xyz")."""
    degrees, seq = True, "xyz"
    for c in root.iter("compiler"):
        degrees = c.get("angle", "degree" if degrees else "radian") != "radian"
        seq = c.get("eulerseq", seq)
    if len(seq) != 3 or any(ch not in "xyzXYZ" for ch in seq):
        raise ValueError(f"<compiler eulerseq={seq!r}>: three of x, y, z, X, Y, Z")
    return degrees, seq


def mjcf_structure_problems(root: ET.Element) -> list[str]:
    """What in an MJCF's tree Pinocchio 4.1 does not read and dexroll does not correct:
    more than one body under ``<worldbody>`` (only the first is read), ``<frame>``
    elements (the bodies in them are lost); [] when none."""
    out = []
    for wb in root.iter("worldbody"):
        bodies = wb.findall("body")
        if len(bodies) > 1:
            names = [b.get("name", "?") for b in bodies]
            out.append(f"<worldbody> holds {len(bodies)} bodies ({', '.join(names)}); "
                       "Pinocchio reads only the first: put the hand under one root body")
    for _ in root.iter("frame"):
        out.append("<frame> elements are not read by Pinocchio 4.1 (the bodies in them are "
                   "lost): write their poses on the bodies, sites and geoms they hold")
        break
    return out


def normalise_mjcf(text: str) -> tuple[str, ET.Element]:
    """The MJCF ``text`` with every orientation written as a unit ``quat`` by MuJoCo's
    rules (:func:`orientation_quat`; bodies, geoms, sites, inertials, cameras, lights,
    in the worldbody and in default classes), and its tree so rewritten. The same
    model to MuJoCo; Pinocchio 4.1 then reads eulerseq and axisangle right. ValueError
    naming the element for an orientation MuJoCo would not accept either."""
    root = ET.fromstring(text)
    degrees, seq = _compiler(root)
    for el in root.iter():
        if el.tag not in _ORIENTED:
            continue
        try:
            q = orientation_quat(dict(el.attrib), degrees, seq)
        except ValueError as exc:
            raise ValueError(f"<{el.tag} name={el.get('name')!r}>: {exc}") from exc
        if q is None:
            continue
        for k in _ALTERNATIVES:
            el.attrib.pop(k, None)
        el.set("quat", " ".join(repr(float(v)) for v in q))
    return ET.tostring(root, encoding="unicode"), root


def _pose(el: ET.Element) -> Any:
    """The pose of a normalised element (pos, quat) in its parent's frame, a pin.SE3."""
    import pinocchio as pin

    p = _nums(el.get("pos", "0 0 0"), 3, "pos")
    q = _nums(el.get("quat", "1 0 0 0"), 4, "quat")
    return pin.SE3(quat_matrix(q), p)


def _site_defaults(root: ET.Element) -> dict[str, dict[str, str]]:
    """The ``pos`` and ``quat`` of ``<site>`` in every default class, inheritance
    resolved (a normalised tree)."""
    out: dict[str, dict[str, str]] = {}

    def walk(el: ET.Element, inherited: dict[str, str]) -> None:
        own = dict(inherited)
        for child in el.findall("site"):
            own.update({k: v for k, v in child.attrib.items() if k in ("pos", "quat")})
        out[el.get("class", "main")] = own
        for child in el.findall("default"):
            walk(child, own)

    for d in root.findall("default"):
        walk(d, {})
    return out


def _site_attrs(site: ET.Element, parents: dict[ET.Element, ET.Element],
                defaults: dict[str, dict[str, str]]) -> dict[str, str]:
    cls = site.get("class")
    el: ET.Element | None = parents.get(site)
    while cls is None and el is not None:
        cls = el.get("childclass")
        el = parents.get(el)
    return {**defaults.get("main", {}), **defaults.get(cls or "main", {}), **site.attrib}


def site_pose(root: ET.Element, site: ET.Element) -> tuple[FloatArray, FloatArray]:
    """(R, p): the pose of ``site`` (of the normalised tree ``root``) in its body's frame,
    its class's ``pos``/``quat`` resolved."""
    parents = {c: p for p in root.iter() for c in p}
    attrs = _site_attrs(site, parents, _site_defaults(root))
    return (quat_matrix(_nums(attrs.get("quat", "1 0 0 0"), 4, "quat")),
            _nums(attrs.get("pos", "0 0 0"), 3, "pos"))


def fix_model(model: Any, root: ET.Element) -> Any:
    """Pinocchio's model of the normalised MJCF tree ``root`` with MuJoCo's frames, in
    place: the fixed-base root body's pose on every joint and frame hanging from the
    universe (the correction ``C = T_root * inv(T_read)``, ``T_read`` where Pinocchio put
    the root body: the identity in 4.1, ``C`` the identity once Pinocchio reads it), and
    every site's frame at its body's frame times its own pose (its class's
    ``pos``/``quat`` resolved). Returns the model."""
    import pinocchio as pin

    bodies = [b for wb in root.iter("worldbody") for b in wb.findall("body")]
    if bodies:
        name = bodies[0].get("name")
        if name is not None and model.existFrame(name, pin.FrameType.BODY):
            fid = model.getFrameId(name, pin.FrameType.BODY)
            frame = model.frames[fid]
            if frame.parentJoint == 0:
                C = _pose(bodies[0]) * frame.placement.inverse()
                if not C.isIdentity(1e-15):
                    for j in range(1, model.njoints):
                        if model.parents[j] == 0:
                            model.jointPlacements[j] = C * model.jointPlacements[j]
                    for i in range(1, len(model.frames)):
                        f = model.frames[i]
                        if f.parentJoint == 0:
                            f.placement = C * f.placement
                            model.frames[i] = f
    parents = {c: p for p in root.iter() for c in p}
    defaults = _site_defaults(root)
    for site in root.iter("site"):
        name, body = site.get("name"), parents.get(site)
        if (name is None or body is None or body.tag != "body"
                or not model.existFrame(name, pin.FrameType.OP_FRAME)
                or not model.existFrame(body.get("name", ""), pin.FrameType.BODY)):
            continue
        sf = model.getFrameId(name, pin.FrameType.OP_FRAME)
        bf = model.frames[model.getFrameId(body.get("name", ""), pin.FrameType.BODY)]
        f = model.frames[sf]
        if f.parentJoint != bf.parentJoint:
            continue  # not a frame of that body's joint: left to the check at load
        attrs = _site_attrs(site, parents, defaults)
        local = ET.Element("site", {k: attrs[k] for k in ("pos", "quat") if k in attrs})
        f.placement = bf.placement * _pose(local)
        model.frames[sf] = f
    return model


def build_mjcf(text: str) -> tuple[Any, str]:
    """Pinocchio's model of the MJCF ``text`` with MuJoCo's frames (normalised by
    :func:`normalise_mjcf`, corrected by :func:`fix_model`), and the normalised text.
    :class:`MjcfReadError` for what it cannot read the way MuJoCo does."""
    import tempfile
    from pathlib import Path

    import pinocchio as pin

    try:
        normalised, root = normalise_mjcf(text)
    except ValueError as exc:
        raise MjcfReadError(str(exc)) from exc
    problems = mjcf_structure_problems(root)
    if problems:
        raise MjcfReadError("; ".join(problems))
    with tempfile.TemporaryDirectory(prefix="dexroll-mjcf-") as tmp:
        path = Path(tmp) / "hand.xml"
        path.write_text(normalised, encoding="utf-8")
        model = pin.buildModelFromMJCF(str(path))
    return fix_model(model, root), normalised


# -- MuJoCo's reading ----------------------------------------------------------------------

def mujoco_text(text: str, inert: bool = False) -> str:
    """The MJCF ``text`` MuJoCo can compile without the files it names
    (:func:`strip_files`; ``inert``: its mesh geoms without mass or contacts)."""
    root = ET.fromstring(text)
    strip_files(root, inert)
    return ET.tostring(root, encoding="unicode")


def strip_files(root: ET.Element, inert: bool = False) -> None:
    """What names files an MJCF tree (``root``, changed in place) cannot have here:
    ``<mesh>``, ``<hfield>``, ``<skin>`` and file textures removed (and every material's
    texture), every mesh or height-field geom (in the bodies and the default classes) a
    small sphere (``inert``: also without mass or contacts), every body given a least mass
    and inertia (``boundmass``, ``boundinertia``: a body with a joint and no geom
    compiles), the compiler's directories dropped. Frames, joints and limits unchanged."""
    for asset in root.iter("asset"):
        for el in list(asset):
            if el.tag in ("mesh", "hfield", "skin") or (el.tag == "texture" and
                                                        "file" in el.attrib):
                asset.remove(el)
    for parent in list(root.iter()):
        for el in list(parent):
            if el.tag == "skin":
                parent.remove(el)
    for mat in root.iter("material"):
        if mat.get("texture") is not None:
            mat.attrib.pop("texture")
    for geom in root.iter("geom"):
        meshy = geom.get("type") in ("mesh", "hfield") or "mesh" in geom.attrib \
            or "hfield" in geom.attrib
        for k in ("mesh", "hfield"):
            geom.attrib.pop(k, None)
        if meshy:
            geom.set("type", "sphere")
            geom.set("size", "0.005")
            geom.attrib.pop("fromto", None)
            if inert:
                geom.set("mass", "0")
                geom.set("contype", "0")
                geom.set("conaffinity", "0")
    compiler = root.find("compiler")
    if compiler is None:
        compiler = ET.Element("compiler")
        root.insert(0, compiler)
    compiler.set("boundmass", "1e-6")
    compiler.set("boundinertia", "1e-12")
    for k in ("meshdir", "texturedir", "assetdir"):
        compiler.attrib.pop(k, None)


def _angle(Ra: FloatArray, Rb: FloatArray) -> float:
    c = (float(np.trace(Ra.T @ Rb)) - 1.0) / 2.0
    return math.acos(max(-1.0, min(1.0, c)))


def mujoco_disagreements(text: str, model: Any, samples: int = 3, seed: int = 0
                         ) -> list[str] | None:
    """Where dexroll's reading ``model`` of the MJCF ``text`` differs from MuJoCo's, as
    reasons naming the body, site or joint and the distance [mm] or angle [deg]: joints
    (their number, names and limits) and, at the nominal joint vector (zero, clipped into
    the limits) and ``samples`` random ones within them (``seed``; unlimited joints within
    +-pi), every body's and site's pose beyond :data:`FRAME_TOLERANCE`. [] when they
    agree; None when MuJoCo is not installed."""
    try:
        import mujoco
    except ImportError:
        return None
    import pinocchio as pin

    try:
        mj = mujoco.MjModel.from_xml_string(mujoco_text(text))
    except Exception as exc:  # MuJoCo's own reason, the model as it reads it
        return [f"MuJoCo cannot compile the MJCF (meshes stripped): {str(exc)[:300]}"]
    obj = mujoco.mjtObj
    out: list[str] = []
    jnames = [mujoco.mj_id2name(mj, obj.mjOBJ_JOINT, j) for j in range(mj.njnt)]
    pnames = [str(model.names[j]) for j in range(1, model.njoints)]
    if len(jnames) != len(pnames) or any(a is not None and a != b
                                         for a, b in zip(jnames, pnames, strict=False)):
        return [f"MuJoCo reads the joints {jnames}, dexroll {pnames}"]
    lo, hi = np.empty(mj.njnt), np.empty(mj.njnt)
    for j in range(mj.njnt):
        pj = model.joints[j + 1]
        plo, phi = float(model.lowerPositionLimit[pj.idx_q]), \
            float(model.upperPositionLimit[pj.idx_q])
        mlo, mhi = (mj.jnt_range[j] if mj.jnt_limited[j] else (-np.inf, np.inf))
        if not (np.isclose(plo, mlo, rtol=0, atol=1e-9) or plo == mlo == -np.inf) or \
                not (np.isclose(phi, mhi, rtol=0, atol=1e-9) or phi == mhi == np.inf):
            out.append(f"joint {pnames[j]!r}: MuJoCo's limits are [{mlo:.6g}, {mhi:.6g}], "
                       f"dexroll's [{plo:.6g}, {phi:.6g}]")
        lo[j], hi[j] = max(mlo, -math.pi), min(mhi, math.pi)
    rng = np.random.default_rng(seed)
    vectors = [np.clip(np.zeros(mj.njnt), lo, hi)] + [rng.uniform(lo, hi)
                                                      for _ in range(samples)]
    frames = [(mujoco.mj_id2name(mj, obj.mjOBJ_BODY, b), "body", b) for b in range(1, mj.nbody)]
    frames += [(mujoco.mj_id2name(mj, obj.mjOBJ_SITE, s), "site", s) for s in range(mj.nsite)]
    kinds = {"body": pin.FrameType.BODY, "site": pin.FrameType.OP_FRAME}
    worst: dict[str, tuple[float, float]] = {}
    data, pdata = mujoco.MjData(mj), model.createData()
    for qv in vectors:
        qp = pin.neutral(model)
        for j in range(mj.njnt):
            data.qpos[mj.jnt_qposadr[j]] = qv[j]
            qp[model.joints[j + 1].idx_q] = qv[j]
        mujoco.mj_kinematics(mj, data)
        pin.framesForwardKinematics(model, pdata, qp)
        for name, kind, k in frames:
            if name is None or not model.existFrame(name, kinds[kind]):
                if name is not None and kind == "body":
                    worst[f"body {name!r}"] = (math.inf, math.inf)
                continue
            M = pdata.oMf[model.getFrameId(name, kinds[kind])]
            p = data.xpos[k] if kind == "body" else data.site_xpos[k]
            R = (data.xmat[k] if kind == "body" else data.site_xmat[k]).reshape(3, 3)
            d, a = float(np.linalg.norm(M.translation - p)), _angle(M.rotation, R)
            if d > FRAME_TOLERANCE or a > FRAME_TOLERANCE:
                old = worst.get(f"{kind} {name!r}", (0.0, 0.0))
                worst[f"{kind} {name!r}"] = (max(old[0], d), max(old[1], a))
    for what, (d, a) in worst.items():
        if d == math.inf:
            out.append(f"{what} of MuJoCo's model is not in dexroll's reading")
            continue
        out.append(f"{what} is {d * 1e3:.3g} mm and {math.degrees(a):.3g} deg from where "
                   f"MuJoCo puts it (over {len(vectors)} joint vectors)")
    return out
