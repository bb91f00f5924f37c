"""A fingertip re-placed while the others roll the ball (docs/gait.md, "Re-placing while
the others roll"; issue 40, item 2).

The gait's other re-placements stop the ball: unload, swing, load, with the others
holding it still. Here the swing is made **during a roll**: the fingertip is unloaded
(the ball still), the others roll the ball by the next step while it lifts off, swings
clear and lands, and it is loaded again (the ball still). The pieces:

* **the roll** is the rolling planner's plan of the grasp without the lifted fingertip
  (:func:`without`: the same problem, its fingers less that one), on its own clock
  (:class:`~ocp.gait.warp.RollClock`), which starts and ends at rest;
* **the swing** (:mod:`ocp.gait.swing`) is planned on the same clock, from the roll's
  start to its end, with the rolling fingertips' bodies and the hand's nearest links as
  **moving** obstacles (their segments at every node of the swing's grid:
  :attr:`~ocp.gait.swing.SwingSpec.moving`); it lands when the roll ends, so the ball is
  at rest at the touch-down;
* **the holds** around it: the unloading at the roll's start (every fingertip's forces
  to the others' with this one's zero), the loading at its end (back), as a gait step's
  (:class:`~ocp.gait.step.GaitStep` with ``during_roll``).

The ball's centre is fixed in a gait's turn (each roll's goal is the centre it started
at), and a ball turned about its centre fills the same space: the swing's clearance
from the ball does not depend on how far the roll has turned it. The ball's centre does
move within the roll's tracking tolerance; the swing keeps its clearance from the ball's
centre at its landing plus that motion (:data:`CENTRE_DRIFT_TOL`: the roll is refused
for an overlap when its centre moves farther), and the landing is at the ball's end
position.

What the certificate checks: the roll's own certificate (its fingertips, forces, cones,
no slip), the roll's clock (the switches at rest, every joint's rate and acceleration,
the swinging tip among the others: ``roll<r>_tip_gap``), the swing's own laws with the
others where they are at each dense sample (``swing_tip_gap_step<i>_<j>``), the ramps'
holds; the gait's links' clearance covers the swinging finger's links (the whole gait at
100 Hz: :func:`~ocp.gait.samples.with_link_clearance`)."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ocp.gait.step import (
    DAMPING_SLACK,
    MAX_SLOWDOWN,
    SWING_OBSTACLES,
    GaitStep,
    TorqueLimits,
    contact_of,
    deep_forces,
    dense_enough,
    driven_factors,
    driven_passes,
    find_swing,
    grasp_hold,
    swing_spec,
)
from ocp.gait.swing import MIN_TIP_GAP, NARROW_SHARE, SwingPlan, SwingSpec, plan_swing
from ocp.gait.warp import RollClock
from ocp.geometry.bodies import point_segment_distance, tip_body
from ocp.shapes.held import Held
from ocp.spec.grasp import ManipulationProblem

__all__ = ["OVERLAP_HOLD_DEPTH", "OVERLAP_SWING", "OverlapRoll", "at_landing", "hold_depth",
           "lift_next", "plan_overlap", "stranded_fingers", "without"]

FloatArray = NDArray[np.float64]

#: The shortest a swing during a roll is tried at first [s] (the swings of the built-in
#: hand's fingers find no path faster than 0.4-0.56 s within 20 rad/s^2): the roll's clock
#: is slowed to it when the roll alone is shorter.
OVERLAP_SWING = 0.45
#: How many times a swing during a roll is tried, each 1.4 times longer (the roll's clock
#: slowed with it) when the last was not found; one found after a length that was not is
#: tried once more halfway between the two (:func:`plan_overlap`).
OVERLAP_TRIES = 3
#: The swing's clearance and gaps kept this much more [m] at its NLP's nodes: the others
#: move between them (2.98 mm against 2.99 mm, 2.69 against 2.70, measured without).
NODE_MARGIN = 5e-5
#: How far [m] the ball's centre may move during a roll that carries a swing: the swing
#: keeps this much more clearance from the ball's centre at the landing.
CENTRE_DRIFT_TOL = 2e-4


#: The extra cone margin [rad] a roll made while a fingertip swings is planned with, where
#: the others' hold of the still ball allows it (:func:`hold_depth`; none where it does
#: not): a roll by fewer fingertips whose forces rode 0.05 rad inside their cones lost the
#: ball in MuJoCo on a user's hand driven by its own servos (examples/own_hand.xml, its
#: thumb lifted: docs/gait.md).
OVERLAP_HOLD_DEPTH = 0.1


def without(template: ManipulationProblem, k: int, extra_margin: float = 0.0
            ) -> ManipulationProblem:
    """The grasp of ``template`` without fingertip ``k``: the roll the others make while it
    swings, its forces ``extra_margin`` [rad] deeper inside the cones. Its links are left to
    the gait's own check (the roll's would stand the lifted finger at its joints'
    defaults)."""
    forces = template.forces
    if forces is not None and extra_margin > 0.0:
        forces = replace(forces, cone_margin=forces.cone_margin + extra_margin)
    return replace(template, fingers=tuple(f for i, f in enumerate(template.fingers)
                                           if i != k), collision=None, forces=forces)


def hold_depth(template: ManipulationProblem, qs: tuple[FloatArray, ...], k: int,
               centre: FloatArray, rho: float, rotation: FloatArray, load: FloatArray
               ) -> float:
    """How much [rad] the friction cones can be narrowed with the others still holding the
    still ball without fingertip ``k`` (:func:`~ocp.gait.hold.deep_hold_forces`; -1 when
    they cannot hold it)."""
    from ocp.gait.hold import deep_hold_forces

    fingers = tuple(f.finger for f in template.fingers)
    rest = [i for i in range(len(fingers)) if i != k]
    F, depth = deep_hold_forces(grasp_hold(fingers, qs, rest, Held(centre, rotation, rho)),
                                load, rho)
    return -1.0 if F is None else float(depth)


def lift_next(spent: list[int], reach: dict[int, float]) -> int | None:
    """Of the ``spent`` fingertips, the one to re-place during the next roll: the one whose
    rolled ``reach`` is the least, one whose reach is not known (infinite:
    :func:`~ocp.gait.planner.spent_reach`) first; None when none is spent."""
    if not spent:
        return None
    return min(spent, key=lambda k: -math.inf if math.isinf(reach[k]) else reach[k])


@dataclass(frozen=True)
class OverlapRoll:
    """The roll and the swing made together, once planned (:func:`plan_overlap`): the
    roll's plan and clock, the gait step (its swing, the holds), the joints after."""

    sol: Any
    clock: RollClock
    step: GaitStep
    q_after: tuple[FloatArray, ...]


def _moving(template: ManipulationProblem, k: int, sol: Any, clock: RollClock,
            q_now: tuple[FloatArray, ...], centre: FloatArray, links: list[int] | None,
            obstacles_at: Any) -> Any:
    """``moving(t)`` of the swing of fingertip ``k`` during the roll ``sol`` on ``clock``:
    the rolling fingertips' bodies and the hand's links ``links`` (indices into
    ``obstacles_at``'s list) at the times ``t``."""
    keep = [i for i in range(len(template.fingers)) if i != k]
    nq = [int(template.fingers[i].finger.nq) for i in keep]
    cut = np.cumsum((0, *nq))

    def joints(t: FloatArray) -> FloatArray:
        s = clock(np.asarray(t, dtype=float))[0]
        return np.asarray(sol.joint_trajectory(s, efforts=False).positions, dtype=float)

    def moving(t: Any) -> list[tuple[FloatArray, FloatArray]]:
        Q = joints(np.atleast_1d(np.asarray(t, dtype=float)))
        out = []
        for c, i in enumerate(keep):
            f = template.fingers[i].finger
            body = tip_body(f)
            ends = [body.placed(*f.fingertip_pose_pin(row[cut[c]:cut[c + 1]])) for row in Q]
            out.append((np.array([e[0] for e in ends]), np.array([e[1] for e in ends])))
        if links:
            segs = []
            for row in Q:
                qs = list(q_now)
                for c, i in enumerate(keep):
                    qs[i] = row[cut[c]:cut[c + 1]]
                every = obstacles_at(tuple(qs))
                segs.append([every[j][1] for j in links])
            for m in range(len(links)):
                out.append((np.array([sg[m][0] for sg in segs]),
                            np.array([sg[m][1] for sg in segs])))
        return out

    return moving


def _link_choice(template: ManipulationProblem, k: int, samples: list[Any],
                 centre: FloatArray) -> tuple[list[int], Any, list[str], list[float]]:
    """The hand's links the swing keeps clear of: the :data:`~ocp.gait.step.
    SWING_OBSTACLES` nearest the ball over the roll (at every finger's joints
    ``samples``: its start, middle and end), as
    (their indices in the obstacles' list, ``obstacles_at(qs)``, names, radii); none
    without a collision model."""
    coll = template.collision
    if coll is None:
        return [], None, [], []
    names = [n for f in template.fingers for n in f.finger.joint_names]
    shape, dims = template.object.shape, template.object.dimensions

    def obstacles_at(qs: tuple[FloatArray, ...]) -> list[Any]:
        return coll.obstacles(shape, dims, names, np.concatenate(qs), k)

    near: dict[int, float] = {}
    for qs in samples:
        for j, (_, (a, b, r)) in enumerate(obstacles_at(qs)):
            d = float(point_segment_distance(centre, a, b)) - r
            near[j] = min(near.get(j, math.inf), d)
    chosen = sorted(near, key=lambda j: near[j])[:SWING_OBSTACLES]
    first = obstacles_at(samples[0])
    return chosen, obstacles_at, [first[j][0] for j in chosen], [first[j][1][2] for j in chosen]


def plan_overlap(template: ManipulationProblem, planner: Any, k: int,
                 q_now: tuple[FloatArray, ...], q_land: FloatArray, roll_problem: Any,
                 warm: Any, speed_of: Any, centre: FloatArray, rho: float,
                 rotation: FloatArray, load: FloatArray, swing: dict[str, Any] | None,
                 hold_time: float, limits: TorqueLimits | None, names: tuple[str, ...],
                 last_swing: SwingPlan | None
                 ) -> tuple[OverlapRoll | None, str, int | None]:
    """Plan fingertip ``k``'s re-placement at the joints ``q_land`` during the roll
    ``roll_problem`` of the others (its problem, :func:`without` ``k``, from the joints
    ``q_now`` less ``k``'s; ``warm`` its warm start; ``speed_of(sol)`` its clock's speed).
    (the plan, "", None) or (None, why not, the rolling fingertip in the swing's way when
    that is why): the others cannot hold the ball, the roll is not certified, its centre
    moves, or no swing is found on its clock. The swing is tried at lengths 1.4 times
    apart (:data:`OVERLAP_TRIES`), the roll's clock slowed with it; one found after a
    length that was not is tried once more at the geometric mean of the two, warm from
    the one found, and that is kept when it is found and within the damping."""
    fingers = tuple(f.finger for f in template.fingers)
    nf = len(fingers)
    allf, rest = list(range(nf)), [i for i in range(nf) if i != k]
    before, rest_start, F_before = _holds(fingers, q_now, k, centre, rho, rotation, load,
                                          limits)
    if F_before is None:
        return None, "the fingertips cannot hold the ball", None
    sol = planner.solve(roll_problem, warm, reach_checked=True)
    if not (sol.ok and sol.certificate.passed):
        return None, f"the roll without {names[k]} was not certified: {sol.status}", None
    drift = float(np.linalg.norm(np.asarray(sol.object_position)
                                 - np.asarray(sol.object_position)[-1], axis=1).max())
    if drift > CENTRE_DRIFT_TOL:
        return None, (f"the ball's centre moves {drift * 1e3:.2f} mm in the roll without "
                      f"{names[k]}"), None
    end = np.asarray(sol.object_position[-1], dtype=float)
    clock = RollClock.of(float(sol.duration), speed_of(sol))
    spec_args = dict(swing or {})
    spec_args.pop("fastest", None)  # timed by the roll's clock
    base = float(spec_args.pop("duration", SwingSpec.duration))
    clearance = float(spec_args.pop("clearance", SwingSpec.clearance)) + drift
    length = max(clock.length, OVERLAP_SWING if last_swing is None else
                 min(last_swing.duration, base))
    _, n_land = contact_of(fingers[k], q_land, end, rho)  # (a ball's: overlap is for one)
    why = "no swing"
    # the actuators' rows against the damping, once a swing without them asked too much
    # of them (within_damping's reasons), and the slower swing planned before those rows
    # when none is found with them
    drive, fallback, driven = None, 0.0, []
    tries, found = OVERLAP_TRIES, False

    def spec_at(length: float, drive: Any) -> tuple[RollClock, SwingSpec]:
        clock = RollClock.lasting(float(sol.duration), length)
        samples = [tuple(_full_rows(sol, clock, t, q_now, k))
                   for t in (0.0, 0.5 * length, length)]
        links, obstacles_at, link_names, link_r = _link_choice(template, k, samples, end)
        moving = _moving(template, k, sol, clock, q_now, end, links, obstacles_at)
        at0 = moving(np.zeros(1))
        radii = [tip_body(fingers[i]).r for i in rest] + link_r
        others = tuple((a[0], b[0], r) for (a, b), r in zip(at0, radii, strict=True))
        return clock, SwingSpec(fingers[k], np.asarray(q_now[k], dtype=float),
                                np.asarray(q_land, dtype=float), n_land, end, rho, others,
                                duration=length, clearance=clearance, name=names[k],
                                other_names=tuple([names[i] for i in rest] + link_names),
                                moving=moving, node_margin=NODE_MARGIN,
                                centre_path=_centre_path(sol, clock), drive=drive,
                                **spec_args)

    def overrun(p: SwingPlan) -> float:
        """How many times the swing ``p`` asks more of the actuators than they give
        against the joints' damping (0 without damping), judged at its nodes: the
        actuators' rows keep its nodes and midpoints, and between them a swing at its
        rate bound asks 0.01-0.2 % more (up to 6 % where a servo gives 0.03 N m), which,
        re-planned 5 % slower each time, found the same and fell back to a re-placement
        at rest. An infinite overrun (a joint moving where its actuator gives nothing
        that way) counts as :data:`MAX_SLOWDOWN`, so that the roll is slowed by a finite
        factor."""
        if limits is None or not limits.rate:
            return 0.0
        return min(limits.damping_overrun(k, p.Q, p.V), MAX_SLOWDOWN)

    short = None
    while tries > 0 and not found:
        tries -= 1
        clock, spec = spec_at(length, drive)
        plan = plan_swing(spec, last_swing if last_swing is not None and len(
            last_swing.spec.others) == len(spec.others) else None)
        # the neighbours' gap narrowed as a swing at rest narrows it (replace_finger),
        # where a gap is what it breaks (about +x the thumb's swings in 0.45 s broke only
        # the ball's clearance: two narrowed tries, 593 IPOPT iterations, 1.6 s, for none)
        for narrow in ({"tip_gap": MIN_TIP_GAP},
                       {"tip_gap": MIN_TIP_GAP, "neighbour_share": NARROW_SHARE}):
            if plan.status != "infeasible" or not plan.gap_broken:
                break
            plan = plan_swing(replace(spec, **narrow))  # type: ignore[arg-type]
        plan = dense_enough(plan)  # (kept at its nodes, a moving neighbour's dips between)
        if plan.ok:
            over = overrun(plan)
            if over > 1.0:  # too fast for the joints' damping: slower, the roll with it
                why = f"{names[k]}'s swing is faster than its actuators' damping allows"
                assert limits is not None
                if not fallback and (drive := limits.drive(k)) is not None:
                    driven = [length * f for f in
                              driven_factors(limits.rate_overrun(k, plan.V), over)]
                    fallback = length * over * DAMPING_SLACK
                    length = driven.pop(0)
                    tries += 1 + len(driven)  # (the old slower swing stays the next)
                else:
                    length *= over * DAMPING_SLACK
                continue
        if plan.ok and (drive is None or driven_passes(plan)):
            found = True
            break
        why = plan.message or "the swing with the actuators' rows fails its own checks"
        if drive is not None:  # the swing with the actuators' rows not found: longer,
            if driven:  # then as before
                length = driven.pop(0)
            else:
                drive, length = None, fallback
            continue
        if plan.blocked_by is not None and plan.blocked_by < len(rest):
            # a rolling fingertip in its way, with the gaps narrowed too: named at once,
            # for it to be re-placed first (about -z the middle's swings were blocked by
            # the index at each of three lengths: 11 infeasible solves, 4.3 s, and then
            # named)
            return None, why, rest[plan.blocked_by]
        short = length
        length *= 1.4
    if not found:
        return None, why, None
    if short is not None and drive is None:
        # found only 1.4 times longer than a length that failed: once more halfway
        # (geometrically), from the swing found (same rolls and re-placements over the
        # seven target turns, 0.1-0.5 s less motion in five: docs/gait.md, session 32)
        mid = math.sqrt(short * length)
        clock_mid, spec_mid = spec_at(mid, None)
        quicker = dense_enough(plan_swing(spec_mid, plan))
        if quicker.ok and overrun(quicker) <= 1.0:
            plan, clock, length = quicker, clock_mid, mid
    q_after = tuple(plan.Q[-1] if i == k else row for i, row in
                    zip(allf, _full_rows(sol, clock, clock.length, q_now, k), strict=True))
    after, rest_end, F_after = _holds(fingers, q_after, k, end, rho, rotation, load,
                                      limits)
    if F_after is None:
        return None, f"the grasp with {names[k]} landed cannot hold the ball", None
    # the ramps meet the roll where its own forces are (both hold the still ball there:
    # every force on a ramp between them does too): the others' deep holds differed from
    # the roll's first and last forces by up to 0.9 N, a step the servos were asked for
    # (the certified roll shows that the others hold the ball at its ends)
    F_rest_start = sol.forces(np.array([0.0]))[0][0]
    F_rest_end = sol.forces(np.array([float(sol.duration)]), side="left")[0][0]
    step = GaitStep(k, "solved", "", plan, (before, rest_start, rest_end, after),
                    (F_before, F_rest_start, F_rest_end, F_after),
                    (tuple(allf), tuple(rest), tuple(rest), tuple(allf)), hold_time,
                    hold_time, q_after, during_roll=-1, q_before=tuple(q_now))
    return OverlapRoll(sol, clock, step, q_after), "", None


def _centre_path(sol: Any, clock: RollClock) -> Any:
    """The ball's centre during the roll ``sol`` on ``clock``, at times from its start
    (its plan's positions at the clock's plan times, interpolated)."""
    t_plan = np.asarray(sol.t, dtype=float)
    P = np.asarray(sol.object_position, dtype=float)

    def path(t: Any) -> FloatArray:
        s = clock(np.atleast_1d(np.asarray(t, dtype=float)))[0]
        return np.stack([np.interp(s, t_plan, P[:, j]) for j in range(3)], axis=1)

    return path


def _holds(fingers: tuple[Any, ...], qs: tuple[FloatArray, ...], k: int,
           centre: FloatArray, rho: float, rotation: FloatArray, load: FloatArray,
           limits: TorqueLimits | None) -> tuple[Any, Any, Any]:
    """The still ball held by every fingertip and by all but ``k`` at the joints ``qs``:
    (both holds, every fingertip's deep forces within the actuators, :func:`~ocp.gait.
    step.deep_forces`, None where they cannot hold it). The others' forces are the roll's
    own where it starts and ends (:func:`plan_overlap`)."""
    every = list(range(len(fingers)))
    rest = [i for i in every if i != k]
    holds = [grasp_hold(fingers, qs, w, Held(centre, rotation, rho)) for w in (every, rest)]
    return holds[0], holds[1], deep_forces(fingers, qs, every, holds[0], load, rho, limits)


def _full_rows(sol: Any, clock: RollClock, t: float, q_now: tuple[FloatArray, ...],
               k: int) -> list[FloatArray]:
    """Every finger's joints at time ``t`` of the roll (the rolling ones' from the plan on
    ``clock``; fingertip ``k``'s where it was)."""
    s = clock(np.array([float(t)]))[0]
    row = np.asarray(sol.joint_trajectory(s, efforts=False).positions, dtype=float)[0]
    out, at = [], 0
    for i, q in enumerate(q_now):
        if i == k:
            out.append(np.asarray(q, dtype=float))
            continue
        out.append(row[at:at + len(q)])
        at += len(q)
    return out


def at_landing(q: FloatArray, land: FloatArray, tol: float = 1e-9) -> bool:
    """Whether a fingertip at the joints ``q`` is where it lands (``land``), every joint
    within ``tol`` [rad]: its re-placement would move it nowhere."""
    return bool(np.abs(np.asarray(q) - np.asarray(land)).max() < tol)


def stranded_fingers(template: ManipulationProblem, q_after: tuple[FloatArray, ...],
                     lands: tuple[FloatArray, ...], centre: FloatArray, rho: float,
                     which: list[int], plan: Any, limits: TorqueLimits | None,
                     obstacles: Any, swing: dict[str, Any] | None) -> list[int]:
    """Of the fingertips ``which``, those that, with every finger at the joints ``q_after``
    and the ball still, would find no swing to their landing joints ``lands`` (the swing
    of the re-placement at rest a gait falls back to: :func:`~ocp.gait.step.swing_spec`
    and :func:`~ocp.gait.step.find_swing`, with the hand's links; warm-started from the
    fingertip's last swing at rest in ``plan``, not from its last check's: warmed so, the
    checks took 1905 IPOPT iterations about +x against 707 cold). A fingertip rolled too
    far from its landing finds none, and a gait that leaves one there cannot go on
    (measured about -x and +y: docs/gait.md). Only the swing is planned: the holds around
    it are the re-placement's own business (the fallback plans them; a check that planned
    them too spent 1.3 of its 4.2 s on them, about +x), with the neighbours' gaps narrowed
    only where a gap is what the swing not found breaks (about -x the middle's checks
    broke only the ball's clearance, each planned three times). ``limits``, ``obstacles``,
    ``swing``: the gait's (:func:`~ocp.gait.step.replace_finger`'s arguments)."""
    fingers = tuple(f.finger for f in template.fingers)
    names = tuple(f.name or f"finger{i}" for i, f in enumerate(template.fingers))
    held = Held(centre, np.eye(3), rho)
    out = []
    for j in which:
        if at_landing(q_after[j], lands[j]):
            continue  # where it lands
        last = next((st.swing for st in reversed(plan.steps) if st.finger == j
                     and st.swing is not None and st.swing.spec.moving is None), None)
        _, n_land = contact_of(fingers[j], lands[j], centre, rho)
        found = find_swing(swing_spec(fingers, q_after, j, n_land, lands[j], held, swing,
                                      last, names, limits, obstacles), last, narrow_any=False)
        if not found.ok:
            out.append(j)
    return out
