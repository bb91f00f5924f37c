"""A finger's shapes as its model declares them: the URDF's visual geometries (boxes,
cylinders, spheres, capsules) as Pinocchio reads them, the pad's thickness. Read by the
viewer (:mod:`planner_service.view`) and the execution (:mod:`planner_service.execution`)
alike; elements that name files (meshes, textures) are removed first, so that a request's
model never makes the service open a path it names."""

from __future__ import annotations

from typing import Any

import pinocchio as pin

from ocp import FingerModel

from ..models_check import without_file_references

__all__ = ["DEFAULT_PAD_THICKNESS", "pad_thickness", "shape_record", "visual_geometry"]

#: Thickness of a pad whose URDF gives none [m].
DEFAULT_PAD_THICKNESS = 0.004


def shape_record(geometry: Any) -> dict[str, Any] | None:
    """A Pinocchio geometry as a tagged record (box ``size``; cylinder, capsule ``radius``
    and ``length`` along z; sphere ``radius``; m), None for what is not drawn."""
    kind = type(geometry).__name__
    if kind == "Box":
        return {"kind": "box", "size": [float(2 * h) for h in geometry.halfSide]}
    if kind == "Cylinder":
        return {"kind": "cylinder", "radius": float(geometry.radius),
                "length": float(2 * geometry.halfLength)}
    if kind == "Capsule":
        return {"kind": "capsule", "radius": float(geometry.radius),
                "length": float(2 * geometry.halfLength)}
    if kind == "Sphere":
        return {"kind": "sphere", "radius": float(geometry.radius)}
    return None  # meshes, convex hulls: not drawn (the joint gets a segment)


def visual_geometry(finger: FingerModel) -> Any:
    """The finger's visual shapes, read from its URDF without the elements that name files
    (meshes, textures: :func:`~planner_service.models_check.without_file_references`):
    a request's model never makes the service open a path; None when none can be read."""
    try:
        return pin.buildGeomFromUrdfString(finger.model,
                                           without_file_references(finger.urdf_text),
                                           pin.GeometryType.VISUAL)
    except Exception:  # no shapes known: every joint gets a segment
        return None


def pad_thickness(finger: FingerModel) -> float:
    """The thickness of the pad's box in the URDF (its z side), or a default."""
    geom = visual_geometry(finger)
    if geom is not None:
        for o in geom.geometryObjects:
            shape = shape_record(o.geometry)
            if o.parentFrame == finger.tip_frame_id and shape and shape["kind"] == "box":
                return float(shape["size"][2])
    return DEFAULT_PAD_THICKNESS
