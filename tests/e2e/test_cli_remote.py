"""The ``quadloc`` CLI managing maps and localizing on a RUNNING server with an API key (the
real entry point in a subprocess, through the SDK), plus its table and progress output."""

from __future__ import annotations

import io
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from quadloc.service.cli.common import Progress, format_table
from quadloc.service.schemas.examples import MAP_EXAMPLE
from quadloc.service.settings import hash_api_key

#: Starts real servers / subprocesses: left out of the inner loop (pytest -m "not slow").
pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parents[2]
EXAMPLE = REPO / "docs" / "examples" / "localize_chess.json"
WRITE_KEY, READ_KEY = "cli-writer-key", "cli-reader-key"


def quadloc(*args: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    full_env = {k: v for k, v in os.environ.items() if not k.startswith("QUADLOC_")}
    full_env.update(env or {})
    return subprocess.run([sys.executable, "-c", "import sys; from quadloc.service.cli.main import "
                           "main; sys.exit(main(sys.argv[1:]))", *args], cwd=REPO, env=full_env,
                          capture_output=True, text=True, timeout=120)


def _columns_aligned(table: str) -> bool:
    """Every line's cells start where the header's do (left-aligned columns)."""
    lines = table.strip().splitlines()
    header = lines[0]
    starts = [i for i in range(1, len(header)) if header[i] != " " and header[i - 1] == " "]
    return all(line[s - 1] == " " for line in lines[1:] for s in starts if s < len(line))


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory):
    from tests.conftest import run_live_server

    keys = f"{hash_api_key(WRITE_KEY)}:read+write,{hash_api_key(READ_KEY)}:read"
    with run_live_server(tmp_path_factory.mktemp("cli_remote"),
                         {"QUADLOC_API_KEYS": keys}) as base:
        yield base


def test_cli_manages_a_map_on_a_server_with_a_key(server: str, tmp_path: Path) -> None:
    doc = {**MAP_EXAMPLE, "map_id": "cli-remote-office"}
    src = tmp_path / "office.json"
    src.write_text(json.dumps(doc))
    env = {"QUADLOC_URL": server, "QUADLOC_API_KEY": WRITE_KEY}

    no_key = quadloc("maps", "list", env={"QUADLOC_URL": server})
    assert no_key.returncode == 2 and "401" in no_key.stderr, no_key.stderr
    reader = quadloc("--url", server, "--api-key", READ_KEY, "maps", "import", str(src))
    assert reader.returncode == 2 and "403" in reader.stderr, reader.stderr

    created = quadloc("maps", "import", str(src), env=env)
    assert created.returncode == 0, created.stderr
    assert "cli-remote-office version 1 (3 objects)" in created.stdout
    again = quadloc("maps", "import", str(src), env=env)
    assert again.returncode == 2 and "--update" in again.stderr
    # flags on the subcommand work as well as the environment
    updated = quadloc("maps", "import", str(src), "--update", "--name", "Renamed",
                      "--url", server, "--api-key", WRITE_KEY)
    assert updated.returncode == 0, updated.stderr
    assert "cli-remote-office version 2" in updated.stdout

    versions = quadloc("maps", "versions", "cli-remote-office", env=env)
    assert versions.returncode == 0, versions.stderr
    lines = versions.stdout.strip().splitlines()
    assert lines[0].split() == ["VERSION", "CREATED", "ETAG"] and len(lines) == 3
    assert [line.split()[0] for line in lines[1:]] == ["1", "2"]
    as_json = json.loads(quadloc("maps", "versions", "cli-remote-office", "--json",
                                 env=env).stdout)
    assert [v["version"] for v in as_json] == [1, 2]

    listed = quadloc("maps", "list", env=env)
    assert listed.returncode == 0 and "cli-remote-office" in listed.stdout
    assert _columns_aligned(listed.stdout), listed.stdout

    exported = quadloc("maps", "export", "cli-remote-office", "--version", "1", env=env)
    assert exported.returncode == 0
    v1 = json.loads(exported.stdout)
    assert v1["version"] == 1 and v1["name"] == doc["name"]
    assert json.loads(quadloc("maps", "export", "cli-remote-office", env=env).stdout)[
        "name"] == "Renamed"

    deleted = quadloc("maps", "delete", "cli-remote-office", env=env)
    assert deleted.returncode == 0, deleted.stderr
    gone = quadloc("maps", "versions", "cli-remote-office", env=env)
    assert gone.returncode == 1 and "404" in gone.stderr


def test_cli_localizes_on_the_server(server: str, tmp_path: Path) -> None:
    env = {"QUADLOC_URL": server, "QUADLOC_API_KEY": READ_KEY}
    one = quadloc("localize", "--map", "chess", str(EXAMPLE), env=env)
    assert one.returncode == 0, one.stderr
    assert "world_from_camera (opencv camera axes)" in one.stdout
    assert "translation_m   = [-0.02" in one.stdout
    # a frame that cannot localize: exit status 1, in the table of several frames
    bad = json.loads(EXAMPLE.read_text())
    bad["detections"] = bad["detections"][:1]
    lone = tmp_path / "lone.json"
    lone.write_text(json.dumps(bad))
    many = quadloc("localize", "--map", "chess", str(EXAMPLE), str(lone), env=env)
    assert many.returncode == 1, many.stderr
    rows = many.stdout.strip().splitlines()
    assert rows[0].split()[:2] == ["FILE", "LOCALIZED"] and len(rows) == 3
    assert " yes " in rows[1] and " no (" in rows[2]
    as_json = json.loads(quadloc("localize", "--map", "chess", str(EXAMPLE), "--json",
                                 env=env).stdout)
    assert as_json["localized"] and as_json["world_from_camera"]["quaternion_xyzw"]
    unreachable = quadloc("localize", "--map", "chess", str(EXAMPLE),
                          env={"QUADLOC_URL": "http://127.0.0.1:9"})
    assert unreachable.returncode == 2 and "cannot reach the server" in unreachable.stderr


def test_version_flag() -> None:
    out = quadloc("--version")
    assert out.returncode == 0 and out.stdout.startswith("quadloc ")
    assert "quadloc-sdk" in out.stdout


def test_table_and_progress_helpers() -> None:
    table = format_table(["ID", "N", "NAME"], [["a", "1", "x"], ["longer-id", "12", "y"]],
                         right={1})
    assert table.splitlines() == ["ID          N  NAME", "a           1  x",
                                  "longer-id  12  y"]
    tty = io.StringIO()
    tty.isatty = lambda: True  # type: ignore[method-assign]
    p = Progress(4, tty)
    p.update(2, "frame.json")
    p.close()
    assert "[###############...............] 2/4  frame.json" in tty.getvalue()
    pipe = io.StringIO()
    q = Progress(4, pipe)
    q.update(2, "x")
    q.close()
    assert pipe.getvalue() == ""  # no bar in logs and pipes


def test_calibration_on_a_server_from_the_sdk_and_the_cli(server: str) -> None:
    """The shipped recording built on the server (SDK), calibrated by ``calibrate_map`` and
    by ``quadloc --url ... calibrate``: both store the same fit (deterministic: same frames,
    same constants), the CLI prints what ``get_calibration`` reads back, a read key is
    refused (403) and an unknown map is exit status 1."""
    from quadloc_sdk import Calibration, QuadLocClient

    recording = REPO / "docs" / "examples" / "room_recording.json.gz"
    doc = json.loads(__import__("gzip").decompress(recording.read_bytes()))
    held = sum(1 for i in range(len(doc["frames"]))
               if (i + 1) % int(doc["holdout_every"]) == 0)
    with QuadLocClient(server, api_key=WRITE_KEY) as c:
        c.build_map(doc, map_id="cli-calibrated")
        sdk = c.calibrate_map("cli-calibrated", doc)
        assert isinstance(sdk, Calibration) and sdk.map_version == 1
        assert sdk.fit_frames == held == sdk.before.frames == sdk.after.frames
        assert sdk.after.mean_nees is not None and sdk.covariance_scale > 0
        assert c.get_calibration("cli-calibrated") == sdk
    refused = quadloc("--url", server, "--api-key", READ_KEY, "calibrate", str(recording),
                      "--map", "cli-calibrated")
    assert refused.returncode == 2 and "403" in refused.stderr, refused.stderr
    missing = quadloc("--url", server, "--api-key", WRITE_KEY, "calibrate", str(recording),
                      "--map", "no-such-map")
    assert missing.returncode == 1, missing.stderr
    cli = quadloc("--url", server, "--api-key", WRITE_KEY, "calibrate", str(recording),
                  "--map", "cli-calibrated", "--json")
    assert cli.returncode == 0, cli.stderr
    with QuadLocClient(server, api_key=READ_KEY) as c:
        stored = c.get_calibration("cli-calibrated")
    assert Calibration.model_validate_json(cli.stderr) == stored == sdk
    assert f"covariance scale {stored.covariance_scale:.4g}" in cli.stdout
    assert f"calibration error {stored.after.calibration_error:.3f}" in cli.stdout
    assert stored.after.calibration_error_sd is not None  # 100 held-out frames: 4 blocks
