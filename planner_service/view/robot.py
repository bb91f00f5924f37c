"""A finger's links as shapes with a pose per sample, from its own model.

The shapes are the URDF's visual geometries as Pinocchio reads them
(``buildGeomFromUrdfString``; boxes, cylinders, spheres, capsules; elements that name
files, meshes and textures, are removed first: no path a request names is opened),
placed by Pinocchio's forward kinematics at the plan's joint angles. A joint whose link
has no such shape (no visual, or a mesh the viewer cannot draw) gets a cylinder from its
origin to the next joint's (or to the pad). The geometry on the pad's own link is left
out: the pad is the fingertip record (:mod:`.scene`), drawn with its contact trace.

For a finger of a hand (a branch of the hand's tree), only its own links move; the fixed
links it hangs from (the hand's palm, its base) are drawn once for the whole hand, and the
other branches' links, frozen in this finger's model, are left to their own fingers.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from typing import Any

import numpy as np
import pinocchio as pin

from ocp import FingerModel, quaternion_wxyz

from ..plans.shapes import shape_record, visual_geometry

__all__ = ["LinkBody", "finger_bodies"]

#: Radius of the cylinders drawn between joints of a link without a shape [m].
SEGMENT_RADIUS = 0.004


@dataclass(frozen=True)
class LinkBody:
    """One shape: a tagged record (``kind``: box with ``size``, cylinder or capsule along
    its z axis with ``radius`` and ``length``, sphere with ``radius``; m), its colour
    (RGBA 0..1), and its poses in the palm frame (rows: samples, or one row when fixed):
    positions [m] and quaternions (w, x, y, z)."""

    name: str
    shape: dict[str, Any]
    color: tuple[float, float, float, float]
    position: np.ndarray
    wxyz: np.ndarray
    static: bool


def _ancestor_links(urdf: str, first_joint: str) -> set[str]:
    """The URDF links the joint ``first_joint`` hangs from, up to the root."""
    try:
        root = ET.fromstring(urdf)
    except ET.ParseError:
        return set()
    parent_of: dict[str, str] = {}
    parent_of_joint: dict[str, str] = {}
    for j in root.iter("joint"):
        p, c = j.find("parent"), j.find("child")
        if p is not None and c is not None:
            parent_of[c.get("link", "")] = p.get("link", "")
            parent_of_joint[j.get("name", "")] = p.get("link", "")
    out: set[str] = set()
    link = parent_of_joint.get(first_joint)
    while link is not None and link not in out:
        out.add(link)
        link = parent_of.get(link)
    return out


def _segment_placement(d: np.ndarray) -> tuple[np.ndarray, np.ndarray, float] | None:
    """(rotation taking z along d, midpoint, length) of a segment from 0 to d."""
    length = float(np.linalg.norm(d))
    if length < 1e-6:
        return None
    z = d / length
    a = np.cross([0.0, 0.0, 1.0], z)
    s, c = float(np.linalg.norm(a)), float(z[2])
    if s < 1e-12:
        R = np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    else:
        R = np.asarray(pin.exp3(a / s * math.atan2(s, c)))
    return R, d / 2, length


def finger_bodies(finger: FingerModel, q: np.ndarray, prefix: str,
                  color: tuple[float, float, float, float] = (0.45, 0.55, 0.8, 1.0)
                  ) -> list[LinkBody]:
    """The finger's link shapes at the joint angles ``q`` (rows: samples), named
    ``prefix`` + the geometry's name; fixed shapes (on no joint) have one pose."""
    model = finger.model
    data = model.createData()
    geom = visual_geometry(finger)
    ancestors = _ancestor_links(finger.urdf_text, str(model.names[1])) if model.njoints > 1 \
        else set()
    # (name, joint, placement in the joint's frame, shape, colour)
    items: list[tuple[str, int, Any, dict[str, Any], tuple[float, ...]]] = []
    drawn_joints: set[int] = set()
    if geom is not None:
        for o in geom.geometryObjects:
            shape = shape_record(o.geometry)
            if shape is None or o.parentFrame == finger.tip_frame_id:
                continue
            joint = int(o.parentJoint)
            if joint == 0 and str(model.frames[o.parentFrame].name) not in ancestors:
                continue  # another branch's link, frozen in this finger's model
            items.append((str(o.name), joint, o.placement, shape,
                          tuple(float(c) for c in o.meshColor)))
            drawn_joints.add(joint)
    for i in range(1, model.njoints):
        if i in drawn_joints:
            continue
        nxt = model.jointPlacements[i + 1].translation if i + 1 < model.njoints else \
            model.frames[finger.tip_frame_id].placement.translation
        seg = _segment_placement(np.asarray(nxt, dtype=float))
        if seg is not None:
            R, mid, length = seg
            items.append((f"{model.names[i]}_segment", i, pin.SE3(R, mid),
                          {"kind": "cylinder", "radius": SEGMENT_RADIUS, "length": length},
                          color))
    q = np.asarray(q, dtype=float).reshape(-1, model.nq)
    Rb, pb = finger.base_rotation, finger.base_position
    poses: list[list[tuple[np.ndarray, np.ndarray]]] = [[] for _ in items]
    for k, qk in enumerate(q):
        pin.forwardKinematics(model, data, qk)
        for i, (_, joint, placement, _, _) in enumerate(items):
            if joint == 0 and k > 0:
                continue
            M = data.oMi[joint] * placement
            poses[i].append((Rb @ np.asarray(M.rotation), Rb @ np.asarray(M.translation) + pb))
    bodies = []
    for (name, joint, _, shape, rgba), pose in zip(items, poses, strict=True):
        rgba4 = (tuple(rgba) + (1.0,) * 4)[:4]
        bodies.append(LinkBody(
            prefix + name, shape, (rgba4[0], rgba4[1], rgba4[2], rgba4[3]),
            np.array([p for _, p in pose]), quaternion_wxyz(np.array([R for R, _ in pose])),
            joint == 0))
    return bodies
