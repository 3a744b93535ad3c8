"""``quadloc maps build recording.json --map-id ID``: build a map from a recording.

With ``--url`` / ``QUADLOC_URL``: a ``POST /v1/maps:build`` job on that server through the SDK
(``client.build_map``), its progress polled. Without: the same build
(``quadloc.maps.building.build.build_map``) in this process against the local database, like the
other ``quadloc maps`` commands. A progress bar goes to stderr either way. An existing map id needs
``--update`` (stored as its next version; refused if the map changed during the build).
``--report PATH`` writes the build report (which detections built which object, per-object
quality, rejected detections) as JSON. Exit codes: 0 built, 1 no map (nothing associated, time
budget, job failed), 2 bad input or store / server error.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, TextIO

from quadloc.service import cli

__all__ = ["ProgressBar", "add_build_parser", "cmd_maps_build"]


class ProgressBar(cli.Progress):
    """``[#####.....]  45% refining (7 objects)`` redrawn in place on a terminal, one line per
    stage change otherwise (logs stay readable)."""

    def __init__(self, stream: TextIO | None = None, width: int = 30) -> None:
        self.stream = stream if stream is not None else sys.stderr
        self.width = width
        self.tty = self.enabled = bool(getattr(stream, "isatty", lambda: False)())
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


def _print_objects(report: dict[str, Any]) -> None:
    for o in report["objects"]:
        q = o["quality"]
        flag = f", unconstrained axes {q['unconstrained_axes']}" if q["unconstrained_axes"] else ""
        print(f"  {o['object_id']:<20} {q['n_views']:>4} views, spread "
              f"{q['view_spread_deg']:5.1f} deg{flag}", file=sys.stderr)


def _remote_build(args: argparse.Namespace, client: Any, data: Any) -> int:
    from quadloc_sdk import errors as sdk_errors
    from quadloc_sdk.build import BuildFailedError

    bar = ProgressBar()
    t0 = time.monotonic()
    try:
        if_match = None
        if args.update:
            try:
                if_match = client.get_map(args.map_id).etag
            except sdk_errors.QuadLocError as exc:
                if getattr(exc, "status", None) != 404:
                    raise
        job = client.build_map(data, map_id=args.map_id, if_match=if_match,
                               on_progress=lambda j: bar(j.stage, j.percent, j.objects_found))
    except BuildFailedError as exc:
        bar.close()
        if exc.job.report is not None:
            _write_report(args.report, exc.job.report)
        return cli._die(str(exc), 1)
    except sdk_errors.QuadLocError as exc:
        bar.close()
        hint = " (pass --update to build its next version)" \
            if "If-Match" in str(exc) and not args.update else ""
        return cli._die(f"{exc}{hint}")
    bar.close()
    _write_report(args.report, job.report)
    _print_objects(job.report)
    c = job.report["counts"]
    print(f"{job.map_id} version {job.map_version} ({c['objects']} objects from "
          f"{c['detections']} detections in {c['frames']} frames, "
          f"{c['rejected_detections']} rejected, {time.monotonic() - t0:.1f} s)")
    return 0


def _write_report(path: str | None, report: Any) -> None:
    if path:
        Path(path).write_text(json.dumps(report, indent=2) + "\n", encoding="utf-8")


def cmd_maps_build(args: argparse.Namespace) -> int:
    from quadloc.factors.budget import Deadline
    from quadloc.maps.building.build import BuildTimeoutError, build_map
    from quadloc.maps.building.recording import RecordingError, parse_recording
    from quadloc.maps.errors import MapNotFound, VersionConflict
    from quadloc.service.api.build_jobs import build_limits

    data = cli._read_json(args.file)
    if cli._server(args):
        return _remote_build(args, cli._client(args), data)
    settings = cli._settings(args)
    try:
        recording = parse_recording(data, build_limits(settings))
    except RecordingError as exc:
        return cli._invalid([(e["field"], e["message"]) for e in exc.errors],
                        f"{args.file}: invalid recording ({len(exc.errors)} problem(s))")
    store = cli._store(args)
    try:
        base = store.get(args.map_id).scene_map.version
    except MapNotFound:
        base = None
    if base is not None and not args.update:
        return cli._die(f"map {args.map_id!r} exists; pass --update to store the build as its next "
                   "version")
    bar = ProgressBar()
    t0 = time.monotonic()
    try:
        scene, report = build_map(recording, map_id=args.map_id, progress=bar,
                                  deadline=Deadline.wall_budget(settings.build_time_budget_s))
    except BuildTimeoutError as exc:
        bar.close()
        return cli._die(f"{exc} (QUADLOC_BUILD_TIME_BUDGET_S={settings.build_time_budget_s:g})", 1)
    bar.close()
    _write_report(args.report, report)
    if not scene.objects:
        return cli._die("no object could be associated and reconstructed (see --report)", 1)
    try:
        stored = store.create(scene) if base is None else store.update(args.map_id, scene, base)
    except VersionConflict as exc:
        return cli._die(f"map {args.map_id!r} changed during the build (now version "
                   f"{exc.current_version}); nothing was overwritten")
    _print_objects(report)
    c = report["counts"]
    print(f"{stored.scene_map.map_id} version {stored.scene_map.version} "
          f"({len(stored.scene_map.objects)} objects from {c['detections']} detections in "
          f"{c['frames']} frames, {c['rejected_detections']} rejected, "
          f"{time.monotonic() - t0:.1f} s) etag \"{stored.content_hash}\"")
    return 0


def add_build_parser(msub: Any, db: Callable[[argparse.ArgumentParser], None]) -> None:
    """Register ``maps build`` on the ``maps`` sub-command parser."""
    p = msub.add_parser("build", help="build a map from a recording (posed frames + detections)",
                        description=__doc__.split("\n\n")[1])
    p.add_argument("file", help="recording JSON (docs/map_building.md; '-' = stdin)")
    p.add_argument("--map-id", required=True, help="id of the map to create (or update)")
    p.add_argument("--update", action="store_true",
                   help="if the id exists, store the build as its next version")
    p.add_argument("--report", metavar="PATH", help="write the build report (JSON) here")
    db(p)
    p.set_defaults(func=cmd_maps_build)
