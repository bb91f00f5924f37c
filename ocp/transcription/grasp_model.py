"""The CasADi functions of one grasp structure, assembled from its contacts.

A grasp structure is the object's shape, its object block (a support, or the free object)
and its fingers (:mod:`ocp.contacts`). :class:`GraspModel` builds, by looping over the
contacts (no case for any kind of contact here):

* ``dynamics(x, u, params) -> x_dot``: every contact's rolling equations;
* ``path(x, params) -> (closure, points, normals, R_po, p_po)``: the path rows' inputs;
* ``cartesian(x, params)``: the object's and the pads' poses, contact points and normals
  in the palm frame;
* ``laws(x, x_dot, params)``: the certificate's law outputs (the object's twist, then each
  contact's own).

``params = (shape, vec(R_c) of every point contact's chart)``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import casadi as ca
import numpy as np
from numpy.typing import NDArray

from ocp.contacts import (
    Contact,
    FingertipContact,
    FreeFingertip,
    ObjectBlock,
    SymbolicGrasp,
    grasp_contacts,
)
from ocp.contacts.palm_model import model_for
from ocp.geometry.rotations import vee
from ocp.transcription.collocation import HermiteInterpolant, reintegrator, rk4_step

__all__ = ["GraspModel"]

FloatArray = NDArray[np.float64]


def _cat(parts: Sequence[Any], rows: int) -> Any:
    return ca.horzcat(*parts) if parts else ca.SX(rows, 0)


class GraspModel:
    """CasADi functions of one grasp structure (object shape, palm or not, the fingers)."""

    def __init__(self, shape: str, palm: bool, fingers: tuple[Any, ...]) -> None:
        surface = model_for(shape).surface
        self.surface = surface
        self.fingers = fingers
        self.contacts: tuple[Contact, ...] = grasp_contacts(surface, palm, fingers)
        obj = self.contacts[0]
        assert isinstance(obj, ObjectBlock)
        self.object: ObjectBlock = obj
        self.fingertips: tuple[FingertipContact, ...] = tuple(
            c for c in self.contacts if isinstance(c, FingertipContact))
        self.point_contacts: tuple[Contact, ...] = tuple(c for c in self.contacts
                                                         if c.has_point)
        self.nx = sum(c.nx for c in self.contacts)
        self.nu = sum(c.nu for c in self.contacts)
        self.n_contacts = len(self.point_contacts)
        x = ca.SX.sym("x", self.nx)
        u = ca.SX.sym("u", self.nu)
        shape_p = ca.SX.sym("shape", surface.n_params)
        charts = [ca.SX.sym(f"Rc{i}", 3, 3) for i in range(self.n_contacts)]
        prm = ca.vertcat(shape_p, *[ca.vec(R) for R in charts])
        self.n_params = int(prm.numel())
        xd = ca.SX.sym("xd", self.nx)
        g = SymbolicGrasp(surface, shape_p, x, xd)
        self._sym = (x, u, prm, g, charts)
        self._phases: dict[tuple[bool, ...], PhaseModel] = {}
        every = self.phase((True,) * len(self.fingertips))
        self.dynamics, self.path = every.dynamics, every.path
        chart_of = self._chart_of()

        def block(c: Contact) -> tuple[Any, Any, Any]:
            return x[c.xs], u[c.us], chart_of.get(id(c), g.eye)

        tip_R, tip_p = [], []
        for tip in self.fingertips:
            xb, _, chart = block(tip)
            R_pf, p_pf = tip.pad_pose(g, xb, chart)
            tip_R.append(R_pf)
            tip_p.append(p_pf)
        P, N = every.points_normals
        R_po, p_po = g.R_po, g.p_po
        self.cartesian = ca.Function(
            "manipulation_cartesian", [x, prm],
            [R_po, p_po, _cat(tip_R, 3), _cat(tip_p, 3), p_po + R_po @ P, R_po @ N],
            ["x", "params"], ["R_po", "p_po", "R_pf", "p_pf", "points", "normals"])
        laws = [("v_obj", g.dot(p_po)), ("omega_obj", vee(g.dot(R_po) @ R_po.T))]
        for c in self.contacts:
            xb, _, chart = block(c)
            laws += c.laws(g, xb, chart)
        self.laws = ca.Function("manipulation_laws", [x, xd, prm], [e for _, e in laws],
                                ["x", "x_dot", "params"], [n for n, _ in laws])
        # one RK4 step of a fingertip's pad point and angle (x, y, psi) while its object
        # point goes from a (rate w0) to the next (rate w1) in time h: the initial guess
        e_, w_ = ca.SX.sym("e", 5), ca.SX.sym("w", 2)
        self.tip_rates = ca.Function("tip_rates", [e_, w_, shape_p], [
            FingertipContact.pair_rates(surface, e_, w_, shape_p)])
        c_, a_ = ca.SX.sym("c", 3), ca.SX.sym("a", 2)
        w0_, w1_, h_ = ca.SX.sym("w0", 2), ca.SX.sym("w1", 2), ca.SX.sym("h")
        e1 = rk4_step(lambda e, w: self.tip_rates(e, w, shape_p), ca.vertcat(a_, c_),
                      w0_, (w0_ + w1_) / 2, w1_, h_)
        self._roll_step = ca.Function("roll_step", [c_, a_, w0_, w1_, h_, shape_p],
                                      [e1[2:5]])
        self._rolls: dict[int, ca.Function] = {}
        self._reintegrators: dict[int, ca.Function] = {}
        self._mapped: dict[tuple[str, int], ca.Function] = {}

    def _chart_of(self) -> dict[int, Any]:
        """Each point contact's chart symbol (the object block's too, or the identity)."""
        _, _, _, g, charts = self._sym
        chart_of = {id(c): charts[k] for k, c in enumerate(self.point_contacts)}
        chart_of[id(self.object)] = chart_of.get(id(self.object), g.eye)
        return chart_of

    def phase(self, touching: tuple[bool, ...]) -> PhaseModel:
        """The grasp in a contact phase: ``touching[i]`` whether fingertip i touches the
        object (:class:`PhaseModel`; built once per mask)."""
        touching = tuple(bool(t) for t in touching)
        if len(touching) != len(self.fingertips):
            raise ValueError(f"a phase of this grasp names {len(self.fingertips)} "
                             f"fingertips, got {len(touching)}")
        if touching not in self._phases:
            self._phases[touching] = PhaseModel(self, touching)
        return self._phases[touching]

    # -- columns of the state and input vectors, by kind ----------------------------------
    def _columns(self, attr: str) -> list[int]:
        return [c.x0 + j for c in self.contacts for j in getattr(c, attr)]

    def length_columns(self) -> list[int]:
        return self._columns("length_columns")

    def angle_columns(self) -> list[int]:
        return self._columns("angle_columns")

    def joint_columns(self) -> list[int]:
        return self._columns("joint_columns")

    def effort_groups(self) -> tuple[list[int], list[int], list[int]]:
        """Input columns of the objective's three effort terms (the object's own motion,
        the fingertips' motion over the object, the joint rates)."""
        return tuple(  # type: ignore[return-value]
            [c.u0 + j for c in self.contacts for j in c.effort_groups[k]] for k in range(3))

    def x_scale(self, L: Any) -> list[Any]:
        return [s for c in self.contacts for s in c.x_scale(L)]

    def u_scale(self, L: Any, T: Any) -> list[Any]:
        return [s for c in self.contacts for s in c.u_scale(L, T)]

    # -- functions over many points --------------------------------------------------------
    def roll(self, steps: int) -> ca.Function:
        """``steps`` RK4 steps of a pad point and angle (:attr:`_roll_step` accumulated):
        (c0, a (2 x k), w0 (2 x k), w1 (2 x k), h (1 x k), shape (. x k)) -> c (3 x k)."""
        if steps not in self._rolls:
            self._rolls[steps] = self._roll_step.mapaccum("roll", steps)
        return self._rolls[steps]

    def unpack_params(self, prm: Any) -> tuple[Any, list[Any]]:
        """(shape, every point contact's chart R_c as 3 x 3) of a parameter vector
        (:meth:`params`' layout; symbolic or numeric)."""
        ns = self.surface.n_params
        return prm[0:ns], [ca.reshape(prm[ns + 9 * k:ns + 9 * k + 9], 3, 3)
                           for k in range(self.n_contacts)]

    def params(self, shape: FloatArray, charts: Sequence[FloatArray]) -> FloatArray:
        return np.concatenate([np.asarray(shape, dtype=float),
                               *[np.asarray(R).ravel(order="F") for R in charts]])

    def mapped(self, name: str, k: int) -> ca.Function:
        """The model's function ``name`` (cartesian, dynamics, laws) over k points, built
        once per size."""
        if (name, k) not in self._mapped:
            self._mapped[(name, k)] = getattr(self, name).map(k)
        return self._mapped[(name, k)]

    def interpolant(self, t_nodes: FloatArray, X: FloatArray, U0: FloatArray,
                    Um: FloatArray, U1: FloatArray, prm: FloatArray) -> HermiteInterpolant:
        """A plan's returned trajectory: the collocation polynomials through its node
        states, with the node rates of the dynamics at each interval's own end inputs."""
        n = len(U0)
        F0 = np.asarray(self.mapped("dynamics", n)(X[:-1].T, U0.T, prm)).T
        F1 = np.asarray(self.mapped("dynamics", n)(X[1:].T, U1.T, prm)).T
        return HermiteInterpolant(np.asarray(t_nodes, dtype=float), X, F0, F1, U0, Um, U1)

    def reintegrator(self, n_sub: int) -> ca.Function:
        if n_sub not in self._reintegrators:
            self._reintegrators[n_sub] = reintegrator(self.dynamics, self.nx, self.nu,
                                                      self.n_params, n_sub)
        return self._reintegrators[n_sub]


class PhaseModel:
    """A grasp in one contact phase: which fingertips touch the object, and the functions
    of the phase built from what each contact contributes where it is active.

    A touching fingertip contributes its rolling equations, its contact point and normal
    (force closure, loads) and its closure rows; a fingertip off the object contributes
    only its joints' kinematics (q_dot = the joint-rate inputs): its contact coordinates
    are not states of the phase (:attr:`dyn_cols` leaves them out of the defects; the
    transcription parks them) and it has no contact rows. The state and input layout is
    the grasp's in every phase (:class:`GraspModel`), so that phases share one grid.

    * ``dynamics(x, u, params) -> x_dot`` (zero rates for the parked coordinates);
    * ``path(x, params) -> (closure, points, normals, R_po, p_po)`` of the active contacts;
    * ``clearance(x, params) -> rows >= 0`` of the lifted fingertips
      (:meth:`~ocp.contacts.free_fingertip.FreeFingertip.clearance`).
    """

    def __init__(self, m: GraspModel, touching: tuple[bool, ...]) -> None:
        self.grasp = m
        self.touching = touching
        x, u, prm, g, _ = m._sym
        chart_of = m._chart_of()
        obj = m.object
        active = {id(c) for c, on in zip(m.fingertips, touching, strict=True) if on}
        #: the fingertips touching the object, and the point contacts (the support, if
        #: any, first): the rows of force closure and loads, in the grasp's order
        self.fingertips: tuple[FingertipContact, ...] = tuple(
            c for c in m.fingertips if id(c) in active)
        self.point_contacts: tuple[Contact, ...] = tuple(
            c for c in m.point_contacts
            if not isinstance(c, FingertipContact) or id(c) in active)
        #: each active point contact's index among the grasp's point contacts (its chart,
        #: its force variables' slot)
        self.slots: tuple[int, ...] = tuple(m.point_contacts.index(c)
                                            for c in self.point_contacts)
        self.n_contacts = len(self.point_contacts)
        #: state columns with dynamics in this phase (all but a lifted tip's coordinates)
        self.dyn_cols: tuple[int, ...] = tuple(
            j for j in range(m.nx) if not any(
                c.eta_cols.start <= j < c.eta_cols.stop
                for c in m.fingertips if id(c) not in active))
        #: the lifted fingertips' contact coordinates and contact inputs: parked
        self.parked_x: tuple[int, ...] = tuple(j for j in range(m.nx)
                                               if j not in self.dyn_cols)
        self.parked_u: tuple[int, ...] = tuple(
            j for c in m.fingertips if id(c) not in active
            for j in range(c.w_cols.start, c.w_cols.stop))

        def block(c: Contact) -> tuple[Any, Any, Any]:
            return x[c.xs], u[c.us], chart_of.get(id(c), g.eye)

        if g.R_po is None:  # the object's pose: the same in every phase
            g.R_po, g.p_po = obj.pose(g, x[obj.xs], chart_of[id(obj)])
        #: the lifted fingertips as what they are in this phase: free fingertips (their
        #: joints' kinematics, their clearance from the object)
        self.free: tuple[FreeFingertip, ...] = tuple(
            FreeFingertip(m.surface, c.finger, c.index) for c in m.fingertips
            if id(c) not in active)
        free_of = {f.index: f for f in self.free}
        rates, clearance = [], []
        for c in m.contacts:
            if isinstance(c, FingertipContact) and id(c) not in active:
                # off the object: the joints move by their rates (the free fingertip's
                # block), the contact coordinates have no dynamics
                free, q = free_of[c.index], x[c.q_cols]
                rates.append(ca.vertcat(ca.SX.zeros(5),
                                        free.rates(g, q, u[c.qd_cols], g.eye)))
                clearance.append(free.clearance(g, q))
            else:
                rates.append(c.rates(g, *block(c)))
        #: rows >= 0 that keep the lifted fingertips off the object (x, params) -> rows
        self.clearance = ca.Function("clearance", [x, prm], [ca.vertcat(*clearance)
                                                             if clearance else ca.SX(0, 1)])
        self.dynamics = ca.Function("manipulation_dynamics", [x, u, prm],
                                    [ca.vertcat(*rates)], ["x", "u", "params"], ["x_dot"])
        points, normals = [], []  # object frame
        for c in self.point_contacts:
            pt, nrm = c.point_normal(g, x[c.xs], chart_of[id(c)])
            points.append(pt)
            normals.append(nrm)
        closure = [c.closure(g, *block(c)[::2]) for c in self.fingertips]
        self.points_normals = (_cat(points, 3), _cat(normals, 3))
        cl = ca.vertcat(*closure) if closure else ca.SX(0, 1)
        self.path = ca.Function("manipulation_path", [x, prm],
                                [cl, *self.points_normals, g.R_po, g.p_po],
                                ["x", "params"], ["closure", "points", "normals", "R_po",
                                                  "p_po"])
        #: every fingertip's closure (eq. 6), touching or not: the touch-down's rows
        all_closure = [c.closure(g, *block(c)[::2]) for c in m.fingertips]
        self.closure_of = ca.Function("closure_of", [x, prm], all_closure) \
            if all_closure else None

    @property
    def nx(self) -> int:
        return self.grasp.nx

    @property
    def nu(self) -> int:
        return self.grasp.nu

    @property
    def n_params(self) -> int:
        return self.grasp.n_params

    @property
    def surface(self) -> Any:
        return self.grasp.surface

    @property
    def object(self) -> ObjectBlock:
        return self.grasp.object

    def unpack_params(self, prm: Any) -> tuple[Any, list[Any]]:
        """(shape, every point contact's chart) of the grasp's parameters; the charts of
        the active contacts are ``charts[k] for k in slots``."""
        return self.grasp.unpack_params(prm)
