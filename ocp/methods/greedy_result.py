"""The paper's greedy method's plan (:func:`ocp.methods.greedy.greedy_plan`): its
trajectories on the method's grid, its closure and limit reports, its failures."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from ocp.solution import Solution

__all__ = ["GreedyResult"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class GreedyResult:
    """A plan by the paper's method. Arrays have one row per grid time t_k (k = 0..n_steps).

    Inputs held over a step (``w_f``, ``q_dot``, ``rotation_step``) are in the row of the
    step's start; their last row is 0 (the motion ends at t_n). ``w_p`` is the palm plan's
    input sampled at t_k.

    t [s]; eta_p = (x, y, u_p, v_p, psi_p) [m, m, rad, rad, rad];
    eta_f = (x_f, y_f, u_f, v_f, psi_f) (pad point [m], ball point in the finger contact's
    chart patch [rad], contact angle [rad]); q [rad]; q_dot [rad/s]; w_p = d/dt (x, y)
    [m/s]; w_f = alpha_dot_of [rad/s]; rotation_step |Delta Theta| of the step [rad];
    grasp_angles (Phi_p, Phi_f) [rad]; cone_margin = atan(mu) - max(Phi_p, Phi_f) [rad];
    fingertip_rotation/position: Pinocchio's FK of q (palm frame) [-, m];
    contact_fingertip_rotation/position: the pose g_po g_of from the contact coordinates;
    closure_position_error [m] / closure_rotation_error [rad] between the two;
    object_rotation/position: the ball's pose in the palm [-, m];
    palm_contact_point, finger_contact_point, finger_contact_normal: palm frame [m, -];
    pad_point: the finger contact point in the pad frame of FK(q) [m] (z ~ 0 on the pad).
    """

    t: FloatArray
    eta_p: FloatArray
    eta_f: FloatArray
    q: FloatArray
    q_dot: FloatArray
    w_p: FloatArray
    w_f: FloatArray
    rotation_step: FloatArray
    grasp_angles: FloatArray
    cone_margin: FloatArray
    fingertip_rotation: FloatArray
    fingertip_position: FloatArray
    contact_fingertip_rotation: FloatArray
    contact_fingertip_position: FloatArray
    closure_position_error: FloatArray
    closure_rotation_error: FloatArray
    object_rotation: FloatArray
    object_position: FloatArray
    palm_contact_point: FloatArray
    finger_contact_point: FloatArray
    finger_contact_normal: FloatArray
    pad_point: FloatArray
    #: Per goal/via-point coordinate error of the integrated palm path [m or rad].
    goal_error: dict[str, float]
    #: Max closure error over the grid: (position [m], rotation [rad]).
    closure_error: tuple[float, float]
    #: sum_k |q_dot_k|^2 dt [rad^2/s].
    joint_effort: float
    #: Wall time of the whole plan, palm plan included [s], and of the palm plan alone [s]
    #: (~0 when the palm plan was given).
    compute_time: float
    palm_plan_time: float
    #: Smallest distance of any joint to its limits along the plan [rad or m] (< 0: beyond).
    joint_limit_margin: float
    #: Largest |q_dot_i| / velocity_limit_i along the plan.
    max_velocity_ratio: float
    #: Smallest singular value of the finger Jacobian met along the plan.
    min_jacobian_singular_value: float
    #: Steps at which no candidate satisfied the pad, cone and pole constraints.
    fallback_steps: int
    #: |eta_p(t_k) integrated - eta_p(t_k) of the palm plan's interpolant| (worst) [m or rad].
    palm_integration_error: float
    #: Settings used.
    dt: float
    delta: float
    grid: tuple[int, int]
    closure_gain: float
    #: What went wrong, each with the first time it happened (empty when the plan holds):
    #: closure beyond :data:`CLOSURE_TOL`, joints beyond their position or velocity limits,
    #: the grasp outside the friction cone, steps without a feasible candidate.
    failures: tuple[str, ...]
    #: Earliest time of any failure [s], or None.
    failure_time: float | None
    palm_plan: Solution = field(repr=False, compare=False)

    @property
    def ok(self) -> bool:
        """Whether the plan holds: no failure (see ``failures``)."""
        return not self.failures

    @property
    def max_grasp_angle(self) -> FloatArray:
        """max(Phi_p, Phi_f) at every t_k [rad]."""
        return np.asarray(self.grasp_angles.max(axis=1))

    @property
    def pad_excursion(self) -> float:
        """max |x_f|, |y_f| over the plan [m]."""
        return float(np.max(np.abs(self.eta_f[:, 0:2])))

    def summary(self) -> str:
        phi = np.degrees(self.max_grasp_angle)
        return "\n".join([
            f"status       {'ok' if self.ok else 'FAILED: ' + '; '.join(self.failures)}",
            f"steps        {len(self.t) - 1} x {self.dt:.4g} s, delta {self.delta:.4g} rad, "
            f"grid {self.grid}, closure gain {self.closure_gain:g}",
            f"grasp angle  start {phi[0]:.3f} deg, end {phi[-1]:.3f} deg, "
            f"max {phi.max():.3f} deg; min cone margin "
            f"{math.degrees(float(self.cone_margin.min())):.3f} deg",
            f"goal error   {max(self.goal_error.values(), default=0.0):.3g}",
            f"closure      {self.closure_error[0]:.3g} m, {self.closure_error[1]:.3g} rad",
            f"pad          max |x_f|, |y_f| {self.pad_excursion * 1e3:.2f} mm",
            f"joints       limit margin {self.joint_limit_margin:.3f}, max |q_dot|/limit "
            f"{self.max_velocity_ratio:.3f}, effort {self.joint_effort:.4g} rad^2/s",
            f"time         {self.compute_time:.3f} s (palm plan {self.palm_plan_time:.3f} s)",
        ])


# -- symbolic model ---------------------------------------------------------------------------
