"""Force closure's rows at one collocation point, by how many contacts touch the object.

What "the grasp can resist any wrench, inside the friction cones" asks of the NLP depends
on the number of active point contacts, not on their kinds: one contact has no condition
(the palm alone carries the object), two need the antipodal condition on their grasp
angles (eq. 7 of the paper: each contact's normal within the cone of the line joining
them), three or more the internal-force condition (:mod:`ocp.geometry.force_closure`:
internal forces in equilibrium, each inside its cone with a margin). Each condition says
which variables a point needs for it (the grasp-angle epigraph, three internal-force
components per contact) and adds its rows; the transcription picks one per phase with
:func:`grasp_condition` and never branches on the count itself.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import casadi as ca

from ocp.geometry.grasp import grasp_cosines

__all__ = ["AddRow", "AntipodalCondition", "GraspCondition", "InternalForceCondition",
           "NoCondition", "grasp_condition"]

#: add(expression, lower, upper): append rows to a point block
AddRow = Callable[[Any, float, float], None]


class GraspCondition:
    """No force-closure rows (one contact)."""

    #: grasp-angle epigraph variables s >= 1 - cos(Phi_i) at a point
    n_epigraph: int = 0
    #: whether the point has three internal-force variables per contact
    internal_forces: bool = False

    def rows(self, add: AddRow, P: Any, N: Any, s: Any, f: Any, ccone: Any, L: Any,
             nc: int) -> None:
        """Add the rows at one point: ``P``, ``N`` the active contacts' points and outward
        normals (object frame, 3 x nc), ``s`` the epigraph, ``f`` the internal forces (3
        per contact, scaled), ``ccone`` the cone's cosine with its margin, ``L`` the
        object's size."""


class NoCondition(GraspCondition):
    pass


class AntipodalCondition(GraspCondition):
    """Two contacts: each one's normal within the friction cone (with a margin) of the
    line joining them; the epigraph bounds 1 - cos of both grasp angles."""

    n_epigraph = 1

    def rows(self, add: AddRow, P: Any, N: Any, s: Any, f: Any, ccone: Any, L: Any,
             nc: int) -> None:
        c1, c2, dist = grasp_cosines(P[:, 0], N[:, 0], P[:, 1], N[:, 1])
        add(ca.vertcat(c1 - dist * ccone, c2 - dist * ccone) / L, 0.0, math.inf)
        add(ca.vertcat(s - (1 - c1 / dist), s - (1 - c2 / dist)), 0.0, math.inf)


class InternalForceCondition(GraspCondition):
    """Three or more contacts: internal forces in equilibrium summing to the contacts'
    count along the normals, every contact loaded, each inside its cone with the margin;
    the epigraph bounds the worst force angle."""

    n_epigraph = 1
    internal_forces = True

    def rows(self, add: AddRow, P: Any, N: Any, s: Any, f: Any, ccone: Any, L: Any,
             nc: int) -> None:
        from ocp.geometry.force_closure import PUSH_FLOOR, internal_force_residuals

        eq, push, norms = internal_force_residuals(P, N, ca.reshape(f, 3, nc), L)
        add(eq, 0.0, 0.0)
        add(ca.sum1(push) - nc, 0.0, 0.0)
        # every contact loaded: an unloaded one would sit in its cone for free
        add(push - PUSH_FLOOR, 0.0, math.inf)
        add(push - ccone * norms, 0.0, math.inf)
        add(push - (1 - s) * norms, 0.0, math.inf)


#: the condition of 0, 1, 2 and 3 or more active point contacts
_BY_COUNT: tuple[GraspCondition, ...] = (NoCondition(), NoCondition(), AntipodalCondition(),
                                         InternalForceCondition())


def grasp_condition(n_contacts: int) -> GraspCondition:
    """The force-closure condition of a point with ``n_contacts`` active point contacts."""
    return _BY_COUNT[min(n_contacts, len(_BY_COUNT) - 1)]
