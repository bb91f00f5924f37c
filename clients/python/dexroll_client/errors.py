"""Exceptions raised by the dexroll clients, and the mapping from HTTP responses to them.

Every exception the clients raise on purpose derives from :class:`DexrollError`::

    DexrollError
     ├── TransportError            no HTTP response at all (connection refused, timeout, ...);
     │                             wraps the httpx exception (also as __cause__)
     ├── PlanTimeoutError          plan() gave up waiting; .job_id (None if no job was created)
     └── APIError                  the service answered 4xx/5xx (or a 2xx body that is not the
          │                        expected model); .status_code, .error (machine code),
          │                        .message, .detail: list[FieldError], .body: ErrorBody | None
          ├── InvalidRequestError  422: the service rejected the request (.detail names fields)
          ├── RequestTooLargeError 413: the request body is too large
          ├── UnauthorizedError    401: the service needs an API key (none or a wrong one)
          ├── NotFoundError        404: no such job
          ├── ConflictError        409: idempotency key reused with another body, or the job
          │                        is already finished (cancel)
          └── ServiceUnavailableError  503: queue full / not ready; .retry_after: float | None

A request dict that does not match the wire models fails *before* any HTTP with pydantic's
``ValidationError`` (not a ``DexrollError``), which names the offending field.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from datetime import UTC, datetime
from email.utils import parsedate_to_datetime

import httpx
from pydantic import ValidationError

from dexroll_client.models import ErrorBody, FieldError, Job

__all__ = [
    "APIError",
    "ConflictError",
    "DexrollError",
    "InvalidRequestError",
    "NotFoundError",
    "PlanTimeoutError",
    "RequestTooLargeError",
    "ServiceUnavailableError",
    "TransportError",
    "UnauthorizedError",
    "error_from_response",
    "parse_retry_after",
]

#: Longest excerpt of a non-JSON error body quoted in an APIError's message.
_EXCERPT = 200


class DexrollError(Exception):
    """Base class of every error raised by the dexroll clients."""


class TransportError(DexrollError):
    """The request got no HTTP response (DNS, connection refused, reset, timeout, ...).

    ``cause`` is the httpx exception (also chained as ``__cause__``); ``request`` the
    ``httpx.Request`` that failed, when httpx knows it.
    """

    def __init__(self, message: str, *, cause: httpx.RequestError | None = None) -> None:
        super().__init__(message)
        self.message = message
        self.cause = cause
        self.request: httpx.Request | None = None
        if cause is not None:
            try:
                self.request = cause.request
            except RuntimeError:  # httpx raises when the exception has no request attached
                self.request = None


class PlanTimeoutError(DexrollError):
    """``plan()`` gave up waiting for a terminal job.

    The job (if one was created: ``job_id`` is not None) keeps running on the service;
    fetch it later with ``get(job_id)`` or stop it with ``cancel(job_id)``. ``job`` is the
    last state seen, ``timeout`` the limit that was exceeded [s].
    """

    def __init__(self, message: str, *, job_id: str | None = None, job: Job | None = None,
                 timeout: float | None = None) -> None:
        super().__init__(message)
        self.message = message
        self.job_id = job_id
        self.job = job
        self.timeout = timeout


class APIError(DexrollError):
    """The service answered with an error status (4xx/5xx).

    ``error`` is the machine-readable code of the body (e.g. ``"invalid_request"``,
    ``"not_found"``), ``message`` its human-readable text, ``detail`` the per-field errors
    (``FieldError(field="goal.u", reason=...)``). ``body`` is the parsed
    :class:`~dexroll_client.models.ErrorBody`, or None when the response was not one (a
    proxy's HTML page, say; ``message`` then quotes its start). ``response`` is the
    ``httpx.Response`` (headers, raw text) when there was one.
    """

    def __init__(self, status_code: int, error: str, message: str, *,
                 detail: Sequence[FieldError] = (), body: ErrorBody | None = None,
                 response: httpx.Response | None = None) -> None:
        self.status_code = status_code
        self.error = error
        self.message = message
        self.detail: list[FieldError] = list(detail)
        self.body = body
        self.response = response
        super().__init__(self._describe())

    def _describe(self) -> str:
        text = f"HTTP {self.status_code} {self.error}: {self.message}"
        # the service's message usually lists the fields already: add only the others
        extra = [f"{d.field}: {d.reason}" for d in self.detail]
        extra = [e for e in extra if e not in self.message]
        return "; ".join([text, *extra])

    def fields(self) -> list[str]:
        """The dotted names of the fields in ``detail`` (e.g. ``["goal.u"]``)."""
        return [d.field for d in self.detail]


class InvalidRequestError(APIError):
    """422: the service rejected the request; ``detail`` names each offending field."""


class RequestTooLargeError(APIError):
    """413: the request body exceeds the service's size limit."""


class UnauthorizedError(APIError):
    """401: the service has API keys and the request carried none or a wrong one (give
    ``api_key`` to ``from_url``)."""


class NotFoundError(APIError):
    """404: no job (or route) with that id."""


class ConflictError(APIError):
    """409: idempotency key reused with a different body (``error`` tells which), or a
    cancel of a job that already finished (``error == "already_finished"``)."""


class ServiceUnavailableError(APIError):
    """503: the queue is full or the service is not ready. ``retry_after`` is the delay the
    service asked for [s] (None when it sent no valid ``Retry-After``)."""

    def __init__(self, status_code: int, error: str, message: str, *,
                 detail: Sequence[FieldError] = (), body: ErrorBody | None = None,
                 response: httpx.Response | None = None,
                 retry_after: float | None = None) -> None:
        self.retry_after = retry_after
        super().__init__(status_code, error, message, detail=detail, body=body,
                         response=response)


_BY_STATUS: dict[int, type[APIError]] = {
    401: UnauthorizedError,
    404: NotFoundError,
    409: ConflictError,
    413: RequestTooLargeError,
    422: InvalidRequestError,
    503: ServiceUnavailableError,
}


def parse_retry_after(value: str | None, *, now: datetime | None = None) -> float | None:
    """Seconds to wait from a ``Retry-After`` header: delta-seconds (fractions accepted) or
    an HTTP date. None when absent or unreadable; never negative."""
    if value is None:
        return None
    value = value.strip()
    try:
        seconds = float(value)
    except ValueError:
        try:
            when = parsedate_to_datetime(value)
        except (TypeError, ValueError, IndexError):
            return None
        if when.tzinfo is None:
            when = when.replace(tzinfo=UTC)
        seconds = (when - (now or datetime.now(UTC))).total_seconds()
    if not math.isfinite(seconds):
        return None
    return max(0.0, seconds)


def _excerpt(text: str) -> str:
    text = " ".join(text.split())
    return text if len(text) <= _EXCERPT else text[:_EXCERPT] + "..."


def error_from_response(response: httpx.Response) -> APIError:
    """The :class:`APIError` (subclass by status code) for an error response.

    Reads an :class:`ErrorBody` when the body is one; otherwise (HTML, plain text, empty,
    JSON of another shape) builds the error from the status line and an excerpt of the
    body, with ``body = None``.
    """
    status = response.status_code
    cls = _BY_STATUS.get(status, APIError)
    body: ErrorBody | None = None
    try:
        body = ErrorBody.model_validate_json(response.content)
    except ValidationError:
        body = None
    if body is not None:
        error, message, detail = body.error, body.message, body.detail
    else:
        error = f"http_{status}"
        reason = response.reason_phrase or "error"
        text = _non_error_body_text(response)
        message = f"{reason} (response body: {text})" if text else f"{reason} (empty body)"
        detail = []
    if cls is ServiceUnavailableError:
        return ServiceUnavailableError(
            status, error, message, detail=detail, body=body, response=response,
            retry_after=parse_retry_after(response.headers.get("Retry-After")))
    return cls(status, error, message, detail=detail, body=body, response=response)


def _non_error_body_text(response: httpx.Response) -> str:
    """An excerpt of a body that is not an ErrorBody (FastAPI's default ``{"detail": ...}``
    bodies are rendered as their ``detail``)."""
    try:
        text = response.text
    except (UnicodeDecodeError, LookupError):
        return f"<{len(response.content)} bytes>"
    try:
        data = json.loads(text)
    except ValueError:
        return _excerpt(text)
    if isinstance(data, dict) and "detail" in data:
        return _excerpt(str(data["detail"]))
    return _excerpt(text)
