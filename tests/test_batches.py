"""Batches on a real service (``/v1/batches``, docs/service.md "Batches"): many plan
requests submitted as one, every item checked before any job is made (a 422 naming
``items[i].field``), their jobs ordinary jobs counted by state, streamed as NDJSON in
submission order or as they finish, cancelled together; the client's ``plan_many`` and
``dexroll batch FILE.jsonl`` with its progress bar."""

from __future__ import annotations

import json
import subprocess
import sys
from datetime import datetime
from pathlib import Path
from typing import Any

import httpx
import pytest

from dexroll_client import DexrollClient
from dexroll_client.errors import NotFoundError
from dexroll_client.models import Job, PlanResult
from tests.conftest import Server

ROOT = Path(__file__).resolve().parents[1]


def final_x(job: Job) -> float:
    """Where a ball-on-palm job's plan ends the contact's x [m]."""
    assert isinstance(job.result, PlanResult) and job.result.grid is not None
    return float(job.result.grid.eta[-1][0])


def palm_request(x: float, n: int = 10) -> dict[str, Any]:
    """The ball rolled on the palm to (x, 0): a plan of a fraction of a second."""
    return {"initial": {"x": 0, "y": 0, "u": 0, "v": 0, "psi": 0}, "goal": {"x": x},
            "duration": 1.0, "n_intervals": n}


def test_a_batch_plans_every_request_and_streams_them_in_submission_order(
        live_server: Server) -> None:
    """Three requests as one batch: its jobs in order, each an ordinary job; the results
    stream in submission order, each succeeded with its plan (its goal the request's);
    the batch then counts them all succeeded. ``plan_many`` returns the terminal jobs in
    the requests' order and reports progress as each ends."""
    goals = [0.01, 0.02, 0.015]
    with DexrollClient.from_url(live_server.url) as client:
        batch = client.submit_batch([palm_request(x) for x in goals])
        assert batch.size == 3 and len(batch.job_ids) == 3
        assert sum(batch.counts.values()) == 3
        jobs = list(client.batch_results(batch.id))
        assert [j.id for j in jobs] == batch.job_ids
        for job, x in zip(jobs, goals, strict=True):
            assert job.state.value == "succeeded", job.message
            assert final_x(job) == pytest.approx(x, abs=1e-6)
            assert client.get(job.id).state.value == "succeeded"
        done = client.batch(batch.id)
        assert done.done and done.counts == {"succeeded": 3}
        seen: list[tuple[int, int]] = []
        planned = client.plan_many([palm_request(x) for x in goals[:2]],
                                   progress=lambda d, n: seen.append((d, n)))
        assert [j.state.value for j in planned] == ["succeeded", "succeeded"]
        assert [final_x(j) for j in planned] == pytest.approx(goals[:2], abs=1e-6)
        assert seen == [(1, 2), (2, 2)]


def test_results_as_they_finish_come_in_the_order_they_ended(live_server: Server) -> None:
    """``order=finished``: each line is a job that has ended, in the order they did."""
    with DexrollClient.from_url(live_server.url) as client:
        batch = client.submit_batch([palm_request(0.01 * (k + 1), 10 + 4 * k)
                                     for k in range(4)])
        jobs = list(client.batch_results(batch.id, order="finished", result=False))
    assert sorted(j.id for j in jobs) == sorted(batch.job_ids)
    ends = [j.finished_at for j in jobs]
    assert all(isinstance(e, datetime) for e in ends)
    assert ends == sorted(ends)  # type: ignore[type-var]
    assert all(j.result is None for j in jobs)


def test_a_bad_item_is_named_with_its_index_and_nothing_is_made(live_server: Server) -> None:
    """An item that fails the checks: 422 naming ``items[1].duration``, and no job of the
    batch is stored (the job count is unchanged); an empty batch and an unknown batch are
    refused as such."""
    url = live_server.url
    total = httpx.get(f"{url}/v1/plans", params={"limit": 1}, timeout=30).json()["total"]
    bad = {**palm_request(0.01), "duration": -1.0}
    r = httpx.post(f"{url}/v1/batches", json={"items": [palm_request(0.01), bad]},
                   timeout=60)
    assert r.status_code == 422, r.text
    assert [d["field"] for d in r.json()["detail"]] == ["items[1].duration"]
    after = httpx.get(f"{url}/v1/plans", params={"limit": 1}, timeout=30).json()["total"]
    assert after == total
    r = httpx.post(f"{url}/v1/batches", json={"items": []}, timeout=60)
    assert r.status_code == 422 and r.json()["detail"][0]["field"] == "items"
    with DexrollClient.from_url(url) as client, pytest.raises(NotFoundError):
        client.batch("nope")


def test_a_cancelled_batch_ends_every_job(live_server: Server) -> None:
    """Twelve requests, cancelled right after the submission: every job ends (those not
    yet finished cancelled), the batch is done, and its stream ends."""
    with DexrollClient.from_url(live_server.url) as client:
        batch = client.submit_batch([palm_request(0.01 + 0.001 * k, 40) for k in range(12)])
        after = client.cancel_batch(batch.id)
        assert after.done, after.counts
        assert after.counts.get("cancelled", 0) >= 1, after.counts
        assert set(after.counts) <= {"cancelled", "succeeded"}
        jobs = list(client.batch_results(batch.id, result=False))
        assert len(jobs) == 12


def test_dexroll_batch_plans_a_jsonl_file_with_a_progress_bar(live_server: Server,
                                                              tmp_path: Path) -> None:
    """``dexroll batch FILE.jsonl --url``: every job written, a line each, exit 0 when all
    succeeded, the progress bar on stderr; a file with a bad request names its line and
    field (exit 2) and plans nothing."""
    good = tmp_path / "requests.jsonl"
    good.write_text("\n".join(json.dumps(palm_request(x)) for x in (0.01, 0.02)) + "\n",
                    encoding="utf-8")
    proc = subprocess.run([sys.executable, "-m", "planner_service.cli", "batch", str(good),
                           "--url", live_server.url], capture_output=True, text=True,
                          timeout=300, cwd=ROOT, check=False)
    assert proc.returncode == 0, proc.stderr
    assert "2/2 done" in proc.stderr
    lines = (tmp_path / "requests.results.jsonl").read_text().splitlines()
    assert len(lines) == 2 and all(json.loads(x)["state"] == "succeeded" for x in lines)
    bad = tmp_path / "bad.jsonl"
    bad.write_text(json.dumps(palm_request(0.01)) + "\n"
                   + json.dumps({**palm_request(0.01), "n_intervals": 0}) + "\n",
                   encoding="utf-8")
    proc = subprocess.run([sys.executable, "-m", "planner_service.cli", "batch", str(bad),
                           "--url", live_server.url], capture_output=True, text=True,
                          timeout=300, cwd=ROOT, check=False)
    assert proc.returncode == 2, proc.stderr
    assert "line 2" in proc.stderr and "n_intervals" in proc.stderr
    assert not (tmp_path / "bad.results.jsonl").exists()


def test_the_async_client_plans_a_batch_too(live_server: Server) -> None:
    """``AsyncDexrollClient.plan_many``: the same terminal jobs in the requests' order."""
    import asyncio

    from dexroll_client import AsyncDexrollClient

    async def run() -> list[Job]:
        async with AsyncDexrollClient.from_url(live_server.url) as client:
            return await client.plan_many([palm_request(x) for x in (0.012, 0.018)])

    jobs = asyncio.run(run())
    assert [j.state.value for j in jobs] == ["succeeded", "succeeded"]
    assert [final_x(j) for j in jobs] == pytest.approx([0.012, 0.018], abs=1e-6)
