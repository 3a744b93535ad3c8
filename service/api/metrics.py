"""Prometheus metrics (one registry per app) and the ASGI middleware that records them and
enforces the request-body size limit.

Series: ``quadloc_http_requests_total{method, route, status}``,
``quadloc_http_request_duration_seconds{method, route}``, ``quadloc_localizations_total{outcome}``,
``quadloc_localization_solve_seconds``, ``quadloc_solves_in_progress``; ``route`` is the route
template and ``method`` one of :data:`METHOD_LABELS` (any other method counts as ``other``):
every label comes from a closed set, whatever a client sends. Details:
docs/design/service.md#metrics.
"""

from __future__ import annotations

import json
import time
from collections.abc import Mapping

from prometheus_client import CollectorRegistry, Counter, Gauge, Histogram
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from quadloc.service.api.errors import PROBLEM_MEDIA_TYPE, problem_body

__all__ = ["METHOD_LABELS", "OTHER_METHOD", "UNMATCHED_ROUTE", "ApiMetrics",
           "MetricsAndLimitsMiddleware", "method_label", "route_label"]

#: The ``method`` label values: the methods of RFC 9110 and PATCH; anything else a client sends
#: (``curl -X FOO1``) is counted as :data:`OTHER_METHOD`, so a client cannot add series.
METHOD_LABELS = frozenset({"GET", "HEAD", "POST", "PUT", "DELETE", "PATCH", "OPTIONS",
                           "CONNECT", "TRACE"})
OTHER_METHOD = "other"
#: The ``route`` label of a request no route matched (the raw path is never a label).
UNMATCHED_ROUTE = "<unmatched>"

_LATENCY_BUCKETS = (0.001, 0.0025, 0.005, 0.01, 0.02, 0.03, 0.05, 0.075, 0.1, 0.15, 0.25, 0.5,
                    1.0, 2.5, 5.0, 10.0)


class ApiMetrics:
    """The service's metric families in their own ``CollectorRegistry``; also the localizer's
    :class:`quadloc.service.app.localization.SolveObserver`."""

    def __init__(self) -> None:
        self.registry = CollectorRegistry(auto_describe=True)
        self.requests = Counter("quadloc_http_requests_total", "HTTP requests answered.",
                                ["method", "route", "status"], registry=self.registry)
        self.latency = Histogram("quadloc_http_request_duration_seconds",
                                 "HTTP request latency in seconds.", ["method", "route"],
                                 buckets=_LATENCY_BUCKETS, registry=self.registry)
        self.localizations = Counter("quadloc_localizations_total",
                                     "Frames processed by outcome (localized or the reason).",
                                     ["outcome"], registry=self.registry)
        self.solve_seconds = Histogram("quadloc_localization_solve_seconds",
                                       "Solve time per frame in seconds.",
                                       buckets=_LATENCY_BUCKETS, registry=self.registry)
        self.in_progress = Gauge("quadloc_solves_in_progress", "Frames being solved now.",
                                 registry=self.registry)

    def solve_started(self) -> None:
        self.in_progress.inc()

    def solve_finished(self, seconds: float) -> None:
        self.in_progress.dec()
        self.solve_seconds.observe(seconds)

    def frame_answered(self, outcome: str) -> None:
        self.localizations.labels(outcome).inc()


def method_label(method: str) -> str:
    """The ``method`` label of a request method: itself if in :data:`METHOD_LABELS`, else
    :data:`OTHER_METHOD`."""
    return method if method in METHOD_LABELS else OTHER_METHOD


def route_label(scope: Scope) -> str:
    """The ``route`` label of a request: the template of the route that matched (a string
    written in the code, e.g. ``/v1/maps/{map_id}``), else :data:`UNMATCHED_ROUTE`."""
    path = getattr(scope.get("route"), "path", None)
    return path if isinstance(path, str) and path else UNMATCHED_ROUTE


def _problem_413(path: str, limit: int) -> bytes:
    return json.dumps(problem_body("payload-too-large", f"request body exceeds {limit} bytes",
                                   path, [{"field": "body",
                                           "message": f"larger than {limit} bytes"}])).encode()


class MetricsAndLimitsMiddleware:
    """Pure ASGI middleware: body size limit (413 problem) and request metrics."""

    def __init__(self, app: ASGIApp, metrics: ApiMetrics, max_body_bytes: int,
                 path_body_bytes: Mapping[str, int] | None = None) -> None:
        self.app = app
        self.metrics = metrics
        self.max_body_bytes = max_body_bytes
        #: Body limits of given request paths (e.g. ``/v1/maps:build``), else max_body_bytes.
        self.path_body_bytes = dict(path_body_bytes or {})

    async def _reject(self, scope: Scope, send: Send, limit: int) -> None:
        body = _problem_413(scope.get("path", ""), limit)
        await send({"type": "http.response.start", "status": 413,
                    "headers": [(b"content-type", PROBLEM_MEDIA_TYPE.encode()),
                                (b"content-length", str(len(body)).encode()),
                                (b"connection", b"close")]})
        await send({"type": "http.response.body", "body": body})

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        start = time.perf_counter()
        status = 500
        limit = self.path_body_bytes.get(scope.get("path", ""), self.max_body_bytes)

        async def send_wrapper(message: Message) -> None:
            nonlocal status
            if message["type"] == "http.response.start":
                status = message["status"]
            await send(message)

        try:
            declared = [v for k, v in scope.get("headers", ()) if k == b"content-length"]
            try:
                too_large = bool(declared) and int(declared[-1]) > limit
            except ValueError:
                too_large = False
            if too_large:
                status = 413
                await self._reject(scope, send, limit)
                return
            # Buffer the body (bounded) so chunked uploads are limited too, then replay it.
            chunks: list[bytes] = []
            size = 0
            more = True
            disconnect: Message | None = None
            while more:
                message = await receive()
                if message["type"] != "http.request":
                    disconnect = message
                    break
                chunk = message.get("body", b"")
                size += len(chunk)
                if size > limit:
                    status = 413
                    await self._reject(scope, send, limit)
                    return
                chunks.append(chunk)
                more = message.get("more_body", False)
            body = b"".join(chunks)
            replayed = False

            async def replay() -> Message:
                nonlocal replayed
                if not replayed:
                    replayed = True
                    if disconnect is not None and not body:
                        return disconnect
                    return {"type": "http.request", "body": body, "more_body": False}
                return await receive()

            await self.app(scope, replay, send_wrapper)
        finally:
            template = route_label(scope)
            method = method_label(scope.get("method", ""))
            self.metrics.requests.labels(method, template, str(status)).inc()
            self.metrics.latency.labels(method, template).observe(time.perf_counter() - start)
