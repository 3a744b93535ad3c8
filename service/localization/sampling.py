"""Which minimal samples the RANSAC search tries, and in which order.

A minimal sample (:data:`Sample`) pairs ``size`` distinct usable detections (rows of a
:class:`quadloc.service.localization.scoring.MatchScorer`, ascending) with as many distinct
label-compatible map objects (3: P3P, 2: P2E). Samples are counted in closed form per label
group (:func:`count_samples`) and listed per label group, never by walking all detection
tuples. :func:`sample_order` chooses the order of one solver's samples:

* **exhaustive** (at most ``budget`` samples): every sample in a fixed order (the seed plays no
  part); P3P samples most promising first (:func:`most_promising_first`) when there are at
  most :data:`ORDER_CAP`, else in the enumeration order (:func:`all_samples`);
* **random** (more than ``budget``): the competitor sweep's samples first
  (:func:`sweep_samples`, P3P only), then seeded random ones (:func:`random_samples`) up to
  the budget.

Samples are generated lazily (bounded memory whatever the budget). Why these orders:
``docs/design/localization.md``, "Label-constrained RANSAC".
"""

from __future__ import annotations

import collections
import functools
import itertools
import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import Literal, overload

import numpy as np

from quadloc.factors.arrays import FloatArray, IntArray
from quadloc.maps.compiled import CompiledMap
from quadloc.service.localization.scoring import LabelGroup, MatchScorer

__all__ = [
    "ORDER_CAP",
    "SWEEP_CANDIDATES",
    "SWEEP_FALLBACK_MAX_SAMPLES",
    "SWEEP_MAX_SAMPLES",
    "Sample",
    "SampleOrder",
    "all_samples",
    "count_map_samples",
    "count_samples",
    "enumerate_samples",
    "most_promising_first",
    "random_samples",
    "sample_order",
    "sweep_samples",
    "triangle_areas",
]

#: Exhaustive P3P searches with at most this many samples try them most promising first
#: (:func:`most_promising_first`; larger ones keep the lazy fixed order: bounded memory).
ORDER_CAP = 4096
#: Competitor sweep (:func:`sweep_samples`): detections considered and most samples.
SWEEP_CANDIDATES = 8
SWEEP_MAX_SAMPLES = 24
#: ... and, when no triple has at most :data:`SWEEP_MAX_SAMPLES` assignments (every label
#: repeated: a map of several copies of a room, k copies giving >= k^3 assignments), the most
#: samples of the fallback triple (the one with the fewest assignments): without it an early
#: exit would skip every copy, the competitors the ambiguity check needs (5 copies: 125).
SWEEP_FALLBACK_MAX_SAMPLES = 1000

#: A minimal sample: (detection rows, ascending; the map object index of each).
Sample = tuple[tuple[int, ...], tuple[int, ...]]
#: A sample with its position key in :func:`all_samples`' order (:func:`_triple_samples`).
_KeyedSample = tuple[tuple[int, ...], Sample]


@dataclass(frozen=True)
class SampleOrder:
    """The minimal samples of one solver (``size`` 3: P3P, 2: P2E) in the order the search
    tries them (:func:`sample_order`).

    Attributes:
        samples: the samples, lazily, in order (at most the budget).
        exhaustive: every label-compatible sample is in ``samples`` (fixed order, no seed).
        sweep_first: the competitor sweep's samples at the head of a random order ([] when
            exhaustive, for P2E, or when no triple qualifies).
    """

    scorer: MatchScorer
    size: int
    samples: Iterator[Sample]
    exhaustive: bool
    sweep_first: list[Sample]

    def competitor_sweep(self, n_taken: int) -> list[Sample]:
        """The competitor sweep's samples not yet tried after ``n_taken`` samples of this
        order were taken: the rest of :attr:`sweep_first` when it leads the order, else every
        sample of :func:`sweep_samples` (P3P; [] for P2E)."""
        if self.sweep_first:
            return self.sweep_first[n_taken:]
        return sweep_samples(self.scorer) if self.size == 3 else []


def sample_order(scorer: MatchScorer, size: int, budget: int,
                 rng: np.random.Generator) -> SampleOrder:
    """The order in which the search tries the samples of ``size`` within ``budget`` samples
    (module docstring); ``rng`` draws the random samples (lazily, as they are taken)."""
    samples = enumerate_samples(scorer, size, budget)
    if samples is None:
        # the competitor sweep's samples first (the most promising triple, found without
        # listing every sample), then random ones (seeded) up to the budget
        sweep_first = sweep_samples(scorer)[:budget] if size == 3 else []
        return SampleOrder(scorer, size, itertools.chain(sweep_first, random_samples(
            scorer, size, budget - len(sweep_first), rng)), False, sweep_first)
    if size == 3 and count_samples(scorer, size) <= ORDER_CAP:
        samples = most_promising_first(scorer)
    # exhaustive: every sample in a fixed order (the seed plays no part)
    return SampleOrder(scorer, size, samples, True, [])


def _compositions(groups: list[LabelGroup], size: int) -> list[tuple[int, ...]]:
    """Ways to split a sample of ``size`` among the groups: ``m_g`` detections (and as many
    distinct objects) from group g, ``m_g <= min(#detections, #objects)``."""
    return _compositions_of(tuple(min(len(d), len(o), size) for d, o in groups), size)


@functools.lru_cache(maxsize=256)
def _compositions_of(caps: tuple[int, ...], size: int) -> list[tuple[int, ...]]:
    """:func:`_compositions` from the groups' caps ``min(#detections, #objects, size)`` (the
    same lists for the same caps: computed once; callers do not modify them)."""
    out: list[tuple[int, ...]] = []

    def rec(g: int, left: int, acc: tuple[int, ...]) -> None:
        if g == len(caps):
            if left == 0:
                out.append(acc)
            return
        for m in range(min(caps[g], left) + 1):
            rec(g + 1, left - m, (*acc, m))

    rec(0, size, ())
    return out


def count_samples(scorer: MatchScorer, size: int) -> int:
    """Number of label-compatible minimal samples of ``size`` (distinct detections, distinct
    objects), from per-label counts: ``sum over splits of prod_g C(n_det_g, m_g) P(n_obj_g, m_g)``
    (no walk over detection tuples, so it costs nothing with hundreds of detections)."""
    return _count_samples(tuple((len(d), len(o)) for d, o in scorer.label_groups), size)


def count_map_samples(compiled: CompiledMap, labels: Sequence[str], size: int) -> int:
    """:func:`count_samples` of detections with ``labels`` against every object of
    ``compiled`` (a whole map, where the scorer holds a part of it: the places the
    constellation search kept)."""
    counts = collections.Counter(labels)
    return _count_samples(tuple((n, len(compiled.indices_for(label)))
                                for label, n in sorted(counts.items())), size)


@functools.lru_cache(maxsize=256)
def _count_samples(group_sizes: tuple[tuple[int, int], ...], size: int) -> int:
    """:func:`count_samples` from the (#detections, #objects) of each label group: the
    coefficient of x^size in prod_g sum_m C(n_det_g, m) P(n_obj_g, m) x^m (exact ints), the same
    sum as over the splits (:func:`_compositions`), in O(groups x size)."""
    coeffs = [1] + [0] * size
    for n_det, n_obj in group_sizes:
        term = [math.comb(n_det, m) * math.perm(n_obj, m) for m in range(size + 1)]
        coeffs = [sum(coeffs[i] * term[k - i] for i in range(k + 1)) for k in range(size + 1)]
    return coeffs[size]


def all_samples(groups: list[LabelGroup], size: int) -> Iterator[Sample]:
    """Every label-compatible minimal sample ((d...), (o...)) (detections ascending) of the
    label ``groups`` (:attr:`MatchScorer.label_groups`), lazily, in a fixed order: split among
    the groups, then itertools' combinations of each group's detections and permutations of its
    objects. Materialised per split: each drawn group's (combination, permutation) list, none
    longer than the split's sample count (callers list at most ``cap`` samples,
    :func:`enumerate_samples`)."""
    for comp in _compositions(groups, size):
        # per group the split draws from: its (detection, object) pair lists, combinations of
        # detections outer, permutations of objects inner; their product in group order
        per_group = [[list(zip(dets, objs, strict=True))
                      for dets in itertools.combinations(d, m)
                      for objs in itertools.permutations([int(x) for x in o], m)]
                     for (d, o), m in zip(groups, comp, strict=True) if m]
        for parts in itertools.product(*per_group):
            dets, objs = zip(*sorted(itertools.chain.from_iterable(parts)), strict=True)
            yield dets, objs


def enumerate_samples(scorer: MatchScorer, size: int, cap: int) -> Iterator[Sample] | None:
    """All label-compatible minimal samples (lazily, :func:`all_samples`' fixed order), or
    None if there are more than ``cap``. Only the samples themselves are generated (per label
    group), never all detection tuples."""
    if count_samples(scorer, size) > cap:
        return None
    return all_samples(scorer.label_groups, size)


def random_samples(scorer: MatchScorer, size: int, count: int,
                   rng: np.random.Generator) -> Iterator[Sample]:
    """``count`` label-compatible samples drawn uniformly (with repetition) over all of them,
    lazily (one at a time): a split among the label groups with probability proportional to
    its number of samples, then distinct detections and distinct objects within each group."""
    groups = scorer.label_groups
    comps = _compositions(groups, size)
    weights = np.array([float(math.prod(math.comb(len(d), m) * math.perm(len(o), m)
                                        for (d, o), m in zip(groups, c, strict=True)))
                        for c in comps])
    if len(comps) == 0 or weights.sum() == 0:
        return
    p = weights / weights.sum()
    # rng.choice(len(comps), p=p) without its per-call checks: the same cdf search of one
    # rng.random() draw (the same stream; tests/service/localization/test_ransac.py)
    cdf = p.cumsum()
    cdf /= cdf[-1]
    for _ in range(count):
        k = int(cdf.searchsorted(rng.random(), side="right"))
        pairs: list[tuple[int, int]] = []
        for (d, o), m in zip(groups, comps[k], strict=True):
            if m == 0:
                continue
            dd = rng.choice(len(d), m, replace=False)
            oo = rng.choice(len(o), m, replace=False)
            pairs += [(d[int(i)], int(o[int(j)])) for i, j in zip(dd, oo, strict=True)]
        pairs.sort()
        yield tuple(q[0] for q in pairs), tuple(q[1] for q in pairs)


def most_promising_first(scorer: MatchScorer) -> Iterator[Sample]:
    """Every label-compatible triple sample (an exhaustive search), ordered so that the ones
    most likely to give the right pose come first, which lets the early exit happen after the
    first batch: fewest label-compatible alternatives first (the product over the sample's
    detections of their numbers of compatible objects: a detection whose label has one object
    in the map can only be matched to it), then the largest image triangle of the detection
    centres (P3P's conditioning); ties in :func:`all_samples`' order. A stable order on fixed
    keys: independent of the seed.

    Both keys depend on the detection triple only, so the triples are sorted (not the samples)
    and each triple's object assignments are generated lazily, when the search reaches them:
    the samples after an early exit are never built. Triples with equal keys (duplicate
    detections) have their samples merged in :func:`all_samples`' order."""
    groups = scorer.label_groups
    comps = _compositions(groups, 3)
    if not comps:
        return
    group_of = np.zeros(scorer.n_det, dtype=np.intp)
    for gi, (d, _) in enumerate(groups):
        group_of[d] = gi
    n_objects = np.array([len(o) for _, o in groups], dtype=np.intp)
    # every detection triple (ascending rows) whose labels have enough distinct objects:
    # per position, the triple's detections of its group are at most the group's objects
    tris = _triples(scorer.n_det)
    g = group_of[tris]
    same = (g[:, :, None] == g[:, None, :]).sum(axis=2)
    dets = tris[np.all(same <= n_objects[g], axis=1)]
    if len(dets) == 0:
        return
    n_compat = scorer.compat.sum(axis=1).astype(float)
    prod = np.prod(n_compat[dets], axis=1)
    area = triangle_areas(scorer, dets)
    # a stable order of the keys; triples with equal keys are merged below in all_samples'
    # order, so the order in which the triples were listed plays no part
    order: list[int] = np.lexsort((-area, prod)).tolist()
    triples: list[tuple[int, ...]] = [tuple(t) for t in dets.tolist()]
    keys: list[tuple[float, float]] = list(zip(prod.tolist(), area.tolist(), strict=True))
    comp_index = {c: ci for ci, c in enumerate(comps)}
    positions = [{x: k for k, x in enumerate(d)} for d, _ in groups]

    def where(triple: tuple[int, ...]) -> tuple[int, tuple[int, ...]]:
        """The triple's split index and per drawn group the index of its detection
        combination among ``itertools.combinations`` of the group's detections."""
        per_group: list[list[int]] = [[] for _ in groups]
        for x in triple:
            per_group[int(group_of[x])].append(positions[int(group_of[x])][x])
        ci = comp_index[tuple(len(p) for p in per_group)]
        return ci, tuple(_combination_rank(p, len(groups[gi][0]))
                         for gi, p in enumerate(per_group) if p)

    k = 0
    while k < len(order):
        run = [order[k]]
        while k + len(run) < len(order) and keys[order[k + len(run)]] == keys[order[k]]:
            run.append(order[k + len(run)])
        k += len(run)
        if len(run) == 1:
            yield from _triple_samples(groups, comps, triples[run[0]], where(triples[run[0]]))
        else:  # equal keys: every sample of the run, in all_samples' order
            merged = sorted(itertools.chain.from_iterable(
                _triple_samples(groups, comps, triples[t], where(triples[t]), keyed=True)
                for t in run))
            yield from (sm for _, sm in merged)


def _combination_rank(combination: Sequence[int], n: int) -> int:
    """Position of ``combination`` (ascending indices in ``range(n)``) in
    ``itertools.combinations(range(n), len(combination))`` (lexicographic)."""
    m = len(combination)
    rank, prev = 0, -1
    for i, c in enumerate(combination):
        for v in range(prev + 1, c):
            rank += math.comb(n - 1 - v, m - 1 - i)
        prev = c
    return rank


@overload
def _triple_samples(groups: list[LabelGroup], comps: list[tuple[int, ...]],
                    triple: tuple[int, ...], where: tuple[int, tuple[int, ...]],
                    keyed: Literal[False] = False) -> Iterator[Sample]: ...


@overload
def _triple_samples(groups: list[LabelGroup], comps: list[tuple[int, ...]],
                    triple: tuple[int, ...], where: tuple[int, tuple[int, ...]],
                    keyed: Literal[True]) -> Iterator[_KeyedSample]: ...


def _triple_samples(
    groups: list[LabelGroup], comps: list[tuple[int, ...]],
    triple: tuple[int, ...], where: tuple[int, tuple[int, ...]], keyed: bool = False,
) -> Iterator[Sample | _KeyedSample]:
    """The samples ``(dets, objs)`` of one detection triple (every assignment of distinct
    compatible objects), in :func:`all_samples`' order; with ``keyed``, each as ``(key,
    sample)``, ``key`` its position there. ``where``: the triple's split index and per drawn
    group its combination index (:func:`most_promising_first`)."""
    ci, combo_index = where
    drawn = [(set(d), [int(x) for x in o], m)
             for (d, o), m in zip(groups, comps[ci], strict=True) if m]
    # per drawn group, the positions of its detections in the (ascending) triple
    slots = [[k for k, x in enumerate(triple) if x in dets] for dets, _, _ in drawn]
    perms = [list(itertools.permutations(o, m)) for _, o, m in drawn]
    for choice in itertools.product(*(range(len(p)) for p in perms)):
        objs = [0] * len(triple)
        for sl, p, j in zip(slots, perms, choice, strict=True):
            for k, o in zip(sl, p[j], strict=True):
                objs[k] = o
        if keyed:  # per group: combination index x permutations + permutation index
            yield (ci, *(c * len(p) + j for c, p, j in zip(combo_index, perms, choice,
                                                           strict=True))), (triple, tuple(objs))
        else:
            yield triple, tuple(objs)


def triangle_areas(scorer: MatchScorer, dets: IntArray) -> FloatArray:
    """Twice the image areas (S,) px^2 of the triangles of the scorer's detection centres
    ``dets`` (S, 3) (detection rows; P3P's conditioning)."""
    c = scorer.params[dets, :2]  # (S, 3, 2)
    return np.abs((c[:, 1, 0] - c[:, 0, 0]) * (c[:, 2, 1] - c[:, 0, 1])
                  - (c[:, 2, 0] - c[:, 0, 0]) * (c[:, 1, 1] - c[:, 0, 1]))


def sweep_samples(scorer: MatchScorer, rows: IntArray | None = None) -> list[Sample]:
    """The minimal samples of the competitor sweep: every label-compatible assignment
    (distinct objects) of ONE detection triple, the one with the largest image triangle among
    the :data:`SWEEP_CANDIDATES` detections with the fewest compatible objects and at most
    :data:`SWEEP_MAX_SAMPLES` assignments; when none has so few, the one with the fewest
    assignments (largest triangle among those) if at most :data:`SWEEP_FALLBACK_MAX_SAMPLES`;
    empty if none qualifies (why: ``docs/design/localization.md``). ``rows``: the detections
    (scorer rows) the triple is taken from (None: every usable detection)."""
    groups = scorer.label_groups
    group_of = np.zeros(scorer.n_det, dtype=np.intp)
    for gi, (dets, _) in enumerate(groups):
        group_of[dets] = gi
    n_objects = np.array([len(o) for _, o in groups], dtype=np.int64)[group_of]  # per detection
    # the candidates: fewest compatible objects, then lowest index; their triples ascending
    pool = np.arange(scorer.n_det) if rows is None else np.asarray(rows, dtype=np.intp)
    cand = np.sort(pool[np.lexsort((pool, n_objects[pool]))][:SWEEP_CANDIDATES])
    tris = cand[_triples(len(cand))]
    # assignments of distinct objects: n0 (n1 - [g1 = g0]) (n2 - [g2 = g0] - [g2 = g1])
    g, n = group_of[tris], n_objects[tris]
    counts = n[:, 0] * (n[:, 1] - (g[:, 1] == g[:, 0])) * (
        n[:, 2] - (g[:, 2] == g[:, 0]) - (g[:, 2] == g[:, 1]))
    ok = np.flatnonzero((counts > 0) & (counts <= SWEEP_MAX_SAMPLES))
    if len(ok) == 0 and np.any(counts > 0):  # every label repeated (copies of a room)
        fewest = int(counts[counts > 0].min())
        ok = np.flatnonzero(counts == fewest) if fewest <= SWEEP_FALLBACK_MAX_SAMPLES else ok
    if len(ok) == 0:
        return []
    tri: tuple[int, ...] = tuple(tris[ok[np.argmax(triangle_areas(scorer, tris[ok]))]].tolist())
    return [(tri, objs)
            for objs in itertools.product(*(groups[group_of[d]][1].tolist() for d in tri))
            if len(set(objs)) == 3]


@functools.lru_cache(maxsize=16)
def _triples(n: int) -> IntArray:
    """``itertools.combinations(range(n), 3)`` as an array (T, 3), read-only."""
    out = np.array(list(itertools.combinations(range(n), 3)), dtype=np.intp).reshape(-1, 3)
    out.setflags(write=False)
    return out
