"""A manipulation plan at its collocation points on the wire (the ``trajectory`` block of
a rolling plan's result, and of each roll of a gait's)."""

from __future__ import annotations

from typing import Any

from dexroll_client.models import (
    ContactTrajectoryModel,
    FingerJointsModel,
    ManipulationTrajectoryModel,
)
from ocp.geometry.rotations import quaternion_wxyz
from ocp.solution import ManipulationSolution

from .common import all_finite, rows

__all__ = ["manipulation_trajectory"]


def manipulation_trajectory(sol: ManipulationSolution, frame: Any = None
                            ) -> ManipulationTrajectoryModel | None:
    """A manipulation plan at its collocation points (None: not planned, or a last
    iterate that is not finite). ``frame``: the rotation a gait's roll is planned in (its
    plan's object rotations R(t) are R(t) frame in the palm frame: ``GaitPlan.rotation``);
    None: the palm frame's own."""
    if sol.t.size == 0:
        return None  # not planned (a turn beyond the grasp's rolled reach)
    arrays: dict[str, Any] = {
        "t": sol.t, "object_position": sol.object_position,
        "object_rotation": sol.object_rotation, "object_velocity": sol.object_velocity,
        "object_angular_velocity": sol.object_angular_velocity,
        "grasp_angle": sol.grasp_angle, "cone_margin": sol.cone_margin}
    optional = {"desired_position": sol.desired_position,
                "desired_rotation": sol.desired_rotation,
                "tracking_position_error": sol.tracking_position_error,
                "tracking_angle_error": sol.tracking_angle_error}
    arrays.update({k: v for k, v in optional.items() if v is not None})
    for c in sol.contacts:
        arrays.update({f"{c.name}.{k}": getattr(c, k) for k in
                       ("eta", "eta_dot", "w", "point", "normal", "force_angle", "force",
                        "torsion") if getattr(c, k) is not None})
    for f in sol.fingers:
        arrays.update({f"{f.name}.{k}": getattr(f, k) for k in
                       ("q", "q_dot", "tip_position", "tip_rotation", "joint_torques")
                       if getattr(f, k) is not None})
    if not all_finite(arrays):
        return None  # JSON has no NaN; a diverged last iterate is reported by its status
    return ManipulationTrajectoryModel(
        t=rows(sol.t), object_position=rows(sol.object_position),
        object_orientation_wxyz=rows(quaternion_wxyz(
            sol.object_rotation if frame is None else sol.object_rotation @ frame)),
        object_velocity=rows(sol.object_velocity),
        object_angular_velocity=rows(sol.object_angular_velocity),
        contacts=[ContactTrajectoryModel(
            name=c.name, body="palm" if c.body == "palm" else "finger", eta=rows(c.eta),
            eta_dot=rows(c.eta_dot), w=rows(c.w), point=rows(c.point),
            normal=rows(c.normal), force_angle=rows(c.force_angle),
            force=None if c.force is None else rows(c.force),
            torsion=None if c.torsion is None else rows(c.torsion))
            for c in sol.contacts],
        fingers=[FingerJointsModel(
            name=f.name, joint_names=list(f.joint_names), q=rows(f.q), q_dot=rows(f.q_dot),
            tip_position=rows(f.tip_position),
            tip_orientation_wxyz=rows(quaternion_wxyz(f.tip_rotation)),
            joint_torques=None if f.joint_torques is None else rows(f.joint_torques))
            for f in sol.fingers],
        grasp_angle=rows(sol.grasp_angle), cone_margin=rows(sol.cone_margin),
        desired_position=None if sol.desired_position is None else
        rows(sol.desired_position),
        desired_orientation_wxyz=None if sol.desired_rotation is None else
        rows(quaternion_wxyz(sol.desired_rotation)),
        tracking_position_error=None if sol.tracking_position_error is None else
        rows(sol.tracking_position_error),
        tracking_angle_error=None if sol.tracking_angle_error is None else
        rows(sol.tracking_angle_error))
