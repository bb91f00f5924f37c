"""What the object should do: poses, a desired motion interpolated on SE(3), and how hard
the planner tracks it."""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ocp.geometry.rotations import (
    axis_angle_rotation,
    log_rotation,
    quaternion_matrix,
    quaternion_wxyz,
)
from ocp.geometry.surfaces import rotation_from_vector
from ocp.spec.problem import MAX_POSITION

__all__ = ["DesiredMotion", "MotionStep", "ObjectPose", "Tracking"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class ObjectPose:
    """A pose of the object in the palm frame: orientation quaternion (w, x, y, z) and
    position [m]."""

    orientation: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)
    position: tuple[float, float, float] = (0.0, 0.0, 0.0)

    @property
    def rotation(self) -> FloatArray:
        return quaternion_matrix(self.orientation)

    def errors(self, name: str) -> list[tuple[str, str]]:
        errs: list[tuple[str, str]] = []
        q = self.orientation
        if len(q) != 4 or not all(map(math.isfinite, q)) or \
                not 0.5 < math.sqrt(sum(c * c for c in q)) < 1.5:
            errs.append((f"{name}.orientation",
                         "must be a unit quaternion (w, x, y, z) of 4 finite numbers"))
        p = self.position
        if len(p) != 3 or not all(math.isfinite(c) and abs(c) <= MAX_POSITION for c in p):
            errs.append((f"{name}.position",
                         f"must be 3 finite numbers within +-{MAX_POSITION} m"))
        return errs


@dataclass(frozen=True)
class MotionStep:
    """One step of a desired object motion: over ``duration`` [s], rotate by ``angle``
    [rad] about ``axis`` (a direction in the palm frame, through the object's centre) and
    translate its centre by ``translation`` [m] (palm frame)."""

    duration: float
    axis: tuple[float, float, float] = (0.0, 0.0, 1.0)
    angle: float = 0.0
    translation: tuple[float, float, float] = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class DesiredMotion:
    """A desired object trajectory: poses at knot times, interpolated on SE(3).

    Between knots the orientation follows the geodesic (constant axis) and the position
    the straight line, both with the same time scaling: ``smooth`` (the default) eases in
    and out (3 s^2 - 2 s^3, zero velocity at every knot), else constant rate.
    """

    times: tuple[float, ...]
    orientations: tuple[tuple[float, float, float, float], ...]
    positions: tuple[tuple[float, float, float], ...]
    smooth: bool = True
    #: The motion's time at the plan's t = 0 [s]: a plan of the rest of the motion (a
    #: re-plan part-way, :meth:`~ocp.spec.grasp.ManipulationProblem.remaining`) follows
    #: the same poses, ``at(t)`` being the motion's at ``t + t0``.
    t0: float = 0.0

    @staticmethod
    def from_steps(start: ObjectPose, steps: Sequence[MotionStep], smooth: bool = True
                   ) -> DesiredMotion:
        """The motion made of ``steps`` one after the other from ``start`` (the paper's
        "rotate about Z by 20 deg, then about Y by 20 deg, ...")."""
        R, p, t = start.rotation, np.asarray(start.position, dtype=float), 0.0
        times, quats, pos = [0.0], [tuple(quaternion_wxyz(R))], [tuple(p)]
        for s in steps:
            t += float(s.duration)
            if s.angle != 0.0:
                R = axis_angle_rotation(s.axis, s.angle) @ R
            p = p + np.asarray(s.translation, dtype=float)
            times.append(t)
            quats.append(tuple(quaternion_wxyz(R)))
            pos.append(tuple(p))
        return DesiredMotion(tuple(times), tuple(quats), tuple(pos), smooth)

    def errors(self, name: str, duration: float) -> list[tuple[str, str]]:
        errs: list[tuple[str, str]] = []
        n = len(self.times)
        if n < 2 or len(self.orientations) != n or len(self.positions) != n:
            return [(name, "needs at least 2 knots, with as many orientations and positions "
                           f"as times (got {n}, {len(self.orientations)}, "
                           f"{len(self.positions)})")]
        ts = self.times
        if not all(map(math.isfinite, ts)) or ts[0] != 0.0 or \
                any(b <= a for a, b in itertools.pairwise(ts)):
            errs.append((f"{name}.times", "must start at 0 and increase strictly"))
        elif abs(ts[-1] - self.t0 - duration) > 1e-9 * max(1.0, duration + self.t0):
            errs.append((f"{name}.times",
                         f"must end at the duration {duration} s"
                         + (f" after {self.t0} s" if self.t0 else "") + f", got {ts[-1]}"))
        if not (math.isfinite(self.t0) and 0.0 <= self.t0 < ts[-1]):
            errs.append((f"{name}.t0", f"must be in [0, {ts[-1]}) s, got {self.t0}"))
        for i, q in enumerate(self.orientations):
            errs += ObjectPose(q, self.positions[i]).errors(f"{name}[{i}]")
        return errs

    @cached_property
    def _knots(self) -> tuple[FloatArray, list[FloatArray], FloatArray, list[FloatArray]]:
        """The knots' times, rotations, positions, and the rotation vector from each
        knot's orientation to the next's (object frame), made once: a guess asks
        :meth:`at` thousands of times."""
        Rk = [quaternion_matrix(q) for q in self.orientations]
        return (np.asarray(self.times, dtype=float), Rk,
                np.asarray(self.positions, dtype=float),
                [log_rotation(Rk[j].T @ Rk[j + 1]) for j in range(len(Rk) - 1)])

    def at(self, t: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """(R (k, 3, 3), p (k, 3)) at the plan's times t (the motion's t + t0, clipped to
        the knots' span)."""
        ts, Rk, Pk, logs = self._knots
        tq = np.clip(np.atleast_1d(np.asarray(t, dtype=float)) + self.t0, ts[0], ts[-1])
        j = np.clip(np.searchsorted(ts, tq, side="right") - 1, 0, len(ts) - 2)
        s = (tq - ts[j]) / (ts[j + 1] - ts[j])
        if self.smooth:
            s = s * s * (3 - 2 * s)
        R = np.empty((len(tq), 3, 3))
        for i, (jj, ss) in enumerate(zip(j, s, strict=True)):
            R[i] = Rk[jj] @ rotation_from_vector(ss * logs[jj])
        p = Pk[j] + s[:, None] * (Pk[j + 1] - Pk[j])
        return R, p


@dataclass(frozen=True)
class Tracking:
    """How hard the object follows a :class:`DesiredMotion`.

    The weights multiply the integrals over normalised time of |p - p_d|^2 / L^2 and of
    1 - cos(angle between R and R_d); ``*_tolerance`` (when given) are hard bounds [m],
    [rad] on the errors at every instant (checked by the certificate between collocation
    points too).
    """

    position_weight: float = 1e4
    orientation_weight: float = 1e4
    position_tolerance: float | None = None
    orientation_tolerance: float | None = None
