"""Plans executed in MuJoCo (sim/, docs/simulation.md): the paper's experiments and every
example with fingers, planned (by the command line: conftest) and executed with the default
grip, pass; a plan that slides the pad instead of rolling fails; without a grip the contacts
are lost; and the report's numbers obey their laws. Real MuJoCo, no mocks."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
import pytest
from conftest import CliPlans
from pydantic import TypeAdapter

from dexroll_client.models import AnyPlanResult, PlanRequest, PlanStatus
from planner_service.bench.report import (
    _table,
    machine_info,
    summarise,
    versions,
    write_report,
)
from planner_service.bench.rows import FIELDS, VOLATILE, row_from_result
from planner_service.bench.suite import Unit, expand, load_suite
from planner_service.cli import plan_request
from planner_service.execution import NotExecutableError, execution_plan, simulate_result
from planner_service.planners import REQUEST
from sim import (
    DEFAULT_MASS,
    ExecutionPlan,
    FingerReference,
    ObjectSpec,
    SimOptions,
    SimReport,
    Simulation,
    TipShape,
    simulate,
)
from sim.run import hermite

ROOT = Path(__file__).resolve().parents[1]
RESULT: TypeAdapter[AnyPlanResult] = TypeAdapter(AnyPlanResult)
#: The paper's experiments and every example whose plan has fingers.
PLANS = {
    "experiment1": ROOT / "docs" / "viewer-experiment1.json",
    "experiment2": ROOT / "examples" / "experiment2_two_fingers.json",
    **{p.stem: p for p in sorted((ROOT / "examples").glob("*.json"))
       if json.loads(p.read_text(encoding="utf-8")).get("planner") in
       ("one_finger", "manipulation") and p.stem != "experiment2_two_fingers"
       and "gait" not in json.loads(p.read_text(encoding="utf-8"))},
}
# (a gait is executed by tests/test_gait_service.py)


#: Examples that tests/test_cli.py plans by the command line (every one but the two
#: whole-hand files, which only this module plans): their plans are the command line's
#: results (conftest's cli_plans, one plan of each for the session), read back.
CLI_PLANNED = {p for p in PLANS.values() if p.parent == ROOT / "examples"
               and p.stem not in ("hand_from_mjcf", "hand_from_urdf")}


def _plan(path: Path, cli_plans: CliPlans) -> tuple[AnyPlanResult, PlanRequest]:
    raw = json.loads(path.read_text(encoding="utf-8"))
    if path in CLI_PLANNED:
        run = cli_plans[path]
        assert run.proc.returncode == 0, run.proc.stdout + run.proc.stderr
        result: AnyPlanResult = RESULT.validate_json(run.result_file.read_text())
        assert result.status is PlanStatus.SOLVED, run.proc.stdout
    else:
        result, summary = plan_request(raw)
        assert result.status is PlanStatus.SOLVED, summary
    return result, REQUEST.validate_python(raw)


def test_the_examples_with_fingers_are_all_executed() -> None:
    assert {"one_finger_roll", "three_finger_turn"} <= set(PLANS)


class _Plans(dict[str, tuple[AnyPlanResult, PlanRequest]]):
    """Each of PLANS planned when first asked for (a test of one plan plans only it)."""

    def __init__(self, cli_plans: CliPlans) -> None:
        super().__init__()
        self.cli_plans = cli_plans

    def __missing__(self, name: str) -> tuple[AnyPlanResult, PlanRequest]:
        self[name] = _plan(PLANS[name], self.cli_plans)
        return self[name]


class _Executed(dict[str, SimReport]):
    def __init__(self, plans: _Plans) -> None:
        super().__init__()
        self.plans = plans

    def __missing__(self, name: str) -> SimReport:
        self[name] = simulate_result(*self.plans[name])
        return self[name]


@pytest.fixture(scope="module")
def plans(cli_plans: CliPlans) -> _Plans:
    return _Plans(cli_plans)


@pytest.fixture(scope="module")
def executed(plans: _Plans) -> _Executed:
    return _Executed(plans)


def check_laws(report: SimReport) -> None:
    """What every report says of itself, whatever the plan."""
    assert report.passed == (not report.failures)
    for e in (report.position_error, report.angle_error):
        assert 0 <= e.final <= e.max and 0 <= e.rms <= e.max
        assert e.worst_at is None or 0 <= e.worst_at <= report.duration + 1e-9
    for c in report.contacts:
        assert 0 <= c.lost_time <= report.duration + 1e-9
        assert (c.lost_time > 0) == (c.loss_events > 0) == (c.first_loss_at is not None)
        assert c.slip_distance >= 0 and c.max_slip_speed >= 0
        # the slip integrates a speed over at most the horizon
        assert c.slip_distance <= c.max_slip_speed * report.duration * (1 + 1e-9)
        assert 0 <= c.normal_force_min <= c.normal_force_mean <= c.normal_force_max
        if c.lost_time > 0:
            assert c.normal_force_min == 0
    s = report.series
    t = np.asarray(s["t"])
    assert np.all(np.diff(t) > 0)
    during = t >= 0
    # the series is recorded from the same steps: never above the worst
    assert np.max(np.asarray(s["position_error"])[during]) <= report.position_error.max
    assert np.max(np.asarray(s["angle_error"])[during]) <= report.angle_error.max
    assert set(s["normal_force"]) == {c.name for c in report.contacts}
    json.dumps(report.to_dict(), allow_nan=False)


#: The three longest executions (11-18 s each on two loaded cores) run with `make
#: test-slow`; the default run executes every other example (the capsule over its seam,
#: the egg by its end among them).
SLOW_PLANS = {"ellipsoid_two_fingers", "capsule_roll", "egg_turn"}


@pytest.mark.parametrize("name", [pytest.param(n, marks=pytest.mark.slow) if n in SLOW_PLANS
                                  else n for n in PLANS])
def test_planned_motions_execute_within_tolerance(executed: dict[str, SimReport],
                                                  name: str) -> None:
    report = executed[name]
    check_laws(report)
    assert report.passed, report.summary()
    assert report.position_error.max <= 1e-3
    assert report.angle_error.max <= math.radians(2.0)
    assert all(c.lost_time == 0 for c in report.contacts)
    assert report.mode == "servo" and report.steps > 0


@pytest.mark.parametrize("name", ["experiment1", "experiment2"])
def test_without_a_grip_a_contact_is_lost(plans: dict[str, tuple[AnyPlanResult, PlanRequest]],
                                          name: str) -> None:
    result, request = plans[name]
    report = simulate_result(result, request, {"squeeze": 0.0, "grip_force": 0.0})
    check_laws(report)
    assert not report.passed
    assert any(c.lost_time > 0 for c in report.contacts), report.summary()
    assert any("lost" in f for f in report.failures)


def _ik(sim: Simulation, finger: int, q0: np.ndarray, R: np.ndarray, p: np.ndarray
        ) -> np.ndarray:
    """Joint angles putting the fingertip frame at (R, p), from q0 (damped least squares
    on MuJoCo's own kinematics)."""
    m = sim.model
    d = mujoco.MjData(m)
    idx = sim.fingers[finger]
    q = q0.copy()
    jacp, jacr = np.zeros((3, m.nv)), np.zeros((3, m.nv))
    for _ in range(50):
        d.qpos[idx.qpos] = q
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        Rc = d.site_xmat[idx.tip_site].reshape(3, 3)
        dp = p - d.site_xpos[idx.tip_site]
        dR = Rc.T @ R
        angle = math.acos(max(-1.0, min(1.0, (np.trace(dR) - 1) / 2)))
        axis = np.array([dR[2, 1] - dR[1, 2], dR[0, 2] - dR[2, 0], dR[1, 0] - dR[0, 1]])
        w = Rc @ (axis / (2 * math.sin(angle)) * angle) if angle > 1e-12 else np.zeros(3)
        err = np.concatenate([dp, w])
        if np.linalg.norm(err) < 1e-10:
            break
        mujoco.mj_jacSite(m, d, jacp, jacr, idx.tip_site)
        J = np.vstack([jacp[:, idx.dofs], jacr[:, idx.dofs]])
        q = q + J.T @ np.linalg.solve(J @ J.T + 1e-10 * np.eye(6), err)
    return q


def test_a_pad_that_slides_instead_of_rolling_fails(
        plans: dict[str, tuple[AnyPlanResult, PlanRequest]]) -> None:
    """The one-finger roll with the fingertip carried along the ball centre's path, its
    orientation kept: the pad slides over the ball instead of rolling on it (the plan
    rolls the ball 10 mm, its pad travels 20 mm): the ball cannot follow the plan."""
    result, request = plans["one_finger_roll"]
    plan = execution_plan(result, request)
    sim = Simulation(plan)
    d = mujoco.MjData(sim.model)
    idx = sim.fingers[0]
    d.qpos[idx.qpos] = plan.references[0].q[0]
    mujoco.mj_kinematics(sim.model, d)
    R0 = d.site_xmat[idx.tip_site].reshape(3, 3).copy()
    p0 = d.site_xpos[idx.tip_site].copy()
    q = [plan.references[0].q[0]]
    for k in range(1, plan.t.size):
        shift = plan.object_position[k] - plan.object_position[0]
        q.append(_ik(sim, 0, q[-1], R0, p0 + shift))
    qa = np.array(q)
    qd = np.gradient(qa, plan.t, axis=0)
    wrong = replace(plan, references=(FingerReference(qa, qd),))
    report = simulate(wrong)
    check_laws(report)
    assert not report.passed
    assert report.position_error.max > 2e-3, report.summary()  # ~5 mm of 10 mm
    # the same plan as planned passes (the controller is not the reason)
    assert simulate(plan).passed


def test_replaying_the_object_has_no_error(
        plans: dict[str, tuple[AnyPlanResult, PlanRequest]]) -> None:
    result, request = plans["experiment2"]
    plan = _head(execution_plan(result, request), 81)  # its first second
    report = simulate(plan, SimOptions(mode="replay"))
    check_laws(report)
    assert report.position_error.max == 0.0 and report.angle_error.max == 0.0
    # the pads, moved 0.5 mm into the object, press on it all along
    assert all(c.lost_time == 0 and c.normal_force_min > 0 for c in report.contacts)
    kinematic = simulate(plan, SimOptions(mode="kinematic"))
    check_laws(kinematic)
    assert kinematic.passed, kinematic.summary()


def test_the_scene_is_the_plans(plans: dict[str, tuple[AnyPlanResult, PlanRequest]]) -> None:
    result, request = plans["experiment2"]
    plan = execution_plan(result, request)
    sim = Simulation(plan)
    m = sim.model
    assert m.opt.cone == mujoco.mjtCone.mjCONE_ELLIPTIC
    assert m.opt.impratio == 10 and m.opt.noslip_iterations == 3 and m.opt.timestep == 5e-4
    obj = sim.object_geom
    assert m.geom_condim[obj] == 4 and m.geom_friction[obj][0] == pytest.approx(0.5)
    r = plan.object.dimensions[0]
    assert m.body_mass[sim.object_body] == pytest.approx(DEFAULT_MASS)
    assert m.body_inertia[sim.object_body] == pytest.approx([0.4 * DEFAULT_MASS * r * r] * 3)
    assert mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "palm") == -1  # no palm planned
    # the fingertips sit where the plan has them, touching the ball
    d = mujoco.MjData(m)
    for idx, ref, track in zip(sim.fingers, plan.references, result.trajectory.fingers,
                               strict=True):
        d.qpos[idx.qpos] = ref.q[0]
        mujoco.mj_kinematics(m, d)
        assert d.site_xpos[idx.tip_site] == pytest.approx(track.tip_position[0], abs=1e-9)
    # the JSON form of the plan is the same plan: the same run, number for number
    again = ExecutionPlan.from_dict(json.loads(json.dumps(plan.to_dict())))
    # ... with a plan's own squeeze and force control (a gait's) carried too
    own = replace(plan, squeeze=1e-4, force_control="pi")
    back = ExecutionPlan.from_dict(json.loads(json.dumps(own.to_dict())))
    assert (back.squeeze, back.force_control) == (1e-4, "pi")
    options = SimOptions(settle=0.05)
    short = replace(plan, t=plan.t[:9], object_position=plan.object_position[:9],
                    object_wxyz=plan.object_wxyz[:9],
                    references=tuple(FingerReference(r.q[:9], r.q_dot[:9])
                                     for r in plan.references),
                    contacts=tuple(replace(c, point=c.point[:9], normal=None)
                                   for c in plan.contacts))
    short_again = replace(again, t=short.t, object_position=short.object_position,
                          object_wxyz=short.object_wxyz, references=short.references,
                          contacts=short.contacts)
    a, b = simulate(short, options), simulate(short_again, options)
    assert a.to_dict(series=False) | {"wall_time": 0} == \
        b.to_dict(series=False) | {"wall_time": 0}
    # the object's mass is an option: a heavier ball, the same run otherwise
    heavy = Simulation(plan, SimOptions(object_mass=0.2))
    assert heavy.model.body_mass[heavy.object_body] == pytest.approx(0.2)
    # the geom it is given: an ellipsoid (a, a, c), MuJoCo's solid ellipsoid
    egg = Simulation(replace(plan, object=ObjectSpec("ellipsoid", (0.02, 0.02, 0.03), 0.1)))
    em = egg.model
    assert em.geom_type[egg.object_geom] == mujoco.mjtGeom.mjGEOM_ELLIPSOID
    assert em.geom_size[egg.object_geom] == pytest.approx([0.02, 0.02, 0.03])
    a2, c2 = 0.02**2, 0.03**2
    assert em.body_inertia[egg.object_body] == pytest.approx(
        [0.1 * (a2 + c2) / 5, 0.1 * (a2 + c2) / 5, 0.1 * 2 * a2 / 5])


@pytest.mark.parametrize("kind", ["box", "sphere", "ellipsoid", "capsule"])
def test_fingertip_shapes_are_placed_as_the_planner_places_them(
        kind: str, plans: dict[str, Any]) -> None:
    """ocp/geometry/tips.py's frames: a pad's top face through the frame's origin; a
    sphere or spheroid centred on it; a capsule's cap centred on it, the cylinder along
    the frame's +y (its axis points out of the cap along -y)."""
    result, request = plans["experiment2"]
    plan = execution_plan(result, request)
    R = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # 90 deg about z
    offset = np.array([0.001, 0.002, -0.003])
    size = {"box": (0.01, 0.01, 0.004), "sphere": (0.01,), "ellipsoid": (0.01, 0.015),
            "capsule": (0.008, 0.01)}[kind]
    tip = TipShape(kind, size, R, offset)
    fingers = tuple(replace(f, tip=tip) for f in plan.fingers)
    sim = Simulation(replace(plan, fingers=fingers))
    m, d = sim.model, sim.data
    gid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, f"{plan.fingers[0].name}/pad")
    mujoco.mj_kinematics(m, d)
    site = sim.fingers[0].tip_site
    Rs, ps = d.site_xmat[site].reshape(3, 3), d.site_xpos[site]
    centre = Rs.T @ (d.geom_xpos[gid] - ps)  # the geom's centre in the fingertip frame
    axis = Rs.T @ d.geom_xmat[gid].reshape(3, 3)[:, 2]
    expected = {"box": offset + R @ [0, 0, -0.002], "sphere": offset,
                "ellipsoid": offset, "capsule": offset + R @ [0, 0.01, 0]}[kind]
    assert centre == pytest.approx(expected, abs=1e-12)
    if kind in ("box", "ellipsoid"):
        assert axis == pytest.approx(R[:, 2], abs=1e-12)
    if kind == "capsule":  # along the frame's y (either way: the capsule is symmetric)
        assert abs(axis @ R[:, 1]) == pytest.approx(1.0, abs=1e-12)
    # the JSON form keeps the placement
    again = ExecutionPlan.from_dict(replace(plan, fingers=fingers).to_dict())
    assert again.fingers[0].tip.offset == pytest.approx(offset)


def test_plans_without_fingers_are_not_executed() -> None:
    result, _ = plan_request(json.loads((ROOT / "examples" / "triangle.json").read_text()))
    with pytest.raises(NotExecutableError, match="no fingers"):
        execution_plan(result)


def test_options_are_checked() -> None:
    with pytest.raises(ValueError, match="unknown"):
        SimOptions.from_dict({"squeez": 1e-3})
    with pytest.raises(ValueError, match="mode"):
        SimOptions.from_dict({"mode": "teleport"})
    with pytest.raises(ValueError, match="solref"):
        SimOptions.from_dict({"timestep": 0.005})
    assert SimOptions.from_dict({"tolerances": {"position": 2e-3}}).tolerances.position == 2e-3


def test_sim_is_independent_of_the_planner_and_the_service() -> None:
    """sim/ takes plain data: importing it loads neither the planner (ocp, CasADi,
    Pinocchio) nor the service."""
    code = ("import sys, sim; bad = [m for m in sys.modules if m.split('.')[0] in "
            "('ocp', 'planner_service', 'casadi', 'pinocchio', 'fastapi')]; print(bad); "
            "sys.exit(bool(bad))")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=False)
    assert proc.returncode == 0, proc.stdout + proc.stderr


def _head(plan: ExecutionPlan, n: int) -> ExecutionPlan:
    """The plan's first n samples."""
    return replace(plan, t=plan.t[:n], object_position=plan.object_position[:n],
                   object_wxyz=plan.object_wxyz[:n],
                   references=tuple(FingerReference(r.q[:n], r.q_dot[:n])
                                    for r in plan.references),
                   contacts=tuple(replace(c, point=c.point[:n],
                                          normal=None if c.normal is None else c.normal[:n])
                                  for c in plan.contacts))


def test_a_plans_own_forces_replace_the_grip(
        plans: dict[str, tuple[AnyPlanResult, PlanRequest]]) -> None:
    """A plan that states its contact forces (issue 15, part 1) is executed with them as
    feed-forward (J^T f) instead of the grip force; one that states joint torques, with
    those. A plan pushing 1 N into the object at each fingertip runs as the 1 N grip."""
    result, request = plans["experiment2"]
    plan = _head(execution_plan(result, request), 41)
    assert not plan.has_forces
    normal_of = {c.finger: c.normal for c in plan.contacts if c.finger is not None}
    pushing = replace(plan, references=tuple(
        replace(r, contact_force=-1.0 * normal_of[f.name])
        for f, r in zip(plan.fingers, plan.references, strict=True)))
    assert pushing.has_forces
    gripped = simulate(plan, SimOptions(grip_force=1.0))
    forced = simulate(pushing, SimOptions(grip_force=0.0))  # the option is not used
    check_laws(forced)
    assert any("the plan's contact force" in n for n in forced.notes)
    assert forced.position_error.max == pytest.approx(gripped.position_error.max, abs=1e-6)
    for c, g in zip(forced.contacts, gripped.contacts, strict=True):
        assert c.planned_normal_force_mean == pytest.approx(1.0)
        # the worst difference is at least the difference of the means
        assert c.normal_force_error_max >= abs(c.normal_force_mean - 1.0) - 1e-12
        assert c.normal_force_mean == pytest.approx(g.normal_force_mean, rel=1e-3)
        assert g.planned_normal_force_mean is None and g.normal_force_error_max is None
    # the same feed-forward stated as joint torques: the same run, number for number
    _, torques, _ = Simulation(pushing, SimOptions(grip_force=0.0))._feedforward()
    with_torques = replace(plan, references=tuple(
        replace(r, joint_torques=tau) for r, tau in zip(plan.references, torques,
                                                        strict=True)))
    torqued = simulate(with_torques, SimOptions(grip_force=0.0))
    assert any("the plan's joint torques" in n for n in torqued.notes)
    assert torqued.position_error == forced.position_error
    assert [c.normal_force_mean for c in torqued.contacts] == \
        [c.normal_force_mean for c in forced.contacts]
    # without use_plan_forces the grip option is used again
    ignored = simulate(pushing, SimOptions(grip_force=1.0, use_plan_forces=False))
    assert ignored.position_error == gripped.position_error


# -- the bench's "executed" column -------------------------------------------------------------

def _unit(name: str, planner: str, request: dict[str, Any]) -> Unit:
    return Unit("paper", name, "collocation", planner, request, "solved")


def test_bench_rows_execute_solved_finger_plans(
        plans: dict[str, tuple[AnyPlanResult, PlanRequest]],
        monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """Every row of a solved plan with fingers (the quick suite's experiment 2 is
    examples/experiment2_two_fingers.json) carries its execution; the report's table an
    "executed" column per family and method."""
    (fixed,) = [p for p in expand(load_suite("quick"), families=["paper"])
                if p.id == "experiment2"]
    request = json.loads(PLANS["experiment2"].read_text(encoding="utf-8"))
    assert fixed.request == request
    result, _ = plans["experiment2"]
    row = row_from_result(_unit("experiment2", "manipulation", request), result, 1.0, 0, 0.0)
    assert set(row) == set(FIELDS) and row["ok"]
    assert row["exec_status"] == "passed", row["exec_message"]
    assert 0 <= row["exec_position_error_max"] <= 1e-3
    assert 0 <= row["exec_angle_error_max"] <= math.radians(2.0)
    assert row["exec_contacts_lost"] == 0 and row["exec_wall_time"] > 0
    assert "exec_status" not in VOLATILE and "exec_position_error_max" in VOLATILE
    # a ball on the palm alone: nothing to execute
    triangle = json.loads((ROOT / "examples" / "triangle.json").read_text())
    palm_result, _ = plan_request(triangle)
    palm_row = row_from_result(_unit("triangle", "ball_on_palm", triangle), palm_result, 1.0,
                               0, 0.0)
    assert palm_row["ok"] and palm_row["exec_status"] is None
    # a failed execution is reported as such
    summary = summarise([row, palm_row, dict(row, problem_id="x", exec_status="failed",
                                             exec_position_error_max=0.01)], ["paper"])
    (paper,) = summary
    assert paper["executed"] == 2 and paper["executed_passed"] == 1
    assert paper["exec_position_error_max"] == 0.01
    table = _table(summary)
    assert table[0].endswith("| executed (worst mm, deg) |")
    assert "| 1/2 (10.00 mm, " in table[2]
    # the report lists the failed execution, and MuJoCo's version
    meta = {"suite": {"name": "t", "source": "test", "description": "", "definition": {}},
            "run": {"runner": "pool", "workers": 1, "started": "", "finished": "",
                    "wall_time": 1.0, "url": None, "methods": ["collocation"],
                    "families": ["paper"], "limit": None, "notes": []},
            "machine": machine_info(), "versions": versions(), "skipped_methods": {}}
    failed = dict(row, problem_id="x", exec_status="failed", exec_position_error_max=0.01,
                  exec_message="position error 10 mm > 1 mm")
    doc = write_report(tmp_path, [row, failed], meta, [])
    report = (tmp_path / "report.md").read_text()
    assert "## Solved plans whose execution in MuJoCo failed" in report
    assert "| paper | x | collocation | failed | 10.000 mm |" in report
    assert doc["versions"]["mujoco"] == mujoco.__version__
    # DEXROLL_BENCH_EXECUTE=0 turns it off
    monkeypatch.setenv("DEXROLL_BENCH_EXECUTE", "0")
    off = row_from_result(_unit("experiment2", "manipulation", request), result, 1.0, 0, 0.0)
    assert off["ok"] and off["exec_status"] is None


def test_the_reference_follows_the_plan_on_both_sides_of_a_rate_break(
        plans: dict[str, tuple[AnyPlanResult, PlanRequest]]) -> None:
    """Experiment 1's joint velocities jump at its via-points with the paper's timing
    (the default, smooth, has none: docs/timing.md): the executed plan lists each break
    twice, with the incoming velocities first, and the reference's rate is the plan's on
    either side."""
    raw = {**json.loads(PLANS["experiment1"].read_text(encoding="utf-8")), "timing": "paper"}
    result, summary = plan_request(raw)
    assert result.status is PlanStatus.SOLVED, summary
    assert not plans["experiment1"][0].joint_trajectory.rate_breaks
    request = REQUEST.validate_python(raw)
    plan = execution_plan(result, request)
    breaks = result.joint_trajectory.rate_breaks
    assert [b.t for b in breaks] == pytest.approx([2.0, 4.0])
    for b in breaks:
        (i, j) = np.flatnonzero(plan.t == b.t)
        assert j == i + 1
        ref = plan.references[0]
        assert ref.q[i] == pytest.approx(ref.q[j], abs=0)
        assert ref.q_dot[i] == pytest.approx(b.velocities_before, abs=1e-12)
        assert ref.q_dot[j] == pytest.approx(b.velocities_after, abs=1e-12)
        eps = 1e-7
        _, rate = hermite(plan.t, ref.q, ref.q_dot, np.array([b.t - eps, b.t, b.t + eps]))
        assert rate[0] == pytest.approx(b.velocities_before, abs=1e-4)
        assert rate[1] == pytest.approx(b.velocities_after, abs=1e-12)
        assert rate[2] == pytest.approx(b.velocities_after, abs=1e-4)


def test_hermite_is_exact_for_cubics_and_splits_at_repeated_times() -> None:
    t = np.array([0.0, 0.5, 1.0, 1.0, 2.0])
    cubic = np.array([[x**3 - x] for x in t])
    rate = np.array([[3 * x**2 - 1] for x in t])
    ts = np.linspace(0.0, 1.0, 7)
    value, d = hermite(t[:3], cubic[:3], rate[:3], ts)
    assert value[:, 0] == pytest.approx(ts**3 - ts, abs=1e-12)
    assert d[:, 0] == pytest.approx(3 * ts**2 - 1, abs=1e-12)
    # a break at t = 1: after it a straight line of slope 5 from the cubic's value there
    y = np.vstack([cubic[:4], [[cubic[3, 0] + 5.0]]])
    dy = np.vstack([rate[:3], [[5.0]], [[5.0]]])
    value, d = hermite(t, y, dy, np.array([0.75, 1.5]))
    assert value[:, 0] == pytest.approx([0.75**3 - 0.75, 2.5], abs=1e-12)
    assert d[:, 0] == pytest.approx([3 * 0.75**2 - 1, 5.0], abs=1e-12)
