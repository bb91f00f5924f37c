"""Solver worker processes and the dispatcher that feeds them.

Each worker is a *spawned* process (no fork: CasADi/IPOPT state is never shared) that
keeps its planner, and so its cache of built NLPs, from job to job. The dispatcher is a
thread of the service process. It hands queued jobs from the store to idle workers, and
makes sure every job ends exactly once:

* a worker's reply ends its job with the plan's typed status;
* one deadline per job, from the moment a worker takes it: the worker's planner gets the
  time left (IPOPT's stop callback ends it at the deadline, with its last iterate); a job
  whose worker has not replied :data:`DEADLINE_MARGIN` past its deadline (still building
  its NLP, in a long first iteration, certifying) ends ``timed_out`` (``time_limit``)
  there, without a plan; its worker finishes what it was doing (an NLP it builds stays
  cached for the next job of that structure) and its late reply is dropped;
* a worker still busy ``kill_grace`` past the deadline is killed and replaced (the last
  resort: its NLP cache is lost); a replaced worker reports ready at once and builds its
  warm-up structures between jobs, never ahead of a queued one;
* a cancelled running job gets its worker killed and replaced, and ends ``cancelled``;
* a worker that dies mid-solve ends its job ``failed`` with the exit code, and is replaced.

The store's faults are states, not crashes (docs/service.md, "Storage faults"): a job
whose result would not fit on the store's disk ends ``failed`` (``storage_error``)
without it; a result the store refuses to write (disk full, read-only) is dropped and the
job ends ``failed`` (``storage_error``) with SQLite's reason; while the store cannot be
written at all, no job is handed out, the ends that could not be written are kept and
written when it can, and the store is probed every :data:`PROBE_INTERVAL` so that the
dispatcher resumes by itself once space returns. An unexpected error in a step is logged
and the next step runs: the dispatcher never stops before the service does.
"""

from __future__ import annotations

import contextlib
import logging
import multiprocessing as mp
import os
import queue
import sqlite3
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from multiprocessing.connection import Connection, wait
from pathlib import Path
from typing import Any

from dexroll_client.models import JobState, PlanStatus

from .store import JobRow, StorageError, Store

__all__ = ["DEADLINE_MARGIN", "Dispatcher", "job_outcome"]

#: How long past its deadline a job waits for its worker's own time-limit reply (IPOPT's
#: last iterate) before the dispatcher ends it without a plan [s].
DEADLINE_MARGIN = 0.3
#: The worker's planner is given the time left minus this much, for the reply to travel [s].
_REPLY_TIME = 0.05
#: How often a faulted store is probed for a write [s].
PROBE_INTERVAL = 1.0

log = logging.getLogger("dexroll.workers")


def job_outcome(status: PlanStatus) -> JobState:
    """The terminal job state for a plan's status."""
    return {
        PlanStatus.SOLVED: JobState.SUCCEEDED,
        PlanStatus.INFEASIBLE: JobState.INFEASIBLE,
        PlanStatus.TIME_LIMIT: JobState.TIMED_OUT,
    }.get(status, JobState.FAILED)


def _worker_main(conn: Connection, warmup: str = "", compile_dir: str | None = None,
                 parent: int | None = None, background_warmup: bool = False,
                 max_result_bytes: int = 1 << 62) -> None:
    """Body of a worker process: plan each request received, reply with the result.

    The process keeps one planner per kind, and so their caches of built NLPs, from job to
    job: the ball-on-palm planner, and the finger planners (one-finger and manipulation,
    one NLP cache) with the finger models and hands they were built for (``FingerCache``).
    Before it reports ready it builds the NLPs of the warm-up requests (``warmup``: files
    or folders, see :mod:`planner_service.warmup`); with ``background_warmup`` (a
    replacement worker) it reports ready first and builds them one at a time while no job
    is waiting. It dies with the service (``parent``: see :mod:`.lifeline`).

    A job comes as (id, request JSON, deadline on the monotonic clock); the reply is
    ("done", (id, job state, code, message, raw status, result JSON or None, whether the
    result holds a plan to view)); between jobs "ready" and "warming" say whether it
    takes one."""
    from .lifeline import die_with_parent

    die_with_parent(parent)
    # Imports happen in the child: the parent's modules are not inherited under spawn.
    from ..planners import (
        REQUEST,
        BallOnPalmPlanner,
        FingerCache,
        ProblemError,
        error_result,
        invalid_result,
        solve,
    )
    from ..view import has_plan

    if not logging.getLogger().handlers:  # spawned: the service's logging is not inherited
        logging.basicConfig(level=logging.INFO,
                            format="%(asctime)s %(levelname)s [worker %(process)d] %(name)s: "
                                   "%(message)s")
    compiled = None if compile_dir is None else Path(compile_dir)
    # The finger NLPs compile in the background (a few seconds of gcc each, the virtual
    # machine solving meanwhile); the ball-on-palm NLP is not compiled here: it is written
    # out in SX, its compile takes tens of seconds in the foreground, and since the
    # closed-form geometry its function evaluations are a small part of its solve.
    palm = BallOnPalmPlanner()
    fingers = FingerCache(compile_dir=compiled, background=True)
    pending: list[Path] = []
    if warmup:
        from ..warmup import request_files, warm_up

        pending = request_files(warmup)
        if not background_warmup:
            t0 = time.perf_counter()
            built = warm_up(pending, palm, fingers)
            pending = []
            log.info("warm-up: %d structures built in %.1f s (%s)", len(built),
                     time.perf_counter() - t0, ", ".join(f"{n} {t:.2f} s" for n, t in built))
    conn.send(("ready", None))
    built_between: list[tuple[str, float]] = []
    while True:
        if pending and not conn.poll(0):  # no job waiting: build one warm-up structure
            conn.send(("warming", None))  # the dispatcher gives jobs to other workers
            if not conn.poll(0):
                built_between += warm_up([pending.pop(0)], palm, fingers)
                if not pending:
                    log.info("warm-up: %d structures built between jobs (%s)",
                             len(built_between),
                             ", ".join(f"{n} {t:.2f} s" for n, t in built_between))
            conn.send(("ready", None))
            continue
        try:
            msg = conn.recv()
        except (EOFError, KeyboardInterrupt):
            return
        if msg is None:
            return
        job_id, request_json, deadline = msg
        planner = "ball_on_palm"
        try:
            request = REQUEST.validate_json(request_json)
            planner = request.planner
            # the time left of the job's one deadline (it started when the dispatcher
            # handed the job over), for the planner's own (build, guesses, IPOPT, ...)
            left = deadline - time.monotonic() - _REPLY_TIME
            request = request.model_copy(update={"solver": request.solver.model_copy(
                update={"time_limit": max(left, 1e-3)})})
            result, _ = solve(request, palm, fingers)
        except ProblemError as exc:  # checked at submission; the store may be older
            result = invalid_result(exc.errors, planner)
        except Exception as exc:  # reply with a typed error, never die on a bad job
            log.exception("job %s failed in the worker", job_id)
            result = error_result(f"planner failed: {exc!r}", planner)
        result_json = result.model_dump_json()
        raw = result.stats.raw_status if result.stats else None
        state = job_outcome(result.status).value
        if len(result_json) > max_result_bytes:
            conn.send(("done", (job_id, JobState.FAILED.value, "result_too_large",
                                f"the plan ended {result.status.value}, but its JSON is "
                                f"{len(result_json)} bytes, over the service's limit of "
                                f"{max_result_bytes} (DEXROLL_MAX_RESULT_BYTES): ask for "
                                "fewer intervals or sample times", raw, None, False)))
            continue
        conn.send(("done", (job_id, state, result.status.value, result.message, raw,
                            result_json, has_plan(result))))


@dataclass(eq=False)
class _Slot:
    process: Any  # multiprocessing SpawnProcess
    conn: Connection
    ready: bool = False
    job: JobRow | None = None
    #: the job's deadline and the kill deadline (+ kill_grace), on the monotonic clock
    job_deadline: float = float("inf")
    deadline: float = float("inf")
    #: the job ended at its deadline; the worker has not replied yet
    draining: bool = False
    #: the worker is building a warm-up structure (ready, but not taking jobs)
    warming: bool = False
    started: float = field(default_factory=time.monotonic)


class Dispatcher(threading.Thread):
    """Feeds queued jobs to ``n_workers`` worker processes and ends every job once."""

    def __init__(self, store: Store, n_workers: int, kill_grace: float,
                 on_finish: Callable[[str], None], warmup: str = "",
                 compile_dir: str | None = None, max_result_bytes: int = 1 << 62,
                 warmup_first: bool = False) -> None:
        super().__init__(name="dexroll-dispatcher", daemon=True)
        self.store = store
        self.n_workers = n_workers
        self.kill_grace = kill_grace
        self.on_finish = on_finish
        self.warmup = warmup
        self.compile_dir = compile_dir
        self.max_result_bytes = max_result_bytes
        #: workers build their warm-up NLPs before they report ready (else between jobs)
        self.warmup_first = warmup_first
        #: called every minute or so from the dispatcher thread (the store's retention)
        self.housekeeping: Callable[[], None] | None = None
        self._housekept = 0.0
        self._ctx = mp.get_context("spawn")
        self._slots: list[_Slot] = []
        self._cancel: queue.SimpleQueue[str] = queue.SimpleQueue()
        self._wake_r, self._wake_w = self._ctx.Pipe(duplex=False)
        self._wake_lock = threading.Lock()
        self._stopping = threading.Event()
        #: job ends the store could not write yet (job id -> the end's fields), written
        #: once it can be written again
        self._unwritten: dict[str, tuple[Any, ...]] = {}
        self._probed = 0.0
        #: the last unexpected error of a step (None: the last step went through)
        self.last_error: str | None = None

    # -- called from other threads -----------------------------------------------------------
    def wake(self) -> None:
        """New work (a job or a cancellation) is waiting."""
        with self._wake_lock:
            self._wake_w.send(None)

    def cancel_running(self, job_id: str) -> None:
        self._cancel.put(job_id)
        self.wake()

    def stop(self) -> None:
        self._stopping.set()
        self.wake()
        self.join(timeout=10)

    @property
    def ready_workers(self) -> int:
        return sum(1 for s in self._slots if s.ready and s.process.is_alive())

    # -- the dispatcher thread -----------------------------------------------------------------
    def _spawn(self, replacement: bool = False) -> _Slot:
        # One BLAS/OpenMP thread per worker: the workers are the parallelism (one per core
        # by default), and a plan's last digits then do not depend on the machine's thread
        # count (docs/benchmarks.md). Set before the child starts: spawned children inherit
        # the environment and load their numeric libraries while importing.
        for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
            os.environ.setdefault(var, "1")
        parent, child = self._ctx.Pipe()
        proc = self._ctx.Process(target=_worker_main, name="dexroll-worker", daemon=True,
                                 args=(child, self.warmup, self.compile_dir, os.getpid(),
                                       replacement, self.max_result_bytes))
        proc.start()
        child.close()
        return _Slot(process=proc, conn=parent)

    def _replace(self, slot: _Slot) -> None:
        if slot.process.is_alive():
            slot.process.kill()
        slot.process.join(timeout=5)
        slot.conn.close()
        self._slots[self._slots.index(slot)] = self._spawn(replacement=True)

    def _end(self, job_id: str, state: JobState, code: str, message: str,
             raw_status: str | None = None, result: str | None = None,
             has_plan: bool | None = None) -> None:
        """End a job in the store and tell its waiters. A result that would not fit on the
        store's disk, or that the store refuses, is dropped: the job ends ``failed``
        (``storage_error``) with the reason; an end the store cannot write at all is kept
        for :meth:`_flush`."""
        if result is not None:
            reason = self.store.room_for(len(result))
            if reason is None:
                try:
                    self._finish(job_id, state.value, code, message, raw_status, result,
                                 has_plan)
                    return
                except StorageError as exc:
                    reason = f"the job store could not store its plan: {exc}"
            log.warning("job %s: %s", job_id, reason)
            message = f"the plan ended {code}, but it was not stored: {reason}"
            state, code, result, has_plan = JobState.FAILED, "storage_error", None, False
        try:
            self._finish(job_id, state.value, code, message, raw_status, result, has_plan)
        except sqlite3.OperationalError as exc:
            log.warning("job %s: its end (%s) cannot be written yet (%s); kept until the "
                        "store can be written", job_id, code, exc)
            self._unwritten[job_id] = (state.value, code, message, raw_status, result,
                                       has_plan)

    def _finish(self, job_id: str, *end: Any) -> None:
        if self.store.finish(job_id, *end):
            log.info("job %s ended %s (%s)", job_id, end[0], end[1])
        self.on_finish(job_id)

    def _flush(self) -> None:
        """Write the job ends kept while the store could not be written."""
        for job_id, end in list(self._unwritten.items()):
            try:
                self._finish(job_id, *end)
            except sqlite3.OperationalError:
                return
            del self._unwritten[job_id]

    def _store_writable(self) -> bool:
        """Whether jobs may be handed out: the store is not faulted, or a probe (at most
        every PROBE_INTERVAL) found it writable again; then the kept ends are written."""
        if self.store.fault is not None or self._unwritten:
            now = time.monotonic()
            if now - self._probed < PROBE_INTERVAL:
                return False
            self._probed = now
            if not self.store.probe():
                return False
            log.info("the job store can be written again")
            self._flush()
        return self.store.fault is None and not self._unwritten

    def run(self) -> None:
        self._slots = [self._spawn(replacement=not self.warmup_first)
                       for _ in range(self.n_workers)]
        try:
            while not self._stopping.is_set():
                try:
                    self._step()
                    self.last_error = None
                except Exception as exc:  # logged; the next step runs (never stop here)
                    log.exception("dispatcher step failed; going on")
                    self.last_error = f"{type(exc).__name__}: {exc}"
                    self._stopping.wait(PROBE_INTERVAL)
        finally:
            for slot in self._slots:
                with contextlib.suppress(OSError, BrokenPipeError):
                    slot.conn.send(None)
            for slot in self._slots:
                slot.process.join(timeout=2)
                if slot.process.is_alive():
                    slot.process.kill()

    def _step(self) -> None:
        # hand queued jobs to idle, ready workers (none while the store cannot be written)
        writable = self._store_writable()
        for slot in self._slots:
            if writable and slot.ready and not slot.warming and slot.job is None:
                try:
                    job = self.store.claim_next()
                except sqlite3.OperationalError as exc:
                    log.warning("no job handed out: the job store cannot be written (%s)",
                                exc)
                    break
                if job is None:
                    break
                slot.job, slot.draining = job, False
                with contextlib.suppress(sqlite3.OperationalError):  # the pid is a hint
                    self.store.set_worker(job.id, slot.process.pid)
                slot.started = time.monotonic()
                slot.job_deadline = slot.started + job.time_limit
                slot.deadline = slot.job_deadline + self.kill_grace
                # if the worker died, its sentinel reports it below
                with contextlib.suppress(OSError, BrokenPipeError):
                    slot.conn.send((job.id, job.request, slot.job_deadline))
        waitables: list[Any] = [self._wake_r]
        for slot in self._slots:
            waitables += [slot.conn, slot.process.sentinel]
        now = time.monotonic()
        timeout = min([0.5 if writable else PROBE_INTERVAL]
                      + [max(0.0, (s.deadline if s.draining else
                                   s.job_deadline + DEADLINE_MARGIN) - now)
                         for s in self._slots if s.job])
        ready = wait(waitables, timeout=timeout)
        if self._wake_r in ready:
            while self._wake_r.poll():
                self._wake_r.recv()
        for slot in list(self._slots):
            if slot.conn in ready:
                self._receive(slot)
        for slot in list(self._slots):
            if not slot.process.is_alive():
                self._died(slot)
        self._cancels()
        self._deadlines()
        if self.housekeeping is not None and now - self._housekept > 60.0:
            self._housekept = now
            try:
                self.housekeeping()
            except Exception:  # housekeeping never stops the dispatcher
                log.exception("housekeeping failed")

    def _receive(self, slot: _Slot) -> None:
        try:
            kind, payload = slot.conn.recv()
        except (EOFError, OSError):
            return  # the process is gone; handled by _died
        if kind in ("ready", "warming"):
            slot.ready, slot.warming = True, kind == "warming"
            return
        # the worker's verdict as it is: its result is stored, never parsed here
        job_id, state, code, message, raw, result_json, plan = payload
        draining = slot.draining
        slot.job, slot.deadline, slot.draining = None, float("inf"), False
        slot.job_deadline = float("inf")
        if draining:  # the job already ended at its deadline
            log.info("job %s: its worker replied %s after the job ended at its deadline",
                     job_id, code)
            return
        self._end(job_id, JobState(state), code, message, raw, result_json, plan)

    def _died(self, slot: _Slot) -> None:
        code = slot.process.exitcode
        if slot.job is not None and not slot.draining:
            self._end(slot.job.id, JobState.FAILED, "worker_died",
                      f"the worker process (pid {slot.process.pid}) died during the solve "
                      f"(exit code {code}); the service replaced it")
        else:
            log.warning("idle worker %s exited with code %s; replacing it",
                        slot.process.pid, code)
        self._replace(slot)

    def _cancels(self) -> None:
        while True:
            try:
                job_id = self._cancel.get_nowait()
            except queue.Empty:
                return
            for slot in self._slots:
                if slot.job is not None and slot.job.id == job_id and not slot.draining:
                    self._end(job_id, JobState.CANCELLED, "cancelled",
                              "cancelled while running; its worker was stopped and replaced")
                    self._replace(slot)
                    break
            else:
                self.on_finish(job_id)

    def _deadlines(self) -> None:
        now = time.monotonic()
        for slot in list(self._slots):
            job = slot.job
            if job is None:
                continue
            if not slot.draining and now > slot.job_deadline + DEADLINE_MARGIN:
                # the job's time is up; its worker finishes (and caches) what it was doing
                slot.draining = True
                self._end(job.id, JobState.TIMED_OUT, "time_limit",
                          f"the time limit {job.time_limit:g} s was reached before the "
                          "planner had an iterate to return (building its NLP, in a first "
                          "iteration or certifying); no plan")
            if now > slot.deadline:
                log.warning("job %s: its worker was still busy %g s past the time limit; "
                            "killed and replaced", job.id, self.kill_grace)
                self._end(job.id, JobState.TIMED_OUT, "killed_at_time_limit",
                          f"the solve did not return within its time limit "
                          f"{job.time_limit} s (+{self.kill_grace} s grace); its worker "
                          "was killed and replaced")
                self._replace(slot)
