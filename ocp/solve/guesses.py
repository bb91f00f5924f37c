"""Initial guesses and solve strategies of the grasp pipeline.

A :class:`Strategy` says how the pipeline (:class:`ocp.solve.planner.ManipulationPlanner`)
starts IPOPT for a kind of grasp: which initial guesses it tries in turn, how it budgets
IPOPT's iterations over them and over grid refinements, how a previous plan seeds a new
one, and which bounds it adds. Two exist:

* :class:`GraspStrategy` (fingers): one consistent guess (:func:`grasp_guess`: the
  object's motion, the fingertips' contacts rolled along it, the joints by inverse
  kinematics), the whole budget for it, a previous plan interpolated (and IPOPT's
  primal-dual point of the same NLP taken as it is);
* :class:`PalmStrategy` (the object on the palm alone, the paper's ball on palm):
  forward simulations of reference palm paths, with loops first when the orientation is a
  target (rolling is nonholonomic: a pure reorientation needs a loop), each with at most
  ``max_iter_per_guess`` iterations out of one budget; a previous plan of the same duration
  sampled with its collocation polynomials; the gauge bound of the symmetric vertical
  reorientation.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from functools import cache
from typing import TYPE_CHECKING, Any

import casadi as ca
import numpy as np
from numpy.typing import NDArray

from ocp.contacts.palm_model import NU, NX, model_for
from ocp.solve.contact_guesses import SubPlanner, guess_contact, guess_joints, object_guess
from ocp.spec.grasp import contact_charts
from ocp.spec.problem import CONTACT_COORDS, BallOnPalmProblem
from ocp.transcription.collocation import WarmStart, node_inputs, rk4_step

if TYPE_CHECKING:
    from ocp.solution import ManipulationSolution
    from ocp.solve.ipopt import NLP
    from ocp.spec.grasp import ManipulationProblem
    from ocp.transcription.grasp_model import GraspModel

__all__ = [
    "GraspStrategy",
    "Guess",
    "PalmStrategy",
    "Strategy",
    "epigraph_guess",
    "grasp_guess",
    "strategy_for",
]

FloatArray = NDArray[np.float64]
#: An initial guess: node states, midpoint states, node input columns, midpoint inputs
#: (physical units, rows).
Guess = tuple[FloatArray, FloatArray, FloatArray, FloatArray]

_GUESS_SUBSTEPS = 2  # RK4 steps per half interval in the palm's guess simulation


class Strategy:
    """How the pipeline starts and budgets IPOPT for a kind of grasp (see the module)."""

    #: whether each initial guess gets at most the planner's ``max_iter_per_guess``
    #: iterations (else the whole budget)
    caps_guesses: bool = False
    #: whether later guesses and grid refinements draw on what earlier ones left of
    #: ``options.max_iter`` (else each solve has the whole budget)
    shared_budget: bool = False
    #: whether a previous plan's IPOPT primal-dual point seeds a solve of the same NLP
    use_nlp_point: bool = True

    def own_guesses(self, planner: SubPlanner, problem: ManipulationProblem, m: GraspModel,
                    nlp: NLP, x0: FloatArray, t_nodes: FloatArray) -> Iterator[Guess]:
        raise NotImplementedError

    def warm_guess(self, warm: WarmStart | ManipulationSolution, problem: ManipulationProblem,
                   nlp: NLP, x0: FloatArray, t_nodes: FloatArray) -> Guess:
        """A previous plan (or a warm start) on this grid."""
        ws = warm if isinstance(warm, WarmStart) else warm.warm_start
        X, Xm, U, Um = ws.on_grid(t_nodes, nlp.hs.left_cols, nlp.hs.right_cols,
                                  nlp.hs.n_input_cols)
        X[0] = x0  # the fixed initial state, exactly
        return X, Xm, U, Um

    def adjust_bounds(self, problem: ManipulationProblem, nlp: NLP, lbx: FloatArray,
                      ubx: FloatArray) -> None:
        """Bounds a kind of grasp adds (in place, scaled NLP variables)."""


class GraspStrategy(Strategy):
    """Grasps with fingers."""

    def own_guesses(self, planner: SubPlanner, problem: ManipulationProblem, m: GraspModel,
                    nlp: NLP, x0: FloatArray, t_nodes: FloatArray) -> Iterator[Guess]:
        yield grasp_guess(planner, problem, m, nlp, x0, t_nodes)


class PalmStrategy(Strategy):
    """The object on the palm alone (the ball-on-palm planner's strategies)."""

    caps_guesses = True
    shared_budget = True
    use_nlp_point = False

    def own_guesses(self, planner: SubPlanner, problem: ManipulationProblem, m: GraspModel,
                    nlp: NLP, x0: FloatArray, t_nodes: FloatArray) -> Iterator[Guess]:
        base = problem.palm_problem()
        n_cols = nlp.hs.n_input_cols
        for loop in guess_loops(base):
            yield simulate_guess(base, t_nodes, reference_input(base, loop),
                                 nlp.hs.left_cols, nlp.hs.right_cols, n_cols)

    def warm_guess(self, warm: WarmStart | ManipulationSolution, problem: ManipulationProblem,
                   nlp: NLP, x0: FloatArray, t_nodes: FloatArray) -> Guess:
        """A previous plan of the same duration sampled with its collocation polynomials;
        anything else interpolated."""
        if isinstance(warm, WarmStart) or warm.collocation is None or \
                abs(warm.duration - problem.duration) >= 1e-9:
            return super().warm_guess(warm, problem, nlp, x0, t_nodes)
        tm = (t_nodes[:-1] + t_nodes[1:]) / 2
        U = node_inputs(lambda ts: warm.sample(ts).u, t_nodes, nlp.hs.left_cols,
                        nlp.hs.right_cols, nlp.hs.n_input_cols)
        sm = warm.sample(tm)
        return warm.sample(t_nodes).x, sm.x, U, sm.u

    def adjust_bounds(self, problem: ManipulationProblem, nlp: NLP, lbx: FloatArray,
                      ubx: FloatArray) -> None:
        if rotation_symmetric(problem.palm_problem()):
            # Gauge: the plan's rotation about the contact normal is free; depart along +x
            # (the first input, or with the smooth timing, which starts at rest, the first
            # midpoint's).
            _, _, Ui, Umi, _, _, _ = nlp.unpack(np.arange(len(lbx), dtype=float))
            first = np.asarray(Umi)[:, 0] if nlp.hs.continuous else \
                np.asarray(Ui)[:, nlp.hs.left_cols[0]]
            i_x, i_y = (round(float(first[j])) for j in (0, 1))
            lbx[i_x] = 0.0
            lbx[i_y] = ubx[i_y] = 0.0


def strategy_for(problem: ManipulationProblem) -> Strategy:
    """The palm's strategies for the object on the palm alone, else the grasp's."""
    if problem.palm is not None and not problem.fingers and problem.motion is None:
        return PalmStrategy()
    return GraspStrategy()


#: The planned forces' initial guess pushes this many times the minimum normal force.
LOAD_GUESS_PUSH = 2.0


def load_guess(R_po: FloatArray, p_po: FloatArray, pts: FloatArray, nrm: FloatArray,
               load: FloatArray) -> FloatArray:
    """Planned-force guesses (``LOAD_VARS * nc`` x k, :mod:`ocp.transcription.nlp_blocks`):
    every contact pushing along its inward normal with twice the minimum normal force,
    corrected by the least-norm forces that restore the object's equilibrium with its
    weight (palm-frame points ``pts`` and normals ``nrm``, k x nc x 3); no torsion."""
    from ocp.transcription.nlp_blocks import LOAD_VARS

    k, nc, _ = pts.shape
    weight, f_min, F0 = load[0:3], float(load[3]), float(load[5])
    out = np.zeros((LOAD_VARS * nc, k))
    for j in range(k):
        r = pts[j] - p_po[j]  # nc x 3, about the object's centre
        A = np.zeros((6, 3 * nc))
        for i in range(nc):
            A[0:3, 3 * i:3 * i + 3] = np.eye(3)
            x, y, z = r[i]
            A[3:6, 3 * i:3 * i + 3] = [[0, -z, y], [z, 0, -x], [-y, x, 0]]
        f0 = (-LOAD_GUESS_PUSH * f_min * nrm[j]).ravel()
        b = np.concatenate([-weight, np.zeros(3)])
        f = f0 + np.linalg.lstsq(A, b - A @ f0, rcond=None)[0]
        f_obj = (R_po[j].T @ f.reshape(nc, 3).T) / F0  # 3 x nc, the object frame
        for i in range(nc):
            out[LOAD_VARS * i:LOAD_VARS * i + 3, j] = f_obj[:, i]
    return out


def _load_guess_at(out: Any, pts: FloatArray, nrm: FloatArray, load: FloatArray
                   ) -> FloatArray:
    """:func:`load_guess` from the grasp model's mapped ``cartesian`` outputs ``out``."""
    k = len(pts)
    R_po = np.asarray(out[0]).T.reshape(k, 3, 3).transpose(0, 2, 1)
    return load_guess(R_po, np.asarray(out[1]).T, pts, nrm, load)


def planned_force_guess(m: GraspModel, Xall: FloatArray, prm: FloatArray,
                        load: FloatArray) -> FloatArray:
    """The planned forces' guess (:func:`load_guess`) at the states ``Xall`` (rows)."""
    k, nc = len(Xall), m.n_contacts
    out = m.mapped("cartesian", k)(Xall.T, prm)
    return _load_guess_at(out, np.asarray(out[4]).T.reshape(k, nc, 3),
                          np.asarray(out[5]).T.reshape(k, nc, 3), load)


def epigraph_guess(m: GraspModel, Xall: FloatArray, prm: FloatArray,
                   load: FloatArray | None = None, charts: Any = None
                   ) -> tuple[FloatArray, FloatArray]:
    """Grasp epigraph values (1 x k; 0 x k for one contact) and force guesses at the
    given states: the internal forces of 3+ contacts, then (``load``: the NLP's load
    parameters, when it plans forces) the planned forces (:func:`load_guess`).
    ``charts`` (:class:`~ocp.transcription.chart_switch.PlanCharts`): the states are a
    grid's points (nodes, then midpoints), each on its chart."""
    from ocp.geometry.grasp import force_angles

    k = len(Xall)
    nc = m.n_contacts
    if nc < 2 and load is None:  # no force closure to certify: neither
        return np.zeros((0, k)), np.zeros((0, k))
    out = m.mapped("cartesian", k)(Xall.T, prm) if charts is None else \
        charts.evaluate("cartesian", charts.point_charts((k - 1) // 2), Xall.T)
    pts = np.asarray(out[4]).T.reshape(k, nc, 3)
    nrm = np.asarray(out[5]).T.reshape(k, nc, 3)
    loads = np.zeros((0, k))
    if load is not None:
        loads = _load_guess_at(out, pts, nrm, load)
    if nc < 2:
        return np.zeros((0, k)), loads
    if nc == 2:
        phi, _, _ = force_angles(pts, nrm)
        return np.clip(1 - np.cos(phi), 0.0, 2.0)[None], loads
    # a pushing guess: each contact pushes along its inward normal (scaled so that the
    # pushes sum to nc); IPOPT restores equilibrium
    F = -nrm.reshape(k, 3 * nc).T
    return np.full((1, k), 0.5), np.vstack([F, loads])


def grasp_guess(planner: SubPlanner, problem: ManipulationProblem, m: GraspModel, nlp: NLP,
                x0: FloatArray, t_nodes: FloatArray) -> Guess:
    """A consistent initial guess: the object's motion (the ball-on-palm plan, or the
    desired motion); each fingertip's contact point kept where it started relative to
    the object's centre (palm frame), its contact coordinates integrated with the
    rolling equations; the joints by inverse kinematics along the way (closure holds);
    joint rates by finite differences (each kind's part: :mod:`ocp.solve.contact_guesses`;
    ``planner`` plans the support's palm sub-plan, :func:`~.contact_guesses.palm_subplan`)."""
    charts = contact_charts(problem)
    shape = np.asarray(problem.object.params, dtype=float)
    prm = m.params(shape, charts)
    tm = (t_nodes[:-1] + t_nodes[1:]) / 2
    ts = np.sort(np.concatenate([t_nodes, tm]))  # node, mid, node, ...
    cart0 = m.cartesian(x0, prm)
    obj = m.object
    Xo, Wo, pose, obj_w = object_guess(planner, problem, obj, x0[obj.xs], ts,
                                       np.asarray(cart0[0]), np.asarray(cart0[1]).ravel())
    p_obj0 = np.asarray(cart0[1]).ravel()
    pts0 = np.asarray(cart0[4])
    X = np.zeros((len(ts), m.nx))
    W = np.zeros((len(ts), m.nu))
    X[:, obj.xs], W[:, obj.us] = Xo, Wo
    X[0, obj.xs] = x0[obj.xs]
    found: list[FloatArray | None] = []  # the joints of the guesses that found them
    for tip in m.fingertips:
        k = m.point_contacts.index(tip)
        X[:, tip.eta_cols], W[:, tip.w_cols], q_found = guess_contact(
            tip, problem, pose, ts, pts0[:, k] - p_obj0, charts[k], shape,
            m.roll(len(ts) - 1))
        found.append(q_found)
    # joints by IK along the way, every finger: the pads' poses do not depend on the
    # joints (one batched evaluation); one batched IK from the initial grasp's joints,
    # and a sequential one from the previous point's where that does not converge
    X[0] = x0
    out = m.mapped("cartesian", len(ts))(X.T, prm)
    R_all = np.asarray(out[2]).reshape(3, len(ts), -1, 3)  # (3, k, finger, 3)
    p_all = np.asarray(out[3]).reshape(3, len(ts), -1)  # (3, k, finger)
    for i, tip in enumerate(m.fingertips):
        X[:, tip.q_cols], W[:, tip.qd_cols] = guess_joints(
            tip, R_all[:, :, i, :].transpose(1, 0, 2), p_all[:, :, i].T, x0[tip.q_cols], ts,
            found[i])
    Ucols = np.zeros((nlp.hs.n_input_cols, m.nu))
    Ucols[nlp.hs.left_cols] = W[0:-1:2]
    Ucols[nlp.hs.right_cols] = W[2::2]
    if obj_w is not None:  # the palm plan's inputs jump at via-points: both sides
        Ucols[:, obj.us] = node_inputs(obj_w, t_nodes, nlp.hs.left_cols,
                                       nlp.hs.right_cols, len(Ucols))
    return X[0::2], X[1::2], Ucols, W[1::2]


# -- the palm's guesses: reference palm paths, simulated ----------------------------------

def palm_anchors(problem: BallOnPalmProblem) -> FloatArray:
    """Palm points the reference path passes at the segment boundaries (2 x n_seg+1)."""
    pts = [np.array(problem.initial[:2], dtype=float)]
    for coords in [*(vp.coords for vp in problem.via_points), problem.goal]:
        q = pts[-1].copy()
        for i, c in enumerate(("x", "y")):
            if c in coords:
                q[i] = coords[c]
        pts.append(q)
    return np.array(pts).T


def reference_input(problem: BallOnPalmProblem, loop: float) -> Callable[[FloatArray],
                                                                         FloatArray]:
    """w(t) of a reference palm path: straight lines between anchors plus a closed loop.

    The system is nonholonomic: a straight-line guess cannot change the object's
    orientation without moving it, and IPOPT started there can stall and report the
    problem infeasible. A loop of signed size ``loop`` (fraction of the object size),
    superposed over the whole horizon, gives the guess the net rotation a pure
    reorientation needs (the holonomy of rolling around a closed path).
    """
    anchors = palm_anchors(problem)
    tb = problem.segment_times
    T = problem.duration
    r = abs(loop) * problem.object.length_scale
    sgn = 1.0 if loop >= 0 else -1.0

    def w(t: FloatArray) -> FloatArray:
        seg = np.clip(np.searchsorted(tb, t, side="right") - 1, 0, len(tb) - 2)
        lin = (anchors[:, seg + 1] - anchors[:, seg]) / (tb[seg + 1] - tb[seg])
        ph = 2 * np.pi * t / T
        loop_v = (2 * np.pi / T) * r * np.vstack([-np.sin(ph), sgn * np.cos(ph)])
        return np.asarray(lin + loop_v)

    return w


def simulate_guess(problem: BallOnPalmProblem, t_nodes: FloatArray,
                   w_of_t: Callable[[FloatArray], FloatArray], left_cols: list[int],
                   right_cols: list[int], n_cols: int
                   ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Forward-simulate the reference input (RK4): a dynamically consistent initial guess."""
    n = len(t_nodes) - 1
    h = np.diff(t_nodes)
    frac = np.arange(_GUESS_SUBSTEPS * 2 + 1) / (_GUESS_SUBSTEPS * 2)
    times = (t_nodes[:-1, None] + h[:, None] * frac[None, :]).ravel()
    W = w_of_t(times)  # nu x (n * (2 substeps + 1))
    u_lim = problem.object.u_limit(problem.pole_margin)
    Xn, Xm = guess_simulator(problem.object.surface.name, n)(
        np.asarray(problem.initial, dtype=float), W, h, list(problem.object.params), u_lim)
    X = np.vstack([np.asarray(problem.initial, dtype=float), np.asarray(Xn).T])
    tm = (t_nodes[:-1] + t_nodes[1:]) / 2
    # node inputs per segment: evaluated just inside the interval they belong to
    U = node_inputs(lambda ts: w_of_t(ts).T, t_nodes, left_cols, right_cols, n_cols)
    return X, np.asarray(Xm).T, U, w_of_t(tm).T


def rotation_symmetric(problem: BallOnPalmProblem) -> bool:
    """True for a pure reorientation about the palm normal with no via-points.

    The goal fixes the palm point and the object point to their initial values, so the net
    motion is a rotation about the vertical through the contact. Rotating a whole plan about
    that vertical leaves both its cost and its final pose unchanged: the optima form a
    continuum, on which IPOPT's convergence stalls unless one member is picked (the gauge
    bound in the planner's input bounds).
    """
    if problem.via_points or "psi" not in problem.goal:
        return False
    return all(c in problem.goal and abs(problem.goal[c] - problem.initial[i]) < 1e-12
               for i, c in enumerate(CONTACT_COORDS[:4]))


def guess_loops(problem: BallOnPalmProblem) -> list[float]:
    """Loop sizes to try, in order: loops first when the object's orientation is a target."""
    orient = any(c in problem.goal for c in ("u", "v", "psi")) or any(
        c in vp.coords for vp in problem.via_points for c in ("u", "v", "psi"))
    return [0.5, -0.5, 0.0, 1.0, -1.0] if orient else [0.0, 0.5, -0.5]


@cache
def guess_simulator(shape: str, n: int) -> ca.Function:
    """RK4 of the palm contact's rolling equations for an object surface (its name) over n
    intervals: (x0, W, h, params, u_lim) -> (X nodes 1..n, X midpoints).

    W holds the input at 2 * _GUESS_SUBSTEPS + 1 equally spaced times per interval
    (columns interval-major). The latitude is clipped to the chart's allowed band.
    """
    model = model_for(shape)
    m = _GUESS_SUBSTEPS
    x = ca.SX.sym("x", NX)
    Wk = ca.SX.sym("W", NU, 2 * m + 1)
    h = ca.SX.sym("h")
    params = ca.SX.sym("params", model.surface.n_params)
    u_lim = ca.SX.sym("u_lim")
    dt = h / (2 * m)

    def f(xx: ca.SX, j: int) -> ca.SX:  # input at sub-time j/2 (half steps use averages)
        w = Wk[:, j // 2] if j % 2 == 0 else (Wk[:, j // 2] + Wk[:, j // 2 + 1]) / 2
        return model.dynamics(xx, w, params)

    xs = x
    mid = x
    for i in range(2 * m):
        xs = rk4_step(f, xs, 2 * i, 2 * i + 1, 2 * i + 2, dt)
        xs = ca.vertcat(xs[0:2], ca.fmin(ca.fmax(xs[2], -u_lim), u_lim), xs[3:])
        if i == m - 1:
            mid = xs
    step = ca.Function("guess_step", [x, Wk, h, params, u_lim], [xs, mid])
    sim = step.mapaccum("guess_sim", n, [0], [0])
    Wall = ca.SX.sym("Wall", NU, n * (2 * m + 1))
    hs = ca.SX.sym("hs", 1, n)
    Wsplit = ca.horzsplit(Wall, list(range(0, n * (2 * m + 1) + 1, 2 * m + 1)))
    Xn, Xm = sim(x, ca.horzcat(*Wsplit), hs, ca.repmat(params, 1, n), ca.repmat(u_lim, 1, n))
    return ca.Function("guess_simulator", [x, Wall, hs, params, u_lim], [Xn, Xm],
                       ["x0", "W", "h", "params", "u_lim"], ["X", "Xm"])
