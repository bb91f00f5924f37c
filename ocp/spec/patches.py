"""Choosing the chart patch a plan's contacts are measured in (docs/conventions.md, "Chart
patches"; docs/shapes.md, "Charts").

The object's latitude/longitude chart is singular at its poles, so the planner keeps
``|u| <= pi/2 - pole_margin``. That bound is the chart's, not the physics': a plan whose
contact path rides it is shaped by the choice of patch (and its motion is not smooth
where the bound engages, which costs grid refinements). For a sphere any rotated patch
describes the same body, so the planner may re-plan in a patch whose poles are far from
the contact's path: :func:`pole_clear_patch` picks one, :func:`recharted` states the same
request in it (the same physical initial grasp, goals and via-points).

An egg's fingertip contacts have a second chart, its side chart (poles on its equator,
``ObjectSpec.side_chart``; docs/shapes.md, "Charts"): :func:`turns_off_chart` predicts
whether a motion carries a contact past the own chart's bound, :func:`rides_bound` tells
a plan that rode it, :func:`side_charted` states the same problem on the side chart, and
:func:`planned_problem` the problem on whichever charts a plan was made on.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from ocp.geometry.rotations import log_rotation
from ocp.geometry.surfaces import Chart, rotation_from_vector

if TYPE_CHECKING:
    from ocp.spec.grasp import ManipulationProblem

__all__ = ["planned_problem", "pole_clear_patch", "recharted", "recharted_coordinates",
           "rides_bound", "rides_pole", "side_charted", "switching_chart", "turns_off_chart"]

FloatArray = NDArray[np.float64]

#: A contact this close to the pole bound [rad] rides it.
RIDING = 1e-6
#: A plan whose fingertip contacts all start within this share of the object chart's bound
#: is not predicted to carry one beyond it (:func:`turns_off_chart`).
NEAR_BOUND = 0.5
#: Candidate pole directions: a Fibonacci lattice on the sphere (about 4 deg apart).
_N_CANDIDATES = 2000


def _psi_matrix(psi: float) -> FloatArray:
    c, s = math.cos(psi), math.sin(psi)
    return np.array([[c, -s, 0.0], [-s, -c, 0.0], [0.0, 0.0, -1.0]])


def recharted_coordinates(chart_old: Chart, chart_new: Chart, coords: Mapping[str, float]
                          ) -> dict[str, float] | None:
    """The palm contact coordinates ``coords`` (any of x, y, u, v, psi) measured in the
    new patch: the same palm point, the same object point, the same object orientation.
    None when they cannot be restated: psi without u and v (the contact angle is measured
    against the patch's frame at the object point), or only one of u, v."""
    out = {k: float(v) for k, v in coords.items() if k in ("x", "y")}
    has = {k for k in ("u", "v", "psi") if k in coords}
    if not has:
        return out
    if not {"u", "v"} <= has:
        return None
    p_old, G_old = chart_old.frame([coords["u"], coords["v"]])
    uv = np.asarray(chart_new.inverse(p_old), dtype=float).ravel()
    _, G_new = chart_new.frame(uv)
    out["u"], out["v"] = float(uv[0]), float(uv[1])
    if "psi" in has:
        # R_psi' = R_psi G_old^T G_new (the object's orientation unchanged)
        M = _psi_matrix(coords["psi"]) @ G_old.T @ G_new
        out["psi"] = float(math.atan2(-M[0, 1], M[0, 0]))
    return out


def rides_pole(problem: ManipulationProblem, u: FloatArray) -> bool:
    """Whether the palm contact's latitudes ``u`` (its path) reach the pole bound."""
    limit = math.pi / 2 - problem.pole_margin
    return bool(np.max(np.abs(u)) >= limit - RIDING)


def _fibonacci(n: int) -> FloatArray:
    k = np.arange(n) + 0.5
    z = 1 - 2 * k / n
    r = np.sqrt(1 - z**2)
    phi = math.pi * (3 - math.sqrt(5)) * k
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def pole_clear_patch(problem: ManipulationProblem, path: FloatArray
                     ) -> tuple[float, float, float] | None:
    """A sphere's patch rotation (rotation vector) whose poles are farthest from the
    contact's path (object-frame points, rows) and clear of the pole bound with a margin
    of half the pole margin; None for other shapes or when no patch clears it."""
    if problem.object.surface.chart_symmetry != "any":
        return None
    d = path / np.linalg.norm(path, axis=1, keepdims=True)
    cand = _fibonacci(_N_CANDIDATES)
    worst = np.max(np.abs(d @ cand.T), axis=0)  # |sin(latitude)| of the path, per pole
    best = int(np.argmin(worst))
    limit = math.pi / 2 - 1.5 * problem.pole_margin
    if math.asin(min(1.0, float(worst[best]))) > limit:
        return None
    z = np.array([0.0, 0.0, 1.0])
    pole = cand[best]
    axis = np.cross(z, pole)
    s, c = float(np.linalg.norm(axis)), float(z @ pole)
    rv = axis / s * math.atan2(s, c) if s > 1e-12 else np.zeros(3)
    return float(rv[0]), float(rv[1]), float(rv[2])


def recharted(problem: ManipulationProblem, rotvec: tuple[float, float, float]
              ) -> ManipulationProblem | None:
    """The same problem with the object's (palm contact's) patch rotated by ``rotvec``:
    its palm initial grasp, goal and via-points restated in it; None when one of them
    cannot be (:func:`recharted_coordinates`)."""
    if problem.palm is None:
        return None
    surface, shape = problem.object.surface, problem.object.params
    old = Chart.of(surface, shape, problem.object.chart_rotation)
    new = Chart.of(surface, shape, rotvec)
    pm = problem.palm
    keys = ("x", "y", "u", "v", "psi")
    initial = recharted_coordinates(old, new, dict(zip(keys, pm.initial, strict=True)))
    goal = recharted_coordinates(old, new, pm.goal)
    vias = []
    for vp in pm.via_points:
        coords = recharted_coordinates(old, new, vp.coords)
        if coords is None:
            return None
        vias.append(replace(vp, coords=coords))
    if initial is None or goal is None:
        return None
    x, y, u, v, psi = (initial[k] for k in keys)
    palm = replace(pm, initial=(x, y, u, v, psi), goal=goal, via_points=tuple(vias))
    return replace(problem, object=replace(problem.object, chart_rotation=rotvec), palm=palm)


def rides_bound(problem: ManipulationProblem, u: FloatArray) -> bool:
    """Whether a fingertip contact's coordinates ``u`` (its path) reach the bound of the
    object's chart (``ObjectSpec.u_limit``: an egg's poles, its ends, less the pole
    margin)."""
    limit = problem.object.u_limit(problem.pole_margin)
    return bool(np.max(np.abs(u)) >= limit - RIDING)


def side_charted(problem: ManipulationProblem) -> ManipulationProblem | None:
    """The same problem with its fingertips' contacts on the object's side chart (an
    egg's, whose poles are on its equator: ``ObjectSpec.side_chart``), each restated in
    the patch that puts it on that chart's equator (the same tip point, object point and
    contact angle); None for a shape without one, an object already on it, a palm, a
    moving start or a reference to track (their coordinates are the old chart's)."""
    obj = problem.object
    side = None if obj.side_chart else obj.kind.side_surface(obj.dimensions)
    if side is None or problem.palm is not None or problem.initial_input is not None \
            or problem.reference is not None:
        return None
    keys = ("x", "y", "u", "v", "psi")
    tips = []
    for tip in problem.fingers:
        old = Chart.of(obj.surface, obj.params, tip.chart_rotation)
        p, _ = old.frame(tip.initial[2:4])
        R = side.axis_patch(p)
        if R is None:
            return None
        new = Chart(side, tuple(obj.params), tuple(tuple(float(x) for x in row) for row in R))
        coords = recharted_coordinates(old, new, dict(zip(keys, tip.initial, strict=True)))
        if coords is None:
            return None
        rv = log_rotation(np.asarray(R, dtype=float))
        x, y, u, v, psi = (coords[k] for k in keys)
        tips.append(replace(tip, initial=(x, y, u, v, psi),
                            chart_rotation=(float(rv[0]), float(rv[1]), float(rv[2]))))
    return replace(problem, object=replace(obj, side_chart=True), fingers=tuple(tips))


def planned_problem(problem: ManipulationProblem, chart_rotation: Any, side_chart: bool
                    ) -> ManipulationProblem | None:
    """``problem`` stated on the charts a plan of it was made on (a solution's
    ``object_chart_rotation`` and ``object_side_chart``: the planner may have re-planned
    it on others, above); None when it cannot be restated there."""
    if chart_rotation is not None and not np.allclose(chart_rotation,
                                                      problem.object.chart_rotation):
        rv = chart_rotation
        return recharted(problem, (float(rv[0]), float(rv[1]), float(rv[2])))
    if side_chart and not problem.object.side_chart:
        return side_charted(problem)
    return problem


def _predictable(problem: ManipulationProblem) -> bool:
    """Whether a problem's contacts' paths over the object's two charts can be predicted
    before its NLP (:func:`turns_off_chart`, :func:`switching_chart`): an object with a
    side chart held by round fingertips alone, one contact phase, a desired motion from
    a given pose."""
    from ocp.robots.turn_reach import rolls

    obj = problem.object
    return not (obj.kind.side_surface(obj.dimensions) is None or problem.palm is not None
                or problem.phases is not None or problem.motion is None
                or problem.initial_pose is None
                or not all(rolls(tip.finger) for tip in problem.fingers))


def turns_off_chart(problem: ManipulationProblem, joints: Callable[[], Sequence[Any]]
                    ) -> bool:
    """Whether the desired motion's turns carry a round fingertip's contact beyond the
    bound of the object's own chart (an egg's end), as the fingers' rolled motion
    predicts it on the object's surface (:func:`~ocp.robots.grasp_reach.roll` with the
    object held, turn after turn; the contact where each finger stops or the turns end):
    such a plan is made on the object's side chart (:func:`side_charted`). False for an
    object without one or already on it, a palm, contact phases, or a motion that turns
    nothing, or whose contacts all start within :data:`NEAR_BOUND` of the bound (a plan's
    contact moves a few degrees over the object); ``joints()`` (the fingers' joints at
    t = 0) is asked only when it applies."""
    from ocp.robots.first_grasp import desired_turns
    from ocp.robots.grasp_reach import roll
    from ocp.shapes.held import held_object

    obj, pose, motion = problem.object, problem.initial_pose, problem.motion
    if obj.side_chart or not _predictable(problem):
        return False
    assert pose is not None and motion is not None
    limit = obj.u_limit(problem.pole_margin)
    if max(abs(float(tip.initial[2])) for tip in problem.fingers) <= NEAR_BOUND * limit:
        return False
    turns = desired_turns(motion)
    if not turns:
        return False
    centre = np.asarray(pose.position, dtype=float)
    start = held_object(obj, centre, pose.rotation)
    for tip, q0 in zip(problem.fingers, joints(), strict=True):
        q, held = np.asarray(q0, dtype=float), start
        for turn in turns:
            rolled = roll(tip.finger, q, centre, float(obj.length_scale), turn.axis,
                          turn.angle, problem.pad_margin, held=held)
            q, held = rolled.q, held.turned(turn.axis, rolled.reach)
            if rolled.why:
                break
        point, _ = held.contact(tip.finger, q)
        body = held.rotation.T @ (point - centre)
        u = Chart.of(obj.surface, obj.params, tip.chart_rotation).inverse(body)[0]
        if abs(float(u)) > limit:
            return True
    return False


#: A predicted contact path's steps per desired turn (:func:`switching_chart`).
PATH_STEPS = 8
#: The share of a chart's bound within which a switched plan's predicted contact paths
#: stay on each of its charts (:func:`switching_chart`).
SWITCH_SHARE = 0.9


def _contact_paths(problem: ManipulationProblem, joints: Sequence[Any]
                   ) -> tuple[FloatArray, list[FloatArray]] | None:
    """The fingers' rolled motion (:func:`~ocp.robots.grasp_reach.roll` with the object
    held, :data:`PATH_STEPS` steps a turn): (the plan's time at each step, per fingertip
    its contact's points in the object's frame at each step (rows)); a finger that stops
    keeps its last point. None when the motion turns nothing."""
    from ocp.robots.first_grasp import desired_turns
    from ocp.robots.grasp_reach import roll
    from ocp.shapes.held import held_object

    obj, pose, motion = problem.object, problem.initial_pose, problem.motion
    assert pose is not None and motion is not None
    turns = desired_turns(motion)
    total = sum(float(t.angle) for t in turns)
    if not turns or total <= 0.0:
        return None
    centre = np.asarray(pose.position, dtype=float)
    start = held_object(obj, centre, pose.rotation)
    steps = [(t.axis, float(t.angle) / PATH_STEPS) for t in turns for _ in range(PATH_STEPS)]
    paths = []
    for tip, q0 in zip(problem.fingers, joints, strict=True):
        q, held = np.asarray(q0, dtype=float), start
        pts: list[FloatArray] = []
        stopped = False
        for j in range(len(steps) + 1):
            if j and not stopped:
                axis, angle = steps[j - 1]
                rolled = roll(tip.finger, q, centre, float(obj.length_scale), axis, angle,
                              problem.pad_margin, held=held)
                q, held = rolled.q, held.turned(axis, rolled.reach)
                stopped = bool(rolled.why)
            if not stopped or not pts:
                point, _ = held.contact(tip.finger, q)
                pts.append(held.rotation.T @ (point - centre))
            else:
                pts.append(pts[-1])
        paths.append(np.array(pts))
    # the plan's time at each step: where the desired motion has turned that share
    ts = np.linspace(0.0, problem.duration, 201)
    R, _ = motion.at(ts)
    turned = np.concatenate([[0.0], np.cumsum(
        [float(np.linalg.norm(log_rotation(R[k].T @ R[k + 1]))) for k in range(200)])])
    share = np.arange(len(steps) + 1) / len(steps) * turned[-1]
    return np.interp(share, turned, ts), paths


def _ratios(problem: ManipulationProblem, side: bool, patches: Sequence[FloatArray],
            paths: list[FloatArray]) -> FloatArray:
    """(steps, fingertips): each predicted contact point's |u| on a chart of the object
    (its side chart or its own, fingertip i in ``patches[i]``) over that chart's bound."""
    obj = problem.object
    surface = obj.kind.side_surface(obj.dimensions) if side else obj.kind.surface(
        obj.dimensions)
    assert surface is not None
    limit = surface.u_limit(obj.params, problem.pole_margin)
    cols = [np.abs(surface.inverse(path @ R, obj.params)[:, 0]) / limit
            for R, path in zip(patches, paths, strict=True)]
    return np.stack(cols, axis=1)


def _patches_at(problem: ManipulationProblem, side: bool, points: Sequence[FloatArray]
                ) -> list[FloatArray]:
    """Each fingertip's patch on a chart of the object for a contact at ``points[i]``:
    the side chart's that puts it on that chart's equator, the own chart's unturned."""
    obj = problem.object
    if not side:
        return [np.eye(3) for _ in points]
    surface = obj.kind.side_surface(obj.dimensions)
    assert surface is not None
    return [np.asarray(surface.axis_patch(p), dtype=float) for p in points]


def switching_chart(problem: ManipulationProblem, joints: Callable[[], Sequence[Any]]
                    ) -> Any:
    """A chart switch (:class:`~ocp.spec.chart_switch.ChartSwitchSpec`) for a motion
    whose fingertip contacts no chart of the object carries throughout, as the fingers'
    rolled motion predicts their paths (:func:`_contact_paths`). An egg's charts: its own
    (poles at its ends) and its side chart, whose patches turn about its axis (poles on
    its equator, across each contact's azimuth where its patch is chosen): a contact that
    rolls up toward an end leaves the first, one that rolls around the equator by more
    than the bound's complement leaves a side patch chosen before it. The switch is at
    the predicted step where the paths before it stay on the problem's chart and those
    after it on the next (the side chart with each patch centred on its contact there, or
    from the side chart the own), each within :data:`SWITCH_SHARE` of its bound, with the
    most room on both. None when the problem's chart carries the predicted paths, or
    (from the own chart) the side chart with its patches at the start does
    (:func:`turns_off_chart` then puts the plan there), when no switch does, or where
    :func:`turns_off_chart`'s conditions do not hold (contacts all within
    :data:`NEAR_BOUND` of the bound at the start: nothing is predicted)."""
    from ocp.spec.chart_switch import ChartSwitchSpec

    obj, motion = problem.object, problem.motion
    if problem.initial_input is not None or problem.reference is not None \
            or not _predictable(problem):
        return None
    assert motion is not None
    limit = obj.u_limit(problem.pole_margin)
    if obj.side_chart:  # every contact starts on its patch's equator: only a long motion
        from ocp.robots.first_grasp import desired_turns  # leaves it

        if sum(float(t.angle) for t in desired_turns(motion)) <= NEAR_BOUND * limit:
            return None
    elif max(abs(float(tip.initial[2])) for tip in problem.fingers) <= NEAR_BOUND * limit:
        return None
    predicted = _contact_paths(problem, joints())
    if predicted is None:
        return None
    times, paths = predicted
    side = obj.side_chart
    now = _ratios(problem, side, [rotation_from_vector(t.chart_rotation)
                                  for t in problem.fingers], paths)
    if now.max() <= 1.0:
        return None  # the problem's chart carries it
    if not side and _ratios(problem, True, _patches_at(problem, True, [p[0] for p in paths]),
                            paths).max() <= 1.0:
        return None  # the side chart carries it throughout (side_charted)
    best, best_room = None, -np.inf
    n = len(times) - 1
    for s in range(1, n):
        before = float(now[:s + 1].max())
        if before > SWITCH_SHARE:
            break
        # the next chart: the side chart, each patch centred on its contact there (also
        # from the side chart: a contact that rolled around the equator), or the own
        for nxt in (True, False) if side else (True,):
            patches = _patches_at(problem, nxt, [p[s] for p in paths])
            after = float(_ratios(problem, nxt, patches, [p[s:] for p in paths]).max())
            room = min(SWITCH_SHARE - before, SWITCH_SHARE - after)
            if after <= SWITCH_SHARE and room > best_room:
                best_room = room
                rvs = [log_rotation(R) for R in patches]
                best = ChartSwitchSpec(float(times[s]), nxt, tuple(
                    (float(r[0]), float(r[1]), float(r[2])) for r in rvs))
    return best
