"""The object shapes' registry (ocp/shapes): each shape means what MuJoCo's geom of it
means (mass, inertia, surface), its surface's chart lies on that geom, and every layer
asks the registry."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from ocp.shapes import SHAPES, shape_of
from ocp.shapes.superellipsoid import MESH_SAG
from ocp.spec.problem import ForceSpec, ObjectSpec

#: Dimensions of every form of every shape [m].
CASES = [("sphere", (0.03,)), ("ellipsoid", (0.025, 0.04)),
         ("ellipsoid", (0.03, 0.03, 0.04)), ("ellipsoid", (0.02, 0.035, 0.05)),
         ("capsule", (0.012, 0.028)), ("superellipsoid", (0.025, 0.025, 0.025, 0.005)),
         ("superellipsoid", (0.02, 0.03, 0.04, 0.008))]
DENSITY = 1100.0


def _mujoco(shape: str, dims: tuple[float, ...]) -> tuple[mujoco.MjModel, mujoco.MjData]:
    import xml.etree.ElementTree as ET

    geom = shape_of(shape).mujoco_geom(dims)
    root = ET.fromstring(
        '<mujoco><worldbody><body name="o"><freejoint/></body>'
        '<body name="probe" mocap="true"><geom name="probe" type="sphere" size="1e-4" '
        'contype="0" conaffinity="0"/></body></worldbody></mujoco>')
    geom.add_asset(root)
    body = root.find("worldbody/body")
    assert body is not None
    ET.SubElement(body, "geom", geom.attributes(), name="o", density=f"{DENSITY}")
    model = mujoco.MjModel.from_xml_string(ET.tostring(root, encoding="unicode"))
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    return model, data


@pytest.mark.parametrize(("shape", "dims"), CASES)
def test_mass_and_inertia_are_mujocos_of_the_geom(shape: str, dims: tuple[float, ...]) -> None:
    model, _ = _mujoco(shape, dims)
    s = shape_of(shape)
    mass = float(model.body_mass[1])
    rel = 2e-3 if s.mujoco_geom(dims).type == "mesh" else 1e-9  # a mesh: its chords
    assert mass == pytest.approx(s.mass_of_density(dims, DENSITY), rel=rel)
    inertia = np.sort(s.inertia(dims, mass))
    assert np.sort(model.body_inertia[1]) == pytest.approx(inertia, rel=rel)
    # the object's default inertia in a plan's forces is the same solid's
    obj = ObjectSpec(shape, dims)
    assert ForceSpec(mass).principal_inertia(obj) == pytest.approx(s.inertia(dims, mass))


@pytest.mark.parametrize(("shape", "dims"), CASES)
def test_the_charts_points_lie_on_mujocos_geom(shape: str, dims: tuple[float, ...]) -> None:
    """Points of the surface's chart, and its support points, are on the geom MuJoCo
    collides (the probe sphere of radius 1e-4 m at the point is 1e-4 m inside it)."""
    model, data = _mujoco(shape, dims)
    obj = ObjectSpec(shape, dims)
    surface, params = obj.surface, obj.params
    rng = np.random.default_rng(7)
    lim = min(1.3, surface.u_limit(params, 0.0))  # the chart's latitudes, or a capsule's seams
    points = [np.asarray(surface.geometry([u, v], params)[0]).ravel()
              for u, v in zip(rng.uniform(-lim, lim, 12), rng.uniform(-math.pi, math.pi, 12),
                              strict=True)]
    points += list(shape_of(shape).sample_points(dims, 24))
    o, probe = (mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, n) for n in ("o", "probe"))
    sag = MESH_SAG if shape_of(shape).mujoco_geom(dims).type == "mesh" else 0.0
    for p in points:
        data.mocap_pos[0] = p
        mujoco.mj_forward(model, data)
        d = mujoco.mj_geomDistance(model, data, o, probe, 0.01, None)
        assert d == pytest.approx(-1e-4, abs=sag + 2e-6), p


def test_every_shape_validates_its_dimensions_by_field() -> None:
    assert ObjectSpec("sphere", (0.02, 0.03)).errors() == [
        ("object.dimensions", "a sphere has 1 dimension (its radius), got 2")]
    why = ObjectSpec("ellipsoid", (0.02,)).errors()
    assert [f for f, _ in why] == ["object.dimensions"] and "2 dimensions" in why[0][1]
    assert ObjectSpec("ellipsoid", (0.02, -0.01, 0.03)).errors()[0][0] == "object.dimensions"
    assert ObjectSpec("cube", (0.02,)).errors()[0][0] == "object.shape"
    for shape, dims in CASES:
        assert ObjectSpec(shape, dims).errors() == []


def test_the_surfaces_key_the_nlps_apart() -> None:
    """An ellipsoid of revolution and a triaxial one are different surfaces (their NLPs
    are different); each shape lists every surface it gives."""
    names = [ObjectSpec(s, d).surface.name for s, d in CASES]
    assert names[0] == "sphere" and names[1] == "ellipsoid" and names[2] == names[3] != names[1]
    for shape, dims in CASES:
        assert ObjectSpec(shape, dims).surface in SHAPES[shape].surfaces()


@pytest.mark.slow
def test_a_triaxial_ellipsoid_turned_between_two_pads_is_certified_and_executed() -> None:
    """The two-finger hand of the paper's experiment 2 turns an ellipsoid with three
    different semi-axes (a chart that is not orthogonal) by its four 20-degree steps, its
    forces planned: certified, and executed in MuJoCo on the ellipsoid geom within 1 mm /
    1 degree with no contact lost. (Slow: the default run plans and executes the same
    request as examples/ellipsoid_two_fingers.json, tests/test_cli.py and test_sim.py.)"""
    import json
    from pathlib import Path

    from helpers import planned_and_executed

    from planner_service.execution import execution_plan
    from planner_service.planners import REQUEST

    raw = json.loads((Path(__file__).parents[1] / "examples" /
                      "experiment2_two_fingers.json").read_text())
    raw["object"] = {"shape": "ellipsoid", "dimensions": [0.025, 0.03, 0.035]}
    raw["forces"] = {"mass": 0.05}
    result, _ = planned_and_executed(raw, 1e-3, 1.0)
    obj = execution_plan(result, REQUEST.validate_python(raw)).object
    assert (obj.geom_type, obj.geom_size) == ("ellipsoid", (0.025, 0.03, 0.035))


@pytest.mark.parametrize(("shape", "dims"), CASES)
def test_each_surfaces_closed_form_is_its_derivation(shape: str, dims: tuple[float, ...]
                                                     ) -> None:
    obj = ObjectSpec(shape, dims)
    surface, params = obj.surface, obj.params
    lim = min(1.3, surface.u_limit(params, 0.0))
    rng = np.random.default_rng(3)
    for u, v in zip(rng.uniform(-lim, lim, 10), rng.uniform(-math.pi, math.pi, 10),
                    strict=True):
        closed = surface.geometry([u, v], params)
        derived = surface.derived_geometry([u, v], params)
        for a, b in zip(closed, derived, strict=True):
            assert np.asarray(a) == pytest.approx(np.asarray(b), abs=1e-12 / dims[0])


@pytest.mark.parametrize("drive", ["a", "b", "eq3"])
@pytest.mark.parametrize(("shape", "dims", "eta0", "amp"), [
    ("capsule", (0.012, 0.03), (0.005, 0.3), 0.02),
    ("capsule", (0.012, 0.03), (0.02996, 0.3), 0.02),
    ("superellipsoid", (0.025, 0.025, 0.025, 0.005), (0.1, 0.5), 0.2),
    ("superellipsoid", (0.025, 0.025, 0.025, 0.005), (0.02, 0.78), 0.2)])
def test_a_ball_tip_rolls_on_each_shape_without_slip_or_spin(
        drive: str, shape: str, dims: tuple[float, ...], eta0: tuple[float, float],
        amp: float) -> None:
    """Montana's equations on a shape's chart (A: the capsule's cylinder, and across its
    seam onto a cap, where the curvature jumps; a rounded cube's radial chart on a face
    and across an edge) under a 12 mm ball tip (B): along a motion driven each way, the
    pose the contact coordinates give has its contact point at rest and no spin about the
    normal (the laws of tests/test_contact.py)."""
    from test_contact import Motion, rolling_defects

    from ocp.geometry.contact import ContactPair
    from ocp.geometry.surfaces import Sphere

    obj = ObjectSpec(shape, dims)
    motion = Motion(ContactPair(obj.surface, Sphere), drive, list(obj.params), [0.012],
                    np.eye(3), np.eye(3), np.array([[0.3, -0.5], [0.4, 0.2], [-0.1, 0.3]]),
                    (2.5 if drive == "eq3" else 1.0) * amp)
    us = []
    for t, eta in motion.integrate(np.array([*eta0, 0.2, -0.4, 0.7])):
        assert abs(eta[0]) < obj.u_limit(0.0)  # on the chart
        d = rolling_defects(motion, t, eta)
        assert d.slip < 1e-6 and d.spin < 1e-6, (t, d)
        us.append(eta[0])
    if eta0[0] == 0.02996:  # the seam case: the contact goes from the cylinder onto the cap
        assert min(us) < dims[1] < max(us)


def test_a_line_contact_is_refused_by_field() -> None:
    """A capsule's cylinder touches a flat palm or a flat pad along a line: the planner's
    contacts are points, so such requests name the field and why (round fingertips are
    points on it)."""
    import json
    from pathlib import Path

    from dexroll_client.models import PlanStatus
    from planner_service.cli import plan_request

    palm = {"planner": "ball_on_palm", "object": {"shape": "capsule",
                                                  "dimensions": [0.012, 0.028]},
            "initial": {"x": 0, "y": 0, "u": 0, "v": 0, "psi": 0}, "goal": {"x": 0.02},
            "duration": 2.0}
    result, _ = plan_request(palm)
    assert result.status is PlanStatus.INVALID_INPUT
    assert [(e.field, "along a line" in e.reason) for e in result.errors] == [
        ("object.shape", True)]
    pads = json.loads((Path(__file__).parents[1] / "examples" /
                       "experiment2_two_fingers.json").read_text())
    pads["object"] = {"shape": "capsule", "dimensions": [0.012, 0.028]}
    result, _ = plan_request(pads)
    assert result.status is PlanStatus.INVALID_INPUT
    assert {(e.field, "along a line" in e.reason) for e in result.errors} == {
        ("fingers[0]", True), ("fingers[1]", True)}


#: The built-in Allegro-class hand's joints (index, middle, ring, thumb) with each capsule
#: cap touching an upright capsule (radius 12 mm, half length 28 mm) centred at
#: (30, 0, 70) mm: its nominal grasp moved by the least joint motion until they touch.
Q_CAPSULE = ((-0.33034, 0.51575, 1.04715, 0.79813), (-0.07205, 0.15793, 1.47607, 0.46308),
             (0.30242, 0.46406, 1.30515, 0.89561), (1.28221, 0.48685, 1.05877, 0.62986))


def test_the_allegro_hand_rolls_a_capsule_about_its_axis() -> None:
    """Four round fingertips roll an upright capsule 15 degrees about its own axis (the
    palm's normal) in 2 s, its 60 g carried: solved, certified, executed in MuJoCo on the
    capsule geom within 2 mm / 3 degrees with no contact lost. (The NLP's length scale is
    the capsule's radius + half length, as its values': with the largest parameter, as
    every NLP took it, even a motion of zero was infeasible.)"""
    from helpers import planned_and_executed

    raw = {"planner": "manipulation",
           "object": {"shape": "capsule", "dimensions": [0.012, 0.028]},
           "hand": {"builtin": "allegro"},
           "fingers": [{"hand_finger": k, "initial_q": list(Q_CAPSULE[k])} for k in range(4)],
           "initial_pose": {"position": [0.03, 0.0, 0.07], "orientation_wxyz": [1, 0, 0, 0]},
           "motion": {"kind": "steps", "steps": [{"duration": 2.0, "axis": [0, 0, 1],
                                                  "angle": math.radians(-15.0)}]},
           "tracking": {"position_tolerance": 0.001, "orientation_tolerance": 0.01745},
           "forces": {"mass": 0.06}, "mu": 0.9, "duration": 2.0, "n_intervals": 20}
    planned_and_executed(raw)


def test_the_capsules_chart_crosses_its_seams_smoothly() -> None:
    """One chart covers the capsule's cylinder and caps: exactly the capsule outside the
    seams' blends (the cylinder's M, K, T; a cap's sphere), within 0.03 um inside it across
    them, its curvature continuous (no jump between points 0.1 um apart) though the
    capsule's own jumps from 0 to 1/r; the inverse finds u back on every part."""
    from ocp.shapes.capsule import SEAM_BLEND

    r, h = 0.012, 0.028
    obj = ObjectSpec("capsule", (r, h))
    surface, params = obj.surface, obj.params
    w = SEAM_BLEND * r
    geo = [surface.geometry([u, 0.4], params) for u in (0.01, h + 0.01)]
    assert np.asarray(geo[0][3]) == pytest.approx(np.diag([0.0, 1 / r]), abs=1e-12)
    assert np.asarray(geo[1][3]) == pytest.approx(np.diag([1 / r, 1 / r]), abs=1e-9)
    assert np.asarray(geo[1][2]) == pytest.approx(np.diag([1.0, r * math.cos(0.01 / r)]))
    us = np.concatenate([np.linspace(h - 2 * w, h + 2 * w, 801),
                         -np.linspace(h - 2 * w, h + 2 * w, 801), [0.0, 0.02, 0.04]])
    pts = np.array([np.asarray(surface.geometry([u, 0.4], params)[0]).ravel() for u in us])
    _, _, dist = shape_of("capsule").nearest((r, h), pts)
    assert np.all(dist <= 1e-15) and np.all(dist > -3e-8)
    k = np.array([float(surface.geometry([u, 0.4], params)[3][0, 0])
                  for u in np.arange(h - 1.2 * w, h + 1.2 * w, 1e-7)])
    assert k[0] == 0.0 and k[-1] == pytest.approx(1 / r)
    assert np.max(np.abs(np.diff(k))) < 0.01 / r
    assert surface.inverse(pts, params)[:, 0] == pytest.approx(us, abs=1e-12)


def test_a_fingertip_rolls_over_the_capsules_seam_onto_its_cap() -> None:
    """examples/capsule_over_seam.json: the upright capsule held 16 mm higher in the
    Allegro-class hand, tilted 12 degrees about the palm's y: the thumb's contact starts on
    the cylinder 0.3 mm above the lower seam and rolls 0.6 mm past it onto the cap, in one
    plan on one chart: solved and certified (with the capsule's jump in curvature at the
    seam in the chart, IPOPT cycled on it to the time limit on 3-8 degree tilts). Its
    execution in MuJoCo is tests/test_sim.py's."""
    import json
    from pathlib import Path

    from dexroll_client.models import PlanStatus
    from planner_service.cli import plan_request

    raw = json.loads((Path(__file__).parents[1] / "examples" /
                      "capsule_over_seam.json").read_text())
    result, summary = plan_request(raw)
    assert result.status is PlanStatus.SOLVED, summary
    assert result.certificate is not None and result.certificate.passed
    h = raw["object"]["dimensions"][1]
    thumb = next(c for c in result.trajectory.contacts if c.name == "thumb")
    u = np.asarray(thumb.eta)[:, 2]
    assert u[0] > -h + 2e-4 and u.min() < -h - 5e-4


def test_the_nlps_length_scale_is_the_values() -> None:
    """The length an NLP scales by, from its parameter symbols, is the one its values are
    scaled by (ObjectSpec.length_scale), for every shape."""
    import casadi as ca

    for shape, dims in CASES:
        obj = ObjectSpec(shape, dims)
        p = ca.SX.sym("p", len(obj.params))
        f = ca.Function("L", [p], [obj.surface.length_scale(p)])
        assert float(f(obj.params)) == obj.length_scale == max(shape_of(shape).semi_axes(dims))


@pytest.mark.parametrize("obj", [  # the capsule by default, the two others slow
    pytest.param({"shape": "ellipsoid", "dimensions": [0.03, 0.0305, 0.031]},
                 marks=pytest.mark.slow),
    pytest.param({"shape": "superellipsoid", "dimensions": [0.03, 0.03, 0.03, 0.024]},
                 marks=pytest.mark.slow),
    {"shape": "capsule", "dimensions": [0.03, 0.0128]}],
    ids=["triaxial", "superellipsoid", "capsule"])
def test_a_users_own_hand_turns_other_shapes_on_its_own_actuators(obj: dict) -> None:
    """The Menagerie-style MJCF hand (examples/own_hand.xml) in the built-in hand's nominal
    grasp turns a three-axis ellipsoid, a rounded cube (its mesh written inline in the
    user's scene) and an upright capsule 0.1 rad about the palm's normal: certified, then
    executed on the file's own position servos with nothing of dexroll's added, within
    2 mm / 3 deg, no contact lost. The capsule's middle fingertip touches its lower cap,
    its ring the cylinder, and its thumb rolls over the upper seam onto the cap (12.63 to
    12.85 mm up the meridian, the seam at 12.8 mm)."""
    from pathlib import Path

    from helpers import nominal_turn, planned_and_executed

    text = (Path(__file__).parents[1] / "examples" / "own_hand.xml").read_text()
    raw = nominal_turn(text, ["ff_tip", "mf_tip", "rf_tip", "th_tip"], forces={"mass": 0.05},
                       mu=0.9)
    raw["object"] = obj
    result, _ = planned_and_executed(raw, model="request")
    if obj["shape"] == "capsule":
        h = obj["dimensions"][1]
        u = {c.name: np.asarray(c.eta)[:, 2] for c in result.trajectory.contacts}
        assert u["mf"].max() < -h and abs(u["rf"]).max() < h
        assert u["th"][0] < h < u["th"].max()
