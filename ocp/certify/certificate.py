"""One certificate type: a list of checks, each with its name, value, tolerance and kind.

A plan's certificate is a statement about the trajectory returned, computed independently
of the NLP (laws along the returned polynomials, Pinocchio's kinematics, a re-integration
with CVODES). Each check says what kind of failure it reports and the time of its worst
sample, and the planners decide by kind (never by message text):

* ``discretisation``: what happens between collocation points (slip, spin, closure, gap,
  re-integration defects, tracking and joint limits between points): it shrinks with the
  grid, so a plan failing only these is refined (solved again on a finer grid,
  :meth:`Certificate.refinement_factor`).
* ``physics``: a law the plan breaks whatever the grid (the object leaves the palm,
  force closure lost).
* ``limits``: a limit of the hand (a contact off its pad).
* ``goal``: a goal or via-point missed.
* ``numerics``: the plan could not be checked (non-finite values, CVODES gave up).

Tolerances are set where each check is made (:mod:`ocp.solve.contact_checks` for the
contacts' laws, :mod:`ocp.solve.certify` for defects, goals and cones) and stated in
docs/conventions.md.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass
from enum import StrEnum
from typing import Any, Protocol


class SolverOptions(Protocol):
    """The certificate's tolerances a problem's solver options carry
    (:class:`ocp.spec.problem.SolverOptions`)."""

    @property
    def cert_position_tol(self) -> float: ...

    @property
    def cert_angle_tol(self) -> float: ...

__all__ = ["CHECK_POINTS", "GRASP_TOLERANCES", "PALM_TOLERANCES", "Certificate", "Check",
           "CheckKind", "TolerancePolicy"]


class CheckKind(StrEnum):
    DISCRETISATION = "discretisation"
    PHYSICS = "physics"
    LIMITS = "limits"
    GOAL = "goal"
    NUMERICS = "numerics"


@dataclass(frozen=True)
class Check:
    """``value`` must be at most ``tolerance`` (``lower_bound``: at least)."""

    name: str
    value: float
    tolerance: float
    kind: CheckKind
    lower_bound: bool = False
    #: The failure's text (default: "<name> <value> > <tolerance>").
    reason: str = ""
    #: Whether the mapping view has a ``tol_<name>`` entry for it, and a ``<name>`` one.
    report_tolerance: bool = True
    report_value: bool = True
    #: The tolerance's key in :meth:`Certificate.tolerances` and in the failure's text
    #: (default: the name).
    tolerance_key: str = ""
    #: The time [s] of the worst sample (None: not a check along the motion).
    time: float | None = None

    @property
    def passed(self) -> bool:
        if self.lower_bound:
            return self.value >= self.tolerance  # NaN fails
        return self.value <= self.tolerance

    @property
    def failure(self) -> str:
        if self.reason:
            return self.reason
        op = "<" if self.lower_bound else ">"
        at = "" if self.time is None else f" at t = {self.time:.6g} s"
        return (f"{self.tolerance_key or self.name} {self.value:.3g} {op} "
                f"{self.tolerance:.3g}{at}")


@dataclass(frozen=True)
class Certificate(Mapping[str, float]):
    """The checks of one plan. As a mapping, it is the flat ``{name: value, "tol_<name>":
    tolerance}`` of the wire's ``certificate`` (values of checks without a tolerance of
    their own, such as the grasp angle, are reported too)."""

    checks: tuple[Check, ...] = ()
    #: Values reported without a check (e.g. the largest grasp angle).
    reported: tuple[tuple[str, float], ...] = ()
    #: Samples of the returned trajectory the laws were checked at.
    n_samples: int = 0

    @staticmethod
    def of(checks: Iterable[Check], reported: Mapping[str, float] | None = None,
           n_samples: int = 0) -> Certificate:
        """Checks of the same name merged (the worst value kept: several fingers' closure
        errors are one check)."""
        merged: dict[str, Check] = {}
        for c in checks:
            old = merged.get(c.name)
            if old is None or _worse(c, old):
                merged[c.name] = c
        return Certificate(tuple(merged.values()), tuple((reported or {}).items()), n_samples)

    @staticmethod
    def failed(reason: str) -> Certificate:
        """A plan that could not be checked at all."""
        return Certificate((Check("checkable", math.nan, 0.0, CheckKind.NUMERICS,
                                  reason=reason),))

    @property
    def passed(self) -> bool:
        return all(c.passed for c in self.checks)

    @property
    def failures(self) -> tuple[str, ...]:
        return tuple(c.failure for c in self.checks if not c.passed)

    def failed_kinds(self) -> set[CheckKind]:
        return {c.kind for c in self.checks if not c.passed}

    @property
    def refinable(self) -> bool:
        """Failed, and only by discretisation checks: a finer grid may pass."""
        kinds = self.failed_kinds()
        return bool(kinds) and kinds <= {CheckKind.DISCRETISATION}

    def refinement_factor(self, order: int = 3, most: int = 8) -> int:
        """How much finer a grid should make the failed discretisation checks pass: a
        power of two, at least 2 and at most ``most``, for errors that shrink like h^order
        (the slowest of the checks: slip and spin between the collocation points, h^3
        since the closure is imposed at the velocity level; measured on the two-finger
        contract plan, 7.2e-6, 1.1e-6, 1.4e-7 m/s at N = 20, 40, 80) with a margin of 2
        on the error (measured on the full bench suite: with 1.25, 13 of 342 plans still
        failed after two refinements, at 1.1-3.5 times the tolerance)."""
        worst = max((c.value / c.tolerance for c in self.checks
                     if not c.passed and c.kind is CheckKind.DISCRETISATION
                     and not c.lower_bound and c.tolerance > 0), default=2.0)
        need = (2.0 * worst) ** (1.0 / order) if math.isfinite(worst) else most
        return int(min(most, max(2, 2 ** math.ceil(math.log2(max(need, 1.0))))))

    def tolerances(self) -> dict[str, float]:
        """Every check's tolerance by its tolerance key."""
        return {c.tolerance_key or c.name: c.tolerance for c in self.checks
                if c.kind is not CheckKind.NUMERICS}

    def times(self) -> dict[str, float]:
        """The time [s] of each check's worst sample, for the checks along the motion."""
        return {c.name: c.time for c in self.checks if c.time is not None}

    def to_dict(self) -> dict[str, Any]:
        """``passed``, every value, ``n_samples``, ``tolerances``, ``times`` (of each
        check's worst sample) and ``failures``."""
        values = {c.name: c.value for c in self.checks
                  if c.kind is not CheckKind.NUMERICS and c.report_value}
        return {"passed": self.passed, **values, **dict(self.reported),
                "n_samples": self.n_samples, "tolerances": self.tolerances(),
                "times": self.times(), "failures": list(self.failures)}

    def check(self, name: str) -> Check:
        for c in self.checks:
            if c.name == name:
                return c
        raise KeyError(name)

    def _flat(self) -> dict[str, float]:
        out: dict[str, float] = {}
        for c in self.checks:
            if c.kind is not CheckKind.NUMERICS and c.report_value:
                out[c.name] = c.value
        out.update(self.reported)
        for c in self.checks:
            if c.kind is not CheckKind.NUMERICS and c.report_tolerance:
                out[f"tol_{c.name}"] = c.tolerance
        return out

    def __getitem__(self, key: str) -> float:
        return self._flat()[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self._flat())

    def __len__(self) -> int:
        return len(self._flat())


def _worse(a: Check, b: Check) -> bool:
    if a.lower_bound:
        return not a.value >= b.value
    return not a.value <= b.value


#: Normalised times in each interval at which the returned trajectory is checked: eight
#: equal steps (both ends included, so a node is checked from both sides, and the
#: midpoint) and the two extrema of the cubic that vanishes at the three collocation points,
#: s = 1/2 -+ 1/(2 sqrt 3): the leading term of the interpolant's error between collocation
#: points, so that the check lands on its largest value (docs/conventions.md).
CHECK_POINTS: tuple[float, ...] = tuple(sorted(
    [j / 8 for j in range(9)] + [0.5 - 0.5 / math.sqrt(3), 0.5 + 0.5 / math.sqrt(3)]))


@dataclass(frozen=True)
class TolerancePolicy:
    """How strictly a plan is certified: one policy for every contact (docs/conventions.md).

    The returned trajectory is checked at :data:`CHECK_POINTS` of every interval. Slip at
    every contact is at most ``slip`` x the plan's speed scale (the RMS over time and
    contacts of the contact points' speed, at least ``speed_floor`` L / T), spin at most
    ``spin`` x its rate scale (the RMS of the contacts' rolling rates, at least the speed
    scale over L); closure and gaps are absolute.

    Re-integration defects (nodes and midpoints): lengths max(``cert_position_tol``,
    ``length_defect_floor``) m, angles and joints ``angle_defect_factor`` x
    ``cert_angle_tol`` rad; the goals of the re-integrated motion the larger of the two.
    The object on the palm touches it to ``support_height`` m (x the object's size with
    ``height_relative``): by construction of its pose, so this is a check of the model.
    """

    name: str
    length_defect_floor: float
    angle_defect_factor: float
    support_height: float
    height_relative: bool
    check_points: tuple[float, ...] = CHECK_POINTS
    slip: float = 1e-3
    spin: float = 1e-3
    speed_floor: float = 1e-2
    #: a fingertip's gap to the object [m], a joint's excursion past its limit [rad or m]
    gap: float = 1e-5
    joint_limit: float = 1e-6
    #: a joint coupling's excursion past its bounds [m of tendon] (ocp.robots.couplings)
    coupling: float = 1e-6
    #: each fingertip where its joints put it (Pinocchio) [m], [rad]
    closure_position: float = 1e-5
    closure_orientation: float = 1e-4
    #: the smallest margin to the friction cones [rad] (force closure: two or more contacts)
    cone_margin: float = -1e-6

    def length_defect(self, o: SolverOptions) -> float:
        return max(o.cert_position_tol, self.length_defect_floor)

    def angle_defect(self, o: SolverOptions) -> float:
        return self.angle_defect_factor * o.cert_angle_tol

    def goal(self, o: SolverOptions) -> float:
        return max(self.length_defect(o), self.angle_defect(o))


#: Grasps with fingers (the general planner's defect tolerances).
GRASP_TOLERANCES = TolerancePolicy("grasp", length_defect_floor=1e-5,
                                   angle_defect_factor=10.0, support_height=1e-9,
                                   height_relative=False)
#: The object on the palm alone (the ball-on-palm planner's defect tolerances: its
#: options' own; the contacts' laws are every grasp's).
PALM_TOLERANCES = TolerancePolicy("palm", length_defect_floor=0.0, angle_defect_factor=1.0,
                                  support_height=1e-9, height_relative=True)
