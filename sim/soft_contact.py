"""MuJoCo's soft contacts, as the execution on a user's file meets them: how a contact
pair's settings mix (``condim``, friction, ``solref``, ``solimp``, ``priority``,
``solmix``), how deep a fingertip sinks to carry a normal force at rest
(:func:`contact_depth`) and how fast it creeps while it carries a tangential one
(:func:`creep_speed`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["contact_depth", "creep_speed", "geom_settings", "pair_settings"]


def _impedance(solimp: Any, r: float) -> float:
    """MuJoCo's impedance d(r) of ``solimp`` (d0, dmax, width, mid, power) at depth r."""
    d0, dmax, width, mid, power = (float(x) for x in solimp)
    x = min(abs(r) / width, 1.0) if width > 0 else 1.0
    if x >= 1.0 or power == 1.0:
        y = x
    elif x <= mid:
        y = x ** power / mid ** (power - 1.0)
    else:
        y = 1.0 - (1.0 - x) ** power / (1.0 - mid) ** (power - 1.0)
    return d0 + y * (dmax - d0)


def contact_depth(m: Any, tip_body: int, object_body: int, force: float, solref: Any,
                  solimp: Any) -> float:
    """How deep [m] a fingertip sinks into the object in MuJoCo's soft contact to carry
    the normal ``force`` [N] at rest. MuJoCo's constraint force is ``f = (A + R)^-1 (aref
    - a0)`` with ``aref = -K d r`` at rest and ``a1 = a0 + A f = 0``, so ``R f = -K d r``:
    ``r = (1 - d) A~ f / (d^2 K)``, ``R = (1 - d) / d A~``, ``A~`` MuJoCo's approximate
    inverse inertia of the contact (the two bodies' ``body_invweight0``), ``K = 1 / (dmax^2
    timeconst^2 dampratio^2)`` of ``solref``, ``d`` the impedance of ``solimp`` at that
    depth. 0 for a direct-stiffness ``solref`` (negative), which this does not model."""
    tau, zeta = (float(x) for x in solref)
    if force <= 0.0 or tau <= 0.0 or zeta <= 0.0:
        return 0.0
    A = float(m.body_invweight0[tip_body, 0] + m.body_invweight0[object_body, 0])
    dmax = float(solimp[1])
    K = 1.0 / (dmax * dmax * tau * tau * zeta * zeta)
    r = 0.0
    for _ in range(50):  # the impedance depends on the depth: a fixed point
        imp = _impedance(solimp, r)
        r_new = (1.0 - imp) * A * force / (imp * imp * K)
        if abs(r_new - r) < 1e-10:
            return r_new
        r = r_new
    return r


def geom_settings(m: Any, g: int) -> dict[str, Any]:
    return {"condim": int(m.geom_condim[g]),
            "friction": [float(x) for x in m.geom_friction[g]],
            "solref": [float(x) for x in m.geom_solref[g]],
            "solimp": [float(x) for x in m.geom_solimp[g]],
            "margin": float(m.geom_margin[g]), "priority": int(m.geom_priority[g])}


def pair_settings(m: Any, g: int, o: int) -> dict[str, Any]:
    """MuJoCo's mix of the settings of the contact of geoms ``g`` (the hand's) and ``o``
    (the object's)."""
    pg, po = int(m.geom_priority[g]), int(m.geom_priority[o])
    if pg != po:
        win = g if pg > po else o
        s = geom_settings(m, win)
        s["margin"] = float(max(m.geom_margin[g], m.geom_margin[o]))
        return s
    w = float(m.geom_solmix[g]) / max(float(m.geom_solmix[g] + m.geom_solmix[o]), 1e-15)
    return {"condim": int(max(m.geom_condim[g], m.geom_condim[o])),
            "friction": [float(x) for x in np.maximum(m.geom_friction[g],
                                                      m.geom_friction[o])],
            "solref": [float(x) for x in w * m.geom_solref[g] + (1 - w) * m.geom_solref[o]],
            "solimp": [float(x) for x in w * m.geom_solimp[g] + (1 - w) * m.geom_solimp[o]],
            "margin": float(max(m.geom_margin[g], m.geom_margin[o])),
            "priority": pg}


def creep_speed(m: Any, d: Any, con: Any) -> float:
    """How fast [m/s] MuJoCo's contact ``con`` (of ``d.contact``) slides while it carries
    its present friction force, however far inside the cone: MuJoCo's friction is soft.
    A friction row's reference acceleration is ``-B v`` (``B`` of ``efc_KBIP``), its
    force ``f = (A + R)^-1 (aref - a0)``; carried steadily (``a1 = a0 + A f = 0``) that
    is ``R f = -B v``, ``v = R f / B`` along the row. An elliptic cone's friction rows
    are the tangent directions; a pyramid's edges ``J_n +- mu J_t`` come in pairs, the
    tangent speed ``(R+ f+ - R- f-) / (2 mu B)``. 0 with the noslip solver on
    (``noslip_iterations``: it removes that slip) or a frictionless contact."""
    import mujoco

    dim, adr = int(con.dim), int(con.efc_address)
    if dim < 3 or adr < 0 or m.opt.noslip_iterations > 0:
        return 0.0
    R, F, B = d.efc_R, d.efc_force, d.efc_KBIP[:, 1]
    v2 = 0.0
    if int(m.opt.cone) == int(mujoco.mjtCone.mjCONE_ELLIPTIC):
        for k in (1, 2):  # the two sliding directions (torsion, rolling: not a slide)
            r = adr + k
            v2 += (R[r] * F[r] / B[r]) ** 2 if B[r] > 0 else 0.0
    else:
        for k in range(2):  # the pyramid's edges of the two sliding directions
            a, b = adr + 2 * k, adr + 2 * k + 1
            mu = float(con.friction[k])
            if mu > 0 and B[a] > 0:
                v2 += ((R[a] * F[a] - R[b] * F[b]) / (2 * mu * B[a])) ** 2
    return float(np.sqrt(v2))
