"""The scene of a plan: every pose the viewer draws at every sample, computed here so that
the page only draws (``static/viewer.js``).

A scene is plain JSON (:func:`build_scene`), palm frame, metres, quaternions (x, y, z, w)
as three.js takes them, arrays flattened row by row:

* ``t`` [s], ``grasp_angle`` [rad] (null: the planner has none), ``cone_half_angle``
  atan(mu) [rad] (null: unknown);
* ``object``: its ``shape`` (a tagged record: ``{"kind": "ellipsoid", "semi_axes":
  [a, b, c]}``; a ball has three equal semi-axes) and ``pose`` (``p``, ``q`` per sample);
* ``palm``: the plane z = 0, a square of ``half_extent`` about ``center`` under what
  moves, with a grid of ``grid`` [m] (null: no palm contact);
* ``contacts``: each contact's ``point`` and the object's outward ``normal`` per sample,
  and its ``trace`` on the object (the contact points in the object's frame);
* ``fingertips``: each fingertip's ``shape``, the model's own (``finger.tip_surface``), as
  a tagged record: a flat pad ``{"kind": "pad", "half_size", "thickness"}`` (its frame the
  pad's, the surface its z = 0); a round tip ``{"kind": "sphere", "radius"}``, ``{"kind":
  "capsule", "radius", "length"}`` (the whole capsule, ``length`` its cylinder's, along
  its frame's z, the frame at its centre) or ``{"kind": "ellipsoid", "semi_axes"}`` (a
  spheroid), each in its own frame placed by the tip surface's pose in the tip frame;
  the fingertip's ``pose`` per sample (that frame's) and the trace of its contact on it
  (in that frame);
* ``bodies``: the fingers' link shapes (:mod:`.robot`), each with its ``pose`` per sample
  (one sample: fixed);
* ``phases``: a gait's contact schedule (docs/gait.md; null for other plans): each phase's
  ``kind`` (roll, unload, swing, load), ``start`` and ``end`` [s] and ``lifted`` (the
  re-placed finger's name; null in a roll). With the contacts' ``active`` (per sample: 1
  touching, 0 lifted clear, between in a ramp) the page draws the schedule on its
  timeline, one row per contact.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ocp import quaternion_wxyz, shape_of

from ..plans.models import SceneModels, quaternion_matrices
from ..plans.shapes import pad_thickness
from ..plans.tracks import PlanTracks
from .robot import finger_bodies

__all__ = ["SCENE_VERSION", "build_scene"]

SCENE_VERSION = 1
#: Contact colours, in order (the palm's first when there is one).
PALETTE = ("#e4572e", "#17bebb", "#ffc914", "#76b041", "#a05195", "#2e86ab")
#: The palm's grid spacing [m].
PALM_GRID = 0.01
#: Half side of a pad whose model is unknown [m].
DEFAULT_PAD_HALF_SIZE = 0.05


def _flat(a: np.ndarray, digits: int = 6) -> list[float]:
    out: list[float] = np.round(np.asarray(a, dtype=float), digits).reshape(-1).tolist()
    return out


def _pose(position: np.ndarray, wxyz: np.ndarray) -> dict[str, list[float]]:
    """A pose track: positions and quaternions (x, y, z, w) with a continuous sign."""
    q = np.asarray(wxyz, dtype=float).reshape(-1, 4)[:, [1, 2, 3, 0]].copy()
    for k in range(1, len(q)):  # the nearer of q and -q to the previous sample
        if float(q[k] @ q[k - 1]) < 0.0:
            q[k] = -q[k]
    return {"p": _flat(position), "q": _flat(q)}


def _round_tip(tip: Any) -> tuple[dict[str, Any], np.ndarray, np.ndarray]:
    """A round fingertip's shape record and its frame (R, p) in the tip frame: a sphere's
    and a spheroid's the tip surface's; a capsule's at the capsule's centre, z along its
    axis (the tip surface's frame has the axis, outwards, along -y and its origin at the
    cap's centre, ``extra`` the cylinder's half length)."""
    R, p = tip.R, tip.p
    if tip.kind == "sphere":
        return {"kind": "sphere", "radius": float(tip.params[0])}, R, p
    if tip.kind == "spheroid":
        a, c = (float(x) for x in tip.params)
        return {"kind": "ellipsoid", "semi_axes": [a, a, c]}, R, p
    half = float(tip.extra[0]) if tip.extra else 0.0
    axis = -R[:, 1]
    R_c = np.column_stack([R[:, 0], R[:, 2], axis])  # x, z, -y: right-handed
    return ({"kind": "capsule", "radius": float(tip.params[0]), "length": 2 * half},
            R_c, p - half * axis)


def build_scene(tracks: PlanTracks, models: SceneModels, title: str = "",
                phases: list[dict[str, Any]] | None = None) -> dict[str, Any]:
    """The scene of a plan drawn with ``models`` (see the module for its layout);
    ``phases``: a gait's (kind, start, end, lifted), its contact schedule."""
    R_obj = quaternion_matrices(tracks.object_wxyz)
    c = tracks.object_position
    object_shape = shape_of(models.shape)
    semi = object_shape.semi_axes(models.dimensions)
    contacts: list[dict[str, Any]] = []
    fingertips: list[dict[str, Any]] = []
    bodies: list[dict[str, Any]] = []
    colors = {ct.name: PALETTE[i % len(PALETTE)] for i, ct in enumerate(tracks.contacts)}
    for ct in tracks.contacts:
        on_object = np.einsum("kji,kj->ki", R_obj, ct.point - c)
        contacts.append({"name": ct.name, "body": ct.body, "color": colors[ct.name],
                         "point": _flat(ct.point), "normal": _flat(ct.normal, 5),
                         "trace": _flat(on_object),
                         "active": None if ct.active is None else _flat(ct.active, 3)})
    points = [c + s * max(semi) for s in (-1.0, 1.0)]
    for i, (f, model) in enumerate(zip(tracks.fingers, models.fingers, strict=True)):
        R_tip = quaternion_matrices(f.tip_wxyz)
        contact = next((ct for ct in tracks.contacts if ct.name == f.name), None)
        trace = None if contact is None else \
            np.einsum("kji,kj->ki", R_tip, contact.point - f.tip_position)
        tip = None if model is None else model.tip_surface
        position, wxyz = f.tip_position, f.tip_wxyz
        if tip is not None and tip.round:
            shape, R_s, p_s = _round_tip(tip)
            position = f.tip_position + np.einsum("kij,j->ki", R_tip, p_s)
            wxyz = quaternion_wxyz(np.einsum("kij,jl->kil", R_tip, R_s))
            if trace is not None:  # in the shape's frame: R_s^T (p_tip - p_s)
                trace = (trace - p_s) @ R_s
        else:
            half = DEFAULT_PAD_HALF_SIZE if model is None else float(model.pad_half_size)
            thick = 0.004 if model is None else pad_thickness(model)
            shape = {"kind": "pad", "half_size": half, "thickness": thick}
        fingertips.append({
            "name": f.name, "color": colors.get(f.name, PALETTE[i % len(PALETTE)]),
            "shape": shape, "pose": _pose(position, wxyz),
            "trace": None if trace is None else _flat(trace)})
        points.append(f.tip_position)
        if model is None:
            continue
        for b in finger_bodies(model, f.q, f"{f.name}/"):
            if b.static and any(o["static_name"] == b.name.split("/", 1)[1]
                                for o in bodies if o["static"]):
                continue  # a fixed link of the hand, drawn once
            bodies.append({"name": b.name, "static": b.static,
                           "static_name": b.name.split("/", 1)[1],
                           "shape": b.shape, "color": list(b.color),
                           "pose": _pose(b.position, b.wxyz)})
            points.append(b.position)
    pts = np.concatenate([np.asarray(p).reshape(-1, 3) for p in points])
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    palm = None
    if models.palm_half_extent is not None:  # a square of it under what moves
        declared = float(models.palm_half_extent)
        centre = np.clip((lo[:2] + hi[:2]) / 2, -declared, declared)
        half = float(np.max(hi[:2] - lo[:2])) / 2 + 0.02
        half = min(half, declared - float(np.max(np.abs(centre))))
        palm = {"center": _flat(centre), "half_extent": half, "grid": PALM_GRID}
    grasp = tracks.grasp_angle
    return {
        "version": SCENE_VERSION,
        "title": title,
        "planner": tracks.planner,
        "status": tracks.status,
        "message": tracks.message,
        "notes": list(models.notes),
        "t": _flat(tracks.t),
        "grasp_angle": None if grasp is None else _flat(grasp),
        "cone_half_angle": tracks.cone_half_angle,
        "bounds": {"center": _flat((lo + hi) / 2),
                   "radius": max(float(np.linalg.norm(hi - lo)) / 2, 0.02)},
        "object": {"shape": {**object_shape.viewer(models.dimensions),
                             "object": models.shape},
                   "pose": _pose(c, tracks.object_wxyz)},
        "palm": palm,
        "contacts": contacts,
        "fingertips": fingertips,
        "bodies": [{k: v for k, v in b.items() if k != "static_name"} for b in bodies],
        "phases": None if phases is None else [
            {"kind": str(p["kind"]), "start": round(float(p["start"]), 6),
             "end": round(float(p["end"]), 6),
             "lifted": None if p.get("lifted") is None else str(p["lifted"])}
            for p in phases],
        "units": {"length": "m", "angle": "rad", "time": "s"},
    }
