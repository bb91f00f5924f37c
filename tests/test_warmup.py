"""Warm-up: a worker builds the NLPs of the configured requests before it is ready, so the
first request of those structures is served from the structure cache (real service)."""

from __future__ import annotations

import json
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest
from conftest import Server, start_server

from ocp.ball_on_palm import BallOnPalmPlanner
from planner_service.planners import FingerCache
from planner_service.warmup import request_files, warm_up

ROOT = Path(__file__).resolve().parents[1]
TRIANGLE = ROOT / "examples" / "triangle.json"
EXPERIMENT2 = ROOT / "examples" / "experiment2_two_fingers.json"


def plan(server: Server, path: Path) -> dict[str, Any]:
    r = httpx.post(f"{server.url}/v1/plans", params={"wait": 60},
                   content=path.read_text(), headers={"content-type": "application/json"},
                   timeout=90)
    assert r.status_code == 201, r.text
    job: dict[str, Any] = r.json()
    assert job["state"] == "succeeded", job["message"]
    result: dict[str, Any] = job["result"]
    return result


@pytest.fixture(scope="module")
def warmed(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[Server, Path]]:
    """One worker that warms up the triangle and experiment 2 (on a grid its certificate
    passes on, not refined: a refinement would build a grid the warm-up did not), and the
    experiment's request file."""
    folder = tmp_path_factory.mktemp("warmup")
    exp2 = folder / "experiment2.json"
    exp2.write_text(json.dumps({**json.loads(EXPERIMENT2.read_text()), "n_intervals": 160,
                                "max_refinements": 0}))
    server = start_server(folder / "data", DEXROLL_WORKERS="1",
                          DEXROLL_WARMUP=f"{TRIANGLE},{exp2}", DEXROLL_WARMUP_FIRST="true")
    yield server, exp2
    server.stop()


def test_by_default_a_worker_is_ready_first_and_warms_up_between_jobs(
        tmp_path: Path) -> None:
    """Without DEXROLL_WARMUP_FIRST a worker reports ready once it has imported the
    planners, builds the warm-up structures while no job waits, and serves them from its
    cache once built (the log says when)."""
    server = start_server(tmp_path / "data", DEXROLL_WORKERS="1",
                          DEXROLL_WARMUP=str(TRIANGLE))
    try:
        deadline = time.monotonic() + 300.0
        while "structures built between jobs" not in server.log_text():
            assert time.monotonic() < deadline, server.log_text()
            time.sleep(0.2)
        assert "warm-up: 1 structures built between jobs" in server.log_text()
        triangle = plan(server, TRIANGLE)
        assert triangle["stats"]["cache_hit"] is True
    finally:
        server.stop()


def test_warmed_structures_are_served_from_the_cache(warmed: tuple[Server, Path]) -> None:
    server, exp2 = warmed
    triangle = plan(server, TRIANGLE)
    assert triangle["stats"]["cache_hit"] is True and triangle["stats"]["build_time"] == 0.0
    two = plan(server, exp2)
    assert two["stats"]["build_time"] == 0.0 and two["certificate"]["passed"]
    assert "warm-up: 2 structures built" in server.log_text()


def test_without_warm_up_the_first_request_builds(warmed: tuple[Server, Path],
                                                  tmp_path: Path) -> None:
    """A structure not in the warm-up list (the triangle over another duration) is built by
    its first request, on the same worker (the service without a warm-up list, conftest's
    default, has none: tests/test_service.py's jobs build theirs)."""
    server, _ = warmed
    other = tmp_path / "triangle_7s.json"
    other.write_text(json.dumps({**json.loads(TRIANGLE.read_text()), "duration": 7.0}))
    first = plan(server, other)
    assert first["stats"]["cache_hit"] is False and first["stats"]["build_time"] > 0.0


def test_bad_and_missing_warm_up_requests_are_skipped(tmp_path: Path) -> None:
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"planner": "ball_on_palm", "duration": -1}))
    broken = tmp_path / "broken.json"
    broken.write_text("{not json")
    files = request_files(f"{tmp_path},{tmp_path / 'missing.json'},{TRIANGLE}")
    assert files == [bad, broken, TRIANGLE]
    palm = BallOnPalmPlanner()
    done = warm_up(files, palm, FingerCache())
    assert [name for name, _ in done] == ["triangle.json"]
    assert done[0][1] > 0.0
    assert warm_up([TRIANGLE], palm, FingerCache()) == [("triangle.json", 0.0)]  # cached


def test_a_gait_request_warms_its_fingers_swing_nlps_too() -> None:
    """A gait's swings use one NLP per finger (ocp.gait.swing: 0.75 s to build each on
    the built-in hand); the warm-up of a gait request builds them with the rolls' NLP,
    so that its first request pays neither. Warmed again: nothing left to build."""
    from ocp.gait.swing import _SOLVERS, SwingSpec, swing_key
    from planner_service.planners import REQUEST, Planners
    from planner_service.planners.manipulation import manipulation_problem

    gait = ROOT / "tests" / "data" / "gait_small_request.json"
    cache = FingerCache()
    palm = BallOnPalmPlanner()
    done = warm_up([gait], palm, cache)
    assert [name for name, _ in done] == [gait.name] and done[0][1] > 0.0
    problem = manipulation_problem(REQUEST.validate_python(json.loads(gait.read_text())),
                                   Planners(palm, cache).fingers)
    fingers = [tip.finger for tip in problem.fingers]
    for f in fingers:
        key = swing_key(f, SwingSpec.n_intervals, SwingSpec.lift_intervals,
                        len(fingers) - 1)
        assert key in _SOLVERS
    assert warm_up([gait], palm, cache) == [(gait.name, 0.0)]


def test_swing_nlps_are_shared_by_equal_fingers_and_not_by_different_ones() -> None:
    """A searched grasp's hand is a new model of the same fingers (only its tips' chart
    sides differ): its swings take the NLPs built for the first (keyed by what they are
    built from, not by the model object). A finger whose joint limits differ gets its own."""
    from dataclasses import replace

    from ocp.gait.swing import SwingSpec, prepare_swings, swing_key
    from ocp.robots.allegro import load_allegro

    a = tuple(load_allegro().fingers)
    b = tuple(load_allegro("urdf", ((0.6481, 0.5744, 0.0), None, None, None)).fingers)
    assert all(x is not y for x, y in zip(a, b, strict=True))
    assert a[0].tip_surface != b[0].tip_surface  # the chart side differs
    n, K = SwingSpec.n_intervals, SwingSpec.lift_intervals
    keys = [swing_key(f, n, K, 3) for f in a]
    assert keys == [swing_key(f, n, K, 3) for f in b]
    assert len(set(keys)) == 4  # four fingers, four NLPs
    prepare_swings(a)
    assert prepare_swings(b) == 0.0
    tighter = replace(a[1], upper=a[1].upper - 0.1)
    assert swing_key(tighter, n, K, 3) != keys[1]
    assert swing_key(a[1], n, K, 2) != keys[1]


@pytest.mark.slow
def test_a_gait_on_a_hand_with_links_warms_its_swings_with_their_obstacles() -> None:
    """On an MJCF hand whose links are checked, a gait's swings keep clear of
    SWING_OBSTACLES of them (one NLP per finger, with them among its 'others'): the
    warm-up builds that NLP, not the one without; its joints are damped, so the variant
    with the actuators' rows (ocp.gait.swing.SwingDrive) is built too."""
    from ocp.gait.step import SWING_OBSTACLES
    from ocp.gait.swing import _SOLVERS, SwingSpec, swing_key
    from planner_service.planners import REQUEST, ManipulationAdapter, Planners
    from planner_service.planners.manipulation import manipulation_problem

    body = json.loads((ROOT / "tests" / "data" / "gait_small_request.json").read_text())
    body["hand"] = {"mjcf": (ROOT / "examples" / "own_hand.xml").read_text(),
                    "tips": [{"name": n} for n in ("ff_tip", "mf_tip", "rf_tip", "th_tip")]}
    body["grasp"] = "auto"
    request = REQUEST.validate_python(body)
    planners = Planners(BallOnPalmPlanner(), FingerCache())
    ManipulationAdapter().prepare(request, planners)
    problem = manipulation_problem(request, planners.fingers)
    assert problem.collision is not None
    fingers = [tip.finger for tip in problem.fingers]
    for f in fingers:
        for driven in (False, True):
            assert swing_key(f, SwingSpec.n_intervals, SwingSpec.lift_intervals,
                             len(fingers) - 1 + SWING_OBSTACLES, "", driven) in _SOLVERS
