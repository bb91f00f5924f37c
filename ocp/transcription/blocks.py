"""The blocks of a grasp's NLP in one contact phase: per-point and per-interval CasADi
functions built from what each active contact contributes.

A block kind is one SX function of its own variables ``z`` (and parameters), with its
Jacobian and the Hessian of its Lagrangian differentiated once at the block's own size
(:mod:`ocp.transcription.nlp_blocks` says why, and maps each kind over its instances):

* :func:`point_block`: the rows at one collocation point: force closure (the phase's
  :func:`~ocp.transcription.grasp_conditions.grasp_condition`), the planned loads
  (:mod:`ocp.transcription.loads`), tracking; the point's objective terms;
* :func:`interval_block`: the Hermite-Simpson defects of one interval (the states with
  dynamics in the phase), its effort, ramp and grasp-angle terms;
* :func:`rate_block`: each touching fingertip's closure at the velocity level;
* :func:`accel_block`: the joints' accelerations (smooth timing);
* :func:`touchdown_block`: the closure of fingertips that land at a node (the velocity
  rows keep it from there on).

The variables of a point are laid out alike in every phase (:class:`PointLayout`): the
grasp's state, the epigraph, three internal-force components per point contact and the
load variables per point contact; a block uses the slots of its phase's active contacts
(``z_map``), the others are parked by the transcription.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np
from numpy.typing import NDArray

from ocp.transcription.collocation import hermite_simpson_defects
from ocp.transcription.grasp_conditions import grasp_condition
from ocp.transcription.loads import LOAD_PARAMS, LOAD_VARS, load_cost, load_rows
from ocp.transcription.velocity_closure import fingertip_twist_rows

__all__ = ["Block", "PointLayout", "accel_block", "interval_block", "point_block",
           "ramp_penalty", "rate_block", "touchdown_block"]

IntArray = NDArray[np.int64]


def _nz(M: Any) -> Any:
    """The nonzeros of a sparse SX matrix as a column (its sparsity's order)."""
    return ca.vertcat(*M.nonzeros()) if M.nnz() else ca.SX(0, 1)


def ramp_penalty(u0: Any, um: Any, u1: Any, hn: Any) -> Any:
    """The integral of |du/ds|^2 over one interval of normalised time s = t / T (length
    ``hn``) of the quadratic input through (u0, um, u1): its derivative is linear, from
    a0 = (-3 u0 + 4 um - u1) / hn to a1 = (u0 - 4 um + 3 u1) / hn, so the integral is
    hn (a0^2 + a0 a1 + a1^2) / 3."""
    a0 = (-3 * u0 + 4 * um - u1) / hn
    a1 = (u0 - 4 * um + 3 * u1) / hn
    return hn * (ca.sumsqr(a0) + ca.dot(a0, a1) + ca.sumsqr(a1)) / 3


@dataclass
class Block:
    """One block kind: ``fn(z, *inputs) -> rows``, ``jac -> (rows, nonzeros of d rows /
    dz)``, ``hess(z, *inputs, lam[, sigma]) -> nonzeros of the upper triangle of the
    Hessian of (sigma cost +) lam' rows``, the sparsity patterns ``J`` and ``H`` of those
    nonzeros, the objective ``cost`` (None: none), the rows' bounds, and for a point
    block the positions of its variables in the point's layout (``z_map``) and the rows it
    has at the grid's first node (``keep0``: not the tracking bounds)."""

    fn: ca.Function
    jac: ca.Function
    hess: ca.Function | None
    J: Any
    H: Any
    cost: ca.Function | None
    lo: list[float]
    hi: list[float]
    z_map: IntArray | None = None
    keep0: list[int] | None = None

    @property
    def n_rows(self) -> int:
        return len(self.lo)


def _block(name: str, z: Any, inputs: list[Any], rows: Any, cost: Any, lam: Any,
           sigma: Any, lo: list[float], hi: list[float], cse: bool = True) -> Block:
    """A block kind from its symbols: its functions, derivatives and bounds."""
    J = ca.jacobian(rows, z)
    lag = ca.dot(lam, rows) if cost is None else sigma * cost + ca.dot(lam, rows)
    H = ca.triu(ca.hessian(lag, z)[0])
    fin = [z, *inputs]
    wrap = ca.cse if cse else (lambda e: e)
    hin = [*fin, lam] if cost is None else [*fin, lam, sigma]
    return Block(ca.Function(name, fin, [rows]),
                 ca.Function(f"{name}_jac", fin, wrap([rows, _nz(J)])),
                 ca.Function(f"{name}_hess", hin, [wrap(_nz(H))]), J, H,
                 None if cost is None else ca.Function(f"{name}_cost", fin, [cost]), lo, hi)


@dataclass(frozen=True)
class PointLayout:
    """The variables at one collocation point, the same in every phase: the grasp's
    ``nx`` states, ``n_s`` epigraph variables, three internal-force components per point
    contact when some phase needs them (``n_force`` contacts), :data:`LOAD_VARS` load
    variables per point contact with planned forces (``n_load`` contacts)."""

    nx: int
    n_s: int
    n_force: int
    n_load: int

    @property
    def size(self) -> int:
        return self.nx + self.n_s + 3 * self.n_force + LOAD_VARS * self.n_load

    def positions(self, n_s: int, slots: tuple[int, ...], internal: bool,
                  loads: bool) -> IntArray:
        """Where a block's (x, s, internal forces, loads) of the contacts in ``slots`` sit
        in the point's variables."""
        f0 = self.nx + self.n_s
        l0 = f0 + 3 * self.n_force
        parts = [np.arange(self.nx), self.nx + np.arange(n_s)]
        if internal:
            parts += [f0 + 3 * k + np.arange(3) for k in slots]
        if loads:
            parts += [l0 + LOAD_VARS * k + np.arange(LOAD_VARS) for k in slots]
        return np.concatenate(parts).astype(np.int64)


def point_params(m: Any) -> tuple[Any, Any, Any, Any, Any, Any]:
    """The point blocks' parameter symbols: (q, shape, charts, ccone, tol, tracking
    weights, loads) with ``q`` their concatenation (the transcription's ``qv``)."""
    shape_q = ca.SX.sym("shape", m.surface.n_params)
    charts_q = ca.SX.sym("charts", 9 * m.n_contacts)
    ccone_q, tol_q = ca.SX.sym("ccone"), ca.SX.sym("tol", 2)
    wtr_q = ca.SX.sym("wtr", 2)  # tracking weights (position, rotation)
    load_q = ca.SX.sym("load", LOAD_PARAMS)
    return ca.vertcat(shape_q, charts_q, ccone_q, tol_q, wtr_q, load_q), shape_q, charts_q, \
        ccone_q, tol_q, (wtr_q, load_q)


def point_block(pm: Any, layout: PointLayout, tracking: bool, forces: bool,
                force_regularisation: float, npts: int, reference: bool = False) -> Block:
    """The rows at one point of phase ``pm``
    (:class:`~ocp.transcription.grasp_model.PhaseModel`): z = (x~, s, f, fl) of its active
    contacts (``z_map``). Force closure by the phase's condition, the loads of the active
    contacts, the tracking bounds (not at the grid's first node); the objective's tracking
    error, the internal forces' and the loads' size; with a ``reference``
    (:class:`~ocp.spec.reference.Reference`) the scaled states' squared distance from the
    point's reference state ``xr``, each state weighted by ``qx``, times the point's weight
    ``wr``."""
    m = pm.grasp
    q, shape_q, charts_q, ccone_q, tol_q, (wtr_q, load_q) = point_params(m)
    L = m.surface.length_scale(shape_q)
    prm = ca.vertcat(shape_q, charts_q)
    x_scale = ca.vertcat(*m.x_scale(L))
    nc = pm.n_contacts
    cond = grasp_condition(nc)
    n_force = nc if cond.internal_forces else 0
    n_load = nc if forces else 0
    xs = ca.SX.sym("xs", m.nx)
    s = ca.SX.sym("s", cond.n_epigraph)
    fcol = ca.SX.sym("f", 3 * n_force)
    fl = ca.SX.sym("fl", LOAD_VARS * n_load)
    zp = ca.vertcat(xs, s, fcol, fl)
    pd = ca.SX.sym("pd", 3 if tracking else 0)
    rd = ca.SX.sym("rd", 9 if tracking else 0)
    swp = ca.SX.sym("sw")  # the point's Simpson weight (normalised time)
    xr = ca.SX.sym("xr", m.nx if reference else 0)  # the reference state (scaled)
    wr = ca.SX.sym("wr", 1 if reference else 0)  # its weight at this point
    qx = ca.SX.sym("qx", m.nx if reference else 0)  # each state's own weight
    rows: list[Any] = []
    lo: list[float] = []
    hi: list[float] = []
    not_at_node0: list[int] = []  # rows the fixed initial grasp does not get

    def add(expr: Any, a: float, b: float, at_node0: bool = True) -> None:
        start = len(lo)
        rows.append(expr)
        lo.extend([a] * int(expr.numel()))
        hi.extend([b] * int(expr.numel()))
        if not at_node0:
            not_at_node0.extend(range(start, len(lo)))

    # (each fingertip where its kinematics put it, eq. 6: the rate rows)
    _, P, N, R_po, p_po = pm.path(x_scale * xs, prm)
    cond.rows(add, P, N, s, fcol, ccone_q, L, nc)
    clear = pm.clearance(x_scale * xs, prm)  # the lifted fingertips kept off the object
    if clear.numel():
        add(clear, 0.0, math.inf)
    for c in m.fingertips:  # each finger's joint couplings (ocp.robots.couplings), in rad
        q_c = (x_scale * xs)[c.q_cols]
        for cp in getattr(c.finger, "couplings", ()):
            a = cp.row(c.finger.joint_names)
            scale = float(np.linalg.norm(a))
            lo_c, hi_c = cp.backed_off()
            add(ca.dot(ca.DM(a / scale), q_c), lo_c / scale, hi_c / scale, at_node0=False)
    if n_load:
        load_rows_, fn = load_rows(P, N, R_po, fl, load_q, L)
        for expr, a, b in load_rows_:
            add(expr, a, b)
    cost_p: Any = ca.SX(0)
    if tracking:
        ep = (p_po - pd) / L
        er = (3 - ca.trace(ca.reshape(rd, 3, 3).T @ R_po)) / 2
        add(ca.vertcat(tol_q[0] - ca.sumsqr(ep), tol_q[1] - er), 0.0, math.inf,
            at_node0=False)
        cost_p = swp * (wtr_q[0] * ca.sumsqr(ep) + wtr_q[1] * er)
    if n_force:
        # The internal forces that certify a grasp form a cone of dimension 3n - 6 - 1; a
        # small penalty on their size picks one, so that IPOPT does not wander along flat
        # directions (the grasp term only sees the worst force angle).
        cost_p = cost_p + force_regularisation * ca.sumsqr(fcol) / (npts * n_force)
    if n_load:
        cost_p = cost_p + load_cost(fl, fn) / (npts * n_load)
    if reference:
        cost_p = cost_p + wr * ca.dot(qx, (xs - xr) ** 2) / m.nx
    Gp = ca.vertcat(*rows)
    dropped = set(not_at_node0)
    block = _block("point", zp, [pd, rd, swp, xr, wr, qx, q], Gp, cost_p,
                   ca.SX.sym("lam", len(lo)), ca.SX.sym("sigma"), lo, hi)
    block.z_map = layout.positions(cond.n_epigraph, pm.slots, bool(n_force), bool(n_load))
    block.keep0 = [r for r in range(len(lo)) if r not in dropped]
    return block


def interval_block(pm: Any, n_s: int, smooth: bool, reference: bool = False,
                   switch_map: ca.Function | None = None) -> Block:
    """One interval of phase ``pm``: z = (x_k, x_m, x_k+1, u_0, u_m, u_1, s_k, s_m,
    s_k+1); rows: the Hermite-Simpson defects of the states with dynamics in the phase
    (its ``dyn_cols``: a lifted fingertip's contact coordinates have none); cost: the
    grasp-angle epigraph and each effort group's inputs (Simpson's rule), with the smooth
    timing their ramps (:func:`ramp_penalty`); with a ``reference`` the scaled inputs'
    squared distance from the reference's ``ur`` (u_0, u_m, u_1) by Simpson's rule, times
    the weight ``wu``. With ``switch_map`` (:func:`~ocp.transcription.chart_switch.chart_map`
    from the next chart to this phase's) the interval ends at a chart switch: its end
    (x_k+1, u_1) is in the next chart, read in this one through the map (the next
    chart's patches ``charts_b`` and the map's ``refs``, two more inputs); the block is
    named ``switch``."""
    m = pm.grasp
    nx, nu = m.nx, m.nu
    shape_q = ca.SX.sym("shape", m.surface.n_params)
    charts_q = ca.SX.sym("charts", 9 * m.n_contacts)
    L = m.surface.length_scale(shape_q)
    prm = ca.vertcat(shape_q, charts_q)
    x_scale = ca.vertcat(*m.x_scale(L))
    xk, xm, xk1 = (ca.SX.sym(name, nx) for name in ("xk", "xm", "xk1"))
    u0, um, u1 = (ca.SX.sym(name, nu) for name in ("u0", "um", "u1"))
    sk, sm, sk1 = ca.SX.sym("sk", n_s), ca.SX.sym("sm", n_s), ca.SX.sym("sk1", n_s)
    zi = ca.vertcat(xk, xm, xk1, u0, um, u1, sk, sm, sk1)
    hq = ca.SX.sym("h")  # the interval's length [s]
    Tq = ca.SX.sym("T")
    wq = ca.SX.sym("w", 4)  # effort weights (object, contacts, joints) and grasp weight
    ramp_q = ca.SX.sym("ramp")  # the ramps' time constant over the duration (smooth)
    u_scale = ca.vertcat(*m.u_scale(L, Tq))

    def fdyn(x_: Any, u_: Any) -> Any:
        return pm.dynamics(x_scale * x_, u_scale * u_, prm) / x_scale

    extra: list[Any] = []
    if switch_map is not None:  # the end in the next chart, read in this one
        charts_b, refs = ca.SX.sym("charts_b", 9 * m.n_contacts), \
            ca.SX.sym("refs", switch_map.size1_in(5))
        x_a, u_a = switch_map(x_scale * xk1, u_scale * u1, shape_q, charts_b, charts_q, refs)
        xk1, u1 = x_a / x_scale, u_a / u_scale
        extra = [charts_b, refs]
    D = hermite_simpson_defects(xk, xm, xk1, fdyn(xk, u0), fdyn(xm, um), fdyn(xk1, u1), hq)
    if len(pm.dyn_cols) < nx:  # only the states with dynamics in this phase
        keep = list(pm.dyn_cols) + [nx + j for j in pm.dyn_cols]
        D = D[keep]
    hn = hq / Tq
    cost_i: Any = wq[3] * hn / 6 * (sk + 4 * sm + sk1) if n_s else ca.SX(0)
    for i, idx in enumerate(m.effort_groups()):
        if idx:
            cost_i += wq[i] * hn / 6 * (ca.sumsqr(u0[idx]) + 4 * ca.sumsqr(um[idx])
                                        + ca.sumsqr(u1[idx]))
            if smooth:
                cost_i += wq[i] * ramp_q ** 2 * ramp_penalty(u0[idx], um[idx], u1[idx], hn)
    ur = ca.SX.sym("ur", 3 * nu if reference else 0)  # the reference inputs (scaled)
    wu = ca.SX.sym("wu", 1 if reference else 0)
    if reference:
        cost_i += wu * hn / 6 * (ca.sumsqr(u0 - ur[:nu]) + 4 * ca.sumsqr(um - ur[nu:2 * nu])
                                 + ca.sumsqr(u1 - ur[2 * nu:])) / nu
    n_d = int(D.numel())
    return _block("interval" if switch_map is None else "switch", zi,
                  [hq, Tq, wq, shape_q, charts_q, ramp_q, ur, wu, *extra], D, cost_i,
                  ca.SX.sym("lam", n_d), ca.SX.sym("sigma"), [0.0] * n_d, [0.0] * n_d)


def rate_block(pm: Any) -> Block:
    """The closure (eq. 6) at the velocity level of phase ``pm``'s touching fingertips at
    one collocation point and one of its inputs: z = (x, u), six rows per fingertip
    (:mod:`ocp.transcription.velocity_closure`; the transcription says why at the velocity
    level)."""
    m = pm.grasp
    nx, nu = m.nx, m.nu
    shape_q = ca.SX.sym("shape", m.surface.n_params)
    charts_q = ca.SX.sym("charts", 9 * m.n_contacts)
    Tq = ca.SX.sym("T")
    L = m.surface.length_scale(shape_q)
    prm = ca.vertcat(shape_q, charts_q)
    x_scale = ca.vertcat(*m.x_scale(L))
    u_scale = ca.vertcat(*m.u_scale(L, Tq))
    xr, ur = ca.SX.sym("xr", nx), ca.SX.sym("ur", nu)
    zr = ca.vertcat(xr, ur)
    nf = len(pm.fingertips)
    if nf:
        closure_scale = ca.vertcat(*([1 / L] * 3 + [1.0] * 3) * nf)
        Gr = Tq * closure_scale * fingertip_twist_rows(pm, x_scale * xr, u_scale * ur, prm)
    else:
        Gr = ca.SX(0, 1)
    n_r = int(Gr.numel())
    return _block("rates", zr, [Tq, shape_q, charts_q], Gr, None, ca.SX.sym("lam", n_r),
                  None, [0.0] * n_r, [0.0] * n_r)


def accel_block(m: Any, smooth: bool) -> Block:
    """The joints' accelerations on one interval (smooth timing): z = (u_0, u_m, u_1). The
    input is the quadratic through them, its derivative linear: (-3 u_0 + 4 u_m - u_1) / h
    at the start, (u_0 - 4 u_m + 3 u_1) / h at the end bound it everywhere. Rows: every
    joint rate's over the limit, in [-1, 1]; linear (no Hessian)."""
    nu = m.nu
    jcols = list(m.effort_groups()[2]) if smooth else []
    ua0, uam, ua1 = (ca.SX.sym(name, nu) for name in ("ua0", "uam", "ua1"))
    za = ca.vertcat(ua0, uam, ua1)
    shape_q = ca.SX.sym("shape", m.surface.n_params)
    hq, Tq, amax_q = ca.SX.sym("h"), ca.SX.sym("T"), ca.SX.sym("amax")
    L = m.surface.length_scale(shape_q)
    u_scale = ca.vertcat(*m.u_scale(L, Tq))
    if jcols:
        sj = u_scale[jcols] / (hq * amax_q)
        Ga = ca.vertcat(sj * (-3 * ua0[jcols] + 4 * uam[jcols] - ua1[jcols]),
                        sj * (ua0[jcols] - 4 * uam[jcols] + 3 * ua1[jcols]))
    else:
        Ga = ca.SX(0, 1)
    Ja = ca.jacobian(Ga, za)
    ain = [za, hq, Tq, shape_q, amax_q]
    n_a = int(Ga.numel())
    return Block(ca.Function("accel", ain, [Ga]), ca.Function("accel_jac", ain, [Ga, _nz(Ja)]),
                 None, Ja, ca.SX(3 * nu, 3 * nu), None, [-1.0] * n_a, [1.0] * n_a)


def touchdown_block(pm: Any, landing: tuple[int, ...]) -> Block:
    """The closure (eq. 6) of the fingertips ``landing`` (indices among the grasp's) at
    the node where they touch the object: z = x~ there; six rows each (position / L,
    orientation), zero. From that node on the phase's velocity rows keep it."""
    m = pm.grasp
    shape_q = ca.SX.sym("shape", m.surface.n_params)
    charts_q = ca.SX.sym("charts", 9 * m.n_contacts)
    L = m.surface.length_scale(shape_q)
    prm = ca.vertcat(shape_q, charts_q)
    x_scale = ca.vertcat(*m.x_scale(L))
    xs = ca.SX.sym("xt", m.nx)
    each = pm.closure_of(x_scale * xs, prm)
    each = each if isinstance(each, (list, tuple)) else [each]
    rows = ca.vertcat(*[ca.vertcat(each[i][0:3] / L, each[i][3:6]) for i in landing])
    n_t = int(rows.numel())
    return _block("touchdown", xs, [shape_q, charts_q], rows, None, ca.SX.sym("lam", n_t),
                  None, [0.0] * n_t, [0.0] * n_t)
