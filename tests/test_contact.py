"""Laws of the rolling-contact kinematics (ocp/geometry/contact.py).

The central test integrates the contact coordinates with the rate equations and checks the
physics on the rebuilt poses by finite differences in time, independently of the planner:
no slip, no separation, no spin, and the two surfaces touch with opposite normals.
Conventions: docs/conventions.md.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache

import casadi as ca
import numpy as np
import pytest
from helpers import assert_close
from hypothesis import Phase, given, settings
from hypothesis import strategies as st

from ocp.geometry.contact import ContactPair, R_contact, R_psi, ball_on_plane_eq8, montana_eq3
from ocp.geometry.surfaces import Ellipsoid, Plane, Sphere, Surface, rotation_from_vector

SETTINGS = settings(max_examples=50, deadline=None)
#: For the integrated motions: no shrinking. A failing motion is reported as found (its
#: draws are printed); shrinking some 20 floats through an integration would take
#: Hypothesis's full shrink budget (minutes) per failing test.
MOTION_SETTINGS = settings(max_examples=50, deadline=None, report_multiple_bugs=False,
                           phases=[Phase.explicit, Phase.reuse, Phase.generate])

# ---------------------------------------------------------------------------------------
# Tolerances (all explicit)
# ---------------------------------------------------------------------------------------
#: Two algebraically equal formulas in double precision, relative to the sum of the
#: absolute values of the terms they add (so that cancellation cannot fake a pass).
RTOL_SAME_FORMULA = 1e-12
#: Formulas that differ by linear solves (eq. 3 against the rate form).
RTOL_SOLVE = 1e-10
#: Rates driven by A, then by B with A's alpha_b_dot: two chains of the same formulas.
RTOL_ROUND_TRIP = 1e-11
#: |R^T R - I| etc. for 3x3 rotations built from cos/sin.
ATOL_ORTHO = 1e-14
#: Time step of the (4th-order) central differences of the pose [s]. Relative rotation
#: rates w are at most O(10) rad/s here, so truncation ~ (h w)^4 / 30 < 1e-10; round-off
#: ~ 1.5 eps |p| / h ~ 1e-13 m/s (|p| <= 0.3 m) against speeds >= 3e-5 m/s: < 1e-8.
H_TIME = 1e-4
#: Slip and separation speed of B's material contact point, relative to the rolling speed,
#: and spin rate about the normal, relative to the rolling angular speed.
RTOL_SLIP = 1e-6
RTOL_SPIN = 1e-6
#: Rolling velocity against the measured relative angular velocity, relative to its size.
RTOL_OMEGA = 1e-6
#: Touching (contact point and normals), an identity up to round-off: relative to lengths.
RTOL_TOUCH = 1e-12
#: Duration of the integrated motions [s] and RK4 steps over it.
T_FINAL = 0.5
N_STEPS = 50
#: Times at which the laws are checked, as fractions of T_FINAL.
CHECK_FRACTIONS = (0.0, 0.37, 1.0)

# ---------------------------------------------------------------------------------------
# Random states
# ---------------------------------------------------------------------------------------
LAT_START = 1.0  # |u| at the start; the motions below move it by < 0.26 rad (< 1.3)
lat0 = st.floats(-LAT_START, LAT_START)
lat = st.floats(-1.3, 1.3, exclude_min=True, exclude_max=True)
angle = st.floats(-np.pi, np.pi)
length = st.floats(0.005, 0.1)  # radius or semi-axis [m]
palm_coord = st.floats(-0.05, 0.05)  # [m]
rotvec = st.tuples(*(st.floats(-4.0, 4.0),) * 3).map(np.array)
unit_coef = st.floats(-1.0, 1.0)


def params_of(surface: Surface) -> st.SearchStrategy:
    return st.tuples(*(length,) * surface.n_params).map(list)


def coords_of(surface: Surface, latitude: st.SearchStrategy = lat) -> st.SearchStrategy:
    if surface is Plane:
        return st.tuples(palm_coord, palm_coord).map(list)
    return st.tuples(latitude, angle).map(list)


def state_of(a: Surface, b: Surface, latitude: st.SearchStrategy = lat) -> st.SearchStrategy:
    """(eta, params_a, params_b): eta = (alpha_a, alpha_b, psi)."""
    return st.tuples(coords_of(a, latitude), coords_of(b, latitude), angle, params_of(a),
                     params_of(b)).map(lambda t: (np.array([*t[0], *t[1], t[2]]), t[3], t[4]))


#: Chart velocities; rounded to 1e-9 so that no subnormal numbers (which underflow in any
#: relative comparison) are drawn.
velocity = st.tuples(st.floats(-1.0, 1.0), st.floats(-1.0, 1.0)).map(
    lambda w: np.round(np.array(w), 9))


def geometry(surface: Surface, alpha, params, derived: bool = False) -> dict[str, np.ndarray]:
    """Surface.geometry (or derived_geometry) evaluated, as numpy arrays keyed p, R, M, K, T."""
    fun = surface.derived_geometry if derived else surface.geometry
    out = fun(np.asarray(alpha, dtype=float), np.asarray(params, dtype=float))
    return {k: np.array(v, dtype=float) for k, v in zip("pRMKT", out, strict=True)}


def vec(x) -> np.ndarray:
    return np.array(x, dtype=float).ravel()


def vee(W: np.ndarray) -> np.ndarray:
    """w from a 3x3 matrix whose skew part is [w]x."""
    return 0.5 * np.array([W[2, 1] - W[1, 2], W[0, 2] - W[2, 0], W[1, 0] - W[0, 1]])


# Pairs whose surfaces are not both flat (a flat pair cannot roll). a = body A, b = body B.
PAIRS = {
    "palm-sphere": ContactPair(Plane, Sphere),
    "palm-ellipsoid": ContactPair(Plane, Ellipsoid),
    "object_sphere-flat_fingertip": ContactPair(Sphere, Plane),
    "ellipsoid-sphere": ContactPair(Ellipsoid, Sphere),
}


# ---------------------------------------------------------------------------------------
# 6. Eq. 8 of the paper (ball on flat palm)
# ---------------------------------------------------------------------------------------
@SETTINGS
@given(state=state_of(Plane, Sphere), w=velocity)
def test_palm_sphere_rates_equal_paper_eq8(state, w: np.ndarray) -> None:
    """ContactPair(Plane, Sphere).rates_driven_by_a(eta, w) = g1(eta) w1 + g2(eta) w2."""
    eta, _, params_b = state
    w = 0.1 * w  # [m/s]
    pair = PAIRS["palm-sphere"]
    rho = params_b[0]
    actual = vec(pair.rates_driven_by_a(eta, w, [], params_b))
    expected = vec(ball_on_plane_eq8(eta, w, rho))
    # Scale: |g1 w1| + |g2 w2| element by element (no cancellation can hide an error), plus
    # the natural size |w| (1 + |tan u|) / (rho cos u) of the angular rates: a term that is
    # zero in closed form (e.g. T_b[0] = 0) is round-off of that size in the derivation.
    u = eta[2]
    w1 = float(np.sum(np.abs(w)))
    floor = np.array([w1, w1, *[w1 * (1 + abs(np.tan(u))) / (rho * np.cos(u))] * 3])
    scale = (np.abs(vec(ball_on_plane_eq8(eta, [w[0], 0.0], rho)))
             + np.abs(vec(ball_on_plane_eq8(eta, [0.0, w[1]], rho))) + floor)
    assert_close(actual, expected, atol=RTOL_SAME_FORMULA * scale, err_msg="eq. 8")


# ---------------------------------------------------------------------------------------
# 7. Montana's eq. 3 against the rate form
# ---------------------------------------------------------------------------------------
def _eq3_scale(pair: ContactPair, eta, rates, params_a, params_b) -> np.ndarray:
    """Per-component size of the terms of the rates (for relative comparisons)."""
    ga, gb = geometry(pair.a, eta[0:2], params_a), geometry(pair.b, eta[2:4], params_b)
    va = np.abs(ga["M"] @ rates[0:2])
    vb = np.abs(gb["M"] @ rates[2:4])
    speed = max(float(np.linalg.norm(va)), float(np.linalg.norm(vb)))
    a_scale = speed / np.diag(ga["M"])
    b_scale = speed / np.diag(gb["M"])
    psi_scale = speed * (np.sum(np.abs(ga["T"])) + np.sum(np.abs(gb["T"])))
    # + a floor far below any physical rate: near a zero torsion (latitude 1e-323 rad, which
    # Hypothesis finds) the rates are subnormal numbers, with few significant bits
    return np.concatenate([a_scale, b_scale, [psi_scale]]) + 1e-200


@SETTINGS
@given(data=st.data(), name=st.sampled_from(sorted(PAIRS)), w=velocity)
def test_montana_eq3_with_rolling_velocity_gives_the_rates(data: st.DataObject, name: str,
                                                           w: np.ndarray) -> None:
    """omega = rolling_velocity(eta, alpha_a_dot) fed to eq. 3 returns the same
    (alpha_a_dot, alpha_b_dot, psi_dot) as rates_driven_by_a."""
    pair = PAIRS[name]
    eta, params_a, params_b = data.draw(state_of(pair.a, pair.b))
    f = _functions(pair)
    rates = vec(f["a"](eta, w, params_a, params_b))
    eq3 = vec(f["eq3"](eta, w, params_a, params_b))
    scale = _eq3_scale(pair, eta, rates, params_a, params_b)
    assert_close(eq3, rates, atol=RTOL_SOLVE * scale, err_msg="eq. 3 vs rates")


@SETTINGS
@given(data=st.data(), name=st.sampled_from(sorted(PAIRS)), w=velocity)
def test_rates_driven_by_b_invert_rates_driven_by_a(data: st.DataObject, name: str,
                                                    w: np.ndarray) -> None:
    """Driving B with the alpha_b_dot that driving A produced gives back the same eta_dot."""
    pair = PAIRS[name]
    eta, params_a, params_b = data.draw(state_of(pair.a, pair.b))
    f = _functions(pair)
    from_a = vec(f["a"](eta, w, params_a, params_b))
    from_b = vec(f["b"](eta, from_a[2:4], params_a, params_b))
    scale = _eq3_scale(pair, eta, from_a, params_a, params_b)
    assert_close(from_b, from_a, atol=RTOL_ROUND_TRIP * scale, err_msg="driven by b vs a")


# ---------------------------------------------------------------------------------------
# 8. The contact rotation
# ---------------------------------------------------------------------------------------
@SETTINGS
@given(psi=st.floats(-10.0, 10.0))
def test_R_contact_is_symmetric_involutive_proper_rotation_with_R_psi_block(psi: float
                                                                            ) -> None:
    """R_contact(psi) = R^T = R^-1, det = +1, flips the normal, upper block = R_psi."""
    R = np.array(R_contact(psi), dtype=float)
    assert_close(R, R.T, atol=0.0, err_msg="symmetric")
    assert_close(R.T @ R, np.eye(3), atol=ATOL_ORTHO, err_msg="orthogonal")
    assert_close(R @ R, np.eye(3), atol=ATOL_ORTHO, err_msg="own inverse")
    assert_close(np.linalg.det(R), 1.0, atol=ATOL_ORTHO, err_msg="det = +1 (a rotation)")
    assert_close(R @ [0.0, 0.0, 1.0], [0.0, 0.0, -1.0], atol=0.0, err_msg="normals opposite")
    Rp = np.array(R_psi(psi), dtype=float)
    assert_close(R[:2, :2], Rp, atol=0.0, err_msg="2x2 block = R_psi")
    c, s = np.cos(psi), np.sin(psi)
    assert_close(Rp, [[c, -s], [-s, -c]], atol=0.0, err_msg="R_psi as in eq. 3")


# ---------------------------------------------------------------------------------------
# 9. The physical law: integrate the rates, rebuild the poses, differentiate in time
# ---------------------------------------------------------------------------------------
@cache
def _functions(pair: ContactPair) -> dict[str, ca.Function]:
    """Numeric CasADi functions of the pair (built once per pair)."""
    eta = ca.SX.sym("eta", 5)
    d = ca.SX.sym("d", 2)
    pa = ca.SX.sym("pa", pair.a.n_params)
    pb = ca.SX.sym("pb", pair.b.n_params)
    Ca = ca.SX.sym("Ca", 3, 3)
    Cb = ca.SX.sym("Cb", 3, 3)
    R_ab, p_ab = pair.pose(eta, pa, pb, Ca, Cb)
    p_c, n_c = pair.contact_point(eta, pa, Ca)
    # Eq. 3 fed with omega = rolling_velocity(eta, d): (alpha_a_dot, alpha_b_dot, psi_dot).
    _, _, M_a, K_a, T_a = pair.a.geometry(eta[0:2], pa)
    _, _, M_b, K_b, T_b = pair.b.geometry(eta[2:4], pb)
    eq3 = montana_eq3(M_a, K_a, T_a, M_b, K_b, T_b, eta[4],
                      pair.rolling_velocity(eta, d, pa, pb))
    return {
        "eq3": ca.Function("eq3", [eta, d, pa, pb], [ca.vertcat(*eq3)]),
        "a": ca.Function("a", [eta, d, pa, pb], [pair.rates_driven_by_a(eta, d, pa, pb)]),
        "b": ca.Function("b", [eta, d, pa, pb], [pair.rates_driven_by_b(eta, d, pa, pb)]),
        "omega": ca.Function("omega", [eta, d, pa, pb],
                             [pair.rolling_velocity(eta, d, pa, pb)]),
        "pose": ca.Function("pose", [eta, pa, pb, Ca, Cb], [R_ab, p_ab]),
        "contact": ca.Function("contact", [eta, pa, Ca], [p_c, n_c]),
    }


@cache
def _stepper(pair: ContactPair, drive: str) -> dict[str, ca.Function]:
    """The rates of a driven motion, the rolling velocity it is driven with, one classical
    Runge-Kutta step of the rates and N_STEPS steps, as CasADi functions of x = (eta, t),
    dt, the input coefficients, amplitude, shape parameters and the negative-control errors
    err = (psi_dot_error, slip_error). (Also used by tests/test_general_charts.py and
    tests/test_shapes.py.)

    input(t) = amp (coef[0] + coef[1] sin 3t + coef[2] cos 5t) is alpha_a_dot for drive
    "a" (rates_driven_by_a) and "diagonal" (the orthogonal charts' division by M_b's
    diagonal: a negative control), alpha_b_dot for "b" (rates_driven_by_b), and the
    rolling velocity (omega_x, omega_y) [rad/s] for "eq3" (montana_eq3). "omega" is the
    rolling velocity the motion is driven with. err[0] adds err[0] |omega| to psi_dot (a
    spin about the normal); err[1] adds err[1] * rolling speed / |f_u| of B to
    alpha_b_dot[0] (slip)."""
    eta = ca.SX.sym("eta", 5)
    t = ca.SX.sym("t")
    dt = ca.SX.sym("dt")
    coef = ca.SX.sym("coef", 3, 2)
    amp = ca.SX.sym("amp")
    pa = ca.SX.sym("pa", pair.a.n_params)
    pb = ca.SX.sym("pb", pair.b.n_params)
    err = ca.SX.sym("err", 2)

    def drive_input(time: ca.SX) -> ca.SX:
        return amp * (coef[0, :] + coef[1, :] * ca.sin(3 * time)
                      + coef[2, :] * ca.cos(5 * time)).T

    def driven_rates(e: ca.SX, d: ca.SX) -> ca.SX:
        if drive == "a":
            return pair.rates_driven_by_a(e, d, pa, pb)
        if drive == "b":
            return pair.rates_driven_by_b(e, d, pa, pb)
        _, _, M_a, K_a, T_a = pair.a.geometry(e[0:2], pa)
        _, _, M_b, K_b, T_b = pair.b.geometry(e[2:4], pb)
        if drive == "eq3":
            return ca.vertcat(*montana_eq3(M_a, K_a, T_a, M_b, K_b, T_b, e[4], d))
        assert drive == "diagonal", drive
        v_b = R_psi(e[4]) @ (M_a @ d)
        return ca.vertcat(d, v_b[0] / M_b[0, 0], v_b[1] / M_b[1, 1],
                          T_a @ M_a @ d + T_b @ v_b)

    def rates(e: ca.SX, time: ca.SX) -> ca.SX:
        e_dot = driven_rates(e, drive_input(time))
        a_dot = e_dot[0:2]
        omega = pair.rolling_velocity(e, a_dot, pa, pb)
        _, _, M_a, _, _ = pair.a.geometry(e[0:2], pa)
        _, _, M_b, _, _ = pair.b.geometry(e[2:4], pb)
        speed = ca.norm_2(M_a @ a_dot)
        return ca.vertcat(e_dot[0:2], e_dot[2] + err[1] * speed / M_b[0, 0], e_dot[3],
                          e_dot[4] + err[0] * ca.norm_2(omega))

    k1 = rates(eta, t)
    omega = drive_input(t) if drive == "eq3" else pair.rolling_velocity(eta, k1[0:2], pa, pb)
    k2 = rates(eta + dt / 2 * k1, t + dt / 2)
    k3 = rates(eta + dt / 2 * k2, t + dt / 2)
    k4 = rates(eta + dt * k3, t + dt)
    x = ca.vertcat(eta, t)
    x_next = ca.vertcat(eta + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4), t + dt)
    args = [coef, amp, pa, pb, err]
    step = ca.Function("step", [x, dt, *args], [x_next])
    return {
        "rates": ca.Function("rates", [x, *args], [k1]),
        "omega": ca.Function("omega", [x, *args], [omega]),
        "step": step,
        "trajectory": step.mapaccum("trajectory", N_STEPS),
    }


@dataclass(frozen=True)
class Motion:
    """A rolling motion: pair, the drive (see _stepper), parameters, charts and its smooth
    input."""

    pair: ContactPair
    drive: str  # "a", "b", "eq3" or "diagonal" (see _stepper)
    params_a: list[float]
    params_b: list[float]
    chart_a: np.ndarray
    chart_b: np.ndarray
    coef: np.ndarray  # 3x2: input(t) = amp (coef0 + coef1 sin 3t + coef2 cos 5t)
    amp: float
    #: Added to psi_dot (negative control), as a multiple of the rolling angular speed.
    psi_dot_error: float = 0.0
    #: Added to the contact speed over B (negative control), as a multiple of the rolling
    #: speed.
    slip_error: float = 0.0

    def _args(self) -> list:
        return [self.coef, self.amp, self.params_a, self.params_b,
                [self.psi_dot_error, self.slip_error]]

    def _f(self, key: str) -> ca.Function:
        return _stepper(self.pair, self.drive)[key]

    def rates(self, t: float, eta: np.ndarray) -> np.ndarray:
        return vec(self._f("rates")([*eta, t], *self._args()))

    def omega(self, t: float, eta: np.ndarray) -> np.ndarray:
        """The rolling velocity the motion is driven with at (t, eta)."""
        return vec(self._f("omega")([*eta, t], *self._args()))

    def step(self, t: float, eta: np.ndarray, dt: float) -> np.ndarray:
        """eta(t + dt) by one classical Runge-Kutta step (dt may be negative)."""
        return vec(self._f("step")([*eta, t], dt, *self._args()))[0:5]

    def pose(self, eta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        R, p = _functions(self.pair)["pose"](eta, self.params_a, self.params_b, self.chart_a,
                                             self.chart_b)
        return np.array(R, dtype=float), vec(p)

    def integrate(self, eta0: np.ndarray) -> list[tuple[float, np.ndarray]]:
        """(t, eta(t)) at the CHECK_FRACTIONS of T_FINAL, by RK4 with N_STEPS steps."""
        return integrate(self, eta0)


def integrate(motion: Motion, eta0: np.ndarray) -> list[tuple[float, np.ndarray]]:
    """(t, eta(t)) at the CHECK_FRACTIONS of T_FINAL, by RK4 with N_STEPS steps."""
    xs = np.array(motion._f("trajectory")([*eta0, 0.0], T_FINAL / N_STEPS, *motion._args()),
                  dtype=float)
    xs = np.column_stack([[*eta0, 0.0], xs])  # x_0 ... x_N
    return [(float(xs[5, k]), xs[0:5, k].copy())
            for k in sorted({round(f * N_STEPS) for f in CHECK_FRACTIONS})]


@dataclass(frozen=True)
class Defects:
    slip: float  # |velocity of B's material contact point in A| / rolling speed
    spin: float  # |relative angular velocity . A's normal| / |relative angular velocity|
    omega_rel: np.ndarray  # angular velocity of B relative to A, in A [rad/s]
    speed: float  # rolling speed [m/s]
    omega: np.ndarray  # (omega_x, omega_y) of A relative to B in A's contact frame [rad/s]


def rolling_defects(motion: Motion, t: float, eta: np.ndarray) -> Defects:
    """Slip, spin and rolling velocity of the motion at (t, eta), from central differences
    of the pose in time (4th-order stencil over t - 2h ... t + 2h).

    eta(t + k h) comes from one RK4 step of k h (error O(h^5), negligible)."""
    pair, h = motion.pair, H_TIME
    poses = {k: motion.pose(motion.step(t, eta, k * h)) for k in (-2, -1, 1, 2)}
    R_0, _ = motion.pose(eta)

    def d_dt(i: int) -> np.ndarray:
        g = {k: poses[k][i] for k in poses}
        return (-g[2] + 8 * g[1] - 8 * g[-1] + g[-2]) / (12 * h)

    R_dot, p_dot = d_dt(0), d_dt(1)
    # B's material point at the contact at time t, in B's body frame (held fixed).
    p_b = motion.chart_b @ geometry(pair.b, eta[2:4], motion.params_b)["p"].ravel()
    v_contact = R_dot @ p_b + p_dot
    omega_rel = vee(R_dot @ R_0.T)  # of B relative to A, in A
    ga = geometry(pair.a, eta[0:2], motion.params_a)
    frame_a = motion.chart_a @ ga["R"]
    speed = float(np.linalg.norm(ga["M"] @ motion.rates(t, eta)[0:2]))
    return Defects(slip=float(np.linalg.norm(v_contact)) / speed,
                   spin=abs(float(omega_rel @ frame_a[:, 2])) / float(np.linalg.norm(omega_rel)),
                   omega_rel=omega_rel, speed=speed, omega=-(frame_a.T @ omega_rel)[0:2])


def latitudes(pair: ContactPair, eta: np.ndarray) -> list[float]:
    """|u| of the contact on each curved surface of the pair (0 for a plane)."""
    return [abs(float(eta[i])) if s is not Plane else 0.0
            for i, s in ((0, pair.a), (2, pair.b))]


def _amplitude(driven: Surface, other: Surface, params_d, params_o) -> float:
    """Input amplitude so that the contact moves by < 0.26 rad of latitude over T_FINAL on
    each curved surface (|input| <= (1 + 0.3 sqrt 2) amp < 1.43 amp, and |f_u| >= the
    smallest semi-axis): keeps the latitude inside the regular part of the chart."""
    rate = 0.5 / T_FINAL / 1.4 / 2.0  # [rad/s]: 1.43 * rate * T_FINAL < 0.26 rad
    radius_o = min(params_o) if params_o else np.inf
    if not params_d:  # driven side is flat: the input is a speed [m/s]
        return rate * radius_o
    # The driven side is curved: input in rad/s, its speed max(params_d) * input at most.
    return rate * min(1.0, radius_o / max(params_d))


# (pair, driven side): Plane/Sphere and Plane/Ellipsoid driven on the palm; the object
# sphere under a flat fingertip driven on the ball (the notes' fingertip equations) and on
# the pad; a curved-on-curved pair in both ways.
MOTION_CASES = [
    ("palm-sphere", "a"),
    ("palm-ellipsoid", "a"),
    ("palm-sphere", "b"),
    ("object_sphere-flat_fingertip", "a"),
    ("object_sphere-flat_fingertip", "b"),
    ("ellipsoid-sphere", "a"),
    ("ellipsoid-sphere", "b"),
]


@st.composite
def motions(draw, name: str, driven: str, psi_dot_error: float = 0.0,
            slip_error: float = 0.0) -> tuple[Motion, np.ndarray]:
    pair = PAIRS[name]
    eta0, params_a, params_b = draw(state_of(pair.a, pair.b, lat0))
    # coef0 of norm >= 0.5, coef1 and coef2 of norm <= 0.15 sqrt 2 each (0.43 together):
    # |input| >= 0.07 amp, the input never stops (the relative tolerances stay meaningful).
    theta = draw(angle)
    coef0 = draw(st.floats(0.5, 1.0)) * np.array([np.cos(theta), np.sin(theta)])
    coef12 = 0.15 * np.array([[draw(unit_coef), draw(unit_coef)] for _ in range(2)])
    surf_d, surf_o = (pair.a, pair.b) if driven == "a" else (pair.b, pair.a)
    par_d, par_o = (params_a, params_b) if driven == "a" else (params_b, params_a)
    motion = Motion(pair, driven, params_a, params_b, rotation_from_vector(draw(rotvec)),
                    rotation_from_vector(draw(rotvec)), np.vstack([coef0, coef12]),
                    _amplitude(surf_d, surf_o, par_d, par_o), psi_dot_error, slip_error)
    return motion, eta0


@pytest.mark.parametrize(("name", "driven"), MOTION_CASES)
@MOTION_SETTINGS
@given(data=st.data())
def test_integrated_rates_roll_without_slip_separation_or_spin(data: st.DataObject, name: str,
                                                               driven: str) -> None:
    """Along integrated motions, with random charts: (a) B's material contact point has zero
    velocity relative to A (no slip, no separation); (b) the relative angular velocity has
    no component along A's normal (no spin)."""
    motion, eta0 = data.draw(motions(name, driven))
    for t, eta in integrate(motion, eta0):
        assert max(latitudes(motion.pair, eta)) < 1.3, "motion left the chart's regular part"
        d = rolling_defects(motion, t, eta)
        assert np.isfinite(d.slip) and d.slip <= RTOL_SLIP, f"slip at t={t}: {d}"
        assert np.isfinite(d.spin) and d.spin <= RTOL_SPIN, f"spin at t={t}: {d}"


@pytest.mark.parametrize(("name", "driven"), MOTION_CASES)
@MOTION_SETTINGS
@given(data=st.data())
def test_integrated_contact_points_coincide_with_opposite_normals(data: st.DataObject,
                                                                  name: str, driven: str
                                                                  ) -> None:
    """(c) B's contact point mapped into A is A's contact point, B's normal mapped into A
    is minus A's, and B's contact frame is A's turned by R_contact(psi)."""
    motion, eta0 = data.draw(motions(name, driven))
    pair, f = motion.pair, _functions(motion.pair)
    for _, eta in integrate(motion, eta0):
        R_ab, p_ab = motion.pose(eta)
        ga = geometry(pair.a, eta[0:2], motion.params_a)
        gb = geometry(pair.b, eta[2:4], motion.params_b)
        p_c, n_c = (vec(x) for x in f["contact"](eta, motion.params_a, motion.chart_a))
        scale = max([1.0, *motion.params_a, *motion.params_b])
        assert_close(p_c, motion.chart_a @ ga["p"].ravel(), atol=RTOL_TOUCH * scale,
                     err_msg="contact_point is A's chart point")
        assert_close(R_ab @ motion.chart_b @ gb["p"].ravel() + p_ab, p_c,
                     atol=RTOL_TOUCH * scale, err_msg="B's contact point maps onto A's")
        assert_close(R_ab @ motion.chart_b @ gb["R"][:, 2], -n_c, atol=RTOL_TOUCH,
                     err_msg="normals opposite")
        assert_close((motion.chart_a @ ga["R"]).T @ R_ab @ motion.chart_b @ gb["R"],
                     np.array(R_contact(eta[4])), atol=RTOL_TOUCH, err_msg="contact frames")


@pytest.mark.parametrize(("name", "driven"), MOTION_CASES)
@MOTION_SETTINGS
@given(data=st.data())
def test_rolling_velocity_is_angular_velocity_of_a_relative_to_b(data: st.DataObject,
                                                                 name: str, driven: str
                                                                 ) -> None:
    """rolling_velocity (the omega of eq. 3) is (omega_x, omega_y) of A relative to B in A's
    contact frame: minus the tangential part of B's angular velocity relative to A."""
    motion, eta0 = data.draw(motions(name, driven))
    pair, f = motion.pair, _functions(motion.pair)
    eta = eta0
    d = rolling_defects(motion, 0.0, eta)
    frame_a = motion.chart_a @ geometry(pair.a, eta[0:2], motion.params_a)["R"]
    measured = -(frame_a.T @ d.omega_rel)[0:2]
    a_dot = motion.rates(0.0, eta)[0:2]
    omega = vec(f["omega"](eta, a_dot, motion.params_a, motion.params_b))
    assert_close(omega, measured, atol=RTOL_OMEGA * float(np.linalg.norm(d.omega_rel)),
                 err_msg="rolling velocity")


@pytest.mark.parametrize(("name", "driven"), [("palm-sphere", "a"), ("palm-ellipsoid", "a"),
                                              ("object_sphere-flat_fingertip", "b")])
@settings(MOTION_SETTINGS, max_examples=10)
@given(data=st.data())
def test_spin_check_detects_perturbed_psi_rate(data: st.DataObject, name: str, driven: str
                                               ) -> None:
    """Negative control: psi_dot + 0.1 |omega| is a spin of 0.1 |omega| about the normal,
    which the check of test_integrated_rates_roll_without_slip_separation_or_spin sees;
    such a wrong psi_dot does not cause slip (the spin axis passes through the contact)."""
    motion, eta0 = data.draw(motions(name, driven, psi_dot_error=0.1))
    for t, eta in integrate(motion, eta0):
        d = rolling_defects(motion, t, eta)
        assert d.spin > 1e3 * RTOL_SPIN, f"spin not detected at t={t}: {d}"
        assert d.slip <= RTOL_SLIP, f"slip at t={t}: {d}"


@pytest.mark.parametrize(("name", "driven"), [("palm-sphere", "a"), ("palm-ellipsoid", "a"),
                                              ("object_sphere-flat_fingertip", "b")])
@settings(MOTION_SETTINGS, max_examples=10)
@given(data=st.data())
def test_slip_check_detects_perturbed_contact_rate_on_b(data: st.DataObject, name: str,
                                                        driven: str) -> None:
    """Negative control: moving the contact over B faster than over A (by 0.1 of the rolling
    speed) is slip, which the check sees."""
    motion, eta0 = data.draw(motions(name, driven, slip_error=0.1))
    for t, eta in integrate(motion, eta0):
        d = rolling_defects(motion, t, eta)
        assert d.slip > 1e3 * RTOL_SLIP, f"slip not detected at t={t}: {d}"


# ---------------------------------------------------------------------------------------
# 10. Poses: object on the palm
# ---------------------------------------------------------------------------------------
@SETTINGS
@given(state=state_of(Plane, Sphere), w=rotvec)
def test_ball_centre_is_straight_above_palm_contact_at_height_rho(state, w: np.ndarray
                                                                 ) -> None:
    """For the palm/ball pair the ball centre is at (x, y, rho) for any (u, v, psi) and any
    chart on the ball (the contact point is straight below it)."""
    eta, _, params_b = state
    _, p_ab = _functions(PAIRS["palm-sphere"])["pose"](eta, [], params_b, np.eye(3),
                                                       rotation_from_vector(w))
    rho = params_b[0]
    assert_close(vec(p_ab), [eta[0], eta[1], rho], atol=RTOL_TOUCH * max(rho, 0.1),
                 err_msg="ball centre")


@SETTINGS
@given(state=state_of(Plane, Ellipsoid), w=rotvec)
def test_spheroid_on_palm_touches_at_its_lowest_point(state, w: np.ndarray) -> None:
    """For the palm/spheroid pair the object rests on the palm: its centre height is its
    support height in the palm's downward direction, and the palm contact point (x, y, 0)
    is the object's support point in that direction (no penetration, no gap).

    The spheroid's chart is rotated by Rc in the body, so the body's surface is Rc times the
    chart's: the support functions are evaluated in the chart's frame."""
    eta, _, params_b = state
    Rc = rotation_from_vector(w)
    R_ab, p_ab = (np.array(x, dtype=float) for x in _functions(PAIRS["palm-ellipsoid"])[
        "pose"](eta, [], params_b, np.eye(3), Rc))
    p_ab = p_ab.ravel()
    down_in_chart = Rc.T @ R_ab.T @ np.array([0.0, 0.0, -1.0])
    scale = max(params_b)
    assert_close(p_ab[2], Ellipsoid.support_height(down_in_chart, params_b),
                 atol=1e-12 * scale, err_msg="centre height = support height")
    lowest = p_ab + R_ab @ Rc @ Ellipsoid.support_point(down_in_chart, params_b)
    assert_close(lowest, [eta[0], eta[1], 0.0], atol=1e-12 * max(scale, 0.1),
                 err_msg="lowest point = palm contact point")


# ---------------------------------------------------------------------------------------
# Safe branch at the ball's pole
# ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("u", [np.pi / 2, -np.pi / 2])
@pytest.mark.parametrize("driven", ["a", "b"])
def test_palm_sphere_rates_and_pose_are_finite_at_the_pole(u: float, driven: str) -> None:
    """At the ball chart's pole the rates (huge: the chart is singular) and the pose are
    finite numbers, not NaN."""
    pair = PAIRS["palm-sphere"]
    eta = np.array([0.01, -0.02, u, 0.4, 0.3])
    f = _functions(pair)
    rates = vec(f[driven](eta, [0.01, 0.02], [], [0.03]))
    R_ab, p_ab = f["pose"](eta, [], [0.03], np.eye(3), np.eye(3))
    for name, value in (("rates", rates), ("R_ab", R_ab), ("p_ab", p_ab)):
        assert np.all(np.isfinite(np.array(value, dtype=float))), f"{name}: {value}"

