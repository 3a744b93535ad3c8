"""In-process store of tracking sessions: bounded in count, idle expiry, one lock per session.

Session ids carry this replica's tag (:func:`replica_id`) so the proxy routes a session to its
replica; beyond ``max_sessions`` live sessions (after evicting idle ones):
:class:`SessionCapacityError` (503). Why sessions live in process:
docs/design/service.md#session-store.
"""

from __future__ import annotations

import os
import re
import secrets
import socket
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field

from quadloc.service.schemas.common import Convention
from quadloc.service.tracking.session import TrackingSession

__all__ = ["SessionCapacityError", "SessionEntry", "SessionNotFound", "SessionStore"]


def replica_id() -> str:
    """This replica's tag in session ids: ``QUADLOC_REPLICA_ID``, else the hostname (the
    compose stack names its replicas ``quadloc-1``, ``quadloc-2``), reduced to ``[a-z0-9-]``.
    The proxy routes ``/v1/sessions/s-<tag>.<random>`` to that replica."""
    tag = (os.environ.get("QUADLOC_REPLICA_ID") or socket.gethostname()).lower()
    return re.sub(r"[^a-z0-9-]", "-", tag)[:40] or "local"


class SessionNotFound(KeyError):  # noqa: N818 (like quadloc.maps.errors.MapNotFound)
    """No live session with that id (never created, deleted, expired, or replica restarted)."""


class SessionCapacityError(RuntimeError):
    """The store is full of non-idle sessions."""


@dataclass
class SessionEntry:
    """A live session and its bookkeeping (``last_used`` is ``time.monotonic()``)."""

    session_id: str
    map_id: str
    map_version: int
    session: TrackingSession
    convention: Convention
    last_used: float
    lock: threading.Lock = field(default_factory=threading.Lock)


class SessionStore:
    """Thread-safe registry of :class:`SessionEntry` (see the module docstring)."""

    def __init__(self, max_sessions: int = 200, idle_timeout_s: float = 300.0,
                 clock: Callable[[], float] = time.monotonic) -> None:
        if max_sessions < 1 or not idle_timeout_s > 0:
            raise ValueError("max_sessions must be >= 1 and idle_timeout_s > 0")
        self.max_sessions = int(max_sessions)
        self.idle_timeout_s = float(idle_timeout_s)
        self._clock = clock
        self._lock = threading.Lock()
        self._entries: dict[str, SessionEntry] = {}

    def __len__(self) -> int:
        with self._lock:
            return len(self._entries)

    def expire(self) -> int:
        """Drop sessions idle for more than ``idle_timeout_s``; returns how many."""
        now = self._clock()
        with self._lock:
            dead = [k for k, e in self._entries.items()
                    if now - e.last_used > self.idle_timeout_s and not e.lock.locked()]
            for k in dead:
                del self._entries[k]
        return len(dead)

    def create(self, map_id: str, map_version: int, session: TrackingSession,
               convention: Convention) -> SessionEntry:
        """Register a new session under a fresh id ``s-<replica_id()>.<22 url-safe chars>``."""
        self.expire()
        now = self._clock()
        with self._lock:
            if len(self._entries) >= self.max_sessions:
                raise SessionCapacityError(
                    f"{len(self._entries)} live sessions (max {self.max_sessions})")
            sid = f"s-{replica_id()}." + secrets.token_urlsafe(16)
            entry = SessionEntry(sid, map_id, map_version, session, convention, now)
            self._entries[sid] = entry
            return entry

    def get(self, session_id: str) -> SessionEntry:
        """The live entry (touching its idle clock) or :class:`SessionNotFound`."""
        now = self._clock()
        with self._lock:
            entry = self._entries.get(session_id)
            if entry is None or now - entry.last_used > self.idle_timeout_s:
                self._entries.pop(session_id, None)
                raise SessionNotFound(session_id)
            entry.last_used = now
            return entry

    def delete(self, session_id: str) -> None:
        with self._lock:
            if self._entries.pop(session_id, None) is None:
                raise SessionNotFound(session_id)
