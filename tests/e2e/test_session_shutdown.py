"""A long session request against a real ``quadloc serve`` on loopback (issue 32, item 2):
its work stops when the client goes away, and SIGTERM during it ends the process within the
grace period (``QUADLOC_SHUTDOWN_GRACE_S``) instead of computing on.

The request: 900 frames (the batch maximum) of a 30 Hz walk through the Chess demo map with the
batch smoother over 60 frames, tens of seconds of CPU; budgets raised so that only the
cancellation can stop it.
"""

from __future__ import annotations

import contextlib
import signal
import subprocess
import threading
import time
from pathlib import Path

import httpx
import pytest

from tests.conftest import run_live_server
from tests.support.walks import chess_walk, frame_json

pytestmark = pytest.mark.slow

GRACE_S = 6.0
ENV = {"QUADLOC_SHUTDOWN_GRACE_S": str(GRACE_S),
       "QUADLOC_SESSION_REQUEST_BUDGET_MS": "300000",
       "QUADLOC_SESSION_FRAME_BUDGET_MS": "60000"}


@pytest.fixture(scope="module")
def long_batch() -> tuple[dict, list[dict]]:
    walk = chess_walk(900, seed=3)
    camera = walk.camera
    frames = [frame_json(f) for f in walk.frames]
    create = {"camera": {"fx": camera.fx, "fy": camera.fy, "cx": camera.cx, "cy": camera.cy,
                         "width": camera.width, "height": camera.height},
              "options": {"smoother": "batch", "window_frames": 60}}
    return create, frames


def _post_in_background(url: str, body: dict, timeout_s: float) -> threading.Thread:
    def run() -> None:
        with contextlib.suppress(httpx.HTTPError):
            httpx.post(url, json=body, timeout=timeout_s)
    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    return thread


def test_a_client_that_goes_away_cancels_its_frames(tmp_path: Path, long_batch) -> None:
    create, frames = long_batch
    with run_live_server(tmp_path / "srv", env=ENV) as base:
        sid = httpx.post(f"{base}/v1/maps/chess/sessions", json=create).json()["session_id"]
        url = f"{base}/v1/sessions/{sid}/frames"
        # the client gives up after 2 s and closes its connection
        _post_in_background(url, {"frames": frames}, 2.0).join()
        # the session's lock is free again once the cancelled request stopped: the next frame
        # is answered long before the 900 frames could have been fused
        nxt = {**frames[-1], "timestamp": 1000.0}
        r = httpx.post(url, json=nxt, timeout=20.0)
        assert r.status_code == 200, r.text
        assert httpx.get(f"{base}/v1/sessions/{sid}").json()["frames"] == 901


def test_sigterm_during_the_longest_request_ends_the_server_within_its_grace(
        tmp_path: Path, long_batch) -> None:
    create, frames = long_batch
    procs: list[subprocess.Popen[bytes]] = []
    with run_live_server(tmp_path / "srv", env=ENV, on_start=procs.append) as base:
        sid = httpx.post(f"{base}/v1/maps/chess/sessions", json=create).json()["session_id"]
        _post_in_background(f"{base}/v1/sessions/{sid}/frames", {"frames": frames}, 120.0)
        time.sleep(2.0)  # the request is being computed
        assert procs[0].poll() is None
        t0 = time.monotonic()
        procs[0].send_signal(signal.SIGTERM)
        procs[0].wait(timeout=GRACE_S + 5.0)  # raises if it computes on
        ended_s = time.monotonic() - t0
    assert ended_s <= GRACE_S + 1.0, ended_s
