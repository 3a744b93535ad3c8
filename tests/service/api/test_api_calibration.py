"""``POST`` / ``GET /v1/maps/{map_id}/calibration``: a map built from a recording with
``holdout_every`` is calibrated from its held-out frames; the calibration is stored with the
version and localize uses it; refusals name their field and store nothing."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from fastapi.testclient import TestClient

from tests.conftest import make_test_app
from tests.service.api.test_api_build import _recording
from tests.support.helpers import wait_for_job


def _noisy_recording(n: int, seed: int = 5) -> dict[str, Any]:
    rec, _ = _recording(n)
    rng = np.random.default_rng(seed)
    for f in rec["frames"]:
        for d in f["detections"]:
            e = d["ellipse"]
            e["cx"] += float(rng.normal(0, 1.5))
            e["cy"] += float(rng.normal(0, 1.5))
            e["a"] *= float(np.exp(rng.normal(0, 0.03)))
            e["b"] *= float(np.exp(rng.normal(0, 0.03)))
            d["sigma"] = 0.05
    return rec


@pytest.mark.slow
def test_calibrate_store_and_use(tmp_path: Path) -> None:
    rec = _noisy_recording(120)
    rec["holdout_every"] = 2
    with TestClient(make_test_app(tmp_path)) as client:
        assert client.post("/v1/maps/room/calibration", json=rec).status_code == 404
        built = client.post("/v1/maps:build", params={"map_id": "room"}, json=rec)
        job = wait_for_job(client, built.headers["Location"])
        assert job["status"] == "succeeded", job
        r = client.get("/v1/maps/room/calibration")
        assert r.status_code == 404
        # without held-out frames there is nothing the map did not see
        r = client.post("/v1/maps/room/calibration", json={**rec, "holdout_every": None})
        assert r.status_code == 422 and r.json()["errors"][0]["field"] == "holdout_every"
        # a frame to localize: a held-out one
        frame = rec["frames"][1]
        body = {"camera": rec["camera"], "detections": frame["detections"],
                "options": {"min_confidence": 0}}
        before = client.post("/v1/maps/room/localize", json=body).json()
        r = client.post("/v1/maps/room/calibration", json=rec)
        assert r.status_code == 200, r.text
        out = r.json()
        assert out["map_version"] == 1 and out["key"] == "level_set"
        assert out["fit_frames"] == 60 == out["before"]["frames"] == out["after"]["frames"]
        assert out["after"]["mean_nees"] is not None
        assert client.get("/v1/maps/room/calibration").json() == out
        after = client.post("/v1/maps/room/localize", json=body).json()
        assert before["localized"] and after["localized"]
        np.testing.assert_allclose(after["world_from_camera"]["matrix"],
                                   before["world_from_camera"]["matrix"], atol=1e-9)
        ratio = (np.asarray(after["covariance"]["matrix"])
                 / np.asarray(before["covariance"]["matrix"]))
        # one scalar factor: k and the s^2 floor of the map's calibration
        assert np.allclose(ratio, ratio[0, 0], rtol=1e-6) and ratio[0, 0] != pytest.approx(1)
