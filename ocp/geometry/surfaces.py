"""Parameterised surfaces: a chart f(u, v) written once, its geometry derived.

A :class:`Surface` holds one CasADi expression, the chart ``f(u, v; params)`` in the body
frame. Everything Montana's contact equations need is derived from it symbolically
(Murray, Li, Sastry 1994, ch. 5.2; Montana 1988), with the frame-based definitions:

* Gauss frame ``R = [x y z]``, ``x = f_u/|f_u|``,
  ``z = f_u x f_v / |f_u x f_v|`` (outward normal), ``y = z x x``;
* metric ``M = [x y]^T [f_u f_v] = [[|f_u|, x.f_v], [0, y.f_v]]``   [m];
* curvature ``K = [x y]^T [z_u z_v] M^-1``                          [1/m];
* torsion ``T = y^T [x_u x_v] M^-1``                                [1/m].

So the contact point moves at ``[x y] M alpha_dot`` over the surface, the normal turns at
``[x y] K M alpha_dot`` and ``y . x_dot = T M alpha_dot``: Montana's eq. 3 holds with these
M, K, T for any regular chart. K is the shape operator in the basis (x, y), symmetric. For
an orthogonal chart (``f_u . f_v = 0``, :attr:`Surface.orthogonal`) ``y = f_v/|f_v|`` and
``M = diag(|f_u|, |f_v|)``, and the derivation is written in that form
(``K = [x y]^T [z_u/|f_u|, z_v/|f_v|]``, ``T = y^T [x_u/|f_u|, x_v/|f_v|]``).

The sphere and the spheroid also write these out in closed form
(:meth:`Surface.closed_form_geometry`), which the NLPs use: the same geometry (tested
against the derivation) in a quarter of the operations.

A :class:`Chart` is a surface with a fixed rotation ``R_chart`` of its coordinate patch
relative to the body, so that each contact can have its own patch and keep the patch's
singular points (the poles of a sphere's latitude/longitude chart) away from where the
contact goes. Rotating the patch rotates ``f`` and the Gauss frame; ``M``, ``K`` and
``T`` are intrinsic to the patch and do not change.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import casadi as ca
import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "AXIS_TURNS",
    "Chart",
    "Ellipsoid",
    "Plane",
    "Sphere",
    "Surface",
    "latitude_longitude",
    "safe_norm",
]

FloatArray = NDArray[np.float64]

#: The 24 proper rotations that permute the body axes with signs: a box's symmetries, the
#: candidates of :meth:`Surface.symmetries`.
AXIS_TURNS: tuple[FloatArray, ...] = tuple(
    R for R in (np.diag(signs)[list(perm)]
                for perm in ((0, 1, 2), (0, 2, 1), (1, 0, 2), (1, 2, 0), (2, 0, 1), (2, 1, 0))
                for signs in ((1, 1, 1), (1, 1, -1), (1, -1, 1), (1, -1, -1), (-1, 1, 1),
                              (-1, 1, -1), (-1, -1, 1), (-1, -1, -1)))
    if np.linalg.det(R) > 0)
#: A turn about body z by 1 rad: a surface whose patch may take it is one of revolution.
_TURN_ABOUT_Z = np.array([[math.cos(1.0), -math.sin(1.0), 0.0],
                          [math.sin(1.0), math.cos(1.0), 0.0], [0.0, 0.0, 1.0]])

#: Length below which a vector is treated as zero when normalised [m]. Far below any
#: physical length in a hand (mm), far above round-off of squared lengths.
_NORM_EPS = 1e-15


def safe_norm(v: ca.SX) -> ca.SX:
    """|v| with a finite value and gradient at v = 0: sqrt(v.v + eps^2), eps = 1e-15."""
    return ca.sqrt(ca.dot(v, v) + _NORM_EPS**2)


ChartExpr = Callable[[ca.SX, ca.SX, ca.SX], ca.SX]


class Surface:
    """A smooth surface given by a right-handed chart f(u, v; params).

    Parameters
    ----------
    name:
        Name of the shape (``"plane"``, ``"sphere"``, ...).
    chart:
        ``chart(u, v, params) -> 3x1 SX``, the point of the surface in the body frame [m].
    param_names:
        Names of the shape parameters (all lengths in m), in the order of ``params``.
    periodic:
        For each chart coordinate, whether it is an angle with period 2 pi.
    singular_u:
        Chart latitude |u| at which the chart is singular (pi/2 for the sphere), or None
        when the chart has no singular points.
    """

    #: Whether the chart is orthogonal (f_u . f_v = 0 everywhere): its geometry is then
    #: derived with M = diag(|f_u|, |f_v|); otherwise with the general, upper triangular M.
    orthogonal: bool = True

    def __init__(
        self,
        name: str,
        chart: ChartExpr,
        param_names: Sequence[str],
        periodic: tuple[bool, bool],
        singular_u: float | None,
        coord_names: tuple[str, str],
    ) -> None:
        self.name = name
        self.param_names = tuple(param_names)
        self.periodic = periodic
        self.singular_u = singular_u
        self.coord_names = coord_names
        self._chart = chart

    @property
    def n_params(self) -> int:
        return len(self.param_names)

    #: Whether one of the surface's principal curvatures is zero everywhere (the plane, a
    #: cylinder): two such surfaces touch along a line, not at a point.
    developable: bool = False
    #: The direction (chart patch frame) along which a curved developable surface is
    #: straight, every normal across it (a cylinder's axis); None for the others.
    ruling: tuple[float, float, float] | None = None

    def length_scale(self, params: Any) -> Any:
        """The length [m] the NLPs scale lengths by, of these parameters, as CasADi
        symbols (inside an NLP) or numbers (its values) alike: the largest parameter (a
        radius, the semi-axes)."""
        if isinstance(params, ca.SX | ca.MX):
            return ca.mmax(params)
        return float(np.max(np.asarray(params, dtype=float)))

    #: What :meth:`u_limit` is, for the errors that name it.
    u_limit_name = "chart pole limit pi/2 - pole_margin"

    def u_limit(self, params: Sequence[float], pole_margin: float) -> float:
        """The bound on |u| a contact keeps on this chart: ``pole_margin`` [rad] inside its
        singular latitude (the poles)."""
        if self.singular_u is None:
            return math.inf
        return self.singular_u - pole_margin

    def chart_expr(self, u: ca.SX, v: ca.SX, params: ca.SX) -> ca.SX:
        """The chart f(u, v; params) in the body frame [m]."""
        return self._chart(u, v, params)

    @cached_property
    def geometry(self) -> ca.Function:
        """Named CasADi function ``(alpha, params) -> (p, R, M, K, T)``.

        ``p`` is f(alpha) [m], ``R`` the Gauss frame (3x3), ``M`` the metric (2x2) [m],
        ``K`` the curvature (2x2) [1/m], ``T`` the torsion (1x2) [1/m]: the closed forms
        of :meth:`closed_form_geometry` where the surface has them, else
        :attr:`derived_geometry`.
        """
        u = ca.SX.sym("u")
        v = ca.SX.sym("v")
        params = ca.SX.sym("params", self.n_params)
        closed = self.closed_form_geometry(u, v, params)
        if closed is None:
            return self.derived_geometry
        return ca.Function(f"{self.name}_geometry", [ca.vertcat(u, v), params], list(closed),
                           ["alpha", "params"], ["p", "R", "M", "K", "T"])

    def closed_form_geometry(self, u: ca.SX, v: ca.SX, params: ca.SX
                             ) -> tuple[ca.SX, ...] | None:
        """(p, R, M, K, T) written out in closed form, or None (the default) to use the
        derivation from the chart. A closed form is the same geometry (the tests check it
        against :attr:`derived_geometry`) in a fraction of the operations: the derivation
        normalises vectors with square roots that CasADi cannot simplify away, and every
        NLP derivative pays for them (for the sphere on the palm: 33 operations per
        evaluation of the rolling equations instead of 115, and 273 instead of 1973 for
        their Jacobian and Hessian)."""
        return None

    @cached_property
    def derived_geometry(self) -> ca.Function:
        """``(alpha, params) -> (p, R, M, K, T)`` derived symbolically from the chart (the
        definitions in the module's doc), whatever the surface: in the orthogonal form
        when :attr:`orthogonal`, else in the general one."""
        u = ca.SX.sym("u")
        v = ca.SX.sym("v")
        params = ca.SX.sym("params", self.n_params)
        f = self._chart(u, v, params)
        R, M, K, T = (self._orthogonal_frame if self.orthogonal else self._general_frame)(
            f, u, v)
        alpha = ca.vertcat(u, v)
        return ca.Function(
            f"{self.name}_derived_geometry",
            [alpha, params],
            [f, R, M, K, T],
            ["alpha", "params"],
            ["p", "R", "M", "K", "T"],
        )

    @staticmethod
    def _tangents(f: ca.SX, u: ca.SX, v: ca.SX) -> tuple[ca.SX, ...]:
        """(f_v, |f_u|, x = f_u/|f_u|, the outward normal z = f_u x f_v normalised, z_u,
        z_v, x_u, x_v) of a chart f(u, v): what both forms of the frame start from."""
        f_u = ca.jacobian(f, u)
        f_v = ca.jacobian(f, v)
        m_u = safe_norm(f_u)
        x = f_u / m_u
        n = ca.cross(f_u, f_v)
        z = n / safe_norm(n)
        return (f_v, m_u, x, z, ca.jacobian(z, u), ca.jacobian(z, v),
                ca.jacobian(x, u), ca.jacobian(x, v))

    @staticmethod
    def _orthogonal_frame(f: ca.SX, u: ca.SX, v: ca.SX) -> tuple[ca.SX, ...]:
        """(R, M, K, T) of an orthogonal chart f(u, v): M = diag(|f_u|, |f_v|) [m]."""
        f_v, m_u, x, z, z_u, z_v, x_u, x_v = Surface._tangents(f, u, v)
        m_v = safe_norm(f_v)
        y = f_v / m_v
        R = ca.horzcat(x, y, z)
        M = ca.diag(ca.vertcat(m_u, m_v))
        K = ca.vertcat(
            ca.horzcat(ca.dot(x, z_u) / m_u, ca.dot(x, z_v) / m_v),
            ca.horzcat(ca.dot(y, z_u) / m_u, ca.dot(y, z_v) / m_v),
        )
        T = ca.horzcat(ca.dot(y, x_u) / m_u, ca.dot(y, x_v) / m_v)
        return R, M, K, T

    @staticmethod
    def _general_frame(f: ca.SX, u: ca.SX, v: ca.SX) -> tuple[ca.SX, ...]:
        """(R, M, K, T) of any regular chart f(u, v): x = f_u/|f_u|, z = f_u x f_v
        normalised, y = z x x; M = [[|f_u|, x.f_v], [0, y.f_v]] [m] (structurally upper
        triangular), K = [x y]^T [z_u z_v] M^-1 and T = y^T [x_u x_v] M^-1 [1/m]."""
        f_v, m_u, x, z, z_u, z_v, x_u, x_v = Surface._tangents(f, u, v)
        y = ca.cross(z, x)
        m_uv = ca.dot(x, f_v)
        m_v = ca.dot(y, f_v)
        # [w_u w_v] M^-1 = [w_u / m_u, (w_v - (m_uv / m_u) w_u) / m_v]
        shear = m_uv / m_u
        dz_x, dz_y = z_u / m_u, (z_v - shear * z_u) / m_v
        dx_x, dx_y = x_u / m_u, (x_v - shear * x_u) / m_v
        R = ca.horzcat(x, y, z)
        M = ca.SX(ca.Sparsity.upper(2), ca.vertcat(m_u, m_uv, m_v))
        K = ca.vertcat(
            ca.horzcat(ca.dot(x, dz_x), ca.dot(x, dz_y)),
            ca.horzcat(ca.dot(y, dz_x), ca.dot(y, dz_y)),
        )
        T = ca.horzcat(ca.dot(y, dx_x), ca.dot(y, dx_y))
        return R, M, K, T

    @cached_property
    def orthogonality(self) -> ca.Function:
        """``(alpha, params) -> f_u . f_v`` [m^2]: zero for an orthogonal chart."""
        u = ca.SX.sym("u")
        v = ca.SX.sym("v")
        params = ca.SX.sym("params", self.n_params)
        f = self._chart(u, v, params)
        val = ca.dot(ca.jacobian(f, u), ca.jacobian(f, v))
        return ca.Function(
            f"{self.name}_orthogonality", [ca.vertcat(u, v), params], [val],
            ["alpha", "params"], ["fu_dot_fv"],
        )

    def inverse(self, point: ArrayLike, params: ArrayLike) -> FloatArray:
        """Chart coordinates (u, v) of a point of the surface given in the patch frame; of
        every row for points (k, 3), as (k, 2)."""
        raise NotImplementedError(f"{self.name} has no inverse chart")

    def inverse_expr(self, point: Any, params: Any) -> Any:
        """:meth:`inverse` of one point (3 x 1) as a CasADi expression (2 x 1): what a
        plan that changes chart at a node maps its contact coordinates with
        (:mod:`ocp.transcription.chart_switch`). The longitude is atan2's, in (-pi, pi]."""
        raise NotImplementedError(f"{self.name} has no symbolic inverse chart")

    def support_height(self, normal: ArrayLike, params: ArrayLike) -> float:
        """h(n) = max_{p on surface} n . p for a unit direction n in the body frame [m].

        Closed form, independent of the chart: used by the certificate to check that the
        object touches the palm without the contact coordinates.
        """
        raise NotImplementedError(f"{self.name} is not a closed convex surface")

    def support_heights(self, normals: ArrayLike, params: ArrayLike) -> FloatArray:
        """:meth:`support_height` of each row of ``normals`` (k x 3) [m], as an array."""
        return np.array([self.support_height(n, params) for n in np.asarray(normals)])

    def support_point(self, direction: ArrayLike, params: ArrayLike) -> FloatArray:
        """The point of the surface whose outward normal is the unit ``direction`` [m]."""
        raise NotImplementedError(f"{self.name} is not a closed convex surface")

    #: Which rotations of the chart patch leave the surface itself unchanged, so that the
    #: rotated patch is another coordinate patch of the same body surface: "any" (sphere),
    #: "axis" (rotations that map the body z axis to itself: +-z for a body symmetric about
    #: its equator), "axis+" (rotations about +z only: the plane, whose normal is +z),
    #: "axes" (the triaxial ellipsoid: the rotations that map it to itself, which its
    #: :meth:`chart_rotation_error` decides from its semi-axes).
    chart_symmetry: str = "axis+"

    def chart_rotation_error(self, rotation: ArrayLike,
                             params: Sequence[float] | None = None) -> str | None:
        """Why ``rotation`` (3x3) is not a valid patch rotation of this surface, or None.
        ``params`` (the shape's parameters [m], when known) matter only to surfaces whose
        symmetries depend on them."""
        R = np.asarray(rotation, dtype=float).reshape(3, 3)
        if not np.allclose(R.T @ R, np.eye(3), atol=1e-9) or np.linalg.det(R) < 0:
            return "not a rotation"
        z = R @ np.array([0.0, 0.0, 1.0])
        if self.chart_symmetry == "any":
            return None
        if self.chart_symmetry == "axis" and abs(abs(z[2]) - 1.0) < 1e-9:
            return None
        if self.chart_symmetry == "axis+" and abs(z[2] - 1.0) < 1e-9:
            return None
        which = "its axis of revolution (body z)" if self.chart_symmetry == "axis" else \
            "its normal (body z)"
        return (f"a {self.name}'s chart patch can only be turned about {which}: any other "
                f"rotation would describe a different, rotated {self.name}")

    def axis_patch(self, point: ArrayLike) -> FloatArray | None:
        """The patch (a rotation in the body frame) that puts the body point ``point`` on
        this chart's equator, for a chart whose patch turns freely about an axis with its
        poles off that axis (an egg's side chart); None (the default) for the others."""
        return None

    def symmetries(self, params: Sequence[float] | None = None) -> tuple[FloatArray, ...]:
        """The quarter and half turns about the body axes (of :data:`AXIS_TURNS`, in its
        order) that map this surface's solid onto itself (:meth:`chart_rotation_error`):
        all 24 for a cube, the 8 that keep body z on its axis for a shape of revolution."""
        return tuple(R for R in AXIS_TURNS if self.chart_rotation_error(R, params) is None)

    def symmetry_near(self, F: ArrayLike, params: Sequence[float] | None = None
                      ) -> FloatArray | None:
        """The symmetry S of this surface's solid (body frame: S maps it onto itself)
        nearest the rotation ``F``, F = T S with T the least tilt: ``F`` itself for a
        sphere; for a shape of revolution about body z, S the turn about z that T (the
        least rotation taking z to F z) leaves; another's nearest of :meth:`symmetries`.
        None when there is none (F turns body z to the lower half, for a shape of
        revolution)."""
        F = np.asarray(F, dtype=float).reshape(3, 3)
        if self.chart_symmetry == "any":
            return F
        if self.chart_rotation_error(_TURN_ABOUT_Z, params) is None:  # of revolution
            z = F[:, 2]
            if z[2] <= 0.0:
                return None
            tilt = np.cross([0.0, 0.0, 1.0], z)
            size = float(np.linalg.norm(tilt))
            T = np.eye(3) if size == 0.0 else \
                rotation_from_vector(tilt / size * math.atan2(size, float(z[2])))
            S = T.T @ F
            return S if self.chart_rotation_error(S, params) is None else None
        turns = self.symmetries(params)
        return max(turns, key=lambda S: float(np.trace(F @ S.T))) if turns else None

    def validate_params(self, params: Sequence[float]) -> list[str]:
        """Reasons why ``params`` do not describe this surface (empty when they do)."""
        errors = []
        if len(params) != self.n_params:
            errors.append(f"expected {self.n_params} parameters {self.param_names}")
            return errors
        for name, value in zip(self.param_names, params, strict=True):
            if not np.isfinite(value):
                errors.append(f"{name} must be finite, got {value}")
            elif value <= 0.0:
                errors.append(f"{name} must be > 0 m, got {value}")
        return errors


def _plane_chart(u: ca.SX, v: ca.SX, params: ca.SX) -> ca.SX:
    return ca.vertcat(u, v, 0)


def _sphere_chart(u: ca.SX, v: ca.SX, params: ca.SX) -> ca.SX:
    rho = params[0]
    return rho * ca.vertcat(ca.cos(u) * ca.cos(v), -ca.cos(u) * ca.sin(v), ca.sin(u))


def _spheroid_chart(u: ca.SX, v: ca.SX, params: ca.SX) -> ca.SX:
    a, c = params[0], params[1]
    return ca.vertcat(a * ca.cos(u) * ca.cos(v), -a * ca.cos(u) * ca.sin(v), c * ca.sin(u))


def _revolution_geometry(u: ca.SX, v: ca.SX, a: ca.SX, c: ca.SX) -> tuple[ca.SX, ...]:
    """(p, R, M, K, T) of the spheroid chart f = (a cos u cos v, -a cos u sin v, c sin u)
    for |u| < pi/2, in closed form. With E = |f_u| = sqrt(a^2 sin^2 u + c^2 cos^2 u):
    x = (-a sin u cos v, a sin u sin v, c cos u) / E, y = (-sin v, -cos v, 0),
    z = (c cos u cos v, -c cos u sin v, a sin u) / E, M = diag(E, a cos u),
    K = diag(a c / E^3, c / (a E)) and T = (0, -tan u / E). The sphere is a = c = rho
    (K = I / rho, T = (0, -tan u / rho))."""
    cu, su, cv, sv = ca.cos(u), ca.sin(u), ca.cos(v), ca.sin(v)
    E = ca.sqrt((a * su) ** 2 + (c * cu) ** 2)
    p = ca.vertcat(a * cu * cv, -a * cu * sv, c * su)
    x = ca.vertcat(-a * su * cv, a * su * sv, c * cu) / E
    y = ca.vertcat(-sv, -cv, 0)
    z = ca.vertcat(c * cu * cv, -c * cu * sv, a * su) / E
    R = ca.horzcat(x, y, z)
    M = ca.diag(ca.vertcat(E, a * cu))
    K = ca.diag(ca.vertcat(a * c / E**3, c / (a * E)))
    T = ca.horzcat(0, -su / (cu * E))
    return p, R, M, K, T


class _Plane(Surface):
    developable = True

    def __init__(self) -> None:
        super().__init__("plane", _plane_chart, (), (False, False), None, ("x", "y"))

    def inverse(self, point: ArrayLike, params: ArrayLike) -> FloatArray:
        p = np.asarray(point, dtype=float)
        return np.stack([p[..., 0], p[..., 1]], axis=-1)


def latitude_longitude(point: Any, a: Any, b: Any, c: Any) -> Any:
    """(u, v) of the point (3 x 1, CasADi) of the chart (a cos u cos v, -b cos u sin v,
    c sin u): u = atan2(z / c, |(x / a, y / b)|), v = atan2(-y / b, x / a)."""
    x, y, z = point[0] / a, point[1] / b, point[2] / c
    return ca.vertcat(ca.atan2(z, ca.sqrt(x * x + y * y)), ca.atan2(-y, x))



class _Sphere(Surface):
    """Sphere of radius rho, f = rho (cos u cos v, -cos u sin v, sin u); poles at u = +-pi/2."""

    chart_symmetry = "any"

    def __init__(self) -> None:
        super().__init__("sphere", _sphere_chart, ("radius",), (False, True), np.pi / 2,
                         ("u", "v"))

    def closed_form_geometry(self, u: ca.SX, v: ca.SX, params: ca.SX
                             ) -> tuple[ca.SX, ...] | None:
        return _revolution_geometry(u, v, params[0], params[0])

    def inverse(self, point: ArrayLike, params: ArrayLike) -> FloatArray:
        p = np.asarray(point, dtype=float)
        r = np.sqrt(np.sum(p * p, axis=-1))
        return np.stack([np.arcsin(np.clip(p[..., 2] / r, -1.0, 1.0)),
                         np.arctan2(-p[..., 1], p[..., 0])], axis=-1)

    def inverse_expr(self, point: Any, params: Any) -> Any:
        return latitude_longitude(point, 1.0, 1.0, 1.0)

    def support_height(self, normal: ArrayLike, params: ArrayLike) -> float:
        return float(np.asarray(params, dtype=float)[0])

    def support_heights(self, normals: ArrayLike, params: ArrayLike) -> FloatArray:
        return np.full(len(np.asarray(normals)), float(np.asarray(params, dtype=float)[0]))

    def support_point(self, direction: ArrayLike, params: ArrayLike) -> FloatArray:
        d = np.asarray(direction, dtype=float)
        return float(np.asarray(params, dtype=float)[0]) * d / np.linalg.norm(d)


class _Ellipsoid(Surface):
    """Ellipsoid of revolution with semi-axes (a, a, c) about the body z axis.

    f = (a cos u cos v, -a cos u sin v, c sin u). This latitude/longitude chart is
    orthogonal because the two equatorial semi-axes are equal (the triaxial ellipsoid's,
    :mod:`ocp.shapes.ellipsoid`, is not); its curvature is not a multiple of the identity.
    """

    chart_symmetry = "axis"

    def __init__(self) -> None:
        super().__init__("ellipsoid", _spheroid_chart, ("equatorial_semi_axis", "polar_semi_axis"),
                         (False, True), np.pi / 2, ("u", "v"))

    def closed_form_geometry(self, u: ca.SX, v: ca.SX, params: ca.SX
                             ) -> tuple[ca.SX, ...] | None:
        return _revolution_geometry(u, v, params[0], params[1])

    def inverse(self, point: ArrayLike, params: ArrayLike) -> FloatArray:
        p = np.asarray(point, dtype=float)
        a, c = np.asarray(params, dtype=float)
        return np.stack([np.arctan2(p[..., 2] / c, np.hypot(p[..., 0], p[..., 1]) / a),
                         np.arctan2(-p[..., 1], p[..., 0])], axis=-1)

    def inverse_expr(self, point: Any, params: Any) -> Any:
        return latitude_longitude(point, params[0], params[0], params[1])

    def support_height(self, normal: ArrayLike, params: ArrayLike) -> float:
        n = np.asarray(normal, dtype=float)
        a, c = np.asarray(params, dtype=float)
        q = np.array([a * a, a * a, c * c])
        return float(np.sqrt(np.sum(q * n * n)))

    def support_heights(self, normals: ArrayLike, params: ArrayLike) -> FloatArray:
        n = np.asarray(normals, dtype=float)
        a, c = np.asarray(params, dtype=float)
        return np.asarray(np.sqrt(n**2 @ np.array([a * a, a * a, c * c])))

    def support_point(self, direction: ArrayLike, params: ArrayLike) -> FloatArray:
        d = np.asarray(direction, dtype=float)
        a, c = np.asarray(params, dtype=float)
        q = np.array([a * a, a * a, c * c])
        return np.asarray(q * d / np.sqrt(np.sum(q * d * d)))


#: The flat palm or a flat fingertip pad: f(x, y) = (x, y, 0), normal +z.
Plane: Surface = _Plane()
#: Sphere of radius rho (latitude u, longitude v).
Sphere: Surface = _Sphere()
#: Ellipsoid of revolution (a, a, c) (latitude u, longitude v).
Ellipsoid: Surface = _Ellipsoid()

SURFACES: dict[str, Surface] = {s.name: s for s in (Plane, Sphere, Ellipsoid)}


def rotation_from_vector(rotvec: ArrayLike) -> FloatArray:
    """Rotation matrix exp([w]x) of a rotation vector w [rad] (Rodrigues)."""
    w = np.asarray(rotvec, dtype=float).reshape(3)
    theta = float(np.linalg.norm(w))
    if theta < 1e-12:
        return np.eye(3)
    k = w / theta
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(theta) * kx + (1.0 - np.cos(theta)) * (kx @ kx)


@dataclass(frozen=True)
class Chart:
    """A surface's coordinate patch rotated by ``rotation`` (3x3) relative to the body.

    ``p_body = rotation @ f(u, v)``; Gauss frame in the body ``rotation @ R(u, v)``.
    """

    surface: Surface
    params: tuple[float, ...] = ()
    rotation: tuple[tuple[float, ...], ...] = field(
        default=((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)))

    @staticmethod
    def of(surface: Surface, params: Sequence[float] = (), rotvec: ArrayLike | None = None
           ) -> Chart:
        R = np.eye(3) if rotvec is None else rotation_from_vector(rotvec)
        error = surface.chart_rotation_error(R, params if len(params) else None)
        if error is not None:
            raise ValueError(error)
        return Chart(surface, tuple(float(p) for p in params),
                     tuple(tuple(float(x) for x in row) for row in R))

    @property
    def R(self) -> FloatArray:
        return np.array(self.rotation, dtype=float)

    def frame(self, alpha: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """(p, R): contact point and Gauss frame in the body frame at chart coordinates."""
        p, R, _, _, _ = self.surface.geometry(np.asarray(alpha, dtype=float), self.params)
        Rc = self.R
        return Rc @ np.asarray(p).reshape(3), Rc @ np.asarray(R)

    def inverse(self, point_body: ArrayLike) -> FloatArray:
        """Chart coordinates of a surface point given in the body frame."""
        return self.surface.inverse(self.R.T @ np.asarray(point_body, dtype=float), self.params)
