"""A fingertip that does not touch the object: :class:`FreeFingertip`.

Between two contacts (finger gaiting) a finger moves through the air: its state block is
its joint angles q, its inputs the joint rates q_dot, and nothing ties it to the object.
What a plan needs of it: its joint and velocity limits, the tip frame's pose from the
finger's CasADi forward kinematics (where it is, to keep it clear of the object and to
place it for the next contact), and its tip point as a law the certificate can read.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import casadi as ca
import numpy as np

from ocp.contacts.base import Contact, SymbolicGrasp, backed_off_joint_limits
from ocp.geometry.surfaces import Surface

if TYPE_CHECKING:
    from ocp.spec.grasp import Fingertip, ManipulationProblem

__all__ = ["FreeFingertip"]


class FreeFingertip(Contact):
    """Finger ``index`` of the problem's ``fingers`` off the object (``surface``: the
    object's, kept so that a free and a touching fingertip are built alike): states q,
    inputs q_dot, no contact point."""

    has_point = False
    body = "finger"

    def __init__(self, surface: Surface, finger: Any, index: int) -> None:
        super().__init__(f"finger{index}", surface)
        self.finger = finger
        self.index = index
        nq = int(finger.nq)
        self.nx = self.nu = nq
        self.joint_columns = tuple(range(nq))
        self.effort_groups = ((), (), tuple(range(nq)))
        self.tip = finger.tip_surface

    @property
    def q_cols(self) -> slice:
        """Its joints' columns in the grasp's state vector (the whole block)."""
        return self.xs

    @property
    def qd_cols(self) -> slice:
        """Its joint rates' columns in the grasp's input vector (the whole block)."""
        return self.us

    def spec(self, problem: ManipulationProblem) -> Fingertip:
        return problem.fingers[self.index]

    def label(self, problem: ManipulationProblem) -> str:
        """The name in plans and certificates: the fingertip's own, else finger<i>."""
        return self.spec(problem).name or self.name

    def x_scale(self, L: Any) -> list[Any]:
        return [1] * int(self.finger.nq)

    def u_scale(self, L: Any, T: Any) -> list[Any]:
        return [1 / T] * int(self.finger.nq)

    def rates(self, g: SymbolicGrasp, x: Any, u: Any, chart: Any) -> Any:
        """The joints move at the joint rates."""
        return u

    def tip_pose(self, g: SymbolicGrasp, x: Any) -> tuple[Any, Any]:
        """(R_pf, p_pf): the fingertip frame's pose in the palm frame at the joints x, by
        the finger's CasADi forward kinematics (the pose the touching kind's closure
        equates with the contact's)."""
        return self.finger.fk(x)

    def clearance(self, g: SymbolicGrasp, x: Any) -> Any:
        """Path rows that keep the free tip off the object (rows >= 0). Finger gaiting
        fills them with the tip's signed distance to the object (the object's pose
        ``g.R_po``, ``g.p_po``) less a margin; until then there are none (SX 0 x 1)."""
        return ca.SX(0, 1)

    def laws(self, g: SymbolicGrasp, x: Any, chart: Any) -> list[tuple[str, Any]]:
        """The tip frame's origin in the palm frame (``tip_point_<index>``, the index as
        the touching kind's laws are named), for the certificate and the plan's reader."""
        _, p_fk = self.tip_pose(g, x)
        return [(f"tip_point_{self.index}", p_fk)]

    def bounds(self, problem: ManipulationProblem) -> tuple[list[float], list[float],
                                                          list[float]]:
        """The joint limits backed off as the touching kind's
        (:func:`~ocp.contacts.base.backed_off_joint_limits`); the joints' velocity
        limits."""
        lower, upper = backed_off_joint_limits(self.finger)
        return [*lower], [*upper], [*np.asarray(self.finger.velocity_limit)]
