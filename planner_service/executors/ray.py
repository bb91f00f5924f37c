"""Workers as actors on a Ray cluster (``dexroll serve --ray ADDRESS``,
``DEXROLL_EXECUTOR=ray``).

The service does not connect to the cluster itself: a local *bridge* process does (the
cluster's driver, :func:`_bridge_main`), and the service talks to it over a pipe. A driver
that loses its cluster may hang or be ended by Ray; with the bridge in between, that is a
dead child process, not a dead service: the API keeps answering, says why no worker can
run (:meth:`RayExecutor.unavailable`: ``/readyz`` not ready, submissions 503 with
Retry-After), and a new bridge is started when a worker is next asked for, at most every
:data:`RECONNECT_AFTER` seconds.

Each worker is one actor (:class:`_Host`, holding the body, e.g. the solver worker with
its NLP caches) with the CPUs and memory of its :class:`~planner_service.executors.Resources`;
Ray places it on any node. A call is one actor task; its result comes back through the
bridge. An actor that dies (its process killed, its node lost) fails its calls with
:class:`~planner_service.executors.WorkerLostError`, and so does an idle one: the bridge
pings actors with no call in flight every :data:`PING_INTERVAL` seconds.
"""

from __future__ import annotations

import contextlib
import itertools
import logging
import multiprocessing as mp
import os
import threading
import time
from collections.abc import Callable
from concurrent.futures import Future, InvalidStateError, ThreadPoolExecutor
from multiprocessing.connection import Connection
from typing import Any

from . import Resources, WorkerLostError, resolve, worker_env

__all__ = ["PING_INTERVAL", "RECONNECT_AFTER", "RayExecutor", "RayWorker"]

log = logging.getLogger("dexroll.executors")

#: How long the bridge may take to connect to the cluster [s].
CONNECT_TIMEOUT = 60.0
#: Seconds between a bridge lost (or a failed connection) and the next attempt.
RECONNECT_AFTER = 5.0
#: How often the bridge pings actors that have no call in flight [s].
PING_INTERVAL = 2.0
#: A ping not answered within this long means the actor (or its node) is lost [s].
PING_TIMEOUT = 10.0


class _Host:
    """The actor: it builds the body and calls its methods (one at a time)."""

    def __init__(self, body: type, args: tuple[Any, ...]) -> None:
        self.body = body(*args)

    def where(self) -> dict[str, Any]:
        import socket

        import ray

        return {"pid": os.getpid(), "host": socket.gethostname(),
                "node": ray.get_runtime_context().get_node_id()}

    def ping(self) -> bool:
        return True

    def call(self, method: str, args: tuple[Any, ...]) -> Any:
        return getattr(self.body, method)(*args)


def _bridge_main(conn: Connection, parent: int, address: str) -> None:
    """The bridge process: the Ray driver. Messages in: ("start", worker id, body, args,
    cpus, memory), ("call", worker id, call id, method, args), ("kill", worker id), None
    (stop). Out: ("connected", info) or ("unavailable", reason) first, then ("where",
    worker id, info), ("result", call id, ok, value), ("lost", worker id, reason) and
    ("cluster", its live nodes and CPUs) every :data:`PING_INTERVAL`, or ("gone", reason)
    before it exits when the cluster does not answer."""
    from ..jobs.lifeline import die_with_parent, received

    die_with_parent(parent)
    send_lock = threading.Lock()

    def send(msg: Any) -> None:
        with send_lock, contextlib.suppress(OSError, ValueError):
            conn.send(msg)

    try:
        import ray
        from ray.exceptions import RayTaskError
    except ImportError as exc:
        send(("unavailable", f"Ray is not installed here ({exc}): pip install "
                             "'dexroll[distributed]'"))
        return
    try:
        ray.init(address=address, namespace="dexroll", log_to_driver=False,
                 logging_level=logging.WARNING, include_dashboard=False)
        nodes = [n for n in ray.nodes() if n.get("Alive")]
        info = {"address": address, "nodes": len(nodes),
                "cpus": float(ray.cluster_resources().get("CPU", 0.0))}
    except Exception as exc:
        send(("unavailable", f"cannot connect to the Ray cluster at {address!r}: "
                             f"{type(exc).__name__}: {exc}"))
        return
    send(("connected", info))
    lock = threading.Lock()
    actors: dict[int, Any] = {}
    in_flight: dict[int, int] = {}  # worker id -> calls in flight

    def lost(wid: int, reason: str) -> None:
        with lock:
            if actors.pop(wid, None) is None:
                return
            in_flight.pop(wid, None)
        send(("lost", wid, reason))

    def settle(wid: int, call_id: int | None, future: Any) -> None:
        try:
            value = future.result()
        except RayTaskError as exc:  # the method raised: the actor lives on
            cause = exc.cause if getattr(exc, "cause", None) is not None else exc
            if call_id is None:
                lost(wid, f"the actor could not start: {cause}")
            else:
                send(("result", call_id, False, f"{type(cause).__name__}: {cause}"))
        except Exception as exc:  # the actor, its node or its worker process died
            lost(wid, f"{type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}")
        else:
            if call_id is not None:
                send(("result", call_id, True, value))
            else:
                send(("where", wid, value))
        finally:
            with lock:
                if wid in in_flight:
                    in_flight[wid] -= 1

    def submit(wid: int, call_id: int | None, ref: Any) -> None:
        with lock:
            in_flight[wid] = in_flight.get(wid, 0) + 1
        ref.future().add_done_callback(lambda f: settle(wid, call_id, f))

    asker = ThreadPoolExecutor(1, thread_name_prefix="dexroll-ray-gcs")

    def cluster() -> dict[str, Any]:
        return {"nodes": sum(1 for n in ray.nodes() if n.get("Alive")),
                "cpus": float(ray.cluster_resources().get("CPU", 0.0))}

    def watch() -> None:  # idle actors are pinged: a lost node is found without a job
        while True:
            time.sleep(PING_INTERVAL)
            try:  # the cluster's size, for /readyz; no answer: the cluster is gone
                send(("cluster", asker.submit(cluster).result(timeout=PING_TIMEOUT)))
            except Exception as exc:
                send(("gone", f"the Ray cluster at {address!r} does not answer "
                              f"({type(exc).__name__}: {exc})"))
                os._exit(3)
            with lock:
                idle = [(w, a) for w, a in actors.items() if not in_flight.get(w)]
            for wid, actor in idle:
                try:
                    ray.get(actor.ping.remote(), timeout=PING_TIMEOUT)
                except Exception as exc:
                    lost(wid, f"{type(exc).__name__}: {str(exc).splitlines()[0]}"
                              if str(exc) else type(exc).__name__)

    threading.Thread(target=watch, name="dexroll-ray-watch", daemon=True).start()
    host: Any = ray.remote(_Host)
    for msg in received(conn):
        kind = msg[0]
        try:
            if kind == "start":
                _, wid, body, args, cpus, memory = msg
                options: dict[str, Any] = {"num_cpus": cpus, "max_restarts": 0,
                                           "runtime_env": {"env_vars": worker_env()}}
                if memory:
                    options["memory"] = memory
                actor: Any = host.options(**options).remote(body, args)
                with lock:
                    actors[wid] = actor
                submit(wid, None, actor.where.remote())
            elif kind == "call":
                _, wid, call_id, method, args = msg
                with lock:
                    actor = actors.get(wid)
                if actor is None:
                    send(("lost", wid, "the actor is gone"))
                    continue
                submit(wid, call_id, actor.call.remote(method, args))
            elif kind == "kill":
                with lock:
                    actor = actors.pop(msg[1], None)
                    in_flight.pop(msg[1], None)
                if actor is not None:
                    ray.kill(actor, no_restart=True)
        except Exception as exc:  # a message the cluster refused: its worker is lost
            log.exception("ray bridge: %s failed", kind)
            if kind in ("start", "call"):
                lost(msg[1], f"{type(exc).__name__}: {exc}")
    with contextlib.suppress(Exception):
        ray.shutdown()


class RayWorker:
    """One actor, seen from the service."""

    def __init__(self, executor: RayExecutor, wid: int, label: str) -> None:
        self._executor, self.id, self.label = executor, wid, label
        self.pid: int | None = None
        self.host = self.node = ""
        self.lost: WorkerLostError | None = None
        self._on_lost: list[Callable[[WorkerLostError], None]] = []

    def _died(self, lost: WorkerLostError) -> None:
        """Record the worker's loss (once) and tell who asked."""
        if self.lost is not None:
            return
        self.lost = lost
        callbacks, self._on_lost = self._on_lost, []
        for callback in callbacks:
            callback(lost)

    def when_lost(self, callback: Callable[[WorkerLostError], None]) -> None:
        if self.lost is not None:
            callback(self.lost)
        else:
            self._on_lost.append(callback)

    def where(self) -> str:
        if self.pid is None:
            return f"Ray actor {self.label} #{self.id} (starting)"
        return f"Ray actor {self.label} #{self.id}, pid {self.pid} on {self.host} " \
               f"(node {self.node[:12]})"

    def call(self, method: str, *args: Any) -> Future[Any]:
        return self._executor._call(self, method, args)

    def kill(self) -> None:
        self._executor._kill(self)


class RayExecutor:
    """Workers as Ray actors on the cluster at ``address`` (``auto``: the one this
    machine's ``ray start`` joined), reached through a bridge process."""

    name = "ray"

    def __init__(self, address: str = "auto") -> None:
        self.address = address
        self._ctx = mp.get_context("spawn")
        self._lock = threading.Lock()
        self._send_lock = threading.Lock()
        self._bridge: Any = None  # a PipedChild while connected or connecting
        self._state = "down"
        self._reason: str | None = f"connecting to the Ray cluster at {address!r}"
        self._info: dict[str, Any] = {}
        self._retry_at = 0.0
        self._ids = itertools.count()
        self._workers: dict[int, RayWorker] = {}
        self._calls: dict[int, tuple[int, Future[Any]]] = {}
        self._waiting: list[Any] = []  # messages for a bridge still connecting
        self._closed = False
        self._gone: str | None = None  # why the bridge found the cluster gone
        self._connect()

    # -- the bridge --------------------------------------------------------------------------
    def _connect(self) -> None:
        """Start a bridge (unless one runs or is starting): it connects in the background."""
        with self._lock:
            if self._state != "down" or self._closed:
                return
            self._state = "connecting"
            self._reason = f"connecting to the Ray cluster at {self.address!r}"
        threading.Thread(target=self._run_bridge, name="dexroll-ray-bridge",
                         daemon=True).start()

    def _run_bridge(self) -> None:
        from ..jobs.lifeline import PipedChild

        bridge = PipedChild(self._ctx, _bridge_main, "dexroll-ray-bridge", os.getpid(),
                            self.address)
        reason = "the Ray bridge process did not connect within " \
                 f"{CONNECT_TIMEOUT:g} s"
        self._gone = None
        try:
            if bridge.conn.poll(CONNECT_TIMEOUT):
                kind, payload = bridge.conn.recv()
                if kind == "connected":
                    with self._lock:
                        self._bridge, self._state, self._reason = bridge, "connected", None
                        self._info = dict(payload)
                        waiting, self._waiting = self._waiting, []
                    log.info("connected to the Ray cluster at %s: %s", self.address, payload)
                    for msg in waiting:
                        self._send(msg)
                    self._read(bridge)
                    reason = self._gone or "the Ray bridge process (the cluster's driver) " \
                                           "exited: the cluster may be unreachable"
                else:
                    reason = str(payload)
        except (EOFError, OSError) as exc:
            reason = f"the Ray bridge process failed: {exc!r}"
        bridge.kill()
        self._down(reason)

    def _down(self, reason: str) -> None:
        """The bridge is gone: every worker and call is lost; a new bridge may be
        started :data:`RECONNECT_AFTER` seconds from now."""
        with self._lock:
            self._bridge, self._state, self._reason = None, "down", reason
            self._retry_at = time.monotonic() + RECONNECT_AFTER
            workers, self._workers = list(self._workers.values()), {}
            calls, self._calls = list(self._calls.values()), {}
            self._waiting = []
        if not self._closed:
            log.warning("Ray executor unavailable: %s", reason)
        lost = WorkerLostError(reason)
        for _, future in calls:
            with contextlib.suppress(InvalidStateError):
                future.set_exception(lost)
        for worker in workers:
            worker._died(lost)

    def _read(self, bridge: Any) -> None:
        while True:
            try:
                msg = bridge.conn.recv()
            except (EOFError, OSError):
                return
            kind = msg[0]
            if kind == "result":
                _, call_id, ok, value = msg
                with self._lock:
                    _, future = self._calls.pop(call_id, (None, None))
                resolve(future, ok, value)
            elif kind == "where":
                worker = self._workers.get(msg[1])
                if worker is not None:
                    info = msg[2]
                    worker.pid, worker.host, worker.node = info["pid"], info["host"], \
                        info["node"]
            elif kind == "lost":
                self._lose(msg[1], WorkerLostError(msg[2]))
            elif kind == "cluster":
                with self._lock:
                    self._info.update(msg[1])
            elif kind == "gone":
                self._gone = str(msg[1])

    def _lose(self, wid: int, lost: WorkerLostError) -> None:
        with self._lock:
            worker = self._workers.pop(wid, None)
            calls = [cid for cid, (w, _) in self._calls.items() if w == wid]
            futures = [self._calls.pop(cid)[1] for cid in calls]
        for future in futures:
            with contextlib.suppress(InvalidStateError):
                future.set_exception(lost)
        if worker is not None:
            worker._died(lost)

    def _send(self, msg: Any) -> bool:
        """Send to the bridge (kept while it connects); False when there is none."""
        with self._lock:
            if self._state == "connecting":
                self._waiting.append(msg)
                return True
            bridge = self._bridge
        if bridge is None:
            return False
        try:
            with self._send_lock:
                bridge.conn.send(msg)
        except (OSError, ValueError):
            return False
        return True

    # -- the executor ------------------------------------------------------------------------
    def start(self, body: type, args: tuple[Any, ...], resources: Resources,
              label: str) -> RayWorker:
        if self._state == "down" and time.monotonic() >= self._retry_at:
            self._connect()
        worker = RayWorker(self, next(self._ids), label)
        with self._lock:
            self._workers[worker.id] = worker
        if not self._send(("start", worker.id, body, args, resources.cpus, resources.memory)):
            self._lose(worker.id, WorkerLostError(self._reason or "no Ray bridge"))
        return worker

    def _call(self, worker: RayWorker, method: str, args: tuple[Any, ...]) -> Future[Any]:
        future: Future[Any] = Future()
        if worker.lost is not None:
            future.set_exception(worker.lost)
            return future
        call_id = next(self._ids)
        with self._lock:
            self._calls[call_id] = (worker.id, future)
        if not self._send(("call", worker.id, call_id, method, args)):
            self._lose(worker.id, WorkerLostError(self._reason or "no Ray bridge"))
            if not future.done():
                future.set_exception(worker.lost or WorkerLostError("no Ray bridge"))
        return future

    def _kill(self, worker: RayWorker) -> None:
        self._send(("kill", worker.id))
        self._lose(worker.id, WorkerLostError("killed by the service"))

    def unavailable(self) -> str | None:
        with self._lock:
            return None if self._state == "connected" else self._reason

    def describe(self) -> dict[str, Any]:
        with self._lock:
            return {"name": self.name, "address": self.address, "state": self._state,
                    **self._info, **({"reason": self._reason} if self._reason else {})}

    def close(self) -> None:
        self._closed = True
        with self._lock:
            bridge = self._bridge
        if bridge is not None:
            with contextlib.suppress(OSError, ValueError), self._send_lock:
                bridge.conn.send(None)
            bridge.process.join(timeout=10)
            bridge.kill()
