"""Wire models of the map resources (``/v1/maps``...): summaries, stored versions, history, and
the ``ETag`` of a version (:func:`etag_of`)."""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel, Field

__all__ = [
    "MapListOut",
    "MapOut",
    "MapSummaryOut",
    "MapVersionOut",
    "MapVersionsOut",
    "etag_of",
]


def etag_of(content_hash: str) -> str:
    """Strong ETag of a map version (its content hash, quoted)."""
    return f'"{content_hash}"'


class MapSummaryOut(BaseModel):
    map_id: str
    name: str
    version: int
    content_hash: str
    updated_at: str | None = None


class MapListOut(BaseModel):
    maps: list[MapSummaryOut]


class MapOut(BaseModel):
    """A stored map version: its metadata and the map document (docs/maps.md format)."""

    map_id: str
    version: int
    content_hash: str = Field(description="sha256 of the canonical map content (the ETag).")
    created_at: str | None = None
    map: dict[str, Any] = Field(description="The map in the documented JSON format.")


class MapVersionOut(BaseModel):
    version: int
    content_hash: str = Field(description="sha256 of the version's canonical content (its ETag).")
    created_at: str | None = None


class MapVersionsOut(BaseModel):
    """Every stored version of a map, ascending (the last one is the latest)."""

    map_id: str
    versions: list[MapVersionOut]
