"""The swing of a fingertip: lifted off the still object, carried clear, landed elsewhere
(docs/gait.md, "The swing").

One finger moves; the object and the other fingers are still (they hold the object:
:mod:`ocp.gait.hold`). The finger's joints are a jerk-driven triple integrator on a grid
(states q, q_dot, q_ddot at the nodes, a constant jerk on each interval, integrated
exactly), so the joint angles are cubic, the rates quadratic and the accelerations
continuous and piecewise linear: the acceleration limit holds everywhere where it holds
at the nodes, and the swing starts and ends at rest with zero acceleration (its switches
to the neighbouring phases are continuous up to the accelerations).

The rows (at the nodes; the certificate samples the returned cubic densely):

* **lift-off** (the first ``lift`` intervals): the cap's centre moves along the object's
  normal at the contact it leaves (two tangential rows zero, the normal one >= 0), the
  tip's body never inside the object (a ball's distance; on an object that is not a
  ball, whose distance the NLP has only a lower bound of, which is below the cap's own
  at the surface, the cap's centre going out along the normal keeps it out of a convex
  object, and the certificate measures the body's true distance);
* **clear** (between lift-off and approach): the tip's body (sphere or capsule,
  :mod:`ocp.geometry.bodies`) at least ``clearance`` from the object (an object that is
  not a ball: by the shape's lower bound on the body's distance,
  :meth:`~ocp.shapes.Shape.segment_clearance`);
* **approach** (the last ``lift`` intervals): along the landing normal to the landing
  point, never inside the object;
* **touch-down**: the cap's centre exactly over the landing point at the tip's radius
  (its surface touches the object there), the contact on the cap (not its cylinder), at
  rest (zero relative normal speed: the object is still);
* **the other fingertips**: the tip's body at least ``min(tip_gap, 90 % of the gap at
  the start and at the landing)`` from each of theirs, at every node (``tip_gap``: the
  clearance unless given; :func:`~ocp.gait.step.replace_finger` tries
  :data:`MIN_TIP_GAP` when the clearance admits no swing);
* joint limits (backed off as the rolling plan's) and velocity limits at the nodes, and
  between them exactly: each interval's cubic lies in the convex hull of its Bezier
  control points, bounded by the limits themselves (the rate's quadratic likewise); the
  acceleration limit;
* **the actuators against the joints' damping** (a hand file whose joints are damped:
  :class:`SwingDrive`, the spec's ``drive``): at every node and interval midpoint the
  torque ``c q_dot`` the damping asks of each joint's actuator within what it gives
  there: its torque range, and for a servo whose control is limited the torques its
  control range reaches at that joint angle (a position servo near the end of its
  range gives little toward it, so the swing moves slowly there or away from it).

The objective: the jerk's integral (squared, scaled), and the landing joints near the
target's (the landing point fixes the cap's centre; a 4-joint finger keeps one degree of
freedom there).
"""

from __future__ import annotations

import hashlib
import math
import time
from collections import OrderedDict
from dataclasses import dataclass, field, fields, replace
from typing import Any

import casadi as ca
import numpy as np
from numpy.typing import NDArray

from ocp.contacts.base import backed_off_joint_limits
from ocp.geometry.bodies import TipBody, point_segment_distance, segment_distance, tip_body
from ocp.shapes.base import CLEARANCE_PARAMS

__all__ = ["SwingDrive", "SwingPlan", "SwingSpec", "plan_swing", "prepare_swings",
           "swing_key"]

FloatArray = NDArray[np.float64]

#: The least gap [m] from the other tips a swing falls back to when the clearance admits
#: none (the middle fingertip between two neighbours 1.8 mm away: docs/gait.md).
MIN_TIP_GAP = 1e-3
#: The share of a close neighbour's gap (at the start or at the landing) the last
#: fallback keeps: a roll cut where two tips come within 0.5 mm leaves one to lift off
#: from 0.5 mm, and lifting along its normal may close on the neighbour by more than the
#: tenth the first two allow (docs/gait.md, "Rolls and tips").
NARROW_SHARE = 0.5
#: The weight added to the landing joints' distance from the target's in a swing with the
#: actuators' rows (:class:`SwingDrive`; 10 in every swing): at its rate bound the jerk
#: costs more, and traded for it a 4-joint finger landed 8-19 mrad from the target's
#: joints on the same point (the grasp the gait's next roll starts from: about +x on the
#: MJCF hand a roll of 131 IPOPT iterations and one roll more).
DRIVEN_LANDING_WEIGHT = 1e3
#: Points of the moving tip's segment at which its distance to another tip is kept.
SEGMENT_SAMPLES = 5
#: IPOPT's options for a swing. ``expect_infeasible_problem``: its restoration phase
#: called sooner, and left only with more of the rows' violation removed; a swing tried
#: too short, or from where its landing is out of reach, is infeasible, and many a gait
#: asks such swings (their lengths tried in turn, the stranded checks): about +z with the
#: overlap options 1771 -> 1111 IPOPT iterations in the 33 swing solves, the same plan
#: (docs/gait.md, session 32).
_IPOPT: dict[str, Any] = {"print_time": False, "ipopt.print_level": 0, "ipopt.sb": "yes",
                          "ipopt.tol": 1e-9, "ipopt.constr_viol_tol": 1e-10,
                          "ipopt.max_iter": 500, "ipopt.expect_infeasible_problem": "yes"}
#: Added for a swing started from a previous swing's primal-dual point (the same finger's
#: previous swing in a gait: the grasp recurs, so it is nearly this one's optimum).
_IPOPT_WARM: dict[str, Any] = {"ipopt.warm_start_init_point": "yes", "ipopt.mu_init": 1e-6,
                               "ipopt.warm_start_bound_push": 1e-9,
                               "ipopt.warm_start_bound_frac": 1e-9,
                               "ipopt.warm_start_slack_bound_push": 1e-9,
                               "ipopt.warm_start_slack_bound_frac": 1e-9,
                               "ipopt.warm_start_mult_bound_push": 1e-9}


@dataclass(frozen=True)
class SwingDrive:
    """What a finger's actuators give its joints' viscous damping, per joint: a joint
    moving at the rate ``v`` asks ``damping * v`` [N m] of its actuator, which gives
    ``torque_lower .. torque_upper`` (its torque range, times the share the gait keeps to)
    and, where its control is limited, ``slope * q + end_lower .. slope * q + end_upper``
    at the joint angle ``q`` (a servo's control range reached there: a position servo of
    stiffness kp has slope -kp; infinite ends without a limited control). The swing's NLP
    keeps ``damping * v`` inside both at its nodes and interval midpoints
    (:meth:`~ocp.gait.step.TorqueLimits.drive` makes one from the gait's limits)."""

    damping: FloatArray
    slope: FloatArray
    end_lower: FloatArray
    end_upper: FloatArray
    torque_lower: FloatArray
    torque_upper: FloatArray

    def row_bounds(self) -> tuple[FloatArray, FloatArray]:
        """(lower, upper) of one point's rows, per joint the control's row ``damping * v
        - slope * q`` then the torque's ``damping * v`` (as :func:`_swing_nlp` orders
        them); infinite where a joint has no damping."""
        c = np.asarray(self.damping, dtype=float)
        on = c > 0
        inf = np.full(c.shape, np.inf)
        lo = np.stack([np.where(on, self.end_lower, -inf),
                       np.where(on, self.torque_lower, -inf)], axis=1).ravel()
        hi = np.stack([np.where(on, self.end_upper, inf),
                       np.where(on, self.torque_upper, inf)], axis=1).ravel()
        return lo, hi

    def digest(self) -> bytes:
        return b"".join(np.ascontiguousarray(getattr(self, f.name), dtype=float).tobytes()
                        for f in fields(self))


@dataclass(frozen=True)
class SwingSpec:
    """One fingertip's swing. ``finger``: its model (:class:`~ocp.robots.finger.
    FingerModel`, a sphere or capsule tip); ``q_start``: its joints, touching the object;
    ``q_target``: joints near the landing (the seed; its cap need not touch);
    ``landing_normal``: the object's outward normal where it lands (palm frame); the
    object, a ball of ``radius`` at ``centre`` (palm frame, still); ``others``: the other
    fingertips' bodies as palm-frame segments (a, b, r), still."""

    finger: Any
    q_start: FloatArray
    q_target: FloatArray
    landing_normal: FloatArray
    centre: FloatArray
    radius: float
    others: tuple[tuple[FloatArray, FloatArray, float], ...] = ()
    duration: float = 0.8
    n_intervals: int = 24
    #: intervals of the lift-off and of the approach, each
    lift_intervals: int = 4
    clearance: float = 0.003
    max_joint_acceleration: float = 20.0
    #: the landing contact's least arc from the cap's seam [m]
    cap_margin: float = 0.002
    #: the least gap [m] kept from the other tips (None: ``clearance``), or
    #: ``neighbour_share`` of the gap at the start or at the landing if smaller
    tip_gap: float | None = None
    neighbour_share: float = 0.9
    #: the finger's name and the other fingertips' (``others``' order), for messages
    name: str = ""
    other_names: tuple[str, ...] = ()
    #: ``duration`` is an upper bound: the swing found is timed as fast as the joints'
    #: velocity and acceleration limits (and the actuators' damping) allow, not below
    #: :data:`MIN_SWING` (:meth:`SwingPlan.scaled`)
    fastest: bool = False
    #: the other bodies moving (a swing while the other fingertips roll the object:
    #: :mod:`ocp.gait.overlap`): ``moving(t)`` gives, at the times ``t`` [s from the
    #: swing's start], each of ``others``' segment ends (a (len(t), 3), b (len(t), 3)),
    #: their radii ``others``'; None: they are still where ``others`` puts them
    moving: Any = field(default=None, compare=False, repr=False)
    #: the object's centre moving during the swing (a roll's: it moves within its
    #: tracking): ``centre_path(t)`` its positions (len(t), 3) at the times ``t`` [s from
    #: the swing's start], which the certificate measures the swing against; None: still
    #: at ``centre`` (the NLP keeps its clearance from ``centre``, the landing's)
    centre_path: Any = field(default=None, compare=False, repr=False)
    #: kept [m] beyond the clearance and the gaps at the NLP's nodes (the certificate
    #: checks them without it, between the nodes too: bodies that move between the nodes
    #: bring the least distance there, 10 um measured)
    node_margin: float = 0.0
    #: kept [m] beyond the clearance and every gap at the NLP's nodes, whatever room a
    #: close neighbour leaves: what an earlier plan of this swing lacked between its nodes
    #: (:func:`~ocp.gait.step.between_nodes`), and a little more
    dip: float = 0.0
    #: the object when it is not a ball (:class:`~ocp.shapes.held.Held`, still: its centre
    #: ``centre``): the contacts and distances are its surface's, the NLP keeps its
    #: clearance by the shape's distance bound; None: a ball of ``radius``
    held: Any = field(default=None, compare=False, repr=False)
    #: where the cap touches down on an object that is not a ball (palm frame; a ball's
    #: is where the landing normal meets it)
    landing_contact: Any = field(default=None, compare=False, repr=False)
    #: the actuators against the joints' damping (:class:`SwingDrive`), kept at the NLP's
    #: nodes and midpoints (a variant of the finger's swing NLP with those rows); None:
    #: not in the NLP (a gait without damped joints, or a swing first planned without and
    #: checked after: :meth:`~ocp.gait.step.TorqueLimits.damping_overrun`)
    drive: SwingDrive | None = field(default=None, compare=False, repr=False)

    @property
    def body(self) -> TipBody:
        return tip_body(self.finger)

    def start_normal(self) -> FloatArray:
        """The object's outward normal where the tip leaves it (through the cap's centre;
        the object where it is at the swing's start)."""
        R, p = self.finger.fingertip_pose_pin(self.q_start)
        a = p + R @ self.body.a
        if self.held is not None:
            return np.asarray(self.held.nearest(a[None])[1][0], dtype=float)
        c = self.centre_at([0.0])[0]
        return (a - c) / np.linalg.norm(a - c)

    def landing_point(self) -> FloatArray:
        """Where the cap's centre is at touch-down (palm frame)."""
        n = np.asarray(self.landing_normal, dtype=float)
        if self.held is not None:
            return np.asarray(self.landing_contact, dtype=float) + \
                self.body.r * n / np.linalg.norm(n)
        return self.centre + (self.radius + self.body.r) * n / np.linalg.norm(n)

    def centre_at(self, t: Any) -> FloatArray:
        """The object's centre at the times ``t`` [s from the swing's start] (rows)."""
        tt = np.atleast_1d(np.asarray(t, dtype=float))
        if self.centre_path is None:
            return np.tile(np.asarray(self.centre, dtype=float), (tt.size, 1))
        return np.asarray(self.centre_path(tt), dtype=float).reshape(tt.size, 3)

    def others_at(self, t: Any) -> list[tuple[FloatArray, FloatArray, float]]:
        """Each other body at the times ``t`` [s from the swing's start] (rows): its
        segment's ends (a, b) and radius; still ones repeated."""
        tt = np.atleast_1d(np.asarray(t, dtype=float))
        if self.moving is None:
            return [(np.tile(a1, (tt.size, 1)), np.tile(b1, (tt.size, 1)), r1)
                    for a1, b1, r1 in self.others]
        return [(np.asarray(a, dtype=float), np.asarray(b, dtype=float), r1)
                for (a, b), (_, _, r1) in zip(self.moving(tt), self.others, strict=True)]

    def required_gaps(self) -> tuple[float, ...]:
        """The least distance kept from each other tip: ``tip_gap`` (None: ``clearance``),
        or ``neighbour_share`` of the gap at the start or at the landing if smaller (the
        others where they are at the start and at the landing), never below zero: a
        landing inside another fingertip (the farthest landings, which a neighbour may
        have rolled into: four_finger_gait-004 landed 2.1 mm inside one) is no swing."""
        out = []
        want = self.clearance if self.tip_gap is None else self.tip_gap
        start, end = self.others_at([0.0]), self.others_at([self.duration])
        for (a0, b0, r1), (a1, b1, _) in zip(start, end, strict=True):
            gaps = [_body_gap(self.finger, self.body, self.q_start, a0[0], b0[0], r1),
                    _body_gap(self.finger, self.body, self.q_target, a1[0], b1[0], r1)]
            out.append(max(0.0, min(want, self.neighbour_share * min(gaps))))
        return tuple(out)


def _body_gap(finger: Any, body: TipBody, q: FloatArray, a1: FloatArray, b1: FloatArray,
              r1: float) -> float:
    R, p = finger.fingertip_pose_pin(q)
    a0, b0 = body.placed(R, p)
    return segment_distance(a0, b0, a1, b1) - body.r - r1


#: The shortest swing [s] a ``fastest`` swing is timed to.
MIN_SWING = 0.15


@dataclass(frozen=True)
class SwingPlan:
    """A swing's joint motion on its grid (nodes at ``t``): angles ``Q``, rates ``V``,
    accelerations ``A`` (rows = nodes), the jerk ``J`` of each interval; the status
    (``"solved"`` or why not) and IPOPT's iterations and time."""

    spec: SwingSpec
    status: str
    message: str
    t: FloatArray
    Q: FloatArray
    V: FloatArray
    A: FloatArray
    J: FloatArray
    iterations: int
    solve_time: float
    #: IPOPT's primal-dual point (scaled variables, multipliers of the bounds and rows):
    #: the warm start of the next swing of this finger (:func:`plan_swing`)
    point: tuple[FloatArray, FloatArray, FloatArray] | None = field(default=None,
                                                                     repr=False)
    #: a swing not found because of another body: its index in ``spec.others`` (the
    #: gap the last iterate breaks most is that body's), else None
    blocked_by: int | None = None
    #: a swing not found: whether its last iterate breaks a gap to another body (else
    #: only the ball's clearance, the joints' motion, ...: narrowing the gaps kept from
    #: the other bodies is no remedy)
    gap_broken: bool = False

    @property
    def ok(self) -> bool:
        return self.status == "solved"

    @property
    def duration(self) -> float:
        return float(self.t[-1])

    def sample(self, t: Any) -> tuple[FloatArray, FloatArray, FloatArray]:
        """(q, q_dot, q_ddot) at times ``t`` [s from the swing's start]: the returned cubic
        itself (rows = times)."""
        tt = np.clip(np.atleast_1d(np.asarray(t, dtype=float)), 0.0, self.duration)
        h = self.duration / (len(self.t) - 1)
        k = np.minimum((tt / h).astype(int), len(self.t) - 2)
        s = (tt - self.t[k])[:, None]
        q, v, a, j = self.Q[k], self.V[k], self.A[k], self.J[k]
        return (q + v * s + a * s**2 / 2 + j * s**3 / 6, v + a * s + j * s**2 / 2, a + j * s)

    def scaled(self, factor: float) -> SwingPlan:
        """The same path in ``factor`` times the time: rates divided by ``factor``,
        accelerations by its square, the jerk by its cube (every check of the path --
        clearance, gaps, limits, landing -- holds as it did; its IPOPT point, in the
        NLP's duration-scaled variables, is the same)."""
        f = float(factor)
        if self.spec.moving is not None:
            raise ValueError("a swing among moving bodies keeps their times: not scaled")
        return replace(self, spec=replace(self.spec, duration=self.spec.duration * f),
                       t=self.t * f, V=self.V / f, A=self.A / f**2, J=self.J / f**3)

    def fastest_factor(self) -> float:
        """The least time factor within the finger's joint velocity limits and the
        spec's ``max_joint_acceleration`` (below 1: the swing can be made faster)."""
        vmax = np.asarray(self.spec.finger.velocity_limit, dtype=float)
        v = float(np.max(np.abs(self.V) / vmax, initial=0.0))
        a = float(np.max(np.abs(self.A), initial=0.0)) / self.spec.max_joint_acceleration
        return max(v, math.sqrt(a))

    def segment(self, t: float) -> str:
        """Which part of the swing ``t`` is in: ``lift``, ``clear`` or ``approach``."""
        h = self.duration / (len(self.t) - 1)
        k = self.spec.lift_intervals * h
        if t < k:
            return "lift"
        if t > self.duration - k:
            return "approach"
        return "clear"


def _tangents(n: FloatArray) -> tuple[FloatArray, FloatArray]:
    e = np.eye(3)[int(np.argmin(np.abs(n)))]
    t1 = np.cross(n, e)
    t1 /= np.linalg.norm(t1)
    return t1, np.cross(n, t1)


def _lifted(finger: Any, body: TipBody, q: FloatArray, centre: FloatArray, rho: float,
            height: float, held: Any = None) -> FloatArray:
    """``q`` moved (a few Gauss-Newton steps, least joint motion) so that the cap's centre
    is ``height`` farther from the object along the line of centres (``held``, an object
    that is not a ball: along the normal at its nearest point): the guess's lift."""
    q = np.array(q, dtype=float)
    for _ in range(5):
        R, p = finger.fingertip_pose_pin(q)
        a = p + R @ body.a
        if held is None:
            d = a - centre
            dist = float(np.linalg.norm(d))
            u, want = d / dist, rho + body.r + height
        else:
            _, nrm, gap = held.nearest(a[None])
            u, dist, want = nrm[0], float(gap[0]), body.r + height
        if abs(dist - want) < 1e-6:
            break
        J = finger.frame_jacobian_pin(q)
        Jc = J[:3] - np.cross(R @ body.a, J[3:].T).T
        target = u * (want - dist)
        q = np.clip(q + np.linalg.lstsq(Jc, target, rcond=None)[0], finger.lower,
                    finger.upper)
    return q


def _guess(spec: SwingSpec) -> FloatArray:
    """Joint angles at the nodes: lift along the normal, carry at the clearance plus 2 mm,
    approach along the landing normal (each joint-space straight, then lifted)."""
    f, body, n, K = spec.finger, spec.body, spec.n_intervals, spec.lift_intervals
    up = spec.clearance + 0.002
    q0 = np.asarray(spec.q_start, dtype=float)
    q1 = np.asarray(spec.q_target, dtype=float)
    s = np.linspace(0.0, 1.0, n + 1)
    ease = s * s * s * (10 - 15 * s + 6 * s * s)
    Q = q0 + ease[:, None] * (q1 - q0)
    for k in range(1, n):
        h = up * min(1.0, k / K, (n - k) / K)
        Q[k] = _lifted(f, body, Q[k], spec.centre, spec.radius, h, spec.held)
    return Q


#: The swing NLPs built, by (the finger's kinematics and tip body, intervals, lift
#: intervals, other tips): the geometry, the times and the margins are parameters. Keyed by
#: content, not identity: a searched grasp's hand is a new model of the same fingers (its
#: tips' chart sides differ), and a swing NLP takes seconds to build. The least recently
#: used beyond :data:`MAX_SWING_NLPS` are dropped.
_SOLVERS: OrderedDict[tuple[str, int, int, int, str],
                      tuple[Any, FloatArray, FloatArray, Any, Any, tuple[str, ...]]
                      ] = OrderedDict()
MAX_SWING_NLPS = 32


def swing_key(f: Any, n: int, K: int, n_others: int, shape: str = "", driven: bool = False
              ) -> tuple[Any, ...]:
    """The key of finger ``f``'s swing NLP on this grid: a hash of everything the NLP is
    built from (the chain's placements, axes and kinds, the base and tip placements, the
    joint and rate limits, the tip's body), so that equal fingers share it; ``shape``:
    the name of an object that is not a ball ("" a ball's); ``driven``: the variant with
    the actuators' rows against the damping (:class:`SwingDrive`)."""
    body = tip_body(f)
    arrays = [f.base_rotation, f.base_position, f.tip_rotation, f.tip_translation, f.lower,
              f.upper, f.velocity_limit, body.a, body.b, [body.r]]
    kinds = []
    for j in f.chain:
        arrays += [j.axis, j.placement_rotation, j.placement_translation, [j.index_q]]
        kinds.append(j.kind)
    for c in getattr(f, "couplings", ()):
        arrays += [c.row(f.joint_names), [c.lower, c.upper]]
    digest = hashlib.sha256("/".join(kinds).encode())
    for a in arrays:
        digest.update(np.ascontiguousarray(a, dtype=float).tobytes())
    key = (digest.hexdigest(), n, K, n_others, shape)
    return (*key, "driven") if driven else key


def _built(f: Any, n: int, K: int, n_others: int, driven: bool = False) -> bool:
    """Whether finger ``f``'s swing NLP of this shape (``driven``: its variant with the
    actuators' rows) is built."""
    return swing_key(f, n, K, n_others, "", driven) in _SOLVERS


#: The parameters an object that is not a ball adds to a swing NLP's: its axes (palm
#: frame, 9) and its shape's clearance numbers (:meth:`~ocp.shapes.Shape.
#: clearance_params`, padded).
BOUND_PARAMS = 9 + CLEARANCE_PARAMS


def _swing_nlp(f: Any, body: TipBody, n: int, K: int, n_others: int, shape: Any = None,
               driven: bool = False
               ) -> tuple[Any, FloatArray, FloatArray, Any, Any, tuple[str, ...]]:
    """(solver, lbg, ubg, the warm-start solver, the rows' function ``g(x, p)``, each
    row's kind in words) of the swing NLP of finger ``f`` (see the module's doc), built
    once; the parameters in :func:`_swing_params`' order. ``shape``: an object that is not
    a ball (:class:`~ocp.shapes.Shape`), its distance the shape's lower bound
    (:meth:`~ocp.shapes.Shape.segment_clearance` of the body's segment in its axes), the
    :data:`BOUND_PARAMS` parameters after the others; None: a ball's. ``driven``: with
    the actuators' rows against the joints' damping last (:class:`SwingDrive`: its
    ``damping`` and ``slope`` parameters after those, the rows' bounds
    :meth:`SwingDrive.row_bounds` at each node 1..n-1, then at each interval's
    midpoint; ``lbg``, ``ubg`` here infinite for them; and the landing joints' added
    weight, the last parameter)."""
    bound = shape is not None
    key = swing_key(f, n, K, n_others, shape.name if bound else "", driven)
    if key in _SOLVERS:
        _SOLVERS.move_to_end(key)
        return _SOLVERS[key]
    nq = int(f.nq)
    n_p = 2 * nq + 31 + 8 * n_others * n
    n_b = n_p + (BOUND_PARAMS if bound else 0)
    P = ca.SX.sym("p", n_b + (2 * nq + 1 if driven else 0))
    q_start, q_target = P[0:nq], P[nq:2 * nq]
    o = 2 * nq
    T, clearance, cap_sin, rho = P[o], P[o + 1], P[o + 2], P[o + 3]
    centre, a_start, n0, t0a, t0b = (P[o + 4 + 3 * i:o + 7 + 3 * i] for i in range(5))
    a_land, n1, t1a, t1b = (P[o + 19 + 3 * i:o + 22 + 3 * i] for i in range(4))
    # the other bodies at each node 1..n (8 numbers each: a, b, radius, the gap kept)
    oth = ca.reshape(P[o + 31:n_p], 8, n_others * n) if n_others else None
    if bound:  # the object's axes, its shape's clearance numbers
        R_obj = ca.reshape(P[n_p:n_p + 9], 3, 3)
        dims = P[n_p + 9:n_p + BOUND_PARAMS]
    h = T / n
    Q, V, A = (ca.SX.sym(s, nq, n + 1) for s in ("Q", "V", "A"))
    Jn = ca.SX.sym("J", nq, n)
    Vp, Ap, Jp = V / T, A / T**2, Jn / T**3  # variables scaled by the duration
    a_loc, b_loc = ca.DM(body.a), ca.DM(body.b)
    capsule = bool(np.linalg.norm(body.b - body.a) > 0)
    r = body.r
    L = rho + r
    rows: list[tuple[Any, float, float, str]] = []
    kind = "the start at the finger's joints"

    def add(e: Any, lo: float, hi: float) -> None:
        rows.append((e, lo, hi, kind))

    add(Q[:, 0] - q_start, 0.0, 0.0)
    kind = "the joints' motion"
    for k in range(n):  # exact integration of the jerk
        qk, vk, ak, jk = Q[:, k], Vp[:, k], Ap[:, k], Jp[:, k]
        add((Q[:, k + 1] - (qk + h * vk + h * h / 2 * ak + h**3 / 6 * jk)), 0.0, 0.0)
        add((Vp[:, k + 1] - (vk + h * ak + h * h / 2 * jk)) * T, 0.0, 0.0)
        add((Ap[:, k + 1] - (ak + h * jk)) * T * T, 0.0, 0.0)
    # the whole cubic inside the limits: its Bezier control points are (convex hull)
    lo_q, hi_q = np.asarray(f.lower, dtype=float), np.asarray(f.upper, dtype=float)
    vmax = np.asarray(f.velocity_limit, dtype=float)
    for k in range(n):
        qk, vk, ak = Q[:, k], Vp[:, k], Ap[:, k]
        for ctrl in (qk + h / 3 * vk, qk + 2 * h / 3 * vk + h * h / 6 * ak):
            for i in range(nq):
                kind = f"joint {f.joint_names[i]}'s limits"
                add(ctrl[i], lo_q[i], hi_q[i])
        # the finger's joint couplings (ocp.robots.couplings), linear: kept by the
        # segment's control points and its end
        for cp in getattr(f, "couplings", ()):
            a = cp.row(f.joint_names)
            scale = float(np.linalg.norm(a))
            kind = f"the coupling {cp.name}"
            for ctrl in (qk + h / 3 * vk, qk + 2 * h / 3 * vk + h * h / 6 * ak,
                         Q[:, k + 1]):
                add(ca.dot(ca.DM(a / scale), ctrl), cp.lower / scale, cp.upper / scale)
        mid_v = vk + h / 2 * ak  # the rate's middle control point
        for i in range(nq):
            kind = f"joint {f.joint_names[i]}'s velocity limit"
            add(mid_v[i] / vmax[i], -1.0, 1.0)
    for k in range(1, n + 1):
        R, p = f.fk(Q[:, k])
        a, b = p + R @ a_loc, p + R @ b_loc
        if bound:  # the body's segment in the object's axes
            dist = shape.segment_clearance(dims, R_obj.T @ (a - centre),
                                           R_obj.T @ (b - centre)) - r
        else:
            dist = point_segment_distance(centre, a, b) - L
        if k == n:  # touch-down: the cap's centre over the landing point, on the cap
            kind = "the landing point (the tip's reach)"
            add((a - a_land) / L, 0.0, 0.0)
            if capsule:
                kind = "the landing on the cap"
                u = (b - a) / float(np.linalg.norm(body.b - body.a))
                if bound:  # (the landing normal: where the cap touches)
                    add(ca.dot(-n1, u) + cap_sin, -np.inf, 0.0)
                else:
                    add(ca.dot(centre - a, u) / L + cap_sin, -np.inf, 0.0)
            continue
        kind = "the clearance from the ball"
        if k in (K, n - K):  # the clear part's ends
            add((dist - clearance) / L, 0.0, np.inf)
        if k <= K:  # lift-off along the normal
            d = a - a_start
            kind = "the lift-off along the normal"
            add(ca.vertcat(ca.dot(d, t0a), ca.dot(d, t0b)) / L, 0.0, 0.0)
            add(ca.dot(d, n0) / L, 0.0, np.inf)
            if not bound:  # (an object's bound is below the distance: the cap's centre
                kind = "the clearance from the ball"  # along the normal keeps it out)
                add(dist / L, 0.0, np.inf)
        elif k >= n - K:  # approach along the landing normal
            d = a - a_land
            kind = "the approach along the landing normal"
            add(ca.vertcat(ca.dot(d, t1a), ca.dot(d, t1b)) / L, 0.0, 0.0)
            add(ca.dot(d, n1) / L, 0.0, np.inf)
            if not bound:
                kind = "the clearance from the ball"
                add(dist / L, 0.0, np.inf)
        else:
            add((dist - clearance) / L, 0.0, np.inf)
        for j in range(n_others):
            assert oth is not None
            c = (k - 1) * n_others + j
            a1, b1, r1, need = oth[0:3, c], oth[3:6, c], oth[6, c], oth[7, c]
            kind = f"{GAP_KIND}{j + 1}"
            for s in np.linspace(0.0, 1.0, SEGMENT_SAMPLES if capsule else 1):
                x = a + float(s) * (b - a)
                add((point_segment_distance(x, a1, b1) - r - r1 - need) / L, 0.0, np.inf)
    if driven:  # the damping's torque within what the actuators give, at each point
        damping, slope = P[n_b:n_b + nq], P[n_b + nq:n_b + 2 * nq]
        points = [(Q[:, k], Vp[:, k]) for k in range(1, n)]
        for k in range(n):  # the interval's midpoint on its cubic
            qk, vk, ak, jk = Q[:, k], Vp[:, k], Ap[:, k], Jp[:, k]
            points.append((qk + h / 2 * vk + h * h / 8 * ak + h**3 / 48 * jk,
                           vk + h / 2 * ak + h * h / 8 * jk))
        for q_pt, v_pt in points:
            for i in range(nq):
                kind = f"joint {f.joint_names[i]}'s actuator (its control range there)"
                add(damping[i] * v_pt[i] - slope[i] * q_pt[i], -np.inf, np.inf)
                kind = f"joint {f.joint_names[i]}'s actuator torque"
                add(damping[i] * v_pt[i], -np.inf, np.inf)
    jref = 20.0 * n  # the jerk's scale in the effort
    cost = h / T * ca.sumsqr(Jp / jref) + 10.0 * ca.sumsqr(Q[:, n] - q_target)
    if driven:  # (the landing joints held nearer the target's: DRIVEN_LANDING_WEIGHT)
        cost += P[n_b + 2 * nq] * ca.sumsqr(Q[:, n] - q_target)
    w = ca.vertcat(ca.vec(Q), ca.vec(V), ca.vec(A), ca.vec(Jn))
    g = ca.vertcat(*[e for e, _, _, _ in rows])
    lbg = np.concatenate([np.full(int(e.numel()), lo) for e, lo, _, _ in rows])
    ubg = np.concatenate([np.full(int(e.numel()), hi) for e, _, hi, _ in rows])
    kinds = tuple(k.replace("the ball", "the object") if bound else k
                  for e, _, _, k in rows for _ in range(int(e.numel())))
    nlp = {"x": w, "p": P, "f": cost, "g": g}
    solver = ca.nlpsol("swing", "ipopt", nlp, _IPOPT)
    warm = ca.nlpsol("swing_warm", "ipopt", nlp, {**_IPOPT, **_IPOPT_WARM})
    _SOLVERS[key] = (solver, lbg, ubg, warm, ca.Function("swing_rows", [w, P], [g]), kinds)
    while len(_SOLVERS) > MAX_SWING_NLPS:
        _SOLVERS.popitem(last=False)
    return _SOLVERS[key]


def prepare_swings(fingers: tuple[Any, ...], n_intervals: int | None = None,
                   lift_intervals: int | None = None, obstacles: int = 0,
                   driven: bool = False) -> float:
    """Build (and keep) the swing NLP of every round fingertip of a grasp of ``fingers``
    (the others its neighbours, and ``obstacles`` of the hand's links:
    :data:`ocp.gait.step.SWING_OBSTACLES` for a hand whose links are checked), as a
    gait's swings use them (``n_intervals`` and ``lift_intervals``: :class:`SwingSpec`'s
    defaults when None; ``driven``: the variants with the actuators' rows too, for a hand
    whose joints are damped), without solving: a service worker's warm-up. Returns the
    build time [s] (0 when built already)."""
    n = SwingSpec.n_intervals if n_intervals is None else int(n_intervals)
    K = SwingSpec.lift_intervals if lift_intervals is None else int(lift_intervals)
    t0 = time.perf_counter()
    built = False
    for f in fingers:
        try:
            body = tip_body(f)
        except ValueError:  # a flat or spheroid tip: no gait
            continue
        others = len(fingers) - 1 + int(obstacles)
        for variant in (False, True) if driven else (False,):
            if not _built(f, n, K, others, variant):
                _swing_nlp(f, body, n, K, others, None, variant)
                built = True
    return time.perf_counter() - t0 if built else 0.0


def _swing_params(spec: SwingSpec) -> FloatArray:
    body = spec.body
    n0 = spec.start_normal()
    n1 = np.asarray(spec.landing_normal, dtype=float)
    n1 = n1 / np.linalg.norm(n1)
    R0, p0 = spec.finger.fingertip_pose_pin(spec.q_start)
    cap_sin = float(np.sin(spec.cap_margin / body.r))
    n = spec.n_intervals
    at = spec.others_at(np.linspace(0.0, spec.duration, n + 1)[1:])
    needs = spec.required_gaps()
    m = spec.node_margin
    # a gap kept from a close neighbour (a share of where it starts or lands) gets at most
    # a quarter of the room that share leaves, so that the lift-off can still go along
    # the normal (the whole margin sent one sideways, 0.10 rad off it, measured)
    room = 0.25 * (1.0 - spec.neighbour_share) / max(spec.neighbour_share, 1e-9)
    others = [np.concatenate([a1[k], b1[k], [r1, need + min(m, room * need) + spec.dip]])
              for k in range(n) for (a1, b1, r1), need in zip(at, needs, strict=True)]
    extra: list[Any] = []
    if spec.held is not None:  # the object's axes (column-major), its clearance numbers
        extra = [np.asarray(spec.held.rotation, dtype=float).ravel(order="F"),
                 spec.held.clearance_params()]
    return np.concatenate([spec.q_start, spec.q_target,
                           [spec.duration, spec.clearance + m + spec.dip, cap_sin,
                            spec.radius],
                           spec.centre, p0 + R0 @ body.a, n0, *_tangents(n0),
                           spec.landing_point(), n1, *_tangents(n1),
                           np.concatenate(others, axis=None) if others else [], *extra,
                           *(() if spec.drive is None else
                             (spec.drive.damping, spec.drive.slope,
                              [DRIVEN_LANDING_WEIGHT]))])


def plan_swing(spec: SwingSpec, warm: SwingPlan | None = None) -> SwingPlan:
    """Solve the swing's NLP (see the module's doc; built once per finger and grid).
    ``warm``: an earlier swing of this finger on this grid (in a gait, the one before: the
    grasp recurs; with or without the actuators' rows), whose primal-dual point starts
    IPOPT; when that does not solve, the swing is solved from its own guess."""
    if warm is not None and warm.point is not None and warm.spec.finger is spec.finger \
            and warm.spec.n_intervals == spec.n_intervals \
            and warm.spec.lift_intervals == spec.lift_intervals \
            and len(warm.spec.others) == len(spec.others) \
            and (warm.spec.held is None) == (spec.held is None) \
            and (spec.held is None or warm.spec.held.shape is spec.held.shape):
        out = _solve_swing(spec, warm.point)
        if out.ok:
            return out
        cold = _solve_swing(spec, None)
        return replace(cold, iterations=cold.iterations + out.iterations,
                       solve_time=cold.solve_time + out.solve_time)
    return _solve_swing(spec, None)


#: Still swings not found, by their spec's digest (:func:`_failed_key`): the same swing
#: is asked again when a gait's stranded check finds none and the gait then re-places
#: that fingertip at rest from the same joints (about -x with the overlap options, 11 of
#: 96 swing solves, all infeasible, 4.4 s). IPOPT from the same point gives the same
#: answer; a spec with moving bodies or a held object (closures) is not remembered.
_FAILED: OrderedDict[str, tuple[Any, SwingPlan]] = OrderedDict()
_FAILED_SIZE = 256


def _failed_key(spec: SwingSpec) -> str | None:
    """A digest of every field of a still swing on a ball (None for another swing)."""
    if spec.moving is not None or spec.centre_path is not None or spec.held is not None \
            or spec.landing_contact is not None:
        return None
    h = hashlib.sha256()
    for f in fields(spec):
        value = getattr(spec, f.name)
        if f.name == "finger":
            h.update(str(id(value)).encode())
        elif f.name == "others":
            for a, b, r in value:
                h.update(np.asarray(a, dtype=float).tobytes())
                h.update(np.asarray(b, dtype=float).tobytes())
                h.update(repr(float(r)).encode())
        elif isinstance(value, np.ndarray):
            h.update(np.asarray(value, dtype=float).tobytes())
        elif isinstance(value, SwingDrive):
            h.update(value.digest())
        else:
            h.update(repr(value).encode())
        h.update(b"|")
    return h.hexdigest()


def _solve_swing(spec: SwingSpec, point: tuple[FloatArray, FloatArray, FloatArray] | None
                 ) -> SwingPlan:
    key = _failed_key(spec) if point is None else None
    known = _FAILED.get(key) if key is not None else None
    if known is not None and known[0] is spec.finger:
        return replace(known[1], spec=spec, iterations=0, solve_time=0.0)  # (none spent)
    plan = _solve(spec, point)
    if key is not None and not plan.ok:
        _FAILED[key] = (spec.finger, plan)
        while len(_FAILED) > _FAILED_SIZE:
            _FAILED.popitem(last=False)
    return plan


def _solve(spec: SwingSpec, point: tuple[FloatArray, FloatArray, FloatArray] | None
           ) -> SwingPlan:
    f, body = spec.finger, spec.body
    nq, n, K = int(f.nq), spec.n_intervals, spec.lift_intervals
    T = float(spec.duration)
    h = T / n
    solver, lbg, ubg, warm_solver, rows_of, kinds = _swing_nlp(
        f, body, n, K, len(spec.others), None if spec.held is None else spec.held.shape,
        spec.drive is not None)
    if spec.drive is not None:  # its rows last: 2 nq at each of n - 1 nodes, n midpoints
        lo_pt, hi_pt = spec.drive.row_bounds()
        m_drive = lo_pt.size * (2 * n - 1)
        lbg = np.concatenate([lbg[:-m_drive], np.tile(lo_pt, 2 * n - 1)])
        ubg = np.concatenate([ubg[:-m_drive], np.tile(hi_pt, 2 * n - 1)])
    vs, as_, js = 1.0 / T, 1.0 / T**2, 1.0 / T**3
    lo_q, hi_q = backed_off_joint_limits(f)
    vmax = np.asarray(f.velocity_limit, dtype=float)
    amax = spec.max_joint_acceleration
    lbq, ubq = np.tile(lo_q, (n + 1, 1)), np.tile(hi_q, (n + 1, 1))
    lbq[0], ubq[0] = np.minimum(lo_q, spec.q_start), np.maximum(hi_q, spec.q_start)
    lbv, ubv = np.tile(-vmax / vs, (n + 1, 1)), np.tile(vmax / vs, (n + 1, 1))
    lbv[0] = ubv[0] = lbv[-1] = ubv[-1] = 0.0
    lba, uba = np.full((n + 1, nq), -amax / as_), np.full((n + 1, nq), amax / as_)
    lba[0] = uba[0] = lba[-1] = uba[-1] = 0.0
    bj = np.full((n, nq), np.inf)
    lbw = np.concatenate([lbq.ravel(), lbv.ravel(), lba.ravel(), -bj.ravel()])
    ubw = np.concatenate([ubq.ravel(), ubv.ravel(), uba.ravel(), bj.ravel()])

    Qg = np.clip(_guess(spec), lbq, ubq)
    Vg = np.gradient(Qg, h, axis=0)
    Vg[0] = Vg[-1] = 0.0
    Ag = np.gradient(Vg, h, axis=0)
    Ag[0] = Ag[-1] = 0.0
    Jg = np.diff(Ag, axis=0) / h
    w0 = np.concatenate([Qg.ravel(), (Vg / vs).ravel(), (Ag / as_).ravel(),
                         (Jg / js).ravel()])
    duals: dict[str, FloatArray] = {}
    if point is not None:
        solver = warm_solver
        # (a point of the finger's other variant, with or without the actuators' rows,
        # which come last: their multipliers dropped, or zero)
        lam_g = point[2][:lbg.size] if point[2].size >= lbg.size else \
            np.concatenate([point[2], np.zeros(lbg.size - point[2].size)])
        w0, duals = point[0], {"lam_x0": point[1], "lam_g0": lam_g}
    t_start = time.perf_counter()
    res = solver(x0=np.clip(w0, lbw, ubw), p=_swing_params(spec), lbx=lbw, ubx=ubw,
                 lbg=lbg, ubg=ubg, **duals)
    elapsed = time.perf_counter() - t_start
    st = solver.stats()
    x = np.asarray(res["x"]).ravel()
    m = nq * (n + 1)
    Qs = x[:m].reshape(n + 1, nq)
    # the first node is q_start by an equality row, met to IPOPT's 1e-10 or better: the
    # returned swing starts exactly where the finger is (a switch's joints are continuous)
    Qs[0] = spec.q_start
    Vs = x[m:2 * m].reshape(n + 1, nq) * vs
    As = x[2 * m:3 * m].reshape(n + 1, nq) * as_
    Js = x[3 * m:].reshape(n, nq) * js
    ok = bool(st["success"])
    status = "solved" if ok else "infeasible" if "Infeasible" in st["return_status"] \
        else "failed"
    message, blocker, gap_broken = "", None, False
    if not ok:
        rows = np.asarray(rows_of(x, _swing_params(spec))).ravel()
        broken = _broken(rows, lbg, ubg, kinds)
        message = (f"the swing of {_name(spec)} was not found (IPOPT "
                   f"{st['return_status']}): " + _cause(broken, spec))
        blocker = _blocker(broken)
        gap_broken = any(_gap_index(k) is not None for k in broken)
    return SwingPlan(spec, status, message, np.linspace(0.0, T, n + 1), Qs, Vs, As, Js,
                     int(st["iter_count"]), elapsed,
                     (x, np.asarray(res["lam_x"]).ravel(), np.asarray(res["lam_g"]).ravel()),
                     blocker, gap_broken)


def _name(spec: SwingSpec) -> str:
    if spec.name:
        return f"finger {spec.name!r}"
    names = getattr(spec.finger, "joint_names", ())
    return f"the finger of joints {', '.join(names)}" if names else "the finger"


def _broken(g: FloatArray, lbg: FloatArray, ubg: FloatArray, kinds: tuple[str, ...]
            ) -> dict[str, float]:
    """Per kind of row, how much the last iterate ``g`` breaks its rows at worst (those
    broken by more than 1e-6, scaled as the NLP's rows are)."""
    over = np.maximum(lbg - g, g - ubg)
    over = np.where(np.isfinite(over), over, 0.0)
    worst: dict[str, float] = {}
    for k, v in zip(kinds, over, strict=True):
        if v > 1e-6:
            worst[k] = max(worst.get(k, 0.0), float(v))
    return worst


#: The row kind of the gap kept from another body, numbered from 1 in ``others``' order.
GAP_KIND = "the gap to the other fingertip "


def _gap_index(kind: str) -> int | None:
    """The index in ``others`` of a gap row's body (its kind :data:`GAP_KIND` and a number
    from 1); None for another kind."""
    return int(kind.rsplit(" ", 1)[1]) - 1 if kind.startswith(GAP_KIND) else None


def _blocker(worst: dict[str, float]) -> int | None:
    """The index in ``others`` of the body whose gap the last iterate breaks most, when
    that is the row kind it breaks most (``worst``: :func:`_broken`); else None."""
    return _gap_index(max(worst, key=lambda k: worst[k])) if worst else None


def _cause(worst: dict[str, float], spec: SwingSpec) -> str:
    """The physical cause of a failed swing, in words: the kind of row the last iterate
    breaks most (``worst``: :func:`_broken`), and the others it breaks."""
    if not worst:
        return "every row is met at the last iterate; IPOPT stopped without converging"
    names = list(spec.other_names)
    ranked = sorted(worst.items(), key=lambda kv: -kv[1])

    def words(k: str) -> str:
        j = _gap_index(k)
        if j is not None and 0 <= j < len(names) and names[j]:  # a tip's name, a link's words
            return f"the gap to {names[j]}" if names[j].startswith("body ") else \
                    f"the gap to fingertip {names[j]!r}"
        return k

    first = words(ranked[0][0])
    rest = ", ".join(words(k) for k, _ in ranked[1:4])
    return (f"it cannot keep {first}" + (f" (nor {rest})" if rest else "") +
            " with this finger's joints")
