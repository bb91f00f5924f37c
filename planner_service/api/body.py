"""Reading a JSON request body before FastAPI and pydantic see it: the body must be UTF-8
text (UTF-16 and UTF-32, which ``json.loads`` would guess from the bytes, are refused), no
object in it may have more keys than any object of a request has fields (thousands of
unknown keys would otherwise cost pydantic an error each: seconds and megabytes), and an
integer too long for Python to read is named by its path. Every refusal is a
:class:`BodyError`: a field and a reason, answered as a 422.

:class:`JSONBodyRoute` is the route class that does this for a route with a JSON body; the
decoded body is handed on as ``request.json()``'s (FastAPI then validates it as before, so
the OpenAPI document does not change).
"""

from __future__ import annotations

import asyncio
import email.message
import json
import sys
from collections.abc import Callable, Coroutine
from typing import Any

from fastapi import Request, Response
from fastapi.routing import APIRoute
from pydantic import TypeAdapter

from dexroll_client.models import ErrorBody, FieldError, PlanRequest
from dexroll_client.simulation import SimulationOptions

__all__ = ["MAX_OBJECT_KEYS", "BodyError", "JSONBodyRoute", "decode_json_body"]

#: The most keys an object of a request body may have: more than any request object has
#: fields (the largest, a manipulation request, has 28; a test pins the margin).
MAX_OBJECT_KEYS = 100
#: How many unknown keys of an object with too many a 422 names (the rest are counted).
SHOWN_KEYS = 5
#: Bodies over this many bytes are decoded in a thread (the event loop keeps answering).
_THREAD_BYTES = 64 * 1024


class BodyError(Exception):
    """A body refused before validation: ``field`` (dotted path; ``body`` for the whole)
    and ``reason``."""

    def __init__(self, field: str, reason: str) -> None:
        super().__init__(f"{field}: {reason}")
        self.field, self.reason = field, reason


def _field_names() -> frozenset[str]:
    """Every field name of every object a request body may hold."""
    names: set[str] = set()
    models: tuple[Any, ...] = (PlanRequest, SimulationOptions)
    for model in models:
        schema = TypeAdapter(model).json_schema(by_alias=True)
        for definition in [schema, *schema.get("$defs", {}).values()]:
            names |= set(definition.get("properties", {}))
    return frozenset(names)


_FIELD_NAMES: frozenset[str] | None = None


def known_field_names() -> frozenset[str]:
    global _FIELD_NAMES
    if _FIELD_NAMES is None:
        _FIELD_NAMES = _field_names()
    return _FIELD_NAMES


class _TooLarge:
    """An integer literal Python refuses to convert (more digits than
    ``sys.get_int_max_str_digits()``), kept until its path is known."""

    def __init__(self, digits: int) -> None:
        self.digits = digits


class _Crowded(dict[str, Any]):
    """An object with more than MAX_OBJECT_KEYS keys, kept until its path is known."""


def _path(parts: list[str | int]) -> str:
    return ".".join(str(p) for p in parts) or "body"


def _find(value: Any, kind: type, parts: list[str | int]) -> tuple[Any, str] | None:
    """The first instance of ``kind`` in ``value`` (depth first) and its dotted path."""
    stack: list[tuple[Any, list[str | int]]] = [(value, parts)]
    while stack:
        item, at = stack.pop()
        if isinstance(item, kind):
            return item, _path(at)
        if isinstance(item, dict):
            stack += [(v, [*at, k]) for k, v in reversed(item.items())]
        elif isinstance(item, list):
            stack += [(v, [*at, i]) for i, v in reversed(list(enumerate(item)))]
    return None


def _not_utf8(raw: bytes) -> BodyError | None:
    """Why ``raw`` is not UTF-8 JSON text (None: it is UTF-8)."""
    hint = ""
    if raw[:2] in (b"\xff\xfe", b"\xfe\xff") or raw[:4] in (b"\x00\x00\xfe\xff",):
        hint = "; its byte-order mark says UTF-16 or UTF-32"
    try:
        raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        return BodyError("body", f"not valid JSON: the body is not UTF-8 text (byte "
                                 f"{exc.start}: {exc.reason}{hint})")
    nul = raw.find(b"\x00")
    if nul >= 0:  # never in JSON text: UTF-16 or UTF-32 without a byte-order mark
        return BodyError("body", f"not valid JSON: the body is not UTF-8 text (byte {nul}: "
                                 "a NUL byte, as UTF-16 or UTF-32 text has)")
    return None


def decode_json_body(raw: bytes) -> Any:
    """The JSON value of a request body; BodyError when it is not UTF-8 JSON text, has an
    object with more than MAX_OBJECT_KEYS keys or an integer too long to read."""
    refused = _not_utf8(raw)
    if refused is not None:
        raise refused
    flags = {"too_large": False, "crowded": False}

    def parse_int(text: str) -> Any:
        try:
            return int(text)
        except ValueError:
            flags["too_large"] = True
            return _TooLarge(len(text.lstrip("-")))

    def pairs(items: list[tuple[str, Any]]) -> dict[str, Any]:
        if len(items) > MAX_OBJECT_KEYS:
            flags["crowded"] = True
            return _Crowded(items)
        return dict(items)

    text = raw.decode("utf-8-sig")  # a UTF-8 byte-order mark is allowed (RFC 8259)
    try:
        value = json.loads(text, parse_int=parse_int, object_pairs_hook=pairs)
    except json.JSONDecodeError as exc:
        raise BodyError("body", f"not valid JSON: {exc.msg} (line {exc.lineno}, column "
                                f"{exc.colno})") from exc
    except RecursionError as exc:
        raise BodyError("body", "not valid JSON: nested too deeply (arrays and objects "
                                "within each other)") from exc
    if flags["crowded"]:
        found = _find(value, _Crowded, [])
        assert found is not None
        crowded, where = found
        names = known_field_names()
        unknown = [k for k in crowded if k not in names]
        shown = ", ".join(repr(k) for k in unknown[:SHOWN_KEYS])
        more = f" …and {len(unknown) - SHOWN_KEYS:,} more" if len(unknown) > SHOWN_KEYS \
            else ""
        raise BodyError(where, f"{len(crowded):,} keys in one object, of which "
                               f"{len(unknown):,} are not a field of any request object "
                               f"(no object has more than {MAX_OBJECT_KEYS} fields): "
                               f"unknown fields {shown}{more}")
    if flags["too_large"]:
        found = _find(value, _TooLarge, [])
        assert found is not None
        number, where = found
        raise BodyError(where, f"a number too large: an integer of {number.digits:,} "
                               f"digits (at most {sys.get_int_max_str_digits():,} are "
                               "read)")
    return value


def _is_json(request: Request) -> bool:
    """Whether FastAPI would read the body as JSON (no content type, or a JSON one)."""
    value = request.headers.get("content-type")
    if not value:
        return True
    message = email.message.Message()
    message["content-type"] = value
    subtype = message.get_content_subtype()
    return message.get_content_maintype() == "application" and (
        subtype == "json" or subtype.endswith("+json"))


class JSONBodyRoute(APIRoute):
    """A route whose JSON body is decoded by :func:`decode_json_body` first: a body it
    refuses is a 422 naming the field, before pydantic sees it."""

    def get_route_handler(self) -> Callable[[Request], Coroutine[Any, Any, Response]]:
        handler = super().get_route_handler()

        async def decoded_first(request: Request) -> Response:
            raw = await request.body()
            if raw and _is_json(request):
                try:
                    value = (await asyncio.to_thread(decode_json_body, raw)
                             if len(raw) > _THREAD_BYTES else decode_json_body(raw))
                except BodyError as exc:
                    body = ErrorBody(error="invalid_request", message=str(exc),
                                     detail=[FieldError(field=exc.field, reason=exc.reason)])
                    return Response(body.model_dump_json(), 422,
                                    media_type="application/json")
                request._json = value  # what request.json() returns (Starlette's cache)
            return await handler(request)

        return decoded_first
