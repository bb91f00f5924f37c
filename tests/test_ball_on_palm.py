"""Laws checked on real ball-on-palm plans (no numbers copied from a run)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from helpers import assert_close

from ocp.ball_on_palm import (
    BallOnPalmPlanner,
    certify,
    contact_coordinates,
    model_for,
    object_pose,
)
from ocp.geometry.surfaces import rotation_from_vector
from ocp.solution import Solution, Status, Trajectory
from ocp.spec.problem import (
    CONTACT_COORDS,
    BallOnPalmProblem,
    ObjectSpec,
    SolverOptions,
    ViaPoint,
)

RHO = 0.025
SPHERE = ObjectSpec("sphere", (RHO,))
ELLIPSOID = ObjectSpec("ellipsoid", (0.025, 0.035))
GOAL_TOL = 1e-6  # m or rad: goals are equality constraints of the NLP

PLANNER = BallOnPalmPlanner()


def triangle(n: int = 60) -> BallOnPalmProblem:
    """The paper's experiment 1 palm path: (0,0) -> (30,0) -> (30,30) -> (0,0) mm, with
    the paper's piecewise timing (its straight segments at constant speed)."""
    return BallOnPalmProblem(
        object=SPHERE, initial=(0.0, 0.0, 0.0, 0.0, -math.pi / 2), goal={"x": 0.0, "y": 0.0},
        duration=6.0, n_intervals=n, timing="paper",
        via_points=(ViaPoint(2.0, {"x": 0.03, "y": 0.0}), ViaPoint(4.0, {"x": 0.03, "y": 0.03})))


def reorientation(obj: ObjectSpec, rotvec: tuple[float, float, float], n: int = 50
                  ) -> tuple[BallOnPalmProblem, np.ndarray]:
    """Same palm point, object turned by the spatial rotation ``rotvec``; and the goal R."""
    eta0 = (0.0, 0.0, 0.0, 0.0, 0.0)
    R0, _ = object_pose(obj, eta0)
    R_goal = rotation_from_vector(rotvec) @ R0
    goal = dict(zip(CONTACT_COORDS, contact_coordinates(obj, (0.0, 0.0), R_goal), strict=True))
    return BallOnPalmProblem(object=obj, initial=eta0, goal=goal, duration=2.0,
                             n_intervals=n), R_goal


@pytest.fixture(scope="module")
def triangle_plan() -> Solution:
    return PLANNER.solve(triangle())


def finite_difference_slip(sol: Solution, duration: float, n: int = 400
                           ) -> tuple[float, float]:
    """Worst slip speed and spin rate of the sampled plan, relative to the rolling motion.

    Computed from the Cartesian samples only (object pose, contact point) by central
    differences in time: independent of the contact coordinates, the charts and the
    certificate. The samples come from the collocation polynomials, so they obey the laws
    only to interpolation accuracy (~1e-3 here); a wrong rolling law gives O(1).
    """
    dt = 1e-5
    t = np.linspace(2 * dt, duration - 2 * dt, n)
    a, b, c = sol.sample(t - dt), sol.sample(t), sol.sample(t + dt)
    # the object's material point that touches the palm at time t, in the object frame
    p_obj = np.einsum("kji,kj->ki", b.object_rotation, b.contact_point - b.object_position)

    def world(s: Trajectory) -> np.ndarray:
        return np.einsum("kij,kj->ki", s.object_rotation, p_obj) + s.object_position

    v = (world(c) - world(a)) / (2 * dt)
    R_dot = (c.object_rotation - a.object_rotation) / (2 * dt)
    W = np.einsum("kij,klj->kil", R_dot, b.object_rotation)
    omega = np.stack([W[:, 2, 1], W[:, 0, 2], W[:, 1, 0]], axis=1)
    spin = np.abs(np.einsum("ki,ki->k", omega, b.contact_normal))
    speed = float(np.max(np.linalg.norm(b.w, axis=1)))
    omega_max = float(np.max(np.linalg.norm(omega, axis=1)))
    return float(np.max(np.linalg.norm(v, axis=1))) / speed, float(np.max(spin)) / omega_max


# -- the paper's triangle --------------------------------------------------------------------

def test_triangle_is_solved_with_certificate(triangle_plan: Solution) -> None:
    assert triangle_plan.status is Status.SOLVED, triangle_plan.message
    assert triangle_plan.certificate.passed, triangle_plan.certificate.failures


def test_triangle_passes_its_via_points_at_their_times(triangle_plan: Solution) -> None:
    problem = triangle()
    for vp in problem.via_points:
        eta = triangle_plan.sample([vp.time]).eta[0]
        assert_close(eta[:2], [vp.coords["x"], vp.coords["y"]], atol=GOAL_TOL)
    assert_close(triangle_plan.nodes.eta[-1, :2], [0.0, 0.0], atol=GOAL_TOL)


def test_triangle_effort_is_the_straight_line_optimum(triangle_plan: Solution) -> None:
    """The effort integral |w|^2 dt does not see the ball: between via-points the optimum
    is the straight segment at constant speed, with effort sum d_s^2 / T_s."""
    problem = triangle()
    pts = np.array([[0, 0], [0.03, 0], [0.03, 0.03], [0, 0]])
    closed_form = sum(np.sum((pts[i + 1] - pts[i]) ** 2) / np.diff(problem.segment_times)[i]
                      for i in range(3))
    assert_close(triangle_plan.stats.objective, closed_form, atol=0, rtol=1e-6)
    # and the palm path really is the triangle: every node lies on one of its edges
    xy = triangle_plan.nodes.eta[:, :2]
    def line_distance(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        d, r = b - a, xy - a
        return np.abs(d[0] * r[:, 1] - d[1] * r[:, 0]) / np.linalg.norm(d)

    dist = np.min([line_distance(pts[i], pts[i + 1]) for i in range(3)], axis=0)
    assert np.max(dist) < 1e-6


def test_no_slip_no_spin_along_sampled_plan(triangle_plan: Solution) -> None:
    slip, spin = finite_difference_slip(triangle_plan, triangle().duration)
    assert slip < 1e-2 and spin < 1e-2


def test_ball_touches_palm_everywhere(triangle_plan: Solution) -> None:
    for traj in (triangle_plan.grid, triangle_plan.sample(np.linspace(0, 6, 301))):
        assert_close(traj.object_position[:, 2], RHO, atol=1e-12)
        assert_close(traj.contact_point[:, 2], 0.0, atol=1e-12)
        # the contact point is straight below the centre, on the ball's surface
        assert_close(traj.contact_point[:, :2], traj.object_position[:, :2], atol=1e-12)
        assert_close(traj.contact_point[:, :2], traj.eta[:, :2], atol=1e-12)


def test_interpolation_reproduces_collocation_points(triangle_plan: Solution) -> None:
    """The Hermite cubic passes through the nodes and, by the collocation constraint,
    through the midpoint states."""
    g = triangle_plan.grid
    s = triangle_plan.sample(g.t[1:-1:2])  # midpoints (grid alternates node, midpoint)
    assert_close(s.eta, g.eta[1:-1:2], atol=1e-8)
    n = triangle_plan.nodes
    assert_close(triangle_plan.sample(n.t).eta, n.eta, atol=1e-12)


def test_plans_agree_at_two_grid_sizes() -> None:
    coarse = PLANNER.solve(triangle(30))
    fine = PLANNER.solve(triangle(90))
    assert coarse.status is Status.SOLVED and fine.status is Status.SOLVED
    t = np.linspace(0, 6, 121)
    a, b = coarse.sample(t), fine.sample(t)
    assert_close(a.eta[:, :2], b.eta[:, :2], atol=1e-6)
    assert_close(a.object_rotation, b.object_rotation, atol=1e-4)


# -- goals of every kind -------------------------------------------------------------------

@pytest.mark.parametrize("goal", [
    {"x": 0.04, "y": -0.02},  # palm position only
    {"u": 0.3, "v": -0.4, "psi": 0.5},  # object orientation only
    {"x": 0.02, "y": 0.01, "u": -0.2, "v": 0.6, "psi": -1.0},  # everything
    {"psi": 2.0},  # a single coordinate
])
def test_goal_subsets_are_met(goal: dict[str, float]) -> None:
    problem = BallOnPalmProblem(object=SPHERE, initial=(0.0, 0.0, 0.1, 0.0, 0.0), goal=goal,
                                duration=2.0)
    sol = PLANNER.solve(problem)
    assert sol.status is Status.SOLVED, sol.message
    final = sol.nodes.eta[-1]
    if not np.allclose(sol.chart_rotation, SPHERE.chart_rotation):
        # the planner re-charted the object (its path rode the patch's pole bound): the
        # plan's coordinates are in its own patch, the goal restated there
        from ocp.spec.patches import Chart, recharted_coordinates

        dims = SPHERE.dimensions
        restated = recharted_coordinates(Chart.of(SPHERE.surface, dims, SPHERE.chart_rotation),
                                         Chart.of(SPHERE.surface, dims, sol.chart_rotation),
                                         goal)
        assert restated is not None
        goal = restated
    for c, target in goal.items():
        i = CONTACT_COORDS.index(c)
        err = final[i] - target
        if c in ("v", "psi"):
            err = (err + math.pi) % (2 * math.pi) - math.pi
        assert abs(err) < GOAL_TOL, (c, final[i], target)


@pytest.mark.parametrize(("obj", "rotvec"), [
    (SPHERE, (0.0, 0.0, math.pi / 2)),  # about the vertical, the paper's hard case
    (SPHERE, (0.0, 0.0, -math.pi)),  # half a turn about the vertical
    (SPHERE, (math.radians(60), 0.0, 0.0)),  # about a horizontal axis
    (SPHERE, (0.5, 0.5, 0.0)),  # about an oblique horizontal axis
    (ELLIPSOID, (0.0, 0.0, math.pi / 2)),
    (ELLIPSOID, (math.radians(60), 0.0, 0.0)),
])
def test_pure_reorientation_returns_to_the_same_palm_point_turned(
        obj: ObjectSpec, rotvec: tuple[float, float, float]) -> None:
    problem, R_goal = reorientation(obj, rotvec)
    if obj is ELLIPSOID and rotvec[0]:
        # its optimal loop runs over the pole (the ellipsoid's axis, which no chart patch
        # moves) and rides the pole bound; at the default 15 deg margin the kink needs 400
        # intervals and ~45 s to certify slip within 1e-3 of the speed scale
        # (docs/performance.md), at 10 deg 400 intervals and ~3 s
        problem = replace(problem, pole_margin=math.radians(10.0))
    sol = PLANNER.solve(problem)
    assert sol.status is Status.SOLVED, sol.message
    final = sol.sample([problem.duration])
    _, p0 = object_pose(obj, problem.initial)
    # the object is back where it started, turned by the requested rotation
    assert_close(final.object_position[0], p0, atol=1e-6)
    assert_close(final.object_rotation[0], R_goal, atol=1e-5)
    # and it got there by rolling: a loop on the palm (nonholonomic), not by standing still
    xy = sol.nodes.eta[:, :2]
    assert np.max(np.linalg.norm(xy, axis=1)) > 0.1 * obj.length_scale
    slip, spin = finite_difference_slip(sol, problem.duration)
    assert slip < 1e-2 and spin < 1e-2
    # the ellipsoid touches the palm: its lowest point is on the plane
    heights = [final.object_position[0, 2] - obj.surface.support_height(
        -R.T @ np.array([0, 0, 1.0]), obj.dimensions) for R in sol.grid.object_rotation[-1:]]
    assert_close(heights, 0.0, atol=1e-9)


# -- the certificate -------------------------------------------------------------------------

def test_certificate_detects_inputs_that_do_not_produce_the_states() -> None:
    """Negative control: the same states with perturbed inputs fail the certificate."""
    problem = BallOnPalmProblem(object=SPHERE, initial=(0.0, 0.0, 0.0, 0.0, 0.0),
                                goal={"x": 0.03, "y": 0.01, "psi": 0.3}, duration=2.0)
    sol = PLANNER.solve(problem)
    assert sol.status is Status.SOLVED
    X, U = sol.nodes.eta, sol.nodes.w
    Um = sol.grid.w[1:-1:2]
    t = sol.nodes.t
    ok = certify(problem, t, X, U[:-1], Um, U[1:])
    assert ok.passed, ok.failures
    bad = certify(problem, t, X, 1.01 * U[:-1], 1.01 * Um, 1.01 * U[1:])
    assert not bad.passed
    assert any(f.startswith("position_defect") for f in bad.failures)


def test_certificate_is_consistent_with_reported_metrics(triangle_plan: Solution) -> None:
    c = triangle_plan.certificate
    for name, value in [("position_defect", c["max_position_defect"]),
                        ("angle_defect", c["max_angle_defect"]),
                        ("slip_speed", c["max_slip_speed"]), ("spin_rate", c["max_spin_rate"]),
                        ("height", c["max_height_error"])]:
        assert np.isfinite(value) and value <= c.tolerances()[name]


# -- statuses and the cache ------------------------------------------------------------------

def test_an_uncertified_plan_is_never_called_solved(triangle_plan: Solution) -> None:
    """certify=False (a plan that only seeds another planner's guess): the same plan, but
    no certificate, so at best inaccurate, saying why, and never refined."""
    guess = PLANNER.solve(triangle(), certify=False)
    assert guess.status is Status.INACCURATE
    assert guess.certificate.failures == ("not certified (planned as an initial guess)",)
    assert not guess.certificate.passed and guess.stats.refinements == 0
    assert_close(guess.grid.eta, triangle_plan.grid.eta, atol=1e-12)


def test_iteration_limit_returns_typed_status_and_last_iterate() -> None:
    problem, _ = reorientation(SPHERE, (0.0, 0.0, math.pi / 2))
    sol = PLANNER.solve(replace(problem, options=SolverOptions(max_iter=2)))
    assert sol.status is Status.ITERATION_LIMIT
    assert sol.stats.iterations <= 2
    assert np.all(np.isfinite(sol.grid.eta)) and len(sol.grid.t) == 2 * 50 + 1


def test_time_limit_returns_typed_status() -> None:
    problem, _ = reorientation(SPHERE, (0.0, 0.0, math.pi / 2), n=80)
    PLANNER.nlp_for(problem)  # build outside the limit
    sol = PLANNER.solve(replace(problem, options=SolverOptions(time_limit=1e-4)))
    assert sol.status is Status.TIME_LIMIT
    assert np.all(np.isfinite(sol.grid.eta))


def test_unreachable_goal_is_reported_not_solved() -> None:
    """0.4 m in 1 s with each velocity component bounded by 0.05 m/s cannot be done."""
    problem = BallOnPalmProblem(object=SPHERE, initial=(0.0, 0.0, 0.0, 0.0, 0.0),
                                goal={"x": 0.4}, duration=1.0, max_contact_speed=0.05)
    sol = PLANNER.solve(problem)
    assert sol.status in (Status.INFEASIBLE, Status.NUMERICAL_ERROR, Status.ITERATION_LIMIT)
    # re-integrating the (bounded) inputs of the last iterate falls short by >= 0.35 m
    assert not sol.certificate.passed
    assert sol.certificate["max_goal_error"] >= 0.4 - 0.05 * 1.0 - 1e-9
    assert np.max(np.abs(sol.grid.w)) <= 0.05 + 1e-9


def test_structure_is_built_once_and_reused_with_new_values() -> None:
    planner = BallOnPalmPlanner()
    first = planner.solve(BallOnPalmProblem(object=SPHERE, initial=(0, 0, 0, 0, 0),
                                            goal={"x": 0.02, "y": 0.01}, duration=1.0))
    other = BallOnPalmProblem(object=ObjectSpec("sphere", (0.04,)),
                              initial=(0.01, -0.01, 0.2, 0.1, 1.0),
                              goal={"x": -0.03, "y": 0.02}, duration=3.0)
    second = planner.solve(other)
    assert not first.stats.cache_hit and second.stats.cache_hit
    assert second.stats.build_time == 0.0
    assert second.status is Status.SOLVED
    assert_close(second.nodes.eta[-1, :2], [-0.03, 0.02], atol=GOAL_TOL)
    assert_close(second.nodes.object_position[:, 2], 0.04, atol=1e-12)


def test_certificate_of_a_non_finite_plan_fails_instead_of_crashing() -> None:
    problem = triangle(30)
    n = 30
    t = np.linspace(0, 6, n + 1)
    X = np.zeros((n + 1, 5))
    X[3, 2] = np.nan
    U = np.zeros((n, 2))
    cert = certify(problem, t, X, U, U, U)
    assert not cert.passed and not cert.refinable
    assert cert.failures == ("the plan has non-finite states or inputs",)


def test_reintegration_over_the_horizon_is_the_intervals_chained() -> None:
    """The certificate's re-integration (one CasADi call over the horizon) is CVODES over
    each interval started where the previous one ended, never reset to the NLP's states:
    the same numbers as integrating interval by interval from Python."""
    from ocp.transcription.collocation import quadratic_input, reintegrate, reintegrator

    rng = np.random.default_rng(3)
    n, n_sub = 7, 4
    t_nodes = np.cumsum(np.r_[0.0, rng.uniform(0.1, 0.3, n)])
    U0, Um, U1 = (rng.normal(scale=0.02, size=(n, 2)) for _ in range(3))
    x0 = np.array([0.0, 0.0, 0.2, 0.1, 0.3])
    params = np.array([0.03])
    F = reintegrator(model_for("sphere").dynamics, 5, 2, 1, n_sub)
    nodes, samples, inputs = reintegrate(F, x0, t_nodes, U0, Um, U1, params, n_sub)
    x, ref_nodes, ref_samples, ref_inputs = x0, [x0], [x0], [U0[0]]
    s = np.linspace(0.0, 1.0, n_sub + 1)[1:]
    for k in range(n):
        q = np.r_[U0[k], Um[k], U1[k], t_nodes[k + 1] - t_nodes[k], params]
        xs = np.asarray(F(x0=x, p=q)["xf"]).T
        ref_samples += list(xs)
        ref_inputs += [quadratic_input(sj, U0[k], Um[k], U1[k]) for sj in s]
        x = xs[-1]
        ref_nodes.append(x)
    assert_close(nodes, np.array(ref_nodes), atol=0.0)
    assert_close(samples, np.array(ref_samples), atol=0.0)
    assert_close(inputs, np.array(ref_inputs), atol=1e-18)
