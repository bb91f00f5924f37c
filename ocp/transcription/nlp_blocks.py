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

import time
from dataclasses import dataclass, field
from typing import Any

import casadi as ca
import numpy as np
from numpy.typing import NDArray

from ocp.spec.problem import PERIODIC
from ocp.transcription.blocks import (
    Block,
    PointLayout,
    accel_block,
    interval_block,
    point_block,
    ramp_penalty,
    rate_block,
    touchdown_block,
)
from ocp.transcription.collocation import HermiteSimpson, target_residuals
from ocp.transcription.loads import (
    LOAD_PARAMS,
    LOAD_PUSH_WEIGHT,
    LOAD_REGULARISATION,
    LOAD_VARS,
    TORSION_SHARE,
    load_cost,
    load_rows,
)
from ocp.transcription.parameters import Parameters

__all__ = ["LOAD_PARAMS", "LOAD_PUSH_WEIGHT", "LOAD_REGULARISATION", "LOAD_VARS",
           "TORSION_SHARE", "BlockAssembler", "BlockNLP", "Schedule", "build_manipulation_nlp",
           "interval_touching", "load_cost", "load_rows"]

#: A grasp's contact phases on its grid: (intervals, which fingertips touch the object) per
#: phase, in time order; None: one phase, every fingertip touching.
Schedule = tuple[tuple[int, tuple[bool, ...]], ...]


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
    #: variables no row or cost of their point's phase uses (a lifted fingertip's contact
    #: coordinates and contact inputs, the forces of contacts that do not touch): fixed
    #: at zero by the bounds (:func:`~ocp.transcription.values.bounds`); empty for one phase
    parked: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    #: each interval's fingertips touching the object (the schedule, per interval)
    touching: tuple[tuple[bool, ...], ...] = ()


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




def interval_touching(n_fingertips: int, n: int, schedule: Schedule | None
                      ) -> list[tuple[bool, ...]]:
    """Which fingertips touch the object on each of the ``n`` intervals."""
    if schedule is None:
        return [(True,) * n_fingertips] * n
    out: list[tuple[bool, ...]] = []
    for k, mask in schedule:
        if k < 1 or len(mask) != n_fingertips:
            raise ValueError(f"a phase needs at least one interval and one flag per "
                             f"fingertip ({n_fingertips}), got {k} and {len(mask)}")
        out += [tuple(bool(t) for t in mask)] * k
    if len(out) != n:
        raise ValueError(f"the phases span {len(out)} intervals, the grid has {n}")
    return out


def _union(a: tuple[bool, ...], b: tuple[bool, ...]) -> tuple[bool, ...]:
    return tuple(x or y for x, y in zip(a, b, strict=True))


@dataclass
class _Placed:
    """The instances of one block kind: its block, their variables (rows of ``z_idx``:
    the global variable of each block variable), the global row of each of their rows
    (``row_maps``, -1 for a row an instance does not have) and their arguments' columns."""

    block: Block
    z_idx: NDArray[np.int64]
    row_maps: list[NDArray[np.int64]]
    cols: list[int]


def build_manipulation_nlp(m: Any, segments: tuple[int, ...], goal_mask: tuple[bool, ...],
                           via_masks: tuple[tuple[bool, ...], ...], tracking: bool,
                           force_regularisation: float, small: bool | None = None,
                           forces: bool = False, smooth: bool = False,
                           schedule: Schedule | None = None) -> BlockNLP:
    """The NLP of one grasp structure (``m``: its
    :class:`~ocp.transcription.grasp_model.GraspModel`) with its contact phases
    (``schedule``: :data:`Schedule`; None, one phase with every fingertip touching):
    variables ``w = (X, Xm, U, Um, S, Sm, F)`` (scaled states and inputs at
    nodes and midpoints, grasp epigraph at every point, internal forces of 3+ contacts),
    parameters ``p = (shape, seg_T, goal, vias, charts, weights, cone cosine, tracking
    tolerances, desired positions, desired rotations)``; constraints: the defects of every
    interval, every point's path constraints (node 0, the given initial grasp, without its
    tracking bounds), the goal and via-point targets, the fingertips' closure at the
    velocity level at every node (with each of its inputs) and midpoint, the joints'
    accelerations, the closure of fingertips landing at a node. ``small`` (default: for
    one contact without tracking) writes the same NLP out in SX instead of from blocks.

    Phases share one grid and one layout of the variables; each interval and point gets
    the blocks of its phase (:mod:`ocp.transcription.blocks`: built from what the phase's
    active contacts contribute, once per distinct set of touching fingertips): a node
    between two phases has the contacts of both (a fingertip lifts off after it, lands
    on it). A lifted fingertip's contact coordinates have no dynamics (they are not states
    of the phase) and its contact inputs drive nothing: both are parked (``parked``), as
    the forces of the contacts a point does not have; where it lands, its closure holds
    (:func:`~ocp.transcription.blocks.touchdown_block`).

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
    hs = HermiteSimpson(m.nx, m.nu, segments, smooth)
    n = hs.n_intervals
    touching = interval_touching(len(m.fingertips), n, schedule)
    one_phase = len(set(touching)) == 1 and all(touching[0])
    if small is None:
        small = nc < 2 and not tracking and one_phase
    if small:
        if nc >= 2 or tracking or forces or not one_phase:
            raise ValueError("only a grasp without path rows (one contact, no tracking, "
                             "one phase) has the small SX form")
        return _small_grasp_nlp(m, segments, goal_mask, via_masks, t0, smooth)
    return _PhasedNLP(m, hs, touching, goal_mask, via_masks, tracking, force_regularisation,
                      forces, smooth).build(t0)


class _PhasedNLP:
    """The assembly of :func:`build_manipulation_nlp` (blocks placed, mapped and summed)."""

    def __init__(self, m: Any, hs: HermiteSimpson, touching: list[tuple[bool, ...]],
                 goal_mask: tuple[bool, ...], via_masks: tuple[tuple[bool, ...], ...],
                 tracking: bool, force_regularisation: float, forces: bool,
                 smooth: bool) -> None:
        self.m, self.hs, self.touching = m, hs, touching
        self.goal_mask, self.via_masks = goal_mask, via_masks
        self.tracking, self.forces, self.smooth = tracking, forces, smooth
        n = hs.n_intervals
        self.n, self.npts = n, 2 * n + 1
        # every point's contacts: a node has those of the intervals it joins
        nodes = [touching[0]] + [_union(touching[k - 1], touching[k])
                                 for k in range(1, n)] + [touching[-1]]
        self.point_masks = nodes + touching  # nodes, then midpoints: the NLP's order
        self._points: dict[tuple[bool, ...], Block] = {}
        conditions = [m.phase(mask) for mask in dict.fromkeys(self.point_masks)]
        from ocp.transcription.grasp_conditions import grasp_condition

        conds = [grasp_condition(pm.n_contacts) for pm in conditions]
        self.layout = PointLayout(
            m.nx, max(c.n_epigraph for c in conds),
            m.n_contacts if any(c.internal_forces for c in conds) else 0,
            m.n_contacts if forces else 0)
        for pm in conditions:
            self._points[pm.touching] = point_block(pm, self.layout, tracking, forces,
                                                    force_regularisation, self.npts)

    def build(self, t0: float) -> BlockNLP:
        m, hs, n, npts, layout = self.m, self.hs, self.n, self.npts, self.layout
        nx = m.nx
        nseg, nv = len(hs.segments), len(self.via_masks)
        n_s, n_fv = layout.n_s, layout.size - nx - layout.n_s
        lc, rc = hs.left_cols, hs.right_cols
        # -- the variables, and where every block instance's sit ---------------------------
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
        SA = np.hstack([Si.reshape(n_s, n + 1), Smi.reshape(n_s, n)])
        point_vars = [np.concatenate([XA[:, c], SA[:, c], Fi[:, c]]) for c in range(npts)]
        Si = Si.reshape(n_s, n + 1)
        Smi = Smi.reshape(n_s, n)
        self.idx = (Xi, Xmi, Ui, Umi, Si, Smi)

        # -- each block kind's instances, their rows in g in order -------------------------
        row = 0
        placed: list[_Placed] = []
        lbg: list[float] = []
        ubg: list[float] = []

        def group(kinds: list[Any], make: Any, z_of: Any, rows_of: Any) -> None:
            """Place the instances (in g's order) of the blocks ``make(kind)``."""
            nonlocal row
            by_kind: dict[Any, _Placed] = {}
            for i, kind in enumerate(kinds):
                if kind not in by_kind:
                    blk = make(kind)
                    by_kind[kind] = _Placed(blk, np.zeros((0, 0), dtype=np.int64), [], [])
                pl = by_kind[kind]
                keep = rows_of(i, pl.block)
                rmap = np.full(pl.block.n_rows, -1, dtype=np.int64)
                rmap[keep] = row + np.arange(len(keep))
                row += len(keep)
                lbg.extend(pl.block.lo[r] for r in keep)
                ubg.extend(pl.block.hi[r] for r in keep)
                pl.row_maps.append(rmap)
                pl.cols.append(i)
            for pl in by_kind.values():
                pl.z_idx = np.array([z_of(i, pl.block) for i in pl.cols], dtype=np.int64)
                placed.append(pl)

        def all_rows(i: int, blk: Block) -> list[int]:
            return list(range(blk.n_rows))

        # defects of every interval
        group(self.touching, lambda k: interval_block(m.phase(k), n_s, self.smooth),
              lambda k, _: np.concatenate([Xi[:, k], Xmi[:, k], Xi[:, k + 1], Ui[:, lc[k]],
                                           Umi[:, k], Ui[:, rc[k]], Si[:, k], Smi[:, k],
                                           Si[:, k + 1]]), all_rows)
        # every point's rows (node 0: the given initial grasp, without tracking bounds)
        group(self.point_masks, lambda k: self._points[k],
              lambda c, blk: point_vars[c][blk.z_map],
              lambda c, blk: blk.keep0 if c == 0 else all_rows(c, blk))
        off_t = row
        tg_fn, tg_jac, tg_hess, Jt, Ht, n_t = self._targets()
        ends = hs.segment_end_nodes
        ze_idx = np.concatenate([Xi[:, e] for e in ends])
        row += n_t
        lbg += [0.0] * n_t
        ubg += [0.0] * n_t
        off_r = row
        # the closure at the velocity level: every node with each of its inputs (those of
        # the intervals using that input touch), then the midpoints
        pairs = _node_input_pairs(hs)
        users = {c: [k for k in range(n) if c in (lc[k], rc[k])] for _, c in pairs}
        rate_kinds = [self._touching_of(users[c]) for _, c in pairs] + list(self.touching)
        rate_z = [np.concatenate([Xi[:, k], Ui[:, c]]) for k, c in pairs] + \
            [np.concatenate([Xmi[:, k], Umi[:, k]]) for k in range(n)]
        if m.fingertips:
            group(rate_kinds, lambda k: rate_block(m.phase(k)), lambda i, _: rate_z[i],
                  all_rows)
        if self.smooth and m.effort_groups()[2]:
            group([None] * n, lambda _: accel_block(m, True),
                  lambda k, _: np.concatenate([Ui[:, lc[k]], Umi[:, k], Ui[:, rc[k]]]),
                  all_rows)
        # fingertips landing on the object at a node: their closure there
        landings = [(k, tuple(i for i, (a, b) in enumerate(zip(self.touching[k - 1],
                                                                 self.touching[k],
                                                                 strict=True))
                              if b and not a)) for k in range(1, n)]
        landings = [(k, tips) for k, tips in landings if tips]
        if landings:
            group([(self.touching[k], tips) for k, tips in landings],
                  lambda kt: touchdown_block(m.phase(kt[0]), kt[1]),
                  lambda i, _: Xi[:, landings[i][0]], all_rows)
        ng = row
        parked = self._parked(point_vars, placed, Ui, Umi, Xi, Xmi)
        return self._functions(t0, nw, ng, placed, (off_t, off_r),
                               (tg_fn, tg_jac, tg_hess, Jt, Ht, ze_idx), lbg, ubg, unpack,
                               pack, nseg, nv, parked)

    def _touching_of(self, intervals: list[int]) -> tuple[bool, ...]:
        out = self.touching[intervals[0]]
        for k in intervals[1:]:
            out = _union(out, self.touching[k])
        return out

    def _targets(self) -> tuple[Any, ...]:
        """The goal and via-point rows on the segments' end nodes."""
        m, hs = self.m, self.hs
        nx, nseg, nv = m.nx, len(hs.segments), len(self.via_masks)
        shape_q = ca.SX.sym("shape", m.surface.n_params)
        x_scale = ca.vertcat(*m.x_scale(ca.mmax(shape_q)))
        xe = ca.SX.sym("xe", nx, nseg)
        goal_q = ca.SX.sym("goal", 5)
        vias_q = ca.SX.sym("vias", 5, nv)
        tg: list[Any] = []
        for j, vmask in enumerate(self.via_masks):
            tg += target_residuals(xe[:, j], vias_q[:, j], vmask, x_scale, PERIODIC)
        tg += target_residuals(xe[:, nseg - 1], goal_q, self.goal_mask, x_scale, PERIODIC)
        Gt = ca.vertcat(*tg) if tg else ca.SX(0, 1)
        lam_t = ca.SX.sym("lam", Gt.numel())
        ze = ca.vec(xe)
        Jt = ca.jacobian(Gt, ze)
        Ht = ca.triu(ca.hessian(ca.dot(lam_t, Gt), ze)[0])
        tin = [ze, goal_q, ca.vec(vias_q), shape_q]
        from ocp.transcription.blocks import _nz

        return (ca.Function("targets", tin, [Gt]), ca.Function("targets_jac", tin, [_nz(Jt)]),
                ca.Function("targets_hess", [*tin, lam_t], [_nz(Ht)]), Jt, Ht,
                int(Gt.numel()))

    def _parked(self, point_vars: list[NDArray[np.int64]], placed: list[_Placed],
                Ui: NDArray[np.int64], Umi: NDArray[np.int64], Xi: NDArray[np.int64],
                Xmi: NDArray[np.int64]) -> NDArray[np.int64]:
        """The variables nothing of their phase uses: each point's unused force and
        epigraph slots; a lifted fingertip's contact coordinates at the midpoints of its
        lifted intervals and at the nodes between two of them, and its contact inputs
        used only by lifted intervals."""
        m, hs, n = self.m, self.hs, self.n
        out: list[int] = []
        for c, mask in enumerate(self.point_masks):
            z_map = self._points[mask].z_map
            assert z_map is not None
            used = set(z_map.tolist())
            out += [int(point_vars[c][j]) for j in range(self.layout.size) if j not in used]
        lc, rc = hs.left_cols, hs.right_cols
        for i, tip in enumerate(m.fingertips):
            lifted = [not t[i] for t in self.touching]
            eta = np.arange(tip.eta_cols.start, tip.eta_cols.stop)
            w = np.arange(tip.w_cols.start, tip.w_cols.stop)
            for k in range(n):
                if lifted[k]:
                    out += Xmi[eta, k].tolist() + Umi[w, k].tolist()
            for j in range(1, n + 1):  # node 0 is the given initial state
                if all(lifted[k] for k in (j - 1, j) if k < n):
                    out += Xi[eta, j].tolist()
            for col in range(hs.n_input_cols):
                ks = [k for k in range(n) if col in (lc[k], rc[k])]
                if ks and all(lifted[k] for k in ks):
                    out += Ui[w, col].tolist()
        return np.array(sorted(set(out)), dtype=np.int64)

    def _functions(self, t0: float, nw: int, ng: int, placed: list[_Placed],
                   offsets: tuple[int, int], targets: tuple[Any, ...],
                   lbg: list[float], ubg: list[float], unpack: ca.Function,
                   pack: ca.Function, nseg: int, nv: int, parked: NDArray[np.int64]
                   ) -> BlockNLP:
        """The NLP in MX from the placed blocks: every kind mapped over its instances,
        the constraints in g's order, the derivatives assembled from the blocks'."""
        m, hs, n, npts = self.m, self.hs, self.n, self.npts
        off_t, off_r = offsets
        tg_fn, tg_jac, tg_hess, Jt, Ht, ze_idx = targets
        segments = hs.segments
        w = ca.MX.sym("w", nw)
        decl = _declaration(m, nseg, nv, npts, self.tracking)
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
        wts = weights[0:4]
        accel = prm_["accel"]

        def cols(M: Any, c: list[int], total: int) -> Any:
            return M if len(c) == total else M[:, c]

        def args(pl: _Placed) -> list[Any]:
            """The mapped arguments of a kind's instances (its variables first)."""
            Z = ca.reshape(w[pl.z_idx.ravel().tolist()], pl.z_idx.shape[1], len(pl.cols))
            name = pl.block.fn.name()
            if name == "point":
                return [Z, cols(Pd, pl.cols, npts), cols(Rd, pl.cols, npts),
                        cols(sw, pl.cols, npts), qv]
            if name == "interval":
                return [Z, cols(h, pl.cols, n), T, wts, shape_p, charts, accel[1]]
            if name == "rates":
                return [Z, T, shape_p, charts]
            if name == "accel":
                return [Z, cols(h, pl.cols, n), T, shape_p, accel[0]]
            return [Z, shape_p, charts]  # touchdown

        t_args = (w[ze_idx.tolist()], goal, vias_v, shape_p)
        # g in its order: each kind's rows (vec: instance by instance), then re-ordered
        pieces: list[Any] = []
        jac_pieces: list[Any] = []
        where: list[NDArray[np.int64]] = []
        jr: list[NDArray[np.int64]] = []
        jc: list[NDArray[np.int64]] = []
        hr: list[NDArray[np.int64]] = []
        hc: list[NDArray[np.int64]] = []
        jnz: list[Any] = []
        hnz: list[Any] = []
        fcost: list[Any] = []
        lam_f = ca.MX.sym("lam_f")
        lam_g = ca.MX.sym("lam_g", ng)
        lam_x = ca.vertcat(lam_g, 0)  # index ng: a row an instance does not have

        def place(row_maps: list[NDArray[np.int64]], z_idx: Any, J: Any, H: Any) -> None:
            rJ, cJ = _triplets(J.sparsity())
            rH, cH = _triplets(H.sparsity())
            for row_map, z in zip(row_maps, z_idx, strict=True):
                jr.append(row_map[rJ])
                jc.append(z[cJ])
                hr.append(z[rH])
                hc.append(z[cH])

        for pl in placed:
            blk, k = pl.block, len(pl.cols)
            a = args(pl)
            G, Jn = blk.jac.map(k)(*a)
            pieces.append(ca.vec(blk.fn.map(k)(*a)))
            jac_pieces.append(ca.vec(G))
            rm = np.concatenate(pl.row_maps)
            where.append(rm)
            jnz.append(ca.vec(Jn))
            place(pl.row_maps, pl.z_idx, blk.J, blk.H)
            if blk.hess is not None:
                L = ca.reshape(lam_x[np.where(rm >= 0, rm, ng).tolist()], blk.n_rows, k)
                extra = [lam_f] if blk.cost is not None else []
                hnz.append(ca.vec(blk.hess.map(k)(*a, L, *extra)))
            if blk.cost is not None:
                fcost.append(ca.sum2(blk.cost.map(k)(*a)))
        # the targets' one instance
        place([off_t + np.arange(int(Jt.size1()))], [ze_idx], Jt, Ht)
        jnz.append(tg_jac(*t_args))
        hnz.append(tg_hess(*t_args, lam_g[off_t:off_r]))
        pieces.append(tg_fn(*t_args))
        jac_pieces.append(tg_fn(*t_args))
        where.append(off_t + np.arange(int(Jt.size1())))
        order = np.concatenate(where)
        keep = np.flatnonzero(order >= 0)
        perm = np.empty(ng, dtype=np.int64)
        perm[order[keep]] = keep

        def g_of(parts: list[Any]) -> Any:
            return ca.vertcat(*parts)[perm.tolist()]

        g_all = g_of(pieces)
        f = sum(fcost[1:], fcost[0]) if fcost else ca.MX(0)
        assert len(lbg) == ng == g_all.numel()
        jac_asm = BlockAssembler((ng, nw), np.concatenate(jr), np.concatenate(jc))
        hess_asm = BlockAssembler((nw, nw), np.concatenate(hr), np.concatenate(hc),
                                  symmetric=True)
        jac_g = ca.Function("nlp_jac_g", [w, p], [g_of(jac_pieces), jac_asm(ca.vertcat(*jnz))],
                            ["x", "p"], ["g", "jac_g_x"])
        hess_lag = ca.Function("nlp_hess_l", [w, p, lam_f, lam_g],
                               [hess_asm(ca.vertcat(*hnz))],
                               ["x", "p", "lam_f", "lam_g"], ["triu_hess_gamma_x_x"])
        oracle = ca.Function("manipulation_nlp", [w, p], [f, g_all], ["x", "p"], ["f", "g"])
        n_force = self.layout.n_force
        return BlockNLP(hs, unpack, pack, decl, np.array(lbg), np.array(ubg),
                        time.perf_counter() - t0, n_force, self.layout.n_s, oracle, jac_g,
                        hess_lag, self.layout.n_load, parked, tuple(self.touching))
