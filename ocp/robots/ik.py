"""Inverse kinematics of a finger (:class:`~ocp.robots.finger.FingerModel`): one fingertip
pose by Levenberg-Marquardt within the joint limits (:func:`inverse_kinematics`), many
nearby poses at once by damped Gauss-Newton (:func:`inverse_kinematics_batch`).

Re-exported by :mod:`ocp.robots.finger`, where they were first written.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike, NDArray

from ocp.robots.arrays import readonly as _readonly
from ocp.robots.arrays import rotation as _rotation
from ocp.robots.arrays import vector3 as _vector3

if TYPE_CHECKING:
    from ocp.robots.finger import FingerModel

__all__ = ["IKResult", "inverse_kinematics", "inverse_kinematics_batch"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class IKResult:
    """Outcome of :func:`inverse_kinematics`.

    ``q`` the joint angles found [rad or m]; ``position_error`` |p(q) - p_target| [m];
    ``orientation_error`` |log3(R_target^T R(q))| [rad]; ``converged`` whether both are
    <= tol; ``within_limits`` whether q is within the joint limits; ``iterations`` the
    number of Levenberg-Marquardt trials made.
    """

    q: FloatArray
    position_error: float
    orientation_error: float
    converged: bool
    within_limits: bool
    iterations: int


def _residual(finger: FingerModel, data: Any, q: FloatArray, R_t: FloatArray,
              p_t: FloatArray) -> tuple[FloatArray, FloatArray, float, float]:
    """Scaled pose residual r = ((p - p_t)/L, log3(R_t^T R)), its Jacobian, both errors."""
    R, p = finger._pose_pin(q, data)
    J = finger._jacobian_pin(q, data)
    e_p = p - p_t
    R_err = R_t.T @ R
    e_r = np.asarray(pin.log3(R_err), dtype=float)
    # d log3(R_t^T R) = Jlog3(R_err) omega_local, omega_local = R^T omega_palm
    J_r = np.asarray(pin.Jlog3(R_err)) @ R.T @ J[3:]
    L = finger.length_scale
    r = np.concatenate([e_p / L, e_r])
    Jr = np.vstack([J[:3] / L, J_r])
    return r, Jr, float(np.linalg.norm(e_p)), float(np.linalg.norm(e_r))


def _lm_step(H: FloatArray, g: FloatArray, lam: float, q: FloatArray, lower: FloatArray,
             upper: FloatArray) -> FloatArray:
    """Damped Gauss-Newton step, with the joints that sit at a limit and would leave the
    box held fixed (the step is re-solved for the others)."""
    n = q.size
    free = np.ones(n, dtype=bool)
    dq = np.zeros(n)
    for _ in range(n + 1):
        dq = np.zeros(n)
        idx = np.flatnonzero(free)
        if idx.size == 0:
            break
        A = H[np.ix_(idx, idx)] + lam * np.eye(idx.size)
        dq[idx] = -np.linalg.solve(A, g[idx])
        blocked = free & (((q <= lower) & (dq < 0.0)) | ((q >= upper) & (dq > 0.0)))
        if not blocked.any():
            break
        free &= ~blocked
    return dq


def inverse_kinematics(
    finger: FingerModel,
    R_target: ArrayLike,
    p_target: ArrayLike,
    q_seed: ArrayLike,
    tol: float = 1e-10,
    max_iter: int = 200,
) -> IKResult:
    """Joint angles putting the fingertip frame at (R_target, p_target) in the palm frame.

    Levenberg-Marquardt on the 6-D pose error ``((p - p_target) / L, log3(R_target^T R))``
    (L = :attr:`FingerModel.length_scale` [m]) with Pinocchio's frame Jacobian and the
    exact Jacobian of log3, starting from ``q_seed`` (clipped into the limits); every step
    is projected onto the joint limits, joints pinned at a limit are held there. The
    damping shrinks after a step that lowers the error and grows after one that does not.
    Stops when both errors are <= ``tol`` (m and rad), after ``max_iter`` trials, or when
    no step lowers the error any more (an unreachable target: ``converged`` False, no
    exception). Deterministic.
    """
    R_t = _rotation(R_target, "R_target")
    p_t = _vector3(p_target, "p_target")
    q = np.clip(finger._check_q(q_seed), finger.lower, finger.upper)
    if not np.all(np.isfinite(q)):
        raise ValueError("q_seed must be finite")
    data = finger.model.createData()
    r, Jr, e_pos, e_rot = _residual(finger, data, q, R_t, p_t)
    cost = 0.5 * float(r @ r)
    H = Jr.T @ Jr
    lam = 1e-3 * max(float(np.max(np.diag(H))), 1e-12)
    lam_min, lam_max = 1e-14, 1e10
    iterations = 0
    while iterations < max_iter and not (e_pos <= tol and e_rot <= tol):
        iterations += 1
        g = Jr.T @ r
        dq = _lm_step(H, g, lam, q, finger.lower, finger.upper)
        q_new = np.clip(q + dq, finger.lower, finger.upper)
        r_new, Jr_new, e_pos_new, e_rot_new = _residual(finger, data, q_new, R_t, p_t)
        cost_new = 0.5 * float(r_new @ r_new)
        if cost_new < cost:
            q, r, Jr, e_pos, e_rot, cost = q_new, r_new, Jr_new, e_pos_new, e_rot_new, cost_new
            H = Jr.T @ Jr
            lam = max(lam / 10.0, lam_min)
        else:
            lam *= 10.0
            if lam > lam_max:
                break
    return IKResult(
        q=_readonly(q),
        position_error=e_pos,
        orientation_error=e_rot,
        converged=bool(e_pos <= tol and e_rot <= tol),
        within_limits=bool(np.all(q >= finger.lower) and np.all(q <= finger.upper)),
        iterations=iterations,
    )


def inverse_kinematics_batch(
    finger: FingerModel,
    R_targets: ArrayLike,
    p_targets: ArrayLike,
    q_seed: ArrayLike,
    tol: float = 1e-10,
    max_iter: int = 30,
) -> tuple[FloatArray, NDArray[np.bool_]]:
    """Joint angles for many fingertip poses at once: (q (k, nq), converged (k,)).

    Damped Gauss-Newton on every target together (the CasADi forward kinematics and
    Jacobian evaluated for all k at once, k small linear systems solved as one batch),
    each started from ``q_seed`` ((nq,) for all, or (k, nq)) and kept inside the joint
    limits. The pose error is the position error and the rotation vector of
    ``R_target R^T`` in the palm frame. A target is converged when both errors are
    <= ``tol`` (m and rad) within the limits; the others are left to the caller (e.g.
    :func:`inverse_kinematics` from a neighbour's solution). Meant for the many nearby
    poses along a motion, where every target is a few steps from the seed.
    """
    R_t = np.asarray(R_targets, dtype=float).reshape(-1, 3, 3)
    p_t = np.asarray(p_targets, dtype=float).reshape(-1, 3)
    k, nq = len(R_t), finger.nq
    q = np.clip(np.broadcast_to(np.asarray(q_seed, dtype=float), (k, nq)).copy(),
                finger.lower, finger.upper)
    L = finger.length_scale
    scale = np.array([1 / L] * 3 + [1.0] * 3)
    done = np.zeros(k, dtype=bool)
    for it in range(max_iter + 1):
        R_, p_ = finger.fk(q.T)
        R = np.asarray(R_).reshape(3, k, 3).transpose(1, 0, 2)  # (k, 3, 3)
        e_p = p_t - np.asarray(p_).T
        E = R_t @ R.transpose(0, 2, 1)  # rotation from the current pad to the target
        e_r = np.array([pin.log3(Ek) for Ek in E]).reshape(k, 3)
        err_p, err_r = np.linalg.norm(e_p, axis=1), np.linalg.norm(e_r, axis=1)
        done = (err_p <= tol) & (err_r <= tol)
        if done.all() or it == max_iter:
            break
        J = np.asarray(finger.jacobian(q.T)).reshape(6, k, nq).transpose(1, 0, 2)
        J = J * scale[None, :, None]
        e = np.concatenate([e_p, e_r], axis=1) * scale
        H = J.transpose(0, 2, 1) @ J + 1e-9 * np.eye(nq)
        g = np.einsum("kij,ki->kj", J, e)
        dq = np.linalg.solve(H, g[..., None])[..., 0]
        dq[done] = 0.0
        q = np.clip(q + dq, finger.lower, finger.upper)
    return q, done

