"""A gait's roll after one whose certificate refined its grid starts on that grid, from
that roll's IPOPT point (ocp.gait.planner.plan_gait; docs/gait.md, "Speed"): 90 deg about
the palm's -z from its searched grasp refines its first 7.9 deg roll from 16 to 64
intervals (the index's slip between collocation points); before, every later roll was
solved on 16 intervals again and refined again. Two rolls of that gait: the second is
planned on the first's grid without a refinement, certified, in fewer iterations."""

from __future__ import annotations

import copy
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
#: the joints of 90 deg about -z's searched grasp (index, middle, ring, thumb)
NEG_Z_GRASP = ([-0.155391, 0.855795, 0.016562, 1.606769],
               [0.354379, -0.041106, 1.579601, 0.576375],
               [0.087103, 0.304557, 1.644007, 0.028379],
               [1.119174, 0.677932, 0.880797, 0.569822])


def test_a_roll_after_a_refined_one_starts_on_its_grid_from_its_point() -> None:
    body = copy.deepcopy(json.loads((ROOT / "examples" / "allegro_turn_90.json").read_text()))
    step = body["motion"]["steps"][0]
    step["axis"], step["angle"] = [0.0, 0.0, -1.0], math.radians(12.0)
    body.pop("grasp")
    for f, q in zip(body["fingers"], NEG_Z_GRASP, strict=True):
        f["initial_q"] = q
    request = REQUEST.validate_python(body)
    cache = FingerCache()
    problem = manipulation_problem(request, cache)
    result, gait = solve_gait(request, problem, cache.manipulation)
    assert gait.ok, gait.message
    assert len(gait.rolls) == 2  # 12 deg: the first roll cut where two tips come close
    first, second = (r.stats for r in gait.rolls)
    assert first is not None and second is not None
    assert first.refinements >= 1 and first.n_intervals > problem.n_intervals
    assert second.n_intervals == first.n_intervals and second.refinements == 0
    assert second.iterations < first.iterations
    assert result.certificate is not None and result.certificate.passed
    # the second roll starts where the swings before it left the joints
    assert result.certificate.values["switch_position_roll1_start"] <= 1e-7
    assert "switch_position_roll0_start" not in result.certificate.values
    # each roll is planned in the ball's frame at its start (GaitPlan.frames): turned back
    # into the palm frame the ball's orientation is continuous over the whole gait, still
    # between the rolls, and ends 12 deg about -z from where it began
    assert result.gait is not None and result.gait.samples is not None
    wxyz = np.array(result.gait.samples.object_orientation_wxyz)
    dots = np.abs(np.einsum("ij,ij->i", wxyz[1:], wxyz[:-1]))
    assert np.degrees(2.0 * np.arccos(np.minimum(dots, 1.0))).max() < 0.2  # per sample
    assert len(gait.frames) == 2 and np.allclose(gait.frames[0], np.eye(3))
    w, x, y, z = wxyz[-1]
    assert np.degrees(2.0 * math.atan2(math.hypot(x, y, z), abs(w))) == \
        pytest.approx(12.0, abs=1.0)
    assert z * w < 0.0 and abs(z) > 10.0 * max(abs(x), abs(y))  # about -z
