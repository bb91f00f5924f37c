"""One certificate type: a list of checks, each with its name, value, tolerance and kind.

A plan's certificate is computed independently of the NLP (re-integration with CVODES,
laws along the re-integrated motion, Pinocchio's kinematics). Each check says what kind of
failure it reports, and the planners decide by kind (never by message text):

* ``discretisation``: what happens between collocation points (slip, spin, closure, gap,
  re-integration defects, tracking and joint limits between points): it shrinks with the
  grid, so a plan failing only these is refined (solved again on a grid twice as fine).
* ``physics``: a law the plan breaks whatever the grid (the object leaves the palm,
  force closure lost).
* ``limits``: a limit of the hand (a contact off its pad).
* ``goal``: a goal or via-point missed.
* ``numerics``: the plan could not be checked (non-finite values, CVODES gave up).

Tolerances are set where each check is made (:mod:`ocp.contacts` for the contacts' laws,
the planners for defects, goals and cones) and stated in docs/conventions.md.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass
from enum import StrEnum
from typing import Any

__all__ = ["Certificate", "Check", "CheckKind"]


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
        return f"{self.tolerance_key or self.name} {self.value:.3g} {op} {self.tolerance:.3g}"


@dataclass(frozen=True)
class Certificate(Mapping[str, float]):
    """The checks of one plan. As a mapping, it is the flat ``{name: value, "tol_<name>":
    tolerance}`` of the wire's ``certificate`` (values of checks without a tolerance of
    their own, such as the grasp angle, are reported too)."""

    checks: tuple[Check, ...] = ()
    #: Values reported without a check (e.g. the largest grasp angle).
    reported: tuple[tuple[str, float], ...] = ()
    #: Samples of the re-integrated motion the laws were checked at.
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

    def tolerances(self) -> dict[str, float]:
        """Every check's tolerance by its tolerance key."""
        return {c.tolerance_key or c.name: c.tolerance for c in self.checks
                if c.kind is not CheckKind.NUMERICS}

    def to_dict(self) -> dict[str, Any]:
        """``passed``, every value, ``n_samples``, ``tolerances`` and ``failures``."""
        values = {c.name: c.value for c in self.checks
                  if c.kind is not CheckKind.NUMERICS and c.report_value}
        return {"passed": self.passed, **values, **dict(self.reported),
                "n_samples": self.n_samples, "tolerances": self.tolerances(),
                "failures": list(self.failures)}

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
