"""The physical certificate of a grasp's plan, computed independently of the NLP.

The plan's inputs are re-integrated from its initial state with CVODES over the whole
horizon (never reset to the NLP's states), and the re-integrated motion is checked at
``samples_per_interval`` points per interval: the re-integration defects at the nodes, the
goals and via-points it reaches, each contact's own laws (:meth:`ocp.spec.contacts.Contact.checks`:
slip, spin, touching, pads, joint limits, closure by Pinocchio), the tracking tolerances
and force closure. The result is one :class:`~ocp.certify.certificate.Certificate`.

How strict it is comes from the problem's :class:`~ocp.certify.certificate.TolerancePolicy`
(docs/conventions.md states both): ``GRASP_TOLERANCES`` for grasps with fingers,
``PALM_TOLERANCES`` for the object on the palm alone (the ball-on-palm planner's,
tighter: its plans have no joints and its paths are checked at twice the density).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from ocp.certify.certificate import Certificate, Check, CheckKind, TolerancePolicy
from ocp.geometry.grasp import force_angles
from ocp.geometry.rotations import rotation_angle_between
from ocp.spec.contacts import CertificateContext
from ocp.spec.grasp import ManipulationProblem, support_goal_errors
from ocp.transcription.collocation import reintegrate

if TYPE_CHECKING:
    from ocp.transcription.grasp_model import GraspModel

__all__ = ["certify_grasp"]

FloatArray = NDArray[np.float64]


def _wrapped(d: FloatArray, periodic: list[bool]) -> FloatArray:
    """Differences of the periodic columns taken modulo 2 pi into [-pi, pi) (only where
    they exceed pi: elsewhere the wrap would only add round-off)."""
    out = d.copy()
    cols = [j for j, p in enumerate(periodic) if p]
    sub = out[:, cols]
    out[:, cols] = np.where(np.abs(sub) > np.pi, (sub + np.pi) % (2 * np.pi) - np.pi, sub)
    return out


def certify_grasp(problem: ManipulationProblem, m: GraspModel, t_nodes: FloatArray,
                  X: FloatArray, U0: FloatArray, Um: FloatArray, U1: FloatArray,
                  prm: FloatArray, policy: TolerancePolicy) -> Certificate:
    """The certificate of a plan given by its node states X and each interval's inputs
    (U0 at its start, Um at its midpoint, U1 at its end): see the module's doc."""
    if not all(np.all(np.isfinite(a)) for a in (X, U0, Um, U1)):
        return Certificate.failed("the plan has non-finite states or inputs")
    n_sub = policy.samples_per_interval
    try:
        Xr, sx, su = reintegrate(m.reintegrator(n_sub), X[0], t_nodes, U0, Um, U1, prm,
                                 n_sub)
    except RuntimeError as exc:  # CVODES gave up: the plan is not a smooth motion
        return Certificate.failed(f"re-integration failed: {str(exc).splitlines()[-1]}")
    n = len(sx)
    xd = np.asarray(m.mapped("dynamics", n)(sx.T, su.T, prm))
    laws = dict(zip(m.laws.name_out(), (np.asarray(a).T for a in
                                        m.mapped("laws", n)(sx.T, xd, prm)), strict=True))
    cart = m.mapped("cartesian", n)(sx.T, prm)
    nc, nf = m.n_contacts, len(m.fingertips)
    R_po = np.asarray(cart[0]).T.reshape(n, 3, 3).transpose(0, 2, 1)
    p_po = np.asarray(cart[1]).T
    pts = np.asarray(cart[4]).T.reshape(n, nc, 3)
    nrm = np.asarray(cart[5]).T.reshape(n, nc, 3)
    L = problem.object.length_scale
    o = problem.options
    speed = float(np.max(np.abs(laws["v_obj"]))) + L * float(
        np.max(np.abs(laws["omega_obj"]))) + L * float(np.max(np.abs(su)))
    ctx = CertificateContext(
        laws=laws, R_po=R_po, p_po=p_po,
        R_pf=np.asarray(cart[2]).T.reshape(n, nf, 3, 3).transpose(0, 1, 3, 2)
        if nf else np.zeros((n, 0, 3, 3)),
        p_pf=np.asarray(cart[3]).T.reshape(n, nf, 3), states=sx, inputs=su,
        shape=np.asarray(problem.object.dimensions, dtype=float), L=L, speed=speed,
        policy=policy)
    D = CheckKind.DISCRETISATION
    # re-integration defects at the nodes, the periodic angles (v, psi) wrapped
    periodic = [False] * m.nx
    for c in m.contacts:
        for j in c.periodic_columns:
            periodic[c.x0 + j] = True
    d = _wrapped(Xr - X, periodic)
    checks = [
        Check("max_length_defect", float(np.max(np.abs(d[:, m.length_columns()]))),
              policy.length_defect(o), D),
        Check("max_angle_defect", float(np.max(np.abs(d[:, m.angle_columns()]))),
              policy.angle_defect(o), D),
    ]
    if nf:
        checks.append(Check("max_joint_defect", float(np.max(np.abs(
            d[:, m.joint_columns()]))), policy.angle_defect(o), D))
    segments, _ = problem.segments()
    goal_err = support_goal_errors(problem, Xr, [0, *np.cumsum(segments).tolist()])
    if goal_err:
        # the goals the re-integrated motion reaches: the NLP meets them to IPOPT's
        # tolerance, so a miss here is drift between collocation points
        checks.append(Check("max_goal_error", max(goal_err.values()), policy.goal(o), D))
    for k, c in enumerate(m.contacts):
        checks += c.checks(problem, k, ctx)
    reported: dict[str, float] = {}
    if problem.motion is not None:
        ts = np.concatenate([[t_nodes[0]], np.concatenate([
            t_nodes[k] + (t_nodes[k + 1] - t_nodes[k]) * np.linspace(0, 1, n_sub + 1)[1:]
            for k in range(len(t_nodes) - 1)])])
        Rd, Pd = problem.motion.at(ts)
        tr = problem.tracking
        for name, value, tol in (
                ("max_tracking_position_error",
                 float(np.max(np.linalg.norm(p_po - Pd, axis=1))), tr.position_tolerance),
                ("max_tracking_angle_error",
                 float(np.max(rotation_angle_between(Rd, R_po))), tr.orientation_tolerance)):
            if tol is None:
                reported[name] = value
            else:
                checks.append(Check(name, value, tol, D))
    if nc >= 2:  # force closure (the object on the palm alone has no grasp to certify)
        phi, _, onto = force_angles(pts, nrm)
        margin = float(np.min(math.atan(problem.mu) - phi))
        checks.append(Check("min_cone_margin", margin, policy.cone_margin, CheckKind.PHYSICS,
                            lower_bound=True, report_tolerance=False,
                            reason=f"min_cone_margin {margin:.3g} < 0 (force closure lost)"))
        reported["max_grasp_angle"] = float(np.max(phi))
        if not np.all(onto):
            checks.append(Check("grasp_map_onto", 0.0, 1.0, CheckKind.PHYSICS,
                                lower_bound=True, report_tolerance=False, report_value=False,
                                reason="the grasp map is not onto at some sample (force "
                                       "closure lost)"))
    return Certificate.of(checks, reported, n_samples=n)

