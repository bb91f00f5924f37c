"""The grasp's state from a measurement: joint angles (and rates) and the object's pose
(and twist), e.g. encoders and vision (docs/replanning.md, "From a measured state").

A re-plan starts from a state of the grasp's layout (:func:`ocp.solve.attempt.attempt`'s
``x0``): contact coordinates that nobody measures and joints that must put every fingertip
exactly where the contact puts it (closure, eq. 6, within the certificate's tolerances).
:func:`estimate_state` finds the state nearest to what is measured that the grasp
explains: a small equality-constrained least-squares problem solved by Gauss-Newton steps
on its KKT system (CasADi's Jacobians of the grasp's own closure and pose functions):

    min  sum |q_i - q_i,meas|^2 / s_q^2 + |p_po(x) - p_meas|^2 / s_p^2
         + |log(R_meas^T R_po(x))|^2 / s_R^2 + eps |x - x_guess|^2
    s.t. closure(x) = 0   (and a unit quaternion for a free object)

The joints move as little as closure needs (a fingertip pressed into the object by the
grip is put back on its surface), the object's pose as little as the palm or the fingers
need. The rates follow the same way, linearly: the inputs u nearest to the measured joint
rates and object twist for which d/dt closure(x) = 0 along the grasp's dynamics (the NLP
imposes closure at the velocity level at every collocation point, the first included, so
a moving start must be consistent).

What the grasp cannot explain is reported, not planned through (:attr:`StateEstimate.
explained` false and its ``problems``): a fingertip that had to move more than
``max_fingertip_shift`` to touch (the contact lost), an object more than
``max_object_shift`` from any pose the grasp allows (dropped, lifted off the palm), or a
solve that does not reach closure.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import casadi as ca
import numpy as np
from numpy.typing import NDArray

from ocp.contacts import FreeObject
from ocp.geometry.rotations import vee_skew
from ocp.spec.grasp import ManipulationProblem, contact_charts
from ocp.transcription.grasp_model import GraspModel

__all__ = ["EstimateOptions", "Measurement", "StateEstimate", "estimate_state"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Measurement:
    """What a controller measures: each finger's joint angles ``q`` (the problem's finger
    order) and the object's pose in the palm frame (``object_position`` [m],
    ``object_wxyz``); optionally the joint rates ``q_dot``, the object's linear velocity
    [m/s] and angular velocity [rad/s] (palm frame)."""

    q: Sequence[Any]
    object_position: Any
    object_wxyz: Any
    q_dot: Sequence[Any] | None = None
    object_velocity: Any = None
    object_omega: Any = None
    #: each finger's measured contact location [m], palm frame (a tactile sensor's), or
    #: None for a finger (or all) not measured
    contact_points: Sequence[Any] | None = None


@dataclass(frozen=True)
class EstimateOptions:
    """Weights (the expected measurement errors: joints ``sigma_q`` [rad], the object's
    position ``sigma_p`` [m] and orientation ``sigma_r`` [rad], the rates likewise) and the
    limits beyond which a measurement is not explained: a fingertip moved more than
    ``max_fingertip_shift`` [m] to touch, the object moved more than ``max_object_shift``
    [m] or ``max_object_turn`` [rad] to a pose the grasp allows; a measured contact
    location weighs ``sigma_c`` [m], and one more than ``max_contact_shift`` [m] from the
    estimated contact point is not explained either (the contact is elsewhere)."""

    sigma_q: float = 1e-3
    sigma_p: float = 5e-4
    sigma_r: float = 1e-2
    sigma_qd: float = 1e-2
    sigma_v: float = 5e-3
    sigma_w: float = 5e-2
    max_fingertip_shift: float = 3e-3
    max_object_shift: float = 3e-3
    max_object_turn: float = 0.1
    sigma_c: float = 1e-3
    max_contact_shift: float = 3e-3
    max_iter: int = 30
    tol: float = 1e-12


@dataclass(frozen=True)
class StateEstimate:
    """The grasp's state ``x`` (and input ``u`` when the rates were measured or guessed)
    nearest to the measurement; ``explained`` whether the grasp explains it (``problems``
    say why not); ``fingertip_shift`` [m] per finger (how far its tip moved to touch),
    ``object_shift`` [m] and ``object_turn`` [rad] (the object's pose against the
    measured one), ``contact_shift`` [m] per finger (the estimated contact point against
    a measured one; None for a finger whose contact was not measured), ``closure`` (the
    largest closure residual left), ``iterations``; ``fields`` names, for each of
    ``problems``, the measurement it is about (``q[i]``, ``object_position``,
    ``object_wxyz``, ``contact_points[i]``)."""

    x: FloatArray
    u: FloatArray | None
    explained: bool
    fingertip_shift: tuple[float, ...]
    object_shift: float
    object_turn: float
    closure: float
    iterations: int
    problems: tuple[str, ...] = field(default=())
    fields: tuple[str, ...] = field(default=())
    contact_shift: tuple[float | None, ...] = field(default=())


class _Functions:
    """The CasADi functions of one grasp model the estimate needs (built once)."""

    def __init__(self, m: GraspModel) -> None:
        x = ca.SX.sym("x", m.nx)
        u = ca.SX.sym("u", m.nu)
        prm = ca.SX.sym("p", m.n_params)
        closure, points, _, R_po, p_po = m.path(x, prm)
        c = [closure]
        if isinstance(m.object, FreeObject):
            qo = x[m.object.x0 + 3:m.object.x0 + 7]
            c.append(ca.dot(qo, qo) - 1)
        c_all = ca.vertcat(*c)
        self.n_closure = int(closure.numel())
        Rm = ca.SX.sym("Rm", 3, 3)
        pose_res = ca.vertcat(p_po, vee_skew(Rm.T @ R_po))
        self.pose = ca.Function("pose", [x, prm, Rm], [pose_res, ca.jacobian(pose_res, x)])
        self.constraint = ca.Function("c", [x, prm], [c_all, ca.jacobian(c_all, x)])
        cdot = ca.jtimes(closure, x, m.dynamics(x, u, prm))
        u0 = ca.DM.zeros(m.nu)
        A = ca.jacobian(cdot, u)
        self.velocity = ca.Function("cdot", [x, u, prm], [A, ca.substitute(cdot, u, u0)])
        tips = []
        for tip in m.fingertips:
            _, p_fk = tip.finger.fk(x[tip.q_cols])
            tips.append(p_fk)
        self.tips = ca.Function("tips", [x], [ca.horzcat(*tips) if tips else ca.SX(3, 0)])
        #: each fingertip's contact point (palm frame) and its Jacobian, fingertip order
        cols = [m.point_contacts.index(tip) for tip in m.fingertips]
        # the path's points are on the object's surface, in its frame: to the palm frame
        pts = ca.vertcat(*[p_po + R_po @ points[:, j] for j in cols]) if cols else \
            ca.SX(0, 1)
        self.points = ca.Function("points", [x, prm], [pts, ca.jacobian(pts, x)])
        obj_v = ca.jtimes(p_po, x, m.dynamics(x, u, prm))
        obj_R = ca.jtimes(ca.vec(R_po), x, m.dynamics(x, u, prm))
        omega = vee_skew(ca.reshape(obj_R, 3, 3) @ R_po.T)
        twist = ca.vertcat(obj_v, omega)
        self.twist = ca.Function("twist", [x, u, prm], [ca.jacobian(twist, u),
                                                        ca.substitute(twist, u, u0)])


_FUNCTIONS: dict[int, tuple[GraspModel, _Functions]] = {}


def _functions(m: GraspModel) -> _Functions:
    hit = _FUNCTIONS.get(id(m))
    if hit is None or hit[0] is not m:
        hit = (m, _Functions(m))
        _FUNCTIONS[id(m)] = hit
    return hit[1]


def _rotation(wxyz: Any) -> FloatArray:
    w, x, y, z = np.asarray(wxyz, dtype=float) / np.linalg.norm(wxyz)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def _kkt(J: FloatArray, r: FloatArray, A: FloatArray, c: FloatArray, reg: float
         ) -> FloatArray:
    """The step dz of min |r + J dz|^2 + reg |dz|^2 s.t. c + A dz = 0."""
    n, k = J.shape[1], A.shape[0]
    K = np.zeros((n + k, n + k))
    K[:n, :n] = J.T @ J + reg * np.eye(n)
    K[:n, n:] = A.T
    K[n:, :n] = A
    rhs = np.concatenate([-J.T @ r, -c])
    try:
        sol = np.linalg.solve(K, rhs)
    except np.linalg.LinAlgError:
        sol = np.linalg.lstsq(K, rhs, rcond=None)[0]
    return np.asarray(sol[:n])


def estimate_state(problem: ManipulationProblem, m: GraspModel, measured: Measurement,
                   guess: Any, u_guess: Any = None,
                   options: EstimateOptions | None = None) -> StateEstimate:
    """The grasp's state nearest to ``measured`` that closure explains (see the module),
    by Gauss-Newton from ``guess`` (a state of the grasp's layout: the current plan's at
    this time). The inputs ``u`` when the measurement has joint rates (or ``u_guess``, the
    plan's inputs, is given): the nearest to the measured rates (else to ``u_guess``) that
    keep closure at the velocity level."""
    o = options or EstimateOptions()
    f = _functions(m)
    prm = m.params(np.asarray(problem.object.params, dtype=float), contact_charts(problem))
    x = np.asarray(guess, dtype=float).copy()
    if len(measured.q) != len(m.fingertips):
        raise ValueError(f"the measurement has {len(measured.q)} fingers, the grasp "
                         f"{len(m.fingertips)}")
    q_cols = [np.arange(m.nx)[t.q_cols] for t in m.fingertips]
    q_meas = [np.asarray(q, dtype=float).ravel() for q in measured.q]
    for cols, q in zip(q_cols, q_meas, strict=True):
        if q.size != cols.size:
            raise ValueError(f"a finger of {cols.size} joints measured with {q.size}")
    p_meas = np.asarray(measured.object_position, dtype=float)
    R_meas = _rotation(measured.object_wxyz)
    if isinstance(m.object, FreeObject):  # the measured pose is a first guess
        qo = np.asarray(measured.object_wxyz, dtype=float)
        qo = qo / np.linalg.norm(qo)
        prev = x[m.object.x0 + 3:m.object.x0 + 7]
        x[m.object.x0:m.object.x0 + 3] = p_meas
        x[m.object.x0 + 3:m.object.x0 + 7] = qo if float(qo @ prev) >= 0 else -qo
    for cols, q in zip(q_cols, q_meas, strict=True):
        x[cols] = q
    x_guess = x.copy()
    c_meas = _contact_points(measured, len(m.fingertips))
    c_rows = np.concatenate([np.arange(3 * i, 3 * i + 3) for i, c in enumerate(c_meas)
                             if c is not None]).astype(int) if any(
        c is not None for c in c_meas) else np.zeros(0, dtype=int)
    c_vals = np.concatenate([c for c in c_meas if c is not None]) if c_rows.size else \
        np.zeros(0)
    w_pose = np.array([1 / o.sigma_p] * 3 + [1 / o.sigma_r] * 3)
    eps = 1e-2  # the contact coordinates nothing measures: near the guess

    def residual(x: FloatArray) -> tuple[FloatArray, FloatArray]:
        pres, pjac = f.pose(x, prm, R_meas)
        pres = np.asarray(pres).ravel() - np.concatenate([p_meas, np.zeros(3)])
        rows, jac = [w_pose * pres], [w_pose[:, None] * np.asarray(pjac)]
        for cols, q in zip(q_cols, q_meas, strict=True):
            rows.append((x[cols] - q) / o.sigma_q)
            J = np.zeros((cols.size, m.nx))
            J[np.arange(cols.size), cols] = 1 / o.sigma_q
            jac.append(J)
        if c_rows.size:
            cres, cjac = f.points(x, prm)
            rows.append((np.asarray(cres).ravel()[c_rows] - c_vals) / o.sigma_c)
            jac.append(np.asarray(cjac)[c_rows] / o.sigma_c)
        rows.append(eps * (x - x_guess))
        jac.append(eps * np.eye(m.nx))
        return np.concatenate(rows), np.vstack(jac)

    it = 0
    for it in range(1, o.max_iter + 1):  # noqa: B007
        r, J = residual(x)
        c, A = (np.asarray(a) for a in f.constraint(x, prm))
        dz = _kkt(J, r, A, c.ravel(), 0.0)
        x = x + dz
        if float(np.max(np.abs(dz))) < 1e-11:
            break
    c = np.asarray(f.constraint(x, prm)[0]).ravel()
    closure = float(np.max(np.abs(c), initial=0.0))
    tips_meas = np.zeros_like(x)
    tips_meas[:] = x
    for cols, q in zip(q_cols, q_meas, strict=True):
        tips_meas[cols] = q
    shift = np.linalg.norm(np.asarray(f.tips(x)) - np.asarray(f.tips(tips_meas)), axis=0)
    pres = np.asarray(f.pose(x, prm, R_meas)[0]).ravel()
    obj_shift = float(np.linalg.norm(pres[:3] - p_meas))
    obj_turn = float(np.linalg.norm(pres[3:]))
    problems, fields = [], []
    for i, s in enumerate(shift):
        if s > o.max_fingertip_shift:
            problems.append(f"finger {i}: its fingertip is {s * 1e3:.2f} mm from any pose "
                            f"touching the object (limit {o.max_fingertip_shift * 1e3:g} "
                            "mm): contact lost")
            fields.append(f"q[{i}]")
    if obj_shift > o.max_object_shift or obj_turn > o.max_object_turn:
        problems.append(f"object: {obj_shift * 1e3:.2f} mm and {np.degrees(obj_turn):.2f} "
                        "deg from any pose the grasp allows (limits "
                        f"{o.max_object_shift * 1e3:g} mm, "
                        f"{np.degrees(o.max_object_turn):.3g} deg): dropped or lifted")
        fields.append("object_position" if obj_shift > o.max_object_shift
                      else "object_wxyz")
    contact_shift: list[float | None] = [None] * len(c_meas)
    if c_rows.size:
        est_points = np.asarray(f.points(x, prm)[0]).ravel()
        for i, point in enumerate(c_meas):
            if point is None:
                continue
            d = float(np.linalg.norm(est_points[3 * i:3 * i + 3] - point))
            contact_shift[i] = d
            if d > o.max_contact_shift:
                problems.append(f"finger {i}: its measured contact is {d * 1e3:.2f} mm from "
                                "any contact point the grasp explains (limit "
                                f"{o.max_contact_shift * 1e3:g} mm): the contact is "
                                "elsewhere")
                fields.append(f"contact_points[{i}]")
    for block in m.contacts:  # off a pad's edge, past a pole, a joint past its limit
        lo, hi, _ = block.bounds(problem)
        xb = x[block.xs]
        out = np.flatnonzero((xb < np.asarray(lo) - 1e-9) | (xb > np.asarray(hi) + 1e-9))
        if out.size:
            problems.append(f"{block.label(problem)}: state {int(out[0])} of its block "
                            f"({xb[out[0]]:.4g}) outside [{lo[out[0]]:.4g}, "
                            f"{hi[out[0]]:.4g}]: off the fingertip's surface or past a "
                            "joint limit")
            fields.append(_block_field(m, block))
    if not np.isfinite(closure) or closure > 1e-7:
        problems.append(f"closure not reached (residual {closure:.3g})")
        fields.append("q")
    u = None
    if measured.q_dot is not None or u_guess is not None:
        u = _rates(m, f, prm, x, measured, u_guess, o)
    return StateEstimate(x, u, not problems, tuple(float(s) for s in shift), obj_shift,
                         obj_turn, closure, it, tuple(problems), tuple(fields),
                         tuple(contact_shift))


def _contact_points(measured: Measurement, n: int) -> list[FloatArray | None]:
    """The measured contact locations, one per finger (None: not measured); ValueError
    naming a bad one."""
    raw = measured.contact_points
    if raw is None:
        return [None] * n
    if len(raw) != n:
        raise ValueError(f"contact_points: {len(raw)} given, the grasp has {n} fingers")
    out: list[FloatArray | None] = []
    for i, c in enumerate(raw):
        if c is None:
            out.append(None)
            continue
        a = np.asarray(c, dtype=float).ravel()
        if a.size != 3 or not np.all(np.isfinite(a)):
            raise ValueError(f"contact_points[{i}]: expected a finite point (x, y, z) [m]")
        out.append(a)
    return out


def _block_field(m: GraspModel, block: Any) -> str:
    """The measurement a contact block's state out of its bounds is about: a fingertip's
    joints, else the object's pose."""
    for i, tip in enumerate(m.fingertips):
        if tip is block:
            return f"q[{i}]"
    return "object_position"


def _rates(m: GraspModel, f: _Functions, prm: FloatArray, x: FloatArray,
           measured: Measurement, u_guess: Any, o: EstimateOptions) -> FloatArray:
    """The inputs nearest to the measured rates (else ``u_guess``) with d/dt closure = 0
    (linear in u: one KKT solve)."""
    A, b = (np.asarray(a) for a in f.velocity(x, np.zeros(m.nu), prm))
    ug = np.zeros(m.nu) if u_guess is None else np.asarray(u_guess, dtype=float).ravel()
    rows: list[FloatArray] = []
    jac: list[FloatArray] = []
    if measured.q_dot is not None:
        for tip, qd in zip(m.fingertips, measured.q_dot, strict=True):
            cols = np.arange(m.nu)[tip.qd_cols]
            J = np.zeros((cols.size, m.nu))
            J[np.arange(cols.size), cols] = 1 / o.sigma_qd
            rows.append(-np.asarray(qd, dtype=float).ravel() / o.sigma_qd)
            jac.append(J)
    if measured.object_velocity is not None and measured.object_omega is not None:
        Jt, t0 = (np.asarray(a) for a in f.twist(x, np.zeros(m.nu), prm))
        w = np.array([1 / o.sigma_v] * 3 + [1 / o.sigma_w] * 3)
        meas = np.concatenate([np.asarray(measured.object_velocity, dtype=float),
                               np.asarray(measured.object_omega, dtype=float)])
        rows.append(w * (t0.ravel() - meas))
        jac.append(w[:, None] * Jt)
    # weakly towards the plan's inputs (the contact rates nothing measures directly)
    reg = 1e-3 if rows else 1.0
    rows.append(-reg * ug)
    jac.append(reg * np.eye(m.nu))
    J = np.vstack(jac)
    r = np.concatenate(rows)
    return np.asarray(_kkt(J, r, A, b.ravel(), 1e-12))
