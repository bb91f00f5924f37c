"""The ball: ``dimensions`` (radius,) [m]; its chart is the latitude/longitude sphere of
:data:`ocp.geometry.surfaces.Sphere` (the same surface a round fingertip has)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import casadi as ca
import numpy as np
from numpy.typing import ArrayLike, NDArray

from ocp.geometry.bodies import point_segment_distance
from ocp.geometry.surfaces import Sphere, Surface
from ocp.shapes.base import MujocoGeom, Shape

__all__ = ["SPHERE", "SphereShape"]

FloatArray = NDArray[np.float64]


class SphereShape(Shape):
    name = "sphere"
    description = "a ball: [radius] [m]"
    parameters = ("radius",)

    def surface(self, dimensions: Sequence[float]) -> Surface:
        return Sphere

    def surfaces(self) -> tuple[Surface, ...]:
        return (Sphere,)

    def count_error(self, dimensions: Sequence[float]) -> str | None:
        if len(dimensions) != 1:
            return f"a sphere has 1 dimension (its radius), got {len(dimensions)}"
        return None

    def semi_axes(self, dimensions: Sequence[float]) -> tuple[float, float, float]:
        r = float(dimensions[0])
        return (r, r, r)

    def volume(self, dimensions: Sequence[float]) -> float:
        return 4.0 / 3.0 * math.pi * float(dimensions[0]) ** 3

    def inertia(self, dimensions: Sequence[float], mass: float
                ) -> tuple[float, float, float]:
        a = float(dimensions[0])
        side = mass * (a * a + a * a) / 5
        return (side, side, 2 * mass * a * a / 5)

    def mujoco_geom(self, dimensions: Sequence[float]) -> MujocoGeom:
        return MujocoGeom("sphere", (float(dimensions[0]),))

    def ball_radius(self, dimensions: Sequence[float]) -> float:
        return float(dimensions[0])

    def nearest(self, dimensions: Sequence[float], points: ArrayLike
                ) -> tuple[FloatArray, FloatArray, FloatArray]:
        r = float(dimensions[0])
        x = np.atleast_2d(np.asarray(points, dtype=float))
        d = np.linalg.norm(x, axis=1)
        n = x / d[:, None]
        return r * n, n, d - r

    def clearance_params(self, dimensions: Sequence[float]) -> tuple[float, ...]:
        return (float(dimensions[0]),)

    def segment_clearance(self, params: Any, a: Any, b: Any) -> Any:
        return point_segment_distance(ca.DM.zeros(3), a, b) - params[0]

    def viewer(self, dimensions: Sequence[float]) -> dict[str, Any]:
        return {"kind": "ellipsoid", "semi_axes": list(self.semi_axes(dimensions))}


SPHERE = SphereShape()
