"""Wire models of map building: ``POST /v1/maps:build`` answers a :class:`BuildJobOut`, and
``GET /v1/build-jobs/{job_id}`` follows it (progress, then the map version and the report, or
the error). The report is the build's own typed model
(:class:`quadloc.maps.building.report.BuildReport`). Times are ISO 8601, UTC."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, Field

from quadloc.maps.building.report import BuildReport

__all__ = ["BuildErrorOut", "BuildJobOut"]


class BuildErrorOut(BaseModel):
    """Why a build job failed."""

    reason: str = Field(description="invalid_recording, time_budget_exceeded, no_objects, "
                                    "map_exists, version_conflict, map_not_found, "
                                    "store_unavailable, busy, runner_lost or internal_error.")
    detail: str


class BuildJobOut(BaseModel):
    """A map-building job."""

    job_id: str
    map_id: str
    status: Literal["queued", "running", "succeeded", "failed"]
    stage: str = Field(description="queued, associating, refining, saving, done or failed")
    percent: float = Field(description="Progress, 0-100.")
    objects_found: int
    base_version: int | None = Field(description="Version the build replaces (If-Match), "
                                                 "null for a new map.")
    map_version: int | None = Field(description="Version created (succeeded jobs).")
    error: BuildErrorOut | None = Field(description="Why it failed (failed jobs).")
    report: BuildReport | None = Field(description="Association and quality report.")
    created_at: str
    updated_at: str
