"""The solvers of a controller's window behind one interface (issue 41; docs/control.md).

A window (:class:`~ocp.control.window.WindowController`) is solved once per tick, within an
iteration budget, from the previous window's point. Every solver does it through
:class:`WindowBackend`:

* ``prepare(s, w)``: work that can be done before the tick's state is measured, at the
  window's guess ``w`` for the setup ``s`` it will have (its parameters: the reference at
  the tick's time); the wall time [s] it took (``prepares`` False: nothing to prepare);
* ``unsupported(s)``: why it cannot solve the window ``s`` (None: it can);
* ``solve(s, w0, point, deadline, max_iter)``: the tick itself, the measured state in
  ``s``'s bounds, from ``w0`` and the previous window's primal-dual ``point``: the run
  (:class:`~ocp.solve.attempt.IpoptRun`, the status in our :class:`~ocp.solution.Status`:
  each backend maps its solver's own codes) and the residuals it left (primal, dual; None
  where a backend has no such measure).

The backends, by name (:data:`WINDOW_BACKENDS`, :func:`window_backend`):

* ``"ipopt"`` (:class:`IpoptWindow`): the collocation window's NLP, IPOPT warm from the
  previous window's multipliers (:func:`~ocp.solve.ipopt.realtime_solver`; statuses by
  :func:`~ocp.solution.status_from_ipopt`); a whole plan's solver choice, IPOPT or fatrop
  (``ManipulationPlanner(solver=...)``), is the planner's;
* ``"rti"`` (:class:`~ocp.solve.rti.RtiBackend`): real-time iterations of the window by
  multiple shooting, QPs by HPIPM (statuses by :data:`~ocp.solve.rti.HPIPM_STATUS`); its
  preparation linearises the window before the measurement.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np
from numpy.typing import NDArray

from ocp.solve.ipopt import kkt_residuals, realtime_solver
from ocp.solve.rti import RtiBackend

if TYPE_CHECKING:
    from ocp.solve.attempt import IpoptRun, Setup
    from ocp.transcription.collocation import NlpPoint

__all__ = ["WINDOW_BACKENDS", "IpoptWindow", "WindowBackend", "window_backend"]

FloatArray = NDArray[np.float64]


class WindowBackend(Protocol):
    """A window's solver (see the module): its ``name``; whether its ``prepare`` does any
    work (``prepares``: the controller then predicts the next window's start for it); why
    it cannot solve a window (``unsupported``: None when it can)."""

    name: str
    prepares: bool

    def unsupported(self, s: Setup) -> str | None:
        ...

    def prepare(self, s: Setup, w: FloatArray) -> float:
        ...

    def solve(self, s: Setup, w0: FloatArray, point: NlpPoint | None, deadline: float,
              max_iter: int) -> tuple[IpoptRun, float | None, float | None]:
        ...


class IpoptWindow:
    """IPOPT on the collocation window, warm from the previous window's primal-dual point
    (:func:`~ocp.solve.ipopt.realtime_solver`: ``gauss_newton``, ``push``); nothing to
    prepare; the residuals are the KKT conditions' (:func:`~ocp.solve.ipopt.kkt_residuals`)."""

    name = "ipopt"
    prepares = False

    def __init__(self, gauss_newton: bool = False, push: float | None = None) -> None:
        self.gauss_newton, self.push = gauss_newton, push

    @staticmethod
    def unsupported(s: Setup) -> str | None:
        return None

    def prepare(self, s: Setup, w: FloatArray) -> float:
        return 0.0

    def solve(self, s: Setup, w0: FloatArray, point: NlpPoint | None, deadline: float,
              max_iter: int) -> tuple[IpoptRun, float | None, float | None]:
        from ocp.solve.attempt import run

        r = run(s, w0, point, deadline, max_iter,
                solver=realtime_solver(s.nlp, self.gauss_newton, self.push))
        if r.point is None:
            return r, None, None
        primal, dual = kkt_residuals(s.nlp, r.point.w, s.p, r.point.lam_g, r.point.lam_x,
                                     s.lbx, s.ubx)
        return r, primal, dual


#: The window backends by name (``ControllerOptions.backend``), each made from the
#: controller's options (``gauss_newton``, ``warm_push``) and the planner's ``compile_dir``
#: (IPOPT's window compiles with the planner's NLP)
WINDOW_BACKENDS: dict[str, Callable[..., Any]] = {
    "ipopt": lambda gauss_newton=False, warm_push=None, compile_dir=None:
        IpoptWindow(gauss_newton, warm_push),
    "rti": lambda gauss_newton=False, warm_push=None, compile_dir=None:
        RtiBackend(compile_dir=compile_dir),
}


def window_backend(name: str, **options: Any) -> WindowBackend:
    """The backend called ``name`` (:data:`WINDOW_BACKENDS`)."""
    try:
        make = WINDOW_BACKENDS[name]
    except KeyError:
        raise ValueError(f"unknown window backend {name!r}: one of "
                         f"{tuple(WINDOW_BACKENDS)}") from None
    backend: WindowBackend = make(**options)
    return backend
