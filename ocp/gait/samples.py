"""A gait at given times (docs/gait.md): every finger's joints, the object's pose, each
fingertip's contact (point, normal, planned force) and its activity, and the tips'
poses; what the wire result carries and what the simulator executes."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ocp.gait.planner import GaitPlan
from ocp.geometry.bodies import tip_body
from ocp.geometry.rotations import axis_angle_rotation, quaternion_matrix, quaternion_wxyz
from ocp.solution import joint_torques

__all__ = ["LINK_CHECK_RATE", "TRANSITION", "GaitSamples", "gait_samples", "gait_times",
           "with_link_clearance"]

FloatArray = NDArray[np.float64]

#: A contact's activity in a swing's lift-off and approach: planned to leave or reach the
#: object there, neither touching (1) nor lifted clear of it (0).
TRANSITION = 0.25


@dataclass(frozen=True)
class GaitSamples:
    """A gait at the times ``t`` [s] (rows): every finger's joint angles, rates and
    accelerations (the fingers' columns one after the other), the object's centre and
    orientation (w, x, y, z), per fingertip (axis 1) its contact's point and the object's
    outward normal there (palm frame; where the line of centres meets the ball, also when
    lifted), the force it applies to the object [N] (zero when lifted) and its activity
    (1 touching, 0 lifted clear, between: the force ramps and the lift-off and approach,
    :data:`TRANSITION` at least), and each tip frame's pose."""

    t: FloatArray
    q: FloatArray
    q_dot: FloatArray
    q_ddot: FloatArray
    object_position: FloatArray
    object_wxyz: FloatArray
    point: FloatArray
    normal: FloatArray
    force: FloatArray
    active: FloatArray
    tip_position: FloatArray
    tip_wxyz: FloatArray
    #: per fingertip the torsion it applies about the object's outward normal [N m]
    #: (a roll's planned one; none in a hold or a swing)
    torsion: FloatArray | None = None
    #: every finger's joint torques [N m] (columns as ``q``):
    #: :func:`~ocp.solution.joint_torques`
    effort: FloatArray | None = None
    #: the object's velocity [m/s] and angular velocity [rad/s] (palm frame): a roll's,
    #: interpolated in its plan's dense samples and timed by the gait's clock; zero in the
    #: holds and swings (the object at rest)
    object_velocity: FloatArray | None = None
    object_angular_velocity: FloatArray | None = None
    #: per fingertip (axis 1) whether it touches the object: all but the fingertip a
    #: swing phase carries (its unloading and loading touch; a switch's time belongs to
    #: the phase it starts)
    touching: NDArray[np.bool_] | None = None
    #: per fingertip (axis 1) its contact point's velocity [m/s] (palm frame), and that
    #: velocity less the object's material point's there: the contact's motion over the
    #: object's surface (tangent to it while the tip touches; zero at rest)
    point_velocity: FloatArray | None = None
    over_object: FloatArray | None = None


#: The least time [s] between two samples of a gait's trajectories.
MIN_SAMPLE_GAP = 1e-6


def gait_times(gait: GaitPlan, rate: float) -> FloatArray:
    """Times at ``rate`` [Hz] over the gait, and every switch: strictly increasing, at
    least :data:`MIN_SAMPLE_GAP` apart (a time of the grid that near a switch is left
    out), so that no two points share a ``time_from_start`` in nanoseconds."""
    t = np.linspace(0.0, gait.duration, max(2, int(np.ceil(gait.duration * rate)) + 1))
    edges = np.unique([p.start for p in gait.phases] + [gait.duration])
    near = np.min(np.abs(t[:, None] - edges[None, :]), axis=1) < MIN_SAMPLE_GAP
    return np.unique(np.concatenate([t[~near], edges]))


def gait_samples(gait: GaitPlan, problem: Any, ts: FloatArray) -> GaitSamples:
    """The gait planned from the grasp ``problem`` at the times ``ts`` (increasing)."""
    if not gait.phases:
        raise ValueError("the gait has no phases")
    fingers = tuple(f.finger for f in problem.fingers)
    nf = len(fingers)
    cut = np.cumsum((0, *gait.nq))
    rho = float(problem.object.dimensions[0])
    n = ts.size
    Q, QD, QDD = (np.zeros((n, int(cut[-1]))) for _ in range(3))
    pos, wxyz = np.zeros((n, 3)), np.zeros((n, 4))
    force, torsion = np.zeros((n, nf, 3)), np.zeros((n, nf))
    vel, omega = np.zeros((n, 3)), np.zeros((n, 3))
    active = np.ones((n, nf))
    touching = np.ones((n, nf), dtype=bool)
    pose = problem.initial_pose
    last = (np.asarray(pose.position, dtype=float), pose.rotation)
    phase_of = np.array([next((j for j, p in enumerate(gait.phases) if t <= p.end + 1e-12),
                              len(gait.phases) - 1) for t in ts])
    for j, ph in enumerate(gait.phases):
        if ph.kind == "roll":
            sol = gait.rolls[ph.index]
            end = (sol.object_position[-1], gait.rotation(ph.index, sol.object_rotation[-1]))
        rows = np.flatnonzero(phase_of == j)
        if not rows.size:
            if ph.kind == "roll":
                last = end
            continue
        tl = ts[rows] - ph.start
        if ph.kind == "roll":  # the roll's own polynomials on its clock, every time at once
            Q[rows], QD[rows], QDD[rows] = gait.roll_joints(ph.index, tl)
            s, ds, _ = gait.clock(ph.index)(tl)
            smp = sol.sample(s)
            for j3 in range(3):  # (the roll's frame change is a fixed right factor: the
                # palm-frame angular velocity is the roll's own)
                vel[rows, j3] = ds * np.interp(s, sol.t, sol.object_velocity[:, j3])
                omega[rows, j3] = ds * np.interp(s, sol.t, sol.object_angular_velocity[:, j3])
            pos[rows] = smp.object_position
            wxyz[rows] = quaternion_wxyz(gait.rotation(ph.index, smp.object_rotation))
            F, M = sol.forces(s)
            if ph.lifted is not None:  # a fingertip swings during this roll: no force
                F, M = np.insert(F, ph.lifted, 0.0, axis=1), np.insert(M, ph.lifted, 0.0,
                                                                       axis=1)
                swung = gait.steps[gait.carried[ph.index]].swing
                assert swung is not None
                active[rows, ph.lifted] = [0.0 if swung.segment(float(x)) == "clear"
                                           else TRANSITION for x in tl]
            force[rows], torsion[rows] = F, M
            last = end
            continue
        for r, t in zip(rows, ts[rows], strict=True):
            Q[r], QD[r], QDD[r] = gait.joints(float(t))
        pos[rows], wxyz[rows] = last[0], quaternion_wxyz(last[1])
        step = gait.steps[ph.index]
        k = step.finger
        s = step.ramp_share(tl / max(ph.end - ph.start, 1e-12))
        if ph.kind == "swing":
            force[rows] = step.ramp_forces("swing", 0.0)
            assert step.swing is not None
            active[rows, k] = [0.0 if step.swing.segment(float(x)) == "clear"
                               else TRANSITION for x in tl]
        else:
            force[rows] = np.array([step.ramp_forces(ph.kind, float(x)) for x in s])
            active[rows, k] = np.maximum(1.0 - s if ph.kind == "unload" else s, TRANSITION)
            if ph.kind == "unload" and step.landing is not None:  # loaded meanwhile
                active[rows, step.landing] = np.maximum(s, TRANSITION)
    # touching: a switch's time belongs to the phase it starts (the last time to the last
    # phase): a swing's lift-off instant is the swing's, its landing the load's
    for i, t in enumerate(ts):
        ph = next((p for p in gait.phases if p.start <= t < p.end), gait.phases[-1])
        if ph.kind in ("swing", "roll") and ph.lifted is not None:
            touching[i, ph.lifted] = False
    shape, dims = problem.object.kind, problem.object.dimensions
    axes = None if shape.ball_radius(dims) is not None else \
        np.array([quaternion_matrix(w) for w in wxyz])
    points, normals, tip_p, tip_q = _contacts(problem, cut, Q, pos, axes, rho)
    # the contact points' velocities: their central difference over the plan's own rates
    # (the joints to second order, the object's pose to first; a switch's time with the
    # phase it starts, as the rates are)
    moved = []
    for dt in (VELOCITY_STEP, -VELOCITY_STEP):
        turned = None if axes is None else \
            np.array([_turn(w, dt) @ R for w, R in zip(omega, axes, strict=True)])
        moved.append(_contacts(problem, cut, Q + dt * QD + 0.5 * dt * dt * QDD,
                               pos + dt * vel, turned, rho, poses=False)[0])
    point_velocity = (moved[0] - moved[1]) / (2.0 * VELOCITY_STEP)
    over = point_velocity - vel[:, None] - np.cross(omega[:, None], points - pos[:, None])
    gravity = problem.forces.gravity if problem.forces is not None else (0.0, 0.0, 0.0)
    effort = np.hstack([joint_torques(f, Q[:, cut[c]:cut[c + 1]], points[:, c],
                                      normals[:, c], force[:, c], torsion[:, c], gravity)
                        for c, f in enumerate(fingers)])
    return GaitSamples(ts, Q, QD, QDD, pos, wxyz, points, normals, force, active, tip_p,
                       tip_q, torsion, effort, vel, omega, touching, point_velocity, over)


#: The time step [s] of the contact points' central differences (:func:`gait_samples`).
VELOCITY_STEP = 1e-5


def _turn(omega: FloatArray, dt: float) -> FloatArray:
    """The rotation of angular velocity ``omega`` [rad/s] (palm frame) over ``dt``."""
    w = float(np.linalg.norm(omega))
    return np.eye(3) if w == 0.0 else axis_angle_rotation(omega / w, w * dt)


def _contacts(problem: Any, cut: FloatArray, Q: FloatArray, pos: FloatArray,
              axes: FloatArray | None, rho: float, poses: bool = True
              ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Per sample (rows of the joints ``Q``, the object's centre ``pos`` and orientation
    ``axes``, None for a ball) and fingertip: the contact point and the object's outward
    normal there, the tip frame's origin and orientation (w, x, y, z; zeros without
    ``poses``)."""
    fingers = tuple(f.finger for f in problem.fingers)
    n, nf = Q.shape[0], len(fingers)
    points, normals = np.zeros((n, nf, 3)), np.zeros((n, nf, 3))
    tip_p, tip_q = np.zeros((n, nf, 3)), np.zeros((n, nf, 4))
    shape, dims = problem.object.kind, problem.object.dimensions
    for c, f in enumerate(fingers):  # the caps' nearest points, every sample at once
        Rs, tip_p[:, c] = f.tip_poses(Q[:, cut[c]:cut[c + 1]])
        d = tip_p[:, c] + Rs @ tip_body(f).a - pos
        if axes is None:  # a ball's: the line of centres (Held.contact)
            normals[:, c] = d / np.linalg.norm(d, axis=1)[:, None]
            points[:, c] = pos + rho * normals[:, c]
        else:  # on the object's surface where it is at each sample
            x, nrm, _ = shape.nearest(dims, np.einsum("kji,kj->ki", axes, d))
            points[:, c] = pos + np.einsum("kij,kj->ki", axes, x)
            normals[:, c] = np.einsum("kij,kj->ki", axes, nrm)
        if poses:
            tip_q[:, c] = quaternion_wxyz(Rs)
    return points, normals, tip_p, tip_q


#: Samples a second at which a gait's links are checked (its rolls' own certificates check
#: them at their dense samples too).
LINK_CHECK_RATE = 100.0


def with_link_clearance(gait: GaitPlan, problem: Any, samples: GaitSamples | None = None
                        ) -> GaitPlan:
    """``gait`` with its certificate's ``gait_link_clearance``: the hand's links (MuJoCo's
    pairs, ``problem.collision``) at least ``LINK_CLEARANCE`` apart over the whole gait at
    :data:`LINK_CHECK_RATE` and every switch, a fingertip's own contact with the object
    left out while it is active at all (its swing checks hold it clear of the ball when
    lifted). Unchanged without a collision model or phases; call it on what
    :func:`~ocp.gait.planner.plan_gait` returns. ``samples``: the gait's samples already
    made at :func:`gait_times` of at least that rate (else made here)."""
    from ocp.certify.certificate import Certificate
    from ocp.solve.certify import link_clearance_check

    if getattr(problem, "collision", None) is None or not gait.phases:
        return gait
    smp = samples if samples is not None else \
        gait_samples(gait, problem, gait_times(gait, LINK_CHECK_RATE))
    R = np.array([quaternion_matrix(w) for w in smp.object_wxyz])
    check = link_clearance_check(problem, smp.t, smp.q, R, smp.object_position,
                                 smp.active > 0.0, name="gait_link_clearance")
    gait.certificate = Certificate.of([*gait.certificate.checks, check])
    return gait
