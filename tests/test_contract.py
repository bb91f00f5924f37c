"""The contract every planner keeps (learnt from Crocoddyl's abstract test case): the same
laws, on a real solve, for the object on the palm alone, one finger pressing it on the
palm, two fingers holding it in the air and three fingers of a hand.

Each front end returns the grasp pipeline's plan (:class:`ManipulationSolution`); on it:

* it is solved and its independent certificate passed (the re-integration defects within
  their tolerances among its checks);
* no slip and no spin at every contact, from the returned trajectory itself: the
  velocities of the two bodies' material points at each contact and their angular
  velocities about its normal, by central differences of the returned interpolant at the
  interval midpoints (the collocation points inside the intervals), the fingers placed by
  Pinocchio's forward kinematics of the returned joint angles;
* each fingertip where its joints put it (closure, Pinocchio) and on the object's surface;
* the goals and via-points met, the tracking tolerances held on the grid;
* ``sample(t)`` is the grid at the grid's own times;
* a warm-start round trip: the plan as its own warm start is solved again to the same plan.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from helpers import assert_close

from ocp.ball_on_palm import BallOnPalmPlanner
from ocp.certify.certificate import CheckKind
from ocp.one_finger import OneFingerPlanner
from ocp.robots.hands import load_hand
from ocp.solution import ManipulationSolution, Status
from ocp.solve.planner import (
    DesiredMotion,
    ManipulationPlanner,
    ManipulationProblem,
    MotionStep,
    ObjectPose,
    Tracking,
    hand_fingertips,
)
from ocp.spec.problem import BallOnPalmProblem, ObjectSpec, ViaPoint

GENERAL = ManipulationPlanner()
RHO = 0.025
DEG = math.pi / 180


def palm_alone() -> tuple[Any, Any, Callable[[Any], ManipulationSolution]]:
    problem = BallOnPalmProblem(
        object=ObjectSpec("sphere", (RHO,)), initial=(0.0, 0.0, 0.0, 0.0, 0.0),
        goal={"x": 0.01, "y": 0.0, "psi": 0.4}, duration=2.0,
        via_points=(ViaPoint(1.0, {"x": 0.02, "y": 0.01}),), n_intervals=20)
    planner = BallOnPalmPlanner(general=GENERAL)
    return planner, problem, lambda sol: sol.plan


def one_finger() -> tuple[Any, Any, Callable[[Any], ManipulationSolution]]:
    from test_manipulation import one_finger_roll

    return OneFingerPlanner(GENERAL), one_finger_roll(), lambda sol: sol.plan


def two_fingers() -> tuple[Any, Any, Callable[[Any], ManipulationSolution]]:
    from test_manipulation import two_fingers as problem

    return GENERAL, problem(n=20), lambda sol: sol


def three_fingers() -> tuple[Any, Any, Callable[[Any], ManipulationSolution]]:
    hand = load_hand("three_finger")
    obj = ObjectSpec("sphere", (RHO,))
    start = ObjectPose(position=hand.nominal_object_position)
    problem = ManipulationProblem(
        obj, hand_fingertips(hand, start, obj), 2.0, initial_pose=start,
        motion=DesiredMotion.from_steps(start, [MotionStep(2.0, (0.0, 0.0, 1.0), 20 * DEG)]),
        tracking=Tracking(position_tolerance=1e-3, orientation_tolerance=DEG),
        n_intervals=16)
    return GENERAL, problem, lambda sol: sol


def round_tips() -> tuple[Any, Any, Callable[[Any], ManipulationSolution]]:
    """The built-in Allegro-class hand (4 fingers, 16 joints, capsule tips of 12 mm) turning
    a 60 mm ball in its nominal grasp (issue 14)."""
    from ocp.robots.allegro import (
        NOMINAL_OBJECT_POSITION,
        NOMINAL_Q,
        NOMINAL_RADIUS,
        load_allegro,
    )
    from ocp.spec.grasp import fingertips_from_joints

    hand = load_allegro()
    obj = ObjectSpec("sphere", (NOMINAL_RADIUS,))
    start = ObjectPose(position=NOMINAL_OBJECT_POSITION)
    names = ("index", "middle", "ring", "thumb")
    problem = ManipulationProblem(
        obj, fingertips_from_joints(hand.fingers, NOMINAL_Q, obj, start, names, names), 2.0,
        initial_pose=start,
        motion=DesiredMotion.from_steps(start, [MotionStep(2.0, (0.0, 0.0, 1.0), 8 * DEG)]),
        tracking=Tracking(position_tolerance=1e-3, orientation_tolerance=DEG),
        n_intervals=12)
    return GENERAL, problem, lambda sol: sol


CASES = {"palm_alone": palm_alone, "one_finger": one_finger, "two_fingers": two_fingers,
         "three_fingers": three_fingers, "round_tips": round_tips}


@pytest.fixture(scope="module", params=list(CASES))
def case(request: pytest.FixtureRequest) -> tuple[Any, Any, Any, ManipulationSolution]:
    planner, problem, plan_of = CASES[request.param]()
    sol = planner.solve(problem)
    return planner, problem, sol, plan_of(sol)


def _twist(R: np.ndarray, p: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """(omega, p_dot) from poses at t - dt and t + dt (rows k, 2, ...)."""
    Rd = (R[:, 1] - R[:, 0]) / (2 * dt)
    Rm = (R[:, 1] + R[:, 0]) / 2
    W = np.einsum("kij,klj->kil", Rd, Rm)  # R_dot R^T
    omega = np.stack([W[:, 2, 1] - W[:, 1, 2], W[:, 0, 2] - W[:, 2, 0],
                      W[:, 1, 0] - W[:, 0, 1]], axis=1) / 2
    return omega, (p[:, 1] - p[:, 0]) / (2 * dt)


def test_solved_and_certified(case: tuple[Any, Any, Any, ManipulationSolution]) -> None:
    _, _, sol, plan = case
    assert sol.status is Status.SOLVED and plan.status is Status.SOLVED, plan.message
    cert = plan.certificate
    assert cert.passed and not plan.certificate_failures
    defects = [c for c in cert.checks if c.name.endswith("_defect")]
    assert {c.name for c in defects} >= {"max_length_defect", "max_angle_defect"}
    assert all(c.kind is CheckKind.DISCRETISATION and 0 <= c.value <= c.tolerance
               for c in defects)


def test_no_slip_and_no_spin_on_the_returned_trajectory(
        case: tuple[Any, Any, Any, ManipulationSolution]) -> None:
    _, problem, _, plan = case
    assert plan.collocation is not None
    tn = plan.collocation.t_nodes
    tm = (tn[:-1] + tn[1:]) / 2
    dt = 1e-6 * float(tn[-1])
    smp = plan.sample(np.stack([tm - dt, tm + dt], axis=1).ravel())
    k = len(tm)
    R = smp.object_rotation.reshape(k, 2, 3, 3)
    p = smp.object_position.reshape(k, 2, 3)
    omega_o, v_o = _twist(R, p, dt)
    mid = slice(1, None, 2)  # the grid's midpoints (nodes and midpoints alternate)
    # the certificate's speed scale (ocp.solve.certify), here from the returned grid
    speed = max(float(np.max(np.abs(plan.object_velocity))) + RHO * float(
        np.max(np.abs(plan.object_angular_velocity))) + RHO * float(np.max(np.abs(plan.U))),
        1e-3)
    models = {}
    if hasattr(problem, "fingers"):
        models = {(t.name or f"finger{i}"): t.finger for i, t in enumerate(problem.fingers)}
    elif hasattr(problem, "finger"):
        models = {plan.fingers[0].name: problem.finger}
    for contact in plan.contacts:
        c = contact.point[mid]  # palm frame
        n = contact.normal[mid]
        v_obj = np.cross(omega_o, c - p.mean(axis=1)) + v_o
        if contact.body == "palm":
            omega_b, v_b = np.zeros_like(omega_o), np.zeros_like(v_o)
        else:
            qs = _joints(plan, smp.x, contact.name)  # at the sampled times, through Pinocchio
            poses = [models[contact.name].fingertip_pose_pin(qq) for qq in qs]
            Rf = np.array([a for a, _ in poses]).reshape(k, 2, 3, 3)
            pf = np.array([b for _, b in poses]).reshape(k, 2, 3)
            omega_b, pf_dot = _twist(Rf, pf, dt)
            v_b = np.cross(omega_b, c - pf.mean(axis=1)) + pf_dot
        slip = np.linalg.norm(v_b - v_obj, axis=1)
        spin = np.abs(np.einsum("ki,ki->k", omega_b - omega_o, n))
        # the palm contact rolls by its own equations: no slip to round-off; a fingertip
        # follows its joints, whose closure holds at the collocation points but not its
        # rate: the certificate's tolerance for fingers (docs/conventions.md)
        frac = 1e-6 if contact.body == "palm" else 1e-2
        assert np.max(slip) <= frac * speed, (contact.name, np.max(slip), speed)
        assert np.max(spin) <= frac * speed / RHO, (contact.name, np.max(spin))


def _joints(plan: ManipulationSolution, x: np.ndarray, name: str) -> np.ndarray:
    """A finger's joint columns of sampled states: located by the grid's own values."""
    f = next(f for f in plan.fingers if f.name == name)
    X = plan.X
    nq = f.q.shape[1]
    for start in range(X.shape[1] - nq + 1):
        if np.array_equal(X[:, start:start + nq], f.q):
            return x[:, start:start + nq]
    raise AssertionError(f"joints of {name} not found in the states")


def test_each_fingertip_is_where_its_joints_put_it_and_touches_the_object(
        case: tuple[Any, Any, Any, ManipulationSolution]) -> None:
    _, problem, _, plan = case
    finger_models = [t.finger for t in problem.fingers] if hasattr(problem, "fingers") \
        else [problem.finger] if hasattr(problem, "finger") else []
    for model, f in zip(finger_models, plan.fingers, strict=True):
        for i in range(0, len(plan.t), 3):
            R_pin, p_pin = model.fingertip_pose_pin(f.q[i])
            assert_close(p_pin, f.tip_position[i], atol=1e-6)
            assert_close(R_pin, f.tip_rotation[i], atol=1e-5)
        tip = model.tip_surface
        rho = float(problem.object.dimensions[0]) if hasattr(problem, "object") else RHO
        if tip.round:  # a round tip: its centre rho + r from the ball's
            centre = f.tip_position + np.einsum("kij,j->ki", f.tip_rotation, tip.p)
            assert_close(np.linalg.norm(centre - plan.object_position, axis=1),
                         rho + tip.params[0], atol=1e-6)
            continue
        # a flat pad tangent to the ball: the centre one radius above the pad's plane
        d = np.einsum("ki,ki->k", plan.object_position - f.tip_position,
                      f.tip_rotation[:, :, 2])
        assert_close(d, RHO, atol=1e-6)
    rho = float(problem.object.dimensions[0]) if hasattr(problem, "object") else RHO
    for contact in plan.contacts:  # every contact point on the ball
        assert_close(np.linalg.norm(contact.point - plan.object_position, axis=1), rho,
                     atol=1e-9)


def test_goals_are_met_and_tracking_held(
        case: tuple[Any, Any, Any, ManipulationSolution]) -> None:
    _, problem, _, plan = case
    assert all(v <= 1e-6 for v in plan.goal_error.values()), plan.goal_error
    if plan.tracking_position_error is not None:
        tr = problem.tracking
        assert np.max(plan.tracking_position_error) <= tr.position_tolerance
        assert np.max(plan.tracking_angle_error) <= tr.orientation_tolerance


def test_sample_is_the_grid_at_its_own_times(
        case: tuple[Any, Any, Any, ManipulationSolution]) -> None:
    _, _, sol, plan = case
    smp = plan.sample(plan.t)
    # the nodes exactly; the midpoints to the collocation defect IPOPT left (the Hermite
    # cubic's midpoint is the NLP's midpoint state when the defect is zero)
    nodes = slice(0, None, 2)
    assert_close(smp.x[nodes], plan.X[nodes], atol=1e-12)
    assert_close(smp.x, plan.X, atol=1e-9)
    assert_close(smp.object_position, plan.object_position, atol=1e-9)
    assert_close(smp.object_rotation, plan.object_rotation, atol=1e-9)
    # inputs: equal except at via-point nodes, where the grid holds the incoming side
    assert plan.collocation is not None
    via_nodes = np.isin(plan.t, plan.collocation.t_nodes[1:-1]) & np.isin(
        plan.t, _via_times(plan))
    assert_close(smp.u[~via_nodes], plan.U[~via_nodes], atol=1e-12)
    # the front end's own sample: the same plan
    own = sol.sample(plan.t)
    own_x = own.x if hasattr(own, "x") else own.eta
    assert_close(own_x, smp.x[:, : own_x.shape[1]], atol=1e-12)


def _via_times(plan: ManipulationSolution) -> np.ndarray:
    """Node times where the input has two sides (the segments' inner ends)."""
    col = plan.collocation
    assert col is not None
    jumps = [k for k in range(1, len(col.t_nodes) - 1)
             if not np.array_equal(col.U1[k - 1], col.U0[k])]
    return col.t_nodes[jumps]


def test_a_plan_warm_starts_itself_to_the_same_plan(
        case: tuple[Any, Any, Any, ManipulationSolution]) -> None:
    planner, problem, sol, plan = case
    again = planner.solve(problem, sol)
    again_plan = again if isinstance(again, ManipulationSolution) else again.plan
    assert again.status is Status.SOLVED
    assert again_plan.stats is not None and plan.stats is not None
    assert again_plan.stats.iterations <= plan.stats.iterations
    assert again_plan.certificate.passed
    # the same motion of the object (the optimum is flat along some joint directions)
    assert_close(again_plan.object_position, plan.object_position, atol=1e-5)
    R_rel = np.einsum("kji,kjl->kil", plan.object_rotation, again_plan.object_rotation)
    angle = np.arccos(np.clip((np.trace(R_rel, axis1=1, axis2=2) - 1) / 2, -1.0, 1.0))
    assert np.max(angle) <= 1e-3
