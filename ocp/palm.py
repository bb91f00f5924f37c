"""The object on a flat palm: the support contact's own functions and strategies.

* :class:`BallOnPalmModel`: named CasADi functions of the palm/object contact (rolling
  equations, kinematics, the contact's twist), for one object shape (:func:`model_for`);
* :class:`Structure`: which palm coordinates the goal and each via-point fix;
  :func:`goal_errors`: how far a plan's palm coordinates are from them;
* the planning strategies of the object on the palm alone (the pipeline uses them for a
  grasp whose only contact is the support, :mod:`ocp.guesses`): initial guesses simulated
  along reference palm paths with loops for pure reorientations (:func:`reference_input`,
  :func:`simulate_guess`, :func:`guess_loops`) and the gauge bound of the symmetric
  vertical reorientation (:func:`rotation_symmetric`);
* conversions between the palm contact coordinates and the object's pose
  (:func:`contact_coordinates`, :func:`object_pose`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import cache
from typing import Any

import casadi as ca
import numpy as np
from numpy.typing import ArrayLike, NDArray

from .collocation import node_inputs, reintegrator, rk4_step
from .contact import ContactPair
from .problem import CONTACT_COORDS, PERIODIC, BallOnPalmProblem, ObjectSpec
from .surfaces import SURFACES, Plane, Surface, rotation_from_vector

__all__ = ["BallOnPalmModel", "Structure", "contact_coordinates", "coordinate_error",
           "goal_errors", "guess_loops", "model_for", "object_pose", "reference_input",
           "rotation_symmetric", "simulate_guess", "wrap_difference"]

FloatArray = NDArray[np.float64]
NX, NU = 5, 2
_GUESS_SUBSTEPS = 2  # RK4 steps per half interval in the initial-guess simulation


def wrap_difference(a: FloatArray | float, b: FloatArray | float) -> FloatArray:
    """a - b wrapped into [-pi, pi)."""
    return np.asarray((np.asarray(a) - np.asarray(b) + np.pi) % (2 * np.pi) - np.pi)


def coordinate_error(coord: str, value: float, target: float) -> float:
    """|value - target| in m or rad, modulo 2 pi for the periodic coordinates."""
    i = CONTACT_COORDS.index(coord)
    d = float(wrap_difference(value, target)) if PERIODIC[i] else value - target
    return abs(d)


@dataclass(frozen=True)
class BallOnPalmModel:
    """Named CasADi functions of the palm/object contact for one object shape."""

    surface: Surface
    #: (eta, w, params) -> eta_dot: the rolling equations, eq. 3 / eq. 8.
    dynamics: ca.Function
    #: (eta, w, params, chart) -> (R_po, p_po, contact_point, contact_normal, omega_roll)
    kinematics: ca.Function
    #: (eta, eta_dot, params, chart) -> (v_slip [m/s], omega [rad/s]), from d/dt g_po.
    twist: ca.Function

    @staticmethod
    def build(surface: Surface) -> BallOnPalmModel:
        pair = ContactPair(Plane, surface)
        eta = ca.SX.sym("eta", NX)
        eta_dot = ca.SX.sym("eta_dot", NX)
        w = ca.SX.sym("w", NU)
        params = ca.SX.sym("params", surface.n_params)
        chart = ca.SX.sym("chart", 3, 3)
        none = ca.SX(0, 1)
        eye = ca.SX.eye(3)
        dyn = ca.Function("ball_on_palm_dynamics", [eta, w, params],
                          [pair.rates_driven_by_a(eta, w, none, params)],
                          ["eta", "w", "params"], ["eta_dot"])
        R_po, p_po = pair.pose(eta, none, params, eye, chart)
        cp, cn = pair.contact_point(eta, none, eye)
        omega = pair.rolling_velocity(eta, w, none, params)
        kin = ca.Function("ball_on_palm_kinematics", [eta, w, params, chart],
                          [R_po, p_po, cp, cn, omega],
                          ["eta", "w", "params", "chart"],
                          ["R_po", "p_po", "contact_point", "contact_normal", "omega_roll"])
        # Velocity of the object's material point at the contact, relative to the palm:
        # v = dR/dt p_b + dp/dt with p_b = chart f_b(alpha_b) held fixed in the object.
        R_dot = ca.reshape(ca.jtimes(ca.vec(R_po), eta, eta_dot), 3, 3)
        p_dot = ca.jtimes(p_po, eta, eta_dot)
        p_b = chart @ surface.geometry(eta[2:4], params)[0]
        v_slip = R_dot @ p_b + p_dot
        W = R_dot @ R_po.T
        omega_s = ca.vertcat(W[2, 1], W[0, 2], W[1, 0])
        twist = ca.Function("ball_on_palm_contact_twist", [eta, eta_dot, params, chart],
                            [v_slip, omega_s], ["eta", "eta_dot", "params", "chart"],
                            ["v_slip", "omega"])
        return BallOnPalmModel(surface, dyn, kin, twist)

    @cache  # noqa: B019 - models live for the whole process
    def guess_simulator(self, n: int) -> ca.Function:
        """RK4 over n intervals: (x0, W, h, params, u_lim) -> (X nodes 1..n, X midpoints).

        W holds the input at 2 * _GUESS_SUBSTEPS + 1 equally spaced times per interval
        (columns interval-major). The latitude is clipped to the chart's allowed band.
        """
        m = _GUESS_SUBSTEPS
        x = ca.SX.sym("x", NX)
        Wk = ca.SX.sym("W", NU, 2 * m + 1)
        h = ca.SX.sym("h")
        params = ca.SX.sym("params", self.surface.n_params)
        u_lim = ca.SX.sym("u_lim")
        dt = h / (2 * m)

        def f(xx: ca.SX, j: int) -> ca.SX:  # input at sub-time j/2 (half steps use averages)
            w = Wk[:, j // 2] if j % 2 == 0 else (Wk[:, j // 2] + Wk[:, j // 2 + 1]) / 2
            return self.dynamics(xx, w, params)

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

    @cache  # noqa: B019 - models live for the whole process
    def mapped(self, name: str, m: int) -> ca.Function:
        """The model's function ``name`` (dynamics, kinematics, twist) over m samples."""
        return getattr(self, name).map(m)

    @cache  # noqa: B019 - one integrator per model, models live for the process
    def reintegrator(self, n_sub: int) -> ca.Function:
        """CVODES over one interval with the collocation input (see collocation.py)."""
        return reintegrator(self.dynamics, NX, NU, self.surface.n_params, n_sub)


@cache
def model_for(shape: str) -> BallOnPalmModel:
    """The (cached) model for an object shape name ("sphere", "ellipsoid")."""
    return BallOnPalmModel.build(SURFACES[shape])


@dataclass(frozen=True)
class Structure:
    """What fixes the shape of the NLP; everything else is a parameter or a bound."""

    shape: str
    segments: tuple[int, ...]
    goal_mask: tuple[bool, ...]
    via_masks: tuple[tuple[bool, ...], ...]

    @staticmethod
    def of(problem: BallOnPalmProblem) -> Structure:
        def mask(coords: Any) -> tuple[bool, ...]:
            return tuple(c in coords for c in CONTACT_COORDS)

        return Structure(problem.object.shape, problem.segment_intervals(),
                         mask(problem.goal), tuple(mask(vp.coords) for vp in problem.via_points))


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


def simulate_guess(model: BallOnPalmModel, problem: BallOnPalmProblem, t_nodes: FloatArray,
                   w_of_t: Callable[[FloatArray], FloatArray], left_cols: list[int],
                   right_cols: list[int], n_cols: int
                   ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Forward-simulate the reference input (RK4): a dynamically consistent initial guess."""
    n = len(t_nodes) - 1
    h = np.diff(t_nodes)
    frac = np.arange(_GUESS_SUBSTEPS * 2 + 1) / (_GUESS_SUBSTEPS * 2)
    times = (t_nodes[:-1, None] + h[:, None] * frac[None, :]).ravel()
    W = w_of_t(times)  # nu x (n * (2 substeps + 1))
    u_lim = math.pi / 2 - problem.pole_margin
    Xn, Xm = model.guess_simulator(n)(np.asarray(problem.initial, dtype=float), W, h,
                                      list(problem.object.dimensions), u_lim)
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


def goal_errors(problem: BallOnPalmProblem, X: FloatArray, ends: list[int]
                ) -> dict[str, float]:
    """Error of every goal and via-point coordinate (m or wrapped rad) of the palm contact
    coordinates ``X[:, 0:5]`` at the segment end nodes ``ends`` (0 first)."""
    out: dict[str, float] = {}
    for j, vp in enumerate(problem.via_points):
        for c, val in vp.coords.items():
            out[f"via_points[{j}].{c}"] = coordinate_error(
                c, X[ends[j + 1], CONTACT_COORDS.index(c)], val)
    for c, val in problem.goal.items():
        out[f"goal.{c}"] = coordinate_error(c, X[ends[-1], CONTACT_COORDS.index(c)], val)
    return out


def contact_coordinates(obj: ObjectSpec, position_xy: ArrayLike, rotation: ArrayLike
                        ) -> tuple[float, float, float, float, float]:
    """Contact coordinates (x, y, u, v, psi) of the object resting on the palm.

    ``rotation`` is the object's orientation in the palm frame (3x3) and ``position_xy``
    the palm point under it [m]. The inverse of the pose map: the contact point on the
    object is the support point whose outward normal points down the palm normal, (u, v)
    its coordinates in the object's chart, psi the angle between the two contact frames.
    """
    R = np.asarray(rotation, dtype=float).reshape(3, 3)
    surf, params = obj.surface, obj.dimensions
    chart = rotation_from_vector(obj.chart_rotation)
    p_b = surf.support_point(R.T @ np.array([0.0, 0.0, -1.0]), params)
    u, v = surf.inverse(chart.T @ p_b, params)
    _, R_gauss, _, _, _ = surf.geometry([u, v], params)
    R_cc = R @ chart @ np.asarray(R_gauss)  # palm contact frame is the identity
    psi = math.atan2(-R_cc[0, 1], R_cc[0, 0])
    xy = np.asarray(position_xy, dtype=float)
    return (float(xy[0]), float(xy[1]), float(u), float(v), psi)


def object_pose(obj: ObjectSpec, eta: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """(R_po, p_po): the object's pose in the palm frame at contact coordinates ``eta``."""
    model = model_for(obj.shape)
    chart = rotation_from_vector(obj.chart_rotation)
    R, p, _, _, _ = model.kinematics(np.asarray(eta, dtype=float), [0.0, 0.0],
                                     list(obj.dimensions), chart)
    return np.asarray(R), np.asarray(p).ravel()
