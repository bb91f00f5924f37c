"""Forces in the plan (issue 15): the request's load and grip, validated field by field;
on a plan, every collocation point's forces balance the object's weight to round-off,
lie inside their friction cones with the margin, push at least the minimum, and the joint
torques are J^T f by Pinocchio's own Jacobian."""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np
import pytest
from test_manipulation import two_fingers

from ocp.spec.problem import ForceSpec, ObjectSpec, ProblemError

LOAD = ForceSpec(mass=0.05, min_normal_force=1.0, torsional_friction=0.005)


@pytest.mark.parametrize(("patch", "field", "words"), [
    ({"mass": -0.1}, "forces.mass", "(0, 100] kg"),
    ({"mass": math.nan}, "forces.mass", "(0, 100] kg"),
    ({"gravity": (0.0, math.inf, -9.81)}, "forces.gravity", "finite"),
    ({"gravity": (0.0, -9.81)}, "forces.gravity", "3 finite"),
    ({"inertia": (1e-5, 0.0, 1e-5)}, "forces.inertia", "principal moments"),
    ({"min_normal_force": 0.0}, "forces.min_normal_force", "(0, 1000] N"),
    ({"torsional_friction": -1e-3}, "forces.torsional_friction", "[0, 0.1] m"),
    ({"cone_margin": 1.0}, "forces.cone_margin", "atan(mu)"),
])
def test_bad_forces_name_the_field(patch: dict[str, Any], field: str, words: str) -> None:
    problem = two_fingers(n=10, forces=replace(LOAD, **patch))
    with pytest.raises(ProblemError) as exc:
        problem.validate()
    errs = dict(exc.value.errors)
    assert field in errs and words in errs[field], errs


def test_the_default_inertia_is_the_solid_bodys() -> None:
    ball = ObjectSpec("sphere", (0.025,))
    assert np.allclose(ForceSpec(0.05).principal_inertia(ball), [0.4 * 0.05 * 0.025**2] * 3)
    egg = ObjectSpec("ellipsoid", (0.02, 0.03))
    Ix, Iy, Iz = ForceSpec(2.0).principal_inertia(egg)
    assert np.isclose(Ix, 2.0 * (0.02**2 + 0.03**2) / 5) and Ix == Iy
    assert np.isclose(Iz, 2 * 2.0 * 0.02**2 / 5)
    assert ForceSpec(1.0, inertia=(1.0, 2.0, 3.0)).principal_inertia(egg) == (1.0, 2.0, 3.0)


# -- a plan with forces: two fingers turn the ball in the air (the paper's experiment 2) ----

@pytest.fixture(scope="module")
def planned() -> tuple[Any, Any]:
    from test_manipulation import PLANNER

    problem = two_fingers(n=40, forces=LOAD)
    return problem, PLANNER.solve(problem)


def _points(problem: Any, sol: Any) -> tuple[np.ndarray, ...]:
    """Object pose, contact points and outward normals (palm frame) at the collocation
    points (nodes, then midpoints) of the NLP's own states, and the forces there."""
    from test_manipulation import PLANNER

    from ocp.spec.grasp import contact_charts

    m = PLANNER.model(problem)
    prm = m.params(np.asarray(problem.object.dimensions, dtype=float),
                   contact_charts(problem))
    col = sol.collocation
    X = np.vstack([col.X, col.Xm])
    k = len(X)
    cart = m.mapped("cartesian", k)(X.T, prm)
    p_po = np.asarray(cart[1]).T
    pts = np.asarray(cart[4]).T.reshape(k, m.n_contacts, 3)
    nrm = np.asarray(cart[5]).T.reshape(k, m.n_contacts, 3)
    f = np.concatenate([col.forces.f_nodes, col.forces.f_mid])
    tau = np.concatenate([col.forces.tau_nodes, col.forces.tau_mid])
    return p_po, pts, nrm, f, tau


def test_the_forces_hold_the_object_at_every_collocation_point(
        planned: tuple[Any, Any]) -> None:
    problem, sol = planned
    assert sol.ok, sol.message
    p_po, pts, nrm, f, tau = _points(problem, sol)
    weight = LOAD.mass * np.asarray(LOAD.gravity)
    # equilibrium with the weight at the centre, to round-off (IPOPT's tolerance)
    assert np.max(np.abs(f.sum(axis=1) + weight)) < 1e-9
    moment = (np.cross(pts - p_po[:, None], f) + tau[:, :, None] * nrm).sum(axis=1)
    assert np.max(np.abs(moment)) < 1e-9 * problem.object.length_scale
    fn = -np.einsum("kci,kci->kc", nrm, f)
    ft = np.linalg.norm(f + fn[:, :, None] * nrm, axis=2)
    mu_m = math.tan(math.atan(problem.mu) - LOAD.cone_margin)
    assert np.all(ft <= mu_m * fn + 1e-9)  # inside the cone with its margin
    assert np.all(fn >= LOAD.min_normal_force - 1e-9)
    assert np.all(np.abs(tau) <= LOAD.torsional_friction * fn + 1e-12)
    # small forces (the objective's terms on the forces): the top finger presses with the
    # minimum, the bottom one carries the weight besides (the grip does not grow)
    assert np.min(fn) < LOAD.min_normal_force * 1.02
    assert np.max(fn) < LOAD.min_normal_force * 1.02 + 1.05 * LOAD.mass * 9.81


def test_the_certificate_checks_the_forces_on_the_returned_samples(
        planned: tuple[Any, Any]) -> None:
    _, sol = planned
    cert = sol.certificate
    for name in ("max_force_equilibrium_residual", "max_moment_equilibrium_residual",
                 "min_friction_cone_margin", "min_normal_force", "min_torsion_margin"):
        assert name in cert, name
    assert cert.passed
    # the grid's forces are the collocation points' and sample() interpolates them
    f, _ = sol.forces(sol.t)
    assert np.allclose(f, np.stack([c.force for c in sol.contacts], axis=1), atol=1e-12)


def test_joint_torques_are_the_transposed_jacobian_times_the_force(
        planned: tuple[Any, Any]) -> None:
    """tau = J^T (f; r x f + tau_n n) with Pinocchio's Jacobian of the tip frame, r from
    its origin to the contact point (independent of the CasADi kinematics the plan used)."""
    problem, sol = planned
    for i, (tip, fin) in enumerate(zip(problem.fingers, sol.fingers, strict=True)):
        c = sol.contacts[i]  # no palm: the contacts are the fingertips
        for j in range(0, len(sol.t), 7):
            J = tip.finger.frame_jacobian_pin(fin.q[j])
            _, p_tip = tip.finger.fingertip_pose_pin(fin.q[j])
            moment = np.cross(c.point[j] - p_tip, c.force[j]) + c.torsion[j] * c.normal[j]
            expect = J[:3].T @ c.force[j] + J[3:].T @ moment
            assert np.allclose(fin.joint_torques[j], expect, rtol=1e-9, atol=1e-12)


def test_without_forces_the_nlp_and_the_plan_are_as_before() -> None:
    from test_manipulation import PLANNER

    from ocp.solve.planner import GraspStructure

    problem = two_fingers(n=10)
    assert not GraspStructure.of(problem).forces
    nlp, _ = PLANNER.build(problem)
    assert nlp.n_load == 0
    with_forces, _ = PLANNER.build(replace(problem, forces=LOAD))
    assert with_forces.n_load == 2
    # 4 variables per contact and point; rows: 6 equilibrium, 2 normal, 2 cone per point
    npts = 2 * 10 + 1
    assert with_forces.pack.nnz_out(0) - nlp.pack.nnz_out(0) == 4 * 2 * npts
    assert len(with_forces.lbg) - len(nlp.lbg) == 10 * npts


def test_three_hard_fingers_hold_the_ball_without_torsion() -> None:
    """Three fingers of the built-in hand turn the ball with hard point contacts (no
    torsional friction): the planned forces sit after the force-closure internal forces in
    the NLP; they balance the weight at every collocation point with no torsion at all."""
    from test_manipulation import DEG, OBJ, PLANNER

    from ocp.robots.hands import load_hand
    from ocp.solve.planner import (
        DesiredMotion,
        ManipulationProblem,
        MotionStep,
        ObjectPose,
        hand_fingertips,
    )

    hand = load_hand("three_finger")
    start = ObjectPose(position=hand.nominal_object_position)
    problem = ManipulationProblem(
        OBJ, hand_fingertips(hand, start, OBJ), 2.0, initial_pose=start,
        motion=DesiredMotion.from_steps(start, [MotionStep(2.0, (1.0, 0.0, 1.0), 10 * DEG)]),
        n_intervals=16, forces=replace(LOAD, torsional_friction=0.0, mass=0.1))
    sol = PLANNER.solve(problem)
    assert sol.ok, sol.message
    p_po, pts, nrm, f, tau = _points(problem, sol)
    assert np.all(tau == 0.0)
    assert np.max(np.abs(f.sum(axis=1) + 0.1 * np.asarray(LOAD.gravity))) < 1e-9
    moment = np.cross(pts - p_po[:, None], f).sum(axis=1)
    assert np.max(np.abs(moment)) < 1e-9 * problem.object.length_scale
    fn = -np.einsum("kci,kci->kc", nrm, f)
    assert np.all(fn >= LOAD.min_normal_force - 1e-9)


def test_two_stages_keep_the_kinematic_plan_and_agree_with_the_coupled_nlp(
        planned: tuple[Any, Any], monkeypatch: pytest.MonkeyPatch) -> None:
    """The forces are planned after the kinematics, point by point
    (ocp/transcription/force_stage.py): the plan with forces moves exactly as the plan
    without them; the coupled NLP (``two_stage_forces = False``) plans forces within 1 % of
    the largest force of the two-stage ones (measured 0.2 %: its forces' small objective
    terms pull the kinematics by up to 7e-4 of a state) and both are certified with
    them."""
    from test_manipulation import PLANNER

    problem, sol = planned
    plain = PLANNER.solve(replace(problem, forces=None))
    assert plain.ok and sol.ok
    assert np.array_equal(sol.X, plain.X)
    assert plain.contacts[0].force is None and sol.contacts[0].force is not None
    # its certificate: the kinematic one with the force checks added, the same values as
    # certifying the plan with its forces from scratch
    from ocp.solve.certify import certify_grasp

    assert sol.collocation is not None and sol._interpolant is not None
    pf = problem.with_intervals(len(sol.collocation.t_nodes) - 1)
    full = certify_grasp(pf, PLANNER.model(pf), sol.trajectory, sol._interpolant.prm,
                         pf.tolerances, sol.collocation.forces)
    assert {c.name: c.value for c in sol.certificate.checks} == pytest.approx(
        {c.name: c.value for c in full.checks}, rel=1e-12, abs=1e-15)
    monkeypatch.setattr(PLANNER, "two_stage_forces", False)
    coupled = PLANNER.solve(problem)
    assert coupled.ok, coupled.message
    assert coupled.certificate.passed and sol.certificate.passed
    f2 = np.stack([c.force for c in sol.contacts])
    fc = np.stack([c.force for c in coupled.contacts])
    assert np.max(np.abs(f2 - fc)) < 0.01 * np.max(np.abs(f2))
    assert 0 < np.max(np.abs(sol.X - coupled.X)) < 5e-3


def test_when_a_point_admits_no_forces_the_coupled_nlp_plans_them(
        planned: tuple[Any, Any], monkeypatch: pytest.MonkeyPatch) -> None:
    """The fallback's control flow: a force stage that finds no forces (here made to
    answer so; on real plans a grasp in force closure always admits them within the
    bounds) hands the problem to the coupled NLP, warm-started from the kinematic plan:
    the plan returned is the coupled one, certified with its forces, its statistics
    holding both solves."""
    from test_manipulation import PLANNER

    from ocp.transcription.force_stage import ForceStage

    problem, _ = planned
    monkeypatch.setattr(ForceStage, "solve", lambda self, *a, **k: (None, 0))
    out = PLANNER.solve(problem)
    assert out.ok, out.message
    assert out.contacts[0].force is not None
    assert {c.name for c in out.certificate.checks} >= {"max_force_equilibrium_residual",
                                                       "min_normal_force"}
    kinematic = PLANNER.solve(replace(problem, forces=None))
    assert out.iterations > kinematic.iterations
    assert not np.array_equal(out.X, kinematic.X)  # the coupled optimum moves a little


def test_joint_torques_hold_the_fingers_own_weight_when_its_model_has_inertias() -> None:
    """A finger whose URDF gives its links masses (the built-in one with 30 g links whose
    centres sit 15 mm along each link): its joint torques are J^T f plus the gradient of
    its links' potential energy, by central differences of the centre of mass's height
    (Pinocchio's centerOfMass, the base mounted in the palm frame); without inertias the
    gravity part is zero."""
    import re

    import pinocchio as pin

    from ocp.robots.finger import builtin_urdf_text, load_finger
    from ocp.solution import joint_torques

    plain = load_finger()
    inertial = ('<inertial><origin xyz="0.005 0.0 0.015" rpy="0 0 0"/><mass value="0.03"/>'
                '<inertia ixx="2e-6" ixy="0" ixz="0" iyy="2e-6" iyz="0" izz="1e-6"/>'
                '</inertial>')
    text = re.sub(r'(<link name="link\d">)', r"\1" + inertial, builtin_urdf_text())
    heavy = load_finger(text, base_rotation=plain.base_rotation,
                        base_position=plain.base_position)
    assert plain.mass == 0.0 and heavy.mass == pytest.approx(0.18)
    gravity = np.array([0.0, 0.0, -9.81])
    rng = np.random.default_rng(5)
    q = plain.lower + (plain.upper - plain.lower) * rng.uniform(0.3, 0.7, (3, plain.nq))
    data = heavy.model.createData()

    def potential(qk: np.ndarray) -> float:
        com = plain.base_rotation @ np.asarray(pin.centerOfMass(heavy.model, data, qk)) \
            + plain.base_position
        return -heavy.mass * float(gravity @ com)

    force, torsion = np.tile([0.3, -0.2, -1.0], (3, 1)), np.full(3, 0.001)
    tip = np.array([np.asarray(heavy.fk(qk)[1]).ravel() for qk in q])
    normal = np.tile([0.0, 0.0, 1.0], (3, 1))
    with_weight = joint_torques(heavy, q, tip, normal, force, torsion, gravity)
    without = joint_torques(plain, q, tip, normal, force, torsion, gravity)
    eps = 1e-6
    for k in range(3):
        grad = np.array([(potential(q[k] + eps * e) - potential(q[k] - eps * e)) / (2 * eps)
                         for e in np.eye(plain.nq)])
        assert np.max(np.abs(with_weight[k] - without[k] - grad)) < 1e-7
        assert np.max(np.abs(grad)) > 1e-3  # the weight matters at these angles
    assert np.array_equal(without, joint_torques(plain, q, tip, normal, force, torsion))
