"""Couplings of a hand's joints as MuJoCo reads them (issue 37, item 3): linear relations
between a finger's joints that every plan keeps.

A coupling is ``lower <= sum_i c_i q_i <= upper`` over the joints of one finger:

* a limited **fixed tendon** over two or more joints: its length ``sum_i coef_i q_i``
  (MuJoCo's fixed tendon) within its ``range`` [m of tendon, or whatever unit its
  coefficients give] -- the Shadow hand's ``T_FFJ1c`` keeps the distal joint J0 within
  1 mm of tendon of 0.00805/0.00705 times J1;
* an ``<equality><joint>`` whose polynomial is linear: ``q1 - q1_0 = a0 + a1 (q2 - q2_0)``
  (``q_0`` the joints' ``qpos0``), or ``q1 - q1_0 = a0`` without ``joint2``: an equality,
  ``lower == upper``;
* an ``<equality><tendon>`` of fixed tendons, linear: ``L1 - L1_0 = a0 + a1 (L2 - L2_0)``
  (``L_0`` the tendons' lengths at ``qpos0``).

Joints held out of the plan (a wrist shared by all fingers) enter at their held values, as
constants. A fixed tendon over one joint is that joint's limit, not a coupling
(:func:`ocp.robots.whole_hand.tendon_limits`). What this does not plan is refused before
anything is built, each naming the element (:func:`ocp.robots.whole_hand.model_problems`):
a coupling of two fingers' joints, a polynomial of higher degree, a spatial tendon that is
limited, held or driven, a tendon over several joints driven by an actuator, a weld or
connect equality.

The planner keeps each coupling at every collocation point (backed off by
:data:`COUPLING_MARGIN` so that the motion between them keeps it too) and the certificate
checks it at every returned sample (``max_coupling_violation_*``, in the coupling's own
unit: metres of tendon).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["COUPLING_MARGIN", "Coupling", "coupled_step", "coupling_violation",
           "hand_couplings", "project_couplings", "tendon_torque_bounds"]

FloatArray = NDArray[np.float64]

#: The share of a coupling's band (at most :data:`COUPLING_MARGIN_ABS` of its value) the
#: planner keeps inside it at the collocation points.
COUPLING_MARGIN = 0.01
#: ... in the coupling's own unit [m of tendon, rad].
COUPLING_MARGIN_ABS = 1e-6
#: The least torque [N m] a roll's forces ask of a passive joint held by its tendon's
#: bound, of the sign that bound gives (:func:`tendon_torque_bounds`).
PASSIVE_MARGIN = 5e-3


@dataclass(frozen=True)
class Coupling:
    """``lower <= coefs . q[joints] <= upper``: one linear coupling of a finger's joints
    (``joints`` in the file's names; held joints already folded into the bounds).
    ``name`` says what the file calls it (``tendon 'T_FFJ1c'``)."""

    name: str
    joints: tuple[str, ...]
    coefs: tuple[float, ...]
    lower: float
    upper: float
    #: its joints no actuator drives (the Shadow hand's J0): their torque comes from the
    #: tendon's limit, which pulls only at a bound (:func:`ocp.robots.grasp_reach.at_tendon_bounds`)
    passive: tuple[str, ...] = ()
    #: the band's bound a passive joint's load holds it at ("lower", "upper"; "": none)
    held_at: str = ""

    def at(self, bound: str) -> Coupling:
        """The coupling held at its ``bound`` ("lower" or "upper"): an equality."""
        value = self.lower if bound == "lower" else self.upper
        return replace(self, lower=value, upper=value, held_at=bound)

    def row(self, joint_names: Sequence[str]) -> FloatArray:
        """Its coefficients over ``joint_names`` (zero for the joints it does not have)."""
        out = np.zeros(len(joint_names))
        for j, c in zip(self.joints, self.coefs, strict=True):
            out[list(joint_names).index(j)] += c
        return out

    def backed_off(self) -> tuple[float, float]:
        """Its bounds at the planner's collocation points (:data:`COUPLING_MARGIN`)."""
        if self.upper - self.lower <= 0.0:
            return self.lower, self.upper
        back = min(COUPLING_MARGIN_ABS, COUPLING_MARGIN * (self.upper - self.lower))
        return self.lower + back, self.upper - back

    def describe(self) -> str:
        terms = " + ".join(f"{c:.6g} {j}" for j, c in zip(self.joints, self.coefs,
                                                           strict=True))
        band = f"= {self.lower:.6g}" if self.lower == self.upper else \
            f"in {self.lower:.6g}..{self.upper:.6g}"
        return f"{self.name}: {terms} {band}"


def coupling_violation(finger: Any, q: ArrayLike) -> FloatArray:
    """Per sample (rows of ``q``), how far the finger's couplings are outside their bounds
    at worst [the couplings' unit; 0 inside, and 0 for a finger without couplings]."""
    Q = np.atleast_2d(np.asarray(q, dtype=float))
    out = np.zeros(len(Q))
    for c in getattr(finger, "couplings", ()):
        v = Q @ c.row(finger.joint_names)
        out = np.maximum(out, np.maximum(v - c.upper, c.lower - v))
    return np.maximum(out, 0.0)


def project_couplings(finger: Any, q: ArrayLike, margin: bool = True,
                      sweeps: int = 50) -> FloatArray:
    """``q`` within the finger's joint limits and its couplings (backed off when
    ``margin``): alternating projections onto the limits' box and each coupling's band
    (exact for one coupling inside the box; the nearest point for the usual few)."""
    x = np.clip(np.asarray(q, dtype=float), finger.lower, finger.upper)
    cs = getattr(finger, "couplings", ())
    if not cs:
        return x
    rows = [(c.row(finger.joint_names), *(c.backed_off() if margin else
                                          (c.lower, c.upper))) for c in cs]
    for _ in range(sweeps):
        moved = 0.0
        for a, lo, hi in rows:
            v = float(a @ x)
            d = (lo - v) if v < lo else (hi - v) if v > hi else 0.0
            if d:
                x = x + d * a / float(a @ a)
                moved = max(moved, abs(d))
        x = np.clip(x, finger.lower, finger.upper)
        if moved < 1e-12:
            break
    return x


def hand_couplings(text: str, fingers: Sequence[Sequence[str]], held: dict[str, float]
                   ) -> tuple[list[tuple[Coupling, ...]], list[str]]:
    """The couplings of an MJCF hand (module docstring) as MuJoCo compiles ``text``, per
    finger (``fingers``: each finger's joint names), and the reasons any cannot be planned
    (a coupling of two fingers, a joint of none). MuJoCo must be installed."""
    import mujoco

    from ocp.robots.mjcf_frames import mujoco_text

    m = mujoco.MjModel.from_xml_string(mujoco_text(text))
    obj = mujoco.mjtObj
    qpos0 = np.asarray(m.qpos0, dtype=float)

    def joint_name(j: int) -> str:
        return mujoco.mj_id2name(m, obj.mjOBJ_JOINT, j) or f"joint {j}"

    def tendon_terms(t: int) -> list[tuple[str, float]] | None:
        adr, num = int(m.tendon_adr[t]), int(m.tendon_num[t])
        out = []
        for w in range(adr, adr + num):
            if int(m.wrap_type[w]) != int(mujoco.mjtWrap.mjWRAP_JOINT):
                return None
            out.append((joint_name(int(m.wrap_objid[w])), float(m.wrap_prm[w])))
        return out

    def q0(name: str) -> float:
        return float(qpos0[int(m.jnt_qposadr[mujoco.mj_name2id(m, obj.mjOBJ_JOINT, name)])])

    found: list[Coupling] = []
    for t in range(m.ntendon):
        terms = tendon_terms(t)
        if terms is None or len(terms) < 2 or not m.tendon_limited[t]:
            continue
        lo, hi = (float(x) for x in m.tendon_range[t])
        name = mujoco.mj_id2name(m, obj.mjOBJ_TENDON, t) or f"tendon {t}"
        found.append(Coupling(f"tendon {name!r}", tuple(j for j, _ in terms),
                              tuple(c for _, c in terms), lo, hi))
    for e in range(m.neq):
        if not bool(m.eq_active0[e]):
            continue
        kind = int(m.eq_type[e])
        a0, a1 = float(m.eq_data[e, 0]), float(m.eq_data[e, 1])
        name = mujoco.mj_id2name(m, obj.mjOBJ_EQUALITY, e)
        label = f" {name!r}" if name else f" {e}"
        i1, i2 = int(m.eq_obj1id[e]), int(m.eq_obj2id[e])
        if kind == int(mujoco.mjtEq.mjEQ_JOINT):
            j1 = joint_name(i1)
            joints, coefs = [j1], [1.0]
            value = a0 + q0(j1)
            if i2 >= 0:
                j2 = joint_name(i2)
                joints.append(j2)
                coefs.append(-a1)
                value -= a1 * q0(j2)
            found.append(Coupling(f"<equality><joint>{label}", tuple(joints),
                                  tuple(coefs), value, value))
        elif kind == int(mujoco.mjtEq.mjEQ_TENDON):
            t1 = tendon_terms(i1)
            if t1 is None:
                continue  # refused by model_problems
            joints = [j for j, _ in t1]
            coefs = [c for _, c in t1]
            value = a0 + float(m.tendon_length0[i1])
            if i2 >= 0:
                t2 = tendon_terms(i2)
                if t2 is None:
                    continue
                joints += [j for j, _ in t2]
                coefs += [-a1 * c for _, c in t2]
                value -= a1 * float(m.tendon_length0[i2])
            found.append(Coupling(f"<equality><tendon>{label}", tuple(joints),
                                  tuple(coefs), value, value))
    driven = {joint_name(int(m.actuator_trnid[a, 0])) for a in range(m.nu)
              if int(m.actuator_trntype[a]) == int(mujoco.mjtTrn.mjTRN_JOINT)}
    per: list[list[Coupling]] = [[] for _ in fingers]
    errs: list[str] = []
    for c in found:
        shift = sum(k * held[j] for j, k in zip(c.joints, c.coefs, strict=True)
                    if j in held)
        own = [(j, k) for j, k in zip(c.joints, c.coefs, strict=True) if j not in held]
        owners = {i for i, names in enumerate(fingers) for j, _ in own if j in names}
        outside = [j for j, _ in own if not any(j in names for names in fingers)]
        if not owners:
            continue  # held joints or joints of fingers not planned: nothing to plan
        if len(owners) > 1 or outside:
            where = f"joint {outside[0]!r}, of no planned finger" if outside else \
                "joints of " + " and ".join(f"the finger of {fingers[i][-1]!r}"
                                            for i in sorted(owners))
            errs.append(f"{c.name} couples {where}: couplings across fingers are not "
                        "planned, so this hand is refused")
            continue
        merged: dict[str, float] = {}
        for j, k in own:
            merged[j] = merged.get(j, 0.0) + k
        passive = tuple(j for j in merged if j not in driven) if m.nu else ()
        per[owners.pop()].append(Coupling(c.name, tuple(merged), tuple(merged.values()),
                                          c.lower - shift, c.upper - shift, passive))
    return [tuple(p) for p in per], errs


def coupled_step(finger: Any, q: ArrayLike, dq: ArrayLike) -> FloatArray:
    """``q + dq`` kept within the finger's couplings and joint limits: the step's part
    that would push a coupling already at its bound further out is removed first (so that
    a Gauss-Newton iteration slides along the bound), then the result is projected
    (:func:`project_couplings`, at the bounds themselves)."""
    x = np.asarray(q, dtype=float)
    d = np.asarray(dq, dtype=float)
    cs = getattr(finger, "couplings", ())
    if not cs:
        return np.clip(x + d, finger.lower, finger.upper)
    active = []
    for c in cs:
        a = c.row(finger.joint_names)
        v, s = float(a @ x), float(a @ d)
        if (v >= c.upper - 1e-12 and s > 0.0) or (v <= c.lower + 1e-12 and s < 0.0):
            active.append(a)
    if active:
        A = np.array(active)
        d = d - A.T @ np.linalg.lstsq(A @ A.T, A @ d, rcond=None)[0]
    return project_couplings(finger, x + d, margin=False)


def tendon_torque_bounds(finger: Any, lower: ArrayLike, upper: ArrayLike
                         ) -> tuple[FloatArray, FloatArray]:
    """Joint torque bounds (``lower``, ``upper``: the finger's joints on the last axis,
    samples on any before it) with each passive joint whose tendon is held at a bound
    (:func:`ocp.robots.grasp_reach.at_tendon_bounds`) given the sign that bound's force
    can give: ``c_p tau_p >= 0`` at the lower bound (the limit's force ``lam = tau_p /
    c_p >= 0``), ``<= 0`` at the upper, with :data:`PASSIVE_MARGIN` to spare (for what
    happens between the forces' stage's points; the stage counts the hand's own torques
    at them: ``ocp.solve.force_plan._model_torques``)."""
    lo, hi = np.array(lower, dtype=float), np.array(upper, dtype=float)
    names = list(finger.joint_names)
    for c in getattr(finger, "couplings", ()):
        for p in c.passive if c.held_at else ():
            k = names.index(p)
            sign = np.sign(c.coefs[c.joints.index(p)]) * (1 if c.held_at == "lower" else -1)
            if sign > 0:
                lo[..., k] = np.maximum(lo[..., k], PASSIVE_MARGIN)
            else:
                hi[..., k] = np.minimum(hi[..., k], -PASSIVE_MARGIN)
    return lo, hi
