"""Executing a plan on the user's own MJCF model (issue 24, item 4: ``sim/user_model.py``)
with ``examples/own_hand.xml`` (ours, in the Menagerie's style: position actuators of
kp 10 N m/rad, joint damping 1, inertials, absent meshes). No plan is solved here: a
grasp held still (the built-in hand's nominal joints, the ball where they touch it) is
executed for a short time. Laws: the scene keeps the file's masses, joints and actuators;
at the reference each position servo's force is the feed-forward torque (the model's
gravity and passive forces plus the grip's J^T f) and a motor's is the same through its
PD; what the scene changes of the contact settings is what MuJoCo's mixing rules give;
a plan needing more torque than the actuators give is reported with the numbers."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

mujoco = pytest.importorskip("mujoco")

from ocp.robots.allegro import NOMINAL_OBJECT_POSITION, NOMINAL_Q, NOMINAL_RADIUS  # noqa: E402
from ocp.robots.grasp_reach import tip_state  # noqa: E402
from ocp.robots.whole_hand import TipSpec, load_whole_hand  # noqa: E402
from sim import (  # noqa: E402
    ContactSpec,
    ExecutionPlan,
    FingerReference,
    FingerSpec,
    JointSpec,
    ObjectSpec,
    SimOptions,
    TipShape,
)
from sim.user_model import OBJECT, UserModel, UserModelSimulation  # noqa: E402

OWN = (Path(__file__).resolve().parents[1] / "examples" / "own_hand.xml").read_text()
TIPS = ("ff_tip", "mf_tip", "rf_tip", "th_tip")
NAMES = ("ff", "mf", "rf", "th")


def held_plan(duration: float = 0.1) -> ExecutionPlan:
    """The nominal grasp held still: every finger's joints constant, the ball where the
    tips touch it (the contacts and normals from the hand's own kinematics)."""
    hand = load_whole_hand(OWN, "mjcf", [TipSpec(t) for t in TIPS])
    t = np.array([0.0, duration])
    fingers, refs, contacts = [], [], []
    for name, f, q in zip(NAMES, hand.fingers, NOMINAL_Q, strict=True):
        s = tip_state(f, q, NOMINAL_OBJECT_POSITION, NOMINAL_RADIUS)
        joints = tuple(JointSpec(n, "revolute", (0.0, 1.0, 0.0), np.eye(3), np.zeros(3))
                       for n in f.joint_names)
        fingers.append(FingerSpec(name, joints, np.eye(3), np.zeros(3), np.eye(3),
                                  np.zeros(3), TipShape("sphere", (0.012,)), name))
        refs.append(FingerReference(np.tile(q, (2, 1)), np.zeros((2, 4))))
        contacts.append(ContactSpec(name, "finger", name, np.tile(s.contact, (2, 1)),
                                    np.tile(s.n, (2, 1))))
    return ExecutionPlan(t, ObjectSpec("sphere", (NOMINAL_RADIUS,), 0.05),
                         np.tile(NOMINAL_OBJECT_POSITION, (2, 1)),
                         np.tile([1.0, 0, 0, 0], (2, 1)), tuple(fingers), tuple(refs),
                         tuple(contacts), None, 0.5)


def _file_model() -> Any:
    import xml.etree.ElementTree as ET

    from ocp.robots.mjcf_frames import strip_files

    root = ET.fromstring(OWN)
    for parent in list(root.iter()):
        for el in list(parent):
            if el.tag == "geom" and "mesh" in el.attrib:
                parent.remove(el)
    strip_files(root, inert=True)
    return mujoco.MjModel.from_xml_string(ET.tostring(root, encoding="unicode"))


def test_the_scene_is_the_files_bodies_joints_and_actuators() -> None:
    sim = UserModelSimulation(held_plan(), UserModel(OWN, TIPS))
    m, f = sim.model, _file_model()
    obj = sim.object_body
    for b in range(1, f.nbody):
        name = mujoco.mj_id2name(f, mujoco.mjtObj.mjOBJ_BODY, b)
        sb = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, name)
        assert m.body_mass[sb] == pytest.approx(f.body_mass[b])
    assert m.nu == f.nu == 16
    assert np.allclose(m.actuator_gainprm[:, 0], f.actuator_gainprm[:, 0])
    assert np.allclose(m.actuator_forcerange, f.actuator_forcerange)
    assert np.allclose(m.dof_damping[:16], f.dof_damping)
    assert m.body_mass[obj] == pytest.approx(0.05)
    s = sim.settings
    assert len(s["meshes_removed"]) == OWN.count(' mesh="')  # every mesh geom
    assert s["file_timestep"] == 0.002 and s["timestep"] == SimOptions().timestep
    assert {d["kind"] for d in s["drive"]} == {"affine"}
    assert all(d["kp"] == 10.0 for d in s["drive"])


@pytest.mark.parametrize("inertia", ["auto", "false"])
def test_the_object_weighs_the_plans_mass_whatever_the_files_compiler_says(
        inertia: str) -> None:
    """A file's ``<compiler inertiafromgeom="false">`` (bodies weigh only what their
    ``<inertial>`` says) does not reach the object: it weighs the plan's mass with the
    inertia of its uniform solid, as MuJoCo gives a geom of that mass (before, 1e-6 kg:
    MuJoCo's boundmass, and the run blew up)."""
    text = OWN.replace("<compiler ", f'<compiler inertiafromgeom="{inertia}" ', 1)
    assert f'inertiafromgeom="{inertia}"' in text
    m = UserModelSimulation(held_plan(), UserModel(text, TIPS)).model
    obj = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, OBJECT)
    assert m.body_mass[obj] == pytest.approx(0.05, rel=1e-12)
    ball = 2.0 / 5.0 * 0.05 * NOMINAL_RADIUS ** 2  # a uniform ball's moments
    assert np.allclose(m.body_inertia[obj], ball, rtol=1e-9)


@pytest.mark.parametrize("condim", [3, 4])
def test_the_contact_settings_reported_are_mujocos_mix(condim: int) -> None:
    sim = UserModelSimulation(held_plan(), UserModel(OWN, TIPS), SimOptions(condim=condim))
    m = sim.model
    og = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, OBJECT)
    for t in sim.settings["fingertip_contacts"]:
        g = t["geom_id"]
        assert t["with_object"]["condim"] == max(m.geom_condim[g], m.geom_condim[og])
        assert np.allclose(t["with_object"]["friction"],
                           np.maximum(m.geom_friction[g], m.geom_friction[og]))
        assert np.allclose(t["with_object"]["solref"], m.geom_solref[g], atol=1e-6)
        # the file's tips are condim 3: only a condim above it differs
        assert t["differs"] == ([] if condim == 3 else ["condim"])
    assert len(sim.settings["fingertip_contacts"]) == 4


@pytest.mark.parametrize("kind", ["position", "motor"])
def test_at_the_reference_each_actuator_gives_the_feedforward_torque(kind: str) -> None:
    text = OWN if kind == "position" else OWN.replace(
        '<position kp="10" inheritrange="1"', '<motor').replace("<position ", "<motor ")
    sim = UserModelSimulation(held_plan(), UserModel(text, TIPS),
                              SimOptions(settle=0.0, squeeze=0.0))
    _, torques, _ = sim._feedforward()
    m, d = sim.model, mujoco.MjData(sim.model)
    for joints, ref in zip(sim.joints, sim.plan.references, strict=True):
        for k, j in enumerate(joints):
            d.qpos[j.qpos] = ref.q[0, k]
    d.qpos[sim.object_qpos:sim.object_qpos + 3] = 10.0
    for joints, ref, tau in zip(sim.joints, sim.plan.references, torques, strict=True):
        for k, j in enumerate(joints):
            if j.kind == "affine":
                d.ctrl[j.actuator] = (tau[0, k] + j.Kp * ref.q[0, k] - j.gear * j.b0) / (
                    j.gear * j.gain)
            else:  # at the reference the PD adds nothing
                d.ctrl[j.actuator] = (tau[0, k] - j.gear * j.b0) / (j.gear * j.gain)
    mujoco.mj_forward(m, d)
    for joints, tau in zip(sim.joints, torques, strict=True):
        for k, j in enumerate(joints):
            lo, hi = m.actuator_forcerange[j.actuator]
            assert d.qfrc_actuator[j.dof] == pytest.approx(np.clip(tau[0, k], lo, hi),
                                                           abs=1e-9)
    # the feed-forward holds the hand still against gravity and its springs and pushes
    # each tip into the ball: with no ball, the tips accelerate toward where it was
    assert np.all(np.isfinite(d.qacc))


def test_a_plan_needing_more_torque_than_the_actuators_give_says_so() -> None:
    weak = OWN.replace('forcerange="-0.7 0.7"', 'forcerange="-0.01 0.01"')
    report = UserModelSimulation(held_plan(0.05), UserModel(weak, TIPS),
                                 SimOptions(settle=0.02)).run()
    short = [n for n in report.notes if "the plan needs up to" in n]
    assert short and "its actuator gives -0.01..0.01 N m" in short[0]
    torque = report.model["torque"]  # type: ignore[index]
    assert all(e["torque_range"] == [-0.01, 0.01] for e in torque)
    assert any(e["saturated_fraction"] > 0 for e in torque)
    assert "model" in report.to_dict() and "torque" in report.summary()


def test_the_requests_hand_names_each_fingers_tip_and_mount() -> None:
    from dexroll_client.models import ManipulationRequest
    from planner_service.execution import NotExecutableError, user_model

    body: dict[str, Any] = {
        "planner": "manipulation", "object": {"shape": "sphere", "dimensions": [0.03]},
        "hand": {"mjcf": OWN, "tips": [{"name": t} for t in TIPS],
                 "mount": {"position": [0.0, 0.0, 0.01], "rotation": [0.0, 0.0, 0.1]}},
        "fingers": [{"hand_finger": 3}, {"hand_finger": 1}],
        "initial_pose": {"position": [0.03, 0.0, 0.07]}, "duration": 1.0}
    request = ManipulationRequest.model_validate(body)
    plan = held_plan()
    two = ExecutionPlan(plan.t, plan.object, plan.object_position, plan.object_wxyz,
                        plan.fingers[:2], plan.references[:2], plan.contacts[:2], None, 0.5)
    got = user_model(request, two)
    assert got.tips == ("th_tip", "mf_tip") and got.text == OWN
    assert np.allclose(got.mount_position, [0.0, 0.0, 0.01])
    assert np.allclose(got.mount_rotation[:2, :2], [[np.cos(0.1), -np.sin(0.1)],
                                                    [np.sin(0.1), np.cos(0.1)]])
    with pytest.raises(NotExecutableError):
        user_model(request, plan)  # 2 fingers asked, 4 planned


def test_links_whose_mass_came_from_their_meshes_are_refused_naming_them() -> None:
    """The Menagerie's style of mass: no ``<inertial>``, the links' mass from their visual
    meshes' volume (here: a density on the meshes' class, collision geoms of mass 0). The
    scene never reads mesh files, so those links would weigh nothing: refused, naming each
    body and the option; with ``model_link_mass`` each is given that mass (reported)."""
    import re

    text = re.sub(r"\s*<inertial [^>]*/>", "", OWN)
    text = text.replace('<default class="visual"><geom type="mesh"',
                        '<default class="visual"><geom type="mesh" density="800"')
    text = text.replace('<geom group="3" type="box"', '<geom group="3" type="box" mass="0"')
    with pytest.raises(ValueError) as exc:
        UserModelSimulation(held_plan(), UserModel(text, TIPS))
    reason = str(exc.value)
    for body in ("ff_proximal", "mf_medial", "rf_distal", "th_base"):
        assert body in reason
    assert "model_link_mass" in reason and "mesh" in reason
    sim = UserModelSimulation(held_plan(), UserModel(text, TIPS),
                              SimOptions(model_link_mass=0.02))
    m = sim.model
    b = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "ff_proximal")
    assert m.body_mass[b] == pytest.approx(0.02)
    assert "th_base" in sim.settings["links_given_mass"]["bodies"]


@pytest.mark.parametrize("solimp", ["0.9 0.95 0.001 0.5 2", "0.95 0.99 0.002 0.5 2"])
def test_the_contact_depth_is_mujocos_own_at_rest(solimp: str) -> None:
    """A 50 g ball resting on a fixed round tip under gravity: MuJoCo's settled depth is
    :func:`sim.soft_contact.contact_depth` of its weight, the file's solref and solimp (what
    the fingertips' set points are pressed in by for a plan's forces)."""
    from sim.soft_contact import contact_depth

    xml = f"""<mujoco><option timestep="0.0005" cone="elliptic"/>
      <worldbody>
        <body name="tip"><geom type="sphere" size="0.012" solref="0.02 1"
                               solimp="{solimp}"/></body>
        <body name="ball" pos="0 0 0.042"><freejoint/>
          <geom type="sphere" size="0.03" mass="0.05" solref="0.02 1" solimp="{solimp}"/>
        </body>
      </worldbody></mujoco>"""
    m = mujoco.MjModel.from_xml_string(xml)
    d = mujoco.MjData(m)
    for _ in range(6000):
        mujoco.mj_step(m, d)
    assert d.ncon == 1
    depth = -float(d.contact[0].dist)
    ball = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "ball")
    tip = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "tip")
    want = contact_depth(m, tip, ball, 0.05 * 9.81, (0.02, 1.0),
                         [float(x) for x in solimp.split()])
    assert depth > 1e-5
    assert want == pytest.approx(depth, rel=0.02)


def test_the_files_couplings_of_planned_joints_are_said() -> None:
    """A plan made without the file's couplings (on a copy without them) executed on the
    file: the report says which tendons constrain the joints the plan moves and how far
    the plan's joints leave each (a plan on the file itself keeps them:
    tests/test_couplings.py)."""
    text = OWN.replace("<actuator>", """<tendon>
      <fixed name="ff_couple" limited="true" range="-0.001 0.001">
        <joint joint="ffj2" coef="0.01"/><joint joint="ffj3" coef="-0.01"/>
      </fixed>
      <fixed name="ff_limit" limited="true" range="-0.01 0.01">
        <joint joint="ffj0" coef="0.02"/>
      </fixed>
    </tendon>
    <actuator>""", 1)
    plan = held_plan()
    sim = UserModelSimulation(plan, UserModel(text, TIPS))
    (said,) = sim.settings["couplings"]
    ff = next(k for k, f in enumerate(plan.fingers) if f.name == "ff")
    tendon = 0.01 * plan.references[ff].q[:, 2] - 0.01 * plan.references[ff].q[:, 3]
    over = float(np.max(np.maximum(tendon - 0.001, -0.001 - tendon)))
    assert over > 1e-6  # the held plan does not keep it
    assert said == ("tendon 'ff_couple' (ffj2, ffj3) limited to -0.001..0.001: the plan "
                    f"leaves it by {over:.3g} at worst")
    report = sim.run()
    assert any("the file couples joints the plan moves" in n and "ff_couple" in n
               for n in report.notes)


def test_a_files_soft_friction_creep_is_said_with_what_would_hold_it() -> None:
    """The held grasp executed for 2 s on the file without the noslip solver and with
    impratio 1: the report says how far each fingertip that carries a friction force
    creeps (MuJoCo's R f / B, tests/test_soft_friction.py) and names the noslip solver;
    on the file as shipped (noslip_iterations 5) nothing is said."""
    plan = held_plan(2.0)
    soft = OWN.replace('<option cone="elliptic" impratio="10" noslip_iterations="5"/>',
                       '<option cone="elliptic"/>')
    assert soft != OWN
    report = UserModelSimulation(plan, UserModel(soft, TIPS)).run()
    said = [n for n in report.notes if "the file's soft friction lets it creep" in n]
    assert said and all("noslip_iterations=\"5\"" in n and "impratio 1," in n for n in said)
    report = UserModelSimulation(plan, UserModel(OWN, TIPS)).run()
    assert not [n for n in report.notes if "creep" in n]
