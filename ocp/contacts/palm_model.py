"""The object on a flat palm: the palm/object contact's named CasADi functions for one
object shape (:class:`BallOnPalmModel`, :func:`model_for`: rolling equations, kinematics,
the contact's twist) and the conversions between the palm contact coordinates and the
object's pose (:func:`contact_coordinates`, :func:`object_pose`)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cache

import casadi as ca
import numpy as np
from numpy.typing import ArrayLike, NDArray

from ocp.geometry.contact import ContactPair
from ocp.geometry.surfaces import Plane, Surface, rotation_from_vector
from ocp.shapes import object_surface
from ocp.spec.problem import ObjectSpec

__all__ = ["NU", "NX", "BallOnPalmModel", "contact_coordinates", "model_for", "object_pose"]

FloatArray = NDArray[np.float64]
NX, NU = 5, 2


@dataclass(frozen=True)
class BallOnPalmModel:
    """Named CasADi functions of the palm/object contact for one object shape."""

    surface: Surface
    #: (eta, w, params) -> eta_dot: the rolling equations, eq. 3 / eq. 8.
    dynamics: ca.Function
    #: (eta, w, params, chart) -> (R_po, p_po, contact_point, contact_normal, omega_roll)
    kinematics: ca.Function
    #: (eta, eta_dot, params, chart) -> (v_slip [m/s], omega [rad/s]), from d/dt g_po.
    twist: ca.Function

    @staticmethod
    def build(surface: Surface) -> BallOnPalmModel:
        pair = ContactPair(Plane, surface)
        eta = ca.SX.sym("eta", NX)
        eta_dot = ca.SX.sym("eta_dot", NX)
        w = ca.SX.sym("w", NU)
        params = ca.SX.sym("params", surface.n_params)
        chart = ca.SX.sym("chart", 3, 3)
        none = ca.SX(0, 1)
        eye = ca.SX.eye(3)
        dyn = ca.Function("ball_on_palm_dynamics", [eta, w, params],
                          [pair.rates_driven_by_a(eta, w, none, params)],
                          ["eta", "w", "params"], ["eta_dot"])
        R_po, p_po = pair.pose(eta, none, params, eye, chart)
        cp, cn = pair.contact_point(eta, none, eye)
        omega = pair.rolling_velocity(eta, w, none, params)
        kin = ca.Function("ball_on_palm_kinematics", [eta, w, params, chart],
                          [R_po, p_po, cp, cn, omega],
                          ["eta", "w", "params", "chart"],
                          ["R_po", "p_po", "contact_point", "contact_normal", "omega_roll"])
        # Velocity of the object's material point at the contact, relative to the palm:
        # v = dR/dt p_b + dp/dt with p_b = chart f_b(alpha_b) held fixed in the object.
        R_dot = ca.reshape(ca.jtimes(ca.vec(R_po), eta, eta_dot), 3, 3)
        p_dot = ca.jtimes(p_po, eta, eta_dot)
        p_b = chart @ surface.geometry(eta[2:4], params)[0]
        v_slip = R_dot @ p_b + p_dot
        W = R_dot @ R_po.T
        omega_s = ca.vertcat(W[2, 1], W[0, 2], W[1, 0])
        twist = ca.Function("ball_on_palm_contact_twist", [eta, eta_dot, params, chart],
                            [v_slip, omega_s], ["eta", "eta_dot", "params", "chart"],
                            ["v_slip", "omega"])
        return BallOnPalmModel(surface, dyn, kin, twist)

    @cache  # noqa: B019 - models live for the whole process
    def mapped(self, name: str, m: int) -> ca.Function:
        """The model's function ``name`` (dynamics, kinematics, twist) over m samples."""
        return getattr(self, name).map(m)


@cache
def model_for(surface: str) -> BallOnPalmModel:
    """The (cached) model for an object surface's name (``ObjectSpec.surface.name``:
    "sphere", "ellipsoid", ...)."""
    return BallOnPalmModel.build(object_surface(surface))


def contact_coordinates(obj: ObjectSpec, position_xy: ArrayLike, rotation: ArrayLike
                        ) -> tuple[float, float, float, float, float]:
    """Contact coordinates (x, y, u, v, psi) of the object resting on the palm.

    ``rotation`` is the object's orientation in the palm frame (3x3) and ``position_xy``
    the palm point under it [m]. The inverse of the pose map: the contact point on the
    object is the support point whose outward normal points down the palm normal, (u, v)
    its coordinates in the object's chart, psi the angle between the two contact frames.
    """
    R = np.asarray(rotation, dtype=float).reshape(3, 3)
    surf, params = obj.surface, obj.params
    chart = rotation_from_vector(obj.chart_rotation)
    p_b = surf.support_point(R.T @ np.array([0.0, 0.0, -1.0]), params)
    u, v = surf.inverse(chart.T @ p_b, params)
    _, R_gauss, _, _, _ = surf.geometry([u, v], params)
    R_cc = R @ chart @ np.asarray(R_gauss)  # palm contact frame is the identity
    psi = math.atan2(-R_cc[0, 1], R_cc[0, 0])
    xy = np.asarray(position_xy, dtype=float)
    return (float(xy[0]), float(xy[1]), float(u), float(v), psi)


def object_pose(obj: ObjectSpec, eta: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """(R_po, p_po): the object's pose in the palm frame at contact coordinates ``eta``."""
    model = model_for(obj.surface.name)
    chart = rotation_from_vector(obj.chart_rotation)
    R, p, _, _, _ = model.kinematics(np.asarray(eta, dtype=float), [0.0, 0.0],
                                     list(obj.params), chart)
    return np.asarray(R), np.asarray(p).ravel()
