"""``quadloc import-recording``: a recording (the input of ``quadloc maps build``) from a camera
trajectory (TUM RGB-D, COLMAP text model, ARKit/ARCore JSON log) and COCO-format detections,
with the SDK's importers (:mod:`quadloc_sdk.importers`; formats, conventions and the sigma
model are stated there). Exit status 0 written, 2 bad input.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from quadloc.service.cli.common import CliError, read_json
from quadloc_sdk import importers

__all__ = ["cmd_import_recording"]


def _text(path: Path) -> str:
    try:
        return path.read_text(encoding="utf-8")
    except OSError as exc:
        raise CliError(f"{path}: {exc}") from exc


def _camera(spec: str) -> dict[str, float | int]:
    try:
        fx, fy, cx, cy, w, h = (float(v) for v in spec.split(","))
    except ValueError as exc:
        raise CliError(f"--camera: expected FX,FY,CX,CY,WIDTH,HEIGHT, got {spec!r}") from exc
    return {"fx": fx, "fy": fy, "cx": cx, "cy": cy, "width": int(w), "height": int(h)}


def _trajectory(args: argparse.Namespace) -> tuple[dict[str, Any], dict[str, Any] | None, str]:
    """``(poses by frame name, camera or None, convention)``."""
    if args.colmap:
        folder = Path(args.colmap)
        return (importers.read_colmap_images(_text(folder / "images.txt")),
                importers.read_colmap_camera(_text(folder / "cameras.txt")), "opencv")
    if args.tum:
        poses = importers.read_tum_trajectory(_text(Path(args.tum)))
        if args.tum_images:
            poses = importers.match_timestamps(poses, _text(Path(args.tum_images)))
        return poses, None, "opencv"
    return importers.read_ar_log(read_json(args.ar_log)), None, "opengl"


def cmd_import_recording(args: argparse.Namespace) -> int:
    try:
        poses, camera, convention = _trajectory(args)
        if args.camera:
            camera = _camera(args.camera)
        if camera is None:
            raise CliError("--camera FX,FY,CX,CY,WIDTH,HEIGHT is required (the trajectory "
                           "does not give the intrinsics)")
        results = read_json(args.coco_results)
        categories: dict[int, str] = {}
        names: dict[int, str] | None = None
        if args.coco_annotations:
            ann = read_json(args.coco_annotations)
            categories = {int(c["id"]): str(c["name"]) for c in ann.get("categories", [])}
            names = {int(i["id"]): str(i["file_name"]) for i in ann.get("images", [])} or None
        else:
            categories = {int(r["category_id"]): str(r["category_id"]) for r in results}
        detections = importers.detections_from_coco(results, categories, image_names=names,
                                                     min_score=args.min_score)
        options: dict[str, Any] = {}
        if args.holdout_every:
            options["holdout_every"] = args.holdout_every
        if args.name:
            options["name"] = args.name
        doc = importers.recording_document(camera, poses, detections, convention=convention,
                                           **options)
    except (ValueError, KeyError, TypeError) as exc:
        raise CliError(f"cannot import: {exc}") from exc
    matched = sum(1 for f in doc["frames"] if f["detections"])
    text = json.dumps(doc)
    if args.output == "-":
        print(text)
    else:
        Path(args.output).write_text(text + "\n", encoding="utf-8")
    print(f"{len(doc['frames'])} frames ({matched} with detections, "
          f"{sum(len(v) for v in detections.values())} detections) -> {args.output}",
          file=sys.stderr)
    return 0
