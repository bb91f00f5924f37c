"""Re-plans from a measured state (``POST /v1/plans/{id}/replan``) in processes of their
own, each keeping the re-planners of the plans it re-planned last (issue 28, part 3;
docs/replanning.md "Through the service").

Why not the solver workers: a worker runs one plan at a time, and a plan may take
minutes; a controller's re-plan queued behind it would wait those minutes, and IPOPT
cannot be interrupted to take it in between. Why not the API process: a re-plan holds
the interpreter for its whole IPOPT call (tens of milliseconds to seconds), which every
other route would wait for, and a crash in CasADi would take the API down. So re-plans
have workers of their own (``DEXROLL_REPLAN_PROCESSES``, one by default; each a
:class:`ReplanWorker` started by the service's executor, a spawned process or a Ray actor)
started at the first re-plan: each keeps, per plan (job id and end time), a
:class:`~ocp.solve.replan.Replanner`: the plan's problem, the NLP of its structure with
its warm-start solver, and the plan being executed (the last re-plan), so that the
controller's next call is warm-started from it. A plan's re-plans always go to the same
process (its job id hashed), which holds ``DEXROLL_REPLAN_CACHE`` plans at most (the least
recently re-planned is dropped).

The first re-plan of a plan in a process builds its re-planner: the request planned again,
warm from the stored plan's ``collocation`` block (IPOPT starts at the stored optimum),
which builds the NLP; seconds (``stats.setup_time``). Not every structure its later
re-plans meet (:meth:`~ocp.solve.replan.Replanner.prepare`): a plan with via-points meets
a new one almost every call (docs/replanning.md, "Through the service"), more than the
planner's NLP cache keeps. Only then does the service send the
stored plan: a call whose plan the process holds sends the measurement alone.

A call waits for its process's previous one (at most ``DEXROLL_REPLAN_QUEUE`` wait: 503
beyond); past its deadline (its time limit plus, on a first call, the setup's
``DEXROLL_REPLAN_SETUP_LIMIT``) the process is killed and replaced, and the call refused
(503).
"""

from __future__ import annotations

import logging
import threading
import time
import zlib
from collections import OrderedDict
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any

from ..executors import Executor, Resources, Worker, WorkerError, WorkerLostError

__all__ = ["ReplanPool", "ReplanRefusedError"]

log = logging.getLogger("dexroll.replans")

#: Time a new re-plan process may take to import CasADi and the planners [s].
START_TIMEOUT = 120.0
#: Added to a call's IPOPT time limit for the estimate, the answer's samples and the
#: pipes [s].
CALL_MARGIN = 5.0

#: (job id, the job's end time[, a controller's backend]): a plan as a process keeps it.
Key = tuple[str, float | None] | tuple[str, float | None, str]


class ReplanRefusedError(Exception):
    """A re-plan not answered: ``status`` and ``error`` as the API answers, ``detail``
    [(field, reason)] for a 422, ``retry_after`` [s] when a retry may succeed."""

    def __init__(self, status: int, error: str, message: str,
                 detail: list[tuple[str, str]] | None = None,
                 retry_after: int | None = None) -> None:
        super().__init__(message)
        self.status, self.error, self.message = status, error, message
        self.detail, self.retry_after = detail or [], retry_after


class ReplanWorker:
    """A re-plan worker's body: it keeps, per kind of call, the sessions of the plans it
    served last (re-planners, window controllers; ``cache_size`` each, the least recently
    used dropped) and answers each call with ("ok", answer JSON), ("need", None) (no
    session of that plan here yet: send the stored plan), or (error kind, payload)."""

    def __init__(self, cache_size: int, time_cap: float) -> None:
        from dexroll_client.control import ControlAnswer, ControlMeasurement
        from dexroll_client.replan import ReplanRequest, ReplanResult

        from ..execution.closed_loop import ReplanSession, TrackingSession

        self.cache_size, self.time_cap = cache_size, time_cap
        #: per kind of call: its body and answer types, its session type
        self.kinds: dict[str, tuple[Any, Any, Any]] = {
            "replan": (ReplanRequest, ReplanResult, ReplanSession),
            "control": (ControlMeasurement, ControlAnswer, TrackingSession)}
        self.sessions: dict[str, OrderedDict[Key, Any]] = {k: OrderedDict()
                                                           for k in self.kinds}

    def ready(self) -> None:
        """The worker is up (CasADi and the planners imported)."""

    def handle(self, kind: str, key: Key, body_json: str, result_json: str | None,
               request_json: str | None) -> tuple[str, Any]:
        """One call of ``kind`` for the plan ``key``; ``result_json`` and
        ``request_json``: the stored plan, sent only when asked for ("need")."""
        from ..execution.closed_loop import replannable
        from ..planners import REQUEST, RESULT

        body_type, answer_type, session_type = self.kinds[kind]
        held = self.sessions[kind]
        try:
            body = body_type.model_validate_json(body_json)
            setup = 0.0
            session = held.get(key)
            if session is None:
                if result_json is None or request_json is None:
                    return "need", None
                t0 = time.perf_counter()
                request = REQUEST.validate_json(request_json)
                result = RESULT.validate_json(result_json)
                why = replannable(request, result)
                if why is not None:
                    return "not_replannable", why
                try:  # (a controller's key ends with its backend)
                    session = session_type(request, result, *key[2:]) \
                        if kind == "control" else session_type(request, result)
                except ValueError as exc:
                    return "not_replannable", (f"its request cannot be planned again "
                                               f"here: {exc}")
                held[key] = session
                while len(held) > self.cache_size:
                    held.popitem(last=False)
                setup = time.perf_counter() - t0
                log.info("%s session of job %s built in %.2f s", kind, key[0], setup)
            held.move_to_end(key)
            if kind == "control":
                reply, payload = session.tick(body, setup)
            else:
                reply, payload = session.replan(key[0], body, setup, self.time_cap)
            if reply == "ok":
                payload = answer_type.model_validate(payload).model_dump_json()
            return reply, payload
        except ValueError as exc:  # a measurement the estimate refuses (shapes)
            return "invalid", [("q", str(exc))]
        except Exception as exc:  # a typed answer, never a dead worker
            log.exception("%s failed", kind)
            return "replan_failed", f"the {kind} call failed: {exc!r}"


class _Slot:
    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.worker: Worker | None = None


#: How each reply other than an answer is refused: (status, error).
_REPLIES = {"invalid": (422, "invalid_request"), "unexplained": (422, "unexplained_state"),
            "not_replannable": (409, "not_replannable"),
            "replan_failed": (503, "replan_failed")}


class ReplanPool:
    """``processes`` re-plan processes (started at their first call), each keeping
    ``cache_size`` plans' re-planners; ``max_waiting`` calls wait at most; a call's IPOPT
    time limit is capped at ``time_cap`` [s], a first call's setup given ``setup_limit``
    [s]."""

    #: Retry-After of a busy pool [s].
    RETRY_AFTER = 1

    def __init__(self, processes: int = 1, cache_size: int = 8, max_waiting: int = 8,
                 time_cap: float = 10.0, setup_limit: float = 300.0,
                 executor: Executor | None = None) -> None:
        self.cache_size, self.max_waiting = cache_size, max_waiting
        self.time_cap, self.setup_limit = time_cap, setup_limit
        if executor is None:
            from ..executors.local import LocalProcesses

            executor = LocalProcesses()
        self.work = executor
        self._slots = [_Slot() for _ in range(processes)]
        self._lock = threading.Lock()
        self._waiting = 0
        self._closed = False
        #: the threads the API's calls wait in (never the event loop's default executor,
        #: which the other routes' store reads share)
        self.executor = ThreadPoolExecutor(max_workers=processes + max_waiting + 1,
                                           thread_name_prefix="dexroll-replan")

    def stats(self) -> dict[str, int]:
        with self._lock:
            return {"waiting": self._waiting, "processes": len(self._slots)}

    def close(self) -> None:
        with self._lock:
            self._closed = True
        for slot in self._slots:
            with slot.lock:
                if slot.worker is not None:
                    slot.worker.kill()
                    slot.worker = None
        self.executor.shutdown(wait=False, cancel_futures=True)

    def call(self, key: Key, body_json: str, time_limit: float,
             fetch: Callable[[], tuple[str, str]], kind: str = "replan") -> str:
        """One re-plan of the plan ``key`` (blocking: run it in a thread): its answer (the
        ReplanResult's JSON, as the process wrote it), or
        ReplanRefusedError. ``fetch`` gives the stored (result, request) JSON when the
        process does not hold the plan yet. ``kind`` "control": one tick of the plan's
        window controller (a ControlMeasurement's JSON; the ControlAnswer's)."""
        with self._lock:
            if self._closed:
                raise ReplanRefusedError(503, "shutting_down", "the service is stopping",
                                         retry_after=self.RETRY_AFTER)
            if self._waiting >= self.max_waiting:
                raise ReplanRefusedError(
                    503, "replans_busy", f"{self._waiting} re-plans wait already (at most "
                                         f"{self.max_waiting}: DEXROLL_REPLAN_QUEUE)",
                    retry_after=self.RETRY_AFTER)
            self._waiting += 1
        slot = self._slots[zlib.crc32(key[0].encode()) % len(self._slots)]
        with slot.lock:
            with self._lock:
                self._waiting -= 1
            if slot.worker is None:
                slot.worker = self._start()
            budget = min(time_limit, self.time_cap) + CALL_MARGIN
            reply, payload = self._exchange(slot, (kind, key, body_json, None, None), budget)
            if reply == "need":
                result_json, request_json = fetch()
                reply, payload = self._exchange(
                    slot, (kind, key, body_json, result_json, request_json),
                    budget + self.setup_limit)
        if reply == "ok":
            return str(payload)
        status, error = _REPLIES.get(reply, (503, "replan_failed"))
        if reply in ("invalid", "unexplained"):
            detail = [(str(f), str(r)) for f, r in payload]
            message = "; ".join(f"{f}: {r}" for f, r in detail)
            if reply == "unexplained":
                message = f"the grasp cannot explain the measured state: {message}"
            raise ReplanRefusedError(status, error, message, detail)
        raise ReplanRefusedError(status, error, str(payload))

    def _start(self) -> Worker:
        worker = self.work.start(ReplanWorker, (self.cache_size, self.time_cap),
                                 Resources(cpus=1.0), "replan")
        try:
            worker.call("ready").result(timeout=START_TIMEOUT)
        except (TimeoutError, WorkerLostError, WorkerError) as exc:
            worker.kill()
            raise ReplanRefusedError(503, "replan_unavailable",
                                     f"the re-plan worker did not start: {exc}",
                                     retry_after=self.RETRY_AFTER) from exc
        return worker

    def _exchange(self, slot: _Slot, msg: tuple[Any, ...], budget: float
                  ) -> tuple[str, Any]:
        """One call of the slot's worker, waited for at most ``budget`` [s]; past it the
        worker is killed (and replaced at the next call)."""
        worker = slot.worker
        assert worker is not None
        try:
            kind, payload = worker.call("handle", *msg).result(timeout=budget)
            return str(kind), payload
        except TimeoutError as exc:
            worker.kill()
            slot.worker = None
            raise ReplanRefusedError(
                503, "replan_time_limit", f"the re-plan did not answer within {budget:g} s "
                "(its time limit and margin, and a first call's setup: "
                "DEXROLL_REPLAN_SETUP_LIMIT); its worker was replaced",
                retry_after=self.RETRY_AFTER) from exc
        except (WorkerLostError, WorkerError) as exc:
            worker.kill()
            slot.worker = None
            raise ReplanRefusedError(503, "replan_failed", f"the re-plan worker failed "
                                     f"({exc}); it is replaced",
                                     retry_after=self.RETRY_AFTER) from exc
