"""One HTTP exchange of the SDK, as the clients perform it (with retries): the description shared
by the clients (:mod:`quadloc_sdk.client`) and the resources they hand out (tracking sessions,
:mod:`quadloc_sdk.session`; build jobs, :mod:`quadloc_sdk.build`)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

__all__ = ["Call"]


@dataclass(frozen=True)
class Call:
    """One HTTP exchange to perform (with retries); ``idempotent`` allows replay after a
    failure that may have reached the server (see :mod:`quadloc_sdk.retry`); ``timeout_s``:
    this exchange's read timeout (s) instead of the client's (a long synchronous request)."""

    method: str
    path: str
    params: dict[str, Any] | None = None
    body: bytes | None = None
    headers: dict[str, str] = field(default_factory=dict)
    idempotent: bool = False
    timeout_s: float | None = None
