"""Laws on real plans of one flat fingertip rolling a ball on the palm (section 3)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from helpers import assert_close

from ocp.one_finger import FingerContact, OneFingerPlanner, OneFingerProblem, OneFingerSolution
from ocp.robots.finger import load_finger
from ocp.solution import Status
from ocp.spec.problem import BallOnPalmProblem, ObjectSpec, ProblemError

RHO = 0.025
FINGER = load_finger()
PLANNER = OneFingerPlanner()
#: The finger contact's chart patch on the ball: patch point (0, 0) is the ball's top at
#: the start (the palm contact's patch has it at the bottom); u_f = 0.2 rad tilts the
#: contact 11.5 deg from the top: grasp angles of 5.7 deg, away from antipodal.
CONTACT = FingerContact(initial=(0.0, 0.0, 0.2, 0.0, 0.0), chart_rotation=(0.0, 0.0, math.pi))


def roll(n: int = 40) -> OneFingerProblem:
    """Roll the ball 10 mm along the palm's x axis in 2 s, the finger pressing on it."""
    base = BallOnPalmProblem(object=ObjectSpec("sphere", (RHO,)),
                             initial=(0.0, 0.0, 0.0, 0.0, -math.pi / 2),
                             goal={"x": 0.01, "y": 0.0}, duration=2.0, n_intervals=n)
    return OneFingerProblem(base=base, finger=FINGER, contact=CONTACT, mu=0.5)


@pytest.fixture(scope="module")
def plan() -> OneFingerSolution:
    return PLANNER.solve(roll())


def test_short_roll_is_solved_and_certified(plan: OneFingerSolution) -> None:
    assert plan.status is Status.SOLVED, plan.message
    assert not plan.certificate_failures
    assert max(plan.goal_error.values()) < 1e-6


def test_closure_holds_along_plan(plan: OneFingerSolution) -> None:
    """Pinocchio's forward kinematics of the joint angles puts the fingertip where the
    object pose and the finger contact coordinates say it is (eq. 6)."""
    # the closure is kept at the velocity level and the positions follow by integration:
    # their drift is the grid's (O(h^4)), well inside the certificate's 1e-5 m and 1e-4 rad
    for i in range(len(plan.t)):
        R_pin, p_pin = FINGER.fingertip_pose_pin(plan.q[i])
        assert_close(p_pin, plan.fingertip_position[i], atol=1e-6)
        assert_close(R_pin, plan.fingertip_rotation[i], atol=1e-5)


def rolling_speed(plan: OneFingerSolution) -> float:
    """Worst speed of the finger contact over the ball [m/s]: the ball's own rolling
    (up to twice its centre speed at the top) plus the contact's motion over it."""
    return float(np.max(2 * np.linalg.norm(plan.w_p, axis=1)
                        + RHO * np.linalg.norm(plan.w_f, axis=1)))


def test_no_slip_or_spin_at_either_contact(plan: OneFingerSolution) -> None:
    """Along the returned trajectory (finger moved by its joints, ball by the palm
    contact), the contact points do not slide or spin: within 1e-3 of the plan's speed
    scale, which is at most the worst rolling speed computed here from the inputs."""
    c = plan.certificate
    speed = rolling_speed(plan)
    assert 0 < c["speed_scale"] <= speed
    for contact in ("palm", "finger"):
        assert c[f"max_slip_speed_{contact}"] <= 1e-3 * c["speed_scale"]
        assert c[f"max_spin_rate_{contact}"] <= 1e-3 * c["rolling_rate_scale"]
        assert c[f"tol_max_slip_speed_{contact}"] == pytest.approx(1e-3 * c["speed_scale"])
    assert c["max_slip_speed_finger"] < 1e-3 * speed


def test_finger_slip_vanishes_as_the_grid_is_refined() -> None:
    """The finger's residual slip is discretisation error: a finer grid shrinks it (the
    same problem on 40 and 80 intervals, not refined further)."""
    coarse, fine = (PLANNER.solve(replace(p, base=replace(p.base, max_refinements=0)))
                    for p in (roll(40), roll(80)))
    assert coarse.raw_status == fine.raw_status == "Solve_Succeeded"
    for check in ("max_slip_speed_finger", "max_closure_position_error"):
        assert fine.certificate[check] < 0.5 * coarse.certificate[check]


def test_fingertip_pad_is_tangent_to_the_ball(plan: OneFingerSolution) -> None:
    """The pad plane (from Pinocchio FK) is at one radius from the ball's centre, and the
    contact lies on the pad."""
    for i in range(len(plan.t)):
        R_pin, p_pin = FINGER.fingertip_pose_pin(plan.q[i])
        gap = float(R_pin[:, 2] @ (plan.object_position[i] - p_pin)) - RHO
        assert abs(gap) < 1e-7
    assert np.max(np.abs(plan.eta_f[:, :2])) <= FINGER.pad_half_size
    assert_close(plan.object_position[:, 2], RHO, atol=1e-12)


def test_grasp_stays_inside_the_friction_cone(plan: OneFingerSolution) -> None:
    assert np.all(plan.cone_margin > 0.0)
    assert np.all(plan.grasp_angles.max(axis=1) < math.atan(0.5))


def test_grasp_angle_moves_towards_antipodal(plan: OneFingerSolution) -> None:
    """Started 5.7 deg away from antipodal, the optimiser brings the grasp closer: from the
    start (at rest: the smooth timing) steadily, to a tenth of it within the first half."""
    worst = plan.grasp_angles.max(axis=1)
    assert worst[0] > math.radians(5.0)
    assert np.min(worst) < 0.25 * worst[0]
    tenth = int(np.argmax(worst < 0.1 * worst[0]))
    assert 0 < tenth < len(worst) // 2
    assert np.all(np.diff(worst[: tenth + 1]) < 0), "it improves from the start"


def test_joint_limits_are_respected(plan: OneFingerSolution) -> None:
    assert np.all(plan.q >= FINGER.lower - 1e-9) and np.all(plan.q <= FINGER.upper + 1e-9)
    assert np.all(np.abs(plan.q_dot) <= FINGER.velocity_limit + 1e-9)


@pytest.mark.parametrize(("contact", "words"), [
    (replace(CONTACT, initial=(0.0, 0.0, 1.2, 0.0, 0.0)), "outside the friction cone"),
    (replace(CONTACT, initial=(0.049, 0.0, 0.2, 0.0, 0.0)), "leaves the pad"),
])
def test_impossible_initial_grasp_is_rejected_with_its_reason(contact: FingerContact,
                                                              words: str) -> None:
    with pytest.raises(ProblemError) as info:
        PLANNER.solve(replace(roll(), contact=contact))
    assert any(words in reason for _, reason in info.value.errors), info.value.errors
    assert any(field.startswith("finger_contact.initial") for field, _ in info.value.errors)


def test_unreachable_initial_grasp_is_rejected_with_the_distance() -> None:
    far = replace(roll(), base=replace(roll().base, initial=(0.3, 0.0, 0.0, 0.0, -math.pi / 2),
                                       goal={"x": 0.31}))
    with pytest.raises(ProblemError) as info:
        PLANNER.solve(far)
    (field, reason), = info.value.errors
    assert field == "finger_contact.initial" and "cannot reach" in reason
    assert " m " in reason  # says by how much


def test_reported_rates_are_the_rolling_equations_at_both_contacts(plan: OneFingerSolution
                                                                   ) -> None:
    """The contact-coordinate rates in the result follow from the inputs by the rolling
    equations: the palm ones move the palm point with w_p, the finger ones move the ball
    point with w_f, and integrating the rates reproduces the coordinates."""
    assert_close(plan.eta_p_dot[:, 0:2], plan.w_p, atol=1e-12)
    assert_close(plan.eta_f_dot[:, 2:4], plan.w_f, atol=1e-12)
    # the grid alternates node, midpoint, node: Simpson's rule over each interval is the
    # collocation condition, so it must hold to the NLP's tolerance
    for eta, rate in ((plan.eta_p, plan.eta_p_dot), (plan.eta_f, plan.eta_f_dot)):
        h = plan.t[2::2] - plan.t[:-2:2]
        simpson = h[:, None] / 6 * (rate[:-2:2] + 4 * rate[1::2] + rate[2::2])
        assert_close(eta[2::2] - eta[:-2:2], simpson, atol=1e-9)


def test_a_grid_too_coarse_for_a_fast_regrasp_is_refined_until_certified() -> None:
    """The grasp weight (100, the default) makes the finger re-grasp fast at the start when
    the ramps are short (0.1 s: the default is 15 % of the 2 s); on 20 intervals the finger
    then slips between collocation points in the first intervals, which the certificate
    catches. Without refinement the plan says so (inaccurate); with
    it the grid is made 2, 4 or 8 times as fine until the plan is certified (80 intervals,
    a few seconds). A heavier weight makes the start a boundary layer that a uniform grid
    resolves slowly (3000: the slip converges like h there, 320 intervals and more)."""
    fast = roll(20)
    fast = replace(fast, base=replace(fast.base, ramp_time=0.1))
    coarse = PLANNER.solve(replace(fast, base=replace(fast.base, max_refinements=0)))
    assert coarse.status is Status.INACCURATE
    assert coarse.certificate_failures
    refined = PLANNER.solve(fast)
    assert refined.status is Status.SOLVED, refined.message
    assert refined.refinements >= 1 and not refined.certificate_failures
    n = (len(refined.t) - 1) // 2
    factor = n // 20
    assert n == 20 * factor and factor >= 2 and factor & (factor - 1) == 0
    assert factor <= 8**refined.refinements
    assert refined.certificate["max_slip_speed_finger"] < coarse.certificate[
        "max_slip_speed_finger"]


def test_the_finger_chart_has_one_default_in_the_library_and_on_the_wire() -> None:
    """A request that leaves out the finger contact's chart gets the library's default."""
    from dexroll_client.models import FingerContactModel
    from ocp.solve.planner import Fingertip
    from ocp.spec.problem import DEFAULT_FINGER_CHART_ROTATION

    wire = FingerContactModel.model_validate({"initial": {"x_f": 0.0, "y_f": 0.0, "u_f": 0.0,
                                                          "v_f": 0.0, "psi_f": 0.0}})
    assert tuple(wire.chart_rotation) == DEFAULT_FINGER_CHART_ROTATION
    assert FingerContact(initial=(0.0,) * 5).chart_rotation == DEFAULT_FINGER_CHART_ROTATION
    assert Fingertip(None, (0.0,) * 5).chart_rotation == DEFAULT_FINGER_CHART_ROTATION
