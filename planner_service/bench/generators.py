"""Generators of random planning problems: each draws one wire request from a numpy
``Generator`` and a family's parameters.

A generator is ``gen(rng, params) -> (request, notes)``: ``request`` is a plan request as a
JSON dict (what ``POST /v1/plans`` takes, validated by ``dexroll_client.models``), ``notes``
what the draw had to do (a rotated object chart, redrawn initial grasps). Every draw comes
from ``rng`` alone, in a fixed order, so a family's requests are a function of its seed and
parameters. ``params["template"]`` holds the request fields a family fixes (object, grid,
duration, finger, hand, solver, ...); the generator adds the drawn ones on top of a copy.

Generators (``GENERATORS``):

* ``ball_translation``: ball on the palm, goal = a palm point at a random distance in
  ``goal_distance`` [m] and direction (the object's orientation free);
* ``ball_reorientation``: the ball returns to its palm point turned by a random rotation of
  ``angle_deg`` about a uniformly random axis (all five coordinates as the goal);
* ``ball_full_goal``: a random palm point and a random rotation, all five coordinates;
* ``one_finger_grasp``: the built-in finger pressing on the ball, an initial finger contact
  drawn inside the friction cone (a grasp angle up to ``cone_fraction`` of atan(mu)), on the
  pad within ``pad_offset`` [m] of its centre, and a random palm goal as for
  ``ball_translation``; a grasp the finger cannot take (``request_errors``) is redrawn;
* ``hand_tracking``: a built-in hand holding the ball in the air (``template``: the hand,
  its fingers, the initial pose) turning it by ``angle_deg`` about a random axis;
* ``hand_gait``: the same, farther than rolling can, by finger gaiting (``template``: the
  hand, its fingers, the initial pose, ``forces`` and ``gait``; docs/gait.md): one rotation
  step of ``angle_deg`` about a random axis, ``seconds_per_radian`` its rolls' speed.

Orientation goals whose chart latitude |u| would lie beyond the chart's pole limit
(pi/2 - pole_margin, less ``pole_slack_deg``) are expressed in a rotated object chart
(``object.chart_rotation``) that puts both the initial and the goal contact points on its
equator; a sphere's chart may be turned about any axis (an ellipsoid's only about its axis
of revolution, which cannot help: such a draw is redrawn and noted).
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable
from typing import Any

import numpy as np

from ocp.ball_on_palm import contact_coordinates, object_pose
from ocp.geometry.surfaces import rotation_from_vector
from ocp.spec.problem import CONTACT_COORDS, ObjectSpec

__all__ = ["GENERATORS", "Draw", "GeneratorError", "random_rotation"]

#: (request, notes) of one draw.
Draw = tuple[dict[str, Any], list[str]]
#: A generator of one family: (rng, params) -> one draw.
GeneratorFn = Callable[[np.random.Generator, dict[str, Any]], Draw]

_DEFAULT_POLE_MARGIN = math.radians(15.0)


class GeneratorError(ValueError):
    """A family's parameters cannot produce a valid request."""


def _range(params: dict[str, Any], key: str, default: tuple[float, float]
           ) -> tuple[float, float]:
    value = params.get(key, default)
    if isinstance(value, int | float):
        return float(value), float(value)
    lo, hi = (float(v) for v in value)
    if not lo <= hi:
        raise GeneratorError(f"{key}: [{lo}, {hi}] is not a range")
    return lo, hi


def _uniform(rng: np.random.Generator, lo_hi: tuple[float, float]) -> float:
    return float(rng.uniform(lo_hi[0], lo_hi[1]))


def _unit_vector(rng: np.random.Generator) -> np.ndarray:
    while True:
        v = rng.normal(size=3)
        n = float(np.linalg.norm(v))
        if n > 1e-9:
            return v / n


def random_rotation(rng: np.random.Generator, angle_deg: tuple[float, float]
                    ) -> tuple[np.ndarray, float]:
    """A uniformly random axis (unit vector) and an angle [rad] uniform in ``angle_deg``."""
    axis = _unit_vector(rng)
    return axis, math.radians(_uniform(rng, angle_deg))


def _template(params: dict[str, Any]) -> dict[str, Any]:
    return copy.deepcopy(params.get("template", {}))


def _object(request: dict[str, Any]) -> ObjectSpec:
    o = request.get("object", {})
    rv = o.get("chart_rotation", [0.0, 0.0, 0.0])
    return ObjectSpec(o.get("shape", "sphere"), tuple(o.get("dimensions", [0.025])),
                      (float(rv[0]), float(rv[1]), float(rv[2])))


def _coords(values: tuple[float, ...]) -> dict[str, float]:
    return dict(zip(CONTACT_COORDS, (float(v) for v in values), strict=True))


def _palm_point(rng: np.random.Generator, params: dict[str, Any], key: str = "goal_distance",
                default: tuple[float, float] = (0.005, 0.03)) -> tuple[float, float]:
    """A palm point at a distance uniform in ``params[key]`` [m], direction uniform."""
    d = _uniform(rng, _range(params, key, default))
    a = float(rng.uniform(0.0, 2.0 * math.pi))
    return d * math.cos(a), d * math.sin(a)


def _equator_chart(d0: np.ndarray, d1: np.ndarray) -> list[float]:
    """Rotation vector of a chart patch with both body directions on its equator (u = 0):
    the patch's pole (its z axis) is normal to both, its (0, 0) point between them."""
    n = np.cross(d0, d1)
    if float(np.linalg.norm(n)) < 1e-9:  # the same contact point: any pole normal to it
        n = np.cross(d0, [1.0, 0.0, 0.0])
        if float(np.linalg.norm(n)) < 1e-6:
            n = np.cross(d0, [0.0, 1.0, 0.0])
    z = n / np.linalg.norm(n)
    x = d0 + d1
    x = x - z * float(z @ x)
    if float(np.linalg.norm(x)) < 1e-9:
        x = d0 - z * float(z @ d0)
    x = x / np.linalg.norm(x)
    C = np.column_stack([x, np.cross(z, x), z])
    return _rotation_vector(C)


def _rotation_vector(R: np.ndarray) -> list[float]:
    angle = math.acos(max(-1.0, min(1.0, (float(np.trace(R)) - 1.0) / 2.0)))
    if angle < 1e-12:
        return [0.0, 0.0, 0.0]
    if math.pi - angle < 1e-6:  # half a turn: the axis from R + I
        M = (R + np.eye(3)) / 2.0
        axis = M[:, int(np.argmax(np.diag(M)))]
        axis = axis / np.linalg.norm(axis)
        return [float(c) * angle for c in axis]
    w = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    return [float(c) for c in w / (2.0 * math.sin(angle)) * angle]


def _orientation_goal(request: dict[str, Any], params: dict[str, Any], xy0: tuple[float, float],
                      xy1: tuple[float, float], R0: np.ndarray, R1: np.ndarray,
                      notes: list[str]) -> bool:
    """Set ``initial`` and ``goal`` (all five coordinates) of a ball-on-palm request for the
    object at orientation R0 over palm point xy0 at the start, R1 over xy1 at the end,
    rotating the object chart when the goal's latitude is beyond the pole limit. False when
    no chart of the object can express the goal (an ellipsoid's pole)."""
    obj = _object(request)
    margin = float(request.get("pole_margin", _DEFAULT_POLE_MARGIN))
    u_max = math.pi / 2 - margin - math.radians(float(params.get("pole_slack_deg", 0.0)))
    initial = contact_coordinates(obj, xy0, R0)
    goal = contact_coordinates(obj, xy1, R1)
    if max(abs(initial[2]), abs(goal[2])) > u_max:
        if obj.shape != "sphere":
            return False
        down = np.array([0.0, 0.0, -1.0])
        chart = _equator_chart(R0.T @ down, R1.T @ down)
        request.setdefault("object", {})["chart_rotation"] = chart
        obj = _object(request)
        initial = contact_coordinates(obj, xy0, R0)
        goal = contact_coordinates(obj, xy1, R1)
        notes.append(f"goal latitude beyond the pole limit: object chart rotated to "
                     f"{[round(c, 4) for c in chart]}")
    request["initial"] = _coords(initial)
    request["goal"] = _coords(goal)
    return True


def _start_orientation(rng: np.random.Generator, request: dict[str, Any],
                       params: dict[str, Any]) -> tuple[tuple[float, float], np.ndarray]:
    """The start: palm point (0, 0) (or ``initial`` of the template), contact angle psi
    uniform in ``initial_psi`` [rad]; the object's orientation there."""
    obj = _object(request)
    base = request.get("initial", {"x": 0.0, "y": 0.0, "u": 0.0, "v": 0.0, "psi": 0.0})
    psi = _uniform(rng, _range(params, "initial_psi", (float(base["psi"]),) * 2))
    eta0 = (float(base["x"]), float(base["y"]), float(base["u"]), float(base["v"]), psi)
    R0, _ = object_pose(obj, eta0)
    return (eta0[0], eta0[1]), np.asarray(R0)


def _draw_palm_roll(rng: np.random.Generator, params: dict[str, Any],
                    request: dict[str, Any]) -> None:
    """Draw the palm contact's initial angle psi and a goal palm point (in this order, from
    ``rng``) into ``request``."""
    base = request.get("initial", {"x": 0.0, "y": 0.0, "u": 0.0, "v": 0.0, "psi": 0.0})
    psi = _uniform(rng, _range(params, "initial_psi", (float(base["psi"]),) * 2))
    request["initial"] = {**base, "psi": psi}
    dx, dy = _palm_point(rng, params)
    request["goal"] = {"x": float(base["x"]) + dx, "y": float(base["y"]) + dy}


def ball_translation(rng: np.random.Generator, params: dict[str, Any]) -> Draw:
    request = _template(params)
    request["planner"] = "ball_on_palm"
    _draw_palm_roll(rng, params, request)
    return request, []


def _rotation_draw(rng: np.random.Generator, params: dict[str, Any], translate: bool
                   ) -> Draw:
    request = _template(params)
    request["planner"] = "ball_on_palm"
    notes: list[str] = []
    angles = _range(params, "angle_deg", (10.0, 90.0))
    for _ in range(int(params.get("max_draws", 20))):
        xy0, R0 = _start_orientation(rng, request, params)
        axis, angle = random_rotation(rng, angles)
        xy1 = xy0
        if translate:
            dx, dy = _palm_point(rng, params)
            xy1 = (xy0[0] + dx, xy0[1] + dy)
        R1 = rotation_from_vector(axis * angle) @ R0
        if _orientation_goal(request, params, xy0, xy1, R0, np.asarray(R1), notes):
            notes.insert(0, f"rotation {math.degrees(angle):.1f} deg about "
                            f"{[round(float(c), 3) for c in axis]}")
            return request, notes
        notes.append("goal at the pole of an ellipsoid's chart: redrawn")
    raise GeneratorError("no draw gave a goal away from the chart's poles")


def ball_reorientation(rng: np.random.Generator, params: dict[str, Any]) -> Draw:
    return _rotation_draw(rng, params, translate=False)


def ball_full_goal(rng: np.random.Generator, params: dict[str, Any]) -> Draw:
    return _rotation_draw(rng, params, translate=True)


def one_finger_grasp(rng: np.random.Generator, params: dict[str, Any]) -> Draw:
    """See the module docstring. The finger contact's chart patch is the template's (the
    wire default [0, 0, pi] puts its (0, 0) at the ball's top at t = 0); the contact is
    drawn at an angle theta from that point (area-uniform in the cap allowed by
    ``cone_fraction``) and a uniform azimuth, which for a sphere on the palm's (0, 0) chart
    point gives grasp angles theta / 2."""
    from planner_service.planners import REQUEST, request_errors

    template = _template(params)
    mu = float(template.get("mu", 0.5))
    fraction = float(params.get("cone_fraction", 0.6))
    theta_max = 2.0 * fraction * math.atan(mu)
    pad = _range(params, "pad_offset", (0.0, 0.01))
    psi_f = _range(params, "psi_f", (0.0, 0.0))
    notes: list[str] = []
    for _ in range(int(params.get("max_draws", 20))):
        request = copy.deepcopy(template)
        request["planner"] = "one_finger"
        _draw_palm_roll(rng, params, request)
        theta = theta_max * math.sqrt(float(rng.uniform()))
        phi = float(rng.uniform(0.0, 2.0 * math.pi))
        r_pad = _uniform(rng, pad)
        a_pad = float(rng.uniform(0.0, 2.0 * math.pi))
        contact = request.setdefault("finger_contact", {})
        contact["initial"] = {
            "x_f": r_pad * math.cos(a_pad), "y_f": r_pad * math.sin(a_pad),
            "u_f": math.asin(math.sin(theta) * math.sin(phi)),
            "v_f": math.atan2(math.sin(theta) * math.cos(phi), math.cos(theta)),
            "psi_f": _uniform(rng, psi_f)}
        errors = request_errors(REQUEST.validate_python(request))
        if not errors:
            return request, notes
        notes.append("initial grasp redrawn: " + "; ".join(f"{f}: {r}" for f, r in errors))
    raise GeneratorError(f"no initial grasp the finger can take in "
                         f"{params.get('max_draws', 20)} draws: {notes[-1]}")


def hand_tracking(rng: np.random.Generator, params: dict[str, Any]) -> Draw:
    """The template's hand turns the ball by a random rotation in one step over the whole
    duration (optionally moving it by up to ``max_translation`` [m] too)."""
    request = _template(params)
    request["planner"] = "manipulation"
    axis, angle = random_rotation(rng, _range(params, "angle_deg", (5.0, 30.0)))
    step: dict[str, Any] = {"duration": float(request["duration"]),
                            "axis": [float(c) for c in axis], "angle": angle}
    reach = float(params.get("max_translation", 0.0))
    if reach > 0.0:
        step["translation"] = [float(c) for c in _unit_vector(rng) * rng.uniform(0.0, reach)]
    request["motion"] = {"kind": "steps", "smooth": bool(params.get("smooth", True)),
                         "steps": [step]}
    return request, [f"rotation {math.degrees(angle):.1f} deg about "
                     f"{[round(float(c), 3) for c in axis]}"]


def hand_gait(rng: np.random.Generator, params: dict[str, Any]) -> Draw:
    """The template's hand turns the ball by a random rotation by finger gaiting: one
    rotation step (no translation) over ``seconds_per_radian`` [s] per radian of its
    angle, the request's duration (docs/gait.md: the step's duration over its angle sets
    the rolls' speed)."""
    request = _template(params)
    request["planner"] = "manipulation"
    request.setdefault("gait", {})
    if "forces" not in request:
        raise GeneratorError("hand_gait: the template needs `forces` (a gait's holds carry "
                             "the ball's weight)")
    axis, angle = random_rotation(rng, _range(params, "angle_deg", (45.0, 180.0)))
    duration = float(params.get("seconds_per_radian", 8.0)) * angle
    request["duration"] = duration
    request["motion"] = {"kind": "steps", "steps": [
        {"duration": duration, "axis": [float(c) for c in axis], "angle": angle}]}
    return request, [f"gait {math.degrees(angle):.1f} deg about "
                     f"{[round(float(c), 3) for c in axis]}"]


#: The generators, by the name a suite's family gives.
GENERATORS: dict[str, GeneratorFn] = {
    "ball_translation": ball_translation,
    "ball_reorientation": ball_reorientation,
    "ball_full_goal": ball_full_goal,
    "one_finger_grasp": one_finger_grasp,
    "hand_tracking": hand_tracking,
    "hand_gait": hand_gait,
}
