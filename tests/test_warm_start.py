"""Warm starts through the wire: a result's ``collocation`` block, a request's
``warm_start`` (a finished job's id, resolved by the service at submission, or the plan
inline), the conversion to the planners' ``WarmStart``, the client and the command line.

The service tests run against the shared ``live_server`` (uvicorn, two workers, SQLite);
the job-store cases that a live service cannot be held in (a job still queued, a stored
plan that does not fit) run the submission checks on a store of their own.
"""

from __future__ import annotations

import asyncio
import copy
import json
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest
from conftest import Server
from helpers import assert_close
from pydantic import TypeAdapter, ValidationError

from dexroll_client import (
    AsyncDexrollClient,
    CollocationModel,
    DexrollClient,
    FingerPlanResult,
    InvalidRequestError,
    Job,
    JobState,
    ManipulationResult,
    PlanRequest,
    PlanResult,
    PlanStatus,
    WarmStartModel,
)
from ocp.solution import Status
from ocp.solve.planner import ManipulationProblem
from ocp.transcription.collocation import NlpPoint, WarmStart
from planner_service.api.submission import resolve_warm_start, submission_errors
from planner_service.cli import main as cli_main
from planner_service.jobs.store import Store
from planner_service.planners import (
    FingerCache,
    adapter_for,
    request_errors,
    solve,
    to_problem,
)
from planner_service.settings import Settings

ROOT = Path(__file__).resolve().parents[1]
TRIANGLE_FILE = ROOT / "examples" / "triangle.json"
TRIANGLE: dict[str, Any] = json.loads(TRIANGLE_FILE.read_text())
ROLL: dict[str, Any] = json.loads((ROOT / "examples" / "one_finger_roll.json").read_text())
EXP2: dict[str, Any] = json.loads(
    (ROOT / "examples" / "experiment2_two_fingers.json").read_text())
REQUEST: TypeAdapter[PlanRequest] = TypeAdapter(PlanRequest)
#: The ball-on-palm certificate's position tolerance [m]: the goal is reached within it.
GOAL_TOL = 1e-6


def post(server: Server, body: Any, wait: float = 60.0, **headers: str) -> httpx.Response:
    return httpx.post(f"{server.url}/v1/plans", params={"wait": wait}, json=body,
                      headers=headers, timeout=90)


def fields(response: httpx.Response) -> dict[str, str]:
    assert response.status_code == 422, response.text
    body = response.json()
    assert body["error"] == "invalid_request" and "Traceback" not in response.text
    return {d["field"]: d["reason"] for d in body["detail"]}


def assert_triangle_reached(job: dict[str, Any]) -> None:
    """Solved, certified, and through every via-point to the goal (the origin)."""
    assert job["state"] == "succeeded", job["message"]
    result = job["result"]
    assert result["status"] == "solved" and result["certificate"]["passed"]
    assert max(result["goal_error"].values()) <= GOAL_TOL, result["goal_error"]
    final = result["grid"]["eta"][-1]
    assert abs(final[0]) <= GOAL_TOL and abs(final[1]) <= GOAL_TOL
    # the plan starts at the request's initial state, whatever the warm start held
    assert_close(result["grid"]["eta"][0], [TRIANGLE["initial"][c] for c in
                                            ("x", "y", "u", "v", "psi")], atol=1e-9)


def collocation_of(job: dict[str, Any]) -> dict[str, Any]:
    block: dict[str, Any] = job["result"]["collocation"]
    return block


@pytest.fixture(scope="module")
def first(live_server: Server) -> dict[str, Any]:
    """A finished ball-on-palm job (the triangle) to warm-start from."""
    r = post(live_server, TRIANGLE)
    assert r.status_code == 201, r.text
    job: dict[str, Any] = r.json()
    assert_triangle_reached(job)
    return job


# -- the wire models (no service) ------------------------------------------------------------

@pytest.mark.parametrize(("warm", "loc", "words"), [
    ({}, (), "give `job_id`"),
    ({"job_id": "abc", "t": [0.0, 1.0]}, (), "not both"),
    ({"job_id": "abc", "state_names": ["x"]}, (), "not both"),
    ({"t": [0.0, 1.0], "x": [[0.0], [1.0]]}, (), "`u` missing"),
    ({"t": [0.0, 1.0], "x": [[0.0, 1.0], [1.0]], "u": [[0.0], [0.0]]}, ("x",),
     "same number of columns"),
    ({"t": [0.0, 1.0], "x": [[0.0]], "u": [[0.0], [0.0]]}, ("x",), "one row per time"),
    ({"t": [0.5, 1.0], "x": [[0.0]] * 2, "u": [[0.0]] * 2}, ("t",), "start at 0"),
    ({"t": [0.0, 1.0, 1.0], "x": [[0.0]] * 3, "u": [[0.0]] * 3}, ("t",), "increase"),
    ({"t": [0.0, 1.0], "x": [[0.0]] * 2, "u": [[0.0]] * 2, "state_names": ["a", "b"]},
     ("state_names",), "every column"),
    ({"t": [0.0, 1.0], "x": [[float("nan")]] * 2, "u": [[0.0]] * 2}, ("x", 0, 0), "finite"),
])
def test_a_warm_start_is_a_job_id_or_a_whole_plan(warm: dict[str, Any], loc: tuple[Any, ...],
                                                  words: str) -> None:
    with pytest.raises(ValidationError) as err:
        WarmStartModel.model_validate(warm)
    errors = err.value.errors()
    assert any(e["loc"] == loc and words in e["msg"] for e in errors), errors


def test_a_result_without_a_plan_gives_no_warm_start() -> None:
    empty = PlanResult(status=PlanStatus.INVALID_INPUT, message="bad")
    with pytest.raises(ValueError, match="no `collocation` block"):
        WarmStartModel.from_result(empty)


# -- the planners' adapters (planner_service.planners), in process --------------------------------

def test_a_ball_on_palm_collocation_block_is_the_plan_at_its_grid_and_warm_starts_it() -> None:
    result, _ = solve(REQUEST.validate_python(TRIANGLE))
    assert isinstance(result, PlanResult) and result.status is PlanStatus.SOLVED
    c, grid = result.collocation, result.grid
    assert c is not None and grid is not None
    assert (c.state_names, c.input_names) == (["x", "y", "u", "v", "psi"], ["w_x", "w_y"])
    assert c.t == grid.t and c.x == grid.eta and c.u == grid.w
    # passed as it is, names included, to a request of another duration (stretched)
    request = REQUEST.validate_python({**TRIANGLE, "duration": 6.5,
                                       "warm_start": c.model_dump()})
    assert request_errors(request) == []
    warm, _ = solve(request)
    assert isinstance(warm, PlanResult) and warm.status is PlanStatus.SOLVED
    assert warm.certificate is not None and warm.certificate.passed
    assert warm.goal_error is not None and max(warm.goal_error.values()) <= GOAL_TOL
    # a plan of other columns is refused by field, before any solve
    narrow = {"t": c.t, "x": [row[:4] for row in c.x], "u": c.u}
    errors = dict(request_errors(REQUEST.validate_python({**TRIANGLE, "warm_start": narrow})))
    assert "5 states" in errors["warm_start.x"] and "121 x 4" in errors["warm_start.x"]
    renamed = {**c.model_dump(), "state_names": ["a", "y", "u", "v", "psi"]}
    errors = dict(request_errors(REQUEST.validate_python({**TRIANGLE,
                                                          "warm_start": renamed})))
    assert "'a'" in errors["warm_start.state_names"]
    # a job id is the service's to resolve: the library path names it
    errors = dict(request_errors(REQUEST.validate_python(
        {**TRIANGLE, "warm_start": {"job_id": "abc"}})))
    assert "POST /v1/plans" in errors["warm_start.job_id"]


def test_a_one_finger_plan_warm_starts_a_nearby_one_through_the_conversion() -> None:
    """The finger NLP takes seconds to build: one plan, then a nearby goal warm-started
    from it (the same cache: the NLP is reused)."""
    cache = FingerCache()
    result, _ = solve(REQUEST.validate_python(ROLL), fingers=cache)
    assert isinstance(result, FingerPlanResult) and result.status is PlanStatus.SOLVED
    c, tr = result.collocation, result.trajectory
    assert c is not None and tr is not None
    joints = result.joint_names
    assert c.state_names == ([f"palm.{k}" for k in ("x", "y", "u", "v", "psi")]
                             + [f"finger.{k}" for k in ("x", "y", "u", "v", "psi")]
                             + [f"finger.q.{j}" for j in joints])
    assert c.input_names == (["palm.w_x", "palm.w_y", "finger.w_u", "finger.w_v"]
                             + [f"finger.q_dot.{j}" for j in joints])
    # the columns are the trajectory's arrays, in that order
    x, u = np.array(c.x), np.array(c.u)
    assert c.t == tr.t
    assert_close(x, np.hstack([tr.eta_p, tr.eta_f, tr.q]), atol=0.0)
    assert_close(u, np.hstack([tr.w_p, tr.w_f, tr.q_dot]), atol=0.0)

    goal_x = ROLL["goal"]["x"] + 0.002
    nearby = copy.deepcopy(ROLL)
    nearby["goal"]["x"] = goal_x
    # on the warm plan's own grid (the certificate refined it): the same NLP
    nearby["n_intervals"] = (len(c.t) - 1) // 2
    nearby["warm_start"] = c.model_dump()
    request = REQUEST.validate_python(nearby)
    assert request_errors(request, cache) == []
    warm, _ = solve(request, fingers=cache)
    assert isinstance(warm, FingerPlanResult)
    assert warm.status is PlanStatus.SOLVED, warm.message
    assert warm.certificate is not None and warm.certificate.passed
    assert warm.trajectory is not None
    assert abs(warm.trajectory.eta_p[-1][0] - goal_x) <= GOAL_TOL
    assert_close(warm.trajectory.eta_p[0], [ROLL["initial"][k] for k in
                                            ("x", "y", "u", "v", "psi")], atol=1e-9)
    # the collocation block carries IPOPT's primal-dual point of this NLP: a nearby problem
    # of the same NLP starts from it, and an interior-point method then needs fewer
    # iterations than from the planner's own guess
    assert c.nlp_point is not None
    assert len(c.nlp_point.w) == len(c.nlp_point.lam_x) > 0 and len(c.nlp_point.lam_g) > 0
    nearby.pop("warm_start")
    cold, _ = solve(REQUEST.validate_python(nearby), fingers=cache)
    assert cold.status is PlanStatus.SOLVED and cold.stats is not None
    assert warm.stats is not None and warm.stats.iterations < cold.stats.iterations
    assert warm.stats.refinements == cold.stats.refinements == 0
    # both are the same optimum (IPOPT's tolerance): the same plan to well below a micron
    assert_close(np.array(warm.trajectory.eta_p), np.array(cold.trajectory.eta_p),
                 atol=1e-6)

    # a ball-on-palm plan does not fit a one-finger request: named, nothing solved
    palm_plan = {"t": c.t, "x": [row[:5] for row in c.x], "u": [row[:2] for row in c.u],
                 "state_names": ["x", "y", "u", "v", "psi"], "input_names": ["w_x", "w_y"]}
    errors = dict(request_errors(REQUEST.validate_python({**ROLL, "warm_start": palm_plan}),
                                 cache))
    assert {"warm_start.x", "warm_start.u", "warm_start.state_names",
            "warm_start.input_names"} <= set(errors)
    assert f"{len(c.state_names)} states" in errors["warm_start.x"]
    # the greedy method takes no initial guess
    greedy = REQUEST.validate_python({**ROLL, "method": "greedy", "warm_start": c.model_dump()})
    assert "greedy" in dict(request_errors(greedy, cache))["warm_start"]


def test_a_primal_dual_point_is_used_only_by_its_own_nlp() -> None:
    point = NlpPoint("nlp-a", np.zeros(4), np.zeros(4), np.zeros(3))
    ws = WarmStart.of([0.0, 1.0], np.zeros((2, 2)), np.zeros((2, 1)), point)
    assert ws.nlp_point_for("nlp-a", 4, 3) is point
    assert ws.nlp_point_for("nlp-b", 4, 3) is None  # another structure or grid
    assert ws.nlp_point_for("nlp-a", 5, 3) is None  # sizes that do not fit
    assert ws.nlp_point_for("nlp-a", 4, 2) is None
    bad = WarmStart.of([0.0, 1.0], np.zeros((2, 2)), np.zeros((2, 1)),
                       NlpPoint("nlp-a", np.zeros(4), np.array([0.0, np.nan, 0, 0]),
                                np.zeros(3)))
    assert [f for f, _ in bad.errors("warm_start", 2, 1)] == ["warm_start.nlp_point.lam_x"]


def test_a_neighbouring_plans_multipliers_start_the_same_optimum_in_fewer_iterations(
        ) -> None:
    """A gait's roll of a turned egg is another problem than the last roll (its contacts
    elsewhere on the egg), so its states are no start, but its multipliers are: the
    planner's own guess with them (``multipliers``) reaches the optimum the cold solve
    reaches, in fewer iterations; multipliers of another NLP are not used (the cold
    solve, iteration for iteration). The paper's experiment 2 stands in for the egg: its
    first step turned 20 deg, then 24 deg."""
    cache = FingerCache()

    def problem(angle: float, n_intervals: int | None = None) -> ManipulationProblem:
        raw = copy.deepcopy(EXP2)
        raw["motion"]["steps"] = raw["motion"]["steps"][:1]
        raw["motion"]["steps"][0]["angle"] = angle
        raw["duration"] = raw["motion"]["steps"][0]["duration"]
        if n_intervals is not None:
            raw["n_intervals"] = n_intervals
        out = to_problem(REQUEST.validate_python(raw), cache)
        assert isinstance(out, ManipulationProblem)
        return out

    planner = cache.manipulation
    before = planner.solve(problem(0.349))
    assert before.status is Status.SOLVED and before.nlp_point is not None
    target = problem(0.419)
    cold = planner.solve(target)
    warm = planner.solve(target, multipliers=before.nlp_point)
    assert cold.status is warm.status is Status.SOLVED
    assert warm.certificate.passed and cold.stats is not None and warm.stats is not None
    assert warm.stats.iterations < cold.stats.iterations, (warm.stats.iterations,
                                                          cold.stats.iterations)
    for a, b in zip(warm.fingers, cold.fingers, strict=True):
        assert_close(a.q, b.q, atol=1e-5)  # the same optimum, to IPOPT's tolerance
    # another grid is another NLP: its multipliers are not this one's
    other = planner.solve(problem(0.349, 2 * target.n_intervals))
    assert other.nlp_point is not None
    again = planner.solve(target, multipliers=other.nlp_point)
    assert again.stats is not None and again.stats.iterations == cold.stats.iterations
    for a, b in zip(again.fingers, cold.fingers, strict=True):
        assert_close(a.q, b.q, atol=0.0)


def test_manipulation_columns_follow_the_planners_layout() -> None:
    """Names of a free object held by two fingers: the object's pose first, then each
    fingertip's contact coordinates and joints where the planner's layout has them."""
    cache = FingerCache()
    problem = to_problem(REQUEST.validate_python(EXP2), cache)
    assert isinstance(problem, ManipulationProblem)
    states, inputs = adapter_for(REQUEST.validate_python(EXP2)).collocation_names(problem)
    model = cache.manipulation.model(problem)
    assert (len(states), len(inputs)) == (model.nx, model.nu)
    assert states[:7] == ["object.position.x", "object.position.y", "object.position.z",
                          "object.orientation.w", "object.orientation.x",
                          "object.orientation.y", "object.orientation.z"]
    assert inputs[3:6] == ["object.angular_velocity_body.x", "object.angular_velocity_body.y",
                           "object.angular_velocity_body.z"]
    for tip, c in zip(problem.fingers, model.fingertips, strict=True):
        joints = tip.finger.joint_names
        assert states[c.eta_cols] == [f"{tip.name}.{k}" for k in ("x", "y", "u", "v", "psi")]
        assert states[c.q_cols] == [f"{tip.name}.q.{j}" for j in joints]
        assert inputs[c.w_cols] == [f"{tip.name}.w_u", f"{tip.name}.w_v"]
        assert inputs[c.qd_cols] == [f"{tip.name}.q_dot.{j}" for j in joints]
    assert len(set(states)) == len(states) and len(set(inputs)) == len(inputs)


def quaternion_rotation(q: np.ndarray) -> np.ndarray:
    w, x, y, z = q / np.linalg.norm(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def test_a_free_objects_columns_mean_what_their_names_say() -> None:
    """Experiment 2 (two fingers, no palm), planned once: the object's columns are its
    position, its quaternion (w, x, y, z; object to palm), its velocity (palm frame) and
    its angular velocity in its own frame (the trajectory's, rotated, is the palm
    frame's); the whole block warm-starts the same request to a certified plan."""
    cache = FingerCache()
    result, _ = solve(REQUEST.validate_python(EXP2), fingers=cache)
    assert isinstance(result, ManipulationResult) and result.status is PlanStatus.SOLVED
    c, tr = result.collocation, result.trajectory
    assert c is not None and tr is not None
    x, u = np.array(c.x), np.array(c.u)
    col = {name: i for i, name in enumerate(c.state_names)}
    icol = {name: i for i, name in enumerate(c.input_names)}
    pos = x[:, [col[f"object.position.{a}"] for a in "xyz"]]
    quat = x[:, [col[f"object.orientation.{a}"] for a in "wxyz"]]
    vel = u[:, [icol[f"object.velocity.{a}"] for a in "xyz"]]
    omega_body = u[:, [icol[f"object.angular_velocity_body.{a}"] for a in "xyz"]]
    assert_close(pos, tr.object_position, atol=1e-12)
    assert_close(vel, tr.object_velocity, atol=1e-12)
    quat = quat * np.sign(quat[:, :1]) / np.linalg.norm(quat, axis=1, keepdims=True)
    assert_close(quat, tr.object_orientation_wxyz, atol=1e-9)
    omega_palm = [quaternion_rotation(q) @ w for q, w in zip(quat, omega_body, strict=True)]
    assert_close(omega_palm, tr.object_angular_velocity, atol=1e-9)
    for contact, finger in zip(tr.contacts, tr.fingers, strict=True):
        name = contact.name
        assert_close(x[:, [col[f"{name}.{k}"] for k in ("x", "y", "u", "v", "psi")]],
                     contact.eta, atol=0.0)
        assert_close(x[:, [col[f"{name}.q.{j}"] for j in finger.joint_names]], finger.q,
                     atol=0.0)
        assert_close(u[:, [icol[f"{name}.w_u"], icol[f"{name}.w_v"]]], contact.w, atol=0.0)
    request = REQUEST.validate_python({**EXP2, "warm_start": c.model_dump()})
    assert request_errors(request, cache) == []
    warm, _ = solve(request, fingers=cache)
    assert isinstance(warm, ManipulationResult) and warm.status is PlanStatus.SOLVED
    assert warm.certificate is not None and warm.certificate.passed


# -- the service: job ids resolved at submission (a store of the test's own) ------------------

def finished_job(store: Store, result: PlanResult | None, planner: str = "ball_on_palm",
                 state: str = "succeeded") -> str:
    row, _ = store.create(planner, json.dumps(TRIANGLE), 60.0, None)
    claimed = store.claim_next()
    assert claimed is not None and claimed.id == row.id
    assert store.finish(row.id, state, "solved" if state == "succeeded" else state, "done",
                        result=None if result is None else result.model_dump_json())
    return row.id


def narrow_plan(columns: int) -> PlanResult:
    return PlanResult(status=PlanStatus.SOLVED, message="solved", collocation=CollocationModel(
        t=[0.0, 3.0, 6.0], x=[[0.0] * columns] * 3, u=[[0.0, 0.0]] * 3,
        state_names=[f"s{i}" for i in range(columns)], input_names=["w_x", "w_y"]))


@pytest.fixture
def store(tmp_path: Path) -> Iterator[Store]:
    s = Store(tmp_path / "jobs.sqlite3")
    yield s
    s.close()


def with_job(job_id: str, **patch: Any) -> PlanRequest:
    return REQUEST.validate_python({**TRIANGLE, **patch, "warm_start": {"job_id": job_id}})


def test_a_job_that_cannot_warm_start_is_named_with_the_reason(store: Store) -> None:
    old = finished_job(store, PlanResult(status=PlanStatus.SOLVED, message="before warm "
                                                                           "starts"))
    finger = finished_job(store, narrow_plan(5), planner="one_finger")
    cancelled, _ = store.create("ball_on_palm", json.dumps(TRIANGLE), 60.0, None)
    assert store.cancel_queued(cancelled.id)
    queued, _ = store.create("ball_on_palm", json.dumps(TRIANGLE), 60.0, None)
    cases = {"no-such-job": "no job", queued.id: "still queued",
             cancelled.id: "without a plan", old: "without a plan",
             finger: "one_finger plan"}
    for job_id, words in cases.items():
        body, errors = resolve_warm_start(with_job(job_id), store)
        assert errors == [("warm_start.job_id", errors[0][1])] and words in errors[0][1], \
            (job_id, errors)
        assert body.warm_start is not None and body.warm_start.job_id == job_id
    # the rest of the request is checked at the same time: every bad field at once
    _, errors = submission_errors(with_job("no-such-job", goal={"u": 1.55}), store)
    assert {f for f, _ in errors} == {"warm_start.job_id", "goal.u"}


def test_a_finished_job_is_replaced_by_its_plan_and_a_misfit_is_named(store: Store) -> None:
    good = finished_job(store, narrow_plan(5).model_copy(update={"collocation": CollocationModel(
        t=[0.0, 3.0, 6.0], x=[[0.0] * 5] * 3, u=[[0.0, 0.0]] * 3,
        state_names=["x", "y", "u", "v", "psi"], input_names=["w_x", "w_y"])}))
    body, errors = submission_errors(with_job(good), store)
    assert errors == []
    ws = body.warm_start
    assert ws is not None and ws.job_id is None
    assert ws.t == [0.0, 3.0, 6.0] and ws.x == [[0.0] * 5] * 3 and ws.u == [[0.0, 0.0]] * 3
    # the resolved request is valid on its own (what the worker gets from the store)
    assert REQUEST.validate_json(body.model_dump_json()).warm_start == ws
    misfit = finished_job(store, narrow_plan(4))
    _, errors = submission_errors(with_job(misfit), store)
    assert {f for f, _ in errors} == {"warm_start.job_id"}, errors
    assert all(r.startswith(f"job {misfit}'s plan does not fit") for _, r in errors)
    assert any("x: must have one row of 5 states" in r for _, r in errors), errors
    assert any("state_names: not this request's columns" in r for _, r in errors), errors


# -- the service, live ------------------------------------------------------------------------

WIRE_CASES: list[tuple[Callable[[dict[str, Any]], Any], str, str]] = [
    (lambda c: {}, "warm_start", "give `job_id`"),
    (lambda c: {"job_id": "abc", "t": c["t"], "x": c["x"], "u": c["u"]}, "warm_start",
     "not both"),
    (lambda c: {"t": c["t"], "x": [r[:4] for r in c["x"]], "u": c["u"]}, "warm_start.x",
     "one row of 5 states"),
    (lambda c: {"t": c["t"], "x": c["x"], "u": [[*r, 0.0] for r in c["u"]]}, "warm_start.u",
     "one row of 2 inputs"),
    (lambda c: {**c, "input_names": ["palm.w_x", "palm.w_y"]}, "warm_start.input_names",
     "'palm.w_x'"),
    (lambda c: {"job_id": "no-such-job"}, "warm_start.job_id", "no job 'no-such-job'"),
]


@pytest.mark.parametrize(("make", "field", "words"), WIRE_CASES,
                         ids=["neither", "both", "x-columns", "u-columns", "names",
                              "unknown-job"])
def test_a_bad_warm_start_is_422_naming_the_field(
        live_server: Server, first: dict[str, Any],
        make: Callable[[dict[str, Any]], Any], field: str, words: str) -> None:
    errors = fields(post(live_server, {**TRIANGLE, "warm_start": make(collocation_of(first))},
                         wait=0.0))
    assert field in errors and words in errors[field], errors


def test_a_job_of_another_planner_is_422(live_server: Server, first: dict[str, Any]) -> None:
    errors = fields(post(live_server, {**ROLL, "warm_start": {"job_id": first["id"]}},
                         wait=0.0))
    assert "ball_on_palm plan" in errors["warm_start.job_id"], errors


def test_warm_starts_by_job_id_and_inline_are_solved_and_certified(
        live_server: Server, first: dict[str, Any]) -> None:
    by_id = post(live_server, {**TRIANGLE, "warm_start": {"job_id": first["id"]}})
    inline = post(live_server, {**TRIANGLE, "warm_start": collocation_of(first)})
    for r in (by_id, inline):
        assert r.status_code == 201, r.text
        assert_triangle_reached(r.json())
        # started from its own optimum, IPOPT converges from the first guess
        assert r.json()["result"]["stats"]["attempts"] == 1
    # a plan of another duration is stretched to this one
    longer = {**TRIANGLE, "duration": 6.6, "warm_start": {"job_id": first["id"]}}
    r = post(live_server, longer)
    assert r.status_code == 201, r.text
    assert_triangle_reached(r.json())
    # the stored job holds the plan itself, not the id: it is self-contained
    store = Store(Settings(data_dir=live_server.data_dir).db_path)
    try:
        row = store.get(by_id.json()["id"])
    finally:
        store.close()
    assert row is not None
    stored = json.loads(row.request)["warm_start"]
    assert stored["job_id"] is None
    assert stored["t"] == collocation_of(first)["t"] and stored["x"] == collocation_of(first)["x"]


def test_a_retried_warm_started_post_gives_one_job(live_server: Server,
                                                   first: dict[str, Any]) -> None:
    body = {**TRIANGLE, "duration": 6.2, "warm_start": {"job_id": first["id"]}}
    key = f"warm-{first['id']}"
    one = post(live_server, body, **{"Idempotency-Key": key})
    two = post(live_server, body, **{"Idempotency-Key": key})
    assert one.status_code == two.status_code == 201, (one.text, two.text)
    assert one.json()["id"] == two.json()["id"]


# -- the client and the command line ----------------------------------------------------------

@pytest.fixture(scope="module")
def client(live_server: Server) -> Iterator[DexrollClient]:
    with DexrollClient.from_url(live_server.url, timeout=60) as c:
        yield c


def test_client_warm_starts_from_a_result_a_job_or_its_id(client: DexrollClient,
                                                          first: dict[str, Any]) -> None:
    previous = Job.model_validate(first)
    assert previous.result is not None
    for warm in (previous.result, previous, previous.id,
                 WarmStartModel.from_result(previous.result)):
        job = client.plan(TRIANGLE, warm_start=warm, timeout=120)
        assert job.state is JobState.SUCCEEDED, (type(warm).__name__, job.message)
        assert_triangle_reached(job.model_dump(mode="json"))
    # another planner's plan, or a result without one, fails locally, before any HTTP
    with pytest.raises(ValueError, match="ball_on_palm plan cannot warm-start a one_finger"):
        client.plan(ROLL, warm_start=previous.result, timeout=10)
    with pytest.raises(ValueError, match="ball_on_palm job cannot warm-start"):
        client.submit(ROLL, warm_start=previous)
    # a job id the service cannot use is its 422
    with pytest.raises(InvalidRequestError) as err:
        client.submit(TRIANGLE, warm_start="no-such-job")
    assert {d.field for d in err.value.detail} == {"warm_start.job_id"}


def test_async_client_warm_starts(live_server: Server, first: dict[str, Any]) -> None:
    async def main() -> Job:
        async with AsyncDexrollClient.from_url(live_server.url, timeout=60) as c:
            return await c.plan(TRIANGLE, warm_start=first["id"], timeout=120)

    job = asyncio.run(main())
    assert job.state is JobState.SUCCEEDED
    assert_triangle_reached(job.model_dump(mode="json"))


def test_client_sends_the_plan_or_the_id_and_no_key_without_one() -> None:
    sent: list[dict[str, Any]] = []

    def handler(request: httpx.Request) -> httpx.Response:
        sent.append(json.loads(request.content))
        return httpx.Response(201, json={"id": "j", "state": "queued", "planner":
                                         "ball_on_palm", "created_at": "2024-01-01T00:00:00Z"})

    block = CollocationModel(t=[0.0, 1.0], x=[[0.0] * 5] * 2, u=[[0.0] * 2] * 2,
                             state_names=["x", "y", "u", "v", "psi"],
                             input_names=["w_x", "w_y"])
    result = PlanResult(status=PlanStatus.SOLVED, message="", collocation=block)
    with DexrollClient(httpx.Client(base_url="http://dexroll.test",
                                    transport=httpx.MockTransport(handler))) as c:
        c.submit(TRIANGLE)
        c.submit(TRIANGLE, warm_start=result)
        c.submit({**TRIANGLE, "warm_start": {"job_id": "old"}}, warm_start="new")
    assert "warm_start" not in sent[0]  # a service older than warm starts accepts it
    assert sent[1]["warm_start"] == {"job_id": None, **block.model_dump()}
    assert sent[2]["warm_start"]["job_id"] == "new"  # the keyword wins


def test_cli_plan_warm_starts_from_a_result_file(tmp_path: Path) -> None:
    first_out, warm_out = tmp_path / "first.json", tmp_path / "warm.json"
    assert cli_main(["plan", str(TRIANGLE_FILE), "-o", str(first_out)]) == 0
    assert cli_main(["plan", str(TRIANGLE_FILE), "--warm-start", str(first_out),
                     "-o", str(warm_out)]) == 0
    warm = PlanResult.model_validate_json(warm_out.read_text())
    assert warm.status is PlanStatus.SOLVED and warm.certificate is not None
    assert warm.certificate.passed and warm.stats is not None and warm.stats.attempts == 1
    # a result of another planner is refused, named, exit code 2
    roll = tmp_path / "roll.json"
    roll.write_text(json.dumps(ROLL))
    bad_out = tmp_path / "bad.json"
    assert cli_main(["plan", str(roll), "--warm-start", str(first_out),
                     "-o", str(bad_out)]) == 2
    bad = FingerPlanResult.model_validate_json(bad_out.read_text())
    assert bad.status is PlanStatus.INVALID_INPUT
    assert [e.field for e in bad.errors] == ["warm_start"]
