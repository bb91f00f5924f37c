"""Choosing the palm contact's chart patch on the object (docs/conventions.md, "Chart
patches").

The object's latitude/longitude chart is singular at its poles, so the planner keeps
``|u| <= pi/2 - pole_margin``. That bound is the chart's, not the physics': a plan whose
contact path rides it is shaped by the choice of patch (and its motion is not smooth
where the bound engages, which costs grid refinements). For a sphere any rotated patch
describes the same body, so the planner may re-plan in a patch whose poles are far from
the contact's path: :func:`pole_clear_patch` picks one, :func:`recharted` states the same
request in it (the same physical initial grasp, goals and via-points).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from ocp.geometry.surfaces import Chart

if TYPE_CHECKING:
    from ocp.spec.grasp import ManipulationProblem

__all__ = ["pole_clear_patch", "recharted", "recharted_coordinates", "rides_pole"]

FloatArray = NDArray[np.float64]

#: A contact this close to the pole bound [rad] rides it.
RIDING = 1e-6
#: Candidate pole directions: a Fibonacci lattice on the sphere (about 4 deg apart).
_N_CANDIDATES = 2000


def _psi_matrix(psi: float) -> FloatArray:
    c, s = math.cos(psi), math.sin(psi)
    return np.array([[c, -s, 0.0], [-s, -c, 0.0], [0.0, 0.0, -1.0]])


def recharted_coordinates(chart_old: Chart, chart_new: Chart, coords: Mapping[str, float]
                          ) -> dict[str, float] | None:
    """The palm contact coordinates ``coords`` (any of x, y, u, v, psi) measured in the
    new patch: the same palm point, the same object point, the same object orientation.
    None when they cannot be restated: psi without u and v (the contact angle is measured
    against the patch's frame at the object point), or only one of u, v."""
    out = {k: float(v) for k, v in coords.items() if k in ("x", "y")}
    has = {k for k in ("u", "v", "psi") if k in coords}
    if not has:
        return out
    if not {"u", "v"} <= has:
        return None
    p_old, G_old = chart_old.frame([coords["u"], coords["v"]])
    uv = np.asarray(chart_new.inverse(p_old), dtype=float).ravel()
    _, G_new = chart_new.frame(uv)
    out["u"], out["v"] = float(uv[0]), float(uv[1])
    if "psi" in has:
        # R_psi' = R_psi G_old^T G_new (the object's orientation unchanged)
        M = _psi_matrix(coords["psi"]) @ G_old.T @ G_new
        out["psi"] = float(math.atan2(-M[0, 1], M[0, 0]))
    return out


def rides_pole(problem: ManipulationProblem, u: FloatArray) -> bool:
    """Whether the palm contact's latitudes ``u`` (its path) reach the pole bound."""
    limit = math.pi / 2 - problem.pole_margin
    return bool(np.max(np.abs(u)) >= limit - RIDING)


def _fibonacci(n: int) -> FloatArray:
    k = np.arange(n) + 0.5
    z = 1 - 2 * k / n
    r = np.sqrt(1 - z**2)
    phi = math.pi * (3 - math.sqrt(5)) * k
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def pole_clear_patch(problem: ManipulationProblem, path: FloatArray
                     ) -> tuple[float, float, float] | None:
    """A sphere's patch rotation (rotation vector) whose poles are farthest from the
    contact's path (object-frame points, rows) and clear of the pole bound with a margin
    of half the pole margin; None for other shapes or when no patch clears it."""
    if problem.object.surface.chart_symmetry != "any":
        return None
    d = path / np.linalg.norm(path, axis=1, keepdims=True)
    cand = _fibonacci(_N_CANDIDATES)
    worst = np.max(np.abs(d @ cand.T), axis=0)  # |sin(latitude)| of the path, per pole
    best = int(np.argmin(worst))
    limit = math.pi / 2 - 1.5 * problem.pole_margin
    if math.asin(min(1.0, float(worst[best]))) > limit:
        return None
    z = np.array([0.0, 0.0, 1.0])
    pole = cand[best]
    axis = np.cross(z, pole)
    s, c = float(np.linalg.norm(axis)), float(z @ pole)
    rv = axis / s * math.atan2(s, c) if s > 1e-12 else np.zeros(3)
    return float(rv[0]), float(rv[1]), float(rv[2])


def recharted(problem: ManipulationProblem, rotvec: tuple[float, float, float]
              ) -> ManipulationProblem | None:
    """The same problem with the object's (palm contact's) patch rotated by ``rotvec``:
    its palm initial grasp, goal and via-points restated in it; None when one of them
    cannot be (:func:`recharted_coordinates`)."""
    if problem.palm is None:
        return None
    surface, shape = problem.object.surface, problem.object.params
    old = Chart.of(surface, shape, problem.object.chart_rotation)
    new = Chart.of(surface, shape, rotvec)
    pm = problem.palm
    keys = ("x", "y", "u", "v", "psi")
    initial = recharted_coordinates(old, new, dict(zip(keys, pm.initial, strict=True)))
    goal = recharted_coordinates(old, new, pm.goal)
    vias = []
    for vp in pm.via_points:
        coords = recharted_coordinates(old, new, vp.coords)
        if coords is None:
            return None
        vias.append(replace(vp, coords=coords))
    if initial is None or goal is None:
        return None
    x, y, u, v, psi = (initial[k] for k in keys)
    palm = replace(pm, initial=(x, y, u, v, psi), goal=goal, via_points=tuple(vias))
    return replace(problem, object=replace(problem.object, chart_rotation=rotvec), palm=palm)
