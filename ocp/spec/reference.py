"""A reference trajectory a plan tracks: the window of a longer plan a controller
re-solves at a fixed rate (:mod:`ocp.control`).

A problem with a :class:`Reference` has two more objective terms (its NLP structure has
them; the rest of the problem is unchanged): the states' squared distance from the
reference's at every collocation point (Simpson's rule over the window, the last node
weighted ``terminal_weight`` more: the window's terminal condition, soft, so that a
disturbed start that cannot reach the reference's end in the window still has a plan),
and the inputs' at every collocation point, both in the NLP's scaled units (states by the
object's size, inputs by the horizon), so that one weight fits every grasp.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

__all__ = ["Reference"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Reference:
    """States ``x`` (k, nx) and inputs ``u`` (k, nu) at increasing times ``t`` (k,) [s]
    from 0 (the window's own clock; physical units, the grasp's layouts), linearly
    interpolated at the grid's points (give them at the grid's nodes and midpoints to
    have them exactly). Weights: ``state_weight`` and ``input_weight`` of the tracking
    terms, ``terminal_weight`` the last node's extra state weight."""

    t: FloatArray = field(repr=False)
    x: FloatArray = field(repr=False)
    u: FloatArray = field(repr=False)
    state_weight: float = 1e4
    input_weight: float = 1.0
    terminal_weight: float = 10.0
    #: each state's weight (nx, relative; None: all 1): a controller weighs the object's
    #: pose, which the task is about, above the joints and contact coordinates
    state_weights: tuple[float, ...] | None = None

    def errors(self, nx: int, nu: int, duration: float) -> list[tuple[str, str]]:
        """(field, reason) pairs; empty when it fits a grasp of ``nx`` states and ``nu``
        inputs over ``duration``."""
        t, x, u = (np.asarray(a, dtype=float) for a in (self.t, self.x, self.u))
        errs: list[tuple[str, str]] = []
        if t.ndim != 1 or t.size < 2 or not np.all(np.isfinite(t)) \
                or np.any(np.diff(t) <= 0) or abs(t[0]) > 1e-12 \
                or t[-1] < duration * (1 - 1e-9):
            errs.append(("reference.t", f"must be increasing times from 0 to the duration "
                                        f"({duration} s) at least"))
        if x.shape != (t.size, nx) or not np.all(np.isfinite(x)):
            errs.append(("reference.x", f"must be {t.size} x {nx} finite states"))
        if u.shape != (t.size, nu) or not np.all(np.isfinite(u)):
            errs.append(("reference.u", f"must be {t.size} x {nu} finite inputs"))
        qx = self.state_weights
        if qx is not None and not (len(qx) == nx and all(math.isfinite(v) and 0.0 <= v <= 1e8
                                                         for v in qx)):
            errs.append(("reference.state_weights", f"must be {nx} weights in [0, 1e8]"))
        for name in ("state_weight", "input_weight", "terminal_weight"):
            w = getattr(self, name)
            if not (math.isfinite(w) and 0.0 <= w <= 1e8):
                errs.append((f"reference.{name}", f"must be in [0, 1e8], got {w}"))
        return errs

    def at(self, ts: FloatArray) -> tuple[FloatArray, FloatArray]:
        """(states, inputs) at times ``ts``, linearly interpolated (taken as they are at
        the reference's own times)."""
        x, u = np.asarray(self.x, dtype=float), np.asarray(self.u, dtype=float)
        ts = np.asarray(ts, dtype=float)
        idx = np.clip(np.searchsorted(self.t, ts), 0, len(self.t) - 1)
        if np.array_equal(np.asarray(self.t)[idx], ts):  # the grid's own points
            return x[idx], u[idx]

        def lerp(v: FloatArray) -> FloatArray:
            return np.column_stack([np.interp(ts, self.t, v[:, j]) for j in range(v.shape[1])])

        return lerp(x), lerp(u)
