"""The planner keeps the NLPs it built, the least recently used dropped beyond its bound
(every refined grid is a structure of its own, so an unbounded cache grows with every
plan a worker refines)."""

from __future__ import annotations

import math
from dataclasses import replace

from ocp.ball_on_palm import BallOnPalmPlanner
from ocp.solve.planner import ManipulationPlanner
from ocp.spec.problem import BallOnPalmProblem, ObjectSpec


def test_the_least_recently_used_nlp_is_dropped_beyond_the_bound() -> None:
    general = ManipulationPlanner(max_nlps=2)
    palm = BallOnPalmPlanner(general=general)
    base = BallOnPalmProblem(object=ObjectSpec("sphere", (0.025,)),
                             initial=(0.0, 0.0, 0.0, 0.0, -math.pi / 2),
                             goal={"x": 0.01, "y": 0.0}, duration=2.0, n_intervals=10)
    a, b, c = (replace(base, n_intervals=n) for n in (10, 12, 14))
    assert palm.nlp_for(a)[1] is False
    assert palm.nlp_for(b)[1] is False
    assert palm.nlp_for(a)[1] is True  # a is now the most recently used
    assert palm.nlp_for(c)[1] is False  # drops b, the least recently used
    assert len(general.nlps) == 2
    assert palm.nlp_for(a)[1] is True
    assert palm.nlp_for(b)[1] is False  # built again
