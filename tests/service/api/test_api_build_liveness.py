"""A live build is never taken for a lost one (issue 32, item 6): a 4,000-detection build was
marked failed ``runner_lost`` by a status poll at 57 s while it ran on a healthy replica (a
stage reported no progress for longer than ``build_stale_after_s``). The runner's heartbeat
thread now refreshes its jobs' rows whatever the build reports; a replica that stops still
loses its jobs (``test_api_build.py``: restart, sweep)."""

from __future__ import annotations

import threading
import time
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient

import quadloc.service.app.builds as builds_module
from quadloc.maps.building.build import BuildTimeoutError
from quadloc.service.app.builds import beat_interval_s
from tests.conftest import make_test_app
from tests.service.api.test_api_build import _recording

STALE_AFTER_S = 5.0  # the smallest liveness window the settings allow
SILENT_S = 2.0 * STALE_AFTER_S  # the stage reports nothing for twice the window


class _SilentStage:
    """Stands in for ``build_map``: one progress report, then a stage that computes (holding
    the GIL, pure Python) for :data:`SILENT_S` without reporting, then fails the build cleanly
    (no map) so that the test sees how it ended."""

    def __init__(self) -> None:
        self.started = threading.Event()

    def __call__(self, recording: Any, *, map_id: str, progress: Any, deadline: Any) -> Any:
        progress("associating", 1.0, 0)
        self.started.set()
        t0 = time.monotonic()
        x = 0
        while time.monotonic() - t0 < SILENT_S:
            x = (x * 31 + 7) % 1_000_003  # busy: the GIL is released only at switch intervals
        raise BuildTimeoutError("the silent stage ended")


def test_a_stage_longer_than_the_liveness_window_is_not_runner_lost(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    silent = _SilentStage()
    monkeypatch.setattr(builds_module, "build_map", silent)
    assert beat_interval_s(STALE_AFTER_S) <= STALE_AFTER_S / 4
    app = make_test_app(tmp_path, build_stale_after_s=STALE_AFTER_S)
    with TestClient(app) as c:
        r = c.post("/v1/maps:build", params={"map_id": "room"}, json=_recording(6)[0])
        assert r.status_code == 202, r.text
        assert silent.started.wait(30)
        seen = []
        t0 = time.monotonic()
        while True:  # poll as a client does: every poll sweeps stale jobs first
            job = c.get(r.headers["Location"]).json()
            seen.append(job["status"])
            if job["status"] in ("succeeded", "failed") or time.monotonic() - t0 > 60:
                break
            time.sleep(0.25)
        assert time.monotonic() - t0 >= STALE_AFTER_S  # the polls spanned the window
        assert job["status"] == "failed", job
        assert job["error"]["reason"] == "time_budget_exceeded", job  # not runner_lost
        assert set(seen[:-1]) == {"running"}
        # the heartbeat thread ends with the last job
        t0 = time.monotonic()
        runner = app.state.services.builds.runner
        while runner._beat_thread is not None and time.monotonic() - t0 < 10:
            time.sleep(0.1)
        assert runner._beat_thread is None
