"""Whole-hand models from URDF and MJCF (issue 14, items 2, 3 and 6): the built-in
Allegro-class hand written twice by us (the same kinematics from one table), fingertip
geometry read from the model, the nominal grasp, and every bad input refused naming the
field and the reason before any NLP is built."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from helpers import assert_close

from ocp.robots.allegro import (
    FINGERS,
    NOMINAL_OBJECT_POSITION,
    NOMINAL_Q,
    NOMINAL_RADIUS,
    TIP_NAMES,
    TIP_RADIUS,
    load_allegro,
    mjcf_text,
    urdf_text,
)
from ocp.robots.grasp_reach import contact_sides, roll, search_grasp, tip_state, tips_gap
from ocp.robots.whole_hand import HandModelError, TipSpec, load_whole_hand, tip_geometry
from ocp.solution import Status
from ocp.solve.planner import ManipulationPlanner, ManipulationProblem
from ocp.spec.grasp import fingertips_from_joints
from ocp.spec.motion import DesiredMotion, MotionStep, ObjectPose, Tracking
from ocp.spec.problem import ObjectSpec, ProblemError, SolverOptions

URDF, MJCF = load_allegro("urdf"), load_allegro("mjcf")
NAMES = ("index", "middle", "ring", "thumb")
BALL = ObjectSpec("sphere", (NOMINAL_RADIUS,))
POSE = ObjectPose(position=NOMINAL_OBJECT_POSITION)
WHERE = tuple(f"fingers[{i}].initial_q" for i in range(4))


def test_the_shipped_files_are_the_table_written_out() -> None:
    assert URDF.text == urdf_text() and MJCF.text == mjcf_text()


def test_urdf_and_mjcf_of_the_hand_have_the_same_kinematics() -> None:
    rng = np.random.default_rng(14)
    for fu, fm in zip(URDF.fingers, MJCF.fingers, strict=True):
        assert fu.joint_names == fm.joint_names and fu.nq == fm.nq == 4
        assert_close(fu.lower, fm.lower, atol=0)
        assert_close(fu.upper, fm.upper, atol=0)
        assert_close(fu.velocity_limit, fm.velocity_limit, atol=0)
        assert fu.tip_surface == fm.tip_surface
        for _ in range(5):
            q = rng.uniform(fu.lower, fu.upper)
            Ru, pu = fu.fingertip_pose_pin(q)
            Rm, pm = fm.fingertip_pose_pin(q)
            assert_close(pu, pm, atol=1e-8)
            assert_close(Ru, Rm, atol=1e-7)
            # the CasADi kinematics the NLP uses is Pinocchio's
            R_ca, p_ca = fu.fk(q)
            assert_close(np.asarray(R_ca), Ru, atol=1e-12)
            assert_close(np.asarray(p_ca).ravel(), pu, atol=1e-12)


@pytest.mark.parametrize("hand", [URDF, MJCF], ids=["urdf", "mjcf"])
def test_fingertip_geometry_read_from_the_model_is_what_the_file_says(hand: Any) -> None:
    """Each tip: the capsule's cap of radius 12 mm, its centre the capsule's centre plus
    its half length along the distal link's z (29 mm for the fingers, 43 mm for the
    thumb), its end outwards (+z)."""
    for row, f in zip(FINGERS, hand.fingers, strict=True):
        tip = f.tip_surface
        assert tip.kind == "capsule" and tip.params == (TIP_RADIUS,)
        assert tip.extra == (row.capsule_half_length,)
        assert_close(tip.p, [0.0, 0.0, row.capsule_centre + row.capsule_half_length],
                     atol=1e-12)
        assert_close(tip.R @ np.array([0.0, -1.0, 0.0]), [0.0, 0.0, 1.0], atol=1e-12)


def test_a_sphere_tip_and_an_mjcf_default_class_are_read() -> None:
    mjcf = """<mujoco><default><default class="tip"><geom type="sphere" size="0.01"
    pos="0 0 0.03"/></default></default><worldbody><body name="b"><joint name="j"
    axis="0 1 0" range="-1 1"/><body name="t" childclass="tip"><geom/></body></body>
    </worldbody></mujoco>"""
    tip = tip_geometry(mjcf, "mjcf", "t")
    assert not isinstance(tip, str)
    assert tip.kind == "sphere" and tip.params == (0.01,)
    assert_close(tip.p, [0, 0, 0.03], atol=0)


@pytest.mark.parametrize("order", ["tip last", "tip first"])
def test_the_fingertip_is_the_colliding_geom_at_the_fingers_end(order: str) -> None:
    """A distal body in the Menagerie's style carries a visual sphere (contype and
    conaffinity 0: MuJoCo never collides it), a link capsule and the fingertip sphere: the
    tip is the colliding geom reaching farthest from the body's origin, whatever the
    order (the first sphere or capsule was taken: the link, or the visual sphere, and the
    plan rolled on it, certified, 5-9 mm from the real tip). Named by a site, the geom
    nearest the site; a body with only visual geoms is refused, saying so."""
    geoms = ['<geom class="link" fromto="0 0 0.006 0 0 0.016"/>',
             '<geom class="tip" pos="0 0 0.03"/>']
    if order == "tip first":
        geoms.reverse()
    mjcf = f"""<mujoco><default><default class="visual"><geom contype="0" conaffinity="0"
    group="2"/></default><default class="link"><geom type="capsule" size="0.009"/>
    </default><default class="tip"><geom type="sphere" size="0.012"/></default></default>
    <worldbody><body name="b"><joint name="j" axis="0 1 0" range="-1 1"/><body name="t">
    <geom class="visual" type="sphere" size="0.02"/>{"".join(geoms)}
    <site name="s" pos="0 0 0.042"/><site name="mid" pos="0 0.009 0.011"/></body></body>
    </worldbody></mujoco>"""
    tip = tip_geometry(mjcf, "mjcf", "t")
    assert not isinstance(tip, str)
    assert tip.kind == "sphere" and tip.params == (0.012,)
    assert_close(tip.p, [0, 0, 0.03], atol=0)
    at_site = tip_geometry(mjcf, "mjcf", "s")  # the sphere, in the site's frame
    assert not isinstance(at_site, str) and at_site.kind == "sphere"
    assert_close(at_site.p, [0, 0, -0.012], atol=1e-15)
    link = tip_geometry(mjcf, "mjcf", "mid")  # a site at the link capsule: it
    assert not isinstance(link, str) and link.kind == "capsule"
    only_visual = mjcf.replace("".join(geoms), "")
    why = tip_geometry(only_visual, "mjcf", "t")
    assert isinstance(why, str) and "not colliding with the object" in why


@pytest.mark.parametrize("fmt", ["urdf", "mjcf"])
def test_a_geom_behind_the_tips_origin_is_not_its_fingertip(fmt: str) -> None:
    """A tip link (body) whose frame sits at the finger's end, with the fingertip sphere
    5 mm ahead of it and another 10 mm behind it, toward the palm: the fingertip is the
    one reaching farthest along the finger (from its last joint out through the tip's
    origin), not the one farthest from the origin (an independent sweep's URDF hand was
    planned on the sphere behind). The finger here runs along the tip frame's +y (the
    joint turns it a quarter turn about x): the direction is read from the chain, turned
    into the tip's frame."""
    ahead, behind = "0 0.005 0", "0 -0.010 0"
    if fmt == "urdf":
        text = f"""<robot name="r"><link name="palm"/><link name="l1"/><link name="tip">
        <collision><origin xyz="{behind}"/><geometry><sphere radius="0.008"/></geometry>
        </collision><collision><origin xyz="{ahead}"/><geometry><sphere radius="0.008"/>
        </geometry></collision></link>
        <joint name="j1" type="revolute"><parent link="palm"/><child link="l1"/>
        <axis xyz="0 1 0"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
        <joint name="j2" type="revolute"><parent link="l1"/><child link="tip"/>
        <origin xyz="0 0 0.05" rpy="1.5707963267948966 0 0"/><axis xyz="1 0 0"/>
        <limit lower="-1" upper="1" effort="1" velocity="1"/></joint></robot>"""
    else:
        text = f"""<mujoco><worldbody><body name="l1"><joint name="j1" axis="0 1 0"
        range="-1 1"/><body name="tip" pos="0 0 0.05" quat="0.7071067811865476
        0.7071067811865476 0 0"><joint name="j2" axis="1 0 0" range="-1 1"/>
        <geom type="sphere" size="0.008" pos="{behind}"/>
        <geom type="sphere" size="0.008" pos="{ahead}"/></body></body></worldbody>
        </mujoco>"""
    tip = tip_geometry(text, fmt, "tip")
    assert not isinstance(tip, str)
    assert_close(tip.p, [0, 0.005, 0], atol=1e-12)


def test_the_nominal_grasp_touches_the_ball_in_force_closure() -> None:
    tips = fingertips_from_joints(URDF.fingers, NOMINAL_Q, BALL, POSE, NAMES, WHERE)
    problem = ManipulationProblem(
        BALL, tips, 1.0, initial_pose=POSE,
        motion=DesiredMotion.from_steps(POSE, [MotionStep(1.0, (0, 0, 1), 0.1)]))
    assert problem.errors() == []
    x0 = ManipulationPlanner().initial_state(problem)  # IK of every finger, force closure
    for tip in tips:  # on the cap (0 < b < pi/2: between the seam and the end), on the
        # chart's equator (the sides of TIP_SIDES are the nominal contacts')
        assert tip.initial[0] == pytest.approx(0.0, abs=1e-3)
        assert 0.3 < tip.initial[1] < math.pi / 2
    assert np.all(np.isfinite(x0))


# -- bad input: each refused naming the field and the reason ---------------------------------

def _errors(call: Callable[[], object]) -> list[tuple[str, str]]:
    try:
        call()
    except (HandModelError, ProblemError) as exc:
        return exc.errors
    raise AssertionError("no error")


def test_a_tip_name_not_in_the_model() -> None:
    errs = _errors(lambda: load_whole_hand(URDF.text, "urdf", [TipSpec("index_tip"),
                                                               TipSpec("pinky_tip")]))
    assert errs[0][0] == "tips[1].name" and "'pinky_tip' is not a link" in errs[0][1]
    assert "index_tip" in errs[0][1]  # the names it has


def test_a_tip_without_sphere_or_capsule_geometry_and_no_surface() -> None:
    text = URDF.text.replace("<capsule", "<box size=\"0.01 0.01 0.01\"/><capsule_no")
    errs = _errors(lambda: load_whole_hand(text, "urdf", [TipSpec("index_tip")]))
    assert errs[0][0] == "tips[0].surface" and "no sphere or capsule" in errs[0][1]
    assert "give the fingertip's surface" in errs[0][1]


@pytest.mark.parametrize(("patch", "words", "why"), [
    ("<worldbody>", "<equality><joint joint1=\"index_j2\" joint2=\"index_j3\" "
                    "polycoef=\"0 1 0.5 0 0\"/></equality><worldbody>",
     "a polynomial of degree above 1"),
    ("<worldbody>", "<equality><weld body1=\"index_tip\"/></equality><worldbody>",
     "closes a kinematic chain"),
    ("<worldbody>", "<tendon><fixed name=\"drive\"><joint joint=\"index_j2\" coef=\"1\"/>"
                    "<joint joint=\"index_j3\" coef=\"1\"/></fixed></tendon><actuator>"
                    "<motor tendon=\"drive\"/></actuator><worldbody>",
     "a transmission to several joints is not commanded"),
    ("<worldbody>", "<tendon><fixed name=\"across\" limited=\"true\" range=\"-0.01 0.01\">"
                    "<joint joint=\"index_j2\" coef=\"1\"/><joint joint=\"middle_j2\" "
                    "coef=\"-1\"/></fixed></tendon><worldbody>",
     "couplings across fingers are not planned"),
    ("<worldbody>", "<include file=\"other.xml\"/><worldbody>", "included files"),
    ('type="hinge" axis="0 0 1"', 'type="ball" axis="0 0 1"', "'ball' joint"),
    # two hinges in one body (Pinocchio composes them into a joint dexroll does not model)
    ('<joint name="index_j2" type="hinge" axis="0 1 0" range="-0.174 1.709"/>',
     '<joint name="index_j2" type="hinge" axis="0 1 0" range="-0.174 1.709"/>'
     '<joint name="index_j2b" type="hinge" axis="1 0 0" range="-0.1 0.1"/>',
     "body 'index_medial' has 2 joints ['index_j2', 'index_j2b']"),
])
def test_mjcf_couplings_it_cannot_plan_includes_and_unsupported_joints_are_refused(
        patch: str, words: str, why: str) -> None:
    text = MJCF.text.replace(patch, words, 1)
    errs = _errors(lambda: load_whole_hand(text, "mjcf", [TipSpec("index_tip"),
                                                         TipSpec("middle_tip")]))
    assert errs[0][0] == "model"
    assert any(why in e for _, e in errs), errs


def test_mjcf_linear_couplings_are_read_as_mujoco_states_them() -> None:
    """A limited fixed tendon over two joints, a linear joint equality (relative to the
    joints' qpos0, as MuJoCo states it) and a tendon equality with a constant: each a
    coupling of its finger, lower <= coefs . q <= upper, in the file's names; a coupling
    of the middle finger's joints is not the index's."""
    pytest.importorskip("mujoco")
    words = ("<tendon><fixed name=\"c\" limited=\"true\" range=\"-0.001 0.002\">"
             "<joint joint=\"index_j2\" coef=\"0.007\"/><joint joint=\"index_j3\" "
             "coef=\"-0.008\"/></fixed><fixed name=\"m\"><joint joint=\"middle_j1\" "
             "coef=\"1\"/><joint joint=\"middle_j2\" coef=\"1\"/></fixed></tendon>"
             "<equality><joint name=\"e\" joint1=\"index_j1\" joint2=\"index_j0\" "
             "polycoef=\"0.1 0.5 0 0 0\"/><tendon tendon1=\"m\" polycoef=\"0.2 0 0 0 0\"/>"
             "</equality><worldbody>")
    hand = load_whole_hand(MJCF.text.replace("<worldbody>", words, 1), "mjcf",
                           [TipSpec("index_tip"), TipSpec("middle_tip")])
    index, middle = hand.fingers
    got = {c.name: c for c in index.couplings}
    assert set(got) == {"tendon 'c'", "<equality><joint> 'e'"}
    c = got["tendon 'c'"]
    assert c.joints == ("index_j2", "index_j3") and c.coefs == (0.007, -0.008)
    assert (c.lower, c.upper) == (-0.001, 0.002)
    assert np.allclose(c.row(index.joint_names), [0, 0, 0.007, -0.008])
    e = got["<equality><joint> 'e'"]  # q1 - 0.5 q0 = 0.1 (qpos0 = 0)
    assert e.lower == e.upper == pytest.approx(0.1)
    assert np.allclose(e.row(index.joint_names), [-0.5, 1, 0, 0])
    (m,) = middle.couplings  # L - L0 = 0.2, L0 = 0 at qpos0
    assert m.name == "<equality><tendon> 1" and m.lower == m.upper == pytest.approx(0.2)
    assert np.allclose(m.row(middle.joint_names), [0, 1, 1, 0])


def test_urdf_mimic_and_continuous_joints_are_refused() -> None:
    text = URDF.text.replace('<joint name="index_j3" type="revolute">',
                             '<joint name="index_j3" type="continuous">')
    errs = _errors(lambda: load_whole_hand(text, "urdf", [TipSpec("index_tip")]))
    assert errs == [("model", "joint 'index_j3' is a 'continuous' joint; only revolute, "
                              "prismatic and fixed joints are supported")]
    text = URDF.text.replace('<child link="index_distal"/>',
                             '<child link="index_distal"/><mimic joint="index_j2"/>')
    errs = _errors(lambda: load_whole_hand(text, "urdf", [TipSpec("index_tip")]))
    assert errs[0][0] == "model" and "mimics 'index_j2'" in errs[0][1]
    # an axis without a direction (NaN kinematics and a misleading reach error before),
    # a revolute joint without its <limit> (urdfdom's reason went to stderr alone)
    j3 = URDF.text[URDF.text.index('<joint name="index_j3"'):]
    j3 = j3[:j3.index("</joint>")]
    for patch, words in ((('<axis xyz="0 1 0"/>', '<axis xyz="0 0 0"/>'),
                          "joint 'index_j3' has the axis '0 0 0'"),
                         (('<limit lower="-0.227" upper="1.618" effort="1" velocity="6"/>',
                           ""), "joint 'index_j3' (revolute) has no <limit>")):
        bad = URDF.text.replace(j3, j3.replace(*patch))
        errs = _errors(lambda bad=bad: load_whole_hand(bad, "urdf", [TipSpec("index_tip")]))
        assert errs[0][0] == "model" and words in errs[0][1], errs


def test_an_unreachable_initial_grasp_names_the_finger_the_distance_and_the_limit() -> None:
    qs = list(NOMINAL_Q)
    qs[1] = (0.0, 0.0, 0.0, 0.0)  # the middle finger straight: far from the ball
    qs[2] = (0.1, 0.3, 2.0, 0.8)  # ring j2 beyond its limit
    errs = _errors(lambda: fingertips_from_joints(URDF.fingers, tuple(qs), BALL, POSE, NAMES,
                                                  WHERE))
    by_field = dict(errs)
    assert "finger 'middle' cannot reach the initial grasp: its tip is" in \
        by_field["fingers[1].initial_q"] and "mm from the object" in \
        by_field["fingers[1].initial_q"]
    assert "ring_j2 = 2 is above its limit 1.709 by 0.291" in by_field["fingers[2].initial_q"]


def test_overlapping_fingertips_are_refused() -> None:
    # two fingers that are the same finger: their tips coincide
    fingers = (URDF.fingers[0], URDF.fingers[0])
    errs = _errors(lambda: fingertips_from_joints(fingers, (NOMINAL_Q[0], NOMINAL_Q[0]), BALL,
                                                  POSE, ("a", "b"), WHERE[:2]))
    assert errs == [("fingers[1].initial_q", "fingers 'a' and 'b': their tips overlap by "
                                             "24 mm")]


def test_tip_names_are_the_hands() -> None:
    assert URDF.tip_names == TIP_NAMES == MJCF.tip_names


# -- how far a grasp can turn the ball: rolling reach and the grasp search ------------------

def test_the_rolled_motion_has_no_slip_no_spin_and_equal_arcs_on_ball_and_tip() -> None:
    """A finger's motion as rolling without slip or spin fixes it (4 rows on 4 joint
    rates) while the ball turns: over a small turn, by finite differences of Pinocchio's
    poses, the tip's material point at the contact moves with the ball's and the tip turns
    about the contact normal as the ball does; over the whole motion the contact's path is
    as long on the ball as on the cap, and the motion stops within the joint limits."""
    f, q0 = URDF.fingers[0], np.asarray(NOMINAL_Q[0])
    c, axis = np.asarray(NOMINAL_OBJECT_POSITION), np.array([0.0, 0.0, -1.0])
    d = 1e-3
    step = roll(f, q0, c, NOMINAL_RADIUS, axis, max_turn=d)
    assert step.reach == pytest.approx(d) and step.why == ""
    s0 = tip_state(f, q0, c, NOMINAL_RADIUS)
    R0, p0 = f.fingertip_pose_pin(q0)
    R1, p1 = f.fingertip_pose_pin(step.q)
    K = np.array([[0, 1, 0], [-1, 0, 0], [0, 0, 0]], dtype=float)  # [axis]x, axis -z
    Rb = np.eye(3) + math.sin(d) * K + (1 - math.cos(d)) * K @ K
    moved = NOMINAL_RADIUS * d  # the ball's surface point moves about this far
    tip_point = p1 + R1 @ R0.T @ (s0.contact - p0)
    assert np.linalg.norm(tip_point - (c + Rb @ (s0.contact - c))) < 1e-2 * moved
    dR = R1 @ R0.T  # the tip's rotation: about the normal as much as the ball's
    spin = 0.5 * np.array([dR[2, 1] - dR[1, 2], dR[0, 2] - dR[2, 0], dR[1, 0] - dR[0, 1]])
    assert float(spin @ s0.n) == pytest.approx(d * float(axis @ s0.n), abs=1e-2 * d)
    whole = roll(f, q0, c, NOMINAL_RADIUS, axis)
    assert 0 < whole.reach < math.pi and whole.why
    assert whole.tip_arc == pytest.approx(whole.ball_arc, rel=1e-3)
    assert np.all(whole.q >= f.lower) and np.all(whole.q <= f.upper)


def test_a_searched_grasp_turns_the_ball_beyond_the_nominal_grasps_reach() -> None:
    """The grasp search (initial contacts near the nominal ones, each finger's rolled
    motion about the axis) finds a grasp whose rolled reach about the palm's z exceeds the
    nominal grasp's; a turn between the two reaches, which the nominal grasp cannot make
    by rolling, is planned from the searched grasp (its tips' charts centred on its
    contacts): solved and certified, every joint within its limits."""
    c, axis = np.asarray(NOMINAL_OBJECT_POSITION), np.array([0.0, 0.0, 1.0])
    nominal = min(roll(f, q, c, NOMINAL_RADIUS, axis).reach
                  for f, q in zip(URDF.fingers, NOMINAL_Q, strict=True))
    found = search_grasp(URDF.fingers, NOMINAL_Q, c, NOMINAL_RADIUS, axis,
                         max_turn=math.radians(45.0), samples=10, seed=0)
    assert found.reach > nominal + math.radians(10.0)
    assert tips_gap(URDF.fingers, found.q) >= 1e-3
    hand = load_whole_hand(urdf_text(), "urdf", [TipSpec(n, side=s) for n, s in zip(
        TIP_NAMES, contact_sides(URDF.fingers, found.q, c, NOMINAL_RADIUS), strict=True)])
    tips = fingertips_from_joints(hand.fingers, tuple(tuple(q) for q in found.q), BALL, POSE,
                                  NAMES, WHERE)
    angle = (nominal + found.reach) / 2
    problem = ManipulationProblem(
        BALL, tips, 2.0, initial_pose=POSE,
        motion=DesiredMotion.from_steps(POSE, [MotionStep(2.0, tuple(axis), angle)]),
        tracking=Tracking(position_tolerance=1e-3, orientation_tolerance=math.radians(1.0)),
        n_intervals=20, options=SolverOptions(time_limit=900.0))  # no wall-clock verdict
    plan = ManipulationPlanner().solve(problem)
    assert plan.status is Status.SOLVED, plan.message
    assert plan.certificate.passed
    for tip, finger in zip(problem.fingers, plan.fingers, strict=True):
        assert np.all(finger.q >= tip.finger.lower - 1e-6)
        assert np.all(finger.q <= tip.finger.upper + 1e-6)
