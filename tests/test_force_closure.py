"""Laws of the generalised grasp angle and force closure (ocp/geometry/force_closure.py).

Force closure (Murray, Li & Sastry 1994, ch. 5, sections 5.2-5.3): G onto and an internal
force strictly inside the friction cones. Phi* = min over internal forces of the largest
angle between a contact force and the inward normal; force closure iff G onto and
Phi* < atan(mu). Two contacts: Phi* = max(Phi_1, Phi_2) of the paper (ocp/geometry/grasp.py).
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np
import pytest
from helpers import assert_close
from hypothesis import given, settings
from hypothesis import strategies as st

import ocp.geometry.force_closure as fc
from ocp.geometry.force_closure import (
    PUSH_FLOOR,
    GraspQuality,
    grasp_matrix,
    grasp_qualities,
    grasp_quality,
    internal_force_residuals,
)
from ocp.geometry.grasp import grasp_angles_numeric

SETTINGS = settings(max_examples=40, deadline=None)

# ---------------------------------------------------------------------------------------
# Tolerances (all explicit)
# ---------------------------------------------------------------------------------------
#: Closed-form formulas compared with each other (acos of the same cosines).
ATOL_FORMULA = 1e-12


def acos_conditioning(angle: float) -> float:
    """Round-off of an angle computed as acos of a cosine with round-off ~1e-15: acos
    amplifies it by 1 / sin(angle), at most to sqrt(2e-15) at 0 and pi."""
    return min(1e-15 / max(math.sin(angle), 1e-300), math.sqrt(2e-15))

#: Phi* of the NLP (IPOPT tol 1e-9 on s = 1 - cos Phi*; near Phi* = 0, Phi* ~ sqrt(2 s),
#: so a 1e-9 error on s is ~5e-5 on the angle; away from 0 it is ~1e-9/sin Phi*).
ATOL_ANGLE = 1e-6
ATOL_ANGLE_AT_ZERO = 1e-4
#: The floor PUSH_FLOOR on each contact's push makes the NLP's Phi* an upper bound that can
#: exceed the infimum by O(PUSH_FLOOR) rad when the infimum unloads a contact (measured up
#: to 2.6 PUSH_FLOOR on random 3-4 contact grasps of a sphere and an ellipsoid); a force
#: found by sampling may beat it by that much, no more.
ATOL_FLOOR = 5 * PUSH_FLOOR
#: Equilibrium of the witness (projected on ker G by construction), relative to |f| ~ 1.
ATOL_EQUILIBRIUM = 1e-10


# ---------------------------------------------------------------------------------------
# Strategies and helpers
# ---------------------------------------------------------------------------------------

def unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


vec3 = st.tuples(*[st.floats(-1.0, 1.0, allow_nan=False)] * 3).map(np.array)
unit3 = vec3.filter(lambda v: np.linalg.norm(v) > 0.2).map(unit)
seeds = st.integers(0, 2**32 - 1)


def sphere_contacts(rng: np.random.Generator, n: int, radius: float = 0.03,
                    centre: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """n contacts at random on a sphere: points, outward normals."""
    nrm = unit(rng.normal(size=(n, 3)))
    c = np.zeros(3) if centre is None else centre
    return c + radius * nrm, nrm


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    w, x, y, z = unit(rng.normal(size=4))
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def max_angles(forces: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """(s,) largest angle between f_i and -n_i of s force sets (s, n, 3)."""
    push = -np.sum(normals * forces, axis=-1)
    c = push / np.linalg.norm(forces, axis=-1)
    return np.arccos(np.clip(c, -1.0, 1.0)).max(axis=-1)


def null_basis(points: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """Orthonormal basis (3n, m) of the internal forces of hard contacts (ker G)."""
    G = grasp_matrix(points - points.mean(axis=0), normals, "hard", 0.03)
    _, sv, Vt = np.linalg.svd(G)
    rank = int(np.sum(sv > 1e-10))
    return Vt[rank:].T


def cap_contacts(rng: np.random.Generator, n: int, alpha: float
                 ) -> tuple[np.ndarray, np.ndarray]:
    """n contacts at random on a unit sphere, within alpha of the +z pole."""
    cos_t = rng.uniform(math.cos(alpha), 1.0, size=n)
    phi = rng.uniform(0.0, 2 * math.pi, size=n)
    sin_t = np.sqrt(1.0 - cos_t**2)
    nrm = np.stack([sin_t * np.cos(phi), sin_t * np.sin(phi), cos_t], axis=1)
    return nrm.copy(), nrm


# ---------------------------------------------------------------------------------------
# Two contacts: the paper's grasp angles
# ---------------------------------------------------------------------------------------

@SETTINGS
@given(u1=unit3, u2=unit3, axes=st.tuples(*[st.floats(0.005, 0.05)] * 3), shift=vec3)
def test_two_contacts_on_a_convex_object_is_the_papers_max_phi(u1, u2, axes, shift):
    """On an ellipsoid (convex) Phi_1 + Phi_2 <= pi, and Phi* = max(Phi_1, Phi_2) exactly,
    with the witness along the line of the contacts and the contact angles (Phi_1, Phi_2)."""
    a = np.array(axes)
    p = np.stack([a * u1, a * u2]) + 0.1 * shift
    nrm = unit(np.stack([u1 / a, u2 / a]))         # gradient of |x/a|^2
    if np.linalg.norm(p[1] - p[0]) < 1e-4:
        return
    phi1, phi2 = grasp_angles_numeric(p[0], nrm[0], p[1], nrm[1])
    g = grasp_quality(p, nrm)
    # both are acos of cosines with round-off ~1e-15: conditioning 1e-15 / sin(angle)
    # (Hypothesis found contact angles of 8e-7 rad that differ by 1.3e-10)
    tol = [ATOL_FORMULA + acos_conditioning(a) for a in (phi1, phi2)]
    assert_close(g.angle, max(phi1, phi2), max(tol))
    assert_close(g.contact_angles, [phi1, phi2], np.array(tol))
    assert g.feasible == (max(phi1, phi2) < math.pi / 2)
    if g.feasible:
        d = unit(p[1] - p[0])
        assert_close(unit(g.forces[0]), d, 1e-12)
        assert_close(g.forces[0] + g.forces[1], np.zeros(3), 1e-15)
        assert_close(-np.sum(nrm * g.forces), 1.0, 1e-12)
    for mu in (0.1, 0.5, 1.0, 3.0):
        assert g.force_closure(mu) == (g.rank_ok and max(phi1, phi2) < math.atan(mu))
        assert_close(g.margin(mu), math.atan(mu) - max(phi1, phi2), max(tol))


@SETTINGS
@given(p1=vec3, p2=vec3, n1=unit3, n2=unit3)
def test_two_arbitrary_contacts_take_the_better_sign(p1, p2, n1, n2):
    """Any two contacts: the internal forces are +-(d, -d); Phi* is the better sign's."""
    if np.linalg.norm(p2 - p1) < 1e-3:
        return
    phi1, phi2 = grasp_angles_numeric(p1, n1, p2, n2)
    g = grasp_quality(np.stack([p1, p2]), np.stack([n1, n2]))
    expected = min(max(phi1, phi2), math.pi - min(phi1, phi2))
    # Both sides are acos of a cosine with round-off ~1e-15; acos amplifies it by
    # 1 / sin(angle), at most to sqrt(2e-15) at 0 and pi (Hypothesis found a pair with the
    # normals along the line of the contacts: 3.14159264 against pi)
    assert_close(g.angle, expected, ATOL_FORMULA + acos_conditioning(expected))
    assert g.feasible == (g.angle < math.pi / 2)


@pytest.mark.parametrize("seed", range(3))
def test_numeric_solver_agrees_with_the_two_contact_closed_form(seed):
    """The NLP (used for n >= 3) run on pairs of sphere contacts gives the paper's angle."""
    rng = np.random.default_rng(seed)
    pts, nrms = zip(*[sphere_contacts(rng, 2) for _ in range(30)], strict=True)
    P, N = np.stack(pts), np.stack(nrms)
    numeric = fc._solve_numeric(P, N)
    for j in range(len(P)):
        phi = max(grasp_angles_numeric(P[j, 0], N[j, 0], P[j, 1], N[j, 1]))
        assert numeric[j].solver_ok
        assert_close(numeric[j].angle, phi, ATOL_ANGLE_AT_ZERO if phi < 0.01 else ATOL_ANGLE)


def test_coincident_contacts_bisect_the_normals():
    """Two contacts at one point: internal forces (f, -f); best f bisects -n_1 and n_2."""
    n1, n2 = unit(np.array([1.0, 0.2, 0.0])), unit(np.array([-1.0, 0.5, 0.3]))
    p = np.zeros((2, 3))
    g = grasp_quality(p, np.stack([n1, n2]))
    half = 0.5 * math.acos(float(np.dot(-n1, n2)))
    assert_close(g.angle, half, ATOL_FORMULA)
    assert not g.rank_ok


# ---------------------------------------------------------------------------------------
# Known grasps
# ---------------------------------------------------------------------------------------

@pytest.mark.parametrize("n", [3, 4, 5])
def test_contacts_evenly_on_an_equator_push_to_the_centre(n):
    """n contacts evenly on a great circle: the inward normals are an internal force, so
    Phi* = 0 and the grasp is force closure for any mu > 0."""
    t = 2 * math.pi * np.arange(n) / n
    nrm = np.stack([np.cos(t), np.sin(t), np.zeros(n)], axis=1)
    g = grasp_quality(0.02 * nrm + [0.1, 0.0, 0.05], nrm)
    assert_close(g.angle, 0.0, ATOL_ANGLE_AT_ZERO)
    assert_close(g.forces, -nrm / n, ATOL_ANGLE_AT_ZERO)
    assert g.rank_ok and g.feasible and g.force_closure(0.01)


@pytest.mark.parametrize("alpha", [0.05, 0.2, 0.5])
def test_equilateral_contacts_on_a_cap_only_squeeze_in_their_plane(alpha):
    """Three contacts on a circle at polar angle alpha: internal forces of three contacts
    lie in their plane, so Phi* = pi/2 - alpha (a squeeze toward the circle's centre):
    never force closure for mu <= cot(alpha)."""
    t = 2 * math.pi * np.arange(3) / 3
    nrm = np.stack([math.sin(alpha) * np.cos(t), math.sin(alpha) * np.sin(t),
                    np.full(3, math.cos(alpha))], axis=1)
    g = grasp_quality(0.03 * nrm, nrm)
    assert_close(g.angle, math.pi / 2 - alpha, ATOL_ANGLE)
    assert g.feasible
    assert not g.force_closure(0.99 / math.tan(alpha))
    assert g.force_closure(1.01 / math.tan(alpha))


@SETTINGS
@given(seed=seeds, n=st.integers(3, 5), alpha=st.floats(0.01, 0.6))
def test_contacts_within_a_cap_have_a_grasp_angle_near_pi_over_2(seed, n, alpha):
    """Normals within alpha of one axis z: for an internal force sum_i f_i . z = 0, so
    sum_i push_i = sum_i f_i . (z - n_i) <= 2 sin(alpha/2) sum_i |f_i|, hence
    cos Phi* <= 2 sin(alpha/2): no contacts on one small cap make a force-closure grasp."""
    P, N = cap_contacts(np.random.default_rng(seed), n, alpha)
    g = grasp_quality(P, N)
    c = 2 * math.sin(alpha / 2)                     # < 1 for alpha < pi/3
    assert g.angle >= math.acos(c) - ATOL_ANGLE
    assert not g.force_closure(0.99 * math.sqrt(1 - c * c) / c)   # mu < tan(acos c)


@pytest.mark.parametrize("beta", [0.1, 0.3, 0.7])
def test_an_unloaded_contact_does_not_count(beta):
    """Antipodal contacts on the x axis and a third at (0, 1, 0) whose normal is tilted by
    beta out of the plane z = 0. Contacts 1, 2 give no moment about x; contact 3's moment
    about x is f3_z, so an internal force has f3_z = 0 and contact 3's angle is >= beta:
    Phi* = beta. (Letting f3 = 0 would give 0: the cone condition needs f3 strictly inside
    its cone, and the grasp cannot make a positive moment about x when mu < tan beta.)"""
    P = np.array([[-1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]) * 0.03
    N = np.array([[-1.0, 0.0, 0.0], [1.0, 0.0, 0.0],
                  [0.0, math.cos(beta), math.sin(beta)]])
    g = grasp_quality(P, N)
    assert_close(g.angle, beta, ATOL_FLOOR)
    assert g.angle >= beta - ATOL_ANGLE
    assert not g.force_closure(math.tan(beta) * 0.99)
    assert g.force_closure(math.tan(beta) * 1.01 + ATOL_FLOOR)


def test_contacts_on_a_flat_face_are_infeasible():
    """Coplanar contacts with one normal: every internal force is tangent (push 0), so no
    pushing internal force exists: flagged, Phi* = pi/2, no NaN."""
    P = np.array([[0.0, 0.0, 0.0], [0.02, 0.0, 0.0], [0.0, 0.03, 0.0], [0.01, 0.01, 0.0]])
    N = np.tile([0.0, 0.0, 1.0], (4, 1))
    for n in (3, 4):
        g = grasp_quality(P[:n], N[:n])
        assert not g.feasible and not g.force_closure(10.0)
        assert g.angle >= math.pi / 2
        assert np.all(np.isfinite(g.contact_angles)) and np.all(np.isfinite(g.forces))


def test_pinwheel_normals_have_no_pushing_internal_force():
    """Three contacts in the plane z = 0 (a scalene triangle, so the field is not a rigid
    rotation), normals tilted along the counter-clockwise tangent t_i about the centroid:
    an internal force lies in the plane, a positive push needs f_i . t_i < 0 at every
    contact, and then the moment about z, sum_i r_i f_i . t_i, cannot vanish."""
    P = np.array([[0.03, 0.0, 0.0], [-0.01, 0.02, 0.0], [-0.015, -0.035, 0.0]])
    c = P.mean(axis=0)
    t = unit(np.cross([0.0, 0.0, 1.0], P - c))
    N = unit(np.array([0.0, 0.0, 1.0]) + 0.3 * t)
    g = grasp_quality(P, N)
    assert not g.feasible
    assert g.angle >= math.pi / 2
    assert np.all(np.isfinite(g.contact_angles))


def test_one_contact_is_never_force_closure():
    g = grasp_quality([[0.0, 0.0, 0.03]], [[0.0, 0.0, 1.0]])
    assert not g.rank_ok and not g.feasible and not g.force_closure(100.0)
    assert g.angle == math.pi / 2


# ---------------------------------------------------------------------------------------
# Invariance
# ---------------------------------------------------------------------------------------

@SETTINGS
@given(seed=seeds, n=st.integers(2, 4))
def test_phi_star_is_invariant_under_rigid_motions_scaling_and_permutations(seed, n):
    rng = np.random.default_rng(seed)
    P, N = sphere_contacts(rng, n, radius=0.03, centre=rng.normal(size=3) * 0.1)
    R = random_rotation(rng)
    perm = rng.permutation(n)
    P2 = (2.5 * (P @ R.T) + rng.normal(size=3))[perm]
    N2 = (N @ R.T)[perm]
    g1, g2 = grasp_qualities(np.stack([P, P2]), np.stack([N, N2]))
    tol = ATOL_ANGLE_AT_ZERO if g1.angle < 0.01 else ATOL_ANGLE
    assert_close(g2.angle, g1.angle, tol)
    assert_close(g2.sigma_min, g1.sigma_min, 1e-9)
    assert g1.rank_ok == g2.rank_ok and g1.feasible == g2.feasible


# ---------------------------------------------------------------------------------------
# The witness and optimality
# ---------------------------------------------------------------------------------------

@pytest.mark.parametrize("n", [3, 4])
def test_witness_is_an_internal_force_within_the_grasp_angle(n):
    rng = np.random.default_rng(10 + n)
    pts, nrms = zip(*[sphere_contacts(rng, n) for _ in range(40)], strict=True)
    P, N = np.stack(pts), np.stack(nrms)
    for j, g in enumerate(grasp_qualities(P, N)):
        assert g.solver_ok and g.feasible
        G = grasp_matrix(P[j], N[j], "hard", 0.03)
        assert_close(G @ g.forces.ravel(), np.zeros(6), ATOL_EQUILIBRIUM)
        assert_close(-np.sum(N[j] * g.forces), 1.0, 1e-12)
        assert np.all(g.contact_angles <= g.angle + ATOL_FORMULA)
        cosines = -np.sum(N[j] * g.forces, axis=1) / np.linalg.norm(g.forces, axis=1)
        assert_close(np.cos(g.contact_angles), cosines, ATOL_FORMULA)
        assert_close(np.max(g.contact_angles), g.angle, 0.0)


@pytest.mark.parametrize("n", [3, 4])
def test_no_sampled_internal_force_beats_phi_star(n):
    """Brute force: random internal forces (Gaussian in ker G, both signs), and random
    perturbations of the witness inside ker G, never have a smaller largest angle."""
    rng = np.random.default_rng(20 + n)
    for _ in range(12):
        P, N = sphere_contacts(rng, n)
        g = grasp_quality(P, N)
        B = null_basis(P, N)
        f = (rng.normal(size=(20000, B.shape[1])) @ B.T).reshape(-1, n, 3)
        assert max_angles(f, N).min() >= g.angle - ATOL_FLOOR
        w = g.forces.ravel() / np.linalg.norm(g.forces)
        for scale in (1e-1, 1e-2, 1e-3):
            d = rng.normal(size=(5000, B.shape[1])) @ B.T
            near = (w + scale * d).reshape(-1, n, 3)
            assert max_angles(near, N).min() >= g.angle - ATOL_FLOOR


@pytest.mark.parametrize("seed", range(4))
def test_three_contacts_phi_star_equals_a_global_search(seed):
    """n = 3: ker G is 3-dimensional, so the internal forces are the directions of a
    2-sphere; a dense search (grid, then three zooms) finds Phi* from both sides."""
    rng = np.random.default_rng(30 + seed)
    P, N = sphere_contacts(rng, 3)
    g = grasp_quality(P, N)
    B = null_basis(P, N)
    assert B.shape[1] == 3
    u = unit(rng.normal(size=(200000, 3)))
    best = u[np.argmin(max_angles((u @ B.T).reshape(-1, 3, 3), N))]
    for radius in (0.05, 0.005, 0.0005):
        cand = unit(best + radius * rng.normal(size=(50000, 3)))
        cand = np.vstack([best, cand])
        best = cand[np.argmin(max_angles((cand @ B.T).reshape(-1, 3, 3), N))]
    found = float(max_angles((best @ B.T).reshape(1, 3, 3), N)[0])
    assert found >= g.angle - ATOL_FLOOR
    assert found <= g.angle + 1e-4


# ---------------------------------------------------------------------------------------
# Symbolic residuals (the planner's constraints)
# ---------------------------------------------------------------------------------------

@pytest.mark.parametrize("sym", [ca.SX, ca.MX])
@pytest.mark.parametrize("n", [2, 3, 4])
def test_symbolic_residuals_at_the_witness(sym, n):
    """At n * witness (the NLP's normalisation sum push = n): equilibrium 0, the pushes sum
    to n, each push is at least the floor and cos(Phi*) times the norm."""
    rng = np.random.default_rng(40 + n)
    P, N = sphere_contacts(rng, n, radius=0.03, centre=np.array([0.1, -0.2, 0.05]))
    g = grasp_quality(P, N)
    p, nn, f = sym.sym("p", 3, n), sym.sym("n", 3, n), sym.sym("f", 3, n)
    eq, push, norms = internal_force_residuals(p, nn, f, 0.03)
    fun = ca.Function("r", [p, nn, f], [eq, push, norms])
    e, pu, no = (np.asarray(x).ravel() for x in fun(P.T, N.T, n * g.forces.T))
    assert_close(e, np.zeros(6), ATOL_EQUILIBRIUM * n)
    assert_close(np.sum(pu), float(n), 1e-12)
    assert_close(no, np.linalg.norm(n * g.forces, axis=1), 1e-12)
    assert np.all(pu >= math.cos(g.angle) * no - 1e-12)
    if n >= 3:
        assert np.all(pu >= PUSH_FLOOR * (1 - 1e-6))


def test_symbolic_equilibrium_is_the_scaled_wrench():
    """A non-internal force: equilibrium = (sum f, sum (p - c) x f / L), push = -n . f."""
    rng = np.random.default_rng(5)
    P, N = sphere_contacts(rng, 3)
    F = rng.normal(size=(3, 3))
    p, nn, f = ca.SX.sym("p", 3, 3), ca.SX.sym("n", 3, 3), ca.SX.sym("f", 3, 3)
    eq, push, _ = internal_force_residuals(p, nn, f, 0.5)
    e, pu = (np.asarray(x).ravel()
             for x in ca.Function("e", [p, nn, f], [eq, push])(P.T, N.T, F.T))
    c = P.mean(axis=0)
    assert_close(e[:3], F.sum(axis=0), 1e-14)
    assert_close(e[3:], np.cross(P - c, F).sum(axis=0) / 0.5, 1e-14)
    assert_close(pu, -np.sum(N * F, axis=1), 1e-15)


# ---------------------------------------------------------------------------------------
# Grasp map
# ---------------------------------------------------------------------------------------

@SETTINGS
@given(seed=seeds, n=st.integers(1, 4), model=st.sampled_from(["hard", "soft"]))
def test_grasp_matrix_maps_contact_forces_to_the_wrench(seed, n, model):
    rng = np.random.default_rng(seed)
    P, N = sphere_contacts(rng, n)
    F = rng.normal(size=(n, 3))
    m = rng.normal(size=n)
    G = grasp_matrix(P, N, model, 0.03)
    x = np.hstack([F, m[:, None] / 0.03]).ravel() if model == "soft" else F.ravel()
    torque = np.cross(P, F).sum(axis=0) + (N * m[:, None]).sum(axis=0) * (model == "soft")
    assert G.shape == (6, (4 if model == "soft" else 3) * n)
    assert_close(G @ x, np.concatenate([F.sum(axis=0), torque / 0.03]), 1e-12)


@SETTINGS
@given(seed=seeds)
def test_two_distinct_soft_contacts_are_onto(seed):
    P, N = sphere_contacts(np.random.default_rng(seed), 2)
    if np.linalg.norm(P[1] - P[0]) < 1e-3:
        return
    assert grasp_quality(P, N).rank_ok
    assert np.linalg.matrix_rank(grasp_matrix(P, N, "hard")) == 5


def test_two_soft_contacts_with_normals_across_their_line_are_not_onto():
    """Torsions about normals perpendicular to the contact line give no moment about it."""
    P = np.array([[0.0, 0.0, 0.0], [0.05, 0.0, 0.0]])
    N = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0]])
    g = grasp_quality(P, N)
    assert not g.rank_ok and not g.force_closure(10.0)
    assert g.sigma_min < 1e-12


def test_three_collinear_hard_contacts_are_not_onto():
    P = np.array([[0.0, 0.0, 0.0], [0.01, 0.0, 0.0], [0.03, 0.0, 0.0]])
    N = unit(np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.3], [0.0, -1.0, -0.4]]))
    g = grasp_quality(P, N)
    assert np.linalg.matrix_rank(grasp_matrix(P, N, "hard")) == 5
    assert not g.rank_ok and not g.force_closure(10.0)
    assert np.isfinite(g.angle)
    # the witness is still an internal force
    assert_close(grasp_matrix(P, N, "hard", 0.03) @ g.forces.ravel(), np.zeros(6),
                 ATOL_EQUILIBRIUM)


# ---------------------------------------------------------------------------------------
# Batching
# ---------------------------------------------------------------------------------------

def test_a_batch_is_one_solver_call_and_equals_single_solves(monkeypatch):
    rng = np.random.default_rng(7)
    pts, nrms = zip(*[sphere_contacts(rng, 3) for _ in range(37)], strict=True)
    P, N = np.stack(pts), np.stack(nrms)
    # a flat face (no pushing internal force) in the middle of the batch
    P[5] = [[0.0, 0.0, 0.0], [0.02, 0.0, 0.0], [0.0, 0.03, 0.0]]
    N[5] = [[0.0, 0.0, 1.0]] * 3
    built = fc._batch_solver
    calls: list[tuple[str, int]] = []

    def counting(n: int, m: int, k: int, phase: str, warm: bool = False):
        solver = built(n, m, k, phase, warm)

        def call(**kw):
            calls.append((phase, k))
            return solver(**kw)
        call.stats = solver.stats  # type: ignore[attr-defined]
        return call

    monkeypatch.setattr(fc, "_batch_solver", counting)
    batch = grasp_qualities(P, N)
    # one LP and one NLP call for the whole batch (these grasps need no second pass)
    assert [phase for phase, _ in calls] == ["push", "angle"]
    assert all(k >= len(P) for _, k in calls)
    assert all(g.solver_ok for g in batch)
    monkeypatch.undo()
    assert not batch[5].feasible and batch[5].angle >= math.pi / 2
    for j in (0, 5, 17, 36):
        single = grasp_quality(P[j], N[j])
        assert isinstance(single, GraspQuality)
        assert_close(batch[j].angle, single.angle, ATOL_ANGLE)
        assert batch[j].feasible == single.feasible


def test_blocks_left_behind_by_the_batch_are_solved_again(monkeypatch):
    """With a batch too short to converge (3 iterations), the warm chunks and the single
    solves must still bring every block to a KKT point, with the same Phi*."""
    rng = np.random.default_rng(8)
    axes = np.array([0.03, 0.03, 0.018])                # an ellipsoid of revolution
    u = unit(rng.normal(size=(70, 3, 3)))
    P, N = axes * u, unit(u / axes)
    reference = grasp_qualities(P, N)
    fc._batch_solver.cache_clear()
    monkeypatch.setattr(fc, "_MAX_ITER_BATCH", 3)
    try:
        again = grasp_qualities(P, N)
    finally:
        fc._batch_solver.cache_clear()
    for g, h in zip(reference, again, strict=True):
        assert g.solver_ok and h.solver_ok
        assert_close(h.angle, g.angle, ATOL_ANGLE)


def test_input_validation():
    with pytest.raises(ValueError):
        grasp_qualities(np.zeros((2, 3, 3)), np.zeros((2, 3, 3)))      # zero normals
    with pytest.raises(ValueError):
        grasp_qualities(np.zeros((2, 3, 3)), np.ones((2, 2, 3)))
    assert grasp_qualities(np.zeros((0, 3, 3)), np.ones((0, 3, 3))) == []


def test_grasp_angles_of_rows_are_the_grasp_angles_of_each_grasp() -> None:
    """The grasp angles of k grasps at once (the planners' reports and guesses) are those of
    each grasp alone."""
    rng = np.random.default_rng(5)
    P1, P2 = rng.normal(size=(8, 3)), rng.normal(size=(8, 3))
    N1, N2 = (a / np.linalg.norm(a, axis=1)[:, None] for a in rng.normal(size=(2, 8, 3)))
    rows = grasp_angles_numeric(P1, N1, P2, N2)
    assert rows.shape == (8, 2)
    for i in range(8):
        assert_close(rows[i], np.array(grasp_angles_numeric(P1[i], N1[i], P2[i], N2[i])),
                     atol=1e-15)
