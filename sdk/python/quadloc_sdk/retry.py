"""Retry policy of the SDK: exponential backoff with jitter, honouring ``Retry-After``.

What is retried (and what never is):

* HTTP **429** and **503** -- the server did not process the request (rate limit, overload,
  not ready). Any method. The wait is at least the server's ``Retry-After`` (seconds or an
  HTTP date) when present; a ``Retry-After`` longer than ``max_retry_after_s`` is not waited
  for: the error is raised at once so the app can reschedule.
* Connection failures that happen **before the request reaches the server**
  (``httpx.ConnectError``, ``ConnectTimeout``, ``PoolTimeout``) -- any method.
* Failures **after** the request may have been received (read/write errors and timeouts,
  a dropped connection) -- only for idempotent calls (GET, and localization, which computes
  without changing anything). Creating, updating or deleting a map is never replayed blindly.
* Never: any other 4xx (the request is wrong) or other 5xx.

Backoff before retry ``k`` (k = 1, 2, ...): ``base = min(max_backoff_s, initial_backoff_s *
multiplier**(k-1))`` and the wait is drawn uniformly in ``[base * (1 - jitter), base]``
("equal jitter" for ``jitter = 0.5``), so synchronized clients spread out after an outage.
"""

from __future__ import annotations

import email.utils
import math
import random
import time
from dataclasses import dataclass, field

import httpx

__all__ = ["RetryPolicy", "parse_retry_after"]

#: HTTP statuses that are retried (the server did not process the request).
RETRY_STATUSES = frozenset({429, 503})

#: Transport errors raised before the request could reach the server: always safe to retry.
_NOT_SENT_ERRORS: tuple[type[Exception], ...] = (
    httpx.ConnectError,
    httpx.ConnectTimeout,
    httpx.PoolTimeout,
)
#: Transport errors after which the server may have processed the request.
_MAYBE_SENT_ERRORS: tuple[type[Exception], ...] = (
    httpx.ReadTimeout,
    httpx.WriteTimeout,
    httpx.ReadError,
    httpx.WriteError,
    httpx.RemoteProtocolError,
)


def parse_retry_after(value: str | None, *, now: float | None = None) -> float | None:
    """Seconds to wait from a ``Retry-After`` header: delta-seconds (``"3"``, ``"1.5"``) or an
    HTTP date (``"Wed, 21 Oct 2015 07:28:00 GMT"``, relative to ``now``, default the current
    time). ``None`` when absent or unparseable; never negative."""
    if value is None:
        return None
    value = value.strip()
    try:
        seconds = float(value)
    except ValueError:
        try:
            when = email.utils.parsedate_to_datetime(value)
        except (TypeError, ValueError, IndexError):
            return None
        if when.tzinfo is None:
            return None
        seconds = when.timestamp() - (time.time() if now is None else now)
    if not math.isfinite(seconds):
        return None
    return max(0.0, seconds)


@dataclass
class RetryPolicy:
    """How many times and how long the client waits before retrying (see the module doc).

    ``max_attempts`` counts the first try (1 = never retry). Times in seconds.
    ``rng`` is the jitter's random source (seed it for reproducible waits in tests).
    """

    max_attempts: int = 4
    initial_backoff_s: float = 0.2
    multiplier: float = 2.0
    max_backoff_s: float = 5.0
    jitter: float = 0.5
    respect_retry_after: bool = True
    max_retry_after_s: float = 30.0
    rng: random.Random = field(default_factory=random.Random, repr=False)

    def __post_init__(self) -> None:
        if not (isinstance(self.max_attempts, int) and self.max_attempts >= 1):
            raise ValueError(f"max_attempts: must be an integer >= 1, got {self.max_attempts!r}")
        for name in ("initial_backoff_s", "max_backoff_s", "max_retry_after_s"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"{name}: must be finite and >= 0, got {v!r}")
        if not (math.isfinite(self.multiplier) and self.multiplier >= 1):
            raise ValueError(f"multiplier: must be >= 1, got {self.multiplier!r}")
        if not 0 <= self.jitter <= 1:
            raise ValueError(f"jitter: must be in [0, 1], got {self.jitter!r}")

    def backoff(self, retry_number: int) -> float:
        """Jittered wait in seconds before retry ``retry_number`` (1 for the first retry)."""
        base = min(
            self.max_backoff_s, self.initial_backoff_s * self.multiplier ** (retry_number - 1)
        )
        return base * (1.0 - self.jitter * self.rng.random())

    def delay_for_response(self, response: httpx.Response, retry_number: int) -> float | None:
        """Wait before retrying after ``response``, or ``None`` if it must not be retried."""
        if response.status_code not in RETRY_STATUSES:
            return None
        delay = self.backoff(retry_number)
        if self.respect_retry_after:
            advised = parse_retry_after(response.headers.get("retry-after"))
            if advised is not None:
                if advised > self.max_retry_after_s:
                    return None
                delay = max(delay, advised)
        return delay

    @staticmethod
    def retryable_exception(exc: Exception, *, idempotent: bool) -> bool:
        """Whether a transport exception may be retried for a call of this idempotency."""
        if isinstance(exc, _NOT_SENT_ERRORS):
            return True
        return idempotent and isinstance(exc, _MAYBE_SENT_ERRORS)
