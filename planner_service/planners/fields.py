"""Field paths: how the wire names the fields of a request, from the core's names or
pydantic's error locations.

The core (``ocp``) names a problem's fields by its own paths (``options.max_iter``,
``fingers[0].initial``, ``motion[2].orientation``); a request names them by its wire paths
(``solver.max_iter``, ``finger_contact.initial``, ``motion.orientations_wxyz[2]``). Each
planner's adapter holds one :class:`FieldMap` from the one to the other, and every error
the core reports passes through it before it reaches a user.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

from pydantic import ValidationError

from dexroll_client.models import PLANNERS

__all__ = ["FieldErrors", "FieldMap", "Rule", "planner_hint", "validation_errors",
           "wire_field"]

#: (field, reason) pairs: every check's answer, fields named by dotted paths.
FieldErrors = list[tuple[str, str]]

_TOKEN = re.compile(r"\[[^\]]*\]|[^.\[\]]+")
#: The tags a discriminated union puts in pydantic's error locations: the planner (a
#: request's first), a motion's kind.
_MOTION_TAGS = ("steps", "samples")


def _tokens(path: str) -> list[str]:
    """``motion[2].orientation`` -> ``["motion", "[2]", "orientation"]``."""
    return _TOKEN.findall(path)


def _join(tokens: Sequence[str]) -> str:
    out = ""
    for t in tokens:
        out += t if t.startswith("[") or not out else "." + t
    return out


@dataclass(frozen=True)
class Rule:
    """``core`` (a path) is called ``wire`` in a request. The rule matches the field
    ``core`` and every field under it (``core.x``, ``core[3]``); in ``core``, ``[{i}]``
    matches any index (which ``{i}`` in ``wire`` repeats) and ``{*}`` any one name.
    What follows the match is kept after ``wire`` unless ``keep_rest`` is false (every
    field under ``core`` is then reported as ``wire`` itself: a wire field the core's
    fields are derived from)."""

    core: str
    wire: str
    keep_rest: bool = True

    def apply(self, field: str) -> str | None:
        """The wire name of ``field`` by this rule; None when it does not match."""
        pattern, tokens = _tokens(self.core), _tokens(field)
        if len(tokens) < len(pattern):
            return None
        index = ""
        for p, t in zip(pattern, tokens, strict=False):
            if p == "[{i}]" and t.startswith("["):
                index = t[1:-1]
            elif p == "{*}" and not t.startswith("["):
                continue
            elif p != t:
                return None
        head = self.wire.replace("{i}", index)
        rest = tokens[len(pattern):] if self.keep_rest else []
        return _join([*_tokens(head), *rest])


class FieldMap:
    """The core's field paths -> a request's wire paths, by :class:`Rule` (the first that
    matches; a field no rule matches is named the same on the wire)."""

    def __init__(self, *rules: Rule) -> None:
        self.rules = rules

    def __add__(self, other: FieldMap) -> FieldMap:
        return FieldMap(*self.rules, *other.rules)

    def wire(self, field: str) -> str:
        for rule in self.rules:
            renamed = rule.apply(field)
            if renamed is not None:
                return renamed
        return field

    def errors(self, errors: Iterable[tuple[str, str]]) -> FieldErrors:
        """``errors`` with every field renamed to its wire name (reasons unchanged)."""
        return [(self.wire(field), reason) for field, reason in errors]


def wire_field(loc: Sequence[int | str]) -> str:
    """The dotted field of a pydantic error location in a request body, without the tags
    that discriminated unions put in it (the planner's first, a motion's kind); a batch's
    item is ``items[i]`` followed by its request's field."""
    parts = [str(p) for p in loc]
    if len(parts) > 1 and parts[0] == "items" and parts[1].isdigit():
        rest = wire_field(parts[2:])
        return f"items[{parts[1]}]" + (f".{rest}" if rest else "")
    if parts and parts[0] in PLANNERS:
        parts = parts[1:]
    if len(parts) > 1 and parts[0] == "motion" and parts[1] in _MOTION_TAGS:
        del parts[1]  # the tag of the motion's kind (also a manipulation request's)
    if len(parts) > 1 and parts[0] == "grasp" and parts[1] in ("auto", "search"):
        del parts[1]  # the tag of a grasp's form: the shorthand 'auto' or the object
    return ".".join(parts)


def validation_errors(exc: ValidationError) -> FieldErrors:
    """(field, reason) pairs of a pydantic error, with dotted field paths."""
    out = []
    for e in exc.errors(include_url=False):
        field = wire_field(e["loc"]) or "request"
        if e["type"] == "invalid_planner":
            field = "planner"
        out.append((field, str(e["msg"])))
    return out


def planner_hint(body: object, errors: FieldErrors) -> FieldErrors:
    """A request without ``planner`` is read as the default, 'ball_on_palm': when its
    errors include top-level fields that planner does not take and another planner
    takes them all (``hand`` and ``fingers`` are the manipulation planner's), the reason
    to give first, on ``planner``; [] otherwise."""
    from dexroll_client.requests import BallOnPalmRequest, ManipulationRequest, OneFingerRequest

    if not isinstance(body, dict) or "planner" in body:
        return []
    extra = sorted({f for f, why in errors if "." not in f and "[" not in f
                    and f in body and "not permitted" in why})
    if not extra:
        return []
    takers = [name for name, m in (("one_finger", OneFingerRequest),
                                   ("manipulation", ManipulationRequest))
              if set(extra) <= set(m.model_fields)]
    if not takers or set(extra) <= set(BallOnPalmRequest.model_fields):
        return []
    fields = ", ".join(f"`{f}`" for f in extra)
    return [("planner", f"not given, so the request is read as the default "
                        f"'ball_on_palm', which has no {fields}; "
                        + " or ".join(f"'{t}'" for t in takers)
                        + f" takes {'it' if len(extra) == 1 else 'them'}: name the "
                          "planner")]
