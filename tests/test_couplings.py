"""Coupled joints planned as constraints (issue 37, item 3; ``ocp/robots/couplings.py``).

The hand is ``examples/own_hand.xml`` with its three fingers' two distal joints coupled in
the Shadow hand's style, written here: a limited fixed tendon ``0.00705 j3 - 0.00805 j2``
within +-1 mm per finger (the distal joint follows the medial one to within 1 mm of
tendon).

Laws: the couplings are read as MuJoCo reads the file; a projection and a Gauss-Newton step
keep them; a rolling plan with a searched grasp keeps every coupling at every returned
sample (the certificate's ``max_coupling_violation_*``, and MuJoCo's own tendon lengths at
the plan's joints) and executes on the file's own actuators, tendons included, within
2 mm and 3 deg; joint angles that break a coupling are refused naming the field, the
tendon and by how much; the execution reports each coupling as the plan keeps it."""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from helpers import nominal_turn, wrist_wrapped

mujoco = pytest.importorskip("mujoco")

from ocp.robots.couplings import (  # noqa: E402
    coupled_step,
    coupling_violation,
    project_couplings,
)
from ocp.robots.mjcf_frames import mujoco_text  # noqa: E402
from ocp.robots.whole_hand import TipSpec, load_whole_hand  # noqa: E402

OWN = (Path(__file__).resolve().parents[1] / "examples" / "own_hand.xml").read_text()
TIPS = ["ff_tip", "mf_tip", "rf_tip", "th_tip"]
COUPLED = ("ff", "mf", "rf")


def coupled_hand(passive: bool = False) -> str:
    """own_hand.xml with each of the three fingers' j3 (distal) coupled to j2 (medial) by
    a limited fixed tendon; ``passive``: their j3 without an actuator (the Shadow hand's
    J0, driven through the coupling alone)."""
    tendons = "".join(f"""
    <fixed name="T_{p}c" limited="true" range="-0.001 0.001">
      <joint joint="{p}j3" coef="0.00705"/>
      <joint joint="{p}j2" coef="-0.00805"/>
    </fixed>""" for p in COUPLED)
    text = OWN.replace("<actuator>", f"<tendon>{tendons}\n  </tendon>\n  <actuator>", 1)
    if passive:
        for p in COUPLED:
            text = re.sub(rf'\s*<position name="{p}a3" joint="{p}j3"[^>]*/>', "", text)
    return text


def test_the_couplings_are_read_and_kept_by_projection_and_steps() -> None:
    hand = load_whole_hand(coupled_hand(), "mjcf", [TipSpec(t) for t in TIPS])
    for p, f in zip((*COUPLED, "th"), hand.fingers, strict=True):
        if p == "th":
            assert f.couplings == ()
            continue
        (c,) = f.couplings
        assert c.name == f"tendon 'T_{p}c'" and (c.lower, c.upper) == (-0.001, 0.001)
        assert np.allclose(c.row(f.joint_names), [0, 0, -0.00805, 0.00705])
    f = hand.fingers[0]
    rng = np.random.default_rng(0)
    a = f.couplings[0].row(f.joint_names)
    for _ in range(50):
        q = f.lower + rng.random(4) * (f.upper - f.lower)
        x = project_couplings(f, q)
        assert coupling_violation(f, x)[0] == 0.0
        assert np.all(x >= f.lower) and np.all(x <= f.upper)
        assert -0.001 < float(a @ x) < 0.001  # backed off, inside the band
        # a step that pushes the coupling out of its band at its bound slides along it
        at = project_couplings(f, q, margin=False)
        dq = rng.normal(size=4) * 0.05
        y = coupled_step(f, at, dq)
        assert coupling_violation(f, y)[0] <= 1e-12


def _plan(text: str, angle_deg: float = 10.0, **extra: object):
    from planner_service.planners import REQUEST, solve

    body = nominal_turn(text, TIPS, angle=math.radians(angle_deg), duration=2.0,
                        forces={"mass": 0.05, "min_normal_force": 1.0}, n_intervals=16,
                        **extra)
    for finger in body["fingers"]:
        finger.pop("initial_q")
    body["grasp"] = "auto"
    req = REQUEST.validate_python(body)
    result, _ = solve(req)
    return req, result


def _tendon_lengths(m: Any, jt: Any) -> np.ndarray:
    """MuJoCo's own tendon lengths (rows: the joint trajectory's points) at the plan's
    joints, the others at qpos0."""
    d = mujoco.MjData(m)
    adr = [int(m.jnt_qposadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, n)])
           for n in jt.joint_names]
    lengths = []
    for point in jt.points:
        d.qpos[:] = m.qpos0
        d.qpos[adr] = point.positions
        mujoco.mj_kinematics(m, d)
        mujoco.mj_tendon(m, d)
        lengths.append(d.ten_length.copy())
    return np.array(lengths)


def test_a_roll_keeps_the_couplings_and_executes_on_the_files_actuators() -> None:
    from planner_service.execution import simulate_result

    text = coupled_hand()
    req, result = _plan(text)
    assert result.status.value == "solved", result.message
    values = result.certificate.values
    for p in COUPLED:
        assert 0.0 <= values[f"max_coupling_violation_{p}"] <= 1e-6
    # MuJoCo's own tendon lengths at the plan's joints: inside their ranges
    m = mujoco.MjModel.from_xml_string(mujoco_text(text))
    L = _tendon_lengths(m, result.joint_trajectory)
    over = np.maximum(m.tendon_range[:, 0] - L, L - m.tendon_range[:, 1])
    assert float(over.max()) <= 1e-6
    assert float(np.ptp(L, axis=0).max()) > 1e-4  # the plan moves within the bands
    report = simulate_result(result, req, model="request")
    assert report.passed, report.failures
    assert report.position_error.max <= 2e-3
    assert report.angle_error.max <= math.radians(3.0)
    said = next(n for n in report.notes if "the file couples joints" in n)
    for p in COUPLED:
        assert f"tendon 'T_{p}c' (" in said
    assert said.count("the plan keeps it") == len(COUPLED)


def test_joint_angles_that_break_a_coupling_are_refused_naming_the_tendon() -> None:
    from ocp.spec.problem import ProblemError
    from planner_service.planners import REQUEST, Planners
    from planner_service.planners.manipulation import manipulation_problem

    body = nominal_turn(coupled_hand(), TIPS)
    q = [0.0, 0.6, 0.2, 1.0]  # 0.00705 - 0.00805 * 0.2 = 5.4 mm of tendon: 4.4 mm out
    body["fingers"][0]["initial_q"] = q
    with pytest.raises(ProblemError) as exc:
        manipulation_problem(REQUEST.validate_python(body), Planners().fingers)
    (field, reason), = [e for e in exc.value.errors if e[0].startswith("fingers[0]")]
    assert field == "fingers[0].initial_q"
    assert "tendon 'T_ffc'" in reason and "outside by 0.0044" in reason


@pytest.mark.parametrize("wrist", [False, True])
def test_a_passive_joint_is_planned_at_its_tendons_bound_and_executed(wrist: bool) -> None:
    """The Shadow hand's J0: the coupled distal joints without actuators (and, the
    Shadow hand's whole structure, the hand carried by two wrist joints). The grasp puts
    each tendon at the bound the fingertip's load pulls it to, the plan keeps it there
    (an equality), the forces keep each passive torque of the sign that bound gives, the
    actuator trajectory takes the tendon's force off the medial joint's actuator, and the
    file's own actuators execute it, the distal joints driven by the tendons alone, within
    2 mm and 3 deg."""
    from planner_service.execution import simulate_result

    text = coupled_hand(passive=True)
    if wrist:
        text = wrist_wrapped(text)
    hand = load_whole_hand(text, "mjcf", [TipSpec(t) for t in TIPS])
    assert hand.held == ({"WRJ1": 0.0, "WRJ0": 0.0} if wrist else {})
    for p, f in zip(COUPLED, hand.fingers[:3], strict=True):
        assert f.couplings[0].passive == (f"{p}j3",)
    req, result = _plan(text)
    assert result.status.value == "solved", result.message
    m = mujoco.MjModel.from_xml_string(mujoco_text(text))
    ids = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_TENDON, f"T_{p}c") for p in COUPLED]
    L = _tendon_lengths(m, result.joint_trajectory)[:, ids]
    r = m.tendon_range[ids]
    at = np.minimum(np.abs(L - r[:, 0]), np.abs(L - r[:, 1]))
    assert float(at.max()) <= 1e-6  # each coupling tendon at one of its bounds throughout
    assert np.all(np.ptp(L, axis=0) <= 1e-6)
    act = result.actuator_trajectory
    names = act.actuators
    for p in COUPLED:
        (said,) = [n for n in act.notes if n.startswith(f"joint {p}j3 has no actuator: its "
                                                        "torque comes from")]
        assert f"tendon 'T_{p}c'" in said
        assert p + "j3" not in [a.joint for a in names if a.actuator]
    report = simulate_result(result, req, model="request")
    assert report.passed, report.failures
    assert report.position_error.max <= 2e-3
    assert report.angle_error.max <= math.radians(3.0)


def test_a_passive_joint_off_its_tendons_bound_or_without_one_is_refused() -> None:
    """The actuators' check: a passive joint whose torque its tendon could give only at a
    bound the plan does not hold it at, and a passive joint without a tendon, are each
    refused naming the joint, the torque, the time and the tendon."""
    hand = load_whole_hand(coupled_hand(passive=True), "mjcf", [TipSpec(t) for t in TIPS])
    act = hand.actuation()
    ff = hand.fingers[0]
    q = np.array([[0.0, 0.5, 0.6, 0.68]])  # tendon 0.00705*0.68 - 0.00805*0.6 = -0.04 mm
    tau = np.array([[0.0, 0.0, 0.0, 0.02]])  # ffj3 flexing: the tendon at its lower bound
    got = act.commands(list(ff.joint_names), [0.5], q, np.zeros((1, 4)), None, tau)
    (why,) = got.refusals()
    assert why.startswith("joint ffj3 has no actuator: its 0.02 N m at t = 0.5 s can come "
                          "only from tendon 'T_ffc' pulling at its lower bound, but the plan "
                          "holds the tendon 0.96")
    # at the bound: carried, the tendon's force taken off ffj2's actuator
    q[0, 3] = (-0.001 + 0.00805 * 0.6) / 0.00705
    got = act.commands(list(ff.joint_names), [0.5], q, np.zeros((1, 4)), None, tau)
    assert got.refusals() == []
    base = act.commands(list(ff.joint_names), [0.5], q, np.zeros((1, 4)), None,
                        np.zeros((1, 4)))
    lam = (got.needed[0, 3] + 0.02 - base.needed[0, 3]) / 0.00705  # the joint's own terms
    assert got.needed[0, 3] == 0.0
    assert got.needed[0, 2] - base.needed[0, 2] == pytest.approx(0.00805 * 0.02 / 0.00705,
                                                                 rel=1e-9)
    assert lam > 0
    # a joint without an actuator and no tendon: its torque has nowhere to come from
    text = re.sub(r'\s*<position name="ffa1" joint="ffj1"[^>]*/>', "", coupled_hand())
    bare = load_whole_hand(text, "mjcf", [TipSpec(t) for t in TIPS])
    got = bare.actuation().commands(list(ff.joint_names), [0.5], q, np.zeros((1, 4)), None,
                                    np.array([[0.0, 0.03, 0.0, 0.0]]))
    assert any(r.startswith("joint ffj1 has no actuator and no coupling to carry its "
                            "torque, but needs") for r in got.refusals())


def test_a_rolled_reach_stops_at_a_couplings_bound_and_the_quick_check_names_it() -> None:
    """A 4-joint finger's rolled motion is fixed by the ball's: where it takes a coupling
    out of its band the roll stops, and the quick reach check refuses a turn beyond it
    naming the tendon (a finger whose coupling is an equality, a passive joint's tendon
    at its bound, is not rolled: it constrains the ball's motion instead)."""
    from dataclasses import replace

    from ocp.robots.allegro import NOMINAL_OBJECT_POSITION, NOMINAL_RADIUS
    from ocp.robots.first_grasp import first_grasp
    from ocp.robots.grasp_reach import roll
    from ocp.robots.turn_reach import Turn, rolls, turn_shortfall

    hand = load_whole_hand(coupled_hand(), "mjcf", [TipSpec(t) for t in TIPS])
    grasp = first_grasp(hand.fingers, NOMINAL_OBJECT_POSITION, NOMINAL_RADIUS)
    f, q = hand.fingers[0], np.asarray(grasp.q[0])
    (c,) = f.couplings
    v = float(c.row(f.joint_names) @ q)
    narrow = f.with_couplings((replace(c, lower=v - 2e-5, upper=v + 2e-5),))
    axis = np.array([0.0, 0.0, 1.0])
    got = roll(narrow, q, NOMINAL_OBJECT_POSITION, NOMINAL_RADIUS, axis, math.radians(30))
    assert got.why == "coupling limit (tendon 'T_ffc')" and got.reach < math.radians(30)
    short = turn_shortfall([narrow], ["ff"], [q], NOMINAL_OBJECT_POSITION, NOMINAL_RADIUS,
                           [Turn(axis, math.radians(60))], 0.0)
    assert short is not None and "its tendon 'T_ffc''s bound" in short.message
    assert rolls(f) and not rolls(f.with_couplings((c.at("lower"),)))
