"""A plan whose fingertip contacts change chart at a time of the motion
(:class:`ChartSwitchSpec`; docs/shapes.md, "Charts that switch inside a plan").

An egg's contacts are measured on its own latitude/longitude chart (poles at its ends) or
on its side chart (poles on its equator, :class:`~ocp.shapes.ellipsoid.EggSideSurface`). A
contact that rolls from where only one of them is regular to where only the other is
(around the equator and then up to an end) is carried by neither for the whole plan: the
plan switches at a node of its grid, every fingertip's contact from the problem's chart
to the next (:mod:`ocp.transcription.chart_switch` maps the coordinates there). The
problem's own charts are the first; :func:`after_switch` states the problem on the next.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from ocp.spec.grasp import ManipulationProblem

__all__ = ["ChartSwitchSpec", "after_switch", "snapped", "switch_errors", "switch_node"]


@dataclass(frozen=True)
class ChartSwitchSpec:
    """Every fingertip's contact changes chart at ``time`` [s] (the grid's node nearest
    it, never its first or last): from the problem's charts to the object's side chart
    (``side_chart``) or to its own, fingertip i in the patch ``patches[i]`` (a rotation
    vector [rad], as ``Fingertip.chart_rotation``)."""

    time: float
    side_chart: bool
    patches: tuple[tuple[float, float, float], ...]


def _nodes(problem: ManipulationProblem) -> np.ndarray:
    """The grid's node times [s] (a switched plan has no palm: one even segment)."""
    return np.linspace(0.0, problem.duration, problem.n_intervals + 1)


def switch_node(problem: ManipulationProblem) -> int:
    """The grid node of the problem's chart switch: the one nearest its time among the
    inner nodes."""
    spec = problem.chart_switch
    assert spec is not None
    t = _nodes(problem)
    n = len(t) - 1
    return int(min(max(int(np.argmin(np.abs(t - spec.time))), 1), n - 1))


def snapped(problem: ManipulationProblem) -> ManipulationProblem:
    """The problem with its switch's time at its node's (a grid refined by halving its
    intervals keeps that node, and a plan's switch stays where it was)."""
    spec = problem.chart_switch
    if spec is None:
        return problem
    t = float(_nodes(problem)[switch_node(problem)])
    return replace(problem, chart_switch=replace(spec, time=t))


def after_switch(problem: ManipulationProblem) -> ManipulationProblem:
    """The problem stated on the chart its contacts switch to: the object on its side
    chart or its own, each fingertip's patch the switch's (its ``initial`` coordinates
    stay the first chart's: only the charts are read from it)."""
    spec = problem.chart_switch
    assert spec is not None
    tips = tuple(replace(tip, chart_rotation=(float(rv[0]), float(rv[1]), float(rv[2])))
                 for tip, rv in zip(problem.fingers, spec.patches, strict=True))
    return replace(problem, object=replace(problem.object, side_chart=spec.side_chart),
                   fingers=tips, chart_switch=None)


def switch_errors(problem: ManipulationProblem) -> list[tuple[str, str]]:
    """(field, reason) of every problem with a problem's chart switch."""
    spec = problem.chart_switch
    if spec is None:
        return []
    errs: list[tuple[str, str]] = []
    name = "chart_switch"
    if not (math.isfinite(spec.time) and 0.0 < spec.time < problem.duration):
        errs.append((f"{name}.time", f"must lie inside the motion (0, {problem.duration:g}) "
                                     f"s, got {spec.time}"))
    if len(spec.patches) != len(problem.fingers):
        errs.append((f"{name}.patches", f"one patch per fingertip ({len(problem.fingers)}), "
                                        f"got {len(spec.patches)}"))
    obj = problem.object
    if spec.side_chart != obj.side_chart and obj.kind.side_surface(obj.dimensions) is None:
        errs.append((f"{name}.side_chart", f"a {obj.shape} has no side chart"))
    for what, present in (("a palm", problem.palm is not None),
                          ("contact phases", problem.phases is not None),
                          ("a moving start", problem.initial_input is not None),
                          ("a reference to track", problem.reference is not None)):
        if present:
            errs.append((name, f"a chart switch is planned for fingertips alone from rest, "
                               f"not with {what}"))
    if problem.n_intervals < 2:
        errs.append((name, "a chart switch needs at least two intervals"))
    return errs
