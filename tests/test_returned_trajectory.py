"""The certificate vouches for the trajectory a user receives (docs/conventions.md).

Laws on real plans (the object on the palm alone, three fingers of a hand holding it):

* a plan whose returned trajectory is perturbed between collocation points (a slip
  injected, a midpoint state moved by 1e-3 rad) fails its certificate, which names the
  check and the time of the worst sample;
* the certificate's slip is the slip of the returned samples, by an independent numeric
  derivative of the returned poses (the fingers placed by Pinocchio);
* ``sample(t)`` agrees with the collocation grid to round-off;
* a joint trajectory's velocities are the time derivative of its positions, and its
  accelerations that of its velocities; at a fixed rate it starts at 0 and ends at the
  plan's duration.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
import pytest
from helpers import assert_close
from test_contract import CASES

from ocp.certify.certificate import CHECK_POINTS, Certificate, CheckKind
from ocp.solution import ManipulationSolution, Status, fixed_rate_times
from ocp.solve.certify import certify_grasp
from ocp.transcription.collocation import HermiteInterpolant


class _Bumped(HermiteInterpolant):
    """The returned trajectory with ``size`` x bump(s) added to one state column on one
    interval (a perturbation a certificate of the returned samples must see)."""

    interval: int = 0
    column: int = 0
    size: float = 0.0
    bump: Any = None

    def on_intervals(self, k: Any, s: Any, order: int = 0) -> Any:
        out = np.array(super().on_intervals(k, s, order))
        h = self.t_nodes[self.interval + 1] - self.t_nodes[self.interval]
        here = np.asarray(k) == self.interval
        out[here, self.column] += self.size * self.bump(np.asarray(s)[here], order) / h**order
        return out


def _bumped(traj: HermiteInterpolant, interval: int, column: int, size: float,
            bump: Any) -> _Bumped:
    b = _Bumped(traj.t_nodes, traj.X, traj.F0, traj.F1, traj.U0, traj.Um, traj.U1)
    for name, value in (("interval", interval), ("column", column), ("size", size),
                        ("bump", bump)):
        object.__setattr__(b, name, value)
    return b


def _between(s: Any, order: int) -> Any:
    """sin^2(2 pi s): zero with zero slope at s = 0, 1/2, 1 (the collocation points)."""
    w = 2 * math.pi
    return np.sin(w * s) ** 2 if order == 0 else w * np.sin(2 * w * s)


def _at_midpoint(s: Any, order: int) -> Any:
    """16 s^2 (1 - s)^2: 1 at the midpoint, zero with zero slope at the nodes."""
    return 16 * (s * (1 - s)) ** 2 if order == 0 else 32 * s * (1 - s) * (1 - 2 * s)


@pytest.fixture(scope="module", params=["palm_alone", "three_fingers"])
def solved(request: pytest.FixtureRequest) -> tuple[Any, Any, ManipulationSolution]:
    planner, problem, plan_of = CASES[request.param]()
    sol = planner.solve(problem)
    plan = plan_of(sol)
    assert plan.status is Status.SOLVED, plan.message
    return getattr(planner, "general", planner), plan, problem


def _grasp_problem(problem: Any) -> Any:
    from ocp.ball_on_palm import grasp_problem
    from ocp.spec.problem import BallOnPalmProblem

    return grasp_problem(problem) if isinstance(problem, BallOnPalmProblem) else problem


def _certify(general: Any, problem: Any, plan: ManipulationSolution,
             traj: HermiteInterpolant) -> Certificate:
    # the problem on the plan's own grid (after its refinements)
    grasp = _grasp_problem(problem).with_intervals(len(traj.t_nodes) - 1)
    assert plan._interpolant is not None
    return certify_grasp(grasp, general.model(grasp), traj, plan._interpolant.prm,
                         grasp.tolerances)


def test_the_certificate_is_the_returned_trajectorys(solved: Any) -> None:
    general, plan, problem = solved
    again = _certify(general, problem, plan, plan.trajectory)
    assert again.passed
    assert again.to_dict() == plan.certificate.to_dict()
    assert again.n_samples == len(CHECK_POINTS) * (len(plan.trajectory.t_nodes) - 1)


def test_a_slip_between_collocation_points_fails_naming_check_and_time(solved: Any) -> None:
    general, plan, problem = solved
    traj = plan.trajectory
    j = len(traj.t_nodes) // 2
    # the object moved between the collocation points, its contacts' coordinates not:
    # the palm contact's x (the object on the palm) or the free object's x, by 1e-4 of
    # its size
    size = 1e-4 * 0.025
    bad = _certify(general, problem, plan, _bumped(traj, j, 0, size, _between))
    assert not bad.passed and bad.refinable
    slips = [c for c in bad.checks if c.name.startswith("max_slip_speed") and not c.passed]
    assert slips, bad.failures
    t0, t1 = traj.t_nodes[j], traj.t_nodes[j + 1]
    for c in slips:
        assert c.time is not None and t0 < c.time < t1 and c.time != (t0 + t1) / 2
        assert f"at t = {c.time:.6g} s" in c.failure
    # nothing else of the plan changed: the collocation points themselves still pass
    assert all(c.passed for c in bad.checks if "defect" in c.name)


def test_a_midpoint_moved_by_a_milliradian_fails_naming_check_and_time(solved: Any) -> None:
    general, plan, problem = solved
    traj = plan.trajectory
    j = 1
    t_mid = (traj.t_nodes[j] + traj.t_nodes[j + 1]) / 2
    grasp = _grasp_problem(problem)
    m = general.model(grasp)
    if m.fingertips:  # a joint of the first finger: the fingertip leaves its contact
        # (the joint defect's tolerance, 10 x cert_angle_tol, is this 1e-3 rad itself)
        column, names = m.fingertips[0].q_cols.start, ("max_closure_position_error",
                                                       "max_closure_orientation_error")
    else:  # the palm contact's angle psi: the object turns on the spot
        column, names = 4, ("max_angle_defect",)
    bad = _certify(general, problem, plan, _bumped(traj, j, column, 1e-3, _at_midpoint))
    failed = {c.name: c for c in bad.checks if not c.passed}
    for name in names:
        assert name in failed, bad.failures
        assert failed[name].time == pytest.approx(t_mid, abs=1e-12)
        assert failed[name].kind is CheckKind.DISCRETISATION


def _twist(R: Any, p: Any, dt: float) -> tuple[Any, Any]:
    """(omega, p_dot) at the middle of poses at t - dt, t, t + dt (axis 1)."""
    Rd = (R[:, 2] - R[:, 0]) / (2 * dt)
    W = np.einsum("kij,klj->kil", Rd, R[:, 1])  # R_dot R^T
    omega = np.stack([W[:, 2, 1] - W[:, 1, 2], W[:, 0, 2] - W[:, 2, 0],
                      W[:, 1, 0] - W[:, 0, 1]], axis=1) / 2
    return omega, (p[:, 2] - p[:, 0]) / (2 * dt)


def test_the_certificates_slip_is_the_returned_samples_slip(solved: Any) -> None:
    """Independent of the certificate's CasADi laws: the returned poses sampled inside
    every interval, differentiated numerically, the fingers placed by Pinocchio."""
    general, plan, problem = solved
    grasp = _grasp_problem(problem)
    m = general.model(grasp)
    traj = plan.trajectory
    n = len(traj.t_nodes) - 1
    s = np.array([p for p in CHECK_POINTS if 0 < p < 1])  # inside: the rate is two-sided
    k = np.repeat(np.arange(n), len(s))
    t = traj.t_nodes[k] + np.diff(traj.t_nodes)[k] * np.tile(s, n)
    dt = 1e-6
    smp = plan.sample(np.stack([t - dt, t, t + dt], axis=1).ravel())
    rows = len(t)
    R = smp.object_rotation.reshape(rows, 3, 3, 3)
    p = smp.object_position.reshape(rows, 3, 3)
    omega_o, v_o = _twist(R, p, dt)
    assert plan._interpolant is not None
    cart = m.mapped("cartesian", 3 * rows)(smp.x.T, plan._interpolant.prm)
    points = np.asarray(cart[4]).T.reshape(rows, 3, m.n_contacts, 3)[:, 1]
    for j, contact in enumerate(m.point_contacts):
        c = points[:, j]
        v_obj = v_o + np.cross(omega_o, c - p[:, 1])
        if contact.body == "palm":
            slip = v_obj
            name = "max_slip_speed_palm"
        else:
            tip = m.fingertips[m.fingertips.index(contact)]  # type: ignore[arg-type]
            q = smp.x[:, tip.q_cols].reshape(rows, 3, -1)
            poses = [[tip.finger.fingertip_pose_pin(q[i, a]) for a in range(3)]
                     for i in range(rows)]
            Rf = np.array([[pose[0] for pose in row] for row in poses])
            pf = np.array([[pose[1] for pose in row] for row in poses])
            omega_f, v_f = _twist(Rf, pf, dt)
            slip = v_f + np.cross(omega_f, c - pf[:, 1]) - v_obj
            name = f"max_slip_speed_{tip.label(grasp)}"
        numeric = float(np.max(np.linalg.norm(slip, axis=1)))
        check = plan.certificate.check(name)
        # the certificate's samples include the nodes (one-sided), these only the inside
        assert numeric <= check.value * (1 + 1e-3) + 1e-9 * check.tolerance
        inside = np.isin(np.round(np.tile(s, n), 12), np.round(s, 12))
        assert inside.all()
        # where the certificate's worst sample is inside an interval, it is this one
        if check.time is not None and not np.any(np.isclose(check.time, traj.t_nodes)):
            i = int(np.argmin(np.abs(t - check.time)))
            assert_close(np.linalg.norm(slip[i]), check.value, atol=1e-9 * check.tolerance,
                         rtol=1e-3)


def test_sample_agrees_with_the_collocation_grid_to_round_off(solved: Any) -> None:
    _, plan, _ = solved
    smp = plan.sample(plan.t)
    assert_close(smp.x, plan.X, atol=1e-14 * max(1.0, float(np.max(np.abs(plan.X)))))
    col = plan.collocation
    assert col is not None
    assert_close(plan.sample(col.t_nodes).x, col.X, atol=1e-15)
    # the NLP's own midpoint states: the same to its constraint tolerance
    assert_close(plan.X[1::2], col.Xm, atol=1e-7)


def test_joint_trajectory_rates_are_the_derivatives_of_its_positions(solved: Any) -> None:
    _, plan, _ = solved
    if not plan.fingers:
        pytest.skip("the object on the palm alone has no joints")
    T = plan.duration
    jt = plan.joint_trajectory(fixed_rate_times(T, 500.0))
    assert jt.t[0] == 0.0 and jt.t[-1] == T and np.all(np.diff(jt.t) > 0)
    assert_close(np.diff(jt.t)[:-1], 1 / 500.0, atol=1e-12)
    assert len(jt.joint_names) == sum(len(f.joint_names) for f in plan.fingers)
    assert len(set(jt.joint_names)) == len(jt.joint_names)
    # central differences at times inside intervals; the positions are cubic there, so
    # the difference's error is dt^2/6 |q'''| + round-off: far below 1e-7 at dt = 1e-5 s
    traj = plan.trajectory
    t = (traj.t_nodes[:-1] + 0.3 * np.diff(traj.t_nodes))
    dt = 1e-5
    a, b, c = (plan.joint_trajectory(t + d) for d in (-dt, 0.0, dt))
    assert_close(b.velocities, (c.positions - a.positions) / (2 * dt), atol=1e-7)
    assert_close(b.accelerations, (c.velocities - a.velocities) / (2 * dt), atol=1e-5)
    d = jt.to_dict()
    assert d["joint_names"] == list(jt.joint_names)
    last = d["points"][-1]
    assert last["time_from_start"]["sec"] + last["time_from_start"]["nanosec"] * 1e-9 == \
        pytest.approx(T, abs=1e-9)
    assert len(last["positions"]) == len(last["velocities"]) == len(jt.joint_names)


def test_via_point_rates_are_reported_from_both_sides() -> None:
    """The object on the palm with a via-point (the paper's piecewise inputs): the state
    is continuous at the via-point node and its two one-sided rates are those of the
    two intervals' polynomials."""
    planner, problem, plan_of = CASES["palm_alone"]()
    plan = plan_of(planner.solve(dataclasses.replace(problem, max_refinements=0,
                                                     timing="paper")))
    breaks = plan.break_nodes()
    assert len(breaks) == 1
    traj = plan.trajectory
    k = breaks[0]
    tk = traj.t_nodes[k:k + 1]
    left, right = plan.sample(tk, side="left"), plan.sample(tk, side="right")
    assert_close(left.x, right.x, atol=1e-15)
    assert np.max(np.abs(left.x_dot - right.x_dot)) > 1e-4  # a real jump
    eps = 1e-7
    before, after = plan.sample(tk - eps), plan.sample(tk + eps)
    assert_close(left.x_dot, before.x_dot, atol=1e-5)
    assert_close(right.x_dot, after.x_dot, atol=1e-5)
