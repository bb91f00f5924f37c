"""A hand of the Shadow hand's structure (issue 37, item 3), written here in the style of
the Gym robotics hand files: two wrist joints that carry every finger, fingers of four
joints (J3 spreads, J2-J0 flex) whose J1 and J0 a limited fixed tendon couples, fixed
tendons over one joint that limit it, a default class with a joint type no body uses,
position servos of kp 1.

Laws: the wrist joints, shared by all fingers, are held (not planned) and said so; a
tendon over one joint is that joint's limit, as MuJoCo reads it; a coupling tendon is a
coupling of its finger's joints (tests/test_couplings.py plans with them); an unused
default class's joint type refuses nothing."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from helpers import nominal_turn, wrist_wrapped

mujoco = pytest.importorskip("mujoco")

from ocp.robots.whole_hand import TipSpec, load_whole_hand  # noqa: E402

FINGERS = (("ff", 0.033), ("mf", 0.011), ("rf", -0.011))


def _finger(name: str, y: float) -> str:
    p = name.upper()
    return f"""
        <body name="{name}_knuckle" pos="0 {y} 0.095">
          <joint name="{p}J3" axis="0 -1 0" range="-0.349 0.349" class="hand"/>
          <geom type="capsule" size="0.008" fromto="0 0 0 0 0 0.045" class="col"/>
          <body name="{name}_proximal" pos="0 0 0">
            <joint name="{p}J2" axis="1 0 0" range="0 1.571" class="hand"/>
            <geom type="capsule" size="0.008" fromto="0 0 0.005 0 0 0.04" class="col"/>
            <body name="{name}_middle" pos="0 0 0.045">
              <joint name="{p}J1" axis="1 0 0" range="0 1.571" class="hand"/>
              <geom type="capsule" size="0.007" fromto="0 0 0.003 0 0 0.022" class="col"/>
              <body name="{name}_distal" pos="0 0 0.025">
                <joint name="{p}J0" axis="1 0 0" range="0 1.571" class="hand"/>
                <body name="{name}_tip" pos="0 0 0.012">
                  <geom name="{name}_tip" type="capsule" size="0.009 0.006" class="col"/>
                </body>
              </body>
            </body>
          </body>
        </body>"""


def hand_text(couplings: bool = True) -> str:
    fingers = "".join(_finger(n, y) for n, y in FINGERS)
    coupled = "".join(f"""
    <fixed name="T_{n.upper()}J1c" limited="true" range="-0.001 0.001">
      <joint joint="{n.upper()}J0" coef="0.00705"/>
      <joint joint="{n.upper()}J1" coef="-0.00805"/>
    </fixed>""" for n, _ in FINGERS) if couplings else ""
    limits = "".join(f"""
    <fixed name="T_{n.upper()}J3r" limited="true" range="-0.0034 0.0034">
      <joint joint="{n.upper()}J3" coef="0.01"/>
    </fixed>""" for n, _ in FINGERS)
    return f"""<mujoco model="wrist_hand">
  <compiler angle="radian"/>
  <default>
    <default class="hand">
      <joint damping="0.05" armature="0.0001" limited="true"/>
      <position kp="1" ctrllimited="true"/>
    </default>
    <default class="col"><geom condim="4" friction="1 0.005 0.001"/></default>
    <default class="unused"><joint type="ball"/></default>
  </default>
  <worldbody>
    <body name="forearm" pos="0 0 0">
      <geom type="box" size="0.02 0.02 0.02" pos="0 0 -0.05" class="col"/>
      <body name="wrist" pos="0 0 0">
        <joint name="WRJ1" axis="0 1 0" range="-0.489 0.14" class="hand"/>
        <inertial pos="0 0 0.01" mass="0.1" diaginertia="1e-4 1e-4 1e-4"/>
        <body name="palm" pos="0 0 0.034">
          <joint name="WRJ0" axis="1 0 0" range="-0.698 0.489" class="hand"/>
          <inertial pos="0 0 0.04" mass="0.3" diaginertia="1e-3 1e-3 1e-3"/>
          <geom type="box" size="0.011 0.032 0.045" pos="0 0 0.045" class="col"/>{fingers}
        </body>
      </body>
    </body>
  </worldbody>
  <tendon>{coupled}{limits}
  </tendon>
  <actuator>
    <position name="A_WRJ1" joint="WRJ1" class="hand" ctrlrange="-0.489 0.14"/>
    <position name="A_WRJ0" joint="WRJ0" class="hand" ctrlrange="-0.698 0.489"/>
  </actuator>
</mujoco>"""


TIPS = [TipSpec(f"{n}_tip") for n, _ in FINGERS]


def test_coupling_tendons_are_read_as_couplings_of_their_fingers() -> None:
    """Each finger's T_J1c (its J0 and J1 within 1 mm of tendon of each other) is a
    coupling of that finger's joints, in the file's names and MuJoCo's numbers; the
    unused default class's joint type refuses nothing."""
    hand = load_whole_hand(hand_text(), "mjcf", TIPS)
    for (n, _), f in zip(FINGERS, hand.fingers, strict=True):
        p = n.upper()
        (c,) = f.couplings
        assert c.name == f"tendon 'T_{p}J1c'"
        assert c.joints == (f"{p}J0", f"{p}J1") and c.coefs == (0.00705, -0.00805)
        assert (c.lower, c.upper) == (-0.001, 0.001)
        assert "0.00705 " + p + "J0 + -0.00805 " + p + "J1 in -0.001..0.001" in c.describe()


def test_shared_wrist_joints_are_held_and_single_joint_tendons_are_limits() -> None:
    hand = load_whole_hand(hand_text(couplings=False), "mjcf", TIPS)
    assert hand.held == {"WRJ1": 0.0, "WRJ0": 0.0}
    for (n, _), f in zip(FINGERS, hand.fingers, strict=True):
        p = n.upper()
        assert f.joint_names == (f"{p}J3", f"{p}J2", f"{p}J1", f"{p}J0")
        # the tendon's range over its coefficient: +-0.34 rad, inside the joint's +-0.349
        assert f.lower[0] == pytest.approx(-0.34) and f.upper[0] == pytest.approx(0.34)
        assert f.lower[1] == 0.0 and f.upper[1] == pytest.approx(1.571)
    # the fingers' kinematics are MuJoCo's with the wrist at its held angles
    m = mujoco.MjModel.from_xml_string(hand_text(couplings=False))
    d = mujoco.MjData(m)
    rng = np.random.default_rng(3)
    for f in hand.fingers:
        q = f.lower + rng.random(4) * (f.upper - f.lower)
        d.qpos[:] = 0.0
        for name, v in zip(f.joint_names, q, strict=True):
            d.qpos[m.jnt_qposadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, name)]] = v
        mujoco.mj_kinematics(m, d)
        _, p = f.fingertip_pose_pin(q)
        tip = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, f.tip_frame)
        assert np.linalg.norm(p - d.xpos[tip]) < 1e-9
    notes = hand.actuation().commands(list(hand.fingers[0].joint_names), [0.0],
                                      np.zeros((1, 4)), np.zeros((1, 4)), None, None).notes
    assert any("held (not planned): WRJ1 at 0, WRJ0 at 0" in n for n in notes), notes


def test_a_wrist_mounted_hand_is_planned_with_its_wrist_held_and_executed() -> None:
    """The wrist-wrapped own_hand.xml: loads without edits, the wrist held at 0 (said in
    the actuator notes), the spread joint limited by its tendon as MuJoCo reads it
    (0.4 rad), and a turn of the nominal grasp planned, certified and executed on the
    file's own actuators (the wrist's servos holding it) within 1 mm and 2 deg."""
    from planner_service.execution import simulate_result
    from planner_service.planners import REQUEST, solve

    text = wrist_wrapped((Path(__file__).resolve().parents[1] / "examples" /
                          "own_hand.xml").read_text())
    tips = [TipSpec(t) for t in ("ff_tip", "mf_tip", "rf_tip", "th_tip")]
    hand = load_whole_hand(text, "mjcf", tips)
    assert hand.held == {"WRJ1": 0.0, "WRJ0": 0.0}
    assert hand.fingers[0].joint_names == ("ffj0", "ffj1", "ffj2", "ffj3")
    assert hand.fingers[0].upper[0] == pytest.approx(0.4)
    req = REQUEST.validate_python(nominal_turn(
        text, [t.name for t in tips], angle=0.2, duration=2.0,
        forces={"mass": 0.05, "min_normal_force": 1.0}, n_intervals=16))
    result, _ = solve(req)
    assert result.status.value == "solved", result.message
    assert "WRJ1" not in result.joint_trajectory.joint_names
    assert any("held (not planned): WRJ1 at 0, WRJ0 at 0" in n
               for n in result.actuator_trajectory.notes)
    report = simulate_result(result, req, model="request")
    assert report.passed, report.failures
