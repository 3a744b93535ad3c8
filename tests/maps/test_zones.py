"""Zones of the map document (rooms, floors as groups of objects): validation naming the field,
round trips through the document, both stores and the HTTP API, old maps unchanged."""

from __future__ import annotations

import copy
import hashlib
import json
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from quadloc.maps.demo import load_demo_map
from quadloc.maps.model import MapValidationError, MapZone, SceneMap, content_hash
from quadloc.maps.store import MapStore
from quadloc.service.schemas.examples import MAP_EXAMPLE
from tests.conftest import make_test_app
from tests.support.buildings import make_building
from tests.support.helpers import assert_problem


def _zoned(doc: dict) -> dict:
    """``doc`` with a floor zone holding every object and a room zone of the first object."""
    out = copy.deepcopy(doc)
    ids = [o["object_id"] for o in out["objects"]]
    out["zones"] = [{"zone_id": "floor-0", "name": "Ground floor", "object_ids": ids},
                    {"zone_id": "kitchen", "object_ids": ids[:1], "parent": "floor-0"}]
    return out


def _fields(doc: dict) -> dict[str, str]:
    with pytest.raises(MapValidationError) as info:
        SceneMap.from_dict(doc)
    return {e["field"]: e["message"] for e in info.value.errors}


def test_zones_round_trip_through_the_document() -> None:
    doc = _zoned(MAP_EXAMPLE)
    scene = SceneMap.from_dict(doc)
    assert scene.zones == (MapZone("floor-0", "Ground floor",
                                   tuple(o["object_id"] for o in MAP_EXAMPLE["objects"])),
                           MapZone("kitchen", None, (MAP_EXAMPLE["objects"][0]["object_id"],),
                                   "floor-0"))
    assert scene.zone_by_id("kitchen").parent == "floor-0"
    exported = scene.to_dict()
    assert exported["zones"] == doc["zones"]  # optional fields absent when not given
    assert SceneMap.from_dict(exported) == scene
    # the in-process constructor validates the same rules
    with pytest.raises(MapValidationError):
        SceneMap(scene.map_id, scene.name, scene.up_axis, scene.categories, scene.objects,
                 zones=(MapZone("z", None, ("no-such-object",)),))


def test_maps_without_zones_keep_their_document_and_hash() -> None:
    demo = load_demo_map()
    doc = demo.to_dict()
    assert "zones" not in doc and demo.zones == ()
    # the hash of a map without zones is the sha256 of its document as before zones existed
    text = json.dumps(doc, sort_keys=True, separators=(",", ":"), ensure_ascii=False)
    rounded = json.loads(text)
    for o in rounded["objects"]:
        for k in ("center", "axes", "quaternion_wxyz"):
            o[k] = [float(f"{v:.12f}") + 0.0 for v in o[k]]
    rounded["up_axis"] = [float(f"{v:.12f}") + 0.0 for v in rounded["up_axis"]]
    expected = hashlib.sha256(json.dumps(rounded, sort_keys=True, separators=(",", ":"),
                                         ensure_ascii=False).encode()).hexdigest()
    assert content_hash(demo) == expected
    assert SceneMap.from_dict({**doc, "zones": []}) == demo
    assert content_hash(SceneMap.from_dict(_zoned(doc))) != expected


def test_bad_zones_name_the_field() -> None:
    doc = _zoned(MAP_EXAMPLE)
    doc["zones"][0]["object_ids"] = [*doc["zones"][0]["object_ids"], "ghost"]
    doc["zones"][1]["parent"] = "attic"
    doc["zones"].append({"zone_id": "kitchen", "object_ids": ["ghost2", "ghost2"]})
    k = len(MAP_EXAMPLE["objects"])
    fields = _fields(doc)
    assert set(fields) == {f"zones[0].object_ids[{k}]", "zones[1].parent", "zones[2].zone_id",
                           "zones[2].object_ids[0]", "zones[2].object_ids[1]"}
    assert "ghost" in fields[f"zones[0].object_ids[{k}]"]
    assert "attic" in fields["zones[1].parent"]
    assert "zones[1]" in fields["zones[2].zone_id"]


@pytest.mark.parametrize("change, field", [
    ({"object_ids": []}, "zones[1].object_ids"),
    ({"zone_id": ""}, "zones[1].zone_id"),
    ({"name": None}, "zones[1].name"),
    ({"parent": None}, "zones[1].parent"),
    ({"colour": "red"}, "zones[1].colour"),
])
def test_malformed_zone_entries(change: dict, field: str) -> None:
    doc = _zoned(MAP_EXAMPLE)
    doc["zones"][1].update(change)
    assert field in _fields(doc)


def test_parent_cycles_are_refused() -> None:
    doc = _zoned(MAP_EXAMPLE)
    doc["zones"][0]["parent"] = "kitchen"  # floor-0 -> kitchen -> floor-0
    assert {"zones[0].parent", "zones[1].parent"} <= set(_fields(doc))
    doc["zones"][0]["parent"] = "floor-0"  # its own parent
    assert "zones[0].parent" in _fields(doc)


def test_both_stores_keep_the_zones(tmp_path: Path) -> None:
    scene = SceneMap.from_dict(_zoned(MAP_EXAMPLE))
    store = MapStore(f"sqlite:///{tmp_path / 'maps.db'}")
    try:
        stored = store.create(scene)
        got = store.get(scene.map_id)
        assert got.scene_map.zones == scene.zones
        assert got.content_hash == stored.content_hash == content_hash(got.scene_map)
    finally:
        store.close()


def test_the_api_stores_zones_and_refuses_bad_ones(tmp_path: Path) -> None:
    with TestClient(make_test_app(tmp_path)) as client:
        doc = _zoned(MAP_EXAMPLE)
        assert client.post("/v1/maps", json=doc).status_code == 201
        got = client.get(f"/v1/maps/{doc['map_id']}").json()
        assert got["map"]["zones"] == doc["zones"]
        bad = _zoned({**MAP_EXAMPLE, "map_id": "zoned-bad"})
        bad["zones"][1]["object_ids"] = [bad["zones"][1]["object_ids"][0], "nope"]
        body = assert_problem(client.post("/v1/maps", json=bad), 422, "invalid-map")
        assert [e["field"] for e in body["errors"]] == ["zones[1].object_ids[1]"]


def test_generated_buildings_name_their_rooms_and_floors_as_zones() -> None:
    b = make_building(5, "perturbed", seed=3, corridors=True)
    zones = {z.zone_id: z for z in b.scene_map.zones}
    for part in (*b.rooms, *b.corridors):
        assert zones[part.zone_id].object_ids == part.object_ids
        assert zones[part.zone_id].parent == part.zone_id.split("-")[0]
    floor_objects = [o.object_id for o in b.scene_map.objects]
    assert sorted(zones["f0"].object_ids) == sorted(floor_objects)
    assert SceneMap.from_dict(b.scene_map.to_dict()) == b.scene_map


def test_the_zone_of_a_pose_is_the_zone_holding_most_of_its_inliers() -> None:
    from quadloc.maps.zones import zone_index

    scene = SceneMap.from_dict(_zoned(MAP_EXAMPLE))  # floor-0: every object; kitchen: the first
    first, second = (o["object_id"] for o in MAP_EXAMPLE["objects"][:2])
    index = zone_index(scene)
    assert index is zone_index(scene)  # memoised
    assert index.zone_of([first]) == "kitchen"  # both hold 1: the smaller zone
    assert index.zone_of([first, second]) == "floor-0"  # 2 against 1
    # per object, the zone of a pose it alone supports (as a position in the map's zones)
    assert index.zone_positions([first, second, "not-in-any-zone"]) == (1, 0, -1)
    assert index.zone_of([]) is None and index.zone_of(["not-in-any-zone"]) is None
    assert zone_index(load_demo_map()).zone_of([first]) is None  # no zones
    # equal counts and sizes: the first in the map's zones
    doc = _zoned(MAP_EXAMPLE)
    doc["zones"] = [{"zone_id": "b", "object_ids": [second]},
                    {"zone_id": "a", "object_ids": [first]}]
    assert zone_index(SceneMap.from_dict(doc)).zone_of([first, second]) == "b"
