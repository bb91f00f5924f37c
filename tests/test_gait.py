"""Finger gaiting (ocp/gait, docs/gait.md): laws of a fingertip's swing and of the hold
while it is lifted, on the built-in Allegro-class hand (capsule tips, a 60 mm ball of
50 g). A whole gait, planned, certified and executed in MuJoCo, is
tests/test_gait_service.py's (through the service's doors)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from ocp.gait.checks import swing_checks
from ocp.gait.step import contact_of, replace_finger
from ocp.gait.swing import SwingPlan, SwingSpec
from ocp.geometry.bodies import tip_body
from ocp.geometry.rotations import axis_angle_rotation, quaternion_wxyz
from ocp.robots.allegro import NOMINAL_Q, load_allegro
from ocp.shapes.held import Held
from ocp.spec.grasp import ManipulationProblem, fingertips_from_joints
from ocp.spec.motion import ObjectPose, Tracking
from ocp.spec.problem import ForceSpec, ObjectSpec
from ocp.transcription.values import load_parameters

HAND = load_allegro("urdf")
FINGERS = tuple(HAND.fingers)
RHO = 0.03
CENTRE = np.array([0.03, 0.0, 0.07])
POSE = ObjectPose(position=tuple(CENTRE))
OBJ = ObjectSpec("sphere", (RHO,))
QS = tuple(np.array(q, dtype=float) for q in NOMINAL_Q)
TEMPLATE = ManipulationProblem(
    object=OBJ, fingers=fingertips_from_joints(FINGERS, QS, OBJ, POSE,
                                               ("index", "middle", "ring", "thumb"),
                                               ("q0", "q1", "q2", "q3")),
    duration=1.0, initial_pose=POSE, n_intervals=12, forces=ForceSpec(mass=0.05),
    tracking=Tracking(position_tolerance=0.001, orientation_tolerance=math.radians(1.0)))
LOAD = load_parameters(TEMPLATE)


def landing(k: int, degrees: float) -> np.ndarray:
    """Finger k's contact normal turned about the palm's z through the ball's centre."""
    _, n = contact_of(FINGERS[k], QS[k], CENTRE, RHO)
    return axis_angle_rotation((0.0, 0.0, 1.0), math.radians(degrees)) @ n


@pytest.fixture(scope="module")
def step() -> object:
    """The middle fingertip re-placed 10 deg around the ball, the others holding."""
    return replace_finger(FINGERS, QS, 1, landing(1, 10.0), QS[1], Held(CENTRE, np.eye(3), RHO),
                          LOAD)


def spec_joints(d: dict) -> tuple[np.ndarray, ...]:
    """Every finger's joints of a stored swing case."""
    return tuple(np.array(q) for q in d["qs"])


def stored_swing(name: str) -> tuple[dict, SwingSpec]:
    """A swing case stored in tests/data (a gait's fingers' joints, the finger lifted,
    its landing), and its SwingSpec with the defaults: the other tips where their joints
    put them."""
    import json
    from pathlib import Path

    d = json.loads((Path(__file__).parent / "data" / name).read_text())
    qs = spec_joints(d)
    k = d["finger"]
    others = []
    for i in range(len(FINGERS)):
        if i == k:
            continue
        R, p = FINGERS[i].fingertip_pose_pin(qs[i])
        a, b = tip_body(FINGERS[i]).placed(R, p)
        others.append((a, b, tip_body(FINGERS[i]).r))
    return d, SwingSpec(FINGERS[k], qs[k], np.array(d["q_target"]),
                        np.array(d["landing_normal"]), np.array(d["centre"]), d["radius"],
                        tuple(others))


def cap_distance(q: np.ndarray, k: int = 1) -> float:
    """The capsule's surface from the ball's (its segment against the centre; our own
    arithmetic, Pinocchio's kinematics)."""
    body = tip_body(FINGERS[k])
    R, p = FINGERS[k].fingertip_pose_pin(q)
    a, b = p + R @ body.a, p + R @ body.b
    s = np.clip((CENTRE - a) @ (b - a) / max((b - a) @ (b - a), 1e-18), 0.0, 1.0)
    return float(np.linalg.norm(CENTRE - (a + s * (b - a)))) - RHO - body.r


def test_a_swing_lifts_carries_clear_and_lands_where_asked(step: object) -> None:
    st = step
    assert st.ok, st.message
    sw = st.swing
    cert = st.checks("s", 0.0, LOAD, 0.5)
    assert all(c.passed for c in cert), [c.failure for c in cert if not c.passed]
    t = np.linspace(0.0, sw.duration, 801)
    q, v, a = sw.sample(t)
    d = np.array([cap_distance(qi) for qi in q])
    clear = np.array([sw.segment(x) == "clear" for x in t])
    assert d[clear].min() >= sw.spec.clearance - 1e-5  # clear of the ball by the margin
    assert d.min() >= -1e-5  # never inside it
    assert abs(d[-1]) < 1e-6 and abs(d[0]) < 1e-5  # touching at both ends
    assert d.max() > sw.spec.clearance  # it did leave the ball
    # the contact moved 10 deg around the ball (the landing normal)
    _, n_end = contact_of(FINGERS[1], q[-1], CENTRE, RHO)
    assert math.degrees(math.acos(np.clip(n_end @ landing(1, 10.0), -1, 1))) < 1e-3
    # at rest with zero acceleration at both ends; rates and accelerations are the
    # positions' derivatives (central differences of the returned cubic)
    assert np.abs(v[[0, -1]]).max() < 1e-12 and np.abs(a[[0, -1]]).max() < 1e-12
    h = t[1] - t[0]
    assert np.abs((q[2:] - q[:-2]) / (2 * h) - v[1:-1]).max() < 1e-3
    assert np.abs((v[2:] - v[:-2]) / (2 * h) - a[1:-1]).max() < 1e-2
    # continuous accelerations: no jump across the grid's nodes
    eps = 1e-9
    for tk in sw.t[1:-1]:
        assert np.abs(sw.sample(tk - eps)[2] - sw.sample(tk + eps)[2]).max() < 1e-5
    lo, hi = np.asarray(FINGERS[1].lower), np.asarray(FINGERS[1].upper)
    assert np.all(q >= lo) and np.all(q <= hi)
    assert np.abs(a).max() <= sw.spec.max_joint_acceleration * (1 + 1e-9)


def test_the_hold_balances_the_weight_inside_the_cones_and_unloads_to_zero(
        step: object) -> None:
    st = step
    weight = LOAD[0:3]
    for name in ("unload", "load"):
        for s in np.linspace(0.0, 1.0, 7):
            F = st.ramp_forces(name, float(s))
            hold = st.holds[0] if name == "unload" else st.holds[2]
            assert np.allclose(F.sum(axis=0), -weight, atol=1e-7)
            r = hold.points - hold.centre
            assert np.abs(np.cross(r, F).sum(axis=0)).max() < 1e-8
            fn = -np.einsum("ij,ij->i", F, hold.normals)
            ft = np.linalg.norm(F + fn[:, None] * hold.normals, axis=1)
            assert np.all(ft <= 0.5 * fn + 1e-9)  # inside the friction cones (mu 0.5)
    assert np.linalg.norm(st.ramp_forces("unload", 1.0)[1]) == 0.0  # lifts with no force
    assert np.linalg.norm(st.ramp_forces("load", 0.0)[1]) == 0.0  # lands with none
    assert np.all(np.linalg.norm(st.forces[1], axis=1) > 0.4)  # three hold it


def test_a_swing_through_the_object_fails_the_certificate_naming_phase_and_time(
        step: object) -> None:
    sw = step.swing
    # the same swing with its clear part pushed 25 mm (linearised) towards the ball's centre
    body = tip_body(FINGERS[1])
    Q = sw.Q.copy()
    mid = len(Q) // 2
    R, p = FINGERS[1].fingertip_pose_pin(Q[mid])
    J = FINGERS[1].frame_jacobian_pin(Q[mid])
    Jc = J[:3] - np.cross(R @ body.a, J[3:].T).T
    n = (p + R @ body.a - CENTRE) / np.linalg.norm(p + R @ body.a - CENTRE)
    dq = np.linalg.lstsq(Jc, -0.025 * n, rcond=None)[0]
    bump = np.sin(np.linspace(0.0, math.pi, len(Q)))[:, None] ** 4
    bad = dataclasses.replace(sw, Q=Q + bump * dq, V=sw.V, A=sw.A, J=sw.J)
    assert isinstance(bad, SwingPlan)
    failed = [c for c in swing_checks(bad, "step3", 7.0) if not c.passed]
    names = {c.name for c in failed}
    assert "swing_clearance_step3" in names and "swing_penetration_step3" in names
    worst = next(c for c in failed if c.name == "swing_penetration_step3")
    assert 7.0 < worst.time < 7.0 + sw.duration and "at t =" in worst.failure


def test_a_fingertip_the_others_cannot_hold_without_is_refused_at_once() -> None:
    st = replace_finger(FINGERS, QS, 3, landing(3, 10.0), QS[3], Held(CENTRE, np.eye(3), RHO),
                        LOAD)
    assert st.status == "infeasible" and st.swing is None
    assert "thumb" in st.message and "friction cones" in st.message


def test_tip_bodies_distance_is_the_least_over_their_segments_and_counts_cylinders() -> None:
    """The closed-form segment distance is a distance between points of the segments
    (never above the least over dense samples) and within the samples' spacing of it;
    two capsule tips whose caps are apart but whose cylinders cross overlap."""
    from ocp.geometry.bodies import points_segment_distance, segments_distance
    from ocp.robots.grasp_reach import tips_gap

    rng = np.random.default_rng(7)
    a0, b0, a1, b1 = rng.normal(size=(4, 300, 3))
    b0[::5] = a0[::5]  # points
    b1[::7] = a1[::7] + 0.5 * (b0[::7] - a0[::7])  # parallel
    got = segments_distance(a0, b0, a1, b1)
    s = np.linspace(0.0, 1.0, 2001)[:, None]
    for k in range(300):
        brute = min(points_segment_distance(a0[k] + s * (b0[k] - a0[k]), a1[k], b1[k]).min(),
                    points_segment_distance(a1[k] + s * (b1[k] - a1[k]), a0[k], b0[k]).min())
        assert brute - 2e-3 <= got[k] <= brute + 1e-12
    # the index and middle tips bent toward each other (abduction -27 and +27 deg): their
    # caps' centres more than two radii apart, their capsules' cylinders crossing
    f = FINGERS[:2]
    q = [np.array(NOMINAL_Q[0], dtype=float), np.array(NOMINAL_Q[1], dtype=float)]
    q[0][0], q[1][0] = math.radians(-27.0), math.radians(27.0)
    caps = [fi.fingertip_pose_pin(qi) for fi, qi in zip(f, q, strict=True)]
    centres = [p + R @ tip_body(fi).a for fi, (R, p) in zip(f, caps, strict=True)]
    assert float(np.linalg.norm(centres[0] - centres[1])) > 2 * tip_body(f[0]).r
    assert tips_gap(f, q) < -5e-3


def test_a_swing_warm_started_from_the_last_is_the_same_swing(step: object) -> None:
    """The next swing of a finger in a gait starts from the last one's primal-dual point
    (the grasp recurs): the same motion as the cold solve, certified, from exactly the
    finger's joints."""
    st = step
    again = replace_finger(FINGERS, QS, 1, landing(1, 10.0), QS[1], Held(CENTRE, np.eye(3), RHO),
                           LOAD, warm=st.swing)
    assert again.ok, again.message
    assert np.array_equal(again.swing.Q[0], QS[1])  # the switch is exact
    assert np.abs(again.swing.Q - st.swing.Q).max() < 1e-6
    cert = again.checks("s", 0.0, LOAD, 0.5)
    assert all(c.passed for c in cert), [c.failure for c in cert if not c.passed]


def test_a_roll_planned_in_the_balls_start_frame_is_the_same_motion_in_the_palm() -> None:
    """A gait plans each roll in the ball's frame at its start (ocp.gait.planner.
    _roll_problem: a uniform ball's motion does not depend on the frame fixed in it). From
    a ball turned by R_now, the same roll planned in the palm frame's ball orientation
    (its charts, start and goal there) gives the same joints, the same contact forces and
    the rotations R(t) R_now; and the roll asked again (a recurring grasp) starts from the
    last one's primal-dual point and takes fewer iterations than it did cold."""
    from ocp.gait.planner import _roll_problem
    from ocp.solve.planner import ManipulationPlanner

    planner = ManipulationPlanner()
    ax = np.array([0.0, 0.0, 1.0])
    R_now = axis_angle_rotation((1.0, 2.0, 0.5), 0.7)
    turned = ObjectPose(tuple(float(c) for c in quaternion_wxyz(R_now).ravel()),
                        tuple(CENTRE))
    target = axis_angle_rotation(ax, math.radians(3.0)) @ R_now
    rel = _roll_problem(TEMPLATE, QS, turned, target, CENTRE, 1.0)
    assert rel.initial_pose is not None and rel.initial_pose.orientation == (1.0, 0.0, 0.0,
                                                                             0.0)
    names = tuple(f.name for f in TEMPLATE.fingers)
    q1 = np.ravel(quaternion_wxyz(target))
    absolute = dataclasses.replace(
        rel, initial_pose=turned,
        fingers=fingertips_from_joints(FINGERS, QS, OBJ, turned, names,
                                       tuple(f"q{i}" for i in range(4))),
        motion=dataclasses.replace(rel.motion, orientations=(
            turned.orientation, tuple(float(c) for c in q1))))
    a, b = planner.solve(rel), planner.solve(absolute)
    assert a.ok and a.certificate.passed and b.ok and b.certificate.passed
    t = np.linspace(0.0, 1.0, 41)
    ja, jb = a.joint_trajectory(t, efforts=False), b.joint_trajectory(t, efforts=False)
    assert np.abs(ja.positions - jb.positions).max() < 1e-5
    assert np.abs(a.sample(t).object_rotation @ R_now - b.sample(t).object_rotation
                  ).max() < 1e-6
    assert np.abs(a.forces(t)[0] - b.forces(t)[0]).max() < 1e-3  # [N], palm frame
    again = planner.solve(rel, a)
    assert again.ok and again.certificate.passed
    assert again.iterations < a.iterations
    assert np.abs(again.joint_trajectory(t, efforts=False).positions - ja.positions
                  ).max() < 1e-5


def test_a_swing_between_close_neighbours_keeps_the_least_tip_gap() -> None:
    """The middle fingertip 1.8 mm from the index (tests/data/gait_narrow_swing.json: a
    gait's swing about the palm's -z) has no swing that keeps the clearance (3 mm, or 90 %
    of the gap at its ends) from its neighbours; the step keeps MIN_TIP_GAP instead, the
    clearance from the ball unchanged, and the swing is certified."""
    from ocp.gait.swing import MIN_TIP_GAP, plan_swing

    d, spec = stored_swing("gait_narrow_swing.json")
    failed = plan_swing(dataclasses.replace(spec, name="middle",
                                            other_names=("index", "ring", "thumb")))
    assert failed.status == "infeasible"
    # the message names the finger and the physical cause: the neighbour it cannot clear
    assert failed.message.startswith("the swing of finger 'middle' was not found (IPOPT "), \
        failed.message
    assert "it cannot keep the gap to fingertip 'index'" in failed.message, failed.message
    step = replace_finger(FINGERS, spec_joints(d), d["finger"], spec.landing_normal,
                          spec.q_target, Held(spec.centre, np.eye(3), spec.radius), LOAD)
    assert step.ok, step.message
    assert step.swing.spec.tip_gap == MIN_TIP_GAP
    assert step.swing.spec.clearance == spec.clearance
    assert max(step.swing.spec.required_gaps()) <= MIN_TIP_GAP + 1e-12
    cert = step.checks("s", 0.0, LOAD, 0.5)
    assert all(c.passed for c in cert), [c.failure for c in cert if not c.passed]


def test_a_rolls_clock_starts_and_ends_still_and_keeps_its_path() -> None:
    """ocp.gait.warp.RollClock: s(tau) runs the plan's whole duration, never faster than
    the plan (rates scaled by s' <= 1), from rest to rest with s' and the accelerations zero
    at both ends; its rates and accelerations are the derivatives of its positions
    (finite differences of a path q(s) run on it)."""
    from ocp.gait.warp import RollClock

    clock = RollClock.of(1.4)
    tau = np.linspace(0.0, clock.length, 20001)
    s, v, a = clock(tau)
    assert s[0] == 0.0 and abs(s[-1] - 1.4) < 1e-12 and np.all(np.diff(s) >= 0.0)
    assert v[0] == 0.0 and v[-1] == 0.0 and v.max() <= 1.0 + 1e-12
    D = clock.duration  # a plan at rest at both ends, as a roll is: smoothstep in s
    x = s / D
    q0, q1, q2 = 3 * x**2 - 2 * x**3, (6 * x - 6 * x**2) / D, (6 - 12 * x) / D**2
    q, qd, qdd = clock.joints(np.column_stack([q0, q0**2]),
                              np.column_stack([q1, 2 * q0 * q1]),
                              np.column_stack([q2, 2 * q1**2 + 2 * q0 * q2]), v, a)
    assert np.abs(qd[[0, -1]]).max() < 1e-12 and np.abs(qdd[[0, -1]]).max() < 1e-12
    h = tau[1] - tau[0]
    assert np.abs(np.gradient(q, h, axis=0)[1:-1] - qd[1:-1]).max() < 1e-3
    assert np.abs(np.gradient(qd, h, axis=0)[2:-2] - qdd[2:-2]).max() < 1e-2
    assert abs(clock.tau_of(0.7) - (0.7 + clock.ramp / 2)) < 1e-6


def test_a_hold_keeps_its_forces_deep_in_the_cones_but_not_large() -> None:
    """The thumb lifted from the grasp searched for 90 deg about the palm's +z
    (tests/data/gait_deep_hold.json): the deepest narrowing that holds the ball (0.2 rad)
    asks 24.5 N of a fingertip, which MuJoCo's servos then drop to a roll's 0.5 N in 0.2 s;
    the hold takes the deepest whose normal forces stay within HOLD_FORCE_FACTOR times the
    ball's weight, and its forces hold the ball inside the narrowed cones."""
    import json
    from pathlib import Path

    from ocp.gait.hold import HOLD_FORCE_FACTOR, Hold, deep_hold_forces, hold_forces, hold_residuals

    d = json.loads((Path(__file__).parent / "data" / "gait_deep_hold.json").read_text())
    hold = Hold(*(np.array(d[k]) for k in ("points", "normals", "centre", "rotation")))
    load = np.array(d["load"])
    weight = float(np.linalg.norm(load[0:3]))

    def narrowed(extra: float) -> np.ndarray:
        out = load.copy()
        out[6] = math.tan(math.atan(load[6]) - extra)
        out[7] = load[7] * out[6] / load[6]
        return out

    def top(F: np.ndarray) -> float:
        return float((-np.einsum("ij,ij->i", F, hold.normals)).max())

    deepest = hold_forces(hold, narrowed(0.2), RHO)
    assert deepest is not None and top(deepest) > HOLD_FORCE_FACTOR * weight
    F, extra = deep_hold_forces(hold, load, RHO)
    assert F is not None and 0.0 < extra < 0.2
    assert top(F) <= HOLD_FORCE_FACTOR * weight
    res = hold_residuals(hold, F, narrowed(extra), np.full(len(F), float(load[3])))
    assert res.equilibrium < 1e-6 and res.normal_margin > -1e-6 and res.cone_margin > -1e-6


def test_a_rolls_tip_gaps_are_the_least_over_its_samples_and_every_pair() -> None:
    """ocp.gait.planner.tips_gaps, the gait certificate's check that rolling fingertips
    stay apart: at the nominal grasp it is grasp_reach.tips_gap's least pair distance;
    with the middle finger swung into the index it is negative (an overlap) at that
    sample."""
    from ocp.gait.planner import tips_gaps
    from ocp.robots.grasp_reach import tips_gap

    nq = tuple(int(f.nq) for f in FINGERS)
    nominal = np.concatenate(QS)
    into = [q.copy() for q in QS]
    into[1][0] = FINGERS[1].upper[0]  # middle_j0 to its limit, toward the index...
    into[0][0] = FINGERS[0].lower[0]  # ... and the index toward the middle
    assert tips_gap(FINGERS, into) < 0.0  # the bodies overlap (this test's premise)
    gap, at = tips_gaps(FINGERS, np.vstack([nominal, np.concatenate(into), nominal]), nq)
    assert at == 1 and gap == pytest.approx(tips_gap(FINGERS, into), abs=1e-12)
    gap0, _ = tips_gaps(FINGERS, nominal[None], nq)
    assert gap0 == pytest.approx(tips_gap(FINGERS, QS), abs=1e-12) and gap0 > 0.0


def test_an_initial_grasp_a_few_nanoradians_off_its_fingers_reach_is_accepted() -> None:
    """A 4-joint finger cannot meet a 6-D pose target off its reachable set; a roll's
    contact coordinates, computed from the joints, can be off by a few 1e-10 (90 deg
    about the palm's -x was refused, the thumb's inverse kinematics stalled at 4.7e-10
    rad). The initial state is accepted within IK_ACCEPT (the thumb's contact moved 3e-9
    rad: refused without it), a real miss still refused naming the finger's field."""
    from ocp.solve.initial import IK_ACCEPT
    from ocp.solve.planner import ManipulationPlanner
    from ocp.spec.problem import ProblemError

    planner = ManipulationPlanner()

    def moved(eps: float) -> ManipulationProblem:
        tips = list(TEMPLATE.fingers)
        init = list(tips[3].initial)
        init[2] += eps
        tips[3] = dataclasses.replace(tips[3], initial=tuple(init))
        return dataclasses.replace(TEMPLATE, fingers=tuple(tips))

    from ocp.spec.grasp import contact_charts

    problem = moved(3e-9)
    x0 = planner.initial_state(problem)
    m = planner.model(problem)
    out = m.cartesian(x0, m.params(np.asarray(problem.object.dimensions, dtype=float),
                                   contact_charts(problem)))
    p_pf = np.asarray(out[3])
    _, p = FINGERS[3].fingertip_pose_pin(x0[m.fingertips[3].q_cols])
    assert 0.0 < np.linalg.norm(p - p_pf[:, 3]) <= IK_ACCEPT  # where the contact says
    with pytest.raises(ProblemError) as err:
        planner.initial_state(moved(1e-6))
    assert err.value.errors[0][0] == "fingers[3].initial" and IK_ACCEPT < 1e-6


#: The grasp the search found for 90 deg about the palm's -z (examples/allegro_turn_90.json
#: with that axis): its index and middle bodies 2.79 mm apart, closing as the ball turns.
NEG_Z_GRASP = (np.array([-0.155391, 0.855795, 0.016562, 1.606769]),
               np.array([0.354379, -0.041106, 1.579601, 0.576375]),
               np.array([0.087103, 0.304557, 1.644007, 0.028379]),
               np.array([1.119174, 0.677932, 0.880797, 0.569822]))


def test_a_roll_is_cut_before_two_fingertips_come_closer_than_the_kept_gap() -> None:
    """ocp.gait.planner._roll_ahead: the fingers' rolled motion (every 4-joint finger's
    fixed by the ball's, grasp_reach.roll) from the -z grasp brings the index's and the
    middle's bodies into each other within 10 deg; the reach stops the roll where they
    are ROLL_TIP_GAP apart: at it the gap is that (within the linear interpolation's
    error), a degree on it is less."""
    from ocp.gait.planner import ROLL_TIP_GAP, _roll_ahead, tips_gaps
    from ocp.robots.grasp_reach import roll

    nq = tuple(int(f.nq) for f in FINGERS)
    ax = np.array([0.0, 0.0, -1.0])
    template = dataclasses.replace(TEMPLATE, fingers=fingertips_from_joints(
        FINGERS, NEG_Z_GRASP, OBJ, POSE, ("index", "middle", "ring", "thumb"),
        ("q0", "q1", "q2", "q3")))

    def gap_after(turn: float) -> float:
        moved = [roll(f, q, CENTRE, RHO, ax, turn) for f, q in zip(FINGERS, NEG_Z_GRASP,
                                                                   strict=True)]
        assert not any(m.why for m in moved)  # no finger stops: only the gap cuts
        return tips_gaps(FINGERS, np.concatenate([m.q for m in moved])[None], nq)[0]

    assert tips_gaps(FINGERS, np.concatenate(NEG_Z_GRASP)[None], nq)[0] > 2e-3
    assert gap_after(math.radians(10.0)) < 0.0  # the whole roll: an overlap (the premise)
    ahead = _roll_ahead(template, NEG_Z_GRASP, CENTRE, RHO, ax, math.radians(10.0))
    apart, need = ahead.apart, ahead.need
    assert need == ROLL_TIP_GAP
    assert not ahead.why and ahead.reach == math.radians(10.0)  # no finger stops
    assert math.radians(1.0) < apart < math.radians(10.0)
    assert gap_after(apart) == pytest.approx(need, abs=2e-5)
    assert gap_after(apart + math.radians(1.0)) < need - 1e-4
    # a turn the gap does not cut is returned whole
    short = _roll_ahead(template, NEG_Z_GRASP, CENTRE, RHO, ax, apart * 0.9).apart
    assert short == pytest.approx(apart * 0.9, abs=1e-15)


@pytest.mark.parametrize("axis", [(-1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)])
def test_the_one_pass_ahead_finds_the_stop_each_fingers_whole_roll_finds(
        axis: tuple[float, float, float]) -> None:
    """ocp.gait.planner._roll_ahead rolls the fingers in ten parts of the turn, all
    together, for the tips' gaps; the first stop it finds (finger, why, where) is the
    first of each finger's own rolled motion over the whole turn (grasp_reach.roll with
    the planner's seam margin), to within one integration step."""
    from ocp.gait.planner import _roll_ahead
    from ocp.robots.grasp_reach import STEP, roll

    template = dataclasses.replace(TEMPLATE, fingers=fingertips_from_joints(
        FINGERS, NEG_Z_GRASP, OBJ, POSE, ("index", "middle", "ring", "thumb"),
        ("q0", "q1", "q2", "q3")))
    ax, upto = np.array(axis), math.radians(60.0)
    whole = [roll(f, q, CENTRE, RHO, ax, upto, template.pad_margin)
             for f, q in zip(FINGERS, NEG_Z_GRASP, strict=True)]
    first = min(range(4), key=lambda i: whole[i].reach)
    assert whole[first].why and whole[first].reach < upto  # a finger stops (the premise)
    ahead = _roll_ahead(template, NEG_Z_GRASP, CENTRE, RHO, ax, upto)
    assert ahead.who == ("index", "middle", "ring", "thumb")[first]
    assert ahead.why == whole[first].why
    assert ahead.reach == pytest.approx(whole[first].reach, abs=STEP)


def test_a_swing_beside_a_close_neighbour_keeps_half_its_gap() -> None:
    """After a roll cut where the index and middle came within ROLL_TIP_GAP and the index
    was re-placed, the middle fingertip lifts 1.45 mm from it
    (tests/data/gait_close_neighbour_swing.json: the full bench's four_finger_gait-009,
    which failed here). Lifting along its normal closes on the index, so neither the
    clearance nor MIN_TIP_GAP (1 mm) admits a swing; the last fallback keeps
    NARROW_SHARE of the ends' gaps, and the swing is certified, the bodies apart
    throughout."""
    from ocp.gait.checks import swing_checks
    from ocp.gait.swing import MIN_TIP_GAP, NARROW_SHARE, plan_swing

    d, spec = stored_swing("gait_close_neighbour_swing.json")
    assert min(spec.required_gaps()) < 1.4e-3  # a neighbour within 1.5 mm (the premise)
    assert plan_swing(spec).status == "infeasible"
    assert plan_swing(dataclasses.replace(spec, tip_gap=MIN_TIP_GAP)).status == "infeasible"
    step = replace_finger(FINGERS, spec_joints(d), d["finger"], spec.landing_normal,
                          spec.q_target,
                          Held(spec.centre, np.array(d["rotation"]), spec.radius), LOAD)
    assert step.ok, step.message
    assert step.swing.spec.neighbour_share == NARROW_SHARE
    need = step.swing.spec.required_gaps()
    assert min(need) > 0.7e-3  # half of the 1.45 mm
    cert = step.checks("s", 0.0, LOAD, 0.5)
    assert all(c.passed for c in cert), [c.failure for c in cert if not c.passed]
    gaps = [c for c in swing_checks(step.swing, "s", 0.0) if "tip_gap" in c.name]
    assert gaps and all(c.value >= 0.7e-3 for c in gaps)


def test_a_holds_forces_keep_the_joints_torques_within_the_actuators() -> None:
    """The nominal grasp held still: with the actuators' torques capped below what the
    deepest hold asks, the hold takes a shallower narrowing whose forces keep every
    joint's torque (J^T f and the links' weight) within the cap, and still hold the
    ball (ocp.gait.step.hold_fits, TorqueLimits)."""
    from ocp.gait.hold import hold_residuals
    from ocp.gait.step import TorqueLimits, deep_forces, grasp_hold, hold_fits
    from ocp.solution import joint_torques

    qs = tuple(np.asarray(q, dtype=float) for q in NOMINAL_Q)
    which = [0, 1, 2, 3]
    hold = grasp_hold(FINGERS, qs, which, Held(CENTRE, np.eye(3), RHO))
    g = np.array([0.0, 0.0, -9.81])

    def peak(F: np.ndarray) -> float:
        return max(float(np.abs(joint_torques(
            FINGERS[i], qs[i][None], hold.points[r][None], hold.normals[r][None],
            F[r][None], np.zeros(1), g)).max()) for r, i in enumerate(which))

    free = deep_forces(FINGERS, qs, which, hold, LOAD, RHO, None)
    assert free is not None
    cap = 0.8 * peak(free)
    limits = TorqueLimits(tuple(np.full(4, -cap) for _ in which),
                          tuple(np.full(4, cap) for _ in which), g)
    F = deep_forces(FINGERS, qs, which, hold, LOAD, RHO, limits)
    assert F is not None and peak(F) <= cap + 1e-12
    assert hold_fits(FINGERS, qs, which, hold, limits)(F)
    res = hold_residuals(hold, F, LOAD, np.full(len(F), float(LOAD[3])))
    assert res.equilibrium < 1e-6 and res.normal_margin > -1e-6 and res.cone_margin > -1e-6


def _stored_step(name: str) -> tuple[int, tuple, object]:
    """The stored swing ``name``'s finger, replace_finger's arguments for it (the ball
    still) and the re-placement they give without actuator limits."""
    d, spec = stored_swing(name)
    k = d["finger"]
    args = (FINGERS, spec_joints(d), k, spec.landing_normal, spec.q_target,
            Held(spec.centre, np.eye(3), spec.radius), LOAD)
    free = replace_finger(*args)
    assert free.ok, free.message
    return k, args, free


def test_a_swing_is_slowed_to_what_the_joints_damping_lets_the_actuators_drive() -> None:
    """A swing whose joint rates, against the file's joint damping, would ask more torque
    than the actuators give is planned again, longer, within those rates."""
    from ocp.gait.step import TorqueLimits

    k, args, free = _stored_step("gait_narrow_swing.json")
    fast = float(np.abs(free.swing.V).max())
    inf = tuple(np.full(4, np.inf) for _ in FINGERS)
    rate = tuple(np.full(4, 0.5 * fast if i == k else np.inf) for i in range(len(FINGERS)))
    slowed = replace_finger(*args, limits=TorqueLimits(tuple(-x for x in inf), inf,
                                                       np.array([0.0, 0.0, -9.81]), rate))
    assert slowed.ok, slowed.message
    assert float(np.abs(slowed.swing.V).max()) <= 0.5 * fast
    assert slowed.swing.spec.duration > 1.9 * free.swing.spec.duration


def _servo_limits(ctrl: list[list[tuple[float, float]]], torque: float, kp: float = 10.0,
                  damping: float = 1.0, share: float = 0.9) -> object:
    """TorqueLimits of position servos (stiffness ``kp``, control ranges ``ctrl`` per
    finger and joint, torque range +-``torque``) on joints of viscous ``damping``, at
    ``share`` of their range, as the gait makes them of an MJCF hand's (e.g.
    examples/own_hand.xml: kp 10, forcerange 0.7 N m, damping 1 N m s/rad)."""
    from ocp.gait.step import TorqueLimits
    from ocp.robots.actuation import Actuator

    acts = tuple(tuple(Actuator(n, n, "servo", 1.0, kp, (0.0, -kp, 0.0), (-torque, torque),
                                ctrl[i][j]) for j, n in enumerate(f.joint_names))
                 for i, f in enumerate(FINGERS))
    lo = tuple(np.full(4, -share * torque) for _ in FINGERS)
    return TorqueLimits(lo, tuple(-x for x in lo), np.array([0.0, 0.0, -9.81]),
                        tuple(np.full(4, share * torque / damping) for _ in FINGERS), share,
                        acts, tuple(np.full(4, damping) for _ in FINGERS))


def test_the_swing_drive_is_what_the_actuators_give_at_every_joint_angle() -> None:
    """TorqueLimits.drive (the swing NLP's rows against the damping): at any joint angles
    ``max(torque_lower, slope q + end_lower) .. min(torque_upper, slope q + end_upper)``
    is exactly TorqueLimits.at (the servos' control ranges reached there, within their
    torque ranges, at the share); a finger whose joints are not damped has none."""
    rng = np.random.default_rng(3)
    ctrl = [[(float(f.lower[j]), float(f.upper[j])) for j in range(4)] for f in FINGERS]
    limits = _servo_limits(ctrl, 0.7)
    for i, f in enumerate(FINGERS):
        drive = limits.drive(i)
        assert drive is not None
        for q in rng.uniform(np.asarray(f.lower) - 0.2, np.asarray(f.upper) + 0.2, (50, 4)):
            lo, hi = limits.at(i, q)
            np.testing.assert_allclose(
                np.maximum(drive.torque_lower, drive.slope * q + drive.end_lower), lo,
                rtol=0, atol=1e-12)
            np.testing.assert_allclose(
                np.minimum(drive.torque_upper, drive.slope * q + drive.end_upper), hi,
                rtol=0, atol=1e-12)
    undamped = dataclasses.replace(limits, damping=tuple(np.zeros(4) for _ in FINGERS))
    assert undamped.drive(0) is None
    lo_pt, hi_pt = dataclasses.replace(limits.drive(0), damping=np.array(
        [1.0, 0.0, 1.0, 1.0])).row_bounds()
    assert np.isinf(lo_pt[2:4]).all() and np.isinf(hi_pt[2:4]).all()
    assert np.isfinite(lo_pt[[0, 1, 4, 5, 6, 7]]).all()


def test_a_damped_swing_is_planned_within_its_actuators_and_faster_than_scaled() -> None:
    """A swing whose rates, against its joints' damping, ask more than its servos give
    (their torque range, and the less their control range reaches near its ends) is
    planned again with the actuators' rows in its NLP (within_damping): the swing
    returned keeps every joint's damping torque within what its actuator gives at that
    angle densely (1000 samples), passes its own checks, and takes less time than the
    same path slowed to its worst sample (the rule before the rows: 0.8 s x 1.63 x 1.05 =
    1.37 s against 1.05 s measured)."""
    from ocp.gait.step import DAMPING_SLACK

    k, args, free = _stored_step("gait_narrow_swing.json")
    sw = free.swing
    # control ranges 20 mrad past the free swing's extremes; 0.35 N m servos
    ctrl = [[(float(f.lower[j]), float(f.upper[j])) for j in range(4)] for f in FINGERS]
    ctrl[k] = [(float(sw.Q[:, j].min()) - 0.02, float(sw.Q[:, j].max()) + 0.02)
               for j in range(4)]
    limits = _servo_limits(ctrl, 0.35)
    over = limits.damping_overrun(k, sw.Q, sw.V)
    assert over > 1.5
    step = replace_finger(*args, limits=limits)
    assert step.ok, step.message
    plan = step.swing
    assert plan.spec.drive is not None
    ts = np.linspace(0.0, plan.duration, 1001)
    Q, V, _ = plan.sample(ts)
    assert limits.damping_overrun(k, Q, V) <= 1.0 + 1e-9
    assert plan.duration < 0.8 * sw.duration * over * DAMPING_SLACK
    cert = step.checks("s", 0.0, LOAD, 0.5)
    assert all(c.passed for c in cert), [c.failure for c in cert if not c.passed]


def test_a_hold_no_forces_of_which_fit_the_actuators_is_named() -> None:
    """hold_torque_refusal: with the actuators capped below what any narrowing of the
    cones asks, the reason names the fingers, the joint, the torque and the range; with
    room, there is none."""
    from ocp.gait.step import TorqueLimits, grasp_hold, hold_torque_refusal

    qs = tuple(np.asarray(q, dtype=float) for q in NOMINAL_Q)
    which = [0, 1, 2, 3]
    hold = grasp_hold(FINGERS, qs, which, Held(CENTRE, np.eye(3), RHO))
    g = np.array([0.0, 0.0, -9.81])
    names = ("index", "middle", "ring", "thumb")

    def limits(cap: float) -> TorqueLimits:
        return TorqueLimits(tuple(np.full(4, -cap) for _ in which),
                            tuple(np.full(4, cap) for _ in which), g)

    assert hold_torque_refusal(FINGERS, qs, which, hold, LOAD, RHO, limits(10.0), names) == ""
    why = hold_torque_refusal(FINGERS, qs, which, hold, LOAD, RHO, limits(1e-3), names)
    assert why.startswith("no forces that hold the ball keep index, middle, ring, thumb "
                          "within their actuators: joint "), why
    assert "its actuator gives -0.001..0.001 N m" in why


def test_a_swing_timed_faster_keeps_its_path_within_the_joints_limits(step: object) -> None:
    """SwingPlan.scaled: the same path in another time (positions at s f equal the
    original's at s; rates over f, accelerations over f^2); fastest_factor times it to
    the joints' velocity or acceleration limit exactly, and its checks still pass."""
    sw = step.swing
    f = sw.fastest_factor()
    assert 0.0 < f < 1.0  # the default 0.8 s swing is slower than its limits
    fast = sw.scaled(f)
    assert fast.duration == pytest.approx(f * sw.duration)
    s = np.linspace(0.0, sw.duration, 97)
    q0, v0, a0 = sw.sample(s)
    q1, v1, a1 = fast.sample(s * f)
    assert np.abs(q1 - q0).max() < 1e-12
    assert np.abs(v1 - v0 / f).max() < 1e-9 and np.abs(a1 - a0 / f**2).max() < 1e-6
    vmax = np.asarray(sw.spec.finger.velocity_limit)
    v_use = float(np.max(np.abs(fast.V) / vmax))
    a_use = float(np.max(np.abs(fast.A))) / sw.spec.max_joint_acceleration
    assert max(v_use, a_use) == pytest.approx(1.0, rel=1e-9)  # at a limit, within both
    assert fast.fastest_factor() == pytest.approx(1.0, rel=1e-9)


def test_a_swing_short_of_a_gap_between_its_nodes_says_by_how_much() -> None:
    """``between_nodes``, by which a gait plans a swing again kept wider at its nodes
    (a rounded cube's swing kept 1 mm from the index at its nodes and 0.983 mm between
    them): 0 for a swing that keeps every gap and its clearance densely; for the same
    path asked 0.2 mm more than it keeps from its nearest neighbour, 0.2 mm. The dense
    samples the gait measures a swing by are made once: its certificate's checks are the
    same as a fresh plan's."""
    from ocp.gait.checks import DISTANCE_TOL
    from ocp.gait.step import between_nodes
    from ocp.gait.swing import MIN_TIP_GAP, NARROW_SHARE, plan_swing

    _, spec = stored_swing("gait_narrow_swing.json")
    plan = plan_swing(dataclasses.replace(spec, tip_gap=MIN_TIP_GAP,
                                          neighbour_share=NARROW_SHARE))
    assert plan.ok and between_nodes(plan) == 0.0
    fresh = dataclasses.replace(plan)  # (no dense samples kept yet)
    assert [(c.name, c.value) for c in swing_checks(plan, "x")] == \
        [(c.name, c.value) for c in swing_checks(fresh, "x")]
    gaps = {c.name: c.value for c in swing_checks(plan, "x")
            if c.name.startswith("swing_tip_gap_")}
    least = min(gaps.values())
    kept = dataclasses.replace(plan.spec, tip_gap=least + 2e-4 + DISTANCE_TOL,
                               neighbour_share=10.0)  # (the share of the ends' gap: none)
    assert min(kept.required_gaps()) == pytest.approx(least + 2e-4 + DISTANCE_TOL)
    assert between_nodes(dataclasses.replace(plan, spec=kept)) == pytest.approx(2e-4,
                                                                              abs=1e-12)


def test_a_swing_planned_again_on_a_finer_grid_keeps_its_path_and_its_laws() -> None:
    """``dense_enough``: a swing that keeps its gaps densely is returned as it is; the same
    swing on the grid FINER times finer (where ``dense_enough`` plans one that dips
    between its coarse nodes) keeps every law of its certificate, lifts off where the
    coarse one does and lands within 1e-3 rad of its joints (the landing's contact is
    free along the surface), and comes no closer to its neighbours."""
    from ocp.gait.step import FINER, between_nodes, dense_enough
    from ocp.gait.swing import MIN_TIP_GAP, NARROW_SHARE, plan_swing

    _, spec = stored_swing("gait_narrow_swing.json")
    coarse = plan_swing(dataclasses.replace(spec, tip_gap=MIN_TIP_GAP,
                                            neighbour_share=NARROW_SHARE))
    assert dense_enough(coarse) is coarse
    fine = plan_swing(dataclasses.replace(
        coarse.spec, n_intervals=FINER * coarse.spec.n_intervals,
        lift_intervals=FINER * coarse.spec.lift_intervals))
    assert fine.ok and between_nodes(fine) == 0.0
    assert all(c.passed for c in swing_checks(fine, "x")), \
        [c.name for c in swing_checks(fine, "x") if not c.passed]
    assert len(fine.Q) == FINER * (len(coarse.Q) - 1) + 1
    assert np.abs(fine.Q[0] - coarse.Q[0]).max() < 1e-12
    assert np.abs(fine.Q[-1] - coarse.Q[-1]).max() < 1e-3
    gaps = [min(c.value for c in swing_checks(p, "x") if c.name.startswith("swing_tip_gap_"))
            for p in (coarse, fine)]
    assert gaps[1] >= gaps[0] - 1e-6
