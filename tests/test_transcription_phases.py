"""The transcription's contact phases: a grasp's motion as a sequence of phases, each with
its set of active contacts.

Today's grasps are one-phase schedules and must give the same NLP as before phases, row
for row: the signatures saved from the builder before them (tests/nlp_signature.py,
tests/data/nlp_signatures.npz) against the builder now."""

from __future__ import annotations

import math
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np
import pytest
from helpers import assert_close
from nlp_signature import CASES, build, signature

from ocp.robots.hands import load_hand
from ocp.solve.attempt import run, setup
from ocp.solve.planner import GraspStructure, ManipulationPlanner
from ocp.spec.grasp import ManipulationProblem, contact_charts, hand_fingertips
from ocp.spec.motion import DesiredMotion, MotionStep, ObjectPose
from ocp.spec.phases import ContactPhase
from ocp.spec.problem import ObjectSpec, ProblemError
from ocp.transcription.grasp_model import GraspModel
from ocp.transcription.nlp_blocks import build_manipulation_nlp
from ocp.transcription.values import bounds, scales
from ocp.transcription.values import parameters as nlp_parameters

PLANNER = ManipulationPlanner()
SAVED = np.load(Path(__file__).parent / "data" / "nlp_signatures.npz")


@pytest.mark.parametrize("name", sorted(CASES))
def test_a_one_phase_grasp_gives_the_nlp_it_gave_before_phases(name: str) -> None:
    """Same sizes, bounds, sparsity patterns (the same rows and variables in the same
    order), and the same values at a random point to round-off."""
    now = signature(build(name)[1])
    for key in ("sizes", "lbg", "ubg", "jac_rows", "jac_cols", "hess_rows", "hess_cols"):
        np.testing.assert_array_equal(now[key], SAVED[f"{name}/{key}"], err_msg=key)
    for key in ("f", "g", "jac", "hess"):
        ref = SAVED[f"{name}/{key}"]
        assert np.all(np.isfinite(ref)), key
        assert_close(now[key], ref, atol=1e-10 * (1 + np.abs(ref)), err_msg=key)


# -- a three-finger grasp whose third fingertip lifts off half-way -------------------------

DEG = math.pi / 180
T_HALF = 1.0


@pytest.fixture(scope="module")
def lifted() -> dict[str, Any]:
    """The three-finger hand turning a ball by 10 deg in 2 s (mu = 1), planned in one
    phase (uncertified: its NLP point is what the laws below evaluate), and the same
    problem with fingertip 2 lifted for the second second, and landing then instead."""
    hand = load_hand("three_finger")
    obj = ObjectSpec("sphere", (0.025,))
    start = ObjectPose(position=hand.nominal_object_position)
    problem = ManipulationProblem(
        obj, hand_fingertips(hand, start, obj), 2 * T_HALF, initial_pose=start,
        motion=DesiredMotion.from_steps(start, [MotionStep(2 * T_HALF, (0.0, 0.0, 1.0),
                                                           10 * DEG)]),
        n_intervals=8, mu=1.0)
    sol = PLANNER.solve(problem, certify=False)
    assert sol.converged and sol.nlp_point is not None
    on, off = (True, True, True), (True, True, False)
    lift = replace(problem, phases=(ContactPhase(T_HALF, on), ContactPhase(T_HALF, off)))
    land = replace(problem, phases=(ContactPhase(T_HALF, off), ContactPhase(T_HALF, on)))
    return {"problem": problem, "w": sol.nlp_point.w, "lift": lift, "land": land}


def _g(nlp: Any, w: np.ndarray, problem: ManipulationProblem) -> np.ndarray:
    p = nlp_parameters(problem, nlp)
    return np.asarray(nlp.oracle(w, p)[1]).ravel()


def test_the_schedule_names_the_nlp(lifted: dict[str, Any]) -> None:
    """The cache key names the schedule: three structures, three NLPs; the phases split
    the grid in proportion to their durations."""
    keys = {GraspStructure.of(lifted[k]) for k in ("problem", "lift", "land")}
    assert len(keys) == 3
    assert GraspStructure.of(lifted["lift"]).schedule == (
        (4, (True, True, True)), (4, (True, True, False)))
    assert GraspStructure.of(lifted["problem"]).schedule is None
    assert lifted["lift"].schedule() != lifted["land"].schedule()


def test_a_lifted_fingertip_contributes_no_contact_rows(lifted: dict[str, Any]) -> None:
    """In the phase where fingertip 2 is off the object, no row reads its contact
    coordinates or contact inputs (their Jacobian columns are zero; the bounds park them),
    while in the one-phase NLP its coordinates there enter its rolling and closure rows."""
    one, _ = PLANNER.build(lifted["problem"])
    two, _ = PLANNER.build(lifted["lift"])
    assert two.pack.nnz_out(0) == one.pack.nnz_out(0) and len(two.lbg) < len(one.lbg)
    w = lifted["w"]
    m = PLANNER.model(lifted["problem"])
    tip = m.fingertips[2]
    _, Xmi, _, Umi, _, _, _ = (np.asarray(a).round().astype(int)
                               for a in two.unpack(np.arange(len(w), dtype=float)))
    phase2 = range(4, 8)  # the second phase's intervals
    eta_mid = np.concatenate([Xmi[tip.eta_cols, k] for k in phase2])
    w_mid = np.concatenate([Umi[tip.w_cols, k] for k in phase2])
    assert set(eta_mid) | set(w_mid) <= set(two.parked.tolist())
    J2 = two.jac_g(w, nlp_parameters(lifted["lift"], two))[1]
    J1 = one.jac_g(w, nlp_parameters(lifted["problem"], one))[1]
    cols = np.concatenate([eta_mid, w_mid])
    assert np.abs(np.asarray(ca.DM(J2)[:, cols.tolist()])).max() == 0.0
    assert np.abs(np.asarray(ca.DM(J1)[:, eta_mid.tolist()])).max() > 0.0
    # every parked variable is read by no row of the phased NLP
    assert np.abs(np.asarray(ca.DM(J2)[:, two.parked.tolist()])).max() == 0.0
    lbx, ubx = bounds(lifted["lift"], two, m, PLANNER.initial_state(lifted["lift"]),
                      *scales(lifted["lift"], m))
    assert np.all(lbx[two.parked] == 0.0) and np.all(ubx[two.parked] == 0.0)


def test_a_lifted_fingertips_joints_follow_their_rates_alone(lifted: dict[str, Any]) -> None:
    """Moving fingertip 2's joints after lift-off along q + c (t - t_b)^2, rates + 2 c
    (t - t_b) (Hermite-Simpson is exact on it) changes no row of the phased NLP but its
    joints' acceleration bounds; in the one-phase NLP it breaks fingertip 2's closure."""
    problem, lift = lifted["problem"], lifted["lift"]
    one, _ = PLANNER.build(problem)
    two, _ = PLANNER.build(lift)
    m = PLANNER.model(problem)
    tip = m.fingertips[2]
    x_scale, u_scale = scales(problem, m)
    w = lifted["w"]
    X, Xm, U, Um, S, Sm, F = (np.asarray(a) for a in two.unpack(w))
    t_nodes = np.linspace(0.0, 2 * T_HALF, 9)
    tm = (t_nodes[:-1] + t_nodes[1:]) / 2
    c = 0.3  # rad/s^2
    q, qd = tip.q_cols, tip.qd_cols
    after = np.maximum(t_nodes - T_HALF, 0.0)
    after_m = np.maximum(tm - T_HALF, 0.0)
    X[q, :] += c * after ** 2 / x_scale[q][:, None]
    Xm[q, :] += c * after_m ** 2 / x_scale[q][:, None]
    U[qd, :] += 2 * c * after / u_scale[qd][:, None]  # smooth timing: one input per node
    Um[qd, :] += 2 * c * after_m / u_scale[qd][:, None]
    w2 = np.asarray(two.pack(X, Xm, U, Um, S, Sm, F)).ravel()
    accel = (two.lbg == -1.0) & (two.ubg == 1.0)
    dg2 = np.abs(_g(two, w2, lift) - _g(two, w, lift))
    assert dg2[~accel].max() < 1e-12 and dg2[accel].max() > 1e-3
    dg1 = np.abs(_g(one, w2, problem) - _g(one, w, problem))
    assert dg1.max() > 1e-2


def test_a_landing_fingertip_closes_where_it_lands(lifted: dict[str, Any]) -> None:
    """Where fingertip 2 lands, the phased NLP holds its closure (eq. 6): rows equal to the
    grasp's own closure residual there (position over the object's size, orientation),
    about zero at the one-phase plan (whose fingertip touches throughout) and the size of
    a joint's error when that joint is moved."""
    land = lifted["land"]
    two, _ = PLANNER.build(land)
    m = PLANNER.model(land)
    x_scale, _ = scales(land, m)
    w = lifted["w"]
    g = _g(two, w, land)
    rows = g[-6:]  # the touch-down's rows come last
    assert np.abs(rows).max() < 1e-6
    X, Xm, U, Um, S, Sm, F = (np.asarray(a) for a in two.unpack(w))
    X[m.fingertips[2].q_cols.start + 1, 4] += 0.01 / x_scale[m.fingertips[2].q_cols.start + 1]
    w2 = np.asarray(two.pack(X, Xm, U, Um, S, Sm, F)).ravel()
    rows2 = _g(two, w2, land)[-6:]
    prm = m.params(np.asarray(land.object.dimensions), contact_charts(land))
    closure = np.asarray(m.path(X[:, 4] * x_scale, prm)[0]).ravel()[12:18]
    L = land.object.length_scale
    assert_close(rows2, np.concatenate([closure[:3] / L, closure[3:]]), atol=1e-12)
    assert np.abs(rows2[3:]).max() > 5e-3


def test_the_phased_nlp_solves_from_the_one_phase_plan(lifted: dict[str, Any]) -> None:
    """The phased NLP is a real NLP: IPOPT converges on it from the one-phase plan, and
    its solution keeps the touching fingertips rolling (their closure rows zero) while
    fingertip 2's rows are gone after lift-off. (The planner does not plan it yet: without
    the swing's clearance a lifted fingertip may pass through the object; the planner
    refuses such a problem by name.)"""
    lift = lifted["lift"]
    s = setup(PLANNER, lift)
    r = run(s, np.clip(lifted["w"], s.lbx, s.ubx), None, time.perf_counter() + 300, 300)
    assert r.raw == "Solve_Succeeded", r.raw
    assert r.violation < 1e-6
    with pytest.raises(ProblemError, match="phases"):
        PLANNER.solve(lift)


def test_the_free_fingertips_clearance_rows_reach_the_nlp(lifted: dict[str, Any],
                                                          monkeypatch: pytest.MonkeyPatch
                                                          ) -> None:
    """Finger gaiting fills :meth:`FreeFingertip.clearance` without touching the
    transcription: a row it returns is a row >= 0 at every point where the fingertip is
    lifted (the second phase's 4 midpoints and its 4 nodes after the lift-off's), and
    nowhere else."""
    from ocp.contacts import FreeFingertip

    def above(self: FreeFingertip, g: Any, x: Any) -> Any:
        return self.tip_pose(g, x)[1][2:3] + 1.0  # the tip's height + 1 m

    problem = lifted["lift"]
    m = GraspModel(problem.object.shape, False, tuple(c.finger for c in problem.fingers))
    before = build_manipulation_nlp(m, (8,), (False,) * 5, (), True, 1e-3, smooth=True,
                                    schedule=problem.schedule())
    monkeypatch.setattr(FreeFingertip, "clearance", above)
    m = GraspModel(problem.object.shape, False, tuple(c.finger for c in problem.fingers))
    after = build_manipulation_nlp(m, (8,), (False,) * 5, (), True, 1e-3, smooth=True,
                                   schedule=problem.schedule())
    assert len(after.lbg) - len(before.lbg) == 8
    assert np.sum(np.isinf(after.ubg)) - np.sum(np.isinf(before.ubg)) == 8
