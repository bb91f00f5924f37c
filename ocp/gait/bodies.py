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
           "tip_body"]

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


def segment_distance(a0: FloatArray, b0: FloatArray, a1: FloatArray, b1: FloatArray,
                     samples: int = 41) -> float:
    """Distance between two segments (numpy): the least point-segment distance over
    ``samples`` points of the first and its ends' projections (exact to (step)^2 / 8r of
    the bodies' curvature, below 0.1 um for fingertip capsules)."""
    s = np.linspace(0.0, 1.0, samples)[:, None]
    best = float(points_segment_distance(a0 + s * (b0 - a0), a1, b1).min())
    return min(best, float(points_segment_distance(np.array([a1, b1]), a0, b0).min()))


def points_segment_distance(x: FloatArray, a: FloatArray, b: FloatArray) -> FloatArray:
    """Distances from the points x (rows) to the segment a-b (numpy)."""
    d = b - a
    dd = float(d @ d)
    s = np.zeros(len(x)) if dd <= 0.0 else np.clip((x - a) @ d / dd, 0.0, 1.0)
    return np.linalg.norm(x - (a + s[:, None] * d), axis=1)
