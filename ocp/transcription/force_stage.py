"""The planned forces of a kinematic plan, point by point (docs/forces.md, "Two stages").

In the manipulation NLP with ``forces`` (:mod:`ocp.transcription.nlp_blocks`) the load
variables of a collocation point appear only in that point's rows (equilibrium, minimum
normal force, friction cones: :func:`~ocp.transcription.nlp_blocks.load_rows`) and in its
own objective term (:func:`~ocp.transcription.nlp_blocks.load_cost`). The kinematics do
not depend on them. So, given a plan's states, its forces are the solutions of one small
convex-like problem per point, and all points are solved as one block-diagonal NLP here.

The planner (:meth:`ocp.solve.planner.ManipulationPlanner.solve`) plans the kinematics
first and then the forces at its collocation points. Only when some point admits no
forces (the kinematic optimum's grasp cannot hold the load inside the cones) does it solve
the coupled NLP, warm-started from the kinematic plan. The forces' objective terms are
small by design ("small enough not to move the plan"), so the coupled optimum differs
from this one by those terms' pull on the kinematics alone.
"""

from __future__ import annotations

from typing import Any

import casadi as ca
import numpy as np
from numpy.typing import NDArray

from ocp.transcription.nlp_blocks import (
    LOAD_PARAMS,
    LOAD_VARS,
    load_cost,
    load_rows,
)
from ocp.transcription.values import load_bounds

__all__ = ["ForceStage"]

FloatArray = NDArray[np.float64]

#: IPOPT options of the force stage: quiet; the rows' tolerance well inside the
#: certificate's (1e-3 of the force scale).
FORCE_STAGE_OPTIONS: dict[str, Any] = {
    "expand": True, "print_time": False, "ipopt.print_level": 0, "ipopt.sb": "yes",
    "ipopt.tol": 1e-9, "ipopt.constr_viol_tol": 1e-9, "ipopt.max_iter": 500,
}
#: The largest row violation (scaled forces) accepted from the force stage.
MAX_VIOLATION = 1e-7


class ForceStage:
    """The per-point force problems of one grasp model, as one NLP per number of points
    (built once, kept)."""

    def __init__(self, m: Any) -> None:
        self.m = m
        nc = m.n_contacts
        fl = ca.SX.sym("fl", LOAD_VARS * nc)
        P, N = ca.SX.sym("P", 3, nc), ca.SX.sym("N", 3, nc)
        R = ca.SX.sym("R", 3, 3)
        load, L = ca.SX.sym("load", LOAD_PARAMS), ca.SX.sym("L")
        rows, fn = load_rows(P, N, R, fl, load, L)
        # each fingertip's joint torques, affine in its force and torsion at a given state:
        # tau = g + A f + b tau_n (parameters per point: A (nq x 3, the object frame's
        # force), b, g), bounded by the actuators (none: infinite bounds)
        #: (the contact's index among the point contacts, the fingertip) of every fingertip
        self.tips = [(m.point_contacts.index(t), t) for t in m.fingertips]
        self.n_torque = sum(5 * int(t.finger.nq) for _, t in self.tips)
        tq = ca.SX.sym("tq", self.n_torque)
        Fl = ca.reshape(fl, LOAD_VARS, nc)
        F0, mu_t = load[5], load[4]
        taus, o = [], 0
        for j, t in self.tips:
            nq = int(t.finger.nq)
            A = ca.reshape(tq[o:o + 3 * nq], nq, 3)
            b, g = tq[o + 3 * nq:o + 4 * nq], tq[o + 4 * nq:o + 5 * nq]
            o += 5 * nq
            taus.append(g + F0 * (A @ Fl[0:3, j]) + b * (mu_t * F0 * fn[j] * Fl[3, j]))
        self._point = ca.Function("force_point", [fl, ca.vec(P), ca.vec(N), ca.vec(R), load, L,
                                                  tq],
                                  [ca.vertcat(*[e for e, _, _ in rows], *taus),
                                   load_cost(fl, fn)])
        self._lo = np.concatenate([np.full(int(e.numel()), a) for e, a, _ in rows])
        self._hi = np.concatenate([np.full(int(e.numel()), b) for e, _, b in rows])
        self._solvers: dict[int, ca.Function] = {}

    def prepare(self, k: int) -> None:
        """Build the NLP of ``k`` points now (outside a timed solve)."""
        self._solver(k)

    def _solver(self, k: int) -> ca.Function:
        if k not in self._solvers:
            nfl = self._point.size1_in(0)
            z = ca.MX.sym("z", nfl * k)
            geo = ca.MX.sym("geo", 3 * self.m.n_contacts * 2 + 9, k)
            tq = ca.MX.sym("tq", self.n_torque, k)
            q = ca.MX.sym("q", LOAD_PARAMS + 1)
            nc3 = 3 * self.m.n_contacts
            g, c = self._point.map(k)(ca.reshape(z, nfl, k), geo[0:nc3, :],
                                      geo[nc3:2 * nc3, :], geo[2 * nc3:, :],
                                      q[0:LOAD_PARAMS], q[LOAD_PARAMS], tq)
            self._solvers[k] = ca.nlpsol("forces", "ipopt",
                                         {"x": z, "p": ca.vertcat(ca.vec(geo), ca.vec(tq), q),
                                          "f": ca.sum2(c), "g": ca.vec(g)},
                                         FORCE_STAGE_OPTIONS)
        return self._solvers[k]

    def torque_params(self, Xall: FloatArray, prm: FloatArray, gravity: Any) -> FloatArray:
        """The torque rows' parameters at the states ``Xall`` (n_torque x points): per
        fingertip its ``A`` (``J_v^T + J_w^T [p - p_tip]x`` times the object's rotation:
        the torques of a force given in the object frame), ``b = J_w^T n`` (the torsion's)
        and ``g`` (its links' weight; ``gravity`` [m/s^2], palm frame)."""
        k = len(Xall)
        _, P, N, R, p_po = self.m.mapped("path", k)(Xall.T, prm)
        nc = self.m.n_contacts
        Pp = np.asarray(P).reshape(3, nc, k, order="F")
        Np = np.asarray(N).reshape(3, nc, k, order="F")
        Rp = np.asarray(R).reshape(3, 3, k, order="F")
        pp = np.asarray(p_po).reshape(3, k, order="F")
        out = np.zeros((self.n_torque, k))
        o = 0
        for j, t in self.tips:
            f, nq = t.finger, int(t.finger.nq)
            q = Xall[:, t.q_cols]
            J = f.tip_jacobians(q)  # (k, 6, nq)
            _, p_tip = f.tip_poses(q)
            g = f.gravity_torques(q, gravity) if f.mass > 0 else np.zeros((k, nq))
            for i in range(k):
                Ri = Rp[:, :, i]
                r = pp[:, i] + Ri @ Pp[:, j, i] - p_tip[i]
                skew = np.array([[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]])
                A = (J[i, :3].T + J[i, 3:].T @ skew) @ Ri
                out[o:o + 3 * nq, i] = A.ravel(order="F")
                out[o + 3 * nq:o + 4 * nq, i] = J[i, 3:].T @ (Ri @ Np[:, j, i])
                out[o + 4 * nq:o + 5 * nq, i] = g[i]
            o += 5 * nq
        return out

    def solve(self, Xall: FloatArray, prm: FloatArray, load: FloatArray, L: float,
              guess: FloatArray,
              torques: tuple[FloatArray, FloatArray, FloatArray] | None = None
              ) -> tuple[FloatArray | None, int]:
        """(the load variables, :data:`LOAD_VARS` per contact x point, or None when some
        point admits no forces; IPOPT's iterations) at the physical states ``Xall``
        (points x nx), from ``guess`` (same shape as the result). ``torques``: the torque
        rows' parameters (:meth:`torque_params`) and their lower and upper bounds (every
        fingertip's joints in turn; one column per point, or one for all) [N m]; None: no
        bounds."""
        k = len(Xall)
        nc = self.m.n_contacts
        _, P, N, R, _ = self.m.mapped("path", k)(Xall.T, prm)
        geo = np.vstack([np.asarray(P).reshape(3 * nc, k, order="F"),
                         np.asarray(N).reshape(3 * nc, k, order="F"),
                         np.asarray(R).reshape(9, k, order="F")])
        bound = load_bounds(nc, k)
        solver = self._solver(k)
        n_tau = sum(int(t.finger.nq) for _, t in self.tips)
        if torques is None:
            tq, lo_t, hi_t = (np.zeros((self.n_torque, k)), np.full(n_tau, -np.inf),
                              np.full(n_tau, np.inf))
        else:
            tq, lo_t, hi_t = torques
        if np.ndim(lo_t) == 1:  # the same bounds at every point
            lo_t, hi_t = np.tile(np.reshape(lo_t, (-1, 1)), k), np.tile(
                np.reshape(hi_t, (-1, 1)), k)
        lo = np.vstack([np.tile(np.reshape(self._lo, (-1, 1)), k), lo_t]).ravel(order="F")
        hi = np.vstack([np.tile(np.reshape(self._hi, (-1, 1)), k), hi_t]).ravel(order="F")
        res = solver(x0=np.clip(guess, -bound, bound).ravel(order="F"),
                     p=np.concatenate([geo.ravel(order="F"), tq.ravel(order="F"), load, [L]]),
                     lbx=-bound.ravel(order="F"), ubx=bound.ravel(order="F"),
                     lbg=lo, ubg=hi)
        st = solver.stats()
        g = np.asarray(res["g"]).ravel()
        with np.errstate(invalid="ignore"):
            viol = float(np.max(np.nan_to_num(np.maximum(lo - g, g - hi), nan=0.0),
                                initial=0.0))
        iterations = int(st["iter_count"])
        if not st["success"] or not np.isfinite(viol) or viol > MAX_VIOLATION:
            return None, iterations
        return np.asarray(res["x"]).reshape(LOAD_VARS * nc, k, order="F"), iterations
