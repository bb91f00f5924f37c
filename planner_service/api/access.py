"""Who may use the service: the Host header allow-list and the optional API keys.

* **Host**: a request whose ``Host`` header (without its port) is not in
  ``DEXROLL_ALLOWED_HOSTS`` (default: the loopback names ``127.0.0.1``, ``localhost``,
  ``::1``; ``*``: any) gets 400 ``invalid_host``. A web page a browser loaded from
  elsewhere can make the browser send requests to a loopback service by DNS rebinding, but
  with its own host name in ``Host``: refused.
* **API keys** (``DEXROLL_API_KEYS`` / ``DEXROLL_API_KEYS_FILE``: ``owner:key`` pairs):
  when set, every request but the health probes (``/healthz``, ``/readyz``) needs one, as
  ``Authorization: Bearer <key>`` or ``X-API-Key: <key>`` (401 ``unauthorized`` without a
  valid one), and jobs belong to the key's owner: another owner's job is a 404, its
  idempotency keys are its own, and the job list shows its own jobs. Without keys (the
  default: one user on loopback) every request is that user's, as before.

The owner of a request is ``request.state.owner`` (:data:`OwnerDep`; ``None`` without
keys: every job is visible).
"""

from __future__ import annotations

import hmac
from collections.abc import Awaitable, Callable, MutableMapping
from typing import Annotated, Any

from fastapi import Depends, Request

from .deps import error_response

__all__ = ["Access", "OwnerDep", "host_name"]

#: Paths served without a key (container and load-balancer health checks).
OPEN_PATHS = frozenset({"/healthz", "/readyz"})


def host_name(host: str) -> str:
    """A Host header's name, lower case, without its port (``[::1]:8000`` -> ``::1``)."""
    host = host.strip().lower()
    if host.startswith("["):
        return host[1:host.find("]")] if "]" in host else host
    return host.rsplit(":", 1)[0] if host.count(":") == 1 else host


class Access:
    """ASGI middleware: the Host allow-list, then the API key (see the module)."""

    def __init__(self, app: Callable[..., Awaitable[None]], keys: dict[str, str],
                 hosts: list[str]) -> None:
        self.app = app
        self.keys = [(k.encode(), owner) for k, owner in keys.items()]
        self.any_host = "*" in hosts
        self.hosts = {h.strip("[]") for h in hosts}

    def owner(self, headers: dict[bytes, bytes]) -> str | None:
        """The owner of the request's key; None when it has none or a wrong one."""
        given = headers.get(b"x-api-key")
        auth = headers.get(b"authorization", b"")
        if given is None and auth[:7].lower() == b"bearer ":
            given = auth[7:].strip()
        if not given:
            return None
        found = None
        for key, owner in self.keys:  # compare with every key, in constant time each
            if hmac.compare_digest(key, given):
                found = owner
        return found

    async def __call__(self, scope: MutableMapping[str, Any], receive: Any, send: Any) -> None:
        if scope["type"] not in ("http", "websocket"):
            await self.app(scope, receive, send)
            return
        headers = dict(scope.get("headers") or [])
        host = host_name(headers.get(b"host", b"").decode("latin-1"))
        socket = scope["type"] == "websocket"  # refused before the handshake: a 403
        if not self.any_host and host not in self.hosts:
            if socket:
                await send({"type": "websocket.close", "code": 1008,
                            "reason": "invalid_host"})
                return
            await error_response(
                400, "invalid_host", f"Host {host!r} is not served here (the service's "
                "DEXROLL_ALLOWED_HOSTS)")(scope, receive, send)
            return
        owner: str | None = None
        if self.keys and scope.get("path") not in OPEN_PATHS:
            owner = self.owner(headers)
            if owner is None and socket:
                await send({"type": "websocket.close", "code": 1008,
                            "reason": "unauthorized"})
                return
            if owner is None:
                await error_response(
                    401, "unauthorized", "an API key is required: `Authorization: Bearer "
                    "<key>` or `X-API-Key: <key>`",
                    headers={"WWW-Authenticate": "Bearer"})(scope, receive, send)
                return
        scope.setdefault("state", {})["owner"] = owner
        await self.app(scope, receive, send)


async def get_owner(request: Request) -> str | None:
    """The owner of the request (its API key's); None without keys: the one local user,
    who sees every job."""
    owner: str | None = getattr(request.state, "owner", None)
    return owner


OwnerDep = Annotated[str | None, Depends(get_owner)]
