"""A roll's clock in a gait (docs/gait.md, "Rolls start and end still"): the roll's plan
(smooth timing: at rest at both ends, but with the joints accelerating from its first
instant) run on a warped clock, so that it joins the still phases around it with
continuous accelerations.

The roll's plan x(s), s in [0, D], is executed as x(phi(tau)), tau in [0, D + ramp]: phi's
rate phi' rises from 0 to 1 over ``ramp`` seconds (smoothstep), stays 1, and falls back to 0
over the last ``ramp``. The path is the plan's, so every law of the roll that is a path's
(no slip, no spin, the closure, the contacts, the quasi-static forces: each is a function of
the configuration or is homogeneous in the velocities) holds as it was certified; the
rates are the plan's times phi' (never larger), the accelerations q''(s) phi'^2 + q'(s) phi''
(zero at both ends, where q' and phi' are: continuous with a hold's), checked densely
against the joints' limit by the gait's certificate.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = ["ROLL_RAMP", "RollClock"]

FloatArray = NDArray[np.float64]

#: How long a roll's clock takes to reach full speed, and to stop [s] (at most half the
#: roll's own duration).
ROLL_RAMP = 0.2


@dataclass(frozen=True)
class RollClock:
    """The warped clock of a roll of ``duration`` [s] (its plan's): it lasts ``duration +
    ramp`` [s]."""

    duration: float
    ramp: float = ROLL_RAMP

    @staticmethod
    def of(duration: float) -> RollClock:
        return RollClock(duration, min(ROLL_RAMP, duration / 2.0))

    @property
    def length(self) -> float:
        """The roll's duration on the gait's clock [s]."""
        return self.duration + self.ramp

    def __call__(self, tau: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """(s, ds/dtau, d2s/dtau2) at the gait's times ``tau`` from the roll's start."""
        d, L = self.ramp, self.length
        t = np.clip(np.asarray(tau, dtype=float), 0.0, L)
        s, v, a = t - d / 2.0, np.ones_like(t), np.zeros_like(t)
        if d <= 0.0:
            return np.clip(t, 0.0, self.duration), v, a
        head, tail = t < d, t > L - d
        x = t[head] / d
        s[head] = d * (x**3 - x**4 / 2.0)
        v[head] = 3 * x**2 - 2 * x**3
        a[head] = (6 * x - 6 * x**2) / d
        y = (L - t[tail]) / d
        s[tail] = self.duration - d * (y**3 - y**4 / 2.0)
        v[tail] = 3 * y**2 - 2 * y**3
        a[tail] = -(6 * y - 6 * y**2) / d
        return s, v, a

    def tau_of(self, s: float) -> float:
        """The time on this clock [s] at which the plan's time ``s`` is reached."""
        tau = np.linspace(0.0, self.length, 2001)
        return float(np.interp(s, self(tau)[0], tau))

    def joints(self, q: FloatArray, qd: FloatArray, qdd: FloatArray, v: FloatArray,
               a: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """The joints on this clock from the plan's (rows) at s(tau), with ds/dtau ``v``
        and d2s/dtau2 ``a``: (q, q' v, q'' v^2 + q' a)."""
        v, a = v[:, None], a[:, None]
        return q, qd * v, qdd * v * v + qd * a
