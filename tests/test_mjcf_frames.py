"""Model files read as their own readers read them (issue 24, item 1): an MJCF's fingertips
where MuJoCo's ``mj_kinematics`` puts them (posed root bodies, degrees and radians,
quaternions, Euler angles in any sequence, axis-angles, default classes, ``childclass``,
sites), a URDF's links where its joint origins put them, and a reading that differs
refused at load naming the body and the distance.

The MJCFs are ours: the Allegro-class hand's table (``ocp/robots/allegro.py``) written in
the style of MuJoCo Menagerie's hands (default classes for joints and geoms, ``childclass``
on the root, mesh geoms whose files are not there, capsule tips in a class, angles in
degrees, the root posed)."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from typing import Any

import numpy as np
import pinocchio as pin
import pytest

from ocp.robots import mjcf_frames
from ocp.robots.allegro import FINGERS, TIP_RADIUS
from ocp.robots.mjcf_frames import (
    build_mjcf,
    mujoco_disagreements,
    mujoco_text,
    orientation_quat,
)
from ocp.robots.urdf_frames import urdf_disagreements, urdf_link_poses
from ocp.robots.whole_hand import HandModelError, TipSpec, WholeHand, load_whole_hand

mujoco = pytest.importorskip("mujoco")

TIPS = ("ff_tip", "mf_tip", "rf_tip", "th_tip")
PARTS = ("base", "proximal", "medial", "distal")


def _v(x: Any) -> str:
    return " ".join(f"{float(c):.9g}" for c in x)


def menagerie_style(root_pose: str = 'quat="0 1 0 1"', compiler: str = "") -> str:
    """Our Allegro-class hand as a Menagerie-style MJCF: the root ``palm`` posed by
    ``root_pose``, joint axes and ranges (degrees unless ``compiler`` says radian) in
    default classes, ``childclass`` on the root, visual mesh geoms (files absent),
    collision capsules in classes, a site on each fingertip."""
    radian = 'angle="radian"' in compiler
    unit = 1.0 if radian else 180 / math.pi
    classes = []
    for f in FINGERS:
        for k, part in enumerate(PARTS):
            lo, hi = f.limits[k]
            classes.append(f'<default class="{f.name}_{part}"><joint axis="{_v(f.axes[k])}" '
                           f'range="{lo * unit:.12g} {hi * unit:.12g}"/></default>')
    body = []
    short = {"index": "ff", "middle": "mf", "ring": "rf", "thumb": "th"}
    for f in FINGERS:
        s = short[f.name]
        opened = 0
        for k, part in enumerate(PARTS):
            pose = (f'pos="{_v(f.base_position)}" quat="{_v(f.base_quaternion)}"' if k == 0
                    else f'pos="{_v(f.offsets[k])}"')
            body += [f'<body name="{s}_{part}" {pose}>',
                     f'<joint name="{s}j{k}" class="{f.name}_{part}"/>',
                     f'<geom class="visual" mesh="link_{k}"/>']
            opened += 1
        body += [f'<body name="{s}_tip">', '<geom class="visual" mesh="tip"/>',
                 f'<geom class="{"thumb" if s == "th" else "finger"}tip_collision"/>',
                 f'<site name="{s}_pad" pos="0 0.005 {f.capsule_centre:.9g}" '
                 'euler="90 0 30"/>' if not radian else
                 f'<site name="{s}_pad" pos="0 0.005 {f.capsule_centre:.9g}" '
                 f'euler="{math.pi / 2} 0 {math.pi / 6}"/>',
                 "</body>"]
        body += ["</body>"] * opened
    th, fi = FINGERS[3], FINGERS[0]
    return f"""<mujoco model="ours_menagerie_style">
  <compiler {compiler} meshdir="assets" autolimits="true"/>
  <default>
    <default class="hand">
      <joint axis="0 1 0" damping="1"/>
      <position kp="10"/>
      <default class="visual"><geom type="mesh" contype="0" conaffinity="0" group="2"/></default>
      <default class="collision"><geom group="3" type="box" mass="0"/>
        <default class="fingertip_collision">
          <geom type="capsule" size="{TIP_RADIUS} {fi.capsule_half_length}"
                pos="0 0 {fi.capsule_centre}"/>
          <default class="thumbtip_collision">
            <geom size="{TIP_RADIUS} {th.capsule_half_length}" pos="0 0 {th.capsule_centre}"/>
          </default>
        </default>
      </default>
      {"".join(classes)}
    </default>
  </default>
  <asset>
    <mesh name="palm" file="palm.stl"/>
    {"".join(f'<mesh name="link_{k}" file="link_{k}.stl"/>' for k in range(4))}
    <mesh name="tip" file="tip.stl"/>
  </asset>
  <worldbody>
    <body name="palm" {root_pose} childclass="hand">
      <geom class="visual" mesh="palm"/>
      {"".join(body)}
    </body>
  </worldbody>
  <actuator>
    {"".join(f'<position joint="{s}j{k}" class="hand"/>' for s in ("ff", "th")
             for k in range(4))}
  </actuator>
</mujoco>
"""


def _mujoco_pose(text: str, name: str, qpos: dict[str, float]) -> tuple[Any, Any]:
    """MuJoCo's pose of body (else site) ``name`` of the MJCF (meshes stripped) with the
    named joints at ``qpos`` (others 0)."""
    m = mujoco.MjModel.from_xml_string(mujoco_text(text))
    d = mujoco.MjData(m)
    for j, v in qpos.items():
        d.qpos[m.jnt_qposadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, j)]] = v
    mujoco.mj_kinematics(m, d)
    b = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, name)
    if b >= 0:
        return d.xmat[b].reshape(3, 3).copy(), d.xpos[b].copy()
    s = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, name)
    return d.site_xmat[s].reshape(3, 3).copy(), d.site_xpos[s].copy()


def _joint_vectors(finger: Any, n: int = 4, seed: int = 24) -> list[Any]:
    rng = np.random.default_rng(seed)
    nominal = np.clip(np.zeros(finger.nq), finger.lower, finger.upper)
    return [nominal] + [rng.uniform(finger.lower, finger.upper) for _ in range(n)]


def _assert_fingertips_are_mujocos(hand: WholeHand, text: str, atol: float = 1e-9) -> float:
    """Every finger's fingertip pose (CasADi kinematics and Pinocchio's, in the palm
    frame) equals MuJoCo's of ``text`` mounted by the hand's mount; the largest
    difference [m or rad]."""
    R_m, p_m = hand.mount
    worst = 0.0
    for finger in hand.fingers:
        for q in _joint_vectors(finger):
            R_mj, p_mj = _mujoco_pose(text, finger.tip_frame,
                                      dict(zip(finger.joint_names, q, strict=True)))
            R_ref, p_ref = R_m @ R_mj, R_m @ p_mj + p_m
            R_ca, p_ca = (np.asarray(x) for x in finger.fk(q))
            R_pin, p_pin = finger.fingertip_pose_pin(q)
            for R, p in ((R_ca, p_ca.ravel()), (R_pin, p_pin)):
                worst = max(worst, float(np.abs(p - p_ref).max()),
                            float(np.abs(R - R_ref).max()))
    assert worst < atol, worst
    return worst


def _pinocchio_raw(text: str) -> Any:
    import tempfile
    from pathlib import Path

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "hand.xml"
        path.write_text(text, encoding="utf-8")
        return pin.buildModelFromMJCF(str(path))


# -- posed roots: degrees and radians, quaternions and Euler angles ----------------------------

ROOTS = [
    ("", 'quat="0 1 0 1"'),  # the Menagerie Allegro's root: x -> -z, z -> x
    ('angle="radian"', 'pos="0.01 -0.02 0.03" quat="0 1 0 1"'),
    ("", 'pos="0 0 0.1" euler="90 0 45"'),  # degrees, MuJoCo's default unit
    ('angle="radian"', 'euler="0.3 -0.5 1.2"'),
    ('eulerseq="ZYX"', 'pos="0.02 0 0" euler="30 -20 75"'),  # extrinsic: Pinocchio 4.1 misreads
    ('angle="radian" eulerseq="zxz"', 'euler="0.4 1.1 -0.7"'),
    ('eulerseq="XzY"', 'euler="10 20 30"'),
    ("", 'axisangle="1 2 2 120"'),  # an axis of length 3: Pinocchio 4.1 misreads
    ("", 'xyaxes="0 1 0 -1 0 0.3"'),
    ("", 'zaxis="1 1 -1"'),
]


@pytest.mark.parametrize(("compiler", "root"), ROOTS)
def test_a_posed_root_is_read_as_mujoco_reads_it(compiler: str, root: str) -> None:
    text = menagerie_style(root, compiler)
    hand = load_whole_hand(text, "mjcf", [TipSpec(t) for t in TIPS])
    _assert_fingertips_are_mujocos(hand, text)
    # the capsule tips of the classes, read in the tip bodies' frames
    assert [f.tip_surface.kind for f in hand.fingers] == ["capsule"] * 4


def test_pinocchio_41_drops_the_root_pose_and_dexroll_puts_it_back() -> None:
    text = menagerie_style()
    raw = _pinocchio_raw(text)
    data = raw.createData()
    pin.framesForwardKinematics(raw, data, pin.neutral(raw))
    _, p_mj = _mujoco_pose(text, "mf_tip", {})
    fixed, _ = build_mjcf(text)
    fdata = fixed.createData()
    pin.framesForwardKinematics(fixed, fdata, pin.neutral(fixed))
    M = fdata.oMf[fixed.getFrameId("mf_tip", pin.FrameType.BODY)]
    assert np.abs(M.translation - p_mj).max() < 1e-12
    raw_error = float(np.linalg.norm(data.oMf[raw.getFrameId("mf_tip")].translation - p_mj))
    if raw_error < 1e-9:
        pytest.skip("this Pinocchio reads the root pose (issue #2782 fixed)")
    assert raw_error > 0.1  # 146 mm with Pinocchio 4.1: the finger's length, turned 90 deg


def test_a_mount_places_mujocos_world_in_the_palm_frame() -> None:
    text = menagerie_style('pos="0 0 0.02" euler="0 90 0"')
    R = np.asarray(pin.rpy.rpyToMatrix(0.3, -0.2, 1.0))
    hand = load_whole_hand(text, "mjcf", [TipSpec(t) for t in TIPS], R, [0.01, 0.02, -0.03])
    _assert_fingertips_are_mujocos(hand, text)


def test_radian_and_degree_files_are_the_same_hand() -> None:
    deg = load_whole_hand(menagerie_style(), "mjcf", [TipSpec(t) for t in TIPS])
    rad = load_whole_hand(menagerie_style(compiler='angle="radian"'), "mjcf",
                          [TipSpec(t) for t in TIPS])
    for fd, fr in zip(deg.fingers, rad.fingers, strict=True):
        np.testing.assert_allclose(fd.lower, fr.lower, atol=1e-12)
        np.testing.assert_allclose(fd.upper, fr.upper, atol=1e-12)
        for q in _joint_vectors(fd):
            for a, b in zip(fd.fingertip_pose_pin(q), fr.fingertip_pose_pin(q), strict=True):
                np.testing.assert_allclose(a, b, atol=1e-12)


def test_sites_as_fingertips_are_mujocos_sites_with_their_surface_in_their_frame() -> None:
    text = menagerie_style('pos="0 0 0.05" euler="0 90 0"')
    hand = load_whole_hand(text, "mjcf", [TipSpec(t.replace("tip", "pad")) for t in TIPS])
    _assert_fingertips_are_mujocos(hand, text)
    # the capsule (its geom on the site's body) is where MuJoCo puts it: the cap's centre
    m = mujoco.MjModel.from_xml_string(mujoco_text(text))
    d = mujoco.MjData(m)
    mujoco.mj_kinematics(m, d)
    for finger, body in zip(hand.fingers, TIPS, strict=True):
        b = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, body)
        geom = next(g for g in range(m.ngeom) if m.geom_bodyid[g] == b
                    and m.geom_type[g] == mujoco.mjtGeom.mjGEOM_CAPSULE)
        axis, centre = d.geom_xmat[geom].reshape(3, 3)[:, 2], d.geom_xpos[geom]
        half = m.geom_size[geom][1]
        R, p = finger.fingertip_pose_pin(np.zeros(4))
        surf = finger.tip_surface
        cap = p + R @ surf.p  # the cap's sphere centre
        far = max((centre + half * axis, centre - half * axis),
                  key=lambda e: float(np.linalg.norm(e - d.xpos[b])))  # from the body's origin
        assert float(np.linalg.norm(cap - far)) < 1e-9


def test_a_site_on_a_nested_jointless_body_is_placed_on_its_body() -> None:
    text = """<mujoco><compiler angle="radian"/><worldbody>
      <body name="root" pos="0.1 0 0" euler="0.2 0 0">
        <body name="b1" pos="0.1 0 0"><joint name="j1" axis="0 0 1" range="-1 1"/>
          <geom size="0.01"/>
          <body name="f1" pos="0 0.1 0" euler="0 0 1">
            <body name="f2" pos="0 0.05 0" euler="1 0 0">
              <geom name="tipcap" type="sphere" size="0.01" pos="0 0 0.02"/>
              <site name="s" pos="0 0 0.02" euler="0.3 0.2 0.1"/>
            </body></body></body></body></worldbody></mujoco>"""
    raw = _pinocchio_raw(text)
    data = raw.createData()
    pin.framesForwardKinematics(raw, data, np.zeros(1))
    _, p_mj = _mujoco_pose(text, "s", {})
    assert np.linalg.norm(data.oMf[raw.getFrameId("s")].translation - p_mj) > 0.01  # 4.1
    hand = load_whole_hand(text, "mjcf", [TipSpec("s"), TipSpec("f2")])
    _assert_fingertips_are_mujocos(hand, text)
    assert hand.fingers[0].tip_surface.kind == "sphere"
    np.testing.assert_allclose(hand.fingers[0].tip_surface.p, 0.0, atol=1e-12)


@pytest.mark.parametrize("seq", ["xyz", "XYZ", "zyx", "ZYX", "xzx", "XzY", "yXy"])
def test_euler_sequences_are_mujocos(seq: str) -> None:
    rng = np.random.default_rng(7)
    for _ in range(5):
        angles = rng.uniform(-180, 180, 3)
        text = (f'<mujoco><compiler eulerseq="{seq}"/><worldbody><body name="b" '
                f'euler="{_v(angles)}"><geom size="0.1"/></body></worldbody></mujoco>')
        m = mujoco.MjModel.from_xml_string(text)
        q = orientation_quat({"euler": _v(angles)}, True, seq)
        assert q is not None
        assert min(np.abs(q - m.body_quat[1]).max(), np.abs(q + m.body_quat[1]).max()) < 1e-9


# -- refused: what dexroll would read in another frame ---------------------------------------

def test_a_reader_that_drops_the_root_pose_is_refused_naming_the_body(monkeypatch: Any
                                                                         ) -> None:
    monkeypatch.setattr(mjcf_frames, "fix_model", lambda model, root: model)
    with pytest.raises(HandModelError) as exc:
        load_whole_hand(menagerie_style(), "mjcf", [TipSpec(t) for t in TIPS])
    text = str(exc.value)
    assert exc.value.errors[0][0] == "model"
    assert "body 'ff_tip' is" in text and " mm and " in text and "MuJoCo" in text
    # the distance in mm, the fingertips' 14-146 mm of the issue
    mm = [float(r.split(" is ")[1].split(" mm")[0]) for _, r in exc.value.errors
          if "_tip'" in r]
    assert max(mm) > 100


def test_the_service_answers_a_misread_hand_with_a_422_naming_the_model(monkeypatch: Any
                                                                          ) -> None:
    from dexroll_client.models import HandModel
    from ocp.spec.problem import ProblemError
    from planner_service.planners.cache import load_hand_model

    monkeypatch.setattr(mjcf_frames, "fix_model", lambda model, root: model)
    spec = HandModel.model_validate({"mjcf": menagerie_style(),
                                     "tips": [{"name": t} for t in TIPS]})
    with pytest.raises(ProblemError) as exc:
        load_hand_model(spec)
    assert exc.value.errors[0][0] == "hand.mjcf"
    assert "from where MuJoCo puts it" in exc.value.errors[0][1]


@pytest.mark.parametrize(("patch", "words"), [
    ('<worldbody><body name="other" pos="1 0 0"><geom size="0.01"/></body>',
     "Pinocchio reads only the first"),
    ('<body name="ff_tip">', '<body name="ff_tip"><frame pos="0 0 0.01"><site name="x"/></frame>'),
])
def test_what_pinocchio_does_not_read_is_refused(patch: str, words: str) -> None:
    text = menagerie_style()
    if patch.startswith("<worldbody>"):
        text = text.replace("<worldbody>", patch)
    else:
        text = text.replace(patch, words)
        words = "<frame> elements are not read"
    with pytest.raises(HandModelError, match=words):
        load_whole_hand(text, "mjcf", [TipSpec(t) for t in TIPS])


def test_a_joint_mujoco_leaves_unlimited_is_refused_naming_it() -> None:
    text = menagerie_style().replace('<joint name="ffj2" ', '<joint name="ffj2" limited="false" ')
    with pytest.raises(HandModelError, match=r"joint 'ffj2': MuJoCo's limits are \[-inf, inf\]"):
        load_whole_hand(text, "mjcf", [TipSpec(t) for t in TIPS])


def test_without_mujoco_the_corrections_stand_alone(monkeypatch: Any) -> None:
    import builtins

    real = builtins.__import__

    def no_mujoco(name: str, *args: Any, **kwargs: Any) -> Any:
        if name == "mujoco":
            raise ImportError("no mujoco")
        return real(name, *args, **kwargs)

    text = menagerie_style('pos="0 0 0.1" euler="90 0 45"')
    monkeypatch.setattr(builtins, "__import__", no_mujoco)
    model, _ = build_mjcf(text)
    assert mujoco_disagreements(text, model) is None
    hand = load_whole_hand(text, "mjcf", [TipSpec(t) for t in TIPS])
    monkeypatch.undo()
    _assert_fingertips_are_mujocos(hand, text)


def test_mujoco_compiles_the_text_without_its_mesh_files() -> None:
    text = menagerie_style()
    with pytest.raises(ValueError, match="stl"):
        mujoco.MjModel.from_xml_string(text)
    m = mujoco.MjModel.from_xml_string(mujoco_text(text))
    assert m.nmesh == 0 and m.njnt == 16
    root = ET.fromstring(mujoco_text(text))
    assert not [g for g in root.iter("geom") if "mesh" in g.attrib]


# -- URDF: Pinocchio's reading is the joint origins' -----------------------------------------

POSED_URDF = """<robot name="posed">
  <link name="base"/><link name="l1"/><link name="l2"/><link name="tip"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>
    <origin xyz="0.05 -0.02 0.1" rpy="0.4 -1.2 2.5"/><axis xyz="0 1 1"/>
    <limit lower="-1" upper="1.5" effort="1" velocity="3"/></joint>
  <joint name="j2" type="prismatic"><parent link="l1"/><child link="l2"/>
    <origin xyz="0 0.03 0" rpy="1.5707963 0 0.3"/><axis xyz="1 0 0"/>
    <limit lower="-0.02" upper="0.02" effort="1" velocity="1"/></joint>
  <joint name="tipj" type="fixed"><parent link="l2"/><child link="tip"/>
    <origin xyz="0.02 0 0.01" rpy="0 0.5 0"/></joint>
  <link name="tip_sphere"/>
  <joint name="j3" type="revolute"><parent link="tip"/><child link="tip_sphere"/>
    <origin xyz="0 0 0.02" rpy="-0.3 0.2 0.1"/><axis xyz="0 0 1"/>
    <limit lower="-2" upper="2" effort="1" velocity="3"/></joint>
</robot>"""


def test_pinocchio_reads_a_posed_first_joint_origin_as_the_urdf_says() -> None:
    model = pin.buildModelFromXML(POSED_URDF)
    assert urdf_disagreements(POSED_URDF, model) == []
    data = model.createData()
    q = np.array([0.7, 0.01, -1.1])
    pin.framesForwardKinematics(model, data, q)
    poses = urdf_link_poses(ET.fromstring(POSED_URDF), {"j1": 0.7, "j2": 0.01, "j3": -1.1})
    for link in ("l1", "l2", "tip", "tip_sphere"):
        M = data.oMf[model.getFrameId(link, pin.FrameType.BODY)]
        np.testing.assert_allclose(M.translation, poses[link][1], atol=1e-12)
        np.testing.assert_allclose(M.rotation, poses[link][0], atol=1e-12)


def test_a_urdf_read_in_another_frame_is_refused_naming_the_link() -> None:
    model = pin.buildModelFromXML(POSED_URDF)
    model.jointPlacements[1] = pin.SE3(np.eye(3), np.zeros(3))  # the origin dropped
    found = urdf_disagreements(POSED_URDF, model)
    assert any(r.startswith("link 'tip' is ") and " mm and " in r for r in found)


def test_a_posed_root_with_its_own_joint_is_left_as_pinocchio_reads_it() -> None:
    text = """<mujoco><worldbody>
      <body name="root" pos="0.1 0 0.02" euler="0 30 90"><joint name="j0" axis="1 0 0"
          range="-40 40"/><geom size="0.01"/>
        <body name="tip" pos="0 0.1 0"><joint name="j1" axis="0 0 1" range="-90 90"/>
          <geom type="sphere" size="0.01"/></body></body></worldbody></mujoco>"""
    hand = load_whole_hand(text, "mjcf", [TipSpec("tip")])
    _assert_fingertips_are_mujocos(hand, text)


def test_a_whole_hand_urdf_is_checked_at_load() -> None:
    from ocp.geometry.tips import sphere_tip

    hand = load_whole_hand(POSED_URDF, "urdf", [TipSpec("tip_sphere", sphere_tip(0.01))])
    finger = hand.fingers[0]
    q = np.array([0.3, -0.01, 0.5])
    poses = urdf_link_poses(ET.fromstring(POSED_URDF),
                            dict(zip(finger.joint_names, q, strict=True)))
    R, p = (np.asarray(x) for x in finger.fk(q))
    np.testing.assert_allclose(p.ravel(), poses["tip_sphere"][1], atol=1e-12)
    np.testing.assert_allclose(R, poses["tip_sphere"][0], atol=1e-12)
