"""A plan's execution in MuJoCo through the service's doors: ``POST/GET
/v1/plans/{id}/simulation`` on a real service (uvicorn on loopback), ``client.simulate``,
and ``dexroll simulate`` on the job's JSON (docs/simulation.md)."""

from __future__ import annotations

import asyncio
import json
import time
from pathlib import Path

import httpx
import pytest
from conftest import Server

from dexroll_client import AsyncDexrollClient, DexrollClient
from dexroll_client.errors import ConflictError, NotFoundError
from dexroll_client.simulation import SimulationOptions
from planner_service.cli import main

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def finger_job(live_server: Server) -> str:
    """A finished one-finger plan (the example on a coarser grid: a few seconds)."""
    request = json.loads((ROOT / "examples" / "one_finger_roll.json").read_text())
    request["n_intervals"] = 16
    with DexrollClient.from_url(live_server.url) as client:
        job = client.plan(request, timeout=300)
    assert job.state.value == "succeeded", job.message
    return job.id


def test_a_plan_is_simulated_and_its_report_stored(live_server: Server,
                                                   finger_job: str) -> None:
    with DexrollClient.from_url(live_server.url) as client:
        with pytest.raises(NotFoundError):
            client.simulation(finger_job)  # not simulated yet
        report = client.simulate(finger_job)
        assert report.passed, report.failures
        assert report.job_id == finger_job and report.mode == "servo"
        assert report.position_error.max <= 1e-3
        assert {c.name for c in report.contacts} == {"palm", "finger"}
        assert report.series is not None and report.series.t[-1] == pytest.approx(
            report.duration, abs=1e-3)
        assert client.simulation(finger_job) == report  # stored beside the plan
        # options: no grip loses the finger; the latest run is the stored one
        loose = client.simulate(finger_job, SimulationOptions(squeeze=0.0, grip_force=0.0),
                                record_every=50, use_plan_forces=True, impratio=10.0,
                                noslip_iterations=3)
        assert not loose.passed
        assert any(c.lost_time > 0 for c in loose.contacts)
        assert loose.options["record_every"] == 50
        assert client.simulation(finger_job) == loose

    async def latest() -> object:
        async with AsyncDexrollClient.from_url(live_server.url) as client:
            return await client.simulation(finger_job)

    assert asyncio.run(latest()) == loose


def test_the_doors_refuse_what_cannot_be_executed(live_server: Server,
                                                  finger_job: str) -> None:
    url = live_server.url
    r = httpx.post(f"{url}/v1/plans/nope/simulation", json={})
    assert r.status_code == 404 and r.json()["error"] == "not_found"
    r = httpx.post(f"{url}/v1/plans/{finger_job}/simulation", json={"squeez": 1})
    assert r.status_code == 422
    r = httpx.post(f"{url}/v1/plans/{finger_job}/simulation", json={"mode": "teleport"})
    assert r.status_code == 422
    triangle = json.loads((ROOT / "examples" / "triangle.json").read_text())
    with DexrollClient.from_url(url) as client:
        job = client.plan(triangle, timeout=120)
        with pytest.raises(ConflictError, match="no fingers"):
            client.simulate(job.id)


def test_a_plan_without_a_hand_model_is_not_executed_on_one(live_server: Server,
                                                            finger_job: str) -> None:
    """``{"model": "request"}`` runs the plan on the request's own MJCF hand
    (docs/simulation.md, "On your own model"); a plan whose request has none is a 409
    saying so (the run on an MJCF hand: tests/test_user_model.py)."""
    r = httpx.post(f"{live_server.url}/v1/plans/{finger_job}/simulation",
                   json={"model": "request"}, timeout=60)
    assert r.status_code == 409, r.text
    assert "needs the plan's request with its `hand`" in r.text
    r = httpx.post(f"{live_server.url}/v1/plans/{finger_job}/simulation",
                   json={"model": "file"}, timeout=60)
    assert r.status_code == 422


def test_the_command_line_simulates_a_jobs_json(live_server: Server, finger_job: str,
                                                tmp_path: Path,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    job = httpx.get(f"{live_server.url}/v1/plans/{finger_job}").json()
    path = tmp_path / "job.json"
    path.write_text(json.dumps(job))
    out, png = tmp_path / "report.json", tmp_path / "errors.png"
    assert main(["simulate", str(path), "-o", str(out), "--plot", str(png)]) == 0
    assert "PASSED" in capsys.readouterr().out
    report = json.loads(out.read_text())
    assert report["passed"] and report["position_error"]["max"] <= 1e-3
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert main(["simulate", str(path), "-o", str(out), "--plot", "none", "--squeeze", "0",
                 "--grip-force", "0"]) == 1
    assert "lost" in capsys.readouterr().out and not json.loads(out.read_text())["passed"]
    assert main(["simulate", str(tmp_path / "missing.json")]) == 2


# -- issue 25, part 2: simulations are jobs of their own processes ----------------------------

def test_a_simulation_over_the_step_bound_is_a_422_naming_timestep(
        live_server: Server, finger_job: str) -> None:
    url = f"{live_server.url}/v1/plans/{finger_job}/simulation"
    r = httpx.post(url, json={"timestep": 1e-5, "settle": 5.0}, timeout=60)
    assert r.status_code == 422, r.text
    (detail,) = r.json()["detail"]
    assert detail["field"] == "timestep"
    assert "at most 500000" in detail["reason"] and "DEXROLL_SIM_MAX_STEPS" in detail["reason"]


def test_the_api_answers_while_simulations_run_and_a_left_run_is_stopped(
        live_server: Server, finger_job: str) -> None:
    """Six long simulations at once (one slot, four waiting at most), each client leaving
    after a few seconds: the API's other routes answer meanwhile, the sixth is refused
    with Retry-After, and the runs stop once their clients have left."""
    url = live_server.url
    long_run = {"timestep": 2e-5, "settle": 2.0, "record_every": 1000}

    async def simulate() -> int | None:
        async with httpx.AsyncClient(timeout=4.0) as client:
            try:
                r = await client.post(f"{url}/v1/plans/{finger_job}/simulation",
                                      json=long_run)
            except httpx.TimeoutException:
                return None  # the client left
            if r.status_code == 503:
                assert r.json()["error"] == "simulations_busy" and "Retry-After" in r.headers
            return r.status_code

    async def the_rest_answer() -> list[int]:
        await asyncio.sleep(1.0)  # the runs have started (or wait)
        async with httpx.AsyncClient(timeout=60.0) as client:
            codes = []
            for path in ("/healthz", "/readyz", "/v1/plans", f"/v1/plans/{finger_job}",
                         "/v1/models"):
                codes.append((await client.get(f"{url}{path}")).status_code)
            busy = (await client.get(f"{url}/readyz")).json()["simulations"]
            assert busy["running"] == 1 and busy["slots"] == 1, busy
            return codes

    async def main() -> tuple[list[int | None], list[int]]:
        runs = asyncio.gather(*(simulate() for _ in range(6)))
        codes = await the_rest_answer()
        return list(await runs), codes

    runs, codes = asyncio.run(main())
    assert codes == [200] * 5
    assert 503 in runs, runs
    # every client has left: the running one is stopped, the waiting ones dropped
    deadline = time.monotonic() + 60.0
    while time.monotonic() < deadline:
        busy = httpx.get(f"{url}/readyz", timeout=30).json()["simulations"]
        if busy["running"] == 0 and busy["queued"] == 0:
            break
        time.sleep(0.2)
    assert busy == {"running": 0, "queued": 0, "slots": 1}
    # and the pool runs the next one
    r = httpx.post(f"{url}/v1/plans/{finger_job}/simulation", json={}, timeout=120)
    assert r.status_code == 201, r.text
