"""What a shape of object is to the project (:class:`Shape`): its surface chart, its size
checks, its mass properties, its MuJoCo geom and its viewer record. One subclass per
shape, each in its own module of :mod:`ocp.shapes`, registered there by its wire name.

A shape's ``dimensions`` are the request's ``object.dimensions`` [m]; the surface's
parameters (:meth:`Shape.surface_params`, what the charts and the NLPs take) are the same
numbers unless the shape says otherwise."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ocp.geometry.surfaces import Surface

__all__ = ["CLEARANCE_PARAMS", "MESH_NAME", "MujocoGeom", "Shape"]

FloatArray = NDArray[np.float64]


#: The most numbers a shape's clearance for a swing's NLP takes
#: (:meth:`Shape.clearance_params`).
CLEARANCE_PARAMS = 4

#: The name of the object's mesh asset in a scene, when its geom is a mesh.
MESH_NAME = "dexroll_object_mesh"


def _numbers(values: Sequence[float]) -> str:
    return " ".join(f"{float(x):.17g}" for x in values)


@dataclass(frozen=True)
class MujocoGeom:
    """A MuJoCo geom of the object, in the object's frame (its centre, its axes): ``type``
    as MJCF names it, ``size`` as MJCF reads it for that type [m], and for a ``mesh`` its
    vertices (x, y, z flattened [m]), written in the scene's ``<asset>`` (MuJoCo collides
    and weighs their convex hull)."""

    type: str
    size: tuple[float, ...]
    vertices: tuple[float, ...] = ()

    def attributes(self) -> dict[str, str]:
        """The geom element's ``type`` and ``size`` (or ``mesh``) attributes, at full
        precision."""
        if self.type == "mesh":
            return {"type": "mesh", "mesh": MESH_NAME}
        return {"type": self.type, "size": _numbers(self.size)}

    def add_asset(self, root: ET.Element) -> None:
        """A mesh's ``<mesh>`` element (its vertices inline) in the scene ``root``'s
        ``<asset>``, made when missing; nothing for a primitive."""
        if self.type != "mesh":
            return
        asset = root.find("asset")
        if asset is None:
            asset = ET.Element("asset")
            root.insert(0, asset)
        ET.SubElement(asset, "mesh", name=MESH_NAME, vertex=_numbers(self.vertices))


class Shape(ABC):
    """One kind of object (a sphere, an ellipsoid, ...): everything that depends on its
    form, given its ``dimensions`` [m]."""

    #: The wire name (``object.shape``).
    name: str
    #: What ``object.dimensions`` holds, for the request's schema and its errors.
    description: str
    #: The names of ``object.dimensions`` in its longest form, in order.
    parameters: tuple[str, ...]

    @abstractmethod
    def surface(self, dimensions: Sequence[float]) -> Surface:
        """The surface whose chart the contact coordinates are measured in."""

    def side_surface(self, dimensions: Sequence[float]) -> Surface | None:
        """A second chart of the same surface whose poles lie where :meth:`surface`'s
        chart is regular and whose patch turns about an axis of the shape
        (``axis_patch``), for contacts near the first chart's poles
        (``ObjectSpec.side_chart``); None (the default) when the shape has none."""
        return None

    def surface_params(self, dimensions: Sequence[float]) -> tuple[float, ...]:
        """The parameters the surface's chart takes: the dimensions themselves unless a
        shape says otherwise."""
        return tuple(float(d) for d in dimensions)

    @abstractmethod
    def surfaces(self) -> tuple[Surface, ...]:
        """Every surface :meth:`surface` may give."""

    @abstractmethod
    def count_error(self, dimensions: Sequence[float]) -> str | None:
        """Why this many dimensions do not describe the shape, or None."""

    def errors(self, dimensions: Sequence[float]) -> list[str]:
        """Every reason ``dimensions`` do not describe this shape (empty when they do)."""
        why = self.count_error(dimensions)
        if why is not None:
            return [why]
        return self.surface(dimensions).validate_params(dimensions)

    @abstractmethod
    def semi_axes(self, dimensions: Sequence[float]) -> tuple[float, float, float]:
        """Half the extent of the object's bounding box along its own axes [m]."""

    def length_scale(self, dimensions: Sequence[float]) -> float:
        """The characteristic length the NLPs are scaled by [m]: the surface's, of its
        parameters (the NLPs compute the same from their parameter symbols)."""
        return float(self.surface(dimensions).length_scale(self.surface_params(dimensions)))

    @abstractmethod
    def volume(self, dimensions: Sequence[float]) -> float:
        """The solid's volume [m^3]."""

    @abstractmethod
    def inertia(self, dimensions: Sequence[float], mass: float
                ) -> tuple[float, float, float]:
        """The principal moments of inertia [kg m^2] of a uniform solid of ``mass`` about
        its centre, along its own axes: what MuJoCo computes for its geom."""

    def mass_of_density(self, dimensions: Sequence[float], density: float) -> float:
        """The mass of a uniform solid of ``density`` [kg/m^3]."""
        return density * self.volume(dimensions)

    @abstractmethod
    def mujoco_geom(self, dimensions: Sequence[float]) -> MujocoGeom:
        """The geom MuJoCo collides and weighs as this object."""

    @abstractmethod
    def viewer(self, dimensions: Sequence[float]) -> dict[str, Any]:
        """The viewer's tagged record of the shape (``kind`` and its sizes [m])."""

    def ball_radius(self, dimensions: Sequence[float]) -> float | None:
        """The radius of a ball (every direction alike: a finger gait measures its
        contacts and clearances from its centre), None for any other object."""
        return None

    def nearest(self, dimensions: Sequence[float], points: ArrayLike
                ) -> tuple[FloatArray, FloatArray, FloatArray] | None:
        """Of each point (rows of ``points`` [m], the object's frame), the surface's point
        nearest it, the outward normal there and the signed distance [m] (negative
        inside): what a finger gait measures its contacts and clearances with, every row
        at once. None where the shape has no such closed form (no gait on it yet)."""
        return None

    def clearance_params(self, dimensions: Sequence[float]) -> tuple[float, ...] | None:
        """The numbers :meth:`segment_clearance` takes (at most :data:`CLEARANCE_PARAMS`),
        or None where the shape has no clearance for a swing's NLP (no gait on it yet)."""
        return None

    def segment_clearance(self, params: Any, a: Any, b: Any) -> Any:
        """A lower bound on the distance of the segment a-b (the object's frame [m],
        CasADi) from the surface, positive only outside, with the shape's
        :meth:`clearance_params` as ``params`` (CasADi symbols): what a swing's NLP keeps
        a fingertip's body clear of the object with."""
        raise NotImplementedError(f"a {self.name} has no clearance for a swing")

    def sample_points(self, dimensions: Sequence[float], n: int = 400) -> FloatArray:
        """About ``n`` points spread over the surface (k, 3) [m], in the object's frame:
        the support points of directions on a Fibonacci sphere."""
        k = np.arange(n) + 0.5
        z = 1.0 - 2.0 * k / n
        phi = math.pi * (1.0 + math.sqrt(5.0)) * k
        r = np.sqrt(1.0 - z * z)
        d = np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)
        surface, params = self.surface(dimensions), self.surface_params(dimensions)
        return np.array([surface.support_point(di, params) for di in d])
