"""A first grasp of a ball for any hand: joint angles that put every chosen round fingertip
on the ball, the contacts opposing each other (force closure), and, where the ball's
motion is given, the grasp whose rolled reach toward that motion is largest.

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
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ocp.geometry.bodies import segments_distance, tip_body
from ocp.robots.couplings import project_couplings
from ocp.robots.grasp_reach import _tip, at_tendon_bounds, grasp_on_ball, roll, tip_state

__all__ = [
    "GOOD_CLOSURE",
    "FingerContact",
    "FirstGrasp",
    "GraspNotFoundError",
    "closure",
    "desired_turns",
    "finger_contacts",
    "first_grasp",
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


def closure(normals: ArrayLike) -> FloatArray:
    """The closure of contact normals (..., n, 3) (outward, unit): three or more, the
    least over directions u (200 on the sphere) of ``max_i n_i . u``, > 0 iff the origin
    is inside their hull (the inward pushes alone balance any force on a ball); two, minus
    the sine of the larger grasp angle (0: antipodal)."""
    N = np.asarray(normals, dtype=float)
    if N.shape[-2] == 2:
        d = N[..., 1, :] - N[..., 0, :]  # ball contacts: p_i = c + rho n_i
        d = d / np.maximum(np.linalg.norm(d, axis=-1, keepdims=True), 1e-12)
        c1 = np.clip(-np.sum(N[..., 0, :] * d, axis=-1), -1.0, 1.0)
        c2 = np.clip(np.sum(N[..., 1, :] * d, axis=-1), -1.0, 1.0)
        ang = np.maximum(np.arccos(c1), np.arccos(c2))
        return np.asarray(-np.sin(ang))
    return np.asarray((N @ _DIRECTIONS.T).max(axis=-2).min(axis=-1))


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
                  turns: Sequence[Any], margin: float, step: float = COARSE_STEP
                  ) -> tuple[float, str]:
    """How far [rad] the finger rolls through the turns (one after the other) before its
    first stop, and the stop ("" none)."""
    done = 0.0
    for turn in turns:
        r = roll(f, q, centre, radius, turn.axis, turn.angle, margin, step)
        done += r.reach
        if r.why or r.reach < turn.angle - 1e-9:
            return done, r.why
        q = r.q
    return done, ""


def finger_contacts(f: Any, centre: ArrayLike, radius: float, seeds: Sequence[ArrayLike] = (),
                    samples: int = 1500, turns: Sequence[Any] = (), margin: float = 0.002,
                    rng: np.random.Generator | None = None
                    ) -> tuple[list[FingerContact], float]:
    """Finger ``f``'s candidate contacts on the ball (module docstring), at most
    :data:`MAX_CANDIDATES`, and the least distance [m] of its tip's centre from the
    sphere of contact over the samples (why none, when none)."""
    rng = rng if rng is not None else np.random.default_rng(0)
    c = np.asarray(centre, dtype=float)
    pc, ax, r = _tip(f)
    shell = radius + r
    band = max(0.01, 0.3 * shell)
    seam = math.pi / 2 - margin / r
    lo, hi = _limits(f)
    Q = [np.clip(np.asarray(s, dtype=float), lo, hi) for s in seeds]
    Q += [(lo + hi) / 2, *(lo + (hi - lo) * rng.random((samples, f.nq)))]
    if getattr(f, "couplings", ()):  # drawn within the couplings too
        Q = [project_couplings(f, q) for q in Q]
    near: list[tuple[float, FloatArray, FloatArray]] = []
    closest = math.inf
    for q in Q:
        R_l, p_l = f.fingertip_pose_pin(q)
        d = p_l + R_l @ pc - c
        dist = float(np.linalg.norm(d))
        off = abs(dist - shell)
        closest = min(closest, off)
        if off > band or dist < 1e-9:
            continue
        n = d / dist
        if ax is not None and math.acos(max(-1.0, min(1.0, float(-n @ (R_l @ ax))))) > seam:
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
        got = grasp_on_ball(f, q, c, radius, n, margin=margin)
        if got is not None:  # a passive joint's tendon at the bound its load needs
            held = at_tendon_bounds(f, got, c, radius)
            got = None if isinstance(held, str) else held[1]
        if got is None or not _outside(f, got, c, radius):
            continue
        s = tip_state(f, got, c, radius)
        reach, stop = (None, "") if not turns else _roll_through(f, got, c, radius, turns,
                                                                  margin)
        kept.append(FingerContact(got, s.n, s.centre, s.m, reach, stop))
    return kept, closest


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


def first_grasp(fingers: Sequence[Any], centre: ArrayLike, radius: float,
                turns: Sequence[Any] = (), mu: float = 0.5,
                fixed: Sequence[ArrayLike | None] | None = None,
                seeds: Sequence[Sequence[ArrayLike]] | None = None, samples: int = 1500,
                keep: int = 8, min_gap: float = 1e-3, margin: float = 0.002,
                seed: int = 0, names: Sequence[str] | None = None,
                prefer: Callable[[tuple[FingerContact, ...]], bool] | None = None,
                clear: Callable[[FloatArray], Any] | None = None
                ) -> FirstGrasp:
    """A first grasp of the ball of ``radius`` at ``centre`` by the round tips of
    ``fingers`` (module docstring): per finger its joints ``fixed[i]`` when given, else
    searched (``samples`` joint vectors, ``seeds[i]`` first); the combination with the
    largest least reach through ``turns`` (:func:`desired_turns`; none: the most closed
    grasp), tips ``min_gap`` [m] apart, contacts ``margin`` [m] from the caps' seams.
    ``prefer``: of the grasps passing the planner's grasp-angle test, in that order, the
    first it accepts (a gait's: every fingertip liftable); the first of all when it
    accepts none. ``clear``: the least clearance of the hand's other links (an
    :class:`ocp.robots.collision.Clearance`) over rows of all fingers' joints (the grasp,
    and each finger's rolled motion halfway through each of ``turns`` and at its end); a
    grasp below :data:`GRASP_LINK_CLEARANCE` is never taken. :class:`GraspNotFoundError`
    naming ``fingers[i]`` or ``grasp`` when there is none."""
    from ocp.geometry.grasp import force_angles

    c = np.asarray(centre, dtype=float)
    rng = np.random.default_rng(seed)
    names = list(names) if names is not None else [f"finger{i}" for i in range(len(fingers))]
    requested = float(sum(t.angle for t in turns))
    turns = _capped(turns, MAX_SEARCH_TURN)
    per: list[list[FingerContact]] = []
    errors: list[tuple[str, str]] = []
    for i, f in enumerate(fingers):
        q_fixed = None if fixed is None else fixed[i]
        if q_fixed is not None:
            q = np.asarray(q_fixed, dtype=float)
            s = tip_state(f, q, c, radius)
            reach, stop = (None, "") if not turns else _roll_through(f, q, c, radius, turns,
                                                                      margin)
            per.append([FingerContact(q, s.n, s.centre, s.m, reach, stop)])
            continue
        got, closest = finger_contacts(f, c, radius, [] if seeds is None else seeds[i],
                                       samples, turns, margin, rng)
        if not got:
            errors.append((f"fingers[{i}]", f"finger {names[i]!r} cannot touch the ball "
                                            f"(radius {radius * 1e3:.3g} mm at "
                                            f"{_mm(c)} mm) with its round tip: over "
                                            f"{samples} joint vectors within its limits its "
                                            "tip's centre came no closer than "
                                            f"{closest * 1e3:.3g} mm to where it would "
                                            "touch, or its cap faced away, or a link "
                                            "entered the ball; move the ball (initial_pose) "
                                            "within the fingers' reach"))
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
    clo = np.concatenate([closure(N[k:k + 4096]) for k in range(0, len(combos), 4096)]) \
        if n >= 2 else np.zeros(len(combos))
    least = np.zeros(len(combos))
    if turns:
        R = np.stack([np.array([min(per[i][k].reach or 0.0, requested, MAX_SEARCH_TURN)
                                for k in range(len(per[i]))])[combos[:, i]]
                      for i in range(n)], axis=1)
        least = np.round(R.min(axis=1), 3)  # ~0.06 deg: equal reaches tie
    cone = math.sin(math.atan(mu))
    ok = (gap >= min_gap) & ((clo > 0.0) if n >= 3 else (clo > -cone))
    if not ok.any():
        best_gap = float(gap.max())
        raise GraspNotFoundError([("grasp", (
            f"no combination of the fingers' contacts ({', '.join(str(len(p)) for p in per)} "
            f"candidates per finger, {len(combos)} combinations) holds the ball in force "
            f"closure with the tips at least {min_gap * 1e3:.3g} mm apart: the most closed "
            f"reaches {float(clo.max()):.3g} (> 0 needed), the widest gap "
            f"{best_gap * 1e3:.3g} mm; give more fingers, or move the ball "
            "(initial_pose)"))])
    good = ok & (clo >= (GOOD_CLOSURE if n >= 3 else -0.5 * cone))
    pool = good if good.any() else ok
    order = np.lexsort((-clo, -least))  # by reach, then closure (last key first)
    chosen = [k for k in order if pool[k]]
    first: tuple[int, tuple[FingerContact, ...], float] | None = None
    worst: Any = None  # the nearest links of the grasps refused for them
    tried, budget = 0, 20 if prefer is None else 60
    paths: dict[tuple[int, int], list[FloatArray]] = {}

    def rolled(i: int, k: int) -> list[FloatArray]:
        """Finger i's candidate k: its joints at the grasp and along the turns."""
        got = paths.get((i, k))
        if got is None:
            q = np.asarray(per[i][k].q, dtype=float)
            got = [q]
            for t in turns:
                for _ in range(2):
                    r = roll(fingers[i], got[-1], c, radius, t.axis, t.angle / 2, margin,
                             COARSE_STEP)
                    got.append(np.asarray(r.q, dtype=float))
            paths[(i, k)] = got
        return got

    for k in chosen[:budget if clear is None else LINK_TRIES]:
        contacts = tuple(per[i][combos[k, i]] for i in range(n))
        pts = np.array([c + radius * ct.normal for ct in contacts])[None]
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
            if first is None:
                first = (k, contacts, angle)
            if prefer is None or prefer(contacts):
                first = (k, contacts, angle)
                break
            if clear is not None and budget <= 0:
                break
    if first is not None:
        k, contacts, angle = first
        if turns:  # the chosen grasp's reach at the planner's check's step
            contacts = tuple(_fine(f, ct, c, radius, turns, margin)
                             for f, ct in zip(fingers, contacts, strict=True))
        return FirstGrasp(contacts, float(clo[k]), float(gap[k]), angle, requested,
                          tuple(len(p) for p in per), len(combos))
    if worst is not None:
        raise GraspNotFoundError([("grasp", (
            f"of the {tried} grasps that hold the ball, none keeps the hand's other links "
            f"{GRASP_LINK_CLEARANCE * 1e3:g} mm clear of the ball and of each other: at "
            f"best {worst.describe()}; move the ball (initial_pose) or give "
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
          turns: Sequence[Any], margin: float) -> FingerContact:
    from dataclasses import replace

    from ocp.robots.grasp_reach import STEP

    reach, stop = _roll_through(f, ct.q, centre, radius, turns, margin, STEP)
    return replace(ct, reach=reach, stop=stop)


def _mm(p: FloatArray) -> str:
    return "(" + ", ".join(f"{1e3 * float(x):.3g}" for x in p) + ")"
