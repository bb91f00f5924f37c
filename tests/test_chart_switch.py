"""A plan whose fingertip contacts change chart at a node (docs/shapes.md, "Charts that
switch inside a plan"): the switched NLP is the same problem on two charts, the planner
plans and certifies it across the switch, the automatic choice picks a switch only where
no chart carries the predicted contact paths, and what cannot follow a switch says so."""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from ocp import ProblemError
from ocp.solve.attempt import setup
from ocp.solve.nlp_cache import FORCE_REGULARISATION, GraspStructure
from ocp.spec import patches
from ocp.spec.chart_switch import ChartSwitchSpec, after_switch
from ocp.spec.grasp import contact_charts
from ocp.spec.patches import side_charted
from ocp.transcription.chart_switch import ChartSwitch, PlanCharts, chart_map
from ocp.transcription.nlp_blocks import build_manipulation_nlp
from ocp.transcription.values import parameters
from planner_service.planners import FINGERS, REQUEST, to_problem
from planner_service.planners.manipulation import result_from_manipulation_solution

ROOT = Path(__file__).resolve().parents[1]


def _egg_turn() -> dict:
    return json.loads((ROOT / "examples" / "egg_turn.json").read_text())


@pytest.fixture(scope="module")
def egg() -> tuple:
    """egg_turn.json's problem, its plan, and the same problem switched at mid-motion to
    the egg's side chart (each fingertip's patch there: the side chart's equator through
    it) with its plan."""
    # (on the grid its certificate refines 20 intervals to: one solve each, not two)
    problem = to_problem(REQUEST.validate_python(_egg_turn())).with_intervals(40)
    planner = FINGERS.manipulation
    plain = planner.solve(problem)
    side = side_charted(problem)
    assert side is not None
    # (asked at 0.98 s: the switch is at the grid's node nearest it, 1.0 s)
    spec = ChartSwitchSpec(0.49 * problem.duration, True,
                           tuple(f.chart_rotation for f in side.fingers))
    switched = replace(problem, chart_switch=spec)
    return problem, plain, switched, planner.solve(switched)


def test_the_switched_nlp_holds_at_the_one_chart_optimum_restated(egg: tuple) -> None:
    """The egg's kinematic plan on its own chart, its points from the middle node on
    restated on the side chart (chart_map: the same surface point, contact frame and
    rates), satisfies every row of the switched NLP to IPOPT's tolerance: the switch
    interval's defects read its end through the map, everything else is the next
    chart's own blocks. (The planner solving it: the next test.)"""
    problem, sol, switched, _ = egg
    problem = replace(problem, forces=None)  # (the plan's point: its kinematic NLP's)
    planner = FINGERS.manipulation
    assert sol.ok and sol.nlp_point is not None
    problem = problem.with_intervals(sol.stats.n_intervals)
    s = setup(planner, problem)
    m, key = s.model, GraspStructure.of(problem)
    pb = after_switch(replace(problem, chart_switch=switched.chart_switch))
    mb = planner.model(pb)
    assert (m.surface.name, mb.surface.name) == ("ellipsoid", "ellipsoid_side")
    n = key.segments[0]
    ks = n // 2
    build = {"forces": key.forces, "smooth": key.smooth}
    plain = build_manipulation_nlp(m, key.segments, key.goal_mask, key.via_masks,
                                   key.tracking, FORCE_REGULARISATION, **build)
    nlp = build_manipulation_nlp(m, key.segments, key.goal_mask, key.via_masks,
                                 key.tracking, FORCE_REGULARISATION, **build,
                                 switch=ChartSwitch(ks, mb))
    w = np.asarray(sol.nlp_point.w, dtype=float)
    X, Xm, U, Um, S, Sm, F = (np.array(a) for a in plain.unpack(w))
    xs, us = s.x_scale, s.u_scale
    cA = np.concatenate([R.ravel(order="F") for R in contact_charts(problem)])
    cB = np.concatenate([R.ravel(order="F") for R in contact_charts(pb)])
    shape = np.asarray(problem.object.params, dtype=float)
    fwd = chart_map(m, mb)
    nf = len(m.fingertips)
    first = PlanCharts((m, mb), (np.r_[shape, cA], np.r_[shape, cB]), ks)
    raw = np.asarray(fwd(X[:, ks] * xs, U[:, ks] * us, shape, cA, cB, np.zeros(2 * nf))[0])
    refs_b = first.refs_of(raw.ravel())
    lc = plain.hs.left_cols
    for j in range(ks, n + 1):  # (smooth timing: one input column per node)
        col = lc[j] if j < n else plain.hs.right_cols[-1]
        a, b = fwd(X[:, j] * xs, U[:, col] * us, shape, cA, cB, refs_b)
        X[:, j], U[:, col] = np.asarray(a).ravel() / xs, np.asarray(b).ravel() / us
    for k in range(ks, n):
        a, b = fwd(Xm[:, k] * xs, Um[:, k] * us, shape, cA, cB, refs_b)
        Xm[:, k], Um[:, k] = np.asarray(a).ravel() / xs, np.asarray(b).ravel() / us
    w2 = np.asarray(nlp.pack(X, Xm, U, Um, S, Sm, F)).ravel()
    refs = first.refs_of(np.asarray(plain.unpack(w)[0])[:, ks - 1] * xs)
    p2 = parameters(problem, nlp, (xs, us), (cB, refs))
    f0, _ = plain.oracle(w, s.p)
    f2, g2 = nlp.oracle(w2, p2)
    g2 = np.asarray(g2).ravel()
    violation = np.maximum(np.maximum(nlp.lbg - g2, g2 - nlp.ubg), 0.0).max()
    assert len(g2) == len(plain.lbg)
    assert violation < 1e-7
    assert abs(float(f2) - float(f0)) < 1e-3 * abs(float(f0))  # (efforts: chart rates)
    # the stage-ordered layout (fatrop's) of the same switched NLP: the same rows hold
    staged = build_manipulation_nlp(m, key.segments, key.goal_mask, key.via_masks,
                                    key.tracking, FORCE_REGULARISATION, **build,
                                    switch=ChartSwitch(ks, mb), stage_order=True)
    w3 = np.asarray(staged.pack(X, Xm, U, Um, S, Sm, F)).ravel()
    f3, g3 = staged.oracle(w3, p2)
    g3 = np.asarray(g3).ravel()
    assert np.maximum(np.maximum(staged.lbg - g3, g3 - staged.ubg), 0.0).max() < 1e-7
    assert float(f3) == pytest.approx(float(f2), rel=1e-12)


def test_a_switched_plan_is_certified_across_its_switch(egg: tuple) -> None:
    """egg_turn.json switched at mid-motion onto the side chart: planned (kinematics and
    forces), certified (the re-integration goes on across the switch, the rates on both
    sides of it read on one chart agree), and the same motion as on the one chart: the
    object's pose and the joints within the solver's tolerance."""
    problem, plain, _, sol = egg
    assert plain.ok and sol.ok, sol.message
    assert sol.chart_switch is not None
    spec = sol.chart_switch
    assert spec.time == pytest.approx(problem.duration / 2, abs=1e-12)  # its node's
    cert = sol.certificate
    assert cert.check("max_velocity_jump").value < 1e-9
    assert cert.check("max_angle_defect").passed
    ts = np.linspace(0.0, problem.duration, 101)
    a, b = plain.sample(ts), sol.sample(ts)
    assert np.abs(a.object_position - b.object_position).max() < 1e-6
    assert np.abs(a.object_rotation - b.object_rotation).max() < 1e-4
    joints = np.hstack([f.q for f in sol.fingers]) - np.hstack([f.q for f in plain.fingers])
    assert np.abs(joints).max() < 1e-3
    # the contact coordinates: before the switch on the egg's own chart, from it on the
    # side chart, the same points of the egg on both sides of it
    charts = sol._interpolant.charts
    assert [m.surface.name for m in charts.models] == ["ellipsoid", "ellipsoid_side"]
    left = sol.sample([spec.time], side="left")
    right = sol.sample([spec.time])
    for tip, c in zip(charts.first.fingertips, range(len(problem.fingers)), strict=True):
        pa = charts.models[0].cartesian(left.x[0], charts.prms[0])[4]
        pb = charts.models[1].cartesian(right.x[0], charts.prms[1])[4]
        assert np.abs(np.asarray(pa)[:, c] - np.asarray(pb)[:, c]).max() < 1e-9
        assert abs(right.x[0, tip.eta_cols.start + 2]) < 0.8 * (math.pi / 2)
    # the joint trajectory has no rate break at the switch (the same motion)
    assert sol.break_nodes() == []
    assert sol.joint_trajectory(ts).breaks == ()
    # planned forces on both charts, continuous (physical, palm frame)
    f, _ = sol.forces([spec.time - 1e-9, spec.time + 1e-9])
    assert np.abs(f[0] - f[1]).max() < 1e-6
    # the wire names the charts the contact coordinates are on
    result = result_from_manipulation_solution(sol)
    assert result.contact_charts is not None
    assert [c.chart for c in result.contact_charts] == ["ellipsoid", "ellipsoid_side"]
    assert result.contact_charts[1].t == pytest.approx(spec.time)
    assert len(result.contact_charts[1].patches) == len(problem.fingers)
    assert result_from_manipulation_solution(plain).contact_charts is None


def test_a_switched_plan_executes_in_mujoco(egg: tuple) -> None:
    """The switched plan executed in dexroll's scene (the joints and forces: no chart
    reaches the simulator) within 2 mm and 3 deg, no planned contact lost."""
    from planner_service.execution import simulate_result

    *_, sol = egg
    report = simulate_result(result_from_manipulation_solution(sol),
                             REQUEST.validate_python(_egg_turn()))
    assert report.passed, report.failures
    assert report.position_error.max < 2e-3


def test_a_switched_plan_executes_on_a_users_hand_file_and_its_own_actuators() -> None:
    """An egg held by examples/own_hand.xml (an MJCF hand of its own: damped joints,
    position servos), its grasp searched, turned 12 deg about the palm's normal with its
    contacts switched onto the side chart at mid-motion: certified, within the file's
    actuators, and executed on the file itself driven by its own actuators (nothing of
    dexroll's scene) within 2 mm and 3 deg, no planned contact lost (0.113 mm, as the
    one-chart plan, on 2026-12-07)."""
    from planner_service.execution import simulate_result
    from planner_service.planners.actuation import with_actuation

    body = json.loads((ROOT / "examples" / "allegro_turn.json").read_text())
    body["hand"] = {"mjcf": (ROOT / "examples" / "own_hand.xml").read_text(),
                    "tips": [{"name": n} for n in ("ff_tip", "mf_tip", "rf_tip", "th_tip")]}
    body["grasp"] = "auto"
    body["object"] = {"shape": "ellipsoid", "dimensions": [0.03, 0.04]}
    body["motion"]["steps"][0].update(axis=[0, 0, 1], angle=math.radians(12), duration=2.0)
    body.update(duration=2.0, forces={"mass": 0.06}, mu=0.9)
    request = REQUEST.validate_python(body)
    problem = to_problem(request)
    side = side_charted(problem)
    assert side is not None and not problem.object.side_chart
    spec = ChartSwitchSpec(problem.duration / 2, True,
                           tuple(f.chart_rotation for f in side.fingers))
    sol = FINGERS.manipulation.solve(replace(problem, chart_switch=spec))
    assert sol.ok and sol.chart_switch is not None, sol.message
    result = with_actuation(result_from_manipulation_solution(sol), problem.actuation)
    assert result.actuator_trajectory is not None
    assert result.actuator_trajectory.max_load <= 1.0
    report = simulate_result(result, request, model="request")
    assert report.passed, report.failures
    assert all(c.loss_events == 0 for c in report.contacts), report.contacts


@pytest.mark.slow
def test_a_contact_rolls_past_its_charts_bound_on_the_next_chart() -> None:
    """egg_turn.json's grasp turned 10 deg about -z with the own chart's bound at
    60.2 deg (a pole margin of 0.52 rad): the ring's contact starts at -60.1 deg and rolls
    to -62.7 deg. Switched onto the side chart at 0.3 s, the plan is certified and
    executed in MuJoCo within 2 mm, no planned contact lost, with the ring past the own
    chart's bound after the switch (48 s, 417 iterations; on the side chart alone, which
    the planner chooses by itself, 156 iterations)."""
    from planner_service.execution import simulate_result

    raw = _egg_turn()
    raw["pole_margin"] = 0.52
    raw["motion"]["steps"][0].update(axis=[0, 0, -1], angle=math.radians(10.0))
    raw["solver"] = {"time_limit": 120}
    request = REQUEST.validate_python(raw)
    problem = to_problem(request)
    side = side_charted(problem)
    assert side is not None
    spec = ChartSwitchSpec(0.15 * problem.duration, True,
                           tuple(f.chart_rotation for f in side.fingers))
    sol = FINGERS.manipulation.solve(replace(problem, chart_switch=spec))
    assert sol.ok, sol.message
    charts = sol._interpolant.charts
    own = problem.object.u_limit(problem.pole_margin)
    end = sol.sample([problem.duration])
    cart = charts.models[1].cartesian(end.x[0], charts.prms[1])
    R, p, P = (np.asarray(cart[k]) for k in (0, 1, 4))
    from ocp.geometry.surfaces import Chart

    body = R.T @ (P - p)
    lat = [abs(float(Chart.of(problem.object.surface, problem.object.params).inverse(
        body[:, i])[0])) for i in range(P.shape[1])]
    assert max(lat) > own  # past the own chart's bound, on the side chart
    report = simulate_result(result_from_manipulation_solution(sol), request)
    assert report.passed, report.failures


def test_what_cannot_follow_a_switch_says_so(egg: tuple) -> None:
    """Tracking or re-planning a switched plan is refused naming it; a switch with a palm
    or outside the motion, named on its field."""
    from ocp.control.window import WindowController
    from ocp.solve.replan import Replanner

    _, _, switched, sol = egg
    with pytest.raises(ProblemError, match="chart switch") as exc:
        WindowController(switched, sol)
    assert exc.value.errors[0][0] == "reference"
    with pytest.raises(ProblemError, match="chart switch") as exc:
        Replanner(switched, sol)
    assert exc.value.errors[0][0] == "first"
    assert switched.chart_switch is not None
    late = replace(switched, chart_switch=replace(switched.chart_switch, time=5.0))
    assert ("chart_switch.time" in [f for f, _ in late.errors()])
    few = replace(switched, chart_switch=replace(switched.chart_switch, patches=()))
    assert ("chart_switch.patches" in [f for f, _ in few.errors()])


def test_a_switch_is_chosen_only_where_no_chart_carries_the_predicted_paths() -> None:
    """The automatic choice: egg_turn.json is carried by the egg's own chart (no switch);
    an upright egg spun 35 deg about the palm's normal with every chart's bound at 9.6 deg
    (a pole margin of 1.4 rad) leaves the side patches chosen at the start (its contacts
    roll around the equator) and is switched to side patches centred where they are
    then."""
    planner = FINGERS.manipulation
    problem = to_problem(REQUEST.validate_python(_egg_turn()))
    assert patches.switching_chart(problem, lambda: planner._initial_joints(problem)) is None
    raw = _egg_turn()
    raw["initial_pose"]["orientation_wxyz"] = [1, 0, 0, 0]
    raw["grasp"] = "auto"
    for f in raw["fingers"]:
        f.pop("initial_q", None)
    raw["pole_margin"] = 1.4
    raw["motion"]["steps"] = [{"duration": 2.0, "axis": [0, 0, -1],
                               "angle": math.radians(35.0)}]
    spun = to_problem(REQUEST.validate_python(raw))
    assert spun.object.side_chart  # (its contacts beyond the own chart's 9.6 deg)
    spec = patches.switching_chart(spun, lambda: planner._initial_joints(spun))
    assert spec is not None and spec.side_chart
    assert 0.0 < spec.time < spun.duration
    assert len(spec.patches) == len(spun.fingers)
    assert not np.allclose(np.array(spec.patches),
                           np.array([f.chart_rotation for f in spun.fingers]))


@pytest.mark.parametrize(("patched", "to_side"), [(False, True), (True, True), (True, False)],
                         ids=["own-to-side", "side-to-side", "side-to-own"])
def test_the_chart_map_restates_a_contact_as_the_numeric_rechart_does(patched: bool,
                                                                      to_side: bool) -> None:
    """chart_map (CasADi, in the NLP) against recharted_coordinates (numpy, the planner's
    restatement of a request's contacts): the same object point, the same contact angle;
    mapped there and back, the state and input come back; the rates mapped are the
    chart's coordinates' rates of the same motion (a finite difference)."""
    from ocp.geometry.rotations import log_rotation
    from ocp.geometry.surfaces import Chart, rotation_from_vector
    from ocp.shapes.ellipsoid import EggSide
    from ocp.spec.patches import recharted_coordinates

    planner = FINGERS.manipulation
    problem = to_problem(REQUEST.validate_python(_egg_turn()))
    side = side_charted(problem)
    assert side is not None
    first = side if patched else problem
    turn = np.array([[math.cos(0.3), -math.sin(0.3), 0.0], [math.sin(0.3), math.cos(0.3), 0.0],
                     [0.0, 0.0, 1.0]])  # the next side patches: turned 0.3 rad about the axis
    patches = tuple(tuple(log_rotation(turn @ rotation_from_vector(f.chart_rotation)))
                    for f in side.fingers) if to_side else ((0.0, 0.0, 0.0),) * 4
    pb = after_switch(replace(first, chart_switch=ChartSwitchSpec(1.0, to_side, patches)))
    ma, mb = planner.model(first), planner.model(pb)
    shape = np.asarray(problem.object.params, dtype=float)
    prm_a = ma.params(shape, contact_charts(first))
    prm_b = mb.params(shape, contact_charts(pb))
    charts = PlanCharts((ma, mb), (prm_a, prm_b), 10)
    x0 = planner.initial_state(first)
    rng = np.random.default_rng(3)
    u = rng.normal(size=ma.nu)
    xb, ub = charts.to_second(x0, u, np.zeros(2 * len(ma.fingertips)))
    for i, tip in enumerate(ma.fingertips):
        e = tip.eta_cols.start
        keys = ("u", "v", "psi")
        old = Chart(first.object.surface, tuple(shape), tuple(map(tuple, rotation_from_vector(
            first.fingers[i].chart_rotation))))
        new = Chart(EggSide if to_side else problem.object.surface, tuple(shape),
                    tuple(map(tuple, rotation_from_vector(patches[i]))))
        want = recharted_coordinates(old, new, dict(zip(keys, x0[e + 2:e + 5], strict=True)))
        assert want is not None
        got = dict(zip(keys, xb[e + 2:e + 5], strict=True))
        for k in keys:
            d = (got[k] - want[k] + math.pi) % (2 * math.pi) - math.pi
            assert abs(d) < 1e-9, (i, k, got[k], want[k])
    charts.refs = charts.refs_of(x0)
    xa, ua = charts.to_first(xb, ub)
    assert np.abs(xa - x0).max() < 1e-9 and np.abs(ua - u).max() < 1e-9
    # the rates: w' = d(u', v')/dt along the motion d(u, v)/dt = w
    h = 1e-6
    x1 = x0.copy()
    for tip in ma.fingertips:
        x1[tip.eta_cols.start + 2:tip.eta_cols.start + 4] += h * u[tip.w_cols]
    xb1 = charts.to_second(x1, None, charts.refs_of(xb))[0]
    for tip in ma.fingertips:
        e, w = tip.eta_cols.start, tip.w_cols
        assert np.allclose((xb1[e + 2:e + 4] - xb[e + 2:e + 4]) / h, ub[w], atol=1e-4)
