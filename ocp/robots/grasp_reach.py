"""How far a grasp of round fingertips on a ball can turn it by rolling, and a grasp search.

A round fingertip (a sphere or a capsule's cap, radius r) rolling without slip or spin on a
ball (radius rho) imposes 4 conditions on its link's twist: no slip (the tip's material
point at the contact moves with the ball's: 3 rows) and no spin (the two angular
velocities agree along the contact normal: 1 row). For a finger of 4 joints that is a
square system: the ball's motion fixes the finger's. :func:`roll` integrates it while the
ball turns about an axis through its centre and stops where the motion cannot go on: a
joint at its limit, the contact at its cap's seam, or the system singular. The contact's
path then has the same length on the ball (in the ball's frame) as on the tip (in the
tip's): the rolling law, which :class:`Rolled` reports both ways. In a plane, with the tip's
centre orbiting the ball's by phi while the ball turns by theta, that path is
``s = rho (theta - phi)`` whatever the tip's own rotation: the cap's arc (at most pi r)
bounds ``theta - phi``, the finger's joints bound phi.

:func:`search_grasp` picks, per finger, the initial contact on the ball (within a cone about
a given one, so that the fingers still oppose each other) whose rolled motion about the
axis goes farthest, and combines the fingers' best so that no two caps overlap: the
initial grasp for a large turn. Its joint angles are a request's ``fingers[i].initial_q``
and :func:`contact_sides` its tips' chart sides (``hand.tips[i].side``).
docs/hands.md, "How far a fingertip grasp can turn a ball".
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ocp.geometry.bodies import segment_distance, tip_body
from ocp.robots.couplings import coupled_step, coupling_violation, project_couplings
from ocp.shapes.held import Held

__all__ = ["GraspSearch", "Rolled", "TipState", "at_tendon_bounds", "cap_bound",
           "contact_sides", "grasp_on_ball", "roll", "search_grasp", "tip_state", "tips_gap"]

FloatArray = NDArray[np.float64]

#: The largest step of the ball's turn [rad] of :func:`roll` (smaller where a joint moves
#: fast: at most 0.01 rad of any joint per step).
STEP = math.radians(0.25)


def _skew(v: FloatArray) -> FloatArray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def _cross(a: FloatArray, b: FloatArray) -> FloatArray:
    """``a x b`` of two 3-vectors (numpy's ``cross`` costs a third of :func:`roll`'s time)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
                     a[0] * b[1] - a[1] * b[0]])


def _angle(a: FloatArray, b: FloatArray) -> float:
    return math.atan2(float(np.linalg.norm(_cross(a, b))), float(a @ b))


def _rotation(axis: FloatArray, angle: float) -> FloatArray:
    K = _skew(axis)
    return np.asarray(np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K)


def _tip(f: Any) -> tuple[FloatArray, FloatArray | None, float]:
    """(the tip's centre, a capsule cap's outward axis or None, its radius), link frame
    (read once per tip surface: a gait asks it some 50 000 times)."""
    tip = f.tip_surface
    known = _TIPS.get(id(tip))
    if known is not None and known[0] is tip:
        return known[1]
    if tip.kind not in ("sphere", "capsule"):
        raise ValueError(f"rolling reach needs a sphere or capsule tip, not {tip.kind!r}")
    axis = -np.asarray(tip.R)[:, 1] if tip.kind == "capsule" else None
    out = (np.asarray(tip.p, dtype=float), axis, float(tip.params[0]))
    if len(_TIPS) >= 256:  # (a service builds hands per request: kept bounded)
        _TIPS.clear()
    _TIPS[id(tip)] = (tip, out)
    return out


#: :func:`_tip`'s answers by the tip surface's identity (the surface kept with its answer,
#: so an id reused by another object is not mistaken for it)
_TIPS: dict[int, tuple[Any, tuple[FloatArray, FloatArray | None, float]]] = {}


@dataclass(frozen=True)
class TipState:
    """A round tip against a ball at some joint angles (palm frame unless said)."""

    R_l: FloatArray      # the tip link's rotation
    p_l: FloatArray      # its origin [m]
    centre: FloatArray   # the tip's centre [m]
    n: FloatArray        # the ball's outward normal at the contact (towards the tip)
    contact: FloatArray  # the contact point [m]
    gap: float           # the tip's distance from the ball [m], negative inside
    polar: float         # a cap: the contact's angle from its end [rad] (pi/2: the seam); 0
    m: FloatArray        # the contact's direction from the tip's centre, link frame


def tip_state(f: Any, q: ArrayLike, centre: ArrayLike, radius: float,
              held: Held | None = None,
              pose: tuple[FloatArray, FloatArray] | None = None) -> TipState:
    """Finger ``f``'s round tip at joints ``q`` against the ball of ``radius`` at
    ``centre``: the contact where the line of centres meets the surfaces; against
    ``held`` (an object that is not a ball, where it is) the object's point nearest the
    tip's centre. ``pose``: the tip link's (R, p) at ``q``, when known."""
    c = np.asarray(centre, dtype=float)
    R_l, p_l = f.fingertip_pose_pin(np.asarray(q, dtype=float)) if pose is None else pose
    pc, ax, r = _tip(f)
    tc = p_l + R_l @ pc
    if held is not None and not held.ball:
        point, nrm, dist_s = held.nearest(tc[None])
        n = nrm[0]
        m = R_l.T @ (-n)
        polar = 0.0 if ax is None else math.acos(max(-1.0, min(1.0, float(m @ ax))))
        return TipState(R_l, p_l, tc, n, point[0], float(dist_s[0]) - r, polar, m)
    d = tc - c
    dist = float(np.linalg.norm(d))
    n = d / dist
    m = R_l.T @ (-n)
    polar = 0.0 if ax is None else math.acos(max(-1.0, min(1.0, float(m @ ax))))
    return TipState(R_l, p_l, tc, n, c + radius * n, dist - r - radius, polar, m)


def joint_rates(f: Any, q: FloatArray, centre: FloatArray, radius: float, omega: FloatArray,
                held: Held | None = None) -> tuple[FloatArray, float]:
    """The joint rates that roll the tip on the ball (or ``held``, where it is) turning at
    ``omega`` about its centre without slip or spin (least squares for a finger of more
    than 4 joints), with a feedback holding the tip on the object; and the system's
    condition number."""
    R_l, p_l, J = f.pose_and_jacobian_pin(q)  # J: (v of the link's origin; omega), palm
    s = tip_state(f, q, centre, radius, held, (R_l, p_l))
    Jp = J[:3] - _skew(s.contact - s.p_l) @ J[3:]  # the tip's material point at the contact
    A = np.vstack([Jp, s.n @ J[3:]])
    w = np.asarray(omega, dtype=float)
    b = np.concatenate([_cross(w, s.contact - centre) - 10.0 * s.gap * s.n,
                        [float(s.n @ omega)]])
    U, S, Vt = np.linalg.svd(A, full_matrices=False)  # one SVD: the solution and cond
    if S[-1] <= S[0] * 1e-15:
        return np.linalg.lstsq(A, b, rcond=None)[0], math.inf
    return Vt.T @ ((U.T @ b) / S), float(S[0] / S[-1])


@dataclass(frozen=True)
class Rolled:
    """A finger's rolled motion while the ball turns: how far and why it stopped."""

    reach: float     # the turn [rad] before the first stop (the whole turn if none)
    why: str         # "joint limit (<joint>)", "cap's seam", "singular", or "" (no stop)
    ball_arc: float  # the contact's path on the ball, in the ball's frame [m]
    tip_arc: float   # its path on the tip, in the tip's frame [m]
    orbit: float     # the angle [rad] the tip's centre moved about the ball's centre
    q: FloatArray    # the joints at the stop


def roll(f: Any, q0: ArrayLike, centre: ArrayLike, radius: float, axis: ArrayLike,
         max_turn: float = math.pi, margin: float = 0.0, step: float = STEP,
         held: Held | None = None) -> Rolled:
    """Finger ``f``'s motion, fixed by rolling without slip or spin, from joints ``q0``
    while the ball of ``radius`` at ``centre`` turns about ``axis`` (through its centre)
    by up to ``max_turn`` [rad]: midpoint steps of at most :data:`STEP`, until a joint
    passes its limit, the contact comes within ``margin`` [m, an arc] of its cap's seam
    (the planner keeps ``pad_margin``, 2 mm) or the system turns singular (a fold of the
    finger's motion: a joint rate without bound). A larger ``step`` (a search's coarse
    roll) allows each joint ``0.01 step / STEP`` rad per step and the tip's distance from
    the ball to drift by ``1 um (step / STEP)^2``. ``held``: an object that is not a ball
    (:class:`~ocp.shapes.held.Held`, at the turn's start, its centre ``centre``): the
    same laws on its surface, turned with it (the contact the tip's centre's nearest
    point; ``ball_arc`` is then the contact's path measured as on a ball of
    ``radius``)."""
    c = np.asarray(centre, dtype=float)
    a = np.asarray(axis, dtype=float)
    a = a / np.linalg.norm(a)
    q = np.array(q0, dtype=float)
    r = _tip(f)[2]
    seam = math.pi / 2 - margin / r
    if held is not None and held.ball:
        held = None

    def at(angle: float) -> Held | None:  # the object turned by ``angle``
        return None if held is None else held.turned(a, angle)

    s0 = prev = tip_state(f, q, c, radius, held)
    theta = ball_arc = tip_arc = 0.0
    n_ball = s0.n.copy()  # the contact's direction in the ball's frame
    h = min(step, max_turn)
    dq_max, gap_tol = 0.01 * step / STEP, 1e-6 * (step / STEP) ** 2

    def stop(why: str) -> Rolled:
        return Rolled(theta, why, ball_arc, tip_arc, _angle(s0.n, prev.n), q)

    while theta < max_turn - 1e-9:  # (a last step below 1e-9 rad is no step)
        qd1, cond = joint_rates(f, q, c, radius, a, at(theta))
        if cond > 1e6 or (h < 1e-6 and max_turn - theta > 2e-6):
            return stop("singular")
        if h < 1e-6:  # within 2e-6 rad of the whole turn: done
            break
        qd2, _ = joint_rates(f, q + h / 2 * qd1, c, radius, a, at(theta + h / 2))
        q_new = q + h * qd2
        s = tip_state(f, q_new, c, radius, at(theta + h))
        if float(np.abs(q_new - q).max()) > dq_max or abs(s.gap) > abs(s0.gap) + gap_tol:
            h /= 2  # a fast joint (near a fold of the finger's motion): smaller steps
            continue
        out = np.flatnonzero((q_new < f.lower) | (q_new > f.upper))
        if out.size:
            return stop(f"joint limit ({f.joint_names[int(out[0])]})")
        bound = [c for c in getattr(f, "couplings", ()) if not
                 c.backed_off()[0] <= float(c.row(f.joint_names) @ q_new) <= c.backed_off()[1]]
        if bound:
            return stop(f"coupling limit ({bound[0].name})")
        if s.polar > seam:
            return stop("cap's seam")
        theta += h
        nb = _rotation(a, theta).T @ s.n
        ball_arc += radius * _angle(n_ball, nb)
        tip_arc += r * _angle(prev.m, s.m)
        n_ball, prev, q = nb, s, q_new
        h = min(step, 2 * h, max_turn - theta)
    return stop("")


def cap_bound(f: Any, q: ArrayLike, centre: ArrayLike, radius: float, axis: ArrayLike
              ) -> float:
    """The turn [rad] about ``axis`` that uses up a cap if the tip's centre stayed put:
    the contact then moves over the cap along ``-(axis x n)`` by ``radius * theta *
    sin(axis, n)`` until the seam (inf when the axis is the normal: no rolling)."""
    a = np.asarray(axis, dtype=float)
    a = a / np.linalg.norm(a)
    s = tip_state(f, q, centre, radius)
    _, ax, r = _tip(f)
    u = -_cross(a, s.n)
    if np.linalg.norm(u) < 1e-9:
        return math.inf
    t = s.R_l.T @ (u / np.linalg.norm(u))
    t = t - (t @ s.m) * s.m
    t /= np.linalg.norm(t)
    if ax is None:
        arc = math.inf
    else:  # the great circle m cos(x) + t sin(x) leaves the cap where it crosses the seam
        arc = min(math.pi, math.atan2(float(s.m @ ax), -float(t @ ax)) % (2 * math.pi))
    return r * arc / (radius * math.sin(_angle(a, s.n)))


def grasp_on_ball(f: Any, q_start: ArrayLike, centre: ArrayLike, radius: float,
                  normal: ArrayLike, tol: float = 1e-7, margin: float = 0.002
                  ) -> FloatArray | None:
    """Joints (within the limits, near ``q_start``) that put finger ``f``'s round tip on
    the ball of ``radius`` at ``centre`` with the contact's outward normal ``normal``;
    None when no such joints are found (within ``tol`` [m]) or the contact is within
    ``margin`` [m, an arc] of a cap's seam."""
    c = np.asarray(centre, dtype=float)
    nrm = np.asarray(normal, dtype=float)
    pc, _, r = _tip(f)
    target = c + (radius + r) * nrm / np.linalg.norm(nrm)
    q_ref = np.asarray(q_start, dtype=float)
    q = project_couplings(f, q_ref)
    for _ in range(40):  # damped Gauss-Newton on the tip's centre, a pull towards q_start
        s = tip_state(f, q, c, radius)
        e = target - s.centre
        if np.linalg.norm(e) < 1e-6:
            break
        J = f.frame_jacobian_pin(q)
        Jc = J[:3] - _skew(s.R_l @ pc) @ J[3:]
        Ae, be = _equalities(f, q)
        A = np.vstack([Jc, Ae, 1e-3 * np.eye(f.nq)])
        dq = np.linalg.lstsq(A, np.concatenate([e, be, 1e-3 * (q_ref - q)]), rcond=None)[0]
        q = coupled_step(f, q, dq / max(1.0, float(np.abs(dq).max()) / 0.3))
    for _ in range(10):  # then onto the target exactly (least-norm steps)
        s = tip_state(f, q, c, radius)
        e = target - s.centre
        if np.linalg.norm(e) < tol / 10:
            break
        J = f.frame_jacobian_pin(q)
        Ae, be = _equalities(f, q)
        dq = np.linalg.lstsq(np.vstack([J[:3] - _skew(s.R_l @ pc) @ J[3:], Ae]),
                             np.concatenate([e, be]), rcond=None)[0]
        q = coupled_step(f, q, dq)
    s = tip_state(f, q, c, radius)
    if np.linalg.norm(s.centre - target) > tol or s.polar > math.pi / 2 - margin / r \
            or coupling_violation(f, q)[0] > 0.0:
        return None
    return np.asarray(q, dtype=float)


def _equalities(f: Any, q: FloatArray) -> tuple[FloatArray, FloatArray]:
    """The finger's equality couplings as rows of a joint step (``A dq = b`` puts each on
    its value), scaled to radians; (0, nq) without any."""
    rows, rhs = [], []
    for c in getattr(f, "couplings", ()):
        if c.lower == c.upper:
            a = c.row(f.joint_names)
            k = float(np.linalg.norm(a))
            rows.append(a / k)
            rhs.append((c.lower - float(a @ q)) / k)
    return np.array(rows).reshape(len(rows), f.nq), np.array(rhs)


def at_tendon_bounds(finger: Any, q: ArrayLike, centre: ArrayLike, radius: float
                     ) -> tuple[Any, FloatArray] | str:
    """A round-tipped finger touching a ball at joints ``q``, with each coupling that
    carries a passive joint's torque held at the bound its load needs (an equality the
    plan keeps), and the joints moved there with the contact kept: ``(finger, q)``, or why
    not (the contact cannot be kept with the tendon at that bound).

    The fingertip pushes the ball along the inward normal, so the passive joint ``p``
    needs ``tau_p = -fn (J_p . n)`` (``J_p`` its column of the contact point's Jacobian,
    ``n`` the ball's outward normal there); the tendon gives ``c_p lam``, and a limit's
    ``lam`` is positive at the tendon's lower bound (MuJoCo's sign): the lower bound when
    ``-(J_p . n) / c_p > 0``, else the upper. The finger returned is
    :meth:`~ocp.robots.finger.FingerModel.with_couplings` of the bounds (the same object
    for the same bounds: its NLPs are cached)."""
    cs = getattr(finger, "couplings", ())
    x = np.asarray(q, dtype=float)
    if not any(c.passive and c.lower < c.upper for c in cs):
        return finger, x
    c0 = np.asarray(centre, dtype=float)
    s = tip_state(finger, x, c0, radius)
    J = finger.frame_jacobian_pin(x)
    Jc = J[:3] - np.cross(s.contact - s.p_l, J[3:].T).T  # the contact point's velocity
    names = list(finger.joint_names)
    held = []
    for c in cs:
        if not c.passive or c.lower == c.upper:
            held.append(c)
            continue
        p = names.index(c.passive[0])
        cp = c.coefs[c.joints.index(c.passive[0])]
        push = -float(Jc[:, p] @ s.n) / cp
        if abs(push) < 1e-9:  # the contact does not load the joint: the nearer bound
            v = float(c.row(names) @ x)
            push = 1.0 if v - c.lower < c.upper - v else -1.0
        held.append(c.at("lower" if push > 0 else "upper"))
    bounded = finger.with_couplings(tuple(held))
    got = grasp_on_ball(bounded, x, c0, radius, s.n, tol=1e-9, margin=0.0)
    if got is None:
        named = "; ".join(f"{c.name} at its {c.held_at} bound" for c in held if c.held_at)
        return (f"the contact cannot be kept with {named} (the load on its passive joint "
                "holds the tendon there)")
    return bounded, got


def tips_gap(fingers: Sequence[Any], qs: Sequence[ArrayLike]) -> float:
    """The least distance [m] between two round tips' bodies at joints ``qs`` (< 0:
    overlap): a capsule's whole body, its cylinder too, not its cap's sphere alone
    (:mod:`ocp.geometry.bodies`)."""
    segs = []
    for f, q in zip(fingers, qs, strict=True):
        R_l, p_l = f.fingertip_pose_pin(np.asarray(q, dtype=float))
        body = tip_body(f)
        segs.append((*body.placed(R_l, p_l), body.r))
    return min((segment_distance(a0, b0, a1, b1) - r0 - r1
                for k, (a0, b0, r0) in enumerate(segs) for a1, b1, r1 in segs[k + 1:]),
               default=math.inf)


def contact_sides(fingers: Sequence[Any], qs: Sequence[ArrayLike], centre: ArrayLike,
                  radius: float) -> list[tuple[float, float, float]]:
    """Each tip's contact direction in its link frame: the ``side`` of a capsule tip's
    chart that puts the contact on the chart's equator (``TipSpec.side``)."""
    out = []
    for f, q in zip(fingers, qs, strict=True):
        m = tip_state(f, q, centre, radius).m
        out.append((float(m[0]), float(m[1]), float(m[2])))
    return out


@dataclass(frozen=True)
class GraspSearch:
    """An initial grasp for a turn: its joints per finger, each finger's rolled motion."""

    q: tuple[FloatArray, ...]
    rolled: tuple[Rolled, ...]

    @property
    def reach(self) -> float:
        """The turn [rad] the whole grasp allows: the least over its fingers."""
        return min(r.reach for r in self.rolled)


def search_grasp(fingers: Sequence[Any], q_nominal: Sequence[ArrayLike], centre: ArrayLike,
                 radius: float, axis: ArrayLike, max_turn: float = math.pi,
                 samples: int = 30, cone: float = math.radians(30.0), keep: int = 6,
                 min_gap: float = 1e-3, margin: float = 0.002, seed: int = 0
                 ) -> GraspSearch:
    """The initial grasp whose least finger reach about ``axis`` is largest: per finger,
    ``samples`` initial contacts whose normals lie within ``cone`` of the contact at
    ``q_nominal`` (which is among them), each rolled (:func:`roll`, up to ``max_turn``);
    of each finger's ``keep`` farthest, the combination with the tips at least ``min_gap``
    apart whose least reach is largest (the nominal grasp if none is). Contacts are kept
    ``margin`` [m] from the caps' seams (the planner's ``pad_margin``)."""
    rng = np.random.default_rng(seed)
    c = np.asarray(centre, dtype=float)
    per: list[list[tuple[FloatArray, Rolled]]] = []
    for f, qn in zip(fingers, q_nominal, strict=True):
        q0 = np.asarray(qn, dtype=float)
        n0 = tip_state(f, q0, c, radius).n
        cands = [q0]
        tries = 0
        while len(cands) < samples and tries < 20 * samples:
            tries += 1
            v = rng.normal(size=3)
            v -= (v @ n0) * n0
            v /= np.linalg.norm(v)
            ang = cone * math.sqrt(rng.uniform())  # uniform over the cone's cap
            q = grasp_on_ball(f, q0 + rng.normal(scale=0.3, size=f.nq), c, radius,
                              math.cos(ang) * n0 + math.sin(ang) * v, margin=margin)
            if q is not None:
                cands.append(q)
        rolled = sorted(((q, roll(f, q, c, radius, axis, max_turn, margin)) for q in cands),
                        key=lambda x: -x[1].reach)
        top = rolled[:keep]
        if not any(x[0] is q0 for x in top):
            top += [x for x in rolled if x[0] is q0]
        per.append(top)
    nominal = tuple(next(k for k, x in enumerate(p)
                         if np.array_equal(x[0], np.asarray(qn, dtype=float)))
                    for p, qn in zip(per, q_nominal, strict=True))
    best: tuple[float, tuple[int, ...]] = (-1.0, nominal)
    for combo in itertools.product(*(range(len(p)) for p in per)):
        reach = min(per[i][k][1].reach for i, k in enumerate(combo))
        if reach > best[0] and tips_gap(fingers, [per[i][k][0] for i, k in
                                                  enumerate(combo)]) >= min_gap:
            best = (reach, combo)
    return GraspSearch(tuple(per[i][k][0] for i, k in enumerate(best[1])),
                       tuple(per[i][k][1] for i, k in enumerate(best[1])))
