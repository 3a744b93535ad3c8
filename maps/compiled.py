"""A map compiled for the solver: per-object numpy arrays, computed once per (map id, version).

Frames and units: everything is in the map's world frame, metres. ``shape_matrices[i]`` is
``R_i diag(axes_i^2) R_i^T`` (m^2) and ``dual_quadrics[i]`` is
``Q*_i = T_i diag(a^2, b^2, c^2, -1) T_i^T`` with ``T_i = [[R_i, center_i], [0, 1]]``, the
conventions of :mod:`quadloc.factors.camera`. Object ``i`` in every array is
``scene_map.objects[i]``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

import numpy as np

from quadloc.factors.arrays import FloatArray, IntArray
from quadloc.factors.camera import Ellipsoid
from quadloc.maps.model import SceneMap, take

__all__ = ["CompiledMap", "compile_map", "compiled_subset"]


def _frozen(array: FloatArray) -> FloatArray:
    """``array`` as a read-only C-contiguous float64 array (the same array when it is one)."""
    frozen = np.ascontiguousarray(array, dtype=float)
    frozen.setflags(write=False)
    return frozen


def _frozen_indices(indices: IntArray) -> IntArray:
    """``indices``, made read-only."""
    indices.setflags(write=False)
    return indices


class MapVersionView:
    """``map_id`` and ``version`` of a class holding a ``scene_map`` (a stored or compiled
    version of a map)."""

    scene_map: SceneMap

    @property
    def map_id(self) -> str:
        return self.scene_map.map_id

    @property
    def version(self) -> int:
        return self.scene_map.version


@dataclass(frozen=True, eq=False)
class CompiledMap(MapVersionView):
    """Immutable solver view of a :class:`SceneMap` (arrays are read-only).

    Attributes:
        scene_map: the source map (its ``version`` is the version compiled).
        object_ids: ``(N,)`` object ids, in map order.
        categories: ``(N,)`` category label of each object.
        ellipsoids: ``(N,)`` the objects' :class:`Ellipsoid` (world frame).
        centers: ``(N, 3)`` ellipsoid centres, world metres.
        axes: ``(N, 3)`` semi-axes, metres.
        rotations: ``(N, 3, 3)`` ellipsoid-to-world rotations.
        shape_matrices: ``(N, 3, 3)`` ``R diag(axes^2) R^T``, m^2.
        dual_quadrics: ``(N, 4, 4)`` dual quadrics ``Q*``.
        indices_by_category: category -> ``int`` array of object indices (only categories that
            have objects; ``indices_for`` returns an empty array for the others).
    """

    scene_map: SceneMap
    object_ids: tuple[str, ...]
    categories: tuple[str, ...]
    ellipsoids: tuple[Ellipsoid, ...]
    centers: FloatArray
    axes: FloatArray
    rotations: FloatArray
    shape_matrices: FloatArray
    dual_quadrics: FloatArray
    indices_by_category: dict[str, IntArray]

    def __len__(self) -> int:
        return len(self.object_ids)

    def indices_for(self, category: str) -> IntArray:
        """Object indices of ``category`` (empty ``int`` array if none)."""
        found = self.indices_by_category.get(category)
        return found if found is not None else np.zeros(0, dtype=np.intp)

    @property
    def positions(self) -> Mapping[str, int]:
        """Object id -> its position in the arrays, built on first use and memoised (a
        building map has thousands of ids: looked up, not searched)."""
        positions: Mapping[str, int] | None = self.__dict__.get("_positions")
        if positions is None:
            positions = MappingProxyType({o: k for k, o in enumerate(self.object_ids)})
            object.__setattr__(self, "_positions", positions)
        return positions

    @property
    def mean_radii(self) -> FloatArray:
        """``(N,)`` each object's size as one radius, m: the geometric mean of its semi-axes;
        memoised."""
        radii: FloatArray | None = self.__dict__.get("_mean_radii")
        if radii is None:
            radii = _frozen(np.prod(self.axes, axis=1) ** (1.0 / 3.0))
            object.__setattr__(self, "_mean_radii", radii)
        return radii

    def index_of(self, object_id: str) -> int:
        """Position of ``object_id`` in the arrays (:attr:`positions`); ``KeyError`` if
        absent."""
        return self.positions[object_id]

    def summary(self) -> dict[str, Any]:
        return {"map_id": self.map_id, "version": self.version, "objects": len(self)}


#: Attribute of a :class:`SceneMap` holding its compiled form (see :func:`compile_map`).
_MEMO = "_compiled"


def compile_map(scene_map: SceneMap | CompiledMap) -> CompiledMap:
    """The solver's per-object arrays of ``scene_map`` (vectorised, O(N)); a
    :class:`CompiledMap` is returned as is.

    Memoised on the (immutable) ``SceneMap`` itself: it lives and dies with the map, nothing to
    evict or invalidate (the cache of compiled map *versions* is
    :class:`quadloc.maps.cache.CompiledMapCache`).
    """
    if isinstance(scene_map, CompiledMap):
        return scene_map
    memo: CompiledMap | None = scene_map.__dict__.get(_MEMO)
    if memo is not None:
        return memo
    objects = scene_map.objects
    n = len(objects)
    ellipsoids = tuple(o.ellipsoid for o in objects)
    centers = np.array([e.center for e in ellipsoids], dtype=float).reshape(n, 3)
    axes = np.array([e.axes for e in ellipsoids], dtype=float).reshape(n, 3)
    rotations = np.array([e.rotation for e in ellipsoids], dtype=float).reshape(n, 3, 3)
    # M = R diag(axes^2) R^T, batched.
    shape_matrices = np.einsum("nij,nj,nkj->nik", rotations, axes**2, rotations)
    # Q* = T diag(a^2, b^2, c^2, -1) T^T = [[M - c c^T, -c], [-c^T, -1]].
    dual_quadrics = np.empty((n, 4, 4))
    dual_quadrics[:, :3, :3] = shape_matrices - centers[:, :, None] * centers[:, None, :]
    dual_quadrics[:, :3, 3] = -centers
    dual_quadrics[:, 3, :3] = -centers
    dual_quadrics[:, 3, 3] = -1.0
    categories = tuple(o.category for o in objects)
    cats = np.array(categories, dtype=object)
    indices_by_category = {c: _frozen_indices(np.flatnonzero(cats == c).astype(np.intp))
                           for c in dict.fromkeys(categories)}
    compiled = CompiledMap(scene_map, tuple(o.object_id for o in objects), categories, ellipsoids,
                           _frozen(centers), _frozen(axes), _frozen(rotations),
                           _frozen(shape_matrices), _frozen(dual_quadrics), indices_by_category)
    object.__setattr__(scene_map, _MEMO, compiled)
    return compiled


def compiled_subset(compiled: CompiledMap, indices: IntArray) -> CompiledMap:
    """The compiled map of the objects ``indices`` (sorted, unique) of ``compiled``: same map
    id, version, name, up axis and categories, the objects in their order (ids kept), so that an
    answer on the subset names the map's objects. Its arrays are rows of ``compiled``'s (the
    same numbers :func:`compile_map` gives the sub-map, without its per-object work: a
    request takes the sub-map of a few places of a large map), memoised on its sub-map like
    :func:`compile_map`'s."""
    idx = np.asarray(indices, dtype=np.intp)
    rows = idx.tolist()
    sub = compiled.scene_map.subset(rows)
    categories = take(compiled.categories, rows)
    cats = np.array(categories, dtype=object)
    indices_by_category = {c: _frozen_indices(np.flatnonzero(cats == c).astype(np.intp))
                           for c in dict.fromkeys(categories)}
    out = CompiledMap(sub, take(compiled.object_ids, rows), categories,
                      take(compiled.ellipsoids, rows),
                      _frozen(compiled.centers[idx]), _frozen(compiled.axes[idx]),
                      _frozen(compiled.rotations[idx]), _frozen(compiled.shape_matrices[idx]),
                      _frozen(compiled.dual_quadrics[idx]), indices_by_category)
    object.__setattr__(sub, _MEMO, out)
    return out
