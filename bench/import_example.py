"""The COLMAP + COCO import example of docs/map_building.md ("Importing your data"): tiny files in
the formats those tools write, made from a simulated walk through the Chess room, so that the
documented ``quadloc import-recording --colmap ... --coco-results ...`` block runs as written.

Usage::

    python -m bench.import_example [--out docs/examples/import] [--seed 3] [--frames 120]

Writes, under ``--out``:

* ``colmap/cameras.txt`` (one ``PINHOLE`` camera) and ``colmap/images.txt`` (one image per
  frame, ``IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME`` = the app pose's
  ``camera_from_world``, as COLMAP stores it, and an empty points line);
* ``coco_instances.json``: the COCO annotations file's ``images`` and ``categories`` (no
  annotations: the labels and image names are what the importer reads from it);
* ``coco_results.json.gz``: COCO detection results, one per simulated detection (wrong labels
  and spurious detections included), each with a ``score`` and a ``bbox`` (the ellipse's
  bounding box, clipped to the image) and, in turn, nothing more (a box detector), a polygon
  ``segmentation`` (24 vertices on the ellipse), or an RLE mask (the ellipse rasterised, COCO's
  compressed string form).

The frames are those of ``bench.map_building.simulated_recording`` (the detector, drifting app
poses and walk of the shipped ``room_recording.json.gz``, the walk resampled to ``--frames``
poses). The
scores are drawn uniformly in [0.5, 1] (they set the importer's sigma, nothing else).
"""

from __future__ import annotations

import argparse
import gzip
import json
from pathlib import Path
from typing import Any

import numpy as np

from bench.map_building import simulated_recording
from quadloc.factors.rotations import invert_pose, quaternion_wxyz_from_rotation

#: Vertices of a polygon segmentation.
POLYGON_VERTICES = 24


def _ellipse_points(e: dict[str, float], n: int) -> np.ndarray:
    """(n, 2) points on the ellipse ``{cx, cy, a, b, angle}`` (px)."""
    t = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    c, s = np.cos(e["angle"]), np.sin(e["angle"])
    x, y = e["a"] * np.cos(t), e["b"] * np.sin(t)
    return np.column_stack([e["cx"] + c * x - s * y, e["cy"] + s * x + c * y])


def _mask(e: dict[str, float], width: int, height: int) -> np.ndarray:
    """The ellipse's pixels (pixel centres at +0.5) inside the image, bool (height, width)."""
    yy, xx = np.mgrid[0:height, 0:width] + 0.5
    c, s = np.cos(e["angle"]), np.sin(e["angle"])
    u = (xx - e["cx"]) * c + (yy - e["cy"]) * s
    v = -(xx - e["cx"]) * s + (yy - e["cy"]) * c
    return np.asarray((u / e["a"]) ** 2 + (v / e["b"]) ** 2 <= 1.0)


def rle_counts(mask: np.ndarray) -> list[int]:
    """The runs of a bool mask (h, w) over its pixels in column-major order, starting with 0s
    (a leading 0 when the first pixel is set): COCO's uncompressed RLE counts."""
    flat = np.asarray(mask, dtype=bool).T.ravel()
    change = np.flatnonzero(np.diff(flat.astype(np.int8))) + 1
    counts: list[int] = np.diff(np.concatenate([[0], change, [flat.size]])).tolist()
    return [0, *counts] if flat.size and flat[0] else counts


def encode_rle_counts(counts: list[int]) -> str:
    """COCO's compressed RLE string of ``counts``, as pycocotools ``rleToString`` writes it
    (each count after the second as the difference to the count two before, 5-bit groups with
    a continuation bit, from ``'0'``)."""
    chars = []
    for i, c in enumerate(counts):
        x = c - counts[i - 2] if i > 2 else c
        more = True
        while more:
            ch = x & 0x1F
            x >>= 5
            more = not ((x == 0 and not ch & 0x10) or (x == -1 and ch & 0x10))
            chars.append(chr(48 + (ch | (0x20 if more else 0))))
    return "".join(chars)


def encode_coco_rle(mask: np.ndarray) -> dict[str, Any]:
    """COCO's compressed RLE of a bool mask (h, w) (:func:`rle_counts`,
    :func:`encode_rle_counts`). The inverse of :func:`quadloc_sdk.importers.decode_coco_rle`."""
    return {"size": [int(mask.shape[0]), int(mask.shape[1])],
            "counts": encode_rle_counts(rle_counts(mask))}


def example(seed: int, frames: int) -> dict[str, Any]:
    """The files' contents: ``{"cameras.txt", "images.txt", "instances", "results"}``."""
    doc, _, app, _ = simulated_recording(seed, frames)
    cam = doc["camera"]
    w, h = int(cam["width"]), int(cam["height"])
    rng = np.random.default_rng([seed, 30])
    labels = sorted({d["label"] for f in doc["frames"] for d in f["detections"]})
    category = {label: i + 1 for i, label in enumerate(labels)}
    images = ["# Image list with two lines of data per image:",
              "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME",
              "#   POINTS2D[] as (X, Y, POINT3D_ID)"]
    coco_images, results = [], []
    for i, f in enumerate(doc["frames"]):
        name = f"frame_{i:04d}.png"
        cfw = invert_pose(np.asarray(app[i], dtype=float))  # COLMAP stores camera_from_world
        q = quaternion_wxyz_from_rotation(cfw[:3, :3])
        images += [f"{i + 1} " + " ".join(f"{v:.9g}" for v in (*q, *cfw[:3, 3])) + f" 1 {name}",
                   ""]
        coco_images.append({"id": i + 1, "file_name": name, "width": w, "height": h})
        for k, d in enumerate(f["detections"]):
            e = d["ellipse"]
            pts = _ellipse_points(e, 4 * POLYGON_VERTICES)
            x0, y0 = np.clip(pts.min(axis=0), 0, [w, h])
            x1, y1 = np.clip(pts.max(axis=0), 0, [w, h])
            r: dict[str, Any] = {
                "image_id": i + 1, "category_id": category[d["label"]],
                "bbox": [round(float(v), 1) for v in (x0, y0, x1 - x0, y1 - y0)],
                "score": round(float(rng.uniform(0.5, 1.0)), 3)}
            kind = (i + k) % 3
            if kind == 1:
                poly = np.clip(_ellipse_points(e, POLYGON_VERTICES), 0, [w, h])
                r["segmentation"] = [[round(float(v), 1) for v in poly.ravel()]]
            elif kind == 2:
                mask = _mask(e, w, h)
                if not mask.any():
                    continue
                r["segmentation"] = encode_coco_rle(mask)
            if r["bbox"][2] > 0 and r["bbox"][3] > 0:
                results.append(r)
    return {
        "cameras.txt": "# Camera list with one line of data per camera:\n"
                       "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n"
                       f"1 PINHOLE {w} {h} {cam['fx']:.9g} {cam['fy']:.9g} {cam['cx']:.9g} "
                       f"{cam['cy']:.9g}\n",
        "images.txt": "\n".join(images) + "\n",
        "instances": {"images": coco_images,
                      "categories": [{"id": i, "name": label} for label, i in category.items()],
                      "annotations": []},
        "results": results}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("docs/examples/import"))
    ap.add_argument("--seed", type=int, default=3)
    ap.add_argument("--frames", type=int, default=120)
    args = ap.parse_args(argv)
    files = example(args.seed, args.frames)
    (args.out / "colmap").mkdir(parents=True, exist_ok=True)
    (args.out / "colmap" / "cameras.txt").write_text(files["cameras.txt"])
    (args.out / "colmap" / "images.txt").write_text(files["images.txt"])
    (args.out / "coco_instances.json").write_text(json.dumps(files["instances"]) + "\n")
    (args.out / "coco_results.json.gz").write_bytes(gzip.compress(
        (json.dumps(files["results"], separators=(",", ":")) + "\n").encode(), mtime=0))
    print(json.dumps({"frames": args.frames, "seed": args.seed,
                      "detections": len(files["results"]), "out": str(args.out)}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
