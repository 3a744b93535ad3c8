"""A map's own calibration (``quadloc.service.localization.map_calibration``) and its use by
``localize``: the covariance follows the map's scale exactly, a calibration fitted for another
key changes nothing, its default ``min_confidence`` applies; the calibration error is the
binned formula; a fit on frames of a known detector reports NEES before / after."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from quadloc.maps.compiled import compile_map
from quadloc.service.localization.calibration_fit import CalibrationConstants
from quadloc.service.localization.map_calibration import (
    FOLDS,
    ReferenceFrame,
    calibration_error,
    calibration_error_floor,
    calibration_error_sd,
    fit_map_calibration,
    folds,
)
from quadloc.service.localization.pipeline import localize
from quadloc.service.localization.types import LocalizationOptions
from tests.support.reference_data import load_chess_map, load_chess_world_from_camera
from tests.support.simulate import SimulationConfig, simulate_frame


def test_calibration_error_is_the_binned_gap() -> None:
    p = np.array([0.05, 0.15, 0.15, 0.95, 0.95, 0.95, 0.95])
    y = np.array([0, 1, 0, 1, 1, 1, 0])
    # bins: [0, .1): conf .05, rate 0 -> 1/7 * .05; [.1, .2): .15 vs .5 -> 2/7 * .35;
    # [.9, 1]: .95 vs .75 -> 4/7 * .2
    assert calibration_error(p, y) == pytest.approx((0.05 + 2 * 0.35 + 4 * 0.2) / 7)
    assert calibration_error(np.array([1.0, 0.0]), np.array([1, 0])) == 0.0
    assert math.isnan(calibration_error(np.array([]), np.array([])))


def test_calibration_error_floor_is_the_sampling_error_of_a_calibrated_model() -> None:
    """Tolerance 0.006 (200 draws, sd of the mean about 0.002)."""
    assert calibration_error_floor(np.array([0.0, 1.0, 1.0])) == 0.0
    # one bin, n = 100 at p = 0.5: E|mean(y) - 0.5| = sqrt(0.25 / n) sqrt(2 / pi) (normal)
    assert calibration_error_floor(np.full(100, 0.5)) == pytest.approx(
        math.sqrt(0.25 / 100) * math.sqrt(2 / math.pi), abs=0.006)
    assert math.isnan(calibration_error_floor(np.array([])))


def test_calibration_error_sd_grows_with_correlated_outcomes() -> None:
    """The same outcomes in runs of 25 (correlated, as along a drifting walk) and shuffled
    (independent): the block bootstrap gives the runs a larger spread."""
    assert calibration_error_sd(np.ones(100), np.ones(100)) == 0.0
    assert math.isnan(calibration_error_sd(np.full(30, 0.5), np.ones(30)))
    rng = np.random.default_rng(1)
    runs = np.repeat(rng.random(40) < 0.5, 25).astype(float)
    p = np.full(runs.size, 0.5)
    shuffled = rng.permutation(runs)
    assert calibration_error_sd(p, runs) > 2 * calibration_error_sd(p, shuffled)


def test_folds_are_chunks_dealt_in_turn_and_even() -> None:
    f = folds(1000)  # chunks of 25: 40 chunks, 8 per fold
    assert list(f[:26]) == [0] * 25 + [1] and np.bincount(f).tolist() == [200] * FOLDS
    g = folds(40)  # short: chunks of 4, two per fold
    assert list(g[:8]) == [0] * 4 + [1] * 4 and np.bincount(g).tolist() == [8] * FOLDS
    assert set(folds(7).tolist()) <= set(range(FOLDS))


@pytest.fixture(scope="module")
def chess() -> tuple:
    cm = compile_map(load_chess_map())
    camera, poses, _ = load_chess_world_from_camera()
    return cm, camera, poses


def _with(constants: CalibrationConstants, key: str, **changes: object) -> CalibrationConstants:
    return dataclasses.replace(constants, provenance={"fitted_keys": [key]}, **changes)


def test_localize_uses_the_maps_calibration_for_its_key_only(chess: tuple) -> None:
    cm, camera, poses = chess
    frame = simulate_frame(cm, camera, poses[10], np.random.default_rng(3))
    options = LocalizationOptions(metric="level_set", min_confidence=0.0, time_budget_ms=None)
    base = localize(frame.detections, cm, camera, options)
    assert base.localized and base.covariance is not None
    shipped = CalibrationConstants.shipped()
    key = "level_set"  # every simulated detection has a sigma
    doubled = _with(shipped, key, covariance_scale={
        **shipped.covariance_scale, key: 2 * shipped.covariance_scale[key]})
    r = localize(frame.detections, cm, camera, options, calibration=doubled)
    np.testing.assert_allclose(r.world_from_camera, base.world_from_camera, atol=0)
    np.testing.assert_allclose(r.covariance, 2 * np.asarray(base.covariance), rtol=1e-9)
    assert r.evidence["cov_scale"] == pytest.approx(2 * base.evidence["cov_scale"], rel=1e-12)
    # fitted for another key: the shipped constants apply
    other = dataclasses.replace(doubled, provenance={"fitted_keys": ["bbox"]})
    r = localize(frame.detections, cm, camera, options, calibration=other)
    np.testing.assert_array_equal(r.covariance, base.covariance)
    assert r.confidence == base.confidence
    # the calibration's default min_confidence applies when the request sets none
    strict = _with(shipped, key, min_confidence=0.999999)
    r = localize(frame.detections, cm, camera,
                 dataclasses.replace(options, min_confidence=None), calibration=strict)
    assert not r.localized and r.reason == "low_confidence"


@pytest.mark.slow
def test_fit_on_a_noisier_detector_brings_nees_into_band(chess: tuple) -> None:
    """Frames at the real poses (reference = truth), a detector twice as noisy as the default:
    the map's calibration brings the report frames' mean NEES into [3, 12] (a loose band for
    about 25 NEES frames) and is stored for the key solved only."""
    cm, camera, poses = chess
    cfg = SimulationConfig(center_noise=0.08, axis_log_noise=0.12,
                           angle_noise_rad=math.radians(8.0))
    rng = np.random.default_rng(7)
    frames = [ReferenceFrame(str(i), poses[i], simulate_frame(cm, camera, poses[i], rng,
                                                              cfg).detections)
              for i in range(0, len(poses), 1)][:90]
    cal = fit_map_calibration(frames, cm, camera)
    assert cal.before.mean_nees is not None and cal.after.mean_nees is not None
    assert 3 <= cal.after.mean_nees <= 12, cal
    assert cal.constants.provenance["fitted_keys"] == ["level_set"] and cal.key == "level_set"
    assert cal.before.frames == cal.after.frames == 90 == cal.fit_frames
    # no decision sets among the user's frames: the ambiguity ratio and the default
    # min_confidence are the shipped ones
    shipped = CalibrationConstants.shipped()
    assert cal.constants.min_confidence == shipped.min_confidence
    assert cal.constants.ambiguity_chi2_ratio == shipped.ambiguity_chi2_ratio
