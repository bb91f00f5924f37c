"""Conversions every planner's adapter shares: request parts to the core's, the core's
arrays and certificates to wire values."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, TypeVar

import numpy as np

from dexroll_client.models import FingerCertificateModel, ForcesModel, ObjectModel, SolverModel
from ocp.certify.certificate import Certificate, CheckKind
from ocp.spec.problem import ForceSpec, ObjectSpec, SolverOptions

__all__ = ["all_finite", "check_tolerances", "check_values", "finger_certificate",
           "finite_or_none", "force_spec", "hand_fingers", "object_spec", "rows",
           "solver_options"]

CertificateT = TypeVar("CertificateT", bound=FingerCertificateModel)


def hand_fingers(request: Any, hand: Any) -> list[int] | None:
    """The request's fingers' indices into its whole hand's (``hand``: a
    :class:`~ocp.robots.whole_hand.WholeHand`), when every finger is one of them; None
    otherwise (no hand, fingers of their own, a hand of flat pads): the condition for
    checking the hand's own links and actuators."""
    if request.hand is None or not hasattr(hand, "collision") or any(
            f.finger is not None or f.hand_finger is None for f in request.fingers):
        return None
    return [int(f.hand_finger) for f in request.fingers]


def force_spec(f: ForcesModel | None) -> ForceSpec | None:
    """The core's load and grip of a request's ``forces`` (None: no forces planned)."""
    if f is None:
        return None
    inertia = None if f.inertia is None else (f.inertia[0], f.inertia[1], f.inertia[2])
    return ForceSpec(f.mass, inertia, (f.gravity[0], f.gravity[1], f.gravity[2]),
                     f.min_normal_force, f.torsional_friction, f.cone_margin)


def solver_options(o: SolverModel) -> SolverOptions:
    return SolverOptions(max_iter=o.max_iter, time_limit=o.time_limit,
                         cert_position_tol=o.cert_position_tol,
                         cert_angle_tol=o.cert_angle_tol)


def object_spec(o: ObjectModel) -> ObjectSpec:
    rv = o.chart_rotation
    return ObjectSpec(o.shape, tuple(o.dimensions), (rv[0], rv[1], rv[2]))


def rows(a: Any) -> list[Any]:
    """An array as (nested) lists of floats."""
    out: list[Any] = np.asarray(a, dtype=float).tolist()
    return out


def all_finite(d: dict[str, Any]) -> bool:
    return all(np.all(np.isfinite(np.asarray(v, dtype=float))) for v in d.values())


def finite_or_none(x: float) -> float | None:
    return float(x) if np.isfinite(x) else None


def check_values(certificate: Certificate) -> dict[str, float]:
    """The worst value of each of a certificate's checks by its name, then the values it
    reports without a check (e.g. the largest grasp angle). A ``numerics`` check (the plan
    could not be checked) has no value to report, nor has a check marked
    ``report_value=False``."""
    values = {c.name: c.value for c in certificate.checks
              if c.kind is not CheckKind.NUMERICS and c.report_value}
    values.update(certificate.reported)
    return values


def check_tolerances(certificate: Certificate) -> dict[str, float]:
    """The tolerance of each of a certificate's checks by its name (not a ``numerics``
    check's, nor one marked ``report_tolerance=False``)."""
    return {c.name: c.tolerance for c in certificate.checks
            if c.kind is not CheckKind.NUMERICS and c.report_tolerance}


def _same(text: str) -> str:
    return text


def finger_certificate(model: type[CertificateT], certificate: Certificate,
                       rename: Callable[[str], str] = _same) -> CertificateT:
    """The wire certificate of a plan with fingers (``model``: the planner's) from the
    core's typed one: each check's worst value and tolerance by name (finite ones: JSON has
    no NaN), the time of its worst sample, the failures. ``passed`` needs values: a plan
    that could not be checked has none. ``rename`` gives a check's (or a failure's) name
    in the planner's vocabulary."""
    values = {rename(k): float(v) for k, v in check_values(certificate).items()
              if math.isfinite(v)}
    tolerances = {rename(k): float(v) for k, v in check_tolerances(certificate).items()
                  if math.isfinite(v)}
    failures = [rename(f) for f in certificate.failures]
    return model(passed=bool(values) and not failures, values=values, tolerances=tolerances,
                 times={rename(k): v for k, v in certificate.times().items()},
                 failures=failures)
