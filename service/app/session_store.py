"""In-process store of tracking sessions: bounded in count (per process and per key), idle
expiry, ownership, one lock per session.

Session ids carry this replica's tag (:func:`replica_id`) so the proxy routes a session to its
replica; beyond ``max_sessions`` live sessions (after evicting idle ones):
:class:`SessionCapacityError` (503); beyond ``max_per_owner`` sessions of one key:
:class:`SessionQuotaError` (429). A session belongs to the key that created it (another key
gets :class:`SessionNotFound`: :mod:`quadloc.service.app.ownership`). Its idle clock runs
from the END of its last request (:meth:`SessionStore.use`): a session is never idle while a
request holds it. Why sessions live in process: docs/design/service.md#session-store.
"""

from __future__ import annotations

import re
import secrets
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field

from quadloc.service.app.ownership import INTERNAL, Caller
from quadloc.service.schemas.common import Convention
from quadloc.service.settings import Settings
from quadloc.service.tracking.session import TrackingSession

__all__ = ["SessionCapacityError", "SessionEntry", "SessionNotFound", "SessionQuotaError",
           "SessionStore", "replica_id"]

#: This process's tag when none is configured: random, drawn once per process start (a tag
#: derived from the host name would publish it in every session id).
_PROCESS_TAG = "r" + secrets.token_hex(4)


def replica_id(configured: str = "") -> str:
    """This replica's tag in session ids: ``configured`` (``QUADLOC_REPLICA_ID``; the compose
    stack names its replicas ``quadloc-1``, ``quadloc-2``) reduced to ``[a-z0-9-]``, else a
    random tag of this process. The proxy routes ``/v1/sessions/s-<tag>.<random>`` to that
    replica."""
    tag = re.sub(r"[^a-z0-9-]", "-", configured.lower())[:40]
    return tag or _PROCESS_TAG


class SessionNotFound(KeyError):  # noqa: N818 (like quadloc.maps.errors.MapNotFound)
    """No live session with that id visible to the caller (never created, deleted, expired,
    replica restarted, or another key's)."""


class SessionCapacityError(RuntimeError):
    """The store is full of non-idle sessions."""


class SessionQuotaError(RuntimeError):
    """The caller's key holds its quota of live sessions."""


@dataclass
class SessionEntry:
    """A live session and its bookkeeping: ``last_used`` (``time.monotonic()``) is when its
    last request ended, ``in_use`` how many requests hold it now (both guarded by the store's
    lock), ``owner`` the creating key's sha256 (None without keys)."""

    session_id: str
    map_id: str
    map_version: int
    session: TrackingSession
    convention: Convention
    last_used: float
    owner: str | None = None
    in_use: int = 0
    lock: threading.Lock = field(default_factory=threading.Lock)


class SessionStore:
    """Thread-safe registry of :class:`SessionEntry` (see the module docstring).

    Args:
        max_sessions: live sessions of the process.
        idle_timeout_s: a session no request held for this long expires.
        clock: monotonic seconds (injectable for tests).
        max_per_owner: live sessions of one key (None: no per-key quota; sessions without an
            owner only count towards ``max_sessions``).
        replica_tag: the tag of the ids (default: :func:`replica_id` of the settings'
            ``replica_id``).
    """

    def __init__(self, max_sessions: int = 200, idle_timeout_s: float = 300.0,
                 clock: Callable[[], float] = time.monotonic, *,
                 max_per_owner: int | None = None, replica_tag: str | None = None) -> None:
        if max_sessions < 1 or not idle_timeout_s > 0:
            raise ValueError("max_sessions must be >= 1 and idle_timeout_s > 0")
        if max_per_owner is not None and max_per_owner < 1:
            raise ValueError("max_per_owner must be >= 1")
        self.max_sessions = int(max_sessions)
        self.max_per_owner = max_per_owner
        self.idle_timeout_s = float(idle_timeout_s)
        self.replica_tag = replica_id(Settings().replica_id if replica_tag is None
                                      else replica_tag)
        self._clock = clock
        self._lock = threading.Lock()
        self._entries: dict[str, SessionEntry] = {}

    def __len__(self) -> int:
        with self._lock:
            return len(self._entries)

    def _idle(self, entry: SessionEntry, now: float) -> bool:
        """Expired: no request holds it and the last one ended ``idle_timeout_s`` ago."""
        return entry.in_use == 0 and now - entry.last_used > self.idle_timeout_s

    def expire(self) -> int:
        """Drop sessions idle for more than ``idle_timeout_s``; returns how many."""
        now = self._clock()
        with self._lock:
            dead = [k for k, e in self._entries.items() if self._idle(e, now)]
            for k in dead:
                del self._entries[k]
        return len(dead)

    def create(self, map_id: str, map_version: int, session: TrackingSession,
               convention: Convention, owner: str | None = None) -> SessionEntry:
        """Register a new session of ``owner`` under a fresh id
        ``s-<replica tag>.<22 url-safe chars>``; :class:`SessionCapacityError` /
        :class:`SessionQuotaError` when full."""
        self.expire()
        now = self._clock()
        with self._lock:
            if len(self._entries) >= self.max_sessions:
                raise SessionCapacityError(
                    f"{len(self._entries)} live sessions (max {self.max_sessions})")
            if owner is not None and self.max_per_owner is not None:
                held = sum(1 for e in self._entries.values() if e.owner == owner)
                if held >= self.max_per_owner:
                    raise SessionQuotaError(
                        f"this API key holds {held} live sessions on this replica (max "
                        f"{self.max_per_owner}); end one (DELETE) or let one expire")
            sid = f"s-{self.replica_tag}." + secrets.token_urlsafe(16)
            entry = SessionEntry(sid, map_id, map_version, session, convention, now, owner)
            self._entries[sid] = entry
            return entry

    def _find(self, session_id: str, caller: Caller, now: float) -> SessionEntry:
        """The live entry visible to ``caller`` (lock held); an expired one is dropped."""
        entry = self._entries.get(session_id)
        if entry is not None and self._idle(entry, now):
            del self._entries[session_id]
            entry = None
        if entry is None or not caller.may_access(entry.owner):
            raise SessionNotFound(session_id)
        return entry

    def get(self, session_id: str, caller: Caller = INTERNAL) -> SessionEntry:
        """The live entry (a request that ends now: its idle clock restarts) or
        :class:`SessionNotFound`."""
        now = self._clock()
        with self._lock:
            entry = self._find(session_id, caller, now)
            entry.last_used = now
            return entry

    @contextmanager
    def use(self, session_id: str, caller: Caller = INTERNAL) -> Iterator[SessionEntry]:
        """Hold the live entry for a request (:class:`SessionNotFound` otherwise): it cannot
        expire meanwhile, and its idle clock restarts when the request ends."""
        with self._lock:
            entry = self._find(session_id, caller, self._clock())
            entry.in_use += 1
        try:
            yield entry
        finally:
            with self._lock:
                entry.in_use -= 1
                entry.last_used = self._clock()

    def delete(self, session_id: str, caller: Caller = INTERNAL) -> None:
        """End the session (:class:`SessionNotFound` if ``caller`` cannot see it)."""
        with self._lock:
            self._find(session_id, caller, self._clock())
            del self._entries[session_id]
