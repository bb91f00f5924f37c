"""The physical certificate of a grasp's plan: a statement about the trajectory returned.

The returned trajectory is the plan's :class:`~ocp.transcription.collocation.HermiteInterpolant`
(the one ``sample(t)`` gives and the wire documents). It is checked at
:data:`~ocp.certify.certificate.CHECK_POINTS` of every interval (nodes from both sides,
midpoints, and between): each contact's laws along the trajectory's own time derivative
(:mod:`ocp.solve.contact_checks`, by the contact's kind: slip and spin from the returned
poses, closure and gaps by Pinocchio at the returned joint angles, pads and joint limits),
tracking and force closure. Independently, the plan's inputs are re-integrated from its
initial state with CVODES over the whole horizon (never reset): its defects against the
returned states at the nodes *and* the midpoints, and the goals and via-points it reaches.
The result is one :class:`~ocp.certify.certificate.Certificate`; every check along the
motion names the time of its worst sample. (It lives in the solve layer: it reads the
transcription's trajectory and grasp model; the certificate's types,
:mod:`ocp.certify.certificate`, are a leaf below every layer.)

How strict it is comes from the problem's :class:`~ocp.certify.certificate.TolerancePolicy`
(docs/conventions.md): the contacts' laws are the same for every grasp; the defects are the
problem's options'.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from ocp.certify.certificate import Certificate, Check, CheckKind, TolerancePolicy
from ocp.geometry.grasp import force_angles
from ocp.geometry.rotations import rotation_angle_between
from ocp.solve.contact_checks import CertificateContext, contact_checks
from ocp.spec.grasp import ManipulationProblem, support_goal_errors
from ocp.transcription.chart_switch import PlanCharts
from ocp.transcription.collocation import HermiteInterpolant, PlannedForces

if TYPE_CHECKING:
    from ocp.transcription.grasp_model import GraspModel

__all__ = ["certify_grasp", "check_samples", "force_checks", "sample_intervals", "timing_checks",
           "with_force_checks"]

#: Relative tolerance of the planned forces' checks between collocation points: the
#: equilibrium residual (of the force scale; moments of it times the object's size) and
#: the normal force's shortfall below the minimum (of the minimum). At the collocation
#: points both hold to IPOPT's tolerance; between them the interpolated forces and the
#: returned poses differ from an exact equilibrium by O(h^3).
FORCE_REL_TOL = 1e-3
#: Tolerance of the smooth timing's rest and continuity checks, of the state's rate scale
#: (length / duration, or 1 / duration for angles): both hold exactly by construction (the
#: inputs at the ends are fixed at zero, one input per node), so anything above round-off
#: is a defect.
TIMING_REL_TOL = 1e-9

FloatArray = NDArray[np.float64]


def _wrapped(d: FloatArray, periodic: list[bool]) -> FloatArray:
    """Differences of the periodic columns taken modulo 2 pi into [-pi, pi) (only where
    they exceed pi: elsewhere the wrap would only add round-off)."""
    out = d.copy()
    cols = [j for j, p in enumerate(periodic) if p]
    sub = out[:, cols]
    out[:, cols] = np.where(np.abs(sub) > np.pi, (sub + np.pi) % (2 * np.pi) - np.pi, sub)
    return out


def sample_intervals(traj: HermiteInterpolant, points: tuple[float, ...]
                     ) -> tuple[NDArray[np.intp], FloatArray]:
    """(interval, normalised time) of every check sample: ``points`` of every interval,
    in time order (:func:`check_samples`' samples)."""
    n, s = len(traj.t_nodes) - 1, np.asarray(points, dtype=float)
    return np.repeat(np.arange(n), len(s)), np.tile(s, n)


def check_samples(traj: HermiteInterpolant, points: tuple[float, ...]
                  ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Where the returned trajectory is checked: (times, states, their time derivatives,
    time weights of the RMS scales) at normalised times ``points`` of every interval, in
    time order (a node twice: as the end of one interval and the start of the next, with
    each side's rate)."""
    n, s = len(traj.t_nodes) - 1, np.asarray(points, dtype=float)
    k, ss = sample_intervals(traj, points)
    h = np.diff(traj.t_nodes)
    t = traj.t_nodes[k] + h[k] * ss
    # trapezoid weights over the equal steps (the extra points weigh nothing)
    uniform = np.isclose(s * 8, np.round(s * 8))
    w1 = np.where(uniform, 1.0, 0.0)
    w1[uniform] = np.r_[0.5, np.ones(int(uniform.sum()) - 2), 0.5] / (uniform.sum() - 1)
    return t, traj.on_intervals(k, ss), traj.on_intervals(k, ss, order=1), \
        np.tile(w1, n) * h[k]


def _rms(values: FloatArray, weights: FloatArray) -> float:
    total = float(np.sum(weights))
    return math.sqrt(float(np.sum(weights * values**2)) / total) if total > 0 else 0.0


def force_checks(problem: ManipulationProblem, forces: PlannedForces,
                 traj: HermiteInterpolant, points: tuple[float, ...], ts: FloatArray,
                 p_po: FloatArray, R_po: FloatArray, pts: FloatArray, nrm: FloatArray
                 ) -> tuple[list[Check], dict[str, float]]:
    """The planned forces' checks on the samples (:func:`check_samples` of the normalised
    times ``points``, at times ts; the returned object pose and contact points and
    outward normals, palm frame):
    the object's quasi-static equilibrium with its weight, every force inside its
    friction cone (the request's mu, not the NLP's narrowed one), every normal force at
    least the minimum, every torsion within its limit. The forces between collocation
    points: :meth:`~ocp.transcription.collocation.PlannedForces.on_intervals` (quadratic,
    like the inputs)."""
    from ocp.transcription.values import force_scale

    fs = problem.forces
    assert fs is not None
    D = CheckKind.DISCRETISATION
    f, tau = forces.on_intervals(*sample_intervals(traj, points))
    F0, L = force_scale(problem), problem.object.length_scale
    weight = fs.mass * np.asarray(fs.gravity, dtype=float)
    r = pts - p_po[:, None, :]
    res_f = np.linalg.norm(f.sum(axis=1) + weight, axis=1) / F0
    res_m = np.linalg.norm((np.cross(r, f) + tau[:, :, None] * nrm).sum(axis=1),
                           axis=1) / (F0 * L)
    fn = -np.einsum("kci,kci->kc", nrm, f)
    ft = np.linalg.norm(f + fn[:, :, None] * nrm, axis=2)
    cone = (problem.mu * fn - ft) / F0
    tors = (fs.torsional_friction * fn - np.abs(tau)) / (F0 * L)
    checks = []
    for name, values, tol in (("max_force_equilibrium_residual", res_f, FORCE_REL_TOL),
                              ("max_moment_equilibrium_residual", res_m, FORCE_REL_TOL)):
        j = int(np.argmax(values))
        checks.append(Check(name, float(values[j]), tol, D, time=float(ts[j])))
    for name, values, tol in (
            ("min_friction_cone_margin", cone.min(axis=1), 0.0),
            ("min_normal_force", fn.min(axis=1), fs.min_normal_force * (1 - FORCE_REL_TOL)),
            ("min_torsion_margin", tors.min(axis=1), -1e-12)):
        j = int(np.argmin(values))
        checks.append(Check(name, float(values[j]), tol, D, lower_bound=True,
                            time=float(ts[j])))
    reported = {"max_normal_force": float(fn.max()),
                "max_tangential_force_ratio": float(np.max(ft / np.maximum(fn, 1e-300)))}
    return checks, reported


def timing_checks(problem: ManipulationProblem, m: GraspModel, traj: HermiteInterpolant,
                  charts: PlanCharts | None = None) -> list[Check]:
    """The smooth timing's laws on the returned trajectory: every state at rest at both ends
    (its rate there), no state's rate jumps at any node (the rates from the interval before
    and after), every joint's acceleration within ``max_joint_acceleration`` (the cubic's
    second derivative is linear on an interval, so the values at both ends of every
    interval bound it). At a chart switch (``charts``) the rate after it is read on the
    chart before (the map's Jacobian): the same motion's rate on both sides."""
    T = float(traj.t_nodes[-1] - traj.t_nodes[0])
    scale = np.full(m.nx, 1.0 / T)
    scale[m.length_columns()] = problem.object.length_scale / T
    rest = np.abs(np.vstack([traj.F0[0], traj.F1[-1]])) / scale
    checks = []
    if problem.reference is not None:  # a window of a longer motion: moving at both ends
        rest[:] = 0.0
    if problem.initial_input is not None:  # a moving start: its given input, not rest
        rest[0] = 0.0
        u0 = np.asarray(problem.initial_input, dtype=float)
        u_scale = np.maximum(np.abs(u0), np.max(np.abs(traj.U0), axis=0))
        err = np.abs(traj.U0[0] - u0) / np.maximum(u_scale, 1e-300)
        checks.append(Check("max_initial_input_error", float(err.max(initial=0.0)),
                            TIMING_REL_TOL, CheckKind.PHYSICS, time=float(traj.t_nodes[0])))
    after = np.array(traj.F0[1:], dtype=float)
    if charts is not None and charts.switched:
        ks = charts.node
        assert ks is not None
        after[ks - 1] = charts.rate_to_first(traj.X[ks], traj.F0[ks])
    jumps = np.abs(traj.F1[:-1] - after) / scale
    k_jump = int(np.argmax(jumps.max(axis=1))) if len(jumps) else 0
    P = CheckKind.PHYSICS
    checks += [Check("max_rest_rate", float(rest.max()), TIMING_REL_TOL, P,
                    time=float(traj.t_nodes[0] if rest[0].max() >= rest[1].max()
                               else traj.t_nodes[-1])),
              Check("max_velocity_jump", float(jumps.max(initial=0.0)), TIMING_REL_TOL, P,
                    time=float(traj.t_nodes[k_jump + 1]))]
    joints = m.joint_columns()
    if joints:
        n = len(traj.t_nodes) - 1
        k = np.repeat(np.arange(n), 2)
        s = np.tile([0.0, 1.0], n)
        acc = np.abs(traj.on_intervals(k, s, order=2)[:, joints]).max(axis=1)
        j = int(np.argmax(acc))
        h = traj.t_nodes[k[j] + 1] - traj.t_nodes[k[j]]
        checks.append(Check("max_joint_acceleration", float(acc[j]),
                            problem.max_joint_acceleration * (1 + 1e-6), CheckKind.LIMITS,
                            time=float(traj.t_nodes[k[j]] + s[j] * h)))
    return checks


def with_force_checks(cert: Certificate, problem: ManipulationProblem, m: GraspModel,
                      traj: HermiteInterpolant, prm: FloatArray, policy: TolerancePolicy,
                      forces: PlannedForces, charts: PlanCharts | None = None
                      ) -> Certificate:
    """The certificate ``cert`` of the plan ``traj`` (its kinematics, by
    :func:`certify_grasp`) with the checks of its planned ``forces`` added: the same
    samples, poses, points and normals as :func:`certify_grasp` gives
    :func:`force_checks`, without checking the kinematics again."""
    ts, sx, _, _ = check_samples(traj, policy.check_points)
    n = len(ts)
    charts = charts or PlanCharts.single(m, prm)
    cart = charts.evaluate("cartesian", charts.interval_charts(
        sample_intervals(traj, policy.check_points)[0]), sx.T)
    nc = m.n_contacts
    R_po = np.asarray(cart[0]).T.reshape(n, 3, 3).transpose(0, 2, 1)
    p_po = np.asarray(cart[1]).T
    pts = np.asarray(cart[4]).T.reshape(n, nc, 3)
    nrm = np.asarray(cart[5]).T.reshape(n, nc, 3)
    more, reported = force_checks(problem, forces, traj, policy.check_points, ts, p_po, R_po,
                                  pts, nrm)
    return Certificate.of([*cert.checks, *more], {**dict(cert.reported), **reported},
                          n_samples=cert.n_samples)


def touching_at(problem: ManipulationProblem, ts: FloatArray) -> NDArray[np.bool_]:
    """(n, fingertips): whether each fingertip's contact is active at ``ts`` (its phases;
    every one without)."""
    n, k = len(ts), len(problem.fingers)
    if problem.phases is None:
        return np.ones((n, k), dtype=bool)
    ends = np.cumsum([ph.duration for ph in problem.phases])
    j = np.minimum(np.searchsorted(ends, ts - ts[0], side="right"), len(ends) - 1)
    return np.array([problem.phases[i].touching for i in j], dtype=bool).reshape(n, k)


def link_clearance_check(problem: ManipulationProblem, ts: FloatArray, q: FloatArray,
                         R_po: FloatArray, p_po: FloatArray,
                         touching: NDArray[np.bool_] | None = None,
                         name: str = "min_link_clearance") -> Check:
    """``min_link_clearance``: every pair of the hand's collision geoms MuJoCo would
    collide (and each with the object) at least ``LINK_CLEARANCE`` apart at the samples
    ``ts`` (joints ``q`` in the fingers' order, the object at ``R_po``, ``p_po``), but
    for a touching fingertip and the object (``touching`` (n, fingertips); default: by
    the problem's phases) (:mod:`ocp.robots.collision`)."""
    from ocp.robots.collision import LINK_CLEARANCE

    names = [n for f in problem.fingers for n in f.finger.joint_names]
    c = problem.collision.least(problem.object.shape, problem.object.dimensions, names, q,
                                R_po, p_po,
                                touching_at(problem, ts) if touching is None else touching)
    at = float(ts[c.sample]) if c.sample >= 0 else None
    return Check(name, c.value, LINK_CLEARANCE, CheckKind.PHYSICS,
                 lower_bound=True, time=at,
                 reason="" if c.passed else
                 f"{name}: {c.describe()} at t = {at:.6g} s (at least "
                 f"{LINK_CLEARANCE * 1e3:g} mm kept between links not in a planned contact)")


def certify_grasp(problem: ManipulationProblem, m: GraspModel, traj: HermiteInterpolant,
                  prm: FloatArray, policy: TolerancePolicy,
                  forces: PlannedForces | None = None, charts: PlanCharts | None = None
                  ) -> Certificate:
    """The certificate of a plan as returned (``traj``, and its planned ``forces``): see
    the module's doc. ``charts``: the plan's charts (default one: ``m``, ``prm``); with
    a chart switch each sample is measured on its interval's chart, and the
    re-integration goes on across the switch from the state it reached there."""
    arrays = (traj.X, traj.F0, traj.F1, traj.U0, traj.Um, traj.U1)
    if not all(np.all(np.isfinite(a)) for a in arrays):
        return Certificate.failed("the plan has non-finite states or inputs")
    t_nodes, o = traj.t_nodes, problem.options
    D = CheckKind.DISCRETISATION
    # the independent re-integration of the inputs: states at every node and midpoint
    charts = charts or PlanCharts.single(m, prm)
    try:
        Xr, sx = charts.reintegrate(traj.X[0], t_nodes, traj.U0, traj.Um, traj.U1, traj.X)
    except RuntimeError as exc:  # CVODES gave up: the plan is not a smooth motion
        return Certificate.failed(f"re-integration failed: {str(exc).splitlines()[-1]}")
    n_int = len(t_nodes) - 1
    mids = np.arange(n_int)
    t_mid = (t_nodes[:-1] + t_nodes[1:]) / 2
    Xm = traj.on_intervals(mids, np.full(n_int, 0.5))
    periodic = [False] * m.nx
    for c in m.contacts:
        for j in c.periodic_columns:
            periodic[c.x0 + j] = True
    d = _wrapped(np.vstack([Xr - traj.X, sx[1::2] - Xm]), periodic)
    t_d = np.concatenate([t_nodes, t_mid])

    def defect(name: str, cols: list[int], tol: float) -> Check:
        v = np.max(np.abs(d[:, cols]), axis=1)
        j = int(np.argmax(v))
        return Check(name, float(v[j]), tol, D, time=float(t_d[j]))

    checks = [defect("max_length_defect", m.length_columns(), policy.length_defect(o)),
              defect("max_angle_defect", m.angle_columns(), policy.angle_defect(o))]
    if m.fingertips:
        checks.append(defect("max_joint_defect", m.joint_columns(), policy.angle_defect(o)))
    segments, _ = problem.segments()
    goal_err = support_goal_errors(problem, Xr, [0, *np.cumsum(segments).tolist()])
    if goal_err:
        # the goals the re-integrated motion reaches: the NLP meets them to IPOPT's
        # tolerance, so a miss here is drift between collocation points
        checks.append(Check("max_goal_error", max(goal_err.values()), policy.goal(o), D))
    # the returned trajectory, densely
    ts, sx, sxd, wts = check_samples(traj, policy.check_points)
    n = len(ts)
    kc = charts.interval_charts(sample_intervals(traj, policy.check_points)[0])
    laws = dict(zip(m.laws.name_out(), (np.asarray(a).T for a in
                                        charts.evaluate("laws", kc, sx.T, sxd.T)),
                    strict=True))
    cart = charts.evaluate("cartesian", kc, sx.T)
    nc, nf = m.n_contacts, len(m.fingertips)
    R_po = np.asarray(cart[0]).T.reshape(n, 3, 3).transpose(0, 2, 1)
    p_po = np.asarray(cart[1]).T
    pts = np.asarray(cart[4]).T.reshape(n, nc, 3)
    nrm = np.asarray(cart[5]).T.reshape(n, nc, 3)
    L, T = problem.object.length_scale, float(t_nodes[-1] - t_nodes[0])
    speeds = [laws[k].ravel() for k in laws if k.startswith("contact_speed_")]
    rates = [laws[k].ravel() for k in laws if k.startswith("rolling_rate_")]
    speed = max(_rms(np.concatenate(speeds), np.tile(wts, len(speeds))) if speeds else 0.0,
                policy.speed_floor * L / T)
    rate = max(_rms(np.concatenate(rates), np.tile(wts, len(rates))) if rates else 0.0,
               speed / L)
    ctx = CertificateContext(
        times=ts, laws=laws, R_po=R_po, p_po=p_po,
        R_pf=np.asarray(cart[2]).T.reshape(n, nf, 3, 3).transpose(0, 1, 3, 2)
        if nf else np.zeros((n, 0, 3, 3)),
        p_pf=np.asarray(cart[3]).T.reshape(n, nf, 3), states=sx,
        shape=np.asarray(problem.object.params, dtype=float), L=L, speed=speed,
        rate=rate, policy=policy)
    for k, c in enumerate(m.contacts):
        checks += contact_checks(c, problem, k, ctx)
    reported: dict[str, float] = {"speed_scale": speed, "rolling_rate_scale": rate}
    if problem.motion is not None:
        Rd, Pd = problem.motion.at(ts)
        tr = problem.tracking
        for name, values, tol in (
                ("max_tracking_position_error", np.linalg.norm(p_po - Pd, axis=1),
                 tr.position_tolerance),
                ("max_tracking_angle_error", rotation_angle_between(Rd, R_po),
                 tr.orientation_tolerance)):
            if tol is None:
                reported[name] = float(np.max(values))
            else:
                checks.append(ctx.check(name, values, tol, D))
    if nc >= 2:  # force closure (the object on the palm alone has no grasp to certify)
        phi, _, onto = force_angles(pts, nrm)
        margin = math.atan(problem.mu) - phi
        j = int(np.argmin(margin))
        checks.append(Check("min_cone_margin", float(margin[j]), policy.cone_margin,
                            CheckKind.PHYSICS, lower_bound=True, report_tolerance=False,
                            reason=f"min_cone_margin {margin[j]:.3g} < 0 at t = "
                                   f"{ts[j]:.6g} s (force closure lost)", time=float(ts[j])))
        reported["max_grasp_angle"] = float(np.max(phi))
        if not np.all(onto):
            checks.append(Check("grasp_map_onto", 0.0, 1.0, CheckKind.PHYSICS,
                                lower_bound=True, report_tolerance=False, report_value=False,
                                reason="the grasp map is not onto at t = "
                                       f"{ts[int(np.argmin(onto))]:.6g} s (force closure "
                                       "lost)"))
    if forces is not None and problem.forces is not None:
        more, rep_ = force_checks(problem, forces, traj, policy.check_points, ts, p_po, R_po,
                                  pts, nrm)
        checks += more
        reported.update(rep_)
    if problem.collision is not None:
        checks.append(link_clearance_check(problem, ts, sx[:, m.joint_columns()], R_po,
                                           p_po))
    if problem.smooth:
        checks += timing_checks(problem, m, traj, charts)
    return Certificate.of(checks, reported, n_samples=n)
