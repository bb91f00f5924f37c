"""Contacts as model objects: a grasp is an object block and a list of fingertip contacts.

Each kind of contact is one class that owns everything about it (learnt from Crocoddyl's
``ContactModelMultiple.addContact``): its slice of the states and inputs and their scales,
its rolling equations, its contact point and normal (for force closure), its path rows
(closure), its laws for the certificate, its bounds and its initial state. The grasp model
(:class:`ocp.transcription.grasp_model.GraspModel`) and the planner only loop over the contacts.

* :class:`SupportContact`: the object resting on a fixed flat surface (the palm); its
  contact coordinates eta_p = (x, y, u, v, psi) fix the object's pose; input w_p = d/dt
  (x, y).
* :class:`FreeObject`: the object's pose as a state when nothing fixes it: position p [m]
  (palm frame) and quaternion (w, x, y, z) (rotation R(q / |q|)); input its twist (v [m/s]
  palm frame, omega [rad/s] object frame).
* :class:`FingertipContact`: a flat pad on a finger link rolling on the object: eta_i =
  (x_i, y_i, u_i, v_i, psi_i) and the finger's joints q_i; inputs w_i = d/dt (u_i, v_i)
  and q_dot_i.

The support and the free object are *object blocks* (:class:`ObjectBlock`): exactly one of
them comes first in a grasp and says where the object is; the fingertips follow.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import casadi as ca
import numpy as np
from numpy.typing import NDArray

from ocp.geometry.contact import ContactPair
from ocp.geometry.rotations import quaternion_rate_sym, quaternion_rotation_sym, vee, vee_skew
from ocp.geometry.surfaces import Plane, Surface
from ocp.spec.problem import MAX_POSITION

if TYPE_CHECKING:
    from ocp.certify.certificate import Check, TolerancePolicy
    from ocp.spec.grasp import Fingertip, ManipulationProblem

__all__ = ["Contact", "FingertipContact", "FreeObject", "ObjectBlock", "SupportContact",
           "SymbolicGrasp"]

FloatArray = NDArray[np.float64]
#: The object's pose at times t: (R (k, 3, 3), p (k, 3)), palm frame.
PoseOfTime = Callable[[FloatArray], tuple[FloatArray, FloatArray]]
#: A block's input at times t, rows.
InputOfTime = Callable[[FloatArray], FloatArray]

#: Joint limits are imposed this far inside [rad or m] at the collocation points.
JOINT_LIMIT_MARGIN = 1e-4
#: Pose tolerance of the inverse kinematics along the initial guess [m, rad], the initial
#: grasp's own. (A guess closed to 1e-8 only sent IPOPT down another path on experiment 1:
#: the same 14 iterations, one with an inertia correction, 30 % more time.)
IK_GUESS_TOL = 1e-10
#: Midpoint steps per collocation point of the integrated initial guess of a round tip on
#: a finger of fewer than six joints (:meth:`FingertipContact._integrated_guess`; its
#: closure feedback keeps it on the closure manifold). The first three four_finger_round
#: plans of the full suite: the same IPOPT iterations (25, 17, 20) with 8 and with 2, the
#: plan's wall time 11.0 / 6.9 / 7.6 s -> 7.7 / 4.3 / 5.5 s (under load).
GUESS_SUBSTEPS = 2


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


@dataclass(frozen=True)
class CertificateContext:
    """The certificate's samples of the returned trajectory that every contact's checks
    read: their times, the law outputs by name (along the trajectory's own time
    derivative), the object's pose, the fingertips' poses from the contact coordinates, the
    states, and the scales of the tolerances."""

    times: FloatArray  # (n,)
    laws: dict[str, FloatArray]
    R_po: FloatArray  # (n, 3, 3)
    p_po: FloatArray  # (n, 3)
    R_pf: FloatArray  # (n, fingers, 3, 3)
    p_pf: FloatArray  # (n, fingers, 3)
    states: FloatArray  # (n, nx)
    shape: FloatArray
    L: float
    speed: float  # the plan's speed scale [m/s] (TolerancePolicy)
    rate: float  # the plan's rolling-rate scale [rad/s]
    policy: TolerancePolicy

    def worst(self, values: FloatArray) -> tuple[float, float]:
        """(the largest value, its time) of per-sample values (NaN counts as largest)."""
        v = np.asarray(values, dtype=float).ravel()
        j = int(np.argmax(np.where(np.isnan(v), np.inf, v)))
        return float(v[j]), float(self.times[j])

    def check(self, name: str, values: FloatArray, tolerance: float, kind: Any) -> Check:
        """The check that the largest of per-sample values is at most ``tolerance``,
        naming the time of the worst sample."""
        from ocp.certify.certificate import Check

        value, t = self.worst(values)
        return Check(name, value, tolerance, kind, time=t)


class Contact(ABC):
    """One block of a grasp's states and inputs: see the module's doc."""

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

    #: what touches the object ("palm", "finger"; "object" for the free object)
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

    def checks(self, problem: ManipulationProblem, k: int, c: CertificateContext
               ) -> list[Check]:
        """The certificate's checks of this contact (k: its index among the point
        contacts)."""
        return []


class ObjectBlock(Contact):
    """A contact that says where the object is (first in a grasp)."""

    @abstractmethod
    def pose(self, g: SymbolicGrasp, x: Any, chart: Any) -> tuple[Any, Any]:
        """(R_po, p_po): the object's pose in the palm frame."""

    @abstractmethod
    def initial(self, problem: ManipulationProblem) -> FloatArray:
        """The block's state at t = 0."""

    @abstractmethod
    def guess(self, problem: ManipulationProblem, x0: FloatArray, ts: FloatArray,
              R0: FloatArray, p0: FloatArray, palm_planner: Any
              ) -> tuple[FloatArray, FloatArray, PoseOfTime, InputOfTime | None]:
        """The initial guess's object motion: the block's states and inputs at times ts
        (from its state x0 at t = 0, the object's pose (R0, p0) then), the object's pose
        as a function of time, and the block's input as one when it jumps (at via-points:
        the guess then takes both sides), else None."""


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

    def guess(self, problem: ManipulationProblem, x0: FloatArray, ts: FloatArray,
              R0: FloatArray, p0: FloatArray, palm_planner: Any
              ) -> tuple[FloatArray, FloatArray, PoseOfTime, InputOfTime | None]:
        """The plan of the object on the palm alone to the support's goal and via-points
        (the palm's strategies: loop guesses for pure reorientations, gauge bound; not
        certified: a guess), or the object at rest when the support has no goal."""
        T = problem.duration
        assert problem.palm is not None
        if problem.palm.goal or problem.palm.via_points:
            plan = palm_planner.solve(problem.palm_only(), certify=False)

            def pose(t: FloatArray) -> tuple[FloatArray, FloatArray]:
                tr = plan.sample(np.clip(t, 0.0, T))
                return tr.object_rotation, tr.object_position

            def palm_w(t: FloatArray) -> FloatArray:
                return np.asarray(plan.sample(t).u)

            smp = plan.sample(ts)
            return smp.x, smp.u, pose, palm_w

        def still(t: FloatArray) -> tuple[FloatArray, FloatArray]:
            t = np.atleast_1d(t)
            return np.tile(R0, (len(t), 1, 1)), np.tile(p0, (len(t), 1))

        return np.tile(x0, (len(ts), 1)), np.zeros((len(ts), 2)), still, None

    def bounds(self, problem: ManipulationProblem) -> tuple[list[float], list[float],
                                                          list[float]]:
        assert problem.palm is not None
        u_lim = math.pi / 2 - problem.pole_margin
        ext = problem.palm.palm_half_extent
        hi = [ext, ext, u_lim, math.inf, math.inf]
        return [-h for h in hi], hi, [problem.palm.max_contact_speed] * 2

    def checks(self, problem: ManipulationProblem, k: int, c: CertificateContext
               ) -> list[Check]:
        from ocp.certify.certificate import CheckKind

        n, pol, D = self.name, c.policy, CheckKind.DISCRETISATION
        # the object touches the palm: support function of its shape along -z (no chart)
        heights = self.surface.support_heights(-c.R_po[:, 2, :], c.shape)  # rows R^T (-e_z)
        return [
            c.check(f"max_slip_speed_{n}", np.linalg.norm(c.laws[f"slip_{n}"], axis=1),
                    pol.slip * c.speed, D),
            c.check(f"max_spin_rate_{n}", np.abs(c.laws[f"spin_{n}"]), pol.spin * c.rate, D),
            c.check(f"max_height_error_{n}", np.abs(c.p_po[:, 2] - heights),
                    pol.support_height * (c.L if pol.height_relative else 1.0),
                    CheckKind.PHYSICS),
        ]


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

    def guess(self, problem: ManipulationProblem, x0: FloatArray, ts: FloatArray,
              R0: FloatArray, p0: FloatArray, palm_planner: Any
              ) -> tuple[FloatArray, FloatArray, PoseOfTime, InputOfTime | None]:
        """The desired motion itself: its poses, its twist by central differences."""
        from ocp.geometry.rotations import quaternion_wxyz

        T = problem.duration
        assert problem.motion is not None
        motion = problem.motion
        R, pos = motion.at(ts)
        quats = quaternion_wxyz(R)
        for i in range(1, len(quats)):  # sign continuity
            if np.dot(quats[i], quats[i - 1]) < 0:
                quats[i] = -quats[i]
        if np.dot(quats[0], x0[3:7]) < 0:
            quats = -quats
        dt = 1e-5 * T
        Rp, pp = motion.at(ts + dt)
        Rn, pn = motion.at(ts - dt)
        tp, tn = np.clip(ts + dt, 0, T), np.clip(ts - dt, 0, T)
        span = (tp - tn)[:, None]
        v = (pp - pn) / span
        Wb = np.einsum("kji,kjl->kil", R, Rp - Rn) / span[:, :, None]  # R^T dR/dt
        omega = np.stack([Wb[:, 2, 1] - Wb[:, 1, 2], Wb[:, 0, 2] - Wb[:, 2, 0],
                          Wb[:, 1, 0] - Wb[:, 0, 1]], axis=1) / 2
        return np.hstack([pos, quats]), np.hstack([v, omega]), motion.at, None

    def bounds(self, problem: ManipulationProblem) -> tuple[list[float], list[float],
                                                          list[float]]:
        hi = [MAX_POSITION] * 3 + [1.5] * 4  # the quaternion's components: not unit-bound
        return ([-h for h in hi], hi,
                [problem.max_object_speed] * 3 + [problem.max_object_rate] * 3)


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
        self._rolls: dict[int, Any] = {}
        self._terms: Any = None
        self._guess_q: tuple[FloatArray, FloatArray] | None = None

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
        u_lim = math.pi / 2 - problem.pole_margin
        inf = math.inf
        (a_lo, a_hi), (b_lo, b_hi) = self.tip.bounds(problem.pad_margin, problem.pole_margin)
        # joint limits backed off at the collocation points, so that the motion between
        # them (checked by the certificate) stays inside the limits themselves
        lower, upper = np.asarray(self.finger.lower), np.asarray(self.finger.upper)
        back = np.minimum(JOINT_LIMIT_MARGIN, 0.01 * (upper - lower))
        return ([a_lo, b_lo, -u_lim, -inf, -inf, *(lower + back)],
                [a_hi, b_hi, u_lim, inf, inf, *(upper - back)],
                [100.0, 100.0, *np.asarray(self.finger.velocity_limit)])

    def roll(self, steps: int) -> Any:
        """``steps`` RK4 steps of the tip point and the contact angle (a, b, psi) while the
        object point goes along given points and rates: (c0 (3), alpha (2 x k), w0 (2 x k),
        w1 (2 x k), h (1 x k), shape (. x k)) -> c (3 x k); the initial guess's roll."""
        if steps not in self._rolls:
            np_ = self.surface.n_params
            shape_p = ca.SX.sym("shape", np_)
            e_, w_ = ca.SX.sym("e", 5), ca.SX.sym("w", 2)
            rates = ca.Function("tip_rates", [e_, w_, shape_p], [
                self.pair_rates(self.surface, e_, w_, shape_p, self.tip)])
            c_, a_ = ca.SX.sym("c", 3), ca.SX.sym("a", 2)
            w0_, w1_, h_ = ca.SX.sym("w0", 2), ca.SX.sym("w1", 2), ca.SX.sym("h")
            # one classic RK4 step (as the grasp model's for the flat pad)
            x0, wm = ca.vertcat(a_, c_), (w0_ + w1_) / 2
            k1 = rates(x0, w0_, shape_p)
            k2 = rates(x0 + h_ / 2 * k1, wm, shape_p)
            k3 = rates(x0 + h_ / 2 * k2, wm, shape_p)
            k4 = rates(x0 + h_ * k3, w1_, shape_p)
            e1 = x0 + h_ / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
            step = ca.Function("roll_step", [c_, a_, w0_, w1_, h_, shape_p], [e1[2:5]])
            self._rolls[steps] = step.mapaccum("roll", steps)
        return self._rolls[steps]

    def guess_contact(self, problem: ManipulationProblem, pose: PoseOfTime, ts: FloatArray,
                      offset: FloatArray, chart: FloatArray, shape: FloatArray,
                      roll: Any) -> tuple[FloatArray, FloatArray]:
        """The initial guess's contact coordinates and inputs at times ts: the contact point
        kept where it started relative to the object's centre (``offset``, palm frame) while
        the object moves by ``pose``; its object point by the inverse chart, its rate by
        central differences, the tip point and angle rolled along (RK4 of the rolling
        equations: ``roll``, the grasp model's for a flat pad, else this contact's own
        :meth:`roll` with its tip's curvature)."""
        if self._carries(problem):
            return self._integrated_guess(problem, pose, ts, chart, shape)
        if self.tip.round:
            roll = self.roll(len(ts) - 1)
        dt = 1e-4 * problem.duration

        def ball_point(t: FloatArray) -> FloatArray:
            R, _ = pose(t)
            pts = np.einsum("kji,j->ki", R, offset)  # R^T offset
            return np.asarray(self.surface.inverse(pts @ chart, shape))  # rows Rc^T p

        alpha = ball_point(ts)
        rate = (ball_point(ts + dt) - ball_point(ts - dt)) / (2 * dt)
        rate[:, 1] = ((rate[:, 1] * 2 * dt + np.pi) % (2 * np.pi) - np.pi) / (2 * dt)
        ef = np.zeros((len(ts), 5))
        ef[:, 2:4] = alpha
        ef[0] = self.spec(problem).initial
        pad = np.asarray(roll(  # the pad point and angle, RK4 steps
            ef[0, [0, 1, 4]], alpha[:-1].T, rate[:-1].T, rate[1:].T, np.diff(ts)[None],
            np.tile(shape[:, None], (1, len(ts) - 1)))).T
        ef[1:, 0:2], ef[1:, 4] = pad[:, 0:2], pad[:, 2]
        return ef, rate

    def _carries(self, problem: ManipulationProblem) -> bool:
        """Whether the initial guess is the integrated one (:meth:`_integrated_guess`): a
        round tip on a finger of fewer than 6 joints, whose joints cannot follow the 6-D
        poses of a tip rolled along a made-up contact path (closure would break)."""
        return self.tip.round and int(self.finger.nq) < 6

    def _closure_terms(self) -> Any:
        """CasADi function (eta, q, R_po, p_po, chart, shape) -> (C, C_eta E, C_q,
        C_R, C_p): the closure residual, its derivative along the contact inputs w
        (eta_dot = E w), along the joints, and along vec(R_po) and p_po."""
        if self._terms is None:
            nq = int(self.finger.nq)
            e, q = ca.SX.sym("eta", 5), ca.SX.sym("q", nq)
            R, p = ca.SX.sym("R", 3, 3), ca.SX.sym("p", 3)
            chart = ca.SX.sym("chart", 3, 3)
            shape = ca.SX.sym("shape", self.surface.n_params)
            w = ca.SX.sym("w", 2)
            x = ca.vertcat(e, q)
            g = SymbolicGrasp(self.surface, shape, x, ca.SX.sym("xd", 5 + nq), R_po=R, p_po=p)
            C = self.closure(g, x, chart)
            ed = self.rates(g, x, ca.vertcat(w, ca.SX.zeros(nq)), chart)[0:5]
            E = ca.jacobian(ed, w)
            self._terms = ca.Function("closure_terms", [e, q, R, p, chart, shape], [
                C, ca.jacobian(C, e) @ E, ca.jacobian(C, q), ca.jacobian(C, ca.vec(R)),
                ca.jacobian(C, p), E])
        return self._terms

    def _integrated_guess(self, problem: ManipulationProblem, pose: PoseOfTime,
                          ts: FloatArray, chart: FloatArray, shape: FloatArray
                          ) -> tuple[FloatArray, FloatArray]:
        """A guess that rolls and closes: from the initial grasp (its joints by inverse
        kinematics), the contact inputs w and the joint rates that keep closure along the
        object's motion (d/dt closure = 0, solved at each step for (w, q_dot): six
        equations in 2 + nq unknowns, the least-norm solution, a feedback on the closure
        residual), integrated with small steps; the joints are clipped into their limits.
        The joints are kept for :meth:`guess_joints`."""
        from ocp.robots.finger import PAPER_SEED, inverse_kinematics

        f, spec = self.finger, self.spec(problem)
        nq = int(f.nq)
        terms = self._closure_terms()
        e = np.asarray(spec.initial, dtype=float)
        R0, p0 = pose(np.asarray(ts[:1], dtype=float))
        # the initial grasp's joints: IK of the tip frame where the contact puts it
        g0 = SymbolicGrasp(self.surface, ca.DM(shape), ca.DM(0, 1), ca.DM(0, 1),
                           R_po=ca.DM(R0[0]), p_po=ca.DM(p0[0]), none=ca.DM(0, 1),
                           eye=ca.DM.eye(3))
        R_l, p_l = (ca.evalf(a) for a in self.pad_pose(g0, ca.DM(e), ca.DM(chart)))
        seed = np.asarray(spec.q_seed if spec.q_seed is not None else
                          PAPER_SEED[:nq], dtype=float)
        q = inverse_kinematics(f, np.asarray(R_l), np.asarray(p_l).ravel(), seed).q.copy()
        n_sub = GUESS_SUBSTEPS
        qs = np.zeros((len(ts), nq))
        ef = np.zeros((len(ts), 5))
        W = np.zeros((len(ts), 2))
        qs[0], ef[0] = q, e

        def inputs(t: float, e: FloatArray, q: FloatArray) -> tuple[FloatArray, FloatArray,
                                                                    FloatArray]:
            dt = 1e-5 * problem.duration
            Rm, pm = pose(np.array([t - dt, t, t + dt]))
            C, Aw, Aq, CR, Cp, E = (np.asarray(a) for a in terms(
                e, q, Rm[1], pm[1], chart, shape))
            Rd = (Rm[2] - Rm[0]) / (2 * dt)
            pd = (pm[2] - pm[0]) / (2 * dt)
            rhs = -(CR @ Rd.ravel(order="F") + Cp @ pd) - 10.0 / problem.duration * \
                C.ravel()
            A = np.hstack([Aw, Aq])
            sol = A.T @ np.linalg.solve(A @ A.T + 1e-12 * np.eye(6), rhs)
            w, qd = sol[:2], sol[2:]
            return w, (E @ w).ravel(), qd

        for k in range(len(ts) - 1):
            h = (ts[k + 1] - ts[k]) / n_sub
            t = float(ts[k])
            for _ in range(n_sub):  # midpoint steps
                _, ed, qd = inputs(t, e, q)
                em, qm = e + h / 2 * ed, np.clip(q + h / 2 * qd, f.lower, f.upper)
                _, ed, qd = inputs(t + h / 2, em, qm)
                e, q = e + h * ed, np.clip(q + h * qd, f.lower, f.upper)
                t += h
            W[k] = inputs(float(ts[k]), ef[k], qs[k])[0]
            ef[k + 1], qs[k + 1] = e, q
        W[-1] = inputs(float(ts[-1]), ef[-1], qs[-1])[0]
        self._guess_q = (np.asarray(ts, dtype=float).copy(), qs)
        return ef, W

    def guess_joints(self, R: FloatArray, p: FloatArray, q0: FloatArray, ts: FloatArray
                     ) -> tuple[FloatArray, FloatArray]:
        """The joints (and their rates, by differences) that put the pad at the poses
        (R (k, 3, 3), p (k, 3)) at times ts: one batched inverse kinematics from the initial
        grasp's joints q0, and a sequential one from the previous point's where that does
        not converge."""
        from ocp.robots.finger import inverse_kinematics, inverse_kinematics_batch

        kept = self._guess_q
        if kept is not None and kept[0].shape == np.shape(ts) and np.allclose(kept[0], ts):
            qs = kept[1].copy()
            qs[0] = q0
            self._guess_q = None
            return qs, np.gradient(qs, ts, axis=0)
        qs, ok = inverse_kinematics_batch(self.finger, R, p, q0, tol=IK_GUESS_TOL)
        qs[0] = q0
        for j in (np.flatnonzero(~ok[1:]) + 1).tolist():  # from a neighbour instead
            qs[j] = inverse_kinematics(self.finger, R[j], p[j], qs[j - 1],
                                       tol=IK_GUESS_TOL).q
        return qs, np.gradient(qs, ts, axis=0)

    def checks(self, problem: ManipulationProblem, k: int, c: CertificateContext
               ) -> list[Check]:
        """Slip and spin (the laws along the returned trajectory), and from Pinocchio's
        forward kinematics at the returned joint angles (point by point, independent of the
        NLP's CasADi kinematics): closure (the pad where the contact coordinates put it)
        and the gap (the pad's plane tangent to the object); the pad and joint limits."""
        from ocp.certify.certificate import CheckKind

        i, f, name, pol = self.index, self.finger, self.label(problem), c.policy
        q_i = c.states[:, self.q_cols]
        poses = [f.fingertip_pose_pin(q) for q in q_i]  # Pinocchio, point by point
        R_pin = np.array([pose[0] for pose in poses])
        p_pin = np.array([pose[1] for pose in poses])
        # the angle between the two rotations, well conditioned near 0 (an arccos of the
        # trace would be noise below ~1e-8 rad): |R1 - R2|_F = 2 sqrt 2 sin(angle / 2)
        diff = np.linalg.norm((R_pin - c.R_pf[:, i]).reshape(len(R_pin), 9), axis=1)
        angle = 2 * np.arcsin(np.minimum(1.0, diff / (2 * math.sqrt(2))))
        # the tip surface's tangent plane at its contact point (Pinocchio's pose of the tip
        # frame, the tip's chart at the returned coordinates) is tangent to the object: the
        # object's centre lies its support height (along the tip's normal) above it; for
        # the flat pad that plane is the pad's
        tip, n_s = self.tip, len(R_pin)
        ab = c.states[:, self.eta_cols][:, 0:2]
        geo = tip.surface.geometry.map(n_s)(ab.T, np.tile(np.asarray(
            tip.surface_params, dtype=float).reshape(-1, 1), (1, n_s)))
        f_t = np.asarray(geo[0]).T  # (n, 3) the tip point, tip surface frame
        z_t = np.asarray(geo[1]).reshape(3, n_s, 3)[:, :, 2].T  # (n, 3) its normal
        R_lt = R_pin @ tip.R  # the tip surface's frame in the palm
        tip_pt = p_pin + np.einsum("kij,kj->ki", R_lt, f_t) + R_pin @ tip.p
        tip_n = np.einsum("kij,kj->ki", R_lt, z_t)
        h = self.surface.support_heights(np.einsum("kji,kj->ki", c.R_po, -tip_n), c.shape)
        gap = np.einsum("ki,ki->k", tip_n, c.p_po - tip_pt) - h
        D = CheckKind.DISCRETISATION
        obj_pt = c.p_po + np.einsum("kij,kj->ki", c.R_po, c.laws[f"object_point_{i}"])
        # the object's contact point in the tip surface's frame
        on_tip = np.einsum("kji,kj->ki", R_lt, obj_pt - p_pin - R_pin @ tip.p)
        if tip.kind == "pad":
            excursion = np.max(np.abs(on_tip[:, 0:2]), axis=1)
            excursion_name, limit = f"max_pad_excursion_{name}", float(f.pad_half_size)
        elif tip.kind == "capsule":
            # how far (as an angle) the contact lies from the cap's end (the tip frame's
            # -y): the cap is the hemisphere within pi/2 of it, the cylinder beyond
            d = on_tip / np.maximum(np.linalg.norm(on_tip, axis=1, keepdims=True), 1e-15)
            excursion = np.arccos(np.clip(-d[:, 1], -1.0, 1.0))
            excursion_name, limit = f"max_cap_angle_{name}", math.pi / 2
        else:  # a whole sphere or spheroid: the tip's pole bound, a property of its chart
            uv = tip.surface.inverse(on_tip, np.asarray(tip.surface_params, dtype=float))
            excursion = np.abs(uv[:, 0])
            excursion_name, limit = f"max_tip_latitude_{name}", math.pi / 2
        return [
            c.check(f"max_slip_speed_{name}", np.linalg.norm(c.laws[f"slip_{i}"], axis=1),
                    pol.slip * c.speed, D),
            c.check(f"max_spin_rate_{name}", np.abs(c.laws[f"spin_{i}"]), pol.spin * c.rate,
                    D),
            c.check(f"max_gap_error_{name}", np.abs(gap), pol.gap, D),
            c.check(excursion_name, excursion, limit, CheckKind.LIMITS),
            c.check(f"max_joint_limit_violation_{name}", np.maximum(np.max(np.maximum(
                q_i - f.upper, f.lower - q_i), axis=1), 0.0), pol.joint_limit, D),
            c.check("max_closure_position_error", np.linalg.norm(p_pin - c.p_pf[:, i],
                                                                  axis=1),
                    pol.closure_position, D),
            c.check("max_closure_orientation_error", angle, pol.closure_orientation, D),
        ]


def grasp_contacts(shape_surface: Surface, palm: bool, fingers: tuple[Any, ...]
                   ) -> tuple[Contact, ...]:
    """The contacts of a grasp structure, offsets set: the object block, then each
    fingertip."""
    obj: Contact = SupportContact(shape_surface) if palm else FreeObject(shape_surface)
    out: list[Contact] = [obj, *(FingertipContact(shape_surface, f, i)
                                 for i, f in enumerate(fingers))]
    x0 = u0 = 0
    for c in out:
        c.x0, c.u0 = x0, u0
        x0, u0 = x0 + c.nx, u0 + c.nu
    return tuple(out)

