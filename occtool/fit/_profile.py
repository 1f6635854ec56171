"""The first-obstacle profile over the pan angle: angle bins, clusters of returns, segments.

Per pan-angle bin, the first obstacle is the nearest *cluster* of returns (single
mismatches do not count, :func:`first_obstacle_distance`); how many returns make a
cluster grows with the data's density (:func:`adaptive_support`). The profile's near runs
are cut into angular segments by dynamic programming (:func:`segment_near_runs`), one group
of pieces per segment.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

#: Pan-angle bins of the range profile that places the segments and centre pieces: the
#: finest resolution, used from :data:`PROFILE_FULL_DENSITY` features on; sparser data
#: gets coarser bins (down to a third), so each bin still holds enough hits.
PROFILE_BINS = 360
PROFILE_FULL_DENSITY = 9000
#: Pan-angle bins of :func:`focus_samples`.
FOCUS_ANGLE_BINS = 120
#: An obstacle is where at least this many hit samples (two per feature) lie within a
#: short stretch of distance: three features.
FOCUS_SUPPORT = 6
#: The stretch: this fraction of the distance plus :data:`FOCUS_WINDOW_ABS` metres.
FOCUS_WINDOW = 0.1
FOCUS_WINDOW_ABS = 0.05


def adaptive_support(n_rays: int) -> tuple[int, int]:
    """Hit samples that make an obstacle, and the frontier's rank, for ``n_rays`` features.

    Sparse data has fewer features per obstacle, and fewer mismatches per bin to guard
    against: three features (six hit samples) and the sixth-farthest ray end at 10k
    features, two features and the second-farthest ray end around 2k, 14 features and
    the 60th-farthest ray end at 100k.
    """
    per_bin = n_rays / FOCUS_ANGLE_BINS
    # Both keep growing with the density beyond 10k features: mismatches grow with it, and
    # a fixed three-feature cluster made of them stood in front of every surface at 100k
    # features (IoU 0.29 instead of 0.69 in office). The support grows slowly, though: a
    # horizontal surface (a table top) spreads its hits over a metre of distance, so a
    # short window holds few of them (per_bin / 30 lost the table at 100k features).
    support = 2 * max(int(np.clip(round(per_bin / 30.0), 2, 3)), round(per_bin / 60.0))
    rank = max(2, round(per_bin / 14.0))
    return support, rank


#: Within this horizontal distance (m) of the sensor an obstacle needs proportionally more
#: hits: ``support * NEAR_SUPPORT_DISTANCE / distance``. Two mismatches 0.33 m away (corridor,
#: 2k features, seed 5) had boxed the robot in. 0.6 m fixed that, moved no other map of
#: 4 scenes x 8 seeds at 1k-10k features by more than a few hundredths of IoU (most not
#: at all) and added no collision; 1.0 m let two office maps collide (0.97 %).
NEAR_SUPPORT_DISTANCE = 0.6


def first_obstacle_distance(alpha: FloatArray, distance: FloatArray, n_bins: int,
                            support: int = FOCUS_SUPPORT, *, front: int = 0, cap: float = np.inf) -> FloatArray:
    """Per pan-angle bin, the horizontal distance of the nearest cluster of hits.

    Isolated outliers (mismatches at a random range) must not count as an obstacle, so
    the first obstacle is the nearest hit followed by at least ``support`` - 1
    more hits within :data:`FOCUS_WINDOW` of its distance (``support`` times
    :data:`NEAR_SUPPORT_DISTANCE` / distance nearer than that distance). Its distance is
    that of the cluster's hit ``front`` places on from its nearest (within its window),
    but at most ``cap`` times the hit ``front // 2`` places on: ``front > 0`` takes a low quantile of the
    cluster, which stays at a surface however many noisy returns there are, and ``cap``
    keeps a surface seen at a grazing angle (a table top, hits spread over its depth) at
    its front edge. ``inf`` where there is none.
    """
    return first_obstacle_distance_in_bins(angle_bins(alpha, n_bins), distance, n_bins, support, front=front, cap=cap)


def first_obstacle_distance_in_bins(bins: NDArray[np.intp], distance: FloatArray, n_bins: int,
                                    support: int = FOCUS_SUPPORT, *, front: int = 0,
                                    cap: float = np.inf) -> FloatArray:
    """:func:`first_obstacle_distance` of hits already in their bins (``angle_bins(alpha, n_bins)``).
    The hits' order does not matter: they are sorted by bin and distance first."""
    if bins.size > NEAREST_FIRST * n_bins:
        return _first_obstacle_by_prefixes(bins, distance, n_bins, support, front, cap)
    distance, bounds = sorted_within_bins(bins, distance, n_bins)
    bins = np.repeat(np.arange(n_bins), np.diff(bounds))
    # One sortable key: bin number, then distance (distances are far below 1e6 m).
    key = bins * 1e6 + distance
    reach = np.searchsorted(key, key + distance * FOCUS_WINDOW + FOCUS_WINDOW_ABS, side="right")
    # Near the robot a real surface spans a wide tilt range and many rays end on it, while
    # two mismatches there box the robot in: within NEAR_SUPPORT_DISTANCE the support grows
    # as 1 / distance.
    needed = support * np.maximum(1.0, NEAR_SUPPORT_DISTANCE / np.maximum(distance, 1e-9))
    supported = (reach - np.arange(key.size)) >= needed
    index = np.flatnonzero(supported)
    ahead = np.minimum(index + front, reach[index] - 1)
    # The cap counts from half way to the front, not from the nearest return:
    # at 100k features a mismatch a few centimetres in front of a dense wall starts a
    # cluster whose window reaches the wall, and capping from it held the crossing 12-15 cm
    # short of the wall.
    anchor = np.minimum(index + front // 2, reach[index] - 1)
    first = np.full(n_bins, np.inf)
    np.minimum.at(first, bins[index], np.minimum(distance[ahead], cap * distance[anchor]))
    return first


#: Hits a bin (on average) beyond which :func:`first_obstacle_distance_in_bins` sorts only
#: each bin's nearest hits, this many at first (twice as many while that does not settle it).
#: A million features: the focus's first obstacles 52 -> 17 ms (1024: 18 ms, 256: 33 ms).
NEAREST_FIRST = 512


def _first_obstacle_by_prefixes(bins: NDArray[np.intp], distance: FloatArray, n_bins: int, support: int,
                                front: int, cap: float) -> FloatArray:
    """:func:`first_obstacle_distance_in_bins` from each bin's nearest hits alone.

    Its value is ``f(i) = min(d[ahead_i], cap d[anchor_i])`` minimised over the supported
    hits ``i`` of a bin sorted by distance; ``ahead_i``, ``anchor_i`` (and the window's
    end) never decrease with ``i``, so neither does ``f``: the bin's first supported hit
    gives it (a NaN, 0 times an infinite cap, included). That hit lies among the nearest
    few hundred of thousands (a million features: at most 327th of ~6,000), so each bin's
    ``k`` nearest are partitioned off and sorted; a hit whose window reaches past them is
    supported when ``k + 1 - i`` hits already are enough. The same keys, sums and
    comparisons as the full sort: the same answer, bit for bit.
    """
    order, bounds = group_by_bin(bins, n_bins)
    grouped = distance[order]
    first = np.full(n_bins, np.inf)
    for b in range(n_bins):  # a loop over bins; each bin's hits are vectorised
        values = grouped[bounds[b]:bounds[b + 1]]
        k = min(values.size, NEAREST_FIRST)
        while values.size:
            value = _first_of_nearest(values, k, float(b) * 1e6, support, front, cap)
            if value is not None:
                first[b] = value
                break
            k = min(values.size, 2 * k)
    return first


def _first_of_nearest(values: FloatArray, k: int, offset: float, support: int, front: int,
                      cap: float) -> float | None:
    """The first obstacle of one bin's hits ``values`` (key offset ``offset``: the bin's
    ``bin * 1e6``) from its ``k`` nearest: ``inf`` for none, None when ``k`` do not tell."""
    if k < values.size:
        part = np.partition(values, k)
        nearest, beyond = np.sort(part[:k]), offset + float(part[k])
    else:
        nearest, beyond = np.sort(values), np.inf
    key = offset + nearest
    end = key + nearest * FOCUS_WINDOW + FOCUS_WINDOW_ABS
    reach = np.searchsorted(key, end, side="right")
    known = end < beyond  # every hit in the window is among the k nearest
    needed = support * np.maximum(1.0, NEAR_SUPPORT_DISTANCE / np.maximum(nearest, 1e-9))
    rank = np.arange(k)
    # A window reaching past the k nearest holds at least k + 1 - i hits.
    supported = np.where(known, reach - rank >= needed, k + 1 - rank >= needed)
    undecided = ~known & ~supported
    candidates = np.flatnonzero(supported | undecided)
    if candidates.size == 0:
        return np.inf if k == values.size else None
    i = int(candidates[0])
    if undecided[i]:
        return None
    # Beyond the k nearest the window's end only bounds these indices from above.
    ahead, anchor = i + front, i + front // 2
    if known[i]:
        ahead, anchor = min(ahead, int(reach[i]) - 1), min(anchor, int(reach[i]) - 1)
    elif ahead >= k:
        return None
    return float(np.minimum(nearest[ahead], cap * nearest[anchor]))



def first_obstacles_in_band(features: Any, robot: Any, n_bins: int) -> FloatArray:
    """Per pan-angle bin, the horizontal distance of the first obstacle among ``features``'
    returns (evidence > 0) inside ``robot``'s body band: :func:`first_obstacle_distance` with
    the support of :func:`adaptive_support`, each return counted twice as the fit's two hit
    samples are. ``inf`` where there is none. The scoring of held-out points and a fused
    map's reach both read a position's first obstacles this way."""
    low, high = robot.body_band
    x, y, z = features.points.T
    band = (z >= low) & (z <= high) & (features.evidence > 0)
    support, _ = adaptive_support(len(features))
    alpha, distance = np.arctan2(y[band], x[band]), np.hypot(x[band], y[band])
    return first_obstacle_distance(np.repeat(alpha, 2), np.repeat(distance, 2), n_bins, support)

#: Values a bin (on average) up to which :func:`order_within_bins` and
#: :func:`sorted_within_bins` sort by both keys at once instead of a bin at a time.
FEW_PER_BIN = 64


def group_by_bin(bins: NDArray[np.intp], n_bins: int) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """The order that groups ``bins`` by bin (stable: ascending index within a bin) and the
    ``n_bins + 1`` bounds of the bins' runs in it. A radix sort of small integers."""
    small = np.int16 if n_bins <= np.iinfo(np.int16).max else np.int32
    order = np.argsort(bins.astype(small), kind="stable")
    bounds = np.zeros(n_bins + 1, dtype=np.intp)
    np.cumsum(np.bincount(bins, minlength=n_bins), out=bounds[1:])
    return order, bounds


def order_within_bins(bins: NDArray[np.intp], values: FloatArray,
                      n_bins: int) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """The order that sorts by bin, then value (stable, as ``np.lexsort((values, bins))``),
    and the ``n_bins + 1`` bounds of the bins' runs in it: a radix grouping, then each run
    sorted on its own (at 10M values several times faster than the two-key sort)."""
    if bins.size <= FEW_PER_BIN * n_bins:
        # Few values a bin: one two-key sort costs less than a sort call a bin.
        bounds = np.zeros(n_bins + 1, dtype=np.intp)
        np.cumsum(np.bincount(bins, minlength=n_bins), out=bounds[1:])
        return np.lexsort((values, bins)), bounds
    order, bounds = group_by_bin(bins, n_bins)
    for first, end in zip(bounds[:-1], bounds[1:]):  # a loop over bins; each run sorts on its own
        run = order[first:end]
        order[first:end] = run[np.argsort(values[run], kind="stable")]
    return order, bounds


def sorted_within_bins(bins: NDArray[np.intp], values: FloatArray,
                       n_bins: int) -> tuple[FloatArray, NDArray[np.intp]]:
    """``values`` grouped by bin (bin 0 first), ascending within each bin.

    Returns the grouped values and the ``n_bins + 1`` bounds of the bins' runs. Grouping
    is a stable radix sort of small integers and only the runs are sorted, several times
    faster than a two-key ``lexsort`` at a million samples, with the same result.
    """
    if bins.size <= FEW_PER_BIN * n_bins:
        order, bounds = order_within_bins(bins, values, n_bins)
        return values[order], bounds
    order, bounds = group_by_bin(bins, n_bins)
    grouped = values[order]
    for first, end in zip(bounds[:-1], bounds[1:]):  # a loop over bins; each run sorts in place
        grouped[first:end].sort()
    return grouped, bounds


def profile_bins(n_rays: int) -> int:
    """Pan-angle bins of the range profile for ``n_rays`` features (120, 240 or 360)."""
    thirds = int(np.clip(round(3 * n_rays / PROFILE_FULL_DENSITY), 1, 3))
    return PROFILE_BINS * thirds // 3


def mean_direction(alpha: FloatArray) -> float:
    """The direction of the mean unit vector of pan angles ``alpha`` (0 if there are none)."""
    if alpha.size == 0:
        return 0.0
    x, y = float(np.cos(alpha).sum()), float(np.sin(alpha).sum())
    return math.atan2(y, x) if math.hypot(x, y) > 1e-9 * alpha.size else 0.0


def angle_bins(alpha: FloatArray, n_bins: int) -> NDArray[np.intp]:
    """Index of the angular bin (of ``n_bins`` over [-pi, pi)) holding each angle."""
    index = np.floor((np.asarray(alpha) + np.pi) * (n_bins / (2.0 * np.pi))).astype(np.intp)
    if index.size and 0 <= int(index.min()) and int(index.max()) < n_bins:
        return index  # every bin in range already: np.mod (an integer division) would keep it
    return np.mod(index, n_bins)


def segment_near_runs(profile: FloatArray, far: NDArray[np.bool_], n_segments: int,
                      max_length: int) -> list[tuple[int, int]]:
    """Cover the near bins of a profile with at most ``n_segments`` runs.

    Dynamic programming over cut positions: a run costs the area between the profile
    and the run's nearest value (what a conservative piece gives away), a stretch of far
    bins may be skipped for free. Returns ``(first, end)`` pairs, ``end`` exclusive.
    """
    n = profile.shape[0]
    y = profile.astype(np.float64)
    far = np.asarray(far, dtype=bool)
    sums = np.concatenate([[0.0], np.cumsum(y)])
    # Runs by their end j (0..n) and length l, longest first, so that the first least
    # cost found is the one with the earliest start, as a scan over starts would find.
    longest = max(1, min(int(max_length), n))
    lengths = np.arange(longest, 0, -1)
    ends = np.arange(n + 1)
    starts = ends[:, None] - lengths[None, :]
    valid = starts >= 0
    starts = np.maximum(starts, 0)
    # min(y[j - l:j]) for l = 1..longest: a running minimum back from each end.
    back = np.where(valid[:, ::-1], y[np.maximum(ends[:, None] - lengths[None, ::-1], 0)], np.inf)
    run_min = np.minimum.accumulate(back, axis=1)[:, ::-1]
    area = sums[ends][:, None] - sums[starts] - run_min * lengths
    cost = np.where(valid, np.maximum(area, 0.0) + 1e-9 * lengths**2, np.inf)
    # Far runs [a, b): from any cut in [a, b) a skip reaches any later cut up to b.
    edges = np.flatnonzero(np.diff(np.concatenate([[0], far.astype(np.int8), [0]])))
    far_runs = list(zip(edges[::2].tolist(), edges[1::2].tolist()))
    leading = far_runs[0][1] if far_runs and far_runs[0][0] == 0 else 0
    # best[g][j]: least cost covering bins [0, j) with g runs; a skip may follow a run.
    best = np.full(n + 1, np.inf)
    best[: leading + 1] = 0.0
    layers = [best]
    # Layer 0 has no runs to trace back. A layer's runs are kept as the index of their
    # length (the start is found again on the way back, for the few cuts it passes).
    run_pick = [np.zeros(0, dtype=np.intp)]
    skip_from = [np.zeros(0, dtype=np.intp)]
    rows = np.arange(n + 1)
    # layer[starts] without a gather: a window over the layer behind `longest` infinities
    # (padded[j + l] = layer[j - lengths[l]], infinite before cut 0 as cost is there).
    padded = np.full(longest + n + 1, np.inf)
    window = np.lib.stride_tricks.sliding_window_view(padded, longest)[: n + 1]
    # A skip from a far run [a, b) to cut j + 1 costs the least run-ending cost in [a, j],
    # from its earliest cut: a running minimum within each far run, all runs at once as
    # the rows of a (runs x longest run) block (padded at the rows' ends, after what is read).
    member = np.concatenate([np.arange(a, b) for a, b in far_runs]) if far_runs else np.zeros(0, dtype=np.intp)
    run_start = np.repeat([a for a, _ in far_runs], [b - a for a, b in far_runs]).astype(np.intp)
    offset = member - run_start
    run_of = np.repeat(np.arange(len(far_runs)), [b - a for a, b in far_runs])
    block_width = int(offset.max(initial=0)) + 1
    block = np.zeros((len(far_runs), block_width), dtype=np.intp)
    block[run_of, offset] = member
    in_block = run_of * block_width + offset
    position_in_run = np.arange(block_width)
    after_skip = np.full(n + 1, np.inf)
    from_skip = np.zeros(n + 1, dtype=np.intp)
    for _ in range(n_segments):
        padded[longest:] = layers[-1]
        total = window + cost
        pick = np.argmin(total, axis=1)
        after_run = total[rows, pick]
        if member.size:
            values = after_run[block]
            least = np.minimum.accumulate(values, axis=1)
            # The earliest cut of the least cost is the last at which the running minimum
            # fell (a tie keeps the earlier cut, as a strict improvement would).
            fell = np.empty(values.shape, dtype=bool)
            fell[:, 0] = True
            np.less(values[:, 1:], least[:, :-1], out=fell[:, 1:])
            earliest = np.maximum.accumulate(np.where(fell, position_in_run, 0), axis=1)
            after_skip[member + 1] = least.ravel()[in_block]
            from_skip[member + 1] = run_start + earliest.ravel()[in_block]
        use_skip = after_skip < after_run
        layers.append(np.where(use_skip, after_skip, after_run))
        run_pick.append(pick)
        skip_from.append(np.where(use_skip, from_skip, -1))
    finals = [layer[n] for layer in layers]
    g = int(np.argmin(finals))
    if not np.isfinite(finals[g]) or g == 0:
        return [(0, n)]
    segments = []
    position = n
    while g > 0:
        source = int(skip_from[g][position])
        if source >= 0:
            position = source
        start = position - int(lengths[run_pick[g][position]])
        segments.append((start, position))
        position = start
        g -= 1
    return segments[::-1]


def segment_cost(profile: FloatArray, first: int, end: int) -> float:
    """Squared error of the best line through a (circular) run of the profile."""
    y = profile[np.mod(np.arange(first, end), profile.shape[0])]
    if y.size < 3:
        return 0.0
    x = np.arange(y.size, dtype=np.float64)
    coefficients = np.polyfit(x, y, 1)
    return float(np.sum((np.polyval(coefficients, x) - y) ** 2))
