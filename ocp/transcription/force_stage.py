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
        self._point = ca.Function("force_point", [fl, ca.vec(P), ca.vec(N), ca.vec(R), load, L],
                                  [ca.vertcat(*[e for e, _, _ in rows]), load_cost(fl, fn)])
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
            q = ca.MX.sym("q", LOAD_PARAMS + 1)
            nc3 = 3 * self.m.n_contacts
            g, c = self._point.map(k)(ca.reshape(z, nfl, k), geo[0:nc3, :],
                                      geo[nc3:2 * nc3, :], geo[2 * nc3:, :],
                                      q[0:LOAD_PARAMS], q[LOAD_PARAMS])
            self._solvers[k] = ca.nlpsol("forces", "ipopt",
                                         {"x": z, "p": ca.vertcat(ca.vec(geo), q),
                                          "f": ca.sum2(c), "g": ca.vec(g)},
                                         FORCE_STAGE_OPTIONS)
        return self._solvers[k]

    def solve(self, Xall: FloatArray, prm: FloatArray, load: FloatArray, L: float,
              guess: FloatArray) -> tuple[FloatArray | None, int]:
        """(the load variables, :data:`LOAD_VARS` per contact x point, or None when some
        point admits no forces; IPOPT's iterations) at the physical states ``Xall``
        (points x nx), from ``guess`` (same shape as the result)."""
        k = len(Xall)
        nc = self.m.n_contacts
        _, P, N, R, _ = self.m.mapped("path", k)(Xall.T, prm)
        geo = np.vstack([np.asarray(P).reshape(3 * nc, k, order="F"),
                         np.asarray(N).reshape(3 * nc, k, order="F"),
                         np.asarray(R).reshape(9, k, order="F")])
        bound = load_bounds(nc, k)
        solver = self._solver(k)
        res = solver(x0=np.clip(guess, -bound, bound).ravel(order="F"),
                     p=np.concatenate([geo.ravel(order="F"), load, [L]]),
                     lbx=-bound.ravel(order="F"), ubx=bound.ravel(order="F"),
                     lbg=np.tile(self._lo, k), ubg=np.tile(self._hi, k))
        st = solver.stats()
        g = np.asarray(res["g"]).ravel()
        viol = float(np.max(np.maximum(np.tile(self._lo, k) - g, g - np.tile(self._hi, k)),
                            initial=0.0))
        iterations = int(st["iter_count"])
        if not st["success"] or not np.isfinite(viol) or viol > MAX_VIOLATION:
            return None, iterations
        return np.asarray(res["x"]).reshape(LOAD_VARS * nc, k, order="F"), iterations
