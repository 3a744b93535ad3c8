"""The ``quadloc`` command line (entry point ``quadloc = quadloc.service.cli.main:main``): the
parser of every command, and their dispatch.

Map commands, ``localize`` and ``maps build`` talk to a running server through the SDK when a
server URL is given (``--url`` or ``QUADLOC_URL``, with ``--api-key`` / ``QUADLOC_API_KEY``);
without one they run the application's use cases in this process, on the local database.
``serve`` runs the REST API. Each command lives in its own module of this package, imported when
the command runs (``COMMANDS``): ``quadloc --help`` and ``--version`` load no solver.
"""

from __future__ import annotations

import argparse
import importlib
from collections.abc import Callable
from importlib.metadata import PackageNotFoundError, version
from typing import Any

from quadloc.service.schemas.common import API_VERSION

__all__ = ["COMMANDS", "build_parser", "main"]

#: The function of each command: ``"<module of quadloc.service.cli>:<function>"``.
COMMANDS: dict[str, str] = {
    "serve": "serve:cmd_serve",
    "worker": "worker:cmd_worker",
    "openapi": "serve:cmd_openapi",
    "hash-key": "serve:cmd_hash_key",
    "maps list": "maps:cmd_list",
    "maps versions": "maps:cmd_versions",
    "maps import": "maps:cmd_import",
    "maps export": "maps:cmd_export",
    "maps delete": "maps:cmd_delete",
    "maps build": "build:cmd_maps_build",
    "localize": "localize:cmd_localize",
    "track": "track:cmd_track",
    "import-recording": "importing:cmd_import_recording",
    "calibrate": "calibrate:cmd_calibrate",
}

EPILOG = """\
examples (in this process, on the local database):
  quadloc serve                                  # http://127.0.0.1:8000, SQLite, demo map "chess"
  quadloc serve --port 9000 --database-url sqlite:////tmp/q.db
  quadloc worker --database-url postgresql://quadloc@db/quadloc   # runs the API's map builds
  QUADLOC_API_KEYS="$(quadloc hash-key s3cret --scopes read+write)" quadloc serve --host 0.0.0.0
  quadloc maps list
  quadloc maps import docs/examples/office_map.json         # our map format (docs/maps.md)
  quadloc maps import tests/support/data/chess_scene.json --chess --map-id chess2
  quadloc maps versions chess
  quadloc maps export chess --version 1 > chess_v1.json
  quadloc maps build docs/examples/room_recording.json.gz --map-id room   # docs/map_building.md
  quadloc calibrate docs/examples/room_recording.json.gz --map room       # its held-out frames
  quadloc localize --map chess docs/examples/localize_chess.json
  quadloc track --map chess docs/examples/track_chess.json
  quadloc openapi --output docs/openapi.json     # regenerate the published schema

examples (a running server, through the SDK):
  quadloc --url http://127.0.0.1:8000 maps list
  export QUADLOC_URL=https://quadloc.example.com QUADLOC_API_KEY=s3cret
  quadloc maps import docs/examples/office_map.json --update   # create, or add a new version
  quadloc maps versions office-3
  quadloc localize --map chess frames/*.json     # one line per frame, progress on stderr

settings come from QUADLOC_* environment variables (docs/deployment.md, "Settings"), e.g.
QUADLOC_DATABASE_URL, QUADLOC_API_KEYS, QUADLOC_DATA_DIR; QUADLOC_URL and QUADLOC_API_KEY
select a server for the map commands, maps build and localize; flags override them.
"""


def _installed(name: str) -> str:
    try:
        return version(name)
    except PackageNotFoundError:  # pragma: no cover - running from a bare checkout
        return "not installed"


def version_text() -> str:
    """``quadloc X (REST API Y, quadloc-sdk Z)``."""
    return (f"quadloc {_installed('quadloc')} (REST API {API_VERSION}, "
            f"quadloc-sdk {_installed('quadloc-sdk')})")


def _remote(p: argparse.ArgumentParser, suppress: bool = True) -> None:
    default = argparse.SUPPRESS if suppress else None
    p.add_argument("--url", metavar="URL", default=default,
                   help="QuadLoc server to talk to, e.g. http://127.0.0.1:8000 (default: "
                        "QUADLOC_URL; unset = work on the local database)")
    p.add_argument("--api-key", metavar="KEY", default=default,
                   help="API key sent as 'Authorization: Bearer KEY' (default: QUADLOC_API_KEY)")


def _db(p: argparse.ArgumentParser, server: bool = True) -> None:
    p.add_argument("--database-url", metavar="URL",
                   help="sqlite:///path or postgresql://... (default: QUADLOC_DATABASE_URL "
                        "or SQLite under QUADLOC_DATA_DIR)")
    if server:
        _remote(p)


def _command(p: argparse.ArgumentParser, name: str) -> argparse.ArgumentParser:
    p.set_defaults(command_name=name)
    return p


def _maps_parsers(sub: Any, fmt: type[argparse.HelpFormatter]) -> None:
    maps_p = sub.add_parser(
        "maps", formatter_class=fmt, help="list, import, export, delete, build maps",
        description="Manage maps on a server (--url / QUADLOC_URL, through the SDK) or directly "
                    "in the local database.",
        epilog="examples:\n  quadloc maps list\n"
               "  quadloc maps import docs/examples/office_map.json\n"
               "  quadloc maps import tests/support/data/chess_scene.json --chess "
               "--map-id chess2\n  quadloc maps export chess > chess.json\n"
               "  quadloc maps build docs/examples/room_recording.json.gz --map-id room\n"
               "  quadloc --url http://127.0.0.1:8000 maps versions chess\n")
    msub = maps_p.add_subparsers(dest="maps_command", metavar="ACTION", required=True)
    p = _command(msub.add_parser("list", help="list maps with their latest version"),
                 "maps list")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    _db(p)
    p = _command(msub.add_parser("versions", help="list a map's stored versions"),
                 "maps versions")
    p.add_argument("map_id", metavar="ID")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    _db(p)
    p = _command(msub.add_parser("import", help="create a map from a JSON file ('-' = stdin)"),
                 "maps import")
    p.add_argument("file", help="map JSON (docs/maps.md format, or the Chess format with --chess)")
    p.add_argument("--chess", action="store_true", help="the file is in the Chess scene format")
    p.add_argument("--map-id", help="id of the map (overrides the file's; Chess default 'chess')")
    p.add_argument("--name", help="display name (overrides the file's)")
    p.add_argument("--update", action="store_true",
                   help="if the id exists, store the file as its next version")
    _db(p)
    p = _command(msub.add_parser("export", help="print a map as JSON (docs/maps.md format)"),
                 "maps export")
    p.add_argument("map_id", metavar="ID")
    p.add_argument("--version", type=int, help="version to export (default: latest)")
    p.add_argument("-o", "--output", help="write to this file instead of stdout")
    _db(p)
    p = _command(msub.add_parser("delete", help="delete a map and all its versions"),
                 "maps delete")
    p.add_argument("map_id", metavar="ID")
    _db(p)
    p = _command(msub.add_parser(
        "build", help="build a map from a recording (posed frames + detections)",
        description="With --url / QUADLOC_URL: a POST /v1/maps:build job on that server, its "
                    "progress polled. Without: the same build in this process against the "
                    "local database. A progress bar goes to stderr either way. An existing map "
                    "id needs --update (stored as its next version; refused if the map changed "
                    "during the build). --report PATH writes the build report (which detections "
                    "built which object, per-object quality, rejected detections) as JSON. Exit "
                    "codes: 0 built, 1 no map (nothing associated, time budget, job failed), 2 "
                    "bad input or store / server error."), "maps build")
    p.add_argument("file", help="recording JSON (docs/map_building.md; '-' = stdin)")
    p.add_argument("--map-id", required=True, help="id of the map to create (or update)")
    p.add_argument("--update", action="store_true",
                   help="if the id exists, store the build as its next version")
    p.add_argument("--report", metavar="PATH", help="write the build report (JSON) here")
    _db(p)


def _import_parser(sub: Any, fmt: type[argparse.HelpFormatter]) -> None:
    p = _command(sub.add_parser(
        "import-recording", formatter_class=fmt,
        help="write a recording (maps build's input) from a trajectory and COCO detections",
        description="A camera trajectory (TUM RGB-D, COLMAP images.txt + cameras.txt, or an "
                    "ARKit/ARCore JSON log) and detections in the COCO results format (boxes, "
                    "polygons or RLE masks, scores) -> a recording JSON (docs/map_building.md, "
                    "'Importing your data'; the functions: quadloc_sdk.importers). Frames are "
                    "the trajectory's, matched to the detections by image name (COCO "
                    "annotations' images[].file_name, or the image id).",
        epilog="examples:\n  quadloc import-recording --colmap sparse/0 --coco-results det.json "
               "--coco-annotations instances.json -o room.json\n"
               "  quadloc import-recording --tum groundtruth.txt --tum-images rgb.txt "
               "--camera 525,525,319.5,239.5,640,480 --coco-results det.json "
               "--coco-annotations instances.json -o room.json\n"), "import-recording")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--tum", metavar="FILE", help="TUM RGB-D trajectory (OpenCV camera axes)")
    src.add_argument("--colmap", metavar="DIR", help="COLMAP text model folder (images.txt, "
                                                     "cameras.txt; PINHOLE cameras)")
    src.add_argument("--ar-log", metavar="FILE", help="ARKit/ARCore JSON log (OpenGL axes)")
    p.add_argument("--tum-images", metavar="FILE",
                   help="TUM rgb.txt ('timestamp filename'): frames named by image file")
    p.add_argument("--camera", metavar="FX,FY,CX,CY,W,H",
                   help="intrinsics (px) and image size (required unless --colmap)")
    p.add_argument("--coco-results", metavar="FILE", required=True,
                   help="COCO results JSON (a list of detections)")
    p.add_argument("--coco-annotations", metavar="FILE",
                   help="COCO annotations JSON: its categories (labels) and images (names)")
    p.add_argument("--min-score", type=float, default=0.0, help="drop detections below this")
    p.add_argument("--holdout-every", type=int, metavar="K",
                   help="hold every K-th frame out of the build, for quadloc calibrate")
    p.add_argument("--name", help="name of the map to build")
    p.add_argument("-o", "--output", required=True, help="recording JSON to write ('-' = stdout)")


def build_parser() -> argparse.ArgumentParser:
    """The parser of every command (argparse only: building it imports no solver)."""
    fmt = argparse.RawDescriptionHelpFormatter
    parser = argparse.ArgumentParser(
        prog="quadloc", formatter_class=fmt, epilog=EPILOG,
        description="QuadLoc: camera relocalization from object detections (ellipses) and a "
                    "map of 3D ellipsoids. Serve the REST API, manage and build maps, localize "
                    "frames, replay tracking sessions.")
    parser.add_argument("--version", action="version", version=version_text(),
                        help="print the versions of quadloc, its REST API and the SDK; exit")
    _remote(parser, suppress=False)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    p = _command(sub.add_parser(
        "serve", formatter_class=fmt, help="run the REST API (Uvicorn)",
        description="Run the REST API. Without QUADLOC_API_KEYS the API is open and only "
                    "loopback hosts are allowed.",
        epilog="examples:\n  quadloc serve\n  quadloc serve --port 9000\n"
               "  QUADLOC_API_KEYS=<sha256>:read+write quadloc serve --host 0.0.0.0\n"), "serve")
    p.add_argument("--host", help="bind address (default 127.0.0.1 / QUADLOC_HOST)")
    p.add_argument("--port", type=int, help="port (default 8000 / QUADLOC_PORT)")
    p.add_argument("--workers", type=int, help="worker processes (default 1; one per core "
                                               "at most, the solver is CPU-bound)")
    p.add_argument("--access-log", action="store_true", help="log every request")
    _db(p, server=False)

    p = _command(sub.add_parser(
        "worker", formatter_class=fmt, help="run map builds from the job queue (PostgreSQL)",
        description="Take map-building jobs from the job queue in PostgreSQL and run them, "
                    "apart from the API replicas (docs/deployment.md, 'Build workers'). "
                    "SIGTERM: the running builds finish within QUADLOC_SHUTDOWN_GRACE_S - 2 s "
                    "or go back to the queue. With SQLite builds run in the API process.",
        epilog="examples:\n  QUADLOC_DATABASE_URL=postgresql://quadloc@db/quadloc quadloc worker\n"
               "  quadloc worker --database-url postgresql://quadloc@db/quadloc "
               "--health-port 0\n"), "worker")
    p.add_argument("--name", help="the worker's name in the logs (default quadloc-worker)")
    p.add_argument("--health-port", type=int, metavar="PORT",
                   help="port of GET /healthz (default 8001 / QUADLOC_WORKER_HEALTH_PORT; "
                        "0: none)")
    _db(p, server=False)

    _maps_parsers(sub, fmt)

    p = _command(sub.add_parser(
        "localize", formatter_class=fmt, help="localize frames (prints the pose)",
        description="Localize the frame in each FILE (the body of POST /v1/maps/{id}/localize) "
                    "against a map: on the server of --url / QUADLOC_URL, or in this process "
                    "on the local database. Several files: one table row per frame and a "
                    "progress bar on stderr. Exit status 0 when every frame localized, 1 when "
                    "one did not.",
        epilog="examples:\n  quadloc localize --map chess docs/examples/localize_chess.json\n"
               "  quadloc --url http://127.0.0.1:8000 localize --map chess frames/*.json\n"
               "  quadloc localize --map office --hint-zone room-301 frame.json\n"
               "  quadloc localize --map office --hint-position 12 3 1.5 --hint-sigma 5 "
               "frame.json\n"),
        "localize")
    p.add_argument("file", nargs="+", help="request JSON ('-' = stdin)")
    p.add_argument("--map", required=True, metavar="ID", help="map id")
    p.add_argument("--version", type=int, help="map version (default: latest)")
    p.add_argument("--convention", choices=["opencv", "opengl"],
                   help="camera axes of the printed pose (overrides the file's options)")
    p.add_argument("--metric", metavar="METRIC",
                   help="refinement metric ('none': the P3P/P2E pose unrefined; overrides the "
                        "file's options)")
    p.add_argument("--on-ambiguity", choices=["not_localized", "best"],
                   help="ambiguous frames: not localized (default) or the best pose; both "
                        "print the candidates with their probabilities")
    p.add_argument("--min-confidence", type=float, metavar="P",
                   help="answers below this confidence are not localized (their candidates "
                        "are printed); default: the calibrated one")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--hint-zone", metavar="ID",
                       help="hint: the camera is in this zone of the map (replaces the file's "
                            "hint)")
    where.add_argument("--hint-position", type=float, nargs=3, metavar=("X", "Y", "Z"),
                       help="hint: the camera is near this position (map world frame, m; needs "
                            "--hint-sigma; replaces the file's hint)")
    p.add_argument("--hint-sigma", type=float, metavar="M",
                   help="1-sigma uncertainty of --hint-position (m)")
    p.add_argument("--json", action="store_true", help="print the full JSON response")
    _db(p)

    p = _command(sub.add_parser(
        "track", help="replay a recorded tracking session (prints the trajectory)",
        description="Recording format (JSON): {\"camera\": {fx, fy, cx, cy, width, height}, "
                    "\"convention\": \"opencv\" | \"opengl\", \"options\": {...session "
                    "options...}, \"frames\": [...frames as for POST /v1/sessions/{id}/frames"
                    "...], \"ground_truth_world_from_camera\": [4x4 | null, ...]}; the last key "
                    "is optional (one entry per frame, in the recording's convention). Prints "
                    "one line per frame (state, camera position, confidence) and, with ground "
                    "truth, the trajectory error of the frames with a pose. Exit status 0 when "
                    "some frame was tracked, 1 otherwise, 2 on bad input.",
        epilog="example:\n  quadloc track --map chess docs/examples/track_chess.json\n",
        formatter_class=fmt), "track")
    p.add_argument("file", help="recording JSON ('-' = stdin)")
    p.add_argument("--map", required=True, metavar="ID", help="map id")
    p.add_argument("--json", action="store_true", help="print the frame results as JSON")
    _db(p, server=False)

    _import_parser(sub, fmt)

    p = _command(sub.add_parser(
        "calibrate", formatter_class=fmt,
        help="calibrate a map version from the recording it was built from",
        description="Fit the covariance scale and the confidence model of a map version from "
                    "the frames its recording held out of the build (holdout_every; their app "
                    "poses the reference), store them with the version (localize and sessions use "
                    "them), "
                    "and print the mean NEES and the confidence calibration error before / "
                    "after on those frames (after: cross-fitted, each frame by a fit that did "
                    "not see it). On the server of --url / QUADLOC_URL, or in this process on "
                    "the local database.",
        epilog="examples (docs/map_building.md):\n"
               "  quadloc calibrate docs/examples/room_recording.json.gz --map room\n"
               "  quadloc --url http://127.0.0.1:8000 calibrate "
               "docs/examples/room_recording.json.gz --map room\n"),
        "calibrate")
    p.add_argument("file", help="recording JSON with holdout_every ('-' = stdin, .gz ok)")
    p.add_argument("--map", required=True, metavar="ID", help="map id")
    p.add_argument("--version", type=int, help="map version (default: latest)")
    p.add_argument("--json", action="store_true", help="also print the result as JSON (stderr)")
    _db(p)

    p = _command(sub.add_parser("openapi", help="print or write the OpenAPI document"),
                 "openapi")
    p.add_argument("-o", "--output", help="write to this file (e.g. docs/openapi.json)")
    p.add_argument("--check", metavar="FILE",
                   help="exit 1 if FILE differs from the current schema")

    p = _command(sub.add_parser(
        "hash-key", help="hash an API key for QUADLOC_API_KEYS",
        description="Print '<sha256>:<scopes>' for QUADLOC_API_KEYS. Without KEY, a random key "
                    "is generated and shown on stderr."), "hash-key")
    p.add_argument("key", nargs="?", help="the key (default: generate one)")
    p.add_argument("--scopes", default="read", help="read, write or read+write (default read)")
    return parser


def command_function(name: str) -> Callable[[argparse.Namespace], int]:
    """The function of command ``name`` (its module imported now: see ``COMMANDS``)."""
    module, function = COMMANDS[name].split(":")
    command: Callable[[argparse.Namespace], int] = getattr(
        importlib.import_module(f"quadloc.service.cli.{module}"), function)
    return command


def main(argv: list[str] | None = None) -> int:
    """Run the CLI; returns the exit status."""
    args = build_parser().parse_args(argv)
    run = importlib.import_module("quadloc.service.cli.common").run
    return int(run(command_function(args.command_name), args))
