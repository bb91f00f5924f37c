"""The contract every contact kind keeps (ocp/contacts/), one set of tests for all of them
(learnt from Crocoddyl's ``ContactModelAbstractTestCase``).

Each kind is put in the smallest grasp that has it (an object block first, as
:func:`ocp.contacts.grasp_contacts` orders them), its states integrated from its own rates
under smooth random inputs, and then:

(a) its rates agree with finite differences of its poses: the support's object rolls on
    the palm (the contact point at rest on the object, no spin, the palm point moving at
    the input); the free object moves at its twist; a fingertip rolls on the (fixed)
    object; a free fingertip's tip moves at Pinocchio's Jacobian times q_dot;
(b) where it touches the object, its certificate laws ``slip_*`` and ``spin_*`` vanish
    along the trajectory (the joints held still and the object rolling on the fingertip,
    so that closure holds exactly);
(c) its certificate checks (ocp/solve/contact_checks.py) pass on that trajectory and the
    named check fails once its joints or contact coordinates are perturbed.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import cache
from types import SimpleNamespace
from typing import Any

import casadi as ca
import numpy as np
import pytest

from ocp.certify.certificate import GRASP_TOLERANCES, PALM_TOLERANCES
from ocp.contacts import (
    Contact,
    FingertipContact,
    FreeFingertip,
    FreeObject,
    SupportContact,
    SymbolicGrasp,
)
from ocp.geometry.rotations import quaternion_rate_sym, quaternion_wxyz, vee
from ocp.geometry.surfaces import Sphere
from ocp.geometry.tips import sphere_tip
from ocp.robots.finger import load_finger
from ocp.solve.contact_checks import CertificateContext, contact_checks

RHO, R_TIP = 0.025, 0.012  # the ball's and the round tip's radii [m]
SHAPE = np.array([RHO])
#: The round tip: a sphere whose front point is the pad's centre (as tests/test_round_tips.py).
PAD_ALIGNED = np.array([[0.0, 0.0, 1.0], [0.0, -1.0, 0.0], [1.0, 0.0, 0.0]])
#: Joint angles the built-in (six-joint) finger is held at, inside its limits [rad].
Q0 = np.array([0.1, 0.5, 0.4, 0.2, -0.3, 0.1])
#: Duration [s] and RK4 step [s] of the integrated trajectories. RK4's error (h^4) and the
#: fourth-order central differences' truncation (h^4 / 30 |f^(5)|) are ~1e-12 of the rates
#: here, their round-off ~ eps |pose| / h ~ 1e-14 m/s.
T, H = 0.4, 1e-3
#: (a): finite differences against the rates, relative to the motion's speed scale.
RTOL_FD = 1e-7
#: (b): the laws are identities along a rolling motion: round-off of the pose chains
#: (~1e3 flops on values of order one), relative to the speed scale.
RTOL_LAW = 1e-10
#: (c): the perturbations: a joint angle [rad], the contact's chart point [rad].
JOINT_KICK, CHART_KICK = 0.01, 0.01


def smooth(rng: np.random.Generator, n: int, scale: float) -> Callable[[float], np.ndarray]:
    """A random smooth input path (n components, a few sines each) of size ``scale``."""
    a = rng.uniform(-1, 1, (3, n)) * scale
    w = rng.uniform(2, 8, (3, n))
    phi = rng.uniform(0, 2 * np.pi, (3, n))
    return lambda t: np.sum(a * np.sin(w * t + phi), axis=0)


def rk4(f: Callable[[np.ndarray, float], np.ndarray], x0: np.ndarray) -> np.ndarray:
    """States at t = 0, H, ..., T of x' = f(x, t)."""
    xs = [np.asarray(x0, dtype=float)]
    for k in range(round(T / H)):
        t, x = k * H, xs[-1]
        k1 = f(x, t)
        k2 = f(x + H / 2 * k1, t + H / 2)
        k3 = f(x + H / 2 * k2, t + H / 2)
        k4 = f(x + H * k3, t + H)
        xs.append(x + H / 6 * (k1 + 2 * k2 + 2 * k3 + k4))
    return np.array(xs)


def diff4(f: np.ndarray) -> np.ndarray:
    """d/dt by fourth-order central differences at the interior samples 2 .. n-3."""
    return (-f[4:] + 8 * f[3:-1] - 8 * f[1:-3] + f[:-4]) / (12 * H)


def placed(contacts: tuple[Contact, ...]) -> tuple[Contact, ...]:
    """The contacts with their offsets in the grasp's vectors (as grasp_contacts sets
    them)."""
    x0 = u0 = 0
    for c in contacts:
        c.x0, c.u0 = x0, u0
        x0, u0 = x0 + c.nx, u0 + c.nu
    return contacts


@dataclass
class Grasp:
    """One kind in its smallest grasp: the contacts, the kind's contact, CasADi functions
    of the whole grasp (rates, laws, the object's pose, the tip frame's pose from the
    contact or FK), and a tolerance policy."""

    contacts: tuple[Contact, ...]
    kind: Contact
    rates: ca.Function
    laws: ca.Function
    pose: ca.Function  # x -> (R_po, p_po)
    tip: ca.Function | None  # x -> (R_pf, p_pf): the contact's own pose of the tip frame
    policy: Any

    @property
    def nx(self) -> int:
        return sum(c.nx for c in self.contacts)

    @property
    def nu(self) -> int:
        return sum(c.nu for c in self.contacts)

    def law(self, x: np.ndarray, xd: np.ndarray) -> dict[str, np.ndarray]:
        if not self.laws.n_out():
            return {}
        out = self.laws.map(len(x))(x.T, xd.T, np.tile(SHAPE[:, None], (1, len(x))))
        out = out if isinstance(out, (list, tuple)) else [out]
        return {k: np.asarray(v).T for k, v in zip(self.laws.name_out(), out, strict=True)}


def build(contacts: tuple[Contact, ...], kind: Contact, policy: Any) -> Grasp:
    contacts = placed(contacts)
    nx, nu = sum(c.nx for c in contacts), sum(c.nu for c in contacts)
    x, u, xd = ca.SX.sym("x", nx), ca.SX.sym("u", nu), ca.SX.sym("xd", nx)
    shape = ca.SX.sym("shape", 1)
    g = SymbolicGrasp(Sphere, shape, x, xd)
    obj = contacts[0]
    assert isinstance(obj, (SupportContact, FreeObject))
    g.R_po, g.p_po = obj.pose(g, x[obj.xs], g.eye)
    rates = ca.vertcat(*[c.rates(g, x[c.xs], u[c.us], g.eye) for c in contacts])
    laws = [e for c in contacts for e in c.laws(g, x[c.xs], g.eye)]
    tip = None
    if isinstance(kind, FingertipContact):
        tip = ca.Function("tip", [x, shape], list(kind.pad_pose(g, x[kind.xs], g.eye)))
    elif isinstance(kind, FreeFingertip):
        tip = ca.Function("tip", [x, shape], list(kind.tip_pose(g, x[kind.xs])))
    return Grasp(
        contacts, kind, ca.Function("rates", [x, u, shape], [rates]).expand(),
        ca.Function("laws", [x, xd, shape], [e for _, e in laws], ["x", "xd", "shape"],
                    [n for n, _ in laws]).expand(),
        ca.Function("pose", [x, shape], [g.R_po, g.p_po]),
        tip, policy)


@cache
def finger(round_tip: bool) -> Any:
    import dataclasses

    f = load_finger()
    if round_tip:
        f = dataclasses.replace(f, tip=sphere_tip(R_TIP, (0.0, 0.0, -R_TIP), PAD_ALIGNED))
    return f


def grasp_of(name: str) -> Grasp:
    if name == "support":
        kind: Contact = SupportContact(Sphere)
        return build((kind,), kind, PALM_TOLERANCES)
    if name == "free_object":
        kind = FreeObject(Sphere)
        return build((kind,), kind, GRASP_TOLERANCES)
    if name == "free_fingertip":
        kind = FreeFingertip(Sphere, finger(False), 0)
        return build((FreeObject(Sphere), kind), kind, GRASP_TOLERANCES)
    kind = FingertipContact(Sphere, finger(name == "fingertip_round"), 0)
    return build((FreeObject(Sphere), kind), kind, GRASP_TOLERANCES)


KINDS = ("support", "free_object", "fingertip_pad", "fingertip_round", "free_fingertip")
TOUCHING = ("support", "fingertip_pad", "fingertip_round")


# -- trajectories ------------------------------------------------------------------------

def _quaternions(R: np.ndarray) -> np.ndarray:
    q = quaternion_wxyz(R)
    for i in range(1, len(q)):  # sign continuity
        if np.dot(q[i], q[i - 1]) < 0:
            q[i] = -q[i]
    return q


def trajectory(gr: Grasp, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray,
                                                  np.ndarray, float]:
    """(times, states, their rates, the inputs, the speed scale [m/s]) of a motion
    integrated from the
    kind's own rates: the object block and a free fingertip under random smooth inputs; a
    fingertip with its joints held at Q0 while the object rolls on it (the object's pose
    from the tip frame's and the contact's, so that closure holds exactly)."""
    rng = np.random.default_rng(seed)
    k = gr.kind
    ts = np.arange(round(T / H) + 1) * H
    if isinstance(k, SupportContact):
        x0 = np.array([0.0, 0.0, 0.3, 0.2, 0.1])
        u = smooth(rng, 2, 0.05)
    elif isinstance(k, FreeObject):
        x0 = np.array([0.0, 0.0, 0.05, 1.0, 0.0, 0.0, 0.0])
        scales = np.array([0.05] * 3 + [1.0] * 3)
        u6 = smooth(rng, 6, 1.0)
        u = lambda t: u6(t) * scales  # noqa: E731
    elif isinstance(k, FreeFingertip):
        x0 = np.r_[0.0, 0.0, 0.05, 1.0, 0.0, 0.0, 0.0, Q0]
        uq = smooth(rng, k.nu, 0.5)
        u = lambda t: np.r_[np.zeros(6), uq(t)]  # noqa: E731
    else:
        return _rolling_on_the_tip(gr, rng, ts)
    f = lambda x, t: np.asarray(gr.rates(x, u(t), SHAPE)).ravel()  # noqa: E731
    X = rk4(f, x0)
    Xd = np.array([f(x, t) for x, t in zip(X, ts, strict=True)])
    return ts, X, Xd, np.array([u(t) for t in ts]), 0.05


def _rolling_on_the_tip(gr: Grasp, rng: np.random.Generator, ts: np.ndarray
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]:
    k = gr.kind
    assert isinstance(k, FingertipContact)
    w = smooth(rng, 2, 1.0)  # the object point's chart rate [rad/s]
    e0 = np.array([0.0, 0.0, 0.2, 0.1, 0.3]) if not k.tip.round else \
        np.array([0.1, 0.05, 0.2, 0.1, 0.3])
    # the contact's rolling equations with the object fixed at the identity
    xs = ca.SX.sym("x", 5)
    ws = ca.SX.sym("w", 2)
    g0 = SymbolicGrasp(Sphere, ca.DM(SHAPE), xs, ca.SX.sym("xd", 5), R_po=ca.DM.eye(3),
                       p_po=ca.DM.zeros(3))
    nq = int(k.finger.nq)
    ed = ca.Function("ed", [xs, ws], [k.rates(g0, ca.vertcat(xs, ca.DM(Q0)),
                                              ca.vertcat(ws, ca.DM.zeros(nq)), ca.DM.eye(3))[0:5]])
    R_of, p_of = k.pad_pose(g0, ca.vertcat(xs, ca.DM(Q0)), ca.DM.eye(3))  # object frame
    rel = ca.Function("rel", [xs], [R_of, p_of])
    E = rk4(lambda e, t: np.asarray(ed(e, w(t))).ravel(), e0)
    Ed = np.array([np.asarray(ed(e, w(t))).ravel() for e, t in zip(E, ts, strict=True)])
    # the object's pose: the tip frame fixed where FK(Q0) puts it, the object placed by the
    # contact, and its exact rate (d/dt of the chain along eta_dot)
    R_f, p_f = (np.asarray(a) for a in k.finger.fk(Q0))
    p_f = p_f.ravel()
    J = ca.Function("J", [xs], [ca.jacobian(ca.vertcat(ca.vec(R_of), p_of), xs)])
    X, Xd = [], []
    for e, e_dot in zip(E, Ed, strict=True):
        Rr, pr = (np.asarray(a) for a in rel(e))
        d = np.asarray(J(e)) @ e_dot
        Rr_dot, pr_dot = d[:9].reshape(3, 3, order="F"), d[9:]
        R_po = R_f @ Rr.T
        p_po = p_f - R_po @ pr.ravel()
        R_dot = R_f @ Rr_dot.T
        p_dot = -R_dot @ pr.ravel() - R_po @ pr_dot
        X.append((R_po, p_po, e))
        Xd.append((R_dot, p_dot, e_dot))
    q = _quaternions(np.array([x[0] for x in X]))
    qs, wq = ca.SX.sym("q", 4), ca.SX.sym("w", 3)
    q_rate = ca.Function("q_rate", [qs, wq], [quaternion_rate_sym(qs, wq)])
    states = np.array([np.r_[p, qi, e, Q0] for (_, p, e), qi in zip(X, q, strict=True)])
    rates = np.array([np.r_[p_dot, np.asarray(q_rate(qi, vee(R.T @ R_dot))).ravel(), e_dot,
                            np.zeros(nq)]
                      for (R, _, _), (R_dot, p_dot, e_dot), qi in zip(X, Xd, q, strict=True)])
    U = np.zeros((len(ts), sum(c.nu for c in gr.contacts)))
    U[:, k.w_cols] = np.array([w(t) for t in ts])
    return ts, states, rates, U, float(np.max(np.linalg.norm(rates[:, 0:3], axis=1)))


@cache
def integrated(name: str) -> tuple[Grasp, np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                                   float]:
    gr = grasp_of(name)
    return (gr, *trajectory(gr))


def poses(f: ca.Function, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    out = f.map(len(X))(X.T, np.tile(SHAPE[:, None], (1, len(X))))
    R = np.asarray(out[0]).reshape(3, len(X), 3).transpose(1, 0, 2)
    return R, np.asarray(out[1]).T


# -- (a) the rates against finite differences of the poses ----------------------------------

@pytest.mark.parametrize("name", KINDS)
def test_the_rates_move_the_poses_as_the_kind_says(name: str) -> None:
    gr, _, X, _, U, speed = integrated(name)
    k = gr.kind
    mid = slice(2, -2)
    if isinstance(k, FreeFingertip):
        assert gr.tip is not None
        _, p = poses(gr.tip, X)
        v_fd = diff4(p)
        q, qd = X[mid, k.q_cols], U[mid, k.qd_cols]  # the joints move at the inputs
        v_pin = np.array([k.finger.frame_jacobian_pin(qi)[:3] @ qdi
                          for qi, qdi in zip(q, qd, strict=True)])
        assert np.max(np.abs(v_fd - v_pin)) <= RTOL_FD * speed
        return
    if isinstance(k, FingertipContact):
        # the object fixed, the tip frame from the contact: the tip's material point at the
        # contact is at rest and the tip does not spin about the normal
        g_fixed = _fixed_object_tip(k)
        R, p = poses(g_fixed, X)
        uv, chart = X[:, k.eta_cols][:, 2:4], np.eye(3)
        pts = np.array([np.asarray(Sphere.geometry(c, SHAPE)[0]).ravel() for c in uv])
        nrm = np.array([np.asarray(Sphere.geometry(c, SHAPE)[1])[:, 2] for c in uv])
        pts, nrm = pts @ chart.T, nrm @ chart.T
        # the object point's chart coordinates move at the contact's input w
        assert np.max(np.abs(diff4(uv) - U[mid, k.w_cols])) <= RTOL_FD * speed / RHO
    else:
        R, p = poses(gr.pose, X)
        if isinstance(k, FreeObject):
            v_fd = diff4(p)
            W = np.einsum("kji,kjl->kil", R[mid], diff4(R))  # R^T R_dot
            om = np.stack([W[:, 2, 1], W[:, 0, 2], W[:, 1, 0]], axis=1)
            scale = max(speed, 1.0 * RHO)
            assert np.max(np.abs(v_fd - U[mid, 0:3])) <= RTOL_FD * scale
            assert np.max(np.abs(om - U[mid, 3:6])) * RHO <= RTOL_FD * scale
            return
        uv = X[:, 2:4]
        pts = np.array([np.asarray(Sphere.geometry(c, SHAPE)[0]).ravel() for c in uv])
        nrm = np.array([np.asarray(Sphere.geometry(c, SHAPE)[1])[:, 2] for c in uv])
        c_palm = p + np.einsum("kij,kj->ki", R, pts)
        # the contact point lies on the palm where (x, y) say and moves at the input
        assert np.max(np.abs(c_palm[:, 0:2] - X[:, 0:2])) <= 1e-12 * RHO
        assert np.max(np.abs(c_palm[:, 2])) <= 1e-12 * RHO
        assert np.max(np.abs(diff4(c_palm[:, 0:2]) - U[mid, 0:2])) <= RTOL_FD * speed
    # the body's material point at the contact and its spin, by differences of its pose
    R_dot, p_dot = diff4(R), diff4(p)
    v = np.einsum("kij,kj->ki", R_dot, pts[mid]) + p_dot
    Om = np.einsum("kij,klj->kil", R_dot, R[mid])  # R_dot R^T
    om = np.stack([Om[:, 2, 1], Om[:, 0, 2], Om[:, 1, 0]], axis=1)
    spin = np.einsum("ki,ki->k", om, np.einsum("kij,kj->ki", R[mid], nrm[mid]))
    assert np.max(np.linalg.norm(v, axis=1)) <= RTOL_FD * max(speed, 0.1 * RHO)
    assert np.max(np.abs(spin)) * RHO <= RTOL_FD * max(speed, 0.1 * RHO)


def _fixed_object_tip(k: FingertipContact) -> ca.Function:
    """x -> the tip frame's pose from the contact with the object at the identity."""
    x = ca.SX.sym("x", k.x0 + k.nx)
    g = SymbolicGrasp(Sphere, ca.SX.sym("s", 1), x, x, R_po=ca.DM.eye(3),
                      p_po=ca.DM.zeros(3))
    R, p = k.pad_pose(g, x[k.xs], ca.DM.eye(3))
    # the object point in the tip frame is what the test differentiates: the object's
    # pose relative to the (moving) tip: invert
    return ca.Function("rel", [x, g.shape], [R.T, -R.T @ p])


# -- (b) no slip, no spin ----------------------------------------------------------------------

@pytest.mark.parametrize("name", TOUCHING)
def test_rolling_neither_slips_nor_spins_by_the_certificate_laws(name: str) -> None:
    gr, _, X, Xd, _, speed = integrated(name)
    laws = gr.law(X, Xd)
    key = gr.kind.name if isinstance(gr.kind, SupportContact) else str(gr.kind.index)
    slip, spin = laws[f"slip_{key}"], laws[f"spin_{key}"]
    assert np.max(np.linalg.norm(slip, axis=1)) <= RTOL_LAW * speed
    assert np.max(np.abs(spin)) * RHO <= RTOL_LAW * speed
    # and a body's actual motion is not a trivial zero
    assert speed > 1e-3


# -- (c) the certificate's checks --------------------------------------------------------------

def context(gr: Grasp, ts: np.ndarray, X: np.ndarray, Xd: np.ndarray, speed: float
            ) -> CertificateContext:
    R_po, p_po = poses(gr.pose, X)
    n = len(X)
    if gr.tip is not None and isinstance(gr.kind, FingertipContact):
        R_pf, p_pf = poses(gr.tip, X)
        R_pf, p_pf = R_pf[:, None], p_pf[:, None]
    else:
        R_pf, p_pf = np.zeros((n, 0, 3, 3)), np.zeros((n, 0, 3))
    return CertificateContext(
        times=ts, laws=gr.law(X, Xd), R_po=R_po, p_po=p_po, R_pf=R_pf, p_pf=p_pf,
        states=X, shape=SHAPE, L=RHO, speed=speed, rate=speed / RHO, policy=gr.policy)


PROBLEM = SimpleNamespace(fingers=[SimpleNamespace(name="f")])


def perturbed(gr: Grasp, ts: np.ndarray, X: np.ndarray, Xd: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray, str]:
    """The states and their rates perturbed, and the check that must then fail: a
    fingertip's first joint turned by JOINT_KICK (closure by Pinocchio breaks), a free
    fingertip's pushed JOINT_KICK past its upper limit, the support's chart latitude moved
    by up to CHART_KICK along the motion (CHART_KICK sin(pi t / T): the object point moves
    at a rate its rolling does not give, a slip of ~ RHO CHART_KICK pi / T, some 4 % of the
    speed scale against the policy's 0.1 %)."""
    k, Y, Yd = gr.kind, X.copy(), Xd.copy()
    if isinstance(k, FingertipContact):
        Y[:, k.q_cols.start] += JOINT_KICK
        return Y, Yd, "max_closure_position_error"
    if isinstance(k, FreeFingertip):
        Y[:, k.q_cols.start] = k.finger.upper[0] + JOINT_KICK
        Yd[:, k.q_cols.start] = 0.0
        return Y, Yd, "max_joint_limit_violation_f"
    assert isinstance(k, SupportContact)
    Y[:, 2] += CHART_KICK * np.sin(np.pi * ts / T)
    Yd[:, 2] += CHART_KICK * np.pi / T * np.cos(np.pi * ts / T)
    return Y, Yd, "max_slip_speed_palm"


@pytest.mark.parametrize("name", KINDS)
def test_the_certificate_checks_pass_and_fail_on_a_perturbed_plan(name: str) -> None:
    gr, ts, X, Xd, _, speed = integrated(name)
    checks = contact_checks(gr.kind, PROBLEM, 0, context(gr, ts, X, Xd, speed))
    assert all(c.passed for c in checks), [c.failure for c in checks if not c.passed]
    if isinstance(gr.kind, FreeObject):
        assert checks == []  # its motion is checked by tracking and re-integration
        return
    Y, Yd, name_failing = perturbed(gr, ts, X, Xd)
    bad = {c.name: c for c in contact_checks(gr.kind, PROBLEM, 0,
                                             context(gr, ts, Y, Yd, speed))}
    assert not bad[name_failing].passed


def test_a_free_fingertip_is_a_finger_off_the_object() -> None:
    f = finger(False)
    k = FreeFingertip(Sphere, f, 1)
    nq = int(f.nq)
    assert (k.nx, k.nu, k.has_point, k.body) == (nq, nq, False, "finger")
    assert k.joint_columns == tuple(range(nq)) and k.effort_groups[2] == tuple(range(nq))
    assert k.x_scale(RHO) == [1] * nq and k.u_scale(RHO, 2.0) == [0.5] * nq
    lower, upper, rates = k.bounds(SimpleNamespace())
    assert np.all(np.array(lower) > f.lower) and np.all(np.array(upper) < f.upper)
    assert np.allclose(rates, f.velocity_limit)
    g = SymbolicGrasp(Sphere, ca.SX.sym("s", 1), ca.SX.sym("x", nq), ca.SX.sym("xd", nq))
    assert k.clearance(g, g.x).shape == (0, 1)
    R, p = (np.asarray(a) for a in ca.Function("t", [g.x], list(k.tip_pose(g, g.x)))(Q0))
    R_pin, p_pin = f.fingertip_pose_pin(Q0)
    assert np.max(np.abs(R - R_pin)) <= 1e-12 and np.max(np.abs(p.ravel() - p_pin)) <= 1e-12
    with pytest.raises(NotImplementedError):
        k.point_normal(g, g.x, g.eye)
    assert math.isclose(k.u_scale(1.0, 4.0)[0], 0.25)
