"""The command line, run as a real process on the shipped examples."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
from conftest import CliPlans

ROOT = Path(__file__).resolve().parents[1]
#: Every example but the two whole-hand files (10 s each here): they describe the built-in
#: hand of allegro_turn (tests/test_hand_service.py: our URDF and MJCF of it give the
#: built-in hand's plan) and tests/test_sim.py plans and executes them; the command line
#: plans allegro_turn (suite time).
SAME_AS_ALLEGRO_TURN = {"hand_from_mjcf", "hand_from_urdf"}
#: The gait examples (the smallest: two rolls and three re-placements, 15 s here; 90 and
#: 180 deg: 4 min each, docs/gait.md): tests/test_gait_service.py
#: plans a smaller gait of the same request through the same adapter and executes it
#: (egg_gait: tests/test_gait_shapes.py).
GAITS = {"allegro_gait", "allegro_turn_90", "allegro_turn_90_overlap", "allegro_turn_180_z",
         "egg_gait", "rounded_cube_gait"}
EXAMPLES = [p for p in sorted((ROOT / "examples").glob("*.json"))
            if p.stem not in SAME_AS_ALLEGRO_TURN | GAITS]
#: Examples whose `dexroll plan` run tests/test_sim.py makes too (the same CLI process,
#: its result certified and executed in MuJoCo) in another worker: their summaries here
#: are slow-marked (16-19 s of planning each, the default run's longest duplicates); test_sim
#: slow-marks their executions too (its SLOW_PLANS): `make test-slow` plans and executes
#: them.
PLANNED_IN_TEST_SIM = {"capsule_roll", "ellipsoid_two_fingers", "egg_turn"}


def _in_result_patch(request: dict[str, Any], result: dict[str, Any],
                     goal: dict[str, float]) -> dict[str, float]:
    """The request's palm goal restated in the chart patch of the result's coordinates."""
    from ocp.geometry.surfaces import Chart
    from ocp.spec.patches import recharted_coordinates
    from ocp.spec.problem import ObjectSpec

    obj = request.get("object", {})
    spec = ObjectSpec(obj.get("shape", "sphere"), tuple(obj.get("dimensions", (0.025,))),
                      tuple(obj.get("chart_rotation", (0.0, 0.0, 0.0))))
    patch = result.get("chart_rotation")
    if not goal or patch is None or tuple(patch) == spec.chart_rotation:
        return goal
    again = recharted_coordinates(Chart.of(spec.surface, spec.dimensions, spec.chart_rotation),
                                  Chart.of(spec.surface, spec.dimensions, patch), goal)
    assert again is not None
    return again


def dexroll(*args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "planner_service.cli", *args], cwd=cwd,
                          capture_output=True, text=True, timeout=600, check=False)


def test_examples_include_the_paper_triangle_and_a_pure_reorientation() -> None:
    names = {p.stem for p in EXAMPLES}
    assert "triangle" in names
    assert any(n.startswith("reorient") for n in names)


@pytest.mark.parametrize("request_file", [
    pytest.param(p, marks=pytest.mark.slow) if p.stem in PLANNED_IN_TEST_SIM else p
    for p in EXAMPLES], ids=[p.stem for p in EXAMPLES])
def test_plan_writes_a_certified_result_and_a_summary(request_file: Path,
                                                      cli_plans: CliPlans) -> None:
    # `dexroll plan` as a real process (conftest: one run per example for the session;
    # tests/test_sim.py executes its result in MuJoCo)
    run = cli_plans[request_file]
    proc, out = run.proc, run.result_file
    assert proc.returncode == 0, proc.stdout + proc.stderr
    request = json.loads(request_file.read_text())
    # a desired object motion is summarised by its tracking error, palm goals by theirs
    aim = "tracking" if request.get("motion") else "goal error"
    for word in ("status", "iterations", aim, "certificate", "solve"):
        assert word in proc.stdout
    assert len(proc.stdout.splitlines()) <= 24, "the summary fits on one screen"
    result = json.loads(out.read_text())
    assert result["status"] == "solved"
    assert result["certificate"]["passed"] is True
    # the plan's samples: ball-on-palm results call them grid/eta, finger results
    # trajectory/eta_p (the palm contact coordinates), manipulation results trajectory and
    # the palm contact's eta (if the grasp has a palm; its goal is palm.goal)
    planner = result.get("planner", "ball_on_palm")
    goal = request.get("goal", {})
    if planner == "ball_on_palm":
        samples, palm_eta = result["grid"], result["grid"]["eta"]
    elif planner == "one_finger":
        samples, palm_eta = result["trajectory"], result["trajectory"]["eta_p"]
    else:
        samples = result["trajectory"]
        palm = [c["eta"] for c in samples["contacts"] if c["body"] == "palm"]
        palm_eta = palm[0] if palm else []
        goal = (request.get("palm") or {}).get("goal", {})
        # inside every friction cone, and within the tracking tolerances, at every sample
        assert min(samples["cone_margin"]) > 0.0
        tracking = request.get("tracking", {})
        for key, errors in (("position_tolerance", "tracking_position_error"),
                            ("orientation_tolerance", "tracking_angle_error")):
            if tracking.get(key) is not None:
                assert max(samples[errors]) <= tracking[key]
    assert samples["t"][0] == 0.0 and abs(samples["t"][-1] - request["duration"]) < 1e-12
    # every goal coordinate is met at the final time, in SI units, in the patch the
    # result states (the request's, or one the planner chose off the pole bound)
    names = ["x", "y", "u", "v", "psi"]
    goal = _in_result_patch(request, result, goal)
    for key, target in goal.items():
        err = palm_eta[-1][names.index(key)] - target
        if key in ("v", "psi"):
            err = (err + math.pi) % (2 * math.pi) - math.pi
        assert abs(err) < 1e-6, (key, palm_eta[-1], goal)


def test_invalid_request_exits_2_and_names_the_field(tmp_path: Path) -> None:
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"initial": {"x": 0, "y": 0, "u": 0, "v": 0, "psi": 0},
                               "goal": {"x": 0.01, "w": 2}, "duration": -1,
                               "object": {"dimensions": [-0.02]}}))
    proc = dexroll("plan", str(bad), "-o", str(tmp_path / "out.json"), cwd=tmp_path)
    assert proc.returncode == 2
    for field in ("goal.w", "duration", "object.dimensions.0"):
        assert field in proc.stderr
    assert "Traceback" not in proc.stderr + proc.stdout
    result = json.loads((tmp_path / "out.json").read_text())
    assert result["status"] == "invalid_input"
    assert {e["field"] for e in result["errors"]} >= {"goal.w", "duration"}


def test_goal_at_chart_pole_is_rejected_with_its_reason(tmp_path: Path) -> None:
    bad = tmp_path / "pole.json"
    bad.write_text(json.dumps({"initial": {"x": 0, "y": 0, "u": 0, "v": 0, "psi": 0},
                               "goal": {"u": 1.5707963}, "duration": 1}))
    proc = dexroll("plan", str(bad), "-o", str(tmp_path / "out.json"), cwd=tmp_path)
    assert proc.returncode == 2
    assert "goal.u" in proc.stderr and "pole" in proc.stderr


def test_unreadable_request_is_an_error_not_a_traceback(tmp_path: Path) -> None:
    bad = tmp_path / "broken.json"
    bad.write_text("{not json")
    proc = dexroll("plan", str(bad), "-o", str(tmp_path / "out.json"), cwd=tmp_path)
    assert proc.returncode == 2
    assert "not valid JSON" in proc.stderr and "Traceback" not in proc.stderr
