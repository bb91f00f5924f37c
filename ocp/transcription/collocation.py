"""Hermite-Simpson direct collocation (separated form), and its interpolants.

Why Hermite-Simpson rather than Legendre/Radau collocation of higher degree:

* one collocation point per interval (the midpoint) keeps every path constraint of later
  planners (friction cone, joint limits, closure) at 2N+1 points with a simple, very sparse
  pattern; IPOPT's factorisations stay cheap at N = 20..100;
* the state is a C1 cubic (Hermite) and the input a continuous quadratic, so joint-rate and
  contact-velocity commands are continuous, as a finger controller wants them;
* 4th-order accurate, which the certificate confirms by re-integration: at N = 50 the
  re-integrated states of our problems agree with the NLP to ~1e-8.

Time is split into segments (between via-points) so that a via-point falls exactly on a
node whatever its time; each segment's duration is an NLP parameter, so one NLP serves
every request with the same structure.

Variables are scaled: the physical state is ``x = Sx * x~`` and the input ``u = Su * u~``
with scale vectors that may depend on parameters (e.g. the object radius).
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np
from numpy.typing import NDArray

__all__ = ["HermiteInterpolant", "HermiteSimpson", "NlpPoint", "PlannedForces", "WarmStart",
           "hermite_simpson_defects", "left_input_columns", "node_inputs", "node_times",
           "quadratic_input", "reintegrate", "reintegrator", "rk4_step", "target_residuals"]


def left_input_columns(segments: tuple[int, ...], continuous: bool = False) -> list[int]:
    """Column of the node inputs holding the input at the start of each interval: a node
    between two segments has two input columns (incoming and outgoing), so each segment
    shifts the columns after it by one; with ``continuous`` inputs (smooth timing) every
    node has one input column, interval k starts at column k."""
    if continuous:
        return list(range(int(sum(segments))))
    return [k + s for s, n0 in enumerate(segments)
            for k in range(sum(segments[:s]), sum(segments[:s]) + n0)]


def node_inputs(u_of_t: Any, t_nodes: NDArray[np.float64], left_cols: list[int],
                right_cols: list[int], n_cols: int) -> NDArray[np.float64]:
    """The inputs at the grid's node columns (rows): each interval's start column from
    ``u_of_t`` (times -> rows) just after its start node, its end column just before its
    end node, so that an input that jumps at a via-point node gets both sides."""
    eps = 1e-9 * float(t_nodes[-1])
    left = np.asarray(u_of_t(t_nodes[:-1] + eps))
    U = np.zeros((n_cols, left.shape[1]))
    U[left_cols] = left
    U[right_cols] = u_of_t(t_nodes[1:] - eps)
    return U


def rk4_step(f: Any, x: Any, u0: Any, um: Any, u1: Any, h: Any) -> Any:
    """One classic Runge-Kutta step of x' = f(x, u) over h, the input u0 at the start, um
    at the midpoint, u1 at the end (symbolic or numeric)."""
    k1 = f(x, u0)
    k2 = f(x + h / 2 * k1, um)
    k3 = f(x + h / 2 * k2, um)
    k4 = f(x + h * k3, u1)
    return x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)


def hermite_simpson_defects(xk: Any, xm: Any, xk1: Any, f0: Any, fm: Any, f1: Any,
                            h: Any) -> Any:
    """One interval's Hermite-Simpson defects (2 nx rows): with f0, fm, f1 the state's
    derivatives at its start, midpoint and end,
    x_m = (x_k + x_k+1)/2 + h/8 (f0 - f1) and x_k+1 - x_k = h/6 (f0 + 4 fm + f1)."""
    return ca.vertcat(xm - (xk + xk1) / 2 - h / 8 * (f0 - f1),
                      xk1 - xk - h / 6 * (f0 + 4 * fm + f1))


def target_residuals(x_node: Any, value: Any, mask: tuple[bool, ...], x_scale: Any,
                     periodic: tuple[bool, ...]) -> list[Any]:
    """Residuals of a node's scaled state ``x_node`` against the physical ``value`` on the
    coordinates ``mask`` selects: ``2 sin(d / 2)`` for a periodic coordinate (zero iff equal
    modulo 2 pi, with a non-zero slope there), else ``x_node - value / x_scale``."""
    return [2 * ca.sin((x_node[i] - value[i]) / 2) if periodic[i] else
            x_node[i] - value[i] / x_scale[i] for i, on in enumerate(mask) if on]


@dataclass(frozen=True)
class NlpPoint:
    """IPOPT's primal-dual point at a plan, in the NLP's own (scaled) order: the decision
    vector ``w``, the multipliers of the variable bounds ``lam_x`` and of the constraints
    ``lam_g``; ``nlp`` is the fingerprint of the NLP they belong to (structure, grid,
    models). A warm start that carries it starts IPOPT from the previous primal-dual point
    when the new plan has the same NLP, which is what makes an interior-point method
    converge in a few iterations (from the primal point alone it needs about as many as
    from a cold guess)."""

    nlp: str
    w: NDArray[np.float64]
    lam_x: NDArray[np.float64]
    lam_g: NDArray[np.float64]

    def fits(self, nlp: str, n_x: int, n_g: int) -> bool:
        """Whether this point belongs to the NLP ``nlp`` with ``n_x`` variables and ``n_g``
        constraints."""
        return self.nlp == nlp and len(self.lam_x) == n_x and len(self.lam_g) == n_g


@dataclass(frozen=True)
class WarmStart:
    """A previous plan as an initial guess: its states ``x`` (k, nx) and inputs ``u``
    (k, nu), physical units and the planner's state and input layout, at increasing times
    ``t`` (k,) [s] from 0 (a plan's collocation points; any samples will do).

    A plan of another duration is stretched in time to the new one, and its inputs (all of
    them rates) are scaled by the inverse ratio, so that states and inputs stay consistent.
    The planner replaces the first state by the problem's own initial state. ``nlp_point``
    (optional, :class:`NlpPoint`: IPOPT's primal-dual point at that plan) is used when it
    belongs to the new plan's NLP and ignored otherwise.
    """

    t: NDArray[np.float64]
    x: NDArray[np.float64]
    u: NDArray[np.float64]
    nlp_point: NlpPoint | None = None

    @staticmethod
    def of(t: Any, x: Any, u: Any, nlp_point: NlpPoint | None = None) -> WarmStart:
        return WarmStart(np.asarray(t, dtype=float), np.atleast_2d(np.asarray(x, dtype=float)),
                         np.atleast_2d(np.asarray(u, dtype=float)), nlp_point)

    def errors(self, name: str, nx: int, nu: int) -> list[tuple[str, str]]:
        """(field, reason) pairs; empty when this warm start fits states of size ``nx`` and
        inputs of size ``nu``. Fields are ``name.t``, ``name.x``, ``name.u``."""
        errs: list[tuple[str, str]] = []
        t, x, u = self.t, self.x, self.u
        if t.ndim != 1 or len(t) < 2:
            return [(f"{name}.t", "must be a list of at least 2 sample times")]
        if not np.all(np.isfinite(t)) or abs(t[0]) > 1e-12 * max(1.0, abs(t[-1])) \
                or np.any(np.diff(t) <= 0):
            errs.append((f"{name}.t", "must start at 0 and increase strictly (finite "
                                      "values)"))
        for key, a, n, what in (("x", x, nx, "states"), ("u", u, nu, "inputs")):
            if a.ndim != 2 or a.shape != (len(t), n):
                errs.append((f"{name}.{key}", f"must have one row of {n} {what} per sample "
                                              f"time ({len(t)} x {n}), got "
                                              f"{' x '.join(map(str, a.shape))}"))
            elif not np.all(np.isfinite(a)):
                errs.append((f"{name}.{key}", "must be finite"))
        if self.nlp_point is not None:
            for key in ("w", "lam_x", "lam_g"):
                a = np.asarray(getattr(self.nlp_point, key))
                if a.ndim != 1 or not np.all(np.isfinite(a)):
                    errs.append((f"{name}.nlp_point.{key}", "must be a list of finite "
                                                            "numbers"))
        return errs

    def nlp_point_for(self, nlp: str, n_x: int, n_g: int) -> NlpPoint | None:
        """The primal-dual point if it belongs to the NLP ``nlp`` with ``n_x`` variables and
        ``n_g`` constraints, else None."""
        m = self.nlp_point
        return m if m is not None and m.fits(nlp, n_x, n_g) else None

    def on_grid(self, t_nodes: NDArray[np.float64], left_cols: list[int],
                right_cols: list[int], n_u_cols: int) -> tuple[
                    NDArray[np.float64], NDArray[np.float64], NDArray[np.float64],
                    NDArray[np.float64]]:
        """(X at the nodes, X at the midpoints, U at the node columns, U at the midpoints),
        interpolated linearly after stretching to the grid's duration."""
        ratio = float(t_nodes[-1]) / float(self.t[-1])
        t = self.t * ratio
        u = self.u / ratio

        def at(values: NDArray[np.float64], ts: NDArray[np.float64]) -> NDArray[np.float64]:
            return np.column_stack([np.interp(ts, t, values[:, j])
                                    for j in range(values.shape[1])])

        tm = (t_nodes[:-1] + t_nodes[1:]) / 2
        U = node_inputs(lambda ts: at(u, ts), t_nodes, left_cols, right_cols, n_u_cols)
        return at(self.x, t_nodes), at(self.x, tm), U, at(u, tm)


@dataclass
class HermiteSimpson:
    """Symbolic decision variables and defect constraints for one problem structure.

    ``segments`` gives the number of intervals in each segment; node k of the whole grid
    is shared by the segments it joins. ``continuous``: one input per node, also at a
    via-point (the smooth timing: every velocity continuous); else a via-point node has the
    input arriving and the one leaving (the paper's piecewise timing).
    """

    nx: int
    nu: int
    segments: tuple[int, ...]
    continuous: bool = False

    def __post_init__(self) -> None:
        n = self.n_intervals
        self.X = ca.SX.sym("X", self.nx, n + 1)  # scaled states at nodes
        self.Xm = ca.SX.sym("Xm", self.nx, n)  # scaled states at midpoints
        # Inputs at nodes, per segment: with the paper's timing a via-point node has an
        # incoming and an outgoing input, since the min-effort optimum turns a corner there.
        self.U = ca.SX.sym("U", self.nu, self.n_input_cols)
        self.Um = ca.SX.sym("Um", self.nu, n)  # scaled inputs at midpoints

    @property
    def n_intervals(self) -> int:
        return int(sum(self.segments))

    @property
    def n_input_cols(self) -> int:
        """Columns of U: one per node, plus one per via-point unless ``continuous``."""
        n = self.n_intervals
        return n + 1 if self.continuous else n + len(self.segments)

    @property
    def left_cols(self) -> list[int]:
        """Column of U holding the input at the start of each interval."""
        return left_input_columns(self.segments, self.continuous)

    @property
    def right_cols(self) -> list[int]:
        """Column of U holding the input at the end of each interval."""
        return [c + 1 for c in self.left_cols]

    @property
    def segment_end_nodes(self) -> list[int]:
        """Node index at the end of each segment (the last one is the final node)."""
        return [int(k) for k in np.cumsum(self.segments)]

    @property
    def w(self) -> ca.SX:
        """The decision vector."""
        return ca.vertcat(ca.vec(self.X), ca.vec(self.Xm), ca.vec(self.U), ca.vec(self.Um))

    def unpack(self) -> ca.Function:
        """Function w -> (X, Xm, U, Um), so no caller unpacks by stride arithmetic."""
        return ca.Function("unpack", [self.w], [self.X, self.Xm, self.U, self.Um],
                           ["w"], ["X", "Xm", "U", "Um"])

    def pack(self) -> ca.Function:
        """Function (X, Xm, U, Um) -> w."""
        return ca.Function("pack", [self.X, self.Xm, self.U, self.Um], [self.w],
                           ["X", "Xm", "U", "Um"], ["w"])

    def steps(self, segment_durations: ca.SX) -> list[ca.SX]:
        """Interval lengths h_k [s] from the (symbolic) segment durations."""
        hs: list[ca.SX] = []
        for s, n in enumerate(self.segments):
            hs += [segment_durations[s] / n] * n
        return hs

    def defects(self, f: ca.Function, p: ca.SX, x_scale: ca.SX, u_scale: ca.SX,
                segment_durations: ca.SX) -> ca.SX:
        """Hermite-Simpson defects (scaled), 2*nx per interval.

        ``f(x, u, p)`` is the physical dynamics. With f_k, f_m, f_k+1 the derivatives at
        the nodes and the midpoint:
        x_m = (x_k + x_k+1)/2 + h/8 (f_k - f_k+1),  x_k+1 - x_k = h/6 (f_k + 4 f_m + f_k+1).
        """
        inv_sx = 1.0 / x_scale
        out = []
        lc, rc = self.left_cols, self.right_cols
        f_right = None
        for k, h in enumerate(self.steps(segment_durations)):
            xk, xk1 = self.X[:, k], self.X[:, k + 1]
            # f at the shared node is reused unless the input jumps there (via-point)
            f0 = f_right if f_right is not None and lc[k] == rc[k - 1] else \
                inv_sx * f(x_scale * xk, u_scale * self.U[:, lc[k]], p)
            f1 = inv_sx * f(x_scale * xk1, u_scale * self.U[:, rc[k]], p)
            fm = inv_sx * f(x_scale * self.Xm[:, k], u_scale * self.Um[:, k], p)
            out.append(hermite_simpson_defects(xk, self.Xm[:, k], xk1, f0, fm, f1, h))
            f_right = f1
        return ca.vertcat(*out)

    def simpson(self, integrand: ca.Function, segment_durations: ca.SX) -> ca.SX:
        """Simpson quadrature of ``integrand(x~, u~)`` over the horizon."""
        total = 0
        lc, rc = self.left_cols, self.right_cols
        for k, h in enumerate(self.steps(segment_durations)):
            total += h / 6 * (integrand(self.X[:, k], self.U[:, lc[k]])
                              + 4 * integrand(self.Xm[:, k], self.Um[:, k])
                              + integrand(self.X[:, k + 1], self.U[:, rc[k]]))
        return total


def node_times(segments: tuple[int, ...], boundaries: NDArray[np.float64]
               ) -> NDArray[np.float64]:
    """Times [s] of the grid's nodes: each segment (between consecutive ``boundaries``)
    split evenly into its number of intervals."""
    pieces = [np.linspace(boundaries[s], boundaries[s + 1], n + 1)[:-1]
              for s, n in enumerate(segments)]
    return np.concatenate([*pieces, [boundaries[-1]]])


def _basis(s: NDArray[np.float64], h: NDArray[np.float64], order: int
           ) -> tuple[NDArray[np.float64], ...]:
    """The cubic Hermite basis (h00, h10 h, h01, h11 h) at normalised times s, or its
    ``order``-th time derivative (d/dt = d/ds / h)."""
    if order == 0:
        return 2 * s**3 - 3 * s**2 + 1, (s**3 - 2 * s**2 + s) * h, -2 * s**3 + 3 * s**2, \
            (s**3 - s**2) * h
    if order == 1:
        return (6 * s**2 - 6 * s) / h, 3 * s**2 - 4 * s + 1, (6 * s - 6 * s**2) / h, \
            3 * s**2 - 2 * s
    return (12 * s - 6) / h**2, (6 * s - 4) / h, (6 - 12 * s) / h**2, (6 * s - 2) / h


@dataclass(frozen=True)
class HermiteInterpolant:
    """A plan as it is returned: the states on each interval the cubic Hermite polynomial
    through the node states ``X`` with the node rates ``F0`` (interval k's start, from its
    outgoing input) and ``F1`` (its end, from its incoming input); the inputs the quadratic
    through (U0, Um, U1) of the interval.

    The states are C1 wherever the input is continuous; at a via-point node, where the
    incoming and outgoing inputs differ, the state is continuous and its rate has two
    one-sided values (``side``). The state's rate and acceleration are the polynomial's own
    derivatives (at the collocation points its rate equals the dynamics to the NLP's
    tolerance; between them it is what a controller following the samples executes).
    """

    t_nodes: NDArray[np.float64]
    X: NDArray[np.float64]
    F0: NDArray[np.float64]
    F1: NDArray[np.float64]
    U0: NDArray[np.float64]
    Um: NDArray[np.float64]
    U1: NDArray[np.float64]
    #: Each interval's end state where it is not the next node's (a plan whose contacts
    #: change chart at a node: the interval ending there ends in its own chart,
    #: :class:`~ocp.transcription.chart_switch.PlanCharts`); None: ``X[1:]``.
    X1: NDArray[np.float64] | None = None

    @property
    def X_end(self) -> NDArray[np.float64]:
        """Each interval's end state (``X[1:]``, or :attr:`X1`)."""
        return self.X[1:] if self.X1 is None else self.X1

    @property
    def duration(self) -> float:
        return float(self.t_nodes[-1] - self.t_nodes[0])

    def locate(self, t: NDArray[np.float64], side: str = "right"
               ) -> tuple[NDArray[np.intp], NDArray[np.float64]]:
        """(interval, normalised time s in [0, 1]) of each time; a time on a node belongs to
        the interval after it (``side="right"``) or before it (``"left"``)."""
        t = np.asarray(t, dtype=float)
        n = len(self.t_nodes) - 1
        if side == "right":
            k = np.clip(np.searchsorted(self.t_nodes, t, side="right") - 1, 0, n - 1)
        else:
            k = np.clip(np.searchsorted(self.t_nodes, t, side="left") - 1, 0, n - 1)
        h = self.t_nodes[k + 1] - self.t_nodes[k]
        return k, (t - self.t_nodes[k]) / h

    def on_intervals(self, k: NDArray[np.intp], s: NDArray[np.float64], order: int = 0
                     ) -> NDArray[np.float64]:
        """The states (``order`` 0), their rates (1) or accelerations (2) at normalised
        times s of intervals k, rows."""
        h = (self.t_nodes[k + 1] - self.t_nodes[k])[:, None]
        b = _basis(np.asarray(s, dtype=float)[:, None], h, order)
        return b[0] * self.X[k] + b[1] * self.F0[k] + b[2] * self.X_end[k] + b[3] * self.F1[k]

    def inputs_on_intervals(self, k: NDArray[np.intp], s: NDArray[np.float64]
                            ) -> NDArray[np.float64]:
        s = np.asarray(s, dtype=float)[:, None]
        return quadratic_input(s, self.U0[k], self.Um[k], self.U1[k])

    def __call__(self, t: NDArray[np.float64], order: int = 0, side: str = "right"
                 ) -> NDArray[np.float64]:
        """The states (or their ``order``-th time derivative) at times t, rows."""
        k, s = self.locate(t, side)
        return self.on_intervals(k, s, order)

    def inputs(self, t: NDArray[np.float64], side: str = "right") -> NDArray[np.float64]:
        """The inputs at times t, rows."""
        k, s = self.locate(t, side)
        return self.inputs_on_intervals(k, s)


def quadratic_input(s: Any, u0: Any, um: Any, u1: Any) -> Any:
    """The collocation input at normalised time s in [0, 1] of an interval."""
    return 2 * (s - 0.5) * (s - 1) * u0 - 4 * s * (s - 1) * um + 2 * s * (s - 0.5) * u1


def reintegrator(dynamics: ca.Function, nx: int, nu: int, n_params: int, n_sub: int
                 ) -> ca.Function:
    """CVODES over one interval in normalised time s in [0, 1], output at n_sub points.

    ``dynamics(x, u, params)``; the integrator's parameters are (u_k, u_m, u_k+1, h,
    params): the input is the interval's collocation quadratic.
    """
    s = ca.SX.sym("s")
    x = ca.SX.sym("x", nx)
    q = ca.SX.sym("q", 3 * nu + 1 + n_params)
    u0, um, u1 = q[0:nu], q[nu:2 * nu], q[2 * nu:3 * nu]
    h, params = q[3 * nu], q[3 * nu + 1:]
    ode = h * dynamics(x, quadratic_input(s, u0, um, u1), params)
    grid = list(np.linspace(0.0, 1.0, n_sub + 1)[1:])
    return ca.integrator("reintegrate", "cvodes", {"x": x, "p": q, "t": s, "ode": ode},
                         0.0, grid, {"abstol": 1e-13, "reltol": 1e-11,
                                                  "max_num_steps": 100_000})


#: Chained re-integrators, most recently used last: (id of the interval integrator,
#: intervals) -> (the integrator, kept alive so that its id is not reused; the chain).
_CHAINS: OrderedDict[tuple[int, int], tuple[ca.Function, ca.Function]] = OrderedDict()
#: At most this many chains are kept (planners come and go in a long-running service).
_MAX_CHAINS = 64


def _chain(F: ca.Function, n: int) -> ca.Function:
    """``F`` over n consecutive intervals as one CasADi call (``mapaccum``: each interval
    starts where the previous one ended): (x0, q (nq x n)) -> (node states 1..n, samples)."""
    key = (id(F), n)
    if key in _CHAINS:
        _CHAINS.move_to_end(key)
    else:
        x = ca.MX.sym("x", F.size1_in("x0"))
        q = ca.MX.sym("q", F.size1_in("p"))
        xs = F(x0=x, p=q)["xf"]
        step = ca.Function("reintegrate_step", [x, q], [xs[:, -1], xs])
        _CHAINS[key] = (F, step.mapaccum("reintegrate_chain", n, [0], [0]))
        while len(_CHAINS) > _MAX_CHAINS:
            _CHAINS.popitem(last=False)
    return _CHAINS[key][1]


def reintegrate(F: ca.Function, x0: NDArray[np.float64], t_nodes: NDArray[np.float64],
                U0: NDArray[np.float64], Um: NDArray[np.float64], U1: NDArray[np.float64],
                params: NDArray[np.float64], n_sub: int
                ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Integrate the collocation inputs from ``x0`` over the whole horizon, never reset.

    Returns (states at the nodes, states at the n_sub samples per interval preceded by
    x0, inputs at those samples).
    """
    x = np.asarray(x0, dtype=float)
    n = len(t_nodes) - 1
    h = np.diff(t_nodes)[:, None]
    q = np.hstack([U0[:n], Um[:n], U1[:n], h, np.tile(params, (n, 1))])
    nodes, samples = _chain(F, n)(x, q.T)
    s = np.linspace(0.0, 1.0, n_sub + 1)[1:][None, :, None]
    ws = quadratic_input(s, U0[:n, None, :], Um[:n, None, :], U1[:n, None, :])
    return (np.vstack([x, np.asarray(nodes).T]), np.vstack([x, np.asarray(samples).T]),
            np.vstack([U0[:1], ws.reshape(n * n_sub, -1)]))


@dataclass(frozen=True)
class PlannedForces:
    """Every contact's planned force at the collocation points: ``f_nodes`` (n+1 x nc x 3)
    and ``f_mid`` (n x nc x 3) [N], palm frame, the force each contact's body exerts on the
    object; ``tau_nodes``, ``tau_mid`` [N m] the torsion about the object's outward normal.
    Between the points, on each interval, the quadratic through node, midpoint and node,
    like the inputs (:meth:`on_intervals`): continuous (the NLP has one force per point).
    ``gravity`` [m/s^2]: the load's gravity, palm frame (the fingers' own weight in their
    joint torques, when their models have inertias)."""

    f_nodes: NDArray[np.float64]
    f_mid: NDArray[np.float64]
    tau_nodes: NDArray[np.float64]
    tau_mid: NDArray[np.float64]
    gravity: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def on_intervals(self, k: NDArray[np.intp], s: NDArray[np.float64]
                     ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """(forces (len x nc x 3), torsions (len x nc)) at normalised times s of intervals k."""
        s = np.asarray(s, dtype=float)
        b0, bm, b1 = 2 * (s - 0.5) * (s - 1), -4 * s * (s - 1), 2 * s * (s - 0.5)
        f = (b0[:, None, None] * self.f_nodes[k] + bm[:, None, None] * self.f_mid[k]
             + b1[:, None, None] * self.f_nodes[k + 1])
        tau = (b0[:, None] * self.tau_nodes[k] + bm[:, None] * self.tau_mid[k]
               + b1[:, None] * self.tau_nodes[k + 1])
        return f, tau
