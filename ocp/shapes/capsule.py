"""The capsule (:data:`CAPSULE`): a cylinder of ``radius`` r along the object's z axis,
from z = -h to z = h (``half_length`` h, as MuJoCo's capsule ``size="r h"``), closed by
two hemispheres [m].

One chart covers the cylinder and both caps, a surface of revolution about z: u runs
along a meridian from the equator [m], v is the angle about the axis [rad] ((u, v) =
(0, 0) is the object's +x point). With s(u) the point of the axis the meridian's circle
is centred on and phi = (u - s) / r its latitude,

    f(u, v) = (r cos(phi) cos v, -r cos(phi) sin v, s + r sin(phi)).

On the cylinder s = u and phi = 0: f = (r cos v, -r sin v, u), M = diag(1, r), K =
diag(0, 1/r), T = 0. On a cap s = +-h: a sphere's latitude/longitude chart, M = diag(1,
r cos(phi)), K = diag(1/r, 1/r), T = (0, -tan(phi) / r). At a seam the capsule's meridian
curvature jumps from 0 to 1/r, and so does K: any chart of it has a kink in its frame
there, and an NLP whose contact crosses one cycles on that kink (the thumb of
examples/capsule_over_seam.json's grasp rolled 0.2-0.8 mm over the seam by tilts of 3-8
degrees: IPOPT ran to the 60 s limit, 550-1200 iterations; 42-48 with the blend). So s(u)
blends the two over w = SEAM_BLEND r either side of each seam (:func:`_ramp`, C3): the
meridian's curvature goes smoothly from 0 to 1/r there (overshooting to 1.125/r), and the
surface lies within 0.022 um inside the capsule (r = 12 mm; tests/test_shapes.py), far
below what the certificate's touching tolerance or MuJoCo's contacts resolve. Outside the
blends the chart is the capsule's exactly. The chart's poles are the caps' ends,
u = +-(h + r pi/2): a contact keeps |u| <= h + r (pi/2 - pole_margin)
(:meth:`CapsuleSurface.u_limit`). The support function a certificate measures gaps with,
the MuJoCo geom and the mass are the exact capsule's.
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


#: The seams' blend [a share of the radius]: the meridian's straight line and its caps'
#: arcs are joined over w = SEAM_BLEND r either side of each seam by a curvature that goes
#: smoothly from 0 to 1/r (overshooting to 1.125/r; see the module): within 0.022 um of
#: the capsule for r = 12 mm.
SEAM_BLEND = 0.01


def _ramp(x: Any) -> tuple[Any, Any, Any]:
    """The seam's C3 ramp P(x) [-] and its first two derivatives: P = 0 for x <= -1, x for
    x >= 1, 2 (t^6 - 3 t^5 + 5 t^4 / 2) between (t = (x + 1) / 2), so P' = 6 t^5 - 15 t^4
    + 10 t^3 (the smoother step) rises from 0 to 1 with P'' = 15 t^2 (1 - t)^2 and its
    rate zero at both ends: the meridian's curvature, and so K, has a continuous
    derivative, which the NLP's Jacobian takes. (With the C2 ramp 2 t^3 - t^4, whose third
    derivative jumps at the blend's ends, examples/own_hand.xml's nominal grasp of a
    capsule of r 30 mm and half length 12.7 mm, the thumb's contact starting 0.07 mm below
    the seam, ran to the 60 s limit; with this one it is certified in 6.2 s.)"""
    t = (x + 1) / 2
    if isinstance(x, ca.SX | ca.MX):
        inside = ca.logic_and(x > -1, x < 1)
        past = x >= 1
        return (ca.if_else(inside, 2 * (t**6 - 3 * t**5 + 2.5 * t**4),
                           ca.if_else(past, x, 0)),
                ca.if_else(inside, 6 * t**5 - 15 * t**4 + 10 * t**3, ca.if_else(past, 1, 0)),
                ca.if_else(inside, 15 * t**2 * (1 - t)**2, 0))
    inside, past = (x > -1) & (x < 1), x >= 1
    return (np.where(inside, 2 * (t**6 - 3 * t**5 + 2.5 * t**4), np.where(past, x, 0.0)),
            np.where(inside, 6 * t**5 - 15 * t**4 + 10 * t**3, np.where(past, 1.0, 0.0)),
            np.where(inside, 15 * t**2 * (1 - t)**2, 0.0))


def _meridian(u: Any, params: Any) -> tuple[Any, ...]:
    """(s, s_u, s_uu) at arc parameter u: the axis's point the meridian's circle is
    centred on [m] (s = u on the cylinder, +-h on the caps, blended over w either side of
    a seam) and its rates; the circle's latitude is phi = (u - s) / r. Written for the
    seam on u's side (the other's ramp is 0 there: the blends are 2 h - 2 w apart)."""
    r, h = params[0], params[1]
    w = SEAM_BLEND * r
    sign = ca.sign(u) if isinstance(u, ca.SX | ca.MX) else np.sign(u)
    P, dP, ddP = _ramp((sign * u - h) / w)
    return u - sign * w * P, 1 - dP, -sign * ddP / w


def _profile(u: Any, params: Any) -> tuple[Any, ...]:
    """The meridian at arc parameter u, CasADi symbols or numbers alike: (rho, z) [m], the
    distance from the axis and the height, and their first and second rates in u."""
    r = params[0]
    cos, sin = (ca.cos, ca.sin) if isinstance(u, ca.SX | ca.MX) else (np.cos, np.sin)
    s, s_u, s_uu = _meridian(u, params)
    phi, phi_u, phi_uu = (u - s) / r, (1 - s_u) / r, -s_uu / r
    cp, sp = cos(phi), sin(phi)
    return (r * cp, s + r * sp, -r * sp * phi_u, s_u + r * cp * phi_u,
            -r * (cp * phi_u**2 + sp * phi_uu), s_uu + r * (cp * phi_uu - sp * phi_u**2))


def _capsule_chart(u: ca.SX, v: ca.SX, params: ca.SX) -> ca.SX:
    rho, z = _profile(u, params)[:2]
    return ca.vertcat(rho * ca.cos(v), -rho * ca.sin(v), z)


class CapsuleSurface(Surface):
    """The capsule's chart over its cylinder and caps (see the module), parameters
    (radius, half_length) [m]; its support function and support points the whole
    capsule's."""

    chart_symmetry = "axis"
    developable = True
    ruling = (0.0, 0.0, 1.0)
    u_limit_name = ("caps' pole limit half_length + radius (pi/2 - pole_margin), an arc "
                    "along the capsule's meridian [m]")

    def __init__(self) -> None:
        super().__init__("capsule", _capsule_chart, ("radius", "half_length"),
                         (False, True), None, ("u", "v"))

    def closed_form_geometry(self, u: ca.SX, v: ca.SX, params: ca.SX
                             ) -> tuple[ca.SX, ...] | None:
        """A surface of revolution's frame, metric, curvature and torsion from its
        meridian (rho, z)(u) (the module's): x = (rho_u c, -rho_u s, z_u) / m, z = (z_u c,
        -z_u s, -rho_u) / m (m = |(rho_u, z_u)|), M = diag(m, rho), K = diag((rho_u z_uu
        - z_u rho_uu) / m^3, z_u / (m rho)), T = (0, rho_u / (m rho))."""
        rho, z, rho_u, z_u, rho_uu, z_uu = _profile(u, params)
        m = ca.sqrt(rho_u**2 + z_u**2)
        cv, sv = ca.cos(v), ca.sin(v)
        p = ca.vertcat(rho * cv, -rho * sv, z)
        R = ca.horzcat(ca.vertcat(rho_u * cv, -rho_u * sv, z_u) / m,
                       ca.vertcat(-sv, -cv, 0), ca.vertcat(z_u * cv, -z_u * sv, -rho_u) / m)
        M = ca.diag(ca.vertcat(m, rho))
        K = ca.diag(ca.vertcat((rho_u * z_uu - z_u * rho_uu) / m**3, z_u / (m * rho)))
        T = ca.horzcat(0, rho_u / (m * rho))
        return p, R, M, K, T

    def length_scale(self, params: Any) -> Any:
        """The capsule's half length, radius + half_length [m]."""
        if isinstance(params, ca.SX | ca.MX):
            return params[0] + params[1]
        return float(params[0]) + float(params[1])

    def u_limit(self, params: Sequence[float], pole_margin: float) -> float:
        """|u| <= half_length + radius (pi/2 - pole_margin) [m]: ``pole_margin`` [rad] of
        latitude short of a cap's end, the chart's pole."""
        return float(params[1]) + float(params[0]) * (math.pi / 2 - pole_margin)

    def inverse(self, point: ArrayLike, params: ArrayLike) -> FloatArray:
        """(u, v) of points on the surface: v their angle about the axis, u the capsule's
        arc parameter, refined on the blended meridian by Gauss-Newton (5 steps)."""
        r, h = (float(x) for x in np.asarray(params, dtype=float)[:2])
        p = np.asarray(point, dtype=float)
        rho_p, z_p = np.hypot(p[..., 0], p[..., 1]), p[..., 2]
        s = np.clip(z_p, -h, h)
        u = s + r * np.arctan2(z_p - s, rho_p)
        for _ in range(5):
            rho, z, rho_u, z_u = _profile(u, (r, h))[:4]
            u = u - ((rho - rho_p) * rho_u + (z - z_p) * z_u) / (rho_u**2 + z_u**2)
        return np.stack([u, np.arctan2(-p[..., 1], p[..., 0])], axis=-1)

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


#: The capsule's chart over its cylinder and caps.
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
