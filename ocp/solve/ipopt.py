"""IPOPT as every planner here uses it: the shared options and the stop callback.

Every NLP of the project (ball on palm, fingers, the peers of the benchmark) is solved by
IPOPT through CasADi's ``nlpsol`` with :data:`IPOPT_OPTIONS`; :class:`StopCallback` ends a
solve at a deadline or an iteration budget and says which (a typed status, not an error).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np

from ocp.solution import Status
from ocp.transcription.nlp_blocks import BlockNLP

__all__ = [
    "FATROP_OPTIONS",
    "IPOPT_OPTIONS",
    "IPOPT_REALTIME_OPTIONS",
    "IPOPT_WARM_OPTIONS",
    "NLP",
    "SOLVERS",
    "StopCallback",
    "StructuredSolver",
    "ipopt_solver",
    "kkt_residuals",
    "realtime_solver",
    "warm_solver",
]

#: The NLP solvers a planner may choose (``ManipulationPlanner(solver=...)``).
SOLVERS = ("ipopt", "fatrop")

#: fatrop's settings (of the few its CasADi interface passes on: no acceptable level, no
#: barrier strategy, no warm-start options): IPOPT's tolerances and barrier start
#: (:data:`IPOPT_OPTIONS`), so that a converged fatrop point is one IPOPT would accept;
#: fatrop calls no iteration callback, so its iteration budget is fixed here.
FATROP_OPTIONS: dict[str, Any] = {
    "tol": 1e-6,
    "constr_viol_tol": 1e-10,
    "mu_init": 1e-3,
    "max_iter": 300,
    "print_level": 0,
}

#: IPOPT settings shared by every structure. Constraint violation (goals, dynamics, in
#: scaled units) must be tight; the optimality (dual) tolerance is looser because a pure
#: reorientation has a continuum of optimal plans (rotating the loop about the vertical
#: through the contact leaves the cost unchanged), where IPOPT's dual residual stalls.
IPOPT_OPTIONS: dict[str, Any] = {
    "ipopt.tol": 1e-6,
    "ipopt.constr_viol_tol": 1e-10,
    "ipopt.acceptable_tol": 1e-4,
    "ipopt.acceptable_iter": 10,
    "ipopt.acceptable_constr_viol_tol": 1e-9,
    # A monotone barrier from mu = 1e-3: the planners' initial guesses are near feasible
    # (simulated palm paths, inverse kinematics along them), so IPOPT's default start at
    # mu = 0.1 with the adaptive strategy first pushed them away. Measured on the full bench
    # suite (docs/performance.md): 1.57x fewer iterations in all, fewer in every family,
    # none lost, and the one-finger problem that hit the iteration limit now solves.
    "ipopt.mu_strategy": "monotone",
    "ipopt.mu_init": 1e-3,
    # MUMPS with METIS ordering. The automatic choice (7) picked an ordering whose
    # factorisations of the multi-finger KKT systems were ~25x slower and whose inertia
    # corrections tripled the iterations (three fingers turning a ball 90 deg: 75 iterations
    # and 23 s with the default, 22 iterations and 1.4 s with METIS; docs/performance.md).
    "ipopt.mumps_pivot_order": 5,
    # No MUMPS scaling of the KKT matrix (neither the permuting one nor the row/column one):
    # the NLPs are scaled by construction (states by the object's size, inputs by it and
    # the duration), and the scalings cost more than they saved. Full bench suite: every
    # family as fast or faster (finger families 12-23 %), no plan lost, iterations within
    # 2 %; experiment 1 (compiled) IPOPT 0.28 -> 0.24 s.
    "ipopt.mumps_permuting_scaling": 0,
    "ipopt.mumps_scaling": 0,
}

#: Added to :data:`IPOPT_OPTIONS` for a solve started from a previous primal-dual point
#: (a warm start with :class:`~ocp.transcription.collocation.NlpPoint`): take the given multipliers,
#: start the barrier near the previous solution's, and do not push the point away from
#: its active bounds. Measured on experiment 1 with its goal moved 2 mm: 6 iterations
#: instead of 14 (docs/performance.md). Pushes of 1e-6 (``AttemptOptions(warm_push=1e-6)``)
#: took fewer iterations on re-plans toward a moved goal or from a moved start (the Allegro
#: 24 -> 10), more from a plan's own optimum (3 -> 7): :func:`warm_solver`'s ``push``.
IPOPT_WARM_OPTIONS: dict[str, Any] = {
    "ipopt.warm_start_init_point": "yes",
    "ipopt.mu_init": 1e-6,
    "ipopt.warm_start_bound_push": 1e-9,
    "ipopt.warm_start_bound_frac": 1e-9,
    "ipopt.warm_start_slack_bound_push": 1e-9,
    "ipopt.warm_start_slack_bound_frac": 1e-9,
    "ipopt.warm_start_mult_bound_push": 1e-9,
}


class StopCallback(ca.Callback):
    """IPOPT iteration callback enforcing a per-solve deadline and iteration limit."""

    def __init__(self, nx: int, ng: int, np_: int) -> None:
        ca.Callback.__init__(self)
        self._sizes = {"x": nx, "lam_x": nx, "g": ng, "lam_g": ng, "lam_p": np_, "f": 1}
        self.deadline = math.inf
        self.max_iter = 1000
        self.iterations = 0
        self.reason: Status | None = None
        self.construct("dexroll_stop", {})

    def arm(self, deadline: float, max_iter: int) -> None:
        self.deadline, self.max_iter, self.iterations, self.reason = deadline, max_iter, 0, None

    def get_n_in(self) -> int:
        return int(ca.nlpsol_n_out())

    def get_n_out(self) -> int:
        return 1

    def get_name_in(self, i: int) -> str:
        return str(ca.nlpsol_out(i))

    def get_name_out(self, i: int) -> str:
        return "ret"

    def get_sparsity_in(self, i: int) -> ca.Sparsity:
        n = self._sizes.get(ca.nlpsol_out(i), 0)
        return ca.Sparsity.dense(n) if n else ca.Sparsity(0, 0)

    def eval(self, arg: list[Any]) -> list[int]:
        self.iterations += 1
        if time.perf_counter() > self.deadline:
            self.reason = Status.TIME_LIMIT
            return [1]
        if self.iterations > self.max_iter:
            self.reason = Status.ITERATION_LIMIT
            return [1]
        return [0]


@dataclass(kw_only=True)
class NLP(BlockNLP):
    """One grasp structure's NLP with its IPOPT solver: what the planner solves."""

    solver: ca.Function | StructuredSolver
    stop: StopCallback
    #: the options of ``solver`` (with the block derivatives): what the warm-start solver
    #: is built from, on first use
    options: dict[str, Any]
    #: fingerprint of this NLP (structure, grid, fingers' models), for warm starts
    fingerprint: str
    warm_solver: ca.Function | StructuredSolver | None = None
    #: the warm-start solvers with other pushes than :data:`IPOPT_WARM_OPTIONS`', by (push,
    #: ``compiled``) (:func:`warm_solver`), made on first use (again once compiled)
    warm_solvers: dict[tuple[float, bool], ca.Function | StructuredSolver] = \
        field(default_factory=dict)
    #: the real-time solvers (:func:`realtime_solver`), by (Gauss-Newton, ``compiled``,
    #: push)
    realtime_solvers: dict[tuple[bool, bool, float | None], ca.Function] = \
        field(default_factory=dict)
    #: whether ``solver`` runs compiled code (``compile_dir``)
    compiled: bool = False
    #: the solver chosen (:data:`SOLVERS`): "fatrop" runs IPOPT as its fallback
    solver_name: str = "ipopt"
    #: (the solver it was made from, (w, p, lam_g, lam_x) -> (g, the Lagrangian's
    #: gradient)): :func:`kkt_residuals`' function, made on first use (again when a
    #: compiled solver replaces the virtual machine's)
    kkt: tuple[Any, ca.Function] | None = None


def _kkt_function(ipopt: ca.Function, nlp: NLP) -> ca.Function:
    """(w, p, lam_g, lam_x) -> (g, grad f + J^T lam_g + lam_x) from the IPOPT solver's own
    functions (compiled when it is): the block-assembled constraint Jacobian and the
    objective's gradient. A reverse sweep through the oracle instead (no Jacobian) cost
    as much as the Jacobian on experiment 1 (docs/performance.md)."""
    w = ca.MX.sym("w", nlp.pack.nnz_out(0))
    p = ca.MX.sym("p", nlp.params.size)
    lam_g = ca.MX.sym("lam_g", len(nlp.lbg))
    lam_x = ca.MX.sym("lam_x", w.numel())
    g, jac = ipopt.get_function("nlp_jac_g")(w, p)
    grad = ipopt.get_function("nlp_grad_f")(w, p)[1]
    return ca.Function("kkt_residuals", [w, p, lam_g, lam_x],
                       [g, grad + ca.mtimes(jac.T, lam_g) + lam_x])


def kkt_residuals(nlp: NLP, w: np.ndarray, p: np.ndarray, lam_g: np.ndarray,
                  lam_x: np.ndarray, lbx: np.ndarray, ubx: np.ndarray
                  ) -> tuple[float, float]:
    """How far a primal-dual point of ``nlp`` is from a KKT point, in the NLP's units:
    (primal infeasibility: the largest violation of the rows' bounds ``lbg``/``ubg`` and
    of the variables' ``lbx``/``ubx``; dual infeasibility: the largest entry of
    ``grad f + J^T lam_g + lam_x``, CasADi's sign convention of the multipliers). The
    point a solver returns, whatever stopped it (an iteration budget, a deadline)."""
    ipopt = nlp.solver.fallback if isinstance(nlp.solver, StructuredSolver) else nlp.solver
    if nlp.kkt is None or nlp.kkt[0] is not ipopt:
        nlp.kkt = (ipopt, _kkt_function(ipopt, nlp))
    g, grad = (np.asarray(a).ravel() for a in nlp.kkt[1](w, p, lam_g, lam_x))
    primal = max(float(np.max(np.maximum(nlp.lbg - g, g - nlp.ubg), initial=0.0)),
                 float(np.max(np.maximum(lbx - w, w - ubx), initial=0.0)))
    return primal, float(np.max(np.abs(grad), initial=0.0))


class StructuredSolver:
    """The solver of a stage-ordered NLP, called as an ``nlpsol`` is (``solver(x0=..., ...)``,
    ``solver.stats()``): the copies of the intervals' ends freed of their bounds (the
    gap-closing rows tie them to the bounded variables; bounded copies would make active
    bounds linearly dependent), fatrop first when there is one, IPOPT (``fallback``) when
    fatrop does not succeed. ``stats()["solver"]`` says which solver's point is returned;
    ``iter_count`` counts both solvers' iterations."""

    def __init__(self, fatrop: ca.Function | None, fallback: ca.Function,
                 copies: Any) -> None:
        self.fatrop, self.fallback, self.copies = fatrop, fallback, copies
        self._stats: dict[str, Any] = {}

    def __call__(self, **kw: Any) -> dict[str, Any]:
        lbx, ubx = (np.array(kw[k], dtype=float, copy=True) for k in ("lbx", "ubx"))
        lbx[self.copies], ubx[self.copies] = -np.inf, np.inf
        kw = {**kw, "lbx": lbx, "ubx": ubx}
        iters, note = 0, ""
        if self.fatrop is not None:
            res = self.fatrop(**{k: v for k, v in kw.items() if k not in ("lam_x0",)})
            st = dict(self.fatrop.stats())
            if st.get("success"):
                self._stats = {**st, "return_status": "Solve_Succeeded", "solver": "fatrop",
                               "fatrop_status": st["return_status"]}
                return dict(res)
            iters, note = int(st.get("iter_count", 0)), f" (fatrop: {st['return_status']})"
        res = self.fallback(**kw)
        st = dict(self.fallback.stats())
        self._stats = {**st, "iter_count": iters + int(st["iter_count"]),
                       "solver": "ipopt" + note}
        return dict(res)

    def stats(self) -> dict[str, Any]:
        return self._stats


def _fatrop(block: BlockNLP, name: str, warm: bool = False) -> ca.Function:
    """fatrop on a stage-ordered block NLP, its stages given (``structure_detection``
    'manual': the layout knows them; 'auto' finds the same, measured in
    benchmarks/structured_solve.py). fatrop's CasADi interface takes no ``jac_g`` or
    ``hess_lag``: it differentiates the oracle itself, here expanded to SX (``expand``:
    seconds more to build, its derivatives' evaluations ~4x faster than CasADi's MX
    derivatives of the mapped blocks; docs/performance.md)."""
    assert block.stages is not None
    opts = {**FATROP_OPTIONS, **({"mu_init": 1e-6} if warm else {})}
    return ca.nlpsol(name, "fatrop", block.oracle,
                     {"structure_detection": "manual", "N": block.stages["N"],
                      "nx": block.stages["nx"], "nu": block.stages["nu"],
                      "ng": block.stages["ng"], "fatrop": opts, "print_time": False,
                      "error_on_fail": False, "expand": True})


def warm_solver(nlp: NLP, push: float | None = None) -> ca.Function | StructuredSolver:
    """The solver of a warm start from a previous primal-dual point of ``nlp``: IPOPT with
    :data:`IPOPT_WARM_OPTIONS` (behind fatrop, warm-barrier, when the NLP's solver is
    fatrop); ``push``: how far the point and its bound multipliers are pushed into the
    interior instead of the options' 1e-9 (IPOPT's ``warm_start_*_push`` and ``_frac``)."""
    opts = dict(IPOPT_WARM_OPTIONS)
    if push is not None:
        opts.update({k: float(push) for k in opts if k.endswith(("_push", "_frac"))})
    ipopt = ca.nlpsol("manipulation_warm", "ipopt", nlp.oracle, {**nlp.options, **opts})
    if nlp.stages is None:
        return ipopt
    fatrop = _fatrop(nlp, "manipulation_warm_fatrop", True) \
        if nlp.solver_name == "fatrop" else None
    return StructuredSolver(fatrop, ipopt, nlp.copies)


#: Added to :data:`IPOPT_WARM_OPTIONS` for a controller's window solved within an iteration
#: or two from the previous window's point (:func:`realtime_solver`): MUMPS with AMD
#: ordering. METIS (:data:`IPOPT_OPTIONS`' choice for whole plans, whose KKT systems it
#: orders far better) cost 8 of experiment 2's 16 ms per call on a 1 100-variable window,
#: every call (the ordering is redone each time): 16.0 -> 7.6 ms, experiment 1 7.7 -> 3.9,
#: the Allegro turn 30 -> 17 (docs/control.md).
IPOPT_REALTIME_OPTIONS: dict[str, Any] = {"ipopt.mumps_pivot_order": 0}


def realtime_solver(nlp: NLP, gauss_newton: bool = False, push: float | None = None
                    ) -> ca.Function:
    """IPOPT for a warm window of ``nlp`` at a controller's rate (made on first use,
    cached on ``nlp``): :data:`IPOPT_WARM_OPTIONS` and :data:`IPOPT_REALTIME_OPTIONS`;
    ``gauss_newton``: the Hessian of the objective alone (the constraints' curvature
    dropped: positive semidefinite for a tracking objective, so IPOPT needs no inertia
    correction, one factorisation per iteration; the steps converge linearly, not
    quadratically); ``push``: as :func:`warm_solver`'s."""
    key = (gauss_newton, nlp.compiled, push)
    if key not in nlp.realtime_solvers:
        opts = {**nlp.options, **IPOPT_WARM_OPTIONS, **IPOPT_REALTIME_OPTIONS}
        if push is not None:
            opts.update({k: float(push) for k in IPOPT_WARM_OPTIONS
                         if k.endswith(("_push", "_frac"))})
        if gauss_newton:
            H = opts["hess_lag"]
            x, p = ca.MX.sym("x", H.size1_in(0)), ca.MX.sym("p", H.size1_in(1))
            lam_f, lam_g = ca.MX.sym("lam_f"), ca.MX.sym("lam_g", H.size1_in(3))
            opts["hess_lag"] = ca.Function(
                "nlp_hess_l", [x, p, lam_f, lam_g],
                [H(x, p, lam_f, ca.DM.zeros(H.size1_in(3)))],
                ["x", "p", "lam_f", "lam_g"], ["triu_hess_gamma_x_x"])
        nlp.realtime_solvers[key] = ca.nlpsol(
            "manipulation_realtime" + ("_gn" if gauss_newton else ""), "ipopt", nlp.oracle,
            opts)
    return nlp.realtime_solvers[key]


def ipopt_solver(block: BlockNLP, fingerprint: str, compile_dir: Path | None = None,
                 solver: str = "ipopt") -> NLP:
    """IPOPT (:data:`IPOPT_OPTIONS`, a :class:`StopCallback`) on a block NLP, its functions
    compiled and cached in ``compile_dir`` when given (:mod:`ocp.solve.compiled`; the virtual
    machine when there is no compiler). A stage-ordered NLP (``block.stages``) is solved by
    a :class:`StructuredSolver`: with ``solver="fatrop"``, fatrop first and this IPOPT as
    its fallback (not compiled: the compiled solver takes the kind-ordered NLP's path)."""
    if solver not in SOLVERS:
        raise ValueError(f"unknown solver {solver!r}: one of {SOLVERS}")
    if solver == "fatrop" and block.stages is None:
        raise ValueError("fatrop needs the stage-ordered NLP (stage_order=True)")
    t0 = time.perf_counter()
    nw, ng = block.pack.nnz_out(0), len(block.lbg)
    stop = StopCallback(nw, ng, block.params.size)
    options = {"ipopt.print_level": 0, "ipopt.sb": "yes", "print_time": False,
               "ipopt.max_iter": 100_000, **IPOPT_OPTIONS, "iteration_callback": stop,
               "error_on_fail": False, "jac_g": block.jac_g, "hess_lag": block.hess_lag}
    ipopt = ca.nlpsol("manipulation", "ipopt", block.oracle, options)
    compiled = False
    structured: Any = None
    if block.stages is not None:
        structured = StructuredSolver(_fatrop(block, "manipulation_fatrop")
                                      if solver == "fatrop" else None, ipopt, block.copies)
    elif compile_dir is not None:
        from ocp.solve.compiled import compiled_block_solver

        try:
            ipopt, options = compiled_block_solver(block.oracle, options, fingerprint,
                                                   compile_dir)
            compiled = True
        except RuntimeError:  # no compiler, or it failed: the virtual machine solves
            pass
    parts = {f.name: getattr(block, f.name) for f in fields(BlockNLP)}
    parts["build_time"] = block.build_time + time.perf_counter() - t0
    return NLP(**parts, solver=structured if structured is not None else ipopt, stop=stop,
               options=options, fingerprint=fingerprint, compiled=compiled,
               solver_name=solver)
