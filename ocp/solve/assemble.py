"""A plan from the NLP's values: the planned forces at the collocation points and the
solution on its grid (every contact's and finger's trajectory, the object's motion, force
closure, tracking), with its certificate's verdict."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from ocp.certify.certificate import Certificate
from ocp.geometry.grasp import force_angles
from ocp.geometry.rotations import rotation_angle_between
from ocp.solution import (
    Collocation,
    ContactTrajectory,
    FingerTrajectory,
    ManipulationSolution,
    Status,
    _Interpolant,
    joint_torques,
)
from ocp.spec.grasp import ManipulationProblem
from ocp.transcription.chart_switch import PlanCharts
from ocp.transcription.collocation import HermiteInterpolant, PlannedForces
from ocp.transcription.grasp_model import GraspModel

__all__ = ["assemble_solution", "planned_forces"]

FloatArray = NDArray[np.float64]


def planned_forces(problem: ManipulationProblem, m: GraspModel, F: FloatArray,
                   X: FloatArray, Xm: FloatArray, prm: FloatArray,
                   charts: PlanCharts | None = None) -> PlannedForces:
    """The planned forces of an NLP solution: ``F`` its load-force rows at the points
    (nodes, then midpoints; :mod:`ocp.transcription.nlp_blocks`: per contact the force in
    the object frame over the force scale, then the torsion's share of its limit), the
    states ``X`` at the nodes and ``Xm`` at the midpoints (rows), in palm-frame newtons
    (``charts``: each point on its chart)."""
    from ocp.transcription.nlp_blocks import LOAD_VARS
    from ocp.transcription.values import force_scale

    assert problem.forces is not None
    nc, n = m.n_contacts, len(Xm)
    Xa = np.vstack([X, Xm])
    k = len(Xa)
    charts = charts or PlanCharts.single(m, prm)
    cart = charts.evaluate("cartesian", charts.point_charts(n), Xa.T)
    R_po = np.asarray(cart[0]).T.reshape(k, 3, 3).transpose(0, 2, 1)
    nrm = np.asarray(cart[5]).T.reshape(k, nc, 3)  # palm frame
    Fl = np.asarray(F, dtype=float).reshape(LOAD_VARS, nc, k, order="F")
    F0 = force_scale(problem)
    f = F0 * np.einsum("kij,jck->kci", R_po, Fl[0:3])  # k x nc x 3, palm frame
    fn = -np.einsum("kci,kci->kc", nrm, f)
    tau = problem.forces.torsional_friction * fn * Fl[3].T
    g = problem.forces.gravity
    return PlannedForces(f[: n + 1], f[n + 1:], tau[: n + 1], tau[n + 1:],
                         (float(g[0]), float(g[1]), float(g[2])))


def assemble_solution(problem: ManipulationProblem, m: GraspModel, status: Status, raw: str,
                      col: Collocation, traj: HermiteInterpolant, prm: FloatArray,
                      cert: Certificate, goal_error: dict[str, float],
                      charts: PlanCharts | None = None) -> ManipulationSolution:
    """The returned trajectory ``traj`` on its collocation grid (nodes and midpoints in time
    order; at a via-point node the outgoing rates): every contact's and finger's
    trajectory, the object's motion, force closure, tracking; the status made
    ``inaccurate`` when the certificate fails. ``charts``: the plan's charts (one,
    ``m`` and ``prm``, by default; two when its contacts change chart at a node)."""
    t_nodes, X, Xm, U0, Um, U1 = col.t_nodes, col.X, col.Xm, col.U0, col.Um, col.U1
    tm = (t_nodes[:-1] + t_nodes[1:]) / 2
    order = np.argsort(np.concatenate([t_nodes, tm]), kind="stable")
    t = np.concatenate([t_nodes, tm])[order]
    finite = all(np.all(np.isfinite(a)) for a in (X, Xm, U0, Um, U1))
    n_int = len(U0)
    kk = np.concatenate([np.arange(n_int), [n_int - 1], np.arange(n_int)])[order]
    ss = np.concatenate([np.zeros(n_int), [1.0], np.full(n_int, 0.5)])[order]
    if finite:  # the returned polynomials on the grid (the midpoints' states theirs)
        Xg, xdot = traj.on_intervals(kk, ss), traj.on_intervals(kk, ss, order=1)
    else:
        Xg = np.vstack([X, Xm])[order]
        xdot = np.full_like(Xg, np.nan)
    Ug = np.vstack([np.vstack([U0, U1[-1:]]), Um])[order]
    k = len(t)
    charts = charts or PlanCharts.single(m, prm)
    kc = charts.interval_charts(kk)
    cart = charts.evaluate("cartesian", kc, Xg.T)
    nc, nf = m.n_contacts, len(m.fingertips)
    R_po = np.asarray(cart[0]).T.reshape(k, 3, 3).transpose(0, 2, 1)
    p_po = np.asarray(cart[1]).T
    R_pf = np.asarray(cart[2]).T.reshape(k, nf, 3, 3).transpose(0, 1, 3, 2) \
        if nf else np.zeros((k, 0, 3, 3))
    p_pf = np.asarray(cart[3]).T.reshape(k, nf, 3)
    pts = np.asarray(cart[4]).T.reshape(k, nc, 3)
    nrm = np.asarray(cart[5]).T.reshape(k, nc, 3)
    laws = charts.evaluate("laws", kc, Xg.T, xdot.T)
    v_obj, w_obj = np.asarray(laws[0]).T, np.asarray(laws[1]).T
    phi, angles, _ = force_angles(pts, nrm)
    margin = math.atan(problem.mu) - phi
    fg: FloatArray | None = None
    tg: FloatArray | None = None
    if col.forces is not None:  # the planned forces on the grid (nodes, midpoints)
        fg = np.concatenate([col.forces.f_nodes, col.forces.f_mid])[order]
        tg = np.concatenate([col.forces.tau_nodes, col.forces.tau_mid])[order]
    contacts = [ContactTrajectory(c.label(problem), c.body, Xg[:, c.eta_cols],
                                  xdot[:, c.eta_cols], Ug[:, c.w_cols], pts[:, j],
                                  nrm[:, j], angles[:, j],
                                  None if fg is None else fg[:, j],
                                  None if tg is None else tg[:, j])
                for j, c in enumerate(m.point_contacts)]
    fingers = []
    for i, tip in enumerate(m.fingertips):
        torques = None
        if fg is not None and tg is not None and finite:
            j = m.point_contacts.index(tip)
            torques = joint_torques(tip.finger, Xg[:, tip.q_cols], pts[:, j], nrm[:, j],
                                    fg[:, j], tg[:, j],
                                    col.forces.gravity if col.forces else (0.0, 0.0, 0.0))
        fingers.append(FingerTrajectory(tip.label(problem), tuple(tip.finger.joint_names),
                                        Xg[:, tip.q_cols], xdot[:, tip.q_cols], p_pf[:, i],
                                        R_pf[:, i], torques))
    Rd = Pd = ep = ea = None
    if problem.motion is not None:
        Rd, Pd = problem.motion.at(t)
        ep = np.linalg.norm(p_po - Pd, axis=1)
        ea = rotation_angle_between(Rd, R_po)
    failures = cert.failures
    if status is Status.SOLVED and failures:
        status = Status.INACCURATE
    message = {
        Status.SOLVED: "converged; certificate passed",
        Status.INACCURATE: "converged, but the certificate failed: " + "; ".join(failures),
    }.get(status, f"not solved: IPOPT {raw}; the last iterate is returned")
    return ManipulationSolution(
        status=status, message=message, raw_status=raw, t=t, object_position=p_po,
        object_rotation=R_po,
        object_velocity=v_obj, object_angular_velocity=w_obj, contacts=tuple(contacts),
        fingers=tuple(fingers), grasp_angle=phi, cone_margin=margin, desired_position=Pd,
        desired_rotation=Rd, tracking_position_error=ep, tracking_angle_error=ea,
        goal_error=goal_error, certificate=cert, certificate_failures=failures, X=Xg, U=Ug,
        collocation=col, object_side_chart=problem.object.side_chart,
        chart_switch=problem.chart_switch,
        _interpolant=_Interpolant(charts, traj) if finite else None)
