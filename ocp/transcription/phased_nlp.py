"""The assembly of a grasp's NLP from its phases' blocks
(:func:`~ocp.transcription.nlp_blocks.build_manipulation_nlp`): every block kind placed at
its instances (its variables' and rows' global positions), mapped over them in MX, the
constraints in the NLP's order, and the derivatives assembled from the blocks' nonzeros
(:class:`~ocp.transcription.nlp_blocks.BlockAssembler`)."""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np
from numpy.typing import NDArray

from ocp.spec.problem import PERIODIC
from ocp.transcription.blocks import (
    Block,
    PointLayout,
    _nz,
    accel_block,
    interval_block,
    point_block,
    rate_block,
    touchdown_block,
)
from ocp.transcription.chart_switch import ChartSwitch, chart_map
from ocp.transcription.collocation import HermiteSimpson, target_residuals
from ocp.transcription.grasp_conditions import grasp_condition
from ocp.transcription.nlp_blocks import (
    BlockAssembler,
    BlockNLP,
    _declaration,
    _node_input_pairs,
    _triplets,
)
from ocp.transcription.stage_order import StageLayout, copy_block, stage_layout, stage_rows

__all__ = ["PhasedNLP"]


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
    #: the chart its instances are in (1: after a chart switch; "switch": the interval
    #: that ends at it; 0 otherwise)
    chart: Any = 0


def _second(kind: tuple[Any, Any]) -> Any:
    """A (what, chart) block kind's chart."""
    return kind[1]


class PhasedNLP:
    """The assembly of :func:`build_manipulation_nlp` (blocks placed, mapped and summed)."""

    def __init__(self, m: Any, hs: HermiteSimpson, touching: list[tuple[bool, ...]],
                 goal_mask: tuple[bool, ...], via_masks: tuple[tuple[bool, ...], ...],
                 tracking: bool, force_regularisation: float, forces: bool,
                 smooth: bool, stage_order: bool = False, reference: bool = False,
                 switch: ChartSwitch | None = None) -> None:
        self.m, self.hs, self.touching = m, hs, touching
        self.switch = switch
        self.goal_mask, self.via_masks = goal_mask, via_masks
        self.tracking, self.forces, self.smooth = tracking, forces, smooth
        self.stage_order, self.reference = stage_order, reference
        n = hs.n_intervals
        self.n, self.npts = n, 2 * n + 1
        # every point's contacts: a node has those of the intervals it joins
        nodes = [touching[0]] + [_union(touching[k - 1], touching[k])
                                 for k in range(1, n)] + [touching[-1]]
        ks = n + 1 if switch is None else switch.node  # the first point in the next chart
        if switch is not None and not 0 < ks < n:
            raise ValueError(f"a chart switch is at an inner node (1..{n - 1}), got {ks}")
        #: every point's (contacts, chart), nodes then midpoints (the NLP's order): nodes
        #: from the switch on, and the midpoints of the intervals after it, in the next
        #: chart
        self.point_kinds = [(mask, self.node_chart(j)) for j, mask in enumerate(nodes)] + \
            [(mask, self.node_chart(k)) for k, mask in enumerate(touching)]
        self._points: dict[tuple[Any, ...], Block] = {}
        conditions = [self.model(c).phase(mask)
                      for mask, c in dict.fromkeys(self.point_kinds)]
        conds = [grasp_condition(pm.n_contacts) for pm in conditions]
        self.layout = PointLayout(
            m.nx, max(c.n_epigraph for c in conds),
            m.n_contacts if any(c.internal_forces for c in conds) else 0,
            m.n_contacts if forces else 0)
        for (mask, c), pm in zip(dict.fromkeys(self.point_kinds), conditions, strict=True):
            self._points[(mask, c)] = point_block(pm, self.layout, tracking, forces,
                                                  force_regularisation, self.npts, reference)
        #: each interval's chart (:class:`_Placed`'s ``chart``)
        self.interval_charts: list[Any] = [0 if k < ks - 1 else "switch" if k == ks - 1
                                           else 1 for k in range(n)]

    def model(self, chart: Any) -> Any:
        """The grasp model of a chart (1: the switch's next chart)."""
        return self.switch.model if chart == 1 and self.switch is not None else self.m

    def node_chart(self, j: int) -> int:
        """The chart of node ``j``'s state (1 from the switch node on), and of interval
        ``j``'s midpoint."""
        return int(self.switch is not None and j >= self.switch.node)

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
        Si, Smi = Si.reshape(n_s, n + 1), Smi.reshape(n_s, n)
        stages = None
        if self.stage_order:
            stages = stage_layout((Xi, Xmi, Ui, Umi, Si, Smi), Fi, lc, rc, nw)
            unpack, pack = _reordered(unpack, pack, stages, nw)
            Xi, Xmi, Ui, Umi, Si, Smi, Fi = (stages.pos[a] for a in
                                             (Xi, Xmi, Ui, Umi, Si, Smi, Fi))
            nw = stages.size
        XA = np.hstack([Xi, Xmi])  # nodes, then midpoints: the points' order in the NLP
        SA = np.hstack([Si.reshape(n_s, n + 1), Smi.reshape(n_s, n)])
        point_vars = [np.concatenate([XA[:, c], SA[:, c], Fi[:, c]]) for c in range(npts)]
        self.idx = (Xi, Xmi, Ui, Umi, Si, Smi)

        # -- each block kind's instances, their rows in g in order -------------------------
        row = 0
        placed: list[_Placed] = []
        lbg: list[float] = []
        ubg: list[float] = []

        def group(kinds: list[Any], make: Any, z_of: Any, rows_of: Any,
                  chart_of: Any = None) -> None:
            """Place the instances (in g's order) of the blocks ``make(kind)``, each kind
            on the chart ``chart_of(kind)`` (None: the first)."""
            nonlocal row
            by_kind: dict[Any, _Placed] = {}
            for i, kind in enumerate(kinds):
                if kind not in by_kind:
                    blk = make(kind)
                    by_kind[kind] = _Placed(blk, np.zeros((0, 0), dtype=np.int64), [], [],
                                            0 if chart_of is None else chart_of(kind))
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

        # defects of every interval (in the stage order: with its end's copy)
        ex, eu, es = (stages.cx, stages.cu, stages.cs) if stages is not None else (
            Xi[:, 1:], Ui[:, rc], Si[:, 1:])
        switch_map = None if self.switch is None else chart_map(self.switch.model, m)

        def interval_of(kind: Any) -> Block:
            mask, chart = kind
            return interval_block(self.model(chart).phase(mask), n_s, self.smooth,
                                  self.reference, switch_map if chart == "switch" else None)

        group(list(zip(self.touching, self.interval_charts, strict=True)), interval_of,
              lambda k, _: np.concatenate([Xi[:, k], Xmi[:, k], ex[:, k], Ui[:, lc[k]],
                                           Umi[:, k], eu[:, k], Si[:, k], Smi[:, k],
                                           es[:, k]]), all_rows, _second)
        if stages is not None:  # the gap-closing rows: s_k+1 = copy_k
            arriving = np.vstack([Xi[:, 1:], Ui[:, rc], Si[:, 1:]])
            copies = np.vstack([ex, eu, es])
            group([None] * n, lambda _: copy_block(copies.shape[0]),
                  lambda k, _: np.concatenate([arriving[:, k], copies[:, k]]), all_rows)
        # every point's rows (node 0: the given initial grasp, without tracking bounds)
        group(self.point_kinds, lambda k: self._points[k],
              lambda c, blk: point_vars[c][blk.z_map],
              lambda c, blk: blk.keep0 if c == 0 else all_rows(c, blk), _second)
        off_t = row
        tg_fn, tg_jac, tg_hess, Jt, Ht, n_t = self._targets()
        ends = hs.segment_end_nodes
        ze_idx = np.concatenate([Xi[:, e] for e in ends])
        row += n_t
        lbg += [0.0] * n_t
        ubg += [0.0] * n_t
        # the closure at the velocity level: every node with each of its inputs (those of
        # the intervals using that input touch), then the midpoints
        pairs = _node_input_pairs(hs, self.reference)
        users = {c: [k for k in range(n) if c in (lc[k], rc[k])] for _, c in pairs}
        rate_kinds = [(self._touching_of(users[c]), self.node_chart(k)) for k, c in pairs] + \
            [(mask, self.node_chart(k)) for k, mask in enumerate(self.touching)]
        rate_z = [np.concatenate([Xi[:, k], Ui[:, c]]) for k, c in pairs] + \
            [np.concatenate([Xmi[:, k], Umi[:, k]]) for k in range(n)]
        if m.fingertips:
            group(rate_kinds, lambda k: rate_block(self.model(k[1]).phase(k[0])),
                  lambda i, _: rate_z[i], all_rows, _second)
        if self.smooth and m.effort_groups()[2]:
            group([None] * n, lambda _: accel_block(m, True),
                  lambda k, _: np.concatenate([Ui[:, lc[k]], Umi[:, k], eu[:, k]]),
                  all_rows)
        # fingertips landing on the object at a node: their closure there
        landings = [(k, tuple(i for i, (a, b) in enumerate(zip(self.touching[k - 1],
                                                                 self.touching[k],
                                                                 strict=True))
                              if b and not a)) for k in range(1, n)]
        landings = [(k, tips) for k, tips in landings if tips]
        if landings:
            group([((self.touching[k], tips), self.node_chart(k)) for k, tips in landings],
                  lambda kt: touchdown_block(self.model(kt[1]).phase(kt[0][0]), kt[0][1]),
                  lambda i, _: Xi[:, landings[i][0]], all_rows, _second)
        ng = row
        parked = self._parked(point_vars, placed, Ui, Umi, Xi, Xmi)
        t_rows = off_t + np.arange(n_t)
        ng_k: list[int] = []
        if stages is not None:
            t_rows, lbg, ubg, ng_k = _reorder_rows(placed, stages, t_rows, Jt, ze_idx,
                                                   lbg, ubg, n)
        out = _functions(self, t0, nw, ng, placed, t_rows,
                         (tg_fn, tg_jac, tg_hess, Jt, Ht, ze_idx), lbg, ubg, unpack,
                         pack, nseg, nv, parked)
        if stages is not None:
            out.copies = stages.copies
            out.stages = {"N": n, "nx": stages.nx, "nu": stages.nu, "ng": ng_k}
        return out

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
        x_scale = ca.vertcat(*m.x_scale(m.surface.length_scale(shape_q)))
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
        for c, kind in enumerate(self.point_kinds):
            z_map = self._points[kind].z_map
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


def _reordered(unpack: ca.Function, pack: ca.Function, st: StageLayout, nw: int
               ) -> tuple[ca.Function, ca.Function]:
    """``unpack`` and ``pack`` of the stage order: the same parts, read from (written to)
    the stage-ordered variables; ``pack`` writes each copy as the value it copies (a
    guess packed from states and inputs is consistent with the gap-closing rows)."""
    w = ca.SX.sym("w", st.size)
    unpack_s = ca.Function("unpack", [w], unpack(w[st.pos[:nw].tolist()]))
    parts = [ca.SX.sym(unpack.name_out(i), *unpack.size_out(i)) for i in range(7)]
    wk = pack(*parts)
    ext = ca.vertcat(wk, wk[st.copy_src.tolist()])
    return unpack_s, ca.Function("pack", parts, [ext[st.order.tolist()]])


def _stage_rows(placed: list[_Placed], st: StageLayout, t_rows: NDArray[np.int64],
                Jt: Any, ze_idx: NDArray[np.int64], ng: int, n: int
                ) -> tuple[NDArray[np.int64], list[int]]:
    """Every row's position in the stage order (:func:`stage_rows`) and each stage's
    number of rows other than its gap-closing ones: a block instance's rows belong to the
    first stage of its variables, a target row to its node's."""
    row_stage = np.zeros(ng, dtype=np.int64)
    gap = np.zeros(ng, dtype=bool)
    for pl in placed:
        for rmap, z in zip(pl.row_maps, pl.z_idx, strict=True):
            rows = rmap[rmap >= 0]
            row_stage[rows] = int(st.stage_of[z].min())
            gap[rows] = pl.block.fn.name() == "copy"
    r, c = (np.asarray(a, dtype=np.int64) for a in Jt.sparsity().get_triplet())
    for i, row in enumerate(t_rows):
        row_stage[row] = int(st.stage_of[ze_idx[c[r == i]]].min())
    return stage_rows(row_stage, gap, n + 1)


def _reorder_rows(placed: list[_Placed], st: StageLayout, t_rows: NDArray[np.int64],
                  Jt: Any, ze_idx: NDArray[np.int64], lbg: list[float], ubg: list[float],
                  n: int) -> tuple[NDArray[np.int64], list[float], list[float], list[int]]:
    """The rows in the stage order (:func:`_stage_rows`): the instances' row maps moved in
    place; the targets' rows, the bounds and each stage's ``ng`` returned."""
    new_row, ng_k = _stage_rows(placed, st, t_rows, Jt, ze_idx, len(lbg), n)
    for pl in placed:
        pl.row_maps = [np.where(r >= 0, new_row[np.maximum(r, 0)], -1) for r in pl.row_maps]
    inv = np.argsort(new_row)
    return new_row[t_rows], [lbg[i] for i in inv], [ubg[i] for i in inv], ng_k


def _functions(nlp: PhasedNLP, t0: float, nw: int, ng: int, placed: list[_Placed],
               t_rows: NDArray[np.int64], targets: tuple[Any, ...],
               lbg: list[float], ubg: list[float], unpack: ca.Function,
               pack: ca.Function, nseg: int, nv: int, parked: NDArray[np.int64]
               ) -> BlockNLP:
    """The NLP in MX from the placed blocks: every kind mapped over its instances,
    the constraints in g's order, the derivatives assembled from the blocks'."""
    m, hs, n, npts = nlp.m, nlp.hs, nlp.n, nlp.npts
    tg_fn, tg_jac, tg_hess, Jt, Ht, ze_idx = targets
    segments = hs.segments
    w = ca.MX.sym("w", nw)
    decl = _declaration(m, nseg, nv, npts, nlp.tracking, nlp.reference,
                        nlp.switch is not None)
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
    charts_b, refs = prm_["charts_b"], prm_["switch_refs"]
    qv = ca.vertcat(shape_p, charts, ccone, tol, weights[4], weights[5], prm_["load"])
    qv_b = ca.vertcat(shape_p, charts_b, ccone, tol, weights[4], weights[5], prm_["load"])
    wts = weights[0:4]
    accel = prm_["accel"]
    Xr, Wr, Qx, Ur, wu = (prm_[k] for k in ("Xr", "Wr", "Qx", "Ur", "wu"))

    def cols(M: Any, c: list[int], total: int) -> Any:
        return M if len(c) == total or M.size2() == 0 else M[:, c]

    def args(pl: _Placed) -> list[Any]:
        """The mapped arguments of a kind's instances (its variables first)."""
        Z = ca.reshape(w[pl.z_idx.ravel().tolist()], pl.z_idx.shape[1], len(pl.cols))
        name = pl.block.fn.name()
        ch = charts_b if pl.chart == 1 else charts  # the instances' chart's patches
        if name == "point":
            return [Z, cols(Pd, pl.cols, npts), cols(Rd, pl.cols, npts),
                    cols(sw, pl.cols, npts), cols(Xr, pl.cols, npts),
                    cols(Wr, pl.cols, npts), Qx, qv_b if pl.chart == 1 else qv]
        if name in ("interval", "switch"):
            extra = [charts_b, refs] if name == "switch" else []
            return [Z, cols(h, pl.cols, n), T, wts, shape_p, ch, accel[1],
                    cols(Ur, pl.cols, n), wu, *extra]
        if name == "rates":
            return [Z, T, shape_p, ch]
        if name == "accel":
            return [Z, cols(h, pl.cols, n), T, shape_p, accel[0]]
        if name == "copy":
            return [Z]
        return [Z, shape_p, ch]  # touchdown

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
    place([t_rows], [ze_idx], Jt, Ht)
    jnz.append(tg_jac(*t_args))
    hnz.append(tg_hess(*t_args, lam_g[t_rows.tolist()]))
    pieces.append(tg_fn(*t_args))
    jac_pieces.append(tg_fn(*t_args))
    where.append(t_rows)
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
    n_force = nlp.layout.n_force
    return BlockNLP(hs, unpack, pack, decl, np.array(lbg), np.array(ubg),
                    time.perf_counter() - t0, n_force, nlp.layout.n_s, oracle, jac_g,
                    hess_lag, nlp.layout.n_load, parked, tuple(nlp.touching))
