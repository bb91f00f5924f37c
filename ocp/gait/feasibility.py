"""Whether a gait can make its turn, decided before any roll is planned (docs/gait.md,
"Bad input").

:func:`~ocp.gait.planner.plan_gait` finds out which fingers cannot be lifted, and how far
the grasp rolls, as it goes: a gait its limits stop is planned up to them (rolls of 2-150 s
each) and then answered ``infeasible``. The same laws, asked once at the start, answer the
requests no sequence of rolls and re-placements within the limits can serve at once
(hundreds of ms: small hold problems and the fingers' rolled reach, no NLP of a roll):

- **the hold**: the fingertips must hold the still ball (its weight balanced by forces
  inside their friction cones and the plan's bound, every normal force at least the
  minimum: :func:`~ocp.gait.hold.hold_forces`). The bound (each force component within
  ``LOAD_BOUND`` times the larger of the weight and the contacts' least grip) is what
  makes a ball too heavy: with little friction three fingertips hold a light ball by
  squeezing it harder, relative to its weight, than they may a heavy one;
- **a lift**: a finger can be lifted only when the others hold the ball without it; a gait
  with no such finger is no gait;
- **the never-lifted fingers' reach**: a finger that cannot be lifted rolls through the
  whole turn from its grasp, so its rolled reach (:func:`~ocp.robots.grasp_reach.roll`)
  bounds the turn;
- **the number of rolls**: a lifted finger is re-placed where it touched when the roll
  began (the planner's "roll and reset"), so every roll starts from its grasp, and its
  rolled reach from there (less the planner's margin) bounds each roll; the turn over the
  largest roll is the least number of rolls, which the planner caps.

The holds are hard point contacts (the planner's holds: a soft finger's torsion is not
used); with ``forces.torsional_friction`` the grasp's own hold is not refused here.
"""

from __future__ import annotations

import inspect
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ocp.gait.hold import hold_forces
from ocp.gait.planner import MIN_ROLL, REACH_MARGIN, REACH_SHARE, plan_gait
from ocp.gait.step import grasp_hold
from ocp.shapes.held import Held, held_object
from ocp.spec.grasp import ManipulationProblem
from ocp.spec.motion import ObjectPose
from ocp.transcription.values import LOAD_BOUND, load_parameters

__all__ = ["MAX_ROLLS", "GaitOutlook", "gait_outlook"]

FloatArray = NDArray[np.float64]

#: The planner's cap on a gait's rolls (:func:`~ocp.gait.planner.plan_gait`'s ``max_rolls``).
MAX_ROLLS: int = int(inspect.signature(plan_gait).parameters["max_rolls"].default)


@dataclass(frozen=True)
class GaitOutlook:
    """What a gait's start allows: the fingers the others cannot hold the ball without
    (they roll through the whole turn), the turn [rad] they roll before the first stops
    (the asked angle when none does) and which and why, the largest roll [rad] the lifted
    fingers' grasp allows and the least number of rolls; ``message``: why the turn cannot
    be made ("" when it may)."""

    never_lifted: tuple[str, ...]
    reach: float
    roll: float
    rolls: int
    message: str

    @property
    def feasible(self) -> bool:
        return not self.message


def _deg(x: float) -> str:
    return f"{math.degrees(x):.1f} deg"


def _axis(a: FloatArray) -> str:
    return "(" + ", ".join(f"{c:.3g}" for c in a) + ")"


def _reach(template: ManipulationProblem, qs: tuple[FloatArray, ...], which: list[int],
           obj: Held, rho: float, axis: FloatArray, upto: float) -> tuple[float, str, str]:
    """(the turn [rad] fingers ``which`` roll about ``axis`` from joints ``qs`` before the
    first stops, at most ``upto``; its name, why): the planner's rolled reach."""
    from ocp.robots.grasp_reach import roll
    from ocp.robots.turn_reach import rolls

    best = (upto, "", "")
    for i in which:
        tip = template.fingers[i]
        if not rolls(tip.finger):
            continue
        r = roll(tip.finger, qs[i], obj.centre, rho, axis, upto, template.pad_margin,
                 held=None if obj.ball else obj)
        if r.why and r.reach < best[0]:
            best = (r.reach, tip.name or f"finger{i}", r.why)
    return best


def gait_outlook(template: ManipulationProblem, qs: tuple[Any, ...], axis: Any,
                 angle: float, roll_step: float, max_rolls: int = MAX_ROLLS) -> GaitOutlook:
    """Whether :func:`~ocp.gait.planner.plan_gait` (the same arguments) can make the turn of
    ``angle`` [rad] about ``axis`` (palm frame) from the joints ``qs``: the module's laws,
    in that order; the first that fails is the message."""
    ax = np.asarray(axis, dtype=float)
    ax = ax / np.linalg.norm(ax)
    pose = template.initial_pose or ObjectPose()
    R0, centre = pose.rotation, np.asarray(pose.position, dtype=float)
    rho = float(template.object.dimensions[0])
    fingers = tuple(f.finger for f in template.fingers)
    names = tuple(f.name or f"finger{i}" for i, f in enumerate(template.fingers))
    nf = len(fingers)
    q = tuple(np.asarray(x, dtype=float) for x in qs)
    fs = template.forces
    if fs is None:
        return GaitOutlook((), 0.0, 0.0, 0, "a gait needs the object's load (forces): the "
                                             "other fingertips hold it while one is lifted")
    load = load_parameters(template)
    weight = float(np.linalg.norm(load[0:3]))
    cones = (f"no forces inside their friction cones (mu {template.mu:g} less the cone "
             f"margin {fs.cone_margin:g} rad), each component within the plan's bound of "
             f"{LOAD_BOUND * float(load[5]):.3g} N, balance its weight of {weight:.3g} N with "
             f"every normal force at least {fs.min_normal_force:g} N")

    obj = held_object(template.object, centre, R0)
    what = obj.what

    def holds(which: list[int]) -> bool:
        return hold_forces(grasp_hold(fingers, q, which, obj), load, obj.radius) \
            is not None

    held = [k for k in range(nf) if not holds([i for i in range(nf) if i != k])]
    never = tuple(names[k] for k in held)
    free = [k for k in range(nf) if k not in held]
    # the grasp's own hold: refused only when no fewer fingertips hold the ball either (a
    # solver's failure on the whole grasp where three of its fingertips hold it is not a law)
    if fs.torsional_friction == 0.0 and not free and not holds(list(range(nf))):
        return GaitOutlook(names, 0.0, 0.0, 0,
                           f"the fingertips ({', '.join(names)}) cannot hold {what} in "
                           f"their grasp: {cones}")
    reach, who, why = _reach(template, q, held, obj, rho, ax, angle)
    if not free:
        alone = (f"rolling alone, finger {who!r} ({why}) stops the turn after "
                 f"{_deg(reach)} of {_deg(angle)} about {_axis(ax)}" if why else
                 f"rolling alone (without `gait`) may make the turn of {_deg(angle)}")
        return GaitOutlook(never, reach, 0.0, 0,
                           f"no fingertip can be lifted: without any one of "
                           f"{', '.join(names)} the others cannot hold {what} ({cones}); "
                           f"{alone}")
    if why and reach < angle - 1e-6:
        return GaitOutlook(never, reach, 0.0, 0,
                           f"finger {who!r} ({why}) stops the turn after {_deg(reach)} of "
                           f"{_deg(angle)} about {_axis(ax)} and cannot be re-placed (without "
                           f"it the other fingertips cannot hold {what}: {cones}): at most "
                           f"{_deg(reach)} can be turned from this grasp")
    step, who, why = _reach(template, q, free, obj, rho, ax, min(roll_step, angle))
    if why:  # the planner's shortened roll
        step = step - max(REACH_MARGIN, REACH_SHARE * step)
    need = math.ceil(angle / step - 1e-9) if step >= MIN_ROLL else 0
    if step < MIN_ROLL or need > max_rolls:
        head = (f"finger {who!r} ({why}) rolls {what} {_deg(max(step, 0.0))} at most "
                f"about {_axis(ax)} from its grasp, where it is re-placed after every roll")
        tail = (f"{_deg(angle)} take at least {need} rolls, more than a gait's {max_rolls}"
                if need else f"less than a gait's least roll of {_deg(MIN_ROLL)}")
        return GaitOutlook(never, reach, max(step, 0.0), need, f"{head}: {tail}")
    return GaitOutlook(never, reach, step, need, "")
