"""Where the service's work runs: the executor seam.

The service's heavy work (solver jobs; see :mod:`planner_service.jobs.workers`) runs in
*workers*: long-lived processes that keep their caches (built NLPs, loaded models) from
call to call. An :class:`Executor` starts workers and nothing else; what a worker does is
its *body*, a plain class whose methods are called one at a time (``body(*args)`` is built
once, in the worker). Two executors are registered in :data:`EXECUTORS`:

* ``local`` (:class:`.local.LocalProcesses`, the default): spawned child processes of the
  service, which die with it;
* ``ray`` (:class:`.ray.RayExecutor`): actors on a Ray cluster (``dexroll serve --ray
  ADDRESS`` or ``DEXROLL_RAY_ADDRESS``), reached through one local *bridge* process that
  is the cluster's driver: a cluster that goes away takes the bridge with it, never the
  service, which then says why it is unavailable (:meth:`Executor.unavailable`) and starts
  a new bridge a few seconds later.

A call returns a :class:`concurrent.futures.Future`. It ends with the method's return
value, with :class:`WorkerError` when the method raised (the worker lives on), or with
:class:`WorkerLostError` when the worker died under it (a killed process, a lost node or
cluster): the caller decides what a lost call means (the dispatcher re-queues its job
once, then fails it ``worker_died``). Adding a place to run work is a module here with a
class that has :class:`Executor`'s methods, and a line in :data:`EXECUTORS`.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Callable
from concurrent.futures import Future, InvalidStateError
from dataclasses import dataclass
from typing import Any, Protocol

__all__ = ["EXECUTORS", "THREAD_VARIABLES", "Executor", "Resources", "Worker", "WorkerError",
           "WorkerLostError", "executor", "resolve", "worker_env"]

#: Threads of the linear algebra libraries in a worker. The last digits of a plan depend on
#: them (the order of a parallel reduction), so every worker gets the same: one thread each
#: (the workers are the parallelism; Ray's own default for a one-CPU actor), unless this
#: process's environment says otherwise.
THREAD_VARIABLES: tuple[str, ...] = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS",
                                     "MKL_NUM_THREADS")


def worker_env() -> dict[str, str]:
    """The thread settings of every worker (a local process, a Ray actor, a bench
    runner's process)."""
    return {k: os.environ.get(k, "1") for k in THREAD_VARIABLES}


class WorkerLostError(Exception):
    """The worker died (or could not be started) under a call: ``reason`` says how, and
    ``exitcode`` is its process's exit code when known (a local process)."""

    def __init__(self, reason: str, exitcode: int | None = None) -> None:
        super().__init__(reason)
        self.reason, self.exitcode = reason, exitcode


class WorkerError(Exception):
    """A worker's method raised (its type and message); the worker lives on."""


@dataclass(frozen=True)
class Resources:
    """What one worker of a kind asks of the place it runs: CPUs (a Ray actor's
    ``num_cpus``; local processes are one per worker anyway), memory in bytes (a Ray
    scheduling reservation; None: none), and whether a local child should be killed by
    the kernel when the thread that started it ends (``PR_SET_PDEATHSIG``: only for
    children started from threads that live as long as the service)."""

    cpus: float = 1.0
    memory: int | None = None
    pdeathsig: bool = True


class Worker(Protocol):
    """One started worker: its methods are called one at a time, in call order."""

    #: process id of the worker (None until known: a Ray actor's, once it is up)
    pid: int | None

    def call(self, method: str, *args: Any) -> Future[Any]:
        """Call ``method(*args)`` of the worker's body; its future ends as the module says."""
        ...

    def kill(self) -> None:
        """Stop the worker at once, whatever it is doing (its pending calls are lost)."""
        ...

    def when_lost(self, callback: Callable[[WorkerLostError], None]) -> None:
        """Call ``callback`` once when the worker dies (killed, its process or node lost),
        busy or idle; at once when it already has."""
        ...

    def where(self) -> str:
        """Where the worker runs, for logs and messages ("pid 123", "Ray actor … on node …")."""
        ...


class Executor(Protocol):
    """A place to run workers."""

    #: its name in :data:`EXECUTORS` (and on ``/readyz``)
    name: str

    def start(self, body: type, args: tuple[Any, ...], resources: Resources,
              label: str) -> Worker:
        """A new worker running ``body(*args)`` (``label``: its kind, for logs). Never
        blocks on a slow start: a worker that cannot start fails its calls with
        :class:`WorkerLostError`."""
        ...

    def unavailable(self) -> str | None:
        """Why no worker can be started now (None: they can)."""
        ...

    def describe(self) -> dict[str, Any]:
        """What it is, for ``/readyz`` (name, address, nodes and CPUs when known)."""
        ...

    def close(self) -> None:
        """Stop every worker it started."""
        ...


def resolve(future: Future[Any] | None, ok: bool, value: Any) -> None:
    """End a call's future with the worker's answer: its value, or (``ok`` false) a
    :class:`WorkerError` with the error's text; nothing when it has ended already."""
    if future is None:
        return
    with contextlib.suppress(InvalidStateError):
        if ok:
            future.set_result(value)
        else:
            future.set_exception(WorkerError(value))


def _local(address: str | None) -> Executor:
    from .local import LocalProcesses

    return LocalProcesses()


def _ray(address: str | None) -> Executor:
    from .ray import RayExecutor

    return RayExecutor(address or "auto")


#: The executors by name: each a factory of the cluster address (None for local).
EXECUTORS: dict[str, Callable[[str | None], Executor]] = {"local": _local, "ray": _ray}


def executor(name: str, address: str | None = None) -> Executor:
    """The executor registered as ``name``."""
    try:
        return EXECUTORS[name](address)
    except KeyError:
        raise ValueError(f"no executor {name!r} (known: {', '.join(EXECUTORS)})") from None
