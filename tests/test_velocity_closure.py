"""The fingertips' closure at the velocity level (ocp/transcription/velocity_closure.py).

Laws:

* the joints move the tip as the time derivative of the forward kinematics does (the
  geometric Jacobian against ``jtimes`` of the FK), for every built-in finger;
* the contact moves the tip as the time derivative of the tip's pose from the contact
  (eq. 6's right-hand side) along the rolling equations does, for flat pads and round tips,
  on the palm and held in the air, in rotated chart patches;
* on a solved finger plan, the returned trajectory does not slip at its collocation points
  (nodes from both sides, midpoints: the solver's tolerance), and between them its slip
  shrinks like h^3 (halving h divides it by more than h^2 would, 4).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import casadi as ca
import numpy as np
import pytest
from helpers import assert_close
from test_contract import CASES
from test_round_tips import SPHERE_TIP, round_three_finger_problem

from ocp.geometry.rotations import vee
from ocp.geometry.tips import capsule_tip
from ocp.robots.hands import load_hand
from ocp.solution import ManipulationSolution
from ocp.solve.planner import ManipulationPlanner
from ocp.spec.grasp import contact_charts
from ocp.transcription.velocity_closure import contact_twists, finger_twist

PLANNER = ManipulationPlanner()


def _rotation(rng: np.random.Generator) -> np.ndarray:
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    return q * np.sign(np.linalg.det(q))


def _fingers() -> list[Any]:
    fingers = [f for name in ("two_finger", "three_finger") for f in load_hand(name).fingers]
    _, problem, _ = CASES["one_finger"]()
    return [*fingers, problem.finger]


@pytest.mark.parametrize("index", range(len(_fingers())))
def test_the_joints_move_the_tip_as_the_derivative_of_its_kinematics(index: int) -> None:
    finger = _fingers()[index]
    q, qd, c = ca.SX.sym("q", finger.nq), ca.SX.sym("qd", finger.nq), ca.SX.sym("c", 3)
    R, p = finger.fk(q)
    R_dot = ca.reshape(ca.jtimes(ca.vec(R), q, qd), 3, 3)
    omega = vee(R_dot @ R.T)
    v = ca.jtimes(p, q, qd) + ca.cross(omega, c - p)
    v_j, omega_j = finger_twist(finger, q, qd, c)
    f = ca.Function("f", [q, qd, c], [v, omega, v_j, omega_j])
    rng = np.random.default_rng(index)
    for _ in range(5):
        lo, hi = np.asarray(finger.lower), np.asarray(finger.upper)
        out = [np.asarray(a).ravel() for a in f(rng.uniform(lo, hi), rng.normal(size=finger.nq),
                                                 0.05 * rng.normal(size=3))]
        assert np.linalg.norm(out[0]) > 1e-3  # not a vacuous comparison
        assert_close(out[2], out[0], atol=1e-12)
        assert_close(out[3], out[1], atol=1e-12)


def _structures() -> dict[str, Any]:
    two = CASES["two_fingers"]()[1]
    three = CASES["three_fingers"]()[1]
    one = CASES["one_finger"]()
    palm_finger = one[0].manipulation_problem(one[1])
    capsule = capsule_tip(0.012, (0.0, 0.0, -0.012), (0.0, 1.0, 0.0), (1.0, 0.0, 0.0))
    ellipsoid = dataclasses.replace(three, object=dataclasses.replace(
        three.object, shape="ellipsoid", dimensions=(0.025, 0.032)))
    return {"palm_and_pad": palm_finger, "two_pads_in_the_air": two,
            "three_pads": three, "ellipsoid_three_pads": ellipsoid,
            "sphere_tips": round_three_finger_problem(SPHERE_TIP),
            "capsule_tips": round_three_finger_problem(capsule)}


@pytest.mark.parametrize("name", list(_structures()))
def test_the_contact_moves_the_tip_as_the_derivative_of_its_pose(name: str) -> None:
    problem = _structures()[name]
    m = PLANNER.model(problem)
    x, u, prm = ca.SX.sym("x", m.nx), ca.SX.sym("u", m.nu), ca.SX.sym("p", m.n_params)
    twists = contact_twists(m, x, u, prm)
    _, _, R_pf, p_pf, _, _ = m.cartesian(x, prm)
    xd = m.dynamics(x, u, prm)
    outs = []
    for i, (cp, v, omega) in enumerate(twists):
        R, p = R_pf[:, 3 * i:3 * i + 3], p_pf[:, i]
        R_dot = ca.reshape(ca.jtimes(ca.vec(R), x, xd), 3, 3)
        omega_pose = vee(R_dot @ R.T)
        v_pose = ca.jtimes(p, x, xd) + ca.cross(omega_pose, cp - p)
        outs += [v, omega, v_pose, omega_pose]
    f = ca.Function("f", [x, u, prm], outs)
    rng = np.random.default_rng(7)
    shape = np.asarray(problem.object.dimensions, dtype=float)
    for _ in range(4):
        charts = [_rotation(rng) for _ in range(m.n_contacts)]
        x0 = 0.3 * rng.normal(size=m.nx)
        if m.object.nx == 7:  # a free object's unit quaternion
            x0[3:7] /= np.linalg.norm(x0[3:7])
        out = [np.asarray(a).ravel() for a in f(x0, rng.normal(size=m.nu),
                                                 m.params(shape, charts))]
        for k in range(0, len(out), 4):
            assert np.linalg.norm(out[k + 3]) > 1e-3
            assert_close(out[k], out[k + 2], atol=1e-12)
            assert_close(out[k + 1], out[k + 3], atol=1e-12)


def _slips(plan: ManipulationSolution, problem: Any, ts: np.ndarray, side: str
           ) -> np.ndarray:
    """The largest slip speed [m/s] of any fingertip at each time, from the returned
    polynomials and their derivatives."""
    m = PLANNER.model(problem)
    prm = m.params(np.asarray(problem.object.dimensions, dtype=float),
                   contact_charts(problem))
    x, xd = plan.trajectory(ts, 0, side), plan.trajectory(ts, 1, side)
    names = [m.laws.name_out(k) for k in range(m.laws.n_out())]
    out = m.mapped("laws", len(ts))(x.T, xd.T, prm)
    slips = [np.linalg.norm(np.asarray(out[k]), axis=0) for k, n in enumerate(names)
             if n.startswith("slip_")]
    return np.max(slips, axis=0)


@pytest.fixture(scope="module")
def two_finger_plans() -> dict[int, tuple[Any, ManipulationSolution]]:
    plans = {}
    for n in (20, 40):
        problem = dataclasses.replace(CASES["two_fingers"]()[1], n_intervals=n,
                                      max_refinements=0)
        plans[n] = (problem, PLANNER.solve(problem))
    return plans


def test_a_finger_plan_does_not_slip_at_its_collocation_points(
        two_finger_plans: dict[int, tuple[Any, ManipulationSolution]]) -> None:
    problem, plan = two_finger_plans[20]
    t = plan.trajectory.t_nodes
    mid = (t[:-1] + t[1:]) / 2
    between = np.concatenate([t[:-1] + (t[1:] - t[:-1]) * s
                              for s in (0.5 - 0.5 / math.sqrt(3), 0.5 + 0.5 / math.sqrt(3))])
    at_points = max(_slips(plan, problem, t[:-1], "right").max(),
                    _slips(plan, problem, t[1:], "left").max(),
                    _slips(plan, problem, mid, "right").max())
    off_points = _slips(plan, problem, between, "right").max()
    assert off_points > 0
    # the collocation points hold the rows to IPOPT's tolerance (1e-8, scaled by T / L)
    assert at_points < 1e-3 * off_points, (at_points, off_points)


def test_the_slip_between_collocation_points_shrinks_like_h_cubed(
        two_finger_plans: dict[int, tuple[Any, ManipulationSolution]]) -> None:
    worst = {}
    for n, (problem, plan) in two_finger_plans.items():
        t = plan.trajectory.t_nodes
        s = np.linspace(0.0, 1.0, 17)[1:-1]
        ts = np.concatenate([t[:-1] + (t[1:] - t[:-1]) * si for si in s])
        worst[n] = _slips(plan, problem, ts, "right").max()
    assert worst[20] / worst[40] > 5.0, worst  # h^2 would give 4, h^3 gives 8
