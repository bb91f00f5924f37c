"""Laws of the built-in hands: fingers cut from a hand's URDF tree are the built-in finger on
its mount, the nominal grasp holds the ball, reconfigured mounts move the fingers rigidly."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
import pinocchio as pin
import pytest
from helpers import assert_close

from ocp.robots.finger import (
    PAD_HALF_SIZE,
    FingerModel,
    _reduce_to_tip_chain,
    builtin_urdf_text,
    inverse_kinematics,
    load_finger,
)
from ocp.robots.hands import (
    HAND_NAMES,
    NOMINAL_SEED,
    Hand,
    builtin_hand_urdf_text,
    default_mounts,
    grasp_ik,
    grasp_poses,
    load_hand,
    reach_sweep,
    sweep_cases,
)

N_FINGERS = {"two_finger": 2, "three_finger": 3}


@pytest.fixture(scope="module", params=HAND_NAMES)
def hand(request: pytest.FixtureRequest) -> Hand:
    return load_hand(request.param)


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    return np.asarray(pin.exp3(rng.normal(size=3)))


def homogeneous(R: np.ndarray, p: np.ndarray) -> np.ndarray:
    g = np.eye(4)
    g[:3, :3] = R
    g[:3, 3] = np.asarray(p).reshape(3)
    return g


def fk_pose(f: FingerModel, q: np.ndarray) -> np.ndarray:
    R, p = f.fk(q)
    return homogeneous(np.asarray(R), np.asarray(p))


def margin(f: FingerModel, q: np.ndarray) -> float:
    return float(np.min(np.minimum(q - f.lower, f.upper - q)))


# -- the hands and their fingers --------------------------------------------------------------


def test_default_hand_is_the_three_finger_hand() -> None:
    assert load_hand().name == "three_finger"
    assert set(HAND_NAMES) == set(N_FINGERS)


def test_each_hand_has_its_fingers_named_by_prefix_and_six_revolute_joints(hand: Hand) -> None:
    n = N_FINGERS[hand.name]
    assert hand.n_fingers == len(hand.fingers) == len(hand.tip_frames) == n
    assert len(hand.mounts) == len(hand.contact_azimuths) == n
    assert hand.tip_frames == tuple(f"f{k}_fingertip" for k in range(1, n + 1))
    bare = load_finger()
    for k, f in enumerate(hand.fingers, start=1):
        assert f.tip_frame == f"f{k}_fingertip"
        assert f.model.frames[f.tip_frame_id].name == f.tip_frame
        assert f.nq == 6 and [j.kind for j in f.chain] == ["revolute"] * 6
        assert f.joint_names == tuple(f"f{k}_{name}" for name in bare.joint_names)
        assert f.urdf_text == hand.urdf_text
        assert_close(f.base_pose, np.eye(4), atol=0.0, err_msg="the URDF root is the palm")
        assert_close(f.lower, bare.lower, atol=0.0)
        assert_close(f.upper, bare.upper, atol=0.0)
        assert_close(f.velocity_limit, bare.velocity_limit, atol=0.0)
        assert f.pad_half_size == hand.pad_half_size


def test_casadi_fk_of_each_finger_is_its_tip_in_the_full_hand_model(hand: Hand) -> None:
    """Cutting a finger out of the tree (locking the other fingers) moved nothing."""
    model = pin.buildModelFromXML(hand.urdf_text)
    data = model.createData()
    assert model.nq == 6 * hand.n_fingers
    rng = np.random.default_rng(11)
    for _ in range(20):
        q_full = rng.uniform(model.lowerPositionLimit, model.upperPositionLimit)
        pin.framesForwardKinematics(model, data, q_full)
        for f in hand.fingers:
            q = np.array([q_full[model.joints[model.getJointId(name)].idx_q]
                          for name in f.joint_names])
            M = data.oMf[model.getFrameId(f.tip_frame)]
            R, p = f.fk(q)
            assert_close(R, M.rotation, atol=1e-12, err_msg=f"{f.tip_frame} R")
            assert_close(p, M.translation, atol=1e-12, err_msg=f"{f.tip_frame} p")
            assert_close(f.jacobian(q), f.frame_jacobian_pin(q), atol=1e-12)


def test_each_finger_is_the_builtin_finger_on_its_mount(hand: Hand) -> None:
    rng = np.random.default_rng(12)
    for f, (R_m, p_m), (R_d, p_d) in zip(hand.fingers, hand.mounts,
                                          default_mounts(hand.name), strict=True):
        assert_close(R_m, R_d, atol=1e-14)
        assert_close(p_m, p_d, atol=1e-14)
        single = load_finger(base_rotation=R_m, base_position=p_m)
        for _ in range(10):
            q = rng.uniform(f.lower, f.upper)
            assert_close(fk_pose(f, q), fk_pose(single, q), atol=1e-12)


def test_the_hand_urdf_is_the_builtin_finger_copied_under_each_prefix(hand: Hand) -> None:
    finger = ET.fromstring(builtin_urdf_text())
    root = ET.fromstring(builtin_hand_urdf_text(hand.name))
    links = {e.get("name"): e for e in root.iter("link")}
    joints = {e.get("name"): e for e in root.iter("joint")}
    n = hand.n_fingers
    n_links, n_joints = len(finger.findall("link")), len(finger.findall("joint"))
    assert len(links) == 1 + n * n_links and len(joints) == n * (n_joints + 1)
    assert "palm" in links
    for k in range(1, n + 1):
        pre = f"f{k}_"
        mount = joints[pre + "mount"]
        assert mount.get("type") == "fixed"
        parent, child = mount.find("parent"), mount.find("child")
        assert parent is not None and child is not None
        assert (parent.get("link"), child.get("link")) == ("palm", pre + "finger_base")
        for j in finger.iter("joint"):
            jh = joints[pre + j.get("name", "")]
            assert jh.get("type") == j.get("type")
            for tag in ("parent", "child"):
                a, b = jh.find(tag), j.find(tag)
                assert a is not None and b is not None
                assert a.get("link") == pre + b.get("link", "")
            for tag in ("origin", "axis", "limit"):
                a, b = jh.find(tag), j.find(tag)
                assert (a is None) == (b is None), (jh.get("name"), tag)
                if a is not None and b is not None:
                    assert a.attrib == b.attrib, (jh.get("name"), tag)
        pad = links[pre + "fingertip"]
        for tag in ("visual", "collision"):
            box = pad.find(f"{tag}/geometry/box")
            origin = pad.find(f"{tag}/origin")
            assert box is not None and origin is not None
            sx, sy, sz = (float(s) for s in box.get("size", "").split())
            assert (sx, sy) == (2 * hand.pad_half_size, 2 * hand.pad_half_size)
            assert_close([float(s) for s in origin.get("xyz", "").split()], [0, 0, -sz / 2],
                         atol=1e-15, err_msg="the pad's outer face is the tip frame's z = 0")


def test_pad_size_is_the_fingers_unless_three_pads_would_overlap() -> None:
    """Three tangent square pads 120 deg apart meet rho tan(60 deg) from each contact."""
    assert load_hand("two_finger").pad_half_size == PAD_HALF_SIZE
    three = load_hand("three_finger")
    assert three.pad_half_size < three.nominal_radius * np.tan(np.deg2rad(60.0))


# -- the nominal grasp ------------------------------------------------------------------------


def test_nominal_grasp_pads_touch_the_ball_with_normals_through_its_centre(
        hand: Hand) -> None:
    assert hand.nominal_q is not None
    c = np.asarray(hand.nominal_object_position)
    rho = hand.nominal_radius
    assert 0.06 <= c[2] <= 0.1, "the ball is in the air, above the palm"
    assert_close(c[:2], 0.0, atol=0.0)
    for f, q, (R_t, p_t) in zip(hand.fingers, hand.nominal_q, grasp_poses(hand), strict=True):
        outward = (p_t - c) / rho
        assert_close(np.linalg.norm(p_t - c), rho, atol=1e-15, err_msg="on the ball")
        assert_close(R_t[:, 2], -outward, atol=1e-15, err_msg="pad normal to the centre")
        assert_close(outward[2], 0.0, atol=1e-15, err_msg="contact on the equator")
        assert_close(R_t[:, 0], [0.0, 0.0, 1.0], atol=1e-15, err_msg="pad x axis up")
        R, p = f.fk(np.asarray(q))  # the fingers are there (IK tolerance 1e-10 m, rad)
        assert_close(R, R_t, atol=1e-9)
        assert_close(p, p_t, atol=1e-9)


def test_two_finger_grasp_is_antipodal_along_x() -> None:
    hand = load_hand("two_finger")
    (R1, p1), (R2, p2) = grasp_poses(hand)
    c = np.asarray(hand.nominal_object_position)
    assert_close(R1[:, 2], -R2[:, 2], atol=1e-15, err_msg="opposite normals")
    assert_close(np.cross(p1 - p2, R1[:, 2]), 0.0, atol=1e-15, err_msg="on one line")
    assert_close((p1 + p2) / 2, c, atol=1e-15)
    assert_close(R1[:, 2], [-1.0, 0.0, 0.0], atol=1e-15, err_msg="finger 1 presses at +x")


def test_three_finger_contacts_are_120deg_apart_on_the_equator() -> None:
    hand = load_hand("three_finger")
    c = np.asarray(hand.nominal_object_position)
    u = [(p - c) / hand.nominal_radius for _, p in grasp_poses(hand)]
    for a in range(3):
        for b in range(a + 1, 3):
            assert_close(u[a] @ u[b], np.cos(np.deg2rad(120.0)), atol=1e-15)
    assert_close(sum(u), 0.0, atol=1e-15)
    assert_close(np.cross(u[0], u[1]) @ [0.0, 0.0, 1.0], np.sin(np.deg2rad(120.0)),
                 atol=1e-15, err_msg="f1, f2, f3 counterclockwise")


def test_ik_of_the_nominal_grasp_converges_well_inside_the_limits(hand: Hand) -> None:
    for f, res in zip(hand.fingers, grasp_ik(hand, seeds=[NOMINAL_SEED] * hand.n_fingers),
                      strict=True):
        assert res.converged and res.within_limits, res
        assert margin(f, res.q) >= np.deg2rad(20.0), np.degrees(res.q)
    assert hand.nominal_q is not None
    for q, res in zip(hand.nominal_q, grasp_ik(hand), strict=True):
        assert_close(res.q, q, atol=1e-12, err_msg="seeded by nominal_q, IK stays there")


def test_grasp_poses_move_rigidly_with_the_ball(hand: Hand) -> None:
    rng = np.random.default_rng(13)
    Rb, c = random_rotation(rng), rng.normal(scale=0.05, size=3)
    nominal = grasp_poses(hand)
    c0 = np.asarray(hand.nominal_object_position)
    g = homogeneous(Rb, c) @ np.linalg.inv(homogeneous(np.eye(3), c0))
    for (R0, p0), (R, p) in zip(nominal, grasp_poses(hand, c, rotation=Rb), strict=True):
        assert_close(homogeneous(R, p), g @ homogeneous(R0, p0), atol=1e-14)
    rho = 0.5 * hand.nominal_radius
    for R, p in grasp_poses(hand, c, rho, Rb):
        assert_close(R[:, 2], -(p - c) / rho, atol=1e-14, err_msg="tangent to a smaller ball")


def test_every_finger_reaches_the_sweep_of_rotated_and_moved_balls(hand: Hand) -> None:
    """The design claim of ocp.robots.hands: +-30 deg about any axis, +-10 mm, all in reach."""
    sweeps = reach_sweep(hand)
    assert len(sweeps) == hand.n_fingers
    for s in sweeps:
        assert s.tried == len(sweep_cases()) and s.reached == s.tried, s.finger
        assert s.min_margin > 0.0
        assert s.reached_with_margin(np.deg2rad(20.0)) >= 0.9 * s.tried


def test_a_sweep_without_displacement_stays_at_the_nominal_grasp() -> None:
    hand = load_hand("two_finger")
    assert hand.nominal_q is not None
    for s, f, q in zip(reach_sweep(hand, max_angle_deg=0.0, max_shift=0.0, steps=1),
                       hand.fingers, hand.nominal_q, strict=True):
        assert s.reached == s.tried
        assert_close(s.margins, margin(f, np.asarray(q)), atol=1e-9)


# -- reconfigured mounts ----------------------------------------------------------------------


@pytest.mark.parametrize("name", HAND_NAMES)
def test_new_mounts_move_each_tip_by_exactly_the_mount_change(name: str) -> None:
    rng = np.random.default_rng(14)
    base = load_hand(name)
    mounts = [(random_rotation(rng), rng.normal(scale=0.1, size=3)) for _ in base.fingers]
    moved = load_hand(name, mounts=mounts)
    assert moved.urdf_text != base.urdf_text
    for f0, f1, (R_new, p_new), (R_old, p_old), (R_rep, p_rep) in zip(
            base.fingers, moved.fingers, mounts, base.mounts, moved.mounts, strict=True):
        assert_close(R_rep, R_new, atol=1e-12)
        assert_close(p_rep, p_new, atol=1e-15)
        change = homogeneous(R_new, p_new) @ np.linalg.inv(homogeneous(R_old, p_old))
        for _ in range(10):
            q = rng.uniform(f0.lower, f0.upper)
            assert_close(fk_pose(f1, q), change @ fk_pose(f0, q), atol=1e-12)
            assert_close(fk_pose(f1, q), fk_pose(load_finger(base_rotation=R_new,
                                                             base_position=p_new), q),
                         atol=1e-12)


def test_default_mounts_given_explicitly_give_the_same_hand(hand: Hand) -> None:
    same = load_hand(hand.name, mounts=hand.mounts)
    assert same.nominal_q is not None and hand.nominal_q is not None
    assert_close(np.array(same.nominal_q), np.array(hand.nominal_q), atol=1e-9)
    q = np.array(hand.nominal_q[0])
    assert_close(fk_pose(same.fingers[0], q), fk_pose(hand.fingers[0], q), atol=1e-14)


def test_mounts_out_of_reach_of_the_nominal_ball_leave_no_nominal_q() -> None:
    far = [(R, p + np.array([0.0, 0.0, 1.0])) for R, p in default_mounts("two_finger")]
    hand = load_hand("two_finger", mounts=far)
    assert hand.nominal_q is None
    assert not all(r.converged for r in grasp_ik(hand))
    with pytest.raises(ValueError, match="nominal grasp"):
        reach_sweep(hand)


# -- errors -----------------------------------------------------------------------------------


def test_unknown_hand_raises_value_error_naming_the_builtin_hands() -> None:
    with pytest.raises(ValueError, match="four_finger") as err:
        load_hand("four_finger")
    for name in HAND_NAMES:
        assert name in str(err.value)
    with pytest.raises(ValueError, match="three_finger"):
        builtin_hand_urdf_text("nope")


@pytest.mark.parametrize(("mounts", "match"), [
    ([(np.eye(3), np.zeros(3))], r"2 fingers.*2 entries, got 1"),
    ([(np.eye(3), np.zeros(3))] * 3, r"2 entries, got 3"),
    ("palm", "sequence"),
    ([(np.eye(3), np.zeros(3)), np.eye(3)], r"mounts\[1\] must be a pair"),
    ([(np.eye(3), np.zeros(3)), (np.eye(3)[:, :2], np.zeros(3))], r"mounts\[1\] rotation"),
    ([(np.diag([1.0, 1.0, -1.0]), np.zeros(3)), (np.eye(3), np.zeros(3))],
     r"mounts\[0\] rotation must be a rotation"),
    ([(np.eye(3), np.zeros(2)), (np.eye(3), np.zeros(3))], r"mounts\[0\] position"),
    ([(np.eye(3), [0.0, np.nan, 0.0]), (np.eye(3), np.zeros(3))], r"mounts\[0\] position"),
])
def test_bad_mounts_raise_value_error_naming_the_problem(mounts: object, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        load_hand("two_finger", mounts=mounts)  # type: ignore[arg-type]


# -- load_finger on trees and serial chains ---------------------------------------------------


def test_a_serial_urdf_is_not_reduced() -> None:
    model = pin.buildModelFromXML(builtin_urdf_text())
    assert _reduce_to_tip_chain(model, int(model.getFrameId("fingertip"))) is model
    f = load_finger()
    assert f.model.nq == model.nq and f.joint_names == tuple(model.names[1:])


TREE_URDF = """<?xml version="1.0"?>
<robot name="tree">
  <link name="root"/><link name="a1"/><link name="a2"/><link name="b1"/><link name="pad_a"/>
  <link name="pad_b"/>
  <joint name="a_q1" type="revolute">
    <parent link="root"/><child link="a1"/>
    <origin xyz="0.01 0 0" rpy="0 0 0.3"/><axis xyz="0 0 1"/>
    <limit lower="-2" upper="2" velocity="1" effort="1"/>
  </joint>
  <joint name="b_q1" type="prismatic">
    <parent link="root"/><child link="b1"/>
    <origin xyz="-0.02 0.01 0" rpy="0.2 0 0"/><axis xyz="1 0 0"/>
    <limit lower="-0.01" upper="0.01" velocity="1" effort="1"/>
  </joint>
  <joint name="a_q2" type="revolute">
    <parent link="a1"/><child link="a2"/>
    <origin xyz="0.03 0 0.01" rpy="0 0.4 0"/><axis xyz="0 1 0"/>
    <limit lower="-1" upper="1" velocity="2" effort="1"/>
  </joint>
  <joint name="a_pad" type="fixed">
    <parent link="a2"/><child link="pad_a"/><origin xyz="0.02 0 0"/>
  </joint>
  <joint name="b_pad" type="fixed">
    <parent link="b1"/><child link="pad_b"/><origin xyz="0 0 0.02" rpy="0 1 0"/>
  </joint>
</robot>
"""


def test_each_branch_of_a_tree_loads_as_its_own_finger() -> None:
    model = pin.buildModelFromXML(TREE_URDF)
    data = model.createData()
    a = load_finger(TREE_URDF, tip_frame="pad_a")
    b = load_finger(TREE_URDF, tip_frame="pad_b")
    assert a.joint_names == ("a_q1", "a_q2") and b.joint_names == ("b_q1",)
    assert [j.kind for j in b.chain] == ["prismatic"]
    assert_close(b.upper, [0.01], atol=0.0)
    rng = np.random.default_rng(15)
    for _ in range(10):
        q_full = rng.uniform(model.lowerPositionLimit, model.upperPositionLimit)
        pin.framesForwardKinematics(model, data, q_full)
        for f in (a, b):
            q = np.array([q_full[model.joints[model.getJointId(n)].idx_q]
                          for n in f.joint_names])
            M = data.oMf[model.getFrameId(f.tip_frame)]
            assert_close(fk_pose(f, q), M.homogeneous, atol=1e-12)


def test_a_tip_frame_inside_a_branch_of_a_tree_is_refused_as_for_a_serial_chain() -> None:
    with pytest.raises(ValueError, match=r"a_q1.*chain ends at joint 'a_q2'"):
        load_finger(TREE_URDF, tip_frame="a1")


def test_a_hand_finger_ik_reaches_random_poses_of_its_own_tip() -> None:
    f = load_hand("three_finger").fingers[2]
    rng = np.random.default_rng(16)
    for _ in range(10):
        q_true = rng.uniform(f.lower, f.upper)
        R_t, p_t = f.fingertip_pose_pin(q_true)
        seed = np.clip(q_true + rng.normal(scale=0.1, size=6), f.lower, f.upper)
        res = inverse_kinematics(f, R_t, p_t, seed)
        assert res.converged and res.within_limits, res
