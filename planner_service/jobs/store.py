"""The job store: one SQLite file in WAL mode, safe across threads (a connection each).

Every job is a row; its ``state`` moves queued -> running -> one terminal state, and the
transitions are single UPDATE statements guarded by the current state, so that a job ends
exactly once (a late worker reply cannot overwrite a cancellation, for instance).
"""

from __future__ import annotations

import hashlib
import sqlite3
import threading
import time
import uuid
from dataclasses import dataclass
from pathlib import Path
from typing import Any

__all__ = ["IdempotencyConflictError", "JobRow", "Store"]

_SCHEMA = """
CREATE TABLE IF NOT EXISTS jobs (
    id TEXT PRIMARY KEY,
    idempotency_key TEXT UNIQUE,
    request_hash TEXT NOT NULL,
    planner TEXT NOT NULL,
    request TEXT NOT NULL,
    time_limit REAL NOT NULL,
    state TEXT NOT NULL,
    code TEXT,
    message TEXT,
    raw_status TEXT,
    result TEXT,
    attempts INTEGER NOT NULL DEFAULT 0,
    worker_pid INTEGER,
    created_at REAL NOT NULL,
    started_at REAL,
    finished_at REAL
);
CREATE INDEX IF NOT EXISTS jobs_by_state ON jobs(state, created_at);
"""

ACTIVE = ("queued", "running")
#: A job interrupted this many times by service restarts is failed instead of re-run.
MAX_ATTEMPTS = 3


class IdempotencyConflictError(Exception):
    """An idempotency key was reused with a different request body."""


@dataclass(frozen=True)
class JobRow:
    id: str
    planner: str
    request: str
    time_limit: float
    state: str
    code: str | None
    message: str | None
    raw_status: str | None
    result: str | None
    created_at: float
    started_at: float | None
    finished_at: float | None
    worker_pid: int | None

    @staticmethod
    def of(row: sqlite3.Row) -> JobRow:
        return JobRow(**{k: row[k] for k in JobRow.__dataclass_fields__})


def request_hash(body: str) -> str:
    return hashlib.sha256(body.encode()).hexdigest()


class Store:
    """SQLite job store at ``path`` (its folder is created)."""

    def __init__(self, path: Path) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._local = threading.local()
        self._conn().executescript(_SCHEMA)  # executescript manages its own transaction

    # -- connections ----------------------------------------------------------------------
    def _conn(self) -> sqlite3.Connection:
        conn: sqlite3.Connection | None = getattr(self._local, "conn", None)
        if conn is None:
            conn = sqlite3.connect(self.path, timeout=30.0, isolation_level=None)
            conn.row_factory = sqlite3.Row
            conn.execute("PRAGMA journal_mode=WAL")
            conn.execute("PRAGMA synchronous=NORMAL")
            self._local.conn = conn
        return conn

    class _Tx:
        def __init__(self, conn: sqlite3.Connection) -> None:
            self.conn = conn

        def __enter__(self) -> sqlite3.Connection:
            self.conn.execute("BEGIN IMMEDIATE")
            return self.conn

        def __exit__(self, exc_type: Any, exc: Any, tb: Any) -> None:
            self.conn.execute("ROLLBACK" if exc_type else "COMMIT")

    def _tx(self) -> Store._Tx:
        return Store._Tx(self._conn())

    # -- jobs ------------------------------------------------------------------------------
    def create(self, planner: str, request: str, time_limit: float,
               idempotency_key: str | None) -> tuple[JobRow, bool]:
        """Insert a queued job; with a known idempotency key return that job instead.

        Returns (job, created). Raises :class:`IdempotencyConflictError` when the key is known
        with a different request.
        """
        digest = request_hash(request)
        with self._tx() as db:
            if idempotency_key is not None:
                row = db.execute("SELECT * FROM jobs WHERE idempotency_key = ?",
                                 (idempotency_key,)).fetchone()
                if row is not None:
                    if row["request_hash"] != digest:
                        raise IdempotencyConflictError(
                            f"Idempotency-Key {idempotency_key!r} was used with a different "
                            "request")
                    return JobRow.of(row), False
            job_id = uuid.uuid4().hex
            db.execute(
                "INSERT INTO jobs (id, idempotency_key, request_hash, planner, request, "
                "time_limit, state, created_at) VALUES (?, ?, ?, ?, ?, ?, 'queued', ?)",
                (job_id, idempotency_key, digest, planner, request, time_limit, time.time()))
            row = db.execute("SELECT * FROM jobs WHERE id = ?", (job_id,)).fetchone()
        return JobRow.of(row), True

    def get(self, job_id: str) -> JobRow | None:
        row = self._conn().execute("SELECT * FROM jobs WHERE id = ?", (job_id,)).fetchone()
        return JobRow.of(row) if row else None

    def list(self, limit: int, offset: int) -> tuple[list[JobRow], int]:
        """A page of jobs, newest first, without their results; and the total count."""
        db = self._conn()
        rows = db.execute(
            "SELECT id, planner, '' AS request, time_limit, state, code, message, raw_status,"
            " NULL AS result, created_at, started_at, finished_at, worker_pid FROM jobs "
            "ORDER BY created_at DESC, rowid DESC LIMIT ? OFFSET ?", (limit, offset)).fetchall()
        total = db.execute("SELECT COUNT(*) FROM jobs").fetchone()[0]
        return [JobRow.of(r) for r in rows], int(total)

    def count(self, state: str) -> int:
        return int(self._conn().execute("SELECT COUNT(*) FROM jobs WHERE state = ?",
                                        (state,)).fetchone()[0])

    def claim_next(self) -> JobRow | None:
        """Move the oldest queued job to running and return it (atomically)."""
        with self._tx() as db:
            row = db.execute("SELECT id FROM jobs WHERE state = 'queued' "
                             "ORDER BY created_at, rowid LIMIT 1").fetchone()
            if row is None:
                return None
            db.execute("UPDATE jobs SET state = 'running', started_at = ?, "
                       "attempts = attempts + 1 WHERE id = ?", (time.time(), row["id"]))
            claimed = db.execute("SELECT * FROM jobs WHERE id = ?", (row["id"],)).fetchone()
        return JobRow.of(claimed)

    def set_worker(self, job_id: str, pid: int) -> None:
        """Record the worker process running a job."""
        with self._tx() as db:
            db.execute("UPDATE jobs SET worker_pid = ? WHERE id = ?", (pid, job_id))

    def finish(self, job_id: str, state: str, code: str, message: str,
               raw_status: str | None = None, result: str | None = None) -> bool:
        """End an active job in ``state``; False if it had already ended."""
        with self._tx() as db:
            cur = db.execute(
                "UPDATE jobs SET state = ?, code = ?, message = ?, raw_status = ?, result = ?,"
                " finished_at = ? WHERE id = ? AND state IN ('queued', 'running')",
                (state, code, message, raw_status, result, time.time(), job_id))
            return cur.rowcount == 1

    def cancel_queued(self, job_id: str) -> bool:
        """Cancel a job that has not started; False if it is not queued."""
        with self._tx() as db:
            cur = db.execute(
                "UPDATE jobs SET state = 'cancelled', code = 'cancelled', message = ?, "
                "finished_at = ? WHERE id = ? AND state = 'queued'",
                ("cancelled before it started", time.time(), job_id))
            return cur.rowcount == 1

    def recover(self) -> tuple[int, int]:
        """After a restart: re-queue jobs that were running (the service stopped under them),
        failing those interrupted MAX_ATTEMPTS times. Returns (re-queued, failed)."""
        with self._tx() as db:
            failed = db.execute(
                "UPDATE jobs SET state = 'failed', code = 'interrupted', message = ?, "
                "finished_at = ? WHERE state = 'running' AND attempts >= ?",
                (f"the service stopped during this job {MAX_ATTEMPTS} times", time.time(),
                 MAX_ATTEMPTS)).rowcount
            requeued = db.execute("UPDATE jobs SET state = 'queued', started_at = NULL "
                                  "WHERE state = 'running'").rowcount
        return int(requeued), int(failed)

    def close(self) -> None:
        conn = getattr(self._local, "conn", None)
        if conn is not None:
            conn.close()
            self._local.conn = None
