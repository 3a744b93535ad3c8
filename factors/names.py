"""Names and rules shared by the math layer and everything above it; dependency-free (stdlib).

Importing this module loads neither numpy nor gtsam, so the service's settings and wire schemas
can publish the valid names and apply the same rules without loading the solver
(``quadloc.service.limits`` re-exports the names).

* :data:`METRIC_NAMES`, :data:`ROBUST_KERNELS`: the valid names.
* :class:`FieldError`: THE error of invalid input, with a structured ``field``;
  :class:`GeometryError`, its kind for geometric input.
* :func:`is_real`, :func:`check_robust`: rules used by every layer that takes these inputs.
* :func:`json_path`: THE spelling of a field path in every error (``objects[3].axes[1]``).
* :func:`text_problem`: THE rule for text a client sends that is stored or echoed (ids, labels,
  names, frame and track ids): no control character, no lone surrogate; :func:`scrubbed_text`
  makes text read back from storage serialisable whatever it holds.
"""

from __future__ import annotations

import math
import numbers
import re
from collections.abc import Sequence
from typing import TypeGuard

__all__ = [
    "CONTROL_MESSAGE",
    "METRIC_NAMES",
    "ROBUST_KERNELS",
    "SURROGATE_MESSAGE",
    "FieldError",
    "GeometryError",
    "check_robust",
    "is_real",
    "json_path",
    "label_problem",
    "scrubbed_text",
    "text_problem",
]

#: The nine ellipse metrics (``quadloc.factors.metrics.residual``,
# ``quadloc.factors.pose_factors``).
METRIC_NAMES: tuple[str, ...] = (
    "iou", "giou", "bbox", "qbbox", "algebraic", "frobenius", "wasserstein", "bhattacharyya",
    "level_set",
)

#: Robust kernels accepted by name (``quadloc.factors.pose_factors.make_noise_model``).
ROBUST_KERNELS: tuple[str, ...] = ("huber", "cauchy", "geman_mcclure")


class FieldError(ValueError):
    """Invalid input naming its field. ``field`` is a path into the caller's input (e.g.
    ``"detections[2].label"``, ``"prior.world_from_camera"``) or None when unknown; ``problem``
    is the rule broken; ``str()`` is ``"<field>: <problem>"`` (or ``problem`` alone). The HTTP
    layer reads ``field`` (never parses the message) to fill a problem's ``errors[].field``."""

    def __init__(self, problem: str, *, field: str | None = None) -> None:
        super().__init__(f"{field}: {problem}" if field else problem)
        self.field = field
        self.problem = problem


class GeometryError(FieldError):
    """Invalid geometric input (a :class:`FieldError`)."""


def is_real(x: object) -> TypeGuard[float]:
    """A real number (Python or numpy scalar), not a bool (for mypy: usable as a float)."""
    return isinstance(x, numbers.Real) and not isinstance(x, bool)


def check_robust(robust: object, robust_scale: object, *, prefix: str = "",
                 error: type[FieldError] = FieldError) -> None:
    """THE rule of the robust-kernel options: ``robust`` is one of :data:`ROBUST_KERNELS` or
    None; ``robust_scale`` is None or finite and > 0, and only given with a kernel. Raises
    ``error`` with ``field = prefix + "robust"`` / ``prefix + "robust_scale"``."""
    if robust is not None and robust not in ROBUST_KERNELS:
        raise error(f"unknown kernel {robust!r}; valid: None, {', '.join(ROBUST_KERNELS)}",
                    field=prefix + "robust")
    if robust_scale is None:
        return
    if robust is None:
        raise error(f"given without {prefix}robust (a robust kernel)",
                    field=prefix + "robust_scale")
    if not (is_real(robust_scale) and math.isfinite(robust_scale) and robust_scale > 0):
        raise error(f"must be finite and > 0, got {robust_scale!r}",
                    field=prefix + "robust_scale")


def json_path(loc: Sequence[str | int], root: str = "$") -> str:
    """``("objects", 3, "axes", 1)`` -> ``"objects[3].axes[1]"``; ``root`` for an empty path.

    Pydantic's validator tags (``function-after[...]``, ``model-...``) are skipped.
    """
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        elif not str(part).startswith(("function-", "model-")):
            out += ("." if out else "") + str(part)
    return out or root


#: C0 control characters (U+0000-U+001F: NUL, which PostgreSQL refuses in text; newlines and
#: escapes that break logs, terminals and XML).
_CONTROL = re.compile(r"[\x00-\x1f]")
#: A surrogate code point in a ``str``: in text decoded from JSON a valid pair has become one
#: character, so any left is a LONE surrogate (``"\ud800"``), which has no UTF-8 encoding.
_SURROGATE = re.compile("[\ud800-\udfff]")
CONTROL_MESSAGE = "must not contain control characters (U+0000-U+001F)"
SURROGATE_MESSAGE = "must be valid Unicode text (a lone surrogate such as \\ud800 is not)"


def text_problem(text: str) -> str | None:
    """Why ``text`` (received from a client, to be stored or echoed) is refused, or None: a
    control character U+0000-U+001F (:data:`CONTROL_MESSAGE`) or a lone surrogate, which cannot
    be encoded as UTF-8, stored, hashed nor serialised (:data:`SURROGATE_MESSAGE`). The map
    document's ids, labels and names, the recordings' and the wire models' text fields all
    apply it (docs/api.md, "Text fields")."""
    if _CONTROL.search(text):
        return CONTROL_MESSAGE
    if _SURROGATE.search(text):
        return SURROGATE_MESSAGE
    return None


def label_problem(text: str) -> str | None:
    """Why ``text`` is refused as an id, label or name of a map (beyond its length), or None:
    blank, or :func:`text_problem`. The map document applies it to its ids, labels and names,
    recordings to the labels and the name that become the built map's."""
    if not text.strip():
        return "must be a non-empty string (not only whitespace)"
    return text_problem(text)


def scrubbed_text(text: str) -> str:
    """``text`` with every lone surrogate replaced by U+FFFD: for text read back from storage
    that :func:`text_problem` did not guard when it was written (it always serialises)."""
    return _SURROGATE.sub("\ufffd", text)
