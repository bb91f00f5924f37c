"""A grasp whose fingertip contacts change chart at a node of the grid: the map of the
contact coordinates from one chart of the object to another (docs/shapes.md, "Charts
that switch inside a plan").

A plan's contacts are measured in one chart of the object (its latitude/longitude chart,
or an egg's side chart, :class:`~ocp.shapes.ellipsoid.EggSideSurface`), and each chart
has poles where its coordinates are singular. A contact that rolls from where one chart
is regular to where only the other is can still be planned in one NLP: the grid's
intervals before the switch node are in the first chart, the node and everything after
it in the second (:class:`ChartSwitch`), and the interval that ends at the switch node
reads its end in the first chart through :func:`chart_map` (the same surface point, the
same contact frame, the same rates): its Hermite-Simpson defects are the first chart's
throughout. Nothing else of the NLP changes: every point and interval has the blocks of
its chart's grasp model, with that chart's patches (``charts`` before the switch,
``charts_b`` from it).

The map of one fingertip's coordinates eta = (a, b, u, v, psi) and input w = d(u, v)/dt:
the tip's point (a, b) and the joints are the same in both charts; the object point
p = R_c f(u, v) (R_c the contact's patch) is the same point, so (u', v') is the second
chart's inverse of R_c'^T p; the contact frame is the same, so the contact angle turns
by the angle between the two charts' frames at that point (the formula of
:func:`~ocp.spec.patches.recharted_coordinates`); the rates w' = d(u', v')/d(u, v) w.
The longitude and the angle are continued from reference values (``refs``: the target
chart's v and psi near the point; in the NLP the first chart's at the switch, from the
initial guess) so that a point near atan2's cut keeps its branch.

What a plan on two charts is downstream of its NLP (:class:`PlanCharts`): every interval
and every point is evaluated with its own chart's model and parameters (the switch
interval, whose polynomial is the first chart's, ends at the switch node's state read in
the first chart, ``HermiteInterpolant.X1``); the re-integration of the certificate goes on
across the switch from the state it reached, restated in the next chart.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any

import casadi as ca
import numpy as np
from numpy.typing import NDArray

from ocp.transcription.collocation import HermiteInterpolant, reintegrate

__all__ = ["ChartSwitch", "PlanCharts", "chart_map", "n_refs"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class ChartSwitch:
    """Every fingertip contact changes chart at grid node ``node`` (0 < node < N): the
    intervals before it are in the grasp model's chart, the node and all after it in
    ``model``'s (a :class:`~ocp.transcription.grasp_model.GraspModel` of the same grasp
    on another chart of the same object: the same states, inputs and parameters)."""

    node: int
    model: Any


def n_refs(m: Any) -> int:
    """The number of reference values :func:`chart_map` takes (two per fingertip)."""
    return 2 * len(m.fingertips)


def _continued(angle: Any, ref: Any) -> Any:
    """``angle`` (mod 2 pi) on the branch within pi of ``ref``."""
    d = angle - ref
    return ref + ca.atan2(ca.sin(d), ca.cos(d))


def _psi_matrix(psi: Any) -> Any:
    c, s = ca.cos(psi), ca.sin(psi)
    return ca.vertcat(ca.horzcat(c, -s, 0), ca.horzcat(-s, -c, 0), ca.horzcat(0, 0, -1))


@lru_cache(maxsize=32)
def chart_map(m_from: Any, m_to: Any) -> ca.Function:
    """``(x, u, shape, charts_from, charts_to, refs) -> (x_to, u_to)``: a state and input
    of the grasp (physical units) with its fingertip contacts in ``m_from``'s chart
    restated in ``m_to``'s (the module's map); ``refs`` (:func:`n_refs`): per fingertip
    the second chart's longitude and contact angle near which they are continued. The
    object's block and any contact but a fingertip's are the same in both (a switched
    plan has no palm: :class:`ChartSwitch`). Built once per pair of models."""
    if m_from.nx != m_to.nx or m_from.nu != m_to.nu or \
            m_from.surface.n_params != m_to.surface.n_params or \
            len(m_from.fingertips) != len(m_to.fingertips) or \
            len(m_from.point_contacts) != len(m_from.fingertips):
        raise ValueError("a chart switch maps between two charts of the same grasp of "
                         "fingertips alone (the same states, inputs and parameters)")
    x, u = ca.SX.sym("x", m_from.nx), ca.SX.sym("u", m_from.nu)
    shape = ca.SX.sym("shape", m_from.surface.n_params)
    nc = m_from.n_contacts
    charts_from, charts_to = ca.SX.sym("charts_from", 9 * nc), ca.SX.sym("charts_to", 9 * nc)
    refs = ca.SX.sym("refs", n_refs(m_from))
    xs, us = [x[j] for j in range(m_from.nx)], [u[j] for j in range(m_from.nu)]
    for i, tip in enumerate(m_from.fingertips):
        k = m_from.point_contacts.index(tip)
        Rf = ca.reshape(charts_from[9 * k:9 * k + 9], 3, 3)
        Rt = ca.reshape(charts_to[9 * k:9 * k + 9], 3, 3)
        e0 = tip.eta_cols.start
        uv = ca.vertcat(x[e0 + 2], x[e0 + 3])
        p, G, _, _, _ = m_from.surface.geometry(uv, shape)
        body = ca.mtimes(Rf, p)
        raw = m_to.surface.inverse_expr(ca.mtimes(Rt.T, body), shape)
        uv_to = ca.vertcat(raw[0], _continued(raw[1], refs[2 * i]))
        _, G_to, _, _, _ = m_to.surface.geometry(uv_to, shape)
        M = ca.mtimes([_psi_matrix(x[e0 + 4]), ca.mtimes(Rf, G).T, ca.mtimes(Rt, G_to)])
        psi_to = _continued(ca.atan2(-M[0, 1], M[0, 0]), refs[2 * i + 1])
        w_to = ca.mtimes(ca.jacobian(uv_to, uv), u[tip.w_cols])
        xs[e0 + 2], xs[e0 + 3], xs[e0 + 4] = uv_to[0], uv_to[1], psi_to
        w0 = tip.w_cols.start
        us[w0], us[w0 + 1] = w_to[0], w_to[1]
    return ca.Function("chart_map", [x, u, shape, charts_from, charts_to, refs],
                       [ca.vertcat(*xs), ca.vertcat(*us)],
                       ["x", "u", "shape", "charts_from", "charts_to", "refs"],
                       ["x_to", "u_to"])


@lru_cache(maxsize=32)
def _rate_map(m_from: Any, m_to: Any) -> ca.Function:
    """``(x, x_dot, shape, charts_from, charts_to, refs) -> x_dot_to``: a state's rate
    restated by :func:`chart_map`'s Jacobian (once per pair of models)."""
    xs, xd = ca.SX.sym("x", m_from.nx), ca.SX.sym("xd", m_from.nx)
    shape = ca.SX.sym("shape", m_from.surface.n_params)
    nc = m_from.n_contacts
    cf, ct = ca.SX.sym("cf", 9 * nc), ca.SX.sym("ct", 9 * nc)
    refs = ca.SX.sym("refs", n_refs(m_from))
    x_to = chart_map(m_from, m_to)(xs, ca.DM.zeros(m_from.nu), shape, cf, ct, refs)[0]
    return ca.Function("rate_map", [xs, xd, shape, cf, ct, refs], [ca.jtimes(x_to, xs, xd)])


def _outputs(result: Any) -> list[FloatArray]:
    """A CasADi function's outputs as arrays (one output comes alone, not in a list)."""
    if isinstance(result, (list, tuple)):
        return [np.asarray(v) for v in result]
    return [np.asarray(result)]


@dataclass
class PlanCharts:
    """The grasp models and parameters of a plan's charts: one (``models[0]``,
    ``prms[0]`` everywhere), or two with a switch at grid node ``node`` (intervals before
    it and their points on the first, the node and everything after on the second;
    ``refs``: the first chart's longitude and contact angle per fingertip at the switch,
    the NLP's ``switch_refs``)."""

    models: tuple[Any, ...]
    prms: tuple[FloatArray, ...]
    node: int | None = None
    refs: FloatArray = field(default_factory=lambda: np.zeros(0))

    @staticmethod
    def single(m: Any, prm: FloatArray) -> PlanCharts:
        return PlanCharts((m,), (np.asarray(prm, dtype=float),))

    @property
    def switched(self) -> bool:
        return self.node is not None

    @property
    def first(self) -> Any:
        return self.models[0]

    def interval_charts(self, k: Any) -> NDArray[np.intp]:
        """The chart (0, 1) of each interval ``k``."""
        k = np.asarray(k, dtype=np.intp)
        return np.zeros_like(k) if self.node is None else (k >= self.node).astype(np.intp)

    def node_charts(self, j: Any) -> NDArray[np.intp]:
        """The chart of each node ``j``'s state (the switch node's is the second)."""
        return self.interval_charts(j)

    def point_charts(self, n: int) -> NDArray[np.intp]:
        """The chart of every collocation point of ``n`` intervals: nodes, then midpoints."""
        return np.concatenate([self.node_charts(np.arange(n + 1)),
                               self.interval_charts(np.arange(n))])

    def evaluate(self, name: str, charts: Any, *cols: Any) -> list[FloatArray]:
        """The models' function ``name`` (cartesian, laws, dynamics, path) at columns
        ``cols`` (each argument's columns, one per point), each point with its chart's
        model and parameters (``charts``): the outputs' columns in the points' order."""
        charts = np.asarray(charts, dtype=np.intp)
        k = len(charts)
        if not self.switched or not charts.any():
            return _outputs(self.first.mapped(name, k)(*cols, self.prms[0]))
        outs: list[FloatArray] | None = None
        for c in (0, 1):
            idx = np.flatnonzero(charts == c)
            if not len(idx):
                continue
            part = self.models[c].mapped(name, len(idx))(
                *[np.asarray(a)[:, idx] for a in cols], self.prms[c])
            part = _outputs(part)
            if outs is None:  # (an output of several columns per point: its blocks)
                outs = [np.zeros((v.shape[0], v.shape[1] // len(idx) * k)) for v in part]
            for o, v in zip(outs, part, strict=True):
                w = v.shape[1] // len(idx)
                o[:, (idx[:, None] * w + np.arange(w)).ravel()] = v
        assert outs is not None
        return outs

    # -- the switch's map, numerically -------------------------------------------------
    def _map(self, backwards: bool) -> ca.Function:
        a, b = self.models
        return chart_map(b, a) if backwards else chart_map(a, b)

    def _charts(self, c: int) -> FloatArray:
        ns = self.first.surface.n_params
        return np.asarray(self.prms[c][ns:], dtype=float)

    def to_first(self, x: FloatArray, u: FloatArray | None = None
                 ) -> tuple[FloatArray, FloatArray]:
        """A state (and input) on the second chart restated on the first (at the switch:
        continued from :attr:`refs`)."""
        m = self.first
        u = np.zeros(m.nu) if u is None else u
        shape = self.prms[0][:m.surface.n_params]
        xa, ua = self._map(True)(x, u, shape, self._charts(1), self._charts(0), self.refs)
        return np.asarray(xa).ravel(), np.asarray(ua).ravel()

    def to_second(self, x: FloatArray, u: FloatArray | None, refs: FloatArray
                  ) -> tuple[FloatArray, FloatArray]:
        """A state (and input) on the first chart restated on the second, its angles
        continued from ``refs`` (:func:`n_refs`)."""
        m = self.first
        u = np.zeros(m.nu) if u is None else u
        shape = self.prms[0][:m.surface.n_params]
        xb, ub = self._map(False)(x, u, shape, self._charts(0), self._charts(1), refs)
        return np.asarray(xb).ravel(), np.asarray(ub).ravel()

    def rate_to_first(self, x: FloatArray, xdot: FloatArray) -> FloatArray:
        """A state's rate on the second chart as the first chart's (the map's Jacobian)."""
        m = self.first
        fn = _rate_map(self.models[1], m)
        return np.asarray(fn(x, xdot, self.prms[0][:m.surface.n_params], self._charts(1),
                             self._charts(0), self.refs)).ravel()

    def refs_of(self, x: FloatArray) -> FloatArray:
        """A state's longitude and contact angle per fingertip (:func:`n_refs`)."""
        return np.asarray(x, dtype=float)[self.angle_columns()]

    def angle_columns(self) -> list[int]:
        """The fingertips' object longitude and contact-angle columns of the state."""
        return [t.eta_cols.start + j for t in self.first.fingertips for j in (3, 4)]

    # -- a plan on these charts ---------------------------------------------------------
    def interpolant(self, t_nodes: FloatArray, X: FloatArray, U0: FloatArray, Um: FloatArray,
                    U1: FloatArray) -> HermiteInterpolant:
        """The plan's polynomials (:meth:`GraspModel.interpolant` on each chart): the
        switch interval ends at the switch node's state read on the first chart (its
        input ``U1`` is the first chart's already: :meth:`first_chart_inputs`)."""
        if not self.switched:
            return self.first.interpolant(t_nodes, X, U0, Um, U1, self.prms[0])
        n = len(U0)
        kc = self.interval_charts(np.arange(n))
        X1 = np.array(X[1:], dtype=float)
        ks = self.node
        assert ks is not None
        X1[ks - 1] = self.to_first(X[ks])[0]
        F0 = self.evaluate("dynamics", kc, X[:-1].T, U0.T)[0].T
        F1 = self.evaluate("dynamics", kc, X1.T, U1.T)[0].T
        return HermiteInterpolant(np.asarray(t_nodes, dtype=float), X, F0, F1, U0, Um, U1,
                                  X1)

    def first_chart_inputs(self, X: FloatArray, U1: FloatArray) -> FloatArray:
        """Each interval's end input on its own chart: the switch interval's (the switch
        node's input, on the second chart in the NLP) restated on the first."""
        if not self.switched:
            return U1
        ks = self.node
        assert ks is not None
        out = np.array(U1, dtype=float)
        out[ks - 1] = self.to_first(X[ks], U1[ks - 1])[1]
        return out

    def reintegrate(self, x0: FloatArray, t_nodes: FloatArray, U0: FloatArray,
                    Um: FloatArray, U1: FloatArray, X: FloatArray, n_sub: int = 2
                    ) -> tuple[FloatArray, FloatArray]:
        """:func:`~ocp.transcription.collocation.reintegrate` over the whole horizon, never
        reset: on a switched plan up to the switch node on the first chart, the state
        reached there restated on the second (its angles continued from the plan's own
        ``X`` there), and on from it. (node states, samples preceded by x0)."""
        if not self.switched:
            m = self.first
            Xr, sx, _ = reintegrate(m.reintegrator(n_sub), x0, t_nodes, U0, Um, U1,
                                    self.prms[0], n_sub)
            return Xr, sx
        ks = self.node
        assert ks is not None
        a, b = self.models
        Xa, sa, _ = reintegrate(a.reintegrator(n_sub), x0, t_nodes[:ks + 1], U0[:ks],
                                Um[:ks], U1[:ks], self.prms[0], n_sub)
        xk = self.to_second(Xa[-1], None, self.refs_of(X[ks]))[0]
        Xb, sb, _ = reintegrate(b.reintegrator(n_sub), xk, t_nodes[ks:], U0[ks:], Um[ks:],
                                U1[ks:], self.prms[1], n_sub)
        return np.vstack([Xa[:-1], Xb]), np.vstack([sa, sb[1:]])
