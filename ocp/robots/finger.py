"""A robot finger from a URDF: Pinocchio model, CasADi forward kinematics, inverse kinematics.

The finger is a serial chain of revolute and prismatic joints read from a URDF by Pinocchio:
the whole URDF, or one finger of a hand's URDF (the branch of its tree that carries the tip
frame, :mod:`ocp.robots.hands`). Its fingertip frame (``"fingertip"`` in the built-in model) is the
frame of the flat pad: its origin is the centre of the pad surface and its +z axis the pad's
outward normal, so the pad is the :data:`~ocp.geometry.surfaces.Plane` chart ``f(x, y) = (x, y, 0)``
in that frame (docs/conventions.md). The finger's base is mounted in the palm frame P by a
fixed pose ``g_pb = (base_rotation, base_position)``; every pose and Jacobian here is in the
palm frame.

* :attr:`FingerModel.fk` is a CasADi function ``q -> (R, p)`` built from the Pinocchio model's
  data (joint placements, joint types and axes, the tip frame's placement), not from a second
  copy of the link dimensions, so that it can go into an NLP;
* :meth:`FingerModel.fingertip_pose_pin` and :meth:`FingerModel.frame_jacobian_pin` are the
  same quantities from Pinocchio itself (the reference the CasADi expressions are tested
  against);
* :func:`~ocp.robots.ik.inverse_kinematics` (in :mod:`ocp.robots.ik`, re-exported here) is
  damped least squares (Levenberg-Marquardt) on the 6-D pose error within the joint limits.

The built-in finger (``ocp/robots/models/k3s_finger.urdf``) is a 6-revolute finger in the spirit of
the HKUST hand's modified Motoman K3S fingers (waist yaw, shoulder pitch, elbow pitch, wrist
roll, wrist pitch, wrist roll), scaled to finger size, with a 100 mm x 100 mm flat pad. Its
default mount (:data:`DEFAULT_BASE_POSITION`) lets the pad press on the top of a 25 mm ball
anywhere along experiment 1's triangle, where the pad travels twice as far as the ball. The
paper's initial joint angles are a configuration above the palm that seeds the inverse
kinematics of the initial grasp; they are not that grasp's joint angles (the paper's
finger dimensions are not given).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import cached_property
from importlib import resources
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike, NDArray

from ocp.robots.arrays import readonly as _readonly
from ocp.robots.arrays import rotation as _rotation
from ocp.robots.arrays import vector3 as _vector3
from ocp.robots.ik import IKResult, inverse_kinematics, inverse_kinematics_batch
from ocp.robots.urdf_frames import kinematic_urdf

from . import models as _models

__all__ = [
    "BUILTIN_URDF",
    "DEFAULT_BASE_POSITION",
    "DEFAULT_BASE_ROTATION",
    "PAD_HALF_SIZE",
    "PAPER_SEED",
    "PAPER_SEED_DEG",
    "ChainJoint",
    "FingerModel",
    "IKResult",
    "builtin_urdf_text",
    "inverse_kinematics",
    "inverse_kinematics_batch",
    "load_finger",
]

FloatArray = NDArray[np.float64]

#: File name of the built-in finger in the package ``ocp.robots.models``.
BUILTIN_URDF = "k3s_finger.urdf"

#: Half the side of the built-in finger's square pad [m] (a 100 mm x 100 mm pad). In the
#: paper's experiment 1 the contact travels across the fingertip as far as the ball's centre
#: travels over the palm (its figure 7): up to 42 mm on the 30 mm triangle when the grasp is
#: kept near antipodal, so the pad must be wider than that on each side.
PAD_HALF_SIZE = 0.05

#: The built-in finger's default mount in the palm frame: its base frame is parallel to the
#: palm frame (the finger reaches along the palm's +x at zero waist angle) ...
DEFAULT_BASE_ROTATION: tuple[tuple[float, ...], ...] = (
    (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
#: ... with its origin 49 mm on the palm's -x side, 40 mm on its +y side of palm point
#: (0, 0), and 10 mm below the palm surface (the finger stands beside the palm) [m]. While
#: the ball's centre rolls along experiment 1's triangle the pad, pressing on its top, moves
#: along a triangle twice as large (0, 0) - (60, 0) - (60, 60) mm (the paper's figure 6);
#: from this mount IK reaches pad poses over that whole triangle, yawed up to 20 deg and
#: tilted up to 20 deg, with at least 24 deg of margin to every joint limit (a sweep of 22
#: pad positions x 15 orientations, 2 of them at the far corner out of reach). The paper's
#: initial joint angles :data:`PAPER_SEED` seed the IK of the initial grasp.
DEFAULT_BASE_POSITION: tuple[float, float, float] = (-0.049, 0.04, -0.01)

#: The paper's initial joint angles of experiment 1 [deg] and [rad].
PAPER_SEED_DEG: tuple[float, ...] = (0.0, -22.68, -12.34, 0.0, 47.65, 0.0)
PAPER_SEED: FloatArray = np.deg2rad(np.array(PAPER_SEED_DEG))
PAPER_SEED.setflags(write=False)

#: Pinocchio joint types the CasADi kinematics supports: kind and fixed axis (None: the
#: joint model carries its own ``axis``).
_JOINT_TYPES: dict[str, tuple[str, tuple[float, float, float] | None]] = {
    "JointModelRX": ("revolute", (1.0, 0.0, 0.0)),
    "JointModelRY": ("revolute", (0.0, 1.0, 0.0)),
    "JointModelRZ": ("revolute", (0.0, 0.0, 1.0)),
    "JointModelRevoluteUnaligned": ("revolute", None),
    "JointModelPX": ("prismatic", (1.0, 0.0, 0.0)),
    "JointModelPY": ("prismatic", (0.0, 1.0, 0.0)),
    "JointModelPZ": ("prismatic", (0.0, 0.0, 1.0)),
    "JointModelPrismaticUnaligned": ("prismatic", None),
}


def builtin_urdf_text() -> str:
    """The text of the built-in finger's URDF (shipped as package data of ``ocp.robots.models``)."""
    return resources.files(_models).joinpath(BUILTIN_URDF).read_text(encoding="utf-8")


def _skew(w: Any) -> Any:
    """[w]x of a 3-vector, as a CasADi matrix."""
    return ca.vertcat(
        ca.horzcat(0, -w[2], w[1]), ca.horzcat(w[2], 0, -w[0]), ca.horzcat(-w[1], w[0], 0))


def _axis_rotation(axis: FloatArray, angle: ca.SX) -> ca.SX:
    """Rotation by ``angle`` [rad] about the unit ``axis``: c I + s [a]x + (1 - c) a a^T."""
    c, s = ca.cos(angle), ca.sin(angle)
    a = ca.DM(axis)
    return c * ca.DM.eye(3) + s * _skew(a) + (1 - c) * (a @ a.T)


@dataclass(frozen=True)
class ChainJoint:
    """One joint of the finger's serial chain, as the CasADi kinematics uses it.

    ``placement_rotation``/``placement_translation`` [m] are the joint's placement in its
    parent joint's frame (Pinocchio's ``jointPlacements``); the joint then rotates about
    (revolute, q in rad) or slides along (prismatic, q in m) the unit ``axis`` of its frame.
    """

    name: str
    kind: str
    axis: FloatArray
    index_q: int
    placement_rotation: FloatArray
    placement_translation: FloatArray


@dataclass(frozen=True, eq=False)
class FingerModel:
    """A serial finger: Pinocchio model, fingertip (pad) frame, base mount, limits.

    Attributes
    ----------
    model, data:
        The Pinocchio ``Model`` and a ``Data`` for it (used by the ``*_pin`` helpers, which
        are therefore not thread-safe; :func:`inverse_kinematics` makes its own ``Data``).
    tip_frame, tip_frame_id:
        Name and Pinocchio id of the fingertip frame: origin at the centre of the pad
        surface, +z the pad's outward normal.
    base_rotation, base_position:
        Pose ``g_pb`` of the finger's base (the URDF root) in the palm frame [-, m].
    lower, upper:
        Joint position limits [rad or m], from the URDF.
    velocity_limit:
        Joint velocity limits [rad/s or m/s], from the URDF.
    pad_half_size:
        Half the side of the square pad [m].
    urdf_text:
        The URDF the model was built from.
    joint_names:
        The chain's joint names, in the order of q.
    chain:
        The chain's joints (placements, kinds, axes) the CasADi kinematics is built from.
    tip_rotation, tip_translation:
        Placement of the fingertip frame in the last joint's frame [-, m].
    """

    model: Any
    data: Any
    tip_frame: str
    tip_frame_id: int
    base_rotation: FloatArray
    base_position: FloatArray
    lower: FloatArray
    upper: FloatArray
    velocity_limit: FloatArray
    pad_half_size: float
    urdf_text: str
    joint_names: tuple[str, ...]
    chain: tuple[ChainJoint, ...] = field(repr=False)
    tip_rotation: FloatArray = field(repr=False)
    tip_translation: FloatArray = field(repr=False)
    #: The fingertip surface in the tip frame (:class:`~ocp.geometry.tips.TipSurface`);
    #: None: the flat square pad of :attr:`pad_half_size` (the tip frame the pad's).
    tip: Any = None
    #: Linear couplings of its joints the plan keeps (:class:`~ocp.robots.couplings.Coupling`:
    #: an MJCF's coupling tendons and joint equalities).
    couplings: tuple[Any, ...] = ()
    #: :meth:`with_couplings`' fingers, by their couplings
    _variants: dict[tuple[Any, ...], Any] = field(default_factory=dict, repr=False)

    def with_couplings(self, couplings: tuple[Any, ...]) -> FingerModel:
        """This finger with other couplings (a passive joint's tendon held at a bound:
        :func:`~ocp.robots.grasp_reach.at_tendon_bounds`); the same object for the same
        couplings, so that the NLPs built for it are found again."""
        if couplings == self.couplings:
            return self
        got = self._variants.get(couplings)
        if got is None:
            got = self._variants[couplings] = replace(self, couplings=couplings,
                                                      _variants={})
        return got

    @property
    def tip_surface(self) -> Any:
        """The fingertip surface (:class:`~ocp.geometry.tips.TipSurface`) in the tip frame."""
        from ocp.geometry.tips import pad_tip

        return self.tip if self.tip is not None else pad_tip(self.pad_half_size)

    @property
    def nq(self) -> int:
        """Number of joints (one coordinate each)."""
        return int(self.model.nq)

    @property
    def base_pose(self) -> FloatArray:
        """The base's pose in the palm frame as a 4x4 homogeneous matrix [m]."""
        g = np.eye(4)
        g[:3, :3] = self.base_rotation
        g[:3, 3] = self.base_position
        return g

    @cached_property
    def length_scale(self) -> float:
        """Sum of the chain's link offsets after the first joint, tip placement included [m].

        The reach of an all-revolute finger is at most this; the inverse kinematics divides
        position errors by it to weigh them against orientation errors in rad.
        """
        total = sum(float(np.linalg.norm(j.placement_translation)) for j in self.chain[1:])
        total += float(np.linalg.norm(self.tip_translation))
        return max(total, 1e-3)

    @cached_property
    def fk(self) -> ca.Function:
        """CasADi function ``fingertip_pose``: ``q (nq) -> (R (3x3), p (3x1))``.

        The fingertip frame's orientation ``R`` and origin ``p`` [m] in the palm frame,
        ``g_pf(q) = g_pb * prod_i (M_i * g_i(q_i)) * M_tip``: ``M_i`` joint i's placement in
        its parent joint's frame (Pinocchio's ``jointPlacements``), ``g_i(q_i)`` the rotation
        about (or translation along) its axis, ``M_tip`` the tip frame's placement in the
        last joint's frame.
        """
        q = ca.SX.sym("q", self.nq)
        R, p = self._fk_expr(q)
        return ca.Function("fingertip_pose", [q], [R, p], ["q"], ["R", "p"])

    @cached_property
    def jacobian(self) -> ca.Function:
        """CasADi function ``fingertip_jacobian``: ``q (nq) -> J (6 x nq)``.

        World-aligned (palm-frame) Jacobian of the fingertip frame: rows 0-2 map joint rates
        to the velocity of the frame's origin [m/s], rows 3-5 to its angular velocity
        [rad/s], both in palm coordinates (Pinocchio's ``LOCAL_WORLD_ALIGNED`` rotated into
        the palm). Derived by differentiating :attr:`fk`: ``dp/dq`` and
        ``vee(dR/dq_i R^T)``.
        """
        q = ca.SX.sym("q", self.nq)
        R, p = self._fk_expr(q)
        J_v = ca.jacobian(p, q)
        dR = ca.jacobian(ca.vec(R), q)  # column i: vec(dR/dq_i), column-major
        cols = []
        for i in range(self.nq):
            S = ca.reshape(dR[:, i], 3, 3) @ R.T
            cols.append(0.5 * ca.vertcat(S[2, 1] - S[1, 2], S[0, 2] - S[2, 0],
                                         S[1, 0] - S[0, 1]))
        J_w = ca.horzcat(*cols)
        return ca.Function("fingertip_jacobian", [q], [ca.vertcat(J_v, J_w)], ["q"], ["J"])

    def tip_poses(self, q: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """(R: n x 3 x 3, p: n x 3): :attr:`fk` at every joint row of ``q`` (n x nq) in one
        call."""
        qa = np.asarray(q, dtype=float).reshape(-1, self.nq)
        n = len(qa)
        R, p = self.fk.map(n)(qa.T)
        return np.asarray(R).reshape(3, n, 3).transpose(1, 0, 2), np.asarray(p).T.copy()

    def tip_jacobians(self, q: ArrayLike) -> FloatArray:
        """n x 6 x nq: :attr:`jacobian` at every joint row of ``q`` (n x nq) in one call."""
        qa = np.asarray(q, dtype=float).reshape(-1, self.nq)
        n = len(qa)
        J = self.jacobian.map(n)(qa.T)
        return np.asarray(J).reshape(6, n, self.nq).transpose(1, 0, 2)

    def joint_frames(self, q: Any) -> tuple[list[tuple[ChainJoint, Any, Any]], Any, Any]:
        """The chain's product (CasADi): each joint with its frame's orientation and origin
        in the palm frame before its own motion, and the last joint's frame after it."""
        R: Any = ca.DM(self.base_rotation)
        p: Any = ca.DM(self.base_position)
        frames = []
        for joint in self.chain:
            p = p + R @ ca.DM(joint.placement_translation)
            R = R @ ca.DM(joint.placement_rotation)
            frames.append((joint, R, p))
            qi = q[joint.index_q]
            if joint.kind == "revolute":
                R = R @ _axis_rotation(joint.axis, qi)
            else:
                p = p + R @ (ca.DM(joint.axis) * qi)
        return frames, R, p

    def _fk_expr(self, q: ca.SX) -> tuple[ca.SX, ca.SX]:
        _, R, p = self.joint_frames(q)
        p = p + R @ ca.DM(self.tip_translation)
        R = R @ ca.DM(self.tip_rotation)
        return R, p

    # -- Pinocchio's own kinematics ---------------------------------------------------------

    def _check_q(self, q: ArrayLike) -> FloatArray:
        qa = np.asarray(q, dtype=float).reshape(-1)
        if qa.shape != (self.nq,):
            raise ValueError(f"q must have {self.nq} entries, got {qa.shape[0]}")
        return qa

    def _pose_pin(self, q: FloatArray, data: Any) -> tuple[FloatArray, FloatArray]:
        pin.framesForwardKinematics(self.model, data, q)
        return self._placed_tip(data)

    def _placed_tip(self, data: Any) -> tuple[FloatArray, FloatArray]:
        """(R, p): the tip frame's placement in ``data`` (as the last Pinocchio pass left
        it), in the palm frame."""
        M = data.oMf[self.tip_frame_id]
        R = self.base_rotation @ np.asarray(M.rotation)
        p = self.base_rotation @ np.asarray(M.translation) + self.base_position
        return R, p

    def _jacobian_pin(self, q: FloatArray, data: Any) -> FloatArray:
        J = pin.computeFrameJacobian(self.model, data, q, self.tip_frame_id,
                                     pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
        Rb = self.base_rotation
        return np.vstack([Rb @ J[:3], Rb @ J[3:]])

    def fingertip_pose_pin(self, q: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """(R, p): the fingertip frame in the palm frame by Pinocchio [-, m]."""
        return self._pose_pin(self._check_q(q), self.data)

    def pose_and_jacobian_pin(self, q: ArrayLike
                              ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """(R, p, J): :meth:`fingertip_pose_pin` and :meth:`frame_jacobian_pin` from one
        Pinocchio pass (its frame Jacobian updates the frame's placement as its forward
        kinematics does: the same numbers, one pass instead of two)."""
        J = self._jacobian_pin(self._check_q(q), self.data)
        return (*self._placed_tip(self.data), J)

    def frame_jacobian_pin(self, q: ArrayLike) -> FloatArray:
        """6 x nq Jacobian of the fingertip frame by Pinocchio, rows (v [m/s]; omega [rad/s])
        in palm coordinates (``LOCAL_WORLD_ALIGNED`` rotated by the base rotation)."""
        return self._jacobian_pin(self._check_q(q), self.data)

    @property
    def mass(self) -> float:
        """The total mass of the finger's links [kg] (0: its model has no inertias, as the
        built-in fingers)."""
        return float(sum(float(inertia.mass) for inertia in self.model.inertias))

    def gravity_torques(self, q: ArrayLike, gravity: ArrayLike) -> FloatArray:
        """The joint torques [N m] that hold the finger's links still against ``gravity``
        [m/s^2, palm frame] at the joint angles ``q`` (rows): Pinocchio's generalized
        gravity of the model, the gravity turned into the finger's base frame."""
        qa = np.atleast_2d(np.asarray(q, dtype=float))
        model = pin.Model(self.model)  # a copy: its gravity is this call's
        g_base = self.base_rotation.T @ np.asarray(gravity, dtype=float)
        model.gravity = pin.Motion(np.concatenate([g_base, np.zeros(3)]))
        data = model.createData()
        return np.array([pin.computeGeneralizedGravity(model, data, self._check_q(qk))
                         for qk in qa]).reshape(len(qa), self.nq)

    def within_limits(self, q: ArrayLike, margin: float = 0.0) -> bool:
        """Whether ``lower + margin <= q <= upper - margin`` for every joint."""
        qa = self._check_q(q)
        return bool(np.all(qa >= self.lower + margin) and np.all(qa <= self.upper - margin))


def _chain(model: Any, tip_frame_id: int, tip_frame: str) -> tuple[ChainJoint, ...]:
    """The joints from the root to the tip frame; ValueError unless a supported serial chain."""
    if model.njoints < 2:
        raise ValueError("the URDF has no movable joint")
    for i in range(1, model.njoints):
        if model.parents[i] != i - 1:
            raise ValueError(
                f"the finger must be a serial chain: joint {model.names[i]!r} hangs from "
                f"{model.names[model.parents[i]]!r}, not from the previous joint "
                f"{model.names[i - 1]!r}")
    last = model.njoints - 1
    parent = model.frames[tip_frame_id].parentJoint
    if parent != last:
        raise ValueError(
            f"the tip frame {tip_frame!r} is attached to joint {model.names[parent]!r}, but "
            f"the chain ends at joint {model.names[last]!r}: the joints after it would not "
            f"move it")
    chain = []
    for i in range(1, model.njoints):
        jm = model.joints[i]
        kind_axis = _JOINT_TYPES.get(jm.shortname())
        if kind_axis is None:
            raise ValueError(
                f"joint {model.names[i]!r} is a Pinocchio {jm.shortname()}; only revolute "
                f"(RX, RY, RZ, RevoluteUnaligned) and prismatic (PX, PY, PZ, "
                f"PrismaticUnaligned) joints are supported (a URDF 'continuous' joint becomes "
                f"an unbounded revolute: declare it 'revolute' with limits)")
        kind, axis = kind_axis
        if jm.nq != 1 or jm.nv != 1:
            raise ValueError(f"joint {model.names[i]!r} must have one coordinate")
        ax = np.array(axis if axis is not None else jm.extract().axis, dtype=float)
        ax = ax / np.linalg.norm(ax)
        M = model.jointPlacements[i]
        chain.append(ChainJoint(
            name=str(model.names[i]), kind=kind, axis=_readonly(ax), index_q=int(jm.idx_q),
            placement_rotation=_readonly(M.rotation),
            placement_translation=_readonly(M.translation)))
    return tuple(chain)


def tip_path(model: Any, tip_frame: str) -> list[str]:
    """The names of the joints from the model's root to the tip frame, root first."""
    joint = int(model.frames[int(model.getFrameId(tip_frame))].parentJoint)
    path = []
    while joint != 0:
        path.append(str(model.names[joint]))
        joint = int(model.parents[joint])
    return path[::-1]


def _reduce_to_tip_chain(model: Any, tip_frame_id: int,
                         held: dict[str, float] | None = None) -> Any:
    """The model restricted to the branch of the kinematic tree that carries the tip frame.

    A hand's URDF is a tree: several fingers hang from its root (the palm). The branch of
    the tip frame is the subtree of the first joint on the tip's path (from the root) that
    is not ``held``; every joint outside it is locked with Pinocchio's
    ``buildReducedModel``: the ``held`` joints (a wrist that carries every finger) at
    their given values, the others (the other fingers' joints, which do not move this tip)
    at their neutral positions. A model with a single branch and nothing held (a serial
    chain, or a chain that branches further out, which :func:`_chain` rejects) is returned
    unchanged.
    """
    held = held or {}
    held_ids = {int(model.getJointId(n)) for n in held}
    joint = int(model.frames[tip_frame_id].parentJoint)
    path = []
    while joint != 0:
        path.append(joint)
        joint = int(model.parents[joint])
    free = [j for j in reversed(path) if j not in held_ids]
    if not free and not held_ids:
        return model  # the tip hangs from the root: no branch to keep
    keep = {free[0]} if free else set()
    for i in range(1, model.njoints):
        if model.parents[i] in keep:  # parents precede their children in Pinocchio
            keep.add(i)
    locked = [i for i in range(1, model.njoints) if i not in keep]
    if not locked:
        return model
    q_ref = pin.neutral(model)
    for name, value in held.items():
        q_ref[model.joints[int(model.getJointId(name))].idx_q] = value
    return pin.buildReducedModel(model, locked, q_ref)


def load_finger(
    urdf: str | Path | None = None,
    tip_frame: str = "fingertip",
    base_rotation: ArrayLike | None = None,
    base_position: ArrayLike | None = None,
    pad_half_size: float | None = None,
    tip: Any = None,
) -> FingerModel:
    """Load a finger from a URDF (``None``: the built-in K3S-like finger).

    ``urdf`` is a file path, or the URDF's XML text itself (a string starting with ``<``).
    ``tip_frame`` names the pad frame (a URDF link or joint). The URDF may be a hand: a tree
    of serial fingers hanging from its root link; the finger is then the branch carrying
    ``tip_frame``, the other branches' joints locked at their neutral positions (see
    :func:`_reduce_to_tip_chain`; the model, ``q`` and the limits are the branch's).
    ``base_rotation`` (3x3) and ``base_position`` [m] mount the URDF's root in the palm
    frame; when None they are the built-in finger's :data:`DEFAULT_BASE_ROTATION`/
    :data:`DEFAULT_BASE_POSITION` for the built-in URDF and the identity/origin for a user
    URDF. ``pad_half_size`` [m] defaults to :data:`PAD_HALF_SIZE`. ``tip`` is the
    fingertip surface in the tip frame (:class:`~ocp.geometry.tips.TipSurface`; None: the
    flat pad of ``pad_half_size``).

    Raises ValueError for an unknown tip frame, a finger (the tip's branch) that is not a
    serial chain, a tip frame not on its last joint, or joints other than revolute and
    prismatic ones.
    """
    builtin = urdf is None
    if urdf is None:
        text, source = builtin_urdf_text(), BUILTIN_URDF
    elif isinstance(urdf, str) and urdf.lstrip().startswith("<"):
        text, source = urdf, "text"
    else:
        text, source = Path(urdf).read_text(encoding="utf-8"), str(urdf)
    try:
        model = pin.buildModelFromXML(kinematic_urdf(text))
    except (RuntimeError, ValueError) as exc:
        raise ValueError(f"cannot build a model from the URDF ({source}): {exc}") from exc
    if base_rotation is None:
        base_rotation = DEFAULT_BASE_ROTATION if builtin else np.eye(3)
    if base_position is None:
        base_position = DEFAULT_BASE_POSITION if builtin else np.zeros(3)
    return finger_from_model(model, text, tip_frame, base_rotation, base_position,
                             pad_half_size, tip)


def finger_from_model(
    model: Any,
    text: str,
    tip_frame: str,
    base_rotation: ArrayLike,
    base_position: ArrayLike,
    pad_half_size: float | None = None,
    tip: Any = None,
    default_velocity: float | None = None,
    held: dict[str, float] | None = None,
) -> FingerModel:
    """The finger of a Pinocchio model (built from ``text``, a URDF or an MJCF) whose tip
    is the frame ``tip_frame``: the branch of the model's tree carrying it (the other
    branches' joints locked at their neutral positions), mounted by ``base_rotation``
    and ``base_position`` in the palm frame; see :func:`load_finger`. Non-finite velocity
    limits (an MJCF has none) become ``default_velocity`` when it is given. ``held``:
    joints on the tip's path locked at the given values, not the finger's (a wrist shared
    by every finger: :func:`ocp.robots.whole_hand.load_whole_hand`)."""
    if not model.existFrame(tip_frame):
        names = sorted({str(f.name) for f in model.frames})
        raise ValueError(f"the URDF has no frame {tip_frame!r}; its frames are {names}")
    model = _reduce_to_tip_chain(model, int(model.getFrameId(tip_frame)), held)
    tip_id = int(model.getFrameId(tip_frame))
    chain = _chain(model, tip_id, tip_frame)
    half = PAD_HALF_SIZE if pad_half_size is None else float(pad_half_size)
    if not (np.isfinite(half) and half > 0.0):
        raise ValueError(f"pad_half_size must be > 0 m, got {half}")
    lower = np.asarray(model.lowerPositionLimit, dtype=float)
    upper = np.asarray(model.upperPositionLimit, dtype=float)
    if np.any(lower > upper):
        raise ValueError("a joint's lower limit exceeds its upper limit")
    vel = getattr(model, "upperVelocityLimit", None)
    velocity = np.asarray(model.velocityLimit if vel is None else vel, dtype=float)
    if default_velocity is not None:
        velocity = np.where(np.isfinite(velocity) & (velocity > 0), velocity,
                            default_velocity)
    tip_surface = tip
    if tip_surface is not None:
        bad = tip_surface.errors("tip")
        if bad:
            raise ValueError("; ".join(f"{f}: {r}" for f, r in bad))
    tip = model.frames[tip_id].placement
    return FingerModel(
        model=model,
        data=model.createData(),
        tip_frame=tip_frame,
        tip_frame_id=tip_id,
        base_rotation=_readonly(_rotation(base_rotation, "base_rotation")),
        base_position=_readonly(_vector3(base_position, "base_position")),
        lower=_readonly(lower),
        upper=_readonly(upper),
        velocity_limit=_readonly(velocity),
        pad_half_size=half,
        urdf_text=text,
        joint_names=tuple(j.name for j in chain),
        chain=chain,
        tip_rotation=_readonly(tip.rotation),
        tip_translation=_readonly(tip.translation),
        tip=tip_surface,
    )
