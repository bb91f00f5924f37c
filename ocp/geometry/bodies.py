"""A fingertip's body for clearance: the segment its surface is swept around.

A round fingertip is a sphere (a segment of zero length) or a capsule, whose cap is the
contact surface (:mod:`ocp.geometry.tips`: the capsule's axis points out of the cap along
the tip frame's -y, so its cylinder runs from the cap's centre along +y, ``2 half_length``
long). The distance between two such bodies, or between one and a ball, is the distance
between their segments (a ball's: its centre) less the radii: exact for spheres and
capsules. Numeric (numpy, for the certificate) and symbolic (CasADi, for the swing's NLP).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np
from numpy.typing import NDArray

__all__ = ["TipBody", "point_segment_distance", "points_segment_distance", "segment_distance",
           "segments_distance", "tip_body"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class TipBody:
    """A fingertip's body in its link frame: the segment from ``a`` (the cap's centre,
    where contacts are) to ``b`` [m], swept by a sphere of radius ``r`` [m]."""

    a: FloatArray
    b: FloatArray
    r: float

    def placed(self, R: Any, p: Any) -> tuple[Any, Any]:
        """The segment's ends in the palm frame at the link pose (R, p) (numpy or CasADi)."""
        if isinstance(R, np.ndarray):
            return p + R @ self.a, p + R @ self.b
        return p + R @ ca.DM(self.a), p + R @ ca.DM(self.b)


def tip_body(finger: Any) -> TipBody:
    """A sphere or capsule fingertip's body; ValueError for the others (a flat pad or a
    spheroid has no clearance model: finger gaiting needs round tips)."""
    tip = finger.tip_surface
    if tip.kind == "sphere":
        return TipBody(tip.p, tip.p, float(tip.params[0]))
    if tip.kind == "capsule":
        half = float(tip.extra[0]) if tip.extra else 0.0
        return TipBody(tip.p, tip.p + 2.0 * half * tip.R[:, 1], float(tip.params[0]))
    raise ValueError(f"a {tip.kind} fingertip has no clearance model: finger gaiting "
                     "needs sphere or capsule tips")


def point_segment_distance(x: Any, a: Any, b: Any) -> Any:
    """Distance from the point x to the segment a-b (numpy or CasADi; a == b allowed)."""
    if isinstance(x, np.ndarray) and isinstance(a, np.ndarray):
        d = b - a
        dd = float(d @ d)
        s = 0.0 if dd <= 0.0 else float(np.clip((x - a) @ d / dd, 0.0, 1.0))
        return float(np.linalg.norm(x - (a + s * d)))
    d = b - a
    dd = ca.dot(d, d)
    s = ca.if_else(dd > 1e-18, ca.fmin(ca.fmax(ca.dot(x - a, d) / ca.fmax(dd, 1e-18), 0.0),
                                        1.0), 0.0)
    e = x - (a + s * d)
    return ca.sqrt(ca.dot(e, e) + 1e-18)


def segment_distance(a0: FloatArray, b0: FloatArray, a1: FloatArray, b1: FloatArray) -> float:
    """Distance between the segments a0-b0 and a1-b1 (numpy; a point is a segment of
    zero length): :func:`segments_distance` of one pair."""
    return float(segments_distance(*(np.asarray(v, dtype=float)[None] for v in
                                     (a0, b0, a1, b1)))[0])


def segments_distance(a0: FloatArray, b0: FloatArray, a1: FloatArray, b1: FloatArray
                      ) -> FloatArray:
    """Distances between segments, pairwise over rows (numpy, ``(k, 3)`` each): the closest
    points' parameters solved in closed form and clamped to the segments (Ericson, *Real-Time
    Collision Detection*, 5.1.9), zero-length segments included."""
    d1, d2, r = b0 - a0, b1 - a1, a0 - a1
    a = np.einsum("ij,ij->i", d1, d1)
    e = np.einsum("ij,ij->i", d2, d2)
    f = np.einsum("ij,ij->i", d2, r)
    c = np.einsum("ij,ij->i", d1, r)
    b = np.einsum("ij,ij->i", d1, d2)
    eps = 1e-18
    safe_a, safe_e = np.maximum(a, eps), np.maximum(e, eps)
    denom = a * e - b * b
    s = np.where(denom > eps * np.maximum(a * e, eps),
                 np.clip((b * f - c * e) / np.where(denom > 0, denom, 1.0), 0.0, 1.0), 0.0)
    s = np.where(a <= eps, 0.0, np.where(e <= eps, np.clip(-c / safe_a, 0.0, 1.0), s))
    t = np.where(e <= eps, 0.0, (b * s + f) / safe_e)
    low, high = t < 0.0, t > 1.0
    s = np.where(a <= eps, s, np.where(low, np.clip(-c / safe_a, 0.0, 1.0),
                                       np.where(high, np.clip((b - c) / safe_a, 0.0, 1.0), s)))
    t = np.clip(t, 0.0, 1.0)
    gap = a0 + s[:, None] * d1 - a1 - t[:, None] * d2
    return np.linalg.norm(gap, axis=1)


def segments_distance_sx(a0: Any, b0: Any, a1: Any, b1: Any) -> Any:
    """The distance between the segments a0-b0 and a1-b1 as a CasADi expression: the
    closest points of :func:`segments_distance` (the same clamped closed form), the first
    segment possibly a point, the second not."""
    d1, d2, r = b0 - a0, b1 - a1, a0 - a1
    a = ca.dot(d1, d1)
    e = ca.dot(d2, d2)
    f = ca.dot(d2, r)
    c = ca.dot(d1, r)
    b = ca.dot(d1, d2)
    eps = 1e-18
    safe_a = ca.fmax(a, eps)
    denom = a * e - b * b

    def clip(x: Any) -> Any:
        return ca.fmin(ca.fmax(x, 0.0), 1.0)

    s = ca.if_else(denom > eps * ca.fmax(a * e, eps), clip((b * f - c * e) /
                                                           ca.fmax(denom, eps)), 0.0)
    s = ca.if_else(a <= eps, 0.0, s)
    t = (b * s + f) / e
    s = ca.if_else(a <= eps, s, ca.if_else(t < 0.0, clip(-c / safe_a),
                                           ca.if_else(t > 1.0, clip((b - c) / safe_a), s)))
    t = clip(t)
    gap = a0 + s * d1 - a1 - t * d2
    return ca.sqrt(ca.dot(gap, gap) + 1e-18)


def points_segment_distance(x: FloatArray, a: FloatArray, b: FloatArray) -> FloatArray:
    """Distances from the points x (rows) to the segment a-b (numpy)."""
    d = b - a
    dd = float(d @ d)
    s = np.zeros(len(x)) if dd <= 0.0 else np.clip((x - a) @ d / dd, 0.0, 1.0)
    return np.linalg.norm(x - (a + s[:, None] * d), axis=1)
