"""Simulations as jobs of a small pool of processes of their own, never in the API process
(issue 25, part 2; docs/simulation.md, "Where simulations run"). It lives with the
jobs: a run is a job of its own kind, only not stored (its report is).

A simulation costs what its options ask: a 20 s plan at ``timestep`` 1e-5 is two million
MuJoCo steps, over a minute of a core. Run in the API process (as it was), such runs queued
behind one lock, each waiting request held an API thread, and each went on after its
client had left. Here each :class:`SimulationPool` slot is a thread of the service that owns
one worker (:class:`SimulationWorker`, started by the service's executor: a spawned local
process, or a Ray actor; MuJoCo and the planners' models imported once, kept from run to
run) and runs one simulation at a time on it:

* at most ``max_queue`` simulations wait for a slot; beyond, :meth:`SimulationPool.submit`
  refuses (:class:`SimulationRefusedError`, a 503 with ``Retry-After``);
* each run has a wall-clock deadline (``time_limit``) and a CPU budget (``cpu_seconds``,
  the process's ``RLIMIT_CPU`` raised to its CPU time so far plus the budget before each
  run: the kernel stops a run past it with SIGXCPU); past either, the worker is killed and
  replaced, and the run refused with the reason (on Ray, whose actors' exit codes do not
  reach the service, a run stopped by its CPU budget reads ``simulation_failed`` naming the
  actor's death);
* a run nobody waits for any more (:meth:`SimulationPool.cancel`: its client left) is
  dropped from the queue, or its process killed and replaced.
"""

from __future__ import annotations

import contextlib
import logging
import math
import queue
import signal
import threading
import time
from concurrent.futures import Future, InvalidStateError
from dataclasses import dataclass, field
from typing import Any

from ..executors import Executor, Resources, Worker, WorkerError, WorkerLostError

__all__ = ["SimulationPool", "SimulationRefusedError", "SimulationTask"]

log = logging.getLogger("dexroll.simulations")

#: Time a new simulation process may take to import MuJoCo and the planners [s].
START_TIMEOUT = 120.0


class SimulationRefusedError(Exception):
    """A simulation not run, or not to the end: ``status`` and ``error`` as the API answers
    (503 busy or past its limits, 409 not executable, 422 an option refused), and
    ``retry_after`` [s] when a retry may succeed."""

    def __init__(self, status: int, error: str, message: str,
                 retry_after: int | None = None, lost: bool = False) -> None:
        super().__init__(message)
        self.status, self.error, self.message = status, error, message
        self.retry_after = retry_after
        #: the worker was killed or died: the slot starts a new one
        self.lost = lost


@dataclass(eq=False)
class SimulationTask:
    """One simulation: the job's result and request (JSON, as stored), the simulator's
    options, and its outcome (the report's dict, or :class:`SimulationRefusedError`)."""

    result_json: str
    request_json: str
    options: dict[str, Any]
    future: Future[dict[str, Any]] = field(default_factory=Future)
    cancelled: threading.Event = field(default_factory=threading.Event)


class SimulationWorker:
    """A simulation worker's body: execute each (result, request, options) it is given in
    MuJoCo, under a CPU budget per run (``RLIMIT_CPU`` raised to the process's CPU time so
    far plus ``cpu_seconds`` before each run: the kernel stops a run past it)."""

    def __init__(self, cpu_seconds: float) -> None:
        self.cpu_seconds = cpu_seconds
        self.missing: str | None = None
        try:
            import sim  # noqa: F401  (MuJoCo: the sim extra)

            from .. import execution  # noqa: F401
        except ImportError as exc:
            self.missing = f"MuJoCo is not installed: {exc}"

    def ready(self) -> str | None:
        """None when simulations can run here, else why not."""
        return self.missing

    def run(self, result_json: str, request_json: str, options: dict[str, Any]
            ) -> tuple[str, Any]:
        """One simulation: ("ok", report dict) or (error, message)."""
        import resource

        from sim import SimOptions, simulate

        from ..execution import NotExecutableError, execution_plan
        from ..planners import REQUEST, RESULT, ProblemError

        usage = resource.getrusage(resource.RUSAGE_SELF)
        soft = math.ceil(usage.ru_utime + usage.ru_stime + self.cpu_seconds)
        _, hard = resource.getrlimit(resource.RLIMIT_CPU)
        with contextlib.suppress(ValueError, OSError):
            resource.setrlimit(resource.RLIMIT_CPU,
                               (soft if hard == resource.RLIM_INFINITY else min(soft, hard),
                                hard))
        try:
            request = REQUEST.validate_json(request_json)
            result = RESULT.validate_json(result_json)
            plan = execution_plan(result, request)
            options = dict(options)
            disturbed = options.pop("disturbances", None)
            loop = options.pop("closed_loop", None)
            if loop is not None:
                from ..execution.closed_loop import closed_loop_report

                reply: tuple[str, Any] = closed_loop_report(request, result, plan, options,
                                                            disturbed, loop)
            elif disturbed is not None:
                from sim.closed_loop import simulate_disturbed
                from sim.disturbances import Disturbances

                options.pop("model", None)
                dist = Disturbances.from_dict(disturbed)
                report = simulate_disturbed(plan, SimOptions.from_dict(options), dist)
                reply = ("ok", {**report.to_dict(), "disturbances": dist.to_dict()})
            elif options.pop("model", "scene") == "request":  # the request's own hand file
                from sim.user_model import simulate_on_model

                from ..execution import user_model

                report = simulate_on_model(plan, user_model(request, plan),
                                           SimOptions.from_dict(options))
                reply = ("ok", report.to_dict())
            else:
                report = simulate(plan, SimOptions.from_dict(options))
                reply = ("ok", report.to_dict())
        except (NotExecutableError, ProblemError) as exc:
            reply = ("not_executable", str(exc))
        except ValueError as exc:  # an option the simulator refuses (solref vs timestep)
            reply = ("invalid_options", str(exc))
        except Exception as exc:  # a typed answer, never a dead process
            log.exception("simulation failed")
            reply = ("simulation_failed", f"the simulation failed: {exc!r}")
        return reply


#: How a process's reply other than a report is answered: (status, retry-after).
_REPLIES = {"not_executable": (409, None), "not_replannable": (409, None),
            "invalid_options": (422, None),
            "simulation_unavailable": (503, None), "simulation_failed": (500, None)}


def _settle(task: SimulationTask, outcome: dict[str, Any] | BaseException) -> None:
    """Give a task its outcome, unless its waiter has cancelled it (nobody to tell)."""
    if task.future.done():
        return
    with contextlib.suppress(InvalidStateError):
        if isinstance(outcome, BaseException):
            task.future.set_exception(outcome)
        else:
            task.future.set_result(outcome)


class SimulationPool:
    """``processes`` simulation slots (each a thread of the service and its process,
    started at the first simulation), ``max_queue`` simulations waiting at most, each run
    under ``time_limit`` [s] of wall time and ``cpu_seconds`` of CPU time."""

    #: Retry-After of a full queue [s].
    RETRY_AFTER = 5

    def __init__(self, processes: int = 1, max_queue: int = 4, time_limit: float = 120.0,
                 cpu_seconds: float = 120.0, executor: Executor | None = None) -> None:
        self.processes, self.max_queue = processes, max_queue
        self.time_limit, self.cpu_seconds = time_limit, cpu_seconds
        if executor is None:
            from ..executors.local import LocalProcesses

            executor = LocalProcesses()
        self.executor = executor
        self._tasks: queue.Queue[SimulationTask | None] = queue.Queue()
        self._lock = threading.Lock()
        self._queued = self._running = 0
        self._closed = False
        self._threads = [threading.Thread(target=self._slot, name=f"dexroll-sim-{i}",
                                          daemon=True) for i in range(processes)]
        for thread in self._threads:
            thread.start()

    # -- called from the API --------------------------------------------------------------
    def submit(self, result_json: str, request_json: str, options: dict[str, Any]
               ) -> SimulationTask:
        """Queue a simulation; SimulationRefusedError (503) when ``max_queue`` already wait."""
        task = SimulationTask(result_json, request_json, options)
        with self._lock:
            if self._closed:
                raise SimulationRefusedError(503, "shutting_down", "the service is stopping",
                                        self.RETRY_AFTER)
            if self._queued >= self.max_queue:
                raise SimulationRefusedError(
                    503, "simulations_busy",
                    f"{self._running} simulations run and {self._queued} wait (at most "
                    f"{self.max_queue}: DEXROLL_SIM_QUEUE); retry later", self.RETRY_AFTER)
            self._queued += 1
        self._tasks.put(task)
        return task

    def cancel(self, task: SimulationTask) -> None:
        """Nobody waits for this simulation any more: drop it, or stop its run."""
        task.cancelled.set()

    def stats(self) -> dict[str, int]:
        """Simulations running and waiting, and the slots (for ``/readyz``)."""
        with self._lock:
            return {"running": self._running, "queued": self._queued,
                    "slots": self.processes}

    def close(self) -> None:
        with self._lock:
            self._closed = True
        for _ in self._threads:
            self._tasks.put(None)
        for thread in self._threads:
            thread.join(timeout=10)

    # -- a slot's thread ---------------------------------------------------------------------
    def _start(self) -> Worker:
        worker = self.executor.start(SimulationWorker, (self.cpu_seconds,),
                                     Resources(cpus=1.0), "simulation")
        try:
            missing = worker.call("ready").result(timeout=START_TIMEOUT)
        except (TimeoutError, WorkerLostError, WorkerError) as exc:
            worker.kill()
            raise SimulationRefusedError(503, "simulation_unavailable",
                                         f"the simulation worker did not start: {exc}",
                                         self.RETRY_AFTER) from exc
        if missing is not None:
            worker.kill()
            raise SimulationRefusedError(503, "simulation_unavailable", str(missing))
        return worker

    def _slot(self) -> None:
        worker: Worker | None = None
        try:
            while True:
                task = self._tasks.get()
                if task is None:
                    return
                with self._lock:
                    self._queued -= 1
                    self._running += 1
                try:
                    if task.cancelled.is_set():
                        raise SimulationRefusedError(499, "cancelled", "nobody waits for it")
                    if worker is None:
                        worker = self._start()
                    _settle(task, self._run(worker, task))
                except SimulationRefusedError as exc:
                    if exc.lost and worker is not None:
                        worker = None
                    _settle(task, exc)
                except Exception as exc:  # the slot goes on: its worker is replaced
                    log.exception("simulation slot error")
                    if worker is not None:
                        worker.kill()
                        worker = None
                    _settle(task, SimulationRefusedError(
                        500, "simulation_failed", f"the simulation failed: {exc!r}"))
                finally:
                    with self._lock:
                        self._running -= 1
        finally:
            if worker is not None:
                worker.kill()

    def _run(self, worker: Worker, task: SimulationTask) -> dict[str, Any]:
        """One run on ``worker``: its report, or SimulationRefusedError (``lost`` when the
        worker was killed: it ran out of time, of CPU, or of anyone waiting)."""
        future = worker.call("run", task.result_json, task.request_json, task.options)
        deadline = time.monotonic() + self.time_limit
        while True:
            try:
                kind, payload = future.result(timeout=0.1)
            except TimeoutError:
                pass
            except WorkerError as exc:
                raise SimulationRefusedError(500, "simulation_failed",
                                             f"the simulation failed: {exc}") from exc
            except WorkerLostError as exc:
                worker.kill()
                if exc.exitcode == -signal.SIGXCPU:
                    raise SimulationRefusedError(
                        503, "simulation_cpu_limit",
                        f"the simulation used its CPU budget of {self.cpu_seconds:g} s "
                        "(DEXROLL_SIM_CPU_SECONDS) and was stopped: ask for a larger "
                        "timestep or a shorter plan", lost=True) from exc
                raise SimulationRefusedError(500, "simulation_failed",
                                             f"the simulation worker died: {exc.reason}",
                                             lost=True) from exc
            else:
                if kind == "ok":
                    return dict(payload)
                status, retry = _REPLIES.get(kind, (500, None))
                raise SimulationRefusedError(status, kind, str(payload), retry)
            if task.cancelled.is_set():
                worker.kill()
                log.info("simulation stopped: its client left")
                raise SimulationRefusedError(499, "cancelled", "nobody waits for it",
                                             lost=True)
            if time.monotonic() > deadline:
                worker.kill()
                raise SimulationRefusedError(
                    503, "simulation_time_limit",
                    f"the simulation did not end within {self.time_limit:g} s "
                    "(DEXROLL_SIM_TIME_LIMIT) and was stopped: ask for a larger timestep "
                    "or a shorter plan", lost=True)
