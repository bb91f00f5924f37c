"""A fingertip re-placed while the others roll the ball (ocp.gait.overlap, docs/gait.md
"Re-placing while the others roll"): the swing among moving bodies, and a gait made of
such rolls, certified, shorter than the same gait re-placing at rest, and executed."""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from helpers import assert_gait_pieces, planned_gait

from ocp.gait.checks import swing_checks
from ocp.gait.swing import MIN_TIP_GAP, plan_swing
from tests.test_gait import FINGERS, stored_swing

ROOT = Path(__file__).resolve().parents[1]


def test_a_swing_among_still_bodies_given_as_moving_is_the_same_swing() -> None:
    """The NLP's other bodies are per node: given as still (``others``) or as a motion that
    stays put (``moving``), the same swing to 1e-9 rad, and the same checks."""
    _, spec = stored_swing("gait_narrow_swing.json")
    spec = replace(spec, tip_gap=MIN_TIP_GAP)  # (its neighbour is 1.8 mm away)
    still = plan_swing(spec)
    assert still.ok, still.message

    def put(t: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
        n = np.atleast_1d(t).size
        return [(np.tile(a, (n, 1)), np.tile(b, (n, 1))) for a, b, _ in spec.others]

    moving = plan_swing(replace(spec, moving=put))
    assert moving.ok, moving.message
    assert np.abs(moving.Q - still.Q).max() < 1e-9
    a = {c.name: c.value for c in swing_checks(still, "s")}
    b = {c.name: c.value for c in swing_checks(moving, "s")}
    assert a.keys() == b.keys() and all(abs(a[k] - b[k]) < 1e-9 for k in a)


def test_a_body_that_moves_into_a_still_swings_path_is_avoided_when_known() -> None:
    """A neighbour's tip that is, in the middle sixth of the swing (between two of its
    nodes), where the swing planned among still bodies passes then (and far away before
    and after): that swing fails its
    gap check among the moving bodies (the certificate samples the others where they are
    at each time); the swing planned knowing the motion keeps the gap (it passes there at
    another time), and every other check too."""
    _, spec = stored_swing("gait_narrow_swing.json")
    spec = replace(spec, tip_gap=MIN_TIP_GAP)  # (its neighbour is 1.8 mm away)
    still = plan_swing(spec)
    assert still.ok, still.message
    T = still.duration
    R, p = spec.finger.fingertip_pose_pin(still.sample(0.5 * T)[0][0])
    there = p + R @ spec.body.a  # the still swing's cap centre at T / 2
    far = spec.centre + np.array([0.0, 0.0, 0.5])

    def moving(t: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
        t = np.atleast_1d(np.asarray(t, dtype=float))
        on = (np.abs(t - 0.5 * T) <= T / 12 + 1e-12)[:, None]  # nodes 10-14 of 24
        at = np.where(on, there, far)
        return [(at, at)] + [(np.tile(a, (t.size, 1)), np.tile(b, (t.size, 1)))
                             for a, b, _ in spec.others[1:]]

    aware = replace(spec, moving=moving, node_margin=5e-5)  # (as ocp.gait.overlap's)
    blind = replace(still, spec=aware)  # the still swing, checked among the moving bodies
    gaps = {c.name: c for c in swing_checks(blind, "s")}
    assert not gaps["swing_tip_gap_s_0"].passed and gaps["swing_tip_gap_s_0"].value < 0
    found = plan_swing(aware)
    assert found.ok, found.message
    checks = {c.name: c for c in swing_checks(found, "s")}
    bad = [c.failure for n, c in checks.items() if not c.passed and n != "swing_tip_gap_s_0"]
    assert not bad, bad
    # the gap is kept at the NLP's nodes, and at the points of the capsule's segment the
    # rows sample (5): a neighbour that appears beside it at once comes 0.03 mm nearer
    # than the rows see (measured); far from the blind swing's overlap
    assert checks["swing_tip_gap_s_0"].value > MIN_TIP_GAP - 1e-4


@pytest.mark.slow
def test_a_gait_re_placing_during_rolls_is_certified_shorter_and_executes() -> None:
    """examples/allegro_turn_90_overlap.json: allegro_turn_90.json about +x with the spent
    fingertips landing where they roll farthest, rolls of up to 30 deg, fastest swings and
    rolls, and ``overlap`` (benchmarks/gait_turns.py's OVERLAP options): certified;
    most re-placements made during rolls; the motion within the issue's 10 s with at most
    10 re-placements (7.9 s and 9 measured; at rest 15.3-24.5 s over the eight turns,
    docs/gait.md); in the samples the lifted fingertip
    touches nothing and carries no force during its roll, every joint and planned force
    is continuous at every switch; executed in MuJoCo."""
    from benchmarks.gait_turns import OVERLAP
    from ocp.gait.samples import gait_samples, gait_times
    from planner_service.execution import simulate_result

    body = json.loads((ROOT / "examples" / "allegro_turn_90_overlap.json").read_text())
    base = json.loads((ROOT / "examples" / "allegro_turn_90.json").read_text())
    assert body["gait"] == {**base["gait"], **OVERLAP}  # the example is the bench's turn
    request, problem, result, gait = planned_gait(body)
    assert math.degrees(gait.turned) == pytest.approx(90.0, abs=1e-3)
    assert len(gait.carried) >= len(gait.steps) // 2 and len(gait.carried) >= 4
    assert gait.duration < 10.0 and len(gait.steps) <= 10  # measured: 7.9 s, 9
    # a hand-over: one ramp loads the last re-placed fingertip and unloads the next
    assert any(st.landing is not None for st in gait.steps)
    smp = gait_samples(gait, problem, gait_times(gait, 200.0))
    assert smp.touching is not None
    for r, i in gait.carried.items():
        ph = next(p for p in gait.phases if p.kind == "roll" and p.index == r)
        k = gait.steps[i].finger
        inside = (smp.t > ph.start + 1e-9) & (smp.t < ph.end - 1e-9)
        assert inside.any() and not smp.touching[inside, k].any()
        assert np.abs(smp.force[inside, k]).max() == 0.0
        assert smp.touching[inside][:, [j for j in range(len(FINGERS)) if j != k]].all()
    for ph in gait.phases[1:]:  # joints continuous at the switches (both sides' motion)
        q0 = gait.joints(ph.start - 1e-9)[0]
        q1 = gait.joints(ph.start + 1e-9)[0]
        assert np.abs(q1 - q0).max() < 1e-6, ph
        # and the planned forces: each ramp meets a roll at the roll's own forces (the
        # others' deep holds differed from them by up to 0.9 N)
        near = gait_samples(gait, problem, np.array([ph.start - 1e-7, ph.start + 1e-7]))
        assert np.abs(near.force[1] - near.force[0]).max() < 1e-4, ph
    assert_gait_pieces(result)  # (the swings carried by rolls among them)
    report = simulate_result(result, request)
    assert report.passed, report.failures


def test_a_swing_not_found_for_a_neighbour_names_it() -> None:
    """The middle fingertip 1.8 mm from the index with the full clearance kept from its
    neighbours has no swing (tests/test_gait.py), and the body it names as in its way
    (``blocked_by``: an index into ``others``, which a gait re-places first when it
    rolls) is the index; a swing found names none."""
    _, spec = stored_swing("gait_narrow_swing.json")
    failed = plan_swing(replace(spec, other_names=("index", "ring", "thumb")))
    assert failed.status == "infeasible"
    assert failed.blocked_by == 0 and "fingertip 'index'" in failed.message
    assert plan_swing(replace(spec, tip_gap=MIN_TIP_GAP)).blocked_by is None


def test_a_landing_inside_a_neighbour_keeps_no_negative_gap() -> None:
    """A neighbour's tip put where the swing lands: the gap the swing keeps from it is
    zero, not 0.9 times the negative gap (which a certified swing once landed into), and
    the swing's own gap check fails such a landing."""
    _, spec = stored_swing("gait_narrow_swing.json")
    f, body = spec.finger, spec.body
    R, p = f.fingertip_pose_pin(spec.q_target)
    a = p + R @ body.a
    r = spec.others[1][2]
    inside = replace(spec, others=(spec.others[0], (a, a, r), spec.others[2]))
    gaps = inside.required_gaps()
    assert gaps[1] == 0.0 and min(gaps) >= 0.0
    found = plan_swing(replace(inside, tip_gap=MIN_TIP_GAP))
    checks = {c.name: c for c in swing_checks(found, "s")} if found.ok else {}
    assert not found.ok or not checks["swing_tip_gap_s_1"].passed


@pytest.mark.slow
@pytest.mark.parametrize("example, axis, motion, replacements", [
    ("allegro_turn_90.json", (0.0, 0.0, -1.0), 10.0, 10),  # measured: 7.89 s, 7
    ("allegro_turn_180_z.json", None, 16.0, 12),  # measured: 10.10 s, 11
])
def test_the_issue_targets_turns_are_certified_within_their_time_and_execute(
        example: str, axis: tuple[float, float, float] | None, motion: float,
        replacements: int) -> None:
    """Two of issue 40's target turns with benchmarks/gait_turns.py's OVERLAP options:
    within the issue's motion (10 s for 90 deg, 16 s for 180 deg) and re-placements.
    About -z an overlap roll is not found once (the middle finger stranded, the ring
    stopping without it): that fingertip alone is re-placed at rest and the gait goes on
    overlapping (four at rest before, 10.4 s). Executed in MuJoCo in dexroll's scene."""
    from benchmarks.gait_turns import OVERLAP
    from planner_service.execution import simulate_result

    body = json.loads((ROOT / "examples" / example).read_text())
    if axis is not None:
        body["motion"]["steps"][0]["axis"] = list(axis)
    body["gait"].update(OVERLAP)
    request, _, result, gait = planned_gait(body)
    assert gait.duration < motion and len(gait.steps) <= replacements
    assert len(gait.steps) - len(gait.carried) <= 1  # at most one made at rest
    report = simulate_result(result, request)
    assert report.passed, report.failures


@pytest.mark.slow
def test_the_six_palm_axis_turns_meet_the_issues_median_motion() -> None:
    """Issue 40's robot-time targets over benchmarks/gait_turns.py's six 90 deg turns with
    its OVERLAP options: each certified within 10 s and 10 re-placements, the median
    motion within 8 s and the median re-placements within 8 (measured: 4.89-8.73 s,
    median 7.896 s; 5-10, median 8). An overlap swing found only after a shorter length
    failed is tried halfway (ocp.gait.overlap.plan_overlap): without that the median was
    8.005 s."""
    import statistics

    from benchmarks.gait_turns import OVERLAP, targets

    motions, replacements = [], []
    for name, body in targets(ROOT).items():
        if not name.startswith("90 ") or "MJCF" in name:
            continue
        body["gait"].update(OVERLAP)
        _, _, _, gait = planned_gait(body)
        assert gait.duration < 10.0 and len(gait.steps) <= 10, name
        motions.append(gait.duration)
        replacements.append(len(gait.steps))
    assert len(motions) == 6
    assert statistics.median(motions) <= 8.0, motions
    assert statistics.median(replacements) <= 8, replacements
