"""What the wire models share: the contract's limits and names, the base classes of
requests and responses, IPOPT's primal-dual point (a request's ``warm_start`` and a
result's ``collocation`` both carry it), and how a request or result says its planner.

Import from :mod:`dexroll_client.models` (it re-exports everything).
"""

from __future__ import annotations

from typing import Annotated

from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, Strict, model_validator

__all__ = [
    "BUILTIN_FINGERS",
    "BUILTIN_HANDS",
    "MAX_DURATION",
    "MAX_FINGERS",
    "MAX_FINGER_JOINTS",
    "MAX_INTERVALS",
    "MAX_MOTION_KNOTS",
    "MAX_NLP_POINT",
    "MAX_POSITION",
    "MAX_SAMPLES",
    "MAX_SAMPLE_RATE",
    "MAX_URDF_CHARS",
    "MAX_VIA_POINTS",
    "MAX_WARM_START_COLUMNS",
    "MIN_DURATION",
    "MIN_SIZE",
    "PLANNERS",
    "Count",
    "NlpPointModel",
    "OptionalCount",
    "Real",
]

#: Limits of a request (the service's core enforces the same ones; a test checks).
MAX_INTERVALS = 2000
MAX_VIA_POINTS = 50
MAX_POSITION = 10.0  # m
MAX_DURATION = 3600.0  # s
#: The shortest horizon (and motion step) a request may ask for [s], and the smallest
#: length of an object or a pad [m]: below them the NLP's scaling breaks down (a 5e-324 s
#: horizon ended `numerical_error`), so they are refused at the door (422).
MIN_DURATION = 1e-3
MIN_SIZE = 1e-4
MAX_SAMPLES = 10_000
#: The highest controller rate a plan is sampled at [Hz].
MAX_SAMPLE_RATE = 10_000.0
#: Limits of a finger: joints of a URDF's chain, characters of a URDF document.
MAX_FINGER_JOINTS = 16
MAX_URDF_CHARS = 500_000

#: The planners, by the value of a request's ``planner`` field.
PLANNERS: tuple[str, ...] = ("ball_on_palm", "one_finger", "manipulation")
#: The built-in fingers, by the value of ``finger.builtin``.
BUILTIN_FINGERS: tuple[str, ...] = ("k3s",)
#: The built-in hands, by the value of ``hand.builtin``.
BUILTIN_HANDS: tuple[str, ...] = ("two_finger", "three_finger", "allegro")
#: Limits of a manipulation request: fingertips, knots of a desired motion.
MAX_FINGERS = 5
MAX_MOTION_KNOTS = 1000
#: Columns a warm start's states (or inputs) may have: the largest plan's (a free object's
#: 7 states and five fingertips of 5 contact coordinates and MAX_FINGER_JOINTS joints each).
MAX_WARM_START_COLUMNS = 7 + MAX_FINGERS * (5 + MAX_FINGER_JOINTS)


def _integral(value: object) -> object:
    """A JSON number without a fractional part (``60.0``) as the integer it is."""
    if isinstance(value, float) and value.is_integer():
        return int(value)
    return value


#: A request's real number: a JSON number, never a boolean (pydantic's lax mode would read
#: ``false`` as 0; strict floats take integers, not booleans or strings), and its integer
#: count: JSON Schema's ``integer`` (what openapi.json says), any number with a zero
#: fractional part (``60`` and ``60.0`` alike: JSON has one number type, and a client's
#: encoder may write either), never a boolean, a string or ``60.5``.
Real = Annotated[float, Strict()]
Count = Annotated[int, Strict(), BeforeValidator(_integral)]
#: An optional count (``Count | None``, the integral float read before the union: pydantic
#: then keeps a field's bounds on the integer in the JSON schema).
OptionalCount = Annotated[Annotated[int, Strict()] | None, BeforeValidator(_integral)]


class _Request(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False, frozen=True)


class _Response(BaseModel):
    # Responses ignore fields they do not know, so that a client keeps working when a newer
    # service adds one.
    model_config = ConfigDict(extra="ignore", allow_inf_nan=False)


#: Entries of a warm start's primal-dual point (the largest NLP's variables or constraints).
MAX_NLP_POINT = 500_000


class NlpPointModel(_Request):
    """IPOPT's primal-dual point at a plan, in the NLP's own (scaled) order: meaningful only
    to an NLP with the same fingerprint ``nlp`` (the same planner structure, grid and
    finger models), which a warm start from it then starts from (a few IPOPT iterations
    for a nearby problem instead of a cold solve's); ignored by any other NLP. Opaque:
    pass it back as it came."""

    nlp: str = Field(min_length=1, max_length=200, description="fingerprint of the NLP")
    w: list[Real] = Field(max_length=MAX_NLP_POINT, description="decision variables")
    lam_x: list[Real] = Field(max_length=MAX_NLP_POINT,
                               description="multipliers of the variable bounds")
    lam_g: list[Real] = Field(max_length=MAX_NLP_POINT,
                               description="multipliers of the constraints")

    @model_validator(mode="after")
    def _sizes(self) -> NlpPointModel:
        if len(self.lam_x) != len(self.w):
            raise ValueError(f"`lam_x` must have one entry per entry of `w` ({len(self.w)}), "
                             f"got {len(self.lam_x)}")
        return self



def _planner_of(value: object) -> str | None:
    """The ``planner`` of a request or result (a dict or a model); ``ball_on_palm`` when
    absent."""
    if isinstance(value, dict):
        planner = value.get("planner", "ball_on_palm")
        return planner if isinstance(planner, str) else None
    if isinstance(value, BaseModel):
        return getattr(value, "planner", None)
    return "ball_on_palm"  # not an object: the default planner's model says why
