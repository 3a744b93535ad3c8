"""``quadloc import-recording``: a COLMAP model and COCO results on disk -> a recording that the
server reads; bad input is exit status 2 naming the problem."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from quadloc.service.app.builds import recording_of
from quadloc.service.cli.main import main


def _write(tmp: Path) -> None:
    (tmp / "sparse").mkdir()
    (tmp / "sparse" / "cameras.txt").write_text("1 PINHOLE 640 480 500 500 320 240\n")
    # camera_from_world: identity rotation, t = (0, 0, 2): the camera centre is (0, 0, -2)
    (tmp / "sparse" / "images.txt").write_text(
        "1 1 0 0 0 0 0 2 1 a.jpg\n\n2 1 0 0 0 0.5 0 2 1 b.jpg\n\n")
    (tmp / "ann.json").write_text(json.dumps({
        "categories": [{"id": 1, "name": "TV"}],
        "images": [{"id": 10, "file_name": "a.jpg"}, {"id": 11, "file_name": "b.jpg"}]}))
    (tmp / "det.json").write_text(json.dumps([
        {"image_id": 10, "category_id": 1, "score": 0.8, "bbox": [100, 100, 50, 30]},
        {"image_id": 11, "category_id": 1, "score": 0.2, "bbox": [120, 100, 50, 30]}]))


def test_import_recording_from_colmap_and_coco(tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    _write(tmp_path)
    out = tmp_path / "rec.json"
    assert main(["import-recording", "--colmap", str(tmp_path / "sparse"), "--coco-results",
                 str(tmp_path / "det.json"), "--coco-annotations", str(tmp_path / "ann.json"),
                 "--min-score", "0.5", "--holdout-every", "2", "-o", str(out)]) == 0
    assert "2 frames (1 with detections, 1 detections)" in capsys.readouterr().err
    doc = json.loads(out.read_text())
    assert [f["frame_id"] for f in doc["frames"]] == ["a.jpg", "b.jpg"]
    rec = recording_of(doc)
    assert len(rec.frames) == 1  # b.jpg held out
    np.testing.assert_allclose(rec.frames[0].world_from_camera[:3, 3], [0, 0, -2], atol=1e-12)
    assert rec.camera.fx == 500.0 and len(rec.observations) == 1


def test_import_recording_bad_input_names_the_problem(tmp_path: Path,
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    _write(tmp_path)
    (tmp_path / "sparse" / "cameras.txt").write_text("1 OPENCV 640 480 1 1 1 1 0 0 0 0\n")
    assert main(["import-recording", "--colmap", str(tmp_path / "sparse"), "--coco-results",
                 str(tmp_path / "det.json"), "-o", str(tmp_path / "x.json")]) == 2
    assert "OPENCV" in capsys.readouterr().err
    assert not (tmp_path / "x.json").exists()
