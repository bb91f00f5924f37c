"""Results of a plan: typed status, trajectories, certificate."""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import StrEnum
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from .certificate import Certificate
from .collocation import WarmStart

if TYPE_CHECKING:
    from .grasp_solution import ManipulationSolution

__all__ = ["Solution", "SolverStats", "Status", "Trajectory", "quaternion_wxyz",
           "status_from_ipopt"]

FloatArray = NDArray[np.float64]


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


def status_from_ipopt(raw: str) -> Status:
    """Map IPOPT's return status to ours; anything unlisted is a numerical error."""
    return _IPOPT_STATUS.get(raw, Status.NUMERICAL_ERROR)


def quaternion_wxyz(R: FloatArray) -> FloatArray:
    """Unit quaternion (w, x, y, z), w >= 0, of rotation matrices R (..., 3, 3)."""
    R = np.asarray(R, dtype=float)
    flat = R.reshape(-1, 3, 3)
    out = np.empty((flat.shape[0], 4))
    for i, m in enumerate(flat):
        tr = np.trace(m)
        if tr > 0:
            s = 2.0 * np.sqrt(tr + 1.0)
            q = [0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s,
                 (m[1, 0] - m[0, 1]) / s]
        else:
            j = int(np.argmax(np.diag(m)))
            a, b = (j + 1) % 3, (j + 2) % 3
            s = 2.0 * np.sqrt(1.0 + m[j, j] - m[a, a] - m[b, b])
            q = [0.0] * 4
            q[0] = (m[b, a] - m[a, b]) / s
            q[1 + j] = 0.25 * s
            q[1 + a] = (m[a, j] + m[j, a]) / s
            q[1 + b] = (m[b, j] + m[j, b]) / s
        qa = np.array(q)
        out[i] = qa if qa[0] >= 0 else -qa
    return out.reshape((*R.shape[:-2], 4))


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

    def to_dict(self) -> dict[str, Any]:
        return dict(self.__dict__)


@dataclass(frozen=True)
class Solution:
    """A plan: status, the NLP's own grid, interpolation on any grid, certificate."""

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
