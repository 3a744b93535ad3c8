"""Map model: JSON format, Chess importer, validation messages, JSON Schema, compile_map."""

from __future__ import annotations

import copy
import json
import math
import re
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from quadloc.factors.camera import Ellipsoid
from quadloc.factors.names import json_path
from quadloc.factors.rotations import rotation_from_quaternion_wxyz
from quadloc.maps.compiled import compile_map
from quadloc.maps.demo import DEMO_MAP_PATH, load_demo_map
from quadloc.maps.model import (
    CHESS_JSON_SCHEMA,
    LIMITS,
    MAP_JSON_SCHEMA,
    MapObject,
    MapValidationError,
    SceneMap,
    canonical_json,
    content_hash,
    scene_map_from_chess,
    scene_map_from_dict,
)
from tests.support.helpers import surface_points
from tests.support.reference_data import CHESS_SCENE_PATH

CHESS_SOURCE = CHESS_SCENE_PATH


@pytest.fixture(scope="module")
def chess_source() -> dict[str, Any]:
    return json.loads(CHESS_SOURCE.read_text())  # shipped in the checkout: never skipped


def _doc() -> dict[str, Any]:
    """A small valid document, written by hand."""
    h = math.sqrt(0.5)
    return {
        "map_id": "lab-1", "name": "Lab", "up_axis": [0, 0, 1],
        "categories": ["chair", "tv"],
        "objects": [
            {"object_id": "a", "category": "chair", "center": [1, 2, 0.5], "axes": [0.3, 0.2, 0.4],
             "quaternion_wxyz": [h, 0, 0, h]},
            {"object_id": "b", "category": "tv", "center": [0, 0, 1], "axes": [0.5, 0.1, 0.3],
             "rotation": [[1, 0, 0], [0, 1, 0], [0, 0, 1]]},
        ],
        "metadata": {"note": "hand-written"},
    }


def _errors(doc: Any) -> dict[str, str]:
    with pytest.raises(MapValidationError) as exc:
        scene_map_from_dict(doc)
    assert isinstance(exc.value, ValueError)
    return {e["field"]: e["message"] for e in exc.value.errors}


# --------------------------------------------------------------------------- format


def test_quaternion_convention_is_wxyz_ellipsoid_to_world() -> None:
    m = scene_map_from_dict(_doc())
    R = m.objects[0].ellipsoid.rotation
    # (w, x, y, z) = (cos 45, 0, 0, sin 45): +90 degrees about +Z maps x -> y.
    np.testing.assert_allclose(R @ [1, 0, 0], [0, 1, 0], atol=1e-15)
    np.testing.assert_allclose(R @ [0, 0, 1], [0, 0, 1], atol=1e-15)
    # The semi-axis a = 0.3 now lies along world +Y: the surface point centre + 0.3 y.
    E = m.objects[0].ellipsoid
    X = E.center + np.array([0.0, 0.3, 0.0])
    d = E.rotation.T @ (X - E.center) / E.axes
    assert d @ d == pytest.approx(1.0)


def test_json_round_trip_is_bit_exact() -> None:
    m = scene_map_from_dict(_doc())
    text = m.to_json()
    again = SceneMap.from_json(text)
    assert again.to_json() == text
    assert canonical_json(again) == canonical_json(m)
    assert content_hash(again) == content_hash(m) == m.content_hash
    # rotation-matrix input is exported as a unit quaternion with w >= 0
    q = m.to_dict()["objects"][1]["quaternion_wxyz"]
    assert q == [1.0, 0.0, 0.0, 0.0]


def test_negative_w_quaternion_is_canonicalised() -> None:
    doc = _doc()
    h = math.sqrt(0.5)
    doc["objects"][0]["quaternion_wxyz"] = [-h, 0, 0, -h]  # same rotation as (h, 0, 0, h)
    m = scene_map_from_dict(doc)
    np.testing.assert_allclose(m.objects[0].quaternion_wxyz, [h, 0, 0, h], atol=1e-15)
    np.testing.assert_allclose(m.objects[0].ellipsoid.rotation,
                               rotation_from_quaternion_wxyz([h, 0, 0, h]), atol=1e-15)


def test_hash_changes_with_content() -> None:
    a = scene_map_from_dict(_doc())
    doc = _doc()
    doc["objects"][0]["center"][2] += 1e-9
    assert content_hash(scene_map_from_dict(doc)) != content_hash(a)


# --------------------------------------------------------------------------- Chess


def test_chess_import_matches_the_source_file(chess_source: dict[str, Any]) -> None:
    m = scene_map_from_chess(chess_source)
    labels = chess_source["category_id_to_label"]
    assert m.map_id == "chess" and m.up_axis == (0.0, 0.0, 1.0)
    assert m.categories == tuple(labels[str(i)] for i in range(len(labels)))
    assert len(m.objects) == len(chess_source["objects"]) == 11
    for src, obj in zip(chess_source["objects"], m.objects, strict=True):
        assert obj.object_id == str(src["object_id"])
        assert obj.category == labels[str(src["category_id"])]
        e = src["ellipsoid"]
        np.testing.assert_array_equal(obj.ellipsoid.center, e["center"])
        np.testing.assert_array_equal(obj.ellipsoid.axes, e["axes"])
        np.testing.assert_allclose(obj.ellipsoid.rotation, e["R"], atol=1e-12)
        # Same point set: surface points of the source ellipsoid lie on ours.
        R, ax, c = np.array(e["R"]), np.array(e["axes"]), np.array(e["center"])
        u = np.random.default_rng(0).normal(size=(50, 3))
        u /= np.linalg.norm(u, axis=1, keepdims=True)
        X = (u * ax) @ R.T + c
        local = (X - obj.ellipsoid.center) @ obj.ellipsoid.rotation / obj.ellipsoid.axes
        np.testing.assert_allclose(np.sum(local**2, axis=1), 1.0, atol=1e-12)


def test_demo_map_is_the_chess_map(chess_source: dict[str, Any]) -> None:
    demo = load_demo_map()
    imported = scene_map_from_chess(chess_source)
    assert demo.map_id == "chess" and demo.version == 1
    assert "provenance" in demo.metadata and "chess_scene.json" in demo.metadata["provenance"]
    a, b = demo.to_dict(), imported.to_dict()
    assert a["categories"] == b["categories"]
    # Numbers with a stated tolerance (another CPU/LAPACK may differ in the last bits), and the
    # content hash, which is defined to be insensitive to that (quadloc.maps.model.HASH_DECIMALS).
    for oa, ob in zip(a["objects"], b["objects"], strict=True):
        assert (oa["object_id"], oa["category"]) == (ob["object_id"], ob["category"])
        for key in ("center", "axes", "quaternion_wxyz"):
            np.testing.assert_allclose(oa[key], ob[key], rtol=0, atol=1e-14, err_msg=key)
    same_header = replace(imported, name=demo.name, metadata=demo.metadata)
    assert content_hash(same_header) == demo.content_hash
    # The shipped file is exactly the exported form (re-export gives the same text).
    assert demo.to_json(indent=2) + "\n" == DEMO_MAP_PATH.read_text()


def test_chess_importer_names_fields_in_its_own_format(chess_source: dict[str, Any]) -> None:
    bad = copy.deepcopy(chess_source)
    bad["objects"][2]["ellipsoid"]["R"][0][0] += 0.1
    bad["objects"][3]["ellipsoid"]["axes"][1] = -1
    bad["objects"][4]["category_id"] = 42
    with pytest.raises(MapValidationError) as exc:
        scene_map_from_chess(bad)
    fields = {e["field"] for e in exc.value.errors}
    assert "objects[4].category_id" in fields
    bad["objects"][4]["category_id"] = 0
    with pytest.raises(MapValidationError) as exc:
        scene_map_from_chess(bad)
    fields = {e["field"]: e["message"] for e in exc.value.errors}
    assert "orthonormal" in fields["objects[2].ellipsoid.R"]
    assert "greater than or equal to 0.001" in fields["objects[3].ellipsoid.axes[1]"]


# --------------------------------------------------------------------------- validation


@pytest.mark.parametrize(
    ("mutate", "field", "fragment"),
    [
        (lambda d: d["objects"][0].update(axes=[0.3, 0.0, 0.4]), "objects[0].axes[1]",
         "greater than or equal to 0.001"),
        (lambda d: d["objects"][0].update(axes=[0.3, 1e-4, 0.4]), "objects[0].axes[1]",
         "greater than or equal to 0.001"),
        (lambda d: d["objects"][0].update(axes=[300, 1, 1]), "objects[0].axes[0]",
         "less than or equal to 100"),
        (lambda d: d["objects"][0].update(center=[1, float("nan"), 0]), "objects[0].center[1]",
         "finite"),
        (lambda d: d["objects"][0].update(center=[1, 2e5, 0]), "objects[0].center[1]",
         "less than or equal to 10000"),
        (lambda d: d["objects"][0].update(center=[1, 2]), "objects[0].center", "at least 3 items"),
        (lambda d: d["objects"][0].update(center=[1, True, 0]), "objects[0].center[1]",
         "valid number"),
        (lambda d: d["objects"][0].update(quaternion_wxyz=None), "objects[0].quaternion_wxyz",
         "valid list"),
        (lambda d: d["objects"][0].update(quaternion_wxyz=[1, 1, 0, 0]),
         "objects[0].quaternion_wxyz", "unit norm"),
        (lambda d: d["objects"][1].update(rotation=[[1, 0, 0], [0, 1, 0], [0, 0, -1]]),
         "objects[1].rotation", "det"),
        (lambda d: d["objects"][1].update(rotation=[[1, 0.1, 0], [0, 1, 0], [0, 0, 1]]),
         "objects[1].rotation", "orthonormal"),
        (lambda d: d["objects"][0].update(rotation=[[1, 0, 0], [0, 1, 0], [0, 0, 1]]),
         "objects[0].rotation", "either"),
        (lambda d: d["objects"][1].update(object_id="a"), "objects[1].object_id", "duplicate"),
        (lambda d: d["objects"][1].update(category="sofa"), "objects[1].category", "unknown"),
        (lambda d: d["objects"][1].update(colour="red"), "objects[1].colour", "unknown field"),
        (lambda d: d["objects"][1].pop("axes"), "objects[1].axes", "missing"),
        (lambda d: d.update(map_id="has space"), "map_id", "match pattern"),
        (lambda d: d.update(map_id=7), "map_id", "string"),
        (lambda d: d.update(name=""), "name", "at least 1 character"),
        (lambda d: d.update(name=" \t"), "name", "non-empty"),
        (lambda d: d.update(name="a\nb"), "name", "control characters"),
        (lambda d: d.update(up_axis=[0, 0, 0]), "up_axis", "non-zero"),
        (lambda d: d.update(categories=["chair", "tv", "chair"]), "categories[2]", "duplicate"),
        (lambda d: d.update(metadata=[1]), "metadata", "JSON object"),
        (lambda d: d.update(metadata={"x": "y" * 70_000}), "metadata", "bytes"),
        (lambda d: d.update(format="other/9"), "format", "quadloc.map/1"),
        (lambda d: d.update(version=0), "version", "greater than or equal to 1"),
        (lambda d: d.update(version=True), "version", "valid integer"),
        (lambda d: d.pop("objects"), "objects", "missing"),
    ],
)
def test_validation_names_the_field(mutate: Any, field: str, fragment: str) -> None:
    doc = _doc()
    mutate(doc)
    errors = _errors(doc)
    assert field in errors, errors
    assert fragment in errors[field], errors[field]


def test_all_problems_are_reported_at_once() -> None:
    doc = _doc()
    doc["objects"][0]["axes"] = [-1, 1, 1]
    doc["objects"][1]["category"] = "sofa"
    doc["name"] = ""
    errors = _errors(doc)
    assert {"objects[0].axes[0]", "objects[1].category", "name"} <= set(errors)


def test_object_count_limit() -> None:
    doc = _doc()
    doc["objects"] = [doc["objects"][0]] * (int(LIMITS["max_objects"]) + 1)
    assert "at most" in _errors(doc)["objects"]


def test_not_an_object() -> None:
    assert "$" in _errors([1, 2])
    with pytest.raises(MapValidationError):
        SceneMap.from_json("{not json")


def test_direct_construction_is_validated() -> None:
    e = Ellipsoid(np.zeros(3), np.ones(3))
    with pytest.raises(MapValidationError) as exc:
        SceneMap("m", "M", (0, 0, 1), ("a",), (MapObject("1", "b", e), MapObject("1", "a", e)))
    fields = {x["field"] for x in exc.value.errors}
    assert fields == {"objects[0].category", "objects[1].object_id"}
    with pytest.raises(MapValidationError):
        MapObject("", "a", e)
    m = SceneMap("m", "M", [0, 0, 2], ["a"], [MapObject("1", "a", e)])
    assert m.categories == ("a",) and isinstance(m.objects, tuple)
    np.testing.assert_allclose(m.up, [0, 0, 1])


# --------------------------------------------------------------------------- JSON Schema


def _schema_errors(schema: dict[str, Any], value: Any, path: str = "$") -> list[str]:
    """A minimal JSON Schema checker for the keywords MAP_JSON_SCHEMA uses (independent of
    the parser, to check that the published schema agrees with it)."""
    out: list[str] = []
    types = {"object": dict, "array": list, "string": str, "integer": int, "number": (int, float)}
    if "type" in schema:
        t = types[schema["type"]]
        if not isinstance(value, t) or (isinstance(value, bool)):
            return [f"{path}: type"]
    if "const" in schema and value != schema["const"]:
        out.append(f"{path}: const")
    if isinstance(value, dict):
        for key in schema.get("required", []):
            if key not in value:
                out.append(f"{path}.{key}: required")
        props = schema.get("properties", {})
        for key, v in value.items():
            if key in props:
                out += _schema_errors(props[key], v, f"{path}.{key}")
            elif schema.get("additionalProperties") is False:
                out.append(f"{path}.{key}: additional")
        if "not" in schema and not _schema_errors(schema["not"], value, path):
            out.append(f"{path}: not")
    if isinstance(value, list):
        if len(value) < schema.get("minItems", 0) or len(value) > schema.get("maxItems", 1e9):
            out.append(f"{path}: items count")
        if schema.get("uniqueItems") and len(set(map(json.dumps, value))) != len(value):
            out.append(f"{path}: unique")
        if "items" in schema:
            for i, v in enumerate(value):
                out += _schema_errors(schema["items"], v, f"{path}[{i}]")
    if isinstance(value, str):
        if not schema.get("minLength", 0) <= len(value) <= schema.get("maxLength", 1e9):
            out.append(f"{path}: length")
        if "pattern" in schema and not re.search(schema["pattern"], value):
            out.append(f"{path}: pattern")
    number = isinstance(value, int | float) and not isinstance(value, bool)
    if number and not schema.get("minimum", -math.inf) <= value <= schema.get("maximum", math.inf):
        out.append(f"{path}: range")
    return out


def test_schema_accepts_valid_documents() -> None:
    assert _schema_errors(MAP_JSON_SCHEMA, load_demo_map().to_dict()) == []
    assert _schema_errors(MAP_JSON_SCHEMA, _doc()) == []


@pytest.mark.parametrize(
    "mutate",
    [
        lambda d: d["objects"][0].update(axes=[0.3, 1e-4, 0.4]),
        lambda d: d["objects"][0].update(center=[1, 2]),
        lambda d: d["objects"][1].update(colour="red"),
        lambda d: d["objects"][0].update(rotation=[[1, 0, 0], [0, 1, 0], [0, 0, 1]]),
        lambda d: d.update(map_id="has space"),
        lambda d: d.update(categories=["chair", "chair"]),
        lambda d: d.pop("name"),
        lambda d: d.update(extra=1),
        # numeric strings: the hand-written parser used to accept them (numpy converted "2"),
        # the schema did not; both come from MapDocument now
        lambda d: d["objects"][0].update(center=[1, "2", 0]),
        lambda d: d.update(up_axis=[0, 0, "1"]),
        lambda d: d["objects"][0].update(quaternion_wxyz=None),
    ],
)
def test_schema_and_parser_both_reject(mutate: Any) -> None:
    doc = _doc()
    mutate(doc)
    assert _schema_errors(MAP_JSON_SCHEMA, doc)
    with pytest.raises(MapValidationError):
        scene_map_from_dict(doc)


# --------------------------------------------------------------------------- compile_map


def test_compiled_arrays_against_sampled_surfaces() -> None:
    demo = load_demo_map()
    c = compile_map(demo)
    n = len(demo.objects)
    assert c.centers.shape == (n, 3) and c.shape_matrices.shape == (n, 3, 3)
    assert c.dual_quadrics.shape == (n, 4, 4) and len(c) == n
    assert c.object_ids == tuple(o.object_id for o in demo.objects)
    for i, obj in enumerate(demo.objects):
        E = obj.ellipsoid
        X = surface_points(E, 12, 7)
        Xh = np.column_stack([X, np.ones(len(X))])
        # Surface points satisfy the primal quadric Q = (Q*)^-1: X~^T Q X~ = 0.
        Q = np.linalg.inv(c.dual_quadrics[i])
        vals = np.einsum("ni,ij,nj->n", Xh, Q, Xh)
        np.testing.assert_allclose(vals, 0.0, atol=1e-9)
        # ... and the centre is inside (negative).
        ch = np.append(E.center, 1.0)
        assert ch @ Q @ ch < 0
        # Shape matrix: (X - c)^T M^-1 (X - c) = 1 on the surface.
        d = X - c.centers[i]
        np.testing.assert_allclose(
            np.einsum("ni,ij,nj->n", d, np.linalg.inv(c.shape_matrices[i]), d), 1.0, atol=1e-9)
    # categories -> indices covers each object exactly once
    seen = sorted(int(i) for idx in c.indices_by_category.values() for i in idx)
    assert seen == list(range(n))
    for cat, idx in c.indices_by_category.items():
        assert all(c.categories[i] == cat for i in idx)
    assert c.indices_for("Sofa").size == 0
    assert c.index_of("3") == 3
    with pytest.raises(ValueError):
        c.centers[0, 0] = 1.0  # read-only


def test_compile_empty_map() -> None:
    c = compile_map(SceneMap("empty", "Empty", (0, 0, 1), ("a",), ()))
    assert c.dual_quadrics.shape == (0, 4, 4) and c.indices_by_category == {}


def test_docs_schema_copy_is_current() -> None:
    text = (Path(__file__).resolve().parents[2] / "docs" / "maps.md").read_text()
    block = text.split("<!-- BEGIN map-json-schema -->", 1)[1]
    block = block.split("<!-- END map-json-schema -->", 1)[0]
    body = block.strip().removeprefix("```json").removesuffix("```")
    assert json.loads(body) == json.loads(json.dumps(MAP_JSON_SCHEMA))


def test_equality_hash_and_pickle() -> None:
    import pickle
    from dataclasses import replace

    m = scene_map_from_dict(_doc())
    again = pickle.loads(pickle.dumps(m))
    assert again == m and hash(again) == hash(m) and again.content_hash == m.content_hash
    assert replace(m, version=2) != m
    assert m.objects[0] == again.objects[0] and m.objects[0] != m.objects[1]
    doc = _doc()
    doc["objects"][0]["center"][0] += 1e-12
    assert scene_map_from_dict(doc) != m


def test_docs_example_document_is_valid() -> None:
    text = (Path(__file__).resolve().parents[2] / "docs" / "maps.md").read_text()
    example = text.split("```json", 1)[1].split("```", 1)[0]
    m = scene_map_from_dict(json.loads(example))
    assert m.map_id == "office-3" and len(m.objects) == 2
    np.testing.assert_allclose(m.objects[0].ellipsoid.rotation @ [1, 0, 0], [0, 1, 0], atol=1e-15)


def _random_doc(seed: int, n: int) -> dict[str, Any]:
    rng = np.random.default_rng(seed)
    objects = []
    for i in range(n):
        q = rng.normal(size=4)
        if i % 2:
            orientation = {"quaternion_wxyz": (q / np.linalg.norm(q)).tolist()}
        else:
            u, _, vt = np.linalg.svd(rng.normal(size=(3, 3)))
            R = u @ vt * np.sign(np.linalg.det(u @ vt))
            orientation = {"rotation": R.tolist()}
        objects.append({"object_id": f"o{i}", "category": ["a", "b", "ç"][i % 3],
                        "center": rng.uniform(-50, 50, 3).tolist(),
                        "axes": np.exp(rng.uniform(np.log(1e-3), np.log(100), 3)).tolist(),
                        **orientation})
    return {"map_id": f"m{seed}", "name": "Café ☕", "categories": ["a", "b", "ç"],
            "objects": objects, "metadata": {"seed": seed, "ünïcode": True}}


@pytest.mark.parametrize("seed", range(8))
def test_random_maps_round_trip_exactly(seed: int) -> None:
    m = scene_map_from_dict(_random_doc(seed, 12))
    again = SceneMap.from_json(m.to_json())
    assert again == m and again.content_hash == m.content_hash
    third = SceneMap.from_json(again.to_json(indent=None))
    assert third.to_json() == m.to_json()
    for a, b in zip(m.objects, third.objects, strict=True):
        np.testing.assert_array_equal(a.ellipsoid.rotation, b.ellipsoid.rotation)
        R = a.ellipsoid.rotation
        np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
        assert a.quaternion_wxyz[0] >= 0
        np.testing.assert_allclose(rotation_from_quaternion_wxyz(a.quaternion_wxyz), R,
                                   atol=1e-12)


# --------------------------------------------------------------------------- review fixes


@pytest.mark.parametrize(
    "mutate",
    [
        lambda d: d["objects"][0].update(object_id=7),  # the parser used to accept it
        lambda d: d.update(metadata=None),  # ditto
        lambda d: d["objects"][0].update(object_id=""),
        lambda d: d.update(metadata=[1, 2]),
    ],
)
def test_schema_and_parser_agree_on_ids_and_metadata(mutate: Any) -> None:
    doc = _doc()
    mutate(doc)
    assert _schema_errors(MAP_JSON_SCHEMA, doc)
    fields = _errors(doc)
    assert any(f.endswith("object_id") or f == "metadata" for f in fields), fields


def test_chess_import_still_converts_integer_ids() -> None:
    data = {"category_id_to_label": {"0": "TV"},
            "objects": [{"category_id": 0, "object_id": 12,
                         "ellipsoid": {"axes": [0.3, 0.2, 0.1], "center": [0, 0, 1],
                                       "R": np.eye(3).tolist()}}]}
    m = scene_map_from_chess(data)
    assert m.objects[0].object_id == "12"
    assert _schema_errors(MAP_JSON_SCHEMA, m.to_dict()) == []


def test_half_turn_quaternions_of_either_sign_give_equal_objects() -> None:
    """q and -q with w = 0 are the same rotation: equal objects and equal map hashes."""
    q = np.array([0.0, 0.6, -0.8, 0.0])
    a = MapObject.from_quaternion_wxyz("a", "chair", [1, 2, 0.5], [0.3, 0.2, 0.4], q)
    b = MapObject.from_quaternion_wxyz("a", "chair", [1, 2, 0.5], [0.3, 0.2, 0.4], -q)
    assert a == b
    np.testing.assert_array_equal(a.quaternion_wxyz, [0.0, 0.6, -0.8, 0.0])  # first x > 0
    maps = [SceneMap("m", "M", (0.0, 0.0, 1.0), ("chair",), (o,)) for o in (a, b)]
    assert maps[0].content_hash == maps[1].content_hash
    # the same tie-break as the rotation -> quaternion conversion
    from quadloc.factors.rotations import quaternion_wxyz_from_rotation
    np.testing.assert_allclose(quaternion_wxyz_from_rotation(a.ellipsoid.rotation),
                               a.quaternion_wxyz, atol=1e-12)


def test_metadata_is_frozen_deeply_and_still_exports() -> None:
    source = {"note": "x", "nested": {"list": [1, {"k": 2}]}}
    m = SceneMap("m", "M", (0.0, 0.0, 1.0), ("chair",), (), metadata=source)
    source["note"] = "changed"  # the caller's dict is not shared
    source["nested"]["list"].append(3)
    assert m.metadata["note"] == "x"
    with pytest.raises(TypeError):
        m.metadata["note"] = "y"  # type: ignore[index]
    with pytest.raises(TypeError):
        m.metadata["nested"]["list2"] = 1  # type: ignore[index]
    assert m.metadata["nested"]["list"] == (1, {"k": 2})
    exported = m.to_dict()["metadata"]
    assert exported == {"note": "x", "nested": {"list": [1, {"k": 2}]}}
    exported["note"] = "mutated"  # a copy: the map is unchanged
    assert m.metadata["note"] == "x"
    again = SceneMap.from_json(m.to_json())
    assert again == m and again.content_hash == m.content_hash
    # a map built from another map's (frozen) metadata validates and compares equal
    assert SceneMap("m", "M", (0.0, 0.0, 1.0), ("chair",), (), metadata=m.metadata) == m


def _nested(levels: int) -> object:
    """A JSON value with ``levels`` levels of list nesting (a scalar is 0 levels)."""
    value: object = 0
    for _ in range(levels):
        value = [value]
    return value


def test_metadata_nesting_is_limited_without_recursion() -> None:
    doc = load_demo_map().to_dict()
    limit = int(LIMITS["max_metadata_depth"])
    doc["metadata"] = {"ok": _nested(limit - 1)}  # the object itself is one level
    assert scene_map_from_dict(doc).to_dict()["metadata"]["ok"] == _nested(limit - 1)
    for levels in (limit, 100_000):  # far past Python's recursion limit: no RecursionError
        doc["metadata"] = {"deep": _nested(levels)}
        with pytest.raises(MapValidationError) as exc:
            scene_map_from_dict(doc)
        assert [e["field"] for e in exc.value.errors] == ["metadata"]
        assert "nesting" in exc.value.errors[0]["message"]


# --------------------------------------------------------------------------- pydantic models


def test_errors_name_the_element_and_all_are_reported() -> None:
    """Field paths go down to the array element, in documents and in code, and every problem of
    the document is reported (per-field rules and the rules across fields together)."""
    doc = _doc()
    doc["objects"][0]["axes"] = [0.3, 1e-4, 400]
    doc["objects"][1]["center"][2] = float("inf")
    doc["objects"][1]["object_id"] = "a"  # duplicate, reported with the geometry errors
    doc["categories"].append("tv")
    errors = _errors(doc)
    assert set(errors) == {"objects[0].axes[1]", "objects[0].axes[2]", "objects[1].center[2]",
                           "objects[1].object_id", "categories[2]"}, errors
    assert "0.001" in errors["objects[0].axes[1]"] and "100" in errors["objects[0].axes[2]"]
    assert "also objects[0]" in errors["objects[1].object_id"]
    e = Ellipsoid(np.zeros(3), np.array([0.5, 0.5, 200.0]))  # a valid ellipsoid, too large a map
    with pytest.raises(MapValidationError) as exc:
        SceneMap("m", "M", (0, 0, 1), ("a",), (MapObject("1", "a", e),))
    assert [x["field"] for x in exc.value.errors] == ["objects[0].axes[2]"]
    assert json_path(("objects", 3, "axes", 1)) == "objects[3].axes[1]" and json_path(()) == "$"


def test_chess_errors_name_the_chess_fields_all_at_once(chess_source: dict[str, Any]) -> None:
    bad = copy.deepcopy(chess_source)
    bad["objects"][1]["category_id"] = 99
    bad["objects"][2]["ellipsoid"]["R"] = [[1, 0, 0], [0, 1, 0]]
    bad["objects"][3]["ellipsoid"].pop("center")
    bad["category_id_to_label"]["0"] = ""
    with pytest.raises(MapValidationError) as exc:
        scene_map_from_chess(bad)
    fields = {e["field"]: e["message"] for e in exc.value.errors}
    assert set(fields) == {"objects[1].category_id", "objects[2].ellipsoid.R",
                           "objects[3].ellipsoid.center", "category_id_to_label.0"}, fields
    assert "unknown category id 99" in fields["objects[1].category_id"]
    assert fields["objects[3].ellipsoid.center"] == "required field missing"


def test_chess_ids_integral_floats_and_strings() -> None:
    """As before the models: integral floats are integers, decimal strings are kept; a
    fractional or boolean id is refused."""
    def doc(category_id: Any, object_id: Any) -> dict[str, Any]:
        return {"category_id_to_label": {"0": "TV"},
                "objects": [{"category_id": category_id, "object_id": object_id,
                             "ellipsoid": {"axes": [0.3, 0.2, 0.1], "center": [0, 0, 1],
                                           "R": np.eye(3).tolist()}}]}
    for cid, oid in ((0.0, 12.0), ("0", "12"), (0, 12)):
        assert scene_map_from_chess(doc(cid, oid)).objects[0].object_id == "12"
    # unknown fields are refused, naming them (issue 30: everywhere in the API)
    with pytest.raises(MapValidationError) as exc:
        scene_map_from_chess({**doc(0, 1), "extra": 1})
    assert [e["field"] for e in exc.value.errors] == ["extra"]
    for cid, oid, field in ((0.5, 1, "objects[0].category_id"), (True, 1,
                            "objects[0].category_id"), (0, 1.5, "objects[0].object_id")):
        with pytest.raises(MapValidationError) as exc:
            scene_map_from_chess(doc(cid, oid))
        assert any(e["field"].startswith(field) for e in exc.value.errors), exc.value.errors
    for labels, objects, field in (({"0": "TV"}, 1.5, "objects"),
                                   ({"0": "TV"}, [7], "objects[0]"),
                                   ([], [], "category_id_to_label"),
                                   ({}, [], "category_id_to_label")):
        with pytest.raises(MapValidationError) as exc:  # not a TypeError: a 422 naming the field
            scene_map_from_chess({"category_id_to_label": labels, "objects": objects})
        assert [e["field"] for e in exc.value.errors] == [field], exc.value.errors
    assert CHESS_JSON_SCHEMA["required"] == ["category_id_to_label", "objects"]
    assert "$defs" not in json.dumps(CHESS_JSON_SCHEMA) + json.dumps(MAP_JSON_SCHEMA)
