"""The ellipsoid (:data:`ELLIPSOID`): of revolution about its z axis, ``dimensions``
(a, c) (semi-axes a, a, c; the chart :data:`ocp.geometry.surfaces.Ellipsoid`), or with
three semi-axes (a, b, c) [m] along the body's x, y, z (the surface below).

Its latitude/longitude chart f = (a cos u cos v, -b cos u sin v, c sin u) is not orthogonal
when a != b (f_u . f_v = (a^2 - b^2) sin u cos u sin v cos v), so its geometry is the
general one of :mod:`ocp.geometry.surfaces`: M upper triangular. With
Q = diag(a^2, b^2, c^2), the outward normal is along Q^-1 p, the support function is
h(n) = sqrt(n^T Q n) and the point of outward normal d is Q d / sqrt(d^T Q d).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import casadi as ca
import numpy as np
from numpy.typing import ArrayLike, NDArray

from ocp.geometry.bodies import point_segment_distance
from ocp.geometry.surfaces import Ellipsoid, Surface, latitude_longitude
from ocp.shapes.base import MujocoGeom, Shape

__all__ = ["ELLIPSOID", "EggSide", "EggSideSurface", "EllipsoidShape", "TriaxialEllipsoid",
           "TriaxialEllipsoidSurface"]

FloatArray = NDArray[np.float64]

#: Relative tolerance on R Q R^T = Q for a patch rotation R to map the body to itself.
_SYMMETRY_RTOL = 1e-9


def _triaxial_chart(u: ca.SX, v: ca.SX, params: ca.SX) -> ca.SX:
    a, b, c = params[0], params[1], params[2]
    return ca.vertcat(a * ca.cos(u) * ca.cos(v), -b * ca.cos(u) * ca.sin(v), c * ca.sin(u))


def _triaxial_geometry(u: ca.SX, v: ca.SX, a: ca.SX, b: ca.SX, c: ca.SX
                       ) -> tuple[ca.SX, ...]:
    """(p, R, M, K, T) of the chart f = (a cos u cos v, -b cos u sin v, c sin u) for
    |u| < pi/2, in closed form. With E = |f_u|, N = Q^-1 f = (cos u cos v / a,
    -cos u sin v / b, sin u / c) (the outward normal's direction) and G = |N|:
    x = f_u / E, z = N / G, y = z x x; M = [[E, x.f_v], [0, y.f_v]] [m];
    K = [x y]^T Q^-1 [x y] / G [1/m] (the normal's derivative along a tangent t is
    (I - z z^T) Q^-1 t / G); T = [y.f_uu, y.f_uv] M^-1 / E [1/m] (y is normal to f_u),
    with f_uu = -f and f_uv = (a sin u sin v, b sin u cos v, 0)."""
    cu, su, cv, sv = ca.cos(u), ca.sin(u), ca.cos(v), ca.sin(v)
    p = ca.vertcat(a * cu * cv, -b * cu * sv, c * su)
    f_u = ca.vertcat(-a * su * cv, b * su * sv, c * cu)
    f_v = ca.vertcat(-a * cu * sv, -b * cu * cv, 0)
    f_uv = ca.vertcat(a * su * sv, b * su * cv, 0)
    q_inv = ca.vertcat(1 / a**2, 1 / b**2, 1 / c**2)
    E = ca.norm_2(f_u)
    N = ca.vertcat(cu * cv / a, -cu * sv / b, su / c)
    G = ca.norm_2(N)
    x = f_u / E
    z = N / G
    y = ca.cross(z, x)
    m_uv, m_v = ca.dot(x, f_v), ca.dot(y, f_v)
    R = ca.horzcat(x, y, z)
    M = ca.SX(ca.Sparsity.upper(2), ca.vertcat(E, m_uv, m_v))
    k_xy = ca.dot(x, q_inv * y) / G
    K = ca.vertcat(ca.horzcat(ca.dot(x, q_inv * x) / G, k_xy),
                   ca.horzcat(k_xy, ca.dot(y, q_inv * y) / G))
    t_u = -ca.dot(y, p) / E
    t_v = ca.dot(y, f_uv) / E
    T = ca.horzcat(t_u / E, (t_v - t_u * m_uv / E) / m_v)
    return p, R, M, K, T


class TriaxialEllipsoidSurface(Surface):
    """Ellipsoid with semi-axes (a, b, c) [m] along the body's x, y, z axes.

    f = (a cos u cos v, -b cos u sin v, c sin u): (u, v) = (0, 0) is the +x point, the
    poles u = +-pi/2 are on the z axis (as the sphere's and the spheroid's charts). The
    chart is not orthogonal for a != b, so its geometry has an upper triangular metric.
    Its patch may only be turned by rotations that map the ellipsoid to itself: the
    half turns about its axes (and, for equal semi-axes, the turns about the third).
    """

    orthogonal = False
    chart_symmetry = "axes"

    def __init__(self) -> None:
        super().__init__("triaxial_ellipsoid", _triaxial_chart,
                         ("semi_axis_x", "semi_axis_y", "semi_axis_z"), (False, True),
                         np.pi / 2, ("u", "v"))

    def closed_form_geometry(self, u: ca.SX, v: ca.SX, params: ca.SX
                             ) -> tuple[ca.SX, ...] | None:
        return _triaxial_geometry(u, v, params[0], params[1], params[2])

    def chart_rotation_error(self, rotation: ArrayLike,
                             params: Sequence[float] | None = None) -> str | None:
        """None when ``rotation`` maps the ellipsoid to itself: R Q R^T = Q to 1e-9
        relative, Q = diag(a^2, b^2, c^2). Without ``params`` (or with other than three)
        the semi-axes are taken as distinct: only the half turns about the axes (and the
        identity) pass."""
        R = np.asarray(rotation, dtype=float).reshape(3, 3)
        if not np.allclose(R.T @ R, np.eye(3), atol=1e-9) or np.linalg.det(R) < 0:
            return "not a rotation"
        known = params is not None and len(params) == 3
        axes = np.asarray(params, dtype=float) if known else np.array([1.0, 2.0, 3.0])
        Q = np.diag(axes**2)
        if np.max(np.abs(R @ Q @ R.T - Q)) <= _SYMMETRY_RTOL * np.max(Q):
            return None
        return (f"a {self.name}'s chart patch can only be turned by a rotation that maps "
                "it to itself (a half turn about one of its axes): any other rotation "
                f"would describe a different, rotated {self.name}")

    def inverse(self, point: ArrayLike, params: ArrayLike) -> FloatArray:
        p = np.asarray(point, dtype=float)
        a, b, c = np.asarray(params, dtype=float)
        x, y, z = p[..., 0] / a, p[..., 1] / b, p[..., 2] / c
        return np.stack([np.arctan2(z, np.hypot(x, y)), np.arctan2(-y, x)], axis=-1)

    def inverse_expr(self, point: Any, params: Any) -> Any:
        return latitude_longitude(point, params[0], params[1], params[2])

    def support_height(self, normal: ArrayLike, params: ArrayLike) -> float:
        n = np.asarray(normal, dtype=float)
        q = np.asarray(params, dtype=float) ** 2
        return float(np.sqrt(np.sum(q * n * n)))

    def support_heights(self, normals: ArrayLike, params: ArrayLike) -> FloatArray:
        n = np.asarray(normals, dtype=float)
        return np.asarray(np.sqrt(n**2 @ np.asarray(params, dtype=float) ** 2))

    def support_point(self, direction: ArrayLike, params: ArrayLike) -> FloatArray:
        d = np.asarray(direction, dtype=float)
        q = np.asarray(params, dtype=float) ** 2
        return np.asarray(q * d / np.sqrt(np.sum(q * d * d)))


#: Triaxial ellipsoid (a, b, c) (latitude u, longitude v).
TriaxialEllipsoid: Surface = TriaxialEllipsoidSurface()


#: The side chart's frame in the body's (a rotation): its x (the chart's c axis) along
#: the body's -z, the egg's axis; its y the body's y; its z, the poles, along the body's x.
_SIDE = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])


def _side_chart(u: ca.SX, v: ca.SX, params: ca.SX) -> ca.SX:
    a, c = params[0], params[1]
    return ca.mtimes(ca.DM(_SIDE), _triaxial_chart(u, v, ca.vertcat(c, a, a)))


class EggSideSurface(Surface):
    """An ellipsoid of revolution (a, a, c) charted from its side: the triaxial chart of
    semi-axes (c, a, a) turned so that its poles lie on the body's x axis, on the
    equator, and its own equator (u = 0) is the ellipse through the ends (0, 0, +-c) in
    the body's y-z plane. Parameters (a, c), as :data:`~ocp.geometry.surfaces.Ellipsoid`.
    Its patch turns about the body's z (the egg's axis), so a contact anywhere on the
    egg, its ends included, is put on that patch's equator (``ObjectSpec.side_chart``;
    docs/shapes.md, "Charts"): the chart a gait's roll takes when a contact has rolled
    toward an end, where the egg's own chart has its poles."""

    orthogonal = False
    chart_symmetry = "axis"

    def __init__(self) -> None:
        super().__init__("ellipsoid_side", _side_chart,
                         ("equatorial_semi_axis", "polar_semi_axis"), (False, True),
                         np.pi / 2, ("u", "v"))

    def closed_form_geometry(self, u: ca.SX, v: ca.SX, params: ca.SX
                             ) -> tuple[ca.SX, ...] | None:
        a, c = params[0], params[1]
        p, R, M, K, T = _triaxial_geometry(u, v, c, a, a)
        side = ca.DM(_SIDE)
        return ca.mtimes(side, p), ca.mtimes(side, R), M, K, T

    def inverse(self, point: ArrayLike, params: ArrayLike) -> FloatArray:
        a, c = np.asarray(params, dtype=float)
        g = np.asarray(point, dtype=float) @ _SIDE  # (the chart frame's coordinates)
        return np.asarray(TriaxialEllipsoid.inverse(g, (c, a, a)))

    def inverse_expr(self, point: Any, params: Any) -> Any:
        g = ca.mtimes(ca.DM(_SIDE.T), point)
        return latitude_longitude(g, params[1], params[0], params[0])

    def support_height(self, normal: ArrayLike, params: ArrayLike) -> float:
        return Ellipsoid.support_height(normal, params)

    def support_heights(self, normals: ArrayLike, params: ArrayLike) -> FloatArray:
        return Ellipsoid.support_heights(normals, params)

    def support_point(self, direction: ArrayLike, params: ArrayLike) -> FloatArray:
        return Ellipsoid.support_point(direction, params)

    def axis_patch(self, point: ArrayLike) -> FloatArray:
        """The patch (a turn about the body's z) that puts the body point ``point`` on
        this chart's equator: its poles across the point's azimuth."""
        p = np.asarray(point, dtype=float).reshape(3)
        b = math.atan2(p[1], p[0]) - math.pi / 2
        return np.array([[math.cos(b), -math.sin(b), 0.0], [math.sin(b), math.cos(b), 0.0],
                         [0.0, 0.0, 1.0]])


#: The egg's side chart.
EggSide: Surface = EggSideSurface()


class EllipsoidShape(Shape):
    """An ellipsoid: ``dimensions`` (a, c), of revolution about its z axis (semi-axes
    a, a, c: the chart :data:`ocp.geometry.surfaces.Ellipsoid`), or (a, b, c) along its
    x, y, z axes (:data:`TriaxialEllipsoid`, a chart that is not orthogonal)."""

    name = "ellipsoid"
    description = ("[a, c]: semi-axes a, a, c, of revolution about its z axis; or [a, b, c]: "
                   "the semi-axes along its x, y, z axes [m]")
    parameters = ("semi_axis_x", "semi_axis_y", "semi_axis_z")

    def surface(self, dimensions: Sequence[float]) -> Surface:
        return Ellipsoid if len(dimensions) == 2 else TriaxialEllipsoid

    def surfaces(self) -> tuple[Surface, ...]:
        return (Ellipsoid, TriaxialEllipsoid, EggSide)

    def side_surface(self, dimensions: Sequence[float]) -> Surface | None:
        """An ellipsoid of revolution's side chart (:data:`EggSide`); a triaxial one has
        none (no patch of it turns freely about an axis)."""
        return EggSide if len(dimensions) == 2 else None

    def count_error(self, dimensions: Sequence[float]) -> str | None:
        if len(dimensions) not in (2, 3):
            return (f"an ellipsoid has 2 dimensions (a, c: of revolution about z) or 3 "
                    f"(a, b, c), got {len(dimensions)}")
        return None

    def semi_axes(self, dimensions: Sequence[float]) -> tuple[float, float, float]:
        d = [float(x) for x in dimensions]
        return (d[0], d[0], d[1]) if len(d) == 2 else (d[0], d[1], d[2])

    def volume(self, dimensions: Sequence[float]) -> float:
        a, b, c = self.semi_axes(dimensions)
        return 4.0 / 3.0 * math.pi * a * b * c

    def inertia(self, dimensions: Sequence[float], mass: float
                ) -> tuple[float, float, float]:
        a, b, c = self.semi_axes(dimensions)
        if len(dimensions) == 2:  # of revolution: the moments as they were always written
            side = mass * (a * a + c * c) / 5
            return (side, side, 2 * mass * a * a / 5)
        return (mass * (b * b + c * c) / 5, mass * (a * a + c * c) / 5,
                mass * (a * a + b * b) / 5)

    def mujoco_geom(self, dimensions: Sequence[float]) -> MujocoGeom:
        return MujocoGeom("ellipsoid", self.semi_axes(dimensions))

    def viewer(self, dimensions: Sequence[float]) -> dict[str, Any]:
        return {"kind": "ellipsoid", "semi_axes": list(self.semi_axes(dimensions))}

    def nearest(self, dimensions: Sequence[float], points: ArrayLike
                ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """The nearest point x_i = a_i^2 p_i / (a_i^2 + t) of each point p, t the root of
        f(t) = sum (a_i p_i / (a_i^2 + t))^2 - 1 in (-a_min^2, inf) (f convex and
        decreasing there: Newton from a t with f(t) >= 0 -- 0 outside, else
        -a_min^2 + a_min |p_min| -- climbs to it monotonically), to 1e-15 of a_min^2."""
        ax = np.asarray(self.semi_axes(dimensions), dtype=float)
        a_min = float(ax.min())
        A = (ax / a_min)[None, :]  # in units of a_min
        P = np.atleast_2d(np.asarray(points, dtype=float)) / a_min
        if len(P) == 1:  # one point (a gait's fingertip at a time): the same steps in floats
            return _nearest_one(A[0].tolist(), P[0].tolist(), int(np.argmin(ax)), a_min)
        outside = np.sum((P / A) ** 2, axis=1) > 1.0
        k = int(np.argmin(ax))
        t = np.where(outside, 0.0, -1.0 + np.maximum(np.abs(P[:, k]), 1e-12))
        for _ in range(100):
            w = A * P / (A * A + t[:, None])
            f = np.sum(w * w, axis=1) - 1.0
            df = -2.0 * np.sum(w * w / (A * A + t[:, None]), axis=1)
            step = f / df
            t = t - step
            if float(np.max(np.abs(step))) < 1e-15:
                break
        X = A * A * P / (A * A + t[:, None])
        g = X / (A * A)
        n = g / np.linalg.norm(g, axis=1)[:, None]
        dist = np.linalg.norm(P - X, axis=1) * np.where(outside, 1.0, -1.0)
        return X * a_min, n, dist * a_min

    def clearance_params(self, dimensions: Sequence[float]) -> tuple[float, ...]:
        return self.semi_axes(dimensions)

    def segment_clearance(self, params: Any, a: Any, b: Any) -> Any:
        """a_min (|diag(1/a_i) x| - 1) at the segment's point least in that norm (a
        point-segment distance in the scaled space): diag(1/a_i) shrinks lengths by at
        most 1/a_min, so a point at |diag(1/a) x| = s > 1 is at least a_min (s - 1) from
        the surface (exact for a ball; 0.75 of the distance at an egg's poles)."""
        inv = 1.0 / params[0:3]
        least = ca.fmin(params[0], ca.fmin(params[1], params[2]))
        return least * (point_segment_distance(ca.DM.zeros(3), inv * a, inv * b) - 1.0)


def _nearest_one(A: list[float], P: list[float], k: int, a_min: float
                 ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """:meth:`EllipsoidShape.nearest` of one point ``P`` (semi-axes ``A``, both in units
    of ``a_min``; ``k`` the least semi-axis): its operations in the same order on Python
    floats (the same bits; numpy's per-call cost was most of a gait's nearest points)."""
    a0, a1, a2 = A
    p0, p1, p2 = P
    q0, q1, q2 = p0 / a0, p1 / a1, p2 / a2
    outside = q0 * q0 + q1 * q1 + q2 * q2 > 1.0
    t = 0.0 if outside else -1.0 + max(abs(P[k]), 1e-12)
    s0, s1, s2 = a0 * a0, a1 * a1, a2 * a2
    for _ in range(100):
        d0, d1, d2 = s0 + t, s1 + t, s2 + t
        w0, w1, w2 = a0 * p0 / d0, a1 * p1 / d1, a2 * p2 / d2
        f = w0 * w0 + w1 * w1 + w2 * w2 - 1.0
        df = -2.0 * (w0 * w0 / d0 + w1 * w1 / d1 + w2 * w2 / d2)
        step = f / df
        t = t - step
        if abs(step) < 1e-15:
            break
    x0, x1, x2 = s0 * p0 / (s0 + t), s1 * p1 / (s1 + t), s2 * p2 / (s2 + t)
    g0, g1, g2 = x0 / s0, x1 / s1, x2 / s2
    gn = math.sqrt(g0 * g0 + g1 * g1 + g2 * g2)
    e0, e1, e2 = p0 - x0, p1 - x1, p2 - x2
    dist = math.sqrt(e0 * e0 + e1 * e1 + e2 * e2) * (1.0 if outside else -1.0)
    return (np.array([[x0 * a_min, x1 * a_min, x2 * a_min]]),
            np.array([[g0 / gn, g1 / gn, g2 / gn]]), np.array([dist * a_min]))


ELLIPSOID = EllipsoidShape()
