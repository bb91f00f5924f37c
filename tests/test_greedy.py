"""Laws of the paper's own method (section 3) for one flat finger on a ball (ocp/methods/greedy.py).

The test problem: the built-in finger with a 50 mm half-size pad, a 25 mm ball rolled
10 mm along the palm's x in 2 s, the finger contact started 0.2 rad (11.5 deg) from the
top of the ball (a grasp angle of 0.1 rad, 5.7 deg), mu = 0.5. The finger contact's
chart patch is turned half a turn about the ball's z, so that its point (0, 0) is the
top of the ball at the start. Quantities are recomputed here from the returned
trajectories with closed-form sphere geometry or Pinocchio, not read back from the
planner's own reports.
"""

from __future__ import annotations

import math
from dataclasses import replace

import casadi as ca
import numpy as np
import pytest
from helpers import assert_close

from ocp.ball_on_palm import BallOnPalmPlanner
from ocp.geometry.contact import ContactPair
from ocp.geometry.grasp import grasp_angles_numeric
from ocp.geometry.surfaces import Plane, Sphere, rotation_from_vector
from ocp.methods.greedy import (
    CLOSURE_TOL,
    DEFAULT_ROLLING_RATE,
    GreedyResult,
    candidate_grid,
    greedy_plan,
    rotation_angle,
    rotation_ellipse,
)
from ocp.one_finger import FingerContact, OneFingerPlanner, OneFingerProblem
from ocp.robots.finger import load_finger
from ocp.solution import Solution
from ocp.spec.problem import BallOnPalmProblem, ObjectSpec, ProblemError, ViaPoint

RHO = 0.025  # ball radius [m]
U_F0 = 0.2  # initial tilt of the finger contact from the top of the ball [rad]
#: Round-off of angles rebuilt from cos/acos and of Euler-free identities [rad].
ATOL_ANGLE = 1e-9
#: The palm plan's goal: its collocation certificate bounds the re-integration defect by
#: 1e-6 m; the greedy integration uses the same input.
GOAL_TOL = 1e-6
#: How far the relative pose of finger and ball may wander when the finger does not roll:
#: the closure tolerance, for position [m] and orientation [rad].
RIGID_TOL = CLOSURE_TOL


# -- fixtures ---------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def problem() -> OneFingerProblem:
    base = BallOnPalmProblem(ObjectSpec("sphere", (RHO,)), (0.0, 0.0, 0.0, 0.0, -math.pi / 2),
                             {"x": 0.01, "y": 0.0}, 2.0)
    return OneFingerProblem(
        base, load_finger(pad_half_size=0.05),
        FingerContact(initial=(0.0, 0.0, U_F0, 0.0, 0.0), chart_rotation=(0.0, 0.0, math.pi)),
        mu=0.5)


@pytest.fixture(scope="module")
def palm_plan(problem: OneFingerProblem) -> Solution:
    plan = BallOnPalmPlanner().solve(problem.base)
    assert plan.ok, plan.message
    return plan


@pytest.fixture(scope="module")
def result(problem: OneFingerProblem, palm_plan: Solution) -> GreedyResult:
    return greedy_plan(problem, palm_plan=palm_plan)


@pytest.fixture(scope="module")
def triangle(problem: OneFingerProblem) -> GreedyResult:
    """The paper's experiment 1: the ball's palm contact around the triangle (0, 0),
    (30, 0), (30, 30) mm in 6 s with the paper's timing, the same finger contact at the
    start."""
    base = replace(problem.base, goal={"x": 0.0, "y": 0.0}, duration=6.0, n_intervals=60,
                   via_points=(ViaPoint(2.0, {"x": 0.03, "y": 0.0}),
                               ViaPoint(4.0, {"x": 0.03, "y": 0.03})), timing="paper")
    return greedy_plan(replace(problem, base=base))


@pytest.fixture(scope="module")
def coarse(problem: OneFingerProblem, palm_plan: Solution) -> GreedyResult:
    return greedy_plan(problem, n_steps=100, palm_plan=palm_plan)


@pytest.fixture(scope="module")
def open_loop(problem: OneFingerProblem, palm_plan: Solution) -> tuple[GreedyResult,
                                                                         GreedyResult]:
    """Without closure correction (the paper's pseudo-inverse alone), at 200 and 100 steps."""
    return (greedy_plan(problem, closure_gain=0.0, palm_plan=palm_plan),
            greedy_plan(problem, n_steps=100, closure_gain=0.0, palm_plan=palm_plan))


# -- closed-form sphere geometry --------------------------------------------------------------

def sphere_point(alpha: np.ndarray, chart_rotvec: tuple[float, float, float]) -> np.ndarray:
    """The ball point at chart coordinates (u, v) of a patch, in the ball frame [m]."""
    u, v = alpha
    f = RHO * np.array([math.cos(u) * math.cos(v), -math.cos(u) * math.sin(v), math.sin(u)])
    return np.asarray(rotation_from_vector(chart_rotvec) @ f)


def grasp_angle(problem: OneFingerProblem, alpha_op: np.ndarray, alpha_of: np.ndarray
                ) -> float:
    """max(Phi_p, Phi_f) [rad] of the two ball points (outward normals p / rho)."""
    p1 = sphere_point(alpha_op, problem.base.object.chart_rotation)
    p2 = sphere_point(alpha_of, problem.contact.chart_rotation)
    return max(grasp_angles_numeric(p1, p1 / RHO, p2, p2 / RHO))


def rolling_angles(result: GreedyResult) -> np.ndarray:
    """|Delta Theta| of every step from w_f: (1/rho) |R_psi M_o w_f| dt with
    M_o = diag(rho, rho cos u_f) at the step's start (R_psi is orthogonal)."""
    u = result.eta_f[:-1, 2]
    w = result.w_f[:-1]
    return np.hypot(w[:, 0], np.cos(u) * w[:, 1]) * result.dt


# -- the rotation bound and its ellipse -------------------------------------------------------

@pytest.mark.parametrize(("u", "psi"), [(0.0, 0.0), (0.4, -1.1), (-1.2, 2.5), (0.9, math.pi)])
def test_ellipse_inverts_the_corrected_rotation_formula(u: float, psi: float) -> None:
    """A maps (Delta Theta_x, Delta Theta_y) to the alpha_dot_of that rolls the finger by
    exactly that angle, with the curvature not inverted: for a sphere its singular values
    are 1/dt and 1/(dt cos u) (radius-free), the rolling velocity (1/rho) R_psi M_o w."""
    dt = 0.01
    M = np.diag([RHO, RHO * math.cos(u)])
    K = np.eye(2) / RHO
    A = rotation_ellipse(M, K, psi, dt)
    for theta in ([1.0, 0.0], [0.0, 1.0], [0.3, -0.7]):
        assert_close(rotation_angle(M, K, psi, A @ np.array(theta), dt), theta, atol=1e-12)
    assert_close(np.sort(np.linalg.svd(A, compute_uv=False)),
                 np.sort([1 / dt, 1 / (dt * math.cos(u))]), atol=0, rtol=1e-12)
    # against the contact module's rolling velocity (ball relative to pad): same magnitude
    pair = ContactPair(Sphere, Plane)
    w = A @ np.array([0.3, -0.7])
    omega = np.asarray(pair.rolling_velocity(ca.DM([u, 0.1, 0.0, 0.0, psi]), ca.DM(w),
                                             ca.DM([RHO]), ca.DM(0, 1))).ravel()
    assert_close(np.linalg.norm(omega) * dt, math.hypot(0.3, 0.7), atol=0, rtol=1e-12)


def test_candidate_grid_fills_the_unit_disc() -> None:
    pts = candidate_grid(9, 24)
    assert pts.shape == (2, 1 + 9 * 24)
    r = np.linalg.norm(pts, axis=0)
    assert r[0] == 0.0 and r.max() <= 1.0 + 1e-15
    assert_close(np.unique(np.round(r, 12)), np.arange(10) / 9, atol=1e-12)


def test_every_step_respects_the_rotation_bound(result: GreedyResult) -> None:
    assert result.delta == pytest.approx(DEFAULT_ROLLING_RATE * result.dt)
    theta = rolling_angles(result)
    assert np.all(theta <= result.delta * (1 + 1e-9)), theta.max()
    assert theta.max() > 0.5 * result.delta  # the bound is used: the contact did move


def test_finger_contact_moves_over_the_ball_by_its_velocity(result: GreedyResult) -> None:
    """The ball side of a contact driven by its motion over the ball advances by w_f dt."""
    assert_close(np.diff(result.eta_f[:, 2:4], axis=0), result.w_f[:-1] * result.dt,
                 atol=1e-12)


# -- grasp quality ----------------------------------------------------------------------------

def test_grasp_angle_decreases_towards_antipodal(problem: OneFingerProblem,
                                                 result: GreedyResult) -> None:
    phi = np.array([grasp_angle(problem, result.eta_p[k, 2:4], result.eta_f[k, 2:4])
                    for k in range(len(result.t))])
    assert_close(result.max_grasp_angle, phi, atol=ATOL_ANGLE)
    assert phi[0] == pytest.approx(U_F0 / 2, abs=ATOL_ANGLE)  # half the tilt from the top
    assert phi[-1] < phi[0] / 10
    assert np.all(phi <= phi[0] + ATOL_ANGLE)
    assert np.all(phi < math.atan(problem.mu))
    assert_close(result.cone_margin, math.atan(problem.mu) - phi, atol=ATOL_ANGLE)
    # it gets there at the bound's pace: the contact must turn by U_F0 at <= delta a step
    k_min = math.ceil(U_F0 / result.delta)
    assert np.argmax(phi < 0.01 * phi[0]) >= k_min - 1


def quantisation_bound(result: GreedyResult) -> float:
    """Grasp angle the grid search can always reach when an exactly antipodal step lies in
    the rotation disc [rad]: a point of the disc is within delta (1/(2 n_r) + pi/n_theta)
    of a grid point, the contact then that far (central angle) from antipodal, and the
    grasp angle of a sphere is half of that."""
    n_r, n_theta = result.grid
    return result.delta * (1 / (2 * n_r) + math.pi / n_theta) / 2


@pytest.mark.parametrize("which", ["result", "triangle"])
def test_once_antipodal_the_grasp_stays_within_the_grid_resolution(
        which: str, request: pytest.FixtureRequest) -> None:
    """While the ball rolls less than delta per step (so an antipodal step stays in reach),
    the grasp angle, once below the grid's resolution, stays there: at via-point corners too."""
    r: GreedyResult = request.getfixturevalue(which)
    bound = quantisation_bound(r)
    ball_roll = np.linalg.norm(r.w_p, axis=1) * r.dt / RHO  # ball's rolling per step [rad]
    assert ball_roll.max() + 4 * bound < r.delta  # the premise
    phi = r.max_grasp_angle
    k0 = int(np.argmax(phi <= bound))
    assert phi[k0] <= bound
    assert np.all(phi[k0:] <= bound), (phi[k0:].max(), bound)


def test_paper_triangle(problem: OneFingerProblem, triangle: GreedyResult) -> None:
    """Via-points and goal met by the integrated palm path, the finger on the pad and in
    closure all the way round (the built-in finger's mount reaches the whole triangle)."""
    assert max(triangle.goal_error.values()) <= GOAL_TOL
    assert len(triangle.goal_error) == 6
    assert triangle.pad_excursion <= problem.finger.pad_half_size - problem.pad_margin
    assert triangle.ok, triangle.failures
    assert np.all(rolling_angles(triangle) <= triangle.delta * (1 + 1e-9))


def test_each_step_is_no_worse_than_not_rolling(problem: OneFingerProblem,
                                                result: GreedyResult) -> None:
    """The origin is a candidate: the chosen step's grasp angle is at most the one reached
    by keeping the finger contact at its place on the ball while the ball rolls."""
    for k in range(len(result.t) - 1):
        still = grasp_angle(problem, result.eta_p[k + 1, 2:4], result.eta_f[k, 2:4])
        chosen = grasp_angle(problem, result.eta_p[k + 1, 2:4], result.eta_f[k + 1, 2:4])
        assert chosen <= still + ATOL_ANGLE, k


# -- palm, pad, closure, rolling --------------------------------------------------------------

def test_palm_path_reaches_the_goal(problem: OneFingerProblem, result: GreedyResult) -> None:
    assert set(result.goal_error) == {"goal.x", "goal.y"}
    assert max(result.goal_error.values()) <= GOAL_TOL
    assert_close(result.eta_p[-1, :2], [0.01, 0.0], atol=GOAL_TOL)
    assert_close(result.object_position[:, 2], RHO, atol=1e-12)  # the ball stays on the palm
    assert_close(result.object_position[:, :2], result.eta_p[:, :2], atol=1e-12)


def test_fingertip_stays_on_the_pad(problem: OneFingerProblem, result: GreedyResult) -> None:
    finger = problem.finger
    limit = finger.pad_half_size - problem.pad_margin
    assert np.all(np.abs(result.eta_f[:, 0:2]) <= limit)
    # Cartesian: the finger contact point, in the pad frame of Pinocchio's FK of q
    for k in range(0, len(result.t), 10):
        R, p = finger.fingertip_pose_pin(result.q[k])
        local = R.T @ (result.finger_contact_point[k] - p)
        assert np.all(np.abs(local[:2]) <= finger.pad_half_size), k
        assert abs(local[2]) <= CLOSURE_TOL[0], k  # on the pad's surface
        assert_close(local[:2], result.eta_f[k, 0:2], atol=CLOSURE_TOL[0])


def contact_pose(problem: OneFingerProblem, eta_p: np.ndarray, eta_f: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
    """g_pf = g_po g_of (eq. 6), composed here from the two contact pairs."""
    shape = ca.DM([RHO])
    none = ca.DM(0, 1)
    R_po, p_po = ContactPair(Plane, Sphere).pose(
        ca.DM(eta_p), none, shape, ca.DM.eye(3),
        ca.DM(rotation_from_vector(problem.base.object.chart_rotation)))
    e = ca.DM([eta_f[2], eta_f[3], eta_f[0], eta_f[1], eta_f[4]])
    R_of, p_of = ContactPair(Sphere, Plane).pose(
        e, shape, none, ca.DM(rotation_from_vector(problem.contact.chart_rotation)),
        ca.DM.eye(3))
    R_po, p_po, R_of, p_of = (np.asarray(a) for a in (R_po, p_po, R_of, p_of))
    return R_po @ R_of, (p_po + R_po @ p_of).ravel()


def closure(problem: OneFingerProblem, result: GreedyResult) -> tuple[float, float]:
    pos, rot = 0.0, 0.0
    for k in range(len(result.t)):
        R_c, p_c = contact_pose(problem, result.eta_p[k], result.eta_f[k])
        R, p = problem.finger.fingertip_pose_pin(result.q[k])
        pos = max(pos, float(np.linalg.norm(p - p_c)))
        c = (np.trace(R.T @ R_c) - 1) / 2
        rot = max(rot, math.acos(min(1.0, c)))
    return pos, rot


def test_closure_holds_with_the_correction(problem: OneFingerProblem,
                                           result: GreedyResult) -> None:
    """Tolerance: CLOSURE_TOL = 1e-4 m / 1e-3 rad (measured: ~3e-6 m, ~5e-5 rad)."""
    assert_close(result.q[0], OneFingerPlanner().initial_grasp(problem), atol=0)
    pos, rot = closure(problem, result)
    assert pos <= CLOSURE_TOL[0] and rot <= CLOSURE_TOL[1], (pos, rot)
    # The same quantities computed apart: equal to round-off. The angle is acos((tr - 1) / 2),
    # which amplifies the round-off of its argument (~1e-15) by 1 / sin(angle).
    assert result.closure_error[0] == pytest.approx(pos, abs=1e-12)
    assert result.closure_error[1] == pytest.approx(rot, abs=1e-14 / max(rot, 1e-7))
    assert result.ok, result.failures
    assert result.joint_limit_margin > 0.0 and result.max_velocity_ratio < 1.0


def test_open_loop_pseudo_inverse_drifts_first_order(
        problem: OneFingerProblem, result: GreedyResult,
        open_loop: tuple[GreedyResult, GreedyResult]) -> None:
    """Without the correction the Euler-integrated joints drift from the contact-derived
    pose, by an error that halves when dt halves (measured ~4e-5 m, ~6e-4 rad at 200
    steps); the correction keeps it far below."""
    fine, coarse_ = open_loop
    pos_f, rot_f = closure(problem, fine)
    pos_c, rot_c = closure(problem, coarse_)
    assert 1.6 < pos_c / pos_f < 2.4 and 1.6 < rot_c / rot_f < 2.4, (pos_c / pos_f,
                                                                       rot_c / rot_f)
    # the same contact plan either way; the correction cuts the drift
    assert_close(result.eta_f, fine.eta_f, atol=0)
    assert result.closure_error[0] < pos_f / 5 and result.closure_error[1] < rot_f / 5


def slip_per_step(result: GreedyResult) -> float:
    """Largest distance, after one step, between the pad's and the ball's material points
    that were at the finger contact at its start (pad from Pinocchio's FK of q)."""
    worst = 0.0
    R_f, p_f = result.fingertip_rotation, result.fingertip_position
    R_o, p_o = result.object_rotation, result.object_position
    c = result.finger_contact_point
    for k in range(len(result.t) - 1):
        pad = R_f[k + 1] @ (R_f[k].T @ (c[k] - p_f[k])) + p_f[k + 1]
        ball = R_o[k + 1] @ (R_o[k].T @ (c[k] - p_o[k])) + p_o[k + 1]
        worst = max(worst, float(np.linalg.norm(pad - ball)))
    return worst


def test_finger_rolls_without_slipping(result: GreedyResult, coarse: GreedyResult) -> None:
    """Over a step the two material points part by O(dt^2) (the contact point moves on),
    not O(dt): a quarter when dt halves."""
    ratio = slip_per_step(result) / slip_per_step(coarse)
    assert 0.15 < ratio < 0.35, ratio


# -- the finger that does not roll ------------------------------------------------------------

@pytest.mark.parametrize("settings", [{"delta": 0.0}, {"grid": (0, 1)}])
def test_without_rolling_the_finger_rides_on_the_ball(
        problem: OneFingerProblem, palm_plan: Solution, settings: dict[str, object]) -> None:
    """delta = 0, or a grid of the origin only: the finger contact never moves over the ball
    (w_f = 0); the grasp angle changes only by the ball's own rolling on the palm; the
    fingertip moves rigidly with the ball."""
    r = greedy_plan(problem, palm_plan=palm_plan, **settings)  # type: ignore[arg-type]
    assert np.all(r.w_f == 0.0)
    assert_close(r.eta_f, np.tile(problem.contact.initial, (len(r.t), 1)), atol=0)
    phi = [grasp_angle(problem, r.eta_p[k, 2:4], np.array(problem.contact.initial[2:4]))
           for k in range(len(r.t))]
    assert_close(r.max_grasp_angle, phi, atol=ATOL_ANGLE)
    assert phi[-1] > phi[0]  # the ball rolled the contact away from antipodal
    R_rel0 = r.object_rotation[0].T @ r.fingertip_rotation[0]
    p_rel0 = r.object_rotation[0].T @ (r.fingertip_position[0] - r.object_position[0])
    for k in range(len(r.t)):
        R_rel = r.object_rotation[k].T @ r.fingertip_rotation[k]
        p_rel = r.object_rotation[k].T @ (r.fingertip_position[k] - r.object_position[k])
        assert_close(p_rel, p_rel0, atol=RIGID_TOL[0])
        assert_close(R_rel, R_rel0, atol=RIGID_TOL[1])


# -- settings ---------------------------------------------------------------------------------

@pytest.mark.parametrize("bad", [{"delta": -0.01}, {"delta": math.nan}, {"grid": (3, 0)},
                                 {"n_steps": 0}, {"closure_gain": 1.5}])
def test_bad_settings_are_rejected(problem: OneFingerProblem, palm_plan: Solution,
                                   bad: dict[str, object]) -> None:
    with pytest.raises(ProblemError):
        greedy_plan(problem, palm_plan=palm_plan, **bad)  # type: ignore[arg-type]


def test_impossible_initial_grasp_is_rejected(problem: OneFingerProblem,
                                              palm_plan: Solution) -> None:
    """A contact 1.2 rad from the top is a grasp angle of 0.6 rad > atan(0.5)."""
    far = replace(problem, contact=replace(problem.contact, initial=(0.0, 0.0, 1.2, 0.0, 0.0)))
    with pytest.raises(ProblemError, match="friction cone"):
        greedy_plan(far, palm_plan=palm_plan)
