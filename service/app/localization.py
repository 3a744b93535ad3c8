"""The localization use cases: one frame, a batch of frames, against a map version.

:class:`Localizer` bounds the work of a process: at most ``max_concurrent_solves`` frames are
solved at once (:class:`FairSlots`, first come first served; tracking-session frames take the
same slots), a frame waits at most ``solve_queue_timeout_s`` for a slot (then ``busy``, retry
after 1 s), each frame has a CPU-time budget (the server's, or less if the request asks) and a
batch a total budget (frames not started when it runs out answer ``time_budget_exceeded``).
Every solver failure is a "not localized" answer or an input error naming the field, never a
crash. Outcomes are reported to a :class:`SolveObserver` (the HTTP layer's Prometheus metrics).
Design: docs/design/service.md#solver-concurrency-and-budgets.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import deque
from collections.abc import Callable, Sequence
from typing import Protocol

from quadloc.factors.budget import Deadline
from quadloc.factors.names import GeometryError
from quadloc.maps.compiled import CompiledMap
from quadloc.maps.zones import zone_index
from quadloc.service.app.conversions import (
    camera_from_request,
    detections_from_request,
    gravity_from_request,
    hint_from_request,
    options_from_request,
    prior_from_request,
    response_from_result,
)
from quadloc.service.app.errors import AppError, field_and_problem
from quadloc.service.app.map_loader import MapLoader
from quadloc.service.localization.calibration_fit import CalibrationConstants
from quadloc.service.localization.pipeline import localize
from quadloc.service.localization.scoring import ScoringTimeoutError
from quadloc.service.localization.types import LocalizationInputError
from quadloc.service.schemas.localize import (
    BatchLocalizeResponse,
    LocalizeRequest,
    LocalizeResponse,
)
from quadloc.service.settings import Settings

__all__ = ["NUMERICAL_FAILURE", "TIME_BUDGET_EXCEEDED", "FairSlots", "Localizer",
           "SolveObserver"]

log = logging.getLogger("quadloc.app")

#: Reason (beyond the pipeline's) of an answer after a numerical failure deep in the solver.
NUMERICAL_FAILURE = "numerical_failure"
#: Reason of a batch frame skipped because the batch's total budget ran out.
TIME_BUDGET_EXCEEDED = "time_budget_exceeded"
#: An input error raised inside ``localize`` is the client's when it names a request field.
_REQUEST_FIELDS = ("detections", "camera", "prior", "gravity", "options")
#: ``Retry-After`` (s) when every solver slot stayed busy for the queue timeout.
BUSY_RETRY_AFTER_S = 1.0


class SolveObserver(Protocol):
    """Where the outcomes of solves are reported (metrics); every method must be cheap."""

    def solve_started(self) -> None:
        """A frame's solve starts."""

    def solve_finished(self, seconds: float) -> None:
        """A started solve ended after ``seconds`` (wall time)."""

    def frame_answered(self, outcome: str) -> None:
        """A frame was answered: ``"localized"`` or the reason it was not."""


class _NoObserver:
    """A :class:`SolveObserver` that records nothing (the CLI's)."""

    def solve_started(self) -> None:
        return None

    def solve_finished(self, seconds: float) -> None:
        return None

    def frame_answered(self, outcome: str) -> None:
        return None


class FairSlots:
    """A counting semaphore that serves waiters first come, first served: ``release`` hands the
    slot to the oldest waiter (no barging; why: docs/design/service.md, solver concurrency).

    The hand-off is a raw lock per waiter, held by the waiting thread's ``acquire`` until
    ``release`` releases it: one C-level unlock, where a ``threading.Event`` ran a Python
    ``Condition.notify`` holding the GIL (12 % of a loaded server's samples, issue 33)."""

    def __init__(self, slots: int) -> None:
        self._free = slots
        self._lock = threading.Lock()
        #: the waiters' hand-off locks, oldest first (each acquired: released on hand-off)
        self._waiters: deque[threading.Lock] = deque()

    def acquire(self, timeout: float | None = None) -> bool:
        """Take a slot, waiting at most ``timeout`` seconds (None = forever). True if taken."""
        with self._lock:
            if self._free > 0 and not self._waiters:
                self._free -= 1
                return True
            handoff = threading.Lock()
            handoff.acquire()
            self._waiters.append(handoff)
        if handoff.acquire(timeout=-1 if timeout is None else max(timeout, 0.0)):
            return True
        with self._lock:
            if handoff not in self._waiters:  # handed over just as the wait timed out
                return True
            self._waiters.remove(handoff)
            return False

    def release(self) -> None:
        """Give the slot to the oldest waiter, or free it."""
        with self._lock:
            if self._waiters:
                self._waiters.popleft().release()
            else:
                self._free += 1


def _is_request_field(exc: Exception) -> bool:
    field = getattr(exc, "field", None) or ""
    return field.split(".")[0].split("[")[0] in _REQUEST_FIELDS


def _invalid_geometry(exc: Exception, prefix: str) -> AppError:
    """The 422 ``invalid-geometry`` refusal of an input error naming its field."""
    field, message = field_and_problem(exc, prefix)
    return AppError("invalid-geometry", f"{field}: {message}", field=field, message=message)


def _not_localized(compiled: CompiledMap, frame: LocalizeRequest, reason: str, metric: str,
                   start: float | None) -> LocalizeResponse:
    """A "not localized" answer with ``reason``; ``timings_ms.total`` is the time since
    ``start`` (``time.perf_counter()``; None: 0, the frame was not started)."""
    elapsed_ms = 0.0 if start is None else (time.perf_counter() - start) * 1e3
    return LocalizeResponse(
        localized=False, reason=reason, world_from_camera=None, covariance=None,
        confidence=0.0, inliers=[], metric=metric, hypotheses_evaluated=0, used_prior=False,
        map_id=compiled.map_id, map_version=compiled.version, timings_ms={"total": elapsed_ms},
        frame_id=frame.frame_id, timestamp=frame.timestamp)


class Localizer:
    """The process's localization runner (see the module docstring).

    Args:
        settings: ``max_concurrent_solves``, ``solve_queue_timeout_s``,
            ``solve_time_budget_ms``, ``max_detections``, ``batch_time_budget_ms``,
            ``max_batch_frames``.
        maps: the map versions (loaded within the request's budget).
        observer: where outcomes are reported (default: nowhere).
    """

    def __init__(self, settings: Settings, maps: MapLoader,
                 observer: SolveObserver | None = None,
                 calibration_of: Callable[[str, int], CalibrationConstants | None] | None = None,
                 ) -> None:
        self.maps = maps
        #: a map version's own calibration (``quadloc calibrate``), None: the shipped one
        self.calibration_of = calibration_of or (lambda _map_id, _version: None)
        self.observer: SolveObserver = observer or _NoObserver()
        self.slots = FairSlots(settings.max_concurrent_solves)
        self.queue_timeout_s = settings.solve_queue_timeout_s
        self.max_budget_ms = settings.solve_time_budget_ms
        self.max_detections = settings.max_detections
        self.batch_budget_ms = settings.batch_time_budget_ms
        self.max_batch_frames = settings.max_batch_frames

    # ----------------------------------------------------------------------------- use cases

    def localize(self, map_id: str, frame: LocalizeRequest,
                 version: int | None = None) -> tuple[CompiledMap, LocalizeResponse]:
        """Localize one frame against ``map_id`` (its latest version, or ``version``).
        Returns the map version used (for drawings) and the answer; refusals raise
        :class:`AppError` (``map-not-found``, ``map-loading``, ``busy``, ``validation-error``,
        ``invalid-geometry``)."""
        compiled = self.maps.get(map_id, version)
        return compiled, self.localize_frames(compiled, [frame], batch=False)[0]

    def localize_batch(self, map_id: str, frames: Sequence[LocalizeRequest],
                       version: int | None = None) -> BatchLocalizeResponse:
        """Localize ``frames`` in order against one version of ``map_id`` within the batch
        budget; errors name ``frames[i]....``."""
        if len(frames) > self.max_batch_frames:
            raise AppError("validation-error",
                           f"frames: at most {self.max_batch_frames} frames per batch",
                           field="frames", message=f"at most {self.max_batch_frames} frames")
        compiled = self.maps.get(map_id, version)
        results = self.localize_frames(compiled, frames, batch=True)
        return BatchLocalizeResponse(map_id=compiled.map_id, map_version=compiled.version,
                                     results=results)

    def localize_frames(self, compiled: CompiledMap, frames: Sequence[LocalizeRequest],
                        batch: bool) -> list[LocalizeResponse]:
        """Solve ``frames`` in order against ``compiled`` (blocking; call from a worker
        thread), one solver slot per frame; batch errors name ``frames[i]....``; a batch stops
        solving when ``batch_time_budget_ms`` (wall clock, from this call) runs out."""
        out: list[LocalizeResponse] = []
        deadline = Deadline.wall_budget(self.batch_budget_ms / 1e3) if batch else Deadline()
        for i, frame in enumerate(frames):
            prefix = f"frames[{i}]." if batch else ""
            remaining_s = deadline.remaining_wall_s()
            if remaining_s <= 0:
                out.append(self._budget_exceeded(compiled, frame, prefix))
                continue
            wait_s = min(self.queue_timeout_s, remaining_s)
            if not self.slots.acquire(timeout=wait_s):
                if wait_s < self.queue_timeout_s:  # the batch budget, not the queue, ran out
                    out.append(self._budget_exceeded(compiled, frame, prefix))
                    continue
                raise AppError("busy", "all solver slots are busy; retry shortly",
                               retry_after_s=BUSY_RETRY_AFTER_S)
            try:
                remaining_ms = deadline.remaining_wall_s() * 1e3
                if remaining_ms <= 0:
                    out.append(self._budget_exceeded(compiled, frame, prefix))
                else:
                    out.append(self._solve_one(compiled, frame, prefix,
                                               remaining_ms if batch else None))
            finally:
                self.slots.release()
        return out

    # ----------------------------------------------------------------------------- the solve

    def _check_size(self, frame: LocalizeRequest, prefix: str) -> None:
        if len(frame.detections) > self.max_detections:
            raise AppError("validation-error",
                           f"{prefix}detections: at most {self.max_detections} per frame",
                           field=f"{prefix}detections",
                           message=f"at most {self.max_detections} detections")

    def _solve_one(self, compiled: CompiledMap, frame: LocalizeRequest,
                   prefix: str, budget_ms: float | None = None) -> LocalizeResponse:
        self._check_size(frame, prefix)
        try:
            camera = camera_from_request(frame.camera)
            detections = detections_from_request(frame.detections)
            prior = prior_from_request(frame.prior)
            gravity = gravity_from_request(frame.gravity)
            hint = hint_from_request(frame.hint, compiled)
            options = options_from_request(
                frame.options,
                self.max_budget_ms if budget_ms is None else min(self.max_budget_ms, budget_ms))
        except ValueError as exc:  # GeometryError, LocalizationInputError
            raise _invalid_geometry(exc, prefix) from exc
        start = time.perf_counter()
        self.observer.solve_started()
        try:
            if not detections:  # an image without detections is a normal "not localized"
                response = _not_localized(compiled, frame, "too_few_detections", options.metric,
                                          start)
            else:
                response = response_from_result(
                    localize(detections, compiled, camera, options, prior, gravity,
                             calibration=self.calibration_of(compiled.map_id, compiled.version),
                             hint=hint),
                    map_id=compiled.map_id, map_version=compiled.version,
                    convention=frame.options.output_convention, frame_id=frame.frame_id,
                    timestamp=frame.timestamp, zones=zone_index(compiled.scene_map))
        except (GeometryError, LocalizationInputError) as exc:
            if _is_request_field(exc):
                raise _invalid_geometry(exc, prefix) from exc
            response = self._failed(compiled, frame, options.metric, start)
        except ScoringTimeoutError:  # scoring a huge map x detections ran past the hard stop
            response = _not_localized(compiled, frame, TIME_BUDGET_EXCEEDED, options.metric,
                                      start)
        except Exception:  # a numerical failure deep in the solver is "not localized", not 5xx
            response = self._failed(compiled, frame, options.metric, start)
        finally:
            self.observer.solve_finished(time.perf_counter() - start)
        self.observer.frame_answered(
            "localized" if response.localized else str(response.reason))
        return response

    @staticmethod
    def _failed(compiled: CompiledMap, frame: LocalizeRequest, metric: str,
                start: float) -> LocalizeResponse:
        """The "not localized" answer for an unexpected solver failure (logged with traceback)."""
        log.exception("solver failure in localize() for frame %r after %.1f ms; answered "
                      "localized=false reason=%s", frame.frame_id,
                      (time.perf_counter() - start) * 1e3, NUMERICAL_FAILURE)
        return _not_localized(compiled, frame, NUMERICAL_FAILURE, metric, start)

    def _budget_exceeded(self, compiled: CompiledMap, frame: LocalizeRequest,
                         prefix: str) -> LocalizeResponse:
        """The answer for a batch frame not solved because the batch budget ran out (an
        oversized frame is still the client's error)."""
        self._check_size(frame, prefix)
        self.observer.frame_answered(TIME_BUDGET_EXCEEDED)
        return _not_localized(compiled, frame, TIME_BUDGET_EXCEEDED, frame.options.metric, None)
