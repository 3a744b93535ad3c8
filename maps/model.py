"""The ellipsoid map model: a scene's objects as labelled 3D ellipsoids.

Frames: every ellipsoid is in the map's **world** frame (metres). ``up_axis`` is the world's unit
up direction (the Chess demo map has +Z up). Orientation of each ellipsoid is a unit
``quaternion_wxyz`` (ellipsoid frame -> world frame), its semi-axes are along the rotated x, y, z.

(Owned by the maps issue; the field names below are the contract other modules rely on.)
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from factors.geometry import Ellipsoid


@dataclass(frozen=True)
class MapObject:
    """One object of the map: a stable string id, a category label and its ellipsoid."""

    object_id: str
    category: str
    ellipsoid: Ellipsoid


@dataclass(frozen=True)
class SceneMap:
    """A versioned ellipsoid map. ``version`` is 1 for a new map and grows by one per update."""

    map_id: str
    name: str
    up_axis: tuple[float, float, float]
    categories: tuple[str, ...]
    objects: tuple[MapObject, ...]
    version: int = 1
    metadata: dict[str, Any] = field(default_factory=dict)

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
