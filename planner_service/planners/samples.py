"""A plan at a controller's times: the request's ``sample_times`` or ``sample_rate``, the
``samples`` block and the ROS-shaped ``joint_trajectory`` of every planner with fingers.

Everything comes from the plan's returned polynomials
(:attr:`ocp.solution.ManipulationSolution.trajectory`), the trajectory its certificate
checked: states on each interval a cubic Hermite polynomial, their rates and accelerations
its derivatives (docs/conventions.md, "The returned trajectory").
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from dexroll_client.models import (
    ContactSamplesModel,
    DurationModel,
    FingerSamplesModel,
    JointTrajectoryModel,
    JointTrajectoryPointModel,
    PlanSamplesModel,
    RateBreakModel,
)
from ocp.geometry.rotations import quaternion_wxyz
from ocp.solution import ManipulationSolution, fixed_rate_times

from .common import rows

__all__ = ["joint_trajectory_block", "joint_trajectory_model", "requested_times", "samples_block"]


def requested_times(request: Any) -> NDArray[np.float64] | None:
    """The request's sample times: ``sample_rate``'s fixed-rate times, ``sample_times``,
    or None."""
    rate = getattr(request, "sample_rate", None)
    if rate is not None:
        return fixed_rate_times(float(request.duration), float(rate))
    times = getattr(request, "sample_times", None)
    return np.asarray(times, dtype=float) if times else None


def _finite(*arrays: Any) -> bool:
    return all(np.all(np.isfinite(np.asarray(a, dtype=float))) for a in arrays)


def samples_block(plan: ManipulationSolution | None, times: NDArray[np.float64] | None
                  ) -> PlanSamplesModel | None:
    """Every contact's coordinates and every finger's joints (angles, rates,
    accelerations) and the object's pose at ``times``; None without times or a finite
    plan."""
    if times is None or plan is None or plan._interpolant is None:
        return None
    smp = plan.sample(times)
    if not _finite(smp.x, smp.x_dot, smp.x_ddot, smp.object_position):
        return None
    m = plan._interpolant.m
    forces: Any = None
    torques: list[Any] = [None] * len(plan.fingers)
    if plan.collocation is not None and plan.collocation.forces is not None:
        forces = plan.forces(times)[0]
        torques = [rows(tau) for tau in plan.joint_torques(times)]
    contacts = [ContactSamplesModel(name=c.name, eta=rows(smp.x[:, mc.eta_cols]),
                                    eta_dot=rows(smp.x_dot[:, mc.eta_cols]),
                                    force=None if forces is None else rows(forces[:, j]))
                for j, (c, mc) in enumerate(zip(plan.contacts, m.point_contacts,
                                                strict=True))]
    fingers = [FingerSamplesModel(name=f.name, joint_names=list(f.joint_names),
                                  q=rows(smp.x[:, tip.q_cols]),
                                  q_dot=rows(smp.x_dot[:, tip.q_cols]),
                                  q_ddot=rows(smp.x_ddot[:, tip.q_cols]),
                                  joint_torques=tau)
               for f, tip, tau in zip(plan.fingers, m.fingertips, torques, strict=True)]
    return PlanSamplesModel(t=rows(smp.t), object_position=rows(smp.object_position),
                            object_orientation_wxyz=rows(quaternion_wxyz(
                                smp.object_rotation)),
                            contacts=contacts, fingers=fingers)


def joint_trajectory_block(plan: ManipulationSolution | None,
                           times: NDArray[np.float64] | None) -> JointTrajectoryModel | None:
    """Every finger's joints as ROS 2's ``trajectory_msgs/JointTrajectory`` at ``times``
    (None: the plan's collocation points); None without fingers or a finite plan."""
    if plan is None or plan._interpolant is None or not plan.fingers:
        return None
    jt = plan.joint_trajectory(plan.t if times is None else times)
    if not _finite(jt.positions, jt.velocities, jt.accelerations):
        return None
    tips = [c.name for c in plan.contacts if c.body != "palm"]  # one phase: all touch
    return joint_trajectory_model(jt, [tips] * len(jt.t))


def joint_trajectory_model(jt: Any, touching: list[list[str]] | None = None
                           ) -> JointTrajectoryModel:
    """The wire form of the core's :class:`~ocp.solution.JointTrajectory` (its
    ``to_dict``: ROS 2's fields), with the fingertips ``touching`` at each point."""
    d = jt.to_dict()
    return JointTrajectoryModel(
        joint_names=d["joint_names"],
        points=[JointTrajectoryPointModel(
            positions=p["positions"], velocities=p["velocities"],
            accelerations=p["accelerations"],
            time_from_start=DurationModel(**p["time_from_start"]), t=p["t"],
            effort=p.get("effort"), touching=None if touching is None else touching[k])
            for k, p in enumerate(d["points"])],
        rate_breaks=[RateBreakModel(**b) for b in d["rate_breaks"]])
