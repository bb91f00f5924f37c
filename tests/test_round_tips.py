"""Round fingertips (issue 14, item 1): a sphere, a spheroid or a capsule's cap fixed in a
finger link's frame, rolling on a curved object through Montana's general equations
(both curvatures), and real plans with them.

* two spheres rolling: the closed form (the tip's centre on the sphere of radius
  rho + r about the object's, the tip turned by theta (rho + r) / r about the axis of the
  motion when the contact has gone theta over the object);
* curved on curved (sphere/sphere, spheroid/sphere, sphere/spheroid, spheroid/spheroid):
  the rates against finite differences of the poses: no slip, no spin, the rolling
  velocity of eq. 3;
* plans with round tips solved and certified, and the laws checked again here on the
  returned trajectory (the tip's surface point where Pinocchio's kinematics put it, on the
  object, normals opposite).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable

import casadi as ca
import numpy as np
import pytest
from helpers import assert_close

from ocp.geometry.contact import ContactPair, R_contact
from ocp.geometry.surfaces import Ellipsoid, Sphere, rotation_from_vector
from ocp.geometry.tips import TipSurface, capsule_tip, sphere_tip, spheroid_tip
from ocp.solution import ManipulationSolution, Status
from ocp.solve.planner import (
    DesiredMotion,
    ManipulationPlanner,
    ManipulationProblem,
    MotionStep,
    ObjectPose,
    Tracking,
    hand_fingertips,
)
from ocp.spec.problem import ObjectSpec

DEG = math.pi / 180
RHO, R_TIP = 0.025, 0.012
#: A round tip's frame turned so that its chart point (0, 0) has the flat pad's contact
#: frame at the pad's centre (x, y along the pad, z its normal): a sphere whose front
#: point is the pad's centre has the same contact coordinates there as the pad.
PAD_ALIGNED = np.array([[0.0, 0.0, 1.0], [0.0, -1.0, 0.0], [1.0, 0.0, 0.0]])


def _pose_fn(pair: ContactPair, na: int, nb: int) -> ca.Function:
    eta = ca.SX.sym("eta", 5)
    pa, pb = ca.SX.sym("pa", na), ca.SX.sym("pb", nb)
    R, p = pair.pose(eta, pa, pb, ca.SX.eye(3), ca.SX.eye(3))
    return ca.Function("pose", [eta, pa, pb], [R, p])


def _rates_fn(pair: ContactPair, na: int, nb: int) -> ca.Function:
    eta, w = ca.SX.sym("eta", 5), ca.SX.sym("w", 2)
    pa, pb = ca.SX.sym("pa", na), ca.SX.sym("pb", nb)
    return ca.Function("rates", [eta, w, pa, pb], [pair.rates_driven_by_a(eta, w, pa, pb)])


def _rk4(f: Callable[[np.ndarray], np.ndarray], x: np.ndarray, h: float, n: int
         ) -> np.ndarray:
    for _ in range(n):
        k1 = f(x)
        k2 = f(x + h / 2 * k1)
        k3 = f(x + h / 2 * k2)
        k4 = f(x + h * k3)
        x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return x


@pytest.mark.parametrize("psi0", [0.0, 0.7, -2.0])
def test_two_spheres_roll_by_the_closed_form(psi0: float) -> None:
    """The contact driven along the object's equator by theta: the tip's centre is at
    (rho + r) (cos theta, -sin theta, 0) and the tip has turned by theta (rho + r) / r
    about -z (the coin rolling around a coin), whatever the tip's point and angle."""
    pair = ContactPair(Sphere, Sphere)  # A = object, B = tip
    rates, pose = _rates_fn(pair, 1, 1), _pose_fn(pair, 1, 1)
    eta0 = np.array([0.0, 0.0, 0.3, -0.4, psi0])
    theta = 1.1

    def f(e: np.ndarray) -> np.ndarray:
        return np.asarray(rates(e, [0.0, 1.0], RHO, R_TIP)).ravel()

    eta = _rk4(f, eta0, theta / 400, 400)
    R0, _ = (np.asarray(a) for a in pose(eta0, RHO, R_TIP))
    R1, p1 = (np.asarray(a) for a in pose(eta, RHO, R_TIP))
    # the tip frame's origin is its centre: the pose's position
    assert_close(p1.ravel(), (RHO + R_TIP) * np.array([math.cos(theta), -math.sin(theta), 0]),
                 atol=1e-12)
    turn = rotation_from_vector([0.0, 0.0, -theta * (RHO + R_TIP) / R_TIP])
    assert_close(R1, turn @ R0, atol=1e-10)
    assert_close(eta[0:2], [0.0, theta], atol=1e-12)


PAIRS = {
    "sphere-sphere": (ContactPair(Sphere, Sphere), (RHO,), (R_TIP,)),
    "spheroid-sphere": (ContactPair(Ellipsoid, Sphere), (0.03, 0.02), (R_TIP,)),
    "sphere-spheroid": (ContactPair(Sphere, Ellipsoid), (RHO,), (0.01, 0.015)),
    "spheroid-spheroid": (ContactPair(Ellipsoid, Ellipsoid), (0.02, 0.035), (0.014, 0.009)),
}


@pytest.mark.parametrize("name", list(PAIRS))
def test_curved_on_curved_rates_match_finite_differences_of_the_poses(name: str) -> None:
    """At random states and rates: the pose of B in A differentiated by central
    differences along the rates gives B's material point at the contact no velocity (no
    slip), no angular velocity about the normal (no spin), and the rolling velocity that
    eq. 3 maps to the rates (``ContactPair.rolling_velocity``)."""
    pair, pa, pb = PAIRS[name]
    rates, pose = _rates_fn(pair, len(pa), len(pb)), _pose_fn(pair, len(pa), len(pb))
    eta_s, w_s = ca.SX.sym("eta", 5), ca.SX.sym("w", 2)
    roll = ca.Function("roll", [eta_s, w_s], [pair.rolling_velocity(
        eta_s, w_s, ca.DM(pa), ca.DM(pb))])
    rng = np.random.default_rng(14)
    h = 1e-6
    for _ in range(20):
        eta = np.concatenate([rng.uniform(-1.0, 1.0, 2), rng.uniform(-1.0, 1.0, 2),
                              rng.uniform(-math.pi, math.pi, 1)])
        w = rng.normal(size=2)
        ed = np.asarray(rates(eta, w, pa, pb)).ravel()
        Rp, pp = (np.asarray(a) for a in pose(eta + h * ed, pa, pb))
        Rn, pn = (np.asarray(a) for a in pose(eta - h * ed, pa, pb))
        R, _ = (np.asarray(a) for a in pose(eta, pa, pb))
        R_dot, p_dot = (Rp - Rn) / (2 * h), (pp - pn).ravel() / (2 * h)
        gb = pair.b.geometry(eta[2:4], pb)
        ga = pair.a.geometry(eta[0:2], pa)
        point_b = np.asarray(gb[0]).ravel()  # B's contact point, B's frame
        slip = R_dot @ point_b + p_dot
        W = R_dot @ R.T
        omega = np.array([W[2, 1], W[0, 2], W[1, 0]])  # B relative to A, A's frame
        frame_a = np.asarray(ga[1])
        speed = float(np.linalg.norm(np.asarray(ga[2]) @ w))
        assert np.linalg.norm(slip) <= 1e-7 * max(speed, 1e-3), (name, slip)
        assert abs(omega @ frame_a[:, 2]) <= 1e-6 * max(float(np.linalg.norm(omega)), 1.0)
        # eq. 3's omega is A's relative to B in A's contact frame: minus B's relative to A
        assert_close(np.asarray(roll(eta, w)).ravel(), -(frame_a.T @ omega)[0:2],
                     atol=1e-6 * max(float(np.linalg.norm(omega)), 1.0))
        # and the contact frames touch: B's contact frame is A's turned by R_contact(psi)
        assert_close(frame_a.T @ R @ np.asarray(gb[1]), np.asarray(R_contact(eta[4])),
                     atol=1e-12)


def test_tip_surfaces_validate_and_bound_their_coordinates() -> None:
    cap = capsule_tip(R_TIP, (0, 0, 0.029), (0, 0, 1), (1, 0, 0), half_length=0.01)
    assert cap.errors("tip") == []
    R = cap.R
    assert_close(R @ np.array([0.0, -1.0, 0.0]), [0.0, 0.0, 1.0], atol=1e-15)  # the end
    (_, a_hi), (b_lo, b_hi) = cap.bounds(0.002, 15 * DEG)
    assert a_hi == pytest.approx(75 * DEG) and b_lo == pytest.approx(0.002 / R_TIP)
    assert b_hi == pytest.approx(math.pi - 0.002 / R_TIP)
    assert sphere_tip(R_TIP).bounds(0.0, 0.2)[1] == (-math.inf, math.inf)
    assert spheroid_tip(0.01, 0.02).errors("tip") == []
    bad = TipSurface("cone", (0.01,))
    assert bad.errors("t")[0][0] == "t.kind"
    assert TipSurface("sphere", (-1.0,)).errors("t")[0][0] == "t.dimensions"
    with pytest.raises(ValueError, match="parallel"):
        capsule_tip(R_TIP, (0, 0, 0), (0, 0, 1), (0, 0, 2))


# -- plans with round tips ----------------------------------------------------------------

PLANNER = ManipulationPlanner()


def round_three_finger_problem(tip: TipSurface, angle: float = 30.0, n: int = 20
                               ) -> ManipulationProblem:
    """The built-in three-finger hand with round tips whose front point is each pad's
    centre, turning a 25 mm ball about a tilted axis."""
    from ocp.robots.hands import load_hand

    hand = load_hand("three_finger")
    obj = ObjectSpec("sphere", (RHO,))
    start = ObjectPose(position=hand.nominal_object_position)
    tips = tuple(dataclasses.replace(t, finger=dataclasses.replace(t.finger, tip=tip))
                 for t in hand_fingertips(hand, start, obj))
    return ManipulationProblem(
        obj, tips, 2.0, initial_pose=start,
        motion=DesiredMotion.from_steps(start, [MotionStep(2.0, (1.0, 0.0, 1.0),
                                                           angle * DEG)]),
        tracking=Tracking(position_tolerance=1e-3, orientation_tolerance=DEG),
        n_intervals=n)


SPHERE_TIP = sphere_tip(R_TIP, (0.0, 0.0, -R_TIP), PAD_ALIGNED)


@pytest.fixture(scope="module")
def sphere_plan() -> tuple[ManipulationProblem, ManipulationSolution]:
    problem = round_three_finger_problem(SPHERE_TIP)
    return problem, PLANNER.solve(problem)


def test_a_round_tipped_hand_turns_the_ball_solved_and_certified(
        sphere_plan: tuple[ManipulationProblem, ManipulationSolution]) -> None:
    _, plan = sphere_plan
    assert plan.status is Status.SOLVED, plan.message
    names = {c.name for c in plan.certificate.checks}
    assert {"max_slip_speed_f1", "max_spin_rate_f2", "max_gap_error_f3",
            "max_tip_latitude_f1"} <= names
    assert not any(n.startswith("max_pad_excursion") for n in names)


def test_round_tips_touch_the_object_where_the_joints_put_them(
        sphere_plan: tuple[ManipulationProblem, ManipulationSolution]) -> None:
    """From the returned joints by Pinocchio: each tip's centre is rho + r from the ball's
    centre, the tip's surface point at its returned coordinates is the contact point on
    the ball, and the two normals are opposite."""
    problem, plan = sphere_plan
    for tip, finger, contact in zip(problem.fingers, plan.fingers, plan.contacts,
                                    strict=True):
        t = tip.finger.tip_surface
        for i in range(0, len(plan.t), 3):
            R, p = tip.finger.fingertip_pose_pin(finger.q[i])
            centre = p + R @ t.p
            assert_close(np.linalg.norm(centre - plan.object_position[i]), RHO + R_TIP,
                         atol=1e-6)
            ab = contact.eta[i, 0:2]
            f, Rg, _, _, _ = Sphere.geometry(ab, [R_TIP])
            point = centre + R @ t.R @ np.asarray(f).ravel()
            normal = R @ t.R @ np.asarray(Rg)[:, 2]
            assert_close(point, contact.point[i], atol=1e-6)
            assert_close(normal, -contact.normal[i], atol=1e-4)


def test_the_flat_pad_and_its_sphere_start_from_the_same_coordinates() -> None:
    """PAD_ALIGNED puts a sphere's chart point (0, 0) with the pad's contact frame at the
    pad's centre: the initial grasp's joints are the same as the flat pads'."""
    flat = round_three_finger_problem(sphere_tip(R_TIP))  # any tip: the specs' IK
    flat = dataclasses.replace(flat, fingers=tuple(dataclasses.replace(
        t, finger=dataclasses.replace(t.finger, tip=None)) for t in flat.fingers))
    x_flat = PLANNER.initial_state(flat)
    x_round = PLANNER.initial_state(round_three_finger_problem(SPHERE_TIP))
    assert_close(x_round, x_flat, atol=1e-8)


def test_capsule_tips_stay_on_their_caps() -> None:
    """A capsule's cap whose very end is the pad's centre (the axis along the pad's normal,
    the cap's end at b = pi/2): the plan keeps every contact on the cap, which the
    certificate checks (``max_cap_angle_*`` within pi/2)."""
    # the capsule's axis along the pad's normal (link z), its end the pad's centre
    cap = capsule_tip(R_TIP, (0.0, 0.0, -R_TIP), (0.0, 0.0, 1.0), (1.0, 0.0, 0.0), 0.01)
    assert_close(cap.R @ np.array([0.0, -1.0, 0.0]), [0.0, 0.0, 1.0], atol=0)
    problem = round_three_finger_problem(cap, angle=20.0)
    # the pad's centre is the cap's end: (a, b) = (0, pi/2) in the cap's chart, and the
    # cap's contact frame there is the pad's turned by 90 deg about the normal
    problem = dataclasses.replace(problem, fingers=tuple(dataclasses.replace(
        t, initial=(0.0, math.pi / 2, 0.0, 0.0, math.pi / 2)) for t in problem.fingers))
    assert problem.errors() == []
    plan = PLANNER.solve(problem)
    assert plan.status is Status.SOLVED, plan.message
    caps = [c for c in plan.certificate.checks if c.name.startswith("max_cap_angle_")]
    assert len(caps) == 3 and all(c.value <= math.pi / 2 for c in caps)


def test_a_contact_off_the_cap_is_refused_naming_the_field() -> None:
    cap = capsule_tip(R_TIP, (0.0, 0.0, -R_TIP), (0.0, 0.0, 1.0), (1.0, 0.0, 0.0))
    problem = round_three_finger_problem(cap)
    problem = dataclasses.replace(problem, fingers=tuple(dataclasses.replace(
        t, initial=(0.0, -0.3, 0.0, 0.0, 0.0)) for t in problem.fingers))
    errs = problem.errors()
    assert any(f == "fingers[0].initial.y_f" and "cap" in r and "cylindrical" in r
               for f, r in errs), errs


def test_spheroid_tips_turn_the_ball_solved_and_certified() -> None:
    """Spheroidal tips (semi-axes 10, 10, 15 mm; the axis of revolution across the pad,
    the front point the pad's centre): curved on curved with a curvature that is not a
    multiple of the identity, solved and certified."""
    a, c = 0.010, 0.015
    # the tip frame's z (the axis of revolution) along the pad's y, its x the pad's normal
    R = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
    tip = spheroid_tip(a, c, (0.0, 0.0, -a), R)
    problem = round_three_finger_problem(tip, angle=20.0)
    # (0, 0) is the front point: its contact frame is the pad's turned about the normal
    from ocp.geometry.surfaces import Ellipsoid

    _, G, _, _, _ = Ellipsoid.geometry([0.0, 0.0], [a, c])
    M = (R @ np.asarray(G))  # the tip's contact frame in the pad (link) frame
    psi = math.atan2(-M[0, 1], M[0, 0])
    problem = dataclasses.replace(problem, fingers=tuple(dataclasses.replace(
        t, initial=(0.0, 0.0, 0.0, 0.0, psi)) for t in problem.fingers))
    assert problem.errors() == []
    plan = PLANNER.solve(problem)
    assert plan.status is Status.SOLVED, plan.message
    names = {ch.name for ch in plan.certificate.checks}
    assert {"max_tip_latitude_f1", "max_gap_error_f3"} <= names


def test_a_round_tip_presses_the_ball_on_the_palm() -> None:
    """The paper's section 3 with a round tip: the built-in finger with a 12 mm sphere
    whose front point is the pad's centre presses the ball on the palm while the palm
    contact rolls 10 mm (three contacts' worth of laws: the palm's and the tip's), the
    grasp-angle objective keeping the grasp near antipodal; solved and certified."""
    from ocp.one_finger import FingerContact, OneFingerPlanner, OneFingerProblem
    from ocp.robots.finger import load_finger
    from ocp.spec.problem import BallOnPalmProblem

    finger = dataclasses.replace(load_finger(), tip=SPHERE_TIP)
    base = BallOnPalmProblem(object=ObjectSpec("sphere", (RHO,)),
                             initial=(0.0, 0.0, 0.0, 0.0, -math.pi / 2),
                             goal={"x": 0.01, "y": 0.0}, duration=2.0, n_intervals=40)
    problem = OneFingerProblem(base=base, finger=finger, contact=FingerContact(
        initial=(0.0, 0.0, 0.2, 0.0, 0.0), chart_rotation=(0.0, 0.0, math.pi)), mu=0.5)
    sol = OneFingerPlanner(PLANNER).solve(problem)
    assert sol.status is Status.SOLVED, sol.message
    assert sol.plan is not None
    names = {c.name for c in sol.plan.certificate.checks}
    assert {"max_slip_speed_palm", "max_gap_error_finger", "max_tip_latitude_finger"} <= names
