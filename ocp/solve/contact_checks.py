"""The certificate's checks of each contact kind (the kinds' models: :mod:`ocp.contacts`),
on the samples of the returned trajectory (:class:`CertificateContext`);
:func:`ocp.solve.certify.certify_grasp` gathers them with the grasp's own checks.

* the support: slip and spin (its laws), the object's height above the palm;
* the free object: nothing of its own (its motion is checked by tracking and
  re-integration);
* a fingertip on the object: slip and spin, and from Pinocchio's forward kinematics at the
  returned joint angles (point by point, independent of the NLP's CasADi kinematics):
  closure and the gap; its tip's excursion and joint limits;
* a free fingertip: its joint limits.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from ocp.certify.certificate import Check, CheckKind, TolerancePolicy
from ocp.contacts import Contact, FingertipContact, FreeFingertip, FreeObject, SupportContact
from ocp.robots.couplings import coupling_violation

if TYPE_CHECKING:
    from ocp.spec.grasp import ManipulationProblem

__all__ = ["CertificateContext", "contact_checks"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class CertificateContext:
    """The certificate's samples of the returned trajectory that every contact's checks
    read: their times, the law outputs by name (along the trajectory's own time
    derivative), the object's pose, the fingertips' poses from the contact coordinates, the
    states, and the scales of the tolerances."""

    times: FloatArray  # (n,)
    laws: dict[str, FloatArray]
    R_po: FloatArray  # (n, 3, 3)
    p_po: FloatArray  # (n, 3)
    R_pf: FloatArray  # (n, fingers, 3, 3)
    p_pf: FloatArray  # (n, fingers, 3)
    states: FloatArray  # (n, nx)
    shape: FloatArray
    L: float
    speed: float  # the plan's speed scale [m/s] (TolerancePolicy)
    rate: float  # the plan's rolling-rate scale [rad/s]
    policy: TolerancePolicy

    def worst(self, values: FloatArray) -> tuple[float, float]:
        """(the largest value, its time) of per-sample values (NaN counts as largest)."""
        v = np.asarray(values, dtype=float).ravel()
        j = int(np.argmax(np.where(np.isnan(v), np.inf, v)))
        return float(v[j]), float(self.times[j])

    def check(self, name: str, values: FloatArray, tolerance: float, kind: Any) -> Check:
        """The check that the largest of per-sample values is at most ``tolerance``,
        naming the time of the worst sample."""
        value, t = self.worst(values)
        return Check(name, value, tolerance, kind, time=t)


def contact_checks(contact: Contact, problem: ManipulationProblem, k: int,
                   c: CertificateContext) -> list[Check]:
    """The certificate's checks of one contact by its kind (k: its index among the
    grasp's contacts); see the module's doc."""
    if isinstance(contact, SupportContact):
        return support_checks(contact, c)
    if isinstance(contact, FingertipContact):
        return fingertip_checks(contact, problem, c)
    if isinstance(contact, FreeFingertip):
        return free_fingertip_checks(contact, problem, c)
    if isinstance(contact, FreeObject):
        return []
    raise TypeError(f"no certificate checks for the contact kind {type(contact).__name__}")


def joint_limit_violation(finger: Any, q: FloatArray) -> FloatArray:
    """Per sample, how far the joints ``q`` (rows) lie outside the finger's limits (0
    inside)."""
    return np.maximum(np.max(np.maximum(q - finger.upper, finger.lower - q), axis=1), 0.0)


def support_checks(contact: SupportContact, c: CertificateContext) -> list[Check]:
    """Slip and spin of the object on the palm (its laws along the returned trajectory),
    and the object's height: its support function along the palm's normal."""
    n, pol, D = contact.name, c.policy, CheckKind.DISCRETISATION
    # the object touches the palm: support function of its shape along -z (no chart)
    heights = contact.surface.support_heights(-c.R_po[:, 2, :], c.shape)  # rows R^T (-e_z)
    return [
        c.check(f"max_slip_speed_{n}", np.linalg.norm(c.laws[f"slip_{n}"], axis=1),
                pol.slip * c.speed, D),
        c.check(f"max_spin_rate_{n}", np.abs(c.laws[f"spin_{n}"]), pol.spin * c.rate, D),
        c.check(f"max_height_error_{n}", np.abs(c.p_po[:, 2] - heights),
                pol.support_height * (c.L if pol.height_relative else 1.0),
                CheckKind.PHYSICS),
    ]


def fingertip_checks(contact: FingertipContact, problem: ManipulationProblem,
                     c: CertificateContext) -> list[Check]:
    """Slip and spin (the laws along the returned trajectory), and from Pinocchio's
    forward kinematics at the returned joint angles (point by point, independent of the
    NLP's CasADi kinematics): closure (the pad where the contact coordinates put it)
    and the gap (the pad's plane tangent to the object); the pad and joint limits."""
    i, f, name, pol = contact.index, contact.finger, contact.label(problem), c.policy
    q_i = c.states[:, contact.q_cols]
    poses = [f.fingertip_pose_pin(q) for q in q_i]  # Pinocchio, point by point
    R_pin = np.array([pose[0] for pose in poses])
    p_pin = np.array([pose[1] for pose in poses])
    # the angle between the two rotations, well conditioned near 0 (an arccos of the
    # trace would be noise below ~1e-8 rad): |R1 - R2|_F = 2 sqrt 2 sin(angle / 2)
    diff = np.linalg.norm((R_pin - c.R_pf[:, i]).reshape(len(R_pin), 9), axis=1)
    angle = 2 * np.arcsin(np.minimum(1.0, diff / (2 * math.sqrt(2))))
    # the tip surface's tangent plane at its contact point (Pinocchio's pose of the tip
    # frame, the tip's chart at the returned coordinates) is tangent to the object: the
    # object's centre lies its support height (along the tip's normal) above it; for
    # the flat pad that plane is the pad's
    tip, n_s = contact.tip, len(R_pin)
    ab = c.states[:, contact.eta_cols][:, 0:2]
    geo = tip.surface.geometry.map(n_s)(ab.T, np.tile(np.asarray(
        tip.surface_params, dtype=float).reshape(-1, 1), (1, n_s)))
    f_t = np.asarray(geo[0]).T  # (n, 3) the tip point, tip surface frame
    z_t = np.asarray(geo[1]).reshape(3, n_s, 3)[:, :, 2].T  # (n, 3) its normal
    R_lt = R_pin @ tip.R  # the tip surface's frame in the palm
    tip_pt = p_pin + np.einsum("kij,kj->ki", R_lt, f_t) + R_pin @ tip.p
    tip_n = np.einsum("kij,kj->ki", R_lt, z_t)
    h = contact.surface.support_heights(np.einsum("kji,kj->ki", c.R_po, -tip_n), c.shape)
    gap = np.einsum("ki,ki->k", tip_n, c.p_po - tip_pt) - h
    D = CheckKind.DISCRETISATION
    obj_pt = c.p_po + np.einsum("kij,kj->ki", c.R_po, c.laws[f"object_point_{i}"])
    # the object's contact point in the tip surface's frame
    on_tip = np.einsum("kji,kj->ki", R_lt, obj_pt - p_pin - R_pin @ tip.p)
    if tip.kind == "pad":
        excursion = np.max(np.abs(on_tip[:, 0:2]), axis=1)
        excursion_name, limit = f"max_pad_excursion_{name}", float(f.pad_half_size)
    elif tip.kind == "capsule":
        # how far (as an angle) the contact lies from the cap's end (the tip frame's
        # -y): the cap is the hemisphere within pi/2 of it, the cylinder beyond
        d = on_tip / np.maximum(np.linalg.norm(on_tip, axis=1, keepdims=True), 1e-15)
        excursion = np.arccos(np.clip(-d[:, 1], -1.0, 1.0))
        excursion_name, limit = f"max_cap_angle_{name}", math.pi / 2
    else:  # a whole sphere or spheroid: the tip's pole bound, a property of its chart
        uv = tip.surface.inverse(on_tip, np.asarray(tip.surface_params, dtype=float))
        excursion = np.abs(uv[:, 0])
        excursion_name, limit = f"max_tip_latitude_{name}", math.pi / 2
    return [
        c.check(f"max_slip_speed_{name}", np.linalg.norm(c.laws[f"slip_{i}"], axis=1),
                pol.slip * c.speed, D),
        c.check(f"max_spin_rate_{name}", np.abs(c.laws[f"spin_{i}"]), pol.spin * c.rate,
                D),
        c.check(f"max_gap_error_{name}", np.abs(gap), pol.gap, D),
        c.check(excursion_name, excursion, limit, CheckKind.LIMITS),
        c.check(f"max_joint_limit_violation_{name}", joint_limit_violation(f, q_i),
                pol.joint_limit, D),
        *coupling_checks(f, name, q_i, c),
        c.check("max_closure_position_error", np.linalg.norm(p_pin - c.p_pf[:, i],
                                                              axis=1),
                pol.closure_position, D),
        c.check("max_closure_orientation_error", angle, pol.closure_orientation, D),
    ]


def free_fingertip_checks(contact: FreeFingertip, problem: ManipulationProblem,
                          c: CertificateContext) -> list[Check]:
    """A free fingertip's joints inside their limits along the returned trajectory."""
    q = c.states[:, contact.q_cols]
    name = contact.label(problem)
    return [c.check(f"max_joint_limit_violation_{name}",
                    joint_limit_violation(contact.finger, q), c.policy.joint_limit,
                    CheckKind.DISCRETISATION),
            *coupling_checks(contact.finger, name, q, c)]


def coupling_checks(finger: Any, name: str, q: FloatArray, c: CertificateContext
                    ) -> list[Check]:
    """The finger's joint couplings kept (:mod:`ocp.robots.couplings`: metres of
    tendon) along the returned trajectory; none for a finger without couplings."""
    if not getattr(finger, "couplings", ()):
        return []
    return [c.check(f"max_coupling_violation_{name}", coupling_violation(finger, q),
                    c.policy.coupling, CheckKind.DISCRETISATION)]
