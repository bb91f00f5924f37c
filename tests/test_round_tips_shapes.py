"""Round fingertips on objects other than a ball, from joint angles
(``ocp.spec.grasp.contact_from_joints``): the tip's contact is the object's point nearest
to the tip's centre, in the object's own chart patch.

* the nearest point of an ellipsoid (of revolution, triaxial) to points outside and inside:
  the tangential residual vanishes, the sign is the implicit function's, it is the global
  nearest point;
* the contact coordinates of the built-in Allegro-class hand's capsule caps on an egg and on
  a triaxial ellipsoid: the contact point on the object and on the tip's sphere, normals
  opposite, the coordinates giving the tip frame through the contact kinematics; the gap's
  sign; a small gap closed by the least joint motion along the true distance's gradient; a
  contact beyond the chart's pole bound refused by field; the ball's coordinates unchanged;
* the Allegro-class hand turning an egg and a triaxial ellipsoid 12 degrees about the palm's
  normal: solved, certified and executed in MuJoCo.
"""

from __future__ import annotations

import math
from typing import Any

import casadi as ca
import numpy as np
import pytest
from helpers import assert_close

from ocp.geometry.contact import ContactPair
from ocp.geometry.nearest import nearest_surface_point
from ocp.geometry.rotations import log_rotation, quaternion_wxyz
from ocp.geometry.surfaces import rotation_from_vector
from ocp.robots.allegro import NOMINAL_Q, load_allegro
from ocp.spec.grasp import contact_from_joints, fingertips_from_joints
from ocp.spec.motion import ObjectPose
from ocp.spec.problem import ObjectSpec, ProblemError

HAND = load_allegro("urdf")
NAMES = ("index", "middle", "ring", "thumb")
WHERE = tuple(f"fingers[{k}].initial_q" for k in range(4))
CENTRE = (0.03, 0.0, 0.07)
EGG = ObjectSpec("ellipsoid", (0.03, 0.04))
TRIAXIAL = ObjectSpec("ellipsoid", (0.028, 0.034, 0.04))
#: The egg's long axis along the palm's -y (a quarter turn about x), and upright.
ACROSS = (math.sqrt(0.5), math.sqrt(0.5), 0.0, 0.0)
UPRIGHT = (1.0, 0.0, 0.0, 0.0)
#: Joint angles [rad] that put the hand's four caps on the egg lying across the fingers
#: (the ring's contact 60 deg from the egg's equator), and on the upright triaxial
#: ellipsoid, both centred at CENTRE: the nominal grasp's, moved by least squares until
#: each cap touches, rounded (the planner closes the rounding's micrometres).
Q_EGG_ACROSS = ((-0.2049, 0.3744, 0.9306, 0.7467), (-0.1044, 0.0519, 1.3709, 0.3929),
                (0.0529, 0.2706, 1.1942, 0.8781), (1.1153, 0.6822, 0.874, 0.5675))
Q_TRIAXIAL_UPRIGHT = ((-0.2169, 0.3997, 0.9484, 0.7534), (-0.1031, 0.0611, 1.3785, 0.396),
                      (0.0876, 0.3112, 1.2127, 0.8798), (1.1245, 0.6733, 0.8886, 0.5721))


def tip_frame(k: int, q: Any) -> tuple[np.ndarray, np.ndarray]:
    """(R, centre): the tip frame of finger k (its cap's centre) in the palm frame."""
    f = HAND.fingers[k]
    R_l, p_l = f.fingertip_pose_pin(np.asarray(q, dtype=float))
    return R_l @ f.tip_surface.R, p_l + R_l @ f.tip_surface.p


def nearest(obj: ObjectSpec, pose: ObjectPose, k: int, q: Any
            ) -> tuple[np.ndarray, float, np.ndarray]:
    """(chart point, distance of the cap's centre [m], outward normal, palm frame) of the
    object's point nearest to finger k's cap centre (the object's own patch)."""
    R_pc = pose.rotation @ rotation_from_vector(obj.chart_rotation)
    _, c = tip_frame(k, q)
    alpha, t = nearest_surface_point(obj.surface, obj.dimensions,
                                     R_pc.T @ (c - np.asarray(pose.position)))
    _, G, _, _, _ = obj.surface.geometry(alpha, obj.dimensions)
    return alpha, t, R_pc @ np.asarray(G)[:, 2]


def touching(obj: ObjectSpec, pose: ObjectPose, k: int, q: Any, gap: float = 0.0
             ) -> ObjectPose:
    """``pose`` moved along the normal so that finger k's cap is ``gap`` [m] from it."""
    _, t, n = nearest(obj, pose, k, q)
    r = HAND.fingers[k].tip_surface.params[0]
    shift = (t - r - gap) * n
    return ObjectPose(pose.orientation, tuple(float(x) for x in  # type: ignore[arg-type]
                                              np.asarray(pose.position) + shift))


def pose_from_contact(obj: ObjectSpec, k: int, init: tuple[float, ...],
                      chart: tuple[float, float, float], pose: ObjectPose
                      ) -> tuple[np.ndarray, np.ndarray]:
    """The tip frame in the palm frame from the contact coordinates (a, b, u, v, psi):
    g_po g_ot(eta) with the pair (object, tip) (``ContactPair.pose``, eta = (u, v, a, b,
    psi))."""
    tip = HAND.fingers[k].tip_surface
    a, b, u, v, psi = init
    R, p = ContactPair(obj.surface, tip.surface).pose(
        ca.DM([u, v, a, b, psi]), ca.DM(obj.dimensions), ca.DM(tip.params),
        ca.DM(rotation_from_vector(chart)), ca.DM.eye(3))
    R_o = pose.rotation
    return R_o @ np.asarray(R), R_o @ np.asarray(p).ravel() + np.asarray(pose.position)


# -- the nearest point --------------------------------------------------------------------

@pytest.mark.parametrize("obj", [EGG, TRIAXIAL], ids=["spheroid", "triaxial"])
def test_the_nearest_point_is_where_the_normal_meets_the_point(obj: ObjectSpec) -> None:
    """From points 0.1 to 40 mm outside and 1 to 10 mm inside: ``point - f`` is along the
    normal there (tangential part <= 1e-14 m), its length the signed distance, the sign the
    implicit function's, and no point of 20000 spread over the surface is nearer."""
    rng = np.random.default_rng(3)
    axes = np.array(obj.kind.semi_axes(obj.dimensions))
    samples = obj.kind.sample_points(obj.dimensions, 20000)
    for _ in range(40):
        d = rng.normal(size=3)
        d /= np.linalg.norm(d)
        base = obj.surface.support_point(d, obj.dimensions)
        depth = rng.choice([rng.uniform(1e-4, 0.04), -rng.uniform(1e-3, 0.01)])
        c = base + depth * d
        alpha, t = nearest_surface_point(obj.surface, obj.dimensions, c)
        p, G, _, _, _ = obj.surface.geometry(alpha, obj.dimensions)
        e = c - np.asarray(p).ravel()
        G = np.asarray(G)
        assert np.linalg.norm(G[:, :2].T @ e) <= 1e-14
        assert_close(abs(t), np.linalg.norm(e), atol=1e-15)
        assert (t > 0) == (np.sum((c / axes) ** 2) > 1.0)
        assert abs(t) <= np.min(np.linalg.norm(samples - c, axis=1)) + 1e-12
        if t > 0:  # from any seed: the same point (the nearest to an outside point is unique)
            _, t2 = nearest_surface_point(obj.surface, obj.dimensions, c, alpha + 0.8)
            assert_close(t2, t, atol=1e-15)


# -- contact coordinates from joint angles -------------------------------------------------

CASES = [(EGG, ACROSS, Q_EGG_ACROSS), (TRIAXIAL, UPRIGHT, Q_TRIAXIAL_UPRIGHT),
         (ObjectSpec("ellipsoid", (0.03, 0.04), (0.0, 0.0, 0.7)), ACROSS, Q_EGG_ACROSS),
         (ObjectSpec("ellipsoid", (0.028, 0.034, 0.04), (math.pi, 0.0, 0.0)), UPRIGHT,
          Q_TRIAXIAL_UPRIGHT)]
IDS = ["egg", "triaxial", "egg-patch-turned-about-z", "triaxial-patch-half-turned"]
#: The egg lying across, its contacts on its side chart (each on its patch's equator)
SIDE = ObjectSpec("ellipsoid", (0.03, 0.04), side_chart=True)


@pytest.mark.parametrize(("obj", "orientation", "qs"), [*CASES, (SIDE, ACROSS, Q_EGG_ACROSS)],
                         ids=[*IDS, "egg-side-chart"])
def test_a_touching_tip_has_coordinates_that_give_its_frame(
        obj: ObjectSpec, orientation: tuple[float, ...], qs: tuple[tuple[float, ...], ...]
        ) -> None:
    """Each cap touching the object exactly: the gap is 0, the coordinates are in the
    object's own patch (on the egg's side chart: in the patch about its axis that puts
    the contact on that chart's equator, the ring's 60 deg up the egg's own), the contact
    point is on the object (its chart) and on the cap's sphere (its chart, radius r from
    the centre) with opposite normals, and the contact kinematics put the tip frame where
    Pinocchio does."""
    for k, q in enumerate(qs):
        pose = touching(obj, ObjectPose(orientation, CENTRE), k, q)  # type: ignore[arg-type]
        init, chart, gap = contact_from_joints(HAND.fingers[k], q, obj, pose)
        assert abs(gap) <= 1e-15
        if obj.side_chart:  # its own patch, about the egg's axis, on its equator
            assert abs(init[2]) <= 1e-12
            assert abs(rotation_from_vector(chart)[2, 2] - 1.0) <= 1e-12
        else:
            assert chart == obj.chart_rotation
        assert obj.surface.chart_rotation_error(rotation_from_vector(chart),
                                                obj.dimensions) is None
        tip = HAND.fingers[k].tip_surface
        R_t, centre = tip_frame(k, q)
        R_pc = pose.rotation @ rotation_from_vector(chart)
        p_o, G_o, _, _, _ = obj.surface.geometry(np.array(init[2:4]), obj.dimensions)
        p_t, G_t, _, _, _ = tip.surface.geometry(np.array(init[0:2]), tip.params)
        point = R_pc @ np.asarray(p_o).ravel() + np.asarray(pose.position)
        assert_close(R_t @ np.asarray(p_t).ravel() + centre, point, atol=1e-15)
        assert_close(np.linalg.norm(point - centre), tip.params[0], atol=1e-15)
        assert_close(R_pc @ np.asarray(G_o)[:, 2], -(R_t @ np.asarray(G_t)[:, 2]),
                     atol=1e-12)
        R, p = pose_from_contact(obj, k, init, chart, pose)
        assert_close(R, R_t, atol=1e-12)
        assert_close(p, centre, atol=1e-15)
        assert abs(init[2]) <= obj.u_limit(math.radians(15.0))


def test_the_eggs_side_chart_is_the_egg_with_its_poles_on_the_equator() -> None:
    """The egg's side chart (EggSide): its closed form is its derivation; its points are
    on the egg with the egg's outward normals; its poles are on the egg's equator and its
    own equator passes through the egg's ends; the inverse gives (u, v) back; its patch
    about the egg's axis puts any point, an end's neighbourhood included, at u = 0."""
    from ocp.shapes.ellipsoid import EggSide

    surface, params = SIDE.surface, SIDE.params
    assert surface is EggSide and EggSide in SIDE.kind.surfaces()
    assert ObjectSpec("ellipsoid", (0.03, 0.034, 0.04), side_chart=True).surface.name == \
        "triaxial_ellipsoid"  # (no side chart: a triaxial one keeps its own)
    a, c = params
    rng = np.random.default_rng(5)
    for u, v in zip(rng.uniform(-1.4, 1.4, 25), rng.uniform(-math.pi, math.pi, 25),
                    strict=True):
        closed = surface.geometry([u, v], params)
        for x, y in zip(closed, surface.derived_geometry([u, v], params), strict=True):
            assert_close(np.asarray(x), np.asarray(y), atol=1e-12)
        p = np.asarray(closed[0]).ravel()
        assert_close(float(np.sum((p / np.array([a, a, c])) ** 2)), 1.0, atol=1e-14)
        grad = p / np.array([a * a, a * a, c * c])
        assert_close(np.asarray(closed[1])[:, 2], grad / np.linalg.norm(grad), atol=1e-14)
        assert_close(surface.inverse(p, params), np.array([u, v]), atol=1e-12)
    pole = np.asarray(surface.geometry([math.pi / 2, 0.0], params)[0]).ravel()
    assert_close(pole, np.array([a, 0.0, 0.0]), atol=1e-12)
    assert_close(np.asarray(surface.geometry([0.0, 0.0], params)[0]).ravel(),
                 np.array([0.0, 0.0, -c]), atol=1e-15)
    for p in (np.array([0.001, 0.002, 0.0399]), np.array([-0.02, 0.02, -0.01])):
        p = p * (1.0 / math.sqrt(float(np.sum((p / np.array([a, a, c])) ** 2))))
        R = surface.axis_patch(p)
        assert abs(float(surface.inverse(R.T @ p, params)[0])) <= 1e-12


def test_the_gap_has_the_sign_of_the_distance_and_a_far_tip_is_refused() -> None:
    """The object moved along the normal: the gap is the distance moved, negative when the
    cap sinks in; beyond 2 mm each way the finger's joints are refused by field."""
    q = Q_EGG_ACROSS[2]
    for gap in (1e-3, -1e-3, 5e-3, -5e-3):
        pose = touching(EGG, ObjectPose(ACROSS, CENTRE), 2, q, gap)
        assert_close(contact_from_joints(HAND.fingers[2], q, EGG, pose)[2], gap, atol=1e-15)
        qs = (*Q_EGG_ACROSS[:2], q)
        if abs(gap) > 2e-3:
            with pytest.raises(ProblemError) as exc:
                fingertips_from_joints(HAND.fingers[:3], qs, EGG, pose, NAMES[:3], WHERE[:3])
            ours = [why for f, why in exc.value.errors if f == WHERE[2]]
            what = "5 mm from" if gap > 0 else "5 mm inside"
            assert len(ours) == 1 and what in ours[0], exc.value.errors


@pytest.mark.parametrize("gap", [1.5e-3, -1.5e-3])
def test_a_small_gap_is_closed_by_the_least_motion_along_the_surface_normal(
        gap: float) -> None:
    """The ring cap 1.5 mm from the egg (or into it), where the egg's normal is 12 deg from
    the line of the centres: the coordinates give a tip frame that the finger reaches
    exactly at joints q' near q (Gauss-Newton on the 6-D pose), and q' - q is along the
    gap's gradient (by finite differences), as long as the least motion that closes it."""
    k, q = 2, np.array(Q_EGG_ACROSS[2])
    f = HAND.fingers[k]
    pose = touching(EGG, ObjectPose(ACROSS, CENTRE), k, q, gap)
    n = nearest(EGG, pose, k, q)[2]
    line = tip_frame(k, q)[1] - np.asarray(pose.position)
    assert math.degrees(math.acos(n @ line / np.linalg.norm(line))) > 10.0
    init, chart, got = contact_from_joints(f, q, EGG, pose)
    assert_close(got, gap, atol=1e-15)
    R_goal, c_goal = pose_from_contact(EGG, k, init, chart, pose)
    x = q.copy()
    for _ in range(20):
        R_t, c = tip_frame(k, x)
        e = np.concatenate([c_goal - c, log_rotation(R_goal @ R_t.T)])
        J = f.frame_jacobian_pin(x)
        Jc = np.vstack([J[:3] - np.cross(c - f.fingertip_pose_pin(x)[1], J[3:].T).T, J[3:]])
        x = x + np.linalg.lstsq(Jc, e, rcond=None)[0]
    R_t, c = tip_frame(k, x)
    assert_close(c, c_goal, atol=1e-12)
    assert_close(R_t, R_goal, atol=1e-10)
    h = 1e-6
    grad = np.array([(contact_from_joints(f, q + h * e, EGG, pose)[2]
                      - contact_from_joints(f, q - h * e, EGG, pose)[2]) / (2 * h)
                     for e in np.eye(4)])
    dq = x - q
    assert abs(dq @ grad) / (np.linalg.norm(dq) * np.linalg.norm(grad)) > 1 - 1e-7
    assert_close(np.linalg.norm(dq), abs(gap) / np.linalg.norm(grad), atol=0.0, rtol=0.01)


def pole_pose(obj: ObjectSpec, k: int, q: Any, u: float) -> ObjectPose:
    """The object turned and placed so that finger k's cap touches it at chart point
    (u, 0) of its own patch."""
    R_c = rotation_from_vector(obj.chart_rotation)
    p, G, _, _, _ = obj.surface.geometry([u, 0.0], obj.dimensions)
    z = R_c @ np.asarray(G)[:, 2]
    _, c = tip_frame(k, q)
    w = c - np.asarray(CENTRE)
    w /= np.linalg.norm(w)
    axis = np.cross(z, w)
    R_o = rotation_from_vector(axis / np.linalg.norm(axis) * math.acos(float(z @ w)))
    r = HAND.fingers[k].tip_surface.params[0]
    position = c - R_o @ (R_c @ np.asarray(p).ravel() + r * z)
    return ObjectPose(tuple(float(x) for x in quaternion_wxyz(R_o)),  # type: ignore[arg-type]
                      tuple(float(x) for x in position))  # type: ignore[arg-type]


@pytest.mark.parametrize("obj", [EGG, TRIAXIAL], ids=["spheroid", "triaxial"])
def test_a_contact_beyond_the_pole_bound_is_refused_by_field(obj: ObjectSpec) -> None:
    """The middle cap touching the object 69 deg from its equator (u = 1.2 rad): taken with
    the default 15 deg pole margin, refused with 25 deg (naming the finger's joints, the
    latitude and the bound), and so is a cap on the very pole."""
    q = NOMINAL_Q[1]
    pose = pole_pose(obj, 1, q, 1.2)
    init, _, gap = contact_from_joints(HAND.fingers[1], q, obj, pose)
    assert abs(gap) <= 1e-15 and init[2] == pytest.approx(1.2, abs=1e-12)
    with pytest.raises(ValueError, match=r"u = 1\.2000, beyond the bound 1\.1345"):
        contact_from_joints(HAND.fingers[1], q, obj, pose, math.radians(25.0))
    with pytest.raises(ProblemError) as exc:
        fingertips_from_joints((HAND.fingers[1],), (q,), obj, pose, ("middle",),
                               (WHERE[1],), math.radians(25.0))
    [(field, why)] = exc.value.errors
    assert field == WHERE[1] and why.startswith("finger 'middle': its contact on the "
                                                "ellipsoid is at u = 1.2000")
    assert "initial_pose.orientation" in why
    on_pole = pole_pose(obj, 1, q, math.pi / 2)
    with pytest.raises(ValueError, match=r"u = 1\.5708, beyond the bound 1\.3090"):
        contact_from_joints(HAND.fingers[1], q, obj, on_pole)


@pytest.mark.parametrize("obj", [EGG, TRIAXIAL], ids=["egg", "triaxial"])
def test_a_request_beyond_its_pole_margin_is_refused_naming_the_finger(
        obj: ObjectSpec) -> None:
    """Through the service: the middle cap touching a triaxial ellipsoid at u = 1.2 rad,
    with the request's pole margin of 25 deg, is an invalid request naming its joint
    angles; an egg touched there is measured on its side chart (tests/test_egg_side_chart.py):
    no error but the one finger's."""
    from planner_service.cli import plan_request

    pose = pole_pose(obj, 1, NOMINAL_Q[1], 1.2)
    raw = turn_request(obj, pose.orientation, pose.position, None)
    raw["fingers"] = [{"hand_finger": 1, "initial_q": list(NOMINAL_Q[1])}]
    raw["pole_margin"] = math.radians(25.0)
    result, _ = plan_request(raw)
    assert result.status.value == "invalid_input"
    if obj is EGG:
        assert [e.field for e in result.errors] == ["fingers"], result.errors
        assert "at least two contacts" in result.errors[0].reason
        return
    assert [e.field for e in result.errors] == ["fingers[0].initial_q"], result.errors
    assert "u = 1.2000, beyond the bound 1.1345" in result.errors[0].reason


#: contact_from_joints on a 30 mm ball turned 30 deg about z, at the nominal grasp moved by
#: (0, 0.01, -0.01, 0.02) rad: (initial, chart_rotation, gap) as they were before any other
#: object was allowed.
BALL = (((-0.011045641591692064, 0.5256308046826573, 0.0, 0.0, 0.0),
         (1.494962424371206, -1.2010084134704913, -0.9183515059456279),
         -0.00055371160068576),
        ((0.002313521531485145, 0.5291129824069573, 0.0, 0.0, 0.0),
         (1.4277850884305696, 0.007065904217587787, -0.4912225650136506),
         -0.0006656271661950423),
        ((0.01259267403725517, 0.5150332981523336, 0.0, 0.0, 0.0),
         (0.6116703127645209, 0.38923814210325103, 0.6071538103304424),
         -0.0002484276440861792),
        ((-0.03818771290706718, 0.9005043881828704, 0.0, 0.0, 0.0),
         (-0.5044722368699031, -2.3612004457496316, -1.8838191658606966),
         0.0005268188427420169))


def test_the_ball_keeps_its_coordinates_and_a_round_ellipsoid_agrees() -> None:
    """On a ball: the same numbers as before, to round-off (they were stored to the last
    bit; with Pinocchio 4.1 they differ in the last bits: 4e-16 in the coordinates, 4e-14
    in the patch's rotation vector, whose logarithm near pi magnifies them). An
    ellipsoid with equal semi-axes, through the general path: the same gap, the same tip
    point, and the same contact point in the palm frame."""
    pose = ObjectPose((math.cos(math.pi / 12), 0.0, 0.0, math.sin(math.pi / 12)), CENTRE)
    step = np.array([0.0, 0.01, -0.01, 0.02])
    ball, round_ = ObjectSpec("sphere", (0.03,)), ObjectSpec("ellipsoid", (0.03, 0.03))
    for k, f in enumerate(HAND.fingers):
        q = np.array(NOMINAL_Q[k]) + step
        init, chart, gap = contact_from_joints(f, q, ball, pose)
        assert_close(np.array(init), np.array(BALL[k][0]), atol=1e-14)
        assert_close(np.array(chart), np.array(BALL[k][1]), atol=1e-12)  # (log near pi)
        assert_close(gap, BALL[k][2], atol=1e-16)
        init2, chart2, gap2 = contact_from_joints(f, q, round_, pose)
        assert_close(gap2, gap, atol=1e-15)
        assert_close(init2[:2], init[:2], atol=1e-12)
        points = []
        for obj, eta, rv in ((ball, init, chart), (round_, init2, chart2)):
            p, _, _, _, _ = obj.surface.geometry(np.array(eta[2:4]), obj.dimensions)
            points.append(pose.rotation @ rotation_from_vector(rv) @ np.asarray(p).ravel())
        assert_close(points[1], points[0], atol=1e-14)


# -- plans --------------------------------------------------------------------------------

def turn_request(obj: ObjectSpec, orientation: tuple[float, ...],
                 position: tuple[float, ...], qs: tuple[tuple[float, ...], ...] | None,
                 angle: float = 12.0) -> dict[str, Any]:
    """The built-in Allegro-class hand turning ``obj`` by ``angle`` degrees about the palm's
    normal in 2 s, its 60 g carried (mu 0.9), the fingers at ``qs`` (None: the hand's
    nominal grasp)."""
    return {
        "planner": "manipulation",
        "object": {"shape": obj.shape, "dimensions": list(obj.dimensions)},
        "hand": {"builtin": "allegro"},
        "fingers": [{"hand_finger": k} if qs is None else
                    {"hand_finger": k, "initial_q": list(qs[k])} for k in range(4)],
        "initial_pose": {"position": list(position), "orientation_wxyz": list(orientation)},
        "motion": {"kind": "steps", "steps": [{"duration": 2.0, "axis": [0, 0, 1],
                                               "angle": math.radians(angle)}]},
        "tracking": {"position_tolerance": 0.001, "orientation_tolerance": 0.01745},
        "forces": {"mass": 0.06}, "mu": 0.9, "duration": 2.0, "n_intervals": 20}


PLANS = [pytest.param(EGG, ACROSS, Q_EGG_ACROSS, marks=pytest.mark.slow),  # (10-13 s)
         (TRIAXIAL, UPRIGHT, Q_TRIAXIAL_UPRIGHT), (EGG, UPRIGHT, None)]


@pytest.mark.parametrize(("obj", "orientation", "qs"), PLANS,
                         ids=["egg-across", "triaxial-upright", "egg-upright-nominal"])
def test_the_allegro_hand_turns_an_egg_solved_certified_and_executed(
        obj: ObjectSpec, orientation: tuple[float, ...],
        qs: tuple[tuple[float, ...], ...] | None) -> None:
    """Four capsule caps from joint angles (the egg lying across the fingers; the triaxial
    ellipsoid upright; the upright egg from the hand's nominal grasp, its caps up to
    0.7 mm off, closed by the planner): solved and certified, then executed in MuJoCo on
    the ellipsoid geom within 2 mm and 3 deg with no contact lost."""
    from helpers import planned_and_executed

    planned_and_executed(turn_request(obj, orientation, CENTRE, qs))
