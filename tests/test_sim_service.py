"""A plan's execution in MuJoCo through the service's doors: ``POST/GET
/v1/plans/{id}/simulation`` on a real service (uvicorn on loopback), ``client.simulate``,
and ``dexroll simulate`` on the job's JSON (docs/simulation.md)."""

from __future__ import annotations

import asyncio
import json
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
