"""The simulator's force control (``SimOptions.force_control``, docs/simulation.md "Force
control"; measured in docs/gait.md "Executed"): a gait executed with contact-force
feedback loses no planned contact and delivers its planned normal forces; feedback as a
shift of the servo's set point (admittance, a gait's default) holds a ball smaller than
planned, which feedback as torque (pi) drops; the setting is checked by name."""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path
from typing import Any, cast

import numpy as np
import pytest
from pydantic import ValidationError

pytest.importorskip("mujoco")

from dexroll_client.simulation import SimulationOptions
from planner_service.execution import execution_plan
from planner_service.planners import REQUEST, RESULT
from sim import SimOptions, simulate

DATA = Path(__file__).resolve().parent / "data"

#: the bound [N] on the worst |delivered - planned| normal force where a contact counts
#: as touching, on the stored gait, by force control. pi: measured 0.17-0.40 N on the
#: re-placed fingertips, 1.16 N on the never-lifted thumb, which opposes the others'
#: 0.65 N floors; admittance: 0.56-0.79 N and 1.88 N on the thumb (it pushes a fingertip
#: in, never pulls one out past the plan's set point: an over-loaded contact stays so);
#: without force control 0.52-1.72 N
FORCE_BOUND = {"pi": 1.3, "admittance": 2.1}


@pytest.fixture(scope="module")
def gait_plan() -> object:
    """The stored short gait (tests/data/gait_small_*.json: examples/allegro_gait.json
    turned 8 deg, every fingertip but the thumb re-placed) as the simulator's plan."""
    request = REQUEST.validate_json((DATA / "gait_small_request.json").read_text())
    result = RESULT.validate_json((DATA / "gait_small_result.json").read_text())
    return execution_plan(result, request)


@pytest.mark.parametrize("control", ["admittance", "pi"])
def test_a_gait_under_force_control_keeps_every_contact_and_its_planned_forces(
        gait_plan: object, control: str) -> None:
    plan = gait_plan
    assert plan.force_control == "admittance"  # type: ignore[attr-defined]
    # the gait's own default, and the torque feedback asked by name
    report = simulate(plan, None if control == "admittance"  # type: ignore[arg-type]
                      else SimOptions(force_control=control))
    assert report.options["force_control"] == control
    head = "force control: admittance" if control == "admittance" else "force control: PI"
    assert any(n.startswith(head) for n in report.notes), report.notes
    assert report.passed, report.failures
    for c in report.contacts:
        assert c.lost_time == 0.0 and c.loss_events == 0, c
        assert c.unplanned_touch_time == 0.0, c
        assert c.normal_force_error_max is not None
        assert c.normal_force_error_max <= FORCE_BOUND[control], c
    if control == "pi":  # the servo alone (other plans' default) misses them by more
        off = simulate(plan, SimOptions(force_control="off"))  # type: ignore[arg-type]
        assert any(n == "force control: off (the servo with the planned forces fed "
                        "forward)" for n in off.notes)
        worst = max(c.normal_force_error_max or 0.0 for c in report.contacts)
        assert worst < max(c.normal_force_error_max or 0.0 for c in off.contacts)


def test_a_ball_smaller_than_planned_is_held_by_the_shifted_set_points_not_by_torque(
        gait_plan: object) -> None:
    """The ball 0.2 mm smaller in radius than the plan's: the 0.1 mm squeeze leaves every
    fingertip 0.1 mm short of it. Torque feedback (pi, at most 3 N against the 200 N m/rad
    servos: some 25 um) cannot bend the fingers that far and the ball falls; the
    admittance shifts the set points in (at most 0.2 mm) and the run passes: within 1 mm
    and 2 deg, no contact lost."""
    from sim.closed_loop import simulate_disturbed
    from sim.disturbances import Disturbances

    small = Disturbances(size_change=-2e-4)
    pi = simulate_disturbed(gait_plan, SimOptions(force_control="pi"),  # type: ignore[arg-type]
                            small)
    assert pi.position_error.max > 0.01  # dropped: centimetres off
    shifted = simulate_disturbed(gait_plan, SimOptions(), small)  # type: ignore[arg-type]
    assert shifted.options["force_control"] == "admittance"
    assert shifted.passed, shifted.failures
    assert shifted.position_error.max < 1e-3
    assert shifted.angle_error.max < math.radians(2.0)
    assert all(c.lost_time == 0.0 for c in shifted.contacts), shifted.contacts


def test_force_control_is_resolved_per_plan_and_checked_by_name(gait_plan: object) -> None:
    assert SimOptions().resolved(gait_plan).force_control == "admittance"
    assert SimOptions(force_control="off").resolved(gait_plan).force_control == "off"
    other = replace(gait_plan, force_control=None)  # type: ignore[type-var]
    assert SimOptions().resolved(other).force_control == "off"
    for bad, name in (({"force_control": "pd"}, "force_control"),
                      ({"force_ki": -1.0}, "force_ki"),
                      ({"force_kp": float("nan")}, "force_kp"),
                      ({"force_limit": -0.1}, "force_limit"),
                      ({"force_min": float("inf")}, "force_min"),
                      ({"force_shift_ki": -1e-3}, "force_shift_ki"),
                      ({"force_shift_limit": float("nan")}, "force_shift_limit")):
        with pytest.raises(ValueError, match=name):
            SimOptions.from_dict(bad)
    with pytest.raises(ValidationError, match="force_control"):
        SimulationOptions.model_validate({"force_control": "pd"})
    wire = SimulationOptions.model_validate({"force_control": "off", "force_min": 0.3})
    assert SimOptions.from_dict(wire.simulator_options()).force_min == 0.3
    json.dumps(SimOptions(force_control="pi").to_dict())  # the report's options
    # with the joints set to the plan there is nothing to feed back into
    replayed = simulate(gait_plan, SimOptions(mode="replay", settle=0.0))  # type: ignore[arg-type]
    assert "force control: admittance asked, but off (replay mode)" in replayed.notes


def test_the_admittance_follows_a_surface_that_moves_under_a_contact_as_the_object_turns(
        gait_plan: object) -> None:
    """Turned by an angle a about its centre, an object's surface moves under a contact at
    p with normal n by a |(p - c) x n| along n: nothing on a ball, so a ball's contacts
    keep the options' own shift bound and rate (the stored gait's, bit for bit); a
    contact 20 mm off a cube's face centre gets the options' bound plus the run's
    orientation tolerance times its 20 mm lever, at the rate that crosses it as fast."""
    from sim.run import ROUND_LEVER, admittance_range

    o, plan = SimOptions(), cast(Any, gait_plan)
    for c in plan.contacts:
        assert admittance_range(o, c.point, c.normal, plan.object_position, c.active) == \
            (o.force_shift_limit, o.force_shift_ki)
    centre = np.zeros((3, 3))
    normal = np.tile([0.0, 0.0, 1.0], (3, 1))
    face = np.array([[0.0, 0.0, 0.025], [0.02, 0.0, 0.025], [0.0, 0.03, 0.025]])
    limit, ki = admittance_range(o, face, normal, centre, np.array([1.0, 1.0, 0.0]))
    assert limit == pytest.approx(o.force_shift_limit + o.tolerances.angle * 0.02, rel=1e-12)
    assert ki / o.force_shift_ki == pytest.approx(limit / o.force_shift_limit, rel=1e-12)
    # at its middle the face does not move along its normal: the options' own
    assert admittance_range(o, face[:1], normal[:1], centre[:1], None) == \
        (o.force_shift_limit, o.force_shift_ki)
    assert ROUND_LEVER <= 1e-6
