"""Problem specifications, validated as a whole before any NLP is built.

Units are SI throughout: lengths in m, angles in rad, times in s, speeds in m/s.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ocp.geometry.surfaces import Surface, rotation_from_vector
from ocp.shapes import SHAPES, Shape

FloatArray = NDArray[np.float64]

__all__ = [
    "CONTACT_COORDS",
    "DEFAULT_MAX_JOINT_ACCELERATION",
    "DEFAULT_RAMP_FRACTION",
    "TIMINGS",
    "BallOnPalmProblem",
    "ForceSpec",
    "ObjectSpec",
    "ProblemError",
    "SolverOptions",
    "Structure",
    "ViaPoint",
    "coordinate_error",
    "goal_errors",
    "wrap_difference",
]

#: Names of the palm/object contact coordinates eta_p = (x, y, u, v, psi):
#: palm point (x, y) [m], object chart latitude/longitude (u, v) [rad], contact angle [rad].
CONTACT_COORDS: tuple[str, ...] = ("x", "y", "u", "v", "psi")
#: Which contact coordinates are angles with period 2 pi (v and psi).
PERIODIC: tuple[bool, ...] = (False, False, False, True, True)

#: Limits that keep a problem sane (and an NLP bounded in size).
MAX_INTERVALS = 2000
MAX_VIA_POINTS = 50
MAX_POSITION = 10.0  # m, any palm coordinate
#: The default chart patch of a fingertip contact (rotation vector [rad] in the object
#: frame), the library's and the wire's: patch point (0, 0) at the antipode of the object
#: chart's (0, 0), which with the default object chart and the palm contact at u = v = 0 is
#: the ball's top.
DEFAULT_FINGER_CHART_ROTATION: tuple[float, float, float] = (0.0, 0.0, math.pi)
MAX_DURATION = 3600.0  # s
#: A plan's timing (docs/timing.md): ``"smooth"`` (the default) starts and ends at rest,
#: every velocity continuous (also at via-points), joint accelerations bounded;
#: ``"paper"`` the paper's piecewise inputs (full speed at the start and the end, velocity
#: jumps at via-points), for reproducing its figures.
TIMINGS: tuple[str, ...] = ("smooth", "paper")
#: The default bound on every joint's acceleration of a smooth plan [rad/s^2].
DEFAULT_MAX_JOINT_ACCELERATION = 20.0
#: The smooth plan's default ramp time constant, as a fraction of the duration.
DEFAULT_RAMP_FRACTION = 0.15


def joint_acceleration_errors(a: object) -> list[tuple[str, str]]:
    """(field, reason) when ``max_joint_acceleration`` is not in (0, 1e5] rad/s^2."""
    if isinstance(a, int | float) and not isinstance(a, bool) and math.isfinite(a) \
            and 0.0 < a <= 1e5:
        return []
    return [("max_joint_acceleration", f"must be in (0, 1e5] rad/s^2, got {a!r}")]


def timing_errors(timing: object) -> list[tuple[str, str]]:
    """(field, reason) when ``timing`` is not one of :data:`TIMINGS`."""
    if timing in TIMINGS:
        return []
    return [("timing", f"must be one of {list(TIMINGS)}, got {timing!r}")]


class ProblemError(ValueError):
    """A problem that cannot be planned. ``errors`` lists (field, reason) pairs."""

    def __init__(self, errors: Sequence[tuple[str, str]]) -> None:
        self.errors = list(errors)
        super().__init__("; ".join(f"{f}: {r}" for f, r in self.errors))


@dataclass(frozen=True)
class ObjectSpec:
    """The rolled object: a closed surface with its chart.

    ``shape`` names one of :data:`ocp.shapes.SHAPES` (``"sphere"``: dimensions (radius,);
    ``"ellipsoid"``: (a, c) of revolution about z, or (a, b, c)), ``dimensions`` in m.
    ``chart_rotation`` is the rotation vector [rad] of the object's chart patch in the
    object frame; the contact coordinates (u, v, psi) are measured in that patch.
    """

    shape: str = "sphere"
    dimensions: tuple[float, ...] = (0.03,)
    chart_rotation: tuple[float, float, float] = (0.0, 0.0, 0.0)
    #: whether the contacts are measured on the shape's side chart
    #: (:meth:`Shape.side_surface`: an egg's, whose poles are on its equator), each in the
    #: patch that puts it on that chart's equator: a gait's roll whose contacts have
    #: rolled toward the poles of the shape's own chart
    side_chart: bool = False

    @property
    def kind(self) -> Shape:
        """The shape (:mod:`ocp.shapes`; KeyError for a name none has)."""
        return SHAPES[self.shape]

    @property
    def surface(self) -> Surface:
        """The surface the contact coordinates are measured on; its ``name`` keys the
        NLPs built for it."""
        side = self.kind.side_surface(self.dimensions) if self.side_chart else None
        return self.kind.surface(self.dimensions) if side is None else side

    @property
    def params(self) -> tuple[float, ...]:
        """The surface's parameters, as its charts and the NLPs take them (the dimensions,
        but for a shape whose chart wants them otherwise: :meth:`Shape.surface_params`)."""
        return self.kind.surface_params(self.dimensions)

    @property
    def length_scale(self) -> float:
        """Characteristic length [m] used to scale the NLP (the largest half extent)."""
        return self.kind.length_scale(self.dimensions)

    def u_limit(self, pole_margin: float) -> float:
        """The bound on a contact's |u| on the object's chart (its poles less
        ``pole_margin`` [rad], or a seam)."""
        return self.surface.u_limit(self.params, pole_margin)

    def errors(self) -> list[tuple[str, str]]:
        """Why the shape and dimensions describe no object, as (field, reason)."""
        if self.shape not in SHAPES:
            return [("object.shape", f"unknown object shape {self.shape!r}; one of "
                                     f"{sorted(SHAPES)}")]
        return [("object.dimensions", r) for r in self.kind.errors(self.dimensions)]


@dataclass(frozen=True)
class ForceSpec:
    """What a plan's contact forces must hold (issue 15; docs/forces.md): the object's
    ``mass`` [kg] and principal ``inertia`` about its own axes [kg m^2] (default: the solid
    sphere's or ellipsoid's of that mass), ``gravity`` [m/s^2] in the palm frame, the grip:
    every contact's normal force at least ``min_normal_force`` [N], and
    ``torsional_friction`` [m], the soft-finger coefficient: the moment about the normal
    within ``torsional_friction`` times the normal force (0: hard point contacts).
    ``cone_margin`` [rad]: the planned forces stay this far inside the friction cones."""

    mass: float
    inertia: tuple[float, float, float] | None = None
    gravity: tuple[float, float, float] = (0.0, 0.0, -9.81)
    min_normal_force: float = 0.5
    torsional_friction: float = 0.0
    cone_margin: float = 0.05

    def principal_inertia(self, obj: ObjectSpec) -> tuple[float, float, float]:
        """The inertia given, else the solid body's of ``obj`` with this mass."""
        if self.inertia is not None:
            return self.inertia
        return obj.kind.inertia(obj.dimensions, self.mass)

    def errors(self, name: str, mu: float) -> list[tuple[str, str]]:
        """Every reason these fields are invalid, as (field, reason) under ``name``."""
        errs: list[tuple[str, str]] = []

        def finite(value: object) -> bool:
            return isinstance(value, int | float) and not isinstance(value, bool) \
                and math.isfinite(value)

        if not (finite(self.mass) and 0.0 < self.mass <= 100.0):
            errs.append((f"{name}.mass", f"must be in (0, 100] kg, got {self.mass}"))
        if self.inertia is not None and not (
                len(self.inertia) == 3 and all(finite(v) and 0.0 < v <= 100.0
                                               for v in self.inertia)):
            errs.append((f"{name}.inertia", "must be 3 principal moments in (0, 100] kg m^2, "
                                            f"got {list(self.inertia)}"))
        if not (len(self.gravity) == 3 and all(finite(v) and abs(v) <= 100.0
                                               for v in self.gravity)):
            errs.append((f"{name}.gravity", "must be 3 finite numbers within 100 m/s^2 "
                                            f"(palm frame), got {list(self.gravity)}"))
        if not (finite(self.min_normal_force) and 0.0 < self.min_normal_force <= 1e3):
            errs.append((f"{name}.min_normal_force",
                         f"must be in (0, 1000] N, got {self.min_normal_force}"))
        if not (finite(self.torsional_friction) and 0.0 <= self.torsional_friction <= 0.1):
            errs.append((f"{name}.torsional_friction",
                         f"must be in [0, 0.1] m, got {self.torsional_friction}"))
        if not (finite(self.cone_margin) and 0.0 <= self.cone_margin
                < (math.atan(mu) if finite(mu) and mu > 0 else math.pi / 2)):
            errs.append((f"{name}.cone_margin",
                         f"must be in [0, atan(mu)) rad, got {self.cone_margin}"))
        return errs


@dataclass(frozen=True)
class ViaPoint:
    """Contact coordinates (any subset of CONTACT_COORDS) to pass through at ``time`` [s]."""

    time: float
    coords: Mapping[str, float]


@dataclass(frozen=True)
class SolverOptions:
    """Limits and tolerances passed to IPOPT for one solve."""

    max_iter: int = 1000
    time_limit: float = 60.0  # s, wall clock for the whole plan (all initial guesses)
    tol: float = 1e-8
    #: Tolerances of the physical certificate (see ocp.certify.certificate).
    cert_position_tol: float = 1e-6  # m: re-integration defect of the palm coordinates
    cert_angle_tol: float = 1e-4  # rad: re-integration defect of the angles


@dataclass(frozen=True)
class BallOnPalmProblem:
    """Roll an object on a flat palm from ``initial`` to ``goal`` (eq. 8, generalised).

    ``initial`` are the five contact coordinates (x, y, u, v, psi) at t = 0; ``goal``
    any non-empty subset of them at t = ``duration``; ``via_points`` subsets at given
    interior times. ``n_intervals`` is the number of collocation intervals over the whole
    horizon. ``pole_margin`` [rad] keeps |u| <= pi/2 - pole_margin on the object chart.
    ``max_contact_speed`` [m/s] bounds each component of the palm contact velocity and
    ``palm_half_extent`` [m] the palm coordinates.
    """

    object: ObjectSpec
    initial: tuple[float, float, float, float, float]
    goal: Mapping[str, float]
    duration: float
    via_points: tuple[ViaPoint, ...] = ()
    n_intervals: int = 50
    pole_margin: float = math.radians(15.0)
    max_contact_speed: float = 1.0
    palm_half_extent: float = 0.5
    max_refinements: int = 2
    options: SolverOptions = field(default_factory=SolverOptions)
    #: :data:`TIMINGS`: ``"smooth"`` starts and ends at rest with continuous velocities;
    #: ``"paper"`` the paper's piecewise inputs.
    timing: str = "smooth"
    #: A smooth plan's ramps' time constant [s]; None: :data:`DEFAULT_RAMP_FRACTION` of the
    #: duration.
    ramp_time: float | None = None

    # -- validation -----------------------------------------------------------------------
    def errors(self) -> list[tuple[str, str]]:
        """Every reason this problem is invalid, as (field, reason); empty when valid: its
        settings' (:meth:`setting_errors`), then its palm contact's (an object that would
        touch the flat palm along a line; the coordinates of its start, goal and
        via-points)."""
        errs = self.setting_errors()
        obj = self.object
        if not obj.errors() and obj.surface.developable:
            errs.append(("object.shape", f"a {obj.shape} touches the flat palm along a "
                                         "line, not at a point as the planner's contacts do"))
        margin_ok = math.isfinite(self.pole_margin) and 0.0 < self.pole_margin < math.pi / 2
        u_max = obj.u_limit(self.pole_margin if margin_ok else 0.0) \
            if not obj.errors() else math.pi / 2
        if len(self.initial) != 5:
            errs.append(("initial", f"must have 5 coordinates {CONTACT_COORDS}, "
                                    f"got {len(self.initial)}"))
        else:
            errs += self._coord_errors("initial", dict(zip(CONTACT_COORDS, self.initial,
                                                           strict=True)), u_max)
        if not self.goal and not self.via_points:
            errs.append(("goal", "empty goal and no via-points: nothing to plan"))
        errs += self._coord_errors("goal", self.goal, u_max)

        last = 0.0
        for i, vp in enumerate(self.via_points):
            name = f"via_points[{i}]"
            if not (math.isfinite(vp.time) and last < vp.time < self.duration):
                errs.append((f"{name}.time",
                             f"must be strictly increasing and inside (0, duration = "
                             f"{self.duration} s), got {vp.time}"))
            else:
                last = vp.time
            if not vp.coords:
                errs.append((f"{name}.coords", "empty: give at least one coordinate"))
            errs += self._coord_errors(f"{name}.coords", vp.coords, u_max)
        return errs

    def setting_errors(self) -> list[tuple[str, str]]:
        """Why the object, the horizon and grid, the timing and the solver options are
        invalid, as (field, reason): what a grasp held without a palm checks by these
        same rules."""
        errs: list[tuple[str, str]] = []
        obj = self.object
        shape_errors = obj.errors()
        errs += shape_errors
        if len(obj.chart_rotation) != 3 or not all(map(math.isfinite, obj.chart_rotation)):
            errs.append(("object.chart_rotation",
                         "must be 3 finite numbers (rotation vector, rad)"))
        elif not shape_errors:
            why = obj.surface.chart_rotation_error(rotation_from_vector(obj.chart_rotation),
                                                   obj.params)
            if why is not None:
                errs.append(("object.chart_rotation", why))

        margin_ok = math.isfinite(self.pole_margin) and 0.0 < self.pole_margin < math.pi / 2
        if not margin_ok:
            errs.append(("pole_margin", f"must be in (0, pi/2) rad, got {self.pole_margin}"))
        if not (math.isfinite(self.duration) and 0.0 < self.duration <= MAX_DURATION):
            errs.append(("duration", f"must be in (0, {MAX_DURATION}] s, got {self.duration}"))
        if not (math.isfinite(self.max_contact_speed) and self.max_contact_speed > 0.0):
            errs.append(("max_contact_speed", f"must be > 0 m/s, got {self.max_contact_speed}"))
        if not (math.isfinite(self.palm_half_extent) and
                0.0 < self.palm_half_extent <= MAX_POSITION):
            errs.append(("palm_half_extent",
                         f"must be in (0, {MAX_POSITION}] m, got {self.palm_half_extent}"))
        n_via = len(self.via_points)
        if n_via > MAX_VIA_POINTS:
            errs.append(("via_points", f"at most {MAX_VIA_POINTS} via-points, got {n_via}"))
        if not (n_via + 1 <= self.n_intervals <= MAX_INTERVALS):
            errs.append(("n_intervals",
                         f"must be in [{n_via + 1}, {MAX_INTERVALS}] (one interval per segment "
                         f"between via-points at least), got {self.n_intervals}"))
        if not (0 <= self.max_refinements <= 5):
            errs.append(("max_refinements", f"must be in [0, 5], got {self.max_refinements}"))
        errs += timing_errors(self.timing)
        r = self.ramp_time
        if r is not None and not (isinstance(r, int | float) and math.isfinite(r)
                                  and 0.0 < r <= self.duration):
            errs.append(("ramp_time", f"must be in (0, duration = {self.duration} s], got "
                                      f"{r}"))
        o = self.options
        if not (1 <= o.max_iter <= 100_000):
            errs.append(("options.max_iter", f"must be in [1, 100000], got {o.max_iter}"))
        if not (math.isfinite(o.time_limit) and o.time_limit > 0):
            errs.append(("options.time_limit", f"must be > 0 s, got {o.time_limit}"))
        if not (math.isfinite(o.tol) and 0 < o.tol < 1):
            errs.append(("options.tol", f"must be in (0, 1), got {o.tol}"))
        return errs

    def _coord_errors(self, name: str, coords: Mapping[str, float], u_max: float
                      ) -> list[tuple[str, str]]:
        errs: list[tuple[str, str]] = []
        for key, value in coords.items():
            where = f"{name}.{key}"
            if key not in CONTACT_COORDS:
                errs.append((where, f"unknown coordinate {key!r}; allowed: {CONTACT_COORDS}"))
                continue
            if not math.isfinite(value):
                errs.append((where, f"must be finite, got {value}"))
            elif key in ("x", "y") and abs(value) > min(self.palm_half_extent, MAX_POSITION):
                errs.append((where, f"|{key}| = {abs(value):.4g} m is outside the palm "
                                    f"(palm_half_extent = {self.palm_half_extent} m)"))
            elif key == "u" and abs(value) > u_max:
                errs.append((where, beyond_u_limit(self.object, value, u_max,
                                                   "object.chart_rotation")))
        return errs

    def validate(self) -> None:
        """Raise :class:`ProblemError` naming every bad field, before any NLP is built."""
        errs = self.errors()
        if errs:
            raise ProblemError(errs)

    # -- derived data ---------------------------------------------------------------------
    @property
    def segment_times(self) -> np.ndarray:
        """Boundaries of the segments between via-points: [0, t_1, ..., duration] [s]."""
        return np.array([0.0, *(vp.time for vp in self.via_points), self.duration])

    def segment_intervals(self) -> tuple[int, ...]:
        """Intervals per segment, proportional to segment duration, at least 1 each."""
        dt = np.diff(self.segment_times)
        n_seg = len(dt)
        counts = np.maximum(1, np.floor(self.n_intervals * dt / self.duration).astype(int))
        # hand the remaining intervals to the segments with the largest remainders
        while counts.sum() < self.n_intervals:
            share = self.n_intervals * dt / self.duration - counts
            counts[int(np.argmax(share))] += 1
        while counts.sum() > self.n_intervals:
            i = int(np.argmax(np.where(counts > 1, counts, -1)))
            counts[i] -= 1
        assert len(counts) == n_seg
        return tuple(int(c) for c in counts)


# -- palm targets: which coordinates a goal or via-point fixes, and how far a plan is --

def wrap_difference(a: FloatArray | float, b: FloatArray | float) -> FloatArray:
    """a - b wrapped into [-pi, pi)."""
    return np.asarray((np.asarray(a) - np.asarray(b) + np.pi) % (2 * np.pi) - np.pi)


def coordinate_error(coord: str, value: float, target: float) -> float:
    """|value - target| in m or rad, modulo 2 pi for the periodic coordinates."""
    i = CONTACT_COORDS.index(coord)
    d = float(wrap_difference(value, target)) if PERIODIC[i] else value - target
    return abs(d)


def beyond_u_limit(obj: ObjectSpec, value: float, limit: float, patch: str) -> str:
    """Why a contact at latitude ``value`` is refused: at or beyond its chart's bound
    ``limit``, and what to do (``patch``: the field of the chart patch, which a ball's
    contact may turn)."""
    surface = obj.surface
    remedy = (f"rotate the object chart ({patch}) so the contact is away from its poles"
              if surface.chart_symmetry == "any" else
              "the poles are the ends of the object's z axis: keep the contact away from "
              "them or lower pole_margin" if surface.singular_u is not None else
              "keep the contact within the chart")
    return (f"|u| = {abs(value):.4f} is at or beyond the {surface.u_limit_name} = "
            f"{limit:.4f}; {remedy}")


@dataclass(frozen=True)
class Structure:
    """What fixes the shape of the NLP; everything else is a parameter or a bound."""

    #: the object surface's name (``ObjectSpec.surface.name``)
    shape: str
    segments: tuple[int, ...]
    goal_mask: tuple[bool, ...]
    via_masks: tuple[tuple[bool, ...], ...]

    @staticmethod
    def of(problem: BallOnPalmProblem) -> Structure:
        def mask(coords: Any) -> tuple[bool, ...]:
            return tuple(c in coords for c in CONTACT_COORDS)

        return Structure(problem.object.surface.name, problem.segment_intervals(),
                         mask(problem.goal), tuple(mask(vp.coords) for vp in problem.via_points))


def goal_errors(problem: BallOnPalmProblem, X: FloatArray, ends: list[int]
                ) -> dict[str, float]:
    """Error of every goal and via-point coordinate (m or wrapped rad) of the palm contact
    coordinates ``X[:, 0:5]`` at the segment end nodes ``ends`` (0 first)."""
    out: dict[str, float] = {}
    for j, vp in enumerate(problem.via_points):
        for c, val in vp.coords.items():
            out[f"via_points[{j}].{c}"] = coordinate_error(
                c, X[ends[j + 1], CONTACT_COORDS.index(c)], val)
    for c, val in problem.goal.items():
        out[f"goal.{c}"] = coordinate_error(c, X[ends[-1], CONTACT_COORDS.index(c)], val)
    return out
