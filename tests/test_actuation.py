"""The hand file's actuator commands (issue 37, item 1: ``ocp/robots/actuation.py``), on
``examples/own_hand.xml`` (ours, the Menagerie's style: position servos of kp 10 inheriting
the joint ranges, force range 0.7 N m, joint damping 1, armature, inertials) and variants
of it with motors and geared general actuators.

Laws: each actuator, commanded the control stated, gives (by MuJoCo's own actuator model
at the planned joints and rates) the torque stated; the torques stated make MuJoCo's model
of the hand follow the plan's accelerations exactly, given the plan's own torques as
MuJoCo's weight of the links; a torque beyond a joint's limit or a control beyond its range
is named with the joint, the value and the limit; a URDF's joints are motors limited by
their effort."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from helpers import nominal_turn

mujoco = pytest.importorskip("mujoco")

from ocp.robots.actuation import HandActuation  # noqa: E402
from ocp.robots.allegro import NOMINAL_Q, load_allegro  # noqa: E402
from ocp.robots.mjcf_frames import mujoco_text  # noqa: E402

OWN = (Path(__file__).resolve().parents[1] / "examples" / "own_hand.xml").read_text()
MOTORS = OWN.replace('<position kp="10" inheritrange="1" forcerange="-0.7 0.7"/>',
                     '<motor ctrlrange="-7 7" gear="0.1"/>').replace("<position ",
                                                                        "<motor ")
GEARED = OWN.replace('<position kp="10" inheritrange="1" forcerange="-0.7 0.7"/>',
                     '<general gaintype="fixed" biastype="affine" gainprm="4" '
                     'biasprm="0.1 -4 -0.2" gear="2.5" forcerange="-1 1"/>') \
    .replace("<position ", "<general ")


def _names(m) -> list[str]:
    return [mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j) for j in range(m.njnt)]


def _samples(m, n=5, seed=0):
    rng = np.random.default_rng(seed)
    lo, hi = m.jnt_range[:, 0], m.jnt_range[:, 1]
    q = lo + (0.2 + 0.6 * rng.random((n, m.njnt))) * (hi - lo)
    return q, rng.normal(0.0, 0.5, q.shape), rng.normal(0.0, 3.0, q.shape), \
        rng.normal(0.0, 0.05, q.shape)


@pytest.mark.parametrize("text", [OWN, MOTORS, GEARED], ids=["position", "motor", "general"])
def test_each_actuator_commanded_gives_the_torque_stated(text: str) -> None:
    act = HandActuation(text)
    m = act.model()
    assert m.nu == 16
    names = _names(m)
    q, qd, qdd, tau_plan = _samples(m)
    got = act.commands(names, np.arange(len(q)), q, qd, qdd, tau_plan)
    assert {a.kind for a in got.actuators} == ({"motor"} if text is MOTORS else {"servo"})
    d = mujoco.MjData(m)
    for i in range(len(q)):
        d.qpos[:], d.qvel[:] = q[i], qd[i]
        d.ctrl[:] = [got.controls[i, names.index(
            mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, int(m.actuator_trnid[a, 0])))]
            for a in range(m.nu)]
        saved = m.actuator_forcerange.copy(), m.actuator_ctrlrange.copy()
        # the force itself, before its range (or the control's) clips it
        m.actuator_forcerange[:] = (-1e9, 1e9)
        m.actuator_ctrlrange[:] = (-1e9, 1e9)
        mujoco.mj_forward(m, d)
        m.actuator_forcerange[:], m.actuator_ctrlrange[:] = saved
        assert np.allclose(d.qfrc_actuator, got.needed[i], atol=1e-9)


def test_the_torques_stated_make_the_plans_accelerations() -> None:
    """Every joint planned, the plan's torques MuJoCo's weight of the links: applied as
    the joints' forces, MuJoCo's forward dynamics give the plan's accelerations."""
    act = HandActuation(OWN)
    m = act.model()
    # links crossing each other, and the servos pulling toward a zero control: left out
    m.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONTACT) | \
        int(mujoco.mjtDisableBit.mjDSBL_ACTUATION)
    names = _names(m)
    q, qd, qdd, _ = _samples(m, seed=1)
    d = mujoco.MjData(m)
    weight = np.zeros_like(q)
    for i in range(len(q)):
        d.qpos[:], d.qvel[:] = q[i], 0.0
        mujoco.mj_forward(m, d)
        weight[i] = d.qfrc_bias
    got = act.commands(names, np.arange(len(q)), q, qd, qdd, weight)
    for i in range(len(q)):
        d.qpos[:], d.qvel[:] = q[i], qd[i]
        d.ctrl[:] = 0.0
        d.qfrc_applied[:] = got.needed[i]
        mujoco.mj_forward(m, d)
        assert np.allclose(d.qacc, qdd[i], atol=1e-6)


def test_a_servo_is_commanded_its_set_point_offset_by_its_stiffness() -> None:
    act = HandActuation(OWN)
    m = act.model()
    names = _names(m)
    q = np.tile(m.qpos0, (2, 1))
    tau = np.full_like(q, 0.3)
    got = act.commands(names, [0.0, 1.0], q, np.zeros_like(q), None, tau)
    # at rest and with the links' weight left out: q + (0.3 - weight terms) / kp; the
    # weight terms are zero at rest without a plan torque for them, so q + 0.3 / 10
    assert np.allclose(got.controls, q + got.needed / 10.0)
    assert np.allclose(got.needed, 0.3)


def test_limits_are_named_with_the_joint_the_torque_and_the_range() -> None:
    act = HandActuation(OWN)
    m = act.model()
    names = _names(m)
    q = np.tile(np.clip(m.qpos0, m.jnt_range[:, 0], m.jnt_range[:, 1]), (3, 1))
    tau = np.zeros_like(q)
    tau[1, names.index("mfj2")] = 1.14
    got = act.commands(names, [0.0, 1.0, 2.0], q, np.zeros_like(q), None, tau)
    share, j, k = got.load()
    assert names[j] == "mfj2" and k == 1 and share == pytest.approx(1.14 / 0.7)
    why = got.refusals()
    assert any("joint mfj2 needs 1.14 N m at t = 1 s; its actuator mfa2 gives "
               "-0.7..0.7 N m" in r for r in why), why
    # a servo whose set point would leave its control range (the joint's: inheritrange)
    q2 = q.copy()
    q2[:, names.index("ffj1")] = m.jnt_range[names.index("ffj1"), 0]
    tau2 = np.zeros_like(q)
    tau2[:, names.index("ffj1")] = -0.05
    why = act.commands(names, [0.0, 1.0, 2.0], q2, np.zeros_like(q), None, tau2).refusals()
    assert any("actuator ffa1 (joint ffj1)" in r and "outside its ctrlrange" in r
               for r in why), why
    within = act.commands(names, [0.0, 1.0, 2.0], q, np.zeros_like(q), None,
                          np.zeros_like(q))
    assert within.refusals() == []


def test_a_urdf_hands_joints_are_motors_limited_by_their_effort() -> None:
    hand = load_allegro("urdf")
    act = hand.actuation()
    names = [n for f in hand.fingers for n in f.joint_names]
    q = np.concatenate(NOMINAL_Q)[None]
    tau = np.full_like(q, 0.5)
    got = act.commands(names, [0.0], q, np.zeros_like(q), None, tau)
    assert all(a.kind == "motor" and a.torque_range == (-1.0, 1.0) for a in got.actuators)
    assert np.allclose(got.controls, 0.5) and got.load()[0] == pytest.approx(0.5)


def test_the_file_is_compiled_as_mujoco_reads_it() -> None:
    """The servos' ranges are MuJoCo's (degrees in the file, ``inheritrange``)."""
    act = HandActuation(OWN)
    acts, notes = act.actuators(["ffj1"])
    m = mujoco.MjModel.from_xml_string(mujoco_text(OWN))
    j = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, "ffj1")
    assert acts[0].ctrl_range == pytest.approx(tuple(m.jnt_range[j]))
    assert acts[0].name == "ffa1" and acts[0].gain == 10.0 and notes == ()


def test_the_force_stages_torque_rows_are_the_plans_joint_torques_and_bound_them(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """The force stage's torque rows (ocp.transcription.force_stage): at a planned roll's
    collocation points they are its fingers' joint torques (J^T of the planned forces and
    torsions, exactly); bounded at those torques the stage finds forces within them; bounded
    below what any forces holding the ball ask, it finds none (and the planner falls back
    to the coupled NLP, whose plan the actuator check then refuses)."""
    import dataclasses
    import json
    from pathlib import Path

    import ocp.transcription.force_stage as fs
    from ocp.solve.planner import ManipulationPlanner
    from planner_service.planners import REQUEST
    from planner_service.planners.cache import FingerCache
    from planner_service.planners.manipulation import manipulation_problem

    seen: dict = {}
    solve = fs.ForceStage.solve

    def watched(self, Xall, prm, load, L, guess, torques=None):  # type: ignore[no-untyped-def]
        seen.update(stage=self, args=(Xall, prm, load, L, guess))
        return solve(self, Xall, prm, load, L, guess, torques)

    monkeypatch.setattr(fs.ForceStage, "solve", watched)
    body = json.loads((Path(__file__).resolve().parents[1] / "examples" /
                       "allegro_turn.json").read_text())
    body["forces"] = {"mass": 0.05, "min_normal_force": 2.0}
    problem = dataclasses.replace(manipulation_problem(REQUEST.validate_python(body),
                                                       FingerCache()), actuation=None)
    free = ManipulationPlanner().solve(problem)
    assert free.status.value == "solved", free.message
    stage, (Xall, prm, load, L, guess) = seen["stage"], seen["args"]
    F, _ = solve(stage, Xall, prm, load, L, guess)
    assert F is not None
    tq = stage.torque_params(Xall, prm, problem.forces.gravity)
    k, nc = len(Xall), stage.m.n_contacts
    _, P, N, R, _ = stage.m.mapped("path", k)(Xall.T, prm)
    n_tau = sum(int(t.finger.nq) for _, t in stage.tips)
    rows = np.array([np.asarray(stage._point(
        F[:, i], np.asarray(P).reshape(3 * nc, k, order="F")[:, i],
        np.asarray(N).reshape(3 * nc, k, order="F")[:, i],
        np.asarray(R).reshape(9, k, order="F")[:, i], load, L, tq[:, i])[0]).ravel()[-n_tau:]
        for i in range(k)])
    plan = np.hstack([f.joint_torques for f in free.fingers])  # nodes and midpoints in turn
    n = (k + 1) // 2
    assert np.abs(rows[:n] - plan[0::2]).max() < 1e-12
    assert np.abs(rows[n:] - plan[1::2]).max() < 1e-12
    top = np.abs(rows).max(axis=0) + 1e-9
    G, _ = solve(stage, Xall, prm, load, L, guess, (tq, -top, top))
    assert G is not None
    G, _ = solve(stage, Xall, prm, load, L, guess, (tq, -0.1 * top, 0.1 * top))
    assert G is None


def _roll_request(**hand: Any) -> Any:
    from planner_service.planners import REQUEST

    return REQUEST.validate_python(nominal_turn(
        OWN, ["ff_tip", "mf_tip", "rf_tip", "th_tip"], hand=hand, forces={"mass": 0.05},
        n_intervals=10))


def test_the_requests_torque_limits_are_the_actuators() -> None:
    """``hand.torque_limits``: a joint's actuator given 0.01 N m (the file says 0.7) makes
    the roll infeasible naming it; a name that is no joint of the fingers is a 422 naming
    it under the field."""
    from planner_service.planners import ProblemError, solve

    result, _ = solve(_roll_request(torque_limits={"ffj2": 0.01}))
    assert result.status.value == "infeasible", result.message
    assert "joint ffj2 needs" in result.message
    assert "its actuator ffa2 gives -0.01..0.01 N m" in result.message
    acts = {a.joint: a for a in result.actuator_trajectory.actuators}
    assert acts["ffj2"].torque_range == [-0.01, 0.01]
    assert acts["ffj1"].torque_range == [-0.7, 0.7]  # the file's
    with pytest.raises(ProblemError) as exc:
        solve(_roll_request(torque_limits={"wrist": 1.0}))
    fields = dict(exc.value.errors)
    assert "'wrist' is not a joint of the hand's fingers" in fields["hand.torque_limits.wrist"]


def test_a_servos_torque_range_at_a_joint_position_is_what_its_ctrlrange_reaches() -> None:
    """A position servo whose set point must stay in its ctrlrange gives, at joint
    position q, kp (c_lo - q) .. kp (c_hi - q) (within its forcerange): MuJoCo's own
    actuator force at the two ends of the control range. Near the range's end a gait's
    holds and swings keep to it (the swing slowed while its joints' damping asks more)."""
    import mujoco

    from ocp.gait.step import TorqueLimits
    from ocp.robots.actuation import HandActuation, torque_bounds_at

    act = HandActuation(OWN)
    names = ["ffj1", "ffj2"]
    m = act.model()
    d = mujoco.MjData(m)
    (a1, a2), _ = act.actuators(names)
    for q in (-0.19, 0.0, 0.9, 1.6):
        lo, hi = a1.range_at(q)
        jid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, "ffj1")
        aid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, a1.name)
        ends = []
        for c in m.actuator_ctrlrange[aid]:
            d.qpos[:] = 0.0
            d.qpos[m.jnt_qposadr[jid]] = q
            d.qvel[:] = 0.0
            d.ctrl[:] = 0.0
            d.ctrl[aid] = c
            mujoco.mj_forward(m, d)
            ends.append(float(d.actuator_force[aid]))
        assert lo == pytest.approx(min(ends), abs=1e-12)
        assert hi == pytest.approx(max(ends), abs=1e-12)
    q_lo = float(m.actuator_ctrlrange[aid, 0])
    lo, hi = torque_bounds_at(act, names, [[q_lo, 0.5]], 0.9)
    assert lo[0, 0] == 0.0 and hi[0, 0] > 0  # at the range's end: nothing further down
    assert (lo[0, 1], hi[0, 1]) == pytest.approx((-0.63, 0.63))  # its forcerange, x 0.9
    limits = TorqueLimits((np.full(2, -0.63),), (np.full(2, 0.63),), np.zeros(3), (),
                          0.9, ((a1, a2),), (np.ones(2),))
    q = np.array([[q_lo + 0.02, 0.5]])
    v = np.array([[-0.1, 0.0]])  # toward the end at 0.1 rad/s against damping 1
    assert limits.damping_overrun(0, q, v) == pytest.approx(0.1 / (0.9 * 10 * 0.02))
