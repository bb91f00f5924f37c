"""MuJoCo's soft friction as the execution on a user's file meets it
(``sim/soft_contact.py`` :func:`creep_speed`; docs/simulation.md, "Soft friction").

Law: a block resting on a plane and pushed sideways by a steady force well inside its
friction cone slides at the speed ``R f / B`` of MuJoCo's friction rows predicts, with
elliptic and pyramidal cones and at two ``impratio``; with the noslip solver it does not
slide, and the estimate is 0. The execution on a file without the noslip solver says
how far each fingertip creeps over the plan."""

from __future__ import annotations

import numpy as np
import pytest

mujoco = pytest.importorskip("mujoco")

from sim.soft_contact import creep_speed  # noqa: E402

BLOCK = """<mujoco>
  <option timestep="0.001" {option}/>
  <worldbody>
    <geom type="plane" size="1 1 0.1" friction="1 0.005 0.0001"/>
    <body name="block" pos="0 0 0.02">
      <freejoint/>
      <geom type="box" size="0.02 0.02 0.02" mass="0.1" friction="1 0.005 0.0001"/>
    </body>
  </worldbody>
</mujoco>"""


def _slide(option: str, push: float = 0.3) -> tuple[float, float]:
    """(the block's steady sliding speed [m/s], the estimate) under a sideways ``push``
    [N] (0.3 of its weight's 0.98 N: inside the cone)."""
    m = mujoco.MjModel.from_xml_string(BLOCK.format(option=option))
    d = mujoco.MjData(m)
    body = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "block")
    for _ in range(300):  # settle
        mujoco.mj_step(m, d)
    d.xfrc_applied[body, 0] = push
    for _ in range(500):  # reach the steady creep
        mujoco.mj_step(m, d)
    x0 = float(d.qpos[0])
    est = []
    for _ in range(500):
        mujoco.mj_step(m, d)
        est.append(sum(creep_speed(m, d, d.contact[i]) for i in range(d.ncon)) / d.ncon)
    speed = (float(d.qpos[0]) - x0) / (500 * m.opt.timestep)
    return speed, float(np.median(est))


@pytest.mark.parametrize("option", ['cone="elliptic"', 'cone="elliptic" impratio="10"',
                                    'cone="pyramidal"', 'cone="pyramidal" impratio="10"'])
def test_a_block_pushed_inside_its_cone_creeps_at_r_f_over_b(option: str) -> None:
    speed, estimate = _slide(option)
    assert speed > 5e-5  # it does creep, inside its cone
    assert estimate == pytest.approx(speed, rel=1e-3)


def test_the_noslip_solver_stops_the_creep_and_the_estimate_says_so() -> None:
    speed, estimate = _slide('cone="elliptic" noslip_iterations="5"')
    assert abs(speed) < 1e-5 and estimate == 0.0
