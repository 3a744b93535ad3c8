"""The report of a map build: which detections built which object, each object's quality, the
objects left out and why, the detections rejected and why, counts, the joint refinement and
timings. One typed model (pydantic), built by :func:`quadloc.maps.building.build.build_map`,
stored with the build job as JSON and served as is by the API (its OpenAPI schema is this
model's). Units are in the field names (``_m``, ``_deg``, ``_s``); frame and detection indices
are 0-based positions in the recording.
"""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field

__all__ = [
    "BuildCounts",
    "BuildReport",
    "DetectionRef",
    "DroppedObject",
    "ObjectQualityReport",
    "ObjectReport",
    "RefinementReport",
    "RejectedDetection",
]


class _ReportModel(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class DetectionRef(_ReportModel):
    """A detection of the recording: its frame (id and position) and its position in it."""

    frame_id: str | None
    frame_index: int
    detection_index: int


class ObjectQualityReport(_ReportModel):
    """How well the views determine an object (``quadloc.maps.building.joint``)."""

    n_views: int
    view_spread_deg: float = Field(description="Largest angle between two viewing rays (deg).")
    residual_cost: float
    rms_level_residual: float = Field(description="RMS level-set residual of its views.")
    log_semi_axis_std: list[float] = Field(description="Std of log(semi-axis), per axis.")
    center_std_m: float = Field(description="Largest std of the centre along a direction (m).")
    unconstrained_axes: list[int] = Field(description="Semi-axes the views do not constrain.")
    semi_axes_m: list[float]


class ObjectReport(_ReportModel):
    """An object of the built map and the detections it was built from."""

    object_id: str
    label: str
    association: str = Field(description="How its detections were grouped (track or geometry).")
    detections: list[DetectionRef]
    quality: ObjectQualityReport


class DroppedObject(_ReportModel):
    """An object reconstructed but left out of the map."""

    object_id: str
    label: str
    reason: str = Field(description="degenerate_shape, rarely_seen, unconstrained or "
                                    "center_unconstrained.")
    detail: str
    n_views: int
    semi_axes_m: list[float]


class RejectedDetection(DetectionRef):
    """A detection that built no object of the map, and why."""

    label: str
    reason: str


class BuildCounts(_ReportModel):
    frames: int
    detections: int
    objects: int
    rejected_detections: int


class RefinementReport(_ReportModel):
    """The joint refinement of objects (and camera poses) over every view."""

    iterations: int
    initial_error: float
    final_error: float
    stopped_early: bool = Field(description="The time budget stopped it: the map holds the "
                                            "estimate at that point.")
    camera_poses_refined: bool


class BuildReport(_ReportModel):
    """The report of one build (module docstring)."""

    objects: list[ObjectReport]
    dropped_objects: list[DroppedObject]
    rejected_detections: list[RejectedDetection]
    counts: BuildCounts
    refinement: RefinementReport | None = Field(description="None when no object was found.")
    timings_s: dict[str, float] = Field(description="association, refinement, total (s).")
    warnings: list[str] = Field(default_factory=list,
                                description="What the user should know about this map.")
