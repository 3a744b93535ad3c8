"""The ellipsoid map model: a scene's objects as labelled 3D ellipsoids.

Frames: every ellipsoid is in the map's **world** frame (metres). ``up_axis`` is the world's unit
up direction (the Chess demo map has +Z up). Orientation of each ellipsoid is a unit
``quaternion_wxyz`` (ellipsoid frame -> world frame), its semi-axes are along the rotated x, y, z.

Validation, once (docs/design/maps.md, "Map model"): the pydantic models :class:`MapDocument`
(``docs/maps.md``) and :class:`ChessDocument` hold every rule (:data:`LIMITS`); the frozen
dataclasses :class:`SceneMap` / :class:`MapObject` validate through the same model. A problem
raises one :class:`MapValidationError` listing every problem found, fields as JSON paths such as
``objects[3].axes[1]``. :data:`MAP_JSON_SCHEMA` and :data:`CHESS_JSON_SCHEMA` are generated.
"""

from __future__ import annotations

import hashlib
import json
import operator
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import TYPE_CHECKING, Annotated, Any, Final, Literal, TypeVar

import numpy as np
from pydantic import (
    AfterValidator,
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    Strict,
    StrictStr,
    ValidationError,
    model_validator,
)
from pydantic.fields import FieldInfo
from pydantic.json_schema import GenerateJsonSchema
from pydantic_core import InitErrorDetails, PydanticCustomError

from quadloc.factors.arrays import FloatArray
from quadloc.factors.camera import Ellipsoid
from quadloc.factors.names import SURROGATE_MESSAGE, json_path, label_problem
from quadloc.factors.rotations import (
    DOCUMENT_ROTATION_TOLERANCE,
    canonical_quaternion_wxyz,
    exact_norm,
    quaternion_wxyz_from_rotation,
    rotation_from_quaternion_wxyz,
    snap_to_rotation,
)

__all__ = [
    "CHESS_JSON_SCHEMA",
    "FORMAT",
    "HASH_DECIMALS",
    "LIMITS",
    "MAP_JSON_SCHEMA",
    "ChessDocument",
    "MapDocument",
    "MapObject",
    "MapValidationError",
    "MapZone",
    "SceneMap",
    "ZoneDocument",
    "canonical_json",
    "content_hash",
    "scene_map_from_chess",
    "scene_map_from_dict",
    "scene_map_to_dict",
]

#: Value of the optional ``format`` field of the JSON document.
FORMAT: Final = "quadloc.map/1"

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
    "max_zones": 10_000,
    # Tolerances of the JSON importer (quadloc.factors.rotations.DOCUMENT_ROTATION_TOLERANCE: looser
    # than the in-process ones, values are re-normalised / snapped):
    "quaternion_norm_tolerance": DOCUMENT_ROTATION_TOLERANCE,
    "rotation_orthonormal_tolerance": DOCUMENT_ROTATION_TOLERANCE,
}

#: ``map_id`` must be URL-path safe: letters, digits, ``_ . -``; first char a letter or digit.
MAP_ID_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9_.\-]{0,127}$"


class MapValidationError(ValueError):
    """A map is invalid. ``errors`` lists every problem as ``{"field": ..., "message": ...}``.

    ``field`` is a JSON path into the map document, e.g. ``"objects[3].axes[1]"`` or
    ``"map_id"`` (``"$"``: the document itself).
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


# --------------------------------------------------------------------------- rules

def _fail(message: str, error_type: str = "map_rule") -> PydanticCustomError:
    """A rule's error (raise it in a validator: pydantic reports it at the field validated)."""
    return PydanticCustomError(error_type, "{message}", {"message": message})


def _is_utf8(text: str) -> bool:
    """False for text with a lone surrogate (it has no UTF-8 encoding: cannot be hashed or
    stored)."""
    try:
        text.encode("utf-8")
    except UnicodeEncodeError:
        return False
    return True


def _printable(text: str) -> str:
    """The map document's validator of :func:`label_problem`."""
    problem = label_problem(text)
    if problem is not None:
        raise _fail(problem)
    return text


def _length(low: float, high: float | None = None, *, description: str | None = None
            ) -> FieldInfo:
    """pydantic's length constraints ``[low, high]`` (``high`` defaults to ``low``: exactly
    ``low`` items) and the schema's ``description``, as ``Annotated`` metadata."""
    field_info: FieldInfo = Field(min_length=int(low),
                                  max_length=int(low if high is None else high),
                                  description=description)
    return field_info


#: Ids and category labels; the map's display name.
Label = Annotated[StrictStr, _length(1, LIMITS["max_id_length"]), AfterValidator(_printable)]
Name = Annotated[StrictStr, _length(1, LIMITS["max_name_length"]), AfterValidator(_printable)]
#: A finite JSON number (booleans refused).
Number = Annotated[float, Field(strict=True, allow_inf_nan=False)]


def _nonzero(v: list[float]) -> list[float]:
    if not float(np.linalg.norm(v)) > 1e-9:
        raise _fail("must be a non-zero vector")
    return v


def _unit_quaternion(q: list[float]) -> list[float]:
    n, tol = float(np.linalg.norm(q)), LIMITS["quaternion_norm_tolerance"]
    if abs(n - 1.0) > tol:
        raise _fail(f"must have unit norm (within {tol:g}), |q| = {n:.9g}")
    return q


def _proper_rotation(rows: list[list[float]]) -> list[list[float]]:
    R, tol = np.array(rows, dtype=float), LIMITS["rotation_orthonormal_tolerance"]
    err = float(np.max(np.abs(R @ R.T - np.eye(3))))
    if err > tol:
        raise _fail(f"must be orthonormal (within {tol:g}): max|R R^T - I| = {err:.3g}")
    det = float(np.linalg.det(R))
    if det < 0:
        raise _fail(f"must be a proper rotation (det +1), det = {det:.6g}")
    return rows


_lim = LIMITS["max_abs_coordinate_m"]
#: World metres, each coordinate within +-LIMITS["max_abs_coordinate_m"].
Center = Annotated[list[Annotated[Number, Field(ge=-_lim, le=_lim)]],
                   _length(3, description="World metres.")]
#: Semi-axes (metres) in [LIMITS["min_semi_axis_m"], LIMITS["max_semi_axis_m"]].
SemiAxes = Annotated[list[Annotated[Number, Field(ge=LIMITS["min_semi_axis_m"],
                                                  le=LIMITS["max_semi_axis_m"])]],
                     _length(3, description="Semi-axes in metres.")]
Quaternion = Annotated[list[Number],
                       _length(4, description="Unit quaternion (w, x, y, z), ellipsoid frame "
                                              "-> world."), AfterValidator(_unit_quaternion)]
Rotation = Annotated[list[Annotated[list[Number], _length(3)]],
                     _length(3, description="3x3 rotation, ellipsoid frame -> world "
                                            "(alternative to quaternion_wxyz)."),
                     AfterValidator(_proper_rotation)]
UpAxis = Annotated[list[Number], _length(3, description="World up direction (default [0, 0, 1])."),
                   AfterValidator(_nonzero)]


def _metadata(value: Mapping[str, Any]) -> dict[str, Any]:
    """A JSON object within the size and nesting limits: returns a plain deep copy."""
    limit = int(LIMITS["max_metadata_depth"])
    if _nesting_depth(value) > limit:  # before any recursion: no RecursionError
        raise _fail(f"at most {limit} levels of nesting, got more than {limit}")
    plain: dict[str, Any] = _thaw(value)
    try:
        size = len(json.dumps(plain, allow_nan=False, sort_keys=True))
    except (TypeError, ValueError) as exc:
        raise _fail(f"must be JSON-serialisable (finite numbers): {exc}") from None
    if size > LIMITS["max_metadata_bytes"]:
        raise _fail(f"at most {int(LIMITS['max_metadata_bytes'])} bytes of JSON, got {size}")
    if not _is_utf8(json.dumps(plain, ensure_ascii=False)):
        raise _fail(f"keys and strings {SURROGATE_MESSAGE}")
    return plain


Metadata = Annotated[Mapping[str, Any], AfterValidator(_metadata)]


def _integral(value: Any) -> Any:
    """An integral float (``3.0``: JSON Schema's ``integer`` allows it) as an int."""
    return int(value) if isinstance(value, float) and value.is_integer() else value


#: The Chess format's integer ids (integral floats accepted; decimal strings kept as they are).
ChessId = Annotated[int, BeforeValidator(_integral), Strict()] | StrictStr


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
    depth, level = 0, [value]
    while depth <= LIMITS["max_metadata_depth"]:
        level = [v.values() if isinstance(v, Mapping) else v for v in level
                 if isinstance(v, Mapping | list | tuple)]
        if not level:
            break
        depth += 1
        level = [child for children in level for child in children]
    return depth


def _thaw(value: Any) -> Any:
    """Plain (mutable, JSON-serialisable) deep copy of :func:`_freeze`'s output."""
    if isinstance(value, Mapping):
        return {k: _thaw(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_thaw(v) for v in value]
    return value


def _with_problems(handler: Any, data: Any, problems: list[tuple[tuple[str | int, ...], str]],
                   title: str) -> Any:
    """Run pydantic's ``handler`` and report its errors together with ``problems`` (rules that
    span fields, found on the raw input), so that every problem is reported at once."""
    errors: list[InitErrorDetails] = []
    try:
        result = handler(data)
    except ValidationError as exc:
        errors = [InitErrorDetails(type=_fail(e["msg"], e["type"]), loc=e["loc"],
                                   input=e["input"]) for e in exc.errors()]
    errors += [InitErrorDetails(type=_fail(message), loc=loc, input=data)
               for loc, message in problems]
    if errors:
        raise ValidationError.from_exception_data(title, errors)
    return result


def _reference_problems(data: Mapping[str, Any]) -> list[tuple[tuple[str | int, ...], str]]:
    """Rules across fields: categories unique, object ids unique, each object's category one of
    ``categories`` (checked on the entries that are strings; the others have their own error)."""
    cats, objs = data.get("categories"), data.get("objects")
    problems: list[tuple[tuple[str | int, ...], str]] = []
    known: set[str] = set()
    if isinstance(cats, list | tuple):
        for i, c in enumerate(cats):
            if isinstance(c, str):
                if c in known:
                    problems.append((("categories", i), f"duplicate category {c!r}"))
                known.add(c)
    if not isinstance(objs, list | tuple) or len(objs) > LIMITS["max_objects"]:
        return problems
    seen: dict[str, int] = {}
    for i, o in enumerate(objs):
        if not isinstance(o, Mapping):
            continue
        oid, cat = o.get("object_id"), o.get("category")
        if isinstance(oid, str):
            if oid in seen:
                problems.append((("objects", i, "object_id"), f"duplicate object id {oid!r} "
                                                              f"(also objects[{seen[oid]}])"))
            else:
                seen[oid] = i
        if isinstance(cat, str) and isinstance(cats, list | tuple) and cat not in known:
            problems.append((("objects", i, "category"),
                             f"unknown category {cat!r} (not in categories)"))
    return problems + _zone_problems(data.get("zones"), seen)


def _zone_problems(zones: Any, object_ids: Mapping[str, int]
                   ) -> list[tuple[tuple[str | int, ...], str]]:
    """Rules of ``zones``: zone ids unique, each of a zone's ``object_ids`` an object of the map
    (and listed once), each ``parent`` another zone's id, no cycle of parents (checked on the
    entries that are well-formed; the others have their own error)."""
    if not isinstance(zones, list | tuple) or len(zones) > LIMITS["max_zones"]:
        return []
    problems: list[tuple[tuple[str | int, ...], str]] = []
    first: dict[str, int] = {}
    for i, z in enumerate(zones):
        zid = z.get("zone_id") if isinstance(z, Mapping) else None
        if isinstance(zid, str):
            if zid in first:
                problems.append((("zones", i, "zone_id"),
                                 f"duplicate zone id {zid!r} (also zones[{first[zid]}])"))
            else:
                first[zid] = i
    parents: dict[str, str] = {}
    for i, z in enumerate(zones):
        if not isinstance(z, Mapping):
            continue
        ids = z.get("object_ids")
        if isinstance(ids, list | tuple):
            listed: set[str] = set()
            for j, oid in enumerate(ids):
                if not isinstance(oid, str):
                    continue
                if oid not in object_ids:
                    problems.append((("zones", i, "object_ids", j),
                                     f"unknown object id {oid!r} (not in objects)"))
                elif oid in listed:
                    problems.append((("zones", i, "object_ids", j),
                                     f"object id {oid!r} listed twice"))
                listed.add(oid)
        zid, parent = z.get("zone_id"), z.get("parent")
        if isinstance(parent, str):
            if parent not in first:
                problems.append((("zones", i, "parent"),
                                 f"unknown parent zone {parent!r} (not in zones)"))
            elif isinstance(zid, str):
                parents.setdefault(zid, parent)
    for i, z in enumerate(zones):
        zid = z.get("zone_id") if isinstance(z, Mapping) else None
        if not isinstance(zid, str) or first.get(zid) != i:
            continue
        step, hops = parents.get(zid), 0
        while step is not None and step != zid and hops <= len(parents):
            step, hops = parents.get(step), hops + 1
        if step == zid:
            problems.append((("zones", i, "parent"), f"zone {zid!r} is its own ancestor"))
    return problems


#: Messages of pydantic's error types, in the document's terms (others are pydantic's own).
_MESSAGES = {"missing": "required field missing", "extra_forbidden": "unknown field",
             "dict_type": "must be a JSON object", "model_type": "must be a JSON object",
             "mapping_type": "must be a JSON object"}


#: a document model (:func:`_validated` returns an instance of the model it is given)
_Model = TypeVar("_Model", bound=BaseModel)
_Item = TypeVar("_Item")


def _validated(model: type[_Model], data: Any) -> _Model:
    """``model.model_validate(data)``, every error as one :class:`MapValidationError` naming
    each field by its :func:`json_path`."""
    try:
        return model.model_validate(data)
    except ValidationError as exc:
        raise MapValidationError([{"field": json_path(e["loc"]),
                                   "message": _MESSAGES.get(e["type"], e["msg"])}
                                  for e in exc.errors()]) from None


# --------------------------------------------------------------------------- documents


class _Document(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class ObjectDocument(_Document):
    """One object of the map document (objects[i])."""

    model_config = ConfigDict(json_schema_extra={"not": {"required": ["quaternion_wxyz",
                                                                      "rotation"]}})

    object_id: Label
    category: Label
    center: Center
    axes: SemiAxes
    # Optional, but not nullable: absent means "not given" (pydantic does not validate the
    # default None, and refuses an explicit null). mypy is told the truth: it may be None.
    if TYPE_CHECKING:
        quaternion_wxyz: Quaternion | None = None
        rotation: Rotation | None = None
    else:
        quaternion_wxyz: Quaternion = None
        rotation: Rotation = None

    @model_validator(mode="after")
    def _one_orientation(self) -> ObjectDocument:
        if self.quaternion_wxyz is not None and self.rotation is not None:
            raise ValidationError.from_exception_data(type(self).__name__, [InitErrorDetails(
                type=_fail("give either quaternion_wxyz or rotation, not both"),
                loc=("rotation",), input=self.rotation)])
        return self


class ZoneDocument(_Document):
    """One zone of the map document (zones[i]): a named group of the map's objects (a room, a
    floor), optionally inside a ``parent`` zone (a room on a floor)."""

    zone_id: Label
    object_ids: Annotated[list[Label], Field(min_length=1, max_length=int(LIMITS["max_objects"]),
                                             json_schema_extra={"uniqueItems": True})]
    # optional, not nullable (as ObjectDocument's orientation)
    if TYPE_CHECKING:
        name: Name | None = None
        parent: Label | None = None
    else:
        name: Name = None
        parent: Label = None


class MapDocument(_Document):
    """The map document, format quadloc.map/1 (docs/maps.md)."""

    model_config = ConfigDict(title="QuadLoc ellipsoid map")

    format: Literal["quadloc.map/1"] = FORMAT
    map_id: Annotated[StrictStr, Field(pattern=MAP_ID_PATTERN)]
    name: Name
    version: Annotated[int, Field(strict=True, ge=1, description="Set by the store; ignored "
                                                                   "on create/update.")] = 1
    up_axis: UpAxis = [0.0, 0.0, 1.0]
    categories: Annotated[list[Label], Field(max_length=int(LIMITS["max_categories"]),
                                             json_schema_extra={"uniqueItems": True})]
    objects: Annotated[list[ObjectDocument], Field(max_length=int(LIMITS["max_objects"]))]
    metadata: Metadata = {}
    zones: Annotated[list[ZoneDocument], Field(
        max_length=int(LIMITS["max_zones"]),
        description="Optional named groups of objects (rooms, floors); answers name the zone "
                    "of their pose (docs/maps.md).")] = []

    @model_validator(mode="wrap")
    @classmethod
    def _references(cls, data: Any, handler: Any) -> Any:
        problems = _reference_problems(data) if isinstance(data, Mapping) else []
        return _with_problems(handler, data, problems, cls.__name__)

    def to_scene_map(self) -> SceneMap:
        """The map of this (validated) document; built without validating it a second time."""
        return _set_fields(object.__new__(SceneMap), self, tuple(
            _map_object(o.object_id, o.category, o.center, o.axes, o.quaternion_wxyz, o.rotation)
            for o in self.objects))


def _set_fields(scene: SceneMap, doc: MapDocument, objects: tuple[MapObject, ...]) -> SceneMap:
    """Fill the frozen ``scene`` from its validated document: tuples, read-only metadata."""
    for key, value in (("map_id", doc.map_id), ("name", doc.name), ("version", doc.version),
                       ("up_axis", tuple(doc.up_axis)), ("categories", tuple(doc.categories)),
                       ("objects", objects), ("metadata", _freeze(doc.metadata)),
                       ("zones", tuple(MapZone(z.zone_id, z.name, tuple(z.object_ids), z.parent)
                                       for z in doc.zones))):
        object.__setattr__(scene, key, value)
    return scene


class _ChessEllipsoid(_Document):
    axes: SemiAxes
    R: Rotation  # the Chess format's name
    center: Center


class _ChessObject(_Document):
    category_id: ChessId
    object_id: Annotated[int, BeforeValidator(_integral), Strict()] | Label
    ellipsoid: _ChessEllipsoid


class ChessDocument(_Document):
    """The Chess scene format (tests/support/data/chess_scene.json); unknown fields are refused
    (naming them), as everywhere in the API."""

    category_id_to_label: Annotated[dict[str, Label], Field(min_length=1)]
    objects: Annotated[list[_ChessObject], Field(max_length=int(LIMITS["max_objects"]))]

    @model_validator(mode="wrap")
    @classmethod
    def _known_categories(cls, data: Any, handler: Any) -> Any:
        labels = data.get("category_id_to_label") if isinstance(data, Mapping) else None
        known: Mapping[str, Any] = labels if isinstance(labels, Mapping) else {}
        objs = data.get("objects") if isinstance(labels, Mapping) else None
        ids = [(i, o.get("category_id")) for i, o in
               enumerate(objs if isinstance(objs, list) else ()) if isinstance(o, Mapping)]
        return _with_problems(handler, data, [
            (("objects", i, "category_id"), f"unknown category id {cid!r}") for i, cid in ids
            if isinstance(cid, int | float | str) and not isinstance(cid, bool)
            and str(_integral(cid)) not in known], cls.__name__)


class _MapObjectLabels(_Document):
    object_id: Label
    category: Label


# --------------------------------------------------------------------------- model


@dataclass(frozen=True)
class MapObject:
    """One object of the map: a stable string id, a category label and its ellipsoid."""

    object_id: str
    category: str
    ellipsoid: Ellipsoid

    def __post_init__(self) -> None:
        _validated(_MapObjectLabels, {"object_id": self.object_id, "category": self.category})
        if not isinstance(self.ellipsoid, Ellipsoid):
            raise MapValidationError([{"field": "ellipsoid", "message": "must be an Ellipsoid, "
                                       f"got {type(self.ellipsoid).__name__}"}])
        # The orientation as exported. Kept (not recomputed) when the object was built from a
        # quaternion, so that JSON export -> import -> export is bit-exact (stable hashes).
        if getattr(self, "_quaternion_wxyz", None) is None:
            q = self.ellipsoid.quaternion_wxyz
            q.setflags(write=False)
            object.__setattr__(self, "_quaternion_wxyz", q)

    @classmethod
    def from_quaternion_wxyz(
        cls, object_id: str, category: str, center: Sequence[float], axes: Sequence[float],
        quaternion_wxyz: FloatArray | Sequence[float],
    ) -> MapObject:
        """Build from centre (m, world), semi-axes (m) and a unit ``(w, x, y, z)`` quaternion
        (ellipsoid frame -> world; renormalised, sign made canonical as in
        :func:`quadloc.factors.rotations.canonical_quaternion_wxyz`: ``w > 0``, and for a half-turn
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
        cls.__init__(obj, object_id, category,
                     Ellipsoid(np.asarray(center, float), np.asarray(axes, float),
                               rotation_from_quaternion_wxyz(q)))
        return obj

    @property
    def quaternion_wxyz(self) -> FloatArray:
        """Orientation (ellipsoid frame -> world) as a unit ``(w, x, y, z)``, ``w >= 0``."""
        q: FloatArray = self.__dict__["_quaternion_wxyz"]  # set in __post_init__ (frozen)
        return q

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
class MapZone:
    """A zone of a map (a room, a floor): its id, optional name, the ids of its objects and the
    id of the zone it is part of (``None``: a top-level zone)."""

    zone_id: str
    name: str | None
    object_ids: tuple[str, ...]
    parent: str | None = None


def take(items: Sequence[_Item], indices: Sequence[int] | np.ndarray) -> tuple[_Item, ...]:
    """``tuple(items[i] for i in indices)`` at C speed (``operator.itemgetter``): the sub-map
    of a few places of a large map takes hundreds of objects per request."""
    idx = indices.tolist() if isinstance(indices, np.ndarray) else list(indices)
    if not idx:
        return ()
    if len(idx) == 1:
        return (items[idx[0]],)
    picked: tuple[_Item, ...] = operator.itemgetter(*idx)(items)
    return picked


@dataclass(frozen=True)
class SceneMap:
    """A versioned ellipsoid map. ``version`` is 1 for a new map and grows by one per update.

    Validated on construction through :class:`MapDocument` (raises
    :class:`MapValidationError`); ``up_axis`` is stored as given (see :attr:`up`), ``metadata``
    ``None`` means empty. ``up_axis``, ``categories`` and ``objects`` become tuples, ``metadata`` a
    read-only deep copy (``MappingProxyType``, arrays as tuples): maps are shared and must not
    change under their content hash. ``to_dict`` returns plain, mutable copies.
    """

    map_id: str
    name: str
    up_axis: tuple[float, float, float]
    categories: tuple[str, ...]
    objects: tuple[MapObject, ...]
    version: int = 1
    metadata: Mapping[str, Any] = field(default_factory=dict)
    zones: tuple[MapZone, ...] = ()

    def __post_init__(self) -> None:
        objs: object = self.objects  # any sequence of MapObject is accepted (made a tuple)
        if isinstance(objs, str) or not isinstance(objs, Sequence):
            raise MapValidationError([{"field": "objects", "message": "must be a list of "
                                                                      "MapObject"}])
        objs = tuple(objs)
        wrong = [{"field": f"objects[{i}]", "message": f"must be a MapObject, got "
                                                       f"{type(o).__name__}"}
                 for i, o in enumerate(objs) if not isinstance(o, MapObject)]
        if wrong:
            raise MapValidationError(wrong)
        doc = _validated(MapDocument, {
            "map_id": self.map_id, "name": self.name, "version": _plain(self.version),
            "up_axis": _plain(self.up_axis), "categories": _plain(self.categories),
            "objects": [_object_dict(o) for o in objs],
            "metadata": {} if self.metadata is None else self.metadata,
            "zones": [_zone_dict(z) if isinstance(z, MapZone) else z for z in self.zones]})
        _set_fields(self, doc, objs)

    def subset(self, indices: Sequence[int]) -> SceneMap:
        """The map of the objects ``indices`` (in that order, unique) of this one: same id,
        name, version, up axis and categories, no metadata, no zones. Not validated again (the
        objects of a valid map, ids unique, categories listed: valid), so that a request may
        take the sub-map of a few places of a large map at the cost of a tuple."""
        sub = object.__new__(SceneMap)
        for key, value in (("map_id", self.map_id), ("name", self.name),
                           ("version", self.version), ("up_axis", self.up_axis),
                           ("categories", self.categories),
                           ("objects", take(self.objects, indices)),
                           ("metadata", _freeze({})), ("zones", ())):
            object.__setattr__(sub, key, value)
        return sub

    def __getstate__(self) -> dict[str, Any]:
        state = dict(self.__dict__)  # mappingproxy does not pickle: store plain JSON data
        state.pop("_compiled", None)  # the memoised CompiledMap (quadloc.maps.compiled.compile_map)
        state.pop("_zone_index", None)  # the memoised quadloc.maps.zones.ZoneIndex
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

    def zone_by_id(self, zone_id: str) -> MapZone:
        """The zone ``zone_id`` (``KeyError`` when the map has none of that id)."""
        for zone in self.zones:
            if zone.zone_id == zone_id:
                return zone
        raise KeyError(zone_id)

    def object_by_id(self, object_id: str) -> MapObject:
        for obj in self.objects:
            if obj.object_id == object_id:
                return obj
        raise KeyError(object_id)

    @property
    def up(self) -> FloatArray:
        """World up axis as a unit vector, shape (3,)."""
        u = np.asarray(self.up_axis, dtype=float)
        unit: FloatArray = u / np.linalg.norm(u)
        return unit

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
        "objects": [_object_dict(o) for o in scene_map.objects],
        "metadata": _thaw(scene_map.metadata),
        # only when there are zones: the documents (and content hashes) of maps without zones
        # are those of before zones existed
        **({"zones": [_zone_dict(z) for z in scene_map.zones]} if scene_map.zones else {}),
    }


def _zone_dict(zone: MapZone) -> dict[str, Any]:
    """One zone as exported (``name`` and ``parent`` only when given)."""
    out: dict[str, Any] = {"zone_id": zone.zone_id}
    if zone.name is not None:
        out["name"] = zone.name
    out["object_ids"] = list(zone.object_ids)
    if zone.parent is not None:
        out["parent"] = zone.parent
    return out


def _object_dict(obj: MapObject) -> dict[str, Any]:
    """One object as exported (orientation as ``quaternion_wxyz``, ``w >= 0``)."""
    e = obj.ellipsoid
    return {"object_id": obj.object_id, "category": obj.category,
            "center": [float(v) for v in e.center], "axes": [float(v) for v in e.axes],
            "quaternion_wxyz": [float(v) for v in obj.quaternion_wxyz]}


def _plain(value: Any) -> Any:
    """numpy arrays and scalars of the in-process API as plain Python values (lists, floats,
    ints) for the document model; anything else unchanged (and judged by the model)."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    return value


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
#: ``quaternion_wxyz``) in the document that :func:`content_hash` hashes (why: design doc).
HASH_DECIMALS = 12


def content_hash(scene_map: SceneMap) -> str:
    """Hex sha256 of :func:`canonical_json` with the geometric numbers rounded to
    :data:`HASH_DECIMALS` decimals (the HTTP ETag of a map version; it covers ``map_id`` and
    ``version``: two versions never share a hash)."""
    doc = scene_map_to_dict(scene_map)
    for part, key in [(doc, "up_axis"), *((o, k) for o in doc["objects"]
                                          for k in ("center", "axes", "quaternion_wxyz"))]:
        part[key] = [round(float(v), HASH_DECIMALS) + 0.0 for v in part[key]]  # -0.0 -> 0.0
    return hashlib.sha256(_canonical_text(doc).encode("utf-8")).hexdigest()



def _map_object(object_id: str, category: str, center: Sequence[float], axes: Sequence[float],
                quaternion_wxyz: FloatArray | Sequence[float] | None,
                rotation: Sequence[Sequence[float]] | None) -> MapObject:
    """The object of a validated document entry; a ``rotation`` is stored as its quaternion
    (the exported form, so that a re-import is exact); neither means axis-aligned."""
    if rotation is not None:
        quaternion_wxyz = quaternion_wxyz_from_rotation(
            snap_to_rotation(np.array(rotation, dtype=float)))
    if quaternion_wxyz is not None:
        return MapObject.from_quaternion_wxyz(object_id, category, center, axes, quaternion_wxyz)
    return MapObject(object_id, category, Ellipsoid(np.array(center, dtype=float),
                                                    np.array(axes, dtype=float), np.eye(3)))


def scene_map_from_dict(data: Mapping[str, Any], *, version: int | None = None) -> SceneMap:
    """Parse and validate the documented JSON document (``docs/maps.md``, :class:`MapDocument`)
    into a SceneMap.

    Each object gives its orientation as ``quaternion_wxyz`` (unit within 1e-4, renormalised)
    or a 3x3 ``rotation`` (orthonormal within 1e-4, snapped to the nearest rotation); neither
    means axis-aligned. ``version`` defaults to 1 when absent; the ``version`` argument, if
    given, overrides it (the document's own ``version``, which the store ignores, is still
    validated: a document that breaks its schema is refused, whatever the store does with the
    field). Every problem found is reported in one :class:`MapValidationError`.
    """
    scene = _validated(MapDocument, data).to_scene_map()
    if version is not None:  # the new, unshared map: set before anyone sees it
        object.__setattr__(scene, "version", version)
    return scene


def scene_map_from_chess(
    data: Mapping[str, Any], *, map_id: str = "chess", name: str = "Chess",
    metadata: Mapping[str, Any] | None = None,
) -> SceneMap:
    """Import the Chess scene format (``tests/support/data/chess_scene.json``,
    :class:`ChessDocument`).

    Format: ``category_id_to_label`` ``{"0": "TV", ...}``; ``objects[]`` with ``category_id``,
    ``object_id`` (integer, kept as its decimal string) and ``ellipsoid {axes (semi-axes, m),
    R (3x3, ellipsoid -> world), center (m)}``. World +Z is up. Categories are ordered by id.
    Errors name the Chess fields (``objects[2].ellipsoid.R``).
    """
    doc = _validated(ChessDocument, data)
    labels = doc.category_id_to_label

    def _key(k: str) -> tuple[int, Any]:
        return (0, int(k)) if str(k).lstrip("-").isdigit() else (1, str(k))

    ordered = sorted(labels, key=_key)
    objects = tuple(_map_object(str(o.object_id), labels[str(o.category_id)], o.ellipsoid.center,
                                o.ellipsoid.axes, None, o.ellipsoid.R) for o in doc.objects)
    meta: dict[str, Any] = {
        "source_format": "chess_scene",
        "category_id_to_label": {str(k): labels[k] for k in ordered},
    }
    meta.update(metadata or {})
    return SceneMap(map_id, name, (0.0, 0.0, 1.0), tuple(labels[k] for k in ordered), objects,
                    metadata=meta)


# --------------------------------------------------------------------------- JSON Schema


class _SchemaGenerator(GenerateJsonSchema):
    def field_title_should_be_set(self, schema: Any) -> bool:
        return False  # the property names say it


def _json_schema(model: type[BaseModel], **head: Any) -> dict[str, Any]:
    """``model.model_json_schema()`` with its ``$defs`` inlined (it is embedded in the OpenAPI
    document as is) and the ``null`` defaults of optional fields (absent = not given)
    dropped."""
    schema = model.model_json_schema(schema_generator=_SchemaGenerator)
    defs = schema.pop("$defs", {})

    def inline(node: Any) -> Any:
        if isinstance(node, list):
            return [inline(v) for v in node]
        if not isinstance(node, dict):
            return node
        if "$ref" in node:
            target = {k: v for k, v in defs[node["$ref"].rsplit("/", 1)[-1]].items()
                      if k != "title"}
            node = {**target, **{k: v for k, v in node.items() if k != "$ref"}}
        return {k: inline(v) for k, v in node.items()
                if not (k == "default" and v is None)}

    return {**head, **inline(schema)}


#: JSON Schema (draft 2020-12) of the map document, generated from :class:`MapDocument`. The
#: rules JSON Schema cannot state (unit norm, orthonormality, unique ids, known categories,
#: metadata size) are checked by the same model.
MAP_JSON_SCHEMA: dict[str, Any] = _json_schema(
    MapDocument, **{"$schema": "https://json-schema.org/draft/2020-12/schema",
                    "$id": "https://quadloc.example/schemas/map-1.json"})

#: JSON Schema of the Chess scene format, generated from :class:`ChessDocument`.
CHESS_JSON_SCHEMA: dict[str, Any] = _json_schema(ChessDocument)
