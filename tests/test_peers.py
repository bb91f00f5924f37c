"""The peers of planner_service.bench.peers pose the project's ball-on-palm NLP.

``casadi_plain`` is the same NLP built the plain way: it must find the project's optimum.
``drake`` (Drake's DirectCollocation with its IPOPT; skipped unless the ``peers`` extra is
installed) discretises slightly differently: close to ours, and certified. No timing is
asserted here; ``python -m planner_service.bench.peers`` measures.
"""

from __future__ import annotations

import importlib
import importlib.util
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from helpers import assert_close

from dexroll_client.models import BallOnPalmRequest
from ocp.ball_on_palm import BallOnPalmPlanner, wrap_difference
from ocp.solution import Solution, Status
from ocp.spec.problem import BallOnPalmProblem
from planner_service.bench import peers
from planner_service.planners import to_problem

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
TRIANGLE = "triangle.json"  # the paper's triangle: two via-points, N = 60
REORIENT = "reorient_vertical_90deg.json"  # a pure reorientation (the gauge), N = 50


def request(name: str, **changes: Any) -> BallOnPalmRequest:
    return BallOnPalmRequest.model_validate({**json.loads((EXAMPLES / name).read_text()),
                                             **changes})


_OURS: dict[str, Solution] = {}


def ours(name: str) -> Solution:
    """The project's plan of an example with the paper's timing, the peers' (one solve per
    test session)."""
    if name not in _OURS:
        problem = to_problem(request(name, timing="paper"))
        assert isinstance(problem, BallOnPalmProblem)
        sol = BallOnPalmPlanner().solve(problem)
        # the peers solve once from the first guess: compare with a plan that did too
        assert sol.status is Status.SOLVED
        assert (sol.stats.attempts, sol.stats.refinements) == (1, 0)
        _OURS[name] = sol
    return _OURS[name]


def assert_certified(out: peers.PeerOutcome) -> None:
    assert out.status == "solved", out.message
    assert out.goal_error is not None and out.goal_error <= peers.GOAL_TOLERANCE
    assert out.certificate["passed"] == 1.0, out.message
    assert out.build_time > 0.0 and out.solve_time > 0.0
    assert out.iterations is not None and out.iterations > 0


def test_methods_and_availability() -> None:
    assert set(peers.PEER_METHODS) == {"casadi_plain", "drake"}
    avail = peers.available()
    assert avail["casadi_plain"] is True
    assert avail["drake"] == (importlib.util.find_spec("pydrake") is not None)


@pytest.mark.parametrize("name", [TRIANGLE, REORIENT])
def test_casadi_plain_finds_our_optimum(name: str) -> None:
    """Same NLP, same first guess, same IPOPT options: the same optimum and plan."""
    sol = ours(name)
    out = peers.PEER_METHODS["casadi_plain"](request(name))
    assert_certified(out)
    assert out.objective is not None and sol.stats.objective is not None
    assert_close(out.objective, sol.stats.objective, atol=0.0, rtol=1e-6)
    assert out.t is not None and out.eta is not None and out.w is not None
    assert_close(out.t, sol.nodes.t, atol=1e-12)
    assert_close(out.eta[:, :3], sol.nodes.eta[:, :3], atol=[1e-8, 1e-8, 1e-6])
    assert_close(wrap_difference(out.eta[:, 3:], sol.nodes.eta[:, 3:]), 0.0, atol=1e-6)
    assert_close(out.w, sol.nodes.w, atol=1e-8)
    # the same IPOPT path: the same iteration count as the project's single attempt
    assert out.iterations == sol.stats.iterations


def test_drake_is_unavailable_without_pydrake(monkeypatch: pytest.MonkeyPatch) -> None:
    real = importlib.import_module

    def no_pydrake(name: str, package: str | None = None) -> Any:
        if name.startswith("pydrake"):
            raise ImportError(f"No module named {name!r}")
        return real(name, package)

    monkeypatch.setattr(peers.importlib, "import_module", no_pydrake)
    out = peers.PEER_METHODS["drake"](request(TRIANGLE))
    assert out.status == "unavailable"
    assert "peers" in out.message and out.certificate == {}


def test_drake_models_the_sphere_only() -> None:
    pytest.importorskip("pydrake", reason="Drake is the optional 'peers' extra")
    ellipsoid = request(REORIENT, object={"shape": "ellipsoid", "dimensions": [0.03, 0.02]})
    out = peers.PEER_METHODS["drake"](ellipsoid)
    assert out.status == "unavailable" and "sphere" in out.message


def test_drake_solves_the_triangle_like_ours() -> None:
    pytest.importorskip("pydrake", reason="Drake is the optional 'peers' extra")
    sol = ours(TRIANGLE)
    out = peers.PEER_METHODS["drake"](request(TRIANGLE))
    assert_certified(out)
    assert out.objective is not None and sol.stats.objective is not None
    # a first-order-hold input and trapezoidal cost instead of our quadratic input and
    # Simpson's rule: the effort integral agrees within a few percent
    assert_close(out.objective, sol.stats.objective, atol=0.0, rtol=0.03)
    assert out.t is not None and out.eta is not None
    assert_close(out.t, sol.nodes.t, atol=1e-12)  # the same grid, via-points on its nodes
    side = 0.03  # m, the triangle's
    assert float(np.max(np.abs(out.eta[:, :2] - sol.nodes.eta[:, :2]))) <= 0.05 * side


def test_drake_solves_the_reorientation() -> None:
    pytest.importorskip("pydrake", reason="Drake is the optional 'peers' extra")
    sol = ours(REORIENT)
    out = peers.PEER_METHODS["drake"](request(REORIENT))
    assert_certified(out)
    assert out.objective is not None and sol.stats.objective is not None
    assert_close(out.objective, sol.stats.objective, atol=0.0, rtol=0.03)
