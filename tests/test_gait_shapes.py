"""Finger gaits on objects that are not balls (docs/gait.md, "Objects other than a
ball"): the geometry a gait measures them with, and an egg turned by a gait, certified
and executed in MuJoCo on its own geom."""

from __future__ import annotations

import copy
import json
import math
from pathlib import Path

import httpx
import numpy as np
import pytest
from helpers import planned_gait

from ocp.geometry.bodies import point_segment_distance
from ocp.geometry.nearest import nearest_surface_point
from ocp.geometry.rotations import (
    axis_angle_rotation,
    log_rotation,
    quaternion_matrix,
    quaternion_wxyz,
)
from ocp.shapes import SHAPES, shape_of
from ocp.shapes.held import Held
from tests.conftest import Server

ROOT = Path(__file__).resolve().parents[1]
EGG = json.loads((ROOT / "examples" / "egg_gait.json").read_text())


def _points(n: int = 300, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).normal(size=(n, 3)) * 0.04


@pytest.mark.parametrize("dims", [(0.03,), (0.025, 0.035), (0.028, 0.034, 0.04)])
def test_the_nearest_point_is_on_the_surface_along_the_normal_at_the_charts_distance(
        dims: tuple[float, ...]) -> None:
    """Of each point, the shape's nearest point lies on its surface, the point is off it
    along the outward normal there by the signed distance, and that distance is the one
    the chart's own search finds (ocp.geometry.nearest, which shares no code with it)."""
    shape = shape_of("sphere" if len(dims) == 1 else "ellipsoid")
    P = _points()
    X, n, d = shape.nearest(dims, P)
    a = np.asarray(shape.semi_axes(dims))
    assert np.abs(np.sum((X / a) ** 2, axis=1) - 1.0).max() < 1e-12
    assert np.abs(np.linalg.norm(n, axis=1) - 1.0).max() < 1e-12
    assert np.abs(P - (X + d[:, None] * n)).max() < 1e-12
    surface, params = shape.surface(dims), shape.surface_params(dims)
    for p, di in zip(P[:12], d[:12], strict=True):
        assert nearest_surface_point(surface, params, p)[1] == pytest.approx(di, abs=1e-12)


@pytest.mark.parametrize("edge", [0.012, 0.005])
def test_a_rounded_cubes_nearest_point_is_the_charts(edge: float) -> None:
    """The superellipsoid's nearest point (Newton on the Lagrange conditions) is on its
    surface, the point off it along the normal by the signed distance; outside, that
    distance is the least to a dense set of its surface points (its MuJoCo mesh's
    vertices, to their spacing; the chart's own search fails near its poles, where a
    point 40 mm up the z axis came out 15.7 mm inside)."""
    shape = shape_of("superellipsoid")
    dims = (0.025, 0.025, 0.025, edge)
    a, b, c, n = shape.surface_params(dims)
    P = _points(200, 3)
    X, nrm, d = shape.nearest(dims, P)
    assert np.abs(np.sum(np.abs(X / np.array([a, b, c])) ** n, axis=1) - 1.0).max() < 1e-10
    assert np.abs(P - (X + d[:, None] * nrm)).max() < 1e-12
    V = np.asarray(shape.mesh(dims), dtype=float).reshape(-1, 3)
    assert np.abs(np.sum(np.abs(V / np.array([a, b, c])) ** n, axis=1) - 1.0).max() < 1e-6
    brute = np.array([np.linalg.norm(V - p, axis=1).min() for p in P])
    out = d > 0
    assert out.sum() > 100
    assert np.all(d[out] <= brute[out] + 1e-12) and np.all(brute[out] - d[out] < 5e-4)


def test_a_capsules_nearest_point_is_on_its_cylinder_or_caps() -> None:
    """A capsule's nearest point is r from its axis segment, the point off it along the
    normal by the signed distance, which is the distance from the axis less r."""
    from ocp.geometry.bodies import points_segment_distance

    r, h = 0.012, 0.028
    P = _points()
    X, n, d = shape_of("capsule").nearest((r, h), P)
    axis = (np.array([0.0, 0.0, -h]), np.array([0.0, 0.0, h]))
    assert np.abs(points_segment_distance(X, *axis) - r).max() < 1e-15
    assert np.abs(P - (X + d[:, None] * n)).max() < 1e-15
    assert np.abs(d - (points_segment_distance(P, *axis) - r)).max() < 1e-15


@pytest.mark.parametrize(("name", "dims", "exact"), [
    ("sphere", (0.03,), True), ("ellipsoid", (0.03, 0.04), False),
    ("ellipsoid", (0.028, 0.034, 0.04), False), ("capsule", (0.012, 0.028), True),
    ("superellipsoid", (0.025, 0.025, 0.025, 0.005), False)])
def test_the_swings_clearance_is_below_a_segments_distance_outside(
        name: str, dims: tuple[float, ...], exact: bool) -> None:
    """The swing NLP's clearance of a segment (the CasADi expression itself) is never
    above the segment's distance from the surface where it is outside (the
    superellipsoid's gauge bound: of points, its samples); a ball's and a capsule's are that
    distance."""
    import casadi as ca

    shape = shape_of(name)
    held = Held(np.zeros(3), np.eye(3), 0.04, shape, dims)
    a, b = ca.SX.sym("a", 3), ca.SX.sym("b", 3)
    p = ca.SX.sym("p", len(shape.clearance_params(dims)))
    f = ca.Function("c", [a, b, p], [shape.segment_clearance(p, a, b)])
    rng = np.random.default_rng(1)
    A = rng.normal(size=(300, 3)) * 0.04
    B = A + rng.normal(size=(300, 3)) * 0.01
    B[:50] = A[:50]  # points (a sphere tip's body)
    true = held.segment_distance(A, B)
    cp = shape.clearance_params(dims)
    got = np.array([float(f(x, y, cp)) for x, y in zip(A, B, strict=True)])
    out = true > 0
    if name == "superellipsoid":
        out[50:] = False  # (points: a segment's samples)
    assert out.sum() > (20 if name == "superellipsoid" else 100)
    assert np.all(got[out] <= true[out] + 1e-9)
    if exact:
        assert np.abs(got[out] - true[out]).max() < 1e-9


def test_a_bodys_distance_from_a_turned_egg_is_the_least_along_its_segment() -> None:
    """Held.segment_distance of a turned, moved egg: the least over a dense sampling of
    each segment (to a nanometre), a ball's the distance from its centre less the
    radius."""
    R = axis_angle_rotation(np.array([1.0, 2.0, 3.0]) / math.sqrt(14.0), 0.7)
    egg = Held(np.array([0.03, 0.0, 0.07]), R, 0.04, shape_of("ellipsoid"), (0.03, 0.04))
    rng = np.random.default_rng(2)
    A = egg.centre + rng.normal(size=(40, 3)) * 0.05
    B = A + rng.normal(size=(40, 3)) * 0.02
    s = np.linspace(0.0, 1.0, 20001)
    dense = np.array([egg.nearest(a + s[:, None] * (b - a))[2].min()
                      for a, b in zip(A, B, strict=True)])
    assert np.abs(egg.segment_distance(A, B) - dense).max() < 1e-9
    ball = Held(egg.centre, R, 0.03)
    want = [point_segment_distance(ball.centre, a, b) - 0.03
            for a, b in zip(A, B, strict=True)]
    assert np.allclose(ball.segment_distance(A, B), want, rtol=0.0, atol=1e-15)


def test_a_shape_without_a_gait_geometry_says_why() -> None:
    """A shape a gait cannot measure (no closed-form nearest point, no clearance for a
    swing's NLP: a new shape's module before it has them) is named, with the shapes
    that have them; every registered shape has them."""
    from types import SimpleNamespace

    from ocp.shapes.base import Shape
    from ocp.shapes.held import gait_shape_error
    from ocp.spec.problem import ObjectSpec

    class Bare(Shape):  # the least a shape is: no nearest point, no clearance
        name = "bare"
        surface = surfaces = count_error = semi_axes = volume = inertia = None  # type: ignore
        mujoco_geom = viewer = None  # type: ignore

    why = gait_shape_error(SimpleNamespace(kind=Bare(), shape="bare", dimensions=(0.03,)))
    assert why is not None and "not yet on a bare" in why and "ellipsoid" in why
    for name, dims in (("sphere", (0.03,)), ("ellipsoid", (0.03, 0.04)),
                       ("capsule", (0.012, 0.028)),
                       ("superellipsoid", (0.025, 0.025, 0.025, 0.005))):
        assert gait_shape_error(ObjectSpec(name, dims)) is None
    assert set(SHAPES) == {"sphere", "ellipsoid", "capsule", "superellipsoid"}


def test_the_rolled_reach_on_an_egg_is_the_rolling_planners_motion() -> None:
    """grasp_reach.roll on the egg's surface (``held``): the upright egg's nominal grasp
    turned 8 deg about +y (its middle fingertip stops at 9.4) ends where the rolling
    planner's plan of that roll ends (every joint within 0.025 rad, 0.019 measured: the
    plan's centre and orientation move within their tolerances); about +x it stops the
    middle fingertip at its cap's seam within 5 deg, where that roll is not planned
    (docs/gait.md)."""
    from ocp.robots.grasp_reach import roll
    from ocp.shapes.held import held_object
    from planner_service.planners import REQUEST
    from planner_service.planners.cache import FingerCache
    from planner_service.planners.manipulation import manipulation_problem

    body = _egg_request(8.0)  # upright, in the hand's nominal grasp, about +y
    for key in ("gait", "grasp"):
        body.pop(key)
    body["initial_pose"]["orientation_wxyz"] = [1.0, 0.0, 0.0, 0.0]
    body["motion"]["steps"][0].update(axis=[0, 1, 0], duration=1.0)
    body["duration"] = 1.0
    cache = FingerCache()
    problem = manipulation_problem(REQUEST.validate_python(body), cache)
    pose = problem.initial_pose
    assert pose is not None
    c = np.asarray(pose.position)
    held = held_object(problem.object, c, pose.rotation)
    qs = [np.asarray(t.q_seed) for t in problem.fingers]
    ahead = [roll(t.finger, q, c, 0.03, np.array([0.0, 1.0, 0.0]), math.radians(8.0),
                  problem.pad_margin, held=held) for t, q in zip(problem.fingers, qs,
                                                                  strict=True)]
    sol = cache.manipulation.solve(problem)
    assert sol.ok and sol.certificate.passed
    end = sol.joint_trajectory(np.array([sol.duration]), efforts=False).positions[0]
    assert not any(r.why for r in ahead)
    assert np.abs(end - np.concatenate([r.q for r in ahead])).max() < 0.025
    middle = roll(problem.fingers[1].finger, qs[1], c, 0.03, np.array([1.0, 0.0, 0.0]),
                  math.radians(40.0), problem.pad_margin, held=held)
    assert middle.why == "cap's seam" and middle.reach < math.radians(5.0)


def _egg_request(angle_deg: float) -> dict:
    body = copy.deepcopy(EGG)
    step = body["motion"]["steps"][0]
    step["duration"] = step["duration"] * angle_deg / math.degrees(step["angle"])
    step["angle"] = math.radians(angle_deg)
    body["duration"] = step["duration"]
    return body


def test_an_egg_turned_by_a_gait_is_certified_on_its_surface_and_executes() -> None:
    """examples/egg_gait.json (the egg lying across the fingers, its grasp searched for
    the rolled reach on its surface) cut to 20 deg about +x (each liftable fingertip
    re-placed after each roll): certified; every sample's contact of a touching fingertip
    is on the egg where it is then, its cap's centre off it by the tip's radius; every
    swing clear of the egg's own surface; executed in MuJoCo on the ellipsoid geom within
    the tracking tolerances, no planned contact lost."""
    from ocp.gait.samples import gait_samples, gait_times
    from ocp.geometry.bodies import tip_body
    from planner_service.execution import simulate_result

    request, problem, result, gait = planned_gait(_egg_request(20.0))
    assert math.degrees(gait.turned) == pytest.approx(20.0, abs=1e-3)
    assert len(gait.rolls) >= 2 and len(gait.steps) >= 3
    names = [c.name for c in gait.certificate.checks]
    assert sum(n.startswith("swing_clearance_") for n in names) == len(gait.steps)
    smp = gait_samples(gait, problem, gait_times(gait, 100.0))
    a = np.asarray(problem.object.kind.semi_axes(problem.object.dimensions))
    fingers = [f.finger for f in problem.fingers]
    cut = np.cumsum((0, *gait.nq))
    assert smp.touching is not None
    for k, f in enumerate(fingers):
        on = smp.touching[:, k]
        R = np.array([quaternion_matrix(w) for w in smp.object_wxyz[on]])
        local = np.einsum("kji,kj->ki", R, smp.point[on, k] - smp.object_position[on])
        assert np.abs(np.sum((local / a) ** 2, axis=1) - 1.0).max() < 1e-9
        Rs, p = f.tip_poses(smp.q[on][:, cut[k]:cut[k + 1]])
        caps = p + Rs @ tip_body(f).a
        gap = np.linalg.norm(caps - smp.point[on, k], axis=1) - tip_body(f).r
        assert np.abs(gap).max() < 2e-5  # the rolls' contact rows' accuracy
        # the contact's motion over the egg: along its surface (the point stays on it as
        # the egg turns), none while the egg is still
        assert smp.point_velocity is not None and smp.over_object is not None
        over, nrm = smp.over_object[on, k], smp.normal[on, k]
        assert np.abs(np.sum(over * nrm, axis=1)).max() < 1e-7
        still = np.linalg.norm(smp.object_angular_velocity[on], axis=1) == 0.0
        assert still.any() and np.abs(over[still]).max() < 1e-9
        assert np.linalg.norm(over[~still], axis=1).max() > 1e-3  # (and it rolls)
    report = simulate_result(result, request)
    assert report.passed, report.failures
    assert report.position_error.max < 2e-3 and report.angle_error.max < math.radians(3.0)


@pytest.mark.slow  # the egg's and the rounded cube's gaits above run by default
def test_a_capsule_turned_about_its_axis_by_a_gait_is_certified_and_executes() -> None:
    """examples/capsule_roll.json's upright capsule turned 10 deg about its axis in rolls
    of 5 deg (every fingertip re-placed after the first): certified, its swings' clearance
    measured from the capsule's surface; the contacts of the samples on it; executed in
    MuJoCo on the capsule geom, no planned contact lost."""
    from ocp.gait.samples import gait_samples, gait_times
    from ocp.geometry.bodies import points_segment_distance
    from planner_service.execution import simulate_result

    body = json.loads((ROOT / "examples" / "capsule_roll.json").read_text())
    body["motion"]["steps"][0].update(axis=[0, 0, -1], angle=math.radians(10.0))
    body["gait"] = {"roll_step": math.radians(5.0)}
    request, problem, result, gait = planned_gait(body)
    assert len(gait.rolls) == 2 and len(gait.steps) == 4
    smp = gait_samples(gait, problem, gait_times(gait, 100.0))
    r, h = problem.object.dimensions
    assert smp.touching is not None
    for k in range(len(problem.fingers)):
        on = smp.touching[:, k]
        R = np.array([quaternion_matrix(w) for w in smp.object_wxyz[on]])
        local = np.einsum("kji,kj->ki", R, smp.point[on, k] - smp.object_position[on])
        axis = (np.array([0.0, 0.0, -h]), np.array([0.0, 0.0, h]))
        assert np.abs(points_segment_distance(local, *axis) - r).max() < 1e-12
    report = simulate_result(result, request)
    assert report.passed, report.failures


def _fields(server: Server, body: dict) -> dict[str, str]:
    r = httpx.post(f"{server.url}/v1/plans", params={"wait": 60}, content=json.dumps(body),
                   headers={"content-type": "application/json"}, timeout=120)
    assert r.status_code == 422, r.text
    return {d["field"]: d["reason"] for d in r.json()["detail"]}


def test_a_gait_with_farthest_landings_or_overlap_on_an_egg_is_422(
        live_server: Server) -> None:
    """Through the service: an egg's gait landing where its fingertips reach farthest or
    re-placing them while the others roll (a ball's landings) names the field."""
    body = _egg_request(30.0)
    body["gait"].update(replace="spent", landing="farthest")
    assert "planned on a ball alone" in _fields(live_server, body)["gait.landing"]
    body["gait"].update(landing="home", overlap=True)
    assert "planned on a ball alone" in _fields(live_server, body)["gait.overlap"]


def test_a_contact_toward_a_pole_is_put_in_the_cubes_patch_that_clears_it() -> None:
    """A rounded cube turned 90 deg about y (examples/rounded_cube_turn.json's grasp): the
    index's contact is 44 deg up its own patch, beyond half the chart's bound (37.5 deg),
    so it is put in the patch of the cube's symmetries that keeps it nearest the equator
    (a turn of 120 deg about (1, 1, 1)), at most asin(1/sqrt(3)) up: the same point of
    the cube, the same contact frame's normal, under the tip where its joints put it. The
    short roll from there is planned and certified (a gait's next roll is made so, which
    is how the rounded_cube_gait family's contacts no longer stop at the pole bound after
    34 deg)."""
    from ocp.geometry.surfaces import rotation_from_vector
    from ocp.spec.grasp import RECHART_SHARE, contact_from_joints
    from ocp.spec.motion import ObjectPose
    from ocp.spec.problem import ObjectSpec
    from planner_service.planners import REQUEST, solve
    from planner_service.planners.cache import FINGERS
    from planner_service.planners.manipulation import problem_and_grasp

    raw = json.loads((ROOT / "examples" / "rounded_cube_turn.json").read_text())
    c = math.cos(math.pi / 4)
    raw["initial_pose"]["orientation_wxyz"] = [c, 0.0, c, 0.0]
    problem, _ = problem_and_grasp(REQUEST.validate_python(raw), FINGERS)
    obj: ObjectSpec = problem.object
    pose = ObjectPose(orientation=(c, 0.0, c, 0.0),
                      position=tuple(raw["initial_pose"]["position"]))
    finger, q = problem.fingers[0].finger, raw["fingers"][0]["initial_q"]
    (_, _, u, v, _), rotvec, gap = contact_from_joints(finger, q, obj, pose)
    R_c = rotation_from_vector(rotvec)
    assert np.allclose(np.abs(R_c), np.round(np.abs(R_c)), atol=1e-9)
    assert obj.surface.chart_rotation_error(R_c, obj.params) is None
    p, G, _, _, _ = obj.surface.geometry([u, v], obj.params)
    point = R_c @ np.asarray(p, dtype=float).reshape(3)  # the object frame
    own_u = float(obj.surface.inverse(point, obj.params)[0])
    assert abs(own_u) > RECHART_SHARE * obj.u_limit(problem.pole_margin)
    assert abs(u) <= math.asin(1.0 / math.sqrt(3.0)) + 1e-9
    R_l, p_l = finger.fingertip_pose_pin(np.asarray(q, dtype=float))
    centre = p_l + R_l @ finger.tip_surface.p
    normal = pose.rotation @ R_c @ np.asarray(G, dtype=float)[:, 2]
    touch = np.asarray(pose.position) + pose.rotation @ point
    r = finger.tip_surface.params[0]
    assert np.linalg.norm(touch + (r + gap) * normal - centre) < 1e-6
    result, _ = solve(REQUEST.validate_python(raw))
    assert result.status.value == "solved", result.message
    assert result.certificate is not None and result.certificate.passed


def test_a_symmetric_turn_is_planned_from_the_first_orientation() -> None:
    """An upright capsule turned 30 deg about its axis and tilted 0.01 rad: the same solid
    as the first orientation tilted, so its roll starts there (``plan_start``: the first
    orientation tilted, at most RECUR_TILT from it) and its plan's rotations map onto the
    palm's by a symmetry of the capsule (``roll_frame``): the roll recurs and the last
    one's point starts it. Turned about a short axis instead it is another solid,
    planned from where it is."""
    from ocp.gait.planner import RECUR_TILT, plan_start, roll_frame
    from ocp.spec.motion import ObjectPose
    from planner_service.planners import REQUEST
    from planner_service.planners.cache import FINGERS
    from planner_service.planners.manipulation import problem_and_grasp

    raw = json.loads((ROOT / "examples" / "capsule_roll.json").read_text())
    problem, _ = problem_and_grasp(REQUEST.validate_python(raw), FINGERS)
    first = problem.initial_pose.rotation
    obj = problem.object
    for axis, turn, recurs in (((0, 0, 1), 30.0, True), ((1, 0, 0), 30.0, False)):
        R = axis_angle_rotation([1, 1, 0], 0.01) @ axis_angle_rotation(
            axis, math.radians(turn)) @ first
        pose = ObjectPose(tuple(quaternion_wxyz(R)), problem.initial_pose.position)
        start, frame = plan_start(problem, pose), roll_frame(problem, pose)
        if not recurs:
            assert start is None and np.array_equal(frame, np.eye(3))
            continue
        assert start is not None
        assert obj.surface.chart_rotation_error(frame, obj.params) is None  # a symmetry
        assert np.abs(start @ frame - pose.rotation).max() < 1e-12
        tilt = np.linalg.norm(log_rotation(first.T @ start))
        assert tilt == pytest.approx(0.01, abs=1e-9) and tilt <= RECUR_TILT


def test_each_shapes_symmetry_nearest_a_turn() -> None:
    """``Surface.symmetry_near``: a rounded cube turned a quarter turn about x and tilted
    0.02 rad has that quarter turn for its symmetry (one of its 24); an egg turned 40 deg
    about its axis and tilted, that turn about its axis; an egg turned upside down and
    more, none of its turns about +z (it is turned to the lower half)."""
    from ocp.shapes import shape_of

    tilt = axis_angle_rotation([0.3, -1.0, 0.2], 0.02)
    cube = shape_of("superellipsoid")
    dims = (0.025, 0.025, 0.025, 0.012)
    surface, params = cube.surface(dims), cube.surface_params(dims)
    assert len(surface.symmetries(params)) == 24
    quarter = axis_angle_rotation([1, 0, 0], math.pi / 2)
    assert np.abs(surface.symmetry_near(tilt @ quarter, params) - quarter).max() < 1e-12
    egg = shape_of("ellipsoid")
    surface, params = egg.surface((0.03, 0.04)), egg.surface_params((0.03, 0.04))
    spin = axis_angle_rotation([0, 0, 1], math.radians(40))
    level = axis_angle_rotation([0.3, -1.0, 0.0], 0.02)  # (a tilt about a level axis)
    S = surface.symmetry_near(level @ spin, params)
    assert S is not None and np.abs(S @ [0, 0, 1] - [0, 0, 1]).max() < 1e-12
    assert np.abs(S - spin).max() < 1e-12
    assert surface.symmetry_near(axis_angle_rotation([1, 0, 0], 2.0), params) is None


@pytest.mark.slow
def test_a_gait_that_does_not_plan_from_the_best_grasp_plans_from_the_next() -> None:
    """The full bench's egg_gait-006 (the egg turned 46.6 deg): from the search's best
    grasp a middle fingertip's swing is not found after 31.4 deg; the service tries the
    search's next grasp, from which the gait is certified. The result says which grasp
    (rank 1) and names the one tried first (about 50 s)."""
    from planner_service.bench.suite import expand, load_suite
    from planner_service.planners import REQUEST, solve

    unit = next(u for u in expand(load_suite("full"), ["egg_gait"]) if u.id == "egg_gait-006")
    # room for the next grasp's gait on a loaded machine (the default 60 s were not: the
    # first grasp's gait took more than half of them, and the next was not tried)
    body = {**unit.request, "solver": {**unit.request.get("solver", {}), "time_limit": 600}}
    result, gait = solve(REQUEST.validate_python(body))
    assert result.status.value == "solved", result.message
    assert result.certificate is not None and result.certificate.passed
    assert gait.ok and result.grasp is not None and result.grasp.rank >= 1
    assert "also tried: grasp 0" in result.message


@pytest.mark.slow
def test_a_rounded_cube_turned_90_degrees_about_a_horizontal_axis_is_executed_clean() -> None:
    """examples/rounded_cube_gait.json (a 50 mm cube with 12 mm edges, 70 g, mu 1.0, its
    grasp searched, 90 deg about +x: one face brought up): the search's best grasp stops
    at 50 deg (an index swing not found), the next one is certified; executed in MuJoCo
    in dexroll's scene with no contact lost (the admittance following the cube's faces,
    which move under the fingertips as the cube turns: sim.run.admittance_range; with a
    ball's bound the index was lost 0.6 s at 1.75 deg of creep). About 3 min."""
    from planner_service.execution import simulate_result
    from planner_service.planners import REQUEST, solve

    request = REQUEST.validate_python(
        json.loads((ROOT / "examples" / "rounded_cube_gait.json").read_text()))
    result, gait = solve(request)
    assert result.status.value == "solved", result.message
    assert result.certificate is not None and result.certificate.passed
    assert gait.ok and math.isclose(gait.turned, math.pi / 2, abs_tol=1e-6)
    report = simulate_result(result, request)
    assert report.passed, report.failures
    assert all(c.lost_time == 0.0 for c in report.contacts)
