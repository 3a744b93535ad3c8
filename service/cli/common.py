"""What every ``quadloc`` command shares: reading input files, reporting errors, tables and
progress on a terminal, and the two places a command works on: a server (``--url`` /
``QUADLOC_URL``, through the SDK) or this process (the application over the local database,
:func:`local_app`).

Exit statuses of every command: 0 done, 1 a normal negative outcome (not localized, not found,
no map built), 2 bad input or a store / server error (:class:`CliError`).

A command on a server loads neither the application nor the solver: what works in this
process (the application, its settings, its errors) is imported where a command uses it.
"""

from __future__ import annotations

import argparse
import gzip
import json
import os
import sys
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, TextIO

from pydantic import ValidationError

from quadloc_sdk import NotFound, QuadLocClient, QuadLocError, TransportError

if TYPE_CHECKING:
    from quadloc.service.app.context import App
    from quadloc.service.app.errors import AppError
    from quadloc.service.settings import Settings

__all__ = [
    "CliError",
    "Progress",
    "ProgressBar",
    "client",
    "die",
    "format_table",
    "json_type",
    "local_app",
    "read_json",
    "report_app_error",
    "run",
    "server_url",
    "settings",
    "show",
    "table_time",
]


class CliError(Exception):
    """A message for the user; the command exits with ``status`` (2 by default)."""

    def __init__(self, message: str, status: int = 2,
                 problems: Sequence[tuple[str, str]] = ()) -> None:
        super().__init__(message)
        self.status = status
        self.problems = list(problems)


def die(message: str, code: int = 2, problems: Iterable[tuple[str, str]] = ()) -> int:
    """Print ``quadloc: error: <message>`` (after each ``field: problem``) on stderr; returns
    ``code`` (the exit status)."""
    for field, problem in problems:
        print(f"  {field}: {problem}", file=sys.stderr)
    print(f"quadloc: error: {message}", file=sys.stderr)
    return code


def report_app_error(exc: AppError) -> int:
    """A use case's refusal as a CLI error: 1 for a missing map / session / job, else 2."""
    code = 1 if exc.code.endswith("not-found") else 2
    return die(exc.detail, code, [(e["field"], e["message"]) for e in exc.errors
                                  if e["message"] not in exc.detail])


def read_json(path: str) -> Any:
    """The JSON document of ``path`` (``-``: stdin; ``.gz``: gzip-compressed); unreadable or
    malformed: :class:`CliError` ``"<path>: <problem>"``."""
    try:
        if path == "-":
            text = sys.stdin.read()
        elif path.endswith(".gz"):
            text = gzip.decompress(Path(path).read_bytes()).decode("utf-8")
        else:
            text = Path(path).read_text(encoding="utf-8")
        return json.loads(text)
    except (OSError, EOFError, json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise CliError(f"{path}: {exc}") from exc


def json_type(value: Any) -> str:
    """JSON name of a parsed value's type (for messages)."""
    if isinstance(value, bool):
        return "boolean"
    if isinstance(value, int | float):
        return "number"
    return {list: "array", str: "string", dict: "object", type(None): "null"}.get(
        type(value), type(value).__name__)


# ------------------------------------------------------------------------------- output


def format_table(headers: list[str], rows: list[list[str]],
                 right: frozenset[int] = frozenset()) -> str:
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


def table_time(value: Any) -> str:
    """ISO timestamps (datetime or str) trimmed to seconds for tables."""
    text = value.isoformat() if hasattr(value, "isoformat") else str(value or "-")
    return text.split(".")[0].replace("+00:00", "") + ("Z" if "+00:00" in text else "")


def show(args: argparse.Namespace, items: list[dict[str, Any]], headers: list[str],
         row: Callable[[dict[str, Any]], list[str]], right: frozenset[int]) -> int:
    """``items`` as JSON (``--json``) or as a table of ``row(item)`` rows."""
    if args.json:
        print(json.dumps(items, indent=2))
    else:
        print(format_table(headers, [row(m) for m in items], right=right))
    return 0


class Progress:
    """A one-line progress bar on stderr (only when stderr is a terminal, so logs and pipes
    stay clean): ``[#####.....]  5/10  frame_005.json``."""

    def __init__(self, total: int, stream: TextIO | None = None) -> None:
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


class ProgressBar(Progress):
    """``[#####.....]  45% refining (7 objects)`` redrawn in place on a terminal, one line per
    stage change otherwise (logs stay readable): a build's ``progress(stage, percent,
    objects)`` callback."""

    def __init__(self, stream: TextIO | None = None, width: int = 30) -> None:
        super().__init__(100, stream)
        self.width = width
        self.tty = self.enabled = bool(getattr(self.stream, "isatty", lambda: False)())
        self._stage = ""

    def __call__(self, stage: str, percent: float, objects: int) -> None:
        filled = round(self.width * max(0.0, min(100.0, percent)) / 100.0)
        line = (f"[{'#' * filled}{'.' * (self.width - filled)}] {percent:5.1f}% {stage} "
                f"({objects} objects)")
        if self.tty:
            self.stream.write("\r" + line)
            self.stream.flush()
        elif stage != self._stage:
            self.stream.write(line + "\n")
        self._stage = stage


# --------------------------------------------------------------------- where commands work




def settings(args: argparse.Namespace) -> Settings:
    """The ``QUADLOC_*`` settings, ``--database-url`` overriding the database."""
    from quadloc.service.settings import Settings

    url = getattr(args, "database_url", None)
    return Settings(**({"database_url": url} if url else {}))


def local_app(args: argparse.Namespace) -> App:
    """The application over the local database (the demo map seeded as ``serve`` does)."""
    from quadloc.service.app.context import App

    return App.create(settings(args))


def server_url(args: argparse.Namespace) -> str | None:
    """The server URL of ``--url`` or ``QUADLOC_URL`` (None: work in this process)."""
    url = getattr(args, "url", None) or os.environ.get("QUADLOC_URL") or None
    return url.strip() if url and url.strip() else None


def client(args: argparse.Namespace) -> QuadLocClient:
    """An SDK client for ``--url`` / ``QUADLOC_URL`` with ``--api-key`` / ``QUADLOC_API_KEY``."""
    key = getattr(args, "api_key", None) or os.environ.get("QUADLOC_API_KEY") or None
    try:
        return QuadLocClient(server_url(args) or "", api_key=key)
    except ValueError as exc:  # e.g. a URL without http:// or https://
        raise CliError(f"--url / QUADLOC_URL / --api-key: {exc}") from exc


def run(command: Callable[[argparse.Namespace], int], args: argparse.Namespace) -> int:
    """Run a command, every failure a message on stderr and an exit status (never a
    traceback for what the user can fix)."""
    try:
        return int(command(args) or 0)
    except CliError as exc:
        return die(str(exc), exc.status, exc.problems)
    except TransportError as exc:
        return die(f"cannot reach the server: {exc} (check --url / QUADLOC_URL)")
    except NotFound as exc:
        return die(str(exc), 1)
    except QuadLocError as exc:  # the server's problem document: status, title, fields
        return die(str(exc))
    except ValidationError as exc:  # QUADLOC_* settings out of range or malformed
        if exc.title != "Settings":
            raise
        lines = [f"  {'.'.join(str(p) for p in e['loc'])}: {e['msg']}" for e in exc.errors()]
        return die("invalid settings (QUADLOC_* environment):\n" + "\n".join(lines))
    except KeyboardInterrupt:  # pragma: no cover
        return 130
    except Exception as exc:
        status = _local_error_status(exc)
        if status is None:
            raise
        return status


def _local_error_status(exc: Exception) -> int | None:
    """The exit status of an error of this process' application or map store, its message
    printed (None: not one of theirs). Their modules are imported here, where one of them was
    raised (so they are loaded already), not by every command."""
    from quadloc.maps.errors import MapStoreError, StoreUnavailable
    from quadloc.maps.model import MapValidationError
    from quadloc.service.app.errors import AppError

    if isinstance(exc, AppError):
        return report_app_error(exc)
    if isinstance(exc, MapValidationError):
        return die(f"invalid map ({len(exc.errors)} problem(s))", 2,
                   [(e["field"], e["message"]) for e in exc.errors])
    if isinstance(exc, StoreUnavailable):  # database down: a message, not a traceback
        return die(f"{exc} (check QUADLOC_DATABASE_URL / --database-url)")
    if isinstance(exc, MapStoreError):
        return die(str(exc))
    return None
