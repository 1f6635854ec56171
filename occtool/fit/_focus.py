"""The samples the fit sees: the focus on what a monotone model can show, and the frontier.

``F`` increases with ``r``, so behind the first obstacle at a pan angle the samples can only
pull the fit away from it: :func:`focus_samples` keeps those in front of it, in the body's
height band and within the focus range. Where the observed free space ends short of that
range, :func:`frontier_samples` adds occupied samples, so linear pieces do not extrapolate
free space into what was never seen.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from occtool.fit._profile import (
    FOCUS_ANGLE_BINS,
    FOCUS_WINDOW,
    FOCUS_WINDOW_ABS,
    adaptive_support,
    angle_bins,
    first_obstacle_distance,
    first_obstacle_distance_in_bins,
    group_by_bin,
)
from occtool.robot import Robot
from occtool.sensor import SAMPLE_KINDS, SampleBlock, Samples

FloatArray = NDArray[np.float64]

#: Samples up to this fraction (and the window) beyond the first obstacle are kept.
FOCUS_MARGIN = 0.1


def focus_samples(samples: Samples, robot: Robot, focus_range: float = np.inf, *,
                  floor_is_obstacle: bool = False) -> Samples:
    """Keep the samples a monotone occupancy function can honour and navigation needs.

    ``F`` increases with ``r``, and the navigation polygon is cut by the nearest obstacle
    at any height of the robot's body. Behind that obstacle the samples (the wall above a
    low box, the free rays over it) can only pull the fit away from the box, so per
    pan-angle bin the samples farther (horizontally) than the first obstacle in the body's
    height band (:func:`first_obstacle_distance`, plus a margin) are dropped, as are samples
    outside the height band: the navigation map never looks there, and samples farther
    than ``focus_range`` (horizontally).
    """
    distance, bins = _geometry(samples)
    return samples.select(_focus_mask(samples, robot, focus_range, floor_is_obstacle, distance, bins))


def _geometry(samples: Samples) -> tuple[FloatArray, NDArray[np.intp]]:
    """Each sample's horizontal distance and its bin of :data:`FOCUS_ANGLE_BINS`: what the
    focus and the frontier both read of every sample."""
    return np.sqrt(np.maximum(samples.r**2 - samples.h**2, 0.0)), angle_bins(samples.alpha, FOCUS_ANGLE_BINS)


def _focus_mask(samples: Samples, robot: Robot, focus_range: float, floor_is_obstacle: bool,
                distance: FloatArray, bins: NDArray[np.intp]) -> NDArray[np.bool_]:
    """Which samples :func:`focus_samples` keeps (``distance``, ``bins``: :func:`_geometry`)."""
    low = robot.floor_h - 0.05
    high = max(robot.body_band[1], 0.0) + 0.1
    in_band = (samples.h >= low) & (samples.h <= high)
    band_low, band_high = robot.body_band
    if floor_is_obstacle:
        band_low = -np.inf
    hit = (samples.kind == SAMPLE_KINDS["hit"]) & (samples.h >= band_low) & (samples.h <= band_high)
    support, _ = adaptive_support(samples.count("robot"))
    first = first_obstacle_distance(samples.alpha[hit], distance[hit], FOCUS_ANGLE_BINS, support)
    limit = first * (1.0 + FOCUS_WINDOW + FOCUS_MARGIN) + FOCUS_WINDOW_ABS
    limit = np.minimum(limit, focus_range)
    in_front = distance <= limit[bins]
    kind = samples.kind
    always = (kind == SAMPLE_KINDS["robot"]) | (kind == SAMPLE_KINDS["footprint"]) | (kind == SAMPLE_KINDS["frontier"])
    return always | (in_band & in_front)


def focused_with_frontier(samples: Samples, robot: Robot, focus_range: float, *, planar: bool,
                          floor_is_obstacle: bool) -> Samples:
    """``join_samples(focus_samples(samples, ...), frontier_samples(samples, ...))`` in one
    pass: the distances and bins made once for both, the kept samples written straight
    into the joined columns (at a million features each copy of the samples is 0.1 s)."""
    whole = SampleBlock(samples.alpha, samples.h, samples.r, samples.m, samples.weight, samples.kind)
    return focused_blocks([whole], robot, focus_range, planar=planar, floor_is_obstacle=floor_is_obstacle)


_ALWAYS = tuple(SAMPLE_KINDS[k] for k in ("robot", "footprint", "frontier"))
_RAY_ENDS = tuple(SAMPLE_KINDS[k] for k in ("hit", "near", "floor"))


def _of_kinds(kind: NDArray[np.integer[Any]] | int, codes: tuple[int, ...]) -> NDArray[np.bool_] | bool:
    """Whether each sample's kind (or the block's one kind) is one of ``codes``."""
    if isinstance(kind, (int, np.integer)):
        return int(kind) in codes
    found = kind == codes[0]
    for code in codes[1:]:  # a few comparisons: np.isin took 12 ms a million samples
        found |= kind == code
    if found.all():  # one answer for the block: no mask to apply or copy by
        return True
    return found if found.any() else False


def focused_blocks(blocks: list[SampleBlock], robot: Robot, focus_range: float, *, planar: bool,
                   floor_is_obstacle: bool) -> Samples:
    """:func:`focused_with_frontier` of the samples that ``blocks`` make in their order
    (:meth:`~occtool.sensor.SensorModel._sample_blocks`), without writing every sample
    first: only the kept ones are written, once (a million features: 4.3M samples made,
    2.5M kept). Each block's pan angles are binned once, shared by the blocks of one
    feature set, and the robot and footprint samples, always kept, are never measured."""
    low = robot.floor_h - 0.05
    high = max(robot.body_band[1], 0.0) + 0.1
    band_low, band_high = robot.body_band
    if floor_is_obstacle:
        band_low = -np.inf
    hit_code = SAMPLE_KINDS["hit"]
    n_robot = sum(block.count(SAMPLE_KINDS["robot"]) for block in blocks)
    binned: dict[int, NDArray[np.intp]] = {}
    measured: list[tuple[FloatArray, NDArray[np.intp], NDArray[np.bool_] | bool] | None] = []
    hit_bins: list[NDArray[np.intp]] = []
    hit_distance: list[FloatArray] = []
    ends: list[tuple[FloatArray, NDArray[np.intp]]] = []
    for block in blocks:
        always = _of_kinds(block.kind, _ALWAYS)
        if always is True:
            measured.append(None)  # kept whole, neither a hit nor a ray end
            continue
        bins = binned.get(id(block.alpha))
        if bins is None:
            bins = binned[id(block.alpha)] = angle_bins(block.alpha, FOCUS_ANGLE_BINS)
        distance = _horizontal(block.r, block.h)
        hit = _of_kinds(block.kind, (hit_code,))
        if not isinstance(hit, bool) or hit:
            hit_index = np.flatnonzero((block.h >= band_low) & (block.h <= band_high) & hit)
            if hit_index.size:
                hit_bins.append(bins.take(hit_index))
                hit_distance.append(distance.take(hit_index))
        rays = _of_kinds(block.kind, _RAY_ENDS)
        if isinstance(rays, bool):
            if rays:
                ends.append((distance, bins))
        elif rays.any():
            ends.append((distance[rays], bins[rays]))
        measured.append((distance, bins, always))
    support, _ = adaptive_support(n_robot)
    first = first_obstacle_distance_in_bins(_joined(hit_bins, np.intp), _joined(hit_distance, np.float64),
                                            FOCUS_ANGLE_BINS, support)
    limit = first * (1.0 + FOCUS_WINDOW + FOCUS_MARGIN) + FOCUS_WINDOW_ABS
    limit = np.minimum(limit, focus_range)
    frontier = _frontier(ends, n_robot, robot, focus_range, planar)
    kept: list[NDArray[np.bool_] | None] = []
    limits: dict[int, FloatArray] = {}  # each bin array's limits, gathered once
    for block, measures in zip(blocks, measured):
        if measures is None:
            kept.append(None)
            continue
        distance, bins, always = measures
        if id(bins) not in limits:
            limits[id(bins)] = limit.take(bins)
        keep = (block.h >= low) & (block.h <= high) & (distance <= limits[id(bins)])
        if not isinstance(always, bool):
            keep |= always
        kept.append(keep)
    count = sum(len(block) if chosen is None else int(np.count_nonzero(chosen)) for block, chosen in zip(blocks, kept))
    total = count + len(frontier)
    alpha, h, r, m, weight = (np.empty(total) for _ in range(5))
    kind = np.empty(total, dtype=np.int8)
    columns: tuple[NDArray[Any], ...] = (alpha, h, r, m, weight, kind)
    start = 0
    for block, chosen in zip(blocks, kept):
        index = None if chosen is None else np.flatnonzero(chosen)  # once for the block's columns
        size = len(block) if index is None else index.size
        part = slice(start, start + size)
        for column, values in zip(columns, block.columns()):
            if np.ndim(values) == 0 or index is None:
                column[part] = values
            else:
                # mode="clip" writes straight into the column ("raise" buffers a copy first);
                # the indices are the block's own, so nothing is ever clipped.
                np.take(values, index, out=column[part], mode="clip")
        start += size
    for column, values in zip(columns, (frontier.alpha, frontier.h, frontier.r, frontier.m, frontier.weight,
                                        frontier.kind)):
        column[count:] = values
    return Samples(alpha, h, r, m, weight, kind)


def _horizontal(r: FloatArray, h: FloatArray) -> FloatArray:
    """``np.sqrt(np.maximum(r**2 - h**2, 0.0))`` (as :func:`_geometry`), in one buffer."""
    distance = r**2
    distance -= h**2
    np.maximum(distance, 0.0, out=distance)
    return np.sqrt(distance, out=distance)


def _joined(parts: list[NDArray[Any]], dtype: type) -> NDArray[Any]:
    """The parts one after another (an empty array of ``dtype`` for none)."""
    return np.concatenate(parts) if parts else np.zeros(0, dtype=dtype)


#: Ray ends beyond which :func:`frontier_samples` first bounds each bin's rank-th farthest
#: from every FRONTIER_STRIDE-th end, and groups only the ends that can reach it.
FRONTIER_PRUNE = 1 << 17
FRONTIER_STRIDE = 8
#: Heights of the body band that get a frontier sample.
FRONTIER_HEIGHTS = 4
#: The frontier stands this share beyond the observed extent, no farther: an untextured
#: wall may stand right behind the last floor seen (10 % + 5 cm let the robot touch the
#: open scene's white wall at 3k features with the wider default reach).
FRONTIER_MARGIN = 0.03
FRONTIER_ABS = 0.0
#: Unseen space this close to the body (m) is taken as free: what the robot swept to get
#: there. (Before the frontier's own margin shrank, it was 0.1 m plus that margin.)
UNSEEN_CLEARANCE = 0.185


def frontier_samples(samples: Samples, robot: Robot, focus_range: float, *, planar: bool = False) -> Samples:
    """Occupied samples where the observed free space ends short of ``focus_range``.

    A ray is evidence of free space up to its end; beyond the farthest ray ends of a
    pan-angle bin nothing has been seen, an untextured wall may stand there, and linear
    pieces would extrapolate the free space into it. A bin's observed extent is the
    distance of its k-th farthest ray end (k from :func:`adaptive_support`), so that a few
    mismatches registered beyond a surface do not open it up; a bin shorter than both its
    neighbours takes the nearer neighbour's extent. One occupied sample (value 1) per
    height of the body band is placed just beyond the bin's observed extent.
    """
    distance, bins = _geometry(samples)
    # The ray ends are the hit samples and the free samples of floor features.
    kind = samples.kind
    rays = (kind == SAMPLE_KINDS["hit"]) | (kind == SAMPLE_KINDS["near"]) | (kind == SAMPLE_KINDS["floor"])
    return _frontier([(distance[rays], bins[rays])], samples.count("robot"), robot, focus_range, planar)


def _frontier(ends: list[tuple[FloatArray, NDArray[np.intp]]], n_robot: int, robot: Robot, focus_range: float,
              planar: bool) -> Samples:
    """:func:`frontier_samples` of the ray ends ``ends`` (parts of horizontal distances and
    their bins, in any order: each bin's rank-th farthest is a value, whatever the order)
    for ``n_robot`` robot samples (one a feature)."""
    # A planar scan has one beam a direction and no mismatches: its farthest end is seen.
    rank = 1 if planar else adaptive_support(n_robot)[1]
    counts = np.zeros(FOCUS_ANGLE_BINS, dtype=np.intp)
    binned: dict[int, NDArray[np.intp]] = {}  # blocks of one feature set share their bins
    for _, part_bins in ends:
        if id(part_bins) not in binned:
            binned[id(part_bins)] = np.bincount(part_bins, minlength=FOCUS_ANGLE_BINS)
        counts += binned[id(part_bins)]
    if sum(part.size for part, _ in ends) > FRONTIER_PRUNE:
        # Only ends at or beyond a bin's rank-th farthest of every FRONTIER_STRIDE-th end
        # can be its rank-th farthest of all (that one is at least as far): the rest need
        # not be grouped (at a million features 4.5M ends, 0.2 s of the fit).
        subset_distance = np.concatenate([part[::FRONTIER_STRIDE] for part, _ in ends])
        subset_bins = np.concatenate([part_bins[::FRONTIER_STRIDE] for _, part_bins in ends])
        order, bounds = group_by_bin(subset_bins, FOCUS_ANGLE_BINS)
        subset_distance = subset_distance[order]
        least = np.full(FOCUS_ANGLE_BINS, -np.inf)
        for b, (first, end) in enumerate(zip(bounds[:-1], bounds[1:])):  # a loop over bins
            if end - first >= rank:
                least[b] = np.partition(subset_distance[first:end], end - first - rank)[end - first - rank]
        bounds_of = {id(part_bins): least[part_bins] for _, part_bins in ends}
        candidates = [np.flatnonzero(part >= bounds_of[id(part_bins)]) for part, part_bins in ends]
        ends = [(part.take(chosen), part_bins.take(chosen)) for (part, part_bins), chosen in zip(ends, candidates)]
    distance = _joined([part for part, _ in ends], np.float64)
    ray_bins = _joined([part_bins for _, part_bins in ends], np.intp)
    order, bounds = group_by_bin(ray_bins, FOCUS_ANGLE_BINS)
    distance = distance[order]
    extent = np.zeros(FOCUS_ANGLE_BINS)
    if rank == 1:
        # A planar scan's extent is each bin's farthest end: one reduction over the bins
        # that have ends (a partition a bin was most of a planar fit's frontier). Those are
        # the bins whose count reaches the rank.
        filled = np.flatnonzero(bounds[1:] > bounds[:-1])
        if filled.size:
            extent[filled] = np.maximum.reduceat(distance, bounds[filled])
    else:
        for b, (first, end) in enumerate(zip(bounds[:-1], bounds[1:])):  # a loop over bins
            if counts[b] >= rank:
                # The rank-th farthest ray end: a partition, not a sort, of the bin's ends.
                extent[b] = np.partition(distance[first:end], end - first - rank)[end - first - rank]
    # A bin short of both its neighbours is a gap between sparse rays, not an edge of the
    # seen space: it takes the nearer neighbour's extent. (At 2k features one such bin in
    # the office doorway, 6 floor features ending at 1.7 m, closed the doorway in two of
    # three seeds; an edge, like the end of the open scene's untextured wall, keeps its
    # extent, since one neighbour is as short.)
    extent = np.maximum(extent, np.minimum(np.roll(extent, 1), np.roll(extent, -1)))
    short = np.flatnonzero(extent < focus_range)
    width = 2.0 * np.pi / FOCUS_ANGLE_BINS
    low, high = robot.body_band
    heights = np.linspace(low, high, FRONTIER_HEIGHTS)
    A, H = np.meshgrid(-np.pi + (short + 0.5) * width, heights, indexing="ij")
    # The body itself is known free (footprint samples): an unseen direction is closed
    # UNSEEN_CLEARANCE outside it, not inside it, so the robot is never in collision where
    # it stands and can turn and back off a little where it cannot see (behind a laser).
    reach = np.maximum(extent[short] * (1.0 + FRONTIER_MARGIN) + FRONTIER_ABS, robot.radius + UNSEEN_CLEARANCE)
    D = np.repeat(reach, FRONTIER_HEIGHTS).reshape(A.shape)
    A, H, D = A.ravel(), H.ravel(), D.ravel()
    return Samples(A, H, np.hypot(D, H), np.ones_like(A), np.ones_like(A),
                   np.full(A.shape, SAMPLE_KINDS["frontier"], dtype=np.int8))


def join_samples(*parts: Samples) -> Samples:
    """Concatenate sample sets."""
    return Samples(*(np.concatenate([getattr(p, name) for p in parts])
                     for name in ("alpha", "h", "r", "m", "weight", "kind")))
