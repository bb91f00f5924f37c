"""Executing a plan in MuJoCo: :func:`simulate` builds the scene (:mod:`.scene`), runs
the controller (:class:`~.options.SimOptions`) over the plan's horizon after a settling
phase, and measures how closely the object followed the plan (:class:`~.report.SimReport`).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

import mujoco
import numpy as np

from .options import SimOptions
from .report import ContactReport, ErrorSummary, SimReport
from .scene import mjcf
from .spec import ExecutionPlan, FloatArray

__all__ = ["Simulation", "StepRows", "hermite", "object_contacts", "simulate", "slerp",
           "step_grid"]

#: A contact whose normal force is at most this [N] is not touching.
TOUCH_FORCE = 1e-6
#: A planned contact counts as touching (its loss a failure) where its ``active`` share is
#: at least this (a gait's force ramps end at zero: the last part of an unloading may lose
#: the contact early, as planned).
ACTIVE_SHARE = 0.5
#: A fingertip's squeeze and grip go linearly from none at this activity to all at 1 (a
#: gait's lift-off and approach are at a quarter: no squeeze while it leaves or reaches
#: the object; at the loss threshold a third of it keeps the contact as planned).
SQUEEZE_FROM = 0.25
#: How far apart [m] a lost contact's bodies are measured, at most (a loss's separation).
SEPARATION_MAX = 0.01
#: The report's time series has at most about this many rows (a long plan is recorded
#: less often than ``record_every`` asks).
MAX_SERIES = 5000


def _unique(t: FloatArray) -> np.ndarray:
    """Indices of the samples kept for interpolation: of repeated times (a rate break
    listed twice), the last (the outgoing side)."""
    keep = np.ones(t.size, dtype=bool)
    keep[:-1] = np.diff(t) > 0
    return np.flatnonzero(keep)


def hermite(t: FloatArray, y: FloatArray, dy: FloatArray, ts: FloatArray
            ) -> tuple[FloatArray, FloatArray]:
    """The cubic Hermite interpolant through (t, y, dy) and its derivative at ``ts``
    (clamped to [t0, tN]); rows of y, dy are samples, t non-decreasing. A time listed twice
    is a rate break (the plan's velocities jump there): the interval before it ends with
    the first row's rate, the one after starts with the second's; at the break itself the
    outgoing rate."""
    times, first = np.unique(t, return_index=True)
    last = np.searchsorted(t, times, side="right") - 1
    ts = np.clip(ts, times[0], times[-1])
    k = np.clip(np.searchsorted(times, ts, side="right") - 1, 0, times.size - 2)
    a, b = last[k], first[k + 1]
    h = (times[k + 1] - times[k])[:, None]
    s = (ts - times[k])[:, None] / h
    h00, h10, h01, h11 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s, -2 * s**3 + 3 * s**2, \
        s**3 - s**2
    value = h00 * y[a] + h10 * h * dy[a] + h01 * y[b] + h11 * h * dy[b]
    d00, d10, d01, d11 = 6 * s**2 - 6 * s, 3 * s**2 - 4 * s + 1, -6 * s**2 + 6 * s, \
        3 * s**2 - 2 * s
    rate = (d00 * y[a] + d01 * y[b]) / h + d10 * dy[a] + d11 * dy[b]
    return value, rate


def _linear(t: FloatArray, y: FloatArray, ts: FloatArray) -> FloatArray:
    keep = _unique(t)
    t, y = t[keep], y[keep]
    return np.stack([np.interp(ts, t, y[:, j]) for j in range(y.shape[1])], axis=1)


def slerp(t: FloatArray, q: FloatArray, ts: FloatArray) -> FloatArray:
    """Unit quaternions (w, x, y, z) interpolated along the geodesic at ``ts``."""
    keep = _unique(t)
    t, q = t[keep], q[keep] / np.linalg.norm(q[keep], axis=1, keepdims=True)
    ts = np.clip(ts, t[0], t[-1])
    i = np.clip(np.searchsorted(t, ts, side="right") - 1, 0, t.size - 2)
    s = ((ts - t[i]) / (t[i + 1] - t[i]))[:, None]
    q0, q1 = q[i], q[i + 1]
    dot = np.sum(q0 * q1, axis=1, keepdims=True)
    q1 = np.where(dot < 0, -q1, q1)
    dot = np.abs(dot)
    theta = np.arccos(np.clip(dot, -1.0, 1.0))
    small = theta < 1e-9
    sin = np.where(small, 1.0, np.sin(theta))
    a = np.where(small, 1 - s, np.sin((1 - s) * theta) / sin)
    b = np.where(small, s, np.sin(s * theta) / sin)
    out = a * q0 + b * q1
    return out / np.linalg.norm(out, axis=1, keepdims=True)


def _angle_between(qa: FloatArray, qb: FloatArray) -> FloatArray:
    dot = np.abs(np.sum(qa * qb, axis=1)) / (np.linalg.norm(qa, axis=1)
                                              * np.linalg.norm(qb, axis=1))
    return 2.0 * np.arccos(np.clip(dot, -1.0, 1.0))


def _damped_pinv(J: FloatArray, damping: float = 1e-8) -> FloatArray:
    return J.T @ np.linalg.inv(J @ J.T + damping * np.eye(J.shape[0]))


@dataclass
class _FingerIndex:
    qpos: np.ndarray
    dofs: np.ndarray
    actuators: np.ndarray
    tip_body: int
    tip_site: int


@dataclass
class _ForceLoop:
    """One fingertip's contact-force feedback (:meth:`Simulation._force_loops`): its
    finger ``k``, its contact ``j``, per step the torques of a unit push along the
    contact's normal ``unit`` (steps x joints), the feedback's ``weight``, the
    ``target`` normal force [N] (the planned one, at least the floor) and ``extra``, the
    target less the planned force (fed forward); ``integral`` the PI law's integral
    term [N], ``shift`` the admittance's set-point shift along the normal [m], at most
    ``shift_limit`` [m], its rate ``shift_ki`` [m/(N s)] times the force's error
    (:func:`admittance_range`)."""

    k: int
    j: int
    unit: FloatArray
    weight: FloatArray
    target: FloatArray
    extra: FloatArray
    shift_limit: float
    shift_ki: float
    integral: float = 0.0
    shift: float = 0.0


#: A contact's lever [m] below which its object's surface does not move under it when the
#: object turns about its centre: a ball's (its normals through its centre, to rounding).
ROUND_LEVER = 1e-6


def admittance_range(o: SimOptions, point: FloatArray, normal: FloatArray,
                     centre: FloatArray, active: FloatArray | None) -> tuple[float, float]:
    """A contact's admittance (``force_control`` 'admittance'): (the bound [m] of its
    set point's shift, its rate [m/(N s)]). Turned by an error of ``a`` [rad] about its
    centre, the object's surface moves under a contact at ``p`` with normal ``n`` by up
    to ``a |(p - c) x n|`` along the normal: nothing for a ball, up to 0.7 mm for a
    fingertip 20 mm off a 50 mm cube's face centre at 2 deg. The shift follows it as far
    as the run's orientation tolerance: ``force_shift_limit`` plus that motion at the
    contact's largest lever while touching, at a rate that crosses the range as fast as
    ``force_shift_ki`` crosses ``force_shift_limit``. A ball's contacts keep the options'
    own (their lever under :data:`ROUND_LEVER`)."""
    lever = np.linalg.norm(np.cross(point - centre, normal), axis=1)
    if active is not None:
        lever = lever[np.asarray(active) > 0.0]
    top = float(lever.max(initial=0.0))
    if top < ROUND_LEVER:
        return o.force_shift_limit, o.force_shift_ki
    limit = o.force_shift_limit + o.tolerances.angle * top
    return limit, o.force_shift_ki * limit / o.force_shift_limit


@dataclass
class StepRows:
    """The controller's rows at every step (times ``ts`` on the plan's clock plus its
    t0): per finger the servo's set point ``ctrl``, the torque feed-forward ``tau``, the
    reference angles ``q_ref`` and rates ``qd_ref`` (steps x joints), and the grip's
    joint offset ``offset`` that ``q_ref`` has on top of the plan's angles (the squeeze:
    what a controller measuring the joints takes off before it estimates the grasp)."""

    ts: FloatArray
    ctrl: list[FloatArray]
    tau: list[FloatArray]
    q_ref: list[FloatArray]
    qd_ref: list[FloatArray]
    offset: list[FloatArray] = field(default_factory=list)


class Simulation:
    """A plan's scene in MuJoCo, ready to run (:meth:`run`); ``model`` and ``data`` are
    MuJoCo's, ``xml`` the scene's MJCF."""

    def __init__(self, plan: ExecutionPlan, options: SimOptions | None = None) -> None:
        plan.check()
        self.plan, self.options = plan, (options or SimOptions()).resolved(plan)
        self.options.check()
        self.xml = mjcf(plan, self.options)
        self.model = mujoco.MjModel.from_xml_string(self.xml)
        self.data = mujoco.MjData(self.model)
        m = self.model
        self.object_body = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "object")
        self.object_geom = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "object")
        joint = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, "object")
        self.object_qpos = int(m.jnt_qposadr[joint])
        self.object_dof = int(m.jnt_dofadr[joint])
        self.fingers: list[_FingerIndex] = []
        for f in plan.fingers:
            ids = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, f"{f.name}/{j.name}")
                   for j in f.joints]
            self.fingers.append(_FingerIndex(
                np.array([m.jnt_qposadr[i] for i in ids]),
                np.array([m.jnt_dofadr[i] for i in ids]),
                np.array([mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR,
                                            f"{f.name}/{j.name}") for j in f.joints]),
                mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, f"{f.name}/tip"),
                mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, f"{f.name}/tip")))
        # which planned contact each geom touching the object makes
        self.contact_of_geom: dict[int, int] = {}
        for k, c in enumerate(plan.contacts):
            name = "palm" if c.body == "palm" else f"{c.finger}/pad"
            gid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, name)
            if gid >= 0:
                self.contact_of_geom[gid] = k

    # -- the reference, the grip ----------------------------------------------------------
    def _feedforward(self, plan: ExecutionPlan | None = None
                     ) -> tuple[list[FloatArray], list[FloatArray], list[str]]:
        """At the plan's times (``plan``: another plan of this scene, e.g. a re-plan),
        per finger: the squeeze's joint offset and the torque feed-forward (the plan's
        torques or J^T of its contact force when it has them and ``use_plan_forces``; else
        J^T of the grip force along the pad's normal); and notes on which was used."""
        plan, o, m = plan or self.plan, self.options, self.model
        d = mujoco.MjData(m)
        n = plan.t.size
        offsets = [np.zeros((n, f.nq)) for f in plan.fingers]
        torques = [np.zeros((n, f.nq)) for f in plan.fingers]
        notes: list[str] = []
        point_of = {c.finger: c.point for c in plan.contacts if c.finger is not None}
        # a lifted fingertip (finger gaiting) gets no squeeze and no grip
        active_of = {c.finger: c.active for c in plan.contacts
                     if c.finger is not None and c.active is not None}
        jacp = np.zeros((3, m.nv))
        for i in range(n):
            for idx, ref in zip(self.fingers, plan.references, strict=True):
                d.qpos[idx.qpos] = ref.q[i]
            mujoco.mj_kinematics(m, d)
            mujoco.mj_comPos(m, d)
            for k, (f, idx, ref) in enumerate(zip(plan.fingers, self.fingers,
                                                  plan.references, strict=True)):
                normal = d.site_xmat[idx.tip_site].reshape(3, 3)[:, 2].copy()
                point = point_of.get(f.name)
                p = d.site_xpos[idx.tip_site].copy() if point is None else point[i]
                mujoco.mj_jac(m, d, jacp, None, p, idx.tip_body)
                J = jacp[:, idx.dofs]
                share = float(active_of[f.name][i]) if f.name in active_of else 1.0
                share = min(max((share - SQUEEZE_FROM) / (1.0 - SQUEEZE_FROM), 0.0), 1.0)
                offsets[k][i] = _damped_pinv(J) @ (share * o.squeeze_for(plan) * normal)
                if o.use_plan_forces and ref.joint_torques is not None:
                    torques[k][i] = ref.joint_torques[i]
                elif o.use_plan_forces and ref.contact_force is not None:
                    torques[k][i] = J.T @ ref.contact_force[i]
                else:
                    torques[k][i] = J.T @ (share * o.grip_force * normal)
        for f, ref in zip(plan.fingers, plan.references, strict=True):
            if o.use_plan_forces and ref.joint_torques is not None:
                notes.append(f"{f.name}: the plan's joint torques as feed-forward")
            elif o.use_plan_forces and ref.contact_force is not None:
                notes.append(f"{f.name}: J^T of the plan's contact force as feed-forward")
            else:
                notes.append(f"{f.name}: grip {o.grip_force:g} N along the pad's normal "
                             f"(J^T f) and a squeeze of {o.squeeze_for(plan) * 1e3:g} mm")
        return offsets, torques, notes

    def _planned_normal_forces(self, ts: FloatArray) -> dict[int, FloatArray]:
        """Per contact with a planned force (a fingertip whose reference has
        ``contact_force``), its planned normal force [N] at the times ``ts``: the push
        into the object, -f . n (n the object's outward normal there; |f| when the plan
        does not say n)."""
        out: dict[int, FloatArray] = {}
        ref_of = {f.name: r for f, r in zip(self.plan.fingers, self.plan.references,
                                            strict=True)}
        for j, c in enumerate(self.plan.contacts):
            ref = ref_of.get(c.finger) if c.finger is not None else None
            if ref is None or ref.contact_force is None:
                continue
            F = ref.contact_force
            fn = -np.sum(F * c.normal, axis=1) if c.normal is not None else \
                np.linalg.norm(F, axis=1)
            out[j] = _linear(self.plan.t, fn[:, None], ts)[:, 0]
        return out

    def _force_loops(self, ts: FloatArray, ramp: FloatArray,
                     planned: dict[int, FloatArray]) -> list[_ForceLoop]:
        """The contact-force feedback (``force_control`` 'pi'): per fingertip whose
        contact has a planned normal force, at the steps ``ts``, the joint torques of a
        unit push along the planned contact normal (J^T n at the plan's joints and
        point), its weight (none where the fingertip is lifted, all from activity
        :data:`SQUEEZE_FROM` on, times the grip's ``ramp``) and the target normal force:
        the planned one, at least ``force_min`` where the contact counts as touching
        (activity :data:`ACTIVE_SHARE` and up; from none at :data:`SQUEEZE_FROM`)."""
        plan, m = self.plan, self.model
        if not self.options.feedback or self.options.mode != "servo":
            return []
        d = mujoco.MjData(m)
        jacp = np.zeros((3, m.nv))
        loops = []
        for j, c in enumerate(plan.contacts):
            if j not in planned or c.finger is None or c.normal is None:
                continue
            k = next((k for k, f in enumerate(plan.fingers) if f.name == c.finger), None)
            if k is None:
                continue
            idx, ref = self.fingers[k], plan.references[k]
            unit = np.zeros((plan.t.size, len(idx.dofs)))
            for i in range(plan.t.size):
                d.qpos[idx.qpos] = ref.q[i]
                mujoco.mj_kinematics(m, d)
                mujoco.mj_comPos(m, d)
                mujoco.mj_jac(m, d, jacp, None, c.point[i], idx.tip_body)
                # the push into the object: against its outward normal
                unit[i] = jacp[:, idx.dofs].T @ (-c.normal[i])
            share = np.ones(ts.size) if c.active is None else \
                _linear(plan.t, c.active[:, None], ts)[:, 0]
            weight = np.clip(share / SQUEEZE_FROM, 0.0, 1.0) * ramp
            floor = self.options.force_min * np.clip(
                (share - SQUEEZE_FROM) / (ACTIVE_SHARE - SQUEEZE_FROM), 0.0, 1.0)
            target = np.maximum(planned[j], floor)
            limit, ki = admittance_range(self.options, c.point, c.normal,
                                         plan.object_position, c.active)
            loops.append(_ForceLoop(k, j, np.ascontiguousarray(_linear(plan.t, unit, ts)),
                                    weight, target, target - planned[j], limit, ki))
        return loops

    # -- the run --------------------------------------------------------------------------
    def run(self, hook: Callable[[int, float, StepRows], None] | None = None
            ) -> SimReport:
        """Run the plan. ``hook(k, t, rows)``, when given, is called before every step
        ``k`` (``t`` its start on the plan's clock) with the controller's rows from that
        step on, which it may change (a re-plan, sim/closed_loop.py), and may change
        ``data`` (a push, sim/disturbances.py)."""
        plan, o, m, d = self.plan, self.options, self.model, self.data
        start = time.perf_counter()
        dt, T = o.timestep, plan.duration
        ts, plan_time, ramp, pin_object = step_grid(plan, o)
        offsets, torques, notes = self._feedforward()
        q_ref, qd_ref, ctrl, tau, grip = [], [], [], [], []
        for ref, off, trq in zip(plan.references, offsets, torques, strict=True):
            q, qd = hermite(plan.t, ref.q, ref.q_dot, ts)
            qd[plan_time < 0] = 0.0
            grip.append(ramp[:, None] * _linear(plan.t, off, ts))
            target = q + grip[-1]
            q_ref.append(target)
            qd_ref.append(qd)
            ctrl.append(target + (o.kv / o.kp) * qd)
            tau.append(ramp[:, None] * _linear(plan.t, trq, ts))
        planned_force = self._planned_normal_forces(ts)
        loops = self._force_loops(ts, ramp, planned_force)
        shifting = o.force_control == "admittance"
        if o.feedback:
            name = "admittance" if shifting else "PI"
            names = ", ".join(plan.contacts[lp.j].name for lp in loops)
            notes.append(
                (f"force control: admittance (the servo's set point shifted along the "
                 f"planned normal by {o.force_shift_ki:g} m/(N s) times the integral of "
                 f"the normal force's error, at most {o.force_shift_limit * 1e3:g} mm; "
                 f"at least {o.force_min:g} N while touching) for {names}"
                 + "".join(f"; {plan.contacts[lp.j].name} at most "
                           f"{lp.shift_limit * 1e3:.3g} mm at {lp.shift_ki:.3g} m/(N s) (the "
                           "object's surface moves under it when the object turns)"
                           for lp in loops if lp.shift_limit != o.force_shift_limit)
                 if shifting
                 else f"force control: PI contact-force feedback (gains {o.force_kp:g} "
                      f"N/N, {o.force_ki:g} 1/s, at most {o.force_limit:g} N; at least "
                      f"{o.force_min:g} N while touching) along the planned normals of "
                      f"{names}, on top of the servo") if loops else
                f"force control: {name} asked, but off ({o.mode} mode)" if o.mode != "servo"
                else f"force control: {name} asked, but no contact has a planned force: off")
        else:
            notes.append("force control: off (the servo with the planned forces fed "
                         "forward)")
        tau_fb = [np.zeros(len(idx.dofs)) for idx in self.fingers]
        shift = [np.zeros(len(idx.dofs)) for idx in self.fingers]  # admittance [rad]
        pos_ref = _linear(plan.t, plan.object_position, ts)
        quat_ref = slerp(plan.t, plan.object_wxyz, ts)
        vel_ref = np.gradient(pos_ref, dt, axis=0) if ts.size > 1 else np.zeros_like(pos_ref)

        mujoco.mj_resetData(m, d)
        for idx, q in zip(self.fingers, q_ref, strict=True):
            d.qpos[idx.qpos] = q[0]
        oq, od = self.object_qpos, self.object_dof
        d.qpos[oq:oq + 3] = pos_ref[0]
        d.qpos[oq + 3:oq + 7] = quat_ref[0]
        mujoco.mj_forward(m, d)

        n_steps = ts.size - 1
        nc = len(plan.contacts)
        obj_pose = np.zeros((n_steps, 7))
        normal_force = np.zeros((n_steps, nc))
        slip_speed = np.zeros((n_steps, nc))
        jac_a, jac_b = np.zeros((3, m.nv)), np.zeros((3, m.nv))
        f6 = np.zeros(6)
        separation = np.zeros((n_steps, nc))
        pair_geoms = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM,
                                        "palm" if c.body == "palm" else f"{c.finger}/pad")
                      for c in plan.contacts]
        ctrl_rows = [np.ascontiguousarray(c) for c in ctrl]
        replay = o.mode == "replay"
        kinematic = o.mode in ("kinematic", "replay")
        rows = StepRows(ts, ctrl_rows, tau, q_ref, qd_ref, grip)
        for k in range(n_steps):
            if hook is not None:
                hook(k, float(plan_time[k]), rows)
            for lp in loops:
                w = lp.weight[k]
                if w <= 0.0:
                    lp.integral = lp.shift = 0.0
                    tau_fb[lp.k][:] = 0.0
                    shift[lp.k][:] = 0.0
                    continue
                # the measured normal force: the previous step's
                error = lp.target[k] - (normal_force[k - 1, lp.j] if k > 0 else 0.0)
                if shifting:
                    lp.shift = min(max(lp.shift + lp.shift_ki * error * dt, 0.0),
                                   lp.shift_limit)
                    unit = lp.unit[k]
                    np.multiply(unit, w * lp.shift / max(float(unit @ unit), 1e-12),
                                out=shift[lp.k])
                    np.multiply(unit, w * lp.extra[k], out=tau_fb[lp.k])
                    continue
                integral = lp.integral + o.force_ki * error * dt
                if abs(o.force_kp * error + integral) <= o.force_limit:
                    lp.integral = integral  # held while clipped: anti-windup
                u = min(max(o.force_kp * error + lp.integral, -o.force_limit),
                        o.force_limit) + lp.extra[k]
                np.multiply(lp.unit[k], w * u, out=tau_fb[lp.k])
            for idx, c, trq, q, qd, fb, sh in zip(self.fingers, ctrl_rows, tau, q_ref,
                                                  qd_ref, tau_fb, shift, strict=True):
                d.ctrl[idx.actuators] = c[k] + sh
                d.qfrc_applied[idx.dofs] = trq[k] + fb
                if kinematic:
                    d.qpos[idx.qpos] = q[k]
                    d.qvel[idx.dofs] = qd[k]
            if pin_object[k] or replay:
                d.qpos[oq:oq + 3] = pos_ref[k]
                d.qpos[oq + 3:oq + 7] = quat_ref[k]
                d.qvel[od:od + 6] = 0.0
                if replay:
                    d.qvel[od:od + 3] = vel_ref[k]
            if replay:
                mujoco.mj_forward(m, d)
                for idx, q in zip(self.fingers, q_ref, strict=True):
                    d.qpos[idx.qpos] = q[k + 1]
                d.qpos[oq:oq + 3] = pos_ref[k + 1]
                d.qpos[oq + 3:oq + 7] = quat_ref[k + 1]
            else:
                mujoco.mj_step(m, d)
            obj_pose[k] = d.qpos[oq:oq + 7]
            # the contacts of the step (found at its start; velocities at its end, the
            # ones the step moved the bodies with)
            for con, other, fn in object_contacts(m, d, self.object_geom, f6):
                j = self.contact_of_geom.get(other)
                if j is None:
                    continue
                normal_force[k, j] += fn
                slip_speed[k, j] = max(slip_speed[k, j],
                                       contact_slip(m, d, con, self.object_body, other,
                                                    jac_a, jac_b))
            for j, g in enumerate(pair_geoms):  # how far apart where none touches
                if normal_force[k, j] <= TOUCH_FORCE and g >= 0:
                    separation[k, j] = mujoco.mj_geomDistance(m, d, g, self.object_geom,
                                                              SEPARATION_MAX, None)
        wall = time.perf_counter() - start
        # errors at the end of every step, against the plan at that time
        t_end = plan_time[1:]
        pos_err = np.linalg.norm(obj_pose[:, :3] - pos_ref[1:], axis=1)
        ang_err = _angle_between(obj_pose[:, 3:], quat_ref[1:])
        during = t_end >= 0
        contacts = [contact_report(spec, plan.t, normal_force[:, j], slip_speed[:, j],
                                   t_end, dt, planned_force.get(j), separation[:, j])
                    for j, spec in enumerate(plan.contacts)]
        rec = recorded_steps(t_end, o)
        report = SimReport.assess(
            mode=o.mode, options=o, contacts=contacts,
            position=ErrorSummary.of(pos_err[during], t_end[during]),
            angle=ErrorSummary.of(ang_err[during], t_end[during]),
            series_t=t_end[rec], series_position=pos_err[rec], series_angle=ang_err[rec],
            series_force=normal_force[rec].T, wall_time=wall, steps=n_steps,
            duration=T, notes=[*plan.notes, *notes],
            mujoco_version=mujoco.__version__)
        return report


def step_grid(plan: ExecutionPlan, o: SimOptions
              ) -> tuple[FloatArray, FloatArray, FloatArray, np.ndarray]:
    """The simulation's steps: each one's start ``ts`` [s] on the plan's clock, from the
    settling's start to the plan's end; the same from the plan's start (negative while
    settling); the grip's ramp (0 to 1 over the settling's first half); and where the
    object is held in place (that first half)."""
    dt = o.timestep
    t0 = float(plan.t[0])
    n_settle = round(o.settle / dt)
    n_plan = math.ceil(plan.duration / dt - 1e-9)
    ts: FloatArray = t0 + dt * np.arange(-n_settle, n_plan + 1, dtype=float)
    plan_time = ts - t0
    ramp = np.clip((plan_time + o.settle) / max(o.settle / 2, dt), 0.0, 1.0) \
        if o.settle > 0 else np.ones_like(ts)
    return ts, plan_time, ramp, plan_time < -o.settle / 2


def object_contacts(m: Any, d: Any, object_geom: int, f6: FloatArray
                    ) -> Iterator[tuple[Any, int, float]]:
    """The step's contacts of the object that push (normal force above
    :data:`TOUCH_FORCE`): (MuJoCo's contact, the other geom, the normal force [N]);
    ``f6`` a scratch array of 6."""
    for i in range(d.ncon):
        con = d.contact[i]
        g1, g2 = int(con.geom1), int(con.geom2)
        if object_geom not in (g1, g2):
            continue
        mujoco.mj_contactForce(m, d, i, f6)
        if f6[0] > TOUCH_FORCE:
            yield con, g2 if g1 == object_geom else g1, float(f6[0])


def contact_slip(m: Any, d: Any, con: Any, object_body: int, other: int,
                 jac_a: FloatArray, jac_b: FloatArray) -> float:
    """The tangential speed [m/s] of the object's material point relative to the touching
    body's at MuJoCo contact ``con`` (``other``: the touching geom; ``jac_a``, ``jac_b``:
    3 x nv work arrays)."""
    p = con.pos
    mujoco.mj_jac(m, d, jac_a, None, p, object_body)
    v = jac_a @ d.qvel
    body = int(m.geom_bodyid[other])
    if body > 0:
        mujoco.mj_jac(m, d, jac_b, None, p, body)
        v = v - jac_b @ d.qvel
    nrm = con.frame[:3]
    return float(np.linalg.norm(v - float(nrm @ v) * nrm))


def contact_report(spec: Any, plan_t: FloatArray, normal_force: FloatArray,
                   slip_speed: FloatArray, t_end: FloatArray, dt: float,
                   planned: FloatArray | None = None,
                   separation: FloatArray | None = None) -> ContactReport:
    """One planned contact's report from its normal force and slip speed at the end of
    every step (``t_end`` [s] from the plan's start; negative: settling), ``planned``: its
    planned normal force at the steps' starts and the last end (None: not stated). A
    contact is lost where it has no force and the plan has it touching (``spec.active``
    at least :data:`ACTIVE_SHARE`: finger gaiting's lifted tips and force ramps excepted);
    a touch where the plan has its fingertip lifted clear is an unplanned touch.
    ``separation`` [m]: the distance between the touching bodies at each step where they
    do not touch (up to :data:`SEPARATION_MAX`; None: not measured), whose largest over
    the losses the report gives."""
    during = t_end >= 0
    # the steps inside the plan's horizon (the one ending at t = 0 is the settling's)
    inside = t_end > 0.5 * dt
    n_steps = t_end.size
    touching = normal_force > TOUCH_FORCE
    # planned touching (finger gaiting: not while its fingertip is lifted, nor in the ends
    # of the force ramps around it, where the force goes to zero)
    share = None if spec.active is None else _linear(plan_t, spec.active[:, None], t_end)[:, 0]
    on = np.ones(n_steps, dtype=bool) if share is None else share >= ACTIVE_SHARE
    lifted = np.zeros(n_steps, dtype=bool) if share is None else share <= 0.0
    lost_all = ~touching & on
    lost = lost_all[during]
    events = int(np.sum(lost[1:] & ~lost[:-1]) + (1 if lost.size and lost[0] else 0))
    first = float(t_end[during][np.argmax(lost)]) if lost.any() else None
    f = normal_force[during]
    if planned is not None:
        planned = planned[1:][during]
    return ContactReport(
        spec.name, spec.body, lost_time=float(np.sum(lost_all[inside]) * dt),
        loss_events=events, first_loss_at=first,
        slip_distance=float(np.sum(slip_speed[during]) * dt),
        max_slip_speed=float(np.max(slip_speed[during], initial=0.0)),
        normal_force_min=float(np.min(f, initial=math.inf)),
        normal_force_mean=float(np.mean(f)) if f.size else 0.0,
        normal_force_max=float(np.max(f, initial=0.0)),
        planned_normal_force_mean=None if planned is None or not planned.size
        else float(np.mean(planned)),
        normal_force_error_max=None if planned is None or not planned.size
        else float(np.max(np.abs(f[on[during]] - planned[on[during]]), initial=0.0)),
        unplanned_touch_time=float(np.sum((touching & lifted)[inside]) * dt),
        lost_separation_max=None if separation is None or not lost_all[inside].any()
        else float(np.max(separation[inside][lost_all[inside]])))


def recorded_steps(t_end: FloatArray, o: SimOptions) -> np.ndarray:
    """The steps of the report's series: every ``record_every``-th, thinned to at most
    :data:`MAX_SERIES` rows, the last one, none before the settling."""
    n_steps = t_end.size
    every = max(o.record_every, math.ceil(n_steps / MAX_SERIES))
    rec = np.arange(0, n_steps, every)
    if rec[-1] != n_steps - 1:
        rec = np.append(rec, n_steps - 1)
    return rec[t_end[rec] >= -o.settle]


def simulate(plan: ExecutionPlan, options: SimOptions | None = None) -> SimReport:
    """Execute ``plan`` in MuJoCo with ``options`` (default :class:`SimOptions`)."""
    return Simulation(plan, options).run()
