"""Wire models of a map's own calibration: ``POST /v1/maps/{map_id}/calibration`` (body: a
recording with ``holdout_every``, :mod:`quadloc.service.schemas.recording`) and ``GET`` of it.
Units: NEES dimensionless (6 for a well-scaled 6-DoF covariance), errors and rates in [0, 1]."""

from __future__ import annotations

from pydantic import BaseModel, Field

__all__ = ["CalibrationOut", "CalibrationQualityOut"]


class CalibrationQualityOut(BaseModel):
    """How well covariance and confidence describe the errors on the report frames."""

    frames: int = Field(description="Report frames solved.")
    localized: int = Field(description="Of them localized (min_confidence 0).")
    nees_frames: int = Field(description="Localized within 10 cm of the reference: the NEES "
                                         "frames.")
    mean_nees: float | None = Field(description="Mean NEES (6 = well scaled; the target band "
                                                "is [4, 9]).")
    calibration_error: float | None = Field(
        description="Expected calibration error of `confidence` (10 bins) against success = "
                    "within 10 cm and 5 deg of the reference.")
    calibration_error_floor: float | None = Field(
        default=None,
        description="The calibration error a perfectly calibrated `confidence` would show on "
                    "these answers by sampling alone (mean over 200 draws of outcomes from the "
                    "confidences): an error near it is as good as these frames can tell.")
    calibration_error_sd: float | None = Field(
        default=None,
        description="Sampling standard deviation of `calibration_error`: moving-block bootstrap "
                    "over blocks of 25 consecutive frames (their outcomes are correlated); "
                    "null with fewer than 50 localized frames.")
    mean_confidence: float | None
    success_rate: float | None


class CalibrationOut(BaseModel):
    """A map version's own calibration (used by localize for the calibration key it was fitted
    for; other keys keep the shipped constants)."""

    map_id: str
    map_version: int
    key: str = Field(description="Calibration key fitted (metric, ':unit_weights' without "
                                 "sigma on every detection).")
    fit_frames: int = Field(description="Held-out frames the stored fit used (all of them; "
                                        "`after` is cross-fitted: each frame reported by a fit "
                                        "on the other folds).")
    covariance_scale: float = Field(description="Fitted k of the key (shipped value in "
                                                "`shipped_covariance_scale`).")
    shipped_covariance_scale: float
    s2_floor: float
    min_confidence: float = Field(description="Default min_confidence with this calibration.")
    before: CalibrationQualityOut = Field(description="Held-out frames, shipped constants.")
    after: CalibrationQualityOut = Field(description="Held-out frames, each with a "
                                                     "calibration fitted without its fold "
                                                     "(5 folds of 25-frame chunks).")
