"""Each fingertip's closure (eq. 6) at the velocity level, in closed form.

The NLP holds every fingertip where its joints put it by asking, at every collocation
point, that the tip frame move as the finger's joints move it and as the rolling contact
moves it (:func:`~ocp.transcription.nlp_blocks.build_manipulation_nlp` says why at the
velocity level). Six rows per fingertip, in the palm frame:

* ``v_fk(c) - v_obj(c)``: the finger's material point at the contact point c, moved by the
  joints (``p_fk_dot + omega_fk x (c - p_fk)``), against the object's material point there
  (``p_po_dot + omega_o x (c - p_po)``): no slip, and no motion along the normal (the
  surfaces stay touching);
* ``omega_fk - (omega_o + omega_rel)``: the tip's angular velocity from its joints against
  the object's plus the rolling one of Montana's equations (eq. 3's first row inverted,
  :meth:`~ocp.geometry.contact.ContactPair.rolling_velocity`, no spin about the normal).

Where the closure holds (c(x) = 0) these rows vanish exactly when d/dt c(x) does along the
dynamics; they are written from the twists instead of differentiating the contact's pose
through the surface's Gauss frame: a fifth of the instructions for the rows' Hessian (the
flat-pad two-finger grasp: 62,787 for d/dt c(x), see ``tests/test_nlp_blocks.py``).
"""

from __future__ import annotations

from typing import Any

import casadi as ca

from ocp.contacts import SymbolicGrasp
from ocp.geometry.rotations import vee

__all__ = ["contact_twists", "finger_twist", "fingertip_twist_rows"]


def finger_twist(finger: Any, q: Any, qd: Any, point: Any) -> tuple[Any, Any]:
    """The velocity of the finger's material point at ``point`` (palm frame) and the
    tip's angular velocity, moved by the joint rates ``qd``: the geometric Jacobian, each
    joint's axis and origin in the palm frame
    (:meth:`~ocp.robots.finger.FingerModel.joint_frames`, the product its ``fk`` takes)."""
    v: Any = ca.SX.zeros(3)
    omega: Any = ca.SX.zeros(3)
    frames, _, _ = finger.joint_frames(q)
    for joint, R, p in frames:
        i = joint.index_q
        axis = R @ ca.DM(joint.axis)  # palm frame
        if joint.kind == "revolute":
            omega = omega + axis * qd[i]
            v = v + ca.cross(axis, point - p) * qd[i]
        else:
            v = v + axis * qd[i]
    return v, omega


def fingertip_twist_rows(m: Any, x: Any, u: Any, prm: Any) -> Any:
    """The 6 rows of every fingertip (``m``: the grasp's
    :class:`~ocp.transcription.grasp_model.GraspModel`, or a phase of it,
    :class:`~ocp.transcription.grasp_model.PhaseModel`: its touching fingertips; ``x``,
    ``u``, ``prm`` in physical units, any expressions): the tip's material velocity at
    the contact point [m/s] from its joints less the one the contact gives it, then its
    angular velocity [rad/s] from its joints less the contact's (:func:`contact_twists`)."""
    xs, us, ps = (ca.SX.sym(n, k) for n, k in (("x", m.nx), ("u", m.nu), ("p", m.n_params)))
    rows = []
    for c, (cp, v_c, omega_c) in zip(m.fingertips, contact_twists(m, xs, us, ps),
                                     strict=True):
        v_fk, omega_fk = finger_twist(c.finger, xs[c.q_cols], us[c.qd_cols], cp)
        rows += [v_fk - v_c, omega_fk - omega_c]
    expr = ca.vertcat(*rows) if rows else ca.SX(0, 1)
    return ca.Function("fingertip_twists", [xs, us, ps], [expr])(x, u, prm)


def contact_twists(m: Any, x: Any, u: Any, prm: Any) -> list[tuple[Any, Any, Any]]:
    """Per fingertip, what its rolling contact makes the tip do (``x``, ``u``, ``prm``
    purely symbolic, physical units): ``(c, v, omega)``, the contact point c in the palm
    frame, the velocity of the tip's material point there (the object's material point's:
    no slip) and the tip's angular velocity (the object's plus Montana's rolling one)."""
    shape, charts = m.unpack_params(prm)
    grasp = getattr(m, "grasp", m)  # a phase's charts are its grasp's, by contact
    chart_of = {id(c): charts[k] for k, c in enumerate(grasp.point_contacts)}
    g = SymbolicGrasp(m.surface, shape, x, m.dynamics(x, u, prm))
    obj = m.object
    g.R_po, g.p_po = obj.pose(g, x[obj.xs], chart_of.get(id(obj), g.eye))
    R_dot, p_dot = g.dot(g.R_po), g.dot(g.p_po)
    omega_o = vee(R_dot @ g.R_po.T)
    out = []
    for c in m.fingertips:
        xb, ub, chart = x[c.xs], u[c.us], chart_of[id(c)]
        point, _ = c.point_normal(g, xb, chart)  # object frame
        eta = c._pair_order(xb[0:5])  # (object point, tip point, psi)
        # (omega_x, omega_y): the object's rolling velocity relative to the tip, in the
        # object's contact frame (A = object in the pair)
        w_xy = c.pair.rolling_velocity(eta, ub[0:2], shape, c.tip_params())
        _, R_a, _, _, _ = c.pair.a.geometry(eta[0:2], shape)
        omega_rel = -g.R_po @ chart @ R_a @ ca.vertcat(w_xy, 0)
        out.append((g.p_po + g.R_po @ point, R_dot @ point + p_dot, omega_o + omega_rel))
    return out
