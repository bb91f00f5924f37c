"""Issue 25, part 1: a full disk or a read-only store is a state of the service, not a
crash. SQLite's own ``OperationalError("database or disk is full")`` is injected at the
store's boundary (its connections' ``execute``), on a real SQLite file, under a real
uvicorn server on loopback with real worker processes, and the free space the store sees
(``free_bytes``) is lowered for the result that must be refused before it is written."""

from __future__ import annotations

import json
import sqlite3
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest
import uvicorn
from conftest import free_port

from planner_service.api.app import create_app
from planner_service.jobs import store as store_module
from planner_service.jobs.store import StorageError, Store
from planner_service.settings import Settings

ROOT = Path(__file__).resolve().parents[1]
TRIANGLE: dict[str, Any] = json.loads((ROOT / "examples" / "triangle.json").read_text())
WRITES = ("INSERT", "UPDATE", "DELETE", "COMMIT")


class Disk:
    """Which writes SQLite refuses: ``refuse(sql, args)`` True raises SQLite's own
    "database or disk is full" from the statement (None: every write goes through)."""

    refuse: Callable[[str, tuple[Any, ...]], bool] | None = None


class FullDiskConnection:
    """A store connection whose writes fail as on a full disk while :class:`Disk` says so
    (reads, and everything else, go to the real connection)."""

    def __init__(self, conn: sqlite3.Connection) -> None:
        self._conn = conn

    def execute(self, sql: str, args: tuple[Any, ...] = ()) -> sqlite3.Cursor:
        refuse = Disk.refuse
        if refuse is not None and sql.lstrip().upper().startswith(WRITES) and \
                refuse(sql, args):
            raise sqlite3.OperationalError("database or disk is full")
        return self._conn.execute(sql, args)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._conn, name)


@pytest.fixture
def full_disk(monkeypatch: pytest.MonkeyPatch) -> Iterator[type[Disk]]:
    real = Store._conn
    monkeypatch.setattr(Store, "_conn",
                        lambda self: FullDiskConnection(real(self)))  # type: ignore[arg-type]
    Disk.refuse = None
    yield Disk
    Disk.refuse = None


def every_write(sql: str, args: tuple[Any, ...]) -> bool:
    return True


def test_a_store_that_cannot_be_written_is_faulted_until_a_write_succeeds(
        tmp_path: Path, full_disk: type[Disk]) -> None:
    store = Store(tmp_path / "jobs.sqlite3")
    job, _ = store.create("ball_on_palm", "{}", 1.0, None)
    full_disk.refuse = every_write
    with pytest.raises(StorageError, match="disk is full"):
        store.create("ball_on_palm", "{}", 1.0, None)
    assert store.fault == "database or disk is full" and store.fault_since is not None
    assert not store.probe() and store.fault is not None
    assert store.get(job.id) is not None  # reads still answer
    with pytest.raises(sqlite3.OperationalError):  # StorageError is one: old catches hold
        store.finish(job.id, "succeeded", "solved", "ok")
    full_disk.refuse = None
    assert store.probe() and store.fault is None and store.fault_since is None
    assert store.finish(job.id, "succeeded", "solved", "ok")
    # a busy store is not a fault
    assert not store_module.is_storage_fault(sqlite3.OperationalError("database is locked"))
    assert store_module.is_storage_fault(
        sqlite3.OperationalError("attempt to write a readonly database"))


@pytest.fixture
def service(tmp_path: Path, full_disk: type[Disk]) -> Iterator[str]:
    """The service in this process (so that its store can be faulted): uvicorn on a
    loopback port, one solver worker, a real SQLite file."""
    settings = Settings(data_dir=tmp_path / "data", workers=1, warmup="", kill_grace=2.0,
                        max_wait=60.0)
    server = uvicorn.Server(uvicorn.Config(create_app(settings), host="127.0.0.1",
                                           port=free_port(), log_level="warning"))
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    url = f"http://127.0.0.1:{server.config.port}"
    assert wait_for(lambda: ready(url), 120.0), "the service did not start"
    yield url
    server.should_exit = True
    thread.join(timeout=30)


def ready(url: str) -> bool:
    try:
        return httpx.get(f"{url}/readyz", timeout=10).status_code == 200
    except httpx.TransportError:
        return False


def wait_for(condition: Callable[[], bool], timeout: float) -> bool:
    """Poll ``condition`` until it holds or ``timeout`` passes (a bound, not a latency)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(0.1)
    return False


def plan(url: str, wait: float = 60.0) -> httpx.Response:
    return httpx.post(f"{url}/v1/plans", params={"wait": wait}, json=TRIANGLE, timeout=120)


def test_readiness_finds_a_store_that_cannot_be_written_before_any_job_writes(
        service: str, full_disk: type[Disk]) -> None:
    """A store that has become unwritable while nothing is submitted: /readyz probes it
    (one small write at most once a second) and says not ready, naming why, without a
    job's write failing first; it is ready again once the store can be written."""
    url = service
    full_disk.refuse = every_write

    def not_ready() -> bool:
        r = httpx.get(f"{url}/readyz", timeout=30)
        return r.status_code == 503 and "disk is full" in r.json()["message"]

    assert wait_for(not_ready, 30.0)
    full_disk.refuse = None
    assert wait_for(lambda: ready(url), 60.0)


def test_a_full_disk_refuses_new_work_and_the_service_resumes_by_itself(
        service: str, full_disk: type[Disk]) -> None:
    url = service
    full_disk.refuse = every_write
    r = plan(url)
    assert r.status_code == 503, r.text
    assert r.json()["error"] == "storage_error" and "disk is full" in r.json()["message"]
    assert int(r.headers["Retry-After"]) > 0
    r = httpx.get(f"{url}/readyz", timeout=30)
    assert r.status_code == 503 and "disk is full" in r.json()["message"]
    assert "Retry-After" in r.headers
    assert httpx.get(f"{url}/v1/plans", timeout=30).status_code == 200  # reads answer
    assert plan(url).json()["error"] == "storage_error"  # refused before any write
    full_disk.refuse = None  # space returns: the dispatcher's probe finds it
    assert wait_for(lambda: ready(url), 60.0)
    r = plan(url)
    assert r.status_code == 201 and r.json()["state"] == "succeeded", r.text


def test_a_plan_that_cannot_be_stored_fails_its_job_and_the_next_one_runs(
        service: str, full_disk: type[Disk], monkeypatch: pytest.MonkeyPatch) -> None:
    url = service
    # the disk fills for the plan's write only: SQLite refuses it, the job fails
    # storage_error without its plan, the smaller write of that end goes through
    full_disk.refuse = lambda sql, args: any(isinstance(a, str) and len(a) > 2000
                                             for a in args)
    job = plan(url).json()
    assert job["state"] == "failed" and job["code"] == "storage_error", job
    assert "disk is full" in job["message"] and job["result"] is None
    assert ready(url)
    # a plan larger than the free space is refused before it is written
    full_disk.refuse = None
    monkeypatch.setattr(store_module, "free_bytes", lambda path: 1000)
    job = plan(url).json()
    assert job["state"] == "failed" and job["code"] == "storage_error", job
    assert "disk has 1000 free" in job["message"] and "ended solved" in job["message"]
    monkeypatch.undo()
    full_disk.refuse = None
    job = plan(url).json()
    assert job["state"] == "succeeded", job


def test_an_end_the_store_cannot_write_is_kept_and_written_when_it_can(
        service: str, full_disk: type[Disk]) -> None:
    url = service
    # the disk fills for every job end (and the dispatcher's probe; readiness's own goes
    # through, so that not ready comes from the job's end): the job runs, its end cannot
    # be written, the service says so, and the end is written once it can
    full_disk.refuse = lambda sql, args: "finished_at = ?" in sql or \
        ("probe" in sql and "readiness" not in sql)
    r = plan(url, wait=0.0)
    assert r.status_code == 202
    job_id = r.json()["id"]
    assert wait_for(lambda: not ready(url), 120.0)
    r = httpx.get(f"{url}/readyz", timeout=30)
    assert r.status_code == 503 and "disk is full" in r.json()["message"]
    assert httpx.get(f"{url}/v1/plans/{job_id}", timeout=30).json()["state"] == "running"
    assert plan(url).status_code == 503
    full_disk.refuse = None
    assert wait_for(lambda: ready(url), 60.0)

    def job() -> dict[str, Any]:
        return dict(httpx.get(f"{url}/v1/plans/{job_id}", timeout=30).json())

    # the dispatcher's probe clears the fault, then writes the end it kept
    assert wait_for(lambda: job()["state"] != "running", 60.0)
    job_now = job()
    assert job_now["state"] == "failed" and job_now["code"] == "storage_error", job_now
    assert "disk is full" in job_now["message"]
