"""Exceptions raised by the QuadLoc SDK, mapped from RFC 9457 ``application/problem+json``.

Every error the server reports is a problem document
``{type, title, status, detail, instance, errors: [{field, message}, ...]}``; the SDK raises the
subclass of :class:`QuadLocError` matching its HTTP status and keeps every member of the
document on the exception. A "not localized" answer is NOT an error (HTTP 200 with
``localized: false``): look at :attr:`quadloc_sdk.models.LocalizeResponse.reason`.

Hierarchy::

    QuadLocError
    ├── TransportError            no HTTP answer (connection refused/reset, timeout), after retries
    └── APIError                  the server answered with a 4xx/5xx status
        ├── ClientError           4xx: fix the request, retrying will not help (except 429)
        │   ├── ValidationError   400 / 422, ``.errors`` lists the offending fields
        │   ├── Unauthorized      401: missing or unknown API key
        │   ├── Forbidden         403: the key lacks the scope (e.g. read-only key writing)
        │   ├── NotFound          404: unknown map (or map version)
        │   ├── Conflict          409: the map changed / already exists
        │   │   ├── PreconditionFailed    412: If-Match / expected version is stale
        │   │   └── PreconditionRequired  428: an update without If-Match
        │   ├── PayloadTooLarge   413
        │   └── RateLimited       429 (retried automatically; raised when retries run out)
        └── ServerError           5xx
            └── ServiceUnavailable 503 (retried automatically; raised when retries run out)
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any

import httpx

from quadloc_sdk.retry import parse_retry_after

__all__ = [
    "APIError",
    "ClientError",
    "Conflict",
    "FieldError",
    "Forbidden",
    "NotFound",
    "PayloadTooLarge",
    "PreconditionFailed",
    "PreconditionRequired",
    "QuadLocError",
    "RateLimited",
    "ServerError",
    "ServiceUnavailable",
    "TransportError",
    "Unauthorized",
    "ValidationError",
    "error_from_response",
]


@dataclass(frozen=True)
class FieldError:
    """One invalid field of a request: ``field`` is a path such as ``detections[2].ellipse.a``."""

    field: str
    message: str

    def __str__(self) -> str:
        return f"{self.field}: {self.message}"


class QuadLocError(Exception):
    """Base class of every SDK error."""


class TransportError(QuadLocError):
    """No HTTP response: the connection failed or timed out (after the retries allowed)."""

    def __init__(self, message: str, *, method: str, url: str, attempts: int) -> None:
        super().__init__(f"{method} {url}: {message} (after {attempts} attempt(s))")
        self.method = method
        self.url = url
        self.attempts = attempts


class APIError(QuadLocError):
    """The server answered with an error status; the problem document's members are attributes.

    ``status`` (int), ``type`` (URI identifying the problem kind), ``title``, ``detail``,
    ``instance``, ``errors`` (list of :class:`FieldError`), ``problem`` (the raw document or
    ``{}`` when the body was not problem JSON), ``method``/``url`` of the request,
    ``headers`` of the response, ``attempts`` made.
    """

    def __init__(
        self,
        *,
        status: int,
        method: str,
        url: str,
        problem: dict[str, Any] | None = None,
        text: str = "",
        headers: httpx.Headers | None = None,
        attempts: int = 1,
    ) -> None:
        self.status = status
        self.method = method
        self.url = url
        self.problem: dict[str, Any] = problem or {}
        self.type: str = str(self.problem.get("type", "about:blank"))
        self.title: str = str(self.problem.get("title", "")) or _reason_phrase(status)
        self.detail: str | None = (
            str(self.problem["detail"]) if self.problem.get("detail") is not None else None
        )
        self.instance: str | None = self.problem.get("instance")
        self.errors: list[FieldError] = _field_errors(self.problem.get("errors"))
        self.headers = headers or httpx.Headers()
        self.attempts = attempts
        self.text = text
        super().__init__(self._message())

    @property
    def fields(self) -> list[str]:
        """Names of the offending fields (possibly empty)."""
        return [e.field for e in self.errors]

    def _message(self) -> str:
        msg = f"{self.status} {self.title}"
        if self.detail:
            msg += f": {self.detail}"
        if self.errors:
            msg += " [" + "; ".join(str(e) for e in self.errors[:10])
            msg += f"; ... {len(self.errors) - 10} more]" if len(self.errors) > 10 else "]"
        if not self.problem and self.text:
            msg += f": {self.text[:200]}"
        return f"{msg} ({self.method} {self.url})"


class ClientError(APIError):
    """4xx: the request is wrong; sending it again unchanged will fail again."""


class ValidationError(ClientError):
    """400 / 422: the request failed validation; ``errors`` names each field and the problem."""


class Unauthorized(ClientError):  # noqa: N818 - HTTP status names read best
    """401: no API key, or an unknown one. Pass ``api_key=`` to the client."""


class Forbidden(ClientError):  # noqa: N818 - HTTP status names read best
    """403: the API key is valid but lacks the scope (``read`` or ``write``) this call needs."""


class NotFound(ClientError):  # noqa: N818 - HTTP status names read best
    """404: the map (or the requested version) does not exist."""


class Conflict(ClientError):  # noqa: N818 - HTTP status names read best
    """409: the map already exists or changed concurrently."""


class PreconditionFailed(Conflict):
    """412: the ``If-Match`` ETag / expected version is stale -- re-read the map and retry."""


class PreconditionRequired(Conflict):
    """428: updates must say which version they replace (``If-Match`` / expected version)."""


class PayloadTooLarge(ClientError):  # noqa: N818 - HTTP status names read best
    """413: the request body exceeds the server's size limit (split a batch)."""


class RateLimited(ClientError):  # noqa: N818 - HTTP status names read best
    """429: too many requests; ``retry_after`` (seconds or ``None``) is the server's advice."""

    @property
    def retry_after(self) -> float | None:
        return parse_retry_after(self.headers.get("retry-after"))


class ServerError(APIError):
    """5xx: the server failed. Report it with ``instance`` if present."""


class ServiceUnavailable(ServerError):  # noqa: N818 - HTTP status names read best
    """503: overloaded or not ready (e.g. database unreachable); retried automatically."""

    @property
    def retry_after(self) -> float | None:
        return parse_retry_after(self.headers.get("retry-after"))


_BY_STATUS: dict[int, type[APIError]] = {
    400: ValidationError,
    401: Unauthorized,
    403: Forbidden,
    404: NotFound,
    409: Conflict,
    412: PreconditionFailed,
    413: PayloadTooLarge,
    422: ValidationError,
    428: PreconditionRequired,
    429: RateLimited,
    503: ServiceUnavailable,
}


def _reason_phrase(status: int) -> str:
    try:
        from http import HTTPStatus

        return HTTPStatus(status).phrase
    except ValueError:
        return "Error"


def _field_errors(raw: Any) -> list[FieldError]:
    out: list[FieldError] = []
    if not isinstance(raw, list):
        return out
    for item in raw:
        if isinstance(item, dict):
            field = item.get("field", item.get("loc", ""))
            if isinstance(field, list):  # FastAPI-style loc lists, in case a proxy passes them
                field = ".".join(str(p) for p in field)
            out.append(FieldError(str(field), str(item.get("message", item.get("msg", "")))))
        else:
            out.append(FieldError("", str(item)))
    return out


def error_from_response(response: httpx.Response, *, attempts: int = 1) -> APIError:
    """The :class:`APIError` subclass for an error ``response`` (status >= 400).

    Parses the body as a problem document when it is JSON (``application/problem+json`` or
    ``application/json``; a proxy's HTML error page is kept as ``text``).
    """
    status = response.status_code
    problem: dict[str, Any] | None = None
    text = ""
    try:
        text = response.text
    except (httpx.ResponseNotRead, UnicodeDecodeError):
        text = ""
    ctype = response.headers.get("content-type", "")
    if "json" in ctype and text:
        try:
            parsed = json.loads(text)
        except ValueError:
            parsed = None
        if isinstance(parsed, dict):
            problem = parsed
    cls = _BY_STATUS.get(status)
    if cls is None:
        cls = ServerError if status >= 500 else ClientError
    request = response.request
    return cls(
        status=status,
        method=request.method,
        url=str(request.url),
        problem=problem,
        text=text,
        headers=response.headers,
        attempts=attempts,
    )
