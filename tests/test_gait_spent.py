"""Re-placing only the fingertips whose reach is spent (the request's ``gait.replace``
"spent"; ocp.gait.planner.spent_fingers; docs/gait.md, "Fewer re-placements").

Laws, on examples/allegro_turn_90.json turned about +y: the same turn is planned and
certified with fewer re-placements and a shorter motion than re-placing every fingertip
after every roll (docs/gait.md has the measured counts), its swings timed to the joints'
limits (``gait.fastest_swings``); no fingertip's reach is spent in the searched grasp;
each re-placed fingertip lands where it touched when the gait began; and the plan
executes in MuJoCo as the default's does."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from planner_service.planners import REQUEST
from planner_service.planners.cache import FingerCache
from planner_service.planners.gait import solve_gait
from planner_service.planners.manipulation import manipulation_problem

ROOT = Path(__file__).resolve().parents[1]


def _gait(replace: str, fastest: bool = False):
    body = json.loads((ROOT / "examples" / "allegro_turn_90.json").read_text())
    body["motion"]["steps"][0]["axis"] = [0.0, 1.0, 0.0]
    body["gait"]["replace"] = replace
    body["gait"]["fastest_swings"] = fastest
    request = REQUEST.validate_python(body)
    cache = FingerCache()
    problem = manipulation_problem(request, cache)
    result, gait = solve_gait(request, problem, cache.manipulation)
    return request, problem, result, gait


@pytest.mark.slow
def test_only_spent_fingertips_are_re_placed_home_and_the_plan_executes() -> None:
    from ocp.gait.planner import spent_fingers
    from ocp.robots.grasp_reach import tip_state
    from planner_service.execution import simulate_result

    _, _, _, every_gait = _gait("all")
    request, problem, result, gait = _gait("spent", fastest=True)
    assert gait.ok and result.certificate is not None and result.certificate.passed
    assert math.degrees(gait.turned) == pytest.approx(90.0, abs=1e-3)
    assert len(gait.steps) < len(every_gait.steps)
    assert gait.duration < every_gait.duration
    # its swings timed to the joints' limits: shorter than the request's 0.8 s
    assert all(0.15 - 1e-9 <= st.swing.duration < 0.8 for st in gait.steps)
    # each lands where it touched when the gait began (relative to the palm)
    fingers = tuple(f.finger for f in problem.fingers)
    centre = np.asarray(problem.initial_pose.position, dtype=float)
    rho = float(problem.object.dimensions[0])
    home = [tip_state(f, tip.q_seed, centre, rho).n for f, tip in zip(
        fingers, problem.fingers, strict=True)]
    for st in gait.steps:
        landed = tip_state(fingers[st.finger], st.swing.Q[-1], centre, rho).n
        assert float(np.degrees(np.arccos(np.clip(landed @ home[st.finger], -1, 1)))) < 3.0
    # the searched grasp: no fingertip's reach is spent for two rolls of 10 deg
    assert spent_fingers(problem, tuple(np.asarray(t.q_seed) for t in problem.fingers),
                         centre, rho, np.array([0.0, 1.0, 0.0]), math.radians(10.0),
                         set()) == []
    report = simulate_result(result, request)
    assert report.passed, report.failures
