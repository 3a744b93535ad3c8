"""The calibration fit (``quadloc.service.localization.calibration_fit``): the shipped constants
are the refit of the committed tuning records, the generated module names its data and
command, and the fit's parts recover what synthetic records were made with."""

from __future__ import annotations

import math
import os
import re
from pathlib import Path

import numpy as np
import pytest

from quadloc.service.localization import calibration
from quadloc.service.localization.calibration_fit import (
    FEATURES,
    CalibrationConstants,
    CalibrationFitError,
    FitSettings,
    SolveRecord,
    calibration_source,
    choose_ambiguity_and_threshold,
    choose_place_threshold,
    decide,
    fit_calibration,
    fit_confidence_models,
    fit_covariance_scale,
    fit_file,
    fit_logistic,
    fit_s2_floor,
    n_inliers,
    read_records,
    refeature,
    sha256_file,
    write_records,
)
from quadloc.service.localization.confidence import (
    answer_chi2_ratio,
    confidence_probability,
    gaussian_tolerance_probability,
)
from tests.support.buildings import REPORT_SEEDS as BUILDING_REPORT_SEEDS

REPO_ROOT = Path(__file__).resolve().parents[3]
RECORDS = REPO_ROOT / "bench" / "data" / "calibration_records.json.gz"
#: The building frames' records (``bench.building --calibration-records``): the ``"places"``
#: confidence model.
BUILDING_RECORDS = REPO_ROOT / "bench" / "data" / "building_calibration_records.json.gz"
#: The generator rounds every fitted number to 6 decimals: a refit on another machine (other
#: BLAS, other summation order) may move the last digit, never more.
ABS_TOL = 2e-6


@pytest.fixture(scope="module")
def refit() -> CalibrationConstants:
    """The refit, run from the checkout's root as the documented command is."""
    cwd = os.getcwd()
    os.chdir(REPO_ROOT)
    try:
        return fit_file(RECORDS, extra_records=[BUILDING_RECORDS.relative_to(REPO_ROOT)])
    finally:
        os.chdir(cwd)


def test_the_shipped_constants_are_the_refit_of_the_committed_records(refit):
    """``python -m quadloc.service.localization.calibration_fit
    bench/data/calibration_records.json.gz bench/data/building_calibration_records.json.gz``
    reproduces calibration.py: every fitted number
    within 2e-6 (its 6 decimals), the ambiguity ratio and the threshold exactly, and the
    provenance."""
    shipped = CalibrationConstants.shipped()
    assert shipped.differences(refit, abs_tol=ABS_TOL) == []
    assert refit.min_confidence == shipped.min_confidence
    assert refit.ambiguity_chi2_ratio == shipped.ambiguity_chi2_ratio
    assert refit.provenance == calibration.PROVENANCE


def test_the_generated_module_names_its_data_and_command():
    """The header and PROVENANCE name the committed records (their sha256: the file is the
    one fitted), the refit command and the command that made the records; no machine-local
    path."""
    prov = calibration.PROVENANCE
    assert prov["records"] == "bench/data/calibration_records.json.gz"
    assert prov["records_sha256"] == sha256_file(RECORDS)
    assert prov["command"] == ("python -m quadloc.service.localization.calibration_fit "
                               "bench/data/calibration_records.json.gz "
                               "bench/data/building_calibration_records.json.gz")
    (extra,) = prov["extra_records"]
    assert extra["records"] == "bench/data/building_calibration_records.json.gz"
    assert extra["records_sha256"] == sha256_file(BUILDING_RECORDS)
    assert extra["records_command"].startswith("python -m bench.building --calibration-records")
    assert not set(extra["tuning_seeds"]) & set(BUILDING_REPORT_SEEDS)
    assert prov["records_command"].startswith("python -m bench.trust --fit")
    _, made = read_records(RECORDS)
    assert made["command"] == prov["records_command"] and made["commit"] == prov["records_commit"]
    assert re.fullmatch(r"[0-9a-f]{7}", made["commit"]), made["commit"]
    assert sorted(prov["tuning_seeds"]) == sorted(made["tuning_seeds"])
    # tuning seeds never overlap the report's (bench.trust defaults)
    assert not set(prov["tuning_seeds"]) & {300, 301, 302, 303, 304, 306}
    text = (REPO_ROOT / "service" / "localization" / "calibration.py").read_text()
    assert "bench/data/calibration_records.json.gz" in text.split('"""')[1]
    assert not re.search(r"(?<![\w.])/(tmp|work|root|home)/", text)


def test_generated_source_round_trips(refit):
    """``calibration_source`` writes a module whose constants are the object's."""
    namespace: dict[str, object] = {}
    exec(compile(calibration_source(refit), "calibration.py", "exec"), namespace)

    class Module:
        pass

    module = Module()
    module.__dict__.update(namespace)
    back = CalibrationConstants.from_module(module)  # type: ignore[arg-type]
    assert back == refit


def test_record_files_round_trip_nan_and_inf(tmp_path):
    rec = _record(localized=False, pos=math.inf, s2=math.nan, nees=math.nan, reason="ambiguous",
                  decision_set="2 default")
    path = tmp_path / "r.json.gz"
    write_records(path, [rec, _record()], {"command": "x"})
    (back, prov) = read_records(path)
    assert prov == {"command": "x"}
    assert back[1] == _record()
    assert back[0].position_error_m == math.inf and math.isnan(back[0].s2)
    assert back[0].reason == "ambiguous" and back[0].decision_set == "2 default"
    write_records(tmp_path / "again.json.gz", [rec, _record()], {"command": "x"})
    assert sha256_file(path) == sha256_file(tmp_path / "again.json.gz")  # no timestamp
    (tmp_path / "bad.json.gz").write_bytes(b"not gzip")
    with pytest.raises(CalibrationFitError):
        read_records(tmp_path / "bad.json.gz")


# ------------------------------------------------------------------ the parts, on synthetic records


def _record(*, key: str = "level_set", group: str = "default", localized: bool = True,
            pos: float = 0.05, rot: float = 1.0, s2: float = 2.0, n: int = 5,
            cov_scale: float = 1.0, nees: float = 6.0, tr_rot: float = 1e-4, tr_pos: float = 1e-3,
            features: dict[str, float] | None = None, reason: str | None = None,
            decision_set: str = "") -> SolveRecord:
    return SolveRecord(key=key, group=group, localized=localized, reason=reason,
                       position_error_m=pos, rotation_error_deg=rot,
                       features=features or {f: 0.0 for f in FEATURES}, s2=s2, n_refined=n,
                       cov_scale=cov_scale, nees=nees, cov_trace_rotation_rad2=tr_rot,
                       cov_trace_position_m2=tr_pos, decision_set=decision_set)


def test_s2_floor_is_the_quantile_of_the_localized_records():
    recs = [_record(s2=float(v)) for v in range(1, 11)] + [_record(s2=1e6, localized=False),
                                                           _record(s2=math.nan)]
    assert fit_s2_floor(recs, 0.9) == pytest.approx(np.quantile(range(1, 11), 0.9), rel=1e-12)
    assert fit_s2_floor([_record(localized=False)], 0.9) is None


def test_covariance_scale_centres_the_nees_cells_on_six():
    """Records whose NEES at k = 1 is 3 in one group and 12 in the other (at every operating
    point): k = sqrt(3 x 12) / 6 = 1, and with NEES doubled k doubles. A cell needs 5
    records; with none the scale is undefined."""
    floor = 1.0
    recs = []
    for group, nees1 in (("a", 3.0), ("b", 12.0)):
        for pos in (0.01, 0.02, 0.03, 0.04, 0.045):
            r = _record(group=group, pos=pos, s2=4.0, n=5)
            factor = max(r.s2, floor) * (9.0 / 7.0)  # student_t_factor(5) = 9 / 7
            recs.append(_record(group=group, pos=pos, s2=4.0, n=5, cov_scale=2.5,
                                nees=nees1 * factor / 2.5))
    assert fit_covariance_scale(recs, floor) == pytest.approx(1.0, rel=1e-12)
    doubled = [_record(group=r.group, pos=r.position_error_m, s2=4.0, n=5, cov_scale=2.5,
                       nees=2 * r.nees) for r in recs]
    assert fit_covariance_scale(doubled, floor) == pytest.approx(2.0, rel=1e-12)
    assert fit_covariance_scale(recs[:4], floor) is None


def test_refeature_rescales_the_covariance_and_its_features():
    r = _record(s2=0.5, n=5, cov_scale=2.0, nees=8.0, tr_rot=3e-4, tr_pos=3e-3)
    new = refeature(r, {"level_set": 3.0}, {"level_set": 1.0})
    ratio = 3.0 * 1.0 * (9.0 / 7.0) / 2.0  # k * max(s2, f) * t(5) / old scale
    assert new.cov_scale == pytest.approx(2.0 * ratio, rel=1e-12)
    assert new.nees == pytest.approx(8.0 / ratio, rel=1e-12)
    assert new.features["log_s2"] == 0.0  # s2 below the floor: no excess
    p = gaussian_tolerance_probability(np.diag([1e-4 * ratio] * 3 + [1e-3 * ratio] * 3))
    assert new.features["logit_gauss"] == pytest.approx(math.log(p / (1 - p)), rel=1e-9)
    assert refeature(r, {}, {}) is r  # no constants for the key: unchanged


def test_logistic_fit_recovers_known_coefficients():
    rng = np.random.default_rng(0)
    X = rng.normal(size=(20_000, 2))
    w_true = np.array([-0.5, 1.5, -2.0])
    y = (rng.random(20_000) < 1 / (1 + np.exp(-(w_true[0] + X @ w_true[1:])))).astype(float)
    np.testing.assert_allclose(fit_logistic(X, y, ridge=0.0), w_true, atol=0.08)


def test_threshold_is_the_smallest_meeting_the_false_accept_target():
    """Ten 'wrong' answers (1 m off) with confidence below ten 'good' ones: the threshold is
    the smallest grid value above every wrong one (margin: no false accept allowed in 100
    frames at 0.5 % x 100 = 0.5); an answer whose chi2 runner-up is within the ratio is
    ambiguous."""
    def rec(pos: float, z: float, chi2c: float = 4.0) -> SolveRecord:
        feats = {f: 0.0 for f in FEATURES}
        feats.update(mean_iou=z, chi2_competitor=chi2c, iou_competitor=0.0)
        return _record(pos=pos, features=feats, decision_set="2 default")

    models = {"refined": {"intercept": 0.0, "coef": {"mean_iou": 1.0}},
              "none": {"intercept": 0.0, "coef": {}}}
    sets = {"2 default": [rec(1.0, z) for z in np.linspace(-3, -1, 10)]
            + [rec(0.05, z) for z in np.linspace(0.5, 2, 10)] + [rec(0.05, 3.0)] * 80}
    ratio, t = choose_ambiguity_and_threshold(sets, models, FitSettings(
        chi2_ratio_grid=(2.0,), min_confidence_grid=tuple(k / 100 for k in range(61))))
    assert ratio == 2.0 and t == pytest.approx(0.27)  # sigmoid(-1) = 0.269 -> 0.27
    assert decide(rec(0.05, 2.0, chi2c=math.log(1.9)), 2.0, 0.0, models).reason == "ambiguous"
    assert decide(rec(0.05, 2.0), 2.0, 0.0, models).localized


def test_extra_record_files_are_fitted_with_the_first(tmp_path):
    """``fit_file(first, extra_records=[...])`` (``calibration_fit RECORDS EXTRA``) fits the
    records of every file together, and the provenance names each extra file with its sha256
    and its own provenance."""
    rng = np.random.default_rng(3)

    def batch(n: int, shift: float, group: str) -> list[SolveRecord]:
        out = []
        for _ in range(n):
            x = float(rng.normal(shift, 1.0))
            feats = {f: 0.0 for f in FEATURES} | {"mean_iou": x}
            ok = rng.random() < 1.0 / (1.0 + math.exp(-2.0 * x))
            out.append(_record(group=group, features=feats, pos=0.05 if ok else 1.0,
                               s2=float(rng.uniform(1.0, 3.0))))
        return out

    first, extra = batch(300, 0.0, "default"), batch(200, 1.0, "building")
    write_records(tmp_path / "a.json.gz", first, {"command": "make a", "commit": "abc1234",
                                                  "tuning_seeds": [1]})
    write_records(tmp_path / "b.json.gz", extra, {"command": "make b", "commit": "def5678",
                                                  "tuning_seeds": [5, 7]})
    base = CalibrationConstants.shipped()
    both = fit_file(tmp_path / "a.json.gz", base, extra_records=[tmp_path / "b.json.gz"])
    alone = fit_file(tmp_path / "a.json.gz", base)
    direct = fit_calibration([*first, *extra], base)
    assert both.confidence_models == direct.confidence_models
    assert both.confidence_models != alone.confidence_models
    (info,) = both.provenance["extra_records"]
    assert info["records"] == "b.json.gz" and info["records_command"] == "make b"
    assert info["records_sha256"] == sha256_file(tmp_path / "b.json.gz")
    assert info["tuning_seeds"] == [5, 7]
    assert both.provenance["command"].endswith("a.json.gz b.json.gz")
    assert "extra_records" not in alone.provenance


def test_place_search_answers_fit_their_own_recalibration_of_the_refined_model():
    """Records of a place search (``place_search`` = 1) whose successes follow
    ``sigmoid(1.5 + 0.8 z)``, ``z`` the refined model's log-odds, give the ``"places"`` model
    (1.5, 0.8) within sampling error, and leave the refined model as the one-room records
    alone fit it (the refined fit never sees them); ``confidence_probability`` applies it to
    those answers only."""
    rng = np.random.default_rng(11)

    def rec(x: float, ok: bool, place: bool) -> SolveRecord:
        feats = {f: 0.0 for f in FEATURES} | {"mean_iou": x, "place_search": float(place)}
        return _record(features=feats, pos=0.05 if ok else 1.0)

    one_room = []
    for x in rng.normal(0.0, 1.0, 3000):
        one_room.append(rec(float(x), bool(rng.random() < 1 / (1 + math.exp(-2.0 * x))), False))
    none = {"intercept": 0.0, "coef": {}}
    alone = fit_confidence_models(one_room, base={"none": none})
    assert "places" not in alone
    z_of = alone["refined"]["coef"]["mean_iou"]
    places = []
    for x in rng.normal(0.0, 1.5, 20_000):
        z = alone["refined"]["intercept"] + z_of * x
        places.append(rec(float(x), bool(rng.random() < 1 / (1 + math.exp(-(1.5 + 0.8 * z)))),
                          True))
    both = fit_confidence_models([*one_room, *places], base={"none": none})
    assert both["refined"] == alone["refined"]
    assert both["places"]["intercept"] == pytest.approx(1.5, abs=0.08)
    assert both["places"]["coef"]["refined_logit"] == pytest.approx(0.8, abs=0.05)
    x = 0.3
    z = alone["refined"]["intercept"] + z_of * x
    feats = {f: 0.0 for f in FEATURES} | {"mean_iou": x}
    a, b = both["places"]["intercept"], both["places"]["coef"]["refined_logit"]
    assert confidence_probability("level_set", feats | {"place_search": 1.0}, both) == \
        pytest.approx(1 / (1 + math.exp(-(a + b * z))), rel=1e-12)
    for f in (feats, feats | {"place_search": 0.0}, feats | {"place_search": math.nan}):
        assert confidence_probability("level_set", f, both) == \
            pytest.approx(1 / (1 + math.exp(-z)), rel=1e-12)
    # a base with a places model keeps it when no record comes from a place search
    assert fit_confidence_models(one_room, base=both)["places"] == both["places"]
    # a map's own calibration (places_model=False): every record fits the refined model
    pooled = fit_confidence_models([*one_room, *places], FitSettings(places_model=False),
                                   base=both)
    assert "places" not in pooled and pooled["refined"] != alone["refined"]


def test_place_threshold_is_chosen_on_place_search_records_alone():
    """Decision records of place-search answers (two sets, one per map size) choose
    ``MIN_CONFIDENCE_PLACES``: the smallest grid value keeping every set's false accepts
    within 0.5 % (no wrong answer accepted in 100 frames); the one-room threshold is chosen on
    the records without a place search, whatever the place records hold."""
    def rec(pos: float, z: float, place: bool, set_name: str) -> SolveRecord:
        feats = {f: 0.0 for f in FEATURES} | {"mean_iou": z, "chi2_competitor": 4.0,
                                               "iou_competitor": 0.0,
                                               "place_search": float(place)}
        return _record(pos=pos, features=feats, decision_set=set_name)

    models = {"refined": {"intercept": 0.0, "coef": {"mean_iou": 1.0}},
              "none": {"intercept": 0.0, "coef": {}}}
    small = [rec(1.0, -2.0, True, "b10")] + [rec(0.05, 3.0, True, "b10")] * 99
    large = [rec(1.0, 0.5, True, "b1000")] + [rec(0.05, 3.0, True, "b1000")] * 99
    settings = FitSettings(chi2_ratio_grid=(2.0,))
    # sigmoid(0.5) = 0.622: the large map's wrong answer sets the threshold
    assert choose_place_threshold({"b10": small, "b1000": large}, models, 2.0, settings) \
        == (2.0, pytest.approx(0.63))
    assert choose_place_threshold({"b10": small}, models, 2.0, settings) \
        == (2.0, pytest.approx(0.12))
    assert choose_place_threshold({}, models, 2.0, settings) is None
    one_room = [rec(1.0, -1.0, False, "2 default")] + [rec(0.05, 3.0, False, "2 default")] * 99
    # wrong places among good answers of the same evidence: the place threshold rises above
    # their probability, the one-room threshold stays where its own records put it
    large = [rec(1.0, 1.0, True, "b1000")] * 2 + [rec(0.05, 1.0, True, "b1000")] * 8 \
        + [rec(0.05, 3.0, True, "b1000")] * 90
    fitted = fit_calibration([*one_room, *small, *large], CalibrationConstants.shipped(),
                             settings)
    ratio, t = choose_ambiguity_and_threshold({"2 default": one_room},
                                              fitted.confidence_models, settings)
    assert (fitted.ambiguity_chi2_ratio, fitted.min_confidence) == (ratio, t)
    chosen = choose_place_threshold({"b10": small, "b1000": large},
                                    fitted.confidence_models, ratio, settings)
    assert chosen is not None and chosen[1] > t
    assert fitted.default_min_confidence(True) == chosen[1]
    assert fitted.default_min_confidence(False) == t


def test_minimal_place_answers_get_their_own_chi2_ratio():
    """``AMBIGUITY_CHI2_RATIO_MINIMAL_PLACES``: place-search answers of 3 inliers whose
    runner-up is within 2 x the best's chi2 are wrong places 1 m off at a high probability,
    those of 5 inliers with the same runner-up are right. Ratios (1.25, 3): at 1.25 only a
    threshold above the wrong answers' probability keeps the false accepts within target
    (losing the good answers of that probability too); at 3 those answers are ambiguous and the
    lower threshold keeps every good answer: (3, lowest) is chosen. The ratio applies to
    minimal place-search answers only (``confidence.answer_chi2_ratio``), and ``decide`` and
    the fitted constants carry it."""
    def rec(pos: float, z: float, inliers: int, chi2: float, place: bool = True) -> SolveRecord:
        feats = {f: 0.0 for f in FEATURES} | {
            "mean_iou": z, "chi2_competitor": chi2, "iou_competitor": 0.0,
            "place_search": float(place), "log_inliers": math.log(inliers),
            "inliers_ge4": float(inliers >= 4)}
        return _record(pos=pos, features=feats, decision_set="b200")

    models = {"refined": {"intercept": 0.0, "coef": {"mean_iou": 1.0}},
              "none": {"intercept": 0.0, "coef": {}}}
    wrong = [rec(1.0, 2.0, 3, math.log(2.0))] * 3
    good_minimal = [rec(0.05, 2.0, 3, math.log(5.0))] * 20
    good_same_runner_up = [rec(0.05, 2.0, 5, math.log(2.0))] * 20
    good = [rec(0.05, 4.0, 6, 4.0)] * 57
    rows = [*wrong, *good_minimal, *good_same_runner_up, *good]
    settings = FitSettings(chi2_ratio_grid=(1.25, 3.0))
    assert n_inliers(wrong[0]) == 3 and n_inliers(good[0]) == 6
    minimal, t = choose_place_threshold({"b200": rows}, models, 1.25, settings)
    assert minimal == 3.0 and t == pytest.approx(0.0)
    assert decide(wrong[0], 1.25, 0.0, models, minimal_ratio=3.0).reason == "ambiguous"
    assert decide(wrong[0], 1.25, 0.0, models).localized
    assert decide(good_same_runner_up[0], 1.25, 0.0, models, minimal_ratio=3.0).localized
    # a one-room answer of 3 inliers keeps the one-room ratio
    assert decide(rec(1.0, 2.0, 3, math.log(2.0), place=False), 1.25, 0.0, models,
                  minimal_ratio=3.0).localized
    # at 1.25 alone, the threshold rises above sigmoid(2) = 0.881
    only, t_only = choose_place_threshold({"b200": rows}, models, 1.25,
                                          FitSettings(chi2_ratio_grid=(1.25,)))
    assert only == 1.25 and t_only == pytest.approx(0.89)
    assert answer_chi2_ratio(1.25, 3.0, True, 3) == 3.0
    assert answer_chi2_ratio(1.25, 3.0, True, 4) == 1.25
    assert answer_chi2_ratio(1.25, 3.0, False, 3) == 1.25
    assert answer_chi2_ratio(1.25, None, True, 3) == 1.25
    assert answer_chi2_ratio(2.0, 1.5, True, 3) == 2.0  # never weaker than the others' rule
    shipped = CalibrationConstants.shipped()
    assert shipped.answer_chi2_ratio(True, 3) >= shipped.ambiguity_chi2_ratio
    assert shipped.answer_chi2_ratio(False, 3) == shipped.ambiguity_chi2_ratio
