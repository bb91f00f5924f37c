"""The service's solver workers on a real Ray cluster (issue 39): a head and a second node
started with `ray start` on loopback (each with one CPU, its own temporary folder), the
service started with DEXROLL_EXECUTOR=ray against it.

* a batch runs on both nodes;
* the second node killed (its raylet and what it started SIGKILLed) while a job runs
  there: nothing lost or duplicated, the job queued again and finished on the head;
* the cluster gone: the API keeps answering, /readyz says why it is not ready, a submission
  gets 503 workers_unavailable with Retry-After.
"""

from __future__ import annotations

import json
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest

from planner_service.executors.local_cluster import RAY_ENV, LocalRayCluster, descendants
from tests.conftest import Server, start_server

ROOT = Path(__file__).resolve().parents[1]
TRIANGLE = json.loads((ROOT / "examples" / "triangle.json").read_text())
pytest.importorskip("ray")


@pytest.fixture(scope="module")
def cluster() -> Iterator[LocalRayCluster]:
    c = LocalRayCluster(head_cpus=1, node_cpus=(1,))
    try:
        yield c
    finally:
        c.stop()


@pytest.fixture(scope="module")
def service(cluster: LocalRayCluster, tmp_path_factory: pytest.TempPathFactory) -> Iterator[Server]:
    server = start_server(tmp_path_factory.mktemp("ray-service"), DEXROLL_EXECUTOR="ray",
                          DEXROLL_RAY_ADDRESS=cluster.address, DEXROLL_WORKERS="2",
                          **RAY_ENV)
    try:
        deadline = time.monotonic() + 120
        while httpx.get(f"{server.url}/readyz").json().get("workers") != 2:
            assert time.monotonic() < deadline, server.log_text()
            time.sleep(0.5)
        yield server
    finally:
        server.stop()


def batch(server: Server, n: int, n_intervals: int = 60) -> str:
    items = [{**TRIANGLE, "duration": 6.0 + 0.1 * i, "n_intervals": n_intervals,
              "max_refinements": 0} for i in range(n)]
    r = httpx.post(f"{server.url}/v1/batches", json={"items": items}, timeout=60)
    assert r.status_code == 201, r.text
    batch_id: str = r.json()["id"]
    return batch_id


def results(server: Server, batch_id: str) -> list[dict[str, Any]]:
    r = httpx.get(f"{server.url}/v1/batches/{batch_id}/results", timeout=300)
    return [json.loads(line) for line in r.text.splitlines()]


def test_a_batch_runs_on_both_nodes(service: Server, cluster: LocalRayCluster) -> None:
    ready = httpx.get(f"{service.url}/readyz").json()
    assert ready["executor"]["name"] == "ray" and ready["executor"]["nodes"] == 2
    jobs = results(service, batch(service, 8))
    assert len(jobs) == 8 and all(j["state"] == "succeeded" for j in jobs)
    nodes = {cluster.node_of(j["worker_pid"]) for j in jobs}
    assert len(nodes) == 2 and None not in nodes  # actors on the head and on node1


def test_a_node_killed_mid_batch_loses_nothing(service: Server, cluster: LocalRayCluster) -> None:
    on_second = descendants(cluster.raylet("node1"))
    batch_id = batch(service, 10, n_intervals=300)
    deadline = time.monotonic() + 120
    while True:  # a job running on the second node's actor
        jobs = httpx.get(f"{service.url}/v1/batches/{batch_id}").json()
        running = [httpx.get(f"{service.url}/v1/plans/{i}").json()
                   for i in jobs["job_ids"]]
        victim = next((j for j in running if j["state"] == "running"
                       and j["worker_pid"] in on_second), None)
        if victim is not None:
            break
        assert time.monotonic() < deadline, "no job ran on the second node"
        time.sleep(0.1)
    cluster.kill_node("node1")
    ended = results(service, batch_id)
    assert len(ended) == 10 and len({j["id"] for j in ended}) == 10  # none lost or twice
    assert all(j["state"] == "succeeded" or j["code"] for j in ended)
    again = next(j for j in ended if j["id"] == victim["id"])
    assert again["state"] == "succeeded" and again["worker_pid"] != victim["worker_pid"]
    ready = httpx.get(f"{service.url}/readyz").json()
    assert ready["requeued"] >= 1
    assert "queued again" in service.log_text()


def test_when_the_cluster_is_gone_the_api_answers_and_refuses_new_work(
        service: Server, cluster: LocalRayCluster) -> None:
    cluster.stop()
    deadline = time.monotonic() + 120
    while True:
        r = httpx.get(f"{service.url}/readyz")
        if r.status_code == 503:
            break
        assert time.monotonic() < deadline, service.log_text()
        time.sleep(0.5)
    assert "Ray" in r.json()["message"] or "worker" in r.json()["message"]
    deadline = time.monotonic() + 120
    while True:
        post = httpx.post(f"{service.url}/v1/plans", json=TRIANGLE, timeout=30)
        if post.status_code == 503:
            break
        assert time.monotonic() < deadline, service.log_text()
        time.sleep(1.0)
    assert post.json()["error"] == "workers_unavailable" and "retry-after" in post.headers
    assert httpx.get(f"{service.url}/healthz").status_code == 200
    assert httpx.get(f"{service.url}/v1/plans").status_code == 200
