"""`dexroll bench`: suites as data, generated requests, the report, and the same rows
whichever way a suite is run (1 or 2 pool workers, a live service)."""

from __future__ import annotations

import csv
import importlib.util
import io
import json
import math
import re
import sys
import types
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import Server

from dexroll_client.models import OneFingerRequest
from ocp.ball_on_palm import object_pose
from ocp.spec.problem import ObjectSpec
from planner_service import cli
from planner_service.bench.command import run_bench
from planner_service.bench.generators import GENERATORS
from planner_service.bench.progress import Progress
from planner_service.bench.report import ratios, summarise
from planner_service.bench.rows import (
    FIELDS,
    comparable,
    differences,
    peer_status,
    row_from_peer,
    row_from_result,
)
from planner_service.bench.runners import Scheduler, affinity_key
from planner_service.bench.suite import (
    PEER_METHODS,
    Problem,
    SuiteError,
    Unit,
    applicable,
    builtin_suites,
    expand,
    load_suite,
    units,
)
from planner_service.planners import REQUEST, request_errors, to_problem

ROOT = Path(__file__).resolve().parents[1]
OURS = ("collocation", "greedy")  # the project's methods (the peers are compared, not judged)


def requests(problems: list[Problem]) -> list[dict[str, Any]]:
    return [p.request for p in problems]


# -- suites and their problems ----------------------------------------------------------------

def test_shipped_suites_are_quick_and_full() -> None:
    assert builtin_suites() == ["full", "quick"]
    for name in ("quick", "full"):
        suite = load_suite(name)
        assert suite.name == name and suite.description


def test_generation_is_deterministic_and_seeded() -> None:
    suite = load_suite("quick")
    first, second = expand(suite), expand(suite)
    assert requests(first) == requests(second)
    assert [p.id for p in first] == [p.id for p in second]
    # another seed draws other problems
    data = json.loads(json.dumps(suite.data))
    data["families"][0]["seed"] += 1
    other = expand(type(suite)(suite.name, suite.source, data), families=["translation"])
    assert requests(other) != requests(expand(suite, families=["translation"]))


def test_limit_keeps_a_prefix_of_each_family() -> None:
    suite = load_suite("quick")
    full, limited = expand(suite), expand(suite, limit=1)
    assert {p.family for p in limited} == {p.family for p in full}
    assert all(p in full for p in limited)
    assert all(p.id.endswith("-000") or p.family == "paper" for p in limited)


@pytest.mark.parametrize("name, each", [("quick", False), ("full", True),
                                        pytest.param("full", False, marks=pytest.mark.slow)],
                         ids=["quick", "full-first-of-each-family", "full"])
def test_every_generated_request_is_valid_on_the_wire_and_plannable(name: str,
                                                                    each: bool) -> None:
    """``each``: the first problem of each family only (every request of the full suite,
    21-31 s, in `make test-slow`)."""
    problems = expand(load_suite(name))
    assert len({p.id for p in problems}) == len(problems)
    if each:
        problems = [p for p in problems if p.id.endswith("-000") or p.family == "paper"]
        assert {p.family for p in problems} == {p.family for p in expand(load_suite(name))}
    searched = 0
    for unit in units(problems):
        request = REQUEST.validate_python(unit.request)
        # a grasp searched per request (the full suite's gaits: 5-10 s each) is checked
        # on two of them; every other request goes through every check
        if unit.request.get("grasp") is None or searched < 2:
            searched += unit.request.get("grasp") is not None
            assert request_errors(request) == [], (unit.problem_id, unit.method)
        # and it goes through JSON as the client sends it
        assert REQUEST.validate_json(json.dumps(unit.request)) == request


def test_every_family_draws_its_own_planner_and_methods() -> None:
    problems = expand(load_suite("quick"))
    planners: dict[str, set[str]] = {}
    for p in problems:
        planners.setdefault(p.family, set()).add(p.planner)
    assert planners == {"translation": {"ball_on_palm"}, "reorientation": {"ball_on_palm"},
                        "full_goal": {"ball_on_palm"}, "one_finger": {"one_finger"},
                        "two_fingers": {"manipulation"}, "three_fingers": {"manipulation"},
                        "four_finger_round": {"manipulation"},
                        "four_finger_gait": {"manipulation"},
                        "paper": {"one_finger", "manipulation"}}
    methods = {(u.family, u.method) for u in units(problems)}
    assert ("one_finger", "greedy") in methods and ("paper", "greedy") in methods
    assert ("translation", "greedy") not in methods
    assert ("two_fingers", "drake") not in methods and ("translation", "drake") in methods
    greedy = [u for u in units(problems) if u.method == "greedy"]
    assert all(u.request["method"] == "greedy" for u in greedy)
    assert not any("method" in u.request for u in units(problems) if u.method != "greedy")


def test_applicable_methods() -> None:
    assert applicable("manipulation", "collocation")
    assert applicable("one_finger", "greedy") and not applicable("ball_on_palm", "greedy")
    assert all(applicable("ball_on_palm", m) for m in PEER_METHODS)
    assert not any(applicable(p, m) for p in ("one_finger", "manipulation")
                   for m in PEER_METHODS)


def test_reorientations_return_to_the_palm_point_turned_within_the_limit() -> None:
    """Each pure reorientation's goal is the same palm point with the object turned by at
    most the family's angle; goals beyond the pole limit are in a rotated chart."""
    rng = np.random.default_rng(3)
    params = {"template": {"object": {"shape": "sphere", "dimensions": [0.025]},
                           "duration": 2.0, "n_intervals": 30},
              "angle_deg": [80.0, 90.0], "initial_psi": [-math.pi, math.pi]}
    rotated = 0
    for _ in range(200):
        request, notes = GENERATORS["ball_reorientation"](rng, params)
        assert request_errors(REQUEST.validate_python(request)) == []
        chart = request["object"].get("chart_rotation", [0.0, 0.0, 0.0])
        rotated += chart != [0.0, 0.0, 0.0]
        obj = ObjectSpec("sphere", (0.025,), tuple(chart))  # type: ignore[arg-type]
        g, i = request["goal"], request["initial"]
        R0, p0 = object_pose(obj, [i[c] for c in ("x", "y", "u", "v", "psi")])
        R1, p1 = object_pose(obj, [g[c] for c in ("x", "y", "u", "v", "psi")])
        np.testing.assert_allclose(p1, p0, atol=1e-12)
        angle = math.degrees(math.acos(max(-1.0, min(1.0, (np.trace(R1 @ R0.T) - 1) / 2))))
        assert 80.0 - 1e-6 <= angle <= 90.0 + 1e-6, notes
        assert max(abs(i["u"]), abs(g["u"])) <= math.radians(75.0)
    assert rotated >= 3  # 80-90 deg turns put some goals beyond the pole limit


def test_one_finger_grasps_start_inside_the_friction_cone() -> None:
    for p in expand(load_suite("quick"), families=["one_finger"]):
        request = REQUEST.validate_python(p.request)
        assert isinstance(request, OneFingerRequest)
        c = request.finger_contact.initial
        # the angle from the ball's top; the grasp angles are half of it on a sphere
        theta = math.acos(math.cos(c.u_f) * math.cos(c.v_f))
        assert theta / 2 < 0.6 * math.atan(request.mu) + 1e-12


def test_the_papers_experiments_are_fixed_members() -> None:
    paper = {p.id: p for p in expand(load_suite("quick"), families=["paper"])}
    assert set(paper) == {"experiment1", "experiment2"}
    assert paper["experiment2"].request == json.loads(
        (ROOT / "examples" / "experiment2_two_fingers.json").read_text())
    path = ROOT / "experiments" / "experiment1.py"
    spec = importlib.util.spec_from_file_location("experiment1_for_bench", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    expected = module.build_problem()
    got = to_problem(REQUEST.validate_python(paper["experiment1"].request))
    assert got.base == expected.base  # type: ignore[union-attr]
    assert got.contact == expected.contact  # type: ignore[union-attr]
    for field in ("mu", "grasp_weight", "finger_effort_weight", "joint_effort_weight",
                  "pad_margin"):
        assert getattr(got, field) == getattr(expected, field), field
    assert got.finger.pad_half_size == expected.finger.pad_half_size  # type: ignore[union-attr]
    # both suites carry the same two
    full = {p.id: p.request for p in expand(load_suite("full"), families=["paper"])}
    assert full == {k: p.request for k, p in paper.items()}


def test_bad_suites_are_refused_with_the_reason(tmp_path: Path) -> None:
    with pytest.raises(SuiteError, match="neither a shipped suite"):
        load_suite("no-such-suite")
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"families": [{"name": "x", "generator": "nope", "count": 1,
                                             "seed": 0}]}))
    with pytest.raises(SuiteError, match="generator 'nope'"):
        load_suite(bad)
    with pytest.raises(SuiteError, match="unknown families"):
        expand(load_suite("quick"), families=["nope"])
    assert cli.main(["bench", str(bad), "--out", str(tmp_path / "r")]) == 2


# -- pieces of the runners and the report -----------------------------------------------------

def test_scheduler_keeps_structures_on_the_worker_that_built_them() -> None:
    problems = expand(load_suite("quick"), families=["translation", "reorientation"])
    todo = units(problems, ["collocation"])
    scheduler = Scheduler(todo)
    a = scheduler.next_for("a")
    b = scheduler.next_for("b")
    assert affinity_key(a) != affinity_key(b)  # two workers start two structures
    a2 = scheduler.next_for("a")
    assert affinity_key(a2) == affinity_key(a)  # and each goes on with its own
    handed = [a, b, a2]
    while scheduler:
        handed.append(scheduler.next_for("a"))
    assert sorted(u.key for u in handed) == sorted(u.key for u in todo)


def test_progress_writes_one_line_per_unit_off_a_terminal() -> None:
    out = io.StringIO()
    bar = Progress(2, stream=out)
    bar.update({"problem_id": "p-000", "method": "collocation", "status": "solved", "ok": True})
    bar.update({"problem_id": "p-001", "method": "greedy", "status": "solved", "ok": False})
    lines = out.getvalue().splitlines()
    assert len(lines) == 2
    assert "1/2, 1 ok" in lines[0] and "2/2, 1 ok" in lines[1]
    assert "certificate failed" in lines[1]


def _fake_peers(available: dict[str, bool]) -> types.ModuleType:
    module = types.ModuleType("planner_service.bench.peers")
    module.available = lambda: available  # type: ignore[attr-defined]
    module.PEER_METHODS = {m: (lambda request: None) for m in PEER_METHODS}  # type: ignore
    return module


def test_peer_status_says_why_a_peer_cannot_run(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "planner_service.bench.peers", None)
    status = peer_status()
    assert set(status) == set(PEER_METHODS)
    assert all(why and "cannot be imported" in why for why in status.values())
    monkeypatch.setitem(sys.modules, "planner_service.bench.peers",
                        _fake_peers({"drake": False, "casadi_plain": True}))
    status = peer_status()
    assert status["casadi_plain"] is None and "drake is not installed" in str(status["drake"])


def test_peer_outcome_rows() -> None:
    unit = Unit("translation", "translation-000", "drake", "ball_on_palm", {}, "any")
    outcome = types.SimpleNamespace(
        status="solved", build_time=0.1, solve_time=0.2, iterations=12, goal_error=1e-9,
        certificate={"passed": 0.0, "max_slip_speed": 1e-17, "max_angle_defect": 3e-4},
        message="IPOPT: Success; certificate failed: angle_defect")
    row = row_from_peer(unit, outcome, 0.5, 1, 100.0)
    assert set(row) == set(FIELDS)
    assert row["status"] == "solved" and not row["certificate_passed"] and not row["ok"]
    assert row["cert_angle_defect_max"] == 3e-4 and "passed" not in row["certificate"]
    assert row["iterations"] == 12


def test_row_differences_leave_out_run_dependent_fields() -> None:
    a = {"status": "solved", "iterations": 7, "solve_time": 1.0, "worker_pid": 1,
         "certificate": {"max_slip_speed": 1e-6, "n": 2.0}}
    b = dict(a, solve_time=2.0, worker_pid=2, certificate={"max_slip_speed": 1.0000001e-6,
                                                           "n": 2.0})
    assert differences(a, b) == {"certificate.max_slip_speed": (1e-6, 1.0000001e-6)}
    assert differences(a, b, rel=1e-6) == {}
    assert differences(a, dict(b, iterations=8), rel=1e-6) == {"iterations": (7, 8)}
    # an absolute floor for residuals at round-off, and only for them
    c = dict(b, certificate={"max_slip_speed": 1.0e-6 + 1e-12, "n": 2.0})
    assert differences(a, c, rel=1e-9) != {}
    assert differences(a, c, rel=1e-9, floor=1e-11) == {}
    assert differences(a, dict(b, iterations=8), floor=10.0) == {"iterations": (7, 8)}


def test_missing_peers_are_skipped_and_reported(monkeypatch: pytest.MonkeyPatch,
                                                tmp_path: Path) -> None:
    monkeypatch.setitem(sys.modules, "planner_service.bench.peers", None)
    code, doc = run_bench("quick", workers=1, out=tmp_path, methods=list(PEER_METHODS),
                          families=["translation"], limit=1, progress=False)
    assert code == 0 and doc["rows"] == []
    assert set(doc["skipped_methods"]) == set(PEER_METHODS)
    report = (tmp_path / "report.md").read_text()
    assert "**skipped**: `drake`" in report and "cannot be imported" in report


def test_summary_statistics() -> None:
    def row(method: str, ok: bool, t: float, slip: float | None) -> dict[str, Any]:
        return {"family": "f", "method": method, "ok": ok, "expected": "solved",
                "status": "solved" if ok else "inaccurate",
                "solve_time": t, "build_time": 0.0, "wall_time": t, "iterations": 3,
                "peak_rss_mb": 1.0, "goal_error_max": 0.0, "cert_slip_speed_max": slip,
                "cert_cone_margin_min": 0.3 if ok else -1.0}
    rows = [row("collocation", True, t, 1e-9 * t) for t in (1.0, 2.0, 3.0, 4.0)]
    rows.append(row("collocation", False, 10.0, 5.0))
    (s,) = summarise(rows)
    assert s["count"] == 5 and s["ok"] == 4 and s["success_rate"] == 0.8
    assert s["solve_time_median"] == 3.0 and s["solve_time_max"] == 10.0
    assert s["solve_time_p90"] == pytest.approx(np.percentile([1, 2, 3, 4, 10], 90))
    assert s["cert_slip_speed_max"] == 4e-9  # residuals over the successful runs only
    assert s["cert_cone_margin_min"] == 0.3
    assert s["expected_solved_failed"] == 1
    unavailable = dict(rows[0], method="drake", status="unavailable", ok=False)
    _, peer = summarise([*rows, unavailable])
    assert peer["count"] == 0 and peer["unavailable"] == 1 and peer["success_rate"] is None


def test_ratios_against_the_collocation_method() -> None:
    """A peer whose solves take k times as long on every problem has both ratios k; the
    pairing goes by problem, over the problems both solved with a passed certificate."""
    def row(pid: str, method: str, t: float | None, ok: bool = True) -> dict[str, Any]:
        return {"family": "f", "problem_id": pid, "method": method, "ok": ok,
                "expected": "any", "status": "solved", "solve_time": t, "build_time": 0.0,
                "wall_time": t, "iterations": 3, "peak_rss_mb": 1.0}
    ours = [row(f"p{i}", "collocation", t) for i, t in enumerate((0.01, 0.02, 0.04))]
    peer = [row(f"p{i}", "drake", 12.5 * t) for i, t in enumerate((0.01, 0.02, 0.04))]
    peer.append(row("p9", "drake", 99.0))  # no collocation run of p9: not paired
    peer[0]["ok"] = False
    rows = ours + peer
    (q,) = ratios(rows, summarise(rows))
    assert (q["family"], q["method"], q["reference"]) == ("f", "drake", "collocation")
    assert q["paired"] == 2  # p0: the peer's plan failed; p9: no collocation run
    assert q["paired_median"] == pytest.approx(12.5)
    assert q["ratio_of_medians"] == pytest.approx(np.median([0.125, 0.25, 0.5, 99.0]) / 0.02)
    # a method with no solve times has no ratio, and the reference is never compared
    # with itself
    untimed = [*ours, row("p0", "greedy", None)]
    (q,) = ratios(untimed, summarise(untimed))
    assert q["ratio_of_medians"] is None and q["paired_median"] is None and q["paired"] == 0


def test_exit_code_follows_the_suites_expectations(tmp_path: Path) -> None:
    """A run expected to solve that does not makes the exit code 1; the same failure
    expected (a known finding) leaves it 0 and is listed in the report."""
    request = {"initial": {"x": 0, "y": 0, "u": 0, "v": 0, "psi": 0},
               "goal": {"x": 0.03, "y": 0.01}, "duration": 1.0, "n_intervals": 10,
               "solver": {"max_iter": 1}}
    suite: dict[str, Any] = {"name": "tiny", "methods": ["collocation"],
                             "fixed": [{"family": "capped", "id": "one-iteration",
                                        "request": request}]}
    path = tmp_path / "tiny.json"
    path.write_text(json.dumps(suite))
    assert cli.main(["bench", str(path), "--workers", "1", "--out", str(tmp_path / "a"),
                     "--no-progress"]) == 1
    suite["exceptions"] = [{"id": "one-iteration", "method": "collocation",
                            "expected": "unsolved", "note": "one IPOPT iteration"}]
    path.write_text(json.dumps(suite))
    assert cli.main(["bench", str(path), "--workers", "1", "--out", str(tmp_path / "b"),
                     "--no-progress"]) == 0
    report = (tmp_path / "b" / "report.md").read_text()
    assert "one-iteration | collocation | unsolved | iteration_limit" in report
    assert "one IPOPT iteration" in report


# -- the quick suite, run -----------------------------------------------------------------------

# quick_run (conftest, one run for the session): the whole quick suite through the library,
# 2 workers, by the command line; tests/test_bench_ray.py compares Ray's rows with it


def _rows(out: Path) -> list[dict[str, Any]]:
    rows: list[dict[str, Any]] = json.loads((out / "results.json").read_text())["rows"]
    return rows


def test_quick_suite_report_has_every_family_and_method(quick_run: tuple[int, Path]) -> None:
    code, out = quick_run
    assert code == 0, (out / "report.md").read_text()
    for name in ("results.json", "results.csv", "report.md", "success_rate.png",
                 "solve_times.png"):
        assert (out / name).stat().st_size > 0, name
    doc = json.loads((out / "results.json").read_text())
    for key in ("suite", "run", "machine", "versions", "summary", "problems", "rows"):
        assert key in doc, key
    assert doc["run"]["runner"] == "pool" and doc["run"]["workers"] == 2
    rows = doc["rows"]
    expected = {(u.family, u.method) for u in units(expand(load_suite("quick")))
                if u.method not in doc["skipped_methods"]}
    assert {(r["family"], r["method"]) for r in rows} == expected
    assert {(s["family"], s["method"]) for s in doc["summary"]} == expected
    assert [(r["family"], r["problem_id"], r["method"]) for r in rows] == sorted(
        (r["family"], r["problem_id"], r["method"]) for r in rows)
    report = (out / "report.md").read_text()
    for family, method in expected:
        assert f"| {family} | {method} |" in report
    # every other method that ran a family next to collocation is compared with it, and
    # the ratio of medians is the summary's medians divided
    by = {(s["family"], s["method"]): s for s in doc["summary"]}
    compared = {(q["family"], q["method"]) for q in doc["ratios"]}
    assert compared == {(f, m) for f, m in expected
                        if m != "collocation" and (f, "collocation") in expected}
    assert compared and "## Against `collocation`, in this run" in report
    for q in doc["ratios"]:
        ours, theirs = by[(q["family"], "collocation")], by[(q["family"], q["method"])]
        assert q["ratio_of_medians"] == pytest.approx(theirs["solve_time_median"]
                                                      / ours["solve_time_median"])
        assert 0 <= q["paired"] <= min(ours["ok"], theirs["ok"])
    # the CSV holds the same rows
    with (out / "results.csv").open(newline="") as f:
        table = list(csv.DictReader(f))
    assert len(table) == len(rows) and list(table[0]) == list(FIELDS)
    for line, row in zip(table, rows, strict=True):
        assert (line["problem_id"], line["method"], line["status"]) == (
            row["problem_id"], row["method"], row["status"])
        assert line["ok"] == str(row["ok"])
        assert json.loads(line["certificate"]) == row["certificate"]
        if row["solve_time"] is not None:
            assert float(line["solve_time"]) == row["solve_time"]


def test_quick_suite_solves_are_certified(quick_run: tuple[int, Path]) -> None:
    rows = _rows(quick_run[1])
    for r in rows:
        if r["method"] in OURS and r["status"] == "solved":
            assert r["certificate_passed"], (r["problem_id"], r["method"], r["failures"])
        assert r["ok"] == (r["status"] == "solved" and r["certificate_passed"])
        if r["expected"] == "solved":
            assert r["ok"], (r["problem_id"], r["method"], r["message"])
        assert r["worker_pid"] and r["peak_rss_mb"] > 0
    # a gait no sequence within its limits makes is answered before any NLP (no iterations,
    # no certificate: tests/test_gait_input.py); the others were planned
    ours = [r for r in rows if r["method"] in OURS and
            not (r["family"] == "four_finger_gait" and r["status"] == "infeasible")]
    # a plan stopped at its time limit has no certificate (the deadline skips it); on a
    # loaded machine a family expected 'any' may end so
    assert ours and all(r["iterations"] and (r["certificate"] or r["status"] == "time_limit")
                        for r in ours)
    assert all(r["status"] != "time_limit" for r in ours if r["expected"] == "solved")
    assert len({r["worker_pid"] for r in rows}) == 2


def test_quick_suite_plans_with_fingers_execute_in_mujoco(quick_run: tuple[int, Path]
                                                          ) -> None:
    """Every solved plan with fingers is executed in MuJoCo by the row that reports it
    (docs/simulation.md) and passes: within 1 mm and 2 degrees, no contact lost."""
    pytest.importorskip("mujoco")
    executed = [r for r in _rows(quick_run[1]) if r.get("exec_status") is not None]
    assert executed, "no plan with fingers was executed"
    for r in executed:
        assert r["exec_status"] == "passed", (r["problem_id"], r["method"], r)


def test_one_worker_gives_the_same_rows(quick_run: tuple[int, Path], tmp_path: Path) -> None:
    # one problem of the families with every planner and method (ball on palm with its
    # peers, one finger, two and three fingers); the four-finger hand's plans take 5-10 s
    code, doc = run_bench("quick", workers=1, out=tmp_path, limit=1, progress=False,
                          families=["translation", "one_finger", "two_fingers",
                                    "three_fingers"])
    assert code == 0
    mine = [comparable(r) for r in doc["rows"]]
    both = {(r["problem_id"], r["method"]) for r in doc["rows"]}
    theirs = [comparable(r) for r in _rows(quick_run[1])
              if (r["problem_id"], r["method"]) in both]
    assert mine == theirs
    assert len({r["worker_pid"] for r in doc["rows"]}) == 1


def test_a_live_service_gives_the_same_rows(quick_run: tuple[int, Path], live_server: Server,
                                            tmp_path: Path) -> None:
    """The same problems through the service (the client) as through the library. The
    ball-on-palm and one-finger plans are bit-identical whatever the BLAS threads; the
    manipulation planner's last digits depend on them (docs/benchmarks.md)."""
    code, doc = run_bench("quick", url=live_server.url, workers=2, out=tmp_path, limit=1,
                          families=["translation", "one_finger"], methods=list(OURS),
                          progress=False)
    assert code == 0
    assert doc["run"]["runner"] == "service"
    mine = [comparable(r) for r in doc["rows"]]
    assert len(mine) == 3  # translation-000; one_finger-000 by collocation and greedy
    both = {(r["problem_id"], r["method"]) for r in doc["rows"]}
    theirs = [comparable(r) for r in _rows(quick_run[1])
              if (r["problem_id"], r["method"]) in both]
    assert mine == theirs
    assert all(r["peak_rss_mb"] is None and r["worker_pid"] for r in doc["rows"])


def test_gait_family_turns_the_ball_farther_than_rolling_about_random_axes() -> None:
    """four_finger_gait: the built-in hand's four fingertips, one rotation step of 45-180
    deg about a random axis (no translation), the rolls' speed 8 s per radian, the quick
    suite at the hand's mu = 0.5 and the full one at mu = 1.0 (docs/benchmarks.md)."""
    for name, mu, count in (("quick", 0.5, 2), ("full", 1.0, 20)):
        problems = expand(load_suite(name), families=["four_finger_gait"])
        assert len(problems) == count
        axes = []
        for p in problems:
            r = p.request
            assert r["mu"] == mu and r["gait"] and r["forces"]["mass"] > 0
            assert len(r["fingers"]) == 4 and r["hand"] == {"builtin": "allegro"}
            (step,) = r["motion"]["steps"]
            assert 45.0 <= math.degrees(step["angle"]) <= 180.0 and "translation" not in step
            assert step["duration"] == r["duration"] == pytest.approx(8.0 * step["angle"])
            assert np.linalg.norm(step["axis"]) == pytest.approx(1.0)
            axes.append(step["axis"])
        assert len({tuple(np.round(a, 6)) for a in axes}) == count


def test_quick_gait_rows_are_typed_answers_naming_the_thumbs_limit(
        quick_run: tuple[int, Path]) -> None:
    """At mu = 0.5 the thumb cannot be lifted (the others cannot hold the ball without
    it), so it rolls through the whole turn: each row is infeasible at once, the message
    names its joint and the turn it allows, less than the turn asked, none made."""
    rows = [r for r in _rows(quick_run[1]) if r["family"] == "four_finger_gait"]
    assert len(rows) == 2
    for r in rows:
        assert r["status"] == "infeasible" and not r["ok"] and r["expected"] == "unsolved"
        m = re.search(r"finger 'thumb' \(joint limit \(thumb_j\d\)\) stops the turn after "
                      r"([0-9.]+) deg of ([0-9.]+) deg", r["message"])
        assert m is not None, r["message"]
        assert float(m.group(1)) < float(m.group(2)) == round(r["turn_asked_deg"], 1)
        assert r["turn_made_deg"] == 0.0 and r["exec_status"] is None


def test_a_certified_gaits_row_is_executed_in_mujoco() -> None:
    """A gait row's executed column: the stored gait (tests/data/gait_small_*.json, the
    example turned 8 deg, planned once; tests/test_view_browser.py draws it) executed in
    MuJoCo on its own forces as every row with forces is (a gait with its own squeeze);
    the turn asked and made."""
    pytest.importorskip("mujoco")
    from planner_service.bench.suite import Unit
    from planner_service.planners import RESULT

    data = Path(__file__).resolve().parent / "data"
    request = json.loads((data / "gait_small_request.json").read_text())
    result = RESULT.validate_json((data / "gait_small_result.json").read_text())
    unit = Unit("four_finger_gait", "stored", "collocation", "manipulation", request, "any")
    row = row_from_result(unit, result, None, None, None)
    assert row["ok"] and row["turn_asked_deg"] == pytest.approx(8.0, abs=1e-4)
    assert row["turn_made_deg"] == pytest.approx(row["turn_asked_deg"], abs=1e-9)
    # on its own forces and the gait's squeeze (docs/gait.md): within 1 mm and 2 deg, no
    # contact lost while planned touching, no touch while planned clear
    assert row["exec_status"] == "passed", row["exec_message"]
    assert math.isfinite(row["exec_position_error_max"])
    assert math.isfinite(row["exec_angle_error_max"]) and row["exec_contacts_lost"] >= 0
    assert (row["exec_status"] == "passed") == (row["exec_message"] == "")
