"""Grasp geometry shared by the finger planners: grasp angles and the friction cone.

For two contacts on an object (paper, section 3, after Montana 1988 and Nguyen 1986): with
``d`` the vector from contact 1 to contact 2 and ``n1``, ``n2`` the object's outward normals
there, the grasp angles are

    Phi_1 = acos(-n1 . d / |d|),   Phi_2 = acos(n2 . d / |d|),

and the grasp is force closure when max(Phi_1, Phi_2) < atan(mu).

acos has an infinite slope at the antipodal optimum (Phi = 0), so the NLP never uses it:
the cone is imposed in its cosine form ``-n1 . d >= |d| cos(atan mu)`` (and likewise for
n2), and the grasp quality is measured by ``1 - cos Phi`` (~ Phi^2 / 2), smooth at 0.
``|d|`` is a safe norm (finite gradient when the contacts coincide).
"""

from __future__ import annotations

import math
from typing import Any

import casadi as ca
import numpy as np
from numpy.typing import ArrayLike, NDArray

from ocp.geometry.surfaces import safe_norm

__all__ = ["cone_cosine", "force_angles", "grasp_angles_numeric", "grasp_cosines"]

Sym = Any
FloatArray = NDArray[np.float64]


def cone_cosine(mu: float) -> float:
    """cos(atan(mu)) = 1/sqrt(1 + mu^2): the friction cone's half-angle cosine."""
    return 1.0 / math.sqrt(1.0 + mu * mu)


def grasp_cosines(p1: Sym, n1: Sym, p2: Sym, n2: Sym) -> tuple[Sym, Sym, Sym]:
    """(cos Phi_1 |d|, cos Phi_2 |d|, |d|) for contacts (p1, n1), (p2, n2) (any frame).

    Returned un-normalised so that constraints stay smooth: the cone at contact i is
    ``c_i - |d| cos(atan mu) >= 0``.
    """
    d = p2 - p1
    dist = safe_norm(d)
    return -ca.dot(n1, d), ca.dot(n2, d), dist


def grasp_angles_numeric(p1: ArrayLike, n1: ArrayLike, p2: ArrayLike, n2: ArrayLike
                         ) -> Any:
    """(Phi_1, Phi_2) [rad] for reporting (numpy, acos clipped): a pair of floats for one
    grasp, or an array (k, 2) for k grasps given as rows (k, 3) of points and normals."""
    p1, n1, p2, n2 = (np.asarray(a, dtype=float) for a in (p1, n1, p2, n2))
    d = p2 - p1
    dist = np.sqrt(np.sum(d * d, axis=-1))
    with np.errstate(divide="ignore", invalid="ignore"):
        c1 = np.clip(-np.sum(n1 * d, axis=-1) / dist, -1.0, 1.0)
        c2 = np.clip(np.sum(n2 * d, axis=-1) / dist, -1.0, 1.0)
    if d.ndim == 1:
        return math.acos(float(c1)), math.acos(float(c2))
    return np.stack([np.arccos(c1), np.arccos(c2)], axis=-1)


def force_angles(points: FloatArray, normals: FloatArray
                 ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """(Phi* (k,), per-contact force angles (k, n), grasp map onto (k,)) for contacts
    (k, n, 3) with the object's outward normals. Two contacts: the paper's grasp angles
    in closed form; three or more: :func:`~ocp.geometry.force_closure.grasp_qualities`;
    one (the object
    on the palm alone, no grasp): NaN angles, no force closure to certify."""
    n = points.shape[1]
    if n < 2:
        k = points.shape[0]
        return np.full(k, np.nan), np.full((k, n), np.nan), np.ones(k, dtype=bool)
    if n == 2:
        ang = grasp_angles_numeric(points[:, 0], normals[:, 0], points[:, 1], normals[:, 1])
        onto = np.linalg.norm(points[:, 1] - points[:, 0], axis=1) > 0
        return ang.max(axis=1), ang, onto
    from ocp.geometry.force_closure import grasp_qualities  # (it imports this module)

    qs = grasp_qualities(points, normals)
    return (np.array([q.angle for q in qs]), np.array([q.contact_angles for q in qs]),
            np.array([q.rank_ok for q in qs]))
