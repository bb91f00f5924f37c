"""How far from converged a plan is (issue 27): every manipulation plan's statistics carry
the primal and dual infeasibility of the NLP point it was read from, whatever stopped the
solver; a re-plan stopped after a fixed number of iterations (real-time-iteration style,
``AttemptOptions(max_iter=k)``) says how far it is, and the figures are what the NLP
itself gives at that point."""

from __future__ import annotations

from dataclasses import replace

import casadi as ca
import numpy as np
import pytest
from helpers import experiment1

from ocp import AttemptOptions, attempt
from ocp.solution import Status
from ocp.solve.attempt import setup
from ocp.solve.planner import ManipulationPlanner, ManipulationProblem
from planner_service.planners.manipulation import result_from_manipulation_solution

PLANNER = ManipulationPlanner()


def palm_and_finger(dx: float = 0.0) -> ManipulationProblem:
    """Experiment 1's grasp rolling the ball 13 mm (+ ``dx`` in x), 16 intervals."""
    return experiment1({"x": 0.012 + dx, "y": 0.006})


@pytest.fixture(scope="module")
def first() -> tuple[ManipulationProblem, object]:
    problem = palm_and_finger()
    sol = PLANNER.solve(problem)
    assert sol.status is Status.SOLVED and sol.certificate.passed, sol.certificate
    assert sol.stats is not None
    return problem.with_intervals(sol.stats.n_intervals), sol


def _recomputed(problem: ManipulationProblem, sol: object) -> tuple[float, float]:
    """The primal and dual infeasibility from the NLP's oracle alone at the plan's point:
    g against its bounds, the variables against theirs, and the Lagrangian's gradient by
    CasADi's reverse mode (not the block Jacobian the statistics use)."""
    s = setup(PLANNER, problem)
    nlp, pt = s.nlp, sol.nlp_point  # type: ignore[attr-defined]
    w = ca.MX.sym("w", len(pt.w))
    lam = ca.MX.sym("lam", len(pt.lam_g))
    f, g = nlp.oracle(w, s.p)
    grad = ca.Function("grad", [w, lam], [ca.gradient(f + ca.dot(lam, g), w)])
    gv = np.asarray(nlp.oracle(pt.w, s.p)[1]).ravel()
    primal = max(np.max(np.maximum(nlp.lbg - gv, gv - nlp.ubg)),
                 np.max(np.maximum(s.lbx - pt.w, pt.w - s.ubx)), 0.0)
    dual = np.max(np.abs(np.asarray(grad(pt.w, pt.lam_g)).ravel() + pt.lam_x))
    return float(primal), float(dual)


def test_a_converged_plan_is_at_a_kkt_point(first: tuple) -> None:
    problem, sol = first
    st = sol.stats
    assert st.primal_infeasibility is not None and st.dual_infeasibility is not None
    assert st.primal_infeasibility <= 1e-9
    assert st.dual_infeasibility <= 1e-5
    primal, dual = _recomputed(problem, sol)
    assert primal == pytest.approx(st.primal_infeasibility, abs=1e-12)
    assert dual == pytest.approx(st.dual_infeasibility, abs=1e-9)
    # and on the wire
    wire = result_from_manipulation_solution(sol).stats
    assert wire is not None
    assert wire.primal_infeasibility == st.primal_infeasibility
    assert wire.dual_infeasibility == st.dual_infeasibility


def test_a_fixed_iteration_replan_says_how_far_it_is(first: tuple) -> None:
    """One warm iteration toward a goal moved 2 mm: stopped by its budget, its residuals
    those of the NLP at the returned point, further from converged than the full re-plan,
    which reaches a KKT point again."""
    problem, sol = first
    moved = replace(problem, palm=replace(problem.palm, goal={
        k: v + (0.002 if k == "x" else 0.0) for k, v in problem.palm.goal.items()}))
    one = attempt(moved, warm=sol, planner=PLANNER, options=AttemptOptions(max_iter=1))
    assert one.status is Status.ITERATION_LIMIT and one.stats.iterations == 1
    primal, dual = _recomputed(moved, one)
    assert primal == pytest.approx(one.stats.primal_infeasibility, rel=1e-9, abs=1e-14)
    assert dual == pytest.approx(one.stats.dual_infeasibility, rel=1e-6, abs=1e-12)
    full = attempt(moved, warm=sol, planner=PLANNER)
    assert full.converged
    assert full.stats.primal_infeasibility <= 1e-9 < one.stats.primal_infeasibility
    assert full.stats.dual_infeasibility < one.stats.dual_infeasibility


def test_the_bench_names_each_family_s_solver() -> None:
    """The bench's row carries the solver whose point the plan is, and a family's summary
    (the report's ``solver`` column) names it, with counts when its problems differ."""
    from planner_service.bench.report import summarise

    def row(solver: str | None) -> dict[str, object]:
        return {"family": "f", "method": "collocation", "ok": True, "expected": "solved",
                "status": "solved", "solve_time": 1.0, "iterations": 3, "solver": solver}

    (one,) = summarise([row("ipopt"), row("ipopt")])
    assert one["solver"] == "ipopt"
    (mixed,) = summarise([row("fatrop"), row("fatrop"), row("ipopt (fatrop: Failed)")])
    assert mixed["solver"] == "fatrop 2, ipopt (fatrop: Failed) 1"
    (none,) = summarise([row(None)])
    assert none["solver"] is None


def test_a_warm_push_is_a_choice_of_the_attempt(first: tuple) -> None:
    """``AttemptOptions(warm_push=...)``: a warm solver of its own (kept for the next
    attempt), converging to the same plan as the library's warm start, certified."""
    problem, sol = first
    moved = replace(problem, palm=replace(problem.palm, goal={
        k: v + (0.002 if k == "x" else 0.0) for k, v in problem.palm.goal.items()}))
    usual = attempt(moved, warm=sol, planner=PLANNER, options=AttemptOptions(certify=True))
    pushed = attempt(moved, warm=sol, planner=PLANNER,
                     options=AttemptOptions(certify=True, warm_push=1e-6))
    nlp = setup(PLANNER, moved).nlp
    assert (1e-6, nlp.compiled) in nlp.warm_solvers
    assert nlp.warm_solvers[(1e-6, nlp.compiled)] is not nlp.warm_solver
    assert usual.status is pushed.status is Status.SOLVED
    assert pushed.stats.objective == pytest.approx(usual.stats.objective, rel=1e-6)
    np.testing.assert_allclose(pushed.X, usual.X, atol=1e-4)
