"""API-key access control: scopes ``read`` and ``write`` (implies ``read``).

A key comes as ``Authorization: Bearer <key>`` or ``X-API-Key: <key>``; its sha256 is compared
in constant time with ``QUADLOC_API_KEYS``. Missing or unknown key -> 401, key without the
scope -> 403; without keys only loopback is served. Rules:
docs/design/service.md#api-key-access-control.
"""

from __future__ import annotations

import functools
import hmac
import ipaddress
from collections.abc import Callable, Coroutine
from typing import Annotated, Any

from fastapi import Depends, Request
from fastapi.security import APIKeyHeader, HTTPAuthorizationCredentials, HTTPBearer

from quadloc.service.api.errors import ProblemError
from quadloc.service.settings import ApiKey, hash_api_key

__all__ = ["ReadAccess", "WriteAccess", "authenticate", "check_access", "request_access",
           "require_scope"]

#: The ``WWW-Authenticate`` header of every 401.
_CHALLENGE = {"WWW-Authenticate": 'Bearer realm="quadloc"'}
_bearer = HTTPBearer(auto_error=False, description="API key as a bearer token.")
_api_key_header = APIKeyHeader(name="X-API-Key", auto_error=False,
                               description="API key in the X-API-Key header.")


def authenticate(keys: tuple[ApiKey, ...], presented: str | None, scope: str) -> ApiKey | None:
    """Check ``presented`` (clear-text key or None) for ``scope``.

    Returns the matching key (None when auth is disabled). Raises ``ProblemError`` 401/403.
    """
    if not keys:
        return None
    if not presented:
        raise ProblemError("unauthorized",
                           "this endpoint needs an API key: 'Authorization: Bearer <key>' or "
                           "'X-API-Key: <key>'",
                           field="header.authorization", message="missing",
                           headers=_CHALLENGE)
    digest = hash_api_key(presented)
    found = None
    for key in keys:  # constant time per key; no early exit
        if hmac.compare_digest(key.sha256, digest):
            found = key
    if found is None:
        raise ProblemError("unauthorized", "unknown API key",
                           field="header.authorization", message="unknown key",
                           headers=_CHALLENGE)
    if not found.allows(scope):
        raise ProblemError("forbidden", f"this API key lacks the '{scope}' scope "
                           f"(it has {sorted(found.scopes)})",
                           field="header.authorization", message=f"scope '{scope}' required")
    return found


@functools.lru_cache(maxsize=64)
def _loopback_or_not_ip(host: str) -> bool:
    """Whether ``host`` (a local address, from ``scope["server"]``) is a loopback IP address or
    not an IP address at all (cached: a server has few local addresses)."""
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return True


def _refuse_non_loopback(request: Request) -> None:
    """403 unless the request arrived on a loopback address (``scope["server"]``; non-IP
    names such as test clients and Unix sockets pass): an open server answers only there."""
    server = request.scope.get("server")
    host = server[0] if server else None
    if host and not _loopback_or_not_ip(str(host)):
        raise ProblemError("forbidden",
                           "this server has no API keys configured (QUADLOC_API_KEYS) and only "
                           "answers on loopback",
                           field="header.authorization",
                           message="server is open: loopback clients only")


def check_access(request: Request, bearer: HTTPAuthorizationCredentials | None,
                 api_key: str | None, scope: str) -> ApiKey | None:
    """The access rule of :func:`require_scope` for ``request`` with the credentials FastAPI's
    security schemes extracted (``_bearer``, ``_api_key_header``). Raises ``ProblemError``."""
    keys = request.app.state.api_keys
    if not keys:
        _refuse_non_loopback(request)
        return None
    authorization = request.headers.get("authorization")
    if authorization is not None and bearer is None:
        raise ProblemError("unauthorized", "the Authorization header must be "
                           "'Bearer <key>'",
                           field="header.authorization", message="not a bearer token",
                           headers=_CHALLENGE)
    presented = [c for c in (bearer.credentials if bearer else None, api_key) if c]
    if len(set(presented)) > 1:
        raise ProblemError("unauthorized", "Authorization and X-API-Key carry different "
                           "keys; send one",
                           field="header.x-api-key", message="conflicts with Authorization",
                           headers=_CHALLENGE)
    return authenticate(keys, presented[0] if presented else None, scope)


async def request_access(request: Request, scope: str) -> ApiKey | None:
    """:func:`check_access` with the credentials read from ``request`` by the same security
    schemes (for code that runs outside FastAPI's dependency injection)."""
    if not request.app.state.api_keys:  # an open server reads no credentials
        return check_access(request, None, None, scope)
    return check_access(request, await _bearer(request), await _api_key_header(request), scope)


def require_scope(scope: str) -> Callable[..., Coroutine[Any, Any, ApiKey | None]]:
    """FastAPI dependency enforcing ``scope`` for the route."""

    async def dependency(
        request: Request,
        bearer: Annotated[HTTPAuthorizationCredentials | None, Depends(_bearer)],
        api_key: Annotated[str | None, Depends(_api_key_header)],
    ) -> ApiKey | None:
        return check_access(request, bearer, api_key, scope)

    dependency.__name__ = f"require_{scope}"
    return dependency


ReadAccess = Annotated[ApiKey | None, Depends(require_scope("read"))]
WriteAccess = Annotated[ApiKey | None, Depends(require_scope("write"))]
