"""How a use case refuses: :class:`AppError`, the one exception the front ends render.

A use case (``quadloc.service.app``) never speaks HTTP or prints: it raises :class:`AppError`
with a problem ``code`` (the slug of an RFC 9457 problem type, e.g. ``"map-not-found"``,
``"validation-error"``, ``"busy"``), a sentence for people (``detail``), the offending fields
(``errors``: ``[{"field": ..., "message": ...}]``, fields spelled like
``detections[2].ellipse.a``, ``header.if-match``, ``path.map_id``) and, where the client should
come back later or compare versions, ``retry_after_s`` and ``etag``. The HTTP layer turns it
into an ``application/problem+json`` answer (``quadloc.service.api.errors``: the code's status
and title), the CLI into a message and an exit status.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence

from sqlalchemy.exc import ProgrammingError

from quadloc.maps.errors import SchemaNotMigrated

__all__ = [
    "MIGRATE_HINT",
    "AppError",
    "field_and_problem",
    "first_line",
    "invalid_input",
    "log_database_error",
    "map_not_found",
]

log = logging.getLogger("quadloc.app")


class AppError(Exception):
    """A use case's refusal (see the module docstring).

    Attributes:
        code: problem type slug (every code used is a key of
            ``quadloc.service.api.errors.PROBLEM_TYPES``; a test checks it).
        detail: one sentence for people.
        errors: ``[{"field": ..., "message": ...}]``, possibly empty.
        retry_after_s: seconds after which a retry may succeed (busy, loading), or None.
        etag: the current ETag of the resource a precondition was checked against, or None.
    """

    def __init__(self, code: str, detail: str, *,
                 errors: Sequence[Mapping[str, str]] = (), field: str | None = None,
                 message: str = "", retry_after_s: float | None = None,
                 etag: str | None = None) -> None:
        super().__init__(detail)
        self.code = code
        self.detail = detail
        self.errors: list[dict[str, str]] = (
            [{"field": field, "message": message}] if field is not None
            else [{"field": str(e["field"]), "message": str(e["message"])} for e in errors])
        self.retry_after_s = retry_after_s
        self.etag = etag


def field_and_problem(exc: Exception, prefix: str = "") -> tuple[str, str]:
    """``(field, problem)`` of an input error, ``prefix`` prepended to the field.

    The field is the error's structured ``field`` (:class:`quadloc.factors.names.FieldError`:
    ``GeometryError``, ``LocalizationInputError``, ``TrackingInputError``); errors raised
    without one answer ``"body"``. The message is never parsed.
    """
    field = getattr(exc, "field", None)
    if field:
        return prefix + field, str(getattr(exc, "problem", exc))
    return prefix + "body", str(exc)


def invalid_input(exc: Exception, prefix: str = "", code: str = "validation-error") -> AppError:
    """The :class:`AppError` of an input error naming its field (``prefix`` before it, e.g.
    ``"frames[3]."``): detail ``"<field>: <problem>"``."""
    field, problem = field_and_problem(exc, prefix)
    return AppError(code, f"{field}: {problem}", field=field, message=problem)


def map_not_found(map_id: str, version: int | None = None) -> AppError:
    """404 ``map-not-found`` for ``map_id`` (and ``version``, when one was asked for)."""
    what = f"map {map_id!r}" if version is None else f"version {version} of map {map_id!r}"
    return AppError("map-not-found", f"{what} not found",
                    field="path.map_id" if version is None else "query.version",
                    message="not found")


#: Logged when the database lacks the map tables (the answer is a 503 like any outage).
MIGRATE_HINT = ("the map database schema is missing or not migrated to this version: restart "
                "the service (it migrates at start) or run 'alembic -c "
                "maps/migrations/alembic.ini -x url=<database url> upgrade head'")


def log_database_error(where: str, exc: Exception) -> None:
    """Log a database failure ``where`` (with :data:`MIGRATE_HINT` when the schema is missing;
    the driver's text goes to the log, never to a client)."""
    if isinstance(exc, SchemaNotMigrated | ProgrammingError):
        log.error("%s: %s (%s)", where, MIGRATE_HINT, first_line(exc))
    else:
        log.error("%s: %s", where, exc)


def _first_line(exc: Exception) -> str:
    return str(exc).splitlines()[0] if str(exc) else type(exc).__name__


def first_line(exc: Exception) -> str:
    """The first line of an exception's text (its type's name when it has none)."""
    return str(exc).splitlines()[0] if str(exc) else type(exc).__name__
