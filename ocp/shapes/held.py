"""The object a gait holds, where it is (docs/gait.md, "Objects other than a ball"):
where a round fingertip touches it, and how far a fingertip's body is from it.

A ball (:attr:`Held.shape` None) is measured as a gait always measured it: a tip's contact
is where the line of centres meets it, a body's distance is its segment's from the centre
less the radius. Any other shape is measured on its own surface, every row at once, with
the shape's closed-form nearest point (:meth:`ocp.shapes.Shape.nearest`; a shape without
one has no gait yet), and a swing's NLP keeps its clearance with the shape's lower bound
on a segment's distance (:meth:`ocp.shapes.Shape.segment_clearance`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ocp.geometry.bodies import point_segment_distance, tip_body
from ocp.geometry.rotations import axis_angle_rotation
from ocp.shapes.base import CLEARANCE_PARAMS

__all__ = ["Held", "held_object"]

FloatArray = NDArray[np.float64]

#: Golden-section steps of a body's distance along its segment (a convex function on a
#: convex object): the segment's length times 0.618^60, far below a nanometre.
SEGMENT_STEPS = 60


@dataclass(frozen=True)
class Held:
    """The still object of a gait: its centre and axes (``rotation``, palm frame), a
    ball's ``radius`` or another shape's length scale (the holds' ``L``), and for a shape
    that is not a ball the shape (:class:`ocp.shapes.Shape`) and its dimensions."""

    centre: FloatArray
    rotation: FloatArray
    radius: float
    shape: Any = None
    dimensions: tuple[float, ...] = ()

    @property
    def ball(self) -> bool:
        return self.shape is None

    @property
    def what(self) -> str:
        """The object in words, for messages: "the ball", "the ellipsoid", ..."""
        return "the ball" if self.shape is None else f"the {self.shape.name}"

    def at(self, centre: ArrayLike, rotation: ArrayLike | None = None) -> Held:
        """The same object at ``centre`` (and ``rotation`` when given)."""
        return replace(self, centre=np.asarray(centre, dtype=float),
                       rotation=self.rotation if rotation is None
                       else np.asarray(rotation, dtype=float))

    def turned(self, axis: ArrayLike, angle: float) -> Held:
        """The same object turned by ``angle`` [rad] about ``axis`` (palm frame, any
        length) through its centre."""
        return self.at(self.centre, axis_angle_rotation(axis, angle) @ self.rotation)

    def nearest(self, points: ArrayLike) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Of each point (rows, palm frame [m]): the object's nearest point, the outward
        normal there (palm frame) and the signed distance [m] (negative inside)."""
        x = np.atleast_2d(np.asarray(points, dtype=float))
        if self.shape is None:
            d = x - self.centre
            dist = np.linalg.norm(d, axis=1)
            n = d / dist[:, None]
            return self.centre + self.radius * n, n, dist - self.radius
        got = self.shape.nearest(self.dimensions, (x - self.centre) @ self.rotation)
        assert got is not None, "a shape without a nearest point has no gait"
        p, n, dist = got
        return p @ self.rotation.T + self.centre, n @ self.rotation.T, dist

    def contact(self, finger: Any, q: FloatArray) -> tuple[FloatArray, FloatArray]:
        """(point, outward normal) of a round fingertip's contact, palm frame: the
        object's point nearest the cap's centre (a ball's: where the line of centres
        meets it)."""
        R, p = finger.fingertip_pose_pin(q)
        a = p + R @ tip_body(finger).a
        if self.shape is None:
            n = (a - self.centre) / np.linalg.norm(a - self.centre)
            return self.centre + self.radius * n, n
        point, n, _ = self.nearest(a[None])
        return point[0], n[0]

    def segment_distance(self, a: ArrayLike, b: ArrayLike) -> FloatArray:
        """The distance [m] of each segment a-b (rows, palm frame) from the object's
        surface (negative: its nearest point inside): a ball's from its centre; another
        shape's the least along the segment (golden-section search: the distance is
        convex along a segment on a convex object)."""
        A = np.atleast_2d(np.asarray(a, dtype=float))
        B = np.atleast_2d(np.asarray(b, dtype=float))
        if self.shape is None:
            return np.array([point_segment_distance(self.centre, ai, bi)
                             for ai, bi in zip(A, B, strict=True)]) - self.radius
        if np.array_equal(A, B):
            return self.nearest(A)[2]
        g = (np.sqrt(5.0) - 1.0) / 2.0
        lo, hi = np.zeros(len(A)), np.ones(len(A))

        def at(s: FloatArray) -> FloatArray:
            return self.nearest(A + s[:, None] * (B - A))[2]

        c, d = hi - g * (hi - lo), lo + g * (hi - lo)
        fc, fd = at(c), at(d)
        for _ in range(SEGMENT_STEPS):
            left = fc < fd  # the least in [lo, d], else in [c, hi]
            lo, hi = np.where(left, lo, c), np.where(left, d, hi)
            new = np.where(left, hi - g * (hi - lo), lo + g * (hi - lo))
            f_new = at(new)
            c, d = np.where(left, new, d), np.where(left, c, new)
            fc, fd = np.where(left, f_new, fd), np.where(left, fc, f_new)
        ends = np.minimum(at(np.zeros(len(A))), at(np.ones(len(A))))
        return np.asarray(np.minimum(np.minimum(fc, fd), ends))

    def clearance_params(self) -> FloatArray:
        """The shape's numbers of its clearance in a swing's NLP
        (:meth:`ocp.shapes.Shape.clearance_params`), padded with zeros to
        :data:`~ocp.shapes.base.CLEARANCE_PARAMS`; a ball has none (its NLP is its own)."""
        out = np.zeros(CLEARANCE_PARAMS)
        if self.shape is not None:
            got = self.shape.clearance_params(self.dimensions)
            assert got is not None, "a shape without a clearance has no gait"
            out[:len(got)] = got
        return out


def held_object(obj: Any, centre: ArrayLike, rotation: ArrayLike) -> Held:
    """The gait's view of ``obj`` (an :class:`~ocp.spec.problem.ObjectSpec`) at
    ``centre`` with its axes ``rotation`` (palm frame): a sphere is a ball, measured as
    always (:meth:`ocp.shapes.Shape.ball_radius`); another shape is measured on its
    surface."""
    c, R = np.asarray(centre, dtype=float), np.asarray(rotation, dtype=float)
    radius = obj.kind.ball_radius(obj.dimensions)
    if radius is not None:
        return Held(c, R, float(radius))
    return Held(c, R, float(obj.length_scale), obj.kind,
                tuple(float(d) for d in obj.dimensions))


def gait_shape_error(obj: Any) -> str | None:
    """Why a gait cannot hold ``obj``: its shape has no closed-form nearest point or no
    clearance for a swing's NLP (None when it can)."""
    from ocp.shapes import SHAPES
    from ocp.shapes.base import Shape

    def held(shape: Shape) -> bool:
        return type(shape).nearest is not Shape.nearest and \
            type(shape).clearance_params is not Shape.clearance_params

    if held(obj.kind):
        return None
    can = ", ".join(s.name for s in SHAPES.values() if held(s))
    return (f"a gait measures its fingertips' contacts and clearances on the object's "
            f"surface: not yet on a {obj.shape} (only on: {can})")
