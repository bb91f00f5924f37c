"""The job store: one SQLite file in WAL mode, safe across threads (a connection each).

Every job is a row; its ``state`` moves queued -> running -> one terminal state, and the
transitions are single UPDATE statements guarded by the current state, so that a job ends
exactly once (a late worker reply cannot overwrite a cancellation, for instance).

A job belongs to an ``owner`` (the API key's; ``''``, the one local user, without keys):
reads and cancels of another owner's job find nothing, and an idempotency key is one
owner's (stored scoped by the owner). A plan's result is stored as the worker's compact
JSON and read back in chunks (:meth:`Store.result_chunks`), never parsed. Finished jobs
are purged by age and count (:meth:`Store.purge`).

A write that SQLite refuses for want of space or permission ("database or disk is full",
"attempt to write a readonly database", "disk I/O error") raises :class:`StorageError`
(an ``sqlite3.OperationalError``) and leaves the store *faulted* (:attr:`Store.fault`): the
API refuses new work with 503 and ``/readyz`` says why, until a write succeeds again
(the dispatcher probes with :meth:`Store.probe` while faulted). Nothing crashes: the
store's state is a fault to report, not an exception to die of.
"""

from __future__ import annotations

import builtins
import contextlib
import hashlib
import math
import shutil
import sqlite3
import threading
import time
import uuid
from collections.abc import Collection, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

__all__ = ["IdempotencyConflictError", "JobRow", "StorageError", "Store", "free_bytes"]

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
CREATE TABLE IF NOT EXISTS probe (
    id INTEGER PRIMARY KEY CHECK (id = 1),
    at REAL NOT NULL
);
CREATE TABLE IF NOT EXISTS simulations (
    job_id TEXT PRIMARY KEY,
    report TEXT NOT NULL,
    created_at REAL NOT NULL
);
CREATE TABLE IF NOT EXISTS batches (
    id TEXT PRIMARY KEY,
    owner TEXT NOT NULL,
    size INTEGER NOT NULL,
    created_at REAL NOT NULL
);
CREATE TABLE IF NOT EXISTS batch_jobs (
    batch_id TEXT NOT NULL,
    idx INTEGER NOT NULL,
    job_id TEXT NOT NULL,
    PRIMARY KEY (batch_id, idx)
);
"""
#: Columns added since the first schema (an older store file gains them when opened).
_MIGRATIONS = {"owner": "ALTER TABLE jobs ADD COLUMN owner TEXT NOT NULL DEFAULT ''",
               "has_plan": "ALTER TABLE jobs ADD COLUMN has_plan INTEGER",
               "structure": "ALTER TABLE jobs ADD COLUMN structure TEXT NOT NULL DEFAULT ''"}
_INDEXES = """
CREATE INDEX IF NOT EXISTS jobs_by_owner ON jobs(owner, created_at);
CREATE INDEX IF NOT EXISTS jobs_by_finish ON jobs(finished_at);
"""
#: Chunks of a stored result served at a time [bytes].
CHUNK = 1 << 16

ACTIVE = ("queued", "running")
#: A job interrupted this many times by service restarts is failed instead of re-run.
MAX_ATTEMPTS = 3
#: How many of the oldest queued jobs a worker's claim looks through for one whose
#: structure it holds (:meth:`Store.claim_next`): a job waits behind at most this many
#: younger ones.
CLAIM_WINDOW = 32


class StorageError(sqlite3.OperationalError):
    """SQLite could not write the store: its disk is full, it is read-only, or its file
    cannot be written (the reason is SQLite's own message)."""


#: SQLite's messages that say a write failed for a lasting reason (space, permission,
#: I/O), not a passing one ("database is locked" is a busy store: retried by SQLite's
#: own timeout, never a fault).
_FAULTS = ("full", "readonly", "read-only", "disk i/o", "unable to open", "out of memory")


def is_storage_fault(exc: BaseException) -> bool:
    """Whether an SQLite error is a lasting write fault (see :data:`_FAULTS`)."""
    text = str(exc).lower()
    return isinstance(exc, sqlite3.OperationalError) and any(f in text for f in _FAULTS)


def free_bytes(path: Path) -> int | None:
    """Free space of the file system holding ``path`` [bytes] (None: unknown)."""
    try:
        return int(shutil.disk_usage(path).free)
    except OSError:
        return None


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
    #: the stored result's size [bytes] (None: no result)
    result_bytes: int | None = None
    owner: str = ""
    #: whether the result holds a plan to show (None: not known, a store before it)
    has_plan: int | None = None
    #: the request's structure key (planner_service.planners.structure; '': not known)
    structure: str = ""
    #: times a worker has taken it
    attempts: int = 0

    @staticmethod
    def of(row: sqlite3.Row) -> JobRow:
        keys = row.keys()
        return JobRow(**{k: row[k] for k in JobRow.__dataclass_fields__ if k in keys})


#: The columns of a job without its result (its size instead).
_HEAD = ("id, planner, '' AS request, time_limit, state, code, message, raw_status, "
         "NULL AS result, created_at, started_at, finished_at, worker_pid, owner, has_plan, "
         "structure, attempts, length(CAST(result AS BLOB)) AS result_bytes")


def request_hash(body: str) -> str:
    return hashlib.sha256(body.encode()).hexdigest()


def scoped_key(owner: str, idempotency_key: str) -> str:
    """An idempotency key as stored: the owner's own (the local user's as given, so that a
    store written before owners keeps its keys)."""
    return idempotency_key if not owner else f"{owner}\x00{idempotency_key}"


class Store:
    """SQLite job store at ``path`` (its folder is created)."""

    def __init__(self, path: Path) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._local = threading.local()
        #: why the last write failed (SQLite's message; None: the last write succeeded)
        self.fault: str | None = None
        self._probed_at = -math.inf  # time.monotonic() of the last probe_if_stale
        #: when the store became faulted (time.time(); None: it is not)
        self.fault_since: float | None = None
        db = self._conn()
        db.executescript(_SCHEMA)  # executescript manages its own transaction
        columns = {r["name"] for r in db.execute("PRAGMA table_info(jobs)")}
        for column, ddl in _MIGRATIONS.items():
            if column not in columns:
                db.execute(ddl)
        db.executescript(_INDEXES)

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

    def _faulted(self, exc: sqlite3.OperationalError) -> sqlite3.OperationalError:
        """Record a failed write: a lasting one (full, read-only, I/O) faults the store and
        comes back as a :class:`StorageError`; a passing one (locked) as it is."""
        if not is_storage_fault(exc):
            return exc
        if self.fault is None:
            self.fault_since = time.time()
        self.fault = str(exc)
        if isinstance(exc, StorageError):
            return exc
        err = StorageError(str(exc))
        err.__cause__ = exc
        return err

    def _wrote(self) -> None:
        self.fault = self.fault_since = None

    class _Tx:
        """One write transaction (BEGIN IMMEDIATE ... COMMIT); a write SQLite refuses
        faults the store (:meth:`Store._faulted`), a committed one clears the fault."""

        def __init__(self, store: Store, conn: sqlite3.Connection) -> None:
            self.store, self.conn = store, conn

        def __enter__(self) -> sqlite3.Connection:
            try:
                self.conn.execute("BEGIN IMMEDIATE")
            except sqlite3.OperationalError as exc:
                raise self.store._faulted(exc) from exc
            return self.conn

        def __exit__(self, exc_type: Any, exc: Any, tb: Any) -> None:
            if exc_type is not None:
                with contextlib.suppress(sqlite3.Error):
                    if self.conn.in_transaction:
                        self.conn.execute("ROLLBACK")
                if isinstance(exc, sqlite3.OperationalError):
                    raise self.store._faulted(exc) from exc
                return
            try:
                self.conn.execute("COMMIT")
            except sqlite3.OperationalError as err:
                with contextlib.suppress(sqlite3.Error):
                    if self.conn.in_transaction:
                        self.conn.execute("ROLLBACK")
                raise self.store._faulted(err) from err
            self.store._wrote()

    def _tx(self) -> Store._Tx:
        return Store._Tx(self, self._conn())

    #: Space kept free beside a result being stored: SQLite writes it to the WAL, then
    #: checkpoints it into the database file (twice its size at worst) [bytes].
    RESERVE = 1 << 20

    def room_for(self, nbytes: int) -> str | None:
        """Why a result of ``nbytes`` would not fit on the store's disk (None: it fits, or
        the free space is not known): refused before it is written, so that one large plan
        does not fill the disk under every other job."""
        free = free_bytes(self.path.parent)
        need = 2 * nbytes + self.RESERVE
        if free is None or need <= free:
            return None
        return (f"the plan's JSON is {nbytes} bytes; storing it needs about {need} bytes "
                f"and the job store's disk has {free} free")

    def probe_if_stale(self, max_age: float) -> bool:
        """:meth:`probe`, unless the last probe is less than ``max_age`` [s] old (then
        whether the store is not faulted): readiness learns that the store cannot be
        written without waiting for a job's write to fail."""
        now = time.monotonic()
        if now - self._probed_at < max_age:
            return self.fault is None
        self._probed_at = now
        return self.probe(by="readiness")

    def probe(self, by: str = "dispatcher") -> bool:
        """Whether the store can be written now: one small write (the row of its own
        table; the statement says ``by`` whom, in a comment); it clears the fault when it
        succeeds, and records it when it does not."""
        try:
            with self._tx() as db:
                db.execute(f"INSERT OR REPLACE INTO probe (id, at) VALUES (1, ?) -- {by}",
                           (time.time(),))
        except sqlite3.OperationalError:
            return False
        return True

    # -- jobs ------------------------------------------------------------------------------
    def create(self, planner: str, request: str, time_limit: float,
               idempotency_key: str | None, owner: str = "", structure: str = ""
               ) -> tuple[JobRow, bool]:
        """Insert a queued job of ``owner`` (``structure``: its request's structure key);
        with an idempotency key this owner used already, return that job instead.

        Returns (job, created). Raises :class:`IdempotencyConflictError` when the key is known
        with a different request.
        """
        digest = request_hash(request)
        scoped = None if idempotency_key is None else scoped_key(owner, idempotency_key)
        with self._tx() as db:
            if scoped is not None:
                row = db.execute("SELECT * FROM jobs WHERE idempotency_key = ?",
                                 (scoped,)).fetchone()
                if row is not None:
                    if row["request_hash"] != digest:
                        raise IdempotencyConflictError(
                            f"Idempotency-Key {idempotency_key!r} was used with a different "
                            "request")
                    return JobRow.of(row), False
            job_id = uuid.uuid4().hex
            db.execute(
                "INSERT INTO jobs (id, idempotency_key, request_hash, planner, request, "
                "time_limit, state, created_at, owner, structure) "
                "VALUES (?, ?, ?, ?, ?, ?, 'queued', ?, ?, ?)",
                (job_id, scoped, digest, planner, request, time_limit, time.time(), owner,
                 structure))
            row = db.execute("SELECT * FROM jobs WHERE id = ?", (job_id,)).fetchone()
        return JobRow.of(row), True

    def get(self, job_id: str, owner: str | None = None) -> JobRow | None:
        """A job with its result (None: no such job, or not ``owner``'s when given)."""
        row = self._conn().execute(
            "SELECT *, length(CAST(result AS BLOB)) AS result_bytes FROM jobs WHERE id = ?",
            (job_id,)).fetchone()
        if row is None or (owner is not None and row["owner"] != owner):
            return None
        return JobRow.of(row)

    def head(self, job_id: str, owner: str | None = None) -> JobRow | None:
        """A job without its result (``result_bytes`` says how large it is)."""
        row = self._conn().execute(
            f"SELECT {_HEAD} FROM jobs WHERE id = ?", (job_id,)).fetchone()
        if row is None or (owner is not None and row["owner"] != owner):
            return None
        return JobRow.of(row)

    def result_chunks(self, job_id: str) -> Iterator[bytes]:
        """A job's stored result, as it was stored, in chunks of :data:`CHUNK` bytes, read
        through a connection of its own (SQLite incremental blob I/O: the whole result is
        never in memory). Nothing when the job has no result (any more)."""
        conn = sqlite3.connect(self.path, timeout=30.0, check_same_thread=False)
        try:
            row = conn.execute("SELECT rowid FROM jobs WHERE id = ? AND result IS NOT NULL",
                               (job_id,)).fetchone()
            if row is None:
                return
            with conn.blobopen("jobs", "result", row[0], readonly=True) as blob:
                while chunk := blob.read(CHUNK):
                    yield chunk
        finally:
            conn.close()

    def list(self, limit: int, offset: int, owner: str | None = None
             ) -> tuple[list[JobRow], int]:
        """A page of jobs (``owner``'s when given), newest first, without their results;
        and the total count."""
        db = self._conn()
        where, args = ("WHERE owner = ?", (owner,)) if owner is not None else ("", ())
        rows = db.execute(
            f"SELECT {_HEAD} FROM jobs {where} ORDER BY created_at DESC, rowid DESC "
            "LIMIT ? OFFSET ?", (*args, limit, offset)).fetchall()
        total = db.execute(f"SELECT COUNT(*) FROM jobs {where}", args).fetchone()[0]
        return [JobRow.of(r) for r in rows], int(total)

    def purge(self, retention_days: float, max_jobs: int, now: float | None = None) -> int:
        """Delete finished jobs older than ``retention_days`` (0: no age limit), then the
        oldest finished ones beyond ``max_jobs`` jobs in all; queued and running jobs are
        never purged. Returns how many were deleted."""
        now = time.time() if now is None else now
        deleted = 0
        with self._tx() as db:
            if retention_days > 0:
                deleted += db.execute(
                    "DELETE FROM jobs WHERE state NOT IN ('queued', 'running') AND "
                    "finished_at < ?", (now - retention_days * 86400.0,)).rowcount
            total = int(db.execute("SELECT COUNT(*) FROM jobs").fetchone()[0])
            if total > max_jobs:
                deleted += db.execute(
                    "DELETE FROM jobs WHERE id IN (SELECT id FROM jobs WHERE state NOT IN "
                    "('queued', 'running') ORDER BY finished_at, rowid LIMIT ?)",
                    (total - max_jobs,)).rowcount
            if deleted:  # a plan's simulation report goes with it, a batch with its jobs
                db.execute("DELETE FROM simulations WHERE job_id NOT IN (SELECT id FROM jobs)")
                db.execute("DELETE FROM batch_jobs WHERE job_id NOT IN (SELECT id FROM jobs)")
                db.execute("DELETE FROM batches WHERE id NOT IN "
                           "(SELECT batch_id FROM batch_jobs)")
        return int(deleted)

    # -- batches (docs/service.md, "Batches") ----------------------------------------------
    def create_batch(self, items: builtins.list[tuple[str, str, float, str]],
                     owner: str = "") -> tuple[str, builtins.list[str]]:
        """A batch of queued jobs of ``owner`` (``items``: each job's planner, request,
        time limit and structure key), all or none in one transaction: (its id, its jobs'
        ids in order)."""
        batch_id = uuid.uuid4().hex
        now = time.time()
        ids = [uuid.uuid4().hex for _ in items]
        with self._tx() as db:
            db.executemany(
                "INSERT INTO jobs (id, idempotency_key, request_hash, planner, request, "
                "time_limit, state, created_at, owner, structure) "
                "VALUES (?, NULL, ?, ?, ?, ?, 'queued', ?, ?, ?)",
                [(job_id, request_hash(request), planner, request, limit, now, owner, key)
                 for job_id, (planner, request, limit, key) in zip(ids, items, strict=True)])
            db.execute("INSERT INTO batches (id, owner, size, created_at) VALUES (?, ?, ?, ?)",
                       (batch_id, owner, len(items), now))
            db.executemany("INSERT INTO batch_jobs (batch_id, idx, job_id) VALUES (?, ?, ?)",
                           [(batch_id, i, job_id) for i, job_id in enumerate(ids)])
        return batch_id, ids

    def batch(self, batch_id: str, owner: str | None = None
              ) -> tuple[float, int, builtins.list[JobRow]] | None:
        """A batch (``owner``'s when given): its creation time, its size and its jobs
        still stored, in submission order, without their results; None: no such batch."""
        db = self._conn()
        row = db.execute("SELECT owner, size, created_at FROM batches WHERE id = ?",
                         (batch_id,)).fetchone()
        if row is None or (owner is not None and row["owner"] != owner):
            return None
        rows = db.execute(  # (no column of batch_jobs is named as one of jobs)
            f"SELECT {_HEAD} FROM batch_jobs JOIN jobs ON jobs.id = batch_jobs.job_id "
            "WHERE batch_jobs.batch_id = ? ORDER BY batch_jobs.idx", (batch_id,)).fetchall()
        return float(row["created_at"]), int(row["size"]), [JobRow.of(r) for r in rows]

    # -- simulation reports (docs/simulation.md) -------------------------------------------
    def put_simulation(self, job_id: str, report: str) -> None:
        """Store (or replace) a job's latest simulation report (JSON text)."""
        with self._tx() as db:
            db.execute("INSERT OR REPLACE INTO simulations (job_id, report, created_at) "
                       "VALUES (?, ?, ?)", (job_id, report, time.time()))

    def get_simulation(self, job_id: str) -> str | None:
        """A job's latest simulation report (JSON text; None: never simulated)."""
        row = self._conn().execute("SELECT report FROM simulations WHERE job_id = ?",
                                   (job_id,)).fetchone()
        return None if row is None else str(row["report"])

    def count(self, state: str) -> int:
        return int(self._conn().execute("SELECT COUNT(*) FROM jobs WHERE state = ?",
                                        (state,)).fetchone()[0])

    def claim_next(self, holds: Collection[str] = (), others: Collection[str] = ()
                   ) -> JobRow | None:
        """Move a queued job to running and return it (atomically): of the
        :data:`CLAIM_WINDOW` oldest, the oldest whose structure key is in ``holds`` (the
        claiming worker's cache holds its NLP), else the oldest whose structure no other
        worker holds (``others``: building it here spreads the structures), else the
        oldest."""
        with self._tx() as db:
            rows = db.execute("SELECT id, structure FROM jobs WHERE state = 'queued' "
                              "ORDER BY created_at, rowid LIMIT ?",
                              (CLAIM_WINDOW,)).fetchall()
            if not rows:
                return None
            pick = next((r for r in rows if r["structure"] and r["structure"] in holds),
                        None) or next((r for r in rows if r["structure"] not in others),
                                      rows[0])
            db.execute("UPDATE jobs SET state = 'running', started_at = ?, "
                       "attempts = attempts + 1 WHERE id = ?", (time.time(), pick["id"]))
            claimed = db.execute("SELECT * FROM jobs WHERE id = ?", (pick["id"],)).fetchone()
        return JobRow.of(claimed)

    def requeue(self, job_id: str) -> bool:
        """Put a running job back in the queue (its worker was lost under it); False if it
        is not running any more."""
        with self._tx() as db:
            cur = db.execute("UPDATE jobs SET state = 'queued', started_at = NULL, "
                             "worker_pid = NULL WHERE id = ? AND state = 'running'",
                             (job_id,))
            return cur.rowcount == 1

    def set_worker(self, job_id: str, pid: int) -> None:
        """Record the worker process running a job."""
        with self._tx() as db:
            db.execute("UPDATE jobs SET worker_pid = ? WHERE id = ?", (pid, job_id))

    def finish(self, job_id: str, state: str, code: str, message: str,
               raw_status: str | None = None, result: str | None = None,
               has_plan: bool | None = None) -> bool:
        """End an active job in ``state``; False if it had already ended."""
        with self._tx() as db:
            cur = db.execute(
                "UPDATE jobs SET state = ?, code = ?, message = ?, raw_status = ?, result = ?,"
                " finished_at = ?, has_plan = ? WHERE id = ? AND state IN "
                "('queued', 'running')",
                (state, code, message, raw_status, result, time.time(),
                 None if has_plan is None else int(has_plan), job_id))
            return cur.rowcount == 1

    def cancel_queued(self, job_id: str) -> bool:  # the owner is checked by the caller
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
