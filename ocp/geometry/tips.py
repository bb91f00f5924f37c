"""Fingertip surfaces: a surface fixed in a finger link's frame.

A fingertip is one of the shapes below, placed in the frame of the finger's tip link (the
frame its forward kinematics gives) by a fixed pose ``(rotation, offset)``: the *tip
frame*. Its chart ``f(a, b)`` is written in the tip frame (``ocp.geometry.surfaces``), so
Montana's equations (eq. 3) see a curved surface on both sides of the contact when the tip
is round (``K_f + K~_o``, both curved: ``ocp.geometry.contact.ContactPair`` with the
object as body A and the tip as body B).

==========  ==================  =============================================================
kind        surface, params     tip frame, coordinates (a, b), where the contact may go
==========  ==================  =============================================================
pad         plane, ()           origin the pad's centre, +z its outward normal; (x, y) [m],
                                ``|x|, |y| <= half_size`` (the paper's flat pad)
sphere      sphere, (r,)        origin the sphere's centre; (u, v) [rad] latitude/longitude;
                                poles on the frame's +-z; ``|u| <= pi/2 - pole margin``
spheroid    ellipsoid, (a, c)   origin its centre, axis of revolution z; as the sphere
capsule     sphere, (r,)        the hemispherical cap of a capsule: origin the cap's centre,
                                the capsule's axis (outwards) along the frame's -y, so the cap
                                is ``0 <= v <= pi`` (v = pi/2 the very end); poles on +-z,
                                across the axis; the cylindrical side is refused (bounds)
==========  ==================  =============================================================

Choose the tip frame so that the contacts stay near (a, b) = (0, 0) for sphere and
spheroid tips (the patch's equator, far from its poles), and inside the cap for a capsule:
:func:`capsule_tip` builds a capsule cap's frame from the axis and the side the contacts
are on (the poles go across both).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ocp.geometry.surfaces import Ellipsoid, Plane, Sphere, Surface

__all__ = ["TIP_KINDS", "TipSurface", "capsule_tip", "pad_tip", "sphere_tip", "spheroid_tip"]

FloatArray = NDArray[np.float64]

#: The fingertip shapes.
TIP_KINDS: tuple[str, ...] = ("pad", "sphere", "spheroid", "capsule")

_EYE = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))


def _rows(a: ArrayLike) -> tuple[tuple[float, ...], ...]:
    return tuple(tuple(float(x) for x in row) for row in np.asarray(a, dtype=float))


@dataclass(frozen=True)
class TipSurface:
    """A fingertip surface in its link's frame (see the module's doc).

    ``params`` are the surface's (m): pad ``(half_size,)`` (the square pad's half side; the
    plane itself has none), sphere and capsule ``(r,)`` (a capsule: also its cylinder's
    ``half_length`` in ``extra``, for the record), spheroid ``(a, c)``. ``rotation`` and
    ``offset`` place the tip frame in the link's: ``p_link = rotation p_tip + offset``.
    """

    kind: str
    params: tuple[float, ...]
    rotation: tuple[tuple[float, ...], ...] = _EYE
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    extra: tuple[float, ...] = field(default=())

    @property
    def surface(self) -> Surface:
        return {"pad": Plane, "sphere": Sphere, "capsule": Sphere,
                "spheroid": Ellipsoid}[self.kind]

    @property
    def round(self) -> bool:
        return self.kind != "pad"

    @property
    def surface_params(self) -> tuple[float, ...]:
        """The parameters of :attr:`surface` (the pad's plane has none)."""
        return () if self.kind == "pad" else self.params

    @property
    def R(self) -> FloatArray:
        return np.array(self.rotation, dtype=float)

    @property
    def p(self) -> FloatArray:
        return np.array(self.offset, dtype=float)

    @property
    def size(self) -> float:
        """Its length scale [m]: the pad's half side, the sphere's radius, the spheroid's
        largest semi-axis."""
        return float(max(self.params))

    @property
    def coord_names(self) -> tuple[str, str]:
        return ("x", "y") if self.kind == "pad" else ("u", "v")

    def bounds(self, margin: float, pole_margin: float
               ) -> tuple[tuple[float, float], tuple[float, float]]:
        """((a_lo, a_hi), (b_lo, b_hi)) where the contact may go: the pad less ``margin``
        [m]; a round tip's pole bound ``pi/2 - pole_margin`` on a, and for a capsule the
        cap, ``margin / r <= b <= pi - margin / r`` (``margin`` as an arc length)."""
        if self.kind == "pad":
            h = self.params[0] - margin
            return (-h, h), (-h, h)
        u = math.pi / 2 - pole_margin
        if self.kind == "capsule":
            m = margin / self.params[0]
            return (-u, u), (m, math.pi - m)
        return (-u, u), (-math.inf, math.inf)

    def errors(self, name: str) -> list[tuple[str, str]]:
        """Why it is not a valid fingertip, as (field, reason) under ``name``."""
        errs: list[tuple[str, str]] = []
        if self.kind not in TIP_KINDS:
            return [(f"{name}.kind", f"must be one of {list(TIP_KINDS)}, got {self.kind!r}")]
        n = 2 if self.kind == "spheroid" else 1
        if len(self.params) != n or not all(math.isfinite(p) and 1e-4 <= p <= 1.0
                                            for p in self.params):
            errs.append((f"{name}.dimensions", f"a {self.kind} tip takes {n} length(s) in "
                                               f"[0.1 mm, 1 m], got {list(self.params)}"))
        R = self.R
        if R.shape != (3, 3) or not np.allclose(R.T @ R, np.eye(3), atol=1e-9) or \
                np.linalg.det(R) < 0:
            errs.append((f"{name}.rotation", "must be a rotation"))
        if len(self.offset) != 3 or not all(math.isfinite(x) and abs(x) <= 1.0
                                            for x in self.offset):
            errs.append((f"{name}.offset", "must be 3 finite numbers within 1 m"))
        return errs

    def describe(self) -> dict[str, Any]:
        return {"kind": self.kind, "dimensions": list(self.params),
                "rotation": [list(r) for r in self.rotation], "offset": list(self.offset)}


def pad_tip(half_size: float) -> TipSurface:
    """The flat square pad of half side ``half_size`` [m], the tip frame the link's."""
    return TipSurface("pad", (float(half_size),))


def sphere_tip(radius: float, offset: ArrayLike = (0.0, 0.0, 0.0),
               rotation: ArrayLike | None = None) -> TipSurface:
    """A spherical fingertip of ``radius`` [m] centred at ``offset`` in the link frame."""
    R = np.eye(3) if rotation is None else np.asarray(rotation, dtype=float)
    o = np.asarray(offset, dtype=float)
    return TipSurface("sphere", (float(radius),), _rows(R),
                      (float(o[0]), float(o[1]), float(o[2])))


def spheroid_tip(a: float, c: float, offset: ArrayLike = (0.0, 0.0, 0.0),
                 rotation: ArrayLike | None = None) -> TipSurface:
    """A spheroidal fingertip (semi-axes a, a, c; axis of revolution the tip frame's z)."""
    R = np.eye(3) if rotation is None else np.asarray(rotation, dtype=float)
    o = np.asarray(offset, dtype=float)
    return TipSurface("spheroid", (float(a), float(c)), _rows(R),
                      (float(o[0]), float(o[1]), float(o[2])))


def capsule_tip(radius: float, cap_centre: ArrayLike, axis: ArrayLike, side: ArrayLike,
                half_length: float = 0.0) -> TipSurface:
    """The hemispherical cap of a capsule of ``radius`` [m], in the link frame: its centre
    ``cap_centre`` [m], the capsule's ``axis`` pointing out of the cap, ``side`` the
    direction (across the axis) the contacts lean to. The tip frame: x the part of ``side``
    across the axis, y = -axis, z = x cross y (the poles, across both)."""
    a = np.asarray(axis, dtype=float)
    a = a / np.linalg.norm(a)
    s = np.asarray(side, dtype=float)
    s = s - np.dot(s, a) * a
    if np.linalg.norm(s) < 1e-9:
        raise ValueError("side must not be parallel to the capsule's axis")
    x = s / np.linalg.norm(s)
    y = -a
    R = np.column_stack([x, y, np.cross(x, y)])
    c = np.asarray(cap_centre, dtype=float)
    return TipSurface("capsule", (float(radius),), _rows(R),
                      (float(c[0]), float(c[1]), float(c[2])), (float(half_length),))
