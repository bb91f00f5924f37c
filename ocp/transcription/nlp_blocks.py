"""The manipulation NLP from small blocks: per-point and per-interval CasADi functions.

A grasp's direct-collocation NLP (:mod:`ocp.solve.planner`) has the same few functions at
every collocation point (force closure, tracking: the finger's forward kinematics and the
contact geometry; the fingertips' closure at the velocity level) and in every interval
(the Hermite-Simpson defects of the rolling equations, the effort and grasp terms of the
objective). Written out in SX at every point,
the NLP of the paper's experiment 1 (palm + one 6-joint finger, N = 60) took 2.7 s to
build, held ~220 MB, and its generated C (72 MB) was beyond gcc. Here each block is one SX
function of its own variables; its Jacobian and the Hessian of its Lagrangian are
differentiated once, at the block's own dimension, and applied to every point or interval
with ``Function.map``; the NLP's constraint Jacobian and Lagrangian Hessian are assembled
from the blocks' nonzeros by a constant sparse matrix (:class:`BlockAssembler`) and given to
IPOPT as ``jac_g`` and ``hess_lag``. Same NLP (same variables, constraints, order, bounds;
the same plan to round-off), built in a fraction of a second, ~20 MB, and small enough to
compile (``compile_dir``: a few MB of C, seconds of gcc).

Why not let CasADi differentiate an MX NLP of mapped functions: its coloring over the whole
NLP calls every block's derivatives in as many directions as the widest block couples
(16 for the Jacobian, 12 for the Hessian of experiment 1), mostly zeros for any one block:
IPOPT took 3.2x longer. ``expand=True`` turns it back into the SX NLP.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np
from numpy.typing import NDArray

from ocp.geometry.grasp import grasp_cosines
from ocp.spec.problem import PERIODIC
from ocp.transcription.collocation import HermiteSimpson, hermite_simpson_defects, target_residuals
from ocp.transcription.parameters import Parameters
from ocp.transcription.velocity_closure import fingertip_twist_rows

__all__ = ["BlockAssembler", "BlockNLP", "build_manipulation_nlp"]


def _node_input_pairs(hs: HermiteSimpson) -> list[tuple[int, int]]:
    """(node, input column) of every input at a node that is not fixed: each interval's
    start, and each segment's end (with the paper's timing a via-point node has the input
    arriving and the one leaving). With the smooth timing (continuous inputs) each node
    has one input, and the first and last are fixed at rest (zero: rows in them would be
    identically zero)."""
    lc, rc = hs.left_cols, hs.right_cols
    ends = [int(k) for k in np.cumsum(hs.segments)]
    pairs = [(k, lc[k]) for k in range(hs.n_intervals)] + [(k, rc[k - 1]) for k in ends]
    if hs.continuous:
        pairs = [pc for pc in dict.fromkeys(pairs)
                 if pc not in ((0, lc[0]), (hs.n_intervals, rc[-1]))]
    return pairs

FloatArray = NDArray[np.float64]


@dataclass
class BlockNLP:
    """One grasp structure's NLP as functions: its variables' layout, parameters,
    constraint bounds, and the problem with its block-assembled derivatives (the solver is
    made from them by :func:`ocp.solve.ipopt.ipopt_solver`)."""

    hs: HermiteSimpson  # SX symbols of the grid: columns, pack/unpack of the states/inputs
    unpack: ca.Function
    pack: ca.Function
    #: the parameter vector's declaration, by name
    #: (:class:`~ocp.transcription.parameters.Parameters`)
    params: Parameters
    lbg: FloatArray
    ubg: FloatArray
    build_time: float
    n_force: int  # contacts with internal-force variables (0 for two contacts)
    n_epigraph: int  # grasp-angle epigraph variables per point (0 for one contact)
    #: the problem as a function (w, p) -> (f, g), its constraints' Jacobian and the
    #: Hessian of its Lagrangian (upper triangle), assembled from the blocks
    oracle: ca.Function
    jac_g: ca.Function
    hess_lag: ca.Function
    #: contacts with planned load forces (:data:`LOAD_VARS` variables each at every
    #: point, after the internal forces in ``F``; 0 without ``forces``)
    n_load: int = 0


#: Variables of one contact's planned force at a point: the force in the object frame,
#: divided by the force scale, and the torsion's fraction of its limit (soft fingers).
LOAD_VARS = 4
#: The torsion stays within this fraction of its limit |tau| <= torsional_friction f_n.
TORSION_SHARE = 0.95
#: Load parameters: the weight m g in the palm frame [N], the minimum normal force [N],
#: the torsional friction [m], the force scale [N], tan(atan(mu) - margin), the cone's
#: smoothing (scaled force).
LOAD_PARAMS = 8
#: Weight of the planned forces' size (scaled) in the objective: it picks the smallest
#: forces that hold the object, and is small enough not to move the plan (the forces'
#: size depends on the grasp's geometry).
LOAD_REGULARISATION = 1e-4
#: Weight of the scaled normal forces' sum in the objective: a gradient that does not
#: vanish as the grip shrinks, so that IPOPT brings the squeeze to the minimum normal force
#: (without it, 1.2-1.8 N for a 1 N minimum; with it, within 0.5 %: docs/forces.md).
LOAD_PUSH_WEIGHT = 1e-2


def load_rows(P: Any, N: Any, R_po: Any, fl: Any, load_q: Any, L: Any
              ) -> tuple[list[tuple[Any, float, float]], Any]:
    """The planned forces' rows at one point: (rows as (expression, lower, upper), the
    scaled normal forces). ``P``, ``N``: the contact points and outward normals in the
    object frame (3 x nc), ``R_po`` the object's rotation, ``fl`` the point's load
    variables (:data:`LOAD_VARS` per contact), ``load_q`` the load parameters
    (:data:`LOAD_PARAMS`), ``L`` the object's size.

    Quasi-static equilibrium of the object (docs/forces.md: the inertial wrench of the
    paper's slow motions is below 1e-3 of the weight), in the object frame: the contact
    forces f_i = F0 fl_i[:3] at the points P_i, the torsion about each outward normal N_i,
    the weight at the centre (the object frame's origin); every normal force at least the
    minimum; every force inside its (smooth, narrowed) friction cone."""
    nc = int(P.shape[1])
    weight, f_min, mu_t, F0, mu_m, eps = (load_q[0:3], load_q[3], load_q[4], load_q[5],
                                          load_q[6], load_q[7])
    Fl = ca.reshape(fl, LOAD_VARS, nc)
    fs = Fl[0:3, :]  # scaled forces, object frame
    fn = -ca.sum1(N * fs)  # scaled normal forces (the push along -N)
    tors = mu_t / L * fn * Fl[3, :]  # scaled torsion moments (/ F0 L)
    w_obj = R_po.T @ weight / F0
    tang2 = ca.sum1(fs * fs) - fn * fn  # |f_t|^2 (scaled)
    # the cone, smooth: mu_m f_n >= sqrt(|f_t|^2 + eps^2), inside the cone of
    # tan(atan(mu) - margin) (never looser); eps a quarter of the smallest normal force's
    # cone radius, so the row's curvature at f_t = 0 stays moderate
    return [(ca.sum2(fs) + w_obj, 0.0, 0.0),
            (ca.sum2(ca.cross(P, fs) / L + N * ca.repmat(tors, 3, 1)), 0.0, 0.0),
            (ca.transpose(fn) - f_min / F0, 0.0, math.inf),
            (ca.transpose(mu_m * fn - ca.sqrt(tang2 + eps * eps)), 0.0, math.inf)], fn


def load_cost(fl: Any, fn: Any) -> Any:
    """One point's forces' objective (before the average over points and contacts): small
    forces that hold the object, the grip at its floor on the normals."""
    return LOAD_REGULARISATION * ca.sumsqr(fl) + LOAD_PUSH_WEIGHT * ca.sum2(fn)


def _nz(M: Any) -> Any:
    """The nonzeros of a sparse SX matrix as a column (its sparsity's order)."""
    return ca.vertcat(*M.nonzeros()) if M.nnz() else ca.SX(0, 1)


class BlockAssembler:
    """A global sparse matrix from the concatenated nonzeros of many blocks.

    ``rows``/``cols``: the global position of every block nonzero, in the order the blocks'
    nonzero vectors are concatenated; entries at the same position are summed, entries with
    a negative row dropped; ``symmetric`` maps each entry to the upper triangle. Calling it
    on the nonzeros (an MX column) gives the MX matrix (one constant sparse product)."""

    def __init__(self, shape: tuple[int, int], rows: NDArray[np.int64],
                 cols: NDArray[np.int64], symmetric: bool = False) -> None:
        keep = rows >= 0
        r, c = rows, cols
        if symmetric:
            r, c = np.minimum(rows, cols), np.maximum(rows, cols)
        lin = c[keep].astype(np.int64) * shape[0] + r[keep]
        uniq, inv = np.unique(lin, return_inverse=True)  # column-major = CCS order
        self.sparsity = ca.Sparsity.triplet(shape[0], shape[1], (uniq % shape[0]).tolist(),
                                            (uniq // shape[0]).tolist())
        src = np.flatnonzero(keep)
        self.matrix = ca.DM(ca.Sparsity.triplet(len(uniq), len(rows), inv.tolist(),
                                                src.tolist()), 1.0)

    def __call__(self, nz: Any) -> Any:
        return ca.MX(self.sparsity, ca.mtimes(self.matrix, nz))


def _declaration(m: Any, nseg: int, nv: int, npts: int, tracking: bool) -> Parameters:
    """The NLP's parameters, by name (every structure's, whatever it uses)."""
    n_track = npts if tracking else 0
    return Parameters.of(shape=(m.surface.n_params, 1), seg_T=(nseg, 1), goal=(5, 1),
                         vias=(5, nv), charts=(9 * m.n_contacts, 1), weights=(6, 1),
                         ccone=(1, 1), tol=(2, 1), Pd=(3, n_track), Rd=(9, n_track),
                         load=(LOAD_PARAMS, 1), accel=(2, 1))


def ramp_penalty(u0: Any, um: Any, u1: Any, hn: Any) -> Any:
    """The integral of |du/ds|^2 over one interval of normalised time s = t / T (length
    ``hn``) of the quadratic input through (u0, um, u1): its derivative is linear, from
    a0 = (-3 u0 + 4 um - u1) / hn to a1 = (u0 - 4 um + 3 u1) / hn, so the integral is
    hn (a0^2 + a0 a1 + a1^2) / 3."""
    a0 = (-3 * u0 + 4 * um - u1) / hn
    a1 = (u0 - 4 * um + 3 * u1) / hn
    return hn * (ca.sumsqr(a0) + ca.dot(a0, a1) + ca.sumsqr(a1)) / 3


def _small_grasp_nlp(m: Any, segments: tuple[int, ...], goal_mask: tuple[bool, ...],
                     via_masks: tuple[tuple[bool, ...], ...], t0: float,
                     smooth: bool) -> BlockNLP:
    """The same NLP for a grasp without path rows (one contact, no tracking: the object
    on the palm alone), written out in SX: at this size one SX graph is cheaper to call
    than mapped blocks, and the rolling equations at a node shared by two intervals are
    evaluated once. Same variables, constraints, order and objective as the blocks'."""
    hs = HermiteSimpson(m.nx, m.nu, segments, smooth)
    n, nseg = hs.n_intervals, len(segments)
    decl = _declaration(m, nseg, len(via_masks), 2 * n + 1, False)
    p = ca.SX.sym("p", decl.size)
    prm = decl.unpack(p)
    shape_p, seg_T, goal, vias = prm["shape"], prm["seg_T"], prm["goal"], prm["vias"]
    L, T = ca.mmax(shape_p), ca.sum1(prm["seg_T"])
    x_scale = ca.vertcat(*m.x_scale(L))
    u_scale = ca.vertcat(*m.u_scale(L, T))
    params = ca.vertcat(shape_p, prm["charts"])
    g = [hs.defects(m.dynamics, params, x_scale, u_scale, seg_T)]
    ends = hs.segment_end_nodes
    for j, vmask in enumerate(via_masks):
        g += target_residuals(hs.X[:, ends[j]], vias[:, j], vmask, x_scale, PERIODIC)
    g += target_residuals(hs.X[:, ends[-1]], goal, goal_mask, x_scale, PERIODIC)
    g_all = ca.vertcat(*g)
    xs, us, wq = ca.SX.sym("xs", m.nx), ca.SX.sym("us", m.nu), ca.SX.sym("wq", 3)
    effort: Any = ca.SX(0)
    for k, idx in enumerate(m.effort_groups()):
        if idx:
            effort += wq[k] * ca.sumsqr(us[idx])
    effort_fn = ca.Function("effort", [xs, us, wq], [effort])
    weights = prm["weights"][0:3]
    f = hs.simpson(lambda x, u: effort_fn(x, u, weights), seg_T / T)
    if smooth:  # the ramps' term (see build_manipulation_nlp)
        ramp = prm["accel"][1]
        hns = hs.steps(seg_T / T)
        for k in range(n):
            for j, idx in enumerate(m.effort_groups()):
                if idx:
                    f += weights[j] * ramp ** 2 * ramp_penalty(
                        hs.U[idx, hs.left_cols[k]], hs.Um[idx, k], hs.U[idx, hs.right_cols[k]],
                        hns[k])
    w = hs.w
    empty = [ca.SX(0, n + 1), ca.SX(0, n), ca.SX(0, 2 * n + 1)]
    unpack = ca.Function("unpack", [w], [hs.X, hs.Xm, hs.U, hs.Um, *empty])
    pack = ca.Function("pack", [hs.X, hs.Xm, hs.U, hs.Um, *empty], [w])
    lam_f, lam_g = ca.SX.sym("lam_f"), ca.SX.sym("lam_g", g_all.numel())
    oracle = ca.Function("manipulation_nlp", [w, p], [f, g_all], ["x", "p"], ["f", "g"])
    jac_g = ca.Function("nlp_jac_g", [w, p], [g_all, ca.jacobian(g_all, w)], ["x", "p"],
                        ["g", "jac_g_x"])
    hess = ca.triu(ca.hessian(lam_f * f + ca.dot(lam_g, g_all), w)[0])
    hess_lag = ca.Function("nlp_hess_l", [w, p, lam_f, lam_g], [hess],
                           ["x", "p", "lam_f", "lam_g"], ["triu_hess_gamma_x_x"])
    zeros = np.zeros(g_all.numel())
    return BlockNLP(hs, unpack, pack, decl, zeros, zeros.copy(), time.perf_counter() - t0,
                    0, 0, oracle, jac_g, hess_lag, 0)


def _triplets(sp: ca.Sparsity) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    r, c = sp.get_triplet()
    return np.asarray(r, dtype=np.int64), np.asarray(c, dtype=np.int64)


def build_manipulation_nlp(m: Any, segments: tuple[int, ...], goal_mask: tuple[bool, ...],
                           via_masks: tuple[tuple[bool, ...], ...], tracking: bool,
                           force_regularisation: float, small: bool | None = None,
                           forces: bool = False, smooth: bool = False) -> BlockNLP:
    """The NLP of one grasp structure (``m``: its
    :class:`~ocp.transcription.grasp_model.GraspModel`):
    variables ``w = (X, Xm, U, Um, S, Sm, F)`` (scaled states and inputs at
    nodes and midpoints, grasp epigraph at every point, internal forces of 3+ contacts),
    parameters ``p = (shape, seg_T, goal, vias, charts, weights, cone cosine, tracking
    tolerances, desired positions, desired rotations)``; constraints: the defects of every
    interval, every point's path constraints (node 0, the given initial grasp, without its
    tracking bounds), the goal and via-point targets, then the fingertips' closure at the
    velocity level at every node (with each of its inputs) and midpoint. ``small`` (default: for
    one contact without tracking) writes the same NLP out in SX instead of from blocks.
    ``forces``: every contact's force at every point too (docs/forces.md): variables
    ``F``'s last ``LOAD_VARS * n_contacts`` rows, the object's quasi-static equilibrium
    with its weight, the friction cones with a margin, the minimum normal force, the
    soft-finger torsion within its limit; the load parameters ``load``.
    ``smooth`` (the smooth timing, docs/timing.md): one input per node, also at via-points
    (every velocity continuous), the first and last fixed at rest by their bounds
    (:func:`~ocp.transcription.values.bounds`), every joint's acceleration within the
    parameter ``accel[0]`` [rad/s^2] at both ends of every interval (the input is quadratic
    on an interval, its derivative linear: the ends bound it), the last rows; and each
    effort term has a ramp term, its weight times ``accel[1]^2`` times the integral of the
    squared rate of change of its inputs (``accel[1]``: the ramps' time constant over the
    duration). Without that term, continuity alone would let the optimum ramp up within
    one interval: a velocity jump again as h -> 0 (slip converged like h on the triangle
    example)."""
    t0 = time.perf_counter()
    nc = m.n_contacts
    if small is None:
        small = nc < 2 and not tracking
    if small:
        if nc >= 2 or tracking or forces:
            raise ValueError("only a grasp without path rows (one contact, no tracking) "
                             "has the small SX form")
        return _small_grasp_nlp(m, segments, goal_mask, via_masks, t0, smooth)
    nf = len(m.fingers)
    hs = HermiteSimpson(m.nx, m.nu, segments, smooth)
    n = hs.n_intervals
    nseg = len(segments)
    npts = 2 * n + 1
    n_force = nc if nc >= 3 else 0
    n_load = nc if forces else 0
    n_fv = 3 * n_force + LOAD_VARS * n_load  # force variables at a point
    n_s = 1 if nc >= 2 else 0  # the grasp-angle epigraph: force closure needs 2+ contacts
    nx, nu = m.nx, m.nu
    ns = m.surface.n_params
    nv = len(via_masks)
    lc, rc = hs.left_cols, hs.right_cols

    # -- parameters the blocks share ------------------------------------------------------
    shape_q = ca.SX.sym("shape", ns)
    charts_q = ca.SX.sym("charts", 9 * nc)
    ccone_q = ca.SX.sym("ccone")
    tol_q = ca.SX.sym("tol", 2)
    wtr_q = ca.SX.sym("wtr", 2)  # tracking weights (position, rotation)
    load_q = ca.SX.sym("load", LOAD_PARAMS)
    q = ca.vertcat(shape_q, charts_q, ccone_q, tol_q, wtr_q, load_q)
    L = ca.mmax(shape_q)
    prm = ca.vertcat(shape_q, charts_q)
    x_scale = ca.vertcat(*m.x_scale(L))
    sig = ca.SX.sym("sigma")  # the objective's factor in the Lagrangian

    # -- point block: z = (x~, s, f) at one collocation point -----------------------------
    xs = ca.SX.sym("xs", nx)
    s = ca.SX.sym("s", n_s)
    fcol = ca.SX.sym("f", 3 * n_force)
    fl = ca.SX.sym("fl", LOAD_VARS * n_load)
    zp = ca.vertcat(xs, s, fcol, fl)
    pd = ca.SX.sym("pd", 3 if tracking else 0)
    rd = ca.SX.sym("rd", 9 if tracking else 0)
    swp = ca.SX.sym("sw")  # the point's Simpson weight (normalised time)
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

    # (each fingertip where its kinematics put it, eq. 6: the rate rows below)
    _, P, N, R_po, p_po = m.path(x_scale * xs, prm)
    if nc == 2:
        c1, c2, dist = grasp_cosines(P[:, 0], N[:, 0], P[:, 1], N[:, 1])
        add(ca.vertcat(c1 - dist * ccone_q, c2 - dist * ccone_q) / L, 0.0, math.inf)
        add(ca.vertcat(s - (1 - c1 / dist), s - (1 - c2 / dist)), 0.0, math.inf)
    elif nc >= 3:
        from ocp.geometry.force_closure import PUSH_FLOOR, internal_force_residuals

        eq, push, norms = internal_force_residuals(P, N, ca.reshape(fcol, 3, nc), L)
        add(eq, 0.0, 0.0)
        add(ca.sum1(push) - nc, 0.0, 0.0)
        # every contact loaded: an unloaded one would sit in its cone for free
        add(push - PUSH_FLOOR, 0.0, math.inf)
        add(push - ccone_q * norms, 0.0, math.inf)
        add(push - (1 - s) * norms, 0.0, math.inf)
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
    Gp = ca.vertcat(*rows)
    ng_pt = len(lo)
    dropped = set(not_at_node0)
    keep0 = [r for r in range(ng_pt) if r not in dropped]
    lam_p = ca.SX.sym("lam", ng_pt)
    Jp = ca.jacobian(Gp, zp)
    Hp = ca.triu(ca.hessian(sig * cost_p + ca.dot(lam_p, Gp), zp)[0])
    pin = [zp, pd, rd, swp, q]
    # the derivative blocks with common subexpressions merged (ca.cse): 7 % less IPOPT time
    # on experiment 1 in the virtual machine
    pt_fn = ca.Function("point", pin, [Gp])
    pt_cost = ca.Function("point_cost", pin, [cost_p])
    pt_jac = ca.Function("point_jac", pin, ca.cse([Gp, _nz(Jp)]))
    pt_hess = ca.Function("point_hess", [*pin, lam_p, sig], [ca.cse(_nz(Hp))])

    # -- interval block: z = (x_k, x_m, x_k+1, u_0, u_m, u_1, s_k, s_m, s_k+1) ------------
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
        return m.dynamics(x_scale * x_, u_scale * u_, prm) / x_scale

    D = hermite_simpson_defects(xk, xm, xk1, fdyn(xk, u0), fdyn(xm, um), fdyn(xk1, u1), hq)
    hn = hq / Tq
    cost_i: Any = wq[3] * hn / 6 * (sk + 4 * sm + sk1) if n_s else ca.SX(0)
    for i, idx in enumerate(m.effort_groups()):
        if idx:
            cost_i += wq[i] * hn / 6 * (ca.sumsqr(u0[idx]) + 4 * ca.sumsqr(um[idx])
                                        + ca.sumsqr(u1[idx]))
            if smooth:
                cost_i += wq[i] * ramp_q ** 2 * ramp_penalty(u0[idx], um[idx], u1[idx], hn)
    lam_i = ca.SX.sym("lam", 2 * nx)
    Ji = ca.jacobian(D, zi)
    Hi = ca.triu(ca.hessian(sig * cost_i + ca.dot(lam_i, D), zi)[0])
    iin = [zi, hq, Tq, wq, shape_q, charts_q, ramp_q]
    int_fn = ca.Function("interval", iin, [D])
    int_cost = ca.Function("interval_cost", iin, [cost_i])
    int_jac = ca.Function("interval_jac", iin, ca.cse([D, _nz(Ji)]))
    int_hess = ca.Function("interval_hess", [*iin, lam_i, sig], [ca.cse(_nz(Hi))])

    # -- rate rows: z = (x, u) at one collocation point ----------------------------------
    # Closure (eq. 6) at the velocity level (ocp/transcription/velocity_closure.py): the
    # tip's twist from its joints equals the one its rolling contact gives it, at every
    # collocation point and with every input there (both sides of a via-point), six rows
    # per finger. The closure itself holds at the initial grasp and follows by integration
    # (Simpson's rule: its drift is O(h^4), measured 3e-8 m at N = 40). Imposed on the
    # positions instead, the fingertip's velocity from its joints (J q_dot at the free
    # joint-rate inputs) matched the contact's only to O(h^2) at the collocation points,
    # and at the ends of a segment not at all on some plans (the rates there are a free
    # mode of Hermite-Simpson with algebraic rows): the returned trajectory slipped. With
    # these rows it does not slip at the collocation points, and between them the slip
    # shrinks like h^3. Written from the twists (the geometric Jacobian, Montana's rolling
    # velocity), the rows' Hessian has 15,252 instructions on the two-finger grasp (the
    # position rows': 11,604; d/dt c(x) by differentiating the contact's pose: 42,822).
    xr, ur = ca.SX.sym("xr", nx), ca.SX.sym("ur", nu)
    zr = ca.vertcat(xr, ur)
    if nf:
        closure_scale = ca.vertcat(*([1 / L] * 3 + [1.0] * 3) * nf)
        Gr = Tq * closure_scale * fingertip_twist_rows(m, x_scale * xr, u_scale * ur, prm)
    else:
        Gr = ca.SX(0, 1)
    lam_r = ca.SX.sym("lam", Gr.numel())
    Jr = ca.jacobian(Gr, zr)
    Hr = ca.triu(ca.hessian(ca.dot(lam_r, Gr), zr)[0])
    rin = [zr, Tq, shape_q, charts_q]
    rt_fn = ca.Function("rates", rin, [Gr])
    rt_jac = ca.Function("rates_jac", rin, ca.cse([Gr, _nz(Jr)]))
    rt_hess = ca.Function("rates_hess", [*rin, lam_r], [ca.cse(_nz(Hr))])
    ng_r = int(Gr.numel())

    # -- joint accelerations (smooth timing): z = (u_0, u_m, u_1) of one interval ---------
    # The input is the quadratic through (u_0, u_m, u_1) on the interval, its derivative
    # linear: (-3 u_0 + 4 u_m - u_1) / h at the start, (u_0 - 4 u_m + 3 u_1) / h at the end
    # bound it everywhere. Rows: those of every joint rate over the limit, in [-1, 1];
    # linear in z (no Hessian).
    jcols = list(m.effort_groups()[2]) if smooth else []
    ua0, uam, ua1 = (ca.SX.sym(name, nu) for name in ("ua0", "uam", "ua1"))
    za = ca.vertcat(ua0, uam, ua1)
    amax_q = ca.SX.sym("amax")
    if jcols:
        sj = u_scale[jcols] / (hq * amax_q)
        Ga = ca.vertcat(sj * (-3 * ua0[jcols] + 4 * uam[jcols] - ua1[jcols]),
                        sj * (ua0[jcols] - 4 * uam[jcols] + 3 * ua1[jcols]))
    else:
        Ga = ca.SX(0, 1)
    ng_a = int(Ga.numel())
    Ja = ca.jacobian(Ga, za)
    ain = [za, hq, Tq, shape_q, amax_q]
    ac_fn = ca.Function("accel", ain, [Ga])
    ac_jac = ca.Function("accel_jac", ain, [Ga, _nz(Ja)])

    # -- targets (goal, via-points) on the segment end nodes ------------------------------
    ends = hs.segment_end_nodes
    xe = ca.SX.sym("xe", nx, nseg)
    goal_q = ca.SX.sym("goal", 5)
    vias_q = ca.SX.sym("vias", 5, nv)
    tg: list[Any] = []
    for j, vmask in enumerate(via_masks):
        tg += target_residuals(xe[:, j], vias_q[:, j], vmask, x_scale, PERIODIC)
    tg += target_residuals(xe[:, nseg - 1], goal_q, goal_mask, x_scale, PERIODIC)
    Gt = ca.vertcat(*tg) if tg else ca.SX(0, 1)
    lam_t = ca.SX.sym("lam", Gt.numel())
    ze = ca.vec(xe)
    Jt = ca.jacobian(Gt, ze)
    Ht = ca.triu(ca.hessian(ca.dot(lam_t, Gt), ze)[0])
    tin = [ze, goal_q, ca.vec(vias_q), shape_q]
    tg_fn = ca.Function("targets", tin, [Gt])
    tg_jac = ca.Function("targets_jac", tin, [_nz(Jt)])
    tg_hess = ca.Function("targets_hess", [*tin, lam_t], [_nz(Ht)])

    # -- where every block entry sits in w and g ------------------------------------------
    nw = int(hs.w.numel()) + n_s * (n + 1) + n_s * n + n_fv * npts
    S_sx, Sm_sx = ca.SX.sym("S", n_s, n + 1), ca.SX.sym("Sm", n_s, n)
    F_sx = ca.SX.sym("F", n_fv, npts)
    w_sx = ca.vertcat(hs.w, ca.vec(S_sx), ca.vec(Sm_sx), ca.vec(F_sx))
    unpack = ca.Function("unpack", [w_sx], [hs.X, hs.Xm, hs.U, hs.Um, S_sx, Sm_sx, F_sx])
    pack = ca.Function("pack", [hs.X, hs.Xm, hs.U, hs.Um, S_sx, Sm_sx, F_sx], [w_sx])
    Xi, Xmi, Ui, Umi, Si, Smi, Fi = (np.asarray(a).round().astype(np.int64)
                                     for a in unpack(np.arange(nw, dtype=float)))
    Fi = Fi.reshape(n_fv, npts)
    XA = np.hstack([Xi, Xmi])  # nodes, then midpoints: the points' order in the NLP
    Si, Smi = Si.reshape(n_s, n + 1), Smi.reshape(n_s, n)
    SA = np.hstack([Si, Smi])
    zp_idx = np.array([np.concatenate([XA[:, c], SA[:, c], Fi[:, c]]) for c in range(npts)])
    zi_idx = np.array([np.concatenate([Xi[:, k], Xmi[:, k], Xi[:, k + 1], Ui[:, lc[k]],
                                       Umi[:, k], Ui[:, rc[k]], Si[:, k], Smi[:, k], Si[:, k + 1]])
                       for k in range(n)])
    ze_idx = np.concatenate([Xi[:, e] for e in ends])
    zr_list = []
    if nf:
        zr_list = [np.concatenate([Xi[:, k], Ui[:, c]]) for k, c in _node_input_pairs(hs)]
        zr_list += [np.concatenate([Xmi[:, k], Umi[:, k]]) for k in range(n)]
    n_rate = len(zr_list)
    zr_idx = np.array(zr_list, dtype=np.int64).reshape(n_rate, nx + nu)
    n_acc = n if ng_a else 0
    za_idx = np.array([np.concatenate([Ui[:, lc[k]], Umi[:, k], Ui[:, rc[k]]])
                       for k in range(n_acc)], dtype=np.int64).reshape(n_acc, 3 * nu)
    n_def = 2 * nx * n
    off_p = n_def
    off_t = off_p + len(keep0) + (npts - 1) * ng_pt
    off_r = off_t + int(Gt.numel())
    off_a = off_r + n_rate * ng_r
    ng = off_a + n_acc * ng_a
    pos0 = np.full(ng_pt, -1, dtype=np.int64)
    pos0[keep0] = off_p + np.arange(len(keep0))

    jr: list[NDArray[np.int64]] = []
    jc: list[NDArray[np.int64]] = []
    hr: list[NDArray[np.int64]] = []
    hc: list[NDArray[np.int64]] = []

    def place(row_maps: list[NDArray[np.int64]], z_idx: Any, J: Any, H: Any) -> None:
        """Each instance of a block: its Jacobian's rows (``row_maps``: the global row of
        each of its rows, -1 for one it does not have) and columns, its Hessian's entries
        (``z_idx``: the global variable of each of its variables)."""
        rJ, cJ = _triplets(J.sparsity())
        rH, cH = _triplets(H.sparsity())
        for row_map, z in zip(row_maps, z_idx, strict=True):
            jr.append(row_map[rJ])
            jc.append(z[cJ])
            hr.append(z[rH])
            hc.append(z[cH])

    place([pos0] + [off_p + len(keep0) + (c - 1) * ng_pt + np.arange(ng_pt)
                    for c in range(1, npts)], zp_idx, Jp, Hp)
    place([2 * nx * k + np.arange(2 * nx) for k in range(n)], zi_idx, Ji, Hi)
    place([off_t + np.arange(int(Gt.numel()))], [ze_idx], Jt, Ht)
    place([off_r + j * ng_r + np.arange(ng_r) for j in range(n_rate)], zr_idx, Jr, Hr)
    place([off_a + k * ng_a + np.arange(ng_a) for k in range(n_acc)], za_idx, Ja,
          ca.SX(3 * nu, 3 * nu))
    jac_asm = BlockAssembler((ng, nw), np.concatenate(jr), np.concatenate(jc))
    hess_asm = BlockAssembler((nw, nw), np.concatenate(hr), np.concatenate(hc),
                              symmetric=True)

    # -- the NLP in MX: mapped blocks ------------------------------------------------------
    w = ca.MX.sym("w", nw)
    decl = _declaration(m, nseg, nv, npts, tracking)
    p = ca.MX.sym("p", decl.size)
    prm_ = decl.unpack(p)
    shape_p, seg_T, goal, charts, weights, ccone, tol, Pd, Rd = (
        prm_[k] for k in ("shape", "seg_T", "goal", "charts", "weights", "ccone", "tol",
                          "Pd", "Rd"))
    vias_v = ca.vec(prm_["vias"])
    T = ca.sum1(seg_T)
    h = ca.horzcat(*[ca.repmat(seg_T[j] / segments[j], 1, segments[j])
                     for j in range(nseg)])  # 1 x n [s]
    hn_all = h / T
    # Simpson weight of every point (nodes, then midpoints), normalised time
    sw = ca.horzcat((ca.horzcat(0, hn_all) + ca.horzcat(hn_all, 0)) / 6, 4 * hn_all / 6)
    qv = ca.vertcat(shape_p, charts, ccone, tol, weights[4], weights[5], prm_["load"])
    ZP = ca.reshape(w[zp_idx.ravel().tolist()], zp_idx.shape[1], npts)
    ZI = ca.reshape(w[zi_idx.ravel().tolist()], zi_idx.shape[1], n)
    ZE = w[ze_idx.tolist()]
    wts = weights[0:4]
    p_args = (ZP, Pd, Rd, sw, qv)
    i_args = (ZI, h, T, wts, shape_p, charts, prm_["accel"][1])
    t_args = (ZE, goal, vias_v, shape_p)
    ZR = ca.reshape(w[zr_idx.ravel().tolist()], nx + nu, n_rate)
    r_args = (ZR, T, shape_p, charts)
    ZA = ca.reshape(w[za_idx.ravel().tolist()], 3 * nu, n_acc)
    a_args = (ZA, h, T, shape_p, prm_["accel"][0])

    def g_of(Dint: Any, Gpts: Any, Grt: Any, Gacc: Any) -> Any:
        return ca.vertcat(ca.vec(Dint), Gpts[keep0, 0], ca.vec(Gpts[:, 1:]), tg_fn(*t_args),
                          ca.vec(Grt), ca.vec(Gacc))

    g_all = g_of(int_fn.map(n)(*i_args), pt_fn.map(npts)(*p_args),
                 rt_fn.map(n_rate)(*r_args) if n_rate else ca.MX(0, 1),
                 ac_fn.map(n_acc)(*a_args) if n_acc else ca.MX(0, 1))
    f = ca.sum2(pt_cost.map(npts)(*p_args)) + ca.sum2(int_cost.map(n)(*i_args))
    zeros_t = [0.0] * (len(tg) + n_rate * ng_r)
    lbg = [0.0] * n_def + [lo[r] for r in keep0] + lo * (npts - 1) + zeros_t \
        + [-1.0] * (n_acc * ng_a)
    ubg = [0.0] * n_def + [hi[r] for r in keep0] + hi * (npts - 1) + zeros_t \
        + [1.0] * (n_acc * ng_a)
    assert len(lbg) == ng == g_all.numel()

    Gj, Jpn = pt_jac.map(npts)(*p_args)
    Dj, Jin = int_jac.map(n)(*i_args)
    if n_rate:
        Gr_j, Jrn = rt_jac.map(n_rate)(*r_args)
    else:
        Gr_j, Jrn = ca.MX(0, 1), ca.MX(0, 1)
    if n_acc:
        Ga_j, Jan = ac_jac.map(n_acc)(*a_args)
    else:
        Ga_j, Jan = ca.MX(0, 1), ca.MX(0, 1)
    Jnz = ca.vertcat(ca.vec(Jpn), ca.vec(Jin), tg_jac(*t_args), ca.vec(Jrn), ca.vec(Jan))
    jac_g = ca.Function("nlp_jac_g", [w, p], [g_of(Dj, Gj, Gr_j, Ga_j), jac_asm(Jnz)],
                        ["x", "p"], ["g", "jac_g_x"])
    lam_f = ca.MX.sym("lam_f")
    lam_g = ca.MX.sym("lam_g", ng)
    # the multipliers of each point's rows (node 0: zero for the rows it does not have)
    E0 = np.zeros((ng_pt, len(keep0)))
    E0[keep0, np.arange(len(keep0))] = 1.0
    LP = ca.horzcat(ca.mtimes(ca.sparsify(ca.DM(E0)), lam_g[off_p:off_p + len(keep0)]),
                    ca.reshape(lam_g[off_p + len(keep0):off_t], ng_pt, npts - 1))
    LI = ca.reshape(lam_g[0:n_def], 2 * nx, n)
    Hnz = ca.vertcat(ca.vec(pt_hess.map(npts)(*p_args, LP, lam_f)),
                     ca.vec(int_hess.map(n)(*i_args, LI, lam_f)),
                     tg_hess(*t_args, lam_g[off_t:off_r]),
                     ca.vec(rt_hess.map(n_rate)(*r_args, ca.reshape(lam_g[off_r:off_a], ng_r,
                                                                     n_rate)))
                     if n_rate else ca.MX(0, 1))
    hess_lag = ca.Function("nlp_hess_l", [w, p, lam_f, lam_g], [hess_asm(Hnz)],
                           ["x", "p", "lam_f", "lam_g"], ["triu_hess_gamma_x_x"])

    oracle = ca.Function("manipulation_nlp", [w, p], [f, g_all], ["x", "p"], ["f", "g"])
    return BlockNLP(hs, unpack, pack, decl, np.array(lbg), np.array(ubg),
                    time.perf_counter() - t0, n_force, n_s, oracle, jac_g, hess_lag, n_load)
