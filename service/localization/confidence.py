"""What a localized answer means: calibrated covariance, confidence as a probability, ambiguity.

* covariance: ``cov = k_metric * max(s^2, f_metric) * t(n) * (J^T W J)^-1`` with
  ``s^2 = r^T W r / (m - 6)`` (:func:`calibrated_covariance`; with a prior or gravity only the
  detections' information is rescaled); constants in
  :mod:`quadloc.service.localization.calibration`. Conditioned on the inlier associations and the
  detection noise model.
* the constants are per calibration key (:func:`calibration_key`): the metric, refined with
  sigma weights or with unit weights (a request without a sigma on every detection, or
  ``use_sigma=False``): ``s^2`` and ``J^T W J`` are in other units without the weights.
* confidence: ``P(position error <= TOLERANCE_POSITION_M and rotation error <=
  TOLERANCE_ROTATION_DEG)`` from a logistic model of :func:`evidence_features`
  (:func:`confidence_probability`), recalibrated on building frames for the answers of a large
  map's place search (:func:`confidence_logit`).
* ambiguity: a distinct runner-up with as many inliers competes by its refined chi2 (refined
  over as many detections with the same metric), or, when the chi2 do not compare, by its IoU
  sum (:func:`is_ambiguous`); an answer of a large map's place search held by a minimal
  sample of inliers is held to a larger chi2 ratio (:func:`answer_chi2_ratio`).

Rationale and measurements: ``docs/design/localization.md``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from quadloc.factors.arrays import FloatArray
from quadloc.service.localization.calibration import (
    AMBIGUITY_CHI2_RATIO,
    AMBIGUITY_RATIO,
    AMBIGUITY_RATIO_SAME_OBJECTS,
    CONFIDENCE_MODELS,
    COVARIANCE_SCALE,
    S2_FLOOR,
)

__all__ = [
    "AMBIGUITY_CHI2_RATIO",
    "AMBIGUITY_RATIO",
    "AMBIGUITY_RATIO_SAME_OBJECTS",
    "CHI2_COMPETITOR_CAP",
    "MINIMAL_SAMPLE_INLIERS",
    "PLACES_MODEL",
    "TOLERANCE_POSITION_M",
    "TOLERANCE_ROTATION_DEG",
    "UNIT_WEIGHTS_SUFFIX",
    "answer_chi2_ratio",
    "calibrated_covariance",
    "calibration_key",
    "chi2_competitor",
    "confidence_logit",
    "confidence_probability",
    "covariance_scale",
    "evidence_features",
    "gaussian_tolerance_probability",
    "is_ambiguous",
    "refined_logit",
    "residual_variance",
    "student_t_factor",
    "variance_factor",
]

#: ``chi2_competitor`` feature without a comparable runner-up (and its largest value): the log
#: of a chi2 ratio of 100, far beyond any competitor.
CHI2_COMPETITOR_CAP = math.log(100.0)

#: The tolerance of ``confidence``: P(position error <= 0.10 m and rotation error <= 5 deg).
TOLERANCE_POSITION_M = 0.10
TOLERANCE_ROTATION_DEG = 5.0


#: Name of the model that recalibrates the refined model for the answers of a place search
#: (:func:`confidence_logit`).
PLACES_MODEL = "places"

#: Inliers of a minimal sample: three correspondences, which P3P puts on their detections in
#: any place with their labels (:func:`answer_chi2_ratio`).
MINIMAL_SAMPLE_INLIERS = 3

#: Suffix of the calibration key of a refinement with unit weights (:func:`calibration_key`).
UNIT_WEIGHTS_SUFFIX = ":unit_weights"


def calibration_key(metric: str, sigma_weighted: bool) -> str:
    """The key of the calibration constants (``COVARIANCE_SCALE``, ``S2_FLOOR``, the confidence
    model's ``metric_offset``) of a refinement with ``metric``: the metric itself when the
    costs were weighted by ``1 / sigma`` (paper eq. 8), ``metric + UNIT_WEIGHTS_SUFFIX`` when
    every weight was 1 (no sigma weighting; ``"none"`` is never refined and keeps its key)."""
    return metric if sigma_weighted or metric == "none" else metric + UNIT_WEIGHTS_SUFFIX


def residual_variance(chi2: float, n_residuals: int) -> float:
    """A-posteriori residual variance ``s^2 = chi2 / (m - 6)`` (``m`` residuals, 6 pose DoF);
    NaN when ``m <= 6`` or ``chi2`` is not finite."""
    dof = n_residuals - 6
    if dof <= 0 or not math.isfinite(chi2):
        return math.nan
    return max(chi2 / dof, 1e-300)


def calibrated_covariance(
    metric: str, raw_covariance: FloatArray | None, chi2: float, n_residuals: int,
    n_detections: int, fixed_information: FloatArray | None = None,
    scale: Mapping[str, float] | None = None, s2_floor: Mapping[str, float] | None = None,
) -> FloatArray | None:
    """The reported 6x6 covariance (order ``[omega, v]``, rad/m, body frame, right
    perturbation) from the refinement's raw one (see the module docstring; ``metric``: its
    :func:`calibration_key`; ``n_detections`` refined, ``n_residuals`` scalar residuals); None
    when the raw covariance is None, ``s^2`` is undefined (``m <= 6``) or the key has no
    calibration. ``fixed_information`` (6, 6): the part of ``raw_covariance^-1`` from the
    prior and gravity factors (``RefinementResult.fixed_information``), kept unscaled: their
    noise is the client's, not the detections'. ``scale`` / ``s2_floor``: a map's own
    constants (:func:`covariance_scale`)."""
    if raw_covariance is None:
        return None
    factor = covariance_scale(metric, chi2, n_residuals, n_detections, scale, s2_floor)
    if not math.isfinite(factor):
        return None
    raw = np.asarray(raw_covariance, dtype=float)
    if fixed_information is None:
        cov = raw * factor
    else:
        fixed = np.asarray(fixed_information, dtype=float)
        info = (np.linalg.inv(raw) - fixed) / factor + fixed
        cov = np.linalg.inv(0.5 * (info + info.T))
    cov = 0.5 * (cov + cov.T)
    if not np.all(np.isfinite(cov)) or np.linalg.eigvalsh(cov)[0] <= 0:
        return None
    return cov


#: Effective independent measurements per detection in the Student-t factor
#: (:func:`student_t_factor`): an ellipse's centre and size are well determined, its
#: orientation and aspect (small, roundish objects) much less.
DOF_PER_DETECTION = 3.0


def student_t_factor(n_detections: int) -> float:
    """``nu / (nu - 2)`` with ``nu = max(DOF_PER_DETECTION * n - 6, 3)``: the covariance of the
    Student-t error distribution when the variance factor ``s^2`` is itself estimated from
    ``nu`` effective degrees of freedom (few detections: ``s^2`` is uncertain, the error's tail
    heavier). 3 for 2-3 detections, 1.29 for 5, 1.13 for 8, -> 1 for many."""
    nu = max(DOF_PER_DETECTION * n_detections - 6.0, 3.0)
    return nu / (nu - 2.0)


def variance_factor(metric: str, chi2: float, n_residuals: int, n_detections: int,
                    s2_floor: Mapping[str, float] | None = None) -> float:
    """``max(s^2, f_metric) * student_t_factor(n_detections)`` (``metric``: its
    :func:`calibration_key`; ``s2_floor``: the floors ``f``, default :data:`S2_FLOOR`); NaN
    without ``s^2``."""
    s2 = residual_variance(chi2, n_residuals)
    if not math.isfinite(s2):
        return math.nan
    floors = S2_FLOOR if s2_floor is None else s2_floor
    return max(s2, floors.get(metric, 0.0)) * student_t_factor(n_detections)


def covariance_scale(metric: str, chi2: float, n_residuals: int, n_detections: int,
                     scale: Mapping[str, float] | None = None,
                     s2_floor: Mapping[str, float] | None = None) -> float:
    """``k_metric * max(s^2, f_metric) * t(n)`` (module docstring; ``metric``: its
    :func:`calibration_key`; ``scale`` / ``s2_floor``: the constants ``k`` / ``f``, default
    :data:`COVARIANCE_SCALE` / :data:`S2_FLOOR`, a map's own calibration otherwise); NaN when
    undefined (no ``s^2``, or a key without calibration constants)."""
    scales = COVARIANCE_SCALE if scale is None else scale
    if metric not in scales:
        return math.nan
    return scales[metric] * variance_factor(metric, chi2, n_residuals, n_detections, s2_floor)


def gaussian_tolerance_probability(covariance: FloatArray | None) -> float:
    """P(|position error| <= TOLERANCE_POSITION_M and |rotation| <= TOLERANCE_ROTATION_DEG)
    for a zero-mean Gaussian error with this covariance, approximated per block by the
    chi-square with 3 DoF of the isotropic equivalent (``sigma^2 = trace / 3``); NaN without a
    covariance."""
    if covariance is None:
        return math.nan
    cov = np.asarray(covariance)
    out = 1.0
    for block, tol in ((slice(0, 3), math.radians(TOLERANCE_ROTATION_DEG)),
                       (slice(3, 6), TOLERANCE_POSITION_M)):
        var = float(np.trace(cov[block, block])) / 3.0
        x = tol * tol / max(var, 1e-300)
        out *= _chi2_3_cdf(x)
    return out


def _chi2_3_cdf(x: float) -> float:
    """CDF of the chi-square distribution with 3 DoF at ``x >= 0``."""
    if x <= 0:
        return 0.0
    r = math.sqrt(x)
    return math.erf(r / math.sqrt(2.0)) - math.sqrt(2.0 / math.pi) * r * math.exp(-x / 2.0)


def evidence_features(
    *, n_inliers: int, n_usable: int, ious: FloatArray, s2: float, covariance: FloatArray | None,
    margin: float, n_samples: int, s2_floor: float = 0.0,
    chi2_ratio_log: float = CHI2_COMPETITOR_CAP, gravity: bool = False,
    place_search: bool = False,
) -> dict[str, float]:
    """The evidence the confidence model uses (names in
    :data:`quadloc.service.localization.calibration.CONFIDENCE_FEATURES`).

    Args:
        n_inliers, n_usable: inliers of the returned pose, detections with a map label.
        ious: the inliers' IoUs at the returned pose.
        s2: a-posteriori residual variance (NaN without refinement).
        s2_floor: the metric's typical ``s^2`` (:data:`S2_FLOOR`): the feature is the excess
            ``log(max(s2, s2_floor) / s2_floor)`` >= 0 (residuals smaller than typical, e.g.
            exact detections, carry no extra evidence; as for the covariance).
        covariance: the calibrated covariance (None without).
        margin: runner-up score / best score (0 without a distinct runner-up), in [0, 1].
        n_samples: number of label-compatible minimal samples (chance matches the map allows).
        chi2_ratio_log: :func:`chi2_competitor` of the answer (the cap without a competitor).
        gravity: the solve had the client's gravity (a factor on the tilt, tilted candidates
            dropped: ``quadloc.service.localization.gravity``).
        place_search: the answer came from the place search of a large map (the map's
            constellations, negative evidence, the copies rule:
            ``quadloc.service.localization.constellations``): :func:`confidence_probability`
            recalibrates the refined model's probability with the ``"places"`` model.
    """
    ious = np.asarray(ious, dtype=float)
    p_gauss = gaussian_tolerance_probability(covariance)
    return {
        "inliers_ge3": float(n_inliers >= 3),
        "inliers_ge4": float(n_inliers >= 4),
        "log_inliers": math.log(max(n_inliers, 1)),
        "inlier_fraction": n_inliers / max(n_usable, 1),
        "mean_iou": float(ious.mean()) if ious.size else 0.0,
        "min_iou": float(ious.min()) if ious.size else 0.0,
        "log_s2": (math.log(max(s2, s2_floor) / s2_floor)
                   if math.isfinite(s2) and s2_floor > 0 else 0.0),
        "logit_gauss": _logit(p_gauss) if math.isfinite(p_gauss) else 0.0,
        "margin": float(min(max(margin, 0.0), 1.0)),
        "log_samples": math.log(max(n_samples, 1)),
        "chi2_competitor": float(chi2_ratio_log),  # clipped by chi2_competitor
        "gravity": float(gravity),
        "place_search": float(place_search),
    }


def _logit(p: float) -> float:
    p = min(max(p, 1e-6), 1.0 - 1e-6)
    return math.log(p / (1.0 - p))


def confidence_probability(metric: str, features: Mapping[str, float],
                           models: Mapping[str, Any] | None = None) -> float:
    """The calibrated probability (logistic model) that the pose is within the tolerance.

    ``metric`` (its :func:`calibration_key`) picks the coefficient set: ``"none"`` (unrefined
    poses: no residual variance or covariance features) or the refined model (shared by the
    nine metrics with and without sigma weights, optionally with an intercept offset per key;
    the calibrated covariance carries the metric's accuracy). A refined answer of the place
    search (feature ``place_search`` > 0) has that model's logit ``z`` recalibrated by the
    ``"places"`` model, ``intercept + coef["refined_logit"] * z`` (fitted on building frames:
    the refined model, fitted in one room, counts every chance match of a whole building
    against an answer the place search and the negative evidence already singled out).
    ``models``: the coefficient sets (default :data:`CONFIDENCE_MODELS`; the bench passes
    candidates while fitting)."""
    return float(1.0 / (1.0 + math.exp(-min(max(confidence_logit(metric, features, models),
                                                 -50.0), 50.0))))


def confidence_logit(metric: str, features: Mapping[str, float],
                     models: Mapping[str, Any] | None = None) -> float:
    """The log-odds of :func:`confidence_probability` (same arguments)."""
    sets: Mapping[str, Any] = CONFIDENCE_MODELS if models is None else models
    refined = metric != "none"
    z = refined_logit(metric, features, sets)
    places = sets.get(PLACES_MODEL)
    if refined and places is not None and features.get("place_search", 0.0) > 0:
        z = places["intercept"] + places["coef"]["refined_logit"] * z
    return z


def refined_logit(metric: str, features: Mapping[str, float],
                  models: Mapping[str, Any] | None = None) -> float:
    """The log-odds of the ``"refined"`` model (``"none"`` for ``metric="none"``) alone,
    before any ``"places"`` recalibration (same arguments as :func:`confidence_probability`)."""
    sets: Mapping[str, Any] = CONFIDENCE_MODELS if models is None else models
    model = sets["none" if metric == "none" else "refined"]
    z = model["intercept"] + model.get("metric_offset", {}).get(metric, 0.0)
    for name, coef in model["coef"].items():
        z += coef * features[name]
    return float(z)


def chi2_competitor(best_chi2: float, best_inliers: int,
                    runners_up: Sequence[tuple[float, int]]) -> float:
    """``log(chi2_runner / chi2_best)`` of the closest runner-up with at least as many inliers
    (``runners_up``: (refined chi2, inliers) of the distinct alternatives), clipped to
    ``+-CHI2_COMPETITOR_CAP``; the cap when there is none or a chi2 is not finite (no
    refinement). Small or negative: a distinct pose fits the detections about as well."""
    ratios = [math.log(max(c, 1e-300) / max(best_chi2, 1e-300)) for c, n in runners_up
              if n >= best_inliers and math.isfinite(c) and math.isfinite(best_chi2)]
    if not ratios:
        return CHI2_COMPETITOR_CAP
    return float(min(max(min(ratios), -CHI2_COMPETITOR_CAP), CHI2_COMPETITOR_CAP))


def answer_chi2_ratio(chi2_ratio: float, minimal_ratio: float | None, place_search: bool,
                      n_inliers: int) -> float:
    """The runner-up / best refined chi2 ratio at and below which an answer is ambiguous:
    ``chi2_ratio`` (``AMBIGUITY_CHI2_RATIO``), or, for an answer of a large map's place search
    held by at most :data:`MINIMAL_SAMPLE_INLIERS` inliers, ``minimal_ratio`` when larger
    (``AMBIGUITY_CHI2_RATIO_MINIMAL_PLACES``; None: no such rule). Three correspondences fit
    their centres exactly in every place with their labels, so only the ellipses' shapes tell
    places apart, with few residual degrees of freedom; among the hundreds of places of a
    building, a wrong one then often beats the true one by a chi2 ratio that would settle a
    one-room answer (tuning frames: 10 of the 12 false accepts at 200-1,000 rooms were such
    answers, their runner-up within 1.4-2.8 x)."""
    if minimal_ratio is not None and place_search and n_inliers <= MINIMAL_SAMPLE_INLIERS:
        return max(chi2_ratio, minimal_ratio)
    return chi2_ratio


def is_ambiguous(best_inliers: int, best_score: float, runner_up_inliers: int,
                 runner_up_score: float, same_objects: bool = False,
                 best_chi2: float = math.nan, runner_up_chi2: float = math.nan,
                 chi2_ratio: float | None = None) -> bool:
    """Whether a distinct runner-up explains the detections comparably well. A runner-up that
    leaves a detection unexplained (fewer inliers) is not a competitor: the best explains
    strictly more. With as many inliers:

    * both chi2 finite (refined over as many detections, the same metric: the evidence the
      solver has about which pose explains the ellipses): a competitor when ``runner_up_chi2
      <= chi2_ratio x best_chi2`` (default :data:`AMBIGUITY_CHI2_RATIO`, fitted by
      ``bench.trust --fit``), whatever the IoU sums say (with 2-3 detections a wrong pose
      overlaps the detections almost as well, so the IoU sum alone rejected good answers
      whose runner-up fits far worse);
    * otherwise (no refinement, or refined over other detections): by the sum of inlier IoUs,
      >= :data:`AMBIGUITY_RATIO` x the best's when it assigns the detections to other map
      objects (``same_objects=False``: e.g. the other Xbox, a label ambiguity), >=
      :data:`AMBIGUITY_RATIO_SAME_OBJECTS` x when it matches the same objects (another pose of
      the same correspondences: only a near tie is ambiguous)."""
    if runner_up_inliers < best_inliers:
        return False
    if math.isfinite(best_chi2) and math.isfinite(runner_up_chi2):
        ratio = AMBIGUITY_CHI2_RATIO if chi2_ratio is None else chi2_ratio
        return runner_up_chi2 <= ratio * best_chi2
    ratio = AMBIGUITY_RATIO_SAME_OBJECTS if same_objects else AMBIGUITY_RATIO
    return best_score > 0 and runner_up_score >= ratio * best_score
