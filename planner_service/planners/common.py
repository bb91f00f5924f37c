"""Conversions every planner's adapter shares: request parts to the core's, the core's
arrays to wire values."""

from __future__ import annotations

from typing import Any

import numpy as np

from dexroll_client.models import ForcesModel, ObjectModel, SolverModel
from ocp.spec.problem import ForceSpec, ObjectSpec, SolverOptions

__all__ = ["all_finite", "finite_or_none", "force_spec", "object_spec", "rows",
           "solver_options"]


def force_spec(f: ForcesModel | None) -> ForceSpec | None:
    """The core's load and grip of a request's ``forces`` (None: no forces planned)."""
    if f is None:
        return None
    inertia = None if f.inertia is None else (f.inertia[0], f.inertia[1], f.inertia[2])
    return ForceSpec(f.mass, inertia, (f.gravity[0], f.gravity[1], f.gravity[2]),
                     f.min_normal_force, f.torsional_friction, f.cone_margin)


def solver_options(o: SolverModel) -> SolverOptions:
    return SolverOptions(max_iter=o.max_iter, time_limit=o.time_limit,
                         cert_position_tol=o.cert_position_tol,
                         cert_angle_tol=o.cert_angle_tol)


def object_spec(o: ObjectModel) -> ObjectSpec:
    rv = o.chart_rotation
    return ObjectSpec(o.shape, tuple(o.dimensions), (rv[0], rv[1], rv[2]))


def rows(a: Any) -> list[Any]:
    """An array as (nested) lists of floats."""
    out: list[Any] = np.asarray(a, dtype=float).tolist()
    return out


def all_finite(d: dict[str, Any]) -> bool:
    return all(np.all(np.isfinite(np.asarray(v, dtype=float))) for v in d.values())


def finite_or_none(x: float) -> float | None:
    return float(x) if np.isfinite(x) else None
