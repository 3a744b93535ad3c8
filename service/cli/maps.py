"""``quadloc maps list | versions | import | export | delete``: on a server (``--url``, through
the SDK) or on the local database (the application's map use cases, imported where a command
uses them: a command on a server loads neither them nor the solver)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from quadloc.service.cli.common import (
    CliError,
    client,
    json_type,
    local_app,
    read_json,
    server_url,
    show,
    table_time,
)
from quadloc.service.schemas.maps import MapOut, etag_of
from quadloc_sdk import Conflict

__all__ = ["cmd_delete", "cmd_export", "cmd_import", "cmd_list", "cmd_versions"]


def cmd_list(args: argparse.Namespace) -> int:
    if server_url(args):
        with client(args) as c:
            items = [m.model_dump(mode="json") for m in c.list_maps()]
    else:
        items = [m.model_dump(mode="json") for m in local_app(args).maps.list().maps]
    return show(args, items, ["MAP_ID", "VERSION", "UPDATED", "NAME"],
                lambda m: [m["map_id"], str(m["version"]), table_time(m.get("updated_at")),
                           m["name"]], frozenset({1}))


def cmd_versions(args: argparse.Namespace) -> int:
    if server_url(args):
        with client(args) as c:
            items = [v.model_dump(mode="json") for v in c.list_versions(args.map_id)]
    else:
        items = [v.model_dump(mode="json")
                 for v in local_app(args).maps.versions(args.map_id).versions]
    return show(args, items, ["VERSION", "CREATED", "ETAG"],
                lambda v: [str(v["version"]), table_time(v.get("created_at")),
                           etag_of(v["content_hash"])], frozenset({0}))


def _exists(map_id: str) -> CliError:
    return CliError(f"map {map_id!r} exists; pass --update to add a new version")


def _print_stored(map_id: str, version: int, n_objects: int, content_hash: str) -> int:
    print(f"{map_id} version {version} ({n_objects} objects) etag {etag_of(content_hash)}")
    return 0


def cmd_import(args: argparse.Namespace) -> int:
    from quadloc.maps.model import MapValidationError, scene_map_from_chess, scene_map_from_dict

    data = read_json(args.file)
    if not isinstance(data, dict):
        raise CliError(f"{args.file}: a map must be a JSON object, got a JSON "
                       f"{json_type(data)}")
    try:  # validated here first: the same messages locally and against a server
        if args.chess:
            scene_map = scene_map_from_chess(data, map_id=args.map_id or "chess",
                                             name=args.name or "Chess")
        else:
            overrides = {"map_id": args.map_id, "name": args.name}
            scene_map = scene_map_from_dict(
                {**data, **{k: v for k, v in overrides.items() if v}}, version=1)
    except MapValidationError as exc:
        raise CliError(f"{args.file}: invalid map ({len(exc.errors)} problem(s))",
                       problems=[(e["field"], e["message"]) for e in exc.errors]) from exc
    document = scene_map.to_dict()
    if server_url(args):
        return _remote_import(args, document)
    from quadloc.service.app.errors import AppError

    maps = local_app(args).maps
    try:
        stored = maps.create(document)
    except AppError as exc:
        if exc.code != "map-exists":
            raise
        if not args.update:
            raise _exists(scene_map.map_id) from exc
        latest = maps.get(scene_map.map_id)
        stored = maps.update(scene_map.map_id, document, etag_of(latest.content_hash))
    return _print_stored(stored.map_id, stored.version, len(stored.map["objects"]),
                         stored.content_hash)


def _remote_import(args: argparse.Namespace, document: dict[str, Any]) -> int:
    """``maps import`` against a server: create the (locally validated) map, or with
    ``--update`` add a version guarded by the ETag just read, so a concurrent writer gets a
    refusal (412/409), never a silent overwrite."""
    map_id = str(document["map_id"])
    with client(args) as c:
        try:
            record = c.create_map(document)
        except Conflict as exc:
            if not exc.type.endswith("map-exists"):
                raise
            if not args.update:
                raise _exists(map_id) from exc
            current = c.get_map(map_id)
            record = c.update_map(map_id, document,
                                  if_match=current.etag or current.content_hash)
    return _print_stored(record.map_id, record.version, len(record.map.get("objects", [])),
                         record.content_hash)


def cmd_export(args: argparse.Namespace) -> int:
    if server_url(args):
        with client(args) as c:
            document = c.get_map(args.map_id, args.version).map
    else:
        stored: MapOut = local_app(args).maps.get(args.map_id, args.version)
        document = stored.map
    text = json.dumps(document, indent=2) + "\n"
    if args.output:
        Path(args.output).write_text(text)
    else:
        sys.stdout.write(text)
    return 0


def cmd_delete(args: argparse.Namespace) -> int:
    if server_url(args):
        with client(args) as c:
            c.delete_map(args.map_id)
    else:
        local_app(args).maps.delete(args.map_id)
    print(f"deleted {args.map_id} (all versions)")
    return 0
