"""The library's front door: ``ocp`` exports what a user needs, each name the object its
module defines, loaded on first use; ``ocp.plan`` plans every kind of problem."""

from __future__ import annotations

import importlib
import math
import subprocess
import sys

import pytest

import ocp


def test_every_exported_name_is_its_modules_object() -> None:
    assert set(ocp.__all__) == {*ocp._EXPORTS, "plan"}
    for name, module in ocp._EXPORTS.items():
        assert getattr(ocp, name) is getattr(importlib.import_module(module), name), name
    with pytest.raises(AttributeError, match="no attribute 'nothing'"):
        ocp.nothing  # noqa: B018


def test_importing_one_module_loads_no_planner() -> None:
    code = ("import sys, ocp.geometry.surfaces; "
            "print(sorted(m for m in sys.modules if m.startswith('ocp.solve')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout
    assert out.strip() == "[]"


def test_plan_solves_a_ball_on_palm_problem_and_refuses_other_objects() -> None:
    problem = ocp.BallOnPalmProblem(object=ocp.ObjectSpec("sphere", (0.025,)),
                                    initial=(0.0, 0.0, 0.0, 0.0, 0.0),
                                    goal={"x": 0.01, "psi": 0.3}, duration=1.0,
                                    n_intervals=10)
    sol = ocp.plan(problem)
    assert sol.status is ocp.Status.SOLVED and sol.certificate.passed
    assert sol.sample([1.0]).eta[0, 0] == pytest.approx(0.01, abs=1e-6)
    with pytest.raises(TypeError, match="no planner for str"):
        ocp.plan("a ball")
    with pytest.raises(ocp.ProblemError, match="duration"):
        ocp.plan(ocp.BallOnPalmProblem(object=problem.object, initial=problem.initial,
                                       goal=problem.goal, duration=-1.0))
    assert math.isfinite(sol.stats.solve_time)
