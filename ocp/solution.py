"""Results of a plan: typed status, solver statistics, and the plan itself.

:class:`ManipulationSolution` is every grasp's plan (the pipeline's, :mod:`ocp.solve.planner`):
the object's motion, every contact's coordinates and every finger's joints on the
collocation grid, the certificate, the NLP's own values (:class:`Collocation`) and the
collocation polynomials to sample it at any time (:meth:`ManipulationSolution.sample`).
:class:`Solution` is the same plan of the object on the palm alone in the ball-on-palm
planner's terms (its contact coordinates' :class:`Trajectory`, sampled on any grid).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from enum import StrEnum
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from ocp.certify.certificate import Certificate
from ocp.geometry.rotations import quaternion_wxyz
from ocp.transcription.collocation import HermiteInterpolant, NlpPoint, PlannedForces, WarmStart

if TYPE_CHECKING:
    from ocp.transcription.chart_switch import PlanCharts
    from ocp.transcription.grasp_model import GraspModel

__all__ = ["Collocation", "ContactTrajectory", "FingerTrajectory", "GraspSample",
           "JointTrajectory", "ManipulationSolution", "PalmSolution", "PlannedForces", "RateBreak",
           "Solution", "SolverStats", "Status", "Trajectory", "fixed_rate_times",
           "joint_torques", "status_from_ipopt", "trajectory_joint_names"]

FloatArray = NDArray[np.float64]


def trajectory_joint_names(fingers: Sequence[tuple[str, Sequence[str]]]) -> tuple[str, ...]:
    """A joint trajectory's names for fingers (name, their joints' names): the model's,
    prefixed with the finger's (``<finger>/<joint>``) only where two fingers share one."""
    names = [(f, j) for f, joints in fingers for j in joints]
    seen = [j for _, j in names]
    return tuple(j if seen.count(j) == 1 else f"{f}/{j}" for f, j in names)


class Status(StrEnum):
    """Outcome of a plan (cf. IPOPT's return status, MoveIt's error codes)."""

    #: IPOPT converged and the independent certificate holds: the plan is physically valid.
    SOLVED = "solved"
    #: IPOPT converged but the certificate exceeds a tolerance (refine the grid).
    INACCURATE = "inaccurate"
    #: IPOPT found the constraints (goals, bounds) locally infeasible.
    INFEASIBLE = "infeasible"
    ITERATION_LIMIT = "iteration_limit"
    TIME_LIMIT = "time_limit"
    #: IPOPT stopped on a numerical difficulty (restoration failure, tiny steps, NaN).
    NUMERICAL_ERROR = "numerical_error"
    #: The request was rejected before any NLP was built (see the message).
    INVALID_INPUT = "invalid_input"
    #: An unexpected error inside the planner; the message names it.
    ERROR = "error"


_IPOPT_STATUS = {
    "Solve_Succeeded": Status.SOLVED,
    "Solved_To_Acceptable_Level": Status.SOLVED,
    "Infeasible_Problem_Detected": Status.INFEASIBLE,
    "Maximum_Iterations_Exceeded": Status.ITERATION_LIMIT,
    "Maximum_CpuTime_Exceeded": Status.TIME_LIMIT,
    "Maximum_WallTime_Exceeded": Status.TIME_LIMIT,
}


#: IPOPT's return statuses of a converged solve.
_CONVERGED = ("Solve_Succeeded", "Solved_To_Acceptable_Level")


def status_from_ipopt(raw: str) -> Status:
    """Map IPOPT's return status to ours; anything unlisted is a numerical error."""
    return _IPOPT_STATUS.get(raw, Status.NUMERICAL_ERROR)


@dataclass(frozen=True)
class Trajectory:
    """A plan sampled at times ``t`` [s] (rows are samples).

    eta: contact coordinates (x [m], y [m], u [rad], v [rad], psi [rad]);
    eta_dot: their rates; w: palm contact velocity d/dt (x, y) [m/s] (the input);
    rolling_velocity: (omega_x, omega_y) of the palm relative to the object [rad/s];
    object_position [m] and object_rotation (3x3) of the object in the palm frame;
    contact_point: the contact point in the palm frame [m];
    contact_normal: the palm's outward normal at the contact (palm frame).
    """

    t: FloatArray
    eta: FloatArray
    eta_dot: FloatArray
    w: FloatArray
    rolling_velocity: FloatArray
    object_position: FloatArray
    object_rotation: FloatArray
    contact_point: FloatArray
    contact_normal: FloatArray

    def to_dict(self) -> dict[str, Any]:
        return {
            "t": self.t.tolist(),
            "eta": self.eta.tolist(),
            "eta_dot": self.eta_dot.tolist(),
            "w": self.w.tolist(),
            "rolling_velocity": self.rolling_velocity.tolist(),
            "object_position": self.object_position.tolist(),
            "object_orientation_wxyz": quaternion_wxyz(self.object_rotation).tolist(),
            "contact_point": self.contact_point.tolist(),
            "contact_normal": self.contact_normal.tolist(),
        }


@dataclass(frozen=True)
class SolverStats:
    """Solver statistics: raw IPOPT status, iterations, and times [s] measured apart."""

    raw_status: str
    iterations: int
    attempts: int
    build_time: float
    solve_time: float
    certificate_time: float
    objective: float
    cache_hit: bool
    #: Grid refinements after the first solve (each doubles the intervals).
    refinements: int = 0
    #: Collocation intervals of the returned plan.
    n_intervals: int = 0
    #: The IPOPT calls alone [s] (part of ``solve_time``, which includes the guesses).
    ipopt_time: float = 0.0
    #: The NLP solver whose point is the plan: "ipopt", "fatrop", or "ipopt (fatrop: its
    #: status)" when IPOPT took over from a fatrop that did not succeed (issue 27).
    solver: str = "ipopt"
    #: How far from a KKT point the returned plan is, in the NLP's own (scaled) units,
    #: evaluated at the returned primal-dual point whatever stopped the solver (converged,
    #: an iteration budget, a deadline): the largest violation of a constraint row's or
    #: a variable's bounds, and the largest entry of the Lagrangian's gradient
    #: ``grad f + J^T lam_g + lam_x``. None where not evaluated (the ball-on-palm planner;
    #: a point with non-finite values).
    primal_infeasibility: float | None = None
    dual_infeasibility: float | None = None

    def to_dict(self) -> dict[str, Any]:
        return dict(self.__dict__)


@dataclass(frozen=True)
class PalmSolution:
    """The ball-on-palm front end's plan (:class:`~ocp.ball_on_palm.BallOnPalmPlanner`) in
    the palm contact's coordinates: status, the NLP's own grid, interpolation on any grid,
    certificate. The general plan it presents is a :class:`ManipulationSolution`."""

    status: Status
    message: str
    stats: SolverStats
    #: Samples at the collocation points (nodes and midpoints, in time order).
    grid: Trajectory
    #: Samples at the nodes only.
    nodes: Trajectory
    certificate: Certificate
    #: Per goal/via-point coordinate error [m or rad] ("goal.x", "via_points[0].y", ...).
    goal_error: dict[str, float]
    _sampler: Any = field(repr=False, compare=False)
    #: The grasp pipeline's own plan (its collocation values, IPOPT's primal-dual point).
    plan: ManipulationSolution | None = field(default=None, repr=False, compare=False)
    #: The object's chart patch (rotation vector [rad]) of the plan's (u, v, psi): the
    #: problem's, or another when the plan rode the pole bound of the problem's.
    chart_rotation: tuple[float, ...] = (0.0, 0.0, 0.0)

    @property
    def ok(self) -> bool:
        return self.status is Status.SOLVED

    @property
    def warm_start(self) -> WarmStart:
        """This plan as the initial guess of another: contact coordinates and palm contact
        velocities at its collocation points."""
        return WarmStart(self.grid.t, self.grid.eta, self.grid.w)

    def sample(self, t: FloatArray | list[float]) -> Trajectory:
        """The plan at any times in [0, duration], from the collocation polynomials."""
        return self._sampler(np.asarray(t, dtype=float))

    def summary(self) -> str:
        c, nan = self.certificate, float("nan")
        worst_goal = max(self.goal_error.values(), default=0.0)
        lines = [
            f"status       {self.status.value}  (IPOPT: {self.stats.raw_status})",
            f"message      {self.message}",
            f"iterations   {self.stats.iterations} in {self.stats.attempts} attempt(s), "
            f"N = {self.stats.n_intervals}, {self.stats.refinements} refinement(s)",
            f"time         build {self.stats.build_time * 1e3:.1f} ms"
            f"{' (cached)' if self.stats.cache_hit else ''}, solve "
            f"{self.stats.solve_time * 1e3:.1f} ms, certificate "
            f"{self.stats.certificate_time * 1e3:.1f} ms",
            f"objective    {self.stats.objective:.6g}",
            f"goal error   {worst_goal:.3g} (worst of {len(self.goal_error)} targets)",
            f"certificate  {'PASSED' if c.passed else 'FAILED: ' + '; '.join(c.failures)}",
            f"  defect     {c.get('max_position_defect', nan):.3g} m, "
            f"{c.get('max_angle_defect', nan):.3g} rad",
            f"  slip/spin  {c.get('max_slip_speed', nan):.3g} m/s, "
            f"{c.get('max_spin_rate', nan):.3g} rad/s",
            f"  height     {c.get('max_height_error', nan):.3g} m",
        ]
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        return {
            "status": self.status.value,
            "message": self.message,
            "stats": self.stats.to_dict(),
            "goal_error": dict(self.goal_error),
            "certificate": self.certificate.to_dict(),
            "grid": self.grid.to_dict(),
        }



#: The former name of :class:`PalmSolution` (the ball-on-palm front end's plan).
Solution = PalmSolution


@dataclass(frozen=True)
class ContactTrajectory:
    """One contact over the plan (rows are samples).

    ``eta`` = (body point x, y [m], object point u, v [rad], psi [rad]): for the palm the
    palm point, for a fingertip the pad point; ``w`` the contact's input (palm: d/dt (x, y)
    [m/s]; fingertip: d/dt (u, v) [rad/s]); ``point`` the contact point and ``normal`` the
    object's outward normal there, in the palm frame; ``force_angle`` the angle [rad]
    between the pushing direction (-normal) and the internal force of the grasp that
    certifies force closure (for two contacts: the paper's grasp angle).
    """

    name: str
    body: str  # "palm" or "finger"
    eta: FloatArray
    eta_dot: FloatArray
    w: FloatArray
    point: FloatArray
    normal: FloatArray
    force_angle: FloatArray
    #: The planned force this contact's body (palm, fingertip) exerts on the object [N],
    #: palm frame, and the torsion [N m]: its moment about the object's outward normal
    #: (soft finger); None for a plan without forces (docs/forces.md).
    force: FloatArray | None = None
    torsion: FloatArray | None = None


@dataclass(frozen=True)
class FingerTrajectory:
    """One finger over the plan: joint angles q [rad], rates q_dot [rad/s], the pad's pose
    (position [m], rotation) in the palm frame."""

    name: str
    joint_names: tuple[str, ...]
    q: FloatArray
    q_dot: FloatArray
    tip_position: FloatArray
    tip_rotation: FloatArray
    #: The joint torques [N m] (or forces [N]) that exert the planned contact force and
    #: torsion on the object, tau = J^T (f; m) at the contact point, and hold the finger's
    #: own links against gravity when its model has inertias (:func:`joint_torques`);
    #: None for a plan without forces.
    joint_torques: FloatArray | None = None


@dataclass(frozen=True)
class Collocation:
    """The NLP's own values of a plan: node times, states at the nodes (rows) and at the
    interval midpoints, each interval's inputs at its start (U0), midpoint (Um) and end
    (U1; at a via-point node the incoming input, U0 of the next interval the outgoing).
    The states between are each interval's cubic Hermite polynomial, the inputs the
    quadratic through (U0, Um, U1): :meth:`ManipulationSolution.sample`."""

    t_nodes: FloatArray
    X: FloatArray
    Xm: FloatArray
    U0: FloatArray
    Um: FloatArray
    U1: FloatArray
    #: The planned contact forces at the nodes and midpoints (None without forces).
    forces: PlannedForces | None = None


def joint_torques(finger: Any, q: FloatArray, tip_point: FloatArray, normal: FloatArray,
                  force: FloatArray, torsion: FloatArray,
                  gravity: Any = (0.0, 0.0, 0.0)) -> FloatArray:
    """tau = J^T (f; r x f + tau_n n) + g(q) for rows of joint angles ``q``, every row at
    once: J the finger's geometric Jacobian of its tip frame
    (:meth:`~ocp.robots.finger.FingerModel.tip_jacobians`; v of the frame's origin), r from
    that origin to the contact point ``tip_point`` (palm frame), f the force the fingertip
    exerts on the object, tau_n n the torsion about the object's outward normal
    ``normal``; g(q) the torques that hold the finger's own links against ``gravity``
    (palm frame; :meth:`~ocp.robots.finger.FingerModel.gravity_torques`: zero when its
    model has no inertias, as the built-in fingers)."""
    q = np.atleast_2d(np.asarray(q, dtype=float))
    k = len(q)
    out = finger.gravity_torques(q, gravity) if finger.mass > 0 else np.zeros((k, finger.nq))
    if not k:
        return out
    _, p_tip = finger.tip_poses(q)
    J = finger.tip_jacobians(q)
    f = np.asarray(force, dtype=float).reshape(k, 3)
    moment = np.cross(np.asarray(tip_point, dtype=float).reshape(k, 3) - p_tip, f) \
        + np.asarray(torsion, dtype=float).reshape(k, 1) * \
        np.asarray(normal, dtype=float).reshape(k, 3)
    return out + np.einsum("kij,ki->kj", J[:, :3], f) + np.einsum("kij,ki->kj", J[:, 3:],
                                                                   moment)


def fixed_rate_times(duration: float, rate: float) -> FloatArray:
    """Times [s] at a controller's rate [Hz] from 0 to ``duration``: k / rate for every k
    with k / rate < duration, then ``duration`` itself (the plan's end, where it stops)."""
    if not (math.isfinite(rate) and rate > 0):
        raise ValueError(f"sample rate must be a positive number of Hz, got {rate}")
    k = np.arange(math.ceil(duration * rate - 1e-9))
    return np.concatenate([k / rate, [duration]])


@dataclass(frozen=True)
class RateBreak:
    """A node where the plan's input jumps (a via-point of the paper's piecewise timing):
    the positions are continuous there, the rates have two one-sided values."""

    t: float
    velocities_before: FloatArray
    velocities_after: FloatArray


@dataclass(frozen=True)
class JointTrajectory:
    """Every finger's joints at given times, shaped like ROS 2's
    ``trajectory_msgs/JointTrajectory``: positions [rad or m], velocities and accelerations
    (the returned polynomials' derivatives, so velocities are the time derivative of
    positions), rows = times. A time on a rate break gets the outgoing rates; ``breaks``
    gives both sides."""

    joint_names: tuple[str, ...]
    t: FloatArray
    positions: FloatArray
    velocities: FloatArray
    accelerations: FloatArray
    breaks: tuple[RateBreak, ...] = ()
    #: Joint torques of the planned forces (ROS's ``effort``); None without forces.
    efforts: FloatArray | None = None

    def to_dict(self) -> dict[str, Any]:
        """The ROS 2 message's fields (``time_from_start`` as builtin_interfaces/Duration
        and, for convenience, in seconds) and the rate breaks."""
        points = []
        for i, t in enumerate(self.t.tolist()):
            sec = math.floor(t)
            nanosec = min(round((t - sec) * 1e9), 999_999_999)
            points.append({"positions": self.positions[i].tolist(),
                           "velocities": self.velocities[i].tolist(),
                           "accelerations": self.accelerations[i].tolist(),
                           "time_from_start": {"sec": sec, "nanosec": nanosec},
                           "t": t})
            if self.efforts is not None:
                points[-1]["effort"] = self.efforts[i].tolist()
        return {"joint_names": list(self.joint_names), "points": points,
                "rate_breaks": [{"t": b.t, "velocities_before": b.velocities_before.tolist(),
                                 "velocities_after": b.velocities_after.tolist()}
                                for b in self.breaks]}


@dataclass(frozen=True)
class GraspSample:
    """A plan at given times (rows): states x and inputs u in the grasp's layout (the
    contacts' blocks, :mod:`ocp.contacts`), the states' rates and accelerations (the
    time derivatives of the returned polynomials), the object's pose (palm frame)."""

    t: FloatArray
    x: FloatArray
    u: FloatArray
    x_dot: FloatArray
    x_ddot: FloatArray
    object_position: FloatArray
    object_rotation: FloatArray


@dataclass(frozen=True)
class ManipulationSolution:
    """A plan sampled on the collocation grid (nodes and midpoints, in time order)."""

    status: Status
    message: str
    raw_status: str
    t: FloatArray
    object_position: FloatArray
    object_rotation: FloatArray
    object_velocity: FloatArray  # [m/s], palm frame
    object_angular_velocity: FloatArray  # [rad/s], palm frame
    contacts: tuple[ContactTrajectory, ...]
    fingers: tuple[FingerTrajectory, ...]
    grasp_angle: FloatArray  # Phi*: the largest force angle over the contacts [rad]
    cone_margin: FloatArray  # atan(mu) - Phi* [rad]
    desired_position: FloatArray | None
    desired_rotation: FloatArray | None
    tracking_position_error: FloatArray | None  # [m]
    tracking_angle_error: FloatArray | None  # [rad]
    goal_error: dict[str, float]
    certificate: Certificate
    certificate_failures: tuple[str, ...] = ()
    #: The collocation grid's raw values (states, inputs), for warm starts.
    X: FloatArray = field(default_factory=lambda: np.zeros((0, 0)), repr=False)
    U: FloatArray = field(default_factory=lambda: np.zeros((0, 0)), repr=False)
    #: IPOPT's primal-dual point at this plan, for a warm start of the same NLP.
    nlp_point: NlpPoint | None = field(default=None, repr=False)
    #: Solver statistics of the whole plan (every initial guess tried, every refinement;
    #: ``solve_time`` the whole attempt loop, ``ipopt_time`` the IPOPT calls): the plan's
    #: one record of its work (``iterations``, ``build_time``, ``ipopt_time`` and
    #: ``refinements`` below read it).
    stats: SolverStats | None = None
    #: The NLP's own values (for sampling and for the ball-on-palm's view).
    collocation: Collocation | None = field(default=None, repr=False)
    #: The object's chart patch (rotation vector [rad]) in which the palm contact's
    #: coordinates are given: the problem's, or the one the planner chose because the
    #: plan rode the pole bound of the problem's (:mod:`ocp.spec.patches`); None without
    #: a palm.
    object_chart_rotation: tuple[float, ...] | None = None
    #: Whether the fingertips' contact coordinates are on the object's side chart (an
    #: egg's: the problem's, or the one the planner chose because a contact rode the own
    #: chart's bound: :func:`ocp.spec.patches.side_charted`).
    object_side_chart: bool = False
    #: Where the fingertips' contacts change chart (the problem's
    #: :class:`~ocp.spec.chart_switch.ChartSwitchSpec`, its time a node of the grid):
    #: their coordinates are on the problem's charts before it and on the switch's from
    #: it on (:mod:`ocp.transcription.chart_switch`); None: one chart throughout.
    chart_switch: Any = None
    _interpolant: _Interpolant | None = field(default=None, repr=False, compare=False)

    @property
    def ok(self) -> bool:
        return self.status is Status.SOLVED

    @property
    def iterations(self) -> int:
        """IPOPT iterations of the whole plan (``stats.iterations``)."""
        return self.stats.iterations if self.stats is not None else 0

    @property
    def build_time(self) -> float:
        """Building the NLPs and solvers the plan needed [s] (``stats.build_time``)."""
        return self.stats.build_time if self.stats is not None else 0.0

    @property
    def ipopt_time(self) -> float:
        """The IPOPT calls of the whole plan [s] (``stats.ipopt_time``)."""
        return self.stats.ipopt_time if self.stats is not None else 0.0

    @property
    def refinements(self) -> int:
        """Grid refinements after the first solve (``stats.refinements``)."""
        return self.stats.refinements if self.stats is not None else 0

    @property
    def primal_infeasibility(self) -> float | None:
        """The returned point's largest bound violation (``stats.primal_infeasibility``)."""
        return self.stats.primal_infeasibility if self.stats is not None else None

    @property
    def dual_infeasibility(self) -> float | None:
        """The returned point's largest Lagrangian-gradient entry
        (``stats.dual_infeasibility``)."""
        return self.stats.dual_infeasibility if self.stats is not None else None

    @property
    def converged(self) -> bool:
        """Whether IPOPT converged (``raw_status``), certified or not: an uncertified
        re-plan (:func:`~ocp.solve.attempt.attempt`) that converged is ``inaccurate`` by
        status (only a certificate makes a plan ``solved``) and ``converged`` here."""
        return self.raw_status in _CONVERGED

    @property
    def warm_start(self) -> WarmStart:
        """This plan as the initial guess of another (its collocation points' states and
        inputs, and IPOPT's primal-dual point for a plan of the same NLP)."""
        return WarmStart(self.t, self.X, self.U, self.nlp_point)

    @property
    def duration(self) -> float:
        return float(self.t[-1])

    @property
    def trajectory(self) -> HermiteInterpolant:
        """The returned trajectory as polynomials (the one the certificate checked)."""
        if self._interpolant is None:
            raise ValueError("this plan has no collocation polynomials (non-finite values)")
        return self._interpolant.traj

    def _times(self, t: FloatArray | list[float]) -> FloatArray:
        t = np.atleast_1d(np.asarray(t, dtype=float))
        if np.any((t < -1e-12) | (t > self.duration + 1e-12)):
            raise ValueError(f"sample times must lie in [0, {self.duration}] s")
        return np.clip(t, 0.0, self.duration)

    def interpolate(self, t: FloatArray | list[float], side: str = "right"
                    ) -> tuple[FloatArray, FloatArray]:
        """(states, inputs) at any times in [0, duration], rows, from the returned
        polynomials (:class:`~ocp.transcription.collocation.HermiteInterpolant`): each
        interval's cubic Hermite polynomial of the states and quadratic of the inputs. A
        time on a via-point node gets the outgoing values (``side="left"``: the incoming)."""
        traj, ts = self.trajectory, self._times(t)
        return traj(ts, side=side), traj.inputs(ts, side=side)

    def sample(self, t: FloatArray | list[float], side: str = "right") -> GraspSample:
        """The plan at any times in [0, duration] (:meth:`interpolate`), with the states'
        rates and accelerations (the polynomials' derivatives) and the object's pose."""
        traj, ts = self.trajectory, self._times(t)
        assert self._interpolant is not None
        k, s = traj.locate(ts, side)
        return self._interpolant.describe(ts, k, traj.on_intervals(k, s),
                                          traj.on_intervals(k, s, 1),
                                          traj.on_intervals(k, s, 2),
                                          traj.inputs_on_intervals(k, s))


    def forces(self, t: FloatArray | list[float], side: str = "right"
               ) -> tuple[FloatArray, FloatArray]:
        """The planned contact forces at any times (:class:`PlannedForces`, quadratic on
        each interval): (forces (len x contacts x 3) [N], palm frame, the force each
        contact's body exerts on the object; torsions (len x contacts) [N m]).
        ValueError for a plan without forces."""
        col = self.collocation
        if col is None or col.forces is None:
            raise ValueError("this plan has no forces (plan with ManipulationProblem.forces)")
        k, s = self.trajectory.locate(self._times(t), side)
        return col.forces.on_intervals(k, s)

    def joint_torques(self, t: FloatArray | list[float], side: str = "right"
                      ) -> list[FloatArray]:
        """Every finger's joint torques at any times (:func:`joint_torques` of the planned
        forces at the returned joint angles and contact points), one (len x joints) array
        per finger."""
        f, tau = self.forces(t, side)
        smp = self.sample(t, side)
        assert self._interpolant is not None
        m = self._interpolant.m
        k = len(smp.t)
        cart = self._interpolant.cartesian(self.trajectory.locate(smp.t, side)[0], smp.x)
        pts = np.asarray(cart[4]).T.reshape(k, m.n_contacts, 3)
        nrm = np.asarray(cart[5]).T.reshape(k, m.n_contacts, 3)
        out = []
        assert self.collocation is not None and self.collocation.forces is not None
        gravity = self.collocation.forces.gravity
        for tip in m.fingertips:
            j = m.point_contacts.index(tip)
            out.append(joint_torques(tip.finger, smp.x[:, tip.q_cols], pts[:, j],
                                     nrm[:, j], f[:, j], tau[:, j], gravity))
        return out

    def break_nodes(self) -> list[int]:
        """The nodes where the input jumps (the rates have two sides): via-point nodes
        of the paper's piecewise timing. (A chart switch's node is none: its inputs are
        each interval's own chart's, the same motion.)"""
        col = self.collocation
        if col is None:
            return []
        switch = None if self._interpolant is None else self._interpolant.charts.node
        return [k for k in range(1, len(col.U0))
                if k != switch and np.any(col.U1[k - 1] != col.U0[k])]

    def joint_trajectory(self, t: FloatArray | list[float], efforts: bool = True
                         ) -> JointTrajectory:
        """Every finger's joints at times t (e.g. :func:`fixed_rate_times`) from the returned
        polynomials, with both one-sided rates at each rate break, and the joint torques of
        a plan with forces (unless ``efforts`` is false). Joint names are the model's;
        where two fingers share a name, prefixed with the finger's
        (``<finger>/<joint>``)."""
        smp = self.sample(t)
        assert self._interpolant is not None
        m = self._interpolant.m
        cols = [c for tip in m.fingertips for c in range(tip.q_cols.start, tip.q_cols.stop)]
        joint_names = trajectory_joint_names([(f.name, f.joint_names) for f in self.fingers])
        breaks = []
        traj = self.trajectory
        for k in self.break_nodes():
            tk = np.array([traj.t_nodes[k]])
            breaks.append(RateBreak(float(tk[0]), traj(tk, 1, "left")[0, cols],
                                    traj(tk, 1, "right")[0, cols]))
        torques = None
        if efforts and self.collocation is not None and self.collocation.forces is not None:
            torques = np.hstack(self.joint_torques(t))
        return JointTrajectory(joint_names, smp.t, smp.x[:, cols], smp.x_dot[:, cols],
                               smp.x_ddot[:, cols], tuple(breaks), torques)


class _Interpolant:
    """A plan's returned polynomials with its charts' models (for the object's pose):
    :class:`~ocp.transcription.chart_switch.PlanCharts`."""

    def __init__(self, charts: PlanCharts, traj: HermiteInterpolant) -> None:
        self.charts, self.traj = charts, traj

    @property
    def m(self) -> GraspModel:
        """The grasp's model (its first chart's: every chart's has the same layout)."""
        return self.charts.first

    @property
    def prm(self) -> FloatArray:
        return self.charts.prms[0]

    def cartesian(self, k: NDArray[np.intp], x: FloatArray) -> list[FloatArray]:
        """The model's ``cartesian`` at states x (rows) of intervals k."""
        return self.charts.evaluate("cartesian", self.charts.interval_charts(k), x.T)

    def describe(self, t: FloatArray, k: NDArray[np.intp], x: FloatArray, xd: FloatArray,
                 xdd: FloatArray, u: FloatArray) -> GraspSample:
        """States x, rates xd, accelerations xdd and inputs u at times t (of intervals k),
        with the object's pose."""
        k_ = len(t)
        cart = self.cartesian(k, x)
        R = np.asarray(cart[0]).T.reshape(k_, 3, 3).transpose(0, 2, 1)
        return GraspSample(t, x, u, xd, xdd, np.asarray(cart[1]).T, R)
