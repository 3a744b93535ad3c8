"""The calibration use cases: fit a map version's own calibration from a recording's held-out
frames (:func:`quadloc.service.localization.map_calibration.fit_map_calibration`), store it with
the version (``MapStore.set_calibration``), read it back, and give it to localize.

Stored document: ``{"constants": CalibrationConstants fields, "report": CalibrationOut}``.
"""

from __future__ import annotations

import dataclasses
from typing import Any, cast

from quadloc.maps.errors import MapNotFound
from quadloc.maps.store import MapStore
from quadloc.service.app.builds import validate_recording
from quadloc.service.app.conversions import RecordingInputError, held_out_frames_from_wire
from quadloc.service.app.errors import AppError, map_not_found
from quadloc.service.localization.calibration_fit import (
    CalibrationConstants,
    CalibrationFitError,
    LogisticModel,
)
from quadloc.service.localization.map_calibration import ReferenceFrame, fit_map_calibration
from quadloc.service.schemas.calibration import CalibrationOut, CalibrationQualityOut

__all__ = ["CalibrationService", "calibration_document"]


def calibration_document(constants: CalibrationConstants, report: CalibrationOut
                         ) -> dict[str, Any]:
    """The stored document of a map version's calibration (module docstring); read back by
    :meth:`CalibrationService.constants_of` and :meth:`CalibrationService.get`."""
    fields = dataclasses.asdict(constants)
    fields["confidence_features"] = list(constants.confidence_features)
    return {"constants": fields, "report": report.model_dump(mode="json")}


class CalibrationService:
    """A process's calibration use cases on ``store``."""

    def __init__(self, store: MapStore) -> None:
        self.store = store

    def calibrate(self, map_id: str, document: Any, version: int | None = None,
                  metric: str = "level_set") -> CalibrationOut:
        """Fit and store the calibration of ``map_id`` (latest version, or ``version``) from a
        recording's held-out frames (``holdout_every``; their app poses the reference).
        Refusals: ``map-not-found``; ``validation-error`` (invalid recording, no held-out
        frame, too few localized frames)."""
        recording = validate_recording(document)
        try:
            camera, held = held_out_frames_from_wire(recording)
        except RecordingInputError as exc:
            raise AppError("validation-error", f"invalid recording: {exc}",
                           errors=exc.errors) from exc
        if not held:
            raise AppError("validation-error", "the recording holds no frame out of the build: "
                           "set holdout_every (as for the build) so that the map did not see "
                           "the frames that calibrate it", field="holdout_every",
                           message="required for calibration")
        try:
            compiled = self.store.compiled(map_id, version)
        except MapNotFound as exc:
            raise map_not_found(map_id, version) from exc
        try:
            cal = fit_map_calibration([ReferenceFrame(f, T, d) for f, T, d in held], compiled,
                                      camera, metric=metric)
        except CalibrationFitError as exc:
            raise AppError("validation-error", f"cannot calibrate: {exc}", field="frames",
                           message=str(exc)) from exc
        shipped = CalibrationConstants.shipped()
        out = CalibrationOut(
            map_id=compiled.map_id, map_version=compiled.version, key=cal.key,
            fit_frames=cal.fit_frames, covariance_scale=cal.constants.covariance_scale[cal.key],
            shipped_covariance_scale=shipped.covariance_scale.get(cal.key, float("nan")),
            s2_floor=cal.constants.s2_floor[cal.key],
            min_confidence=cal.constants.min_confidence,
            before=CalibrationQualityOut(**dataclasses.asdict(cal.before)),
            after=CalibrationQualityOut(**dataclasses.asdict(cal.after)))
        self.store.set_calibration(compiled.map_id, compiled.version,
                                   calibration_document(cal.constants, out))
        return out

    def get(self, map_id: str, version: int | None = None) -> CalibrationOut:
        """The stored calibration of a map version; ``map-not-found`` / ``not-found``."""
        try:
            v = version if version is not None else self.store.get(map_id).scene_map.version
        except MapNotFound as exc:
            raise map_not_found(map_id) from exc
        doc = self.store.calibration(map_id, v)
        if doc is None:
            raise AppError("not-found", f"version {v} of map {map_id!r} has no calibration "
                           "(quadloc calibrate)", field="path.map_id", message="no calibration")
        return CalibrationOut.model_validate(doc["report"])

    def constants_of(self, map_id: str, version: int) -> CalibrationConstants | None:
        """The calibration constants of a map version for localize, or None (shipped)."""
        doc = self.store.calibration(map_id, version)
        if doc is None:
            return None
        c = dict(doc["constants"])
        c["confidence_features"] = tuple(c["confidence_features"])
        c["confidence_models"] = cast(dict[str, LogisticModel], c["confidence_models"])
        return CalibrationConstants(**c)
