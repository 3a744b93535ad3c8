"""Running the app under Uvicorn with connection-level limits (``quadloc serve``): h11 with
``QUADLOC_MAX_HEADER_BYTES`` (however the bytes arrive: :class:`HeadLimitedConnection`), a
request read deadline (:class:`GuardedH11Protocol`, 408), the
keep-alive timeout and at most :data:`MALLOC_ARENAS` glibc arenas. Why each limit:
docs/design/service.md#connection-limits-of-quadloc-serve.
"""

from __future__ import annotations

import asyncio
import ctypes
import ctypes.util
import os
from typing import Any

import h11
import uvicorn
from uvicorn.protocols.http.h11_impl import H11Protocol

from quadloc.service.settings import SHUTDOWN_CANCEL_MARGIN_S, Settings

__all__ = ["GuardedH11Protocol", "HeadLimitedConnection", "limit_malloc_arenas", "serve",
           "uvicorn_config"]

#: glibc malloc arenas of a server process (docs/design/service.md, connection limits).
MALLOC_ARENAS = 2
_M_ARENA_MAX = -8  # glibc <malloc.h>

#: Used when the Uvicorn config carries no ``request_read_timeout_s`` (plain Uvicorn config).
DEFAULT_REQUEST_READ_TIMEOUT_S = 10.0
_RECEIVED = (h11.DONE, h11.MUST_CLOSE, h11.CLOSED, h11.ERROR, h11.SWITCHED_PROTOCOL)
_TIMEOUT_RESPONSE = (b"HTTP/1.1 408 Request Timeout\r\ncontent-type: text/plain\r\n"
                     b"connection: close\r\ncontent-length: 36\r\n\r\n"
                     b"request not received in time; closed")


class HeadLimitedConnection(h11.Connection):
    """An h11 server connection that refuses a request whose request line + headers are larger
    than ``max_head_bytes``, however the bytes arrived.

    h11's own ``max_incomplete_event_size`` only applies while the head is INCOMPLETE: a
    60 KB head sent in one write is parsed whole and passes it. Here the bytes each request
    head took from the receive buffer are counted when h11 returns the ``Request`` event, and a
    head over the limit raises ``h11.RemoteProtocolError`` (Uvicorn answers 400 and closes the
    connection, as for an incomplete head over the limit)."""

    def __init__(self, max_head_bytes: int) -> None:
        super().__init__(h11.SERVER, max_incomplete_event_size=max_head_bytes)
        self.max_head_bytes = int(max_head_bytes)

    def next_event(self) -> Any:
        """h11's next event; ``RemoteProtocolError`` for a request head over the limit."""
        buffered = len(self._receive_buffer)
        event = super().next_event()
        if isinstance(event, h11.Request):
            head = buffered - len(self._receive_buffer)
            if head > self.max_head_bytes:
                raise h11.RemoteProtocolError(
                    f"request line and headers are {head} bytes (max {self.max_head_bytes})",
                    error_status_hint=431)
        return event


class GuardedH11Protocol(H11Protocol):
    """Uvicorn's h11 protocol with a deadline for receiving each complete request and the header
    limit of :class:`HeadLimitedConnection`."""

    def __init__(self, config: uvicorn.Config, *args: Any, **kwargs: Any) -> None:
        super().__init__(config, *args, **kwargs)
        self.conn = HeadLimitedConnection(self.conn._max_incomplete_event_size)
        self.request_read_timeout_s = float(getattr(config, "request_read_timeout_s",
                                                    DEFAULT_REQUEST_READ_TIMEOUT_S))
        self._read_timer: asyncio.TimerHandle | None = None

    def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
        super().connection_made(transport)
        self._arm()  # a connection on which nothing is ever sent is closed too

    def data_received(self, data: bytes) -> None:
        super().data_received(data)
        self._update()

    def on_response_complete(self) -> None:
        super().on_response_complete()
        self._update()  # next request: idle (keep-alive timer) or already started (armed)

    def connection_lost(self, exc: Exception | None) -> None:
        self._disarm()
        super().connection_lost(exc)

    def _update(self) -> None:
        state = self.conn.their_state
        if state in _RECEIVED or (state is h11.IDLE and not self.conn.trailing_data[0]):
            self._disarm()  # the request is in (the app runs) or the connection is idle
        else:
            self._arm()  # a request is partly received: its deadline runs from its first byte

    def _arm(self) -> None:
        if self._read_timer is None:
            self._read_timer = self.loop.call_later(self.request_read_timeout_s,
                                                    self._read_timed_out)

    def _disarm(self) -> None:
        if self._read_timer is not None:
            self._read_timer.cancel()
            self._read_timer = None

    def _read_timed_out(self) -> None:
        self._read_timer = None
        if self.transport.is_closing() or self.conn.their_state in _RECEIVED:
            return
        if self.cycle is None or not self.cycle.response_started:
            self.transport.write(_TIMEOUT_RESPONSE)
        if self.cycle is not None:
            self.cycle.keep_alive = False
        self.logger.info("closed a connection: request not received within %.1f s",
                         self.request_read_timeout_s)
        self.transport.close()


def uvicorn_config(settings: Settings, host: str, port: int, *, workers: int = 1,
                   log_level: str | None = None, access_log: bool = True) -> uvicorn.Config:
    """The Uvicorn config of ``quadloc serve``: the app factory, h11 with the header limit,
    the keep-alive timeout and :class:`GuardedH11Protocol` with the request read timeout."""
    config = uvicorn.Config(
        "quadloc.service.api.app:create_app", factory=True, host=host, port=port, workers=workers,
        log_level=log_level or settings.log_level, access_log=access_log,
        http=GuardedH11Protocol, h11_max_incomplete_event_size=settings.max_header_bytes,
        # (typed int, used as a float timeout: sub-second settings are honoured)
        timeout_keep_alive=settings.keep_alive_timeout_s,  # type: ignore[arg-type]
        timeout_graceful_shutdown=max(1.0, settings.shutdown_grace_s  # type: ignore[arg-type]
                                      - SHUTDOWN_CANCEL_MARGIN_S))
    config.request_read_timeout_s = settings.request_read_timeout_s  # type: ignore[attr-defined]
    return config


def limit_malloc_arenas(arenas: int = MALLOC_ARENAS) -> bool:
    """``mallopt(M_ARENA_MAX, arenas)`` on glibc unless ``MALLOC_ARENA_MAX`` is set (then glibc
    already applied it); False where there is no glibc (nothing to do)."""
    if os.environ.get("MALLOC_ARENA_MAX"):
        return False
    name = ctypes.util.find_library("c")
    try:
        libc = ctypes.CDLL(name) if name else None
        return bool(libc is not None and libc.mallopt(_M_ARENA_MAX, int(arenas)) == 1)
    except (OSError, AttributeError):
        return False


def serve(config: uvicorn.Config) -> None:
    """Run the server like ``uvicorn.run`` (several worker processes when configured), with
    :func:`limit_malloc_arenas` (inherited by worker processes through the environment)."""
    if limit_malloc_arenas():
        os.environ["MALLOC_ARENA_MAX"] = str(MALLOC_ARENAS)  # for spawned worker processes
    server = uvicorn.Server(config)
    if config.workers > 1:
        from uvicorn.supervisors import Multiprocess

        sock = config.bind_socket()
        Multiprocess(config, sockets=[sock]).run()
    else:
        server.run()
