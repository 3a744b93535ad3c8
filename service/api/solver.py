"""Running localizations for the API: bounded concurrency (:class:`FairSlots`,
``QUADLOC_MAX_CONCURRENT_SOLVES``; 503 + ``Retry-After`` after ``QUADLOC_SOLVE_QUEUE_TIMEOUT_S``),
per-frame and per-batch time budgets (frames not started answer ``time_budget_exceeded``),
outcome metrics, and every solver failure as a 4xx problem or a "not localized" answer.
Design: docs/design/service.md#solver-concurrency-and-budgets.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import deque
from collections.abc import Sequence

from quadloc.factors.names import GeometryError
from quadloc.maps.compiled import CompiledMap
from quadloc.service.api.convert import (
    camera_from_request,
    detections_from_request,
    gravity_from_request,
    options_from_request,
    prior_from_request,
    response_from_result,
)
from quadloc.service.api.errors import ProblemError, field_and_problem
from quadloc.service.api.metrics import ApiMetrics
from quadloc.service.localization.pipeline import localize
from quadloc.service.localization.scoring import ScoringTimeoutError
from quadloc.service.localization.types import LocalizationInputError
from quadloc.service.schemas.localize import LocalizeRequest, LocalizeResponse

__all__ = ["Solver"]

log = logging.getLogger("quadloc.api")

#: API-level reason (beyond the pipeline's) for a numerical failure deep in the solver.
NUMERICAL_FAILURE = "numerical_failure"
#: Reason of a batch frame skipped because the batch's total budget ran out.
TIME_BUDGET_EXCEEDED = "time_budget_exceeded"
#: An input error raised inside ``localize`` is the client's when it names a request field.
_REQUEST_FIELDS = ("detections", "camera", "prior", "gravity", "options")


def _is_request_field(exc: Exception) -> bool:
    field = getattr(exc, "field", None) or ""
    return field.split(".")[0].split("[")[0] in _REQUEST_FIELDS


def _invalid_geometry(exc: Exception, prefix: str) -> ProblemError:
    """The 422 ``invalid-geometry`` problem of an input error naming its field."""
    field, message = field_and_problem(exc, prefix)
    return ProblemError("invalid-geometry", f"{field}: {message}",
                        field=field, message=message)


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


class FairSlots:
    """A counting semaphore that serves waiters first come, first served: ``release`` hands the
    slot to the oldest waiter (no barging; why: docs/design/service.md, solver concurrency)."""

    def __init__(self, slots: int) -> None:
        self._free = slots
        self._lock = threading.Lock()
        self._waiters: deque[threading.Event] = deque()

    def acquire(self, timeout: float | None = None) -> bool:
        """Take a slot, waiting at most ``timeout`` seconds (None = forever). True if taken."""
        with self._lock:
            if self._free > 0 and not self._waiters:
                self._free -= 1
                return True
            granted = threading.Event()
            self._waiters.append(granted)
        if granted.wait(timeout):
            return True
        with self._lock:
            if granted.is_set():  # handed over just as the wait timed out
                return True
            self._waiters.remove(granted)
            return False

    def release(self) -> None:
        """Give the slot to the oldest waiter, or free it."""
        with self._lock:
            if self._waiters:
                self._waiters.popleft().set()
            else:
                self._free += 1


class Solver:
    """Per-app localization runner (see the module docstring)."""

    def __init__(self, metrics: ApiMetrics, max_concurrent: int, queue_timeout_s: float,
                 max_budget_ms: float, max_detections: int,
                 batch_budget_ms: float = float("inf")) -> None:
        self.metrics = metrics
        self.batch_budget_ms = batch_budget_ms
        self.slots = FairSlots(max_concurrent)
        self.queue_timeout_s = queue_timeout_s
        self.max_budget_ms = max_budget_ms
        self.max_detections = max_detections

    def _solve_one(self, compiled: CompiledMap, frame: LocalizeRequest,
                   prefix: str, budget_ms: float | None = None) -> LocalizeResponse:
        if len(frame.detections) > self.max_detections:
            raise ProblemError("validation-error",
                               f"{prefix}detections: at most {self.max_detections} per frame",
                               field=f"{prefix}detections",
                               message=f"at most {self.max_detections} detections")
        try:
            camera = camera_from_request(frame.camera)
            detections = detections_from_request(frame.detections)
            prior = prior_from_request(frame.prior)
            gravity = gravity_from_request(frame.gravity)
            options = options_from_request(
                frame.options,
                self.max_budget_ms if budget_ms is None else min(self.max_budget_ms, budget_ms))
        except ValueError as exc:  # GeometryError, LocalizationInputError
            raise _invalid_geometry(exc, prefix) from exc
        start = time.perf_counter()
        self.metrics.in_progress.inc()
        try:
            if not detections:  # an image without detections is a normal "not localized"
                response = _not_localized(compiled, frame, "too_few_detections", options.metric,
                                          start)
            else:
                response = response_from_result(
                    localize(detections, compiled, camera, options, prior, gravity),
                    map_id=compiled.map_id, map_version=compiled.version,
                    convention=frame.options.output_convention, frame_id=frame.frame_id,
                    timestamp=frame.timestamp)
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
            self.metrics.in_progress.dec()
            self.metrics.solve_seconds.observe(time.perf_counter() - start)
        self.metrics.localizations.labels(
            "localized" if response.localized else str(response.reason)).inc()
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
        """The answer for a batch frame not solved because the batch budget ran out."""
        if len(frame.detections) > self.max_detections:  # still the client's error
            self._solve_one(compiled, frame, prefix)
        self.metrics.localizations.labels(TIME_BUDGET_EXCEEDED).inc()
        return _not_localized(compiled, frame, TIME_BUDGET_EXCEEDED, frame.options.metric, None)

    def localize_frames(self, compiled: CompiledMap, frames: Sequence[LocalizeRequest],
                        batch: bool) -> list[LocalizeResponse]:
        """Solve ``frames`` in order against ``compiled`` (blocking; call from a thread), one
        solver slot per frame; batch errors name ``frames[i]....``; a batch stops solving when
        ``batch_budget_ms`` (``time.perf_counter``, from this call) runs out."""
        out: list[LocalizeResponse] = []
        deadline = time.perf_counter() + self.batch_budget_ms / 1e3 if batch else float("inf")
        for i, frame in enumerate(frames):
            prefix = f"frames[{i}]." if batch else ""
            remaining_s = deadline - time.perf_counter()
            if remaining_s <= 0:
                out.append(self._budget_exceeded(compiled, frame, prefix))
                continue
            wait_s = min(self.queue_timeout_s, remaining_s)
            if not self.slots.acquire(timeout=wait_s):
                if wait_s < self.queue_timeout_s:  # the batch budget, not the queue, ran out
                    out.append(self._budget_exceeded(compiled, frame, prefix))
                    continue
                raise ProblemError("busy", "all solver slots are busy; retry shortly",
                                   headers={"Retry-After": "1"})
            try:
                remaining_ms = (deadline - time.perf_counter()) * 1e3
                if remaining_ms <= 0:
                    out.append(self._budget_exceeded(compiled, frame, prefix))
                else:
                    out.append(self._solve_one(compiled, frame, prefix,
                                               remaining_ms if batch else None))
            finally:
                self.slots.release()
        return out
