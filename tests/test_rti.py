"""The real-time-iteration backend of the window controller (issue 41; ocp.solve.rti,
docs/control.md): the window by multiple shooting, one Gauss-Newton QP a tick solved by
HPIPM, linearised before the measurement. The laws: the shooting form is the same NLP
(a converged collocation window satisfies its rows; its Jacobian and gradient are the
derivatives of its rows and objective); the windows it returns along the plan and from a
pushed state start at exactly the measured state and pass the plan's certificate; a
prepared tick spends its wall time on the QP alone; ``backend="auto"`` keeps the backend
it measured faster; what it cannot shoot is refused naming the field."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from ocp.control import ControllerOptions, WindowController
from ocp.solve.backend import IpoptWindow, window_backend
from ocp.solve.rti import RtiBackend, rti_support
from ocp.spec.problem import ProblemError
from planner_service.execution.closed_loop import FirstPlan
from tests.window_helpers import NO_DEADLINE, experiment2, pushed_estimate

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def first() -> FirstPlan:
    return experiment2()


def _failed(cert: object) -> list[tuple[str, float, float]]:
    return [(ch.name, ch.value, ch.tolerance) for ch in cert.checks  # type: ignore[attr-defined]
            if not ch.passed]


def test_the_shooting_form_is_the_same_nlp(first: FirstPlan) -> None:
    """IPOPT's converged window at 1 s, written as shooting variables, satisfies the
    shooting rows (Runge-Kutta 4 over each interval against Hermite-Simpson: within
    1e-7 in the scaled units) and their bounds; the linearisation's Jacobian and the
    objective's gradient are the rows' and objective's derivatives (a random step of
    1e-6: agreement to second order)."""
    c = WindowController(first.problem, first.plan,
                         ControllerOptions(max_iter=50, time_limit=NO_DEADLINE))
    t = 1.0
    tick = c.tick(t, c.state_at(t)[0])
    assert tick.status == "converged"
    s = tick._setup
    assert s is not None and tick._w is not None
    b = RtiBackend()
    win = b.window(s)
    W = b.initial(s, tick._w)
    lo, hi = win.bounds(s.lbx, s.ubx)
    g, obj = (np.asarray(a).ravel() for a in win.rows(W, s.p))
    assert np.max(np.maximum(win.lbg - g, g - win.ubg)) < 1e-7
    assert np.max(np.maximum(lo - W, W - hi)) == 0.0
    lin = b.linearise(s, W)
    d = np.random.default_rng(0).normal(size=win.nW) * 1e-6
    g1, obj1 = (np.asarray(a).ravel() for a in win.rows(W + d, s.p))
    Jd = np.asarray(ca.mtimes(lin.jac, ca.DM(d))).ravel()
    assert np.max(np.abs((g1 - g) - Jd)) < 1e-9
    grad = np.asarray(lin.grad).ravel()
    assert float(obj1[0] - obj[0]) == pytest.approx(float(grad @ d), rel=1e-2, abs=1e-12)
    # the window written back on the collocation grid is the same plan (nodes, inputs)
    w = win.collocation_point(W, s.p, tick._w)
    Xs = [np.asarray(a) for a in s.nlp.unpack(w)[:4]]
    X0 = [np.asarray(a) for a in s.nlp.unpack(tick._w)[:4]]
    for a, b_ in zip(Xs, X0, strict=True):
        np.testing.assert_allclose(a, b_, rtol=0, atol=1e-6)


def test_windows_along_the_plan_are_certified_and_a_prepared_tick_is_its_qp(
        first: FirstPlan) -> None:
    """RTI ticks every 10 ms around 2 s of experiment 2 from the plan's own state, each
    prepared after the last one's answer: one QP a tick; each window starts at exactly
    the measured state and is certified; the tick's wall time excludes the preparation,
    which is reported apart."""
    c = WindowController(first.problem, first.plan, ControllerOptions(backend="rti"))
    assert c.backend.name == "rti"
    c.prepare()
    t0 = 2.0
    c.tick(t0, c.state_at(t0)[0])
    for k in range(1, 6):
        t = t0 + 0.01 * k
        prep = c.prepare_next(t)
        x, _ = c.state_at(t)
        tick = c.tick(t, x)
        assert prep > 0 and tick.prepare_time == prep
        assert tick.status in ("tracked", "converged")
        assert tick.iterations == 1 and tick.raw_status.startswith("hpipm")
        assert tick.collocation is not None
        np.testing.assert_allclose(tick.collocation.X[0], x, rtol=0, atol=1e-12)
        assert tick.primal_infeasibility is not None and tick.primal_infeasibility < 1e-5
        assert tick.input is not None and np.array_equal(tick.input, tick.collocation.U0[0])
    cert = c.certify(tick)
    assert cert.passed, _failed(cert)
    # an unprepared tick (nothing prepared for its time) linearises within its own time
    tick = c.tick(t0 + 0.2, c.state_at(t0 + 0.2)[0])
    assert tick.prepare_time == 0.0 and tick.collocation is not None


def test_a_pushed_window_starts_where_measured_and_is_certified(first: FirstPlan) -> None:
    """The ball measured 1 mm off the plan at 2 s (the estimate makes the state
    consistent): two real-time iterations from the reference's guess; the window starts
    at the estimated state, ends nearer the reference than it started, and is
    certified."""
    c = WindowController(first.problem, first.plan,
                         ControllerOptions(backend="rti", max_iter=2))
    c.prepare()
    t = 2.0
    est = pushed_estimate(c, first, t, (0.0, 1e-3, 0.0))
    tick = c.tick(t, est.x)
    assert tick.collocation is not None
    np.testing.assert_allclose(tick.collocation.X[0], est.x, rtol=0, atol=1e-12)
    sol = c.plan(tick, certify=True)
    assert sol.certificate.passed, _failed(sol.certificate)
    ref_start = first.plan.sample([t]).object_position[0]
    ref_end = first.plan.sample([t + c.options.horizon]).object_position[0]
    start = np.linalg.norm(sol.sample([0.0]).object_position[0] - ref_start)
    end = np.linalg.norm(sol.sample([c.options.horizon]).object_position[0] - ref_end)
    assert start > 0.5e-3 and end < 0.5 * start


def test_auto_keeps_the_backend_it_measured_faster(first: FirstPlan) -> None:
    """``backend="auto"``: both backends measured on the same ticks, each one's last
    window certified; the one kept is the certified one with the least busy time."""
    c = WindowController(first.problem, first.plan, ControllerOptions(backend="auto"))
    c.prepare()
    sel = c.selection
    assert sel is not None and set(sel["measured"]) == {"ipopt", "rti"}
    m = sel["measured"]
    ok = [n for n in m if m[n]["certified"]]
    assert ok and sel["chosen"] == min(ok, key=lambda n: m[n]["busy_median"])
    assert c.backend.name == sel["chosen"]
    assert m["ipopt"]["preparation_median"] == 0.0
    assert not c.ticks  # the measurement's ticks are not the controller's
    tick = c.tick(0.01, c.state_at(0.01)[0])
    assert tick.collocation is not None


def test_what_it_cannot_shoot_is_refused_naming_the_field(first: FirstPlan) -> None:
    """A grasp without the smooth timing (its inputs jump at the nodes) is not shot:
    ProblemError on ``options.backend`` with the reason, at the first window; an unknown
    backend is refused with the names there are."""
    problem = replace(first.problem, timing="paper")
    c = WindowController(problem, first.plan, ControllerOptions(backend="rti"))
    with pytest.raises(ProblemError) as err:
        c.prepare()
    (field, why), = err.value.errors
    assert field == "options.backend" and "smooth" in why
    with pytest.raises(ProblemError) as err:
        WindowController(first.problem, first.plan, ControllerOptions(backend="acados"))
    (field, why), = err.value.errors
    assert field == "options.backend" and "'rti'" in why and "'auto'" in why
    assert isinstance(window_backend("ipopt"), IpoptWindow)
    with pytest.raises(ValueError, match="unknown window backend"):
        window_backend("acados")
    c = WindowController(problem, first.plan)  # (IPOPT's window of the same grasp)
    assert "smooth" in str(rti_support(c._setup(c.window(0.0), c.state_at(0.0)[0])))
