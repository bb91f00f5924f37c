"""The service's solver workers on a real Ray cluster (issue 39): a head and a second node
started with `ray start` on loopback (each with one CPU, its own temporary folder), the
service started with DEXROLL_EXECUTOR=ray against it.

* a batch runs on both nodes;
* the second node killed (its raylet SIGKILLed) while a job runs there: nothing lost or
  duplicated, the job queued again and finished on the head;
* the cluster gone: the API keeps answering, /readyz says why it is not ready, a submission
  gets 503 workers_unavailable with Retry-After.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest

from tests.conftest import Server, free_port, start_server

ROOT = Path(__file__).resolve().parents[1]
TRIANGLE = json.loads((ROOT / "examples" / "triangle.json").read_text())
RAY = Path(sys.executable).with_name("ray")

pytest.importorskip("ray")


class Cluster:
    """A Ray cluster of this machine's own processes (found by their temporary folder)."""

    def __init__(self) -> None:
        self.temp = Path(tempfile.mkdtemp(prefix="dxr-", dir="/tmp"))  # short: unix sockets
        self.port = free_port()
        self.address = f"127.0.0.1:{self.port}"
        self.env = {**os.environ, "RAY_USAGE_STATS_ENABLED": "0", "RAY_AUTH_MODE": "token",
                    "RAY_DISABLE_IMPORT_WARNING": "1"}
        self.ray("start", "--head", f"--port={self.port}", "--num-cpus=1",
                 "--include-dashboard=false", "--disable-usage-stats")
        self.ray("start", f"--address={self.address}", "--num-cpus=1",
                 '--resources={"second": 1}')

    def ray(self, *args: str) -> None:
        subprocess.run([str(RAY), *args, f"--temp-dir={self.temp}"], env=self.env,
                       check=True, capture_output=True, timeout=120)

    def raylets(self) -> list[tuple[int, str]]:
        """(pid, command line) of this cluster's raylets."""
        out = subprocess.run(["ps", "-ww", "-eo", "pid,args"], capture_output=True,
                             text=True).stdout
        return [(int(line.split()[0]), line) for line in out.splitlines()[1:]
                if "raylet/raylet" in line and str(self.temp) in line]

    def second_raylet(self) -> int:
        """The second node's raylet: the one whose resources name 'second'."""
        for pid, line in self.raylets():
            if "second" in line:
                return pid
        raise AssertionError(f"no raylet of the second node among {self.raylets()}")

    def kill_all(self) -> None:
        """SIGKILL every process of the cluster and all they started (agents, workers)."""
        out = subprocess.run(["ps", "-ww", "-eo", "pid,args"], capture_output=True,
                             text=True).stdout
        own = {int(line.split()[0]) for line in out.splitlines()[1:] if str(self.temp) in line}
        for pid in own | set().union(*(descendants(p) for p in own)):
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)


def descendants(pid: int) -> set[int]:
    """The processes started by ``pid`` (a raylet's workers), at any depth."""
    out = subprocess.run(["ps", "-eo", "pid,ppid"], capture_output=True, text=True).stdout
    parent = {int(a): int(b) for a, b in (line.split() for line in out.splitlines()[1:])}
    found: set[int] = set()
    for child in parent:
        p = child
        while p in parent and p > 1:
            p = parent[p]
            if p == pid:
                found.add(child)
                break
    return found


@pytest.fixture(scope="module")
def cluster() -> Iterator[Cluster]:
    c = Cluster()
    try:
        yield c
    finally:
        c.kill_all()
        time.sleep(1.0)
        shutil.rmtree(c.temp, ignore_errors=True)


@pytest.fixture(scope="module")
def service(cluster: Cluster, tmp_path_factory: pytest.TempPathFactory) -> Iterator[Server]:
    server = start_server(tmp_path_factory.mktemp("ray-service"), DEXROLL_EXECUTOR="ray",
                          DEXROLL_RAY_ADDRESS=cluster.address, DEXROLL_WORKERS="2",
                          RAY_AUTH_MODE="token", RAY_USAGE_STATS_ENABLED="0")
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


def test_a_batch_runs_on_both_nodes(service: Server, cluster: Cluster) -> None:
    ready = httpx.get(f"{service.url}/readyz").json()
    assert ready["executor"]["name"] == "ray" and ready["executor"]["nodes"] == 2
    jobs = results(service, batch(service, 8))
    assert len(jobs) == 8 and all(j["state"] == "succeeded" for j in jobs)
    pids = {j["worker_pid"] for j in jobs}
    raylets = {pid for pid, _ in cluster.raylets()}
    nodes = {r for r in raylets if pids & descendants(r)}
    assert len(nodes) == 2, (pids, {r: descendants(r) for r in raylets})  # both nodes


def test_a_node_killed_mid_batch_loses_nothing(service: Server, cluster: Cluster) -> None:
    second = cluster.second_raylet()
    on_second = descendants(second)
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
    os.kill(second, signal.SIGKILL)
    ended = results(service, batch_id)
    assert len(ended) == 10 and len({j["id"] for j in ended}) == 10  # none lost or twice
    assert all(j["state"] == "succeeded" or j["code"] for j in ended)
    again = next(j for j in ended if j["id"] == victim["id"])
    assert again["state"] == "succeeded" and again["worker_pid"] != victim["worker_pid"]
    ready = httpx.get(f"{service.url}/readyz").json()
    assert ready["requeued"] >= 1
    assert "queued again" in service.log_text()


def test_when_the_cluster_is_gone_the_api_answers_and_refuses_new_work(
        service: Server, cluster: Cluster) -> None:
    cluster.kill_all()
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
