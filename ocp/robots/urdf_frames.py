"""A URDF's link frames from its own joint origins, to check Pinocchio's reading against.

A URDF means what its ``<joint>`` elements say: the child link's frame is the parent's
times the joint's ``<origin xyz rpy>`` (roll, pitch, yaw about the parent's fixed x, y, z:
``R = Rz(yaw) Ry(pitch) Rx(roll)``) times the joint's motion about (revolute, continuous)
or along (prismatic) its unit ``<axis>`` (default x). :func:`urdf_link_poses` computes
that with numpy alone, and :func:`urdf_disagreements` compares it with Pinocchio's frames
(every link, at the nominal joint vector and a few random ones within the limits) and
Pinocchio's joint limits with the URDF's ``<limit>``.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["kinematic_urdf", "rpy_matrix", "urdf_disagreements", "urdf_link_poses"]

FloatArray = NDArray[np.float64]
Pose = tuple[FloatArray, FloatArray]


def rpy_matrix(rpy: FloatArray) -> FloatArray:
    """URDF's rotation of (roll, pitch, yaw) [rad]: ``Rz(yaw) Ry(pitch) Rx(roll)``."""
    r, p, y = (float(v) for v in rpy)
    cr, sr, cp, sp, cy, sy = (math.cos(r), math.sin(r), math.cos(p), math.sin(p),
                              math.cos(y), math.sin(y))
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


def kinematic_urdf(text: str) -> str:
    """The URDF without its links' ``<collision>`` and ``<visual>`` elements: what
    Pinocchio's kinematic model is built from (it reads no geometry; urdfdom prints an
    error for each geometry outside the URDF specification, such as the ``<capsule>``
    the fingertips' readers take, :mod:`ocp.robots.whole_hand`). Text that does not parse
    is returned as it is (Pinocchio names the fault)."""
    try:
        root = ET.fromstring(text)
    except ET.ParseError:
        return text
    for link in root.iter("link"):
        for child in [c for c in link if c.tag in ("collision", "visual")]:
            link.remove(child)
    return ET.tostring(root, encoding="unicode")


def _vec(el: ET.Element | None, attr: str, default: tuple[float, ...]) -> FloatArray:
    text = None if el is None else el.get(attr)
    if text is None:
        return np.asarray(default, dtype=float)
    return np.asarray([float(v) for v in text.split()], dtype=float)


def _axis_rotation(axis: FloatArray, angle: float) -> FloatArray:
    x, y, z = axis
    K = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    return np.eye(3) + math.sin(angle) * K + (1.0 - math.cos(angle)) * (K @ K)


def urdf_link_poses(root: ET.Element, q: dict[str, float]) -> dict[str, Pose]:
    """Every link's pose (R, p) in the root link's frame, the moving joints at ``q``
    (by name; a joint not in it at 0)."""
    joints = {}
    for j in root.findall("joint"):
        parent, child = j.find("parent"), j.find("child")
        if parent is not None and child is not None:
            joints[child.get("link", "")] = (parent.get("link", ""), j)
    poses: dict[str, Pose] = {}

    def pose(link: str, depth: int = 0) -> Pose:
        if link in poses:
            return poses[link]
        if link not in joints or depth > 256:
            poses[link] = (np.eye(3), np.zeros(3))
            return poses[link]
        parent, j = joints[link]
        Rp, pp = pose(parent, depth + 1)
        origin = j.find("origin")
        R = Rp @ rpy_matrix(_vec(origin, "rpy", (0, 0, 0)))
        p = pp + Rp @ _vec(origin, "xyz", (0, 0, 0))
        axis = _vec(j.find("axis"), "xyz", (1, 0, 0))
        axis = axis / np.linalg.norm(axis)
        qj = q.get(j.get("name", ""), 0.0)
        if j.get("type") in ("revolute", "continuous"):
            R = R @ _axis_rotation(axis, qj)
        elif j.get("type") == "prismatic":
            p = p + R @ (axis * qj)
        poses[link] = (R, p)
        return poses[link]

    for link in root.findall("link"):
        pose(link.get("name", ""))
    return poses


def urdf_disagreements(text: str, model: Any, samples: int = 3, seed: int = 0,
                       tolerance: float = 1e-6) -> list[str]:
    """Where Pinocchio's ``model`` of the URDF ``text`` differs from the URDF's own joint
    origins and limits, as reasons naming the link (distance [mm], angle [deg]) or the
    joint: at the nominal joint vector (zero, clipped into the limits) and ``samples``
    random ones within the limits (``seed``; unlimited joints within +-pi); [] when they
    agree to ``tolerance`` [m, rad]."""
    import pinocchio as pin

    root = ET.fromstring(text)
    out: list[str] = []
    moving = {j.get("name", ""): j for j in root.findall("joint")
              if j.get("type") in ("revolute", "continuous", "prismatic")}
    lo, hi, idx = {}, {}, {}
    for name, j in moving.items():
        if not model.existJointName(name):
            return [f"joint {name!r} of the URDF is not in Pinocchio's model"]
        jm = model.joints[model.getJointId(name)]
        idx[name] = jm.idx_q
        limit = j.find("limit")
        ulo = -math.inf if j.get("type") == "continuous" or limit is None else \
            float(limit.get("lower", "0"))
        uhi = math.inf if j.get("type") == "continuous" or limit is None else \
            float(limit.get("upper", "0"))
        plo, phi = float(model.lowerPositionLimit[jm.idx_q]), \
            float(model.upperPositionLimit[jm.idx_q])
        if j.get("type") != "continuous" and (abs(plo - ulo) > 1e-12 or abs(phi - uhi) > 1e-12):
            out.append(f"joint {name!r}: the URDF's limits are [{ulo:.6g}, {uhi:.6g}], "
                       f"Pinocchio's [{plo:.6g}, {phi:.6g}]")
        lo[name], hi[name] = max(ulo, -math.pi), min(uhi, math.pi)
    rng = np.random.default_rng(seed)
    vectors = [{n: float(np.clip(0.0, lo[n], hi[n])) for n in moving}]
    vectors += [{n: float(rng.uniform(lo[n], hi[n])) for n in moving} for _ in range(samples)]
    data = model.createData()
    worst: dict[str, tuple[float, float]] = {}
    for qd in vectors:
        qp = pin.neutral(model)
        if model.nq != len(moving):
            return [f"Pinocchio's model has {model.nq} coordinates, the URDF {len(moving)} "
                    "moving joints"]
        for n, v in qd.items():
            qp[idx[n]] = v
        pin.framesForwardKinematics(model, data, qp)
        for link, (R, p) in urdf_link_poses(root, qd).items():
            if not model.existFrame(link, pin.FrameType.BODY):
                continue
            M = data.oMf[model.getFrameId(link, pin.FrameType.BODY)]
            d = float(np.linalg.norm(M.translation - p))
            c = (float(np.trace(M.rotation.T @ R)) - 1.0) / 2.0
            a = math.acos(max(-1.0, min(1.0, c)))
            if d > tolerance or a > tolerance:
                old = worst.get(link, (0.0, 0.0))
                worst[link] = (max(old[0], d), max(old[1], a))
    for link, (d, a) in worst.items():
        out.append(f"link {link!r} is {d * 1e3:.3g} mm and {math.degrees(a):.3g} deg from "
                   f"where the URDF's joint origins put it (over {len(vectors)} joint vectors)")
    return out
