"""``quadloc maps build recording.json --map-id ID``: build a map from a recording.

With ``--url`` / ``QUADLOC_URL``: a ``POST /v1/maps:build`` job on that server through the SDK
(``client.build_map``), its progress polled. Without: the same build in this process against
the local database (the application's ``builds.build_now``), like the other ``quadloc maps``
commands. A progress bar goes to stderr either way. An existing map id needs ``--update``
(stored as its next version; refused if the map changed during the build). ``--report PATH``
writes the build report (which detections built which object, per-object quality, rejected
detections) as JSON. Exit codes: 0 built, 1 no map (nothing associated, time budget, job
failed), 2 bad input or store / server error.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from quadloc.service.cli.common import (
    CliError,
    ProgressBar,
    client,
    die,
    local_app,
    read_json,
    server_url,
)
from quadloc.service.schemas.maps import etag_of
from quadloc_sdk import QuadLocClient
from quadloc_sdk.build import BuildFailedError
from quadloc_sdk.errors import QuadLocError

if TYPE_CHECKING:
    from quadloc.maps.building.report import BuildReport

__all__ = ["cmd_maps_build"]


def _print_objects(report: dict[str, Any]) -> None:
    for o in report["objects"]:
        q = o["quality"]
        flag = f", unconstrained axes {q['unconstrained_axes']}" if q["unconstrained_axes"] else ""
        print(f"  {o['object_id']:<20} {q['n_views']:>4} views, spread "
              f"{q['view_spread_deg']:5.1f} deg{flag}", file=sys.stderr)


def _summary(report: dict[str, Any], t0: float) -> str:
    c = report["counts"]
    return (f"({c['objects']} objects from {c['detections']} detections in {c['frames']} "
            f"frames, {c['rejected_detections']} rejected, {time.monotonic() - t0:.1f} s)")


def _write_report(path: str | None, report: BuildReport | dict[str, Any] | None) -> None:
    from quadloc.maps.building.report import BuildReport

    if path and report is not None:
        text = (report.model_dump_json(indent=2) if isinstance(report, BuildReport)
                else BuildReport.model_validate(report).model_dump_json(indent=2))
        Path(path).write_text(text + "\n", encoding="utf-8")


def _remote_build(args: argparse.Namespace, c: QuadLocClient, data: Any) -> int:
    bar = ProgressBar()
    t0 = time.monotonic()
    try:
        if_match = None
        if args.update:
            try:
                if_match = c.get_map(args.map_id).etag
            except QuadLocError as exc:
                if getattr(exc, "status", None) != 404:
                    raise
        job = c.build_map(data, map_id=args.map_id, if_match=if_match,
                          on_progress=lambda j: bar(j.stage, j.percent, j.objects_found))
    except BuildFailedError as exc:
        bar.close()
        _write_report(args.report, exc.job.report)
        return die(str(exc), 1)
    except QuadLocError as exc:
        bar.close()
        hint = " (pass --update to build its next version)" \
            if "If-Match" in str(exc) and not args.update else ""
        raise CliError(f"{exc}{hint}") from exc
    bar.close()
    _write_report(args.report, job.report)
    report = job.report or {}
    _print_objects(report)
    print(f"{job.map_id} version {job.map_version} {_summary(report, t0)}")
    return 0


def cmd_maps_build(args: argparse.Namespace) -> int:
    data = read_json(args.file)
    if server_url(args):
        with client(args) as c:
            return _remote_build(args, c, data)
    bar = ProgressBar()
    t0 = time.monotonic()
    try:
        built = local_app(args).builds.build_now(data, args.map_id, update=args.update,
                                                 progress=bar)
    finally:
        bar.close()
    _write_report(args.report, built.report)
    if built.stored is None:
        return die(built.detail, 1)
    report = built.report.model_dump() if built.report is not None else {}
    _print_objects(report)
    sm = built.stored.scene_map
    print(f"{sm.map_id} version {sm.version} {_summary(report, t0)} "
          f"etag {etag_of(built.stored.content_hash)}")
    return 0
