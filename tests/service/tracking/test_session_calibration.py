"""Tracking sessions use a map version's own calibration (``quadloc calibrate``) as localize
does: for the calibration key it was fitted for, every answer's covariance is the shipped one
times ``(k' f') / (k f)`` (the map's covariance scale and s^2 floor over the shipped ones),
its confidence the tolerance probability of that covariance; the poses do not change; a
calibration fitted for another key, or none, changes nothing. Through the application too:
a session on a map version with a stored calibration uses it."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
from fastapi.testclient import TestClient

from quadloc.service.app.calibrations import calibration_document
from quadloc.service.localization import calibration as shipped_module
from quadloc.service.localization.calibration_fit import CalibrationConstants
from quadloc.service.schemas.calibration import CalibrationOut, CalibrationQualityOut
from quadloc.service.tracking.session import SessionOptions, TrackingSession
from tests.conftest import make_test_app
from tests.service.tracking.test_session_bounds import _session
from tests.support.walks import ChessWalk, chess_walk, frame_json

KEY = "level_set"  # SessionOptions' metric, every simulated detection with a sigma
#: The map's calibration below: k 10 and the floor 100 times the shipped ones.
K_FACTOR, F_FACTOR = 10.0, 100.0


@pytest.fixture(scope="module")
def walk() -> ChessWalk:
    return chess_walk(40, seed=30)


def _calibration(key: str) -> CalibrationConstants:
    s = CalibrationConstants.shipped()
    return dataclasses.replace(
        s, provenance={"fitted_keys": [key]},
        covariance_scale={**s.covariance_scale, KEY: K_FACTOR * s.covariance_scale[KEY]},
        s2_floor={**s.s2_floor, KEY: F_FACTOR * s.s2_floor[KEY]})


def _answers(walk: ChessWalk, calibration: CalibrationConstants | None) -> list:
    s = TrackingSession(walk.compiled, walk.camera, SessionOptions(), calibration)
    return [s.add_frame(f) for f in walk.frames]


def _tolerance_probability_mc(cov: np.ndarray, rng: np.random.Generator, n: int = 400_000
                              ) -> float:
    """P(|rotation| <= 5 deg and |position| <= 10 cm) by sampling the documented model: each
    block an isotropic 3-D Gaussian of variance trace / 3, the blocks independent."""
    out = 1.0
    for block, tol in ((slice(0, 3), math.radians(5.0)), (slice(3, 6), 0.10)):
        sd = math.sqrt(np.trace(cov[block, block]) / 3.0)
        out *= float(np.mean(np.linalg.norm(rng.normal(0.0, sd, (n, 3)), axis=1) <= tol))
    return out


def test_a_session_scales_its_covariance_by_the_maps_calibration(walk: ChessWalk) -> None:
    """Tolerances: poses and states identical (the smoother is unchanged); covariances 1e-12
    relative; confidence within 0.005 of a 400,000-sample Monte Carlo (sampling sd <= 8e-4)."""
    default = _answers(walk, None)
    calibrated = _answers(walk, _calibration(KEY))
    other_key = _answers(walk, _calibration("bbox"))  # fitted for another key
    ratio = K_FACTOR * F_FACTOR  # (k' f') / (k f), from the constants themselves
    assert shipped_module.COVARIANCE_SCALE[KEY] > 0 and shipped_module.S2_FLOOR[KEY] > 0
    tracked = [i for i, r in enumerate(default) if r.covariance is not None]
    assert len(tracked) >= 10
    rng = np.random.default_rng(0)
    for d, c, o in zip(default, calibrated, other_key, strict=True):
        assert (c.state, c.reason) == (d.state, d.reason) == (o.state, o.reason)
        if d.world_from_camera is None:
            assert c.world_from_camera is None and c.covariance is None
            continue
        assert np.array_equal(c.world_from_camera, d.world_from_camera)
        np.testing.assert_allclose(c.covariance, ratio * d.covariance, rtol=1e-12)
        np.testing.assert_allclose(c.world_from_odom_covariance,
                                   ratio * d.world_from_odom_covariance, rtol=1e-12)
        assert np.array_equal(o.covariance, d.covariance) and o.confidence == d.confidence
    for i in tracked[::4]:
        d, c = default[i], calibrated[i]
        # confidence = P(the committed place) x P(within tolerance there): the committed
        # place is the candidate whose pose is the answer's
        place = next(p.probability for p in d.candidates
                     if np.array_equal(p.world_from_camera, d.world_from_camera))
        assert d.confidence == pytest.approx(
            place * _tolerance_probability_mc(d.covariance, rng), abs=0.005)
        assert c.confidence == pytest.approx(
            place * _tolerance_probability_mc(ratio * d.covariance, rng), abs=0.005)
    assert any(c.confidence < d.confidence - 0.01 for d, c in zip(default, calibrated,
                                                                   strict=True))


def test_api_a_session_on_a_calibrated_map_version_uses_its_calibration(
        tmp_path: Path, walk: ChessWalk) -> None:
    frames = [frame_json(f) for f in walk.frames[:30]]
    quality = CalibrationQualityOut(frames=0, localized=0, nees_frames=0, mean_nees=None,
                                    calibration_error=None, mean_confidence=None,
                                    success_rate=None)
    cal = _calibration(KEY)
    # the two sessions must give the same answers: no frame may hit its budget (1 s of CPU,
    # 2 s of wall clock by default) on a loaded machine (a frame past it has no pose)
    with TestClient(make_test_app(tmp_path, session_frame_budget_ms=60_000.0)) as c:
        before = c.post(f"/v1/sessions/{_session(c, walk)}/frames",
                        json={"frames": frames}).json()["results"]
        app = c.app.state.services  # type: ignore[attr-defined]
        version = app.store.get("chess").scene_map.version
        app.store.set_calibration("chess", version, calibration_document(cal, CalibrationOut(
            map_id="chess", map_version=version, key=KEY, fit_frames=0,
            covariance_scale=cal.covariance_scale[KEY],
            shipped_covariance_scale=shipped_module.COVARIANCE_SCALE[KEY],
            s2_floor=cal.s2_floor[KEY], min_confidence=cal.min_confidence,
            before=quality, after=quality)))
        after = c.post(f"/v1/sessions/{_session(c, walk)}/frames",
                       json={"frames": frames}).json()["results"]
    pairs = [(b, a) for b, a in zip(before, after, strict=True) if b["covariance"] is not None]
    assert pairs
    for b, a in pairs:
        assert a["covariance"] is not None, (a["reason"], a.get("timings_ms"))
        np.testing.assert_allclose(a["covariance"]["matrix"],
                                   K_FACTOR * F_FACTOR * np.asarray(b["covariance"]["matrix"]),
                                   rtol=1e-9)
