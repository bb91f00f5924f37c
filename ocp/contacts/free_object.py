"""The object's pose as a state when nothing fixes it: :class:`FreeObject`.

Its state: position p [m] (palm frame) and quaternion (w, x, y, z) (rotation R(q / |q|));
its input the twist (v [m/s] palm frame, omega [rad/s] object frame). It has no contact
point: the fingertips hold the object.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import casadi as ca
import numpy as np

from ocp.contacts.base import FloatArray, ObjectBlock, SymbolicGrasp
from ocp.geometry.rotations import quaternion_rate_sym, quaternion_rotation_sym
from ocp.geometry.surfaces import Surface
from ocp.spec.problem import MAX_POSITION

if TYPE_CHECKING:
    from ocp.spec.grasp import ManipulationProblem

__all__ = ["FreeObject"]


class FreeObject(ObjectBlock):
    """The object's pose as a state (nothing fixes it): held by the fingertips alone."""

    nx, nu = 7, 6
    has_point = False
    length_columns = (0, 1, 2)
    angle_columns = (3, 4, 5, 6)
    effort_groups = ((0, 1, 2, 3, 4, 5), (), ())

    def __init__(self, surface: Surface, name: str = "object") -> None:
        super().__init__(name, surface)

    def x_scale(self, L: Any) -> list[Any]:
        return [L, L, L, 1, 1, 1, 1]

    def u_scale(self, L: Any, T: Any) -> list[Any]:
        return [L / T] * 3 + [1 / T] * 3

    def pose(self, g: SymbolicGrasp, x: Any, chart: Any) -> tuple[Any, Any]:
        return quaternion_rotation_sym(x[3:7]), x[0:3]

    def rates(self, g: SymbolicGrasp, x: Any, u: Any, chart: Any) -> Any:
        return ca.vertcat(u[0:3], quaternion_rate_sym(x[3:7], u[3:6]))

    def initial(self, problem: ManipulationProblem) -> FloatArray:
        assert problem.initial_pose is not None
        q = np.asarray(problem.initial_pose.orientation, dtype=float)
        return np.concatenate([problem.initial_pose.position, q / np.linalg.norm(q)])

    def bounds(self, problem: ManipulationProblem) -> tuple[list[float], list[float],
                                                          list[float]]:
        hi = [MAX_POSITION] * 3 + [1.5] * 4  # the quaternion's components: not unit-bound
        return ([-h for h in hi], hi,
                [problem.max_object_speed] * 3 + [problem.max_object_rate] * 3)

