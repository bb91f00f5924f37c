"""The certificate's checks of a swing and of a hold (docs/gait.md, "The certificate").

Each check reads the returned motion itself, sampled densely (the swing's joints are
cubics: :meth:`~ocp.gait.swing.SwingPlan.sample`), with Pinocchio's forward kinematics
(not the CasADi expressions the NLP was built from), and names its phase and the time of
its worst sample.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from ocp.certify.certificate import Check, CheckKind
from ocp.gait.hold import Hold, hold_residuals
from ocp.gait.swing import SwingPlan
from ocp.geometry.bodies import point_segment_distance, segments_distance
from ocp.robots.couplings import coupling_violation

__all__ = ["DENSE_SAMPLES", "hold_checks", "swing_checks"]

FloatArray = NDArray[np.float64]

#: Samples per interval of a swing's grid.
DENSE_SAMPLES = 20
#: Distances [m]: how far inside the object or a required gap a sample may be.
DISTANCE_TOL = 1e-5
#: The lift-off's and approach's largest angle from the normal [rad] (where the cap's
#: centre is more than 0.05 mm from where it touches).
DIRECTION_TOL = math.radians(5.0)
#: The touch-down's distance from the landing point and gap [m].
LANDING_TOL = 1e-6
#: A force [N] or moment [N m] residual of the hold.
FORCE_TOL = 1e-6


def _check(name: str, value: float, tol: float, kind: CheckKind, t: float | None,
           t0: float, lower: bool = False) -> Check:
    return Check(name, float(value), tol, kind, lower_bound=lower,
                 time=None if t is None else float(t0 + t))


def _dense(plan: SwingPlan) -> tuple[FloatArray, ...]:
    """A swing's dense samples (times, joints, rates, accelerations), its cap's centre, its
    body's distance from the object and its gap to each other body at each, and the
    segment each is in: made once per plan (kept on it), as the gait measures a swing
    before it keeps it and again in its certificate."""
    got = plan.__dict__.get("_dense")
    if got is not None:
        return got
    sp = plan.spec
    f, body = sp.finger, sp.body
    n = len(plan.t) - 1
    ts = np.linspace(0.0, plan.duration, n * DENSE_SAMPLES + 1)
    q, v, a = plan.sample(ts)
    L = sp.radius + body.r
    placed = [body.placed(*f.fingertip_pose_pin(qi)) for qi in q]
    caps_a, ends_a = np.array([a for a, _ in placed]), np.array([b for _, b in placed])
    if sp.held is not None:  # not a ball: the body's distance from the object's surface
        dist_a = sp.held.segment_distance(caps_a, ends_a) - body.r
    else:  # from the ball's centre where it is at each sample (it may be rolling)
        dist_a = np.array([point_segment_distance(ci, ai, bi) - L for ci, ai, bi
                           in zip(sp.centre_at(ts), caps_a, ends_a, strict=True)])
    seg = np.array([plan.segment(float(t)) for t in ts])
    gaps = np.array([segments_distance(caps_a, ends_a, a1, b1) - body.r - r1
                     for a1, b1, r1 in sp.others_at(ts)]).reshape(-1, len(ts))
    got = (ts, q, v, a, caps_a, dist_a, seg, gaps)
    object.__setattr__(plan, "_dense", got)  # (a frozen plan: its own samples, unchanged)
    return got


def swing_checks(plan: SwingPlan, label: str, t0: float = 0.0) -> list[Check]:
    """The laws of a swing (named ``<check>_<label>``, ``label`` the phase's name; times
    from the plan's start, the swing starting at ``t0``)."""
    sp = plan.spec
    f = sp.finger
    ts, q, v, a, caps_a, dist_a, seg, gaps = _dense(plan)
    out: list[Check] = []
    clear = np.flatnonzero(seg == "clear")
    k = int(clear[np.argmin(dist_a[clear])])
    out.append(_check(f"swing_clearance_{label}", dist_a[k], sp.clearance - DISTANCE_TOL,
                      CheckKind.PHYSICS, ts[k], t0, lower=True))
    k = int(np.argmin(dist_a))
    out.append(_check(f"swing_penetration_{label}", dist_a[k], -DISTANCE_TOL,
                      CheckKind.PHYSICS, ts[k], t0, lower=True))
    a_land = sp.landing_point()
    n0, n1 = sp.start_normal(), sp.landing_normal / np.linalg.norm(sp.landing_normal)
    worst, t_worst = 0.0, 0.0
    for part, ref, nrm in (("lift", caps_a[0], n0), ("approach", a_land, n1)):
        for i in np.flatnonzero(seg == part):
            d = caps_a[i] - ref
            if np.linalg.norm(d) > 5e-5:
                ang = math.acos(float(np.clip(d @ nrm / np.linalg.norm(d), -1.0, 1.0)))
                if ang > worst:
                    worst, t_worst = ang, ts[i]
    out.append(_check(f"swing_direction_{label}", worst, DIRECTION_TOL, CheckKind.PHYSICS,
                      t_worst, t0))
    out.append(_check(f"swing_landing_{label}",
                      max(float(np.linalg.norm(caps_a[-1] - a_land)), abs(dist_a[-1])),
                      LANDING_TOL, CheckKind.PHYSICS, ts[-1], t0))
    rest = max(float(np.abs(v[[0, -1]]).max()), float(np.abs(a[[0, -1]]).max()))
    out.append(_check(f"swing_rest_{label}", rest, 1e-9, CheckKind.PHYSICS, None, t0))
    for j, (gap, need) in enumerate(zip(gaps, sp.required_gaps(), strict=True)):
        k = int(np.argmin(gap))
        out.append(_check(f"swing_tip_gap_{label}_{j}", gap[k], need - DISTANCE_TOL,
                          CheckKind.PHYSICS, ts[k], t0, lower=True))
    lo, hi = np.asarray(f.lower), np.asarray(f.upper)
    over = np.maximum(lo - q, q - hi).max(axis=1)
    k = int(np.argmax(over))
    out.append(_check(f"swing_joint_limits_{label}", over[k], 0.0, CheckKind.LIMITS, ts[k],
                      t0))
    if getattr(f, "couplings", ()):  # the finger's joint couplings [m of tendon]
        over_c = coupling_violation(f, q)
        k = int(np.argmax(over_c))
        out.append(_check(f"swing_coupling_{label}", over_c[k], 1e-6, CheckKind.LIMITS,
                          ts[k], t0))
    vmax = np.asarray(f.velocity_limit, dtype=float)
    over_v = (np.abs(v) / vmax).max(axis=1)
    k = int(np.argmax(over_v))
    out.append(_check(f"swing_velocity_{label}", over_v[k], 1.0 + 1e-9, CheckKind.LIMITS,
                      ts[k], t0))
    acc = np.abs(a).max(axis=1)
    k = int(np.argmax(acc))
    out.append(_check(f"swing_acceleration_{label}", acc[k],
                      sp.max_joint_acceleration * (1 + 1e-9), CheckKind.LIMITS, ts[k], t0))
    return out


def hold_checks(hold: Hold, forces: FloatArray, load: FloatArray, min_normal: FloatArray,
                label: str, t: float) -> list[Check]:
    """The hold's laws for ``forces`` (palm frame, per contact) at time ``t``: equilibrium
    with the weight, the normal forces over ``min_normal``, inside the narrowed cones."""
    res = hold_residuals(hold, forces, load, min_normal)
    return [Check(f"hold_equilibrium_{label}", res.equilibrium, FORCE_TOL, CheckKind.PHYSICS,
                  time=t),
            Check(f"hold_normal_force_{label}", res.normal_margin, -FORCE_TOL,
                  CheckKind.PHYSICS, lower_bound=True, time=t),
            Check(f"hold_cone_{label}", res.cone_margin, -FORCE_TOL, CheckKind.PHYSICS,
                  lower_bound=True, time=t)]
