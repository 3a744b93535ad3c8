"""The COLMAP + COCO files of docs/examples/import/ (docs/map_building.md, "Importing your
data") are what ``python -m bench.import_example`` writes, in the formats those tools write:
the compressed RLE masks decode (``quadloc_sdk.importers.decode_coco_rle``) to the rasterised
ellipses they encode, and the imported recording has the simulated walk's poses and, for every
polygon and mask, the simulated ellipse back (moment matching)."""

from __future__ import annotations

import gzip
import json
from pathlib import Path

import numpy as np
import pytest

from bench.import_example import _mask, encode_coco_rle, example
from bench.map_building import simulated_recording
from quadloc_sdk import importers

DIR = Path(__file__).resolve().parents[2] / "docs" / "examples" / "import"


def _r(e: dict) -> float:
    return float(max(e["a"], e["b"]))


@pytest.fixture(scope="module")
def files() -> dict:
    return example(3, 120)


def test_the_shipped_files_are_the_scripts_output(files: dict) -> None:
    assert (DIR / "colmap" / "cameras.txt").read_text() == files["cameras.txt"]
    assert (DIR / "colmap" / "images.txt").read_text() == files["images.txt"]
    assert json.loads((DIR / "coco_instances.json").read_text()) == files["instances"]
    assert json.loads(gzip.decompress((DIR / "coco_results.json.gz").read_bytes())) \
        == files["results"]
    kinds = {"box" if "segmentation" not in r else
             "mask" if isinstance(r["segmentation"], dict) else "polygon"
             for r in files["results"]}
    assert kinds == {"box", "polygon", "mask"}


def test_rle_round_trip() -> None:
    rng = np.random.default_rng(0)
    for shape in ((5, 7), (48, 64), (1, 1)):
        for p in (0.0, 0.3, 1.0):
            mask = rng.random(shape) < p
            assert np.array_equal(importers.decode_coco_rle(encode_coco_rle(mask)), mask)
    e = {"cx": 30.2, "cy": 20.7, "a": 12.0, "b": 5.0, "angle": 0.4}
    mask = _mask(e, 64, 48)
    assert np.array_equal(importers.decode_coco_rle(encode_coco_rle(mask)), mask)


def test_the_import_gives_back_the_walk_and_the_ellipses(files: dict) -> None:
    """Tolerances: poses 1e-6 (9 significant digits written); a polygon's or a mask's
    moment-matched ellipse within 1.5 px of centre and 8 % of each semi-axis of the simulated
    one (24 vertices; pixels), for detections inside the image."""
    doc, _, app, _ = simulated_recording(3, 120, holdout_every=3)
    poses = importers.read_colmap_images(files["images.txt"])
    assert importers.read_colmap_camera(files["cameras.txt"]) == doc["camera"]
    for i, T in enumerate(app):
        np.testing.assert_allclose(poses[f"frame_{i:04d}.png"], T, atol=1e-6)
    categories = {c["id"]: c["name"] for c in files["instances"]["categories"]}
    names = {im["id"]: im["file_name"] for im in files["instances"]["images"]}
    w, h = doc["camera"]["width"], doc["camera"]["height"]
    checked = 0
    for r in files["results"]:
        if "segmentation" not in r:
            continue
        i = r["image_id"] - 1
        (det,) = importers.detections_from_coco([r], categories, image_names=names)[names[i + 1]]
        sims = [d["ellipse"] for d in doc["frames"][i]["detections"]
                if d["label"] == det["label"]]
        inside = [e for e in sims if e["cx"] - _r(e) > 1 and e["cy"] - _r(e) > 1
                  and e["cx"] + _r(e) < w - 1 and e["cy"] + _r(e) < h - 1
                  and min(e["a"], e["b"]) > 4]
        got = det["ellipse"]
        near = [e for e in inside if abs(e["cx"] - got["cx"]) < 1.5
                and abs(e["cy"] - got["cy"]) < 1.5]
        if not near:
            continue
        e = near[0]
        # semi-axes as a set: the simulator's a (along angle) may be the shorter one
        assert sorted((got["a"], got["b"])) == pytest.approx(sorted((e["a"], e["b"])),
                                                             rel=0.08)
        checked += 1
    assert checked >= 100
