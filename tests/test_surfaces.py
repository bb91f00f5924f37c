"""Laws of the parameterised surfaces (ocp/geometry/surfaces.py).

Every expected value is a closed form or an independent numpy computation from the chart,
never a number copied from a run. Conventions: docs/conventions.md.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
from helpers import assert_close
from hypothesis import given, settings
from hypothesis import strategies as st

from ocp.geometry.surfaces import (
    Chart,
    Ellipsoid,
    Plane,
    Sphere,
    Surface,
    rotation_from_vector,
    safe_norm,
)

# ---------------------------------------------------------------------------------------
# Tolerances (all explicit). Symbolic derivations evaluated in double precision agree with
# closed forms to a few ulps; 1e-12 relative leaves three orders of margin.
# ---------------------------------------------------------------------------------------
RTOL_EXACT = 1e-12  # closed form vs symbolic derivation (relative)
ATOL_ORTHO = 1e-12  # |R^T R - I|, |det R - 1| (dimensionless)
ATOL_ANGLE = 1e-12  # chart round trip [rad]
# Nested 4th-order central differences: inner step H_INNER on f, outer step on the frame
# H_OUTER * min(a, c) / max(a, c) (the normal of a flat spheroid turns over a latitude range
# ~ min/max, so the step follows it). Round-off ~ eps / (H_INNER * outer step) <= 5e-9,
# truncation ~ (H_OUTER)^4 ~ 1e-12, relative to the size of K and T: 1e-7 relative leaves
# more than an order of magnitude of margin.
H_INNER = 1e-3  # [rad]
H_OUTER = 1e-3  # [rad], times min(a, c) / max(a, c)
RTOL_FD = 1e-7

SETTINGS = settings(max_examples=50, deadline=None)

# Chart latitude well inside the regular part of the latitude/longitude chart.
lat = st.floats(-1.3, 1.3, exclude_min=True, exclude_max=True)
lon = st.floats(-np.pi, np.pi, exclude_min=True, exclude_max=True)
radius = st.floats(0.005, 0.1)  # [m]
semi_axis = st.floats(0.005, 0.1)  # [m]
plane_coord = st.floats(-0.2, 0.2)  # [m]
rotvec = st.tuples(*(st.floats(-4.0, 4.0),) * 3).map(np.array)  # [rad], includes 0


def geometry(surface: Surface, alpha, params) -> dict[str, np.ndarray]:
    """Surface.geometry evaluated numerically, as numpy arrays keyed p, R, M, K, T."""
    out = surface.geometry(np.asarray(alpha, dtype=float), np.asarray(params, dtype=float))
    return {k: np.array(v, dtype=float) for k, v in zip("pRMKT", out, strict=True)}


def assert_proper_rotation(R: np.ndarray, what: str) -> None:
    assert_close(R.T @ R, np.eye(3), atol=ATOL_ORTHO, err_msg=f"{what}: R^T R != I")
    assert_close(np.linalg.det(R), 1.0, atol=ATOL_ORTHO, err_msg=f"{what}: det R != +1")


def wrap_angle(x: np.ndarray | float) -> np.ndarray:
    """x mapped to (-pi, pi]."""
    return np.asarray(np.pi - np.mod(np.pi - np.asarray(x), 2.0 * np.pi))


# Surfaces with their random parameters and chart coordinates, for parametrised laws.
def sphere_case() -> st.SearchStrategy:
    return st.tuples(st.just(Sphere), st.tuples(radius), st.tuples(lat, lon))


def ellipsoid_case() -> st.SearchStrategy:
    return st.tuples(st.just(Ellipsoid), st.tuples(semi_axis, semi_axis), st.tuples(lat, lon))


def plane_case() -> st.SearchStrategy:
    return st.tuples(st.just(Plane), st.just(()), st.tuples(plane_coord, plane_coord))


CASES = {"sphere": sphere_case, "ellipsoid": ellipsoid_case, "plane": plane_case}


# ---------------------------------------------------------------------------------------
# 1. Sphere: symbolic derivation == closed forms of the notes
# ---------------------------------------------------------------------------------------
@SETTINGS
@given(u=lat, v=lon, rho=radius)
def test_sphere_metric_curvature_torsion_match_closed_form(u: float, v: float, rho: float
                                                           ) -> None:
    """M = diag(rho, rho cos u), K = I / rho, T = [0, -tan(u) / rho]."""
    g = geometry(Sphere, [u, v], [rho])
    assert_close(g["M"], np.diag([rho, rho * np.cos(u)]), atol=0.0, rtol=RTOL_EXACT,
                 err_msg="M")
    assert_close(g["K"], np.eye(2) / rho, atol=RTOL_EXACT / rho, rtol=RTOL_EXACT, err_msg="K")
    T_expected = np.array([[0.0, -np.tan(u) / rho]])
    assert_close(g["T"], T_expected, atol=RTOL_EXACT * (1.0 + abs(np.tan(u))) / rho,
                 rtol=RTOL_EXACT, err_msg="T")


@SETTINGS
@given(u=lat, v=lon, rho=radius)
def test_sphere_gauss_frame_is_proper_rotation_with_outward_normal(u: float, v: float,
                                                                   rho: float) -> None:
    """R = [x y z] is in SO(3), z = f / rho (outward), x and y along f_u and f_v."""
    g = geometry(Sphere, [u, v], [rho])
    R, p = g["R"], g["p"].ravel()
    assert_proper_rotation(R, "sphere Gauss frame")
    f = rho * np.array([np.cos(u) * np.cos(v), -np.cos(u) * np.sin(v), np.sin(u)])
    assert_close(p, f, atol=RTOL_EXACT * rho, err_msg="p = f(u, v)")
    assert_close(R[:, 2], f / rho, atol=RTOL_EXACT, err_msg="z = outward normal f / rho")
    f_u = rho * np.array([-np.sin(u) * np.cos(v), np.sin(u) * np.sin(v), np.cos(u)])
    f_v = rho * np.cos(u) * np.array([-np.sin(v), -np.cos(v), 0.0])
    assert_close(R[:, 0], f_u / np.linalg.norm(f_u), atol=RTOL_EXACT, err_msg="x = f_u/|f_u|")
    assert_close(R[:, 1], f_v / np.linalg.norm(f_v), atol=RTOL_EXACT, err_msg="y = f_v/|f_v|")


# ---------------------------------------------------------------------------------------
# 2. Ellipsoid of revolution: symbolic derivation == finite differences of the chart
# ---------------------------------------------------------------------------------------
def _spheroid_chart_np(u: float, v: float, a: float, c: float) -> np.ndarray:
    return np.array([a * np.cos(u) * np.cos(v), -a * np.cos(u) * np.sin(v), c * np.sin(u)])


def _central_diff(fun, x: float, h: float) -> np.ndarray:
    """4th-order central difference d fun / dx (error O(h^4))."""
    return (-fun(x + 2 * h) + 8 * fun(x + h) - 8 * fun(x - h) + fun(x - 2 * h)) / (12 * h)


def _fd_frame(u: float, v: float, a: float, c: float):
    """(x, y, z, |f_u|, |f_v|) from central differences of the chart, in numpy only."""
    f_u = _central_diff(lambda s: _spheroid_chart_np(s, v, a, c), u, H_INNER)
    f_v = _central_diff(lambda s: _spheroid_chart_np(u, s, a, c), v, H_INNER)
    m_u, m_v = np.linalg.norm(f_u), np.linalg.norm(f_v)
    n = np.cross(f_u, f_v)
    return f_u / m_u, f_v / m_v, n / np.linalg.norm(n), m_u, m_v


def _fd_geometry(u: float, v: float, a: float, c: float):
    """(R, M, K, T) of the spheroid chart from finite differences, independent of CasADi."""
    x, y, z, m_u, m_v = _fd_frame(u, v, a, c)
    h = H_OUTER * min(a, c) / max(a, c)
    z_u = _central_diff(lambda s: _fd_frame(s, v, a, c)[2], u, h)
    z_v = _central_diff(lambda s: _fd_frame(u, s, a, c)[2], v, h)
    x_u = _central_diff(lambda s: _fd_frame(s, v, a, c)[0], u, h)
    x_v = _central_diff(lambda s: _fd_frame(u, s, a, c)[0], v, h)
    R = np.column_stack([x, y, z])
    M = np.diag([m_u, m_v])
    K = np.array([[x @ z_u / m_u, x @ z_v / m_v], [y @ z_u / m_u, y @ z_v / m_v]])
    T = np.array([[y @ x_u / m_u, y @ x_v / m_v]])
    return R, M, K, T


@SETTINGS
@given(u=lat, v=lon, a=semi_axis, c=semi_axis)
def test_ellipsoid_geometry_matches_finite_differences_of_chart(u: float, v: float, a: float,
                                                                c: float) -> None:
    """R, M, K, T derived by CasADi equal the same definitions evaluated by finite differences."""
    g = geometry(Ellipsoid, [u, v], [a, c])
    R, M, K, T = _fd_geometry(u, v, a, c)
    scale_m = max(a, c)
    assert_close(g["R"], R, atol=RTOL_FD, err_msg="R")
    assert_close(g["M"], M, atol=RTOL_FD * scale_m, err_msg="M")
    scale_k = float(np.max(np.abs(K)))
    assert_close(g["K"], K, atol=RTOL_FD * scale_k, err_msg="K")
    # T's entries are components of the frame's derivative per unit length, as K's are:
    # its finite-difference error is relative to max(|K|, |T|), not to |T| (T(u=0) = 0).
    scale_t = max(float(np.max(np.abs(T))), scale_k)
    assert_close(g["T"], T, atol=RTOL_FD * scale_t, err_msg="T")


@SETTINGS
@given(u=lat, v=lon, a=semi_axis, c=semi_axis)
def test_spheroid_geometry_matches_principal_curvature_closed_form(u: float, v: float, a: float,
                                                                   c: float) -> None:
    """With q = sqrt(a^2 sin^2 u + c^2 cos^2 u) (u the parametric latitude):
    M = diag(q, a cos u), K = diag(a c / q^3 (meridian), c / (a q) (parallel)),
    T = [0, -tan(u) / q]. Reduces to the sphere's closed forms for a = c."""
    g = geometry(Ellipsoid, [u, v], [a, c])
    q = np.hypot(a * np.sin(u), c * np.cos(u))
    assert_close(g["M"], np.diag([q, a * np.cos(u)]), atol=0.0, rtol=RTOL_EXACT, err_msg="M")
    K = np.diag([a * c / q**3, c / (a * q)])
    assert_close(g["K"], K, atol=RTOL_EXACT * float(np.max(K)), rtol=RTOL_EXACT, err_msg="K")
    T = np.array([[0.0, -np.tan(u) / q]])
    assert_close(g["T"], T, atol=RTOL_EXACT * (1.0 + abs(np.tan(u))) / q, rtol=RTOL_EXACT,
                 err_msg="T")


@SETTINGS
@given(data=st.data(), name=st.sampled_from(sorted(CASES)))
def test_curvature_is_symmetric(data: st.DataObject, name: str) -> None:
    """The Weingarten map in an orthonormal tangent frame is self-adjoint: K = K^T."""
    surface, params, alpha = data.draw(CASES[name]())
    K = geometry(surface, alpha, params)["K"]
    scale = max(float(np.max(np.abs(K))), 1.0)
    assert_close(K, K.T, atol=RTOL_EXACT * scale, err_msg=f"{name}: K != K^T")


@pytest.mark.parametrize(("a", "c"), [(0.03, 0.05), (0.05, 0.03), (0.01, 0.1)])
def test_spheroid_curvature_is_not_isotropic(a: float, c: float) -> None:
    """For a != c the curvature is not a multiple of the identity (at the equator the
    principal curvatures are a / c^2 and 1 / a), so the general derivation is exercised."""
    K = geometry(Ellipsoid, [0.0, 0.7], [a, c])["K"]
    k1, k2 = a / c**2, 1.0 / a
    assert abs(k1 - k2) > 0.1 * max(k1, k2)  # the law is worth checking for these a, c
    assert abs(K[0, 0] - K[1, 1]) > 0.5 * abs(k1 - k2), f"K is isotropic: {K}"


@SETTINGS
@given(data=st.data(), name=st.sampled_from(sorted(CASES)))
def test_chart_is_orthogonal(data: st.DataObject, name: str) -> None:
    """f_u . f_v = 0: the derivation of M, K, T assumes an orthogonal chart."""
    surface, params, alpha = data.draw(CASES[name]())
    val = float(surface.orthogonality(np.asarray(alpha, float), np.asarray(params, float)))
    scale = max([1.0, *params]) ** 2  # [m^2]
    assert_close(val, 0.0, atol=RTOL_EXACT * scale, err_msg=f"{name}: f_u . f_v")


@SETTINGS
@given(data=st.data(), name=st.sampled_from(sorted(CASES)))
def test_gauss_frame_is_proper_rotation(data: st.DataObject, name: str) -> None:
    """R = [x y z] in SO(3) for every shipped surface (right-handed chart, outward normal)."""
    surface, params, alpha = data.draw(CASES[name]())
    assert_proper_rotation(geometry(surface, alpha, params)["R"], name)


@SETTINGS
@given(u=lat, v=lon, a=semi_axis, c=semi_axis)
def test_ellipsoid_normal_is_outward_gradient_of_implicit_equation(u: float, v: float, a: float,
                                                                   c: float) -> None:
    """z is parallel to grad(x^2/a^2 + y^2/a^2 + z^2/c^2) with a positive factor (outward)."""
    g = geometry(Ellipsoid, [u, v], [a, c])
    p = g["p"].ravel()
    grad = p / np.array([a * a, a * a, c * c])
    assert_close(g["R"][:, 2], grad / np.linalg.norm(grad), atol=RTOL_EXACT * 10,
                 err_msg="outward normal")


# ---------------------------------------------------------------------------------------
# 3. Plane
# ---------------------------------------------------------------------------------------
@SETTINGS
@given(x=plane_coord, y=plane_coord)
def test_plane_is_flat_with_identity_metric_and_frame(x: float, y: float) -> None:
    """f = (x, y, 0): M = I, K = 0, T = 0, R = I."""
    g = geometry(Plane, [x, y], [])
    assert_close(g["p"], [x, y, 0.0], atol=0.0, err_msg="p")
    assert_close(g["M"], np.eye(2), atol=0.0, err_msg="M")
    assert_close(g["K"], np.zeros((2, 2)), atol=0.0, err_msg="K")
    assert_close(g["T"], np.zeros((1, 2)), atol=0.0, err_msg="T")
    assert_close(g["R"], np.eye(3), atol=0.0, err_msg="R")


# ---------------------------------------------------------------------------------------
# 4. Chart rotation
# ---------------------------------------------------------------------------------------
@SETTINGS
@given(w=rotvec)
def test_rotation_from_vector_is_proper_rotation_about_its_axis(w: np.ndarray) -> None:
    """exp([w]x) is in SO(3), fixes its axis w, turns by |w| (trace = 1 + 2 cos|w|) and
    exp([-w]x) is its inverse."""
    R = rotation_from_vector(w)
    theta = float(np.linalg.norm(w))
    assert_proper_rotation(R, "rotation_from_vector")
    assert_close(R @ w, w, atol=ATOL_ORTHO * max(theta, 1.0), err_msg="axis is fixed")
    assert_close(np.trace(R), 1.0 + 2.0 * np.cos(theta), atol=ATOL_ORTHO, err_msg="angle")
    assert_close(R @ rotation_from_vector(-w), np.eye(3), atol=ATOL_ORTHO, err_msg="inverse")


@SETTINGS
@given(w=rotvec)
def test_rotation_from_vector_matches_matrix_exponential(w: np.ndarray) -> None:
    """R = exp([w]x), compared with a truncated power series of the exponential."""
    W = np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
    # Scaling and squaring: exp(W) = exp(W / 2^k)^(2^k), series of exp(W / 2^k) to order 20.
    k = 6
    A = W / 2**k
    E, term = np.eye(3), np.eye(3)
    for n in range(1, 21):
        term = term @ A / n
        E = E + term
    for _ in range(k):
        E = E @ E
    assert_close(rotation_from_vector(w), E, atol=1e-12, err_msg="exp([w]x)")


def allowed_rotation(surface: Surface, w: np.ndarray) -> np.ndarray:
    """The drawn rotation vector, kept to the patch rotations the surface allows: any for
    the sphere, about the body z axis for the ellipsoid of revolution and the plane."""
    if surface.chart_rotation_error(rotation_from_vector(w)) is None:
        return w
    return np.array([0.0, 0.0, w[2]])


@SETTINGS
@given(data=st.data(), name=st.sampled_from(sorted(CASES)), w=rotvec)
def test_chart_rotation_rotates_point_and_gauss_frame(data: st.DataObject, name: str,
                                                      w: np.ndarray) -> None:
    """Chart.of(S, params, w).frame(alpha) = (Rc f(alpha), Rc R(alpha)), Rc = exp([w]x)."""
    surface, params, alpha = data.draw(CASES[name]())
    w = allowed_rotation(surface, w)
    g = geometry(surface, alpha, params)
    Rc = rotation_from_vector(w)
    chart = Chart.of(surface, params, w)
    assert_close(chart.R, Rc, atol=0.0, err_msg="Chart.R")
    p, R = chart.frame(alpha)
    scale = max([1.0, *params])
    assert_close(p, Rc @ g["p"].ravel(), atol=RTOL_EXACT * scale, err_msg="rotated point")
    assert_close(R, Rc @ g["R"], atol=RTOL_EXACT, err_msg="rotated Gauss frame")


@SETTINGS
@given(data=st.data(), name=st.sampled_from(sorted(CASES)), w=rotvec)
def test_metric_curvature_torsion_are_invariant_under_chart_rotation(
        data: st.DataObject, name: str, w: np.ndarray) -> None:
    """Deriving the geometry of the rotated chart Rc f gives the same M, K, T (they are
    intrinsic to the patch) and the rotated point and Gauss frame."""
    surface, params, alpha = data.draw(CASES[name]())
    Rc = rotation_from_vector(w)
    Rc_sx = ca.DM(Rc)
    rotated = Surface(f"rotated_{name}", lambda u, v, prm: Rc_sx @ surface.chart_expr(u, v, prm),
                      surface.param_names, surface.periodic, surface.singular_u,
                      surface.coord_names)
    g, gr = geometry(surface, alpha, params), geometry(rotated, alpha, params)
    scale = max([1.0, *params])
    assert_close(gr["p"], Rc @ g["p"], atol=RTOL_EXACT * scale, err_msg="p")
    assert_close(gr["R"], Rc @ g["R"], atol=RTOL_EXACT, err_msg="R")
    assert_close(gr["M"], g["M"], atol=RTOL_EXACT * scale, err_msg="M")
    scale_k = max(float(np.max(np.abs(g["K"]))), 1.0)
    assert_close(gr["K"], g["K"], atol=RTOL_EXACT * scale_k, err_msg="K")
    # the torsion form is of the curvatures' units and derived with them: its rounding is
    # of their size (a zero torsion came out 1.3e-12 beside curvatures of order 30)
    scale_t = max(float(np.max(np.abs(g["T"]))), scale_k)
    assert_close(gr["T"], g["T"], atol=RTOL_EXACT * scale_t, err_msg="T")


@SETTINGS
@given(data=st.data(), name=st.sampled_from(sorted(CASES)), w=rotvec)
def test_chart_inverse_round_trip(data: st.DataObject, name: str, w: np.ndarray) -> None:
    """Chart.inverse(Chart.frame(alpha)[0]) = alpha (v compared modulo 2 pi where periodic)."""
    surface, params, alpha = data.draw(CASES[name]())
    chart = Chart.of(surface, params, allowed_rotation(surface, w))
    back = np.asarray(chart.inverse(chart.frame(alpha)[0]), dtype=float)
    err = back - np.asarray(alpha, dtype=float)
    for i, periodic in enumerate(surface.periodic):
        if periodic:
            err[i] = wrap_angle(err[i])
    # Angles in rad; plane coordinates in m (round-off relative to |p| <= 0.3 m).
    assert_close(err, np.zeros(2), atol=ATOL_ANGLE, err_msg=f"{name}: round trip")


@SETTINGS
@given(data=st.data(), name=st.sampled_from(["ellipsoid", "sphere"]), lat_n=lat, lon_n=lon)
def test_support_point_is_on_surface_with_given_outward_normal(
        data: st.DataObject, name: str, lat_n: float, lon_n: float) -> None:
    """support_point(n) lies on the surface, its outward normal is n and n . p = h(n).

    n is kept off the chart's poles (|latitude| < 1.3) so that the chart can be inverted."""
    surface, params, _ = data.draw(CASES[name]())
    n = np.array([np.cos(lat_n) * np.cos(lon_n), np.cos(lat_n) * np.sin(lon_n), np.sin(lat_n)])
    p = surface.support_point(n, params)
    assert_close(n @ p, surface.support_height(n, params), atol=RTOL_EXACT * max(params),
                 err_msg="n . p = h(n)")
    g = geometry(surface, surface.inverse(p, params), params)
    assert_close(g["p"].ravel(), p, atol=1e-10 * max(params), err_msg="point on surface")
    assert_close(g["R"][:, 2], n, atol=1e-9, err_msg="outward normal = n")


def _assert_chart_matches_support_function(surface: Surface, params, rotvec_, alpha) -> None:
    p, R = Chart.of(surface, params, rotvec_).frame(alpha)
    n = R[:, 2]
    scale = max(params)
    assert_close(surface.support_height(n, params), n @ p, atol=1e-12 * scale,
                 err_msg="support height vs chart point")
    assert_close(surface.support_point(n, params), p, atol=1e-12 * scale,
                 err_msg="support point vs chart point")


@pytest.mark.parametrize(("name", "axis"), [("sphere", None), ("ellipsoid", "z")])
@SETTINGS
@given(data=st.data(), w=rotvec)
def test_chart_rotation_reparameterises_the_same_body_surface(data: st.DataObject, name: str,
                                                              axis: str | None,
                                                              w: np.ndarray) -> None:
    """A chart patch of a body's surface and the body's support function describe the same
    surface: with (p, R) = Chart.frame(alpha) and n = R[:, 2] (outward normal in the body),
    support_height(n) = n . p and support_point(n) = p, whatever the patch's rotation
    (any rotation for the sphere, rotations about the axis of revolution for the spheroid;
    for other rotations of the spheroid see the xfail test below)."""
    surface, params, alpha = data.draw(CASES[name]())
    _assert_chart_matches_support_function(
        surface, params, np.array([0.0, 0.0, w[2]]) if axis == "z" else w, alpha)


def test_ellipsoid_chart_rotated_off_its_axis_is_rejected() -> None:
    """A quarter turn about x would describe a different, rotated ellipsoid (not a patch of
    the body's): Chart.of refuses it and says why; so do the problems that take one."""
    with pytest.raises(ValueError, match="axis of revolution"):
        Chart.of(Ellipsoid, [0.03, 0.05], [np.pi / 2, 0.0, 0.0])
    with pytest.raises(ValueError, match="normal"):
        Chart.of(Plane, [], [0.3, 0.0, 0.0])
    from ocp.spec.problem import BallOnPalmProblem, ObjectSpec

    bad = BallOnPalmProblem(object=ObjectSpec("ellipsoid", (0.03, 0.05), (np.pi / 2, 0, 0)),
                            initial=(0, 0, 0, 0, 0), goal={"x": 0.01}, duration=1.0)
    assert any(f == "object.chart_rotation" and "axis of revolution" in r
               for f, r in bad.errors())


@pytest.mark.parametrize("rotvec", [[0.0, 0.0, 0.7], [np.pi, 0.0, 0.0], [0.0, np.pi, 0.0]])
def test_ellipsoid_chart_turned_about_or_flipping_its_axis_is_the_same_surface(
        rotvec: list[float]) -> None:
    """The rotations the ellipsoid of revolution allows (about its axis, or a half turn
    that swaps its poles) re-parameterise the same body surface."""
    _assert_chart_matches_support_function(Ellipsoid, [0.03, 0.05], rotvec, [0.3, 0.4])


def test_validate_params_rejects_wrong_count_nonpositive_and_nonfinite() -> None:
    """Lengths must be finite and > 0 and there must be one per parameter name."""
    assert Sphere.validate_params([0.03]) == []
    assert Ellipsoid.validate_params([0.03, 0.05]) == []
    assert Plane.validate_params([]) == []
    assert Sphere.validate_params([]) != []
    assert Sphere.validate_params([0.03, 0.04]) != []
    assert Sphere.validate_params([0.0]) != []
    assert Sphere.validate_params([-0.03]) != []
    assert Sphere.validate_params([float("nan")]) != []
    assert Ellipsoid.validate_params([0.03, float("inf")]) != []


# ---------------------------------------------------------------------------------------
# 5. Safe branches at singular points
# ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("u", [np.pi / 2, -np.pi / 2])
@pytest.mark.parametrize("surface_params", [(Sphere, [0.03]), (Ellipsoid, [0.03, 0.05])])
def test_geometry_is_finite_at_chart_pole(u: float, surface_params) -> None:
    """At the pole of the latitude/longitude chart (|f_v| = 0 up to round-off) every output
    of geometry is finite (no NaN/inf), and the point is the pole.

    The Gauss frame there is NOT orthonormal and T is O(1e12) 1/m: the chart is singular and
    safe_norm only keeps the numbers finite (see the report), so only finiteness is a law."""
    surface, params = surface_params
    g = geometry(surface, [u, 0.3], params)
    for key, value in g.items():
        assert np.all(np.isfinite(value)), f"{key} is not finite at the pole: {value}"
    pole = np.array([0.0, 0.0, np.sign(u) * params[-1]])
    assert_close(g["p"].ravel(), pole, atol=1e-15, err_msg="pole")


def test_plane_geometry_is_finite_at_origin() -> None:
    """The palm chart has no singular point: finite (and exact) at the origin."""
    for value in geometry(Plane, [0.0, 0.0], []).values():
        assert np.all(np.isfinite(value))


def test_safe_norm_is_finite_with_finite_gradient_at_zero() -> None:
    """safe_norm(0) and its gradient are finite (norm's gradient is NaN there); elsewhere it
    equals the norm to within its epsilon (1e-15 m)."""
    v = ca.SX.sym("v", 3)
    n = safe_norm(v)
    fun = ca.Function("safe_norm", [v], [n, ca.gradient(n, v), ca.hessian(n, v)[0]])
    val, grad, hess = (np.array(x, dtype=float) for x in fun(np.zeros(3)))
    assert np.all(np.isfinite(val)) and np.all(np.isfinite(grad)) and np.all(np.isfinite(hess))
    assert_close(val, 0.0, atol=1e-15, err_msg="safe_norm(0)")
    assert_close(grad.ravel(), np.zeros(3), atol=0.0, err_msg="gradient at 0")
    w = np.array([3e-3, -4e-3, 1.2e-2])
    val_w, grad_w, _ = (np.array(x, dtype=float) for x in fun(w))
    assert_close(val_w, np.linalg.norm(w), atol=1e-15, err_msg="safe_norm(w) ~ |w|")
    assert_close(grad_w.ravel(), w / np.linalg.norm(w), atol=1e-12, err_msg="gradient ~ w/|w|")


@SETTINGS
@given(u=lat, v=lon, a=semi_axis, c=semi_axis)
def test_closed_form_geometry_equals_the_derivation_from_the_chart(u: float, v: float,
                                                                    a: float, c: float) -> None:
    """The sphere's and the spheroid's closed forms (what every NLP differentiates) are the
    geometry derived symbolically from their charts, to round-off, frame, metric, curvature
    and torsion alike; and they are closed forms: fewer operations than the derivation."""
    for surface, params in ((Sphere, [a]), (Ellipsoid, [a, c])):
        closed = surface.geometry([u, v], params)
        derived = surface.derived_geometry([u, v], params)
        scale = {"p": max(a, c), "R": 1.0, "M": max(a, c), "K": 1.0 / min(a, c) ** 3 * max(a, c)
                 ** 2, "T": 1.0 / (min(a, c) * np.cos(u))}
        for name, x, y in zip("pRMKT", closed, derived, strict=True):
            assert_close(np.array(x, dtype=float), np.array(y, dtype=float),
                         atol=1e-12 * scale[name], err_msg=f"{surface.name} {name}")
        assert surface.geometry.n_instructions() < surface.derived_geometry.n_instructions()


@SETTINGS
@given(a=semi_axis, c=semi_axis, seed=st.integers(0, 2**16))
def test_support_heights_are_support_height_row_by_row(a: float, c: float, seed: int) -> None:
    """The vectorised support function (the certificate's height check over every sample)
    is the scalar one applied to each direction."""
    n = np.random.default_rng(seed).normal(size=(9, 3))
    n /= np.linalg.norm(n, axis=1)[:, None]
    for surface, params in ((Sphere, [a]), (Ellipsoid, [a, c])):
        assert_close(surface.support_heights(n, params),
                     np.array([surface.support_height(row, params) for row in n]),
                     atol=1e-15, err_msg=surface.name)


@SETTINGS
@given(u=lat, v=lon, a=semi_axis, c=semi_axis, seed=st.integers(0, 2**16))
def test_inverse_of_rows_is_the_inverse_of_each_point(u: float, v: float, a: float, c: float,
                                                      seed: int) -> None:
    """Inverse charts take points row by row (the finger guess inverts a whole path at
    once) and give what they give each point alone, which is the chart's preimage."""
    rng = np.random.default_rng(seed)
    alphas = np.column_stack([rng.uniform(-1.3, 1.3, 6), rng.uniform(-3.1, 3.1, 6)])
    alphas[0] = (u, v)
    for surface, params in ((Sphere, [a]), (Ellipsoid, [a, c]), (Plane, [])):
        pts = np.array([np.asarray(surface.geometry(al, params)[0], dtype=float).ravel()
                        for al in alphas])
        rows = surface.inverse(pts, params)
        assert rows.shape == (6, 2)
        assert_close(rows, np.array([surface.inverse(p, params) for p in pts]), atol=0.0)
        assert_close(rows, alphas, atol=1e-9, err_msg=surface.name)
