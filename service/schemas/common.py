"""Wire format of the REST API (pydantic v2 models; the OpenAPI document is generated from them).

Conventions (also in the OpenAPI descriptions and docs/api.md): pixels from the top-left pixel
corner, +x right, +y down; ellipses ``{cx, cy, a, b, angle}``: centre px, SEMI-axes px (``a``
along ``angle``), ``angle`` in radians from +x towards +y; a box becomes its inscribed ellipse;
``sigma = exp(alpha / 2)`` for ``log_variance = alpha``. Poses ``world_from_camera`` (m) as unit
``quaternion_wxyz`` (``w >= 0``) + ``translation_m`` and a 4x4, OpenCV camera axes unless
``"opengl"`` (``world_from_camera_gl = world_from_camera_cv @ diag(1, -1, -1, 1)``).
Covariances 6x6 ``[omega_x, omega_y, omega_z, v_x, v_y, v_z]`` (rad, m), right perturbation,
camera (body) frame. Floats must be finite and unknown fields are rejected (422 naming the field).

This module: the shared pieces (the strict base model, integral numbers, matrix rows, the camera
convention), the health answer and the RFC 9457 problem document.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Annotated, Any, Literal

from pydantic import (
    AfterValidator,
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
)
from pydantic_core import PydanticCustomError

from quadloc.factors.names import json_path, label_problem, text_problem

__all__ = [
    "API_VERSION",
    "COVARIANCE_FRAME",
    "Convention",
    "HealthOut",
    "Int",
    "LabelText",
    "Problem",
    "ProblemField",
    "Row4",
    "Row6",
    "Text",
    "WireModel",
    "field_path",
    "integral",
]


#: Version of the REST API (the wire format): the OpenAPI document's ``info.version``.
API_VERSION = "1.0.0"

COVARIANCE_FRAME = "camera (body) frame, right perturbation T*exp(xi), omega in rad, v in m"


Convention = Literal["opencv", "opengl"]


def integral(value: Any) -> Any:
    """JSON Schema's ``integer`` includes integral floats (``640.0``): accept them as ints
    (other floats, strings and booleans still fail the strict check, naming the field)."""
    if isinstance(value, float) and value.is_integer() and abs(value) <= 2**53:
        return int(value)
    return value


#: An integer field that also accepts integral JSON numbers such as ``640.0``.
Int = Annotated[int, BeforeValidator(integral)]


#: Rows of a pose matrix / covariance (the shapes are in the schema).
Row4 = Annotated[list[float], Field(min_length=4, max_length=4)]


Row6 = Annotated[list[float], Field(min_length=6, max_length=6)]


def _checked_text(value: str) -> str:
    problem = text_problem(value)
    if problem is not None:
        raise PydanticCustomError("text", "{message}", {"message": problem})
    return value


#: A text field that is stored or echoed (labels, frame ids): the rule of
#: :func:`quadloc.factors.names.text_problem` (no control character, no lone surrogate), 422
#: naming the field; lengths are the field's own.
Text = Annotated[str, AfterValidator(_checked_text)]


def _checked_label(value: str) -> str:
    problem = label_problem(value)
    if problem is not None:
        raise PydanticCustomError("text", "{message}", {"message": problem})
    return value


#: A text that becomes a map's label or name (a recording's): :data:`Text` and not blank, the
#: map document's rule (:func:`quadloc.factors.names.label_problem`), checked at intake.
LabelText = Annotated[str, AfterValidator(_checked_label)]


class WireModel(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False, strict=True)


class HealthOut(BaseModel):
    status: str
    checks: dict[str, str] = Field(default_factory=dict)


class ProblemField(BaseModel):
    field: str
    message: str


class Problem(BaseModel):
    """RFC 9457 problem details (media type application/problem+json)."""

    type: str
    title: str
    status: int
    detail: str
    instance: str | None = None
    errors: list[ProblemField] = Field(default_factory=list)


def field_path(loc: Sequence[Any]) -> str:
    """``('body', 'detections', 2, 'ellipse', 'a')`` -> ``'detections[2].ellipse.a'``.

    Body locations drop the ``body`` prefix and tagged-union tags (``~...``);
    ``query``/``header``/``path`` keep it (the path spelling is
    :func:`quadloc.factors.names.json_path`'s, the map documents' own).
    """
    # a tagged union's tag (spelled with a leading "~", e.g. the session frames body's) is
    # pydantic's, not a field of the request
    parts = [p for p in loc if not (isinstance(p, str) and p.startswith("~"))]
    if parts and parts[0] in ("query", "header", "path", "cookie"):
        return f"{parts[0]}.{json_path(parts[1:], 'body')}"
    return json_path(parts[1:] if parts and parts[0] == "body" else parts, "body")
