"""The capsule (:data:`CAPSULE`): a cylinder of ``radius`` r along the object's z axis,
from z = -h to z = h (``half_length`` h, as MuJoCo's capsule ``size="r h"``), closed by
two hemispheres [m].

Contacts roll on its cylinder, whose chart is f(u, v) = (r cos v, -r sin v, u): u the
height along the axis [m], v the angle [rad] ((u, v) = (0, 0) is the object's +x point).
It is orthogonal, with x = (0, 0, 1) along the axis, y = (-sin v, -cos v, 0), the normal
z = (cos v, -sin v, 0), M = diag(1, r), K = diag(0, 1/r) and T = 0. The chart ends at the
seams u = +-h, where the curvature jumps to the caps' 1/r: a contact keeps |u| <= h
(:meth:`CapsuleSurface.u_limit`); the caps are not a chart of their own yet, so no
contact rolls onto them. Everything that does not go through the chart (the support
function a certificate measures the gap with, the MuJoCo geom, the mass) is the whole
capsule's.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import casadi as ca
import numpy as np
from numpy.typing import ArrayLike, NDArray

from ocp.geometry.bodies import segments_distance_sx
from ocp.geometry.surfaces import Surface
from ocp.shapes.base import MujocoGeom, Shape

__all__ = ["CAPSULE", "CapsuleShape", "CapsuleSide", "CapsuleSurface"]

FloatArray = NDArray[np.float64]


def _cylinder_chart(u: ca.SX, v: ca.SX, params: ca.SX) -> ca.SX:
    r = params[0]
    return ca.vertcat(r * ca.cos(v), -r * ca.sin(v), u)


class CapsuleSurface(Surface):
    """The capsule's cylinder as a chart (see the module), parameters (radius,
    half_length) [m]; its support function and support points the whole capsule's."""

    chart_symmetry = "axis"
    developable = True
    ruling = (0.0, 0.0, 1.0)
    u_limit_name = "end of the capsule's cylinder (its seam with a cap) half_length [m]"

    def __init__(self) -> None:
        super().__init__("capsule", _cylinder_chart, ("radius", "half_length"),
                         (False, True), None, ("u", "v"))

    def closed_form_geometry(self, u: ca.SX, v: ca.SX, params: ca.SX
                             ) -> tuple[ca.SX, ...] | None:
        r = params[0]
        cv, sv = ca.cos(v), ca.sin(v)
        p = ca.vertcat(r * cv, -r * sv, u)
        R = ca.horzcat(ca.vertcat(0, 0, 1), ca.vertcat(-sv, -cv, 0), ca.vertcat(cv, -sv, 0))
        M = ca.diag(ca.vertcat(1, r))
        K = ca.diag(ca.vertcat(0, 1 / r))
        T = ca.horzcat(0, 0)
        return p, R, M, K, T

    def length_scale(self, params: Any) -> Any:
        """The capsule's half length, radius + half_length [m]."""
        if isinstance(params, ca.SX | ca.MX):
            return params[0] + params[1]
        return float(params[0]) + float(params[1])

    def u_limit(self, params: Sequence[float], pole_margin: float) -> float:
        """The seams: |u| <= half_length [m] (the margin is an angle of a pole chart)."""
        return float(params[1])

    def inverse(self, point: ArrayLike, params: ArrayLike) -> FloatArray:
        p = np.asarray(point, dtype=float)
        return np.stack([p[..., 2], np.arctan2(-p[..., 1], p[..., 0])], axis=-1)

    def support_height(self, normal: ArrayLike, params: ArrayLike) -> float:
        r, h = (float(x) for x in np.asarray(params, dtype=float)[:2])
        return r + h * abs(float(np.asarray(normal, dtype=float)[2]))

    def support_heights(self, normals: ArrayLike, params: ArrayLike) -> FloatArray:
        r, h = (float(x) for x in np.asarray(params, dtype=float)[:2])
        return np.asarray(r + h * np.abs(np.asarray(normals, dtype=float)[:, 2]))

    def support_point(self, direction: ArrayLike, params: ArrayLike) -> FloatArray:
        """The point of outward normal ``direction``: on a cap, or for a direction across
        the axis the middle of the cylinder's line of such points."""
        r, h = (float(x) for x in np.asarray(params, dtype=float)[:2])
        d = np.asarray(direction, dtype=float)
        d = d / np.linalg.norm(d)
        return np.asarray(r * d + np.array([0.0, 0.0, h * float(np.sign(d[2]))]))


#: The capsule's cylinder chart.
CapsuleSide: Surface = CapsuleSurface()


class CapsuleShape(Shape):
    """A capsule: ``dimensions`` (radius, half_length) [m], its axis the object's z."""

    name = "capsule"
    description = ("[radius, half_length]: a cylinder along its z axis from -half_length to "
                   "half_length, closed by hemispheres (MuJoCo's capsule size) [m]")
    parameters = ("radius", "half_length")

    def surface(self, dimensions: Sequence[float]) -> Surface:
        return CapsuleSide

    def surfaces(self) -> tuple[Surface, ...]:
        return (CapsuleSide,)

    def count_error(self, dimensions: Sequence[float]) -> str | None:
        if len(dimensions) != 2:
            return f"a capsule has 2 dimensions (radius, half_length), got {len(dimensions)}"
        return None

    def semi_axes(self, dimensions: Sequence[float]) -> tuple[float, float, float]:
        r, h = (float(x) for x in dimensions[:2])
        return (r, r, h + r)

    def volume(self, dimensions: Sequence[float]) -> float:
        r, h = (float(x) for x in dimensions[:2])
        return math.pi * r * r * 2.0 * h + 4.0 / 3.0 * math.pi * r**3

    def inertia(self, dimensions: Sequence[float], mass: float
                ) -> tuple[float, float, float]:
        """The cylinder's and the two hemispheres' (each about its own centroid, 3 r / 8
        from its flat face, moved to the capsule's centre) [kg m^2]."""
        r, h = (float(x) for x in dimensions[:2])
        cyl = math.pi * r * r * 2.0 * h
        caps = 4.0 / 3.0 * math.pi * r**3
        m_c, m_s = mass * cyl / (cyl + caps), mass * caps / (cyl + caps)
        axial = m_c * r * r / 2.0 + m_s * 2.0 * r * r / 5.0
        side = m_c * (r * r / 4.0 + h * h / 3.0) + m_s * (2.0 * r * r / 5.0 + h * h
                                                          + 3.0 * h * r / 4.0)
        return (side, side, axial)

    def mujoco_geom(self, dimensions: Sequence[float]) -> MujocoGeom:
        r, h = (float(x) for x in dimensions[:2])
        return MujocoGeom("capsule", (r, h))

    def viewer(self, dimensions: Sequence[float]) -> dict[str, Any]:
        r, h = (float(x) for x in dimensions[:2])
        return {"kind": "capsule", "radius": r, "length": 2.0 * h}

    def nearest(self, dimensions: Sequence[float], points: ArrayLike
                ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """The axis's nearest point s (|z| clamped to h), the normal along the point's
        offset from it, the distance that offset's length less r."""
        r, h = (float(x) for x in dimensions[:2])
        P = np.atleast_2d(np.asarray(points, dtype=float))
        S = np.zeros_like(P)
        S[:, 2] = np.clip(P[:, 2], -h, h)
        d = P - S
        dist = np.linalg.norm(d, axis=1)
        n = d / dist[:, None]
        return S + r * n, n, dist - r

    def clearance_params(self, dimensions: Sequence[float]) -> tuple[float, ...]:
        return (float(dimensions[0]), float(dimensions[1]))

    def segment_clearance(self, params: Any, a: Any, b: Any) -> Any:
        """The segment's distance from the axis less r: exact."""
        h = params[1]
        return segments_distance_sx(a, b, ca.vertcat(0, 0, -h), ca.vertcat(0, 0, h)) \
            - params[0]


CAPSULE = CapsuleShape()
