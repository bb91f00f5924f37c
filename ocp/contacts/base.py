"""The base of the contact kinds: a contact is one block of a grasp's states and inputs.

Each kind of contact is one class that owns its CasADi model (learnt from Crocoddyl's
``ContactModelMultiple.addContact``): its slice of the states and inputs and their scales,
its rolling equations, its contact point and normal (for force closure), its path rows
(closure), its laws for the certificate, its bounds and its initial state. The grasp model
(:class:`ocp.transcription.grasp_model.GraspModel`) only loops over the contacts. What is
not a model lives in the layers that use it: the initial guesses of each kind in
:mod:`ocp.solve.contact_guesses`, the certificate's checks of each kind in
:mod:`ocp.solve.contact_checks`.

:class:`SymbolicGrasp` is what the contacts of one grasp share while their expressions are
built; :class:`ObjectBlock` is a contact that says where the object is.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import casadi as ca
import numpy as np
from numpy.typing import NDArray

from ocp.geometry.surfaces import Surface

if TYPE_CHECKING:
    from ocp.spec.grasp import ManipulationProblem

__all__ = ["JOINT_LIMIT_MARGIN", "Contact", "ObjectBlock", "SymbolicGrasp",
           "backed_off_joint_limits"]

FloatArray = NDArray[np.float64]

#: Joint limits are imposed this far inside [rad or m] at the collocation points.
JOINT_LIMIT_MARGIN = 1e-4


def backed_off_joint_limits(finger: Any) -> tuple[FloatArray, FloatArray]:
    """A finger's joint limits backed off by :data:`JOINT_LIMIT_MARGIN` (at most 1 % of a
    joint's range), the bounds at the collocation points: so that the motion between them
    (checked by the certificate) stays inside the limits themselves."""
    lower, upper = np.asarray(finger.lower), np.asarray(finger.upper)
    back = np.minimum(JOINT_LIMIT_MARGIN, 0.01 * (upper - lower))
    return lower + back, upper - back


@dataclass
class SymbolicGrasp:
    """What the contacts of one grasp share while their CasADi expressions are built: the
    object's surface and shape parameters, the object's pose (set by the object block) and,
    for the certificate's laws, the state's time derivative ``xd`` along which
    :meth:`dot` differentiates."""

    surface: Surface
    shape: Any
    x: Any
    xd: Any
    R_po: Any = None
    p_po: Any = None
    none: Any = field(default_factory=lambda: ca.SX(0, 1))
    eye: Any = field(default_factory=lambda: ca.SX.eye(3))

    def dot(self, expr: Any) -> Any:
        """d/dt of an expression of the state, along ``xd``."""
        return ca.reshape(ca.jtimes(ca.vec(expr), self.x, self.xd), expr.size1(),
                          expr.size2())

    def rolling(self, key: str, point: Any, normal: Any, omega_rel: Any
                ) -> list[tuple[str, Any]]:
        """The scales of a contact's slip and spin: the speed of the contact point (object
        frame ``point``) in the palm frame, and the rolling rate (the relative angular
        velocity's part tangent to the surfaces, palm-frame ``normal``)."""
        rolling = omega_rel - ca.dot(omega_rel, normal) * normal
        return [(f"contact_speed_{key}", ca.norm_2(self.dot(self.p_po + self.R_po @ point))),
                (f"rolling_rate_{key}", ca.norm_2(rolling))]

    def point_normal(self, uv: Any, chart: Any) -> tuple[Any, Any]:
        """The object's point at chart coordinates uv and its outward normal (object
        frame) in a contact's chart patch rotated by ``chart``."""
        pc, Rg, _, _, _ = self.surface.geometry(uv, self.shape)
        return chart @ pc, chart @ Rg[:, 2]


class Contact(ABC):
    """One block of a grasp's states and inputs: see the module's doc. A contact whose
    ``has_point`` is true touches the object (its ``point_normal`` is a row of the
    force-closure contacts); a contact's ``body`` says what touches it."""

    #: states and inputs of the block
    nx: int = 0
    nu: int = 0
    #: whether it touches the object at a point (a row of the force-closure contacts)
    has_point: bool = True
    #: block columns by kind: lengths [m] (scaled by the object's size), angles [rad] and
    #: joints, for the certificate's re-integration defects
    length_columns: tuple[int, ...] = ()
    angle_columns: tuple[int, ...] = ()
    joint_columns: tuple[int, ...] = ()
    #: angle columns defined modulo 2 pi (their defects are wrapped)
    periodic_columns: tuple[int, ...] = ()
    #: input columns by the objective's effort group: 0 the object's own motion, 1 the
    #: fingertips' motion over the object, 2 the joint rates
    effort_groups: tuple[tuple[int, ...], tuple[int, ...], tuple[int, ...]] = ((), (), ())

    def __init__(self, name: str, surface: Surface) -> None:
        self.name = name
        self.surface = surface
        self.x0 = 0  # where the block starts in the grasp's state vector
        self.u0 = 0  # ... and in its input vector

    #: what touches the object ("palm", "finger"; "object" for the free object; a free
    #: fingertip's "finger" touches nothing)
    body: str = "object"

    @property
    def xs(self) -> slice:
        return slice(self.x0, self.x0 + self.nx)

    @property
    def us(self) -> slice:
        return slice(self.u0, self.u0 + self.nu)

    @property
    def eta_cols(self) -> slice:
        """Its contact coordinates' columns in the grasp's state vector."""
        return self.xs

    @property
    def w_cols(self) -> slice:
        """Its contact inputs' columns in the grasp's input vector."""
        return self.us

    def label(self, problem: ManipulationProblem) -> str:
        """Its name in plans and certificates."""
        return self.name

    @abstractmethod
    def x_scale(self, L: Any) -> list[Any]:
        """Scale of each state (L: the object's length scale)."""

    @abstractmethod
    def u_scale(self, L: Any, T: Any) -> list[Any]:
        """Scale of each input (T: the horizon)."""

    @abstractmethod
    def rates(self, g: SymbolicGrasp, x: Any, u: Any, chart: Any) -> Any:
        """d/dt of the block's states (its rolling equations)."""

    def point_normal(self, g: SymbolicGrasp, x: Any, chart: Any) -> tuple[Any, Any]:
        """Contact point and the object's outward normal there, object frame."""
        raise NotImplementedError(f"{type(self).__name__} has no contact point")

    def laws(self, g: SymbolicGrasp, x: Any, chart: Any) -> list[tuple[str, Any]]:
        """Named expressions of (x, x_dot) the certificate checks."""
        return []

    @abstractmethod
    def bounds(self, problem: ManipulationProblem) -> tuple[list[float], list[float],
                                                          list[float]]:
        """(state lower, state upper, input magnitude) bounds, physical units."""


class ObjectBlock(Contact):
    """A contact that says where the object is (first in a grasp)."""

    @abstractmethod
    def pose(self, g: SymbolicGrasp, x: Any, chart: Any) -> tuple[Any, Any]:
        """(R_po, p_po): the object's pose in the palm frame."""

    @abstractmethod
    def initial(self, problem: ManipulationProblem) -> FloatArray:
        """The block's state at t = 0."""

