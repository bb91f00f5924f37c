"""The shapes of objects, each in its own module, registered here by the name a request
gives (``object.shape``).

A shape (:class:`Shape`) is all the project knows of an object's form, given its
``object.dimensions``: the surface whose chart the contact coordinates are measured in,
its size checks, its mass properties, the geom MuJoCo collides and weighs, and the record
the viewer draws. Everything else asks the registry (:func:`shape_of`) or the object
(:class:`ocp.spec.problem.ObjectSpec`), never a shape's name. Adding a shape is a module
here with a :class:`Shape` subclass, and its entry in :data:`SHAPES` (and in the wire's
``object.shape`` names, ``dexroll_client.requests.ObjectModel``, which a test pins to this
registry)."""

from __future__ import annotations

from ocp.geometry.surfaces import Surface
from ocp.shapes.base import MujocoGeom, Shape
from ocp.shapes.capsule import CAPSULE
from ocp.shapes.ellipsoid import ELLIPSOID
from ocp.shapes.sphere import SPHERE
from ocp.shapes.superellipsoid import SUPERELLIPSOID

__all__ = ["SHAPES", "MujocoGeom", "Shape", "object_surface", "shape_of"]

#: Every shape, by its wire name.
SHAPES: dict[str, Shape] = {s.name: s for s in (SPHERE, ELLIPSOID, CAPSULE, SUPERELLIPSOID)}


def shape_of(name: str) -> Shape:
    """The shape of that name (KeyError naming the known ones)."""
    try:
        return SHAPES[name]
    except KeyError:
        raise KeyError(f"unknown object shape {name!r}; one of {sorted(SHAPES)}") from None


def object_surface(name: str) -> Surface:
    """The object surface of that surface name (the key of the NLPs' caches: a shape may
    have several surfaces, as an ellipsoid of revolution and a triaxial one)."""
    for shape in SHAPES.values():
        for surface in shape.surfaces():
            if surface.name == name:
                return surface
    raise KeyError(f"no object shape has the surface {name!r}")
