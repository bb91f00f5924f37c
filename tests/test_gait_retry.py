"""A gait whose fingertip finds no swing back after a roll goes back and rolls half as far
(ocp.gait.planner.MAX_ROLL_RETRIES; docs/gait.md, "Rolls and tips"): 90 deg about the
palm's -x from the searched grasp, asked in rolls of 20 deg. After the first 20 deg roll
the middle fingertip has no swing back (IPOPT: infeasible), which ended the gait before.
The plan that comes back is whole and consistent: the undone roll leaves no phase, step
or check behind."""

from __future__ import annotations

import copy
import json
import math
from pathlib import Path

import pytest

from dexroll_client import ManipulationResult, PlanStatus
from planner_service.cli import plan_request

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.slow  # (16-24 s; by default test_gait_service's gait whose swing is never found
# halves its rolls twice and keeps only the roll it made)
def test_a_failed_re_placement_rolls_again_half_as_far() -> None:
    body = copy.deepcopy(json.loads((ROOT / "examples" / "allegro_turn_90.json").read_text()))
    body["motion"]["steps"][0]["axis"] = [-1.0, 0.0, 0.0]
    body["gait"]["roll_step"] = 0.35  # 20 deg: the grasp's reach allows it
    result, summary = plan_request(body)
    assert isinstance(result, ManipulationResult)
    assert result.status is PlanStatus.SOLVED, summary
    assert result.certificate is not None and result.certificate.passed
    gait = result.gait
    assert gait is not None
    assert abs(gait.turned - math.pi / 2) < 1e-6
    # 20 deg rolls would take 5; halved (and kept halved: the grasp recurs) at least 9
    assert gait.rolls >= 9
    rolls = [p for p in gait.phases if p.kind == "roll"]
    assert len(rolls) == gait.rolls
    # the phases tile the plan: the undone roll and its re-placements left nothing
    for a, b in zip(gait.phases[:-1], gait.phases[1:], strict=True):
        assert abs(b.start - a.end) < 1e-9, (a, b)
    names = set(result.certificate.values)
    assert f"roll{gait.rolls - 1}_tip_gap" in names and f"roll{gait.rolls}_tip_gap" not in names
    swings = [p for p in gait.phases if p.kind == "swing"]
    assert len(swings) == gait.replacements
    assert all(f"swing_rest_step{i}" in names for i in range(len(swings)))
    assert f"swing_rest_step{len(swings)}" not in names
