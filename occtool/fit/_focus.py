"""The samples the fit sees: the focus on what a monotone model can show, and the frontier.

``F`` increases with ``r``, so behind the first obstacle at a pan angle the samples can only
pull the fit away from it: :func:`focus_samples` keeps those in front of it, in the body's
height band and within the focus range. Where the observed free space ends short of that
range, :func:`frontier_samples` adds occupied samples, so linear pieces do not extrapolate
free space into what was never seen.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from occtool.fit._profile import (
    FOCUS_ANGLE_BINS,
    FOCUS_WINDOW,
    FOCUS_WINDOW_ABS,
    adaptive_support,
    angle_bins,
    first_obstacle_distance,
    group_by_bin,
)
from occtool.robot import Robot
from occtool.sensor import SAMPLE_KINDS, Samples

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
    distance, bins = _geometry(samples)
    frontier = _frontier(samples, robot, focus_range, planar, distance, bins)
    keep = _focus_mask(samples, robot, focus_range, floor_is_obstacle, distance, bins)
    kept = np.flatnonzero(keep)
    count = kept.size
    columns = []
    for name in ("alpha", "h", "r", "m", "weight", "kind"):
        values, extra = getattr(samples, name), getattr(frontier, name)
        joined = np.empty(count + extra.size, dtype=np.result_type(values, extra))
        np.take(values, kept, out=joined[:count])
        joined[count:] = extra
        columns.append(joined)
    return Samples(*columns)


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
    return _frontier(samples, robot, focus_range, planar, distance, bins)


def _frontier(samples: Samples, robot: Robot, focus_range: float, planar: bool, distance: FloatArray,
              bins: NDArray[np.intp]) -> Samples:
    """:func:`frontier_samples` (``distance``, ``bins``: :func:`_geometry`)."""
    # The ray ends are the hit samples and the free samples of floor features.
    kind = samples.kind
    rays = (kind == SAMPLE_KINDS["hit"]) | (kind == SAMPLE_KINDS["near"]) | (kind == SAMPLE_KINDS["floor"])
    distance, ray_bins = distance[rays], bins[rays]
    # A planar scan has one beam a direction and no mismatches: its farthest end is seen.
    rank = 1 if planar else adaptive_support(samples.count("robot"))[1]
    counts = np.bincount(ray_bins, minlength=FOCUS_ANGLE_BINS)
    if distance.size > FRONTIER_PRUNE:
        # Only ends at or beyond a bin's rank-th farthest of every FRONTIER_STRIDE-th end
        # can be its rank-th farthest of all (that one is at least as far): the rest need
        # not be grouped (at a million features 4.5M ends, 0.2 s of the fit).
        subset_distance, subset_bins = distance[::FRONTIER_STRIDE], ray_bins[::FRONTIER_STRIDE]
        order, bounds = group_by_bin(subset_bins, FOCUS_ANGLE_BINS)
        subset_distance = subset_distance[order]
        least = np.full(FOCUS_ANGLE_BINS, -np.inf)
        for b, (first, end) in enumerate(zip(bounds[:-1], bounds[1:])):  # a loop over bins
            if end - first >= rank:
                least[b] = np.partition(subset_distance[first:end], end - first - rank)[end - first - rank]
        candidates = distance >= least[ray_bins]
        distance, ray_bins = distance[candidates], ray_bins[candidates]
    order, bounds = group_by_bin(ray_bins, FOCUS_ANGLE_BINS)
    distance = distance[order]
    extent = np.zeros(FOCUS_ANGLE_BINS)
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
