"""experiments/experiment2.py end to end: the paper's experiment 2 with the built-in
two-finger hand, its figures and summary written to a temporary folder (one NLP solve)."""

from __future__ import annotations

import importlib.util
import json
import math
import sys
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest

SCRIPT = Path(__file__).resolve().parents[1] / "experiments" / "experiment2.py"
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def script() -> ModuleType:
    spec = importlib.util.spec_from_file_location("experiment2", SCRIPT)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def output(script: ModuleType, tmp_path_factory: pytest.TempPathFactory
           ) -> tuple[Path, dict[str, Any]]:
    out = tmp_path_factory.mktemp("experiment2")
    returned = script.main(["--out", str(out)])
    written = json.loads((out / script.SUMMARY).read_text(encoding="utf-8"))
    assert written == json.loads(json.dumps(returned))
    return out, written


def test_figures_are_drawn(script: ModuleType, output: tuple[Path, dict[str, Any]]) -> None:
    out, summary = output
    assert summary["figures"] == list(script.FIGURES)
    assert {"fig9_positions.png", "fig10_contacts_on_fingertips.png"} <= set(script.FIGURES)
    for name in script.FIGURES:
        data = (out / name).read_bytes()
        assert data[:8] == PNG_MAGIC and len(data) > 10_000, name


def test_plan_is_certified_and_tracks_the_paper_motion(script: ModuleType,
                                                       output: tuple[Path, dict[str, Any]]
                                                       ) -> None:
    _, s = output
    assert s["status"] == "solved" and s["certificate_passed"], s["message"]
    assert s["max_tracking_position_error_m"] <= script.POSITION_TOLERANCE
    assert s["max_tracking_angle_error_rad"] <= script.ORIENTATION_TOLERANCE
    # the ball does turn: 20 deg about Z, then 20 deg about Y on top of it
    assert s["max_rotation_from_start_rad"] >= math.radians(20)
    assert s["min_cone_margin_rad"] > 0
    assert s["closure_error_m"] <= 1e-4
    for name, f in s["fingers"].items():
        assert f["pad_excursion_m"] < s["setup"]["pad_half_size_m"], name
        assert f["pad_contact_path_length_m"] > 0.005, name  # the contacts roll over the pads
