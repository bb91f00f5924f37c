"""The planned contact forces' rows at one collocation point (docs/forces.md): the
object's quasi-static equilibrium with its weight, the friction cones with a margin, the
minimum normal force, the soft-finger torsion within its limit; and their objective."""

from __future__ import annotations

import math
from typing import Any

import casadi as ca

__all__ = ["LOAD_PARAMS", "LOAD_PUSH_WEIGHT", "LOAD_REGULARISATION", "LOAD_VARS",
           "TORSION_SHARE", "load_cost", "load_rows"]


#: Variables of one contact's planned force at a point: the force in the object frame,
#: divided by the force scale, and the torsion's fraction of its limit (soft fingers).
LOAD_VARS = 4
#: The torsion stays within this fraction of its limit |tau| <= torsional_friction f_n.
TORSION_SHARE = 0.95
#: Load parameters: the weight m g in the palm frame [N], the minimum normal force [N],
#: the torsional friction [m], the force scale [N], tan(atan(mu) - margin), the cone's
#: smoothing (scaled force).
LOAD_PARAMS = 8
#: Weight of the planned forces' size (scaled) in the objective: it picks the smallest
#: forces that hold the object, and is small enough not to move the plan (the forces'
#: size depends on the grasp's geometry).
LOAD_REGULARISATION = 1e-4
#: Weight of the scaled normal forces' sum in the objective: a gradient that does not
#: vanish as the grip shrinks, so that IPOPT brings the squeeze to the minimum normal force
#: (without it, 1.2-1.8 N for a 1 N minimum; with it, within 0.5 %: docs/forces.md).
LOAD_PUSH_WEIGHT = 1e-2


def load_rows(P: Any, N: Any, R_po: Any, fl: Any, load_q: Any, L: Any
              ) -> tuple[list[tuple[Any, float, float]], Any]:
    """The planned forces' rows at one point: (rows as (expression, lower, upper), the
    scaled normal forces). ``P``, ``N``: the contact points and outward normals in the
    object frame (3 x nc), ``R_po`` the object's rotation, ``fl`` the point's load
    variables (:data:`LOAD_VARS` per contact), ``load_q`` the load parameters
    (:data:`LOAD_PARAMS`), ``L`` the object's size.

    Quasi-static equilibrium of the object (docs/forces.md: the inertial wrench of the
    paper's slow motions is below 1e-3 of the weight), in the object frame: the contact
    forces f_i = F0 fl_i[:3] at the points P_i, the torsion about each outward normal N_i,
    the weight at the centre (the object frame's origin); every normal force at least the
    minimum; every force inside its (smooth, narrowed) friction cone."""
    nc = int(P.shape[1])
    weight, f_min, mu_t, F0, mu_m, eps = (load_q[0:3], load_q[3], load_q[4], load_q[5],
                                          load_q[6], load_q[7])
    Fl = ca.reshape(fl, LOAD_VARS, nc)
    fs = Fl[0:3, :]  # scaled forces, object frame
    fn = -ca.sum1(N * fs)  # scaled normal forces (the push along -N)
    tors = mu_t / L * fn * Fl[3, :]  # scaled torsion moments (/ F0 L)
    w_obj = R_po.T @ weight / F0
    tang2 = ca.sum1(fs * fs) - fn * fn  # |f_t|^2 (scaled)
    # the cone, smooth: mu_m f_n >= sqrt(|f_t|^2 + eps^2), inside the cone of
    # tan(atan(mu) - margin) (never looser); eps a quarter of the smallest normal force's
    # cone radius, so the row's curvature at f_t = 0 stays moderate
    return [(ca.sum2(fs) + w_obj, 0.0, 0.0),
            (ca.sum2(ca.cross(P, fs) / L + N * ca.repmat(tors, 3, 1)), 0.0, 0.0),
            (ca.transpose(fn) - f_min / F0, 0.0, math.inf),
            (ca.transpose(mu_m * fn - ca.sqrt(tang2 + eps * eps)), 0.0, math.inf)], fn


def load_cost(fl: Any, fn: Any) -> Any:
    """One point's forces' objective (before the average over points and contacts): small
    forces that hold the object, the grip at its floor on the normals."""
    return LOAD_REGULARISATION * ca.sumsqr(fl) + LOAD_PUSH_WEIGHT * ca.sum2(fn)
