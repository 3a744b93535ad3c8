"""Fit the calibration constants of :mod:`quadloc.service.localization.confidence` from solve
records: the covariance scale ``k_key`` and residual-variance floor ``f_key``, the confidence
model, ``AMBIGUITY_CHI2_RATIO`` and ``MIN_CONFIDENCE``.

Pure functions from :class:`SolveRecord` (one per solve of a frame whose reference pose is
known) to :class:`CalibrationConstants`; no simulator, no solver. Where the records come from
is the caller's business: ``bench.trust --fit`` simulates detections at the real Chess poses
(tuning seeds only), a user would run ``localize`` on recorded frames with reference poses.
The discipline "tune on some seeds, report on others" is the caller's too: the records fed here
are the tuning records; the figures that judge the constants come from other records.

Steps of :func:`fit_calibration` (each formula is in one function below):

1. ``f_key`` (:func:`fit_s2_floor`): the :attr:`FitSettings.s2_floor_quantile` quantile of the
   a-posteriori residual variance ``s^2`` of the key's localized covariance records.
2. ``k_key`` (:func:`fit_covariance_scale`): the mean NEES of the covariance records within
   each operating point (5 / 10 / 20 cm) and recording group (detector setting) is a cell;
   ``k`` centres the geometric mean of the smallest and largest cell on 6 (the 6-DoF
   expectation; a wider error bound keeps frames further in the tail, so the cells grow with
   the operating point).
3. The residual and covariance features (``log_s2``, ``logit_gauss``) of every record are
   recomputed for the new ``k`` / ``f`` (:func:`refeature`), then the logistic models of
   ``confidence`` are fitted (:func:`fit_confidence_models`): ``"refined"`` over every refined
   key with an intercept offset per key (``level_set`` is the reference), ``"none"`` over the
   unrefined answers, ``"places"`` (the refined model's log-odds recalibrated) over the answers
   of a large map's place search (building frames: ``bench.building --calibration-records``).
4. ``AMBIGUITY_CHI2_RATIO`` and ``MIN_CONFIDENCE`` (:func:`choose_ambiguity_and_threshold`):
   on the decision sets (unchecked answers of hard frames, e.g. 2 or 3 detections), the pair
   that keeps the most good frames while every set's false accepts stay within
   ``false_accept_target x false_accept_tuning_margin``; then
   ``AMBIGUITY_CHI2_RATIO_MINIMAL_PLACES`` and ``MIN_CONFIDENCE_PLACES``
   (:func:`choose_place_threshold`) by the same rule on the decision records of place-search
   answers (building frames, one set per map size and repetition mode) at that ratio.

The generated module ``quadloc.service.localization.calibration`` is written by
:func:`calibration_source`; records are stored by :func:`write_records` (gzip JSON, columns)::

    python -m quadloc.service.localization.calibration_fit RECORDS.json.gz [--output PATH]
    python -m quadloc.service.localization.calibration_fit RECORDS.json.gz --check
"""

from __future__ import annotations

import argparse
import dataclasses
import gzip
import hashlib
import json
import math
import pprint
import sys
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType
from typing import Any, NotRequired, TypedDict, cast

import numpy as np

from quadloc.service.localization import calibration
from quadloc.service.localization.confidence import (
    MINIMAL_SAMPLE_INLIERS,
    PLACES_MODEL,
    TOLERANCE_POSITION_M,
    TOLERANCE_ROTATION_DEG,
    answer_chi2_ratio,
    confidence_probability,
    gaussian_tolerance_probability,
    refined_logit,
    student_t_factor,
)

__all__ = [
    "FEATURES",
    "RECORDS_FORMAT",
    "REFINED_ONLY",
    "CalibrationConstants",
    "CalibrationFitError",
    "Decision",
    "DecisionOutcome",
    "FitSettings",
    "LogisticModel",
    "SolveRecord",
    "calibration_source",
    "choose_ambiguity_and_threshold",
    "choose_place_threshold",
    "decide",
    "decision_outcome",
    "decision_sets",
    "display_path",
    "fit_calibration",
    "fit_confidence_models",
    "fit_covariance_scale",
    "fit_logistic",
    "fit_s2_floor",
    "map_calibration_applies",
    "n_inliers",
    "place_search",
    "read_records",
    "record_from_evidence",
    "refeature",
    "session_variance_ratio",
    "success",
    "write_records",
]

#: Features of the confidence model (names of ``confidence.evidence_features``). Not
#: ``min_iou``: its distribution shifts with the detector's noise, and leaving it out transfers
#: better between the two noise settings of ``bench.trust`` (tuning seeds, each setting fitted
#: on the other).
FEATURES = ("inliers_ge3", "inliers_ge4", "log_inliers", "inlier_fraction", "mean_iou",
            "log_s2", "logit_gauss", "margin", "log_samples", "chi2_competitor", "gravity")
#: Features that need a refinement (not in the ``none`` model).
REFINED_ONLY = ("log_s2", "logit_gauss", "chi2_competitor")
#: Evidence a record keeps besides the features: a runner-up with a larger IoU sum on other
#: map objects (> 0: ambiguous by the IoU rule, ``decide``); the answer came from the place
#: search of a large map (> 0: its confidence is the ``"places"`` model's).
RECORD_EVIDENCE = ("iou_competitor", "place_search")
#: ``format`` of the record files of :func:`write_records`.
RECORDS_FORMAT = "quadloc.calibration-records/1"
#: Key of the reference model (no intercept offset) and of the unrefined answers.
REFERENCE_KEY = "level_set"
UNREFINED_KEY = "none"


class CalibrationFitError(ValueError):
    """Records that cannot be fitted (missing fields, no usable record, bad file)."""


# ------------------------------------------------------------------ input: solve records


@dataclass(frozen=True)
class SolveRecord:
    """One solve of a frame with a known reference pose (the fit's unit of input).

    Attributes:
        key: calibration key of the solve (``confidence.calibration_key``: the metric, or
            ``<metric>:unit_weights`` without sigma weights, ``"none"`` unrefined).
        group: recording group, e.g. the detector setting (``"default"``, ``"noisy"``): the
            covariance scale is fitted on the spread of the groups' mean NEES.
        localized: the answer was ``localized`` (solved with ``min_confidence=0``: every
            verified, unambiguous pose; ``decision_set`` records: ``on_ambiguity="best"`` too).
        reason: the answer's ``reason`` (None when localized).
        position_error_m: camera position error against the reference (inf without a pose).
        rotation_error_deg: rotation error against the reference (inf without a pose).
        features: the answer's evidence (``LocalizationResult.evidence``): the confidence
            features (:data:`FEATURES`) and :data:`RECORD_EVIDENCE`; NaN when the answer has
            none.
        s2: a-posteriori residual variance of the refinement (NaN without refinement).
        n_refined: detections in the refinement (0 without).
        cov_scale: ``k * max(s^2, f) * t(n)`` applied to the reported covariance (NaN
            without).
        nees: ``xi^T cov^-1 xi`` of the reported covariance, ``xi`` the GTSAM Pose3 tangent
            ``Logmap(estimate^-1 reference)`` (body frame, ``[omega, v]``); NaN without a
            covariance.
        cov_trace_rotation_rad2, cov_trace_position_m2: traces of the reported covariance's
            rotation (rad^2) and position (m^2) blocks (all ``confidence`` uses of it); NaN
            without.
        covariance: the record feeds ``k`` and ``f`` (frames solved from scratch, without
            prior or gravity information, whose covariance is the detections' alone).
        confidence: the record feeds the confidence model.
        decision_set: non-empty for the unchecked answer (``on_ambiguity="best"``,
            ``min_confidence=0``) of a hard frame: the name of its set (e.g. ``"2 default"``),
            on which the ambiguity ratio and the threshold are chosen.

    Rescaling for new constants multiplies the covariance by a scalar (:func:`refeature`):
    exact for solves without prior or gravity factors, an approximation for those with (their
    information is kept unscaled by ``confidence.calibrated_covariance``).
    """

    key: str
    group: str
    localized: bool
    reason: str | None
    position_error_m: float
    rotation_error_deg: float
    features: Mapping[str, float]
    s2: float
    n_refined: int
    cov_scale: float
    nees: float
    cov_trace_rotation_rad2: float
    cov_trace_position_m2: float
    covariance: bool = True
    confidence: bool = True
    decision_set: str = ""


def record_from_evidence(
    *, key: str, group: str, localized: bool, reason: str | None, position_error_m: float,
    rotation_error_deg: float, evidence: Mapping[str, float], covariance_6x6: Any | None,
    nees: float | None, covariance: bool = True, confidence: bool = True,
    decision_set: str = "", features: Sequence[str] = FEATURES,
) -> SolveRecord:
    """A :class:`SolveRecord` from an answer's evidence (``LocalizationResult.evidence``) and
    reported covariance (6x6 ``[omega, v]``, rad / m, or None), with its errors against the
    reference (computed by the caller: position m, rotation deg, NEES or None); ``features``:
    the evidence names kept (with :data:`RECORD_EVIDENCE`)."""
    nan = math.nan
    names = (*features, *(n for n in RECORD_EVIDENCE if n not in features))
    feats = {n: _float(evidence.get(n)) for n in names}
    if covariance_6x6 is None:
        tr_rot = tr_pos = nan
    else:
        cov = np.asarray(covariance_6x6, dtype=float)
        tr_rot, tr_pos = float(np.trace(cov[:3, :3])), float(np.trace(cov[3:, 3:]))
    return SolveRecord(
        key=key, group=group, localized=bool(localized), reason=reason,
        position_error_m=float(position_error_m), rotation_error_deg=float(rotation_error_deg),
        features=feats, s2=_float(evidence.get("s2")),
        n_refined=int(evidence.get("n_refined") or 0), cov_scale=_float(evidence.get("cov_scale")),
        nees=nan if nees is None else float(nees), cov_trace_rotation_rad2=tr_rot,
        cov_trace_position_m2=tr_pos, covariance=covariance, confidence=confidence,
        decision_set=decision_set)


def _float(v: object) -> float:
    return math.nan if v is None else float(cast(float, v))


def place_search(r: SolveRecord) -> bool:
    """The record's answer came from the place search of a large map (feature
    ``place_search``; records made before it existed have none: one-room solves)."""
    return bool(r.features.get("place_search", 0.0) > 0)


def n_inliers(r: SolveRecord) -> int:
    """The inliers of the record's answer (from its feature ``log_inliers``, the log of at
    least 1: 1 for a record without)."""
    return round(math.exp(r.features.get("log_inliers", 0.0)))


def success(r: SolveRecord) -> bool:
    """What ``confidence`` predicts: localized within ``TOLERANCE_POSITION_M`` and
    ``TOLERANCE_ROTATION_DEG`` of the reference."""
    return bool(r.localized and r.position_error_m <= TOLERANCE_POSITION_M
                and r.rotation_error_deg <= TOLERANCE_ROTATION_DEG)


# ------------------------------------------------------------------ output: the constants


class LogisticModel(TypedDict):
    """``P = 1 / (1 + exp(-(intercept + metric_offset[key] + sum coef[f] * feature[f])))``."""

    intercept: float
    coef: dict[str, float]
    metric_offset: NotRequired[dict[str, float]]


@dataclass(frozen=True)
class CalibrationConstants:
    """The constants of ``quadloc.service.localization.calibration`` (generated module; the
    names in brackets), typed.

    Attributes:
        covariance_scale: ``k_key`` per calibration key (``COVARIANCE_SCALE``).
        s2_floor: ``f_key`` per calibration key, the key's ``s^2`` units (``S2_FLOOR``).
        ambiguity_chi2_ratio: runner-up / best refined chi2 at and below which an answer is
            ambiguous (``AMBIGUITY_CHI2_RATIO``).
        ambiguity_ratio, ambiguity_ratio_same_objects: the IoU-sum ratios of the ambiguity
            rule when the chi2 do not compare (``AMBIGUITY_RATIO``,
            ``AMBIGUITY_RATIO_SAME_OBJECTS``; not fitted, carried over).
        min_confidence: default ``LocalizationOptions.min_confidence`` (``MIN_CONFIDENCE``).
        min_confidence_places: the same default for the answers of a place search
            (``MIN_CONFIDENCE_PLACES``; None: ``min_confidence``): chosen on the building
            frames' decision sets, where a failure is more often a wrong place (metres off)
            than a near miss.
        ambiguity_chi2_ratio_minimal_places: the ambiguity chi2 ratio of a place-search
            answer held by a minimal sample of inliers
            (``AMBIGUITY_CHI2_RATIO_MINIMAL_PLACES``, ``confidence.answer_chi2_ratio``; None:
            ``ambiguity_chi2_ratio``), chosen with ``min_confidence_places``.
        confidence_features: the models' features, in order (``CONFIDENCE_FEATURES``).
        confidence_models: ``"refined"``, ``"none"`` and, fitted on building frames,
            ``"places"`` (``CONFIDENCE_MODELS``), the ``models`` argument of
            ``confidence.confidence_probability``.
        provenance: what the constants were fitted from (``PROVENANCE``): ``records`` (file),
            ``records_sha256``, ``command``, ``tuning_seeds``, ...
    """

    covariance_scale: dict[str, float]
    s2_floor: dict[str, float]
    ambiguity_chi2_ratio: float
    ambiguity_ratio: float
    ambiguity_ratio_same_objects: float
    min_confidence: float
    confidence_features: tuple[str, ...]
    confidence_models: dict[str, LogisticModel]
    provenance: dict[str, Any] = field(default_factory=dict)
    min_confidence_places: float | None = None
    ambiguity_chi2_ratio_minimal_places: float | None = None

    def answer_chi2_ratio(self, place_search: bool, n_inliers: int) -> float:
        """The ambiguity chi2 ratio an answer is held to (``confidence.answer_chi2_ratio``
        with these constants)."""
        return answer_chi2_ratio(self.ambiguity_chi2_ratio,
                                 self.ambiguity_chi2_ratio_minimal_places, place_search,
                                 n_inliers)

    def default_min_confidence(self, place_search: bool) -> float:
        """The default ``min_confidence`` of an answer: ``min_confidence_places`` for the
        answers of a place search (when set), ``min_confidence`` otherwise."""
        if place_search and self.min_confidence_places is not None:
            return self.min_confidence_places
        return self.min_confidence

    @classmethod
    def from_module(cls, module: ModuleType) -> CalibrationConstants:
        """The constants of a calibration module (default use: the shipped
        ``quadloc.service.localization.calibration``)."""
        return cls(
            covariance_scale=dict(module.COVARIANCE_SCALE), s2_floor=dict(module.S2_FLOOR),
            ambiguity_chi2_ratio=float(module.AMBIGUITY_CHI2_RATIO),
            ambiguity_ratio=float(module.AMBIGUITY_RATIO),
            ambiguity_ratio_same_objects=float(module.AMBIGUITY_RATIO_SAME_OBJECTS),
            min_confidence=float(module.MIN_CONFIDENCE),
            min_confidence_places=float(module.MIN_CONFIDENCE_PLACES),
            ambiguity_chi2_ratio_minimal_places=float(
                module.AMBIGUITY_CHI2_RATIO_MINIMAL_PLACES),
            confidence_features=tuple(module.CONFIDENCE_FEATURES),
            confidence_models=cast(dict[str, LogisticModel], dict(module.CONFIDENCE_MODELS)),
            provenance=dict(module.PROVENANCE))

    @classmethod
    def shipped(cls) -> CalibrationConstants:
        """The constants in force (``quadloc.service.localization.calibration``)."""
        return cls.from_module(calibration)

    def differences(self, other: CalibrationConstants, abs_tol: float = 2e-6,
                    rel_tol: float = 1e-9) -> list[str]:
        """Where ``other``'s fitted values differ from these (not the provenance): each
        number compared with ``math.isclose(abs_tol, rel_tol)`` (the generator rounds to 6
        decimals), keys and features exactly; empty when they agree."""
        out: list[str] = []

        def num(name: str, a: float, b: float) -> None:
            if not math.isclose(a, b, abs_tol=abs_tol, rel_tol=rel_tol):
                out.append(f"{name}: {a!r} != {b!r}")

        def table(name: str, a: Mapping[str, float], b: Mapping[str, float]) -> None:
            if set(a) != set(b):
                out.append(f"{name}: keys {sorted(set(a) ^ set(b))} in only one")
            for k in sorted(set(a) & set(b)):
                num(f"{name}[{k!r}]", a[k], b[k])

        table("covariance_scale", self.covariance_scale, other.covariance_scale)
        table("s2_floor", self.s2_floor, other.s2_floor)
        for name in ("ambiguity_chi2_ratio", "ambiguity_ratio", "ambiguity_ratio_same_objects",
                     "min_confidence"):
            num(name, getattr(self, name), getattr(other, name))
        num("min_confidence_places", self.default_min_confidence(True),
            other.default_min_confidence(True))
        num("ambiguity_chi2_ratio_minimal_places",
            self.answer_chi2_ratio(True, MINIMAL_SAMPLE_INLIERS),
            other.answer_chi2_ratio(True, MINIMAL_SAMPLE_INLIERS))
        if self.confidence_features != other.confidence_features:
            out.append(f"confidence_features: {self.confidence_features} != "
                       f"{other.confidence_features}")
        if set(self.confidence_models) != set(other.confidence_models):
            out.append("confidence_models: not the same models")
        for m in sorted(set(self.confidence_models) & set(other.confidence_models)):
            a, b = self.confidence_models[m], other.confidence_models[m]
            num(f"confidence_models[{m!r}].intercept", a["intercept"], b["intercept"])
            table(f"confidence_models[{m!r}].coef", a["coef"], b["coef"])
            table(f"confidence_models[{m!r}].metric_offset", a.get("metric_offset", {}),
                  b.get("metric_offset", {}))
        return out


def map_calibration_applies(calibration: CalibrationConstants | None, key: str) -> bool:
    """A map's own calibration replaces the shipped constants for the calibration keys it was
    fitted for (``provenance["fitted_keys"]``, set by
    ``quadloc.service.localization.map_calibration``), only: its confidence model was fitted
    on those keys' answers."""
    return calibration is not None and key in calibration.provenance.get("fitted_keys", ())


def session_variance_ratio(calibration: CalibrationConstants | None, key: str) -> float:
    """How much a map's own calibration rescales a tracking session's covariance (1 when it
    does not apply to ``key``: :func:`map_calibration_applies`).

    A session's covariance is the smoother's marginal of the detections' factors as the
    client's sigmas weight them, with no residual variance ``s^2`` of its own: it takes the
    detections' noise to be what the shipped constants say at their floor, ``k f`` (the
    localize factor of a frame whose ``s^2`` is at most the floor). A map's
    calibration measured that noise for its detector as ``k' f'``: the session's covariance is
    multiplied by ``(k' f') / (k f)`` (dimensionless; key ``key``:
    :func:`quadloc.service.localization.confidence.calibration_key`). A first-order transfer
    of the map's calibration to sessions: no benchmark measures a session's NEES on a
    calibrated map yet."""
    if calibration is None or not map_calibration_applies(calibration, key):
        return 1.0
    shipped = CalibrationConstants.shipped()
    return (calibration.covariance_scale[key] * calibration.s2_floor[key]
            / (shipped.covariance_scale[key] * shipped.s2_floor[key]))


# ------------------------------------------------------------------ settings


@dataclass(frozen=True)
class FitSettings:
    """Choices of the fit (defaults: those of the shipped constants).

    Attributes:
        s2_floor_quantile: ``f_key`` is this quantile of the key's ``s^2`` (0.9 rather than
            the median: fewer default-noise frames claim the precision of a lucky small
            residual, which narrows the NEES spread between the two noise settings).
        operating_points_m: position errors (m) within which the NEES cells are taken (the
            covariance is conditioned on correct associations).
        nees_target: the geometric centre of the NEES cells after scaling (6: the 6-DoF
            expectation, the geometric centre of [4, 9]).
        min_cell_records: a NEES cell needs this many records.
        features: the confidence model's features.
        metric_offsets: a per-key intercept offset in the refined model.
        ridge: L2 penalty of the logistic fit (not on the intercept).
        chi2_ratio_grid, min_confidence_grid, min_confidence_grid_places: candidate
            ``AMBIGUITY_CHI2_RATIO``, ``MIN_CONFIDENCE`` and ``MIN_CONFIDENCE_PLACES`` values.
        false_accept_error_m: a localized answer farther than this is a false accept.
        false_accept_target: largest share of false accepts in a decision set.
        false_accept_tuning_margin: the tuning records are held to this fraction of the
            target: a threshold chosen AT the target on tuning frames exceeds it on about half
            of new frame sets (``bench.trust``: 0.9 % on the tuning frames, 2.3 % on new
            seeds); 0.5 chosen by cross-validation on the tuning seeds alone.
        good_error_m: a decision record's frame is good when its unchecked answer is within
            this (the kept share counts the good frames answered ``localized``).
        places_model: fit the ``"places"`` recalibration on the place-search answers, the
            refined model without them (the shipped fit: one-room and building frames); False:
            every localized record fits the refined model and no ``"places"`` model is kept
            (a map's own calibration: one map, its frames all of one kind).
    """

    s2_floor_quantile: float = 0.9
    operating_points_m: tuple[float, ...] = (0.05, 0.10, 0.20)
    nees_target: float = 6.0
    min_cell_records: int = 5
    features: tuple[str, ...] = FEATURES
    metric_offsets: bool = True
    ridge: float = 1e-2
    chi2_ratio_grid: tuple[float, ...] = (1.0, 1.25, 1.5, 2.0, 2.5, 3.0, 4.0, 6.0)
    min_confidence_grid: tuple[float, ...] = tuple(round(0.01 * k, 2) for k in range(61))
    min_confidence_grid_places: tuple[float, ...] = tuple(round(0.01 * k, 2)
                                                          for k in range(100))
    false_accept_error_m: float = 0.5
    false_accept_target: float = 0.01
    false_accept_tuning_margin: float = 0.5
    good_error_m: float = TOLERANCE_POSITION_M
    places_model: bool = True


# ------------------------------------------------------------------ the fit


def variance_factor(r: SolveRecord, floor: float) -> float:
    """The record's ``max(s^2, f) t(n)`` for the floor ``f`` (as
    ``confidence.variance_factor``)."""
    return max(r.s2, floor) * student_t_factor(r.n_refined)


def fit_s2_floor(records: Iterable[SolveRecord], quantile: float) -> float | None:
    """``f``: the ``quantile`` of ``s^2`` over the localized records with a finite ``s^2``
    (None without any)."""
    s2 = [r.s2 for r in records if r.localized and math.isfinite(r.s2)]
    return float(np.quantile(s2, quantile)) if s2 else None


def fit_covariance_scale(records: Sequence[SolveRecord], floor: float,
                         settings: FitSettings = FitSettings()) -> float | None:
    """``k`` for the floor ``f``: each group's mean NEES at ``k = 1`` over the records within
    each operating point (cells of at least ``min_cell_records``) is a cell; ``k`` puts the
    geometric mean of the smallest and largest cell at ``nees_target``. None without a cell."""
    cells = []
    for group in sorted({r.group for r in records}):
        for t in settings.operating_points_m:
            v = [r.nees * r.cov_scale / variance_factor(r, floor) for r in records
                 if math.isfinite(r.nees) and r.position_error_m <= t and r.group == group]
            if len(v) >= settings.min_cell_records:
                cells.append(float(np.mean(v)))
    if not cells:
        return None
    return math.sqrt(min(cells) * max(cells)) / settings.nees_target


def refeature(r: SolveRecord, scale: Mapping[str, float],
              floor: Mapping[str, float]) -> SolveRecord:
    """The record as if solved with the constants ``scale`` / ``floor``: its residual feature
    ``log_s2`` and, with a covariance, the covariance (scale, traces, NEES) and its feature
    ``logit_gauss`` (formulas of ``confidence.evidence_features``); unchanged without ``s^2``
    or constants for its key."""
    if r.key not in floor or not math.isfinite(r.s2):
        return r
    f = floor[r.key]
    feats = dict(r.features)
    feats["log_s2"] = math.log(max(r.s2, f) / f)
    if not math.isfinite(r.cov_trace_position_m2):
        return dataclasses.replace(r, features=feats)
    new = scale[r.key] * variance_factor(r, f)
    ratio = new / r.cov_scale
    tr_rot, tr_pos = r.cov_trace_rotation_rad2 * ratio, r.cov_trace_position_m2 * ratio
    p = gaussian_tolerance_probability(np.diag([tr_rot, 0.0, 0.0, tr_pos, 0.0, 0.0]))
    p = min(max(p, 1e-6), 1 - 1e-6)
    feats["logit_gauss"] = math.log(p / (1 - p))
    return dataclasses.replace(r, features=feats, cov_scale=new, nees=r.nees / ratio,
                               cov_trace_rotation_rad2=tr_rot, cov_trace_position_m2=tr_pos)


def fit_logistic(X: np.ndarray, y: np.ndarray, ridge: float = 1e-2) -> np.ndarray:
    """Logistic regression by Newton's method with an L2 penalty ``ridge`` (not on the
    intercept). ``X`` (n, d), ``y`` (n,) in {0, 1}; returns (d + 1,), intercept first."""
    A = np.column_stack([np.ones(len(X)), X])
    w = np.zeros(A.shape[1])
    R = ridge * np.eye(A.shape[1])
    R[0, 0] = 0.0
    for _ in range(100):
        p = 1.0 / (1.0 + np.exp(-np.clip(A @ w, -50, 50)))
        g = A.T @ (p - y) + R @ w
        H = (A * (p * (1 - p))[:, None]).T @ A + R + 1e-9 * np.eye(len(w))
        step = np.linalg.solve(H, g)
        w -= step
        if np.abs(step).max() < 1e-8:
            break
    return w


def fit_confidence_models(records: Sequence[SolveRecord], settings: FitSettings = FitSettings(),
                          base: Mapping[str, LogisticModel] | None = None
                          ) -> dict[str, LogisticModel]:
    """The logistic models of ``confidence`` (coefficients rounded to 6 decimals) on the
    localized records (features as recorded: :func:`refeature` them first): ``"refined"``
    over every key but ``"none"``, with an intercept offset per key (``level_set`` the
    reference) when ``settings.metric_offsets``; ``"none"`` over the unrefined answers,
    without :data:`REFINED_ONLY`; with ``settings.places_model``, both without the answers
    of a place search (:func:`place_search`), which fit ``"places"``: the refined model's
    log-odds recalibrated (``intercept + coef["refined_logit"] * z``,
    ``confidence.confidence_logit``). A model without records is ``base``'s (``"places"``:
    absent when ``base`` has none or without ``settings.places_model``)."""
    models: dict[str, LogisticModel] = {}
    apart = settings.places_model
    for name in ("refined", UNREFINED_KEY):
        rr = [r for r in records if r.localized and not (apart and place_search(r))
              and (r.key == UNREFINED_KEY) == (name != "refined")]
        if not rr:
            if base is None or name not in base:
                raise CalibrationFitError(f"no localized record for the {name!r} model")
            models[name] = base[name]
            continue
        use = [f for f in settings.features if not (name == UNREFINED_KEY and f in REFINED_ONLY)]
        offsets = sorted({r.key for r in rr} - {REFERENCE_KEY, UNREFINED_KEY}) \
            if settings.metric_offsets else []
        X = np.array([[r.features[f] for f in use] + [float(r.key == m) for m in offsets]
                      for r in rr])
        y = np.array([success(r) for r in rr], dtype=float)
        w = fit_logistic(X, y, settings.ridge)
        model: LogisticModel = {
            "intercept": round(float(w[0]), 6),
            "coef": {f: round(float(c), 6) for f, c in zip(use, w[1:1 + len(use)], strict=True)}}
        if offsets:
            model["metric_offset"] = {
                m: round(float(c), 6) for m, c in zip(offsets, w[1 + len(use):], strict=True)}
        models[name] = model
    if not apart:
        return models
    rp = [r for r in records if r.localized and place_search(r) and r.key != UNREFINED_KEY]
    if rp:
        z = np.array([[refined_logit(r.key, r.features, models)] for r in rp])
        w = fit_logistic(z, np.array([success(r) for r in rp], dtype=float), settings.ridge)
        models[PLACES_MODEL] = {"intercept": round(float(w[0]), 6),
                                "coef": {"refined_logit": round(float(w[1]), 6)}}
    elif base is not None and PLACES_MODEL in base:
        models[PLACES_MODEL] = base[PLACES_MODEL]
    return models


@dataclass(frozen=True)
class Decision:
    """What ``localize`` would answer for a decision record under other constants."""

    localized: bool
    reason: str | None
    confidence: float


def decide(r: SolveRecord, chi2_ratio: float, min_confidence: float,
           models: Mapping[str, LogisticModel] | None = None,
           confidence: float | None = None, minimal_ratio: float | None = None) -> Decision:
    """The answer to a decision record's frame (its unchecked answer: every verified pose,
    with its evidence) under ``chi2_ratio`` / ``min_confidence`` / ``models`` (None: the
    shipped models): ambiguous as ``confidence.is_ambiguous`` decides (a runner-up whose chi2
    compares competes when ``chi2_competitor <= log(chi2_ratio)``, the others by IoU sum:
    ``iou_competitor > 0``), else ``low_confidence`` below ``min_confidence`` (``confidence``:
    the record's probability under ``models`` when already computed). ``minimal_ratio``: the
    ratio of a place-search answer of a minimal sample of inliers
    (``confidence.answer_chi2_ratio``)."""
    if not r.localized:
        return Decision(False, r.reason, 0.0)
    conf = confidence_probability(r.key, r.features, models) if confidence is None else confidence
    ev = r.features
    ratio = answer_chi2_ratio(chi2_ratio, minimal_ratio, place_search(r), n_inliers(r))
    if ev.get("iou_competitor", 0.0) > 0 or ev["chi2_competitor"] <= math.log(ratio):
        return Decision(False, "ambiguous", conf)
    if conf < min_confidence:
        return Decision(False, "low_confidence", conf)
    return Decision(True, None, conf)


@dataclass(frozen=True)
class DecisionOutcome:
    """Of a decision set under some constants: ``false_accepts`` (localized, more than
    ``false_accept_error_m`` off) of ``frames``; ``kept`` (localized) of the ``good`` frames
    (unchecked answer within ``good_error_m``)."""

    frames: int
    false_accepts: int
    good: int
    kept: int


def decision_outcome(records: Sequence[SolveRecord], chi2_ratio: float, min_confidence: float,
                     models: Mapping[str, LogisticModel] | None = None,
                     settings: FitSettings = FitSettings(),
                     confidences: Sequence[float] | None = None,
                     minimal_ratio: float | None = None) -> DecisionOutcome:
    """:class:`DecisionOutcome` of decision records under these constants (:func:`decide`;
    ``confidences``: the records' probabilities under ``models``, when computed)."""
    fa = kept = good = 0
    for i, r in enumerate(records):
        loc = decide(r, chi2_ratio, min_confidence, models,
                     None if confidences is None else confidences[i], minimal_ratio).localized
        fa += int(loc and r.position_error_m > settings.false_accept_error_m)
        if r.position_error_m <= settings.good_error_m:
            good += 1
            kept += int(loc)
    return DecisionOutcome(len(records), fa, good, kept)


def decision_sets(records: Iterable[SolveRecord]) -> dict[str, list[SolveRecord]]:
    """The decision records per ``decision_set`` (in order of first appearance)."""
    sets: dict[str, list[SolveRecord]] = {}
    for r in records:
        if r.decision_set:
            sets.setdefault(r.decision_set, []).append(r)
    return sets


def _set_confidences(sets: Mapping[str, Sequence[SolveRecord]],
                     models: Mapping[str, LogisticModel]) -> dict[str, list[float]]:
    """Each decision record's probability under ``models`` (0 when not localized), per set."""
    return {name: [confidence_probability(r.key, r.features, models) if r.localized else 0.0
                   for r in rows] for name, rows in sets.items()}


def choose_ambiguity_and_threshold(
    sets: Mapping[str, Sequence[SolveRecord]], models: Mapping[str, LogisticModel],
    settings: FitSettings = FitSettings(),
) -> tuple[float, float] | None:
    """``(AMBIGUITY_CHI2_RATIO, MIN_CONFIDENCE)``: for each ratio of the grid, the smallest
    threshold whose false accepts are <= ``false_accept_target x false_accept_tuning_margin``
    of the frames in every set; of those, the pair keeping the most good frames (ties: the
    larger ratio, more cautious). None when no pair meets the target, or without decision
    sets (nothing to choose on: e.g. a map's calibration from the user's frames)."""
    if not sets:
        return None
    confs = _set_confidences(sets, models)
    return _most_kept_pair(
        sets, settings.chi2_ratio_grid, settings.min_confidence_grid, settings,
        lambda name, rows, ratio, t: decision_outcome(rows, ratio, t, models, settings,
                                                      confs[name]))


def _most_kept_pair(
    sets: Mapping[str, Sequence[SolveRecord]], ratios: Sequence[float],
    thresholds: Sequence[float], settings: FitSettings,
    outcome: Callable[[str, Sequence[SolveRecord], float, float], DecisionOutcome],
) -> tuple[float, float] | None:
    """The rule of both choosers: for each ratio of ``ratios``, the smallest of
    ``thresholds`` whose false accepts (``outcome`` of each set at that ratio and threshold)
    are <= ``false_accept_target x false_accept_tuning_margin`` of the frames in every set;
    of those, the ``(ratio, threshold)`` keeping the most good frames (ties: the larger
    ratio, more cautious). None when no pair meets the target."""
    limit = settings.false_accept_target * settings.false_accept_tuning_margin
    best: tuple[int, float, float] | None = None
    for ratio in ratios:
        for t in thresholds:
            outs = [outcome(name, rows, ratio, t) for name, rows in sets.items()]
            if all(o.false_accepts <= limit * o.frames for o in outs):
                kept = sum(o.kept for o in outs)
                if best is None or (kept, ratio) >= (best[0], best[1]):
                    best = (kept, ratio, t)
                break
    return None if best is None else (best[1], best[2])


def choose_place_threshold(
    sets: Mapping[str, Sequence[SolveRecord]], models: Mapping[str, LogisticModel],
    chi2_ratio: float, settings: FitSettings = FitSettings(),
) -> tuple[float, float] | None:
    """``(AMBIGUITY_CHI2_RATIO_MINIMAL_PLACES, MIN_CONFIDENCE_PLACES)`` by the rule of
    :func:`choose_ambiguity_and_threshold`: for each ratio of the grid at least ``chi2_ratio``
    (the ambiguity ratio chosen on the other sets, which holds every other answer), the
    smallest threshold whose false accepts are <= ``false_accept_target x
    false_accept_tuning_margin`` of the frames in every set; of those, the pair keeping the
    most good frames (ties: the larger ratio). ``sets``: decision records of place-search
    answers (:func:`place_search`), e.g. one set per map size and repetition mode of building
    frames. None without sets or when no pair meets the target."""
    sets = {name: rows for name, rows in sets.items() if rows}
    if not sets:
        return None
    confs = _set_confidences(sets, models)
    return _most_kept_pair(
        sets, [r for r in settings.chi2_ratio_grid if r >= chi2_ratio],
        settings.min_confidence_grid_places, settings,
        lambda name, rows, minimal, t: decision_outcome(rows, chi2_ratio, t, models, settings,
                                                        confs[name], minimal))


def fit_calibration(records: Sequence[SolveRecord], base: CalibrationConstants,
                    settings: FitSettings = FitSettings(),
                    provenance: Mapping[str, Any] | None = None) -> CalibrationConstants:
    """New constants from tuning records (module docstring, steps 1-4). ``base``: the
    constants the records were solved with; keys without covariance records, a model without
    records, the IoU-sum ambiguity ratios and (when no pair meets the false-accept target)
    the ratio and threshold are carried over from it.

    Raises:
        CalibrationFitError: no record, or a record without the features the fit uses.
    """
    if not records:
        raise CalibrationFitError("no solve record")
    need = (*settings.features, "chi2_competitor")
    for r in records:
        if r.localized and any(f not in r.features for f in need):
            missing = sorted(f for f in need if f not in r.features)
            raise CalibrationFitError(f"a localized record of {r.key!r} lacks {missing}")
    scale, floor = dict(base.covariance_scale), dict(base.s2_floor)
    by_key: dict[str, list[SolveRecord]] = {}
    for r in records:
        if r.covariance and r.key != UNREFINED_KEY:
            by_key.setdefault(r.key, []).append(r)
    for key, rows in by_key.items():
        f = fit_s2_floor(rows, settings.s2_floor_quantile)
        if f is None:
            continue
        floor[key] = f
        k = fit_covariance_scale(rows, f, settings)
        if k is not None:
            scale[key] = k
    fitted = [refeature(r, scale, floor) if r.localized else r for r in records]
    models = fit_confidence_models([r for r in fitted if r.confidence], settings,
                                   base.confidence_models)
    sets = decision_sets(fitted)
    chosen = choose_ambiguity_and_threshold(
        {n: kept for n, rows in sets.items()
         if (kept := [r for r in rows if not place_search(r)])}, models, settings)
    ratio, threshold = chosen if chosen is not None else (base.ambiguity_chi2_ratio,
                                                          base.min_confidence)
    places = choose_place_threshold(
        {n: [r for r in rows if place_search(r)] for n, rows in sets.items()}, models, ratio,
        settings)
    minimal, place_threshold = ((base.ambiguity_chi2_ratio_minimal_places,
                                 base.min_confidence_places) if places is None else places)
    return CalibrationConstants(
        covariance_scale={k: round(v, 6) for k, v in scale.items()},
        s2_floor={k: round(v, 6) for k, v in floor.items()},
        ambiguity_chi2_ratio=ratio, ambiguity_ratio=base.ambiguity_ratio,
        ambiguity_ratio_same_objects=base.ambiguity_ratio_same_objects,
        min_confidence=threshold, confidence_features=tuple(settings.features),
        confidence_models=models, provenance=dict(provenance or {}),
        min_confidence_places=place_threshold, ambiguity_chi2_ratio_minimal_places=minimal)


# ------------------------------------------------------------------ the generated module


def calibration_source(c: CalibrationConstants) -> str:
    """The text of ``service/localization/calibration.py`` holding ``c`` (its provenance
    names the records file, their sha256 and the commands)."""
    p = c.provenance
    header = ["Calibration constants of :mod:`quadloc.service.localization.confidence`",
              "(generated: do not edit).", ""]
    if p.get("records"):
        header += ["Fitted (:mod:`quadloc.service.localization.calibration_fit`) from the solve "
                   "records", f"``{p['records']}`` by::", "", f"    {p.get('command', '')}", "",
                   f"The records were made by ``{p.get('records_command', '')}`` at commit "
                   f"{p.get('records_commit', '?')};",
                   "tuning seeds only (:data:`PROVENANCE`): ``bench.trust`` reports on other "
                   "seeds."]
    for x in p.get("extra_records", []):
        header += ["", f"With ``{x['records']}``, made by ``{x['records_command']}`` at commit "
                       f"{x['records_commit']} (tuning seeds {x['tuning_seeds']}; "
                       "``bench.building`` reports on other seeds)."]
    doc = "\n".join(header).rstrip()

    def fmt(v: object, **kw: Any) -> str:
        return pprint.pformat(v, width=96, **kw)

    return f'''"""{doc}
"""
# ruff: noqa: E501  (generated: the commands and sha256 sums are not wrapped)

PROVENANCE = {fmt(p, sort_dicts=False)}

#: k_key of ``cov = k * max(s^2, f) * t(n) * (J^T W J)^-1`` (``calibration_fit.
#: fit_covariance_scale``: the smallest and largest mean NEES over the 5 / 10 / 20 cm operating
#: points and the recording groups of the tuning frames centred on 6).
COVARIANCE_SCALE = {fmt(c.covariance_scale, sort_dicts=False)}

#: f_key: floor of the a-posteriori variance factor (``calibration_fit.fit_s2_floor``: the 0.9
#: quantile of the tuning frames' s^2).
S2_FLOOR = {fmt(c.s2_floor, sort_dicts=False)}

#: Runner-up / best refined chi2 (same detections, same metric) at and below which an answer is
#: ambiguous (``confidence.is_ambiguous``; ``calibration_fit.choose_ambiguity_and_threshold``).
AMBIGUITY_CHI2_RATIO = {c.ambiguity_chi2_ratio!r}

#: Runner-up / best score (sum of inlier IoUs) at and above which an answer is ambiguous, when
#: their chi2 do not compare.
AMBIGUITY_RATIO = {c.ambiguity_ratio!r}

#: The same ratio for a runner-up matching the same map objects (``confidence.is_ambiguous``).
AMBIGUITY_RATIO_SAME_OBJECTS = {c.ambiguity_ratio_same_objects!r}

#: Default ``LocalizationOptions.min_confidence`` (with ``AMBIGUITY_CHI2_RATIO``:
#: ``calibration_fit.choose_ambiguity_and_threshold``).
MIN_CONFIDENCE = {c.min_confidence!r}

#: The same default for the answers of a place search (a large map), chosen on the building
#: frames' decision sets at that ratio (``calibration_fit.choose_place_threshold``).
MIN_CONFIDENCE_PLACES = {c.default_min_confidence(True)!r}

#: The ambiguity chi2 ratio of a place-search answer held by a minimal sample of inliers
#: (``confidence.answer_chi2_ratio``), chosen with ``MIN_CONFIDENCE_PLACES``.
AMBIGUITY_CHI2_RATIO_MINIMAL_PLACES = {c.answer_chi2_ratio(True, MINIMAL_SAMPLE_INLIERS)!r}

#: Features of the confidence model (``confidence.evidence_features``), in order.
CONFIDENCE_FEATURES = {fmt(c.confidence_features)}

#: Logistic models: P = 1 / (1 + exp(-(intercept + metric_offset + sum coef * feature))); an
#: answer of the place search: P = 1 / (1 + exp(-(places intercept + coef * z))), z the refined
#: model's log-odds (``confidence.confidence_logit``).
CONFIDENCE_MODELS = {fmt(c.confidence_models, sort_dicts=False)}
'''


# ------------------------------------------------------------------ record files

_FLOAT_COLUMNS = ("position_error_m", "rotation_error_deg", "s2", "cov_scale", "nees",
                  "cov_trace_rotation_rad2", "cov_trace_position_m2")


def _enc(v: float) -> float | str | None:
    """A float for JSON: NaN -> null, +-inf -> "inf" / "-inf" (exact otherwise: repr)."""
    if math.isnan(v):
        return None
    if math.isinf(v):
        return "inf" if v > 0 else "-inf"
    return v


def _dec(v: float | str | None) -> float:
    return math.nan if v is None else float(v)


def write_records(path: Path, records: Sequence[SolveRecord],
                  provenance: Mapping[str, Any]) -> None:
    """Write records as gzip JSON (columns; floats exact, NaN as null, inf as ``"inf"``;
    gzip without a timestamp, so the same records give the same bytes). ``provenance``:
    how they were made (command, commit, seeds, ...)."""
    names = sorted({f for r in records for f in r.features})
    cols: dict[str, Any] = {
        "key": [r.key for r in records], "group": [r.group for r in records],
        "localized": [r.localized for r in records], "reason": [r.reason for r in records],
        "n_refined": [r.n_refined for r in records],
        "covariance": [r.covariance for r in records],
        "confidence": [r.confidence for r in records],
        "decision_set": [r.decision_set for r in records]}
    for c in _FLOAT_COLUMNS:
        cols[c] = [_enc(getattr(r, c)) for r in records]
    cols["features"] = {f: [_enc(r.features.get(f, math.nan)) for r in records] for f in names}
    doc = {"format": RECORDS_FORMAT, "provenance": dict(provenance), "n": len(records),
           "columns": cols}
    text = json.dumps(doc, separators=(",", ":"), allow_nan=False)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "wb") as fh, gzip.GzipFile(fileobj=fh, mode="wb", mtime=0,
                                               filename="") as gz:
        gz.write(text.encode("utf-8"))


def read_records(path: Path) -> tuple[list[SolveRecord], dict[str, Any]]:
    """(records, provenance) of a file written by :func:`write_records`.

    Raises:
        CalibrationFitError: not such a file.
    """
    try:
        doc = json.loads(gzip.decompress(Path(path).read_bytes()).decode("utf-8"))
    except (OSError, ValueError) as exc:
        raise CalibrationFitError(f"{path}: not a gzip JSON record file ({exc})") from exc
    if not isinstance(doc, dict) or doc.get("format") != RECORDS_FORMAT:
        raise CalibrationFitError(f"{path}: format is not {RECORDS_FORMAT!r}")
    cols, n = doc["columns"], int(doc["n"])
    feats = {f: [_dec(v) for v in vals] for f, vals in cols["features"].items()}
    floats = {c: [_dec(v) for v in cols[c]] for c in _FLOAT_COLUMNS}
    records = [SolveRecord(
        key=cols["key"][i], group=cols["group"][i], localized=bool(cols["localized"][i]),
        reason=cols["reason"][i], position_error_m=floats["position_error_m"][i],
        rotation_error_deg=floats["rotation_error_deg"][i],
        features={f: v[i] for f, v in feats.items()}, s2=floats["s2"][i],
        n_refined=int(cols["n_refined"][i]), cov_scale=floats["cov_scale"][i],
        nees=floats["nees"][i], cov_trace_rotation_rad2=floats["cov_trace_rotation_rad2"][i],
        cov_trace_position_m2=floats["cov_trace_position_m2"][i],
        covariance=bool(cols["covariance"][i]), confidence=bool(cols["confidence"][i]),
        decision_set=cols["decision_set"][i]) for i in range(n)]
    return records, dict(doc.get("provenance", {}))


def sha256_file(path: Path) -> str:
    """Hex sha256 of a file's bytes."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def display_path(path: Path) -> str:
    """``path`` relative to the working directory when inside it (a checkout's
    ``bench/data/...``), else its file name: never a machine-local absolute path."""
    p = Path(path).resolve()
    try:
        return p.relative_to(Path.cwd().resolve()).as_posix()
    except ValueError:
        return p.name


def fit_file(records_path: Path, base: CalibrationConstants | None = None,
             settings: FitSettings = FitSettings(),
             command: str | None = None,
             extra_records: Sequence[Path] = ()) -> CalibrationConstants:
    """:func:`fit_calibration` of a record file (and of ``extra_records``, e.g. the building
    frames' records of ``bench.building --calibration-records``, fitted together with it),
    their provenance (records, sha256, the records' own provenance, ``command``) in the
    constants. ``base``: default the shipped constants."""
    records, made = read_records(records_path)
    shown = display_path(records_path)
    flags = "" if settings.metric_offsets else " --no-metric-offsets"
    extra_shown = "".join(f" {display_path(x)}" for x in extra_records)
    prov: dict[str, Any] = {
        "records": shown, "records_sha256": sha256_file(records_path),
        "command": command or f"python -m quadloc.service.localization.calibration_fit "
                              f"{shown}{extra_shown}{flags}",
        "records_command": made.get("command", ""), "records_commit": made.get("commit", ""),
        "tuning_seeds": made.get("tuning_seeds", [])}
    if extra_records:
        prov["extra_records"] = []
        for path in extra_records:
            more, made_more = read_records(path)
            records = [*records, *more]
            prov["extra_records"].append({
                "records": display_path(path), "records_sha256": sha256_file(path),
                "records_command": made_more.get("command", ""),
                "records_commit": made_more.get("commit", ""),
                "tuning_seeds": made_more.get("tuning_seeds", [])})
    return fit_calibration(records, CalibrationConstants.shipped() if base is None else base,
                           settings, prov)


def main(argv: list[str] | None = None) -> int:
    """``python -m quadloc.service.localization.calibration_fit RECORDS [--output PATH |
    --check]``: fit and write the calibration module (default: the installed
    ``calibration.py``), or check that the shipped constants are the refit (exit 1 with the
    differences otherwise)."""
    ap = argparse.ArgumentParser(description=main.__doc__)
    ap.add_argument("records", type=Path, help="gzip JSON solve records (write_records)")
    ap.add_argument("extra_records", type=Path, nargs="*",
                    help="more record files fitted with them (e.g. building frames')")
    ap.add_argument("--output", type=Path, default=Path(__file__).with_name("calibration.py"))
    ap.add_argument("--no-metric-offsets", dest="metric_offsets", action="store_false",
                    help="no per-key intercept offsets in the refined confidence model")
    ap.add_argument("--check", action="store_true",
                    help="compare the refit with the shipped constants, write nothing")
    args = ap.parse_args(argv)
    try:
        fitted = fit_file(args.records,
                          settings=FitSettings(metric_offsets=args.metric_offsets),
                          extra_records=args.extra_records)
    except CalibrationFitError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if args.check:
        diff = CalibrationConstants.shipped().differences(fitted)
        for d in diff:
            print(d)
        print("shipped constants reproduced" if not diff else f"{len(diff)} difference(s)")
        return 1 if diff else 0
    args.output.write_text(calibration_source(fitted))
    print(f"wrote {display_path(args.output)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
