"""The whole hand's links against the object and against each other, as MuJoCo collides
them (issue 37, item 4).

A hand file's collision geoms (boxes, capsules, spheres, cylinders, ellipsoids) are what
touches the object in MuJoCo, not only the fingertips a plan rolls on. This module
compiles the hand's MJCF with MuJoCo (mesh files absent: :func:`collision_text`) and the
object added as a free body, sets the joints and the object's pose of each sample of a
plan, and runs MuJoCo's own collision detection (``mj_collision``) with every geom's
``margin`` widened to :data:`WINDOW`, so that every pair MuJoCo would collide — its
``contype``/``conaffinity`` bits, ``<exclude>``, a body never colliding with its parent,
bodies welded together — is reported with its signed distance. The pairs a plan touches on
purpose (a fingertip's geoms and the object, while that fingertip's contact is active)
are left out; what remains must keep :data:`LINK_CLEARANCE`.

Mesh geoms are not checked: their files are never read (a collision mesh is left out,
as a visual one). The object is its shape's geom (:meth:`ocp.shapes.Shape.mujoco_geom`) whose
``contype`` and ``conaffinity`` are 1, as in the execution's scene (``sim.user_model``).
Frames: the hand's world frame sits at ``mount`` (R, p) in the palm frame, as for
:func:`ocp.robots.whole_hand.load_whole_hand`.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ocp.shapes import shape_of

__all__ = ["LINK_CLEARANCE", "WINDOW", "Clearance", "HandCollision", "collision_text"]

FloatArray = NDArray[np.float64]

#: The least distance [m] between two geoms MuJoCo would collide, where no contact is
#: planned: the issue's 0.5 mm.
LINK_CLEARANCE = 5e-4
#: Pairs nearer than this [m] are measured (MuJoCo's margin on every geom).
WINDOW = 5e-3
#: The object's body and geom in the collision model.
OBJECT = "dexroll_object"


@dataclass(frozen=True)
class Clearance:
    """The least distance [m] between two geoms not meant to touch (``WINDOW`` when no
    pair comes nearer), the pair (body/geom names) and the sample it was at (-1: none)."""

    value: float
    pair: tuple[str, str] = ("", "")
    sample: int = -1
    #: Every pair nearer than ``LINK_CLEARANCE``: (names, least distance [m]).
    near: tuple[tuple[tuple[str, str], float], ...] = ()
    #: The fingertips (indices) whose fingers carry the nearest pair's geoms.
    fingers: tuple[int, ...] = ()

    @property
    def passed(self) -> bool:
        return self.value >= LINK_CLEARANCE

    def describe(self) -> str:
        if self.sample < 0:
            return f"every pair of links at least {WINDOW * 1e3:g} mm apart"
        a, b = self.pair
        how = (f"{-self.value * 1e3:.3g} mm into" if self.value < 0 else
               f"{self.value * 1e3:.3g} mm from")
        return f"{a} {how} {b}"


def collision_text(text: str) -> str:
    """The MJCF ``text`` MuJoCo compiles without the files it names, for collision: mesh
    and height-field geoms (bodies' and default classes') made inert (no contacts: their
    files are never read): :func:`ocp.robots.mjcf_frames.mujoco_text`."""
    from ocp.robots.mjcf_frames import mujoco_text

    return mujoco_text(text, inert=True)


#: At most this many capsules cover one box (along its longest axis, side by side across
#: the longer side of its section).
BOX_CAPSULES = 3


def _box_capsules(c: FloatArray, R: FloatArray, size: FloatArray
                  ) -> list[tuple[FloatArray, float, float, FloatArray]]:
    """Capsules (centre, half-length, radius, axis) whose union bounds a box of half-sizes
    ``size`` at ``c`` with axes ``R``'s columns: along its longest axis, ``n`` of them side
    by side across the longer side of its section (each bounding its share of the
    section), ``n`` as few as keep each radius within 1.25 times the shorter side's half."""
    i = int(np.argmax(size))
    j, k = (x for x in range(3) if x != i)
    if size[j] > size[k]:
        j, k = k, j  # j the shorter side of the section, k the longer
    hj, hk = float(size[j]), float(size[k])
    n = 1
    while n < BOX_CAPSULES and math.hypot(hj, hk / n) > 1.25 * hj:
        n += 1
    r = math.hypot(hj, hk / n)
    out = []
    for m in range(n):
        offset = (-hk + hk / n * (2 * m + 1)) * R[:, k]
        out.append((c + offset, float(size[i]), r, R[:, i]))
    return out


def _collides(mj: Any, g1: int, g2: int) -> bool:
    """Whether MuJoCo would collide geoms ``g1`` and ``g2``: their contype/conaffinity
    bits, not one body, neither body the other's parent (unless it is the world), no
    ``<exclude>`` of their bodies."""
    if not ((mj.geom_contype[g1] & mj.geom_conaffinity[g2]) or
            (mj.geom_contype[g2] & mj.geom_conaffinity[g1])):
        return False
    b1, b2 = int(mj.geom_bodyid[g1]), int(mj.geom_bodyid[g2])
    if b1 == b2:
        return False
    w1, w2 = int(mj.body_weldid[b1]), int(mj.body_weldid[b2])
    if w1 == w2:
        return False
    p1, p2 = int(mj.body_weldid[mj.body_parentid[w1]]), int(mj.body_weldid[mj.body_parentid[w2]])
    if (p1 == w2 and w2 != 0) or (p2 == w1 and w1 != 0):
        return False
    signature = min(b1, b2) << 16 | max(b1, b2)
    return int(signature) not in {int(x) for x in mj.exclude_signature}


def _on_chain(mj: Any, body: int, tip: int) -> bool:
    """Whether ``body`` is ``tip`` or one of its ancestors below the root body."""
    b = tip
    while b > 0 and int(mj.body_parentid[b]) > 0:
        if b == body:
            return True
        b = int(mj.body_parentid[b])
    return False


def _name(mj: Any, obj: Any, i: int) -> str:
    import mujoco

    return mujoco.mj_id2name(mj, obj, i) or ""


@dataclass(eq=False)
class HandCollision:
    """The collision geoms of an MJCF hand (module docstring). ``tips``: per fingertip of a
    plan (in its order), the body or site its tip is; ``mount``: the hand's world frame in
    the palm frame (R, p)."""

    text: str
    tips: tuple[str, ...]
    mount: tuple[FloatArray, FloatArray] = field(
        default_factory=lambda: (np.eye(3), np.zeros(3)))
    #: Joints not planned, held at these values (a shared wrist); the rest at ``qpos0``.
    held: dict[str, float] = field(default_factory=dict)
    _models: dict[tuple[str, tuple[float, ...]], Any] = field(default_factory=dict,
                                                              repr=False)

    def _model(self, shape: str, dims: Sequence[float]) -> Any:
        import mujoco

        key = (shape, tuple(float(x) for x in dims))
        got = self._models.get(key)
        if got is not None:
            return got
        root = ET.fromstring(collision_text(self.text))
        world = root.find("worldbody")
        assert world is not None
        obj = ET.SubElement(world, "body", name=OBJECT)
        ET.SubElement(obj, "freejoint", name=OBJECT)
        geom = shape_of(shape).mujoco_geom(dims)
        geom.add_asset(root)  # a mesh's vertices, inline
        ET.SubElement(obj, "geom", geom.attributes(), name=OBJECT, contype="1",
                      conaffinity="1")
        mj = mujoco.MjModel.from_xml_string(ET.tostring(root, encoding="unicode"))
        mj.geom_margin[:] = WINDOW
        mj.geom_gap[:] = 0.0
        data = mujoco.MjData(mj)
        o_geom = mujoco.mj_name2id(mj, mujoco.mjtObj.mjOBJ_GEOM, OBJECT)
        o_joint = mujoco.mj_name2id(mj, mujoco.mjtObj.mjOBJ_JOINT, OBJECT)
        tip_geoms: list[set[int]] = []
        for tip in self.tips:
            b = mujoco.mj_name2id(mj, mujoco.mjtObj.mjOBJ_BODY, tip)
            if b < 0:
                s = mujoco.mj_name2id(mj, mujoco.mjtObj.mjOBJ_SITE, tip)
                if s < 0:
                    raise ValueError(f"the hand has no body or site {tip!r}")
                b = int(mj.site_bodyid[s])
            tip_geoms.append({g for g in range(mj.ngeom) if int(mj.geom_bodyid[g]) == b})
        # per geom, the fingertip whose chain carries it (-1: the palm, or shared)
        tip_bodies = [int(mj.geom_bodyid[next(iter(gs))]) if gs else -1 for gs in tip_geoms]
        finger_of = []
        for g in range(mj.ngeom):
            on = [k for k, tb in enumerate(tip_bodies) if _on_chain(mj, int(mj.geom_bodyid[g]),
                                                                     tb)]
            finger_of.append(on[0] if len(on) == 1 else -1)
        names = []
        for g in range(mj.ngeom):
            body = _name(mj, mujoco.mjtObj.mjOBJ_BODY, int(mj.geom_bodyid[g])) or "world"
            gn = _name(mj, mujoco.mjtObj.mjOBJ_GEOM, g)
            names.append("the object" if g == o_geom else
                         f"body {body!r}" + (f" (geom {gn!r})" if gn else f" (geom {g})"))
        got = (mj, data, o_geom, int(mj.jnt_qposadr[o_joint]), tip_geoms, names, finger_of)
        self._models[key] = got
        return got

    def joint_address(self, shape: str, dims: Sequence[float],
                      joint_names: Sequence[str]) -> list[int]:
        """The qpos addresses of ``joint_names`` (ValueError naming one the file lacks)."""
        import mujoco

        mj = self._model(shape, dims)[0]
        out = []
        for n in joint_names:
            j = mujoco.mj_name2id(mj, mujoco.mjtObj.mjOBJ_JOINT, n)
            if j < 0:
                raise ValueError(f"the hand has no joint {n!r}")
            out.append(int(mj.jnt_qposadr[j]))
        return out

    def obstacles(self, shape: str, dims: Sequence[float], joint_names: Sequence[str],
                  q: ArrayLike, finger: int, near: tuple[FloatArray, float] | None = None
                  ) -> list[tuple[str, tuple[FloatArray, FloatArray, float]]]:
        """The hand's collision geoms a swing of fingertip ``finger`` must keep clear of,
        at joints ``q`` (the values of ``joint_names``), as capsules in the palm frame
        (name, (a, b, r)): every geom MuJoCo would collide with that tip's, but its own
        finger's (they move with it), the other tips' (a swing keeps clear of them by
        their own bodies) and the object. A sphere
        is itself, a capsule or cylinder its axis and radius, a box up to
        :data:`BOX_CAPSULES` capsules along its longest axis that together bound it
        (:func:`_box_capsules`), an ellipsoid its longest axis with the larger of its
        other two half-sizes.
        ``near``: (a point [m], a distance [m]); only geoms within that distance of it."""
        import mujoco

        mj, d, o_geom, _, tip_geoms, names, _ = self._model(shape, dims)
        addr = self.joint_address(shape, dims, joint_names)
        held_at = self.joint_address(shape, dims, list(self.held))
        d.qpos[:] = mj.qpos0
        d.qpos[held_at] = np.array(list(self.held.values()), dtype=float)
        d.qpos[addr] = np.asarray(q, dtype=float)
        mujoco.mj_kinematics(mj, d)
        mine = tip_geoms[finger]
        tips = {g for gs in tip_geoms for g in gs}
        own = int(mj.geom_bodyid[next(iter(mine))]) if mine else -1  # its chain moves
        Rm, pm = (np.asarray(x, dtype=float) for x in self.mount)
        out = []
        for g in range(mj.ngeom):
            if g in tips or g == o_geom or _on_chain(mj, int(mj.geom_bodyid[g]), own) or \
                    not any(_collides(mj, g, t) for t in mine):
                continue
            kind, size = int(mj.geom_type[g]), np.asarray(mj.geom_size[g], dtype=float)
            R = d.geom_xmat[g].reshape(3, 3)
            c = d.geom_xpos[g]
            T = mujoco.mjtGeom
            parts: list[tuple[FloatArray, float, float, FloatArray]] = []  # centre, half, r, axis
            if kind == int(T.mjGEOM_SPHERE):
                parts.append((c, 0.0, float(size[0]), R[:, 2]))
            elif kind in (int(T.mjGEOM_CAPSULE), int(T.mjGEOM_CYLINDER)):
                parts.append((c, float(size[1]), float(size[0]), R[:, 2]))
            elif kind == int(T.mjGEOM_BOX):
                parts += _box_capsules(c, R, size)
            elif kind == int(T.mjGEOM_ELLIPSOID):
                i = int(np.argmax(size))
                r = float(np.delete(size, i).max())
                parts.append((c, max(float(size[i]) - r, 0.0), r, R[:, i]))
            for centre, half, r, axis in parts:
                a, b = Rm @ (centre - half * axis) + pm, Rm @ (centre + half * axis) + pm
                if near is not None:
                    from ocp.geometry.bodies import point_segment_distance

                    if float(point_segment_distance(near[0], a, b)) - r > near[1]:
                        continue
                out.append((names[g], (a, b, r)))
        return out

    def least(self, shape: str, dims: Sequence[float], joint_names: Sequence[str],
              q: ArrayLike, object_R: ArrayLike, object_p: ArrayLike,
              touching: NDArray[np.bool_] | None = None) -> Clearance:
        """The least clearance over samples: ``q`` (n, joints) the values of
        ``joint_names`` (the other joints at their ``qpos0``), the object's pose in the
        palm frame (``object_R`` (n, 3, 3), ``object_p`` (n, 3)), ``touching`` (n, tips)
        which fingertips' contacts are active (None: all)."""
        import mujoco

        mj, d, o_geom, o_q, tip_geoms, names, finger_of = self._model(shape, dims)
        addr = self.joint_address(shape, dims, joint_names)
        held_at = self.joint_address(shape, dims, list(self.held))
        held_q = np.array(list(self.held.values()), dtype=float)
        Q = np.atleast_2d(np.asarray(q, dtype=float))
        Ro = np.asarray(object_R, dtype=float).reshape(-1, 3, 3)
        po = np.asarray(object_p, dtype=float).reshape(-1, 3)
        n = Q.shape[0]
        on = np.ones((n, len(self.tips)), dtype=bool) if touching is None else \
            np.asarray(touching, dtype=bool).reshape(n, len(self.tips))
        Rm, pm = (np.asarray(x, dtype=float) for x in self.mount)
        quat = np.zeros(4)
        best = Clearance(WINDOW)
        near: dict[tuple[str, str], float] = {}
        for i in range(n):
            d.qpos[:] = mj.qpos0
            d.qpos[held_at] = held_q
            d.qpos[addr] = Q[i]
            # the object's pose in the hand's world frame: x_palm = Rm x_world + pm
            d.qpos[o_q:o_q + 3] = Rm.T @ (po[i] - pm)
            mujoco.mju_mat2Quat(quat, (Rm.T @ Ro[i]).ravel())
            d.qpos[o_q + 3:o_q + 7] = quat
            mujoco.mj_kinematics(mj, d)
            mujoco.mj_collision(mj, d)
            allowed = {g for k, gs in enumerate(tip_geoms) if on[i, k] for g in gs}
            for c in d.contact[:d.ncon]:
                g1, g2 = int(c.geom1), int(c.geom2)
                other = g2 if g1 == o_geom else g1 if g2 == o_geom else -1
                if other >= 0 and other in allowed:
                    continue
                dist = float(c.dist)
                pair = (names[g1], names[g2])
                if dist < LINK_CLEARANCE:
                    near[pair] = min(near.get(pair, np.inf), dist)
                if dist < best.value:
                    best = Clearance(dist, pair, i, fingers=tuple(
                        k for k in (finger_of[g1], finger_of[g2]) if k >= 0))
        return Clearance(best.value, best.pair, best.sample,
                         tuple(sorted(near.items(), key=lambda kv: kv[1])), best.fingers)

