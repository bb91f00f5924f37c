"""A fingertip surface rolling on the object: :class:`FingertipContact`.

Its coordinates eta_i = (a_i, b_i, u_i, v_i, psi_i) (the point on the tip, the point on the
object, the contact angle) and the finger's joints q_i; its inputs w_i = d/dt (u_i, v_i)
and q_dot_i. Closure (eq. 6) ties the two: the tip frame's pose from the joints (the
finger's CasADi forward kinematics) equals its pose from the contact.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import casadi as ca
import numpy as np

from ocp.contacts.base import Contact, SymbolicGrasp, backed_off_joint_limits
from ocp.geometry.contact import ContactPair
from ocp.geometry.rotations import vee, vee_skew
from ocp.geometry.surfaces import Plane, Surface

if TYPE_CHECKING:
    from ocp.spec.grasp import Fingertip, ManipulationProblem

__all__ = ["FingertipContact"]


class FingertipContact(Contact):
    """A fingertip surface (:class:`~ocp.geometry.tips.TipSurface`: the flat pad, a sphere,
    a spheroid, a capsule's cap) fixed in a finger's tip frame, rolling on the object;
    ``index`` is the finger's place in the problem's ``fingers``. Its coordinates eta_i =
    (a_i, b_i, u_i, v_i, psi_i): the point on the tip (the pad's x, y [m]; a round tip's
    u, v [rad] in the tip's chart), the point on the object, the contact angle. The pair
    is (object, tip): Montana's equations with both curvatures (a flat pad's is zero)."""

    body = "finger"
    length_columns: tuple[int, ...] = (0, 1)
    angle_columns: tuple[int, ...] = (2, 3, 4)
    periodic_columns = (3, 4)

    def __init__(self, surface: Surface, finger: Any, index: int) -> None:
        super().__init__(f"finger{index}", surface)
        self.finger = finger
        self.index = index
        nq = int(finger.nq)
        self.nx, self.nu = 5 + nq, 2 + nq
        self.joint_columns = tuple(range(5, 5 + nq))
        self.effort_groups = ((), (0, 1), tuple(range(2, 2 + nq)))
        self.tip = finger.tip_surface
        if self.tip.round:
            self.length_columns, self.angle_columns = (), (0, 1, 2, 3, 4)
        # A = object (this contact's patch), B = the fingertip surface
        self.pair = ContactPair(surface, self.tip.surface)

    def tip_params(self) -> Any:
        """The tip surface's parameters as CasADi constants (none for the pad's plane)."""
        prm = self.tip.surface_params
        return ca.DM(prm) if prm else ca.SX(0, 1)

    def _placed(self) -> bool:
        """Whether the tip frame differs from the finger's tip (link) frame."""
        return not (np.allclose(self.tip.R, np.eye(3)) and np.allclose(self.tip.p, 0.0))

    @property
    def eta_cols(self) -> slice:
        """Its contact coordinates' columns in the grasp's state vector."""
        return slice(self.x0, self.x0 + 5)

    @property
    def q_cols(self) -> slice:
        """Its joints' columns in the grasp's state vector."""
        return slice(self.x0 + 5, self.x0 + self.nx)

    @property
    def w_cols(self) -> slice:
        """Its contact inputs' columns in the grasp's input vector."""
        return slice(self.u0, self.u0 + 2)

    @property
    def qd_cols(self) -> slice:
        """Its joint rates' columns in the grasp's input vector."""
        return slice(self.u0 + 2, self.u0 + self.nu)

    def spec(self, problem: ManipulationProblem) -> Fingertip:
        return problem.fingers[self.index]

    def label(self, problem: ManipulationProblem) -> str:
        """The name in plans and certificates: the fingertip's own, else finger<i>."""
        return self.spec(problem).name or self.name

    def x_scale(self, L: Any) -> list[Any]:
        tip = 1 if self.tip.round else L
        return [tip, tip, 1, 1, 1] + [1] * int(self.finger.nq)

    def u_scale(self, L: Any, T: Any) -> list[Any]:
        return [1 / T, 1 / T] + [1 / T] * int(self.finger.nq)

    @staticmethod
    def pair_rates(surface: Surface, e: Any, w: Any, shape: Any, tip: Any = None) -> Any:
        """The rolling equations in the pair's order (u, v, a, b, psi), driven by the
        object point's rate w: the initial guess's roll of the tip point (``tip``: the
        :class:`~ocp.geometry.tips.TipSurface`, None: the flat pad)."""
        if tip is None or not tip.surface_params:
            return ContactPair(surface, Plane if tip is None else tip.surface
                               ).rates_driven_by_a(e, w, shape, ca.SX(0, 1))
        return ContactPair(surface, tip.surface).rates_driven_by_a(
            e, w, shape, ca.DM(tip.surface_params))

    @staticmethod
    def _pair_order(eta: Any) -> Any:
        return ca.vertcat(eta[2:4], eta[0:2], eta[4])  # the pair's order (u, v, a, b, psi)

    def rates(self, g: SymbolicGrasp, x: Any, u: Any, chart: Any) -> Any:
        ed = self.pair.rates_driven_by_a(self._pair_order(x[0:5]), u[0:2], g.shape,
                                         self.tip_params())
        return ca.vertcat(ed[2:4], ed[0:2], ed[4], u[2:])

    def pad_pose(self, g: SymbolicGrasp, x: Any, chart: Any) -> tuple[Any, Any]:
        """The tip (link) frame's pose in the palm frame from the object's pose and the
        contact coordinates (eq. 6's right-hand side): the tip surface's frame from the
        contact, less the surface's placement in the tip frame."""
        R_of, p_of = self.pair.pose(self._pair_order(x[0:5]), g.shape, self.tip_params(),
                                    chart, g.eye)
        if self._placed():
            R_of = R_of @ ca.DM(self.tip.R).T
            p_of = p_of - R_of @ ca.DM(self.tip.p)
        return g.R_po @ R_of, g.p_po + g.R_po @ p_of

    def closure(self, g: SymbolicGrasp, x: Any, chart: Any) -> Any:
        """Eq. 6: the tip frame's pose from the joints (FK) equals its pose from the
        contact."""
        R_pf, p_pf = self.pad_pose(g, x, chart)
        R_fk, p_fk = self.finger.fk(x[5:])
        return ca.vertcat(p_pf - p_fk, vee_skew(R_fk.T @ R_pf))

    def point_normal(self, g: SymbolicGrasp, x: Any, chart: Any) -> tuple[Any, Any]:
        return g.point_normal(x[2:4], chart)

    def laws(self, g: SymbolicGrasp, x: Any, chart: Any) -> list[tuple[str, Any]]:
        """The finger moves by its joints (FK), the object by its pose: material points of
        both bodies at the contact; the contact's point on the object (object frame)."""
        point, normal = self.point_normal(g, x, chart)
        R_fk, p_fk = self.finger.fk(x[5:])
        R_dot, p_dot = g.dot(g.R_po), g.dot(g.p_po)
        c_pt = g.p_po + g.R_po @ point
        on_pad = R_fk.T @ (c_pt - p_fk)
        v_pad = g.dot(R_fk) @ on_pad + g.dot(p_fk)
        v_obj = R_dot @ point + p_dot
        omega_rel = vee(g.dot(R_fk) @ R_fk.T - R_dot @ g.R_po.T)
        i = self.index
        return [(f"slip_{i}", v_pad - v_obj),
                (f"spin_{i}", ca.dot(omega_rel, g.R_po @ normal)),
                *g.rolling(str(i), point, g.R_po @ normal, omega_rel),
                (f"object_point_{i}", point)]

    def bounds(self, problem: ManipulationProblem) -> tuple[list[float], list[float],
                                                          list[float]]:
        u_lim = problem.object.u_limit(problem.pole_margin)
        inf = math.inf
        (a_lo, a_hi), (b_lo, b_hi) = self.tip.bounds(problem.pad_margin, problem.pole_margin)
        lower, upper = backed_off_joint_limits(self.finger)
        return ([a_lo, b_lo, -u_lim, -inf, -inf, *lower],
                [a_hi, b_hi, u_lim, inf, inf, *upper],
                [100.0, 100.0, *np.asarray(self.finger.velocity_limit)])
