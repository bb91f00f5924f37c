"""Write ``examples/own_hand.xml``: a whole-hand MJCF of our own in the style of MuJoCo
Menagerie's hands, the user's kind of file for docs/hands.md's "your own hand" recipe and
the tests (``python tools/own_hand_mjcf.py``).

The kinematics are the Allegro-class hand's table (``ocp/robots/allegro.py``); the rest is
our choice, written as a Menagerie file writes it: angles in degrees, the root body posed
(``palm``: the vendor's base frame, so that MuJoCo's world frame is dexroll's built-in palm
frame: fingers along x, the palm's normal z), default classes and ``childclass``, visual
mesh geoms whose files are absent, collision capsules (the links and fingertips) and a box
(the palm), the palm's contacts with each finger's first two links excluded (they meet at
the joints, as a Menagerie file excludes them), an ``<inertial>`` on every body (masses
10-40 g a link, 0.4 kg the palm: our round numbers, not a vendor's), joint damping
1 N m s/rad and armature, and one ``<position>`` actuator per joint (kp 10 N m/rad, the
joint's range, force range +-0.7 N m: our choice).
"""

from __future__ import annotations

import math
from pathlib import Path

from ocp.robots.allegro import FINGERS, HAND_MOUNT, TIP_RADIUS

PARTS = ("base", "proximal", "medial", "distal")
SHORT = {"index": "ff", "middle": "mf", "ring": "rf", "thumb": "th"}
#: Link masses [kg] by part (the tip body: the fingertip).
MASS = {"base": 0.010, "proximal": 0.040, "medial": 0.030, "distal": 0.020, "tip": 0.015}
#: The actuators' force range [N m] (our choice).
FORCE = 0.7


def _v(x: object) -> str:
    return " ".join(f"{float(c):.9g}" for c in x)  # type: ignore[attr-defined]


def _inertial(mass: float, length: float) -> str:
    """A rod of ``length`` along z from the body's origin, radius 8 mm."""
    r = 0.008
    ixx = mass * (3 * r * r + length * length) / 12 + mass * (length / 2) ** 2
    izz = mass * r * r / 2
    return (f'<inertial pos="0 0 {length / 2:.6g}" mass="{mass:.6g}" '
            f'diaginertia="{ixx:.6g} {ixx:.6g} {izz:.6g}"/>')


def own_hand_mjcf() -> str:
    """The file's text."""
    deg = 180 / math.pi
    classes = []
    for f in FINGERS:
        for k in range(len(PARTS)):
            lo, hi = f.limits[k]
            classes.append(f'      <default class="{SHORT[f.name]}{k}"><joint '
                           f'axis="{_v(f.axes[k])}" range="{lo * deg:.9g} {hi * deg:.9g}"/>'
                           "</default>")
    body = []
    for f in FINGERS:
        s = SHORT[f.name]
        indent = "      "
        for k, part in enumerate(PARTS):
            pose = (f'pos="{_v(f.base_position)}" quat="{_v(f.base_quaternion)}"' if k == 0
                    else f'pos="{_v(f.offsets[k])}"')
            nxt_v = f.offsets[k + 1] if k + 1 < len(PARTS) else (0.0, 0.0, 0.0)
            nxt = math.sqrt(sum(c * c for c in nxt_v))
            length = nxt if nxt > 0 else 0.01
            body += [f'{indent}<body name="{s}_{part}" {pose}>',
                     f"{indent}  {_inertial(MASS[part], length)}",
                     f'{indent}  <joint name="{s}j{k}" class="{s}{k}"/>',
                     f'{indent}  <geom class="visual" mesh="{"thumb_" if s == "th" else ""}'
                     f'link_{k}"/>']
            if nxt > 0.02:  # the link to the next joint, 6 mm short at each end
                a = [c * 0.006 / nxt for c in nxt_v]
                b = [c * (1 - 0.006 / nxt) for c in nxt_v]
                body.append(f'{indent}  <geom class="link_collision" '
                            f'fromto="{_v(a)} {_v(b)}"/>')
            indent += "  "
        body += [f'{indent}<body name="{s}_tip">',
                 f"{indent}  {_inertial(MASS['tip'], f.capsule_centre + TIP_RADIUS)}",
                 f'{indent}  <geom class="visual" mesh="tip"/>',
                 f'{indent}  <geom class="{"thumb" if s == "th" else "finger"}'
                 'tip_collision"/>',
                 f"{indent}</body>"]
        for _ in PARTS:
            indent = indent[:-2]
            body.append(f"{indent}</body>")
    th, fi = FINGERS[3], FINGERS[0]
    (_, p_mount) = HAND_MOUNT
    actuators = "\n".join(f'    <position name="{SHORT[f.name]}a{k}" joint="{SHORT[f.name]}j{k}" '
                          f'class="hand"/>' for f in FINGERS for k in range(4))
    excludes = "\n".join(f'    <exclude body1="palm" body2="{SHORT[f.name]}_{part}"/>'
                         for f in FINGERS for part in ("base", "proximal"))
    meshes = "\n".join(f'    <mesh name="{p}link_{k}" file="{p}link_{k}.stl"/>'
                       for p in ("", "thumb_") for k in range(4))
    return f"""<mujoco model="own_hand">
  <!-- A hand of our own in the style of MuJoCo Menagerie's hands (tools/own_hand_mjcf.py
       writes it): the Allegro-class kinematics of ocp/robots/allegro.py, angles in
       degrees, the root posed, default classes, visual meshes whose files are absent,
       collision capsules, inertials and position actuators of our choosing. MuJoCo's
       friction is soft: a fingertip holding a tangential force creeps (about 2 mm/s
       under 0.3 N at impratio 10); the noslip solver removes that creep, without which
       a gait of a minute drifts off (docs/simulation.md). -->
  <compiler angle="degree" meshdir="assets" autolimits="true"/>
  <option cone="elliptic" impratio="10" noslip_iterations="5"/>
  <default>
    <default class="hand">
      <joint axis="0 1 0" damping="1" armature="0.001"/>
      <position kp="10" inheritrange="1" forcerange="-{FORCE} {FORCE}"/>
      <default class="visual"><geom type="mesh" contype="0" conaffinity="0" group="2"/></default>
      <default class="collision">
        <geom group="3" type="box" friction="1 0.005 0.0001"/>
        <default class="link_collision"><geom type="capsule" size="0.008"/></default>
        <default class="fingertip_collision">
          <geom type="capsule" size="{TIP_RADIUS} {fi.capsule_half_length}"
                pos="0 0 {fi.capsule_centre}"/>
          <default class="thumbtip_collision">
            <geom size="{TIP_RADIUS} {th.capsule_half_length}" pos="0 0 {th.capsule_centre}"/>
          </default>
        </default>
      </default>
{chr(10).join(classes)}
    </default>
  </default>
  <asset>
    <mesh name="palm" file="palm.stl"/>
{meshes}
    <mesh name="tip" file="tip.stl"/>
  </asset>
  <worldbody>
    <body name="palm" pos="{_v(p_mount)}" quat="0 1 0 1" childclass="hand">
      <inertial pos="-0.0093 0 -0.0475" mass="0.4" diaginertia="4e-4 3e-4 3e-4"/>
      <geom class="visual" mesh="palm"/>
      <geom class="collision" size="0.0204 0.0565 0.0475" pos="-0.0093 0 -0.0475"/>
{chr(10).join(body)}
    </body>
  </worldbody>
  <contact>
{excludes}
  </contact>
  <actuator>
{actuators}
  </actuator>
</mujoco>
"""


if __name__ == "__main__":  # pragma: no cover - writes the example
    out = Path(__file__).resolve().parent.parent / "examples" / "own_hand.xml"
    out.write_text(own_hand_mjcf(), encoding="utf-8")
    print(out)
