"""Real-time iterations (RTI) of a controller's window by multiple shooting, the QPs solved
by HPIPM's Riccati recursion (issue 41, item 3; docs/control.md).

The window (:class:`~ocp.control.window.WindowController`) is the grasp's collocation NLP
over a short horizon. Its KKT systems, laid out by stage for a Riccati solver
(:mod:`~ocp.transcription.stage_order`), have stages of 81 (experiment 1) to 230 (three
fingers) variables, because a collocation interval carries its midpoint and a copy of its
end; HPIPM's dense stage factorisations of that layout cost more than IPOPT's sparse
MUMPS (experiment 2: 45 ms a QP against 10 ms a whole IPOPT tick). Here the same window is
written by **multiple shooting** (:class:`ShootingWindow`), with stages as small as the
grasp allows:

* stage ``k`` of the ``N`` intervals: the state ``z_k = (x_k, u_k)`` (the grasp's scaled
  states and its inputs at node ``k``) and the controls ``v_k = (u_m, u_1, s_k, f_k, s_m,
  f_m)`` (the interval's input is the quadratic through ``u_k``, ``u_m``, ``u_1``, as the
  collocation's; the epigraph and internal forces of node ``k`` and of the interval's
  midpoint). Inputs linear over an interval (``u_m`` not free) left one control per input
  for the twelve velocity-closure rows of a fingertip's node and midpoint: the QPs had no
  solution (HPIPM at its iteration limit, steps of 10 in scaled units); a last stage ``N``
  holds node ``N``'s epigraph and forces and copies ``z_N`` into a stage without
  controls (HPIPM's last stage has none);
* dynamics: the rolling equations (the same :meth:`~ocp.transcription.grasp_model.
  PhaseModel.dynamics`) integrated over each interval by explicit Runge-Kutta 4 with the
  quadratic input, and ``u_k+1 = u_1``;
* rows of stage ``k``: the plan's own blocks (:mod:`~ocp.transcription.blocks`) at node
  ``k`` and at the interval's midpoint (the Hermite midpoint of the interval's states,
  the point the certificate's interpolant passes through): the closure at the velocity
  level, force closure in the friction cones, the joints' couplings and clearances, the
  joints' accelerations; the variables' bounds are the collocation NLP's at the same
  nodes (joint limits, rates, contacts in their pads);
* objective: the collocation window's (tracking of the reference's states and inputs,
  effort, the grasp-angle epigraph, the internal forces' size), positive semidefinite in
  the stage variables: its Hessian is the Gauss-Newton Hessian of the tracking problem,
  the constraints' curvature dropped.

One real-time iteration at a point ``W``: **preparation** (:meth:`RtiBackend.prepare`,
before the measured state is known: the rows, their Jacobian, the objective's gradient
and Hessian at ``W``) and **feedback** (:meth:`RtiBackend.run`: the measured state enters
only the bounds of ``x_0``; HPIPM solves the QP, the step is taken in full). The window's
point is then written back on the collocation grid (:meth:`ShootingWindow.collocation_point`)
and certified by the same dense checks as every plan.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np
from numpy.typing import NDArray

from ocp.solution import Status
from ocp.transcription.blocks import (
    PointLayout,
    accel_block,
    point_block,
    ramp_penalty,
    rate_block,
)
from ocp.transcription.collocation import NlpPoint
from ocp.transcription.loads import LOAD_VARS

__all__ = ["HPIPM_OPTIONS", "HPIPM_STATUS", "Linearisation", "RtiBackend", "ShootingWindow",
           "rti_support"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

#: HPIPM's settings (CasADi's ``hpipm`` conic plugin): its 'speed' mode with every residual
#: tolerance 1e-6 (the scaled NLP's stationarity tolerance). On the collocation layout of
#: experiment 1's window: 6 QP iterations, 7.4 ms; with the rows' residuals at 1e-8 HPIPM
#: stopped on its minimal step after 23 iterations (27 ms), and its 'balance' and 'robust'
#: modes ran into their iteration limits (65 ms, 126 ms)
HPIPM_OPTIONS: dict[str, Any] = {"mode": "speed", "iter_max": 30, "res_g_max": 1e-6,
                                 "res_b_max": 1e-6, "res_d_max": 1e-6, "res_m_max": 1e-6}

#: HPIPM's return codes (``hpipm_status``) as ours: 0 converged, 1 its iteration limit,
#: 2 a step too small to go on (its point is still the QP's best), 3 NaN in the
#: solution, 4 an inconsistent equality
HPIPM_STATUS: dict[int, Status] = {0: Status.SOLVED, 1: Status.ITERATION_LIMIT,
                                   2: Status.ITERATION_LIMIT, 3: Status.NUMERICAL_ERROR,
                                   4: Status.INFEASIBLE}

#: Runge-Kutta 4 steps per interval of the window
SUBSTEPS = 1

#: The Levenberg-Marquardt term added to the QP's Hessian on the internal forces (scaled
#: units): the objective curves them hardly at all (their size weighed 1e-3), and without
#: the constraints' curvature the QPs of three fingers took steps of 1 in the forces from
#: the third iteration on, 0.4 infeasible in their cones' rows, HPIPM stopping on its
#: minimal step; with 1e-2 the same from the sixth; with 1 every iteration converged (3 QP
#: iterations, steps 1e-12). On the epigraph too, experiment 2's ticks took 18.4 ms
#: instead of 14.5 (HPIPM on its minimal step in 241 of 399)
FORCE_DAMPING = 1.0


def rti_support(s: Any) -> str | None:
    """Why the RTI backend cannot solve the window ``s`` (a
    :class:`~ocp.solve.attempt.Setup`; None: it can)."""
    nlp = s.nlp
    hs = nlp.hs
    if not hs.continuous or hs.n_input_cols != hs.n_intervals + 1:
        return ("the RTI backend shoots continuous inputs, one per node: the grasp's "
                "timing must be smooth (the request's 'timing')")
    if len(nlp.touching) and any(not all(t) for t in nlp.touching):
        return "the RTI backend tracks one contact phase with every fingertip touching"
    if s.problem.palm is not None and s.problem.palm.goal:
        return "the RTI backend tracks a reference: the window has no goal rows"
    return None


class ShootingWindow:
    """The multiple-shooting form of one window NLP (see the module): its stage functions,
    the QP's pieces at a point (``lin``), and the maps between its variables ``W`` and the
    collocation NLP's ``w`` (same scaling)."""

    def __init__(self, s: Any, force_regularisation: float,
                 compile_dir: Path | None = None) -> None:
        nlp, m = s.nlp, s.model
        self.fingerprint = nlp.fingerprint
        hs = nlp.hs
        n = hs.n_intervals
        nx, nu = m.nx, m.nu
        pm = m.phase((True,) * len(m.fingertips))
        n_s, n_f = nlp.n_epigraph, 3 * nlp.n_force + LOAD_VARS * nlp.n_load
        npts = 2 * n + 1
        layout = PointLayout(nx, n_s, nlp.n_force, nlp.n_load)
        point = point_block(pm, layout, False, bool(nlp.n_load), force_regularisation, npts,
                            True)
        assert point.z_map is not None and np.array_equal(point.z_map,
                                                          np.arange(layout.size))
        assert point.cost is not None
        point_cost = point.cost
        rate = rate_block(pm) if m.fingertips else None
        accel = accel_block(m, True) if s.problem.smooth and m.effort_groups()[2] else None
        nz, na = nx + nu, 2 * nu
        nvk = na + 2 * (n_s + n_f)  # u_m, u_1, (s, f) at the node and at the midpoint
        nvN = n_s + n_f

        # -- symbols ------------------------------------------------------------------
        decl = nlp.params
        p = ca.SX.sym("p", decl.size)
        prm = decl.unpack(p)
        shape_q, charts_q, weights = prm["shape"], prm["charts"], prm["weights"]
        T = ca.sum1(prm["seg_T"])
        h = T / n
        hn = h / T
        qv = ca.vertcat(shape_q, charts_q, prm["ccone"], prm["tol"], weights[4], weights[5],
                        prm["load"])
        wts, accel_p = weights[0:4], prm["accel"]
        Qx, wu = prm["Qx"], prm["wu"]
        L = m.surface.length_scale(shape_q)
        x_scale = ca.vertcat(*m.x_scale(L))
        u_scale = ca.vertcat(*m.u_scale(L, T))
        mp = ca.vertcat(shape_q, charts_q)
        empty = ca.SX(0, 1)

        def part(vec: Any, a: int, b: int) -> Any:  # (an empty slice of a 1-vector is 1x0)
            return vec[a:b] if b > a else empty

        def fdyn(x: Any, u: Any) -> Any:
            return pm.dynamics(x_scale * x, u_scale * u, mp) / x_scale

        def shoot(x: Any, u0: Any, um: Any, u1: Any) -> Any:
            """RK4 over the interval, the input the quadratic through (u0, um, u1)."""
            c1 = (-3 * u0 + 4 * um - u1) / h
            c2 = (2 * u0 - 4 * um + 2 * u1) / h ** 2

            def u_at(t: Any) -> Any:
                return u0 + t * c1 + t ** 2 * c2

            dt = h / SUBSTEPS
            for i in range(SUBSTEPS):
                t0 = i * dt
                k1 = fdyn(x, u_at(t0))
                k2 = fdyn(x + dt / 2 * k1, u_at(t0 + dt / 2))
                k3 = fdyn(x + dt / 2 * k2, u_at(t0 + dt / 2))
                k4 = fdyn(x + dt * k3, u_at(t0 + dt))
                x = x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
            return x

        def point_rows(x: Any, s_: Any, f_: Any, xr: Any, wr: Any) -> tuple[Any, Any]:
            zp = ca.vertcat(x, s_, f_)
            args = [zp, empty, empty, 0.0, xr, wr, Qx, qv]
            return point.fn(*args), point_cost(*args)

        def rates(x: Any, u: Any) -> Any:
            if rate is None:
                return empty
            return rate.fn(ca.vertcat(x, u), T, shape_q, charts_q)

        # -- an interval's stage -------------------------------------------------------
        z, v = ca.SX.sym("z", nz), ca.SX.sym("v", nvk)
        x, u = z[:nx], z[nx:]
        um, u1 = v[:nu], v[nu:na]
        sk, fk = part(v, na, na + n_s), part(v, na + n_s, na + n_s + n_f)
        sm = part(v, na + n_s + n_f, na + 2 * n_s + n_f)
        fm = part(v, na + 2 * n_s + n_f, nvk)
        # per-stage parameters: the node's and midpoint's reference states and weights,
        # the interval's reference inputs, the node's Simpson weight
        xr_k, xr_m = ca.SX.sym("xr_k", nx), ca.SX.sym("xr_m", nx)
        wr_k, wr_m, sw_k = (ca.SX.sym(k) for k in ("wr_k", "wr_m", "sw_k"))
        ur = ca.SX.sym("ur", 3 * nu)
        pk = ca.vertcat(xr_k, wr_k, xr_m, wr_m, ur, sw_k)
        x1 = shoot(x, u, um, u1)
        xm = (x + x1) / 2 + h / 8 * (fdyn(x, u) - fdyn(x1, u1))  # the Hermite midpoint
        Gk, ck = point_rows(x, sk, fk, xr_k, wr_k)
        Gm, cm = point_rows(xm, sm, fm, xr_m, wr_m)
        rows = [Gk, Gm, rates(x, u), rates(xm, um)]
        lo = [point.lo, point.lo]
        hi = [point.hi, point.hi]
        n_rate = rate.n_rows if rate else 0
        lo += [[0.0] * n_rate] * 2
        hi += [[0.0] * n_rate] * 2
        if accel is not None:
            rows.append(accel.fn(ca.vertcat(u, um, u1), h, T, shape_q, accel_p[0]))
            lo.append(accel.lo)
            hi.append(accel.hi)
        cost = ck + cm + (wts[3] * (sw_k * ca.sum1(sk) + 4 * hn / 6 * ca.sum1(sm))
                          if n_s else 0)
        for i, idx in enumerate(m.effort_groups()):
            if idx:
                cost += wts[i] * hn / 6 * (ca.sumsqr(u[idx]) + 4 * ca.sumsqr(um[idx])
                                           + ca.sumsqr(u1[idx]))
                if accel is not None:
                    cost += wts[i] * accel_p[1] ** 2 * ramp_penalty(u[idx], um[idx], u1[idx],
                                                                    hn)
        cost += wu * hn / 6 * (ca.sumsqr(u - ur[:nu]) + 4 * ca.sumsqr(um - ur[nu:2 * nu])
                               + ca.sumsqr(u1 - ur[2 * nu:])) / nu
        c_rows = ca.vertcat(*rows)
        # the rows the fixed initial grasp does not get (point rows outside ``keep0``)
        assert point.keep0 is not None
        free0 = np.ones(point.n_rows, dtype=bool)
        free0[point.keep0] = False
        lo_k, hi_k = np.concatenate(lo), np.concatenate(hi)
        free0_rows = np.flatnonzero(free0)
        F = ca.vertcat(x1, u1)
        zv = ca.vertcat(z, v)
        G = ca.vertcat(F, c_rows)
        H = ca.hessian(cost, zv)[0]
        stage_k = ca.Function("stage", [z, v, pk, p],
                              [G, ca.jacobian(G, zv), ca.gradient(cost, zv), H, cost])
        values_k = ca.Function("stage_values", [z, v, pk, p], [G, cost])
        self.mid = ca.Function("midpoint", [z, v, p], [xm]).map(n)
        # -- the last node's stage -----------------------------------------------------
        zN, vN = ca.SX.sym("zN", nz), ca.SX.sym("vN", nvN)
        xN, uN = zN[:nx], zN[nx:]
        pN = ca.vertcat(xr_k, wr_k, sw_k)
        GN, cN = point_rows(xN, part(vN, 0, n_s), part(vN, n_s, nvN), xr_k, wr_k)
        costN = cN + (wts[3] * sw_k * ca.sum1(part(vN, 0, n_s)) if n_s else 0)
        GN_all = ca.vertcat(zN, GN, rates(xN, uN))
        zvN = ca.vertcat(zN, vN)
        stage_N = ca.Function("stage_last", [zN, vN, pN, p],
                              [GN_all, ca.jacobian(GN_all, zvN), ca.gradient(costN, zvN),
                               ca.hessian(costN, zvN)[0], costN])
        values_N = ca.Function("stage_last_values", [zN, vN, pN, p], [GN_all, costN])
        lo_N = np.concatenate([point.lo, [0.0] * n_rate])
        hi_N = np.concatenate([point.hi, [0.0] * n_rate])

        # -- the whole window: W = (z_0, v_0, ..., z_N-1, v_N-1, z_N, v_N, z_N+1) --------
        nW = n * (nz + nvk) + nz + nvN + nz
        self.nW = nW
        start = np.arange(n) * (nz + nvk)
        self.z_at = np.stack([start + j for j in range(nz)])  # nz x n
        self.v_at = np.stack([start + nz + j for j in range(nvk)])
        oN = n * (nz + nvk)
        self.zN_at, self.vN_at = oN + np.arange(nz), oN + nz + np.arange(nvN)
        self.zE_at = oN + nz + nvN + np.arange(nz)
        Wm = ca.MX.sym("W", nW)
        P = ca.MX.sym("p", decl.size)
        Pm = decl.unpack(P)
        Xr, Wr, Ur = Pm["Xr"], Pm["Wr"], Pm["Ur"]
        TT = ca.sum1(Pm["seg_T"])
        hnm = (TT / n) / TT
        sw_nodes = ca.horzcat(hnm / 6, ca.repmat(2 * hnm / 6, 1, n - 1), hnm / 6)
        PK = ca.vertcat(Xr[:, :n], Wr[:, :n], Xr[:, n + 1:], Wr[:, n + 1:], Ur,
                        sw_nodes[:, :n])
        Zm = ca.reshape(Wm[self.z_at.T.ravel().tolist()], nz, n)
        Vm = ca.reshape(Wm[self.v_at.T.ravel().tolist()], nvk, n)
        Gs, Js, gs, Hs, cs = stage_k.map(n)(Zm, Vm, PK, P)
        zN_, vN_ = Wm[self.zN_at.tolist()], Wm[self.vN_at.tolist()]
        PN = ca.vertcat(Xr[:, n], Wr[:, n], sw_nodes[:, n])
        GN_, JN_, gN_, HN_, cN_ = stage_N(zN_, vN_, PN, P)
        Gv, cv = values_k.map(n)(Zm, Vm, PK, P)
        GNv, cNv = values_N(zN_, vN_, PN, P)
        nck = int(G.numel()) - nz
        ncN = int(GN_all.numel()) - nz
        cols_k = nz + nvk
        J_blocks = [Js[:, k * cols_k:(k + 1) * cols_k] for k in range(n)]
        H_blocks = [Hs[:, k * cols_k:(k + 1) * cols_k] for k in range(n)]
        J = ca.diagcat(*J_blocks, JN_, ca.MX(0, nz))
        H = ca.diagcat(*H_blocks, HN_, ca.MX(nz, nz))
        # the whole diagonal in the pattern, and a Levenberg-Marquardt term on the
        # internal forces (:data:`FORCE_DAMPING`)
        aux = np.zeros(nW)
        for k in range(n):
            v0 = self.z_at[:, k][-1] + 1
            aux[v0 + na + n_s + np.arange(n_f)] = 1.0  # the node's forces
            aux[v0 + na + 2 * n_s + n_f + np.arange(n_f)] = 1.0  # the midpoint's
        aux[self.vN_at[n_s:]] = 1.0
        H = H + ca.MX(ca.DM(ca.Sparsity.diag(nW), FORCE_DAMPING * aux))
        # the gap rows' -I on the next stage's state
        rows_gap: list[int] = []
        cols_gap: list[int] = []
        r = 0
        nxt = [self.z_at[:, k + 1] for k in range(n - 1)] + [self.zN_at, self.zE_at]
        for k in range(n + 1):
            rows_gap += list(range(r, r + nz))
            cols_gap += [int(c) for c in nxt[k]]
            r += nz + (nck if k < n else ncN)
        E = ca.DM(ca.Sparsity.triplet(r, nW, rows_gap, cols_gap), -1.0)
        J = J + E
        g = ca.vertcat(ca.vec(Gs), GN_) + ca.mtimes(E, Wm)
        grad = ca.vertcat(ca.vec(gs), gN_, ca.MX.zeros(nz))
        obj = ca.sum2(cs) + cN_
        self.lin = ca.Function("rti_linearisation", [Wm, P], [g, J, grad, H, obj])
        self.rows = ca.Function("rti_rows", [Wm, P],
                                [ca.vertcat(ca.vec(Gv), GNv) + ca.mtimes(E, Wm),
                                 ca.sum2(cv) + cNv])
        lbg, ubg = np.zeros(r), np.zeros(r)
        r = 0
        for k in range(n + 1):
            r += nz
            lo_, hi_ = (lo_k, hi_k) if k < n else (lo_N, hi_N)
            lbg[r:r + len(lo_)], ubg[r:r + len(hi_)] = lo_, hi_
            if k == 0:
                lbg[r + free0_rows], ubg[r + free0_rows] = -np.inf, np.inf
            r += len(lo_)
        self.lbg, self.ubg = lbg, ubg
        self.qp = ca.conic("rti_qp", "hpipm", {"h": self.lin.sparsity_out(3),
                                               "a": self.lin.sparsity_out(1)},
                           {"N": n + 1, "nx": [nz] * (n + 2), "nu": [nvk] * n + [nvN, 0],
                            "ng": [nck] * n + [ncN, 0], "hpipm": HPIPM_OPTIONS,
                            "error_on_fail": False})
        # -- where W's variables sit in the collocation NLP's w -------------------------
        Xi, Xmi, Ui, Umi, Si, Smi, Fi = (np.asarray(arr).round().astype(np.int64)
                                         for arr in nlp.unpack(np.arange(
                                             nlp.pack.nnz_out(0), dtype=float)))
        Si, Smi = Si.reshape(n_s, n + 1), Smi.reshape(n_s, n)
        Fi = Fi.reshape(n_f, npts)
        to_w = np.full(nW, -1, dtype=np.int64)
        for k in range(n):
            to_w[self.z_at[:nx, k]] = Xi[:, k]
            to_w[self.z_at[nx:, k]] = Ui[:, k]
            vk = self.v_at[:, k]
            to_w[vk[:nu]] = Umi[:, k]
            to_w[vk[nu:na]] = Ui[:, k + 1]
            to_w[vk[na:na + n_s]] = Si[:, k]
            to_w[vk[na + n_s:na + n_s + n_f]] = Fi[:, k]
            to_w[vk[na + n_s + n_f:na + 2 * n_s + n_f]] = Smi[:, k]
            to_w[vk[na + 2 * n_s + n_f:]] = Fi[:, n + 1 + k]
        to_w[self.zN_at[:nx]] = Xi[:, n]
        to_w[self.zN_at[nx:]] = Ui[:, n]
        to_w[self.vN_at[:n_s]] = Si[:, n]
        to_w[self.vN_at[n_s:]] = Fi[:, n]
        self.to_w = to_w
        self.Xmi = Xmi
        #: whether the functions run compiled (``compile_dir``: C generated, compiled with
        #: gcc, cached there; the virtual machine when there is no compiler)
        self.compiled = False
        if compile_dir is not None:
            from ocp.solve.compiled import compiled_functions

            try:
                self.lin, self.rows, self.mid = compiled_functions(
                    [self.lin, self.rows, self.mid], self.fingerprint + ":rti", compile_dir)
                self.compiled = True
            except RuntimeError:
                pass

    def point(self, w: FloatArray) -> FloatArray:
        """The shooting variables of a collocation point ``w`` (the last stage a copy of
        the last node)."""
        W = np.zeros(self.nW)
        mapped = self.to_w >= 0
        W[mapped] = w[self.to_w[mapped]]
        W[self.zE_at] = W[self.zN_at]
        return W

    def bounds(self, lbx: FloatArray, ubx: FloatArray) -> tuple[FloatArray, FloatArray]:
        """The shooting variables' bounds from the collocation NLP's (the copy of the last
        node free)."""
        lo, hi = np.full(self.nW, -np.inf), np.full(self.nW, np.inf)
        mapped = self.to_w >= 0
        lo[mapped], hi[mapped] = lbx[self.to_w[mapped]], ubx[self.to_w[mapped]]
        return lo, hi

    def collocation_point(self, W: FloatArray, p: FloatArray, w_base: FloatArray
                          ) -> FloatArray:
        """The collocation NLP's point of the shooting variables ``W`` (``w_base`` gives
        what the shooting does not have): nodes, inputs (the midpoints' among the
        controls), epigraph and forces, and the midpoints' states (the Hermite midpoint)."""
        w = w_base.copy()
        mapped = self.to_w >= 0
        w[self.to_w[mapped]] = W[mapped]
        w[self.Xmi] = np.asarray(self.mid(W[self.z_at], W[self.v_at], p))
        return w


@dataclass
class Linearisation:
    """The QP of one real-time iteration: the shooting point ``W`` it was made at, the
    parameters ``p`` it was made with, the rows' values ``g``, their Jacobian, the
    objective's gradient and Hessian there; ``time`` [s] it took."""

    W: FloatArray
    p: FloatArray
    g: FloatArray
    jac: Any
    grad: Any
    hess: Any
    time: float


class RtiBackend:
    """Real-time iterations of windows by multiple shooting (see the module), one
    :class:`ShootingWindow` per window NLP: a :class:`~ocp.solve.backend.WindowBackend`.
    ``prepare`` linearises the next window at its guess; ``solve`` takes that
    linearisation when it was made with the tick's parameters (the reference at the same
    time), else linearises first (within the tick)."""

    name = "rti"
    #: its preparation linearises the next window (:meth:`prepare`)
    prepares = True

    def __init__(self, force_regularisation: float = 1e-3,
                 compile_dir: Path | None = None) -> None:
        self._windows: dict[str, ShootingWindow] = {}
        self.force_regularisation = force_regularisation
        #: where the windows' functions are compiled and cached (None: the virtual machine)
        self.compile_dir = compile_dir
        self._prepared: Linearisation | None = None

    @staticmethod
    def unsupported(s: Any) -> str | None:
        """Why this backend cannot solve the window ``s`` (:func:`rti_support`)."""
        return rti_support(s)

    def window(self, s: Any) -> ShootingWindow:
        why = rti_support(s)
        if why is not None:
            raise ValueError(why)
        win = self._windows.get(s.nlp.fingerprint)
        if win is None:
            win = self._windows[s.nlp.fingerprint] = ShootingWindow(
                s, self.force_regularisation, self.compile_dir)
        return win

    def initial(self, s: Any, w0: FloatArray) -> FloatArray:
        """The shooting point of a collocation point ``w0`` (the window's guess)."""
        return self.window(s).point(w0)

    def linearise(self, s: Any, W: FloatArray) -> Linearisation:
        """The QP at the shooting point ``W`` with ``s``'s parameters."""
        win = self.window(s)
        t0 = time.perf_counter()
        g, jac, grad, hess, _ = win.lin(W, s.p)
        return Linearisation(np.asarray(W, dtype=float).copy(), np.asarray(s.p).copy(),
                             np.asarray(g).ravel(), jac, grad, hess,
                             time.perf_counter() - t0)

    def prepare(self, s: Any, w: FloatArray) -> float:
        """The preparation phase: the next window linearised at its guess ``w`` (a
        collocation point of the setup ``s`` the tick will have, the state the last window
        predicts at its start); the wall time [s]."""
        self._prepared = self.linearise(s, self.initial(s, w))
        return self._prepared.time

    def solve(self, s: Any, w0: FloatArray, point: NlpPoint | None, deadline: float,
              max_iter: int) -> tuple[Any, float | None, float | None]:
        """The feedback phase (see :meth:`run`), with the prepared linearisation when it
        was made with ``s``'s parameters; the residual: the shooting rows' and bounds'
        largest violation after the step (no dual residual)."""
        prepared, self._prepared = self._prepared, None
        if prepared is not None and not np.array_equal(prepared.p, s.p):
            prepared = None
        r = self.run(s, w0, deadline, max_iter, prepared)
        return r, (r.violation if math.isfinite(r.violation) else None), None

    def run(self, s: Any, w0: FloatArray, deadline: float, max_iter: int,
            prepared: Linearisation | None = None) -> Any:
        """``max_iter`` real-time iterations of the window ``s`` (its bounds fix the
        measured state) from ``prepared`` or from the collocation guess ``w0``: each one
        QP (HPIPM) and its full step. The outcome as an
        :class:`~ocp.solve.attempt.IpoptRun` on the collocation grid (its ``violation``:
        the shooting rows' largest violation after the step; status: HPIPM's of the last
        QP, solved when the step was below 1e-9 in the scaled variables)."""
        from ocp.solve.attempt import IpoptRun

        win = self.window(s)
        t0 = time.perf_counter()
        lbW, ubW = win.bounds(s.lbx, s.ubx)
        lin = prepared
        W = lin.W.copy() if lin is not None else self.initial(s, w0)
        status, raw, iterations = Status.ITERATION_LIMIT, "", 0
        for _ in range(max_iter):
            if lin is None:
                lin = self.linearise(s, W)
            res = win.qp(h=lin.hess, g=lin.grad, a=lin.jac, lba=win.lbg - lin.g,
                         uba=win.ubg - lin.g, lbx=lbW - W, ubx=ubW - W)
            st = win.qp.stats()
            code = st.get("return_status")
            code = int(code) if isinstance(code, (int, np.integer)) else 3
            raw = f"hpipm {code} ({st.get('iter_count', '?')} QP iterations)"
            iterations += 1
            d = np.asarray(res["x"]).ravel()
            if code not in (0, 1, 2) or not np.all(np.isfinite(d)):
                status = HPIPM_STATUS.get(code, Status.NUMERICAL_ERROR)
                break
            W = np.clip(W + d, lbW, ubW)  # (an interior point's tolerance off a fixed bound)
            step = float(np.max(np.abs(d), initial=0.0))
            # converged: the QP solved and its step nil; else the budget's end
            status = Status.SOLVED if step < 1e-9 and code == 0 else Status.ITERATION_LIMIT
            lin = None
            if status is Status.SOLVED or time.perf_counter() > deadline:
                break
        g, obj = win.rows(W, s.p)
        g = np.asarray(g).ravel()
        viol = float(max(np.max(np.maximum(win.lbg - g, g - win.ubg), initial=0.0),
                         np.max(np.maximum(lbW - W, W - ubW), initial=0.0)))
        w = win.collocation_point(W, s.p, np.asarray(w0, dtype=float))
        elapsed = time.perf_counter() - t0
        ok = bool(np.all(np.isfinite(W)))
        return IpoptRun(status, raw, iterations, float(obj), viol if math.isfinite(viol)
                        else math.inf, w, elapsed,
                        NlpPoint(s.nlp.fingerprint, w, np.zeros(len(w)),
                                 np.zeros(len(s.nlp.lbg))) if ok else None, "rti")
