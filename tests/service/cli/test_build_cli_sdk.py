"""``quadloc maps build`` (local) and ``client.build_map`` (SDK against a live server)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

import quadloc_sdk as sdk
from quadloc.service.cli.main import main
from quadloc_sdk.build import BuildFailedError
from tests.service.api.test_api_build import _recording
from tests.service.api.test_api_calibration import _noisy_recording

#: Starts real servers / subprocesses: left out of the inner loop (pytest -m "not slow").
pytestmark = pytest.mark.slow


@pytest.fixture
def db(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> list[str]:
    for k in ("QUADLOC_DATABASE_URL", "QUADLOC_API_KEYS", "QUADLOC_DATA_DIR"):
        monkeypatch.delenv(k, raising=False)
    return ["--database-url", f"sqlite:///{tmp_path / 'cli.db'}"]


def test_cli_maps_build_creates_then_updates(db: list[str], tmp_path: Path,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    rec, _ = _recording()
    src = tmp_path / "recording.json"
    src.write_text(json.dumps(rec))
    report = tmp_path / "report.json"
    assert main(["maps", "build", str(src), "--map-id", "room", "--report", str(report),
                 *db]) == 0
    out = capsys.readouterr()
    assert "room version 1 (3 objects" in out.out
    assert "% " in out.err  # the progress bar
    assert len(json.loads(report.read_text())["objects"]) == 3
    assert main(["maps", "build", str(src), "--map-id", "room", *db]) == 2  # exists
    assert "--update" in capsys.readouterr().err
    assert main(["maps", "build", str(src), "--map-id", "room", "--update", *db]) == 0
    assert "room version 2" in capsys.readouterr().out


def test_cli_maps_build_names_bad_fields(db: list[str], tmp_path: Path,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    rec, _ = _recording(4)
    rec["frames"][0]["detections"][1]["label"] = ""
    src = tmp_path / "bad.json"
    src.write_text(json.dumps(rec))
    assert main(["maps", "build", str(src), "--map-id", "x", *db]) == 2
    err = capsys.readouterr().err
    assert "frames[0].detections[1].label" in err
    assert main(["maps", "export", "x", *db]) != 0  # nothing stored


def test_sdk_build_map_waits_and_reports_progress(live_server: str) -> None:
    rec, _ = _recording()
    seen = []
    with sdk.QuadLocClient(live_server) as client:
        job = client.build_map(rec, map_id="sdk-room", on_progress=seen.append,
                               poll_interval_s=0.1, timeout_s=120)
        assert job.status == "succeeded" and job.map_version == 1
        assert len(job.report["objects"]) == 3
        assert seen and seen[0].status in ("queued", "running")
        m = client.get_map("sdk-room")
        assert len(m.map["objects"]) == 3
        # a new version needs the ETag; a stale one is refused before any job starts
        with pytest.raises(sdk.errors.QuadLocError):
            client.build_map(rec, map_id="sdk-room", if_match='"stale"')
        job2 = client.build_map(rec, map_id="sdk-room", if_match=m.etag, poll_interval_s=0.1)
        assert job2.map_version == 2
        # a recording with nothing to associate fails with a reason
        empty = {**rec, "frames": [{**f, "detections": []} for f in rec["frames"]]}
        with pytest.raises(BuildFailedError) as exc:
            client.build_map(empty, map_id="sdk-empty", poll_interval_s=0.1)
        assert exc.value.job.error["reason"] == "no_objects"


def test_cli_maps_build_remote(live_server: str, tmp_path: Path,
                               capsys: pytest.CaptureFixture[str]) -> None:
    rec, _ = _recording()
    src = tmp_path / "recording.json"
    src.write_text(json.dumps(rec))
    assert main(["--url", live_server, "maps", "build", str(src), "--map-id", "cli-remote"]) == 0
    assert "cli-remote version 1 (3 objects" in capsys.readouterr().out
    # exists: refused without --update (the server wants If-Match), then a new version
    assert main(["--url", live_server, "maps", "build", str(src), "--map-id", "cli-remote"]) == 2
    assert "--update" in capsys.readouterr().err
    assert main(["--url", live_server, "maps", "build", str(src), "--map-id", "cli-remote",
                 "--update"]) == 0
    assert "cli-remote version 2" in capsys.readouterr().out


def test_async_sdk_build_map(live_server: str) -> None:
    import asyncio

    rec, _ = _recording(12)

    async def go() -> sdk.build.BuildJob:
        async with sdk.AsyncQuadLocClient(live_server) as client:
            return await client.build_map(rec, map_id="async-room", poll_interval_s=0.1)

    job = asyncio.run(go())
    assert job.status == "succeeded" and job.map_version == 1
    assert job.report["counts"]["objects"] == 3


def test_cli_calibrate_needs_held_out_frames_then_stores(db: list[str], tmp_path: Path,
                                                         capsys: pytest.CaptureFixture[str]
                                                         ) -> None:
    """``quadloc calibrate``: a recording without ``holdout_every`` is refused naming the field
    (nothing stored); with it, the calibration is fitted and stored (before / after lines)."""
    rec = _noisy_recording(120)
    src = tmp_path / "rec.json"
    src.write_text(json.dumps(rec))
    assert main(["maps", "build", str(src), "--map-id", "room", *db]) == 0
    capsys.readouterr()
    assert main(["calibrate", str(src), "--map", "room", *db]) == 2
    assert "holdout_every" in capsys.readouterr().err
    src.write_text(json.dumps({**rec, "holdout_every": 2}))
    assert main(["calibrate", str(src), "--map", "room", *db]) == 0
    out = capsys.readouterr().out
    assert "calibration stored for level_set" in out and "before" in out and "after" in out
    assert main(["calibrate", str(src), "--map", "nowhere", *db]) == 1
