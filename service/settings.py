"""Service settings, read from the environment (``QUADLOC_<FIELD>``, case-insensitive) with
pydantic-settings.

API keys (``QUADLOC_API_KEYS``) are sha256 hex digests with scopes, never keys in clear:
compact ``"<sha256hex>:read,<sha256hex>:read+write"`` (entries separated by ``,`` or whitespace,
scopes joined by ``+``) or JSON ``[{"sha256": "<hex>", "scopes": ["read", "write"], "name":
"ci"}]``. Scopes: ``read`` (localize, get and list maps, tracking sessions), ``write``
(create, update, delete and build maps; implies ``read``), ``admin`` (sees and ends every key's
sessions and build jobs; implies ``write``); hash a key with ``quadloc hash-key``. With no key
the service is open and binds only loopback (:func:`check_bind_allowed`).
"""

from __future__ import annotations

import hashlib
import ipaddress
import json
import re
import sys
from dataclasses import dataclass
from pathlib import Path
from types import NoneType, UnionType
from typing import Any, Literal, get_args, get_origin

from pydantic import Field, field_validator
from pydantic_settings import BaseSettings, SettingsConfigDict

from quadloc.service.limits import MAX_BATCH_FRAMES, MAX_DETECTIONS

__all__ = [
    "BUILD_LIMIT_DEFAULTS",
    "SCOPES",
    "SHUTDOWN_CANCEL_MARGIN_S",
    "ApiKey",
    "BuildLimitSettings",
    "Settings",
    "check_bind_allowed",
    "hash_api_key",
    "is_loopback_host",
    "parse_api_keys",
    "settings_table_markdown",
]

#: The access scopes, each implying the ones before it: ``write`` implies ``read``; ``admin``
#: (every key's sessions and build jobs: quadloc.service.app.ownership) implies ``write``.
SCOPES = ("read", "write", "admin")
#: Seconds before ``QUADLOC_SHUTDOWN_GRACE_S`` at which work still running is stopped on SIGTERM:
#: ``quadloc serve`` stops waiting for the requests in progress and the app cancels their work
#: (``App.close``); ``quadloc worker`` asks its running builds to stop (and releases them). The
#: process ends within the grace.
SHUTDOWN_CANCEL_MARGIN_S = 2.0
_HEX64 = re.compile(r"^[0-9a-f]{64}$")


@dataclass(frozen=True)
class ApiKey:
    """One configured key: its sha256 hex digest, its scopes and an optional display name."""

    sha256: str
    scopes: frozenset[str]
    name: str = ""

    def allows(self, scope: str) -> bool:
        """True when this key grants ``scope``: one of its scopes is ``scope`` or comes after
        it in :data:`SCOPES` (``admin`` implies ``write``, which implies ``read``)."""
        if scope not in SCOPES:
            return False
        rank = SCOPES.index(scope)
        return any(SCOPES.index(s) >= rank for s in self.scopes)


def hash_api_key(key: str) -> str:
    """sha256 hex digest of an API key (UTF-8), the form stored in ``QUADLOC_API_KEYS``."""
    return hashlib.sha256(key.encode("utf-8")).hexdigest()


def _make_key(where: str, digest: object, scopes: object, name: object = "") -> ApiKey:
    if not isinstance(digest, str) or not _HEX64.match(digest.strip().lower()):
        raise ValueError(f"{where}: the key must be a sha256 hex digest (64 hex characters)")
    if isinstance(scopes, str):
        scopes = [s for s in scopes.split("+") if s]
    if not isinstance(scopes, list | tuple) or not scopes:
        raise ValueError(f"{where}: scopes must be a non-empty list of {list(SCOPES)}")
    bad = [s for s in scopes if s not in SCOPES]
    if bad:
        raise ValueError(f"{where}: unknown scope(s) {bad}; valid scopes are {list(SCOPES)}")
    return ApiKey(digest.strip().lower(), frozenset(scopes), str(name or ""))


def parse_api_keys(text: str) -> tuple[ApiKey, ...]:
    """Parse ``QUADLOC_API_KEYS`` (compact or JSON form, see the module docstring).

    Raises ``ValueError`` naming the entry and the problem.
    """
    text = (text or "").strip()
    if not text:
        return ()
    if text.startswith("["):
        try:
            entries = json.loads(text)
        except json.JSONDecodeError as exc:
            raise ValueError(f"QUADLOC_API_KEYS: invalid JSON: {exc}") from exc
        keys = []
        for i, entry in enumerate(entries):
            where = f"QUADLOC_API_KEYS[{i}]"
            if not isinstance(entry, dict):
                raise ValueError(f"{where}: must be an object with 'sha256' and 'scopes'")
            keys.append(_make_key(where, entry.get("sha256"), entry.get("scopes"),
                                  entry.get("name", "")))
        return tuple(keys)
    keys = []
    for i, entry in enumerate(re.split(r"[,\s]+", text)):
        if not entry:
            continue
        digest, sep, scopes = entry.partition(":")
        if not sep:
            raise ValueError(f"QUADLOC_API_KEYS entry {i}: expected '<sha256hex>:<scopes>'")
        keys.append(_make_key(f"QUADLOC_API_KEYS entry {i}", digest, scopes))
    return tuple(keys)


@dataclass(frozen=True)
class BuildLimitSettings:
    """The limits of one map build (:attr:`Settings.build_limits`): recording frames and
    detections (more -> 422), wall time of the build (s), request body (bytes; more -> 413;
    0: the general ``max_body_bytes``)."""

    max_frames: int
    max_detections: int
    time_budget_s: float
    max_body_bytes: int


#: The build limits of each runner when their settings are unset. In-process (the SQLite default,
#: ``make serve``): a build shares the API process and its GIL with the solves, so it stays small
#: and short. The job queue: builds run in ``quadloc worker`` processes apart from the API, so a
#: building-scale recording (measured: 6,000 frames of a 20-room walk, about 230 s and 0.9 GB of
#: RSS on the loaded 2-core machine, docs/results.md "Map building at building scale") fits with
#: room to spare.
BUILD_LIMIT_DEFAULTS: dict[str, BuildLimitSettings] = {
    "in-process": BuildLimitSettings(max_frames=2000, max_detections=20_000,
                                     time_budget_s=120.0, max_body_bytes=4_000_000),
    "queue": BuildLimitSettings(max_frames=10_000, max_detections=200_000,
                                time_budget_s=1800.0, max_body_bytes=32_000_000),
}
_IN_PROCESS, _QUEUE = BUILD_LIMIT_DEFAULTS["in-process"], BUILD_LIMIT_DEFAULTS["queue"]


def _default_data_dir() -> Path:
    """``<checkout>/var`` when running from a source checkout (an editable install, as ``make
    serve`` does: the package sits next to ``pyproject.toml`` and ``.git``), so every clone has
    its own database; otherwise (an installed wheel) ``~/.local/share/quadloc``. The container
    image sets ``QUADLOC_DATA_DIR=/data``."""
    checkout = Path(__file__).resolve().parents[1]
    if (checkout / "pyproject.toml").is_file() and (checkout / ".git").exists():
        return checkout / "var"
    return Path.home() / ".local" / "share" / "quadloc"


class Settings(BaseSettings):
    """All tunables of the service. Units are in the field names (``_ms``, ``_bytes``, ``_s``)."""

    model_config = SettingsConfigDict(env_prefix="QUADLOC_", extra="ignore")

    data_dir: Path = Field(default_factory=_default_data_dir,
                           description="Directory of the default SQLite database.")
    database_url: str | None = Field(
        default=None,
        description="SQLAlchemy URL: sqlite:///path or postgresql://... "
                    "(default: sqlite:///<data_dir>/quadloc.db).",
    )
    api_keys: str = Field(default="", description="Hashed API keys with scopes (module doc).")
    host: str = "127.0.0.1"
    port: int = Field(default=8000, ge=0, le=65535)
    workers: int = Field(default=1, ge=1, le=64,
                         description="Uvicorn worker processes (CPU-bound: ~1 per core).")
    log_level: str = "info"
    default_map_id: str = "chess"
    seed_demo_map: bool = Field(default=True,
                                description="Create the demo Chess map at startup if absent.")
    max_body_bytes: int = Field(default=2_000_000, ge=1024,
                                description="Largest request body; larger -> 413.")
    max_json_depth: int = Field(
        default=32, ge=8, le=64,
        description="Deepest nesting of objects/arrays accepted in a JSON request body; deeper "
                    "-> 422 naming the field (the top-level object is depth 1).",
    )
    # The request schema caps these (quadloc.service.limits); a larger setting would do nothing,
    # so it is refused at start.
    max_detections: int = Field(default=MAX_DETECTIONS, ge=1, le=MAX_DETECTIONS,
                                description="Detections per frame.")
    max_batch_frames: int = Field(default=32, ge=1, le=MAX_BATCH_FRAMES,
                                  description="Frames per batch request.")
    max_map_objects: int = Field(default=10_000, ge=1)
    solve_time_budget_ms: float = Field(
        default=1000.0, gt=0,
        description="Per-frame solve budget; a client may ask for less, never more.",
    )
    max_concurrent_solves: int = Field(
        default=2, ge=1,
        description="Frames solved at once per process (why 2: docs/design/service.md, "
                    "solver concurrency).",
    )
    batch_time_budget_ms: float = Field(
        default=20_000.0, gt=0, le=300_000.0,
        description="Total wall time of one localize:batch request (queue waits included). "
                    "Frames not started when it runs out answer localized=false with reason "
                    "time_budget_exceeded; frames already solved are kept. Keep it below the "
                    "proxy's read timeout (deploy/nginx.conf: 60 s).",
    )
    solve_queue_timeout_s: float = Field(
        default=5.0, ge=0,
        description="Longest wait for a solve slot before answering 503 + Retry-After.",
    )

    max_header_bytes: int = Field(
        default=32_768, ge=1024, le=1_048_576,
        description="Largest request line + headers (bytes); larger -> 400 and the connection "
                    "is closed (quadloc serve; service/api/server.py).",
    )
    request_read_timeout_s: float = Field(
        default=10.0, gt=0, le=300,
        description="A request (line, headers, body) must be received within this many seconds "
                    "of its first byte, else 408 and the connection is closed (slowloris guard).",
    )
    keep_alive_timeout_s: float = Field(
        default=5.0, gt=0, le=300,
        description="Idle keep-alive connections are closed after this many seconds.",
    )
    shutdown_grace_s: float = Field(
        default=30.0, ge=3.0, le=3600.0,
        description="On SIGTERM, requests in progress get this long to end (quadloc serve): "
                    "2 s before it, session frames and builds still running are cancelled, "
                    "and the process exits.",
    )
    max_build_frames: int | None = Field(
        default=None, ge=1, le=100_000,
        description="Frames per map-building recording; more -> 422 naming frames. Unset: "
                    "the build runner's default (BUILD_LIMIT_DEFAULTS: "
                    f"{_IN_PROCESS.max_frames} in-process, {_QUEUE.max_frames} with the job "
                    "queue's workers).",
    )
    max_build_detections: int | None = Field(
        default=None, ge=1, le=10_000_000,
        description="Detections per map-building recording; more -> 422. Unset: the build "
                    f"runner's default ({_IN_PROCESS.max_detections} in-process, "
                    f"{_QUEUE.max_detections} with the job queue).",
    )
    build_time_budget_s: float | None = Field(
        default=None, gt=0, le=86_400.0,
        description="Wall time of one map build; association past it fails the job "
                    "(time_budget_exceeded), refinement past it keeps its estimate so far. "
                    f"Unset: the build runner's default ({_IN_PROCESS.time_budget_s:g} s "
                    f"in-process, {_QUEUE.time_budget_s:g} s in a quadloc worker).",
    )
    max_build_body_bytes: int | None = Field(
        default=None, ge=1024, le=1_000_000_000,
        description="Largest body of POST /v1/maps:build (a recording); larger -> 413. "
                    f"Unset: the build runner's default ({_IN_PROCESS.max_body_bytes} "
                    f"in-process, {_QUEUE.max_body_bytes} with the job queue). Other requests: "
                    "max_body_bytes.",
    )
    build_runner: Literal["auto", "in-process", "queue"] = Field(
        default="auto",
        description="Where map builds run. queue: in quadloc worker processes, through the "
                    "job queue in PostgreSQL (procrastinate; the API only queues them); "
                    "in-process: in the API process's own threads (one process, not several "
                    "replicas); auto: queue on PostgreSQL, in-process on SQLite.",
    )
    max_concurrent_builds: int = Field(
        default=1, ge=1, le=16,
        description="Builds run at once per process: per API process (in-process runner, "
                    "threads sharing the GIL with the solves) or per quadloc worker.",
    )
    max_queued_builds: int = Field(default=4, ge=0, le=1000,
                                   description="Builds waiting per API process with the "
                                               "in-process runner; more -> 503.")
    max_active_build_jobs: int = Field(
        default=200, ge=1, le=100_000,
        description="Build jobs queued or running at once in the whole deployment with the "
                    "job queue (each holds its recording in the database until it ends); more "
                    "-> 503 + Retry-After (a soft limit: requests at the same instant may pass "
                    "it by a few).",
    )
    build_stale_after_s: float = Field(
        default=30.0, ge=5.0,
        description="Liveness window of a build runner. In-process: a queued/running job "
                    "silent this long lost its replica and is marked failed (runner_lost). "
                    "Queue: a quadloc worker silent this long (killed) lost its jobs: they "
                    "run again on another worker (3 runs at most, then runner_lost).",
    )
    worker_health_port: int = Field(
        default=8001, ge=0, le=65535,
        description="Port of a quadloc worker's health endpoint (GET /healthz: 200 while it "
                    "runs and reaches the database, else 503), on QUADLOC_HOST; 0: none.",
    )

    max_sessions: int = Field(
        default=200, ge=1, le=100_000,
        description="Live tracking sessions per process; more -> 503 session-capacity (after "
                    "idle ones expire).",
    )
    session_frame_budget_ms: float = Field(
        default=1000.0, gt=0, le=60_000.0,
        description="CPU time of one tracking-session frame; a frame past it is answered "
                    "without a pose, reason time_budget_exceeded (the session goes on).",
    )
    session_request_budget_ms: float = Field(
        default=20_000.0, gt=0, le=300_000.0,
        description="CPU time of one session frames request (a batch included; wall-clock "
                    "hard limit 2x, slot waits included); frames past it are answered "
                    "time_budget_exceeded. Keep it below the proxy's read timeout.",
    )
    max_sessions_per_key: int = Field(
        default=50, ge=1, le=100_000,
        description="Live tracking sessions per API key and process (besides max_sessions); "
                    "more -> 429 session-quota. Without keys the server has one caller: only "
                    "max_sessions applies.",
    )
    replica_id: str = Field(
        default="", pattern=r"^[a-z0-9-]{0,40}$",
        description="This replica's tag in tracking session ids (s-<tag>.<random>), which "
                    "the proxy routes by (deploy/nginx.conf). Empty: a random tag per process "
                    "start (the host name is never used).",
    )
    session_idle_timeout_s: float = Field(
        default=300.0, gt=0, le=86_400.0,
        description="A tracking session without a request for this long (counted from the "
                    "END of its last request) expires (404 session-not-found).",
    )

    map_cache_ttl_s: float = Field(
        default=1.0, ge=0,
        description="How long a replica may serve a cached map version (0 = always ask the "
                    "database); writes through this replica invalidate at once.",
    )

    @field_validator("api_keys")
    @classmethod
    def _check_keys(cls, value: str) -> str:
        if not parse_api_keys(value) and value.strip():
            # e.g. "," or "[]": the operator meant to configure keys but configured none.
            raise ValueError("QUADLOC_API_KEYS is set but contains no key; unset it to run "
                             "open (loopback only) or list '<sha256hex>:<scopes>' entries")
        return value

    @property
    def effective_database_url(self) -> str:
        """``database_url`` or the default SQLite file under ``data_dir``."""
        if self.database_url:
            return self.database_url
        return f"sqlite:///{(Path(self.data_dir) / 'quadloc.db').resolve()}"

    def build_limits_for(self, runner: Literal["in-process", "queue"]) -> BuildLimitSettings:
        """The map-building limits in force where builds run on ``runner`` (the resolved
        ``build_runner``): each ``QUADLOC_MAX_BUILD_*`` / ``QUADLOC_BUILD_TIME_BUDGET_S`` that is
        set, else :data:`BUILD_LIMIT_DEFAULTS` of that runner."""
        base = BUILD_LIMIT_DEFAULTS[runner]
        return BuildLimitSettings(
            max_frames=self.max_build_frames or base.max_frames,
            max_detections=self.max_build_detections or base.max_detections,
            time_budget_s=self.build_time_budget_s or base.time_budget_s,
            max_body_bytes=self.max_build_body_bytes or base.max_body_bytes
            or self.max_body_bytes)

    @property
    def keys(self) -> tuple[ApiKey, ...]:
        """Parsed API keys (empty when the service is open)."""
        return parse_api_keys(self.api_keys)

    @property
    def auth_enabled(self) -> bool:
        """True when at least one key is configured (based on the parsed keys)."""
        return bool(self.keys)


def is_loopback_host(host: str) -> bool:
    """True for ``localhost`` and loopback IP literals (127.0.0.0/8, ::1)."""
    if host.strip().lower() == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


def check_bind_allowed(settings: Settings, host: str) -> None:
    """Refuse (``ValueError``) to bind a non-loopback ``host`` when no API key is configured."""
    if not settings.auth_enabled and not is_loopback_host(host):
        raise ValueError(
            f"refusing to listen on {host!r} without API keys: set QUADLOC_API_KEYS "
            "(sha256 of each key with its scopes) or bind 127.0.0.1"
        )


#: Markers of the generated settings table in ``docs/deployment.md``.
SETTINGS_TABLE_BEGIN = ("<!-- BEGIN settings-table: generated by "
                        "python -m quadloc.service.settings --update docs/deployment.md -->")
SETTINGS_TABLE_END = "<!-- END settings-table -->"
_TYPE_NAMES = {int: "integer", float: "number", str: "string", bool: "boolean", Path: "path"}
_BOUNDS = (("ge", ">="), ("gt", ">"), ("le", "<="), ("lt", "<"))


def _type_name(annotation: Any) -> str:
    if isinstance(annotation, UnionType):
        args = [a for a in get_args(annotation) if a is not NoneType]
        return " or ".join(_type_name(a) for a in args) + (
            " (optional)" if len(args) < len(get_args(annotation)) else "")
    if get_origin(annotation) is Literal:
        return "one of " + ", ".join(f"`{a}`" for a in get_args(annotation))
    return _TYPE_NAMES.get(annotation, getattr(annotation, "__name__", str(annotation)))


def _value_text(value: object) -> str:
    if value is None:
        return "(unset)"
    if isinstance(value, bool):
        return "`true`" if value else "`false`"
    if isinstance(value, float) and value.is_integer():
        value = int(value)
    return "(empty)" if value == "" else f"`{value}`"


def _cell(text: str) -> str:
    return " ".join(text.split()).replace("|", "\\|")


def settings_table_markdown() -> str:
    """The settings table of ``docs/deployment.md``, one row per :class:`Settings` field:
    variable ``QUADLOC_<FIELD>``, type, default (a computed default: its function's
    docstring), bounds (the field's ``ge`` / ``gt`` / ``le`` / ``lt``) and description.
    Written by ``python -m quadloc.service.settings --update docs/deployment.md``;
    ``tests/test_docs.py`` fails when the committed table differs."""
    rows = ["| variable | type | default | bounds | description |", "|---|---|---|---|---|"]
    for name, info in Settings.model_fields.items():
        if info.default_factory is not None:
            doc = info.default_factory.__doc__ or info.default_factory.__name__
            default = "computed: " + doc.replace("``", "`")
        else:
            default = _value_text(info.default)
        bounds = ", ".join(f"{sym} {_value_text(getattr(m, attr)).strip('`')}"
                           for m in info.metadata for attr, sym in _BOUNDS
                           if getattr(m, attr, None) is not None)
        rows.append(f"| `QUADLOC_{name.upper()}` | {_type_name(info.annotation)} | "
                    f"{_cell(default)} | {bounds or '-'} | {_cell(info.description or '-')} |")
    return "\n".join(rows)


def _update_table(path: Path) -> bool:
    """Replace the generated table between the markers of ``path``; True when it changed."""
    text = path.read_text()
    head, sep, rest = text.partition(SETTINGS_TABLE_BEGIN)
    _, sep2, tail = rest.partition(SETTINGS_TABLE_END)
    if not sep or not sep2:
        raise SystemExit(f"{path}: no settings-table markers")
    new = f"{head}{SETTINGS_TABLE_BEGIN}\n{settings_table_markdown()}\n{SETTINGS_TABLE_END}{tail}"
    path.write_text(new)
    return new != text


if __name__ == "__main__":
    # python -m quadloc.service.settings                  prints the table
    # python -m quadloc.service.settings --update FILE    rewrites it between the markers
    if sys.argv[1:2] == ["--update"] and len(sys.argv) == 3:
        print("updated" if _update_table(Path(sys.argv[2])) else "unchanged")
    else:
        print(settings_table_markdown())
