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

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = ["MIN_ROLL_TIME", "ROLL_RAMP", "RollClock", "fastest_speed"]

FloatArray = NDArray[np.float64]

#: How long a roll's clock takes to reach full speed, and to stop [s] (at most half the
#: roll's own duration).
ROLL_RAMP = 0.2
#: The shortest plateau a fastest roll is run in [s].
MIN_ROLL_TIME = 0.3


@dataclass(frozen=True)
class RollClock:
    """The warped clock of a roll of ``duration`` [s] (its plan's), run at ``speed`` times
    its plan's rate between the ramps: it lasts ``duration / speed + ramp`` [s]. A speed
    above 1 runs the same path faster (:func:`fastest_speed`): every law of the path holds
    as it was certified; the rates scale by the speed, the accelerations by its square
    (plus the ramps' term), and the damping's torques with the rates."""

    duration: float
    ramp: float = ROLL_RAMP
    speed: float = 1.0

    @staticmethod
    def of(duration: float, speed: float = 1.0) -> RollClock:
        return RollClock(duration, min(ROLL_RAMP, duration / speed / 2.0), speed)

    @staticmethod
    def lasting(duration: float, length: float) -> RollClock:
        """The clock of a roll of ``duration`` [s] that lasts ``length`` [s] on the gait's
        clock (slower or faster than planned; its ramps as :meth:`of`'s)."""
        if length - ROLL_RAMP >= 2.0 * ROLL_RAMP:  # the full ramps: D / k + ramp
            return RollClock(duration, ROLL_RAMP, duration / (length - ROLL_RAMP))
        speed = 1.5 * duration / length  # ramps of half the plateau: 1.5 D / k
        return RollClock(duration, duration / speed / 2.0, speed)

    @property
    def length(self) -> float:
        """The roll's duration on the gait's clock [s]."""
        return self.duration / self.speed + self.ramp

    def __call__(self, tau: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """(s, ds/dtau, d2s/dtau2) at the gait's times ``tau`` from the roll's start."""
        s, v, a = self._unit(tau)
        k = self.speed
        return k * s, k * v, k * a

    def _unit(self, tau: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """The clock at unit speed over the plateau ``duration / speed``."""
        d, L, D = self.ramp, self.length, self.duration / self.speed
        t = np.clip(np.asarray(tau, dtype=float), 0.0, L)
        s, v, a = t - d / 2.0, np.ones_like(t), np.zeros_like(t)
        if d <= 0.0:
            return np.clip(t, 0.0, D), v, a
        head, tail = t < d, t > L - d
        x = t[head] / d
        s[head] = d * (x**3 - x**4 / 2.0)
        v[head] = 3 * x**2 - 2 * x**3
        a[head] = (6 * x - 6 * x**2) / d
        y = (L - t[tail]) / d
        s[tail] = D - d * (y**3 - y**4 / 2.0)
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


def fastest_speed(duration: float, qd: FloatArray, qdd: FloatArray, vmax: FloatArray,
                  amax: float, damping: float = 0.0) -> float:
    """The highest speed (at least 1) at which a roll of ``duration`` [s] whose joints'
    rates and accelerations at its plan's times (evenly spaced over ``duration``) are the
    rows ``qd`` and ``qdd`` keeps them within ``vmax`` (per joint) and ``amax`` (every
    joint) on its clock, with its plateau at least :data:`MIN_ROLL_TIME`; ``damping``: the
    rate overrun of the actuators' damping share at speed 1
    (:meth:`~ocp.gait.step.TorqueLimits.damping_overrun`; the speed at most its inverse).
    The accelerations are evaluated on the clock, q'' s'^2 + q' s'' (the ramps' term
    included), at the plan's samples; the speed is found by bisection."""
    v = float(np.max(np.abs(qd) / vmax, initial=0.0))
    top = math.inf if v <= 0 else 1.0 / v
    if damping > 0:
        top = min(top, 1.0 / damping)
    top = min(top, duration / MIN_ROLL_TIME)
    if top <= 1.0:
        return 1.0
    s_grid = np.linspace(0.0, duration, len(qd))

    def peak(speed: float) -> float:
        clock = RollClock.of(duration, speed)
        tau = np.linspace(0.0, clock.length, 4 * len(qd) + 1)
        s, sv, sa = clock(tau)
        d1 = np.stack([np.interp(s, s_grid, c) for c in np.asarray(qd).T], axis=1)
        d2 = np.stack([np.interp(s, s_grid, c) for c in np.asarray(qdd).T], axis=1)
        return float(np.max(np.abs(d2 * sv[:, None] ** 2 + d1 * sa[:, None]), initial=0.0))

    if peak(top) <= amax:
        return top
    if peak(1.0) > amax:
        return 1.0
    lo, hi = 1.0, top
    for _ in range(30):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if peak(mid) <= amax else (lo, mid)
    return lo
