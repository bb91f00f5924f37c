"""Warm-up: a worker builds the NLPs of the configured requests before it is ready, so the
first request of those structures is served from the structure cache (real service)."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import httpx
from conftest import Server

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


def test_warmed_structures_are_served_from_the_cache(
        server_factory: Callable[..., Server], tmp_path: Path) -> None:
    # experiment 2 on a grid its certificate passes on, not refined (a refinement would
    # build a grid the warm-up did not)
    exp2 = tmp_path / "experiment2.json"
    exp2.write_text(json.dumps({**json.loads(EXPERIMENT2.read_text()), "n_intervals": 160,
                                "max_refinements": 0}))
    server = server_factory(DEXROLL_WORKERS="1", DEXROLL_WARMUP=f"{TRIANGLE},{exp2}")
    triangle = plan(server, TRIANGLE)
    assert triangle["stats"]["cache_hit"] is True and triangle["stats"]["build_time"] == 0.0
    two = plan(server, exp2)
    assert two["stats"]["build_time"] == 0.0 and two["certificate"]["passed"]
    assert "warm-up: 2 structures built" in server.log_text()


def test_without_warm_up_the_first_request_builds(server_factory: Callable[..., Server]
                                                  ) -> None:
    server = server_factory(DEXROLL_WORKERS="1")  # conftest: DEXROLL_WARMUP empty
    triangle = plan(server, TRIANGLE)
    assert triangle["stats"]["cache_hit"] is False and triangle["stats"]["build_time"] > 0.0


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
