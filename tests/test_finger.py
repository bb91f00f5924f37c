"""Laws of the finger model: CasADi kinematics = Pinocchio's, the built-in finger's design,
inverse kinematics, user URDFs."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from helpers import assert_close

from ocp.robots.finger import (
    PAD_HALF_SIZE,
    PAPER_SEED,
    FingerModel,
    builtin_urdf_text,
    inverse_kinematics,
    inverse_kinematics_batch,
    load_finger,
)

RHO = 0.025  # ball radius of the paper's experiment 1 [m]
R_TOP = np.diag([1.0, -1.0, -1.0])  # pad normal down, pad x along the palm's +x


@pytest.fixture(scope="module")
def finger() -> FingerModel:
    return load_finger()


def random_q(f: FingerModel, rng: np.random.Generator) -> np.ndarray:
    return rng.uniform(f.lower, f.upper)


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    return np.asarray(pin.exp3(rng.normal(size=3)))


def top_grasp(x: float, y: float, tilt: float = 0.0, azimuth: float = 0.0
              ) -> tuple[np.ndarray, np.ndarray]:
    """Pad pose touching the ball lying at palm point (x, y) where its outward normal is
    tilted by ``tilt`` [rad] from +z towards ``azimuth`` [rad]: the pad normal is the
    opposite of the ball's, the pad centre on the ball."""
    n = np.array([np.sin(tilt) * np.cos(azimuth), np.sin(tilt) * np.sin(azimuth),
                  np.cos(tilt)])
    axis = np.cross([0.0, 0.0, 1.0], n)
    R_tilt = np.asarray(pin.exp3(axis / np.linalg.norm(axis) * tilt)) if tilt else np.eye(3)
    return R_tilt @ R_TOP, np.array([x, y, RHO]) + RHO * n


def fd_jacobian(f: FingerModel, q: np.ndarray, h: float = 1e-6) -> np.ndarray:
    """Central differences of the CasADi fk: (dp/dq; vee(dR/dq R^T))."""
    R0 = np.asarray(f.fk(q)[0])
    cols = []
    for i in range(f.nq):
        dq = np.zeros(f.nq)
        dq[i] = h
        Rp, pp = (np.asarray(a) for a in f.fk(q + dq))
        Rm, pm = (np.asarray(a) for a in f.fk(q - dq))
        S = (Rp - Rm) / (2 * h) @ R0.T
        w = 0.5 * np.array([S[2, 1] - S[1, 2], S[0, 2] - S[2, 0], S[1, 0] - S[0, 1]])
        cols.append(np.concatenate([(pp - pm).reshape(3) / (2 * h), w]))
    return np.array(cols).T


# -- CasADi kinematics = Pinocchio's ----------------------------------------------------------


def test_casadi_fk_equals_pinocchio_forward_kinematics_at_random_configurations() -> None:
    rng = np.random.default_rng(1)
    for base in (None, random_rotation(rng)):
        f = load_finger(base_rotation=base, base_position=None if base is None
                        else rng.normal(scale=0.05, size=3))
        for _ in range(50):
            q = random_q(f, rng)
            R, p = f.fk(q)
            R_pin, p_pin = f.fingertip_pose_pin(q)
            assert_close(R, R_pin, atol=1e-12, err_msg=f"R at q={q}")
            assert_close(p, p_pin, atol=1e-12, err_msg=f"p at q={q}")


def test_fk_is_named_q_to_rotation_and_position() -> None:
    f = load_finger()
    assert f.fk.name() == "fingertip_pose"
    assert f.fk.name_in() == ["q"]
    assert f.fk.name_out() == ["R", "p"]
    assert f.jacobian.name_out() == ["J"]


def test_casadi_jacobian_and_finite_differences_equal_pinocchio_frame_jacobian() -> None:
    rng = np.random.default_rng(2)
    f = load_finger(base_rotation=random_rotation(rng), base_position=[0.01, -0.02, 0.03])
    for _ in range(20):
        q = random_q(f, rng)
        J_pin = f.frame_jacobian_pin(q)
        assert J_pin.shape == (6, 6)
        assert_close(f.jacobian(q), J_pin, atol=1e-12, err_msg=f"CasADi J at q={q}")
        assert_close(fd_jacobian(f, q), J_pin, atol=1e-8, err_msg=f"FD J at q={q}")


def test_pinocchio_pose_is_the_urdf_pose_composed_with_the_base_mount() -> None:
    rng = np.random.default_rng(3)
    Rb, pb = random_rotation(rng), rng.normal(scale=0.1, size=3)
    mounted = load_finger(base_rotation=Rb, base_position=pb)
    bare = load_finger(base_rotation=np.eye(3), base_position=np.zeros(3))
    q = random_q(bare, rng)
    R0, p0 = bare.fingertip_pose_pin(q)
    R1, p1 = mounted.fingertip_pose_pin(q)
    assert_close(R1, Rb @ R0, atol=1e-14)
    assert_close(p1, Rb @ p0 + pb, atol=1e-14)
    assert_close(mounted.base_pose[:3, :3], Rb, atol=0.0)
    assert_close(mounted.base_pose[:3, 3], pb, atol=0.0)


# -- the built-in finger ----------------------------------------------------------------------


def test_builtin_finger_has_six_limited_revolute_joints_and_a_fingertip_frame(
        finger: FingerModel) -> None:
    assert finger.nq == 6
    assert [j.kind for j in finger.chain] == ["revolute"] * 6
    assert finger.tip_frame == "fingertip"
    assert finger.model.frames[finger.tip_frame_id].name == "fingertip"
    assert np.all(np.isfinite(finger.lower)) and np.all(np.isfinite(finger.upper))
    assert np.all(finger.lower < 0.0) and np.all(finger.upper > 0.0)
    assert np.all(np.isfinite(finger.velocity_limit)) and np.all(finger.velocity_limit > 0.0)
    assert finger.pad_half_size == PAD_HALF_SIZE
    assert finger.urdf_text == builtin_urdf_text()
    assert finger.within_limits(PAPER_SEED, margin=np.deg2rad(10.0))


def test_pad_size_in_python_is_the_urdf_pad_with_its_surface_at_the_tip_frame() -> None:
    root = ET.fromstring(builtin_urdf_text())
    (link,) = [e for e in root.iter("link") if e.get("name") == "fingertip"]
    box = link.find("collision/geometry/box")
    origin = link.find("collision/origin")
    assert box is not None and origin is not None
    sx, sy, sz = (float(s) for s in box.get("size", "").split())
    assert (sx, sy) == (2 * PAD_HALF_SIZE, 2 * PAD_HALF_SIZE)
    xyz = [float(s) for s in origin.get("xyz", "").split()]
    assert_close(xyz, [0.0, 0.0, -sz / 2], atol=1e-15)  # the pad's outer face is z = 0


def test_paper_seed_is_a_configuration_within_the_limits_facing_the_palm(
        finger: FingerModel) -> None:
    """The paper's initial joint angles seed the IK of the initial grasp: they are a valid
    configuration whose pad faces down towards the palm, above it."""
    assert finger.within_limits(PAPER_SEED)
    R, p = finger.fingertip_pose_pin(PAPER_SEED)
    assert R[2, 2] < -0.9 and p[2] > 0.0


# -- inverse kinematics -----------------------------------------------------------------------


def test_ik_recovers_reachable_poses_from_nearby_seeds(finger: FingerModel) -> None:
    rng = np.random.default_rng(4)
    for _ in range(30):
        q_true = random_q(finger, rng)
        R_t, p_t = finger.fingertip_pose_pin(q_true)
        seed = np.clip(q_true + rng.normal(scale=0.1, size=finger.nq),
                       finger.lower, finger.upper)
        res = inverse_kinematics(finger, R_t, p_t, seed)
        assert res.converged, res
        assert res.position_error < 1e-9 and res.orientation_error < 1e-9, res
        assert res.within_limits and finger.within_limits(res.q)
        R, p = finger.fk(res.q)
        assert_close(R, R_t, atol=1e-9)
        assert_close(p, p_t, atol=1e-9)


@pytest.mark.parametrize("xy", [(0.0, 0.0), (0.03, 0.0), (0.03, 0.03)])
def test_ik_from_paper_seed_reaches_the_antipodal_grasp_at_each_triangle_corner(
        finger: FingerModel, xy: tuple[float, float]) -> None:
    R_t, p_t = top_grasp(*xy)
    assert_close(p_t, [xy[0], xy[1], 2 * RHO], atol=1e-15)
    res = inverse_kinematics(finger, R_t, p_t, PAPER_SEED)
    assert res.converged and res.within_limits, res
    assert res.position_error < 1e-9 and res.orientation_error < 1e-9
    R, p = finger.fk(res.q)
    assert_close(np.asarray(R)[:, 2], [0.0, 0.0, -1.0], atol=1e-9, err_msg="pad faces down")
    assert_close(p, p_t, atol=1e-9)
    assert finger.within_limits(res.q, margin=np.deg2rad(20.0))


@pytest.mark.parametrize("azimuth_deg", [0.0, 90.0, 180.0, 270.0])
def test_ik_from_paper_seed_reaches_a_grasp_tilted_20deg_from_antipodal(
        finger: FingerModel, azimuth_deg: float) -> None:
    R_t, p_t = top_grasp(0.0, 0.0, np.deg2rad(20.0), np.deg2rad(azimuth_deg))
    res = inverse_kinematics(finger, R_t, p_t, PAPER_SEED)
    assert res.converged and res.within_limits, res
    assert res.position_error < 1e-9 and res.orientation_error < 1e-9
    R, p = finger.fingertip_pose_pin(res.q)
    normal_of_ball = (p - np.array([0.0, 0.0, RHO])) / RHO
    assert_close(R[:, 2], -normal_of_ball, atol=1e-9, err_msg="pad tangent to the ball")
    assert_close(np.degrees(np.arccos(-R[2, 2])), 20.0, atol=1e-6)


def test_ik_of_an_unreachable_target_reports_failure_without_raising(
        finger: FingerModel) -> None:
    res = inverse_kinematics(finger, R_TOP, [1.0, 0.0, 0.05], PAPER_SEED)
    assert not res.converged
    assert res.position_error > 0.5
    assert res.within_limits


def test_batched_ik_reaches_nearby_poses_by_pinocchio_and_flags_the_unreachable(
        finger: FingerModel) -> None:
    """Poses along a motion (configurations drifting from a seed) and one pose out of reach:
    the batched IK puts the pad on every reachable pose (checked with Pinocchio's forward
    kinematics) inside the limits, and reports the unreachable one as not converged."""
    rng = np.random.default_rng(11)
    q_seed = random_q(finger, rng)
    qs = np.clip(q_seed + np.cumsum(rng.normal(scale=0.02, size=(20, finger.nq)), axis=0),
                 finger.lower, finger.upper)
    poses = [finger.fingertip_pose_pin(q) for q in qs]
    R_t = np.array([R for R, _ in poses] + [R_TOP])
    p_t = np.array([p for _, p in poses] + [[1.0, 0.0, 0.05]])
    q, ok = inverse_kinematics_batch(finger, R_t, p_t, q_seed, tol=1e-10)
    assert ok[:-1].all() and not ok[-1]
    assert np.all(q >= finger.lower) and np.all(q <= finger.upper)
    for k in range(len(poses)):
        R, p = finger.fingertip_pose_pin(q[k])
        assert_close(p, p_t[k], atol=1e-10)
        assert_close(R, R_t[k], atol=1e-9)


def test_ik_is_deterministic(finger: FingerModel) -> None:
    R_t, p_t = top_grasp(0.02, 0.01, np.deg2rad(25.0), 1.0)
    a = inverse_kinematics(finger, R_t, p_t, PAPER_SEED)
    b = inverse_kinematics(finger, R_t, p_t, PAPER_SEED)
    assert np.array_equal(a.q, b.q) and a.iterations == b.iterations


# -- user URDFs -------------------------------------------------------------------------------

USER_URDF = """<?xml version="1.0"?>
<robot name="tiny">
  <link name="root"/><link name="a"/><link name="b"/><link name="c"/><link name="pad"/>
  <joint name="q1" type="revolute">
    <parent link="root"/><child link="a"/>
    <origin xyz="0 0 0.02" rpy="0.1 -0.2 0.3"/><axis xyz="0 0.6 -0.8"/>
    <limit lower="-2" upper="2" velocity="1.5" effort="1"/>
  </joint>
  <joint name="q2" type="prismatic">
    <parent link="a"/><child link="b"/>
    <origin xyz="0.03 0.01 0" rpy="0 0.4 0"/><axis xyz="1 0 0"/>
    <limit lower="-0.01" upper="0.02" velocity="0.1" effort="1"/>
  </joint>
  <joint name="q3" type="revolute">
    <parent link="b"/><child link="c"/>
    <origin xyz="0.04 0 -0.005" rpy="0 0 0.5"/><axis xyz="0 0 -1"/>
    <limit lower="-1" upper="1" velocity="2" effort="1"/>
  </joint>
  <joint name="pad_joint" type="fixed">
    <parent link="c"/><child link="pad"/><origin xyz="0.01 0 0" rpy="0 1.5707963 0"/>
  </joint>
</robot>
"""


def test_user_urdf_casadi_fk_equals_pinocchio_and_mount_defaults_to_identity(
        tmp_path: Path) -> None:
    path = tmp_path / "tiny.urdf"
    path.write_text(USER_URDF)
    f = load_finger(path, tip_frame="pad", pad_half_size=0.005)
    assert f.nq == 3 and f.joint_names == ("q1", "q2", "q3")
    assert [j.kind for j in f.chain] == ["revolute", "prismatic", "revolute"]
    assert_close(f.velocity_limit, [1.5, 0.1, 2.0], atol=0.0)
    model = pin.buildModelFromUrdf(str(path))
    data = model.createData()
    rng = np.random.default_rng(5)
    for _ in range(20):
        q = random_q(f, rng)
        R, p = f.fk(q)
        pin.framesForwardKinematics(model, data, q)
        M = data.oMf[model.getFrameId("pad")]
        assert_close(R, M.rotation, atol=1e-12)
        assert_close(p, M.translation, atol=1e-12)
        assert_close(f.jacobian(q), f.frame_jacobian_pin(q), atol=1e-12)


def test_user_urdf_given_as_text_is_the_same_finger_as_from_its_file(tmp_path: Path) -> None:
    path = tmp_path / "tiny.urdf"
    path.write_text(USER_URDF)
    from_file = load_finger(path, tip_frame="pad")
    from_text = load_finger(USER_URDF, tip_frame="pad")
    assert from_text.urdf_text == from_file.urdf_text == USER_URDF
    q = np.array([0.3, 0.01, -0.4])
    for a, b in zip(from_text.fk(q), from_file.fk(q), strict=True):
        assert_close(a, b, atol=0.0)


def test_unknown_tip_frame_raises_value_error_naming_it(tmp_path: Path) -> None:
    path = tmp_path / "tiny.urdf"
    path.write_text(USER_URDF)
    with pytest.raises(ValueError, match="no_such_tip"):
        load_finger(path, tip_frame="no_such_tip")


def test_unsupported_joint_raises_value_error_naming_it(tmp_path: Path) -> None:
    path = tmp_path / "continuous.urdf"
    path.write_text(USER_URDF.replace('name="q3" type="revolute"', 'name="q3" type="continuous"'))
    with pytest.raises(ValueError, match="q3"):
        load_finger(path, tip_frame="pad")


def test_branching_urdf_raises_value_error(tmp_path: Path) -> None:
    branch = """  <link name="side"/>
  <joint name="side_joint" type="revolute">
    <parent link="a"/><child link="side"/><axis xyz="1 0 0"/>
    <limit lower="-1" upper="1" velocity="1" effort="1"/>
  </joint>
</robot>"""
    path = tmp_path / "branch.urdf"
    path.write_text(USER_URDF.replace("</robot>", branch))
    with pytest.raises(ValueError, match="serial"):
        load_finger(path, tip_frame="pad")
