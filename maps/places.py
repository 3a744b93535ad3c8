"""The place index of a compiled map: where objects can be seen together.

Built once per compiled map and memoised on it (:func:`place_index`, like
:func:`quadloc.maps.compiled.compile_map` on its ``SceneMap``: it lives and dies with the
version). Everything in the map's world frame, metres.

* **Spatial grid** of the object centres, cells of :data:`VIEW_RANGE_M` (:meth:`PlaceIndex.near`).
* **Covisibility**: two objects are covisible when their centres are at most
  :data:`VIEW_RANGE_M` apart (what one camera inside a room can see together; objects of two
  rooms 12 m apart are not), stored as the sorted pairs ``(i, j)``, ``i < j``
  (:attr:`PlaceIndex.pair_i`, ``pair_j``, ``pair_distance``) and per object as a CSR list of
  neighbours (:meth:`PlaceIndex.neighbours`).
* **Local objects**: each object and its :data:`LOCAL_OBJECTS` - 1 nearest covisible
  neighbours as one padded table (:attr:`PlaceIndex.local`, ``local_valid``): the objects a
  pose anchored on that object is scored against, looked up, not gathered per request.
* **Constellations**: the covisible pairs keyed by their labels, ordered: for labels
  ``(a, b)`` the pairs ``(i, j)`` with ``categories[i] == a`` and ``categories[j] == b`` (both
  orders of a pair of one label), with their centre distance (:meth:`PlaceIndex.pairs_for`).

Cost: O(N k) time and memory for N objects with k covisible neighbours each (a building of
rooms: k is bounded by a room's content, not the number of rooms). Measured on the 1,000-room
building of ``bench.building`` (10,000 objects, 95,000 covisible pairs): about 0.3 s to build,
:meth:`PlaceIndex.nbytes` about 11 MB.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from quadloc.factors.arrays import BoolArray, FloatArray, IntArray
from quadloc.maps.compiled import CompiledMap

__all__ = ["LOCAL_OBJECTS", "VIEW_RANGE_M", "PlaceIndex", "place_index"]

#: Objects whose centres are further apart than this (m) are never seen together.
VIEW_RANGE_M = 6.0
#: Width of the local-object table: an object and at most this many minus one of its
#: covisible neighbours (the nearest).
LOCAL_OBJECTS = 32

#: Attribute of a :class:`CompiledMap` holding its place index.
_MEMO = "_place_index"


def _frozen(a: np.ndarray) -> np.ndarray:
    a = np.ascontiguousarray(a)
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class PlaceIndex:
    """Spatial grid, covisibility and constellations of a compiled map (module docstring).

    Attributes:
        view_range_m: the covisibility distance, m (also the grid's cell size).
        cells: (N, 3) integer grid cell of each object centre.
        grid: cell -> object indices in it.
        pair_i, pair_j: (P,) covisible pairs, ``i < j``; pair_distance: (P,) centre distance m.
        offsets, neighbour: CSR of the covisible neighbours: ``neighbour[offsets[i]:offsets[i+1]]``
            are the objects covisible with ``i`` (sorted, ``i`` itself excluded).
        constellations: (label_a, label_b) -> (I, J, D): ordered pairs of those labels and their
            distance (m).
        local, local_valid: (N, L) object ``i`` then its nearest covisible neighbours
            (``L = min(LOCAL_OBJECTS, 1 + most neighbours)``), padding marked False.
        codes: (N,) each object's label as an index into ``labels`` (the sorted categories).
        radius: (N,) each object's radius, m: the geometric mean of its semi-axes (the size
            the place search compares with a detection's, per request: computed once here).
        cell_ids: (N,) the grid cell of each object as one integer (equal cells, equal ids:
            the place key of the search, no per-request unique over cell rows).
    """

    view_range_m: float
    centers: FloatArray
    cells: IntArray
    grid: dict[tuple[int, int, int], IntArray]
    pair_i: IntArray
    pair_j: IntArray
    pair_distance: FloatArray
    offsets: IntArray
    neighbour: IntArray
    constellations: dict[tuple[str, str], tuple[IntArray, IntArray, FloatArray]]
    local: IntArray
    local_valid: BoolArray
    labels: tuple[str, ...]
    codes: IntArray
    radius: FloatArray
    cell_ids: IntArray

    def nbytes(self) -> int:
        """Bytes held by the index's arrays (the grid's and the constellations' included)."""
        arrays = [self.centers, self.cells, self.pair_i, self.pair_j, self.pair_distance,
                  self.offsets, self.neighbour, self.local, self.local_valid, self.codes,
                  self.radius, self.cell_ids,
                  *self.grid.values(), *(a for t in self.constellations.values() for a in t)]
        return sum(int(a.nbytes) for a in arrays)

    def neighbours(self, i: int) -> IntArray:
        """Objects covisible with object ``i`` (sorted indices, ``i`` excluded)."""
        return self.neighbour[self.offsets[i]:self.offsets[i + 1]]

    def near(self, point: FloatArray, radius: float) -> IntArray:
        """Objects whose centre is within ``radius`` m of ``point`` (3,) world, sorted."""
        p = np.asarray(point, dtype=float)
        lo = np.floor((p - radius) / self.view_range_m).astype(int)
        hi = np.floor((p + radius) / self.view_range_m).astype(int)
        found = [self.grid[(x, y, z)]
                 for x in range(lo[0], hi[0] + 1) for y in range(lo[1], hi[1] + 1)
                 for z in range(lo[2], hi[2] + 1) if (x, y, z) in self.grid]
        if not found:
            return np.zeros(0, dtype=np.intp)
        idx = np.concatenate(found)
        d = np.linalg.norm(self.centers[idx] - p, axis=1)
        return np.sort(idx[d <= radius])

    def pairs_for(self, label_a: str, label_b: str) -> tuple[IntArray, IntArray, FloatArray]:
        """Covisible ordered pairs ``(i, j)`` with labels ``(label_a, label_b)`` and their
        centre distances (m); empty arrays when none."""
        found = self.constellations.get((label_a, label_b))
        if found is None:
            empty = np.zeros(0, dtype=np.intp)
            return empty, empty, np.zeros(0)
        return found


def _covisible_pairs(centers: FloatArray, cells: IntArray,
                     grid: dict[tuple[int, int, int], IntArray], view_range: float
                     ) -> tuple[IntArray, IntArray, FloatArray]:
    """All pairs ``i < j`` with centres at most ``view_range`` apart (grid: only the 27 cells
    around each occupied cell are compared)."""
    ii, jj, dd = [], [], []
    offsets = [(x, y, z) for x in (-1, 0, 1) for y in (-1, 0, 1) for z in (-1, 0, 1)]
    for cell, members in grid.items():
        around = [grid[c] for c in ((cell[0] + a, cell[1] + b, cell[2] + c)
                                    for a, b, c in offsets) if c in grid]
        others = np.concatenate(around)
        d = np.linalg.norm(centers[members][:, None] - centers[others][None], axis=2)
        a, b = np.nonzero((d <= view_range) & (members[:, None] < others[None]))
        ii.append(members[a])
        jj.append(others[b])
        dd.append(d[a, b])
    if not ii:
        empty = np.zeros(0, dtype=np.intp)
        return empty, empty, np.zeros(0)
    i, j, dist = np.concatenate(ii), np.concatenate(jj), np.concatenate(dd)
    order = np.lexsort((j, i))
    return i[order].astype(np.intp), j[order].astype(np.intp), dist[order]


def build_place_index(compiled: CompiledMap, view_range_m: float = VIEW_RANGE_M) -> PlaceIndex:
    """The :class:`PlaceIndex` of ``compiled`` (not memoised: :func:`place_index` is)."""
    centers = np.asarray(compiled.centers, dtype=float)
    n = len(centers)
    cells = np.floor(centers / view_range_m).astype(np.intp).reshape(n, 3)
    grid: dict[tuple[int, int, int], list[int]] = {}
    for k, (x, y, z) in enumerate(cells.tolist()):
        grid.setdefault((x, y, z), []).append(k)
    grid_arrays = {c: _frozen(np.array(v, dtype=np.intp)) for c, v in grid.items()}
    pi, pj, pd = _covisible_pairs(centers, cells, grid_arrays, view_range_m)
    # CSR of both directions
    src = np.concatenate([pi, pj])
    dst = np.concatenate([pj, pi])
    order = np.lexsort((dst, src))
    src, dst = src[order], dst[order]
    offsets = np.zeros(n + 1, dtype=np.intp)
    np.cumsum(np.bincount(src, minlength=n), out=offsets[1:])
    # constellations: ordered label pairs over both directions of every pair
    dist2 = np.concatenate([pd, pd])[order]
    cats = np.array(compiled.categories, dtype=object)
    labels_src, labels_dst = cats[src], cats[dst]
    constellations: dict[tuple[str, str], tuple[IntArray, IntArray, FloatArray]] = {}
    if len(src):
        keys = np.char.add(np.char.add(labels_src.astype(str), "\x1f"), labels_dst.astype(str))
        uniq, inverse = np.unique(keys, return_inverse=True)
        by_key = np.argsort(inverse, kind="stable")
        bounds = np.searchsorted(inverse[by_key], np.arange(len(uniq) + 1))
        for k, key in enumerate(uniq.tolist()):
            sel = by_key[bounds[k]:bounds[k + 1]]
            a, b = key.split("\x1f")
            constellations[(a, b)] = (_frozen(src[sel]), _frozen(dst[sel]), _frozen(dist2[sel]))
    local, local_valid = _local_table(src, dst, dist2, offsets, n)
    labels = tuple(sorted(set(compiled.categories)))
    code = {c: k for k, c in enumerate(labels)}
    codes = np.array([code[c] for c in compiled.categories], dtype=np.intp)
    radius = compiled.mean_radii.reshape(n)
    cell_ids = (np.unique(cells, axis=0, return_inverse=True)[1].ravel().astype(np.intp)
                if n else np.zeros(0, dtype=np.intp))
    return PlaceIndex(view_range_m, _frozen(centers), _frozen(cells), grid_arrays,
                      _frozen(pi), _frozen(pj), _frozen(pd), _frozen(offsets), _frozen(dst),
                      constellations, _frozen(local), _frozen(local_valid), labels,
                      _frozen(codes), _frozen(radius), _frozen(cell_ids))


def _local_table(src: IntArray, dst: IntArray, dist: FloatArray, offsets: IntArray, n: int
                 ) -> tuple[IntArray, BoolArray]:
    """The local-object table (:attr:`PlaceIndex.local`) from the neighbour CSR (``src``,
    ``dst``, ``dist`` sorted by ``src``; ``offsets`` (n + 1,))."""
    counts = np.diff(offsets)
    width = int(min(LOCAL_OBJECTS, 1 + (counts.max() if n else 0)))
    local = np.zeros((n, width), dtype=np.intp)
    valid = np.zeros((n, width), dtype=bool)
    local[:, 0] = np.arange(n)
    valid[:, 0] = True
    order = np.lexsort((dist, src))  # by object, nearest first
    s, d = src[order], dst[order]
    rank = np.arange(len(s)) - offsets[s]
    keep = rank < width - 1
    local[s[keep], 1 + rank[keep]] = d[keep]
    valid[s[keep], 1 + rank[keep]] = True
    return local, valid


def place_index(compiled: CompiledMap) -> PlaceIndex:
    """The :class:`PlaceIndex` of ``compiled`` with :data:`VIEW_RANGE_M`, built on first use
    and memoised on the compiled map (no second cache)."""
    memo: PlaceIndex | None = compiled.__dict__.get(_MEMO)
    if memo is None:
        memo = build_place_index(compiled)
        object.__setattr__(compiled, _MEMO, memo)
    return memo
