"""Which zone of a map an answer is in (zones: docs/maps.md, "Zones").

The rule, in one place: the zone of a pose is the zone holding the most of the objects that
support it (its inliers' ``object_ids``); among zones holding equally many, the one with the
fewest objects (the most specific: a room before its floor), then the first in the map's
``zones``. ``None`` when the map has no zones or no zone holds any of them.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from types import MappingProxyType

from quadloc.maps.model import SceneMap

__all__ = ["ZoneIndex", "zone_index"]

_MEMO = "_zone_index"


@dataclass(frozen=True)
class ZoneIndex:
    """The zones of one map: ``zones_of[object_id]`` the positions (in the map's ``zones``) of
    the zones holding that object; ``sizes[k]`` zone k's object count; ``ids[k]`` its id."""

    ids: tuple[str, ...]
    sizes: tuple[int, ...]
    zones_of: Mapping[str, tuple[int, ...]]

    def zone_of(self, object_ids: Iterable[str]) -> str | None:
        """The zone of a pose supported by ``object_ids`` (the module's rule)."""
        counts: dict[int, int] = {}
        for oid in object_ids:
            for k in self.zones_of.get(oid, ()):
                counts[k] = counts.get(k, 0) + 1
        if not counts:
            return None
        best = min(counts, key=lambda k: (-counts[k], self.sizes[k], k))
        return self.ids[best]

    def zone_positions(self, object_ids: Iterable[str]) -> tuple[int, ...]:
        """Per object, the position (in the map's ``zones``) of the zone of a pose supported by
        that object alone (the module's rule: its most specific zone), -1 where none holds it."""
        return tuple(min(ks, key=lambda k: (self.sizes[k], k)) if ks else -1
                     for ks in (self.zones_of.get(oid, ()) for oid in object_ids))


def zone_index(scene_map: SceneMap) -> ZoneIndex:
    """The :class:`ZoneIndex` of ``scene_map`` (O(total zone members)); memoised on the
    immutable map."""
    memo: ZoneIndex | None = scene_map.__dict__.get(_MEMO)
    if memo is not None:
        return memo
    zones_of: dict[str, list[int]] = {}
    for k, zone in enumerate(scene_map.zones):
        for oid in zone.object_ids:
            zones_of.setdefault(oid, []).append(k)
    index = ZoneIndex(tuple(z.zone_id for z in scene_map.zones),
                      tuple(len(z.object_ids) for z in scene_map.zones),
                      MappingProxyType({o: tuple(ks) for o, ks in zones_of.items()}))
    object.__setattr__(scene_map, _MEMO, index)
    return index
