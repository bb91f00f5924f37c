"""The wire contract grows only by additions: the published OpenAPI document
(tests/data/openapi_baseline.json, the contract before the wire models shared their bases)
is contained in the service's, every shipped example request still validates unchanged, and
the certificates built from the core's typed checks say what the flat ``tol_<name>``
mapping said."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import pytest

from dexroll_client.models import (
    FingerCertificateModel,
    FingerPlanResult,
    ManipulationCertificateModel,
    ManipulationRequest,
    ManipulationResult,
    OneFingerRequest,
    PlanRequestBase,
    PlanResult,
    PlanResultBase,
)
from ocp.certify.certificate import Certificate, Check, CheckKind
from planner_service.api.app import create_app
from planner_service.planners import REQUEST
from planner_service.planners.common import finger_certificate
from planner_service.planners.one_finger import one_finger_check_name
from planner_service.settings import Settings

ROOT = Path(__file__).resolve().parents[1]
BASELINE = json.loads((ROOT / "tests" / "data" / "openapi_baseline.json").read_text())


#: Bounds whose growth (upper) or decrease (lower) accepts more than before: what was
#: valid stays valid (an ellipsoid's dimensions: 2 semi-axes, now 2 or 3).
_UPPER = ("maxItems", "maxLength", "maximum", "exclusiveMaximum")
_LOWER = ("minItems", "minLength", "minimum", "exclusiveMinimum")


def _widened(key: str, old: Any, new: Any) -> bool:
    """Whether a bound ``key`` went from ``old`` to ``new`` by accepting more."""
    numbers = all(isinstance(v, int | float) and not isinstance(v, bool) for v in (old, new))
    return numbers and ((key in _UPPER and new >= old) or (key in _LOWER and new <= old))


def _missing(old: Any, new: Any, where: str) -> list[str]:
    """What of ``old`` (a JSON schema document) ``new`` lacks or states otherwise: every
    key of an object, every item of a list (``required`` and ``enum`` as sets), every
    scalar equal, but for bounds that widen (:func:`_widened`). Descriptions and summaries
    are prose: they may be reworded when what they describe grows (a route's readiness
    checking more), the contract they describe may not shrink."""
    if isinstance(old, dict):
        if not isinstance(new, dict):
            return [f"{where}: was an object"]
        out = []
        for key, value in old.items():
            if key not in new:
                out.append(f"{where}/{key}: removed")
            elif (key in ("description", "summary") and isinstance(value, str)
                  and isinstance(new[key], str)) or _widened(key, value, new[key]):
                continue
            else:
                out += _missing(value, new[key], f"{where}/{key}")
        return out
    if isinstance(old, list):
        if not isinstance(new, list):
            return [f"{where}: was a list"]
        if where.endswith(("/required", "/enum")):
            gone = [v for v in old if v not in new]
            return [f"{where}: {gone} removed"] if gone else []
        if len(old) != len(new):  # e.g. anyOf: a type may not widen or narrow
            return [f"{where}: {len(old)} items, now {len(new)}"]
        return [m for i, (a, b) in enumerate(zip(old, new, strict=True))
                for m in _missing(a, b, f"{where}[{i}]")]
    return [] if old == new else [f"{where}: {old!r}, now {new!r}"]


def _corrected(baseline: dict[str, Any]) -> dict[str, Any]:
    """The baseline with what it stated and the service never did put right: a one-finger
    body without ``planner`` was always read as a ball_on_palm request (the discriminator's
    default), so the field is required and has no default (issue 25, item 7)."""
    out = json.loads(json.dumps(baseline))
    one_finger = out["components"]["schemas"]["OneFingerRequest"]
    one_finger["properties"]["planner"].pop("default")
    one_finger["required"] = ["planner", *one_finger["required"]]
    return out


def test_the_published_contract_only_grows() -> None:
    new = create_app(Settings()).openapi()
    baseline = _corrected(BASELINE)
    assert _missing(baseline["paths"], new["paths"], "paths") == []
    old_schemas, new_schemas = baseline["components"]["schemas"], new["components"]["schemas"]
    assert set(old_schemas) <= set(new_schemas)
    for name, schema in old_schemas.items():
        assert _missing(schema, new_schemas[name], name) == [], name
        # the same required fields: none newly required (an old request would be refused)
        assert set(new_schemas[name].get("required", [])) == set(schema.get("required", [])), \
            name


def test_the_comparison_sees_a_removed_property_a_new_type_and_a_new_requirement() -> None:
    schema = BASELINE["components"]["schemas"]["StatsModel"]
    gone = json.loads(json.dumps(schema))
    del gone["properties"]["attempts"]
    assert _missing(schema, gone, "s") == ["s/properties/attempts: removed"]
    retyped = json.loads(json.dumps(schema))
    retyped["properties"]["attempts"]["type"] = "number"
    assert _missing(schema, retyped, "s") == ["s/properties/attempts/type: 'integer', "
                                              "now 'number'"]
    assert _missing(schema, {**schema, "required": ["raw_status"]}, "s") != []


EXAMPLES = sorted((ROOT / "examples").glob("*.json"))


@pytest.mark.parametrize("path", EXAMPLES, ids=[p.stem for p in EXAMPLES])
def test_every_example_request_validates_unchanged(path: Path) -> None:
    # (the bench suites' generated requests: tests/test_bench.py)
    body = json.loads(path.read_text())
    request = REQUEST.validate_python(body)
    assert isinstance(request, PlanRequestBase)
    assert request.model_dump(mode="json", exclude_unset=True) == body
    assert REQUEST.validate_json(path.read_text()) == request


def test_every_request_and_result_is_on_the_shared_bases() -> None:
    for model in (OneFingerRequest, ManipulationRequest):
        assert issubclass(model, PlanRequestBase)
        # the shared fields are the base's declarations (only `planner` is narrowed)
        for name, field in PlanRequestBase.model_fields.items():
            if name != "planner":
                assert repr(model.model_fields[name]) == repr(field), (model, name)
    for result in (PlanResult, FingerPlanResult, ManipulationResult):
        assert issubclass(result, PlanResultBase)
    assert issubclass(ManipulationCertificateModel, FingerCertificateModel)
    # the sample-time checks are the base's, for every planner
    with pytest.raises(ValueError, match="sample times must lie in"):
        ManipulationRequest.model_validate(
            json.loads((ROOT / "examples" / "three_finger_turn.json").read_text())
            | {"sample_times": [0.0, 1e3]})


# -- the certificate, typed to the adapter ----------------------------------------------------

def _flat_certificate(model: type[FingerCertificateModel], flat: dict[str, float],
                      failures: list[str], times: dict[str, float]) -> FingerCertificateModel:
    """The wire certificate as it was built from the flat mapping (split by prefix)."""
    values = {k: float(v) for k, v in flat.items()
              if not k.startswith("tol_") and math.isfinite(v)}
    tolerances = {k.removeprefix("tol_"): float(v) for k, v in flat.items()
                  if k.startswith("tol_") and math.isfinite(v)}
    return model(passed=bool(values) and not failures, values=values, tolerances=tolerances,
                 times=times, failures=failures)


CERTIFICATES = {
    "passed": Certificate.of(
        [Check("max_length_defect", 1e-7, 1e-5, CheckKind.DISCRETISATION),
         Check("max_slip_speed_palm", 2e-6, 1e-3, CheckKind.DISCRETISATION, time=0.25),
         Check("max_pad_excursion_finger", 0.003, 0.004, CheckKind.LIMITS, time=1.0),
         Check("min_cone_margin", 0.1, -1e-6, CheckKind.PHYSICS, lower_bound=True,
               report_tolerance=False),
         Check("force_closure", 1.0, 0.0, CheckKind.PHYSICS, lower_bound=True,
               report_tolerance=False, report_value=False)],
        reported={"max_grasp_angle": 0.4}, n_samples=99),
    "failed": Certificate.of(
        [Check("max_length_defect", 3e-5, 1e-5, CheckKind.DISCRETISATION, time=0.5),
         Check("max_joint_limit_violation_finger", math.inf, 1e-6, CheckKind.LIMITS),
         Check("max_goal_error", math.nan, 1e-5, CheckKind.GOAL,
               tolerance_key="goal")]),
    "unchecked": Certificate.failed("CVODES gave up"),
}


@pytest.mark.parametrize("name", list(CERTIFICATES))
def test_the_typed_certificate_gives_what_the_flat_mapping_gave(name: str) -> None:
    c = CERTIFICATES[name]
    for model in (FingerCertificateModel, ManipulationCertificateModel):
        typed = finger_certificate(model, c)
        assert typed.model_dump_json() == _flat_certificate(
            model, dict(c), list(c.failures), c.times()).model_dump_json()
    # the one-finger planner's names, as its core solution restates the flat mapping
    flat = {one_finger_check_name(k): v for k, v in c.items()}
    renamed = finger_certificate(FingerCertificateModel, c, one_finger_check_name)
    assert renamed.model_dump_json() == _flat_certificate(
        FingerCertificateModel, flat, [one_finger_check_name(f) for f in c.failures],
        {one_finger_check_name(k): v for k, v in c.times().items()}).model_dump_json()


def test_the_one_finger_names_are_the_core_solutions() -> None:
    from ocp.one_finger import _rename  # the core's restatement of the general plan's names

    for text in ("max_length_defect", "tol_max_length_defect", "max_pad_excursion_finger",
                 "max_joint_limit_violation_finger 0.1 > 1e-06 at t = 0.5 s",
                 "max_slip_speed_finger", "max_angle_defect"):
        assert one_finger_check_name(text) == _rename(text)
