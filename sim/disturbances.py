"""Disturbances of a run (docs/simulation.md, "Disturbances"): what the world does that
the plan did not expect, for open-loop and closed-loop runs alike.

* a **push** ``(time, dx, dy, dz)``: the object displaced by (dx, dy, dz) [m] in the palm
  frame at ``time`` [s] on the plan's clock, as a **kinematic shift** (its position set
  that far in one step, its velocity and orientation kept): exactly the displacement
  asked, whatever the grip resists (an impulse's displacement would depend on the
  contacts' friction);
* an **impulse** ``(time, px, py, pz)`` [N s]: the object's velocity changed by p / m at
  ``time`` (what the contacts then make of it is the simulation's);
* ``friction_scale``: every contact's friction coefficient times this (the plan's mu is
  unchanged: the planner believes its own);
* ``size_change`` [m]: added to every semi-axis of the object (a ball 1 mm larger in
  diameter: 0.5e-3), ``mass_scale``: its mass times this; the plan and its models keep
  the planned object;
* ``pose_noise`` (position [m], angle [rad]): the standard deviations of Gaussian noise on
  the object's pose as the controller measures it (closed loop only: an open-loop run
  measures nothing), drawn with ``seed``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from .run import StepRows
from .spec import ExecutionPlan

__all__ = ["Disturbances", "Kick", "parse_kick"]


@dataclass(frozen=True)
class Kick:
    """A push (a displacement [m]) or an impulse [N s] at ``time`` [s], palm frame."""

    time: float
    vector: tuple[float, float, float]

    def to_dict(self) -> dict[str, Any]:
        return {"time": self.time, "vector": list(self.vector)}


def parse_kick(text: str) -> Kick:
    """``TIME,X,Y,Z`` as a :class:`Kick` (ValueError naming what is wrong)."""
    parts = [p.strip() for p in str(text).split(",")]
    if len(parts) != 4:
        raise ValueError(f"{text!r}: expected TIME,X,Y,Z (four numbers)")
    try:
        t, x, y, z = (float(p) for p in parts)
    except ValueError as exc:
        raise ValueError(f"{text!r}: expected TIME,X,Y,Z (four numbers)") from exc
    if not all(math.isfinite(v) for v in (t, x, y, z)):
        raise ValueError(f"{text!r}: the numbers must be finite")
    return Kick(t, (x, y, z))


def _kicks(raw: Any) -> tuple[Kick, ...]:
    out = []
    for k in raw or ():
        if isinstance(k, Kick):
            out.append(k)
        elif isinstance(k, str):
            out.append(parse_kick(k))
        elif isinstance(k, dict):
            v = [float(a) for a in k["vector"]]
            out.append(Kick(float(k["time"]), (v[0], v[1], v[2])))
        else:
            t, x, y, z = (float(a) for a in k)
            out.append(Kick(t, (x, y, z)))
    return tuple(out)


@dataclass(frozen=True)
class Disturbances:
    """See the module."""

    pushes: tuple[Kick, ...] = ()
    impulses: tuple[Kick, ...] = ()
    friction_scale: float = 1.0
    size_change: float = 0.0
    mass_scale: float = 1.0
    pose_noise: tuple[float, float] = (0.0, 0.0)
    seed: int = 0
    notes: tuple[str, ...] = field(default=())

    @staticmethod
    def from_dict(raw: dict[str, Any] | None) -> Disturbances:
        raw = dict(raw or {})
        unknown = set(raw) - {"pushes", "impulses", "friction_scale", "size_change",
                              "mass_scale", "pose_noise", "seed"}
        if unknown:
            raise ValueError(f"unknown disturbance {sorted(unknown)[0]!r}")
        noise = raw.get("pose_noise", (0.0, 0.0))
        d = Disturbances(_kicks(raw.get("pushes")), _kicks(raw.get("impulses")),
                         float(raw.get("friction_scale", 1.0)),
                         float(raw.get("size_change", 0.0)),
                         float(raw.get("mass_scale", 1.0)),
                         (float(noise[0]), float(noise[1])), int(raw.get("seed", 0)))
        d.check()
        return d

    def to_dict(self) -> dict[str, Any]:
        return {"pushes": [k.to_dict() for k in self.pushes],
                "impulses": [k.to_dict() for k in self.impulses],
                "friction_scale": self.friction_scale, "size_change": self.size_change,
                "mass_scale": self.mass_scale, "pose_noise": list(self.pose_noise),
                "seed": self.seed}

    @property
    def any(self) -> bool:
        return bool(self.pushes or self.impulses or self.friction_scale != 1.0
                    or self.size_change != 0.0 or self.mass_scale != 1.0
                    or any(self.pose_noise))

    def check(self) -> None:
        """ValueError naming the first disturbance out of range."""
        if not (math.isfinite(self.friction_scale) and self.friction_scale > 0):
            raise ValueError("friction_scale must be positive")
        if not (math.isfinite(self.mass_scale) and 0.01 <= self.mass_scale <= 100.0):
            raise ValueError("mass_scale must be within 0.01..100 (the object's mass times "
                             "this)")
        if not (math.isfinite(self.size_change) and abs(self.size_change) < 0.05):
            raise ValueError("size_change must be within (-0.05, 0.05) m")
        if not all(math.isfinite(s) and s >= 0 for s in self.pose_noise):
            raise ValueError("pose_noise must be two standard deviations >= 0")
        for k in (*self.pushes, *self.impulses):
            if not all(math.isfinite(v) for v in (k.time, *k.vector)) or k.time < 0:
                raise ValueError("a push or impulse needs a time >= 0 and finite numbers")

    def scene_plan(self, plan: ExecutionPlan) -> ExecutionPlan:
        """The plan whose scene is the disturbed world: the friction scaled, the object's
        size and mass changed (the references are the plan's own)."""
        obj = plan.object
        if self.size_change:  # each of the geom's sizes (semi-axes, radii) grown, a
            # mesh's vertices moved out along their directions from its centre
            v = np.asarray(obj.geom_vertices, dtype=float).reshape(-1, 3)
            v = v + self.size_change * v / np.maximum(np.linalg.norm(v, axis=1,
                                                                     keepdims=True), 1e-12)
            obj = replace(obj, geom_size=tuple(d + self.size_change for d in obj.geom_size),
                          geom_vertices=tuple(float(x) for x in v.ravel()))
        obj = replace(obj, mass=obj.mass * self.mass_scale)
        return replace(plan, object=obj, mu=plan.mu * self.friction_scale)

    def hook(self, sim: Any) -> Callable[[int, float, StepRows], None]:
        """The step hook that applies the pushes and impulses to ``sim`` (a
        :class:`~sim.run.Simulation`), each at the first step starting at or after its
        time."""
        pending = sorted([(k.time, "push", k) for k in self.pushes]
                         + [(k.time, "impulse", k) for k in self.impulses],
                         key=lambda e: e[0])
        d, oq, od = sim.data, sim.object_qpos, sim.object_dof
        mass = float(sim.model.body_mass[sim.object_body])

        def hook(k: int, t: float, rows: StepRows) -> None:
            while pending and t >= pending[0][0] - 1e-12:
                _, kind, kick = pending.pop(0)
                v = np.asarray(kick.vector, dtype=float)
                if kind == "push":
                    d.qpos[oq:oq + 3] += v
                else:
                    d.qvel[od:od + 3] += v / mass

        return hook

    def noise(self) -> Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]:
        """The measured pose of a true (position, wxyz): Gaussian noise of ``pose_noise``
        (the angle's about a random axis), from ``seed``."""
        rng = np.random.default_rng(self.seed)
        sp, sa = self.pose_noise

        def measure(p: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            p = p + (rng.normal(0.0, sp, 3) if sp > 0 else 0.0)
            if sa > 0:
                rv = rng.normal(0.0, sa, 3)
                a = float(np.linalg.norm(rv))
                if a > 0:
                    ax = rv / a
                    dq = np.concatenate([[math.cos(a / 2)], math.sin(a / 2) * ax])
                    w0, x0, y0, z0 = dq
                    w1, x1, y1, z1 = q
                    q = np.array([w0 * w1 - x0 * x1 - y0 * y1 - z0 * z1,
                                  w0 * x1 + x0 * w1 + y0 * z1 - z0 * y1,
                                  w0 * y1 - x0 * z1 + y0 * w1 + z0 * x1,
                                  w0 * z1 + x0 * y1 - y0 * x1 + z0 * w1])
            return p, q

        return measure
