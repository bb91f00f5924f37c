"""experiments/experiment1.py end to end: the paper's experiment 1 planned by both methods,
its figures and summary written to a temporary folder (one NLP solve, ~10 s)."""

from __future__ import annotations

import importlib.util
import itertools
import json
import math
import sys
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest

SCRIPT = Path(__file__).resolve().parents[1] / "experiments" / "experiment1.py"
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
#: The palm contact path's goal and via-points are met to this [m] (both methods integrate
#: or collocate the same rolling equations; the NLP's are equality constraints).
GOAL_TOL = 1e-6
CONVERGED = math.radians(1.0)


def load_script() -> ModuleType:
    spec = importlib.util.spec_from_file_location("experiment1", SCRIPT)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up here
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def script() -> ModuleType:
    return load_script()


@pytest.fixture(scope="module")
def output(script: ModuleType, tmp_path_factory: pytest.TempPathFactory
           ) -> tuple[Path, dict[str, Any]]:
    out = tmp_path_factory.mktemp("experiment1")
    returned = script.main(["--out", str(out)])
    written = json.loads((out / script.SUMMARY).read_text(encoding="utf-8"))
    assert written == json.loads(json.dumps(returned))  # the file is what main returned
    return out, written


def test_figures_are_non_empty_pngs(script: ModuleType,
                                    output: tuple[Path, dict[str, Any]]) -> None:
    out, summary = output
    assert set(script.FIGURES) >= {"fig6_paths.png", "fig7_contact_on_fingertip.png",
                                   "grasp_angles.png"}
    assert summary["figures"] == list(script.FIGURES)
    for name in script.FIGURES:
        data = (out / name).read_bytes()
        assert data[:8] == PNG_MAGIC, name
        assert len(data) > 10_000, (name, len(data))  # drawn, not a blank canvas


def test_both_methods_reach_the_goal_and_an_antipodal_grasp(
        output: tuple[Path, dict[str, Any]]) -> None:
    _, summary = output
    methods = summary["methods"]
    assert set(methods) == {"nlp", "greedy"}
    for name, m in methods.items():
        assert m["ok"], (name, m["message"], m["failures"])
        assert m["goal_error_m"] < GOAL_TOL, name
        # started away from antipodal on purpose (the paper's experiment), then brought in
        assert m["grasp_angle_start_rad"] > 5 * CONVERGED, name
        assert m["time_below_1deg_s"] is not None, name
        assert m["time_below_1deg_s"] < summary["setup"]["via_point_times_s"][0], name
        assert 0.0 < m["min_cone_margin_rad"] <= math.atan(summary["setup"]["mu"]), name


def test_nlp_certificate_passed(output: tuple[Path, dict[str, Any]]) -> None:
    nlp = output[1]["methods"]["nlp"]
    assert nlp["status"] == "solved"
    assert nlp["certificate_passed"] is True, nlp["certificate_failures"]
    assert nlp["certificate_failures"] == []
    assert nlp["closure_error_m"] <= 1e-4  # the certificate's own tolerance


def test_paths_scale_as_in_the_papers_figures(output: tuple[Path, dict[str, Any]]) -> None:
    """The ball's centre goes round the triangle; the pad, rolling on the ball's top, moves
    twice as far (figure 6); the contact crosses the pad as far as the ball travels
    (figure 7). Loose bounds: the grasp is not antipodal at the start."""
    _, summary = output
    corners = summary["setup"]["triangle_m"]
    perimeter = sum(math.dist(a, b) for a, b in itertools.pairwise(corners))
    for name, m in summary["methods"].items():
        ball = m["ball_centre_path_length_m"]
        assert ball == pytest.approx(perimeter, rel=0.02), name
        assert m["fingertip_path_length_m"] == pytest.approx(2 * ball, rel=0.1), name
        assert m["pad_contact_path_length_m"] == pytest.approx(ball, rel=0.15), name
        assert m["pad_excursion_m"] < summary["setup"]["pad_half_size_m"], name
