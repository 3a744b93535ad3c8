"""``quadloc maps build recording.json --map-id ID``: build a map from a recording, locally.

Runs the same build as ``POST /v1/maps:build`` (``maps.building.build.build_map``) in this
process, against the configured database (like the other ``quadloc maps`` commands), with a
progress bar on stderr. An existing map id needs ``--update`` (the map is stored as its next
version, refused if it changed during the build). ``--report PATH`` writes the build report
(which detections built which object, per-object quality, rejected detections) as JSON.
Exit codes: 0 built, 1 no map (nothing associated / time budget), 2 bad input or store error.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, TextIO

__all__ = ["ProgressBar", "add_build_parser", "cmd_maps_build"]


class ProgressBar:
    """``[#####.....]  45% refining (7 objects)`` redrawn in place on a terminal, one line per
    stage change otherwise (logs stay readable)."""

    def __init__(self, stream: TextIO = sys.stderr, width: int = 30) -> None:
        self.stream = stream
        self.width = width
        self.tty = bool(getattr(stream, "isatty", lambda: False)())
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

    def close(self) -> None:
        if self.tty:
            self.stream.write("\n")
            self.stream.flush()


def cmd_maps_build(args: argparse.Namespace, store_factory: Callable[[argparse.Namespace], Any],
                   settings_factory: Callable[[argparse.Namespace], Any]) -> int:
    from maps.building.build import BuildTimeoutError, build_map
    from maps.building.recording import BuildLimits, RecordingError, parse_recording
    from maps.errors import MapNotFound, VersionConflict

    def die(msg: str, code: int = 2) -> int:
        print(f"quadloc: error: {msg}", file=sys.stderr)
        return code

    try:
        text = sys.stdin.read() if args.file == "-" else Path(args.file).read_text("utf-8")
        data = json.loads(text)
    except (OSError, json.JSONDecodeError, UnicodeDecodeError) as exc:
        return die(f"{args.file}: {exc}")
    settings = settings_factory(args)
    try:
        recording = parse_recording(data, BuildLimits(
            max_frames=settings.max_build_frames, max_detections_per_frame=settings.max_detections,
            max_detections=settings.max_build_detections))
    except RecordingError as exc:
        for e in exc.errors:
            print(f"  {e['field']}: {e['message']}", file=sys.stderr)
        return die(f"{args.file}: invalid recording ({len(exc.errors)} problem(s))")
    store = store_factory(args)
    try:
        base = store.get(args.map_id).scene_map.version
    except MapNotFound:
        base = None
    if base is not None and not args.update:
        return die(f"map {args.map_id!r} exists; pass --update to store the build as its next "
                   "version")
    bar = ProgressBar()
    t0 = time.monotonic()
    try:
        scene, report = build_map(recording, map_id=args.map_id, progress=bar,
                                  deadline=t0 + settings.build_time_budget_s)
    except BuildTimeoutError as exc:
        bar.close()
        return die(f"{exc} (QUADLOC_BUILD_TIME_BUDGET_S={settings.build_time_budget_s:g})", 1)
    bar.close()
    if args.report:
        Path(args.report).write_text(json.dumps(report, indent=2) + "\n", encoding="utf-8")
    if not scene.objects:
        return die("no object could be associated and reconstructed (see --report)", 1)
    try:
        stored = store.create(scene) if base is None else store.update(args.map_id, scene, base)
    except VersionConflict as exc:
        return die(f"map {args.map_id!r} changed during the build (now version "
                   f"{exc.current_version}); nothing was overwritten")
    for o in report["objects"]:
        q = o["quality"]
        flag = f", unconstrained axes {q['unconstrained_axes']}" if q["unconstrained_axes"] else ""
        print(f"  {o['object_id']:<20} {q['n_views']:>4} views, spread "
              f"{q['view_spread_deg']:5.1f} deg{flag}", file=sys.stderr)
    c = report["counts"]
    print(f"{stored.scene_map.map_id} version {stored.scene_map.version} "
          f"({len(stored.scene_map.objects)} objects from {c['detections']} detections in "
          f"{c['frames']} frames, {c['rejected_detections']} rejected, "
          f"{time.monotonic() - t0:.1f} s) etag \"{stored.content_hash}\"")
    return 0


def add_build_parser(msub: Any, db: Callable[[argparse.ArgumentParser], None],
                     store_factory: Callable[[argparse.Namespace], Any],
                     settings_factory: Callable[[argparse.Namespace], Any]) -> None:
    """Register ``maps build`` on the ``maps`` sub-command parser."""
    p = msub.add_parser("build", help="build a map from a recording (posed frames + detections)",
                        description=__doc__.split("\n\n")[1])
    p.add_argument("file", help="recording JSON (docs/map_building.md; '-' = stdin)")
    p.add_argument("--map-id", required=True, help="id of the map to create (or update)")
    p.add_argument("--update", action="store_true",
                   help="if the id exists, store the build as its next version")
    p.add_argument("--report", metavar="PATH", help="write the build report (JSON) here")
    db(p)
    p.set_defaults(func=lambda a: cmd_maps_build(a, store_factory, settings_factory))
