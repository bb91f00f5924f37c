"""A plan whose fingertip contacts change chart at a node (``problem.chart_switch``;
:mod:`ocp.spec.chart_switch`), on its way through the solve: its two charts' models and
parameters (:class:`~ocp.transcription.chart_switch.PlanCharts`), the NLP's reference
angles at the switch, and initial guesses restated on the chart of each point.

An initial guess of the strategy's own is made on the problem's (first) chart for the
whole motion; the points from the switch node on are restated on the next chart
(:meth:`PlanCharts.to_second`), their angles continued along the motion. A previous plan
with the same switch is sampled with its own polynomials (each interval on its chart)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from ocp.spec.chart_switch import after_switch, switch_node
from ocp.spec.grasp import ManipulationProblem, contact_charts
from ocp.transcription.chart_switch import PlanCharts, n_refs
from ocp.transcription.collocation import node_inputs
from ocp.transcription.values import parameters as nlp_parameters

if TYPE_CHECKING:
    from ocp.solution import ManipulationSolution
    from ocp.solve.attempt import Setup

__all__ = ["plan_charts", "sampled_guess", "switch_parameters", "with_refs"]

FloatArray = NDArray[np.float64]
Guess = tuple[FloatArray, FloatArray, FloatArray, FloatArray]


def plan_charts(model: Any, problem: ManipulationProblem, m: Any, prm: FloatArray
                ) -> PlanCharts:
    """The charts a plan of ``problem`` is made on (``model``: the planner's grasp models
    by problem; ``m``, ``prm``: the problem's own)."""
    if problem.chart_switch is None:
        return PlanCharts.single(m, prm)
    pb = after_switch(problem)
    mb = model(pb)
    prm_b = mb.params(np.asarray(pb.object.params, dtype=float), contact_charts(pb))
    return PlanCharts((m, mb), (np.asarray(prm, dtype=float), prm_b), switch_node(problem),
                      np.zeros(n_refs(m)))


def switch_parameters(charts: PlanCharts) -> tuple[FloatArray, FloatArray] | None:
    """The NLP's ``charts_b`` and ``switch_refs`` of a switched plan (None: one chart)."""
    if not charts.switched:
        return None
    ns = charts.first.surface.n_params
    return charts.prms[1][ns:], charts.refs


def with_refs(s: Setup, X: FloatArray) -> None:
    """The switch's reference angles from the node states ``X`` (physical, rows) of the
    initial point IPOPT starts from: the first chart's at the node before the switch; the
    setup's parameter vector with them (nothing for one chart)."""
    charts = s.charts
    if not charts.switched:
        return
    assert charts.node is not None
    charts.refs = charts.refs_of(X[charts.node - 1])
    s.p = nlp_parameters(s.problem, s.nlp, (s.x_scale, s.u_scale), switch_parameters(charts))


def restated(s: Setup, guess: Guess) -> Guess:
    """A guess made on the first chart for the whole motion, its points from the switch
    node on restated on the next chart (angles continued along the motion:
    ``numpy.unwrap`` from the node before the switch)."""
    charts = s.charts
    if not charts.switched:
        return guess
    ks = charts.node
    assert ks is not None
    X, Xm, U, Um = (np.array(a, dtype=float) for a in guess)
    n = len(Xm)
    lc, rc = s.nlp.hs.left_cols, s.nlp.hs.right_cols
    zero = np.zeros(n_refs(charts.first))
    nodes, mids = range(ks, n + 1), range(ks, n)
    at_nodes = [charts.to_second(X[j], U[lc[j] if j < n else rc[n - 1]], zero)
                for j in nodes]
    at_mids = [charts.to_second(Xm[j], Um[j], zero) for j in mids]
    # the points in time order (node ks, mid ks, node ks+1, ...), their angles unwrapped
    seq = np.empty((len(at_nodes) + len(at_mids), X.shape[1]))
    seq[0::2] = [x for x, _ in at_nodes]
    seq[1::2] = [x for x, _ in at_mids]
    cols = charts.angle_columns()
    start = charts.to_second(X[ks - 1], None, zero)[0][cols]  # continued from just before
    seq[:, cols] = np.unwrap(np.vstack([start, seq[:, cols]]), axis=0)[1:]
    X[ks:], Xm[ks:] = seq[0::2], seq[1::2]
    for j, (_, ub) in zip(nodes, at_nodes, strict=True):
        for col in {lc[j] if j < n else rc[n - 1], rc[j - 1]}:
            U[col] = ub
    Um[ks:] = [u for _, u in at_mids]
    return X, Xm, U, Um


def sampled_guess(warm: ManipulationSolution, s: Setup) -> Guess | None:
    """A previous plan with the same switch time on this grid, sampled with its own
    polynomials (each point on its interval's chart); None for any other plan."""
    spec = s.problem.chart_switch
    if spec is None or warm.chart_switch is None or warm._interpolant is None \
            or abs(warm.chart_switch.time - spec.time) > 1e-9 \
            or abs(warm.duration - s.problem.duration) > 1e-9:
        return None
    t = s.t_nodes
    tm = (t[:-1] + t[1:]) / 2
    hs = s.nlp.hs
    U = node_inputs(lambda ts: warm.sample(ts).u, t, hs.left_cols, hs.right_cols,
                    hs.n_input_cols)
    sm = warm.sample(tm)
    X = warm.sample(t).x
    X[0] = s.x0
    return X, sm.x, U, sm.u
