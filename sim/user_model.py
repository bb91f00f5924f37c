"""Executing a plan on the user's own MJCF hand: its bodies, masses, joints (limits,
damping, armature), actuators and contact settings, as MuJoCo reads the file
(docs/simulation.md, "On your own model").

The scene is the user's MJCF with three changes, each reported (:mod:`sim.user_scene`).
MuJoCo mixes a contact pair's settings (the larger ``condim`` and friction, ``solref``
and ``solimp`` weighted by ``solmix``; a higher ``priority`` wins: :mod:`sim.soft_contact`):
the report lists, per fingertip geom, the file's settings, the pair's, and which differ.

The controller drives the model's own actuators (joint transmissions), per joint:

* an affine actuator (MuJoCo's ``position``, ``velocity``, ``general`` with affine bias:
  force ``gain ctrl + b0 + b1 L + b2 L_dot``, ``L = gear q``) gets the control that
  makes its force, at the reference, the feed-forward torque: ``ctrl = (tau_ff +
  Kp q_ref + Kv q_dot_ref - gear b0) / (gear gain)`` with ``Kp = -gear^2 b1``, ``Kv =
  -gear^2 b2`` (a position servo: the reference offset ``tau_ff / kp``);
* a motor (no bias): PD plus feed-forward in the loop, ``(tau_ff + kp (q_ref - q) + kv
  (q_dot_ref - q_dot)) / (gear gain)``, ``kp``, ``kv`` the simulator's options;
* no actuator (or another kind): the joint is left passive (reported).

``tau_ff`` = the plan's joint torques (its contact forces through ``J^T`` and its links'
weight; a plan without forces: the simulator's grip force pushing each fingertip into the
object along the planned normal), plus what the model itself needs to follow the
reference: Coriolis (and gravity, where the plan's torques do not hold the links' weight)
less its passive forces (joint damping, springs, gravity compensation) at ``(q_ref,
q_dot_ref)``, by MuJoCo (``qfrc_bias - qfrc_passive``; the links' inertia ``M q_ddot`` is
left out). A plan that states its forces is driven by them alone: no squeeze unless
asked (a plan without forces: the simulator's default squeeze). Control ranges and force
ranges are the file's: the report
gives each joint's largest feed-forward torque against its actuator's force range, the
steps at the range's end, and the control clipped (a position servo whose reference
offset would leave its control range). The grip ramps up while the object is held at its
initial pose (the first half of ``settle``), then it is let go.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from typing import Any

import mujoco
import numpy as np

from .options import SimOptions
from .report import ErrorSummary, SimReport
from .run import (
    _angle_between,
    _damped_pinv,
    _linear,
    contact_report,
    contact_slip,
    hermite,
    object_contacts,
    recorded_steps,
    slerp,
    step_grid,
)
from .soft_contact import contact_depth, creep_speed, geom_settings, pair_settings
from .spec import ExecutionPlan, FloatArray
from .user_scene import OBJECT, UserModel, compiled, massless_links, user_scene, with_inertials

__all__ = ["OBJECT", "UserModel", "UserModelSimulation", "contact_depth", "simulate_on_model",
           "user_scene"]

def _through_tendons(m: Any, joints: list[Any], tau: FloatArray) -> FloatArray:
    """A finger's feed-forward torques with each joint no actuator drives given its torque
    through a limited fixed tendon over it and the finger's other joints (the Shadow
    hand's J0): the tendon's limit force ``lam = tau_p / c_p`` comes off every joint of
    the tendon (``tau -= c lam``), as ``ocp.robots.actuation`` plans it."""
    out = np.array(tau, dtype=float)
    index = {j.qpos: k for k, j in enumerate(joints)}
    for t in range(m.ntendon):
        adr, num = int(m.tendon_adr[t]), int(m.tendon_num[t])
        if num < 2 or not m.tendon_limited[t]:
            continue
        terms = [(int(m.jnt_qposadr[int(m.wrap_objid[w])]), float(m.wrap_prm[w]))
                 for w in range(adr, adr + num)
                 if int(m.wrap_type[w]) == int(mujoco.mjtWrap.mjWRAP_JOINT)]
        if len(terms) < num or any(a not in index for a, _ in terms):
            continue
        passive = [(index[a], c) for a, c in terms if joints[index[a]].kind == "passive"]
        if len(passive) != 1:
            continue
        lam = out[passive[0][0]] / passive[0][1]
        for a, c in terms:
            out[index[a]] -= c * lam
    return out


@dataclass
class _Joint:
    name: str
    qpos: int
    dof: int
    actuator: int  # -1: none usable
    kind: str      # "affine", "motor", "passive"
    gain: float = 0.0
    b0: float = 0.0
    Kp: float = 0.0
    Kv: float = 0.0
    gear: float = 1.0
    note: str = ""


def _joint_drive(m: Any, jid: int, name: str) -> _Joint:
    """How joint ``jid`` is driven by the model's actuators (the first on it)."""
    qpos, dof = int(m.jnt_qposadr[jid]), int(m.jnt_dofadr[jid])
    ids = [a for a in range(m.nu) if int(m.actuator_trntype[a]) == int(mujoco.mjtTrn.mjTRN_JOINT)
           and int(m.actuator_trnid[a, 0]) == jid]
    if not ids:
        return _Joint(name, qpos, dof, -1, "passive", note="no actuator: left passive")
    a = ids[0]
    more = f" ({len(ids) - 1} more on it unused)" if len(ids) > 1 else ""
    gear = float(m.actuator_gear[a, 0])
    gaintype, biastype = int(m.actuator_gaintype[a]), int(m.actuator_biastype[a])
    gain = float(m.actuator_gainprm[a, 0])
    if gaintype != int(mujoco.mjtGain.mjGAIN_FIXED) or gain == 0.0 or gear == 0.0 \
            or int(m.actuator_dyntype[a]) != int(mujoco.mjtDyn.mjDYN_NONE):
        return _Joint(name, qpos, dof, -1, "passive",
                      note=f"actuator {mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_ACTUATOR, a)!r}"
                           " has activation dynamics or a non-fixed gain: not driven, the "
                           "joint left passive")
    b = m.actuator_biasprm[a]
    if biastype == int(mujoco.mjtBias.mjBIAS_NONE) or (b[1] == 0.0 and b[2] == 0.0):
        return _Joint(name, qpos, dof, a, "motor", gain, float(b[0]) if biastype else 0.0,
                      gear=gear, note="motor: PD + feed-forward in the loop" + more)
    if biastype != int(mujoco.mjtBias.mjBIAS_AFFINE):
        return _Joint(name, qpos, dof, -1, "passive", note="actuator bias not affine: "
                                                           "joint left passive")
    return _Joint(name, qpos, dof, a, "affine", gain, float(b[0]),
                  Kp=-gear * gear * float(b[1]) + 0.0, Kv=-gear * gear * float(b[2]) + 0.0,
                  gear=gear,
                  note="affine servo: the reference offset that gives the feed-forward "
                       "torque at its gain" + more)


def _differs(a: Any, b: Any) -> bool:
    return not np.allclose(np.asarray(a, dtype=float), np.asarray(b, dtype=float),
                           rtol=1e-6, atol=1e-9)


class UserModelSimulation:
    """A plan on the user's model in MuJoCo (module docstring), ready to :meth:`run`;
    ``xml`` the scene, ``model`` and ``data`` MuJoCo's, ``settings`` what the report
    states of the scene and the drive."""

    def __init__(self, plan: ExecutionPlan, model: UserModel,
                 options: SimOptions | None = None) -> None:
        plan.check()
        options = options or SimOptions()
        #: the fingertips pressed in by the depth the file's own contacts need to carry
        #: the planned forces (:func:`contact_depth`), instead of a squeeze of ours
        self.compliance = options.squeeze is None and all(
            r.contact_force is not None for r in plan.references)
        if self.compliance:
            options = replace(options, squeeze=0.0)
        self.plan, self.user, self.options = plan, model, options.resolved(plan)
        self.options.check()
        if self.options.mode != "servo":
            raise ValueError("on the user's model the joints are driven by its actuators: "
                             "mode must be 'servo'")
        if len(model.tips) != len(plan.fingers):
            raise ValueError(f"{len(model.tips)} tips named for {len(plan.fingers)} fingers")
        self.xml, changes = user_scene(plan, model, self.options)
        self.model = compiled(self.xml)
        light = massless_links(self.model)
        if light:
            mass = self.options.model_link_mass
            if mass is None:
                raise ValueError(
                    f"the model's moving bodies {', '.join(light)} have no mass once their "
                    "mesh geoms are removed (their mass came from the meshes' volume: the "
                    "scene never reads mesh files); give each an <inertial> in the file, or "
                    "a mass with the simulation option model_link_mass [kg]")
            self.xml = with_inertials(self.xml, self.model, light, mass)
            self.model = compiled(self.xml)
            changes["links_given_mass"] = {"bodies": light, "mass": mass}
        self.data = mujoco.MjData(self.model)
        m = self.model
        ident = mujoco.mjtObj
        self.object_body = mujoco.mj_name2id(m, ident.mjOBJ_BODY, OBJECT)
        self.object_geom = mujoco.mj_name2id(m, ident.mjOBJ_GEOM, OBJECT)
        jo = mujoco.mj_name2id(m, ident.mjOBJ_JOINT, OBJECT)
        self.object_qpos, self.object_dof = int(m.jnt_qposadr[jo]), int(m.jnt_dofadr[jo])
        self.joints: list[list[_Joint]] = []
        self.tip_bodies: list[int] = []
        self.contact_of_geom: dict[int, int] = {}
        contact_of_finger = {c.finger: k for k, c in enumerate(plan.contacts)
                             if c.finger is not None}
        for f, tip in zip(plan.fingers, model.tips, strict=True):
            joints = []
            for j in f.joints:
                jid = mujoco.mj_name2id(m, ident.mjOBJ_JOINT, j.name)
                if jid < 0:
                    raise ValueError(f"finger {f.name}: the model has no joint {j.name!r}")
                joints.append(_joint_drive(m, jid, j.name))
            self.joints.append(joints)
            body = mujoco.mj_name2id(m, ident.mjOBJ_BODY, tip)
            if body < 0:
                site = mujoco.mj_name2id(m, ident.mjOBJ_SITE, tip)
                if site < 0:
                    raise ValueError(f"finger {f.name}: the model has no body or site "
                                     f"{tip!r}")
                body = int(m.site_bodyid[site])
            self.tip_bodies.append(body)
            k = contact_of_finger.get(f.name)
            for g in range(m.ngeom):
                touches = bool(m.geom_contype[g] or m.geom_conaffinity[g])
                if int(m.geom_bodyid[g]) == body and touches and k is not None:
                    self.contact_of_geom[g] = k
        self.settings = self._settings(changes)

    def _settings(self, changes: dict[str, Any]) -> dict[str, Any]:
        m, o = self.model, self.options
        tips = []
        for g, k in sorted(self.contact_of_geom.items()):
            file_s = geom_settings(m, g)
            pair = pair_settings(m, g, self.object_geom)
            body = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, int(m.geom_bodyid[g]))
            tips.append({"geom": mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_GEOM, g)
                         or f"{body}'s geom {g}", "geom_id": g,
                         "contact": self.plan.contacts[k].name,
                         "file": file_s, "with_object": pair,
                         "differs": [key for key in file_s if _differs(file_s[key],
                                                                        pair[key])]})
        drive = []
        for f, joints in zip(self.plan.fingers, self.joints, strict=True):
            for j in joints:
                entry: dict[str, Any] = {"finger": f.name, "joint": j.name, "kind": j.kind,
                                         "note": j.note}
                if j.actuator >= 0:
                    a = j.actuator
                    entry.update({
                        "actuator": mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_ACTUATOR, a),
                        "gear": j.gear, "gain": j.gain, "kp": j.Kp if j.kind == "affine"
                        else o.kp, "kv": j.Kv if j.kind == "affine" else o.kv,
                        "ctrlrange": [float(x) for x in m.actuator_ctrlrange[a]]
                        if m.actuator_ctrllimited[a] else None,
                        "forcerange": [float(x) for x in m.actuator_forcerange[a]]
                        if m.actuator_forcelimited[a] else None})
                entry.update({"damping": float(m.dof_damping[j.dof]),
                              "armature": float(m.dof_armature[j.dof]),
                              "range": [float(x) for x in m.jnt_range[
                                  mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, j.name)]]})
                drive.append(entry)
        hand_mass = float(sum(m.body_mass[b] for b in range(1, m.nbody)
                              if b != self.object_body))
        integrators = {int(v): k for k, v in mujoco.mjtIntegrator.__members__.items()}
        cones = {int(v): k for k, v in mujoco.mjtCone.__members__.items()}
        return {
            "source": "the user's MJCF (meshes stripped)", **changes,
            "timestep": float(m.opt.timestep), "gravity": [float(x) for x in m.opt.gravity],
            "integrator": integrators.get(int(m.opt.integrator), str(m.opt.integrator)),
            "cone": cones.get(int(m.opt.cone), str(m.opt.cone)),
            "impratio": float(m.opt.impratio),
            "noslip_iterations": int(m.opt.noslip_iterations),
            "solver_iterations": int(m.opt.iterations),
            "hand_mass": hand_mass,
            "object": {"mass": float(m.body_mass[self.object_body]),
                       **geom_settings(m, self.object_geom),
                       "solmix": float(m.geom_solmix[self.object_geom])},
            "fingertip_contacts": tips, "drive": drive,
            "couplings": self._couplings()}

    def _couplings(self) -> list[str]:
        """The file's constraints between the joints the plan moves (limited tendons over
        two or more of them, joint equalities), in words, each with how far the plan's
        joints leave it at worst (the plan keeps those of the hand it was planned on; a
        different file's may be broken, and the execution has them)."""
        m = self.model
        d = mujoco.MjData(m)
        plan = self.plan
        joint = {j.name: j for joints in self.joints for j in joints}
        planned = {mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, n) for n in joint}
        lengths, values = [], []
        for i in range(plan.t.size):  # the tendons and joints along the plan
            d.qpos[:] = m.qpos0
            for joints, ref in zip(self.joints, plan.references, strict=True):
                for k, j in enumerate(joints):
                    d.qpos[j.qpos] = ref.q[i, k]
            mujoco.mj_kinematics(m, d)
            mujoco.mj_tendon(m, d)
            lengths.append(d.ten_length.copy())
            values.append(d.qpos.copy())
        L, Q = np.array(lengths), np.array(values)
        out = []
        for t in range(m.ntendon):
            adr, num = int(m.tendon_adr[t]), int(m.tendon_num[t])
            wrapped = [int(m.wrap_objid[adr + i]) for i in range(num)
                       if int(m.wrap_type[adr + i]) == int(mujoco.mjtWrap.mjWRAP_JOINT)]
            if num > 1 and m.tendon_limited[t] and planned & set(wrapped):
                names = ", ".join(mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j)
                                  for j in wrapped)
                lo, hi = (float(x) for x in m.tendon_range[t])
                over = float(np.max(np.maximum(L[:, t] - hi, lo - L[:, t]), initial=0.0))
                out.append(f"tendon {mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_TENDON, t)!r}"
                           f" ({names}) limited to {lo:g}..{hi:g}: "
                           + ("the plan keeps it" if over <= 1e-6 else
                              f"the plan leaves it by {over:.3g} at worst"))
        for e in range(m.neq):
            if int(m.eq_type[e]) == int(mujoco.mjtEq.mjEQ_JOINT) and \
                    planned & {int(m.eq_obj1id[e]), int(m.eq_obj2id[e])}:
                i1, i2 = int(m.eq_obj1id[e]), int(m.eq_obj2id[e])
                a = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, i1)
                q1 = Q[:, int(m.jnt_qposadr[i1])] - m.qpos0[int(m.jnt_qposadr[i1])]
                poly = np.asarray(m.eq_data[e, :5], dtype=float)
                if i2 >= 0:
                    b = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, i2)
                    q2 = Q[:, int(m.jnt_qposadr[i2])] - m.qpos0[int(m.jnt_qposadr[i2])]
                else:
                    b, q2 = "a constant", np.zeros_like(q1)
                err = float(np.max(np.abs(q1 - sum(c * q2 ** k for k, c in enumerate(poly)))))
                out.append(f"joint equality {a} = f({b}): " +
                           ("the plan keeps it" if err <= 1e-6 else
                            f"the plan leaves it by {err:.3g} at worst"))
        return out

    # -- the reference --------------------------------------------------------------------
    def _feedforward(self) -> tuple[list[FloatArray], list[FloatArray], list[str]]:
        """At the plan's times, per finger: the squeeze's joint offset and the feed-forward
        torque (module docstring); notes on which the plan gave."""
        plan, o, m = self.plan, self.options, self.model
        d = mujoco.MjData(m)
        n = plan.t.size
        offsets = [np.zeros((n, f.nq)) for f in plan.fingers]
        torques = [np.zeros((n, f.nq)) for f in plan.fingers]
        contact_of = {c.finger: c for c in plan.contacts if c.finger is not None}
        jacp = np.zeros((3, m.nv))
        centre = np.asarray(plan.object_position, dtype=float)
        for i in range(n):
            d.qpos[:] = m.qpos0
            d.qvel[:] = 0.0
            for joints, ref in zip(self.joints, plan.references, strict=True):
                for k, j in enumerate(joints):
                    d.qpos[j.qpos] = ref.q[i, k]
                    d.qvel[j.dof] = ref.q_dot[i, k]
            oq = self.object_qpos
            if self.compliance:
                depths = self._depths(i, contact_of)
            d.qpos[oq:oq + 3] = centre[i] + 10.0  # away: no contact in this evaluation
            mujoco.mj_forward(m, d)
            model_needs = d.qfrc_bias - d.qfrc_passive
            d.qvel[:] = 0.0
            mujoco.mj_forward(m, d)
            weight = d.qfrc_bias.copy()  # the links' weight: in a plan's joint torques
            for f_i, (f, joints, ref, body) in enumerate(zip(
                    plan.fingers, self.joints, plan.references, self.tip_bodies,
                    strict=True)):
                dofs = [j.dof for j in joints]
                c = contact_of.get(f.name)
                point = c.point[i] if c is not None else d.xpos[body]
                if c is not None and c.normal is not None:
                    n_out = np.asarray(c.normal[i], dtype=float)
                else:
                    n_out = point - centre[i]
                    n_out = n_out / max(float(np.linalg.norm(n_out)), 1e-12)
                mujoco.mj_jac(m, d, jacp, None, point, body)
                J = jacp[:, dofs]
                depth = o.squeeze_for(plan)
                if self.compliance and c is not None and ref.contact_force is not None:
                    depth = depths[f_i]
                offsets[f_i][i] = _damped_pinv(J) @ (-depth * n_out)
                if o.use_plan_forces and ref.joint_torques is not None:
                    contact = ref.joint_torques[i] - weight[dofs]
                elif o.use_plan_forces and ref.contact_force is not None:
                    contact = J.T @ ref.contact_force[i]
                else:
                    contact = J.T @ (-o.grip_force * n_out)
                torques[f_i][i] = _through_tendons(
                    m, joints, contact + model_needs[dofs])
        notes = []
        for f, ref in zip(plan.fingers, plan.references, strict=True):
            if o.use_plan_forces and ref.joint_torques is not None:
                src = "the plan's joint torques"
            elif o.use_plan_forces and ref.contact_force is not None:
                src = "J^T of the plan's contact force"
            else:
                src = (f"a grip of {o.grip_force:g} N along the planned normal (J^T f; the "
                       "plan states no forces)")
            notes.append(f"{f.name}: feed-forward = {src} + the model's gravity, Coriolis "
                         f"and passive forces at the reference; squeeze "
                         f"{o.squeeze_for(plan) * 1e3:g} mm")
        notes.append("force control: off (the user's model is driven through its own "
                     "actuators; contact-force feedback runs on dexroll's scene only)"
                     if o.feedback else "force control: off")
        return offsets, torques, notes

    def _depths(self, i: int, contact_of: dict[str, Any]) -> list[float]:
        """Per finger, the depth [m] its contact sinks in the file's soft contact under the
        planned normal force at sample ``i`` (:func:`contact_depth`)."""
        plan, m = self.plan, self.model
        out = []
        for f, ref, body in zip(plan.fingers, plan.references, self.tip_bodies, strict=True):
            c = contact_of.get(f.name)
            geom = next((g for g, k in self.contact_of_geom.items()
                         if int(m.geom_bodyid[g]) == body), None)
            if c is None or ref.contact_force is None or geom is None or c.normal is None:
                out.append(0.0)
                continue
            n_out = np.asarray(c.normal[i], dtype=float)
            f_n = max(float(-np.asarray(ref.contact_force[i]) @ n_out), 0.0)
            pair = pair_settings(m, geom, self.object_geom)
            out.append(contact_depth(m, body, self.object_body, f_n, pair["solref"],
                                     pair["solimp"]))
        return out

    # -- the run --------------------------------------------------------------------------
    def run(self) -> SimReport:
        plan, o, m, d = self.plan, self.options, self.model, self.data
        start = time.perf_counter()
        dt, T = o.timestep, plan.duration
        ts, plan_time, ramp, pin_object = step_grid(plan, o)
        offsets, torques, notes = self._feedforward()
        q_ref, qd_ref, tau = [], [], []
        for ref, off, trq in zip(plan.references, offsets, torques, strict=True):
            q, qd = hermite(plan.t, ref.q, ref.q_dot, ts)
            qd[plan_time < 0] = 0.0
            q_ref.append(q + ramp[:, None] * _linear(plan.t, off, ts))
            qd_ref.append(qd)
            # the model's own needs at once, the grip's ramped
            tau.append(ramp[:, None] * _linear(plan.t, trq, ts))
        # the affine actuators' controls, precomputed; clipped to their ranges
        flat = [(j, q[:, k], qd[:, k], tq[:, k]) for joints, q, qd, tq in
                zip(self.joints, q_ref, qd_ref, tau, strict=True)
                for k, j in enumerate(joints)]
        ctrl_pre: dict[int, FloatArray] = {}
        clipped: dict[str, float] = {}
        demand: dict[str, float] = {}
        for j, q, qd, tq in flat:
            demand[j.name] = float(np.max(np.abs(tq[plan_time >= 0]), initial=0.0))
            if j.kind != "affine":
                continue
            u = (tq + j.Kp * q + j.Kv * qd - j.gear * j.b0) / (j.gear * j.gain)
            a = j.actuator
            if m.actuator_ctrllimited[a]:
                lo, hi = m.actuator_ctrlrange[a]
                cu = np.clip(u, lo, hi)
                taken = np.abs(u - cu) * abs(j.gear * j.gain)  # torque the clip takes away
                clipped[j.name] = float(np.max(taken[plan_time >= 0], initial=0.0))
                u = cu
            ctrl_pre[j.dof] = u
        pos_ref = _linear(plan.t, plan.object_position, ts)
        quat_ref = slerp(plan.t, plan.object_wxyz, ts)

        mujoco.mj_resetData(m, d)
        for joints, q in zip(self.joints, q_ref, strict=True):
            for k, j in enumerate(joints):
                d.qpos[j.qpos] = q[0, k]
        oq, od = self.object_qpos, self.object_dof
        d.qpos[oq:oq + 3] = pos_ref[0]
        d.qpos[oq + 3:oq + 7] = quat_ref[0]
        mujoco.mj_forward(m, d)
        planned_dofs = {j.dof for joints in self.joints for j in joints}
        # actuators of joints the plan does not move hold their initial angles
        for a in range(m.nu):
            if int(m.actuator_trntype[a]) == int(mujoco.mjtTrn.mjTRN_JOINT):
                jid = int(m.actuator_trnid[a, 0])
                if int(m.jnt_dofadr[jid]) not in planned_dofs and m.actuator_biastype[a]:
                    d.ctrl[a] = d.qpos[m.jnt_qposadr[jid]] * float(m.actuator_gear[a, 0])

        n_steps = ts.size - 1
        nc = len(plan.contacts)
        obj_pose = np.zeros((n_steps, 7))
        normal_force = np.zeros((n_steps, nc))
        slip_speed = np.zeros((n_steps, nc))
        other_force: dict[str, float] = {}
        saturated = {j.name: 0 for j, _, _, _ in flat}
        jac_a, jac_b = np.zeros((3, m.nv)), np.zeros((3, m.nv))
        f6 = np.zeros(6)
        motors = [(j, q, qd, tq) for j, q, qd, tq in flat if j.kind == "motor"]
        act_of = self._actuator_of
        limited = [(j, float(m.actuator_forcerange[j.actuator, 1]),
                    float(m.actuator_forcerange[j.actuator, 0])) for j, _, _, _ in flat
                   if j.actuator >= 0 and m.actuator_forcelimited[j.actuator]]
        creep: list[list[float]] = [[] for _ in range(nc)]
        creep_every = max(1, round(0.01 / dt))  # the friction's creep, sampled at 100 Hz
        for k in range(n_steps):
            for dof, u in ctrl_pre.items():
                d.ctrl[act_of[dof]] = u[k]
            for j, q, qd, tq in motors:
                u = (tq[k] + o.kp * (q[k] - d.qpos[j.qpos]) + o.kv * (qd[k] - d.qvel[j.dof])
                     - j.gear * j.b0) / (j.gear * j.gain)
                d.ctrl[j.actuator] = u
            if pin_object[k]:
                d.qpos[oq:oq + 3] = pos_ref[k]
                d.qpos[oq + 3:oq + 7] = quat_ref[k]
                d.qvel[od:od + 6] = 0.0
            mujoco.mj_step(m, d)
            if plan_time[k + 1] >= 0:
                for jl, hi, lo in limited:
                    force = float(d.actuator_force[jl.actuator])
                    if force >= hi - 1e-9 or force <= lo + 1e-9:
                        saturated[jl.name] += 1
            obj_pose[k] = d.qpos[oq:oq + 7]
            sample_creep = plan_time[k + 1] >= 0 and k % creep_every == 0
            for con, other, fn in object_contacts(m, d, self.object_geom, f6):
                j_c = self.contact_of_geom.get(other)
                if j_c is None:
                    if plan_time[k + 1] >= 0:
                        body = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY,
                                                 int(m.geom_bodyid[other])) or "world"
                        other_force[body] = max(other_force.get(body, 0.0), fn)
                    continue
                normal_force[k, j_c] += fn
                if sample_creep:
                    creep[j_c].append(creep_speed(m, d, con))
                slip_speed[k, j_c] = max(slip_speed[k, j_c],
                                         contact_slip(m, d, con, self.object_body, other,
                                                      jac_a, jac_b))
        wall = time.perf_counter() - start
        t_end = plan_time[1:]
        pos_err = np.linalg.norm(obj_pose[:, :3] - pos_ref[1:], axis=1)
        ang_err = _angle_between(obj_pose[:, 3:], quat_ref[1:])
        during = t_end >= 0
        contacts = [contact_report(spec, plan.t, normal_force[:, jc], slip_speed[:, jc],
                                   t_end, dt) for jc, spec in enumerate(plan.contacts)]
        rec = recorded_steps(t_end, o)
        steps_in_plan = max(int(np.sum(during)), 1)
        torque = []
        for j, _, _, _ in flat:
            entry: dict[str, Any] = {"joint": j.name, "kind": j.kind,
                                     "feedforward_max": demand[j.name]}
            if j.actuator >= 0 and m.actuator_forcelimited[j.actuator]:
                lo, hi = (float(x) * j.gear for x in m.actuator_forcerange[j.actuator])
                entry.update({"torque_range": [lo, hi],
                              "saturated_fraction": saturated[j.name] / steps_in_plan})
            if j.name in clipped:
                entry["torque_lost_to_ctrlrange_max"] = clipped[j.name]
            torque.append(entry)
        short = [e for e in torque if e.get("torque_range") is not None and
                 e["feedforward_max"] > max(abs(e["torque_range"][0]),
                                            abs(e["torque_range"][1]))]
        short_notes = [f"joint {e['joint']}: the plan needs up to {e['feedforward_max']:.3g} "
                       f"N m, its actuator gives {e['torque_range'][0]:.3g}.."
                       f"{e['torque_range'][1]:.3g} N m" for e in short]
        clip_notes = [f"joint {e['joint']}: its control range takes away up to "
                      f"{e['torque_lost_to_ctrlrange_max']:.3g} N m of the feed-forward"
                      for e in torque if e.get("torque_lost_to_ctrlrange_max", 0.0) > 1e-6]
        drive_notes = [f"{e['finger']}/{e['joint']}: {e['note']}" for e in
                       self.settings["drive"] if e["kind"] == "passive"]
        settings = dict(self.settings, torque=torque,
                        unplanned_contacts={b: f for b, f in sorted(other_force.items())})
        changed = sorted({key for t in settings["fingertip_contacts"] for key in t["differs"]})
        extra = [f"on the user's model: {len(settings['meshes_removed'])} mesh geoms "
                 "removed; timestep "
                 f"{settings['timestep']:g} s (the file's {settings['file_timestep']:g} s), "
                 "gravity the plan's"]
        if changed:
            extra.append("fingertip contact settings that differ from the file's (with the "
                         f"object): {', '.join(changed)}")
        if settings["couplings"]:
            extra.append("the file couples joints the plan moves (the execution has the "
                         "couplings): " + "; ".join(settings["couplings"]))
        extra += _creep_notes(plan, creep, m, T)
        report = SimReport.assess(
            mode="servo (the model's actuators)", options=o, contacts=contacts,
            position=ErrorSummary.of(pos_err[during], t_end[during]),
            angle=ErrorSummary.of(ang_err[during], t_end[during]),
            series_t=t_end[rec], series_position=pos_err[rec], series_angle=ang_err[rec],
            series_force=normal_force[rec].T, wall_time=wall, steps=n_steps, duration=T,
            notes=[*plan.notes, *extra, *notes, *drive_notes, *short_notes, *clip_notes],
            mujoco_version=mujoco.__version__)
        report.model = settings
        return report

    @property
    def _actuator_of(self) -> dict[int, int]:
        return {j.dof: j.actuator for joints in self.joints for j in joints
                if j.actuator >= 0}


#: A fingertip whose creep over the plan's duration would exceed this [m] is reported.
CREEP_NOTE = 1e-3


def _creep_notes(plan: ExecutionPlan, creep: list[list[float]], m: Any, T: float
                 ) -> list[str]:
    """What the file's soft friction does to the plan (:func:`creep_speed`, sampled while
    it ran): each fingertip whose median creep over the plan's duration exceeds
    :data:`CREEP_NOTE`, and what would hold it."""
    out = []
    for spec, speeds in zip(plan.contacts, creep, strict=True):
        if not speeds:
            continue
        med, top = float(np.median(speeds)), float(np.max(speeds))
        if med * T > CREEP_NOTE:
            out.append(f"fingertip {spec.name}: the file's soft friction lets it creep "
                       f"{med * 1e3:.3g} mm/s (up to {top * 1e3:.3g}) under its friction "
                       f"force, about {med * T * 1e3:.3g} mm over this {T:.3g} s plan "
                       f"(MuJoCo's v = R f / B; impratio {float(m.opt.impratio):g}, "
                       "noslip_iterations 0): the noslip solver (<option "
                       "noslip_iterations=\"5\">) removes that creep")
    return out


def simulate_on_model(plan: ExecutionPlan, model: UserModel,
                      options: SimOptions | None = None) -> SimReport:
    """Execute ``plan`` on the user's ``model`` in MuJoCo (module docstring)."""
    return UserModelSimulation(plan, model, options).run()
