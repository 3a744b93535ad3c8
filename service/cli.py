"""The ``quadloc`` command line (entry point ``quadloc = quadloc.service.cli:main``).

Map commands and ``localize`` talk to a running server through the SDK when a server URL is
given (``--url`` or ``QUADLOC_URL``, with ``--api-key`` / ``QUADLOC_API_KEY``); without one they
work directly on the local database (no server needed). ``serve`` runs the REST API.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import secrets
import sys
from pathlib import Path
from typing import Any

__all__ = ["build_parser", "main", "openapi_document", "openapi_text"]

REPO_ROOT = Path(__file__).resolve().parents[1]
OPENAPI_PATH = REPO_ROOT / "docs" / "openapi.json"

EPILOG = """\
examples (local database):
  quadloc serve                                  # http://127.0.0.1:8000, SQLite, demo map "chess"
  quadloc serve --port 9000 --database-url sqlite:////tmp/q.db
  QUADLOC_API_KEYS="$(quadloc hash-key s3cret --scopes read+write)" quadloc serve --host 0.0.0.0
  quadloc maps list
  quadloc maps import office.json                # our map format (docs/maps.md)
  quadloc maps import chess_scene.json --chess --map-id chess2
  quadloc maps export chess --version 1 > chess_v1.json
  quadloc localize --map chess docs/examples/localize_chess.json
  quadloc openapi --output docs/openapi.json     # regenerate the published schema
  quadloc maps build recording.json --map-id room   # build a map from posed detections

examples (a running server, through the SDK):
  quadloc --url http://127.0.0.1:8000 maps list
  export QUADLOC_URL=https://quadloc.example.com QUADLOC_API_KEY=s3cret
  quadloc maps import office.json --update       # create, or add a new version
  quadloc maps versions office-3
  quadloc localize --map chess frames/*.json     # one line per frame, progress on stderr

settings come from QUADLOC_* environment variables (see service/settings.py), e.g.
QUADLOC_DATABASE_URL, QUADLOC_API_KEYS, QUADLOC_DATA_DIR; QUADLOC_URL and QUADLOC_API_KEY
select a server for the map commands and localize; flags override them.
"""


def _version_text() -> str:
    from importlib.metadata import PackageNotFoundError, version

    from quadloc.service.api.app import API_VERSION

    def installed(name: str) -> str:
        try:
            return version(name)
        except PackageNotFoundError:  # pragma: no cover - running from a bare checkout
            return "not installed"

    return (f"quadloc {installed('quadloc')} (REST API {API_VERSION}, "
            f"quadloc-sdk {installed('quadloc-sdk')})")


class _VersionAction(argparse.Action):
    """``--version``: computed only when asked (it imports the app for the API version)."""

    def __init__(self, option_strings: list[str], dest: str, **kwargs: Any) -> None:
        super().__init__(option_strings, dest, nargs=0, default=argparse.SUPPRESS,
                         help="print the versions of quadloc, its REST API and the SDK; exit")

    def __call__(self, parser: argparse.ArgumentParser, *args: Any, **kwargs: Any) -> None:
        print(_version_text())
        parser.exit()


# ---------------------------------------------------------------------------------- output


def format_table(headers: list[str], rows: list[list[str]], right: set[int] = frozenset()) -> str:
    """Plain-text table: columns as wide as their widest cell, two spaces apart; ``right``
    holds the indices of right-aligned (numeric) columns."""
    cells = [headers, *rows]
    widths = [max(len(str(r[i])) for r in cells) for i in range(len(headers))]
    lines = []
    for r in cells:
        parts = [str(v).rjust(w) if i in right else str(v).ljust(w)
                 for i, (v, w) in enumerate(zip(r, widths, strict=True))]
        lines.append("  ".join(parts).rstrip())
    return "\n".join(lines)


class Progress:
    """A one-line progress bar on stderr (only when stderr is a terminal, so logs and pipes
    stay clean): ``[#####.....]  5/10  frame_005.json``."""

    def __init__(self, total: int, stream: Any = None) -> None:
        self.total = total
        self.stream = stream or sys.stderr
        self.enabled = total > 1 and bool(getattr(self.stream, "isatty", lambda: False)())

    def update(self, done: int, label: str = "") -> None:
        if not self.enabled:
            return
        width = 30
        filled = int(width * done / max(self.total, 1))
        count = f"{done:>{len(str(self.total))}}/{self.total}"
        self.stream.write(f"\r[{'#' * filled}{'.' * (width - filled)}] {count}  {label[:40]:<40}")
        self.stream.flush()

    def close(self) -> None:
        if self.enabled:
            self.stream.write("\n")
            self.stream.flush()


def _settings(args: argparse.Namespace) -> Any:
    from quadloc.service.settings import Settings

    url = getattr(args, "database_url", None)
    return Settings(**({"database_url": url} if url else {}))


def _store(args: argparse.Namespace) -> Any:
    """The map store of the settings' database, with the demo map seeded like ``serve`` does."""
    from quadloc.maps.store import MapStore
    from quadloc.service.api.app import seed_demo_map

    settings = _settings(args)
    store = MapStore(settings.effective_database_url)
    if settings.seed_demo_map and settings.default_map_id:
        seed_demo_map(store, settings.default_map_id)
    return store


def _die(message: str, code: int = 2) -> int:
    print(f"quadloc: error: {message}", file=sys.stderr)
    return code


def _invalid(problems: Any, message: str) -> int:
    """Print each ``(field, problem)`` on stderr, then :func:`_die` with ``message``."""
    for field, problem in problems:
        print(f"  {field}: {problem}", file=sys.stderr)
    return _die(message)


def _read_json(path: str) -> Any:
    """The JSON document of ``path`` (``-``: stdin); unreadable or malformed: :class:`_CliError`
    ``"<path>: <problem>"``."""
    try:
        text = sys.stdin.read() if path == "-" else Path(path).read_text(encoding="utf-8")
        return json.loads(text)
    except (OSError, json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise _CliError(f"{path}: {exc}") from exc


def _json_type(value: Any) -> str:
    """JSON name of a parsed value's type (for messages)."""
    if isinstance(value, bool):
        return "boolean"
    if isinstance(value, int | float):
        return "number"
    return {list: "array", str: "string", dict: "object", type(None): "null"}.get(
        type(value), type(value).__name__)


def _server(args: argparse.Namespace) -> str | None:
    """The server URL of ``--url`` or ``QUADLOC_URL`` (None: work on the local database)."""
    url = getattr(args, "url", None) or os.environ.get("QUADLOC_URL") or None
    return url.strip() if url and url.strip() else None


def _client(args: argparse.Namespace) -> Any:
    """An SDK client for ``--url`` / ``QUADLOC_URL`` with ``--api-key`` / ``QUADLOC_API_KEY``."""
    from quadloc_sdk import QuadLocClient

    key = getattr(args, "api_key", None) or os.environ.get("QUADLOC_API_KEY") or None
    try:
        return QuadLocClient(_server(args) or "", api_key=key)
    except ValueError as exc:  # e.g. a URL without http:// or https://
        raise _CliError(f"--url / QUADLOC_URL / --api-key: {exc}") from exc


def _table_time(value: Any) -> str:
    """ISO timestamps (datetime or str) trimmed to seconds for tables."""
    text = value.isoformat() if hasattr(value, "isoformat") else str(value or "-")
    return text.split(".")[0].replace("+00:00", "") + ("Z" if "+00:00" in text else "")


def _show(args: argparse.Namespace, items: list[dict[str, Any]], headers: list[str],
          row: Any, right: set[int]) -> int:
    """``items`` as JSON (``--json``) or as a table of ``row(item)`` rows."""
    if args.json:
        print(json.dumps(items, indent=2))
    else:
        print(format_table(headers, [row(m) for m in items], right=right))
    return 0


# ---------------------------------------------------------------------------------- commands


def cmd_serve(args: argparse.Namespace) -> int:
    from quadloc.service.api.server import serve, uvicorn_config
    from quadloc.service.settings import check_bind_allowed

    if args.database_url:
        os.environ["QUADLOC_DATABASE_URL"] = args.database_url
    settings = _settings(args)
    host = args.host or settings.host
    port = settings.port if args.port is None else args.port
    try:
        check_bind_allowed(settings, host)
    except ValueError as exc:
        return _die(str(exc))
    if not settings.auth_enabled:
        print(f"quadloc: no API key configured: the API is open, listening on loopback only "
              f"({host}:{port})", file=sys.stderr)
    serve(uvicorn_config(settings, host, port, workers=args.workers or settings.workers,
                         access_log=args.access_log))
    return 0


def cmd_maps_list(args: argparse.Namespace) -> int:
    if _server(args):
        with _client(args) as client:
            items = [m.model_dump(mode="json") for m in client.list_maps()]
    else:
        items = [{"map_id": r.map_id, "name": r.name, "version": r.latest_version,
                  "content_hash": r.content_hash, "updated_at": r.updated_at.isoformat()}
                 for r in _store(args).list()]
    return _show(args, items, ["MAP_ID", "VERSION", "UPDATED", "NAME"],
                 lambda m: [m["map_id"], str(m["version"]), _table_time(m.get("updated_at")),
                            m["name"]], {1})


def cmd_maps_versions(args: argparse.Namespace) -> int:
    if _server(args):
        with _client(args) as client:
            items = [v.model_dump(mode="json") for v in client.list_versions(args.map_id)]
    else:
        items = [{"version": h.version, "content_hash": h.content_hash,
                  "created_at": h.created_at.isoformat()}
                 for h in _store(args).version_history(args.map_id)]
    return _show(args, items, ["VERSION", "CREATED", "ETAG"],
                 lambda v: [str(v["version"]), _table_time(v.get("created_at")),
                            f'"{v["content_hash"]}"'], {0})


def _exists(map_id: str) -> int:
    return _die(f"map {map_id!r} exists; pass --update to add a new version")


def _print_stored(map_id: str, version: int, n_objects: int, content_hash: str) -> int:
    print(f"{map_id} version {version} ({n_objects} objects) etag \"{content_hash}\"")
    return 0


def cmd_maps_import(args: argparse.Namespace) -> int:
    from quadloc.maps.errors import MapAlreadyExists, MapNotFound, VersionConflict
    from quadloc.maps.model import MapValidationError, scene_map_from_chess, scene_map_from_dict

    data = _read_json(args.file)
    if not isinstance(data, dict):
        return _die(f"{args.file}: a map must be a JSON object, got a JSON "
                    f"{_json_type(data)}")
    try:
        if args.chess:
            scene_map = scene_map_from_chess(data, map_id=args.map_id or "chess",
                                             name=args.name or "Chess")
        else:
            overrides = {"map_id": args.map_id, "name": args.name}
            data = {**data, **{k: v for k, v in overrides.items() if v}}
            scene_map = scene_map_from_dict(data, version=1)
    except MapValidationError as exc:
        return _invalid([(e["field"], e["message"]) for e in exc.errors],
                        f"{args.file}: invalid map ({len(exc.errors)} problem(s))")
    if _server(args):
        return _remote_import(args, scene_map.to_dict())
    store = _store(args)
    try:
        stored = store.create(scene_map)
    except MapAlreadyExists:
        if not args.update:
            return _exists(scene_map.map_id)
        try:
            current = store.get(scene_map.map_id)
            new = type(scene_map).from_dict({**scene_map.to_dict(),
                                             "version": current.scene_map.version + 1})
            stored = store.update(scene_map.map_id, new, current.scene_map.version)
        except (VersionConflict, MapNotFound) as exc:
            return _die(str(exc))
    sm = stored.scene_map
    return _print_stored(sm.map_id, sm.version, len(sm.objects), stored.content_hash)


def _remote_import(args: argparse.Namespace, document: dict[str, Any]) -> int:
    """``maps import`` against a server: create the (locally validated) map, or with
    ``--update`` add a version guarded by the ETag just read, so a concurrent writer gets a
    refusal (412/409), never a silent overwrite."""
    from quadloc_sdk import Conflict

    map_id = str(document["map_id"])
    with _client(args) as client:
        try:
            record = client.create_map(document)
        except Conflict as exc:
            if not exc.type.endswith("map-exists"):
                raise
            if not args.update:
                return _exists(map_id)
            current = client.get_map(map_id)
            record = client.update_map(map_id, document,
                                       if_match=current.etag or current.content_hash)
    return _print_stored(record.map_id, record.version, len(record.map.get("objects", [])),
                         record.content_hash)


def cmd_maps_export(args: argparse.Namespace) -> int:
    if _server(args):
        with _client(args) as client:
            document = client.get_map(args.map_id, args.version).map
    else:
        document = _store(args).get(args.map_id, args.version).scene_map.to_dict()
    text = json.dumps(document, indent=2) + "\n"
    if args.output:
        Path(args.output).write_text(text)
    else:
        sys.stdout.write(text)
    return 0


def cmd_maps_delete(args: argparse.Namespace) -> int:
    if _server(args):
        with _client(args) as client:
            client.delete_map(args.map_id)
    else:
        _store(args).delete(args.map_id)
    print(f"deleted {args.map_id} (all versions)")
    return 0


def _print_answer(result: Any) -> None:
    """Human-readable answer (server schema or SDK model: same fields)."""
    print(f"map {result.map_id} v{result.map_version}  frame {result.frame_id or '-'}")
    if not result.localized:
        print(f"NOT LOCALIZED: {result.reason}")
    else:
        pose = result.world_from_camera
        print(f"world_from_camera ({pose.convention} camera axes):")
        print("  quaternion_wxyz = [" + ", ".join(f"{v:+.6f}" for v in pose.quaternion_wxyz)
              + "]")
        print("  translation_m   = [" + ", ".join(f"{v:+.4f}" for v in pose.translation_m) + "]")
        print(f"confidence {result.confidence:.3f}  inliers {len(result.inliers)}  "
              f"metric {result.metric}  total "
              f"{result.timings_ms.get('total', float('nan')):.1f} ms")
        if result.covariance is not None:
            diag = [max(float(result.covariance.matrix[i][i]), 0.0) for i in range(6)]
            rot = [round(math.degrees(math.sqrt(d)), 3) for d in diag[:3]]
            trans = [round(math.sqrt(d), 4) for d in diag[3:]]
            print(f"std: rotation [deg] {rot}  translation [m] {trans}")
    # the candidate poses of an ambiguous or low-confidence answer, with their probabilities
    for k, a in enumerate(result.alternatives):
        t = " ".join(f"{v:+.3f}" for v in a.world_from_camera.translation_m)
        print(f"candidate {k}: confidence {a.confidence:.3f}  inliers {a.n_inliers}  "
              f"score {a.score:.2f}  translation_m [{t}]")


def cmd_localize(args: argparse.Namespace) -> int:
    from pydantic import ValidationError

    from quadloc.service.api.errors import field_path
    from quadloc.service.schemas.localize import LocalizeRequest

    overrides = {k: v for k, v in (
        ("metric", args.metric), ("on_ambiguity", getattr(args, "on_ambiguity", None)),
        ("min_confidence", getattr(args, "min_confidence", None))) if v is not None}
    requests = []
    for path in args.file:
        body = _read_json(path)
        if overrides and isinstance(body, dict):
            options = body.setdefault("options", {})
            if isinstance(options, dict):
                options.update(overrides)  # validated with the request below
        try:
            request = LocalizeRequest.model_validate(body)
        except ValidationError as exc:
            return _invalid([(field_path(e["loc"]), e["msg"]) for e in exc.errors()],
                            f"{path}: invalid request")
        if args.convention:
            request = request.model_copy(update={"options": request.options.model_copy(
                update={"output_convention": args.convention})})
        requests.append(request)
    solve, close = _solver(args)
    progress = Progress(len(requests))
    results = []
    try:
        for i, (path, request) in enumerate(zip(args.file, requests, strict=True)):
            progress.update(i, path)
            results.append(solve(request))
        progress.update(len(requests))
    finally:
        progress.close()
        close()
    if args.json:
        if len(results) == 1:
            print(results[0].model_dump_json(indent=2))
        else:
            print(json.dumps([r.model_dump(mode="json") for r in results], indent=2))
    elif len(results) == 1:
        _print_answer(results[0])
    else:
        rows = []
        for path, r in zip(args.file, results, strict=True):
            t = r.world_from_camera.translation_m if r.localized else None
            rows.append([path, "yes" if r.localized else f"no ({r.reason})",
                         f"{r.confidence:.2f}", str(len(r.inliers)),
                         "-" if t is None else " ".join(f"{v:+.3f}" for v in t)])
        print(format_table(["FILE", "LOCALIZED", "CONF", "INLIERS", "TRANSLATION_M"], rows,
                           right={2, 3}))
    return 0 if all(r.localized for r in results) else 1


def _solver(args: argparse.Namespace) -> tuple[Any, Any]:
    """``(solve, close)``: localize a request through the SDK on the server
    (``POST /v1/maps/{map}/localize``), or in process against the local database (the server's
    solver and settings)."""
    if _server(args):
        client = _client(args)
        return (lambda request: client.localize(
            args.map, request.model_dump(mode="json", exclude_none=True),
            map_version=args.version)), client.close
    from quadloc.service.api.errors import ProblemError
    from quadloc.service.api.metrics import ApiMetrics
    from quadloc.service.api.solver import Solver

    settings = _settings(args)
    compiled = _store(args).compiled(args.map, args.version)
    solver = Solver(ApiMetrics(), 1, 0.0, settings.solve_time_budget_ms, settings.max_detections)

    def solve(request: Any) -> Any:
        try:
            return solver.localize_frames(compiled, [request], batch=False)[0]
        except ProblemError as exc:
            raise _CliError(exc.detail) from exc

    return solve, lambda: None


class _CliError(Exception):
    """A message for the user (exit status 2)."""


def openapi_document() -> dict[str, Any]:
    """The API's OpenAPI document (built on an in-memory store, nothing seeded)."""
    from quadloc.maps.store import MapStore
    from quadloc.service.api.app import build_openapi, create_app
    from quadloc.service.settings import Settings

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
    from quadloc.service.settings import SCOPES, hash_api_key

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
    parser.add_argument("--version", action=_VersionAction)

    def remote(p: argparse.ArgumentParser, suppress: bool = True) -> None:
        default = argparse.SUPPRESS if suppress else None
        p.add_argument("--url", metavar="URL", default=default,
                       help="QuadLoc server to talk to, e.g. http://127.0.0.1:8000 (default: "
                            "QUADLOC_URL; unset = work on the local database)")
        p.add_argument("--api-key", metavar="KEY", default=default,
                       help="API key sent as 'Authorization: Bearer KEY' (default: "
                            "QUADLOC_API_KEY)")

    remote(parser, suppress=False)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    def db(p: argparse.ArgumentParser, server: bool = True) -> None:
        p.add_argument("--database-url", metavar="URL",
                       help="sqlite:///path or postgresql://... (default: QUADLOC_DATABASE_URL "
                            "or SQLite under QUADLOC_DATA_DIR)")
        if server:
            remote(p)

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
    db(p, server=False)
    p.set_defaults(func=cmd_serve)

    maps_p = sub.add_parser("maps", formatter_class=fmt, help="list, import, export, delete maps",
                            description="Manage maps on a server (--url / QUADLOC_URL, through "
                                        "the SDK) or directly in the local database.",
                            epilog="examples:\n  quadloc maps list\n"
                                   "  quadloc maps import office.json\n"
                                   "  quadloc maps import chess_scene.json --chess "
                                   "--map-id chess2\n  quadloc maps export chess > chess.json\n"
                                   "  quadloc --url http://127.0.0.1:8000 maps versions chess\n")
    msub = maps_p.add_subparsers(dest="maps_command", metavar="ACTION", required=True)
    p = msub.add_parser("list", help="list maps with their latest version")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    db(p)
    p.set_defaults(func=cmd_maps_list)
    p = msub.add_parser("versions", help="list a map's stored versions")
    p.add_argument("map_id", metavar="ID")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    db(p)
    p.set_defaults(func=cmd_maps_versions)
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
    from quadloc.service.cli_build import add_build_parser  # issue 16: quadloc maps build

    add_build_parser(msub, db)

    p = sub.add_parser("localize", formatter_class=fmt, help="localize frames (prints the pose)",
                       description="Localize the frame in each FILE (the body of POST "
                                   "/v1/maps/{id}/localize) against a map: on the server of "
                                   "--url / QUADLOC_URL, or in process on the local database. "
                                   "Several files: one table row per frame and a progress bar "
                                   "on stderr. Exit status 0 when every frame localized, 1 "
                                   "when one did not.",
                       epilog="examples:\n  quadloc localize --map chess "
                              "docs/examples/localize_chess.json\n"
                              "  quadloc --url http://127.0.0.1:8000 localize --map chess "
                              "frames/*.json\n")
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

    from quadloc.service.tracking.cli_track import add_track_parser

    add_track_parser(sub, db)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run the CLI; returns the exit status."""
    from pydantic import ValidationError

    from quadloc.maps.errors import MapNotFound, MapStoreError, StoreUnavailable
    from quadloc_sdk import NotFound, QuadLocError, TransportError

    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except StoreUnavailable as exc:  # database down: a message, not a traceback
        return _die(f"{exc} (check QUADLOC_DATABASE_URL / --database-url)")
    except _CliError as exc:
        return _die(str(exc))
    except TransportError as exc:
        return _die(f"cannot reach the server: {exc} (check --url / QUADLOC_URL)")
    except (NotFound, MapNotFound) as exc:
        return _die(str(exc), 1)
    except QuadLocError as exc:  # the server's problem document: status, title, fields
        return _die(str(exc))
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
