"""The stage-ordered NLP (issue 27): the same NLP as the kind-ordered one (its variables and
rows laid out stage by stage, each interval's end copied into its stage), in the layout
fatrop's stages need, and the same plans whichever solver (IPOPT on either order, fatrop
with IPOPT as its fallback)."""

from __future__ import annotations

from functools import partial
from typing import Any

import casadi as ca
import numpy as np
import pytest
from helpers import experiment1
from nlp_signature import CASES, build

from ocp.solve.attempt import setup
from ocp.solve.ipopt import FATROP_OPTIONS, StructuredSolver
from ocp.solve.planner import ManipulationPlanner
from ocp.spec.grasp import ManipulationProblem
from ocp.transcription.nlp_blocks import build_manipulation_nlp

STAGED = partial(build_manipulation_nlp, stage_order=True)


@pytest.mark.parametrize("name", sorted(CASES))
def test_the_stage_order_is_the_same_nlp(name: str) -> None:
    """At a point packed from the same parts: the same objective, the same constraint
    values (the kind order's rows, and the gap-closing rows at zero), the parts read back
    unchanged; the same variables parked."""
    _, a = build(name)
    _, b = build(name, STAGED)
    rng = np.random.default_rng(3)
    nw, p = a.pack.nnz_out(0), 0.5 + 0.2 * rng.random(a.params.size)
    parts = a.unpack(0.3 * rng.standard_normal(nw))
    w_a, w_b = (np.asarray(x.pack(*parts)).ravel() for x in (a, b))
    assert len(w_b) == nw + len(b.copies)
    f_a, g_a = (np.asarray(v).ravel() for v in a.oracle(w_a, p))
    f_b, g_b = (np.asarray(v).ravel() for v in b.oracle(w_b, p))
    np.testing.assert_allclose(f_b, f_a, rtol=1e-12)
    n_gap = len(g_b) - len(g_a)
    assert n_gap == len(b.copies)
    np.testing.assert_allclose(np.sort(g_b), np.sort(np.concatenate([g_a, np.zeros(n_gap)])),
                               rtol=1e-12, atol=1e-14)
    np.testing.assert_array_equal(np.sort(b.lbg), np.sort(np.concatenate([a.lbg,
                                                                          np.zeros(n_gap)])))
    for x, y in zip(b.unpack(w_b), parts, strict=True):
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))
    mark_a, mark_b = np.zeros(nw), np.zeros(len(w_b))
    mark_a[a.parked], mark_b[b.parked] = 1.0, 1.0
    for x, y in zip(a.unpack(mark_a), b.unpack(mark_b), strict=True):
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))


@pytest.mark.parametrize("name", sorted(CASES))
def test_the_stage_order_has_fatrop_s_structure(name: str) -> None:
    """Every row of stage k reads stage k's variables only, but the gap-closing rows, which
    read the next stage's state through +1 on the diagonal (exactly); the Lagrangian's
    Hessian is block-diagonal by stage."""
    _, b = build(name, STAGED)
    st = b.stages
    assert st is not None
    nx, nu, ng, n = st["nx"], st["nu"], st["ng"], st["N"]
    col0 = np.concatenate([[0], np.cumsum(np.add(nx, nu))])
    allowed: set[tuple[int, int]] = set()
    row = 0
    for k in range(n + 1):
        n_gap = nx[k + 1] if k < n else 0
        stage_cols = range(col0[k], col0[k + 1])
        allowed |= {(row + i, j) for i in range(n_gap + ng[k]) for j in stage_cols}
        allowed |= {(row + i, col0[k + 1] + i) for i in range(n_gap)}
        row += n_gap + ng[k]
    assert row == len(b.lbg)
    rng = np.random.default_rng(5)
    w = 0.3 * rng.standard_normal(b.pack.nnz_out(0))
    p = 0.5 + 0.2 * rng.random(b.params.size)
    J = b.jac_g(w, p)[1]
    r, c = (np.asarray(x) for x in J.sparsity().get_triplet())
    assert set(zip(r.tolist(), c.tolist(), strict=True)) <= allowed
    gap_rows = [(col0[k + 1], sum(nx[1:k + 1]) + sum(ng[:k])) for k in range(n)]
    Jd = np.asarray(ca.DM(J))
    for (x_next, row0), k in zip(gap_rows, range(n), strict=True):
        block = Jd[row0:row0 + nx[k + 1], x_next:x_next + nx[k + 1]]
        np.testing.assert_array_equal(block, np.eye(nx[k + 1]))
    H = b.hess_lag(w, p, 1.0, rng.standard_normal(len(b.lbg)))
    hr, hc = (np.asarray(x, dtype=np.int64) for x in H.sparsity().get_triplet())
    assert len(hr) > 0
    stage = np.searchsorted(col0, np.arange(col0[-1]), side="right") - 1
    np.testing.assert_array_equal(stage[hr], stage[hc])


def _experiment1() -> ManipulationProblem:
    return experiment1({"x": 0.012, "y": 0.006}, n_intervals=32)


def _same_plans(a: Any, b: Any) -> None:
    assert a.status == b.status
    assert bool(a.certificate.passed) == bool(b.certificate.passed)
    for key in ("X", "Xm", "U0", "Um", "U1"):
        x, y = getattr(a.collocation, key), getattr(b.collocation, key)
        np.testing.assert_allclose(y, x, atol=1e-6 * (1 + np.abs(x).max()), err_msg=key)


@pytest.fixture(scope="module")
def exp1_plans() -> dict[str, Any]:
    problem = _experiment1()
    return {label: ManipulationPlanner(**kw).solve(problem) for label, kw in (
        ("kind", {}), ("stage", {"stage_order": True}), ("fatrop", {"solver": "fatrop"}))}


def test_experiment1_gives_the_same_plan_in_either_order_and_either_solver(
        exp1_plans: dict[str, Any]) -> None:
    kind = exp1_plans["kind"]
    assert kind.certificate.passed
    _same_plans(kind, exp1_plans["stage"])
    _same_plans(kind, exp1_plans["fatrop"])
    assert kind.stats.solver == exp1_plans["stage"].stats.solver == "ipopt"
    assert exp1_plans["fatrop"].stats.solver == "fatrop"


def test_ipopt_takes_over_when_fatrop_fails() -> None:
    """fatrop stopped after two iterations: IPOPT solves the same NLP from the same point,
    and says so (with fatrop's status); the iterations of both are counted."""
    planner = ManipulationPlanner(stage_order=True)
    problem = _experiment1()
    s = setup(planner, problem)
    nlp = s.nlp
    assert nlp.stages is not None
    short = ca.nlpsol("short", "fatrop", nlp.oracle, {
        "structure_detection": "manual", **{k: nlp.stages[k] for k in ("N", "nx", "nu", "ng")},
        "fatrop": {**FATROP_OPTIONS, "max_iter": 2}, "print_time": False,
        "error_on_fail": False})
    assert isinstance(nlp.solver, StructuredSolver)
    solver = StructuredSolver(short, nlp.solver.fallback, nlp.copies)
    ipopt = planner.solve(problem)
    x0 = nlp.pack(*nlp.unpack(np.zeros(nlp.pack.nnz_out(0))))
    x0 = np.clip(np.asarray(x0).ravel(), s.lbx, s.ubx)
    res = solver(x0=x0, p=s.p, lbx=s.lbx, ubx=s.ubx, lbg=nlp.lbg, ubg=nlp.ubg)
    st = solver.stats()
    assert st["solver"].startswith("ipopt (fatrop: ") and st["success"]
    assert st["iter_count"] > 2
    assert np.all(np.isfinite(np.asarray(res["x"])))
    assert ipopt.stats.solver == "ipopt"
