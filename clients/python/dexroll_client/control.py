"""The wire contract of a controller session on a finished plan
(``WebSocket /v1/plans/{id}/control``, docs/control.md "Through the service"), and the
client's controller object.

A robot executing a finished job's rolling plan opens the session once, then sends each
tick's measurement (time on the plan's clock, each finger's joint angles, the object's
pose) as one JSON message and gets the tick's answer: the next window of the plan from
that state (every finger's joint angles and rates at the window's collocation points,
times from the measured instant), the tick's status and its KKT residuals, and the
service's own times. The session keeps the window controller (its NLP, the previous
window's primal-dual point) between ticks, in the service's re-plan processes. A
measurement that does not fit the plan, or a state the grasp cannot explain, is answered
with an ``error`` message naming the field, and the session goes on.

Import from :mod:`dexroll_client.control`::

    with DexrollClient.from_url(url).controller(job_id) as ctl:
        while running:
            answer = ctl.tick(t, q, object_position, object_wxyz)
            robot.follow(answer.t + np.asarray(answer.window.t), answer.window.q)
"""

from __future__ import annotations

import json
import time
from typing import Annotated, Any, Literal

from pydantic import Field

from dexroll_client.common import (
    MAX_DURATION,
    MAX_FINGER_JOINTS,
    MAX_FINGERS,
    MAX_POSITION,
    Real,
    _Request,
    _Response,
)

__all__ = ["ControlAnswer", "ControlError", "ControlMeasurement", "ControlSession",
           "ControlWindow"]

_Coordinate = Annotated[Real, Field(ge=-MAX_POSITION, le=MAX_POSITION)]
_Joints = Annotated[list[Annotated[Real, Field(ge=-100.0, le=100.0)]],
                    Field(min_length=1, max_length=MAX_FINGER_JOINTS)]


class ControlMeasurement(_Request):
    """One tick's measurement."""

    t: Real = Field(ge=0.0, le=MAX_DURATION, description="time on the plan's clock [s]")
    q: list[_Joints] = Field(min_length=1, max_length=MAX_FINGERS,
                             description="each finger's measured joint angles [rad] (the "
                                         "plan's finger and joint order), less any squeeze "
                                         "your executor adds on top of the plan")
    object_position: list[_Coordinate] = Field(min_length=3, max_length=3,
                                               description="[m], palm frame")
    object_wxyz: list[Annotated[Real, Field(ge=-1.5, le=1.5)]] = Field(
        min_length=4, max_length=4, description="the object's orientation (w, x, y, z)")


class ControlWindow(_Response):
    """The window from the measured instant: its collocation points."""

    t: list[float] = Field(description="times from the measured instant [s]")
    q: list[list[list[float]]] = Field(description="per finger, per time: joint angles [rad]")
    q_dot: list[list[list[float]]] = Field(description="per finger, per time: rates [rad/s]")
    object_position: list[list[float]] = Field(description="per time [m]")


class ControlAnswer(_Response):
    """One tick's answer."""

    t: float
    status: Literal["tracked", "converged", "failed"]
    iterations: int
    primal_infeasibility: float | None = None
    dual_infeasibility: float | None = None
    solve_time: float = Field(description="IPOPT [s]")
    estimate_time: float = Field(description="the grasp's state from the measurement [s]")
    wall_time: float = Field(description="the whole tick in the service's process [s]")
    setup_time: float = Field(default=0.0,
                              description="a session's first tick: building its controller")
    window: ControlWindow | None = None


class ControlError(Exception):
    """A tick the service refused (the session goes on): ``error`` and ``detail``
    [(field, reason)]."""

    def __init__(self, error: str, message: str, detail: list[tuple[str, str]]) -> None:
        super().__init__(message)
        self.error, self.message, self.detail = error, message, detail


class ControlSession:
    """An open controller session (:meth:`DexrollClient.controller`): :meth:`tick` sends a
    measurement and waits for its answer; ``round_trips`` [s] the client's time per tick
    (the answer's ``wall_time`` is the service's process's: the difference is the
    transport and the API's share)."""

    def __init__(self, url: str, headers: dict[str, str], open_timeout: float = 30.0
                 ) -> None:
        try:
            from websockets.exceptions import InvalidHandshake
            from websockets.sync.client import connect
        except ImportError as exc:
            raise ImportError("the controller session needs the websockets package: "
                              "pip install 'dexroll-client[control]'") from exc

        try:
            self._cm = connect(url, additional_headers=headers, open_timeout=open_timeout,
                               max_size=None)
            self._ws = self._cm.__enter__()
        except InvalidHandshake as exc:  # the service closed it before the handshake
            raise ControlError("rejected", f"the session was refused: {exc} (an unknown "
                                           "job, one not finished or not a rolling plan, "
                                           "an unknown backend, a missing API key)",
                               []) from exc
        self.round_trips: list[float] = []

    def tick(self, t: float, q: Any, object_position: Any, object_wxyz: Any,
             timeout: float = 300.0) -> ControlAnswer:
        body = ControlMeasurement(t=t, q=[list(map(float, row)) for row in q],
                                  object_position=list(map(float, object_position)),
                                  object_wxyz=list(map(float, object_wxyz)))
        t0 = time.perf_counter()
        self._ws.send(body.model_dump_json())
        raw = self._ws.recv(timeout=timeout)
        self.round_trips.append(time.perf_counter() - t0)
        data = json.loads(raw)
        if "error" in data:
            raise ControlError(str(data["error"]), str(data.get("message", "")),
                               [(str(d["field"]), str(d["reason"]))
                                for d in data.get("detail") or []])
        return ControlAnswer.model_validate(data)

    def close(self) -> None:
        self._cm.__exit__(None, None, None)

    def __enter__(self) -> ControlSession:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
