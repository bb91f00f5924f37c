"""What the hand file's own actuators must be commanded to make a plan's motion and forces
(issue 37, item 1), read as MuJoCo reads the file.

Per planned joint, the torque it must get (``needed``) at each sample:

    tau = tau_plan + (c(q, q_dot) - c(q, 0)) - passive(q, q_dot) + M(q) q_ddot

``tau_plan`` the plan's joint torques (``J^T`` of the planned contact forces and torsion,
and the links' weight, as the plan's ``joint_trajectory`` efforts give them; zero for a
plan without forces), then MuJoCo's: the Coriolis and centrifugal terms (``qfrc_bias`` at
the velocity less at rest), less the passive forces (joint damping, springs, gravity
compensation: ``qfrc_passive``), plus the links' inertia. Joint ``frictionloss`` is not
compensated (its sign follows the motion; reported).

The joint's actuator (MuJoCo joint transmission: ``position``, ``velocity``, ``motor``,
``general`` with a fixed gain and an affine bias, any ``gear``; force ``F = gain ctrl + b0
+ b1 L + b2 L_dot``, ``L = gear q``, the joint torque ``gear F``) gets

    ctrl = (tau / gear - b0 - b1 gear q - b2 gear q_dot) / gain

(a position servo of stiffness kp: the set point ``q + tau / kp``; a motor: ``tau /
(gear gain)``). Its limits are the file's: ``forcerange`` (on F, so ``gear`` times it on the
joint) and ``ctrlrange``. A joint without such an actuator has none (reported); a URDF's
joints are motors limited by their ``effort``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["Actuation", "Actuator", "HandActuation", "UrdfActuation", "actuation_of",
           "ranges_of", "torque_bounds", "torque_bounds_at", "urdf_actuators"]

FloatArray = NDArray[np.float64]

#: A joint no actuator drives may need at most this torque [N m] (its damping, inertia
#: and weight over a plan's motion) without a tendon to carry it.
PASSIVE_TOL = 1e-5


@dataclass(frozen=True)
class Actuator:
    """The actuator of one joint (module docstring). ``kind``: "servo" (an affine bias,
    e.g. ``position``), "motor" (no bias on the length or rate) or "none"."""

    joint: str
    name: str = ""
    kind: str = "none"
    gear: float = 1.0
    gain: float = 1.0
    bias: tuple[float, float, float] = (0.0, 0.0, 0.0)
    #: The joint torque the actuator can give [N m] (gear times its forcerange), or None.
    torque_range: tuple[float, float] | None = None
    ctrl_range: tuple[float, float] | None = None

    def control(self, tau: FloatArray, q: FloatArray, q_dot: FloatArray) -> FloatArray:
        b0, b1, b2 = self.bias
        g = self.gear
        return (tau / g - b0 - b1 * g * q - b2 * g * q_dot) / self.gain

    def range_at(self, q: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """The joint torques [N m] it can give at joint positions ``q`` (at rest): its
        ``torque_range``, and where its control is limited the torques its ``ctrlrange``
        reaches there (a position servo of stiffness kp whose set point must stay in
        ``[c_lo, c_hi]`` gives ``kp (c_lo - q) .. kp (c_hi - q)``: nothing below 0 at
        ``q = c_lo``); infinite where it has no limit."""
        Q = np.asarray(q, dtype=float)
        lo, hi = np.full(Q.shape, -np.inf), np.full(Q.shape, np.inf)
        if self.torque_range is not None:
            lo, hi = np.maximum(lo, self.torque_range[0]), np.minimum(hi, self.torque_range[1])
        ends = self.control_ends()
        if ends is not None:
            slope, lo_end, hi_end = ends
            lo, hi = np.maximum(lo, slope * Q + lo_end), np.minimum(hi, slope * Q + hi_end)
        return lo, hi

    def control_ends(self) -> tuple[float, float, float] | None:
        """Where its control is limited, the joint torques [N m] its control range's ends
        give, affine in the joint position q: ``(slope, lower, upper)``, the torques
        ``slope q + lower .. slope q + upper`` (a position servo of stiffness kp: slope
        -kp g^2); None where the control is not limited (:meth:`range_at`)."""
        if self.ctrl_range is None or self.kind == "none":
            return None
        g, (b0, b1, _) = self.gear, self.bias
        ends = [g * (self.gain * c + b0) for c in self.ctrl_range]
        return g * g * b1, min(ends), max(ends)

    def describe_range(self) -> str:
        if self.torque_range is None:
            return "no torque limit"
        lo, hi = self.torque_range
        return f"{lo:.3g}..{hi:.3g} N m"


@dataclass(frozen=True)
class Actuation:
    """A plan's actuator commands at its samples ``t``: per joint (``actuators``, in the
    plan's joint order), the torque ``needed`` (n, joints) and the ``controls`` (n, joints;
    NaN where a joint has no actuator), and the worst use of the limits."""

    t: FloatArray
    actuators: tuple[Actuator, ...]
    needed: FloatArray
    controls: FloatArray
    notes: tuple[str, ...] = ()
    #: why the file cannot make this plan other than by a limit: a joint no actuator
    #: drives that needs a torque (:meth:`HandActuation.through_tendons`)
    problems: tuple[str, ...] = ()

    def load(self) -> tuple[float, int, int]:
        """The largest share of a torque limit needed (1 at the limit), the joint and the
        sample: ``(0, -1, -1)`` without limits."""
        best = (0.0, -1, -1)
        for j, a in enumerate(self.actuators):
            if a.torque_range is None:
                continue
            lo, hi = a.torque_range
            tau = self.needed[:, j]
            share = np.maximum(np.where(tau > 0, tau / hi if hi > 0 else np.inf, 0.0),
                               np.where(tau < 0, tau / lo if lo < 0 else np.inf, 0.0))
            k = int(np.argmax(share)) if share.size else -1
            if k >= 0 and share[k] > best[0]:
                best = (float(share[k]), j, k)
        return best

    def ctrl_overrun(self) -> tuple[float, int, int]:
        """How far [the control's unit] a control leaves its ``ctrlrange`` at worst, the
        joint and the sample: ``(0, -1, -1)`` when none does."""
        best = (0.0, -1, -1)
        for j, a in enumerate(self.actuators):
            if a.ctrl_range is None or a.kind == "none":
                continue
            u = self.controls[:, j]
            over = np.maximum(u - a.ctrl_range[1], a.ctrl_range[0] - u)
            k = int(np.argmax(over)) if over.size else -1
            if k >= 0 and over[k] > best[0]:
                best = (float(over[k]), j, k)
        return best

    def refusals(self, tol: float = 1e-6) -> list[str]:
        """Why the file's actuators cannot make this plan: a torque beyond a joint's limit,
        a control beyond its range (each the worst; [] when within)."""
        out = list(self.problems)
        share, j, k = self.load()
        if share > 1.0 + tol:
            a = self.actuators[j]
            out.append(f"joint {a.joint} needs {self.needed[k, j]:.3g} N m at t = "
                       f"{self.t[k]:.4g} s; its actuator {a.name or '(none)'} gives "
                       f"{a.describe_range()}")
        over, j, k = self.ctrl_overrun()
        if over > tol:
            a = self.actuators[j]
            assert a.ctrl_range is not None
            out.append(f"actuator {a.name} (joint {a.joint}) would be commanded "
                       f"{self.controls[k, j]:.4g} at t = {self.t[k]:.4g} s, outside its "
                       f"ctrlrange {a.ctrl_range[0]:.4g}..{a.ctrl_range[1]:.4g}")
        return out


def urdf_actuators(joint_names: Sequence[str], effort: ArrayLike) -> tuple[Actuator, ...]:
    """A URDF's joints as motors limited by their ``effort`` (none where it is not a
    positive finite number)."""
    out = []
    for n, e in zip(joint_names, np.asarray(effort, dtype=float), strict=True):
        ok = bool(np.isfinite(e) and e > 0)
        out.append(Actuator(n, n if ok else "", "motor" if ok else "none",
                            torque_range=(-float(e), float(e)) if ok else None))
    return tuple(out)


@dataclass(frozen=True)
class UrdfActuation:
    """A URDF hand's joints as motors limited by their ``effort`` (``effort`` by joint
    name); the plan's torques are what they must give (no damping or inertia added)."""

    effort: dict[str, float]

    def actuators(self, joint_names: Sequence[str]) -> tuple[tuple[Actuator, ...],
                                                             tuple[str, ...]]:
        """Each joint's motor (:func:`urdf_actuators`), and no notes."""
        return urdf_actuators(joint_names, [self.effort.get(n, np.inf)
                                            for n in joint_names]), ()

    def with_limits(self, limits: dict[str, float]) -> UrdfActuation:
        """The same joints with ``limits`` [N m] as their efforts where given."""
        return UrdfActuation({**self.effort, **limits})

    def damping(self, joint_names: Sequence[str]) -> FloatArray:
        """No damping is read from a URDF's joints."""
        return np.zeros(len(joint_names))

    def commands(self, joint_names: Sequence[str], t: ArrayLike, q: ArrayLike,
                 q_dot: ArrayLike, q_ddot: ArrayLike | None,
                 plan_torques: ArrayLike | None) -> Actuation:
        acts, _ = self.actuators(joint_names)
        Q = np.atleast_2d(np.asarray(q, dtype=float))
        tau = np.zeros_like(Q) if plan_torques is None else \
            np.atleast_2d(np.asarray(plan_torques, dtype=float))
        notes: tuple[str, ...] = (
            "a URDF's joints: motors limited by their effort; the links' inertia and joint "
            "damping not added",)
        if plan_torques is None:
            notes = (*notes, "the plan states no forces: no torques needed")
        return actuation_of(np.asarray(t, dtype=float), acts, tau, Q,
                            np.atleast_2d(np.asarray(q_dot, dtype=float)), notes)


@dataclass(eq=False)
class HandActuation:
    """An MJCF hand's actuators and dynamics as MuJoCo reads them (mesh files absent); its
    world frame at ``mount`` (R, p) in the palm frame."""

    text: str
    mount: tuple[FloatArray, FloatArray] = field(
        default_factory=lambda: (np.eye(3), np.zeros(3)))
    #: Joints not planned, held at these values (a shared wrist); the rest at ``qpos0``.
    held: dict[str, float] = field(default_factory=dict)
    #: Torque limits [N m] given for joints' actuators, over the file's ``forcerange``.
    limits: dict[str, float] = field(default_factory=dict)
    #: The fingers' joint couplings (:class:`~ocp.robots.couplings.Coupling`): a joint no
    #: actuator drives gets its torque through one (:meth:`through_tendons`).
    couplings: tuple[Any, ...] = ()
    _mj: Any = field(default=None, repr=False)

    def with_limits(self, limits: dict[str, float]) -> HandActuation:
        """The same hand with ``limits`` [N m] as its joints' actuators' torque ranges
        (either way) where given."""
        return replace(self, limits={**self.limits, **limits})

    def model(self) -> Any:
        import mujoco

        from ocp.robots.mjcf_frames import mujoco_text

        if self._mj is None:
            self._mj = mujoco.MjModel.from_xml_string(mujoco_text(self.text))
        return self._mj

    def actuators(self, joint_names: Sequence[str]) -> tuple[tuple[Actuator, ...],
                                                             tuple[str, ...]]:
        """Each joint's actuator (the first with a joint transmission on it; ``limits``
        over its torque range), and notes."""
        m = self.model()
        out: list[Actuator] = []
        notes: list[str] = []
        for n in joint_names:
            given = self.limits.get(n)
            got = self._actuator(m, n, notes)
            if given is not None:
                got = replace(got, torque_range=(-float(given), float(given)))
                notes.append(f"joint {n}: its actuator gives {given:g} N m, as asked")
            out.append(got)
        return tuple(out), tuple(notes)

    def _actuator(self, m: Any, n: str, notes: list[str]) -> Actuator:
        """Joint ``n``'s actuator as the file says (the first with a joint transmission on
        it), notes added on what it is not."""
        import mujoco

        obj = mujoco.mjtObj
        jid = mujoco.mj_name2id(m, obj.mjOBJ_JOINT, n)
        ids = [a for a in range(m.nu)
               if int(m.actuator_trntype[a]) == int(mujoco.mjtTrn.mjTRN_JOINT)
               and int(m.actuator_trnid[a, 0]) == jid] if jid >= 0 else []
        if not ids:
            notes.append(f"joint {n}: no actuator drives it")
            return Actuator(n)
        a = ids[0]
        name = mujoco.mj_id2name(m, obj.mjOBJ_ACTUATOR, a) or f"actuator {a}"
        gear = float(m.actuator_gear[a, 0])
        gain = float(m.actuator_gainprm[a, 0])
        fixed = int(m.actuator_gaintype[a]) == int(mujoco.mjtGain.mjGAIN_FIXED)
        plain = int(m.actuator_dyntype[a]) == int(mujoco.mjtDyn.mjDYN_NONE)
        biastype = int(m.actuator_biastype[a])
        if not (fixed and plain and gain != 0.0 and gear != 0.0) or biastype not in (
                int(mujoco.mjtBias.mjBIAS_NONE), int(mujoco.mjtBias.mjBIAS_AFFINE)):
            notes.append(f"joint {n}: actuator {name} has activation dynamics, a non-fixed "
                         "gain or a non-affine bias: not commanded")
            return Actuator(n, name)
        b = (0.0, 0.0, 0.0) if biastype == int(mujoco.mjtBias.mjBIAS_NONE) else \
            (float(m.actuator_biasprm[a, 0]), float(m.actuator_biasprm[a, 1]),
             float(m.actuator_biasprm[a, 2]))
        force = None
        if m.actuator_forcelimited[a]:
            lo, hi = sorted(gear * float(x) for x in m.actuator_forcerange[a])
            force = (lo, hi)
        ctrl = (float(m.actuator_ctrlrange[a, 0]), float(m.actuator_ctrlrange[a, 1])) \
            if m.actuator_ctrllimited[a] else None
        kind = "servo" if b[1] != 0.0 or b[2] != 0.0 else "motor"
        if len(ids) > 1:
            notes.append(f"joint {n}: {len(ids) - 1} more actuators on it, not commanded")
        if float(m.dof_frictionloss[int(m.jnt_dofadr[jid])]) > 0:
            notes.append(f"joint {n}: its frictionloss is not compensated")
        return Actuator(n, name, kind, gear, gain, b, force, ctrl)

    def damping(self, joint_names: Sequence[str]) -> FloatArray:
        """The joints' viscous damping [N m s/rad] in the file (``damping``)."""
        import mujoco

        m = self.model()
        return np.array([float(m.dof_damping[int(m.jnt_dofadr[
            mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, n)])]) for n in joint_names])

    def model_torques(self, joint_names: Sequence[str], q: ArrayLike, q_dot: ArrayLike,
                      q_ddot: ArrayLike | None = None) -> FloatArray:
        """(n, joints): what MuJoCo's model of the hand needs on top of the plan's torques
        (module docstring), the other joints at ``qpos0``, the object absent."""
        import mujoco

        m = self.model()
        d = mujoco.MjData(m)
        ids = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, n) for n in joint_names]
        if min(ids, default=0) < 0:
            missing = [n for n, i in zip(joint_names, ids, strict=True) if i < 0]
            raise ValueError(f"the hand has no joint {missing[0]!r}")
        qa = [int(m.jnt_qposadr[i]) for i in ids]
        va = [int(m.jnt_dofadr[i]) for i in ids]
        held = [(int(m.jnt_qposadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, n)]), v)
                for n, v in self.held.items()]
        Q = np.atleast_2d(np.asarray(q, dtype=float))
        QD = np.atleast_2d(np.asarray(q_dot, dtype=float))
        QDD = None if q_ddot is None else np.atleast_2d(np.asarray(q_ddot, dtype=float))
        out = np.zeros_like(Q)
        acc, mq = np.zeros(m.nv), np.zeros(m.nv)
        for i in range(len(Q)):
            d.qpos[:] = m.qpos0
            for a, v in held:
                d.qpos[a] = v
            d.qpos[qa] = Q[i]
            d.qvel[:] = 0.0
            mujoco.mj_forward(m, d)
            rest = d.qfrc_bias[va].copy()
            d.qvel[va] = QD[i]
            mujoco.mj_forward(m, d)
            tau = d.qfrc_bias[va] - rest - d.qfrc_passive[va]
            if QDD is not None:  # the other joints at rest
                acc[:] = 0.0
                acc[va] = QDD[i]
                mujoco.mj_mulM(m, d, mq, acc)
                tau = tau + mq[va]
            out[i] = tau
        return out

    def commands(self, joint_names: Sequence[str], t: ArrayLike, q: ArrayLike,
                 q_dot: ArrayLike, q_ddot: ArrayLike | None,
                 plan_torques: ArrayLike | None) -> Actuation:
        """The plan's actuator commands (module docstring) at the samples ``t``."""
        acts, notes = self.actuators(joint_names)
        if self.held:
            notes = (*notes, "joints shared by several fingers, held (not planned): " +
                     ", ".join(f"{n} at {v:.4g}" for n, v in self.held.items()) +
                     "; their actuators hold them there")
        Q = np.atleast_2d(np.asarray(q, dtype=float))
        QD = np.atleast_2d(np.asarray(q_dot, dtype=float))
        tau = self.model_torques(joint_names, Q, QD, q_ddot)
        if plan_torques is not None:
            tau = tau + np.atleast_2d(np.asarray(plan_torques, dtype=float))
        else:
            notes = (*notes, "the plan states no forces: the commands make its motion "
                             "alone, not a grip")
        T = np.asarray(t, dtype=float)
        tau, more, problems = self.through_tendons(joint_names, acts, T, Q, tau)
        return replace(actuation_of(T, acts, tau, Q, QD, (*notes, *more)),
                       problems=tuple(problems))

    def through_tendons(self, joint_names: Sequence[str], acts: tuple[Actuator, ...],
                        t: FloatArray, q: FloatArray, tau: FloatArray
                        ) -> tuple[FloatArray, list[str], list[str]]:
        """The torques the actuators must give when a joint no actuator drives (the
        Shadow hand's J0) gets its torque through a coupling tendon: the tendon's force
        ``lam = tau_p / c_p`` (a limit's force: it pulls only at the tendon's bound, at
        the lower one for ``lam > 0``, MuJoCo's sign), taken off every joint of the
        tendon (``tau -= c lam``; the passive joint's then 0). Returns (the torques, notes
        on each tendon's force, problems: a passive joint that needs a torque its tendon
        cannot give there, or that no coupling carries)."""
        names = list(joint_names)
        out = np.array(tau, dtype=float)
        notes: list[str] = []
        problems: list[str] = []
        carried: set[str] = set()
        for c in self.couplings:
            if not set(c.joints) <= set(names):
                continue
            passive = [j for j in c.joints if not _driven(acts[names.index(j)])]
            if len(passive) != 1:
                continue
            p = passive[0]
            a = c.row(names)
            lam = out[:, names.index(p)] / a[names.index(p)]
            out = out - np.outer(lam, a)
            carried.add(p)
            length = q @ a
            need = np.abs(lam * a[names.index(p)]) > PASSIVE_TOL
            off = np.where(need & (lam > 0), length - c.lower,
                           np.where(need & (lam < 0), c.upper - length, 0.0))
            k = int(np.argmax(off))
            if off[k] > 1e-6:
                side = "lower" if lam[k] > 0 else "upper"
                problems.append(
                    f"joint {p} has no actuator: its {tau[k, names.index(p)]:.3g} N m at "
                    f"t = {t[k]:.4g} s can come only from {c.name} pulling at its {side} "
                    f"bound, but the plan holds the tendon {off[k] * 1e3:.3g} mm from it")
            notes.append(f"joint {p} has no actuator: its torque comes from {c.name} "
                         f"({float(lam.min()):.3g}..{float(lam.max()):.3g} N at its bound), "
                         "taken off the other joints' actuators")
        if not self.model().nu:  # a file without actuators does not say how it is driven
            return out, notes, problems
        for j, (n, act) in enumerate(zip(names, acts, strict=True)):
            if _driven(act) or n in carried:
                continue
            k = int(np.argmax(np.abs(out[:, j])))
            if out.size and abs(out[k, j]) > PASSIVE_TOL:
                problems.append(f"joint {n} has no actuator and no coupling to carry its "
                                f"torque, but needs {out[k, j]:.3g} N m at t = {t[k]:.4g} s")
        return out, notes, problems


def _driven(a: Actuator) -> bool:
    """Whether an actuator drives the joint (the file's, or a limit the request gave)."""
    return bool(a.name) or a.torque_range is not None


def torque_bounds(actuation: Any, joint_names: Sequence[str], share: float = 1.0
                  ) -> tuple[FloatArray, FloatArray]:
    """(lower, upper) joint torques [N m] the actuators give ``joint_names`` (infinite
    where a joint has no limit), times ``share``."""
    return ranges_of(actuation.actuators(joint_names)[0], share)


def ranges_of(acts: Sequence[Actuator], share: float = 1.0) -> tuple[FloatArray, FloatArray]:
    """(lower, upper) joint torques [N m] the actuators ``acts`` give (infinite where one
    has no limit), times ``share``."""
    lo = np.array([a.torque_range[0] if a.torque_range else -np.inf for a in acts])
    hi = np.array([a.torque_range[1] if a.torque_range else np.inf for a in acts])
    return share * lo, share * hi


def torque_bounds_at(actuation: Any, joint_names: Sequence[str], q: ArrayLike,
                     share: float = 1.0) -> tuple[FloatArray, FloatArray]:
    """(lower, upper) joint torques [N m] the actuators give ``joint_names`` at the joint
    positions ``q`` (rows: samples): :meth:`Actuator.range_at`, times ``share`` (each
    range is narrowed toward 0 torque)."""
    acts, _ = actuation.actuators(joint_names)
    Q = np.atleast_2d(np.asarray(q, dtype=float))
    lo, hi = np.empty_like(Q), np.empty_like(Q)
    for j, a in enumerate(acts):
        lo[:, j], hi[:, j] = a.range_at(Q[:, j])
    return share * lo, share * hi


def actuation_of(t: FloatArray, acts: tuple[Actuator, ...], tau: FloatArray, q: FloatArray,
                 q_dot: FloatArray, notes: tuple[str, ...] = ()) -> Actuation:
    """The commands of ``acts`` that give the torques ``tau`` (n, joints) at ``q``,
    ``q_dot``."""
    ctrl = np.full_like(tau, np.nan)
    for j, a in enumerate(acts):
        if a.kind != "none":
            ctrl[:, j] = a.control(tau[:, j], q[:, j], q_dot[:, j])
    return Actuation(t, acts, tau, ctrl, notes)
