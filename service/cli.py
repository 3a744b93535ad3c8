"""The ``quadloc`` command line (entry point ``quadloc = service.cli:main``).

Map commands work directly on the database (no server needed); ``serve`` runs the REST API.
"""

from __future__ import annotations

import argparse
import json
import os
import secrets
import sys
from pathlib import Path
from typing import Any

__all__ = ["build_parser", "main", "openapi_document", "openapi_text"]

REPO_ROOT = Path(__file__).resolve().parents[1]
OPENAPI_PATH = REPO_ROOT / "docs" / "openapi.json"

EPILOG = """\
examples:
  quadloc serve                                  # http://127.0.0.1:8000, SQLite, demo map "chess"
  quadloc serve --port 9000 --database-url sqlite:////tmp/q.db
  QUADLOC_API_KEYS="$(quadloc hash-key s3cret --scopes read+write)" quadloc serve --host 0.0.0.0
  quadloc maps list
  quadloc maps import office.json                # our map format (docs/maps.md)
  quadloc maps import chess_scene.json --chess --map-id chess2
  quadloc maps export chess --version 1 > chess_v1.json
  quadloc localize --map chess docs/examples/localize_chess.json
  quadloc openapi --output docs/openapi.json     # regenerate the published schema

settings come from QUADLOC_* environment variables (see service/settings.py), e.g.
QUADLOC_DATABASE_URL, QUADLOC_API_KEYS, QUADLOC_DATA_DIR; flags override them.
"""


def _settings(args: argparse.Namespace) -> Any:
    from service.settings import Settings

    overrides: dict[str, Any] = {}
    if getattr(args, "database_url", None):
        overrides["database_url"] = args.database_url
    return Settings(**overrides)


def _store(args: argparse.Namespace) -> Any:
    """The map store of the settings' database, with the demo map seeded like ``serve`` does."""
    from maps.store import MapStore
    from service.api.app import seed_demo_map

    settings = _settings(args)
    store = MapStore(settings.effective_database_url)
    if settings.seed_demo_map and settings.default_map_id:
        seed_demo_map(store, settings.default_map_id)
    return store


def _die(message: str, code: int = 2) -> int:
    print(f"quadloc: error: {message}", file=sys.stderr)
    return code


def _read_json(path: str) -> Any:
    text = sys.stdin.read() if path == "-" else Path(path).read_text(encoding="utf-8")
    return json.loads(text)


def _json_type(value: Any) -> str:
    """JSON name of a parsed value's type (for messages)."""
    if isinstance(value, bool):
        return "boolean"
    if isinstance(value, int | float):
        return "number"
    return {list: "array", str: "string", dict: "object", type(None): "null"}.get(
        type(value), type(value).__name__)


# ---------------------------------------------------------------------------------- commands


def cmd_serve(args: argparse.Namespace) -> int:
    import uvicorn

    from service.settings import check_bind_allowed

    if args.database_url:
        os.environ["QUADLOC_DATABASE_URL"] = args.database_url
    settings = _settings(args)
    host = args.host or settings.host
    port = settings.port if args.port is None else args.port
    workers = args.workers or settings.workers
    try:
        check_bind_allowed(settings, host)
    except ValueError as exc:
        return _die(str(exc))
    if not settings.auth_enabled:
        print(f"quadloc: no API key configured: the API is open, listening on loopback only "
              f"({host}:{port})", file=sys.stderr)
    uvicorn.run("service.api.app:create_app", factory=True, host=host, port=port,
                workers=workers, log_level=settings.log_level, access_log=args.access_log)
    return 0


def cmd_maps_list(args: argparse.Namespace) -> int:
    rows = _store(args).list()
    if args.json:
        print(json.dumps([{"map_id": r.map_id, "name": r.name, "version": r.latest_version,
                           "content_hash": r.content_hash,
                           "updated_at": r.updated_at.isoformat()} for r in rows], indent=2))
        return 0
    print(f"{'MAP_ID':<24} {'VERSION':>7}  {'UPDATED':<25} NAME")
    for r in rows:
        print(f"{r.map_id:<24} {r.latest_version:>7}  {r.updated_at.isoformat():<25} {r.name}")
    return 0


def cmd_maps_import(args: argparse.Namespace) -> int:
    from maps.errors import MapAlreadyExists, MapNotFound, VersionConflict
    from maps.model import MapValidationError, scene_map_from_chess, scene_map_from_dict

    try:
        data = _read_json(args.file)
    except (OSError, json.JSONDecodeError, UnicodeDecodeError) as exc:
        return _die(f"{args.file}: {exc}")
    if not isinstance(data, dict):
        return _die(f"{args.file}: a map must be a JSON object, got a JSON "
                    f"{_json_type(data)}")
    store = _store(args)
    try:
        if args.chess:
            scene_map = scene_map_from_chess(data, map_id=args.map_id or "chess",
                                             name=args.name or "Chess")
        else:
            if args.map_id:
                data = {**data, "map_id": args.map_id}
            if args.name:
                data = {**data, "name": args.name}
            scene_map = scene_map_from_dict(data, version=1)
    except MapValidationError as exc:
        for e in exc.errors:
            print(f"  {e['field']}: {e['message']}", file=sys.stderr)
        return _die(f"{args.file}: invalid map ({len(exc.errors)} problem(s))")
    try:
        stored = store.create(scene_map)
    except MapAlreadyExists:
        if not args.update:
            return _die(f"map {scene_map.map_id!r} exists; pass --update to add a new version")
        try:
            current = store.get(scene_map.map_id)
            new = type(scene_map).from_dict({**scene_map.to_dict(),
                                             "version": current.scene_map.version + 1})
            stored = store.update(scene_map.map_id, new, current.scene_map.version)
        except (VersionConflict, MapNotFound) as exc:
            return _die(str(exc))
    print(f"{stored.scene_map.map_id} version {stored.scene_map.version} "
          f"({len(stored.scene_map.objects)} objects) etag \"{stored.content_hash}\"")
    return 0


def cmd_maps_export(args: argparse.Namespace) -> int:
    from maps.errors import MapNotFound

    try:
        stored = _store(args).get(args.map_id, args.version)
    except MapNotFound as exc:
        return _die(str(exc), 1)
    text = json.dumps(stored.scene_map.to_dict(), indent=2) + "\n"
    if args.output:
        Path(args.output).write_text(text)
    else:
        sys.stdout.write(text)
    return 0


def cmd_maps_delete(args: argparse.Namespace) -> int:
    from maps.errors import MapNotFound

    try:
        _store(args).delete(args.map_id)
    except MapNotFound as exc:
        return _die(str(exc), 1)
    print(f"deleted {args.map_id} (all versions)")
    return 0


def cmd_localize(args: argparse.Namespace) -> int:
    from pydantic import ValidationError

    from maps.errors import MapNotFound
    from service.api.errors import ProblemError, field_path
    from service.api.metrics import ApiMetrics
    from service.api.schemas import LocalizeRequest
    from service.api.solver import Solver

    try:
        request = LocalizeRequest.model_validate(_read_json(args.file))
    except (OSError, json.JSONDecodeError) as exc:
        return _die(f"{args.file}: {exc}")
    except ValidationError as exc:
        for e in exc.errors():
            print(f"  {field_path(e['loc'])}: {e['msg']}", file=sys.stderr)
        return _die(f"{args.file}: invalid request")
    if args.convention:
        request = request.model_copy(update={"options": request.options.model_copy(
            update={"output_convention": args.convention})})
    settings = _settings(args)
    try:
        compiled = _store(args).compiled(args.map, args.version)
    except MapNotFound as exc:
        return _die(str(exc), 1)
    solver = Solver(ApiMetrics(), 1, 0.0, settings.solve_time_budget_ms, settings.max_detections)
    try:
        result = solver.localize_frames(compiled, [request], batch=False)[0]
    except ProblemError as exc:
        return _die(exc.detail)
    if args.json:
        print(result.model_dump_json(indent=2))
        return 0 if result.localized else 1
    print(f"map {result.map_id} v{result.map_version}  frame {result.frame_id or '-'}")
    if not result.localized:
        print(f"NOT LOCALIZED: {result.reason}")
        return 1
    pose = result.world_from_camera
    assert pose is not None
    print(f"world_from_camera ({pose.convention} camera axes):")
    print("  quaternion_wxyz = [" + ", ".join(f"{v:+.6f}" for v in pose.quaternion_wxyz) + "]")
    print("  translation_m   = [" + ", ".join(f"{v:+.4f}" for v in pose.translation_m) + "]")
    print(f"confidence {result.confidence:.3f}  inliers {len(result.inliers)}  "
          f"metric {result.metric}  total {result.timings_ms.get('total', float('nan')):.1f} ms")
    if result.covariance is not None:
        import numpy as np

        sd = np.sqrt(np.clip(np.diag(np.array(result.covariance.matrix)), 0, None))
        print(f"std: rotation [deg] {np.degrees(sd[:3]).round(3).tolist()}  "
              f"translation [m] {sd[3:].round(4).tolist()}")
    return 0


def openapi_document() -> dict[str, Any]:
    """The API's OpenAPI document (built on an in-memory store, nothing seeded)."""
    from maps.store import MapStore
    from service.api.app import build_openapi, create_app
    from service.settings import Settings

    app = create_app(Settings(seed_demo_map=False, api_keys=""), store=MapStore("sqlite://"))
    return build_openapi(app)


def openapi_text() -> str:
    """``docs/openapi.json`` as written by ``quadloc openapi --output`` (stable formatting)."""
    return json.dumps(openapi_document(), indent=2, ensure_ascii=False) + "\n"


def cmd_openapi(args: argparse.Namespace) -> int:
    text = openapi_text()
    if args.check:
        current = Path(args.check).read_text() if Path(args.check).exists() else ""
        if current != text:
            return _die(f"{args.check} is out of date; run: quadloc openapi --output "
                        f"{args.check}", 1)
        print(f"{args.check} is up to date")
        return 0
    if args.output:
        Path(args.output).parent.mkdir(parents=True, exist_ok=True)
        Path(args.output).write_text(text)
        print(f"wrote {args.output}", file=sys.stderr)
    else:
        sys.stdout.write(text)
    return 0


def cmd_hash_key(args: argparse.Namespace) -> int:
    from service.settings import SCOPES, hash_api_key

    key = args.key or secrets.token_urlsafe(32)
    bad = [s for s in args.scopes.split("+") if s not in SCOPES]
    if bad:
        return _die(f"--scopes: unknown scope(s) {bad}; valid: {list(SCOPES)}")
    if not args.key:
        print(f"new key (give it to the client, it is not stored): {key}", file=sys.stderr)
    print(f"{hash_api_key(key)}:{args.scopes}")
    return 0


# ---------------------------------------------------------------------------------- parser


def build_parser() -> argparse.ArgumentParser:
    fmt = argparse.RawDescriptionHelpFormatter
    parser = argparse.ArgumentParser(
        prog="quadloc", formatter_class=fmt, epilog=EPILOG,
        description="QuadLoc: camera relocalization from object detections (ellipses) and a "
                    "map of 3D ellipsoids. Serve the REST API, manage maps, localize frames.")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    def db(p: argparse.ArgumentParser) -> None:
        p.add_argument("--database-url", metavar="URL",
                       help="sqlite:///path or postgresql://... (default: QUADLOC_DATABASE_URL "
                            "or SQLite under QUADLOC_DATA_DIR)")

    p = sub.add_parser("serve", formatter_class=fmt, help="run the REST API (Uvicorn)",
                       description="Run the REST API. Without QUADLOC_API_KEYS the API is open "
                                   "and only loopback hosts are allowed.",
                       epilog="examples:\n  quadloc serve\n  quadloc serve --port 9000\n"
                              "  QUADLOC_API_KEYS=<sha256>:read+write quadloc serve "
                              "--host 0.0.0.0\n")
    p.add_argument("--host", help="bind address (default 127.0.0.1 / QUADLOC_HOST)")
    p.add_argument("--port", type=int, help="port (default 8000 / QUADLOC_PORT)")
    p.add_argument("--workers", type=int, help="worker processes (default 1; one per core "
                                               "at most, the solver is CPU-bound)")
    p.add_argument("--access-log", action="store_true", help="log every request")
    db(p)
    p.set_defaults(func=cmd_serve)

    maps_p = sub.add_parser("maps", formatter_class=fmt, help="list, import, export, delete maps",
                            description="Manage maps directly in the database (no server).",
                            epilog="examples:\n  quadloc maps list\n"
                                   "  quadloc maps import office.json\n"
                                   "  quadloc maps import chess_scene.json --chess "
                                   "--map-id chess2\n  quadloc maps export chess > chess.json\n")
    msub = maps_p.add_subparsers(dest="maps_command", metavar="ACTION", required=True)
    p = msub.add_parser("list", help="list maps with their latest version")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    db(p)
    p.set_defaults(func=cmd_maps_list)
    p = msub.add_parser("import", help="create a map from a JSON file ('-' = stdin)")
    p.add_argument("file", help="map JSON (docs/maps.md format, or the Chess format with --chess)")
    p.add_argument("--chess", action="store_true", help="the file is in the Chess scene format")
    p.add_argument("--map-id", help="id of the map (overrides the file's; Chess default 'chess')")
    p.add_argument("--name", help="display name (overrides the file's)")
    p.add_argument("--update", action="store_true",
                   help="if the id exists, store the file as its next version")
    db(p)
    p.set_defaults(func=cmd_maps_import)
    p = msub.add_parser("export", help="print a map as JSON (docs/maps.md format)")
    p.add_argument("map_id", metavar="ID")
    p.add_argument("--version", type=int, help="version to export (default: latest)")
    p.add_argument("-o", "--output", help="write to this file instead of stdout")
    db(p)
    p.set_defaults(func=cmd_maps_export)
    p = msub.add_parser("delete", help="delete a map and all its versions")
    p.add_argument("map_id", metavar="ID")
    db(p)
    p.set_defaults(func=cmd_maps_delete)

    p = sub.add_parser("localize", formatter_class=fmt, help="localize one frame (prints the pose)",
                       description="Localize the frame in FILE (the body of POST "
                                   "/v1/maps/{id}/localize) against a stored map, in process. "
                                   "Exit status 0 when localized, 1 when not.",
                       epilog="example:\n  quadloc localize --map chess "
                              "docs/examples/localize_chess.json\n")
    p.add_argument("file", help="request JSON ('-' = stdin)")
    p.add_argument("--map", required=True, metavar="ID", help="map id")
    p.add_argument("--version", type=int, help="map version (default: latest)")
    p.add_argument("--convention", choices=["opencv", "opengl"],
                   help="camera axes of the printed pose (overrides the file's options)")
    p.add_argument("--json", action="store_true", help="print the full JSON response")
    db(p)
    p.set_defaults(func=cmd_localize)

    p = sub.add_parser("openapi", help="print or write the OpenAPI document")
    p.add_argument("-o", "--output", help="write to this file (e.g. docs/openapi.json)")
    p.add_argument("--check", metavar="FILE",
                   help="exit 1 if FILE differs from the current schema")
    p.set_defaults(func=cmd_openapi)

    p = sub.add_parser("hash-key", help="hash an API key for QUADLOC_API_KEYS",
                       description="Print '<sha256>:<scopes>' for QUADLOC_API_KEYS. Without KEY, "
                                   "a random key is generated and shown on stderr.")
    p.add_argument("key", nargs="?", help="the key (default: generate one)")
    p.add_argument("--scopes", default="read", help="read, write or read+write (default read)")
    p.set_defaults(func=cmd_hash_key)

    from service.tracking.cli_track import add_track_parser

    add_track_parser(sub, db)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run the CLI; returns the exit status."""
    from pydantic import ValidationError

    from maps.errors import MapStoreError, StoreUnavailable

    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except StoreUnavailable as exc:  # database down: a message, not a traceback
        return _die(f"{exc} (check QUADLOC_DATABASE_URL / --database-url)")
    except MapStoreError as exc:
        return _die(str(exc))
    except ValidationError as exc:  # QUADLOC_* settings out of range or malformed
        if exc.title != "Settings":
            raise
        lines = [f"  {'.'.join(str(p) for p in e['loc'])}: {e['msg']}" for e in exc.errors()]
        return _die("invalid settings (QUADLOC_* environment):\n" + "\n".join(lines))
    except KeyboardInterrupt:  # pragma: no cover
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
