"""The one certificate type: checks with name, value, tolerance and kind; refinement by kind;
the flat mapping the wire carries."""

from __future__ import annotations

import math

from ocp.certify.certificate import Certificate, Check, CheckKind

D, P = CheckKind.DISCRETISATION, CheckKind.PHYSICS


def test_a_check_passes_within_its_bound_and_nan_never_passes() -> None:
    assert Check("a", 1.0, 1.0, D).passed
    assert not Check("a", 1.0 + 1e-12, 1.0, D).passed
    assert Check("m", -0.5, -1.0, P, lower_bound=True).passed
    assert not Check("m", -1.5, -1.0, P, lower_bound=True).passed
    assert not Check("a", math.nan, 1.0, D).passed
    assert not Check("m", math.nan, 0.0, P, lower_bound=True).passed


def test_checks_of_one_name_merge_to_the_worst() -> None:
    """Several fingers' closure errors are one check: the largest (or, for a lower bound,
    the smallest) value wins, whatever the order."""
    checks = [Check("closure", 1e-6, 1e-4, D), Check("closure", 3e-4, 1e-4, D),
              Check("closure", 2e-5, 1e-4, D), Check("margin", 0.2, 0.0, P, lower_bound=True),
              Check("margin", -0.1, 0.0, P, lower_bound=True)]
    for order in (checks, checks[::-1]):
        cert = Certificate.of(order)
        assert cert.check("closure").value == 3e-4
        assert cert.check("margin").value == -0.1
        assert not cert.passed and len(cert.failures) == 2


def test_refinement_is_decided_by_kind() -> None:
    slip = Check("slip", 2.0, 1.0, D)
    cone = Check("cone", -1.0, 0.0, P, lower_bound=True)
    assert Certificate.of([slip]).refinable
    assert not Certificate.of([slip, cone]).refinable
    assert not Certificate.of([Check("slip", 0.5, 1.0, D)]).refinable  # nothing failed
    assert Certificate.of([slip, cone]).failed_kinds() == {D, P}


def test_the_mapping_is_the_wires_flat_values_and_tolerances() -> None:
    cert = Certificate.of([Check("max_slip", 1e-9, 1e-6, D),
                           Check("min_margin", 0.1, -1e-6, P, lower_bound=True,
                                 report_tolerance=False),
                           Check("onto", 0.0, 1.0, P, lower_bound=True, report_tolerance=False,
                                 report_value=False, reason="not onto")],
                          {"max_grasp_angle": 0.3})
    assert dict(cert) == {"max_slip": 1e-9, "min_margin": 0.1, "max_grasp_angle": 0.3,
                          "tol_max_slip": 1e-6}
    assert cert.failures == ("not onto",)


def test_a_plan_that_cannot_be_checked_fails_with_no_values() -> None:
    cert = Certificate.failed("re-integration failed: CVODES")
    assert not cert.passed and not cert.refinable
    assert cert.failures == ("re-integration failed: CVODES",) and dict(cert) == {}
