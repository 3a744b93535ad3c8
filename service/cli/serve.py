"""``quadloc serve`` (the REST API under Uvicorn), ``quadloc openapi`` (its OpenAPI document)
and ``quadloc hash-key`` (an API key's digest for ``QUADLOC_API_KEYS``): the commands about the
HTTP front end itself."""

from __future__ import annotations

import argparse
import os
import secrets
import sys
from pathlib import Path

from quadloc.service.api.app import openapi_text
from quadloc.service.api.server import serve, uvicorn_config
from quadloc.service.cli.common import CliError, settings
from quadloc.service.settings import SCOPES, check_bind_allowed, hash_api_key

__all__ = ["cmd_hash_key", "cmd_openapi", "cmd_serve"]


def cmd_serve(args: argparse.Namespace) -> int:
    if args.database_url:
        os.environ["QUADLOC_DATABASE_URL"] = args.database_url  # the workers read it too
    config = settings(args)
    host = args.host or config.host
    port = config.port if args.port is None else args.port
    try:
        check_bind_allowed(config, host)
    except ValueError as exc:
        raise CliError(str(exc)) from exc
    if not config.auth_enabled:
        print(f"quadloc: no API key configured: the API is open, listening on loopback only "
              f"({host}:{port})", file=sys.stderr)
    serve(uvicorn_config(config, host, port, workers=args.workers or config.workers,
                         access_log=args.access_log))
    return 0


def cmd_openapi(args: argparse.Namespace) -> int:
    text = openapi_text()
    if args.check:
        current = Path(args.check).read_text() if Path(args.check).exists() else ""
        if current != text:
            raise CliError(f"{args.check} is out of date; run: quadloc openapi --output "
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
    key = args.key or secrets.token_urlsafe(32)
    bad = [s for s in args.scopes.split("+") if s not in SCOPES]
    if bad:
        raise CliError(f"--scopes: unknown scope(s) {bad}; valid: {list(SCOPES)}")
    if not args.key:
        print(f"new key (give it to the client, it is not stored): {key}", file=sys.stderr)
    print(f"{hash_api_key(key)}:{args.scopes}")
    return 0
