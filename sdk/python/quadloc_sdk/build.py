"""Map building through the API: ``client.build_map(recording, map_id=..., wait=True,
on_progress=...)`` (:class:`sdk.QuadLocClient`; ``await client.build_map(...)`` on
:class:`sdk.AsyncQuadLocClient`).

``POST /v1/maps:build?map_id=...`` starts a job (202 + ``Location``); with ``wait=True`` the job
resource is polled every ``poll_interval_s`` until it succeeds (the :class:`BuildJob` is
returned: ``map_version``, ``report``) or fails (:class:`BuildFailedError` carrying the job and
its ``error {reason, detail}``). ``on_progress(job)`` is called whenever the stage, percent or
number of objects changed. To build a new version of an existing map, pass ``if_match`` = its
ETag (``client.get_map(map_id).etag``).

The recording is a dict or a path to a JSON file in the format of docs/map_building.md
(intrinsics, frames with ``world_from_camera`` and detections).
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from quadloc_sdk.errors import QuadLocError
from quadloc_sdk.transport import Call

__all__ = ["BuildFailedError", "BuildJob", "Recording", "abuild_map", "aget_build_job",
           "build_map", "get_build_job", "load_recording"]

Recording = Mapping[str, Any] | str | Path


@dataclass(frozen=True)
class BuildJob:
    """A map-building job as the server reports it (``GET /v1/build-jobs/{job_id}``)."""

    job_id: str
    map_id: str
    status: str
    stage: str
    percent: float
    objects_found: int
    base_version: int | None
    map_version: int | None
    error: dict[str, Any] | None
    report: dict[str, Any] | None
    created_at: str
    updated_at: str

    @classmethod
    def from_wire(cls, data: Mapping[str, Any]) -> BuildJob:
        return cls(**{k: data.get(k) for k in cls.__dataclass_fields__})  # type: ignore[arg-type]
        # (the server's BuildJobOut has every field, of these types)

    @property
    def done(self) -> bool:
        return self.status in ("succeeded", "failed")


class BuildFailedError(QuadLocError):
    """The job ended ``failed`` (``job.error["reason"]``: e.g. ``time_budget_exceeded``,
    ``no_objects``, ``version_conflict``, ``runner_lost``) or did not end within the timeout."""

    def __init__(self, message: str, job: BuildJob) -> None:
        super().__init__(message)
        self.job = job


def load_recording(recording: Recording) -> bytes:
    """The JSON body of a recording given as a dict or a path to a JSON file (the build and
    the calibration send it as is)."""
    if isinstance(recording, str | Path):
        return Path(recording).read_bytes()
    if not isinstance(recording, Mapping):
        raise TypeError(f"recording: expected a dict or a path, got {type(recording).__name__}")
    return json.dumps(recording, allow_nan=False).encode()


def get_build_job(client: Any, job_id_or_location: str) -> BuildJob:
    """The current state of a job (by id or by the ``Location`` path)."""
    return BuildJob.from_wire(client._json(client._send(
        Call("GET", _job_path(job_id_or_location), idempotent=True))))


def _start_call(recording: Recording, map_id: str, if_match: str | None) -> Any:
    headers = {"Content-Type": "application/json"}
    if if_match is not None:
        headers["If-Match"] = if_match if if_match.startswith(('"', "W/")) else f'"{if_match}"'
    # Not idempotent: a replay after a lost answer would start a second job.
    return Call("POST", "/v1/maps:build", params={"map_id": map_id}, body=load_recording(recording),
                 headers=headers)


def _job_path(job_id_or_location: str) -> str:
    return job_id_or_location if job_id_or_location.startswith("/") \
        else f"/v1/build-jobs/{job_id_or_location}"


def _failed(job: BuildJob) -> BuildFailedError:
    err = job.error or {}
    return BuildFailedError(f"build job {job.job_id} failed: {err.get('reason')}: "
                            f"{err.get('detail')}", job)


def _timed_out(job: BuildJob, timeout_s: float) -> BuildFailedError:
    return BuildFailedError(f"build job {job.job_id} not finished after {timeout_s:g} s "
                            f"(still {job.status}); poll it with get_build_job", job)


async def aget_build_job(client: Any, job_id_or_location: str) -> BuildJob:
    """:func:`get_build_job` for :class:`sdk.AsyncQuadLocClient`."""
    response = await client._send(Call("GET", _job_path(job_id_or_location), idempotent=True))
    return BuildJob.from_wire(client._json(response))


async def abuild_map(
    client: Any, recording: Recording, *, map_id: str, if_match: str | None = None,
    wait: bool = True, on_progress: Callable[[BuildJob], None] | None = None,
    poll_interval_s: float = 0.5, timeout_s: float = 600.0,
) -> BuildJob:
    """:func:`build_map` for :class:`sdk.AsyncQuadLocClient` (polls with ``asyncio.sleep``)."""
    import asyncio

    response = await client._send(_start_call(recording, map_id, if_match))
    job = BuildJob.from_wire(client._json(response))
    location = response.headers.get("location") or f"/v1/build-jobs/{job.job_id}"
    if on_progress is not None:
        on_progress(job)
    if not wait:
        return job
    t0 = time.monotonic()
    last = (job.stage, job.percent, job.objects_found)
    while not job.done:
        if time.monotonic() - t0 > timeout_s:
            raise _timed_out(job, timeout_s)
        await asyncio.sleep(poll_interval_s)
        job = await aget_build_job(client, location)
        now = (job.stage, job.percent, job.objects_found)
        if on_progress is not None and now != last:
            on_progress(job)
        last = now
    if job.status == "failed":
        raise _failed(job)
    return job


def build_map(
    client: Any, recording: Recording, *, map_id: str, if_match: str | None = None,
    wait: bool = True, on_progress: Callable[[BuildJob], None] | None = None,
    poll_interval_s: float = 0.5, timeout_s: float = 600.0,
) -> BuildJob:
    """Start a build (and wait for it unless ``wait=False``); see the module docstring."""
    response = client._send(_start_call(recording, map_id, if_match))
    job = BuildJob.from_wire(client._json(response))
    location = response.headers.get("location") or f"/v1/build-jobs/{job.job_id}"
    if on_progress is not None:
        on_progress(job)
    if not wait:
        return job
    t0 = time.monotonic()
    last = (job.stage, job.percent, job.objects_found)
    while not job.done:
        if time.monotonic() - t0 > timeout_s:
            raise _timed_out(job, timeout_s)
        time.sleep(poll_interval_s)
        job = get_build_job(client, location)
        now = (job.stage, job.percent, job.objects_found)
        if on_progress is not None and now != last:
            on_progress(job)
        last = now
    if job.status == "failed":
        raise _failed(job)
    return job
