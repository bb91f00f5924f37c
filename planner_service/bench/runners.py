"""Ways to run a suite's units, all giving the same rows (up to ``rows.VOLATILE``):

* :func:`run_pool`: a local pool of spawned worker processes; each keeps the library's
  process-wide planner caches (NLPs, fingers, hands) from unit to unit;
* :func:`run_service`: through a running dexroll service with the client
  (``DexrollClient.plan``), ``workers`` jobs in flight; the service's workers keep their
  own caches. The peers are not service planners: their units run in this process;
* :func:`run_ray`: on a Ray cluster, units dispatched to a small pool of actors, each a
  process holding its own planner caches (as a pool worker does).

Each calls ``on_row(row)`` as a unit finishes (in completion order) and returns the rows
sorted by (family, problem id, method).
"""

from __future__ import annotations

import contextlib
import multiprocessing as mp
import os
import threading
import time
from collections.abc import Callable, Iterator
from concurrent.futures import FIRST_COMPLETED, ThreadPoolExecutor, wait
from multiprocessing.connection import Connection
from multiprocessing.connection import wait as mp_wait
from typing import Any

from ..executors import THREAD_VARIABLES, worker_env
from ..planners.structure import structure_key
from .rows import error_row, row_from_result, run_unit
from .suite import PEER_METHODS, Unit

__all__ = ["THREAD_VARIABLES", "RayInfo", "Scheduler", "affinity_key", "default_workers",
           "dispatch_order", "run_pool", "run_ray", "run_service", "sort_rows", "worker_env"]

Row = dict[str, Any]
OnRow = Callable[[Row], None]

#: Heavier planners first, so that the long units do not end a run on one busy worker.
_WEIGHT = {"manipulation": 0, "one_finger": 1, "ball_on_palm": 2}


@contextlib.contextmanager
def _environment(values: dict[str, str]) -> Iterator[None]:
    """os.environ with ``values`` while processes are spawned (they copy it)."""
    saved = {k: os.environ.get(k) for k in values}
    os.environ.update(values)
    try:
        yield
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def default_workers() -> int:
    """One worker per core."""
    return max(1, os.cpu_count() or 1)


def sort_rows(rows: list[Row]) -> list[Row]:
    return sorted(rows, key=lambda r: (r["family"], r["problem_id"], r["method"]))


def dispatch_order(units: list[Unit]) -> list[Unit]:
    """The order units are handed out: heavier planners first, then suite order."""
    return sorted(units, key=lambda u: (_WEIGHT.get(u.planner, 3), u.key))


def affinity_key(unit: Unit) -> str:
    """What decides which cached NLPs a unit needs: the service's own structure key
    (:func:`planner_service.planners.structure.structure_key`), with the unit's method.
    Units with the same key reuse the NLPs a worker built for the first of them."""
    return structure_key(unit.planner, unit.request, unit.method)


class Scheduler:
    """Hands units to workers, preferring for each worker a unit whose NLPs it has built
    (same :func:`affinity_key`), then a structure no worker has started, then any unit
    (heaviest planners first): each worker builds as few NLPs as it can, and none idles
    while units are left."""

    def __init__(self, units: list[Unit]) -> None:
        self.queue = dispatch_order(units)
        self.seen: dict[Any, set[str]] = {}
        self.started: set[str] = set()

    def __bool__(self) -> bool:
        return bool(self.queue)

    def next_for(self, worker: Any) -> Unit:
        seen = self.seen.setdefault(worker, set())
        keys = [affinity_key(u) for u in self.queue]
        pick = next((i for i, k in enumerate(keys) if k in seen), None)
        if pick is None:
            pick = next((i for i, k in enumerate(keys) if k not in self.started), 0)
        seen.add(keys[pick])
        self.started.add(keys[pick])
        return self.queue.pop(pick)

    def forget(self, worker: Any) -> None:
        """A worker replaced: its successor has built nothing."""
        self.seen.pop(worker, None)


def _quiet() -> None:
    """The library's INFO logs would break the progress bar."""
    import logging

    logging.basicConfig(level=logging.WARNING)


def _pool_worker(conn: Connection) -> None:
    """Body of a pool worker: plan each unit received (None: stop), reply with its row. The
    process keeps the library's planner caches from unit to unit."""
    _quiet()
    while True:
        unit = conn.recv()
        if unit is None:
            return
        conn.send(run_unit(unit))


def run_pool(units: list[Unit], workers: int, on_row: OnRow) -> list[Row]:
    """Run the units on ``workers`` spawned processes (no fork: CasADi/IPOPT state is never
    shared), each fed by the :class:`Scheduler`. A worker that dies ends its unit as a row
    with status ``error`` and is replaced."""
    ctx = mp.get_context("spawn")
    scheduler = Scheduler(units)
    procs: dict[Connection, Any] = {}

    def spawn() -> Connection:
        parent, child = ctx.Pipe()
        proc = ctx.Process(target=_pool_worker, args=(child,), daemon=True)
        with _environment(worker_env()):
            proc.start()
        child.close()
        procs[parent] = proc
        return parent

    rows: list[Row] = []
    running: dict[Connection, Unit] = {}
    try:
        idle = [spawn() for _ in range(min(max(1, workers), len(units)))]
        while scheduler or running:
            while idle and scheduler:
                conn = idle.pop(0)
                unit = scheduler.next_for(conn)
                conn.send(unit)
                running[conn] = unit
            for ready in mp_wait(list(running)):
                assert isinstance(ready, Connection)
                unit = running.pop(ready)
                try:
                    row = ready.recv()
                except (EOFError, OSError):  # the worker died mid-unit
                    proc = procs.pop(ready)
                    proc.join(timeout=5)
                    row = error_row(unit, "error", f"the worker process died (exit code "
                                                   f"{proc.exitcode})")
                    scheduler.forget(ready)
                    ready.close()
                    ready = spawn()
                idle.append(ready)
                rows.append(row)
                on_row(row)
    finally:
        for conn in procs:
            with contextlib.suppress(OSError, ValueError):
                conn.send(None)
        for conn, proc in procs.items():
            proc.join(timeout=10)
            if proc.is_alive():
                proc.terminate()
                proc.join(timeout=5)
            conn.close()
    return sort_rows(rows)


def run_service(units: list[Unit], url: str, workers: int, on_row: OnRow,
                timeout: float = 3600.0) -> list[Row]:
    """Run the units through the service at ``url`` (``workers`` jobs in flight, one client
    per thread). Peer units run in this process, one at a time."""
    from dexroll_client import DexrollClient
    from dexroll_client.errors import DexrollError, InvalidRequestError

    local = threading.local()
    clients: list[DexrollClient] = []
    clients_lock = threading.Lock()
    peer_lock = threading.Lock()

    def client() -> DexrollClient:
        c = getattr(local, "client", None)
        if c is None:
            c = DexrollClient.from_url(url)
            local.client = c
            with clients_lock:
                clients.append(c)
        return c

    def one(unit: Unit) -> Row:
        if unit.method in PEER_METHODS:
            with peer_lock:
                return run_unit(unit)
        t0 = time.perf_counter()
        try:
            job = client().plan(unit.request, timeout=timeout)
        except InvalidRequestError as exc:
            detail = "; ".join(f"{d.field}: {d.reason}" for d in exc.detail) or exc.message
            return error_row(unit, "invalid_input", detail, time.perf_counter() - t0)
        except DexrollError as exc:
            return error_row(unit, "error", f"{type(exc).__name__}: {exc}",
                             time.perf_counter() - t0)
        except Exception as exc:  # a local validation error, or anything unexpected
            return error_row(unit, "error", f"{type(exc).__name__}: {exc}",
                             time.perf_counter() - t0)
        wall = time.perf_counter() - t0
        if job.result is None:  # killed, cancelled, worker died: no plan
            return error_row(unit, job.code or job.state.value, job.message or "",
                             wall, job.worker_pid)
        return row_from_result(unit, job.result, wall, job.worker_pid, None)

    rows: list[Row] = []
    try:
        with ThreadPoolExecutor(max_workers=max(1, workers)) as pool:
            futures = [pool.submit(one, u) for u in dispatch_order(units)]
            pending = set(futures)
            while pending:
                done, pending = wait(pending, return_when=FIRST_COMPLETED)
                for fut in done:
                    row = fut.result()
                    rows.append(row)
                    on_row(row)
    finally:
        for c in clients:
            c.close()
    return sort_rows(rows)


class _BenchActor:
    """A Ray actor: one process planning units with its own process-wide planner caches."""

    def run(self, unit: Unit) -> Row:
        return run_unit(unit)

    def pid(self) -> int:
        return os.getpid()


class RayInfo(dict[str, Any]):
    """What :func:`run_ray` found: address, actors, cluster CPUs, whether it started Ray."""


def run_ray(units: list[Unit], address: str | None, workers: int | None, on_row: OnRow,
            info: RayInfo | None = None) -> list[Row]:
    """Run the units on Ray: connect to ``address`` (``auto``: the cluster this machine
    belongs to; ``local``: start a local instance with ``workers`` CPUs; ``None``: the
    instance this process already initialised), start one actor per worker (at most one per
    CPU of the cluster; default: every CPU) and hand each idle actor its next unit (by the
    :class:`Scheduler`, so that actors reuse the NLPs they have built). An
    actor that dies is replaced and its unit ends as a row with status ``error``. Ray is
    shut down at the end only if this call started it."""
    if not units:
        return []
    import ray

    started = False
    if not ray.is_initialized():
        if address in (None, "local"):
            ray.init(num_cpus=workers or default_workers(), include_dashboard=False,
                     log_to_driver=False)
        else:
            ray.init(address=address, log_to_driver=False)
        started = True
    try:
        cpus = int(ray.cluster_resources().get("CPU", 1))
        n = max(1, min(workers or cpus, cpus))
        actor_cls: Any = ray.remote(num_cpus=1, runtime_env={"env_vars": worker_env()}
                                    )(_BenchActor)
        actors: list[Any] = [actor_cls.remote() for _ in range(n)]
        if info is not None:
            info.update(address=address or "(already initialised)", actors=n,
                        cluster_cpus=cpus, started_here=started)
        scheduler = Scheduler(units)
        slots = list(actors)  # slot -> its actor (replaced when one dies)
        idle = list(range(n))
        pending: dict[Any, tuple[int, Unit]] = {}
        rows: list[Row] = []
        while scheduler or pending:
            while idle and scheduler:
                slot = idle.pop(0)
                unit = scheduler.next_for(slot)
                pending[slots[slot].run.remote(unit)] = (slot, unit)
            done, _ = ray.wait(list(pending), num_returns=1)
            slot, unit = pending.pop(done[0])
            try:
                row = ray.get(done[0])
            except ray.exceptions.RayActorError as exc:
                row = error_row(unit, "error", f"the Ray actor died: {exc}")
                slots[slot] = actor_cls.remote()
                actors.append(slots[slot])
                scheduler.forget(slot)
            except Exception as exc:
                row = error_row(unit, "error", f"{type(exc).__name__}: {exc}")
            idle.append(slot)
            rows.append(row)
            on_row(row)
        for actor in actors:
            ray.kill(actor)
        return sort_rows(rows)
    finally:
        if started:
            ray.shutdown()
