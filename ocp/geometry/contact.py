"""Rolling-contact kinematics between two parameterised surfaces (Montana 1988, 1995).

A contact is between body A and body B (A = palm, B = object; or A = object, B = fingertip).
Its coordinates are ``eta = (alpha_a, alpha_b, psi)``: the chart coordinates of the contact
point on A and on B and the contact angle psi between the two Gauss frames.

Conventions (docs/conventions.md): the contact frames share the point and have opposite
normals, ``R_{c_a c_b} = [[c, -s, 0], [-s, -c, 0], [0, 0, -1]]`` with c = cos psi,
s = sin psi; its upper 2x2 block is the paper's ``R_psi``. The pose of B in A is
``g_ab = g_{a c_a}(alpha_a) (0, R_{c_a c_b}(psi)) g_{b c_b}(alpha_b)^-1``.

In the paper's eq. 3, F is body A and O is body B here.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import casadi as ca

from ocp.geometry.surfaces import Surface

__all__ = [
    "ContactPair",
    "R_contact",
    "R_psi",
    "ball_on_plane_eq8",
    "montana_eq3",
]

#: A CasADi symbolic or numeric matrix (SX, MX or DM); casadi is untyped for mypy.
Sym = Any


def R_psi(psi: Sym) -> Sym:
    """The paper's R_psi = [[c, -s], [-s, -c]] (eq. 3): symmetric and its own inverse."""
    c, s = ca.cos(psi), ca.sin(psi)
    return ca.vertcat(ca.horzcat(c, -s), ca.horzcat(-s, -c))


def R_contact(psi: Sym) -> Sym:
    """R_{c_a c_b}(psi): rotation from B's contact frame to A's (normals opposite)."""
    c, s = ca.cos(psi), ca.sin(psi)
    return ca.vertcat(ca.horzcat(c, -s, 0), ca.horzcat(-s, -c, 0), ca.horzcat(0, 0, -1))


def montana_eq3(
    M_a: Sym, K_a: Sym, T_a: Sym, M_b: Sym, K_b: Sym, T_b: Sym, psi: Sym, omega: Sym
) -> tuple[Sym, Sym, Sym]:
    """Montana's kinematic equations of contact, eq. 3 of the paper (F = A, O = B).

    ``omega = (omega_x, omega_y)`` [rad/s] is the rolling velocity of A relative to B in
    A's local frame. Returns (alpha_a_dot, alpha_b_dot, psi_dot) with
    alpha_a_dot = M_a^-1 (K_a + K~_b)^-1 (-omega_y, omega_x),
    alpha_b_dot = M_b^-1 R_psi (K_a + K~_b)^-1 (-omega_y, omega_x),
    psi_dot = T_a M_a alpha_a_dot + T_b M_b alpha_b_dot, with K~_b = R_psi K_b R_psi.
    """
    Rp = R_psi(psi)
    w = ca.vertcat(-omega[1], omega[0])
    rel = ca.solve(K_a + Rp @ K_b @ Rp, w)
    a_dot = ca.solve(M_a, rel)
    b_dot = ca.solve(M_b, Rp @ rel)
    psi_dot = T_a @ M_a @ a_dot + T_b @ M_b @ b_dot
    return a_dot, b_dot, psi_dot


def ball_on_plane_eq8(eta: Sym, w: Sym, rho: Sym) -> Sym:
    """The paper's eq. 8, typed in as printed: eta_dot = g1(eta) w1 + g2(eta) w2.

    ``eta = (x, y, u, v, psi)`` (palm point, ball latitude/longitude, contact angle),
    ``w = d/dt (x, y)`` [m/s], ``rho`` the ball radius [m]. Kept only as the reference
    the general equations are tested against.
    """
    u, psi = eta[2], eta[4]
    c, s, cu, tu = ca.cos(psi), ca.sin(psi), ca.cos(u), ca.tan(u)
    g1 = ca.vertcat(1, 0, c / rho, -s / (rho * cu), s * tu / rho)
    g2 = ca.vertcat(0, 1, -s / rho, -c / (rho * cu), c * tu / rho)
    return g1 * w[0] + g2 * w[1]


def _solve_metric(M: Sym, v: Sym) -> Sym:
    """alpha_dot (chart rates) with M alpha_dot = v, for a metric M (2x2) [m] and a velocity
    v [m/s]. A diagonal M (off-diagonal entries structurally zero, as the orthogonal charts
    build it) is divided through, an upper triangular one (the general charts') solved by
    back-substitution, any other by ca.solve."""
    if M[0, 1].is_zero() and M[1, 0].is_zero():
        return ca.vertcat(v[0] / M[0, 0], v[1] / M[1, 1])
    if not M[1, 0].is_zero():
        return ca.solve(M, v)
    v_dot = v[1] / M[1, 1]
    return ca.vertcat((v[0] - M[0, 1] * v_dot) / M[0, 0], v_dot)


@dataclass(frozen=True)
class ContactPair:
    """Rolling contact between surface ``a`` (on body A) and surface ``b`` (on body B)."""

    a: Surface
    b: Surface

    def rates_driven_by_a(self, eta: Sym, alpha_a_dot: Sym, params_a: Sym, params_b: Sym
                          ) -> Sym:
        """eta_dot when the contact point moves over A at ``alpha_a_dot`` (no slip, no spin).

        Rolling without slip makes the contact point move equally fast over both surfaces:
        M_b alpha_b_dot = R_psi M_a alpha_a_dot (eq. 3 with the curvature factor cancelled;
        M_b diagonal or upper triangular), and
        psi_dot = T_a M_a alpha_a_dot + T_b M_b alpha_b_dot (eq. 3, third row).
        """
        alpha_a, alpha_b, psi = eta[0:2], eta[2:4], eta[4]
        _, _, M_a, _, T_a = self.a.geometry(alpha_a, params_a)
        _, _, M_b, _, T_b = self.b.geometry(alpha_b, params_b)
        v_b = R_psi(psi) @ (M_a @ alpha_a_dot)
        alpha_b_dot = _solve_metric(M_b, v_b)
        psi_dot = T_a @ M_a @ alpha_a_dot + T_b @ v_b
        return ca.vertcat(alpha_a_dot, alpha_b_dot, psi_dot)

    def rates_driven_by_b(self, eta: Sym, alpha_b_dot: Sym, params_a: Sym, params_b: Sym
                          ) -> Sym:
        """eta_dot when the contact point moves over B at ``alpha_b_dot`` (no slip, no spin)."""
        alpha_a, alpha_b, psi = eta[0:2], eta[2:4], eta[4]
        _, _, M_a, _, T_a = self.a.geometry(alpha_a, params_a)
        _, _, M_b, _, T_b = self.b.geometry(alpha_b, params_b)
        v_a = R_psi(psi) @ (M_b @ alpha_b_dot)
        alpha_a_dot = _solve_metric(M_a, v_a)
        psi_dot = T_a @ v_a + T_b @ M_b @ alpha_b_dot
        return ca.vertcat(alpha_a_dot, alpha_b_dot, psi_dot)

    def rolling_velocity(self, eta: Sym, alpha_a_dot: Sym, params_a: Sym, params_b: Sym
                         ) -> Sym:
        """(omega_x, omega_y) [rad/s] that eq. 3 maps to ``alpha_a_dot``.

        Inverts the first row of eq. 3: (-omega_y, omega_x) = (K_a + K~_b) M_a alpha_a_dot.
        """
        alpha_a, alpha_b, psi = eta[0:2], eta[2:4], eta[4]
        _, _, M_a, K_a, _ = self.a.geometry(alpha_a, params_a)
        _, _, _, K_b, _ = self.b.geometry(alpha_b, params_b)
        Rp = R_psi(psi)
        w = (K_a + Rp @ K_b @ Rp) @ (M_a @ alpha_a_dot)
        return ca.vertcat(w[1], -w[0])

    def pose(self, eta: Sym, params_a: Sym, params_b: Sym, chart_a: Sym, chart_b: Sym
             ) -> tuple[Sym, Sym]:
        """(R_ab, p_ab): pose of body B in body A from the contact coordinates.

        ``chart_a``/``chart_b`` are the 3x3 rotations of each surface's chart patch in its
        body. g_ab = g_{a c_a}(alpha_a) (0, R_{c_a c_b}(psi)) g_{b c_b}(alpha_b)^-1.
        """
        alpha_a, alpha_b, psi = eta[0:2], eta[2:4], eta[4]
        p_a, R_a, _, _, _ = self.a.geometry(alpha_a, params_a)
        p_b, R_b, _, _, _ = self.b.geometry(alpha_b, params_b)
        R_ac = chart_a @ R_a  # A's contact frame in A
        R_bc = chart_b @ R_b  # B's contact frame in B
        R_ab = R_ac @ R_contact(psi) @ R_bc.T
        p_ab = chart_a @ p_a - R_ab @ (chart_b @ p_b)
        return R_ab, p_ab

    def contact_point(self, eta: Sym, params_a: Sym, chart_a: Sym) -> tuple[Sym, Sym]:
        """(p, n): the contact point and A's outward normal there, in body A's frame."""
        p_a, R_a, _, _, _ = self.a.geometry(eta[0:2], params_a)
        return chart_a @ p_a, chart_a @ R_a[:, 2]
