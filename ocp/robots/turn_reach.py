"""Whether a grasp of round fingertips can make a requested turn of a ball, decided before
any NLP is built: the rolled reach of each finger about the turn's axis.

A 4-joint finger whose round tip rolls on the ball without slip or spin has its motion
fixed by the ball's (:func:`ocp.robots.grasp_reach.roll`: 4 rows in 4 joint rates), so a
finger that meets a joint limit or its cap's seam before the ball has turned as asked
stops the whole grasp, whatever the optimiser does: from that grasp rolling alone cannot
turn further, and an NLP would only find that out after a minute (issue 24: from the
built-in hand's nominal grasp, 30 deg about z ended ``time_limit`` after 63 s). Each
finger's motion is fixed by the ball's alone, so one finger's stop is proof enough; a
finger whose integration turns singular (a fold of its motion) proves nothing and is
not counted.

The planner's slack is allowed for: the tracking tolerance (the object may lag the
desired turn by ``orientation_tolerance``) and a margin, :data:`MARGIN` or
:data:`RELATIVE_MARGIN` of the reach, whichever is larger, for what the rolled model does
not see (the ball moving within ``position_tolerance``, limits held only within the
certificate's tolerances). A turn is refused only when a finger stops more than both
short of it. docs/hands.md, "A turn beyond the reach is answered at once".
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ocp.geometry.rotations import log_rotation, quaternion_matrix
from ocp.robots.grasp_reach import roll

__all__ = ["MARGIN", "RELATIVE_MARGIN", "Shortfall", "Turn", "axis_name", "motion_turns",
           "problem_shortfall", "refusal_reach", "rolls", "turn_shortfall"]

FloatArray = NDArray[np.float64]

#: The least margin [rad] by which a finger's rolled reach must fall short of a turn (less
#: the tracking tolerance) for the turn to be refused: over the largest excess the planner
#: ever certified beyond the rolled reach (3 deg: +y from the nominal grasp, 13 deg for a
#: rolled 10, docs/hands.md), with room to spare.
MARGIN = math.radians(5.0)
#: ... or this fraction of the reach, when larger (a reach of 20 deg refuses only turns
#: beyond 30 deg plus the tolerance).
RELATIVE_MARGIN = 0.5
#: The turns of a motion checked, in all [rad] (a longer motion is checked that far).
MAX_CHECKED = math.pi


@dataclass(frozen=True)
class Turn:
    """A part of the desired motion that turns the ball about one palm axis."""

    axis: FloatArray  # unit, palm frame
    angle: float      # [rad], > 0


@dataclass(frozen=True)
class Shortfall:
    """A finger that stops the requested turn: where and why."""

    finger: str
    stop: str         # "its joint 'index_j3' upper limit", "its cap's seam (...)"
    reached: float    # the turn [rad] of this part before the stop
    requested: float  # this part's turn [rad]
    axis: FloatArray
    before: float = 0.0  # turned by the motion's earlier parts [rad]

    @property
    def message(self) -> str:
        earlier = f" (after the motion's first {math.degrees(self.before):.1f} deg)" \
            if self.before > 0.0 else ""
        return (f"finger {self.finger!r} reaches {self.stop} after "
                f"{math.degrees(self.reached):.1f} deg of the "
                f"{math.degrees(self.requested):.3g} deg turn about {axis_name(self.axis)}"
                f"{earlier}; rolling alone cannot turn further from this grasp: search a "
                "grasp (ocp.robots.grasp_reach.search_grasp) or re-place fingers (finger "
                "gaiting)")


def axis_name(axis: ArrayLike) -> str:
    """``z``, ``-x``, ... for a palm axis, else its components."""
    a = np.asarray(axis, dtype=float)
    for k, name in enumerate("xyz"):
        if abs(abs(a[k]) - 1.0) < 1e-6:
            return name if a[k] > 0 else f"-{name}"
    return "(" + ", ".join(f"{c:.3g}" for c in a) + ")"


def motion_turns(rotations: Sequence[FloatArray], tol: float = 1e-6) -> list[Turn]:
    """The turns between successive orientations (palm frame): between knots the desired
    orientation follows the geodesic ``R_k exp(s w)`` = ``exp(s R_k w) R_k``, a turn about
    the palm axis ``R_k w``; successive turns about the same axis are one, holds dropped."""
    turns: list[Turn] = []
    for Ra, Rb in itertools.pairwise(rotations):
        w = np.asarray(Ra) @ log_rotation(np.asarray(Ra).T @ np.asarray(Rb))
        angle = float(np.linalg.norm(w))
        if angle < tol:
            continue
        axis = w / angle
        if turns and float(np.linalg.norm(turns[-1].axis - axis)) < tol:
            turns[-1] = Turn(turns[-1].axis, turns[-1].angle + angle)
        else:
            turns.append(Turn(axis, angle))
    return turns


def refusal_reach(requested: float, tolerance: float) -> float:
    """The reach [rad] below which a turn of ``requested`` is refused: the turn less the
    tracking ``tolerance`` exceeds the reach by more than ``max(MARGIN, RELATIVE_MARGIN *
    reach)``."""
    needed = requested - tolerance
    return min(needed - MARGIN, needed / (1.0 + RELATIVE_MARGIN))


def _stop(f: Any, why: str, q: FloatArray, seam_margin: float) -> str | None:
    """What a definite stop of :func:`roll` is, in words (None: not one, e.g. singular)."""
    if why.startswith("joint limit ("):
        name = why[len("joint limit ("):-1]
        j = list(f.joint_names).index(name)
        side = "upper" if abs(q[j] - f.upper[j]) < abs(q[j] - f.lower[j]) else "lower"
        return f"its joint {name!r} {side} limit"
    if why.startswith("coupling limit ("):  # a band's bound: as definite as a limit
        return f"its {why[len('coupling limit ('):-1]}'s bound"
    if why == "cap's seam":
        return f"its cap's seam (within {seam_margin * 1e3:.3g} mm, the pad_margin)" \
            if seam_margin > 0 else "its cap's seam"
    return None


def rolls(f: Any) -> bool:
    """Whether a finger's motion is fixed by the ball's: 4 joints, none tied to another
    by an equality (a passive joint's tendon held at its bound leaves 3: the finger then
    constrains the ball's motion instead), a sphere or capsule tip."""
    tied = any(c.lower == c.upper for c in getattr(f, "couplings", ()))
    return bool(f.nq == 4 and not tied and f.tip_surface.kind in ("sphere", "capsule"))


def turn_shortfall(fingers: Sequence[Any], names: Sequence[str], qs: Sequence[ArrayLike],
                   centre: ArrayLike, radius: float, turns: Sequence[Turn], tolerance: float,
                   seam_margin: float = 0.0) -> Shortfall | None:
    """The finger that stops the ``turns`` (one after the other) of the ball of ``radius``
    at ``centre`` short of :func:`refusal_reach` from joints ``qs``, the earliest; None when
    none does. Only 4-joint fingers with a sphere or capsule tip are rolled (the others'
    motion is not fixed by the ball's). Each finger is rolled no farther than the refusal
    needs: a part's refusal reach, or the stop already found."""
    live = {i: np.asarray(q, dtype=float) for i, (f, q) in enumerate(zip(fingers, qs,
                                                                          strict=True))
            if rolls(f)}
    before = 0.0
    for turn in turns:
        if not live or before >= MAX_CHECKED:
            return None
        bound = refusal_reach(turn.angle, tolerance)
        best: Shortfall | None = None
        for i in list(live):
            f = fingers[i]
            upto = min(turn.angle, bound) if turn is turns[-1] else turn.angle
            if best is not None:
                upto = min(upto, best.reached)
            if upto <= 0.0:
                live.pop(i)
                continue
            r = roll(f, live[i], centre, radius, turn.axis, upto, seam_margin)
            stop = _stop(f, r.why, r.q, seam_margin) if r.why else None
            if stop is not None and r.reach < bound and (best is None or r.reach < best.reached):
                best = Shortfall(names[i], stop, r.reach, turn.angle, turn.axis, before)
            if r.why or r.reach < turn.angle - 1e-9:
                live.pop(i)  # stopped (or rolled only as far as the refusal needs)
            else:
                live[i] = r.q
        if best is not None:
            return best
        before += turn.angle
    return None


def problem_shortfall(problem: Any, joints: Callable[[], Sequence[ArrayLike]]
                      ) -> Shortfall | None:
    """:func:`turn_shortfall` of a manipulation problem (``ocp.spec``'s
    ``ManipulationProblem``, read by its fields: this layer sits below the problems) whose
    fingers hold a ball in the air at the joints ``joints()`` gives (its initial state's,
    asked only when the check applies) and whose desired
    motion turns it with the centre held within the tracking's ``position_tolerance``:
    the only kind whose reach the rolled motion decides. None for any other problem (a
    palm, another shape, soft tracking, contact phases, a moving centre)."""
    tr, motion, pose = problem.tracking, problem.motion, problem.initial_pose
    if (problem.palm is not None or problem.object.shape != "sphere" or motion is None
            or pose is None or problem.phases is not None
            or tr.orientation_tolerance is None or tr.position_tolerance is None
            or not any(rolls(c.finger) for c in problem.fingers)):
        return None
    R0, p0 = motion.at(0.0)
    later = [k for k, t in enumerate(motion.times) if t > motion.t0]
    positions = np.asarray([p0[0], *(motion.positions[k] for k in later)], dtype=float)
    if float(np.linalg.norm(positions - positions[0], axis=1).max()) > tr.position_tolerance:
        return None
    rotations = [R0[0], *(quaternion_matrix(motion.orientations[k]) for k in later)]
    return turn_shortfall([c.finger for c in problem.fingers],
                          [c.name or f"finger{i}" for i, c in enumerate(problem.fingers)],
                          joints(), pose.position, float(problem.object.dimensions[0]),
                          motion_turns(rotations), float(tr.orientation_tolerance),
                          float(problem.pad_margin))
