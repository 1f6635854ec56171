"""The line-of-sight test: features that other rays pass through are mismatches.

A real surface stops the rays that meet it; a mismatch registered at a wrong, shorter
range sits in space other rays of nearly the same direction cross on their way to
something farther (:func:`contradicted_features`). The fit drops such features before
sampling, and the return guard drops those rays clearly pass through.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from occtool.features import FeatureGeometry, Features
from occtool.fit._profile import FOCUS_WINDOW, FOCUS_WINDOW_ABS, angle_bins, group_by_bin

FloatArray = NDArray[np.float64]

#: Pan-angle bins of the line-of-sight test (:func:`contradicted_features`).
SIGHT_BINS = 120
#: A ray passes "through" a feature when it crosses the feature's horizontal distance
#: within this many metres of the feature's height, plus this share of the distance. Tight,
#: because rays grazing a horizontal surface (a table top seen from above) end on it a
#: little farther on: 5 cm + 10 % counted those as passing through the nearer part.
SIGHT_HEIGHT_TOLERANCE = 0.02
SIGHT_HEIGHT_SHARE = 0.02
#: Rays per bin tested against each feature at most (an even subsample beyond that), so
#: the test stays linear in the number of features.
SIGHT_MAX_RAYS = 128
#: Features of the line-of-sight test evaluated at once: their pairs' temporaries stay in
#: the cache and are reused from the heap block after block (1 << 16 made them fresh pages
#: every fit: the narrow aisle's first fit touched 540 more, of 3,800).
SIGHT_BLOCK = 1 << 10


#: Buckets per key of :class:`SortedRays`' search table: at least SEARCH_BUCKETS, up to
#: SEARCH_BUCKETS_MAX when queries outnumber the keys (a finer table is worth building for
#: a million queries, 66 -> 36 ms, not for ten thousand, whose searches it slowed by 2 ms).
SEARCH_BUCKETS = 4
SEARCH_BUCKETS_MAX = 16
#: Most keys a bucket may hold for the table to be searched (beyond: a binary search).
SEARCH_CROWD = 32


class SortedRays:
    """Rays sorted by a key, with each ray's horizontal distance and height in that order
    (read per pair from these few thousand values, not from every feature's), and a bucket
    table that finds runs of keys faster than a binary search.

    A binary search of a million unsorted queries is a branch mispredicted at each of
    its ~14 levels (80 ms at a million features); the table maps a query's bucket
    (``floor((key - base) * scale)``, monotone in the key) to the keys of lower buckets,
    all below the query, and only the few keys of its own bucket are compared.
    """

    # A plain class, not a dataclass (as SightIndex): each dataclass made was about 1 ms of
    # a fresh process's import, for records only the fit builds and reads.
    __slots__ = ("keys", "distance", "h", "base", "scale", "n_buckets", "first")

    def __init__(self, keys: FloatArray, distance: FloatArray, h: FloatArray, base: float, scale: float,
                 n_buckets: int, first: NDArray[np.intp] | None) -> None:
        self.keys, self.distance, self.h = keys, distance, h
        self.base, self.scale, self.n_buckets = base, scale, n_buckets
        #: ``first[b]``: the first key whose bucket is ``b - 1`` or higher (bucket -1 holds
        #: what lies below the first key); None: no table (binary searches).
        self.first = first

    @classmethod
    def build(cls, keys: FloatArray, distance: FloatArray, h: FloatArray, queries: int = 0) -> SortedRays:
        """The rays sorted by ``keys`` (ascending), for about ``queries`` queries a search."""
        base, span = (float(keys[0]), float(keys[-1] - keys[0])) if keys.size else (0.0, 0.0)
        per_key = int(np.clip(queries // max(4 * keys.size, 1), SEARCH_BUCKETS, SEARCH_BUCKETS_MAX))
        n_buckets = per_key * keys.size
        scale = n_buckets / span if span > 0 and np.isfinite(span) else 0.0
        rays = cls(keys, distance, h, base, scale, n_buckets, None)
        if scale > 0:
            crowd = np.bincount(rays._buckets(keys), minlength=n_buckets + 2)
            if int(crowd.max()) <= SEARCH_CROWD:
                first = np.zeros(n_buckets + 3, dtype=np.intp)
                np.cumsum(crowd, out=first[1:])
                rays = cls(keys, distance, h, base, scale, n_buckets, first)
        return rays

    def _buckets(self, values: NDArray[np.floating[Any]]) -> NDArray[np.intp]:
        """Each value's bucket plus one, clipped to ``[0, n_buckets + 1]``: monotone in the value."""
        return (np.clip(np.floor((values - self.base) * self.scale), -1.0, float(self.n_buckets)) + 1.0
                ).astype(np.intp)

    def search(self, queries: NDArray[np.floating[Any]], side: str) -> NDArray[np.intp]:
        """``np.searchsorted(self.keys, queries, side=side)``, exactly."""
        if self.first is None or not np.isfinite(queries).all():
            return np.searchsorted(self.keys, queries, side=side)  # type: ignore[call-overload]
        bucket = self._buckets(queries)
        # Every key of a lower bucket lies below the query, every key of a higher one above
        # it: the answer lies among the keys of the query's own bucket.
        index, end = self.first.take(bucket), self.first.take(bucket + 1)
        keys = self.keys
        open_ = np.flatnonzero(index < end)
        while open_.size:
            at, asked = index.take(open_), queries.take(open_)
            below = keys.take(at) < asked if side == "left" else keys.take(at) <= asked
            open_ = open_[below]
            index[open_] += 1
            open_ = open_[index.take(open_) < end.take(open_)]
        return index

    def pairs(self, low: NDArray[np.floating[Any]],
              high: NDArray[np.floating[Any]]) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
        """Every pair (query ``i``, ray) whose key lies in ``[low[i], high[i]]``: the query's
        index and the ray's position in this order, one row per pair."""
        first = self.search(low, "left")
        span = np.maximum(self.search(high, "right") - first, 0)
        owner = np.repeat(np.arange(span.size), span)
        return owner, np.repeat(first - np.cumsum(span) + span, span) + np.arange(owner.size)


class SightIndex:
    """What the line-of-sight test knows of the features whatever it tests: their
    horizontal distance, height and bin, the bins' rays sorted by elevation and by
    distance, and the features in bins of at least three (the only ones tested)."""

    __slots__ = ("distance", "h", "bins", "lane", "by_elevation", "by_distance", "tested")

    def __init__(self, distance: FloatArray, h: FloatArray, bins: NDArray[np.intp], lane: float,
                 by_elevation: SortedRays, by_distance: SortedRays, tested: NDArray[np.intp]) -> None:
        self.distance, self.h, self.bins, self.lane = distance, h, bins, lane
        self.by_elevation, self.by_distance, self.tested = by_elevation, by_distance, tested


def sight_index(features: Features, origin: float = 0.0, *, geometry: FeatureGeometry | None = None) -> SightIndex:
    """The :class:`SightIndex` of ``features`` with the bins starting at ``origin``
    (``geometry``: the features' :class:`~occtool.features.FeatureGeometry`, if held)."""
    alpha, h, r = (geometry if geometry is not None else FeatureGeometry.of(features)).polar()
    if r.size == 0:
        empty = np.zeros(0)
        nothing = np.zeros(0, dtype=np.intp)
        no_rays = SortedRays.build(empty, empty, empty)
        return SightIndex(empty, empty, nothing, 1.0, no_rays, no_rays, nothing)
    distance = np.sqrt(np.maximum(r**2 - h**2, 0.0))
    bins = angle_bins(alpha - origin, SIGHT_BINS)
    order, _ = group_by_bin(bins, SIGHT_BINS)
    counts = np.bincount(bins, minlength=SIGHT_BINS)
    starts = np.cumsum(counts) - counts
    # Each bin's rays: all its features, or an even subsample of them.
    step = np.maximum(1, counts // SIGHT_MAX_RAYS)
    n_rays = np.where(counts > 0, -(-counts // step), 0)
    ray_bin = np.repeat(np.arange(SIGHT_BINS), n_rays)
    slot = np.arange(ray_bin.size) - np.repeat(np.cumsum(n_rays) - n_rays, n_rays)
    rays = order[starts[ray_bin] + slot * step[ray_bin]]
    tested = np.flatnonzero(counts.take(bins) >= 3)
    # A ray passes a feature when it ends beyond it (d > D + window) and its height at the
    # feature's distance, z D / d, lies within `within` of the feature's: an interval of
    # the ray's elevation z / d. With the rays sorted by bin, then elevation (as an angle,
    # so the key is bounded), each feature's candidate rays are one run; the exact test is
    # made on those pairs alone (trying every ray of the bin: 2.3x the time at 10k and
    # 100k features, the same answer). Rays ending near the feature, which can save it,
    # are a run of the rays sorted by bin, then distance.
    d_ray, z_ray = distance[rays], h[rays]
    ahead = d_ray > 0
    elevation_key = 4.0 * ray_bin[ahead] + np.arctan2(z_ray[ahead], d_ray[ahead])
    order = np.argsort(elevation_key, kind="stable")
    by_elevation = SortedRays.build(elevation_key[order], d_ray[ahead][order], z_ray[ahead][order], tested.size)
    lane = 2.0 * float(distance.max()) + 1.0
    # Any order that sorts the keys finds the same rays in a run (a two-key lexsort took
    # a millisecond at 10k features).
    distance_key = ray_bin * lane + d_ray
    order = np.argsort(distance_key, kind="stable")
    by_distance = SortedRays.build(distance_key[order], d_ray[order], z_ray[order])
    return SightIndex(distance, h, bins, lane, by_elevation, by_distance, tested)


def contradicted_features(features: Features, origin: float = 0.0,
                          candidates: NDArray[np.bool_] | None = None, *,
                          tolerance: tuple[float, float] = (SIGHT_HEIGHT_TOLERANCE, SIGHT_HEIGHT_SHARE),
                          ratio: int = 2, index: SightIndex | None = None) -> NDArray[np.bool_]:
    """Features that other rays in nearly the same direction pass through.

    A real surface stops the rays that meet it. A mismatch registered at a wrong, shorter
    range sits in space that other rays of its pan-angle bin cross on their way to
    something farther. A feature is contradicted when at least two rays of its bin
    (:data:`SIGHT_BINS`), and at least twice as many as end near it (itself included),
    pass within :data:`SIGHT_HEIGHT_TOLERANCE` (+ :data:`SIGHT_HEIGHT_SHARE` of the
    distance) of its height at its horizontal distance
    and end beyond the focus window (:data:`FOCUS_WINDOW`, :data:`FOCUS_WINDOW_ABS`).
    Near the robot the height tolerance spans a wide tilt range, so isolated mismatches
    there, which would box the robot in, are the ones most surely caught. The bins start
    at the pan angle ``origin``; only the ``candidates`` (default: all) are tested, every
    feature counts as a ray. ``index``: the features' :func:`sight_index` at ``origin``,
    when it was built already (the screen and the return guard test the same features).
    """
    index = sight_index(features, origin) if index is None else index
    contradicted = np.zeros(index.distance.size, dtype=bool)
    if index.distance.size == 0:
        return contradicted
    distance, h, bins, lane = index.distance, index.h, index.bins, index.lane
    by_elevation, by_distance = index.by_elevation, index.by_distance
    tested = index.tested
    if candidates is not None:
        tested = tested[candidates[tested]]
    if tested.size == 0:
        return contradicted
    for first in range(0, tested.size, SIGHT_BLOCK):  # blocks of features bound the pairs' memory
        block = tested[first:first + SIGHT_BLOCK]
        D, H = distance[block], h[block]
        window = D * FOCUS_WINDOW + FOCUS_WINDOW_ABS
        within = tolerance[0] + tolerance[1] * D
        D_safe = np.maximum(D, 1e-12)
        owner, pair_ray = by_elevation.pairs(4.0 * bins[block] + np.arctan((H - within) / D_safe) - 1e-9,
                                             4.0 * bins[block] + np.arctan((H + within) / D_safe) + 1e-9)
        # (np.take: the same gathers, a fifth faster than fancy indexing on millions of pairs.)
        d, z, D_pair = by_elevation.distance.take(pair_ray), by_elevation.h.take(pair_ray), D.take(owner)
        with np.errstate(divide="ignore", invalid="ignore"):
            passes = (d > D_pair + window.take(owner)) & (np.abs(z * D_pair / d - H.take(owner)) < within.take(owner))
        beyond = np.bincount(owner, weights=passes, minlength=block.size)
        maybe = np.flatnonzero(beyond >= ratio)
        if maybe.size == 0:
            continue
        D, H, window, within, beyond = D[maybe], H[maybe], window[maybe], within[maybe], beyond[maybe]
        owner, pair_ray = by_distance.pairs(bins[block[maybe]] * lane + (D - window) - 1e-9,
                                            bins[block[maybe]] * lane + (D + window) + 1e-9)
        ends_near = (np.abs(by_distance.distance.take(pair_ray) - D.take(owner)) <= window.take(owner)) & (
            np.abs(by_distance.h.take(pair_ray) - H.take(owner)) < within.take(owner))
        near = np.maximum(np.bincount(owner, weights=ends_near, minlength=maybe.size), 1)
        contradicted[block[maybe]] = beyond >= np.maximum(ratio, ratio * near)
    return contradicted
