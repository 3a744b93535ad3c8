"""The ellipsoid map model: a scene's objects as labelled 3D ellipsoids.

Frames: every ellipsoid is in the map's **world** frame (metres). ``up_axis`` is the world's unit
up direction (the Chess demo map has +Z up). Orientation of each ellipsoid is a unit
``quaternion_wxyz`` (ellipsoid frame -> world frame), its semi-axes are along the rotated x, y, z.

(Owned by the maps issue; the field names below are the contract other modules rely on.)

Every :class:`SceneMap` is validated when it is built (see :data:`LIMITS`); a problem raises one
:class:`MapValidationError` listing every problem found as ``{"field", "message"}`` entries, with
fields as JSON paths such as ``objects[3].axes``. The JSON format (``to_dict`` / ``from_dict``)
is documented in ``docs/maps.md``; :data:`MAP_JSON_SCHEMA` is its JSON Schema.
"""

from __future__ import annotations

import hashlib
import json
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

import numpy as np

from factors.geometry import (
    DOCUMENT_ROTATION_TOLERANCE,
    Ellipsoid,
    canonical_quaternion_wxyz,
    exact_norm,
    quaternion_wxyz_from_rotation,
    rotation_from_quaternion_wxyz,
    snap_to_rotation,
)

__all__ = [
    "FORMAT",
    "HASH_DECIMALS",
    "LIMITS",
    "MAP_JSON_SCHEMA",
    "MapObject",
    "MapValidationError",
    "SceneMap",
    "canonical_json",
    "content_hash",
    "scene_map_from_chess",
    "scene_map_from_dict",
    "scene_map_to_dict",
]

#: Value of the optional ``format`` field of the JSON document.
FORMAT = "quadloc.map/1"

#: Sanity limits enforced on every map (documented in docs/maps.md).
LIMITS: dict[str, float] = {
    "min_semi_axis_m": 1e-3,
    "max_semi_axis_m": 100.0,
    "max_abs_coordinate_m": 1e4,
    "max_objects": 10_000,
    "max_categories": 1_000,
    "max_id_length": 128,
    "max_name_length": 256,
    "max_metadata_bytes": 65_536,
    "max_metadata_depth": 32,
    # Tolerances of the JSON importer (factors.geometry.DOCUMENT_ROTATION_TOLERANCE: looser than
    # the in-process ones, values are re-normalised / snapped):
    "quaternion_norm_tolerance": DOCUMENT_ROTATION_TOLERANCE,
    "rotation_orthonormal_tolerance": DOCUMENT_ROTATION_TOLERANCE,
}

#: ``map_id`` must be URL-path safe: letters, digits, ``_ . -``; first char a letter or digit.
MAP_ID_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9_.\-]{0,127}$"
_MAP_ID_RE = re.compile(MAP_ID_PATTERN)


class MapValidationError(ValueError):
    """A map is invalid. ``errors`` lists every problem as ``{"field": ..., "message": ...}``.

    ``field`` is a JSON path into the map document, e.g. ``"objects[3].axes"`` or ``"map_id"``.
    """

    def __init__(self, errors: Sequence[Mapping[str, str]]) -> None:
        self.errors: list[dict[str, str]] = [
            {"field": str(e["field"]), "message": str(e["message"])} for e in errors
        ]
        if not self.errors:
            raise ValueError("MapValidationError needs at least one error")
        shown = "; ".join(f"{e['field']}: {e['message']}" for e in self.errors[:5])
        more = f" (and {len(self.errors) - 5} more)" if len(self.errors) > 5 else ""
        super().__init__(f"invalid map: {shown}{more}")


class _Errors:
    """Collects validation problems; ``raise_if_any`` raises one MapValidationError."""

    def __init__(self) -> None:
        self.items: list[dict[str, str]] = []

    def add(self, field_path: str, message: str) -> None:
        self.items.append({"field": field_path, "message": message})

    def raise_if_any(self) -> None:
        if self.items:
            raise MapValidationError(self.items)


def _check_text(errors: _Errors, path: str, value: object, max_len: int) -> bool:
    if not isinstance(value, str):
        errors.add(path, f"must be a string, got {type(value).__name__}")
        return False
    if not value or not value.strip():
        errors.add(path, "must be a non-empty string")
        return False
    if len(value) > max_len:
        errors.add(path, f"must be at most {max_len} characters, got {len(value)}")
        return False
    if any(ord(ch) < 32 for ch in value):
        errors.add(path, "must not contain control characters")
        return False
    if not _is_utf8(value):
        errors.add(path, _SURROGATE_MESSAGE)
        return False
    return True


_SURROGATE_MESSAGE = "must be valid Unicode text (a lone surrogate such as \\ud800 is not)"


def _is_utf8(text: str) -> bool:
    """False for text with a lone surrogate (it has no UTF-8 encoding: cannot be hashed or
    stored)."""
    try:
        text.encode("utf-8")
    except UnicodeEncodeError:
        return False
    return True


def _check_ellipsoid(errors: _Errors, path: str, ellipsoid: Ellipsoid) -> None:
    axes = ellipsoid.axes
    lo, hi = LIMITS["min_semi_axis_m"], LIMITS["max_semi_axis_m"]
    if np.any(axes < lo) or np.any(axes > hi):
        errors.add(f"{path}.axes", f"semi-axes must be in [{lo:g}, {hi:g}] m, got "
                                   f"{[round(float(a), 6) for a in axes]}")
    lim = LIMITS["max_abs_coordinate_m"]
    if np.any(np.abs(ellipsoid.center) > lim):
        errors.add(f"{path}.center", f"coordinates must be within +-{lim:g} m, got "
                                     f"{ellipsoid.center.tolist()}")


def _validate_header(
    errors: _Errors, map_id: object, name: object, version: object, up_axis: object,
    categories: object, metadata: object,
) -> dict[str, Any]:
    """Check the map-level fields; returns their normalised values (tuples, floats)."""
    fixed: dict[str, Any] = {}
    if not isinstance(map_id, str):
        errors.add("map_id", f"must be a string, got {type(map_id).__name__}")
    elif not _MAP_ID_RE.match(map_id):
        errors.add("map_id", f"must match {MAP_ID_PATTERN} (URL-safe, at most 128 "
                             f"characters), got {map_id!r}")
    _check_text(errors, "name", name, int(LIMITS["max_name_length"]))
    if isinstance(version, bool) or not isinstance(version, int | np.integer):
        errors.add("version", f"must be an integer, got {version!r}")
    elif version < 1:
        errors.add("version", f"must be >= 1, got {version}")
    else:
        fixed["version"] = int(version)
    try:
        up = np.asarray(up_axis, dtype=float)
    except (TypeError, ValueError):
        up = np.full(1, np.nan)
    if up.shape != (3,) or not np.all(np.isfinite(up)):
        errors.add("up_axis", f"must be 3 finite numbers, got {up_axis!r}")
    elif not np.linalg.norm(up) > 1e-9:
        errors.add("up_axis", "must be a non-zero vector")
    else:
        fixed["up_axis"] = tuple(float(v) for v in up)
    if isinstance(categories, str) or not isinstance(categories, Sequence):
        errors.add("categories", "must be a list of strings")
        categories = ()
    cats = tuple(categories)
    if len(cats) > LIMITS["max_categories"]:
        errors.add("categories", f"at most {int(LIMITS['max_categories'])} categories, "
                                 f"got {len(cats)}")
    seen: set[str] = set()
    for i, c in enumerate(cats):
        if _check_text(errors, f"categories[{i}]", c, int(LIMITS["max_id_length"])):
            if c in seen:
                errors.add(f"categories[{i}]", f"duplicate category {c!r}")
            seen.add(c)
    fixed["categories"] = tuple(c for c in cats if isinstance(c, str))  # others reported
    if metadata is None:
        metadata = {}
    depth = _nesting_depth(metadata)
    if depth > LIMITS["max_metadata_depth"]:
        errors.add("metadata", f"at most {int(LIMITS['max_metadata_depth'])} levels of "
                               f"nesting, got more than {int(LIMITS['max_metadata_depth'])}")
        metadata = {}
    elif isinstance(metadata, Mapping):
        metadata = _thaw(metadata)  # a deep, private copy (frozen below)
    if not isinstance(metadata, dict):
        errors.add("metadata", f"must be a JSON object, got {type(metadata).__name__}")
    else:
        try:
            size = len(json.dumps(metadata, allow_nan=False, sort_keys=True))
        except (TypeError, ValueError) as exc:
            errors.add("metadata", f"must be JSON-serialisable (finite numbers): {exc}")
        else:
            if size > LIMITS["max_metadata_bytes"]:
                errors.add("metadata", f"at most {int(LIMITS['max_metadata_bytes'])} bytes "
                                       f"of JSON, got {size}")
            if not _is_utf8(json.dumps(metadata, ensure_ascii=False)):
                errors.add("metadata", f"keys and strings {_SURROGATE_MESSAGE}")
        fixed["metadata"] = _freeze(metadata)
    return fixed


def _freeze(value: Any) -> Any:
    """Read-only deep view of JSON data: objects -> ``MappingProxyType``, arrays -> tuples."""
    if isinstance(value, Mapping):
        return MappingProxyType({k: _freeze(v) for k, v in value.items()})
    if isinstance(value, list | tuple):
        return tuple(_freeze(v) for v in value)
    return value


def _nesting_depth(value: Any) -> int:
    """Nesting depth of JSON-like containers (a scalar is 0, ``{}`` is 1), without recursion;
    stops counting past ``LIMITS["max_metadata_depth"] + 1``."""
    limit = int(LIMITS["max_metadata_depth"]) + 1
    depth, level = 0, [value]
    while level and depth < limit:
        children = []
        for v in level:
            if isinstance(v, Mapping):
                children.extend(v.values())
            elif isinstance(v, list | tuple):
                children.extend(v)
        if not children and not any(isinstance(v, Mapping | list | tuple) for v in level):
            break
        depth += 1
        level = children
    return depth


def _thaw(value: Any) -> Any:
    """Plain (mutable, JSON-serialisable) deep copy of :func:`_freeze`'s output."""
    if isinstance(value, Mapping):
        return {k: _thaw(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_thaw(v) for v in value]
    return value


def _validate_objects(
    errors: _Errors, indexed: Sequence[tuple[int, object]], categories: set[str]
) -> None:
    """Check objects given with their index in the document: ids, categories, sizes."""
    if len(indexed) > LIMITS["max_objects"]:
        errors.add("objects", f"at most {int(LIMITS['max_objects'])} objects, got {len(indexed)}")
    seen_ids: dict[str, int] = {}
    for i, o in indexed:
        path = f"objects[{i}]"
        if not isinstance(o, MapObject):
            errors.add(path, f"must be a MapObject, got {type(o).__name__}")
            continue
        if o.object_id in seen_ids:
            errors.add(f"{path}.object_id", f"duplicate object id {o.object_id!r} "
                                            f"(also objects[{seen_ids[o.object_id]}])")
        else:
            seen_ids[o.object_id] = i
        if o.category not in categories:
            errors.add(f"{path}.category", f"unknown category {o.category!r} (not in categories)")
        _check_ellipsoid(errors, path, o.ellipsoid)


# --------------------------------------------------------------------------- model


@dataclass(frozen=True)
class MapObject:
    """One object of the map: a stable string id, a category label and its ellipsoid."""

    object_id: str
    category: str
    ellipsoid: Ellipsoid

    def __post_init__(self) -> None:
        errors = _Errors()
        _check_text(errors, "object_id", self.object_id, int(LIMITS["max_id_length"]))
        _check_text(errors, "category", self.category, int(LIMITS["max_id_length"]))
        if not isinstance(self.ellipsoid, Ellipsoid):
            errors.add("ellipsoid", f"must be an Ellipsoid, got {type(self.ellipsoid).__name__}")
        errors.raise_if_any()
        # The orientation as exported. Kept (not recomputed) when the object was built from a
        # quaternion, so that JSON export -> import -> export is bit-exact (stable hashes).
        if getattr(self, "_quaternion_wxyz", None) is None:
            q = self.ellipsoid.quaternion_wxyz
            q.setflags(write=False)
            object.__setattr__(self, "_quaternion_wxyz", q)

    @classmethod
    def from_quaternion_wxyz(
        cls, object_id: str, category: str, center: Sequence[float], axes: Sequence[float],
        quaternion_wxyz: Sequence[float],
    ) -> MapObject:
        """Build from centre (m, world), semi-axes (m) and a unit ``(w, x, y, z)`` quaternion
        (ellipsoid frame -> world; renormalised, sign made canonical as in
        :func:`factors.geometry.canonical_quaternion_wxyz`: ``w > 0``, and for a half-turn
        (``w = 0``) the first non-zero of ``x, y, z`` positive, so ``q`` and ``-q`` give equal
        objects and equal map hashes)."""
        q = np.array(quaternion_wxyz, dtype=float)
        n = exact_norm(q.ravel())  # no BLAS: the same bits on every machine
        if abs(n - 1.0) > 1e-15:  # leave unit ones bit-for-bit: re-imports stay exact
            q = q / n
        if q.shape == (4,) and (q[0] < 0 or abs(q[0]) <= 1e-12):  # else q is kept bit for bit
            q = canonical_quaternion_wxyz(q)
        q = q + 0.0  # -0.0 -> 0.0 (same rotation, same exported text); other values unchanged
        q.setflags(write=False)
        obj = cls.__new__(cls)
        object.__setattr__(obj, "_quaternion_wxyz", q)
        obj.__init__(object_id, category,  # type: ignore[misc]
                     Ellipsoid(np.asarray(center, float), np.asarray(axes, float),
                               rotation_from_quaternion_wxyz(q)))
        return obj

    @property
    def quaternion_wxyz(self) -> np.ndarray:
        """Orientation (ellipsoid frame -> world) as a unit ``(w, x, y, z)``, ``w >= 0``."""
        return self._quaternion_wxyz  # type: ignore[attr-defined]

    def __eq__(self, other: object) -> bool:
        """Same id, category, centre, semi-axes and ``quaternion_wxyz`` (exactly: the same
        exported JSON)."""
        if not isinstance(other, MapObject):
            return NotImplemented
        a, b = self.ellipsoid, other.ellipsoid
        return (self.object_id == other.object_id and self.category == other.category
                and np.array_equal(a.center, b.center) and np.array_equal(a.axes, b.axes)
                and np.array_equal(self.quaternion_wxyz, other.quaternion_wxyz))

    def __hash__(self) -> int:
        return hash((self.object_id, self.category))


@dataclass(frozen=True)
class SceneMap:
    """A versioned ellipsoid map. ``version`` is 1 for a new map and grows by one per update.

    Validated on construction (raises :class:`MapValidationError`): ``map_id`` matches
    :data:`MAP_ID_PATTERN`; ``up_axis`` finite and non-zero (stored as given, see :attr:`up`);
    categories unique non-empty strings; object ids unique; each object's category in
    ``categories``; semi-axes and coordinates within :data:`LIMITS`; ``metadata`` a JSON object.
    ``up_axis``, ``categories`` and ``objects`` are converted to tuples; ``metadata`` to a
    read-only deep copy (``MappingProxyType``, arrays as tuples): maps are shared, e.g. by the
    compiled-map cache, and must not change under their content hash. ``to_dict`` returns
    plain, mutable copies.
    """

    map_id: str
    name: str
    up_axis: tuple[float, float, float]
    categories: tuple[str, ...]
    objects: tuple[MapObject, ...]
    version: int = 1
    metadata: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        errors = _Errors()
        fixed = _validate_header(errors, self.map_id, self.name, self.version, self.up_axis,
                                 self.categories, self.metadata)
        objs = self.objects
        if isinstance(objs, str) or not isinstance(objs, Sequence):
            errors.add("objects", "must be a list of MapObject")
            objs = ()
        objs = tuple(objs)
        _validate_objects(errors, list(enumerate(objs)), set(fixed["categories"]))
        errors.raise_if_any()
        for key, value in fixed.items():
            object.__setattr__(self, key, value)
        object.__setattr__(self, "objects", objs)

    def __getstate__(self) -> dict[str, Any]:
        state = dict(self.__dict__)  # mappingproxy does not pickle: store plain JSON data
        state.pop("_compiled", None)  # the memoised CompiledMap (maps.compiled.compile_map)
        state["metadata"] = _thaw(self.metadata)
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        state = dict(state)
        state["metadata"] = _freeze(state["metadata"])
        self.__dict__.update(state)

    def __eq__(self, other: object) -> bool:
        """Equal documents: same :func:`canonical_json` (content and version)."""
        if not isinstance(other, SceneMap):
            return NotImplemented
        return canonical_json(self) == canonical_json(other)

    def __hash__(self) -> int:
        return hash(canonical_json(self))

    def object_by_id(self, object_id: str) -> MapObject:
        for obj in self.objects:
            if obj.object_id == object_id:
                return obj
        raise KeyError(object_id)

    @property
    def up(self) -> np.ndarray:
        """World up axis as a unit vector, shape (3,)."""
        u = np.asarray(self.up_axis, dtype=float)
        return u / np.linalg.norm(u)

    # -- JSON
    def to_dict(self) -> dict[str, Any]:
        """The JSON document of this map (see :func:`scene_map_to_dict`)."""
        return scene_map_to_dict(self)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> SceneMap:
        """Parse and validate a JSON document (see :func:`scene_map_from_dict`)."""
        return scene_map_from_dict(data)

    def to_json(self, indent: int | None = 2) -> str:
        return json.dumps(self.to_dict(), indent=indent, allow_nan=False)

    @classmethod
    def from_json(cls, text: str | bytes) -> SceneMap:
        try:
            data = json.loads(text)
        except (TypeError, ValueError) as exc:
            raise MapValidationError([{"field": "$", "message": f"not valid JSON: {exc}"}]) from exc
        return scene_map_from_dict(data)

    @property
    def content_hash(self) -> str:
        """Hex sha256 of :func:`canonical_json` of the map (see :func:`content_hash`)."""
        return content_hash(self)


# --------------------------------------------------------------------------- JSON format


def scene_map_to_dict(scene_map: SceneMap) -> dict[str, Any]:
    """Export to the documented JSON format (orientation as ``quaternion_wxyz``, ``w >= 0``)."""
    return {
        "format": FORMAT,
        "map_id": scene_map.map_id,
        "name": scene_map.name,
        "version": scene_map.version,
        "up_axis": [float(v) for v in scene_map.up_axis],
        "categories": list(scene_map.categories),
        "objects": [
            {
                "object_id": o.object_id,
                "category": o.category,
                "center": [float(v) for v in o.ellipsoid.center],
                "axes": [float(v) for v in o.ellipsoid.axes],
                "quaternion_wxyz": [float(v) for v in o.quaternion_wxyz],
            }
            for o in scene_map.objects
        ],
        "metadata": _thaw(scene_map.metadata),
    }


def canonical_json(scene_map: SceneMap) -> str:
    """Canonical JSON of the map document: sorted keys, no whitespace, shortest float repr.

    Floats go through Python's ``repr`` (round-trip exact), so the same map always gives the
    same text, and parsing it back gives the same map bit for bit.
    """
    return _canonical_text(scene_map_to_dict(scene_map))


def _canonical_text(document: dict[str, Any]) -> str:
    """The one canonical serialisation (stored content and hashed form)."""
    return json.dumps(document, sort_keys=True, separators=(",", ":"), ensure_ascii=False,
                      allow_nan=False)


#: Decimal places kept of the geometric numbers (``up_axis``; ``center`` and ``axes`` in metres;
#: ``quaternion_wxyz``) in the document that :func:`content_hash` hashes: 1e-12 m and 1e-12 per
#: quaternion component, far below any geometric meaning and far above the last-bit (~1e-16)
#: differences between CPUs and LAPACK builds. The stored document keeps every bit.
HASH_DECIMALS = 12


def _hash_numbers(values: Sequence[float]) -> list[float]:
    return [round(float(v), HASH_DECIMALS) + 0.0 for v in values]  # + 0.0: -0.0 -> 0.0


def content_hash(scene_map: SceneMap) -> str:
    """Hex sha256 of :func:`canonical_json` with the geometric numbers rounded to
    :data:`HASH_DECIMALS` decimals (the HTTP ETag of a map version).

    So a map re-imported on another machine or through another route (rotation matrix or
    quaternion) hashes the same when its numbers agree to 1e-12; the import itself avoids
    LAPACK for rotations that are already orthonormal (:func:`factors.geometry.snap_to_rotation`),
    so such maps agree bit for bit. The hashed document includes ``map_id`` and ``version``:
    two versions never share a hash.
    """
    doc = scene_map_to_dict(scene_map)
    doc["up_axis"] = _hash_numbers(doc["up_axis"])
    for obj in doc["objects"]:
        for key in ("center", "axes", "quaternion_wxyz"):
            obj[key] = _hash_numbers(obj[key])
    return hashlib.sha256(_canonical_text(doc).encode("utf-8")).hexdigest()


_TOP_KEYS = {"format", "map_id", "name", "version", "up_axis", "categories", "objects",
             "metadata"}
_OBJECT_KEYS = {"object_id", "category", "center", "axes", "quaternion_wxyz", "rotation"}


def _numbers(
    errors: _Errors, path: str, value: object, shape: tuple[int, ...]
) -> np.ndarray | None:
    if isinstance(value, str | bytes | Mapping) or value is None:
        errors.add(path, f"must be an array of numbers with shape {list(shape)}")
        return None
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError):
        errors.add(path, f"must be an array of numbers with shape {list(shape)}")
        return None
    if arr.shape != shape:
        errors.add(path, f"must have shape {list(shape)}, got {list(arr.shape)}")
        return None
    flat = np.array(value, dtype=object).reshape(-1)
    if any(isinstance(v, bool) for v in flat):
        errors.add(path, "must contain numbers, not booleans")
        return None
    if not np.all(np.isfinite(arr)):
        errors.add(path, f"must be finite, got {arr.tolist()}")
        return None
    return arr


def _parse_object(errors: _Errors, path: str, obj: object) -> MapObject | None:
    if not isinstance(obj, Mapping):
        errors.add(path, f"must be an object, got {type(obj).__name__}")
        return None
    n_before = len(errors.items)
    for key in sorted(set(obj) - _OBJECT_KEYS):
        errors.add(f"{path}.{key}", "unknown field")
    for key in ("object_id", "category", "center", "axes"):
        if key not in obj:
            errors.add(f"{path}.{key}", "required field missing")
    object_id = obj.get("object_id")  # a string, as MAP_JSON_SCHEMA says (no integers)
    if "object_id" in obj:
        _check_text(errors, f"{path}.object_id", object_id, int(LIMITS["max_id_length"]))
    if "category" in obj:
        _check_text(errors, f"{path}.category", obj["category"], int(LIMITS["max_id_length"]))
    center = _numbers(errors, f"{path}.center", obj["center"], (3,)) if "center" in obj else None
    axes = _numbers(errors, f"{path}.axes", obj["axes"], (3,)) if "axes" in obj else None
    if axes is not None and np.any(axes <= 0):
        errors.add(f"{path}.axes", f"semi-axes must be > 0, got {axes.tolist()}")
        axes = None
    rotation = quaternion = None
    has_q, has_r = "quaternion_wxyz" in obj, "rotation" in obj
    if has_q and has_r:
        errors.add(f"{path}.rotation", "give either quaternion_wxyz or rotation, not both")
    elif has_q:
        q = _numbers(errors, f"{path}.quaternion_wxyz", obj["quaternion_wxyz"], (4,))
        if q is not None:
            n = float(np.linalg.norm(q))
            tol = LIMITS["quaternion_norm_tolerance"]
            if abs(n - 1.0) > tol:
                errors.add(f"{path}.quaternion_wxyz",
                           f"must have unit norm (within {tol:g}), |q| = {n:.9g}")
            else:
                quaternion = q
    elif has_r:
        R = _numbers(errors, f"{path}.rotation", obj["rotation"], (3, 3))
        if R is not None:
            tol = LIMITS["rotation_orthonormal_tolerance"]
            err = float(np.max(np.abs(R @ R.T - np.eye(3))))
            det = float(np.linalg.det(R))
            if err > tol:
                errors.add(f"{path}.rotation", f"must be orthonormal (within {tol:g}): "
                                               f"max|R R^T - I| = {err:.3g}")
            elif det < 0:
                errors.add(f"{path}.rotation", f"must be a proper rotation (det +1), det = "
                                               f"{det:.6g}")
            else:
                # Stored as its quaternion (the exported form), so that a re-import is exact.
                quaternion = quaternion_wxyz_from_rotation(snap_to_rotation(R))
    else:
        rotation = np.eye(3)  # documented default: axis-aligned
    if len(errors.items) > n_before or center is None or axes is None:
        return None
    if quaternion is not None:
        return MapObject.from_quaternion_wxyz(object_id, obj["category"], center, axes, quaternion)
    if rotation is None:
        return None
    return MapObject(object_id, obj["category"], Ellipsoid(center, axes, rotation))


def scene_map_from_dict(data: Mapping[str, Any], *, version: int | None = None) -> SceneMap:
    """Parse and validate the documented JSON document (``docs/maps.md``) into a SceneMap.

    Each object gives its orientation as ``quaternion_wxyz`` (unit within 1e-4, renormalised)
    or a 3x3 ``rotation`` (orthonormal within 1e-4, snapped to the nearest rotation); neither
    means axis-aligned. ``version`` defaults to 1 when absent; the ``version`` argument, if
    given, overrides it. Every problem found is reported in one :class:`MapValidationError`.
    """
    errors = _Errors()
    if not isinstance(data, Mapping):
        errors.add("$", f"the map must be a JSON object, got {type(data).__name__}")
        errors.raise_if_any()
    for key in sorted(set(data) - _TOP_KEYS):
        errors.add(key, "unknown field")
    if "format" in data and data["format"] != FORMAT:
        errors.add("format", f"must be {FORMAT!r}, got {data['format']!r}")
    for key in ("map_id", "name", "categories", "objects"):
        if key not in data:
            errors.add(key, "required field missing")
    up = data.get("up_axis", [0.0, 0.0, 1.0])
    up_arr = _numbers(errors, "up_axis", up, (3,))
    cats = data.get("categories", [])
    if not isinstance(cats, list):
        errors.add("categories", "must be an array of strings")
        cats = []
    raw_objects = data.get("objects", [])
    if not isinstance(raw_objects, list):
        errors.add("objects", "must be an array")
        raw_objects = []
    if len(raw_objects) > LIMITS["max_objects"]:
        errors.add("objects", f"at most {int(LIMITS['max_objects'])} objects, got "
                              f"{len(raw_objects)}")
        raw_objects = []
    objects = [_parse_object(errors, f"objects[{i}]", o) for i, o in enumerate(raw_objects)]
    metadata = data.get("metadata", {})
    if metadata is None:  # present but null: MAP_JSON_SCHEMA says "object"
        errors.add("metadata", "must be a JSON object, got null")
        metadata = {}
    ver = data.get("version", 1) if version is None else version
    fixed = _validate_header(errors, data.get("map_id", ""), data.get("name", ""), ver,
                             up_arr if up_arr is not None else (0.0, 0.0, 1.0), cats, metadata)
    _validate_objects(errors, [(i, o) for i, o in enumerate(objects) if o is not None],
                      set(fixed["categories"]))
    # Missing required fields were already reported once: drop the echo from the header check.
    missing = {e["field"] for e in errors.items if e["message"] == "required field missing"}
    errors.items = [e for e in errors.items
                    if e["field"] not in missing or e["message"] == "required field missing"]
    errors.raise_if_any()
    return SceneMap(
        map_id=data["map_id"], name=data["name"], up_axis=fixed["up_axis"],
        categories=fixed["categories"], objects=tuple(objects), version=fixed["version"],
        metadata=fixed["metadata"],
    )


def _integral(value: Any) -> Any:
    """An integral float (``3.0``: JSON Schema's ``integer`` allows it) as an int."""
    return int(value) if isinstance(value, float) and value.is_integer() else value


def scene_map_from_chess(
    data: Mapping[str, Any], *, map_id: str = "chess", name: str = "Chess",
    metadata: Mapping[str, Any] | None = None,
) -> SceneMap:
    """Import the Chess scene format (``bench/data/chess_scene.json``).

    Format: ``category_id_to_label`` ``{"0": "TV", ...}``; ``objects[]`` with ``category_id``,
    ``object_id`` (integer, kept as its decimal string) and ``ellipsoid {axes (semi-axes, m),
    R (3x3, ellipsoid -> world), center (m)}``. World +Z is up. Categories are ordered by id.
    """
    errors = _Errors()
    if not isinstance(data, Mapping):
        errors.add("$", f"the map must be a JSON object, got {type(data).__name__}")
        errors.raise_if_any()
    labels = data.get("category_id_to_label")
    if not isinstance(labels, Mapping) or not labels:
        errors.add("category_id_to_label", "required object {id: label} missing or empty")
        labels = {}
    raw = data.get("objects")
    if not isinstance(raw, list):
        errors.add("objects", "required array missing")
        raw = []

    def _key(k: str) -> tuple[int, Any]:
        return (0, int(k)) if str(k).lstrip("-").isdigit() else (1, str(k))

    ordered = sorted(labels, key=_key)
    converted = []
    for i, o in enumerate(raw):
        path = f"objects[{i}]"
        if not isinstance(o, Mapping):
            errors.add(path, "must be an object")
            continue
        cid = str(_integral(o.get("category_id")))
        if cid not in labels:
            errors.add(f"{path}.category_id", f"unknown category id {o.get('category_id')!r}")
            continue
        ell = o.get("ellipsoid")
        if not isinstance(ell, Mapping):
            errors.add(f"{path}.ellipsoid", "required object {axes, R, center} missing")
            continue
        oid = _integral(o.get("object_id"))
        if isinstance(oid, int) and not isinstance(oid, bool):
            oid = str(oid)  # the Chess format's integer ids become their decimal string
        entry: dict[str, Any] = {"object_id": oid, "category": labels[cid],
                                 "center": ell.get("center"), "axes": ell.get("axes"),
                                 "rotation": ell.get("R")}
        converted.append(entry)
    errors.raise_if_any()
    meta: dict[str, Any] = {
        "source_format": "chess_scene",
        "category_id_to_label": {str(k): labels[k] for k in ordered},
    }
    meta.update(metadata or {})
    doc = {"map_id": map_id, "name": name, "up_axis": [0.0, 0.0, 1.0],
           "categories": [labels[k] for k in ordered], "objects": converted, "metadata": meta}
    try:
        return scene_map_from_dict(doc)
    except MapValidationError as exc:
        # Report the Chess field names (R instead of rotation, under ellipsoid).
        renamed = []
        for e in exc.errors:
            f = e["field"]
            for ours, theirs in ((".rotation", ".ellipsoid.R"), (".center", ".ellipsoid.center"),
                                 (".axes", ".ellipsoid.axes")):
                if f.endswith(ours):
                    f = f[: -len(ours)] + theirs
            renamed.append({"field": f, "message": e["message"]})
        raise MapValidationError(renamed) from None


# --------------------------------------------------------------------------- JSON Schema

_NUM = {"type": "number"}
_VEC3 = {"type": "array", "items": _NUM, "minItems": 3, "maxItems": 3}

#: JSON Schema (draft 2020-12) of the map document. Semantic checks (unit norm, orthonormality,
#: unique ids, known categories) are done by :func:`scene_map_from_dict`.
MAP_JSON_SCHEMA: dict[str, Any] = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "$id": "https://quadloc.example/schemas/map-1.json",
    "title": "QuadLoc ellipsoid map",
    "type": "object",
    "additionalProperties": False,
    "required": ["map_id", "name", "categories", "objects"],
    "properties": {
        "format": {"const": FORMAT},
        "map_id": {"type": "string", "pattern": MAP_ID_PATTERN},
        "name": {"type": "string", "minLength": 1, "maxLength": int(LIMITS["max_name_length"])},
        "version": {"type": "integer", "minimum": 1,
                    "description": "Set by the store; ignored on create/update."},
        "up_axis": {**_VEC3, "description": "World up direction (default [0, 0, 1])."},
        "categories": {"type": "array", "uniqueItems": True,
                       "maxItems": int(LIMITS["max_categories"]),
                       "items": {"type": "string", "minLength": 1,
                                 "maxLength": int(LIMITS["max_id_length"])}},
        "objects": {
            "type": "array",
            "maxItems": int(LIMITS["max_objects"]),
            "items": {
                "type": "object",
                "additionalProperties": False,
                "required": ["object_id", "category", "center", "axes"],
                "properties": {
                    "object_id": {"type": "string", "minLength": 1,
                                  "maxLength": int(LIMITS["max_id_length"])},
                    "category": {"type": "string", "minLength": 1,
                                 "maxLength": int(LIMITS["max_id_length"])},
                    "center": {**_VEC3, "description": "World metres.",
                               "items": {"type": "number",
                                         "minimum": -LIMITS["max_abs_coordinate_m"],
                                         "maximum": LIMITS["max_abs_coordinate_m"]}},
                    "axes": {**_VEC3, "description": "Semi-axes in metres.",
                             "items": {"type": "number", "minimum": LIMITS["min_semi_axis_m"],
                                       "maximum": LIMITS["max_semi_axis_m"]}},
                    "quaternion_wxyz": {"type": "array", "items": _NUM, "minItems": 4,
                                        "maxItems": 4,
                                        "description": "Unit quaternion (w, x, y, z), "
                                                       "ellipsoid frame -> world."},
                    "rotation": {"type": "array", "minItems": 3, "maxItems": 3,
                                 "items": _VEC3,
                                 "description": "3x3 rotation, ellipsoid frame -> world "
                                                "(alternative to quaternion_wxyz)."},
                },
                "not": {"required": ["quaternion_wxyz", "rotation"]},
            },
        },
        "metadata": {"type": "object"},
    },
}
