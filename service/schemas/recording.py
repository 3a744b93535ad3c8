"""Wire models of a recording: the body of ``POST /v1/maps:build`` (and of
``POST /v1/maps/{map_id}/calibration``), the file of ``quadloc maps build`` / ``quadloc
calibrate`` and what ``quadloc import-recording`` writes.

The recording speaks the dialect of localize and sessions: the same ``camera``
(:class:`CameraIn`), the same poses (:class:`PoseIn`: ``quaternion_wxyz`` or ``quaternion_xyzw``
+ ``translation_m``, or a 4x4 ``matrix``; camera axes of the recording's ``convention``) and the
same detections (:class:`DetectionIn`: ``ellipse`` or ``box`` object, ``sigma`` or
``log_variance``, ``score``) plus a ``track_id``. Unknown fields are refused (422 naming them).

The form of earlier releases (``intrinsics`` instead of ``camera``, ``box`` as an array
``[xmin, ymin, xmax, ymax]``) is still read for one release (:class:`LegacyRecordingIn`, marked
deprecated in the OpenAPI document); a build from it carries :data:`LEGACY_RECORDING_WARNING` in
its report. :data:`RecordingBody` is the union of both, told apart by the ``intrinsics`` key.
"""

from __future__ import annotations

from typing import Annotated, Any

from pydantic import ConfigDict, Discriminator, Field, Tag, model_validator

from quadloc.service.limits import MAX_DETECTIONS
from quadloc.service.schemas.common import Convention, Int, LabelText, Text, WireModel
from quadloc.service.schemas.localize import CameraIn, DetectionIn, PoseIn

__all__ = [
    "LEGACY_RECORDING_WARNING",
    "MAX_RECORDING_FRAMES",
    "LegacyDetectionIn",
    "LegacyFrameIn",
    "LegacyRecordingIn",
    "OdometryNoiseIn",
    "RecordingBody",
    "RecordingDetectionIn",
    "RecordingFrameIn",
    "RecordingIn",
    "SizePriorIn",
    "recording_form",
]

#: Schema bound on the frames of one recording (the server's ``QUADLOC_MAX_BUILD_FRAMES`` is
#: checked after validation and is usually lower).
MAX_RECORDING_FRAMES = 100_000

#: The build report's warning for a recording in the form of earlier releases.
LEGACY_RECORDING_WARNING = (
    "deprecated recording form ('intrinsics', boxes as arrays): it is read for one more "
    "release; send 'camera' and boxes as {xmin, ymin, xmax, ymax} (docs/map_building.md)")


class SizePriorIn(WireModel):
    """Prior on every log semi-axis of a label's objects: ``N(log semi_axis_m, log_sigma^2)``."""

    semi_axis_m: float = Field(gt=0, le=100, description="Typical semi-axis (m).")
    log_sigma: float = Field(default=0.5, gt=0, le=10,
                             description="Std of the log semi-axis (dimensionless).")


class OdometryNoiseIn(WireModel):
    """Noise of the app's poses between two recorded frames, a random walk (defaults shown;
    ``quadloc.maps.building.recording.OdometryNoise`` states the model)."""

    rotation_rad_per_sqrt_m: float = Field(default=0.005, ge=0, le=10)
    translation_m_per_sqrt_m: float = Field(default=0.01, ge=0, le=10)
    rotation_rad_per_step: float = Field(default=0.0005, gt=0, le=10,
                                         description="Floor per frame step (rad), > 0.")
    translation_m_per_step: float = Field(default=0.001, gt=0, le=10,
                                          description="Floor per frame step (m), > 0.")


class RecordingDetectionIn(DetectionIn):
    """A detection as for localize, plus an optional ``track_id``: detections of one track (and
    label) are one object."""

    label: LabelText = Field(min_length=1, max_length=128,
                             description="Category label: the built object's category.")
    track_id: Text | None = Field(default=None, min_length=1, max_length=128,
                                 description="The detector's / tracker's object track.")


class RecordingFrameIn(WireModel):
    """One recorded frame: the app's camera pose and the frame's detections."""

    frame_id: Text | None = Field(default=None, min_length=1, max_length=128,
                                 description="Defaults to the frame's position.")
    world_from_camera: PoseIn = Field(description="The app's camera pose (m), in the "
                                                  "recording's `convention`.")
    timestamp: float | None = Field(default=None, ge=-1e12, le=1e12,
                                    description="Client clock (s); informative.")
    detections: list[RecordingDetectionIn] = Field(default_factory=list,
                                                   max_length=MAX_DETECTIONS)


class _RecordingOptions(WireModel):
    """The build options of a recording (both forms)."""

    name: LabelText = Field(default="Built map", min_length=1, max_length=256,
                            description="Name of the built map.")
    up_axis: list[float] = Field(default=[0.0, 0.0, 1.0], min_length=3, max_length=3,
                                 description="World up direction of the app's world frame.")
    size_priors: dict[LabelText, SizePriorIn] = Field(
        default_factory=dict, description="Label -> prior on its objects' semi-axes.")
    refine_camera_poses: bool = Field(
        default=True, description="Refine the app's camera poses with the objects (tied by "
                                  "their relative poses with `odometry_noise`).")
    odometry_noise: OdometryNoiseIn = Field(default_factory=OdometryNoiseIn)
    holdout_every: Int | None = Field(
        default=None, ge=2, le=1000,
        description="Hold every k-th frame (positions k-1, 2k-1, ...) out of the build: those "
                    "frames, with their app poses as reference, calibrate the map "
                    "(POST /v1/maps/{map_id}/calibration with the same recording).")


class RecordingIn(_RecordingOptions):
    """A recording: the camera, posed frames with detections, build options."""

    model_config = ConfigDict(json_schema_extra={"examples": []})

    camera: CameraIn
    convention: Convention = Field(
        default="opencv", description="Camera axes of every `world_from_camera` (opengl = "
                                      "ARKit/ARCore).")
    frames: list[RecordingFrameIn] = Field(min_length=1, max_length=MAX_RECORDING_FRAMES)


class LegacyDetectionIn(RecordingDetectionIn):
    """A detection of the deprecated form: ``box`` may be an array ``[xmin, ymin, xmax, ymax]``
    and ``track_id`` an integer."""

    @model_validator(mode="before")
    @classmethod
    def _box_array(cls, data: Any) -> Any:
        if not isinstance(data, dict):
            return data
        box, track = data.get("box"), data.get("track_id")
        if isinstance(box, list) and len(box) == 4:
            data = {**data, "box": dict(zip(("xmin", "ymin", "xmax", "ymax"), box, strict=True))}
        if isinstance(track, int) and not isinstance(track, bool):  # ids were str | int
            data = {**data, "track_id": str(track)}
        return data


class LegacyFrameIn(RecordingFrameIn):
    """A frame of the deprecated form."""

    detections: list[LegacyDetectionIn] = Field(  # type: ignore[assignment]
        default_factory=list, max_length=MAX_DETECTIONS)

    @model_validator(mode="before")
    @classmethod
    def _integer_id(cls, data: Any) -> Any:
        fid = data.get("frame_id") if isinstance(data, dict) else None
        if isinstance(fid, int) and not isinstance(fid, bool):  # ids were str | int
            return {**data, "frame_id": str(fid)}
        return data


class LegacyRecordingIn(_RecordingOptions):
    """DEPRECATED form of earlier releases (``intrinsics``, boxes as arrays); read for one more
    release, its build report carries a deprecation warning."""

    model_config = ConfigDict(json_schema_extra={"deprecated": True})

    intrinsics: CameraIn
    frames: list[LegacyFrameIn] = Field(min_length=1, max_length=MAX_RECORDING_FRAMES)

    def upgraded(self) -> RecordingIn:
        """The same recording in the current form (OpenCV axes, as the old form's)."""
        data = self.model_dump(exclude_unset=True)
        data["camera"] = data.pop("intrinsics")
        return RecordingIn.model_validate(data)


def recording_form(value: Any) -> str:
    """Which form a recording body is: ``~legacy`` (it has ``intrinsics`` and no ``camera``)
    or ``~recording``."""
    if isinstance(value, dict):
        return "~legacy" if "intrinsics" in value and "camera" not in value else "~recording"
    return "~legacy" if isinstance(value, LegacyRecordingIn) else "~recording"


#: The body of ``POST /v1/maps:build``: a recording, or one in the deprecated form. The ``~``
#: tags are not fields (``quadloc.service.schemas.common.field_path`` drops them).
RecordingBody = Annotated[
    Annotated[RecordingIn, Tag("~recording")] | Annotated[LegacyRecordingIn, Tag("~legacy")],
    Discriminator(recording_form)]
