"""The object on a fixed flat surface (the palm): :class:`SupportContact`.

Its contact coordinates eta_p = (x, y, u, v, psi) fix the object's pose (x, y [m] on the
palm, (u, v) the object's chart point, psi the contact angle); its input w_p = d/dt (x, y),
the rolling equations driven by the palm side (eq. 8 for a sphere).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import casadi as ca
import numpy as np

from ocp.contacts.base import FloatArray, ObjectBlock, SymbolicGrasp
from ocp.geometry.contact import ContactPair
from ocp.geometry.rotations import vee
from ocp.geometry.surfaces import Plane, Surface

if TYPE_CHECKING:
    from ocp.spec.grasp import ManipulationProblem

__all__ = ["SupportContact"]


class SupportContact(ObjectBlock):
    """The object on a fixed flat surface (the palm, z = 0 of the palm frame)."""

    nx, nu = 5, 2
    body = "palm"
    length_columns = (0, 1)
    angle_columns = (2, 3, 4)
    periodic_columns = (3, 4)
    effort_groups = ((0, 1), (), ())

    def __init__(self, surface: Surface, name: str = "palm") -> None:
        super().__init__(name, surface)
        self.pair = ContactPair(Plane, surface)  # A = palm, B = object

    def x_scale(self, L: Any) -> list[Any]:
        return [L, L, 1, 1, 1]

    def u_scale(self, L: Any, T: Any) -> list[Any]:
        return [L / T, L / T]

    def pose(self, g: SymbolicGrasp, x: Any, chart: Any) -> tuple[Any, Any]:
        return self.pair.pose(x, g.none, g.shape, g.eye, chart)

    def rates(self, g: SymbolicGrasp, x: Any, u: Any, chart: Any) -> Any:
        return self.pair.rates_driven_by_a(x, u, g.none, g.shape)

    def point_normal(self, g: SymbolicGrasp, x: Any, chart: Any) -> tuple[Any, Any]:
        return g.point_normal(x[2:4], chart)

    def laws(self, g: SymbolicGrasp, x: Any, chart: Any) -> list[tuple[str, Any]]:
        point, normal = self.point_normal(g, x, chart)
        R_dot, p_dot = g.dot(g.R_po), g.dot(g.p_po)
        omega = vee(R_dot @ g.R_po.T)
        return [(f"slip_{self.name}", R_dot @ point + p_dot),
                (f"spin_{self.name}", ca.dot(omega, g.R_po @ normal)),
                *g.rolling(self.name, point, g.R_po @ normal, omega)]

    def initial(self, problem: ManipulationProblem) -> FloatArray:
        assert problem.palm is not None
        return np.asarray(problem.palm.initial, dtype=float)

    def bounds(self, problem: ManipulationProblem) -> tuple[list[float], list[float],
                                                          list[float]]:
        assert problem.palm is not None
        u_lim = problem.object.u_limit(problem.pole_margin)
        ext = problem.palm.palm_half_extent
        hi = [ext, ext, u_lim, math.inf, math.inf]
        return [-h for h in hi], hi, [problem.palm.max_contact_speed] * 2
