"""The tracking-session use cases: start a session on a map, describe it, end it, add frames.

Sessions live in this process (:class:`quadloc.service.app.session_store.SessionStore`: at most
``max_sessions`` live and ``max_sessions_per_key`` per key, each expiring
``session_idle_timeout_s`` after the end of its last request; ids carry this replica's tag so
that a proxy routes a session to its replica). A session belongs to the key that created it:
another key gets ``session-not-found``, an ``admin`` key sees all
(:mod:`quadloc.service.app.ownership`). The map version (and its own calibration, if stored:
``calibration_of``) is
loaded once at creation, through the :class:`MapLoader` (the same bounded wait as localize).
A frames request is validated whole before any frame is fused (an error names
``frames[i]....`` and leaves the session unchanged); its frames are fused in order, each
holding one of the process's solver slots (the ones localize uses), so that sessions and
single frames share the CPU fairly. Design: docs/design/service.md#tracking-session-routes.
"""

from __future__ import annotations

import threading
from collections.abc import Callable

from quadloc.factors.budget import Deadline, earliest
from quadloc.factors.names import GeometryError
from quadloc.maps.zones import zone_index
from quadloc.service.app.conversions import (
    camera_from_request,
    frame_input_from_wire,
    frame_out,
    session_options_from_wire,
)
from quadloc.service.app.errors import AppError, invalid_input
from quadloc.service.app.localization import BUSY_RETRY_AFTER_S, FairSlots
from quadloc.service.app.map_loader import MapLoader
from quadloc.service.app.ownership import INTERNAL, Caller
from quadloc.service.app.session_store import (
    SessionCapacityError,
    SessionEntry,
    SessionNotFound,
    SessionQuotaError,
    SessionStore,
)
from quadloc.service.localization.calibration_fit import CalibrationConstants
from quadloc.service.localization.types import LocalizationInputError
from quadloc.service.schemas.sessions import (
    SessionCreate,
    SessionFrameIn,
    SessionFramesIn,
    SessionFramesOut,
    SessionOut,
)
from quadloc.service.settings import Settings
from quadloc.service.tracking.session import FrameInput, TrackingInputError, TrackingSession

__all__ = ["SESSION_CAPACITY_RETRY_AFTER_S", "SessionService"]

#: ``Retry-After`` (s) when the process holds ``max_sessions`` live sessions.
SESSION_CAPACITY_RETRY_AFTER_S = 30.0
#: The input errors of a frame or a session's parameters (each names its field).
_INPUT_ERRORS = (GeometryError, LocalizationInputError, TrackingInputError)


class SessionService:
    """The session use cases of a process (see the module docstring).

    Args:
        settings: ``max_sessions``, ``session_idle_timeout_s``, ``solve_queue_timeout_s``.
        maps: where map versions are loaded.
        slots: the process's solver slots (shared with localize).
        calibration_of: a map version's own calibration (``quadloc calibrate``), None: the
            shipped constants (the localizer's: ``CalibrationService.constants_of``).
    """

    def __init__(self, settings: Settings, maps: MapLoader, slots: FairSlots,
                 calibration_of: Callable[[str, int], CalibrationConstants | None] | None
                 = None) -> None:
        self.maps = maps
        self.calibration_of = calibration_of or (lambda _map_id, _version: None)
        self.slots = slots
        self.queue_timeout_s = settings.solve_queue_timeout_s
        self.frame_budget_ms = settings.session_frame_budget_ms
        self.request_budget_ms = settings.session_request_budget_ms
        self._stopping = threading.Event()
        self.store = SessionStore(settings.max_sessions, settings.session_idle_timeout_s,
                                  max_per_owner=settings.max_sessions_per_key,
                                  replica_tag=settings.replica_id)

    def create(self, map_id: str, body: SessionCreate, caller: Caller = INTERNAL) -> SessionOut:
        """Start a session of ``caller`` on the latest version of ``map_id``;
        ``map-not-found``, ``validation-error`` (a bad camera or option), ``session-capacity``,
        ``session-quota``."""
        compiled = self.maps.get(map_id)
        try:
            session = TrackingSession(compiled, camera_from_request(body.camera),
                                      session_options_from_wire(body.options),
                                      self.calibration_of(compiled.map_id, compiled.version))
        except _INPUT_ERRORS as exc:
            raise invalid_input(exc) from exc
        try:
            entry = self.store.create(map_id, compiled.version, session, body.convention,
                                      caller.owner)
        except SessionCapacityError as exc:
            raise AppError("session-capacity", str(exc),
                           retry_after_s=SESSION_CAPACITY_RETRY_AFTER_S) from exc
        except SessionQuotaError as exc:
            raise AppError("session-quota", str(exc),
                           retry_after_s=SESSION_CAPACITY_RETRY_AFTER_S) from exc
        return self._out(entry)

    def get(self, session_id: str, caller: Caller = INTERNAL) -> SessionOut:
        """The session's description (touches its idle clock); ``session-not-found`` (also
        for another key's session)."""
        try:
            return self._out(self.store.get(session_id, caller))
        except SessionNotFound as exc:
            raise _not_found(session_id) from exc

    def delete(self, session_id: str, caller: Caller = INTERNAL) -> None:
        """End the session; ``session-not-found`` (also for another key's session)."""
        try:
            self.store.delete(session_id, caller)
        except SessionNotFound as exc:
            raise _not_found(session_id) from exc

    def close(self, stop: bool = True) -> None:
        """The process is stopping (``stop``; False: it serves again): the frames being fused
        stop at their next stage, later ones are answered ``time_budget_exceeded`` without
        work."""
        if stop:
            self._stopping.set()
        else:
            self._stopping.clear()

    def add_frames(self, session_id: str, body: SessionFramesIn | SessionFrameIn,
                   caller: Caller = INTERNAL, cancel: threading.Event | None = None
                   ) -> SessionFramesOut:
        """Fuse one frame, or a batch in time order (see the module docstring); errors name
        ``frames[i]....`` for a batch, the frame's own fields otherwise. The session is held
        for the whole request (:meth:`SessionStore.use`): its idle clock restarts at the end.
        Each frame has the CPU budget ``session_frame_budget_ms``, the request
        ``session_request_budget_ms``; ``cancel`` (set when the client went away) and
        :meth:`close` end the work like a budget (frames answered ``time_budget_exceeded``)."""
        try:
            with self.store.use(session_id, caller) as entry:
                return self._add_frames(entry, body, cancel)
        except SessionNotFound as exc:
            raise _not_found(session_id) from exc

    def _add_frames(self, entry: SessionEntry, body: SessionFramesIn | SessionFrameIn,
                    cancel: threading.Event | None = None) -> SessionFramesOut:
        """:meth:`add_frames` on the held ``entry``."""
        batch = isinstance(body, SessionFramesIn)
        frames = body.frames if isinstance(body, SessionFramesIn) else [body]
        with entry.lock:
            inputs = self._validated(entry, frames, batch)
            # CPU time of this thread (it fuses every frame of the request), from here
            request = Deadline.cpu_budget(self.request_budget_ms).cancelled_by(
                self._stopping, *(() if cancel is None else (cancel,)))
            results = []
            for i, frame in enumerate(inputs):
                if request.passed():  # counted, not fused: no slot needed
                    results.append(frame_out(entry.session.add_frame(frame, request),
                                             entry.convention))
                    continue
                # the first frame may wait for a slot only as long as a localize would; later
                # ones take their turn (a batch half fused is never refused)
                if not self.slots.acquire(timeout=self.queue_timeout_s if i == 0 else None):
                    raise AppError("busy", "all solver slots are busy; retry shortly",
                                   retry_after_s=BUSY_RETRY_AFTER_S)
                try:
                    result = entry.session.add_frame(
                        frame, earliest(request, Deadline.cpu_budget(self.frame_budget_ms)))
                except _INPUT_ERRORS as exc:
                    raise invalid_input(exc, f"frames[{i}]." if batch else "") from exc
                finally:
                    self.slots.release()
                results.append(frame_out(result, entry.convention,
                                         zone_index(entry.session.compiled.scene_map)))
        return SessionFramesOut(session_id=entry.session_id, results=results)

    # ---------------------------------------------------------------------------- helpers

    def _validated(self, entry: SessionEntry, frames: list[SessionFrameIn],
                   batch: bool) -> list[FrameInput]:
        """Every frame converted and checked (timestamps non-decreasing, from the session's
        last one) before any is fused."""
        inputs = []
        last = entry.session.last_timestamp
        for i, f in enumerate(frames):
            prefix = f"frames[{i}]." if batch else ""
            try:
                inp = frame_input_from_wire(f, entry.convention)
            except _INPUT_ERRORS as exc:
                raise invalid_input(exc, prefix) from exc
            if last is not None and inp.timestamp < last:
                raise invalid_input(TrackingInputError(
                    f"{inp.timestamp} is before the previous frame's {last}",
                    field="timestamp"), prefix)
            last = inp.timestamp
            inputs.append(inp)
        return inputs

    def _out(self, entry: SessionEntry) -> SessionOut:
        return SessionOut(session_id=entry.session_id, url=f"/v1/sessions/{entry.session_id}",
                          map_id=entry.map_id, map_version=entry.map_version,
                          convention=entry.convention,
                          state=entry.session.state, frames=entry.session.frame_count,
                          idle_timeout_s=self.store.idle_timeout_s)


def _not_found(session_id: str) -> AppError:
    return AppError("session-not-found",
                    f"session {session_id!r} not found: it expired, was deleted, or its server "
                    "restarted; start a new session",
                    field="path.session_id", message="not found")
