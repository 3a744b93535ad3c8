"""Limits of the HTTP surface that a client without a key reaches (issue 32, items 3 and 7).

* ``/metrics`` labels come from closed sets: any method outside the known ones is counted as
  ``other`` and any path no route matched as ``<unmatched>`` (200 requests with distinct 16 KB
  methods grew ``/metrics`` to 71 MB);
* the request-head limit holds however the bytes arrive: a head over the limit in ONE write is
  refused like one that trickles (h11's own limit only applies to incomplete heads).
"""

from __future__ import annotations

import re
from pathlib import Path

import h11
import pytest
from fastapi.testclient import TestClient

from quadloc.service.api.metrics import METHOD_LABELS
from quadloc.service.api.server import HeadLimitedConnection
from tests.conftest import make_test_app


def test_metrics_labels_are_a_closed_set(tmp_path: Path) -> None:
    with TestClient(make_test_app(tmp_path, seed_demo_map=False)) as c:
        for i in range(200):
            c.request(f"FOO{i:03d}" + "X" * 16_000, "/healthz")
            c.request("GET", f"/no/such/path/{i}")
            c.request("PATCH", f"/v1/maps/m{i}")
        text = c.get("/metrics").text
    methods = set(re.findall(r'quadloc_http_requests_total\{method="([^"]*)"', text))
    routes = set(re.findall(r'route="([^"]*)"', text))
    assert methods <= METHOD_LABELS | {"other"} and "other" in methods
    assert routes <= {"/healthz", "/v1/maps/{map_id}", "/metrics", "<unmatched>"}, routes
    other = re.search(r'quadloc_http_requests_total\{method="other",route="/healthz",'
                      r'status="\d+"\} ([0-9.e+]+)', text)
    assert other is not None and float(other.group(1)) == 200
    assert len(text) < 50_000  # 71 MB before: one series per method sent


def _head(pad: int) -> bytes:
    return (b"GET /healthz HTTP/1.1\r\nHost: t\r\nX-Pad: " + b"a" * pad
            + b"\r\nConnection: close\r\n\r\n")


def _events(conn: h11.Connection, data: bytes) -> list[object]:
    conn.receive_data(data)
    events = []
    while True:
        event = conn.next_event()
        if event is h11.NEED_DATA or event is h11.PAUSED:
            return events
        events.append(event)
        if isinstance(event, h11.EndOfMessage):
            return events


@pytest.mark.parametrize("pad", [40_000, 60_000, 120_000])
def test_a_head_over_the_limit_in_one_write_is_refused(pad: int) -> None:
    limit = 32_768
    # the repro: plain h11 with the same limit parses a complete oversized head
    assert isinstance(_events(h11.Connection(h11.SERVER, max_incomplete_event_size=limit),
                              _head(pad))[0], h11.Request)
    with pytest.raises(h11.RemoteProtocolError) as info:
        _events(HeadLimitedConnection(limit), _head(pad))
    assert info.value.error_status_hint == 431
    # ... and trickled in small writes (h11's own limit)
    conn = HeadLimitedConnection(limit)
    data = _head(pad)
    with pytest.raises(h11.RemoteProtocolError):
        for i in range(0, len(data), 1000):
            _events(conn, data[i:i + 1000])


def test_a_head_within_the_limit_passes_also_when_pipelined() -> None:
    limit = 32_768
    conn = HeadLimitedConnection(limit)
    head = _head(limit - 200)
    assert len(head) <= limit
    events = _events(conn, head + b"GET /x HTTP/1.1\r\nHost: t\r\n\r\n")
    assert isinstance(events[0], h11.Request) and events[0].target == b"/healthz"
