"""Rotations: quaternions (w, x, y, z), rotation vectors and geodesic angles, numeric and
symbolic (CasADi), shared by the motion specification, the grasp model and the certificate."""

from __future__ import annotations

import math
from typing import Any

import casadi as ca
import numpy as np
from numpy.typing import ArrayLike, NDArray

from ocp.geometry.surfaces import rotation_from_vector

__all__ = [
    "axis_angle_rotation",
    "log_rotation",
    "quaternion_matrix",
    "quaternion_rate_sym",
    "quaternion_rotation_sym",
    "quaternion_wxyz",
    "rotation_angle_between",
    "vee",
    "vee_skew",
]

FloatArray = NDArray[np.float64]


def quaternion_matrix(q: ArrayLike) -> FloatArray:
    """Rotation matrix of a quaternion (w, x, y, z) (normalised first)."""
    w, x, y, z = np.asarray(q, dtype=float) / np.linalg.norm(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def quaternion_rotation_sym(q: Any) -> Any:
    """Rotation matrix R(q / |q|) of a symbolic quaternion (w, x, y, z), its norm free."""
    n2 = ca.dot(q, q)
    w, x, y, z = q[0], q[1], q[2], q[3]
    return ca.vertcat(
        ca.horzcat(n2 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)),
        ca.horzcat(2 * (x * y + w * z), n2 - 2 * (x * x + z * z), 2 * (y * z - w * x)),
        ca.horzcat(2 * (x * z - w * y), 2 * (y * z + w * x), n2 - 2 * (x * x + y * y))) / n2


def quaternion_rate_sym(q: Any, omega: Any) -> Any:
    """d/dt q = q (x) (0, omega) / 2, omega in the body frame."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    a, b, c = omega[0], omega[1], omega[2]
    return 0.5 * ca.vertcat(-(x * a + y * b + z * c), w * a + y * c - z * b,
                            w * b + z * a - x * c, w * c + x * b - y * a)


def axis_angle_rotation(axis: ArrayLike, angle: float) -> FloatArray:
    """Rotation by ``angle`` [rad] about ``axis`` (any length)."""
    a = np.asarray(axis, dtype=float)
    return rotation_from_vector(a / np.linalg.norm(a) * angle)


def log_rotation(R: FloatArray) -> FloatArray:
    """Rotation vector of R (angle in [0, pi])."""
    c = float(np.clip((np.trace(R) - 1) / 2, -1.0, 1.0))
    angle = math.acos(c)
    v = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    if angle < 1e-9:
        return v / 2
    if math.pi - angle < 1e-6:  # axis from the symmetric part
        M = (R + np.eye(3)) / 2
        axis = M[:, int(np.argmax(np.diag(M)))]
        return axis / np.linalg.norm(axis) * angle
    return v * angle / (2 * math.sin(angle))


def rotation_angle_between(Ra: FloatArray, Rb: FloatArray) -> FloatArray:
    """Geodesic angle [rad] between stacks of rotations (k, 3, 3)."""
    tr = np.einsum("kji,kji->k", Ra, Rb)  # tr(Ra^T Rb)
    return np.arccos(np.clip((tr - 1) / 2, -1.0, 1.0))


def vee_skew(E: Any) -> Any:
    """vee((E - E^T)/2): zero for E = I, ~ the rotation vector for E near I."""
    return ca.vertcat(E[2, 1] - E[1, 2], E[0, 2] - E[2, 0], E[1, 0] - E[0, 1]) / 2


def vee(W: Any) -> Any:
    """The vector of a skew-symmetric matrix W = [w]x."""
    return ca.vertcat(W[2, 1], W[0, 2], W[1, 0])


def quaternion_wxyz(R: FloatArray) -> FloatArray:
    """Unit quaternion (w, x, y, z), w >= 0, of rotation matrices R (..., 3, 3)."""
    R = np.asarray(R, dtype=float)
    flat = R.reshape(-1, 3, 3)
    out = np.empty((flat.shape[0], 4))
    for i, m in enumerate(flat):
        tr = np.trace(m)
        if tr > 0:
            s = 2.0 * np.sqrt(tr + 1.0)
            q = [0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s,
                 (m[1, 0] - m[0, 1]) / s]
        else:
            j = int(np.argmax(np.diag(m)))
            a, b = (j + 1) % 3, (j + 2) % 3
            s = 2.0 * np.sqrt(1.0 + m[j, j] - m[a, a] - m[b, b])
            q = [0.0] * 4
            q[0] = (m[b, a] - m[a, b]) / s
            q[1 + j] = 0.25 * s
            q[1 + a] = (m[a, j] + m[j, a]) / s
            q[1 + b] = (m[b, j] + m[j, b]) / s
        qa = np.array(q)
        out[i] = qa if qa[0] >= 0 else -qa
    return out.reshape((*R.shape[:-2], 4))
