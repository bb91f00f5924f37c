"""The superellipsoid (:data:`SUPERELLIPSOID`): a box with rounded edges and corners, all
smooth, |x/a|^n + |y/b|^n + |z/c|^n = 1 with half sides (a, b, c) [m].

A request gives ``dimensions`` (a, b, c, edge_radius) [m]: the exponent n is the one whose
edge between two faces of the smallest half side s has the radius of curvature
``edge_radius`` at its middle, sqrt(2) s 2^(-1/n) / (n - 1) (a cube's every edge; n = 2 is
the ellipsoid, whose "edge radius" is s). The surface's parameters are (a, b, c, n).

Its chart is radial over the sphere's latitude/longitude directions:
d(u, v) = (cos u cos v, -cos u sin v, sin u) and f = rho(d) d with
rho = (sum_i |d_i / a_i|^n)^(-1/n), the point of the surface in direction d: smooth (C^k,
k < n, |x|^n written as (x^2)^(n/2)) everywhere but the poles u = +-pi/2, which chart
rotations by the box's symmetries move away from a contact. It is not orthogonal: the
general geometry of :mod:`ocp.geometry.surfaces`. The support function (the certificate's
gap) is the exact one, h(d) = (sum_i |a_i d_i|^q)^(1/q), q = n / (n - 1). MuJoCo has no
such primitive: its geom is a convex mesh whose vertices are written in the scene
(no file), fine enough that its chords sag less than :data:`MESH_SAG` [m]."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import casadi as ca
import numpy as np
from numpy.typing import ArrayLike, NDArray

from ocp.geometry.surfaces import Surface
from ocp.shapes.base import MujocoGeom, Shape

__all__ = ["MAX_EXPONENT", "SUPERELLIPSOID", "Superellipsoid", "SuperellipsoidShape",
           "SuperellipsoidSurface", "exponent_of_edge_radius"]

FloatArray = NDArray[np.float64]

#: The largest exponent (sharpest edges: an edge radius of 7 % of the half side).
MAX_EXPONENT = 20.0
#: The MuJoCo mesh's chords sag at most about this from the surface [m].
MESH_SAG = 5e-5
#: Points of a fingertip body's segment at which a swing's NLP keeps it clear of the
#: superellipsoid (:meth:`SuperellipsoidShape.segment_clearance`).
CLEARANCE_SAMPLES = 5


#: |x|^n is written (x^2 + EPS^2)^(n/2) in the chart: its derivatives of every order the
#: NLPs take (to the fourth) stay finite where a direction's component is zero (there
#: (x^2)^(n/2 - 4) x^4 is inf * 0); the surface moves by less than EPS^n (nothing).
_EPS = 1e-6


def _rho(d: Any, a: Any, b: Any, c: Any, n: Any) -> Any:
    e2 = _EPS**2
    return ((d[0] ** 2 / a**2 + e2) ** (n / 2) + (d[1] ** 2 / b**2 + e2) ** (n / 2)
            + (d[2] ** 2 / c**2 + e2) ** (n / 2)) ** (-1 / n)


def _chart(u: ca.SX, v: ca.SX, params: ca.SX) -> ca.SX:
    d = ca.vertcat(ca.cos(u) * ca.cos(v), -ca.cos(u) * ca.sin(v), ca.sin(u))
    return _rho(d, params[0], params[1], params[2], params[3]) * d


def edge_radius(half_side: float, n: float) -> float:
    """The radius of curvature [m] at the middle of an edge between two faces of half
    side ``half_side`` [m], exponent ``n``."""
    return math.sqrt(2.0) * half_side * 2.0 ** (-1.0 / n) / (n - 1.0)


def exponent_of_edge_radius(half_side: float, radius: float) -> float:
    """The exponent n in [2, :data:`MAX_EXPONENT`] of that edge radius (bisection: the
    radius falls as n grows)."""
    lo, hi = 2.0, MAX_EXPONENT
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if edge_radius(half_side, mid) > radius:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


class SuperellipsoidSurface(Surface):
    """The radial chart of the superellipsoid (see the module), parameters (a, b, c, n)."""

    orthogonal = False

    def __init__(self) -> None:
        super().__init__("superellipsoid", _chart,
                         ("semi_axis_x", "semi_axis_y", "semi_axis_z", "exponent"),
                         (False, True), math.pi / 2, ("u", "v"))

    def chart_rotation_error(self, rotation: ArrayLike,
                             params: Sequence[float] | None = None) -> str | None:
        """Only the box's symmetries: signed permutations of axes of equal half sides."""
        R = np.asarray(rotation, dtype=float).reshape(3, 3)
        if not np.allclose(R.T @ R, np.eye(3), atol=1e-9) or np.linalg.det(R) < 0:
            return "not a rotation"
        P = np.abs(R)
        if not np.allclose(P, np.round(P), atol=1e-9):
            return ("a superellipsoid's chart patch can only be turned onto itself: by "
                    "quarter or half turns about its axes")
        if params is not None:
            half = np.asarray(params, dtype=float)[:3]
            if not np.allclose(np.round(P) @ half, half, rtol=1e-9):
                return ("a superellipsoid's chart patch can only be turned by its "
                        "symmetries: a quarter turn would swap unequal half sides")
        return None

    def length_scale(self, params: Any) -> Any:
        """The largest half side [m] (not the exponent, its fourth parameter)."""
        if isinstance(params, ca.SX | ca.MX):
            return ca.mmax(params[0:3])
        return float(np.max(np.asarray(params, dtype=float)[:3]))

    def inverse(self, point: ArrayLike, params: ArrayLike) -> FloatArray:
        p = np.asarray(point, dtype=float)
        r = np.sqrt(np.sum(p * p, axis=-1))
        return np.stack([np.arcsin(np.clip(p[..., 2] / r, -1.0, 1.0)),
                         np.arctan2(-p[..., 1], p[..., 0])], axis=-1)

    @staticmethod
    def _q_terms(normals: FloatArray, params: ArrayLike) -> tuple[FloatArray, float]:
        prm = np.asarray(params, dtype=float)
        n = float(prm[3])
        q = n / (n - 1.0)
        return np.abs(prm[:3] * normals) ** q, q

    def support_height(self, normal: ArrayLike, params: ArrayLike) -> float:
        return float(self.support_heights(np.asarray(normal, dtype=float)[None], params)[0])

    def support_heights(self, normals: ArrayLike, params: ArrayLike) -> FloatArray:
        terms, q = self._q_terms(np.asarray(normals, dtype=float).reshape(-1, 3), params)
        return np.asarray(np.sum(terms, axis=1) ** (1.0 / q))

    def support_point(self, direction: ArrayLike, params: ArrayLike) -> FloatArray:
        """The point whose outward normal is ``direction``: x_i = a_i sgn(d_i)
        |a_i d_i|^(1/(n-1)) / S, S = (sum |a_i d_i|^q)^(1/n)."""
        prm = np.asarray(params, dtype=float)
        half, n = prm[:3], float(prm[3])
        d = np.asarray(direction, dtype=float)
        d = d / np.linalg.norm(d)
        terms = np.abs(half * d) ** (n / (n - 1.0))
        return np.asarray(half * np.sign(d) * np.abs(half * d) ** (1.0 / (n - 1.0))
                          / np.sum(terms) ** (1.0 / n))


#: The superellipsoid's radial chart.
Superellipsoid: Surface = SuperellipsoidSurface()


class SuperellipsoidShape(Shape):
    """A box with rounded edges: ``dimensions`` (a, b, c, edge_radius) [m]."""

    name = "superellipsoid"
    description = ("[a, b, c, edge_radius]: a box of half sides a, b, c along its x, y, z "
                   "axes with smoothly rounded edges, |x/a|^n + |y/b|^n + |z/c|^n = 1, n "
                   "such that an edge between faces of the smallest half side has that "
                   "radius of curvature at its middle [m]")
    parameters = ("half_side_x", "half_side_y", "half_side_z", "edge_radius")

    def surface(self, dimensions: Sequence[float]) -> Surface:
        return Superellipsoid

    def surfaces(self) -> tuple[Surface, ...]:
        return (Superellipsoid,)

    def surface_params(self, dimensions: Sequence[float]) -> tuple[float, ...]:
        a, b, c, r = (float(x) for x in dimensions[:4])
        return (a, b, c, exponent_of_edge_radius(min(a, b, c), r))

    def count_error(self, dimensions: Sequence[float]) -> str | None:
        if len(dimensions) != 4:
            return (f"a superellipsoid has 4 dimensions (a, b, c, edge_radius), got "
                    f"{len(dimensions)}")
        return None

    def errors(self, dimensions: Sequence[float]) -> list[str]:
        why = self.count_error(dimensions)
        if why is not None:
            return [why]
        bad = [f"{n} must be > 0 m, got {v}" for n, v in zip(self.parameters, dimensions,
                                                                  strict=True)
               if not (math.isfinite(v) and v > 0.0)]
        if bad:
            return bad
        s, r = min(float(x) for x in dimensions[:3]), float(dimensions[3])
        smallest = edge_radius(s, MAX_EXPONENT)
        if not smallest <= r <= s:
            return [f"edge_radius must be in [{smallest:.3g}, {s:.3g}] m (from the sharpest "
                    f"edge this shape allows to the ellipsoid's, the smallest half side), "
                    f"got {r}"]
        return []

    def semi_axes(self, dimensions: Sequence[float]) -> tuple[float, float, float]:
        a, b, c = (float(x) for x in dimensions[:3])
        return (a, b, c)

    def _gammas(self, dimensions: Sequence[float]) -> tuple[float, float]:
        """(the unit superball's volume over 8, its <x^2>) of the exponent."""
        n = self.surface_params(dimensions)[3]
        g = math.gamma
        return (g(1 + 1 / n) ** 3 / g(1 + 3 / n),
                g(3 / n) * g(1 + 3 / n) / (g(1 / n) * g(1 + 5 / n)))

    def volume(self, dimensions: Sequence[float]) -> float:
        a, b, c = self.semi_axes(dimensions)
        return 8.0 * a * b * c * self._gammas(dimensions)[0]

    def inertia(self, dimensions: Sequence[float], mass: float
                ) -> tuple[float, float, float]:
        a, b, c = self.semi_axes(dimensions)
        k = mass * self._gammas(dimensions)[1]
        return (k * (b * b + c * c), k * (a * a + c * c), k * (a * a + b * b))

    def mesh(self, dimensions: Sequence[float]) -> FloatArray:
        """The vertices (k, 3) of the convex mesh MuJoCo collides [m]: the surface points
        in the directions of a grid on each face of a cube, its spacing such that a chord
        sags at most :data:`MESH_SAG` where the surface is most curved."""
        a, b, c, n = self.surface_params(dimensions)
        r = edge_radius(min(a, b, c), n)
        k = int(min(max(math.ceil(2.0 * max(a, b, c) / math.sqrt(8.0 * r * MESH_SAG)), 8),
                    48))
        g = np.linspace(-1.0, 1.0, k + 1)
        s, t = (x.ravel() for x in np.meshgrid(g, g))
        one = np.ones_like(s)
        faces = []
        for axis in range(3):
            for sign in (-1.0, 1.0):
                cols = [s, t]
                cols.insert(axis, sign * one)
                faces.append(np.stack(cols, axis=1))
        d = np.unique(np.round(np.concatenate(faces), 12), axis=0)
        d = d / np.linalg.norm(d, axis=1, keepdims=True)
        rho = (np.abs(d[:, 0] / a) ** n + np.abs(d[:, 1] / b) ** n
               + np.abs(d[:, 2] / c) ** n) ** (-1.0 / n)
        return np.asarray(rho[:, None] * d)

    def mujoco_geom(self, dimensions: Sequence[float]) -> MujocoGeom:
        return MujocoGeom("mesh", (), tuple(float(x) for x in self.mesh(dimensions).ravel()))

    def nearest(self, dimensions: Sequence[float], points: ArrayLike
                ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Newton on the nearest point's conditions x - p + lam grad F(x) = 0, F(x) = 1
        (F = sum (x_i^2 / a_i^2 + eps^2)^(n/2), the chart's own smoothing), every point at
        once, from the point on the surface along its ray (a step at most a tenth of the
        smallest half side), to 1e-13 of it."""
        a, b, c, n = self.surface_params(dimensions)
        A = np.array([a, b, c])
        L = float(A.min())
        An = A / L  # in units of the smallest half side
        P = np.atleast_2d(np.asarray(points, dtype=float)) / L
        e2 = _EPS**2

        def parts(X: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
            w = X * X / (An * An) + e2
            F = np.sum(w ** (n / 2), axis=1)
            g = n * w ** (n / 2 - 1) * X / (An * An)
            h = n * ((n - 2) * w ** (n / 2 - 2) * X * X / An**4 + w ** (n / 2 - 1) / An**2)
            return F, g, h

        F0, _, _ = parts(P)
        X = P / F0[:, None] ** (1.0 / n)
        _, g, _ = parts(X)
        lam = np.einsum("ij,ij->i", P - X, g) / np.einsum("ij,ij->i", g, g)
        for _ in range(100):
            F, g, h = parts(X)
            r = np.concatenate([X - P + lam[:, None] * g, (F - 1.0)[:, None]], axis=1)
            J = np.zeros((len(X), 4, 4))
            J[:, [0, 1, 2], [0, 1, 2]] = 1.0 + lam[:, None] * h
            J[:, :3, 3] = g
            J[:, 3, :3] = g
            step = np.linalg.solve(J, -r[:, :, None])[:, :, 0]
            big = np.linalg.norm(step[:, :3], axis=1)
            scale = np.minimum(1.0, 0.1 / np.maximum(big, 1e-300))
            X = X + scale[:, None] * step[:, :3]
            lam = lam + scale * step[:, 3]
            if float(np.max(np.abs(r))) < 1e-13 and float(big.max()) < 1e-13:
                break
        F, g, _ = parts(X)
        nrm = g / np.linalg.norm(g, axis=1)[:, None]
        outside = F0 > 1.0
        dist = np.linalg.norm(P - X, axis=1) * np.where(outside, 1.0, -1.0)
        X, dist = X * L, dist * L
        for k in np.flatnonzero(np.abs(F - 1.0) > 1e-10):  # (a point deep inside near a
            # corner, where the conditions hold at several points): the chart's search
            from ocp.geometry.nearest import nearest_surface_point

            surf, params = self.surface(dimensions), self.surface_params(dimensions)
            alpha, t = nearest_surface_point(surf, params, P[k] * L)
            _, G, _, _, _ = surf.geometry(alpha, params)
            nrm[k] = np.asarray(G, dtype=float)[:, 2]
            dist[k] = float(t)
            X[k] = P[k] * L - t * nrm[k]
        return X, nrm, dist

    def clearance_params(self, dimensions: Sequence[float]) -> tuple[float, ...]:
        return self.surface_params(dimensions)

    def segment_clearance(self, params: Any, a: Any, b: Any) -> Any:
        """s_min (g(x) - 1), g the gauge (sum |x_i / a_i|^n)^(1/n) (the chart's smoothing),
        s_min the smallest half side, least over :data:`CLEARANCE_SAMPLES` points of the
        segment: the solid holds the ball of radius s_min, so the solid grown by
        s_min (g - 1) lies in g times the solid, and a point of gauge g is at least that
        far from it (exact on a face's middle; a box around it, the first version, left
        no lift-off along the normal at a rounded edge). Below the distance at those
        points, not between them (the certificate measures the body's true distance)."""
        e2 = _EPS**2
        least = ca.fmin(params[0], ca.fmin(params[1], params[2]))
        out = None
        for s in np.linspace(0.0, 1.0, CLEARANCE_SAMPLES):
            x = a + float(s) * (b - a)
            g = sum((x[i] ** 2 / params[i] ** 2 + e2) ** (params[3] / 2)
                    for i in range(3)) ** (1 / params[3])
            d = least * (g - 1.0)
            out = d if out is None else ca.fmin(out, d)
        return out

    def viewer(self, dimensions: Sequence[float]) -> dict[str, Any]:
        a, b, c, n = self.surface_params(dimensions)
        return {"kind": "superellipsoid", "semi_axes": [a, b, c], "exponent": n}


SUPERELLIPSOID = SuperellipsoidShape()
