"""The dispatcher: it hands the store's queued jobs to solver workers and ends every job once.

The workers run where the service's executor puts them (:mod:`planner_service.executors`:
spawned local processes by default, or actors on a Ray cluster); each keeps its planners,
and so its cache of built NLPs, from job to job (:class:`.solver.SolverWorker`). The
dispatcher is a thread of the service process that reacts to events (a worker's reply, a
worker lost, a submission, a cancellation) and makes sure every job ends exactly once:

* a worker's reply ends its job with the plan's typed status;
* one deadline per job, from the moment a worker takes it: the worker's planner gets the
  time left (IPOPT's stop callback ends it at the deadline, with its last iterate); a job
  whose worker has not replied :data:`DEADLINE_MARGIN` past its deadline (still building
  its NLP, in a long first iteration, certifying) ends ``timed_out`` (``time_limit``)
  there, without a plan; its worker finishes what it was doing (an NLP it builds stays
  cached for the next job of that structure) and its late reply is dropped;
* a worker still busy ``kill_grace`` past the deadline is killed and replaced (the last
  resort: its NLP cache is lost);
* a cancelled running job gets its worker killed and replaced, and ends ``cancelled``;
* a worker lost under a job (its process died, its node or the cluster went away) puts the
  job back in the queue once (``retries``), and the job ends ``failed`` (``worker_died``,
  naming where it ran and how it died) when it is lost again; the worker is replaced (a
  worker that was lost before it ever became ready is replaced after a back-off, so that
  an unreachable cluster is not asked again many times a second).

Jobs go to workers by structure (:func:`planner_service.planners.structure.structure_key`,
stored with each job): an idle worker takes the oldest queued job whose NLP it holds, else
one whose structure no other worker holds, else the oldest (:meth:`.store.Store.claim_next`);
the workers' cache hits are counted (:attr:`Dispatcher.cache`). A worker is ready once it
has imported the planners; it builds the warm-up requests' NLPs one at a time while no job
is queued (``warmup_first``: before it reports ready).

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
import queue
import sqlite3
import threading
import time
from collections import deque
from collections.abc import Callable
from concurrent.futures import Future
from dataclasses import dataclass, field
from typing import Any

from dexroll_client.models import JobState

from ..executors import Executor, Resources, Worker, WorkerError, WorkerLostError
from .solver import SolverWorker, job_outcome
from .store import JobRow, StorageError, Store

__all__ = ["DEADLINE_MARGIN", "Dispatcher", "job_outcome"]

#: How long past its deadline a job waits for its worker's own time-limit reply (IPOPT's
#: last iterate) before the dispatcher ends it without a plan [s].
DEADLINE_MARGIN = 0.3
#: How often a faulted store is probed for a write [s].
PROBE_INTERVAL = 1.0
#: Back-off before a worker lost before it became ready is started again: doubled at each
#: such loss in a row, from this, up to :data:`MAX_BACKOFF` [s].
BACKOFF = 1.0
MAX_BACKOFF = 30.0

log = logging.getLogger("dexroll.workers")


@dataclass(eq=False)
class _Slot:
    """One worker's place in the pool and what the dispatcher knows of it."""

    worker: Worker | None  # None: waiting to be started at ``start_at``
    start_at: float = 0.0
    ready: bool = False
    #: a call (ready, warm or solve) is outstanding
    busy: bool = False
    lost: bool = False
    job: JobRow | None = None
    #: the job's deadline and the kill deadline (+ kill_grace), on the monotonic clock
    job_deadline: float = float("inf")
    deadline: float = float("inf")
    #: the job ended at its deadline; the worker has not replied yet
    draining: bool = False
    #: structure keys whose NLPs the worker holds (built or used)
    holds: set[str] = field(default_factory=set)
    #: warm-up requests left to build: (file name, JSON text, structure key)
    warmup: list[tuple[str, str, str]] = field(default_factory=list)
    #: warm-up requests built: (file name, build time [s])
    built: list[tuple[str, float]] = field(default_factory=list)
    pid: int | None = None
    #: the warm-up request being built
    warming: str = ""
    #: losses before ready in a row (the back-off's exponent)
    failures: int = 0
    started: float = field(default_factory=time.monotonic)


def warmup_requests(spec: str) -> list[tuple[str, str, str]]:
    """The warm-up requests of ``spec`` (DEXROLL_WARMUP): (file name, JSON text, structure
    key), read here so that workers on other machines are sent the text."""
    import json

    from ..planners.structure import structure_key
    from ..warmup import request_files

    out = []
    for path in request_files(spec):
        try:
            text = path.read_text(encoding="utf-8")
            body = json.loads(text)
            key = structure_key(str(body.get("planner", "ball_on_palm")), body)
        except (OSError, ValueError, AttributeError) as exc:
            log.warning("warm-up: %s skipped: %s", path, exc)
            continue
        out.append((path.name, text, key))
    return out


def _failed(exc: BaseException) -> Future[Any]:
    future: Future[Any] = Future()
    future.set_exception(exc)
    return future


class Dispatcher(threading.Thread):
    """Feeds queued jobs to ``n_workers`` solver workers started by ``executor`` and ends
    every job once."""

    def __init__(self, store: Store, n_workers: int, kill_grace: float,
                 on_finish: Callable[[str], None], warmup: str = "",
                 compile_dir: str | None = None, max_result_bytes: int = 1 << 62,
                 warmup_first: bool = False, executor: Executor | None = None,
                 retries: int = 1) -> None:
        super().__init__(name="dexroll-dispatcher", daemon=True)
        #: the executor is closed with the dispatcher only when it made its own
        self._owns_executor = executor is None
        if executor is None:
            from ..executors.local import LocalProcesses

            executor = LocalProcesses()
        self.store = store
        self.executor = executor
        self.n_workers = n_workers
        self.kill_grace = kill_grace
        self.on_finish = on_finish
        self.warmup = warmup
        self.compile_dir = compile_dir
        self.max_result_bytes = max_result_bytes
        #: workers build their warm-up NLPs before they report ready (else between jobs)
        self.warmup_first = warmup_first
        #: times a job is put back in the queue when its worker is lost under it
        self.retries = retries
        #: called every minute or so from the dispatcher thread (the store's retention)
        self.housekeeping: Callable[[], None] | None = None
        self._housekept = 0.0
        self._slots: list[_Slot] = []
        self._warmup: list[tuple[str, str, str]] = []
        self._events: queue.SimpleQueue[tuple[_Slot, str, Future[Any]] | None] = \
            queue.SimpleQueue()
        self._cancel: queue.SimpleQueue[str] = queue.SimpleQueue()
        self._stopping = threading.Event()
        #: job ends the store could not write yet (job id -> the end's fields), written
        #: once it can be written again
        self._unwritten: dict[str, tuple[Any, ...]] = {}
        self._probed = 0.0
        #: the last unexpected error of a step (None: the last step went through)
        self.last_error: str | None = None
        #: jobs whose NLP came from their worker's cache, and those that built it
        self.cache = {"hits": 0, "misses": 0}
        #: jobs put back in the queue after their worker was lost
        self.requeued = 0
        #: the last jobs' dispatch overheads: the time from handing a job over to its
        #: verdict back, less the worker's own time on it [s]
        self._overheads: deque[float] = deque(maxlen=1000)

    # -- called from other threads -----------------------------------------------------------
    def wake(self) -> None:
        """New work (a job or a cancellation) is waiting."""
        self._events.put(None)

    def cancel_running(self, job_id: str) -> None:
        self._cancel.put(job_id)
        self.wake()

    def stop(self) -> None:
        self._stopping.set()
        self.wake()
        self.join(timeout=10)

    @property
    def ready_workers(self) -> int:
        return sum(1 for s in list(self._slots) if s.ready and not s.lost)

    def dispatch(self) -> dict[str, float | int]:
        """The last jobs' dispatch overheads (median and 99th percentile [ms], count)."""
        values = sorted(self._overheads)
        if not values:
            return {"jobs": 0}
        return {"jobs": len(values), "median_ms": 1e3 * values[len(values) // 2],
                "p99_ms": 1e3 * values[min(len(values) - 1, int(0.99 * len(values)))]}

    def unavailable(self) -> str | None:
        """Why new jobs cannot be run now (the executor's reason, when no worker is
        ready); None: they can."""
        reason = self.executor.unavailable()
        return None if reason is None or self.ready_workers else reason

    # -- the dispatcher thread -----------------------------------------------------------------
    def _start(self, slot: _Slot) -> None:
        """Start ``slot``'s worker and ask it whether it is up."""
        slot.worker = self.executor.start(
            SolverWorker, (self.compile_dir, self.max_result_bytes), Resources(cpus=1.0),
            "worker")
        slot.started = time.monotonic()
        slot.worker.when_lost(lambda lost: self._events.put((slot, "lost", _failed(lost))))
        self._call(slot, "ready")

    def _call(self, slot: _Slot, method: str, *args: Any) -> None:
        assert slot.worker is not None
        slot.busy = True
        future = slot.worker.call(method, *args)
        future.add_done_callback(lambda f: self._events.put((slot, method, f)))

    def _new_slot(self, failures: int = 0) -> _Slot:
        slot = _Slot(worker=None, warmup=list(self._warmup), failures=failures)
        if failures:
            slot.start_at = time.monotonic() + min(MAX_BACKOFF, BACKOFF * 2 ** (failures - 1))
        else:
            self._start(slot)
        return slot

    def _replace(self, slot: _Slot) -> None:
        """Kill ``slot``'s worker and put a new one in its place (its late events are
        ignored: they name a slot no longer in the pool)."""
        slot.lost = True
        if slot.worker is not None:
            slot.worker.kill()
        failures = 0 if slot.ready else slot.failures + 1
        self._slots[self._slots.index(slot)] = self._new_slot(failures)

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
        if self.warmup:
            self._warmup = warmup_requests(self.warmup)
        self._slots = [self._new_slot() for _ in range(self.n_workers)]
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
                if slot.worker is not None:
                    slot.worker.kill()
            if self._owns_executor:
                self.executor.close()

    def _step(self) -> None:
        now = time.monotonic()
        for slot in self._slots:  # workers whose back-off is over
            if slot.worker is None and now >= slot.start_at:
                self._start(slot)
        # hand queued jobs to idle, ready workers (none while the store cannot be written)
        writable = self._store_writable()
        queue_empty = False
        for slot in self._slots:
            if not (slot.ready and not slot.busy and slot.job is None):
                continue
            if writable and not queue_empty:
                others = set().union(*(s.holds for s in self._slots if s is not slot))
                try:
                    job = self.store.claim_next(slot.holds, others)
                except sqlite3.OperationalError as exc:
                    log.warning("no job handed out: the job store cannot be written (%s)",
                                exc)
                    writable = False
                    continue
                if job is not None:
                    self._hand(slot, job)
                    continue
                queue_empty = True
            if queue_empty and slot.warmup:  # nothing waits: build a warm-up structure
                self._warm_next(slot)
        timeout = min([0.5 if writable else PROBE_INTERVAL]
                      + [max(0.0, (s.deadline if s.draining else
                                   s.job_deadline + DEADLINE_MARGIN) - now)
                         for s in self._slots if s.job]
                      + [max(0.0, s.start_at - now) for s in self._slots if s.worker is None])
        try:
            event = self._events.get(timeout=timeout)
        except queue.Empty:
            event = None
        while True:
            if event is not None:
                slot, method, future = event
                if slot in self._slots and not slot.lost:
                    self._reply(slot, method, future)
            try:
                event = self._events.get_nowait()
            except queue.Empty:
                break
        self._cancels()
        self._deadlines()
        if self.housekeeping is not None and now - self._housekept > 60.0:
            self._housekept = now
            try:
                self.housekeeping()
            except Exception:  # housekeeping never stops the dispatcher
                log.exception("housekeeping failed")

    def _hand(self, slot: _Slot, job: JobRow) -> None:
        """Give ``job`` (claimed) to ``slot``'s idle worker, its one deadline starting now."""
        slot.job, slot.draining = job, False
        if slot.pid is not None:
            with contextlib.suppress(sqlite3.OperationalError):  # the pid is a hint
                self.store.set_worker(job.id, slot.pid)
        slot.started = time.monotonic()
        slot.job_deadline = slot.started + job.time_limit
        slot.deadline = slot.job_deadline + self.kill_grace
        self._call(slot, "solve", job.id, job.request, job.time_limit)

    def _reply(self, slot: _Slot, method: str, future: Future[Any]) -> None:
        """A call of ``slot``'s worker ended (or, ``lost``, the worker did)."""
        if method != "lost":
            slot.busy = False
        try:
            value = future.result()
        except WorkerLostError as exc:
            self._lost(slot, exc)
            return
        except WorkerError as exc:  # the body's own failure: the worker lives on
            log.error("worker %s: %s failed: %s", slot.pid, method, exc)
            value = None
            if method == "ready":  # it cannot work: replaced after a back-off
                self._lost(slot, WorkerLostError(str(exc)))
                return
            if method == "solve" and slot.job is not None:
                value = (JobState.FAILED.value, "error", f"the worker failed: {exc}", None,
                         None, False, None, None)
        if method == "solve":
            self._solved(slot, value)
            return
        if method == "ready":
            slot.pid = int(value["pid"]) if isinstance(value, dict) else None
            slot.failures = 0
            log.info("solver worker ready: %s (%s)", slot.worker and slot.worker.where(),
                     value.get("host") if isinstance(value, dict) else "?")
            slot.started = time.monotonic()
        elif method == "warm":
            if value is not None:
                slot.built.append((slot.warming, float(value)))
            if not slot.warmup:
                log.info("warm-up: %d structures built %s (%s)", len(slot.built),
                         "between jobs" if slot.ready else
                         f"in {time.monotonic() - slot.started:.1f} s",
                         ", ".join(f"{n} {t:.2f} s" for n, t in slot.built))
        # up, or one more warm-up structure built: the next one first, or jobs
        if self.warmup_first and slot.warmup:
            self._warm_next(slot)
        else:
            slot.ready = True

    def _warm_next(self, slot: _Slot) -> None:
        """Have ``slot``'s worker build its next warm-up structure."""
        name, text, key = slot.warmup.pop(0)
        slot.holds.add(key)
        slot.warming = name
        self._call(slot, "warm", name, text)

    def _solved(self, slot: _Slot, verdict: Any) -> None:
        job, draining = slot.job, slot.draining
        slot.job, slot.deadline, slot.draining = None, float("inf"), False
        slot.job_deadline = float("inf")
        if job is None or verdict is None:
            return
        state, code, message, raw, result_json, plan, hit, inside = verdict
        if inside is not None:  # the round trip's time outside the worker's solve
            self._overheads.append(time.monotonic() - slot.started - float(inside))
        if job.structure:
            slot.holds.add(job.structure)
        if hit is not None:
            self.cache["hits" if hit else "misses"] += 1
        if draining:  # the job already ended at its deadline
            log.info("job %s: its worker replied %s after the job ended at its deadline",
                     job.id, code)
            return
        # the worker's verdict as it is: its result is stored, never parsed here
        self._end(job.id, JobState(state), code, message, raw, result_json, plan)

    def _lost(self, slot: _Slot, exc: WorkerLostError) -> None:
        """``slot``'s worker is gone: its job is put back once, or failed; it is replaced."""
        job = slot.job
        where = slot.worker.where() if slot.worker is not None else "?"
        if job is not None and not slot.draining:
            if job.attempts <= self.retries and self._requeue(job):
                log.warning("job %s: its worker (%s) was lost (%s); queued again",
                            job.id, where, exc.reason)
            else:
                self._end(job.id, JobState.FAILED, "worker_died",
                          f"the worker ({where}) was lost during the solve: {exc.reason}; "
                          f"the service replaced it (attempt {job.attempts}, "
                          f"{self.retries} retry after a lost worker)")
        elif slot.ready:
            log.warning("idle worker %s lost (%s); replacing it", where, exc.reason)
        else:
            log.warning("worker %s could not start (%s); trying again", where, exc.reason)
        self._replace(slot)

    def _requeue(self, job: JobRow) -> bool:
        try:
            done = self.store.requeue(job.id)
        except sqlite3.OperationalError:
            return False
        if done:
            self.requeued += 1
        return done

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
