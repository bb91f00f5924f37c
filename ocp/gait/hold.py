"""Holding the still object with the fingertips that touch it (docs/gait.md, "The hold").

While a fingertip is re-placed the object is held still by the others. Its load is then
quasi-static and the geometry fixed, so the planned forces of a held grasp are one small
convex-like problem: the rows of the rolling plan's forces (:func:`~ocp.transcription.loads.
load_rows`: equilibrium with the weight, every normal force at least the minimum, every
force inside its friction cone narrowed by the margin) at one point, solved once.

Between two holds of the same geometry the forces move along the straight line from one
solution to the other: equilibrium is linear and the cones are convex, so every force on
the line holds the object (the unloading of a fingertip before it lifts: from the grasp's
forces to the forces without it, its own force going to zero with the ramp; the loading
after it lands, the reverse).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np
from numpy.typing import NDArray

from ocp.transcription.loads import LOAD_VARS, load_cost, load_rows
from ocp.transcription.values import load_bounds

__all__ = ["HOLD_FORCE_FACTOR", "HOLD_MARGINS", "Hold", "HoldResiduals", "deep_hold_forces",
           "hold_forces", "hold_residuals", "narrowed_load"]

FloatArray = NDArray[np.float64]

_OPTIONS: dict[str, Any] = {"print_time": False, "ipopt.print_level": 0, "ipopt.sb": "yes",
                            "ipopt.tol": 1e-10, "ipopt.constr_viol_tol": 1e-10,
                            "ipopt.max_iter": 300}
_SOLVERS: dict[int, tuple[ca.Function, ca.Function, FloatArray, FloatArray]] = {}


@dataclass(frozen=True)
class Hold:
    """A still object held by contacts: their points and the object's outward normals
    there (palm frame, one row each), the object's centre and rotation (palm frame)."""

    points: FloatArray
    normals: FloatArray
    centre: FloatArray
    rotation: FloatArray

    def local(self) -> tuple[FloatArray, FloatArray]:
        """(points, normals) in the object frame, one column each."""
        R = self.rotation
        return R.T @ (self.points - self.centre).T, R.T @ self.normals.T


@dataclass(frozen=True)
class HoldResiduals:
    """How well forces hold the object [N, N m]: the equilibrium's residual (force and
    moment, the larger), the least normal force's margin over the minimum (negative:
    below it), the least cone margin (mu_m f_n - |f_t|; negative: outside)."""

    equilibrium: float
    normal_margin: float
    cone_margin: float


def _solver(nc: int) -> tuple[ca.Function, ca.Function, FloatArray, FloatArray]:
    if nc not in _SOLVERS:
        fl = ca.SX.sym("fl", LOAD_VARS * nc)
        P, N, R = ca.SX.sym("P", 3, nc), ca.SX.sym("N", 3, nc), ca.SX.sym("R", 3, 3)
        q, L = ca.SX.sym("load", 8), ca.SX.sym("L")
        rows, fn = load_rows(P, N, R, fl, q, L)
        g = ca.vertcat(*[e for e, _, _ in rows])
        lo = np.concatenate([np.full(int(e.numel()), a) for e, a, _ in rows])
        hi = np.concatenate([np.full(int(e.numel()), b) for e, _, b in rows])
        p = ca.vertcat(ca.vec(P), ca.vec(N), ca.vec(R), q, L)
        solver = ca.nlpsol(f"hold{nc}", "ipopt", {"x": fl, "p": p, "f": load_cost(fl, fn),
                                                  "g": g}, _OPTIONS)
        _SOLVERS[nc] = (solver, ca.Function("rows", [fl, p], [g]), lo, hi)
    return _SOLVERS[nc]


def hold_forces(hold: Hold, load: FloatArray, L: float) -> FloatArray | None:
    """The planned forces [N] (palm frame, one row per contact) that hold the still object
    with the least effort (:func:`~ocp.transcription.loads.load_cost`), or None when these
    contacts cannot hold it (no forces inside the cones balance the weight). ``load``: the
    load parameters (:func:`~ocp.transcription.values.load_parameters`), ``L`` the object's
    length scale. Hard point contacts: a soft finger's torsion is not used."""
    nc = len(hold.points)
    if nc == 0:
        return None
    P, N = hold.local()
    solver, rows, lo, hi = _solver(nc)
    load = np.array(load, dtype=float)
    load[4] = 0.0  # hard point contacts: no torsion (conservative; the residuals' model)
    p = np.concatenate([P.ravel(order="F"), N.ravel(order="F"),
                        hold.rotation.ravel(order="F"), load, [L]])
    bound = load_bounds(nc, 1).ravel()
    res = solver(x0=np.zeros(LOAD_VARS * nc), p=p, lbx=-bound, ubx=bound, lbg=lo, ubg=hi)
    g = np.asarray(rows(res["x"], p)).ravel()
    if not solver.stats()["success"] or np.max(np.maximum(lo - g, g - hi)) > 1e-7:
        return None
    fl = np.asarray(res["x"]).reshape(nc, LOAD_VARS)
    F0 = float(load[5])
    return (hold.rotation @ (fl[:, :3].T * F0)).T


#: Extra narrowings of the friction cones [rad] a hold's forces are tried with, the
#: largest that holds the object first (:func:`deep_hold_forces`).
HOLD_MARGINS = (0.3, 0.2, 0.15, 0.1, 0.05, 0.0)
#: A hold's largest normal force over the object's weight that a narrowing may ask (the
#: thumb lifted from a searched grasp of 90 deg about +z: 24.5 N at 0.2 rad, 2.1 N at 0.15,
#: for a 0.49 N ball; the drop from there to a roll's 0.5 N lost contacts in MuJoCo).
HOLD_FORCE_FACTOR = 10.0


#: The last holds' deep forces, by their geometry and load (:func:`deep_hold_forces`): a
#: gait step's hold after its fingertip lands is the next step's before it lifts.
_DEEP: dict[bytes, tuple[FloatArray | None, float]] = {}
_DEEP_KEPT = 16


def deep_hold_forces(hold: Hold, load: FloatArray, L: float,
                     fits: Callable[[FloatArray], bool] | None = None, fits_key: bytes = b""
                     ) -> tuple[FloatArray | None, float]:
    """:func:`_deep_hold_forces` of the hold, remembered for the last :data:`_DEEP_KEPT`
    holds (keyed by the exact bytes of the geometry, the load, ``L`` and ``fits_key``,
    which names what ``fits`` checks)."""
    key = b"".join(np.ascontiguousarray(a, dtype=float).tobytes() for a in (
        hold.points, hold.normals, hold.centre, hold.rotation, load, [L])) + fits_key
    if key not in _DEEP:
        if len(_DEEP) >= _DEEP_KEPT:
            _DEEP.pop(next(iter(_DEEP)))
        _DEEP[key] = _deep_hold_forces(hold, load, L, fits)
    F, extra = _DEEP[key]
    return (None if F is None else F.copy()), extra


def _deep_hold_forces(hold: Hold, load: FloatArray, L: float,
                      fits: Callable[[FloatArray], bool] | None = None
                      ) -> tuple[FloatArray | None, float]:
    """(forces, the extra margin [rad] they keep inside the cones): :func:`hold_forces`
    with each cone narrowed by the largest of :data:`HOLD_MARGINS` that still holds the
    object with no normal force over :data:`HOLD_FORCE_FACTOR` times its weight and whose
    forces ``fits`` accepts (the joints' torques within the actuators'; least-effort
    forces ride the cones' edges, which a servo-driven hand does not deliver exactly; the
    deepest forces can be large: docs/gait.md); when every narrowing asks more, the least
    normal force's of those ``fits`` accepts, else of all; (None, 0) when none holds it."""
    cap = HOLD_FORCE_FACTOR * float(np.linalg.norm(load[0:3]))
    best: tuple[FloatArray | None, float, float] = (None, 0.0, math.inf)
    best_fit: tuple[FloatArray | None, float, float] = (None, 0.0, math.inf)
    for extra in HOLD_MARGINS:
        F = hold_forces(hold, narrowed_load(load, extra), L)
        if F is None:
            continue
        top = float((-np.einsum("ij,ij->i", F, hold.normals)).max())
        fit = fits is None or fits(F)
        if top <= cap and fit:
            return F, extra
        if top < best[2]:
            best = (F, extra, top)
        if fit and top < best_fit[2]:
            best_fit = (F, extra, top)
    if best_fit[0] is not None:
        return best_fit[0], best_fit[1]
    return best[0], best[1]


def narrowed_load(load: FloatArray, extra: float) -> FloatArray:
    """The load parameters with the friction cones narrowed by ``extra`` [rad] more (their
    smoothing with them)."""
    mu_m = float(load[6])
    out = np.array(load, dtype=float)
    out[6] = np.tan(max(np.arctan(mu_m) - extra, 1e-3))
    out[7] = load[7] * out[6] / mu_m
    return out


def hold_residuals(hold: Hold, forces: FloatArray, load: FloatArray, min_normal: FloatArray
                   ) -> HoldResiduals:
    """The residuals of ``forces`` [N] (palm frame, per contact) holding the object with
    the weight ``load[0:3]`` [N]: the wrench's (about the centre), the normal forces over
    ``min_normal`` [N] per contact, and the cones (``load[6]``: tan(atan(mu) - margin)).
    Hard point contacts (the torsion is not checked here)."""
    r = hold.points - hold.centre
    wrench_f = forces.sum(axis=0) + load[0:3]
    wrench_m = np.cross(r, forces).sum(axis=0)
    fn = -np.einsum("ij,ij->i", forces, hold.normals)
    ft = np.linalg.norm(forces + fn[:, None] * hold.normals, axis=1)
    return HoldResiduals(float(max(np.abs(wrench_f).max(), np.abs(wrench_m).max())),
                         float(np.min(fn - min_normal)), float(np.min(load[6] * fn - ft)))

