"""Laws of general (non-orthogonal) charts and of the triaxial ellipsoid
(ocp/geometry/surfaces.py, ocp/geometry/contact.py, ocp/shapes/ellipsoid.py).

The frame-based geometry (x = f_u/|f_u|, z the outward normal, y = z x x, M upper
triangular, K = [x y]^T [z_u z_v] M^-1, T = y^T [x_u x_v] M^-1) is checked against numpy
formulas of the chart and finite differences of its frame; Montana's equations with it
are checked against the physics: the poses rebuilt from integrated contact coordinates
roll without slip or spin and touch with opposite normals. Expected values are closed
forms or independent numpy computations, never numbers copied from a run. Conventions:
docs/conventions.md.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
from helpers import assert_close
from hypothesis import Phase, given, settings
from hypothesis import strategies as st
from test_contact import (
    RTOL_OMEGA,
    RTOL_SLIP,
    RTOL_SPIN,
    T_FINAL,
    Motion,
    _functions,
    geometry,
    rolling_defects,
    vec,
)

from ocp.geometry.contact import ContactPair, R_contact
from ocp.geometry.surfaces import Chart, Ellipsoid, Plane, Sphere, Surface, rotation_from_vector
from ocp.shapes.ellipsoid import TriaxialEllipsoid, TriaxialEllipsoidSurface

# ---------------------------------------------------------------------------------------
# Tolerances (all explicit)
# ---------------------------------------------------------------------------------------
#: Closed forms, identities and two derivations of the same quantity in double precision,
#: relative to the size of the compared quantity (a few ulps, three orders of margin).
RTOL_EXACT = 1e-12
#: Chart round trip [rad].
ATOL_ANGLE = 1e-12
#: Nested 4th-order central differences of the numpy frame, step H_FRAME * min/max of the
#: semi-axes (the normal turns over a latitude range ~ min/max): truncation ~ 1e-12 and
#: round-off ~ eps / step <= 2e-11 relative to the derivatives; 1e-7 leaves a large margin.
H_FRAME = 1e-3  # [rad]
RTOL_FD = 1e-7
#: The rolling laws' tolerances (H_TIME, RTOL_SLIP, RTOL_SPIN, RTOL_OMEGA) and the
#: integrated motions' T_FINAL, N_STEPS and CHECK_FRACTIONS are tests/test_contact.py's.
#: Contact distance travelled over T_FINAL, as a fraction of the smallest semi-axis or
#: radius of the curved surfaces: moves a latitude by at most that many rad.
TRAVEL = 0.3
LAT_START = 0.9  # |u| at the start of a motion: stays below 0.9 + TRAVEL < 1.3

SETTINGS = settings(max_examples=100, deadline=None)
MOTION_SETTINGS = settings(max_examples=40, deadline=None, report_multiple_bugs=False,
                           phases=[Phase.explicit, Phase.reuse, Phase.generate])

lat = st.floats(-1.3, 1.3, exclude_min=True, exclude_max=True)
lon = st.floats(-np.pi, np.pi, exclude_min=True, exclude_max=True)
semi_axis = st.floats(0.01, 0.1)  # [m]
axes3 = st.tuples(semi_axis, semi_axis, semi_axis).map(np.array)
angle = st.floats(-np.pi, np.pi)
rotvec = st.tuples(*(st.floats(-4.0, 4.0),) * 3).map(np.array)
unit_coef = st.floats(-1.0, 1.0)


# ---------------------------------------------------------------------------------------
# The chart in numpy (independent of CasADi)
# ---------------------------------------------------------------------------------------
def chart_np(u: float, v: float, axes: np.ndarray) -> np.ndarray:
    a, b, c = axes
    return np.array([a * np.cos(u) * np.cos(v), -b * np.cos(u) * np.sin(v), c * np.sin(u)])


def chart_derivatives_np(u: float, v: float, axes: np.ndarray
                         ) -> tuple[np.ndarray, np.ndarray]:
    """(f_u, f_v) [m] of the triaxial chart, differentiated by hand."""
    a, b, c = axes
    f_u = np.array([-a * np.sin(u) * np.cos(v), b * np.sin(u) * np.sin(v), c * np.cos(u)])
    f_v = np.array([-a * np.cos(u) * np.sin(v), -b * np.cos(u) * np.cos(v), 0.0])
    return f_u, f_v


def frame_np(u: float, v: float, axes: np.ndarray) -> np.ndarray:
    """[x y z]: x = f_u/|f_u|, z = the normalised gradient of x^2/a^2 + y^2/b^2 + z^2/c^2
    (outward), y = z x x."""
    f_u, _ = chart_derivatives_np(u, v, axes)
    grad = chart_np(u, v, axes) / axes**2
    x = f_u / np.linalg.norm(f_u)
    z = grad / np.linalg.norm(grad)
    return np.column_stack([x, np.cross(z, x), z])


def central_diff(fun, x: float, h: float) -> np.ndarray:
    """4th-order central difference d fun / dx (error O(h^4))."""
    return (-fun(x + 2 * h) + 8 * fun(x + h) - 8 * fun(x - h) + fun(x - 2 * h)) / (12 * h)


# ---------------------------------------------------------------------------------------
# 1. Geometry of the general chart
# ---------------------------------------------------------------------------------------
@SETTINGS
@given(u=lat, v=lon, a=semi_axis, c=semi_axis, derived=st.booleans())
def test_triaxial_with_equal_equatorial_axes_is_the_spheroid(u: float, v: float, a: float,
                                                             c: float, derived: bool) -> None:
    """With a = b the general derivation (and the closed form) give the spheroid's p, R, M,
    K, T (its orthogonal chart): M's off-diagonal entry x.f_v vanishes."""
    g = geometry(TriaxialEllipsoid, [u, v], [a, a, c], derived)
    s = geometry(Ellipsoid, [u, v], [a, c])
    for key in "pRMKT":
        scale = max(float(np.max(np.abs(s[key]))), float(np.max(np.abs(s["K"]))) * (
            key == "T"), 1e-300)
        assert_close(g[key], s[key], atol=RTOL_EXACT * scale, err_msg=key)


@SETTINGS
@given(u=lat, v=lon, axes=axes3)
def test_closed_form_equals_the_general_derivation(u: float, v: float, axes: np.ndarray
                                                   ) -> None:
    """TriaxialEllipsoid.geometry (closed form) = derived_geometry (the chart's derivation)."""
    g = geometry(TriaxialEllipsoid, [u, v], axes)
    d = geometry(TriaxialEllipsoid, [u, v], axes, derived=True)
    scale_k = float(np.max(np.abs(d["K"])))
    for key, scale in (("p", max(axes)), ("R", 1.0), ("M", max(axes)), ("K", scale_k),
                       ("T", max(scale_k, float(np.max(np.abs(d["T"])))))):
        assert_close(g[key], d[key], atol=RTOL_EXACT * scale, err_msg=key)
    assert g["M"][1, 0] == 0.0 and d["M"][1, 0] == 0.0


@SETTINGS
@given(u=lat, v=lon, axes=axes3, derived=st.booleans())
def test_frame_and_metric_of_the_general_chart(u: float, v: float, axes: np.ndarray,
                                               derived: bool) -> None:
    """R is a proper rotation, x = f_u/|f_u|, z the outward normal; M is upper triangular
    with f_u = [x y] M[:, 0] and f_v = [x y] M[:, 1]; p = f(u, v)."""
    g = geometry(TriaxialEllipsoid, [u, v], axes, derived)
    R, M = g["R"], g["M"]
    assert_close(R.T @ R, np.eye(3), atol=RTOL_EXACT, err_msg="R^T R = I")
    assert_close(np.linalg.det(R), 1.0, atol=RTOL_EXACT, err_msg="det R = +1")
    assert_close(R, frame_np(u, v, axes), atol=10 * RTOL_EXACT, err_msg="Gauss frame")
    assert_close(g["p"], chart_np(u, v, axes), atol=RTOL_EXACT * max(axes), err_msg="p")
    assert M[1, 0] == 0.0, f"M is not upper triangular: {M}"
    f_u, f_v = chart_derivatives_np(u, v, axes)
    assert_close(R[:, :2] @ M[:, 0], f_u, atol=RTOL_EXACT * max(axes), err_msg="f_u")
    assert_close(R[:, :2] @ M[:, 1], f_v, atol=RTOL_EXACT * max(axes), err_msg="f_v")


def test_the_triaxial_chart_is_not_orthogonal() -> None:
    """f_u . f_v = (a^2 - b^2) sin u cos u sin v cos v: not zero for a != b, so the general
    form is needed (and M has a nonzero off-diagonal entry x.f_v there)."""
    axes, (u, v) = np.array([0.03, 0.04, 0.05]), (0.6, 0.7)
    val = float(TriaxialEllipsoid.orthogonality([u, v], axes))
    expected = (0.03**2 - 0.04**2) * np.sin(u) * np.cos(u) * np.sin(v) * np.cos(v)
    assert_close(val, expected, atol=RTOL_EXACT * 0.05**2, err_msg="f_u . f_v")
    M = geometry(TriaxialEllipsoid, [u, v], axes)["M"]
    assert abs(M[0, 1]) > 0.05 * abs(M[1, 1]), f"M is nearly diagonal: {M}"
    assert not TriaxialEllipsoid.orthogonal and Ellipsoid.orthogonal and Sphere.orthogonal


@SETTINGS
@given(u=lat, v=lon, axes=axes3, derived=st.booleans())
def test_curvature_is_the_symmetric_shape_operator(u: float, v: float, axes: np.ndarray,
                                                   derived: bool) -> None:
    """K = K^T; det K is the Gaussian curvature 1 / (a^2 b^2 c^2 s^2) and trace K twice
    the mean curvature (a^2 + b^2 + c^2 - |p|^2) / (2 a^2 b^2 c^2 s^(3/2)), with
    s = x^2/a^4 + y^2/b^4 + z^2/c^4 at p = (x, y, z)."""
    g = geometry(TriaxialEllipsoid, [u, v], axes, derived)
    K, p = g["K"], g["p"].ravel()
    scale = float(np.max(np.abs(K)))
    assert_close(K, K.T, atol=RTOL_EXACT * scale, err_msg="K symmetric")
    q = axes**2
    s = float(np.sum(p**2 / q**2))
    abc2 = float(np.prod(q))
    assert_close(np.linalg.det(K), 1.0 / (abc2 * s**2), atol=0.0, rtol=1e-11,
                 err_msg="Gaussian curvature")
    assert_close(np.trace(K), (np.sum(q) - p @ p) / (abc2 * s**1.5), atol=0.0, rtol=1e-11,
                 err_msg="mean curvature")
    assert np.all(np.linalg.eigvalsh(0.5 * (K + K.T)) > 0.0), "convex: K positive definite"


@SETTINGS
@given(u=lat, v=lon, axes=axes3, derived=st.booleans())
def test_frame_derivatives_match_finite_differences(u: float, v: float, axes: np.ndarray,
                                                    derived: bool) -> None:
    """Differentiating the numpy frame by finite differences: z_u = [x y] K M[:, 0],
    z_v = [x y] K M[:, 1] (the normal's rate is K M alpha_dot), y . x_u = (T M)[0] and
    y . x_v = (T M)[1] (y . x_dot = T M alpha_dot), i.e. K = [x y]^T [z_u z_v] M^-1 and
    T = y^T [x_u x_v] M^-1."""
    g = geometry(TriaxialEllipsoid, [u, v], axes, derived)
    R, M, K, T = g["R"], g["M"], g["K"], g["T"]
    h = H_FRAME * min(axes) / max(axes)
    d_u = central_diff(lambda s: frame_np(s, v, axes), u, h)
    d_v = central_diff(lambda s: frame_np(u, s, axes), v, h)
    scale = max(float(np.max(np.abs(K))), float(np.max(np.abs(T)))) * max(axes)
    KM, TM = K @ M, (T @ M).ravel()
    assert_close(d_u[:, 2], R[:, :2] @ KM[:, 0], atol=RTOL_FD * scale, err_msg="z_u")
    assert_close(d_v[:, 2], R[:, :2] @ KM[:, 1], atol=RTOL_FD * scale, err_msg="z_v")
    assert_close(R[:, 1] @ d_u[:, 0], TM[0], atol=RTOL_FD * scale, err_msg="y . x_u")
    assert_close(R[:, 1] @ d_v[:, 0], TM[1], atol=RTOL_FD * scale, err_msg="y . x_v")
    inv_M = np.linalg.inv(M)
    assert_close(R[:, :2].T @ np.column_stack([d_u[:, 2], d_v[:, 2]]) @ inv_M, K,
                 atol=RTOL_FD * scale / min(axes), err_msg="K definition")
    assert_close(R[:, 1] @ np.column_stack([d_u[:, 0], d_v[:, 0]]) @ inv_M, T.ravel(),
                 atol=RTOL_FD * scale / min(axes), err_msg="T definition")


class _DerivedTriaxial(TriaxialEllipsoidSurface):
    """The triaxial ellipsoid without its closed form: its geometry is the derivation's."""

    def closed_form_geometry(self, u: ca.SX, v: ca.SX, params: ca.SX
                             ) -> tuple[ca.SX, ...] | None:
        return None


DerivedTriaxial = _DerivedTriaxial()


def _sheared(surface: Surface, shear: float) -> Surface:
    """The surface in the non-orthogonal chart f(u, v + shear u) (the plane's chart
    (x + shear y, y, 0) instead)."""
    if surface is Plane:
        def chart(u: ca.SX, v: ca.SX, params: ca.SX) -> ca.SX:
            return ca.vertcat(u + shear * v, v, 0)
    else:
        def chart(u: ca.SX, v: ca.SX, params: ca.SX) -> ca.SX:
            return surface.chart_expr(u, v + shear * u, params)
    out = Surface(f"sheared_{surface.name}", chart, surface.param_names, surface.periodic,
                  surface.singular_u, surface.coord_names)
    out.orthogonal = False
    return out


@SETTINGS
@given(u=lat, v=lon, rho=semi_axis, shear=st.floats(-2.0, 2.0))
def test_general_derivation_of_sheared_charts(u: float, v: float, rho: float, shear: float
                                              ) -> None:
    """The same surface in a sheared chart has the same normal and shape operator: the
    plane's chart (x + s y, y, 0) gives R = I, M = [[1, s], [0, 1]], K = 0, T = 0; the
    sphere's chart at (u, v + s u) gives z = f / rho and K = I / rho, with
    f_u = [x y] M[:, 0] and f_v = [x y] M[:, 1]."""
    g = geometry(_sheared(Plane, shear), [u, v], [], derived=True)
    assert_close(g["R"], np.eye(3), atol=RTOL_EXACT, err_msg="plane R")
    assert_close(g["M"], [[1.0, shear], [0.0, 1.0]], atol=RTOL_EXACT, err_msg="plane M")
    assert_close(g["K"], np.zeros((2, 2)), atol=0.0, err_msg="plane K")
    assert_close(g["T"], np.zeros((1, 2)), atol=0.0, err_msg="plane T")
    g = geometry(_sheared(Sphere, shear), [u, v], [rho], derived=True)
    w = v + shear * u
    f = rho * np.array([np.cos(u) * np.cos(w), -np.cos(u) * np.sin(w), np.sin(u)])
    f_lat = rho * np.array([-np.sin(u) * np.cos(w), np.sin(u) * np.sin(w), np.cos(u)])
    f_lon = rho * np.cos(u) * np.array([-np.sin(w), -np.cos(w), 0.0])
    assert_close(g["R"][:, 2], f / rho, atol=RTOL_EXACT, err_msg="sphere normal")
    assert_close(g["K"], np.eye(2) / rho, atol=RTOL_EXACT / rho, err_msg="sphere K")
    assert_close(g["R"][:, :2] @ g["M"][:, 0], f_lat + shear * f_lon, atol=RTOL_EXACT * rho,
                 err_msg="f_u")
    assert_close(g["R"][:, :2] @ g["M"][:, 1], f_lon, atol=RTOL_EXACT * rho, err_msg="f_v")


# ---------------------------------------------------------------------------------------
# 2. Inverse chart, support function, patch rotations
# ---------------------------------------------------------------------------------------
@SETTINGS
@given(us=st.lists(lat, min_size=1, max_size=5), vs=st.lists(lon, min_size=5, max_size=5),
       axes=axes3)
def test_inverse_round_trips_row_by_row(us: list[float], vs: list[float], axes: np.ndarray
                                        ) -> None:
    """inverse(f(u, v)) = (u, v), for one point and for the rows of (k, 3) points."""
    alphas = np.column_stack([us, vs[:len(us)]])
    points = np.array([chart_np(u, v, axes) for u, v in alphas])
    assert_close(TriaxialEllipsoid.inverse(points, axes), alphas, atol=ATOL_ANGLE,
                 err_msg="rows")
    assert_close(TriaxialEllipsoid.inverse(points[0], axes), alphas[0], atol=ATOL_ANGLE,
                 err_msg="one point")


@SETTINGS
@given(d=st.tuples(*(st.floats(-1.0, 1.0),) * 3).map(np.array), axes=axes3)
def test_support_point_and_height(d: np.ndarray, axes: np.ndarray) -> None:
    """The support point of a direction d lies on the surface with outward normal d/|d|,
    and h(n) = n . support_point(n) >= n . p for any surface point p."""
    if np.linalg.norm(d) < 1e-3:
        d = np.array([0.0, 0.0, 1.0])
    n = d / np.linalg.norm(d)
    p = TriaxialEllipsoid.support_point(d, axes)
    assert_close(np.sum(p**2 / axes**2), 1.0, atol=RTOL_EXACT, err_msg="on the surface")
    alpha = TriaxialEllipsoid.inverse(p, axes)
    normal = geometry(TriaxialEllipsoid, alpha, axes)["R"][:, 2]
    assert_close(normal, n, atol=1e-9, err_msg="normal = direction")
    h = TriaxialEllipsoid.support_height(n, axes)
    assert_close(h, n @ p, atol=RTOL_EXACT * max(axes), err_msg="h(n) = n . p")
    u, v = np.meshgrid(np.linspace(-np.pi / 2, np.pi / 2, 41), np.linspace(-np.pi, np.pi, 81))
    samples = np.array([chart_np(a, b, axes) for a, b in zip(u.ravel(), v.ravel(),
                                                            strict=True)])
    assert np.max(samples @ n) <= h * (1 + RTOL_EXACT), "h is the maximum of n . p"
    normals = np.array([n, -n, [1.0, 0.0, 0.0]])
    assert_close(TriaxialEllipsoid.support_heights(normals, axes),
                 [TriaxialEllipsoid.support_height(m, axes) for m in normals],
                 atol=RTOL_EXACT * max(axes), err_msg="support_heights rows")


HALF_TURNS = [np.zeros(3), np.array([np.pi, 0, 0]), np.array([0, np.pi, 0]),
              np.array([0, 0, np.pi])]


@pytest.mark.parametrize("w", HALF_TURNS)
def test_half_turns_about_the_axes_are_patch_rotations(w: np.ndarray) -> None:
    """The identity and the 180-degree turns about x, y, z map the ellipsoid to itself."""
    axes = (0.03, 0.04, 0.05)
    assert TriaxialEllipsoid.chart_rotation_error(rotation_from_vector(w)) is None
    assert TriaxialEllipsoid.chart_rotation_error(rotation_from_vector(w), axes) is None
    assert_close(Chart.of(TriaxialEllipsoid, axes, w).R, rotation_from_vector(w), atol=0.0)


def test_other_rotations_are_not_patch_rotations() -> None:
    """A quarter turn about z is rejected when a != b (and when the semi-axes are not
    given), accepted when a = b (it maps that ellipsoid to itself); a generic rotation is
    rejected; a reflection is not a rotation."""
    quarter = rotation_from_vector([0.0, 0.0, np.pi / 2])
    assert TriaxialEllipsoid.chart_rotation_error(quarter, (0.03, 0.04, 0.05)) is not None
    assert TriaxialEllipsoid.chart_rotation_error(quarter) is not None
    assert TriaxialEllipsoid.chart_rotation_error(quarter, (0.04, 0.04, 0.05)) is None
    with pytest.raises(ValueError, match="maps it to itself"):
        Chart.of(TriaxialEllipsoid, (0.03, 0.04, 0.05), [0.0, 0.0, np.pi / 2])
    Chart.of(TriaxialEllipsoid, (0.04, 0.04, 0.05), [0.0, 0.0, np.pi / 2])
    generic = rotation_from_vector([0.3, -0.2, 0.1])
    assert TriaxialEllipsoid.chart_rotation_error(generic, (0.04, 0.04, 0.04)) is None
    assert TriaxialEllipsoid.chart_rotation_error(generic, (0.04, 0.04, 0.05)) is not None
    assert TriaxialEllipsoid.chart_rotation_error(np.diag([1.0, 1.0, -1.0])) == \
        "not a rotation"


# ---------------------------------------------------------------------------------------
# 3. Montana's equations with the general chart
# ---------------------------------------------------------------------------------------
TIP = (0.012,)  # sphere fingertip radius [m]
OBJECT = (0.03, 0.04, 0.05)  # semi-axes [m]

#: a = body A, b = body B. The ellipsoid rolls on the palm (B general) and under a round
#: fingertip (A general), so both the back-substitution and the division branches run;
#: and on the palm with its derived geometry instead of its closed form.
PAIRS = {
    "palm-triaxial": ContactPair(Plane, TriaxialEllipsoid),
    "palm-triaxial_derived": ContactPair(Plane, DerivedTriaxial),
    "triaxial-sphere_tip": ContactPair(TriaxialEllipsoid, Sphere),
}


def params_of(surface: Surface) -> st.SearchStrategy:
    if surface is Plane:
        return st.just([])
    if surface is Sphere:
        return st.just(list(TIP))
    return st.one_of(st.just(list(OBJECT)), st.tuples(*(st.floats(0.02, 0.06),) * 3).map(
        list))


def coords_of(surface: Surface, latitude: st.SearchStrategy) -> st.SearchStrategy:
    if surface is Plane:
        return st.tuples(st.floats(-0.05, 0.05), st.floats(-0.05, 0.05)).map(list)
    return st.tuples(latitude, angle).map(list)


def state_of(pair: ContactPair, latitude: st.SearchStrategy = lat) -> st.SearchStrategy:
    """(eta, params_a, params_b)."""
    return st.tuples(coords_of(pair.a, latitude), coords_of(pair.b, latitude), angle,
                     params_of(pair.a), params_of(pair.b)).map(
        lambda t: (np.array([*t[0], *t[1], t[2]]), t[3], t[4]))


velocity = st.tuples(st.floats(-1.0, 1.0), st.floats(-1.0, 1.0)).map(
    lambda w: np.round(np.array(w), 9))


def _rates_scale(pair: ContactPair, eta, rates, params_a, params_b) -> np.ndarray:
    """Per-component size of the rates' terms, for relative comparisons."""
    ga, gb = geometry(pair.a, eta[0:2], params_a), geometry(pair.b, eta[2:4], params_b)
    speed = max(float(np.linalg.norm(ga["M"] @ rates[0:2])),
                float(np.linalg.norm(gb["M"] @ rates[2:4])))
    a_scale = speed * np.sum(np.abs(np.linalg.inv(ga["M"])), axis=1)
    b_scale = speed * np.sum(np.abs(np.linalg.inv(gb["M"])), axis=1)
    psi_scale = speed * (np.sum(np.abs(ga["T"])) + np.sum(np.abs(gb["T"])))
    return np.concatenate([a_scale, b_scale, [psi_scale]]) + 1e-200


@pytest.mark.parametrize("name", sorted(PAIRS))
@SETTINGS
@given(data=st.data(), w=velocity)
def test_eq3_rates_and_their_inverse_agree(data: st.DataObject, name: str, w: np.ndarray
                                           ) -> None:
    """Eq. 3 (ca.solve with the upper triangular M) fed with rolling_velocity(alpha_a_dot)
    returns rates_driven_by_a's rates; rates_driven_by_b with their alpha_b_dot gives them
    back; evaluated on numbers (DM metrics) they are the same."""
    pair = PAIRS[name]
    eta, params_a, params_b = data.draw(state_of(pair))
    f = _functions(pair)
    rates = vec(f["a"](eta, w, params_a, params_b))
    scale = _rates_scale(pair, eta, rates, params_a, params_b)
    assert_close(vec(f["eq3"](eta, w, params_a, params_b)), rates, atol=1e-10 * scale,
                 err_msg="eq. 3 vs rates")
    assert_close(vec(f["b"](eta, rates[2:4], params_a, params_b)), rates,
                 atol=1e-11 * scale, err_msg="driven by b vs a")
    numeric = vec(pair.rates_driven_by_a(ca.DM(eta), ca.DM(w), ca.DM(params_a),
                                         ca.DM(params_b)))
    assert_close(numeric, rates, atol=RTOL_EXACT * scale, err_msg="DM vs SX")


def _min_curvature(surface: Surface, params: list[float]) -> float:
    """A lower bound of the principal curvatures [1/m]: 0 for the plane, a_min / a_max^2
    for an ellipsoid (1/rho for a sphere)."""
    return 0.0 if surface is Plane else min(params) / max(params) ** 2


def _amplitude(pair: ContactPair, drive: str, params_a: list[float], params_b: list[float]
               ) -> float:
    """Input amplitude such that the contact travels at most TRAVEL times the smallest
    semi-axis or radius over T_FINAL (|input| <= 1.43 amp): each latitude then moves by at
    most TRAVEL rad (the map p -> (x/a, y/b, z/c) to the unit sphere stretches lengths
    by at most 1 / a_min)."""
    reach = TRAVEL * min(min(p) for p in (params_a, params_b) if p)
    if drive == "eq3":  # speed <= |omega| / (smallest eigenvalue of K_a + K~_b)
        gain = 1.0 / (_min_curvature(pair.a, params_a) + _min_curvature(pair.b, params_b))
    else:  # speed = |M alpha_dot| <= sqrt(2) a_max |alpha_dot| (1 for the palm)
        driven = params_b if drive == "b" else params_a
        gain = np.sqrt(2.0) * max(driven) if driven else 1.0
    return reach / (1.43 * T_FINAL * gain)


@st.composite
def motions(draw, name: str, drive: str) -> tuple[Motion, np.ndarray]:
    pair = PAIRS[name]
    eta0, params_a, params_b = draw(state_of(pair, st.floats(-LAT_START, LAT_START)))
    theta = draw(angle)
    coef0 = draw(st.floats(0.5, 1.0)) * np.array([np.cos(theta), np.sin(theta)])
    coef12 = 0.15 * np.array([[draw(unit_coef), draw(unit_coef)] for _ in range(2)])
    motion = Motion(pair, drive, params_a, params_b, rotation_from_vector(draw(rotvec)),
                    rotation_from_vector(draw(rotvec)), np.vstack([coef0, coef12]),
                    _amplitude(pair, drive, params_a, params_b))
    return motion, eta0


def _curved_latitudes(pair: ContactPair, eta: np.ndarray) -> list[float]:
    return [abs(float(eta[i])) for i, s in ((0, pair.a), (2, pair.b)) if s is not Plane]


MOTION_CASES = [(name, drive) for name in sorted(PAIRS) for drive in ("a", "b", "eq3")]


@pytest.mark.parametrize(("name", "drive"), MOTION_CASES)
@MOTION_SETTINGS
@given(data=st.data())
def test_integrated_motion_rolls_without_slip_or_spin(data: st.DataObject, name: str,
                                                      drive: str) -> None:
    """Along motions integrated with rates_driven_by_a, rates_driven_by_b or montana_eq3
    (random charts on both bodies): B's material contact point has zero velocity relative
    to A, the relative angular velocity has no component along A's normal, and it is the
    rolling velocity the motion is driven with (eq. 3's omega, or rolling_velocity of
    alpha_a_dot)."""
    motion, eta0 = data.draw(motions(name, drive))
    for t, eta in motion.integrate(eta0):
        assert max(_curved_latitudes(motion.pair, eta)) < 1.3, "left the chart's regular part"
        d = rolling_defects(motion, t, eta)
        assert np.isfinite(d.slip) and d.slip <= RTOL_SLIP, f"slip at t={t}: {d}"
        assert np.isfinite(d.spin) and d.spin <= RTOL_SPIN, f"spin at t={t}: {d}"
        omega = motion.omega(t, eta)
        assert_close(d.omega, omega, atol=RTOL_OMEGA * float(np.linalg.norm(omega)),
                     err_msg=f"rolling velocity at t={t}")


@pytest.mark.parametrize(("name", "drive"), MOTION_CASES)
@MOTION_SETTINGS
@given(data=st.data())
def test_integrated_contact_points_coincide_with_opposite_normals(data: st.DataObject,
                                                                  name: str, drive: str
                                                                  ) -> None:
    """B's contact point mapped into A is A's, on both surfaces; B's normal mapped into A
    is minus A's; B's contact frame is A's turned by R_contact(psi)."""
    motion, eta0 = data.draw(motions(name, drive))
    pair, f = motion.pair, _functions(motion.pair)
    scale = max([0.1, *motion.params_a, *motion.params_b])
    for _, eta in motion.integrate(eta0):
        R_ab, p_ab = motion.pose(eta)
        ga = geometry(pair.a, eta[0:2], motion.params_a)
        gb = geometry(pair.b, eta[2:4], motion.params_b)
        p_c, n_c = (vec(x) for x in f["contact"](eta, motion.params_a, motion.chart_a))
        assert_close(p_c, motion.chart_a @ ga["p"].ravel(), atol=RTOL_EXACT * scale,
                     err_msg="contact point on A")
        assert_close(R_ab @ motion.chart_b @ gb["p"].ravel() + p_ab, p_c,
                     atol=RTOL_EXACT * scale, err_msg="B's contact point maps onto A's")
        assert_close(R_ab @ motion.chart_b @ gb["R"][:, 2], -n_c, atol=RTOL_EXACT,
                     err_msg="normals opposite")
        assert_close((motion.chart_a @ ga["R"]).T @ R_ab @ motion.chart_b @ gb["R"],
                     np.array(R_contact(eta[4])), atol=RTOL_EXACT, err_msg="contact frames")
        for surface, alpha, params in ((pair.a, eta[0:2], motion.params_a),
                                       (pair.b, eta[2:4], motion.params_b)):
            if isinstance(surface, TriaxialEllipsoidSurface):
                p = geometry(surface, alpha, params)["p"].ravel()
                assert_close(np.sum(p**2 / np.asarray(params) ** 2), 1.0, atol=RTOL_EXACT,
                             err_msg="on the ellipsoid")


def test_dividing_by_the_diagonal_of_a_general_metric_slips() -> None:
    """Negative control: the orthogonal charts' alpha_b_dot = v_b / diag(M_b), applied to
    the triaxial ellipsoid on the palm where x.f_v is not small, slips (the check of
    test_integrated_motion_rolls_without_slip_or_spin sees it)."""
    pair = PAIRS["palm-triaxial"]
    coef = np.array([[0.8, 0.3], [0.0, 0.0], [0.0, 0.0]])
    eta0 = np.array([0.0, 0.0, 0.6, 0.7, 0.2])
    for drive, slips in (("diagonal", True), ("a", False)):
        motion = Motion(pair, drive, [], list(OBJECT), np.eye(3), np.eye(3), coef,
                        _amplitude(pair, drive, [], list(OBJECT)))
        d = rolling_defects(motion, 0.0, eta0)
        assert (d.slip > 1e3 * RTOL_SLIP) == slips, f"{drive}: {d}"
