"""Built-in multi-finger hands: K3S-like fingers around a palm, holding a ball in the air.

The paper's HKUST hand had three 6R K3S fingers on reconfigurable bases around a palm. The
built-in hands here are URDF trees (package data of ``ocp.robots.models``) whose root link
``palm`` is the palm frame P (origin on the palm's upper surface, z up) and whose fingers
are copies of the built-in finger (``k3s_finger.urdf``: the same links, joints, dimensions
and limits, every name prefixed ``f1_``, ``f2_``, ...), each hung from the palm by a fixed
joint ``fN_mount``. Each finger is a :class:`~ocp.robots.finger.FingerModel` loaded from the
hand's URDF with :func:`~ocp.robots.finger.load_finger` (the branch of the tree carrying its tip
frame ``fN_fingertip``; base identity, since the URDF root is the palm frame), so its
``fk``, Jacobian and :func:`~ocp.robots.finger.inverse_kinematics` work as for a single finger.

=================  ==========================================================================
``two_finger``     fingers f1, f2 on opposite sides: pads pressing on the ball at +x and -x,
                   an antipodal grasp; 100 mm x 100 mm pads
                   (:data:`~ocp.robots.finger.PAD_HALF_SIZE`)
``three_finger``   fingers f1, f2, f3 at azimuths 0, 120, 240 deg about the palm's z axis,
                   pads on the ball's equator; 60 mm x 60 mm pads
                   (:data:`THREE_FINGER_PAD_HALF_SIZE`)
=================  ==========================================================================

Geometry (palm frame, m). The nominal object is a ball of radius :data:`NOMINAL_RADIUS`
(25 mm, experiment 1's) with its centre at :data:`NOMINAL_OBJECT_POSITION` = (0, 0, 0.08):
80 mm above the palm, nothing under it. Finger k's contact is at azimuth ``phi_k``
(:attr:`Hand.contact_azimuths`): the pad centre at ``c + rho u_k``, ``u_k = (cos phi_k,
sin phi_k, 0)``, the pad frame's z axis (its outward normal) ``-u_k`` through the ball's
centre and its x axis up (+z of the palm), see :func:`grasp_poses`. Each finger base stands
beside the palm, :data:`MOUNT_RADIUS` = 95 mm from the palm's z axis at azimuth ``phi_k``
and :data:`MOUNT_HEIGHT` = 25 mm below the palm's surface, yawed by ``phi_k + 180 deg`` so
that the finger reaches towards the ball at zero waist angle (:func:`default_mounts`).
Only the ball centre's height above the finger bases (105 mm) and its distance from them
(95 mm) matter for reach; the bases stand 25 mm below the palm (as the built-in finger
stands 10 mm below it) to put the ball 80 mm above the palm. The three-finger hand's pads
are smaller: three 100 mm pads tangent to a 25 mm ball 120 deg apart would cut into each
other (adjacent pad planes meet 43.3 mm from each contact), while a 30 mm half side still
covers the 13 mm the contact travels across the pad when the ball rolls 30 deg on it.

Nominal grasp (:attr:`Hand.nominal_q`, IK from :data:`NOMINAL_SEED`): every finger has the
same joint angles, (0, -47.1, 7.5, 0, -50.4, 0) deg (waist, shoulder, elbow, wrist roll,
wrist pitch, tip roll): the upper arm leans back away from the ball, the forearm is about
level, the wrist pitches the pad to face the ball. Margin to the joint limits: 42.9 deg
(the shoulder; elbow 82.5, wrist pitch 69.6, waist 90, rolls 170).

Reach (:func:`reach_sweep`, IK tracked from the nominal grasp in 3 steps to each target):
each pad rotated with the ball by 30 deg about 26 axes through the ball's centre (the
directions of a cube's faces, edges and corners) or not rotated, times the ball centre
translated by 0, +-10 mm along each palm axis or to the 8 corners (+-10, +-10, +-10) mm: 405
poses per finger. Every finger of both hands reaches all 405 poses within its limits. Finger
f1 of either hand (and f2 of the two-finger hand: turned by 180 deg, which maps the sweep
onto itself) reaches 393 of them with >= 20 deg of margin to every joint limit and all with
>= 12.5 deg; fingers f2, f3 of the three-finger hand, which see the sweep's palm-aligned
axes and corners turned by +-120 deg, reach 392 with >= 20 deg and 402 with >= 10 deg. The
least margins per joint over the sweep (waist, shoulder, elbow, wrist roll, wrist pitch, tip
roll) are (44.9, 14.7, 40.5, 12.5, 15.6, 15.8) deg for f1 and (46.7, 7.0, 39.0, 7.5, 14.8,
1.4) deg for f2, f3 of the three-finger hand: the small roll margins are poses where the
tracked IK rolled the wrist over (another solution of the same pose may keep more). A hand's
sweep takes about 1 s per finger. The mounts were chosen with this sweep (finger f1) over a
grid of the bases' distance from the ball's axis x their depth below its centre (10 mm, then
5 mm steps): nearer or lower bases lose the poses with the pad above the ball (the wrist out
of the arm's reach); of the grid points reaching all 405 poses, 95 mm x 105 mm had the
largest least margin.

``load_hand(name, mounts=...)`` reconfigures the finger bases by rewriting the
``fN_mount`` joints' origins in the URDF before loading (the fingers then equal the
built-in finger mounted at ``mounts[k]``); the nominal ball stays where it is, and
:attr:`Hand.nominal_q` is None when the new mounts do not reach its grasp.
"""

from __future__ import annotations

import itertools
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass
from importlib import resources

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike, NDArray

from ocp.robots.finger import (
    PAD_HALF_SIZE,
    FingerModel,
    IKResult,
    _rotation,
    _vector3,
    inverse_kinematics,
    load_finger,
)

from . import models as _models

__all__ = [
    "HAND_NAMES",
    "MOUNT_HEIGHT",
    "MOUNT_RADIUS",
    "NOMINAL_OBJECT_POSITION",
    "NOMINAL_RADIUS",
    "NOMINAL_SEED",
    "NOMINAL_SEED_DEG",
    "THREE_FINGER_PAD_HALF_SIZE",
    "Hand",
    "ReachSweep",
    "builtin_hand_urdf_text",
    "default_mounts",
    "grasp_ik",
    "grasp_poses",
    "load_hand",
    "reach_sweep",
    "sweep_cases",
]

FloatArray = NDArray[np.float64]
Mount = tuple[FloatArray, FloatArray]

#: The built-in hands' names.
HAND_NAMES: tuple[str, ...] = ("two_finger", "three_finger")

#: Radius of the nominal ball [m] (experiment 1's).
NOMINAL_RADIUS = 0.025
#: Centre of the nominal ball in the palm frame [m]: 80 mm above the palm, in the air.
NOMINAL_OBJECT_POSITION: tuple[float, float, float] = (0.0, 0.0, 0.08)
#: Distance of each finger base from the palm's z axis [m] ...
MOUNT_RADIUS = 0.095
#: ... and its height relative to the palm's surface [m] (below it, beside the palm).
MOUNT_HEIGHT = -0.025
#: Half the side of the three-finger hand's square pads [m].
THREE_FINGER_PAD_HALF_SIZE = 0.03

#: Seed of the nominal grasp's IK [deg] and [rad] (every finger).
NOMINAL_SEED_DEG: tuple[float, ...] = (0.0, -45.0, 5.0, 0.0, -50.0, 0.0)
NOMINAL_SEED: FloatArray = np.deg2rad(np.array(NOMINAL_SEED_DEG))
NOMINAL_SEED.setflags(write=False)

#: name -> (URDF file in ocp.robots.models, contact azimuths [deg], pad half size [m])
_HANDS: dict[str, tuple[str, tuple[float, ...], float]] = {
    "two_finger": ("two_finger_hand.urdf", (0.0, 180.0), PAD_HALF_SIZE),
    "three_finger": ("three_finger_hand.urdf", (0.0, 120.0, 240.0), THREE_FINGER_PAD_HALF_SIZE),
}


def _readonly(a: ArrayLike) -> FloatArray:
    out = np.array(a, dtype=float)
    out.setflags(write=False)
    return out


def _check_name(name: str) -> tuple[str, tuple[float, ...], float]:
    if name not in _HANDS:
        raise ValueError(f"unknown hand {name!r}; the built-in hands are {list(HAND_NAMES)}")
    return _HANDS[name]


def builtin_hand_urdf_text(name: str) -> str:
    """The text of a built-in hand's URDF (package data of ``ocp.robots.models``)."""
    file, _, _ = _check_name(name)
    return resources.files(_models).joinpath(file).read_text(encoding="utf-8")


def _rz(angle: float) -> FloatArray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def default_mounts(name: str) -> tuple[Mount, ...]:
    """The built-in mounts ``(R, p)`` of a hand's finger bases in the palm frame [-, m]:
    :data:`MOUNT_RADIUS` from the palm's z axis at each contact's azimuth ``phi``,
    :data:`MOUNT_HEIGHT` below the palm, yawed by ``phi + 180 deg`` (facing the axis).
    The same as the shipped URDF's ``fN_mount`` joints (to its 15 printed decimals)."""
    _, azimuths, _ = _check_name(name)
    out = []
    for az in np.deg2rad(azimuths):
        p = np.array([MOUNT_RADIUS * np.cos(az), MOUNT_RADIUS * np.sin(az), MOUNT_HEIGHT])
        out.append((_readonly(_rz(az + np.pi)), _readonly(p)))
    return tuple(out)


def _mount_joint(root: ET.Element, k: int) -> ET.Element:
    for joint in root.iter("joint"):
        if joint.get("name") == f"f{k}_mount":
            return joint
    raise ValueError(f"the hand's URDF has no joint 'f{k}_mount'")  # pragma: no cover


def _mount_of(joint: ET.Element) -> Mount:
    origin = joint.find("origin")
    xyz = [0.0] * 3 if origin is None else [float(v) for v in origin.get("xyz", "0 0 0").split()]
    rpy = [0.0] * 3 if origin is None else [float(v) for v in origin.get("rpy", "0 0 0").split()]
    R = np.asarray(pin.rpy.rpyToMatrix(*rpy), dtype=float)
    return _readonly(R), _readonly(xyz)


def _parse(text: str) -> ET.Element:
    # keep the URDF's comments when it is rewritten
    return ET.fromstring(text, parser=ET.XMLParser(target=ET.TreeBuilder(insert_comments=True)))


def _check_mounts(mounts: object, n: int, name: str) -> list[Mount]:
    if isinstance(mounts, (str, bytes)) or not isinstance(mounts, Sequence):
        raise ValueError(f"mounts must be a sequence of {n} (rotation 3x3, position 3) pairs")
    if len(mounts) != n:
        raise ValueError(
            f"the {name} hand has {n} fingers, so mounts must have {n} entries, got "
            f"{len(mounts)}")
    out = []
    for k, mount in enumerate(mounts):
        try:
            R, p = mount
        except (TypeError, ValueError) as exc:
            raise ValueError(
                f"mounts[{k}] must be a pair (rotation 3x3, position 3 [m])") from exc
        out.append((_rotation(R, f"mounts[{k}] rotation"), _vector3(p, f"mounts[{k}] position")))
    return out


def _format(x: float) -> str:
    return repr(float(x))


@dataclass(frozen=True, eq=False)
class Hand:
    """A hand: fingers around a palm, and the nominal grasp of a ball held in the air.

    Attributes
    ----------
    name:
        One of :data:`HAND_NAMES`.
    fingers:
        One :class:`~ocp.robots.finger.FingerModel` per finger (f1, f2, ...), each the branch of
        the hand's URDF carrying its tip frame; poses in the palm frame.
    tip_frames:
        The fingers' pad frames, ``("f1_fingertip", "f2_fingertip", ...)``.
    urdf_text:
        The hand's URDF (with the mounts written into it).
    mounts:
        Pose ``(R, p)`` [-, m] of each finger's base (``fN_finger_base``) in the palm frame.
    contact_azimuths:
        Azimuth [rad] about the palm's z axis of each finger's contact on the ball's
        equator in the nominal grasp.
    nominal_object_position, nominal_radius:
        Centre [m] (palm frame) and radius [m] of the ball of the nominal grasp.
    nominal_q:
        Each finger's joint angles [rad] in the nominal grasp (IK from
        :data:`NOMINAL_SEED`), or None when a finger does not reach it within its limits
        (reconfigured mounts).
    """

    name: str
    fingers: tuple[FingerModel, ...]
    tip_frames: tuple[str, ...]
    urdf_text: str
    mounts: tuple[Mount, ...]
    contact_azimuths: tuple[float, ...]
    nominal_object_position: tuple[float, float, float]
    nominal_radius: float
    nominal_q: tuple[tuple[float, ...], ...] | None

    @property
    def n_fingers(self) -> int:
        """Number of fingers."""
        return len(self.fingers)

    @property
    def pad_half_size(self) -> float:
        """Half the side of the fingers' square pads [m]."""
        return self.fingers[0].pad_half_size


def load_hand(name: str = "three_finger",
              mounts: Sequence[tuple[ArrayLike, ArrayLike]] | None = None) -> Hand:
    """Load a built-in hand (:data:`HAND_NAMES`), its finger bases optionally reconfigured.

    ``mounts[k] = (R, p)``: the pose of finger k+1's base in the palm frame (rotation 3x3,
    position [m]), written into the URDF's fixed joint ``f{k+1}_mount`` before loading;
    None keeps the built-in mounts (:func:`default_mounts`). Raises ValueError for an
    unknown name, or mounts of the wrong count, shape, or not rotations.
    """
    _, azimuths, pad = _check_name(name)
    n = len(azimuths)
    text = builtin_hand_urdf_text(name)
    root = _parse(text)
    if mounts is not None:
        root.insert(0, ET.Comment(
            " reconfigured: the fN_mount origins were rewritten by"
            " ocp.robots.hands.load_hand(mounts=...);"
            " the mount geometry described above no longer holds "))
        for k, (R, p) in enumerate(_check_mounts(mounts, n, name), start=1):
            origin = _mount_joint(root, k).find("origin")
            if origin is None:  # pragma: no cover - the shipped URDFs have one
                origin = ET.SubElement(_mount_joint(root, k), "origin")
            rpy = np.asarray(pin.rpy.matrixToRpy(R), dtype=float)
            origin.set("xyz", " ".join(_format(v) for v in p))
            origin.set("rpy", " ".join(_format(v) for v in rpy))
        text = '<?xml version="1.0"?>\n' + ET.tostring(root, encoding="unicode") + "\n"
    tip_frames = tuple(f"f{k}_fingertip" for k in range(1, n + 1))
    fingers = tuple(load_finger(text, tip_frame=tip, pad_half_size=pad) for tip in tip_frames)
    contact_azimuths = tuple(float(a) for a in np.deg2rad(azimuths))
    poses = _grasp_poses(contact_azimuths, np.array(NOMINAL_OBJECT_POSITION), NOMINAL_RADIUS,
                         np.eye(3))
    results = [inverse_kinematics(f, R, p, NOMINAL_SEED)
               for f, (R, p) in zip(fingers, poses, strict=True)]
    nominal_q = None
    if all(r.converged and r.within_limits for r in results):
        nominal_q = tuple(tuple(float(v) for v in r.q) for r in results)
    return Hand(
        name=name,
        fingers=fingers,
        tip_frames=tip_frames,
        urdf_text=text,
        mounts=tuple(_mount_of(_mount_joint(root, k)) for k in range(1, n + 1)),
        contact_azimuths=contact_azimuths,
        nominal_object_position=NOMINAL_OBJECT_POSITION,
        nominal_radius=NOMINAL_RADIUS,
        nominal_q=nominal_q,
    )


def _grasp_poses(azimuths: Sequence[float], c: FloatArray, rho: float, Rb: FloatArray
                 ) -> tuple[tuple[FloatArray, FloatArray], ...]:
    out = []
    for az in azimuths:
        u = np.array([np.cos(az), np.sin(az), 0.0])
        z = -u
        x = np.array([0.0, 0.0, 1.0])
        R = np.column_stack([x, np.cross(z, x), z])
        out.append((Rb @ R, c + rho * (Rb @ u)))
    return tuple(out)


def grasp_poses(hand: Hand, object_position: ArrayLike | None = None,
                radius: float | None = None, rotation: ArrayLike | None = None
                ) -> tuple[tuple[FloatArray, FloatArray], ...]:
    """The pad poses ``(R, p)`` (palm frame) of the hand's grasp of a ball.

    The nominal grasp (defaults: :attr:`Hand.nominal_object_position`,
    :attr:`Hand.nominal_radius`, ``rotation`` = identity) moved with the ball: finger k's
    pad frame is ``R = rotation @ R_k``, ``p = c + radius * rotation @ u_k`` with ``u_k``
    the unit vector at the contact azimuth on the equator and ``R_k`` the pad frame with z
    axis ``-u_k`` (the pad's outward normal through the centre) and x axis the palm's +z.
    """
    c = _vector3(hand.nominal_object_position if object_position is None else object_position,
                 "object_position")
    rho = hand.nominal_radius if radius is None else float(radius)
    if not (np.isfinite(rho) and rho > 0.0):
        raise ValueError(f"radius must be > 0 m, got {rho}")
    Rb = np.eye(3) if rotation is None else _rotation(rotation, "rotation")
    return _grasp_poses(hand.contact_azimuths, c, rho, Rb)


def grasp_ik(hand: Hand, object_position: ArrayLike | None = None,
             radius: float | None = None, rotation: ArrayLike | None = None,
             seeds: Sequence[ArrayLike] | None = None) -> tuple[IKResult, ...]:
    """Each finger's :func:`~ocp.robots.finger.inverse_kinematics` of the pad poses of
    :func:`grasp_poses`, from ``seeds`` (default: :attr:`Hand.nominal_q`, else
    :data:`NOMINAL_SEED`)."""
    poses = grasp_poses(hand, object_position, radius, rotation)
    if seeds is None:
        seeds = hand.nominal_q if hand.nominal_q is not None else [NOMINAL_SEED] * hand.n_fingers
    if len(seeds) != hand.n_fingers:
        raise ValueError(f"seeds must have {hand.n_fingers} entries, got {len(seeds)}")
    return tuple(inverse_kinematics(f, R, p, s)
                 for f, (R, p), s in zip(hand.fingers, poses, seeds, strict=True))


# -- reach around the nominal grasp ----------------------------------------------------------


def sweep_cases(max_angle_deg: float = 30.0, max_shift: float = 0.01
                ) -> tuple[tuple[FloatArray, FloatArray], ...]:
    """The displacements of the ball of :func:`reach_sweep`: pairs (rotation vector [rad],
    translation [m]), every combination of 27 rotations (none, and ``max_angle_deg`` about
    each of the 26 unit directions of a cube's faces, edges and corners) and 15
    translations (none, ``+-max_shift`` along each palm axis, and the 8 corners
    ``(+-1, +-1, +-1) max_shift``): 405 cases."""
    cube = [np.array(v, dtype=float) for v in itertools.product((-1, 0, 1), repeat=3) if any(v)]
    angle = np.deg2rad(max_angle_deg)
    rotations = [np.zeros(3)] + [v / np.linalg.norm(v) * angle for v in cube]
    shifts = [np.zeros(3)] + [max_shift * v for v in cube if np.sum(np.abs(v)) in (1, 3)]
    return tuple((_readonly(w), _readonly(t)) for w in rotations for t in shifts)


@dataclass(frozen=True, eq=False)
class ReachSweep:
    """One finger's :func:`reach_sweep`: ``margins[i]`` is the least distance [rad] of the
    IK solution of case i (:func:`sweep_cases`) to a joint limit, NaN when not reached."""

    finger: int
    margins: FloatArray

    @property
    def tried(self) -> int:
        """Number of poses tried."""
        return int(self.margins.size)

    @property
    def reached(self) -> int:
        """Number of poses reached (IK converged within the limits)."""
        return int(np.count_nonzero(np.isfinite(self.margins)))

    @property
    def min_margin(self) -> float:
        """The least margin to a joint limit [rad] over the poses reached (NaN if none)."""
        m = self.margins[np.isfinite(self.margins)]
        return float(m.min()) if m.size else float("nan")

    def reached_with_margin(self, margin: float) -> int:
        """Number of poses reached with at least ``margin`` [rad] to every joint limit."""
        m = self.margins[np.isfinite(self.margins)]
        return int(np.count_nonzero(m >= margin))


def reach_sweep(hand: Hand, max_angle_deg: float = 30.0, max_shift: float = 0.01,
                steps: int = 3) -> tuple[ReachSweep, ...]:
    """Which pad poses around the nominal grasp each finger reaches.

    For each case ``(w, t)`` of :func:`sweep_cases` the ball is rotated by ``exp(w)`` about
    its centre and its centre translated by ``t``, each pad moving with it (on the sphere
    of radius rho about the centre, :func:`grasp_poses`); the IK is tracked from
    :attr:`Hand.nominal_q` along ``s (w, t)``, ``s = 1/steps, ..., 1``, each step seeded
    by the previous one. Raises ValueError if the hand does not reach its nominal grasp.
    """
    if hand.nominal_q is None:
        raise ValueError(f"the {hand.name} hand's mounts do not reach its nominal grasp")
    if steps < 1:
        raise ValueError(f"steps must be >= 1, got {steps}")
    c = np.asarray(hand.nominal_object_position, dtype=float)
    nominal = grasp_poses(hand)
    cases = sweep_cases(max_angle_deg, max_shift)
    out = []
    for k, (finger, (R0, p0), q0) in enumerate(
            zip(hand.fingers, nominal, hand.nominal_q, strict=True)):
        margins = np.full(len(cases), np.nan)
        for i, (w, t) in enumerate(cases):
            q = np.asarray(q0, dtype=float)
            res = None
            for s in np.arange(1, steps + 1) / steps:
                Rb = np.asarray(pin.exp3(s * w), dtype=float)
                res = inverse_kinematics(finger, Rb @ R0, c + s * t + Rb @ (p0 - c), q)
                q = res.q
            if res is not None and res.converged and res.within_limits:
                margins[i] = float(np.min(np.minimum(q - finger.lower, finger.upper - q)))
        out.append(ReachSweep(finger=k, margins=_readonly(margins)))
    return tuple(out)
