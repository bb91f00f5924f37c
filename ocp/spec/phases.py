"""Contact phases: a grasp's motion as a sequence of phases, each with its duration and
the fingertips touching the object in it (learnt from Crocoddyl's contact status per
action model and acados' multiphase OCP; written for rolling grasps).

A phase is data only. The transcription turns a problem's phases into a
:data:`~ocp.transcription.nlp_blocks.Schedule` (intervals per phase on the problem's grid)
and builds each phase's blocks from what its touching contacts contribute
(:mod:`ocp.transcription.blocks`); the NLP cache key names the schedule. A problem
without phases is one phase in which every fingertip touches: today's grasps.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["ContactPhase", "phase_errors", "phase_intervals"]


@dataclass(frozen=True)
class ContactPhase:
    """One phase: its ``duration`` [s] and, per fingertip of the problem (in its order),
    whether it touches the object (``touching``)."""

    duration: float
    touching: tuple[bool, ...]


def phase_errors(phases: tuple[ContactPhase, ...], duration: float, n_fingers: int,
                 n_intervals: int, palm: bool, via_points: int) -> list[tuple[str, str]]:
    """(field, reason) of every problem with a problem's phases."""
    errs: list[tuple[str, str]] = []
    if not phases:
        return [("phases", "give at least one phase, or none for one phase with every "
                           "fingertip touching")]
    for j, ph in enumerate(phases):
        name = f"phases[{j}]"
        if not (math.isfinite(ph.duration) and ph.duration > 0.0):
            errs.append((f"{name}.duration", f"must be > 0 s, got {ph.duration}"))
        if len(ph.touching) != n_fingers:
            errs.append((f"{name}.touching", f"one flag per fingertip ({n_fingers}), got "
                                             f"{len(ph.touching)}"))
        elif not palm and sum(ph.touching) < 2:
            errs.append((f"{name}.touching", "without a palm at least two fingertips hold "
                                             f"the object; {sum(ph.touching)} touch it"))
    total = sum(ph.duration for ph in phases)
    if not errs and abs(total - duration) > 1e-9 * max(1.0, duration):
        errs.append(("phases", f"the phases last {total:.9g} s, the plan {duration:.9g} s"))
    if len(phases) > n_intervals:
        errs.append(("phases", f"{len(phases)} phases need at least as many intervals; "
                               f"n_intervals is {n_intervals}"))
    if len(phases) > 1 and via_points:
        errs.append(("phases", "phases with via-points are not planned yet: give the "
                               "phases or the via-points"))
    return errs


def phase_intervals(phases: tuple[ContactPhase, ...], n_intervals: int) -> tuple[int, ...]:
    """The grid's intervals per phase, in proportion to the phases' durations (largest
    remainders), at least one each."""
    total = sum(ph.duration for ph in phases)
    share = [n_intervals * ph.duration / total for ph in phases]
    counts = [max(1, math.floor(s)) for s in share]
    while sum(counts) < n_intervals:
        j = max(range(len(share)), key=lambda i: share[i] - counts[i])
        counts[j] += 1
    while sum(counts) > n_intervals:
        j = max((i for i in range(len(counts)) if counts[i] > 1),
                key=lambda i: counts[i] - share[i])
        counts[j] -= 1
    return tuple(counts)
