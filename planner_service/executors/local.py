"""Workers as spawned child processes of the service (the default executor).

Each worker is a *spawned* process (no fork: CasADi/IPOPT state is never shared) running
:func:`serve`: it builds its body once, then answers each call received on its pipe, in
order. It dies with the service (:mod:`planner_service.jobs.lifeline`). On the service's
side a reader thread per worker resolves the calls' futures; when the pipe closes (the
process died or was killed) every pending call ends with :class:`WorkerLostError`, naming the
process and its exit code.
"""

from __future__ import annotations

import contextlib
import itertools
import logging
import multiprocessing as mp
import os
import threading
from collections.abc import Callable
from concurrent.futures import Future, InvalidStateError
from multiprocessing.connection import Connection
from typing import Any

from . import Resources, WorkerLostError, resolve, worker_env

__all__ = ["LocalProcesses", "ProcessWorker", "serve"]

log = logging.getLogger("dexroll.executors")

def serve(conn: Connection, parent: int, pdeathsig: bool, body: type,
          args: tuple[Any, ...]) -> None:
    """A worker process: build ``body(*args)``, then answer each ``(call id, method,
    args)`` received with ``(call id, ok, value or error text)`` until the pipe closes or
    a None arrives."""
    from ..jobs.lifeline import die_with_parent, received

    die_with_parent(parent, pdeathsig=pdeathsig)
    if not logging.getLogger().handlers:  # spawned: the service's logging is not inherited
        logging.basicConfig(level=logging.INFO,
                            format="%(asctime)s %(levelname)s [%(processName)s "
                                   "%(process)d] %(name)s: %(message)s")
    try:
        instance = body(*args)
    except Exception as exc:  # said on every call: the worker cannot work
        log.exception("worker body %s could not be built", body.__name__)
        failure = f"{body.__name__} could not start: {type(exc).__name__}: {exc}"
        for call_id, _, _ in received(conn):
            conn.send((call_id, False, failure))
        return
    for call_id, method, call_args in received(conn):
        try:
            value = getattr(instance, method)(*call_args)
        except Exception as exc:
            log.exception("worker call %s failed", method)
            conn.send((call_id, False, f"{type(exc).__name__}: {exc}"))
            continue
        conn.send((call_id, True, value))


class ProcessWorker:
    """One spawned worker process and the futures of its calls."""

    def __init__(self, ctx: Any, body: type, args: tuple[Any, ...], resources: Resources,
                 label: str) -> None:
        for var, value in worker_env().items():  # spawned children copy the environment
            os.environ.setdefault(var, value)
        self._conn, child = ctx.Pipe()
        self.process = ctx.Process(target=serve, name=f"dexroll-{label}", daemon=True,
                                   args=(child, os.getpid(), resources.pdeathsig, body, args))
        self.process.start()
        child.close()
        self.pid: int | None = self.process.pid
        self._ids = itertools.count()
        self._lock = threading.Lock()
        self._send_lock = threading.Lock()
        self._pending: dict[int, Future[Any]] = {}
        self._lost: WorkerLostError | None = None
        self._on_lost: list[Callable[[WorkerLostError], None]] = []
        threading.Thread(target=self._read, name=f"dexroll-{label}-reader",
                         daemon=True).start()

    def where(self) -> str:
        return f"pid {self.pid}"

    def call(self, method: str, *args: Any) -> Future[Any]:
        future: Future[Any] = Future()
        with self._lock:
            if self._lost is not None:
                future.set_exception(self._lost)
                return future
            call_id = next(self._ids)
            self._pending[call_id] = future
        try:
            with self._send_lock:
                self._conn.send((call_id, method, args))
        except (OSError, ValueError):  # the pipe is gone: the reader reports the death
            pass
        return future

    def kill(self) -> None:
        with contextlib.suppress(Exception):
            self.process.kill()

    def when_lost(self, callback: Callable[[WorkerLostError], None]) -> None:
        with self._lock:
            lost = self._lost
            if lost is None:
                self._on_lost.append(callback)
        if lost is not None:
            callback(lost)

    def ask_to_end(self) -> None:
        """Ask the worker to end after its current call (the pipe's None)."""
        with contextlib.suppress(OSError, ValueError), self._send_lock:
            self._conn.send(None)

    def _read(self) -> None:
        while True:
            try:
                call_id, ok, value = self._conn.recv()
            except (EOFError, OSError, ValueError):
                break
            with self._lock:
                future = self._pending.pop(call_id, None)
            resolve(future, ok, value)
        self.process.join(timeout=5)
        lost = WorkerLostError(f"the worker process (pid {self.pid}) died (exit code "
                          f"{self.process.exitcode})", self.process.exitcode)
        with self._lock:
            self._lost = lost
            pending, self._pending = list(self._pending.values()), {}
            callbacks, self._on_lost = self._on_lost, []
        for future in pending:
            with contextlib.suppress(InvalidStateError):
                future.set_exception(lost)
        for callback in callbacks:
            callback(lost)
        with contextlib.suppress(OSError):
            self._conn.close()


class LocalProcesses:
    """Workers as spawned child processes of this service."""

    name = "local"

    def __init__(self) -> None:
        self._ctx = mp.get_context("spawn")
        self._workers: list[ProcessWorker] = []
        self._lock = threading.Lock()

    def start(self, body: type, args: tuple[Any, ...], resources: Resources,
              label: str) -> ProcessWorker:
        worker = ProcessWorker(self._ctx, body, args, resources, label)
        with self._lock:
            self._workers = [w for w in self._workers if w.process.is_alive()] + [worker]
        return worker

    def unavailable(self) -> str | None:
        return None

    def describe(self) -> dict[str, Any]:
        return {"name": self.name, "cpus": os.cpu_count()}

    def close(self) -> None:
        with self._lock:
            workers, self._workers = self._workers, []
        for worker in workers:  # all asked first: they end together
            worker.ask_to_end()
        for worker in workers:
            worker.process.join(timeout=2)
            worker.kill()
