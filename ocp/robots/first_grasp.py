"""A first grasp of a ball, or of any closed convex object of :mod:`ocp.shapes`, for any
hand: joint angles that put every chosen round fingertip on the object, the contacts
opposing each other (force closure), and, where a ball's motion is given, the grasp whose
rolled reach toward that motion is largest.

No nominal grasp is needed. Per finger (:func:`finger_contacts`): joint vectors are drawn
uniformly within the limits (the finger's known grasps first), each whose tip's centre
lies near the sphere of contact (radius ``rho + r`` about the ball's centre) with its cap
facing the ball is pulled onto it (:func:`~ocp.robots.grasp_reach.grasp_on_ball`), every
joint origin of the finger kept outside the ball; of those, contacts with distinct normals
are kept. Per candidate, when the motion turns the ball, the finger is rolled
(:func:`~ocp.robots.grasp_reach.roll`) through the turns up to the whole turn: how far it
gets is its reach toward the motion. Then every combination of one candidate per finger is
scored (:func:`first_grasp`): tips' bodies (a capsule's cylinder too) at least ``min_gap``
apart; the normals' *closure* (the
least over directions u of ``max_i n_i . u``: > 0 iff the inward normals positively span
space, so that normal pushes alone hold the ball against any force; two fingers: minus
the sine of their grasp angle); of the combinations closed by :data:`GOOD_CLOSURE` (else
by any positive margin), the one whose least finger reach is largest, then the most
closed. The chosen grasp is checked with the planner's own force-closure test
(:func:`~ocp.geometry.grasp.force_angles`: the grasp angle below ``atan(mu)``).

The result (:class:`FirstGrasp`) gives the joints (``fingers[i].initial_q``) and each
capsule tip's ``side`` (the contact's direction across the cap's axis, link frame: the
contact then starts on its chart's equator). Nothing found is :class:`GraspNotFoundError`,
naming the finger or the combination and why. docs/hands.md, "A first grasp".

Any other object (:class:`ObjectGeometry`, from an ``ObjectSpec`` and its orientation) is
searched the same way through its signed distance and outward normal at the nearest point
(:func:`~ocp.geometry.nearest.nearest_surface_point`): a tip's centre is near when its distance
from the surface is within the ball's band about ``r``; it is pulled onto the surface
(distance ``r``) by a Gauss-Newton on the joints along the normal (:func:`onto_surface`);
a contact beyond the chart's bound (``u_limit``: a capsule's ends; not an egg's, which
its side chart carries) or on a cap's seam is dropped, every joint origin kept outside
the object; the closure is that of the object's normals at the contacts. An object with
a closed-form nearest point (an ellipsoid, a capsule: the search's ``held``) has its
candidates rolled through the turns on its surface (:func:`~ocp.robots.grasp_reach.roll`
with ``held``) and ranked by that reach as a ball's are; any other object's grasps well
closed are ranked by the room their
joints leave to roll (the least, over the fingers and their joints, distance to a joint
limit as a share of the joint's range: :func:`joint_room`), then by closure (``turns``
ignored, no ``reach``): the most closed grasps of an egg put joints at their limits, and
did not plan a 10 deg turn, nor did those of the most room. docs/shapes.md.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ocp.geometry.bodies import segments_distance, tip_body
from ocp.geometry.nearest import nearest_surface_point
from ocp.geometry.surfaces import rotation_from_vector
from ocp.robots.couplings import coupled_step, coupling_violation, project_couplings
from ocp.robots.grasp_reach import (
    _equalities,
    _skew,
    _tip,
    at_tendon_bounds,
    grasp_on_ball,
    roll,
    tip_state,
)
from ocp.shapes.held import Held

__all__ = [
    "GOOD_CLOSURE",
    "FingerContact",
    "FirstGrasp",
    "GraspNotFoundError",
    "Misses",
    "ObjectGeometry",
    "closure",
    "desired_turns",
    "finger_contacts",
    "first_grasp",
    "joint_room",
    "onto_surface",
]

FloatArray = NDArray[np.float64]

#: A combination whose closure is at least this (the inward normals' hull holds the
#: origin 0.15 deep, in units of the unit normals) is preferred to any less closed one,
#: whatever its reach; below it only when no combination reaches it.
GOOD_CLOSURE = 0.15
#: The least angle [rad] between two kept candidate normals of one finger.
DISTINCT = math.radians(6.0)
#: At most this many candidate contacts per finger are pulled onto the ball.
MAX_CANDIDATES = 16
#: The search's roll step [rad] (the planner's check rolls at 0.25 deg: a candidate's
#: reach is a search's estimate; the chosen grasp's is rolled again at that step).
COARSE_STEP = math.radians(1.0)
#: A searched grasp keeps the hand's links (all but the touching fingertips) this far [m]
#: from the ball and from each other, as MuJoCo collides them: twice the certificate's
#: ``LINK_CLEARANCE``, so that a roll's motion keeps that.
GRASP_LINK_CLEARANCE = 1e-3
#: At most this many grasps (in order of preference) are checked for their links.
LINK_TRIES = 400
#: At most this many combinations are weighed (each finger's least preferred candidates
#: dropped first): 4 fingers keep 16 each, 5 fingers 9.
MAX_COMBINATIONS = 66_000
#: A candidate's reach is rolled at most this far [rad] (a turn farther than rolling can
#: go, docs/hands.md, is not worth the time: the search stays within seconds).
MAX_SEARCH_TURN = math.radians(60.0)
#: Finite stand-in for an unlimited joint's range [rad].
_UNLIMITED = math.pi


class GraspNotFoundError(ValueError):
    """No grasp: ``errors`` are (field, reason) pairs, fields ``fingers[i]`` (a finger
    that cannot touch the ball) or ``grasp`` (no combination holds it)."""

    def __init__(self, errors: list[tuple[str, str]]) -> None:
        super().__init__("; ".join(f"{f}: {r}" for f, r in errors))
        self.errors = errors


@dataclass(frozen=True)
class FingerContact:
    """A candidate contact of one finger: joints, the ball's outward normal at the
    contact (palm frame), the tip's centre, the contact's direction in the tip link's
    frame, and its rolled reach toward the motion [rad] (None: no motion) and stop."""

    q: FloatArray
    normal: FloatArray
    centre: FloatArray
    link_direction: FloatArray
    reach: float | None = None
    stop: str = ""
    point: FloatArray | None = None  # the contact point [m] on an object not a ball


@dataclass(frozen=True)
class FirstGrasp:
    """The grasp found: one contact per finger, its closure, the least distance between
    tips [m], Phi* [rad] (the planner's grasp angle), the turn requested [rad, 0: none],
    and how many candidates and combinations were weighed."""

    contacts: tuple[FingerContact, ...]
    closure: float
    gap: float
    grasp_angle: float
    requested: float
    candidates: tuple[int, ...]
    combinations: int

    @property
    def q(self) -> tuple[FloatArray, ...]:
        return tuple(c.q for c in self.contacts)

    @property
    def reach(self) -> float | None:
        """The turn [rad] the whole grasp allows toward the motion (the least finger's)."""
        got = [c.reach for c in self.contacts if c.reach is not None]
        return min(got) if got else None


def _fibonacci(n: int) -> FloatArray:
    k = np.arange(n) + 0.5
    z = 1.0 - 2.0 * k / n
    phi = math.pi * (1.0 + math.sqrt(5.0)) * k
    s = np.sqrt(1.0 - z * z)
    return np.stack([s * np.cos(phi), s * np.sin(phi), z], axis=1)


_DIRECTIONS = _fibonacci(200)


def closure(normals: ArrayLike, points: ArrayLike | None = None,
            directions: ArrayLike | None = None) -> FloatArray:
    """The closure of contact normals (..., n, 3) (outward, unit): three or more, the
    least over ``directions`` u (default 200 on the sphere) of ``max_i n_i . u``, > 0 iff
    the origin is inside their hull (the inward pushes alone balance any force on a ball);
    two, minus the sine of the larger grasp angle (0: antipodal) between the normals and
    the line through the contact ``points`` (..., 2, 3) [m] (None: a ball's, along
    n_1 - n_0)."""
    N = np.asarray(normals, dtype=float)
    if N.shape[-2] == 2:
        P = N if points is None else np.asarray(points, dtype=float)
        d = P[..., 1, :] - P[..., 0, :]
        d = d / np.maximum(np.linalg.norm(d, axis=-1, keepdims=True), 1e-12)
        c1 = np.clip(-np.sum(N[..., 0, :] * d, axis=-1), -1.0, 1.0)
        c2 = np.clip(np.sum(N[..., 1, :] * d, axis=-1), -1.0, 1.0)
        ang = np.maximum(np.arccos(c1), np.arccos(c2))
        return np.asarray(-np.sin(ang))
    U = _DIRECTIONS if directions is None else np.asarray(directions, dtype=float)
    return np.asarray((N @ U.T).max(axis=-2).min(axis=-1))


@dataclass(frozen=True)
class _Turn:
    axis: FloatArray
    angle: float


def desired_turns(motion: Any) -> list[Any]:
    """The turns (palm axes, angles) of a desired motion (``ocp.spec``'s DesiredMotion)
    between its knots from the plan's start, successive turns about one axis merged
    (:func:`~ocp.robots.turn_reach.motion_turns`)."""
    from ocp.geometry.rotations import quaternion_matrix
    from ocp.robots.turn_reach import motion_turns

    R0, _ = motion.at(0.0)
    later = [k for k, t in enumerate(motion.times) if t > motion.t0]
    rotations = [np.asarray(R0[0]), *(quaternion_matrix(motion.orientations[k])
                                      for k in later)]
    return motion_turns(rotations)


def _limits(f: Any) -> tuple[FloatArray, FloatArray]:
    lo = np.where(np.isfinite(f.lower), f.lower, -_UNLIMITED)
    hi = np.where(np.isfinite(f.upper), f.upper, _UNLIMITED)
    return np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)


def _outside(f: Any, q: FloatArray, centre: FloatArray, radius: float) -> bool:
    """Whether every joint origin of the finger is outside the ball."""
    import pinocchio as pin

    pin.forwardKinematics(f.model, f.data, q)
    for k in range(1, f.model.njoints):
        p = f.base_rotation @ np.asarray(f.data.oMi[k].translation) + f.base_position
        if float(np.linalg.norm(p - centre)) < radius:
            return False
    return True


@dataclass(frozen=True)
class ObjectGeometry:
    """A closed convex object for the search, about its centre (given apart): its chart's
    surface and parameters, the chart's axes in the palm frame (``rotation``: the pose's
    times the chart patch's), the bound ``u_limit`` on a contact's |u| on the chart, its
    support heights along the 200 search directions (chart axes [m]), the length its band
    is scaled by [m] and the shape's name."""

    surface: Any
    params: tuple[float, ...]
    rotation: FloatArray
    u_limit: float
    heights: FloatArray
    length: float
    shape: str
    #: the object's dimensions, for its shape's closed-form nearest point
    #: (:meth:`ocp.shapes.Shape.nearest`), which seeds the chart's search
    dimensions: tuple[float, ...] = ()
    #: whether a searched contact beyond ``u_limit`` is kept: another chart of the shape
    #: carries it (an egg's side chart, its poles on the equator: ``ObjectSpec.side_chart``)
    beyond_limit: bool = False

    @classmethod
    def of(cls, obj: Any, rotation: ArrayLike, pole_margin: float) -> ObjectGeometry:
        """The geometry of ``obj`` (an ``ObjectSpec``) turned by ``rotation`` (palm frame)
        with contacts ``pole_margin`` [rad] from its chart's poles."""
        R = np.asarray(rotation, dtype=float) @ rotation_from_vector(obj.chart_rotation)
        h = np.asarray(obj.surface.support_heights(_DIRECTIONS, obj.params), dtype=float)
        return cls(obj.surface, tuple(float(x) for x in obj.params), R,
                   float(obj.u_limit(pole_margin)), h, float(obj.length_scale), obj.shape,
                   tuple(float(x) for x in obj.dimensions),
                   not obj.side_chart and obj.kind.side_surface(obj.dimensions) is not None)

    @property
    def outer(self) -> float:
        """The largest support height [m]: no point of the object is farther."""
        return float(self.heights.max())

    def closure_directions(self) -> FloatArray | None:
        """The directions the normals' closure is taken over: every direction (None), but
        on a surface straight along a ``ruling`` (a capsule's cylinder, its normals all
        across its axis) the 64 across it, palm frame: along the axis the normals push
        nothing (their closure over every direction is 0, positive only by the sampling),
        friction holds the object there, which the chosen grasp's force-closure test with
        friction checks."""
        if self.surface.ruling is None:
            return None
        axis = self.rotation @ np.asarray(self.surface.ruling, dtype=float)
        e1 = np.cross(axis, [1.0, 0.0, 0.0] if abs(axis[0]) < 0.9 else [0.0, 1.0, 0.0])
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(axis, e1)
        a = np.linspace(0.0, 2.0 * math.pi, 64, endpoint=False)
        return np.asarray(np.outer(np.cos(a), e1) + np.outer(np.sin(a), e2))

    def nearest(self, d: ArrayLike, alpha: ArrayLike | None = None
                ) -> tuple[FloatArray, float, FloatArray]:
        """Of the surface's point nearest to the point ``d`` [m] from the centre (palm
        axes): (its chart coordinates, the signed distance [m], negative inside, and the
        outward normal there, palm axes). Without ``alpha``, the chart's search starts at
        the shape's closed-form nearest point where it has one (the chart patch is one of
        its symmetries): from the chart's own start it can settle elsewhere near the
        chart's poles (a point 40 mm up a rounded cube's z axis came out 15.7 mm inside,
        and a searched grasp's contact beyond the chart's bound that the problem then
        refused)."""
        x = self.rotation.T @ np.asarray(d, dtype=float)
        if alpha is None and self.dimensions:
            from ocp.shapes import shape_of

            got = shape_of(self.shape).nearest(self.dimensions, x[None])
            if got is not None:
                alpha = np.asarray(self.surface.inverse(got[0][0], self.params), dtype=float)
        a, t = nearest_surface_point(self.surface, self.params, x, alpha)
        _, G, _, _, _ = self.surface.geometry(a, self.params)
        return np.asarray(a, dtype=float), t, self.rotation @ np.asarray(G, dtype=float)[:, 2]

    def distance_bounds(self, d: ArrayLike) -> FloatArray:
        """A lower bound [m] on the signed distance of each point (rows of ``d``, from the
        centre, palm axes): the largest ``n . d - h(n)`` over 200 directions n."""
        D = np.atleast_2d(np.asarray(d, dtype=float)) @ self.rotation
        return np.asarray((D @ _DIRECTIONS.T - self.heights).max(axis=1))


def _outside_object(f: Any, q: FloatArray, centre: FloatArray, geo: ObjectGeometry) -> bool:
    """Whether every joint origin of the finger is outside the object."""
    import pinocchio as pin

    pin.forwardKinematics(f.model, f.data, q)
    for k in range(1, f.model.njoints):
        d = f.base_rotation @ np.asarray(f.data.oMi[k].translation) + f.base_position - centre
        if float(np.linalg.norm(d)) <= geo.outer and geo.nearest(d)[1] < 0.0:
            return False
    return True


def onto_surface(f: Any, q: ArrayLike, centre: ArrayLike, geo: ObjectGeometry,
                 alpha: ArrayLike | None = None, tol: float = 1e-12
                 ) -> tuple[FloatArray, FloatArray, float, FloatArray] | None:
    """Joints near ``q`` (within the limits and couplings) that put finger ``f``'s round
    tip on the object at ``centre`` (its centre at distance r from the surface, within
    ``tol`` [m]): Gauss-Newton on the joints along the nearest point's normal, a step at
    most 0.3 rad; (joints, the contact's chart coordinates, the tip centre's distance
    from the surface [m], the outward normal, palm axes), or None when it does not
    converge."""
    c = np.asarray(centre, dtype=float)
    pc, _, r = _tip(f)
    x = project_couplings(f, np.asarray(q, dtype=float))
    a = None if alpha is None else np.asarray(alpha, dtype=float)
    for _ in range(40):
        R_l, p_l = f.fingertip_pose_pin(x)
        a, t, n = geo.nearest(p_l + R_l @ pc - c, a)
        gap = t - r
        if abs(gap) <= tol:
            if coupling_violation(f, x)[0] > 0.0:
                return None
            return x, a, t, n
        J = f.frame_jacobian_pin(x)
        g = n @ (J[:3] - _skew(R_l @ pc) @ J[3:])  # d gap / dq
        Ae, be = _equalities(f, x)
        dq = np.linalg.lstsq(np.vstack([g[None], Ae]), np.concatenate([[-gap], be]),
                             rcond=None)[0]
        x = coupled_step(f, x, dq / max(1.0, float(np.abs(dq).max()) / 0.3))
    return None


@dataclass
class Misses:
    """Why a finger's sampled joint vectors gave no contact (:func:`finger_contacts`): the
    least distance [m] of its tip's centre from where it would touch (``closest``), how
    many samples brought it within the search's band (``near``), of those how many faced
    the cap away (``away``), and of those pulled onto the object (``tried``) how many
    found no joints touching it within the limits, couplings and tendons (``unpulled``),
    put a link inside it (``inside``) or touched off the cap or past the object chart's
    bound (``off``)."""

    closest: float = math.inf
    near: int = 0
    away: int = 0
    tried: int = 0
    unpulled: int = 0
    inside: int = 0
    off: int = 0

    def why(self, samples: int, what: str) -> str:
        """The reason, in words (``what``: "the ball", "the object")."""
        if not self.near:
            return (f"over {samples} joint vectors within its limits its tip's centre came "
                    f"no closer than {self.closest * 1e3:.3g} mm to where it would touch")
        parts = [f"{n} {w}" for n, w in (
            (self.unpulled, "found no joints touching it within their limits"),
            (self.inside, f"put a link inside {what}"),
            (self.off, "touched it off the cap or past the chart's bound")) if n]
        return (f"of {samples} joint vectors within its limits {self.near} brought its tip "
                f"near {what}: {self.away} with the cap facing away"
                + (f"; of {self.tried} pulled onto it, " + ", ".join(parts) if parts else ""))


def _surface_contacts(f: Any, c: FloatArray, geo: ObjectGeometry, Q: list[FloatArray],
                      margin: float) -> tuple[list[FingerContact], Misses]:
    """:func:`finger_contacts` on an object not a ball, from the joint vectors ``Q``."""
    pc, ax, r = _tip(f)
    band = max(0.01, 0.3 * (geo.length + r))
    seam = math.pi / 2 - margin / r
    X = np.array([p + R @ pc for R, p in (f.fingertip_pose_pin(q) for q in Q)]) - c
    low = geo.distance_bounds(X) - r  # at most the distances from touching
    miss = Misses(float(np.min(low[low > band], initial=math.inf)))
    near: list[tuple[float, FloatArray, FloatArray, FloatArray]] = []
    for k in np.flatnonzero(low <= band):
        a, t, n = geo.nearest(X[k])
        off = abs(t - r)
        miss.closest = min(miss.closest, off)
        if off > band:
            continue
        miss.near += 1
        R_l, _ = f.fingertip_pose_pin(Q[k])
        if ax is not None and math.acos(max(-1.0, min(1.0, float(-n @ (R_l @ ax))))) > seam:
            miss.away += 1
            continue  # the cap faces away from the object
        near.append((off, Q[k], n, a))
    near.sort(key=lambda x: x[0])
    kept: list[FingerContact] = []
    tried: list[FloatArray] = []
    for _, q, n, a in near:
        if len(kept) >= MAX_CANDIDATES or len(tried) >= 3 * MAX_CANDIDATES:
            break
        if any(float(n @ m) > math.cos(DISTINCT) for m in tried):
            continue
        tried.append(n)
        miss.tried += 1
        got = onto_surface(f, q, c, geo, a)
        if got is None:
            miss.unpulled += 1
            continue
        q1, a1, _, n1 = got
        if abs(float(a1[0])) > geo.u_limit and not geo.beyond_limit:
            miss.off += 1
            continue
        if not _outside_object(f, q1, c, geo):
            miss.inside += 1
            continue
        R_l, p_l = f.fingertip_pose_pin(q1)
        m = R_l.T @ (-n1)
        if ax is not None and math.acos(max(-1.0, min(1.0, float(m @ ax)))) > seam:
            miss.off += 1
            continue
        centre = p_l + R_l @ pc
        kept.append(FingerContact(q1, n1, centre, m, None, "", centre - r * n1))
    return kept, miss


def _capped(turns: Sequence[Any], cap: float) -> list[Any]:
    """The turns, one after the other, up to ``cap`` [rad] in all."""
    out, left = [], cap
    for t in turns:
        if left <= 0.0:
            break
        out.append(t if t.angle <= left else _Turn(np.asarray(t.axis), left))
        left -= t.angle
    return out


def _roll_through(f: Any, q: FloatArray, centre: FloatArray, radius: float,
                  turns: Sequence[Any], margin: float, step: float = COARSE_STEP,
                  held: Held | None = None) -> tuple[float, str]:
    """How far [rad] the finger rolls through the turns (one after the other) before its
    first stop, and the stop ("" none); on ``held`` (an object that is not a ball, at the
    first turn's start) its surface turned by each turn in turn."""
    done = 0.0
    for turn in turns:
        r = roll(f, q, centre, radius, turn.axis, turn.angle, margin, step, held=held)
        done += r.reach
        if r.why or r.reach < turn.angle - 1e-9:
            return done, r.why
        q = r.q
        held = None if held is None else held.turned(turn.axis, turn.angle)
    return done, ""


def finger_contacts(f: Any, centre: ArrayLike, radius: float | ObjectGeometry,
                    seeds: Sequence[ArrayLike] = (), samples: int = 1500,
                    turns: Sequence[Any] = (), margin: float = 0.002,
                    rng: np.random.Generator | None = None
                    ) -> tuple[list[FingerContact], Misses]:
    """Finger ``f``'s candidate contacts on the ball of ``radius`` [m], or on the object
    ``radius`` (an :class:`ObjectGeometry`: ``turns`` ignored), at ``centre`` (module
    docstring), at most :data:`MAX_CANDIDATES`, and what the samples missed by
    (:class:`Misses`: why none, when none)."""
    rng = rng if rng is not None else np.random.default_rng(0)
    c = np.asarray(centre, dtype=float)
    pc, ax, r = _tip(f)
    shell = (radius.length if isinstance(radius, ObjectGeometry) else radius) + r
    band = max(0.01, 0.3 * shell)
    seam = math.pi / 2 - margin / r
    lo, hi = _limits(f)
    Q = [np.clip(np.asarray(s, dtype=float), lo, hi) for s in seeds]
    Q += [(lo + hi) / 2, *(lo + (hi - lo) * rng.random((samples, f.nq)))]
    if getattr(f, "couplings", ()):  # drawn within the couplings too
        Q = [project_couplings(f, q) for q in Q]
    if isinstance(radius, ObjectGeometry):
        return _surface_contacts(f, c, radius, Q, margin)
    near: list[tuple[float, FloatArray, FloatArray]] = []
    miss = Misses()
    for q in Q:
        R_l, p_l = f.fingertip_pose_pin(q)
        d = p_l + R_l @ pc - c
        dist = float(np.linalg.norm(d))
        off = abs(dist - shell)
        miss.closest = min(miss.closest, off)
        if off > band or dist < 1e-9:
            continue
        miss.near += 1
        n = d / dist
        if ax is not None and math.acos(max(-1.0, min(1.0, float(-n @ (R_l @ ax))))) > seam:
            miss.away += 1
            continue  # the cap faces away from the ball
        near.append((off, q, n))
    near.sort(key=lambda x: x[0])
    kept: list[FingerContact] = []
    tried: list[FloatArray] = []
    for _, q, n in near:
        if len(kept) >= MAX_CANDIDATES or len(tried) >= 3 * MAX_CANDIDATES:
            break
        if any(float(n @ m) > math.cos(DISTINCT) for m in tried):
            continue
        tried.append(n)
        miss.tried += 1
        got = grasp_on_ball(f, q, c, radius, n, margin=margin)
        if got is not None:  # a passive joint's tendon at the bound its load needs
            held = at_tendon_bounds(f, got, c, radius)
            got = None if isinstance(held, str) else held[1]
        if got is None:
            miss.unpulled += 1
            continue
        if not _outside(f, got, c, radius):
            miss.inside += 1
            continue
        s = tip_state(f, got, c, radius)
        if s.polar > seam:  # moved to hold a tendon at its bound: the contact off the cap
            miss.off += 1
            continue
        reach, stop = (None, "") if not turns else _roll_through(f, got, c, radius, turns,
                                                                  margin)
        kept.append(FingerContact(got, s.n, s.centre, s.m, reach, stop))
    return kept, miss


def _pick(per: list[list[FingerContact]], keep: int, ranked: bool) -> list[list[int]]:
    """Per finger the indices of its candidates weighed in combinations, in order of
    preference: its ``keep`` farthest-reaching (when ``ranked``) interleaved with ``keep``
    of its most distinct normals; trimmed (the least preferred first, from the longest)
    until the combinations number at most :data:`MAX_COMBINATIONS`."""
    out = []
    for cands in per:
        idx: list[int] = []
        if ranked:
            idx = sorted(range(len(cands)), key=lambda k: -(cands[k].reach or 0.0))[:keep]
        fps = [0] if cands else []
        N = np.array([c.normal for c in cands]) if cands else np.zeros((0, 3))
        while len(fps) < min(keep, len(cands)):
            dmin = np.min(N @ N[fps].T, axis=1)  # cos to the nearest chosen
            dmin[fps] = np.inf
            fps.append(int(np.argmin(dmin)))
        order: list[int] = []
        for pair in itertools.zip_longest(idx, fps):
            order += [k for k in pair if k is not None and k not in order]
        out.append(order)
    while math.prod(len(o) for o in out) > MAX_COMBINATIONS:
        max(out, key=len).pop()
    return out


def first_grasp(fingers: Sequence[Any], centre: ArrayLike, radius: float | ObjectGeometry,
                turns: Sequence[Any] = (), mu: float = 0.5,
                fixed: Sequence[ArrayLike | None] | None = None,
                seeds: Sequence[Sequence[ArrayLike]] | None = None, samples: int = 1500,
                keep: int = 8, min_gap: float = 1e-3, margin: float = 0.002,
                seed: int = 0, names: Sequence[str] | None = None,
                prefer: Callable[[tuple[FingerContact, ...]], bool] | None = None,
                clear: Callable[[FloatArray], Any] | None = None,
                held: Held | None = None, skip: int = 0) -> FirstGrasp:
    """A first grasp of the ball of ``radius`` [m] at ``centre``, or of the object
    ``radius`` (an :class:`ObjectGeometry`: without ``held``, ``turns`` only reported as
    requested, the grasps ranked by their joints' room, :func:`joint_room`, then
    closure), by the round
    tips of ``fingers`` (module docstring): per
    finger its joints ``fixed[i]`` when given, else searched (``samples`` joint vectors,
    ``seeds[i]`` first); the combination with the largest least reach through ``turns``
    (:func:`desired_turns`; none: the most closed grasp), tips ``min_gap`` [m] apart,
    contacts ``margin`` [m] from the caps' seams.
    ``prefer``: of the grasps passing the planner's grasp-angle test, in that order, the
    first it accepts (a gait's: every fingertip liftable); the first of all when it
    accepts none. ``clear``: the least clearance of the hand's other links (an
    :class:`ocp.robots.collision.Clearance`) over rows of all fingers' joints (the grasp,
    and each finger's rolled motion halfway through each of ``turns`` and at its end); a
    grasp below :data:`GRASP_LINK_CLEARANCE` is never taken. ``held``: the object
    (:class:`~ocp.shapes.held.Held`) of an :class:`ObjectGeometry` search with a closed-form
    nearest point: its candidates are then rolled through ``turns`` on its surface
    (:func:`~ocp.robots.grasp_reach.roll` with ``held``) and ranked by that reach, as a
    ball's. ``skip``: the grasp after the ``skip`` best (those ``prefer`` accepts first,
    then the others, each in the order above), for a caller whose plan from the best
    failed (the service's gaits try the next ones). :class:`GraspNotFoundError`
    naming ``fingers[i]`` or ``grasp`` when there is none (or no other)."""
    from ocp.geometry.grasp import force_angles

    c = np.asarray(centre, dtype=float)
    rng = np.random.default_rng(seed)
    names = list(names) if names is not None else [f"finger{i}" for i in range(len(fingers))]
    requested = float(sum(t.angle for t in turns))
    geo = radius if isinstance(radius, ObjectGeometry) else None
    rho = 0.0 if isinstance(radius, ObjectGeometry) else float(radius)
    what = "the ball" if geo is None else f"the {geo.shape}"
    if held is not None and held.ball:
        held = None
    turns = [] if geo is not None and held is None else _capped(turns, MAX_SEARCH_TURN)
    per: list[list[FingerContact]] = []
    errors: list[tuple[str, str]] = []
    for i, f in enumerate(fingers):
        q_fixed = None if fixed is None else fixed[i]
        if q_fixed is not None:
            q = np.asarray(q_fixed, dtype=float)
            if geo is not None:
                R_l, p_l = f.fingertip_pose_pin(q)
                tc = p_l + R_l @ _tip(f)[0]
                _, t, nrm = geo.nearest(tc - c)
                reach, stop = (None, "") if not turns else _roll_through(
                    f, q, c, rho, turns, margin, held=held)
                per.append([FingerContact(q, nrm, tc, R_l.T @ (-nrm), reach, stop,
                                          tc - t * nrm)])
                continue
            s = tip_state(f, q, c, rho)
            reach, stop = (None, "") if not turns else _roll_through(f, q, c, rho, turns,
                                                                      margin)
            per.append([FingerContact(q, s.n, s.centre, s.m, reach, stop)])
            continue
        got, miss = finger_contacts(f, c, radius, [] if seeds is None else seeds[i],
                                       samples, turns, margin, rng)
        if turns and geo is not None:  # rolled on the object's surface
            rolled_ = [_roll_through(f, ct.q, c, rho, turns, margin, held=held) for ct in got]
            got = [replace(ct, reach=rs[0], stop=rs[1])
                   for ct, rs in zip(got, rolled_, strict=True)]
        if not got:
            size = f"radius {rho * 1e3:.3g} mm" if geo is None else \
                f"chart parameters {', '.join(f'{x:.3g}' for x in geo.params)}"
            errors.append((f"fingers[{i}]", f"finger {names[i]!r} cannot touch {what} "
                                            f"({size} at {_mm(c)} mm) with its round tip: "
                                            f"{miss.why(samples, what)}; move {what} "
                                            "(initial_pose) within the fingers' reach"))
        per.append(got)
    if errors:
        raise GraspNotFoundError(errors)
    idx = _pick(per, keep, bool(turns))
    combos = np.array(list(itertools.product(*idx)), dtype=int)  # (k, n)
    n = len(fingers)
    N = np.stack([np.array([per[i][k].normal for k in range(len(per[i]))])[combos[:, i]]
                  for i in range(n)], axis=1)
    ends = [_body_ends(f, per[i]) for i, f in enumerate(fingers)]
    gap = np.full(len(combos), np.inf)
    for a, b in itertools.combinations(range(n), 2):
        (a0, b0, r0), (a1, b1, r1) = ends[a], ends[b]
        ka, kb = combos[:, a], combos[:, b]
        gap = np.minimum(gap, segments_distance(a0[ka], b0[ka], a1[kb], b1[kb]) - r0 - r1)
    P = None if geo is None or n != 2 else np.stack([np.array(
        [per[i][k].point for k in range(len(per[i]))])[combos[:, i]] for i in range(n)], axis=1)
    across = None if geo is None else geo.closure_directions()
    clo = np.concatenate([closure(N[k:k + 4096], None if P is None else P[k:k + 4096],
                                  across) for k in range(0, len(combos), 4096)]) \
        if n >= 2 else np.zeros(len(combos))
    least = np.zeros(len(combos))
    if turns:
        R = np.stack([np.array([min(per[i][k].reach or 0.0, requested, MAX_SEARCH_TURN)
                                for k in range(len(per[i]))])[combos[:, i]]
                      for i in range(n)], axis=1)
        least = np.round(R.min(axis=1), 3)  # ~0.06 deg: equal reaches tie
    elif geo is not None:  # another shape than a ball: the room the joints leave to roll
        room = np.stack([np.array([joint_room(fingers[i], per[i][k].q)
                                   for k in range(len(per[i]))])[combos[:, i]]
                         for i in range(n)], axis=1)
        least = np.round(room.min(axis=1), 2)  # 1 % of a joint's range: equal rooms tie
    cone = math.sin(math.atan(mu))
    apart, closed = gap >= min_gap, (clo > 0.0) if n >= 3 else (clo > -cone)
    ok = apart & closed
    if not ok.any():
        need = "> 0" if n >= 3 else f"> {-cone:.3g}"
        why = (f"in none are the tips {min_gap * 1e3:.3g} mm apart (the widest gap "
               f"{float(gap.max()) * 1e3:.3g} mm: the fingertips overlap where they touch "
               f"{what})" if not apart.any() else
               f"none holds {what} in force closure (the most closed reaches "
               f"{float(clo.max()):.3g}, {need} needed)" if not closed.any() else
               f"those with the tips {min_gap * 1e3:.3g} mm apart ({int(apart.sum())}) are "
               f"not in force closure (the most closed of them reaches "
               f"{float(clo[apart].max()):.3g}, {need} needed) and those in force closure "
               f"({int(closed.sum())}) have tips closer (their widest gap "
               f"{float(gap[closed].max()) * 1e3:.3g} mm)")
        raise GraspNotFoundError([("grasp", (
            f"no combination of the fingers' contacts ({', '.join(str(len(p)) for p in per)} "
            f"candidates per finger, {len(combos)} combinations) holds {what}: {why}; give "
            f"more fingers, or move {what} (initial_pose)"))])
    good = ok & (clo >= (GOOD_CLOSURE if n >= 3 else -0.5 * cone))
    pool = good if good.any() else ok
    order = np.lexsort((-clo, -least))  # by reach, then closure (last key first)
    chosen = [k for k in order if pool[k]]
    #: the grasps that pass, in order: those ``prefer`` accepts, and the others
    accepted: list[tuple[int, tuple[FingerContact, ...], float]] = []
    others: list[tuple[int, tuple[FingerContact, ...], float]] = []
    worst: Any = None  # the nearest links of the grasps refused for them
    tried, budget = 0, 20 if prefer is None else 60
    paths: dict[tuple[int, int], list[FloatArray]] = {}

    def rolled(i: int, k: int) -> list[FloatArray]:
        """Finger i's candidate k: its joints at the grasp and along the turns."""
        got = paths.get((i, k))
        if got is None:
            q = np.asarray(per[i][k].q, dtype=float)
            got = [q]
            on = held
            for t in turns:
                for _ in range(2):
                    r = roll(fingers[i], got[-1], c, rho, t.axis, t.angle / 2, margin,
                             COARSE_STEP, held=on)
                    got.append(np.asarray(r.q, dtype=float))
                    on = None if on is None else on.turned(t.axis, t.angle / 2)
            paths[(i, k)] = got
        return got

    for k in chosen[:budget if clear is None else LINK_TRIES]:
        contacts = tuple(per[i][combos[k, i]] for i in range(n))
        pts = np.array([c + rho * ct.normal if ct.point is None else ct.point
                        for ct in contacts])[None]
        nrm = np.array([ct.normal for ct in contacts])[None]
        phi, _, onto = force_angles(pts, nrm) if n >= 2 else (np.zeros(1), None,
                                                               np.ones(1, dtype=bool))
        # the planner's own test: the grasp angle below atan(mu)
        if n < 2 or (bool(onto[0]) and float(phi[0]) < math.atan(mu)):
            angle = float(phi[0]) if n >= 2 else 0.0
            if clear is not None:
                tried += 1
                got = clear(np.array([np.concatenate(row) for row in zip(*(
                    rolled(i, int(combos[k, i])) for i in range(n)), strict=True)]))
                if got.value < GRASP_LINK_CLEARANCE:
                    if worst is None or got.value > worst.value:
                        worst = got
                    continue
                budget -= 1  # of the clear grasps, as many weighed as without the links
            if prefer is None or prefer(contacts):
                accepted.append((k, contacts, angle))
                if len(accepted) > skip:
                    break
            else:
                others.append((k, contacts, angle))
            if clear is not None and budget <= 0:
                break
    ranked = accepted + others
    if skip and len(ranked) <= skip:
        raise GraspNotFoundError([("grasp", f"no grasp besides the {len(ranked)} tried")])
    if ranked:
        k, contacts, angle = ranked[skip]
        if turns:  # the chosen grasp's reach at the planner's check's step
            contacts = tuple(_fine(f, ct, c, rho, turns, margin, held)
                             for f, ct in zip(fingers, contacts, strict=True))
        return FirstGrasp(contacts, float(clo[k]), float(gap[k]), angle, requested,
                          tuple(len(p) for p in per), len(combos))
    if worst is not None:
        raise GraspNotFoundError([("grasp", (
            f"of the {tried} grasps that hold {what}, none keeps the hand's other links "
            f"{GRASP_LINK_CLEARANCE * 1e3:g} mm clear of {what} and of each other: at "
            f"best {worst.describe()}; move {what} (initial_pose) or give "
            "fewer fingers"))])
    raise GraspNotFoundError([("grasp", f"no combination's grasp angle is below atan(mu) = "
                                   f"{math.degrees(math.atan(mu)):.3g} deg (mu {mu}) with a "
                                   "grasp map onto; raise mu or give more fingers")])


def _body_ends(f: Any, cands: Sequence[FingerContact]) -> tuple[FloatArray, FloatArray, float]:
    """The ends of finger ``f``'s tip body (:mod:`ocp.geometry.bodies`: a capsule's whole
    segment) at each candidate's joints (palm frame, one row each) and its radius."""
    body = tip_body(f)
    ends = [body.placed(*f.fingertip_pose_pin(np.asarray(ct.q, dtype=float))) for ct in cands]
    return np.array([e[0] for e in ends]), np.array([e[1] for e in ends]), body.r


def _fine(f: Any, ct: FingerContact, centre: FloatArray, radius: float,
          turns: Sequence[Any], margin: float, held: Held | None = None) -> FingerContact:
    from ocp.robots.grasp_reach import STEP

    reach, stop = _roll_through(f, ct.q, centre, radius, turns, margin, STEP, held)
    return replace(ct, reach=reach, stop=stop)


def joint_room(f: Any, q: ArrayLike) -> float:
    """The least distance of the finger's joints ``q`` from their limits, as a share of
    each joint's range (0 at a limit, 0.5 mid-range)."""
    lo, hi = np.asarray(f.lower, dtype=float), np.asarray(f.upper, dtype=float)
    qa = np.asarray(q, dtype=float)
    return float(np.min(np.minimum(qa - lo, hi - qa) / np.maximum(hi - lo, 1e-12)))


def _mm(p: FloatArray) -> str:
    return "(" + ", ".join(f"{1e3 * float(x):.3g}" for x in p) + ")"
